"""Attitude representations and their conversions (pure, compiled).

Conventions (docs/conventions.md "Frames and attitude"):
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

# Below this angle (rad) the series forms of exp(phi) are used, to the s^6
# term: the first omitted (s^8 / 8! and smaller) is then below 1e-20, far
# below double precision.
SMALL_ANGLE = 1e-2
# The inverse series (quaternion to rotation vector) converges slower (x^6/7).
SMALL_ANGLE_LOG = 1e-4

Quat = tuple[float, float, float, float]
Mat9 = tuple[float, float, float, float, float, float, float, float, float]


@kernel
def _vec4(t: Quat) -> np.ndarray:
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = t[0], t[1], t[2], t[3]
    return out


@kernel
def _mat3(t: Mat9) -> np.ndarray:
    out = np.empty((3, 3))
    out[0, 0], out[0, 1], out[0, 2] = t[0], t[1], t[2]
    out[1, 0], out[1, 1], out[1, 2] = t[3], t[4], t[5]
    out[2, 0], out[2, 1], out[2, 2] = t[6], t[7], t[8]
    return out


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
    """Hamilton product ``p (x) q`` (Savage, Strapdown Analytics, quaternion algebra; Hamilton convention of docs/conventions.md)."""
    return _vec4(quat_mul_s((p[0], p[1], p[2], p[3]), (q[0], q[1], q[2], q[3])))


@kernel
def quat_mul_s(p: Quat, q: Quat) -> Quat:
    """:func:`quat_mul` on 4-tuples (allocation-free, for the hot loop)."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return (p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0)


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
    return _mat3(quat_to_dcm_s((q[0], q[1], q[2], q[3])))


@kernel
def quat_to_dcm_s(q: Quat) -> Mat9:
    """:func:`quat_to_dcm` on a 4-tuple; the DCM as a row-major 9-tuple."""
    w, x, y, z = q
    return (w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z)


@kernel
def dcm_to_quat(c: np.ndarray) -> np.ndarray:
    """Unit quaternion (scalar >= 0) of a rotation matrix.

    Shepperd's method: pick the largest of the four squared components so the
    division is always well conditioned (Shepperd 1978).
    """
    return _vec4(dcm_to_quat_s((c[0, 0], c[0, 1], c[0, 2], c[1, 0], c[1, 1], c[1, 2], c[2, 0], c[2, 1], c[2, 2])))


@kernel
def dcm_to_quat_s(c: Mat9) -> Quat:
    """:func:`dcm_to_quat` of a row-major 9-tuple."""
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = c
    tr = c00 + c11 + c22
    if tr >= c00 and tr >= c11 and tr >= c22:
        s = 2.0 * np.sqrt(1.0 + tr)
        q0, q1, q2, q3 = 0.25 * s, (c21 - c12) / s, (c02 - c20) / s, (c10 - c01) / s
    elif c00 >= c11 and c00 >= c22:
        s = 2.0 * np.sqrt(1.0 + c00 - c11 - c22)
        q0, q1, q2, q3 = (c21 - c12) / s, 0.25 * s, (c01 + c10) / s, (c02 + c20) / s
    elif c11 >= c22:
        s = 2.0 * np.sqrt(1.0 - c00 + c11 - c22)
        q0, q1, q2, q3 = (c02 - c20) / s, (c01 + c10) / s, 0.25 * s, (c12 + c21) / s
    else:
        s = 2.0 * np.sqrt(1.0 - c00 - c11 + c22)
        q0, q1, q2, q3 = (c10 - c01) / s, (c02 + c20) / s, (c12 + c21) / s, 0.25 * s
    n = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    if q0 < 0.0:
        n = -n
    return q0 / n, q1 / n, q2 / n, q3 / n


@kernel
def euler_to_dcm(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``C_b^n = Rz(yaw) Ry(pitch) Rx(roll)`` ([DE] section 2, ZYX DCM product)."""
    return _mat3(euler_to_dcm_s(roll, pitch, yaw))


@kernel
def euler_to_dcm_s(roll: float, pitch: float, yaw: float) -> Mat9:
    """:func:`euler_to_dcm` as a row-major 9-tuple."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return (cp * cy, -cr * sy + sr * sp * cy, sr * sy + cr * sp * cy,
            cp * sy, cr * cy + sr * sp * sy, -sr * cy + cr * sp * sy,
            -sp, sr * cp, cr * cp)


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

    Inverse of :func:`euler_to_dcm` (docs/conventions.md Euler ranges). At pitch = +-90 deg
    roll and yaw are not separable; roll is then set to 0.
    """
    r, p, y = dcm_to_euler_s(c[0, 0], c[0, 1], c[1, 0], c[1, 1], c[2, 0], c[2, 1], c[2, 2])
    out = np.empty(3)
    out[0] = r
    out[1] = p
    out[2] = y
    return out


@kernel
def dcm_to_euler_s(c00: float, c01: float, c10: float, c11: float, c20: float, c21: float,
                   c22: float) -> tuple[float, float, float]:
    """:func:`dcm_to_euler` from the DCM elements it needs."""
    s = -c20
    if s > 1.0:
        s = 1.0
    elif s < -1.0:
        s = -1.0
    pitch = np.arcsin(s)
    if abs(s) > 1.0 - 1e-15:
        return 0.0, pitch, _atan2_half_open(-c01, c11)
    return _atan2_half_open(c21, c22), pitch, _atan2_half_open(c10, c00)


@kernel
def _atan2_half_open(y: float, x: float) -> float:
    """``atan2`` mapped to (-pi, pi] (it returns -pi for y = -0.0, x < 0)."""
    a = np.arctan2(y, x)
    return np.pi if a <= -np.pi else a


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

    Bortz 1971; the exact form of the truncated series in docs/conventions.md ``--order``.
    """
    return _vec4(rotvec_to_quat_s(phi[0], phi[1], phi[2]))


@kernel
def rotvec_to_quat_s(x: float, y: float, z: float) -> Quat:
    """:func:`rotvec_to_quat` on scalars."""
    c, k = half_angle_coeffs(x * x + y * y + z * z)
    return c, k * x, k * y, k * z


@kernel
def half_angle_coeffs(s2: float) -> tuple[float, float]:
    """``(cos(s/2), sin(s/2)/s)`` for ``s2 = s^2`` (Bortz 1971); Taylor series below SMALL_ANGLE."""
    if s2 < SMALL_ANGLE * SMALL_ANGLE:
        c = 1.0 - s2 / 8.0 + s2 * s2 / 384.0 - s2 * s2 * s2 / 46080.0
        k = 0.5 - s2 / 48.0 + s2 * s2 / 3840.0 - s2 * s2 * s2 / 645120.0
    else:
        s = np.sqrt(s2)
        c = np.cos(0.5 * s)
        k = np.sin(0.5 * s) / s
    return c, k


@kernel
def quat_from_coeffs(phi: np.ndarray, c: float, k: float) -> np.ndarray:
    """``[c, k phi]``: the quaternion form shared by the exact and truncated updates."""
    return _vec4((c, k * phi[0], k * phi[1], k * phi[2]))


@kernel
def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vector (rad, angle in [0, pi]) of a unit quaternion."""
    qc = quat_canonical(q)
    v = np.sqrt(qc[1] * qc[1] + qc[2] * qc[2] + qc[3] * qc[3])
    angle = 2.0 * np.arctan2(v, qc[0])
    if v < SMALL_ANGLE_LOG:
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
    return _mat3(rotvec_to_dcm_s(phi[0], phi[1], phi[2]))


@kernel
def rotvec_to_dcm_s(x: float, y: float, z: float) -> Mat9:
    """:func:`rotvec_to_dcm` on scalars; row-major 9-tuple.

    From the quaternion's half-angle coefficients ``c = cos(s/2)``, ``k = sin(s/2)/s``
    (:func:`rotvec_to_quat_s`, series below SMALL_ANGLE included): ``C = I + 2 c [q x] + 2 [q x]^2``
    with ``q = k phi`` (Savage 1998, "Strapdown inertial navigation integration algorithm
    design part 1", eq. 23), i.e. ``sin s/s = 2 c k`` and ``(1 - cos s)/s^2 = 2 k^2``.
    """
    c, k = half_angle_coeffs(x * x + y * y + z * z)
    return dcm_from_coeffs_s(x, y, z, 2.0 * c * k, 2.0 * k * k)


@kernel
def dcm_from_coeffs(phi: np.ndarray, a1: float, a2: float) -> np.ndarray:
    """``I + a1 [phi x] + a2 [phi x]^2`` (using ``[phi x]^2 = phi phi^T - |phi|^2 I``).

    The DCM form shared by the exact and truncated updates ([TW11] 11.2.1).
    """
    return _mat3(dcm_from_coeffs_s(phi[0], phi[1], phi[2], a1, a2))


@kernel
def dcm_from_coeffs_s(x: float, y: float, z: float, a1: float, a2: float) -> Mat9:
    """:func:`dcm_from_coeffs` on scalars; row-major 9-tuple."""
    s2 = x * x + y * y + z * z
    return (1.0 + a2 * (x * x - s2), -a1 * z + a2 * x * y, a1 * y + a2 * x * z,
            a1 * z + a2 * x * y, 1.0 + a2 * (y * y - s2), -a1 * x + a2 * y * z,
            -a1 * y + a2 * x * z, a1 * x + a2 * y * z, 1.0 + a2 * (z * z - s2))


@kernel
def mat3_mul_s(a: Mat9, b: Mat9) -> Mat9:
    """Product of two 3x3 matrices held as row-major 9-tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = b
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8)


@kernel
def mat3t_vec_s(a: Mat9, x: float, y: float, z: float) -> tuple[float, float, float]:
    """``A^T v`` for a 3x3 matrix held as a row-major 9-tuple."""
    return (a[0] * x + a[3] * y + a[6] * z, a[1] * x + a[4] * y + a[7] * z, a[2] * x + a[5] * y + a[8] * z)


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
    return _mat3(orthonormalize_s((c[0, 0], c[0, 1], c[0, 2], c[1, 0], c[1, 1], c[1, 2], c[2, 0], c[2, 1], c[2, 2])))


@kernel
def orthonormalize_s(c: Mat9) -> Mat9:
    """:func:`orthonormalize` of a row-major 9-tuple: ``C - 1/2 (C C^T - I) C``."""
    c0, c1, c2, c3, c4, c5, c6, c7, c8 = c
    ct = (c0, c3, c6, c1, c4, c7, c2, c5, c8)
    e0, e1, e2, e3, e4, e5, e6, e7, e8 = mat3_mul_s(c, ct)
    d0, d1, d2, d3, d4, d5, d6, d7, d8 = mat3_mul_s((e0 - 1.0, e1, e2, e3, e4 - 1.0, e5, e6, e7, e8 - 1.0), c)
    return (c0 - 0.5 * d0, c1 - 0.5 * d1, c2 - 0.5 * d2, c3 - 0.5 * d3, c4 - 0.5 * d4, c5 - 0.5 * d5,
            c6 - 0.5 * d6, c7 - 0.5 * d7, c8 - 0.5 * d8)


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


@kernel
def quat_angle_rows(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """:func:`quat_angle_between` of each row pair of two (n, 4) arrays (rad): the attitude error."""
    out = np.empty(p.shape[0])
    for i in range(p.shape[0]):
        out[i] = quat_angle_between(p[i], q[i])
    return out


@kernel
def quat_error_rows(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """Attitude error (rad) of each row pair of two (n, 4) arrays: the rotation vector of ``q_est (x) q_true^-1``.

    Estimate minus truth in the reference frame, ``C(est) = exp([phi x]) C(true)``;
    its norm is :func:`quat_angle_rows`.
    """
    out = np.empty((q_est.shape[0], 3))
    for i in range(q_est.shape[0]):
        out[i] = quat_to_rotvec(quat_mul(q_est[i], quat_conj(q_true[i])))
    return out
