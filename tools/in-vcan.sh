#!/usr/bin/env bash
# Run a command with a real, up `vcan0` available; exit with the command's exit code.
#
#   tools/in-vcan.sh CMD [ARGS...]
#
# Where the host kernel has SocketCAN (vcan0 already up, or `modprobe vcan` plus
# `ip link add dev vcan0 type vcan` work), CMD runs directly on the host. Otherwise CMD runs
# inside a User-Mode Linux guest (Debian's user-mode-linux package) that sees the host's `/`
# read-write through hostfs and has its own real vcan0; see shared/docs/vcan-in-ci.md.
#
# In the guest, CMD's stdout and stderr both go to the guest console, which is this script's
# stdout (live). CMD's stdin is empty. The guest ends when CMD ends: processes CMD left running in
# the background are ended then (so `CMD | cat` or `CMD > file` returns).
#
# Environment:
#   VCAN_TIMEOUT   seconds bounding the whole UML run (default 900)
#   VCAN_MODE      auto (default) | host | uml   (uml: always boot UML, even if the host has vcan)
#   VCAN_MEM       guest memory (default 1G)
#   VCAN_PASS_ENV  extra variable names (space-separated) to pass into the guest
#   VCAN_VERBOSE   1: show the guest kernel's boot messages and timings
#   VCAN_CPU       host CPU to pin the guest to (default: the last allowed one; "none": unpinned)
#   VCAN_NICE      0: leave the guest at the default priority (default 1: nice -10 where allowed)
#   VCAN_KEEP      1: keep the temp dir under .uml/ (init script, exit code) for debugging
set -euo pipefail

die() {
    echo "in-vcan.sh: ERROR: $*" >&2
    exit 1
}
VERBOSE=${VCAN_VERBOSE:-0}
[[ "$VERBOSE" == 1 ]] || VERBOSE=0
note() {
    if [[ "$VERBOSE" == 1 ]]; then echo "in-vcan.sh: $*" >&2; fi
}

[[ $# -ge 1 ]] || die "usage: tools/in-vcan.sh CMD [ARGS...]"

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)
TIMEOUT=${VCAN_TIMEOUT:-900}
MODE=${VCAN_MODE:-auto}
[[ "$TIMEOUT" =~ ^[0-9]+$ ]] || die "VCAN_TIMEOUT must be a whole number of seconds, got '$TIMEOUT'"

# ---------------------------------------------------------------- host path
host_vcan_up() {
    [[ -r /sys/class/net/vcan0/flags ]] || return 1
    local flags
    flags=$(cat /sys/class/net/vcan0/flags)
    (((flags & 1) == 1)) # IFF_UP
}

host_try_vcan() {
    host_vcan_up && return 0
    modprobe vcan >/dev/null 2>&1 || true
    if [[ ! -e /sys/class/net/vcan0 ]]; then
        ip link add dev vcan0 type vcan >/dev/null 2>&1 || return 1
    fi
    ip link set dev vcan0 up >/dev/null 2>&1 || return 1
    host_vcan_up
}

case "$MODE" in
auto)
    if host_try_vcan; then
        note "host has vcan0 up: running directly"
        exec "$@"
    fi
    ;;
host)
    host_try_vcan || die "VCAN_MODE=host but the host cannot bring up vcan0"
    exec "$@"
    ;;
uml) ;;
*) die "VCAN_MODE must be auto, host or uml, got '$MODE'" ;;
esac

# ---------------------------------------------------------------- UML path
ensure_uml() {
    if command -v linux.uml >/dev/null && command -v busybox >/dev/null; then
        return 0
    fi
    echo "in-vcan.sh: linux.uml/busybox missing: installing user-mode-linux busybox-static" >&2
    command -v apt-get >/dev/null || die "no apt-get: install Debian's user-mode-linux and busybox-static by hand"
    local sudo=()
    if [[ $(id -u) -ne 0 ]]; then
        command -v sudo >/dev/null || die "not root and no sudo: cannot apt-get install user-mode-linux"
        sudo=(sudo)
    fi
    "${sudo[@]}" apt-get update -q >&2 || die "apt-get update failed"
    DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -q user-mode-linux busybox-static >&2 ||
        die "apt-get install user-mode-linux busybox-static failed"
    command -v linux.uml >/dev/null || die "linux.uml still missing after apt-get install"
    command -v busybox >/dev/null || die "busybox still missing after apt-get install"
}
ensure_uml
command -v ip >/dev/null || die "ip (iproute2) missing on the host; the guest uses the host's binaries"

MODDIR=$(find /usr/lib/uml/modules -mindepth 2 -maxdepth 2 -type d -name kernel 2>/dev/null | sort | tail -1)
[[ -n "$MODDIR" ]] || die "no UML kernel modules under /usr/lib/uml/modules"
for k in net/can/can.ko net/can/can-raw.ko net/can/can-bcm.ko drivers/net/can/dev/can-dev.ko drivers/net/can/vcan.ko; do
    [[ -f "$MODDIR/$k" ]] || die "UML module missing: $MODDIR/$k"
done

# Private temp dir under the repo (git-ignored); the guest sees it at the same path.
mkdir -p "$REPO/.uml"

# Bookworm's UML 6.1 cannot restore a guest task's FP registers on a host CPU whose XSAVE area
# is larger than AVX's 832 bytes (AVX-512, AMX): the guest panics at boot with "ptrace set fp
# regs failed, errno = 14". tools/uml-xstate-shim.c, preloaded into linux.uml, moves the whole
# area; on other hosts it changes nothing. Built here (a C compiler is on the machine for the
# crates that build C), once per source change; temp file + rename, so concurrent runs agree.
SHIM_SRC="$REPO/tools/uml-xstate-shim.c"
SHIM="$REPO/.uml/uml-xstate-shim.so"
if [[ ! -f "$SHIM" || "$SHIM_SRC" -nt "$SHIM" ]]; then
    command -v cc >/dev/null || die "no C compiler (cc) to build $SHIM_SRC: apt-get install gcc libc6-dev"
    shim_tmp=$(mktemp "$REPO/.uml/shim.XXXXXXXX")
    cc -O2 -Wall -Werror -shared -fPIC -o "$shim_tmp" "$SHIM_SRC" -ldl ||
        { rm -f "$shim_tmp"; die "building $SHIM_SRC failed"; }
    mv -f "$shim_tmp" "$SHIM"
fi
WORK=$(mktemp -d "$REPO/.uml/run.XXXXXXXX")
# shellcheck disable=SC2317 # called by the trap
cleanup() {
    if [[ "${VCAN_KEEP:-0}" == 1 ]]; then
        echo "in-vcan.sh: kept $WORK" >&2
    else
        rm -rf "$WORK"
    fi
}
trap cleanup EXIT

# Single-quote a string for /bin/sh.
sq() {
    local s=${1//\'/\'\\\'\'}
    printf "'%s'" "$s"
}

# Environment for the guest: it starts with an empty one.
# Host PATH plus cargo's and the sbin dirs (ip, modprobe), without duplicates.
GUEST_PATH=$(printf '%s' "$HOME/.cargo/bin:$PATH:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin" |
    awk -v RS=: -v ORS=: 'length($0) && !seen[$0]++' | sed 's/:$//')
PASS=(CI RUST_BACKTRACE RUST_LOG RUST_LIB_BACKTRACE RUST_TEST_THREADS CARGO_TARGET_DIR CARGO_HOME
    CARGO_TERM_COLOR RUSTUP_HOME RUSTUP_TOOLCHAIN PYTHONPATH PYTHONUNBUFFERED VIRTUAL_ENV
    PYENV_ROOT PYENV_VERSION USER LOGNAME LANG LC_ALL TZ TERM NO_COLOR)
# shellcheck disable=SC2206 # word splitting of the user's list is intended
PASS+=(${VCAN_PASS_ENV:-})
while IFS= read -r name; do PASS+=("$name"); done < <(compgen -e | grep '^CANMOTION_' || true)

CMDLINE=""
for a in "$@"; do CMDLINE+=" $(sq "$a")"; done

TTY_OUT=0
if [[ -t 1 ]]; then TTY_OUT=1; fi
INIT="$WORK/init.sh"
RCFILE="$WORK/exit-code"
{
    echo '#!/bin/sh'
    echo '# generated by tools/in-vcan.sh: PID 1 of the UML guest, which starts with an empty env'
    echo "export PATH=$(sq "$GUEST_PATH") HOME=$(sq "$HOME")"
    for name in "${PASS[@]}"; do
        if [[ -n "${!name+x}" ]]; then echo "export $name=$(sq "${!name}")"; fi
    done
    echo "M=$(sq "$MODDIR") D=$(sq "$PWD") RCFILE=$(sq "$RCFILE") VERBOSE=$VERBOSE TTY_OUT=$TTY_OUT"
    echo "run_cmd() {$CMDLINE; }"
    cat <<'EOF'
unset mem uml_dir # the kernel hands unknown boot parameters to init as env variables
stty -onlcr </dev/console 2>/dev/null # no CRLF in the host's logs
mount -t proc proc /proc
mount -t sysfs sys /sys
# /dev is the guest's own devtmpfs: give it /dev/shm (POSIX semaphores, e.g. Python's
# multiprocessing) and /dev/pts. Do NOT mount over /tmp: the guest's /tmp is the host's.
mkdir -p /dev/shm /dev/pts
mount -t tmpfs -o mode=1777 shm /dev/shm
mount -t devpts -o gid=5,mode=620 devpts /dev/pts
fail() {
    echo "in-vcan guest: $*" >&2
    busybox sync
    busybox poweroff -f
}
# Order matters: can before can-raw/can-bcm, can-dev before vcan.
for k in net/can/can.ko net/can/can-raw.ko net/can/can-bcm.ko \
    drivers/net/can/dev/can-dev.ko drivers/net/can/vcan.ko; do
    busybox insmod "$M/$k" || fail "insmod $k failed"
done
# The plug qdisc holds vcan0's transmit queue full (ENOBUFS) for the tests of a blocked bus.
busybox insmod "$M/net/sched/sch_plug.ko" 2>/dev/null || true
ip link set lo up || fail "lo up failed"
{ ip link add dev vcan0 type vcan && ip link set vcan0 up; } || fail "vcan0 setup failed"
if [ "$VERBOSE" = 1 ]; then
    echo "in-vcan guest: vcan0 up at uptime $(cut -d' ' -f1 /proc/uptime) s" >&2
fi
cd "$D" || fail "cannot cd to $D"
# The guest ends when CMD ends, with whatever CMD left running in the background (a simdrive
# started with `&`): every process but this init (and the console reader) is ended first.
end_the_rest() {
    for sig in TERM KILL; do
        for p in /proc/[0-9]*; do
            p=${p#/proc/}
            [ "$p" = 1 ] || [ "$p" = "${1:-}" ] || kill -"$sig" "$p" 2>/dev/null
        done
        [ "$sig" = KILL ] || sleep 0.2
    done
}
# The console is a tty. When the host's stdout is not one (CI), give CMD a pipe as on the host:
# no colour codes or tty-only behaviour in the logs. The pipe is a FIFO read by cat, not a shell
# pipeline: a pipeline would wait for every holder of its write end, CMD's background children
# included, and never end.
if [ "$TTY_OUT" = 1 ]; then
    run_cmd </dev/null
    echo "$?" >"$RCFILE.tmp"
    end_the_rest
else
    mkfifo /dev/shm/in-vcan-out || fail "mkfifo failed"
    cat /dev/shm/in-vcan-out &
    reader=$!
    run_cmd </dev/null >/dev/shm/in-vcan-out 2>&1
    echo "$?" >"$RCFILE.tmp"
    end_the_rest "$reader"
    wait "$reader"
fi
mv "$RCFILE.tmp" "$RCFILE"
busybox sync # hostfs writes go through the guest's page cache
busybox poweroff -f
EOF
} >"$INIT"
chmod +x "$INIT"

KERNEL_LOG=(quiet loglevel=0)
if [[ "$VERBOSE" == 1 ]]; then KERNEL_LOG=(); fi

# UML's console (con0) writes to its fd 1. That fd is a FIFO read by cat, not our stdout itself:
# UML puts a tty on fd 1 into raw mode (Ctrl-C would no longer interrupt), and it cannot poll a
# regular file.
mkfifo "$WORK/console"
cat "$WORK/console" &

# Ctrl-C / CI cancellation: stop the guest rather than leave it running until the timeout.
uml_pid=""
interrupted=""
# shellcheck disable=SC2317 # called by the traps
on_signal() {
    interrupted=$1
    if [[ -n "$uml_pid" ]]; then kill -TERM "$uml_pid" 2>/dev/null || true; fi
}
trap 'on_signal INT' INT
trap 'on_signal TERM' TERM
trap 'on_signal HUP' HUP

note "booting UML (timeout ${TIMEOUT}s), init $INIT"
start=$(date +%s.%N)
# timeout puts UML in its own process group and signals the whole group (UML's helper processes
# too) on expiry or when it is itself sent TERM/INT/HUP; -k: SIGKILL 10 s later if still alive.
# UML backs the guest's memory with a file in TMPDIR: on tmpfs it stays in RAM. On disk (/tmp)
# the host's proactive reclaim (DAMON pageout, seen here) pages it out and every guest system
# call slows from ~20 µs to ~500 µs (measured with a clock_gettime loop in the guest).
#
# UML is a uniprocessor guest whose every system call is a ptrace round trip between two host
# threads (the guest process and UML's kernel). Left to the host scheduler they land on different
# CPUs, and each round trip waits for a cross-CPU wake-up; on a virtual machine host (a
# Firecracker guest here) that took ~300 µs per guest system call instead of ~21 µs pinned to
# one CPU (same clock_gettime loop). So the guest runs pinned to one CPU: the last one this
# script may use, or VCAN_CPU (a CPU number; "none" to leave it unpinned).
pin=()
cpu=${VCAN_CPU:-$(sed -n 's/^Cpus_allowed_list:[[:space:]]*//p' /proc/self/status | tr ',-' '\n\n' | tail -1)}
if [[ "$cpu" != none ]]; then
    [[ "$cpu" =~ ^[0-9]+$ ]] || die "VCAN_CPU must be a CPU number or 'none', got '$cpu'"
    command -v taskset >/dev/null || die "taskset (util-linux) missing: cannot pin the UML guest"
    pin=(taskset -c "$cpu")
    note "UML pinned to CPU $cpu"
fi
# Whatever else the host runs (a build beside the tests), the guest's timing tests keep their
# CPU first: a higher priority where permitted (root), the default otherwise.
if [[ "${VCAN_NICE:-1}" == 1 && $(id -u) == 0 ]]; then
    pin=(nice -n -10 "${pin[@]}")
    note "UML at nice -10"
fi
TMPDIR="${VCAN_UML_TMPDIR:-/dev/shm}" timeout -k 10 "$TIMEOUT" "${pin[@]}" env LD_PRELOAD="$SHIM" linux.uml mem="${VCAN_MEM:-1G}" rootfstype=hostfs rootflags=/ rw \
    init="$INIT" uml_dir="$WORK" con=null con0=null,fd:1 "${KERNEL_LOG[@]}" \
    </dev/null >"$WORK/console" &
uml_pid=$!
if [[ -n "$interrupted" ]]; then on_signal "$interrupted"; fi
uml_rc=0
wait "$uml_pid" || uml_rc=$?
while kill -0 "$uml_pid" 2>/dev/null; do # wait was cut short by a signal
    uml_rc=0
    wait "$uml_pid" || uml_rc=$?
done
wait # for cat: all of the guest's output is out before we report
note "UML ran $(awk -v s="$start" -v e="$(date +%s.%N)" 'BEGIN { printf "%.2f", e - s }') s"

if [[ -n "$interrupted" ]]; then
    die "interrupted (SIG$interrupted): UML guest stopped; command: $*"
fi
if [[ $uml_rc -eq 124 || $uml_rc -eq 137 ]]; then
    die "TIMEOUT: UML guest did not finish within ${TIMEOUT}s (VCAN_TIMEOUT); command: $*"
fi
if [[ ! -s "$RCFILE" ]]; then
    die "no exit code came back from the UML guest (linux.uml exit $uml_rc): the guest crashed or" \
        "never ran the command; rerun with VCAN_VERBOSE=1 VCAN_KEEP=1. Command: $*"
fi
rc=$(cat "$RCFILE")
[[ "$rc" =~ ^[0-9]+$ ]] || die "garbled exit code '$rc' from the UML guest"
exit "$rc"
