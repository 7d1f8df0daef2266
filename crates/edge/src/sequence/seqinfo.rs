//! `seqinfo.ini`, the MOTChallenge sequence description.

use super::{Error, Result};
use std::fmt::Write as _;
use std::path::Path;

/// Slowest `frameRate` a recording may give, frames/s (one frame per 1000 s): frame times stay
/// durations a timer can hold.
pub const MIN_FRAME_RATE: f64 = 0.001;
/// Fastest `frameRate` a recording may give, frames/s.
pub const MAX_FRAME_RATE: f64 = 10_000.0;

/// The `[Sequence]` section of `seqinfo.ini`.
#[derive(Debug, Clone, PartialEq)]
pub struct SeqInfo {
    /// Sequence name.
    pub name: String,
    /// Frame folder relative to the sequence, `img1`.
    pub im_dir: String,
    /// Frames per second.
    pub frame_rate: f64,
    /// Number of frames.
    pub seq_length: u32,
    /// Image width, pixels.
    pub im_width: u32,
    /// Image height, pixels.
    pub im_height: u32,
    /// Frame extension including the dot, `.jpg`.
    pub im_ext: String,
}

impl SeqInfo {
    /// Parses the text of a `seqinfo.ini`; `path` is used in errors. Keys outside `[Sequence]` and
    /// unknown keys are ignored; `seqLength`, `imWidth`, `imHeight`, `frameRate` are required.
    pub fn parse(path: &Path, text: &str) -> Result<Self> {
        let mut in_seq = false;
        let (mut name, mut im_dir, mut im_ext) = (None, None, None);
        let (mut rate, mut len, mut w, mut h) = (None, None, None, None);
        for (i, raw) in text.lines().enumerate() {
            let line = i + 1;
            let l = raw.trim();
            if l.is_empty() || l.starts_with(';') || l.starts_with('#') {
                continue;
            }
            if l.starts_with('[') {
                if !l.ends_with(']') {
                    return Err(Error::parse(path, line, format!("malformed section header {l:?}")));
                }
                in_seq = l[1..l.len() - 1].trim().eq_ignore_ascii_case("sequence");
                continue;
            }
            if !in_seq {
                continue;
            }
            let Some((k, v)) = l.split_once('=') else {
                return Err(Error::parse(path, line, format!("expected key=value, got {l:?}")));
            };
            let (k, v) = (k.trim(), v.trim());
            let int = |what: &str| -> Result<u32> {
                v.parse::<u32>()
                    .map_err(|_| Error::parse(path, line, format!("{what}: expected an integer, got {v:?}")))
            };
            match k {
                "name" => name = Some(v.to_string()),
                "imDir" => im_dir = Some(v.to_string()),
                "imExt" => im_ext = Some(v.to_string()),
                "frameRate" => {
                    let r: f64 = v
                        .parse()
                        .map_err(|_| Error::parse(path, line, format!("frameRate: expected a number, got {v:?}")))?;
                    if !(MIN_FRAME_RATE..=MAX_FRAME_RATE).contains(&r) {
                        return Err(Error::parse(
                            path,
                            line,
                            format!("frameRate must be {MIN_FRAME_RATE}..={MAX_FRAME_RATE} frames/s, got {v:?}"),
                        ));
                    }
                    rate = Some(r);
                }
                "seqLength" => len = Some(int("seqLength")?),
                "imWidth" => w = Some(int("imWidth")?),
                "imHeight" => h = Some(int("imHeight")?),
                _ => {}
            }
        }
        let missing = |k: &str| Error::invalid(path, format!("[Sequence] lacks required key {k}"));
        Ok(Self {
            name: name.unwrap_or_default(),
            im_dir: im_dir.unwrap_or_else(|| "img1".into()),
            frame_rate: rate.ok_or_else(|| missing("frameRate"))?,
            seq_length: len.ok_or_else(|| missing("seqLength"))?,
            im_width: w.ok_or_else(|| missing("imWidth"))?,
            im_height: h.ok_or_else(|| missing("imHeight"))?,
            im_ext: im_ext.unwrap_or_else(|| ".jpg".into()),
        })
    }

    /// Reads `seqinfo.ini`.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::parse(path, &text)
    }

    /// The file's text.
    pub fn to_ini(&self) -> String {
        let mut s = String::from("[Sequence]\n");
        let _ = writeln!(s, "name={}", self.name);
        let _ = writeln!(s, "imDir={}", self.im_dir);
        let _ = writeln!(s, "frameRate={}", self.frame_rate);
        let _ = writeln!(s, "seqLength={}", self.seq_length);
        let _ = writeln!(s, "imWidth={}", self.im_width);
        let _ = writeln!(s, "imHeight={}", self.im_height);
        let _ = writeln!(s, "imExt={}", self.im_ext);
        s
    }

    /// Writes `seqinfo.ini`.
    pub fn write(&self, path: &Path) -> Result<()> {
        std::fs::write(path, self.to_ini()).map_err(|e| Error::io(path, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_motchallenge_seqinfo_and_round_trips() {
        let p = Path::new("seqinfo.ini");
        let text = "[Sequence]\nname=MOT16-02\nimDir=img1\nframeRate=30\nseqLength=600\nimWidth=1920\nimHeight=1080\nimExt=.jpg\n";
        let s = SeqInfo::parse(p, text).unwrap();
        assert_eq!((s.seq_length, s.im_width, s.frame_rate), (600, 1920, 30.0));
        assert_eq!(s.to_ini(), text);
        let err = SeqInfo::parse(p, "[Sequence]\nseqLength=ten\n").unwrap_err().to_string();
        assert!(err.starts_with("seqinfo.ini:2:"), "{err}");
        assert!(SeqInfo::parse(p, "[Sequence]\nframeRate=30\n").unwrap_err().to_string().contains("seqLength"));
    }
}
