"""Strapdown mechanisation: attitude, velocity and position on j/k/l cycles.

One implementation for every caller. The state lives in a flat float64 array
(layout below) so that the same compiled kernels run sample by sample in the
service (:func:`push_increment`, :func:`push_rate`) and over whole arrays in
the batch runner (:func:`run_increments`, :func:`run_rates`).

Computation rates ([TW11] 11.1 and 11.4 summary):

* j cycle, every IMU sample: buffer the increments (and, for instantaneous
  rates, the recursive coning/sculling sums);
* k cycle, every N samples: coning-compensated body rotation vector sigma,
  attitude update with the chosen order, specific-force transformation with
  rotation and sculling terms, velocity and position update;
* l cycle, every M k cycles: Earth rate, transport rate and gravity at the
  extrapolated mid-interval position and velocity.

Attitude update ([TW11] 11.2.1 and 11.2.4): ``C_b^n(k) = B C_b^n(k-1) A(sigma)``
with ``B = exp(-[zeta x])``, ``zeta = w_in^n T`` (the navigation frame's own
rotation); in quaternion form ``q(k) = r(-zeta) (x) q(k-1) (x) r(sigma)``.

Velocity ([TW11] 11.3, lecture eq. 11.64, and 11.4): ``v(k) = v(k-1) + u^n +
[g - (2 w_ie + w_en) x v]_mid T`` with ``u^n = (I - 1/2 [zeta x]) C_b^n(k-1)
(V + rot(sigma, V) + dv_scul)``; the ``-1/2 zeta x`` term is Savage's
navigation-frame rotation correction (Strapdown Analytics 7.2.2.2).

Position ([TW11] 11.4): ``C_n^e(k) = C_n^e(k-1) exp([xi x])``, ``xi =
w_en^n(v_eff) T``, ``h(k) = h(k-1) - v_D,eff T``, with v_eff from the
rectangular, trapezoidal or one-step Simpson (parabolic) rule.
"""

from __future__ import annotations

import numpy as np

from . import earth
from .coning import (
    MAX_SAMPLES,
    nsample_coning,
    nsample_sculling,
    rate_coning,
    rate_sculling,
    rotation_compensation,
)
from .jit import kernel
from .rotation import (
    cross,
    dcm_from_coeffs,
    dcm_to_euler,
    dcm_to_quat,
    mat_mul,
    mat_vec,
    euler_to_dcm,
    orthonormalize,
    quat_canonical,
    quat_from_coeffs,
    quat_mul,
    quat_to_dcm,
    rotvec_to_dcm,
    rotvec_to_quat,
)

# --- configuration vector -------------------------------------------------
CFG_SAMPLES = 0  # N, samples per k cycle (1..6)
CFG_DCM = 1  # 1 = DCM attitude, 0 = quaternion
CFG_ORDER = 2  # 1..4 truncated series, 0 = exact
CFG_EARTH = 3  # 1 = WGS-84, 0 = none (laboratory)
CFG_ORTHO_EVERY = 4  # DCM re-orthonormalisation period (k cycles), 0 = never
CFG_VHOLD = 5  # 1 = hold height and vertical velocity
CFG_CONING = 6  # 1 = coning and sculling corrections on
CFG_POSINT = 7  # 0 rectangular, 1 trapezoidal, 2 Simpson
CFG_L_EVERY = 8  # M, k cycles per l cycle
CFG_SAMPLED = 9  # push_rate: 1 = instantaneous samples, 0 = interval averages
CFG_SIZE = 10

POSINT = {"rectangular": 0, "trapezoidal": 1, "simpson": 2}
ORDERS = {"1": 1, "2": 2, "3": 3, "4": 4, "exact": 0}

# --- state vector ---------------------------------------------------------
S_T = 0  # time of the last k update (s)
S_Q = 1  # q_nb [w x y z]
S_C = 5  # C_b^n, row-major
S_V = 14  # v^n (m/s) at k
S_VP = 17  # v^n at k-1
S_VPP = 20  # v^n at k-2
S_CNE = 23  # C_n^e, row-major
S_H = 32  # ellipsoidal height (m)
S_PF = 33  # flat NED offset from the start (earth = none)
S_LAT0 = 36  # initial latitude (rad)
S_LON0 = 37  # initial longitude (rad)
S_H0 = 38  # initial height (m)
S_VD0 = 39  # initial down velocity (m/s)
S_WIE = 40  # l-cycle Earth rate in n (rad/s)
S_WEN = 43  # l-cycle transport rate in n (rad/s)
S_G = 46  # l-cycle gravity down (m/s^2)
S_G0 = 47  # gravity at the start (earth = none)
S_NK = 48  # k updates done
S_NJ = 49  # samples buffered in this k cycle
S_BUFT = 50  # summed interval of the buffered samples (s)
S_BTH = 51  # 6 x 3 angle increments buffer
S_BDV = 69  # 6 x 3 velocity increments buffer
S_CONE = 87  # recursive coning sum (sampled rates)
S_SCUL = 90  # recursive sculling sum (sampled rates)
S_ACCA = 93  # angle accumulated in this k cycle (sampled rates)
S_ACCV = 96  # velocity accumulated in this k cycle (sampled rates)
S_PW = 99  # previous rate sample w (sampled rates)
S_PFO = 102  # previous force sample f (sampled rates)
S_HAVEP = 105  # 1 once a previous rate sample exists
S_TJ = 106  # time of the last accepted sample (s)
S_NL = 107  # k cycles since the last l cycle
S_SIZE = 110

OUT_COLUMNS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw", "qw", "qx", "qy", "qz")
OUT_SIZE = len(OUT_COLUMNS)


def make_config(
    samples: int = 2,
    attitude: str = "quaternion",
    order: str = "exact",
    earth_model: str = "wgs84",
    orthonormalize_every: int = 1,
    vertical: str = "free",
    coning: bool = True,
    position: str = "trapezoidal",
    l_every: int = 1,
    imu_rates: str = "averaged",
) -> np.ndarray:
    """Build the configuration vector from the user-facing option names."""
    if not 1 <= samples <= MAX_SAMPLES:
        raise ValueError(f"samples must be 1..{MAX_SAMPLES}, got {samples}")
    if attitude not in ("quaternion", "dcm"):
        raise ValueError(f"attitude must be quaternion or dcm, got {attitude!r}")
    if str(order) not in ORDERS:
        raise ValueError(f"order must be 1, 2, 3, 4 or exact, got {order!r}")
    if earth_model not in ("wgs84", "none"):
        raise ValueError(f"earth must be wgs84 or none, got {earth_model!r}")
    if orthonormalize_every < 0:
        raise ValueError("orthonormalize_every must be >= 0")
    if vertical not in ("free", "hold"):
        raise ValueError(f"vertical must be free or hold, got {vertical!r}")
    if position not in POSINT:
        raise ValueError(f"position must be one of {sorted(POSINT)}, got {position!r}")
    if l_every < 1:
        raise ValueError("l_every must be >= 1")
    if imu_rates not in ("averaged", "sampled"):
        raise ValueError(f"imu_rates must be averaged or sampled, got {imu_rates!r}")
    cfg = np.zeros(CFG_SIZE)
    cfg[CFG_SAMPLES] = samples
    cfg[CFG_DCM] = 1.0 if attitude == "dcm" else 0.0
    cfg[CFG_ORDER] = ORDERS[str(order)]
    cfg[CFG_EARTH] = 1.0 if earth_model == "wgs84" else 0.0
    cfg[CFG_ORTHO_EVERY] = orthonormalize_every
    cfg[CFG_VHOLD] = 1.0 if vertical == "hold" else 0.0
    cfg[CFG_CONING] = 1.0 if coning and samples >= 2 else 0.0
    cfg[CFG_POSINT] = POSINT[position]
    cfg[CFG_L_EVERY] = l_every
    cfg[CFG_SAMPLED] = 1.0 if imu_rates == "sampled" else 0.0
    return cfg


@kernel
def init_state(
    t: float, lat: float, lon: float, h: float, v: np.ndarray, roll: float, pitch: float, yaw: float
) -> np.ndarray:
    """A fresh state at time t (s); angles and lat/lon in rad, h in m, v NED m/s."""
    s = np.zeros(S_SIZE)
    s[S_T] = t
    s[S_TJ] = t
    c = euler_to_dcm(roll, pitch, yaw)
    s[S_C : S_C + 9] = c.ravel()
    s[S_Q : S_Q + 4] = dcm_to_quat(c)
    for i in range(3):
        s[S_V + i] = v[i]
        s[S_VP + i] = v[i]
        s[S_VPP + i] = v[i]
    s[S_CNE : S_CNE + 9] = earth.cne_from_latlon(lat, lon).ravel()
    s[S_H] = h
    s[S_LAT0] = lat
    s[S_LON0] = lon
    s[S_H0] = h
    s[S_VD0] = v[2]
    s[S_G0] = earth.gravity(lat, h)
    return s


@kernel
def position(s: np.ndarray, cfg: np.ndarray) -> tuple[float, float, float]:
    """Latitude, longitude (rad) and height (m) of the state."""
    if cfg[CFG_EARTH] > 0.5:
        lat, lon = earth.latlon_from_cne(s[S_CNE : S_CNE + 9].reshape(3, 3))
        return lat, lon, s[S_H]
    # earth = none: flat NED offset mapped through the start point's radii.
    r_n, r_e = earth.radii(s[S_LAT0])
    h0 = s[S_H0]
    lat = s[S_LAT0] + s[S_PF] / (r_n + h0)
    lon = s[S_LON0] + s[S_PF + 1] / ((r_e + h0) * np.cos(s[S_LAT0]))
    return lat, lon, h0 - s[S_PF + 2]


@kernel
def solution_row(s: np.ndarray, cfg: np.ndarray, out: np.ndarray) -> None:
    """Write ``t,lat,lon,h,vn,ve,vd,roll,pitch,yaw,qw,qx,qy,qz`` (rad) into out."""
    lat, lon, h = position(s, cfg)
    out[0] = s[S_T]
    out[1] = lat
    out[2] = lon
    out[3] = h
    out[4] = s[S_V]
    out[5] = s[S_V + 1]
    out[6] = s[S_V + 2]
    e = dcm_to_euler(s[S_C : S_C + 9].reshape(3, 3))
    out[7] = e[0]
    out[8] = e[1]
    out[9] = e[2]
    q = quat_canonical(s[S_Q : S_Q + 4])
    out[10] = q[0]
    out[11] = q[1]
    out[12] = q[2]
    out[13] = q[3]


@kernel
def body_update_quat(sigma: np.ndarray, order: int) -> np.ndarray:
    """Quaternion of the body rotation vector, truncated to ``order``.

    ``r = [a_c, a_s sigma]`` with ``(a_c, a_s)`` = (1, 1/2), (1 - s^2/8, 1/2),
    (1 - s^2/8, 1/2 - s^2/48), (1 - s^2/8 + s^4/384, 1/2 - s^2/48) for orders
    1..4 and the exact ``(cos s/2, sin(s/2)/s)`` for order 0 ([TW11] 11.2.1
    quaternion error analysis and table 11.2; CONVENTIONS.md ``--order``).
    """
    if order == 0:
        return rotvec_to_quat(sigma)
    s2 = sigma[0] * sigma[0] + sigma[1] * sigma[1] + sigma[2] * sigma[2]
    if order == 1:
        ac, as_ = 1.0, 0.5
    elif order == 2:
        ac, as_ = 1.0 - s2 / 8.0, 0.5
    elif order == 3:
        ac, as_ = 1.0 - s2 / 8.0, 0.5 - s2 / 48.0
    else:
        ac, as_ = 1.0 - s2 / 8.0 + s2 * s2 / 384.0, 0.5 - s2 / 48.0
    return quat_from_coeffs(sigma, ac, as_)


@kernel
def body_update_dcm(sigma: np.ndarray, order: int) -> np.ndarray:
    """``A = I + a1 [s x] + a2 [s x]^2`` truncated to ``order``.

    ``(a1, a2)`` = (1, 0), (1, 1/2), (1 - s^2/6, 1/2), (1 - s^2/6, 1/2 - s^2/24)
    for orders 1..4, exact ``(sin s/s, (1 - cos s)/s^2)`` for order 0
    ([TW11] slide "11.2.1 DCM algorithm"; CONVENTIONS.md ``--order``).
    """
    if order == 0:
        return rotvec_to_dcm(sigma)
    s2 = sigma[0] * sigma[0] + sigma[1] * sigma[1] + sigma[2] * sigma[2]
    if order == 1:
        a1, a2 = 1.0, 0.0
    elif order == 2:
        a1, a2 = 1.0, 0.5
    elif order == 3:
        a1, a2 = 1.0 - s2 / 6.0, 0.5
    else:
        a1, a2 = 1.0 - s2 / 6.0, 0.5 - s2 / 24.0
    return dcm_from_coeffs(sigma, a1, a2)


@kernel
def _l_cycle(s: np.ndarray, cfg: np.ndarray, T: float, v_mid: np.ndarray) -> None:
    """Slow terms at the extrapolated mid-interval point (l cycle)."""
    if cfg[CFG_EARTH] < 0.5:
        for i in range(3):
            s[S_WIE + i] = 0.0
            s[S_WEN + i] = 0.0
        s[S_G] = s[S_G0]
        return
    lat, lon, h = position(s, cfg)
    r_n, r_e = earth.radii(lat)
    lat_mid = lat + 0.5 * T * v_mid[0] / (r_n + h)
    h_mid = h - 0.5 * T * v_mid[2]
    s[S_WIE : S_WIE + 3] = earth.earth_rate_n(lat_mid)
    s[S_WEN : S_WEN + 3] = earth.transport_rate(lat_mid, h_mid, v_mid)
    s[S_G] = earth.gravity(lat_mid, h_mid)


@kernel
def k_update(s: np.ndarray, cfg: np.ndarray) -> None:
    """One attitude/velocity/position update over the buffered samples (k cycle).

    Vector arithmetic is written on scalars so the update allocates only a few
    small arrays (it runs once per N samples, up to several kHz).
    """
    n = int(s[S_NJ])
    T = s[S_BUFT]
    dth = s[S_BTH : S_BTH + 18].reshape(6, 3)
    dvs = s[S_BDV : S_BDV + 18].reshape(6, 3)
    sigma = np.zeros(3)
    vsum = np.zeros(3)
    for i in range(n):
        for a in range(3):
            sigma[a] += dth[i, a]
            vsum[a] += dvs[i, a]

    # Body rotation vector and sculling ([TW11] 11.2.2, 11.3; coning.py).
    scx = scy = scz = 0.0
    if cfg[CFG_CONING] > 0.5 and n >= 2:
        if cfg[CFG_SAMPLED] > 0.5:
            for a in range(3):
                sigma[a] += s[S_CONE + a]
            scx, scy, scz = s[S_SCUL], s[S_SCUL + 1], s[S_SCUL + 2]
        else:
            cone = nsample_coning(dth, n)
            scul = nsample_sculling(dth, dvs, n)
            for a in range(3):
                sigma[a] += cone[a]
            scx, scy, scz = scul[0], scul[1], scul[2]

    vox, voy, voz = s[S_V], s[S_V + 1], s[S_V + 2]
    vpx, vpy, vpz = s[S_VP], s[S_VP + 1], s[S_VP + 2]
    # Mid-interval velocity extrapolated from the last two updates ([TW11] 11.4,
    # Coriolis and gravity "evaluated at the l rate").
    vmx, vmy, vmz = 1.5 * vox - 0.5 * vpx, 1.5 * voy - 0.5 * vpy, 1.5 * voz - 0.5 * vpz
    if int(s[S_NL]) % int(cfg[CFG_L_EVERY]) == 0:
        _l_cycle(s, cfg, T, np.array([vmx, vmy, vmz]))
    s[S_NL] += 1.0
    wix, wiy, wiz = s[S_WIE], s[S_WIE + 1], s[S_WIE + 2]
    wex, wey, wez = s[S_WEN], s[S_WEN + 1], s[S_WEN + 2]
    zx, zy, zz = (wix + wex) * T, (wiy + wey) * T, (wiz + wez) * T

    # Specific-force transformation ([TW11] 11.3, eq. 11.64) with Savage's
    # rotation term and the navigation-frame rotation correction -1/2 zeta x u.
    rc = rotation_compensation(sigma, vsum)
    bx = vsum[0] + rc[0] + scx
    by = vsum[1] + rc[1] + scy
    bz = vsum[2] + rc[2] + scz
    c = s[S_C : S_C + 9]
    ux = c[0] * bx + c[1] * by + c[2] * bz
    uy = c[3] * bx + c[4] * by + c[5] * bz
    uz = c[6] * bx + c[7] * by + c[8] * bz
    ux, uy, uz = ux - 0.5 * (zy * uz - zz * uy), uy - 0.5 * (zz * ux - zx * uz), uz - 0.5 * (zx * uy - zy * ux)
    ox, oy, oz = 2.0 * wix + wex, 2.0 * wiy + wey, 2.0 * wiz + wez
    vnx = vox + ux - (oy * vmz - oz * vmy) * T
    vny = voy + uy - (oz * vmx - ox * vmz) * T
    vnz = voz + uz - (ox * vmy - oy * vmx) * T + s[S_G] * T
    if cfg[CFG_VHOLD] > 0.5:
        vnz = s[S_VD0]

    # Attitude: body update A(sigma), navigation-frame update B = exp(-zeta).
    order = int(cfg[CFG_ORDER])
    mzeta = np.array([-zx, -zy, -zz])
    if cfg[CFG_DCM] > 0.5:
        c_old = c.reshape(3, 3)
        c_new = mat_mul(mat_mul(rotvec_to_dcm(mzeta), c_old), body_update_dcm(sigma, order))
        k = int(cfg[CFG_ORTHO_EVERY])
        if k > 0 and (int(s[S_NK]) + 1) % k == 0:
            c_new = orthonormalize(c_new)
        s[S_C : S_C + 9] = c_new.ravel()
        s[S_Q : S_Q + 4] = dcm_to_quat(c_new)
    else:
        q = quat_mul(rotvec_to_quat(mzeta), quat_mul(s[S_Q : S_Q + 4], body_update_quat(sigma, order)))
        qn = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        for a in range(4):
            s[S_Q + a] = q[a] / qn
        s[S_C : S_C + 9] = quat_to_dcm(s[S_Q : S_Q + 4]).ravel()

    # Position ([TW11] 11.4 rectangular / trapezoidal / Simpson).
    rule = int(cfg[CFG_POSINT])
    if rule == 0:
        ex, ey, ez = vox, voy, voz
    elif rule == 1:
        ex, ey, ez = 0.5 * (vox + vnx), 0.5 * (voy + vny), 0.5 * (voz + vnz)
    else:
        # One-step parabola through v(k-2), v(k-1), v(k) integrated over the
        # last interval: (-v(k-2) + 8 v(k-1) + 5 v(k)) / 12. The lecture's
        # printed Simpson line covers two intervals with one-interval weights;
        # see docs/algorithms.md.
        ex = (-vpx + 8.0 * vox + 5.0 * vnx) / 12.0
        ey = (-vpy + 8.0 * voy + 5.0 * vny) / 12.0
        ez = (-vpz + 8.0 * voz + 5.0 * vnz) / 12.0
    if cfg[CFG_EARTH] > 0.5:
        lat, lon, h = position(s, cfg)
        r_n, r_e = earth.radii(lat)
        lat_mid = lat + 0.5 * T * ex / (r_n + h)
        h_mid = h - 0.5 * T * ez
        xi = earth.transport_rate(lat_mid, h_mid, np.array([ex, ey, ez])) * T
        cne = mat_mul(s[S_CNE : S_CNE + 9].reshape(3, 3), rotvec_to_dcm(xi))
        s[S_CNE : S_CNE + 9] = cne.ravel()
    else:
        s[S_PF] += ex * T
        s[S_PF + 1] += ey * T
        s[S_PF + 2] += ez * T
    if cfg[CFG_VHOLD] > 0.5:
        s[S_H] = s[S_H0]
        s[S_PF + 2] = 0.0
    else:
        s[S_H] -= ez * T

    s[S_VPP], s[S_VPP + 1], s[S_VPP + 2] = vpx, vpy, vpz
    s[S_VP], s[S_VP + 1], s[S_VP + 2] = vox, voy, voz
    s[S_V], s[S_V + 1], s[S_V + 2] = vnx, vny, vnz
    s[S_T] = s[S_TJ]
    s[S_NK] += 1.0
    s[S_NJ] = 0.0
    s[S_BUFT] = 0.0
    for i in range(S_CONE, S_ACCV + 3):
        s[i] = 0.0


@kernel
def push_increment(s: np.ndarray, cfg: np.ndarray, t: float, dtheta: np.ndarray, dv: np.ndarray) -> int:
    """Feed one increment row covering (t_prev, t] (j cycle).

    Returns 1 when the sample completed a k cycle (a new solution exists),
    0 when it was buffered, -1 when rejected because t is not after the last
    accepted sample.
    """
    dt = t - s[S_TJ]
    if not dt > 0.0:
        return -1
    j = int(s[S_NJ])
    for i in range(3):
        s[S_BTH + 3 * j + i] = dtheta[i]
        s[S_BDV + 3 * j + i] = dv[i]
    s[S_NJ] = j + 1
    s[S_BUFT] += dt
    s[S_TJ] = t
    if j + 1 >= int(cfg[CFG_SAMPLES]):
        k_update(s, cfg)
        return 1
    return 0


@kernel
def push_rate(s: np.ndarray, cfg: np.ndarray, t: float, w: np.ndarray, f: np.ndarray) -> int:
    """Feed one rate sample (rad/s, m/s^2 in FRD); same return codes as push_increment.

    Averaged rates: ``dtheta = w dt`` exactly. Instantaneous rates: increments
    by the trapezoid rule and the piecewise-linear coning/sculling terms of
    coning.py; a sample at the start time only opens the first interval, and
    without one the first sample's values hold back to the start (CONVENTIONS.md
    "Sensor data").
    """
    t_last = s[S_TJ]
    if cfg[CFG_SAMPLED] < 0.5:
        if not t > t_last:
            return -1
        dt = t - t_last
        return push_increment(s, cfg, t, w * dt, f * dt)
    if s[S_HAVEP] < 0.5:
        if t < t_last:
            return -1
        s[S_PW : S_PW + 3] = w
        s[S_PFO : S_PFO + 3] = f
        s[S_HAVEP] = 1.0
        if t == t_last:
            return 0
    if not t > t_last:
        return -1
    h = t - t_last
    w0 = s[S_PW : S_PW + 3].copy()
    f0 = s[S_PFO : S_PFO + 3].copy()
    dth = 0.5 * (w0 + w) * h
    dvv = 0.5 * (f0 + f) * h
    acc_a = s[S_ACCA : S_ACCA + 3]
    acc_v = s[S_ACCV : S_ACCV + 3]
    s[S_CONE : S_CONE + 3] += 0.5 * cross(acc_a, dth) + rate_coning(w0, w, h)
    s[S_SCUL : S_SCUL + 3] += 0.5 * (cross(acc_a, dvv) + cross(acc_v, dth)) + rate_sculling(w0, f0, w, f, h)
    s[S_ACCA : S_ACCA + 3] += dth
    s[S_ACCV : S_ACCV + 3] += dvv
    s[S_PW : S_PW + 3] = w
    s[S_PFO : S_PFO + 3] = f
    return push_increment(s, cfg, t, dth, dvv)


@kernel
def push_rate_scalars(
    s: np.ndarray, cfg: np.ndarray, t: float, wx: float, wy: float, wz: float, fx: float, fy: float, fz: float
) -> int:
    """:func:`push_rate` with the sample as scalars (cheaper to call from Python, same update)."""
    w = np.empty(3)
    f = np.empty(3)
    w[0], w[1], w[2] = wx, wy, wz
    f[0], f[1], f[2] = fx, fy, fz
    return push_rate(s, cfg, t, w, f)


@kernel
def run_increments(
    s: np.ndarray, cfg: np.ndarray, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, out: np.ndarray
) -> int:
    """Batch j/k loop over increment rows; writes one solution row per k update.

    ``out`` needs at least ``len(t) // N`` rows; returns the number written.
    """
    m = 0
    for i in range(t.shape[0]):
        if push_increment(s, cfg, t[i], dtheta[i], dv[i]) == 1:
            solution_row(s, cfg, out[m])
            m += 1
    return m


@kernel
def run_rates(s: np.ndarray, cfg: np.ndarray, t: np.ndarray, w: np.ndarray, f: np.ndarray, out: np.ndarray) -> int:
    """Batch loop over rate rows (rows before the state's time are skipped)."""
    m = 0
    t0 = s[S_TJ]
    for i in range(t.shape[0]):
        if t[i] < t0:
            continue
        if push_rate(s, cfg, t[i], w[i], f[i]) == 1:
            solution_row(s, cfg, out[m])
            m += 1
    return m
