"""What the mutation runs found unchecked in mavins/live/engine.py (docs/testing.md).

The engine in-process, fed ImuSamples at rest built from the physics typed here
(``f^b = -C_n^b [0, 0, gamma]``, ``w^b = C_n^b w_ie^n``, ``m^b = C_n^b m^n``; ZYX
Euler angles, NED, FRD; WGS-84 Earth rate and Somigliana gravity as in
docs/conventions.md), never from the engine or the core. Checked: the states and
their events (WAITING -> ALIGNING -> NAVIGATING, docs/conventions.md ``--align``),
which heading source is used (``--heading`` degrees or auto/gyrocompass/mag/vehicle),
the gyro bias taken at rest, the motion and time-gap rules, the output rate, and the
published solution row (t, lat, lon, h, vn, ve, vd, roll, pitch, yaw, q) after
alignment. Aided (the filter on): GNSS position/velocity, baro, magnetometer and
zero-velocity updates moving the solution by the gains worked by hand from the
initial covariance of docs/filter.md, the gate and its counters, measurements stamped
ahead, GNSS lost/recovered, the divergence check, restarts, and the limits of the gap,
motion and still rules taken exactly (binary-exact times and thresholds).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.live.livefilter import FilterSettings
from mavins.core.records import ImuSample
from mavins.live.engine import Engine, EngineConfig, State
from support import cbn as c_bn
from support import gamma as gamma_rad

LAT, LON, ALT = 47.397742, 8.545594, 488.0
OMEGA = 7.292115e-5
A, F = 6378137.0, 1.0 / 298.257223563
E2 = F * (2.0 - F)
DT = 0.01


def gamma(lat_deg: float, h: float) -> float:
    """Normal gravity (m/s^2) at latitude lat_deg (deg), height h (m): tests/support.py's typed WGS-84 form."""
    return float(gamma_rad(math.radians(lat_deg), h))


ATT = (math.radians(3.0), math.radians(-2.0), math.radians(30.0))
M_N = np.array([0.21, 0.02, 0.43])  # gauss, NED: declination atan2(0.02, 0.21) = 5.44 deg east


def rest(t, att=ATT, gyro_bias=(0.0, 0.0, 0.0), mag=True, lat=LAT, h=ALT):
    cnb = c_bn(*att).T
    la = math.radians(lat)
    w = cnb @ np.array([OMEGA * math.cos(la), 0.0, -OMEGA * math.sin(la)]) + np.asarray(gyro_bias)
    f = cnb @ np.array([0.0, 0.0, -gamma(lat, h)])
    m = tuple(cnb @ M_N) if mag else None
    return ImuSample(t, tuple(w), tuple(f), m, 1, 1)


def cfg(**kw) -> EngineConfig:
    base = dict(lat=LAT, lon=LON, alt=ALT, align=0.5, rate=50.0, filter=FilterSettings(aiding=()))
    base.update(kw)
    return EngineConfig(**base)


def align(e: Engine, t0=1.0, n=None, **kw):
    """Feed samples at rest until the engine navigates (0.5 s of alignment at 100 Hz)."""
    t = t0
    for _ in range(n or 60):
        e.on_imu(rest(t, **kw))
        t = round(t + DT, 9)
        if e.state is State.NAVIGATING:
            break
    return t


def texts(e: Engine) -> list[str]:
    return [f"{lvl} {txt}" for lvl, txt in e.take_events()]


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="heading must be degrees or one of auto, gyrocompass, mag, vehicle"):
        Engine(cfg(heading="north"))
    with pytest.raises(ValueError, match="gyro_bias must be estimate or none"):
        Engine(cfg(gyro_bias="guess"))
    with pytest.raises(ValueError, match=r"^--frame wander navigates free inertial only \(the filter works in the "
                                         r"geographic frame\): add --aiding none$"):
        Engine(cfg(frame="wander", filter=FilterSettings()))
    Engine(cfg(frame="wander"))  # no aiding: fine
    for word in ("auto", "gyrocompass", "mag", "vehicle"):
        Engine(cfg(heading=word))


def test_states_and_initial_position():
    e = Engine(cfg(lat=None, lon=None, alt=None))
    assert e.state is State.WAITING and not e.position_known and e.origin is None
    assert texts(e) == ["INFO WAITING: for an initial position (--lat/--lon/--alt, the vehicle's GPS or its "
                        "GPS_GLOBAL_ORIGIN)"]
    assert e.on_imu(rest(1.0)) is None
    assert e.state is State.WAITING
    e.set_position(47.5, 8.25, 500.0, "GPS_RAW_INT", 2.0)
    e.set_position(10.0, 10.0, 10.0, "GLOBAL_POSITION_INT")  # the first one stays
    assert e.origin == (47.5, 8.25, 500.0) and e.position_known
    assert texts(e) == ["INFO initial position from GPS_RAW_INT: 47.5000000, 8.2500000, 500.0 m"]
    e.on_imu(rest(1.01, lat=47.5, h=500.0))
    assert e.state is State.ALIGNING
    assert texts(e) == ["INFO ALIGNING: initial position known"]


def test_position_from_options():
    e = Engine(cfg())
    assert e.origin == (LAT, LON, ALT)
    assert texts(e) == ["INFO initial position from options: 47.3977420, 8.5455940, 488.0 m"]


def test_gnss_before_navigation_is_the_initial_position():
    e = Engine(cfg(lat=None, lon=None, alt=None))
    e.take_events()
    e.on_gnss(None, 47.5, 8.25, 500.0, None, 2.0, 4.0, 0.3, "GPS_INPUT")
    assert e.origin == (47.5, 8.25, 500.0)
    assert e._pos_sigma == 2.0
    assert texts(e) == ["INFO initial position from GPS_INPUT: 47.5000000, 8.2500000, 500.0 m"]
    e = Engine(cfg(lat=None, lon=None, alt=None))
    e.take_events()
    e.on_gnss(None, 47.5, 8.25, 500.0, None, 2.0, 4.0, 0.3)  # the source's default name
    assert texts(e) == ["INFO initial position from GNSS: 47.5000000, 8.2500000, 500.0 m"]
    e.on_baro(None, 100.0, 0.5)  # not navigating: nothing happens


def nav_rows(e: Engine, t: float, n: int, **kw):
    rows = []
    for _ in range(n):
        out = e.on_imu(rest(t, **kw))
        if out is not None:
            rows.append(out)
        t = round(t + DT, 9)
    return rows, t


@pytest.mark.parametrize("heading, vehicle_yaw, mag, source, yaw_deg", [
    (30.0, None, True, "--heading", 30.0),
    (-150.0, None, True, "--heading", -150.0),
    ("auto", math.radians(30.0), True, "vehicle ATTITUDE", 30.0),
    ("vehicle", math.radians(30.0), False, "vehicle ATTITUDE", 30.0),
    ("auto", None, True, "magnetometer", 30.0),
    ("mag", None, True, "magnetometer", 30.0),
    ("auto", None, False, "gyrocompass", 30.0),
    ("gyrocompass", math.radians(99.0), True, "gyrocompass", 30.0),
])
def test_alignment_heading_and_published_row(heading, vehicle_yaw, mag, source, yaw_deg):
    """The vehicle's true attitude is (3, -2, yaw_deg) deg; each source must find that yaw."""
    att = (ATT[0], ATT[1], math.radians(yaw_deg))
    decl = math.degrees(math.atan2(M_N[1], M_N[0]))
    e = Engine(cfg(heading=heading, declination=decl))
    if vehicle_yaw is not None:
        e.set_vehicle_yaw(vehicle_yaw)
    e.take_events()
    t = align(e, mag=mag, att=att)
    assert e.state is State.NAVIGATING
    assert e.heading_used == source
    ev = texts(e)
    assert ev[0] == "INFO ALIGNING: initial position known"
    assert ev[1] == f"INFO NAVIGATING: aligned over 0.5 s: roll 3.00 pitch -2.00 heading {yaw_deg:.2f} deg from " \
                    f"{source}"
    rows, _ = nav_rows(e, t, 6, mag=mag, att=att)
    assert len(rows) == 3  # 2 samples per update at 100 Hz: 50 Hz updates, all due at --rate 50
    r = rows[-1].row
    assert r[0] == pytest.approx(t + 5 * DT, abs=1e-9)
    assert r[1] == pytest.approx(math.radians(LAT), abs=1e-9) and r[2] == pytest.approx(math.radians(LON), abs=1e-9)
    assert r[3] == pytest.approx(ALT, abs=1e-3)
    np.testing.assert_allclose(r[4:7], 0.0, atol=1e-3)
    np.testing.assert_allclose(r[7:9], ATT[:2], atol=1e-6)
    assert math.remainder(r[9] - math.radians(yaw_deg), 2 * math.pi) == pytest.approx(0.0, abs=1e-6)
    assert rows[-1].origin == (LAT, LON, ALT)
    assert rows[-1].degraded is False
    # the published body rate w_ib^b, bias removed: at rest the Earth rate in body axes
    np.testing.assert_allclose(rows[-1].gyro, np.array(rest(0.0, att=att).gyro), rtol=0, atol=1e-12)


def test_missing_heading_sources_fall_back_to_gyrocompass():
    e = Engine(cfg(heading="vehicle"))
    align(e)
    assert e.heading_used == "gyrocompass"
    assert "WARNING no vehicle ATTITUDE seen: heading from gyrocompass" in texts(e)
    e = Engine(cfg(heading="mag"))
    align(e, mag=False)
    assert e.heading_used == "gyrocompass"
    assert "WARNING no magnetometer data: heading from gyrocompass" in texts(e)


def test_all_zero_magnetometer_is_no_magnetometer():
    e = Engine(cfg(heading="auto"))
    t = 1.0
    for _ in range(60):
        s = rest(t)
        e.on_imu(ImuSample(s.t, s.gyro, s.accel, (0.0, 0.0, 0.0), 1, 1))
        t = round(t + DT, 9)
    assert e.heading_used == "gyrocompass"


BIAS = (2e-4, -3e-4, 1e-4)  # rad/s: 41, 62, 21 deg/h


def test_gyro_bias_at_rest():
    e = Engine(cfg(heading=30.0))
    t = align(e, gyro_bias=BIAS)
    np.testing.assert_allclose(e.gyro_bias, BIAS, rtol=0, atol=1e-12)
    assert "INFO gyro bias estimated at rest: 41.3 -61.9 20.6 deg/h" in texts(e)
    # published: the body rate with the bias removed, at rest the Earth rate in body axes
    out, _ = step(e, t, gyro_bias=BIAS)
    np.testing.assert_allclose(out.gyro, rest(0.0).gyro, rtol=0, atol=1e-12)
    e = Engine(cfg(heading=30.0))
    align(e, gyro_bias=(5e-3, 0.0, 0.0))  # 1031.3 deg/h: the conversion to the last digit
    assert any(x.startswith("INFO gyro bias estimated at rest: 1031.3 ") for x in texts(e))
    e = Engine(cfg(heading=30.0, gyro_bias="none"))
    align(e, gyro_bias=BIAS)
    np.testing.assert_array_equal(e.gyro_bias, 0.0)
    assert not any("gyro bias" in x for x in texts(e))
    e = Engine(cfg(heading="gyrocompass"))  # the gyrocompass has used the Earth rate: no bias from it
    align(e)
    np.testing.assert_array_equal(e.gyro_bias, 0.0)


def test_motion_restarts_the_alignment():
    e = Engine(cfg(heading=30.0))
    e.on_imu(rest(1.0))
    e.take_events()
    s = rest(1.01)
    e.on_imu(ImuSample(1.01, (0.0, 0.0, 0.1001), s.accel, None, 1, 1))  # |w| > 0.1 rad/s
    assert e.counters["align_restarts"] == 1
    assert texts(e) == ["WARNING motion during alignment: restarting it"]
    e.on_imu(ImuSample(1.02, (0.0, 0.0, 0.1001), s.accel, None, 1, 1))  # nothing collected: no new warning
    assert e.counters["align_restarts"] == 2 and texts(e) == []
    e.on_imu(ImuSample(1.03, (0.0, 0.0, 0.0999), s.accel, None, 1, 1))  # below: collected
    g = gamma(LAT, ALT)
    e.on_imu(ImuSample(1.04, (0.0, 0.0, 0.0), (0.0, 0.0, -(g + 1.51)), None, 1, 1))  # |f| - g > 1.5
    assert e.counters["align_restarts"] == 3
    e.on_imu(ImuSample(1.05, (0.0, 0.0, 0.0), (0.0, 0.0, -(g - 1.51)), None, 1, 1))
    assert e.counters["align_restarts"] == 4
    e.on_imu(ImuSample(1.06, (0.0, 0.0, 0.0), (0.0, 0.0, -(g + 1.49)), None, 1, 1))
    e.on_imu(ImuSample(1.07, (0.0, 0.0, 0.0), (0.0, 0.0, -(g - 1.49)), None, 1, 1))
    assert e.counters["align_restarts"] == 4
    # the window restarts at the first sample after the motion: 0.5 s from 1.06
    t = 1.08
    while e.state is not State.NAVIGATING:
        e.on_imu(rest(t))
        t = round(t + DT, 9)
    assert t == pytest.approx(1.57, abs=1e-9)


def test_time_gaps():
    e = Engine(cfg(heading=30.0))
    t = 1.0
    for _ in range(10):
        e.on_imu(rest(t))
        t = round(t + DT, 9)
    e.on_imu(rest(t + 0.02))  # 3 nominal intervals: bridged
    assert e.counters["gaps_bridged"] == 1
    e.on_imu(rest(t + 0.035))  # 1.5 nominal: nothing
    assert e.counters["gaps_bridged"] == 1
    e.take_events()
    e.on_imu(rest(t + 1.6))  # a long gap while aligning: the window starts over
    assert e.counters["gaps_long"] == 1
    assert texts(e) == ["WARNING sensor-time gap of 1.565 s during alignment: restarting it"]
    t = align(e, t0=t + 1.61)
    assert e.state is State.NAVIGATING
    e.take_events()
    rows, t = nav_rows(e, t, 4)
    e.on_imu(rest(t + 2.0))  # a long gap while navigating: not integrated, degraded
    assert e.counters["gaps_long"] == 2 and e.degraded
    assert texts(e) == ["WARNING sensor-time gap of 2.010 s not integrated: solution degraded"]
    rows, t2 = nav_rows(e, round(t + 2.01, 9), 4)
    assert rows and all(r.degraded for r in rows)
    assert t2 - 2 * DT - 1e-9 <= rows[-1].row[0] <= t2 - DT + 1e-9
    np.testing.assert_allclose(rows[-1].row[4:7], 0.0, atol=1e-3)  # the gap was not integrated
    e.on_imu(rest(t2 + 2.5))
    assert texts(e) == []  # already degraded: warned once
    e.on_imu(rest(t2 + 70.0))  # beyond restart_gap (60 s): alignment starts over
    assert e.counters["time_jumps"] == 1 and e.counters["restarts"] == 1
    assert e.state is State.ALIGNING
    assert texts(e) == ["INFO ALIGNING: sensor time jumped 67.5 s forward"]


def test_restart_without_position_waits():
    e = Engine(cfg(lat=None, lon=None, alt=None))
    e.restart("why")
    assert e.state is State.WAITING and e.counters["restarts"] == 1


@pytest.mark.parametrize("rate", [50.0, 20.0, 10.0])
def test_output_rate(rate):
    e = Engine(cfg(heading=30.0, rate=rate))
    t = align(e)
    rows, _ = nav_rows(e, t, 60)  # 0.6 s
    assert len(rows) == pytest.approx(0.6 * rate, abs=1)
    # one set each time sensor time crosses a multiple of 1/rate, on the first update at or after it
    k = np.floor(np.array([r.row[0] for r in rows]) * rate + 1e-9)
    np.testing.assert_array_equal(np.diff(k), 1.0)
    if rate != 20.0:  # updates every 20 ms from 1.52 s: each multiple of 1/rate is an update's time
        times = np.array([r.row[0] for r in rows[1:]])
        np.testing.assert_allclose(times * rate, np.round(times * rate), rtol=0, atol=1e-6)


# -- aided: the filter's measurements through the engine ------------------------------------------
# Expected values from the Kalman equations by hand (docs/filter.md): right after the alignment
# the covariance is diagonal (position sigma from the first fix's accuracy, else 10 m, each
# axis; velocity 0.1 m/s; baro offset 50 m), and the few hundredths of a second propagated
# before the update add relatively < 1e-3 to it. A position fix p_m with R = diag(sh^2, sh^2,
# sv^2) and H = [0 0 I] moves each axis by P/(P + R) of (p_m - p); a barometric height h_m with
# H = (-1 on the down position, +1 on the offset) moves h by P_h/(P_h + P_off + R) of (h_m - h).

def radii(lat_deg: float) -> tuple[float, float]:
    """WGS-84 meridian and prime-vertical radii (m)."""
    s2 = math.sin(math.radians(lat_deg)) ** 2
    return A * (1.0 - E2) / (1.0 - E2 * s2) ** 1.5, A / math.sqrt(1.0 - E2 * s2)


def ned_of(row, ref) -> np.ndarray:
    """North, east, down (m) of a solution row from another row (small offsets)."""
    rm, rn = radii(LAT)
    return np.array([(row[1] - ref[1]) * (rm + ALT), (row[2] - ref[2]) * (rn + ALT) * math.cos(math.radians(LAT)),
                     -(row[3] - ref[3])])


def fix_at(ned) -> tuple[float, float, float]:
    """lat, lon (deg), h (m) of the point ned (m) from (LAT, LON, ALT)."""
    rm, rn = radii(LAT)
    return (LAT + math.degrees(ned[0] / (rm + ALT)),
            LON + math.degrees(ned[1] / ((rn + ALT) * math.cos(math.radians(LAT)))), ALT - ned[2])


def aided(aiding=("gnss", "baro"), **kw) -> Engine:
    e = Engine(cfg(heading=30.0, filter=FilterSettings(aiding=aiding), **kw))
    return e


def step(e: Engine, t: float, **kw):
    """Feed samples until the next output; returns it and the next sample time."""
    for _ in range(10):
        out = e.on_imu(rest(t, **kw))
        t = round(t + DT, 9)
        if out is not None:
            return out, t
    raise AssertionError("no output")


def test_gnss_position_fix_moves_by_the_gain():
    e = aided()
    t = align(e)
    before, t = step(e, t)
    off = np.array([4.0, -6.0, 3.0])  # m NED
    e.on_gnss(None, *fix_at(off), None, 10.0, 5.0, 0.3)  # P 100 m^2 each axis: gains 0.5, 0.5, 100/125
    assert e.filter.counters["gnss_pos_accepted"] == 1 and e.filter.counters["gnss_vel_accepted"] == 0
    after, t = step(e, t)
    np.testing.assert_allclose(ned_of(after.row, before.row), [2.0, -3.0, 2.4], rtol=0, atol=0.01)
    assert after.unc.abs_pos and after.unc.abs_hgt and not after.unc.glitch
    assert after.unc.sigma_pos == pytest.approx([50.0 ** 0.5, 50.0 ** 0.5, 20.0 ** 0.5], rel=2e-3)


def test_gnss_sigma_of_the_first_fix_is_the_initial_position_sigma():
    e = aided(lat=None, lon=None, alt=None)
    e.on_gnss(None, LAT, LON, ALT, None, 2.0, 3.0, 0.3, "GPS_RAW_INT")  # the initial position, 2 m
    t = align(e)
    assert e.state is State.NAVIGATING
    before, t = step(e, t)
    assert before.unc.sigma_pos == pytest.approx([2.0, 2.0, 2.0], rel=2e-3)
    e.on_gnss(None, *fix_at([4.0, 0.0, -4.0]), None, 2.0, 4.0, 0.3, "GPS_RAW_INT")  # gains 4/8, 4/20
    after, t = step(e, t)
    np.testing.assert_allclose(ned_of(after.row, before.row), [2.0, 0.0, -0.8], rtol=0, atol=0.01)


def test_gnss_velocity_fix():
    e = aided()
    t = align(e)
    before, t = step(e, t)
    e.on_gnss(None, LAT, LON, ALT, (0.3, -0.2, 0.1), 10.0, 10.0, 0.1)  # P_v 0.01, R 0.01: gain 0.5
    assert e.filter.counters["gnss_vel_accepted"] == 1
    after, t = step(e, t)
    np.testing.assert_allclose(after.row[4:7], [0.15, -0.1, 0.05], rtol=0, atol=0.003)


def test_gnss_outside_the_gate_is_rejected_and_counted():
    e = aided()
    t = align(e)
    before, t = step(e, t)
    e.on_gnss(None, *fix_at([80.0, 0.0, 0.0]), None, 2.0, 2.0, 0.3)  # 80 / sqrt(100 + 4) = 7.8 > 5 sigma
    assert e.filter.counters["gnss_pos_rejected"] == 1 and e.filter.counters["gnss_pos_accepted"] == 0
    after, t = step(e, t)
    np.testing.assert_allclose(ned_of(after.row, before.row), 0.0, atol=1e-3)
    assert after.unc.glitch and not after.unc.abs_pos
    assert after.unc.pos_ratio == pytest.approx((80.0 / 104.0 ** 0.5 / 5.0) ** 2, rel=2e-3)


def test_gnss_fix_stamped_ahead_waits_for_its_time():
    e = aided()
    t = align(e)
    before, t = step(e, t)
    t_now = before.row[0]
    e.on_gnss(t_now + 0.05, *fix_at([4.0, 0.0, 0.0]), None, 10.0, 10.0, 0.3)  # 2.5 updates ahead
    assert e.filter.counters["gnss_pos_accepted"] == 0
    rows = []
    for _ in range(3):
        out, t = step(e, t)
        rows.append(ned_of(out.row, before.row)[0])
    assert rows[0] == pytest.approx(0.0, abs=1e-3) and rows[1] == pytest.approx(0.0, abs=1e-3)
    assert rows[2] == pytest.approx(2.0, abs=0.01)
    assert e.filter.counters["gnss_pos_accepted"] == 1


def test_gnss_not_in_aiding_is_ignored():
    e = aided(aiding=("baro",))
    t = align(e)
    before, t = step(e, t)
    e.on_gnss(None, *fix_at([4.0, 0.0, 0.0]), None, 10.0, 10.0, 0.3)
    after, t = step(e, t)
    np.testing.assert_allclose(ned_of(after.row, before.row), 0.0, atol=1e-3)


def test_measurements_before_navigation_change_nothing():
    e = aided()
    e.on_imu(rest(1.0))
    assert e.state is State.ALIGNING
    e.on_gnss(None, *fix_at([4.0, 0.0, 0.0]), (1.0, 0.0, 0.0), 10.0, 10.0, 0.3)
    e.on_baro(None, ALT + 10.0, 0.5)
    e.on_baro(1.0, ALT + 10.0, 0.5)
    assert e.origin == (LAT, LON, ALT)  # the options' position stays
    assert not e.filter.counters
    t = align(e, t0=1.01)
    before, t = step(e, t)
    assert before.row[3] == pytest.approx(ALT, abs=1e-3)


def test_baro_height_moves_by_the_gain():
    e = aided()
    t = align(e)
    before, t = step(e, t)
    e.on_baro(None, ALT + 10.0, 0.5)  # P_h 100, P_off 2500, R 0.25
    assert e.filter.counters["baro_accepted"] == 1
    after, t = step(e, t)
    assert after.row[3] - before.row[3] == pytest.approx(10.0 * 100.0 / 2600.25, abs=0.004)
    # the offset (baro minus ellipsoidal height) took P_off/S of it
    assert e.filter.bias[12] == pytest.approx(10.0 * 2500.0 / 2600.25, abs=0.05)


def test_baro_stamped_ahead_waits_for_its_time():
    e = aided()
    t = align(e)
    before, t = step(e, t)
    e.on_baro(before.row[0] + 0.03, ALT + 10.0, 0.5)
    assert e.filter.counters["baro_accepted"] == 0
    first, t = step(e, t)
    assert first.row[3] == pytest.approx(before.row[3], abs=1e-3)
    second, t = step(e, t)
    assert second.row[3] - before.row[3] == pytest.approx(10.0 * 100.0 / 2600.25, abs=0.004)


def test_baro_sigma_reaches_the_filter():
    e = aided()
    t = align(e)
    before, t = step(e, t)
    e.on_baro(None, ALT + 10.0, 50.0)  # R 2500
    after, t = step(e, t)
    assert after.row[3] - before.row[3] == pytest.approx(10.0 * 100.0 / 5100.0, abs=0.004)


def test_gnss_lost_and_recovered_are_announced_once():
    e = aided()
    t = align(e)
    before, t = step(e, t)
    t_now = before.row[0]
    e.on_gnss(t_now - 2.97, LAT, LON, ALT, None, 10.0, 10.0, 0.3)  # accepted, 2.97 s old (at rest: v dt = 0)
    assert e.filter.counters["gnss_pos_accepted"] == 1
    e.take_events()
    out, t = step(e, t)  # 2.99 s after the fix
    assert out.unc.abs_pos and texts(e) == []
    out, t = step(e, t)  # 3.01 s: lost
    assert texts(e) == ["WARNING GNSS lost: no accepted fix for 3 s, free inertial"]
    assert e.filter.counters["gnss_lost"] == 1
    out, t = step(e, t)
    assert texts(e) == []  # once
    e.on_gnss(None, LAT, LON, ALT, None, 10.0, 10.0, 0.3)
    out, t = step(e, t)
    assert texts(e) == ["INFO GNSS recovered: position aided again"]
    out, t = step(e, t)
    assert texts(e) == []


def moving(t, a_n, att=ATT):
    """A sample of a vehicle at attitude att accelerating at a_n (NED m/s^2) near (LAT, ALT)."""
    cnb = c_bn(*att).T
    la = math.radians(LAT)
    w = cnb @ np.array([OMEGA * math.cos(la), 0.0, -OMEGA * math.sin(la)])
    f = cnb @ (np.asarray(a_n, dtype=float) - np.array([0.0, 0.0, gamma(LAT, ALT)]))
    return ImuSample(t, tuple(w), tuple(f), None, 1, 1)


def kick(e: Engine, t: float, dv):
    """One attitude update (2 samples, just after an output) changing the velocity by dv (m/s NED)."""
    a = np.asarray(dv) / (2 * DT)
    assert e.on_imu(moving(t, a)) is None
    out = e.on_imu(moving(round(t + DT, 9), a))
    return out, round(t + 2 * DT, 9)


@pytest.mark.parametrize("dv, diverged", [
    ((-4500.0, -3500.0, -2500.0), True),  # |vn| + |ve| + |vd| = 10500 m/s: beyond any vehicle
    ((4500.0, 3000.0, 2000.0), False),  # 9500 m/s: published
])
def test_speed_beyond_any_vehicle_is_never_published(dv, diverged):
    e = aided(aiding=())
    t = align(e)
    _, t = step(e, t)
    e.take_events()
    out, t = kick(e, t, dv)
    if not diverged:
        np.testing.assert_allclose(out.row[4:7], dv, rtol=0, atol=1.0)
        assert e.counters["diverged"] == 0 and e.state is State.NAVIGATING
        return
    assert out is None
    assert e.counters["diverged"] == 1 and e.counters["restarts"] == 1
    assert texts(e) == ["ERROR solution diverged (non-finite or beyond any vehicle): re-aligning",
                        "INFO ALIGNING: solution diverged"]
    assert e.state is State.ALIGNING
    t = align(e, t0=t)  # and it starts over at the same position
    out, t = step(e, t)
    assert out.row[3] == pytest.approx(ALT, abs=1e-3) and out.origin == (LAT, LON, ALT)
    np.testing.assert_allclose(out.row[4:7], 0.0, atol=1e-3)


@pytest.mark.parametrize("alt, diverged", [(1.001e6, True), (-1.001e6, True), (0.999e6, False),
                                            (1e6, False)])  # at rest the first output is at exactly 1e6 m
def test_height_beyond_any_vehicle_is_never_published(alt, diverged):
    e = aided(aiding=(), alt=alt)
    t = 1.0
    for _ in range(60):
        out = e.on_imu(rest(t, h=alt))
        t = round(t + DT, 9)
        if out is not None or e.counters["diverged"]:
            break
    assert e.counters["diverged"] == (1 if diverged else 0)
    assert (out is None) == diverged


def test_non_finite_solution_is_never_published():
    e = aided(aiding=())
    t = align(e)
    for n in (1, 2):  # each time counted
        _, t = step(e, t)
        nan = ImuSample(t, (0.0, 0.0, 0.0), (0.0, math.nan, -9.8), None, 1, 1)
        assert e.on_imu(nan) is None
        assert e.on_imu(rest(round(t + DT, 9))) is None
        assert e.counters["diverged"] == n and e.state is State.ALIGNING
        t = align(e, t0=round(t + 2 * DT, 9))


def test_restart_while_navigating_starts_the_alignment_over():
    e = aided(aiding=())
    t = align(e)
    _, t = step(e, t)
    e.take_events()
    e.restart("autopilot restarted")
    e.restart("again")
    assert e.counters["restarts"] == 2
    assert texts(e) == ["INFO ALIGNING: autopilot restarted"]
    assert e.state is State.ALIGNING
    # the sensor clock went back; samples every 5 ms now: the nominal interval is learnt afresh
    t = 0.5
    for _ in range(4):
        assert e.on_imu(rest(t)) is None
        t = round(t + 0.005, 9)
    assert e.on_imu(rest(round(t + 0.007, 9))) is None  # 12 ms: over twice 5 ms
    assert e.counters["gaps_bridged"] == 1
    t = round(t + 0.012, 9)
    while e.state is not State.NAVIGATING:
        e.on_imu(rest(t))
        t = round(t + 0.005, 9)
    rows = []
    while len(rows) < 3:
        out = e.on_imu(rest(t))
        t = round(t + 0.005, 9)
        if out is not None:
            rows.append(out)
    assert rows[0].row[0] < 1.1  # published on the new clock, straight away
    assert rows[-1].unc.resets == 2
    np.testing.assert_allclose(rows[-1].row[4:7], 0.0, atol=1e-3)


def test_long_gap_is_not_integrated():
    e = aided(aiding=())
    t = align(e)
    before, t = step(e, t)
    t_gap = round(t + 2.0, 9)
    e.on_imu(moving(t_gap, (1.0, 0.0, 0.0)))  # after 2 s: counts for the nominal 10 ms only
    out = e.on_imu(moving(round(t_gap + DT, 9), (1.0, 0.0, 0.0)))
    assert out is not None and out.degraded
    assert out.row[4] == pytest.approx(0.02, abs=1e-3)  # 1 m/s^2 for 2 x 10 ms, not 2.01 s


def test_geographic_frame_limit_degrades_the_solution():
    lat = 89.6
    e = Engine(cfg(heading=30.0, lat=lat))
    e.take_events()
    t = align(e, lat=lat)
    e.take_events()
    out, t = step(e, t, lat=lat)
    assert out.degraded
    assert texts(e) == ["WARNING geographic frame beyond |lat| 89.5 deg: solution degraded (use --frame wander, "
                        "free or inertial)"]
    out, t = step(e, t, lat=lat)
    assert out.degraded and texts(e) == []
    e = Engine(cfg(heading=30.0, lat=89.4))
    t = align(e, lat=89.4)
    out, t = step(e, t, lat=89.4)
    assert not out.degraded


def test_magnetometer_heading_updates_fifty_times_a_second():
    """Typed heading 30 deg (1-sigma 10 deg); the magnetometer says 34 deg (the declination set 4 deg
    east of the field's); sigma_mag 3 deg: the first update moves the heading by 100/109 of 4 deg,
    the next by 8.26/17.26 of what is left (P after the first: 100 x 9/109). Samples every 10 ms, an
    output every 20 ms: the magnetometer's grid of 20 ms (docs/filter.md) takes one per output."""
    decl = math.degrees(math.atan2(M_N[1], M_N[0])) + 4.0
    e = aided(aiding=("mag",), declination=decl)
    t = align(e)
    yaws = []
    for _ in range(5):
        out, t = step(e, t)
        yaws.append(math.degrees(out.row[9]))
    first = 30.0 + 4.0 * 100.0 / 109.0
    assert yaws[0] == pytest.approx(first, abs=0.1)
    p1 = 100.0 * 9.0 / 109.0
    assert yaws[1] - yaws[0] == pytest.approx((34.0 - first) * p1 / (p1 + 9.0), abs=0.03)
    assert e.filter.counters["mag_accepted"] == 5


@pytest.mark.parametrize("on_update", [False, True])
def test_a_magnetometer_sample_on_either_sample_of_an_update_is_used(on_update: bool):
    """Two samples per attitude update: a magnetometer sample on the first of a pair (no update completes there)
    waits for the update that passes its time; one on the second is applied at once. Either way the heading
    moves by 100/109 of the 4 deg (see above) at that update, one sample accepted."""
    decl = math.degrees(math.atan2(M_N[1], M_N[0])) + 4.0
    e = aided(aiding=("mag",), declination=decl)
    t = align(e, mag=False)
    before, t = step(e, t, mag=False)
    assert e.on_imu(rest(t, mag=not on_update)) is None  # the first sample of the pair: no update yet
    t = round(t + DT, 9)
    out = e.on_imu(rest(t, mag=on_update))
    assert out is not None
    assert math.degrees(out.row[9]) - math.degrees(before.row[9]) == pytest.approx(4.0 * 100.0 / 109.0, abs=0.1)
    assert e.filter.counters["mag_accepted"] == 1


def test_a_dense_magnetometer_is_used_fifty_times_a_second():
    """A magnetometer on every sample of a 125 Hz IMU (8 ms): taken at t0, then at the first sample from
    t0 + 15 ms (three quarters of the 20 ms interval), then on the 20 ms grid from there (t0 + 0.035,
    0.055, ...): 50 in the first second (t0, 0.016, 0.040, 0.056, 0.080, ...), where a rule of 15 ms from
    the last one would take 63 and one of 20 ms from it, 42."""
    e = aided(aiding=("mag",))
    t = align(e, mag=False)
    _, t = step(e, t, mag=False)
    for k in range(125):
        e.on_imu(rest(round(t + k * 0.008, 9), mag=True))
    assert e.filter.counters["mag_accepted"] + len(e.filter._pending) == 50


def test_the_next_magnetometer_sample_may_come_three_quarters_of_the_interval_later():
    """After one is taken at t, a sample at exactly t + 0.75 x 20 ms is taken too, one just before it is not."""
    for dt_next, taken in ((0.75 * 0.02, 2), (0.75 * 0.02 - 1e-6, 1)):
        e = aided(aiding=("mag",))
        t = align(e, mag=False)
        _, t = step(e, t, mag=False)
        e.on_imu(rest(t, mag=True))
        e.on_imu(rest(t + dt_next, mag=True))
        assert e.filter.counters["mag_accepted"] + e.filter.counters["mag_rejected"] + len(e.filter._pending) \
            == taken, dt_next


@pytest.mark.parametrize("mag", [None, (0.0, 0.0, 0.0)])
def test_no_magnetometer_no_heading_update(mag):
    e = aided(aiding=("mag",))
    t = align(e, mag=False)
    for _ in range(3):
        s = rest(t, mag=False)
        e.on_imu(ImuSample(s.t, s.gyro, s.accel, mag, 1, 1))
        t = round(t + DT, 9)
    assert not e.filter.counters


def test_zero_velocity_updates_after_half_a_second_still():
    e = aided(aiding=("zupt",))
    t = align(e)
    _, t = step(e, t)
    out, t = kick(e, t, (0.1, 0.0, 0.0))  # 5 m/s^2 for 20 ms: moving, then still from the next sample
    t_still = t
    assert out.row[4] == pytest.approx(0.1, abs=1e-3)
    vn = {}
    while t < t_still + 0.7:
        out = e.on_imu(rest(t))
        if out is not None:
            vn[round(out.row[0] - t_still, 2)] = out.row[4]
        t = round(t + DT, 9)
    # still since the first update after the kick (t_still + 0.01); updates start 0.5 s later, every 0.1 s
    assert vn[0.49] == pytest.approx(0.1, abs=2e-3)
    # the first ZUPT leaves R/(P + R) of it, P about 0.01 + the level error's g^2 sigma^2 t^2: gain > 0.96
    assert abs(vn[0.51]) < 0.004
    assert e.filter.counters["zupt_accepted"] == 2  # at +0.51 and +0.61 s


def test_sampled_rates_start_at_the_last_alignment_sample():
    """--imu-rates sampled: the sample ending the alignment opens the first interval, so the first
    update (2 samples) completes 2 samples later, as with averaged rates. A sample of 1 m/s^2 at
    1.51 s between rest samples: sampled rates are piecewise linear (docs/conventions.md), 0.5 m/s^2
    on average over each of the two intervals around it: 0.01 m/s; averaged, the mean over
    1.50-1.51 s: 0.01 m/s as well."""
    for rates in ("sampled", "averaged"):
        e = Engine(cfg(heading=30.0, imu_rates=rates))
        t = align(e)
        assert t == pytest.approx(1.51, abs=1e-9)  # the alignment ended on the sample at 1.50 s
        assert e.on_imu(moving(1.51, (1.0, 0.0, 0.0))) is None
        out = e.on_imu(moving(1.52, (0.0, 0.0, 0.0)))
        assert out.row[0] == pytest.approx(1.52, abs=1e-9)
        np.testing.assert_allclose(out.row[4:7], [0.01, 0.0, 0.0], atol=1e-6)
        out, t = step(e, 1.53)
        assert out.row[0] == pytest.approx(1.54, abs=1e-9)


# consumer grade (docs/simulator.md, model values): gyro random walk, turn-on sigma, Gauss-Markov
# sigma B / 0.6174; accelerometer turn-on sigma
ARW, GYRO_ON, GYRO_GM, ACC_ON = 6.981e-5, 5.818e-3, 4.848e-5 / 0.6174, 8.172e-2


@pytest.mark.parametrize("heading, vehicle_yaw, sigma_yaw", [
    (30.0, None, 10.0), ("vehicle", math.radians(30.0), 1.0), ("mag", None, 5.0)])
def test_initial_attitude_sigma_by_heading_source(heading, vehicle_yaw, sigma_yaw):
    """docs/filter.md "Tuning": level 1-sigma the accelerometer bias over g, heading by its source
    (a typed number 10 deg, the vehicle's ATTITUDE 1 deg, the magnetometer 5 deg)."""
    decl = math.degrees(math.atan2(M_N[1], M_N[0]))
    e = Engine(cfg(heading=heading, declination=decl, filter=FilterSettings(aiding=())))
    if vehicle_yaw is not None:
        e.set_vehicle_yaw(vehicle_yaw)
    t = align(e)
    out, t = step(e, t)
    level = math.degrees(math.atan(ACC_ON / 9.8))
    np.testing.assert_allclose(np.degrees(out.unc.sigma_att), [level, level, sigma_yaw], rtol=2e-3)


@pytest.mark.parametrize("gyro_bias, heading, window", [("estimate", 30.0, 0.5), ("none", 30.0, 0.0),
                                                        ("estimate", "gyrocompass", 0.0)])
def test_gyro_bias_sigma_after_the_rest_window(gyro_bias, heading, window):
    """docs/filter.md "Tuning": after a zero-rate calibration over T = 0.5 s the constant gyro bias
    1-sigma is ARW/sqrt(T) combined with the Earth rate seen through the heading error (10 deg
    typed); without one (--gyro-bias none, or a gyrocompass heading, which used the Earth rate) the
    turn-on sigma. The published sigma adds the Gauss-Markov part."""
    e = Engine(cfg(heading=heading, gyro_bias=gyro_bias, filter=FilterSettings(aiding=())))
    t = align(e, gyro_bias=BIAS if gyro_bias == "estimate" and heading != "gyrocompass" else (0.0, 0.0, 0.0))
    out, t = step(e, t)
    if window:
        const = ARW ** 2 / window + (OMEGA * math.radians(10.0)) ** 2
    else:
        const = GYRO_ON ** 2
    np.testing.assert_allclose(out.unc.sigma_gyro, math.sqrt(const + GYRO_GM ** 2), rtol=5e-3)


Q = 2.0 ** -7  # s: a sample interval exact in binary, so that the gaps below are exact


def test_gap_limits_exactly():
    """A gap of exactly max_gap (1 s) is bridged, exactly restart_gap (60 s) is a long gap, exactly
    twice the nominal interval is not counted (docs/conventions.md: longer than these)."""
    e = Engine(cfg(heading=30.0, align=100.0))  # stays aligning
    t = 1.0
    for _ in range(5):
        e.on_imu(rest(t))
        t += Q
    t -= Q
    e.on_imu(rest(t + 2 * Q))  # exactly twice the nominal
    assert e.counters["gaps_bridged"] == 0
    t += 2 * Q
    e.on_imu(rest(t + 1.0))  # exactly max_gap: bridged, not long
    assert e.counters["gaps_bridged"] == 1 and e.counters["gaps_long"] == 0
    t += 1.0
    e.on_imu(rest(t + 60.0))  # exactly restart_gap: long, no restart
    assert e.counters["gaps_long"] == 1 and e.counters["time_jumps"] == 0 and e.counters["restarts"] == 0
    t += 60.0
    e.on_imu(rest(t + 60.5))
    e.on_imu(rest(t + 121.0))
    assert e.counters["time_jumps"] == 2 and e.counters["restarts"] == 2  # each counted
    e.on_imu(rest(t + 121.0 + 3 * Q))
    e.on_imu(rest(t + 121.0 + 6 * Q))
    assert e.counters["gaps_bridged"] == 1  # the nominal interval restarted with the restart: 3 Q


def test_nominal_interval_follows_the_gaps_slowly():
    """The nominal interval moves 5 % of the way to each gap up to max_gap (a first-order filter):
    from 7.8125 ms, gaps of 15 and 15.5 ms are within twice it, one of 20 ms is not; a 1 s gap
    (bridged) moves it to 57.4 ms, so a 20 ms gap after it is not counted."""
    e = Engine(cfg(heading=30.0, align=100.0))
    t = 1.0
    for _ in range(5):
        e.on_imu(rest(t))
        t += Q
    t -= Q
    counts = []
    for gap in (0.015, 0.0155, 0.02):
        t += gap
        e.on_imu(rest(t))
        counts.append(e.counters["gaps_bridged"])
    assert counts == [0, 0, 1]
    t += 1.0
    e.on_imu(rest(t))
    assert e.counters["gaps_bridged"] == 2  # 1 s: over twice the nominal
    t += 0.02
    e.on_imu(rest(t))
    assert e.counters["gaps_bridged"] == 2


def test_motion_limits_exactly():
    """|w| of exactly motion_gyro (0.1 rad/s) and ||f| - g| of exactly motion_accel (1.5 m/s^2) are
    still at rest: motion is beyond them."""
    from mavins.core.earth import gravity  # the engine's reference, to build an exact boundary sample

    g = gravity(math.radians(LAT), ALT)
    e = Engine(cfg(heading=30.0))
    t = 1.0
    for w, f in (((0.0, 0.0, 0.1), (0.0, 0.0, -g)), ((0.0, 0.0, 0.0), (0.0, 0.0, -(g + 1.5))),
                 ((0.0, 0.0, 0.0), (0.0, 0.0, -(g - 1.5)))):
        assert abs(math.sqrt(sum(x * x for x in f)) - g) == 1.5 or f[2] == -g
        e.on_imu(ImuSample(t, w, f, None, 1, 1))
        t += DT
    assert e.counters["align_restarts"] == 0


def test_long_gap_while_aligning_with_nothing_collected_is_silent():
    e = Engine(cfg(heading=30.0))
    e.on_imu(rest(1.0))
    e.on_imu(ImuSample(1.01, (0.0, 0.0, 0.2), rest(1.01).accel, None, 1, 1))  # motion: nothing collected
    e.take_events()
    e.on_imu(rest(3.0))
    assert e.counters["gaps_long"] == 1 and texts(e) == []


def test_long_gap_without_a_nominal_interval_integrates_nothing():
    """--align 0: aligned on the first sample, so no interval is known yet; the sample after a long
    gap then covers nothing, and the next ones their own 10 ms."""
    e = aided(aiding=(), align=0.0)
    e.on_imu(rest(1.0))
    assert e.state is State.NAVIGATING
    assert e.on_imu(moving(3.0, (1.0, 0.0, 0.0))) is None
    assert e.on_imu(moving(3.01, (1.0, 0.0, 0.0))) is None
    out = e.on_imu(moving(3.02, (1.0, 0.0, 0.0)))  # 2 samples of 10 ms: the first update
    assert out is not None and out.degraded and out.row[0] == pytest.approx(3.02, abs=1e-9)
    assert out.row[4] == pytest.approx(0.02, abs=1e-4)


LEVEL = (0.0, 0.0, math.radians(30.0))


@pytest.mark.parametrize("case", ["still", "gyro at the limit", "accel at the limit", "accel within, above g"])
def test_zero_velocity_updates_exactly(case):
    """On a timeline exact in binary (samples every 2^-7 s, updates every 2^-6 s, zupt_every_s 1/8,
    zupt_gyro 2^-6 rad/s, zupt_accel 1/8 m/s^2): still from the first update, a zero-velocity
    update at exactly 0.5 s still and then every 1/8 s. A rate of exactly zupt_gyro or a specific
    force exactly zupt_accel from gravity is not still. Gravity is the engine's reference at the
    initial position (latitude and height), so a specific force 0.12 m/s^2 above it is still."""
    from mavins.core.earth import gravity

    g = gravity(math.radians(LAT), ALT)
    e = aided(aiding=("zupt",), gyro_bias="none", zupt_gyro=2.0 ** -6, zupt_accel=0.125, zupt_every_s=0.125,
              rate=64.0)  # an output at each update
    t = 1.0
    while e.state is not State.NAVIGATING:
        e.on_imu(rest(t, att=LEVEL))
        t += Q
    w, f = rest(0.0, att=LEVEL).gyro, (0.0, 0.0, -g)
    if case == "gyro at the limit":
        w = (0.0, 0.0, 2.0 ** -6)
    elif case == "accel at the limit":
        f = (0.0, 0.0, -(g + 0.125))
        assert math.sqrt(sum(x * x for x in f)) - g == 0.125
    elif case == "accel within, above g":
        f = (0.0, 0.0, -(g + 0.12))
    zupts = []
    t_first = None
    for _ in range(2 * 50):
        out = e.on_imu(ImuSample(t, w, f, None, 1, 1))
        if out is not None:
            t_first = out.row[0] if t_first is None else t_first
            n = e.filter.counters["zupt_accepted"] + e.filter.counters["zupt_rejected"]
            if n > len(zupts):
                zupts.append(out.row[0] - t_first)
        t += Q
    if case in ("still", "accel within, above g"):
        assert zupts == [0.5, 0.625, 0.75]
    else:
        assert zupts == []


def test_body_rate_is_the_raw_rate_minus_both_gyro_bias_parts_to_the_bit() -> None:
    """LiveFilter.body_rate (floats, per attitude update) equals ``u - M u`` with u = (w - (constant +
    Gauss-Markov bias)) / (1 + s), worked here bit for bit, and uses no accelerometer part."""
    from mavins.live.livefilter import LiveFilter
    from mavins.core import kalman

    flt = LiveFilter(FilterSettings(spec="consumer"))
    rng = np.random.default_rng(3)
    for _ in range(200):
        flt.bias[:] = rng.normal(0.0, 1e-2, flt.bias.size)
        w = tuple(float(x) for x in rng.normal(0.0, 0.5, 3))
        want = (np.array(w) - (flt.bias[kalman.B_BG:kalman.B_BG + 3] + flt.bias[kalman.B_GG:kalman.B_GG + 3])) \
            / (1.0 + flt.bias[kalman.B_SG:kalman.B_SG + 3])  # the scale factor: (w - b) / (1 + s)
        mxy, mxz, myx, myz, mzx, mzy = flt.bias[kalman.B_MG:kalman.B_MG + 6]  # then the misalignment: u - M u
        u = want.copy()
        want = np.array([u[0] - (mxy * u[1] + mxz * u[2]), u[1] - (myx * u[0] + myz * u[2]),
                         u[2] - (mzx * u[0] + mzy * u[1])])
        got = flt.body_rate(w)
        assert all(type(x) is float for x in got)
        assert np.array_equal(np.array(got), want)


@pytest.mark.parametrize("frame", ["free", "inertial"])
def test_published_row_is_the_configured_frames(frame: str) -> None:
    """The solution row comes from the configured frame's kernel: at rest with exact inputs every
    frame reports the true NED attitude and the start position. (The geographic form read from a
    free-azimuth state is off by the wander angle, Omega sin L t = 1.6e-4 rad after 3 s; from an
    inertial state it is not a position at all.)"""
    e = Engine(cfg(heading=30.0, frame=frame))
    t = align(e)
    assert e.state is State.NAVIGATING
    rows, _ = nav_rows(e, t, 300)
    r = rows[-1].row
    assert r[0] > t + 2.5
    np.testing.assert_allclose(r[7:10], ATT, rtol=0, atol=1e-7)
    np.testing.assert_allclose(r[1:3], [math.radians(LAT), math.radians(LON)], rtol=0, atol=1e-9)
    np.testing.assert_allclose(r[4:7], 0.0, atol=1e-6)


# --- the Earth's field from the model (docs/conventions.md "Magnetic field") ---------------------------
# NOAA's WMM2025 test values at 80 S, 240 E (= -120), 0 km (WMM2025testvalues.pdf): X, Y, Z (nT), D (deg)
NOAA_2025 = ((6117.5, 15751.9, -52022.5), 68.78)
NOAA_2027_5 = ((6200.7, 15730.3, -51783.7), 68.49)


@pytest.mark.parametrize("year, date_s, noaa", [(2025.0, None, NOAA_2025), (None, 1_814_529_600.0, NOAA_2027_5)])
def test_alignment_takes_the_models_declination_and_field(year, date_s, noaa):
    """No declination given: at alignment the engine takes the World Magnetic Model's declination at the
    initial position, for mag_year or else the date the vehicle gave (set_date: 2027-07-02T12:00Z =
    2027.5), and gives the filter the field's inclination atan2(Z, hypot(X, Y)) and strength (gauss:
    nT * 1e-5) for its disturbance checks: NOAA's published values within their rounding (0.005 deg,
    0.05 nT per component)."""
    (x, y, z), d = noaa
    e = Engine(cfg(lat=-80.0, lon=-120.0, alt=0.0, heading=0.0, mag_year=year, filter=FilterSettings(aiding=("mag",))))
    if date_s is not None:
        e.set_date(123.0)  # a boot clock is no date
        e.set_date(date_s)
    align(e, lat=-80.0, h=0.0)
    assert abs(e.declination - d) <= 0.005
    assert abs(e.filter.settings.declination - d) <= 0.005
    incl, strength = e.filter.settings.mag_model
    assert abs(incl - math.degrees(math.atan2(z, math.hypot(x, y)))) <= 1e-3
    assert abs(strength - math.sqrt(x * x + y * y + z * z) * 1e-5) <= 1e-6
    assert any("magnetic declination" in t and "WMM-2025" in t for t in texts(e))


def test_a_given_declination_wins_and_the_field_is_still_checked():
    """--declination 4.5: used as given (no line about the model), the model's field still gates."""
    e = Engine(cfg(heading=0.0, declination=4.5, mag_year=2025.0, filter=FilterSettings(aiding=("mag",))))
    align(e)
    assert e.declination == 4.5 and e.filter.settings.declination == 4.5
    assert e.filter.settings.mag_model is not None
    assert not any("magnetic declination" in t for t in texts(e))


# --- a dual-antenna GNSS heading (GPS_RAW_INT yaw) ---------------------------------------------------------
def test_alignment_takes_a_dual_antenna_heading_less_the_baseline_offset():
    """--heading auto with a GNSS yaw of 120 deg from a baseline mounted 90 deg to the right (FRD): the vehicle
    heads 30 deg, the source is named, and it wins over the magnetometer (the samples carry M_N, whose own
    heading is different); the filter starts with the GNSS heading's 2 deg 1-sigma."""
    e = Engine(cfg(heading="auto", gnss_yaw_offset=90.0, declination=0.0))
    e.on_gnss_yaw(None, math.radians(120.0), math.radians(0.5))
    align(e)
    assert e.heading_used == "GNSS yaw"
    row = e._row.copy()
    e._solution_row(e._s, e._kcfg, row)
    assert math.degrees(row[9]) == pytest.approx(30.0, abs=1e-9)
    assert math.sqrt(e.filter.P[2, 2]) == pytest.approx(math.radians(2.0), rel=1e-12)


def test_a_dual_antenna_heading_while_navigating_is_a_heading_update():
    """Navigating with GNSS aiding, a GNSS yaw is fused (counted gnss_yaw); without GNSS aiding, ignored."""
    e = Engine(cfg(heading=30.0, filter=FilterSettings(aiding=("gnss",))))
    align(e)
    e.on_gnss_yaw(None, math.radians(31.0), math.radians(1.0))
    assert e.filter.counters["gnss_yaw_accepted"] == 1
    e = Engine(cfg(heading=30.0))
    align(e)
    e.on_gnss_yaw(None, math.radians(31.0), math.radians(1.0))
    assert not e.filter.counters


# --- a camera's pose (ODOMETRY, VISION_POSITION_ESTIMATE) -----------------------------------------------------
def camera(yaw_deg: float, frame_deg: float = 0.0) -> np.ndarray:
    """A camera's attitude (body to its frame) for the vehicle at ATT's roll and pitch heading ``yaw_deg``, seen
    from a frame turned ``frame_deg`` from north."""
    f = math.radians(frame_deg)
    rz = np.array([[math.cos(f), -math.sin(f), 0.0], [math.sin(f), math.cos(f), 0.0], [0.0, 0.0, 1.0]])
    return rz.T @ c_bn(ATT[0], ATT[1], math.radians(yaw_deg))


@pytest.mark.parametrize("heading, aiding, mag, source", [
    ("vision", ("vision",), True, "vision"),  # asked for: over the magnetometer
    ("auto", ("vision",), False, "vision"),  # the only position aiding, nothing else knows north
    ("auto", ("vision", "baro"), False, "vision"),
    ("auto", ("vision",), True, "magnetometer"),  # a magnetometer knows north
    ("auto", ("vision", "gnss"), False, "gyrocompass"),  # with GNSS the yaw estimator's way instead (navigation gyros here)
])
def test_the_heading_from_a_cameras_attitude(heading, aiding, mag, source):
    """--heading vision, or auto when the camera is the only position aiding and no magnetometer, takes the
    camera's yaw in its frame (here the vehicle heads 30 deg, its camera frame turned -20 deg: 50 deg) with the
    filter's typed-heading 1-sigma; otherwise the others' order holds. The latest pose's attitude counts."""
    e = Engine(cfg(heading=heading, declination=math.degrees(math.atan2(M_N[1], M_N[0])),
                   filter=FilterSettings(aiding=aiding, spec="navigation")))
    e.on_vision_pose(None, (0.0, 0.0, 0.0), camera(10.0), (0.1,) * 3, (0.01,) * 3, 0)
    e.on_vision_pose(None, (0.0, 0.0, 0.0), camera(30.0, -20.0), (0.1,) * 3, (0.01,) * 3, 0)
    align(e, mag=mag, att=(ATT[0], ATT[1], math.radians(30.0)))
    assert e.heading_used == source
    if source == "vision":
        row = e._row.copy()
        e._solution_row(e._s, e._kcfg, row)
        assert math.degrees(row[9]) == pytest.approx(50.0, abs=1e-9)
        assert math.sqrt(e.filter.P[2, 2]) == pytest.approx(math.radians(e.filter.settings.sigma_yaw), rel=1e-12)


def test_the_heading_from_a_camera_never_seen_falls_back_to_gyrocompass():
    e = Engine(cfg(heading="vision", filter=FilterSettings(aiding=("vision",))))
    e.on_vision_pose(None, (0.0, 0.0, 0.0), None, (0.1,) * 3, (0.01,) * 3, 0)  # a pose without an attitude
    align(e, mag=False)
    assert e.heading_used == "gyrocompass"
    assert "WARNING no camera attitude seen: heading from gyrocompass" in texts(e)


def test_a_cameras_pose_while_navigating_places_its_frame_then_is_fused():
    """Before navigation a pose only gives a heading; navigating, the first places the camera's frame (turned
    -20 deg, found to the pose's 0.01 rad) and the next ones are fused at their time; without vision aiding
    nothing."""
    e = Engine(cfg(heading=30.0, filter=FilterSettings(aiding=("vision",))))
    e.on_vision_pose(None, (1.0, 2.0, 3.0), camera(30.0, -20.0), (0.1,) * 3, (0.01,) * 3, 0)
    assert not e.filter.counters
    t = align(e, att=(ATT[0], ATT[1], math.radians(30.0)))
    e.on_vision_pose(None, (1.0, 2.0, 3.0), camera(30.0, -20.0), (0.1,) * 3, (0.01,) * 3, 0)
    assert e.filter.counters["vision_frame_placed"] == 1 and e.filter.vision_frame == 0
    assert math.degrees(e.filter.bias[-1]) == pytest.approx(-20.0, abs=1e-6)
    e.on_vision_pose(t - DT, (1.0, 2.0, 3.0), camera(30.0, -20.0), (0.1,) * 3, (0.01,) * 3, 0)
    assert e.filter.counters["vision_pose_accepted"] == 1
    e.on_vision_pose(t + 0.5, (1.0, 2.0, 3.0), camera(30.0, -20.0), (0.1,) * 3, (0.01,) * 3, 0)  # ahead: waits
    assert e.filter.counters["vision_pose_accepted"] == 1
    e = Engine(cfg(heading=30.0, filter=FilterSettings(aiding=("gnss",))))
    align(e, att=(ATT[0], ATT[1], math.radians(30.0)))
    e.on_vision_pose(None, (1.0, 2.0, 3.0), camera(30.0, -20.0), (0.1,) * 3, (0.01,) * 3, 0)
    assert not e.filter.counters


@pytest.mark.parametrize("bias_deg_h, aiding, heading, source", [
    (1.03, ("gnss",), "auto", "GNSS velocity (pending)"),  # 5.8 deg of gyrocompass at 47.4 deg north: too coarse
    (0.80, ("gnss",), "auto", "gyrocompass"),  # 4.6 deg: good enough
    (1.03, ("baro",), "auto", "gyrocompass"),  # no GNSS to find the heading from
    (1.03, ("gnss",), "gyrocompass", "gyrocompass"),  # asked for
])
def test_coarse_gyros_leave_the_heading_to_gnss_velocity(bias_deg_h, aiding, heading, source):
    """auto without a vehicle heading, a GNSS yaw or a magnetometer: gyrocompassing when its 1-sigma (the gyro
    bias over the horizontal Earth rate at the start's latitude) is at most 5 deg, else, with GNSS aiding, the
    heading from GNSS velocity once moving (the yaw estimator); the bias is set around 5 deg: 0.93 deg/h."""
    spec = {"gyro_arw": 0.01, "gyro_bias": bias_deg_h, "accel_vrw": 0.02, "accel_bias": 0.1}
    e = Engine(cfg(heading=heading, filter=FilterSettings(aiding=aiding, spec=spec)))
    align(e, mag=False)
    assert e.heading_used == source
