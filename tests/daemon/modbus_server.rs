//! Modbus server roles against in-process clients: register reads, mirrored holding registers,
//! exceptions for illegal addresses and functions, PLC-writable holding registers; TCP and RTU.

use crate::support;

use fme::capture::{FrameSource, RecordedSource};
use fme::config::{ModbusMode, WordOrder};
use fme::output::bank::RegisterBank;
use fme::output::modbus;
use fme::output::registers::{self, StatusBits, Update, decode_f32};
use fme::output::tcp_conns::{Connections, TcpLimits};
use fme::service::{Daemon, RunOptions};
use std::sync::Arc;
use std::time::Duration;
use tokio_modbus::ExceptionCode;
use tokio_modbus::prelude::*;

fn sample_bank() -> Arc<RegisterBank> {
    let bank = Arc::new(RegisterBank::new());
    let inp = Update {
        mean_mps: 0.125,
        smoothed_mps: 0.25,
        fish: 12,
        status: StatusBits::RUNNING | StatusBits::CAMERA_OK,
        heartbeat: 42,
        feeding: true,
        ..Default::default()
    };
    bank.publish(registers::encode(&inp, WordOrder::HighFirst));
    bank
}

async fn start_tcp(bank: Arc<RegisterBank>) -> (std::net::SocketAddr, tokio::sync::oneshot::Sender<()>) {
    start_tcp_with(bank, TcpLimits::default()).await
}

async fn start_tcp_with(
    bank: Arc<RegisterBank>,
    limits: TcpLimits,
) -> (std::net::SocketAddr, tokio::sync::oneshot::Sender<()>) {
    let (listener, addr) = modbus::bind_tcp("127.0.0.1:0").await.expect("bind");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(modbus::serve_tcp(listener, bank, limits, async move {
        let _ = rx.await;
    }));
    (addr, tx)
}

#[tokio::test]
async fn tcp_reads_writes_and_exceptions() {
    let bank = sample_bank();
    let (addr, _stop) = start_tcp(bank.clone()).await;
    let mut ctx = tcp::connect_slave(addr, Slave(1)).await.expect("connect");
    let ir = ctx.read_input_registers(0, 24).await.expect("transport").expect("exception");
    assert_eq!(ir, bank.block().to_vec());
    assert_eq!(decode_f32([ir[0], ir[1]], WordOrder::HighFirst), 0.125);
    assert_eq!(ir[8], 12);
    assert_eq!(ir[12], 42);
    let hr = ctx.read_holding_registers(0, 24).await.expect("transport").expect("exception");
    assert_eq!(hr, ir, "holding registers mirror input registers");
    let part = ctx.read_input_registers(8, 2).await.expect("transport").expect("exception");
    assert_eq!(part, vec![12, 125]);
    assert_eq!(ctx.read_coils(0, 1).await.expect("transport").expect("exception"), vec![true]);
    assert_eq!(ctx.read_discrete_inputs(0, 1).await.expect("transport").expect("exception"), vec![true]);

    // Out of the map: illegal data address, not silence or zeros.
    let e = ctx.read_input_registers(20, 10).await.expect("transport");
    assert_eq!(e, Err(ExceptionCode::IllegalDataAddress));
    let e = ctx.read_input_registers(100, 1).await.expect("transport");
    assert_eq!(e, Err(ExceptionCode::IllegalDataAddress), "HR 100 is not an input register");
    // The block is read-only.
    let e = ctx.write_single_register(10, 0).await.expect("transport");
    assert_eq!(e, Err(ExceptionCode::IllegalDataAddress));
    let e = ctx.write_multiple_registers(99, &[1, 2]).await.expect("transport");
    assert_eq!(e, Err(ExceptionCode::IllegalDataAddress), "straddles into the read-only area");
    let e = ctx.write_single_coil(0, true).await.expect("transport");
    assert_eq!(e, Err(ExceptionCode::IllegalDataAddress));
    assert_eq!(bank.block()[10], (StatusBits::RUNNING | StatusBits::CAMERA_OK).bits(), "nothing was written");
    // Unsupported function: illegal function.
    let e = ctx.read_write_multiple_registers(0, 2, 100, &[1]).await.expect("transport");
    assert_eq!(e, Err(ExceptionCode::IllegalFunction));
    let e = ctx.masked_write_register(100, 0xFF, 0).await.expect("transport");
    assert_eq!(e, Err(ExceptionCode::IllegalFunction));

    // The PLC-writable holding registers.
    ctx.write_single_register(registers::HR_FEEDING_ACK, 1).await.expect("transport").expect("exception");
    ctx.write_multiple_registers(registers::HR_PLC_HEARTBEAT, &[7, 8, 9]).await.expect("transport").expect("exception");
    assert_eq!(bank.writable(), [1, 7, 8, 9]);
    let back = ctx.read_holding_registers(100, 4).await.expect("transport").expect("exception");
    assert_eq!(back, vec![1, 7, 8, 9]);
    let e = ctx.write_multiple_registers(102, &[1, 2, 3]).await.expect("transport");
    assert_eq!(e, Err(ExceptionCode::IllegalDataAddress), "past the writable area");
    // Quantity 0 and 126 are illegal data values (exception 03), sent raw: the client library
    // would refuse to send them.
    for qty in [0u16, 126] {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let mut raw = tokio::net::TcpStream::connect(addr).await.expect("connect raw");
        let q = qty.to_be_bytes();
        raw.write_all(&[0, 7, 0, 0, 0, 6, 1, 0x04, 0, 0, q[0], q[1]]).await.expect("send");
        let mut reply = [0u8; 9];
        tokio::time::timeout(Duration::from_secs(2), raw.read_exact(&mut reply)).await.expect("reply").expect("read");
        assert_eq!(reply, [0, 7, 0, 0, 0, 3, 1, 0x84, 0x03], "quantity {qty}: exception 03");
    }

    let c = bank.counters();
    assert!(c.requests >= 15 && c.exceptions >= 8, "{c:?}");
    assert!(bank.served_within(Duration::from_secs(10)));
}

#[tokio::test]
async fn tcp_server_sees_new_blocks_and_many_clients() {
    let bank = sample_bank();
    let (addr, stop) = start_tcp(bank.clone()).await;
    let mut a = tcp::connect_slave(addr, Slave(1)).await.expect("connect a");
    let mut b = tcp::connect_slave(addr, Slave(7)).await.expect("connect b (any unit id over TCP)");
    let mut blk = bank.block();
    blk[12] = 43;
    bank.publish(blk);
    assert_eq!(a.read_input_registers(12, 1).await.expect("t").expect("e"), vec![43]);
    assert_eq!(b.read_input_registers(12, 1).await.expect("t").expect("e"), vec![43]);
    let _ = stop.send(());
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert!(tcp::connect_slave(addr, Slave(1)).await.is_err(), "server stopped listening");
}

/// One register read with a deadline: `Ok` only when the server answered with data.
async fn read_ok(ctx: &mut tokio_modbus::client::Context) -> bool {
    matches!(tokio::time::timeout(Duration::from_secs(2), ctx.read_input_registers(8, 1)).await, Ok(Ok(Ok(_))))
}

#[tokio::test]
async fn tcp_server_closes_a_connection_idle_past_the_timeout_and_keeps_a_polling_one() {
    let bank = sample_bank();
    let limits = TcpLimits { max_connections: 8, idle_timeout: Some(Duration::from_secs(1)), ..TcpLimits::default() };
    let (addr, _stop) = start_tcp_with(bank.clone(), limits).await;
    let mut polling = tcp::connect_slave(addr, Slave(1)).await.expect("connect polling");
    let mut idle = tcp::connect_slave(addr, Slave(1)).await.expect("connect idle");
    assert!(read_ok(&mut idle).await, "first read on the idle connection");
    // 3 s of polling every 100 ms: three idle timeouts long, never idle for one.
    for i in 0..30 {
        assert!(read_ok(&mut polling).await, "poll {i} on a busy connection");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(!read_ok(&mut idle).await, "the connection idle for 3 s must have been closed");
    let c = bank.counters();
    assert_eq!((c.tcp_idle_closed, c.tcp_open), (1, 1), "{c:?}");
    // The PLC simply reconnects.
    let mut again = tcp::connect_slave(addr, Slave(1)).await.expect("reconnect");
    assert!(read_ok(&mut again).await);
}

#[tokio::test]
async fn an_evicted_stream_keeps_failing_when_polled_again() {
    use tokio::io::AsyncReadExt as _;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = listener.local_addr().expect("addr");
    let conns =
        Connections::new(TcpLimits { max_connections: 1, idle_timeout: None, ..TcpLimits::default() }, sample_bank());
    let _ca = tokio::net::TcpStream::connect(addr).await.expect("connect a");
    let (sa, peer_a) = listener.accept().await.expect("accept a");
    let mut a = conns.admit(sa, peer_a).expect("a admitted");
    let _cb = tokio::net::TcpStream::connect(addr).await.expect("connect b");
    let (sb, peer_b) = listener.accept().await.expect("accept b");
    let _b = conns.admit(sb, peer_b).expect("b admitted");
    let mut buf = [0u8; 8];
    for attempt in 0..3 {
        let e = a.read(&mut buf).await.expect_err("evicted stream must fail");
        assert_eq!(e.kind(), std::io::ErrorKind::ConnectionAborted, "attempt {attempt}: {e}");
    }
    drop(a);
    assert_eq!(conns.open(), 1, "only b is registered");
}

#[tokio::test]
async fn tcp_server_at_its_connection_limit_closes_the_least_recently_active_for_a_new_one() {
    let bank = sample_bank();
    let limits = TcpLimits { max_connections: 2, idle_timeout: None, ..TcpLimits::default() };
    let (addr, _stop) = start_tcp_with(bank.clone(), limits).await;
    let mut a = tcp::connect_slave(addr, Slave(1)).await.expect("connect a");
    let mut b = tcp::connect_slave(addr, Slave(1)).await.expect("connect b");
    assert!(read_ok(&mut b).await);
    tokio::time::sleep(Duration::from_millis(20)).await;
    assert!(read_ok(&mut a).await, "a is now the most recently active");
    // A rebooted PLC's new connection: served, and b (silent longest) makes room.
    let mut c = tcp::connect_slave(addr, Slave(1)).await.expect("connect c beyond the limit");
    assert!(read_ok(&mut c).await, "the new connection is served, not refused");
    assert!(!read_ok(&mut b).await, "b, the least recently active, was closed");
    assert!(read_ok(&mut a).await, "a stays open");
    let n = bank.counters();
    assert_eq!((n.tcp_evicted, n.tcp_open), (1, 2), "{n:?}");
}

#[tokio::test]
async fn rtu_server_over_pty_pair() {
    let bank = sample_bank();
    let (server_end, client_end) = tokio_serial::SerialStream::pair().expect("pty pair");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(modbus::serve_rtu(server_end, bank.clone(), 5, async move {
        let _ = rx.await;
    }));
    let mut ctx = rtu::attach_slave(client_end, Slave(5));
    let ir = tokio::time::timeout(Duration::from_secs(2), ctx.read_input_registers(0, 24))
        .await
        .expect("rtu read timed out")
        .expect("transport")
        .expect("exception");
    assert_eq!(ir, bank.block().to_vec());
    let e = tokio::time::timeout(Duration::from_secs(2), ctx.write_single_register(3, 1)).await.expect("timeout");
    assert_eq!(e.expect("transport"), Err(ExceptionCode::IllegalDataAddress));
    // Another unit id on the bus: no reply at all.
    ctx.set_slave(Slave(9));
    let r = tokio::time::timeout(Duration::from_millis(300), ctx.read_input_registers(0, 1)).await;
    assert!(r.is_err(), "a request for unit 9 must be ignored by unit 5: {r:?}");
    let _ = tx.send(());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn daemon_rtu_server_role_and_missing_adapter() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 20, 64, 48, 30);
    // Adapter missing at start: the daemon runs anyway and keeps retrying.
    let mut cfg = support::test_config(dir.path());
    cfg.output.modbus.mode = ModbusMode::RtuServer;
    cfg.output.modbus.serial_device = "/dev/ttyFME-absent".into();
    cfg.output.modbus.reconnect_min_ms = 50;
    let src: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), true, true).expect("open"));
    let d = Daemon::start(cfg.clone(), String::new(), src, support::edge_pipeline(&cfg), RunOptions::default())
        .await
        .expect("start without the adapter");
    let hb = d.bank().block()[12];
    tokio::time::sleep(Duration::from_millis(400)).await;
    assert_ne!(d.bank().block()[12], hb, "running without the RS-485 adapter");
    d.shutdown().await;

    // With a device (one end of a pty pair; the PLC is on the other end).
    use tokio_serial::SerialPort as _;
    let (plc_end, box_end) = tokio_serial::SerialStream::pair().expect("pty pair");
    cfg.output.modbus.serial_device = box_end.name().expect("pty name");
    cfg.output.modbus.parity = fme::config::Parity::None;
    cfg.output.modbus.unit_id = 4;
    let src: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), true, true).expect("open"));
    let d = Daemon::start(cfg.clone(), String::new(), src, support::edge_pipeline(&cfg), RunOptions::default())
        .await
        .expect("start");
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut ctx = rtu::attach_slave(plc_end, Slave(4));
    let mut beats = Vec::new();
    for _ in 0..3 {
        let r = tokio::time::timeout(Duration::from_secs(2), ctx.read_input_registers(10, 3))
            .await
            .expect("rtu read timed out")
            .expect("transport")
            .expect("exception");
        assert_ne!(r[0] & StatusBits::RUNNING.bits(), 0);
        beats.push(r[2]);
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    assert!(beats.windows(2).all(|w| w[1] > w[0]), "heartbeat over RTU: {beats:?}");
    d.shutdown().await;
    drop(box_end);
}

/// The RTU server frames and checks requests itself too: the frame of upstream issue 298 (FC15,
/// quantity 16 with one data byte), which panics tokio-modbus's RTU decoder, gets exception 03,
/// and the server goes on serving.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rtu_server_answers_the_fc15_frame_that_panics_tokio_modbus_with_exception_03() {
    use fme::output::modbus_guard::crc16;
    use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
    use tokio_serial::SerialPort as _;
    let bank = sample_bank();
    let (mut plc, box_end) = tokio_serial::SerialStream::pair().expect("pty pair");
    let cfg = fme::config::ModbusConfig {
        mode: ModbusMode::RtuServer,
        serial_device: box_end.name().expect("pty name"),
        parity: fme::config::Parity::None,
        unit_id: 5,
        reconnect_min_ms: 50,
        reconnect_max_ms: 100,
        ..Default::default()
    };
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let role = tokio::spawn(modbus::run_rtu_server(cfg, bank.clone(), stop_rx));
    tokio::time::sleep(Duration::from_millis(200)).await;
    // Noise first, then the frame: the server resynchronises on the CRC.
    let mut frame = vec![5u8, 0x0f, 0x00, 0x00, 0x00, 0x10, 0x01, 0xff];
    frame.extend_from_slice(&crc16(&frame));
    plc.write_all(&[0xff, 0x00]).await.expect("write noise");
    tokio::time::sleep(Duration::from_millis(100)).await;
    plc.write_all(&frame).await.expect("write");
    let mut want = vec![5u8, 0x8f, 0x03];
    want.extend_from_slice(&crc16(&want));
    let mut got = vec![0u8; want.len()];
    tokio::time::timeout(Duration::from_secs(2), plc.read_exact(&mut got)).await.expect("answered").expect("read");
    assert_eq!(got, want, "exception 03 (illegal data value)");
    let mut ctx = rtu::attach_slave(plc, Slave(5));
    let r = tokio::time::timeout(Duration::from_secs(2), ctx.read_input_registers(12, 1)).await;
    assert!(matches!(r, Ok(Ok(Ok(ref v))) if *v == vec![42]), "still serving: {r:?}");
    assert_eq!(bank.counters().task_panics, 0);
    assert!(!role.is_finished(), "the role keeps running");
    let _ = stop_tx.send(true);
    drop(box_end);
}
