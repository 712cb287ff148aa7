# point2quad — the two set-up commands are `make demo` and `make test`.
CARGO ?= cargo
BIN := target/release/point2quad
WASM_TARGET := wasm32-unknown-unknown

.PHONY: all build demo train quality test fmt fmt-check clippy wasm nodefault test-debug test-heavy bench coverage clean help

all: build

help:
	@echo "make demo   - build, reconstruct/process a shipped example, write results under out/demo"
	@echo "make test   - fmt check, clippy -D warnings, no-default-features + wasm builds, all tests"
	@echo "make bench  - benchmarks (one 'bench <name> <value> <unit>' line per figure)"
	@echo "make train  - rebuild the shipped weights (scripts/train.sh: data, seed, epochs)"
	@echo "make quality - reconstruct every ../shared/data/quads/eval mesh (10% noise and clean) and tabulate metrics"
	@echo "make coverage - candidate coverage on synthetic shapes and ../shared/data/quads/train"

build:
	$(CARGO) build --release

demo: build
	@mkdir -p out/demo
	./scripts/demo.sh $(BIN) out/demo

train: build
	./scripts/train.sh $(BIN)

quality: build
	./scripts/quality_table.sh $(BIN) ../shared/data/quads/eval 0.1
	./scripts/quality_table.sh $(BIN) ../shared/data/quads/eval 0

test: fmt-check clippy nodefault wasm test-debug test-heavy
	@echo "make test: all checks passed"

fmt:
	$(CARGO) fmt --all

fmt-check:
	$(CARGO) fmt --all -- --check

clippy:
	$(CARGO) clippy --all-targets -- -D warnings
	$(CARGO) clippy --lib --no-default-features -- -D warnings

nodefault:
	$(CARGO) build --lib --no-default-features

# The wasm check: add the target if it is missing; if that fails, say so loudly and skip.
wasm:
	@if ! rustup target list --installed 2>/dev/null | grep -q '^$(WASM_TARGET)$$'; then \
		rustup target add $(WASM_TARGET) || { \
			echo "!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!"; \
			echo "!!! WARNING: could not install $(WASM_TARGET); SKIPPING the wasm build check"; \
			echo "!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!"; \
			exit 0; }; \
	fi; \
	$(CARGO) build --lib --no-default-features --target $(WASM_TARGET)

# Fast tests in the test profile (opt-level 1); heavy tests are #[ignore]d there
# and run in release mode below.
test-debug:
	$(CARGO) test --all-targets

test-heavy:
	$(CARGO) test --release --tests -- --ignored

bench:
	$(CARGO) bench --bench kdtree
	$(CARGO) bench --bench face_net
	$(CARGO) bench --bench kpfcnn
	$(CARGO) bench --bench candidates

coverage: build
	$(BIN) coverage-report 2>/dev/null || $(CARGO) test --release --test coverage -- --ignored --nocapture

clean:
	$(CARGO) clean
	rm -rf out
