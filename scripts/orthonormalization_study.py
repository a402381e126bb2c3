"""Orthonormalisation and normalisation (Zhang & Sun 3.4, 3.5) against the truncated updates' drift.

For the constant-rate motion of docs/validation.md tables 11.1/11.2 (10 rad/s about (1, 2, 2)/3,
sigma = 0.1 rad, 2000 updates, drift = least-squares slope of the attitude-error angle over the
second half) the DCM recursion ``C(k) = C(k-1) A(sigma)`` is run with

* ``optimal``: the closest orthonormal matrix ``C (C^T C)^(-1/2)`` (Zhang & Sun 3.4, the
  Frobenius-optimal orthonormalisation, here from the SVD ``U V^T``), every update;
* ``first order``: its first-order form ``C - 1/2 C (C^T C - I)``, every update;
* ``kernel``: what ``mavins nav --attitude dcm`` measures (``C - 1/2 (C C^T - I) C``,
  rotation.orthonormalize_s), every update;
* ``never``: no orthonormalisation, the error angle taken of the closest orthonormal matrix,
  with the orthogonality defect ``|C^T C - I|`` at the end;

and the quaternion recursion with ``q / |q|`` (Zhang & Sun 3.5: the optimal normalisation, the
closest unit quaternion) against the first-order ``q (3 - |q|^2)/2``. Prints a markdown table.

Run from the repository root::

    .venv/bin/python scripts/orthonormalization_study.py
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mavins.core.rotation import dcm_from_coeffs, quat_to_dcm, rotvec_to_dcm
from mavins.core.runner import navigate
from sim import motion

AXIS = np.array([1.0, 2.0, 2.0]) / 3.0
RATE, DT, N = 10.0, 0.01, 2000
DEG_H = math.degrees(1.0) * 3600.0


def _dcm_coeffs(order: int, s2: float) -> tuple[float, float]:
    """(a1, a2) of docs/conventions.md --order for the DCM update."""
    a1 = 1.0 if order <= 2 else 1.0 - s2 / 6.0
    a2 = (0.0, 0.5, 0.5, 0.5 - s2 / 24.0)[order - 1]
    return a1, a2


def _quat_coeffs(order: int, s2: float) -> tuple[float, float]:
    """(a_c, a_s) of docs/conventions.md --order for the quaternion update."""
    ac = (1.0, 1.0 - s2 / 8.0, 1.0 - s2 / 8.0, 1.0 - s2 / 8.0 + s2 * s2 / 384.0)[order - 1]
    as_ = (0.5, 0.5, 0.5 - s2 / 48.0, 0.5 - s2 / 48.0)[order - 1]
    return ac, as_


def _closest(c: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(c)
    return u @ vt


def _angle(c: np.ndarray, k: int, sigma: np.ndarray) -> float:
    e = rotvec_to_dcm(sigma * k).T @ c
    sin_a = 0.5 * float(np.linalg.norm([e[2, 1] - e[1, 2], e[0, 2] - e[2, 0], e[1, 0] - e[0, 1]]))
    return math.atan2(sin_a, 0.5 * (float(np.trace(e)) - 1.0))


def _drift(angles: np.ndarray) -> float:
    """deg/h: least-squares slope over the second half."""
    k = np.arange(1, angles.shape[0] + 1)[N // 2:] * DT
    return float(np.polyfit(k, angles[N // 2:], 1)[0]) * DEG_H


def dcm_run(order: int, method: str) -> tuple[float, float]:
    sigma = AXIS * RATE * DT
    a1, a2 = _dcm_coeffs(order, float(sigma @ sigma))
    a = dcm_from_coeffs(sigma, a1, a2)
    c = np.eye(3)
    angles = np.empty(N)
    for k in range(1, N + 1):
        c = c @ a
        if method == "optimal":
            c = _closest(c)
        elif method == "first order":
            c = c - 0.5 * c @ (c.T @ c - np.eye(3))
        angles[k - 1] = _angle(_closest(c) if method == "never" else c, k, sigma)
    return _drift(angles), float(np.linalg.norm(c.T @ c - np.eye(3)))


def quat_run(order: int, method: str) -> float:
    sigma = AXIS * RATE * DT
    ac, as_ = _quat_coeffs(order, float(sigma @ sigma))
    r = np.array([ac, *(as_ * sigma)])
    q = np.array([1.0, 0.0, 0.0, 0.0])
    angles = np.empty(N)
    for k in range(1, N + 1):
        w0, v0 = q[0], q[1:]
        q = np.array([w0 * r[0] - v0 @ r[1:], *(w0 * r[1:] + r[0] * v0 + np.cross(v0, r[1:]))])
        n2 = float(q @ q)
        q = q / math.sqrt(n2) if method == "optimal" else q * (3.0 - n2) / 2.0
        w, x, y, z = q / np.linalg.norm(q)
        c = np.array([[w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]])
        angles[k - 1] = _angle(c, k, sigma)
    return _drift(angles)


def kernel_drift(order: int, attitude: str) -> float:
    m = motion.constant_rate(AXIS * RATE, DT, N)
    init = {"t": 0.0, "lat": 0.0, "lon": 0.0, "h": 0.0, "vn": 0.0, "ve": 0.0, "vd": 0.0,
            "roll": 0.0, "pitch": 0.0, "yaw": 0.0}
    sol = navigate(m.t, m.dtheta, m.dv, init, samples=1, attitude=attitude, order=str(order), earth_model="none")
    angles = np.array([_angle(quat_to_dcm(q), k + 1, AXIS * RATE * DT) for k, q in enumerate(sol[:, 10:14])])
    return _drift(angles)


def main() -> None:
    print("| order | DCM optimal C(CᵀC)^-1/2 | DCM first order C - ½C(CᵀC - I) | **kernel** DCM (C - ½(CCᵀ - I)C) "
          "| DCM never (closest) | defect after 2000 never | quaternion q/abs(q) | quaternion q(3 - abs(q)²)/2 "
          "| **kernel** quaternion |")
    print("|---|---|---|---|---|---|---|---|---|")
    for order in (1, 2, 3, 4):
        opt, _ = dcm_run(order, "optimal")
        fo, _ = dcm_run(order, "first order")
        nev, defect = dcm_run(order, "never")
        qo = quat_run(order, "optimal")
        qf = quat_run(order, "first order")
        print(f"| {order} | {abs(opt):.4g} | {abs(fo):.4g} | {abs(kernel_drift(order, 'dcm')):.4g} | {abs(nev):.4g} "
              f"| {defect:.3g} | {abs(qo):.4g} | {abs(qf):.4g} | {abs(kernel_drift(order, 'quaternion')):.4g} |")


if __name__ == "__main__":
    main()
