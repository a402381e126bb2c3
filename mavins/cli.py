"""The ``mavins`` command line: parses options and calls in, nothing more.

Heavy modules (numba kernels, pymavlink, rerun) are imported only inside the
subcommand that needs them, so ``mavins --help`` answers at once.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, Sequence

EXIT_USAGE = 2


def _positive_int(lo: int, hi: int | None = None) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{v} is outside {lo}..{hi if hi is not None else 'inf'}")
        return v

    return parse


def _add_nav(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "nav",
        help="strapdown solution from IMU files (offline)",
        description=(
            "Integrate an IMU file (increments or rates, CONVENTIONS.md columns) from an initial "
            "state and write the navigation solution, one row per attitude update at the time of "
            "its last sample. Trailing samples that do not fill an update are not used."
        ),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("imu", type=Path, metavar="IMU.csv", help="increments (t,dtheta_*,dv_*) or rates (t,gyro_*,acc_*)")
    p.add_argument("--init", type=Path, required=True, metavar="INIT.json", help="initial state JSON")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="NAV.csv", help="solution CSV to write")
    p.add_argument("--input", choices=("increments", "rates"), default="increments", help="what the IMU file holds")
    p.add_argument(
        "--imu-rates",
        choices=("averaged", "sampled"),
        default="averaged",
        help="with --input rates: each row is the mean over the interval ending at its t, or an instantaneous sample",
    )
    p.add_argument(
        "--samples",
        type=_positive_int(1, 6),
        default=2,
        metavar="N",
        help="samples per attitude/velocity update, 1..6; N>=2 applies N-sample coning and sculling",
    )
    p.add_argument("--no-coning", action="store_true", help="keep N-sample updates but drop coning and sculling corrections")
    p.add_argument("--attitude", choices=("quaternion", "dcm"), default="quaternion", help="attitude representation")
    p.add_argument(
        "--order", choices=("1", "2", "3", "4", "exact"), default="exact", help="series order of the attitude update"
    )
    p.add_argument(
        "--earth", choices=("wgs84", "none"), default="wgs84", help="none = non-rotating laboratory frame, constant gravity"
    )
    p.add_argument(
        "--orthonormalize-every",
        type=_positive_int(0),
        default=1,
        metavar="K",
        help="with --attitude dcm, re-orthonormalise every K updates (0 = never)",
    )
    p.add_argument(
        "--vertical", choices=("free", "hold"), default="free", help="hold = keep height and vertical velocity at start values"
    )
    p.add_argument(
        "--position",
        choices=("rectangular", "trapezoidal", "simpson"),
        default="trapezoidal",
        help="integration rule of the position update",
    )
    p.add_argument(
        "--l-every",
        type=_positive_int(1),
        default=1,
        metavar="M",
        help="attitude updates per slow (l) cycle: Earth rate, transport rate, gravity",
    )
    p.add_argument("--timing", action="store_true", help="print read/compute/write seconds to stderr")
    p.set_defaults(func=_cmd_nav)


def _cmd_nav(args: argparse.Namespace) -> int:
    from . import files
    from .nav import NavOptions, run_nav

    opts = NavOptions(
        input=args.input,
        samples=args.samples,
        no_coning=args.no_coning,
        attitude=args.attitude,
        order=args.order,
        earth=args.earth,
        orthonormalize_every=args.orthonormalize_every,
        vertical=args.vertical,
        imu_rates=args.imu_rates,
        position=args.position,
        l_every=args.l_every,
        timing=args.timing,
    )
    try:
        rows = run_nav(args.imu, args.init, args.output, opts)
    except files.DataFileError as exc:
        print(f"mavins nav: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    print(f"mavins nav: wrote {rows} solution rows to {args.output}", file=sys.stderr)
    return 0


def _add_sim(sub: argparse._SubParsersAction) -> None:
    from sim import SCENARIO_DIR

    names = sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))
    p = sub.add_parser(
        "sim",
        help="IMU simulator: write files or stream MAVLink like an autopilot",
        description=(
            "Simulate a scenario with exact IMU increments and ground truth. Write the contract's "
            "files (imu.csv, imu_rates.csv, truth.csv, init.json) with -o DIR, or stream it over "
            "MAVLink with --stream URL (HEARTBEAT, HIGHRES_IMU or RAW_IMU, SIM_STATE truth, "
            "GPS_RAW_INT, SCALED_PRESSURE)."
        ),
        epilog="built-in scenarios: " + ", ".join(names) + ". A path to your own .toml works too "
        "(see docs/simulator.md).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("scenario", metavar="SCENARIO", help="built-in name or path to a scenario .toml")
    out = p.add_mutually_exclusive_group(required=True)
    out.add_argument("-o", "--output", type=Path, metavar="DIR", help="write the files into DIR")
    out.add_argument("--stream", metavar="URL", help="stream over MAVLink to a pymavlink URL, e.g. udpout:127.0.0.1:14551")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="seconds to simulate (default: the scenario's)")
    p.add_argument("--rate", type=float, default=None, metavar="HZ", help="IMU sample rate (default: the scenario's)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the sensor errors")
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
    p.add_argument("--speed", default="1", metavar="X|max", help="streaming pace: 1 = real time, 10 = ten times, max = as fast as possible")
    p.add_argument("--sysid", type=int, default=1, help="system id of the simulated autopilot")
    p.add_argument("--imus", type=_positive_int(1, 3), default=1, metavar="N",
                   help="IMUs to stream (1..3): extras as HIGHRES_IMU id 1, 2, or with --msg raw as SCALED_IMU2/3")
    p.set_defaults(func=_cmd_sim)


def _cmd_sim(args: argparse.Namespace) -> int:
    from sim.scenarios import ScenarioError, load

    try:
        scenario = load(args.scenario)
    except ScenarioError as exc:
        print(f"mavins sim: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    speed: float | None
    if args.speed == "max":
        speed = None
    else:
        try:
            speed = float(args.speed)
        except ValueError:
            print(f"mavins sim: error: --speed takes a number or 'max', got {args.speed!r}", file=sys.stderr)
            return EXIT_USAGE
        if speed <= 0:
            print("mavins sim: error: --speed must be positive", file=sys.stderr)
            return EXIT_USAGE
    from sim.generate import generate, write

    try:
        run = generate(scenario, duration=args.duration, rate=args.rate, seed=args.seed, grade=args.grade,
                       usec_grid=args.stream is not None)
    except ValueError as exc:
        print(f"mavins sim: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.output is not None:
        paths = write(run, args.output)
        print(f"mavins sim: {scenario.name}: {len(run.t)} samples at {run.rate:g} Hz, grade {run.grade}: "
              + ", ".join(str(p) for p in paths), file=sys.stderr)
        return 0
    from sim.stream import StreamOptions, stream

    stats = stream(run, args.stream, StreamOptions(msg=args.msg, imu_rates=args.imu_rates, speed=speed, sysid=args.sysid,
                                                  imus=args.imus, seed=args.seed))
    print(f"mavins sim: streamed {stats.imu_messages} IMU messages to {args.stream}", file=sys.stderr)
    return 0


def _nav_options(p: argparse.ArgumentParser) -> None:
    """Navigation options shared by run, replay (CONVENTIONS.md ``mavins run``)."""
    g = p.add_argument_group("navigation")
    g.add_argument("--lat", type=float, metavar="DEG", help="initial latitude (else the vehicle's first good GPS fix)")
    g.add_argument("--lon", type=float, metavar="DEG", help="initial longitude")
    g.add_argument("--alt", type=float, metavar="M", help="initial ellipsoidal height")
    g.add_argument("--heading", default="auto", metavar="DEG|SOURCE",
                   help="initial yaw in degrees, or a source: vehicle (its ATTITUDE), mag (magnetometer), "
                        "gyrocompass (navigation-grade gyros), auto (vehicle, else mag, else gyrocompass)")
    g.add_argument("--declination", type=float, default=0.0, metavar="DEG", help="magnetic declination for --heading mag")
    g.add_argument("--gyro-bias", choices=("estimate", "none"), default="estimate",
                   help="estimate = remove the mean gyro minus Earth rate of the static window (not with gyrocompass)")
    g.add_argument("--align", type=float, default=10.0, metavar="S", help="static coarse alignment window (sensor time)")
    g.add_argument("--imu-rates", choices=("averaged", "sampled"), default="averaged",
                   help="IMU rates are interval averages (PX4 HIGHRES_IMU) or instantaneous samples")
    g.add_argument("--samples", type=_positive_int(1, 6), default=2, metavar="N", help="samples per attitude update (1..6)")
    g.add_argument("--rate", type=float, default=50.0, metavar="HZ", help="output rate in sensor time")
    g.add_argument("--imu", default="auto", choices=("auto", "highres", "raw", "scaled", "scaled2", "scaled3"),
                   help="IMU message to navigate on (auto = the first one seen)")
    g.add_argument("--imu-id", type=int, default=None, metavar="ID", help="id field of HIGHRES_IMU/RAW_IMU to use")
    g.add_argument("--raw-acc-scale", type=float, default=9.80665e-3, metavar="M_S2",
                   help="RAW_IMU accelerometer scale, m/s^2 per count (ArduPilot: 1 mG)")
    g.add_argument("--raw-gyro-scale", type=float, default=1e-3, metavar="RAD_S",
                   help="RAW_IMU gyro scale, rad/s per count (ArduPilot: 1 mrad/s)")
    g.add_argument("--target-system", type=int, default=None, metavar="SYSID", help="accept IMU data only from this system")
    g.add_argument("--max-accel", type=float, default=16 * 9.80665, metavar="M_S2", help="accelerometer range")
    g.add_argument("--max-gyro", type=float, default=2000.0, metavar="DEG_S", help="gyro range")
    g.add_argument("--max-gap", type=float, default=1.0, metavar="S",
                   help="a longer gap in sensor time is not integrated and marks the solution degraded")
    g.add_argument("--config", type=Path, metavar="FILE.toml", help="TOML file with any of these options (command line wins)")


_IMU_NAMES = {"auto": "auto", "highres": "HIGHRES_IMU", "raw": "RAW_IMU", "scaled": "SCALED_IMU",
              "scaled2": "SCALED_IMU2", "scaled3": "SCALED_IMU3"}


def _apply_config(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Fill options from --config where the command line left the default."""
    path = getattr(args, "config", None)
    if path is None:
        return
    import tomllib

    try:
        doc = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        parser.error(f"--config {path}: {exc}")
    for key, value in doc.items():
        dest = key.replace("-", "_")
        if not hasattr(args, dest):
            parser.error(f"--config {path}: unknown option {key!r}")
        if getattr(args, dest) == parser.get_default(dest):
            setattr(args, dest, value)


def _engine_config(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from .engine import EngineConfig

    heading: float | str = args.heading
    try:
        heading = float(args.heading)
    except (TypeError, ValueError):
        pass
    return EngineConfig(lat=args.lat, lon=args.lon, alt=args.alt, heading=heading, declination=args.declination,
                        align=args.align, imu_rates=args.imu_rates, rate=args.rate, samples=args.samples,
                        gyro_bias=args.gyro_bias, max_gap=args.max_gap)


def _ingest_config(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from .ingest import IngestConfig

    import math

    return IngestConfig(message=_IMU_NAMES[args.imu], imu_id=args.imu_id, target_system=args.target_system,
                        raw_acc_scale=args.raw_acc_scale, raw_gyro_scale=args.raw_gyro_scale,
                        max_accel=args.max_accel, max_gyro=math.radians(args.max_gyro))


def _add_run(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="the MAVLink INS service",
        description="Connect to a MAVLink stream, align on the IMU, navigate on sensor time and publish "
        "ATTITUDE, ATTITUDE_QUATERNION, LOCAL_POSITION_NED, GLOBAL_POSITION_INT, ODOMETRY and HEARTBEAT. "
        "Stops cleanly on Ctrl-C or SIGTERM.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--master", default="udpin:127.0.0.1:14551", metavar="URL",
                   help="pymavlink connection string to read (udpin:/udpout:/tcp:/serial device)")
    p.add_argument("--out", action="append", default=[], metavar="URL", help="extra output link (repeatable)")
    p.add_argument("--sysid", type=int, default=None, help="our system id (default: the vehicle's)")
    p.add_argument("--compid", type=int, default=191, help="our component id (191 = onboard computer)")
    p.add_argument("--geoid-height", type=float, default=0.0, metavar="M",
                   help="geoid undulation: GLOBAL_POSITION_INT alt = ellipsoidal height - this")
    p.add_argument("--tlog", type=Path, metavar="FILE", help="record every received message (replayable)")
    p.add_argument("-o", "--output", type=Path, metavar="NAV.csv", help="also write each output set as a solution row")
    p.add_argument("--request-imu", type=float, metavar="HZ", help="ask the autopilot for HIGHRES_IMU at HZ")
    p.add_argument("--rerun", type=Path, metavar="FILE.rrd", help="record to a Rerun file")
    p.add_argument("--rerun-serve", action="store_true", help="serve the recording for a live Rerun viewer")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds of wall time")
    p.add_argument("--signing-key", type=Path, metavar="FILE",
                   help="MAVLink 2 signing key (32 bytes or 64 hex digits, mode 600): input must be signed, "
                        "output is signed (see 'mavins key')")
    p.add_argument("--peer-timeout", type=float, default=10.0, metavar="S",
                   help="stop sending to a listening link's peer after S seconds of silence")
    p.add_argument("--max-peers", type=int, default=8, metavar="N", help="most peers a listening link sends to")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    _nav_options(p)
    p.set_defaults(func=_cmd_run, parser=p)


def _setup_logging(verbose: bool) -> None:
    import logging

    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO, format="%(asctime)s %(levelname)s %(message)s")


def _cmd_run(args: argparse.Namespace) -> int:
    import signal
    import threading

    _apply_config(args, args.parser)
    _setup_logging(args.verbose)
    from .publish import PublishConfig
    from .service import Service, ServiceConfig

    try:
        engine_cfg = _engine_config(args)
    except ValueError as exc:
        print(f"mavins run: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    from .link import PeerPolicy
    from .signing import KeyFileError, load_key

    key = state = None
    if args.signing_key is not None:
        try:
            key = load_key(args.signing_key)
        except KeyFileError as exc:
            print(f"mavins run: error: {exc}", file=sys.stderr)
            return EXIT_USAGE
        state = args.signing_key.with_name(args.signing_key.name + ".timestamp")
    ingest_cfg = _ingest_config(args)
    cfg = ServiceConfig(master=args.master, outs=args.out, sysid=args.sysid, compid=args.compid, tlog=args.tlog,
                        solution=args.output, request_imu=args.request_imu, signing_key=key, signing_state=state,
                        peers=PeerPolicy(timeout=args.peer_timeout, max_peers=args.max_peers),
                        publish=PublishConfig(geoid_height=args.geoid_height))
    try:
        svc = Service(engine_cfg, ingest_cfg, cfg)
    except OSError as exc:
        print(f"mavins run: error: cannot open a link: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.rerun or args.rerun_serve:
        from .record import Recorder

        rec = Recorder(args.rerun, serve=args.rerun_serve, app="mavins")
        svc.attach_recorder(rec)
        if rec.url:
            print(f"mavins run: live recording at {rec.url} (open it with: rerun {rec.url})", file=sys.stderr)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    if args.duration:
        timer = threading.Timer(args.duration, stop.set)
        timer.daemon = True  # a signal may end the run first; never wait for the timer
        timer.start()
    print(f"mavins run: listening on {args.master}", file=sys.stderr)
    summary = svc.run(stop)
    for line in summary.lines():
        print(f"mavins run: {line}", file=sys.stderr)
    return 0


def _add_replay(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay",
        help="run the service pipeline over a log (.tlog, ArduPilot .bin, PX4 .ulg)",
        description="Replay a recorded log through the same pipeline as 'mavins run', as fast as possible, "
        "writing each output set as a solution row (same results as live).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("log", type=Path, metavar="LOG", help=".tlog, .bin or .ulg")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="NAV.csv", help="solution CSV to write")
    p.add_argument("--rerun", type=Path, metavar="FILE.rrd", help="also write a Rerun recording")
    _nav_options(p)
    p.set_defaults(func=_cmd_replay, parser=p)


def _cmd_replay(args: argparse.Namespace) -> int:
    _apply_config(args, args.parser)
    from .files import DataFileError
    from .replay import replay

    try:
        engine_cfg = _engine_config(args)
        recorder = None
        if args.rerun:
            from .record import Recorder

            recorder = Recorder(args.rerun, serve=False, app="mavins-replay", live=False)
        res = replay(args.log, engine_cfg, _ingest_config(args), args.output, recorder=recorder)
    except (DataFileError, ValueError) as exc:
        print(f"mavins replay: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    eng = res.pipeline.engine
    print(f"mavins replay: {res.messages} messages, {res.outputs} solution rows to {args.output}; "
          f"final state {eng.state.value}" + (f", heading from {eng.heading_used}" if eng.heading_used else ""),
          file=sys.stderr)
    return 0


def _add_demo(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="loopback simulation: simulator -> UDP -> service -> UDP, recorded to Rerun",
        description="Stream a built-in scenario from the simulator over UDP into the service, collect what it "
        "publishes, record everything to Rerun and print the errors against the simulator's truth.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--scenario", default="flight", help="built-in scenario or .toml path")
    p.add_argument("--duration", type=float, default=120.0, metavar="S", help="simulated seconds")
    p.add_argument("--speed", default="5", metavar="X|max", help="pace: 1 = real time")
    p.add_argument("--grade", default="industrial", choices=("ideal", "consumer", "industrial", "tactical", "navigation"))
    p.add_argument("--heading", default="vehicle", help="heading source for the alignment")
    p.add_argument("--rerun", type=Path, default=Path("mavins-demo.rrd"), metavar="FILE.rrd", help="recording to write")
    p.add_argument("--rerun-serve", action="store_true", help="also serve the recording to a live viewer")
    p.add_argument("--no-rerun", action="store_true", help="do not record")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_cmd_demo)


def _cmd_demo(args: argparse.Namespace) -> int:
    import threading

    _setup_logging(False)
    from .demo import run_demo

    speed = None if args.speed == "max" else float(args.speed)
    stop = threading.Event()
    try:
        report = run_demo(args.scenario, args.duration, speed, args.grade, args.heading,
                          None if args.no_rerun else args.rerun, args.rerun_serve, args.seed, stop)
    except KeyboardInterrupt:
        stop.set()
        print("mavins demo: interrupted", file=sys.stderr)
        return 130
    for line in report.lines():
        print(f"mavins demo: {line}")
    if not args.no_rerun:
        print(f"mavins demo: recording written to {args.rerun} (open it with: rerun {args.rerun})")
    return 0


def _add_key(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "key",
        help="make a MAVLink 2 signing key file",
        description="Write a 32-byte signing key (as 64 hex digits, file mode 600). With --passphrase the key is "
        "SHA-256 of the passphrase, the same key MAVProxy's 'signing setup PASSPHRASE' uses; without, a random key.",
    )
    p.add_argument("file", type=Path, metavar="FILE")
    p.add_argument("--passphrase", help="derive the key from a passphrase (MAVProxy's convention)")
    p.add_argument("--force", action="store_true", help="overwrite an existing file")
    p.set_defaults(func=_cmd_key)


def _cmd_key(args: argparse.Namespace) -> int:
    import os
    import secrets

    from .signing import key_from_passphrase

    if args.file.exists() and not args.force:
        print(f"mavins key: error: {args.file} exists (use --force to overwrite)", file=sys.stderr)
        return EXIT_USAGE
    try:
        key = key_from_passphrase(args.passphrase) if args.passphrase else secrets.token_bytes(32)
    except UnicodeEncodeError:
        print("mavins key: error: the passphrase must be ASCII (MAVProxy hashes its ASCII bytes)", file=sys.stderr)
        return EXIT_USAGE
    fd = os.open(args.file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    os.fchmod(fd, 0o600)  # an existing file keeps its old mode through O_TRUNC: close it before writing
    with os.fdopen(fd, "w") as fh:
        fh.write(key.hex() + "\n")
    print(f"mavins key: wrote {args.file} (mode 600)", file=sys.stderr)
    return 0


def _add_review(sub: argparse._SubParsersAction) -> None:
    from .review import DESCRIPTION, add_arguments, run

    p = sub.add_parser("review", help="render a Rerun recording to PNG, headless", description=DESCRIPTION)
    add_arguments(p)
    p.set_defaults(func=lambda a: run(a, "mavins review"))


def build_parser() -> argparse.ArgumentParser:
    """The full ``mavins`` parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="mavins",
        description="MAVLink inertial navigation: strapdown INS service, offline tools and IMU simulator.",
        epilog="Run 'mavins COMMAND --help' for the options of a command.",
    )
    parser.add_argument("--version", action="version", version=f"mavins {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_nav(sub)
    for add in _EXTRA_COMMANDS:
        add(sub)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("mavins")
    except PackageNotFoundError:
        return "unknown"


_EXTRA_COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [_add_sim, _add_run, _add_replay, _add_demo, _add_review, _add_key]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mavins`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        print("mavins: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
