//! The Modbus TCP server on a hostile LAN: a PLC polling every second keeps every poll while 20
//! idle connections a second are opened against it, and a PLC polling steadily keeps every poll
//! while clients from four addresses open polling connections every 100 ms; connections that never
//! had a request answered are closed before a working one; the allow list closes other addresses at
//! accept; a peer trickling bytes that never complete a request is closed at the idle timeout.

use fme::config::allow::AllowList;
use fme::output::bank::RegisterBank;
use fme::output::modbus;
use fme::output::tcp_conns::TcpLimits;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio::net::{TcpSocket, TcpStream};
use tokio_modbus::prelude::*;

async fn start(limits: TcpLimits) -> (Arc<RegisterBank>, SocketAddr, tokio::sync::oneshot::Sender<()>) {
    let bank = Arc::new(RegisterBank::new());
    let mut blk = bank.block();
    blk[12] = 42;
    bank.publish(blk);
    let (listener, addr) = modbus::bind_tcp("127.0.0.1:0").await.expect("bind");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(modbus::serve_tcp(listener, bank.clone(), limits, async move {
        let _ = rx.await;
    }));
    (bank, addr, tx)
}

/// A TCP connection from a chosen loopback address (127.0.0.0/8 is all local on Linux).
async fn connect_from(from: &str, to: SocketAddr) -> TcpStream {
    let s = TcpSocket::new_v4().expect("socket");
    s.bind(format!("{from}:0").parse().expect("addr")).expect("bind source address");
    s.connect(to).await.expect("connect")
}

async fn poll_ok(ctx: &mut tokio_modbus::client::Context) -> bool {
    matches!(
        tokio::time::timeout(Duration::from_secs(2), ctx.read_input_registers(12, 1)).await,
        Ok(Ok(Ok(v))) if v == [42]
    )
}

/// Whether the server closed `s` (EOF or reset) within 3 s.
async fn closed(s: &mut TcpStream) -> bool {
    let mut b = [0u8; 16];
    matches!(tokio::time::timeout(Duration::from_secs(3), s.read(&mut b)).await, Ok(Ok(0)) | Ok(Err(_)))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_polling_plc_survives_20_idle_connections_a_second() {
    let (bank, addr, _stop) = start(TcpLimits::default()).await;
    let mut plc = tcp::connect_slave(addr, Slave(1)).await.expect("plc connects");
    // The attacker: 20 connections a second that never send anything, half from the PLC's own
    // address, half from another; all kept open.
    let attacker = tokio::spawn(async move {
        let mut held = Vec::new();
        for i in 0..100 {
            let from = if i % 2 == 0 { "127.0.0.1" } else { "127.0.0.2" };
            held.push(connect_from(from, addr).await);
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        held
    });
    let mut failed = 0;
    for _ in 0..5 {
        if !poll_ok(&mut plc).await {
            failed += 1;
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
    let held = attacker.await.expect("attacker");
    assert!(poll_ok(&mut plc).await, "still served after the flood");
    let c = bank.counters();
    eprintln!(
        "churn: 5 polls 1 s apart, {failed} failed; 100 idle connections opened, {} evicted, {} open",
        c.tcp_evicted, c.tcp_open
    );
    assert_eq!(failed, 0, "no PLC poll may fail: {c:?}");
    assert!(c.tcp_evicted >= 90, "the flood was evicted, not the PLC: {c:?}");
    assert!(c.tcp_open <= 8, "{c:?}");
    drop(held);
}

/// One busy host: every 100 ms a new connection that polls every 20 ms until the server closes it;
/// at most 4 open at once (the oldest is dropped for a new one).
async fn busy_host(from: &'static str, addr: SocketAddr, stop: tokio::sync::watch::Receiver<bool>) {
    let mut open: std::collections::VecDeque<tokio::task::JoinHandle<()>> = std::collections::VecDeque::new();
    while !*stop.borrow() {
        if open.len() >= 4
            && let Some(oldest) = open.pop_front()
        {
            oldest.abort();
        }
        let s = connect_from(from, addr).await;
        let mut stop = stop.clone();
        open.push_back(tokio::spawn(async move {
            let mut ctx = tcp::attach_slave(s, Slave(1));
            while !*stop.borrow() && poll_ok(&mut ctx).await {
                tokio::select! {
                    _ = tokio::time::sleep(Duration::from_millis(20)) => {},
                    _ = stop.changed() => {},
                }
            }
        }));
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    for t in open {
        t.abort();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_steadily_polling_plc_keeps_its_slot_against_busy_clients_from_four_addresses() {
    let limits = TcpLimits { priority_after: Some(Duration::from_millis(600)), ..TcpLimits::default() };
    let (bank, addr, _stop) = start(limits).await;
    // The PLC (127.0.0.1) polls every 200 ms; like a real PLC it reconnects after a lost poll.
    let mut plc = tcp::connect_slave(addr, Slave(1)).await.expect("plc connects");
    for _ in 0..5 {
        assert!(poll_ok(&mut plc).await, "polls before the crowd");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let hosts: Vec<_> = ["127.0.0.2", "127.0.0.3", "127.0.0.4", "127.0.0.5"]
        .into_iter()
        .map(|h| tokio::spawn(busy_host(h, addr, stop_rx.clone())))
        .collect();
    // No pause here: a gap in the PLC's polls longer than `priority_after` would end its priority.
    // 40 connections a second fill the 7 other slots within the first poll or two.
    let mut lost = 0;
    for _ in 0..20 {
        if !poll_ok(&mut plc).await {
            lost += 1;
            if let Ok(Ok(c)) = tokio::time::timeout(Duration::from_secs(2), tcp::connect_slave(addr, Slave(1))).await {
                plc = c;
            }
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let _ = stop_tx.send(true);
    for h in hosts {
        let _ = h.await;
    }
    let c = bank.counters();
    eprintln!(
        "crowd: 20 PLC polls 200 ms apart, {lost} lost; busy clients: {} requests, {} evicted, {} refused",
        c.requests, c.tcp_evicted, c.tcp_refused
    );
    assert_eq!(lost, 0, "no PLC poll may be lost: {c:?}");
    assert!(c.requests > 200, "the busy clients really polled: {c:?}");
    assert!(c.tcp_evicted + c.tcp_refused > 20, "the server really was full: {c:?}");
}

#[tokio::test]
async fn connections_without_an_answered_request_are_closed_first() {
    let limits = TcpLimits { max_connections: 2, max_per_peer: 2, idle_timeout: None, ..TcpLimits::default() };
    let (bank, addr, _stop) = start(limits).await;
    let mut plc = tcp::connect_slave(addr, Slave(1)).await.expect("plc");
    assert!(poll_ok(&mut plc).await);
    tokio::time::sleep(Duration::from_millis(50)).await;
    // Newer than the PLC's last poll, but never asked anything.
    let mut silent = TcpStream::connect(addr).await.expect("silent");
    tokio::time::sleep(Duration::from_millis(50)).await;
    let mut newcomer = tcp::connect_slave(addr, Slave(1)).await.expect("newcomer");
    assert!(poll_ok(&mut newcomer).await);
    assert!(closed(&mut silent).await, "the connection that never sent a request goes first");
    assert!(poll_ok(&mut plc).await, "the PLC (least recently active, but answered) stays");
    assert_eq!(bank.counters().tcp_evicted, 1);
}

#[tokio::test]
async fn one_address_cannot_take_every_slot() {
    let limits = TcpLimits { max_connections: 8, max_per_peer: 2, idle_timeout: None, ..TcpLimits::default() };
    let (bank, addr, _stop) = start(limits).await;
    let mut plc = tcp::connect_slave(addr, Slave(1)).await.expect("plc");
    assert!(poll_ok(&mut plc).await);
    // Another host opens connections that do send requests: it only ever evicts its own.
    let mut others = Vec::new();
    for _ in 0..6 {
        let s = connect_from("127.0.0.3", addr).await;
        let mut ctx = tcp::attach_slave(s, Slave(1));
        assert!(poll_ok(&mut ctx).await);
        others.push(ctx);
    }
    assert!(poll_ok(&mut plc).await, "the PLC keeps its connection");
    let c = bank.counters();
    assert_eq!((c.tcp_evicted, c.tcp_open), (4, 3), "two from 127.0.0.3 plus the PLC: {c:?}");
}

#[tokio::test]
async fn addresses_outside_the_allow_list_are_closed_at_accept() {
    let allow = AllowList::parse(&["127.0.0.1/32".into()]).expect("valid");
    let (bank, addr, _stop) = start(TcpLimits { allow, ..TcpLimits::default() }).await;
    let mut stranger = connect_from("127.0.0.2", addr).await;
    let _ = stranger.write_all(&[0, 1, 0, 0, 0, 6, 1, 4, 0, 12, 0, 1]).await;
    assert!(closed(&mut stranger).await, "127.0.0.2 is not allowed");
    let mut plc = tcp::connect_slave(addr, Slave(1)).await.expect("plc");
    assert!(poll_ok(&mut plc).await, "127.0.0.1 is");
    let c = bank.counters();
    assert_eq!((c.tcp_refused, c.requests), (1, 1), "{c:?}");
}

#[tokio::test]
async fn trickled_bytes_do_not_keep_a_connection_open() {
    let limits = TcpLimits { idle_timeout: Some(Duration::from_secs(1)), ..TcpLimits::default() };
    let (bank, addr, _stop) = start(limits).await;
    let mut trickle = TcpStream::connect(addr).await.expect("connect");
    // A valid header announcing a long PDU, then one byte every 200 ms: never a complete request.
    trickle.write_all(&[0, 1, 0, 0, 0, 200, 1]).await.expect("header");
    let mut closed_after = None;
    for i in 0..20 {
        tokio::time::sleep(Duration::from_millis(200)).await;
        if trickle.write_all(&[3]).await.is_err() {
            closed_after = Some(i);
            break;
        }
        let mut b = [0u8; 4];
        if let Ok(Ok(0) | Err(_)) = tokio::time::timeout(Duration::from_millis(1), trickle.read(&mut b)).await {
            closed_after = Some(i);
            break;
        }
    }
    assert!(closed_after.is_some(), "a connection trickling bytes for 4 s must be closed (idle timeout 1 s)");
    assert_eq!(bank.counters().tcp_idle_closed, 1);
}
