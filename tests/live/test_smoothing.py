"""live/smoothing.py: the smoother on the live path (``mavins replay --smooth``), over the engine itself.

The car scenario through the live engine (tests/support.feed_engine) with its 5 Hz fixes cut for a minute:
the forward rows kept with their epochs (KeptRows) and smoothed afterwards must cut the outage's error
several-fold and stay within their own sigmas, as the batch smoother does (tests/core/test_aided_filter.py
has its Monte Carlo).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.live.engine import Engine, EngineConfig
from mavins.live.livefilter import FilterSettings
from mavins.live.smoothing import KeptRows
from sim.aiding import GnssConfig, simulate_aiding
from sim.generate import generate
from sim.scenarios import load
from support import feed_engine

OUTAGE = (60.0, 120.0)


def horizontal_errors(rows: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """North and east errors (m) of kernel rows against the truth row at or after each row's time."""
    k = np.clip(np.searchsorted(truth[:, 0], rows[:, 0]), 0, len(truth) - 1)
    lat = np.radians(truth[k, 1])
    a, e2 = 6378137.0, (1 / 298.257223563) * (2 - 1 / 298.257223563)
    r_n = a * (1 - e2) / (1 - e2 * np.sin(lat) ** 2) ** 1.5
    r_e = a / np.sqrt(1 - e2 * np.sin(lat) ** 2)
    h = truth[k, 3]
    return np.column_stack([(rows[:, 1] - lat) * (r_n + h),
                            (rows[:, 2] - np.radians(truth[k, 2])) * (r_e + h) * np.cos(lat)])


pytestmark = pytest.mark.plain_python_slow  # the car through the engine: minutes as plain Python (mutation runs)


@pytest.fixture(scope="module")
def drive():  # type: ignore[no-untyped-def]
    run = generate(load("car"), rate=100.0, grade="industrial", seed=11)
    g = simulate_aiding(run, GnssConfig(rate=5.0), None, None).gnss
    g = g[(g[:, 0] < OUTAGE[0]) | (g[:, 0] >= OUTAGE[1])]
    init = run.init()
    eng = Engine(EngineConfig(lat=init.lat, lon=init.lon, alt=init.h, heading=float(init.yaw), align=5.0,
                              filter=FilterSettings(spec="industrial", aiding=("gnss",), smooth=True)))
    kept = KeptRows()
    fwd = np.array(feed_engine(eng, run, g, row=lambda sol: kept.add(eng.filter.output_row(sol.row),
                                                                     eng.filter.epochs) or eng.filter.output_row(sol.row)))
    smo, singular = kept.smooth(eng.filter.epochs)
    return fwd, np.array(smo), singular, eng, run.exact.truth


def test_the_live_smoother_cuts_the_outage_error_at_least_fivefold(drive) -> None:  # type: ignore[no-untyped-def]
    """Inside the minute without fixes: smoothed horizontal RMS at most a fifth of the forward rows'; the
    smoother kept an epoch at least every aided.SMOOTH_DT through the gap, and none was singular."""
    fwd, smo, singular, eng, truth = drive
    assert fwd.shape == smo.shape and singular == 0
    inside = (fwd[:, 0] > OUTAGE[0]) & (fwd[:, 0] < OUTAGE[1])
    rms_f, rms_s = (math.sqrt(np.mean(np.sum(horizontal_errors(r[inside], truth) ** 2, axis=1))) for r in (fwd, smo))
    assert rms_s <= rms_f / 5.0, (rms_s, rms_f)
    assert eng.filter.epochs.count >= (OUTAGE[1] - OUTAGE[0]) / 1.0


def test_the_live_smoothed_errors_lie_within_their_sigmas(drive) -> None:  # type: ignore[no-untyped-def]
    """North and east errors over the smoothed sigma columns (sigma_n, sigma_e): RMS below 2 over the run
    and inside the outage (a consistent smoother gives 1; a single run of strongly correlated errors, so the
    bound is loose), and the last row, the last epoch's, is the forward one."""
    fwd, smo, singular, eng, truth = drive
    z = horizontal_errors(smo, truth) / smo[:, 14:16]
    inside = (smo[:, 0] > OUTAGE[0]) & (smo[:, 0] < OUTAGE[1])
    assert math.sqrt(np.mean(z ** 2)) < 2.0 and math.sqrt(np.mean(z[inside] ** 2)) < 2.0
    np.testing.assert_array_equal(smo[-1], fwd[-1])
