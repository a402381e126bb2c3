"""The yaw estimator from GNSS velocity (mavins/core/yawgsf.py) against closed forms worked here.

Prediction: the levelled increment turned by the model's mid-interval yaw; F P F^T + Q with
F = I + g e_3^T, g = (-dv_E, dv_N, 0), written out by hand below. Update: the two-dimensional
Kalman update (D. Simon, *Optimal State Estimation*, 2006, eqs. 5.19) and the Gaussian-sum
re-weighting ``w_i N(nu_i; 0, S_i)`` (Alspach and Sorenson 1972, eq. 17). Estimate: the weighted
circular mean and the mixture variance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import yawgsf


def one(psi: float, p: np.ndarray | None = None, v=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    X = np.array([[v[0], v[1], psi]])
    P = np.array([np.eye(3) if p is None else p], dtype=float)
    return X, P, np.zeros(1)


def test_a_bank_starts_evenly_around_the_circle_with_equal_weights() -> None:
    """N = 5: yaws -144, -72, 0, 72, 144 deg, yaw 1-sigma half the 72 deg spacing, velocity 1-sigma
    SIGMA_VEL0, no correlation, weights 1/5."""
    X, P, logw = yawgsf.make(1.5, -2.0)
    assert X.shape == (5, 3) and P.shape == (5, 3, 3) and logw.shape == (5,)
    np.testing.assert_allclose(np.degrees(X[:, 2]), [-144.0, -72.0, 0.0, 72.0, 144.0], atol=1e-12)
    np.testing.assert_allclose(X[:, :2], [[1.5, -2.0]] * 5)
    v0 = yawgsf.SIGMA_VEL0 ** 2
    for Pi in P:
        np.testing.assert_allclose(Pi, np.diag([v0, v0, math.radians(36.0) ** 2]), rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.exp(logw), 0.2, rtol=1e-12)


def rx(a: float) -> np.ndarray:
    return np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)], [0.0, math.sin(a), math.cos(a)]])


def ry(a: float) -> np.ndarray:
    return np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])


def test_predict_with_roll_pitch_and_a_correlated_covariance() -> None:
    """Roll 0.3, pitch -0.2 rad (C_b^n with yaw 0 = Ry(pitch) Rx(roll), the contract's rotation), body
    increments dv = (1, 0.5, -2) m/s, dtheta = (0.1, -0.2, 0.3) rad, a model at 0.7 rad moving (2, -1) m/s
    with a full covariance: velocity += Rz(psi + dpsi/2) u[:2], yaw += dpsi, P <- F P F^T + Q, all
    computed here with numpy from the rotation matrices."""
    roll, pitch, T, w_in_d = 0.3, -0.2, 0.05, -4e-5
    dv, dth = np.array([1.0, 0.5, -2.0]), np.array([0.1, -0.2, 0.3])
    p = np.array([[0.5, 0.1, 0.05], [0.1, 0.4, -0.02], [0.05, -0.02, 0.3]])
    X, P, _ = one(0.7, p, v=(2.0, -1.0))
    yawgsf.predict(X, P, dv, dth, roll, pitch, w_in_d, T)
    u = ry(pitch) @ rx(roll) @ dv
    dpsi = (ry(pitch) @ rx(roll) @ dth)[2] - w_in_d * T
    m = 0.7 + dpsi / 2
    dn, de = math.cos(m) * u[0] - math.sin(m) * u[1], math.sin(m) * u[0] + math.cos(m) * u[1]
    np.testing.assert_allclose(X[0], [2.0 + dn, -1.0 + de, 0.7 + dpsi], atol=1e-12)
    F = np.array([[1.0, 0.0, -de], [0.0, 1.0, dn], [0.0, 0.0, 1.0]])
    q = np.diag([yawgsf.SIGMA_ACC ** 2 * T] * 2 + [yawgsf.SIGMA_YAW_RATE ** 2 * T + (yawgsf.SCALE_YAW * dpsi) ** 2])
    np.testing.assert_allclose(P[0], F @ p @ F.T + q, atol=1e-12)


@pytest.mark.parametrize("psi_deg", [0.0, 30.0, -120.0])
def test_predict_turns_the_levelled_increment_by_the_models_yaw(psi_deg: float) -> None:
    """Level, dv_b = (1, 0.5, -9.8 T) m/s (gravity's reaction does not reach the horizontal), a yaw
    increment of 0.2 rad about the body's z: the velocity grows by the forward/right increment turned by
    psi + 0.1 (mid-interval), the yaw by 0.2 less w_in,D T."""
    psi = math.radians(psi_deg)
    X, P, _ = one(psi)
    T, w_in_d = 0.5, -5e-5
    yawgsf.predict(X, P, np.array([1.0, 0.5, -9.8 * T]), np.array([0.0, 0.0, 0.2]), 0.0, 0.0, w_in_d, T)
    m = psi + 0.1 - 0.5 * w_in_d * T
    dn, de = math.cos(m) - 0.5 * math.sin(m), math.sin(m) + 0.5 * math.cos(m)
    np.testing.assert_allclose(X[0, :2], [dn, de], atol=1e-12)
    assert X[0, 2] == pytest.approx(math.remainder(psi + 0.2 - w_in_d * T, 2 * math.pi), abs=1e-12)
    # F P F^T + Q with P = I: F = [[1, 0, -de], [0, 1, dn], [0, 0, 1]]
    F = np.array([[1.0, 0.0, -de], [0.0, 1.0, dn], [0.0, 0.0, 1.0]])
    q = np.diag([yawgsf.SIGMA_ACC ** 2 * T] * 2 + [yawgsf.SIGMA_YAW_RATE ** 2 * T + (yawgsf.SCALE_YAW * (0.2 - w_in_d * T)) ** 2])
    np.testing.assert_allclose(P[0], F @ F.T + q, atol=1e-12)


def test_predict_levels_with_roll_and_pitch() -> None:
    """Rolled 90 deg, C_b^n = Rx(90) takes z_b to (0, -sin 90, cos 90) = west and y_b to (0, 0, 1) = down:
    a body increment (0, 0, 1) m/s is 1 m/s west, a rotation about z_b no yaw at all, one about y_b yaw."""
    X, P, _ = one(0.0)
    yawgsf.predict(X, P, np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.3]), math.pi / 2, 0.0, 0.0, 0.1)
    np.testing.assert_allclose(X[0], [0.0, -1.0, 0.0], atol=1e-12)
    X, P, _ = one(0.0)
    yawgsf.predict(X, P, np.zeros(3), np.array([0.0, 0.3, 0.0]), math.pi / 2, 0.0, 0.0, 0.1)
    assert X[0, 2] == pytest.approx(0.3, abs=1e-12)


def test_update_is_the_two_dimensional_kalman_update() -> None:
    """P = [[4, 1, 2], [1, 9, -3], [2, -3, 5]], sigma = 0.5: S = P_vv + 0.25 I, K = P[:, :2] S^-1, x - K nu
    (nu = (0.5, -2)), P - K S K^T (numbers from numpy's own algebra on the typed matrices)."""
    p = np.array([[4.0, 1.0, 2.0], [1.0, 9.0, -3.0], [2.0, -3.0, 5.0]])
    X, P, logw = one(0.4, p, v=(1.0, 2.0))
    yawgsf.update(X, P, logw, 0.5, 4.0, 0.5)
    S = p[:2, :2] + 0.25 * np.eye(2)
    K = p[:, :2] @ np.linalg.inv(S)
    nu = np.array([0.5, -2.0])
    np.testing.assert_allclose(X[0], np.array([1.0, 2.0, 0.4]) - K @ nu, atol=1e-12)
    np.testing.assert_allclose(P[0], p - K @ S @ K.T, atol=1e-12)
    assert logw[0] == 0.0  # one model: normalised to weight 1


def test_weights_take_the_full_mahalanobis_distance_and_the_prior() -> None:
    """Two models, prior weights 0.8 / 0.2, correlated velocity covariances, sigma 0.5: each new weight is
    prior x N(nu; 0, S) normalised, N the bivariate normal density written out here."""
    X = np.array([[1.0, -0.5, 0.0], [-0.7, 1.2, 1.0]])
    P = np.array([[[2.0, 0.6, 0.1], [0.6, 1.0, 0.0], [0.1, 0.0, 0.5]],
                  [[1.5, -0.4, 0.0], [-0.4, 3.0, 0.2], [0.0, 0.2, 0.5]]])
    prior = np.array([0.8, 0.2])
    logw = np.log(prior)
    dens = []
    for i in range(2):
        S = P[i, :2, :2] + 0.25 * np.eye(2)
        nu = X[i, :2] - np.array([0.3, 0.4])
        dens.append(math.exp(-0.5 * nu @ np.linalg.solve(S, nu)) / (2 * math.pi * math.sqrt(np.linalg.det(S))))
    yawgsf.update(X, P, logw, 0.3, 0.4, 0.5)
    want = prior * np.array(dens)
    np.testing.assert_allclose(np.exp(logw), want / want.sum(), rtol=1e-12)


def test_weights_follow_the_likelihood_of_each_innovation() -> None:
    """Two models with the same covariance (S = 2 I) whose velocities miss the fix by 1 and by 3 m/s:
    w2 / w1 = exp(-(9 - 1) / (2 * 2)) = exp(-2); with S1 = 2 I and S2 = 5 I and no innovation,
    w2 / w1 = det(S1)^(1/2) / det(S2)^(1/2) = 2 / 5."""
    X = np.array([[1.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    P = np.array([np.eye(3), np.eye(3)])
    logw = np.log(np.array([0.5, 0.5]))
    yawgsf.update(X, P, logw, 0.0, 0.0, 1.0)
    w = np.exp(logw)
    assert w.sum() == pytest.approx(1.0, abs=1e-12) and w[1] / w[0] == pytest.approx(math.exp(-2.0), rel=1e-12)
    X = np.zeros((2, 3))
    P = np.array([np.eye(3), np.diag([4.0, 4.0, 1.0])])
    logw = np.log(np.array([0.5, 0.5]))
    yawgsf.update(X, P, logw, 0.0, 0.0, 1.0)
    w = np.exp(logw)
    assert w[1] / w[0] == pytest.approx(2.0 / 5.0, rel=1e-12)


def test_estimate_is_the_circular_mean_and_the_mixtures_variance() -> None:
    """Equal weights at +170 and -170 deg: the mean is 180 deg (not the arithmetic 0), the variance the
    models' own 0.01 plus the 10 deg spread squared; weights 0.75 / 0.25 at 0 and 90 deg: atan2(0.25, 0.75)."""
    X = np.array([[0.0, 0.0, math.radians(170.0)], [0.0, 0.0, math.radians(-170.0)]])
    P = np.array([np.diag([1.0, 1.0, 0.01])] * 2)
    logw = np.log(np.array([0.5, 0.5]))
    psi, var = yawgsf.estimate(X, P, logw)
    assert abs(math.remainder(psi - math.pi, 2 * math.pi)) < 1e-12
    assert var == pytest.approx(0.01 + math.radians(10.0) ** 2, rel=1e-12)
    X[:, 2] = [0.0, math.pi / 2]
    logw = np.log(np.array([0.75, 0.25]))
    psi, var = yawgsf.estimate(X, P, logw)
    m = math.atan2(0.25, 0.75)
    assert psi == pytest.approx(m, abs=1e-12)
    assert var == pytest.approx(0.01 + 0.75 * m * m + 0.25 * (math.pi / 2 - m) ** 2, rel=1e-12)
