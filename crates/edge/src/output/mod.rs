//! Outputs to the farm: register map, Modbus TCP/RTU server and client, serial line, feeding rule,
//! MQTT telemetry ([`mqtt`], docs/mqtt.md) and the Prometheus endpoint ([`metrics`], served by
//! [`crate::web`]). Each reads the one published [`Update`], made once per update by the
//! publisher; none decodes another's encoding.
//!
//! The register map ([`registers`]) and the feeding rule ([`feeding`]) are pure and tested without
//! I/O; [`modbus`] and the serial line are the I/O edges around the shared [`bank::RegisterBank`].
//! Both TCP servers (Modbus, metrics) limit connections per address with one [`peer_limit`].

pub mod bank;
pub mod config;
pub mod feeding;
pub mod listen_hint;
pub mod log_throttle;
pub mod metrics;
pub mod modbus;
pub mod modbus_guard;
pub mod mqtt;
pub mod peer_limit;
pub mod registers;
pub mod roles;
pub mod serial_line;
pub mod tcp_conns;
pub mod update;

pub use update::{StatusBits, Update};
