//! Freezing the ring into a MOTChallenge sequence `recordings/<UTC>-<label>/` that `fme run
//! --source`, `fme eval` and `fme tune` read: seqinfo.ini, img1/, det/det.txt (the detections),
//! tracks.txt (the tracks, MOTChallenge rows), series.csv (the `fme run --series` columns),
//! times.txt (the original frame timestamps), meta.json (the calibration as loaded) and fme.toml
//! (the effective configuration). docs/recording.md.

use super::ring::Ring;
use crate::sequence::{Meta, SeqInfo, frame_file_name};
use crate::sequence::{SeriesRow, SeriesWriter};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What a frozen recording carries besides the frames.
#[derive(Debug, Clone, Default)]
pub struct FreezeInputs {
    /// The calibration file the pipeline loaded, if any.
    pub calibration: Option<PathBuf>,
    /// The effective configuration text.
    pub config_text: String,
}

/// Keeps a label to letters, digits, `-` and `_` (at most 40), so it is a safe file name.
pub fn clean_label(label: &str) -> String {
    let s: String = label
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '-' })
        .take(40)
        .collect();
    if s.is_empty() { "manual".into() } else { s }
}

/// Frame rate of the ring from its timestamps, rounded to 1/1000 frame/s (a recording replays
/// with timestamps `(k - 1) / fps`; a 30 frames/s source gives exactly 30).
fn frame_rate(ring: &Ring) -> f64 {
    let e = ring.entries();
    match (e.front(), e.back()) {
        (Some(a), Some(b)) if e.len() > 1 && b.t > a.t => {
            let r = (e.len() - 1) as f64 / (b.t - a.t);
            (r * 1000.0).round() / 1000.0
        }
        _ => 30.0,
    }
}

/// Prefix of the hidden folder a recording is staged in before its rename.
pub const PARTIAL_PREFIX: &str = ".partial-";

/// Writes the ring as `<recordings>/<stamp>-<label>/` (staged in a hidden folder and renamed, so a
/// recording appears complete or not at all). Frames are hard links into the ring where the file
/// system allows, copies otherwise. A failed freeze removes its staged folder: its hard links
/// would pin ring frames on the disk. Errors name the file.
pub fn freeze(
    ring: &Ring,
    recordings: &Path,
    stamp: &str,
    label: &str,
    inputs: &FreezeInputs,
) -> Result<PathBuf, String> {
    let name = format!("{stamp}-{}", clean_label(label));
    let staged = recordings.join(format!("{PARTIAL_PREFIX}{name}"));
    let result = stage_and_rename(ring, recordings, &name, &staged, inputs);
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&staged);
    }
    result
}

/// Deletes the staged folders (`.partial-*`) left in `recordings` by a freeze that was killed or
/// failed: only the writer thread freezes, so none is in progress when it calls this. Returns how
/// many.
pub fn remove_partials(recordings: &Path) -> usize {
    let Ok(rd) = std::fs::read_dir(recordings) else { return 0 };
    rd.flatten()
        .filter(|e| e.file_name().to_str().is_some_and(|n| n.starts_with(PARTIAL_PREFIX)))
        .filter(|e| std::fs::remove_dir_all(e.path()).is_ok())
        .count()
}

fn stage_and_rename(
    ring: &Ring,
    recordings: &Path,
    name: &str,
    staged: &Path,
    inputs: &FreezeInputs,
) -> Result<PathBuf, String> {
    let target = recordings.join(name);
    let io = |p: &Path, e: std::io::Error| format!("{}: {e}", p.display());
    let entries = ring.entries();
    let Some(first) = entries.front() else { return Err("the ring is empty: nothing to save".into()) };
    if staged.exists() {
        let _ = std::fs::remove_dir_all(staged);
    }
    let img = staged.join("img1");
    std::fs::create_dir_all(&img).map_err(|e| io(&img, e))?;
    std::fs::create_dir_all(staged.join("det")).map_err(|e| io(staged, e))?;
    let (mut det, mut tracks, mut times) = (String::new(), String::new(), String::from("frame,t\n"));
    let series_path = staged.join("series.csv");
    let mut series = SeriesWriter::create(&series_path, "")?;
    for (i, e) in entries.iter().enumerate() {
        let k = i as u32 + 1;
        let (src, dst) = (ring.path(e.seq), img.join(frame_file_name(k, ".jpg")));
        if std::fs::hard_link(&src, &dst).is_err() {
            std::fs::copy(&src, &dst).map_err(|e| io(&dst, e))?;
        }
        for (b, score) in &e.overlays.detections {
            let _ = writeln!(det, "{k},-1,{:.2},{:.2},{:.2},{:.2},{score:.4},-1,-1,-1", b.x, b.y, b.w, b.h);
        }
        for t in &e.overlays.fish {
            let b = t.bbox;
            let _ = writeln!(tracks, "{k},{},{:.2},{:.2},{:.2},{:.2},1,-1,-1,-1", t.id, b.x, b.y, b.w, b.h);
        }
        let _ = writeln!(times, "{k},{}", e.t);
        if let Some(sample) = e.sample {
            series.write(&SeriesRow { frame: u64::from(k), sample })?;
        }
    }
    series.finish()?;
    let fps = frame_rate(ring);
    let info = SeqInfo {
        name: name.to_string(),
        im_dir: "img1".into(),
        frame_rate: fps,
        seq_length: entries.len() as u32,
        im_width: first.size.0,
        im_height: first.size.1,
        im_ext: ".jpg".into(),
    };
    info.write(&staged.join("seqinfo.ini")).map_err(|e| e.to_string())?;
    for (file, text) in [("det/det.txt", &det), ("tracks.txt", &tracks), ("times.txt", &times)] {
        let p = staged.join(file);
        std::fs::write(&p, text).map_err(|e| io(&p, e))?;
    }
    let p = staged.join("fme.toml");
    std::fs::write(&p, &inputs.config_text).map_err(|e| io(&p, e))?;
    if let Some(calib) = &inputs.calibration {
        let p = staged.join("meta.json");
        // A sequence's meta.json (it states a frame rate) gets this recording's rate, size and length
        // (so `fme eval` opens it); any other calibration file (`fme calibrate`'s) is kept as it was
        // loaded: the sequence reader takes what it leaves out from seqinfo.ini.
        match Meta::read(calib) {
            Ok(mut m) if m.fps > 0.0 => {
                (m.fps, m.width, m.height, m.frames) = (fps, first.size.0, first.size.1, entries.len() as u32);
                m.write(&p).map_err(|e| e.to_string())?;
            }
            _ => {
                std::fs::copy(calib, &p).map_err(|e| io(&p, e))?;
            }
        }
    }
    std::fs::rename(staged, &target).map_err(|e| io(&target, e))?;
    Ok(target)
}

/// Deletes the oldest entries of `dir` whose names start with a digit (recordings, snapshots) so
/// that at most `keep` remain (0 = keep all), and any staged folder a failed freeze left. Names
/// begin with a UTC stamp, so name order is age.
pub fn rotate(dir: &Path, keep: usize) {
    remove_partials(dir);
    if keep == 0 {
        return;
    }
    let Ok(rd) = std::fs::read_dir(dir) else { return };
    let mut names: Vec<PathBuf> = rd
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(|c: char| c.is_ascii_digit())))
        .collect();
    names.sort();
    let excess = names.len().saturating_sub(keep);
    for p in names.into_iter().take(excess) {
        let _ = if p.is_dir() { std::fs::remove_dir_all(&p) } else { std::fs::remove_file(&p) };
    }
}

/// A UTC time stamp `YYYYMMDDTHHMMSSZ` (file names sort by age).
pub fn utc_stamp(t: std::time::SystemTime) -> String {
    let secs = t.duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let (y, m, d) = crate::civil::civil_from_days(days);
    format!("{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z", rem / 3600, rem / 60 % 60, rem % 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_and_labels() {
        let t = std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_796_398_651);
        assert_eq!(utc_stamp(t), "20261204T153731Z");
        assert_eq!(utc_stamp(std::time::UNIX_EPOCH), "19700101T000000Z");
        assert_eq!(clean_label("../etc passwd"), "---etc-passwd");
        assert_eq!(clean_label(""), "manual");
    }
}
