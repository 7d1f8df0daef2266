//! The daemon's edges in one test binary sharing [`support`]: start-up and the command line,
//! capture of bad frames, a small, full or stalled disk under the state directory, the serial console over a pseudo-terminal, the whole daemon end to end,
//! the Modbus roles (in-process PLC peers), the Prometheus endpoint and the calibration reload on SIGHUP. The real pipeline has its
//! own tests (`pipeline_e2e.rs`); the in-process tests here use the frame-difference test double so
//! they need no models (the `fme run` ones of `cli`, `history` and `metrics` use the real models).
//! Two daemon tests have binaries of their own, including `support` by path: `daemon_alloc` (its
//! counting allocator is process-wide) and `daemon_watchdog` (it sets the process's systemd variables).

mod bad_frames;
mod camera_back;
mod cli;
mod console_pty;
mod console_socat;
mod disk;
mod e2e;
mod history;
mod metrics;
mod metrics_text;
mod modbus_client;
mod modbus_server;
mod reload;
mod support;
