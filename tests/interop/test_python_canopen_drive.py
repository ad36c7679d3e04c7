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
