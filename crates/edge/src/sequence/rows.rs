//! Per-frame text rows: `gt/gt.txt` (MOTChallenge rows, read and written with [`crate::sequence::mot_text`],
//! the one MOTChallenge parser) and `gt/world.csv`.

use super::{Error, Result};
use crate::sequence::mot_text::{MotRow, RowLayout, parse_line};
use fme_core::geometry::{PixelBox, WorldPoint};
use fme_core::units::Metres;
use nalgebra::Vector3;
use std::fmt::Write as _;
use std::path::Path;

/// Header line of `gt/world.csv`.
pub const WORLD_HEADER: &str = "frame,id,x,y,z,vx,vy,vz,length_m,visibility";

/// One ground-truth box of `gt/gt.txt`: `frame,id,x,y,w,h,1,1,visibility`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GtBox {
    /// 1-based frame number.
    pub frame: u32,
    /// 1-based fish id.
    pub id: u32,
    /// Amodal box of the whole fish (tail included), pixels; may reach outside the image.
    pub bbox: PixelBox,
    /// Visible pixels / pixels of the fish rendered alone, in `[0, 1]`.
    pub visibility: f64,
}

impl GtBox {
    /// The row written to `gt.txt`: consider flag 1, class 1, the visibility in column 9.
    pub fn to_row(&self) -> MotRow {
        MotRow { extra: [1.0, self.visibility, -1.0], ..MotRow::new(self.frame, i64::from(self.id), self.bbox, 1.0) }
    }
}

/// One row of `gt/world.csv`: body centre and analytic velocity in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldRow {
    /// 1-based frame number.
    pub frame: u32,
    /// 1-based fish id (same ids as `gt.txt`).
    pub id: u32,
    /// Body centre (not the box centre), world frame, metres.
    pub position: WorldPoint,
    /// Velocity of the body centre, world frame, m/s.
    pub velocity: Vector3<f64>,
    /// Body length (snout to tail tip).
    pub length: Metres,
    /// Same visibility as the fish's `gt.txt` row (0 when it is outside the image).
    pub visibility: f64,
}

fn fields(line: &str) -> Vec<&str> {
    line.split(',').map(str::trim).collect()
}

fn num<T: std::str::FromStr>(path: &Path, line: usize, col: &str, s: &str) -> Result<T> {
    s.parse::<T>().map_err(|_| Error::parse(path, line, format!("column {col}: cannot parse {s:?}")))
}

fn finite(path: &Path, line: usize, col: &str, s: &str) -> Result<f64> {
    let v: f64 = num(path, line, col, s)?;
    if v.is_finite() { Ok(v) } else { Err(Error::parse(path, line, format!("column {col}: {s:?} is not finite"))) }
}

fn frame_no(path: &Path, line: usize, s: &str) -> Result<u32> {
    // Some tools write frame numbers as floats ("1.0"); accept integral values only.
    let v = finite(path, line, "frame", s)?;
    if v < 1.0 || v.fract() != 0.0 || v > f64::from(u32::MAX) {
        return Err(Error::parse(path, line, format!("frame must be a positive integer, got {s:?}")));
    }
    Ok(v as u32)
}

/// Non-empty, non-comment lines with their 1-based numbers.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// Parses `gt.txt` text with the MOTChallenge row parser ([`parse_line`]). Columns 7 and 8
/// (consider flag, class) must be numbers but are not kept; ids start at 1; a missing or negative
/// visibility (MOT15 writes -1 there) reads as 1.
pub fn parse_gt(path: &Path, text: &str) -> Result<Vec<GtBox>> {
    let mut out = Vec::new();
    for (k, l) in text.lines().enumerate() {
        let line = k + 1;
        let Some(r) = parse_line(l).map_err(|msg| Error::parse(path, line, msg))? else { continue };
        if r.id < 1 || r.id > i64::from(u32::MAX) {
            return Err(Error::parse(path, line, format!("id must be a positive integer, got {}", r.id)));
        }
        let v = r.extra[1];
        if v > 1.0 {
            return Err(Error::parse(path, line, format!("visibility {v} is above 1")));
        }
        let visibility = if v < 0.0 { 1.0 } else { v };
        out.push(GtBox { frame: r.frame, id: r.id as u32, bbox: r.bbox, visibility });
    }
    Ok(out)
}

/// Parses `world.csv` text (the header line is required).
pub fn parse_world(path: &Path, text: &str) -> Result<Vec<WorldRow>> {
    let mut out = Vec::new();
    let mut seen_header = false;
    for (line, l) in data_lines(text) {
        if !seen_header {
            let h: Vec<&str> = fields(l);
            let want: Vec<&str> = WORLD_HEADER.split(',').collect();
            if h != want {
                return Err(Error::parse(path, line, format!("expected header {WORLD_HEADER:?}, got {l:?}")));
            }
            seen_header = true;
            continue;
        }
        let f = fields(l);
        if f.len() != 10 {
            return Err(Error::parse(path, line, format!("expected 10 columns, got {}", f.len())));
        }
        let frame = frame_no(path, line, f[0])?;
        let id: u32 = num(path, line, "id", f[1])?;
        if id == 0 {
            return Err(Error::parse(path, line, "id must be positive"));
        }
        let g = |i: usize, n: &str| finite(path, line, n, f[i]);
        let position = WorldPoint::new(g(2, "x")?, g(3, "y")?, g(4, "z")?);
        let velocity = Vector3::new(g(5, "vx")?, g(6, "vy")?, g(7, "vz")?);
        let length = g(8, "length_m")?;
        if length <= 0.0 {
            return Err(Error::parse(path, line, format!("length_m must be positive, got {length}")));
        }
        let visibility = g(9, "visibility")?;
        if !(0.0..=1.0).contains(&visibility) {
            return Err(Error::parse(path, line, format!("visibility {visibility} is outside [0, 1]")));
        }
        out.push(WorldRow { frame, id, position, velocity, length: Metres(length), visibility });
    }
    if !seen_header {
        return Err(Error::parse(path, 1, format!("missing header {WORLD_HEADER:?}")));
    }
    Ok(out)
}

fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| Error::io(path, e))
}

/// Reads `gt.txt`.
pub fn read_gt(path: &Path) -> Result<Vec<GtBox>> {
    parse_gt(path, &read_text(path)?)
}
/// Reads `world.csv`.
pub fn read_world(path: &Path) -> Result<Vec<WorldRow>> {
    parse_world(path, &read_text(path)?)
}

/// Formats `gt.txt` rows ([`RowLayout::GroundTruth`]: boxes to 1/100 pixel, visibility to 4 decimals).
pub fn format_gt(rows: &[GtBox]) -> String {
    let mut s = String::with_capacity(rows.len() * 48);
    for r in rows {
        let _ = writeln!(s, "{}", r.to_row().display(RowLayout::GroundTruth));
    }
    s
}

/// Formats `world.csv` with its header (positions and velocities to 1e-6).
pub fn format_world(rows: &[WorldRow]) -> String {
    let mut s = String::with_capacity(rows.len() * 96 + 64);
    s.push_str(WORLD_HEADER);
    s.push('\n');
    for r in rows {
        let p = r.position.0;
        let v = r.velocity;
        let _ = writeln!(
            s,
            "{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.4},{:.4}",
            r.frame, r.id, p.x, p.y, p.z, v.x, v.y, v.z, r.length.0, r.visibility
        );
    }
    s
}

fn write_text(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).map_err(|e| Error::io(path, e))
}

/// Writes `gt.txt`.
pub fn write_gt(path: &Path, rows: &[GtBox]) -> Result<()> {
    write_text(path, &format_gt(rows))
}
/// Writes `world.csv`.
pub fn write_world(path: &Path, rows: &[WorldRow]) -> Result<()> {
    write_text(path, &format_world(rows))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gt_parse_reports_file_and_line() {
        let p = Path::new("gt/gt.txt");
        let rows = parse_gt(p, "1,1,10,20,30,40,1,1,0.5\n\n2,1,11,20,30,40,1,1,1\n").unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].bbox, PixelBox::new(11.0, 20.0, 30.0, 40.0));
        let err = parse_gt(p, "1,1,10,20,30,40,1,1,0.5\n2,1,x,20,30,40,1,1,1\n").unwrap_err().to_string();
        assert!(err.starts_with("gt/gt.txt:2:") && err.contains("x `x` is not a number"), "{err}");
        let err = parse_gt(p, "0,1,1,1,1,1\n").unwrap_err().to_string();
        assert!(err.contains(":1:") && err.contains("frame"), "{err}");
        // MOT15 ground truth writes -1 in column 9: visibility unknown reads as 1.
        assert_eq!(parse_gt(p, "1,3,1,2,3,4,1,-1,-1,-1\n").unwrap()[0].visibility, 1.0);
    }

    #[test]
    fn gt_accepts_whitespace_and_round_trips() {
        let p = Path::new("gt/gt.txt");
        let rows = parse_gt(p, "1 1 10 20 30 40 1 1 0.5\n2,1,11,20,30,40\n").unwrap();
        assert_eq!(rows[0].visibility, 0.5);
        assert_eq!(rows[1].visibility, 1.0);
        assert_eq!(parse_gt(p, &format_gt(&rows)).unwrap(), rows);
        assert_eq!(format_gt(&rows[..1]), "1,1,10.00,20.00,30.00,40.00,1,1,0.5000\n");
        let err = parse_gt(p, "1,1,1,1,1,1\n1,-1,1,1,1,1\n").unwrap_err().to_string();
        assert!(err.starts_with("gt/gt.txt:2:") && err.contains("id must be a positive integer"), "{err}");
        assert!(parse_gt(p, "1,1,1,1,1,1,1,1,1.5\n").unwrap_err().to_string().contains("above 1"));
    }

    #[test]
    fn world_requires_header_and_valid_values() {
        let p = Path::new("world.csv");
        assert!(parse_world(p, "1,1,0,0,0,0,0,0,0.3,1\n").unwrap_err().to_string().contains("header"));
        let bad = format!("{WORLD_HEADER}\n1,1,0,0,0,0,0,0,-0.3,1\n");
        assert!(parse_world(p, &bad).unwrap_err().to_string().contains("world.csv:2:"));
    }
}
