"""The strapdown core against closed-form motion, with tolerances from theory.

Every expected number here is computed from an analytic expression that does
not use the code under test; the algorithm is *run* on exact increments.
Derivations are in docs/validation.md.
"""

from __future__ import annotations

import numpy as np
import pytest

from mavins.core import earth
from mavins.core.coning import CONING_COEFFS
from mavins.core.rotation import quat_to_euler
from mavins.core.runner import navigate
from sim import motion
from support import quat_angle

DEG_H = np.degrees(1.0) * 3600.0  # rad/s -> deg/h


def init_from(q: np.ndarray, lat: float = 0.0, lon: float = 0.0, h: float = 0.0, v=(0.0, 0.0, 0.0)) -> dict:
    e = np.degrees(quat_to_euler(q))
    return dict(t=0.0, lat=lat, lon=lon, h=h, vn=v[0], ve=v[1], vd=v[2], roll=e[0], pitch=e[1], yaw=e[2])


def final_angle(sol: np.ndarray, q_true: np.ndarray) -> float:
    return float(quat_angle(q_true, sol[-1, 10:14]))


def drift_slope(sol: np.ndarray, q_true: np.ndarray) -> float:
    """Error growth rate (rad/s) between the middle and the end of a run.

    A slope cancels any constant error, such as the angle bias of reading a
    quaternion out of a DCM that keeps a small steady scale defect.
    """
    k = len(sol) // 2
    e_mid = quat_angle(q_true[k], sol[k, 10:14])
    e_end = quat_angle(q_true[-1], sol[-1, 10:14])
    return (e_end - e_mid) / (sol[-1, 0] - sol[k, 0])


# --- Tables 11.1 / 11.2: truncated attitude updates under constant rate --------

DCM_A = {1: lambda s: (1.0, 0.0), 2: lambda s: (1.0, 0.5), 3: lambda s: (1 - s * s / 6, 0.5), 4: lambda s: (1 - s * s / 6, 0.5 - s * s / 24)}
QUAT_A = {
    1: lambda s: (1.0, 0.5),
    2: lambda s: (1 - s * s / 8, 0.5),
    3: lambda s: (1 - s * s / 8, 0.5 - s * s / 48),
    4: lambda s: (1 - s * s / 8 + s**4 / 384, 0.5 - s * s / 48),
}


def dcm_exact_drift(order: int, s: float, dt: float) -> float:
    """Rotation per step of A = I + a1[s x] + a2[s x]^2 after orthonormalisation, minus s.

    In the plane normal to sigma, A acts as the complex number (1 - a2 s^2) + i a1 s;
    the orthonormalisation step z(1 - (|z|^2 - 1)/2) keeps its argument.
    """
    a1, a2 = DCM_A[order](s)
    return (np.arctan2(a1 * s, 1 - a2 * s * s) - s) / dt


def dcm_textbook_drift(order: int, s: float, dt: float) -> float:
    """[TW11] eq. 11.1 skew coefficient: (s a1 cos s - sin s + s^2 a2 sin s)/dt (first order)."""
    a1, a2 = DCM_A[order](s)
    return (s * a1 * np.cos(s) - np.sin(s) + s * s * a2 * np.sin(s)) / dt


def quat_exact_drift(order: int, s: float, dt: float) -> float:
    """Rotation angle of the normalised r = [ac, as sigma], minus s, per step."""
    ac, as_ = QUAT_A[order](s)
    return (2 * np.arctan2(as_ * s, ac) - s) / dt


@pytest.mark.parametrize("sigma,dt", [(0.1, 0.01), (0.05, 0.005)])
@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_dcm_table_11_1(order, sigma, dt):
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    n = 400
    m = motion.constant_rate(axis * sigma / dt, dt, n)
    sol = navigate(m.t, m.dtheta, m.dv, init_from(np.array([1.0, 0, 0, 0])), samples=1, attitude="dcm",
                   order=str(order), earth_model="none", orthonormalize_every=1)
    measured = drift_slope(sol, m.q)
    exact = abs(dcm_exact_drift(order, sigma, dt))
    textbook = abs(dcm_textbook_drift(order, sigma, dt))
    # The run reproduces the algorithm's own drift. After orthonormalisation the
    # DCM keeps an in-plane scale defect |r - 1| ~ (|A z|^2 - 1)^2 ~ (a1^2 s^2 +
    # (1 - a2 s^2)^2 - 1)^2; reading a quaternion out of it biases each reading
    # by at most about that much, hence the readout term over the slope window.
    a1, a2 = DCM_A[order](sigma)
    defect = (a1**2 * sigma**2 + (1 - a2 * sigma**2) ** 2 - 1) ** 2
    window = sol[-1, 0] - sol[len(sol) // 2, 0]
    assert abs(measured - exact) <= 1e-6 * exact + 2 * defect / window
    # ... and the textbook's first-order expression up to its neglected O(s^2) terms
    assert measured == pytest.approx(textbook, rel=sigma**2)


@pytest.mark.parametrize("sigma,dt", [(0.1, 0.01), (0.05, 0.005)])
@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_quaternion_table_11_2(order, sigma, dt):
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    n = 400
    m = motion.constant_rate(axis * sigma / dt, dt, n)
    sol = navigate(m.t, m.dtheta, m.dv, init_from(np.array([1.0, 0, 0, 0])), samples=1,
                   attitude="quaternion", order=str(order), earth_model="none")
    measured = final_angle(sol, m.q[-1]) / m.t[-1]
    assert measured == pytest.approx(abs(quat_exact_drift(order, sigma, dt)), rel=1e-6)


def test_quaternion_table_disagrees_with_its_formula():
    """The lecture's table 11.2 prints 0.4 / 0.2 deg/h (orders 3 / 4, sigma 0.1);
    the algorithm, run, gives the closed form's 0.43 / 0.107 (references/README)."""
    d3 = abs(quat_exact_drift(3, 0.1, 0.01)) * DEG_H
    d4 = abs(quat_exact_drift(4, 0.1, 0.01)) * DEG_H
    assert d3 == pytest.approx(0.43, abs=0.005)
    assert d4 == pytest.approx(0.107, abs=0.001)


def test_exact_order_has_no_drift():
    m = motion.constant_rate(np.array([3.0, -7.0, 5.0]), 0.01, 1000)
    for att in ("quaternion", "dcm"):
        sol = navigate(m.t, m.dtheta, m.dv, init_from(np.array([1.0, 0, 0, 0])), samples=1, attitude=att,
                       order="exact", earth_model="none")
        assert final_angle(sol, m.q[-1]) < 1e-12


# --- Coning ---------------------------------------------------------------------


def coning_theory(n_samples: int, w: float, T: float, sin_beta: float) -> float:
    """Mean drift (rad/s) of the N-sample algorithm under classic coning.

    With h = T/N and lambda = W h: (dtheta_i x dtheta_j)_z = 4 s^2 sin^2(lambda/2)
    sin((j-i) lambda); the exact coning per update is s^2/2 (W T - sin W T)
    ([TW11] 11.2.3). Error = algorithm term - exact term, per second.
    """
    lam = w * T / n_samples
    s2 = sin_beta**2
    alg = 0.0
    for i in range(n_samples - 1):
        alg += CONING_COEFFS[n_samples, i] * np.sin((n_samples - 1 - i) * lam)
    alg *= 4 * s2 * np.sin(lam / 2) ** 2
    exact = 0.5 * s2 * (w * T - np.sin(w * T))
    return abs(alg - exact) / T


SIN_BETA = np.radians(0.1)  # 0.1 deg rate amplitude on x and y, 90 deg phase
BETA = np.arcsin(SIN_BETA)
W50 = 2 * np.pi * 50.0


def run_coning(n_samples: int, T: float, duration: float, coning: bool = True) -> float:
    dt = T / n_samples
    m = motion.classic_coning(BETA, 50.0, dt, int(round(duration / dt)))
    sol = navigate(m.t, m.dtheta, m.dv, init_from(m.q[0] * 0 + np.array([np.cos(BETA / 2), np.sin(BETA / 2), 0, 0])),
                   samples=n_samples, earth_model="none", coning=coning)
    assert sol[-1, 0] == pytest.approx(m.t[-1])
    return final_angle(sol, m.q[-1]) / m.t[-1]


def test_textbook_coning_example_uncompensated():
    """[TW11] 11.2.3 example: ~100 deg/h at 100 Hz, ~6 deg/h at 500 Hz."""
    d100 = run_coning(1, 0.01, 2.0) * DEG_H
    d500 = run_coning(1, 0.002, 2.0) * DEG_H
    # closed form (W s^2/2)(1 - sin WT / WT); neglected terms are O(s^2) relative
    assert d100 == pytest.approx(coning_theory(1, W50, 0.01, SIN_BETA) * DEG_H, rel=1e-4)
    assert d500 == pytest.approx(coning_theory(1, W50, 0.002, SIN_BETA) * DEG_H, rel=1e-4)
    assert d100 == pytest.approx(98.7, abs=0.05)
    assert d500 == pytest.approx(6.37, abs=0.01)


# Absolute floor of the first-order theory: neglected s^4 W terms (rad/s).
S4_FLOOR = 10 * SIN_BETA**4 * W50


@pytest.mark.parametrize("n_samples", [2, 3, 4])
def test_coning_residual_textbook_rate(n_samples):
    measured = run_coning(n_samples, 0.01, 2.0)
    theory = coning_theory(n_samples, W50, 0.01, SIN_BETA)
    assert abs(measured - theory) < 1e-4 * theory + S4_FLOOR


@pytest.mark.parametrize("n_samples", [2, 3, 4, 5, 6])
def test_coning_residual_follows_theory(n_samples):
    """At W T = 3 pi every N's residual stands far above the s^4 floor."""
    T = 0.03
    measured = run_coning(n_samples, T, 3.0)
    theory = coning_theory(n_samples, W50, T, SIN_BETA)
    assert theory > 100 * S4_FLOOR
    assert abs(measured - theory) < 1e-4 * theory + S4_FLOOR
    if n_samples > 2:
        assert measured < run_coning(n_samples - 1, T, 3.0)


def test_no_coning_flag_matches_single_sample_error():
    """--no-coning with N samples integrates like N=1 updates of the summed angle."""
    with_flag = run_coning(4, 0.01, 2.0, coning=False)
    assert with_flag == pytest.approx(coning_theory(1, W50, 0.01, SIN_BETA), rel=1e-3)


# --- Sculling -------------------------------------------------------------------


def sculling_theory(n_samples: int, w: float, T: float, theta: float, accel: float) -> float:
    """Mean velocity drift error (m/s^2) along D: by sculling/coning duality
    (Ignagni 1998) the N-sample residual has the coning form with s^2 W/2 -> A theta/2."""
    return coning_theory(n_samples, w, T, 1.0) / (w / 2) * accel * theta / 2


@pytest.mark.parametrize("n_samples", [1, 2, 3, 4])
def test_sculling_drift_follows_theory(n_samples):
    theta, accel, f, T = 1e-3, 2.0, 50.0, 0.01
    dt = T / n_samples
    m = motion.classic_sculling(theta, accel, f, dt, int(round(2.0 / dt)))
    sol = navigate(m.t, m.dtheta, m.dv, init_from(np.array([1.0, 0, 0, 0])), samples=n_samples, earth_model="none")
    g0 = earth.gravity(0.0, 0.0)
    t_end = m.t[-1]
    v_true = m.v[-1] + np.array([0.0, 0.0, g0 * t_end])
    err_rate = (sol[-1, 4:7] - v_true) / t_end
    theory = sculling_theory(n_samples, 2 * np.pi * f, T, theta, accel)
    # O(theta^2) relative corrections plus the rectified drift's own scale as floor
    assert abs(abs(err_rate[2]) - theory) < 1e-3 * theory + 10 * theta**3 * accel
    assert abs(err_rate[0]) < 1e-12 and abs(err_rate[1]) < 10 * theta**2 * accel


# --- Stationary on the rotating Earth and Schuler ---------------------------------


def test_stationary_one_hour_rotating_earth():
    lat, lon, h = 45.0, 10.0, 100.0
    m = motion.stationary(lat, h, 2.0, -3.0, 30.0, 0.01, 360_000)
    sol = navigate(m.t, m.dtheta, m.dv, dict(t=0.0, lat=lat, lon=lon, h=h, vn=0.0, ve=0.0, vd=0.0,
                                             roll=2.0, pitch=-3.0, yaw=30.0))
    r_n, r_e = earth.radii(np.radians(lat))
    dn = np.radians(sol[:, 1] - lat) * (r_n + h)
    de = np.radians(sol[:, 2] - lon) * (r_e + h) * np.cos(np.radians(lat))
    assert np.max(np.hypot(dn, de)) < 1e-3
    assert np.max(np.abs(sol[:, 3] - h)) < 1e-2
    att = quat_angle(m.q[0], sol[::1000, 10:14]).max()
    assert np.degrees(att) < 1e-7


def test_schuler_oscillation_period():
    """A 1 m/s north velocity error oscillates with 2 pi sqrt(R/g) (84.4 min)."""
    lat, h = 45.0, 0.0
    dt = 0.1
    n = int(3 * 5100 / dt)
    m = motion.stationary(lat, h, 0.0, 0.0, 0.0, dt, n)
    sol = navigate(m.t, m.dtheta, m.dv, dict(t=0.0, lat=lat, lon=0.0, h=h, vn=1.0, ve=0.0, vd=0.0,
                                             roll=0.0, pitch=0.0, yaw=0.0), vertical="hold")
    vn = sol[:, 4]
    t = sol[:, 0]
    up = np.flatnonzero((vn[:-1] < 0) & (vn[1:] >= 0))
    crossings = t[up] - vn[up] * (t[up + 1] - t[up]) / (vn[up + 1] - vn[up])
    assert len(crossings) >= 2
    period = np.mean(np.diff(crossings))
    expected = earth.schuler_period(np.radians(lat), h)
    assert period == pytest.approx(expected, rel=0.01)
    assert np.max(np.abs(vn)) == pytest.approx(1.0, rel=0.02)
