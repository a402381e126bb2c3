"""Run a scenario: exact motion, sensor errors, and the contract's files."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mavins import files

from . import errors
from .scenarios import Scenario, apply_turntable, build
from .trajectory import SimResult, simulate


@dataclass(frozen=True)
class SimRun:
    """A simulated recording: exact truth plus what the (imperfect) IMU reports.

    ``t``, ``dtheta``, ``dv`` are the sensor's rows (after jitter and drops);
    ``exact`` holds the error-free increments and truth at the true times.
    """

    scenario: Scenario
    rate: float
    grade: str
    seed: int
    exact: SimResult
    t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    kept: np.ndarray

    def init(self) -> files.InitialState:
        return files.InitialState(**self.exact.init())

    def rates(self) -> tuple[np.ndarray, np.ndarray]:
        """Interval-averaged rates: increment / the row's interval in the file."""
        dt = np.diff(np.concatenate(([self.exact.t0], self.t)))[:, None]
        return self.dtheta / dt, self.dv / dt


def generate(
    scenario: Scenario, *, duration: float | None = None, rate: float | None = None, seed: int = 0,
    grade: str | None = None, usec_grid: bool = False,
) -> SimRun:
    """Simulate a scenario for ``duration`` s at ``rate`` Hz with the IMU ``grade``.

    ``usec_grid`` puts the samples on whole microseconds (for MAVLink streaming).
    """
    traj = build(scenario)
    length = traj.t - traj.t0
    dur = duration if duration is not None else (scenario.duration or length)
    if dur <= 0:
        raise ValueError(f"duration must be positive, got {dur}")
    if length < dur:
        traj.static(dur - length)
    apply_turntable(scenario, traj, traj.t0 + dur)
    hz = rate if rate is not None else scenario.rate
    if hz <= 0:
        raise ValueError(f"rate must be positive, got {hz}")
    exact = simulate(traj, hz, dur, usec_grid=usec_grid)
    g = grade if grade is not None else scenario.grade
    model = errors.grade(g)
    t, dth, dv, kept = errors.apply(model, exact.t, exact.dtheta, exact.dv, seed, t_start=exact.t0)
    return SimRun(scenario, hz, g, seed, exact, t, dth, dv, kept)


def write(run: SimRun, outdir: Path) -> list[Path]:
    """Write imu.csv, imu_rates.csv, truth.csv and init.json (CONVENTIONS.md) into outdir."""
    outdir.mkdir(parents=True, exist_ok=True)
    imu = outdir / "imu.csv"
    files.write_table(imu, files.INCREMENT_COLUMNS, np.column_stack([run.t, run.dtheta, run.dv]))
    w, f = run.rates()
    rates = outdir / "imu_rates.csv"
    files.write_table(rates, files.RATE_COLUMNS, np.column_stack([run.t, w, f]))
    truth = outdir / "truth.csv"
    files.write_table(truth, SimResult.TRUTH_COLUMNS, run.exact.truth)
    init = outdir / "init.json"
    files.write_init(init, run.init())
    return [imu, rates, truth, init]
