"""``mavins replay``: a log (.tlog, .ulg, .bin) through the live path."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .options import EXIT_USAGE, _apply_config, _engine_config, _ingest_config, _nav_options, _say, _subparser


def _add_replay(sub: argparse._SubParsersAction) -> None:
    p = _subparser(sub, "replay", "run the service pipeline over a log (.tlog, ArduPilot .bin, PX4 .ulg)",
                   "Replay a recorded log through the same pipeline as 'mavins run', as fast as possible, "
                   "writing each output set as a solution row (same results as live).")
    p.add_argument("log", type=Path, metavar="LOG", help=".tlog, .bin or .ulg")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="NAV.csv", help="solution CSV to write")
    p.add_argument("--rerun", type=Path, metavar="FILE.rrd", help="also write a Rerun recording")
    _nav_options(p)
    p.set_defaults(func=_cmd_replay, parser=p)


def _cmd_replay(args: argparse.Namespace) -> int:
    _apply_config(args, args.parser)
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
    if res.report is not None and res.report.damaged:
        print(f"mavins replay: warning: replayed what could be read: IMU samples from sensor time "
              f"{res.t_first:.3f} to {res.t_last:.3f} s", file=sys.stderr)
    lines = res.report.lines() if res.report is not None else ()
    _say("replay", (("" if ln.split(": ", 1)[-1].startswith("note:") else "warning: ") + ln for ln in lines))
    return 0
