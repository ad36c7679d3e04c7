"""pytest plumbing for the python-canopen interoperability suite (tests/interop/).

- The report header says whether vcan0 exists and is up (this suite only runs where it does,
  see tests/interop/run.sh), and which python-canopen / python-can versions act as master.
- Each test item gets its call report attached (``item.rep_call``), so fixtures can dump the
  CAN trace and the drive's log on failure.
"""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

VCAN = "vcan0"
ARPHRD_CAN = 280  # /sys/class/net/<if>/type of a CAN interface


# Receive buffer of a test's CAN socket. The default (~200 KiB, a few hundred frames) overflows
# when the single-CPU guest's Python stalls while a 1-2 ms SYNC and PDOs stream, and the socket
# then silently drops frames (an SDO response, the NMT command a test looks for).
RCVBUF_BYTES = 4 << 20


def roomy_receive_buffer(bus) -> None:
    """Gives python-can's socket RCVBUF_BYTES of receive buffer (beyond rmem_max as root)."""
    sock = getattr(bus, "socket", None)
    if sock is None:
        return
    force = getattr(socket, "SO_RCVBUFFORCE", None)
    try:
        sock.setsockopt(socket.SOL_SOCKET, force or socket.SO_RCVBUF, RCVBUF_BYTES)
    except OSError:  # not root: capped at net.core.rmem_max
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)


def vcan_status(ifname: str = VCAN) -> tuple[bool, str]:
    """(usable, description) of a SocketCAN interface, from sysfs."""
    base = Path("/sys/class/net") / ifname
    if not base.exists():
        return False, f"{ifname}: MISSING (no {base})"
    try:
        flags = int((base / "flags").read_text().strip(), 16)
        iftype = int((base / "type").read_text().strip())
        mtu = (base / "mtu").read_text().strip()
    except OSError as e:
        return False, f"{ifname}: unreadable sysfs entry: {e}"
    up = bool(flags & 0x1)
    ok = up and iftype == ARPHRD_CAN
    return ok, (
        f"{ifname}: {'UP' if up else 'DOWN'}, type {iftype}"
        f" ({'CAN' if iftype == ARPHRD_CAN else 'NOT CAN'}), mtu {mtu}, flags 0x{flags:x}"
    )


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "simdrive_args(*args): extra command-line options of `canmotion simdrive`"
    )


def pytest_report_header(config):
    import can
    import canopen

    _, desc = vcan_status()
    return [
        f"interop bus: {desc}",
        f"master: python-canopen {canopen.__version__}, python-can {can.__version__}",
    ]


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    rep = outcome.get_result()
    setattr(item, "rep_" + rep.when, rep)
