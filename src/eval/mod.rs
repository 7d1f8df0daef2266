//! Evaluation against ground truth: speed RMSE, distance correlation, depth metrics, plots.
