//! Frame sources: V4L2 cameras and recorded sequences, behind one `FrameSource` trait.
