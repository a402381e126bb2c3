"""Heading from GNSS velocity: a Gaussian-sum bank of small yaw filters (no magnetometer needed).

Each of N models holds ``x = [v_N, v_E, psi]`` (m/s, rad) and its 3x3
covariance, started with the yaws spread evenly around the circle. Between
fixes every model integrates the IMU's horizontal velocity increments turned by
its own yaw, with the tilt taken from the navigation solution; a GNSS velocity
fix updates each model (an extended Kalman filter: Y. Bar-Shalom, X. R. Li,
T. Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001,
10.3) and re-weights the bank by each model's likelihood of the innovation,
``w_i <- w_i N(nu_i; 0, S_i)`` (the Gaussian-sum filter, D. L. Alspach and
H. W. Sorenson, IEEE TAC 17(4), 1972, eq. 17). The heading is the weighted
circular mean of the models' yaws, its variance the mixture's
``sum w_i (P_i,psi + (psi_i - psi)^2)`` (ibid. eq. 19). The same idea is PX4
EKF2's "EKF-GSF" yaw estimator; this is written from the references above.

Arrays: ``X`` (N, 3), ``P`` (N, 3, 3), ``logw`` (N,) log-weights. Tuning in
:data:`SIGMA_ACC`, :data:`SIGMA_YAW_RATE` (docs/filter.md "Heading from GNSS
velocity").
"""

from __future__ import annotations

import math

import numpy as np

from .jit import kernel
from .rotation import wrap_pi

N_MODELS = 5
SIGMA_ACC = 0.15  # m/s/sqrt(s): horizontal velocity random walk of a model (accelerometer noise, tilt error g*dphi)
SIGMA_YAW_RATE = 0.002  # rad/sqrt(s): yaw random walk of a model (gyro noise and residual bias; 0.11 deg/sqrt(s))
SCALE_YAW = 0.02  # 1-sigma error of a yaw increment as a fraction of it (consumer gyro scale 1 %, cross-axis 2 %)
SIGMA_VEL0 = 0.5  # m/s: initial velocity 1-sigma of each model (it starts at the solution's velocity)


def make(v_n: float, v_e: float, n: int = N_MODELS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A bank of ``n`` models at velocity (v_N, v_E) (m/s), yaws ``-pi + (i + 1/2) 2 pi / n``, each
    with the yaw 1-sigma of half the spacing, equal weights."""
    X = np.zeros((n, 3))
    P = np.zeros((n, 3, 3))
    half = math.pi / n
    for i in range(n):
        X[i, 0], X[i, 1], X[i, 2] = v_n, v_e, -math.pi + (2 * i + 1) * half
        P[i, 0, 0] = P[i, 1, 1] = SIGMA_VEL0 * SIGMA_VEL0
        P[i, 2, 2] = half * half
    return X, P, np.full(n, -math.log(n))


@kernel
def predict(X: np.ndarray, P: np.ndarray, dv_b: np.ndarray, dtheta_b: np.ndarray, roll: float, pitch: float,
            w_in_d: float, T: float) -> None:
    """Propagate every model over T (s) with the bias-corrected body increments dv_b (m/s) and dtheta_b
    (rad), FRD, at the solution's roll and pitch (rad).

    The increments are levelled, ``u = Ry(pitch) Rx(roll) dv_b`` (the contract's C_b^n with yaw 0), and
    turned by each model's yaw at mid-interval: ``dv_N = cos(psi) u_x - sin(psi) u_y``,
    ``dv_E = sin(psi) u_x + cos(psi) u_y``; the yaw grows by the levelled rotation's vertical part less
    the navigation frame's own turn, ``dpsi = (Ry Rx dtheta)_z - w_in,D T`` (w_in,D: rad/s, down).
    ``F = [[1, 0, -dv_E], [0, 1, dv_N], [0, 0, 1]]``, ``Q = diag(SIGMA_ACC^2 T, SIGMA_ACC^2 T,
    SIGMA_YAW_RATE^2 T + (SCALE_YAW dpsi)^2)``.
    """
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    # Ry(pitch) Rx(roll): rows of the level-from-body rotation with yaw 0
    ux = cp * dv_b[0] + sp * sr * dv_b[1] + sp * cr * dv_b[2]
    uy = cr * dv_b[1] - sr * dv_b[2]
    dpsi = -sp * dtheta_b[0] + cp * sr * dtheta_b[1] + cp * cr * dtheta_b[2] - w_in_d * T
    qv = SIGMA_ACC * SIGMA_ACC * T
    qy = SIGMA_YAW_RATE * SIGMA_YAW_RATE * T + (SCALE_YAW * dpsi) ** 2
    for i in range(X.shape[0]):
        psi = X[i, 2] + 0.5 * dpsi
        c, s = math.cos(psi), math.sin(psi)
        dn = c * ux - s * uy
        de = s * ux + c * uy
        X[i, 0] += dn
        X[i, 1] += de
        X[i, 2] = wrap_pi(X[i, 2] + dpsi)
        # F P F^T with F = I + g e_3^T, g = (-dv_E, dv_N, 0): P + g p3^T + p3 g^T + P_33 g g^T (p3: column 3)
        g0, g1 = -de, dn
        p02, p12, p22 = P[i, 0, 2], P[i, 1, 2], P[i, 2, 2]
        P[i, 0, 0] += 2.0 * g0 * p02 + g0 * g0 * p22 + qv
        P[i, 1, 1] += 2.0 * g1 * p12 + g1 * g1 * p22 + qv
        P[i, 0, 1] += g0 * p12 + g1 * p02 + g0 * g1 * p22
        P[i, 1, 0] = P[i, 0, 1]
        P[i, 0, 2] = p02 + g0 * p22
        P[i, 2, 0] = P[i, 0, 2]
        P[i, 1, 2] = p12 + g1 * p22
        P[i, 2, 1] = P[i, 1, 2]
        P[i, 2, 2] = p22 + qy


@kernel
def update(X: np.ndarray, P: np.ndarray, logw: np.ndarray, v_n: float, v_e: float, sigma: float) -> None:
    """A GNSS horizontal velocity fix (m/s, 1-sigma per axis): each model's EKF update with ``H = [I_2 0]``,
    ``nu = x_v - z``, ``S = P_vv + sigma^2 I``, ``K = P H^T S^-1``, ``x <- x - K nu``, ``P <- P - K S K^T``;
    the log-weights gain ``-nu^T S^-1 nu / 2 - log(2 pi sqrt(det S))`` and are normalised."""
    r = sigma * sigma
    n = X.shape[0]
    for i in range(n):
        s00, s01, s11 = P[i, 0, 0] + r, P[i, 0, 1], P[i, 1, 1] + r
        det = s00 * s11 - s01 * s01
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
        nu0, nu1 = X[i, 0] - v_n, X[i, 1] - v_e
        d2 = nu0 * (i00 * nu0 + i01 * nu1) + nu1 * (i01 * nu0 + i11 * nu1)
        logw[i] += -0.5 * d2 - math.log(2.0 * math.pi * math.sqrt(det))
        K = np.empty((3, 2))
        for a in range(3):
            K[a, 0] = P[i, a, 0] * i00 + P[i, a, 1] * i01
            K[a, 1] = P[i, a, 0] * i01 + P[i, a, 1] * i11
        for a in range(3):
            X[i, a] -= K[a, 0] * nu0 + K[a, 1] * nu1
        X[i, 2] = wrap_pi(X[i, 2])
        # P - K S K^T = P - K (P H^T)^T: K S = P H^T
        Pn = np.empty((3, 3))
        for a in range(3):
            for b in range(3):
                Pn[a, b] = P[i, a, b] - (K[a, 0] * P[i, b, 0] + K[a, 1] * P[i, b, 1])
        for a in range(3):
            for b in range(3):
                P[i, a, b] = 0.5 * (Pn[a, b] + Pn[b, a])
    top = logw.max()
    total = 0.0
    for i in range(n):
        total += math.exp(logw[i] - top)
    lse = top + math.log(total)
    for i in range(n):
        logw[i] -= lse


@kernel
def estimate(X: np.ndarray, P: np.ndarray, logw: np.ndarray) -> tuple[float, float]:
    """The bank's yaw (rad, the weighted circular mean) and its variance (rad^2, the mixture's)."""
    sn = 0.0
    cs = 0.0
    for i in range(X.shape[0]):
        w = math.exp(logw[i])
        sn += w * math.sin(X[i, 2])
        cs += w * math.cos(X[i, 2])
    psi = math.atan2(sn, cs)
    var = 0.0
    for i in range(X.shape[0]):
        d = wrap_pi(X[i, 2] - psi)
        var += math.exp(logw[i]) * (P[i, 2, 2] + d * d)
    return psi, var
