//! The one reader and writer of MOTChallenge text rows (`frame,id,x,y,w,h,score,...`): detection
//! files, tracker results and ground truth (`gt/gt.txt`) all go through [`parse_line`] and
//! [`write_row`], whichever command reads or writes them.
//!
//! Accepted input: fields separated by commas (spaces around them allowed) or, on a line without a
//! comma, by whitespace; blank lines and lines starting with `#` are skipped; at least the six
//! columns `frame,id,x,y,w,h`, the optional seventh (score, 1 when absent) and eighth to tenth
//! (-1 when absent) must be finite numbers; columns after the tenth are ignored. The frame is a
//! whole number from 1, the id -1 (an untracked detection) or a whole number from 0, the box size
//! not negative.

use fme_core::geometry::PixelBox;
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
    /// Seventh column: confidence of a detection or result, the "consider" flag of ground truth
    /// (1 when absent).
    pub score: f64,
    /// Eighth to tenth columns (-1 when absent): the unused world position `x, y, z` of detections
    /// and results, `class, visibility` (and nothing) in ground truth.
    pub extra: [f64; 3],
}

impl MotRow {
    /// A row with the eighth to tenth columns unused (-1).
    pub const fn new(frame: u32, id: i64, bbox: PixelBox, score: f64) -> Self {
        Self { frame, id, bbox, score, extra: [-1.0; 3] }
    }

    /// The row as text in `layout`, without a line end.
    pub fn display(&self, layout: RowLayout) -> impl std::fmt::Display + '_ {
        Shown(self, layout)
    }
}

/// How [`write_row`] writes the columns of a row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowLayout {
    /// Detections and tracker results (as SORT writes them): ten columns, box and score to 1/100
    /// pixel, `frame,id,x,y,w,h,score,x,y,z`.
    Result,
    /// Ground truth (`gt/gt.txt`): nine columns, box to 1/100 pixel, visibility to 4 decimals,
    /// `frame,id,x,y,w,h,consider,class,visibility`.
    GroundTruth,
}

struct Shown<'a>(&'a MotRow, RowLayout);

impl std::fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Shown(r, layout) = self;
        let b = r.bbox;
        write!(f, "{},{},{:.2},{:.2},{:.2},{:.2}", r.frame, r.id, b.x, b.y, b.w, b.h)?;
        let [e0, e1, e2] = r.extra;
        match layout {
            RowLayout::Result => write!(f, ",{:.2},{e0},{e1},{e2}", r.score),
            RowLayout::GroundTruth => write!(f, ",{},{e0},{e1:.4}", r.score),
        }
    }
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

/// Names of the first ten columns, for messages.
const COLUMNS: [&str; 10] = ["frame", "id", "x", "y", "width", "height", "score", "column 8", "column 9", "column 10"];

/// Parses one line (see the module doc for what is accepted); `Ok(None)` for a blank or `#` line.
/// The error says what is wrong, without file and line (callers add them).
pub fn parse_line(text: &str) -> Result<Option<MotRow>, String> {
    let text = text.trim();
    if text.is_empty() || text.starts_with('#') {
        return Ok(None);
    }
    let mut v = [-1.0f64; 10];
    let mut n = 0usize;
    let mut field = |k: usize, f: &str| -> Result<(), String> {
        if k >= v.len() {
            return Ok(());
        }
        let name = COLUMNS[k];
        if f.is_empty() {
            return Err(format!("{name} is empty"));
        }
        let x = f.parse::<f64>().map_err(|_| format!("{name} `{f}` is not a number"))?;
        if !x.is_finite() {
            return Err(format!("{name} is {x}"));
        }
        v[k] = x;
        Ok(())
    };
    if text.contains(',') {
        // A trailing comma (some tools write one) ends the row rather than adding an empty column.
        let body = text.trim_end_matches(|c: char| c == ',' || c.is_whitespace());
        for (k, f) in body.split(',').enumerate() {
            field(k, f.trim())?;
            n = k + 1;
        }
    } else {
        for (k, f) in text.split_whitespace().enumerate() {
            field(k, f)?;
            n = k + 1;
        }
    }
    if n < 6 {
        return Err(format!("missing {} (need frame,id,x,y,w,h)", COLUMNS[n]));
    }
    let [frame, id, x, y, w, h, score, e0, e1, e2] = v;
    if !(frame.fract() == 0.0 && frame >= 1.0 && frame <= f64::from(u32::MAX)) {
        return Err(format!("frame {frame} is not a whole number in 1..={}", u32::MAX));
    }
    if !(id.fract() == 0.0 && (-1.0..9.0e15).contains(&id)) {
        return Err(format!("id {id} is neither -1 nor a whole number >= 0"));
    }
    if w < 0.0 || h < 0.0 {
        return Err(format!("negative box size {w} x {h}"));
    }
    let score = if n > 6 { score } else { 1.0 };
    Ok(Some(MotRow { frame: frame as u32, id: id as i64, bbox: PixelBox::new(x, y, w, h), score, extra: [e0, e1, e2] }))
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
pub fn read_detections(path: &Path, frames: u32) -> Result<Vec<Vec<fme_core::detection::Detection>>, MotError> {
    let rows = read_file(path, ReadOptions::default())?;
    let mut out = vec![Vec::new(); frames as usize];
    for r in rows {
        let beyond = || MotError::Beyond { path: path.to_path_buf(), frame: r.frame, frames };
        let slot = (r.frame as usize).checked_sub(1).and_then(|i| out.get_mut(i)).ok_or_else(beyond)?;
        slot.push(fme_core::detection::Detection::new(r.bbox, r.score));
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

/// Writes one row in `layout`, with a line end.
pub fn write_row(mut w: impl Write, row: &MotRow, layout: RowLayout) -> std::io::Result<()> {
    writeln!(w, "{}", row.display(layout))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_rejects_with_line_numbers() {
        let text = "1,-1,1,2,3,4,0.9,-1,-1,-1\n\n# comment\n2 -1 1 2 3 4\n3, 7, 1.5, 2, 3, 4, 1, 2, 0.5,\n";
        let rows = read_rows(text.as_bytes(), Path::new("d.txt"), ReadOptions::default()).expect("valid");
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[1].score, 1.0);
        assert_eq!(rows[1].extra, [-1.0; 3]);
        assert_eq!(
            rows[2],
            MotRow { extra: [2.0, 0.5, -1.0], ..MotRow::new(3, 7, PixelBox::new(1.5, 2.0, 3.0, 4.0), 1.0) }
        );
        for (bad, what) in [
            ("1,-1,1,2,3\n", "missing height"),
            ("1,-1,1,2,-3,4\n", "negative"),
            ("1,-1,1,2,NaN,4\n", "width is NaN"),
            ("1,-1,a,2,3,4\n", "x `a` is not a number"),
            ("1,-1,1,,3,4\n", "y is empty"),
            ("1 -1 1 2 3 4 0.9 z\n", "column 8 `z` is not a number"),
            ("0,-1,1,2,3,4\n", "frame 0"),
            ("1,-2,1,2,3,4\n", "id -2"),
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

    #[test]
    fn writes_both_layouts_and_reads_them_back() {
        let r = MotRow::new(4, 12, PixelBox::new(1.0, 2.5, 30.126, 40.0), 0.9);
        let mut text = Vec::new();
        write_row(&mut text, &r, RowLayout::Result).expect("in memory");
        assert_eq!(text, b"4,12,1.00,2.50,30.13,40.00,0.90,-1,-1,-1\n");
        let back = read_rows(text.as_slice(), Path::new("r.txt"), ReadOptions::default()).expect("valid");
        assert_eq!(back[0].frame, 4);
        assert_eq!(back[0].score, 0.9);
        let g = MotRow { extra: [1.0, 0.25, -1.0], ..MotRow::new(4, 12, PixelBox::new(1.0, 2.0, 3.0, 4.0), 1.0) };
        assert_eq!(g.display(RowLayout::GroundTruth).to_string(), "4,12,1.00,2.00,3.00,4.00,1,1,0.2500");
        assert_eq!(parse_line(&g.display(RowLayout::GroundTruth).to_string()), Ok(Some(g)));
    }
}
