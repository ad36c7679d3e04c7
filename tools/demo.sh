#!/usr/bin/env bash
# The main job on the embedded default: the demo program on the demo machine (X, Y, Z on nodes
# 1, 2, 3), with simulated CiA 402 drives on the in-process bus. Writes demo.csv.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
command -v cargo >/dev/null || { echo "demo: ERROR: cargo is not installed (install Rust 1.85+ with rustup)" >&2; exit 1; }
command -v gcc >/dev/null || { apt-get update -qq && apt-get install -y -qq gcc; } \
  || { echo "demo: ERROR: a C linker (gcc) is needed and apt-get could not install it" >&2; exit 1; }
echo "demo: building canmotion (release; 3-4 minutes the first time on 2 cores, seconds after)" >&2
cargo build --release
echo "demo: running the demo program on the demo machine, simulated drives on the in-process bus (about 10 s)" >&2
exec target/release/canmotion run --log demo.csv "$@"
