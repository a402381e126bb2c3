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

import math

import numpy as np

from mavins.core import earth
from mavins.core.jit import inline_kernel, kernel, sum_kernel
from mavins.core.rotation import (Mat9, dcm_to_quat_s, euler_to_dcm_s, mat3_mul_s, mat3t_vec_s, quat_mul_s,
                                   quat_to_dcm_s, quat_to_euler, rotvec_to_dcm_s)

CH_ROLL, CH_PITCH, CH_YAW, CH_SPEED, CH_VD, CH_TT1, CH_TT2 = range(7)
N_CHANNELS = 7

# consts vector: coning half-angle (rad), coning rate (rad/s), laboratory gravity (m/s^2)
K_BETA, K_WCONE, K_GLAB = range(3)


def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of the n-point Gauss-Legendre rule on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


# The 5-point rule: the floor of quadrature_order, and sim.polar's.
GL_NODES, GL_WEIGHTS = gauss_legendre(5)


@kernel
def channel_eval(starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, count: int, t: float) -> tuple[float, float]:
    """Value and rate of one channel at time t (held constant-rate beyond its ends)."""
    n = starts.shape[0]
    starts2 = starts.reshape((1, n))
    return channel_at(starts2, durs.reshape((1, n)), coefs.reshape((1, n, coefs.shape[1])), 0,
                      piece_index(starts2, 0, count, t), t)


@kernel
def channel_values(starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, count: int, t: np.ndarray,
                   out: np.ndarray) -> None:
    """channel_eval's value at each of the times t into ``out``."""
    for i in range(t.shape[0]):
        out[i] = channel_eval(starts, durs, coefs, count, t[i])[0]


@kernel
def piece_index(starts: np.ndarray, ch: int, count: int, t: float) -> int:
    """The piece of channel ch (its ``count`` pieces start at ``starts[ch, :count]``, sorted) that holds t:
    the last one starting at or before t (the first before its start). A binary search on the indexed
    row (``searchsorted(..., side="right") - 1``, NaN after everything as numpy has it): no view is made."""
    lo, hi = 0, count
    if t != t:
        lo = count
    while lo < hi:
        mid = (lo + hi) // 2
        if starts[ch, mid] <= t:
            lo = mid + 1
        else:
            hi = mid
    k = lo - 1
    return k if k > 0 else 0


@kernel
def pieces_at(starts: np.ndarray, counts: np.ndarray, t: float, out: np.ndarray) -> None:
    """piece_index of every channel at t into ``out`` (N_CHANNELS integers)."""
    for c in range(N_CHANNELS):
        out[c] = piece_index(starts, c, counts[c], t)


@inline_kernel
def channel_at(starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, ch: int, k: int, t: float
               ) -> tuple[float, float]:
    """Value and rate at t of piece k of channel ch (row ch of ``starts``, ``durs``, ``coefs``): its
    polynomial of degree <= 6 in ``u = (t - start) / dur`` (Horner), continued with the end value and rate
    beyond u = 1 and linearly before u = 0. Inside a sample interval, split at every channel's breaks, the
    piece of each channel is known once (pieces_at). The arrays are indexed, never sliced: no view is made."""
    d = durs[ch, k]
    u = (t - starts[ch, k]) / d
    c0, c1, c2, c3 = coefs[ch, k, 0], coefs[ch, k, 1], coefs[ch, k, 2], coefs[ch, k, 3]
    c4, c5, c6 = coefs[ch, k, 4], coefs[ch, k, 5], coefs[ch, k, 6]
    if u > 1.0:
        # beyond the last piece: continue with the end value and rate
        v1 = c0 + c1 + c2 + c3 + c4 + c5 + c6
        r1 = (c1 + 2 * c2 + 3 * c3 + 4 * c4 + 5 * c5 + 6 * c6) / d
        return v1 + r1 * (u - 1.0) * d, r1
    if u < 0.0:
        return c0 + c1 * u, c1 / d
    val = (((((c6 * u + c5) * u + c4) * u + c3) * u + c2) * u + c1) * u + c0
    der = ((((6.0 * c6 * u + 5 * c5) * u + 4 * c4) * u + 3 * c3) * u + 2 * c2) * u + c1
    return val, der / d


@kernel
def right_jacobian_rate_s(px: float, py: float, pz: float, dx: float, dy: float, dz: float
                          ) -> tuple[float, float, float]:
    """Body rate of ``exp([phi x])``: ``J_r(phi) phi' = phi' - b1 phi x phi' + b2 phi x (phi x phi')``,
    ``b1 = (1 - cos a)/a^2``, ``b2 = (a - sin a)/a^3`` (Bortz 1971; series below 1e-6 rad)."""
    a2 = px * px + py * py + pz * pz
    if a2 < 1e-12:
        b1 = 0.5 - a2 / 24.0
        b2 = 1.0 / 6.0 - a2 / 120.0
    else:
        a = np.sqrt(a2)
        b1 = (1.0 - np.cos(a)) / a2
        b2 = (a - np.sin(a)) / (a2 * a)
    c1x, c1y, c1z = py * dz - pz * dy, pz * dx - px * dz, px * dy - py * dx
    c2x, c2y, c2z = py * c1z - pz * c1y, pz * c1x - px * c1z, px * c1y - py * c1x
    return dx - b1 * c1x + b2 * c2x, dy - b1 * c1y + b2 * c2y, dz - b1 * c1z + b2 * c2z


# Sums of the superposed sinusoids at one instant (vib_sums): angular vibration phi (rad) and its
# rate (rad/s), linear vibration's NED velocity (m/s) and acceleration (m/s^2).
VS_PHI, VS_PHID, VS_VEL, VS_ACC = 0, 3, 6, 9
VS_SIZE = 12


@kernel
def sine_terms(vib: np.ndarray, linvib: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of each sinusoid's sine and cosine in the vibration sums, one column per sinusoid.

    Rows of ``vib``/``linvib``: amplitude x, y, z, angular frequency w (rad/s), phase p (rad).
    Angular (first result): rows 0-2 ``A`` (``phi = sum A sin(w t + p)``), rows 3-5 ``A w``
    (``phi' = sum A w cos(w t + p)``). Linear (second): rows 0-2 ``-A/w^2`` (displacement
    ``-sum A/w^2 sin(w t + p)``), rows 3-5 ``-A/w`` (velocity ``-sum A/w cos(w t + p)``), rows 6-8
    ``A`` (acceleration ``sum A sin(w t + p)``): velocity and displacement are the integrals of a.
    """
    ta = np.empty((6, vib.shape[0]))
    for k in range(vib.shape[0]):
        for i in range(3):
            ta[i, k] = vib[k, i]
            ta[3 + i, k] = vib[k, i] * vib[k, 3]
    tl = np.empty((9, linvib.shape[0]))
    for k in range(linvib.shape[0]):
        w = linvib[k, 3]
        for i in range(3):
            tl[i, k] = -linvib[k, i] / (w * w)
            tl[3 + i, k] = -linvib[k, i] / w
            tl[6 + i, k] = linvib[k, i]
    return ta, tl


# Rows of sine_terms per family, and the VS_* slots they fill: (sine rows, cosine rows, sine slot, cosine slot).
ANGULAR_ROWS = (0, 3, VS_PHI, VS_PHID)
LINEAR_ROWS = (6, 3, VS_ACC, VS_VEL)
DISPLACEMENT_ROWS = (0, 3, 3, 0)  # into ends[j]: velocity at 0:3, displacement at 3:6


@sum_kernel
def _sine_sum(terms: np.ndarray, rows: tuple[int, int, int, int], pc: np.ndarray, ps: np.ndarray, j: int,
              rot: np.ndarray, slot: int, g: int, out: np.ndarray, at: int) -> None:
    """``out[at, sin_slot + i] += sum_k terms[sin_row + i, k] sin_k``, ``out[at, cos_slot + i] +=
    sum_k terms[cos_row + i, k] cos_k`` (i = 0..2), where ``(cos_k, sin_k)`` is the phasor
    ``(pc, ps)[j, k]`` turned by ``rot[slot, :, g, k]`` (angle sum: ``cos(a + b) = c rc - s rs``,
    ``sin(a + b) = s rc + c rs``). Every array is indexed, never sliced: a view would cost two atomic
    reference counts per call."""
    sin_row, cos_row, sin_slot, cos_slot = rows
    a0 = a1 = a2 = b0 = b1 = b2 = 0.0
    for k in range(pc.shape[1]):
        c, s, rc, rs = pc[j, k], ps[j, k], rot[slot, 0, g, k], rot[slot, 1, g, k]
        ck = c * rc - s * rs
        sk = s * rc + c * rs
        a0 += terms[sin_row, k] * sk
        a1 += terms[sin_row + 1, k] * sk
        a2 += terms[sin_row + 2, k] * sk
        b0 += terms[cos_row, k] * ck
        b1 += terms[cos_row + 1, k] * ck
        b2 += terms[cos_row + 2, k] * ck
    out[at, sin_slot] += a0
    out[at, sin_slot + 1] += a1
    out[at, sin_slot + 2] += a2
    out[at, cos_slot] += b0
    out[at, cos_slot + 1] += b1
    out[at, cos_slot + 2] += b2


@kernel
def vib_sums(t: float, vib: np.ndarray, linvib: np.ndarray, out: np.ndarray) -> None:
    """The vibration sums at t into ``out[0]`` (VS_* slots, sine_terms), each phase evaluated directly."""
    ta, tl = sine_terms(vib, linvib)
    out[0, :] = 0.0
    for fam, terms, rows in ((vib, ta, ANGULAR_ROWS), (linvib, tl, LINEAR_ROWS)):
        ph = fam[:, 3] * t + fam[:, 4]
        n = fam.shape[0]
        still = np.empty((1, 2, 1, n))  # the phasors as they are: turned by (1, 0)
        still[0, 0, 0, :] = 1.0
        still[0, 1, 0, :] = 0.0
        _sine_sum(terms, rows, np.cos(ph).reshape((1, n)), np.sin(ph).reshape((1, n)), 0, still, 0, 0, out, 0)


@inline_kernel
def vehicle_s(t: float, starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, pieces: np.ndarray, vs: np.ndarray,
              vi: int) -> tuple[float, float, float, float, float, float, float, float, float, float, float, float]:
    """Vehicle roll, pitch, yaw (rad), their rates (rad/s), NED velocity (m/s) and acceleration
    (m/s^2) at t, the linear vibration's from ``vs[vi]`` (VS_VEL, VS_ACC) added.

    ``v = [V cos psi, V sin psi, v_D]``, ``a = [V' cos psi - V psi' sin psi, V' sin psi + V psi' cos psi, v_D']``.
    """
    r, rd = channel_at(starts, durs, coefs, CH_ROLL, pieces[CH_ROLL], t)
    p, pd = channel_at(starts, durs, coefs, CH_PITCH, pieces[CH_PITCH], t)
    y, yd = channel_at(starts, durs, coefs, CH_YAW, pieces[CH_YAW], t)
    spd, spd_d = channel_at(starts, durs, coefs, CH_SPEED, pieces[CH_SPEED], t)
    vd, vd_d = channel_at(starts, durs, coefs, CH_VD, pieces[CH_VD], t)
    cy, sy = np.cos(y), np.sin(y)
    return (r, p, y, rd, pd, yd,
            spd * cy + vs[vi, VS_VEL], spd * sy + vs[vi, VS_VEL + 1], vd + vs[vi, VS_VEL + 2],
            spd_d * cy - spd * yd * sy + vs[vi, VS_ACC], spd_d * sy + spd * yd * cy + vs[vi, VS_ACC + 1],
            vd_d + vs[vi, VS_ACC + 2])


@inline_kernel
def perturbation_s(t: float, vs: np.ndarray, vi: int, consts: np.ndarray) -> tuple[Mat9, float, float, float]:
    """DCM ``C_p^v`` (row-major 9-tuple) and body rate (rad/s) of the angular perturbations at t.

    Angular vibration ``exp(phi(t))`` (phi, phi' from ``vs[vi]``), then classic coning relative to
    its start: ``q_c(0)^-1 (x) q_c(t)`` with the cone rate of sim.motion.classic_coning.
    """
    px, py, pz = vs[vi, VS_PHI], vs[vi, VS_PHI + 1], vs[vi, VS_PHI + 2]
    c_p = rotvec_to_dcm_s(px, py, pz)
    wx, wy, wz = right_jacobian_rate_s(px, py, pz, vs[vi, VS_PHID], vs[vi, VS_PHID + 1], vs[vi, VS_PHID + 2])
    beta, wc = consts[K_BETA], consts[K_WCONE]
    if beta != 0.0:
        # q_c(t) = [cos b/2, sin b/2 cos wt, sin b/2 sin wt, 0], taken relative to t = 0
        hb = 0.5 * beta
        ch, sh = np.cos(hb), np.sin(hb)
        c_c = quat_to_dcm_s(quat_mul_s((ch, -sh, 0.0, 0.0), (ch, sh * np.cos(wc * t), sh * np.sin(wc * t), 0.0)))
        sb = np.sin(beta)
        ux, uy, uz = mat3t_vec_s(c_c, wx, wy, wz)
        wx = ux - wc * sb * np.sin(wc * t)
        wy = uy + wc * sb * np.cos(wc * t)
        wz = uz - wc * (1.0 - np.cos(beta))
        c_p = mat3_mul_s(c_p, c_c)
    return c_p, wx, wy, wz


@inline_kernel
def _moves(coefs: np.ndarray, ch: int, k: int) -> bool:
    """Whether piece k of channel ch has a nonzero coefficient (indexed: no view is made; one exit, so that
    numba can prune the reference counts of the caller's arrays once this is inlined)."""
    moving = False
    for j in range(coefs.shape[2]):
        if coefs[ch, k, j] != 0.0:
            moving = True
    return moving


@inline_kernel
def turntable_s(t: float, starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, pieces: np.ndarray
                ) -> tuple[Mat9, float, float, float, float, float]:
    """``C_s^v = Rz(a1) Rx(a2)`` (9-tuple), the IMU's rate relative to the vehicle (in s), angles a1, a2.
    No turntable (both channels' pieces zero, as in every scenario without one): the identity."""
    c_sv = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    wx = wy = wz = a1 = a2 = 0.0
    if _moves(coefs, CH_TT1, pieces[CH_TT1]) or _moves(coefs, CH_TT2, pieces[CH_TT2]):
        a1, r1 = channel_at(starts, durs, coefs, CH_TT1, pieces[CH_TT1], t)
        a2, r2 = channel_at(starts, durs, coefs, CH_TT2, pieces[CH_TT2], t)
        c_sv = euler_to_dcm_s(a2, 0.0, a1)
        # rate of Rz(a1) Rx(a2) in s: Rx(a2)^T [0, 0, r1] + [r2, 0, 0]
        wx, wy, wz = r2, np.sin(a2) * r1, np.cos(a2) * r1
    return c_sv, wx, wy, wz, a1, a2


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
    """True ``w_is^s`` (rad/s) and ``f^s`` (m/s^2) of the IMU at t, latitude, height (rates_s)."""
    vs = np.empty((1, VS_SIZE))
    vib_sums(t, vib, linvib, vs)
    pieces = np.empty(N_CHANNELS, dtype=np.int64)
    pieces_at(starts, counts, t, pieces)
    r = rates_s(t, lat, h, starts, durs, coefs, pieces, vs, 0, consts, use_earth)
    return np.array([r[0], r[1], r[2]]), np.array([r[3], r[4], r[5]])


@kernel
def rates_s(
    t: float, lat: float, h: float, starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, pieces: np.ndarray,
    vs: np.ndarray, vi: int, consts: np.ndarray, use_earth: bool,
) -> tuple[float, float, float, float, float, float]:
    """``w_is^s`` and ``f^s`` at t given the vibration sums ``vs[vi]`` there ([TW11] 11.1, inverted):
    ``w_iv = w_nv + C_n^v (w_ie + w_en)``, ``f^v = C_n^v (a + (2 w_ie + w_en) x v - g)``, then
    through the perturbation and the turntable. Allocation-free (tuples)."""
    r, p, y, rd, pd, yd, vn, ve, vd, an, ae, ad = vehicle_s(t, starts, durs, coefs, pieces, vs, vi)
    c_vn = euler_to_dcm_s(r, p, y)
    sr, cr = np.sin(r), np.cos(r)
    sp, cp = np.sin(p), np.cos(p)
    # body rate from the Euler rates (ZYX)
    wnx = rd - yd * sp
    wny = pd * cr + yd * sr * cp
    wnz = -pd * sr + yd * cr * cp
    if use_earth:
        kn, ke, kt, ien, ied, g = earth.nav_terms(lat, h)
        enx, eny, enz = earth.transport_rate_k(kn, ke, kt, vn, ve)
    else:
        ien, ied, g = 0.0, 0.0, consts[K_GLAB]
        enx, eny, enz = 0.0, 0.0, 0.0
    ux, uy, uz = mat3t_vec_s(c_vn, ien + enx, eny, ied + enz)
    wvx, wvy, wvz = wnx + ux, wny + uy, wnz + uz
    ox, oy, oz = 2.0 * ien + enx, eny, 2.0 * ied + enz
    fx, fy, fz = mat3t_vec_s(c_vn, an + oy * vd - oz * ve, ae + oz * vn - ox * vd, ad + ox * ve - oy * vn - g)
    c_pv, wpx, wpy, wpz = perturbation_s(t, vs, vi, consts)
    wx, wy, wz = mat3t_vec_s(c_pv, wvx, wvy, wvz)
    fx, fy, fz = mat3t_vec_s(c_pv, fx, fy, fz)
    c_sp, wtx, wty, wtz, _, _ = turntable_s(t, starts, durs, coefs, pieces)
    wx, wy, wz = mat3t_vec_s(c_sp, wx + wpx, wy + wpy, wz + wpz)
    fx, fy, fz = mat3t_vec_s(c_sp, fx, fy, fz)
    return wx + wtx, wy + wty, wz + wtz, fx, fy, fz


# Rotations of the sinusoids' phasors kept between sample intervals (integrate): one set per distinct
# sub-step length, looked up by its exact value, so a cached rotation is the one computed afresh.
N_ROT_CACHE = 4

# Largest relative quadrature error allowed on a sinusoid over one sub-step (quadrature_order).
QUADRATURE_TOL = 1e-15


def quadrature_order(wh: float, tol: float = QUADRATURE_TOL) -> int:
    """Fewest Gauss-Legendre nodes (5 .. 40) that integrate ``sin(W t)`` over a step h with ``wh = W h``
    to ``tol`` relative to ``A h``.

    Remainder of the n-point rule on [0, h] ([AS64] 25.4.30, mapped from [-1, 1]):
    ``h^(2n+1) (n!)^4 / ((2n+1) ((2n)!)^3) f^(2n)``, and ``|f^(2n)| <= A W^(2n)`` for ``A sin(W t)``.
    """
    for n in range(5, 41):  # in logarithms: (2n)!^3 overflows a double from n = 29
        log_c = 4.0 * math.lgamma(n + 1) - math.log(2 * n + 1) - 3.0 * math.lgamma(2 * n + 1)
        if wh <= 0.0 or log_c + 2 * n * math.log(wh) <= math.log(tol):
            return n
    raise ValueError(f"W h = {wh:g} rad per sub-step needs more than 40 quadrature nodes (raise substeps)")


@kernel
def _rotations(w: np.ndarray, hstep: float, nodes: np.ndarray, step: np.ndarray, rot: np.ndarray, slot: int) -> None:
    """cos and sin of ``w hstep`` (step[slot, 0], step[slot, 1]) and of ``w x_g hstep`` at the quadrature
    nodes x_g (rot[slot, 0, g], rot[slot, 1, g]), for each angular frequency w (rad/s, one column each);
    after the nodes, g = len(nodes), no turn (1, 0): the phasors as they are."""
    ng = nodes.shape[0]
    for k in range(w.shape[0]):
        a = w[k] * hstep
        step[slot, 0, k] = np.cos(a)
        step[slot, 1, k] = np.sin(a)
        for g in range(ng):
            b = w[k] * nodes[g] * hstep
            rot[slot, 0, g, k] = np.cos(b)
            rot[slot, 1, g, k] = np.sin(b)
        rot[slot, 0, ng, k] = 1.0
        rot[slot, 1, ng, k] = 0.0


# Phasors are carried from piece to piece by rotation and evaluated afresh every ANCHOR_EVERY pieces,
# so their roundings (about 1e-16 per rotation) never add up beyond ~1e-14.
ANCHOR_EVERY = 64


@kernel
def _piece_sums(
    ta0: float, anchor: bool, substeps: int, fam: np.ndarray, terms: np.ndarray, rows: tuple[int, int, int, int],
    step: np.ndarray, rot: np.ndarray, slot: int, carry: np.ndarray, pc: np.ndarray, ps: np.ndarray,
    node_vs: np.ndarray, end_vs: np.ndarray,
) -> None:
    """Add one family of sinusoids (``fam``: rows of amplitude x, y, z, w, phase) to the vibration sums
    of a piece starting at ta0: at the quadrature nodes of each sub-step (node_vs[j n + g, VS_*]) and at
    the piece's end (end_vs[0]). ``pc``/``ps`` receive each sinusoid's phasor ``(cos, sin)`` of its phase
    at the sub-step boundaries ``ta0 + j hstep`` (row j = 0 .. substeps).

    ``carry`` holds the phasors at ta0, evaluated directly when ``anchor``; the others follow by turning
    them with the angle-sum identity by this hstep's rotations (_rotations: ``step[slot]``, ``rot[slot]``).
    On return ``carry`` holds the phasors at the piece's end. ``terms``/``rows``: sine_terms and
    ANGULAR_ROWS or LINEAR_ROWS.
    """
    n = fam.shape[0]
    ng = rot.shape[2] - 1
    if anchor:
        for k in range(n):
            a = fam[k, 3] * ta0 + fam[k, 4]
            carry[0, k] = np.cos(a)
            carry[1, k] = np.sin(a)
    for k in range(n):
        pc[0, k] = carry[0, k]
        ps[0, k] = carry[1, k]
    for j in range(substeps):
        for k in range(n):
            pc[j + 1, k] = pc[j, k] * step[slot, 0, k] - ps[j, k] * step[slot, 1, k]
            ps[j + 1, k] = ps[j, k] * step[slot, 0, k] + pc[j, k] * step[slot, 1, k]
        for g in range(ng):
            _sine_sum(terms, rows, pc, ps, j, rot, slot, g, node_vs, j * ng + g)
    _sine_sum(terms, rows, pc, ps, substeps, rot, slot, ng, end_vs, 0)
    for k in range(n):
        carry[0, k] = pc[substeps, k]
        carry[1, k] = ps[substeps, k]


@kernel
def integrate(
    t0: float,
    t: np.ndarray,
    substeps: int,
    nodes: np.ndarray,
    weights: np.ndarray,
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
    rows: np.ndarray,
) -> None:
    """Exact IMU increments, the true position and the truth rows (truth_row) at every sample time.

    Position: classical RK4 on ``L' = v_N/(R_N+h)``, ``lon' = v_E/((R_E+h) cos L)``,
    ``h' = -v_D`` for the channels' smooth velocity at ``substeps`` per sample, plus
    the linear vibration's displacement over the step in closed form (its integral
    ``-sum A/w^2 sin(w t + p)``) scaled at the step's start. Increments:
    Gauss-Legendre quadrature (``nodes``, ``weights`` on [0, 1], gauss_legendre) of
    the IMU rates on each sub-step, with latitude and height at the nodes from a
    cubic Hermite interpolation of the step. Sample intervals are first split at
    every channel piece boundary in ``breaks`` (sorted), so each quadrature spans
    one smooth piece. With ``use_earth`` false, position is the flat NED offset
    (north m, east m, -h). The vibration sums come from _piece_sums (one direct
    phase per sinusoid and piece).
    """
    lat, lon, h = lat0, lon0, h0
    tp = t0
    nb = breaks.shape[0]
    edges = np.empty(nb + 2)
    ng = nodes.shape[0]
    node_vs = np.empty((substeps * ng, VS_SIZE))
    ends = np.empty((substeps + 1, 6))
    end_vs = np.empty((1, VS_SIZE))
    na, nl = vib.shape[0], linvib.shape[0]
    terms_a, terms_l = sine_terms(vib, linvib)
    cache_h = np.full(N_ROT_CACHE, np.nan)
    # per cached hstep: cos and sin of w hstep; of w x_g hstep at each node, and (1, 0) after them
    step_a, step_l = np.empty((N_ROT_CACHE, 2, na)), np.empty((N_ROT_CACHE, 2, nl))
    rot_a, rot_l = np.empty((N_ROT_CACHE, 2, ng + 1, na)), np.empty((N_ROT_CACHE, 2, ng + 1, nl))
    pc_a, ps_a = np.empty((substeps + 1, na)), np.empty((substeps + 1, na))
    pc_l, ps_l = np.empty((substeps + 1, nl)), np.empty((substeps + 1, nl))
    carry_a, carry_l = np.empty((2, na)), np.empty((2, nl))
    next_slot = 0
    acc_th = np.empty(3)
    acc_v = np.empty(3)
    pieces = np.empty(N_CHANNELS, dtype=np.int64)
    n_pieces = 0  # pieces integrated (phasors re-anchored every ANCHOR_EVERY)
    for i in range(t.shape[0]):
        ti = t[i]
        b0 = np.searchsorted(breaks, tp, side="right")  # the breaks inside (tp, ti)
        b1 = np.searchsorted(breaks, ti, side="left")
        ne = 0
        edges[ne] = tp
        ne += 1
        for k in range(b0, b1):
            edges[ne] = breaks[k]
            ne += 1
        edges[ne] = ti
        ne += 1
        acc_th[:] = 0.0
        acc_v[:] = 0.0
        for piece in range(ne - 1):
            ta0 = edges[piece]
            hstep = (edges[piece + 1] - ta0) / substeps
            slot = -1
            for c in range(N_ROT_CACHE):
                if cache_h[c] == hstep:
                    slot = c
            if slot < 0:
                slot = next_slot
                next_slot = (next_slot + 1) % N_ROT_CACHE
                _rotations(vib[:, 3], hstep, nodes, step_a, rot_a, slot)
                _rotations(linvib[:, 3], hstep, nodes, step_l, rot_l, slot)
                cache_h[slot] = hstep
            node_vs[:] = 0.0
            end_vs[:] = 0.0
            ends[:] = 0.0
            anchor = n_pieces % ANCHOR_EVERY == 0
            pieces_at(starts, counts, 0.5 * (ta0 + edges[piece + 1]), pieces)  # each channel's piece in here
            _piece_sums(ta0, anchor, substeps, vib, terms_a, ANGULAR_ROWS, step_a, rot_a, slot, carry_a,
                        pc_a, ps_a, node_vs, end_vs)
            _piece_sums(ta0, anchor, substeps, linvib, terms_l, LINEAR_ROWS, step_l, rot_l, slot, carry_l,
                        pc_l, ps_l, node_vs, end_vs)
            for j in range(substeps + 1):  # the linear vibration's velocity and displacement at the boundaries
                _sine_sum(terms_l, DISPLACEMENT_ROWS, pc_l, ps_l, j, rot_l, slot, ng, ends, j)
            n_pieces += 1
            for j in range(substeps):
                ta = ta0 + j * hstep
                hh = 0.5 * hstep
                # classical RK4 on the smooth velocity, the vibration's displacement added exactly; k2 and k3
                # share the velocity at ta + hstep/2, k4 and the end slope m1 the one at ta + hstep
                va = smooth_velocity_s(ta, starts, durs, coefs, pieces)
                vm = smooth_velocity_s(ta + hh, starts, durs, coefs, pieces)
                vb = smooth_velocity_s(ta + hstep, starts, durs, coefs, pieces)
                sx, sy, sz = pos_scale_s(lat, h, use_earth)  # at the step's start: k1's, and the vibration's
                k1 = (va[0] * sx, va[1] * sy, va[2] * sz)  # pos_rate_s at (lat, h)
                k2 = pos_rate_s(lat + hh * k1[0], h + hh * k1[2], vm[0], vm[1], vm[2], use_earth)
                k3 = pos_rate_s(lat + hh * k2[0], h + hh * k2[2], vm[0], vm[1], vm[2], use_earth)
                k4 = pos_rate_s(lat + hstep * k3[0], h + hstep * k3[2], vb[0], vb[1], vb[2], use_earth)
                h6 = hstep / 6.0
                lat1 = lat + h6 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]) + sx * (ends[j + 1, 3] - ends[j, 3])
                lon1 = lon + h6 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]) + sy * (ends[j + 1, 4] - ends[j, 4])
                h1 = h + h6 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]) + sz * (ends[j + 1, 5] - ends[j, 5])
                # Hermite end slopes: the full velocity (smooth + vibration) at both ends
                s0x, s0z = k1[0] + sx * ends[j, 0], k1[2] + sz * ends[j, 2]
                m1 = pos_rate_s(lat1, h1, vb[0] + ends[j + 1, 0], vb[1] + ends[j + 1, 1], vb[2] + ends[j + 1, 2],
                                use_earth)
                for g in range(ng):
                    x = nodes[g]
                    h00 = 2 * x**3 - 3 * x**2 + 1
                    h10 = x**3 - 2 * x**2 + x
                    h01 = -2 * x**3 + 3 * x**2
                    h11 = x**3 - x**2
                    latn = h00 * lat + h10 * hstep * s0x + h01 * lat1 + h11 * hstep * m1[0]
                    hn = h00 * h + h10 * hstep * s0z + h01 * h1 + h11 * hstep * m1[2]
                    r = rates_s(ta + x * hstep, latn, hn, starts, durs, coefs, pieces, node_vs, j * ng + g, consts,
                                use_earth)
                    wq = weights[g] * hstep
                    acc_th[0] += wq * r[0]
                    acc_th[1] += wq * r[1]
                    acc_th[2] += wq * r[2]
                    acc_v[0] += wq * r[3]
                    acc_v[1] += wq * r[4]
                    acc_v[2] += wq * r[5]
                lat, lon, h = lat1, lon1, h1
        for c in range(3):
            dtheta[i, c] = acc_th[c]
            dv[i, c] = acc_v[c]
        pos[i, 0] = lat
        pos[i, 1] = lon
        pos[i, 2] = h
        pieces_at(starts, counts, ti, pieces)
        truth_row(ti, starts, durs, coefs, pieces, end_vs, 0, consts, rows, i)
        tp = ti


@inline_kernel
def pos_scale_s(lat: float, h: float, use_earth: bool) -> tuple[float, float, float]:
    """``d(lat, lon, h)/d(north, east, down)``: ``1/(R_N+h)``, ``1/((R_E+h) cos L)``, -1 (flat: 1, 1, -1)."""
    if use_earth:
        r_n, r_e = earth.radii(lat)
        return 1.0 / (r_n + h), 1.0 / ((r_e + h) * np.cos(lat)), -1.0
    return 1.0, 1.0, -1.0


@inline_kernel
def smooth_velocity_s(t: float, starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, pieces: np.ndarray
                      ) -> tuple[float, float, float]:
    """The channels' NED velocity (m/s) at t, no linear vibration: ``[V cos psi, V sin psi, v_D]`` (as
    vehicle_s, from the three channels it needs)."""
    y, _ = channel_at(starts, durs, coefs, CH_YAW, pieces[CH_YAW], t)
    spd, _ = channel_at(starts, durs, coefs, CH_SPEED, pieces[CH_SPEED], t)
    vd, _ = channel_at(starts, durs, coefs, CH_VD, pieces[CH_VD], t)
    return spd * np.cos(y), spd * np.sin(y), vd


@inline_kernel
def pos_rate_s(lat: float, h: float, vn: float, ve: float, vd: float, use_earth: bool) -> tuple[float, float, float]:
    """Rate of (lat, lon, h) (or flat north, east, up) for the NED velocity (m/s) at (lat, h):
    ``L' = v_N/(R_N+h)``, ``lon' = v_E/((R_E+h) cos L)``, ``h' = -v_D``."""
    sx, sy, sz = pos_scale_s(lat, h, use_earth)
    return vn * sx, ve * sy, vd * sz


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
    """truth_row at each t (the vibration sums evaluated directly)."""
    vs = np.empty((1, VS_SIZE))
    pieces = np.empty(N_CHANNELS, dtype=np.int64)
    for i in range(t.shape[0]):
        vib_sums(t[i], vib, linvib, vs)
        pieces_at(starts, counts, t[i], pieces)
        truth_row(t[i], starts, durs, coefs, pieces, vs, 0, consts, out, i)


@kernel
def truth_row(t: float, starts: np.ndarray, durs: np.ndarray, coefs: np.ndarray, pieces: np.ndarray, vs: np.ndarray,
              vi: int, consts: np.ndarray, out: np.ndarray, oi: int) -> None:
    """True velocity and attitudes at t into ``out[oi]``: ``vn, ve, vd, q_ns[4], q_nv[4], a1, a2``
    (vibration sums ``vs[vi]``).

    ``q_ns`` is the IMU's attitude (what the strapdown solution estimates),
    ``q_nv`` the vehicle's (angular vibration and coning included), a1/a2 the
    turntable angles (rad).
    """
    r, p, y, _, _, _, vn, ve, vd, _, _, _ = vehicle_s(t, starts, durs, coefs, pieces, vs, vi)
    c_pv, _, _, _ = perturbation_s(t, vs, vi, consts)
    c_sp, _, _, _, a1, a2 = turntable_s(t, starts, durs, coefs, pieces)
    c_nv = mat3_mul_s(euler_to_dcm_s(r, p, y), c_pv)
    out[oi, 0], out[oi, 1], out[oi, 2] = vn, ve, vd
    out[oi, 3], out[oi, 4], out[oi, 5], out[oi, 6] = dcm_to_quat_s(mat3_mul_s(c_nv, c_sp))
    out[oi, 7], out[oi, 8], out[oi, 9], out[oi, 10] = dcm_to_quat_s(c_nv)
    out[oi, 11] = a1
    out[oi, 12] = a2


@kernel
def euler_rows(q: np.ndarray, out: np.ndarray) -> None:
    """Roll, pitch, yaw (rad) of each quaternion row (rotation.quat_to_euler)."""
    for i in range(q.shape[0]):
        out[i] = quat_to_euler(q[i])
