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
        run = generate(scenario, duration=args.duration, rate=args.rate, seed=args.seed, grade=args.grade)
    except ValueError as exc:
        print(f"mavins sim: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.output is not None:
        paths = write(run, args.output)
        print(f"mavins sim: {scenario.name}: {len(run.t)} samples at {run.rate:g} Hz, grade {run.grade}: "
              + ", ".join(str(p) for p in paths), file=sys.stderr)
        return 0
    from sim.stream import StreamOptions, stream

    stats = stream(run, args.stream, StreamOptions(msg=args.msg, imu_rates=args.imu_rates, speed=speed, sysid=args.sysid))
    print(f"mavins sim: streamed {stats.imu_messages} IMU messages to {args.stream}", file=sys.stderr)
    return 0


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


_EXTRA_COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [_add_sim]


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
