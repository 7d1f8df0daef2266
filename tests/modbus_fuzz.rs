//! Seeded Modbus TCP fuzz against the in-process server: 100,000 random and mutated frames (and
//! the 14-byte FC15 frame that panics tokio-modbus 0.17, upstream issue 298). Fails on any panic in
//! a connection task, on a connection dropped or an answer missing where an answer (normal or
//! exception) is due, on a wrong exception code, and on a wrong register value during or after the
//! run. The expected answer of every frame comes from an independent model of the register map
//! (README / docs/plc-integration.md), not from the server's code.

use fme::output::bank::RegisterBank;
use fme::output::modbus;
use fme::output::registers::{self, StatusBits, Update};
use fme::output::tcp_conns::TcpLimits;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio::net::TcpStream;

const FRAMES: usize = 100_000;
const SEED: u64 = 0x5EED_0033_F15C_0DE5;
const BATCH: usize = 64;

struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        // xorshift64*
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn byte(&mut self) -> u8 {
        (self.next() >> 32) as u8
    }
    /// Addresses and quantities biased to the edges of the map and of the protocol limits.
    fn word(&mut self) -> u16 {
        const EDGES: [u16; 16] = [0, 1, 2, 8, 23, 24, 25, 99, 100, 101, 103, 104, 123, 124, 125, 126];
        match self.below(4) {
            0 | 1 => EDGES[self.below(16) as usize],
            2 => self.below(300) as u16,
            _ => self.next() as u16,
        }
    }
}

/// The model's answer to a request PDU: `Ok` = a normal answer, `Err(code)` = exception `code`.
fn expected(pdu: &[u8]) -> Result<(), u8> {
    let fc = pdu[0];
    let w = |i: usize| u16::from_be_bytes([pdu[i], pdu[i + 1]]);
    match fc {
        1..=6 => {
            if pdu.len() != 5 {
                return Err(3);
            }
            let (a, n) = (u32::from(w(1)), u32::from(w(3)));
            match fc {
                1 | 2 if !(1..=2000).contains(&n) => Err(3),
                1 | 2 => {
                    if a == 0 && n == 1 {
                        Ok(())
                    } else {
                        Err(2)
                    }
                }
                3 | 4 if !(1..=125).contains(&n) => Err(3),
                3 | 4 => {
                    if a + n <= 24 || (fc == 3 && a >= 100 && a + n <= 104) {
                        Ok(())
                    } else {
                        Err(2)
                    }
                }
                5 if n != 0 && n != 0xFF00 => Err(3),
                5 => Err(2), // the coil is read-only
                _ => {
                    if (100..=103).contains(&a) {
                        Ok(())
                    } else {
                        Err(2)
                    }
                }
            }
        }
        15 | 16 => {
            if pdu.len() < 6 {
                return Err(3);
            }
            let (a, n, count) = (u32::from(w(1)), u32::from(w(3)), usize::from(pdu[5]));
            if pdu.len() - 6 != count {
                return Err(3);
            }
            if fc == 15 {
                if !(1..=1968).contains(&n) || count != n.div_ceil(8) as usize { Err(3) } else { Err(2) }
            } else if !(1..=123).contains(&n) || count != 2 * n as usize {
                Err(3)
            } else if a >= 100 && a + n <= 104 {
                Ok(())
            } else {
                Err(2)
            }
        }
        _ => Err(1),
    }
}

/// A well-formed request of a supported function code (random addresses and quantities).
fn template(r: &mut Rng) -> Vec<u8> {
    let fc = [1u8, 2, 3, 4, 5, 6, 15, 16][r.below(8) as usize];
    let (a, n) = match r.below(3) {
        // Inside the map, so that normal answers (and real writes to HR 100-103) are frequent.
        0 if fc == 3 || fc == 6 || fc == 16 => {
            let a = 100 + r.below(4) as u16;
            (a, 1 + r.below(u64::from(104 - a)) as u16)
        }
        0 => {
            let a = r.below(24) as u16;
            (a, 1 + r.below(u64::from(24 - a)) as u16)
        }
        _ => (r.word(), r.word()),
    };
    let mut p = vec![fc];
    p.extend_from_slice(&a.to_be_bytes());
    match fc {
        5 => p.extend_from_slice(&[if r.below(2) == 0 { 0xFF } else { 0 }, 0]),
        15 | 16 => {
            let n = n % 130;
            let count = if fc == 15 { usize::from(n).div_ceil(8) } else { 2 * usize::from(n) };
            p.extend_from_slice(&n.to_be_bytes());
            p.push(count.min(250) as u8);
            p.extend((0..count.min(247)).map(|_| r.byte()));
        }
        _ => p.extend_from_slice(&n.to_be_bytes()),
    }
    p
}

fn mutate(r: &mut Rng, mut p: Vec<u8>) -> Vec<u8> {
    for _ in 0..=r.below(3) {
        match r.below(4) {
            0 => {
                let i = r.below(p.len() as u64) as usize;
                p[i] = r.byte();
            }
            1 if p.len() > 1 => p.truncate(1 + r.below(p.len() as u64 - 1) as usize),
            2 => p.extend((0..=r.below(8)).map(|_| r.byte())),
            _ => {
                // The FC15/FC16 quantity / byte-count pair made inconsistent (issue 298's shape).
                if p.len() >= 6 {
                    let q = r.word();
                    p[3..5].copy_from_slice(&q.to_be_bytes());
                }
            }
        }
    }
    p.truncate(253);
    p
}

fn adu(tid: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut f = Vec::with_capacity(pdu.len() + 7);
    f.extend_from_slice(&tid.to_be_bytes());
    f.extend_from_slice(&[0, 0]);
    f.extend_from_slice(&(pdu.len() as u16 + 1).to_be_bytes());
    f.push(unit);
    f.extend_from_slice(pdu);
    f
}

enum Case {
    /// A framed request and its expected answer.
    Request(Vec<u8>),
    /// Bytes that cannot be framed: the server must close the connection.
    Unframeable(Vec<u8>),
}

fn case(r: &mut Rng, i: usize) -> Case {
    if i % 5000 == 17 {
        // The frame of upstream issue 298, verbatim.
        return Case::Request(vec![0x0f, 0x00, 0x00, 0x00, 0x10, 0x01, 0xff]);
    }
    match r.below(100) {
        0 => {
            let (proto, len) = match r.below(3) {
                0 => (1 + r.below(0xFFFF) as u16, 6),
                1 => (0, r.below(2) as u16),
                _ => (0, 255 + r.below(1000) as u16),
            };
            let mut f = vec![0, 1];
            f.extend_from_slice(&proto.to_be_bytes());
            f.extend_from_slice(&len.to_be_bytes());
            f.push(1);
            Case::Unframeable(f)
        }
        1..=40 => Case::Request(template(r)),
        41..=75 => {
            let t = template(r);
            Case::Request(mutate(r, t))
        }
        _ => {
            let span = if r.below(4) == 0 { 253 } else { 12 };
            let len = 1 + r.below(span) as usize;
            let mut p: Vec<u8> = (0..len).map(|_| r.byte()).collect();
            if r.below(2) == 0 {
                p[0] = [1u8, 2, 3, 4, 5, 6, 15, 16, 0x17, 0x2b, 0x80, 0x8f][r.below(12) as usize];
            }
            Case::Request(p)
        }
    }
}

/// Reads one answer ADU within 5 s; `None` when the connection was dropped or went silent.
async fn read_answer(s: &mut TcpStream) -> Option<(u16, u8, Vec<u8>)> {
    let read = async {
        let mut h = [0u8; 7];
        s.read_exact(&mut h).await.ok()?;
        let len = usize::from(u16::from_be_bytes([h[4], h[5]]));
        if u16::from_be_bytes([h[2], h[3]]) != 0 || !(2..=254).contains(&len) {
            return None;
        }
        let mut pdu = vec![0u8; len - 1];
        s.read_exact(&mut pdu).await.ok()?;
        Some((u16::from_be_bytes([h[0], h[1]]), h[6], pdu))
    };
    tokio::time::timeout(Duration::from_secs(5), read).await.ok().flatten()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fuzzed_frames_get_the_right_answers_and_never_panic() {
    let bank = Arc::new(RegisterBank::new());
    let inp = Update {
        mean_mps: 0.125,
        fish: 12,
        status: StatusBits::RUNNING | StatusBits::CAMERA_OK,
        heartbeat: 42,
        feeding: true,
        ..Default::default()
    };
    let block = registers::encode(&inp, fme::config::WordOrder::HighFirst);
    bank.publish(block);
    let (listener, addr) = modbus::bind_tcp("127.0.0.1:0").await.expect("bind");
    let (_stop, rx) = tokio::sync::oneshot::channel::<()>();
    let limits = TcpLimits { idle_timeout: Some(Duration::from_secs(30)), ..TcpLimits::default() };
    tokio::spawn(modbus::serve_tcp(listener, bank.clone(), limits, async move {
        let _ = rx.await;
    }));

    let mut r = Rng(SEED);
    let mut model = [0u16; 4];
    let mut conn = TcpStream::connect(addr).await.expect("connect");
    let (mut tid, mut sent, mut unframeable, mut exceptions) = (0u16, 0usize, 0u64, 0u64);
    let (mut requests, mut writes) = (0u64, 0u64);
    let mut batch: Vec<Vec<u8>> = Vec::with_capacity(BATCH);
    let mut bytes = Vec::new();
    while sent < FRAMES {
        batch.clear();
        bytes.clear();
        let mut closing = None;
        while batch.len() < BATCH && sent < FRAMES {
            sent += 1;
            match case(&mut r, sent) {
                Case::Request(pdu) => {
                    tid = tid.wrapping_add(1);
                    bytes.extend_from_slice(&adu(tid, (tid % 256) as u8, &pdu));
                    batch.push(pdu);
                }
                Case::Unframeable(f) => {
                    closing = Some(f);
                    break;
                }
            }
        }
        conn.write_all(&bytes).await.expect("write batch");
        let first_tid = tid.wrapping_sub(batch.len() as u16);
        for (k, pdu) in batch.iter().enumerate() {
            let want_tid = first_tid.wrapping_add(k as u16 + 1);
            requests += 1;
            let Some((got_tid, unit, ans)) = read_answer(&mut conn).await else {
                panic!("frame {} (pdu {pdu:02x?}): connection dropped or silent where an answer is due", sent);
            };
            assert_eq!((got_tid, unit), (want_tid, (want_tid % 256) as u8), "MBAP echo for {pdu:02x?}");
            match expected(pdu) {
                Ok(()) => {
                    assert_eq!(ans.first(), Some(&pdu[0]), "normal answer expected to {pdu:02x?}, got {ans:02x?}");
                    let w = |i: usize| u16::from_be_bytes([pdu[i], pdu[i + 1]]);
                    match pdu[0] {
                        3 | 4 => {
                            let (a, n) = (usize::from(w(1)), usize::from(w(3)));
                            let want: Vec<u16> =
                                if a >= 100 { model[a - 100..a - 100 + n].to_vec() } else { block[a..a + n].to_vec() };
                            let got: Vec<u16> =
                                ans[2..].chunks_exact(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect();
                            assert_eq!((ans[1] as usize, got), (2 * n, want), "register values for {pdu:02x?}");
                        }
                        6 => {
                            writes += 1;
                            model[usize::from(w(1)) - 100] = w(3);
                            assert_eq!(ans, pdu.clone(), "FC06 echo");
                        }
                        16 => {
                            writes += 1;
                            let a = usize::from(w(1)) - 100;
                            for (j, c) in pdu[6..].chunks_exact(2).enumerate() {
                                model[a + j] = u16::from_be_bytes([c[0], c[1]]);
                            }
                            assert_eq!(ans, pdu[..5].to_vec(), "FC16 answer");
                        }
                        _ => assert_eq!(ans, vec![pdu[0], 1, 1], "FC01/02: the feeding bit is set"),
                    }
                }
                Err(code) => {
                    exceptions += 1;
                    assert_eq!(ans, vec![pdu[0] | 0x80, code], "exception {code:02x} expected to {pdu:02x?}");
                }
            }
        }
        if let Some(f) = closing {
            unframeable += 1;
            conn.write_all(&f).await.expect("write unframeable header");
            let mut one = [0u8; 1];
            let closed = tokio::time::timeout(Duration::from_secs(5), conn.read(&mut one)).await;
            assert!(matches!(closed, Ok(Ok(0)) | Ok(Err(_))), "an unframeable header must close: {closed:?}");
            conn = TcpStream::connect(addr).await.expect("reconnect");
        }
    }
    let c = bank.counters();
    assert_eq!(c.task_panics, 0, "no connection task may panic");
    assert_eq!(c.tcp_bad_frames, unframeable);
    assert_eq!(c.exceptions, exceptions, "the server's exception count agrees with the model's");
    assert_eq!(bank.writable(), model, "HR 100-103 hold exactly what the answered writes wrote");
    assert_eq!(bank.block(), block, "the published block is untouched");
    let normal = requests - exceptions;
    eprintln!(
        "fuzz: {FRAMES} frames, {normal} normal answers ({writes} writes), {exceptions} exceptions, {unframeable} unframeable headers, seed {SEED:#x}"
    );
    assert!(
        exceptions > 10_000 && normal > 5000 && writes > 1000 && unframeable > 100,
        "the mix covers answers, writes, exceptions and unframeable headers"
    );
}

/// The same model over RTU (a pty pair): 5,000 CRC-correct frames to our unit, to the broadcast
/// address (carried out, never answered) and to other units (ignored). Each answer must be exactly
/// the model's; a stray or missing answer shifts the byte stream and fails the next comparison.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fuzzed_rtu_frames_get_the_right_answers() {
    use fme::output::modbus_guard::crc16;
    const RTU_FRAMES: usize = 5000;
    const UNIT: u8 = 5;
    let bank = Arc::new(RegisterBank::new());
    let block = registers::encode(
        &Update { fish: 3, feeding: true, heartbeat: 9, ..Default::default() },
        fme::config::WordOrder::HighFirst,
    );
    bank.publish(block);
    let (mut plc, box_end) = tokio_serial::SerialStream::pair().expect("pty pair");
    let (stop, rx) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(modbus::serve_rtu(box_end, bank.clone(), UNIT, async move {
        let _ = rx.await;
    }));
    let mut r = Rng(SEED ^ 0x52_54_55);
    let mut model = [0u16; 4];
    let (mut sent, mut answered, mut silent, mut exceptions) = (0, 0, 0, 0u64);
    while sent < RTU_FRAMES {
        let Case::Request(pdu) = case(&mut r, sent + 1) else { continue };
        // Only frames whose length is the one their function code implies (the framing rule);
        // unknown function codes (answered after the silence) only now and then.
        let framed = match pdu[0] {
            1..=6 => pdu.len() == 5,
            15 | 16 => pdu.len() >= 6 && pdu.len() == 6 + usize::from(pdu[5]),
            _ => r.below(100) == 0,
        };
        if !framed {
            continue;
        }
        sent += 1;
        let unit = match r.below(10) {
            0 => 0,
            1 => 1 + r.below(247) as u8,
            _ => UNIT,
        };
        let mut adu = vec![unit];
        adu.extend_from_slice(&pdu);
        adu.extend_from_slice(&crc16(&adu));
        plc.write_all(&adu).await.expect("write");
        let outcome = if unit == 0 || unit == UNIT { Some(expected(&pdu)) } else { None };
        // The model: what the server must have done, and (our unit only) what it must answer.
        let w = |i: usize| u16::from_be_bytes([pdu[i], pdu[i + 1]]);
        let mut want = vec![UNIT];
        match outcome {
            Some(Ok(())) => match pdu[0] {
                3 | 4 => {
                    let (a, n) = (usize::from(w(1)), usize::from(w(3)));
                    let regs = if a >= 100 { model[a - 100..a - 100 + n].to_vec() } else { block[a..a + n].to_vec() };
                    want.extend_from_slice(&[pdu[0], (2 * n) as u8]);
                    regs.iter().for_each(|v| want.extend_from_slice(&v.to_be_bytes()));
                }
                6 => {
                    model[usize::from(w(1)) - 100] = w(3);
                    want.extend_from_slice(&pdu);
                }
                16 => {
                    let a = usize::from(w(1)) - 100;
                    for (j, c) in pdu[6..].chunks_exact(2).enumerate() {
                        model[a + j] = u16::from_be_bytes([c[0], c[1]]);
                    }
                    want.extend_from_slice(&pdu[..5]);
                }
                _ => want.extend_from_slice(&[pdu[0], 1, 1]),
            },
            Some(Err(code)) => {
                exceptions += 1;
                want.extend_from_slice(&[pdu[0] | 0x80, code]);
            }
            None => {}
        }
        if unit != UNIT {
            silent += 1;
            continue;
        }
        answered += 1;
        let crc = crc16(&want);
        want.extend_from_slice(&crc);
        let mut got = vec![0u8; want.len()];
        let read = tokio::time::timeout(Duration::from_secs(2), plc.read_exact(&mut got)).await;
        assert!(matches!(read, Ok(Ok(_))), "frame {sent} ({adu:02x?}): no answer where one is due");
        assert_eq!(got, want, "frame {sent} ({adu:02x?})");
    }
    // Nothing stray after the last frame.
    let mut extra = [0u8; 16];
    let tail = tokio::time::timeout(Duration::from_millis(200), plc.read(&mut extra)).await;
    assert!(tail.is_err(), "no answer may follow: {tail:?}");
    assert_eq!(bank.writable(), model, "HR 100-103 hold what the unit's and the broadcast writes wrote");
    assert_eq!(bank.counters().task_panics, 0);
    eprintln!(
        "rtu fuzz: {RTU_FRAMES} frames, {answered} answered ({exceptions} exceptions), {silent} broadcast or other units"
    );
    assert!(answered > 3000 && silent > 500 && exceptions > 1000, "the mix covers every case");
    let _ = stop.send(());
}
