"""A dual-antenna GNSS heading (GPS_RAW_INT ``yaw``/``hdg_acc``) as alignment source and as a measurement.

The simulator's multicopter flight at consumer grade (no magnetometer, gyros far too coarse to
gyrocompass), ``--heading auto``, GNSS aiding at 5 Hz with a heading: the vehicle's true yaw plus N(0,
sigma), sigma 0.5 deg, the 1-sigma the message states, as `mavins sim --stream --gnss-heading 0.5` sends
it. Expected values: the simulator's truth and the chi-square law. The engine must align on that heading
(no heading typed in, no waiting for motion) and publish a yaw whose errors its own 1-sigma describes: the
normalised yaw error squared, averaged over the runs at each 1 Hz epoch and then over the epochs, in the
two-sided 95 % band of the mean of N chi-square(1) values (Wilson-Hilferty quantiles).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.live.engine import Engine, EngineConfig
from mavins.live.livefilter import GNSS_HEADING, FilterSettings
from sim.aiding import GnssConfig, simulate_aiding
from sim.generate import generate
from sim.scenarios import load
from support import Z975, chi2_quantile, feed_engine

SIGMA_DEG = 0.5  # the receiver's heading 1-sigma (hdg_acc)
N_RUNS = 10
DURATION = 70.0




def fly(seed: int, heading_from: float = 0.0):  # type: ignore[no-untyped-def]
    """The engine fed the run's IMU samples, its 5 Hz fixes (ground velocity) and, from ``heading_from`` s on,
    each fix's dual-antenna heading; returns the engine, the output rows (t, yaw, published yaw 1-sigma) and
    the truth (t, yaw deg)."""
    run = generate(load("flight"), duration=DURATION, rate=100.0, grade="consumer", seed=seed)
    g = simulate_aiding(run, GnssConfig(rate=5.0), None, None).gnss
    truth = run.exact.truth
    true_yaw = np.interp(g[:, 0], truth[:, 0], np.unwrap(np.radians(truth[:, 16])))  # the vehicle's yaw
    noise = np.random.default_rng([seed, 0x4EAD]).standard_normal(len(g)) * math.radians(SIGMA_DEG)
    init = run.init()
    eng = Engine(EngineConfig(lat=init.lat, lon=init.lon, alt=init.h, heading="auto", align=5.0,
                              filter=FilterSettings(spec="consumer", aiding=("gnss", "baro"))))

    def heading(engine: Engine, j: int, fix: list) -> None:  # type: ignore[type-arg]
        if fix[0] >= heading_from:
            engine.on_gnss_yaw(fix[0], math.remainder(true_yaw[j] + noise[j], 2.0 * math.pi), math.radians(SIGMA_DEG))

    out = feed_engine(eng, run, g, heading, row=lambda sol: (sol.row[0], sol.row[9], sol.unc.sigma_att[2]))
    return eng, np.array(out), truth[:, [0, 16]]


@pytest.fixture(scope="module")
def runs():  # type: ignore[no-untyped-def]
    return [fly(1000 + k) for k in range(N_RUNS)]


def yaw_z(out: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(published yaw - true yaw, wrapped) / published 1-sigma, per output row."""
    ty = np.interp(out[:, 0], truth[:, 0], np.unwrap(np.radians(truth[:, 1])))
    return np.angle(np.exp(1j * (out[:, 1] - ty))) / out[:, 2]


def test_the_engine_aligns_on_the_receivers_heading(runs) -> None:  # type: ignore[no-untyped-def]
    """No heading given, no magnetometer, no vehicle ATTITUDE: the heading comes from the receiver at
    alignment, with the dual-antenna source's initial 1-sigma (2 deg), and the first yaw is within 3 of it;
    its heading measurements are fused all along (counted accepted, none rejected in a clean run)."""
    for eng, out, truth in runs:
        assert eng.heading_used == GNSS_HEADING
        assert out[0, 2] <= math.radians(2.0) * 1.001  # the 2 deg prior, propagated over one update
        assert abs(yaw_z(out[:1], truth)[0]) < 3.0
        assert eng.filter.counters["gnss_yaw_accepted"] > 5 * (DURATION - 10.0)
        assert eng.filter.counters["gnss_yaw_rejected"] == 0


def test_the_published_yaw_sigma_is_consistent_over_the_runs(runs) -> None:  # type: ignore[no-untyped-def]
    """The yaw's normalised error squared at the 1 Hz epochs (the first output row at or after each whole
    second from 6 s: the consumer grade's sample times jitter),
    averaged over the N runs at each epoch and then over the epochs, lies in the 95 % band of the mean of N
    chi2(1)."""
    epochs = np.arange(6.0, DURATION)

    def at_epochs(out: np.ndarray, truth: np.ndarray) -> np.ndarray:
        z = yaw_z(out, truth)
        idx = np.searchsorted(out[:, 0], epochs)
        assert np.all(out[idx, 0] - epochs < 0.05)
        return z[idx] ** 2

    z2 = np.array([at_epochs(out, truth) for _, out, truth in runs])
    anees = float(np.mean(np.mean(z2, axis=0)))
    lo, hi = chi2_quantile(-Z975, N_RUNS) / N_RUNS, chi2_quantile(Z975, N_RUNS) / N_RUNS
    assert lo < anees < hi, (anees, lo, hi)


def test_a_heading_that_arrives_after_the_alignment_ends_the_wait() -> None:
    """No heading source at the alignment (the receiver's heading only from 15 s on, before the vehicle moves
    at 36.8 s): the engine aligns with the heading pending, and the first dual-antenna heading ends the wait
    at once (put on the last fix, as the GNSS-velocity reset does), not the yaw estimator 20 s later: one
    reset, the receiver's heading used, every later yaw within 3 published sigma and the sigma at most the
    receiver's plus what a few seconds of gyro drift add."""
    eng, out, truth = fly(1000, heading_from=15.0)
    assert eng.heading_used == GNSS_HEADING and eng.counters["yaw_resets"] == 1
    assert any(text.startswith("heading from the GNSS receiver") for _, text in eng.events)
    after = out[:, 0] >= 15.3
    pending = out[:, 0] < 15.0
    assert np.all(out[pending, 2] > math.radians(90.0))  # a heading uniform on the circle until then
    z = yaw_z(out[after], truth)
    assert np.all(np.abs(z) < 3.0), np.abs(z).max()
    assert np.all(out[after, 2] < math.radians(1.0))
