//! MOTChallenge sequences with fme's extras (`gt/world.csv`, `depth/`, `meta.json`): reader and writer.
//!
//! The on-disk layout of one sequence:
//!
//! ```text
//! seqinfo.ini          [Sequence] name, imDir, frameRate, seqLength, imWidth, imHeight, imExt
//! img1/000001.jpg ...  frames, 1-based
//! gt/gt.txt            frame,id,x,y,w,h,1,1,visibility   (amodal box of the whole fish)
//! gt/world.csv         frame,id,x,y,z,vx,vy,vz,length_m,visibility   (body centre, world frame)
//! depth/000001.png     16-bit PNG, camera z in millimetres, 0 = no data
//! meta.json            camera (intrinsics + world_to_camera), water, reference objects, ...
//! ```
//!
//! `gt.txt`, detections and tracker results are MOTChallenge text rows, parsed and written by
//! [`crate::sequence::mot_text`] (comma- or whitespace-separated). Every parser names the file and the 1-based
//! line of a bad row ([`Error`]).

mod depth;
mod error;
mod meta;
pub mod mot_text;
mod reader;
mod rows;
mod seqinfo;
mod series;
mod writer;

pub use depth::{DepthMap, read_depth_png, write_depth_png};
pub use error::Error;
pub use meta::{CameraMeta, GeneratorMeta, Meta, ReferenceObject, WaterMeta, WorldToCamera};
pub use reader::Sequence;
pub use rows::{
    GtBox, WORLD_HEADER, WorldRow, format_gt, format_world, parse_gt, parse_world, read_gt, read_world, write_gt,
    write_world,
};
pub use seqinfo::{MAX_FRAME_RATE, MIN_FRAME_RATE, SeqInfo};
pub use series::{SeriesRow, SeriesWriter};
pub use writer::{SequenceWriter, StagedDir, encode_jpeg};

/// Result type of the sequence module.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// File name of frame `frame` (1-based) with extension `ext` (including the dot): `000001.jpg`.
pub fn frame_file_name(frame: u32, ext: &str) -> String {
    format!("{frame:06}{ext}")
}
