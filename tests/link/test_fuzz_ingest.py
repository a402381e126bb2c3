"""Fuzzing the ingest path in-process with hypothesis (issue "Hardening").

Every datagram takes the real path of a live one: ``UdpLink.receive`` (one
datagram at a time through pymavlink's parser with robust parsing, partial
frames turned into counted garbage) -> ``Service._handle`` (signature check,
peer table, ``Pipeline.handle`` = ingest + engine, ``publish.encode`` and
packing/signing of every output set). Only the socket is an in-memory queue,
so an example costs milliseconds and nothing depends on the scheduler.

The valid data is the simulator's: a vehicle at rest, tilted (roll 3 deg,
pitch -2 deg, heading 30 deg), ideal 100 Hz IMU, streamed as an autopilot
does (``sim.stream.frames``: HEARTBEAT, HIGHRES_IMU, SIM_STATE, ATTITUDE,
GPS_RAW_INT, SCALED_PRESSURE, one message per datagram). The service is
aligned and navigating on a valid prefix (captured once and deep-copied into
every example); hostile datagrams are then mixed into the valid continuation.

Properties (docs/reliability.md lists them with the counts of the dedicated run):

1. ``test_invalid_input_has_no_effect``: datagrams the service must refuse
   (random bytes, truncated, corrupted and bad-CRC frames; IMU frames with a
   NaN/Inf or out-of-range value, a missing ``fields_updated`` bit, another
   IMU id, type or system, a duplicate time or a time up to 1 s back; commands,
   other systems' messages) change nothing: the output rows are bit-identical
   to those of the clean stream, every injected IMU frame is counted as
   rejected exactly once, every garbage datagram at least once.
   (Exception: a corrupted frame whose CRC-16 still matches, about 1 in 65536
   for corruptions of the length/flags/id bytes; such examples are reported as
   the hypothesis event "CRC collision" and only checked by property 2.)
2. ``test_hostile_values_keep_state_finite_and_recover``: any well-formed
   frame with any field values (NaN, Inf, float32 extremes, any uint64 time
   including "negative" int64 times, any ids, MAVLink 1 framing) never raises,
   leaves the kernel state and every output row finite and encodable, and
   after an autopilot restart (the next valid data on a new time base) the
   solution is right again: roll/pitch/yaw within 0.01 deg of the truth.
3. ``test_signed_service_ignores_all_but_the_key_holder``: with a signing key,
   unsigned frames (even perfectly valid samples), wrong-key frames with the
   genuine link id and far-future timestamps, replays of genuine frames and
   tampered signatures change nothing and are each counted.

Sizes: ``MAVINS_FUZZ_EXAMPLES=N`` runs every property with N examples (the
dedicated run, e.g. ``MAVINS_FUZZ_EXAMPLES=100000 .venv/bin/python -m pytest
tests/link/test_fuzz_ingest.py``); otherwise ``FAST_EXAMPLES`` each (a few seconds).
"""

from __future__ import annotations

import copy
import math
import os
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, event, given, note, settings
from hypothesis import strategies as st

os.environ.setdefault("MAVLINK20", "1")

from mavins.live.engine import EngineConfig, State  # noqa: E402
from mavins.link.ingest import IngestConfig  # noqa: E402
from mavins.link.links import _parser  # noqa: E402
from mavins.link.mavlink import mavlink  # noqa: E402
from mavins.service import BATCH, Service, ServiceConfig, Summary  # noqa: E402
from mavins.link.signing import now_timestamp  # noqa: E402
from sim.generate import generate  # noqa: E402
from sim.scenarios import Scenario  # noqa: E402
from sim.stream import StreamOptions, frames  # noqa: E402
from support import wrap_deg  # noqa: E402

FAST_EXAMPLES = 300
EXAMPLES = int(os.environ.get("MAVINS_FUZZ_EXAMPLES") or 0) or FAST_EXAMPLES
# the fast subset reports a failure unshrunk (shrinking these lists takes minutes); the dedicated run shrinks
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck), print_blob=True,
                phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.target]
                + ([Phase.shrink] if EXAMPLES != FAST_EXAMPLES else []))

VEH_SYS, VEH_COMP = 1, mavlink.MAV_COMP_ID_AUTOPILOT1
OWN_COMP = 191
ROLL, PITCH, YAW = 3.0, -2.0, 30.0  # deg, the simulated vehicle at rest
START = (47.397742, 8.545594, 488.0)
ALIGN_S = 0.5
BOOT_US = 1_000_000_000  # sensor time of the simulation's start: the autopilot booted 1000 s ago
PREFIX_S = 1.0  # valid data before the hostile part: aligned at 0.5 s, navigating after
CONT_S = 0.4  # valid continuation the hostile datagrams are mixed into
REC_ALIGN_SAMPLES, REC_NAV_SAMPLES = 52, 30  # recovery after a restart: > 0.5 s of alignment, then navigation
MAX_ACCEL = 16 * 9.80665  # IngestConfig defaults (the sensor range)
MAX_GYRO = math.radians(2000.0)
U64 = 2**64 - 1
KEY = bytes(range(1, 33))
WRONG_KEY = bytes(range(101, 133))

SIGNING_REASONS = ("rejected_unsigned", "rejected_bad_signature", "rejected_replayed", "rejected_stale_new_stream")
GENUINE_ADDR = ("127.0.0.1", 40001)  # where the valid stream comes from
FRAME_ADDR = ("127.0.0.1", 40002)  # well-formed hostile frames
GARBAGE_ADDR = ("127.0.0.1", 40003)  # byte-level garbage


# -- the valid stream ---------------------------------------------------------------
def _scenario() -> Scenario:
    doc = {"description": "tilted, at rest",
           "start": {"lat": START[0], "lon": START[1], "h": START[2], "roll": ROLL, "pitch": PITCH, "yaw": YAW},
           "imu": {"rate": 100.0}, "segments": [{"kind": "static", "duration": 3.0}]}
    return Scenario("tilted-rest", "test_fuzz_ingest", doc)


@dataclass
class Valid:
    """The valid stream as datagrams, split into prefix and continuation, plus what recovery needs."""

    prefix: list[bytes]
    cont: list[bytes]
    cont_imu_t: list[int | None]  # per continuation datagram: the IMU time (us) it carries, or None
    prefix_end_us: int
    f: np.ndarray  # specific force and rate of one sample at rest (for the recovery data)
    w: np.ndarray
    truth_deg: np.ndarray  # roll, pitch, yaw


def _valid_stream(signing_key: bytes | None) -> Valid:
    run = generate(_scenario(), duration=3.0, grade="ideal")
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=VEH_COMP)
    if signing_key is not None:
        enc.signing.secret_key = signing_key
        enc.signing.sign_outgoing = True
        enc.signing.link_id = 0
        enc.signing.timestamp = now_timestamp()
    prefix: list[bytes] = []
    cont: list[bytes] = []
    cont_t: list[float | None] = []
    last_prefix_us = 0
    for t, msgs in frames(run, enc, StreamOptions(sysid=VEH_SYS, compid=VEH_COMP)):
        if t > PREFIX_S + CONT_S + 1e-9:
            break
        for m in msgs:
            if hasattr(m, "time_usec"):
                m.time_usec += BOOT_US
            elif hasattr(m, "time_boot_ms"):
                m.time_boot_ms += BOOT_US // 1000
            buf = m.pack(enc)
            enc.seq = (enc.seq + 1) % 256
            if t <= PREFIX_S + 1e-9:
                prefix.append(buf)
                if m.get_type() == "HIGHRES_IMU":
                    last_prefix_us = m.time_usec
            else:
                cont.append(buf)
                cont_t.append(m.time_usec if m.get_type() == "HIGHRES_IMU" else None)
    w, f = run.rates()
    return Valid(prefix, cont, cont_t, last_prefix_us, f[5].copy(), w[5].copy(),
                 np.array(run.exact.truth[0, 7:10]))


# -- the service, fed from memory --------------------------------------------------------
class MemorySocket:
    """Stands in for the UDP socket of the master link: a queue of (datagram, sender)."""

    def __init__(self) -> None:
        self.queue: deque[tuple[bytes, tuple[str, int]]] = deque()
        self.sent = 0

    def recvmsg(self, bufsize: int, ancbufsize: int = 0):  # noqa: ANN201
        if not self.queue:
            raise BlockingIOError
        data, addr = self.queue.popleft()
        return data[:bufsize], [], 0, addr

    def recvfrom(self, bufsize: int):  # noqa: ANN201
        if not self.queue:
            raise BlockingIOError
        data, addr = self.queue.popleft()
        return data[:bufsize], addr

    def sendto(self, buf: bytes, addr: object) -> int:
        self.sent += 1
        return len(buf)

    def fileno(self) -> int:
        return -1

    def close(self) -> None:
        pass


class Rows:
    """Stands in for the solution file: keeps every output row."""

    def __init__(self) -> None:
        self.rows: list[np.ndarray] = []

    def write(self, row: np.ndarray) -> None:
        self.rows.append(np.array(row, copy=True))

    def close(self) -> None:
        pass


class Rig:
    """One Service, reset to the navigating template before each example."""

    def __init__(self, signing_key: bytes | None) -> None:
        from mavins.demo import free_udp_port

        self.valid = _valid_stream(signing_key)
        self.svc = Service(
            EngineConfig(lat=START[0], lon=START[1], alt=START[2], heading="vehicle", align=ALIGN_S),
            IngestConfig(),
            ServiceConfig(master=f"udpin:127.0.0.1:{free_udp_port()}", signing_key=signing_key, signing_state=None),
        )
        self.svc.master.sock.close()
        self.sock = MemorySocket()
        self.svc.master.sock = self.sock
        self.svc._solution = Rows()
        self.feed([(d, GENUINE_ADDR) for d in self.valid.prefix])
        assert self.svc.pipeline.engine.state is State.NAVIGATING
        self.template = (copy.deepcopy(self.svc.pipeline), copy.deepcopy(self.svc.verifier),
                         self.svc.mav.srcSystem, self.svc._sysid_known)
        self.reset()
        passed = self.feed([(d, GENUINE_ADDR) for d in self.valid.cont])
        assert not passed
        self.ref_rows = list(self.svc._solution.rows)
        self.ref_accepted = self.svc.pipeline.ingest.accepted
        assert len(self.ref_rows) >= 15 and self.ref_accepted > 0

    def reset(self) -> None:
        pipeline, verifier, sysid, known = self.template
        svc = self.svc
        svc.pipeline = copy.deepcopy(pipeline)
        svc.verifier = copy.deepcopy(verifier)
        svc.mav.srcSystem, svc._sysid_known = sysid, known
        svc.counters = Counter()
        svc.summary = Summary()
        svc._solution = Rows()
        svc.master.peers.clear()
        svc.master.parser = _parser()

    def feed(self, datagrams: list[tuple[bytes, tuple[str, int]]]) -> list[object]:
        """Run datagrams through receive + _handle; returns messages of GARBAGE_ADDR that parsed as frames."""
        self.sock.queue.extend(datagrams)
        passed = []
        while True:
            batch, n = self.svc.master.receive(BATCH)
            if n == 0:
                return passed
            for msg, addr in batch:
                if addr == GARBAGE_ADDR and msg.get_type() != "BAD_DATA":
                    passed.append(msg)
                self.svc._handle(msg, addr)

    @property
    def rows(self) -> list[np.ndarray]:
        return self.svc._solution.rows  # type: ignore[union-attr]

    def imu_rejections(self) -> int:
        return sum(self.svc.pipeline.ingest.rejected.values())

    def garbage_rejections(self) -> int:
        """Datagrams refused before the signature check (garbage, bad CRC, truncated, unknown id ...)."""
        return sum(v for k, v in self.link_rejections().items() if k not in SIGNING_REASONS)

    def link_rejections(self) -> Counter:
        return Counter({k: v for k, v in self.svc.counters.items() if k.startswith("rejected_")})

    def assert_finite(self) -> None:
        s = self.svc.pipeline.engine._s
        if s is not None:
            assert np.all(np.isfinite(s)), f"kernel state not finite: {s}"
        for r in self.rows:
            assert np.all(np.isfinite(r)), f"output row not finite: {r}"


@pytest.fixture(scope="module")
def rig() -> Rig:
    return Rig(None)


@pytest.fixture(scope="module")
def signed_rig() -> Rig:
    return Rig(KEY)


# -- strategies -------------------------------------------------------------------------
F32_EXTREMES = [0.0, -0.0, math.nan, math.inf, -math.inf, 3.4028234663852886e38, -3.4028234663852886e38,
                1.401298464324817e-45, 1e30, -1e30]
any_f32 = st.one_of(st.floats(width=32), st.sampled_from(F32_EXTREMES), st.floats(-50.0, 50.0, width=32))
non_finite = st.sampled_from([math.nan, math.inf, -math.inf])
u8 = st.integers(0, 255)
u16 = st.integers(0, 2**16 - 1)
i16 = st.integers(-(2**15), 2**15 - 1)
u32 = st.integers(0, 2**32 - 1)
i32 = st.integers(-(2**31), 2**31 - 1)
# times: absolute (any uint64, with "negative" int64 values and other edges), or relative to the last valid sample
abs_time = st.one_of(st.integers(0, U64), st.sampled_from([0, 1, 2**31, 2**32 - 1, 2**53, 2**63, U64 - 999_999, U64]))
# edges of the time policy: duplicate, within / beyond 1 s back (restart), beyond --max-gap, beyond 60 s (restart)
TIME_EDGES_US = [0, 1, -1, -999_999, -1_000_000, -1_000_001, 999_999, 1_000_000, 1_000_001, 60_000_000, 60_000_001,
                 -60_000_001]
rel_time = st.one_of(st.integers(-5_000_000, 5_000_000), st.sampled_from(TIME_EDGES_US)).map(lambda d: ("rel", d))
any_time = st.one_of(rel_time, rel_time, abs_time)
sysid = st.one_of(st.just(VEH_SYS), u8)
compid = st.one_of(st.just(VEH_COMP), st.just(OWN_COMP), u8)
IMU_TYPES = ("HIGHRES_IMU", "RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3")


@dataclass(frozen=True)
class Spec:
    """A well-formed MAVLink frame to build at injection time (``time`` may be relative)."""

    name: str
    fields: tuple
    time: object = 0
    sysid: int = VEH_SYS
    compid: int = VEH_COMP
    mavlink1: bool = False


def _resolve(t: object, base_us: int) -> int:
    if isinstance(t, tuple):
        return min(max(base_us + t[1], 0), U64)
    return int(t)  # type: ignore[call-overload]


def build(spec: Spec, base_us: int, enc: mavlink.MAVLink) -> bytes:
    """Encode a Spec; IMU and GPS times relative to ``base_us`` (the last valid sample)."""
    t = _resolve(spec.time, base_us)
    f = spec.fields
    n = spec.name
    if n == "HIGHRES_IMU":
        m = enc.highres_imu_encode(t, *f)
    elif n == "RAW_IMU":
        m = enc.raw_imu_encode(t, *f)
    elif n in ("SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3"):
        m = getattr(enc, n.lower() + "_encode")((t // 1000) % 2**32, *f)
    elif n == "GPS_RAW_INT":
        m = enc.gps_raw_int_encode(t, *f)
    else:
        m = getattr(enc, n.lower() + "_encode")(*f)
    enc.srcSystem, enc.srcComponent = spec.sysid, spec.compid
    return m.pack(enc, force_mavlink1=spec.mavlink1)


@st.composite
def highres_fields(draw, values=None, fields_updated=None, imu_id=None) -> tuple:  # noqa: ANN001
    v = list(values) if values is not None else [draw(any_f32) for _ in range(6)]
    rest = [draw(any_f32) for _ in range(7)]  # mag, pressures, altitude, temperature
    fu = draw(fields_updated if fields_updated is not None else st.one_of(st.just(0b111111), st.just(0x1FFF), u16))
    i = draw(imu_id if imu_id is not None else st.one_of(st.just(0), u8))
    return (*v, *rest, fu, i)


def int_imu_fields(name: str):  # noqa: ANN201
    n = 9
    if name == "RAW_IMU":
        return st.tuples(*([i16] * n), u8, i16)
    return st.tuples(*([i16] * n), i16)


def any_imu_spec(name_strategy=st.sampled_from(IMU_TYPES)):  # noqa: ANN001, ANN201
    @st.composite
    def spec(draw) -> Spec:  # noqa: ANN001
        name = draw(name_strategy)
        fields = draw(highres_fields() if name == "HIGHRES_IMU" else int_imu_fields(name))
        return Spec(name, fields, draw(any_time), draw(sysid), draw(compid), draw(st.booleans()) and draw(st.booleans()))

    return spec()


other_specs = st.one_of(
    st.builds(lambda f, t, s, c: Spec("GPS_RAW_INT", f, t, s, c),
              st.tuples(u8, i32, i32, i32, u16, u16, u16, u16, u8, i32, u32, u32, u32, u32, u16), any_time, sysid, compid),
    st.builds(lambda f, s, c: Spec("GLOBAL_POSITION_INT", f, 0, s, c),
              st.tuples(u32, i32, i32, i32, i32, i16, i16, i16, u16), sysid, compid),
    st.builds(lambda f, s, c: Spec("ATTITUDE", f, 0, s, c), st.tuples(u32, *([any_f32] * 6)), sysid, compid),
    st.builds(lambda f, s, c: Spec("COMMAND_LONG", f, 0, s, c),
              st.tuples(st.one_of(st.just(VEH_SYS), u8), st.one_of(st.just(OWN_COMP), u8),
                        st.one_of(st.sampled_from([mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                                                   mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN,
                                                   mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_DO_SET_HOME]), u16),
                        u8, *([any_f32] * 7)), sysid, compid),
    st.builds(lambda f, s, c: Spec("COMMAND_INT", f, 0, s, c),
              st.tuples(u8, u8, u8, u16, u8, u8, any_f32, any_f32, any_f32, any_f32, i32, i32, any_f32), sysid, compid),
    st.builds(lambda f, s, c: Spec("COMMAND_ACK", f, 0, s, c), st.tuples(u16, u8, u8, i32, u8, u8), sysid, compid),
    st.builds(lambda f, s, c: Spec("SETUP_SIGNING", f, 0, s, c),
              st.tuples(u8, u8, st.lists(u8, min_size=32, max_size=32), st.integers(0, 2**64 - 1)), sysid, compid),
    st.builds(lambda f, s, c: Spec("HEARTBEAT", f, 0, s, c), st.tuples(u8, u8, u8, u32, u8), sysid, compid),
)


@st.composite
def invalid_imu_spec(draw) -> Spec:  # noqa: ANN001
    """An IMU frame the ingest must reject at the point where it is injected."""
    why = draw(st.sampled_from(["non_finite", "out_of_range", "fields_missing", "other_id", "other_system",
                                "other_type", "duplicate", "back_within_1s"]))
    values = [draw(any_f32) for _ in range(6)]
    fields_updated: st.SearchStrategy = st.just(0b111111) | u16.map(lambda x: x | 0b111111)
    imu_id: st.SearchStrategy = st.just(0)
    name, t, sys_ = "HIGHRES_IMU", draw(any_time), VEH_SYS
    if why == "non_finite":
        values[draw(st.integers(0, 5))] = draw(non_finite)
    elif why == "out_of_range":
        i = draw(st.integers(0, 5))
        limit = MAX_ACCEL if i < 3 else MAX_GYRO
        above = float(np.nextafter(np.float32(limit), np.float32(np.inf)))  # the first float32 beyond the range
        values[i] = draw(st.floats(above, 3.4028234663852886e38, width=32)) * draw(st.sampled_from([1, -1]))
    elif why == "fields_missing":
        fields_updated = u16.filter(lambda x: x & 0b111111 != 0b111111)
    elif why == "other_id":
        imu_id = st.integers(1, 255)
    elif why == "other_system":
        sys_ = draw(u8.filter(lambda s: s != VEH_SYS))
        name = draw(st.sampled_from(IMU_TYPES))
    elif why == "other_type":
        name = draw(st.sampled_from(IMU_TYPES[1:]))
    else:
        # a late or repeated datagram: plausible values, only its time is wrong
        values = [draw(st.floats(-20.0, 20.0, width=32)) for _ in range(6)]
        t = ("rel", 0) if why == "duplicate" else ("rel", draw(st.integers(-999_999, -1)))
    event(f"invalid IMU frame: {why}")
    if name == "HIGHRES_IMU":
        fields = draw(highres_fields(values=values, fields_updated=fields_updated, imu_id=imu_id))
    else:
        fields = draw(int_imu_fields(name))
    return Spec(name, fields, t, sys_, draw(compid))


@st.composite
def garbage(draw, sample_frames: list[tuple[bytes, int]]) -> bytes:  # noqa: ANN001
    """Byte-level garbage: random bytes, or a real frame truncated, corrupted or with bytes inserted/removed.

    Changes stay inside the part of a frame its CRC covers (a signature is
    checked only with a key: see property 3), so no change is undetectable
    except by a CRC-16 collision.
    """
    kind = draw(st.sampled_from(["random", "prefixed", "truncated", "corrupted", "spliced", "empty"]))
    event(f"garbage: {kind}")
    if kind == "random":
        return draw(st.binary(min_size=1, max_size=300))
    if kind == "prefixed":
        return draw(st.sampled_from([b"\xfd", b"\xfe"])) + draw(st.binary(max_size=300))
    if kind == "empty":
        return b""
    frame, covered = draw(st.sampled_from(sample_frames))
    if kind == "truncated":
        return frame[: draw(st.integers(1, len(frame) - 1))]
    if kind == "corrupted":
        i = draw(st.integers(1, covered - 1))
        b = draw(u8.filter(lambda x: x != frame[i]))
        return frame[:i] + bytes([b]) + frame[i + 1:]
    i = draw(st.integers(1, covered - 1))
    if draw(st.booleans()):
        return frame[:i] + draw(st.binary(min_size=1, max_size=4)) + frame[i:]
    return frame[:i] + frame[i + draw(st.integers(1, min(4, covered - i))):]


def _sample_frames() -> list[tuple[bytes, int]]:
    """Frames to corrupt, with the length their CRC covers (all but a signature)."""
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=VEH_COMP)
    out = [enc.highres_imu_encode(1_234_567, 0.1, -0.2, -9.8, 0.001, 0.002, -0.003, 0.2, 0.0, 0.4, 1013.0, 0.0, 488.0,
                                  20.0, 0b111111, 0).pack(enc),
           enc.attitude_encode(1234, 0.05, -0.03, 0.5, 0.0, 0.0, 0.0).pack(enc),
           enc.gps_raw_int_encode(1_234_567, 3, 473977420, 85455940, 488000, 80, 120, 0, 0, 12).pack(enc),
           enc.highres_imu_encode(1_234_567, 0.1, -0.2, -9.8, 0.001, 0.002, -0.003, 0, 0, 0, 0, 0, 0, 0, 0b111111,
                                  0).pack(enc, force_mavlink1=True)]
    enc.signing.secret_key, enc.signing.sign_outgoing, enc.signing.timestamp = KEY, True, now_timestamp()
    out.append(enc.highres_imu_encode(1_234_567, 0.1, -0.2, -9.8, 0.001, 0.002, -0.003, 0, 0, 0, 0, 0, 0, 0,
                                      0b111111, 0).pack(enc))
    return [(f, len(f) - (13 if f[0] == 0xFD and f[2] & 1 else 0)) for f in out]


SAMPLE_FRAMES = _sample_frames()


def _mix(draw, cont: list[bytes], hostile: list) -> list[tuple[int, object]]:  # noqa: ANN001
    """Positions in the continuation (0..len) for each hostile item, in stream order."""
    pos = [draw(st.integers(0, len(cont))) for _ in hostile]
    return sorted(zip(pos, range(len(hostile))), key=lambda p: p)


def _last_valid_us(valid: Valid, pos: int) -> int:
    """Time (us) of the last valid IMU sample delivered before continuation position ``pos``."""
    ts = [t for t in valid.cont_imu_t[:pos] if t is not None]
    return ts[-1] if ts else valid.prefix_end_us


def _unknown(msg: object) -> bool:
    """A frame of a message id the dialect does not know: pymavlink cannot check its CRC."""
    return isinstance(msg, mavlink.MAVLink_unknown)


def _feed_expect_clean_output(rig: "Rig", stream: list) -> list | None:
    """Feed the stream; the state stays finite and the output rows equal the clean stream's bit for bit.

    Returns the messages that passed parsing, or None when a corrupted frame happened to parse
    as a valid one (a CRC collision: the example then proves nothing and is only counted).
    """
    passed = rig.feed(stream)
    rig.assert_finite()
    if any(not _unknown(m) for m in passed):
        event("CRC collision (a corrupted frame parsed as valid)")
        return None
    rows = rig.rows
    assert len(rows) == len(rig.ref_rows)
    for got, ref in zip(rows, rig.ref_rows):
        assert np.array_equal(got, ref), (got, ref)
    return passed


# -- 1. invalid input has no effect -------------------------------------------------------
@FUZZ
@given(data=st.data())
def test_invalid_input_has_no_effect(rig: Rig, data: st.DataObject) -> None:
    hostile = data.draw(st.lists(st.one_of(invalid_imu_spec(), invalid_imu_spec(), other_specs, garbage(SAMPLE_FRAMES)),
                                 min_size=1, max_size=25), label="hostile")
    order = _mix(data.draw, rig.valid.cont, hostile)
    rig.reset()
    enc = mavlink.MAVLink(None)
    stream: list[tuple[bytes, tuple[str, int]]] = []
    n_imu = n_garbage = 0
    k = 0
    for pos, i in order + [(len(rig.valid.cont) + 1, None)]:
        while k < min(pos, len(rig.valid.cont)):
            stream.append((rig.valid.cont[k], GENUINE_ADDR))
            k += 1
        if i is None:
            break
        h = hostile[i]
        if isinstance(h, Spec):
            stream.append((build(h, _last_valid_us(rig.valid, pos), enc), FRAME_ADDR))
            n_imu += h.name in IMU_TYPES
        else:
            stream.append((h, GARBAGE_ADDR))
            n_garbage += 1
    note(f"{len(stream)} datagrams, {n_imu} invalid IMU frames, {n_garbage} garbage")
    passed = _feed_expect_clean_output(rig, stream)
    if passed is None:
        return
    if passed:
        event("garbage parsed as a frame of unknown id (no CRC check possible)")
    # garbage never earns output: not even a "frame" with an unknown id, whose CRC nobody can check
    assert GARBAGE_ADDR not in rig.svc.master.peers, [m.get_type() for m in passed]
    assert rig.svc.pipeline.ingest.accepted == rig.ref_accepted
    assert rig.svc.pipeline.engine.counters["restarts"] == 0
    assert rig.imu_rejections() == n_imu, dict(rig.svc.pipeline.ingest.rejected)
    assert rig.garbage_rejections() >= n_garbage


# -- 2. hostile values: finite, and right again after a restart ------------------------------
@FUZZ
@given(data=st.data())
def test_hostile_values_keep_state_finite_and_recover(rig: Rig, data: st.DataObject) -> None:
    hostile = data.draw(st.lists(st.one_of(any_imu_spec(), any_imu_spec(st.just("HIGHRES_IMU")), other_specs,
                                           garbage(SAMPLE_FRAMES)), min_size=1, max_size=30), label="hostile")
    repeat = data.draw(st.integers(1, 40), label="repeat the last IMU frame n times, time advancing")
    step_us = data.draw(st.sampled_from([1, 2_500, 10_000, 999_999, 1_000_001]), label="step")
    rig.reset()
    enc = mavlink.MAVLink(None)
    base = rig.valid.prefix_end_us
    stream = []
    last_imu: Spec | None = None
    for h in hostile:
        if isinstance(h, Spec):
            stream.append((build(h, base, enc), FRAME_ADDR))
            if h.name == "HIGHRES_IMU":
                last_imu = h
        else:
            stream.append((h, GARBAGE_ADDR))
    if last_imu is not None:
        t0 = _resolve(last_imu.time, base)
        for j in range(1, repeat):
            stream.append((build(Spec(last_imu.name, last_imu.fields, min(t0 + j * step_us, U64), last_imu.sysid,
                                      last_imu.compid), base, enc), FRAME_ADDR))
    rig.feed(stream)
    rig.assert_finite()
    # the autopilot restarts: valid data on a new time base (forward by 100 s, or back if that overflows)
    last = rig.svc.pipeline.ingest.last_t
    t_new = int(last * 1e6) + 100_000_000 if last is not None and last * 1e6 + 2e8 < U64 else 1_000_000_000
    if last is not None and t_new <= last * 1e6:
        t_new = 1_000_000_000
    n_rows = len(rig.rows)
    rig.feed(_recovery(rig.valid, t_new))
    rig.assert_finite()
    eng = rig.svc.pipeline.engine
    assert eng.state is State.NAVIGATING, (eng.state, eng.counters)
    new_rows = rig.rows[n_rows:]
    assert len(new_rows) >= 10
    for r in new_rows[-5:]:
        assert r[0] * 1e6 >= t_new - 1
        err = wrap_deg(np.degrees(r[7:10]) - rig.valid.truth_deg)
        assert np.all(np.abs(err) < 0.01), err


def _recovery(valid: Valid, t0_us: int) -> list[tuple[bytes, tuple[str, int]]]:
    """Valid data at rest from sensor time t0: ATTITUDE (heading source), then 100 Hz HIGHRES_IMU."""
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=VEH_COMP)
    r, p, y = np.radians(valid.truth_deg)
    out = [enc.attitude_encode((t0_us // 1000) % 2**32, r, p, y, 0.0, 0.0, 0.0).pack(enc)]
    for i in range(REC_ALIGN_SAMPLES + REC_NAV_SAMPLES):
        out.append(enc.highres_imu_encode(t0_us + i * 10_000, *valid.f, *valid.w, 0, 0, 0, 0, 0, 0, 20.0,
                                          0b111111, 0).pack(enc))
    return [(d, GENUINE_ADDR) for d in out]


# -- 3. with a key, only the key holder counts ------------------------------------------
@st.composite
def signing_attack(draw, valid: Valid):  # noqa: ANN001, ANN201
    """(kind, builder): a frame without the key, built at its position in the stream."""
    kind = draw(st.sampled_from(["unsigned", "wrong_key", "replay", "tampered_signature", "tampered_timestamp",
                                 "garbage"]))
    event(f"signing attack: {kind}")
    if kind == "garbage":
        return kind, draw(garbage(SAMPLE_FRAMES))
    if kind in ("unsigned", "wrong_key"):
        spec = draw(st.one_of(any_imu_spec(st.just("HIGHRES_IMU")), other_specs,
                              # a perfectly plausible sample from the vehicle: accepted by a service without a key
                              st.builds(lambda rel: Spec("HIGHRES_IMU", (*valid.f, 0.5, 0.0, 0.0, 0, 0, 0, 0, 0, 0,
                                                                         20.0, 0b111111, 0), ("rel", rel)),
                                        st.integers(1, 900_000))))
        link_id = draw(st.one_of(st.just(0), u8))
        ts = draw(st.one_of(st.just("far_future"), st.just("now"), st.integers(0, 2**48 - 1)))
        return kind, (spec, link_id, ts)
    if kind == "replay":
        return kind, draw(st.integers(0, 10**6))
    return kind, (draw(st.integers(0, len(valid.cont) - 1)), draw(st.integers(1, 6)), draw(st.integers(1, 255)))


@FUZZ
@given(data=st.data())
def test_signed_service_ignores_all_but_the_key_holder(signed_rig: Rig, data: st.DataObject) -> None:
    rig = signed_rig
    valid = rig.valid
    attacks = data.draw(st.lists(signing_attack(valid), min_size=1, max_size=20), label="attacks")
    order = _mix(data.draw, valid.cont, attacks)
    rig.reset()
    stream: list[tuple[bytes, tuple[str, int]]] = []
    n_frames = n_garbage = 0
    k = 0
    for pos, i in order + [(len(valid.cont) + 1, None)]:
        while k < min(pos, len(valid.cont)):
            stream.append((valid.cont[k], GENUINE_ADDR))
            k += 1
        if i is None:
            break
        kind, arg = attacks[i]
        if kind == "garbage":
            stream.append((arg, GARBAGE_ADDR))
            n_garbage += 1
            continue
        n_frames += 1
        if kind in ("unsigned", "wrong_key"):
            spec, link_id, ts = arg
            enc = mavlink.MAVLink(None)
            if kind == "wrong_key":
                enc.signing.secret_key, enc.signing.sign_outgoing, enc.signing.link_id = WRONG_KEY, True, link_id
                enc.signing.timestamp = (now_timestamp() + 86_400 * 100_000 if ts == "far_future"
                                         else now_timestamp() if ts == "now" else ts)
            stream.append((build(spec, _last_valid_us(valid, pos), enc), FRAME_ADDR))
        elif kind == "replay":
            # a genuine frame delivered earlier (prefix, or continuation before this point)
            delivered = valid.prefix + valid.cont[:k]
            stream.append((delivered[arg % len(delivered)], FRAME_ADDR))
        else:
            j, back, x = arg
            frame = bytearray(valid.cont[j])
            where = len(frame) - back if kind == "tampered_signature" else len(frame) - 6 - back
            frame[where] ^= x
            stream.append((bytes(frame), FRAME_ADDR))
    passed = _feed_expect_clean_output(rig, stream)
    if passed is None:
        return
    assert rig.svc.pipeline.ingest.accepted == rig.ref_accepted
    rejected = rig.link_rejections()
    signing = sum(v for key, v in rejected.items() if key in SIGNING_REASONS)
    # garbage that parses as a frame of an unknown id may be refused as unsigned or as garbage
    assert n_frames <= signing <= n_frames + len(passed), rejected
    assert sum(rejected.values()) >= n_frames + n_garbage, rejected
    assert not rig.svc.master.peers.keys() - {GENUINE_ADDR}, "only the key holder earns output"


# -- the failures the fuzzing found, pinned as plain regression tests ------------------------
def _imu_frame(t_us: int, f: tuple = (0.0, 0.0, -9.80665), w: tuple = (0.0, 0.0, 0.0), imu_id: int = 0) -> bytes:
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=VEH_COMP)
    return enc.highres_imu_encode(t_us, *f, *w, 0, 0, 0, 0, 0, 0, 20.0, 0b111111, imu_id).pack(enc)


def test_frame_of_unknown_id_earns_no_output(rig: Rig) -> None:
    """12 bytes that look like a MAVLink 2 header of an unknown message id: pymavlink cannot check their CRC
    and returns a MAVLink_unknown; that is no evidence of a peer, so it must not be authorised."""
    rig.reset()
    junk = bytes([0xFD, 0, 0, 0, 0, 1, 1, 0xFF, 0xFF, 0xFF, 0x12, 0x34])
    rig.feed([(junk, GARBAGE_ADDR)])
    assert GARBAGE_ADDR not in rig.svc.master.peers
    assert rig.garbage_rejections() == 1, dict(rig.svc.counters)


def test_rejected_frame_never_restarts_the_engine(rig: Rig) -> None:
    """One late datagram (time_backwards, within 1 s) and then a frame rejected for another reason (here a
    second IMU, id 1, on another clock) must not be taken for an autopilot restart."""
    rig.reset()
    last = rig.valid.prefix_end_us
    rig.feed([(_imu_frame(last - 5_000), FRAME_ADDR),  # reordered: rejected time_backwards
              (_imu_frame(500_000, imu_id=1), FRAME_ADDR),  # another IMU: rejected other_imu
              (_imu_frame(500_000, f=(math.nan, 0.0, -9.8)), FRAME_ADDR)]  # a NaN sample: rejected non_finite
             + [(d, GENUINE_ADDR) for d in rig.valid.cont])
    assert rig.svc.pipeline.engine.counters["restarts"] == 0
    assert dict(rig.svc.pipeline.ingest.rejected) == {"time_backwards": 1, "other_imu": 1, "non_finite": 1}
    assert len(rig.rows) == len(rig.ref_rows)


def test_long_stream_of_extreme_but_in_range_samples(rig: Rig) -> None:
    """600 samples within the sensor range (16 g down), 0.99 s apart (each gap bridged, below --max-gap): the
    unaided vertical channel runs away (through the Earth's centre after ~450 samples). The service must stay
    up, keep the kernel state and every output finite and encodable (GLOBAL_POSITION_INT carries int32 mm,
    2147 km), and navigate correctly again after the next restart."""
    rig.reset()
    t = rig.valid.prefix_end_us
    stream = [(_imu_frame(t + i * 990_000, f=(0.0, 0.0, 150.0)), FRAME_ADDR) for i in range(1, 601)]
    rig.feed(stream)  # raised struct.error from publish.encode at ~166 samples, NaN state at ~455
    rig.assert_finite()
    last = rig.svc.pipeline.ingest.last_t
    n = len(rig.rows)
    rig.feed(_recovery(rig.valid, int(last * 1e6) + 100_000_000))
    rig.assert_finite()
    assert rig.svc.pipeline.engine.state is State.NAVIGATING
    err = wrap_deg(np.degrees(rig.rows[-1][7:10]) - rig.valid.truth_deg)
    assert len(rig.rows) > n and np.all(np.abs(err) < 0.01)
