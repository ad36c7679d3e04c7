#!/usr/bin/env bash
# Create (idempotently) the interop-test venv at .venv/ in the repo root and install the pinned
# tools/requirements-interop.txt (canopen, python-can, pytest). Prints the venv path on stdout;
# everything else goes to stderr, so `VENV=$(tools/python-env.sh)` works.
#
# Environment:
#   PYTHON   interpreter to build the venv from (default: python3 on PATH)
#
# The venv is built from the real interpreter behind python3 (not a pyenv shim), so
# .venv/bin/python also runs inside the UML guest of tools/in-vcan.sh, which sees the same files.
# Use .venv/bin/python there: a pyenv shim costs seconds per call inside the guest.
set -euo pipefail

die() {
    echo "python-env.sh: ERROR: $*" >&2
    exit 1
}
say() { echo "python-env.sh: $*" >&2; }

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)
VENV="$REPO/.venv"
REQ="$REPO/tools/requirements-interop.txt"
PY=${PYTHON:-python3}

[[ -f "$REQ" ]] || die "missing $REQ"

has_venv() { "$1" -c 'import venv, ensurepip' >/dev/null 2>&1; }

command -v "$PY" >/dev/null || die "no '$PY' on PATH"
if ! has_venv "$PY"; then
    say "'$PY' lacks venv/ensurepip: installing Debian's python3-venv"
    if [[ $(id -u) -eq 0 ]]; then
        apt-get update -q >&2 || die "apt-get update failed"
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q python3-venv >&2 ||
            die "apt-get install python3-venv failed"
    else
        die "not root: run 'apt-get install python3-venv' first"
    fi
    has_venv "$PY" || die "'$PY' still cannot create venvs after installing python3-venv"
fi
# The real interpreter, e.g. /root/.pyenv/versions/3.11.7/bin/python3 behind pyenv's shim.
BASE_PY=$("$PY" -c 'import sys; print(sys.executable)')
[[ -x "$BASE_PY" ]] || die "cannot find the interpreter behind '$PY' (got '$BASE_PY')"

mkdir -p "$VENV"
# Serialise concurrent runs (two CI jobs, two shells) on the venv directory itself, which
# `venv --clear` empties but keeps.
exec 9<"$VENV"
flock 9

STAMP="$VENV/.requirements-interop.stamp"
want="$(sha256sum "$REQ" | cut -d' ' -f1) $BASE_PY"
if [[ -f "$STAMP" && "$(cat "$STAMP")" == "$want" ]] &&
    "$VENV/bin/python" -c 'import can, canopen, pytest' >/dev/null 2>&1; then
    echo "$VENV" # up to date
    exit 0
fi

# New, stale (requirements or base interpreter changed) or broken: build it afresh.
say "creating $VENV from $BASE_PY"
"$BASE_PY" -m venv --clear "$VENV" >&2 || die "$BASE_PY -m venv $VENV failed"
say "installing $(basename "$REQ") into $VENV"
"$VENV/bin/python" -m pip install --disable-pip-version-check -q -r "$REQ" >&2 ||
    die "pip install -r $REQ failed"
"$VENV/bin/python" -c 'import can, canopen, pytest' ||
    die "the venv cannot import can, canopen, pytest after pip install"
echo "$want" >"$STAMP"
echo "$VENV"
