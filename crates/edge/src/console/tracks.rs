//! The console's `tracks` lines: one per fish the estimator follows, formatted from the frame
//! outcome's typed fish.

use fme_core::motion::Fish;
use std::fmt::Write;

/// Writes one line per fish (at most `max`): id, time last seen, box centre and size, depth, speed.
pub fn describe_fish(out: &mut String, fish: &[Fish], max: usize) {
    for v in fish.iter().take(max) {
        let c = v.bbox.center();
        let _ = write!(
            out,
            "id {:>4} t {:.2} s box ({:.0},{:.0}) {:.0}x{:.0} px",
            v.id, v.last_seen.0, c.u, c.v, v.bbox.w, v.bbox.h
        );
        let _ = match v.depth {
            Some(d) => write!(out, " depth {:.2} m", d.0),
            None => write!(out, " depth -"),
        };
        let _ = match v.speed {
            Some(s) => writeln!(out, " speed {:.3} m/s", s.0),
            None => writeln!(out, " speed -"),
        };
    }
}
