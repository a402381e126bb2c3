"""Statistical and exact checks of the IMU error models in ``sim.errors``.

Every tolerance is derived from the sampling statistics of the estimator it
checks (see the comment above each test); all runs use fixed seeds, so the
tests are deterministic.  Rates are recovered from increments as
``dtheta / dt``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from sim import errors as E
from sim.errors import ImuErrorModel, SensorErrorModel

DT = 0.01


def _uniform_log(n: int, dt: float = DT) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(1, n + 1) * dt
    return t, np.zeros((n, 3)), np.zeros((n, 3))


def _motion(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5 * DT, 1.5 * DT, n))
    return t, rng.normal(0.0, 1e-2, (n, 3)), rng.normal(0.0, 1e-1, (n, 3))


def _gyro_only(**kwargs: float) -> ImuErrorModel:
    return ImuErrorModel(gyro=SensorErrorModel(**kwargs))


# --- presets and plumbing ---------------------------------------------------


def test_grade_names_and_unknown() -> None:
    assert set(E.GRADES) == {"ideal", "consumer", "industrial", "tactical", "navigation"}
    for name in E.GRADES:
        assert isinstance(E.grade(name), ImuErrorModel)
    with pytest.raises(ValueError):
        E.grade("strategic")


def test_ideal_is_identity_bit_for_bit() -> None:
    t, dth, dv = _motion(5000)
    t_out, dth_out, dv_out, kept = E.apply(E.grade("ideal"), t, dth, dv, seed=123)
    assert kept.all()
    for got, ref in ((t_out, t), (dth_out, dth), (dv_out, dv)):
        assert got.dtype == ref.dtype and got.shape == ref.shape
        assert got.tobytes() == ref.tobytes()
    assert dth_out is not dth and dv_out is not dv
    rows = np.column_stack([t, dth, dv])
    rows_out, kept = E.apply_rows(E.grade("ideal"), rows, seed=5)
    assert rows_out.tobytes() == rows.tobytes() and kept.all()


# Second table of the sim.errors docstring: (gyro ARW, gyro B, gyro turn-on,
# gyro LSB, g-sensitivity, accel VRW, accel B, accel turn-on, accel LSB,
# gyro rate random walk, accel rate random walk), SI.
_TABLE = {
    "consumer": (
        6.981e-5, 4.848e-5, 5.818e-3, 1.064e-6, 1.780e-4, 9.807e-4, 9.807e-4, 8.172e-2, 4.788e-6, 3.755e-6, 7.596e-5
    ),
    "industrial": (
        9.890e-5, 3.879e-5, 1.745e-3, 1.756e-8, 1.780e-5, 6.167e-4, 1.275e-4, 1.961e-2, 1.863e-7, 2.124e-6, 6.983e-6
    ),
    "tactical": (3.636e-5, 4.848e-6, 4.848e-6, 1e-7, 0.0, 3.302e-4, 4.903e-4, 9.807e-3, 1e-6, 1.533e-7, 1.551e-5),
    "navigation": (5.818e-7, 1.697e-8, 1.697e-8, 1e-8, 0.0, 9.807e-5, 2.452e-4, 2.452e-4, 1e-7, 1.549e-10, 2.238e-6),
}


@pytest.mark.parametrize("name", sorted(_TABLE))
def test_preset_values_match_docstring_table(name: str) -> None:
    m = E.grade(name)
    got = (
        m.gyro.random_walk,
        m.gyro.bias_instability_sigma * E.GM_ADEV_PEAK_RATIO,
        m.gyro.turn_on_bias_sigma,
        m.gyro.quantization,
        m.g_sensitivity[0][0],
        m.accel.random_walk,
        m.accel.bias_instability_sigma * E.GM_ADEV_PEAK_RATIO,
        m.accel.turn_on_bias_sigma,
        m.accel.quantization,
        m.gyro.rate_random_walk,
        m.accel.rate_random_walk,
    )
    assert got == pytest.approx(_TABLE[name], rel=1e-3)


def test_preset_unit_conversions() -> None:
    # Independent hand conversions of a few datasheet lines.
    deg_rth = math.pi / 180.0 / 60.0
    assert E.grade("consumer").gyro.random_walk == pytest.approx(0.004 * math.pi / 180.0, rel=1e-12)
    assert E.grade("industrial").gyro.random_walk == pytest.approx(0.34 * deg_rth, rel=1e-12)
    assert E.grade("tactical").accel.random_walk == pytest.approx(0.065 * 0.3048 / 60.0, rel=1e-12)
    # Bias instability B = GM peak ADEV: 8 deg/h for the ADIS16470 class.
    ind = E.grade("industrial").gyro
    peak = E.gauss_markov_adev(
        ind.bias_instability_sigma, ind.bias_instability_tau, E.GM_ADEV_PEAK_TAU_RATIO * ind.bias_instability_tau
    )
    assert peak == pytest.approx(8.0 * math.pi / 180.0 / 3600.0, rel=1e-4)


def test_gauss_markov_adev_peak_constants() -> None:
    x = np.linspace(0.5, 5.0, 200_001)
    adev = E.gauss_markov_adev(1.0, 1.0, x)
    assert x[np.argmax(adev)] == pytest.approx(E.GM_ADEV_PEAK_TAU_RATIO, abs=1e-3)
    assert adev.max() == pytest.approx(E.GM_ADEV_PEAK_RATIO, rel=1e-9)


def test_every_preset_runs_and_is_repeatable() -> None:
    t, dth, dv = _motion(20_000)
    for name in E.GRADES:
        a = E.apply(E.grade(name), t, dth, dv, seed=9)
        b = E.apply(E.grade(name), t, dth, dv, seed=9)
        for x, y in zip(a, b):
            assert np.array_equal(x, y)
        assert np.all(np.diff(a[0]) > 0.0)
        assert a[1].shape == (a[3].sum(), 3)


def test_seed_determinism_and_sensitivity() -> None:
    t, dth, dv = _motion(2000)
    model = dataclasses.replace(E.grade("consumer"), drop_probability=0.01)
    a = E.apply(model, t, dth, dv, seed=1)
    b = E.apply(model, t, dth, dv, seed=1)
    c = E.apply(model, t, dth, dv, seed=2)
    for x, y in zip(a, b):
        assert np.array_equal(x, y)
    for x, y in zip(a, c):
        assert not np.array_equal(x, y)


def test_sources_use_independent_streams() -> None:
    # Turning drops on must not change the noise of the rows that are kept.
    t, dth, dv = _motion(10_000)
    base = E.grade("industrial")
    no_drop = dataclasses.replace(base, drop_probability=0.0)
    with_drop = dataclasses.replace(base, drop_probability=0.2)
    _, d0, v0, _ = E.apply(no_drop, t, dth, dv, seed=4)
    _, d1, v1, kept = E.apply(with_drop, t, dth, dv, seed=4)
    assert np.array_equal(d1, d0[kept]) and np.array_equal(v1, v0[kept])


def test_validation() -> None:
    with pytest.raises(ValueError):
        SensorErrorModel(random_walk=-1.0)
    with pytest.raises(ValueError):
        SensorErrorModel(bias_instability_tau=0.0)
    with pytest.raises(ValueError):
        SensorErrorModel(bias=(1.0, 2.0))
    with pytest.raises(ValueError):
        ImuErrorModel(drop_probability=1.0)
    t, dth, dv = _uniform_log(3)
    with pytest.raises(ValueError):
        E.apply(ImuErrorModel(), t[::-1], dth, dv, seed=0)
    with pytest.raises(ValueError):
        E.apply(ImuErrorModel(), t[:1], dth[:1], dv[:1], seed=0)
    out = E.apply(ImuErrorModel(), t[:1], dth[:1], dv[:1], seed=0, t_start=0.0)
    assert out[1].shape == (1, 3)


# --- deterministic error terms (exact) --------------------------------------


def test_constant_bias_exact() -> None:
    t, dth, dv = _motion(1000)
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    bg, ba = np.array([1e-3, -2e-3, 3e-3]), np.array([0.1, -0.05, 0.2])
    model = ImuErrorModel(gyro=SensorErrorModel(bias=bg), accel=SensorErrorModel(bias=ba))
    _, dth_out, dv_out, _ = E.apply(model, t, dth, dv, seed=0)
    np.testing.assert_allclose(dth_out, dth + bg * dt[:, None], rtol=0.0, atol=1e-17)
    np.testing.assert_allclose(dv_out, dv + ba * dt[:, None], rtol=0.0, atol=1e-16)


def test_scale_factor_and_misalignment_exact() -> None:
    t, dth, dv = _motion(1000)
    sf = np.array([500.0, -1200.0, 3000.0])
    mis = np.array([[0.0, 1e-3, -2e-3], [3e-3, 0.0, 5e-4], [-1e-3, 2e-3, 0.0]])
    model = ImuErrorModel(
        gyro=SensorErrorModel(scale_factor_ppm=sf, misalignment=mis),
        accel=SensorErrorModel(scale_factor_ppm=-sf, misalignment=mis.T),
    )
    _, dth_out, dv_out, _ = E.apply(model, t, dth, dv, seed=0)
    a_g = (np.eye(3) + np.diag(sf * 1e-6)) @ (np.eye(3) + mis)
    a_a = (np.eye(3) + np.diag(-sf * 1e-6)) @ (np.eye(3) + mis.T)
    np.testing.assert_allclose(dth_out, np.einsum("ij,nj->ni", a_g, dth), rtol=1e-14, atol=1e-18)
    np.testing.assert_allclose(dv_out, np.einsum("ij,nj->ni", a_a, dv), rtol=1e-14, atol=1e-17)
    # Unit input on x: scale hits the diagonal, misalignment leaks into y and z.
    _, d, _, _ = E.apply(model, t[:2], np.array([[1.0, 0.0, 0.0]] * 2), dv[:2], seed=0)
    assert d[0, 0] == pytest.approx(1.0 + 500e-6, abs=1e-15)
    assert d[0, 1] == pytest.approx((1.0 - 1200e-6) * 3e-3, abs=1e-15)
    assert d[0, 2] == pytest.approx((1.0 + 3000e-6) * -1e-3, abs=1e-15)


def test_g_sensitivity_exact() -> None:
    t, dth, dv = _motion(1000)
    g = np.array([[1e-4, 2e-5, 0.0], [0.0, -1e-4, 3e-5], [5e-6, 0.0, 2e-4]])
    _, dth_out, dv_out, _ = E.apply(ImuErrorModel(g_sensitivity=g), t, dth, dv, seed=0)
    np.testing.assert_allclose(dth_out, dth + dv @ g.T, rtol=1e-15, atol=1e-18)
    assert np.array_equal(dv_out, dv)


def test_turn_on_bias_constant_in_run_and_sigma() -> None:
    # Within a run the bias is constant; across R runs x 3 axes the sample
    # sigma s of the drawn biases has relative std 1/sqrt(2(R*3-1)) (normal
    # samples); 5 of those is the tolerance.
    sigma, runs = 2e-3, 400
    t, dth, dv = _uniform_log(10)
    model = _gyro_only(turn_on_bias_sigma=sigma)
    draws = []
    for seed in range(runs):
        _, d, _, _ = E.apply(model, t, dth, dv, seed=seed)
        rate = d / DT
        np.testing.assert_allclose(rate, np.broadcast_to(rate[0], rate.shape), rtol=1e-12)
        draws.append(rate[0])
    s = np.std(np.array(draws), ddof=1)
    assert abs(s / sigma - 1.0) < 5.0 / math.sqrt(2.0 * (3 * runs - 1))


# --- stochastic error terms (Allan deviation) --------------------------------


def test_angle_random_walk_adev() -> None:
    # White rate noise of density N: ADEV(tau) = N / sqrt(tau).  With n samples
    # and m = tau/dt, the estimate has K = n/m clusters and relative std
    # about 1/sqrt(2(K-1)) (non-overlapping bound; the overlapping estimator
    # does better).  Tolerance: 4.5 of those, at each tau and axis.
    n, noise = 200_000, 1e-3
    t, dth, dv = _uniform_log(n)
    _, d, _, _ = E.apply(_gyro_only(random_walk=noise), t, dth, dv, seed=11)
    m = np.array([1, 2, 5, 10, 20, 50, 100])
    taus, adev = E.allan_deviation(d / DT, DT, m * DT)
    expected = noise / np.sqrt(taus)
    tol = 4.5 / np.sqrt(2.0 * (n / m - 1.0))
    rel = adev / expected[:, None] - 1.0
    assert np.all(np.abs(rel) < tol[:, None]), rel
    # Per-row variance N^2 dt also holds for irregular intervals.
    t2, dth2, dv2 = _motion(60_000)
    dt2 = np.diff(t2, prepend=t2[0] - (t2[1] - t2[0]))
    _, d2, _, _ = E.apply(_gyro_only(random_walk=noise), t2, dth2, dv2, seed=12)
    z = (d2 - dth2) / (noise * np.sqrt(dt2)[:, None])
    assert abs(z.var() - 1.0) < 5.0 * math.sqrt(2.0 / z.size)


def test_velocity_random_walk_on_accel() -> None:
    # Same estimator as the ARW test, accelerometer channel, one tau.
    n, vrw = 100_000, 5e-4
    t, dth, dv = _uniform_log(n)
    model = ImuErrorModel(accel=SensorErrorModel(random_walk=vrw))
    _, d, v, _ = E.apply(model, t, dth, dv, seed=13)
    assert not d.any()
    taus, adev = E.allan_deviation(v / DT, DT, [10 * DT])
    assert np.all(np.abs(adev[0] / (vrw / np.sqrt(taus[0])) - 1.0) < 4.5 / math.sqrt(2.0 * (n / 10 - 1)))


def test_bias_instability_gauss_markov() -> None:
    # Stationary variance: the rate seen in row k is the trapezoid mean
    # (b_k + b_{k+1})/2 of the GM state, whose variance is
    # sigma^2 (1 + phi)/2 with phi = exp(-dt/tau_c).  For an AR(1) series the
    # sample variance has relative std sqrt(2 (1+phi^2)/(1-phi^2) / n)
    # (Bartlett); tolerance 4.5 of those.
    # ADEV peak: at tau = 1.893 tau_c the theory is gauss_markov_adev(); the
    # estimator has K = T/tau clusters, relative std about 1/sqrt(2(K-1)).
    n, sigma, tau_c = 200_000, 2e-3, 0.5
    t, dth, dv = _uniform_log(n)
    model = _gyro_only(bias_instability_sigma=sigma, bias_instability_tau=tau_c)
    _, d, _, _ = E.apply(model, t, dth, dv, seed=21)
    rate = d / DT
    phi = math.exp(-DT / tau_c)
    var_expected = sigma**2 * (1.0 + phi) / 2.0
    var_tol = 4.5 * math.sqrt(2.0 * (1.0 + phi**2) / (1.0 - phi**2) / n)
    assert np.all(np.abs(rate.var(axis=0) / var_expected - 1.0) < var_tol)
    tau_peak = E.GM_ADEV_PEAK_TAU_RATIO * tau_c
    taus, adev = E.allan_deviation(rate, DT, [tau_peak])
    clusters = n * DT / taus[0]
    peak_expected = E.gauss_markov_adev(sigma, tau_c, taus[0])
    assert peak_expected == pytest.approx(E.GM_ADEV_PEAK_RATIO * sigma, rel=1e-3)
    assert np.all(np.abs(adev[0] / peak_expected - 1.0) < 4.5 / math.sqrt(2.0 * (clusters - 1.0)))


def test_gauss_markov_exact_discretisation_irregular_steps() -> None:
    # Block-wise closed form of the AR(1) recursion equals the plain loop.
    rng = np.random.default_rng(3)
    dt = rng.uniform(1e-3, 0.5, 3000)
    for tau in (1e-2, 1.0, 100.0):
        got = E._gauss_markov_states(2.0, tau, dt, np.random.default_rng(7))
        r = np.random.default_rng(7)
        ref = np.empty_like(got)
        ref[0] = 2.0 * r.standard_normal(3)
        phi = np.exp(-dt / tau)
        w = (2.0 * np.sqrt(1.0 - phi**2))[:, None] * r.standard_normal((dt.size, 3))
        for k in range(dt.size):
            ref[k + 1] = phi[k] * ref[k] + w[k]
        np.testing.assert_allclose(got, ref, rtol=0.0, atol=1e-10)


def test_rate_random_walk_slope() -> None:
    # Random-walk bias of strength K: ADEV(tau) = K sqrt(tau/3), slope +1/2.
    # ADEV is averaged (as AVAR) over the 3 axes.  Equivalent degrees of
    # freedom of the overlapping estimator for random-walk FM (Howe, Allan &
    # Barnes 1981): edf = (N-2)/m * ((N-1)^2 - 3m(N-1) + 4m^2)/(N-3)^2 per
    # axis; relative ADEV std = 1/sqrt(2 * 3 edf).  Level tolerance: 5 of
    # those.  At the longest tau (T/tau = 20) the relative std is ~0.09; a
    # least-squares slope over two decades then has std ~0.09/ln(100) = 0.02;
    # slope tolerance 0.1 = 5 of those.
    n, k = 100_000, 1e-4
    t, dth, dv = _uniform_log(n)
    _, d, _, _ = E.apply(_gyro_only(rate_random_walk=k), t, dth, dv, seed=31)
    taus, adev = E.allan_deviation(d / DT, DT, np.logspace(np.log10(0.5), np.log10(50.0), 9))
    avar = (adev**2).mean(axis=1)
    slope = np.polyfit(np.log(taus), np.log(avar), 1)[0] / 2.0
    assert abs(slope - 0.5) < 0.1
    m = np.rint(taus / DT)
    big_n = n + 1
    edf = (big_n - 2) / m * ((big_n - 1) ** 2 - 3 * m * (big_n - 1) + 4 * m**2) / (big_n - 3) ** 2
    rel = np.sqrt(avar) / (k * np.sqrt(taus / 3.0)) - 1.0
    assert np.all(np.abs(rel) < 5.0 / np.sqrt(2.0 * 3.0 * edf)), rel


def test_allan_deviation_reference_values() -> None:
    rng = np.random.default_rng(0)
    y = rng.normal(size=1001)
    taus, adev = E.allan_deviation(y, 0.5, [0.5, 1.0])
    np.testing.assert_allclose(taus, [0.5, 1.0])
    assert adev[0] == pytest.approx(math.sqrt(np.mean(np.diff(y) ** 2) / 2.0), rel=1e-12)
    pair = y[:-1] + y[1:]
    diffs = (pair[2:] - pair[:-2]) / 2.0
    assert adev[1] == pytest.approx(math.sqrt(np.mean(diffs**2) / 2.0), rel=1e-12)
    taus_d, adev_d = E.allan_deviation(np.column_stack([y, 2 * y]), 0.5)
    assert taus_d[0] == 0.5 and taus_d[-1] <= 0.5 * 500
    np.testing.assert_allclose(adev_d[:, 1], 2 * adev_d[:, 0], rtol=1e-12)


# --- quantisation, jitter, drops --------------------------------------------


def _check_quantized(out: np.ndarray, ref: np.ndarray, step: float) -> None:
    counts = out / step
    np.testing.assert_allclose(counts, np.rint(counts), rtol=0.0, atol=1e-6)
    slack = 1e-9 * step + 1e-12 * np.abs(np.cumsum(ref, axis=0)).max()
    gap = np.abs(np.cumsum(out, axis=0) - np.cumsum(ref, axis=0))
    assert gap.max() <= 0.5 * step + slack


def test_quantisation_residual_carries() -> None:
    n = 100_000
    t, dth, dv = _motion(n)
    qg, qa = 1e-5, 1e-4
    model = ImuErrorModel(gyro=SensorErrorModel(quantization=qg), accel=SensorErrorModel(quantization=qa))
    _, d, v, _ = E.apply(model, t, dth, dv, seed=0)
    _check_quantized(d, dth, qg)
    _check_quantized(v, dv, qa)
    # Increments well below one LSB still add up over time.
    tiny = np.full((n, 3), 0.013 * qg)
    _, d_tiny, _, _ = E.apply(model, t, tiny, dv, seed=0)
    _check_quantized(d_tiny, tiny, qg)
    assert np.count_nonzero(d_tiny[:, 0]) == pytest.approx(0.013 * n, abs=1.0)


@settings(max_examples=60, deadline=None)
@given(
    x=arrays(np.float64, (50, 3), elements=st.floats(-1e3, 1e3, allow_nan=False)),
    step=st.floats(1e-3, 10.0),
)
def test_quantiser_property(x: np.ndarray, step: float) -> None:
    _check_quantized(E._quantize(x, step)[0], x, step)


def test_dropped_samples_fraction() -> None:
    # Each row is dropped independently with probability p: the dropped
    # fraction has binomial std sqrt(p(1-p)/n); tolerance 5 of those.
    n, p = 200_000, 0.01
    t, dth, dv = _motion(n)
    t_out, d, v, kept = E.apply(ImuErrorModel(drop_probability=p), t, dth, dv, seed=41)
    frac = 1.0 - kept.mean()
    assert abs(frac - p) < 5.0 * math.sqrt(p * (1.0 - p) / n)
    assert np.array_equal(t_out, t[kept]) and np.array_equal(d, dth[kept]) and np.array_equal(v, dv[kept])


def test_jitter_keeps_times_increasing_and_increments_true() -> None:
    # Small jitter: (t_out - t) is N(0, sigma^2) (truncation at 0.45 dt is 45
    # sigma away); sample-variance relative std sqrt(2/n), tolerance 5 of those.
    n, sigma = 100_000, 1e-4
    t, dth, dv = _motion(n)
    t_out, d, v, kept = E.apply(ImuErrorModel(jitter_sigma=sigma), t, dth, dv, seed=51)
    assert kept.all() and np.array_equal(d, dth) and np.array_equal(v, dv)
    assert np.all(np.diff(t_out) > 0.0)
    err = t_out - t
    assert abs(err.var() / sigma**2 - 1.0) < 5.0 * math.sqrt(2.0 / n)
    # Jitter far larger than the sample period is truncated, never reorders.
    t_big, *_ = E.apply(ImuErrorModel(jitter_sigma=10 * DT, drop_probability=0.3), t, dth, dv, seed=52)
    assert np.all(np.diff(t_big) > 0.0)


@pytest.mark.parametrize("grade", [g for g in E.GRADES if g != "ideal"])
def test_error_stream_in_chunks_equals_the_run_at_once(grade: str) -> None:
    """Chunks starting on multiples of BLOCK rows give the rows apply() gives at once, bit for bit:
    the same random streams drawn in row order, Gauss-Markov, rate random walk and quantiser states
    carried, the last row's jitter limit from the next interval (g-sensitivity coupling included)."""
    rng = np.random.default_rng(5)
    n = 3 * E.BLOCK + 123
    t = 10.0 + np.arange(1, n + 1) / 400.0
    dth = rng.normal(0.0, 1e-3, (n, 3))
    dv = rng.normal(0.0, 1e-2, (n, 3)) + [0.0, 0.0, -9.8 / 400.0]
    model = dataclasses.replace(E.grade(grade), g_sensitivity=((1e-4, 0.0, 0.0), (0.0, 2e-4, 0.0), (0.0, 0.0, 3e-4)),
                                drop_probability=0.01, jitter_sigma=1e-4)
    whole = E.apply(model, t, dth, dv, 17, t_start=10.0)
    stream = E.ErrorStream(model, t, 17, t_start=10.0)
    parts = [stream.corrupt(dth[a:b], dv[a:b]) for a, b in ((0, E.BLOCK), (E.BLOCK, 3 * E.BLOCK), (3 * E.BLOCK, n))]
    for k in range(4):
        assert np.array_equal(np.concatenate([p[k] for p in parts]), whole[k])
    assert 0 < np.count_nonzero(~whole[3]) < 0.03 * n  # drops and jitter exercised
    assert np.all(np.diff(whole[0]) > 0) and not np.array_equal(whole[0], t[whole[3]])
    with pytest.raises(ValueError, match="rows"):
        stream.corrupt(dth[:1], dv[:1])  # past the run's last row


def test_error_stream_bias_matches_bias_states() -> None:
    """bias_states() draws the same Gauss-Markov and rate-random-walk states as the chunked stream: the
    industrial gyro's increments minus the truth average the bias between boundaries (white noise off)."""
    model = E.grade("industrial")
    quiet = dataclasses.replace(model, gyro=dataclasses.replace(model.gyro, random_walk=0.0, quantization=0.0,
                                                                scale_factor_ppm=(0.0,) * 3,
                                                                misalignment=((0.0,) * 3,) * 3),
                                g_sensitivity=((0.0,) * 3,) * 3, jitter_sigma=0.0, drop_probability=0.0)
    n = 2 * E.BLOCK + 7
    t = np.arange(1, n + 1) / 200.0
    zeros = np.zeros((n, 3))
    stream = E.ErrorStream(quiet, t, 3, t_start=0.0)
    out = np.concatenate([stream.corrupt(zeros[:E.BLOCK], zeros[:E.BLOCK])[1],
                          stream.corrupt(zeros[E.BLOCK:], zeros[E.BLOCK:])[1]])
    b_g, _ = E.bias_states(quiet, t, 3, t_start=0.0)
    np.testing.assert_allclose(out, 0.5 * (b_g[:-1] + b_g[1:]) * np.diff(t, prepend=0.0)[:, None], rtol=1e-12,
                               atol=1e-20)
