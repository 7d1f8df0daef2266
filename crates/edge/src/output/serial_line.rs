//! Plain serial line output for simple data loggers: one ASCII line per update.
//!
//! ```text
//! $FME,<heartbeat>,<uptime_s>,<mean_mps>,<mean_bls>,<smoothed_mps>,<ci95_mps>,<fish>,<status_hex>,<fault>,<feeding>*<CS>\r\n
//! ```
//! - `heartbeat`: register 12 (0..65535, wraps); `uptime_s`: integer seconds since start.
//! - speeds: 4 decimals, m/s or body lengths/s; `nan` when unavailable.
//! - `status_hex`: register 10 as 4 hex digits; `fault`: register 11; `feeding`: 0/1.
//! - `CS`: two upper-case hex digits, XOR of every byte between `$` and `*` (NMEA 0183 style).

use super::update::Update;
use std::fmt::Write as _;

/// XOR checksum of a payload (the bytes between `$` and `*`).
pub fn checksum(payload: &str) -> u8 {
    payload.bytes().fold(0, |a, b| a ^ b)
}

fn num(out: &mut String, v: f64) {
    if v.is_finite() {
        let _ = write!(out, ",{v:.4}");
    } else {
        out.push_str(",nan");
    }
}

/// Formats one line (with `\r\n`) into `out` (cleared first; reuse it to avoid allocation).
pub fn format_line(inp: &Update, out: &mut String) {
    out.clear();
    out.push('$');
    let _ = write!(out, "FME,{},{}", inp.heartbeat, inp.uptime_s);
    num(out, inp.mean_mps);
    num(out, inp.mean_bls);
    num(out, inp.smoothed_mps);
    num(out, inp.ci95_half_mps);
    let _ = write!(out, ",{},{:04X},{},{}", inp.fish, inp.status.bits(), inp.fault as u16, u8::from(inp.feeding));
    let cs = checksum(&out[1..]);
    let _ = write!(out, "*{cs:02X}\r\n");
}

/// Checks a received line: returns the payload fields when the checksum matches.
pub fn parse_line(line: &str) -> Option<Vec<&str>> {
    let body = line.trim_end().strip_prefix('$')?;
    let (payload, cs) = body.rsplit_once('*')?;
    let cs = u8::from_str_radix(cs, 16).ok()?;
    (checksum(payload) == cs).then(|| payload.split(',').collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::registers::FaultCode;

    #[test]
    fn line_round_trip_and_checksum() {
        let inp = Update {
            heartbeat: 7,
            uptime_s: 12,
            mean_mps: 0.21234,
            mean_bls: 0.6,
            smoothed_mps: 0.2,
            ci95_half_mps: f64::NAN,
            fish: 9,
            status: crate::output::update::StatusBits::from_word(0x23),
            fault: FaultCode::Camera,
            feeding: true,
            ..Default::default()
        };
        let mut s = String::new();
        format_line(&inp, &mut s);
        assert!(s.starts_with("$FME,7,12,0.2123,0.6000,0.2000,nan,9,0023,1,1*"), "{s}");
        assert!(s.ends_with("\r\n"));
        let fields = parse_line(&s);
        assert_eq!(fields.as_ref().map(|f| f.len()), Some(11));
        let corrupted = s.replacen("0.2123", "0.2124", 1);
        assert!(parse_line(&corrupted).is_none());
    }
}
