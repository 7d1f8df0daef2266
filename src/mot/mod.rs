//! Multi-object tracking metrics (MOTA, MOTP, IDF1, ID switches) with MOTChallenge devkit conventions.
