//! The serial field-diagnostics console (line based, read-only).
