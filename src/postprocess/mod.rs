//! Post-processing of tracks: box-fluctuation (eq. 3) and depth-jump (eq. 4) detectors with EWMA.
