"""Compiled evaluation of a simulated motion: truth and IMU rates at any time.

A motion is described by arrays (built by sim.trajectory):

* channels (roll, pitch, yaw, horizontal speed, down velocity, turntable
  angles): piecewise polynomials of degree <= 6 in the local time u in [0, 1],
  so value and rate are exact at any t;
* perturbations composed onto the vehicle: angular vibration
  ``exp(phi(t))`` with ``phi`` a sum of sinusoids, classic coning, linear
  vibration (sum of sinusoids of NED acceleration);
* the IMU frame s is the vehicle frame turned by a turntable:
  ``C_s^v = Rz(a1) Rx(a2)``.

IMU rates follow the navigation equations the strapdown core inverts
([TW11] 11.1): ``w_ib = w_nb + C_n^b (w_ie + w_en)``,
``f^b = C_n^b (dv_n/dt + (2 w_ie + w_en) x v_n - g_n)``, with the body rate of
``exp(phi)`` from the right Jacobian ``J_r(phi) phi'`` (Bortz 1971).
"""

from __future__ import annotations

import numpy as np

from mavins.core import earth
from mavins.core.jit import kernel
from mavins.core.rotation import cross, dcm_to_quat, euler_to_dcm, mat_mul, mat_vec, quat_conj, quat_mul, quat_to_dcm, rotvec_to_dcm

CH_ROLL, CH_PITCH, CH_YAW, CH_SPEED, CH_VD, CH_TT1, CH_TT2 = range(7)
N_CHANNELS = 7

# consts vector: coning half-angle (rad), coning rate (rad/s), laboratory gravity (m/s^2)
K_BETA, K_WCONE, K_GLAB = range(3)

# Gauss-Legendre 5-point nodes and weights on [0, 1].
_GL_X = np.array([-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831, 0.9061798459386640])
_GL_W = np.array([0.2369268850561891, 0.4786286704993665, 0.5688888888888889, 0.4786286704993665, 0.2369268850561891])
GL_NODES = 0.5 * (_GL_X + 1.0)
GL_WEIGHTS = 0.5 * _GL_W


@kernel
def channel_eval(starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, count: int, t: float) -> tuple[float, float]:
    """Value and rate of one channel at time t (held constant-rate beyond its ends)."""
    k = np.searchsorted(starts[:count], t, side="right") - 1
    if k < 0:
        k = 0
    d = durs[k]
    u = (t - starts[k]) / d
    c = coefs[k]
    if u > 1.0:
        # beyond the last piece: continue with the end value and rate
        v1 = c[0] + c[1] + c[2] + c[3] + c[4] + c[5] + c[6]
        r1 = (c[1] + 2 * c[2] + 3 * c[3] + 4 * c[4] + 5 * c[5] + 6 * c[6]) / d
        return v1 + r1 * (u - 1.0) * d, r1
    if u < 0.0:
        return c[0] + c[1] * u, c[1] / d
    val = c[6]
    for j in range(5, -1, -1):
        val = val * u + c[j]
    der = 6.0 * c[6]
    for j in range(5, 0, -1):
        der = der * u + j * c[j]
    return val, der / d


@kernel
def right_jacobian_rate(phi: np.ndarray, phidot: np.ndarray) -> np.ndarray:
    """Body rate of ``exp([phi x])``: ``J_r(phi) phi'`` (Bortz 1971)."""
    a2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    if a2 < 1e-12:
        b1 = 0.5 - a2 / 24.0
        b2 = 1.0 / 6.0 - a2 / 120.0
    else:
        a = np.sqrt(a2)
        b1 = (1.0 - np.cos(a)) / a2
        b2 = (a - np.sin(a)) / (a2 * a)
    c1 = cross(phi, phidot)
    return phidot - b1 * c1 + b2 * cross(phi, c1)


@kernel
def vehicle_state(
    t: float, starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, counts: np.ndarray, linvib: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Vehicle Euler angles, their rates, NED velocity and acceleration at t."""
    e = np.empty(3)
    ed = np.empty(3)
    for i in range(3):
        e[i], ed[i] = channel_eval(starts[i], durs[i], coefs[i], counts[i], t)
    spd, spd_d = channel_eval(starts[CH_SPEED], durs[CH_SPEED], coefs[CH_SPEED], counts[CH_SPEED], t)
    vd, vd_d = channel_eval(starts[CH_VD], durs[CH_VD], coefs[CH_VD], counts[CH_VD], t)
    cy, sy = np.cos(e[2]), np.sin(e[2])
    v = np.empty(3)
    a = np.empty(3)
    v[0] = spd * cy
    v[1] = spd * sy
    v[2] = vd
    a[0] = spd_d * cy - spd * ed[2] * sy
    a[1] = spd_d * sy + spd * ed[2] * cy
    a[2] = vd_d
    for k in range(linvib.shape[0]):
        w = linvib[k, 3]
        ph = w * t + linvib[k, 4]
        for i in range(3):
            v[i] += -linvib[k, i] / w * np.cos(ph)
            a[i] += linvib[k, i] * np.sin(ph)
    return e, ed, v, a


@kernel
def perturbation(t: float, vib: np.ndarray, consts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """DCM ``C_p^v`` and body rate (rad/s) of the angular perturbations at t.

    Angular vibration ``exp(phi(t))``, then classic coning relative to its
    start: ``q_c(0)^-1 (x) q_c(t)`` with the cone rate of sim.motion.classic_coning.
    """
    phi = np.zeros(3)
    phid = np.zeros(3)
    for k in range(vib.shape[0]):
        w = vib[k, 3]
        ph = w * t + vib[k, 4]
        s, c = np.sin(ph), np.cos(ph)
        for i in range(3):
            phi[i] += vib[k, i] * s
            phid[i] += vib[k, i] * w * c
    c_p = rotvec_to_dcm(phi)
    w_p = right_jacobian_rate(phi, phid)
    beta, wc = consts[K_BETA], consts[K_WCONE]
    if beta != 0.0:
        # q_c(t) = [cos b/2, sin b/2 cos wt, sin b/2 sin wt, 0], taken relative to t = 0
        hb = 0.5 * beta
        q0 = np.array([np.cos(hb), np.sin(hb), 0.0, 0.0])
        qt = np.array([np.cos(hb), np.sin(hb) * np.cos(wc * t), np.sin(hb) * np.sin(wc * t), 0.0])
        c_c = quat_to_dcm(quat_mul(quat_conj(q0), qt))
        sb = np.sin(beta)
        w_c = np.array([-wc * sb * np.sin(wc * t), wc * sb * np.cos(wc * t), -wc * (1.0 - np.cos(beta))])
        w_p = mat_vec(c_c.T, w_p) + w_c
        c_p = mat_mul(c_p, c_c)
    return c_p, w_p


@kernel
def turntable(t: float, starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """``C_s^v = Rz(a1) Rx(a2)``, the IMU's rate relative to the vehicle (in s), angles a1, a2."""
    a1, r1 = channel_eval(starts[CH_TT1], durs[CH_TT1], coefs[CH_TT1], counts[CH_TT1], t)
    a2, r2 = channel_eval(starts[CH_TT2], durs[CH_TT2], coefs[CH_TT2], counts[CH_TT2], t)
    c = euler_to_dcm(a2, 0.0, a1)
    # rate of Rz(a1) Rx(a2) in s: Rx(a2)^T [0, 0, r1] + [r2, 0, 0]
    w = np.empty(3)
    ca, sa = np.cos(a2), np.sin(a2)
    w[0] = r2
    w[1] = sa * r1
    w[2] = ca * r1
    return c, w, a1, a2


@kernel
def imu_rates(
    t: float,
    lat: float,
    h: float,
    starts: np.ndarray,
    durs: np.ndarray,
    coefs: np.ndarray,
    counts: np.ndarray,
    vib: np.ndarray,
    consts: np.ndarray,
    linvib: np.ndarray,
    use_earth: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """True ``w_is^s`` (rad/s) and ``f^s`` (m/s^2) of the IMU at t, latitude, height."""
    e, ed, v, a = vehicle_state(t, starts, durs, coefs, counts, linvib)
    c_vn = euler_to_dcm(e[0], e[1], e[2])
    sr, cr = np.sin(e[0]), np.cos(e[0])
    sp, cp = np.sin(e[1]), np.cos(e[1])
    w_nv = np.empty(3)
    w_nv[0] = ed[0] - ed[2] * sp
    w_nv[1] = ed[1] * cr + ed[2] * sr * cp
    w_nv[2] = -ed[1] * sr + ed[2] * cr * cp
    if use_earth:
        w_ie = earth.earth_rate_n(lat)
        w_en = earth.transport_rate(lat, h, v)
        g = earth.gravity(lat, h)
    else:
        w_ie = np.zeros(3)
        w_en = np.zeros(3)
        g = consts[K_GLAB]
    c_nv = c_vn.T
    w_iv = w_nv + mat_vec(c_nv, w_ie + w_en)
    acc = a + cross(2.0 * w_ie + w_en, v)
    acc[2] -= g
    f_v = mat_vec(c_nv, acc)
    c_pv, w_p = perturbation(t, vib, consts)
    w_ip = mat_vec(c_pv.T, w_iv) + w_p
    f_p = mat_vec(c_pv.T, f_v)
    c_sp, w_t, _, _ = turntable(t, starts, durs, coefs, counts)
    w_is = mat_vec(c_sp.T, w_ip) + w_t
    f_s = mat_vec(c_sp.T, f_p)
    return w_is, f_s


@kernel
def integrate(
    t0: float,
    t: np.ndarray,
    substeps: int,
    lat0: float,
    lon0: float,
    h0: float,
    starts: np.ndarray,
    durs: np.ndarray,
    coefs: np.ndarray,
    counts: np.ndarray,
    vib: np.ndarray,
    consts: np.ndarray,
    linvib: np.ndarray,
    use_earth: bool,
    breaks: np.ndarray,
    dtheta: np.ndarray,
    dv: np.ndarray,
    pos: np.ndarray,
) -> None:
    """Exact IMU increments and the true position at every sample time.

    Position: classical RK4 on ``L' = v_N/(R_N+h)``, ``lon' = v_E/((R_E+h) cos L)``,
    ``h' = -v_D`` at ``substeps`` per sample. Increments: 5-point Gauss-Legendre
    quadrature of the IMU rates on each sub-step, with latitude and height at the
    nodes from a cubic Hermite interpolation of the RK4 solution. Sample
    intervals are first split at every channel piece boundary in ``breaks``
    (sorted), so each quadrature spans one smooth piece. With ``use_earth``
    false, position is the flat NED offset (north m, east m, -h).
    """
    lat, lon, h = lat0, lon0, h0
    tp = t0
    nb = breaks.shape[0]
    edges = np.empty(nb + 2)
    for i in range(t.shape[0]):
        ti = t[i]
        k0 = np.searchsorted(breaks, tp, side="right")
        k1 = np.searchsorted(breaks, ti, side="left")
        ne = 0
        edges[ne] = tp
        ne += 1
        for k in range(k0, k1):
            edges[ne] = breaks[k]
            ne += 1
        edges[ne] = ti
        ne += 1
        acc_th = np.zeros(3)
        acc_v = np.zeros(3)
        for piece in range(ne - 1):
            ta0 = edges[piece]
            hstep = (edges[piece + 1] - ta0) / substeps
            for j in range(substeps):
                ta = ta0 + j * hstep
                y0 = np.array([lat, lon, h])
                k1v = _pos_rate(ta, y0, starts, durs, coefs, counts, linvib, use_earth)
                k2v = _pos_rate(ta + 0.5 * hstep, y0 + 0.5 * hstep * k1v, starts, durs, coefs, counts, linvib, use_earth)
                k3v = _pos_rate(ta + 0.5 * hstep, y0 + 0.5 * hstep * k2v, starts, durs, coefs, counts, linvib, use_earth)
                k4v = _pos_rate(ta + hstep, y0 + hstep * k3v, starts, durs, coefs, counts, linvib, use_earth)
                y1 = y0 + hstep / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
                m1 = _pos_rate(ta + hstep, y1, starts, durs, coefs, counts, linvib, use_earth)
                for g in range(5):
                    x = GL_NODES[g]
                    h00 = 2 * x**3 - 3 * x**2 + 1
                    h10 = x**3 - 2 * x**2 + x
                    h01 = -2 * x**3 + 3 * x**2
                    h11 = x**3 - x**2
                    yn = h00 * y0 + h10 * hstep * k1v + h01 * y1 + h11 * hstep * m1
                    w_s, f_s = imu_rates(ta + x * hstep, yn[0], yn[2], starts, durs, coefs, counts, vib, consts,
                                         linvib, use_earth)
                    acc_th += GL_WEIGHTS[g] * hstep * w_s
                    acc_v += GL_WEIGHTS[g] * hstep * f_s
                lat, lon, h = y1[0], y1[1], y1[2]
        dtheta[i] = acc_th
        dv[i] = acc_v
        pos[i, 0] = lat
        pos[i, 1] = lon
        pos[i, 2] = h
        tp = ti


@kernel
def _pos_rate(
    t: float, y: np.ndarray, starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, counts: np.ndarray,
    linvib: np.ndarray, use_earth: bool,
) -> np.ndarray:
    _, _, v, _ = vehicle_state(t, starts, durs, coefs, counts, linvib)
    out = np.empty(3)
    if use_earth:
        r_n, r_e = earth.radii(y[0])
        out[0] = v[0] / (r_n + y[2])
        out[1] = v[1] / ((r_e + y[2]) * np.cos(y[0]))
        out[2] = -v[2]
    else:
        out[0] = v[0]
        out[1] = v[1]
        out[2] = -v[2]
    return out


@kernel
def truth(
    t: np.ndarray,
    starts: np.ndarray,
    durs: np.ndarray,
    coefs: np.ndarray,
    counts: np.ndarray,
    vib: np.ndarray,
    consts: np.ndarray,
    linvib: np.ndarray,
    out: np.ndarray,
) -> None:
    """True velocity and attitudes at each t: rows ``vn, ve, vd, q_ns[4], q_nv[4], a1, a2``.

    ``q_ns`` is the IMU's attitude (what the strapdown solution estimates),
    ``q_nv`` the vehicle's (angular vibration and coning included), a1/a2 the
    turntable angles (rad).
    """
    for i in range(t.shape[0]):
        e, _, v, _ = vehicle_state(t[i], starts, durs, coefs, counts, linvib)
        c_pv, _ = perturbation(t[i], vib, consts)
        c_sp, _, a1, a2 = turntable(t[i], starts, durs, coefs, counts)
        c_nv = mat_mul(euler_to_dcm(e[0], e[1], e[2]), c_pv)
        q_nv = dcm_to_quat(c_nv)
        q_ns = dcm_to_quat(mat_mul(c_nv, c_sp))
        out[i, 0:3] = v
        out[i, 3:7] = q_ns
        out[i, 7:11] = q_nv
        out[i, 11] = a1
        out[i, 12] = a2
