//! Client roles: the daemon writes its block into an in-process PLC simulator (one FC16 per update);
//! PLC down at start, dropping mid-run and back: the daemon keeps running and catches up.

use crate::support::{self, wait_until};

use fme::capture::{Backoff, FrameSource, RecordedSource};
use fme::config::{ModbusMode, WordOrder};
use fme::output::bank::RegisterBank;
use fme::output::modbus::{self, ClientSettings, ClientTarget};
use fme::output::registers::{self, StatusBits, Update};
use fme::service::{Daemon, RunOptions};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};

/// A PLC with 200 holding registers that records every FC16 write.
#[derive(Clone, Default)]
struct Plc {
    regs: Arc<Mutex<Vec<u16>>>,
    writes: Arc<Mutex<u32>>,
}

impl Plc {
    fn new() -> Self {
        Self { regs: Arc::new(Mutex::new(vec![0; 200])), writes: Arc::default() }
    }
    fn regs(&self, at: usize, n: usize) -> Vec<u16> {
        self.regs.lock().expect("lock")[at..at + n].to_vec()
    }
    fn writes(&self) -> u32 {
        *self.writes.lock().expect("lock")
    }
}

impl tokio_modbus::server::Service for Plc {
    type Request = SlaveRequest<'static>;
    type Response = Response;
    type Exception = ExceptionCode;
    type Future = std::future::Ready<Result<Response, ExceptionCode>>;
    fn call(&self, req: Self::Request) -> Self::Future {
        std::future::ready(match req.request {
            Request::WriteMultipleRegisters(a, w) => {
                let a = usize::from(a);
                let mut r = self.regs.lock().expect("lock");
                if a + w.len() > r.len() {
                    Err(ExceptionCode::IllegalDataAddress)
                } else {
                    r[a..a + w.len()].copy_from_slice(&w);
                    *self.writes.lock().expect("lock") += 1;
                    Ok(Response::WriteMultipleRegisters(a as u16, w.len() as u16))
                }
            }
            _ => Err(ExceptionCode::IllegalFunction),
        })
    }
}

/// Serves the PLC on `addr` until the returned sender is dropped or used.
async fn serve_plc(plc: Plc, addr: SocketAddr) -> tokio::sync::oneshot::Sender<()> {
    let listener = tokio::net::TcpListener::bind(addr).await.expect("bind plc");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(async move {
        let server = tokio_modbus::server::tcp::Server::new(listener);
        let on_connected = move |stream, a| {
            let plc = plc.clone();
            async move { tokio_modbus::server::tcp::accept_tcp_connection(stream, a, move |_| Ok(Some(plc.clone()))) }
        };
        let _ = server
            .serve_until(&on_connected, |_e| {}, async move {
                let _ = rx.await;
            })
            .await;
    });
    tx
}

fn free_port() -> SocketAddr {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    l.local_addr().expect("addr")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn daemon_writes_block_to_plc_survives_plc_outages() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 30, 96, 64, 30);
    let plc_addr = free_port(); // nothing listens yet: PLC down at start
    let mut cfg = support::test_config(dir.path());
    cfg.output.modbus.mode = ModbusMode::TcpClient;
    cfg.output.modbus.peer = plc_addr.to_string();
    cfg.output.modbus.base_address = 50;
    cfg.output.modbus.timeout_ms = 300;
    cfg.output.modbus.reconnect_min_ms = 50;
    cfg.output.modbus.reconnect_max_ms = 200;
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let shared = daemon.shared().clone();
    let bank = daemon.bank().clone();

    // PLC down: the daemon keeps running (heartbeat advances), the link bit is clear, fault 5.
    wait_until("client failures", 5, || bank.counters().client_failures >= 2).await;
    let hb0 = bank.block()[12];
    tokio::time::sleep(Duration::from_millis(300)).await;
    let blk = bank.block();
    assert_ne!(blk[12], hb0, "heartbeat advances while the PLC is down");
    assert_eq!(blk[10] & StatusBits::PLC_LINK_OK.bits(), 0);
    assert_eq!(blk[11], registers::FaultCode::PlcLink as u16);
    assert!(shared.health().frames_processed > 0, "pipeline never blocks on the PLC");

    // PLC comes up: writes arrive at the base address, heartbeat increments there.
    let plc = Plc::new();
    let stop = serve_plc(plc.clone(), plc_addr).await;
    wait_until("first write", 5, || plc.writes() >= 1).await;
    let hb1 = plc.regs(62, 1)[0];
    wait_until("more writes", 5, || plc.writes() >= 4).await;
    assert_ne!(plc.regs(62, 1)[0], hb1, "heartbeat at base+12 increments in the PLC");
    assert_eq!(plc.regs(50 + 18, 2), bank.block()[18..20].to_vec(), "version registers");
    assert_eq!(plc.regs(0, 50), vec![0; 50], "nothing written below the base address");
    wait_until("link bit", 5, || bank.block()[10] & StatusBits::PLC_LINK_OK.bits() != 0).await;

    // PLC drops mid-run, then comes back on the same address: the daemon catches up.
    drop(stop);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let failures = bank.counters().client_failures;
    wait_until("failure noticed", 5, || bank.counters().client_failures > failures).await;
    let plc2 = Plc::new();
    let _stop2 = serve_plc(plc2.clone(), plc_addr).await;
    wait_until("writes after reconnect", 5, || plc2.writes() >= 2).await;
    assert_ne!(plc2.regs(50 + 10, 1)[0] & StatusBits::RUNNING.bits(), 0);

    // Shutdown: the final write carries the "stopped" status.
    daemon.shutdown().await;
    let last = plc2.regs(50, 24);
    assert_eq!(last[10] & StatusBits::RUNNING.bits(), 0, "final block says stopped: {last:?}");
    assert_eq!(last[11], registers::FaultCode::Stopped as u16);
}

#[tokio::test]
async fn rtu_client_writes_over_pty() {
    use tokio_serial::SerialPort as _;
    let (plc_end, daemon_end) = tokio_serial::SerialStream::pair().expect("pty pair");
    let device = daemon_end.name().expect("pty name");
    let plc = Plc::new();
    let server = tokio_modbus::server::rtu::Server::new(plc_end);
    let p = plc.clone();
    tokio::spawn(async move { server.serve_forever(p).await });
    let bank = Arc::new(RegisterBank::new());
    let mut mcfg = fme::config::ModbusConfig {
        mode: ModbusMode::RtuClient,
        serial_device: device,
        baud: 19_200,
        parity: fme::config::Parity::None,
        ..Default::default()
    };
    mcfg.unit_id = 3;
    let settings = ClientSettings {
        target: ClientTarget::Rtu(mcfg),
        unit_id: 3,
        base_address: 10,
        timeout: Duration::from_millis(500),
        backoff: Backoff::new(Duration::from_millis(50), Duration::from_millis(200)),
    };
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let task = tokio::spawn(modbus::run_client(settings, bank.clone(), stop_rx));
    let inp = Update { heartbeat: 1234, fish: 5, ..Default::default() };
    bank.publish(registers::encode(&inp, WordOrder::LowFirst));
    wait_until("rtu write", 5, || plc.writes() >= 1).await;
    assert_eq!(plc.regs(10 + 12, 1), vec![1234]);
    assert_eq!(plc.regs(10 + 8, 1), vec![5]);
    assert!(bank.client_link_ok());
    let _ = stop_tx.send(true);
    tokio::time::timeout(Duration::from_secs(2), task).await.expect("client stops").expect("join");
    drop(daemon_end);
}
