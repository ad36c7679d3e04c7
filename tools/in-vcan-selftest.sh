#!/usr/bin/env bash
# Self-test of tools/in-vcan.sh without a terminal: output to a pipe and to a file, a command
# that leaves a child running in the background, and its exit code passed through. Before the
# fix the pipe case hung until VCAN_TIMEOUT (the guest waited on the background child).
# Then: vector registers (AVX, AVX-512) survive the guest's context switches between threads
# (tools/uml-fp-check.c), which on an AMX host go through tools/uml-xstate-shim.c.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
fail() { echo "in-vcan-selftest: FAIL: $*" >&2; exit 1; }
export VCAN_TIMEOUT=120
cmd='sleep 1000 & echo out-line; echo err-line >&2; ip link show vcan0 >/dev/null && exit 7'

start=$(date +%s)
set +e
out=$(tools/in-vcan.sh sh -c "$cmd" | cat)
rc=${PIPESTATUS[0]}
set -e
took=$(($(date +%s) - start))
[ "$rc" = 7 ] || fail "to a pipe: exit code $rc, expected 7 (took ${took}s; output: $out)"
[ "$took" -lt 60 ] || fail "to a pipe: took ${took}s: the guest waited on the background child"
grep -qx out-line <<<"$out" || fail "to a pipe: stdout missing: $out"
grep -qx err-line <<<"$out" || fail "to a pipe: stderr missing: $out"

tmp=$(mktemp)
trap 'rm -f "$tmp"' EXIT
set +e
tools/in-vcan.sh sh -c "$cmd" >"$tmp" 2>&1
rc=$?
set -e
[ "$rc" = 7 ] || fail "to a file: exit code $rc, expected 7"
grep -qx out-line "$tmp" || fail "to a file: stdout missing: $(cat "$tmp")"

mkdir -p .uml
check=$(mktemp "$root/.uml/fp-check.XXXXXXXX")
trap 'rm -f "$tmp" "$check"' EXIT
cc -O2 -Wall -Werror -pthread -o "$check" tools/uml-fp-check.c || fail "building tools/uml-fp-check.c failed"
set +e
fp=$(tools/in-vcan.sh "$check" 2>&1)
rc=$?
set -e
[ "$rc" = 0 ] || fail "vector registers across guest context switches: exit code $rc: $fp"
echo "in-vcan-selftest: ok (pipe and file, background child ended, exit code passed through; ${took}s; ${fp#uml-fp-check: })"
