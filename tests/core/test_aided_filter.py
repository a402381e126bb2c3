"""The closed-loop error-state filter (mavins/core/kalman.py, aided.py) and the simulator's aiding data.

Consistency is judged against chi-square distributions, with the quantiles
from the Wilson-Hilferty approximation (no SciPy): for a consistent filter
the error ``e`` with covariance ``P`` gives ``NEES = e^T P^-1 e ~ chi2(d)``,
and the average over N independent runs ``~ chi2(d N) / N``; the
innovations give ``NIS = nu^T S^-1 nu ~ chi2(dim nu)``, white in time, so
the mean over M innovations ``~ chi2(M dim) / M``. Two-sided 95 % bands.

Monte Carlo set-up (one simulated trajectory, N independent IMUs, GNSS and
initial errors):

* the flight scenario (take-off, hover, four legs at 10 m/s with
  coordinated turns) without its random vibration, 120 s at 100 Hz, two
  samples per attitude update, N_RUNS = 50 runs;
* the simulator's consumer grade, stochastic errors only: turn-on bias,
  Gauss-Markov bias instability, rate random walk, white noise,
  quantisation and timestamp jitter as the grade has them. Its deterministic
  errors (scale factor, misalignment, g-sensitivity) and dropped samples are
  not in the 15-state model, so they are switched off here;
* the filter's spec is errmodel.spec_from_grade("consumer"): the same figures;
* GNSS 1 Hz, 1 m horizontal, 1.5 m vertical, 0.1 m/s velocity;
* initial errors drawn from the filter's initial covariance: 3 m, 0.3 m/s,
  0.05 deg level, 3 deg yaw; the first 10 s at rest are used for ZUPT and
  ZARU;
* a second set-up adds the simulator's magnetometer (50 Hz, the live
  path's rate, 0.3 uT per axis, calibrated) and is held to the same bands,
  and to the issue's 0.1 deg on heading too.

Why the small initial level sigma and the rest period: the consumer part's
turn-on biases (8 mg, 0.33 deg/s, 1-sigma) are large. A level error that the
data cannot separate from the accelerometer bias (in hover they are one
quantity) of 0.3 deg gives the neglected second-order terms of the error
model, ``1/2 g |phi_h|^2`` on the vertical and ``1/2 g phi_D phi_h`` on the
horizontal specific force, a size several times the sigma of the estimated
accelerometer bias, and the filter becomes measurably inconsistent there
(measured with 0.5 deg level sigma: attitude ANEES 5.0 .. 5.5 from 30 to
70 s; with the accelerometer turn-on bias as the only bias, the z
accelerometer bias ends with mean z^2 7.7 instead of 1). A heading drifting at
0.33 deg/s before the first acceleration (no ZARU) is likewise outside the
first-order model. The tests check the filter where its model holds; those
limits are properties of the first-order ESKF, not tolerances.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mavins.core import aided
from mavins.core import earth
from mavins.core import errmodel as em
from mavins.core import kalman as kf
from mavins.core import strapdown as sd
from mavins.core.jit import for_frame
from mavins.core.rotation import dcm_to_euler, euler_to_dcm, quat_to_dcm, rotvec_to_dcm
from sim import aiding, errors
from sim.generate import generate
from sim.scenarios import Scenario, load
from support import NO_SMOOTHING, Z975, Z995, chi2_quantile, consumer_stochastic, quat_error, wrap_rad

N_RUNS = 50
DURATION = 120.0
RATE = 100.0
GNSS = aiding.GnssConfig(rate=1.0, sigma_h=1.0, sigma_v=1.5, sigma_vel=0.1)
INIT_SIGMA = {"sigma_pos": 3.0, "sigma_vel": 0.3, "sigma_level": 0.05, "sigma_yaw": 3.0}
STATIC = [(0.0, 10.0)]




def band(dof: int, n: int, z: float = Z975) -> tuple[float, float]:
    """Two-sided 95 % band (or the band of quantile z) of the mean of n independent chi2(dof) values."""
    return chi2_quantile(-z, dof * n) / n, chi2_quantile(z, dof * n) / n


def band99(dof: int, n: int) -> tuple[float, float]:
    """Two-sided 99 % band: for single-run checks, which would otherwise fail one seed in 20."""
    return band(dof, n, Z995)


def test_wilson_hilferty_against_tabulated_quantiles() -> None:
    """chi2 quantiles from tables: k = 60: 40.48, 83.30; k = 3: 0.2158, 9.348 (WH good to 1 % there)."""
    assert chi2_quantile(-Z975, 60) == pytest.approx(40.48, rel=2e-3)
    assert chi2_quantile(Z975, 60) == pytest.approx(83.30, rel=2e-3)
    assert chi2_quantile(Z975, 3) == pytest.approx(9.348, rel=1e-2)




MODEL = consumer_stochastic()


@pytest.fixture(scope="module")
def trajectory():
    sc = load("flight")
    doc = {k: v for k, v in sc.doc.items() if k != "perturbations"}
    return generate(Scenario("flight_quiet", sc.source, doc), duration=DURATION, rate=RATE, seed=0, grade="ideal")


def nav_errors(rows: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(phi, dv, dp) of kernel rows against truth rows (file units): estimate minus truth.

    ``C(est) = exp([phi x]) C(true)``, i.e. ``q(est) = r(phi) (x) q(true)``;
    position in NED metres through the radii of the true position.
    """
    phi = quat_error(rows[:, 10:14], truth[:, 10:14])
    lat = np.radians(truth[:, 1])
    h = truth[:, 3]
    s2 = np.sin(lat) ** 2
    a, e2 = 6378137.0, (1 / 298.257223563) * (2 - 1 / 298.257223563)
    r_n = a * (1 - e2) / (1 - e2 * s2) ** 1.5
    r_e = a / np.sqrt(1 - e2 * s2)
    dp = np.column_stack([(rows[:, 1] - lat) * (r_n + h), (rows[:, 2] - np.radians(truth[:, 2])) * (r_e + h) * np.cos(lat),
                          -(rows[:, 3] - h)])
    return np.column_stack([phi, rows[:, 4:7] - truth[:, 4:7], dp])


def perturbed_init(init: dict, rng: np.random.Generator, sigmas: dict | None = None) -> dict:
    """The true initial state with errors drawn from ``sigmas`` (the filter's P0; default INIT_SIGMA), plus those keys."""
    sig = INIT_SIGMA if sigmas is None else sigmas
    lat, h = math.radians(init["lat"]), init["h"]
    r_n, r_e = earth.radii(lat)
    dp = rng.standard_normal(3) * sig["sigma_pos"]
    dv = rng.standard_normal(3) * sig["sigma_vel"]
    phi = rng.standard_normal(3) * np.radians([sig["sigma_level"]] * 2 + [sig["sigma_yaw"]])
    c = rotvec_to_dcm(phi) @ euler_to_dcm(*np.radians([init["roll"], init["pitch"], init["yaw"]]))
    e = np.degrees(dcm_to_euler(c))
    return dict(init, lat=init["lat"] + math.degrees(dp[0] / (r_n + h)),
                lon=init["lon"] + math.degrees(dp[1] / ((r_e + h) * math.cos(lat))), h=h - dp[2],
                vn=init["vn"] + dv[0], ve=init["ve"] + dv[1], vd=init["vd"] + dv[2],
                roll=e[0], pitch=e[1], yaw=e[2], **sig)


def simulate_run(trajectory, seed: int, gnss_config: aiding.GnssConfig = GNSS):
    """IMU rows, GNSS rows, perturbed init and the true biases at the IMU rows of one run."""
    ex = trajectory.exact
    t, dth, dv, _ = errors.apply(MODEL, ex.t, ex.dtheta, ex.dv, seed, t_start=ex.t0)
    run = dataclasses.replace(trajectory, seed=seed)
    gnss = aiding.gnss(run, gnss_config)
    init = perturbed_init(ex.init(), np.random.default_rng([seed, 1]))
    bg, ba = errors.bias_states(MODEL, ex.t, seed, t_start=ex.t0)
    return np.column_stack([t, dth, dv]), gnss, init, bg, ba


EVERY = 50  # covariance kept every 50 attitude updates (1 s)
BIAS_SUM = np.zeros((6, em.NX))
BIAS_SUM[0:3, em.X_BG : em.X_BG + 3] = np.eye(3)
BIAS_SUM[0:3, em.X_GG : em.X_GG + 3] = np.eye(3)
BIAS_SUM[3:6, em.X_BA : em.X_BA + 3] = np.eye(3)
BIAS_SUM[3:6, em.X_GA : em.X_GA + 3] = np.eye(3)


MAG = aiding.MagConfig(rate=50.0)  # the live path's magnetometer rate (docs/filter.md), 0.3 uT, calibrated
MAG_SIGMA_YAW = MAG.sigma / (MAG.strength * math.cos(math.radians(MAG.inclination)))  # rad per sample


def magnetometer_rows(trajectory, seed: int, rate: float = MAG.rate) -> np.ndarray:
    """The simulator's magnetometer (at ``rate`` Hz) for run ``seed`` with the heading sigma column (deg) aided.py
    reads."""
    mag = aiding.magnetometer(dataclasses.replace(trajectory, seed=seed), dataclasses.replace(MAG, rate=rate))
    return np.column_stack([mag, np.full(mag.shape[0], math.degrees(MAG_SIGMA_YAW))])


def epoch_nees(nees: dict, rows: np.ndarray, p_history: np.ndarray, truth_all: np.ndarray):
    """Append one run's attitude, velocity and position NEES at its kept covariances (every EVERY rows) to
    ``nees``; returns the run's errors, truth rows and the kept rows' indices."""
    idx = 2 * (np.arange(rows.shape[0]) + 1)  # row k is the update at sample 2k+1: truth row 2(k+1)
    err = nav_errors(rows, truth_all[idx])
    sel = np.arange(p_history.shape[0]) * EVERY + EVERY - 1
    for k, o in (("att", 0), ("vel", 3), ("pos", 6)):
        e = err[sel, o : o + 3]
        pb = p_history[:, o : o + 3, o : o + 3]
        nees[k].append(np.einsum("ki,kij,kj->k", e, np.linalg.inv(pb), e))
    return err, idx, sel


def run_monte_carlo(trajectory, with_mag: bool) -> dict:
    """N runs: NEES per epoch (1 Hz) per block, errors, final bias NEES and z, NIS logs."""
    truth_all = trajectory.exact.truth
    out = {"nees": {k: [] for k in ("att", "vel", "pos")}, "err": [], "t": None, "bias_nees": [], "bias_z": [],
           "nis": [], "counts": [], "fixes": 0, "P_sigma": []}
    for r in range(N_RUNS):
        imu, gnss, init, bg, ba = simulate_run(trajectory, 1000 + r)
        kw = {"mag": magnetometer_rows(trajectory, 1000 + r), "declination": MAG.declination} if with_mag else {}
        rows, st = aided.navigate_aided(imu, init, gnss, static=STATIC, spec="consumer", file_units=False,
                                        covariance_every=EVERY, **kw)
        err, idx, sel = epoch_nees(out["nees"], rows, st["P_history"], truth_all)
        out["err"].append(err)
        out["P_sigma"].append(np.sqrt(np.diagonal(st["P_history"], axis1=1, axis2=2)[:, :9]))
        eb = np.concatenate([rows[-1, 23:26] - bg[idx[-1]], rows[-1, 26:29] - ba[idx[-1]]])
        pb = BIAS_SUM @ st["P"] @ BIAS_SUM.T
        out["bias_nees"].append(float(eb @ np.linalg.solve(pb, eb)))
        out["bias_z"].append(eb / np.sqrt(np.diag(pb)))
        np.testing.assert_allclose(np.sqrt(np.diag(pb)), rows[-1, 29:35], rtol=1e-12)
        out["nis"].append(st["nis"])
        out["fixes"] += int(np.sum(gnss[:, 0] <= imu[-1, 0]))
        out["counts"].append(st["counts"])
        out["t"] = rows[:, 0]
        out["t_sel"] = rows[sel, 0]
    out["P_sigma"] = np.array(out["P_sigma"])
    return out


@pytest.fixture(scope="module")
def monte_carlo(trajectory):
    """GNSS (and the rest window) only."""
    return run_monte_carlo(trajectory, False)


@pytest.fixture(scope="module")
def monte_carlo_mag(trajectory):
    """GNSS and the simulator's magnetometer."""
    return run_monte_carlo(trajectory, True)


@pytest.fixture(params=["monte_carlo", "monte_carlo_mag"])
def either_mc(request):
    """Each Monte Carlo set-up in turn."""
    return request.getfixturevalue(request.param)


@pytest.mark.parametrize("block", ["pos", "vel", "att"])
def test_monte_carlo_nees(either_mc, block: str) -> None:
    """ANEES (mean over runs, 3 dof, full 3x3 covariance) averaged over the 1 Hz epochs of the run.

    Each epoch's ANEES ~ chi2(3N)/N; the time average has the same mean and
    at most the spread of one epoch, so it lies in that band (N = 50: 2.36 .. 3.72).
    """
    anees = np.mean(np.array(either_mc["nees"][block]), axis=0)
    lo, hi = band(3, N_RUNS)
    assert lo < anees.mean() < hi, (block, anees.mean(), lo, hi)


def test_monte_carlo_accuracy(either_mc) -> None:
    """After the first 60 s: horizontal position RMS below 0.5 m, level attitude RMS below 0.1 deg.

    The heading is held to 0.1 deg with the magnetometer only
    (test_monte_carlo_heading_with_magnetometer): without one it is
    observable only in the turns and accelerations and drifts with the z
    gyro's bias instability (16 deg/h) in between, 0.33 deg by the
    covariance along the true trajectory (docs/filter.md "Limits"). Its
    consistency is part of the attitude NEES.
    """
    late = either_mc["t"] >= 60.0
    err = np.array(either_mc["err"])[:, late]
    assert math.sqrt(np.mean(np.sum(err[:, :, 6:8] ** 2, axis=2))) < 0.5
    assert np.degrees(math.sqrt(np.mean(np.sum(err[:, :, 0:2] ** 2, axis=2)))) < 0.1


def test_monte_carlo_heading_with_magnetometer(monte_carlo_mag) -> None:
    """With the 50 Hz magnetometer the heading RMS after the first 60 s is below the issue's 0.1 deg.

    The bound is the issue's; the covariance along the true trajectory gives
    0.09 deg for this set-up (benchmarks/heading_budget.py): the
    magnetometer sees heading plus tan(63 deg) ~ 2 times the tilt about
    magnetic north, which is known to about 0.05 deg.
    """
    late = monte_carlo_mag["t"] >= 60.0
    err = np.array(monte_carlo_mag["err"])[:, late]
    assert np.degrees(math.sqrt(np.mean(err[:, :, 2] ** 2))) < 0.1


def test_monte_carlo_biases_at_the_end(monte_carlo) -> None:
    """Gyro and accelerometer bias estimates (6 dof, sums of both bias parts) against the simulator's truth.

    Mean NEES over the runs in the chi2(6N)/N band; the number of the 6N
    components within 2 sigma at least the binomial(6N, 0.9545) 0.1 %
    quantile (normal approximation, mean - 3.09 sigma: 275 of 300 for N = 50).
    """
    lo, hi = band(6, N_RUNS)
    assert lo < np.mean(monte_carlo["bias_nees"]) < hi
    z = np.abs(np.array(monte_carlo["bias_z"]))
    n, p = z.size, 0.9545
    assert np.sum(z < 2.0) >= math.floor(n * p - 3.09 * math.sqrt(n * p * (1 - p)))


def test_monte_carlo_normalised_errors(either_mc) -> None:
    """Every state's normalised error e / sigma has an RMS between 1 / 1.5 and 1.5 over runs and 1 Hz
    epochs (issue target 1.5 above; the same factor below, so an over-cautious filter, whose sigmas are
    half again too large, fails as an over-confident one does; a consistent filter gives 1, and the RMS of
    50 x 120 unit normals lies within 1 +- 0.03). Attitude, velocity, position from the kept covariances;
    biases at the end."""
    sel = np.arange(either_mc["P_sigma"].shape[1]) * EVERY + EVERY - 1
    err = np.array(either_mc["err"])[:, sel]
    rms = np.sqrt(np.mean((err / either_mc["P_sigma"]) ** 2, axis=(0, 1)))
    assert np.all(rms < 1.5) and np.all(rms > 1.0 / 1.5), rms
    bias_rms = np.sqrt(np.mean(np.array(either_mc["bias_z"]) ** 2, axis=0))
    assert np.all(bias_rms < 1.5) and np.all(bias_rms > 1.0 / 1.5), bias_rms


@pytest.mark.parametrize("kind", [aided.K_GNSS_POS, aided.K_GNSS_VEL])
def test_monte_carlo_nis(monte_carlo, kind: int) -> None:
    """GNSS position and velocity NIS (3 dof): mean over every fix of every run in the chi2(3M)/M band."""
    nis = np.concatenate(monte_carlo["nis"])
    sel = (nis[:, 1] == kind) & (nis[:, 4] == 1.0)
    m = int(sel.sum())
    assert m == monte_carlo["fixes"]
    lo, hi = band(3, m)
    assert lo < nis[sel, 2].mean() < hi, (nis[sel, 2].mean(), lo, hi)
    assert all(c["gnss_pos"][1] == 0 and c["gnss_vel"][1] == 0 for c in monte_carlo["counts"])


def single_run(trajectory, seed: int, gnss_config: aiding.GnssConfig = GNSS, **kw):
    imu, gnss, init, bg, ba = simulate_run(trajectory, seed, gnss_config)
    rows, st = aided.navigate_aided(imu, init, gnss, static=STATIC, spec="consumer", file_units=False, **kw)
    idx = 2 * (np.arange(rows.shape[0]) + 1)
    return rows, st, nav_errors(rows, trajectory.exact.truth[idx]), gnss


def test_gnss_outage_stays_inside_three_sigma(trajectory) -> None:
    """A 30 s outage (60..90 s, through the first turns): every position error within 3 sigma.

    The horizontal sigma must grow during the outage (free inertial with
    the estimated biases) and shrink again once fixes return.
    """
    cfg = dataclasses.replace(GNSS, outages=((60.0, 90.0),))
    rows, st, err, gnss = single_run(trajectory, 7, cfg)
    assert np.isnan(gnss[(gnss[:, 0] >= 60.0) & (gnss[:, 0] < 90.0), 1]).all()
    t = rows[:, 0]
    window = (t >= 55.0) & (t <= 100.0)
    assert np.all(np.abs(err[window, 6:9]) <= 3.0 * rows[window, 14:17])
    sig_h = np.hypot(rows[:, 14], rows[:, 15])
    before = sig_h[np.searchsorted(t, 59.9)]
    end = sig_h[np.searchsorted(t, 89.9)]
    after = sig_h[np.searchsorted(t, 100.0)]
    assert end > 3.0 * before and after < 0.5 * end
    fixes = int(np.sum(np.isfinite(gnss[:, 1]) & (gnss[:, 0] <= rows[-1, 0])))
    assert st["counts"]["gnss_pos"] == (fixes, 0)


def test_gate_rejects_an_outlier(trajectory) -> None:
    """A fix 100 m north of the truth is rejected and counted, its velocity with it (a glitch); the run equals
    one without that fix bit for bit (a rejected measurement leaves no trace)."""
    imu, gnss, init, _, _ = simulate_run(trajectory, 11)
    bad = gnss.copy()
    k = 70
    bad[k, 1] += math.degrees(100.0 / 6.37e6)
    rows_bad, st_bad = aided.navigate_aided(imu, init, bad, static=STATIC, spec="consumer", file_units=False)
    none = gnss.copy()
    none[k, 1:7] = np.nan
    rows_none, st_none = aided.navigate_aided(imu, init, none, static=STATIC, spec="consumer", file_units=False)
    fixes = int(np.sum(gnss[:, 0] <= imu[-1, 0]))
    assert st_bad["counts"]["gnss_pos"] == (fixes - 1, 1) and st_bad["counts"]["gnss_vel"] == (fixes - 1, 1)
    assert st_none["counts"]["gnss_pos"] == (fixes - 1, 0)
    np.testing.assert_array_equal(rows_bad, rows_none)
    log = st_bad["nis"]
    rejected = log[(log[:, 1] == aided.K_GNSS_POS) & (log[:, 4] == 0.0)]
    assert rejected.shape[0] == 1 and rejected[0, 0] == gnss[k, 0]
    assert rejected[0, 5] > 1.0  # test ratio: normalised innovation / gate
    assert rejected[0, 2] > 25.0 * 100.0  # NIS ~ (100 m / sigma ~ 1 m)^2


def test_lever_arm(trajectory) -> None:
    """An antenna 1 m ahead, 0.5 m right, 0.8 m above the IMU (one run).

    Modelled: the position NIS stays in its chi2 band (99 %, one run) and the
    IMU's horizontal error after 60 s below 0.5 m RMS. Ignored (filter told
    0), the solution follows the antenna: the IMU's horizontal error is then
    about the 1.1 m horizontal lever arm.
    """
    lever = (1.0, 0.5, -0.8)
    cfg = dataclasses.replace(GNSS, lever_arm=lever)
    rows, st, err, _ = single_run(trajectory, 13, cfg, lever_arm=lever)
    nis = st["nis"]
    pos = nis[nis[:, 1] == aided.K_GNSS_POS, 2]
    lo, hi = band99(3, pos.size)
    assert lo < pos.mean() < hi
    late = rows[:, 0] >= 60.0
    assert math.sqrt(np.mean(np.sum(err[late, 6:8] ** 2, axis=1))) < 0.5
    _, _, err0, _ = single_run(trajectory, 13, cfg)
    assert math.sqrt(np.mean(np.sum(err0[late, 6:8] ** 2, axis=1))) > 0.9 * math.hypot(1.0, 0.5)


def test_baro_offset_is_estimated(trajectory) -> None:
    """GNSS plus a barometer 25 m off: the offset estimate ends within 3 sigma of 25 m, baro NIS in its band (99 %)."""
    imu, gnss, init, _, _ = simulate_run(trajectory, 17)
    baro = aiding.baro(dataclasses.replace(trajectory, seed=17), aiding.BaroConfig(rate=10.0, sigma=0.3, offset=25.0))
    rows, st = aided.navigate_aided(imu, init, gnss, baro, static=STATIC, spec="consumer", file_units=False)
    sigma = math.sqrt(st["P"][em.X_BARO, em.X_BARO])
    assert abs(st["baro_offset"] - 25.0) < 3.0 * sigma
    assert sigma < 1.0
    nis = st["nis"]
    b = nis[nis[:, 1] == aided.K_BARO, 2]
    assert b.size == int(np.sum(baro[:, 0] <= imu[-1, 0]))
    lo, hi = band99(1, b.size)
    assert lo < b.mean() < hi


@pytest.fixture(scope="module")
def static_run():
    sc = load("static")
    return generate(sc, duration=60.0, rate=RATE, seed=0, grade="ideal")


def test_zupt_zaru_and_magnetometer_at_rest(static_run) -> None:
    """At rest for 60 s, no GNSS: ZUPT, a ZARU every 5 s and magnetometer heading.

    Initial errors drawn from 1 m, 0.1 m/s, 0.05 deg level, 10 deg yaw.
    A ZARU over a window T measures the gyro bias with variance ``ARW^2 / T``
    plus the bias's walk within the window; the z gyro bias (unobservable
    otherwise) must end within 3 sigma of the truth, its variance at most
    that of the last ZARU plus the walk since. The magnetometer (0.3 uT on
    a 21.8 uT horizontal field: 0.79 deg per sample, 10 Hz) brings the
    heading within 3 sigma; what it measures, heading plus tan(inclination)
    times the tilt about the magnetic north axis, ends within 3 sigma with
    sigma below three times that of the mean of the 600 samples. Velocity
    stays within 3 sigma throughout.
    """
    ex = static_run.exact
    seed = 23
    t, dth, dv, _ = errors.apply(MODEL, ex.t, ex.dtheta, ex.dv, seed, t_start=ex.t0)
    bg, _ = errors.bias_states(MODEL, ex.t, seed, t_start=ex.t0)
    mag_cfg = aiding.MagConfig(sigma=0.3)
    mag = aiding.magnetometer(dataclasses.replace(static_run, seed=seed), mag_cfg)
    sig_yaw = mag_cfg.sigma / (mag_cfg.strength * math.cos(math.radians(mag_cfg.inclination)))
    mag = np.column_stack([mag, np.full(mag.shape[0], math.degrees(sig_yaw))])
    sigmas = {"sigma_pos": 1.0, "sigma_vel": 0.1, "sigma_level": 0.05, "sigma_yaw": 10.0}
    init = perturbed_init(ex.init(), np.random.default_rng([seed, 1]), sigmas)
    windows = [(5.0 * i + (0.01 if i else 0.0), 5.0 * (i + 1)) for i in range(11)] + [(55.01, 59.9)]
    rows, st = aided.navigate_aided(np.column_stack([t, dth, dv]), init, mag=mag, static=windows, spec="consumer",
                                    declination=mag_cfg.declination, file_units=False)
    assert st["counts"]["zaru"] == (len(windows), 0)
    assert st["counts"]["mag"][1] == 0
    assert st["counts"]["zupt"][1] == 0 and st["counts"]["zupt"][0] >= 0.99 * rows.shape[0]
    idx = 2 * (np.arange(rows.shape[0]) + 1)
    err = nav_errors(rows, ex.truth[idx])
    g = MODEL.gyro
    walk = 2.0 * g.bias_instability_sigma**2 / g.bias_instability_tau + g.rate_random_walk**2
    last = 59.9 - 55.01
    assert rows[-1, 31] ** 2 <= g.random_walk**2 / last + walk * last / 3.0 + walk * (rows[-1, 0] - 59.9)
    assert abs(rows[-1, 25] - bg[idx[-1], 2]) < 3.0 * rows[-1, 31]
    assert abs(err[-1, 2]) < 3.0 * rows[-1, 22]
    m_n = kf.mag_level(st["state"], sd.make_config(), np.zeros(kf.B_SIZE), mag[-1, 1:4], np.zeros(3), 0.0)
    _, H, _ = kf.mag_heading(st["state"], m_n, math.radians(mag_cfg.declination), kf.mag_tan_inclination(m_n),
                             math.hypot(m_n[0], m_n[1]), sig_yaw)
    h = H[0, 0:3]
    assert np.hypot(h[0], h[1]) == pytest.approx(math.tan(math.radians(mag_cfg.inclination)), rel=0.02)
    sig_z = math.sqrt(h @ st["P"][0:3, 0:3] @ h)
    assert sig_z < 3.0 * sig_yaw / math.sqrt(mag.shape[0])
    assert abs(h @ err[-1, 0:3]) < 3.0 * sig_z
    assert np.all(np.abs(err[50:, 3:6]) < 3.0 * rows[50:, 17:20])


def test_magnetometer_data_gives_the_true_heading(static_run) -> None:
    """sim.aiding: tilt-compensated heading of the simulated field = true yaw within 4 sigma of its noise."""
    cfg = aiding.MagConfig(sigma=0.3, declination=3.0, hard_iron=(5.0, -2.0, 1.0))
    mag = aiding.magnetometer(dataclasses.replace(static_run, seed=5), cfg)
    truth = static_run.exact.truth[0]
    m = mag[:, 1:4] - np.array(cfg.hard_iron)
    yaws = np.array([aiding.mag_heading(r, math.radians(truth[7]), math.radians(truth[8]),
                                        math.radians(cfg.declination)) for r in m])
    sig = cfg.sigma / (cfg.strength * math.cos(math.radians(cfg.inclination)))
    dy = wrap_rad(yaws - math.radians(truth[9]))
    assert abs(dy.mean()) < 4.0 * sig / math.sqrt(dy.size)
    assert dy.std() == pytest.approx(sig, rel=4.0 / math.sqrt(2 * dy.size))


def test_gnss_data_statistics(trajectory) -> None:
    """sim.aiding.gnss: antenna = IMU + C l, noise with the configured sigmas, outages are NaN rows."""
    lever = (1.0, -0.5, 0.3)
    cfg = aiding.GnssConfig(rate=5.0, sigma_h=2.0, sigma_v=3.0, sigma_vel=0.2, lever_arm=lever, outages=((30.0, 40.0),))
    run = dataclasses.replace(trajectory, seed=3)
    g = aiding.gnss(run, cfg)
    assert g.shape == (int(DURATION * 5), len(aiding.GNSS_COLUMNS))
    out = (g[:, 0] >= 30.0) & (g[:, 0] < 40.0)
    assert np.isnan(g[out, 1:7]).all() and np.isfinite(g[~out, 1:7]).all()
    ok = ~out
    ex = trajectory.exact
    rows = np.rint((g[ok, 0] - ex.t0) * RATE).astype(int)
    truth = ex.truth[rows]
    lat = np.radians(truth[:, 1])
    r_n, r_e = earth.radii(float(lat.mean()))
    arm = np.array([euler_to_dcm(*np.radians(r[7:10])) @ np.array(lever) for r in truth])
    dn = (np.radians(g[ok, 1]) - lat) * (r_n + truth[:, 3]) - arm[:, 0]
    de = (np.radians(g[ok, 2]) - np.radians(truth[:, 2])) * (r_e + truth[:, 3]) * np.cos(lat) - arm[:, 1]
    dd = -(g[ok, 3] - truth[:, 3]) - arm[:, 2]
    n = int(ok.sum())
    for d, s in ((dn, 2.0), (de, 2.0), (dd, 3.0)):
        assert abs(d.mean()) < 4.0 * s / math.sqrt(n)
        assert d.std() == pytest.approx(s, rel=4.0 / math.sqrt(2 * n))
    np.testing.assert_array_equal(g[:, 7:10], np.tile([2.0, 3.0, 0.2], (g.shape[0], 1)))


def test_run_continues_across_calls(trajectory) -> None:
    """run_aided over two chunks (split at an attitude update, a fix exactly at the split) = one call."""
    imu, gnss, init, _, _ = simulate_run(trajectory, 29)
    g = gnss.copy()
    g[:, 1:3] = np.radians(g[:, 1:3])
    cfg = sd.make_config(samples=2)
    spec = em.make_spec("consumer")
    split = 6000  # IMU rows; the update at row 5999 is the 60th second, where a fix is stamped
    empty = np.empty((0, 4))

    def fresh():
        s = sd.init_state(0.0, math.radians(init["lat"]), math.radians(init["lon"]), init["h"],
                          np.array([init["vn"], init["ve"], init["vd"]]), *np.radians([init["roll"], init["pitch"], init["yaw"]]))
        P = kf.initial_covariance(spec, 3.0, 0.3, math.radians(0.05), math.radians(3.0), 50.0, 0.0)
        return s, P, np.zeros(kf.B_SIZE)

    def call(s, P, bias, rows):
        out = np.empty((rows.stop - rows.start, aided.ROW_SIZE))
        counts = np.zeros((len(aided.KIND_NAMES), 2), dtype=np.int64)
        n, _, _ = aided.run_aided(s, cfg, np.ascontiguousarray(imu[rows, 0]), np.ascontiguousarray(imu[rows, 1:4]),
                               np.ascontiguousarray(imu[rows, 4:7]), g, np.empty((0, 3)), np.empty((0, 5)), empty,
                               spec, np.zeros(3), 0.0, math.nan, math.nan, math.nan, 5.0, 1, P, bias, out, counts, np.empty((0, 6)),
                               np.empty((0, em.NX, em.NX)), 1, *NO_SMOOTHING)
        return out[:n], counts

    s, P, bias = fresh()
    one, c1 = call(s, P, bias, slice(0, imu.shape[0]))
    s, P, bias = fresh()
    first, ca = call(s, P, bias, slice(0, split))
    second, cb = call(s, P, bias, slice(split, imu.shape[0]))
    assert abs(first[-1, 0] - 60.0) < 1e-3 and np.any(g[:, 0] == 60.0)
    np.testing.assert_array_equal(np.vstack([first, second]), one)
    np.testing.assert_array_equal(ca + cb, c1)


def test_bias_states_are_what_apply_adds(trajectory) -> None:
    """sim.errors.bias_states: with only bias errors, apply adds 0.5 (b[i] + b[i+1]) dt per row."""
    m = MODEL
    only = dataclasses.replace(
        m, jitter_sigma=0.0,
        gyro=dataclasses.replace(m.gyro, random_walk=0.0, quantization=0.0, bias=(1e-4, 0.0, -2e-4)),
        accel=dataclasses.replace(m.accel, random_walk=0.0, quantization=0.0),
    )
    ex = trajectory.exact
    t, dth, dv, _ = errors.apply(only, ex.t, ex.dtheta, ex.dv, 5, t_start=ex.t0)
    bg, ba = errors.bias_states(only, ex.t, 5, t_start=ex.t0)
    dt = np.diff(np.concatenate(([ex.t0], ex.t)))[:, None]
    np.testing.assert_allclose(dth - ex.dtheta, 0.5 * (bg[:-1] + bg[1:]) * dt, rtol=0, atol=1e-15)
    np.testing.assert_allclose(dv - ex.dv, 0.5 * (ba[:-1] + ba[1:]) * dt, rtol=0, atol=1e-14)


def test_aiding_files(trajectory, tmp_path) -> None:
    """generate.write with aiding writes gnss.csv and baro.csv beside imu.csv; no fix is a nan position."""
    from sim.generate import write

    run = dataclasses.replace(trajectory, seed=2)
    data = aiding.simulate_aiding(run, dataclasses.replace(GNSS, outages=((10.0, 12.0),)), aiding.BaroConfig())
    paths = write(run, tmp_path, data)
    names = [p.name for p in paths]
    assert names[:4] == ["imu.csv", "imu_rates.csv", "truth.csv", "init.json"]
    assert names[4:] == ["gnss.csv", "baro.csv"]
    lines = (tmp_path / "gnss.csv").read_text().splitlines()
    assert lines[0] == ",".join(aiding.GNSS_COLUMNS)
    back = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    np.testing.assert_array_equal(np.isnan(back), np.isnan(data.gnss))
    np.testing.assert_array_equal(back[np.isfinite(back)], data.gnss[np.isfinite(data.gnss)])
    assert np.isnan(back[(back[:, 0] >= 10.0) & (back[:, 0] < 12.0), 1]).all()
    assert (tmp_path / "baro.csv").read_text().splitlines()[0] == "t,h,sigma"


# --- kernel-level checks ------------------------------------------------------


def test_joseph_update_equals_the_textbook_update() -> None:
    """Against K = P H^T (H P H^T + R)^-1, P+ = (I - K H) P, NIS = nu^T S^-1 nu (numpy); gate by component."""
    rng = np.random.default_rng(4)
    a = rng.standard_normal((em.NX, em.NX))
    P = a @ a.T + np.eye(em.NX)
    H = rng.standard_normal((3, em.NX))
    R = np.diag([0.5, 1.0, 2.0])
    nu = rng.standard_normal(3)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    x = np.zeros(em.NX)
    p = P.copy()
    nis, ratio, ok = kf.update(x, p, H, nu, R, 5.0, kf.ALL)
    assert ok
    np.testing.assert_allclose(x, K @ nu, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(p, (np.eye(em.NX) - K @ H) @ P, rtol=1e-9, atol=1e-9)
    assert nis == pytest.approx(nu @ np.linalg.solve(S, nu), rel=1e-12)
    assert ratio == pytest.approx(np.max(np.abs(nu) / np.sqrt(np.diag(S))) / 5.0, rel=1e-12)
    big = nu.copy()
    big[1] = 5.01 * math.sqrt(S[1, 1])
    x = np.zeros(em.NX)
    p = P.copy()
    nis, ratio, ok = kf.update(x, p, H, big, R, 5.0, kf.ALL)
    assert not ok and ratio > 1.0 and np.all(x == 0.0) and np.array_equal(p, P)
    nis, ratio, ok = kf.update(x, p, H, big, R, 0.0, kf.ALL)  # gate off
    assert ok


def inject(s: np.ndarray, cfg: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """A copy of s carrying the error dx (phi, dv, dp) relative to s (estimate = s + error)."""
    out = s.copy()
    c = rotvec_to_dcm(dx[0:3]) @ s[sd.S.C : sd.S.C + 9].reshape(3, 3)
    out[sd.S.C : sd.S.C + 9] = c.ravel()
    w = math.sqrt(max(1.0 + np.trace(c), 0.0)) / 2.0
    out[sd.S.Q : sd.S.Q + 4] = [w, (c[2, 1] - c[1, 2]) / (4 * w), (c[0, 2] - c[2, 0]) / (4 * w),
                                (c[1, 0] - c[0, 1]) / (4 * w)]
    out[sd.S.V : sd.S.V + 3] += dx[3:6]
    out[sd.S.VP : sd.S.VP + 3] += dx[3:6]
    lat, lon, h = for_frame(sd.position, sd.GEOGRAPHIC)(s, cfg)
    r_n, r_e = earth.radii(lat)
    out[sd.S.CNE : sd.S.CNE + 9] = earth.cne_from_latlon(lat + dx[6] / (r_n + h),
                                                          lon + dx[7] / ((r_e + h) * math.cos(lat))).ravel()
    out[sd.S.H] = h - dx[8]
    for_frame(sd.sync_position, sd.GEOGRAPHIC)(out, cfg)
    return out


CFG = sd.make_config(samples=2)


def moving_state() -> np.ndarray:
    return sd.init_state(0.0, math.radians(47.4), math.radians(8.5), 500.0, np.array([8.0, -3.0, 0.5]),
                         math.radians(15.0), math.radians(-10.0), math.radians(120.0))


def test_feedback_removes_an_injected_error() -> None:
    """feedback(x) of a state carrying the error x returns the reference state (attitude, velocity, position)."""
    ref = moving_state()
    dx = np.zeros(em.NX)
    dx[0:9] = [2e-3, -1e-3, 5e-3, 0.3, -0.2, 0.1, 12.0, -7.0, 3.0]
    dx[em.X_BG : em.X_BG + 3] = [1e-4, 2e-4, -3e-4]
    dx[em.X_BARO] = 1.5
    s = inject(ref, CFG, dx)
    bias = np.zeros(kf.B_SIZE)
    x = dx.copy()
    kf.feedback(s, CFG, bias, x)
    assert np.all(x == 0.0)
    np.testing.assert_allclose(s[sd.S.C : sd.S.C + 9], ref[sd.S.C : sd.S.C + 9], atol=1e-14)
    np.testing.assert_allclose(s[sd.S.V : sd.S.V + 3], ref[sd.S.V : sd.S.V + 3], atol=1e-14)
    np.testing.assert_allclose(s[sd.S.VP : sd.S.VP + 3], ref[sd.S.VP : sd.S.VP + 3], atol=1e-14)
    np.testing.assert_allclose(quat_to_dcm(s[sd.S.Q : sd.S.Q + 4]).ravel(), s[sd.S.C : sd.S.C + 9], atol=1e-15)
    assert abs(np.linalg.norm(s[sd.S.Q : sd.S.Q + 4]) - 1.0) < 1e-15
    lat, lon, h = for_frame(sd.position, sd.GEOGRAPHIC)(s, CFG)
    lr, lo, hr = for_frame(sd.position, sd.GEOGRAPHIC)(ref, CFG)
    # the transport-rotation step and the lat/lon offsets differ at second order: dp^2 tan L / R ~ 3e-5 m
    assert abs(lat - lr) * 6.4e6 < 1e-4 and abs(lon - lo) * 4.3e6 < 1e-4 and abs(h - hr) < 1e-12
    np.testing.assert_allclose(bias[0:3], -dx[em.X_BG : em.X_BG + 3], rtol=1e-15)
    assert bias[kf.B_BARO] == -1.5


def measurement_jacobian_check(measure, dx: np.ndarray, tol: float) -> None:
    """nu(state with error dx) - nu(reference) = H dx to first order (second-order residual below tol)."""
    ref = moving_state()
    nu0, H, _ = measure(ref)
    nu1, _, _ = measure(inject(ref, CFG, dx))
    d = wrap_rad(nu1 - nu0) if nu0.size == 1 else nu1 - nu0
    np.testing.assert_allclose(d, H[:, :9] @ dx[:9], atol=tol)


@pytest.mark.parametrize("which", ["pos", "vel", "baro", "yaw", "mag", "zupt", "nhc", "wheel", "body"])
def test_measurement_models_linearise_the_measurement(which: str) -> None:
    """Each measurement's H against the change of its innovation under an injected error (phi 1 mrad, dv, dp).

    Second-order residuals: lever arm |phi|^2 |l| ~ 1e-6 m, heading |phi|^2 ~ 1e-6 rad.
    """
    dx = np.zeros(em.NX)
    dx[0:9] = [1e-3, -2e-3, 1.5e-3, 0.2, -0.1, 0.05, 3.0, -2.0, 1.0]
    lever = np.array([1.0, 0.5, -0.8])
    w = np.array([0.1, -0.2, 0.3])
    lat0, lon0 = math.radians(47.4), math.radians(8.5)
    if which == "pos":
        def measure(s):
            return kf.gnss_position(s, CFG, lat0, lon0, 480.0, lever, 0.0, 1.0, 1.0)
        tol = 1e-5
    elif which == "vel":
        def measure(s, w=w):
            return kf.gnss_velocity(s, np.array([8.0, -3.0, 0.5]), w, lever, 0.0, 0.02, 0.1)
        tol = 1e-5  # |phi|^2 |w x l| ~ 1e-5 m/s
        # a gyro bias error db (estimate - truth) lowers the compensated rate by db
        db = np.array([1e-3, -2e-3, 3e-3])
        ref = moving_state()
        nu0, H, _ = measure(ref)
        nu1, _, _ = measure(ref, w - db)
        np.testing.assert_allclose(nu1 - nu0, H[:, em.X_BG : em.X_BG + 3] @ db, atol=1e-15)
        np.testing.assert_array_equal(H[:, em.X_BG : em.X_BG + 3], H[:, em.X_GG : em.X_GG + 3])
    elif which == "baro":
        def measure(s):
            return kf.baro_height(s, np.zeros(kf.B_SIZE), 470.0, 0.0, 0.5)
        tol = 1e-9
    elif which == "yaw":
        def measure(s):
            return kf.heading(s, 2.0, 0.01)
        tol = 1e-5
    elif which == "mag":
        m_n = 48.0 * np.array([math.cos(1.1) * math.cos(0.05), math.cos(1.1) * math.sin(0.05), math.sin(1.1)])
        c_true = moving_state()[sd.S.C : sd.S.C + 9].reshape(3, 3)
        m_b = c_true.T @ m_n

        def measure(s):
            return kf.mag_heading(s, kf.mag_level(s, CFG, np.zeros(kf.B_SIZE), m_b, np.zeros(3), 0.0), 0.05,
                                  math.tan(1.1), 48.0 * math.cos(1.1), 0.01)
        tol = 2e-5
    elif which == "nhc":
        def measure(s):
            return kf.nhc(s, 0.1)
        tol = 7e-4  # second order: |phi| |dv| = 2.7e-3 x 0.23 m/s and |phi|^2 |v| / 2 = 3e-5 m/s
    elif which == "body":
        v_b = np.array([5.0, -1.0, 0.3])

        def measure(s):
            return kf.body_velocity(s, v_b, np.array([0.1, 0.2, 0.3]))
        tol = 7e-4  # as nhc's
        ref = moving_state()
        nu0, H, R = measure(ref)
        c = ref[sd.S.C:sd.S.C + 9].reshape(3, 3)
        np.testing.assert_allclose(nu0, c.T @ ref[sd.S.V:sd.S.V + 3] - v_b, rtol=0, atol=1e-14)
        np.testing.assert_allclose(np.diag(R), [0.01, 0.04, 0.09], rtol=1e-15)
        np.testing.assert_array_equal(H[1:3], kf.nhc(ref, 0.1)[1])  # the constraint's rows are its y and z
    elif which == "wheel":
        bias = np.zeros(kf.B_SIZE)
        bias[kf.B_WS] = 0.02

        def measure(s, w=w, bias=bias):
            return kf.wheel_speed(s, bias, 8.3, w, lever, 0.0, 0.02, 0.05)
        tol = 7e-4  # as nhc's: the same body velocity, row x, times 1.02
        # a gyro bias error db (estimate - truth) lowers the compensated rate by db; a scale-factor error dk
        # (estimate - truth) scales the prediction by 1 + dk: both exactly linear
        ref = moving_state()
        nu0, H, _ = measure(ref)
        db = np.array([1e-3, -2e-3, 3e-3])
        np.testing.assert_allclose(measure(ref, w - db)[0] - nu0, H[:, em.X_BG:em.X_BG + 3] @ db, atol=1e-15)
        np.testing.assert_array_equal(H[:, em.X_BG:em.X_BG + 3], H[:, em.X_GG:em.X_GG + 3])
        b2 = bias.copy()
        b2[kf.B_WS] += 0.01
        np.testing.assert_allclose(measure(ref, w, b2)[0] - nu0, H[:, em.X_WS] * 0.01, rtol=1e-12)
        # the speed at the axle centre: C^T v along x plus (w x l)_x, times 1 + k, less the measured one
        v_b = ref[sd.S.C:sd.S.C + 9].reshape(3, 3).T @ ref[sd.S.V:sd.S.V + 3]
        assert nu0[0] == pytest.approx(1.02 * (v_b[0] + np.cross(w, lever)[0]) - 8.3, rel=1e-14)
    else:
        def measure(s):
            return kf.zupt(s, 0.01)
        tol = 1e-12
    measurement_jacobian_check(measure, dx, tol)


def test_batch_filter_carries_a_late_magnetometer_sample(trajectory) -> None:
    """aided.run_aided carries a sample to the update after it (kalman.mag_heading with that update's mean rate).

    Ideal IMU from the true start, navigation-grade model and a 0.01 deg
    heading sigma, so that the innovation's variance stays about R; one
    noise-free sample half an attitude interval (0.01 s) before the update at
    72.02 s, in the steady first turn. Carried
    with the interval's mean rate w_m, the innovation is at most
    ``(|w dt|^2 / 2 + |w_last - w_m| dt) / cos(I)`` (second-order term and the
    rate's change over the interval, from the exact increments): its NIS at
    most that squared over R. Uncarried it is the turn over 0.01 s, 3.5 mrad.
    """
    ex = trajectory.exact
    t_m = 72.01
    i = int(round(t_m / 0.01))  # truth row at t_m; the update at 72.02 ends with increment i
    assert ex.truth[i, 0] == pytest.approx(t_m, abs=1e-9) and ex.t[i] == pytest.approx(72.02, abs=1e-9)
    m_n = MAG.field_n()
    m_b = quat_to_dcm(ex.truth[i, 10:14]).T @ m_n
    sigma = 0.1  # deg
    mag = np.array([[t_m, *m_b, sigma]])
    init = dict(ex.init(), **dict(INIT_SIGMA, sigma_yaw=0.01))
    _, st = aided.navigate_aided(np.column_stack([ex.t, ex.dtheta, ex.dv]), init, mag=mag,
                                 declination=MAG.declination, spec="navigation", file_units=False)
    dt = 0.01
    w_last = ex.dtheta[i] / dt
    w_mean = (ex.dtheta[i - 1] + ex.dtheta[i]) / (2 * dt)
    cos_i = math.cos(math.radians(MAG.inclination))
    bound = (0.5 * (np.linalg.norm(w_last) * dt) ** 2 + np.linalg.norm(w_last - w_mean) * dt) / cos_i
    turned = np.linalg.norm(w_last) * dt
    assert turned > 100 * bound
    log = st["nis"][st["nis"][:, 1] == aided.K_MAG]
    assert log.shape[0] == 1 and log[0, 0] == t_m and log[0, 4] == 1.0
    r = math.radians(sigma) ** 2
    assert log[0, 2] < bound**2 / r


def test_late_fix_moves_the_solution_back_along_the_velocity() -> None:
    """A fix dt seconds old is compared with p - v dt: the same innovation as a current fix of p_m + v dt."""
    s = moving_state()
    lever = np.zeros(3)
    lat, lon, h = for_frame(sd.position, sd.GEOGRAPHIC)(s, CFG)
    nu_late, H, _ = kf.gnss_position(s, CFG, lat, lon, h, lever, 0.01, 1.0, 1.0)
    np.testing.assert_allclose(nu_late, -0.01 * s[sd.S.V : sd.S.V + 3], atol=1e-9)
    np.testing.assert_allclose(H[:, em.X_DV : em.X_DV + 3], -0.01 * np.eye(3))


def test_file_units() -> None:
    """to_file_units: degrees for lat, lon, Euler angles and sigma_att; deg/h for the gyro bias and its sigma."""
    rows = np.arange(aided.OUT_SIZE, dtype=float)[None, :] * 1e-3
    out = aided.to_file_units(rows)
    deg_h = math.degrees(1.0) * 3600.0
    for j in range(aided.OUT_SIZE):
        name = aided.OUT_COLUMNS[j]
        if name in ("lat", "lon", "roll", "pitch", "yaw") or name.startswith("sigma_att"):
            assert out[0, j] == pytest.approx(math.degrees(rows[0, j]))
        elif name.startswith("bg_") or name.startswith("sigma_bg"):
            assert out[0, j] == pytest.approx(rows[0, j] * deg_h)
        else:
            assert out[0, j] == rows[0, j]
    assert aided.OUT_COLUMNS[14:] == ("sigma_n", "sigma_e", "sigma_d", "sigma_vn", "sigma_ve", "sigma_vd",
                                      "sigma_att_n", "sigma_att_e", "sigma_att_d", "bg_x", "bg_y", "bg_z",
                                      "ba_x", "ba_y", "ba_z", "sigma_bg_x", "sigma_bg_y", "sigma_bg_z",
                                      "sigma_ba_x", "sigma_ba_y", "sigma_ba_z")


# --- the sensor-error states: the magnetometer's hard iron and the IMU's scale factors -------------------

N_SENSOR = 20  # runs of each Monte Carlo below (the bands are for N_SENSOR)
HARD_IRON = 10.0  # uT: 0.1 gauss of hard iron
HARD_IRON_SIGMA = HARD_IRON / math.sqrt(3.0)  # uT per axis: the filter's prior, 0.1 gauss RMS


def misalignment_matrix(m6: np.ndarray) -> tuple[tuple[float, float, float], ...]:
    """The simulator's 3 x 3 misalignment (zero diagonal) of the six off-diagonal elements m_xy m_xz m_yx m_yz
    m_zx m_zy (row i, column j: the true j-th component sensed on axis i; errmodel.OFF_DIAGONAL)."""
    m = np.zeros((3, 3))
    m[[0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1]] = m6
    return tuple(tuple(float(x) for x in row) for row in m)


def run_sensor_monte_carlo(trajectory, *, hard_iron: bool, scale: bool, estimate: bool,
                           misalign: bool = False) -> dict:
    """N_SENSOR runs of the quiet flight with the consumer grade's stochastic errors and, drawn per run from the
    filter's prior, a hard iron on the 50 Hz magnetometer (``hard_iron``; 10 uT in a random direction) or gyro
    and accelerometer
    scale factors (``scale``; the grade's 3333 and 10000 ppm as 1-sigma). ``estimate``: the filter models them
    (``mag_bias``, the spec's scale sigmas), else not; or gyro and accelerometer misalignments (``misalign``; the
    grade's 6.7e-3 rad, 0.38 deg, as 1-sigma of each of the 12 elements). Returns the attitude/velocity/position NEES per 1 Hz
    epoch, the heading's normalised errors after 60 s, and the final NEES and z of the sensor-error states."""
    truth_all = trajectory.exact.truth
    spec_true = em.spec_from_grade("consumer", scale_factors=True, misalignment=True)
    out = {"nees": {k: [] for k in ("att", "vel", "pos")}, "yaw_z": [], "state_nees": [], "state_z": [],
           "state_sigma": [], "yaw_err": []}
    for r in range(N_SENSOR):
        seed = 3000 + r
        rng = np.random.default_rng([seed, 2])
        model, spec, kw = MODEL, spec_true, {}
        if scale:
            sg = rng.standard_normal(3) * spec_true.gyro_scale
            sa = rng.standard_normal(3) * spec_true.accel_scale
            model = dataclasses.replace(MODEL, gyro=dataclasses.replace(MODEL.gyro, scale_factor_ppm=tuple(sg * 1e6)),
                                        accel=dataclasses.replace(MODEL.accel, scale_factor_ppm=tuple(sa * 1e6)))
            truth_state, block = np.concatenate([sg, sa]), slice(em.X_SG, em.X_SA + 3)
        if misalign:
            mg = rng.standard_normal(6) * spec_true.gyro_misalignment
            ma = rng.standard_normal(6) * spec_true.accel_misalignment
            model = dataclasses.replace(
                MODEL, gyro=dataclasses.replace(MODEL.gyro, misalignment=misalignment_matrix(mg)),
                accel=dataclasses.replace(MODEL.accel, misalignment=misalignment_matrix(ma)))
            truth_state, block = np.concatenate([mg, ma]), slice(em.X_MG, em.X_MA + 6)
        if not (scale and estimate):
            spec = dataclasses.replace(spec, gyro_scale=0.0, accel_scale=0.0)
        if not (misalign and estimate):
            spec = dataclasses.replace(spec, gyro_misalignment=0.0, accel_misalignment=0.0)
        ex = trajectory.exact
        t, dth, dv, _ = errors.apply(model, ex.t, ex.dtheta, ex.dv, seed, t_start=ex.t0)
        run = dataclasses.replace(trajectory, seed=seed)
        gnss = aiding.gnss(run, GNSS)
        init = perturbed_init(ex.init(), np.random.default_rng([seed, 1]))
        if hard_iron:
            u = rng.standard_normal(3)
            hi = u / np.linalg.norm(u) * HARD_IRON  # 0.1 gauss in a random direction: E|hi|^2 = 3 sigma^2
            mag = aiding.magnetometer(run, dataclasses.replace(MAG, hard_iron=tuple(hi)))
            kw = {"mag": np.column_stack([mag, np.full(mag.shape[0], math.degrees(MAG_SIGMA_YAW))]),
                  "declination": MAG.declination, "mag_bias": HARD_IRON_SIGMA if estimate else 0.0,
                  "mag_inclination": MAG.inclination, "mag_strength": MAG.strength, "mag_strength_gate": 20.0}
            truth_state, block = hi, slice(em.X_MB, em.X_MB + 3)
        rows, st = aided.navigate_aided(np.column_stack([t, dth, dv]), init, gnss, static=STATIC, spec=spec,
                                        file_units=False, covariance_every=EVERY, **kw)
        err, _, sel = epoch_nees(out["nees"], rows, st["P_history"], truth_all)
        late = rows[sel, 0] >= 60.0
        out["yaw_z"].append(err[sel, 2][late] / np.sqrt(st["P_history"][late, 2, 2]))
        out["yaw_err"].append(err[sel, 2][late])
        if estimate:
            e = st["bias"][block.start - em.X_SENSORS : block.stop - em.X_SENSORS] - truth_state
            pb = st["P"][block, block]
            out["state_nees"].append(float(e @ np.linalg.solve(pb, e)))
            out["state_z"].append(e / np.sqrt(np.diag(pb)))
            out["state_sigma"].append(np.sqrt(np.diag(pb)))
    return out


@pytest.fixture(scope="module")
def hard_iron_mc(trajectory):
    return run_sensor_monte_carlo(trajectory, hard_iron=True, scale=False, estimate=True)


@pytest.fixture(scope="module")
def scale_mc(trajectory):
    return run_sensor_monte_carlo(trajectory, hard_iron=False, scale=True, estimate=True)


@pytest.fixture(scope="module")
def misalignment_mc(trajectory):
    return run_sensor_monte_carlo(trajectory, hard_iron=False, scale=False, estimate=True, misalign=True)


@pytest.fixture(params=["hard_iron_mc", "scale_mc", "misalignment_mc"])
def sensor_mc(request):
    return request.getfixturevalue(request.param)


@pytest.mark.parametrize("block", ["pos", "vel", "att"])
def test_sensor_error_monte_carlo_nees(sensor_mc, block: str) -> None:
    """With 0.1 gauss of hard iron, or with the consumer grade's scale factors or misalignments, estimated: the
    ANEES of each
    navigation block, averaged over the 1 Hz epochs, in the chi2(3N)/N band (N = 20: 2.0 .. 4.1)."""
    anees = np.mean(np.array(sensor_mc["nees"][block]), axis=0)
    lo, hi = band(3, N_SENSOR)
    assert lo < anees.mean() < hi, (block, anees.mean(), lo, hi)


def test_scale_factors_end_inside_their_sigma(scale_mc) -> None:
    """The six scale factors at the end against the simulator's: each component's normalised error RMS over
    the runs within 1 / 1.5 .. 1.5 (the bound of test_monte_carlo_normalised_errors)."""
    rms = np.sqrt(np.mean(np.array(scale_mc["state_z"]) ** 2, axis=0))
    assert np.all(rms < 1.5) and np.all(rms > 1.0 / 1.5), rms
    # jointly (6 dof) measured 8.2 against 6: the correlations of the barely observable accelerometer scale
    # factors with the biases are somewhat over-confident (docs/filter.md); held below 1.5^2 times 6
    assert np.mean(scale_mc["state_nees"]) < 1.5 ** 2 * 6, np.mean(scale_mc["state_nees"])


def test_misalignments_end_inside_their_sigma(misalignment_mc) -> None:
    """The twelve misalignment elements at the end against the simulator's: each one's normalised error RMS over
    the runs within 1 / 1.5 .. 1.5, and jointly (12 dof) the mean NEES below 1.5^2 times 12; the elements the
    flight excites are learnt (final sigma below 0.9 of the prior for at least two of them in every run)."""
    z = np.array(misalignment_mc["state_z"])
    rms = np.sqrt(np.mean(z ** 2, axis=0))
    assert np.all(rms < 1.5) and np.all(rms > 1.0 / 1.5), rms
    assert np.mean(misalignment_mc["state_nees"]) < 1.5 ** 2 * 12, np.mean(misalignment_mc["state_nees"])
    prior = em.spec_from_grade("consumer", misalignment=True).gyro_misalignment
    learnt = (np.array(misalignment_mc["state_sigma"]) < 0.9 * prior).sum(axis=1)
    assert np.all(learnt >= 2), learnt


def test_hard_iron_is_learnt_nearly_inside_its_sigma(hard_iron_mc) -> None:
    """The hard iron at the end against the simulator's. A hard iron of 0.1 gauss is 46 % of this horizontal
    field, where the heading is far from linear in it, and the first-order filter is not quite consistent
    (docs/filter.md "Magnetometer", measured: 19 of 20 runs below the chi2(3) 99.9 % point, normalised-error
    RMS 1.5, 1.4, 0.8 by axis). Held to: at least 18 of 20 runs below 16.27, and each axis's RMS below 2 (a
    filter with the hard iron's column wrong by its sign or size, or none, fails both by far)."""
    assert sum(n < 16.27 for n in hard_iron_mc["state_nees"]) >= N_SENSOR - 2, hard_iron_mc["state_nees"]
    rms = np.sqrt(np.mean(np.array(hard_iron_mc["state_z"]) ** 2, axis=0))
    assert np.all(rms < 2.0), rms


def test_heading_within_its_sigma_with_hard_iron(hard_iron_mc) -> None:
    """0.1 gauss of hard iron (about 15 deg of heading on this 22 uT horizontal field, the issue's figure):
    after 60 s the heading's normalised error RMS over runs and 1 Hz epochs lies within 1 / 1.5 .. 1.5, and the
    horizontal hard iron is learnt in at least 18 of 20 runs (its final sigma below half the prior's 5.8 uT)."""
    z = np.concatenate(hard_iron_mc["yaw_z"])
    assert 1.0 / 1.5 < math.sqrt(np.mean(z ** 2)) < 1.5, math.sqrt(np.mean(z ** 2))
    learnt = np.all(np.array(hard_iron_mc["state_sigma"])[:, :2] < 0.5 * HARD_IRON_SIGMA, axis=1)
    assert learnt.sum() >= N_SENSOR - 2, learnt  # a run may end just after a reset (aided.apply_mag)


@pytest.mark.parametrize("which", ["hard_iron", "scale", "misalign"])
def test_without_the_states_the_filter_is_overconfident(trajectory, which: str) -> None:
    """The same data with the states left out of the filter: the heading (hard iron) or the attitude (scale
    factors, misalignments) is off by several of its sigmas, so the tests above can fail."""
    mc = run_sensor_monte_carlo(trajectory, hard_iron=which == "hard_iron", scale=which == "scale", estimate=False,
                                misalign=which == "misalign")
    if which == "hard_iron":
        z = np.concatenate(mc["yaw_z"])
        assert math.sqrt(np.mean(z ** 2)) > 3.0
    else:
        anees = np.mean(np.array(mc["nees"]["att"]), axis=0).mean()
        assert anees > band(3, N_SENSOR)[1], anees


SMOOTH_RUNS = 40
OUTAGE = (40.0, 100.0)  # s: 60 s without GNSS through the flight's turns, 20 s of fixes after it


@pytest.fixture(scope="module")
def smoothed_outage(trajectory):
    """SMOOTH_RUNS runs with a 60 s outage, each navigated forward and smoothed (navigate_aided smooth=True):
    their errors and 1-sigma columns every EVERY rows (1 Hz), and the rows' times."""
    cfg = dataclasses.replace(GNSS, outages=(OUTAGE,))
    out = {"fwd": [], "smo": [], "sig": [], "epochs": [], "singular": []}
    for r in range(SMOOTH_RUNS):
        imu, gnss, init, bg, ba = simulate_run(trajectory, 2000 + r, cfg)
        idx = None
        for key, smooth in (("fwd", False), ("smo", True)):
            rows, st = aided.navigate_aided(imu, init, gnss, static=STATIC, spec="consumer", file_units=False,
                                            smooth=smooth)
            idx = 2 * (np.arange(rows.shape[0]) + 1)
            sel = np.arange(EVERY - 1, rows.shape[0], EVERY)
            out[key].append(nav_errors(rows, trajectory.exact.truth[idx])[sel])
            if smooth:
                out["sig"].append(np.column_stack([rows[sel, 20:23], rows[sel, 17:20], rows[sel, 14:17]]))
                out["epochs"].append(st["epochs"])
                out["singular"].append(st["singular"])
                out["t"] = rows[sel, 0]
    return {k: np.array(v) if k != "t" else v for k, v in out.items()}


def test_smoother_cuts_the_outage_error_at_least_fivefold(smoothed_outage) -> None:
    """Issue 34's bound: inside the 60 s outage the smoothed horizontal position RMS (over runs and 1 Hz
    epochs) is at most a fifth of the forward filter's (the fix after the gap constrains the path in it)."""
    t = smoothed_outage["t"]
    w = (t > OUTAGE[0]) & (t < OUTAGE[1])

    def rms(e: np.ndarray) -> float:
        return math.sqrt(np.mean(np.sum(e[:, w, 6:8] ** 2, axis=2)))

    assert rms(smoothed_outage["smo"]) <= rms(smoothed_outage["fwd"]) / 5.0, (rms(smoothed_outage["smo"]),
                                                                              rms(smoothed_outage["fwd"]))
    assert not smoothed_outage["singular"].any()


@pytest.mark.parametrize("window", ["run", "outage"])
@pytest.mark.parametrize("block, o", [("att", 0), ("vel", 3), ("pos", 6)])
def test_smoothed_errors_are_inside_their_sigma(smoothed_outage, window: str, block: str, o: int) -> None:
    """The smoothed errors against the smoothed 1-sigma columns: per block the sum of the three squared
    normalised errors has mean 3 whatever their correlation; its mean over the runs lies in the band of
    3 chi2(N)/N (the fully correlated case, the widest; 99 %), and its time average (1 Hz, over the
    whole run or the outage) at most as widely, as in test_monte_carlo_nees."""
    t = smoothed_outage["t"]
    w = np.ones(t.shape, bool) if window == "run" else (t > OUTAGE[0]) & (t < OUTAGE[1])
    z2 = np.sum((smoothed_outage["smo"][:, w, o:o + 3] / smoothed_outage["sig"][:, w, o:o + 3]) ** 2, axis=2)
    lo, hi = band99(1, SMOOTH_RUNS)
    assert 3.0 * lo < z2.mean() < 3.0 * hi, (block, window, z2.mean(), 3.0 * lo, 3.0 * hi)
