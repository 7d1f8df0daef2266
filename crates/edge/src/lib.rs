//! # fme-edge: the box's edges
//!
//! Everything that touches the outside world, around the pure core (`fme-core`): the one
//! configuration file, frame sources, the outputs to the PLC and the fleet, the field console, the
//! black box and the history, and the daemon that runs them.
//!
//! | module | job |
//! |---|---|
//! | [`config`] | the one configuration file (`config/fme.toml`): load, `--set`, checks |
//! | [`calibration`] | the calibration file (`meta.json` format) the pipeline's metric fit uses |
//! | [`sequence`] | MOTChallenge sequences with fme's ground-truth extras: read, write, replay |
//! | [`capture`] | V4L2 cameras and recorded sequences as frame sources, the frame queue |
//! | [`status`] | health, status bits and fault codes shared by the outputs |
//! | [`output`] | Modbus (four roles), serial line, MQTT, Prometheus metrics |
//! | [`console`] | the serial field-diagnostics console |
//! | [`history`] | a daily CSV row per output update, hourly summaries, day plots |
//! | [`record`] | the black box: ring of frames, frozen recordings, snapshots |
//! | [`service`] | the daemon: threads, watchdog, signals, publishing |
//! | [`draw`] | text and overlays on images and plots |
//!
//! Low-level helpers: [`backoff`] (reconnect delays) and [`civil`] (calendar dates).

#![warn(missing_docs)]

pub mod backoff;
pub mod calibration;
pub mod capture;
pub mod civil;
pub mod config;
pub mod console;
pub mod draw;
pub mod history;
pub mod output;
pub mod record;
pub mod sequence;
pub mod service;
pub mod status;
pub mod web;
