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
from support import feed_engine, horizontal_errors

OUTAGE = (60.0, 120.0)


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


@pytest.mark.plain_python_slow  # the car through the engine: minutes as plain Python (mutation runs)
def test_the_live_smoother_cuts_the_outage_error_at_least_fivefold(drive) -> None:  # type: ignore[no-untyped-def]
    """Inside the minute without fixes: smoothed horizontal RMS at most a fifth of the forward rows'; the
    smoother kept an epoch at least every aided.SMOOTH_DT through the gap, and none was singular."""
    fwd, smo, singular, eng, truth = drive
    assert fwd.shape == smo.shape and singular == 0
    inside = (fwd[:, 0] > OUTAGE[0]) & (fwd[:, 0] < OUTAGE[1])
    rms_f, rms_s = (math.sqrt(np.mean(np.sum(horizontal_errors(r[inside], truth) ** 2, axis=1))) for r in (fwd, smo))
    assert rms_s <= rms_f / 5.0, (rms_s, rms_f)
    assert eng.filter.epochs.count >= (OUTAGE[1] - OUTAGE[0]) / 1.0


@pytest.mark.plain_python_slow
def test_the_live_smoothed_errors_lie_within_their_sigmas(drive) -> None:  # type: ignore[no-untyped-def]
    """North and east errors over the smoothed sigma columns (sigma_n, sigma_e): RMS below 2 over the run
    and inside the outage (a consistent smoother gives 1; a single run of strongly correlated errors, so the
    bound is loose), and the last row, the last epoch's, is the forward one."""
    fwd, smo, singular, eng, truth = drive
    z = horizontal_errors(smo, truth) / smo[:, 14:16]
    inside = (smo[:, 0] > OUTAGE[0]) & (smo[:, 0] < OUTAGE[1])
    assert math.sqrt(np.mean(z ** 2)) < 2.0 and math.sqrt(np.mean(z[inside] ** 2)) < 2.0
    np.testing.assert_array_equal(smo[-1], fwd[-1])


# -- EpochLog and KeptRows on their own: what they keep, and the smoothing of a constant ----------------------
from mavins.core import aided, earth  # noqa: E402
from mavins.core import errmodel as em  # noqa: E402
from mavins.core import smoother  # noqa: E402
from mavins.live.smoothing import EpochLog  # noqa: E402


def epoch_args(p_minus: float, p_plus: float, dx_n: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """P^-, P^+ (the north position's variance only), a pending-propagation vector with a transition tail
    and a correction of dx_n m north."""
    Pm, Pp = np.zeros((em.NX, em.NX)), np.zeros((em.NX, em.NX))
    Pm[em.X_DP, em.X_DP], Pp[em.X_DP, em.X_DP] = p_minus, p_plus
    acc = np.zeros(aided.ACC_SIZE + em.NX * em.NX)
    smoother.reset_transition(acc[aided.ACC_SIZE:])
    dx = np.zeros(em.NX)
    dx[em.X_DP] = dx_n
    return Pm, Pp, acc, dx


def test_epoch_log_keeps_each_epoch_as_smoother_record_lays_it_out() -> None:
    log = EpochLog(np.array([em.X_DP]), generation=3)
    assert (log.count, log.generation, log.t_last) == (0, 3, -math.inf) and log.store().shape == (0, 7)
    for k, (t, pm, pp, d) in enumerate(((0.5, 4.0, 4.0, 0.0), (1.5, 5.0, 2.5, 1.25))):
        Pm, Pp, acc, dx = epoch_args(pm, pp, d)
        acc[aided.ACC_SIZE + em.X_DP * em.NX + em.X_DP] = 1.5  # the transition's north element
        log.record(t, Pm, Pp, acc, dx)
        assert log.count == k + 1 and log.t_last == t
        np.testing.assert_array_equal(acc[aided.ACC_SIZE:].reshape(em.NX, em.NX), np.eye(em.NX))  # restarted
    store = log.store()
    # t, row (the count before it), dx, e, P^-, P^+, Phi (smoother.py's layout over one state)
    np.testing.assert_array_equal(store, [[0.5, 0, 0.0, 0.0, 4.0, 4.0, 1.5], [1.5, 1, 1.25, 0.0, 5.0, 2.5, 1.5]])
    store[0, 3] = 7.0  # writable, and the file itself
    assert log.store()[0, 3] == 7.0


def test_kept_rows_smooth_a_constant_and_leave_an_earlier_start_alone() -> None:
    """Two epochs of a constant north error (no process noise, transition 1): the prior 4 m^2, then a fix
    moving the solution dx = 1 m north with P^+ 2 m^2. Given both, the error at the first epoch is the fix's
    correction, e^s_0 = P^+_0 Phi (P^-_1)^-1 dx_1 = 1 m, with P^s_0 = 2 m^2: the rows written before the fix
    move 1 m south and take sigma sqrt 2, the row after it stays. A row of an earlier start (generation 0)
    and a row before any epoch keep their values."""
    kept = KeptRows()
    lat = math.radians(47.0)
    row = np.zeros(aided.ROW_SIZE)
    row[1], row[10], row[14] = lat, 1.0, 2.0
    old = EpochLog(np.array([em.X_DP]), generation=0)
    kept.add(row, None)
    kept.add(row, old)
    log = EpochLog(np.array([em.X_DP]), generation=1)
    log.record(0.0, *epoch_args(4.0, 4.0, 0.0))
    for t in (0.0, 0.4):
        row[0] = t
        kept.add(row, log)
    log.record(1.0, *epoch_args(4.0, 2.0, 1.0))
    row[0], row[14] = 1.0, math.sqrt(2.0)
    kept.add(row, log)
    rows, singular = kept.smooth(log)
    assert singular == 0 and rows.shape == (5, aided.ROW_SIZE) and kept.count == 5
    r_n = earth.radii(lat)[0]
    np.testing.assert_allclose(rows[2:4, 1], lat - 1.0 / r_n, rtol=0, atol=1e-16)
    np.testing.assert_allclose(rows[2:4, 14], math.sqrt(2.0), rtol=1e-15)
    assert rows[4, 1] == lat and rows[0, 1] == lat and rows[1, 1] == lat and rows[1, 14] == 2.0


def test_kept_rows_without_epochs_are_the_forward_rows() -> None:
    kept = KeptRows()
    assert kept.smooth(None)[0].shape == (0, aided.ROW_SIZE) and kept.smooth(None)[1] == 0
    row = np.arange(aided.ROW_SIZE, dtype=float)
    kept.add(row, None)
    rows, singular = kept.smooth(None)
    np.testing.assert_array_equal(rows[0], row)
    assert singular == 0
    one = EpochLog(np.array([em.X_DP]))
    one.record(0.0, *epoch_args(4.0, 4.0, 0.0))
    np.testing.assert_array_equal(kept.smooth(one)[0][0], row)  # one epoch: nothing to smooth

