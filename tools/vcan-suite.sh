#!/usr/bin/env bash
# The vcan0 suite: the Rust tests of tests/vcan.rs (gateway and simulated drives as separate
# processes) and the python-canopen interop tests of tests/interop/, all on a real vcan0.
#
# Builds everything on the host, then runs the suite once where vcan0 exists: directly when the
# host has vcan, inside User-Mode Linux otherwise (tools/in-vcan.sh). The exit code is the
# suite's; the whole run is bounded by VCAN_TIMEOUT (default 900 s).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

echo "== vcan suite: building on the host"
# The binary's path from cargo's own report (CARGO_TARGET_DIR may move it).
bin=$(cargo build --message-format=json 2>/dev/null \
  | python3 -c 'import json,sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] == "canmotion":
        print(m["executable"])')
if [ -z "$bin" ] || [ ! -x "$bin" ]; then
  echo "vcan-suite: ERROR: could not build the canmotion binary" >&2
  exit 1
fi
# The path of the vcan test binary, from cargo's own report.
vcan_bin=$(cargo test --features vcan-tests --test vcan --no-run --message-format=json 2>/dev/null \
  | python3 -c 'import json,sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] == "vcan":
        print(m["executable"])')
if [ -z "$vcan_bin" ] || [ ! -x "$vcan_bin" ]; then
  echo "vcan-suite: ERROR: could not build the vcan test binary" >&2
  exit 1
fi
venv=$(tools/python-env.sh)

export CANMOTION_BIN="$bin"
# Inside User-Mode Linux the whole guest runs on one host thread: a SCHED_FIFO cyclic thread
# there starves the simulated drives' process (measured: heartbeats 150 ms late). Normal
# scheduling in the guest; on a host with vcan the default (FIFO 80) applies.
if [ ! -e /sys/class/net/vcan0 ] && ! { modprobe vcan 2>/dev/null && ip link add dev vcan0 type vcan 2>/dev/null; }; then
  export CANMOTION_RT_PRIORITY="${CANMOTION_RT_PRIORITY:-0}"
fi
export VCAN_TIMEOUT="${VCAN_TIMEOUT:-900}"
rust_log=$(mktemp /tmp/vcan-rust.XXXXXX)
echo "== vcan suite: running on vcan0 ($vcan_bin, python-canopen from $venv)"
exec tools/in-vcan.sh sh -c '
  set -u
  ip -details link show vcan0 | head -3
  # Page the binaries in before anything runs on a deadline: inside User-Mode Linux the host
  # file system is read lazily, and a first run otherwise stalls for hundreds of ms on page
  # faults in the middle of its motion.
  cat "$1" "$CANMOTION_BIN" > /dev/null
  rc=0
  echo "== Rust vcan0 tests (tests/vcan.rs)"
  # Its output is kept in a file too: CI shows the end of the log, so the failures are
  # repeated after the python-canopen tests.
  { "$1" --test-threads=1 2>&1 || echo "vcan-suite: FAILED: the Rust vcan0 tests"; } | tee "$3"
  rust_failed=0
  grep -q "^vcan-suite: FAILED" "$3" && { rust_failed=1; rc=1; }
  if [ -d tests/interop ]; then
    echo "== python-canopen interop tests on vcan0 (tests/interop)"
    "$2/bin/python" -m pytest -v -rA -p no:cacheprovider tests/interop || rc=1
  else
    echo "vcan-suite: ERROR: tests/interop is missing" >&2; rc=1
  fi
  if [ "$rust_failed" = 1 ]; then
    echo "== the Rust vcan0 tests failed; their failures again (the end of $3):"
    sed -n "/^failures:/,\$p" "$3" | tail -n 80
  fi
  exit $rc
' vcan-suite "$vcan_bin" "$venv" "$rust_log"
