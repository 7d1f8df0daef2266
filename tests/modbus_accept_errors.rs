//! The Modbus TCP server survives failed accepts: with the process out of file descriptors
//! (EMFILE) it pauses and resumes accepting instead of stopping for good, as tokio-modbus's own
//! accept loop does. Its own test binary: it lowers this process's RLIMIT_NOFILE.

use fme::output::bank::RegisterBank;
use fme::output::modbus;
use fme::output::tcp_conns::TcpLimits;
use std::sync::Arc;
use std::time::Duration;
use tokio_modbus::prelude::*;

/// The lowest free descriptor number: with RLIMIT_NOFILE set to it, no new descriptor can be made.
fn lowest_free_fd() -> u64 {
    use std::os::fd::AsRawFd as _;
    let probe = std::fs::File::open("/dev/null").expect("open /dev/null");
    probe.as_raw_fd() as u64
}

fn set_nofile(soft: u64) -> libc::rlimit {
    let mut old = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: plain libc calls on a valid, local rlimit struct.
    unsafe {
        assert_eq!(libc::getrlimit(libc::RLIMIT_NOFILE, &mut old), 0, "getrlimit");
        let new = libc::rlimit { rlim_cur: soft, rlim_max: old.rlim_max };
        assert_eq!(libc::setrlimit(libc::RLIMIT_NOFILE, &new), 0, "setrlimit");
    }
    old
}

#[tokio::test(flavor = "current_thread")]
async fn tcp_server_keeps_accepting_after_running_out_of_file_descriptors() {
    let bank = Arc::new(RegisterBank::new());
    let (listener, addr) = modbus::bind_tcp("127.0.0.1:0").await.expect("bind");
    let (_stop, rx) = tokio::sync::oneshot::channel::<()>();
    let limits = TcpLimits { max_connections: 64, max_per_peer: 64, idle_timeout: None, ..TcpLimits::default() };
    tokio::spawn(modbus::serve_tcp(listener, bank.clone(), limits, async move {
        let _ = rx.await;
    }));

    // Client sockets made first; then not one descriptor left, so the server's accept fails.
    let sockets: Vec<_> = (0..4).map(|_| tokio::net::TcpSocket::new_v4().expect("socket")).collect();
    let old = set_nofile(lowest_free_fd());
    let mut clients = Vec::new();
    for s in sockets {
        if let Ok(Ok(c)) = tokio::time::timeout(Duration::from_secs(1), s.connect(addr)).await {
            clients.push(c);
        }
    }
    let deadline = tokio::time::Instant::now() + Duration::from_secs(5);
    while bank.counters().tcp_accept_errors == 0 && tokio::time::Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let errors = bank.counters().tcp_accept_errors;
    drop(clients);
    let _ = set_nofile(old.rlim_cur);
    assert!(errors > 0, "the descriptor limit never made an accept fail; the test proves nothing");

    // Descriptors free again: a PLC connects and is served (within the longest pause, 5 s).
    let mut served = false;
    for _ in 0..40 {
        if let Ok(Ok(mut ctx)) = tokio::time::timeout(Duration::from_secs(1), tcp::connect_slave(addr, Slave(1))).await
            && let Ok(Ok(Ok(_))) = tokio::time::timeout(Duration::from_secs(1), ctx.read_input_registers(0, 4)).await
        {
            served = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    assert!(served, "the server stopped accepting after running out of descriptors");
}
