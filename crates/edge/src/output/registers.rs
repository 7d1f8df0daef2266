//! The Modbus register map: a stable contract for PLC programmers (docs/plc-integration.md).
//!
//! 0-based PDU addresses. float32 and uint32 use two registers; the word order is configurable
//! (default high word first). Input registers 0..[`BLOCK_LEN`] hold the block below; holding registers
//! 0..[`BLOCK_LEN`] mirror them read-only; holding registers [`HR_WRITABLE_START`].. are writable by
//! the PLC. Coil 0 / discrete input 0 = feeding recommended.
//!
//! | reg | content |
//! |---|---|
//! | 0-1 | activity mean, m/s (float32; NaN when unavailable) |
//! | 2-3 | activity mean, body lengths/s (float32) |
//! | 4-5 | smoothed activity, m/s (float32) |
//! | 6-7 | half-width of the 95% interval, m/s (float32) |
//! | 8 | fish count |
//! | 9 | activity mean, mm/s (uint16, saturating; 65535 = unavailable) |
//! | 10 | status bits ([`StatusBits`]) |
//! | 11 | fault code ([`FaultCode`]) |
//! | 12 | heartbeat (increments every update, wraps) |
//! | 13-14 | uptime, s (uint32) |
//! | 15 | camera frames/s x10 |
//! | 16 | dropped frames: queue drops + driver sequence gaps (wrapping) |
//! | 17 | feeding recommended (0/1) |
//! | 18 | version major |
//! | 19 | version minor |
//! | 20 | detector runs/s x10 |
//! | 21 | depth runs/s x10 |
//! | 22 | age of the activity value, 0.1 s (saturating) |
//! | 23 | last feeding acknowledge written by the PLC (echo of HR 100) |

use crate::config::WordOrder;

/// Registers in the block.
pub const BLOCK_LEN: usize = 24;
/// First holding register writable by the PLC.
pub const HR_WRITABLE_START: u16 = 100;
/// Number of writable holding registers.
pub const HR_WRITABLE_LEN: usize = 4;
/// HR 100: feeding acknowledge (the PLC writes 1 when it acted on "feeding recommended", 0 otherwise).
pub const HR_FEEDING_ACK: u16 = 100;
/// HR 101: PLC heartbeat (the PLC increments it; shown on the console so a technician sees the link).
pub const HR_PLC_HEARTBEAT: u16 = 101;
/// HR 102-103: reserved, writable, stored and echoed on the console only.
pub const HR_RESERVED: u16 = 102;

/// How a register's raw word(s) read ([`MAP`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// IEEE-754 float32 over two registers (`output.modbus.word_order`); NaN = unavailable.
    F32,
    /// uint32 over two registers (`output.modbus.word_order`).
    U32,
    /// uint16.
    U16,
    /// uint16, the value x10.
    Tenths,
    /// uint16, the value x1000 (m/s as mm/s); 65535 = unavailable.
    Thousandths,
    /// uint16, the age x10 in s; 65534 = no value yet.
    Age,
    /// The status bits ([`StatusBits`]).
    Bits,
    /// The fault code ([`FaultCode`]).
    Fault,
    /// 0/1.
    Flag,
}

/// One entry of the register map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Register {
    /// First register (0-based PDU address).
    pub addr: usize,
    /// Name (the console `regs`).
    pub name: &'static str,
    /// How the word(s) read.
    pub encoding: Encoding,
    /// Unit of the decoded value (empty: a count or a code).
    pub unit: &'static str,
}

impl Register {
    /// Registers it spans (2 for float32 and uint32).
    pub const fn len(&self) -> usize {
        match self.encoding {
            Encoding::F32 | Encoding::U32 => 2,
            _ => 1,
        }
    }

    /// Never empty: every entry spans at least one register.
    pub const fn is_empty(&self) -> bool {
        false
    }

    /// The decoded value with its unit, from `block` encoded in word order `order`.
    pub fn decode(&self, block: &[u16; BLOCK_LEN], order: WordOrder) -> String {
        let w = block[self.addr];
        let unit = |v: String| if self.unit.is_empty() { v } else { format!("{v} {}", self.unit) };
        match self.encoding {
            Encoding::F32 => {
                let v = decode_f32([w, block[self.addr + 1]], order);
                if v.is_finite() { unit(format!("{v:.4}")) } else { "n/a".into() }
            }
            Encoding::U32 => unit(join_u32([w, block[self.addr + 1]], order).to_string()),
            Encoding::U16 => unit(w.to_string()),
            Encoding::Tenths => unit(format!("{:.1}", f64::from(w) / 10.0)),
            Encoding::Thousandths if w == u16::MAX => "n/a".into(),
            Encoding::Thousandths => unit(format!("{:.3}", f64::from(w) / 1000.0)),
            Encoding::Age if w >= u16::MAX - 1 => "no value yet".into(),
            Encoding::Age => unit(format!("{:.1}", f64::from(w) / 10.0)),
            Encoding::Bits => StatusBits::from_word(w).words(),
            Encoding::Fault => crate::status::fault_name(w).to_string(),
            Encoding::Flag => (if w == 0 { "no" } else { "yes" }).to_string(),
        }
    }
}

/// The register block, register by register: the one map the encoder ([`encode`]), the console
/// `regs` and docs/plc-integration.md follow.
pub const MAP: [Register; 19] = [
    Register { addr: 0, name: "activity_mean", encoding: Encoding::F32, unit: "m/s" },
    Register { addr: 2, name: "activity_mean_bls", encoding: Encoding::F32, unit: "BL/s" },
    Register { addr: 4, name: "activity_smoothed", encoding: Encoding::F32, unit: "m/s" },
    Register { addr: 6, name: "ci95_half_width", encoding: Encoding::F32, unit: "m/s" },
    Register { addr: 8, name: "fish", encoding: Encoding::U16, unit: "" },
    Register { addr: 9, name: "activity_mean_mm", encoding: Encoding::Thousandths, unit: "m/s" },
    Register { addr: 10, name: "status", encoding: Encoding::Bits, unit: "" },
    Register { addr: 11, name: "fault", encoding: Encoding::Fault, unit: "" },
    Register { addr: 12, name: "heartbeat", encoding: Encoding::U16, unit: "" },
    Register { addr: 13, name: "uptime", encoding: Encoding::U32, unit: "s" },
    Register { addr: 15, name: "camera_fps", encoding: Encoding::Tenths, unit: "frames/s" },
    Register { addr: 16, name: "dropped_frames", encoding: Encoding::U16, unit: "" },
    Register { addr: 17, name: "feeding_recommended", encoding: Encoding::Flag, unit: "" },
    Register { addr: 18, name: "version_major", encoding: Encoding::U16, unit: "" },
    Register { addr: 19, name: "version_minor", encoding: Encoding::U16, unit: "" },
    Register { addr: 20, name: "detector_rate", encoding: Encoding::Tenths, unit: "runs/s" },
    Register { addr: 21, name: "depth_rate", encoding: Encoding::Tenths, unit: "runs/s" },
    Register { addr: 22, name: "value_age", encoding: Encoding::Age, unit: "s" },
    Register { addr: 23, name: "feeding_ack", encoding: Encoding::U16, unit: "" },
];

pub use super::update::{StatusBits, Update};
pub use crate::status::FaultCode;

/// Splits a 32-bit value into two registers in the configured word order.
pub fn split_u32(v: u32, order: WordOrder) -> [u16; 2] {
    let (hi, lo) = ((v >> 16) as u16, v as u16);
    match order {
        WordOrder::HighFirst => [hi, lo],
        WordOrder::LowFirst => [lo, hi],
    }
}

/// Joins two registers into a 32-bit value (inverse of [`split_u32`]).
pub fn join_u32(regs: [u16; 2], order: WordOrder) -> u32 {
    let (hi, lo) = match order {
        WordOrder::HighFirst => (regs[0], regs[1]),
        WordOrder::LowFirst => (regs[1], regs[0]),
    };
    (u32::from(hi) << 16) | u32::from(lo)
}

/// Encodes an IEEE-754 float32 into two registers.
pub fn encode_f32(v: f32, order: WordOrder) -> [u16; 2] {
    split_u32(v.to_bits(), order)
}

/// Decodes two registers into a float32.
pub fn decode_f32(regs: [u16; 2], order: WordOrder) -> f32 {
    f32::from_bits(join_u32(regs, order))
}

/// Non-negative value x `scale`, rounded and saturated to u16; `nan_value` for NaN/negative/infinite.
fn scaled_u16(v: f64, scale: f64, nan_value: u16) -> u16 {
    if v.is_finite() && v >= 0.0 { (v * scale).round().min(f64::from(u16::MAX - 1)) as u16 } else { nan_value }
}

/// The crate version (major, minor) for registers 18-19.
pub fn version() -> (u16, u16) {
    (env!("CARGO_PKG_VERSION_MAJOR").parse().unwrap_or(0), env!("CARGO_PKG_VERSION_MINOR").parse().unwrap_or(0))
}

/// Encodes the register block (pure; see the module table).
pub fn encode(inp: &Update, order: WordOrder) -> [u16; BLOCK_LEN] {
    let mut r = [0u16; BLOCK_LEN];
    let mut put_f32 = |at: usize, v: f64| r[at..at + 2].copy_from_slice(&encode_f32(v as f32, order));
    put_f32(0, inp.mean_mps);
    put_f32(2, inp.mean_bls);
    put_f32(4, inp.smoothed_mps);
    put_f32(6, inp.ci95_half_mps);
    r[8] = inp.fish.min(u32::from(u16::MAX)) as u16;
    r[9] = if inp.mean_mps.is_finite() && inp.mean_mps >= 0.0 {
        (inp.mean_mps * 1000.0).round().min(65534.0) as u16
    } else {
        u16::MAX
    };
    r[10] = inp.status.bits();
    r[11] = inp.fault as u16;
    r[12] = inp.heartbeat;
    r[13..15].copy_from_slice(&split_u32(inp.uptime_s, order));
    r[15] = scaled_u16(inp.camera_fps, 10.0, 0);
    r[16] = inp.dropped as u16; // wrapping by contract
    r[17] = u16::from(inp.feeding);
    let (maj, min) = version();
    r[18] = maj;
    r[19] = min;
    r[20] = scaled_u16(inp.detector_hz, 10.0, 0);
    r[21] = scaled_u16(inp.depth_hz, 10.0, 0);
    r[22] = scaled_u16(inp.value_age_s, 10.0, u16::MAX - 1).min(u16::MAX - 1);
    r[23] = inp.feeding_ack;
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float_word_orders() {
        // 1.5f32 = 0x3FC00000
        assert_eq!(encode_f32(1.5, WordOrder::HighFirst), [0x3FC0, 0x0000]);
        assert_eq!(encode_f32(1.5, WordOrder::LowFirst), [0x0000, 0x3FC0]);
        for o in [WordOrder::HighFirst, WordOrder::LowFirst] {
            assert_eq!(decode_f32(encode_f32(-0.123, o), o), -0.123);
            assert_eq!(join_u32(split_u32(0xDEAD_BEEF, o), o), 0xDEAD_BEEF);
        }
    }

    #[test]
    fn block_layout() {
        let inp = Update {
            mean_mps: 0.2345,
            mean_bls: 0.67,
            smoothed_mps: 0.25,
            ci95_half_mps: 0.01,
            fish: 17,
            status: StatusBits::RUNNING | StatusBits::CAMERA_OK,
            fault: FaultCode::Depth,
            heartbeat: 65535,
            uptime_s: 70_000,
            camera_fps: 29.97,
            dropped: 65_537,
            feeding: true,
            detector_hz: 10.04,
            depth_hz: 5.0,
            value_age_s: 0.42,
            feeding_ack: 1,
            ..Update::default()
        };
        let r = encode(&inp, WordOrder::HighFirst);
        assert_eq!(decode_f32([r[0], r[1]], WordOrder::HighFirst), 0.2345);
        assert_eq!(decode_f32([r[4], r[5]], WordOrder::HighFirst), 0.25);
        assert_eq!(r[8], 17);
        assert_eq!(r[9], 235);
        assert_eq!(r[10], 0b11);
        assert_eq!(r[11], 3);
        assert_eq!(r[12], 65535);
        assert_eq!(join_u32([r[13], r[14]], WordOrder::HighFirst), 70_000);
        assert_eq!(r[15], 300);
        assert_eq!(r[16], 1);
        assert_eq!(r[17], 1);
        assert_eq!((r[18], r[19]), version());
        assert_eq!((r[20], r[21], r[22], r[23]), (100, 50, 4, 1));
        let low = encode(&inp, WordOrder::LowFirst);
        assert_eq!([low[0], low[1]], [r[1], r[0]]);
        assert_eq!([low[13], low[14]], [r[14], r[13]]);
    }

    #[test]
    fn unavailable_values() {
        let inp = Update { mean_mps: f64::NAN, value_age_s: f64::INFINITY, ..Default::default() };
        let r = encode(&inp, WordOrder::HighFirst);
        assert!(decode_f32([r[0], r[1]], WordOrder::HighFirst).is_nan());
        assert_eq!(r[9], u16::MAX);
        assert_eq!(r[22], u16::MAX - 1);
        let big = Update { mean_mps: 1000.0, ..Default::default() };
        assert_eq!(encode(&big, WordOrder::HighFirst)[9], 65534);
    }

    #[test]
    fn the_map_covers_the_block_and_decodes_what_encode_wrote() {
        let mut next = 0;
        for r in &MAP {
            assert_eq!(r.addr, next, "{} starts where the previous entry ends", r.name);
            next += r.len();
        }
        assert_eq!(next, BLOCK_LEN);
        let inp = Update {
            mean_mps: 0.2345,
            mean_bls: f64::NAN,
            fish: 17,
            status: StatusBits::RUNNING | StatusBits::TOO_FEW_FISH,
            fault: FaultCode::Camera,
            uptime_s: 70_000,
            camera_fps: 29.97,
            feeding: true,
            value_age_s: 0.42,
            ..Default::default()
        };
        for order in [WordOrder::HighFirst, WordOrder::LowFirst] {
            let block = encode(&inp, order);
            let v = |name: &str| MAP.iter().find(|r| r.name == name).expect(name).decode(&block, order);
            assert_eq!(v("activity_mean"), "0.2345 m/s");
            assert_eq!(v("activity_mean_bls"), "n/a");
            assert_eq!(v("fish"), "17");
            assert_eq!(v("activity_mean_mm"), "0.235 m/s");
            assert_eq!(v("status"), "running too_few_fish");
            assert_eq!(v("fault"), "camera");
            assert_eq!(v("uptime"), "70000 s");
            assert_eq!(v("camera_fps"), "30.0 frames/s");
            assert_eq!(v("feeding_recommended"), "yes");
            assert_eq!(v("value_age"), "0.4 s");
        }
    }
}
