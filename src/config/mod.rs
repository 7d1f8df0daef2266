//! The TOML configuration: one section per pipeline stage, validated with errors naming the key.
