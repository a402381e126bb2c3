"""Coning of a rotating IMU in closed form, after [LAI12] (Lai, Lü, Zhang, Liu 2012).

[LAI12] "Coning error analysis and compensation in rotation inertial
navigation system" (J. Nanjing Univ. Aeronautics & Astronautics 44(2)),
eqs. 1-18.

Motion model (the paper's, eq. 2): the body frame b cones about the z axis of
a non-rotating reference frame r with half-angle alpha and, on a turntable,
turns about z_r through the angle a(t):

    Q(t) = Q2(t) (x) Q1(t),
    Q2 = [cos(alpha/2), sin(alpha/2) cos psi, sin(alpha/2) sin psi, 0],  psi = wc t + a(t),
    Q1 = [cos(a/2), 0, 0, sin(a/2)]  (a = turntable angle)

which multiplies out to eq. (2) for ``a = wr t``:
``Q = [cos(alpha/2) cos(a/2), sin(alpha/2) cos(wc t + a/2),
sin(alpha/2) sin(wc t + a/2), cos(alpha/2) sin(a/2)]``.
The body rate ``w = 2 Q* (x) dQ/dt`` is eq. (4) with ``wr`` replaced by the
turntable rate ``a'(t)``:

    w = [-(wc + a') sin(alpha) sin(wc t),  (wc + a') sin(alpha) cos(wc t),
         a' cos(alpha) - 2 wc sin^2(alpha/2)]

so the x/y rates always oscillate at wc in the body (wc is the coning rate
*the gyros see*; seen from r the cone turns at wc + a'), their amplitude is
``(wc + a') sin(alpha)``, and while the turntable stops the motion is the
classic coning of sim.motion.classic_coning (eq. 1).

For a piecewise-constant turntable rate (constant rotation, or the paper's
stop-and-go scheme with instantaneous starts and stops) the increments
integrate in closed form, per constant-rate piece:

    dtheta_x = sin(alpha) [cos wc t] - sin(alpha) [G_x],  G_x' = a' sin(wc t)
    dtheta_y = sin(alpha) [sin wc t] + sin(alpha) [G_y],  G_y' = a' cos(wc t)
    dtheta_z = cos(alpha) [a] - 2 wc sin^2(alpha/2) [t]

with ``G_x = r/wc (cos wc b - cos wc t)`` and ``G_y = r/wc (sin wc t - sin wc b)``
on a piece of rate r starting at b. For constant rate this is the paper's
eq. (9): ``dtheta_x = (wc + wr)/wc sin(alpha) [cos wc t]`` etc.

The closed forms of the paper's error analysis (eq. 18 as printed and
corrected) and the exact error of one update are at the end of the module.
Angles in rad, rates in rad/s, times in s; quaternions Hamilton, scalar
first, ``Q`` maps body vectors to the reference frame (mavins' ``q_nb``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from .motion import Motion


# --- turntable schedule ---------------------------------------------------------


@dataclass(frozen=True)
class Schedule:
    """Piecewise-constant turntable rate.

    ``rates[k]`` (rad/s) holds on ``[starts[k], starts[k+1])`` (the last piece
    runs on forever); ``angles[k]`` is the turntable angle (rad) at
    ``starts[k]``. ``gx``/``gy`` are the running integrals
    ``int_t0^t a'(u) sin(wc u) du`` and ``... cos(wc u) du`` at the piece
    starts, which depend on wc and are filled by :meth:`prepared`.
    """

    starts: np.ndarray
    rates: np.ndarray
    angles: np.ndarray

    def angle(self, t: np.ndarray) -> np.ndarray:
        """Turntable angle a(t) (rad)."""
        t = np.asarray(t, dtype=np.float64)
        k = self.piece(t)
        return self.angles[k] + self.rates[k] * (t - self.starts[k])

    def rate(self, t: np.ndarray) -> np.ndarray:
        """Turntable rate a'(t) (rad/s), right-continuous at the switches."""
        return self.rates[self.piece(np.asarray(t, dtype=np.float64))]

    def piece(self, t: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, len(self.starts) - 1)

    def g_integrals(self, t: np.ndarray, wc: float) -> tuple[np.ndarray, np.ndarray]:
        """``G_x(t) = int a' sin(wc u) du`` and ``G_y(t) = int a' cos(wc u) du`` from starts[0]."""
        t = np.asarray(t, dtype=np.float64)
        b, r = self.starts, self.rates
        # integrals over each whole piece, accumulated to the piece starts
        gx0 = np.zeros(len(b))
        gy0 = np.zeros(len(b))
        if len(b) > 1:
            dx = r[:-1] / wc * (np.cos(wc * b[:-1]) - np.cos(wc * b[1:]))
            dy = r[:-1] / wc * (np.sin(wc * b[1:]) - np.sin(wc * b[:-1]))
            gx0[1:] = np.cumsum(dx)
            gy0[1:] = np.cumsum(dy)
        k = self.piece(t)
        gx = gx0[k] + r[k] / wc * (np.cos(wc * b[k]) - np.cos(wc * t))
        gy = gy0[k] + r[k] / wc * (np.sin(wc * t) - np.sin(wc * b[k]))
        return gx, gy


def constant_rate(wr: float, t0: float = 0.0, angle0: float = 0.0) -> Schedule:
    """Turntable turning at ``wr`` rad/s from ``t0`` (the paper's eq. 2: ``a = wr t``)."""
    return Schedule(np.array([t0]), np.array([float(wr)]), np.array([float(angle0)]))


def stop_and_go(
    positions_deg: list[float], rate_deg_s: float, dwell: float, until: float, alternate: bool = True, t0: float = 0.0,
) -> Schedule:
    """The stop-and-go scheme of [LAI12] 2.2 / 3.3 with instantaneous starts and stops.

    Dwell ``dwell`` s at each position, move to the next at ``rate_deg_s``;
    with ``alternate`` the order runs forward then back (0, 90, 180, 270, 180,
    90, 0, ...) like sim.trajectory.Trajectory.turntable_stop_and_go, so
    rotations of opposite directions follow each other. One full cycle then
    takes ``2 (n - 1)`` moves and dwells.
    """
    seq = list(positions_deg)
    order = seq + (seq[-2:0:-1] if alternate else [seq[0] + 360.0])
    starts, rates, angles = [t0], [0.0], [math.radians(order[0])]
    t, k, ang = t0, 0, math.radians(order[0])
    while True:
        t += dwell
        if t >= until:
            break
        cur, nxt = order[k % len(order)], order[(k + 1) % len(order)]
        if not alternate and k % len(order) == len(order) - 1:
            nxt = order[0] + 360.0
        delta = math.radians(nxt - cur)
        r = math.copysign(math.radians(rate_deg_s), delta)
        starts.append(t)
        rates.append(r)
        angles.append(ang)
        t += delta / r
        ang += delta
        starts.append(t)
        rates.append(0.0)
        angles.append(ang)
        k += 1
    return Schedule(np.array(starts), np.array(rates), np.array(angles))


# --- the paper's motion -----------------------------------------------------------


def _schedule(turntable: float | Schedule) -> Schedule:
    return turntable if isinstance(turntable, Schedule) else constant_rate(float(turntable))


def quaternion(t: np.ndarray, alpha: float, wc: float, turntable: float | Schedule = 0.0) -> np.ndarray:
    """True ``Q(t)`` of eq. (2) (rows [w, x, y, z]); ``turntable`` is wr (rad/s) or a Schedule."""
    t = np.asarray(t, dtype=np.float64)
    a = _schedule(turntable).angle(t)
    ca, sa = math.cos(0.5 * alpha), math.sin(0.5 * alpha)
    ph = wc * t + 0.5 * a
    return np.stack([ca * np.cos(0.5 * a), sa * np.cos(ph), sa * np.sin(ph), ca * np.sin(0.5 * a)], axis=-1)


def body_rate(t: np.ndarray, alpha: float, wc: float, turntable: float | Schedule = 0.0) -> np.ndarray:
    """Body rate ``w(t) = 2 Q* (x) dQ/dt`` of eq. (4) (rows x, y, z; rad/s)."""
    t = np.asarray(t, dtype=np.float64)
    r = _schedule(turntable).rate(t)
    amp = (wc + r) * math.sin(alpha)
    return np.stack([-amp * np.sin(wc * t), amp * np.cos(wc * t),
                     r * math.cos(alpha) - 2.0 * wc * math.sin(0.5 * alpha) ** 2 + 0.0 * t], axis=-1)


def increments(t_edges: np.ndarray, alpha: float, wc: float, turntable: float | Schedule = 0.0) -> np.ndarray:
    """Exact ``dtheta = int w dt`` over each ``(t_edges[i], t_edges[i+1]]`` (rows; rad).

    Differences of closed-form antiderivatives, so the increments telescope
    to the same phases the truth quaternion uses.
    """
    sched = _schedule(turntable)
    t = np.asarray(t_edges, dtype=np.float64)
    sa = math.sin(alpha)
    gx, gy = sched.g_integrals(t, wc)
    fx = sa * (np.cos(wc * t) - gx)
    fy = sa * (np.sin(wc * t) + gy)
    fz = math.cos(alpha) * sched.angle(t) - 2.0 * wc * math.sin(0.5 * alpha) ** 2 * t
    f = np.stack([fx, fy, fz], axis=-1)
    return np.diff(f, axis=0)


def paper_motion(alpha: float, wc: float, turntable: float | Schedule, dt: float, n: int, t0: float = 0.0) -> Motion:
    """Exact increments (sample interval dt, n samples) and truth of the paper's motion.

    Returned as a sim.motion.Motion: ``dv`` is zero (only attitude matters;
    in a navigation run gravity then makes the velocity fall freely).
    """
    edges = t0 + dt * np.arange(n + 1, dtype=np.float64)
    return Motion(t0, edges[1:], increments(edges, alpha, wc, turntable), np.zeros((n, 3)),
                  quaternion(edges[1:], alpha, wc, turntable))


# --- closed forms of the error analysis ------------------------------------------

#: N-sample coning coefficients k_{N-1}, ..., k_1 for dtheta_1 ... dtheta_{N-1}
#: (oldest first), re-typed as exact fractions (docs/conventions.md ``--samples``;
#: Lee, Yoon, Lee 1990; the paper's eq. 14 takes them from the non-rotating INS).
CONING_COEFFS: dict[int, tuple[Fraction, ...]] = {
    1: (),
    2: (Fraction(2, 3),),
    3: (Fraction(9, 20), Fraction(27, 20)),
    4: (Fraction(54, 105), Fraction(92, 105), Fraction(214, 105)),
    5: (Fraction(250, 504), Fraction(525, 504), Fraction(650, 504), Fraction(1375, 504)),
    6: (Fraction(2315, 4620), Fraction(4558, 4620), Fraction(7296, 4620), Fraction(7834, 4620), Fraction(15797, 4620)),
}


def eq18_terms(n: int, alpha: float, wc: float, wr: float, T: float, interval: str = "T") -> tuple[float, float, float]:
    """The three terms of the paper's residual eq. (18), rad per update T.

    ``-(wr T)^3/24 cos^2(alpha/2)``, ``-alpha^2 (wr T)(wc T)^2/24`` and
    ``N N!/(2^(N+1) prod_{k=1}^{N+1}(2k-1)) alpha^2 (wc X)^(2N+1)`` with
    X = T as printed (``interval="T"``) or the sample interval h = T/N
    (``interval="h"``), with which the term is the known N-sample residual.
    """
    x = T if interval == "T" else T / n
    prod = math.prod(2 * k - 1 for k in range(1, n + 2))
    c = n * math.factorial(n) / (2 ** (n + 1) * prod)
    return (-(wr * T) ** 3 / 24.0 * math.cos(0.5 * alpha) ** 2,
            -alpha**2 * (wr * T) * (wc * T) ** 2 / 24.0,
            c * alpha**2 * (wc * x) ** (2 * n + 1))


def coning_residual(n: int, s: float, wc: float, T: float) -> float:
    """Second-order residual per update (rad) of the N-sample algorithm, algorithm minus exact.

    For body rates ``[-s wc sin wc t, s wc cos wc t, const]`` the z part of
    the algorithm's term is ``4 s^2 sin^2(l/2) sum_i k_i sin((N-i) l)`` with
    ``l = wc h`` (the paper's eq. 15), and the exact second-order coning term
    ``1/2 int alpha x w dt`` is ``s^2/2 (wc T - sin wc T)``, whatever the
    constant z rate. N = 1 (no compensation) gives ``-s^2/2 (wc T - sin wc T)``.
    With the paper's motion ``s = (wc + wr)/wc sin(alpha)``.
    """
    lam = wc * T / n
    alg = sum(float(k) * math.sin((n - 1 - i) * lam) for i, k in enumerate(CONING_COEFFS[n]))
    alg *= 4.0 * s * s * math.sin(0.5 * lam) ** 2
    return alg - 0.5 * s * s * (wc * T - math.sin(wc * T))


#: Leading coefficient r_N of the part of the per-update heading error (estimate
#: minus truth) that is odd in wr: ``r_N alpha^2 (wr T)(wc T)^4`` for N >= 2 and
#: ``r_1 alpha^2 (wr T)(wc T)^2`` without compensation. Obtained by a series
#: expansion of :func:`update_error` in alpha, wr/wc and wc T (sympy, exact
#: rationals); the next order is about ``-(wc T)^2/20`` relative. The paper's
#: eq. (18) has ``-1/24 alpha^2 (wr T)(wc T)^2`` instead (docs/rins.md).
ROTATION_COEFFS: dict[int, Fraction] = {
    1: Fraction(-1, 12),
    2: Fraction(1, 320),
    3: Fraction(7, 1296),
    4: Fraction(209, 35840),
    5: Fraction(769, 126000),
    6: Fraction(5389, 855360),
}

#: Their next-order terms ``q_N alpha^2 (wr T)(wc T)^6`` (N >= 2; same expansion).
ROTATION_NEXT: dict[int, Fraction] = {
    2: Fraction(-5, 32256),
    3: Fraction(-619, 2449440),
    4: Fraction(-1037, 3440640),
    5: Fraction(-6409, 18900000),
    6: Fraction(-949093, 2586608640),
}


def rotation_residual(n: int, alpha: float, wc: float, wr: float, T: float) -> float:
    """Leading rotation (odd in wr) part of the per-update heading error, rad (estimate minus truth)."""
    k = 2 if n == 1 else 4
    return float(ROTATION_COEFFS[n]) * alpha**2 * (wr * T) * (wc * T) ** k


def _qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.array([
        p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
        p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
        p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
    ])


def _rotvec(q: np.ndarray) -> np.ndarray:
    if q[0] < 0:
        q = -q
    v = math.sqrt(q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
    if v == 0.0:
        return np.zeros(3)
    return 2.0 * math.atan2(v, q[0]) / v * q[1:4]


def _exp(phi: np.ndarray) -> np.ndarray:
    s = math.sqrt(float(phi @ phi))
    k = 0.5 if s == 0.0 else math.sin(0.5 * s) / s
    return np.array([math.cos(0.5 * s), k * phi[0], k * phi[1], k * phi[2]])


def update_error(n: int, alpha: float, wc: float, wr: float, T: float, coning: bool = True) -> np.ndarray:
    """Exact reference-frame attitude error added by one update, constant-rate turntable (rad).

    Because ``Q(t + tau) = Rz(Omega t) Q(tau) Rz(-wc t)`` with ``Omega = wc + wr``,
    every update repeats the first one turned by ``Omega t`` about z_r, so the
    error ``delta = Q_est (x) Q_true*`` grows by the same z rotation each
    update and its x/y parts rotate (and stay bounded). This returns the
    rotation vector of ``u = Q(0) (x) exp(sigma) (x) exp(Phi)* (x) Q(0)*`` for the
    first update: its z component divided by T is the yaw drift rate of a
    long run (exact, up to the second-order composition of the x/y parts).
    ``Phi`` is the exact rotation vector of eq. (6) (no small-angle step),
    ``sigma`` the N-sample algorithm on the exact increments (eq. 14 with the
    coefficients above; ``coning=False`` just sums them).
    """
    h = T / n
    edges = h * np.arange(n + 1, dtype=np.float64)
    dth = increments(edges, alpha, wc, wr)
    sigma = dth.sum(axis=0)
    if coning and n >= 2:
        acc = np.zeros(3)
        for i, k in enumerate(CONING_COEFFS[n]):
            acc += float(k) * dth[i]
        sigma = sigma + np.cross(acc, dth[-1])
    # eq. (6): q(t, t+T) = Q(t)* (x) Q(t+T) at t = 0
    ca2, sa2 = math.cos(0.5 * alpha) ** 2, math.sin(0.5 * alpha) ** 2
    x = 0.5 * (wr + wc) * T
    q = np.array([
        ca2 * math.cos(0.5 * wr * T) + sa2 * math.cos(0.5 * wr * T + wc * T),
        -math.sin(x) * math.sin(alpha) * math.sin(0.5 * wc * T),
        math.sin(x) * math.sin(alpha) * math.cos(0.5 * wc * T),
        ca2 * math.sin(0.5 * wr * T) - sa2 * math.sin(0.5 * wr * T + wc * T),
    ])
    e = _qmul(_exp(sigma), np.array([q[0], -q[1], -q[2], -q[3]]))
    q0 = quaternion(np.array([0.0]), alpha, wc, wr)[0]
    u = _qmul(_qmul(q0, e), np.array([q0[0], -q0[1], -q0[2], -q0[3]]))
    return _rotvec(u)
