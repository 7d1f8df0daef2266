//! Fixed-capacity multi-object tracker: constant-velocity Kalman filter and optimal assignment.
