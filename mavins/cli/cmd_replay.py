"""``mavins replay``: a log (.tlog, .ulg, .bin) through the live path."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .options import (
    EXIT_USAGE, _apply_config, _engine_config, _fleet_option_alone, _fleet_options, _ingest_config, _nav_options, _say,
    _smooth_option, _subparser,
)


def _add_replay(sub: argparse._SubParsersAction) -> None:
    p = _subparser(sub, "replay", "run the service pipeline over a log (.tlog, ArduPilot .bin, PX4 .ulg)",
                   "Replay a recorded log through the same pipeline as 'mavins run', as fast as possible, "
                   "writing each output set as a solution row (same results as live).")
    p.add_argument("log", type=Path, nargs="+", metavar="LOG", help=".tlog, .bin or .ulg (several with --each)")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="NAV.csv",
                   help="solution CSV to write (.parquet by the suffix); with --each a folder")
    p.add_argument("--rerun", type=Path, metavar="FILE.rrd", help="also write a Rerun recording")
    b = p.add_argument_group("fleet (many logs, each on its own)")
    b.add_argument("--each", action="store_true",
                   help="replay every LOG on its own: each solution goes to OUTPUT/<folder>/<name>.nav.csv and "
                        "OUTPUT/summary.csv gets one row per log (duration, samples, GNSS accepted/rejected, worst "
                        "test ratio, final sigmas, final state, error); a bad log is reported in its row and the "
                        "others go on (exit 2 if any failed)")
    _fleet_options(b)
    _nav_options(p)
    _smooth_option(p.add_argument_group("post-processing (docs/postprocessing.md)"))
    p.set_defaults(func=_cmd_replay, parser=p)


def _cmd_replay(args: argparse.Namespace) -> int:
    _apply_config(args, args.parser)
    if args.each:
        return _cmd_replay_each(args)
    refused = _fleet_option_alone(args, "replay", "several logs, each replayed on its own")
    if refused is not None:
        return refused
    if len(args.log) > 1:
        print(f"mavins replay: error: {len(args.log)} logs given: replay them with --each (one solution per log "
              "in the -o folder)", file=sys.stderr)
        return EXIT_USAGE
    args.log = args.log[0]
    if args.smooth and not args.aiding:
        print("mavins replay: error: --smooth smooths the aided solution: it cannot go with --aiding none",
              file=sys.stderr)
        return EXIT_USAGE
    from ..common.files import DataFileError, ResourceError, check_outputs
    from ..replay import replay

    try:
        check_outputs({"-o": args.output, "--rerun": args.rerun}, {"LOG": args.log, "--config": args.config})
        engine_cfg = _engine_config(args)
        res = replay(args.log, engine_cfg, _ingest_config(args), args.output, rerun=args.rerun)
    except (DataFileError, ResourceError, ValueError) as exc:
        print(f"mavins replay: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        print(f"mavins replay: error: {exc.filename or args.output}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    eng = res.pipeline.engine
    print(f"mavins replay: {res.messages} messages, {res.outputs} solution rows to {args.output}; "
          f"final state {eng.state.value}" + (f", heading from {eng.heading_used}" if eng.heading_used else ""),
          file=sys.stderr)
    if res.smoothed is not None:
        from ..core.smoother import described

        print(f"mavins replay: {described(*res.smoothed)}", file=sys.stderr)
    if res.report is not None and res.report.damaged:
        print(f"mavins replay: warning: replayed what could be read: IMU samples from sensor time "
              f"{res.t_first:.3f} to {res.t_last:.3f} s", file=sys.stderr)
    lines = res.report.lines() if res.report is not None else ()
    _say("replay", (("" if ln.split(": ", 1)[-1].startswith("note:") else "warning: ") + ln for ln in lines))
    return 0


def _cmd_replay_each(args: argparse.Namespace) -> int:
    """``mavins replay --each LOG... -o DIR``: every log on its own, then DIR/summary.csv; exit 2 if any failed."""
    from ..common.files import DataFileError, ResourceError
    from ..replay import replay_each

    if args.rerun is not None:
        print("mavins replay: error: --rerun records one log; with --each replay the log of interest on its own",
              file=sys.stderr)
        return EXIT_USAGE
    if args.output.exists() and not args.output.is_dir():
        print(f"mavins replay: error: {args.output}: with --each, -o names a folder", file=sys.stderr)
        return EXIT_USAGE
    try:
        outcomes, summary = replay_each(args.log, args.output, _engine_config(args), _ingest_config(args),
                                        jobs=args.jobs, cluster=args.cluster)
    except (DataFileError, ResourceError, ValueError, ImportError) as exc:
        print(f"mavins replay: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    failed = [o for o in outcomes if o.error]
    for o in outcomes:
        if o.error:
            print(f"mavins replay: error: {o.error}", file=sys.stderr)
        else:
            print(f"mavins replay: {o.solution_rows} solution rows to {o.output}; final state {o.state}",
                  file=sys.stderr)
    print(f"mavins replay: {len(outcomes) - len(failed)} of {len(outcomes)} logs replayed; summary in {summary}",
          file=sys.stderr)
    return EXIT_USAGE if failed else 0
