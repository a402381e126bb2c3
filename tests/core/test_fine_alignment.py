"""Fine alignment at rest (textbook ch. 4): coarse alignment over the first seconds, then
the filter with zero-velocity and zero-angular-rate updates (and the magnetometer for
MEMS) for 5 minutes, against the textbook's alignment limits.

Limits (static alignment, any estimator): the level error is the horizontal
accelerometer bias over g (a tilt and a bias give the same specific force), and the
heading error of gyrocompassing is the east gyro bias over the horizontal Earth rate,
``psi = -b_E / (Omega cos L)`` (the bias looks like the Earth rate of a heading error).
The part the averaging cannot remove in a time T is the gyro's angle random walk,
``ARW / (Omega cos L sqrt(T))``. Expected values come from the simulator's true biases
and the grade's datasheet figures, never from the filter.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from support import quat_error, quat_zyx, wrap_rad

from mavins.core import aided, align
from mavins.core.grades import grade_figures
from sim import aiding, errors
from sim.generate import generate
from sim.scenarios import Scenario, load

OMEGA = 7.292115e-5  # rad/s, WGS-84 Earth rate (typed from the standard)
G = 9.80665
LAT = 45.0
T_COARSE = 5.0  # s of coarse alignment
T_FINE = 300.0  # s of fine alignment
RATE = 100.0
WINDOW = 5.0  # s per zero-angular-rate update


@pytest.fixture(scope="module")
def rest():
    sc = load("static")
    doc = dict(sc.doc, start=dict(sc.doc["start"], lat=LAT))
    return generate(Scenario("static45", sc.source, doc), duration=T_COARSE + T_FINE, rate=RATE, seed=0,
                    grade="ideal")


def _model(grade: str) -> errors.ImuErrorModel:
    """The grade's random errors; scale factor, misalignment, g-sensitivity play no part at rest and level."""
    m = errors.grade(grade)
    zero = ((0.0,) * 3,) * 3
    strip = lambda s: dataclasses.replace(s, scale_factor_ppm=(0.0,) * 3, misalignment=zero)
    return dataclasses.replace(m, gyro=strip(m.gyro), accel=strip(m.accel), g_sensitivity=zero,
                               drop_probability=0.0, jitter_sigma=0.0)


def _align(rest, grade: str, seed: int, mag: np.ndarray | None):
    """Coarse alignment, then fine: returns (final filter row, attitude error (rad, NED), true
    horizontal gyro and accelerometer biases in NED at the end)."""
    ex = rest.exact
    model = _model(grade)
    t, dth, dv, _ = errors.apply(model, ex.t, ex.dtheta, ex.dv, seed, t_start=ex.t0)
    bg, ba = errors.bias_states(model, ex.t, seed, t_start=ex.t0)
    k = round(T_COARSE * RATE)
    dt = t[k - 1] - ex.t0
    roll, pitch = align.level(dv[:k].sum(axis=0) / dt)
    if mag is None:
        yaw = align.gyrocompass(dth[:k].sum(axis=0) / dt, roll, pitch)
    else:
        cfg = aiding.MagConfig()
        yaw = align.mag_heading(mag[mag[:, 0] <= t[k - 1], 1:4].mean(axis=0), roll, pitch,
                                math.radians(cfg.declination))
    if mag is not None:
        # MEMS: the coarse window also calibrates the gyro bias, mean rate minus the Earth rate in the
        # coarse attitude (what `mavins run --gyro-bias estimate` does); the filter refines it
        c_nb = _c_nb(quat_zyx(roll, pitch, yaw))
        w_ie = OMEGA * np.array([math.cos(math.radians(LAT)), 0.0, -math.sin(math.radians(LAT))])
        b0 = dth[:k].sum(axis=0) / dt - c_nb.T @ w_ie
        dth = dth - np.diff(np.concatenate(([ex.t0], t)))[:, None] * b0
    truth0 = ex.truth[k]  # the state at t[k - 1]
    f = grade_figures(grade)
    init = {"t": float(t[k - 1]), "lat": truth0[1], "lon": truth0[2], "h": truth0[3], "vn": 0.0, "ve": 0.0,
            "vd": 0.0, "roll": math.degrees(roll), "pitch": math.degrees(pitch), "yaw": math.degrees(yaw),
            "sigma_pos": 0.1, "sigma_vel": 0.01,
            "sigma_level": max(math.degrees(f.accel.turn_on_sigma / G), 1e-3),
            "sigma_yaw": 10.0 if mag is not None else 1.0}
    static = [(t[k - 1] + WINDOW * i + (0.01 if i else 0.0), t[k - 1] + WINDOW * (i + 1))
              for i in range(int(T_FINE / WINDOW))]
    imu = np.column_stack([t, dth, dv])[k:]
    kw = {}
    if mag is not None:
        kw = {"mag": mag[mag[:, 0] > t[k - 1]], "declination": aiding.MagConfig().declination}
    rows, _ = aided.navigate_aided(imu, init, static=static, spec=grade, file_units=False, **kw)
    last = k + 2 * rows.shape[0]  # row index of the last attitude update
    q_true = ex.truth[last, 10:14]
    phi = quat_error(rows[-1:, 10:14], q_true[None, :])[0]
    c_nb = _c_nb(q_true)
    return rows[-1], phi, c_nb @ bg[last - 1], c_nb @ ba[last - 1]


def _c_nb(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_navigation_grade_gyrocompasses_to_the_textbook_limit(rest, seed: int) -> None:
    row, phi, b_g, _ = _align(rest, "navigation", seed, mag=None)
    f = grade_figures("navigation").gyro
    w_h = OMEGA * math.cos(math.radians(LAT))
    sigma_bias = math.hypot(f.turn_on_sigma, f.gm_sigma) / w_h  # the limit as a 1-sigma over the bias population
    sigma_noise = f.random_walk / (w_h * math.sqrt(T_FINE))  # what 5 min of averaging leaves
    sigma_theory = math.hypot(sigma_bias, sigma_noise)
    # the filter's heading 1-sigma: the textbook figure, to within what the discrete 5 s
    # windows and the 1 deg prior change (their share is below 20 %)
    assert 0.8 * sigma_theory < row[22] < 1.2 * sigma_theory, (math.degrees(row[22]), math.degrees(sigma_theory))
    # the actual heading error is the textbook's -b_E / (Omega cos L) of this unit, up to the noise part
    limit = -b_g[1] / w_h
    assert abs(wrap_rad(phi[2]) - limit) < 3.0 * sigma_noise, (math.degrees(phi[2]), math.degrees(limit))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_consumer_grade_levels_within_twice_its_limit_heading_from_the_magnetometer(rest, seed: int) -> None:
    mag = aiding.magnetometer(dataclasses.replace(rest, seed=seed), aiding.MagConfig())
    cfg = aiding.MagConfig()
    sig_mag = math.degrees(cfg.sigma / (cfg.strength * math.cos(math.radians(cfg.inclination))))
    mag = np.column_stack([mag, np.full(mag.shape[0], sig_mag)])
    row, phi, _, _ = _align(rest, "consumer", seed, mag=mag)
    # level: the limit b_a / g as a 1-sigma over the grade's accelerometers (turn-on bias), which the
    # filter may not beat (tilt and bias are one measurement at rest) and must reach within 2x, and the
    # actual error within 3 of the filter's sigma
    limit = grade_figures("consumer").accel.turn_on_sigma / G
    for axis in (0, 1):
        assert 0.5 * limit < row[20 + axis] < 2.0 * limit, (axis, math.degrees(row[20 + axis]), math.degrees(limit))
        assert abs(phi[axis]) < 3.0 * row[20 + axis], (axis, math.degrees(phi[axis]), math.degrees(row[20 + axis]))
    # heading from the magnetometer: within 3 sigma of the filter, whose sigma carries the tilt error the
    # magnetometer cannot tell from heading (tan(I) times the tilt about magnetic north, which at rest
    # nothing else tells apart: kalman.mag_heading's H, docs/filter.md "Magnetometer")
    assert abs(wrap_rad(phi[2])) < 3.0 * row[22], (math.degrees(phi[2]), math.degrees(row[22]))
