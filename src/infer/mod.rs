//! ONNX Runtime inference: YOLO-style detector, MiDaS-style relative depth, reduced-rate scheduling.
