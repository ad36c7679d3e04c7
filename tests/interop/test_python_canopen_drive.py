"""Interoperability: python-canopen as the DRIVE (its LocalNode, the slave side) against canmotion's
SDO client, on vcan0.

The other file has python-canopen as the master against our simulated drive; here the roles turn
round, so our client meets a server we did not write. The objects are longer than the 32 bytes
canopen-rs's client stopped at (issue 13, defect 3): a 34-byte device name (0x1008) and a
1000-byte DOMAIN (0x2000). python-canopen's server answers a block upload with a normal one (CiA 301
lets it switch), which `canmotion sdo read --block` must follow.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import canopen
import pytest
from canopen import objectdictionary as odt

from conftest import VCAN, vcan_status

REPO = Path(__file__).resolve().parents[2]
NODE_ID = 9
NAME = b"canmotion interop: python-canopen!"  # 34 bytes
DOMAIN = bytes((i * 37 + 11) % 256 for i in range(1000))


def canmotion_bin() -> Path:
    p = Path(os.environ.get("CANMOTION_BIN", "target/debug/canmotion"))
    return p if p.is_absolute() else REPO / p


@pytest.fixture
def python_drive():
    ok, desc = vcan_status()
    assert ok, f"this suite needs vcan0 up: {desc}"
    od = odt.ObjectDictionary()
    for index, name, data_type in [
        (0x1000, "Device type", odt.UNSIGNED32),
        (0x1008, "Manufacturer device name", odt.VISIBLE_STRING),
        (0x2000, "Long domain", odt.DOMAIN),
    ]:
        var = odt.ODVariable(name, index, 0)
        var.data_type = data_type
        var.access_type = "rw"
        od.add_object(var)
    network = canopen.Network()
    network.connect(interface="socketcan", channel=VCAN)
    node = canopen.LocalNode(NODE_ID, od)
    network.add_node(node)
    node.set_data(0x1000, 0, (0x00020192).to_bytes(4, "little"), check_writable=False)
    node.set_data(0x1008, 0, NAME, check_writable=False)
    node.set_data(0x2000, 0, DOMAIN, check_writable=False)
    try:
        yield node
    finally:
        network.disconnect()


def sdo_read(*args: str) -> str:
    cmd = [str(canmotion_bin()), "sdo", "read", VCAN, str(NODE_ID), *args]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, f"{cmd}: exit {r.returncode}\n{r.stdout}\n{r.stderr}"
    return r.stdout.strip()


def hex_of(data: bytes) -> str:
    return " ".join(f"{b:02X}" for b in data)


def test_a_34_byte_device_name_reads_whole(python_drive):
    out = sdo_read("0x1008", "string")
    assert out.startswith(f'"{NAME.decode()}"'), out
    assert hex_of(NAME) in out, out


@pytest.mark.parametrize("block", [False, True])
def test_a_1000_byte_domain_matches_the_bytes_on_the_drive(python_drive, block):
    out = sdo_read("0x2000", *(["--block"] if block else []))
    assert hex_of(DOMAIN) in out, out[:300]
    assert python_drive.get_data(0x2000, 0) == DOMAIN


def test_python_canopen_block_transfers_of_1000_bytes_against_our_simdrive(tmp_path):
    """The other way round: python-canopen's client (block download, block upload, and a
    segmented upload) against OUR simulated drive, with a 1000-byte DOMAIN in its dictionary."""
    import queue
    import time

    ok, desc = vcan_status()
    assert ok, f"this suite needs vcan0 up: {desc}"
    node_id = 7
    base = (REPO / "dictionaries/drives/cia402-servo.toml").read_text()
    dict_path = tmp_path / "with-domain.toml"
    dict_path.write_text(
        base
        + '\n[[object]]\nindex = 0x2000\nname = "Data block"\ntype = "domain"\n'
        + 'access = "rw"\ndefault = ""\n'
    )
    network = canopen.Network()
    network.connect(interface="socketcan", channel=VCAN)
    bootups: queue.Queue = queue.Queue()
    network.subscribe(0x700 + node_id, lambda can_id, data, ts: bootups.put(bytes(data)))
    log_path = tmp_path / "simdrive.log"
    proc = subprocess.Popen(
        [str(canmotion_bin()), "simdrive", "--bus", VCAN, "--node", str(node_id),
         "--dictionary", str(dict_path)],
        cwd=REPO, stdin=subprocess.DEVNULL, stdout=open(log_path, "wb"), stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.monotonic() + 20
        while True:
            assert proc.poll() is None, f"simdrive exited: {log_path.read_text(errors='replace')}"
            assert time.monotonic() < deadline, "no boot-up from the simulated drive within 20 s"
            try:
                if bootups.get(timeout=0.2) == b"\x00":
                    break
            except queue.Empty:
                pass
        od = odt.ObjectDictionary()
        var = odt.ODVariable("Data block", 0x2000, 0)
        var.data_type = odt.DOMAIN
        var.access_type = "rw"
        od.add_object(var)
        remote = network.add_node(node_id, od)
        remote.sdo.RESPONSE_TIMEOUT = 2.0
        remote.sdo.MAX_RETRIES = 3
        with remote.sdo.open(0x2000, 0, "wb", size=len(DOMAIN), block_transfer=True) as f:
            f.write(DOMAIN)
        with remote.sdo.open(0x2000, 0, "rb", block_transfer=True) as f:
            assert f.read() == DOMAIN
        assert remote.sdo.upload(0x2000, 0) == DOMAIN
        # And canmotion's own client reads what python-canopen wrote, block and segmented.
        for extra in ([], ["--block"]):
            cmd = [str(canmotion_bin()), "sdo", "read", VCAN, str(node_id), "0x2000", *extra]
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
            assert r.returncode == 0, r.stderr
            assert hex_of(DOMAIN) in r.stdout
    finally:
        proc.terminate()
        proc.wait(timeout=10)
        network.disconnect()
