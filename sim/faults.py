"""Sensor faults for redundancy studies: scenario keys ``[[faults]]`` and their effect on increments.

A fault acts on one axis of one sensor (``gyro`` or ``accel``) of one IMU (0 = the primary, 1.. the
extra IMUs of ``--imus N``) from ``start`` to ``end`` (s of sensor time; default: the end of the run),
after the grade's sensor errors:

==========  ==========================================  ======================================
kind        effect on the axis's rate                   keys (gyro units; accel in brackets)
==========  ==========================================  ======================================
step        ``+ bias``                                  ``bias`` deg/s [m/s^2]
ramp        ``+ rate (t - start)``                      ``rate`` deg/s^2 [m/s^3]
stuck       held at the last rate before ``start``      none
noise       ``+ sigma n`` per sample, n ~ N(0, 1)       ``sigma`` deg/s [m/s^2], ``seed``
scale       ``(1 + ppm 1e-6)`` times the output         ``ppm``
dropout     reads zero                                  none
==========  ==========================================  ======================================

Each is applied exactly over the part of each sample interval ``(t[i-1], t[i]]`` that lies in
``[start, end)`` (so a fault may start inside an interval). Also here: single-axis skewed sensor sets
(the six-gyro dodecahedron) for offline studies, :func:`skewed_gyros`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from . import errors

KINDS: dict[str, tuple[str, ...]] = {
    "step": ("bias",),
    "ramp": ("rate",),
    "stuck": (),
    "noise": ("sigma",),
    "scale": ("ppm",),
    "dropout": (),
}
_COMMON = ("imu", "sensor", "axis", "start")
_OPTIONAL = {"end", "seed"}
AXES = {"x": 0, "y": 1, "z": 2}


@dataclasses.dataclass(frozen=True)
class Fault:
    """One fault, SI units (rad/s, rad/s^2 for the gyro; m/s^2, m/s^3 for the accelerometer)."""

    kind: str
    imu: int
    sensor: str
    axis: int
    start: float
    end: float = math.inf
    value: float = 0.0
    seed: int = 0


def parse(doc: dict[str, Any], source: str = "scenario") -> list[Fault]:
    """The ``[[faults]]`` tables of a scenario document (raises ValueError naming the key)."""
    items = doc.get("faults", [])
    if not isinstance(items, list):
        raise ValueError(f"{source}: faults: expected an array of tables ([[faults]])")  # noqa: TRY004 (a scenario error)
    out = []
    for i, tab in enumerate(items):
        where = f"{source}: faults[{i}]"
        if not isinstance(tab, dict):
            raise ValueError(f"{where}: expected a table")  # noqa: TRY004 (a scenario error)
        kind = tab.get("kind")
        if kind not in KINDS:
            raise ValueError(f"{where}: kind {kind!r} is not one of {', '.join(KINDS)}")
        allowed = set(_COMMON) | set(KINDS[kind]) | _OPTIONAL | {"kind"}
        unknown = set(tab) - allowed
        if unknown:
            raise ValueError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}")
        missing = [k for k in (*_COMMON, *KINDS[kind]) if k not in tab]
        if missing:
            raise ValueError(f"{where}: key(s) {', '.join(missing)} missing")
        imu = tab["imu"]
        if not isinstance(imu, int) or isinstance(imu, bool) or not 0 <= imu <= 2:
            raise ValueError(f"{where}: imu must be 0, 1 or 2, got {imu!r}")
        if tab["sensor"] not in ("gyro", "accel"):
            raise ValueError(f"{where}: sensor must be gyro or accel, got {tab['sensor']!r}")
        if tab["axis"] not in AXES:
            raise ValueError(f"{where}: axis must be x, y or z, got {tab['axis']!r}")
        nums = {k: tab[k] for k in ("start", "end", *KINDS[kind]) if k in tab}
        for k, v in nums.items():
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ValueError(f"{where}: {k} must be a finite number, got {v!r}")
        start = float(tab["start"])
        end = float(tab.get("end", math.inf))
        if not (start >= 0.0 and end > start):
            raise ValueError(f"{where}: need 0 <= start < end, got start {start!r}, end {tab.get('end')!r}")
        if kind == "noise" and not tab["sigma"] >= 0.0:
            raise ValueError(f"{where}: sigma must be >= 0, got {tab['sigma']!r}")
        seed = tab.get("seed", 0)
        if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
            raise ValueError(f"{where}: seed must be a non-negative integer, got {seed!r}")
        value = float(tab[KINDS[kind][0]]) if KINDS[kind] else 0.0
        if tab["sensor"] == "gyro" and kind in ("step", "ramp", "noise"):
            value = math.radians(value)
        out.append(Fault(kind, imu, tab["sensor"], AXES[tab["axis"]], start, end, value, seed))
    return out


@dataclasses.dataclass
class ChannelState:
    """What a fault carries from one chunk of rows to the next: the noise fault's random stream, and
    the rate of the last interval that ended at or before the fault's start (a stuck sensor holds it)."""

    rng: np.random.Generator | None = None
    rate_before: float = 0.0


def apply_channel(fault: Fault, x: np.ndarray, t_begin: np.ndarray, t_end: np.ndarray,
                  state: ChannelState | None = None) -> np.ndarray:
    """The increments ``x`` (N,) of one channel over intervals ``(t_begin, t_end]`` with ``fault``.

    ``state`` (kept by the caller across consecutive chunks of rows) makes chunks add up to the run at
    once; without it the rows are the whole run.
    """
    state = ChannelState() if state is None else state
    x = np.array(x, dtype=float)
    dt = t_end - t_begin
    u1 = np.maximum(t_begin, fault.start)
    u2 = np.minimum(t_end, fault.end)
    cover = np.clip(u2 - u1, 0.0, None)  # s of each interval inside the fault
    frac = np.divide(cover, dt, out=np.zeros_like(cover), where=dt > 0.0)
    hit = cover > 0.0
    if fault.kind == "step":
        x += fault.value * cover
    elif fault.kind == "ramp":  # integral of rate (tau - start) over [u1, u2]
        x += np.where(hit, 0.5 * fault.value * ((u2 - fault.start) ** 2 - (u1 - fault.start) ** 2), 0.0)
    elif fault.kind == "noise":
        if state.rng is None:
            state.rng = np.random.default_rng(fault.seed)
        x += fault.value * cover * state.rng.standard_normal(x.shape[0])
    elif fault.kind == "scale":
        x += fault.value * 1e-6 * x * frac
    elif fault.kind == "dropout":
        x *= 1.0 - frac
    elif fault.kind == "stuck":
        before = np.flatnonzero(~hit & (t_end <= fault.start))
        if before.size and dt[before[-1]] > 0.0:
            state.rate_before = x[before[-1]] / dt[before[-1]]
        x = x * (1.0 - frac) + state.rate_before * cover
    return x


class FaultStream:
    """The faults that name one IMU, applied to consecutive chunks of its rows (:func:`apply` is one
    chunk: the whole run)."""

    def __init__(self, faults: list[Fault], imu: int) -> None:
        self.mine = [f for f in faults if f.imu == imu]
        self.states = [ChannelState() for _ in self.mine]

    def apply(self, t_begin: np.ndarray, t_end: np.ndarray, dtheta: np.ndarray, dv: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """``(dtheta, dv)`` (N, 3) of the next rows with the faults (copies when any apply)."""
        if not self.mine:
            return dtheta, dv
        dtheta, dv = dtheta.copy(), dv.copy()
        for f, st in zip(self.mine, self.states):
            arr = dtheta if f.sensor == "gyro" else dv
            arr[:, f.axis] = apply_channel(f, arr[:, f.axis], t_begin, t_end, st)
        return dtheta, dv


def apply(faults: list[Fault], imu: int, t_begin: np.ndarray, t_end: np.ndarray, dtheta: np.ndarray,
          dv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(dtheta, dv)`` of IMU ``imu`` (N, 3) with the faults that name it (copies when any do)."""
    return FaultStream(faults, imu).apply(t_begin, t_end, dtheta, dv)


def skewed_gyros(t0: float, t: np.ndarray, dtheta: np.ndarray, axes: np.ndarray, grade: str, seed: int,
                 faults: tuple[tuple[int, Fault], ...] = ()) -> np.ndarray:
    """Single-axis gyros along ``axes`` (n, 3, unit, body FRD): increments (N, n) in rad of the true
    body increments ``dtheta`` (N, 3) over ``(t[i-1], t[i]]`` (``t[-1] = t0``), each sensor with its own
    draws of the grade's bias (turn-on, Gauss-Markov, rate random walk) and random walk; scale factor,
    misalignment and g-sensitivity (triad properties) are left out. ``faults`` pairs a sensor index
    with a fault (its imu, sensor and axis fields are not used)."""
    axes = np.asarray(axes, dtype=float)
    n = axes.shape[0]
    model = errors.grade(grade)
    gyro = dataclasses.replace(model.gyro, scale_factor_ppm=(0.0, 0.0, 0.0),
                               misalignment=((0.0,) * 3,) * 3)
    single = dataclasses.replace(model, gyro=gyro, accel=errors.SensorErrorModel(),
                                 g_sensitivity=((0.0,) * 3,) * 3, jitter_sigma=0.0, drop_probability=0.0)
    ideal = dtheta @ axes.T
    out = np.empty_like(ideal)
    zeros = np.zeros((t.shape[0], 3))
    for k in range(0, n, 3):  # three channels at a time through the triad error model
        cols = list(range(k, min(k + 3, n)))
        block = np.zeros((t.shape[0], 3))
        block[:, : len(cols)] = ideal[:, cols]
        _, noisy, _, _ = errors.apply(single, t, block, zeros, seed + 104729 * (k // 3 + 1), t_start=t0)
        out[:, cols] = noisy[:, : len(cols)]
    t_begin = np.concatenate(([t0], t[:-1]))
    for j, f in faults:
        out[:, j] = apply_channel(f, out[:, j], t_begin, t)
    return out
