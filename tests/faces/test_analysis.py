"""Error analysis (`mavins analyze`, core/covariance.py, mavins/analysis.py) against closed forms.

Free-inertial error propagation at rest on the equator (L = 0), level, heading
north, vertical channel held (docs/conventions.md ``--vertical hold``). With the
error model of core/errmodel.py (Groves 2nd ed. 14.2.4) the north channel is,
with x = north position error, phi_E, phi_D the attitude errors,
``w_s^2 = g / (R_N + h)`` and Omega the Earth rate (horizontal at L = 0):

    x''    = -g phi_E + b_N                     (velocity row, f^n = [0, 0, -g])
    phi_E' =  Omega phi_D + x' / R - eps_E      (-[w_ie x] phi, transport rate)
    phi_D' = -Omega phi_E + Omega x / R         (Earth rate seen through dL)

which gives ``x'''' + (w_s^2 + Omega^2) x'' + w_s^2 Omega^2 x = forcing``: the
Schuler and 24 h modes, ``(s^2 + w_s^2)(s^2 + Omega^2) = 0`` (Titterton &
Weston, *Strapdown Inertial Navigation Technology*, 2nd ed., 2004, ch. 12,
error propagation of the stationary system, where the Foucault term
``Omega sin L`` vanishes at the equator; Britting, *Inertial Navigation Systems
Analysis*, 1971, the same single-channel equations). From rest:

* accelerometer bias b (measured = true + b) along north:
  ``x(t) = (b / w_s^2)(1 - cos w_s t)`` exactly (the 24 h mode is not
  excited: the initial conditions give its coefficient 0): amplitude
  ``b R / g``, period ``2 pi sqrt(R / g)`` (84.4 min for R = 6371 km,
  g = 9.80665);
* gyro bias eps about east (measured = true + eps):
  ``x(t) = -g eps / (w_s^2 - Omega^2) [sin(Omega t)/Omega - sin(w_s t)/w_s]``,
  which is ``-R eps (t - sin(w_s t)/w_s)`` (the single-channel Schuler
  response) while ``Omega t << 1``, and ``-g eps t^3 / 6`` at first
  (a nose-up attitude error tilts gravity into -north). After 4 h the Earth-rate
  coupling (24 h term) makes it 16 % smaller than the single-channel form.

Tolerances. The acceptance bands are the issue's (amplitude 2 %, period 1 %,
gyro response 5 %). What theory leaves between the closed form and the two
implementations is far below them: the linearisation's neglected terms are
of relative size |phi| (below 1e-3 rad here: b/g = 1e-3 for 1 mg), the
radius and gravity change over a position error of 13 km is 13 km / R = 2e-3
of their values (and enters the period as half of that), and at rest the
strapdown integrates exactly; the covariance's second-order transition matrix
over 1 s steps errs by (w_s T)^3 / 6 = 3e-10 per step. So each check also
asserts the tighter band 0.5 %, which these terms cannot reach (the values
measured are in docs/analysis.md).

Covariance against Monte Carlo: with N runs of a Gaussian error of standard
deviation sigma, ``(N - 1) s^2 / sigma^2`` is chi-square with N - 1 degrees of
freedom, so s / sigma lies in ``[sqrt(chi2_lo / (N-1)), sqrt(chi2_hi / (N-1))]``
with the chosen probability (quantiles by Wilson and Hilferty's cube-root
approximation, J. Wilson, M. Hilferty, PNAS 17, 1931, accurate to 1e-3 for
these degrees of freedom). The band is set for a joint false-failure
probability of 1e-3 over all compared values (Bonferroni).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mavins import analysis as an
from mavins.cli import main
from mavins.core import covariance as cov
from mavins.core import errmodel as em
from mavins.core.runner import navigate
from sim import errors
from sim.scenarios import load

A_WGS = 6378137.0
F_WGS = 1.0 / 298.257223563
E2 = F_WGS * (2.0 - F_WGS)
OMEGA = 7.292115e-5
G_EQ = 9.7803253359  # normal gravity at the equator, h = 0 (docs/conventions.md)
R_N_EQ = A_WGS * (1.0 - E2)  # meridian radius at the equator
MG = 9.80665e-3
DEG_PER_H = math.pi / 180.0 / 3600.0

HOURS = 4.0
RATE = 10.0


class AtRest:
    """Exact increments and truth at rest on the equator, level, heading north (closed form).

    ``w_ib^b = C_n^b w_ie^n = [Omega, 0, 0]`` and ``f^b = -g^n = [0, 0, -gamma]``
    (docs/conventions.md Earth model: plumb-bob gravity, so at rest f = -g); the
    truth never changes. The same numbers as the simulator's ``static``
    segment there, without its 100 Hz internal integration of four hours.
    """

    def __init__(self, hours: float, rate: float) -> None:
        n = round(hours * 3600.0 * rate)
        self.t0 = 0.0
        self.t = np.arange(1, n + 1) / rate
        dt = np.diff(self.t, prepend=0.0)[:, None]
        self.dtheta = np.array([OMEGA, 0.0, 0.0]) * dt
        self.dv = np.array([0.0, 0.0, -G_EQ]) * dt
        self.truth = np.zeros((n + 1, 14))
        self.truth[:, 0] = np.concatenate(([0.0], self.t))
        self.truth[:, 10] = 1.0

    def init(self) -> dict[str, float]:
        return {"t": 0.0, "lat": 0.0, "lon": 0.0, "h": 0.0, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0}


@pytest.fixture(scope="module")
def equator() -> AtRest:
    return AtRest(HOURS, RATE)


def north_error(sol: np.ndarray, lat0_deg: float) -> np.ndarray:
    """North position error (m) of solution rows at rest: (L - L0)(R_N + h), R_N at the equator."""
    return np.radians(sol[:, 1] - lat0_deg) * R_N_EQ


def strapdown_north_error(exact: AtRest, model: errors.ImuErrorModel) -> tuple[np.ndarray, np.ndarray]:
    """(t from start, north error) of the nonlinear strapdown at 1 s, vertical held."""
    t, dth, dv, _ = errors.apply(model, exact.t, exact.dtheta, exact.dv, 0, t_start=exact.t0)
    sol = navigate(t, dth, dv, exact.init(), samples=2, vertical="hold")
    sol = sol[int(RATE / 2) - 1 :: int(RATE / 2)]  # 1 s rows
    return sol[:, 0] - exact.t0, north_error(sol, exact.truth[0, 1])


def fit_schuler(t: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """(amplitude, period) of x(t) = c0 + c1 cos(w t) + c2 sin(w t), least squares over w (s)."""

    def resid(w: float) -> tuple[float, float]:
        a = np.column_stack([np.ones_like(t), np.cos(w * t), np.sin(w * t)])
        coef, *_ = np.linalg.lstsq(a, x, rcond=None)
        return float(np.sum((a @ coef - x) ** 2)), float(math.hypot(coef[1], coef[2]))

    w0 = 2.0 * math.pi / 5064.0
    grid = np.linspace(0.8 * w0, 1.2 * w0, 801)
    best = grid[int(np.argmin([resid(w)[0] for w in grid]))]
    lo, hi = best - 0.4 * w0 / 800, best + 0.4 * w0 / 800
    for _ in range(60):  # golden-section refinement
        m1, m2 = lo + 0.382 * (hi - lo), lo + 0.618 * (hi - lo)
        if resid(m1)[0] < resid(m2)[0]:
            hi = m2
        else:
            lo = m1
    w = 0.5 * (lo + hi)
    return resid(w)[1], 2.0 * math.pi / w


def schuler_expected() -> tuple[float, float]:
    """(b R/g, 2 pi sqrt(R/g)) on the equator for 1 mg: R = R_N + h, g the normal gravity there."""
    ws2 = G_EQ / R_N_EQ
    return MG / ws2, 2.0 * math.pi / math.sqrt(ws2)


def check_schuler(amp: float, period: float) -> None:
    amp_exp, per_exp = schuler_expected()
    assert abs(amp / amp_exp - 1.0) < 0.005
    assert abs(period / per_exp - 1.0) < 0.005
    # The bands, with the textbook's round figures (R = 6371 km, g = 9.80665 m/s^2).
    assert abs(amp / (MG * 6371e3 / 9.80665) - 1.0) < 0.02
    assert abs(period / (84.4 * 60.0) - 1.0) < 0.01


def test_schuler_oscillation_from_an_accelerometer_bias_strapdown(equator: AtRest) -> None:
    model = errors.ImuErrorModel(accel=errors.SensorErrorModel(bias=(MG, 0.0, 0.0)))
    t, x = strapdown_north_error(equator, model)
    amp, period = fit_schuler(t, x)
    check_schuler(amp, period)
    # b > 0 along north: the estimate accelerates north, x = +A (1 - cos).
    assert x[int(np.argmin(abs(t - period / 2)))] == pytest.approx(2.0 * amp, rel=0.01)


@pytest.mark.plain_python_slow
def test_schuler_oscillation_from_an_accelerometer_bias_covariance(equator: AtRest) -> None:
    exact = equator
    track = cov.track_means(exact.t0, exact.t, exact.dtheta, exact.dv, exact.truth, int(RATE))
    spec = cov.AnalysisSpec(em.ImuSpec(accel_bias=MG))
    P = cov.propagate(track, spec, vertical="hold")["accel_bias"]
    sigma_n = cov.sigma_rows(P)[:, 0]
    amp, period = fit_schuler(track.t - track.t[0], sigma_n)
    check_schuler(amp, period)


def gyro_closed_form(t: np.ndarray, eps: float) -> np.ndarray:
    """North error from an east gyro bias eps (module docstring), R = R_N, g at the equator."""
    ws2 = G_EQ / R_N_EQ
    ws = math.sqrt(ws2)
    return -G_EQ * eps / (ws2 - OMEGA**2) * (np.sin(OMEGA * t) / OMEGA - np.sin(ws * t) / ws)


def check_gyro_response(t: np.ndarray, x: np.ndarray) -> None:
    ref = gyro_closed_form(t, 0.01 * DEG_PER_H)
    late = t >= 1800.0  # from half an hour on (before, the error is a few metres)
    rel = np.abs(x[late] / ref[late] - 1.0)
    assert rel.max() < 0.005
    assert rel.max() < 0.05  # the band
    # Without the Earth-rate coupling the 4 h value would be off by far more than the band.
    single = -(R_N_EQ * 0.01 * DEG_PER_H) * (t[-1] - math.sin(math.sqrt(G_EQ / R_N_EQ) * t[-1]) / math.sqrt(G_EQ / R_N_EQ))
    assert abs(x[-1] / single - 1.0) > 0.10


def test_gyro_bias_position_growth_strapdown(equator: AtRest) -> None:
    model = errors.ImuErrorModel(gyro=errors.SensorErrorModel(bias=(0.0, 0.01 * DEG_PER_H, 0.0)))
    t, x = strapdown_north_error(equator, model)
    assert t[-1] == pytest.approx(HOURS * 3600.0)
    check_gyro_response(t, x)


def test_gyro_bias_position_growth_covariance(equator: AtRest) -> None:
    exact = equator
    track = cov.track_means(exact.t0, exact.t, exact.dtheta, exact.dv, exact.truth, int(RATE))
    eps = 0.01 * DEG_PER_H
    east_only = cov.Source("east gyro bias", (em.X_BG + 1,), (eps**2,), (0.0,) * 10)
    P = cov.propagate(track, cov.AnalysisSpec(em.ImuSpec()), vertical="hold", only=east_only)["east gyro bias"]
    t = track.t - track.t[0]
    check_gyro_response(t, -cov.sigma_rows(P)[:, 0])  # sigma = |x|, x < 0 here


# --- covariance against Monte Carlo -------------------------------------------------------------


def chi_band(dof: int, p_two_sided: float) -> tuple[float, float]:
    """Band of s / sigma for a sample sigma with ``dof`` degrees of freedom (Wilson-Hilferty quantiles)."""
    from statistics import NormalDist

    z = NormalDist().inv_cdf(1.0 - p_two_sided / 2.0)
    k = 2.0 / (9.0 * dof)

    def q(zz: float) -> float:  # chi2 quantile / dof
        return (1.0 - k + zz * math.sqrt(k)) ** 3

    return math.sqrt(q(-z)), math.sqrt(q(z))


MC_RUNS = 300
MC_SPEC = {  # small biases, large scale factors and misalignments: the augmented states dominate
    "gyro_arw": 0.05, "gyro_bias": 2.0, "accel_vrw": 0.02, "accel_bias": 2e-3,
    "gyro_scale": 3000.0, "accel_scale": 3000.0, "gyro_misalignment": 600.0, "accel_misalignment": 600.0,
}


@pytest.fixture(scope="module")
def flight_short() -> object:
    return load("flight")


@pytest.mark.plain_python_slow
def test_covariance_matches_monte_carlo(flight_short: object) -> None:
    opts = an.AnalysisOptions(runs=MC_RUNS, jobs=2, duration=120.0, rate=50.0, vertical="free", every=1.0)
    spec = cov.spec_from_keys(MC_SPEC)
    result = an.analyze(flight_short, spec, opts)
    # Every source contributes: the scale factors and misalignments are not negligible.
    total = result.budget["total"]
    for name in ("gyro_scale", "gyro_misalignment", "accel_scale", "accel_misalignment"):
        assert np.max(result.budget[name] / total) > 0.1, name
    times = [30, 60, 90, 120]
    rows = [int(np.argmin(abs(result.t - result.t[0] - s))) for s in times]
    cols = range(9)
    lo, hi = chi_band(MC_RUNS - 1, 1e-3 / (len(rows) * len(cols)))
    ratio = result.montecarlo[rows][:, cols] / result.covariance[rows][:, cols]
    assert np.all((ratio > lo) & (ratio < hi)), (lo, hi, ratio)


@pytest.mark.plain_python_slow
def test_jobs_and_dask_cluster_give_identical_numbers(flight_short: object) -> None:
    spec = cov.spec_from_grade("tactical")
    base = an.AnalysisOptions(runs=6, jobs=1, duration=20.0, rate=50.0, seed=7)
    one = an.analyze(flight_short, spec, base)
    two = an.analyze(flight_short, spec, an.AnalysisOptions(**{**base.__dict__, "jobs": 2}))
    assert np.array_equal(one.montecarlo, two.montecarlo)
    assert np.all(one.montecarlo[1:] > 0.0)
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc:
        remote = an.analyze(flight_short, spec, an.AnalysisOptions(**{**base.__dict__, "cluster": lc.scheduler_address}))
    assert np.array_equal(one.montecarlo, remote.montecarlo)
    other_seed = an.analyze(flight_short, spec, an.AnalysisOptions(**{**base.__dict__, "seed": 8}))
    assert not np.array_equal(one.montecarlo, other_seed.montecarlo)


@pytest.mark.plain_python_slow
def test_budget_sums_to_the_full_propagation(flight_short: object) -> None:
    """The sources' covariances add up to one propagation of all states together (linearity)."""
    spec = cov.spec_from_keys(MC_SPEC | {"gyro_bias_instability": 5.0, "gyro_bias_tau": 100.0,
                                         "accel_bias_instability": 1e-3, "accel_bias_tau": 100.0})
    exact = an.exact_run(flight_short, 30.0, 50.0)
    track = cov.track_means(exact.t0, exact.t, exact.dtheta, exact.dv, exact.truth, 5)
    parts = cov.propagate(track, spec, every=10)
    srcs = cov.sources(spec)
    states = tuple(sorted({s for src in srcs for s in src.states}))
    p0 = {s: v for src in srcs for s, v in zip(src.states, src.p0) if v > 0}
    q = np.zeros(9 + len(states))
    for src in srcs:
        ix = list(range(9)) + [9 + states.index(s) for s in src.states]
        q[ix] += np.array(src.q)
    everything = cov.Source("all", states, tuple(p0.get(s, 0.0) for s in states), tuple(q))
    full = cov.propagate(track, spec, every=10, only=everything)["all"]
    summed = sum(parts.values())
    assert np.allclose(full, summed, rtol=1e-9, atol=1e-15 * np.abs(full).max())
    assert summed[-1, 6, 6] > 0.0


# --- command line ----------------------------------------------------------------------------------


def test_cli_writes_the_contract_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    code = main(["analyze", "flight", "--runs", "3", "--jobs", "1", "--duration", "5", "--rate", "50", "-o", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "total (covariance)" in printed and "Monte Carlo (3 runs)" in printed
    for name in ("covariance.csv", "montecarlo.csv"):
        lines = (out / name).read_text().splitlines()
        assert lines[0] == "t,sigma_n,sigma_e,sigma_d,sigma_vn,sigma_ve,sigma_vd,sigma_att_n,sigma_att_e,sigma_att_d"
        assert len(lines) == 1 + 6  # t = 0..5 s
    budget = (out / "budget.csv").read_text().splitlines()
    assert budget[0] == "source,pos_h,pos_v,vel_h,att_level,att_yaw"
    assert [r.split(",")[0] for r in budget[1:]] == list(cov.SOURCES) + ["total"]
    png = (out / "analysis.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    from rerun.chunk import RrdReader

    table = np.loadtxt(out / "covariance.csv", delimiter=",", skiprows=1)
    seen = {}
    for ch in RrdReader(str(out / "analysis.rrd")).stream():
        batch = ch.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("Scalars:scalars"):
                seen[ch.entity_path] = np.array(batch.column(name).to_pylist(), dtype=float)
    assert np.array_equal(seen["/analysis/covariance/position"], table[:, 1:4])
    assert set(seen) == {f"/analysis/{k}/{q}" for k in ("covariance", "montecarlo")
                         for q in ("position", "velocity", "attitude")}


@pytest.mark.parametrize(
    "args, message",
    [
        (["nosuch"], "no such scenario"),
        (["flight", "--imu-spec", "SPEC", "--duration", "5"], "unknown keys gyro_scalefactor"),
        (["flight", "--imu-spec", "NEG", "--duration", "5"], "must be non-negative"),
        (["flight", "--duration", "0.5", "--rate", "50"], "shorter than one output interval"),
    ],
)
def test_cli_bad_input_exits_2_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                  args: list[str], message: str) -> None:
    (tmp_path / "SPEC").write_text("gyro_scalefactor = 10.0\n")
    (tmp_path / "NEG").write_text("gyro_scale = -1.0\n")
    out = tmp_path / "out"
    args = [str(tmp_path / a) if a in ("SPEC", "NEG") else a for a in args]
    code = main(["analyze", *args, "--runs", "2", "--jobs", "1", "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("mavins analyze: error: ") and message in err[0], err
    assert not out.exists()


def test_cli_output_that_is_a_file_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "file"
    target.write_text("keep")
    assert main(["analyze", "flight", "--runs", "2", "--duration", "2", "-o", str(target)]) == 2
    assert "expected a directory" in capsys.readouterr().err
    assert target.read_text() == "keep"


def test_monte_carlo_sigma_is_the_sample_sigma_over_n_minus_1() -> None:
    """analysis.mc_sigma: the sample standard deviation with n - 1 (two runs a and -a give a sqrt(2), not a),
    per output time and column, the attitude columns turned to degrees and nothing else."""
    a = np.arange(1.0, 10.0) * 0.01
    errors = np.stack([np.stack([a, 2 * a]), np.stack([-a, -2 * a])])  # (runs 2, n_out 2, 9)
    s = an.mc_sigma(errors)
    want = np.stack([a, 2 * a]) * math.sqrt(2.0)
    want[:, 6:9] *= 180.0 / math.pi
    np.testing.assert_allclose(s, want, rtol=1e-14, atol=0)


def test_the_printed_table_sums_north_and_east_as_the_budget_does() -> None:
    """The summary's Monte Carlo row: horizontal position and velocity and the level attitude as the root of
    the north and east sample variances (as cov.budget_row for the covariance), vertical and yaw as they are."""
    budget = {name: np.array([1.0, 2.0, 3.0, 4.0, 5.0]) for name in cov.SOURCES}
    budget["total"] = np.array([6.0, 7.0, 8.0, 9.0, 10.0])
    m = np.array([3.0, 4.0, 12.0, 0.6, 0.8, 0.05, 0.05, 0.12, 0.7])
    result = an.AnalysisResult(np.array([0.0, 60.0]), np.zeros((2, 9)), np.stack([np.zeros(9), m]), budget, 40)
    lines = an._table(result).splitlines()
    assert lines[0] == "error budget at t = 60 s (1-sigma, each source alone)"
    mc = lines[-1]
    assert mc.startswith("Monte Carlo (40 runs)")
    assert [float(v) for v in mc.split(")")[1].split()] == pytest.approx([5.0, 12.0, 1.0, 0.13, 0.7], rel=1e-12)
    assert [float(v) for v in lines[-2].split(")")[1].split()] == [6.0, 7.0, 8.0, 9.0, 10.0]


MC_HOLD_SPEC = cov.AnalysisSpec(  # gyro and accelerometer with different figures, instability and rate random walk
    em.ImuSpec(gyro_arw=0.1 * math.radians(1.0) / 60.0, gyro_bias=math.radians(1.0) / 3600.0,
               gyro_gm=math.radians(3.0) / 3600.0, gyro_tau=40.0, gyro_rrw=math.radians(2.0) / 3600.0 / 10.0,
               accel_vrw=0.05 / 60.0, accel_bias=1e-3, accel_gm=4e-3, accel_tau=90.0, accel_rrw=2e-4),
    gyro_scale=1500e-6, accel_scale=2000e-6, gyro_misalignment=60.0 * cov.ARCSEC,
    accel_misalignment=100.0 * cov.ARCSEC)


@pytest.mark.plain_python_slow
def test_covariance_matches_monte_carlo_with_every_source_and_the_vertical_held(flight_short: object) -> None:
    """``--vertical hold`` with gyro and accelerometer figures that differ, Gauss-Markov instabilities and rate
    random walks: the instability and rate-random-walk sources are not negligible (above 5 % of the total),
    the held vertical is zero in the covariance and round-off in the runs, and every horizontal and attitude sigma of the 300 runs lies in the sample sigma's band around
    the covariance's (chi with 299 dof, Bonferroni over the values compared, 1e-3 overall)."""
    opts = an.AnalysisOptions(runs=MC_RUNS, jobs=2, duration=120.0, rate=50.0, vertical="hold", every=1.0)
    result = an.analyze(flight_short, MC_HOLD_SPEC, opts)
    total = result.budget["total"]
    horizontal = [0, 2, 3, 4]  # the budget's pos_h, vel_h, att_level, att_yaw (pos_v is held)
    for name in ("gyro_instability", "accel_instability", "gyro_rate_random_walk", "accel_rate_random_walk"):
        assert np.max(result.budget[name][horizontal] / total[horizontal]) > 0.05, name
    assert total[1] == 0.0
    assert np.all(result.covariance[:, [2, 5]] == 0.0)
    assert np.all(result.montecarlo[:, [2, 5]] < 1e-9)  # held to the truth: round-off only
    times = [30, 60, 90, 120]
    rows = [int(np.argmin(abs(result.t - result.t[0] - s))) for s in times]
    cols = [0, 1, 3, 4, 6, 7, 8]
    lo, hi = chi_band(MC_RUNS - 1, 1e-3 / (len(rows) * len(cols)))
    ratio = result.montecarlo[rows][:, cols] / result.covariance[rows][:, cols]
    assert np.all((ratio > lo) & (ratio < hi)), (lo, hi, ratio)


# --- the pieces of mavins/analysis.py, each against what it promises (fast: the mutation run's tests) ---------
def test_grid_outputs_every_interval_in_whole_steps_of_whole_updates() -> None:
    """make_grid: the output interval in whole strapdown updates, the propagation step the nearest divisor of it
    to ``step``; Grid.every the steps per output row."""
    g = an.make_grid(100.0, an.AnalysisOptions(every=1.0, step=0.1, samples=2))
    assert (g.out_samples, g.step_samples, g.samples, g.every) == (100, 10, 2, 10)
    g = an.make_grid(250.0, an.AnalysisOptions(every=1.0, step=0.3, samples=2))  # 250 / 75 -> 3, not a divisor: 2
    assert (g.out_samples, g.step_samples, g.every) == (250, 125, 2)
    g = an.make_grid(50.0, an.AnalysisOptions(every=0.01, step=0.1, samples=2))  # shorter than one update: one
    assert (g.out_samples, g.step_samples, g.every) == (2, 2, 1)
    g = an.make_grid(50.0, an.AnalysisOptions(every=1.0, step=5.0, samples=1))  # a step longer than the output
    assert (g.out_samples, g.step_samples, g.every) == (50, 50, 1)
    g = an.make_grid(10.0, an.AnalysisOptions(every=2.0, step=0.01, samples=2))  # steps below one sample: per sample
    assert (g.out_samples, g.step_samples, g.every) == (20, 1, 20)


def test_run_seeds_are_numpys_seed_sequence_of_seed_and_index() -> None:
    """run_seeds(seed, i): the 64-bit seed of SeedSequence([seed, i])'s first two words (low, high), and a
    generator on SeedSequence([seed, i, 1]): reproducible, different for every run and every seed."""
    for seed, i in ((0, 0), (7, 3), (2**40, 99)):
        st = np.random.SeedSequence([seed, i]).generate_state(2)
        s, rng = an.run_seeds(seed, i)
        assert s == int(st[0]) + (int(st[1]) << 32) and 0 <= s < 2**64
        assert rng.standard_normal() == np.random.default_rng(np.random.SeedSequence([seed, i, 1])).standard_normal()
    seeds = {an.run_seeds(s, i)[0] for s in range(3) for i in range(50)}
    assert len(seeds) == 150


def test_error_model_draws_each_runs_scale_and_misalignment_from_the_spec() -> None:
    """error_model: the gyro triad takes the gyro figures and the accelerometer's its own; each run's scale
    factors (ppm) and off-diagonal misalignments (rad) are N(0, 1-sigma) draws, the diagonal of the
    misalignment zero. Over 4000 runs each sample sigma lies in its chi band (3999 dof, 1e-3 over the 24
    compared, Wilson-Hilferty)."""
    spec = cov.AnalysisSpec(em.ImuSpec(gyro_arw=1e-4, gyro_bias=2e-5, gyro_gm=3e-5, gyro_tau=40.0, gyro_rrw=4e-6,
                                       accel_vrw=1e-3, accel_bias=2e-3, accel_gm=3e-3, accel_tau=90.0,
                                       accel_rrw=4e-4),
                            gyro_scale=1500e-6, accel_scale=400e-6, gyro_misalignment=2e-4, accel_misalignment=7e-4)
    rng = np.random.default_rng(11)
    models = [an.error_model(spec, rng) for _ in range(4000)]
    m = models[0]
    assert (m.gyro.turn_on_bias_sigma, m.gyro.bias_instability_sigma, m.gyro.bias_instability_tau,
            m.gyro.random_walk, m.gyro.rate_random_walk) == (2e-5, 3e-5, 40.0, 1e-4, 4e-6)
    assert (m.accel.turn_on_bias_sigma, m.accel.bias_instability_sigma, m.accel.bias_instability_tau,
            m.accel.random_walk, m.accel.rate_random_walk) == (2e-3, 3e-3, 90.0, 1e-3, 4e-4)
    lo, hi = chi_band(3999, 1e-3 / 24)
    for triad, scale, mis in (("gyro", 1500.0, 2e-4), ("accel", 400.0, 7e-4)):
        sf = np.array([getattr(x, triad).scale_factor_ppm for x in models])
        mm = np.array([getattr(x, triad).misalignment for x in models])
        assert np.all(mm[:, [0, 1, 2], [0, 1, 2]] == 0.0)
        for s in np.std(sf, axis=0, ddof=1) / scale:
            assert lo < s < hi, (triad, s)
        off = mm[:, [0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1]]
        for s in np.std(off, axis=0, ddof=1) / mis:
            assert lo < s < hi, (triad, s)


STATIC_SC = load("static")
EQUATOR_SC = type(STATIC_SC)("static_equator", STATIC_SC.source,
                             {**STATIC_SC.doc, "start": {**STATIC_SC.doc["start"], "lat": 0.0}})


@pytest.mark.parametrize("vertical", ["hold", "free"])
def test_a_monte_carlo_run_is_the_strapdown_error_at_each_output_time(vertical: str) -> None:
    """monte_carlo_run at rest on the equator with an accelerometer turn-on bias alone: row 0 zero, then one
    row per second; the horizontal velocity error is b_h t and the position error b_h t^2/2 (the Schuler term
    is (g/R) t^2/6 = 1e-5 relative over 6 s, and the equator has no vertical Earth rate to turn them), so
    |dv| / t is the same at every row and |dp| / |dv| = t / 2 at the row's own time (a row taken one update
    early or late breaks both by 0.02 / t); the vertical is zero with ``hold``; with ``free`` dp_D / dv_D =
    t / 2 up to the Coriolis coupling of the east error, relative Omega t |b_E / b_D| / 3 (and the vertical
    error reaches the east one likewise)."""
    spec = cov.AnalysisSpec(em.ImuSpec(accel_bias=1e-3))
    grid = an.make_grid(50.0, an.AnalysisOptions(every=1.0, samples=2))
    err = an.monte_carlo_run(an.MonteCarloJob(EQUATOR_SC, 6.0, 50.0, spec, 3, 0, vertical, grid))
    assert err.shape == (7, 9) and not err[0].any()
    t = np.arange(1.0, 7.0)
    dv = np.hypot(err[1:, 3], err[1:, 4])
    dp = np.hypot(err[1:, 0], err[1:, 1])
    assert dv[0] > 1e-4  # the drawn bias: 1e-3 m/s^2 per axis
    # a free vertical feeds the east error through Coriolis (2 Omega dv_D): relative Omega t |b_D / b_h|
    tol = 1e-4 + (2.0 * OMEGA * 6.0 * abs(err[1, 5]) / dv[0] if vertical == "free" else 0.0)
    np.testing.assert_allclose(dv / t, dv[0], rtol=tol)
    np.testing.assert_allclose(dp / dv, t / 2.0, rtol=tol)
    if vertical == "hold":
        assert np.all(np.abs(err[:, 2]) < 1e-9) and np.all(np.abs(err[:, 5]) < 1e-9)
    else:
        coupling = OMEGA * 6.0 * abs(err[1, 4] / err[1, 5]) / 3.0
        np.testing.assert_allclose(err[1:, 2] / err[1:, 5], t / 2.0, rtol=2.0 * coupling + 1e-5)
    assert np.all(np.abs(err[:, 6:9]) < 1e-7)  # no gyro error: the attitude stays (Earth-rate coupling only)


def test_analyze_refuses_too_few_runs_and_too_short_a_run_and_reports_the_grid() -> None:
    """analyze: fewer than 2 runs and a run shorter than one output interval are refused with one line each;
    a short analysis reports one row per second from 0, the covariance and the runs zero at 0 (both start
    from the truth), and the budget of every source and the total."""
    spec = cov.AnalysisSpec(em.ImuSpec(accel_bias=1e-3, gyro_bias=1e-5))
    with pytest.raises(ValueError, match=r"^--runs must be at least 2 \(a sample standard deviation\), got 1$"):
        an.analyze(STATIC_SC, spec, an.AnalysisOptions(runs=1, duration=3.0))
    with pytest.raises(ValueError, match=r"^0.5 s at 50 Hz is shorter than one output interval \(1 s\)$"):
        an.analyze(STATIC_SC, spec, an.AnalysisOptions(runs=2, duration=0.5, rate=50.0))
    res = an.analyze(STATIC_SC, spec, an.AnalysisOptions(runs=3, jobs=1, duration=3.0, rate=20.0))
    np.testing.assert_allclose(res.t, [0.0, 1.0, 2.0, 3.0], atol=1e-12)
    assert res.covariance.shape == res.montecarlo.shape == (4, 9) and res.runs == 3
    assert not res.covariance[0].any() and not res.montecarlo[0].any()
    assert np.all(res.covariance[-1, :2] > res.covariance[1, :2]) and np.all(res.montecarlo[-1, 3:5] > 0.0)
    assert list(res.budget) == list(cov.SOURCES) + ["total"] and set(res.by_source) == set(cov.SOURCES)


def test_duration_and_rate_come_from_the_options_then_the_scenario() -> None:
    """--duration, else the scenario's [imu] duration, else its trajectory's length; --rate, else the
    scenario's."""
    assert an._duration_rate(STATIC_SC, an.AnalysisOptions()) == (600.0, 100.0)
    assert an._duration_rate(STATIC_SC, an.AnalysisOptions(duration=5.0, rate=20.0)) == (5.0, 20.0)
    from sim.scenarios import Scenario, build

    doc = {k: v for k, v in STATIC_SC.doc.items() if k != "imu"}
    doc["segments"] = [{"kind": "static", "duration": 42.0}]
    bare = Scenario("bare", STATIC_SC.source, doc)
    assert bare.duration is None
    traj = build(bare)
    assert an._duration_rate(bare, an.AnalysisOptions()) == (float(traj.t - traj.t0), 100.0) == (42.0, 100.0)


def test_exact_run_is_made_once_per_scenario_and_length() -> None:
    """exact_run keeps the scenario's exact increments: the same scenario and length give the same object, a
    different length a different run."""
    a = an.exact_run(STATIC_SC, 2.0, 50.0)
    assert an.exact_run(STATIC_SC, 2.0, 50.0) is a
    b = an.exact_run(STATIC_SC, 3.0, 50.0)
    assert b is not a and len(b.t) == 150 and len(a.t) == 100


def test_the_table_rows_have_the_printed_widths() -> None:
    """_table: each row is the name in 24 columns, then pos_h, pos_v, vel_h (12 columns each) and the two
    attitudes (13 each), four significant digits; the header names them."""
    budget = {name: np.array([1.0, 0.123456, 12345.6, 2e-7, 90.0]) for name in cov.SOURCES}
    budget["total"] = np.array([6.0, 7.0, 8.0, 9.0, 10.0])
    result = an.AnalysisResult(np.array([0.0, 1.5]), np.zeros((2, 9)), np.zeros((2, 9)), budget, 2)
    lines = an._table(result).splitlines()
    assert lines[1] == ("source" + " " * 18 + "     pos_h m     pos_v m   vel_h m/s  att_lvl deg  att_yaw deg")
    assert lines[2] == (cov.SOURCES[0].ljust(24) + "           1" + "      0.1235" + "   1.235e+04" + "        2e-07"
                        + "           90")
    assert len(lines) == 2 + len(cov.SOURCES) + 2 and lines[-2].startswith("total (covariance)      ")
    assert lines[-1].startswith("Monte Carlo (2 runs)    ")


@pytest.mark.skipif(not an._have_matplotlib(), reason="matplotlib is not installed (analysis.png is optional)")
@pytest.mark.parametrize("span, unit", [(300.0, "s"), (3600.0, "min")])
def test_the_plot_shows_each_panel_against_time(tmp_path: Path, span: float, unit: str) -> None:
    """analysis.png: four panels, each the covariance 1-sigma (line) and the Monte Carlo sigma (dots) of one
    quantity (horizontal and vertical position, horizontal velocity, level attitude: north and east as root
    sum of squares), against time from the start in s, or in minutes beyond 10 minutes; 1100 x 700 pixels."""
    t = np.linspace(100.0, 100.0 + span, 5)
    c = np.arange(45.0).reshape(5, 9) + 1.0
    m = c * 2.0
    result = an.AnalysisResult(t, c, m, {}, 7)
    fig = an._figure(result)
    axes = fig.axes
    assert [ax.get_title() for ax in axes] == ["horizontal position (m)", "vertical position (m)",
                                               "horizontal velocity (m/s)", "level attitude (deg)"]
    scale = 60.0 if unit == "min" else 1.0
    for ax, (a, b) in zip(axes, ((0, 1), (2, None), (3, 4), (6, 7))):
        line, dots = ax.get_lines()
        np.testing.assert_allclose(line.get_xdata(), (t - 100.0) / scale)
        want_c = c[:, a] if b is None else np.hypot(c[:, a], c[:, b])
        want_m = m[:, a] if b is None else np.hypot(m[:, a], m[:, b])
        np.testing.assert_allclose(line.get_ydata(), want_c)
        np.testing.assert_allclose(dots.get_ydata(), want_m)
        np.testing.assert_allclose(dots.get_xdata(), (t - 100.0) / scale)
        assert dots.get_linestyle() == "None" and dots.get_marker() == "." and dots.get_markersize() == 3
        grid = ax.xaxis.get_gridlines()[0]
        assert grid.get_visible() and grid.get_alpha() == 0.3
    assert all(axes[0].get_shared_x_axes().joined(axes[0], ax) for ax in axes[1:])  # one time axis
    assert [ax.get_xlabel() for ax in axes[2:]] == [f"time ({unit})"] * 2
    labels = [tx.get_text() for tx in axes[0].get_legend().get_texts()]
    assert labels == ["covariance 1-sigma", "Monte Carlo sigma (7 runs)"]
    png = tmp_path / "a.png"
    an._plot(png, result)
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert (int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")) == (1100, 700)



@pytest.mark.skipif(not an._have_matplotlib(), reason="matplotlib is not installed (analysis.png is optional)")
@pytest.mark.parametrize("t, unit", [
    ([500.0, 600.0, 700.0], "s"),  # 200 s, not 1200: the span is last minus first
    ([0.0, 400.0, 800.0, 1200.0, 3600.0], "min"),  # the last time, not the second
    ([0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 700.0], "min"),  # from the first time to the last
    ([0.0, 300.0, 600.0], "s"),  # exactly 10 minutes: seconds still
    ([0.0, 300.0, 600.5], "min"),
])
def test_the_plot_turns_to_minutes_beyond_ten_minutes_of_span(t: list[float], unit: str) -> None:
    """_figure's time axis: minutes when the last output time is more than 600 s after the first."""
    n = len(t)
    result = an.AnalysisResult(np.array(t), np.ones((n, 9)), np.ones((n, 9)), {}, 2)
    fig = an._figure(result)
    assert fig.axes[2].get_xlabel() == f"time ({unit})"
    np.testing.assert_allclose(fig.axes[0].get_lines()[0].get_xdata(),
                               (np.array(t) - t[0]) / (60.0 if unit == "min" else 1.0))


def test_the_table_reports_the_last_output_time_and_row() -> None:
    """_table: the header's time and the Monte Carlo row are those of the last output row, not the second."""
    budget = {name: np.ones(5) for name in cov.SOURCES + ("total",)}
    mc = np.zeros((3, 9))
    mc[1] = 1.0
    mc[2] = [3.0, 4.0, 12.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.7]
    lines = an._table(an.AnalysisResult(np.array([0.0, 1.0, 2.0]), np.zeros((3, 9)), mc, budget, 5)).splitlines()
    assert lines[0] == "error budget at t = 2 s (1-sigma, each source alone)"
    assert [float(v) for v in lines[-1].split(")")[1].split()] == pytest.approx([5.0, 12.0, 0.0, 0.0, 0.7])


SHORT_SC = type(STATIC_SC)("static_short", STATIC_SC.source,
                           {**STATIC_SC.doc, "imu": {"rate": 20.0, "duration": 3.0}})
LAB_SC = type(STATIC_SC)("static_lab", STATIC_SC.source,
                         {**STATIC_SC.doc, "imu": {"rate": 20.0, "duration": 3.0, "earth": "none"}})


def test_analyze_takes_the_scenarios_length_and_rate_and_reports_the_last_row_budget() -> None:
    """With neither --duration nor --rate the scenario's [imu] gives them (3 s at 20 Hz: rows at 0, 1, 2, 3 s);
    a run of exactly one output interval is analysed; the budget is that of the last row, each source's
    and the total's (core/covariance.budget_row of the covariance printed in the last row)."""
    spec = cov.AnalysisSpec(em.ImuSpec(accel_bias=1e-3, gyro_bias=1e-5))
    res = an.analyze(SHORT_SC, spec, an.AnalysisOptions(runs=2, jobs=1))
    np.testing.assert_allclose(res.t, [0.0, 1.0, 2.0, 3.0], atol=1e-12)
    c = res.covariance[-1]
    np.testing.assert_allclose(res.budget["total"], [math.hypot(c[0], c[1]), c[2], math.hypot(c[3], c[4]),
                                                     math.hypot(c[6], c[7]), c[8]], rtol=1e-12)
    for name, P in res.by_source.items():
        d = np.sqrt(np.maximum(np.diagonal(P[-1]), 0.0))
        assert res.budget[name][1] == pytest.approx(d[8], rel=1e-12, abs=1e-300), name
    one = an.analyze(SHORT_SC, spec, an.AnalysisOptions(runs=2, jobs=1, duration=1.0))  # 20 samples: one interval
    np.testing.assert_allclose(one.t, [0.0, 1.0], atol=1e-12)
    many = an.analyze(SHORT_SC, spec, an.AnalysisOptions(runs=2, jobs=1, every=0.2))  # more rows than 9 columns
    assert many.covariance.shape == many.montecarlo.shape == (16, 9)


@pytest.mark.parametrize("vertical", ["free", "hold"])
def test_in_the_laboratory_the_covariance_and_the_runs_are_the_closed_form(vertical: str) -> None:
    """A scenario with ``earth = "none"`` (no Earth rate, gravity model or curvature): with an accelerometer
    turn-on bias sigma_b alone, the covariance of each horizontal velocity is sigma_b t and of position
    sigma_b t^2/2 exactly (F^3 = 0 on bias -> dv -> dp, so the second-order transition is exact), the held
    vertical is zero; each Monte Carlo run's horizontal error is b t and b t^2/2 (velocity to round-off), at
    the output times of ``samples = 1`` (one update per sample), the same for a second call (its own seed)."""
    sb = 1e-3
    spec = cov.AnalysisSpec(em.ImuSpec(accel_bias=sb))
    opts = an.AnalysisOptions(runs=2, jobs=1, vertical=vertical, samples=1)
    grid, by_source, t = an.covariance_part(LAB_SC, spec, opts)
    np.testing.assert_allclose(t, [0.0, 1.0, 2.0, 3.0], atol=1e-12)
    P = by_source["accel_bias"]
    np.testing.assert_allclose(np.sqrt(P[:, 3, 3]), sb * t, rtol=1e-12)
    np.testing.assert_allclose(np.sqrt(P[:, 6, 6]), sb * t ** 2 / 2.0, rtol=1e-12)
    assert (np.all(P[:, 5, 5] == 0.0) and np.all(P[:, 8, 8] == 0.0)) == (vertical == "hold")
    job = an.MonteCarloJob(LAB_SC, 3.0, 20.0, spec, 5, 1, vertical, grid)
    err = an.monte_carlo_run(job)
    assert np.array_equal(err, an.monte_carlo_run(job))  # the run's seed, not a fresh one
    b = err[1, 3:5]
    np.testing.assert_allclose(err[1:, 3:5], np.outer(t[1:], b), rtol=1e-9, atol=1e-15)
    # position rows pass through latitude and longitude (radii at the start) and back (radii at the truth):
    # 1e-6 relative between the two conversions, far below a row one update off (1/20 s: 3 % at 3 s)
    np.testing.assert_allclose(err[1:, 0:2], np.outer(t[1:] ** 2 / 2.0, b), rtol=1e-5)


def test_error_models_draw_every_misalignment_element_on_its_own() -> None:
    """The six off-diagonal misalignment elements of a run are independent draws: over 4000 runs the sample
    correlation of any two is within 0.1 of zero (its standard deviation is 1/sqrt(4000) = 0.016)."""
    spec = cov.AnalysisSpec(em.ImuSpec(), gyro_misalignment=1e-3)
    rng = np.random.default_rng(12)
    off = np.array([np.asarray(an.error_model(spec, rng).gyro.misalignment)[[0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1]]
                    for _ in range(4000)])
    corr = np.corrcoef(off.T)
    assert np.all(np.abs(corr[~np.eye(6, dtype=bool)]) < 0.1), corr


def test_run_analyze_writes_the_budget_values_and_refuses_to_overwrite_the_scenario(tmp_path: Path) -> None:
    """budget.csv: one row per source and the total, each value the budget's own double (repr, comma
    separated); an output that is the scenario file itself is refused, naming it SCENARIO, and nothing is
    written."""
    spec = cov.AnalysisSpec(em.ImuSpec(accel_bias=1e-3, gyro_bias=1e-5))
    out = tmp_path / "out"
    an.run_analyze(SHORT_SC, spec, out, an.AnalysisOptions(runs=2, jobs=1))
    rows = (out / "budget.csv").read_text(encoding="utf-8").splitlines()
    res = an.analyze(SHORT_SC, spec, an.AnalysisOptions(runs=2, jobs=1))
    for row, name in zip(rows[1:], list(cov.SOURCES) + ["total"]):
        got = row.split(",")
        assert got[0] == name and [float(v) for v in got[1:]] == [float(v) for v in res.budget[name]]
    victim = tmp_path / "out2" / "budget.csv"
    victim.parent.mkdir()
    victim.write_text(Path(STATIC_SC.source).read_text())
    inside = type(STATIC_SC)("in_out", str(victim), SHORT_SC.doc)
    from mavins.common.files import DataFileError

    with pytest.raises(DataFileError, match=r"is also the input SCENARIO"):
        an.run_analyze(inside, spec, victim.parent, an.AnalysisOptions(runs=2, jobs=1))
    assert sorted(p.name for p in victim.parent.iterdir()) == ["budget.csv"]


def test_on_the_earth_the_vertical_channel_diverges_as_the_gravity_gradient_says() -> None:
    """The same 3 s at rest with a vertical accelerometer bias alone, on the Earth and in the laboratory: the
    laboratory's vertical position sigma is sigma_b t^2/2 exactly, the Earth's grows by the gravity
    gradient k = 2 g/R (x'' = b + k x: x = (b/k)(cosh(sqrt(k) t) - 1)), a factor 1 + k t^2/12 to first order
    (2.3e-6 at 3 s); the horizontal channels are unaffected at this order."""
    sb = 1e-3
    spec = cov.AnalysisSpec(em.ImuSpec(accel_bias=sb))
    opts = an.AnalysisOptions(runs=2, jobs=1, samples=1)
    _, earth_src, t = an.covariance_part(SHORT_SC, spec, opts)
    _, lab_src, _ = an.covariance_part(LAB_SC, spec, opts)
    pd_earth = np.sqrt(earth_src["accel_bias"][-1, 8, 8])
    pd_lab = np.sqrt(lab_src["accel_bias"][-1, 8, 8])
    assert pd_lab == pytest.approx(sb * t[-1] ** 2 / 2.0, rel=1e-12)
    k = 2.0 * G_EQ / R_N_EQ  # 47 deg N instead of the equator: the gradient differs by 0.5 %
    growth = k * t[-1] ** 2 / 12.0
    assert pd_earth / pd_lab - 1.0 == pytest.approx(growth, rel=0.1)
