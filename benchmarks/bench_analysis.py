"""``mavins analyze`` at the issue's size: Monte Carlo speed on 1 and 2 jobs, and MC against covariance.

* **Case.** The ``flight`` scenario for 10 min at 200 Hz (its segments, then a
  static tail that keeps the last speed and heading), a grade's figures
  (default industrial; scale factor and misalignment as 1-sigma), free
  inertial, 500 runs (``--runs``).
* **Speed.** The exact increments are simulated once (timed apart); the
  covariance analysis (12 sources) is timed; then the same 500 Monte Carlo
  runs with ``--jobs 1`` and ``--jobs 2`` (mavins/common/parallel.py, forked local
  pool), whose results must be identical bit for bit; speed-up = time(1) / time(2).
* **Agreement.** At every minute: the Monte Carlo's sample sigma of the
  horizontal position, sqrt(s_n^2 + s_e^2), divided by the covariance's
  sqrt(P_nn + P_ee), with its 95 % sample-size band: ``(N - 1) s^2 / sigma^2``
  is chi-square with N - 1 degrees of freedom for one Gaussian component
  (2 (N - 1) when north and east are independent with equal variance, so the
  band printed, for N - 1, is the wider of the two); quantiles by Wilson and
  Hilferty (1931). The issue's goal is the ratio within 10 % at every minute.

Run from the repository root (about 2 min on 2 cores; ``--quick``: 40 runs of 2 min at 100 Hz)::

    .venv/bin/python benchmarks/bench_analysis.py [--runs N] [--grade G] [--quick]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from statistics import NormalDist
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # as mavins analyze does
    os.environ.setdefault(_var, "1")

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (str(HERE), str(ROOT)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

BASELINE = "the same Monte Carlo runs on 1 job, same run"
NOTES = [("bench_analysis: MC/cov = Monte Carlo sample sigma of horizontal position over the covariance's 1-sigma; "
         "band = 95 % chi interval for the number of runs")]


def chi_band(dof: int, p_two_sided: float = 0.05) -> tuple[float, float]:
    """95 % band of s / sigma for a sample sigma with ``dof`` degrees of freedom (Wilson-Hilferty)."""
    z = NormalDist().inv_cdf(1.0 - p_two_sided / 2.0)
    k = 2.0 / (9.0 * dof)
    return tuple(math.sqrt((1.0 - k + zz * math.sqrt(k)) ** 3) for zz in (-z, z))  # type: ignore[return-value]


def main(argv: Sequence[str] = ()) -> list[dict[str, Any]]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--grade", default="industrial")
    ap.add_argument("--quick", action="store_true", help="40 runs of 2 min at 100 Hz")
    args = ap.parse_args(list(argv))
    if args.quick:
        args.runs, args.duration, args.rate = 40, 120.0, 100.0

    from mavins import analysis as an
    from mavins.core import covariance as cov
    from mavins.common.parallel import run_jobs
    from sim.scenarios import load

    scenario = load("flight")
    spec = cov.spec_from_grade(args.grade)
    opts = an.AnalysisOptions(runs=args.runs, duration=args.duration, rate=args.rate)
    samples = an.samples_in(args.duration, args.rate)
    rows: list[dict[str, Any]] = []

    an.covariance_part(scenario, spec, replace(opts, duration=2.0))  # kernels compiled or loaded, not timed
    t0 = time.perf_counter()
    an.exact_run(scenario, args.duration, args.rate)  # cached: the forked workers inherit it
    t_sim = time.perf_counter() - t0
    rows.append({"case": f"simulate flight {args.duration:g} s at {args.rate:g} Hz (once)", "samples": samples,
                 "seconds": t_sim})

    t0 = time.perf_counter()
    grid, by_source, t = an.covariance_part(scenario, spec, opts)
    t_cov = time.perf_counter() - t0
    rows.append({"case": "covariance, 12 sources", "samples": samples, "seconds": t_cov})
    total = sum(by_source.values())
    cov_sig = cov.sigma_rows(total)

    jobs = [an.MonteCarloJob(scenario, args.duration, args.rate, spec, 0, i, "free", grid) for i in range(args.runs)]
    an.monte_carlo_run(jobs[0])  # kernels compiled or loaded before the clock starts
    results: dict[int, np.ndarray] = {}
    times: dict[int, float] = {}
    for j in (1, 2):
        t0 = time.perf_counter()
        results[j] = np.stack(run_jobs(an.monte_carlo_run, jobs, jobs=j, label=f"monte carlo, {j} job(s)"))
        times[j] = time.perf_counter() - t0
        rows.append({"case": f"Monte Carlo {args.runs} runs, --jobs {j}", "samples": samples * args.runs,
                     "seconds": times[j], "rate": samples * args.runs / times[j],
                     **({"ratio": times[1] / times[2], "note": "speed-up over --jobs 1"} if j == 2 else {})})
    same = np.array_equal(results[1], results[2])
    rows.append({"case": "--jobs 2 equals --jobs 1 bit for bit", "value": str(same)})

    mc_sig = an.mc_sigma(results[1])
    lo, hi = chi_band(args.runs - 1)
    worst = 0.0
    step = max(1, round(60.0 / (grid.out_samples / args.rate)))
    for k in range(step, len(t), step):
        c = math.hypot(cov_sig[k, 0], cov_sig[k, 1])
        m = math.hypot(mc_sig[k, 0], mc_sig[k, 1])
        worst = max(worst, abs(m / c - 1.0))
        rows.append({"case": f"MC/cov horizontal position, t = {(t[k] - t[0]) / 60:.0f} min",
                     "value": f"{m:.4g} m / {c:.4g} m = {m / c:.3f}", "note": f"95 % band {lo:.3f}..{hi:.3f}"})
    rows.append({"case": "largest |MC/cov - 1| over the minutes", "value": f"{worst:.3f}",
                 "goal": f"<= 0.10: {'met' if worst <= 0.10 else 'not met'}"})
    return rows


def _print(rows: list[dict[str, Any]]) -> None:
    keys = ("case", "samples", "seconds", "rate", "value", "ratio", "goal", "note")
    fmt = {"samples": lambda v: f"{int(v):,}", "seconds": lambda v: f"{v:.2f}", "rate": lambda v: f"{v:,.0f}",
           "ratio": lambda v: f"{v:.2f}x"}
    cols = [k for k in keys if any(k in r for r in rows)]
    cells = [[fmt.get(k, str)(r[k]) if k in r else "-" for k in cols] for r in rows]
    width = [max(len(k), *(len(c[i]) for c in cells)) for i, k in enumerate(cols)]
    print("  ".join(k.ljust(w) for k, w in zip(cols, width)))
    for c in cells:
        print("  ".join(v.ljust(w) for v, w in zip(c, width)))


if __name__ == "__main__":
    _print(main(sys.argv[1:]))
