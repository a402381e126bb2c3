"""Fixed-interval smoothing of the closed-loop error-state filter (Rauch-Tung-Striebel).

The forward filter keeps its error state at zero between updates and feeds each update's estimate back
into the nominal solution (kalman.feedback): at an epoch k (the covariance propagated to t_k, then the
measurements at t_k) the updates' total correction ``dx_k`` leaves the posterior nominal, ``nominal^+ =
nominal^- (-) dx_k``, with covariance ``P^+_k``; the propagation to the next epoch gives ``P^-_{k+1} =
Phi_k P^+_k Phi_k^T + Q_k``. The error estimate of the prior nominal given everything is then the smoothed
error of the posterior plus the correction, and the RTS recursion (H. E. Rauch, F. Tung, C. T. Striebel,
AIAA Journal 3(8), 1965; Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
Systems*, 2nd ed., 2013, section 3.4.2, fixed-interval smoothing) runs backward from the last epoch N::

    A_k   = P^+_k Phi_k^T (P^-_{k+1})^-1
    e^s_k = A_k (e^s_{k+1} + dx_{k+1}),                  e^s_N = 0
    P^s_k = P^+_k + A_k (P^s_{k+1} - P^-_{k+1}) A_k^T,   P^s_N = P^+_N

``e^s_k`` estimates the posterior nominal's error at t_k (estimate minus truth): the smoothed solution is
that nominal corrected by it (kalman.feedback's correction with x = e^s_k), its covariance ``P^s_k``.

The forward pass records one row of a **store** per epoch (:func:`record`), only over the ``na`` active
states (those with a variance; the others are not estimated and keep e = 0): ``t``, the output row, then
``dx`` (na), ``e`` (na, filled by :func:`backward`), ``P^-`` (na^2), ``P^+`` (na^2, replaced by P^s),
``Phi`` from the epoch before (na^2): :func:`store_width` values. The transition is the product of the
propagations' ``Phi`` since the epoch before, kept in the pending-propagation vector's tail (aided.py:
``acc[ACC_SIZE:]``, NX x NX) so that a measurement undone restores it with the rest.
"""

from __future__ import annotations

import numpy as np

from . import earth
from . import strapdown as sd
from .errmodel import NX, X_DP, X_DV, X_PHI, X_SENSORS, matmul, matmul_bt
from .jit import kernel
from .kalman import spd_inverse
from .rotation import dcm_to_euler_s, quat_mul_s, quat_to_dcm_s, quat_to_rotvec, rotvec_to_quat_s
from .strapdown import GEOGRAPHIC

EP_T, EP_ROW, EP_DX = 0, 1, 2  # store columns: epoch time (s), its output row, then the slots of store_slots


def store_width(na: int) -> int:
    """Values per epoch of a store over ``na`` active states (module docstring; Python's, for allocating)."""
    return 2 + 2 * na + 3 * na * na


def described(epochs: int, singular: int) -> str:
    """What a smoothing did, for the command line: its epochs, and those whose prior could not be inverted."""
    return f"smoothed over {epochs} epochs" + (
        f"; at {singular} of them the prior could not be inverted and the forward solution was kept" if singular
        else "")


@kernel
def store_slots(na: int) -> tuple[int, int, int, int, int]:
    """First columns of ``dx``, ``e``, ``P^-``, ``P^+`` (P^s after :func:`backward`) and ``Phi`` in a store row."""
    o_e = EP_DX + na
    o_pm = o_e + na
    o_pp = o_pm + na * na
    return EP_DX, o_e, o_pm, o_pp, o_pp + na * na


@kernel
def reset_transition(tail: np.ndarray) -> None:
    """The transition product (NX x NX, row-major in ``tail``) back to the identity."""
    for i in range(NX * NX):
        tail[i] = 0.0
    for i in range(NX):
        tail[i * NX + i] = 1.0


@kernel
def chain_transition(tail: np.ndarray, phi: np.ndarray) -> None:
    """One more propagation: the transition product (row-major NX x NX in ``tail``) becomes ``phi`` times it."""
    run = tail[:NX * NX].copy().reshape((NX, NX))
    prod = matmul(phi, run)
    for i in range(NX):
        for j in range(NX):
            tail[i * NX + j] = prod[i, j]


@kernel
def nominal_difference(s_a: np.ndarray, bias_a: np.ndarray, s_b: np.ndarray, bias_b: np.ndarray,
                       cfg: np.ndarray) -> np.ndarray:
    """The error state ``x`` (NX) that kalman.feedback applies to nominal a to give nominal b.

    Inverts feedback: ``phi = -rotvec(q_b q_a^*)`` (feedback's ``q_b = r(-phi) q_a``), ``dv = v_a - v_b``,
    ``dp_N = (L_a - L_b)(R_N + h)``, ``dp_E = (lambda_a - lambda_b)(R_E + h) cos L`` (the transport
    rotation to first order in dp / R; laboratory mode: ``p_a - p_b``), ``dp_D = h_b - h_a``, sensors
    ``bias_a - bias_b``.
    """
    x = np.zeros(NX)
    qa = (s_a[sd.S.Q], -s_a[sd.S.Q + 1], -s_a[sd.S.Q + 2], -s_a[sd.S.Q + 3])
    d = quat_mul_s((s_b[sd.S.Q], s_b[sd.S.Q + 1], s_b[sd.S.Q + 2], s_b[sd.S.Q + 3]), qa)
    rv = quat_to_rotvec(np.array([d[0], d[1], d[2], d[3]]))
    for i in range(3):
        x[X_PHI + i] = -rv[i]
        x[X_DV + i] = s_a[sd.S.V + i] - s_b[sd.S.V + i]
    if cfg[sd.CFG_EARTH] > 0.5:
        lat_a, lon_a, h_a = sd.position(s_a, cfg, GEOGRAPHIC)
        lat_b, lon_b, h_b = sd.position(s_b, cfg, GEOGRAPHIC)
        r_n, r_e = earth.radii(lat_a)
        x[X_DP] = (lat_a - lat_b) * (r_n + h_a)
        x[X_DP + 1] = (lon_a - lon_b) * (r_e + h_a) * np.cos(lat_a)
        x[X_DP + 2] = h_b - h_a
    else:
        for i in range(3):
            x[X_DP + i] = s_a[sd.S.PF + i] - s_b[sd.S.PF + i]
    for i in range(bias_a.shape[0]):
        x[X_SENSORS + i] = bias_a[i] - bias_b[i]
    return x


@kernel
def record(store: np.ndarray, n_ep: int, t: float, row: int, Pm: np.ndarray, Pp: np.ndarray, tail: np.ndarray,
           dx: np.ndarray, active: np.ndarray) -> int:
    """One epoch into ``store`` row ``n_ep`` (module docstring): its time, output row, the correction ``dx``
    (NX), ``P^-``, ``P^+`` (NX x NX) and the transition product in ``tail`` over the ``active`` states; the
    product restarts at the identity. Returns the new epoch count; a full store records nothing more."""
    if n_ep >= store.shape[0]:
        return n_ep
    na = active.shape[0]
    o_dx, o_e, o_pm, o_pp, o_phi = store_slots(na)
    r = store[n_ep]
    r[EP_T] = t
    r[EP_ROW] = row
    for a in range(na):
        r[o_dx + a] = dx[active[a]]
        r[o_e + a] = 0.0
        for b in range(na):
            r[o_pm + a * na + b] = Pm[active[a], active[b]]
            r[o_pp + a * na + b] = Pp[active[a], active[b]]
            r[o_phi + a * na + b] = tail[active[a] * NX + active[b]]
    reset_transition(tail)
    return n_ep + 1


@kernel
def backward(store: np.ndarray, n_ep: int, na: int) -> int:
    """The RTS recursion (module docstring) over the first ``n_ep`` epochs of ``store``, in place: each
    row's ``e`` slot receives e^s and its ``P^+`` slot P^s. States whose ``P^-_{k+1}`` variance is not
    positive take no part in that step's inverse. Returns the number of epochs whose ``P^-_{k+1}`` was not
    positive definite over those states: there A = 0 and the forward estimate is kept."""
    o_dx, o_e, o_pm, o_pp, o_phi = store_slots(na)
    bad = 0
    ps_next = np.empty((na, na))
    if n_ep > 0:
        ps_next[:, :] = store[n_ep - 1, o_pp:o_pp + na * na].reshape((na, na))
    idx = np.empty(na, dtype=np.int64)
    for k in range(n_ep - 2, -1, -1):
        nxt = store[k + 1]
        m = nxt[o_pm:o_pm + na * na].copy().reshape((na, na))
        phi = nxt[o_phi:o_phi + na * na].copy().reshape((na, na))
        pp = store[k, o_pp:o_pp + na * na].copy().reshape((na, na))
        n_act = 0
        for i in range(na):
            if m[i, i] > 0.0:
                idx[n_act] = i
                n_act += 1
        sub = np.empty((n_act, n_act))
        for a in range(n_act):
            for b in range(n_act):
                sub[a, b] = m[idx[a], idx[b]]
        inv, ok = spd_inverse(sub)
        if not ok:
            bad += 1
            ps_next[:, :] = pp  # P^s_k = P^+_k, e^s_k = 0 (the row's e slot stays 0)
            continue
        minv = np.zeros((na, na))
        for a in range(n_act):
            for b in range(n_act):
                minv[idx[a], idx[b]] = inv[a, b]
        A = matmul(matmul_bt(pp, phi), minv)  # P^+_k Phi_k^T (P^-_{k+1})^-1
        for i in range(na):
            acc = 0.0
            for j in range(na):
                acc += A[i, j] * (nxt[o_e + j] + nxt[o_dx + j])
            store[k, o_e + i] = acc
        ps = pp + matmul_bt(matmul(A, ps_next - m), A)
        for i in range(na):
            for j in range(na):
                store[k, o_pp + i * na + j] = ps[i, j]
        ps_next[:, :] = ps
    return bad


@kernel
def correct_solution(row: np.ndarray, e: np.ndarray) -> None:
    """A solution row ``t, lat, lon, h, v_ned, roll, pitch, yaw, q`` (rad, strapdown.solution_row) corrected
    by the error estimate ``e`` (NX) as kalman.feedback corrects the state: ``q <- r(-phi) q``, the Euler
    angles from it; ``v -= dv``; ``lat -= dp_N / (R_N + h)``, ``lon -= dp_E / ((R_E + h) cos lat)`` (first
    order in dp / R, at the row's latitude), ``h += dp_D``."""
    q = quat_mul_s(rotvec_to_quat_s(-e[X_PHI], -e[X_PHI + 1], -e[X_PHI + 2]), (row[10], row[11], row[12], row[13]))
    qn = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    sign = -1.0 if q[0] < 0.0 else 1.0  # a non-negative scalar part, as solution_row writes it
    for a in range(4):
        row[10 + a] = sign * q[a] / qn
    c = quat_to_dcm_s((row[10], row[11], row[12], row[13]))
    row[7], row[8], row[9] = dcm_to_euler_s(c[0], c[1], c[3], c[4], c[6], c[7], c[8])
    for i in range(3):
        row[4 + i] -= e[X_DV + i]
    lat, h = row[1], row[3]
    r_n, r_e = earth.radii(lat)
    row[1] = lat - e[X_DP] / (r_n + h)
    row[2] -= e[X_DP + 1] / ((r_e + h) * np.cos(lat))
    row[3] = h + e[X_DP + 2]


__all__ = ["backward", "correct_solution", "nominal_difference", "record", "store_slots", "store_width"]
