"""``mavins demo``: simulator -> service -> client over UDP, with a Rerun recording."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .options import (
    EXIT_USAGE, POSITIVE, _Aiding, _Heading, _Outage, _Speed, _positive_int, _real, _say, _scenario_error,
    _setup_logging, _subparser
)


def _add_demo(sub: argparse._SubParsersAction) -> None:
    p = _subparser(sub, "demo", "loopback simulation: simulator -> UDP -> service -> UDP, recorded to Rerun",
                   "Stream a built-in scenario from the simulator over UDP into the service, collect what it "
                   "publishes, record everything to Rerun and print the errors against the simulator's truth.")
    p.add_argument("--scenario", default="flight", help="built-in scenario or .toml path")
    p.add_argument("--duration", type=_real(**POSITIVE), default=120.0, metavar="S", help="simulated seconds")
    p.add_argument("--speed", type=_Speed(), default="5", metavar="X|max",
                   help="pace: 1 = real time; max = as fast as the service takes the messages (the stream waits "
                        "while more than 100 of them are not yet taken, so that none is lost)")
    p.add_argument("--grade", default="industrial", choices=("ideal", "consumer", "industrial", "tactical", "navigation"))
    p.add_argument("--heading", type=_Heading(), default="vehicle", metavar="DEG|SOURCE",
                   help="heading source for the alignment")
    p.add_argument("--rerun", type=Path, default=Path("mavins-demo.rrd"), metavar="FILE.rrd", help="recording to write")
    p.add_argument("--rerun-serve", action="store_true", help="also serve the recording to a live viewer")
    p.add_argument("--no-rerun", action="store_true", help="do not record")
    p.add_argument("--seed", type=_positive_int(0), default=0, metavar="N", help="random seed of the sensor errors")
    p.add_argument("--aiding", type=_Aiding(), default="gnss,baro", metavar="KINDS",
                   help="what the service aids with from the simulator's stream (gnss,baro,mag,zupt,nhc), or none")
    p.add_argument("--gnss-outage", type=_Outage(), default="60,90", metavar="START,END",
                   help="no GNSS between these sensor times (s)")
    p.add_argument("--no-outage", action="store_true", help="GNSS throughout")
    p.add_argument("--scale-factors", action="store_true",
                   help="the service's filter estimates the IMU's scale factors too; the report shows them beside "
                        "the simulated unit's")
    p.add_argument("--misalignment", action="store_true",
                   help="the service's filter estimates the IMU's misalignments too; the report shows them beside "
                        "the simulated unit's (arcsec)")
    p.set_defaults(func=_cmd_demo)


def _cmd_demo(args: argparse.Namespace) -> int:
    import threading

    from ..common.files import DataFileError, ResourceError, check_outputs
    from sim.generate import check_size
    from sim.scenarios import ScenarioError, load

    try:  # the scenario, the size of the run and the recording's path are checked before anything starts
        scenario = load(args.scenario)
        check_size(scenario, duration=args.duration, rate=None)
        check_outputs({"--rerun": None if args.no_rerun else args.rerun}, {"--scenario": Path(scenario.source)})
    except (ScenarioError, UnicodeDecodeError, OSError) as exc:
        print(f"mavins demo: error: {_scenario_error(args.scenario, exc)}", file=sys.stderr)
        return EXIT_USAGE
    except (DataFileError, ResourceError, ValueError) as exc:
        print(f"mavins demo: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    _setup_logging(False)
    from ..demo import run_demo

    speed = None if args.speed == "max" else float(args.speed)
    heading: float | str = args.heading
    try:
        heading = float(args.heading)
    except ValueError:
        pass
    stop = threading.Event()
    try:
        report = run_demo(args.scenario, args.duration, speed, args.grade, heading,  # type: ignore[arg-type]
                          None if args.no_rerun else args.rerun, args.rerun_serve, args.seed, stop,
                          aiding=args.aiding, gnss_outage=None if args.no_outage else args.gnss_outage,
                          scale_factors=args.scale_factors, misalignment=args.misalignment)
    except KeyboardInterrupt:
        stop.set()
        print("mavins demo: interrupted", file=sys.stderr)
        return 130
    _say("demo", report.lines(), sys.stdout)
    if not args.no_rerun:
        print(f"mavins demo: recording written to {args.rerun} (open it with: rerun {args.rerun})")
    return 0
