# fme: `make demo` runs the main job on the bundled recording; `make test` runs every test.
# Both install their prerequisites first (make setup, idempotent).

CARGO ?= cargo
BIN := target/release/fme

.PHONY: all setup setup-training build install static static-copy static-check test lint fmt clippy demo demo-run bench bench-synth bench-core bench-daemon bench-track bench-infer bench-history bench-mqtt bench-backends bench-anchors four-groups clean

all: build

setup:
	@bash scripts/setup.sh

# The training Python stack (training/requirements.txt, about 6 GB, in VENV, default /tmp/venv-infer):
# the fine-tuning test needs it; `make demo` does not.
setup-training:
	@bash scripts/setup_training.sh

build: setup
	$(CARGO) build --release --locked

# Installs the release build, models, ONNX Runtime, the systemd unit and the docs under PREFIX
# (below DESTDIR for packaging), and BOARD's config as /etc/fme/fme.toml unless one is there
# (scripts/install.sh; docs/deployment.md#installing).
PREFIX ?= /usr/local
install: build
	PREFIX="$(PREFIX)" DESTDIR="$(DESTDIR)" BOARD="$(BOARD)" STRIP="$(STRIP)" bash scripts/install.sh $(BIN)

# One static executable: the pure-Rust backend (tract) and the bundled models inside,
# glibc's static-pie; nothing else needed beside it (docs/deployment.md#one-static-binary). For an
# aarch64 board: STATIC_TARGET=aarch64-unknown-linux-gnu STRIP=aarch64-linux-gnu-strip with the
# target's std and a cross linker (see there).
STATIC_TARGET ?= x86_64-unknown-linux-gnu
STRIP ?= strip
STATIC_CARGO := RUSTFLAGS="$(RUSTFLAGS) -C target-feature=+crt-static" $(CARGO)
STATIC_FLAGS := --release --locked --no-default-features --features tract,embed-models --target $(STATIC_TARGET)
STATIC_BUILT = $(or $(CARGO_TARGET_DIR),target)/$(STATIC_TARGET)/release/fme
static: setup
	$(STATIC_CARGO) build $(STATIC_FLAGS) --bin fme
	@$(MAKE) --no-print-directory static-copy
static-copy:
	mkdir -p target/static
	cp $(STATIC_BUILT) target/static/fme
	$(STRIP) target/static/fme
	@ls -l target/static/fme

# The static binary checked (CI runs it after `make test`): ldd, the bundled recording from an empty
# directory (scripts/static_check.sh), tract's parity with ONNX Runtime (tests/backend_parity.rs,
# against the reference tests/backend_reference.rs keeps), and the unit and model tests under tract
# (eval_recorded runs the static binary itself). The binary is built by the parity test's
# build: cargo unifies the dev-dependencies' features into a test build, so a separate `cargo build`
# would compile most dependencies twice. Same sources, features and flags as `make static`.
STATIC_TESTS := --workspace --lib --test backend_parity --test infer_onnx --test pipeline_e2e --test eval_recorded \
	--test pipeline_alloc
static-check: setup
	$(STATIC_CARGO) test $(STATIC_FLAGS) $(STATIC_TESTS) --no-run
	@$(MAKE) --no-print-directory static-copy
	bash scripts/static_check.sh target/static/fme
	$(STATIC_CARGO) test $(STATIC_FLAGS) $(STATIC_TESTS)

# Unit, integration and doc tests. Benchmarks are built by `make lint` (clippy --all-targets) but
# only run by `make bench`: a benchmark measures speed, it is not a test.
test: setup setup-training
	$(CARGO) test --locked --workspace --lib --bins --tests
	$(CARGO) test --locked --workspace --doc

fmt:
	$(CARGO) fmt --all

# The second clippy lints the static build's code paths (feature tract, no ONNX Runtime): about a
# minute more, the dependencies' checks are shared with the first.
lint: setup
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --locked --workspace --all-targets -- -D warnings
	$(CARGO) clippy --locked --workspace --no-default-features --features tract,embed-models --all-targets -- -D warnings

# The main job on the bundled recording and models: `fme run` (detector + tracker + depth + eq. 1-5) with a
# Modbus TCP server on 127.0.0.1:5020 and a live one-line view, then `fme eval` of the same models against
# the recording's ground truth. No camera, no PLC needed.
demo: build
	$(MAKE) --no-print-directory demo-run
	$(BIN) eval --sequence $(DEMO_SEQ) --boxes model --depth model

# Every benchmark (speed is measured here, never in tests). mot15 parity needs ../shared beside the repo.
bench: bench-synth bench-core bench-track bench-infer bench-daemon bench-history

bench-synth: setup
	$(CARGO) bench --locked --bench synth
# Per-frame cost of post-processing + motion; a benchmark, not a test.
bench-core:
	$(CARGO) bench --locked --bench core
# `fme run` on a recording (default: the bundled one) with a Modbus TCP server on 127.0.0.1:5020 and a
# live one-line view; stops after DEMO_FRAMES frames (real time: 15 s). Read it with mbpoll (docs/plc-integration.md).
DEMO_SEQ ?= tests/data/swarm20
DEMO_FRAMES ?= 450
# The web page (docs/web.md) on this box only while the demo runs.
DEMO_WEB ?= 127.0.0.1:8080
demo-run: build
	@echo "demo: the web page is at http://$(DEMO_WEB)/ while fme runs (docs/web.md)"
	$(BIN) run --config config/fme.toml --source $(DEMO_SEQ) --modbus-listen 127.0.0.1:5020 --set 'web.listen="$(DEMO_WEB)"' --live --max-frames $(DEMO_FRAMES)

# The whole daemon with the real pipeline on the bundled recording: real-time replay (drops, latency,
# CPU, RSS) and a long as-fast-as-possible run (memory flatness); then its CPU over an RTSP camera
# against the folder (daemon_rtsp) and with the web page open against without (daemon_web).
bench-daemon: setup
	$(CARGO) bench --locked --bench daemon_replay
	$(CARGO) bench --locked --bench daemon_rtsp
	$(CARGO) bench --locked --bench daemon_web
# Tracker speed and quality; mot15 parity/quality need ../shared/benchmarks/mot15 (and the
# motmetrics venv for quality: see scripts/check_motmetrics.py).
bench-track: build
	$(CARGO) bench --locked --bench track
	$(CARGO) bench --locked --bench track_quality
	bash scripts/mot15_parity.sh $(BIN)
# Activity history cost per row and disk use per day (docs/history.md).
bench-history:
	$(CARGO) bench --locked --bench history
# 50 simulated boxes publishing activity JSON at 1 Hz for 60 s through one local mosquitto, one
# subscriber: messages/s, lost, broker CPU, end-to-end latency (docs/mqtt.md).
bench-mqtt: setup
	$(CARGO) bench --locked --bench mqtt_fleet
bench-infer: setup
	$(CARGO) bench --locked --bench infer
# ONNX Runtime against tract in one run: per-inference time of both networks (int8 and fp32) and the
# pipeline's CPU at 30 fps, as ratios (docs/benchmarks.md#backends).
bench-backends: setup
	$(CARGO) bench --locked --features tract --bench backends
# The anchor models (YOLO11n) timed beside the bundled int8 files: this machine against the
# anchors' (needs the ~6 GB Python stack of training/requirements.txt; not part of `bench`).
bench-anchors:
	bash scripts/anchor_timing.sh
# The paper's four groups (GT/predicted boxes x GT/estimated depth) with the bundled models on held-out
# synthetic sequences, two sets of seeds (about 20 minutes; sequences cached in target/four-groups).
four-groups: build
	SEED_BASE=7021 bash scripts/four_groups.sh
	SEED_BASE=7041 bash scripts/four_groups.sh

clean:
	$(CARGO) clean
