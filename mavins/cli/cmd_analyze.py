"""``mavins analyze``: error budget by covariance analysis and Monte Carlo."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .options import EXIT_USAGE, GRADES, POSITIVE, _imu_spec, _positive_int, _real, _scenario_error


def _add_analyze(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "analyze",
        help="error budget of a scenario: covariance analysis and Monte Carlo (docs/analysis.md)",
        description=(
            "How far does the free-inertial solution drift on this scenario with this IMU? Propagates the "
            "linear error model (attitude, velocity, position, biases, scale factors, misalignments) along "
            "the scenario's true trajectory, each error source alone and together, and runs N strapdown "
            "solutions on the scenario's data corrupted with random sensor errors drawn from the same "
            "specification. Every run starts from the true initial state. Writes DIR/covariance.csv "
            "(1-sigma), DIR/montecarlo.csv (sample sigma of the runs), columns t, sigma_n,sigma_e,sigma_d (m), "
            "sigma_vn,sigma_ve,sigma_vd (m/s), sigma_att_n,sigma_att_e,sigma_att_d (deg); DIR/budget.csv "
            "(source,pos_h,pos_v,vel_h,att_level,att_yaw at the end: each source alone); DIR/analysis.png "
            "when matplotlib is installed; and prints the budget."
        ),
        epilog="Runs go to all local cores (--jobs) or, with --cluster tcp://HOST:8786, to a running Dask "
        "scheduler whose workers have mavins installed (pip install 'mavins[cluster]').")
    p.add_argument("scenario", metavar="SCENARIO", help="built-in scenario name or path to a scenario .toml")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="DIR", help="write the files into DIR")
    p.add_argument("--runs", type=_positive_int(2, 1_000_000), default=100, metavar="N", help="Monte Carlo runs")
    spec = p.add_mutually_exclusive_group()
    spec.add_argument("--grade", choices=GRADES, default="industrial",
                      help="IMU error model: a grade's figures (scale factor and misalignment taken as 1-sigma)")
    spec.add_argument("--imu-spec", type=Path, metavar="SPEC.toml",
                      help="IMU error model from a TOML file: the aided-navigation keys plus gyro_scale, accel_scale "
                      "(ppm), gyro_misalignment, accel_misalignment (arcsec), all 1-sigma (docs/conventions.md)")
    p.add_argument("--jobs", type=_positive_int(1, 4096), default=None, metavar="J",
                   help="local worker processes for the Monte Carlo (default: all cores; 1 = in this process)")
    p.add_argument("--cluster", metavar="ADDRESS", default=None,
                   help="submit the Monte Carlo runs to this Dask distributed scheduler instead of local cores")
    p.add_argument("--vertical", choices=("free", "hold"), default="free",
                   help="hold = height and vertical velocity kept at their true values (no unstable vertical channel)")
    p.add_argument("--duration", type=_real(**POSITIVE), default=None, metavar="S",
                   help="seconds to simulate (default: the scenario's)")
    p.add_argument("--rate", type=_real(0.0, 1e6, above=True), default=None, metavar="HZ",
                   help="IMU sample rate (default: the scenario's)")
    p.add_argument("--seed", type=_positive_int(0), default=0, metavar="N",
                   help="random seed of the Monte Carlo (run i uses the seed sequence (N, i))")
    p.set_defaults(func=_cmd_analyze)


def _cmd_analyze(args: argparse.Namespace) -> int:
    import os

    # The runs are parallel across processes: one BLAS thread each (set before numpy loads it), else the
    # small matrix products of the sensor error model contend for the cores (70 ms instead of 2 ms).
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    from sim.scenarios import ScenarioError, load

    try:
        scenario = load(args.scenario)
    except (ScenarioError, UnicodeDecodeError, OSError) as exc:
        print(f"mavins analyze: error: {_scenario_error(args.scenario, exc)}", file=sys.stderr)
        return EXIT_USAGE
    from sim.generate import check_size

    from ..analysis import AnalysisOptions, run_analyze
    from ..core import covariance
    from ..common.parallel import JobError

    try:
        keys = _imu_spec(args, covariance.ANALYSIS_KEYS)
        spec = covariance.spec_from_grade(keys) if isinstance(keys, str) else covariance.spec_from_keys(keys)
        check_size(scenario, duration=args.duration, rate=args.rate)
        opts = AnalysisOptions(runs=args.runs, jobs=args.jobs, cluster=args.cluster, vertical=args.vertical,
                               duration=args.duration, rate=args.rate, seed=args.seed)
        paths = run_analyze(scenario, spec, args.output, opts)
    except (ValueError, OSError, ImportError, JobError) as exc:  # ScenarioError, DataFileError, ResourceError: ValueError
        text = f"{exc.filename}: {exc.strerror}" if isinstance(exc, OSError) and exc.filename else str(exc)
        print(f"mavins analyze: error: {text}", file=sys.stderr)
        return EXIT_USAGE
    print(f"mavins analyze: {scenario.name}: {args.runs} runs: " + ", ".join(str(p) for p in paths), file=sys.stderr)
    return 0
