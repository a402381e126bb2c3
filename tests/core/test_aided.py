"""What the mutation runs found unchecked in mavins/core/aided.py, the filter's batch driver and live push (docs/testing.md).

A level vehicle at rest in laboratory mode (earth = none: no Earth rate, constant gravity), a few
10 ms updates, a noise-free sensor model and an initial P that holds only the states a test is
about: the covariance then stays what it was between measurements, and each update is the scalar
Kalman update worked by hand, x = P/(P + R) nu per axis (D. Simon, *Optimal State Estimation*,
2006, 5.1), fed back as docs/filter.md "Measurements" says. The rules of the driver are
docs/filter.md "Time alignment" and the module docstring of aided.py (rows at or before a continued
state's time skipped, a measurement used at the first update at or after its time, ZUPTs inside a
rest window and one ZARU at its end with the bias walk in its variance).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import aided
from mavins.core import errmodel as em
from mavins.core import kalman as kf
from mavins.core import strapdown as sd
from mavins.core.rotation import euler_to_dcm
from support import NO_SMOOTHING, A, E2, gamma, mag_by_hand

LAT0, LON0, H0 = 45.0, 7.0, 100.0  # deg, deg, m
DT = 0.01
DEG_H = 180.0 / math.pi * 3600.0  # rad/s -> deg/h
N_ROWS = 10
NAN = math.nan


def radii(lat_deg: float) -> tuple[float, float]:
    d = 1.0 - E2 * math.sin(math.radians(lat_deg)) ** 2
    return A * (1.0 - E2) / d**1.5, A / math.sqrt(d)


RN, RE = radii(LAT0)


def init(**sig) -> dict:
    base = {"t": 0.0, "lat": LAT0, "lon": LON0, "h": H0, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 0.0, "pitch": 0.0,
            "yaw": 0.0, "sigma_pos": 0.0, "sigma_vel": 0.0, "sigma_level": 0.0, "sigma_yaw": 0.0}
    base.update(sig)
    return base


def imu(n: int = N_ROWS, wz: float = 0.0) -> np.ndarray:
    """Increment rows at rest, level: dv = f dt with f^b = [0, 0, -gamma] (NIMA Somigliana, typed), a turn rate wz."""
    g = float(gamma(math.radians(LAT0), H0))
    t = np.round(np.arange(1, n + 1) * DT, 12)
    dt = np.diff(np.concatenate([[0.0], t]))
    rows = np.zeros((n, 7))
    rows[:, 0] = t
    rows[:, 3] = wz * dt
    rows[:, 6] = -g * dt
    return rows


def nav(rows=None, **kw):
    kw.setdefault("spec", em.ImuSpec())
    kw.setdefault("earth_model", "none")
    kw.setdefault("samples", 1)
    kw.setdefault("baro_offset_sigma", 0.0)
    return aided.navigate_aided(imu() if rows is None else rows, kw.pop("init", init()), **kw)


def col(name: str) -> int:
    return aided.OUT_COLUMNS.index(name)


def test_gnss_position_and_baro_by_hand() -> None:
    """sigma_pos 2 m, a fix at 0.05 s 3 m north, 6 m west, 1.5 m up with sigma 2 m: each axis moves half way
    (P = R = 4); a baro height 4 m above the solution at 0.08 s (P_h = 2 after the fix, offset P 1, R 1: S = 4)
    moves h by P_h/S of it and the offset by -P_off/S."""
    dlat, dlon = math.degrees(3.0 / (RN + H0)), math.degrees(-6.0 / ((RE + H0) * math.cos(math.radians(LAT0))))
    gnss = [[-1.0, LAT0 + 1.0, LON0, H0, NAN, NAN, NAN, 2.0, 2.0, 0.3],  # before the start: skipped
            [0.05, LAT0 + dlat, LON0 + dlon, H0 + 1.5, NAN, NAN, NAN, 2.0, 2.0, 0.3]]
    baro = [[0.08, H0 + 0.75 + 4.0, 1.0]]
    rows, st = nav(gnss=gnss, baro=baro, init=init(sigma_pos=2.0), baro_offset_sigma=1.0)
    assert rows.shape == (N_ROWS, aided.ROW_SIZE)
    np.testing.assert_allclose(rows[:, 0], np.arange(1, 11) * DT, rtol=0, atol=1e-15)
    before, after = rows[:4], rows[4:]
    np.testing.assert_allclose(before[:, 1:4], [[LAT0, LON0, H0]] * 4, rtol=0, atol=1e-12)
    np.testing.assert_allclose(after[:, 1], LAT0 + dlat / 2, rtol=0, atol=1e-12)  # degrees: 1e-12 deg ~ 0.1 mm
    np.testing.assert_allclose(after[:, 2], LON0 + dlon / 2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(after[:3, 3], H0 + 0.75, rtol=0, atol=1e-9)
    np.testing.assert_allclose(after[3:, 3], H0 + 0.75 + 2.0, rtol=0, atol=1e-9)  # x_dpD = -P_h nu / S = 2
    assert st["baro_offset"] == pytest.approx(1.0, rel=1e-12) and st["bias"][kf.B_BARO] == st["baro_offset"]
    np.testing.assert_allclose(rows[:, col("sigma_n")], [2.0] * 4 + [math.sqrt(2.0)] * 6, rtol=1e-15, atol=0)
    np.testing.assert_allclose(rows[:, col("sigma_d")], [2.0] * 4 + [math.sqrt(2.0)] * 3 + [1.0] * 3, rtol=1e-15,
                               atol=0)
    np.testing.assert_array_equal(rows[:, col("sigma_vn")], 0.0)
    assert st["counts"] == {"gnss_pos": (1, 0), "gnss_vel": (0, 0), "baro": (1, 0), "mag": (0, 0), "zupt": (0, 0),
                            "zaru": (0, 0), "mag_disturbed": (0, 0), "wheel": (0, 0), "nhc": (0, 0)}
    log = st["nis"]
    assert log.shape == (2, 6)
    np.testing.assert_allclose(log[0], [0.05, aided.K_GNSS_POS, (9 + 36 + 2.25) / 8, 3, 1, 6 / math.sqrt(8) / 5],
                               rtol=1e-9, atol=0)
    np.testing.assert_allclose(log[1], [0.08, aided.K_BARO, 16 / 4, 1, 1, 2 / 5], rtol=1e-9, atol=0)
    np.testing.assert_allclose(st["P"][8, 8], 1.0, rtol=1e-15)
    assert st["state"].shape == (sd.S_SIZE,) and st["state"][sd.S.T] == pytest.approx(0.1, abs=1e-15)


def test_a_fix_between_updates_waits_for_the_next_and_a_rejection_is_counted() -> None:
    """A fix at 0.045 s is applied at the update of 0.05 s (docs/filter.md "Time alignment"), not before;
    one 10 sigma off at 0.07 s is rejected by the gate (5) and logged as such."""
    gnss = [[0.045, LAT0 + math.degrees(4.0 / (RN + H0)), LON0, H0, NAN, NAN, NAN, 2.0, 2.0, 0.3],
            [0.07, LAT0 + math.degrees(40.0 / (RN + H0)), LON0, H0, NAN, NAN, NAN, 1.0, 1.0, 0.3]]
    rows, st = nav(gnss=gnss, init=init(sigma_pos=1.0))
    north = (np.radians(rows[:, 1]) - math.radians(LAT0)) * (RN + H0)
    np.testing.assert_allclose(north[:4], 0.0, rtol=0, atol=1e-7)
    np.testing.assert_allclose(north[4:], 4.0 / 5.0, rtol=0, atol=1e-7)  # P 1, R 4
    assert st["counts"]["gnss_pos"] == (1, 1)
    np.testing.assert_allclose(st["nis"][:, [0, 1, 3, 4]], [[0.045, 0, 3, 1], [0.07, 0, 3, 0]])
    # the second: 39.2 m against sqrt(0.8 + 1): the ratio over the gate of 5
    assert st["nis"][1, 5] == pytest.approx(39.2 / math.sqrt(1.8) / 5, rel=1e-6)
    assert st["nis"][1, 2] == pytest.approx(39.2**2 / 1.8, rel=1e-6)


def test_gnss_velocity_with_lever_arm_and_turn_rate() -> None:
    """sigma_vel 1, a velocity fix (sigma 1) at 0.05 s: v = (v_m - C (w x l)) / 2 with w = [0, 0, 0.1] rad/s
    (the summed increments over the interval), the lever arm [1, 0, 0] m and yaw 0.1 * 0.05 rad."""
    v_m = np.array([0.4, -0.2, 0.1])
    gnss = [[0.05, NAN, NAN, NAN, *v_m, 2.0, 2.0, 1.0]]
    rows, st = nav(imu(wz=0.1), gnss=gnss, init=init(sigma_vel=1.0), lever_arm=(1.0, 0.0, 0.0))
    yaw = 0.005
    cwl = 0.1 * np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    np.testing.assert_allclose(rows[:4, 4:7], 0.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rows[4, 4:7], (v_m - cwl) / 2, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rows[:, col("yaw")], np.degrees(0.1 * rows[:, 0]), rtol=1e-9, atol=0)
    assert st["counts"]["gnss_vel"] == (1, 0) and st["counts"]["gnss_pos"] == (0, 0)
    np.testing.assert_allclose(rows[4:, col("sigma_vn")], math.sqrt(0.5), rtol=1e-15)


def test_magnetometer_heading_with_declination() -> None:
    """sigma_yaw 0.1 rad, a field seen from a vehicle whose true yaw is 0.02 rad (estimate 0), declination 5 deg,
    sigma 0.1 rad: the heading moves half way (kalman.mag_heading, docs/filter.md)."""
    inc, dec, psi = math.radians(60.0), math.radians(5.0), 0.02
    m_n = np.array([math.cos(inc) * math.cos(dec), math.cos(inc) * math.sin(dec), math.sin(inc)])
    rz = np.array([[math.cos(psi), -math.sin(psi), 0.0], [math.sin(psi), math.cos(psi), 0.0], [0.0, 0.0, 1.0]])
    m_b = rz.T @ m_n
    mag = [[0.03, *m_b, math.degrees(0.1)], [0.06, NAN, 1.0, 1.0, math.degrees(0.1)]]  # the second: no field
    rows, st = nav(mag=mag, init=init(sigma_yaw=math.degrees(0.1)), declination=5.0)
    np.testing.assert_allclose(rows[:2, col("yaw")], 0.0, atol=1e-12)
    np.testing.assert_allclose(rows[2:, col("yaw")], math.degrees(psi / 2), rtol=1e-9)
    assert st["counts"]["mag"] == (1, 0)
    np.testing.assert_allclose(rows[2:, col("sigma_att_d")], math.degrees(math.sqrt(0.005)), rtol=1e-15)  # file units: deg
    assert st["nis"][0, 2] == pytest.approx(psi**2 / 0.02, rel=1e-9)


def test_rest_window_zupt_and_zaru() -> None:
    """A rest window (0, 0.05]: a ZUPT (sigma 1 m/s, P_vD 1) at each of its 5 updates leaves P_vD = 1/6; at
    its end one ZARU with the mean raw rate: a z gyro bias of 1e-3 rad/s against its sigma 1e-3 (P_bg = 1e-6)
    and the ZARU's 1e-3 rad/s (R 1e-6): half of it is taken (the z bias does not couple to the level
    velocity at rest: phi_D x f^n = 0)."""
    rows_in = imu(wz=1e-3)
    static = [[0.0, 0.05, 1.0, 1e-3 * DEG_H]]
    spec = em.ImuSpec(gyro_bias=1e-3)
    rows, st = nav(rows_in, static=static, spec=spec, init=init(sigma_vel=1.0))
    np.testing.assert_allclose(rows[:5, col("sigma_vd")] ** 2, [1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 6], rtol=1e-12)
    assert rows[5, col("sigma_vd")] ** 2 == pytest.approx(1 / 6, rel=1e-12)
    assert st["counts"]["zupt"] == (5, 0) and st["counts"]["zaru"] == (1, 0)
    assert st["bias"][kf.B_BG + 2] == pytest.approx(0.5e-3, rel=1e-9)
    assert rows[4, col("bg_z")] == pytest.approx(0.5e-3 * DEG_H, rel=1e-9)
    assert rows[3, col("bg_z")] == 0.0
    assert rows[4, col("sigma_bg_z")] == pytest.approx(math.sqrt(0.5e-6) * DEG_H, rel=1e-9)
    log = st["nis"]
    np.testing.assert_allclose(log[:, [0, 1, 3, 4]], [[0.01 * k, 4, 3, 1] for k in range(1, 6)] + [[0.05, 5, 3, 1]],
                               atol=1e-15)
    # after the window the bias is removed from the increments: the yaw rate is 0.5e-3 rad/s
    yaw = np.radians(rows[:, col("yaw")])
    assert yaw[9] - yaw[5] == pytest.approx(4 * DT * 0.5e-3, rel=1e-6)


def test_zaru_default_sigma_and_bias_walk() -> None:
    """sigma_w 0: ARW / sqrt(window) (aided docstring); the variance also holds the bias's walk over the window,
    K^2 T / 3 (rate random walk K), while P_bg itself grows by K^2 T: P = 1e-6 + 1.2e-5 * 0.05 = 1.6e-6,
    R = ARW^2 / 0.05 + 1.2e-5 * 0.05 / 3 = 1e-6 + 2e-7: gain 1.6 / 2.8."""
    spec = em.ImuSpec(gyro_bias=1e-3, gyro_arw=math.sqrt(5e-8), gyro_rrw=math.sqrt(1.2e-5))
    rows, st = nav(imu(wz=1e-3), static=[[0.0, 0.05, 1.0]], spec=spec, init=init(sigma_vel=1.0))
    assert st["bias"][kf.B_BG + 2] == pytest.approx(1e-3 * 1.6 / 2.8, rel=1e-9)
    # with a Gauss-Markov part the walk adds 2 sigma^2 / tau: P_bg 1e-6 and P_gg 1e-6 (decaying), ...
    spec = em.ImuSpec(gyro_bias=1e-3, gyro_arw=math.sqrt(5e-8), gyro_gm=1e-3, gyro_tau=1e6)
    rows, st = nav(imu(wz=1e-3), static=[[0.0, 0.05, 1.0]], spec=spec, init=init(sigma_vel=1.0))
    # tau 1e6 s: over 0.05 s P_gg stays 1e-6 (to 1e-7 relative) and is driven by 2 sigma^2/tau = 2e-12 /s;
    # S = P_bg + P_gg + R = 1e-6 + 1e-6 + 1e-6 + 2e-12 * 0.05 / 3: each part takes 1/3 of the 1e-3
    b = st["bias"]
    assert b[kf.B_BG + 2] == pytest.approx(1e-3 / 3, rel=1e-6)
    assert b[kf.B_GG + 2] == pytest.approx(1e-3 / 3, rel=1e-6)
    assert b[kf.B_BG + 2] + b[kf.B_GG + 2] == pytest.approx(rows[9, col("bg_z")] / DEG_H, rel=1e-6)


def test_navigate_aided_defaults_and_checks() -> None:
    """The initial P from init's sigmas (defaults 10 m, 1 m/s, 1 deg, 10 deg) and the spec; the argument checks."""
    empty = np.zeros((0, 7))
    spec = em.ImuSpec(gyro_bias=2.0, accel_bias=3.0, gyro_gm=4.0, accel_gm=5.0)
    _, st = aided.navigate_aided(empty, {k: v for k, v in init().items() if not k.startswith("sigma")}, spec=spec,
                                 earth_model="none")
    d = np.diag(st["P"])
    np.testing.assert_allclose(d, [math.radians(1) ** 2] * 2 + [math.radians(10) ** 2] + [1.0] * 3 + [100.0] * 3
                               + [4.0] * 3 + [9.0] * 3 + [16.0] * 3 + [25.0] * 3 + [2500.0] + [0.0] * (em.NX - 22), rtol=1e-15)
    _, st = aided.navigate_aided(empty, init(sigma_pos=3.0, sigma_vel=0.5, sigma_level=2.0, sigma_yaw=4.0),
                                 spec=spec, earth_model="none", baro_offset_sigma=6.0)
    np.testing.assert_allclose(np.diag(st["P"])[[0, 2, 3, 6, 21]], [math.radians(2) ** 2, math.radians(4) ** 2,
                                                                     0.25, 9.0, 36.0], rtol=1e-15)
    assert st["nis"].shape == (0, 6) and st["P_history"].shape == (0, em.NX, em.NX)
    with pytest.raises(ValueError, match=r"^predict_every must be >= 1$"):
        nav(predict_every=0)
    with pytest.raises(ValueError, match=r"^imu must have shape \(N, 7\), got \(3, 6\)$"):
        nav(np.zeros((3, 6)))
    with pytest.raises(ValueError, match=r"^imu must have shape \(N, 7\), got \(7,\)$"):
        nav(np.zeros(7))
    with pytest.raises(ValueError, match=r"^covariance_every must be >= 0$"):
        nav(covariance_every=-1)
    rows, st = nav(init=init(sigma_pos=2.0), covariance_every=3,
                   gnss=[[0.05, LAT0, LON0, H0, NAN, NAN, NAN, 2.0, 2.0, 0.3]])
    ph = st["P_history"]
    assert ph.shape == (3, em.NX, em.NX)  # after rows 3, 6, 9
    np.testing.assert_allclose([p[6, 6] for p in ph], [4.0, 2.0, 2.0], rtol=1e-15)
    rows_k, _ = nav(init=init(sigma_pos=2.0), file_units=False)
    rows_f, _ = nav(init=init(sigma_pos=2.0))
    np.testing.assert_allclose(rows_f, aided.to_file_units(rows_k), rtol=0, atol=0)
    assert rows_k[0, 1] == pytest.approx(math.radians(LAT0), rel=1e-15)


def test_predict_every_and_default_sigmas_of_measurements() -> None:
    """predict_every 5: P propagated every fifth update and before each measurement (a velocity sigma 1 m/s
    grows the position variance by T^2 over T); measurement rows without sigmas take the defaults
    (2.5 m, 5 m, 0.3 m/s, baro 0.5 m, magnetometer 3 deg, ZUPT 0.01 m/s)."""
    rows, st = nav(init=init(sigma_vel=1.0), predict_every=5)
    sig_n2 = rows[:, col("sigma_n")] ** 2
    np.testing.assert_allclose(sig_n2[[4, 9]], [0.05**2, 0.1**2], rtol=1e-9)
    np.testing.assert_allclose(sig_n2[[0, 1, 2, 3]], 0.0, atol=0)
    np.testing.assert_allclose(sig_n2[[5, 8]], 0.05**2, rtol=1e-9)
    # the final propagation brings P to the state's time
    rows, st = nav(imu(7), init=init(sigma_vel=1.0), predict_every=5)
    assert st["P"][6, 6] == pytest.approx(0.07**2, rel=1e-9)
    # default sigmas, read back through each measurement's NIS nu^2 / (P + R) with P constant (no velocity
    # uncertainty): a fix 1 m north and 1 m up (P 1, R 2.5^2 and 5^2; no velocity: NaN), then h moved up by
    # 1/26 m; a baro height 1 m below that (P_h 25/26, R 0.5^2); a heading 1 deg off (P 1 deg^2, R 3 deg^2)
    gnss = [[0.02, LAT0 + math.degrees(1.0 / (RN + H0)), LON0, H0 + 1.0, 0.3, NAN, NAN]]
    psi = math.radians(1.0)
    m_b = np.array([math.cos(psi), -math.sin(psi), 1.0])  # the field along north seen from yaw psi
    rows, st = nav(init=init(sigma_pos=1.0, sigma_yaw=1.0), gnss=gnss, baro=[[0.05, H0 + 1.0 / 26 - 1.0]],
                   mag=[[0.06, *m_b]])
    log = st["nis"]
    assert list(log[:, 1]) == [0, 2, 3]
    np.testing.assert_allclose(log[:, 2], [1 / 7.25 + 1 / 26, 1 / (25 / 26 + 0.25), 0.1], rtol=1e-7)
    rows, st = nav(init=init(sigma_vel=1.0), gnss=[[0.02, NAN, NAN, NAN, 0.3, 0.0, 0.0]])
    assert st["nis"][0, 1] == 1 and st["nis"][0, 2] == pytest.approx(0.09 / 1.09, rel=1e-12)


def test_continued_runs_skip_rows_at_their_start() -> None:
    """run_aided over two calls: the second skips measurement rows at or before the state's time (used by the
    call before); a fresh state uses a row at its own start time at its first update, 0.01 s late."""
    cfg = sd.make_config(samples=1, earth_model="none")
    spec = em.ImuSpec().as_array()
    rows = imu()

    def run(s, P, t_rows, gnss):
        out = np.empty((len(t_rows) + 1, aided.ROW_SIZE))
        counts = np.zeros((len(aided.KIND_NAMES), 2), dtype=np.int64)
        log = np.empty((10, 6))
        n, nl, _ = aided.run_aided(s, cfg, np.ascontiguousarray(t_rows[:, 0]), np.ascontiguousarray(t_rows[:, 1:4]),
                                np.ascontiguousarray(t_rows[:, 4:7]), gnss, np.empty((0, 3)), np.empty((0, 5)),
                                np.empty((0, 4)), spec, np.zeros(3), 0.0, math.nan, math.nan, math.nan, 5.0, 1, P, np.zeros(kf.B_SIZE), out, counts,
                                log, np.zeros((0, em.NX, em.NX)), 100, *NO_SMOOTHING)
        return out[:n], counts, log[:nl]

    lat0 = math.radians(LAT0)
    fix = lambda t: [t, lat0 + 1.0 / (RN + H0), math.radians(LON0), H0, NAN, NAN, NAN, 1.0, 1.0, 0.3]  # noqa: E731
    s = sd.init_state(0.0, lat0, math.radians(LON0), H0, np.zeros(3), 0.0, 0.0, 0.0)
    P = np.zeros((em.NX, em.NX))
    P[6, 6] = P[7, 7] = P[8, 8] = 1.0
    out, counts, log = run(s, P, rows[:5], np.array([fix(0.0)]))
    assert counts[0, 0] == 1 and log[0, 0] == 0.0
    np.testing.assert_allclose((out[:, 1] - lat0) * (RN + H0), 0.5, atol=1e-7)
    out, counts, log = run(s, P, rows[5:], np.array([fix(0.05), fix(0.07)]))
    assert counts[0, 0] == 1 and log[0, 0] == 0.07  # 0.05 was the first call's
    np.testing.assert_allclose((out[:, 1] - lat0) * (RN + H0), [0.5] + [0.5 + 0.5 / 3] * 4, atol=1e-7)  # P 1/2, R 1


def test_after_k_update_accumulates_and_decays() -> None:
    """The interval's mean C T and C dv sums go to acc, T = t_k - t_last, sums reset; the Gauss-Markov bias
    estimates decay by exp(-T/tau) (their expected value) only when the part exists; P is propagated every
    predict_every-th update."""
    cfg = sd.make_config(samples=1, earth_model="none")
    s = sd.init_state(0.0, 0.7, 0.1, 100.0, np.zeros(3), 0.0, 0.0, math.pi / 2)  # yaw 90 deg: C = Rz(90)
    s[sd.S.T] = 0.25
    s[sd.S.NK] = 3
    spec = em.ImuSpec(gyro_gm=1.0, gyro_tau=0.5).as_array()
    P = np.eye(em.NX)
    bias = np.r_[np.arange(1.0, 14.0), np.zeros(kf.B_SIZE - 13)]
    acc = np.zeros(aided.ACC_SIZE)
    sums = np.array([0.1, 0.2, 0.3, 1.0, 2.0, 3.0, 0.05])
    T = aided.after_k_update(s, cfg, spec, P, bias, acc, sums, 2, sd.GEOGRAPHIC)
    assert T == pytest.approx(0.2, rel=1e-15)
    np.testing.assert_array_equal(sums, [0, 0, 0, 0, 0, 0, 0.25])
    c = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(acc[0:9], (c * 0.2).ravel(), atol=1e-16)
    np.testing.assert_allclose(acc[9:12], c @ [1.0, 2.0, 3.0], atol=1e-15)
    assert acc[12] == pytest.approx(0.2, rel=1e-15)
    e = math.exp(-0.2 / 0.5)
    np.testing.assert_allclose(bias, [1, 2, 3, 4, 5, 6, 7 * e, 8 * e, 9 * e, 10, 11, 12, 13] + [0] * (kf.B_SIZE - 13), rtol=1e-15)
    np.testing.assert_array_equal(P, np.eye(em.NX))  # 3 % 2: not propagated
    s[sd.S.NK] = 4
    s[sd.S.T] = 0.35
    spec = em.ImuSpec(accel_gm=1e-9, accel_tau=0.25).as_array()  # a tiny part: its noise 8e-18 /s is negligible
    bias = np.r_[np.arange(1.0, 14.0), np.zeros(kf.B_SIZE - 13)]
    P = np.zeros((em.NX, em.NX))
    P[3:6, 3:6] = np.eye(3)
    T = aided.after_k_update(s, cfg, spec, P, bias, acc, sums, 2, sd.GEOGRAPHIC)
    assert T == pytest.approx(0.1, rel=1e-14)
    e = math.exp(-0.1 / 0.25)
    np.testing.assert_allclose(bias, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10 * e, 11 * e, 12 * e, 13] + [0] * (kf.B_SIZE - 13), rtol=1e-15)
    assert np.all(acc == 0.0)  # propagated (4 % 2 == 0) over the 0.3 s accumulated: acc reset
    assert P[6, 6] == pytest.approx(0.3**2, rel=1e-12)  # dp from dv over T = 0.3 s, P_vv = 1
    assert P[6, 3] == pytest.approx(0.3, rel=1e-12)


def test_push_rate_aided_subtracts_the_bias_estimates() -> None:
    """The live path: rate samples minus (constant + Gauss-Markov) bias estimates, summed over the interval,
    then the k update; a sample not after the last is refused and changes nothing."""
    cfg = sd.make_config(samples=2, earth_model="none")
    s = sd.init_state(0.0, 0.7, 0.1, 100.0, np.zeros(3), 0.0, 0.0, 0.0)
    spec = em.ImuSpec().as_array()
    P = np.zeros((em.NX, em.NX))
    bias = np.zeros(kf.B_SIZE)
    bias[0:12] = [0.01, 0.02, 0.03, 0.1, 0.2, 0.3, 0.001, 0.002, 0.003, 0.01, 0.02, 0.03]
    acc, sums = np.zeros(aided.ACC_SIZE), np.zeros(7)
    w, f = (0.5, -0.25, 0.125), (1.0, 2.0, -9.0)
    r = aided.push_rate_aided(s, cfg, spec, P, bias, acc, sums, 0.01, *w, *f, 1000, sd.GEOGRAPHIC)
    assert r == 0
    np.testing.assert_allclose(sums[0:6], [(0.5 - 0.011) * 0.01, (-0.25 - 0.022) * 0.01, (0.125 - 0.033) * 0.01,
                                           (1.0 - 0.11) * 0.01, (2.0 - 0.22) * 0.01, (-9.0 - 0.33) * 0.01],
                               rtol=1e-13)
    before = (s.copy(), sums.copy())
    assert aided.push_rate_aided(s, cfg, spec, P, bias, acc, sums, 0.01, *w, *f, 1000, sd.GEOGRAPHIC) < 0
    np.testing.assert_array_equal(s, before[0])
    np.testing.assert_array_equal(sums, before[1])
    r = aided.push_rate_aided(s, cfg, spec, P, bias, acc, sums, 0.02, *w, *f, 1000, sd.GEOGRAPHIC)
    assert r == 1 and acc[12] == pytest.approx(0.02, rel=1e-12) and np.all(sums[0:6] == 0.0)
    assert sums[6] == s[sd.S.T]
    # C f dt over the interval with C at its end: turned by the bias-corrected rate over 0.02 s (Rodrigues)
    th = 0.02 * np.array([0.5 - 0.011, -0.25 - 0.022, 0.125 - 0.033])
    k = np.array([[0.0, -th[2], th[1]], [th[2], 0.0, -th[0]], [-th[1], th[0], 0.0]])
    a = np.linalg.norm(th)
    c = np.eye(3) + math.sin(a) / a * k + (1 - math.cos(a)) / a**2 * (k @ k)
    np.testing.assert_allclose(acc[9:12], c @ (0.02 * np.array([1.0 - 0.11, 2.0 - 0.22, -9.0 - 0.33])), rtol=0,
                               atol=1e-14)
    np.testing.assert_allclose(acc[0:9], 0.02 * c.ravel(), rtol=0, atol=1e-16)


def test_filter_row() -> None:
    """sigma of position, velocity, attitude; each bias as the sum of its parts and the sigma of that sum,
    sqrt(P_cc + P_gg + 2 P_cg) (clipped at 0)."""
    P = np.zeros((em.NX, em.NX))
    for i in range(3):
        P[6 + i, 6 + i], P[3 + i, 3 + i], P[i, i] = (4.0, 9.0, 16.0)[i], (1.0, 0.25, 0.0625)[i], (0.01, 0.04, 0.09)[i]
        P[9 + i, 9 + i], P[15 + i, 15 + i], P[9 + i, 15 + i] = 2.0, 3.0, (-1.0, 0.5, -3.0)[i]
        P[12 + i, 12 + i], P[18 + i, 18 + i], P[12 + i, 18 + i] = 5.0, 6.0, (1.5, -2.5, 0.0)[i]
    bias = np.r_[np.arange(1.0, 14.0), np.zeros(kf.B_SIZE - 13)]
    out = np.full(aided.OUT_SIZE, -7.0)
    aided.filter_row(P, bias, out)
    assert np.all(out[:14] == -7.0)
    np.testing.assert_array_equal(out[14:23], [2, 3, 4, 1, 0.5, 0.25, 0.1, 0.2, 0.3])
    np.testing.assert_array_equal(out[23:29], [1 + 7, 2 + 8, 3 + 9, 4 + 10, 5 + 11, 6 + 12])
    np.testing.assert_allclose(out[29:35], np.sqrt([3.0, 6.0, 0.0, 14.0, 6.0, 11.0]), rtol=1e-15)


def test_record_counts_and_logs_while_there_is_room() -> None:
    log = np.zeros((2, 6))
    counts = np.zeros((len(aided.KIND_NAMES), 2), dtype=np.int64)
    assert aided._record(log, 0, counts, 1.5, 3, 1, 2.5, 0.25, True) == 1
    assert aided._record(log, 1, counts, 2.5, 3, 1, 9.0, 1.5, False) == 2
    assert aided._record(log, 2, counts, 3.5, 0, 3, 1.0, 0.5, True) == 2  # full: counted, not logged
    np.testing.assert_array_equal(log, [[1.5, 3, 2.5, 1, 1, 0.25], [2.5, 3, 9.0, 1, 0, 1.5]])
    assert counts[3].tolist() == [1, 1] and counts[0].tolist() == [1, 0] and counts.sum() == 3


def test_columns_and_file_units() -> None:
    c = aided._columns
    assert c(None, 3, (None, None, 0.5), "baro").shape == (0, 3)
    assert c([], 3, (None, None, 0.5), "baro").shape == (0, 3)
    np.testing.assert_array_equal(c([1.0, 2.0], 3, (None, None, 0.5), "baro"), [[1.0, 2.0, 0.5]])
    np.testing.assert_array_equal(c([[1.0, 2.0, NAN], [2.0, NAN, 0.25], [2.0, 3.0, math.inf]], 3,
                                    (None, None, 0.5), "baro"), [[1.0, 2.0, 0.5], [2.0, NAN, 0.25], [2.0, 3.0, 0.5]])
    with pytest.raises(ValueError, match=r"^baro: at most 3 columns, got 4$"):
        c([[1.0, 2.0, 3.0, 4.0]], 3, (None, None, 0.5), "baro")
    with pytest.raises(ValueError, match=r"^mag: rows must be sorted by time$"):
        c([[2.0, 1.0], [1.0, 1.0]], 5, (None,) * 5, "mag")
    out = c([[1, 2]], 2, (None, None), "x")
    assert out.dtype == np.float64 and out.flags["C_CONTIGUOUS"]
    rows = np.arange(aided.OUT_SIZE, dtype=float)[None, :] * 1e-3
    f = aided.to_file_units(rows)
    deg = {1, 2, 7, 8, 9, 20, 21, 22}
    degh = set(range(23, 26)) | set(range(29, 32))
    for j in range(aided.OUT_SIZE):
        expect = math.degrees(rows[0, j]) if j in deg else rows[0, j] * DEG_H if j in degh else rows[0, j]
        assert f[0, j] == pytest.approx(expect, rel=1e-15, abs=0), j
    assert rows[0, 1] == 1e-3  # a copy


def test_navigate_aided_default_declination_and_static_defaults() -> None:
    """The default declination is 0 and a rest row without sigmas takes 0.01 m/s for its ZUPT."""
    inc = math.radians(60.0)
    m_b = np.array([math.cos(inc), 0.0, math.sin(inc)])  # along magnetic north, declination 0: no innovation
    rows, st = nav(mag=[[0.03, *m_b, 1.0]], init=init(sigma_yaw=1.0))
    assert abs(st["nis"][0, 2]) < 1e-20
    rows, st = nav(static=[[0.0, 0.01]], init=init(sigma_vel=0.01))
    assert rows[0, col("sigma_vd")] ** 2 == pytest.approx(0.5e-4, rel=1e-12)  # P 1e-4, R 1e-4


# ---------------------------------------------------------------------- the driver's rules, one by one

G_DATA = float(gamma(math.radians(LAT0), H0))
CFG_LAB1 = sd.make_config(samples=1, earth_model="none")


def integral_exp(w: np.ndarray, T: float) -> np.ndarray:
    """int_0^T exp([w x] t) dt = T I + (1 - cos aT)/a^2 [w x] + (T - sin(aT)/a)/a^2 [w x]^2 (Rodrigues, integrated)."""
    a = float(np.linalg.norm(w))
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return T * np.eye(3) + (1 - math.cos(a * T)) / a**2 * k + (T - math.sin(a * T) / a) / a**2 * (k @ k)


def rodrigues(r: np.ndarray) -> np.ndarray:
    a = float(np.linalg.norm(r))
    k = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    return np.eye(3) + math.sin(a) / a * k + (1 - math.cos(a)) / a**2 * (k @ k)


def run_direct(rows, bias=None, P=None, gnss=None, baro=None, mag=None, static=None, s=None, p_hist=None,
               p_every=1000, spec=None, cfg=CFG_LAB1, predict_every=1):
    s = sd.init_state(0.0, math.radians(LAT0), math.radians(LON0), H0, np.zeros(3), 0.0, 0.0, 0.0) if s is None else s
    P = np.zeros((em.NX, em.NX)) if P is None else P
    bias = np.zeros(kf.B_SIZE) if bias is None else bias
    out = np.empty((len(rows) + 1, aided.ROW_SIZE))
    counts = np.zeros((len(aided.KIND_NAMES), 2), dtype=np.int64)
    log = np.empty((40, 6))
    e = np.empty
    n, nl, _ = aided.run_aided(s, cfg, np.ascontiguousarray(rows[:, 0]), np.ascontiguousarray(rows[:, 1:4]),
                            np.ascontiguousarray(rows[:, 4:7]), e((0, 10)) if gnss is None else np.array(gnss, float),
                            e((0, 3)) if baro is None else np.array(baro, float),
                            e((0, 5)) if mag is None else np.array(mag, float),
                            e((0, 4)) if static is None else np.array(static, float),
                            (spec or em.ImuSpec()).as_array(), np.zeros(3), 0.0, math.nan, math.nan, math.nan, 5.0, predict_every, P, bias, out,
                            counts, log, np.zeros((0, em.NX, em.NX)) if p_hist is None else p_hist, p_every,
                            *NO_SMOOTHING)
    return s, P, bias, out[:n], counts, log[:nl]


def test_the_bias_estimates_are_subtracted_from_the_increments() -> None:
    """dtheta - (b_g + g_g) dt and dv - (b_a + g_a) dt (aided docstring): with the estimates preset and no
    measurements, the solution turns at -(b_g + g_g) and accelerates by C (f - b_a - g_a) + g: after T,
    C = exp([w x] T) and v = int_0^T exp([w x] t) dt (f - b_a - g_a) + [0, 0, g] T (constant rates)."""
    bias = np.zeros(kf.B_SIZE)
    bias[0:12] = [1e-3, 2e-3, 3e-3, 0.01, 0.02, 0.03, 4e-4, 5e-4, 6e-4, 0.004, 0.005, 0.006]
    s, P, b, out, counts, log = run_direct(imu(), bias=bias)
    w = -(bias[0:3] + bias[6:9])
    f = np.array([0.0, 0.0, -G_DATA]) - (bias[3:6] + bias[9:12])
    T = 0.1
    np.testing.assert_allclose(s[sd.S.C : sd.S.C + 9], rodrigues(w * T).ravel(), rtol=0, atol=1e-13)
    g0 = s[sd.S.G0]
    np.testing.assert_allclose(s[sd.S.V : sd.S.V + 3], integral_exp(w, T) @ f + [0.0, 0.0, g0 * T], rtol=0,
                               atol=1e-12)
    assert len(out) == N_ROWS and counts.sum() == 0


def test_samples_two_and_a_duplicate_row() -> None:
    """Two samples per attitude update: an output row per pair; a row not after the last (a repeated time) is
    skipped, and its increments are not counted anywhere (the rest window's mean rate stays that of the
    accepted rows)."""
    cfg = sd.make_config(samples=2, earth_model="none")
    rows = imu(wz=2e-3)
    rows = np.insert(rows, 5, rows[4] * [1, 100, 100, 100, 1, 1, 1], axis=0)  # t = 0.05 again, a wild rate
    spec = em.ImuSpec(gyro_bias=1e-3)
    s, P, b, out, counts, log = run_direct(rows, spec=spec, cfg=cfg, static=[[0.0, 0.1, 1.0, 1e-3]],
                                           P=np.diag([0.0] * 9 + [1e-6] * 3 + [0.0] * (em.NX - 12)))
    assert len(out) == 5
    np.testing.assert_allclose(out[:, 0], [0.02, 0.04, 0.06, 0.08, 0.1], atol=1e-15)
    assert counts[aided.K_ZARU].tolist() == [1, 0]
    assert b[kf.B_BG + 2] == pytest.approx(1e-3, rel=1e-9)  # half of the mean raw rate 2e-3


def test_propagation_uses_the_intervals_mean_attitude_and_force() -> None:
    """_propagate: F from the mean C (acc[0:9] / T) and f^n (acc[9:12] / T): over T = 0.5 s an accelerometer
    bias variance diag(1, 2, 3) reaches dv as T^2 C diag C^T, a tilt variance diag(4, 5, 0) as
    T^2 [f x] diag [f x]^T = T^2 g^2 diag(5, 4, 0) (f^n = [0, 0, -g]); laboratory mode (no Earth terms)."""
    s = sd.init_state(0.0, 0.7, 0.1, 100.0, np.zeros(3), 0.0, 0.0, 0.0)
    c = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    T, g = 0.5, 9.75
    acc = np.concatenate([(c * T).ravel(), [0.0, 0.0, -g * T], [T], np.zeros(6)])
    P = np.zeros((em.NX, em.NX))
    P[12:15, 12:15] = np.diag([1.0, 2.0, 3.0])
    P[0:3, 0:3] = np.diag([4.0, 5.0, 0.0])
    aided.flush_propagation(s, CFG_LAB1, em.ImuSpec().as_array(), P, acc, sd.GEOGRAPHIC)
    assert np.all(acc == 0.0)
    expect = T**2 * (c @ np.diag([1.0, 2.0, 3.0]) @ c.T + g**2 * np.diag([5.0, 4.0, 0.0]))
    np.testing.assert_allclose(P[3:6, 3:6], expect, rtol=1e-14, atol=0)
    # nothing pending: nothing happens
    P0 = P.copy()
    aided.flush_propagation(s, CFG_LAB1, em.ImuSpec().as_array(), P, np.zeros(aided.ACC_SIZE), sd.GEOGRAPHIC)
    np.testing.assert_array_equal(P, P0)


def test_propagation_with_the_earth_model() -> None:
    """With WGS-84 the gravity gradient couples dp_D into dv_D: P_dvD = (gamma' T)^2 P_dpD with
    gamma' = -d gamma/dh (exact height derivative of the typed Somigliana series), level at rest."""
    cfg = sd.make_config(samples=1)
    lat = math.radians(LAT0)
    s = sd.init_state(0.0, lat, 0.1, H0, np.zeros(3), 0.0, 0.0, 0.0)
    T = 1.0
    acc = np.concatenate([(np.eye(3) * T).ravel(), [0.0, 0.0, -G_DATA * T], [T], np.zeros(6)])
    P = np.zeros((em.NX, em.NX))
    P[8, 8] = 1.0
    aided.flush_propagation(s, cfg, em.ImuSpec().as_array(), P, acc, sd.GEOGRAPHIC)
    gg = -(gamma(lat, H0 + 1000.0) - gamma(lat, H0 - 1000.0)) / 2000.0
    assert P[5, 5] == pytest.approx(gg**2, rel=1e-9)


def test_skip_rules_of_a_fresh_and_a_continued_run() -> None:
    """Rows before the start are skipped (several of them); a fresh state uses a row at its own time, a continued
    one (after one update) skips the row at its time, used by the call before (aided.run_aided)."""
    lat, lon = math.radians(LAT0), math.radians(LON0)
    g_row = lambda t: [t, lat, lon, H0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0]  # noqa: E731
    b_row = lambda t: [t, H0, 1.0]  # noqa: E731
    m_row = lambda t: [t, 1.0, 0.0, 1.0, 0.1]  # noqa: E731
    P = np.diag([0.01, 0.01, 0.01, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0] + [0.0] * 12 + [1.0] + [0.0] * (em.NX - 22))
    kw = dict(gnss=[g_row(-2.0), g_row(-1.0), g_row(0.0), g_row(0.03)], baro=[b_row(-2.0), b_row(-1.0), b_row(0.0),
              b_row(0.03)], mag=[m_row(-2.0), m_row(-1.0), m_row(0.0), m_row(0.03)],
              static=[[-3.0, -2.0, 0.5, 1.0], [-2.0, -1.0, 0.5, 1.0], [0.0, 0.01, 0.5, 1.0]])
    s, P1, _, out, counts, log = run_direct(imu(5), P=P.copy(), **kw)
    assert counts[:, 0].tolist() == [2, 2, 2, 2, 1, 1, 0, 0, 0]  # the window [0, 0.01]: a ZUPT and the ZARU at 0.01
    assert counts[:, 1].tolist() == [0] * 9
    assert log[0, 0] == 0.0 and log[0, 1] == aided.K_GNSS_POS
    # continued after exactly one update: rows at its time (0.01) are skipped, later ones used
    s = sd.init_state(0.0, lat, lon, H0, np.zeros(3), 0.0, 0.0, 0.0)
    s, P2, _, out, counts, log = run_direct(imu(1), P=P.copy(), s=s)
    assert s[sd.S.NK] == 1.0
    kw = dict(gnss=[g_row(0.01), g_row(0.03)], baro=[b_row(0.01), b_row(0.03)], mag=[m_row(0.01), m_row(0.03)],
              static=[[0.005, 0.04, 0.005, 1.0]])
    s, P2, _, out, counts, log = run_direct(imu(5)[1:], P=P2, s=s, **kw)
    assert counts[:, 0].tolist() == [1, 1, 1, 1, 3, 1, 0, 0, 0]
    # one window before the start, then one at it
    _, _, _, _, counts, _ = run_direct(imu(3), P=P.copy(), static=[[-2.0, -1.0, 0.5, 1.0], [0.0, 0.02, 0.5, 1.0]])
    assert counts[aided.K_ZUPT].tolist() == [2, 0]
    np.testing.assert_allclose(log[:3, 0], [0.02, 0.03, 0.03], atol=1e-15)  # ZUPT at 0.02, then the fix at 0.03


def test_measurements_flush_the_pending_propagation() -> None:
    """predict_every 5: P is propagated at updates 5 and 10 only, and before each measurement; the NIS of a
    measurement at 0.03 s shows P at 0.03 s: position variance 1 + t^2 (sigma_vel 1), heading variance
    p + t^2 p_bz (z gyro bias), vertical velocity variance 1 + t^2 p_az (z accelerometer bias), gyro bias
    variance p + K^2 t (rate random walk), each with nu = 1 (or a rate of 1e-3 rad/s)."""
    t = 0.03
    lat, lon = math.radians(LAT0), math.radians(LON0)
    dn = 1.0 / (RN + H0)
    P = np.zeros((em.NX, em.NX))
    P[6:9, 6:9] = P[3:6, 3:6] = np.eye(3)
    _, _, _, _, c, log = run_direct(imu(5), P=P.copy(), predict_every=5,
                                    gnss=[[t, lat + dn, lon, H0, NAN, NAN, NAN, 1.0, 1.0, 1.0]])
    assert log[0, 2] == pytest.approx(1.0 / (2.0 + t * t), rel=1e-9)
    _, _, _, _, c, log = run_direct(imu(5), P=P.copy(), predict_every=5, baro=[[t, H0 - 1.0, 1.0]])
    assert log[0, 2] == pytest.approx(1.0 / (2.0 + t * t), rel=1e-9)
    P = np.zeros((em.NX, em.NX))
    P[2, 2], P[11, 11] = 1e-4, 1.0
    psi = 0.01
    _, _, _, _, c, log = run_direct(imu(5), P=P, predict_every=5,
                                    mag=[[t, math.cos(psi), -math.sin(psi), 1.0, 0.01]])
    assert log[0, 2] == pytest.approx(psi**2 / (1e-4 + t * t + 1e-4), rel=1e-9)
    P = np.zeros((em.NX, em.NX))
    P[5, 5], P[14, 14] = 1.0, 1.0
    _, _, _, _, c, log = run_direct(imu(5), P=P, predict_every=5, static=[[t - 1e-9, t, 1.0, 1.0]],
                                    s=sd.init_state(0.0, lat, lon, H0, np.array([0.0, 0.0, 1.0]), 0.0, 0.0, 0.0))
    assert log[0, 1] == aided.K_ZUPT and log[0, 2] == pytest.approx(1.0 / (2.0 + t * t), rel=1e-9)
    P = np.zeros((em.NX, em.NX))
    P[11, 11] = 1e-6
    spec = em.ImuSpec(gyro_rrw=math.sqrt(1e-5))
    rows = imu(5, wz=1e-3)
    _, _, _, _, c, log = run_direct(rows, P=P, predict_every=5, spec=spec, static=[[0.0, 0.035, 1.0, 1e-3]])
    assert log[-1, 1] == aided.K_ZARU and log[-1, 0] == pytest.approx(0.04, abs=1e-15)
    # P_bg at 0.04: 1e-6 + 1e-5 * 0.04; R: 1e-6 + 1e-5 * 0.03 / 3 (the walk over the window's 0.03 s of rows)
    assert log[-1, 2] == pytest.approx(1e-6 / (1e-6 + 4e-7 + 1e-6 + 1e-7), rel=1e-9)


def test_late_measurements_are_taken_back_along_the_velocity() -> None:
    """Moving at 1 m/s north and 1 m/s down: a fix and a baro height stamped 0.045 s, at the true position of that
    time, are applied at the update of 0.05 s with zero innovation (p(t_m) = p(t_k) - v (t_k - t_m))."""
    lat, lon = math.radians(LAT0), math.radians(LON0)
    s = sd.init_state(0.0, lat, lon, H0, np.array([1.0, 0.0, 1.0]), 0.0, 0.0, 0.0)
    P = np.diag([0.0] * 6 + [1.0] * 3 + [0.0] * 12 + [1.0] + [0.0] * (em.NX - 22))
    tm = 0.045
    s, P, b, out, c, log = run_direct(imu(), P=P, s=s, gnss=[[tm, lat + tm / (RN + H0), lon, H0 - tm, NAN, NAN, NAN,
                                                                1.0, 1.0, 1.0]], baro=[[tm, H0 - tm, 1.0]])
    assert c[0, 0] == 1 and c[2, 0] == 1
    assert log[0, 0] == tm and log[0, 2] < 1e-12 and log[1, 2] < 1e-12


def test_partial_rows_are_not_used() -> None:
    """A GNSS position needs lat, lon and h; a velocity vn and ve; a baro row its height; a magnetometer row
    all three components. Rows with any of them NaN are not used (nothing counted)."""
    lat, lon = math.radians(LAT0), math.radians(LON0)
    gnss = [[0.02, NAN, lon, H0, NAN, 0.0, 0.0, 1.0, 1.0, 1.0], [0.03, lat, NAN, H0, 0.0, NAN, 0.0, 1.0, 1.0, 1.0],
            [0.04, lat, lon, NAN, NAN, NAN, 0.0, 1.0, 1.0, 1.0]]
    baro = [[0.02, NAN, 1.0]]
    mag = [[0.02, NAN, 1.0, 1.0, 0.1], [0.03, 1.0, NAN, 1.0, 0.1], [0.04, 1.0, 0.0, NAN, 0.1]]
    P = np.diag([0.01] * 3 + [1.0] * 6 + [0.0] * 12 + [1.0] + [0.0] * (em.NX - 22))
    _, _, _, out, c, log = run_direct(imu(), P=P, gnss=gnss, baro=baro, mag=mag)
    assert c.sum() == 0 and len(log) == 0


def test_a_velocity_without_its_down_component_gives_the_horizontal_rows() -> None:
    """GPS_RAW_INT's ground speed and course carry no vertical velocity: a GNSS row with vn, ve and an empty vd
    is fused as the two horizontal rows (dof 2), in the batch as the live path does (aided.apply_gnss); at
    rest with P_vel = 1 and sigma_vel 1 its NIS is 0 (zero innovation)."""
    gnss = [[0.02, NAN, NAN, NAN, 0.0, 0.0, NAN, 1.0, 1.0, 1.0]]
    P = np.diag([0.01] * 3 + [1.0] * 6 + [0.0] * 12 + [1.0] + [0.0] * (em.NX - 22))
    _, _, _, _, c, log = run_direct(imu(), P=P, gnss=gnss)
    assert c[aided.K_GNSS_VEL, 0] == 1 and c.sum() == 1
    assert log[0, 1] == aided.K_GNSS_VEL and log[0, 3] == 2 and log[0, 2] < 1e-12


def test_a_late_magnetometer_sample_is_carried_to_the_update() -> None:
    """The body turns at 0.5 rad/s about z (laboratory mode, level); a sample stamped 0.025 s, between the updates
    at 0.02 and 0.03 s, sees the field [1, 0, 1] (declination 0) from the attitude of its own time, Rz(0.5 *
    0.025). Applied at 0.03 s it is carried back over 5 ms (kalman.mag_level): what is left is the first-order
    carry's (0.5 * 0.005)^2 / 2 rad, NIS below 1e-9 with P_yaw 0.01 and sigma 0.1. Carried over t_k + t_m
    (55 ms), or uncarried, it would be off by 0.5 * 0.05 or 0.5 * 0.005 rad: NIS 0.03 or 3e-4."""
    yaw_m = 0.5 * 0.025
    P = np.zeros((em.NX, em.NX))
    P[2, 2] = 0.01
    mag = [[0.025, math.cos(yaw_m), -math.sin(yaw_m), 1.0, 0.1]]
    _, _, _, _, c, log = run_direct(imu(wz=0.5), P=P, mag=mag)
    assert c[aided.K_MAG, 0] == 1 and log[0, 0] == 0.025
    assert log[0, 2] < 1e-9


@pytest.mark.parametrize("before", ["none", "accepted", "rejected"])
def test_magnetometer_h_takes_the_inclination_of_the_samples_before(before: str) -> None:
    """kalman.mag_heading's tilt terms use the mean tan(inclination) of the accepted samples before this one, its
    own only for the first. Level at rest, yaw 0, P = diag(phi_N 0.01), declination 0, sigma 0.1 rad: H_N =
    -tan I. Two samples [1, 0, 2] and [1, 0, 0.5] (tan I 2 and 0.5, nu 0: the state stays; the second uses
    2) before [cos 0.1, -sin 0.1, 3] (tan I 3, nu -0.1), which then uses 1.25; alone, or after a sample the
    gate rejects (2 rad off, sigma 0.01), it uses its own 3. Its NIS and the roll it leaves (-x_N) as the
    scalar Kalman algebra gives it (support.mag_by_hand)."""
    last = [0.05, math.cos(0.1), -math.sin(0.1), 3.0, 0.1]
    firsts = {"none": [], "accepted": [[0.03, 1.0, 0.0, 2.0, 0.1], [0.04, 1.0, 0.0, 0.5, 0.1]],
              "rejected": [[0.03, math.cos(2.0), -math.sin(2.0), 1.0, 0.01]]}
    P = np.zeros((em.NX, em.NX))
    P[0, 0] = 0.01
    s, _, _, _, c, log = run_direct(imu(wz=0.0), P=P, mag=firsts[before] + [last])
    assert c[aided.K_MAG, 1] == (1 if before == "rejected" else 0)
    assert log[-1, 0] == 0.05 and log[-1, 4] == 1.0
    nis, x_n = mag_by_hand(([2.0, 0.5] if before == "accepted" else []) + [3.0], 0.01, 0.01, -0.1)
    assert log[-1, 2] == pytest.approx(nis, rel=1e-9)
    cnb = s[sd.S.C : sd.S.C + 9].reshape(3, 3)
    assert math.atan2(cnb[2, 1], cnb[2, 2]) == pytest.approx(-x_n, rel=1e-9)


def test_log_rows_of_every_kind() -> None:
    """Each measurement's log row: t (its own, or the update's for ZUPT/ZARU), kind, NIS, dof, accepted, ratio
    (NIS and ratio worked by hand: P 1, R 1, nu 1 per measured axis; gate 5)."""
    lat, lon = math.radians(LAT0), math.radians(LON0)
    P = np.diag([0.0, 0.0, 1.0] + [1.0] * 3 + [0.0] * 3 + [0.0] * 12 + [1.0] + [0.0] * (em.NX - 22))
    gnss = [[0.02, NAN, NAN, NAN, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0]]
    rows = imu(wz=0.0)
    _, _, _, out, c, log = run_direct(rows, P=P, gnss=gnss)
    np.testing.assert_allclose(log[0], [0.02, aided.K_GNSS_VEL, 1.5, 3, 1, 1 / math.sqrt(2) / 5], rtol=1e-12)
    P = np.diag([0.0, 0.0, 0.01] + [0.0] * 18 + [0.0] * (em.NX - 21))
    _, _, _, out, c, log = run_direct(rows, P=P, mag=[[0.03, math.cos(0.1), -math.sin(0.1), 0.0, 0.1]])
    np.testing.assert_allclose(log[0], [0.03, aided.K_MAG, 0.5, 1, 1, 0.1 / math.sqrt(0.02) / 5], rtol=1e-12)
    P = np.diag([0.0] * 3 + [1.0] * 3 + [0.0] * 3 + [0.0] * 2 + [1e-6] + [0.0] * (em.NX - 12))
    s = sd.init_state(0.0, lat, lon, H0, np.array([0.0, 0.0, 1.0]), 0.0, 0.0, 0.0)
    _, _, _, out, c, log = run_direct(imu(wz=1e-3), P=P, s=s, static=[[0.0, 0.01, 1.0, 1e-3]])
    np.testing.assert_allclose(log[0], [0.01, aided.K_ZUPT, 0.5, 3, 1, 1 / math.sqrt(2) / 5], rtol=1e-9)
    np.testing.assert_allclose(log[1], [0.01, aided.K_ZARU, 0.5, 3, 1, 1e-3 / math.sqrt(2e-6) / 5], rtol=1e-9)


def test_rest_windows_in_a_row() -> None:
    """Four windows: [0.02, 0.04] (its start on an update: ZUPTs at 0.02, 0.03, 0.04), (0.045, 0.05] (a ZUPT and
    the ZARU at 0.05), (0.055, 0.085] ending between updates (ZUPTs at 0.06, 0.07, 0.08, the ZARU at 0.09 without
    a ZUPT), (0.091, 0.095] (no IMU row inside: no ZARU). The mean raw rates are those of each window's own
    rows: 2e-3 rad/s in the first two, 6e-3 in the third (the rows at 0.02 and 0.09 turn at 1 rad/s: outside)."""
    rows = imu()
    rows[:, 3] = 2e-3 * DT
    rows[1, 3] = rows[8, 3] = 1.0 * DT  # t = 0.02 and 0.09
    rows[5:8, 3] = 6e-3 * DT  # 0.06 .. 0.08
    P = np.diag([0.0] * 3 + [1.0] * 3 + [0.0] * 5 + [1.0] + [0.0] * (em.NX - 12))
    static = [[0.02, 0.04, 1.0, 1.0], [0.045, 0.05, 1.0, 1.0], [0.055, 0.085, 1.0, 1.0], [0.091, 0.095, 1.0, 1.0]]
    _, _, b, out, c, log = run_direct(rows, P=P, static=static)
    assert c[aided.K_ZUPT].tolist() == [7, 0] and c[aided.K_ZARU].tolist() == [3, 0]
    zupt_t = log[log[:, 1] == aided.K_ZUPT, 0]
    np.testing.assert_allclose(zupt_t, [0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08], atol=1e-15)
    zaru = log[log[:, 1] == aided.K_ZARU]
    np.testing.assert_allclose(zaru[:, 0], [0.04, 0.05, 0.09], atol=1e-15)
    # P_bgz 1, R 1: the first ZARU takes half of 2e-3 (P 1/2), the second a third of 2e-3 - 1e-3 (P 1/3), the third
    # a quarter of 6e-3 - 4/3 e-3: 2.5e-3
    assert b[kf.B_BG + 2] == pytest.approx(2.5e-3, rel=1e-9)
    np.testing.assert_allclose(zaru[:, 2], [4e-6 / 2, 1e-6 / 1.5, (14e-3 / 3) ** 2 / (4 / 3)], rtol=1e-9)


def test_direct_p_history_keeps_only_what_fits() -> None:
    """p_hist receives P after every p_every-th output row while it has room (run_aided docstring)."""
    P = np.diag([0.0] * 6 + [4.0] * 3 + [0.0] * (em.NX - 9))
    hist = np.full((2, em.NX, em.NX), -1.0)
    _, _, _, out, _, _ = run_direct(imu(), P=P, p_hist=hist, p_every=3)
    assert len(out) == N_ROWS
    assert hist[0, 6, 6] == 4.0 and hist[1, 6, 6] == 4.0


def test_zaru_variance_holds_the_gauss_markov_walk() -> None:
    """A Gauss-Markov part (sigma 1e-3 rad/s, tau 0.1 s) and a rate random walk (K^2 1e-5): the ZARU's variance
    holds (K^2 + 2 sigma^2 / tau) T / 3 over the window's T = 0.05 s (aided docstring). P_gg follows the scalar
    discretisation P <- Phi^2 P + (Phi^2 q + q) T / 2, Phi = 1 - T/tau + (T/tau)^2 / 2, q = 2 sigma^2 / tau
    (Groves 3.2.3, docs/filter.md "Model"); P_bg = 1e-6 + K^2 t. Each part takes its share P/S of the 1e-3."""
    spec = em.ImuSpec(gyro_bias=1e-3, gyro_gm=1e-3, gyro_tau=0.1, gyro_rrw=math.sqrt(1e-5))
    P = np.zeros((em.NX, em.NX))
    P[3:6, 3:6] = np.eye(3)
    P[11, 11] = P[17, 17] = 1e-6
    s, P, b, out, c, log = run_direct(imu(wz=1e-3), P=P, spec=spec, static=[[0.0, 0.05, 1.0, 1e-3]])
    q, a = 2e-6 / 0.1, 0.1
    phi = 1 - a + a * a / 2
    p_gg = 1e-6
    for _ in range(5):
        p_gg = phi * phi * p_gg + (phi * phi * q + q) * 0.01 / 2
    p_bg = 1e-6 + 1e-5 * 0.05
    S = p_bg + p_gg + 1e-6 + (1e-5 + 2e-5) * 0.05 / 3
    zaru = log[log[:, 1] == aided.K_ZARU][0]
    assert zaru[2] == pytest.approx(1e-6 / S, rel=1e-8)
    assert out[4, col("bg_z")] == pytest.approx(1e-3 * (p_bg + p_gg) / S, rel=1e-8)
    # afterwards the Gauss-Markov estimate decays by exp(-T/tau) per update: 5 more of 0.01 s
    assert b[kf.B_GG + 2] == pytest.approx(1e-3 * p_gg / S * math.exp(-0.5), rel=1e-8)
    assert b[kf.B_BG + 2] == pytest.approx(1e-3 * p_bg / S, rel=1e-8)


def test_after_k_update_accumulates_over_several_updates() -> None:
    """Without a propagation in between (predict_every 3), acc holds the sums of C T and C dv of both intervals."""
    cfg = CFG_LAB1
    s = sd.init_state(0.0, 0.7, 0.1, 100.0, np.zeros(3), 0.0, 0.0, 0.0)
    P = np.zeros((em.NX, em.NX))
    acc, sums = np.zeros(aided.ACC_SIZE), np.zeros(7)
    spec = em.ImuSpec().as_array()
    s[sd.S.T], s[sd.S.NK] = 0.25, 1
    sums[:] = [0, 0, 0, 1.0, 2.0, 3.0, 0.0]
    aided.after_k_update(s, cfg, spec, P, np.zeros(kf.B_SIZE), acc, sums, 3, sd.GEOGRAPHIC)
    s[sd.S.C : sd.S.C + 9] = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]  # turned 90 deg
    s[sd.S.T], s[sd.S.NK] = 0.75, 2
    sums[0:6] = [0, 0, 0, 1.0, 2.0, 3.0]
    aided.after_k_update(s, cfg, spec, P, np.zeros(kf.B_SIZE), acc, sums, 3, sd.GEOGRAPHIC)
    np.testing.assert_allclose(acc[0:9], [0.25, -0.5, 0.0, 0.5, 0.25, 0.0, 0.0, 0.0, 0.75], atol=1e-15)
    np.testing.assert_allclose(acc[9:12], [1.0 - 2.0, 2.0 + 1.0, 6.0], atol=1e-15)
    assert acc[12] == 0.75 and np.all(P == 0.0)


def test_push_rate_aided_velocity() -> None:
    """The live path hands the bias-corrected rates to the strapdown: after one k update of 0.02 s at constant
    rates, v = int_0^T exp([w x] t) dt (f - b_a) + [0, 0, g] T with w = w_raw - b_g (laboratory gravity)."""
    cfg = sd.make_config(samples=2, earth_model="none")
    s = sd.init_state(0.0, 0.7, 0.1, 100.0, np.zeros(3), 0.0, 0.0, 0.0)
    bias = np.zeros(kf.B_SIZE)
    bias[0:12] = [0.01, 0.02, 0.035, 0.1, 0.2, 0.3, 0.001, 0.002, 0.004, 0.01, 0.02, 0.03]
    w_raw, f_raw = np.array([0.5, -0.25, 0.125]), np.array([1.0, 2.0, -9.0])
    args = (em.ImuSpec().as_array(), np.zeros((em.NX, em.NX)), bias, np.zeros(aided.ACC_SIZE), np.zeros(7))
    for t in (0.01, 0.02):
        r = aided.push_rate_aided(s, cfg, *args, t, *w_raw, *f_raw, 1000, sd.GEOGRAPHIC)
    assert r == 1
    w = w_raw - (bias[0:3] + bias[6:9])
    f = f_raw - (bias[3:6] + bias[9:12])
    np.testing.assert_allclose(s[sd.S.C : sd.S.C + 9], rodrigues(w * 0.02).ravel(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(s[sd.S.V : sd.S.V + 3], integral_exp(w, 0.02) @ f + [0, 0, s[sd.S.G0] * 0.02],
                               rtol=0, atol=1e-9)


def test_small_things() -> None:
    """_record counts every rejection; filter_row's sigma of a bias sum below 1; _columns takes None as missing."""
    log, counts = np.zeros((4, 6)), np.zeros((len(aided.KIND_NAMES), 2), dtype=np.int64)
    n = 0
    for _ in range(3):
        n = aided._record(log, n, counts, 1.0, 2, 1, 9.0, 2.0, False)
    assert counts[2].tolist() == [0, 3] and n == 3
    P = np.zeros((em.NX, em.NX))
    for i in range(3):
        P[12 + i, 12 + i], P[18 + i, 18 + i], P[12 + i, 18 + i] = 0.25, 0.0625, 0.0
        P[9 + i, 9 + i], P[15 + i, 15 + i] = 0.04, 0.0
    out = np.zeros(aided.OUT_SIZE)
    aided.filter_row(P, np.zeros(kf.B_SIZE), out)
    np.testing.assert_allclose(out[29:35], [0.2] * 3 + [math.sqrt(0.3125)] * 3, rtol=1e-15)
    np.testing.assert_array_equal(aided._columns([[1.0, 2.0, None]], 3, (None, None, 0.5), "baro"),
                                  [[1.0, 2.0, 0.5]])


def test_navigate_aided_defaults_and_messages() -> None:
    """The defaults: grade consumer (turn-on sigmas 1 deg/s / 3 and 25 mg / 3, Gauss-Markov sigmas
    B / 0.6173642831 with B 10 deg/h and 0.1 mg: core/grades.py, IEEE Std 952 annex C), two samples per update,
    P propagated at every update, no covariance history; the messages name the input."""
    _, st = aided.navigate_aided(np.zeros((0, 7)), init(), earth_model="none")
    d = np.diag(st["P"])
    assert d[9] == pytest.approx((math.pi / 180 / 3) ** 2, rel=1e-12)
    assert d[12] == pytest.approx((25e-3 * 9.80665 / 3) ** 2, rel=1e-12)
    assert d[15] == pytest.approx((10 * math.pi / 180 / 3600 / 0.6173642831) ** 2, rel=1e-12)
    assert d[18] == pytest.approx((0.1e-3 * 9.80665 / 0.6173642831) ** 2, rel=1e-12)
    rows, st = aided.navigate_aided(imu(), init(sigma_vel=1.0), spec=em.ImuSpec(), earth_model="none")
    np.testing.assert_allclose(rows[:, 0], [0.02, 0.04, 0.06, 0.08, 0.1], atol=1e-15)
    np.testing.assert_allclose(rows[:, col("sigma_n")] ** 2, rows[:, 0] ** 2, rtol=1e-9)  # propagated each time
    assert st["P_history"].shape == (0, em.NX, em.NX)
    rows, st = nav(covariance_every=1, baro_drift=2.0)
    assert st["P_history"].shape == (N_ROWS, em.NX, em.NX)
    np.testing.assert_allclose([p[21, 21] for p in st["P_history"]], 4.0 * rows[:, 0], rtol=1e-9)  # drift^2 t
    for name, width, kw in (("gnss", 10, "gnss"), ("baro", 3, "baro"), ("mag", 5, "mag"), ("static", 4, "static")):
        with pytest.raises(ValueError, match=rf"^{name}: at most {width} columns, got {width + 1}$"):
            nav(**{kw: [[0.01] * (width + 1)]})
        with pytest.raises(ValueError, match=rf"^{name}: rows must be sorted by time$"):
            nav(**{kw: [[0.02] + [1.0] * (width - 1), [0.01] + [1.0] * (width - 1)]})
    with pytest.raises(ValueError):
        nav(lever_arm=(1.0, 2.0, 3.0, 4.0))


def test_two_samples_per_update_sum_the_increments() -> None:
    """Two samples per update: the interval's rate (for the lever arm) and specific force (for the propagation)
    are the sums of both samples' increments over the interval. A tilt variance p reaches the north velocity as
    g^2 t^2 p (phi x f^n with f^n = [0, 0, -g]); a velocity fix at 0.06 s with the lever arm moves v half way to
    v_m - C (w x l) (yaw 0.1 * 0.06 rad)."""
    rows, st = nav(init=init(sigma_level=math.degrees(1e-3)), samples=2)
    np.testing.assert_allclose(rows[:, col("sigma_vn")] ** 2, G_DATA**2 * rows[:, 0] ** 2 * 1e-6, rtol=1e-9)
    assert st["P"][3, 1] == pytest.approx(-G_DATA * 0.1 * 1e-6, rel=1e-9)  # cov(dv_N, phi_E) = f_D p t, f_D = -g
    v_m = np.array([0.4, -0.2, 0.1])
    rows, st = nav(imu(wz=0.1), gnss=[[0.06, NAN, NAN, NAN, *v_m, 2.0, 2.0, 1.0]], init=init(sigma_vel=1.0),
                   lever_arm=(1.0, 0.0, 0.0), samples=2)
    cwl = 0.1 * np.array([-math.sin(0.006), math.cos(0.006), 0.0])
    np.testing.assert_allclose(rows[2, 4:7], (v_m - cwl) / 2, rtol=0, atol=1e-9)


def test_the_nis_log_holds_every_measurement() -> None:
    """navigate_aided sizes the log for two rows per GNSS fix, one per baro and magnetometer row, one ZUPT per
    update and one ZARU per rest window: 13 fixes, 5 baro, 7 magnetometer rows and ten one-update windows
    ((t - 0.005, t], a ZUPT and a ZARU each) fill it but for one row, and every one is logged."""
    t = [round(0.01 * k, 12) for k in range(1, 11)]
    gnss = [[t[min(k, 9)], LAT0, LON0, H0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0] for k in range(13)]
    baro = [[t[k], H0, 1.0] for k in range(5)]
    mag = [[t[k], 1.0, 0.0, 1.0, 1.0] for k in range(7)]
    static = [[tk - 0.005, tk, 1.0, 1.0] for tk in t]
    rows, st = nav(gnss=sorted(gnss), baro=baro, mag=mag, static=static, spec=em.ImuSpec(gyro_bias=1.0),
                   init=init(sigma_pos=1.0, sigma_vel=1.0, sigma_level=1.0, sigma_yaw=1.0), baro_offset_sigma=1.0)
    total = sum(a + r for a, r in st["counts"].values())
    assert total == 2 * 13 + 5 + 7 + 10 + 10
    assert len(st["nis"]) == total


def test_module_level_names_and_kinds() -> None:
    """The constants mutmut does not mutate, by value (aided.py's module docstring and LOG_COLUMNS)."""
    assert (aided.K_GNSS_POS, aided.K_GNSS_VEL, aided.K_BARO, aided.K_MAG, aided.K_ZUPT, aided.K_ZARU,
            aided.K_MAG_DISTURBED, aided.K_WHEEL, aided.K_NHC) == tuple(range(9))
    assert aided.KIND_NAMES == ("gnss_pos", "gnss_vel", "baro", "mag", "zupt", "zaru", "mag_disturbed", "wheel", "nhc")
    # the magnetometer's checks (PX4 EKF2's EKF2_MAG_CHK_INC 20 deg, EKF2_MAG_CHK_STR 0.2 gauss) and reset
    assert aided.MAG_INCL_GATE == math.radians(20.0) and aided.MAG_STRENGTH_GATE == 0.2
    assert aided.MAG_RESET_AFTER == 50 and kf.MAG_STATS == 5 and aided.ACC_SIZE == 19
    assert aided.ROW_SIZE == 35 + 6 + 6 + 12 + 12 + 6 + 2 and aided.STATE_BLOCKS == ("SG", "SA", "MG", "MA", "MB",
                                                                                     "WS")
    assert aided.STATE_COLUMNS[-2:] == ("ws", "sigma_ws")  # a single value: the block's name alone
    assert aided.STATE_COLUMNS[12:24] == ("mg_xy", "mg_xz", "mg_yx", "mg_yz", "mg_zx", "mg_zy", "sigma_mg_xy",
                                          "sigma_mg_xz", "sigma_mg_yx", "sigma_mg_yz", "sigma_mg_zx", "sigma_mg_zy")
    assert aided.STATE_COLUMNS[:3] == ("sg_x", "sg_y", "sg_z") and aided.STATE_COLUMNS[-5:-2] == (
        "sigma_mb_x", "sigma_mb_y", "sigma_mb_z")
    assert aided.GNSS_COLUMNS == ("t", "lat", "lon", "h", "vn", "ve", "vd", "sigma_h", "sigma_v", "sigma_vel")
    assert aided.BARO_COLUMNS == ("t", "h", "sigma") and aided.MAG_COLUMNS == ("t", "mx", "my", "mz", "sigma")
    assert aided.STATIC_COLUMNS == ("t0", "t1", "sigma_v", "sigma_w")
    assert aided.LOG_COLUMNS == ("t", "kind", "nis", "dof", "accepted", "ratio")
    assert aided.OUT_SIZE == 35 and aided.OUT_COLUMNS[:14] == ("t", "lat", "lon", "h", "vn", "ve", "vd", "roll",
                                                               "pitch", "yaw", "qw", "qx", "qy", "qz")


def test_rest_windows_sharing_their_ends_log_every_update() -> None:
    """Five windows end to end over ten rows at 100 Hz, one update per row: each shared end gets the ZUPT of both
    windows (their starts count, docs/filter.md), so 10 + 4 ZUPTs and 5 ZARUs, and the NIS log holds a row for
    each of the 19 (it was sized for one ZUPT per update and dropped the last rows)."""
    static = [[0.0, 0.02], [0.02, 0.04], [0.04, 0.06], [0.06, 0.08], [0.08, 0.10]]
    _, st = nav(static=static, init=init(sigma_vel=1.0))
    counts = st["counts"]
    assert sum(counts["zupt"]) == 14 and sum(counts["zaru"]) == 5
    log = st["nis"]
    assert len(log) == 19
    np.testing.assert_allclose(np.sort(log[log[:, 1] == aided.K_ZUPT, 0]),
                               np.sort(np.r_[np.arange(1, 11) * DT, [0.02, 0.04, 0.06, 0.08]]), atol=1e-15)


def test_a_rejected_measurement_leaves_no_trace() -> None:
    """A fix 1 km off (position rejected by the gate) with a velocity that alone would pass: the velocity is
    counted rejected with its position (a glitch), and P, the solution and the rows equal those of the run
    without that row bit for bit, although it fell between the propagations (aided.keep_or_undo). A rejected
    baro sample likewise; an accepted fix does change P."""
    P = np.diag([1e-4] * 3 + [0.01] * 3 + [1.0] * 3 + [1e-6] * 12 + [1.0] + [0.0] * (em.NX - 22))
    lat0, lon0 = math.radians(LAT0), math.radians(LON0)
    good = [0.045, lat0, lon0, H0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.1]
    far = [0.055, lat0 + 1000.0 / RN, lon0, H0, 0.05, 0.0, 0.0, 1.0, 1.0, 0.1]
    ref = run_direct(imu(), P=P.copy(), predict_every=3, gnss=[good])
    got = run_direct(imu(), P=P.copy(), predict_every=3, gnss=[good, far], baro=[[0.065, H0 + 500.0, 0.5]])
    assert got[4][aided.K_GNSS_POS].tolist() == [1, 1] and got[4][aided.K_GNSS_VEL].tolist() == [1, 1]
    assert got[4][aided.K_BARO].tolist() == [0, 1]
    np.testing.assert_array_equal(got[1], ref[1])  # P
    np.testing.assert_array_equal(got[0], ref[0])  # the state
    np.testing.assert_array_equal(got[3], ref[3])  # the rows
    near = [0.055, lat0 + 0.5 / RN, lon0, H0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.1]
    moved = run_direct(imu(), P=P.copy(), predict_every=3, gnss=[good, near])
    assert not np.array_equal(moved[1], ref[1])


def test_apply_gnss_reports_each_part_of_a_fix() -> None:
    """aided.apply_gnss on a level vehicle at rest at the fix's position: position and velocity accepted (3 rows
    each, zero innovation); an empty down velocity gives 2 rows; a fix 1 km off fails the gate and its
    velocity is left out (GLITCH) with P untouched by it; a fix without a position still fuses its velocity;
    nothing finite: ABSENT twice, nothing changed."""
    cfg = sd.make_config()
    lat, lon = math.radians(LAT0), math.radians(LON0)

    def fresh():
        s = sd.init_state(0.0, lat, lon, H0, np.zeros(3), 0.0, 0.0, 0.0)
        return s, np.zeros(kf.B_SIZE), np.diag([1e-4] * 3 + [1.0] * 3 + [1e-12, 1e-12, 1.0] + [1e-6] * (em.NX - 9))

    def fix(s, bias, P, la, lo, h, v):
        return aided.apply_gnss(s, cfg, bias, P, la, lo, h, np.asarray(v, float), np.zeros(3), np.zeros(3), 0.0,
                                0.01, 1.0, 1.0, 0.1, 5.0, kf.ALL)

    s, bias, P = fresh()
    ps, pr, pnis, _, vs, vr, vnis, _ = fix(s, bias, P, lat, lon, H0, [0.0, 0.0, 0.0])
    assert (ps, pr, vs, vr) == (aided.ACCEPTED, 3, aided.ACCEPTED, 3) and pnis < 1e-12 and vnis < 1e-12
    s, bias, P = fresh()
    assert fix(s, bias, P, lat, lon, H0, [0.0, 0.0, math.nan])[4:6] == (aided.ACCEPTED, 2)
    s, bias, P = fresh()
    P0 = P.copy()
    far = lat + 1000.0 / A  # ~1 km north: 1000 sigma
    ps, _, _, _, vs, vr, vnis, vratio = fix(s, bias, P, far, lon, H0, [0.0, 0.0, 0.0])
    assert (ps, vs, vr, vnis, vratio) == (aided.REJECTED, aided.GLITCH, 0, 0.0, 0.0)
    np.testing.assert_array_equal(P, P0)
    s, bias, P = fresh()
    ps, pr, _, _, vs, vr, _, _ = fix(s, bias, P, math.nan, lon, H0, [0.0, 0.0, 0.0])
    assert (ps, pr, vs, vr) == (aided.ABSENT, 0, aided.ACCEPTED, 3)
    s, bias, P = fresh()
    s0, P0 = s.copy(), P.copy()
    assert fix(s, bias, P, math.nan, math.nan, math.nan, [math.nan] * 3) == (aided.ABSENT, 0, 0.0, 0.0) * 2
    np.testing.assert_array_equal(s, s0)
    np.testing.assert_array_equal(P, P0)


def test_mag_stats_start_empty_with_the_hard_iron_variance() -> None:
    P = np.diag(np.arange(1.0, em.NX + 1.0))
    incl = aided.mag_stats(P)
    assert incl.shape == (kf.MAG_STATS,) and not incl[:4].any() and incl[4] == P[em.X_MB, em.X_MB] == em.X_MB + 1.0


def test_smoothing_a_constant_position_gives_every_row_the_final_estimate() -> None:
    """At rest without process noise (an ideal IMU, no velocity or attitude uncertainty) the position error is
    a constant seen by the prior (0 m, sigma 2 m) and two fixes (3 m then 6 m north, 1.5 then -3 m east,
    sigma 2 m): given all three, the north error at every time is their mean, 3 m, east -0.5 m, with variance
    4/3 (the information sum). The forward rows step from 0 to 1.5 to 3 m north, sigma 2, sqrt 2, sqrt(4/3);
    the smoothed rows are 3 m and sqrt(4/3) throughout. Epochs: the first row and the two fixes'."""
    m_n, m_e = RN + H0, (RE + H0) * math.cos(math.radians(LAT0))
    gnss = [[0.03, LAT0 + math.degrees(3.0 / m_n), LON0 + math.degrees(1.5 / m_e), H0, NAN, NAN, NAN, 2.0, 2.0, 0.3],
            [0.07, LAT0 + math.degrees(6.0 / m_n), LON0 + math.degrees(-3.0 / m_e), H0, NAN, NAN, NAN, 2.0, 2.0, 0.3]]
    fwd, _ = nav(gnss=gnss, init=init(sigma_pos=2.0), file_units=False)
    smo, st = nav(gnss=gnss, init=init(sigma_pos=2.0), file_units=False, smooth=True)
    north = lambda rows: (rows[:, 1] - math.radians(LAT0)) * m_n  # noqa: E731
    east = lambda rows: (rows[:, 2] - math.radians(LON0)) * m_e  # noqa: E731
    np.testing.assert_allclose(north(fwd), [0.0] * 2 + [1.5] * 4 + [3.0] * 4, rtol=0, atol=1e-6)
    np.testing.assert_allclose(north(smo), 3.0, rtol=0, atol=1e-6)
    np.testing.assert_allclose(east(smo), -0.5, rtol=0, atol=1e-6)
    np.testing.assert_allclose(smo[:, col("sigma_n")], math.sqrt(4.0 / 3.0), rtol=1e-12, atol=0)
    np.testing.assert_allclose(smo[:, col("sigma_e")], math.sqrt(4.0 / 3.0), rtol=1e-12, atol=0)
    np.testing.assert_allclose(fwd[:, col("sigma_n")], [2.0] * 2 + [math.sqrt(2.0)] * 4 + [math.sqrt(4 / 3)] * 4,
                               rtol=1e-12, atol=0)
    assert st["epochs"] == 3 and st["singular"] == 0
    np.testing.assert_array_equal(smo[-1], fwd[-1])
    np.testing.assert_array_equal(smo[:, 4:14], fwd[:, 4:14])  # nothing else moves: velocity, attitude


def full_spec() -> np.ndarray:
    """Every sensor error of the model estimated: Gauss-Markov parts, scale factors, misalignments, the odometer,
    a barometer drift and a camera frame's walk."""
    return em.make_spec("consumer", baro_drift=0.01, scale_factors=True, misalignment=True, wheel_scale=0.02,
                        vision_drift=0.01, vision_yaw_drift=1e-4)


def moving_f(spec: np.ndarray) -> np.ndarray:
    """F of a turning, climbing, accelerating vehicle (errmodel.system_matrix and motion_columns)."""
    c = euler_to_dcm(0.2, -0.1, 2.0)
    F = em.system_matrix(c, np.array([12.0, -5.0, 1.0]), 0.8, 300.0, np.array([0.5, -1.0, -9.5]), spec, True)
    em.motion_columns(F, c, np.array([0.1, -0.2, 0.3]), np.array([0.5, 0.2, -9.8]), spec)
    return F


def test_a_sensor_errors_row_of_f_is_at_most_its_own_diagonal() -> None:
    """What predict_active leaves out rests on this: every error from the gyro bias on changes by itself alone
    (random constants, walks, first-order Gauss-Markov), with every error of the model estimated."""
    F = moving_f(full_spec())
    off = F[em.X_SENSORS:].copy()
    for i in range(off.shape[0]):
        off[i, em.X_SENSORS + i] = 0.0
    assert not off.any()
    assert F[:em.X_SENSORS, em.X_SENSORS:].any()  # the navigation errors do depend on them


@pytest.mark.parametrize("estimated", ["some", "all", "walking"])
def test_predict_active_is_the_full_propagation(estimated: str) -> None:
    """P propagated over the states with variance or noise equals Phi P Phi^T + Qd over all NX (the same
    products less exact zeros: to 1e-15 of the largest element), its rows of the states left out stay exactly
    zero; ``some``: the camera frame, scale factors and misalignments not estimated (zero rows, no noise);
    ``all``: nothing left out; ``walking``: the camera frame's states with a walk but no variance yet."""
    rng = np.random.default_rng(3)
    if estimated == "some":
        spec = em.make_spec("consumer", baro_drift=0.01)
        live = np.r_[0:em.X_SG, em.X_MB:em.X_MB + 3]  # a hard iron estimated: variance, no noise
    elif estimated == "walking":  # a camera frame not placed yet walks: no variance, driving noise
        spec = em.make_spec("consumer", vision_drift=0.01, vision_yaw_drift=1e-4)
        live = np.r_[0:em.X_SG]
    else:
        spec = full_spec()
        live = np.arange(em.NX)
    F = moving_f(spec)
    a = rng.normal(size=(live.size, live.size))
    P = np.zeros((em.NX, em.NX))
    P[np.ix_(live, live)] = a @ a.T * 1e-2
    want = P.copy()
    phi, qd = em.discretise(F, spec, 0.01)
    kf.predict(want, phi, qd)
    got = P.copy()
    aided.predict_active(got, F, em.noise_density(spec), 0.01)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15 * np.abs(want).max())
    dead = np.setdiff1d(np.arange(em.NX), live)
    dead = dead[em.noise_density(spec)[dead] == 0.0]
    assert not got[dead].any() and not got[:, dead].any()
    assert (estimated == "all") == (dead.size == 0)
    if estimated == "walking":  # it grew by its walk over the step (Qd's diagonal: q T to first order)
        assert got[em.X_VP, em.X_VP] == pytest.approx(1e-4 * 0.01, rel=1e-12)
        assert got[em.X_VY, em.X_VY] == pytest.approx(1e-8 * 0.01, rel=1e-12)
