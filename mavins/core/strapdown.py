"""Strapdown mechanisation: attitude, velocity and position on j/k/l cycles.

One implementation for every caller. The state lives in a flat float64 array
(layout below) so that the same compiled kernels run sample by sample in the
service (:func:`push_increment`, :func:`push_rate`) and over whole arrays in
the batch runner (:func:`run_increments`, :func:`run_rates`).

Computation rates ([TW11] 11.1 and 11.4 summary):

* j cycle, every IMU sample: buffer the increments (and, for instantaneous
  rates, the recursive coning/sculling sums);
* k cycle, every N samples: coning-compensated body rotation vector sigma,
  specific-force transformation with rotation and sculling terms, velocity,
  position, and attitude update with the chosen order;
* l cycle, every M k cycles: Earth rate, transport rate and gravity at the
  extrapolated mid-interval position and velocity.

Velocity ([TW11] 11.3, lecture eq. 11.64, and 11.4): ``v(k) = v(k-1) + u^n +
[g - (2 w_ie + w_en) x v]_mid T`` with ``u^n = (I - 1/2 [zeta x] + 1/12 [zeta x]^2 +
1/12 [dzeta x]) C_b^n(k-1) (V + rot(sigma, V) + dv_scul)``, ``zeta = w_in^n T`` at the
l cycle's mid-interval point and ``dzeta`` its change since the last update; ``-1/2 zeta x``
is Savage's first-order navigation-frame rotation correction ([SAV98] part 2; Strapdown
Analytics 7.2.2.2), the 1/12 terms its second order (:func:`_velocity_step`).

Position ([TW11] 11.4): ``C_n^e(k) = C_n^e(k-1) exp([xi x])``, ``xi =
w_en^n(v_eff) T``, ``h(k) = h(k-1) - v_D,eff T``, with v_eff from the
rectangular, trapezoidal or one-step Simpson (parabolic) rule.

Attitude update ([TW11] 11.2.1 and 11.2.4): ``C_b^n(k) = B C_b^n(k-1) A(sigma)``
with ``B = exp(-[zeta x])``, ``zeta = w_ie^n T + xi`` (the navigation frame's own
rotation over the update, as the position step turned it); in quaternion form ``q(k) =
r(-zeta) (x) q(k-1) (x) r(sigma)``.

Frames (``--frame``, [ZS] Zhang & Sun ch. 2; docs/algorithms.md "Mechanisation frames"): the
above is the geographic frame (2.4). The wander-azimuth (2.2) and free-azimuth (2.3) frames
keep ``C_b^w``, ``v^w`` and ``C_w^e`` in the same slots with a transport rate free of tan L;
the inertial frame (2.1) keeps ``C_b^i``, ``v^i`` and ``r^i`` (ECI = ECEF at the start). All
report NED rows. Each frame's k cycle is compiled on its own (the frame is a compile-time
constant), so the geographic kernel carries none of the others' branches.
"""

from __future__ import annotations

from collections import namedtuple
from typing import NamedTuple

import numpy as np
from numba import literally

from . import earth
from .coning import (
    nsample_coning,
    nsample_sculling,
    rate_coning,
    rate_sculling,
    rotation_compensation,
)
from .jit import call_for_frame, inline_kernel, kernel
from .rotation import (
    SMALL_ANGLE,
    Mat9,
    Quat,
    dcm_from_coeffs_s,
    dcm_to_euler_s,
    dcm_to_quat_s,
    euler_to_dcm_s,
    half_angle_coeffs,
    mat3_mul_s,
    orthonormalize_s,
    quat_mul_s,
    quat_to_dcm_s,
    rotvec_to_dcm_s,
)
from .settings import BY_NAME, Strapdown

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
CFG_FRAME = 10  # mechanisation frame, FRAMES
CFG_SIZE = 11

POSINT = {"rectangular": 0, "trapezoidal": 1, "simpson": 2}
ORDERS = {"1": 1, "2": 2, "3": 3, "4": 4, "exact": 0}
GEOGRAPHIC, WANDER, FREE, INERTIAL = 0, 1, 2, 3
FRAMES = {"geographic": GEOGRAPHIC, "wander": WANDER, "free": FREE, "inertial": INERTIAL}

# --- state vector: declared once -------------------------------------------
class Slot(NamedTuple):
    """A named run of the state vector ``s``: its name (``S.<NAME>`` is its first index), size and meaning."""

    name: str
    size: int
    what: str


STATE_LAYOUT = (
    Slot("T", 1, "time of the last k update (s)"),
    Slot("Q", 4, "q_nb [w x y z]"),
    Slot("C", 9, "C_b^n, row-major"),
    Slot("V", 3, "v^n (m/s) at k"),
    Slot("VP", 3, "v^n at the update before the last"),
    Slot("LATC", 1, "latitude (rad) of C_n^e, kept with it (sync_position)"),
    Slot("LONC", 1, "longitude (rad) of C_n^e, likewise"),
    Slot("CNE", 9, "C_n^e, row-major"),
    Slot("H", 1, "ellipsoidal height (m)"),
    Slot("PF", 3, "flat NED offset from the start (earth = none)"),
    Slot("LAT0", 1, "initial latitude (rad)"),
    Slot("LON0", 1, "initial longitude (rad)"),
    Slot("H0", 1, "initial height (m)"),
    Slot("VD0", 1, "initial down velocity (m/s)"),
    Slot("WIE", 3, "l-cycle Earth rate in n (rad/s)"),
    Slot("WEN", 3, "l-cycle transport rate in n (rad/s)"),
    Slot("G", 1, "l-cycle gravity down (m/s^2)"),
    Slot("G0", 1, "gravity at the start (earth = none)"),
    Slot("NK", 1, "k updates done"),
    Slot("NJ", 1, "samples buffered in this k cycle"),
    Slot("BUFT", 1, "summed interval of the buffered samples (s)"),
    Slot("BTH", 18, "6 x 3 angle increments buffer"),
    Slot("BDV", 18, "6 x 3 velocity increments buffer"),
    Slot("CONE", 3, "recursive coning sum (sampled rates)"),
    Slot("SCUL", 3, "recursive sculling sum (sampled rates)"),
    Slot("ACCA", 3, "angle accumulated in this k cycle (sampled rates)"),
    Slot("ACCV", 3, "velocity accumulated in this k cycle (sampled rates)"),
    Slot("PW", 3, "previous rate sample w (sampled rates)"),
    Slot("PFO", 3, "previous force sample f (sampled rates)"),
    Slot("HAVEP", 1, "1 once a previous rate sample exists"),
    Slot("TJ", 1, "time of the last accepted sample (s)"),
    Slot("NL", 1, "k cycles since the last l cycle"),
    Slot("KN", 1, "l-cycle 1/(R_N + h) (1/m): w_en^n = [v_E k_E, -v_N k_N, -v_E k_T]"),
    Slot("KE", 1, "l-cycle 1/(R_E + h) (1/m)"),
    Slot("KT", 1, "l-cycle tan L/(R_E + h) (1/m)"),
    Slot("MW", 4, "wander/free: l-cycle horizontal transport-rate matrix M (1/m), rho_h^w = M v_h^w, 2x2 row-major"),
    Slot("RZ", 1, "wander/free: l-cycle vertical transport rate (rad/s): 0 (wander), Omega sin L (free)"),
    Slot("RI", 3, "inertial: position r^i in ECI (m); S.V then holds v^i = dr^i/dt, S.C and S.Q C_b^i"),
    Slot("GH", 2, "inertial: l-cycle gravitation x, y in ECI (m/s^2); z is S.G"),
    Slot("T0", 1, "inertial: time (s) at which ECI coincides with ECEF"),
    Slot("INI", 1, "inertial: 1 once the state is held in ECI"),
    Slot("FLAG", 1, "1 once the geographic frame was asked to navigate beyond GEO_LAT_LIMIT"),
    Slot("FLAGT", 1, "time (s) of the update that first went beyond it"),
    Slot("GP", 3, "inertial: gravitation (m/s^2, ECI) of the last l cycle, before its quadrature term"),
    Slot("GPP", 3, "inertial: the same of the l cycle before"),
    Slot("GN", 1, "inertial: l cycles in that history (0, 1, 2)"),
)
S_SIZE = sum(f.size for f in STATE_LAYOUT)
# Each slot's first index by name, generated from STATE_LAYOUT: ``s[S.V + 2]`` is v_D. Numba takes a global
# named tuple as a compile-time constant, so that compiles to the load of a literal index (a numba record
# of the same fields is no faster under the JIT and slower as plain Python: benchmarks/bench_state_layout.py).
S = namedtuple("StateIndex", [f.name for f in STATE_LAYOUT])(
    *(sum(g.size for g in STATE_LAYOUT[:i]) for i in range(len(STATE_LAYOUT))))

# The geographic frame's transport rate has -v_E tan L/(R_E + h) in its vertical component:
# beyond this latitude (55 km from a pole) it is clamped there and the state flagged, since
# its errors grow like 1/distance^2 from the pole (docs/algorithms.md, "Near the poles").
GEO_LAT_LIMIT = float(np.radians(89.5))

# The attitude quaternion is renormalised when |q|^2 is further than this from 1 (4 ulps of 1),
# so |q| stays within 2 ulps of 1 after every update (_attitude_step).
QUAT_NORM_TOL = 2.0**-50

OUT_COLUMNS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw", "qw", "qx", "qy", "qz")
OUT_SIZE = len(OUT_COLUMNS)


_DEFAULT = Strapdown()


def make_config(
    samples: int = _DEFAULT.samples,
    attitude: str = _DEFAULT.attitude,
    order: str = _DEFAULT.order,
    earth_model: str = _DEFAULT.earth_model,
    orthonormalize_every: int = _DEFAULT.orthonormalize_every,
    vertical: str = _DEFAULT.vertical,
    coning: bool = _DEFAULT.coning,
    position: str = _DEFAULT.position,
    l_every: int = _DEFAULT.l_every,
    imu_rates: str = _DEFAULT.imu_rates,
    frame: str = _DEFAULT.frame,
) -> np.ndarray:
    """Build the configuration vector from the settings of core/settings.py (their names, defaults
    and allowed values)."""
    for name, value in dict(locals()).items():
        BY_NAME[name].check(value)
    if frame != "geographic" and earth_model != "wgs84":
        raise ValueError(f"frame {frame!r} needs the WGS-84 Earth (earth_model wgs84)")
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
    cfg[CFG_FRAME] = FRAMES[frame]
    return cfg


def kernel_frame(cfg: np.ndarray) -> int:
    """The ``frame`` argument of the kernels for cfg: GEOGRAPHIC, WANDER (which also runs the
    free-azimuth frame, its transport rate chosen by cfg) or INERTIAL.

    Kernels take it as a compile-time constant (numba ``literally``), so a run compiles only
    its own frame's branches; a dispatch on cfg inside a kernel would compile every frame (the
    first ``mavins nav`` waited twice as long). From Python, call such a kernel through
    :func:`mavins.core.jit.for_frame`, which compiles it once for that constant."""
    frame = int(cfg[CFG_FRAME])
    return frame if frame in (GEOGRAPHIC, INERTIAL) else WANDER


@kernel
def _get9(s: np.ndarray, o: int) -> Mat9:
    return s[o], s[o + 1], s[o + 2], s[o + 3], s[o + 4], s[o + 5], s[o + 6], s[o + 7], s[o + 8]


@kernel
def _put9(s: np.ndarray, o: int, c: Mat9) -> None:
    s[o], s[o + 1], s[o + 2], s[o + 3], s[o + 4], s[o + 5], s[o + 6], s[o + 7], s[o + 8] = c


@kernel
def init_state(
    t: float, lat: float, lon: float, h: float, v: np.ndarray, roll: float, pitch: float, yaw: float
) -> np.ndarray:
    """A fresh state at time t (s); angles and lat/lon in rad, h in m, v NED m/s."""
    s = np.zeros(S_SIZE)
    s[S.T] = t
    s[S.TJ] = t
    c = euler_to_dcm_s(roll, pitch, yaw)
    _put9(s, S.C, c)
    s[S.Q], s[S.Q + 1], s[S.Q + 2], s[S.Q + 3] = dcm_to_quat_s(c)
    for i in range(3):
        s[S.V + i] = v[i]
        s[S.VP + i] = v[i]
    _put9(s, S.CNE, earth.cne_from_latlon_s(lat, lon))
    s[S.H] = h
    s[S.LAT0] = lat
    s[S.LON0] = lon
    s[S.H0] = h
    s[S.VD0] = v[2]
    s[S.G0] = earth.gravity(lat, h)
    s[S.LATC] = lat
    s[S.LONC] = lon
    s[S.KN] = 1.0 / (earth.radii(lat)[0] + h)
    return s


@inline_kernel
def _wander_latlon(s: np.ndarray) -> tuple[float, float, float, float]:
    """Latitude, longitude (rad) and the wander angle's cosine and sine from ``C_w^e``.

    ``C_w^e = C_n^e Rz(alpha)`` (alpha: azimuth of the w frame's x axis from north), so its
    third row is ``[cos L cos alpha, -cos L sin alpha, -sin L]`` and its third column the down
    vector in e, ``-[cos L cos lon, cos L sin lon, sin L]``. Exactly at a pole (``cos L = 0``
    in double precision) alpha is taken as 0: w's x axis is north and its y axis east, and the
    longitude is that of the east direction, as in :func:`earth.latlon_from_cne`.
    """
    c = S.CNE
    c20, c21, c22 = s[c + 6], s[c + 7], s[c + 8]
    cl = np.hypot(c20, c21)
    lat = np.arctan2(-c22, cl)
    if cl == 0.0:
        return lat, np.arctan2(-s[c + 1], s[c + 4]), 1.0, 0.0
    return lat, np.arctan2(-s[c + 5], -s[c + 2]), c20 / cl, -c21 / cl


@inline_kernel
def _position_of(s: np.ndarray, cfg: np.ndarray, frame: int) -> tuple[float, float, float]:
    """Latitude, longitude (rad) and height (m) of the state.

    ``frame`` is :func:`kernel_frame` of cfg, a compile-time constant (the calling kernel's): each
    frame's kernel holds only its own branch (FREE shares WANDER's). Inlined into its callers."""
    if cfg[CFG_EARTH] > 0.5:
        if frame == INERTIAL and s[S.INI] > 0.5:
            lat, lon, h, _x, _y, _z, _r = _inertial_position(s, s[S.T])
            return lat, lon, h
        if frame == WANDER:
            lat, lon, _ca, _sa = _wander_latlon(s)
            return lat, lon, s[S.H]
        c = S.CNE
        lat, lon = earth.latlon_from_cne_s(s[c + 1], s[c + 4], s[c + 6], s[c + 7], s[c + 8])
        return lat, lon, s[S.H]
    # earth = none: flat NED offset mapped through the start point's radii.
    r_n, r_e = earth.radii(s[S.LAT0])
    h0 = s[S.H0]
    lat = s[S.LAT0] + s[S.PF] / (r_n + h0)
    lon = s[S.LON0] + s[S.PF + 1] / ((r_e + h0) * np.cos(s[S.LAT0]))
    return lat, lon, h0 - s[S.PF + 2]


@kernel
def position(s: np.ndarray, cfg: np.ndarray, frame: int) -> tuple[float, float, float]:
    """Latitude, longitude (rad) and height (m) of the state (:func:`_position_of`, for Python:
    ``frame`` made a compile-time constant)."""
    literally(frame)
    return _position_of(s, cfg, frame)


@inline_kernel
def _sync_position(s: np.ndarray, cfg: np.ndarray, frame: int) -> None:
    """Refresh the latitude/longitude kept beside C_n^e (``frame``: the calling kernel's constant)."""
    lat, lon, h = _position_of(s, cfg, frame)
    s[S.LATC] = lat
    s[S.LONC] = lon
    if frame == INERTIAL and s[S.INI] > 0.5:
        s[S.H] = h


@kernel
def sync_position(s: np.ndarray, cfg: np.ndarray, frame: int) -> None:
    """Refresh the latitude/longitude kept beside C_n^e; call after writing C_n^e or h directly."""
    literally(frame)
    _sync_position(s, cfg, frame)


@kernel
def solution_row(s: np.ndarray, cfg: np.ndarray, out: np.ndarray, frame: int) -> None:
    """Write ``t,lat,lon,h,vn,ve,vd,roll,pitch,yaw,qw,qx,qy,qz`` (rad) into out.

    Every frame reports NED attitude and velocity: in the wander and free-azimuth frames
    ``v^n = Rz(alpha) v^w`` and ``C_b^n = Rz(alpha) C_b^w`` (docs/algorithms.md).
    """
    literally(frame)
    if frame == INERTIAL and s[S.INI] > 0.5:
        _inertial_row(s, out)
        return
    if frame == WANDER:
        _wander_row(s, out)
        return
    out[0] = s[S.T]
    out[1] = s[S.LATC]
    out[2] = s[S.LONC]
    out[3] = s[S.H] if cfg[CFG_EARTH] > 0.5 else s[S.H0] - s[S.PF + 2]
    out[4] = s[S.V]
    out[5] = s[S.V + 1]
    out[6] = s[S.V + 2]
    c = S.C
    out[7], out[8], out[9] = dcm_to_euler_s(s[c], s[c + 1], s[c + 3], s[c + 4], s[c + 6], s[c + 7], s[c + 8])
    sign = -1.0 if s[S.Q] < 0.0 else 1.0  # the same rotation with a non-negative scalar part
    for a in range(4):
        out[10 + a] = sign * s[S.Q + a]


@kernel
def _write_ned_row(out: np.ndarray, t: float, lat: float, lon: float, h: float, vn: float, ve: float, vd: float,
                   c: Mat9) -> None:
    """A solution row from NED velocity (m/s) and ``C_b^n`` (row-major), angles in rad."""
    out[0], out[1], out[2], out[3] = t, lat, lon, h
    out[4], out[5], out[6] = vn, ve, vd
    out[7], out[8], out[9] = dcm_to_euler_s(c[0], c[1], c[3], c[4], c[6], c[7], c[8])
    out[10], out[11], out[12], out[13] = dcm_to_quat_s(c)


@kernel
def _wander_row(s: np.ndarray, out: np.ndarray) -> None:
    """Solution row of the wander and free-azimuth frames: turned by the wander angle into NED."""
    lat, lon, ca, sa = _wander_latlon(s)
    vx, vy = s[S.V], s[S.V + 1]
    w0, w1, w2, w3, w4, w5, w6, w7, w8 = _get9(s, S.C)
    c = (ca * w0 - sa * w3, ca * w1 - sa * w4, ca * w2 - sa * w5,
         sa * w0 + ca * w3, sa * w1 + ca * w4, sa * w2 + ca * w5, w6, w7, w8)
    _write_ned_row(out, s[S.T], lat, lon, s[S.H], ca * vx - sa * vy, sa * vx + ca * vy, s[S.V + 2], c)


@inline_kernel
def _inertial_position(s: np.ndarray, t: float) -> tuple[float, float, float, float, float, float, float]:
    """Latitude, longitude (rad), height (m), ECEF position (m) and R_E (m) of the inertial
    state at time t: ``r^e = Rz(-Omega (t - t0)) r^i`` (ECI = ECEF at t0). At a pole
    (``x = y = 0`` in e) the longitude is 0."""
    th = earth.OMEGA * (t - s[S.T0])
    ct, st = np.cos(th), np.sin(th)
    x, y, z = s[S.RI], s[S.RI + 1], s[S.RI + 2]
    xe, ye = ct * x + st * y, ct * y - st * x
    sl, cl, h, r_e = earth.geodetic_from_ecef_s(xe, ye, z)
    return np.arctan2(sl, cl), np.arctan2(ye, xe), h, xe, ye, z, r_e


@kernel
def _inertial_row(s: np.ndarray, out: np.ndarray) -> None:
    """Solution row of the inertial frame: ``v^e = C_i^e v^i - Omega x r^e``, ``v^n = C_e^n v^e``,
    ``C_b^n = C_e^n C_i^e C_b^i`` ([ZS] 2.1; [ZS1] eq. 1-3-14)."""
    t = s[S.T]
    lat, lon, h, xe, ye, _z, _r = _inertial_position(s, t)
    th = earth.OMEGA * (t - s[S.T0])
    ct, st = np.cos(th), np.sin(th)
    vx, vy, vz = s[S.V], s[S.V + 1], s[S.V + 2]
    vex = ct * vx + st * vy + earth.OMEGA * ye
    vey = ct * vy - st * vx - earth.OMEGA * xe
    n0, n1, n2, n3, n4, n5, n6, n7, n8 = earth.cne_from_latlon_s(lat, lon)
    cie = (ct, st, 0.0, -st, ct, 0.0, 0.0, 0.0, 1.0)
    cen = (n0, n3, n6, n1, n4, n7, n2, n5, n8)
    c = mat3_mul_s(mat3_mul_s(cen, cie), _get9(s, S.C))
    _write_ned_row(out, t, lat, lon, h, n0 * vex + n3 * vey + n6 * vz, n1 * vex + n4 * vey + n7 * vz,
                   n2 * vex + n5 * vey + n8 * vz, c)


@inline_kernel
def _enter_inertial(s: np.ndarray) -> None:
    """Turn a fresh NED state into the inertial frame at its time t0 (ECI = ECEF then):
    ``C_b^i = C_n^e C_b^n``, ``r^i = r^e``, ``v^i = C_n^e v^n + Omega x r^e`` ([ZS1] eq. 1-3-14)."""
    cne = _get9(s, S.CNE)
    sl = -cne[8]
    r_e = earth.radii_sin(sl)[1]
    h = s[S.H]
    x, y = -(r_e + h) * cne[2], -(r_e + h) * cne[5]
    s[S.RI], s[S.RI + 1], s[S.RI + 2] = x, y, (r_e * (1.0 - earth.E2) + h) * sl
    for o in (S.V, S.VP):
        a, b, c = s[o], s[o + 1], s[o + 2]
        s[o] = cne[0] * a + cne[1] * b + cne[2] * c - earth.OMEGA * y
        s[o + 1] = cne[3] * a + cne[4] * b + cne[5] * c + earth.OMEGA * x
        s[o + 2] = cne[6] * a + cne[7] * b + cne[8] * c
    c_bi = mat3_mul_s(cne, _get9(s, S.C))
    _put9(s, S.C, c_bi)
    s[S.Q], s[S.Q + 1], s[S.Q + 2], s[S.Q + 3] = dcm_to_quat_s(c_bi)
    s[S.T0] = s[S.T]
    s[S.INI] = 1.0
    s[S.GN] = 0.0


@inline_kernel
def _inertial_hold(s: np.ndarray, cfg: np.ndarray, vx: float, vy: float, vz: float) -> tuple[float, float, float]:
    """``--vertical hold`` in the inertial frame: move r^i along the ellipsoid normal back to the
    initial height and set the velocity's component along it (relative to the Earth, ``v^i -
    Omega x r^i``, [ZS] 2.1) to the initial ``-v_D``; returns the new v^i (m/s).

    The move must not change the velocity relative to the Earth, so v^i gains ``Omega x dr``
    with the move dr; without it every update turned ``Omega cos L |dr|`` of it east."""
    th = earth.OMEGA * (s[S.T] - s[S.T0])
    ct, st = np.cos(th), np.sin(th)
    x, y, z = s[S.RI], s[S.RI + 1], s[S.RI + 2]
    sl, _cl, h, r_e = earth.geodetic_from_ecef_s(ct * x + st * y, ct * y - st * x, z)
    k = 1.0 / (r_e + h)
    nx, ny, nz = x * k, y * k, sl  # the normal turned into ECI: the same x/(R_E + h) form
    dh = s[S.H0] - h
    s[S.RI], s[S.RI + 1], s[S.RI + 2] = x + dh * nx, y + dh * ny, z + dh * nz
    dv = -s[S.VD0] - (nx * (vx + earth.OMEGA * y) + ny * (vy - earth.OMEGA * x) + nz * vz)
    _sync_position(s, cfg, INERTIAL)
    wx, wy = -earth.OMEGA * dh * ny, earth.OMEGA * dh * nx  # Omega x dr, Omega = [0, 0, OMEGA]
    return vx + wx + dv * nx, vy + wy + dv * ny, vz + dv * nz


@inline_kernel
def _l_cycle_inertial(s: np.ndarray, cfg: np.ndarray, T: float, vmx: float, vmy: float, vmz: float) -> None:
    """The l cycle of the inertial frame ([ZS] 2.1): no Earth or transport rate; gravitation
    ``G = g + Omega x (Omega x r)`` ([ZS1] eq. 1-3-26, g the contract's normal gravity along the
    ellipsoid normal) at the extrapolated mid-interval point, turned into ECI.

    The point is ``r^i + T/4 (v(k-1) + v_mid)``: the mean velocity over the first half interval,
    so it misses r(t + T/2) by O(T^3) (``r^i + T/2 v_mid`` overshoots by ``T^2/8 a``, which the
    horizontal gravitation gradient g/R turns into a steady acceleration error). The velocity
    step takes ``T G(mid)`` for ``int G dt``; the midpoint rule misses ``T^3/24 G''``, taken here
    from the second difference of the last three l cycles' values, ``(G_l - 2 G_l-1 + G_l-2)/(24
    M^2)`` per unit T (M = --l-every): as the rotation of the specific force in the local-level
    frames' velocity step, a steady horizontal acceleration of ``T^2/24 Omega^2 g`` order that
    the Schuler loop integrates (docs/algorithms.md, "Mechanisation frames", accuracy).
    """
    ht = 0.5 * T
    th = earth.OMEGA * (s[S.T] + ht - s[S.T0])
    ct, st = np.cos(th), np.sin(th)
    qt = 0.25 * T
    x = s[S.RI] + qt * (s[S.V] + vmx)
    y = s[S.RI + 1] + qt * (s[S.V + 1] + vmy)
    z = s[S.RI + 2] + qt * (s[S.V + 2] + vmz)
    xe, ye = ct * x + st * y, ct * y - st * x
    sl, _cl, h, r_e = earth.geodetic_from_ecef_s(xe, ye, z)
    g = earth.gravity_sin(sl, r_e, h)
    k = g / (r_e + h) + earth.OMEGA * earth.OMEGA
    gx, gy = -k * xe, -k * ye
    for i in range(3):
        s[S.WIE + i] = 0.0
        s[S.WEN + i] = 0.0
    gx, gy, gz = ct * gx - st * gy, st * gx + ct * gy, -g * sl
    cx = cy = cz = 0.0
    if s[S.GN] > 1.5:
        m = cfg[CFG_L_EVERY]
        k = 1.0 / (24.0 * m * m)
        cx = k * (gx - 2.0 * s[S.GP] + s[S.GPP])
        cy = k * (gy - 2.0 * s[S.GP + 1] + s[S.GPP + 1])
        cz = k * (gz - 2.0 * s[S.GP + 2] + s[S.GPP + 2])
    else:
        s[S.GN] += 1.0
    for i in range(3):
        s[S.GPP + i] = s[S.GP + i]
    s[S.GP], s[S.GP + 1], s[S.GP + 2] = gx, gy, gz
    s[S.GH], s[S.GH + 1], s[S.G] = gx + cx, gy + cy, gz + cz


# --- state access for the stateful shells (engine, filter) ------------------
def state_time(s: np.ndarray) -> float:
    """Time (s) of the state's last k update."""
    return float(s[S.T])


def body_to_nav(s: np.ndarray) -> np.ndarray:
    """``C_b^n`` of the state, row-major (9, a view): the navigation frame's (NED, or the wander frame's)."""
    return s[S.C:S.C + 9]


def frame_limit(s: np.ndarray) -> float | None:
    """Time (s) at which the geographic frame first went beyond GEO_LAT_LIMIT, or None.

    From then on its solution is not trustworthy (finite, but the transport rate is clamped).
    """
    return float(s[S.FLAGT]) if s[S.FLAG] > 0.5 else None


def skip_to(s: np.ndarray, t: float) -> None:
    """Move the state's sample clock to ``t`` (s) without integrating the interval.

    For a sensor-time gap that must not be integrated: the next sample covers
    only its own nominal interval, and with sampled rates it opens a fresh one.
    """
    s[S.TJ] = max(s[S.TJ], t)
    s[S.HAVEP] = 0.0


# --- the k cycle in named steps -------------------------------------------
@kernel
def body_update_quat_minus_one(x: float, y: float, z: float, order: int) -> Quat:
    """Quaternion of the body rotation vector sigma = (x, y, z), truncated to ``order``, minus
    the identity quaternion: ``(a_c - 1, a_s sigma)``.

    ``(a_c, a_s)`` = (1, 1/2), (1 - s^2/8, 1/2), (1 - s^2/8, 1/2 - s^2/48),
    (1 - s^2/8 + s^4/384, 1/2 - s^2/48) for orders 1..4 and the exact ``(cos s/2,
    sin(s/2)/s)`` for order 0 ([TW11] 11.2.1 quaternion error analysis and table 11.2;
    docs/conventions.md ``--order``). ``a_c - 1`` is formed directly (``-k^2 s^2/(1 +
    cos(s/2))`` for the exact map) rather than as ``cos(s/2) - 1``: the update is then added
    to q as a small increment (:func:`_attitude_step`)."""
    s2 = x * x + y * y + z * z
    if order == 0:
        if s2 < SMALL_ANGLE * SMALL_ANGLE:  # the series of half_angle_coeffs, less its 1
            k = 0.5 + s2 * (-1.0 / 48.0 + s2 * (1.0 / 3840.0 - s2 * (1.0 / 645120.0)))
            return s2 * (-0.125 + s2 * (1.0 / 384.0 - s2 * (1.0 / 46080.0))), k * x, k * y, k * z
        c, k = half_angle_coeffs(s2)
        return -k * k * s2 / (1.0 + c), k * x, k * y, k * z
    if order == 1:
        cm, as_ = 0.0, 0.5
    elif order == 2:
        cm, as_ = -s2 / 8.0, 0.5
    elif order == 3:
        cm, as_ = -s2 / 8.0, 0.5 - s2 / 48.0
    else:
        cm, as_ = -s2 / 8.0 + s2 * s2 / 384.0, 0.5 - s2 / 48.0
    return cm, as_ * x, as_ * y, as_ * z


@kernel
def body_update_dcm(x: float, y: float, z: float, order: int) -> Mat9:
    """``A = I + a1 [s x] + a2 [s x]^2`` truncated to ``order`` (row-major 9-tuple).

    ``(a1, a2)`` = (1, 0), (1, 1/2), (1 - s^2/6, 1/2), (1 - s^2/6, 1/2 - s^2/24)
    for orders 1..4, exact ``(sin s/s, (1 - cos s)/s^2)`` for order 0
    ([TW11] slide "11.2.1 DCM algorithm"; docs/conventions.md ``--order``).
    """
    if order == 0:
        return rotvec_to_dcm_s(x, y, z)
    s2 = x * x + y * y + z * z
    if order == 1:
        a1, a2 = 1.0, 0.0
    elif order == 2:
        a1, a2 = 1.0, 0.5
    elif order == 3:
        a1, a2 = 1.0 - s2 / 6.0, 0.5
    else:
        a1, a2 = 1.0 - s2 / 6.0, 0.5 - s2 / 24.0
    return dcm_from_coeffs_s(x, y, z, a1, a2)


@inline_kernel
def _body_increments(s: np.ndarray, cfg: np.ndarray, n: int) -> tuple[float, float, float, float, float, float,
                                                                      float, float, float]:
    """Step 1, increments: the k cycle's body rotation vector sigma (rad, coning included),
    summed velocity increment and its sculling term (m/s), body frame ([TW11] 11.2.2, 11.3; coning.py)."""
    sx = sy = sz = vx = vy = vz = 0.0
    for i in range(n):
        j = S.BTH + 3 * i
        m = S.BDV + 3 * i
        sx += s[j]
        sy += s[j + 1]
        sz += s[j + 2]
        vx += s[m]
        vy += s[m + 1]
        vz += s[m + 2]
    cx = cy = cz = ux = uy = uz = 0.0
    if cfg[CFG_CONING] > 0.5 and n >= 2:
        if cfg[CFG_SAMPLED] > 0.5:
            cx, cy, cz = s[S.CONE], s[S.CONE + 1], s[S.CONE + 2]
            ux, uy, uz = s[S.SCUL], s[S.SCUL + 1], s[S.SCUL + 2]
        else:
            cx, cy, cz = nsample_coning(s, S.BTH, n)
            ux, uy, uz = nsample_sculling(s, S.BTH, S.BDV, n)
    return sx + cx, sy + cy, sz + cz, vx, vy, vz, ux, uy, uz


@inline_kernel
def _l_cycle(s: np.ndarray, cfg: np.ndarray, frame: int, T: float, lat: float, h: float, vmx: float, vmy: float,
             vmz: float) -> None:
    """Slow terms at the extrapolated mid-interval point (l cycle): Earth rate, transport
    rate (and its radius coefficients, which the position step reuses) and gravity
    ([TW11] 11.4, "evaluated at the l rate"); lat (rad), h (m) at the start of the interval."""
    if cfg[CFG_EARTH] < 0.5:
        for i in range(3):
            s[S.WIE + i] = 0.0
            s[S.WEN + i] = 0.0
        s[S.G] = s[S.G0]
        return
    if frame == WANDER:
        _l_cycle_wander(s, cfg, T, h, vmx, vmy, vmz)
        return
    if frame == INERTIAL:
        _l_cycle_inertial(s, cfg, T, vmx, vmy, vmz)
        return
    lat_mid = lat + 0.5 * T * vmx * s[S.KN]
    if abs(lat_mid) > GEO_LAT_LIMIT:
        if s[S.FLAG] < 0.5:
            s[S.FLAG] = 1.0
            s[S.FLAGT] = s[S.T]
        lat_mid = GEO_LAT_LIMIT if lat_mid > 0.0 else -GEO_LAT_LIMIT
    h_mid = h - 0.5 * T * vmz
    kn, ke, kt, wn, wd, g = earth.nav_terms(lat_mid, h_mid)
    s[S.KN], s[S.KE], s[S.KT] = kn, ke, kt
    s[S.WIE], s[S.WIE + 1], s[S.WIE + 2] = wn, 0.0, wd
    s[S.WEN], s[S.WEN + 1], s[S.WEN + 2] = vmy * ke, -vmx * kn, -vmy * kt
    s[S.G] = g


@inline_kernel
def _wander_terms(s: np.ndarray, r0: float, r1: float, r2: float, h: float, free: bool) -> float:
    """Transport-rate coefficients of the wander (or free-azimuth) frame at the point whose
    ``C_w^e`` third row is ``(r0, r1, r2) = (cos L cos alpha, -cos L sin alpha, -sin L)``, height
    h (m); stores them in S.MW, S.RZ and returns gravity (m/s^2, down).

    The NED transport rate ``[v_E k_E, -v_N k_N]`` turned into w (``v^n = Rz(alpha) v^w``) is
    ``M v_h^w`` with ``M = (k_E + k_N)/2 J + kappa [[-2 r0 r1, r0^2 - r1^2], [r0^2 - r1^2, 2 r0 r1]]``,
    ``J = [[0, 1], [-1, 0]]``, ``kappa = (k_E - k_N)/(2 cos^2 L) = -e^2 R_E k_E k_N / (2(1 - e^2
    sin^2 L))``: no tan L and no alpha, regular at the poles ([ZS] 2.2; docs/algorithms.md).
    Vertical: 0 in the wander frame, ``-w_ie,z^w = Omega sin L`` in the free-azimuth frame
    ([ZS] 2.3: the frame does not turn about its vertical relative to inertial space).
    """
    sl = -r2
    r_n, r_e = earth.radii_sin(sl)
    kn = 1.0 / (r_n + h)
    ke = 1.0 / (r_e + h)
    a = 0.5 * (ke + kn)
    kap = -0.5 * earth.E2 * r_e / (1.0 - earth.E2 * sl * sl) * ke * kn
    d = r0 * r0 - r1 * r1
    x2 = -2.0 * r0 * r1
    s[S.MW], s[S.MW + 1], s[S.MW + 2], s[S.MW + 3] = kap * x2, a + kap * d, kap * d - a, -kap * x2
    s[S.RZ] = earth.OMEGA * sl if free else 0.0
    return earth.gravity_sin(sl, r_e, h)


@inline_kernel
def _l_cycle_wander(s: np.ndarray, cfg: np.ndarray, T: float, h: float, vmx: float, vmy: float,
                    vmz: float) -> None:
    """The l cycle of the wander and free-azimuth frames ([ZS] 2.2, 2.3).

    Earth rate ``w_ie^w = Omega (C_w^e)^T z_e = Omega r`` (r: third row of C_w^e), transport rate
    ``[M v_h, rho_z]`` and gravity at the extrapolated mid-interval point, whose third row is
    ``r + T/2 r x rho`` (first order of ``dC_w^e/dt = C_w^e [rho x]``), h - T/2 v_D.
    """
    c = S.CNE
    r0, r1, r2 = s[c + 6], s[c + 7], s[c + 8]
    free = int(cfg[CFG_FRAME]) == FREE
    if s[S.NK] < 0.5:
        _wander_terms(s, r0, r1, r2, h, free)  # first cycle: coefficients at the start point
    px = s[S.MW] * vmx + s[S.MW + 1] * vmy
    py = s[S.MW + 2] * vmx + s[S.MW + 3] * vmy
    pz = s[S.RZ]
    ht = 0.5 * T
    m0 = r0 + ht * (r1 * pz - r2 * py)
    m1 = r1 + ht * (r2 * px - r0 * pz)
    m2 = r2 + ht * (r0 * py - r1 * px)
    s[S.G] = _wander_terms(s, m0, m1, m2, h - ht * vmz, free)
    s[S.WIE], s[S.WIE + 1], s[S.WIE + 2] = earth.OMEGA * m0, earth.OMEGA * m1, earth.OMEGA * m2
    s[S.WEN] = s[S.MW] * vmx + s[S.MW + 1] * vmy
    s[S.WEN + 1] = s[S.MW + 2] * vmx + s[S.MW + 3] * vmy
    s[S.WEN + 2] = s[S.RZ]


@inline_kernel
def _velocity_step(s: np.ndarray, T: float, sgx: float, sgy: float, sgz: float, vsx: float, vsy: float,
                   vsz: float, scx: float, scy: float, scz: float, zx: float, zy: float, zz: float,
                   dzx: float, dzy: float, dzz: float, vmx: float, vmy: float,
                   vmz: float) -> tuple[float, float, float]:
    """Step 2, velocity (m/s, NED) at the end of the k cycle, from the attitude at its start.

    ``v(k) = v(k-1) + u^n + [g - (2 w_ie + w_en) x v_mid] T`` with ``u^n = (I - 1/2 [zeta x] +
    1/12 [zeta x]^2 + 1/12 [dzeta x]) u``, ``u = C_b^n(k-1) (V + rot(sigma, V) + dv_scul)``
    ([TW11] 11.3, lecture eq. 11.64, and 11.4). The ``zeta`` terms turn u, summed in the frame
    of the interval's start, into the frame that rotates by zeta over it: ``-1/2 zeta x`` is
    Savage's first-order navigation-frame rotation correction ([SAV98] part 2; Strapdown
    Analytics 7.2.2.2), the ``1/12`` terms the second order of the same integral
    ``int C_n(t)^n(k-1) f^n dt`` for a specific force fixed in the rotating frame, with ``zeta =
    w_in T`` at the mid-interval and ``dzeta`` = this cycle's zeta minus the last one's (``dw_in/dt
    T^2``, the frame rate's own change; docs/algorithms.md derives both). Without them the
    velocity drifts by ``1/12 T^2 (w x (w x f) + dw/dt x f)``, the specific force's second
    derivative in inertial space: 9e-12 m/s^2 in level flight at 45 deg, 250 m/s, T = 0.04 s.
    """
    rcx, rcy, rcz = rotation_compensation(sgx, sgy, sgz, vsx, vsy, vsz)
    bx = vsx + rcx + scx
    by = vsy + rcy + scy
    bz = vsz + rcz + scz
    c0, c1, c2, c3, c4, c5, c6, c7, c8 = _get9(s, S.C)
    ux = c0 * bx + c1 * by + c2 * bz
    uy = c3 * bx + c4 * by + c5 * bz
    uz = c6 * bx + c7 * by + c8 * bz
    # -1/2 zeta x u + 1/12 dzeta x u = -1/2 (zeta - dzeta/6) x u, and zeta x that is
    # zeta x (zeta x u) but for a third-order term: two cross products for the three terms.
    c6, c12 = 1.0 / 6.0, 1.0 / 12.0
    px, py, pz = zx - c6 * dzx, zy - c6 * dzy, zz - c6 * dzz
    ax, ay, az = py * uz - pz * uy, pz * ux - px * uz, px * uy - py * ux
    bx, by, bz = zy * az - zz * ay, zz * ax - zx * az, zx * ay - zy * ax
    ux, uy, uz = ux - 0.5 * ax + c12 * bx, uy - 0.5 * ay + c12 * by, uz - 0.5 * az + c12 * bz
    wix, wiy, wiz = s[S.WIE], s[S.WIE + 1], s[S.WIE + 2]
    ox, oy, oz = 2.0 * wix + s[S.WEN], 2.0 * wiy + s[S.WEN + 1], 2.0 * wiz + s[S.WEN + 2]
    vnx = s[S.V] + ux - (oy * vmz - oz * vmy) * T
    vny = s[S.V + 1] + uy - (oz * vmx - ox * vmz) * T
    vnz = s[S.V + 2] + uz - (ox * vmy - oy * vmx) * T + s[S.G] * T
    return vnx, vny, vnz


@inline_kernel
def _attitude_step(s: np.ndarray, cfg: np.ndarray, sgx: float, sgy: float, sgz: float,
                   zx: float, zy: float, zz: float) -> None:
    """Step 4, attitude: ``C_b^n(k) = B C_b^n(k-1) A(sigma)``, ``B = exp(-[zeta x])``, or in
    quaternion form ``q(k) = r(-zeta) (x) q(k-1) (x) r(sigma)`` ([TW11] 11.2.1, 11.2.4). Here
    zeta is the frame's rotation over the update as the position step applied it, ``w_ie T +
    xi`` (:func:`_k_cycle`)."""
    order = int(cfg[CFG_ORDER])
    if cfg[CFG_DCM] > 0.5:
        c_new = mat3_mul_s(mat3_mul_s(rotvec_to_dcm_s(-zx, -zy, -zz), _get9(s, S.C)),
                           body_update_dcm(sgx, sgy, sgz, order))
        k = int(cfg[CFG_ORTHO_EVERY])
        if k > 0 and (int(s[S.NK]) + 1) % k == 0:
            c_new = orthonormalize_s(c_new)
        _put9(s, S.C, c_new)
        s[S.Q], s[S.Q + 1], s[S.Q + 2], s[S.Q + 3] = dcm_to_quat_s(c_new)
        return
    # q + q (x) (r(sigma) - 1), then q + (r(-zeta) - 1) (x) q: the same product, with the
    # increments added to q rather than q multiplied by quaternions 1e-12 short of 1, and the
    # division by |q| only when |q|^2 is more than 4 ulps from 1. Multiplied and divided at
    # every update in double precision, the rounding turned the attitude by 3e-16 rad/s in
    # the inertial frame (0.4 prad in 1200 s against the same products in extended precision),
    # about a micrometre of position in a quarter Schuler period; this way 100 times less.
    q0, q1, q2, q3 = s[S.Q], s[S.Q + 1], s[S.Q + 2], s[S.Q + 3]
    d0, d1, d2, d3 = quat_mul_s((q0, q1, q2, q3), body_update_quat_minus_one(sgx, sgy, sgz, order))
    q0, q1, q2, q3 = q0 + d0, q1 + d1, q2 + d2, q3 + d3
    d0, d1, d2, d3 = quat_mul_s(body_update_quat_minus_one(-zx, -zy, -zz, 0), (q0, q1, q2, q3))
    q0, q1, q2, q3 = q0 + d0, q1 + d1, q2 + d2, q3 + d3
    n2 = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    if abs(n2 - 1.0) > QUAT_NORM_TOL:
        qn = np.sqrt(n2)
        q0, q1, q2, q3 = q0 / qn, q1 / qn, q2 / qn, q3 / qn
    s[S.Q], s[S.Q + 1], s[S.Q + 2], s[S.Q + 3] = q0, q1, q2, q3
    _put9(s, S.C, quat_to_dcm_s((q0, q1, q2, q3)))


@inline_kernel
def _rotate_position(s: np.ndarray, x: float, y: float, z: float) -> None:
    """``C_n^e <- C_n^e exp([xi x])`` written as ``C + C (a1 [xi x] + a2 [xi x]^2)``.

    The same product as ``C exp([xi x])``, but the update's diagonal ``1 - a2 (|xi|^2 - xi_i^2)``
    (1 - 1e-12 for a 1e-6 rad step) is never rounded to a double: rounded, it scales the columns
    of C_n^e by the same 1e-17 or so at every update while the transport rate holds steady, and
    C_n^e, which is never re-orthonormalised, drifts from a rotation by 1e-12 in a 1340 s flight,
    a micrometre of latitude. Here only the sums C + dC round, which are as often up as down.
    """
    xx, yy, zz = x * x, y * y, z * z
    s2 = xx + yy + zz
    if s2 < SMALL_ANGLE * SMALL_ANGLE:  # sin s/s and (1 - cos s)/s^2 to s^6, as rotvec_to_dcm_s's
        a1 = 1.0 + s2 * (-1.0 / 6.0 + s2 * (1.0 / 120.0 - s2 * (1.0 / 5040.0)))
        a2 = 0.5 + s2 * (-1.0 / 24.0 + s2 * (1.0 / 720.0 - s2 * (1.0 / 40320.0)))
    else:
        c, k = half_angle_coeffs(s2)
        a1, a2 = 2.0 * c * k, 2.0 * k * k
    d0, d4, d8 = -a2 * (yy + zz), -a2 * (xx + zz), -a2 * (xx + yy)
    d1, d2, d3 = -a1 * z + a2 * x * y, a1 * y + a2 * x * z, a1 * z + a2 * x * y
    d5, d6, d7 = -a1 * x + a2 * y * z, -a1 * y + a2 * x * z, a1 * x + a2 * y * z
    o = S.CNE
    for r in range(3):
        i = o + 3 * r
        c0, c1, c2 = s[i], s[i + 1], s[i + 2]
        s[i] = c0 + (c0 * d0 + c1 * d3 + c2 * d6)
        s[i + 1] = c1 + (c0 * d1 + c1 * d4 + c2 * d7)
        s[i + 2] = c2 + (c0 * d2 + c1 * d5 + c2 * d8)


@inline_kernel
def _position_step(s: np.ndarray, cfg: np.ndarray, frame: int, T: float, vnx: float, vny: float,
                   vnz: float) -> tuple[float, float, float]:
    """Step 3, position: ``C_n^e(k) = C_n^e(k-1) exp([xi x])``, ``xi = w_en^n(v_eff) T``,
    ``h(k) = h(k-1) - v_D,eff T`` with v_eff from the rectangular, trapezoidal or one-step
    Simpson (parabolic) rule ([TW11] 11.4). The transport rate's radius coefficients are
    those of the l cycle at the mid-interval point (1e-12 relative from the
    effective-velocity midpoint at 100 Hz, below double precision in xi). Returns xi (rad; 0 in
    the inertial frame and without the Earth model)."""
    vox, voy, voz = s[S.V], s[S.V + 1], s[S.V + 2]
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
        ex = (-s[S.VP] + 8.0 * vox + 5.0 * vnx) / 12.0
        ey = (-s[S.VP + 1] + 8.0 * voy + 5.0 * vny) / 12.0
        ez = (-s[S.VP + 2] + 8.0 * voz + 5.0 * vnz) / 12.0
    xn = xe = xd = 0.0
    if frame == INERTIAL:
        s[S.RI] += ex * T
        s[S.RI + 1] += ey * T
        s[S.RI + 2] += ez * T
    elif cfg[CFG_EARTH] > 0.5:
        if frame == GEOGRAPHIC:
            xn, xe, xd = ey * s[S.KE] * T, -ex * s[S.KN] * T, -ey * s[S.KT] * T
        else:
            xn = (s[S.MW] * ex + s[S.MW + 1] * ey) * T
            xe = (s[S.MW + 2] * ex + s[S.MW + 3] * ey) * T
            xd = s[S.RZ] * T
        _rotate_position(s, xn, xe, xd)
    else:
        s[S.PF] += ex * T
        s[S.PF + 1] += ey * T
        s[S.PF + 2] += ez * T
    if cfg[CFG_VHOLD] > 0.5:
        s[S.H] = s[S.H0]
        s[S.PF + 2] = 0.0
    else:
        s[S.H] -= ez * T
    _sync_position(s, cfg, frame)
    return xn, xe, xd


@inline_kernel
def _first_mid_velocity(s: np.ndarray, cfg: np.ndarray, frame: int, T: float, sgx: float, sgy: float, sgz: float,
                        vsx: float, vsy: float, vsz: float, scx: float, scy: float,
                        scz: float) -> tuple[float, float, float]:
    """v_mid of the first update of a local-level frame, which has no v(k-2) to extrapolate from.

    ``v_mid = v(k-1)`` would miss ``T/2 a``, which the Coriolis term turns into a step of ``T^2/2
    (2 w_ie + w_en) x a`` in v(1) (1e-9 m/s in level flight at 45 deg, 0.8 um of position after
    a quarter Schuler period). Predicted v(1) with ``v_mid = v(0)``, then ``(v(0) + v(1))/2``.
    (The inertial frame has no Coriolis term; there v_mid only places gravitation.)"""
    vx, vy, vz = s[S.V], s[S.V + 1], s[S.V + 2]
    _l_cycle(s, cfg, frame, T, s[S.LATC], s[S.H], vx, vy, vz)
    px, py, pz = _velocity_step(s, T, sgx, sgy, sgz, vsx, vsy, vsz, scx, scy, scz, (s[S.WIE] + s[S.WEN]) * T,
                                (s[S.WIE + 1] + s[S.WEN + 1]) * T, (s[S.WIE + 2] + s[S.WEN + 2]) * T, 0.0, 0.0, 0.0,
                                vx, vy, vz)
    if cfg[CFG_VHOLD] > 0.5:
        pz = s[S.VD0]
    return 0.5 * (vx + px), 0.5 * (vy + py), 0.5 * (vz + pz)


@kernel
def k_update(s: np.ndarray, cfg: np.ndarray, frame: int) -> None:
    """One attitude/velocity/position update over the buffered samples (k cycle).

    Increments, l-cycle terms, velocity, position, attitude, in that order; all
    on scalars, so the update allocates nothing. ``frame`` (GEOGRAPHIC, WANDER, which
    also runs FREE, or INERTIAL) is a compile-time constant, so each frame's kernel
    runs only its own branches.
    """
    literally(frame)
    n = int(s[S.NJ])
    T = s[S.BUFT]
    inertial = frame == INERTIAL
    if inertial and s[S.INI] < 0.5:
        _enter_inertial(s)
    sgx, sgy, sgz, vsx, vsy, vsz, scx, scy, scz = _body_increments(s, cfg, n)
    # Mid-interval velocity extrapolated from the last two updates ([TW11] 11.4).
    vmx = 1.5 * s[S.V] - 0.5 * s[S.VP]
    vmy = 1.5 * s[S.V + 1] - 0.5 * s[S.VP + 1]
    vmz = 1.5 * s[S.V + 2] - 0.5 * s[S.VP + 2]
    # The frame rate the last update used (l-cycle values), for dzeta.
    wpx, wpy, wpz = s[S.WIE] + s[S.WEN], s[S.WIE + 1] + s[S.WEN + 1], s[S.WIE + 2] + s[S.WEN + 2]
    first = s[S.NK] < 0.5
    if first and not inertial:
        vmx, vmy, vmz = _first_mid_velocity(s, cfg, frame, T, sgx, sgy, sgz, vsx, vsy, vsz, scx, scy, scz)
    if int(s[S.NL]) % int(cfg[CFG_L_EVERY]) == 0:
        _l_cycle(s, cfg, frame, T, s[S.LATC], s[S.H], vmx, vmy, vmz)
    s[S.NL] += 1.0
    wx, wy, wz = s[S.WIE] + s[S.WEN], s[S.WIE + 1] + s[S.WEN + 1], s[S.WIE + 2] + s[S.WEN + 2]
    zx, zy, zz = wx * T, wy * T, wz * T
    if first:
        wpx, wpy, wpz = wx, wy, wz
    vnx, vny, vnz = _velocity_step(s, T, sgx, sgy, sgz, vsx, vsy, vsz, scx, scy, scz, zx, zy, zz,
                                   (wx - wpx) * T, (wy - wpy) * T, (wz - wpz) * T, vmx, vmy, vmz)
    if inertial:
        vnx += s[S.GH] * T
        vny += s[S.GH + 1] * T
    elif cfg[CFG_VHOLD] > 0.5:
        vnz = s[S.VD0]
    s[S.T] = s[S.TJ]  # the position step's output (inertial: the Earth's angle) is at the new time
    xn, xe, xd = _position_step(s, cfg, frame, T, vnx, vny, vnz)
    # The attitude turns with the frame by what the position step turned C_n^e (xi, from the
    # same v_eff) plus the Earth's rotation, so attitude and position see one transport rate
    # (zeta's v_mid extrapolation would add T^3/2 w_en(v'') per update, a gyro-like drift).
    _attitude_step(s, cfg, sgx, sgy, sgz, s[S.WIE] * T + xn, s[S.WIE + 1] * T + xe, s[S.WIE + 2] * T + xd)
    if inertial and cfg[CFG_VHOLD] > 0.5:
        vnx, vny, vnz = _inertial_hold(s, cfg, vnx, vny, vnz)
    for a in range(3):
        s[S.VP + a] = s[S.V + a]
    s[S.V], s[S.V + 1], s[S.V + 2] = vnx, vny, vnz
    s[S.NK] += 1.0
    s[S.NJ] = 0.0
    s[S.BUFT] = 0.0
    for i in range(S.CONE, S.ACCV + 3):
        s[i] = 0.0


# --- the j cycle: feeding samples -------------------------------------------
@kernel
def push_increment_s(s: np.ndarray, cfg: np.ndarray, t: float, ax: float, ay: float, az: float,
                     bx: float, by: float, bz: float, frame: int) -> int:
    """Feed one increment row covering (t_prev, t] (j cycle): angle (ax, ay, az) rad and
    velocity (bx, by, bz) m/s, FRD; ``frame`` is :func:`kernel_frame` of cfg.

    Returns 1 when the sample completed a k cycle (a new solution exists),
    0 when it was buffered, -1 when rejected because t is not after the last
    accepted sample.
    """
    literally(frame)
    r = _buffer(s, cfg, t, ax, ay, az, bx, by, bz)
    if r == 1:
        k_update(s, cfg, frame)
    return r


@kernel
def _buffer(s: np.ndarray, cfg: np.ndarray, t: float, ax: float, ay: float, az: float,
            bx: float, by: float, bz: float) -> int:
    """The j cycle of :func:`push_increment_s` without its k update: 1 when one is due, 0 when
    the sample was buffered, -1 when it was rejected."""
    dt = t - s[S.TJ]
    if not dt > 0.0:
        return -1
    j = int(s[S.NJ])
    o = S.BTH + 3 * j
    s[o], s[o + 1], s[o + 2] = ax, ay, az
    o = S.BDV + 3 * j
    s[o], s[o + 1], s[o + 2] = bx, by, bz
    s[S.NJ] = j + 1
    s[S.BUFT] += dt
    s[S.TJ] = t
    if j + 1 >= int(cfg[CFG_SAMPLES]):
        return 1
    return 0


@kernel
def push_increment(s: np.ndarray, cfg: np.ndarray, t: float, dtheta: np.ndarray, dv: np.ndarray, frame: int) -> int:
    """:func:`push_increment_s` with the increments as arrays."""
    literally(frame)
    return push_increment_s(s, cfg, t, dtheta[0], dtheta[1], dtheta[2], dv[0], dv[1], dv[2], frame)


@kernel
def push_rate_scalars(
    s: np.ndarray, cfg: np.ndarray, t: float, wx: float, wy: float, wz: float, fx: float, fy: float, fz: float,
    frame: int
) -> int:
    """Feed one rate sample (rad/s, m/s^2 in FRD); same return codes and ``frame`` as push_increment_s.

    Averaged rates: ``dtheta = w dt`` exactly. Instantaneous rates: increments
    by the trapezoid rule and the piecewise-linear coning/sculling terms of
    coning.py, accumulated recursively with ``1/2 alpha x dtheta`` and ``1/2
    (alpha x dv + v x dtheta)`` (docs/algorithms.md); a sample at the start time
    only opens the first interval, and without one the first sample's values
    hold back to the start (docs/conventions.md "Sensor data").
    """
    literally(frame)
    t_last = s[S.TJ]
    if cfg[CFG_SAMPLED] < 0.5:
        if not t > t_last:
            return -1
        dt = t - t_last
        return push_increment_s(s, cfg, t, wx * dt, wy * dt, wz * dt, fx * dt, fy * dt, fz * dt, frame)
    if s[S.HAVEP] < 0.5:
        if t < t_last:
            return -1
        s[S.PW], s[S.PW + 1], s[S.PW + 2] = wx, wy, wz
        s[S.PFO], s[S.PFO + 1], s[S.PFO + 2] = fx, fy, fz
        s[S.HAVEP] = 1.0
        if t == t_last:
            return 0
    if not t > t_last:
        return -1
    h = t - t_last
    w0x, w0y, w0z = s[S.PW], s[S.PW + 1], s[S.PW + 2]
    f0x, f0y, f0z = s[S.PFO], s[S.PFO + 1], s[S.PFO + 2]
    ax, ay, az = 0.5 * (w0x + wx) * h, 0.5 * (w0y + wy) * h, 0.5 * (w0z + wz) * h
    bx, by, bz = 0.5 * (f0x + fx) * h, 0.5 * (f0y + fy) * h, 0.5 * (f0z + fz) * h
    aax, aay, aaz = s[S.ACCA], s[S.ACCA + 1], s[S.ACCA + 2]
    avx, avy, avz = s[S.ACCV], s[S.ACCV + 1], s[S.ACCV + 2]
    cx, cy, cz = rate_coning(w0x, w0y, w0z, wx, wy, wz, h)
    s[S.CONE] += 0.5 * (aay * az - aaz * ay) + cx
    s[S.CONE + 1] += 0.5 * (aaz * ax - aax * az) + cy
    s[S.CONE + 2] += 0.5 * (aax * ay - aay * ax) + cz
    ux, uy, uz = rate_sculling(w0x, w0y, w0z, f0x, f0y, f0z, wx, wy, wz, fx, fy, fz, h)
    s[S.SCUL] += 0.5 * ((aay * bz - aaz * by) + (avy * az - avz * ay)) + ux
    s[S.SCUL + 1] += 0.5 * ((aaz * bx - aax * bz) + (avz * ax - avx * az)) + uy
    s[S.SCUL + 2] += 0.5 * ((aax * by - aay * bx) + (avx * ay - avy * ax)) + uz
    s[S.ACCA] += ax
    s[S.ACCA + 1] += ay
    s[S.ACCA + 2] += az
    s[S.ACCV] += bx
    s[S.ACCV + 1] += by
    s[S.ACCV + 2] += bz
    s[S.PW], s[S.PW + 1], s[S.PW + 2] = wx, wy, wz
    s[S.PFO], s[S.PFO + 1], s[S.PFO + 2] = fx, fy, fz
    return push_increment_s(s, cfg, t, ax, ay, az, bx, by, bz, frame)


@kernel
def push_rate(s: np.ndarray, cfg: np.ndarray, t: float, w: np.ndarray, f: np.ndarray, frame: int) -> int:
    """:func:`push_rate_scalars` with the sample as arrays."""
    literally(frame)
    return push_rate_scalars(s, cfg, t, w[0], w[1], w[2], f[0], f[1], f[2], frame)


def run_increments(
    s: np.ndarray, cfg: np.ndarray, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, out: np.ndarray
) -> int:
    """Batch j/k loop over increment rows; writes one solution row per k update.

    ``out`` needs at least ``len(t) // N`` rows; returns the number written.
    The frame reaches the kernel as a compile-time constant (:func:`kernel_frame`).
    """
    return call_for_frame(_run_increments, kernel_frame(cfg), s, cfg, t, dtheta, dv, out)


@kernel
def _run_increments(s: np.ndarray, cfg: np.ndarray, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray,
                    out: np.ndarray, frame: int) -> int:
    """:func:`run_increments` compiled for one frame (see :func:`k_update`)."""
    literally(frame)
    m = 0
    for i in range(t.shape[0]):
        if _buffer(s, cfg, t[i], dtheta[i, 0], dtheta[i, 1], dtheta[i, 2], dv[i, 0], dv[i, 1], dv[i, 2]) == 1:
            k_update(s, cfg, frame)
            solution_row(s, cfg, out[m], frame)
            m += 1
    return m


def run_rates(s: np.ndarray, cfg: np.ndarray, t: np.ndarray, w: np.ndarray, f: np.ndarray, out: np.ndarray) -> int:
    """Batch loop over rate rows (rows before the state's time are skipped); the frame as in
    :func:`run_increments`."""
    return call_for_frame(_run_rates, kernel_frame(cfg), s, cfg, t, w, f, out)


@kernel
def _run_rates(s: np.ndarray, cfg: np.ndarray, t: np.ndarray, w: np.ndarray, f: np.ndarray, out: np.ndarray,
               frame: int) -> int:
    """:func:`run_rates` compiled for one frame."""
    literally(frame)
    m = 0
    t0 = s[S.TJ]
    for i in range(t.shape[0]):
        if t[i] < t0:
            continue
        if push_rate_scalars(s, cfg, t[i], w[i, 0], w[i, 1], w[i, 2], f[i, 0], f[i, 1], f[i, 2], frame) == 1:
            solution_row(s, cfg, out[m], frame)
            m += 1
    return m
