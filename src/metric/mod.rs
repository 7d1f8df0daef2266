//! Metric depth from relative inverse depth using reference objects (paper eq. 1-2).
