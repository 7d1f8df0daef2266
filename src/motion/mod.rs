//! World positions, per-fish 3D speed and the swarm activity index (paper sec. 3.3, eq. 5).
