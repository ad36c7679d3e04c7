#!/usr/bin/env bash
# SYNC timing benchmark on vcan0: `canmotion simdrive` and `canmotion run` as separate processes,
# one run per machine file, each streaming a generated back-and-forth program for at least
# SECONDS; prints the SYNC period statistics `run` measures from the kernel's receive timestamps
# (p50 / p99 / p99.9 / max |deviation| from the cycle) and the cyclic thread's overruns.
#
#   tools/sync-bench.sh [SECONDS]        # default 60
#
# Environment:
#   BENCH_MACHINES  machine files under dictionaries/machines/, without .toml
#                   (default "bench-1ax-1ms bench-3ax-1ms bench-6ax-1ms bench-6ax-2ms";
#                   bench-6ax-1ms is refused by the bus-load admission, and the table says so)
#   BENCH_PROFILE   cargo profile of the binary: release (default) or dev
#   BENCH_OUT       also write the table to this file
#   CANMOTION_RT_PRIORITY  passed on (default 0 where the suite runs inside User-Mode Linux: its
#                   single-CPU guest runs every process on one host thread, and a SCHED_FIFO
#                   cyclic thread there starves the simulated drives)
#
# Runs where vcan0 exists: directly on a host with vcan, inside User-Mode Linux otherwise
# (tools/in-vcan.sh). Not part of the vcan suite: it takes a minute per machine.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

secs=${1:-60}
[[ "$secs" =~ ^[0-9]+$ ]] && ((secs > 0)) || {
    echo "sync-bench: SECONDS must be a positive whole number, got '$secs'" >&2
    exit 2
}
machines=${BENCH_MACHINES:-bench-1ax-1ms bench-3ax-1ms bench-6ax-1ms bench-6ax-2ms}
profile=${BENCH_PROFILE:-release}
case "$profile" in
release) cargo_args=(--release) ;;
dev) cargo_args=() ;;
*)
    echo "sync-bench: BENCH_PROFILE must be release or dev" >&2
    exit 2
    ;;
esac

echo "== sync-bench: building ($profile)" >&2
bin=$(cargo build "${cargo_args[@]}" --message-format=json 2>/dev/null |
    python3 -c 'import json,sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] == "canmotion":
        print(m["executable"])')
if [ -z "$bin" ] || [ ! -x "$bin" ]; then
    echo "sync-bench: ERROR: could not build the canmotion binary" >&2
    exit 1
fi

work=$(mktemp -d "${TMPDIR:-/tmp}/sync-bench.XXXXXX")
trap 'rm -rf "$work"' EXIT

# One program per machine: every one of X, Y, Z the machine has goes back and forth (100 mm,
# 60 mm, 2 mm) at a feed of 20 mm/s, at least 5 s a move, until SECONDS are covered. The timing
# does not depend on the speed; a slow feed keeps a stall of the guest (tens of ms on a busy
# host) inside the drives' following-error window, so that it shows in the figures instead of
# ending the run.
moves=$((secs / 5 + 1))
for m in $machines; do
    f="dictionaries/machines/$m.toml"
    [ -f "$f" ] || {
        echo "sync-bench: no machine file $f" >&2
        exit 1
    }
    has() { grep -q "^name = \"$1\"" "$f"; }
    {
        echo "G21 G90"
        for ((i = 0; i < moves; i++)); do
            if ((i % 2 == 0)); then line="G1 X100"; else line="G1 X0"; fi
            if has Y; then if ((i % 2 == 0)); then line+=" Y60"; else line+=" Y0"; fi; fi
            if has Z; then if ((i % 2 == 0)); then line+=" Z-2"; else line+=" Z0"; fi; fi
            echo "$line F1200"
        done
        echo "M2"
    } >"$work/$m.ngc"
    grep '^node = ' "$f" | sed 's/node = //' | tr '\n' ' ' >"$work/$m.nodes"
done

if [ ! -e /sys/class/net/vcan0 ] && ! { modprobe vcan 2>/dev/null && ip link add dev vcan0 type vcan 2>/dev/null; }; then
    export CANMOTION_RT_PRIORITY="${CANMOTION_RT_PRIORITY:-0}"
fi
n_machines=$(wc -w <<<"$machines")
export VCAN_TIMEOUT="${VCAN_TIMEOUT:-$((n_machines * (secs * 2 + 60) + 120))}"

echo "== sync-bench: $secs s per machine on vcan0: $machines" >&2
tools/in-vcan.sh sh -c '
  bin=$1 work=$2; shift 2
  cat "$bin" >/dev/null # page the binary in before anything runs on a deadline
  for m in "$@"; do
    nodes=""
    for n in $(cat "$work/$m.nodes"); do nodes="$nodes --node $n"; done
    "$bin" simdrive --bus vcan0 $nodes 2>"$work/$m.sim" &
    sim=$!
    i=0
    until grep -q "Ctrl-C to stop" "$work/$m.sim" 2>/dev/null; do
      i=$((i + 1))
      if [ $i -gt 200 ]; then echo "simdrive for $m did not start" >"$work/$m.err"; break; fi
      sleep 0.05
    done
    "$bin" run --bus vcan0 --machine "dictionaries/machines/$m.toml" "$work/$m.ngc" \
      >"$work/$m.out" 2>"$work/$m.err"
    echo $? >"$work/$m.rc"
    kill $sim 2>/dev/null; wait $sim 2>/dev/null
  done
  exit 0
' sync-bench "$bin" "$work" $machines >&2

{
    echo "SYNC period |deviation| from the kernel's receive timestamps on vcan0, $secs s per machine"
    echo "($(date -u +%Y-%m-%d), $(uname -n), profile $profile, CANMOTION_RT_PRIORITY=${CANMOTION_RT_PRIORITY:-80})"
    printf '%-15s %5s %7s %8s %8s %8s %8s %8s %8s %9s  %s\n' machine axes cycle ran periods p50 p99 p99.9 max overruns result
    for m in $machines; do
        f="dictionaries/machines/$m.toml"
        axes=$(grep -c '^\[\[axis\]\]' "$f")
        cyc=$(sed -n 's/^cycle_us = \([0-9]*\).*/\1/p' "$f")
        rc=$(cat "$work/$m.rc" 2>/dev/null || echo "?")
        # A run that stops on a fault prints its figures up to the stop on stderr.
        sync=$(cat "$work/$m.out" "$work/$m.err" 2>/dev/null | grep '^SYNC period' || true)
        cycles=$(cat "$work/$m.out" "$work/$m.err" 2>/dev/null | grep '^cycles' || true)
        if [ -n "$sync" ]; then
            # "SYNC period  N periods of T µs from ...: |deviation| p50 A µs, p99 B µs, p99.9 C µs, max D µs (...)"
            read -r periods p50 p99 p999 max < <(sed -E 's/^SYNC period +([0-9]+) periods.*p50 ([0-9]+) µs, p99 ([0-9]+) µs, p99\.9 ([0-9]+) µs, max ([0-9]+) µs.*/\1 \2 \3 \4 \5/' <<<"$sync")
            overruns=$(sed -E 's/.*\(([0-9]+) overruns\).*/\1/' <<<"$cycles")
            all=$(sed -E 's/.* ([0-9]+) in all.*/\1/' <<<"$cycles")
            # Time the cyclic thread ran: every cycle and every deadline an overrun skipped.
            ran=$(((all + overruns) * cyc / 1000000))
            result=$([ "$rc" = 0 ] && echo ok || echo "stopped: $(tail -1 "$work/$m.err")")
            printf '%-15s %5s %5sµs %7ss %8s %6sµs %6sµs %6sµs %6sµs %9s  %s\n' "$m" "$axes" "$cyc" "$ran" "$periods" "$p50" "$p99" "$p999" "$max" "$overruns" "$result"
        else
            printf '%-15s %5s %5sµs %8s %8s %8s %8s %8s %8s %9s  %s\n' "$m" "$axes" "$cyc" - - - - - - - "not run: $(tail -1 "$work/$m.err" 2>/dev/null)"
        fi
    done
} | tee "${BENCH_OUT:-/dev/null}"
