"""Linear covariance analysis of the free-inertial solution (error budgets, textbook ch. 6).

The error of a strapdown solution started from the truth obeys, to first
order, ``dx/dt = F(t) x + G w`` along the true trajectory (core/errmodel.py:
Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
Systems*, 2nd ed., 2013, section 14.2.4). The covariance of x is propagated
over steps of T seconds as

    P(k+1) = Phi P(k) Phi^T + Qd,   Phi = I + F T + (F T)^2 / 2,
    Qd = (Phi Qc Phi^T + Qc) T / 2

(Groves 2nd ed., section 3.2.3; errmodel.discretise_density), starting from
zero navigation error (every run starts from the true initial state) and the
sensors' random constants at their 1-sigma.

The analysis augments the filter's NX = 48 states (errmodel.py) with the
scale factor and misalignment of each triad as random constants (18 states,
for the analysis only: it takes the mean of ``C[r, i] u_j`` over each step,
where the filter's own scale-factor and misalignment states, which stay at
zero here, take the mean C times the mean u):

    x[48:57]  K_g  gyro error matrix, row-major: K[i, j] at 48 + 3 i + j
    x[57:66]  K_a  accelerometer error matrix, likewise

``measured = (I + K) true + bias``: the diagonal of K is the scale-factor
error, the off-diagonal terms the misalignment / non-orthogonality (sim/errors.py
``(I + S)(I + M)`` to first order). K enters exactly as a bias ``b = K u``
does (u = w_ib^b or f^b), so its columns in F are those of the bias times the
measured quantity (the sensor error model ``dw = B + S w + M w`` of Titterton
& Weston, *Strapdown Inertial Navigation Technology*, 2nd ed., 2004, ch. 12,
generalised system performance analysis; section number not checked):

    d(phi)/dt  += -C_b^n[:, i] w_j   for K_g[i, j]
    d(dv)/dt   += -C_b^n[:, i] f_j   for K_a[i, j]

Over a step the products ``C(t)[:, i] u_j(t)`` are averaged over the IMU
samples (C at each sample's mid-time), so vibration and manoeuvres enter with
their mean, which is what a first-order model needs.

Error budget. The sources (turn-on bias, bias instability, rate random walk,
angle/velocity random walk, scale factor, misalignment of each triad) are
independent and the model linear, so the covariance is the sum of the
covariances each source causes alone. Each is propagated on its own states
only (the navigation states plus the source's): F has no coupling from one
source's states to another's, so the sub-system is exact, and the total is
their sum.

Vertical hold (``--vertical hold`` of the contract): height and vertical
velocity are kept at their true values, so their errors and every coupling
through them are zero (rows and columns of dv_D and dp_D removed).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from . import errmodel as em
from . import grades
from .jit import kernel

NNAV = 9  # phi, dv, dp
X_KG = em.NX
X_KA = em.NX + 9
NA = em.NX + 18

ARCSEC = math.pi / 180.0 / 3600.0
PPM = 1e-6

ANALYSIS_KEYS = ("gyro_misalignment", "accel_misalignment")
"""Spec keys of the error analysis beyond errmodel.SPEC_KEYS (which has the scale factors): arcsec, 1-sigma
(docs/conventions.md)."""

SOURCES = (
    "gyro_bias", "gyro_instability", "gyro_rate_random_walk", "gyro_random_walk", "gyro_scale", "gyro_misalignment",
    "accel_bias", "accel_instability", "accel_rate_random_walk", "accel_random_walk", "accel_scale",
    "accel_misalignment",
)
"""The error sources of the budget, in its row order."""

SIGMA_COLUMNS = ("sigma_n", "sigma_e", "sigma_d", "sigma_vn", "sigma_ve", "sigma_vd",
                 "sigma_att_n", "sigma_att_e", "sigma_att_d")
BUDGET_COLUMNS = ("pos_h", "pos_v", "vel_h", "att_level", "att_yaw")

_OFF_DIAGONAL = (1, 2, 3, 5, 6, 7)
_DIAGONAL = (0, 4, 8)


@dataclass(frozen=True)
class AnalysisSpec:
    """The sensor model of the analysis: the filter's ImuSpec plus scale factor and misalignment.

    ``*_scale`` is the 1-sigma scale-factor error (dimensionless, 1e-6 = 1 ppm)
    of each axis; ``*_misalignment`` the 1-sigma (rad) of each of the six
    off-diagonal elements of the triad's misalignment matrix.
    """

    imu: em.ImuSpec
    gyro_scale: float = 0.0
    accel_scale: float = 0.0
    gyro_misalignment: float = 0.0
    accel_misalignment: float = 0.0

    def __post_init__(self) -> None:
        for name in ("gyro_scale", "accel_scale", "gyro_misalignment", "accel_misalignment"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
            object.__setattr__(self, name, value)


def spec_from_keys(keys: Mapping[str, float]) -> AnalysisSpec:
    """AnalysisSpec from the contract's keys: errmodel.SPEC_KEYS plus ANALYSIS_KEYS (ppm, arcsec); absent = 0."""
    imu = em.spec_from_keys(keys)
    return AnalysisSpec(
        imu,
        gyro_scale=imu.gyro_scale,
        accel_scale=imu.accel_scale,
        gyro_misalignment=float(keys.get("gyro_misalignment", 0.0)) * ARCSEC,
        accel_misalignment=float(keys.get("accel_misalignment", 0.0)) * ARCSEC,
    )


def spec_from_grade(name: str) -> AnalysisSpec:
    """AnalysisSpec of a grade (core/grades.py); its scale-factor and misalignment magnitudes are taken as 1-sigma."""
    f = grades.grade_figures(name)
    imu = em.spec_from_grade(name, scale_factors=True)
    return AnalysisSpec(
        imu,
        gyro_scale=imu.gyro_scale,
        accel_scale=imu.accel_scale,
        gyro_misalignment=f.gyro.misalignment,
        accel_misalignment=f.accel.misalignment,
    )


@dataclass(frozen=True)
class Source:
    """One independent error source: its states beyond the navigation nine, their initial
    variances, and the white-noise densities on the navigation states and its own."""

    name: str
    states: tuple[int, ...]
    p0: tuple[float, ...]
    q: tuple[float, ...]

    @property
    def index(self) -> np.ndarray:
        return np.array(tuple(range(NNAV)) + self.states, dtype=np.int64)

    @property
    def active(self) -> bool:
        return any(v > 0.0 for v in self.p0 + self.q)


def sources(spec: AnalysisSpec) -> list[Source]:
    """The sources of SOURCES for a spec (a source whose figures are zero is inactive)."""
    s = spec.imu
    out: list[Source] = []
    for tri, bias, gm, tau, rrw, white, scale, mis, x_b, x_gm, x_k, nav in (
        ("gyro", s.gyro_bias, s.gyro_gm, s.gyro_tau, s.gyro_rrw, s.gyro_arw, spec.gyro_scale, spec.gyro_misalignment,
         em.X_BG, em.X_GG, X_KG, em.X_PHI),
        ("accel", s.accel_bias, s.accel_gm, s.accel_tau, s.accel_rrw, s.accel_vrw, spec.accel_scale,
         spec.accel_misalignment, em.X_BA, em.X_GA, X_KA, em.X_DV),
    ):
        three = tuple(range(x_b, x_b + 3))
        gm_states = tuple(range(x_gm, x_gm + 3))
        nav0 = (0.0,) * NNAV
        white_q = tuple(white**2 if nav <= i < nav + 3 else 0.0 for i in range(NNAV))
        out += [
            Source(f"{tri}_bias", three, (bias**2,) * 3, nav0 + (0.0,) * 3),
            # Gauss-Markov: stationary from the start, driven by 2 sigma^2 / tau (errmodel.noise_density).
            Source(f"{tri}_instability", gm_states, (gm**2,) * 3, nav0 + (2.0 * gm**2 / tau,) * 3),
            Source(f"{tri}_rate_random_walk", three, (0.0,) * 3, nav0 + (rrw**2,) * 3),
            Source(f"{tri}_random_walk", (), (), white_q),
            Source(f"{tri}_scale", tuple(x_k + i for i in _DIAGONAL), (scale**2,) * 3, nav0 + (0.0,) * 3),
            Source(f"{tri}_misalignment", tuple(x_k + i for i in _OFF_DIAGONAL), (mis**2,) * 6, nav0 + (0.0,) * 6),
        ]
    order = {name: i for i, name in enumerate(SOURCES)}
    return sorted(out, key=lambda src: order[src.name])


@dataclass(frozen=True)
class TrackMeans:
    """The true trajectory averaged over each propagation step (K steps).

    ``t`` (K+1,) step boundaries (s); ``c`` (K,3,3) mean C_b^n; ``v`` (K,3)
    NED velocity (m/s); ``lat`` (rad), ``h`` (m) (K,); ``f_n`` (K,3) mean
    specific force in n (m/s^2); ``cw``, ``cf`` (K,3,3,3): mean of
    ``C[r, i] w_j`` (rad/s) and ``C[r, i] f_j`` (m/s^2), indexed [k, r, i, j].
    """

    t: np.ndarray
    c: np.ndarray
    v: np.ndarray
    lat: np.ndarray
    h: np.ndarray
    f_n: np.ndarray
    cw: np.ndarray
    cf: np.ndarray


def _quat_to_dcm_rows(q: np.ndarray) -> np.ndarray:
    """C_b^n (n,3,3) of unit quaternions [w, x, y, z] (Hamilton, docs/conventions.md; Groves eq. 2.34)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z], axis=-1),
    ], axis=1)


def track_means(t0: float, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, truth: np.ndarray,
                step: int) -> TrackMeans:
    """Step means of a true trajectory: exact increments (rad, m/s, rows (t[i-1], t[i]]) and truth rows.

    ``truth`` has the contract's solution columns (file units: degrees), row 0
    at t0 and row i at t[i-1]; ``step`` samples make one propagation step
    (trailing samples that do not fill a step are left out).
    """
    n = (len(t) // step) * step
    if n == 0:
        raise ValueError(f"fewer than {step} samples: nothing to propagate")
    k = n // step
    c = _quat_to_dcm_rows(truth[: n + 1, 10:14])
    cm = 0.5 * (c[:-1] + c[1:])  # C at each sample's mid-time (second order)
    tb = np.concatenate(([t0], t[:n]))
    dt = np.diff(tb[:: step]).reshape(k)
    cm = cm.reshape(k, step, 3, 3)
    dth = dtheta[:n].reshape(k, step, 3)
    dvv = dv[:n].reshape(k, step, 3)
    cw = np.einsum("kmri,kmj->krij", cm, dth) / dt[:, None, None, None]
    cf = np.einsum("kmri,kmj->krij", cm, dvv) / dt[:, None, None, None]
    mid = 0.5 * (truth[:n, :] + truth[1 : n + 1, :]).reshape(k, step, truth.shape[1])
    return TrackMeans(
        t=tb[:: step].copy(),
        c=cm.mean(axis=1),
        v=mid[:, :, 4:7].mean(axis=1),
        lat=np.radians(mid[:, :, 1].mean(axis=1)),
        h=mid[:, :, 3].mean(axis=1),
        f_n=np.einsum("krii->kr", cf),
        cw=cw,
        cf=cf,
    )


@kernel
def analysis_matrix(c: np.ndarray, v: np.ndarray, lat: float, h: float, f_n: np.ndarray, cw: np.ndarray,
                    cf: np.ndarray, spec: np.ndarray, earth_on: bool) -> np.ndarray:
    """F (NA x NA): errmodel.system_matrix plus the scale-factor / misalignment columns (module docstring)."""
    F = np.zeros((NA, NA))
    F[: em.NX, : em.NX] = em.system_matrix(c, v, lat, h, f_n, spec, earth_on)
    for r in range(3):
        for i in range(3):
            for j in range(3):
                F[em.X_PHI + r, X_KG + 3 * i + j] = -cw[r, i, j]
                F[em.X_DV + r, X_KA + 3 * i + j] = -cf[r, i, j]
    return F


@kernel
def _propagate(t: np.ndarray, c: np.ndarray, v: np.ndarray, lat: np.ndarray, h: np.ndarray, f_n: np.ndarray,
               cw: np.ndarray, cf: np.ndarray, spec: np.ndarray, earth_on: bool, vhold: bool, idx: np.ndarray,
               p0: np.ndarray, q: np.ndarray, every: int) -> np.ndarray:
    """Navigation covariance (n_out, 9, 9) at step 0, every, 2 every, ... of one source's sub-system."""
    m = idx.shape[0]
    k_steps = c.shape[0]
    n_out = k_steps // every + 1
    out = np.zeros((n_out, NNAV, NNAV))
    P = np.zeros((m, m))
    for a in range(m):
        P[a, a] = p0[a]
    qv = q.copy()
    if vhold:
        qv[em.X_DV + 2] = 0.0
        qv[em.X_DP + 2] = 0.0
    Fs = np.zeros((m, m))
    for k in range(k_steps):
        F = analysis_matrix(c[k], v[k], lat[k], h[k], f_n[k], cw[k], cf[k], spec, earth_on)
        for a in range(m):
            for b in range(m):
                Fs[a, b] = F[idx[a], idx[b]]
        if vhold:
            for z in (em.X_DV + 2, em.X_DP + 2):
                for a in range(m):
                    Fs[z, a] = 0.0
                    Fs[a, z] = 0.0
        phi, qd = em.discretise_density(Fs, qv, t[k + 1] - t[k])
        P = em.matmul_bt(em.matmul(phi, P), phi) + qd
        for a in range(m):
            for b in range(a + 1, m):
                s = 0.5 * (P[a, b] + P[b, a])
                P[a, b] = s
                P[b, a] = s
        if (k + 1) % every == 0:
            out[(k + 1) // every] = P[:NNAV, :NNAV]
    return out


def propagate(track: TrackMeans, spec: AnalysisSpec, *, every: int = 1, earth: bool = True,
              vertical: str = "free", only: Source | None = None) -> dict[str, np.ndarray]:
    """Navigation covariance caused by each source alone, at track.t[0::every].

    Returns ``{source name: (n_out, 9, 9)}`` in the error-state order (phi
    rad, dv m/s, dp m); ``only`` propagates that one source instead of
    SOURCES. The total covariance is the sum over the sources (module docstring).
    """
    if vertical not in ("free", "hold"):
        raise ValueError(f"vertical must be free or hold, got {vertical!r}")
    if every < 1:
        raise ValueError("every must be >= 1")
    sp = spec.imu.as_array()
    n_out = (len(track.t) - 1) // every + 1
    out: dict[str, np.ndarray] = {}
    for src in [only] if only is not None else sources(spec):
        if not src.active:
            out[src.name] = np.zeros((n_out, NNAV, NNAV))
            continue
        out[src.name] = _propagate(track.t, track.c, track.v, track.lat, track.h, track.f_n, track.cw, track.cf, sp,
                                   earth, vertical == "hold", src.index, np.array((0.0,) * NNAV + src.p0),
                                   np.array(src.q), every)
    return out


def sigma_rows(P: np.ndarray) -> np.ndarray:
    """(n, 9, 9) navigation covariances -> (n, 9) 1-sigma in SIGMA_COLUMNS order (m, m/s, deg)."""
    d = np.sqrt(np.maximum(np.diagonal(P, axis1=1, axis2=2), 0.0))
    return np.column_stack([d[:, em.X_DP : em.X_DP + 3], d[:, em.X_DV : em.X_DV + 3],
                            np.degrees(d[:, em.X_PHI : em.X_PHI + 3])])


def budget_row(P: np.ndarray) -> np.ndarray:
    """One 9x9 navigation covariance -> BUDGET_COLUMNS: horizontal position (m, root of the north
    and east variances), vertical position (m), horizontal velocity (m/s), level and yaw attitude (deg)."""
    d = np.maximum(np.diagonal(P), 0.0)
    return np.array([
        math.sqrt(d[em.X_DP] + d[em.X_DP + 1]),
        math.sqrt(d[em.X_DP + 2]),
        math.sqrt(d[em.X_DV] + d[em.X_DV + 1]),
        math.degrees(math.sqrt(d[em.X_PHI] + d[em.X_PHI + 1])),
        math.degrees(math.sqrt(d[em.X_PHI + 2])),
    ])
