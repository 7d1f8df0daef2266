//! Selection and spawning of the output roles of `fme run`: the Modbus role chosen by
//! `output.modbus.mode` (TCP server, TCP client, RTU server, RTU client, or none) and the plain
//! serial line (`output.serial`). The service only calls [`spawn`] and keeps the [`Roles`] handles
//! for its shutdown.

use super::bank::RegisterBank;
use super::modbus::{self, ClientSettings, ClientTarget, ModbusError};
use crate::backoff::Backoff;
use crate::config::{Config, ModbusMode};
use crate::status::Shared;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tracing::Level;

/// A role could not start.
#[derive(Debug, thiserror::Error)]
pub enum RoleError {
    /// A Modbus role could not start (bind).
    #[error(transparent)]
    Modbus(#[from] ModbusError),
    /// The serial line thread could not be spawned.
    #[error("cannot spawn serial line: {0}")]
    Spawn(std::io::Error),
}

/// The running output roles.
#[derive(Debug, Default)]
pub struct Roles {
    /// The bound Modbus TCP server address (tcp-server role).
    pub modbus_addr: Option<SocketAddr>,
    /// One stop signal per server task (tcp-server).
    pub server_stops: Vec<tokio::sync::oneshot::Sender<()>>,
    /// Server tasks (tcp-server, rtu-server).
    pub server_tasks: Vec<tokio::task::JoinHandle<()>>,
    /// The client task (tcp-client, rtu-client).
    pub client_task: Option<tokio::task::JoinHandle<()>>,
    /// The serial line: lines sent here are written to `output.serial.device` (never waits).
    pub serial_tx: Option<std::sync::mpsc::SyncSender<String>>,
    /// The serial line thread.
    pub serial_thread: Option<std::thread::JoinHandle<()>>,
}

/// Starts the Modbus role of `output.modbus.mode` and the serial line over `bank`. Must be called
/// inside a tokio runtime. `stop` turning true stops the client and RTU server roles; the TCP
/// server stops through [`Roles::server_stops`].
pub async fn spawn(
    cfg: &Config,
    bank: &Arc<RegisterBank>,
    shared: &Arc<Shared>,
    stop: tokio::sync::watch::Receiver<bool>,
) -> Result<Roles, RoleError> {
    let mut roles = Roles::default();
    let m = &cfg.output.modbus;
    match m.mode {
        ModbusMode::Off => {}
        ModbusMode::TcpServer => {
            let (listener, addr) = modbus::bind_tcp(&m.listen).await?;
            roles.modbus_addr = Some(addr);
            let (tx, rx) = tokio::sync::oneshot::channel::<()>();
            roles.server_stops.push(tx);
            roles.server_tasks.push(tokio::spawn(modbus::serve_tcp(
                listener,
                bank.clone(),
                super::tcp_conns::TcpLimits::from_config(m),
                async move {
                    let _ = rx.await;
                },
            )));
            announce_tcp_server(m, addr, shared);
        }
        ModbusMode::RtuServer => {
            // A missing RS-485 adapter is retried with backoff, not fatal.
            roles.server_tasks.push(tokio::spawn(modbus::run_rtu_server(m.clone(), bank.clone(), stop.clone())));
            shared.log(Level::INFO, format!("modbus rtu server on {} unit {}", m.serial_device, m.unit_id));
            let _ = shared.modbus.set(format!("rtu-server on {} unit {}", m.serial_device, m.unit_id));
        }
        ModbusMode::TcpClient | ModbusMode::RtuClient => {
            let target = if m.mode == ModbusMode::TcpClient {
                ClientTarget::Tcp(m.peer.clone()) // resolved at each connect: DNS changes are picked up
            } else {
                ClientTarget::Rtu(m.clone())
            };
            let settings = ClientSettings {
                target,
                unit_id: m.unit_id,
                base_address: m.base_address,
                timeout: Duration::from_millis(m.timeout_ms),
                backoff: Backoff::new(
                    Duration::from_millis(m.reconnect_min_ms),
                    Duration::from_millis(m.reconnect_max_ms),
                ),
            };
            roles.client_task = Some(tokio::spawn(modbus::run_client(settings, bank.clone(), stop.clone())));
            shared.log(
                Level::INFO,
                format!(
                    "modbus client ({:?}) to {}",
                    m.mode,
                    if m.mode == ModbusMode::TcpClient { &m.peer } else { &m.serial_device }
                ),
            );
            let to = if m.mode == ModbusMode::TcpClient { &m.peer } else { &m.serial_device };
            let _ = shared.modbus.set(format!("client to {to} (serves nobody)"));
        }
    }
    if cfg.output.serial.enabled {
        let (tx, rx) = std::sync::mpsc::sync_channel::<String>(4);
        let (dev, baud, sh) = (cfg.output.serial.device.clone(), cfg.output.serial.baud, shared.clone());
        roles.serial_thread = Some(
            std::thread::Builder::new()
                .name("fme-serial-line".into())
                .spawn(move || serial_line_loop(dev, baud, rx, sh))
                .map_err(RoleError::Spawn)?,
        );
        roles.serial_tx = Some(tx);
    }
    Ok(roles)
}

/// Logs where the Modbus TCP server listens and who may reach it, warning when it is open to every
/// address or, under systemd, reachable from this box only; the console `status` shows the same.
fn announce_tcp_server(m: &crate::config::ModbusConfig, addr: SocketAddr, shared: &Shared) {
    shared.log(Level::INFO, format!("modbus tcp server on {addr}"));
    let open = crate::config::allow::open_to_all(&addr.to_string(), &m.allow);
    let _ = shared.modbus.set(if open {
        format!("tcp-server on {addr}, OPEN TO EVERY ADDRESS (output.modbus.allow is empty)")
    } else if m.allow.is_empty() {
        format!("tcp-server on {addr} (this box only)")
    } else {
        format!("tcp-server on {addr}, allow {}", m.allow.join(", "))
    });
    if open {
        shared.log(
            Level::WARN,
            format!(
                "modbus tcp server on {addr} is open to every address: output.modbus.allow is empty, so any \
                 host on the network may read the registers and write HR 100-103. List the PLC's address \
                 (and any HMI/SCADA poller) in output.modbus.allow"
            ),
        );
    }
    // The built-in default serves this box only; a service needs the board config's address.
    if addr.ip().is_loopback() && std::env::var_os("INVOCATION_ID").is_some() {
        shared.log(
            Level::WARN,
            format!(
                "modbus tcp server listens on {addr}, this box only: a PLC on the network cannot \
                 reach it. Set output.modbus.listen = \"0.0.0.0:502\" (as boards/*.toml do)"
            ),
        );
    }
}

fn serial_line_loop(device: String, baud: u32, rx: std::sync::mpsc::Receiver<String>, shared: Arc<Shared>) {
    let mut port: Option<Box<dyn serialport::SerialPort>> = None;
    let mut backoff = Backoff::new(Duration::from_millis(500), Duration::from_secs(30));
    let mut retry_at = Instant::now();
    loop {
        let line = match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(l) => l,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) if shared.stopping() => return,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => continue,
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return,
        };
        if port.is_none() && Instant::now() >= retry_at {
            match serialport::new(&device, baud).timeout(Duration::from_millis(200)).open() {
                Ok(p) => {
                    backoff.reset();
                    port = Some(p);
                }
                Err(e) => {
                    let d = backoff.next_delay();
                    retry_at = Instant::now() + d;
                    shared.log(Level::WARN, format!("serial line {device}: {e}; retry in {} ms", d.as_millis()));
                }
            }
        }
        if let Some(p) = port.as_mut()
            && let Err(e) = p.write_all(line.as_bytes()).and_then(|()| p.flush())
        {
            shared.log(Level::WARN, format!("serial line {device}: write failed: {e}"));
            port = None;
        }
    }
}
