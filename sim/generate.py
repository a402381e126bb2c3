"""Run a scenario: exact motion, sensor errors, and the contract's files."""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterator

import numpy as np

from mavins.common import files

from . import errors, faults, polar
from .polar import EarthFixedMotion
from .scenarios import Scenario, apply_turntable, build
from .trajectory import SimResult, join, simulate_chunks

FILE_NAMES = ("imu.csv", "imu_rates.csv", "truth.csv", "init.json")

if TYPE_CHECKING:
    from .aiding import Aiding


@dataclass(frozen=True)
class SimRun:
    """A simulated recording: exact truth plus what the (imperfect) IMU reports.

    ``t``, ``dtheta``, ``dv`` are the sensor's rows (after jitter and drops);
    ``exact`` holds the error-free increments and truth at the true times;
    ``extra`` the (dtheta, dv) of the extra IMUs 1.. on the same rows (own
    error draws, no timing defects of their own), scenario faults included.
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
    extra: tuple[tuple[np.ndarray, np.ndarray], ...] = ()

    def init(self) -> files.InitialState:
        return files.InitialState(**self.exact.init())

    def rates(self) -> tuple[np.ndarray, np.ndarray]:
        """Interval-averaged rates: increment / the row's interval in the file."""
        dt = np.diff(np.concatenate(([self.exact.t0], self.t)))[:, None]
        return self.dtheta / dt, self.dv / dt


def generate(
    scenario: Scenario, *, duration: float | None = None, rate: float | None = None, seed: int = 0,
    grade: str | None = None, usec_grid: bool = False, imus: int = 1,
) -> SimRun:
    """Simulate a scenario for ``duration`` s at ``rate`` Hz with the IMU ``grade``.

    ``usec_grid`` puts the samples on whole microseconds (for MAVLink streaming);
    ``imus`` (1..3) IMUs, the scenario's ``[[faults]]`` applied (sim/faults.py).
    The run is :func:`generate_chunks`'s pieces joined, so a stream made in
    pieces carries the same rows as the files.
    """
    return join_runs(list(generate_chunks(scenario, duration=duration, rate=rate, seed=seed, grade=grade,
                                          usec_grid=usec_grid, imus=imus)))


def generate_chunks(
    scenario: Scenario, *, duration: float | None = None, rate: float | None = None, seed: int = 0,
    grade: str | None = None, usec_grid: bool = False, imus: int = 1,
) -> Iterator[SimRun]:
    """:func:`generate`'s run in consecutive pieces (sim.trajectory.chunk_bounds rows), each a SimRun of
    its rows: the exact motion, the sensor errors (sim.errors.ErrorStream) and the faults
    (sim.faults.FaultStream) carried from piece to piece. The arguments are checked here; the motion is
    computed piece by piece as the iterator is consumed."""
    traj = build(scenario)
    length = traj.t - traj.t0
    dur = run_duration(scenario, duration, traj)
    if dur <= 0:
        raise ValueError(f"duration must be positive, got {dur}")
    hz = rate if rate is not None else scenario.rate
    if hz <= 0:
        raise ValueError(f"rate must be positive, got {hz}")
    if not 1 <= imus <= 3:
        raise ValueError(f"imus must be 1..3, got {imus}")
    check_size(scenario, duration=dur, rate=hz)  # before anything is allocated
    flist = faults.parse(scenario.doc, scenario.source)
    if any(f.imu >= imus for f in flist):
        raise ValueError(f"{scenario.source}: a fault names IMU {max(f.imu for f in flist)}, "
                         f"but the run has {imus} IMU(s) (--imus)")
    if length < dur:
        traj.static(dur - length)
    apply_turntable(scenario, traj, traj.t0 + dur)
    if isinstance(traj, EarthFixedMotion):
        pieces = polar.simulate_chunks(traj, hz, dur, usec_grid=usec_grid)
    else:
        pieces = simulate_chunks(traj, hz, dur, usec_grid=usec_grid)
    g = grade if grade is not None else scenario.grade
    model = errors.grade(g)
    t0 = traj.t0
    primary = errors.ErrorStream(model, pieces.t, seed, t_start=t0)
    # IMUs 1..imus-1: own error draws (seed + 7919 k), no jitter or drops of their own (one clock samples
    # them all), their faults applied, on the primary's kept rows
    quiet = dataclasses.replace(model, jitter_sigma=0.0, drop_probability=0.0)
    extras = [errors.ErrorStream(quiet, pieces.t, seed + 7919 * k, t_start=t0) for k in range(1, imus)]
    fault_streams = [faults.FaultStream(flist, k) for k in range(imus)]

    def run() -> Iterator[SimRun]:
        for exact in pieces:
            t, dth, dv, kept = primary.corrupt(exact.dtheta, exact.dv)
            begin = np.concatenate(([exact.t0], exact.t[:-1]))[kept]
            end = exact.t[kept]
            dth, dv = fault_streams[0].apply(begin, end, dth, dv)
            more = []
            for k, stream in enumerate(extras, start=1):
                _, dth_k, dv_k, _ = stream.corrupt(exact.dtheta, exact.dv)
                more.append(fault_streams[k].apply(begin, end, dth_k[kept], dv_k[kept]))
            yield SimRun(scenario, hz, g, seed, exact, t, dth, dv, kept, tuple(more))

    return run()


def join_runs(parts: list[SimRun]) -> SimRun:
    """One SimRun of consecutive pieces (generate_chunks)."""
    first = parts[0]
    extra = tuple((np.concatenate([p.extra[k][0] for p in parts]), np.concatenate([p.extra[k][1] for p in parts]))
                  for k in range(len(first.extra)))
    return SimRun(first.scenario, first.rate, first.grade, first.seed, join([p.exact for p in parts]),
                  np.concatenate([p.t for p in parts]), np.concatenate([p.dtheta for p in parts]),
                  np.concatenate([p.dv for p in parts]), np.concatenate([p.kept for p in parts]), extra)


def extra_names(imus: int) -> tuple[str, ...]:
    """Files of the extra IMUs written with ``--imus N``: imu1.csv, imu2.csv."""
    return tuple(f"imu{k}.csv" for k in range(1, imus))


def write(run: SimRun, outdir: Path, aiding: Aiding | None = None) -> list[Path]:
    """Write imu.csv, imu_rates.csv, truth.csv and init.json (docs/conventions.md) into outdir.

    With extra IMUs also imu1.csv, imu2.csv (increments, the rows of imu.csv). With ``aiding``
    (sim.aiding.simulate_aiding) also gnss.csv, baro.csv, mag.csv (those it holds).
    """
    # Files are written beside their targets and renamed into place at the end (files.atomic_outputs): an
    # error, a full disk or Ctrl-C leaves outdir as it was. Too large for the disk: files.ResourceError first.
    imu, rates, truth, init = (outdir / name for name in FILE_NAMES)
    extras = [outdir / name for name in extra_names(len(run.extra) + 1)]
    files.check_resources(f"the files of {len(run.t):,} samples", disk=len(run.t) * DISK_PER_SAMPLE, disk_at=outdir,
                          hint=" (shorten --duration or lower --rate)")
    stage: Path | None = None
    try:
        with files.atomic_outputs([imu, rates, truth, init, *extras]) as (t_imu, t_rates, t_truth, t_init,
                                                                          *t_extras):
            try:
                files.write_table(t_imu, files.INCREMENT_COLUMNS, np.column_stack([run.t, run.dtheta, run.dv]))
                w, f = run.rates()
                files.write_table(t_rates, files.RATE_COLUMNS, np.column_stack([run.t, w, f]))
                files.write_table(t_truth, SimResult.TRUTH_COLUMNS, run.exact.truth)
                files.write_init(t_init, run.init())
                for t_x, (dth_x, dv_x) in zip(t_extras, run.extra):
                    files.write_table(t_x, files.INCREMENT_COLUMNS, np.column_stack([run.t, dth_x, dv_x]))
                if aiding is not None:  # its files go to a hidden folder in outdir, moved in with the others
                    stage = Path(tempfile.mkdtemp(dir=outdir, prefix=".aiding.", suffix=".tmp"))
                    staged = [Path(p) for p in aiding.write(stage)]
            except BaseException:
                if stage is not None:  # before atomic_outputs removes a folder it made
                    shutil.rmtree(stage, ignore_errors=True)
                raise
        paths = [imu, rates, truth, init, *extras]
        if stage is not None:
            for p in staged:
                os.replace(p, outdir / p.name)
                paths.append(outdir / p.name)
        return paths
    finally:
        if stage is not None:
            shutil.rmtree(stage, ignore_errors=True)


# Sizes of a run, per IMU sample, measured on the built-in scenarios (peak memory of generate() plus
# write(): about 0.8 kB for static, 1.2 kB for flight; the three CSVs: 450-640 bytes), with a margin.
MEMORY_PER_SAMPLE = 1600
DISK_PER_SAMPLE = 700


def run_duration(scenario: Scenario, duration: float | None, traj: object = None) -> float:
    """Seconds a run lasts: ``duration`` when given, else the scenario's, else its trajectory's length."""
    if duration is not None:
        return duration
    if scenario.duration:
        return scenario.duration
    traj = build(scenario) if traj is None else traj
    return traj.t - traj.t0  # type: ignore[attr-defined]


def samples(duration: float, rate: float) -> int:
    """IMU samples of a run (simulate()'s grid t0 + k/rate, k = 1..n)."""
    return int(math.floor(duration * rate + 1e-9))


def check_size(scenario: Scenario, *, duration: float | None, rate: float | None, outdir: Path | None = None) -> None:
    """Refuse a run that cannot be held in memory (or, with ``outdir``, written to its disk), with the estimate.

    Raises ValueError for a run of no sample and files.ResourceError for one
    too large; call it before generate() so nothing is computed in vain.
    """
    hz = rate if rate is not None else scenario.rate
    dur = run_duration(scenario, duration)
    if not (dur > 0 and hz > 0 and math.isfinite(dur) and math.isfinite(hz)):
        raise ValueError(f"duration and rate must be positive and finite, got {dur:g} s at {hz:g} Hz")
    n = samples(dur, hz)
    if n < 1:
        raise ValueError(f"{dur:g} s at {hz:g} Hz is less than one IMU sample (lengthen --duration or raise --rate)")
    what = f"{dur:g} s at {hz:g} Hz ({n:,} samples)"
    hint = " (shorten --duration or lower --rate)"
    files.check_resources(what, memory=n * MEMORY_PER_SAMPLE, hint=hint)
    if outdir is not None:
        files.check_resources(what, disk=n * DISK_PER_SAMPLE, disk_at=outdir, hint=hint)
