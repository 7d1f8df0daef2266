//! `[output.modbus]`: the Modbus role, addresses, serial line and TCP server limits, and their check.

use super::host_port;
use crate::config::{KeyError, allow::AllowList, ensure};
use serde::{Deserialize, Serialize};

/// Modbus role.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum ModbusMode {
    /// No Modbus.
    Off,
    /// TCP server: the PLC polls (default).
    TcpServer,
    /// TCP client: one FC16 write of the register block to the PLC per update.
    TcpClient,
    /// RTU server on a serial line (RS-485).
    RtuServer,
    /// RTU client on a serial line.
    RtuClient,
}

/// Order of the two 16-bit words of a float32/uint32.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum WordOrder {
    /// High word first (ABCD, "big endian"; default).
    #[default]
    HighFirst,
    /// Low word first (CDAB, "Modicon"/little-endian word order).
    LowFirst,
}

/// Serial parity.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Parity {
    /// No parity.
    None,
    /// Even parity (the Modbus RTU default).
    Even,
    /// Odd parity.
    Odd,
}

/// `[output.modbus]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ModbusConfig {
    /// Role: `off`, `tcp-server`, `tcp-client`, `rtu-server`, `rtu-client`.
    pub mode: ModbusMode,
    /// TCP server: address to listen on, HOST:PORT. The built-in default is `127.0.0.1:5020` (this
    /// box only, an unprivileged port: a replay needs no root and does not collide with the
    /// service); `boards/*.toml` set `0.0.0.0:502` for the PLC.
    pub listen: String,
    /// TCP client: the PLC's address, HOST:PORT.
    pub peer: String,
    /// Unit (slave) id: served by the RTU server; addressed by the clients.
    pub unit_id: u8,
    /// Word order of float32/uint32 values.
    pub word_order: WordOrder,
    /// Client modes: first holding register of the block in the PLC (0-based PDU address).
    pub base_address: u16,
    /// RTU: serial device.
    pub serial_device: String,
    /// RTU: baud rate, bit/s.
    pub baud: u32,
    /// RTU: parity.
    pub parity: Parity,
    /// RTU: stop bits (1 or 2).
    pub stop_bits: u8,
    /// Timeout of every Modbus call, ms.
    pub timeout_ms: u64,
    /// First reconnect delay after losing the PLC, ms (doubles up to `reconnect_max_ms`).
    pub reconnect_min_ms: u64,
    /// Longest reconnect delay, ms.
    pub reconnect_max_ms: u64,
    /// TCP server: connections served at once; one more closes the least recently active
    /// (Modbus TCP implementation guide 4.2.1).
    pub max_connections: u32,
    /// TCP server: connections served at once from one IP address (at most `max_connections`); one
    /// more closes one of that address's own.
    pub max_connections_per_peer: u32,
    /// TCP server: close a connection with no complete request for this long, ms (0 = never);
    /// keep it well above the PLC's poll interval.
    pub idle_timeout_ms: u64,
    /// TCP server: a connection whose requests have been answered for this long, no two more than
    /// this apart (a PLC polling steadily), has priority: it is never closed for a newcomer, which
    /// is refused instead when no other connection can make room, ms (0 = no priority). Keep it
    /// above the PLC's poll interval.
    pub priority_after_ms: u64,
    /// TCP server: addresses or CIDR ranges allowed to connect (`["192.168.1.0/24"]`); empty =
    /// everyone. Others are closed at accept and counted (console `counters`).
    pub allow: Vec<String>,
}

impl Default for ModbusConfig {
    fn default() -> Self {
        Self {
            mode: ModbusMode::TcpServer,
            listen: "127.0.0.1:5020".into(),
            peer: "192.168.0.10:502".into(),
            unit_id: 1,
            word_order: WordOrder::HighFirst,
            base_address: 0,
            serial_device: "/dev/ttyUSB0".into(),
            baud: 19_200,
            parity: Parity::Even,
            stop_bits: 1,
            timeout_ms: 1000,
            reconnect_min_ms: 500,
            reconnect_max_ms: 30_000,
            max_connections: 8,
            max_connections_per_peer: 4,
            idle_timeout_ms: 60_000,
            priority_after_ms: 10_000,
            allow: Vec::new(),
        }
    }
}

impl ModbusConfig {
    /// The role's address or device, the reconnect delays' order and the allow list.
    pub fn validate(&self) -> Result<(), KeyError> {
        match self.mode {
            ModbusMode::TcpServer => host_port("output.modbus.listen", &self.listen)?,
            ModbusMode::TcpClient => host_port("output.modbus.peer", &self.peer)?,
            ModbusMode::RtuServer | ModbusMode::RtuClient => {
                ensure(!self.serial_device.is_empty(), "output.modbus.serial_device", "must name a serial device")?;
            }
            ModbusMode::Off => {}
        }
        let delays = self.reconnect_min_ms <= self.reconnect_max_ms;
        ensure(delays, "output.modbus.reconnect_min_ms", "must be <= output.modbus.reconnect_max_ms")?;
        AllowList::parse(&self.allow).map(drop).map_err(|e| KeyError::new("output.modbus.allow", e))
    }
}
