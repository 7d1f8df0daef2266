//! Modbus in all four roles (tokio-modbus): TCP server (default; the PLC polls), TCP client (one
//! FC16 write of the block per update), RTU server and RTU client over a serial line.
//!
//! The TCP and RTU servers frame and decode requests themselves, checking them first
//! ([`super::modbus_guard`]: tokio-modbus 0.17 panics on some malformed FC15 frames); the TCP server limits and
//! filters its connections and closes idle ones ([`super::tcp_conns`]), and a failed accept pauses
//! it instead of stopping it.
//!
//! Every client call has a timeout (tokio-modbus has none of its own, issue #113); a lost PLC is
//! reconnected with exponential backoff (tokio-modbus does not reconnect, #219/#309); the pipeline
//! only ever publishes into the [`RegisterBank`] and never waits on the PLC.

use super::bank::RegisterBank;
use super::log_throttle::LogThrottle;
use super::modbus_guard::{FrameError, MAX_PDU, RtuSplit, answer, answer_pdu, crc_ok, crc16, read_frame, rtu_split};
use super::registers::{BLOCK_LEN, HR_WRITABLE_LEN, HR_WRITABLE_START};
use super::tcp_conns::{Connections, GuardedStream, TcpLimits};
use crate::backoff::Backoff;
use crate::config::{ModbusConfig, Parity};
use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio_modbus::prelude::*;
use tokio_modbus::{ExceptionCode, Request, Response};

/// A Modbus role failed to start (bind, open serial). Runtime failures are retried, not returned.
#[derive(Debug, thiserror::Error)]
pub enum ModbusError {
    /// Binding the TCP listener failed.
    #[error(
        "modbus tcp server: cannot listen on {addr} (output.modbus.listen): {error}{}",
        super::listen_hint::listen_hint(error, "output.modbus.listen")
    )]
    Bind {
        /// The address.
        addr: String,
        /// The I/O error (in the message, not a separate cause: printed once).
        error: std::io::Error,
    },
    /// Opening the serial device failed.
    #[error("modbus rtu: cannot open {device}: {message}")]
    Serial {
        /// The device.
        device: String,
        /// What failed.
        message: String,
    },
}

/// The server-side request handler over a [`RegisterBank`] (shared by the TCP and RTU servers).
///
/// FC03/FC04 read the block (holding registers also expose HR 100..103); FC06/FC16 may write only
/// HR 100..103 (anything else: IllegalDataAddress); FC01/FC02 read coil/discrete input 0 = feeding
/// recommended; any other function: IllegalFunction. Which unit ids are answered is the framing's
/// business (the RTU server ignores other units, as on a shared RS-485 bus; TCP answers any).
#[derive(Debug, Clone)]
pub struct RegisterService {
    bank: Arc<RegisterBank>,
}

impl RegisterService {
    /// A handler over `bank`.
    pub fn new(bank: Arc<RegisterBank>) -> Self {
        Self { bank }
    }

    fn read(&self, addr: u16, cnt: u16, holding: bool) -> Result<Vec<u16>, ExceptionCode> {
        if cnt == 0 || cnt > 125 {
            return Err(ExceptionCode::IllegalDataValue);
        }
        let (start, end) = (usize::from(addr), usize::from(addr) + usize::from(cnt));
        if end <= BLOCK_LEN {
            return Ok(self.bank.block()[start..end].to_vec());
        }
        let hr_start = usize::from(HR_WRITABLE_START);
        if holding && start >= hr_start && end <= hr_start + HR_WRITABLE_LEN {
            return Ok(self.bank.writable()[start - hr_start..end - hr_start].to_vec());
        }
        Err(ExceptionCode::IllegalDataAddress)
    }

    fn bits(&self, addr: u16, cnt: u16) -> Result<Vec<bool>, ExceptionCode> {
        if cnt == 0 || cnt > 2000 {
            return Err(ExceptionCode::IllegalDataValue);
        }
        if addr != 0 || cnt != 1 {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        Ok(vec![self.bank.block()[17] != 0])
    }

    /// Handles one request (pure apart from the bank).
    pub fn handle(&self, req: Request<'_>) -> Result<Response, ExceptionCode> {
        match req {
            Request::ReadInputRegisters(a, n) => self.read(a, n, false).map(Response::ReadInputRegisters),
            Request::ReadHoldingRegisters(a, n) => self.read(a, n, true).map(Response::ReadHoldingRegisters),
            Request::ReadCoils(a, n) => self.bits(a, n).map(Response::ReadCoils),
            Request::ReadDiscreteInputs(a, n) => self.bits(a, n).map(Response::ReadDiscreteInputs),
            Request::WriteSingleRegister(a, v) => {
                if self.bank.write_holding(a, &[v]) {
                    Ok(Response::WriteSingleRegister(a, v))
                } else {
                    Err(ExceptionCode::IllegalDataAddress)
                }
            }
            Request::WriteMultipleRegisters(a, words) => {
                if words.is_empty() || words.len() > 123 {
                    Err(ExceptionCode::IllegalDataValue)
                } else if self.bank.write_holding(a, &words) {
                    Ok(Response::WriteMultipleRegisters(a, words.len() as u16))
                } else {
                    Err(ExceptionCode::IllegalDataAddress)
                }
            }
            Request::WriteSingleCoil(..) | Request::WriteMultipleCoils(..) => Err(ExceptionCode::IllegalDataAddress),
            _ => Err(ExceptionCode::IllegalFunction),
        }
    }
}

/// Binds the TCP server (so bind errors surface at start-up). Returns the listener and its address.
pub async fn bind_tcp(listen: &str) -> Result<(tokio::net::TcpListener, SocketAddr), ModbusError> {
    let l = tokio::net::TcpListener::bind(listen)
        .await
        .map_err(|error| ModbusError::Bind { addr: listen.to_string(), error })?;
    let addr = l.local_addr().map_err(|error| ModbusError::Bind { addr: listen.to_string(), error })?;
    Ok((l, addr))
}

/// Serves Modbus TCP on `listener` until `shutdown` resolves, within `limits` (allow list,
/// connection limits, priority connections, idle timeout: [`super::tcp_conns`]).
///
/// Framing and request decoding are this crate's own ([`super::modbus_guard`]): malformed
/// requests get exception 03 and never reach tokio-modbus's decoder (upstream issue 298). Each
/// connection is its own task; a panic in one is counted and logged at most once per 10 s.
///
/// A failed accept (the process out of file descriptors, say) never stops the server: it is
/// counted, logged, and accepting resumes after a pause (backoff 0.1 s doubling to 5 s); the
/// connections already open are served meanwhile.
pub async fn serve_tcp(
    listener: tokio::net::TcpListener,
    bank: Arc<RegisterBank>,
    limits: TcpLimits,
    shutdown: impl Future<Output = ()> + Send + 'static,
) {
    let conns = Connections::new(limits, bank.clone());
    let mut tasks = tokio::task::JoinSet::new();
    let mut panic_log = LogThrottle::new(TASK_LOG_PERIOD);
    let mut refused_log = LogThrottle::new(TASK_LOG_PERIOD);
    let mut shutdown = std::pin::pin!(shutdown);
    let mut backoff = Backoff::new(Duration::from_millis(100), Duration::from_secs(5));
    loop {
        tokio::select! {
            () = &mut shutdown => return, // dropping the JoinSet aborts the connection tasks
            Some(done) = tasks.join_next(), if !tasks.is_empty() => {
                if let Err(e) = done
                    && e.is_panic()
                {
                    note_panic(&bank, &mut panic_log, "modbus tcp connection", e.into_panic());
                }
            }
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    backoff.reset();
                    if !conns.permits(peer) {
                        bank.note_tcp_refused();
                        if let Some(n) = refused_log.allow(tokio::time::Instant::now()) {
                            tracing::warn!("modbus tcp: connection from {peer} refused (not in output.modbus.allow; {n} more since the last message)");
                        }
                        drop(stream);
                        continue;
                    }
                    let _ = stream.set_nodelay(true);
                    // `None`: refused, every slot that could make room held by a priority connection.
                    if let Some(guarded) = conns.admit(stream, peer) {
                        tasks.spawn(serve_connection(guarded, bank.clone()));
                    }
                }
                Err(e) => {
                    let pause = backoff.next_delay();
                    bank.note_tcp_accept_error();
                    tracing::warn!("modbus tcp server: accept failed: {e}; accepting again in {:.1} s", pause.as_secs_f64());
                    tokio::select! {
                        _ = tokio::time::sleep(pause) => {},
                        () = &mut shutdown => return,
                    }
                }
            },
        }
    }
}

/// At most one panic / refusal message per this period (the bank counts each).
const TASK_LOG_PERIOD: Duration = Duration::from_secs(10);

/// A write of one answer taking longer than this (a peer that does not read) ends the connection.
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

fn note_panic(bank: &RegisterBank, log: &mut LogThrottle, what: &str, p: Box<dyn std::any::Any + Send>) {
    bank.note_task_panic();
    if let Some(n) = log.allow(tokio::time::Instant::now()) {
        let msg = p
            .downcast_ref::<&str>()
            .map(|s| (*s).to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "(no message)".into());
        tracing::error!(
            "{what} task panicked: {msg} ({n} more since the last message; {} in all)",
            bank.counters().task_panics
        );
    }
}

/// Serves one TCP connection: frame, decode (checked), answer, until the peer closes, the idle
/// timeout, eviction, or a frame that cannot be framed.
async fn serve_connection(mut stream: GuardedStream, bank: Arc<RegisterBank>) {
    use tokio::io::AsyncWriteExt as _;
    let service = RegisterService::new(bank.clone());
    let mut buf = Vec::with_capacity(MAX_PDU);
    let mut out = Vec::with_capacity(MAX_PDU + 7);
    loop {
        let frame = match read_frame(&mut stream, std::mem::take(&mut buf)).await {
            Ok(f) => f,
            Err(FrameError::Header { protocol, length }) => {
                bank.note_tcp_bad_frame();
                tracing::debug!(
                    "modbus tcp {}: bad MBAP header (protocol {protocol}, length {length}); closing",
                    stream.peer()
                );
                return;
            }
            Err(FrameError::Io(e)) => {
                tracing::debug!("modbus tcp connection ended: {e}");
                return;
            }
        };
        let exception = answer(&frame, |req| service.handle(req), &mut out);
        bank.note_request(exception);
        stream.note_request(!exception);
        buf = frame.pdu;
        match tokio::time::timeout(WRITE_TIMEOUT, stream.write_all(&out)).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => {
                tracing::debug!("modbus tcp connection ended: {e}");
                return;
            }
            Err(_) => {
                tracing::debug!(
                    "modbus tcp {}: answer not read for {} s; closing",
                    stream.peer(),
                    WRITE_TIMEOUT.as_secs()
                );
                return;
            }
        }
    }
}

fn serial_builder(cfg: &ModbusConfig) -> tokio_serial::SerialPortBuilder {
    let parity = match cfg.parity {
        Parity::None => tokio_serial::Parity::None,
        Parity::Even => tokio_serial::Parity::Even,
        Parity::Odd => tokio_serial::Parity::Odd,
    };
    let stop = if cfg.stop_bits == 2 { tokio_serial::StopBits::Two } else { tokio_serial::StopBits::One };
    tokio_serial::new(&cfg.serial_device, cfg.baud)
        .parity(parity)
        .stop_bits(stop)
        .data_bits(tokio_serial::DataBits::Eight)
}

/// Opens the RTU serial device described by `cfg`.
pub fn open_serial(cfg: &ModbusConfig) -> Result<tokio_serial::SerialStream, ModbusError> {
    tokio_serial::SerialStream::open(&serial_builder(cfg))
        .map_err(|e| ModbusError::Serial { device: cfg.serial_device.clone(), message: e.to_string() })
}

/// Serves Modbus RTU on an opened serial stream (answers only `unit_id`; broadcasts to unit 0 are
/// carried out without an answer) until `shutdown`.
pub async fn serve_rtu(
    mut serial: tokio_serial::SerialStream,
    bank: Arc<RegisterBank>,
    unit_id: u8,
    shutdown: impl Future<Output = ()> + Send + 'static,
) {
    let shutdown = std::pin::pin!(shutdown);
    if let Err(e) = rtu_loop(&mut serial, &bank, unit_id, shutdown).await {
        tracing::error!("modbus rtu server stopped: {e}");
    }
}

/// Silence that ends a frame whose length its function code does not tell (and flushes noise).
/// Far above the 3.5 character times of the spec: USB RS-485 adapters deliver bytes in bursts.
const RTU_GAP: Duration = Duration::from_millis(50);

/// The RTU server loop, with this crate's own framing and checked decoding
/// ([`super::modbus_guard`]; tokio-modbus's RTU decoder panics on the same FC15 frames as its TCP
/// one). `Ok(true)`: stopped by `shutdown`; `Ok(false)`: the port reached its end.
async fn rtu_loop<S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin>(
    port: &mut S,
    bank: &Arc<RegisterBank>,
    unit_id: u8,
    mut shutdown: std::pin::Pin<&mut impl Future<Output = ()>>,
) -> std::io::Result<bool> {
    use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
    let service = RegisterService::new(bank.clone());
    let mut buf: Vec<u8> = Vec::with_capacity(512);
    let mut chunk = [0u8; 256];
    let mut pdu = Vec::with_capacity(MAX_PDU);
    let mut out = Vec::with_capacity(MAX_PDU + 3);
    loop {
        let gap = !buf.is_empty();
        tokio::select! {
            () = &mut shutdown => return Ok(true),
            r = port.read(&mut chunk) => match r? {
                0 => return Ok(false),
                n => buf.extend_from_slice(&chunk[..n]),
            },
            () = tokio::time::sleep(RTU_GAP), if gap => {
                // Silence: whatever is left is one frame of a length only the silence tells, or noise.
                while buf.len() >= 4 {
                    match rtu_split(&buf) {
                        RtuSplit::Frame(n) => { rtu_answer(&buf[..n], &service, bank, unit_id, &mut pdu, &mut out); buf.drain(..n); }
                        RtuSplit::NeedMore if crc_ok(&buf) => { rtu_answer(&buf, &service, bank, unit_id, &mut pdu, &mut out); buf.clear(); }
                        RtuSplit::NeedMore | RtuSplit::Skip => { buf.remove(0); }
                    }
                    if !out.is_empty() { port.write_all(&out).await?; out.clear(); }
                }
                buf.clear();
                continue;
            }
        }
        loop {
            match rtu_split(&buf) {
                RtuSplit::Frame(n) => {
                    rtu_answer(&buf[..n], &service, bank, unit_id, &mut pdu, &mut out);
                    buf.drain(..n);
                    if !out.is_empty() {
                        port.write_all(&out).await?;
                        out.clear();
                    }
                }
                RtuSplit::Skip => {
                    buf.remove(0);
                }
                RtuSplit::NeedMore => break,
            }
        }
        if buf.len() > 2 * (MAX_PDU + 3) {
            buf.clear(); // noise that never framed
        }
    }
}

/// Answers one CRC-checked RTU request `adu` into `out` (left empty when no answer is due: another
/// unit, or a broadcast).
fn rtu_answer(
    adu: &[u8],
    service: &RegisterService,
    bank: &RegisterBank,
    unit_id: u8,
    pdu: &mut Vec<u8>,
    out: &mut Vec<u8>,
) {
    out.clear();
    let unit = adu[0];
    if unit != unit_id && unit != 0 {
        return;
    }
    let exception = answer_pdu(&adu[1..adu.len() - 2], |req| service.handle(req), pdu);
    bank.note_request(exception);
    if unit == 0 {
        return;
    }
    out.push(unit);
    out.extend_from_slice(pdu);
    let crc = crc16(out);
    out.extend_from_slice(&crc);
}

/// RTU server role with recovery: opens `cfg.serial_device`, serves, and on an open failure or a
/// lost device (USB RS-485 adapter unplugged) logs, waits with backoff and reopens, until `shutdown`.
/// Each opened port is served in its own task: a panic there is counted, logged at most once per
/// 10 s, and the port reopened.
pub async fn run_rtu_server(
    cfg: ModbusConfig,
    bank: Arc<RegisterBank>,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
) {
    let mut backoff =
        Backoff::new(Duration::from_millis(cfg.reconnect_min_ms), Duration::from_millis(cfg.reconnect_max_ms));
    let mut panic_log = LogThrottle::new(TASK_LOG_PERIOD);
    while !*shutdown.borrow() {
        match open_serial(&cfg) {
            Ok(mut port) => {
                backoff.reset();
                tracing::info!("modbus rtu server on {} unit {}", cfg.serial_device, cfg.unit_id);
                let mut rx = shutdown.clone();
                let (b, unit) = (bank.clone(), cfg.unit_id);
                let serving = tokio::spawn(async move {
                    let stop = std::pin::pin!(async move {
                        let _ = rx.wait_for(|s| *s).await;
                    });
                    rtu_loop(&mut port, &b, unit, stop).await
                });
                match serving.await {
                    Ok(Ok(true)) => return,
                    Ok(Ok(false)) => tracing::warn!("modbus rtu {}: port closed", cfg.serial_device),
                    Ok(Err(e)) => tracing::warn!("modbus rtu {}: {e}", cfg.serial_device),
                    Err(e) if e.is_panic() => note_panic(&bank, &mut panic_log, "modbus rtu server", e.into_panic()),
                    Err(_) => return,
                }
            }
            Err(e) => tracing::warn!("{e}"),
        }
        let d = backoff.next_delay();
        tokio::select! {
            _ = tokio::time::sleep(d) => {},
            _ = shutdown.changed() => {},
        }
    }
}

/// How a client reaches the PLC.
#[derive(Debug, Clone)]
pub enum ClientTarget {
    /// Modbus TCP to this HOST:PORT (resolved at each connect attempt).
    Tcp(String),
    /// Modbus RTU on this serial config.
    Rtu(ModbusConfig),
}

/// Client settings.
#[derive(Debug, Clone)]
pub struct ClientSettings {
    /// Where the PLC is.
    pub target: ClientTarget,
    /// Unit id addressed.
    pub unit_id: u8,
    /// First holding register of the block in the PLC.
    pub base_address: u16,
    /// Timeout of every call.
    pub timeout: Duration,
    /// Reconnect backoff.
    pub backoff: Backoff,
}

async fn connect(s: &ClientSettings) -> Result<tokio_modbus::client::Context, String> {
    let slave = Slave(s.unit_id);
    match &s.target {
        ClientTarget::Tcp(peer) => {
            let attempt = async {
                let addr = tokio::net::lookup_host(peer.as_str())
                    .await?
                    .next()
                    .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "no address"))?;
                tcp::connect_slave(addr, slave).await
            };
            match tokio::time::timeout(s.timeout, attempt).await {
                Ok(Ok(ctx)) => Ok(ctx),
                Ok(Err(e)) => Err(format!("connect {peer}: {e}")),
                Err(_) => Err(format!("connect {peer}: timed out")),
            }
        }
        ClientTarget::Rtu(cfg) => {
            open_serial(cfg).map(|port| rtu::attach_slave(port, slave)).map_err(|e| e.to_string())
        }
    }
}

/// Client role: writes the block to the PLC with one FC16 per published update, until `shutdown`.
/// Connection failures are retried with backoff; updates published meanwhile are coalesced (only
/// the latest block is written). After `shutdown`, the current block (the "stopped" block) is
/// written once more, best effort, within one timeout.
pub async fn run_client(
    settings: ClientSettings,
    bank: Arc<RegisterBank>,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
) {
    let mut rx = bank.subscribe();
    rx.mark_changed(); // write the current block at once, even if it was published before we subscribed
    let mut ctx: Option<tokio_modbus::client::Context> = None;
    let mut backoff = settings.backoff;
    let mut retry_at: Option<tokio::time::Instant> = None;
    loop {
        let stopping = *shutdown.borrow();
        if !stopping {
            // Wait for a new block, or for the retry time when the last write failed.
            let retry = async {
                match retry_at {
                    Some(t) => tokio::time::sleep_until(t).await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                r = rx.changed() => if r.is_err() { return },
                _ = retry => {},
                _ = shutdown.changed() => {},
            }
        }
        let block = *rx.borrow_and_update();
        if ctx.is_none() {
            match connect(&settings).await {
                Ok(c) => ctx = Some(c),
                Err(e) => {
                    bank.note_client(false);
                    let d = backoff.next_delay();
                    tracing::warn!("plc link down ({e}); retry in {} ms", d.as_millis());
                    retry_at = Some(tokio::time::Instant::now() + d);
                    if stopping {
                        return;
                    }
                    continue;
                }
            }
        }
        let Some(c) = ctx.as_mut() else { continue };
        let res =
            tokio::time::timeout(settings.timeout, c.write_multiple_registers(settings.base_address, &block)).await;
        let err = match res {
            Ok(Ok(Ok(()))) => None,
            Ok(Ok(Err(exc))) => Some(format!("PLC answered exception {exc:?}")),
            Ok(Err(e)) => Some(e.to_string()),
            Err(_) => Some(format!("no answer within {} ms", settings.timeout.as_millis())),
        };
        match err {
            None => {
                if !bank.client_link_ok() {
                    tracing::info!("plc link up");
                }
                bank.note_client(true);
                backoff.reset();
                retry_at = None;
            }
            Some(e) => {
                bank.note_client(false);
                ctx = None; // drop the context: tokio-modbus contexts do not recover
                let d = backoff.next_delay();
                tracing::warn!("plc write failed ({e}); reconnect in {} ms", d.as_millis());
                retry_at = Some(tokio::time::Instant::now() + d);
            }
        }
        if stopping {
            if let Some(mut c) = ctx.take() {
                let _ = tokio::time::timeout(settings.timeout, c.disconnect()).await;
            }
            return;
        }
    }
}
