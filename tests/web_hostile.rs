//! The web page on a hostile LAN with the PLC polling beside it (docs/web.md, "A hostile LAN"): with
//! the shipped `[web]` limits, 500 connections held open from 50 addresses, slowloris from four
//! addresses, 10 KB heads and garbage requests against the web port, while a Modbus TCP client polls
//! the registers the page reads (one register bank, one runtime, as in `fme run`). The page's
//! `GET /api/status` and every Modbus poll keep answering. The durations of both, quiet and under
//! attack, are printed (not asserted: the figures in docs/web.md come from this output).

#[path = "common/web_lan.rs"]
mod web_lan;

use fme::output::modbus;
use fme::output::tcp_conns::TcpLimits;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tokio_modbus::prelude::*;
use web_lan::{connect_from, get_code, repeat, slowloris, start};

const ROUNDS: usize = 20;

/// Milliseconds of each sample: (median, max).
fn spread(mut ms: Vec<f64>) -> (f64, f64) {
    ms.sort_by(f64::total_cmp);
    (ms[ms.len() / 2], ms[ms.len() - 1])
}

/// `ROUNDS` page requests and Modbus polls, alternating 100 ms apart: how many of each succeeded
/// and their durations in ms.
async fn sample(web: SocketAddr, plc: &mut tokio_modbus::client::Context) -> (usize, usize, Vec<f64>, Vec<f64>) {
    let (mut pages, mut polls, mut page_ms, mut poll_ms) = (0, 0, Vec::new(), Vec::new());
    for _ in 0..ROUNDS {
        let t = Instant::now();
        pages += usize::from(get_code(web, "/api/status").await == 200);
        page_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let poll = tokio::time::timeout(Duration::from_secs(2), plc.read_input_registers(12, 1)).await;
        polls += usize::from(matches!(poll, Ok(Ok(Ok(v))) if v == [42]));
        poll_ms.push(t.elapsed().as_secs_f64() * 1e3);
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    (pages, polls, page_ms, poll_ms)
}

/// The attack on `addr` until `stop`; the connections it holds open.
async fn attack(
    addr: SocketAddr,
    stop: &Arc<AtomicBool>,
) -> (Vec<tokio::net::TcpStream>, Vec<tokio::task::JoinHandle<()>>) {
    let mut tasks = Vec::new();
    for host in ["127.0.0.2", "127.0.0.3", "127.0.0.4", "127.0.0.5"] {
        for _ in 0..8 {
            tasks.push(tokio::spawn(slowloris(host, addr, "/api/status", stop.clone())));
        }
    }
    let mut huge = b"GET /api/status HTTP/1.1\r\nX-Filler: ".to_vec();
    huge.resize(10 * 1024, b'a');
    huge.extend_from_slice(b"\r\n\r\n");
    let garbage = b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\xff\r\n\r\nGET\r\n\r\n".to_vec();
    for _ in 0..4 {
        tasks.push(tokio::spawn(repeat("127.0.0.6", addr, huge.clone(), stop.clone())));
        tasks.push(tokio::spawn(repeat("127.0.0.7", addr, garbage.clone(), stop.clone())));
    }
    let mut held = Vec::new();
    for i in 0..500 {
        let from: &'static str = Box::leak(format!("127.0.1.{}", 1 + i % 50).into_boxed_str());
        if let Some(s) = connect_from(from, addr).await {
            held.push(s);
        }
    }
    (held, tasks)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_and_the_plc_answer_through_a_hostile_lan() {
    let f = start(|_| {}).await.expect("the web page serves");
    let mut blk = f.bank.block();
    blk[12] = 42;
    f.bank.publish(blk);
    let (listener, modbus_addr) = modbus::bind_tcp("127.0.0.1:0").await.expect("bind Modbus");
    let (stop_modbus, stopped) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(modbus::serve_tcp(listener, f.bank.clone(), TcpLimits::default(), async move {
        let _ = stopped.await;
    }));
    let mut plc = tcp::connect_slave(modbus_addr, Slave(1)).await.expect("the PLC connects");

    let (q_pages, q_polls, q_page_ms, q_poll_ms) = sample(f.addr, &mut plc).await;
    assert_eq!((q_pages, q_polls), (ROUNDS, ROUNDS), "quiet");

    let stop = Arc::new(AtomicBool::new(false));
    let (held, tasks) = attack(f.addr, &stop).await;
    tokio::time::sleep(Duration::from_millis(300)).await; // every slot the attackers can get, taken
    let (pages, polls, page_ms, poll_ms) = sample(f.addr, &mut plc).await;
    stop.store(true, Ordering::Relaxed);
    let made = held.len();
    // The flood really met the limits: every held connection was closed or answered by the server
    // (refused at accept, or 408 at the head timeout), none is still waiting.
    let mut b = [0u8; 64];
    let waiting = held
        .iter()
        .filter(|s| matches!(s.try_read(&mut b), Err(e) if e.kind() == std::io::ErrorKind::WouldBlock))
        .count();
    drop(held);
    for t in tasks {
        let _ = tokio::time::timeout(Duration::from_secs(3), t).await;
    }
    let (q_page, q_poll, page, poll) = (spread(q_page_ms), spread(q_poll_ms), spread(page_ms), spread(poll_ms));
    eprintln!(
        "web+modbus hostile LAN, {ROUNDS} rounds each (median / max ms):\n  \
         quiet:  GET /api/status {:.2} / {:.2}, Modbus poll {:.2} / {:.2}\n  \
         attack: GET /api/status {:.2} / {:.2} ({pages} of {ROUNDS} answered), Modbus poll {:.2} / {:.2} \
         ({polls} of {ROUNDS}); {made} of 500 connections made, {waiting} still open",
        q_page.0, q_page.1, q_poll.0, q_poll.1, page.0, page.1, poll.0, poll.1
    );
    assert_eq!(polls, ROUNDS, "every Modbus poll answered under the attack");
    assert!(made >= 450 && waiting == 0, "the flood: {made} made, {waiting} left waiting");
    assert!(pages >= ROUNDS - 1, "{pages} of {ROUNDS} page requests answered under the attack");
    assert_eq!(get_code(f.addr, "/api/status").await, 200, "after the attack");
    let _ = stop_modbus.send(());
    f.server.stop().await;
}
