"""Motions over and near the poles with exact IMU increments, in an Earth-fixed Cartesian form.

sim.kinematics integrates latitude and longitude (``lon' = v_E/((R_E + h) cos L)``) and
takes the transport rate with ``tan L``: both are singular at a pole. Here the vehicle's
ellipsoid normal turns about a fixed ECEF axis, ``n(t) = exp(t [w x]) n0``: a great circle
(w normal to n0; it crosses a pole when it starts on a meridian) or a circle of latitude
(w along the Earth's axis). With ``sin L = n_z`` the geodetic/ECEF relation
(docs/algorithms.md, earth.py) reads ``r = (R_E + h) n - e^2 R_E n_z z_e`` with
``R_E = a/sqrt(1 - e^2 n_z^2)``, so position, velocity and acceleration are closed forms
of t with no singularity anywhere. A track frame ``T(t) = exp(t [w x]) T0`` (T0 = NED at
the start turned by the course; for a great circle its x axis stays along the track)
carries the vehicle, which rolls and pitches sinusoidally relative to it. The IMU sees
([ZS1] eq. 1-3-14 and 1-3-27 in e-frame form)::

    w_ib^b = C_e^b (w + Omega z_e) + w_Tb^b
    f^b    = C_e^b (r'' + 2 Omega z_e x r' + gamma(L, h) n)

with the contract's normal gravity gamma along the normal. Increments are 5-point
Gauss-Legendre quadratures of these smooth rates (error far below double precision at the
sub-step used), truth is evaluated at every sample time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mavins.core import earth
from mavins.core.jit import kernel
from mavins.core.rotation import dcm_to_euler, dcm_to_quat, euler_to_dcm, mat_mul, mat_vec

from .kinematics import GL_NODES, GL_WEIGHTS

KINDS = ("great_circle", "parallel")
MAX_SUBSTEP = 0.05  # s: longest quadrature sub-interval (rocking periods are seconds)


@dataclass
class EarthFixedMotion:
    """A great circle or circle of latitude at constant height with sinusoidal roll and pitch.

    Angles in degrees, speed in m/s (nominal: the angular rate of the normal is
    ``speed/(sqrt(R_N R_E) + h)`` at the start for a great circle, ``speed/((R_E + h) cos L)``
    on a circle of latitude), periods in s. ``t`` is the end time; :meth:`static` extends it.
    """

    kind: str
    lat: float
    lon: float
    h: float
    course: float
    speed: float
    roll: float = 0.0
    roll_period: float = 10.0
    pitch: float = 0.0
    pitch_period: float = 10.0
    t0: float = 0.0
    t: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if not -90.0 <= self.lat <= 90.0:
            raise ValueError(f"lat must be in [-90, 90], got {self.lat}")
        if self.kind == "parallel" and abs(self.lat) == 90.0:
            raise ValueError("a circle of latitude needs |lat| < 90")
        for name in ("roll_period", "pitch_period"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        self.t = max(self.t, self.t0)

    def static(self, duration: float) -> EarthFixedMotion:
        """Continue the same motion for ``duration`` s more (the name the scenario runner calls)."""
        self.t += duration
        return self

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """The turn axis w (rad/s, ECEF) and the track frame's start ``C_T0^e``."""
        lat, lon = math.radians(self.lat), math.radians(self.lon)
        c = earth.cne_from_latlon(lat, lon) @ euler_to_dcm(0.0, 0.0, math.radians(self.course))
        r_n, r_e = earth.radii(lat)
        if self.kind == "great_circle":
            n0, x0 = -c[:, 2], c[:, 0]
            w = self.speed / (math.sqrt(r_n * r_e) + self.h) * np.cross(n0, x0)
        else:
            w = np.array([0.0, 0.0, self.speed / ((r_e + self.h) * math.cos(lat))])
            w *= math.copysign(1.0, math.sin(math.radians(self.course)))
        return w, c


def _rotate(w: np.ndarray, t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``exp(t [w x]) v`` for every t (Rodrigues), rows."""
    wn = float(np.linalg.norm(w))
    if wn == 0.0:
        return np.broadcast_to(v, (t.shape[0], 3)).copy()
    u = w / wn
    th = wn * t[:, None]
    return v * np.cos(th) + np.sin(th) * np.cross(u, v) + (1.0 - np.cos(th)) * float(u @ v) * u


@kernel
def _gravity_rows(sl: np.ndarray, r_e: np.ndarray, h: float) -> np.ndarray:
    """The contract's normal gravity (m/s^2) at each sine of latitude (earth.gravity_sin)."""
    out = np.empty(sl.shape[0])
    for i in range(sl.shape[0]):
        out[i] = earth.gravity_sin(sl[i], r_e[i], h)
    return out


@kernel
def _tilt_rows(roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """``C_b^T = euler_to_dcm(roll, pitch, 0)`` at each row (n, 3, 3)."""
    out = np.empty((roll.shape[0], 3, 3))
    for i in range(roll.shape[0]):
        out[i] = euler_to_dcm(roll[i], pitch[i], 0.0)
    return out


@kernel
def _ned_rows(lat: np.ndarray, lon: np.ndarray, v_e: np.ndarray, c_be: np.ndarray, out: np.ndarray) -> None:
    """NED velocity, Euler angles (rad) and quaternion of C_b^n at each row into out[:, 0:10], through
    ``C_e^n = C_n^e(lat, lon)^T`` (earth.cne_from_latlon)."""
    for i in range(lat.shape[0]):
        c_en = earth.cne_from_latlon(lat[i], lon[i]).T
        out[i, 0:3] = mat_vec(c_en, v_e[i])
        c_bn = mat_mul(c_en, c_be[i])
        out[i, 3:6] = dcm_to_euler(c_bn)
        out[i, 6:10] = dcm_to_quat(c_bn)


def _state(m: EarthFixedMotion, t: np.ndarray) -> dict[str, np.ndarray]:
    """Normal, position and its derivatives (ECEF), C_b^e and the IMU rates at times t (s)."""
    w, c0 = m.axes()
    tau = t - m.t0
    cols = [_rotate(w, tau, c0[:, k]) for k in range(3)]
    c_te = np.stack(cols, axis=2)  # C_T^e(t), (n, 3, 3)
    n = -cols[2]
    n1 = np.cross(w, n)
    n2 = np.cross(w, n1)
    q, q1, q2 = n[:, 2], n1[:, 2], n2[:, 2]
    a, e2, h = earth.A, earth.E2, m.h
    d = 1.0 - e2 * q * q
    f = a / np.sqrt(d)
    fq = a * e2 * q / d**1.5
    fqq = a * e2 / d**1.5 + 3.0 * a * e2 * e2 * q * q / d**2.5
    f1 = fq * q1
    f2 = fqq * q1 * q1 + fq * q2
    z = np.array([0.0, 0.0, 1.0])
    r = (f + h)[:, None] * n - (e2 * f * q)[:, None] * z
    r1 = f1[:, None] * n + (f + h)[:, None] * n1 - (e2 * (f1 * q + f * q1))[:, None] * z
    r2 = (f2[:, None] * n + 2.0 * f1[:, None] * n1 + (f + h)[:, None] * n2
          - (e2 * (f2 * q + 2.0 * f1 * q1 + f * q2))[:, None] * z)
    wr, wp = 2.0 * math.pi / m.roll_period, 2.0 * math.pi / m.pitch_period
    ar, ap = math.radians(m.roll), math.radians(m.pitch)
    roll, droll = ar * np.sin(wr * tau), ar * wr * np.cos(wr * tau)
    pitch, dpitch = ap * np.sin(wp * tau), ap * wp * np.cos(wp * tau)
    c_bt = _tilt_rows(np.ascontiguousarray(roll), np.ascontiguousarray(pitch))
    c_be = np.einsum("nij,njk->nik", c_te, c_bt)
    w_tb = np.stack([droll, dpitch * np.cos(roll), -dpitch * np.sin(roll)], axis=1)  # ZYX rates, yaw fixed
    om = np.array([0.0, 0.0, earth.OMEGA])
    w_ib = np.einsum("nji,j->ni", c_be, w + om) + w_tb
    gamma = _gravity_rows(np.ascontiguousarray(q), np.ascontiguousarray(f), h)
    f_e = r2 + 2.0 * np.cross(om, r1) + gamma[:, None] * n
    f_b = np.einsum("nji,nj->ni", c_be, f_e)
    return {"n": n, "r": r, "v_e": r1, "c_be": c_be, "w_ib": w_ib, "f_b": f_b}


def truth_rows(m: EarthFixedMotion, t: np.ndarray) -> np.ndarray:
    """Truth in the simulator's columns (SimResult.TRUTH_COLUMNS, degrees) at times t.

    Latitude and longitude from the normal (``atan2(n_z, hypot(n_x, n_y))``, ``atan2(n_y,
    n_x)``; longitude 0 exactly at a pole), NED velocity and attitude through the C_n^e of
    those very angles, so they are consistent with each other everywhere.
    """
    st = _state(m, t)
    n = st["n"]
    lat = np.arctan2(n[:, 2], np.hypot(n[:, 0], n[:, 1]))
    lon = np.arctan2(n[:, 1], n[:, 0])
    out = np.zeros((t.shape[0], 19))
    out[:, 0] = t
    out[:, 1], out[:, 2], out[:, 3] = np.degrees(lat), np.degrees(lon), m.h
    rows = np.empty((t.shape[0], 10))
    _ned_rows(lat, lon, np.ascontiguousarray(st["v_e"]), np.ascontiguousarray(st["c_be"]), rows)
    out[:, 4:7] = rows[:, 0:3]
    out[:, 7:10] = np.degrees(rows[:, 3:6])
    out[:, 10:14] = rows[:, 6:10]
    out[:, 14:17] = out[:, 7:10]
    return out


def increments(m: EarthFixedMotion, t_prev: float, t: np.ndarray, substeps: int) -> tuple[np.ndarray, np.ndarray]:
    """Exact ``dtheta`` (rad) and ``dv`` (m/s) over (t[i-1], t[i]] (t[-1] = t_prev)."""
    edges = np.concatenate(([t_prev], t))
    h = np.diff(edges) / substeps
    nodes = (edges[:-1, None, None] + h[:, None, None] * (np.arange(substeps)[None, :, None] + GL_NODES[None, None, :]))
    st = _state(m, nodes.ravel())
    wts = (h[:, None, None] * np.broadcast_to(GL_WEIGHTS, nodes.shape)).ravel()[:, None]
    shape = (t.shape[0], substeps * GL_NODES.shape[0], 3)
    return (st["w_ib"] * wts).reshape(shape).sum(axis=1), (st["f_b"] * wts).reshape(shape).sum(axis=1)


def simulate(m: EarthFixedMotion, rate: float, duration: float | None = None, usec_grid: bool = False):
    """Sample the motion at ``rate`` Hz: a sim.trajectory.SimResult (its ``spec`` is None)."""
    from .trajectory import join

    return join(list(simulate_chunks(m, rate, duration, usec_grid)))


def simulate_chunks(m: EarthFixedMotion, rate: float, duration: float | None = None, usec_grid: bool = False):
    """:func:`simulate` in the pieces of sim.trajectory.chunk_bounds (each a SimResult whose ``t0`` and
    truth row 0 are the previous piece's last); ``n`` is the run's number of samples."""
    from .trajectory import sample_times

    dur = (m.t - m.t0) if duration is None else duration
    n = math.floor(dur * rate + 1e-9)
    return _Chunks(m, sample_times(m.t0, n, rate, usec_grid), max(1, math.ceil(1.0 / (rate * MAX_SUBSTEP))))


@dataclass
class _Chunks:
    """The pieces of an Earth-fixed run, made when iterated."""

    m: EarthFixedMotion
    t: np.ndarray
    substeps: int

    @property
    def n(self) -> int:
        return int(self.t.shape[0])

    def __iter__(self):  # type: ignore[no-untyped-def]
        from .trajectory import SimResult, chunk_bounds

        t_prev = self.m.t0
        for a, b in chunk_bounds(self.n):
            t = self.t[a:b]
            dtheta, dv = increments(self.m, t_prev, t, self.substeps) if b > a else (np.empty((0, 3)), np.empty((0, 3)))
            yield SimResult(t_prev, t.copy(), dtheta, dv, truth_rows(self.m, np.concatenate(([t_prev], t))),
                            None)  # type: ignore[arg-type]
            t_prev = float(t[-1]) if len(t) else t_prev
