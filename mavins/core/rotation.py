"""Attitude representations and their conversions (pure, compiled).

Conventions (CONVENTIONS.md "Frames and attitude"):
- quaternions are Hamilton, scalar first ``[w, x, y, z]``; ``q_nb`` maps body
  vectors to the navigation frame, ``v_n = C(q) v_b``;
- a DCM is a 3x3 array ``C`` with the same meaning (``C = C_b^n``);
- Euler angles are ZYX: ``C_b^n = Rz(yaw) Ry(pitch) Rx(roll)``, radians;
- a rotation vector ``phi`` is axis times angle (rad); ``exp(phi)`` is the
  rotation through ``|phi|`` about ``phi`` (Bortz 1971; [TW11] slide
  "11.2.1 DCM algorithm": ``A = I + sin s/s [s x] + (1 - cos s)/s^2 [s x]^2``).

Citation keys ([TW11], [DE], ...) are listed in docs/algorithms.md.

Small angles use Taylor series so every function is smooth through zero.
"""

from __future__ import annotations

import numpy as np

from .jit import kernel

# Below this angle (rad) the series forms are used; their truncation error
# (s^6 terms) is then far below double precision.
SMALL_ANGLE = 1e-4


@kernel
def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[v x]`` so that ``[v x] u = v x u``."""
    m = np.zeros((3, 3))
    m[0, 1] = -v[2]
    m[0, 2] = v[1]
    m[1, 0] = v[2]
    m[1, 2] = -v[0]
    m[2, 0] = -v[1]
    m[2, 1] = v[0]
    return m


@kernel
def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Vector product ``a x b`` of two 3-vectors."""
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


@kernel
def mat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3x3 matrix product (explicit loops: no BLAS call for tiny matrices)."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]
    return out


@kernel
def mat_vec(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """3x3 matrix times 3-vector."""
    out = np.empty(3)
    for i in range(3):
        out[i] = a[i, 0] * v[0] + a[i, 1] * v[1] + a[i, 2] * v[2]
    return out


@kernel
def quat_mul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p (x) q`` (Savage, Strapdown Analytics, quaternion algebra; Hamilton convention of CONVENTIONS.md)."""
    out = np.empty(4)
    out[0] = p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3]
    out[1] = p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2]
    out[2] = p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1]
    out[3] = p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0]
    return out


@kernel
def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate ``[w, -x, -y, -z]`` (the inverse of a unit quaternion)."""
    out = np.empty(4)
    out[0] = q[0]
    out[1] = -q[1]
    out[2] = -q[2]
    out[3] = -q[3]
    return out


@kernel
def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternion ``q / |q|``."""
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return q / n


@kernel
def quat_canonical(q: np.ndarray) -> np.ndarray:
    """The same rotation with a non-negative scalar part."""
    if q[0] < 0.0:
        return -q
    return q.copy()


@kernel
def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``C(q) v`` for a unit quaternion without forming the DCM."""
    w = q[0]
    u = q[1:4]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)


@kernel
def quat_to_dcm(q: np.ndarray) -> np.ndarray:
    """DCM of a unit quaternion, ``v_n = C(q) v_b`` (Savage, Strapdown Analytics, quaternion/DCM relation)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    c = np.empty((3, 3))
    c[0, 0] = w * w + x * x - y * y - z * z
    c[0, 1] = 2.0 * (x * y - w * z)
    c[0, 2] = 2.0 * (x * z + w * y)
    c[1, 0] = 2.0 * (x * y + w * z)
    c[1, 1] = w * w - x * x + y * y - z * z
    c[1, 2] = 2.0 * (y * z - w * x)
    c[2, 0] = 2.0 * (x * z - w * y)
    c[2, 1] = 2.0 * (y * z + w * x)
    c[2, 2] = w * w - x * x - y * y + z * z
    return c


@kernel
def dcm_to_quat(c: np.ndarray) -> np.ndarray:
    """Unit quaternion (scalar >= 0) of a rotation matrix.

    Shepperd's method: pick the largest of the four squared components so the
    division is always well conditioned (Shepperd 1978).
    """
    tr = c[0, 0] + c[1, 1] + c[2, 2]
    q = np.empty(4)
    if tr >= c[0, 0] and tr >= c[1, 1] and tr >= c[2, 2]:
        s = 2.0 * np.sqrt(1.0 + tr)
        q[0] = 0.25 * s
        q[1] = (c[2, 1] - c[1, 2]) / s
        q[2] = (c[0, 2] - c[2, 0]) / s
        q[3] = (c[1, 0] - c[0, 1]) / s
    elif c[0, 0] >= c[1, 1] and c[0, 0] >= c[2, 2]:
        s = 2.0 * np.sqrt(1.0 + c[0, 0] - c[1, 1] - c[2, 2])
        q[0] = (c[2, 1] - c[1, 2]) / s
        q[1] = 0.25 * s
        q[2] = (c[0, 1] + c[1, 0]) / s
        q[3] = (c[0, 2] + c[2, 0]) / s
    elif c[1, 1] >= c[2, 2]:
        s = 2.0 * np.sqrt(1.0 - c[0, 0] + c[1, 1] - c[2, 2])
        q[0] = (c[0, 2] - c[2, 0]) / s
        q[1] = (c[0, 1] + c[1, 0]) / s
        q[2] = 0.25 * s
        q[3] = (c[1, 2] + c[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 - c[0, 0] - c[1, 1] + c[2, 2])
        q[0] = (c[1, 0] - c[0, 1]) / s
        q[1] = (c[0, 2] + c[2, 0]) / s
        q[2] = (c[1, 2] + c[2, 1]) / s
        q[3] = 0.25 * s
    q = quat_normalize(q)
    return quat_canonical(q)


@kernel
def euler_to_dcm(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``C_b^n = Rz(yaw) Ry(pitch) Rx(roll)`` ([DE] section 2, ZYX DCM product)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    c = np.empty((3, 3))
    c[0, 0] = cp * cy
    c[0, 1] = -cr * sy + sr * sp * cy
    c[0, 2] = sr * sy + cr * sp * cy
    c[1, 0] = cp * sy
    c[1, 1] = cr * cy + sr * sp * sy
    c[1, 2] = -sr * cy + cr * sp * sy
    c[2, 0] = -sp
    c[2, 1] = sr * cp
    c[2, 2] = cr * cp
    return c


@kernel
def wrap_pi(a: float) -> float:
    """Angle in (-pi, pi]."""
    a = np.fmod(a, 2.0 * np.pi)
    if a > np.pi:
        a -= 2.0 * np.pi
    elif a <= -np.pi:
        a += 2.0 * np.pi
    return a


@kernel
def dcm_to_euler(c: np.ndarray) -> np.ndarray:
    """``[roll, pitch, yaw]`` (rad) of ``C_b^n``; roll, yaw in (-pi, pi].

    Inverse of :func:`euler_to_dcm` (CONVENTIONS.md Euler ranges). At pitch = +-90 deg
    roll and yaw are not separable; roll is then set to 0.
    """
    s = -c[2, 0]
    if s > 1.0:
        s = 1.0
    elif s < -1.0:
        s = -1.0
    pitch = np.arcsin(s)
    out = np.empty(3)
    if abs(s) > 1.0 - 1e-15:
        out[0] = 0.0
        out[1] = pitch
        out[2] = wrap_pi(np.arctan2(-c[0, 1], c[1, 1]))
        return out
    out[0] = wrap_pi(np.arctan2(c[2, 1], c[2, 2]))
    out[1] = pitch
    out[2] = wrap_pi(np.arctan2(c[1, 0], c[0, 0]))
    return out


@kernel
def euler_to_quat(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Quaternion of ZYX Euler angles: ``q(yaw z) (x) q(pitch y) (x) q(roll x)``."""
    cr, sr = np.cos(0.5 * roll), np.sin(0.5 * roll)
    cp, sp = np.cos(0.5 * pitch), np.sin(0.5 * pitch)
    cy, sy = np.cos(0.5 * yaw), np.sin(0.5 * yaw)
    q = np.empty(4)
    q[0] = cr * cp * cy + sr * sp * sy
    q[1] = sr * cp * cy - cr * sp * sy
    q[2] = cr * sp * cy + sr * cp * sy
    q[3] = cr * cp * sy - sr * sp * cy
    return quat_canonical(q)


@kernel
def quat_to_euler(q: np.ndarray) -> np.ndarray:
    """``[roll, pitch, yaw]`` (rad) of a unit quaternion."""
    return dcm_to_euler(quat_to_dcm(q))


@kernel
def rotvec_to_quat(phi: np.ndarray) -> np.ndarray:
    """Exact ``exp(phi)`` as a quaternion ``[cos(s/2), sin(s/2)/s phi]``.

    Bortz 1971; the exact form of the truncated series in CONVENTIONS.md ``--order``.
    """
    s2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    s = np.sqrt(s2)
    if s < SMALL_ANGLE:
        c = 1.0 - s2 / 8.0 + s2 * s2 / 384.0
        k = 0.5 - s2 / 48.0 + s2 * s2 / 3840.0
    else:
        c = np.cos(0.5 * s)
        k = np.sin(0.5 * s) / s
    return quat_from_coeffs(phi, c, k)


@kernel
def quat_from_coeffs(phi: np.ndarray, c: float, k: float) -> np.ndarray:
    """``[c, k phi]``: the quaternion form shared by the exact and truncated updates."""
    q = np.empty(4)
    q[0] = c
    q[1] = k * phi[0]
    q[2] = k * phi[1]
    q[3] = k * phi[2]
    return q


@kernel
def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vector (rad, angle in [0, pi]) of a unit quaternion."""
    qc = quat_canonical(q)
    v = np.sqrt(qc[1] * qc[1] + qc[2] * qc[2] + qc[3] * qc[3])
    angle = 2.0 * np.arctan2(v, qc[0])
    if v < SMALL_ANGLE:
        # angle / v = 2 atan(x) / v with x = v / w: 2/w (1 - x^2/3 + x^4/5)
        x2 = v * v / (qc[0] * qc[0])
        k = 2.0 / qc[0] * (1.0 - x2 / 3.0 + x2 * x2 / 5.0)
    else:
        k = angle / v
    out = np.empty(3)
    out[0] = k * qc[1]
    out[1] = k * qc[2]
    out[2] = k * qc[3]
    return out


@kernel
def rotvec_to_dcm(phi: np.ndarray) -> np.ndarray:
    """Exact ``exp([phi x]) = I + sin s/s [phi x] + (1-cos s)/s^2 [phi x]^2``.

    [TW11] slide "11.2.1 DCM algorithm".
    """
    x, y, z = phi[0], phi[1], phi[2]
    s2 = x * x + y * y + z * z
    if s2 < SMALL_ANGLE * SMALL_ANGLE:
        a1 = 1.0 - s2 / 6.0 + s2 * s2 / 120.0
        a2 = 0.5 - s2 / 24.0 + s2 * s2 / 720.0
    else:
        s = np.sqrt(s2)
        a1 = np.sin(s) / s
        a2 = (1.0 - np.cos(s)) / s2
    return dcm_from_coeffs(phi, a1, a2)


@kernel
def dcm_from_coeffs(phi: np.ndarray, a1: float, a2: float) -> np.ndarray:
    """``I + a1 [phi x] + a2 [phi x]^2`` (using ``[phi x]^2 = phi phi^T - |phi|^2 I``).

    The DCM form shared by the exact and truncated updates ([TW11] 11.2.1).
    """
    x, y, z = phi[0], phi[1], phi[2]
    s2 = x * x + y * y + z * z
    c = np.empty((3, 3))
    c[0, 0] = 1.0 + a2 * (x * x - s2)
    c[0, 1] = -a1 * z + a2 * x * y
    c[0, 2] = a1 * y + a2 * x * z
    c[1, 0] = a1 * z + a2 * x * y
    c[1, 1] = 1.0 + a2 * (y * y - s2)
    c[1, 2] = -a1 * x + a2 * y * z
    c[2, 0] = -a1 * y + a2 * x * z
    c[2, 1] = a1 * x + a2 * y * z
    c[2, 2] = 1.0 + a2 * (z * z - s2)
    return c


@kernel
def dcm_to_rotvec(c: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix (through the quaternion)."""
    return quat_to_rotvec(dcm_to_quat(c))


@kernel
def orthonormalize(c: np.ndarray) -> np.ndarray:
    """One step of ``C <- C - 1/2 (C C^T - I) C`` ([TW11] 11.2.1 error analysis,
    the orthogonality defect S of the computed matrix).

    Removes the first-order non-orthogonality; applied every update it keeps
    the DCM orthonormal to round-off.
    """
    e = mat_mul(c, c.T) - np.eye(3)
    return c - 0.5 * mat_mul(e, c)


@kernel
def euler_rates(euler: np.ndarray, w_nb_b: np.ndarray) -> np.ndarray:
    """Euler-angle kinematics ``[roll', pitch', yaw']`` from the body rate.

    Inverse of ``w_nb^b = [[1, 0, -sin p], [0, cos r, sin r cos p],
    [0, -sin r, cos r cos p]] [r', p', y']`` (attitude-equation notes,
    "Euler angle differential equation"). Singular at
    pitch = +-90 deg.
    """
    r, p = euler[0], euler[1]
    sr, cr = np.sin(r), np.cos(r)
    tp, cp = np.tan(p), np.cos(p)
    wx, wy, wz = w_nb_b[0], w_nb_b[1], w_nb_b[2]
    out = np.empty(3)
    out[0] = wx + (wy * sr + wz * cr) * tp
    out[1] = wy * cr - wz * sr
    out[2] = (wy * sr + wz * cr) / cp
    return out


@kernel
def dcm_rate(c: np.ndarray, w_nb_b: np.ndarray) -> np.ndarray:
    """DCM kinematics ``dC/dt = C [w_nb^b x]`` ([TW11] 11.1; [DE] DCM equation)."""
    return mat_mul(c, skew(w_nb_b))


@kernel
def quat_rate(q: np.ndarray, w_nb_b: np.ndarray) -> np.ndarray:
    """Quaternion kinematics ``dq/dt = 1/2 q (x) [0, w_nb^b]`` ([DE] lists it beside the DCM and Euler forms; [LAI12] eq. 3)."""
    p = np.empty(4)
    p[0] = 0.0
    p[1] = w_nb_b[0]
    p[2] = w_nb_b[1]
    p[3] = w_nb_b[2]
    return 0.5 * quat_mul(q, p)


@kernel
def quat_angle_between(p: np.ndarray, q: np.ndarray) -> float:
    """Rotation angle (rad, in [0, pi]) of ``p^-1 (x) q`` for unit quaternions.

    The atan2 form keeps full precision for tiny angles, where acos loses it.
    """
    e = quat_mul(quat_conj(p), q)
    v = np.sqrt(e[1] * e[1] + e[2] * e[2] + e[3] * e[3])
    return 2.0 * np.arctan2(v, abs(e[0]))
