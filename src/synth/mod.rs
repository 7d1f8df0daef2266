//! Synthetic underwater fish sequences with exact ground truth (`fme synth`).
