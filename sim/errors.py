"""IMU sensor error models that corrupt ideal increments (pure numpy).

Data convention (project contract): body frame FRD; row ``i`` of an increment
log holds ``t[i]`` [s] and the increments over the interval ``(t[i-1], t[i]]``:
``dtheta`` [rad] (integral of the angular rate) and ``dv`` [m/s] (integral of
the specific force).  :func:`apply` takes ideal increments and returns
corrupted ones in the same convention.

Error model, per interval of length ``dt`` (all vectors in the FRD body frame)::

    dtheta_out = (I + S_g)(I + M_g) dtheta + G dv + bias_g * dt + N_g sqrt(dt) n
    dv_out     = (I + S_a)(I + M_a) dv               + bias_a * dt + N_a sqrt(dt) n

where ``S = diag(scale_factor_ppm) * 1e-6``, ``M`` is the misalignment /
non-orthogonality matrix (small angles, zero diagonal expected), ``G`` the
gyro g-sensitivity, ``N`` the angle / velocity random walk and ``n`` unit
white Gaussian noise.  The bias is ``bias = constant + turn_on + gm(t) +
rrw(t)``: the turn-on part is drawn once per run, ``gm`` is a first-order
Gauss-Markov process (bias instability) and ``rrw`` a random walk (rate random
walk).  Both time-varying states are propagated exactly at the interval
boundaries (``phi = exp(-dt/tau)``, ``q = sigma^2 (1 - phi^2)`` for the
Gauss-Markov state, ``q = K^2 dt`` for the random walk) and their integral over
the interval is taken with the trapezoidal rule on the boundary states.  After
that the increments pass a residual-carrying quantiser, the timestamps get
jitter and samples are dropped (see :func:`apply`).

Grade presets (:func:`grade`): the datasheet figures and how they become model
values are in ``mavins/core/grades.py`` (shared with the filter).

The ``ideal`` grade has every error set to zero: :func:`apply` then returns
the input unchanged, bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mavins.core import grades

__all__ = [
    "GM_ADEV_PEAK_RATIO",
    "GM_ADEV_PEAK_TAU_RATIO",
    "GRADES",
    "BLOCK",
    "ErrorStream",
    "ImuErrorModel",
    "SensorErrorModel",
    "allan_deviation",
    "apply",
    "apply_rows",
    "bias_states",
    "gauss_markov_adev",
    "grade",
]

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]

GM_ADEV_PEAK_RATIO = grades.GM_ADEV_PEAK_RATIO
GM_ADEV_PEAK_TAU_RATIO = grades.GM_ADEV_PEAK_TAU_RATIO

_MAX_EFOLDS = 20.0

_ZERO3: Vec3 = (0.0, 0.0, 0.0)
_ZERO33: Mat3 = (_ZERO3, _ZERO3, _ZERO3)


def _vec3(value: ArrayLike, name: str) -> Vec3:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _mat3(value: ArrayLike, name: str) -> Mat3:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3, 3) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite 3x3 matrix, got {value!r}")
    return (_vec3(arr[0], name), _vec3(arr[1], name), _vec3(arr[2], name))


def _nonneg(value: float, name: str) -> float:
    out = float(value)
    if not (math.isfinite(out) and out >= 0.0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return out


@dataclass(frozen=True)
class SensorErrorModel:
    """Error parameters of one triad (gyro or accelerometer), FRD body axes.

    Units below use ``u`` for the sensed quantity: rad/s for the gyro, m/s^2
    for the accelerometer; increments are then in rad or m/s.  Array-like
    inputs are stored as tuples so instances are immutable and hashable.

    Attributes:
        bias: constant bias per axis [u].
        turn_on_bias_sigma: sigma of the per-run bias, drawn once per run [u].
        bias_instability_sigma: stationary sigma of the Gauss-Markov bias [u].
        bias_instability_tau: its correlation time [s].
        random_walk: angle / velocity random walk [u*sqrt(s)], i.e. rad/sqrt(s)
            or m/s/sqrt(s); ADEV(tau) = random_walk / sqrt(tau).
        rate_random_walk: bias random walk [u/sqrt(s)];
            ADEV(tau) = rate_random_walk * sqrt(tau/3).
        scale_factor_ppm: scale-factor error per axis [ppm].
        misalignment: small-angle misalignment / non-orthogonality matrix
            [rad]; the sensed vector is (I + misalignment) times the true one,
            so the diagonal should be zero (scale lives in scale_factor_ppm).
        quantization: increment quantisation step [rad or m/s]; 0 = off.
    """

    bias: Vec3 = _ZERO3
    turn_on_bias_sigma: float = 0.0
    bias_instability_sigma: float = 0.0
    bias_instability_tau: float = 1.0
    random_walk: float = 0.0
    rate_random_walk: float = 0.0
    scale_factor_ppm: Vec3 = _ZERO3
    misalignment: Mat3 = _ZERO33
    quantization: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "bias", _vec3(self.bias, "bias"))
        object.__setattr__(self, "scale_factor_ppm", _vec3(self.scale_factor_ppm, "scale_factor_ppm"))
        object.__setattr__(self, "misalignment", _mat3(self.misalignment, "misalignment"))
        for name in (
            "turn_on_bias_sigma",
            "bias_instability_sigma",
            "random_walk",
            "rate_random_walk",
            "quantization",
        ):
            object.__setattr__(self, name, _nonneg(getattr(self, name), name))
        tau = float(self.bias_instability_tau)
        if not (math.isfinite(tau) and tau > 0.0):
            raise ValueError(f"bias_instability_tau must be finite and > 0, got {self.bias_instability_tau!r}")
        object.__setattr__(self, "bias_instability_tau", tau)


@dataclass(frozen=True)
class ImuErrorModel:
    """Complete IMU error model: both triads plus timing defects.

    Attributes:
        gyro: gyro triad errors (u = rad/s).
        accel: accelerometer triad errors (u = m/s^2).
        g_sensitivity: gyro rate error per unit specific force
            [rad/s per m/s^2]; adds ``g_sensitivity @ dv`` to ``dtheta``.
        jitter_sigma: sigma of the Gaussian error added to each reported
            timestamp [s].
        drop_probability: probability that a row is lost, independently per
            row, in [0, 1).
    """

    gyro: SensorErrorModel = field(default_factory=SensorErrorModel)
    accel: SensorErrorModel = field(default_factory=SensorErrorModel)
    g_sensitivity: Mat3 = _ZERO33
    jitter_sigma: float = 0.0
    drop_probability: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "g_sensitivity", _mat3(self.g_sensitivity, "g_sensitivity"))
        object.__setattr__(self, "jitter_sigma", _nonneg(self.jitter_sigma, "jitter_sigma"))
        p = _nonneg(self.drop_probability, "drop_probability")
        if p >= 1.0:
            raise ValueError(f"drop_probability must be < 1, got {p!r}")
        object.__setattr__(self, "drop_probability", p)


def gauss_markov_adev(sigma: float, tau_c: float, tau: ArrayLike) -> NDArray[np.float64]:
    """Allan deviation of a first-order Gauss-Markov process.

    ``AVAR = (2 sigma^2 / x) [1 - (3 - 4 e^-x + e^-2x) / (2x)]`` with
    ``x = tau / tau_c`` (IEEE Std 952, exponentially correlated noise with
    ``q_c = 2 sigma^2 / tau_c``).

    Args:
        sigma: stationary sigma of the process [u].
        tau_c: correlation time [s].
        tau: averaging times [s].

    Returns:
        Allan deviation at each ``tau`` [u].
    """
    x = np.asarray(tau, dtype=np.float64) / tau_c
    bracket = 1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x)
    return sigma * np.sqrt(2.0 / x * bracket)


_SF_PATTERN = np.array([1.0, -0.7, 0.4])
_MIS_PATTERN = np.array([[0.0, 1.0, -0.6], [-0.8, 0.0, 0.5], [0.3, -0.9, 0.0]])
_GSENS_PATTERN = np.array([[1.0, 0.2, -0.1], [-0.2, 0.8, 0.1], [0.1, -0.1, 0.6]])


def _sensor(f: grades.TriadFigures) -> SensorErrorModel:
    """One representative unit of a triad: magnitudes times the fixed sign/size patterns."""
    return SensorErrorModel(
        turn_on_bias_sigma=f.turn_on_sigma,
        bias_instability_sigma=f.gm_sigma,
        bias_instability_tau=f.tau_c,
        random_walk=f.random_walk,
        rate_random_walk=f.rate_random_walk,
        scale_factor_ppm=f.scale_factor_ppm * _SF_PATTERN,
        misalignment=f.misalignment * _MIS_PATTERN,
        quantization=f.quantization,
    )


def _preset(name: str) -> ImuErrorModel:
    f = grades.grade_figures(name)
    g_sens = f.g_sensitivity * _GSENS_PATTERN if f.g_sensitivity else _ZERO33
    return ImuErrorModel(_sensor(f.gyro), _sensor(f.accel), g_sens, jitter_sigma=f.jitter_sigma,
                         drop_probability=f.drop_probability)


_BUILDERS = {"ideal": ImuErrorModel, **{name: (lambda n=name: _preset(n)) for name in grades.GRADES}}

GRADES: tuple[str, ...] = tuple(_BUILDERS)
"""Names accepted by :func:`grade` (parameters in the module docstring table)."""


def grade(name: str) -> ImuErrorModel:
    """Return the preset error model ``name`` (one of :data:`GRADES`).

    Raises:
        ValueError: unknown grade name.
    """
    try:
        builder = _BUILDERS[name]
    except KeyError:
        raise ValueError(f"unknown IMU grade {name!r}; choose one of {GRADES}") from None
    return builder()


_STREAMS = (
    "gyro_turn_on",
    "gyro_gm",
    "gyro_rrw",
    "gyro_white",
    "accel_turn_on",
    "accel_gm",
    "accel_rrw",
    "accel_white",
    "jitter",
    "drop",
)


def _generators(seed: int) -> dict[str, np.random.Generator]:
    children = np.random.SeedSequence(seed).spawn(len(_STREAMS))
    return {name: np.random.Generator(np.random.PCG64(child)) for name, child in zip(_STREAMS, children)}


# Rows per Gauss-Markov block boundary: the closed form below never spans a multiple of BLOCK rows, so a
# run corrupted in chunks that start on multiples of BLOCK (ErrorStream) equals the run corrupted at
# once, bit for bit.
BLOCK = 4096


def _gauss_markov_states(
    sigma: float, tau: float, dt: NDArray[np.float64], rng: np.random.Generator,
    state0: NDArray[np.float64] | None = None, row0: int = 0,
) -> NDArray[np.float64]:
    """Exact discrete Gauss-Markov states at the N+1 interval boundaries, shape (N+1, 3).

    ``b_k = phi_k b_{k-1} + w_k``, ``phi = exp(-dt/tau)``, ``q = sigma^2 (1 - phi^2)``. The first
    state is ``state0`` (drawn from the stationary distribution when None); ``row0`` is the global
    row of ``dt[0]`` (for the block boundaries).
    """
    n = dt.size
    states = np.empty((n + 1, 3))
    states[0] = sigma * rng.standard_normal(3) if state0 is None else state0
    efolds = dt / tau
    phi = np.exp(-efolds)
    noise = (sigma * np.sqrt(-np.expm1(-2.0 * efolds)))[:, None] * rng.standard_normal((n, 3))
    # Closed form of b_k = phi_k b_{k-1} + w_k inside a block:
    # b_k = P_k (b_start + sum_j w_j / P_j) with P_k the product of the phis
    # since the block start; blocks end before P drops below exp(-_MAX_EFOLDS)
    # so that 1/P stays well inside the float range, and at every multiple of BLOCK rows.
    cum = np.cumsum(efolds)
    start = 0
    while start < n:
        base = cum[start - 1] if start > 0 else 0.0
        stop = max(int(np.searchsorted(cum, base + _MAX_EFOLDS, side="right")), start + 1)
        stop = min(stop, (row0 + start) // BLOCK * BLOCK + BLOCK - row0)
        if stop == start + 1:
            states[start + 1] = phi[start] * states[start] + noise[start]
        else:
            decay = np.exp(-(cum[start:stop] - base))[:, None]
            states[start + 1 : stop + 1] = decay * (states[start] + np.cumsum(noise[start:stop] / decay, axis=0))
        start = stop
    return states


def _running_sum(x: NDArray[np.float64], last: NDArray[np.float64]) -> NDArray[np.float64]:
    """``last, last + x_0, last + x_0 + x_1, ...`` (N+1 rows), summed in order so that a sum taken in
    consecutive chunks equals the sum taken at once."""
    return np.cumsum(np.concatenate([last[None, :], x]), axis=0)


class _Triad:
    """The error state of one sensor triad between chunks: turn-on bias, Gauss-Markov and rate random
    walk states, and the quantiser's running sums."""

    def __init__(self, err: SensorErrorModel, rngs: dict[str, np.random.Generator], prefix: str) -> None:
        self.err = err
        self.prefix = prefix
        self.rngs = rngs
        bias = np.asarray(err.bias, dtype=float)
        if err.turn_on_bias_sigma > 0.0:
            bias = bias + err.turn_on_bias_sigma * rngs[f"{prefix}_turn_on"].standard_normal(3)
        self.bias = bias
        self.gm: NDArray[np.float64] | None = None  # drawn with the first chunk, from the gm stream
        self.rrw = np.zeros(3)
        self.q_sum = np.zeros(3)
        self.q_count = np.zeros(3)

    def corrupt(self, x: NDArray[np.float64], dt: NDArray[np.float64], row0: int,
                coupling: NDArray[np.float64] | None) -> NDArray[np.float64]:
        """The model of the module docstring on rows ``row0 ..`` (increments x, intervals dt)."""
        err, rngs, prefix = self.err, self.rngs, self.prefix
        out = x.copy()
        scale = np.diag(np.asarray(err.scale_factor_ppm) * 1e-6)
        mis = np.asarray(err.misalignment)
        if scale.any() or mis.any():
            out = x @ ((np.eye(3) + scale) @ (np.eye(3) + mis)).T
        if coupling is not None:
            out = out + coupling
        dt_col = dt[:, None]
        if self.bias.any():
            out = out + self.bias * dt_col
        if err.bias_instability_sigma > 0.0:
            states = _gauss_markov_states(err.bias_instability_sigma, err.bias_instability_tau, dt,
                                          rngs[f"{prefix}_gm"], self.gm, row0)
            self.gm = states[-1].copy()
            out = out + 0.5 * (states[:-1] + states[1:]) * dt_col
        if err.rate_random_walk > 0.0:
            steps = err.rate_random_walk * np.sqrt(dt_col) * rngs[f"{prefix}_rrw"].standard_normal((dt.size, 3))
            states = _running_sum(steps, self.rrw)
            self.rrw = states[-1].copy()
            out = out + 0.5 * (states[:-1] + states[1:]) * dt_col
        if err.random_walk > 0.0:
            out = out + err.random_walk * np.sqrt(dt_col) * rngs[f"{prefix}_white"].standard_normal((dt.size, 3))
        if err.quantization > 0.0:
            out, self.q_sum, self.q_count = _quantize(out, err.quantization, self.q_sum, self.q_count)
        return out


def _quantize(x: NDArray[np.float64], step: float, q_sum: NDArray[np.float64] | None = None,
              q_count: NDArray[np.float64] | None = None
              ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Residual-carrying quantiser: outputs are multiples of ``step`` and the running sum of the
    outputs stays within step/2 of the running sum of ``x``. ``q_sum``/``q_count``: the input's
    running sum and the output's count so far (zero at the start); returned updated."""
    q_sum = np.zeros(x.shape[1]) if q_sum is None else q_sum
    q_count = np.zeros(x.shape[1]) if q_count is None else q_count
    sums = _running_sum(x, q_sum)
    counts = np.rint(sums[1:] / step)
    out = np.diff(np.concatenate([q_count[None, :], counts]), axis=0) * step
    return out, sums[-1].copy(), (counts[-1] if len(counts) else q_count).copy()


class ErrorStream:
    """:func:`apply` in consecutive chunks of rows, with the same result as at once when every chunk
    but the last is a multiple of :data:`BLOCK` rows long (one random stream per error source, drawn
    in row order; the states carried from chunk to chunk).

    ``t`` holds the true end times of all rows of the run (known before the increments are), so that
    the timestamp jitter of a chunk's last row sees the next interval.
    """

    def __init__(self, model: ImuErrorModel, t: ArrayLike, seed: int, *, t_start: float | None = None) -> None:
        t_arr = np.asarray(t, dtype=np.float64)
        if t_arr.ndim != 1:
            raise ValueError(f"expected t (N,), got {t_arr.shape}")
        if t_start is None:
            if t_arr.size < 2:
                raise ValueError("t_start is required when there is a single row")
            t_start = float(t_arr[0] - (t_arr[1] - t_arr[0]))
        self.dt = np.diff(t_arr, prepend=t_start)
        if not np.all(self.dt > 0.0):
            raise ValueError("times must be strictly increasing and t_start < t[0]")
        self.model = model
        self.t = t_arr
        self.rows = 0  # rows corrupted so far
        rngs = _generators(seed)
        self.rngs = rngs
        self.gyro = _Triad(model.gyro, rngs, "gyro")
        self.accel = _Triad(model.accel, rngs, "accel")

    def corrupt(self, dtheta: ArrayLike, dv: ArrayLike
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """The next rows: ``(t_out, dtheta_out, dv_out, kept)`` as :func:`apply` returns them."""
        dth = np.asarray(dtheta, dtype=np.float64)
        dvel = np.asarray(dv, dtype=np.float64)
        a = self.rows
        n = dth.shape[0] if dth.ndim == 2 else -1
        b = a + n
        if dth.shape != (n, 3) or dvel.shape != (n, 3) or b > self.t.size:
            raise ValueError(f"expected dtheta (N,3), dv (N,3) for rows {a}.. of {self.t.size}; "
                             f"got {dth.shape}, {dvel.shape}")
        model = self.model
        dt = self.dt[a:b]
        coupling = dvel @ np.asarray(model.g_sensitivity).T if np.any(model.g_sensitivity) else None
        dth_out = self.gyro.corrupt(dth, dt, a, coupling)
        dv_out = self.accel.corrupt(dvel, dt, a, None)
        t_out = self.t[a:b].copy()
        if model.jitter_sigma > 0.0 and n > 0:
            # Gaussian timestamp error, truncated to +-0.45 of the shorter adjacent interval so that
            # the output stays strictly increasing
            nxt = np.append(self.dt[a + 1:b + 1], self.dt[-1]) if b == self.t.size else self.dt[a + 1:b + 1]
            limit = 0.45 * np.minimum(dt, nxt)
            t_out = t_out + np.clip(model.jitter_sigma * self.rngs["jitter"].standard_normal(n), -limit, limit)
        self.rows = b
        kept = np.ones(n, dtype=bool)
        if model.drop_probability > 0.0:
            kept = self.rngs["drop"].random(n) >= model.drop_probability
            return t_out[kept], dth_out[kept], dv_out[kept], kept
        return t_out, dth_out, dv_out, kept


def apply(
    model: ImuErrorModel,
    t: ArrayLike,
    dtheta: ArrayLike,
    dv: ArrayLike,
    seed: int,
    *,
    t_start: float | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Corrupt ideal IMU increments with ``model``.

    Deterministic for a given ``seed``: a ``numpy.random.SeedSequence(seed)``
    is split into one PCG64 stream per error source, so switching one source
    on or off does not change the random numbers of the others.

    Args:
        model: error model (see :func:`grade`).
        t: (N,) strictly increasing end times of the intervals [s].
        dtheta: (N, 3) true angle increments over ``(t[i-1], t[i]]``, FRD [rad].
        dv: (N, 3) true specific-force velocity increments, FRD [m/s].
        seed: seed of the run.
        t_start: start of the first interval [s]; defaults to
            ``t[0] - (t[1] - t[0])`` (required when N == 1).

    Returns:
        ``(t_out, dtheta_out, dv_out, kept_mask)``: the kept rows only, and a
        (N,) boolean mask telling which input rows were kept.

        * ``t_out`` carries the timestamp jitter (truncated so that times
          stay strictly increasing); the increments still integrate over the
          *true* intervals ``(t[i-1], t[i]]``: jitter only corrupts the
          reported times.
        * A dropped row is lost, as in a real logger drop: its increment is
          removed, not merged into the next kept row, whose increment still
          covers only its own true interval.  Quantisation happens in the
          sensor, before the drop, so the quantiser residual is not affected
          by drops.
    """
    t_arr = np.asarray(t, dtype=np.float64)
    dth = np.asarray(dtheta, dtype=np.float64)
    dvel = np.asarray(dv, dtype=np.float64)
    n = t_arr.size
    if t_arr.ndim != 1 or dth.shape != (n, 3) or dvel.shape != (n, 3):
        raise ValueError(f"expected t (N,), dtheta (N,3), dv (N,3); got {t_arr.shape}, {dth.shape}, {dvel.shape}")
    if n == 0:
        return t_arr.copy(), dth.copy(), dvel.copy(), np.ones(0, dtype=bool)
    return ErrorStream(model, t_arr, seed, t_start=t_start).corrupt(dth, dvel)


def apply_rows(
    model: ImuErrorModel, rows: ArrayLike, seed: int, *, t_start: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`apply` on contract rows ``t,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z``.

    Args:
        model: error model.
        rows: (N, 7) increment rows (see module docstring for units).
        seed: seed of the run.
        t_start: start of the first interval [s], as in :func:`apply`.

    Returns:
        ``(rows_out, kept_mask)``: (M, 7) corrupted kept rows and the (N,) mask.
    """
    arr = np.asarray(rows, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 7:
        raise ValueError(f"rows must have shape (N, 7), got {arr.shape}")
    t_out, dth, dvel, kept = apply(model, arr[:, 0], arr[:, 1:4], arr[:, 4:7], seed, t_start=t_start)
    return np.column_stack([t_out, dth, dvel]), kept


def allan_deviation(
    rate: ArrayLike, dt: float, taus: ArrayLike | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Overlapping Allan deviation of a uniformly sampled rate signal.

    Args:
        rate: (N,) or (N, k) samples, each the mean rate over one period
            (e.g. ``dtheta / dt``) [u].
        dt: sample period [s].
        taus: requested averaging times [s]; rounded to multiples ``m dt``
            with ``1 <= m <= N // 2``, duplicates removed.  Default: about 60
            log-spaced values over that range.

    Returns:
        ``(taus, adev)``: the averaging times used [s], shape (T,), and the
        Allan deviation [u], shape (T,) or (T, k).
    """
    y = np.asarray(rate, dtype=np.float64)
    one_d = y.ndim == 1
    if one_d:
        y = y[:, None]
    if y.ndim != 2:
        raise ValueError(f"rate must be (N,) or (N, k), got {np.shape(rate)}")
    n = y.shape[0]
    if n < 2 or not dt > 0.0:
        raise ValueError("need at least two samples and dt > 0")
    m_max = n // 2
    if taus is None:
        m = np.unique(np.rint(np.logspace(0.0, math.log10(m_max), 60)).astype(np.int64))
    else:
        m = np.unique(np.rint(np.asarray(taus, dtype=np.float64) / dt).astype(np.int64))
        m = m[(m >= 1) & (m <= m_max)]
    # Phase (integrated rate); the mean is removed first for numerical range,
    # which leaves the Allan variance unchanged.
    phase = np.zeros((n + 1, y.shape[1]))
    np.cumsum((y - y.mean(axis=0)) * dt, axis=0, out=phase[1:])
    adev = np.empty((m.size, y.shape[1]))
    for i, mi in enumerate(m):
        d2 = phase[2 * mi :] - 2.0 * phase[mi:-mi] + phase[: -2 * mi]
        tau = mi * dt
        adev[i] = np.sqrt(np.mean(d2 * d2, axis=0) / (2.0 * tau * tau))
    return m * dt, adev[:, 0] if one_d else adev


def bias_states(
    model: ImuErrorModel, t: ArrayLike, seed: int, *, t_start: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The true sensor biases that :func:`apply` adds for the same ``model``, ``t`` and ``seed``.

    The bias is ``constant + turn-on + Gauss-Markov + rate random walk``,
    drawn from the same random streams as :func:`apply`, so it is exactly the
    bias of that run (before scale factor, misalignment, g-sensitivity,
    noise and quantisation, which are not biases).

    Args:
        model: error model.
        t: (N,) true end times of the intervals [s] (as given to :func:`apply`).
        seed: seed of the run.
        t_start: start of the first interval [s], as in :func:`apply`.

    Returns:
        ``(gyro, accel)``: (N+1, 3) biases [rad/s], [m/s^2] at the interval
        boundaries ``t_start, t[0], ..., t[N-1]``. Row ``i`` of :func:`apply`'s
        increments carries ``0.5 (b[i] + b[i+1]) dt`` of the time-varying parts.
    """
    t_arr = np.asarray(t, dtype=np.float64)
    if t_start is None:
        if t_arr.size < 2:
            raise ValueError("t_start is required when there is a single row")
        t_start = float(t_arr[0] - (t_arr[1] - t_arr[0]))
    dt = np.diff(t_arr, prepend=t_start)
    rngs = _generators(seed)

    def triad(err: SensorErrorModel, prefix: str) -> NDArray[np.float64]:
        out = np.tile(np.asarray(err.bias), (dt.size + 1, 1))
        if err.turn_on_bias_sigma > 0.0:
            out = out + err.turn_on_bias_sigma * rngs[f"{prefix}_turn_on"].standard_normal(3)
        if err.bias_instability_sigma > 0.0:
            out = out + _gauss_markov_states(
                err.bias_instability_sigma, err.bias_instability_tau, dt, rngs[f"{prefix}_gm"]
            )
        if err.rate_random_walk > 0.0:
            steps = err.rate_random_walk * np.sqrt(dt[:, None]) * rngs[f"{prefix}_rrw"].standard_normal((dt.size, 3))
            out = out + np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
        return out

    return triad(model.gyro, "gyro"), triad(model.accel, "accel")
