"""Fixed-interval smoothing of the closed-loop error-state filter (Rauch-Tung-Striebel).

The forward filter keeps its error state at zero between updates and feeds each update's estimate back
into the nominal solution (kalman.feedback): at an epoch k (the covariance propagated to t_k, then the
measurements at t_k) the update's total correction ``dx_k`` leaves the posterior nominal, ``nominal^+ =
nominal^- (-) dx_k``, with covariance ``P^+_k``; the propagation to the next epoch gives ``P^-_{k+1} =
Phi_k P^+_k Phi_k^T + Q_k``. The error estimate of the prior nominal given everything is then the smoothed
error of the posterior plus the correction, and the RTS recursion (H. E. Rauch, F. Tung, C. T. Striebel,
AIAA Journal 3(8), 1965; Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
Systems*, 2nd ed., 2013, section 3.4.2, fixed-interval smoothing) runs backward from the last epoch N::

    A_k   = P^+_k Phi_k^T (P^-_{k+1})^-1
    e^s_k = A_k (e^s_{k+1} + dx_{k+1}),                  e^s_N = 0
    P^s_k = P^+_k + A_k (P^s_{k+1} - P^-_{k+1}) A_k^T,   P^s_N = P^+_N

``e^s_k`` estimates the posterior nominal's error at t_k (estimate minus truth): the smoothed solution is
that nominal corrected by it (kalman.feedback with x = e^s_k), its covariance ``P^s_k``. States that do
not take part (zero variance in ``P^-``: not estimated) are left out of the inverse and keep e = 0.
"""

from __future__ import annotations

import numpy as np

from .errmodel import matmul, matmul_bt
from .jit import kernel
from .kalman import spd_inverse


@kernel
def backward(Pp: np.ndarray, Pm: np.ndarray, phi: np.ndarray, dx: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The RTS recursion (module docstring) over E epochs of an n-state filter.

    ``Pp`` (E, n, n) P^+ at each epoch; ``Pm`` (E, n, n) P^- at each epoch (row 0 unused); ``phi`` (E, n, n)
    the transition from epoch k to k + 1 (the last unused); ``dx`` (E, n) each epoch's total correction
    (row 0 unused). Returns the smoothed errors ``e`` (E, n), covariances ``Ps`` (E, n, n) and the number
    of epochs whose P^- was not positive definite over the active states (there A = 0: the forward
    estimate is kept).
    """
    n_ep, n = Pp.shape[0], Pp.shape[1]
    e = np.zeros((n_ep, n))
    Ps = np.zeros((n_ep, n, n))
    Ps[n_ep - 1] = Pp[n_ep - 1]
    bad = 0
    for k in range(n_ep - 2, -1, -1):
        m = Pm[k + 1]
        idx = np.empty(n, dtype=np.int64)
        na = 0
        for i in range(n):
            if m[i, i] > 0.0:
                idx[na] = i
                na += 1
        sub = np.empty((na, na))
        for a in range(na):
            for b in range(na):
                sub[a, b] = m[idx[a], idx[b]]
        inv, ok = spd_inverse(sub)
        if not ok:
            bad += 1
            Ps[k] = Pp[k]
            continue
        minv = np.zeros((n, n))
        for a in range(na):
            for b in range(na):
                minv[idx[a], idx[b]] = inv[a, b]
        A = matmul(matmul_bt(Pp[k], phi[k]), minv)  # P^+_k Phi_k^T (P^-_{k+1})^-1
        nxt = e[k + 1] + dx[k + 1]
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += A[i, j] * nxt[j]
            e[k, i] = acc
        diff = Ps[k + 1] - m
        Ps[k] = Pp[k] + matmul_bt(matmul(A, diff), A)
    return e, Ps, bad
