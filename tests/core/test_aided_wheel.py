"""The batch filter on a wheeled vehicle: wheel odometry (kalman.wheel_speed, its scale factor estimated, the
axle's lever arm) and the non-holonomic constraint (kalman.nhc) through a 5-minute GNSS outage.

The simulator's car scenario driven for four laps of its city block (about 6.5 minutes), industrial IMU
with the errors the filter's model holds (scale factors, misalignments and g-sensitivity off, as
tests/core/test_aided_filter.py does for the consumer grade), 5 Hz GNSS cut from 60 s to 360 s. The
odometer (sim.aiding.wheel) sits at the rear axle, 1.2 m behind, 0.5 m to the right of and 0.4 m below the
IMU, with a scale-factor error drawn per run from the filter's own prior (2 %), 0.05 m/s noise at 10 Hz.

Expected values come from outside the code: the chi-square bands of the normalised errors (Wilson-Hilferty,
as test_aided_filter.py) and the free-inertial drift the same runs show without the odometer.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mavins.core import aided
from sim import aiding, errors
from sim.generate import generate
from sim.scenarios import Scenario, load
from support import Z995, chi2_quantile, consumer_stochastic
from test_aided_filter import nav_errors, perturbed_init

RUNS = 10
OUTAGE = (60.0, 360.0)
LEVER = (-1.2, 0.5, 0.4)
SCALE_SIGMA = aided.DEFAULT_WHEEL_SCALE
SIGMAS = {"sigma_pos": 2.0, "sigma_vel": 0.1, "sigma_level": 0.05, "sigma_yaw": 0.5}




MODEL = consumer_stochastic("industrial")  # the industrial grade without the errors outside the model


@pytest.fixture(scope="module")
def drive():  # type: ignore[no-untyped-def]
    """The car's city block four times (no vibration: its 10-30 Hz body motion is not the constraint's)."""
    sc = load("car")
    segs = sc.doc["segments"]
    lap = segs[2:-2]  # from the first cruise to the last turn
    doc = {k: v for k, v in sc.doc.items() if k != "perturbations"}
    doc["segments"] = segs[:2] + lap * 4 + segs[-2:]
    return generate(Scenario("car_laps", sc.source, doc), rate=100.0, seed=0, grade="ideal")


def one_run(drive, seed: int, with_wheel: bool):  # type: ignore[no-untyped-def]
    """One run, with the odometer and the constraint or GNSS alone: times, north and east errors, their
    published sigmas, the scale factor's estimate and sigma at each row, its truth, the stats, the odometer
    rows."""
    ex = drive.exact
    t, dth, dv, _ = errors.apply(MODEL, ex.t, ex.dtheta, ex.dv, seed, t_start=ex.t0)
    run = dataclasses.replace(drive, seed=seed)
    gnss = aiding.gnss(run, aiding.GnssConfig(rate=5.0, outages=(OUTAGE,)))
    k_true = float(np.random.default_rng([seed, 7]).standard_normal()) * SCALE_SIGMA
    wheel = aiding.wheel(run, aiding.WheelConfig(rate=10.0, scale=k_true, lever_arm=LEVER))
    init = perturbed_init(ex.init(), np.random.default_rng([seed, 1]), SIGMAS)
    kw = {"wheel": wheel, "wheel_lever_arm": LEVER, "nhc": aided.DEFAULT_SIGMA_NHC} if with_wheel else {}
    rows, st = aided.navigate_aided(np.column_stack([t, dth, dv]), init, gnss, spec="industrial", file_units=False,
                                    **kw)
    err = nav_errors(rows, drive.exact.truth[2 * (np.arange(rows.shape[0]) + 1)])
    ws = aided.ROW_COLUMNS.index("ws")
    return rows[:, 0], err[:, 6:8], rows[:, 14:16], rows[:, ws], rows[:, ws + 1], k_true, st, wheel


@pytest.fixture(scope="module")
def runs(drive):  # type: ignore[no-untyped-def]
    return {"aided": [one_run(drive, 500 + r, True) for r in range(RUNS)],
            "free": [one_run(drive, 500 + r, False) for r in range(RUNS)]}


def _end_of_outage(t: np.ndarray) -> int:
    return int(np.searchsorted(t, OUTAGE[1])) - 1


def test_odometry_and_the_constraint_bound_a_five_minute_outage(runs) -> None:  # type: ignore[no-untyped-def]
    """At the end of the 5-minute outage the horizontal RMS over the runs with the odometer and the constraint
    is below a twentieth of free inertial's, and every odometer row and constraint was applied and accepted."""
    def rms(key: str) -> float:
        return math.sqrt(np.mean([np.sum(r[1][_end_of_outage(r[0])] ** 2) for r in runs[key]]))

    assert rms("aided") < rms("free") / 20.0, (rms("aided"), rms("free"))
    for a in runs["aided"]:
        assert a[6]["counts"]["wheel"] == (a[7].shape[0], 0)
        n_nhc = a[6]["counts"]["nhc"]
        assert n_nhc[1] == 0 and abs(n_nhc[0] - (a[0][-1] - a[0][0]) / aided.NHC_EVERY) <= 2


def test_the_outage_drift_lies_within_its_sigma(runs) -> None:  # type: ignore[no-untyped-def]
    """North and east errors over the published sigma through the outage (1 Hz epochs): the mean of the
    squared normalised errors over the runs lies in the band of chi2(2N)/(2N) at 99 % (each epoch's; the
    time average has the same mean and at most that spread), with and without the odometer."""
    lo, hi = (chi2_quantile(z, 2 * RUNS) / (2 * RUNS) for z in (-Z995, Z995))
    for key in ("aided", "free"):
        z2 = []
        for r in runs[key]:
            t = r[0]
            sel = np.arange(int(np.searchsorted(t, OUTAGE[0])), _end_of_outage(t) + 1, 50)
            z2.append((r[1][sel] / r[2][sel]) ** 2)
        m = float(np.mean(np.concatenate(z2)))
        assert lo < m < hi, (key, m, lo, hi)


def test_the_odometer_scale_factor_is_learnt(runs) -> None:  # type: ignore[no-untyped-def]
    """At the end the scale factor's estimate against each run's drawn truth: its normalised error squared
    averages inside chi2(N)/N at 99 %, and its sigma is below a tenth of the prior's 2 %."""
    z2 = [((r[3][-1] - r[5]) / r[4][-1]) ** 2 for r in runs["aided"]]
    lo, hi = (chi2_quantile(z, RUNS) / RUNS for z in (-Z995, Z995))
    assert lo < float(np.mean(z2)) < hi, z2
    assert max(r[4][-1] for r in runs["aided"]) < 0.1 * SCALE_SIGMA
