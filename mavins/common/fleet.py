"""A fleet of inputs, each processed on its own (``mavins nav --each``, ``mavins replay --each``).

What the two faces share: where each input's solution goes (:func:`batch_outputs`), the outcome of one
input (:class:`Outcome`, one row of ``DIR/summary.csv``, docs/conventions.md "Aided navigation"), and the
summary file itself (:func:`write_summary`). Each face runs its own job per input through
``common/parallel.run_jobs`` (local processes, or a Dask cluster with ``--cluster``); a job reports a bad
input in its outcome instead of raising, so one bad file never stops the batch.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from . import files

SUMMARY_FILE = "summary.csv"
SUMMARY_COLUMNS = ("input", "output", "duration_s", "samples", "solution_rows", "gnss_accepted", "gnss_rejected",
                   "worst_ratio", "sigma_n", "sigma_e", "sigma_d", "state", "error")


@dataclass
class Outcome:
    """One input of a batch: what it gave, or why not (``error``, one line; then no solution file).

    ``duration_s``: sensor time from the first to the last IMU sample used (s); ``samples``: IMU samples
    used; ``solution_rows``: rows written; ``gnss_*``: GNSS measurements (positions and velocities) the
    filter accepted and rejected; ``worst_ratio``: the largest test ratio of any measurement (below 1
    passes the gate; NaN without aiding); ``sigma``: the filter's final 1-sigma position (m, N E D; NaN
    without aiding); ``state``: the final state (replay: the engine's; nav: ``done``).
    """

    input: str
    output: str
    duration_s: float = math.nan
    samples: int = 0
    solution_rows: int = 0
    gnss_accepted: int = 0
    gnss_rejected: int = 0
    worst_ratio: float = math.nan
    sigma: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    state: str = ""
    error: str = ""
    extra: dict[str, object] = field(default_factory=dict, repr=False)

    def row(self) -> list[str]:
        """The summary.csv row: numbers as the shortest text that reads back the same (``repr``), empty for
        what is not known (NaN)."""
        def num(v: float) -> str:
            return "" if not math.isfinite(v) else repr(float(v))

        return [self.input, "" if self.error else self.output, num(self.duration_s), str(self.samples),
                str(self.solution_rows), str(self.gnss_accepted), str(self.gnss_rejected), num(self.worst_ratio),
                *(num(s) for s in self.sigma), self.state, self.error]


def batch_outputs(paths: list[Path], out_dir: Path) -> list[Path]:
    """Where ``--each`` writes each input's solution: ``OUT_DIR/<its folder relative to the inputs' common
    folder>/<name up to its first dot>.nav.csv`` (``.nav.parquet`` for a parquet input); two inputs that
    would write the same file are refused."""
    resolved = [p.resolve() for p in paths]
    common = Path(os.path.commonpath([p.parent for p in resolved]))
    outs = [out_dir / p.parent.relative_to(common) / (p.name.split(".")[0] + (".nav.parquet" if p.suffix == ".parquet"
                                                                               else ".nav.csv"))
            for p in resolved]
    if len(set(outs)) != len(outs):
        raise files.DataFileError("--each: two inputs would write the same solution (same folder and name)")
    return outs


def write_summary(out_dir: Path, outcomes: list[Outcome]) -> Path:
    """``OUT_DIR/summary.csv``: SUMMARY_COLUMNS, one row per input in the order given (written atomically)."""
    path = out_dir / SUMMARY_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    with files.atomic_outputs([path]) as (tmp,):
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(SUMMARY_COLUMNS)
            w.writerows(o.row() for o in outcomes)
    return path
