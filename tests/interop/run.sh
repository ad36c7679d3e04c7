#!/usr/bin/env bash
# Interoperability suite: python-canopen (master) against `canmotion simdrive` on a real vcan0.
#
#   tests/interop/run.sh [PYTEST ARGS...]      e.g. tests/interop/run.sh -k abort
#
# 1. cargo build (the drive binary: target/debug/canmotion, or $CARGO_TARGET_DIR/debug/...)
# 2. tools/python-env.sh (the .venv with the pinned canopen, python-can, pytest)
# 3. pytest -v -rA tests/interop inside tools/in-vcan.sh, i.e. where vcan0 exists (a UML guest on
#    machines without SocketCAN). The tests fail, not skip, when vcan0 is missing.
#
# Exit code: pytest's (0 all passed, 1 failures, ...); 124 when INTEROP_TIMEOUT expired;
# cargo's or 2 when the build or the setup fails before pytest runs.
#
# Environment:
#   INTEROP_TIMEOUT       seconds for the pytest run, guest boot included (default 300)
#   CANMOTION_BIN         drive binary (default: the one cargo build just made)
#   CANMOTION_DICTIONARY  drive dictionary TOML for the drive and the test (default: embedded)
#   VCAN_MODE etc.        see tools/README.md
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd -P)
cd "$REPO"
TIMEOUT=${INTEROP_TIMEOUT:-300}
[[ "$TIMEOUT" =~ ^[0-9]+$ ]] || { echo "run.sh: INTEROP_TIMEOUT must be seconds" >&2; exit 2; }

echo "run.sh: cargo build" >&2
cargo build >&2

VENV=$(tools/python-env.sh)
[[ -x "$VENV/bin/python" ]] || { echo "run.sh: no python in '$VENV'" >&2; exit 2; }

if [[ -z "${CANMOTION_BIN:-}" ]]; then
    export CANMOTION_BIN="${CARGO_TARGET_DIR:-$REPO/target}/debug/canmotion"
    [[ "$CANMOTION_BIN" = /* ]] || CANMOTION_BIN="$REPO/$CANMOTION_BIN"
fi
[[ -x "$CANMOTION_BIN" ]] || { echo "run.sh: no drive binary at $CANMOTION_BIN" >&2; exit 2; }

export PYTHONUNBUFFERED=1
# in-vcan.sh bounds a UML run by VCAN_TIMEOUT; timeout(1) bounds the host path too, and in-vcan.sh
# stops its guest on the SIGTERM. -B / no:cacheprovider: no .pyc or .pytest_cache in the tree.
export VCAN_TIMEOUT=$((TIMEOUT + 30))
rc=0
timeout -k 15 "$TIMEOUT" tools/in-vcan.sh "$VENV/bin/python" -B -m pytest \
    -p no:cacheprovider -v -rA --rootdir "$REPO/tests/interop" "$REPO/tests/interop" "$@" || rc=$?
if [[ $rc -eq 124 ]]; then
    echo "run.sh: TIMEOUT: the interop suite did not finish within ${TIMEOUT} s" >&2
fi
exit "$rc"
