"""What the mutation runs found unchecked in mavins/live/livefilter.py, the live filter's stateful shell (docs/testing.md).

LiveFilter in-process on a level vehicle in laboratory mode (earth = none: no Earth rate,
constant gravity, the position a flat NED offset from the start in metres, strapdown.position),
one sample per attitude update, a sensor model without noise (spec keys {}) unless a test is about
the model. After ``start`` a test sets P to the few states it is about, so that each update is the
scalar Kalman update worked by hand, x = P/(P + R) nu (D. Simon, *Optimal State Estimation*, 2006,
5.1), fed back as docs/filter.md "Measurements" says (estimate minus truth, corrections
subtracted); the test ratio is the largest |nu_i| / sqrt(S_ii) over the gate, squared (docs/filter.md
"Gate"). Initial 1-sigmas come from docs/filter.md "Tuning" and the textbook's ch. 4 alignment
limits (level atan(b_a / g), heading atan(b_g / (Omega cos L))). Times and thresholds are taken at
their boundaries with binary-exact values.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.live import livefilter
from mavins.live.livefilter import AIDING_KINDS, FilterSettings, LiveFilter
from mavins.core import errmodel as em
from mavins.core import kalman as kf
from mavins.core import strapdown as sd
from mavins.core.runner import initial_state
from support import mag_by_hand
from support import A, E2, OMEGA, gamma

DEG = math.pi / 180.0
LAT0, LON0, H0 = 45.0, 7.0, 100.0  # deg, deg, m
T0 = 1.0  # s: the state's start time (not 0, so that t - t0 and t + t0 differ)
CFG = sd.make_config(samples=1, earth_model="none")
G = float(gamma(LAT0 * DEG, H0))  # the laboratory mode's gravity, that of the start point
NEXT = math.inf


def radii() -> tuple[float, float]:
    """R_N + h0, (R_E + h0) cos L0 (m per rad of latitude, longitude) at the start point, WGS-84."""
    d = 1.0 - E2 * math.sin(LAT0 * DEG) ** 2
    return A * (1.0 - E2) / d**1.5 + H0, (A / math.sqrt(d) + H0) * math.cos(LAT0 * DEG)


MN, ME = radii()


def state(t=T0, v=(0.0, 0.0, 0.0)) -> np.ndarray:
    return initial_state({"t": t, "lat": LAT0, "lon": LON0, "h": H0, "vn": v[0], "ve": v[1], "vd": v[2],
                          "roll": 0.0, "pitch": 0.0, "yaw": 0.0})


def live(s, aiding=AIDING_KINDS, p=None, **kw) -> LiveFilter:
    """A started filter (noise-free model unless spec is given) with P = diag(p) (a dict index -> variance)."""
    kw.setdefault("spec", {})
    f = LiveFilter(FilterSettings(aiding=aiding, **kw))
    f.start(s, CFG, np.zeros(3), 0.01)
    if p is not None:
        f.P[:] = 0.0
        for i, var in p.items():
            f.P[i, i] = var
    return f


def fix(n=0.0, e=0.0, d=0.0) -> tuple[float, float, float]:
    """lat, lon (rad), h (m) of the point (n, e, d) m NED from the start."""
    return LAT0 * DEG + n / MN, LON0 * DEG + e / ME, H0 - d


def offset(s) -> np.ndarray:
    """The solution's NED offset from the start (m): the flat position of the laboratory mode."""
    return s[sd.S.PF:sd.S.PF + 3].copy()


def velocity(s) -> np.ndarray:
    return s[sd.S.V:sd.S.V + 3].copy()


def yaw(s) -> float:
    return math.atan2(s[sd.S.C + 3], s[sd.S.C])


def pos_var(var):
    return {em.X_DP + i: var for i in range(3)}


def vel_var(var):
    return {em.X_DV + i: var for i in range(3)}


# ============================================================== construction


def test_unknown_aiding_kind_is_refused_naming_the_kinds() -> None:
    """Each kind is checked, not only the first; the message lists AIDING_KINDS (docs/filter.md) and the bad one."""
    msg = r"^aiding kinds are gnss, baro, mag, zupt, nhc, wheel, vision \(or none\), got 'lidar'$"
    with pytest.raises(ValueError, match=msg):
        LiveFilter(FilterSettings(aiding=("lidar",)))
    with pytest.raises(ValueError, match=msg):
        LiveFilter(FilterSettings(aiding=("gnss", "baro", "lidar")))
    for ok in ((), AIDING_KINDS, ("zupt",), ("mag", "gnss")):
        assert LiveFilter(FilterSettings(aiding=ok)).settings.aiding == ok


def test_a_new_filter_holds_zeros_and_nothing_seen() -> None:
    """Before start: P 44 x 44 zero, the 35 sensor-error estimates zero, no ratios, nothing aided, no glitch, no
    resets; the spec is the settings' (60 deg/sqrt(h) = pi/180 rad/sqrt(s)); the lever arm as floats."""
    f = LiveFilter(FilterSettings(spec={"gyro_arw": 60.0}, lever_arm=(1, -2, 3)))
    assert f.P.shape == (em.NX, em.NX) == (48, 48) and not f.P.any()
    assert f.bias.shape == (kf.B_SIZE,) == (39,) and not f.bias.any()
    assert f.acc.shape == (19,) and not f.acc.any() and f.sums.shape == (7,) and not f.sums.any()
    assert f.predict_every == 1 and f.resets == 0 and f.ratios == {} and not f.counters and f.events == []
    assert f.last_pos_t == -math.inf and f.last_hgt_t == -math.inf
    assert f.glitch is False and f.gnss_seen is False and f.gnss_lost is False
    assert f.spec[em.SP_GYRO_ARW] == pytest.approx(DEG, rel=1e-15, abs=0)
    assert f.lever.dtype == np.float64 and f.lever.shape == (3,)
    np.testing.assert_array_equal(f.lever, [1.0, -2.0, 3.0])
    assert np.array_equal(LiveFilter(FilterSettings(lever_arm=[[0.5], [0.0], [-1.0]])).lever, [0.5, 0.0, -1.0])
    u = f.uncertainty(0.0, 0)
    assert not u.abs_pos and not u.abs_hgt and not u.glitch and u.resets == 0
    assert all(math.isnan(r) for r in (u.vel_ratio, u.pos_ratio, u.hgt_ratio, u.mag_ratio))


def test_body_rate_is_zero_until_the_first_attitude_update() -> None:
    """A velocity fix before any sample: the lever-arm term C (w x l) is zero (no rate seen yet), so
    with P_v = R the velocity moves half way to the fix and nothing else."""
    s = state()
    f = LiveFilter(FilterSettings(spec={}, lever_arm=(1.0, 1.0, 1.0)))
    f.P[:] = 0.0
    for i in range(3):
        f.P[em.X_DV + i, em.X_DV + i] = 0.01
    f.measure(s, CFG, T0, "gnss", *fix(), (0.4, -0.2, 0.1), 1.0, 1.0, 0.1)
    np.testing.assert_allclose(velocity(s), [0.2, -0.1, 0.05], rtol=0, atol=1e-15)


# ============================================================== start


SPEC_KEYS = {"gyro_arw": 0.3, "gyro_bias": 36.0, "gyro_bias_instability": 7.2, "gyro_bias_tau": 120.0,
             "accel_vrw": 0.06, "accel_bias": 0.02, "accel_bias_instability": 0.003, "accel_bias_tau": 240.0}
ARW = 0.3 * DEG / 60.0  # deg/sqrt(h) -> rad/sqrt(s)
B_G, GM_G = 36.0 * DEG / 3600.0, 7.2 * DEG / 3600.0  # deg/h -> rad/s
LEVEL = math.atan(0.02 / 9.8)  # rad: the accelerometer bias over g


def expected_p(pos, yaw_rad, level=LEVEL, bg_var=None) -> np.ndarray:
    """docs/filter.md "Tuning": P diagonal, position sigma_pos^2, velocity 0.1^2, level and yaw, the spec's
    turn-on and Gauss-Markov bias sigmas squared, baro offset 50^2."""
    d = np.zeros(em.NX)
    d[0:2], d[2] = level**2, yaw_rad**2
    d[3:6], d[6:9] = 0.01, pos**2
    d[9:12] = B_G**2 if bg_var is None else bg_var
    d[12:15], d[15:18], d[18:21], d[21] = 0.02**2, GM_G**2, 0.003**2, 2500.0
    return np.diag(d)


def test_start_takes_p_from_the_settings_and_the_sources() -> None:
    """Position sigma from the argument when given, else the settings' 10 m; level atan(b_a/g) (0.117 deg,
    inside [0.05, 1]); heading: a typed number -> the settings' 10 deg. Each figure to a few ulps."""
    s = state()
    f = LiveFilter(FilterSettings(spec=SPEC_KEYS))
    f.start(s, CFG, np.zeros(3), 0.01)
    np.testing.assert_allclose(f.P, expected_p(10.0, 10.0 * DEG), rtol=1e-15, atol=0)
    f.start(s, CFG, np.zeros(3), 0.01, sigma_pos=2.5)
    np.testing.assert_allclose(f.P, expected_p(2.5, 10.0 * DEG), rtol=1e-15, atol=0)
    f.start(s, CFG, np.zeros(3), 0.01, 2.5, "vehicle ATTITUDE")
    np.testing.assert_allclose(f.P, expected_p(2.5, 1.0 * DEG), rtol=1e-15, atol=0)


def test_start_gyrocompass_heading_sigma_at_the_given_latitude() -> None:
    """Gyrocompassing at 60 deg: heading 1-sigma atan(b_g / (Omega cos 60)) (textbook ch. 4): 36 deg/h over
    7.52 deg/h, 78 deg, capped at 30 deg; with 1 deg/h it is atan(1/7.52) = 7.6 deg, at the equator atan(1/15.04)."""
    s = state()
    f = LiveFilter(FilterSettings(spec=SPEC_KEYS))
    f.start(s, CFG, np.zeros(3), 0.01, None, "gyrocompass", 60.0 * DEG)
    np.testing.assert_allclose(f.P, expected_p(10.0, 30.0 * DEG), rtol=1e-15, atol=0)
    f = LiveFilter(FilterSettings(spec={**SPEC_KEYS, "gyro_bias": 1.0}))
    f.start(s, CFG, np.zeros(3), 0.01, None, "gyrocompass", 60.0 * DEG)
    want = math.atan(DEG / 3600.0 / (OMEGA * 0.5))
    assert f.P[2, 2] == pytest.approx(want**2, rel=1e-13, abs=0)
    f.start(s, CFG, np.zeros(3), 0.01, None, "gyrocompass")  # latitude not given: the equator
    assert f.P[2, 2] == pytest.approx(math.atan(DEG / 3600.0 / OMEGA) ** 2, rel=1e-13, abs=0)


@pytest.mark.parametrize("window,source,yaw_deg", [(0.5, "--heading", 10.0), (30.0, "vehicle ATTITUDE", 1.0)])
def test_start_after_a_zero_rate_calibration(window, source, yaw_deg) -> None:
    """bias_window_s > 0 (docs/filter.md "Tuning"): the gyro-bias 1-sigma is ARW/sqrt(T) combined with the Earth
    rate seen through the heading error, var = ARW^2/T + (Omega sigma_yaw)^2, on each axis, with no
    correlation; everything else as without the window. Windows below and above 1 s."""
    s = state()
    f = LiveFilter(FilterSettings(spec=SPEC_KEYS))
    f.start(s, CFG, np.zeros(3), 0.01, None, source, 0.0, bias_window_s=window)
    var = ARW**2 / window + (OMEGA * yaw_deg * DEG) ** 2
    np.testing.assert_allclose(f.P, expected_p(10.0, yaw_deg * DEG, bg_var=var), rtol=1e-15, atol=0)


def test_start_sets_the_bias_and_clears_the_sums() -> None:
    """The gyro bias of the rest window goes to the constant part; every other estimate (Gauss-Markov, accelerometer,
    baro offset) and the propagation accumulators restart at zero; the interval sums at the state's time."""
    s = state()
    f = live(s)
    f.bias[:] = 1.0
    f.acc[:] = 1.0
    f.sums[:] = 1.0
    f.start(s, CFG, np.array([1e-3, -2e-3, 4e-3]), 0.01)
    np.testing.assert_array_equal(f.bias, [1e-3, -2e-3, 4e-3] + [0.0] * (kf.B_SIZE - 3))
    np.testing.assert_array_equal(f.gyro_bias, [1e-3, -2e-3, 4e-3])
    np.testing.assert_array_equal(f.accel_bias, 0.0)
    assert not f.acc.any()
    np.testing.assert_array_equal(f.sums, [0.0] * 6 + [T0])


@pytest.mark.parametrize("predict_dt,dt,samples,every", [
    (0.01, 0.001, 2, 5),  # 0.01 / (0.001 * 2)
    (0.01, 0.0015, 1, 7),  # 6.67 rounds to 7
    (0.01, 0.02, 1, 1),  # 0.5 rounds to 0: at least 1
    (0.01, 0.03, 2, 1),
    (0.04, 0.01, 2, 2),
    (0.01, 0.0, 1, 10000),  # no sample interval: floored at 1 us
])
def test_start_predict_every(predict_dt, dt, samples, every) -> None:
    """P is propagated every round(predict_dt / (dt N)) attitude updates, at least every one (docs/filter.md:
    about every predict_dt); N samples per update from the strapdown configuration."""
    s = state()
    f = LiveFilter(FilterSettings(spec={}, predict_dt=predict_dt))
    f.start(s, sd.make_config(samples=samples, earth_model="none"), np.zeros(3), dt)
    assert f.predict_every == every


def test_restart_forgets_pending_ratios_fixes_and_glitch() -> None:
    """A restart (new alignment): measurements waiting for their time are dropped, ratios are NaN again,
    position and height no longer absolute, no glitch."""
    s = state()
    f = live(s, p={**pos_var(4.0), **vel_var(0.01)})
    f.measure(s, CFG, T0, "gnss", *fix(3.0), (0.1, 0.0, 0.0), 2.0, 2.0, 0.1)
    f.measure(s, CFG, T0, "gnss", *fix(500.0), None, 1.0, 1.0, 0.1)  # rejected: glitch
    f.measure(s, CFG, T0 + 0.01, "zupt")
    u = f.uncertainty(T0, 0)
    assert u.glitch and u.abs_pos and u.abs_hgt and not math.isnan(u.pos_ratio + u.vel_ratio + u.hgt_ratio)
    f.start(s, CFG, np.zeros(3), 0.01)
    u = f.uncertainty(T0, 0)
    assert u.glitch is False and not u.abs_pos and not u.abs_hgt
    assert all(math.isnan(r) for r in (u.vel_ratio, u.pos_ratio, u.hgt_ratio, u.mag_ratio))
    f.push(s, CFG, T0 + 0.01, (0.0, 0.0, 0.0), (0.0, 0.0, -G))
    assert f.counters["zupt_accepted"] + f.counters["zupt_rejected"] == 0


# ============================================================== initial sigmas


@pytest.mark.parametrize("accel_bias,level_setting,want", [
    (9.8 * math.tan(0.3 * DEG), 1.0, 0.3),  # the limit itself
    (9.8 * math.tan(0.3 * DEG), 0.2, 0.2),  # the settings' value is the most
    (9.8 * math.tan(0.3 * DEG), 0.06, 0.06),
    (9.8 * math.tan(0.01 * DEG), 1.0, 0.05),  # never below 0.05 deg
    (0.0, 1.0, 0.05),
    (9.8 * math.tan(2.0 * DEG), 1.0, 1.0),
])
def test_level_sigma(accel_bias, level_setting, want) -> None:
    """Level 1-sigma (deg): atan(b_a / g) with g = 9.8 (textbook ch. 4), within [0.05, sigma_level]."""
    f = LiveFilter(FilterSettings(spec={"accel_bias": accel_bias}, sigma_level=level_setting))
    assert f.level_sigma_deg() == pytest.approx(want, rel=1e-14, abs=0)


@pytest.mark.parametrize("source,setting,want", [
    ("vehicle ATTITUDE", 10.0, 1.0), ("vehicle ATTITUDE", 0.5, 0.5),
    ("magnetometer", 10.0, 5.0), ("magnetometer", 3.0, 3.0),
    ("--heading", 10.0, 10.0), ("--heading", 0.25, 0.25), ("something else", 7.0, 7.0),
])
def test_yaw_sigma_by_source(source, setting, want) -> None:
    """docs/filter.md "Tuning": the vehicle's ATTITUDE 1 deg, the magnetometer 5 deg, a typed number the
    settings' value; a source better than the settings' value never loosens it."""
    f = LiveFilter(FilterSettings(spec={"gyro_bias": 1.0}, sigma_yaw=setting))
    assert f.yaw_sigma_deg(source, 0.0) == want


@pytest.mark.parametrize("gyro_bias_rad,lat_deg,want", [
    (OMEGA * math.cos(60.0 * DEG) * math.tan(7.0 * DEG), 60.0, 7.0),
    (OMEGA * math.cos(60.0 * DEG) * math.tan(7.0 * DEG), -60.0, 7.0),
    (OMEGA * math.tan(12.0 * DEG), 0.0, 12.0),
    (OMEGA * math.tan(40.0 * DEG), 0.0, 30.0),  # at most 30 deg
    (OMEGA * math.tan(0.01 * DEG), 0.0, 0.05),  # at least 0.05 deg
    (0.0, 0.0, 0.05),
    (OMEGA * 1e-3 * math.tan(10.0 * DEG), 90.0, 10.0),  # the pole: cos L floored at 1e-3
    (OMEGA * 1e-3 * math.tan(10.0 * DEG), 89.99 + 0.0099, 10.0),  # cos L = 1.7e-6, floored too
])
def test_yaw_sigma_gyrocompass(gyro_bias_rad, lat_deg, want) -> None:
    """Gyrocompassing: atan(b_g / (Omega max(cos L, 1e-3))) (textbook ch. 4), within [0.05, 30] deg, whatever the
    settings' value (here 10 deg)."""
    f = LiveFilter(FilterSettings(spec={"gyro_bias": gyro_bias_rad / DEG * 3600.0}))
    assert f.yaw_sigma_deg("gyrocompass", lat_deg * DEG) == pytest.approx(want, rel=1e-12, abs=0)


# ============================================================== push


def still(f, s, t, w=(0.0, 0.0, 0.0)) -> int:
    return f.push(s, CFG, t, w, (0.0, 0.0, -G))


def test_pending_measurements_wait_for_the_update_that_passes_them() -> None:
    """Two samples per update (updates at t0 + 0.02, t0 + 0.04): a ZUPT stamped exactly at the first update is
    applied there (at or before, docs/filter.md "Time alignment"), once; a baro between the updates at the second.
    push returns 1 only when an attitude update completed."""
    s = state()
    cfg2 = sd.make_config(samples=2, earth_model="none")
    f = LiveFilter(FilterSettings(spec={}, aiding=AIDING_KINDS))
    f.start(s, cfg2, np.zeros(3), 0.01)
    f.measure(s, cfg2, 1.03, "baro", H0, 1.0)
    f.measure(s, cfg2, 1.02, "zupt")

    def n(kind):
        return f.counters[f"{kind}_accepted"] + f.counters[f"{kind}_rejected"]

    assert f.push(s, cfg2, 1.01, (0.0, 0.0, 0.0), (0.0, 0.0, -G)) == 0 and (n("zupt"), n("baro")) == (0, 0)
    assert f.push(s, cfg2, 1.02, (0.0, 0.0, 0.0), (0.0, 0.0, -G)) == 1 and (n("zupt"), n("baro")) == (1, 0)
    assert f.push(s, cfg2, 1.03, (0.0, 0.0, 0.0), (0.0, 0.0, -G)) == 0 and (n("zupt"), n("baro")) == (1, 0)
    assert f.push(s, cfg2, 1.04, (0.0, 0.0, 0.0), (0.0, 0.0, -G)) == 1 and (n("zupt"), n("baro")) == (1, 1)
    assert f.push(s, cfg2, 1.05, (0.0, 0.0, 0.0), (0.0, 0.0, -G)) == 0
    assert f.push(s, cfg2, 1.06, (0.0, 0.0, 0.0), (0.0, 0.0, -G)) == 1 and (n("zupt"), n("baro")) == (1, 1)


@pytest.mark.parametrize("t0,started", [(T0, True), (-1.0, True), (0.0, False)])
def test_lever_arm_rate_is_the_last_updates_bias_corrected_rate(t0, started) -> None:
    """Yaw rate 0.1 rad/s raw, gyro bias 0.02 from the rest window (none when the filter was never started): the
    lever-arm velocity of the antenna at l = (1, 0, 0) is C (w x l) with w = 0.08 (0.1) rad/s (docs/filter.md;
    kalman.gnss_velocity), C the yaw of one update, w * 0.01 rad. A velocity fix of zero with P_v = R:
    v <- v - (v + C (w x l)) / 2. Sensor times on either side of zero."""
    s = state(t=t0)
    f = LiveFilter(FilterSettings(spec={}, lever_arm=(1.0, 0.0, 0.0)))
    if started:
        f.start(s, CFG, np.array([0.0, 0.0, 0.02]), 0.01)
    assert still(f, s, t0 + 0.01, (0.0, 0.0, 0.1)) == 1
    f.P[:] = 0.0
    for i in range(3):
        f.P[em.X_DV + i, em.X_DV + i] = 0.01
    v0 = velocity(s)
    w = 0.08 if started else 0.1
    psi = w * 0.01
    assert yaw(s) == pytest.approx(psi, rel=1e-12)
    cwl = w * np.array([-math.sin(psi), math.cos(psi), 0.0])
    f.measure(s, CFG, t0 + 0.01, "gnss", *fix(), (0.0, 0.0, 0.0), 1.0, 1.0, 0.1)
    np.testing.assert_allclose(velocity(s), v0 - (v0 + cwl) / 2, rtol=0, atol=1e-14)
    assert f.counters["gnss_vel_accepted"] == 1


def test_push_feeds_each_axis_of_the_sample() -> None:
    """One 0.01 s update from level at rest, laboratory mode: a constant rate w turns C_b^n into exp([w dt x])
    (Rodrigues); a constant specific force f gives v = (f + [0, 0, g]) dt (no Earth or transport rate)."""
    s = state()
    f = live(s)
    w = np.array([0.01, -0.02, 0.03])
    assert f.push(s, CFG, T0 + 0.01, tuple(w), (0.0, 0.0, -G)) == 1
    r = w * 0.01
    t = np.linalg.norm(r)
    k = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    c = np.eye(3) + math.sin(t) / t * k + (1.0 - math.cos(t)) / t**2 * (k @ k)
    np.testing.assert_allclose(s[sd.S.C:sd.S.C + 9].reshape(3, 3), c, rtol=0, atol=1e-15)
    s = state()
    f = live(s)
    assert f.push(s, CFG, T0 + 0.01, (0.0, 0.0, 0.0), (0.5, -0.25, -G + 0.125)) == 1
    np.testing.assert_allclose(velocity(s), [0.005, -0.0025, 0.00125], rtol=0, atol=1e-15)


@pytest.mark.parametrize("started", [True, False])
def test_push_moves_the_position_in_the_geographic_frame(started) -> None:
    """WGS-84 Earth, 10 m/s north and 5 m/s east at 45 deg: one 0.01 s update moves the position by v T, 0.1 m north
    and 0.05 m east ((R_N + h) dL, (R_E + h) cos L dlambda). Coriolis and the transport rate change v by less than
    2e-5 m/s in that time, so the move is right to 1e-6 m. The same whether or not the filter was started."""
    cfg = sd.make_config(samples=1)
    s = state(v=(10.0, 5.0, 0.0))
    f = LiveFilter(FilterSettings(spec={}))
    if started:
        f.start(s, cfg, np.zeros(3), 0.01)
    assert f.push(s, cfg, T0 + 0.01, (0.0, 0.0, 0.0), (0.0, 0.0, -G)) == 1
    lat = s[sd.S.LATC]
    d = 1.0 - E2 * math.sin(LAT0 * DEG) ** 2
    r_n, r_e = A * (1.0 - E2) / d**1.5, A / math.sqrt(d)
    north = (lat - LAT0 * DEG) * (r_n + H0)
    east = (s[sd.S.LONC] - LON0 * DEG) * (r_e + H0) * math.cos(LAT0 * DEG)
    assert north == pytest.approx(0.1, abs=1e-6) and east == pytest.approx(0.05, abs=1e-6)


def test_covariance_is_flushed_before_a_measurement_and_propagated_every_n_updates() -> None:
    """Gyro ARW 0.01 rad/sqrt(s) only, propagation every 2 updates (predict_dt 0.02, 0.01 s samples): in the
    laboratory mode the attitude variance grows by ARW^2 T exactly (Qd = (Phi Qc Phi^T + Qc) T / 2 with the
    attitude rows of Phi the identity). After one update nothing yet; a measurement first propagates the 0.01 s
    that waited, and a rejected one leaves P and the waiting interval as they were; then every second update
    propagates 0.02 s."""
    arw_key = 0.01 / DEG * 60.0  # 0.01 rad/sqrt(s) in deg/sqrt(h)
    s = state()
    f = LiveFilter(FilterSettings(spec={"gyro_arw": arw_key}, predict_dt=0.02))
    f.start(s, CFG, np.zeros(3), 0.01)
    assert f.predict_every == 2
    f.P[:] = 0.0
    q = f.spec[em.SP_GYRO_ARW] ** 2
    assert q == pytest.approx(1e-4, rel=1e-15)
    still(f, s, 1.01)
    assert not f.P.any()
    f.measure(s, CFG, 1.01, "baro", H0 + 100.0, 1.0)  # 100 sigma: rejected, no trace
    assert not f.P.any() and f.acc[12] == pytest.approx(0.01, rel=1e-12)
    f.measure(s, CFG, 1.01, "baro", H0 - 0.5, 1.0)  # accepted: the 0.01 s that waited propagated first
    np.testing.assert_allclose(np.diag(f.P)[0:3], q * 0.01, rtol=1e-12, atol=0)
    assert not f.acc.any()
    still(f, s, 1.02)
    np.testing.assert_allclose(np.diag(f.P)[0:3], q * 0.02, rtol=1e-12, atol=0)  # the second update: 0.01 s more
    still(f, s, 1.03)
    np.testing.assert_allclose(np.diag(f.P)[0:3], q * 0.02, rtol=1e-12, atol=0)
    still(f, s, 1.04)
    np.testing.assert_allclose(np.diag(f.P)[0:3], q * 0.04, rtol=1e-12, atol=0)


def test_bias_estimates_are_the_sums_of_their_parts() -> None:
    """gyro_bias = constant + Gauss-Markov part, accel_bias likewise (errmodel.py), and body_rate is the raw rate
    minus the gyro's: binary-exact values."""
    f = LiveFilter(FilterSettings(spec={}))
    f.bias[:] = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 0.5, 0.25, 0.125, 64.0, 128.0, 256.0, 1024.0] + [0.0] * (kf.B_SIZE - 13)
    np.testing.assert_array_equal(f.gyro_bias, [1.5, 2.25, 4.125])
    np.testing.assert_array_equal(f.accel_bias, [72.0, 144.0, 288.0])
    assert f.body_rate((3.0, -1.0, 8.0)) == (1.5, -3.25, 3.875)


# ============================================================== measure


def test_measurement_at_the_state_time_is_applied_now_and_later_ones_wait() -> None:
    """t_m equal to the last update's time is applied at once; the next float after it waits."""
    s = state()
    f = live(s)
    f.measure(s, CFG, T0, "zupt")
    assert f.counters["zupt_accepted"] == 1
    f.measure(s, CFG, math.nextafter(T0, NEXT), "zupt")
    assert f.counters["zupt_accepted"] == 1
    still(f, s, T0 + 0.01)
    assert f.counters["zupt_accepted"] == 2


def test_kinds_not_aided_are_ignored() -> None:
    """A kind left out of --aiding changes nothing, now or later: no counter, no ratio, the state and P kept."""
    s = state(v=(0.5, 0.0, 0.0))
    f = live(s, aiding=("baro",), p={**vel_var(1.0), **pos_var(1.0)})
    p0 = f.P.copy()
    f.measure(s, CFG, T0, "zupt")
    f.measure(s, CFG, T0, "gnss", *fix(3.0), (0.0, 0.0, 0.0), 1.0, 1.0, 0.1)
    f.measure(s, CFG, T0, "mag", (1.0, 0.5, 0.0))
    f.measure(s, CFG, T0 + 0.005, "zupt")
    np.testing.assert_array_equal(f.P, p0)
    np.testing.assert_array_equal(offset(s), 0.0)
    still(f, s, T0 + 0.01)
    assert not f.counters and f.ratios == {}
    assert velocity(s)[0] == pytest.approx(0.5, abs=1e-12)
    f.measure(s, CFG, T0 + 0.01, "baro", H0, 1.0)
    assert f.counters["baro_accepted"] == 1


def test_at_most_64_measurements_wait() -> None:
    """Measurements stamped ahead beyond the 64th are dropped and counted as {kind}_dropped_pending; the 64 that
    waited are all applied when their time has passed."""
    s = state()
    f = live(s)
    for _ in range(63):
        f.measure(s, CFG, T0 + 0.005, "baro", H0, 1.0)
    f.measure(s, CFG, T0 + 0.005, "zupt")
    assert not f.counters
    f.measure(s, CFG, T0 + 0.005, "zupt")
    f.measure(s, CFG, T0 + 0.005, "baro", H0, 1.0)
    f.measure(s, CFG, T0 + 0.005, "zupt")
    assert f.counters == {"zupt_dropped_pending": 2, "baro_dropped_pending": 1}
    still(f, s, T0 + 0.01)
    assert f.counters["baro_accepted"] == 63 and f.counters["zupt_accepted"] == 1


# ============================================================== the updates


def test_gnss_position_by_hand() -> None:
    """P = 4 m^2 per axis, R = 4: a fix 3 m N, 1.6 m W, 1.5 m up moves the solution half way (P to 2); accepted,
    absolute position and height, gnss_seen; both ratios (3/sqrt(8)/5)^2; a 1.7 m horizontal correction is a reset."""
    s = state()
    f = live(s, p=pos_var(4.0))
    f.measure(s, CFG, T0, "gnss", *fix(3.0, -1.6, -1.5), None, 2.0, 2.0, 0.3)
    np.testing.assert_allclose(offset(s), [1.5, -0.8, -0.75], rtol=0, atol=1e-8)
    assert f.counters == {"gnss_pos_accepted": 1}
    assert f.ratios == pytest.approx({"pos": 9.0 / 8.0 / 25.0, "hgt": 9.0 / 8.0 / 25.0}, rel=1e-8)
    assert f.gnss_seen and not f.glitch and f.resets == 1  # a 1.7 m correction
    np.testing.assert_allclose(np.diag(f.P)[6:9], 2.0, rtol=1e-15)
    u = f.uncertainty(T0, 0)
    assert u.abs_pos and u.abs_hgt and not u.glitch and u.resets == 1 and math.isnan(u.vel_ratio)


def test_gnss_antenna_lever_arm() -> None:
    """The antenna at l = (2, -1, 0.5) m FRD, level and yaw 0: a fix at p + l agrees with the solution (nu = 0,
    ratio 0, no move); without the lever arm it would be 2 m off."""
    s = state()
    f = live(s, p=pos_var(4.0), lever_arm=(2.0, -1.0, 0.5))
    f.measure(s, CFG, T0, "gnss", *fix(2.0, -1.0, 0.5), None, 2.0, 2.0, 0.3)
    np.testing.assert_allclose(offset(s), 0.0, rtol=0, atol=1e-8)
    assert f.ratios["pos"] < 1e-18 and f.resets == 0


def test_late_gnss_fix_is_taken_back_along_the_velocity() -> None:
    """The solution at t0 moving 2 m/s north; a fix stamped 0.25 s earlier at -1.5 m N: the solution then was at
    p - v (t_k - t_m) = -0.5 m (docs/filter.md "Time alignment"), so nu = 1 m, half of it corrected (P = R = 4),
    ratio (1/sqrt(8)/5)^2. No reset (0.5 m). Position is absolute until 5 s after t_m, not t_k."""
    s = state(v=(2.0, 0.0, 0.0))
    f = live(s, p=pos_var(4.0))
    f.measure(s, CFG, T0 - 0.25, "gnss", *fix(-1.5), None, 2.0, 2.0, 0.3)
    np.testing.assert_allclose(offset(s), [-0.5, 0.0, 0.0], rtol=0, atol=1e-8)
    assert f.ratios["pos"] == pytest.approx(1.0 / 8.0 / 25.0, rel=1e-8) and f.resets == 0
    assert f.uncertainty(T0 - 0.25 + 5.0, 0).abs_pos
    assert not f.uncertainty(math.nextafter(T0 - 0.25 + 5.0, NEXT), 0).abs_pos


def test_gnss_delay_fuses_a_fix_at_its_stamp_minus_the_delay() -> None:
    """--gnss-delay 250: the same fix as above (-1.5 m N, taken 0.25 s before t0) stamped t0, the time it arrived:
    it is taken back along the velocity over the delay exactly as a fix stamped t0 - 0.25, so the solution moves
    to -0.5 m N (half of nu = 1 m; docs/conventions.md "Sensor delays"). Without the delay, the fix stamped t0
    reads as 1.5 m behind the solution: -0.75 m. The delay of one kind leaves the others alone."""
    s = state(v=(2.0, 0.0, 0.0))
    f = live(s, p=pos_var(4.0), delays={"gnss": 0.25})
    f.measure(s, CFG, T0, "gnss", *fix(-1.5), None, 2.0, 2.0, 0.3)
    np.testing.assert_allclose(offset(s), [-0.5, 0.0, 0.0], rtol=0, atol=1e-8)
    assert f.uncertainty(T0 - 0.25 + 5.0, 0).abs_pos and not f.uncertainty(T0 + 5.0, 0).abs_pos
    s = state(v=(2.0, 0.0, 0.0))
    f = live(s, p=pos_var(4.0))
    f.measure(s, CFG, T0, "gnss", *fix(-1.5), None, 2.0, 2.0, 0.3)
    np.testing.assert_allclose(offset(s), [-0.75, 0.0, 0.0], rtol=0, atol=1e-8)


@pytest.mark.parametrize("kind", ["baro", "mag"])
def test_baro_and_magnetometer_delays_shift_only_their_own_kind(kind: str) -> None:
    """--baro-delay / --mag-delay 500: a measurement stamped t0 + 0.5 is applied now (measured at t0), one of the
    other kind stamped t0 + 0.5 waits for the update that passes t0 + 0.5."""
    other = "mag" if kind == "baro" else "baro"
    args = {"baro": (H0, 0.5), "mag": ((0.2, 0.0, 0.4),)}
    s = state()
    f = live(s, delays={kind: 0.5})
    f.measure(s, CFG, T0 + 0.5, kind, *args[kind])
    assert f.counters[f"{kind}_accepted"] + f.counters[f"{kind}_rejected"] == 1 and not f._pending
    f.measure(s, CFG, T0 + 0.5, other, *args[other])
    assert [p[:2] for p in f._pending] == [(T0 + 0.5, other)]


def test_resets_count_horizontal_corrections_above_one_metre() -> None:
    """JUMP_M = 1 m: corrections of 0.9 m (north) and of 2 m down are not discontinuities, 1.1 m east is
    (gain 1/2: fixes 1.8 m, 4 m, 2.2 m off), then 1.5 m north is another."""
    s = state()
    f = live(s, p=pos_var(4.0))
    f.measure(s, CFG, T0, "gnss", *fix(1.8), None, 2.0, 2.0, 0.3)
    f.P[:] = np.diag([0.0] * 6 + [4.0] * 3 + [0.0] * (em.NX - 9))
    f.measure(s, CFG, T0, "gnss", *fix(0.9, 0.0, 4.0), None, 2.0, 2.0, 0.3)
    assert f.resets == 0
    np.testing.assert_allclose(offset(s), [0.9, 0.0, 2.0], rtol=0, atol=1e-8)
    f.P[:] = np.diag([0.0] * 6 + [4.0] * 3 + [0.0] * (em.NX - 9))
    f.measure(s, CFG, T0, "gnss", *fix(0.9, 2.2, 2.0), None, 2.0, 2.0, 0.3)
    assert f.resets == 1
    f.P[:] = np.diag([0.0] * 6 + [4.0] * 3 + [0.0] * (em.NX - 9))
    f.measure(s, CFG, T0, "gnss", *fix(3.9, 1.1, 2.0), None, 2.0, 2.0, 0.3)  # 1.5 m north
    assert f.resets == 2
    assert f.uncertainty(T0, 2).resets == 4


def test_rejected_gnss_is_a_glitch_with_its_velocity_and_heading() -> None:
    """A fix 40 m off with S = 4 + 4 is 14 sigma (gate 5): rejected, counted, position unchanged, glitch, not
    absolute, GNSS not seen; its velocity (which alone would pass) and its dual-antenna heading are rejected
    with it, and P is as before (a rejected measurement leaves no trace). The next accepted fix clears the
    glitch."""
    s = state()
    f = live(s, p={**pos_var(4.0), **vel_var(0.01)})
    P0 = f.P.copy()
    f.measure(s, CFG, T0, "gnss", *fix(40.0), (0.2, 0.0, -0.1), 2.0, 2.0, 0.1)
    f.measure(s, CFG, T0, "gnss_yaw", 0.01, 0.1)
    np.testing.assert_allclose(offset(s), 0.0, atol=1e-12)
    np.testing.assert_array_equal(velocity(s), 0.0)
    np.testing.assert_array_equal(f.P, P0)
    assert f.counters == {"gnss_pos_rejected": 1, "gnss_vel_rejected": 1, "gnss_yaw_rejected": 1}
    assert f.ratios["pos"] == pytest.approx(1600.0 / 8.0 / 25.0, rel=1e-8) == f.ratios["hgt"]
    assert "vel" not in f.ratios
    assert f.glitch and not f.gnss_seen
    u = f.uncertainty(T0, 0)
    assert u.glitch and not u.abs_pos and not u.abs_hgt
    f.tick(T0 + 100.0)  # never seen: never lost
    assert not f.gnss_lost and not f.events
    f.measure(s, CFG, T0, "gnss", *fix(0.0), None, 2.0, 2.0, 0.1)
    assert not f.glitch and f.counters["gnss_pos_accepted"] == 1 and f.gnss_seen


def test_late_gnss_velocity_is_interpolated_over_the_last_attitude_interval() -> None:
    """kalman.gnss_velocity: v(t_m) is interpolated between the last two updates over the last attitude interval T.
    2 m/s^2 north from rest, updates at t0 + 0.01 and t0 + 0.02 (v 0.02, 0.04 m/s); a fix stamped half way back
    (t0 + 0.015) reporting the true 0.03 m/s agrees with v(t_m) = 0.04 - (0.005/0.01)(0.04 - 0.02): nu = 0, no
    correction."""
    s = state()
    f = live(s)
    for t in (T0 + 0.01, T0 + 0.02):
        assert f.push(s, CFG, t, (0.0, 0.0, 0.0), (2.0, 0.0, -G)) == 1
    np.testing.assert_allclose(velocity(s), [0.04, 0.0, 0.0], rtol=0, atol=1e-12)
    f.P[:] = np.diag([0.0] * 3 + [0.01] * 3 + [0.0] * (em.NX - 6))
    f.measure(s, CFG, T0 + 0.015, "gnss", *fix(), (0.03, 0.0, 0.0), 100.0, 100.0, 0.1)
    np.testing.assert_allclose(velocity(s), [0.04, 0.0, 0.0], rtol=0, atol=1e-9)


def test_a_late_velocity_fix_before_the_first_update_is_compared_with_the_current_velocity() -> None:
    """Right after start there is no attitude interval to interpolate over: a velocity fix stamped 5 ms back is
    compared with the current velocity. State v = 1 m/s north, previous-update velocity 0: a fix of 1 m/s gives
    nu = 0 (no correction); interpolating over any interval (e.g. 1 s: 1 - 0.005 (1 - 0) = 0.995, corrected half
    way with P = R) would not. The position fix is put where the solution was 5 ms back, so it corrects nothing."""
    s = state(v=(1.0, 0.0, 0.0))
    s[sd.S.VP:sd.S.VP + 3] = 0.0
    f = live(s, p=vel_var(0.01))
    f.measure(s, CFG, T0 - 0.005, "gnss", *fix(n=-0.005), (1.0, 0.0, 0.0), 100.0, 100.0, 0.1)  # p(t_m) = -v 5 ms
    assert f.counters["gnss_vel_accepted"] == 1
    np.testing.assert_allclose(velocity(s), [1.0, 0.0, 0.0], rtol=0, atol=1e-12)  # the 1 s interval: 0.9975


def test_ground_speed_fix_corrects_north_and_east_only() -> None:
    """A fix of (0.2, -0.4, NaN) m/s (GPS_RAW_INT: ground speed and course, nothing vertical) with
    P_v = R = 0.01 on every axis, the solution at rest with vd = 0.1 m/s: north and east move half way
    (0.1, -0.2: x = P/(P + R) nu), the vertical velocity and its variance are untouched (a 3-row
    update with any finite vertical would change both), the variance of north and east halves."""
    s = state(v=(0.0, 0.0, 0.1))
    f = live(s, p=vel_var(0.01))
    f.measure(s, CFG, T0, "gnss", *fix(), (0.2, -0.4, math.nan), 100.0, 100.0, 0.1)
    assert f.counters["gnss_vel_accepted"] == 1
    np.testing.assert_allclose(velocity(s), [0.1, -0.2, 0.1], rtol=0, atol=1e-12)
    vd = em.X_DV + 2
    assert f.P[vd, vd] == 0.01
    np.testing.assert_allclose(np.diag(f.P)[em.X_DV:em.X_DV + 2], 0.005, rtol=1e-12)
    # the ratio: the larger normalised north/east innovation, |0.4| / sqrt(0.02), over the gate 5, squared
    assert f.ratios["vel"] == pytest.approx(0.16 / 0.02 / 25.0, rel=1e-12)


def test_horizontal_rows_are_the_north_and_east_rows_of_a_velocity_model() -> None:
    """kalman.horizontal_rows keeps rows 0 and 1 of nu and H and the top-left 2x2 of R, as new
    C-contiguous arrays (the compiled update takes those)."""
    nu = np.array([1.0, 2.0, 3.0])
    H = np.arange(3.0 * em.NX).reshape(3, em.NX)
    R = np.array([[4.0, 0.5, 0.25], [0.5, 5.0, 0.125], [0.25, 0.125, 6.0]])
    n2, H2, R2 = kf.horizontal_rows(nu, H, R)
    assert n2.tolist() == [1.0, 2.0]
    np.testing.assert_array_equal(H2, H[:2])
    assert R2.tolist() == [[4.0, 0.5], [0.5, 5.0]]
    assert n2.flags.c_contiguous and H2.flags.c_contiguous and R2.flags.c_contiguous
    nu[0] = H[0, 0] = R[0, 0] = -1.0  # copies, not views
    assert n2[0] == 1.0 and H2[0, 0] == 0.0 and R2[0, 0] == 4.0


def test_gnss_velocity_rejected_is_counted() -> None:
    """A velocity fix 1 m/s off with S = 0.01 + 0.01 (7 sigma) is rejected: gnss_vel_rejected, velocity kept."""
    s = state()
    f = live(s, p=vel_var(0.01))
    f.measure(s, CFG, T0, "gnss", *fix(), (1.0, 0.0, 0.0), 100.0, 100.0, 0.1)
    assert f.counters["gnss_vel_rejected"] == 1 and f.counters["gnss_vel_accepted"] == 0
    assert f.ratios["vel"] == pytest.approx(1.0 / 0.02 / 25.0, rel=1e-12)
    np.testing.assert_array_equal(velocity(s), 0.0)


def test_gnss_lost_and_recovered() -> None:
    """GNSS_LOST_S = 3 s after the last accepted fix (at t0 - 0.25): at exactly 3 s not yet lost; just after, lost
    once (counter, WARNING); a later tick adds nothing; an accepted fix recovers (INFO), a rejected one does not."""
    s = state()
    f = live(s, p=pos_var(4.0))
    f.measure(s, CFG, T0 - 0.25, "gnss", *fix(), None, 2.0, 2.0, 0.3)
    f.tick(T0 - 0.25 + 3.0)
    assert not f.gnss_lost and not f.events and not f.counters["gnss_lost"]
    f.tick(math.nextafter(T0 - 0.25 + 3.0, NEXT))
    lost = ("WARNING", "GNSS lost: no accepted fix for 3 s, free inertial")
    assert f.gnss_lost and f.events == [lost] and f.counters["gnss_lost"] == 1
    f.tick(T0 + 10.0)
    assert f.events == [lost] and f.counters["gnss_lost"] == 1
    f.measure(s, CFG, T0, "gnss", *fix(400.0), None, 2.0, 2.0, 0.3)  # rejected
    assert f.gnss_lost and f.events == [lost]
    f.measure(s, CFG, T0, "gnss", *fix(), None, 2.0, 2.0, 0.3)
    assert f.gnss_lost is False and f.events == [lost, ("INFO", "GNSS recovered: position aided again")]
    f.tick(T0 + 3.0)
    assert not f.gnss_lost
    f.tick(T0 + 3.5)
    assert f.gnss_lost and f.counters["gnss_lost"] == 2 and len(f.events) == 3


def test_baro_by_hand() -> None:
    """P_dpD = 1, P_offset = 1, R = sigma^2 = 2: S = 4. The solution 0.5 m/s down, the height stamped 0.25 s before
    it: predicted h + v_D dt + offset (docs/filter.md), 4 m below the measured: h up by 1 m, the offset by 1 m;
    ratio (4/2/5)^2; absolute height (not position) until 5 s after t_m."""
    s = state(v=(0.0, 0.0, 0.5))
    f = live(s, p={em.X_DP + 2: 1.0, em.X_BARO: 1.0})
    t_m = T0 - 0.25
    f.measure(s, CFG, t_m, "baro", H0 + 0.5 * 0.25 + 4.0, math.sqrt(2.0))
    assert f.counters == {"baro_accepted": 1}
    assert offset(s)[2] == pytest.approx(-1.0, abs=1e-12)
    assert f.bias[kf.B_BARO] == pytest.approx(1.0, abs=1e-12)
    assert f.ratios == pytest.approx({"hgt": 0.16}, rel=1e-12)
    u = f.uncertainty(t_m + 5.0, 0)
    assert u.abs_hgt and not u.abs_pos and u.hgt_ratio == pytest.approx(0.16, rel=1e-12)
    assert math.isnan(u.pos_ratio) and math.isnan(u.vel_ratio) and math.isnan(u.mag_ratio)
    assert not f.uncertainty(math.nextafter(t_m + 5.0, NEXT), 0).abs_hgt
    f.measure(s, CFG, T0, "baro", H0 + 100.0, 0.5)  # 50 sigma: rejected, height time kept
    assert f.counters["baro_rejected"] == 1 and f.uncertainty(t_m + 5.0, 0).abs_hgt
    assert not f.uncertainty(math.nextafter(t_m + 5.0, NEXT), 0).abs_hgt


def test_magnetometer_heading_by_hand() -> None:
    """Level, yaw estimate 0, declination 3 deg east, a horizontal field 7 deg east of the body's x axis: the true
    yaw is -4 deg; P_yaw = R = (2 deg)^2 moves the yaw half way, to -2 deg. Every state correlated with the
    heading is corrected by P_xy / S nu: the gyro-bias parts (P_xy = r / 4), velocity and accelerometer bias
    (P_xy = r / 400). Ratio (4/sqrt(8)/5)^2 = 0.08."""
    s = state()
    r = (2.0 * DEG) ** 2
    f = live(s, p={2: r, em.X_DV: 1.0, em.X_BG + 2: r, em.X_GG + 2: r, em.X_BA: 1.0},
             declination=3.0, sigma_mag=2.0)
    c = 0.25 * r
    for j in (em.X_DV, em.X_BG + 2, em.X_GG + 2, em.X_BA):
        f.P[2, j] = f.P[j, 2] = c * (0.01 if j in (em.X_DV, em.X_BA) else 1.0)
    f.measure(s, CFG, T0, "mag", (math.cos(7.0 * DEG), math.sin(7.0 * DEG), 0.0))
    nu = 4.0 * DEG
    assert yaw(s) == pytest.approx(-2.0 * DEG, rel=1e-12)
    assert f.bias[kf.B_BG + 2] == pytest.approx(-c / (2 * r) * nu, rel=1e-12)
    assert f.bias[kf.B_GG + 2] == pytest.approx(-c / (2 * r) * nu, rel=1e-12)
    np.testing.assert_allclose(velocity(s), [-0.01 * c / (2 * r) * nu, 0.0, 0.0], rtol=1e-12, atol=0)
    assert f.bias[kf.B_BA] == pytest.approx(-0.01 * c / (2 * r) * nu, rel=1e-12)
    assert f.counters == {"mag_accepted": 1} and f.ratios == pytest.approx({"mag": 0.08}, rel=1e-12)
    u = f.uncertainty(T0, 0)
    assert u.mag_ratio == pytest.approx(0.08, rel=1e-12) and not u.abs_pos and not u.abs_hgt
    f.measure(s, CFG, T0, "mag", (0.0, 1.0, 0.0))  # 85 deg off, S = 1.5 R: rejected
    assert f.counters["mag_rejected"] == 1


@pytest.mark.parametrize("before", [0, 2])
def test_magnetometer_h_takes_the_inclination_of_the_samples_before(before: int) -> None:
    """The live filter keeps the mean tan(inclination) of its accepted samples for kalman.mag_heading's tilt terms
    (its own for the first sample). Level, yaw 0, declination 0, P = diag(phi_N 0.01), sigma_mag 0.1 rad:
    H_N = -tan I. Samples [1, 0, 2] and [1, 0, 0.5] (tan I 2 and 0.5, nu 0: the state stays) before
    [cos 0.1, -sin 0.1, 3] (tan I 3, nu -0.1), which then uses tan I 1.25; alone it uses its own 3. Its NIS
    and the roll it leaves (-x_N: C <- exp(-[x x]) C) as the scalar algebra gives (_mag_by_hand); the ratio
    kept is NIS / gate^2 (gate 5). A restart forgets the inclination."""
    s = state()
    f = live(s, p={0: 0.01}, declination=0.0, sigma_mag=math.degrees(0.1))
    tans = [2.0, 0.5][:before] + [3.0]
    for tan_i in tans[:-1]:
        f.measure(s, CFG, T0, "mag", (1.0, 0.0, tan_i))
    assert yaw(s) == 0.0
    f.measure(s, CFG, T0, "mag", (math.cos(0.1), -math.sin(0.1), 3.0))
    nis, x_n = mag_by_hand(tans, 0.01, 0.01, -0.1)
    assert f.counters == {"mag_accepted": len(tans)}
    assert f.ratios["mag"] == pytest.approx(nis / 25.0, rel=1e-12)
    c = s[sd.S.C : sd.S.C + 9].reshape(3, 3)
    assert math.atan2(c[2, 1], c[2, 2]) == pytest.approx(-x_n, rel=1e-9)
    s = state()
    f.start(s, CFG, np.zeros(3), 0.01)
    f.P[:] = 0.0
    f.P[0, 0] = 0.01
    f.measure(s, CFG, T0, "mag", (math.cos(0.1), -math.sin(0.1), 3.0))
    assert f.ratios["mag"] == pytest.approx(mag_by_hand([3.0], 0.01, 0.01, -0.1)[0] / 25.0, rel=1e-12)


@pytest.mark.parametrize("late", [0.01, 0.0])
def test_late_magnetometer_sample_is_turned_with_the_bias_corrected_rate(late) -> None:
    """Raw yaw rate 0.1 rad/s, gyro bias 0.02 from the rest window: one update turns the yaw to psi = 0.08 * 0.01.
    A sample of a field straight north, stamped at the start (10 ms before the update: the body then pointed
    north, so it reads (1, 0, 0)), is carried to the update by -late (w x m_b) (kalman.mag_heading) with
    w = 0.08: it agrees with the turned yaw to third order (psi - atan(psi) = psi^3/3 ~ 2e-10), so the yaw
    stays. The same sample stamped at the update (late 0) is psi off, and P_yaw = R moves the yaw half way."""
    s = state()
    f = LiveFilter(FilterSettings(spec={}, sigma_mag=2.0))
    f.start(s, CFG, np.array([0.0, 0.0, 0.02]), 0.01)
    assert still(f, s, T0 + 0.01, (0.0, 0.0, 0.1)) == 1
    psi = 0.08 * 0.01
    assert yaw(s) == pytest.approx(psi, rel=1e-12)
    f.P[:] = 0.0
    f.P[2, 2] = (2.0 * DEG) ** 2
    f.measure(s, CFG, T0 + 0.01 - late, "mag", (1.0, 0.0, 0.0))
    assert f.counters == {"mag_accepted": 1}
    want = psi if late else psi / 2
    assert yaw(s) == pytest.approx(want, abs=1e-9)


@pytest.mark.parametrize("incl_deg, strength, disturbed", [
    (63.0, 0.48, False), (63.0 + 19.9, 0.48, False), (63.0 - 20.1, 0.48, True), (63.0 + 20.1, 0.48, True),
    (63.0, 0.48 + 0.19, False), (63.0, 0.48 - 0.21, True), (63.0, 0.48 + 0.21, True),
])
def test_magnetometer_samples_far_from_the_model_are_disturbances(incl_deg, strength, disturbed) -> None:
    """The model's field I = 63 deg, 0.48 gauss: a level sample (yaw 0, so m_n = m_b) of inclination and
    strength within 20 deg and 0.2 gauss (PX4 EKF2's default checks) is used; beyond either, it is counted
    mag_disturbed and not applied (no mag counter, heading untouched). Without a model nothing is gated."""
    i = math.radians(incl_deg)
    m_b = (strength * math.cos(i), 0.0, strength * math.sin(i))
    s = state()
    f = live(s, p={em.X_PHI + 2: 0.01}, mag_model=(63.0, 0.48))
    f.measure(s, CFG, T0, "mag", m_b)
    assert (f.counters["mag_disturbed"] == 1) is disturbed
    assert f.counters["mag_accepted"] + f.counters["mag_rejected"] == (0 if disturbed else 1)
    s = state()
    f = live(s, p={em.X_PHI + 2: 0.01})
    f.measure(s, CFG, T0, "mag", m_b)
    assert f.counters["mag_disturbed"] == 0 and f.counters["mag_accepted"] + f.counters["mag_rejected"] == 1


def test_gnss_yaw_by_hand() -> None:
    """A dual-antenna heading of 0.1 rad (sigma 0.1) on a level solution at yaw 0 with P_yaw = R = 0.01:
    half of it is taken (yaw 0.05, P_yaw 0.005: x = P/(P + R) nu), counted gnss_yaw, its test ratio
    published as the heading's ((0.1 / sqrt(0.02)) / 5)^2. It comes with GNSS aiding: without it, ignored;
    the GNSS delay moves it too."""
    s = state()
    f = live(s, p={em.X_PHI + 2: 0.01})
    f.measure(s, CFG, T0, "gnss_yaw", 0.1, 0.1)
    assert yaw(s) == pytest.approx(0.05, abs=1e-12) and f.P[em.X_PHI + 2, em.X_PHI + 2] == pytest.approx(0.005)
    assert f.counters == {"gnss_yaw_accepted": 1}
    assert f.ratios["mag"] == pytest.approx(0.01 / 0.02 / 25.0, rel=1e-12)
    s = state()
    f = live(s, aiding=("baro", "mag"), p={em.X_PHI + 2: 0.01})
    f.measure(s, CFG, T0, "gnss_yaw", 0.1, 0.1)
    assert yaw(s) == 0.0 and not f.counters
    s = state()
    f = live(s, p={em.X_PHI + 2: 0.01}, delays={"gnss": 0.5})
    f.measure(s, CFG, T0 + 0.5, "gnss_yaw", 0.1, 0.1)  # measured at t0: applied now
    assert f.counters == {"gnss_yaw_accepted": 1}


def test_zupt_by_hand() -> None:
    """v = (0.02, -0.04, 0.01) m/s, P_v = sigma_zupt^2 = 0.05^2: a ZUPT halves the velocity; ratio
    (0.04 / sqrt(0.005) / 5)^2 = 0.0128; a 10 m/s velocity is rejected by the gate."""
    s = state(v=(0.02, -0.04, 0.01))
    f = live(s, p=vel_var(0.0025), sigma_zupt=0.05)
    f.measure(s, CFG, T0, "zupt")
    np.testing.assert_allclose(velocity(s), [0.01, -0.02, 0.005], rtol=0, atol=1e-15)
    assert f.counters == {"zupt_accepted": 1} and f.ratios == pytest.approx({"vel": 0.0128}, rel=1e-12)
    s[sd.S.V] = 10.0
    f.measure(s, CFG, T0, "zupt")
    assert f.counters["zupt_rejected"] == 1 and velocity(s)[0] == 10.0


# ============================================================== published


def test_uncertainty_is_the_square_root_of_the_covariance() -> None:
    """sigma = sqrt(diag P) per block, a negative round-off variance read as 0; the gyro sigma combines the
    constant and Gauss-Markov parts in quadrature (sqrt(9 + 16) = 5, ...); resets: the engine's plus the filter's."""
    f = LiveFilter(FilterSettings(spec={}))
    d = np.zeros(em.NX)
    d[0:3] = [0.01, 0.0004, 0.09]
    d[3:6] = [0.25, -1e-12, 0.0625]
    d[6:9] = [4.0, 0.16, 0.0]
    d[9:12] = [0.09, 0.0004, 0.01]
    d[12:15] = [7.0, 7.0, 7.0]
    d[15:18] = [0.16, 0.0, 0.03]
    d[18:22] = 5.0
    f.P[:] = np.diag(d)
    f.resets = 2
    u = f.uncertainty(0.0, 3)
    np.testing.assert_allclose(u.sigma_att, [0.1, 0.02, 0.3], rtol=1e-15, atol=0)
    np.testing.assert_allclose(u.sigma_vel, [0.5, 0.0, 0.25], rtol=1e-15, atol=0)
    np.testing.assert_allclose(u.sigma_pos, [2.0, 0.4, 0.0], rtol=1e-15, atol=0)
    np.testing.assert_allclose(u.sigma_gyro, [0.5, 0.02, 0.2], rtol=1e-15, atol=0)
    assert u.resets == 5 and not u.glitch and not u.abs_pos and not u.abs_hgt
    f.glitch = True
    assert f.uncertainty(0.0, 0).glitch and f.uncertainty(0.0, 0).resets == 2


def test_uncertainty_gyro_sigma_includes_the_cross_covariance() -> None:
    """The published gyro-bias sigma is that of the estimate, the sum of the constant and Gauss-Markov parts:
    var(b + g) = P_bb + P_gg + 2 P_bg. With P_bb = 4 and P_gg = 9: P_bg = -3 gives 7, +2 gives 17, +6 (fully
    correlated) gives 25 (sigma 5), on x, y and z respectively."""
    f = LiveFilter(FilterSettings(spec={}))
    f.P[:] = 0.0
    for i, cross in enumerate((-3.0, 2.0, 6.0)):
        b, g = em.X_BG + i, em.X_GG + i
        f.P[b, b], f.P[g, g] = 4.0, 9.0
        f.P[b, g] = f.P[g, b] = cross
    u = f.uncertainty(0.0, 0)
    np.testing.assert_allclose(u.sigma_gyro, [math.sqrt(7.0), math.sqrt(17.0), 5.0], rtol=1e-15, atol=0)


def test_warm_measurements_runs_every_kind_once() -> None:
    """The warm-up (service.warm_up) starts a filter with every aiding kind and applies one measurement of each at
    the state's time: each kind's update runs once (accepted or rejected), GNSS twice (a NED velocity, and a
    ground speed with no vertical: both velocity models compile)."""
    made = []

    class Recording(LiveFilter):
        def __post_init__(self) -> None:
            super().__post_init__()
            made.append(self)

    mp = pytest.MonkeyPatch()
    mp.setattr(livefilter, "LiveFilter", Recording)
    try:
        assert livefilter.warm_measurements() is None
    finally:
        mp.undo()
    (f,) = made
    assert f.settings.aiding == AIDING_KINDS
    for kind, n in (("gnss_pos", 2), ("gnss_vel", 2), ("baro", 1), ("mag", 1), ("zupt", 1), ("gnss_yaw", 1)):
        assert f.counters[f"{kind}_accepted"] + f.counters[f"{kind}_rejected"] == n, kind
