"""The size effect (accelerometers at different points of the IMU): simulator and compensation.

Classic coning at rest (half-angle b, W rad/s) has the body rate
``w = [-W sin b sin Wt, W sin b cos Wt, -W (1 - cos b)]`` (docs/simulator.md).
An axis-i accelerometer at ``r_i = d e_i`` senses component i of
``dw/dt x r_i + w x (w x r_i)``; the first averages to zero over whole cone
periods, the second is ``d (w_i^2 - |w|^2)``, so the mean added specific
force over whole periods is (plus Earth-rate cross terms that average out
and ``Omega^2 d`` ~ 5e-9 d)

    x, y: -d (W^2 sin^2 b / 2 + W^2 (1 - cos b)^2)        z: -d W^2 sin^2 b

a rectified, bias-like error. Free inertial at rest, heading north, vertical
held, a constant body bias (b_x, b_y) moves the position by
``(b_x, b_y) t^2 / 2`` (Schuler and Coriolis corrections of relative order
(w_s t)^2 / 12 = 1e-4 and Omega t = 2e-3 over 30 s). The compensation
(core/size_effect.py) leaves a residual of relative order (W h)^2 / 12 = 7e-4
at 7.5 Hz and 500 Hz, so the compensated run must come within a few per
mille of the run without the effect.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core.runner import navigate
from mavins.core.size_effect import compensate
from sim.generate import generate
from sim.scenarios import load
from sim.accel_offsets import size_effect_dv

HALF_ANGLE = 2.0  # deg
FREQ = 7.5  # Hz
RATE = 500.0
DURATION = 30.0  # whole cone periods: 225
D = 0.03  # m, each accelerometer 3 cm from the reference point along its own axis
SCENARIO = f"""
description = "classic coning at rest for the size effect"
[start]
lat = 30.0
lon = 10.0
h = 100.0
[imu]
rate = {RATE}
duration = {DURATION}
[[segments]]
kind = "static"
duration = {DURATION}
[[perturbations]]
kind = "coning"
half_angle = {HALF_ANGLE}
freq = {FREQ}
"""


@pytest.fixture(scope="module")
def coning(tmp_path_factory: pytest.TempPathFactory) -> object:
    path = tmp_path_factory.mktemp("scn") / "coning.toml"
    path.write_text(SCENARIO)
    return generate(load(str(path))).exact


def expected_bias() -> np.ndarray:
    b, w = math.radians(HALF_ANGLE), 2.0 * math.pi * FREQ
    xy = -D * (w * w * math.sin(b) ** 2 / 2.0 + w * w * (1.0 - math.cos(b)) ** 2)
    return np.array([xy, xy, -D * w * w * math.sin(b) ** 2])


def test_simulated_size_effect_is_the_rectified_centripetal_term(coning: object) -> None:
    extra = size_effect_dv(coning, D * np.eye(3))
    mean = extra.sum(axis=0) / DURATION
    assert np.allclose(mean, expected_bias(), rtol=1e-4)
    assert abs(expected_bias()[0]) > 1e-2  # 4.1 mg: an error worth compensating
    # An accelerometer at the reference point feels nothing; one across its axis only the cross terms.
    assert np.array_equal(size_effect_dv(coning, np.zeros((3, 3))), np.zeros_like(extra))


def horizontal_error(exact: object, dv: np.ndarray) -> np.ndarray:
    sol = navigate(exact.t, exact.dtheta, dv, exact.init(), samples=2, vertical="hold")
    lat0, lon0 = exact.truth[0, 1], exact.truth[0, 2]
    r = 6378137.0
    return np.array([math.radians(sol[-1, 1] - lat0) * r, math.radians(sol[-1, 2] - lon0) * r * math.cos(math.radians(lat0))])


def test_compensation_removes_the_size_effect(coning: object) -> None:
    arms = D * np.eye(3)
    extra = size_effect_dv(coning, arms)
    clean = horizontal_error(coning, coning.dv)
    raw = horizontal_error(coning, coning.dv + extra)
    fixed = horizontal_error(coning, compensate(coning.t0, coning.t, coning.dtheta, coning.dv + extra, arms))
    # The cone turns the body about the vertical by -W (1 - cos b) t (49 deg in 30 s) and tilts its
    # mean z axis by b: the expected shift carries the body-frame bias through the true attitude,
    # p = double integral of C_b^n(t) b (Schuler and Coriolis: below 1e-3 of it over 30 s).
    q = coning.truth[1:, 10:14]
    w, x, y, z = q.T
    c = np.stack([np.stack([w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                  np.stack([2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)], -1)], 1)
    acc = c @ expected_bias()
    vel = np.cumsum(acc, axis=0) / RATE
    expected = vel.sum(axis=0) / RATE
    shift = raw - clean
    assert np.hypot(*(shift - expected)) < 0.01 * np.hypot(*expected)
    assert np.hypot(*expected) > 20.0  # metres: what the effect does uncompensated in 30 s
    assert np.hypot(*(fixed - clean)) < 3e-3 * np.hypot(*shift)
