"""Coning in a rotation INS, after [LAI12]: the strapdown against closed forms.

[LAI12] Lai, Lü, Zhang, Liu 2012, "Coning error analysis and compensation in
rotation INS" (references/rins-coning-error-paper.md). The motion is the
paper's eq. (2)/(4) in closed form (sim.rins); the strapdown
(mavins.core.runner.navigate) runs on its exact increments. Expected numbers
come from closed forms of sim.rins, not from the code under test; the
derivations and the full-length runs are in docs/rins.md
(scripts/rins_paper.py). Shorter runs here.

Conventions: error = estimate minus truth, phi = rotvec(q_est (x) q_true*) in
the reference frame; drift = yaw error / time. The paper's epsilon is truth
minus computed, so it enters negated.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core.rotation import quat_to_euler
from mavins.core.runner import navigate
from sim import rins
from support import quat_error

ALPHA = math.radians(2.0)
WC = 7.5 * 2.0 * math.pi
WR = math.radians(6.0)
T = 0.01
X = WC * T  # 0.47 rad
RHO = WR / WC


# --- helpers ---------------------------------------------------------------------


def qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.stack([
        p[..., 0] * q[..., 0] - p[..., 1] * q[..., 1] - p[..., 2] * q[..., 2] - p[..., 3] * q[..., 3],
        p[..., 0] * q[..., 1] + p[..., 1] * q[..., 0] + p[..., 2] * q[..., 3] - p[..., 3] * q[..., 2],
        p[..., 0] * q[..., 2] - p[..., 1] * q[..., 3] + p[..., 2] * q[..., 0] + p[..., 3] * q[..., 1],
        p[..., 0] * q[..., 3] + p[..., 1] * q[..., 2] - p[..., 2] * q[..., 1] + p[..., 3] * q[..., 0],
    ], axis=-1)


def conj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def run(n: int, turntable, duration: float, coning: bool = True, alpha: float = ALPHA):
    """navigate() on the paper's motion; update times and reference-frame error rows (rad)."""
    h = T / n
    m = rins.paper_motion(alpha, WC, turntable, h, int(round(duration / h)))
    q0 = rins.quaternion(np.array([0.0]), alpha, WC, turntable)[0]
    e = np.degrees(quat_to_euler(q0))
    init = dict(t=0.0, lat=0.0, lon=0.0, h=0.0, vn=0.0, ve=0.0, vd=0.0, roll=e[0], pitch=e[1], yaw=e[2])
    sol = navigate(m.t, m.dtheta, m.dv, init, samples=n, earth_model="none", coning=coning)
    q_true = m.q[n - 1 :: n]
    assert len(sol) == len(q_true) and sol[-1, 0] == pytest.approx(m.t[-1])
    return sol[:, 0], quat_error(sol[:, 10:14], q_true)


def drift(t: np.ndarray, phi: np.ndarray) -> float:
    return float(phi[-1, 2] / t[-1])


def tolerance(n: int, wr: float, duration: float, coning: bool = True) -> float:
    """How far a run may sit from the exact one-update drift (rad/s).

    Every update adds the same z rotation u_z plus x/y parts that turn by
    Omega T per update; composing them adds at most |u_xy|^2 / (4 tan(Omega T/2))
    of z per update (second-order product of the bounded x/y sums), and the
    quaternion arithmetic a round-off of ~1e-16 rad per update.
    """
    u = rins.update_error(n, ALPHA, WC, wr, T, coning)
    omega = WC + wr
    comp = (u[0] ** 2 + u[1] ** 2) / (4.0 * math.tan(omega * T / 2.0)) / T
    roundoff = 1e-16 * math.sqrt(duration / T) / duration + 1e-16 / T
    return 1e-9 * abs(u[2] / T) + 2.0 * comp + 10.0 * roundoff


# --- the model ---------------------------------------------------------------------


def test_eq2_is_cone_times_turntable_and_eq4_is_its_body_rate():
    t = np.array([0.013, 0.77, 3.3, 41.0])
    q = rins.quaternion(t, ALPHA, WC, WR)
    ca, sa = math.cos(ALPHA / 2), math.sin(ALPHA / 2)
    for ti, qi in zip(t, q):
        ph = (WR + WC) * ti
        q2 = np.array([ca, sa * math.cos(ph), sa * math.sin(ph), 0.0])
        q1 = np.array([math.cos(WR * ti / 2), 0.0, 0.0, math.sin(WR * ti / 2)])
        assert np.allclose(qmul(q2, q1), qi, rtol=0, atol=1e-12)  # phases ~2e3 rad carry ~4e-13
    # w = 2 Q* dQ/dt (central difference, error ~ (W eps)^2 W)
    eps = 1e-5
    qd = (rins.quaternion(t + eps, ALPHA, WC, WR) - rins.quaternion(t - eps, ALPHA, WC, WR)) / (2 * eps)
    w = 2.0 * qmul(conj(q), qd)[:, 1:]
    assert np.allclose(w, rins.body_rate(t, ALPHA, WC, WR), rtol=0, atol=1e-7)
    # eq. (4) z: wr cos(alpha) - 2 wc sin^2(alpha/2)
    assert rins.body_rate(t, ALPHA, WC, WR)[0, 2] == pytest.approx(WR * math.cos(ALPHA) - 2 * WC * sa**2, rel=1e-15)


def test_eq6_is_the_relative_quaternion():
    t0 = 0.4321
    q = qmul(conj(rins.quaternion(np.array([t0]), ALPHA, WC, WR)[0]), rins.quaternion(np.array([t0 + T]), ALPHA, WC, WR)[0])
    ca2, sa2 = math.cos(ALPHA / 2) ** 2, math.sin(ALPHA / 2) ** 2
    s = math.sin((WR + WC) * T / 2) * math.sin(ALPHA)
    eq6 = [ca2 * math.cos(WR * T / 2) + sa2 * math.cos(WR * T / 2 + WC * T),
           -s * math.sin(WC * t0 + WC * T / 2), s * math.cos(WC * t0 + WC * T / 2),
           ca2 * math.sin(WR * T / 2) - sa2 * math.sin(WR * T / 2 + WC * T)]
    assert np.allclose(q, eq6, rtol=0, atol=1e-15)


@pytest.mark.parametrize("which", ["constant", "stop_and_go"])
def test_increments_integrate_eq4(which):
    """Closed-form increments against Gauss-Legendre quadrature of eq. (4), across a start and a stop."""
    sched = WR if which == "constant" else rins.stop_and_go([0, 90, 180, 270], 6.0, 10.0, 100.0)
    intervals = [(9.995, 10.0), (9.998, 10.001), (10.0, 10.004), (24.997, 25.003), (50.001, 50.004), (3.0, 3.01)]
    nodes, weights = np.polynomial.legendre.leggauss(16)
    for a, b in intervals:
        dth = rins.increments(np.array([a, b]), ALPHA, WC, sched)[0]
        cuts = [a] + [c for c in (10.0, 25.0) if a < c < b] + [b]  # the turntable switches at 10 and 25 s
        num = np.zeros(3)
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            x = 0.5 * (hi - lo) * nodes + 0.5 * (hi + lo)
            num += 0.5 * (hi - lo) * weights @ rins.body_rate(x, ALPHA, WC, sched)
        # 16-point quadrature of a smooth piece with W (hi - lo) <= 0.5 is exact to round-off;
        # the phases wc t ~ 2e3 rad carry ~1e-13 rad, times sin(alpha)
        assert np.allclose(dth, num, rtol=0, atol=1e-14), (a, b)
    if which == "constant":
        # the paper's eq. (9): (wc + wr)/wc sin(alpha) [cos wc t]
        a, b = intervals[0]
        dth = rins.increments(np.array([a, b]), ALPHA, WC, sched)[0]
        assert dth[0] == pytest.approx((WC + WR) / WC * math.sin(ALPHA) * (math.cos(WC * b) - math.cos(WC * a)), rel=1e-12)


def test_stop_and_go_schedule():
    s = rins.stop_and_go([0, 90, 180, 270], 6.0, 100.0, 3600.0)
    moves = [(np.degrees(s.angles[k]), np.degrees(s.angles[k + 1])) for k in range(len(s.rates) - 1) if s.rates[k] != 0]
    assert [round(b) for _, b in moves[:8]] == [90, 180, 270, 180, 90, 0, 90, 180]
    assert s.starts[1] == 100.0 and s.starts[2] == pytest.approx(115.0)
    assert np.degrees(s.angle(np.array([107.5])))[0] == pytest.approx(45.0)


# --- figures 1 and 2: uncompensated and 3-sample, turntable at +6 deg/s ------------------------


def test_uncompensated_drift_follows_closed_form():
    duration = 20.0
    t, phi = run(3, WR, duration, coning=False)
    measured = drift(t, phi)
    exact = rins.update_error(3, ALPHA, WC, WR, T, coning=False)[2] / T
    assert abs(measured - exact) < tolerance(3, WR, duration, coning=False)
    # leading order: classic -s^2/2 (wcT - sin wcT) with s = sin(alpha), plus the rotation term
    # -alpha^2 (wr T)(wc T)^2 / 12; neglected terms are O(alpha^2) and O(rho (wcT)^2) relative
    series = (rins.coning_residual(1, math.sin(ALPHA), WC, T) + rins.rotation_residual(1, ALPHA, WC, WR, T)) / T
    assert measured == pytest.approx(series, rel=ALPHA**2)
    assert measured * math.degrees(3600.0) == pytest.approx(-217.15, abs=0.01)


def test_uncompensated_rotation_dependence_is_two_thirds_of_eq12():
    """Eq. (12) (through lambda_1) moves by -alpha^2 (wrT)(wcT)^2/8 per update; the runs by /12."""
    plus = drift(*run(3, WR, 10.0, coning=False))
    minus = drift(*run(3, -WR, 10.0, coning=False))
    odd = (plus - minus) / 2 * T
    assert odd == pytest.approx(-(ALPHA**2) * (WR * T) * X**2 / 12, rel=X**2 / 5 + ALPHA**2)

    def eq12(wr):  # truth minus raw sum, negated
        x = wr * T / 2 + WC * T
        ca2, sa2 = math.cos(ALPHA / 2) ** 2, math.sin(ALPHA / 2) ** 2
        return -(2 * ca2 * (math.sin(wr * T / 2) - wr * T / 2) - 2 * sa2 * (math.sin(x) - x))

    assert (eq12(WR) - eq12(-WR)) / 2 / odd == pytest.approx(1.5, rel=X**2)


def test_three_sample_compensation_cuts_the_error():
    t, phi = run(3, WR, 20.0, coning=True)
    measured = drift(t, phi)
    assert abs(measured - rins.update_error(3, ALPHA, WC, WR, T)[2] / T) < tolerance(3, WR, 20.0)
    uncompensated = rins.update_error(3, ALPHA, WC, WR, T, coning=False)[2] / T
    assert abs(measured) < 1e-4 * abs(uncompensated)
    # x/y errors stay bounded: sums of u_xy turned by Omega T each update, |sum| <= |u_xy| / sin(Omega T/2)
    u = rins.update_error(3, ALPHA, WC, WR, T)
    bound = math.hypot(u[0], u[1]) / math.sin((WC + WR) * T / 2)
    assert np.max(np.hypot(phi[:, 0], phi[:, 1])) < bound * (1 + 1e-3) + 1e-13


def test_pure_rotation_is_exact():
    """With no coning (alpha = 0) the update is exact: eq. (18)'s -(wr T)^3/24 is not a drift."""
    t, phi = run(3, WR, 20.0, coning=True, alpha=0.0)
    assert np.max(np.abs(phi)) < 1e-13
    assert abs(rins.eq18_terms(3, 0.0, WC, WR, T)[0]) / T * 20.0 > 1e4 * 1e-13


# --- figure 3: residual against N ---------------------------------------------------------------

DUR3 = 10.0


@pytest.fixture(scope="module")
def residuals() -> dict:
    out = {}
    for n in range(2, 7):
        for wr in (WR, 0.0, -WR):
            out[(n, wr)] = drift(*run(n, wr, DUR3))
    return out


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_residual_is_the_exact_one_update_error(residuals, n):
    for wr in (WR, 0.0, -WR):
        exact = rins.update_error(n, ALPHA, WC, wr, T)[2] / T
        assert abs(residuals[(n, wr)] - exact) < tolerance(n, wr, DUR3), (n, wr)


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_rotation_part_follows_r_n(residuals, n):
    """The part odd in wr is r_N alpha^2 (wr T)(wc T)^4 per update, not eq. (18)'s alpha^2 (wr T)(wc T)^2/24."""
    odd = (residuals[(n, WR)] - residuals[(n, -WR)]) / 2
    lead = rins.rotation_residual(n, ALPHA, WC, WR, T) / T
    nxt = float(rins.ROTATION_NEXT[n]) * ALPHA**2 * (WR * T) * X**6 / T
    # next order known; the rest (alpha^2 and (wc T)^4 relative) within the same size again
    assert abs(odd - (lead + nxt)) < abs(nxt) + ALPHA**2 * abs(lead)
    paper_term2 = -rins.eq18_terms(n, ALPHA, WC, WR, T)[1] / T  # negated: estimate minus truth
    assert 0 < odd < paper_term2 / 25


def test_residual_stops_improving_beyond_three_samples(residuals):
    rot = [abs(residuals[(n, WR)]) for n in range(2, 7)]
    assert rot[1] < rot[0] / 50  # N = 2 -> 3: large gain
    assert max(rot[1:]) < 1.5 * min(rot[1:])  # N = 3..6: no gain, the rotation term dominates
    # the floor is the rotation: it changes sign with the turntable direction
    for n in range(3, 7):
        assert residuals[(n, WR)] > 0 > residuals[(n, -WR)]
        assert abs(residuals[(n, 0.0)]) < abs(residuals[(n, WR)]) / 5


@pytest.mark.parametrize("n", [2, 3])
def test_fixed_imu_matches_eq18_coning_term_with_h(residuals, n):
    """Eq. (18)'s third term is the fixed-IMU residual when evaluated with h = T/N, not T."""
    measured = residuals[(n, 0.0)]
    classic = rins.coning_residual(n, math.sin(ALPHA), WC, T) / T  # second order, exact in wc T
    # beyond it: terms of order alpha^4 (wc T)^5 per update, coefficients 1/1440 (N = 2) and
    # 1/12960 (N = 3), with next-order terms up to 4 (wc T)^2 times those (series of the one-update error)
    a4 = {2: 1 / 1440, 3: 1 / 12960}[n] * ALPHA**4 * X**5 / T
    assert abs(measured - classic) < a4 * (1 + 4 * X**2)
    with_h = -rins.eq18_terms(n, ALPHA, WC, 0.0, T, "h")[2] / T
    lam = X / n  # eq. (18)'s term is the leading order in lambda = wc h
    assert measured == pytest.approx(with_h, rel=lam**2)
    as_printed = -rins.eq18_terms(n, ALPHA, WC, 0.0, T, "T")[2] / T
    assert as_printed / with_h == pytest.approx(n ** (2 * n + 1), rel=1e-12)


# --- figure 4: stop-and-go ----------------------------------------------------------------------


@pytest.mark.parametrize("coning", [True, False], ids=["3-sample", "uncompensated"])
def test_stop_and_go_cancels_and_stops_behave_like_a_fixed_imu(coning):
    """Dwell 10 s instead of the paper's 100 s: two full cycles (6 moves of 15 s each) in 300 s."""
    dwell, cycle = 10.0, 6 * (10.0 + 15.0)
    sched = rins.stop_and_go([0, 90, 180, 270], 6.0, dwell, 2 * cycle + 5.0)
    t, phi = run(3, sched, 2 * cycle + 5.0, coning)
    t0, phi0 = run(3, 0.0, 2 * cycle + 5.0, coning)
    d = phi[:, 2] - phi0[:, 2]  # rotation-induced yaw error

    def at(x):
        return float(np.interp(x, t, d))

    d_plus = (rins.update_error(3, ALPHA, WC, WR, T, coning)[2] - rins.update_error(3, ALPHA, WC, 0.0, T, coning)[2]) / T * 15.0
    d_minus = (rins.update_error(3, ALPHA, WC, -WR, T, coning)[2] - rins.update_error(3, ALPHA, WC, 0.0, T, coning)[2]) / T * 15.0
    # the x/y parts of the error are bounded; they shift the z sums by their second-order products
    u = rins.update_error(3, ALPHA, WC, WR, T, coning)
    slack = 1e-3 * abs(d_plus) + 1e3 * (u[0] ** 2 + u[1] ** 2) + 1e-13
    changes = []
    for k in range(len(sched.starts) - 1):
        a, b = sched.starts[k], sched.starts[k + 1]
        if sched.rates[k] != 0.0:
            expected = d_plus if sched.rates[k] > 0 else d_minus
            assert at(b) - at(a) == pytest.approx(expected, abs=slack)
            changes.append(at(b) - at(a))
        else:
            # stops: the rotation-induced error stays where it is (a fixed IMU's drift only)
            sel = (t >= a) & (t <= b)
            assert np.ptp(d[sel]) < slack
            sel = (t > a + 0.5) & (t < b - 0.5)
            rate, rate0 = np.polyfit(t[sel], phi[sel, 2], 1)[0], np.polyfit(t[sel], phi0[sel, 2], 1)[0]
            assert rate == pytest.approx(rate0, rel=1e-6, abs=slack / dwell)
    assert len(changes) == 12
    # opposite directions: opposite signs, nearly equal size
    assert d_plus * d_minus < 0 and abs(d_plus + d_minus) < 0.05 * abs(d_plus)
    # end of each full cycle: only the part even in wr is left, much less than one move's growth
    for c in (1, 2):
        end = at(c * cycle)
        assert end == pytest.approx(3 * c * (d_plus + d_minus), abs=c * slack)
        assert abs(end) < 0.05 * abs(d_plus)
