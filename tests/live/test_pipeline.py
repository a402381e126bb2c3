"""What the mutation runs found unchecked in mavins/live/pipeline.py (docs/testing.md).

In-process: real pymavlink messages (encoded by a sender, packed, parsed back) into
``gnss_fix``/``gnss_invalid``/``isa_height`` and into ``Pipeline.handle`` with a
recording stand-in for the engine, so each test sees exactly which fix, height and
heading reach the navigation. Expected values typed from the MAVLink message
definitions (GPS_RAW_INT: lat/lon degE7, alt/alt_ellipsoid/h_acc/v_acc mm, eph/epv
DOP x100; HIL_GPS: alt mm, vn/ve/vd cm/s; GPS_INPUT: alt m, speeds m/s, accuracies
m, ignore_flags bits; GPS_FIX_TYPE 3 = 3D .. 8 = PPP), docs/conventions.md (GNSS
defaults 2.5 m, 5 m, 0.3 m/s; baro 0.5 m; --geoid-height), docs/filter.md (a fix
claiming worse than 50 m is refused) and ICAO Doc 7488 (standard atmosphere).
Also ``--imus`` (two streams fused before the engine) and what the pipeline hands to
the recording (outputs with their NED offset, filter, counters, FDI tests, events).
"""

from __future__ import annotations

import math
import numpy as np

import pytest

from mavins.live import pipeline as pl
from mavins.live.engine import EngineConfig
from mavins.link.mavlink import mavlink

SIGMA_H, SIGMA_V, SIGMA_VEL = 2.5, 5.0, 0.3  # docs/conventions.md GNSS defaults
# GPS_INPUT_IGNORE_FLAGS (MAVLink common.xml)
IGN_VEL_HORIZ, IGN_VEL_VERT, IGN_SPEED_ACC, IGN_HORIZ_ACC, IGN_VERT_ACC = 8, 16, 32, 64, 128


def wire(make, sysid: int = 1, compid: int = 1):
    tx = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    buf = make(tx).pack(tx)
    return mavlink.MAVLink(None).decode(bytearray(buf))


def raw_int(fix=3, lat=473977420, lon=85455940, alt=488_000, eph=120, epv=200, alt_e=0, h_acc=0, v_acc=0,
            t_us=5_000_000, vel=65535, cog=65535, **kw):
    """GPS_RAW_INT; ground speed and course unknown (UINT16_MAX) unless given."""
    return wire(lambda m: m.gps_raw_int_encode(t_us, fix, lat, lon, alt, eph, epv, vel, cog, 12, alt_e, h_acc, v_acc,
                                               0, 0), **kw)


def gps_input(fix=3, ign=0, lat=-338688000, lon=1512093000, alt=58.5, vel=(1.5, -2.25, 0.5), sacc=0.4, hacc=1.25,
              vacc=2.5, t_us=6_000_000, **kw):
    return wire(lambda m: m.gps_input_encode(t_us, 0, ign, 0, 0, fix, lat, lon, alt, 1.0, 1.0, *vel, sacc, hacc,
                                             vacc, 10), **kw)


def hil_gps(fix=3, lat=100_000_000, lon=-200_000_000, alt=1_250, eph=150, epv=300, vel=(125, -250, 50),
            t_us=7_000_000, **kw):
    return wire(lambda m: m.hil_gps_encode(t_us, fix, lat, lon, alt, eph, epv, 0, *vel, 0, 10), **kw)


# --- gnss_fix: every field and its scale ------------------------------------------------------
def test_gps_raw_int_amsl_and_dop():
    t, lat, lon, h, vel, sh, sv, svel = pl.gnss_fix(raw_int(), 47.5)
    assert t == pytest.approx(5.0, abs=1e-12)
    assert lat == pytest.approx(47.397742, abs=1e-12) and lon == pytest.approx(8.545594, abs=1e-12)
    assert h == pytest.approx(488.0 + 47.5, abs=1e-9)  # AMSL + geoid height
    assert vel is None  # speed and course unknown: position only
    assert (sh, sv, svel) == (SIGMA_H, SIGMA_V, SIGMA_VEL)  # no h_acc/v_acc: the defaults


def test_gps_raw_int_ellipsoid_height_and_accuracies():
    fix = pl.gnss_fix(raw_int(alt_e=535_250, h_acc=1_500, v_acc=3_250), 47.5)
    assert fix[3] == pytest.approx(535.25, abs=1e-9)  # alt_ellipsoid wins, no geoid added
    assert fix[5] == pytest.approx(1.5, abs=1e-12) and fix[6] == pytest.approx(3.25, abs=1e-12)
    assert fix[7] == SIGMA_VEL


def test_gps_raw_int_without_time():
    assert pl.gnss_fix(raw_int(t_us=0), 0.0)[0] is None


@pytest.mark.parametrize("fix_type, ok", [(0, False), (1, False), (2, False), (3, True), (4, True), (5, True),
                                          (6, True), (7, True), (8, True), (9, False)])
def test_fix_types(fix_type, ok):
    assert (pl.gnss_fix(raw_int(fix=fix_type), 0.0) is not None) is ok
    assert (pl.gnss_fix(gps_input(fix=fix_type), 0.0) is not None) is ok
    assert (pl.gnss_fix(hil_gps(fix=fix_type), 0.0) is not None) is ok


def test_zero_position_is_no_fix():
    assert pl.gnss_fix(raw_int(lat=0, lon=0), 0.0) is None
    assert pl.gnss_fix(raw_int(lat=0, lon=5), 0.0) is not None
    assert pl.gnss_fix(raw_int(lat=5, lon=0), 0.0) is not None


def test_gps_input_all_fields():
    t, lat, lon, h, vel, sh, sv, svel = pl.gnss_fix(gps_input(), 10.0)
    assert t == pytest.approx(6.0, abs=1e-12)
    assert lat == pytest.approx(-33.8688, abs=1e-12) and lon == pytest.approx(151.2093, abs=1e-12)
    assert h == pytest.approx(68.5, abs=1e-5)  # alt (m, float) + geoid height
    assert vel == (1.5, -2.25, 0.5)
    assert (sh, sv, svel) == (1.25, 2.5, pytest.approx(0.4, abs=1e-7))


@pytest.mark.parametrize("ign", [IGN_VEL_HORIZ, IGN_VEL_VERT, IGN_VEL_HORIZ | IGN_VEL_VERT])
def test_gps_input_ignored_velocity(ign):
    assert pl.gnss_fix(gps_input(ign=ign), 0.0)[4] is None


def test_gps_input_ignored_or_missing_accuracies():
    fix = pl.gnss_fix(gps_input(ign=IGN_HORIZ_ACC | IGN_VERT_ACC | IGN_SPEED_ACC), 0.0)
    assert fix[5:] == (SIGMA_H, SIGMA_V, SIGMA_VEL)
    assert fix[4] == (1.5, -2.25, 0.5)
    assert pl.gnss_fix(gps_input(ign=IGN_HORIZ_ACC), 0.0)[5:] == (SIGMA_H, 2.5, pytest.approx(0.4, abs=1e-7))
    assert pl.gnss_fix(gps_input(ign=IGN_VERT_ACC), 0.0)[5:] == (1.25, SIGMA_V, pytest.approx(0.4, abs=1e-7))
    assert pl.gnss_fix(gps_input(ign=IGN_SPEED_ACC), 0.0)[5:] == (1.25, 2.5, SIGMA_VEL)
    assert pl.gnss_fix(gps_input(sacc=0.0, hacc=0.0, vacc=0.0), 0.0)[5:] == (SIGMA_H, SIGMA_V, SIGMA_VEL)
    assert pl.gnss_fix(gps_input(sacc=-1.0, hacc=-1.0, vacc=-1.0), 0.0)[5:] == (SIGMA_H, SIGMA_V, SIGMA_VEL)


def test_hil_gps_all_fields():
    t, lat, lon, h, vel, sh, sv, svel = pl.gnss_fix(hil_gps(), 2.0)
    assert t == pytest.approx(7.0, abs=1e-12)
    assert lat == pytest.approx(10.0, abs=1e-12) and lon == pytest.approx(-20.0, abs=1e-12)
    assert h == pytest.approx(1.25 + 2.0, abs=1e-12)
    assert vel == pytest.approx((1.25, -2.5, 0.5), abs=1e-12)  # cm/s
    assert sh == pytest.approx(1.5 * SIGMA_H, abs=1e-12) and sv == pytest.approx(3.0 * SIGMA_V, abs=1e-12)
    assert svel == SIGMA_VEL


@pytest.mark.parametrize("dop", [0, 65535])
def test_hil_gps_unknown_dop(dop):
    fix = pl.gnss_fix(hil_gps(eph=dop, epv=dop), 0.0)
    assert fix[5:7] == (SIGMA_H, SIGMA_V)


def test_hil_gps_smallest_and_largest_known_dop():
    fix = pl.gnss_fix(hil_gps(eph=1, epv=65534), 0.0)
    assert fix[5] == pytest.approx(0.01 * SIGMA_H, abs=1e-15)
    assert fix[6] == pytest.approx(655.34 * SIGMA_V, abs=1e-9)


# --- gnss_invalid -------------------------------------------------------------------------------
GOOD = (1.0, 45.0, 7.0, 100.0, (0.0, 0.0, 0.0), 2.5, 5.0, 0.3)


def fix_with(**kw):
    names = ("t", "lat", "lon", "h", "vel", "sh", "sv", "svel")
    d = dict(zip(names, GOOD))
    d.update(kw)
    return tuple(d[n] for n in names)


def test_a_good_fix_is_valid():
    assert pl.gnss_invalid(GOOD) is None
    assert pl.gnss_invalid(fix_with(vel=None)) is None
    assert pl.gnss_invalid(fix_with(lat=90.0, lon=-180.0)) is None
    assert pl.gnss_invalid(fix_with(lat=-90.0, lon=180.0)) is None
    assert pl.gnss_invalid(fix_with(sh=50.0, sv=50.0)) is None  # at most 50 m
    assert pl.gnss_invalid(fix_with(svel=1e-3)) is None
    assert pl.gnss_invalid(fix_with(svel=1e3)) is None  # no upper bound on the velocity accuracy
    assert pl.gnss_invalid(fix_with(vel=(1.0, -2.0, math.nan))) is None  # ground speed: no vertical


@pytest.mark.parametrize("kw", [dict(lat=90.0001), dict(lat=-90.0001), dict(lon=180.0001), dict(lon=-180.0001),
                                dict(lat=math.nan), dict(lon=math.inf), dict(h=math.nan), dict(sh=math.inf),
                                dict(sv=math.nan), dict(svel=math.nan), dict(vel=(0.0, math.nan, 0.0)),
                                dict(vel=(math.inf, 0.0, 0.0)), dict(vel=(0.0, 0.0, -math.inf))])
def test_out_of_range(kw):
    assert pl.gnss_invalid(fix_with(**kw)) == "out_of_range"


@pytest.mark.parametrize("kw", [dict(sh=50.01), dict(sv=50.01), dict(sh=0.0), dict(sv=0.0), dict(svel=0.0),
                                dict(sh=-1.0), dict(sv=-1.0), dict(svel=-0.1)])
def test_inaccurate(kw):
    assert pl.gnss_invalid(fix_with(**kw)) == "inaccurate"


# --- isa_height ---------------------------------------------------------------------------------
def isa(p_hpa: float) -> float:
    """ICAO Doc 7488 troposphere: h = T0/L (1 - (p/p0)^(R L/g0)), T0 = 288.15 K, L = 0.0065 K/m,
    p0 = 1013.25 hPa, R = 287.05287 J/(kg K), g0 = 9.80665 m/s^2."""
    return 288.15 / 0.0065 * (1.0 - (p_hpa / 1013.25) ** (287.05287 * 0.0065 / 9.80665))


@pytest.mark.parametrize("p, h_table", [(1013.25, 0.0), (898.76, 1000.0), (795.01, 2000.0), (540.20, 5000.0),
                                        (264.36, 10000.0), (1050.0, None)])
def test_isa_height(p, h_table):
    """The ICAO table (898.76 hPa at 1000 m, 540.20 hPa at 5000 m, 264.36 hPa at 10 km) to its printed
    rounding, and the closed form to 5 mm at 10 km (the code's rounded 5.25588 and 2.25577e-5)."""
    h = pl.isa_height(p)
    assert h == pytest.approx(isa(p), abs=5e-3)
    if h_table is not None:
        assert h == pytest.approx(h_table, abs=1.0)
    assert pl.isa_height(1013.25) == 0.0


# --- Pipeline.handle routing, with a recording engine -------------------------------------------
class FakeEngine:
    def __init__(self):
        self.calls = []
        self.origin = None
        self.counters = {}

    def on_gnss(self, *a):
        self.calls.append(("gnss", a))

    def on_baro(self, *a):
        self.calls.append(("baro", a))

    def set_position(self, *a):
        self.calls.append(("position", a))

    def set_vehicle_yaw(self, *a):
        self.calls.append(("yaw", a))

    def set_date(self, *a):
        self.calls.append(("date", a))

    def on_imu(self, smp):
        self.calls.append(("imu", smp.t))
        return None

    def restart(self, why):
        self.calls.append(("restart", why))

    def take_events(self):
        return [("INFO", "x")]


def highres(t_us, sysid=1, compid=1):
    return wire(lambda m: m.highres_imu_encode(t_us, 0.0, 0.0, -9.81, 0.0, 0.0, 0.0, 0.2, 0.0, 0.4, 1013.0, 0.0,
                                               0.0, 20.0, 0b1_1111_1111, 0), sysid, compid)


@pytest.fixture
def pipe():
    p = pl.Pipeline(EngineConfig(geoid_height=10.0))
    p.engine = FakeEngine()
    return p


def test_bad_data_is_counted(pipe):
    assert pipe.handle(mavlink.MAVLink_bad_data(b"\x00", "junk")) is None
    assert pipe.counters["bad_data"] == 1
    assert pipe.engine.calls == []


def test_gnss_reaches_the_engine_on_the_imu_clock(pipe):
    pipe.handle(highres(5_500_000))
    assert pipe.engine.calls == [("imu", 5.5)]
    assert pipe.vehicle_sysid == 1
    pipe.handle(raw_int(t_us=5_000_000))  # 0.5 s before the last sample: on the IMU clock
    name, a = pipe.engine.calls[-1]
    assert name == "gnss"
    assert a[0] == pytest.approx(5.0, abs=1e-12)
    assert a[1:4] == pytest.approx((47.397742, 8.545594, 498.0), abs=1e-9)
    assert a[4:] == (None, SIGMA_H, SIGMA_V, SIGMA_VEL, "GPS_RAW_INT")
    pipe.handle(raw_int(t_us=7_600_000))  # 2.1 s after: another clock, taken as of the latest sample
    assert pipe.engine.calls[-1][1][0] is None
    pipe.handle(raw_int(t_us=7_500_000))  # exactly 2 s: still on the IMU clock
    assert pipe.engine.calls[-1][1][0] == pytest.approx(7.5, abs=1e-12)
    pipe.handle(raw_int(t_us=3_400_000))  # 2.1 s before
    assert pipe.engine.calls[-1][1][0] is None
    pipe.handle(gps_input())
    assert pipe.engine.calls[-1][1][-1] == "GPS_INPUT"
    pipe.handle(hil_gps())
    assert pipe.engine.calls[-1][1][-1] == "HIL_GPS"


def test_gnss_before_any_imu_has_no_imu_time(pipe):
    pipe.handle(raw_int(t_us=5_000_000))
    assert pipe.engine.calls[-1][1][0] is None


def test_rejected_fixes_are_counted(pipe):
    pipe.handle(raw_int(fix=2))
    pipe.handle(raw_int(h_acc=60_000))
    pipe.handle(raw_int(lat=910_000_000))
    assert pipe.counters == {"gnss_no_fix": 1, "gnss_inaccurate": 1, "gnss_out_of_range": 1}
    assert pipe.engine.calls == []


def test_other_vehicles_and_own_component_are_ignored(pipe):
    pipe.handle(highres(1_000_000, sysid=7))
    pipe.handle(raw_int(sysid=8))
    pipe.handle(raw_int(sysid=7, compid=191))  # our own messages echoed back
    assert [c[0] for c in pipe.engine.calls] == ["imu"]
    pipe.handle(raw_int(sysid=7, compid=190))
    assert pipe.engine.calls[-1][0] == "gnss"


def test_no_lock_takes_any_vehicle(pipe):
    pipe.handle(raw_int(sysid=9))
    assert pipe.engine.calls[-1][0] == "gnss"


def test_baro(pipe):
    pipe.handle(highres(2_000_000))
    pipe.handle(wire(lambda m: m.scaled_pressure_encode(1_500, 898.76, 0.0, 2000)))
    name, (t, h, sigma) = pipe.engine.calls[-1]
    assert name == "baro"
    assert t == pytest.approx(1.5, abs=1e-12)
    assert h == pytest.approx(isa(898.76), abs=5e-3)
    assert sigma == 0.5
    n = len(pipe.engine.calls)
    pipe.handle(wire(lambda m: m.scaled_pressure_encode(1_500, 0.0, 0.0, 2000)))
    pipe.handle(wire(lambda m: m.scaled_pressure_encode(1_500, -5.0, 0.0, 2000)))
    pipe.handle(wire(lambda m: m.scaled_pressure_encode(1_500, math.nan, 0.0, 2000)))
    assert len(pipe.engine.calls) == n


SITL_US = 1_732_838_400_123_456  # an IMU clock in UNIX microseconds (PX4 SITL: 2024-11-29T00:00:00.123456Z)
WRAP_MS = 2**32  # SCALED_PRESSURE.time_boot_ms is uint32 ms (common.xml)


@pytest.mark.parametrize("dt_ms", [-1500, 0, 2000])
def test_baro_on_a_unix_time_clock_is_unwrapped_to_the_imu_clock(pipe, dt_ms):
    """An autopilot whose clock is UNIX time sends time_boot_ms modulo 2^32 ms; with the IMU's uint64
    time the high part comes back: a pressure sampled dt before/at/after the last IMU sample reaches
    the engine stamped on the IMU clock (not 'now', not dropped). Expected: (SITL_US/1000 + dt) ms."""
    pipe.handle(highres(SITL_US))
    ms = SITL_US // 1000 + dt_ms
    pipe.handle(wire(lambda m: m.scaled_pressure_encode(ms % WRAP_MS, 898.76, 0.0, 2000)))
    name, (t, h, sigma) = pipe.engine.calls[-1]
    assert name == "baro" and t == pytest.approx(ms * 1e-3, abs=1e-6)


def test_baro_just_after_the_millisecond_field_wrapped(pipe):
    """The IMU at 2^32 ms - 0.5 s, the pressure 1 s later has wrapped to 500 ms: it is 0.5 s after the
    wrap (2^32 ms + 500 ms), and the reverse: IMU just after the wrap, pressure just before it."""
    pipe.handle(highres((WRAP_MS - 500) * 1000))
    pipe.handle(wire(lambda m: m.scaled_pressure_encode(500, 898.76, 0.0, 2000)))
    assert pipe.engine.calls[-1][1][0] == pytest.approx((WRAP_MS + 500) * 1e-3, abs=1e-9)
    pipe.handle(highres((WRAP_MS + 700) * 1000))
    pipe.handle(wire(lambda m: m.scaled_pressure_encode(WRAP_MS - 300, 898.76, 0.0, 2000)))
    assert pipe.engine.calls[-1][1][0] == pytest.approx((WRAP_MS - 300) * 1e-3, abs=1e-9)


def test_system_time_gives_the_engine_the_date(pipe):
    """SYSTEM_TIME.time_unix_usec (us) goes to the engine as UNIX seconds; 0 (no time yet) does not."""
    pipe.handle(wire(lambda m: m.system_time_encode(0, 1000)))
    assert pipe.engine.calls == []
    pipe.handle(wire(lambda m: m.system_time_encode(1_751_457_600_000_000, 1000)))
    assert pipe.engine.calls == [("date", (1_751_457_600.0,))]


def test_global_position_int(pipe):
    pipe.handle(wire(lambda m: m.global_position_int_encode(0, 473977420, -85455940, 488_250, 0, 0, 0, 0, 0)))
    name, a = pipe.engine.calls[-1]
    assert name == "position"
    assert a[:3] == pytest.approx((47.397742, -8.545594, 488.25), abs=1e-9)
    assert a[3] == "GLOBAL_POSITION_INT"
    pipe.handle(wire(lambda m: m.global_position_int_encode(0, 0, 0, 488_250, 0, 0, 0, 0, 0)))
    assert len(pipe.engine.calls) == 1
    pipe.handle(wire(lambda m: m.global_position_int_encode(0, 0, 5, 1_000, 0, 0, 0, 0, 0)))
    pipe.handle(wire(lambda m: m.global_position_int_encode(0, 5, 0, 1_000, 0, 0, 0, 0, 0)))
    assert len(pipe.engine.calls) == 3


def test_vehicle_attitude(pipe):
    pipe.handle(wire(lambda m: m.attitude_encode(0, 0.1, 0.2, -1.25, 0.0, 0.0, 0.0)))
    assert pipe.engine.calls == [("yaw", (-1.25,))]
    pipe.handle(wire(lambda m: m.attitude_encode(0, 0.1, 0.2, math.nan, 0.0, 0.0, 0.0)))
    assert len(pipe.engine.calls) == 1


def test_autopilot_restart(pipe):
    """Sensor time going back by more than 1 s restarts the engine and the sample is used;
    a smaller step back is just a rejected sample."""
    pipe.handle(highres(10_000_000))
    pipe.handle(highres(9_500_000))  # 0.5 s back: rejected, no restart
    assert pipe.engine.calls == [("imu", 10.0)]
    pipe.handle(highres(8_900_000))  # 1.1 s back: the autopilot restarted
    assert pipe.engine.calls[1] == ("restart", "sensor time went back from 10.000 to 8.900 s")
    assert pipe.engine.calls[2] == ("imu", 8.9)
    assert pipe.last_sample.t == 8.9


def test_msg_time():
    assert pl._msg_time(highres(2_500_000)) == pytest.approx(2.5, abs=1e-12)
    assert pl._msg_time(wire(lambda m: m.scaled_pressure_encode(1_500, 900.0, 0.0, 0))) == pytest.approx(1.5,
                                                                                                        abs=1e-12)
    assert pl._msg_time(wire(lambda m: m.heartbeat_encode(0, 0, 0, 0, 0))) is None


# --- survivors of the first run ---------------------------------------------------------------
class FakeRecorder:
    def __init__(self):
        self.gnss = []

        self.samples = []

    def on_gnss(self, t, ned):
        self.gnss.append((t, tuple(ned)))

    def on_sample(self, t, gyro, accel):
        self.samples.append((t, tuple(gyro), tuple(accel)))


def test_counters_count(pipe):
    for _ in range(2):
        pipe.handle(mavlink.MAVLink_bad_data(b"\x00", "junk"))
        pipe.handle(raw_int(fix=1))
    assert pipe.counters == {"bad_data": 2, "gnss_no_fix": 2}


def test_gps_input_velocity_reaches_the_engine(pipe):
    pipe.handle(gps_input())
    assert pipe.engine.calls[-1][1][4] == (1.5, -2.25, 0.5)


def test_small_but_valid_values():
    """Sub-metre accuracies and a 0.01 DOP are values, not "unknown"; 0.5 hPa is a pressure."""
    fix = pl.gnss_fix(gps_input(hacc=0.5, vacc=0.75), 0.0)
    assert fix[5:7] == (0.5, 0.75)
    assert pl.gnss_invalid(fix) is None
    assert pl.gnss_invalid(fix_with(sh=0.5, sv=0.5)) is None
    fix = pl.gnss_fix(hil_gps(eph=65534, epv=1), 0.0)
    assert fix[6] == pytest.approx(0.01 * SIGMA_V, abs=1e-15)


def test_low_pressure_is_used(pipe):
    pipe.handle(wire(lambda m: m.scaled_pressure_encode(1_500, 0.5, 0.0, 2000)))
    assert pipe.engine.calls[-1][0] == "baro"


def test_gnss_drawn_in_the_recording(pipe):
    """The recording (docs/recording.md) shows each accepted fix at its NED offset from the origin."""
    pipe.recorder = FakeRecorder()
    pipe.handle(raw_int())
    assert pipe.recorder.gnss == []  # no sample yet
    pipe.handle(highres(5_500_000))
    pipe.handle(raw_int())
    assert pipe.recorder.gnss == []  # no origin yet
    pipe.engine.origin = (47.397742, 8.545594, 505.0)  # 7 m above the fix (488 m + 10 m geoid)
    pipe.handle(raw_int())
    (t, ned), = pipe.recorder.gnss
    assert t == 5.5
    assert pipe.recorder.samples == [(5.5, (0.0, 0.0, 0.0), pytest.approx((0.0, 0.0, -9.81), abs=1e-6))]
    assert ned == pytest.approx((0.0, 0.0, 7.0), abs=1e-6)
    pipe.recorder = None
    pipe.handle(raw_int())  # no recorder: nothing to draw


def test_restart_needs_more_than_a_second_back(pipe):
    pipe.handle(highres(10_000_000))
    pipe.handle(highres(9_000_000))  # exactly 1 s back: rejected, no restart
    assert pipe.engine.calls == [("imu", 10.0)]


def test_the_pipeline_builds_its_engine_and_ingest():
    from mavins.live.engine import Engine
    from mavins.link.ingest import Ingest
    p = pl.Pipeline(EngineConfig(lat=1.0, lon=2.0, alt=3.0))
    assert isinstance(p.engine, Engine) and p.engine.origin == (1.0, 2.0, 3.0)
    assert isinstance(p.ingest, Ingest) and p.imuset is None


def highres_of(t_us, imu, gz):
    return wire(lambda m: m.highres_imu_encode(t_us, 0.0, 0.0, -9.81, 0.0, 0.0, gz, 0.2, 0.0, 0.4, 1013.0, 0.0,
                                               0.0, 20.0, 0b1_1111_1111, imu))


def test_imus_are_fused_before_the_engine():
    """--imus 0,1: both HIGHRES_IMU streams reach one ImuSet (docs/redundancy.md), the engine gets
    one sample per instant, the least-squares fusion of two identically mounted equal-noise IMUs:
    their mean."""
    from mavins.live.livefilter import FilterSettings
    from mavins.live.imuset import ImuSet
    from mavins.link.ingest import IngestConfig

    p = pl.Pipeline(EngineConfig(filter=FilterSettings(spec="tactical")), IngestConfig(imus=(0, 1),
                                                                                      false_alarm=1e-5))
    assert isinstance(p.imuset, ImuSet) and p.ingest is p.imuset.primary
    assert p.imuset.wanted == (0, 1) and p.imuset.spec == "tactical" and p.imuset.false_alarm == 1e-5
    seen = []

    class Engine(FakeEngine):
        def on_imu(self, smp):
            seen.append(smp)

    p.engine = Engine()
    for k in range(5):
        t_us = 10_000_000 + 10_000 * k
        p.handle(highres_of(t_us, 0, 0.001))
        p.handle(highres_of(t_us, 1, 0.003))
    p.handle(highres_of(10_050_000, 2, 0.5))  # not in the set
    assert p.vehicle_sysid == 1
    assert p.imuset.counters["other_imu"] == 1
    assert [s.t for s in seen] == pytest.approx([10.01, 10.02, 10.03, 10.04], abs=1e-9)
    for s in seen:
        assert s.gyro[2] == pytest.approx(0.002, abs=1e-9)
        assert s.accel == pytest.approx((0.0, 0.0, -9.81), abs=1e-6)  # float32 on the wire
    assert p.imuset.monitor is not None  # the FDI monitor ran on the instants


# --- the recording (docs/recording.md): what the pipeline hands to its sink ------------------------
class FullRecorder(FakeRecorder):
    def __init__(self):
        super().__init__()
        self.outputs, self.filters, self.counters, self.fdi, self.states = [], [], [], [], []

    def on_output(self, row, origin, ned):
        self.outputs.append((row, origin, tuple(ned)))

    def on_filter(self, t, unc):
        self.filters.append((t, unc))

    def on_states(self, t, groups, row):
        self.states.append((t, groups, row.copy()))

    def on_counters(self, t, counters):
        self.counters.append((t, dict(counters)))

    def on_fdi(self, t, sensor, statistic, threshold, residuals):
        self.fdi.append((t, sensor, statistic, threshold, residuals))


ORIGIN = (47.397742, 8.545594, 505.0)


def test_outputs_filter_and_counters_are_recorded():
    """Each output set: its row, origin and NED offset from the origin (10 m north, 5 m east, 7 m up
    of it: WGS-84 radii at 47.4 deg; the exact ECEF difference bends by d^2 / 2R < 1e-5 m), the
    filter's uncertainty when it has one, and the counters (ingest rejections and the engine's
    non-zero ones) at the 1st, 51st, ... output."""
    from mavins.core.records import Solution

    a, f = 6378137.0, 1.0 / 298.257223563
    e2 = f * (2.0 - f)
    s2 = math.sin(math.radians(ORIGIN[0])) ** 2
    rm, rn = a * (1.0 - e2) / (1.0 - e2 * s2) ** 1.5, a / math.sqrt(1.0 - e2 * s2)
    h = ORIGIN[2] + 7.0
    lat = math.radians(ORIGIN[0]) + 10.0 / (rm + h)
    lon = math.radians(ORIGIN[1]) + 5.0 / ((rn + h) * math.cos(math.radians(ORIGIN[0])))
    unc = object()
    sols = []

    from mavins.live.livefilter import FilterSettings, LiveFilter

    class Engine(FakeEngine):
        filter = LiveFilter(FilterSettings())

        def on_imu(self, smp):
            if len(sols) == 2:
                sols.append(None)
                return None
            row = np.array([smp.t, lat, lon, h, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
            sols.append(Solution(row, np.zeros(3), ORIGIN, False, unc if len(sols) % 2 == 0 else None))
            return sols[-1]

    p = pl.Pipeline(EngineConfig())
    p.engine = Engine()
    p.engine.filter.bias[0] = 1e-5
    p.engine.counters = {"gaps_bridged": 2, "restarts": 0}
    p.recorder = FullRecorder()
    p.handle(highres(1_000_000))
    p.handle(highres(1_000_000))  # the same time again: rejected by ingest, counted
    for k in range(1, 53):
        p.handle(highres(1_000_000 + 10_000 * k))
    rec = p.recorder
    out = [s for s in sols if s is not None]
    assert len(rec.outputs) == len(out) == 52 and len(rec.samples) == 53
    for (row, origin, ned), s in zip(rec.outputs, out):
        assert row is s.row and origin == ORIGIN
        assert ned == pytest.approx((10.0, 5.0, -7.0), abs=1e-4)
    assert rec.filters == [(s.row[0], unc) for s in out if s.unc is not None]
    assert len(rec.filters) == 26
    # with each filter output, the filter's columns grouped by quantity (aided.column_groups) in file units:
    # here a fresh filter (zero covariance and biases) with a gyro bias of 1e-5 rad/s = 2.063 deg/h on x
    assert [t for t, _, _ in rec.states] == [t for t, _ in rec.filters]
    t, groups, row = rec.states[-1]
    assert [g for g, _, _ in groups] == ["sigma_pos", "sigma_vel", "sigma_att", "bg", "ba", "sigma_bg", "sigma_ba"]
    assert groups[3] == ("bg", ("bg_x", "bg_y", "bg_z"), (23, 24, 25))
    assert row[23] == pytest.approx(1e-5 * 180.0 / math.pi * 3600.0, rel=1e-12) and not row[24:].any()
    assert [t for t, _ in rec.counters] == [out[0].row[0], out[50].row[0]]
    assert rec.counters[0][1] == {"gaps_bridged": 2}  # the duplicate came after the first output
    assert rec.counters[1][1] == {"rejected_duplicate_time": 1, "gaps_bridged": 2}


def test_fdi_tests_are_recorded():
    """--imus: every window test of the set (time, sensor, statistic, threshold, residuals) reaches
    the recording as the set reports it."""
    from mavins.live.livefilter import FilterSettings
    from mavins.link.ingest import IngestConfig

    p = pl.Pipeline(EngineConfig(filter=FilterSettings(spec="tactical")), IngestConfig(imus=(0, 1)))
    p.engine = FakeEngine()
    p.recorder = FullRecorder()
    reported = []
    take = p.imuset.take_tests

    def spy():
        tests = take()
        reported.extend(tests)
        return tests

    p.imuset.take_tests = spy
    for k in range(70):  # at 10 Hz: 0.5 s windows of 5 instants, tested after the 5 s calibration
        t_us = 10_000_000 + 100_000 * k
        p.handle(highres_of(t_us, 0, 0.001))
        p.handle(highres_of(t_us, 1, 0.001))
    assert reported and p.recorder.fdi == reported
    sensors = {x[1] for x in reported}
    assert sensors == {"gyro", "accel"}


def test_events_are_drained_and_recorded():
    """take_events: the engine's events, then the IMU set's (--imus all: "fusing IMUs 0, 1" once the
    1 s discovery is over), each drained once and sent to the recording stamped with the last
    sample's time (None before any sample)."""
    from mavins.link.ingest import IngestConfig

    class Recorder(FullRecorder):
        def __init__(self):
            super().__init__()
            self.events = []

        def on_event(self, t, level, text):
            self.events.append((t, level, text))

    p = pl.Pipeline(EngineConfig(), IngestConfig(imus=()))
    p.engine = FakeEngine()
    p.recorder = Recorder()
    assert p.take_events() == [("INFO", "x"), ]
    assert p.recorder.events == [(None, "INFO", "x")]
    for k in range(13):
        t_us = 10_000_000 + 100_000 * k
        p.handle(highres_of(t_us, 0, 0.001))
        p.handle(highres_of(t_us, 1, 0.001))
    t_last = p.last_sample.t
    assert p.take_events() == [("INFO", "x"), ("INFO", "fusing IMUs 0, 1")]
    assert p.recorder.events[1:] == [(t_last, "INFO", "x"), (t_last, "INFO", "fusing IMUs 0, 1")]
    assert p.take_events() == [("INFO", "x")]  # the set's event was drained
    p.recorder = None
    assert p.take_events() == [("INFO", "x")]
