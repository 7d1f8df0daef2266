//! Reading and writing MOTChallenge text files (`frame,id,x,y,w,h,score,...`).

use crate::geometry::PixelBox;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};

/// One row of a MOTChallenge file (detections have `id = -1`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotRow {
    /// Frame number, from 1.
    pub frame: u32,
    /// Object or track id (-1 for detections).
    pub id: i64,
    /// Box, top-left corner and size in pixels.
    pub bbox: PixelBox,
    /// Confidence (7th column; 1 when absent).
    pub score: f64,
}

/// Error reading a MOTChallenge file; always names the file, and the line for content errors.
#[derive(Debug, thiserror::Error)]
pub enum MotError {
    /// The file could not be read.
    #[error("reading {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A row is malformed.
    #[error("{path}:{line}: {msg}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        msg: String,
    },
    /// A row's frame lies outside the sequence it is read for.
    #[error("{path}: frame {frame} is beyond the sequence's {frames} frames")]
    Beyond {
        /// The file.
        path: PathBuf,
        /// The row's frame.
        frame: u32,
        /// Frames in the sequence.
        frames: u32,
    },
}

/// What a reader accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReadOptions {
    /// Reject a row whose frame number is lower than the previous row's (detection files are
    /// written frame by frame; ground-truth files are often sorted by id and need `false`).
    pub require_sorted: bool,
}

/// Parses one line; `Ok(None)` for a blank line.
pub fn parse_line(text: &str) -> Result<Option<MotRow>, String> {
    let text = text.trim();
    if text.is_empty() {
        return Ok(None);
    }
    let mut fields = text.split(|c: char| c == ',' || c.is_whitespace()).filter(|f| !f.is_empty());
    let mut num = |name: &str| -> Result<Option<f64>, String> {
        match fields.next() {
            None => Ok(None),
            Some(f) => f.parse::<f64>().map(Some).map_err(|_| format!("{name} `{f}` is not a number")),
        }
    };
    let need = |v: Option<f64>, name: &str| v.ok_or_else(|| format!("missing {name} (need frame,id,x,y,w,h)"));
    let frame = need(num("frame")?, "frame")?;
    let id = need(num("id")?, "id")?;
    let x = need(num("x")?, "x")?;
    let y = need(num("y")?, "y")?;
    let w = need(num("width")?, "width")?;
    let h = need(num("height")?, "height")?;
    let score = num("score")?.unwrap_or(1.0);
    if !(frame.fract() == 0.0 && frame >= 1.0 && frame <= f64::from(u32::MAX)) {
        return Err(format!("frame {frame} is not a whole number in 1..={}", u32::MAX));
    }
    if !(id.fract() == 0.0 && id.abs() < 9.0e15) {
        return Err(format!("id {id} is not a whole number"));
    }
    for (name, v) in [("x", x), ("y", y), ("width", w), ("height", h), ("score", score)] {
        if !v.is_finite() {
            return Err(format!("{name} is {v}"));
        }
    }
    if w < 0.0 || h < 0.0 {
        return Err(format!("negative box size {w} x {h}"));
    }
    Ok(Some(MotRow { frame: frame as u32, id: id as i64, bbox: PixelBox::new(x, y, w, h), score }))
}

/// Reads rows from any reader; `path` only names the source in errors.
pub fn read_rows(reader: impl BufRead, path: &Path, opts: ReadOptions) -> Result<Vec<MotRow>, MotError> {
    let mut rows = Vec::new();
    let mut prev = 0u32;
    for (k, line) in reader.lines().enumerate() {
        let line = line.map_err(|source| MotError::Io { path: path.to_path_buf(), source })?;
        let perr = |msg: String| MotError::Parse { path: path.to_path_buf(), line: k + 1, msg };
        let Some(row) = parse_line(&line).map_err(perr)? else { continue };
        if opts.require_sorted && row.frame < prev {
            return Err(perr(format!("frame {} comes after frame {prev}: rows must be sorted by frame", row.frame)));
        }
        prev = row.frame;
        rows.push(row);
    }
    Ok(rows)
}

/// Reads a MOTChallenge file.
pub fn read_file(path: &Path, opts: ReadOptions) -> Result<Vec<MotRow>, MotError> {
    let f = std::fs::File::open(path).map_err(|source| MotError::Io { path: path.to_path_buf(), source })?;
    read_rows(std::io::BufReader::new(f), path, opts)
}

/// Reads a MOTChallenge detection file (`frame,-1,x,y,w,h,score,...`) into per-frame lists for a
/// sequence of `frames` frames (index 0 = frame 1); a row beyond the sequence is an error naming the file.
pub fn read_detections(path: &Path, frames: u32) -> Result<Vec<Vec<crate::detection::Detection>>, MotError> {
    let rows = read_file(path, ReadOptions::default())?;
    let mut out = vec![Vec::new(); frames as usize];
    for r in rows {
        let beyond = || MotError::Beyond { path: path.to_path_buf(), frame: r.frame, frames };
        let slot = (r.frame as usize).checked_sub(1).and_then(|i| out.get_mut(i)).ok_or_else(beyond)?;
        slot.push(crate::detection::Detection::new(r.bbox, r.score));
    }
    Ok(out)
}

/// Sorts rows by frame (stable) and returns `(frame, range)` for every frame that has rows, in
/// increasing frame order (frames without rows are absent; memory stays proportional to the rows
/// even for absurd frame numbers).
pub fn group_by_frame(rows: &mut [MotRow]) -> Vec<(u32, std::ops::Range<usize>)> {
    rows.sort_by_key(|r| r.frame);
    let mut out: Vec<(u32, std::ops::Range<usize>)> = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        match out.last_mut() {
            Some((f, range)) if *f == r.frame => range.end = i + 1,
            _ => out.push((r.frame, i..i + 1)),
        }
    }
    out
}

/// Writes one result row `frame,id,x,y,w,h,score,-1,-1,-1` (two decimals, like SORT).
pub fn write_row(mut w: impl Write, frame: u32, id: u32, b: &PixelBox, score: f64) -> std::io::Result<()> {
    writeln!(w, "{frame},{id},{:.2},{:.2},{:.2},{:.2},{score:.2},-1,-1,-1", b.x, b.y, b.w, b.h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_rejects_with_line_numbers() {
        let text = "1,-1,1,2,3,4,0.9,-1,-1,-1\n\n2 -1 1 2 3 4\n";
        let rows = read_rows(text.as_bytes(), Path::new("d.txt"), ReadOptions::default()).expect("valid");
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].score, 1.0);
        for (bad, what) in [
            ("1,-1,1,2,3\n", "missing height"),
            ("1,-1,1,2,-3,4\n", "negative"),
            ("1,-1,1,2,NaN,4\n", "width is NaN"),
            ("1,-1,a,2,3,4\n", "`a`"),
            ("0,-1,1,2,3,4\n", "frame 0"),
        ] {
            let text = format!("1,-1,1,2,3,4\n{bad}");
            let e = read_rows(text.as_bytes(), Path::new("d.txt"), ReadOptions::default()).expect_err(bad);
            let msg = e.to_string();
            assert!(msg.starts_with("d.txt:2: ") && msg.contains(what), "{msg}");
        }
        let e =
            read_rows("2,-1,1,2,3,4\n1,-1,1,2,3,4\n".as_bytes(), Path::new("d"), ReadOptions { require_sorted: true })
                .expect_err("order");
        assert!(e.to_string().contains("d:2: frame 1 comes after frame 2"), "{e}");
    }
}
