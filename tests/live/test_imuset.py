"""What the mutation runs found unchecked in mavins/live/imuset.py (live ``--imus``) and mavins/navfdi.py (``mavins nav IMU0 IMU1 ...
--fdi-log``), docs/testing.md.

In-process: real pymavlink messages (encoded by a sender, packed, parsed back) into ``ImuSet.sample``, real
IMU files in tmp_path into ``read_imus`` and ``run_nav_fdi``. Expected values come from the contract
(docs/redundancy.md "Live" and "The monitor", CONVENTIONS "Redundant IMUs": IMU numbering, 1.5 ms instants,
one fused sample per instant on the first IMU's time, a missing IMU holding its last rates, the 1 s
discovery, STATUSTEXT wording and levels, FDI.csv columns), MAVLink common.xml (MAV_SYS_STATUS_SENSOR
3D_GYRO = 1, 3D_ACCEL = 2, 3D_GYRO2 = 0x20000, 3D_ACCEL2 = 0x40000) and arithmetic:

* the IMUs see noise-free, identical rates (float32-exact on the wire) except where a test adds a fault f
  to one axis of one IMU, so a window's statistic is exactly its non-centrality
  f^2 P_jj / sigma^2 / (1 + v): P_jj = 2/3 for three IMUs in one frame, 1/2 for two; sigma^2 = N^2 / T
  with N the white noise of the spec keys (deg/sqrt(h) -> rad/sqrt(s), m/s/sqrt(h) -> m/s/sqrt(s)) and T
  the window (0.5 s); v the bias estimate's variance before window k, 1/(k - 1) while the tracker is
  the running mean (k <= 120) and was never frozen, the documented recursion otherwise;
* the thresholds are chi-square upper quantiles with n - 3 degrees of freedom, from the closed-form tails
  of Abramowitz & Stegun 26.4.4/26.4.5, by bisection;
* the fused rate of an instant is the mean of the IMUs' rates (least squares, equal noise), with a
  third of a fault in the window that reveals it and none after its isolation.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from mavins import navfdi as fdi  # the offline multi-IMU face (mavins/navfdi.py)
from mavins.core import errmodel
from mavins.core.fdi import FdiEvent
from mavins.core.grades import grade_figures
from mavins.core.settings import Strapdown
from mavins.common.files import DataFileError
from mavins.live.imuset import ImuSet, imu_index
from mavins.link.ingest import IngestConfig
from mavins.link.mavlink import mavlink
from mavins.nav import NavOptions
import chi2_closed as cc

GYRO, ACCEL, GYRO2, ACCEL2 = 1, 2, 0x20000, 0x40000  # MAV_SYS_STATUS_SENSOR_* (common.xml)
BOTH = GYRO | ACCEL | GYRO2 | ACCEL2
W = (0.25, -0.125, 0.5)  # rad/s, exact in float32
F = (0.5, 0.25, -9.75)  # m/s^2
SPEC = {"gyro_arw": 0.6, "accel_vrw": 0.6}  # deg/sqrt(h), m/s/sqrt(h)
T_WIN = 0.5  # s: the monitor's window; at 2 Hz one instant a window
SIG_G2 = (math.radians(0.6) / 60.0) ** 2 / T_WIN  # rad^2/s^2: white noise over the window
SIG_A2 = (0.6 / 60.0) ** 2 / T_WIN


def wire(make, sysid: int = 1, compid: int = 1):
    tx = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    return mavlink.MAVLink(None).decode(bytearray(make(tx).pack(tx)))


def hr(t_us: int, imu: int, gyro=W, acc=F, mag=None, sysid: int = 1, compid: int = 1):
    """HIGHRES_IMU ``id`` imu at t_us; the magnetometer fields flagged only when given."""
    bits = 0b111111 | (0b111000000 if mag else 0)
    m = mag or (0.0, 0.0, 0.0)
    return wire(lambda x: x.highres_imu_encode(t_us, *acc, *gyro, *m, 1013.0, 0.0, 0.0, 20.0, bits, imu),
                sysid, compid)


def new_set(imus=(0, 1), false_alarm: float = 1e-6, **cfg) -> ImuSet:
    return ImuSet(IngestConfig(**cfg), imus, SPEC, false_alarm)


def run_instants(s: ImuSet, n: int, faults: dict) -> list[dict]:
    """Instant k at t = 10 + 0.5 k s, every IMU of the set in its order; faults[(imu, k)] = (gyro, accel)
    offsets. Per instant: the fused sample, the drained events and tests, and the SYS_STATUS bits."""
    rec = []
    for k in range(n):
        outs = []
        for imu in s.order:
            dg, da = faults.get((imu, k), ((0.0,) * 3, (0.0,) * 3))
            outs.append(s.sample(hr(10_000_000 + 500_000 * k, imu, [a + b for a, b in zip(W, dg)],
                                    [a + b for a, b in zip(F, da)])))
        assert all(o is None for o in outs[:-1])  # only the message that completes an instant gives one
        rec.append({"out": outs[-1], "events": s.take_events(), "tests": s.take_tests(), "bits": s.status_bits()})
    return rec


FG, FA = 0.0625, 0.25  # rad/s, m/s^2: the faults' sizes
PHASE1, PHASE2 = range(13, 17), range(40, 42)  # instants of the faults


def bias_variance(k: int, frozen: tuple[int, ...]) -> float:
    """v_(k-1), what window k's statistic divides by: v_j = (1 - 1/j)^2 v_(j-1) + 1/j^2 (the running
    mean's weight 1/j while 1/j > T / tau_b = 1/120), kept in the frozen windows."""
    v = 0.0
    for j in range(1, k):
        if j not in frozen:
            v = (1.0 - 1.0 / j) ** 2 * v + 1.0 / j**2
    return v


@pytest.fixture
def three():
    """IMUs 0, 1, 3 (not 0, 1, 2: position and number differ), 42 instants: IMU 1's gyro x and IMU 3's
    accel y off at instants 13 to 16, then IMU 0's gyro x and IMU 1's accel z at 40 and 41."""
    s = new_set((3, 1, 0))
    faults = {}
    for k in PHASE1:
        faults[(1, k)] = ((FG, 0.0, 0.0), (0.0,) * 3)
        faults[(3, k)] = ((0.0,) * 3, (0.0, FA, 0.0))
    for k in PHASE2:
        faults[(0, k)] = ((FG, 0.0, 0.0), (0.0,) * 3)
        faults[(1, k)] = ((0.0,) * 3, (0.0, 0.0, FA))
    return s, run_instants(s, 42, faults)


def test_imu_numbers_of_the_messages():
    """HIGHRES_IMU id k is IMU k; RAW_IMU (any id) and SCALED_IMU are IMU 0, SCALED_IMU2/3 IMUs 1, 2;
    other messages have none."""
    assert imu_index(hr(1000, 2)) == 2 and imu_index(hr(1000, 0)) == 0
    assert imu_index(wire(lambda m: m.raw_imu_encode(1000, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 1))) == 0
    for enc, k in (("scaled_imu_encode", 0), ("scaled_imu2_encode", 1), ("scaled_imu3_encode", 2)):
        assert imu_index(wire(lambda m, e=enc: getattr(m, e)(1, 0, 0, -1000, 0, 0, 0, 0, 0, 0))) == k
    assert imu_index(wire(lambda m: m.heartbeat_encode(2, 3, 0, 0, 4))) is None


def test_three_imus_fused_on_the_first_imus_time(three):
    """One sample per instant from the second on (the first has no interval), on IMU 0's time, the mean
    of the rates; the instant that reveals the faults carries a third of each, the next ones none."""
    s, rec = three
    assert rec[0]["out"] is None
    for k, r in enumerate(rec[1:], start=1):
        out = r["out"]
        assert out.t == pytest.approx(10.0 + 0.5 * k, abs=1e-12)
        gx = W[0] + FG / 3.0 if k in (13, 40) else W[0]
        ay = F[1] + FA / 3.0 if k == 13 else F[1]
        az = F[2] + FA / 3.0 if k == 40 else F[2]
        assert out.gyro == pytest.approx((gx, W[1], W[2]), abs=1e-12)
        assert out.accel == pytest.approx((F[0], ay, az), abs=1e-12)
        assert out.mag is None and (out.sysid, out.compid) == (1, 1)
    assert s.last_t == pytest.approx(30.5, abs=1e-12) and s.wanted == (3, 1, 0) and s.order == [0, 1, 3]
    assert s.primary.accepted == 41 and s.counters["imu_missing"] == 0 and s.counters["other_imu"] == 0
    assert s.primary.locked_message == "HIGHRES_IMU" and s.primary.locked_id == 0


def test_isolations_and_recoveries_are_announced(three):
    """A detection isolated at once is told by its isolation (WARNING, the IMU's number, not its
    position, and the statistic f^2 (2/3) / sigma^2 / (1 + v) against the 6-dof threshold), sensor row 0
    included; the recoveries 20 windows (10 s) after the faults end are INFO, with the threshold of the
    set without the sensor (5 dof)."""
    s, rec = three
    thr6 = cc.upper(cc.q6, 1e-6)

    def text(t, who, stat):
        return f"FDI at t={t} s: {who} isolated (statistic {stat:.4g}, threshold {thr6:.4g})"

    v13, v40 = bias_variance(13, ()), bias_variance(40, (13,))
    assert v13 == pytest.approx(1.0 / 12.0, rel=1e-12)
    sg, sa = FG**2 * (2.0 / 3.0) / SIG_G2, FA**2 * (2.0 / 3.0) / SIG_A2
    told = {k: r["events"] for k, r in enumerate(rec) if r["events"]}
    assert sorted(told) == [13, 36, 40]
    assert told[13] == [("WARNING", text("16.500", "IMU 1 gyro x", sg / (1 + v13))),
                        ("WARNING", text("16.500", "IMU 3 accel y", sa / (1 + v13)))]
    assert told[40] == [("WARNING", text("30.000", "IMU 0 gyro x", sg / (1 + v40))),
                        ("WARNING", text("30.000", "IMU 1 accel z", sa / (1 + v40)))]
    thr5 = f"{cc.upper(cc.q5, 1e-6):.4g}"
    assert [lv for lv, _ in told[36]] == ["INFO", "INFO"]
    for (_, line), sensor in zip(told[36], ("IMU 1 gyro x", "IMU 3 accel y")):
        assert re.fullmatch(rf"FDI at t=28\.000 s: {sensor} recovered \(statistic [-+.e0-9]+, threshold {thr5}\)",
                            line), line
    assert [(e.event, e.sensor, e.index) for e in s.fdi] == [
        ("detected", "gyro", -1), ("isolated", "gyro", 3), ("detected", "accel", -1), ("isolated", "accel", 7),
        ("recovered", "gyro", 3), ("recovered", "accel", 7),
        ("detected", "gyro", -1), ("isolated", "gyro", 0), ("detected", "accel", -1), ("isolated", "accel", 5)]
    assert s.take_events() == []


def test_window_tests_are_reported_once(three):
    """No test during the 5 s calibration (windows 1 to 10), then one per sensor and window: its time,
    the statistic (0 without fault), the threshold and the nine residuals; each drained once."""
    s, rec = three
    thr6 = cc.upper(cc.q6, 1e-6)
    assert all(r["tests"] == [] for r in rec[:11])
    for k in (11, 12, 13):
        tests = rec[k]["tests"]
        assert [(t, name) for t, name, *_ in tests] == [(pytest.approx(10.0 + 0.5 * k, abs=1e-12), "gyro"),
                                                        (pytest.approx(10.0 + 0.5 * k, abs=1e-12), "accel")]
        for _, _, stat, thr, res in tests:
            assert thr == pytest.approx(thr6, rel=1e-12) and res.shape == (9,)
            if k < 13:
                assert stat == pytest.approx(0.0, abs=1e-12) and np.abs(res).max() < 1e-9
    assert rec[13]["tests"][0][2] == pytest.approx(FG**2 * (2 / 3) * (12 / 13) / SIG_G2, rel=1e-9)
    assert rec[13]["tests"][1][2] == pytest.approx(FA**2 * (2 / 3) * (12 / 13) / SIG_A2, rel=1e-9)
    assert len(rec[13]["tests"][0][4]) == 9 and abs(rec[13]["tests"][0][4][3]) > 10.0  # IMU 1's gyro x stands out
    assert s.take_tests() == []
    assert s.monitor.gyro.statistics().shape == (0, 3)  # a live run keeps no log of every test


def test_status_bits_of_three_imus(three):
    """IMUs 0 and 1 are present (IMU 3 has no bit); an isolated sensor's bit is unhealthy until it is
    taken back: IMU 1's gyro (IMU 3's isolated accel has no bit), later IMU 0's gyro and IMU 1's accel."""
    _, rec = three
    for k, r in enumerate(rec):
        bad = GYRO2 if 13 <= k <= 35 else GYRO | ACCEL2 if k >= 40 else 0
        assert r["bits"] == (BOTH, bad), k


def test_two_imus_detect_without_isolating():
    """Two IMUs: a fault is detected, not isolated (WARNING, statistic f^2 (1/2) / sigma^2 / (1 + v), 3-dof
    threshold at the set's false-alarm probability), IMU 0's bit of that sensor is unhealthy during
    the alarm, and the alarm is cleared (INFO) after 20 passing windows."""
    s = new_set((1, 0), false_alarm=1e-3)
    faults = {(1, k): ((0.0, 0.0, FG), (0.0,) * 3) for k in (13, 14)}
    faults[(0, 20)] = ((0.0,) * 3, (FA, 0.0, 0.0))
    rec = run_instants(s, 41, faults)
    thr3 = cc.upper(cc.q3, 1e-3)
    sg = FG**2 * 0.5 / SIG_G2 / (1 + bias_variance(13, ()))
    sa = FA**2 * 0.5 / SIG_A2 / (1 + bias_variance(20, ()))
    told = {k: r["events"] for k, r in enumerate(rec) if r["events"]}
    assert sorted(told) == [13, 20, 34, 40]
    assert told[13] == [("WARNING", f"FDI at t=16.500 s: gyro fault detected, not isolable (statistic {sg:.4g}, "
                                    f"threshold {thr3:.4g})")]
    assert told[20] == [("WARNING", f"FDI at t=20.000 s: accel fault detected, not isolable (statistic {sa:.4g}, "
                                    f"threshold {thr3:.4g})")]
    for k, sensor, t in ((34, "gyro", "27.000"), (40, "accel", "30.000")):
        (level, text), = told[k]
        assert level == "INFO"
        assert re.fullmatch(rf"FDI at t={t} s: {sensor} fault cleared \(statistic [-+.e0-9]+, threshold {thr3:.4g}\)",
                            text), text
    for k, r in enumerate(rec):
        assert r["bits"] == (BOTH, (GYRO if 13 <= k <= 33 else 0) | (ACCEL if 20 <= k <= 39 else 0)), k
    assert rec[13]["out"].gyro[2] == pytest.approx(W[2] + FG / 2.0, abs=1e-12)  # both still fused
    assert rec[15]["out"].gyro[2] == pytest.approx(W[2], abs=1e-12)
    assert rec[11]["tests"][0][3] == pytest.approx(thr3, rel=1e-12)


def test_a_new_set_has_nothing_to_tell():
    """Before any sample: no time, no reason, no events, tests or FDI decisions."""
    s = new_set()
    assert s.last_t is None and s.last_reason is None and s.fdi == []
    assert s.take_tests() == [] and s.take_events() == []


def test_each_stream_is_read_by_its_own_message_and_id():
    """--imus names the streams: the single-stream choice of message and id (--imu, --imu-id) does
    not filter them."""
    s = new_set(message="RAW_IMU", imu_id=3)
    s.sample(hr(1_000_000, 0))
    s.sample(hr(1_000_000, 1))
    s.sample(hr(1_500_000, 0))
    assert s.sample(hr(1_500_000, 1)).t == 1.5 and s.primary.rejected == {}


@pytest.mark.parametrize("imus, present", [((0, 1, 2), BOTH), ((2, 1), GYRO2 | ACCEL2), ((0,), GYRO | ACCEL),
                                           ((2, 3), 0)])
def test_status_bits_before_any_instant(imus, present):
    """Present bits follow the IMU numbers of the set; nothing is unhealthy before the monitor runs."""
    assert new_set(imus).status_bits() == (present, 0)


def test_discovery_takes_the_imus_of_the_first_second():
    """--imus all: every stream seen before 1 s of sensor time has passed (exactly 1 s ends it) is
    fused, announced in number order; those samples are not navigated; a stream appearing later is
    counted, not fused."""
    s = new_set(())
    for t_us in (10_000_000, 10_250_000, 10_500_000, 10_750_000):
        assert s.sample(hr(t_us, 2)) is None
        assert s.sample(hr(t_us, 0)) is None
    assert s.take_events() == [] and not s.fixed
    assert s.sample(hr(11_000_000, 0)) is None  # 1 s after the first sample: discovery over
    assert s.take_events() == [("INFO", "fusing IMUs 0, 2")]
    assert s.sample(hr(11_001_000, 2)) is None  # the first fused instant (no interval yet)
    assert s.sample(hr(11_250_000, 0)) is None
    out = s.sample(hr(11_251_000, 2))
    assert out.t == 11.25 and out.gyro == pytest.approx(W, abs=1e-12)
    assert s.sample(hr(11_500_000, 1)) is None and s.counters["other_imu"] == 1
    assert s.sample(hr(11_750_000, 1)) is None and s.counters["other_imu"] == 2
    assert s.order == [0, 2] and s.primary.accepted == 1


def test_discovery_of_one_imu_navigates_on_it():
    """--imus all with one stream: announced, then every sample passes through unchanged, counted."""
    s = new_set(())
    for t_us in (5_000_000, 5_500_000):
        assert s.sample(hr(t_us, 4)) is None
    out = s.sample(hr(6_000_000, 4, gyro=(0.5, 0.25, -0.125)))
    assert s.take_events() == [("INFO", "only IMU 4 found: navigating on it without FDI")]
    assert out.t == 6.0 and out.gyro == (0.5, 0.25, -0.125) and out.accel == F
    assert s.sample(hr(6_500_000, 4)).t == 6.5
    assert s.last_t == 6.5 and s.primary.accepted == 2 and s.monitor is None
    assert s.status_bits() == (0, 0)


def test_one_named_imu_passes_through():
    """--imus 1: no fusion; each sample out as it came, on its own time."""
    s = new_set((1,))
    assert s.sample(hr(2_000_000, 1)).t == 2.0
    assert s.sample(hr(2_010_000, 1)).t == pytest.approx(2.01, abs=1e-12)
    assert s.sample(hr(2_020_000, 0)) is None and s.counters["other_imu"] == 1
    assert s.primary.accepted == 2 and s.last_t == pytest.approx(2.01, abs=1e-12)


def test_same_instant_is_within_one_and_a_half_milliseconds():
    """Samples exactly 1.5 ms apart are one instant (nothing held, nothing missing)."""
    s = new_set()
    assert s.sample(hr(1000, 0)) is None
    assert s.sample(hr(2500, 1)) is None  # completes the first instant (no interval yet)
    assert s.sample(hr(501_000, 0)) is None
    out = s.sample(hr(502_500, 1))
    assert out.t == pytest.approx(0.501, abs=1e-15) and s.counters["imu_missing"] == 0


def test_more_than_one_and_a_half_milliseconds_is_a_new_instant():
    """1.501 ms apart: two instants, each missing an IMU (held from the other; the very first, with
    no IMU 1 yet, is dropped)."""
    s = new_set()
    assert s.sample(hr(1000, 0)) is None
    assert s.sample(hr(2501, 1)) is None  # flushes IMU 0 alone: IMU 1 never seen, no instant
    assert s.counters["imu_missing"] == 0
    assert s.sample(hr(501_000, 0)) is None  # flushes IMU 1 alone at 2.501 ms, IMU 0 held
    assert s.counters["imu_missing"] == 1
    out = s.sample(hr(502_501, 1))  # flushes IMU 0 alone at 0.501 s
    assert out.t == pytest.approx(0.501, abs=1e-15) and s.counters["imu_missing"] == 2


def test_a_repeated_imu_closes_the_instant():
    """An IMU's second sample within 1.5 ms starts a new instant; the missing IMU holds its last rates."""
    s = new_set()
    s.sample(hr(1_000_000, 0))
    s.sample(hr(1_000_000, 1, gyro=(0.5, 0.5, 0.5)))
    assert s.sample(hr(1_001_000, 0)) is None
    out = s.sample(hr(1_002_000, 0, gyro=(0.125, 0.125, 0.125)))
    assert out.t == pytest.approx(1.001, abs=1e-12) and s.counters["imu_missing"] == 1
    assert out.gyro == pytest.approx(((0.25 + 0.5) / 2, (-0.125 + 0.5) / 2, 0.5), abs=1e-12)


def test_an_instant_is_timed_from_its_first_sample():
    """The 1.5 ms count from the instant's first sample, not its latest: 0, 1 and 2 ms are two instants."""
    s = new_set((0, 1, 2))
    for k in (0, 1, 2):
        s.sample(hr(1_000_000, k))
    s.sample(hr(1_500_000, 0))
    s.sample(hr(1_501_000, 1))
    out = s.sample(hr(1_502_000, 2))
    assert out.t == 1.5 and s.counters["imu_missing"] == 1


def test_fused_sample_takes_the_lowest_imus_time_and_source():
    """IMU 1 arriving first does not set the time: IMU 0's time, system and component; the
    magnetometer is the first IMU's that has one."""
    s = new_set()
    s.sample(hr(1_001_000, 1, compid=7))
    s.sample(hr(1_000_000, 0, compid=3))
    s.sample(hr(1_501_000, 1, compid=7, mag=(0.25, 0.5, 0.125)))
    out = s.sample(hr(1_500_000, 0, compid=3))
    assert out.t == 1.5 and (out.sysid, out.compid) == (1, 3)
    assert out.mag == pytest.approx((0.25, 0.5, 0.125), abs=1e-15)
    s.sample(hr(2_001_000, 1, compid=7, mag=(0.25, 0.5, 0.125)))
    out = s.sample(hr(2_000_000, 0, compid=3, mag=(-0.5, 0.0, 0.25)))
    assert out.mag == pytest.approx((-0.5, 0.0, 0.25), abs=1e-15)


def test_an_instant_that_does_not_advance_is_dropped():
    """An instant on the same time as the previous one (IMU 0 late, IMU 1 early) gives no sample."""
    s = new_set()
    s.sample(hr(1_000_000, 0))
    s.sample(hr(1_000_500, 1))
    s.sample(hr(1_500_500, 1))  # new instant: IMU 0 held, on IMU 1's time 1.5005 s
    s.sample(hr(1_500_600, 1))  # IMU 1 again closes it: an output at 1.5005
    assert s.sample(hr(1_500_500, 0)) is None  # completes an instant at 1.5005 again: dropped
    assert s.primary.accepted == 1
    out = s.sample(hr(2_000_000, 0)), s.sample(hr(2_000_500, 1))
    assert out[0] is None and out[1].t == 2.0 and s.primary.accepted == 2


def test_rejections_are_counted_and_reported():
    """A stream's rejection is its reason and the primary's count; an accepted sample or another
    message clears the reason."""
    s = new_set()
    s.sample(hr(1_000_000, 0))
    assert s.sample(hr(1_000_000, 0)) is None
    assert s.last_reason == "duplicate_time" and s.primary.rejected["duplicate_time"] == 1
    s.sample(hr(1_000_000, 1))
    assert s.last_reason is None
    s.sample(hr(900_000, 1))
    assert s.last_reason == "time_backwards"
    assert s.sample(wire(lambda m: m.heartbeat_encode(2, 3, 0, 0, 4))) is None and s.last_reason is None
    assert s.primary.rejected == {"duplicate_time": 1, "time_backwards": 1}


def test_streams_follow_the_first_system():
    """The first accepted stream locks the vehicle (message, IMU number, system) for every stream."""
    s = new_set()
    s.sample(hr(1_000_000, 1, sysid=5))
    assert (s.primary.locked_message, s.primary.locked_id, s.primary.locked_system) == ("HIGHRES_IMU", 1, 5)
    assert s.sample(hr(1_000_000, 0, sysid=6)) is None and s.last_reason == "other_system"
    assert s.primary.rejected["other_system"] == 1
    s.sample(hr(1_000_000, 0, sysid=5))
    assert s.primary.locked_id == 1 and s.last_reason is None


def test_target_system_is_kept():
    """--target-system: a stream from another system is refused even as the first one."""
    s = new_set(target_system=7)
    assert s.sample(hr(1_000_000, 0, sysid=1)) is None and s.last_reason == "other_system"
    s.sample(hr(1_000_000, 0, sysid=7))
    assert s.last_reason is None and s.primary.locked_system == 7


def test_one_imu_number_from_two_message_kinds():
    """RAW_IMU is IMU 0: beside HIGHRES_IMU id 0 it is another stream of the same number, not fused."""
    s = new_set()
    s.sample(hr(1_000_000, 0))
    raw = wire(lambda m: m.raw_imu_encode(1_000_000, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0))
    assert s.sample(raw) is None and s.counters["other_imu"] == 1 and s.last_reason is None
    raw = wire(lambda m: m.raw_imu_encode(1_500_000, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0))
    assert s.sample(raw) is None and s.counters["other_imu"] == 2


def test_scaled_imu_streams_are_fused():
    """SCALED_IMU and SCALED_IMU2 (mG, mrad/s, ms) are IMUs 0 and 1."""
    s = new_set()

    def sc(enc, ms, gx):
        return wire(lambda m: getattr(m, enc)(ms, 0, 0, -1000, gx, 0, 0, 0, 0, 0))

    s.sample(sc("scaled_imu_encode", 1000, 100))
    s.sample(sc("scaled_imu2_encode", 1000, 300))
    s.sample(sc("scaled_imu_encode", 1500, 100))
    out = s.sample(sc("scaled_imu2_encode", 1500, 300))
    assert out.t == 1.5 and out.gyro[0] == pytest.approx(0.2, abs=1e-12)


def test_reset_time_starts_over():
    """After an autopilot restart the streams accept earlier times, the instant being gathered is
    dropped and the first instant again only starts the interval."""
    s = new_set()
    for t_us in (5_000_000, 5_500_000):
        s.sample(hr(t_us, 0))
        s.sample(hr(t_us, 1))
    s.sample(hr(6_000_000, 0))
    assert s.last_t == 5.5
    s.reset_time()
    assert s.last_t is None
    assert s.sample(hr(1_000_000, 1)) is None and s.last_reason is None
    assert s.sample(hr(1_000_000, 0)) is None and s.counters["imu_missing"] == 0
    s.sample(hr(1_500_000, 0))
    assert s.sample(hr(1_500_000, 1)).t == 1.5


# --- mavins/navfdi.py ------------------------------------------------------------------------------------------------
def test_imu_spec_from_grade_or_keys():
    """A grade name takes its figures; spec keys are in file units (60 deg/sqrt(h) = 1 deg/sqrt(s))."""
    g = errmodel.spec_of("consumer")
    fig = grade_figures("consumer")
    assert g.gyro_arw == fig.gyro.random_walk and g.accel_vrw == fig.accel.random_walk
    k = errmodel.spec_of({"gyro_arw": 60.0, "accel_vrw": 120.0})
    assert k.gyro_arw == pytest.approx(math.radians(1.0), rel=1e-15) and k.accel_vrw == pytest.approx(2.0)


def write_imu(path: Path, t, rows=None, rates: bool = False) -> Path:
    cols = "t,gyro_x,gyro_y,gyro_z,acc_x,acc_y,acc_z" if rates else "t,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z"
    rows = rows if rows is not None else [[0.25 * i, 0.5, -0.25, 1.0, 2.0, -4.0] for i in range(len(t))]
    path.write_text(cols + "\n" + "".join(",".join(repr(float(v)) for v in (ti, *r)) + "\n"
                                          for ti, r in zip(t, rows)))
    return path


def test_read_imus_stacks_the_files(tmp_path):
    """(N, n_imus, 6) in file order, the times of the first file, all increment rows kept."""
    a = write_imu(tmp_path / "a.csv", [0.5, 1.0, 1.5])
    b = write_imu(tmp_path / "b.csv", [0.5, 1.0, 1.5], [[1, 2, 3, 4, 5, 6]] * 3)
    t, data = fdi.read_imus([a, b], 0.25, False, False)
    assert t.tolist() == [0.5, 1.0, 1.5] and t.flags.c_contiguous
    assert data.shape == (3, 2, 6)
    assert data[2, 0].tolist() == [0.5, 0.5, -0.25, 1.0, 2.0, -4.0] and data[1, 1].tolist() == [1, 2, 3, 4, 5, 6]


@pytest.mark.parametrize("sampled, first", [(True, 0.0), (False, 0.5)])
def test_read_imus_rates_at_the_initial_time(tmp_path, sampled, first):
    """A rate row at the initial state's time starts the first interval of sampled rates, is dropped
    for averaged ones (it covers the interval before)."""
    a = write_imu(tmp_path / "a.csv", [0.0, 0.5, 1.0], rates=True)
    b = write_imu(tmp_path / "b.csv", [0.0, 0.5, 1.0], rates=True)
    t, data = fdi.read_imus([a, b], 0.0, True, sampled)
    assert t[0] == first and data.shape == (3 if sampled else 2, 2, 6)
    assert data[0, 1, 0] == pytest.approx(0.25 * (0 if sampled else 1))


def test_read_imus_wants_the_rate_columns(tmp_path):
    """Rate files have the rate columns; increments the increment ones."""
    a = write_imu(tmp_path / "a.csv", [0.5, 1.0])
    with pytest.raises(DataFileError, match="gyro_x"):
        fdi.read_imus([a, a], 0.0, True, False)


def test_increments_must_start_after_the_initial_state(tmp_path):
    """An increment row at the initial state's time is refused (row i covers (t[i-1], t[i]])."""
    a = write_imu(tmp_path / "a.csv", [0.5, 1.0])
    b = write_imu(tmp_path / "b.csv", [0.5, 1.0])
    fdi.read_imus([a, b], 0.499, False, False)
    with pytest.raises(DataFileError, match=re.escape(f"{a}: line 2, column 't': first increment time ") + r"\S*0\.5\S*"
                       + re.escape(" is not after the initial state's t = 0.5 (row i covers (t[i-1], t[i]])")):
        fdi.read_imus([a, b], 0.5, False, False)


def test_time_errors_give_plain_numbers(tmp_path):
    """The times in these messages read as numbers, as in every other file error (files.py)."""
    a = write_imu(tmp_path / "a.csv", [0.5, 1.0])
    b = write_imu(tmp_path / "b.csv", [0.5, 1.25])
    with pytest.raises(DataFileError) as first:
        fdi.read_imus([a, a], 0.5, False, False)
    with pytest.raises(DataFileError) as differs:
        fdi.read_imus([a, b], 0.0, False, False)
    assert "first increment time 0.5 is not after" in str(first.value)
    assert "'t': 1.25 differs from 1.0 in" in str(differs.value)


def test_rates_all_before_the_initial_state(tmp_path):
    """No rate row after the initial time: refused."""
    a = write_imu(tmp_path / "a.csv", [0.5, 1.0], rates=True)
    b = write_imu(tmp_path / "b.csv", [0.5, 1.0], rates=True)
    with pytest.raises(DataFileError, match=re.escape(f"{a}: no row after the initial state's t = 1.0")):
        fdi.read_imus([a, b], 1.0, True, False)


def test_times_must_agree_to_a_microsecond(tmp_path):
    """1e-6 s apart is the same time; more is refused, naming the file, its line and both times."""
    a = write_imu(tmp_path / "a.csv", [0.0, 0.5, 1.0], rates=True)
    b = write_imu(tmp_path / "b.csv", [1e-6, 0.5, 1.0], rates=True)
    c = write_imu(tmp_path / "c.csv", [0.0, 0.5, 1.000002], rates=True)
    assert fdi.read_imus([a, b], 0.0, True, True)[0].shape == (3,)
    with pytest.raises(DataFileError, match=re.escape(f"{c}: line 4, column 't': ") + r".*1\.000002.* differs from "
                       + r".*1\.0.* in " + re.escape(f"{a} (the IMU files must be sampled at the same times)")):
        fdi.read_imus([a, b, c], 0.0, True, True)
    with pytest.raises(DataFileError, match=re.escape(f"{c}: line 4")):
        fdi.read_imus([a, c, b], 0.0, True, True)


@pytest.mark.parametrize("n", [2, 4])
def test_files_must_have_the_same_rows(tmp_path, n):
    """A file shorter or longer than the first is refused with both row counts."""
    a = write_imu(tmp_path / "a.csv", [0.5, 1.0, 1.5])
    b = write_imu(tmp_path / "b.csv", [0.5, 1.0, 1.5, 2.0][:n])
    with pytest.raises(DataFileError, match=re.escape(f"{b}: {n} rows, {a} has 3 (the IMU files must be sampled")):
        fdi.read_imus([a, b], 0.0, False, False)


def test_fdi_log_rows(tmp_path):
    """FDI.csv: the header, round-trip floats, empty imu and axis for a detection, empty statistic
    when it is not finite."""
    p = tmp_path / "FDI.csv"
    fdi.write_events(p, [FdiEvent(1.25, "detected", "gyro", -1, math.nan, 38.25),
                         FdiEvent(1.25, "isolated", "accel", 4, 0.1, 38.25),
                         FdiEvent(2.5, "recovered", "gyro", 8, math.inf, 30.5)])
    assert p.read_bytes() == (b"t,event,imu,sensor,axis,statistic,threshold\n1.25,detected,,gyro,,,38.25\n"
                              b"1.25,isolated,1,accel,y,0.1,38.25\n2.5,recovered,2,gyro,z,,30.5\n")


def test_strapdown_keywords_of_the_options():
    """Every strapdown setting of mavins nav's options, by name."""
    kw = fdi.strapdown_keywords(NavOptions(strapdown=Strapdown(samples=1, imu_rates="sampled")))
    assert kw["samples"] == 1 and kw["imu_rates"] == "sampled" and kw["earth_model"] == "wgs84"


INIT = {"t": 0.0, "lat": 45.0, "lon": 7.0, "h": 100.0, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 0.0, "pitch": 0.0,
        "yaw": 0.0}
AN, FY = 0.5, 0.4  # m/s^2: north acceleration of every IMU; fault on IMU 2's accel y


def nav_files(tmp_path: Path, rates: bool, n: int = 80, start: int = 1, wz: float = 0.0, t=None,
              fault_from: float = 5.5) -> list[Path]:
    """Three IMU files of a level vehicle turning at wz about z and accelerating at AN along x in
    laboratory mode (gravity of the start point), at t = 0.1 s steps unless t is given; IMU 2's accel y
    off by FY after fault_from (by default from the 12th 0.5 s window on)."""
    from support import gamma

    g = float(gamma(math.radians(INIT["lat"]), INIT["h"]))
    t = t if t is not None else [round(0.1 * i, 10) for i in range(start, n + 1)]
    paths = []
    for k in range(3):
        rows = []
        for i, ti in enumerate(t):
            dt = ti - t[i - 1] if i else 0.1
            f = [AN, FY if (k == 2 and ti > fault_from) else 0.0, -g]
            rows.append([0.0, 0.0, wz * (1.0 if rates else dt)] + ([v * dt for v in f] if not rates else f))
        paths.append(write_imu(tmp_path / f"imu{k}.csv", t, rows, rates))
    (tmp_path / "init.json").write_text(json.dumps(INIT))
    return paths


@pytest.mark.parametrize("rates, sampled", [(False, False), (True, False), (True, True)])
def test_nav_fdi_isolates_and_navigates_on_the_rest(tmp_path, rates, sampled):
    """8 s at 10 Hz: the fault is found at the end of its first window, with statistic
    (c FY)^2 (2/3)(11/12) / sigma^2 (c the part of the window it covers) against the 6-dof threshold;
    the solution (one row per update of two samples, or one) reaches vn = AN t, and ve = FY/3 over
    the fault's samples fused before the isolation. Sampled rates keep the row at the initial time,
    which starts the first window: windows end 0.1 s earlier and the fault covers 4/5 of its first."""
    paths = nav_files(tmp_path, rates, start=0 if sampled else 1)
    out, log = tmp_path / "nav.csv", tmp_path / "FDI.csv"
    kw = {"earth_model": "none", "imu_rates": "sampled" if sampled else "averaged"}
    if rates and not sampled:
        kw["samples"] = 1
    m, events = fdi.run_nav_fdi(paths, tmp_path / "init.json", out, log, rates=rates, strapdown=kw,
                                spec={"gyro_arw": 0.6, "accel_vrw": 0.6}, false_alarm=1e-6)
    cover, t_det = (0.8, 5.9) if sampled else (1.0, 6.0)
    stat = (cover * FY) ** 2 * (2 / 3) * (11 / 12) / SIG_A2
    thr6 = cc.upper(cc.q6, 1e-6)
    assert [(e.event, e.sensor, e.imu, e.axis) for e in events] == [("detected", "accel", None, ""),
                                                                     ("isolated", "accel", 2, "y")]
    lines = log.read_text().splitlines()
    assert lines[0] == "t,event,imu,sensor,axis,statistic,threshold" and len(lines) == 3
    for line, (imu, axis) in zip(lines[1:], (("", ""), ("2", "y"))):
        t, ev, i, sensor, ax, st, th = line.split(",")
        assert float(t) == t_det and (i, sensor, ax) == (imu, "accel", axis)
        assert float(st) == pytest.approx(stat, rel=1e-9) and float(th) == pytest.approx(thr6, rel=1e-12)
    sol = np.loadtxt(out, delimiter=",", skiprows=1)
    rows = 80 if kw.get("samples") == 1 else 40
    assert m == rows and sol.shape == (rows, 14)
    assert sol[-1, 0] == pytest.approx(8.0, abs=1e-12)
    assert sol[-1, 4] == pytest.approx(AN * 8.0, abs=1e-9)
    assert sol[-1, 5] == pytest.approx(FY / 3.0 * (t_det - 5.5), abs=1e-9)
    assert np.abs(sol[:, 7:10]).max() < 1e-9


def test_nav_fdi_window_false_alarm_and_default_samples(tmp_path):
    """A 1 s window: 5 calibration windows, the fault covers half of the 6th (ending at 6.0 s), whose
    white noise is N^2 / 1 s; the threshold is the 6-dof quantile at the given false-alarm
    probability; the default 2 samples per update; the fused gyros turn the vehicle by wz t."""
    paths = nav_files(tmp_path, False, wz=0.05)
    out = tmp_path / "nav.csv"
    m, events = fdi.run_nav_fdi(paths, tmp_path / "init.json", out, None, rates=False,
                                strapdown={"earth_model": "none"}, spec=SPEC, false_alarm=1e-3, window=1.0)
    assert m == 40 and [(e.event, e.t) for e in events] == [("detected", 6.0), ("isolated", 6.0)]
    assert events[0].statistic == pytest.approx((FY / 2) ** 2 * (2 / 3) * (5 / 6) / (0.6 / 60) ** 2, rel=1e-9)
    assert events[0].threshold == pytest.approx(cc.upper(cc.q6, 1e-3), rel=1e-12)
    sol = np.loadtxt(out, delimiter=",", skiprows=1)
    assert sol[-1, 9] == pytest.approx(math.degrees(0.05 * 8.0), abs=1e-9)


def test_nav_fdi_nominal_interval_is_the_median_of_the_positive_ones(tmp_path):
    """Sampled rates at intervals of 0.1 and 0.2 s alternately, 30 of each after the row at the initial
    time: the nominal interval is their median, 0.15 s (the zero interval of that row left out), so a
    window is 3 samples (0.45 s, white noise N^2 / 0.45 s) and calibration 11 windows; a fault from
    the 13th window (sample 36, t = 5.4 s) on is found at its end, sample 38 (t = 5.7 s), with
    v = 1/12."""
    t = [round(0.3 * (i // 2) + (0.1 if i % 2 else 0.0), 10) for i in range(61)]
    paths = nav_files(tmp_path, True, t=t, fault_from=5.35)
    _, events = fdi.run_nav_fdi(paths, tmp_path / "init.json", tmp_path / "nav.csv", None, rates=True,
                                strapdown={"earth_model": "none", "imu_rates": "sampled"}, spec=SPEC,
                                false_alarm=1e-6)
    assert [e.event for e in events] == ["detected", "isolated"]
    assert events[0].t == pytest.approx(5.7, abs=1e-12)
    assert events[0].statistic == pytest.approx(FY**2 * (2 / 3) * (12 / 13) / ((0.6 / 60) ** 2 / 0.45), rel=1e-9)


def test_nav_fdi_refuses_unusable_input(tmp_path):
    """One file, an output over an input, one file given twice under two spellings: refused, nothing
    written."""
    paths = nav_files(tmp_path, False, n=10)
    init = tmp_path / "init.json"
    out = tmp_path / "nav.csv"
    args = {"rates": False, "strapdown": {}, "spec": SPEC, "false_alarm": 1e-6}
    with pytest.raises(DataFileError, match="^--fdi-log needs two or more IMU files$"):
        fdi.run_nav_fdi(paths[:1], init, out, None, **args)
    with pytest.raises(DataFileError, match=re.escape(f"{paths[1]}: -o is also the input IMU1")):
        fdi.run_nav_fdi(paths, init, paths[1], None, **args)
    with pytest.raises(DataFileError, match="--fdi-log is also the input --init"):
        fdi.run_nav_fdi(paths, init, out, init, **args)
    (tmp_path / "x").mkdir()
    twice = tmp_path / "x" / ".." / "imu1.csv"
    with pytest.raises(DataFileError, match=re.escape(f"{twice}: given twice (each IMU file once)")):
        fdi.run_nav_fdi([paths[0], paths[1], twice], init, out, None, **args)
    with pytest.raises(DataFileError, match="given twice"):
        fdi.run_nav_fdi([paths[0], paths[0]], init, out, None, **args)
    assert not out.exists()
