"""``mavins sim``: the IMU simulator's files or MAVLink stream."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from .options import (
    EXIT_USAGE, POSITIVE, SYSID, _Date, _Disturbance, _Outage, _Speed, _Vec3, _positive_int, _real,
    _scenario_error, _subparser
)


def _add_sim(sub: argparse._SubParsersAction) -> None:
    from sim import SCENARIO_DIR

    names = sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))
    p = _subparser(sub, "sim", "IMU simulator: write files or stream MAVLink like an autopilot",
                   "Simulate a scenario with exact IMU increments and ground truth. Write the contract's "
                   "files (imu.csv, imu_rates.csv, truth.csv, init.json) with -o DIR, or stream it over "
                   "MAVLink with --stream URL (HEARTBEAT, HIGHRES_IMU or RAW_IMU, SIM_STATE truth, "
                   "GPS_RAW_INT, SCALED_PRESSURE).",
                   epilog="built-in scenarios: " + ", ".join(names) + ". A path to your own .toml works too "
                          "(see docs/simulator.md).")
    p.add_argument("scenario", metavar="SCENARIO", help="built-in name or path to a scenario .toml")
    out = p.add_mutually_exclusive_group(required=True)
    out.add_argument("-o", "--output", type=Path, metavar="DIR", help="write the files into DIR")
    out.add_argument("--stream", metavar="URL", help="stream over MAVLink to a pymavlink URL, e.g. udpout:127.0.0.1:14551")
    p.add_argument("--duration", type=_real(**POSITIVE), default=None, metavar="S",
                   help="seconds to simulate (default: the scenario's)")
    p.add_argument("--rate", type=_real(0.0, 1e6, above=True), default=None, metavar="HZ",
                   help="IMU sample rate (default: the scenario's)")
    p.add_argument("--seed", type=_positive_int(0), default=0, metavar="N", help="random seed of the sensor errors")
    p.add_argument(
        "--grade",
        choices=("ideal", "consumer", "industrial", "tactical", "navigation"),
        default=None,
        help="sensor error preset; ideal = no errors (default: the scenario's, else ideal)",
    )
    p.add_argument("--msg", choices=("highres", "raw"), default="highres", help="IMU message when streaming")
    p.add_argument(
        "--imu-rates",
        choices=("averaged", "sampled"),
        default="averaged",
        help="HIGHRES_IMU carries interval averages (like PX4) or instantaneous samples",
    )
    p.add_argument("--speed", type=_Speed(), default="1", metavar="X|max",
                   help="streaming pace: 1 = real time, 10 = ten times, max = as fast as possible")
    p.add_argument("--sysid", type=_positive_int(*SYSID), default=1, metavar="ID", help="system id of the simulated autopilot")
    p.add_argument("--gnss-rate", type=_real(0.0, 100.0), default=None, metavar="HZ",
                   help="GNSS fixes per second written to gnss.csv (with baro.csv; default 1) or streamed as "
                        "GPS_RAW_INT (default 5); 0 = none (docs/simulator.md)")
    p.add_argument("--gnss-outage", type=_Outage(), metavar="START,END",
                   help="no GNSS fix between these sensor times (s), in files and when streaming")
    p.add_argument("--gnss-latency", type=_real(0.0, 1000.0), default=0.0, metavar="MS",
                   help="with --stream: each GPS_RAW_INT is sent this long after its fix was measured and stamped "
                        "when sent, as an autopilot stamps a receiver's late output (test run's --gnss-delay)")
    p.add_argument("--gnss-heading", type=_real(0.0, 30.0), default=0.0, metavar="SIGMA_DEG",
                   help="with --stream: GPS_RAW_INT carries a dual-antenna heading (yaw, hdg_acc), the vehicle's "
                        "true yaw plus this 1-sigma noise (deg; default 0: none)")
    p.add_argument("--mag-rate", type=_real(0.0, 100.0), default=0.0, metavar="HZ",
                   help="magnetometer samples per second written to mag.csv, or streamed in HIGHRES_IMU (0 = none; "
                        "the World Magnetic Model's field at the start on --date, 0.3 uT noise; docs/simulator.md)")
    p.add_argument("--wheel-rate", type=_real(0.0, 100.0), metavar="HZ",
                   help="wheel odometer speeds per second written to wheel.csv (t,speed,sigma: the forward speed with a "
                        "1 %% scale-factor error and 0.05 m/s noise), or with --stream WHEEL_DISTANCE messages (one "
                        "wheel: the distance travelled, 1 %% long); 0 = none; default 10 for the car scenario, else 0")
    p.add_argument("--vision-rate", type=_real(0.0, 200.0), default=0.0, metavar="HZ",
                   help="with --stream: a camera's ODOMETRY per second (pose and body velocity in its own frame, "
                        "heading 30 deg, origin at the start; 5 cm, 1 deg, 5 cm/s noise) and GPS_GLOBAL_ORIGIN with "
                        "each HEARTBEAT (0 = none; docs/simulator.md)")
    p.add_argument("--date", type=_Date(), default=None, metavar="YYYY-MM-DD",
                   help="the date of the simulated magnetic field (or a decimal year); default: today's")
    p.add_argument("--mag-hard-iron", type=_Vec3(), default="0,0,0", metavar="X,Y,Z",
                   help="the simulated magnetometer's hard iron, body FRD (gauss; 1 gauss = 100 uT)")
    p.add_argument("--mag-disturbance", type=_Disturbance(), action="append", metavar="START,END,N,E,D",
                   help="a local field (gauss, NED: steel, a power line) added to the Earth's between these sensor "
                        "times (s); repeatable")
    p.add_argument("--imus", type=_positive_int(1, 3), default=1, metavar="N",
                   help="IMUs (1..3): extras written as imu1.csv, imu2.csv, streamed as HIGHRES_IMU id 1, 2 "
                        "(with --msg raw as SCALED_IMU2/3); scenario [[faults]] name them (docs/redundancy.md)")
    p.set_defaults(func=_cmd_sim)


def _cmd_sim(args: argparse.Namespace) -> int:
    from ..common import files
    from sim.scenarios import ScenarioError, load

    try:
        scenario = load(args.scenario)
    except (ScenarioError, UnicodeDecodeError, OSError) as exc:
        print(f"mavins sim: error: {_scenario_error(args.scenario, exc)}", file=sys.stderr)
        return EXIT_USAGE
    speed = None if args.speed == "max" else float(args.speed)
    from sim.generate import FILE_NAMES, check_size, extra_names, generate, generate_chunks, write

    try:
        if args.output is not None:
            if args.output.exists() and not args.output.is_dir():
                raise files.DataFileError(f"{args.output}: -o names a file, expected a directory to write into")
            files.check_outputs({f"-o {args.output}/{n}": args.output / n for n in FILE_NAMES + extra_names(args.imus)},
                                {"SCENARIO": Path(scenario.source)})
        check_size(scenario, duration=args.duration, rate=args.rate, outdir=args.output)
        if args.stream is not None:  # made in pieces while it streams: the first message leaves at once
            pieces = generate_chunks(scenario, duration=args.duration, rate=args.rate, seed=args.seed,
                                     grade=args.grade, usec_grid=True, imus=args.imus)
            run = next(pieces)
        else:
            run = generate(scenario, duration=args.duration, rate=args.rate, seed=args.seed, grade=args.grade,
                           imus=args.imus)
        if args.output is not None:
            from sim.aiding import BaroConfig, GnssConfig, MagConfig, WheelConfig, simulate_aiding

            outages = (tuple(args.gnss_outage),) if args.gnss_outage else ()
            gnss_rate = 1.0 if args.gnss_rate is None else args.gnss_rate
            gnss_on = gnss_rate > 0
            wheel_rate = _wheel_rate(args, scenario)
            aiding = simulate_aiding(run, GnssConfig(rate=gnss_rate, outages=outages) if gnss_on else None,
                                     BaroConfig() if gnss_on else None,
                                     _sim_mag(MagConfig, run, args) if args.mag_rate > 0 else None,
                                     WheelConfig(rate=wheel_rate) if wheel_rate > 0 else None) \
                if gnss_on or args.mag_rate > 0 or wheel_rate > 0 else None
            paths = write(run, args.output, aiding)
    except (ValueError, OSError) as exc:  # ScenarioError, DataFileError and ResourceError are ValueErrors
        text = f"{exc.filename}: {exc.strerror}" if isinstance(exc, OSError) and exc.filename else str(exc)
        print(f"mavins sim: error: {text}", file=sys.stderr)
        return EXIT_USAGE
    if args.output is not None:
        print(f"mavins sim: {scenario.name}: {len(run.t)} samples at {run.rate:g} Hz, grade {run.grade}: "
              + ", ".join(str(p) for p in paths), file=sys.stderr)
        return 0
    import itertools

    from sim.aiding import MagConfig
    from sim.generate import run_duration
    from sim.stream import StreamOptions, stream

    from ..common.progress import Progress

    outages = (tuple(args.gnss_outage),) if args.gnss_outage else ()
    try:
        with Progress("stream", run_duration(scenario, args.duration), "s") as bar:
            stats = stream(itertools.chain([run], pieces), args.stream,
                           StreamOptions(msg=args.msg, imu_rates=args.imu_rates, speed=speed, sysid=args.sysid,
                                         imus=args.imus, seed=args.seed, gnss_outages=outages,
                                         gnss_latency=args.gnss_latency / 1000.0,
                                         gnss_heading=math.radians(args.gnss_heading), mag_rate=args.mag_rate,
                                         wheel_rate=_wheel_rate(args, scenario), vision_rate=args.vision_rate,
                                         **({} if args.gnss_rate is None else {"gps_rate": args.gnss_rate}),
                                         mag=_sim_mag(MagConfig, run, args)),
                           progress=bar)
    except (ValueError, OSError) as exc:  # a piece that could not be made, or the link
        print(f"mavins sim: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    print(f"mavins sim: streamed {stats.imu_messages} IMU messages to {args.stream}", file=sys.stderr)
    return 0


def _wheel_rate(args: argparse.Namespace, scenario: object) -> float:
    """--wheel-rate, by default 10 Hz for the car scenario and none for the others."""
    if args.wheel_rate is not None:
        return float(args.wheel_rate)
    return 10.0 if getattr(scenario, "name", "") == "car" else 0.0


def _sim_mag(mag_config: type, run: object, args: argparse.Namespace) -> object:
    """The simulator's magnetometer: the World Magnetic Model's field at the scenario's start on
    ``--date`` (default today), at ``--mag-rate``."""
    from mavins.core.magmodel import this_year

    init = run.init()  # type: ignore[attr-defined]
    year = args.date if args.date is not None else this_year()
    uT = 100.0  # per gauss
    return mag_config.at(init.lat, init.lon, init.h, year, rate=args.mag_rate or 10.0,
                         hard_iron=tuple(uT * v for v in args.mag_hard_iron),
                         disturbances=tuple((d[0], d[1], tuple(uT * v for v in d[2:])) for d in args.mag_disturbance or ()))
