"""``mavins analyze``: error budget of a scenario by covariance analysis and Monte Carlo (docs/analysis.md).

1. Covariance: core/covariance.py propagates the linear error model along the
   scenario's true trajectory, each error source alone (the budget) and their sum.
2. Monte Carlo: ``runs`` strapdown runs (core/runner.py, the same kernel as
   ``mavins nav``) over the scenario's exact increments, each corrupted by
   sim/errors.apply with errors drawn from the same specification (seeded per
   run), through mavins/common/parallel.py (local cores or a Dask cluster); the
   sample standard deviation of the error against truth at every output time.
3. Files (docs/conventions.md "Error analysis"): covariance.csv, montecarlo.csv,
   budget.csv, plus analysis.rrd (Rerun, record/budget.py) and analysis.png
   (when matplotlib is installed); written
   together, temp-and-rename, only when everything succeeded.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from .common import files
from .core import covariance as cov
from .common.parallel import run_jobs

OUTPUT_FILES = ("covariance.csv", "montecarlo.csv", "budget.csv")
RECORDING_FILE = "analysis.rrd"
PLOT_FILE = "analysis.png"
COLUMNS = ("t",) + cov.SIGMA_COLUMNS
BUDGET_HEADER = ("source",) + cov.BUDGET_COLUMNS


@dataclass(frozen=True)
class AnalysisOptions:
    """Options of ``mavins analyze`` (names as on the command line; s, Hz)."""

    runs: int = 100
    jobs: int | None = None
    cluster: str | None = None
    vertical: str = "free"
    duration: float | None = None
    rate: float | None = None
    seed: int = 0
    every: float = 1.0  # output interval (s)
    step: float = 0.1  # covariance propagation step (s), rounded to whole samples
    samples: int = 2  # samples per strapdown update


@dataclass(frozen=True)
class Grid:
    """Sample counts of the output and propagation grids (both whole multiples of ``samples``)."""

    out_samples: int
    step_samples: int
    samples: int

    @property
    def every(self) -> int:
        """Propagation steps per output row."""
        return self.out_samples // self.step_samples


def make_grid(rate: float, opts: AnalysisOptions) -> Grid:
    """Output every ``opts.every`` s and propagate in steps near ``opts.step`` s, in whole updates of the strapdown."""
    upd = opts.samples
    out = upd * max(1, round(opts.every * rate / upd))
    n_sub = max(1, round(out / max(1.0, opts.step * rate)))
    while out % n_sub:
        n_sub -= 1
    return Grid(out, out // n_sub, upd)


@dataclass(frozen=True)
class MonteCarloJob:
    """One Monte Carlo run: what a worker needs to rebuild the exact data and corrupt it (picklable)."""

    scenario: object  # sim.scenarios.Scenario (kept loose: mavins does not import sim at module level)
    duration: float
    rate: float
    spec: cov.AnalysisSpec
    seed: int
    index: int
    vertical: str
    grid: Grid


@lru_cache(maxsize=2)
def _exact_cached(name: str, source: str, doc_json: str, duration: float, rate: float) -> object:
    from sim.generate import generate
    from sim.scenarios import Scenario

    return generate(Scenario(name, source, json.loads(doc_json)), duration=duration, rate=rate, grade="ideal").exact


def exact_run(scenario: object, duration: float, rate: float) -> object:
    """The scenario's error-free increments and truth (sim.trajectory.SimResult), once per process."""
    s = scenario
    return _exact_cached(s.name, s.source, json.dumps(s.doc, sort_keys=True), float(duration), float(rate))  # type: ignore[attr-defined]


def run_seeds(seed: int, index: int) -> tuple[int, np.random.Generator]:
    """Run ``index``'s seed for sim/errors.apply and its generator for the random constants (scale, misalignment)."""
    state = np.random.SeedSequence([seed, index]).generate_state(2)
    return int(state[0]) | (int(state[1]) << 32), np.random.default_rng(np.random.SeedSequence([seed, index, 1]))


def error_model(spec: cov.AnalysisSpec, rng: np.random.Generator) -> object:
    """A sim.errors.ImuErrorModel with this run's scale factors and misalignments drawn from ``spec``.

    Biases, instability, random walks are drawn by sim/errors.apply from the
    run's seed; quantisation, g-sensitivity, jitter and drops are left out
    (they are not in the analysis model).
    """
    from sim.errors import ImuErrorModel, SensorErrorModel

    s = spec.imu
    off = np.ones((3, 3)) - np.eye(3)

    def triad(bias: float, gm: float, tau: float, white: float, rrw: float, scale: float, mis: float) -> SensorErrorModel:
        return SensorErrorModel(
            turn_on_bias_sigma=bias, bias_instability_sigma=gm, bias_instability_tau=tau, random_walk=white,
            rate_random_walk=rrw, scale_factor_ppm=scale * rng.standard_normal(3) / cov.PPM,
            misalignment=mis * rng.standard_normal((3, 3)) * off,
        )

    gyro = triad(s.gyro_bias, s.gyro_gm, s.gyro_tau, s.gyro_arw, s.gyro_rrw, spec.gyro_scale, spec.gyro_misalignment)
    accel = triad(s.accel_bias, s.accel_gm, s.accel_tau, s.accel_vrw, s.accel_rrw, spec.accel_scale,
                  spec.accel_misalignment)
    return ImuErrorModel(gyro, accel)


def monte_carlo_run(job: MonteCarloJob) -> np.ndarray:
    """Errors (n_out, 9) of one run at the output times: position NED (m), velocity NED (m/s), phi (rad)."""
    from sim.errors import apply

    from .core.frames import nav_errors
    from .core.runner import navigate

    exact = exact_run(job.scenario, job.duration, job.rate)
    seed, rng = run_seeds(job.seed, job.index)
    model = error_model(job.spec, rng)
    t, dth, dv, _ = apply(model, exact.t, exact.dtheta, exact.dv, seed, t_start=exact.t0)  # type: ignore[attr-defined]
    earth = "none" if job.scenario.earth == "none" else "wgs84"  # type: ignore[attr-defined]
    sol = navigate(t, dth, dv, exact.init(), samples=job.grid.samples, vertical=job.vertical,  # type: ignore[attr-defined]
                   earth_model=earth)
    g = job.grid
    n_out = len(exact.t) // g.out_samples  # type: ignore[attr-defined]
    k = np.arange(1, n_out + 1) * g.out_samples
    errs = nav_errors(sol[k // g.samples - 1], exact.truth[k])  # type: ignore[attr-defined]
    return np.vstack([np.zeros((1, 9)), errs])


@dataclass
class AnalysisResult:
    """Everything ``mavins analyze`` reports (arrays in SIGMA_COLUMNS order: m, m/s, deg)."""

    t: np.ndarray
    covariance: np.ndarray
    montecarlo: np.ndarray
    budget: dict[str, np.ndarray]
    runs: int
    by_source: dict[str, np.ndarray] = field(repr=False, default_factory=dict)


def mc_sigma(errors: np.ndarray) -> np.ndarray:
    """Sample standard deviation (n-1) over runs of (runs, n_out, 9) errors -> (n_out, 9), attitude in deg."""
    s = np.std(errors, axis=0, ddof=1)
    s[:, 6:9] = np.degrees(s[:, 6:9])
    return s


def covariance_part(scenario: object, spec: cov.AnalysisSpec, opts: AnalysisOptions) -> tuple[Grid, dict[str, np.ndarray], np.ndarray]:
    """(grid, per-source navigation covariances, output times) of the scenario."""
    duration, rate = _duration_rate(scenario, opts)
    grid = make_grid(rate, opts)
    exact = exact_run(scenario, duration, rate)
    track = cov.track_means(exact.t0, exact.t, exact.dtheta, exact.dv, exact.truth, grid.step_samples)  # type: ignore[attr-defined]
    by_source = cov.propagate(track, spec, every=grid.every, earth=scenario.earth != "none",  # type: ignore[attr-defined]
                              vertical=opts.vertical)
    n_out = len(exact.t) // grid.out_samples + 1  # type: ignore[attr-defined]
    t = track.t[:: grid.every][:n_out]
    return grid, {k: v[:n_out] for k, v in by_source.items()}, t


def samples_in(duration: float, rate: float) -> int:
    """IMU samples of a run (sim.generate.samples)."""
    from sim.generate import samples

    return samples(duration, rate)


def _duration_rate(scenario: object, opts: AnalysisOptions) -> tuple[float, float]:
    from sim.scenarios import build

    rate = opts.rate if opts.rate is not None else scenario.rate  # type: ignore[attr-defined]
    if opts.duration is not None:
        return float(opts.duration), float(rate)
    if scenario.duration is not None:  # type: ignore[attr-defined]
        return float(scenario.duration), float(rate)  # type: ignore[attr-defined]
    traj = build(scenario)  # type: ignore[arg-type]
    return float(traj.t - traj.t0), float(rate)


def analyze(scenario: object, spec: cov.AnalysisSpec, opts: AnalysisOptions) -> AnalysisResult:
    """Covariance analysis and Monte Carlo of a scenario (no files)."""
    if opts.runs < 2:
        raise ValueError(f"--runs must be at least 2 (a sample standard deviation), got {opts.runs}")
    duration, rate = _duration_rate(scenario, opts)
    if samples_in(duration, rate) < make_grid(rate, opts).out_samples:
        raise ValueError(f"{duration:g} s at {rate:g} Hz is shorter than one output interval ({opts.every:g} s)")
    grid, by_source, t = covariance_part(scenario, spec, opts)
    total = sum(by_source.values())
    budget = {name: cov.budget_row(P[-1]) for name, P in by_source.items()}
    budget["total"] = cov.budget_row(total[-1])
    jobs = [MonteCarloJob(scenario, duration, rate, spec, opts.seed, i, opts.vertical, grid) for i in range(opts.runs)]
    errors = np.stack(run_jobs(monte_carlo_run, jobs, jobs=opts.jobs, cluster=opts.cluster, label="monte carlo"))
    n = min(len(t), errors.shape[1])
    return AnalysisResult(t[:n], cov.sigma_rows(total)[:n], mc_sigma(errors)[:n], budget, opts.runs,
                          by_source)


def _table(result: AnalysisResult) -> str:
    """The printed summary: budget at the end of the run, total and the Monte Carlo's sample sigma."""
    head = f"{'source':<24}{'pos_h m':>12}{'pos_v m':>12}{'vel_h m/s':>12}{'att_lvl deg':>13}{'att_yaw deg':>13}"
    lines = [f"error budget at t = {result.t[-1]:g} s (1-sigma, each source alone)", head]

    def row(name: str, v: np.ndarray) -> str:
        return f"{name:<24}{v[0]:>12.4g}{v[1]:>12.4g}{v[2]:>12.4g}{v[3]:>13.4g}{v[4]:>13.4g}"

    for name in cov.SOURCES:
        lines.append(row(name, result.budget[name]))
    lines.append(row("total (covariance)", result.budget["total"]))
    m = result.montecarlo[-1]
    mc = np.array([math.hypot(m[0], m[1]), m[2], math.hypot(m[3], m[4]), math.hypot(m[6], m[7]), m[8]])
    lines.append(row(f"Monte Carlo ({result.runs} runs)", mc))
    return "\n".join(lines)


PLOT_SIZE_IN, PLOT_DPI = (11.0, 7.0), 100  # analysis.png: 1100 x 700 pixels


def _plot(path: Path, result: AnalysisResult) -> None:
    """analysis.png: :func:`_figure` as a PNG."""
    import matplotlib.pyplot as plt

    fig = _figure(result)
    fig.savefig(path, dpi=PLOT_DPI, format="png")
    plt.close(fig)


def _figure(result: AnalysisResult) -> object:
    """Four panels (horizontal and vertical position, horizontal velocity, level attitude): the covariance
    1-sigma (lines) and the Monte Carlo sample sigma (dots) against time from the start, in minutes when
    the run is longer than 10 minutes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    span = result.t[-1] - result.t[0]
    unit, scale = ("min", 60.0) if span > 600.0 else ("s", 1.0)
    t = (result.t - result.t[0]) / scale
    c, m = result.covariance, result.montecarlo
    panels = (("horizontal position (m)", np.hypot(c[:, 0], c[:, 1]), np.hypot(m[:, 0], m[:, 1])),
              ("vertical position (m)", c[:, 2], m[:, 2]),
              ("horizontal velocity (m/s)", np.hypot(c[:, 3], c[:, 4]), np.hypot(m[:, 3], m[:, 4])),
              ("level attitude (deg)", np.hypot(c[:, 6], c[:, 7]), np.hypot(m[:, 6], m[:, 7])))
    fig, axes = plt.subplots(2, 2, figsize=PLOT_SIZE_IN, sharex=True)
    for ax, (title, cv, mv) in zip(axes.flat, panels):
        ax.plot(t, cv, label="covariance 1-sigma")
        ax.plot(t, mv, ".", markersize=3, label=f"Monte Carlo sigma ({result.runs} runs)")
        ax.set_title(title)
        ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel(f"time ({unit})")
    axes[0, 0].legend()
    fig.tight_layout()
    return fig


def _have_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def run_analyze(scenario: object, spec: cov.AnalysisSpec, outdir: Path, opts: AnalysisOptions) -> list[Path]:
    """Analyse, write the files into ``outdir`` together (nothing on failure), print the table; returns the paths."""
    if outdir.exists() and not outdir.is_dir():
        raise files.DataFileError(f"{outdir}: -o names a file, expected a directory to write into")
    names = OUTPUT_FILES + (RECORDING_FILE,) + ((PLOT_FILE,) if _have_matplotlib() else ())
    targets = [outdir / name for name in names]
    files.check_outputs({f"-o {p}": p for p in targets}, {"SCENARIO": Path(scenario.source)})  # type: ignore[attr-defined]
    result = analyze(scenario, spec, opts)
    with files.atomic_outputs(targets) as tmps:
        t_cov, t_mc, t_budget = (Path(str(p)) for p in tmps[:3])
        files.write_table(t_cov, COLUMNS, np.column_stack([result.t, result.covariance]))
        files.write_table(t_mc, COLUMNS, np.column_stack([result.t, result.montecarlo]))
        with open(t_budget, "w", encoding="utf-8") as fh:
            fh.write(",".join(BUDGET_HEADER) + "\n")
            fh.writelines(f"{name},{','.join(repr(float(v)) for v in result.budget[name])}\n"
                          for name in cov.SOURCES + ("total",))
        from .record.budget import write_analysis

        write_analysis(Path(str(tmps[3])), result.t, result.covariance, result.montecarlo)
        if len(tmps) > 4:
            _plot(Path(str(tmps[4])), result)
    print(_table(result))
    return targets
