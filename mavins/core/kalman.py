"""Error-state Kalman filter kernels: prediction, gated update, closed-loop feedback, measurements.

The error state ``x`` and its layout are errmodel.py's (estimate minus truth).
The filter runs closed loop: after every accepted update the estimate is fed
back into the strapdown state ``s`` (strapdown.py's ``S_*`` layout) and into
the bias vector ``bias``, and ``x`` is reset to zero, so between updates the
error-state estimate is always zero and only P is propagated. The filter works in
the geographic frame only (strapdown.GEOGRAPHIC): the engine and ``mavins nav``
refuse aiding in the other frames.

Bias vector ``bias`` (``B_*``, the filter's nominal sensor-error estimates):
``[bg_const(3) rad/s, ba_const(3) m/s^2, bg_gm(3), ba_gm(3), baro_offset m,
sg(3), sa(3) scale factors, mg(6), ma(6) misalignments, mb(3) magnetometer
hard iron, ws wheel scale factor, vp(3) m and vy rad: where an external vision
frame sits]``; ``bias[i]`` corrects ``x[X_SENSORS + i]``. The bias the sensor
carries is ``const + gm`` per axis; the IMU data are corrected as ``u - M u``
with ``u = (measured - bias) / (1 + scale)`` (:func:`correct_gyro3`,
:func:`correct_accel3`; errmodel.py's sensor model).

Innovations are *predicted minus measured*, ``nu = h(est) - z``, so that
``nu = H x + noise`` with x = estimate minus truth; the update is then
``x += K (nu - H x)``, ``K = P H^T S^-1``, ``S = H P H^T + R``, and P takes
Joseph's form ``(I - K H) P (I - K H)^T + K R K^T``.

Gate (docs/conventions.md ``--gate N``): a measurement is rejected when any
component's normalised innovation ``|nu_i - (H x)_i| / sqrt(S_ii)`` exceeds
N (sigma). The returned test ratio is the largest of them divided by N
(below 1 passes); the NIS ``nu^T S^-1 nu`` is returned for consistency tests
(chi-square with dim(nu) degrees of freedom for a consistent filter).

Measurement time: a fix stamped ``t_m`` is used at the first attitude update
``t_k >= t_m``, after the IMU solution has passed it. The solution is taken
back to ``t_m`` along the current velocity, ``p(t_m) = p(t_k) - v (t_k -
t_m)`` (and ``v(t_m)`` by interpolation between the last two updates), which
adds ``-(t_k - t_m)`` on the dv columns of the position H. With t_k - t_m
under one attitude interval the neglected acceleration term is ``a dt^2/2``
(below a millimetre at 50 Hz).
"""

from __future__ import annotations

import numpy as np

from . import earth
from . import strapdown as sd
from .strapdown import GEOGRAPHIC
from .errmodel import (
    NX,
    SP_ACC_BIAS,
    SP_ACC_GM,
    SP_ACC_MIS,
    SP_ACC_SCALE,
    SP_GYRO_BIAS,
    SP_GYRO_GM,
    SP_GYRO_MIS,
    SP_GYRO_SCALE,
    SP_WHEEL_SCALE,
    X_BA,
    X_BARO,
    X_BG,
    X_DP,
    X_DV,
    X_GA,
    X_GG,
    X_MA,
    X_MB,
    X_MG,
    X_PHI,
    X_SA,
    X_SENSORS,
    X_SG,
    X_VP,
    X_VY,
    X_WS,
    _set_skew,
    matmul,
    matmul_bt,
)
from .jit import kernel
from .rotation import dcm_to_rotvec, mat3_mul_s, mat_vec, quat_mul_s, quat_to_dcm_s, rotvec_to_dcm_s, rotvec_to_quat_s, skew, wrap_pi

ALL = np.ones(NX)  # update(): every state may be corrected
ALL_BUT_HEADING = ALL.copy()  # update(): the heading is a consider state (unknown, not learnt: engine.GNSS_YAW_PENDING)
ALL_BUT_HEADING[X_PHI + 2] = 0.0

# the bias vector: the sensor-error blocks of the state (errmodel.STATE), at the same places less X_SENSORS
B_BG, B_BA, B_GG, B_GA, B_BARO = (X_BG - X_SENSORS, X_BA - X_SENSORS, X_GG - X_SENSORS, X_GA - X_SENSORS,
                                  X_BARO - X_SENSORS)
B_SG, B_SA, B_MB = X_SG - X_SENSORS, X_SA - X_SENSORS, X_MB - X_SENSORS
B_MG, B_MA = X_MG - X_SENSORS, X_MA - X_SENSORS
B_WS, B_VP, B_VY = X_WS - X_SENSORS, X_VP - X_SENSORS, X_VY - X_SENSORS
B_SIZE = NX - X_SENSORS


@kernel
def gyro_bias_total(bias: np.ndarray) -> np.ndarray:
    """The gyro bias estimate (rad/s, body): the constant part plus the Gauss-Markov part."""
    return bias[B_BG:B_BG + 3] + bias[B_GG:B_GG + 3]


@kernel
def accel_bias_total(bias: np.ndarray) -> np.ndarray:
    """The accelerometer bias estimate (m/s^2, body): the constant part plus the Gauss-Markov part."""
    return bias[B_BA:B_BA + 3] + bias[B_GA:B_GA + 3]


def calibrated_gyro_bias(P: np.ndarray, bias: np.ndarray, gyro_bias: np.ndarray, var: float) -> None:
    """A gyro bias measured by a zero-rate calibration (rad/s, body): the constant part's estimate, its
    variance ``var`` per axis, uncorrelated with the rest of the state (P's rows and columns cleared)."""
    bias[B_BG:B_BG + 3] = gyro_bias
    if var > 0.0:
        for i in range(3):
            j = X_BG + i
            P[j, :] = 0.0
            P[:, j] = 0.0
            P[j, j] = var


@kernel
def correct_gyro(bias: np.ndarray, axis: int, x: float, dt: float) -> float:
    """A raw gyro reading on ``axis`` corrected by the estimates: ``(x - b dt) / (1 + s)`` with b the
    bias (constant plus Gauss-Markov part, rad/s) and s the scale factor; x an angle increment over dt
    (rad, s), or a rate with dt = 1 (errmodel.py, scale-factor model)."""
    return (x - (bias[B_BG + axis] + bias[B_GG + axis]) * dt) / (1.0 + bias[B_SG + axis])


@kernel
def correct_accel(bias: np.ndarray, axis: int, x: float, dt: float) -> float:
    """:func:`correct_gyro` for the accelerometer (m/s increment over dt, or m/s^2 with dt = 1)."""
    return (x - (bias[B_BA + axis] + bias[B_GA + axis]) * dt) / (1.0 + bias[B_SA + axis])


@kernel
def unmisalign(bias: np.ndarray, b0: int, u0: float, u1: float, u2: float) -> tuple[float, float, float]:
    """``u - M u`` with M the misalignment estimate at ``bias[b0:b0 + 6]`` (off-diagonal m_xy m_xz m_yx m_yz
    m_zx m_zy, rad): the first-order inverse of ``(I + M)`` (errmodel.py, misalignment model)."""
    return (u0 - (bias[b0] * u1 + bias[b0 + 1] * u2),
            u1 - (bias[b0 + 2] * u0 + bias[b0 + 3] * u2),
            u2 - (bias[b0 + 4] * u0 + bias[b0 + 5] * u1))


@kernel
def correct_gyro3(bias: np.ndarray, x0: float, x1: float, x2: float, dt: float) -> tuple[float, float, float]:
    """A raw gyro triad (angle increments over dt, or rates with dt = 1) corrected by every estimate:
    :func:`correct_gyro` per axis, then :func:`unmisalign` (errmodel.py's sensor model)."""
    return unmisalign(bias, B_MG, correct_gyro(bias, 0, x0, dt), correct_gyro(bias, 1, x1, dt),
                      correct_gyro(bias, 2, x2, dt))


@kernel
def correct_accel3(bias: np.ndarray, x0: float, x1: float, x2: float, dt: float) -> tuple[float, float, float]:
    """:func:`correct_gyro3` for the accelerometer triad."""
    return unmisalign(bias, B_MA, correct_accel(bias, 0, x0, dt), correct_accel(bias, 1, x1, dt),
                      correct_accel(bias, 2, x2, dt))


@kernel
def symmetrise(P: np.ndarray) -> None:
    """Replace P by ``(P + P^T) / 2`` in place."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            m = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = m
            P[j, i] = m


@kernel
def predict(P: np.ndarray, phi: np.ndarray, qd: np.ndarray) -> None:
    """``P <- Phi P Phi^T + Qd`` in place, symmetrised."""
    p_new = matmul_bt(matmul(phi, P), phi)
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            P[i, j] = p_new[i, j] + qd[i, j]
    symmetrise(P)


@kernel
def spd_inverse(S: np.ndarray) -> tuple[np.ndarray, bool]:
    """Inverse of a small symmetric positive definite matrix (Cholesky); ok=False if not SPD."""
    m = S.shape[0]
    L = np.zeros((m, m))
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return np.zeros((m, m)), False
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, m):
            a = S[i, j]
            for k in range(j):
                a -= L[i, k] * L[j, k]
            L[i, j] = a / L[j, j]
    # inverse of L (lower triangular), then S^-1 = L^-T L^-1
    li = np.zeros((m, m))
    for i in range(m):
        li[i, i] = 1.0 / L[i, i]
        for j in range(i):
            a = 0.0
            for k in range(j, i):
                a -= L[i, k] * li[k, j]
            li[i, j] = a / L[i, i]
    inv = np.zeros((m, m))
    for i in range(m):
        for j in range(m):
            a = 0.0
            for k in range(max(i, j), m):
                a += li[k, i] * li[k, j]
            inv[i, j] = a
    return inv, True


@kernel
def update(
    x: np.ndarray, P: np.ndarray, H: np.ndarray, nu: np.ndarray, R: np.ndarray, gate: float, free: np.ndarray
) -> tuple[float, float, bool]:
    """Gated Joseph-form update of x and P in place.

    ``free[i] = 0`` keeps state i out of the correction: its gain row is zero
    (a Schmidt, or "consider", update: the state's uncertainty still counts in
    S and its correlations are kept; the Joseph form stays exact for any gain;
    Simon, Optimal State Estimation, 2006, sec. 7.4). ALL frees every state.

    Returns ``(nis, ratio, accepted)``: the normalised innovation squared,
    the largest normalised innovation component divided by ``gate`` (gate <= 0:
    no gating, ratio is then the largest normalised component itself), and
    whether the update was applied.
    """
    n = x.shape[0]
    m = nu.shape[0]
    pht = matmul_bt(P, H)
    S = matmul(H, pht)
    for i in range(m):
        for j in range(m):
            S[i, j] += R[i, j]
    y = nu.copy()
    for i in range(m):
        for j in range(n):
            y[i] -= H[i, j] * x[j]
    sinv, ok = spd_inverse(S)
    if not ok:
        return np.inf, np.inf, False
    nis = 0.0
    for i in range(m):
        for j in range(m):
            nis += y[i] * sinv[i, j] * y[j]
    worst = 0.0
    for i in range(m):
        z = abs(y[i]) / np.sqrt(S[i, i])
        if not z <= worst:
            worst = z
    ratio = worst / gate if gate > 0.0 else worst
    if not np.isfinite(nis) or (gate > 0.0 and not ratio <= 1.0):
        return nis, ratio, False
    K = matmul(pht, sinv)
    for i in range(n):
        for j in range(m):
            K[i, j] *= free[i]
            x[i] += K[i, j] * y[j]
    A = -matmul(K, H)
    for i in range(n):
        A[i, i] += 1.0
    p_new = matmul_bt(matmul(A, P), A)
    krk = matmul_bt(matmul(K, R), K)
    for i in range(n):
        for j in range(n):
            P[i, j] = p_new[i, j] + krk[i, j]
    symmetrise(P)
    return nis, ratio, True


@kernel
def feedback(s: np.ndarray, cfg: np.ndarray, bias: np.ndarray, x: np.ndarray) -> None:
    """Correct the strapdown state and the biases by the error estimate, then zero x.

    Attitude ``C <- exp(-[phi x]) C`` (``q <- r(-phi) (x) q``, the DCM from
    the quaternion, so both stay consistent); velocity ``v -= dv`` at k and
    at k-1 (S.VP: the mid-interval extrapolation and Simpson's rule then see
    one consistent history); position
    moved by ``-dp``: ``C_n^e <- C_n^e exp([xi x])`` with ``xi`` the transport
    rotation of that displacement (as strapdown.k_update moves it), height
    ``h <- h + dp_D``, and the latitude/longitude kept beside C_n^e
    refreshed (strapdown.sync_position); biases ``bias -= x[X_SENSORS:]``.
    """
    q0, q1, q2, q3 = quat_mul_s(rotvec_to_quat_s(-x[X_PHI], -x[X_PHI + 1], -x[X_PHI + 2]),
                                (s[sd.S.Q], s[sd.S.Q + 1], s[sd.S.Q + 2], s[sd.S.Q + 3]))
    qn = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    q0, q1, q2, q3 = q0 / qn, q1 / qn, q2 / qn, q3 / qn
    s[sd.S.Q], s[sd.S.Q + 1], s[sd.S.Q + 2], s[sd.S.Q + 3] = q0, q1, q2, q3
    sd._put9(s, sd.S.C, quat_to_dcm_s((q0, q1, q2, q3)))
    for i in range(3):
        s[sd.S.V + i] -= x[X_DV + i]
        s[sd.S.VP + i] -= x[X_DV + i]
    if cfg[sd.CFG_EARTH] > 0.5:
        lat, lon, h = sd.position(s, cfg, GEOGRAPHIC)
        # the transport rotation of the displacement (-dp_N, -dp_E), as strapdown._position_step moves C_n^e
        xn, xe, xd = earth.transport_rate_s(lat, h, -x[X_DP], -x[X_DP + 1])
        sd._put9(s, sd.S.CNE, mat3_mul_s(sd._get9(s, sd.S.CNE), rotvec_to_dcm_s(xn, xe, xd)))
    else:
        for i in range(3):
            s[sd.S.PF + i] -= x[X_DP + i]
    s[sd.S.H] += x[X_DP + 2]
    sd.sync_position(s, cfg, GEOGRAPHIC)
    for i in range(B_SIZE):
        bias[i] -= x[X_SENSORS + i]
    for i in range(x.shape[0]):
        x[i] = 0.0


@kernel
def apply_update(
    s: np.ndarray,
    cfg: np.ndarray,
    bias: np.ndarray,
    P: np.ndarray,
    H: np.ndarray,
    nu: np.ndarray,
    R: np.ndarray,
    gate: float,
    free: np.ndarray,
) -> tuple[float, float, bool]:
    """Gated update from a zero error state followed by feedback; returns (nis, ratio, accepted)."""
    x = np.zeros(P.shape[0])
    nis, ratio, ok = update(x, P, H, nu, R, gate, free)
    if ok:
        feedback(s, cfg, bias, x)
    return nis, ratio, ok


# --- measurement models: (nu, H, R) -----------------------------------------


@kernel
def yaw_reset(s: np.ndarray, cfg: np.ndarray, bias: np.ndarray, P: np.ndarray, dpsi: float, var_yaw: float,
              lat: float, lon: float, var_pos: float, v_n: float, v_e: float, var_vel: float) -> None:
    """Turn the solution's heading by dpsi (rad, about down) and put its horizontal position and velocity on
    a GNSS fix (lat, lon rad; v_N, v_E m/s), through :func:`feedback` with ``phi_D = -dpsi`` (so
    ``C <- Rz(dpsi) C``, exact for any angle), ``dp = p - p_fix``, ``dv = v - v_fix``; then the rows and
    columns of phi_D, the horizontal position and velocity in P are reset to these variances (rad^2, m^2,
    m^2/s^2) and no correlation (a reset, as PX4 EKF2 resets its yaw from the GNSS-velocity yaw
    estimator). The vertical, the level and the biases are kept."""
    x = np.zeros(P.shape[0])
    x[X_PHI + 2] = -dpsi
    lat0, lon0, _ = sd.position(s, cfg, GEOGRAPHIC)
    mn, me = metres_per_radian(s, cfg)
    x[X_DP] = (lat0 - lat) * mn
    x[X_DP + 1] = (lon0 - lon) * me
    x[X_DV] = s[sd.S.V] - v_n
    x[X_DV + 1] = s[sd.S.V + 1] - v_e
    feedback(s, cfg, bias, x)
    idx = (X_PHI + 2, X_DP, X_DP + 1, X_DV, X_DV + 1)
    var = (var_yaw, var_pos, var_pos, var_vel, var_vel)
    for k in range(5):
        j = idx[k]
        for i in range(P.shape[0]):
            P[j, i] = 0.0
            P[i, j] = 0.0
        P[j, j] = var[k]


@kernel
def metres_per_radian(s: np.ndarray, cfg: np.ndarray) -> tuple[float, float]:
    """``(R_N + h, (R_E + h) cos L)``: metres per radian of latitude and of longitude.

    In laboratory mode (earth = none) the start point's, as strapdown.position maps them.
    """
    if cfg[sd.CFG_EARTH] > 0.5:
        lat, lon, h = sd.position(s, cfg, GEOGRAPHIC)
    else:
        lat, h = s[sd.S.LAT0], s[sd.S.H0]
    r_n, r_e = earth.radii(lat)
    return r_n + h, (r_e + h) * np.cos(lat)


@kernel
def gnss_position(
    s: np.ndarray,
    cfg: np.ndarray,
    lat_m: float,
    lon_m: float,
    h_m: float,
    lever: np.ndarray,
    dt: float,
    sigma_h: float,
    sigma_v: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Antenna position fix (rad, rad, m) taken ``dt`` = t_k - t_m >= 0 s before the solution.

    ``p_ant = p + C_b^n l`` with the lever arm l (m, FRD). Innovation in NED
    metres: ``nu = (p + C l - v dt) - p_m``; ``H = [-[(C l) x], -dt I, I, 0...]``
    (``C(est) l - C l = phi x (C l)``). sigma_h per horizontal axis, sigma_v
    vertical (m).
    """
    lat, lon, h = sd.position(s, cfg, GEOGRAPHIC)
    mn, me = metres_per_radian(s, cfg)
    c = s[sd.S.C : sd.S.C + 9].reshape(3, 3)
    la = mat_vec(c, lever)
    nu = np.empty(3)
    nu[0] = (lat - lat_m) * mn + la[0] - s[sd.S.V] * dt
    nu[1] = wrap_pi(lon - lon_m) * me + la[1] - s[sd.S.V + 1] * dt
    nu[2] = -(h - h_m) + la[2] - s[sd.S.V + 2] * dt
    H = np.zeros((3, NX))
    _set_skew(H, 0, X_PHI, la, -1.0)
    for i in range(3):
        H[i, X_DV + i] = -dt
        H[i, X_DP + i] = 1.0
    R = np.zeros((3, 3))
    R[0, 0] = sigma_h * sigma_h
    R[1, 1] = sigma_h * sigma_h
    R[2, 2] = sigma_v * sigma_v
    return nu, H, R


@kernel
def gnss_velocity(
    s: np.ndarray,
    v_m: np.ndarray,
    w_ib: np.ndarray,
    lever: np.ndarray,
    dt: float,
    T: float,
    sigma: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Antenna velocity fix (NED m/s) taken dt before the solution; T is the last attitude interval.

    ``v_ant = v + C (w_ib x l)``; the Earth-rate term ``-w_in x (C l)`` (below
    1e-4 m/s per metre of lever arm) is ignored. ``v(t_m)`` is interpolated
    between the last two updates. ``w_ib`` is the bias-corrected body rate
    (rad/s). ``H = [-[(C (w x l)) x], I, 0, C [l x], 0, C [l x], 0...]``: a
    gyro bias error db changes the rate by -db, so the lever-arm velocity by
    ``C (l x db)``.
    """
    c = s[sd.S.C : sd.S.C + 9].reshape(3, 3)
    wl = np.empty(3)
    wl[0] = w_ib[1] * lever[2] - w_ib[2] * lever[1]
    wl[1] = w_ib[2] * lever[0] - w_ib[0] * lever[2]
    wl[2] = w_ib[0] * lever[1] - w_ib[1] * lever[0]
    cwl = mat_vec(c, wl)
    a = dt / T if T > 0.0 else 0.0
    nu = np.empty(3)
    for i in range(3):
        v_tm = s[sd.S.V + i] - a * (s[sd.S.V + i] - s[sd.S.VP + i])
        nu[i] = v_tm + cwl[i] - v_m[i]
    H = np.zeros((3, NX))
    _set_skew(H, 0, X_PHI, cwl, -1.0)
    # C [l x]
    lx = skew(lever)
    for i in range(3):
        H[i, X_DV + i] = 1.0
        for j in range(3):
            e = c[i, 0] * lx[0, j] + c[i, 1] * lx[1, j] + c[i, 2] * lx[2, j]
            H[i, X_BG + j] = e
            H[i, X_GG + j] = e
    R = np.zeros((3, 3))
    for i in range(3):
        R[i, i] = sigma * sigma
    return nu, H, R


@kernel
def horizontal_rows(nu: np.ndarray, H: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The north and east rows of a NED velocity model (nu, H, R): a GNSS that gives ground speed
    and course only (GPS_RAW_INT ``vel``, ``cog``) measures ``v_N = |v_h| cos(cog)``,
    ``v_E = |v_h| sin(cog)`` and nothing vertical."""
    return nu[:2].copy(), H[:2, :].copy(), R[:2, :2].copy()


@kernel
def baro_height(
    s: np.ndarray, bias: np.ndarray, h_m: float, dt: float, sigma: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Barometric height (m) = h + offset + noise, taken dt before the solution.

    ``nu = h + v_D dt + offset - h_m``; ``H``: -1 on dp_D (dh = -dp_D),
    +dt on dv_D, +1 on the offset.
    """
    nu = np.empty(1)
    nu[0] = s[sd.S.H] + s[sd.S.V + 2] * dt + bias[B_BARO] - h_m
    H = np.zeros((1, NX))
    H[0, X_DP + 2] = -1.0
    H[0, X_DV + 2] = dt
    H[0, X_BARO] = 1.0
    R = np.zeros((1, 1))
    R[0, 0] = sigma * sigma
    return nu, H, R


@kernel
def heading(s: np.ndarray, yaw_m: float, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A yaw measurement (rad, ZYX Euler) with 1-sigma (rad).

    With ``C(est) = (I + [phi x]) C``, ``yaw = atan2(C21, C11)`` changes by
    ``dyaw = phi_D + tan(pitch) (phi_N cos yaw + phi_E sin yaw)``.
    """
    c = s[sd.S.C : sd.S.C + 9].reshape(3, 3)
    yaw = np.arctan2(c[1, 0], c[0, 0])
    hh = c[0, 0] * c[0, 0] + c[1, 0] * c[1, 0]
    nu = np.empty(1)
    nu[0] = wrap_pi(yaw - yaw_m)
    H = np.zeros((1, NX))
    H[0, X_PHI] = -c[2, 0] * c[0, 0] / hh
    H[0, X_PHI + 1] = -c[2, 0] * c[1, 0] / hh
    H[0, X_PHI + 2] = 1.0
    R = np.zeros((1, 1))
    R[0, 0] = sigma * sigma
    return nu, H, R


@kernel
def mag_level(s: np.ndarray, cfg: np.ndarray, bias: np.ndarray, m_b: np.ndarray, w_ib: np.ndarray,
              dt: float) -> np.ndarray:
    """A magnetometer sample ``m_b`` (body FRD, any unit) less the hard-iron estimate ``bias[B_MB:]``
    (same unit), taken dt (s) before the solution, carried to the solution's time and levelled with the
    estimated attitude (NED, same unit).

    A vector fixed in n seen in b obeys ``d(m_b)/dt = -w_nb x m_b`` (from the
    DCM differential equation ``dC_b^n/dt = C_b^n [w_nb x]``, attitude-equation
    notes, "DCM differential equation"), so ``m_b(t) = m_b - dt (w_nb x m_b)``
    with ``w_nb = w_ib - C^T (w_ie + w_en)`` from the bias-corrected body rate
    ``w_ib`` (rad/s) and the Earth and transport rates at the solution (none in
    laboratory mode). Without it a sample one 20 ms attitude interval old in a
    20 deg/s turn reads 0.4 deg off in heading. Then ``m = C m_b``.
    """
    c = s[sd.S.C : sd.S.C + 9].reshape(3, 3)
    w = w_ib.copy()
    if cfg[sd.CFG_EARTH] > 0.5:
        lat, lon, h = sd.position(s, cfg, GEOGRAPHIC)
        w_in = earth.earth_rate_n(lat) + earth.transport_rate(lat, h, s[sd.S.V : sd.S.V + 3])
        for i in range(3):
            w[i] -= c[0, i] * w_in[0] + c[1, i] * w_in[1] + c[2, i] * w_in[2]
    m_c = np.empty(3)
    for i in range(3):
        m_c[i] = m_b[i] - bias[B_MB + i]
    m_t = np.empty(3)
    m_t[0] = m_c[0] - dt * (w[1] * m_c[2] - w[2] * m_c[1])
    m_t[1] = m_c[1] - dt * (w[2] * m_c[0] - w[0] * m_c[2])
    m_t[2] = m_c[2] - dt * (w[0] * m_c[1] - w[1] * m_c[0])
    return mat_vec(c, m_t)


@kernel
def mag_tan_inclination(m: np.ndarray) -> float:
    """tan(I) of a levelled field sample m (NED): its down part over its horizontal part."""
    return m[2] / np.sqrt(m[0] * m[0] + m[1] * m[1])


MAG_STATS = 5  # mag_accept's running sums (tan I, count, horizontal strength), then aided.apply_mag's
# consecutive rejections and the hard iron's initial variance (its reset)


@kernel
def mag_inclination(incl: np.ndarray, m: np.ndarray) -> float:
    """The model's tan(I) for :func:`mag_heading`: the mean over the accepted samples before this one, kept in
    ``incl = [sum of tan I, count, sum of |m_h|]`` (:func:`mag_accept`), or the levelled sample m's own while
    there are none."""
    if incl[1] == 0.0:
        return mag_tan_inclination(m)
    return incl[0] / incl[1]


@kernel
def mag_horizontal(incl: np.ndarray, m: np.ndarray) -> float:
    """The horizontal field strength for :func:`mag_heading` (the sample's unit): the mean over the accepted
    samples before this one (``incl``, :func:`mag_inclination`), or the levelled sample m's own."""
    if incl[1] == 0.0:
        return np.sqrt(m[0] * m[0] + m[1] * m[1])
    return incl[2] / incl[1]


@kernel
def mag_accept(incl: np.ndarray, m: np.ndarray) -> None:
    """Count the accepted levelled sample m into ``incl`` (:func:`mag_inclination`)."""
    incl[0] += mag_tan_inclination(m)
    incl[1] += 1.0
    incl[2] += np.sqrt(m[0] * m[0] + m[1] * m[1])


@kernel
def mag_disturbed(m: np.ndarray, incl_model: float, strength_model: float, gate_incl: float,
                  gate_strength: float) -> bool:
    """Whether a levelled sample m (NED) disagrees with the Earth's field a model gives: its inclination
    ``atan2(m_D, |m_h|)`` off the model's ``incl_model`` (rad) by more than ``gate_incl`` (rad), or its
    strength off ``strength_model`` by more than ``gate_strength`` (m's unit); a NaN model figure is
    not checked (PX4 EKF2's magnetometer checks, EKF2_MAG_CHK_INC and EKF2_MAG_CHK_STR)."""
    h = np.sqrt(m[0] * m[0] + m[1] * m[1])
    if np.isfinite(incl_model) and abs(np.arctan2(m[2], h) - incl_model) > gate_incl:
        return True
    if np.isfinite(strength_model) and abs(np.sqrt(h * h + m[2] * m[2]) - strength_model) > gate_strength:
        return True
    return False


@kernel
def mag_heading(
    s: np.ndarray, m: np.ndarray, declination: float, tan_incl: float, horizontal: float, sigma: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heading from a levelled magnetometer sample m (NED, :func:`mag_level`).

    The measurement is the angle of the field's horizontal part east of
    north, which must equal the declination D (rad): ``nu = atan2(m_E, m_N) - D``.
    With ``m(est) = m + phi x m``, ``d nu = -(1/|m_h|^2) [-m_E, m_N, 0] [m x] phi``;
    taken at the field the model predicts (declination D, inclination I,
    tan_incl = tan I), ``H_phi = [-tan(I) cos D, -tan(I) sin D, 1]``: the tilt
    about magnetic north couples through the vertical field. H must not come
    from the sample itself. Along the sample's own horizontal direction, H's
    east part carries the sample's noise across the field, the innovation's
    own noise, and their product has the mean ``tan(I) sigma^2 / |m_h|^2``: it
    walked the east tilt one way (50 Hz over the consumer flight:
    normalised-error RMS 2.9). With the sample's own tan I, every sample
    measures a slightly different combination of heading and tilt, and the
    filter tells the two apart from noise (docs/filter.md "Magnetometer").
    Callers pass the mean tan I of the accepted samples before this one
    (:func:`mag_inclination`). sigma (rad) is the heading noise, about
    sensor noise / horizontal field.

    Hard iron: the sample is corrected by the estimate, ``m = C (m_b - b)``,
    so an error db of the estimate moves m by ``-C db`` and the heading by
    ``-g^T C db`` with ``g = [-sin D, cos D, 0] / |m_h|`` (the gradient of
    atan2 at the model's field): ``H_mb = -g^T C``, with ``horizontal`` the
    horizontal strength ``|m_h|`` (the sample's unit, :func:`mag_horizontal`).
    """
    c = s[sd.S.C : sd.S.C + 9].reshape(3, 3)
    nu = np.empty(1)
    nu[0] = wrap_pi(np.arctan2(m[1], m[0]) - declination)
    H = np.zeros((1, NX))
    H[0, X_PHI] = -tan_incl * np.cos(declination)
    H[0, X_PHI + 1] = -tan_incl * np.sin(declination)
    H[0, X_PHI + 2] = 1.0
    g0 = -np.sin(declination) / horizontal
    g1 = np.cos(declination) / horizontal
    for j in range(3):
        H[0, X_MB + j] = -(g0 * c[0, j] + g1 * c[1, j])
    R = np.zeros((1, 1))
    R[0, 0] = sigma * sigma
    return nu, H, R


@kernel
def nhc(s: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Non-holonomic constraint of a wheeled vehicle: no sideways and no vertical velocity in the body frame
    (sigma m/s each): :func:`body_velocity`'s rows y and z with 0 measured (Groves 2nd ed., section 16.4.1,
    context-based constraints; Shin's motion constraints of a land vehicle)."""
    return _body_rows(s, 1, np.zeros(3), np.full(3, sigma))


@kernel
def body_velocity(s: np.ndarray, v_b: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A velocity measured in the body frame (m/s, FRD; a visual-inertial camera's or a motion-capture system's
    ODOMETRY in its child frame BODY_FRD), 1-sigma per axis ``sigma`` (m/s) (:func:`_body_rows`, all three
    axes; Groves 2nd ed., section 16.4.1, the same body-frame velocity measurement)."""
    return _body_rows(s, 0, v_b, sigma)


@kernel
def _body_rows(s: np.ndarray, first: int, v_b: np.ndarray, sigma: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The body-frame velocity's rows from axis ``first`` (0 x, 1 y) to z: predicted ``v_b = C^T v``, measured
    ``v_b[a]`` with 1-sigma ``sigma[a]``. With ``C(true) = (I - [phi x]) C(est)`` the estimate's error is
    ``dv_b = C^T dv + C^T [v x] phi`` (first order): the rows of ``C^T`` (on dv) and of ``C^T [v x]`` (on phi)
    are H; the innovation is predicted minus measured."""
    c = s[sd.S.C:sd.S.C + 9]
    v0, v1, v2 = s[sd.S.V], s[sd.S.V + 1], s[sd.S.V + 2]
    n = 3 - first
    nu = np.empty(n)
    H = np.zeros((n, NX))
    R = np.zeros((n, n))
    for r in range(n):
        a = first + r
        c0, c1, c2 = c[a], c[3 + a], c[6 + a]  # column a of C: row a of C^T
        nu[r] = c0 * v0 + c1 * v1 + c2 * v2 - v_b[a]
        H[r, X_DV] = c0
        H[r, X_DV + 1] = c1
        H[r, X_DV + 2] = c2
        # (C^T [v x]) row a = c_a^T [v x] = (c_a x v)^T, c_a the a-th column of C
        H[r, X_PHI] = c1 * v2 - c2 * v1
        H[r, X_PHI + 1] = c2 * v0 - c0 * v2
        H[r, X_PHI + 2] = c0 * v1 - c1 * v0
        R[r, r] = sigma[a] * sigma[a]
    return nu, H, R


@kernel
def wheel_speed(s: np.ndarray, bias: np.ndarray, speed: float, w_ib: np.ndarray, lever: np.ndarray, dt: float,
                T: float, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wheel odometry: the forward speed ``speed`` (m/s, along body x) measured ``dt`` s before the solution
    at the axle centre ``lever`` (m, body FRD, from the IMU) is ``(1 + k)`` times the true one, k the
    odometer's scale-factor error (state X_WS, estimate ``bias[B_WS]``).

    Predicted: ``(1 + k) u``, ``u = c_0^T v(t_m) + (w_ib x l)_x`` with c_0 the first column of C (body x in
    NED), ``v(t_m)`` interpolated between the last two updates over the attitude interval T as in
    :func:`gnss_velocity`, w_ib the bias-corrected body rate (rad/s; the Earth and transport rates' share,
    below 1e-4 m/s per metre of lever arm, is left out). With the errors of :func:`nhc`, ``du = c_0^T dv +
    (c_0 x v)^T phi + (l x db)_x`` to first order (a gyro bias error db changes the rate by -db), so H is
    ``(1 + k)`` times that on dv, phi and both gyro bias parts, and ``u`` on X_WS; the innovation is
    predicted minus measured, sigma m/s (Groves 2nd ed., chapters 6 and 16, odometers and their
    integration, section numbers not checked against the book; Shin 2005, a land vehicle's odometer)."""
    c = s[sd.S.C:sd.S.C + 9]
    a = dt / T if T > 0.0 else 0.0
    v0 = s[sd.S.V] - a * (s[sd.S.V] - s[sd.S.VP])
    v1 = s[sd.S.V + 1] - a * (s[sd.S.V + 1] - s[sd.S.VP + 1])
    v2 = s[sd.S.V + 2] - a * (s[sd.S.V + 2] - s[sd.S.VP + 2])
    c0, c1, c2 = c[0], c[3], c[6]  # column 0 of C: row x of C^T
    u = c0 * v0 + c1 * v1 + c2 * v2 + w_ib[1] * lever[2] - w_ib[2] * lever[1]
    g = 1.0 + bias[B_WS]
    nu = np.empty(1)
    H = np.zeros((1, NX))
    R = np.zeros((1, 1))
    nu[0] = g * u - speed
    H[0, X_DV] = g * c0
    H[0, X_DV + 1] = g * c1
    H[0, X_DV + 2] = g * c2
    H[0, X_PHI] = g * (c1 * v2 - c2 * v1)
    H[0, X_PHI + 1] = g * (c2 * v0 - c0 * v2)
    H[0, X_PHI + 2] = g * (c0 * v1 - c1 * v0)
    for x0 in (X_BG, X_GG):  # (l x db)_x = l_y db_z - l_z db_y
        H[0, x0 + 1] = -g * lever[2]
        H[0, x0 + 2] = g * lever[1]
    H[0, X_WS] = u
    R[0, 0] = sigma * sigma
    return nu, H, R


# --- external vision: a camera's pose in its own local frame ----------------------------------------
# The frame V (a VIO camera's or a motion-capture system's: z down, origin and heading arbitrary) is placed by
# two states: its origin o (X_VP, NED metres from the reference point ``ref`` = lat, lon rad, h m, which
# LiveFilter fixes at the first pose) and its heading psi (X_VY: about down from north to V's x axis), so
# that a NED vector is ``Rz(psi)`` times the same vector in V. Rotating about one axis, Rz(psi + e) = Rz(psi)
# (I + e [z x]) with [z x] commuting with Rz (Groves 2nd ed., section 2.2, rotations about one axis).


@kernel
def _vision_axes(bias: np.ndarray) -> tuple[float, float]:
    """``(cos psi, sin psi)`` of the vision frame's heading estimate: ``Rz(psi) = [[c, -s, 0], [s, c, 0],
    [0, 0, 1]]`` takes V to NED."""
    return np.cos(bias[B_VY]), np.sin(bias[B_VY])


@kernel
def vision_relative(s: np.ndarray, cfg: np.ndarray, bias: np.ndarray, ref: np.ndarray, dt: float) -> np.ndarray:
    """``d = p(t_m) - o``: the body's NED metres from the vision frame's origin, ``dt`` s before the
    solution (``p(t_m) = p - v dt``, the module docstring), the position as :func:`gnss_position` takes it
    (metres per radian at the solution's latitude; the curvature over a camera's range, d^2 / 2R, is
    below 0.1 m at 1 km)."""
    lat, lon, h = sd.position(s, cfg, GEOGRAPHIC)
    mn, me = metres_per_radian(s, cfg)
    d = np.empty(3)
    d[0] = (lat - ref[0]) * mn - s[sd.S.V] * dt - bias[B_VP]
    d[1] = wrap_pi(lon - ref[1]) * me - s[sd.S.V + 1] * dt - bias[B_VP + 1]
    d[2] = (ref[2] - h) - s[sd.S.V + 2] * dt - bias[B_VP + 2]
    return d


@kernel
def vision_position(s: np.ndarray, cfg: np.ndarray, bias: np.ndarray, ref: np.ndarray, p_v: np.ndarray,
                    dt: float, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A camera's position ``p_v`` (m, in its frame V) measured ``dt`` s before the solution, 1-sigma per
    axis ``sigma`` (m, in V). Predicted ``Rz(psi)^T d`` (d of :func:`vision_relative`); with the errors
    estimate minus truth, ``Rz(psi + e)^T = Rz^T (I - e [z x])`` gives ``nu = Rz^T (dp - dt dv - do) - e Rz^T
    [z x] d`` to first order: H is ``Rz^T`` on dp, ``-dt Rz^T`` on dv, ``-Rz^T`` on X_VP and ``-Rz^T (z x d)``
    on X_VY, ``z x d = (-d_E, d_N, 0)`` (the same lever-free position model as :func:`gnss_position`, in a
    rotated and shifted frame)."""
    d = vision_relative(s, cfg, bias, ref, dt)
    c, sn = _vision_axes(bias)
    rt = np.array([[c, sn, 0.0], [-sn, c, 0.0], [0.0, 0.0, 1.0]])  # Rz(psi)^T
    zd0, zd1 = -d[1], d[0]
    nu = np.empty(3)
    H = np.zeros((3, NX))
    R = np.zeros((3, 3))
    for i in range(3):
        nu[i] = rt[i, 0] * d[0] + rt[i, 1] * d[1] + rt[i, 2] * d[2] - p_v[i]
        for j in range(3):
            H[i, X_DP + j] = rt[i, j]
            H[i, X_DV + j] = -dt * rt[i, j]
            H[i, X_VP + j] = -rt[i, j]
        H[i, X_VY] = -(rt[i, 0] * zd0 + rt[i, 1] * zd1)
        R[i, i] = sigma[i] * sigma[i]
    return nu, H, R


@kernel
def vision_attitude(s: np.ndarray, bias: np.ndarray, c_vb: np.ndarray, sigma: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A camera's attitude ``c_vb`` (3 x 3, body FRD to its frame V), 1-sigma ``sigma`` (rad) about each body
    axis. Its NED attitude is ``Rz(psi) c_vb``; with ``C(est) = (I + [phi x]) C`` and ``Rz(psi + e) = Rz (I +
    e [z x])`` the product ``M = C(est) (Rz(psi) c_vb)^T = (I + [phi x]) (I - e [z x])`` is the rotation
    ``phi - e z`` (first order). nu is M's rotation vector (exact for any angle: dcm_to_rotvec); H is I on
    phi and ``-z`` on X_VY; R is the body-axis noise in NED, ``C diag(sigma^2) C^T``."""
    cn = s[sd.S.C:sd.S.C + 9].reshape(3, 3)
    c, sn = _vision_axes(bias)
    meas = np.empty((3, 3))  # Rz(psi) c_vb: the camera's attitude in NED
    for j in range(3):
        meas[0, j] = c * c_vb[0, j] - sn * c_vb[1, j]
        meas[1, j] = sn * c_vb[0, j] + c * c_vb[1, j]
        meas[2, j] = c_vb[2, j]
    nu = dcm_to_rotvec(matmul_bt(cn.copy(), meas))
    H = np.zeros((3, NX))
    R = np.zeros((3, 3))
    for i in range(3):
        H[i, X_PHI + i] = 1.0
        for j in range(3):
            for k in range(3):
                R[i, j] += cn[i, k] * sigma[k] * sigma[k] * cn[j, k]
    H[2, X_VY] = -1.0
    return nu, H, R


@kernel
def vision_place(s: np.ndarray, cfg: np.ndarray, bias: np.ndarray, P: np.ndarray, ref: np.ndarray,
                 p_v: np.ndarray, c_vb: np.ndarray, dt: float, sigma_p: np.ndarray, sigma_att: np.ndarray) -> None:
    """Place the vision frame from one pose (its first, or the first after a ``reset_counter`` change): the
    heading ``psi`` (from ``yaw(C) - yaw(c_vb)``, refined until the attitude innovation has no down component)
    and origin ``o = p(t_m) - Rz(psi) p_v`` that make the pose's heading
    and position innovations zero, and their covariance with the rest of the state by augmentation: with
    the models' rows (:func:`vision_position`, :func:`vision_attitude`: ``0 = H_x x - e + n_z`` on the
    heading row, ``0 = H_x x - Rz^T do + b e + n_p`` on the position rows, b the X_VY column), ``e = H_x x +
    n_z`` and ``do = Rz (H_x x + b e + n_p)``: ``y = J x + L n``, so ``P_yx = J P``, ``P_yy = J P J^T + L N
    L^T`` (stochastic cloning of the state; Roumeliotis & Burdick, ICRA 2002, eq. 10-12, the augmentation
    of a state with a function of it). The pose's information is spent placing the frame, not fused."""
    cn = s[sd.S.C:sd.S.C + 9]
    bias[B_VY] = wrap_pi(np.arctan2(cn[3], cn[0]) - np.arctan2(c_vb[1, 0], c_vb[0, 0]))  # the Euler yaws equal
    for _ in range(2):  # then the innovation's down component zero (its H on X_VY is -1): Newton steps
        nu_a, _, _ = vision_attitude(s, bias, c_vb, sigma_att)
        bias[B_VY] = wrap_pi(bias[B_VY] + nu_a[2])
    for i in range(3):
        bias[B_VP + i] = 0.0
    d = vision_relative(s, cfg, bias, ref, dt)
    c, sn = _vision_axes(bias)
    bias[B_VP] = d[0] - (c * p_v[0] - sn * p_v[1])
    bias[B_VP + 1] = d[1] - (sn * p_v[0] + c * p_v[1])
    bias[B_VP + 2] = d[2] - p_v[2]
    _, hp, rp = vision_position(s, cfg, bias, ref, p_v, dt, sigma_p)
    _, ha, ra = vision_attitude(s, bias, c_vb, sigma_att)
    rz = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    b = hp[:, X_VY].copy()
    J = np.zeros((4, NX))
    for j in range(NX):
        if j < X_VP or j > X_VY:
            J[3, j] = ha[2, j]
            for i in range(3):
                for k in range(3):
                    J[i, j] += rz[i, k] * (hp[k, j] + b[k] * ha[2, j])
    sz2 = ra[2, 2]
    rb = mat_vec(rz, b)
    N = np.zeros((4, 4))
    for i in range(3):
        for j in range(3):
            N[i, j] = rb[i] * rb[j] * sz2
            for k in range(3):
                N[i, j] += rz[i, k] * rp[k, k] * rz[j, k]
        N[i, 3] = rb[i] * sz2
        N[3, i] = rb[i] * sz2
    N[3, 3] = sz2
    jp = matmul(J, P)
    pyy = matmul_bt(jp, J)
    for a in range(4):
        ya = X_VP + a
        for j in range(NX):
            if j < X_VP or j > X_VY:
                P[ya, j] = jp[a, j]
                P[j, ya] = jp[a, j]
        for k in range(4):  # symmetric to the last bit: the mean of the two triangles
            P[ya, X_VP + k] = 0.5 * (pyy[a, k] + pyy[k, a] + N[a, k] + N[k, a])


@kernel
def zupt(s: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zero-velocity update: the vehicle is at rest, v = 0 (sigma m/s per axis)."""
    nu = np.empty(3)
    H = np.zeros((3, NX))
    R = np.zeros((3, 3))
    for i in range(3):
        nu[i] = s[sd.S.V + i]
        H[i, X_DV + i] = 1.0
        R[i, i] = sigma * sigma
    return nu, H, R


@kernel
def zaru(
    s: np.ndarray, cfg: np.ndarray, bias: np.ndarray, w_raw: np.ndarray, sigma: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zero angular rate update: at rest the mean raw gyro rate ``w_raw`` (rad/s) is bias plus Earth rate.

    ``z = w_raw - C^T w_ie^n`` measures the gyro bias (const + Gauss-Markov
    part) and, through the Earth rate, the attitude: with
    ``C(true) = (I - [phi x]) C`` (this filter's phi),
    ``z = b + C^T [phi x] w_ie = b - C^T [w_ie x] phi``, so
    ``nu = b(est) - z`` has H = I on both bias parts and ``C^T [w_ie x]`` on
    phi (the static gyrocompass measurement, textbook ch. 4: a heading error
    psi shows as ``Omega cos(L) psi`` on the east gyro, the same as an east
    gyro bias, hence the heading limit ``b_E / (Omega cos L)``). sigma (rad/s)
    per axis, about ARW / sqrt(averaging time); the correlation between the
    averaged gyro noise and the attitude error is neglected.
    """
    c = s[sd.S.C : sd.S.C + 9].reshape(3, 3)
    w_ie = np.zeros(3)
    if cfg[sd.CFG_EARTH] > 0.5:
        lat, lon, h = sd.position(s, cfg, GEOGRAPHIC)
        w_ie = earth.earth_rate_n(lat)
    nu = np.empty(3)
    H = np.zeros((3, NX))
    R = np.zeros((3, 3))
    wx = skew(w_ie)
    for i in range(3):
        wb = c[0, i] * w_ie[0] + c[1, i] * w_ie[1] + c[2, i] * w_ie[2]
        nu[i] = bias[B_BG + i] + bias[B_GG + i] - (w_raw[i] - wb)
        H[i, X_BG + i] = 1.0
        H[i, X_GG + i] = 1.0
        for j in range(3):
            H[i, X_PHI + j] = c[0, i] * wx[0, j] + c[1, i] * wx[1, j] + c[2, i] * wx[2, j]
        R[i, i] = sigma * sigma
    return nu, H, R


@kernel
def initial_covariance(
    spec: np.ndarray, sigma_pos: float, sigma_vel: float, sigma_level: float, sigma_yaw: float, sigma_baro: float,
    sigma_mag_bias: float
) -> np.ndarray:
    """Diagonal initial P: position (m, each axis), velocity (m/s), level and yaw (rad), baro offset (m),
    magnetometer hard iron (its unit, each axis; 0: taken as calibrated, not estimated).

    The bias blocks take the spec's initial 1-sigma (constant part) and the
    stationary Gauss-Markov sigma, the scale factors and misalignments the spec's (0: not estimated).
    """
    P = np.zeros((NX, NX))
    for i in range(3):
        P[X_DP + i, X_DP + i] = sigma_pos * sigma_pos
        P[X_DV + i, X_DV + i] = sigma_vel * sigma_vel
        P[X_BG + i, X_BG + i] = spec[SP_GYRO_BIAS] ** 2
        P[X_BA + i, X_BA + i] = spec[SP_ACC_BIAS] ** 2
        P[X_GG + i, X_GG + i] = spec[SP_GYRO_GM] ** 2
        P[X_GA + i, X_GA + i] = spec[SP_ACC_GM] ** 2
        P[X_SG + i, X_SG + i] = spec[SP_GYRO_SCALE] ** 2
        P[X_SA + i, X_SA + i] = spec[SP_ACC_SCALE] ** 2
        P[X_MB + i, X_MB + i] = sigma_mag_bias * sigma_mag_bias
    for k in range(6):
        P[X_MG + k, X_MG + k] = spec[SP_GYRO_MIS] ** 2
        P[X_MA + k, X_MA + k] = spec[SP_ACC_MIS] ** 2
    P[X_PHI, X_PHI] = sigma_level * sigma_level
    P[X_PHI + 1, X_PHI + 1] = sigma_level * sigma_level
    P[X_PHI + 2, X_PHI + 2] = sigma_yaw * sigma_yaw
    P[X_BARO, X_BARO] = sigma_baro * sigma_baro
    P[X_WS, X_WS] = spec[SP_WHEEL_SCALE] ** 2
    return P
