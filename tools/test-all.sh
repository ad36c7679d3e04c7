#!/usr/bin/env bash
# Every test of canmotion: formatting and lints, unit, property, golden and in-process
# integration tests, then the vcan0 suite (Rust and python-canopen interop) on a real vcan0.
# Installs what it needs (Debian packages, the Python venv) and fails loudly if it cannot.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

need_apt=()
command -v cargo >/dev/null || { echo "test-all: ERROR: cargo is not installed (install Rust with rustup)" >&2; exit 1; }
command -v python3 >/dev/null || need_apt+=(python3 python3-venv)
command -v ip >/dev/null || need_apt+=(iproute2)
command -v gcc >/dev/null || need_apt+=(gcc)
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "== installing ${need_apt[*]}"
  apt-get update -qq && apt-get install -y -qq "${need_apt[@]}" \
    || { echo "test-all: ERROR: apt-get install ${need_apt[*]} failed" >&2; exit 1; }
fi
rustup component list --installed 2>/dev/null | grep -q '^rustfmt' || rustup component add rustfmt clippy

# Third-party data the tests read (never committed): say up front whether it is there, since the
# tests that need it skip quietly under `cargo test --quiet`.
corpus="$root/../shared/corpus"
if [ -d "$corpus/linuxcnc-tp" ] && [ -d "$corpus/eds" ]; then
  echo "== third-party corpus at $corpus: the corpus tests run"
else
  echo "== WARNING: no third-party corpus at $corpus: tests/gcode_corpus.rs and tests/eds_import.rs skip their corpus tests"
fi
echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy --all-targets -- -D warnings (2-4 minutes the first time)"
cargo clippy --all-targets --features vcan-tests -- -D warnings
echo "== cargo doc --no-deps (links in the documentation resolve; about a minute)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --quiet
echo "== building the tests (5-8 minutes the first time on 2 cores)"
cargo test --no-run
echo "== cargo test (unit, property, golden, in-process integration; about 6 minutes)"
cargo test --quiet
echo "== tools/in-vcan.sh without a terminal (background children, pipe and file)"
tools/in-vcan-selftest.sh
echo "== vcan0 suite (Rust and python-canopen tests on a real vcan0; about 5 minutes)"
tools/vcan-suite.sh
echo "== all tests passed"
