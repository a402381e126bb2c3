"""Redundant sensors (core/redundancy.py, core/fdi.py): every expected value comes from theory or a
published table, never from the code under test.

Also the rest of mavins/core/redundancy.py and mavins/core/fdi.py (docs/testing.md).

Expected values are closed forms, never the code under test:

* the normal and chi-square tails of Abramowitz & Stegun (A&S): Q(x) = erfc(x/sqrt 2)/2 (26.2.29),
  Q(chi^2 | nu) for odd nu (26.4.4) and even nu (26.4.5), and the non-central chi-square of three
  degrees of freedom, the law of |z + mu|^2 for z ~ N(0, I_3), integrated by hand below;
* the least-squares projection of the parity space, V^T V = P = I - W H (H^T W^2 H)^-1 H^T W
  (Sturza 1988; Potter & Suman 1977), which for the sets used here (H^T H = 2 I, or triads in one
  frame) is a matrix of halves and thirds;
* the monitor's rules as docs/redundancy.md "The monitor" states them: window means of the rates,
  a bias tracker that takes the mean of the calibration windows (weight 1/k, its variance 1/k in
  sensor-noise units) and then an exponential average of weight alpha = T / tau_b, with variance
  v_k = (1 - a)^2 v_(k-1) + a^2, frozen while a test fails; the statistic p^T p / (1 + v); the 1-dof
  check of a dropped sensor against sigma^2 + h^T C h; hold-offs counted in windows.

The monitors see noise-free data, so each statistic is exactly its non-centrality,
f^2 P_jj / sigma^2 / (1 + v) for a fault f on sensor j, and every event time is a window's end.
"""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest

from mavins.core import redundancy as rd
from mavins.core.errmodel import ImuSpec
from mavins.core.fdi import ImuSetMonitor, ParityMonitor
import chi2_closed as cc


def _random_h(rng: np.random.Generator, n: int) -> np.ndarray:
    h = rng.standard_normal((n, 3))
    return h / np.linalg.norm(h, axis=1, keepdims=True)


@pytest.mark.parametrize("n", [4, 5, 6, 9, 12])
def test_parity_matrix_annihilates_h_and_has_orthonormal_rows(n: int) -> None:
    rng = np.random.default_rng(n)
    H = _random_h(rng, n)
    sigma = rng.uniform(0.5, 2.0, n)
    for s in (None, sigma):
        V = rd.parity_matrix(H, s)
        W = np.eye(n) if s is None else np.diag(1.0 / s)
        assert V.shape == (n - 3, n)
        # V W H = 0 and V V^T = I to rounding: entries of order 1, so a few ulp times n
        np.testing.assert_allclose(V @ W @ H, 0.0, atol=1e-13)
        np.testing.assert_allclose(V @ V.T, np.eye(n - 3), atol=1e-13)


def test_parity_matrix_refuses_axes_that_do_not_span_3d() -> None:
    H = np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 1.0, 0], [1.0, -1.0, 0]]) / np.array([[1], [1], [2**0.5], [2**0.5]])
    with pytest.raises(ValueError, match="span"):
        rd.parity_matrix(H)


def test_fused_estimate_equals_hand_solution() -> None:
    # x, y, z and (1,1,1)/sqrt 3: H^T H = I + 1 1^T / 3, inverse by Sherman-Morrison I - 1 1^T / 6,
    # so x = (I - 1 1^T/6) (m_xyz + m_4 (1,1,1)/sqrt 3)
    H = np.vstack([np.eye(3), np.ones(3) / math.sqrt(3.0)])
    m = np.array([0.3, -1.2, 2.0, 0.7])
    expect = (np.eye(3) - np.ones((3, 3)) / 6.0) @ (m[:3] + m[3] * np.ones(3) / math.sqrt(3.0))
    np.testing.assert_allclose(rd.fuse(H, m), expect, rtol=1e-14, atol=1e-15)
    # two triads in one frame with sigmas s1, s2: the inverse-variance weighted mean of each axis
    H2 = rd.triad_rows([np.eye(3), np.eye(3)])
    m2 = np.array([1.0, 2.0, 3.0, 1.5, 1.0, 2.0])
    s = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
    expect2 = (m2[:3] / 1.0 + m2[3:] / 4.0) / (1.0 + 0.25)
    np.testing.assert_allclose(rd.fuse(H2, m2, s), expect2, rtol=1e-14)


# Upper critical values chi^2_{1-a}(nu), P(X > x) = a, as printed (3 decimals) in the NIST/SEMATECH
# e-Handbook of Statistical Methods, table 1.3.6.7.4 "Critical values of the chi-square distribution".
UPPER = {
    1: {0.10: 2.706, 0.05: 3.841, 0.025: 5.024, 0.01: 6.635, 0.001: 10.828},
    2: {0.10: 4.605, 0.05: 5.991, 0.025: 7.378, 0.01: 9.210, 0.001: 13.816},
    3: {0.10: 6.251, 0.05: 7.815, 0.025: 9.348, 0.01: 11.345, 0.001: 16.266},
    6: {0.10: 10.645, 0.05: 12.592, 0.025: 14.449, 0.01: 16.812, 0.001: 22.458},
    10: {0.10: 15.987, 0.05: 18.307, 0.025: 20.483, 0.01: 23.209, 0.001: 29.588},
}
# Lower critical values, P(X < x) = a, same table.
LOWER = {
    6: {0.10: 2.204, 0.05: 1.635, 0.025: 1.237, 0.01: 0.872, 0.001: 0.381},
    10: {0.10: 4.865, 0.05: 3.940, 0.025: 3.247, 0.01: 2.558, 0.001: 1.479},
}


@pytest.mark.parametrize("dof", sorted(UPPER))
def test_chi2_quantiles_match_published_table(dof: int) -> None:
    for a, x in UPPER[dof].items():
        # the table rounds to 3 decimals: half a unit of the last place
        assert rd.chi2_quantile(a, dof, upper=True) == pytest.approx(x, abs=5e-4)
        assert rd.chi2_sf(x, dof) == pytest.approx(a, rel=2e-3)
    for a, x in LOWER.get(dof, {}).items():
        assert rd.chi2_quantile(a, dof) == pytest.approx(x, abs=5e-4)


@pytest.mark.parametrize("p", [1e-3, 1e-6, 1e-9, 1e-12])
def test_chi2_far_tail_against_closed_forms(p: float) -> None:
    # nu = 2: Q = exp(-x/2), so x = -2 ln p; nu = 4: Q = exp(-x/2) (1 + x/2) (A&S 26.4.21)
    assert rd.chi2_quantile(p, 2, upper=True) == pytest.approx(-2.0 * math.log(p), rel=1e-12)
    x4 = rd.chi2_quantile(p, 4, upper=True)
    assert math.exp(-x4 / 2.0) * (1.0 + x4 / 2.0) == pytest.approx(p, rel=1e-10)
    # nu = 1: X = Z^2, P(X > x) = erfc(sqrt(x/2))
    x1 = rd.chi2_quantile(p, 1, upper=True)
    assert math.erfc(math.sqrt(x1 / 2.0)) == pytest.approx(p, rel=1e-10)


def test_noncentral_chi2_against_closed_form_for_one_dof() -> None:
    # nu = 1: X = (Z + sqrt(lam))^2, P(X <= x) = Phi(sqrt x - sqrt lam) - Phi(-sqrt x - sqrt lam)
    def phi(z: float) -> float:
        return 0.5 * math.erfc(-z / math.sqrt(2.0))

    for lam in (0.5, 4.0, 30.0, 400.0):
        for x in (0.3, 3.0, 25.0, 500.0):
            expect = phi(math.sqrt(x) - math.sqrt(lam)) - phi(-math.sqrt(x) - math.sqrt(lam))
            assert rd.ncx2_cdf(x, 1, lam) == pytest.approx(expect, abs=1e-12)


def test_dodecahedron_and_cone_are_optimal() -> None:
    for H in (rd.dodecahedron_axes(), rd.cone_axes(6)):
        np.testing.assert_allclose(np.linalg.norm(H, axis=1), 1.0, rtol=1e-15)
        np.testing.assert_allclose(H.T @ H, 2.0 * np.eye(3), atol=1e-14)  # N/3 I, N = 6
        assert rd.gdop(H) == pytest.approx(3.0 / math.sqrt(6.0), rel=1e-14)  # sqrt(trace(I/2)) = sqrt(3/2)
    # dodecahedron: every pair of axes at arccos(1/sqrt 5) = 63.4349 deg
    D = rd.dodecahedron_axes()
    cos = np.abs(D @ D.T)[~np.eye(6, dtype=bool)]
    np.testing.assert_allclose(cos, 1.0 / math.sqrt(5.0), rtol=1e-14)
    # cone of half-angle a: H^T H = diag(N/2 sin^2 a, N/2 sin^2 a, N cos^2 a), so
    # GDOP^2 = 4 / (N sin^2 a) + 1 / (N cos^2 a), least at tan^2 a = 2
    for a_deg in (30.0, 45.0, 54.7356103172, 70.0):
        a = math.radians(a_deg)
        expect = math.sqrt(4.0 / (6 * math.sin(a) ** 2) + 1.0 / (6 * math.cos(a) ** 2))
        assert rd.gdop(rd.cone_axes(6, a)) == pytest.approx(expect, rel=1e-13)
    assert math.degrees(rd.OPTIMAL_CONE_HALF_ANGLE) == pytest.approx(54.7356103172, abs=1e-9)
    # three orthogonal axes: sqrt 3
    assert rd.gdop(np.eye(3)) == pytest.approx(math.sqrt(3.0), rel=1e-15)


@pytest.mark.parametrize("H", [rd.dodecahedron_axes(), rd.cone_axes(6)], ids=["dodecahedron", "cone"])
def test_six_sensor_sets_isolate_any_single_failure_and_detect_any_two(H: np.ndarray) -> None:
    rng = np.random.default_rng(6)
    V = rd.parity_matrix(H)
    assert rd.isolable(V).all()
    thr = rd.chi2_quantile(1e-6, 3, upper=True)
    x = np.array([0.3, -0.2, 0.5])
    for j in range(6):
        # a fault of f sigma on sensor j moves p by f v_j; |v_j|^2 = 1 - h_j^T (H^T H)^-1 h_j = 1/2, so
        # f = 20 gives a non-centrality of 200, far over the threshold (31.0), and the test statistic of
        # sensor j exceeds every other one's by (f |v_j|)^2 (1 - cos^2) >> noise
        for trial in range(20):
            m = H @ x + rng.standard_normal(6)
            m[j] += 20.0
            p = rd.parity_vector(V, m)
            assert rd.test_statistic(p) > thr
            assert rd.isolate(V, p) == j
    for j, k in itertools.combinations(range(6), 2):
        for sj, sk in ((1, 1), (1, -1)):
            m = H @ x
            m[j] += 20.0 * sj
            m[k] += 20.0 * sk
            # V^T V = I - H H^T / 2, so |v_j|^2 = 1/2 and v_j.v_k = -h_j.h_k / 2: the noise-free
            # statistic |f_j v_j + f_k v_k|^2 = 400 (1 +- h_j.h_k) >= 400 (1 - 2/3) = 133 (|h_j.h_k| is
            # 1/sqrt 5 in the dodecahedron, at most 2/3 in the cone), over the threshold 31.0
            assert rd.test_statistic(rd.parity_vector(V, m)) > thr


def test_two_triads_detect_without_isolating() -> None:
    H = rd.triad_rows([np.eye(3), np.eye(3)])
    V = rd.parity_matrix(H)
    # each axis has two measurements: a one-dimensional parity per axis whose two columns are opposite
    assert not rd.isolable(V).any()
    m = H @ np.array([1.0, 2.0, 3.0])
    m[4] += 10.0
    p = rd.parity_vector(V, m)
    assert rd.test_statistic(p) == pytest.approx(50.0, rel=1e-12)  # 10^2 |v|^2, |v|^2 = 1/2
    assert rd.isolate(V, p) == -1
    # three triads: every column isolable; four single axes: parity of one dimension, none isolable
    assert rd.isolable(rd.parity_matrix(rd.triad_rows([np.eye(3)] * 3))).all()
    assert not rd.isolable(rd.parity_matrix(np.vstack([np.eye(3), np.ones(3) / math.sqrt(3)]))).any()


WHITE_SPEC = ImuSpec(gyro_arw=1e-3, accel_vrw=1e-2)


def test_monitor_with_two_imus_detects_and_never_isolates() -> None:
    dt = 0.01
    n = 6000
    t = dt * np.arange(1, n + 1)
    rng = np.random.default_rng(2)
    dth = 1e-3 * math.sqrt(dt) * rng.standard_normal((n, 2, 3))
    dv = 1e-2 * math.sqrt(dt) * rng.standard_normal((n, 2, 3))
    dth[t > 30.0, 1, 0] += 0.02 * dt  # 0.02 rad/s against a window sigma of 1e-3/sqrt(0.5) = 1.4e-3
    mon = ImuSetMonitor(2, WHITE_SPEC, dt)
    _, _, events = mon.process(t, dth, dv, np.full(n, dt))
    assert [e.event for e in events] == ["detected"]
    assert events[0].sensor == "gyro" and events[0].imu is None and events[0].axis == ""
    assert 30.0 < events[0].t <= 31.0


def test_parity_monitor_rejects_a_noiseless_model() -> None:
    with pytest.raises(ValueError, match="no noise"):
        ParityMonitor(rd.triad_rows([np.eye(3)] * 2), 0.0, window=10, window_s=0.1, false_alarm=1e-6)


def test_rotated_imus_fuse_to_the_body_vector_and_isolate_in_their_own_axes() -> None:
    # IMU 1 turned 90 deg about z: its x axis is body y (R maps body to IMU axes)
    rz = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    rots = [np.eye(3), rz, np.eye(3)]
    H = rd.triad_rows(rots)
    x = np.array([0.1, -0.2, 0.3])
    m = H @ x
    np.testing.assert_allclose(rd.fuse(H, m), x, rtol=1e-14)
    m[3] += 5.0  # IMU 1, its own x axis
    V = rd.parity_matrix(H)
    assert rd.isolate(V, rd.parity_vector(V, m)) == 3
    # the fused vector is off along body y by 1/3 of the fault: the mean of three measurements of y
    np.testing.assert_allclose(rd.fuse(H, m), x + np.array([0.0, 5.0 / 3.0, 0.0]), rtol=1e-13)


def test_monitor_isolates_a_noise_burst_and_takes_the_sensor_back() -> None:
    dt = 0.01
    n = 5000
    t = dt * np.arange(1, n + 1)
    rng = np.random.default_rng(8)
    dth = 1e-3 * math.sqrt(dt) * rng.standard_normal((n, 3, 3))
    dv = 1e-2 * math.sqrt(dt) * rng.standard_normal((n, 3, 3))
    burst = (t > 20.0) & (t <= 25.0)
    # 0.5 m/s^2 per sample for 5 s: window-mean sigma 0.5 / sqrt(50) = 0.07 against the window noise
    # 1e-2 / sqrt(0.5) = 0.014: non-centrality about (0.07/0.014)^2 (2/3) = 17 per window on average
    # with a chi-square(6) spread, far over 38 in some window of the ten
    dv[burst, 0, 2] += 0.5 * dt * rng.standard_normal(int(burst.sum()))
    mon = ImuSetMonitor(3, WHITE_SPEC, dt)
    _, _, events = mon.process(t, dth, dv, np.full(n, dt))
    kinds = [(e.event, e.sensor, e.imu, e.axis) for e in events]
    assert kinds[:2] == [("detected", "accel", None, ""), ("isolated", "accel", 0, "z")]
    assert 20.0 < events[1].t <= 25.0
    # taken back after 20 windows (10 s) in a row of agreement: not before 10 s after the isolation
    # (burst windows may pass the 1-dof test by chance), and at the latest 10 s after the burst, when
    # every clean window passes (each fails with probability 1e-6)
    assert kinds[2] == ("recovered", "accel", 0, "z")
    assert events[1].t + 10.0 - 1e-9 <= events[2].t <= 35.0 + 1e-9
    assert len(events) == 3


P_FA = 1e-6
THR1, THR2, THR3 = cc.upper(cc.q1, P_FA), -2.0 * math.log(P_FA), cc.upper(cc.q3, P_FA)


def _turn(axis: tuple[float, float, float], angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K  # Rodrigues


GOLD = (1.0 + math.sqrt(5.0)) / 2.0
# the six dodecahedron face normals (H^T H = 2 I), turned so that no row has a zero component
SKEW = np.array([[0.0, 1.0, GOLD], [0.0, -1.0, GOLD], [1.0, GOLD, 0.0], [-1.0, GOLD, 0.0], [GOLD, 0.0, 1.0],
                 [GOLD, 0.0, -1.0]]) / math.sqrt(1.0 + GOLD * GOLD) @ _turn((1.0, 2.0, 3.0), 0.4).T
TWO = np.vstack([np.eye(3), np.eye(3)])
THREE = np.vstack([np.eye(3)] * 3)


def _proj(H: np.ndarray) -> np.ndarray:
    """P = I - H (H^T H)^-1 H^T, the parity space's projector V^T V for equal sigmas."""
    return np.eye(H.shape[0]) - H @ np.linalg.inv(H.T @ H) @ H.T


SIG = 4.0  # sensor 1-sigma of a window mean (rate units); not 1 or 2, so sigma, sigma^2, 2 sigma differ
OMEGA = np.array([0.3, -0.7, 1.1])
BIAS6 = np.array([5.0, -3.0, 2.0, 7.0, -6.0, 1.0])
DT = 0.1  # two samples a window: window k ends at row 2k - 1, t = 0.2 k


def _monitor(H: np.ndarray, **kw) -> ParityMonitor:
    """alpha = 0.2 s / 1 s = 0.2, two calibration windows, a hold-off of three windows."""
    args = {"window": 2, "window_s": 0.2, "false_alarm": P_FA, "tau_bias": 1.0, "calibration": 2, "holdoff": 3}
    args.update(kw)
    return ParityMonitor(H, SIG, **args)


def _rates(H: np.ndarray, bias: np.ndarray, windows: int, faults: dict, omega: np.ndarray = OMEGA) -> np.ndarray:
    """Constant rates H omega + bias, plus faults[(window, sensor)] over both samples of a window."""
    m = np.tile(H @ omega + bias, (2 * windows, 1))
    for (k, j), f in faults.items():
        m[2 * k - 2: 2 * k, j] += f
    return m


def _tracker(windows: int, n_cal: int, alpha: float, frozen: tuple[int, ...] = ()) -> tuple[dict, dict]:
    """Per window k: the tracker weight, and the variance v its test divides by (v_(k-1)), by the
    documented rules (1/k while calibrating or while 1/k > alpha, then alpha; frozen windows keep v)."""
    v, weight, before = 0.0, {}, {}
    for k in range(1, windows + 1):
        weight[k] = 1.0 / k if (k <= n_cal or 1.0 / k > alpha) else alpha
        before[k] = v
        if k not in frozen:
            v = (1.0 - weight[k]) ** 2 * v + weight[k] ** 2
    return weight, before


# ---------------------------------------------------------------------------------------------------------------
# Normal and chi-square functions


def test_normal_quantiles_match_the_table_and_the_tail() -> None:
    """normal_isf against A&S table 26.5 (9 decimals) and against its own definition Q(z) = p. Newton
    stops at a step under 1e-14 |z|, which moves log Q by z dz <= 1e-14 z^2 (5e-13 at z = 7)."""
    for p, z in ((0.025, 1.959963985), (1e-3, 3.090232306), (1e-6, 4.753424309), (1e-9, 5.997807015)):
        assert rd.normal_isf(p) == pytest.approx(z, abs=5e-10)
    for p in (0.4, 0.025, 1e-6, 1e-12, 0.6, 0.975, 1.0 - 1e-6):
        z = rd.normal_isf(p)
        assert 0.5 * math.erfc(z / math.sqrt(2.0)) == pytest.approx(p, rel=1e-11)
    assert rd.normal_isf(0.6) < 0.0 < rd.normal_isf(0.4)
    assert rd.normal_isf(0.5) == pytest.approx(0.0, abs=1e-15)  # the median, reached without recursion


@pytest.mark.parametrize("p", [0.0, 1.0, 1.5, -0.5])
def test_probabilities_outside_the_open_interval_are_refused(p: float) -> None:
    """normal_isf and chi2_quantile take a probability in (0, 1); the message names the value given."""
    with pytest.raises(ValueError, match=rf"^probability must be in \(0, 1\), got {p!r}$"):
        rd.normal_isf(p)
    with pytest.raises(ValueError, match=rf"^probability must be in \(0, 1\), got {p!r}$"):
        rd.chi2_quantile(p, 3)
    with pytest.raises(ValueError, match=r"^degrees of freedom must be >= 1, got 0$"):
        rd.chi2_quantile(0.5, 0)


def test_chi2_distribution_and_density_against_closed_forms() -> None:
    """P and Q for 1, 2 and 4 dof (A&S 26.4.4, 26.4.5), the density for 1, 2, 4, 6 dof (A&S 26.4.1),
    at x on both sides of the series / continued-fraction switch (x/2 = dof/2 + 1) and at x <= 0.
    The results are exp of an argument near -x/2 (10 at most): rounding 1e-15 x 10."""
    for x in (0.5, 2.9, 3.0, 3.1, 6.0, 20.0):
        assert rd.chi2_cdf(x, 2) == pytest.approx(-math.expm1(-0.5 * x), rel=1e-13)
        assert rd.chi2_sf(x, 2) == pytest.approx(math.exp(-0.5 * x), rel=1e-13)
        assert rd.chi2_cdf(x, 1) == pytest.approx(math.erf(math.sqrt(0.5 * x)), rel=1e-13)
        assert rd.chi2_sf(x, 1) == pytest.approx(math.erfc(math.sqrt(0.5 * x)), rel=1e-13)
        assert rd.chi2_sf(x, 4) == pytest.approx(math.exp(-0.5 * x) * (1.0 + 0.5 * x), rel=1e-13)
        assert rd.chi2_pdf(x, 1) == pytest.approx(math.exp(-0.5 * x) / math.sqrt(2.0 * math.pi * x), rel=1e-13)
        assert rd.chi2_pdf(x, 2) == pytest.approx(0.5 * math.exp(-0.5 * x), rel=1e-13)
        assert rd.chi2_pdf(x, 4) == pytest.approx(0.25 * x * math.exp(-0.5 * x), rel=1e-13)
        assert rd.chi2_pdf(x, 6) == pytest.approx(x * x / 16.0 * math.exp(-0.5 * x), rel=1e-13)
    for x in (0.0, -1.0):
        assert rd.gamma_pq(1.5, x) == (0.0, 1.0)
        assert rd.chi2_cdf(x, 3) == 0.0 and rd.chi2_sf(x, 3) == 1.0 and rd.chi2_pdf(x, 3) == 0.0


def test_chi2_quantile_lower_tails_and_small_quantiles() -> None:
    """Lower-tail quantiles for 1 and 2 dof (x = -2 log(1 - q) for 2 dof; erf(sqrt(x/2)) = q for 1),
    and upper-tail quantiles below 1 (q near 1), where the root lies in (0, 1)."""
    for q in (1e-12, 1e-6, 0.1, 0.5, 0.9, 0.999):
        assert rd.chi2_quantile(q, 2) == pytest.approx(-2.0 * math.log1p(-q), rel=1e-12)
        x1 = rd.chi2_quantile(q, 1)
        assert math.erf(math.sqrt(0.5 * x1)) == pytest.approx(q, rel=1e-12)
    for q in (0.9, 0.999999):
        assert rd.chi2_quantile(q, 2, upper=True) == pytest.approx(-2.0 * math.log(q), rel=1e-12)
        assert cc.q1(rd.chi2_quantile(q, 1, upper=True)) == pytest.approx(q, rel=1e-12)
    for q in (0.1, 0.5, 0.9):
        x4 = rd.chi2_quantile(q, 4)
        assert 1.0 - math.exp(-0.5 * x4) * (1.0 + 0.5 * x4) == pytest.approx(q, rel=1e-12)


def test_chi2_quantile_far_tails_against_closed_forms() -> None:
    """Upper tails at 1e-300, where Q underflows beyond the root and the bracket must keep the search in
    (0, inf): 2 dof -2 ln q, 1, 3 and 10 dof through log Q (its slope is -1/2, so a relative error
    1e-14 of x ~ 1400 moves log Q by 1e-11). Lower tails at 1e-100 and 1e-300: 2 dof x = -2 log(1 - q),
    1 dof erf(sqrt(x/2)) = q."""
    lq = math.log(1e-300)
    assert rd.chi2_quantile(1e-300, 2, upper=True) == pytest.approx(-2.0 * lq, rel=1e-12)
    assert math.log(cc.q1(rd.chi2_quantile(1e-300, 1, upper=True))) == pytest.approx(lq, abs=1e-9)
    assert math.log(cc.q3(rd.chi2_quantile(1e-300, 3, upper=True))) == pytest.approx(lq, abs=1e-9)
    assert cc.log_q10(rd.chi2_quantile(1e-300, 10, upper=True)) == pytest.approx(lq, abs=1e-9)
    for q in (1e-100, 1e-300):
        assert rd.chi2_quantile(q, 2) == pytest.approx(-2.0 * math.log1p(-q), rel=1e-12)
    assert math.erf(math.sqrt(0.5 * rd.chi2_quantile(1e-100, 1))) == pytest.approx(1e-100, rel=1e-12)


def test_chi2_lower_quantiles_of_small_probabilities() -> None:
    """P(X <= x) = q for 4 dof, 1 - e^-u (1 + u) = u^2/2 - u^3/3 + u^4/8 - ... (u = x/2, A&S 26.4.5),
    q = 1e-9 at u = 4.5e-5; for 3 dof erf(sqrt(x/2)) - 2 phi(sqrt x) sqrt x = q (A&S 26.4.4), q = 1e-6."""
    u = 0.5 * rd.chi2_quantile(1e-9, 4)
    assert u * u / 2.0 - u**3 / 3.0 + u**4 / 8.0 == pytest.approx(1e-9, rel=1e-9)
    assert cc.p3(rd.chi2_quantile(1e-6, 3)) == pytest.approx(1e-6, rel=1e-9)


def test_chi2_quantiles_deep_in_the_lower_tail() -> None:
    """For even k = 2m, P(X <= x) = 1 - e^-u sum_{i<m} u^i / i! (u = x/2, A&S 26.4.21), whose leading term
    for small u is u^m / m! (the next is -m/(m+1) u times it, below 1e-30 relative here): q = 1e-30, 1e-100
    and 1e-300 at 4, 6 and 10 dof in the lower tail; q = 1e-12 as the upper tail's 1 - q near 1, to the
    second term, within 1e-3 (the double nearest 1 - 1e-12 is off by up to 1.1e-16, 1.1e-4 of q)."""
    for m in (2, 3, 5):
        for q in (1e-30, 1e-100, 1e-300):
            u = 0.5 * rd.chi2_quantile(q, 2 * m)
            assert u**m / math.factorial(m) == pytest.approx(q, rel=1e-9)
    q = 1e-12
    for m in (2, 3, 5):
        u = 0.5 * rd.chi2_quantile(1.0 - q, 2 * m, upper=True)
        assert u**m / math.factorial(m) * (1.0 - m / (m + 1.0) * u) == pytest.approx(q, rel=1e-3)


def test_chi2_upper_quantiles_of_probabilities_near_one() -> None:
    """P(X > x) = 0.9999 for 3 dof: the small root with 1 - Q = erf(sqrt(x/2)) - 2 phi(sqrt x) sqrt x
    = 1e-4 (A&S 26.4.4); the design false-alarm probability of a two-IMU set (3 dof) may be any value
    in (0, 1)."""
    q = 0.9999
    assert cc.p3(rd.chi2_quantile(q, 3, upper=True)) == pytest.approx(1.0 - q, rel=1e-9)


def _ncx2_cdf_3(x: float, lam: float) -> float:
    """P(|z + mu|^2 <= x), z ~ N(0, I_3), |mu|^2 = lam: with s = sqrt x, a = sqrt lam, the radial density
    (r/a)(phi(r - a) - phi(r + a)) integrates to Phi(s - a) - Phi(-s - a) - (phi(s - a) - phi(s + a))/a."""
    s, a = math.sqrt(x), math.sqrt(lam)
    return cc.phi(s - a) - cc.phi(-s - a) - (cc.dens(s - a) - cc.dens(s + a)) / a


def test_noncentral_chi2_and_detection_probability_for_three_dof() -> None:
    """ncx2_cdf for 3 dof against the closed form above; at lam = 0 (and below) the central law; the
    detection probability is its complement, and at lam = 0 and the design threshold it is P_fa."""
    for lam in (0.5, 4.0, 30.0, 400.0):
        for x in (0.3, 3.0, 25.0, 500.0):
            assert rd.ncx2_cdf(x, 3, lam) == pytest.approx(_ncx2_cdf_3(x, lam), abs=1e-12)
            assert rd.detection_probability(lam, 3, x) == pytest.approx(1.0 - _ncx2_cdf_3(x, lam), abs=1e-12)
    for lam in (0.0, -1.0):
        assert rd.ncx2_cdf(3.0, 2, lam) == pytest.approx(-math.expm1(-1.5), rel=1e-13)
    assert rd.detection_probability(0.0, 3, THR3) == pytest.approx(P_FA, rel=1e-9)
    assert rd.detection_probability(0.0, 2, THR2) == pytest.approx(P_FA, rel=1e-9)


# ---------------------------------------------------------------------------------------------------------------
# The measurement model and its parity space


def test_parity_matrix_refuses_wrong_shapes_and_flat_sets_and_accepts_a_triad() -> None:
    """H must be (n, 3), n >= 3; a single triad has no parity (0 rows); axes that do not span 3D are
    refused, also when whitening makes one sensor a million times heavier: the rank is judged relative
    to the largest singular value (numerical rank, Golub & Van Loan 5.4.1), here 7e-7 against 1.4e6."""
    for shape in ((2, 3), (4, 2), (4, 3, 1)):
        with pytest.raises(ValueError, match="^" + re.escape(f"H must be (n, 3) with n >= 3, got {shape}") + "$"):
            rd.parity_matrix(np.ones(shape))
    assert rd.parity_matrix(np.eye(3)).shape == (0, 3)
    with pytest.raises(ValueError, match=r"^the sensor axes do not span three dimensions$"):
        rd.parity_matrix(np.zeros((4, 3)))
    flat = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 1e-12], [0.0, 1.0, 0.0], [0.0, 1.0, 1e-12]])
    with pytest.raises(ValueError, match="span three dimensions"):
        rd.parity_matrix(flat, np.array([1e-6, 1e-6, 1.0, 1.0]))


def test_sigmas_must_be_positive() -> None:
    """A zero (or negative) sensor sigma has no weight W = 1/sigma."""
    for s in (0.0, -1.0):
        with pytest.raises(ValueError, match=r"^sensor sigmas must be positive$"):
            rd.fusion_matrix(TWO, np.array([1.0, 1.0, 1.0, 1.0, 1.0, s]))


def test_weighted_parity_statistic_of_two_triads_is_the_weighted_disagreement() -> None:
    """Two triads with sigmas 1 and 2: p^T p is the weighted least-squares residual, per axis
    (m0 - m1)^2 / (s0^2 + s1^2), whatever basis V has; a batch (N, n) gives one statistic per row."""
    s = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
    V = rd.parity_matrix(TWO, s)
    m = np.array([[1.0, 2.0, 3.0, 1.5, 1.0, 2.0], [0.0, 0.0, 0.0, 5.0, 0.0, 0.0]])
    p = rd.parity_vector(V, m, s)
    assert p.shape == (2, 3)
    np.testing.assert_allclose(rd.test_statistic(p), [(0.25 + 1.0 + 1.0) / 5.0, 25.0 / 5.0], rtol=1e-14)
    np.testing.assert_allclose(rd.test_statistic(rd.parity_vector(V, m[1], s)), 5.0, rtol=1e-14)


def test_isolation_scores_of_three_triads_and_of_a_reduced_set() -> None:
    """Three triads: V^T V = I - (1/3) [I I I]..., so |v_j|^2 = 2/3 and v_j^T p = m_j - (mean of its axis):
    score (m_j - mean)^2 * 3/2. With sensor 0 dropped (reconfigure), axis x keeps a pair: |v|^2 = 1/2,
    score (m_3 - m_6)^2 / 2, and the dropped column (zero) scores 0."""
    m = np.array([1.0, 2.0, 3.0, 1.6, 2.3, 2.4, 0.5, 2.0, 3.9])
    V = rd.parity_matrix(THREE)
    axis_mean = np.tile(m.reshape(3, 3).mean(axis=0), 3)
    np.testing.assert_allclose(rd.isolation_scores(V, rd.parity_vector(V, m)), 1.5 * (m - axis_mean) ** 2,
                               rtol=1e-12, atol=1e-15)
    active = np.ones(9, dtype=bool)
    active[0] = False
    _, V8 = rd.reconfigure(THREE, active)
    scores = rd.isolation_scores(V8, rd.parity_vector(V8, m))
    assert scores[0] == 0.0
    np.testing.assert_allclose(scores[[3, 6]], (m[3] - m[6]) ** 2 / 2.0, rtol=1e-12)
    np.testing.assert_allclose(scores[[1, 2, 4, 5, 7, 8]], 1.5 * (m - axis_mean)[[1, 2, 4, 5, 7, 8]] ** 2, rtol=1e-12)


def test_isolable_follows_its_definition() -> None:
    """A column is isolable when it is non-zero and parallel to no other (docstring): hand-made V."""
    r = 1.0 / math.sqrt(2.0)
    res = rd.isolable(np.array([[r, -r, 0.0], [0.0, 0.0, 1.0]]))
    assert res.dtype == np.bool_ and res.tolist() == [False, False, True]
    res = rd.isolable(np.array([[1.0, 0.0, 0.0, 0.0]]))
    assert res.tolist() == [True, False, False, False]
    res = rd.isolable(np.zeros((0, 4)))
    assert res.dtype == np.bool_ and res.tolist() == [False] * 4


def test_reconfigure_weights_the_remaining_sensors() -> None:
    """Two triads, sigmas 1 and 2, IMU 1's y dropped: x and z are the inverse-variance means (weights
    1 and 1/4 over 1.25), y is IMU 0's alone; V has n_active - 3 = 2 rows with V W H = 0 and V V^T = I
    on the active columns and zeros on the dropped one. A monitor-style 0.0/1.0 mask is the same mask.
    Four sensors left: one parity row; three: none."""
    s = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
    mask = np.array([1.0, 1.0, 1.0, 1.0, 0.0, 1.0])
    G, V = rd.reconfigure(TWO, mask > 0.0, s)
    expect = np.array([[0.8, 0, 0, 0.2, 0, 0], [0, 1.0, 0, 0, 0, 0], [0, 0, 0.8, 0, 0, 0.2]])
    np.testing.assert_allclose(G, expect, rtol=1e-14, atol=1e-15)
    assert V.shape == (2, 6) and np.all(V[:, 4] == 0.0)
    act = mask > 0.0
    np.testing.assert_allclose(V[:, act] @ np.diag(1.0 / s[act]) @ TWO[act], 0.0, atol=1e-14)
    np.testing.assert_allclose(V @ V.T, np.eye(2), atol=1e-14)
    G2, V2 = rd.reconfigure(TWO, mask, s)
    np.testing.assert_allclose(G2, expect, rtol=1e-14, atol=1e-15)
    assert V2.shape == (2, 6) and np.all(V2[:, 4] == 0.0)
    _, V4 = rd.reconfigure(TWO, np.array([True, True, True, True, False, False]), s)
    assert V4.shape == (1, 6) and np.linalg.norm(V4) == pytest.approx(1.0, rel=1e-14)
    _, V3 = rd.reconfigure(TWO, np.array([True, True, True, False, False, False]), s)
    assert V3.shape == (0, 6)


def test_window_sigma_terms() -> None:
    """white^2 / T; plus gm^2 tau_b / (tau_b + tau_gm) for a Gauss-Markov bias (none for tau_gm = inf,
    a constant the tracker removes); plus rrw^2 tau_b / 2."""
    assert rd.window_sigma(2e-3, 0.5, 60.0) == pytest.approx(2e-3 / math.sqrt(0.5), rel=1e-15)
    assert rd.window_sigma(2e-3, 0.5, 60.0, gm=3e-4) == pytest.approx(2e-3 / math.sqrt(0.5), rel=1e-15)
    assert rd.window_sigma(2e-3, 0.5, 60.0, gm=3e-4, tau_gm=100.0) == pytest.approx(
        math.sqrt(8e-6 + 9e-8 * 60.0 / 160.0), rel=1e-15)
    assert rd.window_sigma(2e-3, 0.5, 60.0, gm=3e-4, tau_gm=100.0, rrw=1e-5) == pytest.approx(
        math.sqrt(8e-6 + 9e-8 * 60.0 / 160.0 + 1e-10 * 30.0), rel=1e-15)


def test_cone_of_three_is_a_triad_and_fewer_are_refused() -> None:
    """At the optimal half-angle N = 3 axes give H^T H = (N/3) I = I; two axes cannot make a cone."""
    np.testing.assert_allclose(rd.cone_axes(3).T @ rd.cone_axes(3), np.eye(3), atol=1e-15)
    with pytest.raises(ValueError, match=r"^a cone needs at least 3 sensors, got 2$"):
        rd.cone_axes(2)


# ---------------------------------------------------------------------------------------------------------------
# The monitor


def test_skew_set_detects_isolates_takes_back_and_fuses_without_a_jump() -> None:
    """Six skewed gyros (P_jj = 1/2), biases learnt in windows 1-2. A fault of 80 (20 sigma) on sensor 0
    in window 6: statistic 80^2 / 2 / 4^2 / (1 + v_5) with v_5 = 1/5, over THR3 (3 dof): detected and
    isolated at t = 1.2. Its 1-dof check (sigma^2 (1 + h^T (H_a^T H_a)^-1 h) = 2 sigma^2) passes in windows
    7-9: taken back at 1.8. The same fault in window 12 again; then window 13 reads z^2 = 25 (over THR1
    = 23.9: not taken back, though under 2-dof 27.6) and windows 14-16 z^2 = 23: taken back at 3.2,
    its bias untouched while it was out (windows 17-18 test 0). Fused: (omega + G c) dt throughout, the
    fault's f h_0 / 2 in the two windows that revealed it."""
    mon = _monitor(SKEW)
    assert mon.isolating
    P = _proj(SKEW)
    f, r25, r23 = 80.0, SIG * math.sqrt(2.0) * 5.0, SIG * math.sqrt(2.0) * math.sqrt(23.0)
    rates = _rates(SKEW, BIAS6, 18, {(6, 0): f, (12, 0): f, (13, 0): r25, (14, 0): r23, (15, 0): r23,
                                     (16, 0): r23})
    t = DT * np.arange(1, 37)
    dt = np.full(36, DT)
    fused, events, res = [], [], {}
    for a, b in ((0, 10), (10, 12), (12, 26), (26, 36)):
        out, ev = mon.process(t[a:b], rates[a:b] * DT, dt[a:b])
        fused.append(out)
        events += ev
        res[b] = mon.residuals().copy()
    _, v = _tracker(18, 2, 0.2, frozen=(6, 12))
    s6, s12 = f * f / 2.0 / SIG**2 / (1.0 + v[6]), f * f / 2.0 / SIG**2 / (1.0 + v[12])
    assert v[6] == pytest.approx(0.2, rel=1e-15) and s6 > THR3 and s12 > THR3
    got = [(e.event, e.sensor, e.index, e.t, e.statistic) for e in events]
    expect = [("detected", "gyro", -1, t[11], s6), ("isolated", "gyro", 0, t[11], s6),
              ("recovered", "gyro", 0, t[17], 0.0), ("detected", "gyro", -1, t[23], s12),
              ("isolated", "gyro", 0, t[23], s12), ("recovered", "gyro", 0, t[31], 0.0)]
    assert [g[:4] for g in got] == [e[:4] for e in expect]
    np.testing.assert_allclose([g[4] for g in got], [e[4] for e in expect], rtol=1e-12, atol=1e-20)
    assert [e.threshold for e in events[:2] + events[3:5]] == pytest.approx([THR3] * 4, rel=1e-10)
    assert all(math.isfinite(e.threshold) and e.threshold > 0.0 for e in events)
    # the log: every window after calibration, the statistic against the threshold of its configuration
    stats = mon.statistics()
    thr = [THR3] * 4 + [THR2] * 3 + [THR3] * 3 + [THR2] * 4 + [THR3] * 2
    stat = [0.0] * 3 + [s6] + [0.0] * 5 + [s12] + [0.0] * 6
    np.testing.assert_allclose(stats[:, 0], t[5::2], rtol=0, atol=0)
    np.testing.assert_allclose(stats[:, 1], stat, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(stats[:, 2], thr, rtol=1e-10)
    np.testing.assert_allclose(mon.recent, stats[-5:], rtol=0, atol=0)  # the last call's tests (14-18)
    # residuals v_k^T p / |v_k| of the last test of each call: f P_0k / (sigma sqrt(P_kk)) at the detection
    np.testing.assert_allclose(res[10], 0.0, atol=1e-12)
    np.testing.assert_allclose(res[12], f * P[0] / (SIG * np.sqrt(np.diag(P))), rtol=1e-12)
    assert res[26][0] == 0.0  # window 13, sensor 0 dropped
    np.testing.assert_allclose(res[26], 0.0, atol=1e-12)
    fused = np.concatenate(fused)
    base = (OMEGA + SKEW.T @ BIAS6 / 2.0) * DT
    expect_fused = np.tile(base, (36, 1))
    expect_fused[[10, 11, 22, 23]] += f * SKEW[0] / 2.0 * DT
    np.testing.assert_allclose(fused, expect_fused, rtol=0, atol=1e-14)


def test_rates_are_averaged_over_time_and_the_bias_is_a_rate() -> None:
    """Rates over alternating intervals 0.05 and 0.15 s: the window mean is sum(m dt) / sum(dt), so a
    fault of 320 in the first (0.05 s) sample of window 5 weighs 80: statistic 80^2/2/16/(1 + 1/4) = 160,
    isolated at the window's end; after it the fused rate G_a (m - b) is still omega + G c. A large x rate
    (60) makes the dropped sensor's check h^T x depend on every component of x."""
    omega = np.array([60.0, -25.0, 40.0])
    mon = _monitor(SKEW)
    rates = _rates(SKEW, BIAS6, 9, {}, omega)
    rates[8, 3] += 320.0
    dt = np.tile([0.05, 0.15], 9)
    t = np.cumsum(dt)
    fused, events = mon.process(t, rates, dt, rates=True)
    s5 = 80.0**2 / 2.0 / SIG**2 / 1.25
    assert [(e.event, e.index, e.t) for e in events] == [("detected", -1, t[9]), ("isolated", 3, t[9]),
                                                         ("recovered", 3, t[15])]
    assert events[0].statistic == pytest.approx(s5, rel=1e-12)
    expect = np.tile(omega + SKEW.T @ BIAS6 / 2.0, (18, 1))
    expect[8] += 320.0 * SKEW[3] / 2.0
    np.testing.assert_allclose(fused, expect, rtol=0, atol=1e-13)  # values to 220: a few ulp of 60 x 6 terms


def test_bias_tracker_follows_a_small_step_with_the_documented_weights() -> None:
    """A step of 24 (6 sigma) on sensor 2 from window 3 on, under the threshold: the tracker takes the
    fraction 1 - prod(1 - w_i) of its parity part, w = 1/3, 1/4 while 1/k > alpha = 0.2, then 0.2, so
    window k tests 24^2 / 2 / 16 (1 - frac_(k-1))^2 / (1 + v_(k-1))."""
    mon = _monitor(SKEW)
    rates = _rates(SKEW, BIAS6, 12, {(k, 2): 24.0 for k in range(3, 13)})
    t = DT * np.arange(1, 25)
    mon.process(t, rates * DT, np.full(24, DT))
    w, v = _tracker(12, 2, 0.2)
    assert [w[3], w[4], w[5], w[6]] == [1 / 3, 0.25, 0.2, 0.2]
    left, expect = 1.0, []
    for k in range(3, 13):
        expect.append(24.0**2 / 2.0 / SIG**2 * left**2 / (1.0 + v[k]))
        left *= 1.0 - w[k]
    stats = mon.statistics()
    assert max(expect) < THR3
    np.testing.assert_allclose(stats[:, 1], expect, rtol=1e-12)


def test_tracker_weight_is_at_most_one() -> None:
    """A window longer than tau_bias (2 s against 1 s) gives alpha = min(1, T / tau) = 1: the tracker
    takes all of a step (6 sigma) after one window, and v stays 1: 18 / 2, then 0."""
    mon = ParityMonitor(SKEW, SIG, window=1, window_s=2.0, false_alarm=P_FA, tau_bias=1.0, calibration=1)
    rates = np.tile(SKEW @ OMEGA + BIAS6, (4, 1))
    rates[1:, 2] += 24.0
    mon.process(2.0 * np.arange(1, 5), rates * 2.0, np.full(4, 2.0))
    np.testing.assert_allclose(mon.statistics()[:, 1], [9.0, 0.0, 0.0], rtol=1e-12, atol=1e-20)


def test_two_triads_raise_an_alarm_and_clear_it() -> None:
    """Two triads: opposite parity columns, nothing isolable (P_jj = 1/2). A fault of 80 on IMU 1's y in
    windows 4-5: detected at 0.8 (statistic 200 / (1 + 1/3)), tracker frozen so window 5 tests the same;
    cleared after three clean windows (1.6); detected again in window 10, cleared at 2.6. The fusion
    keeps both IMUs: the fault's half in those windows. Residuals +-f / (sigma sqrt 2) on the pair."""
    mon = _monitor(TWO)
    assert not mon.isolating
    c = BIAS6
    rates = _rates(TWO, c, 13, {(4, 4): 80.0, (5, 4): 80.0, (10, 4): 80.0})
    t = DT * np.arange(1, 27)
    fused1, ev1 = mon.process(t[:8], rates[:8] * DT, np.full(8, DT))
    res = mon.residuals().copy()
    fused2, ev2 = mon.process(t[8:], rates[8:] * DT, np.full(18, DT))
    _, v = _tracker(13, 2, 0.2, frozen=(4, 5, 10))
    s4, s10 = 200.0 / (1.0 + v[4]), 200.0 / (1.0 + v[10])
    assert v[4] == pytest.approx(1.0 / 3.0, rel=1e-15)
    events = ev1 + ev2
    assert [(e.event, e.sensor, e.index, e.t) for e in events] == [
        ("detected", "gyro", -1, t[7]), ("recovered", "gyro", -1, t[15]), ("detected", "gyro", -1, t[19]),
        ("recovered", "gyro", -1, t[25])]
    np.testing.assert_allclose([e.statistic for e in events], [s4, 0.0, s10, 0.0], rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose([e.threshold for e in events], THR3, rtol=1e-10)
    np.testing.assert_allclose(mon.statistics()[:, 1], [0.0, s4, s4] + [0.0] * 4 + [s10] + [0.0] * 3,
                               rtol=1e-12, atol=1e-20)
    r = 80.0 / (SIG * math.sqrt(2.0))
    np.testing.assert_allclose(res, [0.0, -r, 0.0, 0.0, r, 0.0], rtol=1e-12, atol=1e-12)
    expect = np.tile((OMEGA + (c[:3] + c[3:]) / 2.0) * DT, (26, 1))
    expect[[6, 7, 8, 9, 18, 19], 1] += 40.0 * DT
    np.testing.assert_allclose(np.concatenate([fused1, fused2]), expect, rtol=0, atol=1e-14)


def test_monitor_weights_the_imus_by_their_sigmas() -> None:
    """Two triads with window sigmas 2 and 4: the fusion is the inverse-variance mean (weights 1/4 and
    1/16: 0.8 and 0.2), and a fault of 40 on IMU 1's x tests as the weighted disagreement,
    40^2 / (2^2 + 4^2) / (1 + 1/2) = 53.3 in window 3, over THR3: detected (two triads isolate nothing)."""
    s = np.array([2.0, 2.0, 2.0, 4.0, 4.0, 4.0])
    mon = ParityMonitor(TWO, s, window=2, window_s=0.2, false_alarm=P_FA, tau_bias=1.0, calibration=2)
    rates = _rates(TWO, BIAS6, 3, {(3, 3): 40.0})
    t = DT * np.arange(1, 7)
    fused, events = mon.process(t, rates * DT, np.full(6, DT))
    assert [(e.event, e.index, e.t) for e in events] == [("detected", -1, t[5])]
    assert events[0].statistic == pytest.approx(1600.0 / 20.0 / 1.5, rel=1e-12)
    expect = np.tile((OMEGA + 0.8 * BIAS6[:3] + 0.2 * BIAS6[3:]) * DT, (6, 1))
    expect[4:, 0] += 0.2 * 40.0 * DT
    np.testing.assert_allclose(fused, expect, rtol=0, atol=1e-14)


def test_four_sensors_detect_on_one_degree_of_freedom() -> None:
    """A triad and (1,1,1)/sqrt 3: the parity is v = (1, 1, 1, -sqrt 3)/sqrt 6, P_00 = 1/6, threshold the
    1-dof quantile. A fault of 120 on x in window 4: 120^2/6/16/(1 + 1/3) = 112.5, detected, not isolated."""
    H = np.vstack([np.eye(3), np.ones(3) / math.sqrt(3.0)])
    mon = _monitor(H)
    rates = _rates(H, np.array([1.0, -2.0, 0.5, 3.0]), 5, {(4, 0): 120.0})
    t = DT * np.arange(1, 11)
    _, events = mon.process(t, rates * DT, np.full(10, DT))
    assert [(e.event, e.index, e.t) for e in events] == [("detected", -1, t[7])]
    assert events[0].statistic == pytest.approx(112.5, rel=1e-12)
    assert events[0].threshold == pytest.approx(THR1, rel=1e-10)


def test_single_triad_fuses_without_testing() -> None:
    """Three sensors: no parity, so no test, no event and an infinite threshold; the fusion is the triad."""
    mon = _monitor(np.eye(3))
    m = np.arange(30.0).reshape(10, 3) * DT
    fused, events = mon.process(DT * np.arange(1, 11), m, np.full(10, DT))
    assert events == [] and mon.statistics().shape == (0, 3) and mon.threshold == math.inf
    assert not mon.isolating
    np.testing.assert_allclose(fused, m, rtol=0, atol=1e-15)


def test_a_window_of_zero_duration_waits_for_the_next_sample() -> None:
    """One-sample windows (allowed); a sample of dt = 0 has no mean rate, so its window continues into
    the next sample: tests at 0.2, 0.3, 0.4 s, none at the zero-length one."""
    mon = _monitor(SKEW, window=1, calibration=1)
    dt = np.array([0.1, 0.0, 0.1, 0.1, 0.1])
    t = np.array([0.1, 0.1, 0.2, 0.3, 0.4])
    m = np.outer(dt, SKEW @ OMEGA + BIAS6)
    fused, _ = mon.process(t, m, dt)
    stats = mon.statistics()
    np.testing.assert_allclose(stats[:, 0], [0.2, 0.3, 0.4], rtol=0, atol=0)
    np.testing.assert_allclose(stats[:, 1], 0.0, atol=1e-20)
    np.testing.assert_allclose(fused, np.outer(dt, OMEGA + SKEW.T @ BIAS6 / 2.0), rtol=0, atol=1e-14)


def test_parity_monitor_validates_its_arguments() -> None:
    """False-alarm probability in (0, 1), a window of at least one sample, at least three sensors."""
    for p in (0.0, 1.0, 1.5):
        with pytest.raises(ValueError, match=rf"^false-alarm probability must be in \(0, 1\), got {p!r}$"):
            ParityMonitor(SKEW, SIG, window=2, window_s=0.2, false_alarm=p)
    with pytest.raises(ValueError, match=r"^window must hold at least one sample, got 0$"):
        ParityMonitor(SKEW, SIG, window=0, window_s=0.2, false_alarm=P_FA)
    with pytest.raises(ValueError, match=r"^gyro: fewer than three sensors left$"):
        ParityMonitor(np.eye(3)[:2], SIG, window=2, window_s=0.2, false_alarm=P_FA)


def test_parity_monitor_defaults_are_the_documented_ones() -> None:
    """docs/redundancy.md with 0.5 s windows: tracker 60 s, calibration 5 s (10 windows), hold-off 10 s
    (20 windows), the set named gyro, every test kept for statistics()."""
    mon = ParityMonitor(SKEW, SIG, window=1, window_s=0.5, false_alarm=P_FA)
    assert (mon.alpha, mon.calibration, mon.holdoff, mon.name) == (0.5 / 60.0, 10, 20, "gyro")
    t = 0.5 * np.arange(1, 13)
    mon.process(t, np.outer(np.full(12, 0.5), SKEW @ OMEGA), np.full(12, 0.5))
    np.testing.assert_allclose(mon.statistics()[:, 0], [5.5, 6.0], rtol=0, atol=0)


def test_statistics_accumulate_over_calls_unless_not_kept() -> None:
    """statistics() is empty before any test and concatenates the calls' tests; with keep_log off it stays
    empty while recent still holds the last call's tests."""
    for keep in (True, False):
        mon = _monitor(SKEW, keep_log=keep)
        assert mon.statistics().shape == (0, 3) and mon.recent.shape == (0, 3)
        m = np.outer(np.full(12, DT), SKEW @ OMEGA)
        t = DT * np.arange(1, 13)
        mon.process(t[:8], m[:8], np.full(8, DT))
        mon.process(t[8:], m[8:], np.full(4, DT))
        assert mon.recent.shape == (2, 3)
        np.testing.assert_allclose(mon.recent[:, 0], t[9::2], rtol=0, atol=0)
        if keep:
            np.testing.assert_allclose(mon.statistics()[:, 0], t[5::2], rtol=0, atol=0)
        else:
            assert mon.statistics().shape == (0, 3)


def test_imu_set_monitor_validates_and_sizes_its_windows() -> None:
    """Two or more IMUs, a positive finite sample interval; the window holds round(0.5 s / dt) samples,
    the calibration 5 s, the hold-off 10 s, the tracker 60 s (docs/redundancy.md); alpha = T / tau_bias;
    a window, a calibration and a hold-off are at least one (sample, window, window)."""
    spec = ImuSpec(gyro_arw=1e-3, accel_vrw=1e-2)
    with pytest.raises(ValueError, match=r"^FDI needs two or more IMUs, got 1$"):
        ImuSetMonitor(1, spec, 0.01)
    for dt in (0.0, -0.01, math.inf, math.nan):
        with pytest.raises(ValueError, match=r"^sample interval must be positive"):
            ImuSetMonitor(3, spec, dt)
    mon = ImuSetMonitor(3, spec, 0.01)
    for part in (mon.gyro, mon.accel):
        assert (part.window, part.calibration, part.holdoff) == (50, 10, 20)
        assert part.alpha == pytest.approx(0.5 / 60.0, rel=1e-14)
    assert mon.window_s == pytest.approx(0.5, rel=1e-15)
    mon = ImuSetMonitor(3, spec, 1.0)
    assert mon.window_s == 1.0 and mon.gyro.window == 1
    mon = ImuSetMonitor(3, spec, 0.5, tau_bias=2.0, calibration=0.0, holdoff=0.0)
    assert (mon.gyro.alpha, mon.gyro.calibration, mon.gyro.holdoff) == (0.25, 1, 1)  # at least one window
    mon = ImuSetMonitor(3, spec, 0.5)
    n = 12
    mon.process(0.5 * np.arange(1, n + 1), np.zeros((n, 3, 3)), np.zeros((n, 3, 3)), np.full(n, 0.5))
    np.testing.assert_allclose(mon.gyro.statistics()[:, 0], [5.5, 6.0], rtol=0, atol=0)


def test_imu_set_monitor_noise_figure_rotations_and_rates() -> None:
    """Three IMUs, IMU 1 turned 90 deg about z, rates, one sample a window (0.5 s), calibration and
    hold-off 1 s (two windows). The noise figure s^2 = N^2/T + gm^2 tau_b/(tau_b + tau_c) + K^2 tau_b/2
    (docs/redundancy.md); P_jj = 2/3. A gyro fault of 20 s on IMU 1's own x in window 4 (v_3 = 1/3):
    statistic 400 (2/3) / (4/3) = 200, isolated as IMU 1 x at 2.0 s, back at 3.0 s; an accel fault of
    20 s on IMU 0's z in window 5 (v_4 = 1/4): 400 (2/3) / (5/4). The fused rates are the body ones."""
    spec = ImuSpec(gyro_arw=2e-3, gyro_gm=1e-3, gyro_tau=100.0, gyro_rrw=1e-4, accel_vrw=2e-2, accel_gm=3e-3,
                   accel_tau=300.0, accel_rrw=2e-4)
    sg = math.sqrt(4e-6 / 0.5 + 1e-6 * 60.0 / 160.0 + 1e-8 * 30.0)
    sa = math.sqrt(4e-4 / 0.5 + 9e-6 * 60.0 / 360.0 + 4e-8 * 30.0)
    rz = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    rots = [np.eye(3), rz, np.eye(3)]
    mon = ImuSetMonitor(3, spec, 0.5, calibration=1.0, holdoff=1.0, rotations=rots, keep_log=False)
    n = 8
    fb = np.array([0.2, -0.1, -9.8])
    gyro = np.tile(np.stack([r @ OMEGA for r in rots]), (n, 1, 1))
    accel = np.tile(np.stack([r @ fb for r in rots]), (n, 1, 1))
    gyro[3, 1, 0] += 20.0 * sg
    accel[4, 0, 2] += 20.0 * sa
    t = 0.5 * np.arange(1, n + 1)
    g, a, events = mon.process(t, gyro, accel, np.full(n, 0.5), rates=True)
    got = [(e.t, e.event, e.sensor, e.imu, e.axis) for e in events]
    assert got == [(2.0, "detected", "gyro", None, ""), (2.0, "isolated", "gyro", 1, "x"),
                   (2.5, "detected", "accel", None, ""), (2.5, "isolated", "accel", 0, "z"),
                   (3.0, "recovered", "gyro", 1, "x"), (3.5, "recovered", "accel", 0, "z")]
    assert events[0].statistic == pytest.approx(200.0, rel=1e-9)
    assert events[2].statistic == pytest.approx(400.0 * 2.0 / 3.0 / 1.25, rel=1e-9)
    assert mon.gyro.statistics().shape == (0, 3)
    expect_g = np.tile(OMEGA, (n, 1))
    expect_g[3, 1] += 20.0 * sg / 3.0  # IMU 1's x is body y: a third of the fault in the revealing window
    expect_a = np.tile(fb, (n, 1))
    expect_a[4, 2] += 20.0 * sa / 3.0
    np.testing.assert_allclose(g, expect_g, rtol=0, atol=1e-15)
    np.testing.assert_allclose(a, expect_a, rtol=0, atol=1e-13)


def test_recovered_event_pairs_the_statistic_with_its_own_threshold() -> None:
    """FDI.csv's statistic and threshold are 'the test's values at that time' (docs/conventions.md):
    the test that saw sensor 0 agree ran on five sensors (2 dof, threshold -2 ln P_fa), so the
    'recovered' row must carry that threshold, as the log of the same test does."""
    mon = _monitor(SKEW)
    rates = _rates(SKEW, BIAS6, 9, {(6, 0): 80.0})
    t = DT * np.arange(1, 19)
    _, events = mon.process(t, rates * DT, np.full(18, DT))
    rec = [e for e in events if e.event == "recovered"]
    assert len(rec) == 1 and rec[0].t == t[17]
    assert mon.statistics()[-1, 2] == pytest.approx(THR2, rel=1e-10)
    assert rec[0].threshold == pytest.approx(THR2, rel=1e-10)
