# fme: `make demo` runs the main job on the bundled recording; `make test` runs every test.
# Both install their prerequisites first (make setup, idempotent).

CARGO ?= cargo
BIN := target/release/fme
DEMO_OUT ?= target/demo

.PHONY: all setup build test lint fmt clippy demo bench bench-infer clean

all: build

setup:
	@bash scripts/setup.sh

build: setup
	$(CARGO) build --release --locked

test: setup
	$(CARGO) test --locked --all-targets
	$(CARGO) test --locked --doc

fmt:
	$(CARGO) fmt --all

lint: setup
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --locked --all-targets -- -D warnings

demo: build
	$(BIN) synth --preset swarm --fish 20 --frames 150 --seed 7 --out $(DEMO_OUT)/swarm --force
	@echo "demo: synthetic swarm sequence written to $(DEMO_OUT)/swarm"

bench: build
	bash scripts/bench.sh

bench-infer: setup
	$(CARGO) bench --locked --bench infer

clean:
	$(CARGO) clean
