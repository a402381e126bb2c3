"""``mavins nav IMU0.csv IMU1.csv ... --fdi-log FDI.csv``: fault detection, isolation and fusion of
several IMU files, then the strapdown solution on the fused data (docs/conventions.md "Redundant IMUs",
docs/redundancy.md)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .common import files

FDI_COLUMNS = ("t", "event", "imu", "sensor", "axis", "statistic", "threshold")
SAME_TIME = 1e-6  # s: rows of the IMU files must carry the same t to this


def read_imus(paths: Sequence[Path], init_t: float, rates: bool, sampled: bool) -> tuple[np.ndarray, np.ndarray]:
    """The rows of every IMU file after the initial state's time, checked to share their times.

    Returns ``t`` (N,) and ``data`` (N, n_imus, 6): increments, or rates with ``rates``. A row at
    ``init_t`` is kept for sampled rates (it starts the first interval), dropped otherwise; increment
    rows must all be after ``init_t`` (docs/conventions.md "Files").
    """
    columns = files.RATE_COLUMNS if rates else files.INCREMENT_COLUMNS
    tables = [files.read_table(p, columns) for p in paths]
    ref = tables[0]
    for p, tab in zip(paths[1:], tables[1:]):
        n = min(tab.shape[0], ref.shape[0])
        bad = np.flatnonzero(np.abs(tab[:n, 0] - ref[:n, 0]) > SAME_TIME)
        if bad.size:
            i = int(bad[0])
            raise files.DataFileError(
                f"{p}: line {i + 2}, column 't': {float(tab[i, 0])!r} differs from {float(ref[i, 0])!r} in {paths[0]} "
                "(the IMU files must be sampled at the same times)")
        if tab.shape[0] != ref.shape[0]:
            raise files.DataFileError(f"{p}: {tab.shape[0]} rows, {paths[0]} has {ref.shape[0]} "
                                      "(the IMU files must be sampled at the same times)")
    t = ref[:, 0]
    if not rates:
        if t[0] <= init_t:
            raise files.first_increment_error(paths[0], t[0], init_t)
        keep = np.ones(t.shape[0], dtype=bool)
    else:
        keep = t >= init_t if sampled else t > init_t
    if not keep.any():
        raise files.DataFileError(f"{paths[0]}: no row after the initial state's t = {init_t!r}")
    data = np.stack([tab[keep, 1:7] for tab in tables], axis=1)
    return np.ascontiguousarray(t[keep]), data


def write_events(path: Path, events: Sequence[Any]) -> None:
    """FDI.csv: ``t,event,imu,sensor,axis,statistic,threshold``; empty imu/axis when not known."""
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(",".join(FDI_COLUMNS) + "\n")
        for e in events:
            imu = "" if e.imu is None else str(e.imu)
            stat = repr(float(e.statistic)) if math.isfinite(e.statistic) else ""
            fh.write(f"{e.t!r},{e.event},{imu},{e.sensor},{e.axis},{stat},{float(e.threshold)!r}\n")


def run_nav_fdi(imu_paths: Sequence[Path], init_path: Path, out_path: Path, fdi_path: Path | None, *,
                rates: bool, strapdown: dict[str, Any], spec: str | dict[str, float], false_alarm: float,
                window: float = 0.5) -> tuple[int, list[Any]]:
    """Monitor and fuse the IMU files (core/fdi.py), navigate on the fused data, write the solution and
    the events. ``strapdown`` holds the ``strapdown.make_config`` keywords. Returns the solution rows
    and the events. Raises files.DataFileError (or ValueError) for unusable input; nothing is written
    then."""
    from .core import errmodel
    from .core import strapdown as sd
    from .core.fdi import ImuSetMonitor
    from .core.runner import initial_state, to_file_units

    if len(imu_paths) < 2:
        raise files.DataFileError("--fdi-log needs two or more IMU files")
    inputs = {f"IMU{i}": p for i, p in enumerate(imu_paths)}
    files.check_outputs({"-o": out_path, "--fdi-log": fdi_path}, {**inputs, "--init": init_path})
    for i, p in enumerate(imu_paths):
        for q in imu_paths[i + 1:]:
            if Path(p).resolve() == Path(q).resolve():
                raise files.DataFileError(f"{q}: given twice (each IMU file once)")
    init = files.read_init(init_path)
    sampled = rates and strapdown.get("imu_rates") == "sampled"
    t, data = read_imus(imu_paths, init.t, rates, sampled)
    dt = np.diff(np.concatenate(([init.t], t)))
    positive = dt[dt > 0.0]
    mon = ImuSetMonitor(len(imu_paths), errmodel.spec_of(spec), float(np.median(positive)), window=window,
                        false_alarm=false_alarm)
    g, a, events = mon.process(t, data[:, :, 0:3], data[:, :, 3:6], dt, rates=rates)
    cfg = sd.make_config(**strapdown)
    run = sd.run_rates if rates else sd.run_increments
    state = initial_state(init.to_dict())
    out = np.empty((t.shape[0] // int(strapdown.get("samples", 2)) + 1, sd.OUT_SIZE))
    m = run(state, cfg, t, np.ascontiguousarray(g), np.ascontiguousarray(a), out)
    sol = to_file_units(out[:m], copy=False)
    with files.atomic_outputs([out_path, fdi_path]) as (tmp_out, tmp_fdi):
        files.write_table(tmp_out, files.SOLUTION_COLUMNS, sol)
        if tmp_fdi is not None:
            write_events(tmp_fdi, events)
    return int(m), events


def strapdown_keywords(opts: Any) -> dict[str, Any]:
    """The ``strapdown.make_config`` keywords of ``mavins nav``'s options (NavOptions)."""
    return dict(opts.strapdown.keywords())
