"""Interoperability: python-canopen as CANopen master against `canmotion simdrive` on vcan0.

python-canopen (PyPI `canopen`, with `python-can`) is an independent CANopen implementation. Here
it is the master, on a real SocketCAN vcan0, and our simulated CiA 402 drive runs as a separate
process (`canmotion simdrive --bus vcan0 --node 1`). python-canopen uses its own SDO client, PDO
configuration code and CiA 402 state machine (`canopen.profiles.p402.BaseNode402`) on an object
dictionary built from OUR drive dictionary (TOML), so anything our own master and drive agree on
by mistake shows up here.

Run it with tests/interop/run.sh (builds, makes the venv, runs pytest where vcan0 exists).

Environment:
  CANMOTION_BIN         the canmotion binary (default: target/debug/canmotion in the repo root)
  CANMOTION_DICTIONARY  a drive dictionary (TOML): read here AND passed to the drive with
                        --dictionary. Default: dictionaries/drives/cia402-servo.toml, which is the
                        drive's embedded default, so the drive is started without --dictionary.
"""

from __future__ import annotations

import os
import queue
import subprocess
import threading
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import can
import canopen
import pytest
from canopen import objectdictionary as odt
from canopen.profiles.p402 import BaseNode402

from conftest import VCAN, roomy_receive_buffer, vcan_status

REPO = Path(__file__).resolve().parents[2]
NODE_ID = 1
DEFAULT_DICTIONARY = REPO / "dictionaries/drives/cia402-servo.toml"

BOOTUP_TIMEOUT_S = 20.0  # process start + boot-up frame; generous for the UML guest
# python-canopen's default timeouts (SDO 0.3 s; p402: 0.2 s for a TPDO, 0.4 s per state change)
# are too tight for a single-CPU UML guest that other guests load too: Python there can stall
# for hundreds of ms. These are deadlines, not delays.
# Measured there with another guest running: the drive process stalled up to ~1.2 s, and a
# starved drive's socket can overflow and lose an SDO request, hence retries.
SDO_TIMEOUT_S = 2.0
SDO_RETRIES = 3  # python-canopen re-sends the request after each timeout (default 1)
TPDO_TIMEOUT_S = 3.0
P402_TIMEOUTS = {
    "TIMEOUT_CHECK_TPDO": TPDO_TIMEOUT_S,
    "TIMEOUT_SWITCH_STATE_SINGLE": 20.0,
    "TIMEOUT_SWITCH_STATE_FINAL": 10.0,
    "TIMEOUT_SWITCH_OP_MODE": 20.0,
}
SYNC_PERIOD_S = 0.002
SYNC_PERIOD_US = 2000

# CiA 402 statusword bits
SW_FAULT = 1 << 3
SW_IP_ACTIVE = 1 << 12  # mode-specific bit 12: in IP mode, "IP mode active"
SW_FOLLOWING_ERROR = 1 << 13
CW_ENABLE_OPERATION = 0x000F
CW_IP_ENABLE = 1 << 4

EMCY_SYNC_MISSING = 0x8100  # tolerated (loose timing of a loaded guest), reported


# ---------------------------------------------------------------------------------------------
# Our TOML drive dictionary -> python-canopen ObjectDictionary
# ---------------------------------------------------------------------------------------------

TOML_TYPES = {
    "bool": odt.BOOLEAN,
    "i8": odt.INTEGER8,
    "i16": odt.INTEGER16,
    "i32": odt.INTEGER32,
    "i64": odt.INTEGER64,
    "u8": odt.UNSIGNED8,
    "u16": odt.UNSIGNED16,
    "u32": odt.UNSIGNED32,
    "u64": odt.UNSIGNED64,
    "f32": odt.REAL32,
    "f64": odt.REAL64,
    "string": odt.VISIBLE_STRING,
    "octets": odt.OCTET_STRING,
    "domain": odt.DOMAIN,
}
TOML_ACCESS = {"const", "ro", "wo", "rw"}
# Objects with sub-entries are RECORDs (CiA 301/306: identity, PDO communication and mapping
# parameters, ...) except these, which CiA 301/402 define as ARRAYs. The TOML does not say.
# (PDO mappings MUST stay records: python-canopen's PdoMap.save() iterates an SdoArray by its
# sub 0 read back over SDO, which it has just written to 0, and would write no entries.)
CIA_ARRAYS = {0x1003, 0x1016, 0x1029, 0x607D, 0x60C1}


def resolve_default(value, node_id: int):
    """A TOML default, with EDS-style "$NODEID" / "$NODEID+0x..." resolved."""
    if isinstance(value, str) and value.startswith("$NODEID"):
        rest = value[len("$NODEID"):].strip()
        if not rest:
            return node_id
        if not rest.startswith("+"):
            raise ValueError(f"bad node-id default {value!r}")
        return node_id + int(rest[1:].strip().replace("_", ""), 0)
    return value


def _variable(name: str, index: int, sub: int, spec: dict, node_id: int) -> odt.ODVariable:
    var = odt.ODVariable(name, index, sub)
    try:
        var.data_type = TOML_TYPES[spec["type"]]
    except KeyError:
        raise ValueError(f"0x{index:04X}:{sub}: unknown or missing type {spec.get('type')!r}")
    access = spec.get("access")
    if access not in TOML_ACCESS:
        raise ValueError(f"0x{index:04X}:{sub}: bad access {access!r}")
    var.access_type = access
    var.pdo_mappable = bool(spec.get("pdo", False))
    if "default" in spec:
        default = resolve_default(spec["default"], node_id)
        if var.data_type in (odt.OCTET_STRING, odt.DOMAIN) and isinstance(default, str):
            default = default.encode()
        var.default = default
        var.value = default
    var.min = spec.get("min")
    var.max = spec.get("max")
    var.unit = spec.get("unit", "")
    return var


def build_object_dictionary(doc: dict, node_id: int) -> canopen.ObjectDictionary:
    """python-canopen's ObjectDictionary for `node_id` from a parsed canmotion drive dictionary."""
    od = canopen.ObjectDictionary()
    od.node_id = node_id
    dev = doc["device"]
    od.device_information.product_name = dev["name"]
    od.device_information.vendor_number = dev["vendor_id"]
    od.device_information.product_number = dev["product_code"]
    od.device_information.revision_number = dev["revision"]
    for obj in doc["object"]:
        index, name = obj["index"], obj["name"]
        subs = obj.get("sub")
        if subs is None:
            od.add_object(_variable(name, index, 0, obj, node_id))
            continue
        if any(k in obj for k in ("type", "access", "default")):
            raise ValueError(f"0x{index:04X}: both variable keys and sub-entries")
        rec = (odt.ODArray if index in CIA_ARRAYS else odt.ODRecord)(name, index)
        for s in subs:
            rec.add_member(_variable(s["name"], index, s["sub"], s, node_id))
        od.add_object(rec)
    return od


@dataclass
class TomlDictionary:
    path: Path
    doc: dict
    objects: dict = field(default_factory=dict)  # index -> raw TOML table

    @classmethod
    def load(cls, path: Path) -> "TomlDictionary":
        with open(path, "rb") as f:
            doc = tomllib.load(f)
        return cls(path, doc, {o["index"]: o for o in doc["object"]})

    @property
    def device(self) -> dict:
        return self.doc["device"]

    def entry(self, index: int, sub: int = 0) -> dict:
        obj = self.objects[index]
        if "sub" not in obj:
            assert sub == 0
            return obj
        return next(s for s in obj["sub"] if s["sub"] == sub)

    def default(self, index: int, sub: int = 0, node_id: int = NODE_ID):
        return resolve_default(self.entry(index, sub)["default"], node_id)


# ---------------------------------------------------------------------------------------------
# Bus trace, drive process
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Frame:
    t: float
    id: int
    data: bytes
    rtr: bool

    def __str__(self) -> str:
        return f"{self.t:17.6f}  {self.id:03X}  [{len(self.data)}]  {self.data.hex(' ')}" + (
            "  RTR" if self.rtr else ""
        )


class Trace(can.Listener):
    """Every frame the master's socket receives, in order, with the kernel's receive timestamps
    (runs in python-can's notifier thread). The socket is filtered to node 1's COB-IDs and does
    not receive the master's own frames (SYNC, NMT, RPDOs, SDO requests)."""

    def __init__(self):
        self.frames: list[Frame] = []

    def on_message_received(self, msg: can.Message) -> None:
        if not msg.is_error_frame:
            self.frames.append(
                Frame(msg.timestamp, msg.arbitration_id, bytes(msg.data), msg.is_remote_frame)
            )

    def mark(self) -> int:
        return len(self.frames)

    def since(self, mark: int, cob_id: int | None = None) -> list[Frame]:
        return [f for f in self.frames[mark:] if cob_id is None or f.id == cob_id]

    def dump(self, last: int = 80) -> str:
        return "\n".join(str(f) for f in self.frames[-last:])


@dataclass
class Drive:
    proc: subprocess.Popen
    log_path: Path
    node: BaseNode402
    network: canopen.Network
    trace: Trace
    bootup: Frame

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def assert_alive(self) -> None:
        rc = self.proc.poll()
        assert rc is None, f"canmotion simdrive exited early with {rc}; its log:\n{self.log()}"


def canmotion_bin() -> Path:
    p = Path(os.environ.get("CANMOTION_BIN", "target/debug/canmotion"))
    return p if p.is_absolute() else REPO / p


def dictionary_path() -> Path:
    p = os.environ.get("CANMOTION_DICTIONARY")
    if not p:
        return DEFAULT_DICTIONARY
    path = Path(p)
    return path if path.is_absolute() else REPO / path


@pytest.fixture(scope="session", autouse=True)
def vcan0_present():
    """This suite is only run where vcan0 is provided: a missing vcan0 is a failure, not a skip."""
    ok, desc = vcan_status(VCAN)
    print(f"\n[interop] {desc}")
    if not ok:
        pytest.fail(f"{desc}: run this suite through tests/interop/run.sh (tools/in-vcan.sh)")
    return desc


@pytest.fixture(scope="session")
def dictionary() -> TomlDictionary:
    return TomlDictionary.load(dictionary_path())


@pytest.fixture
def network():
    trace = Trace()
    # Kernel filter: only frames of node 1 (COB-ID & 0x7F == 1: EMCY, TPDOs, SDO, heartbeat).
    # Not the SYNC, which the master itself produces: 500 frames/s less to receive in Python,
    # which matters on a single-CPU UML guest.
    node_filter = [{"can_id": NODE_ID, "can_mask": 0x07F, "extended": False}]
    bus = can.interface.Bus(interface="socketcan", channel=VCAN, can_filters=node_filter)
    roomy_receive_buffer(bus)
    net = canopen.Network(bus)
    net.listeners.insert(0, trace)  # before python-canopen's own listener: trace first
    net.connect()
    net.trace = trace
    try:
        yield net
    finally:
        net.disconnect()  # also stops the bus's periodic (BCM) tasks still running, e.g. SYNC


@pytest.fixture
def drive(request, network, dictionary, tmp_path):
    """`canmotion simdrive` for node 1 on vcan0, up and booted; stopped afterwards."""
    exe = canmotion_bin()
    assert exe.is_file() and os.access(exe, os.X_OK), f"no canmotion binary at {exe} (cargo build)"
    node = BaseNode402(NODE_ID, build_object_dictionary(dictionary.doc, NODE_ID))
    network.add_node(node)
    node.sdo.RESPONSE_TIMEOUT = SDO_TIMEOUT_S
    node.sdo.MAX_RETRIES = SDO_RETRIES
    for name, value in P402_TIMEOUTS.items():
        setattr(node, name, value)

    bootups: queue.Queue = queue.Queue()
    hb_id = 0x700 + NODE_ID

    def on_heartbeat(can_id, data, timestamp):
        bootups.put(Frame(timestamp, can_id, bytes(data), False))

    network.subscribe(hb_id, on_heartbeat)  # armed BEFORE the process starts: no race

    cmd = [str(exe), "simdrive", "--bus", VCAN, "--node", str(NODE_ID)]
    # @pytest.mark.simdrive_args(...): more options of the simulated drive (e.g. its home switch).
    extra = request.node.get_closest_marker("simdrive_args")
    if extra is not None:
        cmd += [str(a) for a in extra.args]
    if os.environ.get("CANMOTION_DICTIONARY"):
        cmd += ["--dictionary", str(dictionary.path)]
    log_path = tmp_path / "simdrive.log"
    log = open(log_path, "wb")
    proc = subprocess.Popen(cmd, cwd=REPO, stdin=subprocess.DEVNULL, stdout=log, stderr=log)
    print(f"[interop] started {' '.join(cmd)} (pid {proc.pid})")
    d = None
    try:
        deadline = time.monotonic() + BOOTUP_TIMEOUT_S
        bootup = None
        while bootup is None:
            left = deadline - time.monotonic()
            if proc.poll() is not None:
                pytest.fail(f"simdrive exited with {proc.returncode} before boot-up:\n"
                            f"{log_path.read_text(errors='replace')}")
            if left <= 0:
                pytest.fail(f"no boot-up (0x{hb_id:03X} [00]) within {BOOTUP_TIMEOUT_S} s; "
                            f"frames seen:\n{network.trace.dump()}")
            try:
                f = bootups.get(timeout=min(left, 0.2))
            except queue.Empty:
                continue
            if f.data[:1] == b"\x00":
                bootup = f
        network.unsubscribe(hb_id, on_heartbeat)
        # CiA 301 7.2.8.3.2.1: boot-up = 0x700+id, exactly one data byte 0x00.
        assert bootup.data == b"\x00", f"boot-up frame {bootup}: want DLC 1, data 00"
        assert node.nmt.state == "PRE-OPERATIONAL", node.nmt.state
        print(f"[interop] boot-up seen: {bootup}")
        d = Drive(proc, log_path, node, network, network.trace, bootup)
        yield d
    finally:
        failed = getattr(request.node, "rep_call", None) is not None and request.node.rep_call.failed
        if failed:
            full = tmp_path / "vcan0-trace.txt"
            full.write_text(network.trace.dump(len(network.trace.frames)) + "\n")
            print(f"[interop] full CAN trace: {full}; last frames (time, id, [dlc], data):")
            print(network.trace.dump(120))
        rc_before = proc.poll()
        print("[interop] diagnostics:\n" + bus_diagnostics(proc))
        if rc_before is None:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
        log.close()
        text = log_path.read_text(errors="replace")
        lines = text.splitlines()
        shown = lines if failed else lines[-40:]
        print(f"[interop] simdrive log ({log_path}, {len(lines)} lines"
              f"{'' if len(shown) == len(lines) else f', last {len(shown)}'}):")
        print("\n".join(shown))
        if d is not None and rc_before is not None:
            pytest.fail(f"simdrive died during the test (exit {rc_before}):\n{text}")


def _cpu_seconds(pid: int | str) -> str:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        tck = os.sysconf("SC_CLK_TCK")
        return f"user {int(fields[11]) / tck:.2f} s, sys {int(fields[12]) / tck:.2f} s"
    except (OSError, IndexError, ValueError):
        return "n/a"


def bus_diagnostics(proc: subprocess.Popen) -> str:
    """Load and drop counters of the machine running the test (the UML guest, usually)."""
    lines = []
    try:
        lines.append("loadavg " + Path("/proc/loadavg").read_text().strip())
    except OSError:
        pass
    lines.append(f"CPU simdrive (pid {proc.pid}): {_cpu_seconds(proc.pid)}; "
                 f"pytest: {_cpu_seconds('self')}")
    try:
        cols = [ln.split() for ln in Path("/proc/net/softnet_stat").read_text().splitlines()]
        lines.append("softnet backlog drops per CPU: "
                     + ", ".join(str(int(c[1], 16)) for c in cols if len(c) > 1))
    except (OSError, ValueError):
        pass
    st = Path("/sys/class/net") / VCAN / "statistics"
    try:
        lines.append(f"{VCAN}: " + ", ".join(
            f"{k} {(st / k).read_text().strip()}"
            for k in ("tx_packets", "rx_packets", "tx_dropped", "rx_dropped")))
    except OSError:
        pass
    return "\n".join("[interop]   " + ln for ln in lines)


def wait_until(pred, timeout: float, what: str, status=None, poll: float = 0.002):
    deadline = time.monotonic() + timeout
    while True:
        v = pred()
        if v:
            return v
        if time.monotonic() > deadline:
            extra = f" ({status()})" if status else ""
            raise AssertionError(f"timed out after {timeout} s waiting for {what}{extra}")
        time.sleep(poll)


def abort_code(fn) -> int | None:
    """The SDO abort code python-canopen raised for fn(), or None if it succeeded."""
    try:
        fn()
    except canopen.SdoAbortedError as e:
        return e.code
    return None


def mapping_entry(index: int, sub: int, bits: int) -> int:
    return index << 16 | sub << 8 | bits


# ---------------------------------------------------------------------------------------------
# PDO helpers (python-canopen's PDO API)
# ---------------------------------------------------------------------------------------------


def set_mapping(pdo_map, entries, trans_type: int, enabled: bool = True) -> None:
    pdo_map.clear()
    for index, sub in entries:
        var = pdo_map.add_variable(index, sub)
        assert var is not None, f"python-canopen could not map 0x{index:04X}:{sub} from our OD"
    pdo_map.trans_type = trans_type
    pdo_map.enabled = enabled


def read_pdo_config(node, comm_index: int, map_index: int):
    """(COB-ID, transmission type, [mapping entries]) read back by SDO."""
    cob_id = node.sdo[comm_index][1].raw
    trans_type = node.sdo[comm_index][2].raw
    n = node.sdo[map_index][0].raw
    return cob_id, trans_type, [node.sdo[map_index][s].raw for s in range(1, n + 1)]


class SyncedRpdoPump:
    """Sends RPDO1 once per SYNC period, timed to the SYNC.

    The drive sends TPDO1 (transmission type 1) right after every SYNC; this callback on TPDO1
    reception sends RPDO1 with the current data (controlword + 0x60C1:01), which the drive
    applies at the following SYNC. While a ramp is set, each answered TPDO1 also advances the
    setpoint by one step: one setpoint per SYNC period. It runs in python-can's notifier thread.

    A TPDO1 the kernel received before our last RPDO went out is a backlog of a stalled Python
    (loaded single-CPU guest): it is recorded but not answered, so a stall slows the ramp down
    instead of bursting setpoints at the drive.
    """

    def __init__(self, rpdo, setpoint_var):
        self.rpdo = rpdo
        self.setpoint_var = setpoint_var
        self.lock = threading.Lock()
        self.ramp = None
        self.ramp_done = threading.Event()
        self.ramp_end = None  # wall time the last setpoint of the ramp was sent
        self.setpoint = None
        self.samples: list[tuple[float, int, int, int | None]] = []  # (t, sw, pos, sp sent)
        self.sent = 0
        self.backlog = 0
        self.last_sent = 0.0  # wall time (same clock as the kernel's frame timestamps)
        self.last_rpdo = b""
        self.errors: list[str] = []
        self.running = True

    def on_tpdo(self, pdo_map) -> None:
        if not self.running:
            return
        try:
            sw, pos = pdo_map[0].raw, pdo_map[1].raw
            with self.lock:
                self.samples.append((pdo_map.timestamp, sw, pos, self.setpoint))
                if pdo_map.timestamp < self.last_sent:
                    self.backlog += 1
                    return
                last = False
                if self.ramp is not None:
                    try:
                        sp = next(self.ramp)
                    except StopIteration:
                        self.ramp = None
                        self.ramp_done.set()
                    else:
                        self.setpoint_var.raw = sp
                        self.setpoint = sp
                        last = sp == self.ramp_last
                self.rpdo.transmit()
                self.last_rpdo = bytes(self.rpdo.data)
                self.last_sent = time.time()
                self.sent += 1
                if last:
                    self.ramp_end = self.last_sent
        except Exception as e:  # the notifier swallows exceptions: keep them for the test
            self.errors.append(repr(e))

    def start_ramp(self, points: list[int]) -> None:
        with self.lock:
            self.ramp_done.clear()
            self.ramp_end = None
            self.ramp_last = points[-1]
            self.ramp = iter(points)

    def n_samples(self) -> int:
        return len(self.samples)

    def status(self) -> str:
        t = self.samples[-1][0] if self.samples else float("nan")
        return (f"pump: {len(self.samples)} TPDO1, {self.sent} RPDOs sent, {self.backlog} "
                f"backlogged; last TPDO1 kernel time {t - time.time():+.3f} s from now, last "
                f"RPDO {self.last_sent - time.time():+.3f} s; errors {self.errors[-3:]}")


# ---------------------------------------------------------------------------------------------
# Steps of the IP scenario
# ---------------------------------------------------------------------------------------------


def remap_cyclic_pdos(node, rpdo_entries, tpdo_entries) -> None:
    """RPDO1 / TPDO1 with these mappings, transmission type 1 (every SYNC), by python-canopen's
    PDO API; TPDO2 (event-driven SW + velocity) disabled to keep the bus quiet. Read back by SDO."""
    set_mapping(node.rpdo[1], rpdo_entries, trans_type=1)
    set_mapping(node.tpdo[1], tpdo_entries, trans_type=1)
    node.tpdo[2].enabled = False
    node.rpdo.save()
    node.tpdo.save()
    entries = lambda pdo_map: [mapping_entry(v.index, v.subindex, v.length) for v in pdo_map.map]
    rpdo_cfg = read_pdo_config(node, 0x1400, 0x1600)
    tpdo_cfg = read_pdo_config(node, 0x1800, 0x1A00)
    assert rpdo_cfg == (0x200 + NODE_ID, 1, entries(node.rpdo[1])), rpdo_cfg
    assert tpdo_cfg == (0x180 + NODE_ID, 1, entries(node.tpdo[1])), tpdo_cfg
    assert node.sdo[0x1801][1].raw & 0x8000_0000, "TPDO2 should now be invalid"


def set_ip_period(node) -> None:
    node.sdo[0x1006].raw = SYNC_PERIOD_US
    node.sdo[0x60C2][1].raw = 2
    node.sdo[0x60C2][2].raw = -3  # 2 x 10^-3 s = 2000 us = 0x1006
    assert node.sdo[0x1006].raw == SYNC_PERIOD_US
    assert (node.sdo[0x60C2][1].raw, node.sdo[0x60C2][2].raw) == (2, -3)


def go_operational(node, trace) -> None:
    """NMT start, confirmed by the drive's heartbeat (0x1017 = 50 ms)."""
    node.sdo[0x1017].raw = 50
    heartbeats: list[int] = []
    node.nmt.add_heartbeat_callback(heartbeats.append)
    mark = trace.mark()
    node.nmt.state = "OPERATIONAL"
    wait_until(lambda: 0x05 in heartbeats, 20.0, "a heartbeat with state 0x05 (Operational)")
    for f in trace.since(mark, 0x700 + NODE_ID):
        assert len(f.data) == 1 and f.data[0] in (0x05, 0x7F), f"heartbeat frame {f}"


def start_cyclic(node, network, trace) -> tuple[SyncedRpdoPump, int]:
    """BaseNode402 set up on the PDOs, the RPDO pump on TPDO1, SYNC every 2 ms."""
    # setup_402_state_machine reads the whole PDO configuration back by SDO: done before SYNC
    # starts, so the SDO traffic does not compete with SYNC + TPDO on a loaded guest.
    node.setup_402_state_machine()
    assert 0x6041 in node.tpdo_pointers and 0x6040 in node.rpdo_pointers
    rpdo1, tpdo1 = node.rpdo[1], node.tpdo[1]
    assert (rpdo1.map[0].index, rpdo1.map[1].index, rpdo1.map[1].subindex) == (0x6040, 0x60C1, 1)
    assert (tpdo1.map[0].index, tpdo1.map[1].index) == (0x6041, 0x6064)
    assert rpdo1.is_periodic  # so BaseNode402 only updates the RPDO data: the pump sends it
    pump = SyncedRpdoPump(rpdo1, rpdo1.map[1])
    tpdo1.add_callback(pump.on_tpdo)
    mark = trace.mark()
    network.sync.start(SYNC_PERIOD_S)
    tx_cob = 0x180 + NODE_ID
    wait_until(lambda: len(trace.since(mark, tx_cob)) >= 3, 20.0, "TPDO1 on SYNC")
    size = tpdo1.length // 8
    for f in trace.since(mark, tx_cob):
        assert len(f.data) == size, f"TPDO1 {f}: its mapping is {size} bytes"
    return pump, mark


def enable_operation(node, pump) -> int:
    """BaseNode402 walks the CiA 402 state machine to OPERATION ENABLED. Returns the sample
    index from which on the drive is enabled."""
    node.check_statusword(timeout=TPDO_TIMEOUT_S)
    print(f"[interop] before enable: state {node.state}, SW 0x{node.statusword:04X}")
    node.state = "OPERATION ENABLED"
    assert node.state == "OPERATION ENABLED"
    node.check_statusword(timeout=TPDO_TIMEOUT_S)
    sw = node.statusword
    assert sw & 0x6F == 0x27, f"SW 0x{sw:04X}"
    assert not sw & SW_IP_ACTIVE, f"SW 0x{sw:04X}: bit 12 set before CW bit 4"
    return pump.n_samples()


def start_ip(node, pump) -> tuple[int, int]:
    """CiA 402 IP start: preload 0x60C1:01 with 0x6064, CW 0x1F, wait for SW bit 12.
    Returns (start position, sample index from which on IP is active)."""
    node.check_statusword(timeout=TPDO_TIMEOUT_S)
    start = node.tpdo_values[0x6064]
    assert start == node.sdo[0x6064].raw
    with pump.lock:
        pump.setpoint_var.raw = start
        pump.setpoint = start
        sent0 = pump.sent
    wait_until(lambda: pump.sent >= sent0 + 3, 20.0, "3 RPDOs with the preload", pump.status)
    node.controlword = CW_ENABLE_OPERATION | CW_IP_ENABLE  # 0x1F
    try:
        wait_until(lambda: pump.samples[-1][1] & SW_IP_ACTIVE, 20.0,
                   "statusword bit 12 (IP active) after CW 0x1F", pump.status)
    finally:
        recent = [f"0x{sw:04X}" for _, sw, _, _ in pump.samples[-5:]]
        tpdo = pump.rpdo.pdo_node.node.tpdo[1]
        print(f"[interop] after CW 0x1F: last statuswords {recent}; last RPDO1 sent "
              f"0x{pump.rpdo.cob_id:03X} [{pump.last_rpdo.hex(' ')}], last TPDO1 received "
              f"0x{tpdo.cob_id:03X} [{bytes(tpdo.data).hex(' ')}]")
    return start, pump.n_samples()


def stream_ramp(node, pump, start: int, distance: int, step: int) -> int:
    """Streams start + step, + 2 step, ... one setpoint per SYNC period, then holds the last one
    until 0x6064 (TPDO1) settles within 3 counts of it. Returns the last setpoint."""
    target = start + distance
    ramp = [start + step * k for k in range(1, distance // step + 1)]
    assert ramp[-1] == target
    t0 = time.monotonic()
    sent0, backlog0 = pump.sent, pump.backlog
    pump.start_ramp(ramp)
    assert pump.ramp_done.wait(timeout=60.0), "the ramp did not finish"
    ramp_s = time.monotonic() - t0
    ramp_sent, ramp_backlog = pump.sent - sent0, pump.backlog - backlog0
    # 0x6064 must settle within a few counts of the last setpoint, seen in a TPDO1 the drive
    # sent at least 200 ms (100 SYNC periods) after that setpoint went out.
    settled = lambda: (pump.samples[-1][0] >= pump.ramp_end + 0.2
                       and abs(pump.samples[-1][2] - target) <= 3)
    try:
        wait_until(settled, 10.0, f"0x6064 in TPDO1 to settle at {target} +- 3", pump.status)
    finally:
        t, sw, pos, _ = pump.samples[-1]
        print(f"[interop] ramp {start} -> {target} in {len(ramp)} steps: {ramp_s:.2f} s, "
              f"{ramp_sent} RPDOs ({ramp_backlog} backlogged TPDO1 not answered); "
              f"last TPDO1 {t - pump.ramp_end:+.3f} s after the last setpoint: "
              f"0x6064 {pos}, SW 0x{sw:04X}")
    assert not pump.errors, pump.errors
    final_sdo = node.sdo[0x6064].raw
    demand = node.sdo[0x6062].raw
    print(f"[interop] by SDO: 0x6064 {final_sdo}, 0x6062 {demand}")
    assert abs(final_sdo - target) <= 3, f"0x6064 (SDO) {final_sdo} vs setpoint {target}"
    assert demand == target, f"0x6062 position demand {demand} vs last setpoint {target}"
    return target


def check_motion_record(node, pump, enable_mark: int, ip_mark: int) -> None:
    samples = pump.samples
    streamed = samples[ip_mark:]
    lag = max(abs(sp - pos) for _, _, pos, sp in streamed if sp is not None)
    print(f"[interop] {len(streamed)} TPDO1 since IP active; "
          f"max |setpoint sent - 0x6064| {lag}")
    # Loose bound: it also contains the Python master's own delays.
    window = node.sdo[0x6065].raw
    assert lag < window, f"0x6064 lagged the setpoints by up to {lag} counts (0x6065 {window})"
    bad = [(t, f"0x{sw:04X}") for t, sw, _, _ in samples[enable_mark:]
           if sw & (SW_FAULT | SW_FOLLOWING_ERROR)]
    assert not bad, f"statusword fault / following-error bits seen: {bad[:10]}"
    not_ip = [(t, f"0x{sw:04X}") for t, sw, _, _ in streamed if not sw & SW_IP_ACTIVE]
    assert not not_ip, f"statusword bit 12 dropped during IP: {not_ip[:10]}"
    emcys = [(f"0x{e.code:04X}", e.timestamp) for e in node.emcy.log]
    if emcys:
        print(f"[interop] EMCYs (0x8100 = SYNC later than 1.5 x 0x1006, tolerated: the guest's "
              f"SYNC timer and scheduling jitter by tens of ms under load): {emcys}")
    unexpected = [e for e in node.emcy.log if e.code != EMCY_SYNC_MISSING]
    assert not unexpected, f"unexpected EMCY during the test: {emcys}"


def stop_ip_and_disable(node, pump) -> None:
    """Clearing CW bit 4 stops IP (SW bit 12 clears); then BaseNode402 disables the drive."""
    node.controlword = CW_ENABLE_OPERATION
    wait_until(lambda: not pump.samples[-1][1] & SW_IP_ACTIVE, 20.0,
               "statusword bit 12 to clear after CW 0x0F", pump.status)
    node.state = "SWITCH ON DISABLED"
    assert node.state == "SWITCH ON DISABLED"


# ---------------------------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------------------------


def test_ip_stream_with_python_canopen_master(drive, dictionary):
    node, network, trace = drive.node, drive.network, drive.trace
    rx_cob, tx_cob = 0x200 + NODE_ID, 0x180 + NODE_ID

    # --- 3. identity by SDO, against the TOML's [device] -----------------------------------
    dev = dictionary.device
    device_type = node.sdo[0x1000].raw
    assert device_type == dev["device_type"], f"0x1000 = 0x{device_type:08X}"
    assert device_type & 0xFFFF == 0x0192, "0x1000 low word must be profile 402"
    assert node.sdo[0x1018][0].raw == dictionary.default(0x1018, 0)
    identity = [node.sdo[0x1018][s].raw for s in (1, 2, 3, 4)]
    assert identity == [dev["vendor_id"], dev["product_code"], dev["revision"],
                        dictionary.default(0x1018, 4)], [hex(x) for x in identity]
    # A string longer than 4 bytes: segmented upload.
    name = node.sdo[0x1008].raw
    assert name == dictionary.default(0x1008), name
    print(f"[interop] identity: 0x1000=0x{device_type:08X} 0x1018:1..4="
          f"{[f'0x{x:08X}' for x in identity]} 0x1008={name!r}")

    # --- 4. remap RPDO1 and TPDO1 with python-canopen's PDO API, read back by SDO ---------------
    node.rpdo.read()
    node.tpdo.read()
    # First a layout unlike the defaults, so the read-back proves the remap took...
    set_mapping(node.rpdo[1], [(0x60C1, 1), (0x6040, 0)], trans_type=2)
    set_mapping(node.tpdo[1], [(0x6064, 0), (0x6041, 0), (0x6061, 0)], trans_type=2)
    node.rpdo.save()
    node.tpdo.save()
    assert read_pdo_config(node, 0x1400, 0x1600) == (
        rx_cob, 2, [mapping_entry(0x60C1, 1, 32), mapping_entry(0x6040, 0, 16)])
    assert read_pdo_config(node, 0x1800, 0x1A00) == (
        tx_cob, 2, [mapping_entry(0x6064, 0, 32), mapping_entry(0x6041, 0, 16),
                    mapping_entry(0x6061, 0, 8)])
    # ...then the layout this test runs with.
    node.rpdo[1].clear()
    node.rpdo[1].add_variable(0x6040)
    node.rpdo[1].add_variable(0x60C1, 1)
    node.rpdo[1].trans_type = 1
    node.rpdo[1].enabled = True
    node.tpdo[1].clear()
    node.tpdo[1].add_variable(0x6041)
    node.tpdo[1].add_variable(0x6064)
    node.tpdo[1].trans_type = 1
    node.tpdo[1].enabled = True
    node.tpdo[2].enabled = False  # event-driven SW + velocity: not needed, keeps the bus quiet
    node.rpdo.save()
    node.tpdo.save()
    rpdo_cfg = read_pdo_config(node, 0x1400, 0x1600)
    tpdo_cfg = read_pdo_config(node, 0x1800, 0x1A00)
    assert rpdo_cfg == (rx_cob, 1, [0x60400010, 0x60C10120]), rpdo_cfg
    assert tpdo_cfg == (tx_cob, 1, [0x60410010, 0x60640020]), tpdo_cfg
    assert node.sdo[0x1801][1].raw & 0x8000_0000, "TPDO2 should now be invalid"

    # --- 5. IP period = SYNC period, mode 7, NMT start ------------------------------------------
    set_ip_period(node)
    node.sdo[0x6060].raw = 7
    assert node.sdo[0x6061].raw == 7, "mode 7 (IP) not echoed in 0x6061"
    go_operational(node, trace)

    # --- 5./6. SYNC, CiA 402 state machine with python-canopen's BaseNode402 -------------------
    pump, _ = start_cyclic(node, network, trace)
    try:
        enable_mark = enable_operation(node, pump)
        # --- 7. IP: preload, CW bit 4, SW bit 12, a ramp of +20000 counts in 40-count steps -----
        start, ip_mark = start_ip(node, pump)
        stream_ramp(node, pump, start, 20000, 40)  # 40 counts / 2 ms = 20000 counts/s
        check_motion_record(node, pump, enable_mark, ip_mark)
        stop_ip_and_disable(node, pump)
    finally:
        pump.running = False
        network.sync.stop()
    drive.assert_alive()


def test_ip_with_mode_of_operation_in_the_cyclic_rpdo(drive, dictionary):
    """python-canopen's BaseNode402 wants 0x6060 in an RPDO and 0x6061 in a TPDO (it warns
    otherwise), and sets the mode through them (`node.op_mode = ...`). In a cyclic RPDO the drive
    then receives 0x6060 = 7 at every SYNC. Writing the mode already in force is not a mode
    change (CiA 402: the mode changes when 0x6061 shows a new one): interpolation must stay
    active and follow the setpoints."""
    node, network, trace = drive.node, drive.network, drive.trace
    node.rpdo.read()
    node.tpdo.read()
    remap_cyclic_pdos(node, [(0x6040, 0), (0x60C1, 1), (0x6060, 0)],
                      [(0x6041, 0), (0x6064, 0), (0x6061, 0)])
    set_ip_period(node)
    go_operational(node, trace)
    pump, _ = start_cyclic(node, network, trace)
    try:
        assert 0x6060 in node.rpdo_pointers and 0x6061 in node.tpdo_pointers
        node.op_mode = "INTERPOLATED POSITION"  # through RPDO1; p402 logs, not raises, on timeout
        assert node.op_mode == "INTERPOLATED POSITION"
        assert node.sdo[0x6061].raw == 7
        enable_mark = enable_operation(node, pump)
        start, ip_mark = start_ip(node, pump)
        # IP must still be active 50 SYNC periods later, with 0x6060 = 7 in every RPDO.
        t_ip = pump.samples[-1][0]
        wait_until(lambda: pump.samples[-1][0] >= t_ip + 0.1, 20.0, "100 ms of TPDO1", pump.status)
        still = [f"0x{sw:04X}" for t, sw, _, _ in pump.samples[ip_mark:] if not sw & SW_IP_ACTIVE]
        assert not still, f"SW bit 12 (IP active) cleared while 0x6060 = 7 is rewritten: {still[:8]}"
        stream_ramp(node, pump, start, 4000, 40)
        check_motion_record(node, pump, enable_mark, ip_mark)
        stop_ip_and_disable(node, pump)
    finally:
        pump.running = False
        network.sync.stop()
    drive.assert_alive()


def test_sdo_abort_codes_seen_by_python_canopen(drive, dictionary):
    node, trace = drive.node, drive.trace
    sdo_tx = 0x580 + NODE_ID
    results = []  # (what, expected, got)

    def expect(what, expected, fn):
        """Run fn; record the abort code and check the abort frame itself (CiA 301 7.2.4.3.17)."""
        mark = trace.mark()
        got = abort_code(fn)
        frames = trace.since(mark, sdo_tx)
        exp_set = expected if isinstance(expected, tuple) else (expected,)
        ok = got in exp_set
        if got is not None:
            fr = frames[-1]
            if len(fr.data) != 8 or fr.data[0] != 0x80:
                ok, what = False, f"{what} [abort frame {fr}]"
        results.append((what, exp_set, got, ok))
        return got

    def wr(index, sub, value):
        var = node.sdo[index] if sub is None else node.sdo[index][sub]
        return lambda: setattr(var, "raw", value)

    # Objects / sub-indices that do not exist (bypassing python-canopen's OD, which has none).
    missing = next(i for i in range(0x2000, 0x6000) if i not in dictionary.objects)
    expect(f"upload 0x{missing:04X}:00 (no such object)", 0x06020000,
           lambda: node.sdo.upload(missing, 0))
    top = max(s["sub"] for s in dictionary.objects[0x1018]["sub"])
    expect(f"upload 0x1018:{top + 1:02X} (no such sub-index)", 0x06090011,
           lambda: node.sdo.upload(0x1018, top + 1))
    expect("upload 0x1000:01 (sub-index of a VAR)", 0x06090011,
           lambda: node.sdo.upload(0x1000, 1))
    expect(f"download 0x{missing:04X}:00 (no such object)", 0x06020000,
           lambda: node.sdo.download(missing, 0, b"\x01\x00\x00\x00"))
    # Access.
    expect("download 0x1018:01 (ro)", 0x06010002, wr(0x1018, 1, 0x1234))
    expect("download 0x1000 (const)", 0x06010002, wr(0x1000, None, 0x00020192))
    expect("download 0x6041 (ro)", 0x06010002, wr(0x6041, None, 0x0006))
    assert dictionary.entry(0x60C4, 6)["access"] == "wo"
    expect("upload 0x60C4:06 (wo)", 0x06010001, lambda: node.sdo.upload(0x60C4, 6))
    # Length.
    expect("download 0x6040 (u16) with 4 bytes", (0x06070010, 0x06070012),
           lambda: node.sdo.download(0x6040, 0, b"\x06\x00\x00\x00"))
    # Range (the TOML's min / max).
    hi = dictionary.entry(0x6060)["max"]
    expect(f"download 0x6060 = {hi + 1} (max {hi})", 0x06090031, wr(0x6060, None, hi + 1))
    assert node.sdo[0x6060].raw == dictionary.default(0x6060), "rejected write was stored"
    lo = dictionary.entry(0x60C2, 2)["min"]
    expect(f"download 0x60C2:02 = {lo - 1} (min {lo})", 0x06090032, wr(0x60C2, 2, lo - 1))
    # PDO remap rules (CiA 301 7.5.2.35/36), with RPDO1 valid as at boot.
    rx_cob = dictionary.default(0x1400, 1)
    assert rx_cob & 0x8000_0000 == 0, "RPDO1 must be valid at boot for this check"
    expect("download 0x1600:01 while RPDO1 is valid", 0x06010000,
           wr(0x1600, 1, 0x60400010))
    expect("download 0x1600:00 = 0 while RPDO1 is valid", 0x06010000, wr(0x1600, 0, 0))
    expect("disable RPDO1 (0x1400:01 | 0x80000000)", None, wr(0x1400, 1, rx_cob | 0x8000_0000))
    expect("download 0x1600:01 while 0x1600:00 != 0", 0x06010000, wr(0x1600, 1, 0x60400010))
    expect("download 0x1600:00 = 0", None, wr(0x1600, 0, 0))
    expect("map 0x6041 (ro) into an RPDO", 0x06040041, wr(0x1600, 1, 0x60410010))
    expect("map a nonexistent object", (0x06020000, 0x06040041),
           wr(0x1600, 1, mapping_entry(missing, 0, 32)))
    expect("0x1600:01 = 0x60C10120", None, wr(0x1600, 1, 0x60C10120))
    expect("0x1600:02 = 0x607A0020", None, wr(0x1600, 2, 0x607A0020))
    expect("0x1600:03 = 0x60400010", None, wr(0x1600, 3, 0x60400010))
    expect("0x1600:00 = 3 (80 bits)", 0x06040042, wr(0x1600, 0, 3))
    expect("enable RPDO1 with an empty mapping", 0x06090030, wr(0x1400, 1, rx_cob))
    expect("0x1400:02 = 241 (reserved)", 0x06090030, wr(0x1400, 2, 241))
    expect("0x1600:00 = 2", None, wr(0x1600, 0, 2))
    expect("enable RPDO1 again", None, wr(0x1400, 1, rx_cob))
    assert read_pdo_config(node, 0x1400, 0x1600) == (rx_cob, 1, [0x60C10120, 0x607A0020])

    # Segmented download (python-canopen forced) of a u32, then expedited upload.
    window = dictionary.default(0x6065)
    mark = trace.mark()
    node.sdo.download(0x6065, 0, (12345).to_bytes(4, "little"), force_segment=True)
    seg = trace.since(mark, sdo_tx)
    assert node.sdo[0x6065].raw == 12345
    node.sdo[0x6065].raw = window
    assert [f.data[0] & 0xE0 for f in seg] == [0x60, 0x20], f"segmented download: {seg}"

    # Expedited upload responses carry the size of the type (CiA 301: 0x43/0x47/0x4B/0x4F).
    for index, cmd in ((0x1000, 0x43), (0x6041, 0x4B), (0x6061, 0x4F), (0x6064, 0x43)):
        mark = trace.mark()
        node.sdo.upload(index, 0)
        resp = trace.since(mark, sdo_tx)
        ok = len(resp) == 1 and len(resp[-1].data) == 8 and resp[-1].data[0] == cmd \
            and resp[-1].data[1:4] == bytes([index & 0xFF, index >> 8, 0])
        results.append((f"upload 0x{index:04X} response command 0x{cmd:02X}", (cmd,),
                        resp[-1].data[0] if resp else None, ok))

    table = "\n".join(
        f"  {'ok  ' if ok else 'FAIL'} {what}: expected "
        f"{' or '.join('success' if e is None else f'0x{e:08X}' for e in exp)}, got "
        f"{'success' if got is None else f'0x{got:08X}'}"
        for what, exp, got, ok in results)
    print(f"[interop] SDO checks:\n{table}")
    assert all(ok for *_, ok in results), f"SDO mismatches:\n{table}"
    drive.assert_alive()


# Entries whose boot value is the drive's live state, not the dictionary default.
LIVE_AT_BOOT = {(0x6041, 0)}  # statusword: Switch on disabled after boot, not 0


def test_sdo_upload_of_every_entry_matches_the_dictionary(drive, dictionary):
    """Every readable entry of our TOML, read by python-canopen right after boot: the upload
    response has the size of the entry's type (expedited, size indicated, CiA 301 7.2.4.3.6) or
    is a segmented upload of the string, and the value is the TOML default."""
    node, trace = drive.node, drive.trace
    sdo_tx = 0x580 + NODE_ID
    problems, n = [], 0
    for index in node.object_dictionary:
        obj = node.object_dictionary[index]
        entries = [obj] if isinstance(obj, odt.ODVariable) else [obj[s] for s in obj.subindices]
        for var in entries:
            if not var.readable:
                continue
            n += 1
            where = f"0x{var.index:04X}:{var.subindex:02X} {var.name!r}"
            mark = trace.mark()
            try:
                value = node.sdo[var.index].raw if isinstance(obj, odt.ODVariable) \
                    else node.sdo[var.index][var.subindex].raw
            except canopen.SdoAbortedError as e:
                problems.append(f"{where}: aborted {e}")
                continue
            first = trace.since(mark, sdo_tx)[0].data
            if var.data_type == odt.VISIBLE_STRING:
                size = len(var.default.encode())
                if size > 4:
                    want = [0x41, *size.to_bytes(4, "little")]
                    if first[0] != 0x41 or list(first[0:1]) + list(first[4:8]) != want:
                        problems.append(f"{where}: segmented upload initiate {first.hex(' ')}, "
                                        f"want 41 .. .. .. {bytes(want[1:]).hex(' ')}")
            else:
                size = len(var) // 8
                want_cmd = 0x43 | (4 - size) << 2
                if first[0] != want_cmd:
                    problems.append(f"{where}: response command 0x{first[0]:02X}, want "
                                    f"0x{want_cmd:02X} ({size} bytes)")
            if (var.index, var.subindex) not in LIVE_AT_BOOT and value != var.default:
                problems.append(f"{where}: value {value!r}, TOML default {var.default!r}")
    print(f"[interop] read {n} entries by SDO, {len(problems)} problems")
    assert not problems, "\n".join(problems)
    drive.assert_alive()


# ---------------------------------------------------------------------------------------------
# Homing mode (6), run by python-canopen's BaseNode402.homing()
# ---------------------------------------------------------------------------------------------

SW_TARGET_REACHED = 1 << 10
SW_HOMING_ATTAINED = 1 << 12
SW_HOMING_ERROR = 1 << 13
HOME_SWITCH_COUNTS = -3000  # the simulated home switch's edge (position actual at power-on)
HOME_OFFSET_COUNTS = 1234


def configure_homing(node, method: int) -> None:
    """Method, speeds, acceleration and home offset by python-canopen's SDO client, read back."""
    node.sdo[0x6098].raw = method
    node.sdo[0x6099][1].raw = 20000  # counts/s: search for the switch
    node.sdo[0x6099][2].raw = 2000  # counts/s: search for zero
    node.sdo[0x609A].raw = 200000  # counts/s^2
    node.sdo[0x607C].raw = HOME_OFFSET_COUNTS
    got = (node.sdo[0x6098].raw, node.sdo[0x6099][1].raw, node.sdo[0x6099][2].raw,
           node.sdo[0x609A].raw, node.sdo[0x607C].raw)
    assert got == (method, 20000, 2000, 200000, HOME_OFFSET_COUNTS), got
    node.TIMEOUT_HOMING_DEFAULT = 20


@pytest.mark.simdrive_args("--home-switch", f"{NODE_ID}:{HOME_SWITCH_COUNTS}")
@pytest.mark.parametrize("method", [21, 19, 37])
def test_python_canopen_homes_our_simdrive(drive, dictionary, method):
    """BaseNode402.homing() (mode 6, its state walk, CW bit 4, the CiA 402 homing statusword
    table) against our simulated drive: it reports success, statusword bits 12 (attained) and
    10 (target reached) are set, position actual is the home offset 0x607C, and the motor stands
    still there. 21 searches the switch below 0 and comes back off it; 19 starts on the switch
    (active above -3000) and moves off it downward; 37 declares the current position home."""
    node = drive.node
    assert node.sdo[0x6502].raw & 0x20, "0x6502: homing mode supported"
    configure_homing(node, method)
    before = node.sdo[0x6064].raw
    assert node.homing(), f"homing failed: SW 0x{node.sdo[0x6041].raw:04X}"
    assert node.op_mode == "HOMING"
    sw = wait_until(lambda: (lambda w: w if w & SW_TARGET_REACHED else 0)(node.sdo[0x6041].raw),
                    10.0, "statusword bit 10 after homing")
    assert sw & SW_HOMING_ATTAINED, f"SW 0x{sw:04X}: bit 12 (homing attained)"
    assert not sw & SW_HOMING_ERROR, f"SW 0x{sw:04X}: bit 13 (homing error)"
    assert sw & 0x6F == 0x27, f"SW 0x{sw:04X}: Operation enabled"
    assert node.sdo[0x6064].raw == HOME_OFFSET_COUNTS
    time.sleep(0.05)  # not a wait for a condition: the position must STAY at the offset
    assert node.sdo[0x6064].raw == HOME_OFFSET_COUNTS
    print(f"[interop] method {method}: position actual {before} -> {HOME_OFFSET_COUNTS}, "
          f"SW 0x{sw:04X}")
    node.state = "SWITCHED ON"
    drive.assert_alive()


def test_python_canopen_sees_a_homing_error_when_the_switch_is_never_found(drive, dictionary):
    """No home switch (simdrive without --home-switch): method 21's search runs to the end of the
    travel, here the software position limit 0x607D:1, and the drive reports a homing error
    (bit 13) instead of attained; homing() returns False, and the drive stays enabled."""
    node = drive.node
    configure_homing(node, 21)
    node.sdo[0x607D][1].raw = -20000
    node.sdo[0x607D][2].raw = 20000
    assert not node.homing(), "homing() succeeded without a home switch"
    sw = wait_until(lambda: (lambda w: w if w & SW_TARGET_REACHED else 0)(node.sdo[0x6041].raw),
                    10.0, "statusword bit 10 (standstill) after the homing error")
    assert sw & SW_HOMING_ERROR, f"SW 0x{sw:04X}: bit 13 (homing error)"
    assert not sw & SW_HOMING_ATTAINED, f"SW 0x{sw:04X}: bit 12"
    assert sw & 0x6F == 0x27, f"SW 0x{sw:04X}: a homing error is no fault"
    pos = node.sdo[0x6064].raw
    assert -22000 <= pos <= -20000, f"stopped at {pos}, past the -20000 limit by the braking distance"
    node.state = "SWITCHED ON"
    drive.assert_alive()

