"""The command line's shared pieces: option types with their ranges, the option groups several
commands take (strapdown, filter, magnetic, service), and the settings they build (docs/conventions.md)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from collections.abc import Callable, Iterable, Sequence

from ..common.argcheck import checked


EXIT_USAGE = 2


class _Range:
    """An argparse type: a finite number within a range, checked at parse time.

    ``describe(metavar)`` is the range as --help shows it (every numeric option
    carries its range there, see :func:`_show_ranges`).
    """

    def __init__(self, kind: type, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False) -> None:
        self.kind, self.lo, self.hi, self.lo_open = kind, lo, hi, lo_open
        self.__name__ = "whole number" if kind is int else "number"  # argparse's "invalid <name> value"
        self.metavar = "X"

    def describe(self, metavar: str | None = None) -> str:
        m = metavar or self.metavar
        lo, hi = (f"{v:g}" if isinstance(v, float) else str(v) for v in (self.lo, self.hi))
        if self.lo is not None and self.hi is not None:
            return f"{lo} < {m} <= {hi}" if self.lo_open else f"{m} in {lo}..{hi}"
        if self.lo is not None:
            return f"{m} {'>' if self.lo_open else '>='} {lo}"
        if self.hi is not None:
            return f"{m} <= {hi}"
        return f"{m} finite"

    def __call__(self, text: str) -> int | float:
        noun = "a whole number" if self.kind is int else "a number"
        return checked(text, lambda t: self.kind(str(t).strip()), self._inside, f"{noun}, {self.describe()}",
                       self.describe())

    def _inside(self, v: int | float) -> bool:
        bad = self.kind is float and not math.isfinite(v)
        bad = bad or (self.lo is not None and (v <= self.lo if self.lo_open else v < self.lo))
        bad = bad or (self.hi is not None and v > self.hi)
        return not bad


def _positive_int(lo: int, hi: int | None = None) -> _Range:
    return _Range(int, lo, hi)


def _real(lo: float | None = None, hi: float | None = None, *, above: bool = False) -> _Range:
    """A float in [lo, hi] (``above``: lo excluded); NaN and infinities are refused."""
    return _Range(float, lo, hi, lo_open=above)


POSITIVE = dict(lo=0.0, above=True)  # ranges used by several options


SYSID = (1, 255)


HEADING_WORDS = ("auto", "gyrocompass", "mag", "vehicle", "vision")  # engine.HEADING_WORDS (not imported: --help stays light)


AIDING_WORDS = ("gnss", "baro", "mag", "zupt", "nhc", "wheel", "vision")  # aiding.AIDING_KINDS, likewise


class _Heading:
    """``--heading``: degrees in -360..360 or a source word (returned as given)."""

    __name__ = "heading"
    metavar = "DEG|SOURCE"

    def __init__(self, words: tuple[str, ...] = HEADING_WORDS) -> None:
        self.words = words

    def describe(self, metavar: str | None = None) -> str:
        return f"DEG in -360..360 or {', '.join(self.words)}"

    def __call__(self, text: str) -> str:
        text = str(text).strip()
        if text not in self.words:
            checked(text, float, lambda v: math.isfinite(v) and -360.0 <= v <= 360.0, self.describe(), self.describe())
        return text


class _Speed:
    """``--speed``: a positive factor of real time, or ``max`` (returned as given)."""

    __name__ = "speed"
    metavar = "X|max"

    def describe(self, metavar: str | None = None) -> str:
        return "X > 0 or max"

    def __call__(self, text: str) -> str:
        text = str(text).strip()
        if text != "max":
            checked(text, float, lambda v: math.isfinite(v) and v > 0, self.describe(), self.describe())
        return text


def _show_ranges(parser: argparse.ArgumentParser) -> None:
    """Append each validated option's range to its --help text (unless the text already gives it)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _show_ranges(sub)
            continue
        kind = action.type
        if not hasattr(kind, "describe") or action.help in (None, argparse.SUPPRESS):
            continue
        metavar = action.metavar if isinstance(action.metavar, str) else action.dest.upper()
        kind.metavar = metavar  # type: ignore[union-attr]
        plain = kind.describe(metavar).split(" in ")[-1]  # "1..6" is already said by "--samples ... 1..6"
        if plain not in action.help:
            action.help = f"{action.help} ({kind.describe(metavar)})"


def _say(command: str, lines: Iterable[str], stream=None) -> None:  # type: ignore[no-untyped-def]
    """Print ``lines`` as ``mavins COMMAND: line`` (to stderr unless ``stream`` is given)."""
    for line in lines:
        print(f"mavins {command}: {line}", file=stream or sys.stderr)


def _subparser(sub: argparse._SubParsersAction, name: str, help_text: str, description: str,
               **kw: object) -> argparse.ArgumentParser:
    """A subcommand whose --help shows every default."""
    return sub.add_parser(name, help=help_text, description=description,
                          formatter_class=argparse.ArgumentDefaultsHelpFormatter, **kw)


def _fleet_options(g: argparse._ArgumentGroup) -> None:
    """``--jobs`` and ``--cluster`` of a command's ``--each`` (common/fleet.py, common/parallel.py)."""
    g.add_argument("--jobs", type=_positive_int(1, 1024), default=None, metavar="N",
                   help="with --each: worker processes (default: every core)")
    g.add_argument("--cluster", metavar="ADDRESS",
                   help="with --each: run on the Dask cluster at ADDRESS (e.g. tcp://scheduler:8786) instead; "
                        "OUTPUT/summary.csv gets one row per input either way")


def _fleet_option_alone(args: argparse.Namespace, command: str, each: str) -> int | None:
    """EXIT_USAGE, said in one line, when ``--jobs`` or ``--cluster`` comes without ``--each`` (``each``: what
    --each does, for the message); None when neither does."""
    for given, name in ((args.jobs, "--jobs"), (args.cluster, "--cluster")):
        if given is not None:
            print(f"mavins {command}: error: {name} goes with --each ({each})", file=sys.stderr)
            return EXIT_USAGE
    return None


def _strapdown_options(p: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """The strapdown settings nav, run and replay share, built from their one definition
    (mavins/core/settings.py; docs/conventions.md ``mavins nav``)."""
    from ..core.settings import SETTINGS

    for s in SETTINGS:
        if s.switch_off:
            p.add_argument(s.flag, action="store_true", help=s.help)
        elif s.choices is not None:
            p.add_argument(s.flag, choices=s.choices, default=s.default, help=s.help)
        else:
            lo, hi = s.int_range  # type: ignore[misc]
            p.add_argument(s.flag, type=_positive_int(lo, hi) if hi is not None else _positive_int(lo),
                           default=s.default, metavar=s.metavar, help=s.help)


GRADES = ("consumer", "industrial", "tactical", "navigation")


def _filter_options(g: argparse._ArgumentGroup, with_aiding: bool = True) -> None:
    """The error-state filter's options (docs/conventions.md "Aided navigation")."""
    if with_aiding:
        g.add_argument("--aiding", type=_Aiding(), default="gnss,baro,mag", metavar="KINDS",
                       help="comma list of gnss,baro,mag,zupt,nhc,wheel,vision to use from the stream (nhc: the non-holonomic constraint of a wheeled vehicle; wheel: WHEEL_DISTANCE odometry; vision: the pose of ODOMETRY and VISION_POSITION_ESTIMATE and the velocity of ODOMETRY and VISION_SPEED_ESTIMATE from a camera or motion capture, its frame's origin and heading estimated), or none (free inertial)")
    g.add_argument("--grade", choices=GRADES, default="consumer",
                   help="the filter's IMU error model: the simulator's grade figures")
    g.add_argument("--imu-spec", type=Path, metavar="SPEC.toml",
                   help="the filter's IMU error model from a TOML file (gyro_arw, gyro_bias, ... : docs/conventions.md)")
    g.add_argument("--gate", type=_real(0.0, 1e3, above=True), default=5.0, metavar="N",
                   help="reject a measurement whose normalised innovation exceeds N sigma")
    g.add_argument("--lever-arm", type=_Vec3(), default="0,0,0", metavar="X,Y,Z",
                   help="GNSS antenna position from the IMU, body frame FRD (m)")
    g.add_argument("--scale-factors", action="store_true",
                   help="estimate the gyro and accelerometer scale factors too, from the grade's figures or the "
                        "spec's gyro_scale/accel_scale (ppm); written as sg_*, sa_* columns (docs/filter.md)")
    g.add_argument("--misalignment", action="store_true",
                   help="estimate the gyro and accelerometer misalignments (6 cross-axis terms each) too, from the "
                        "grade's figure or the spec's gyro_misalignment/accel_misalignment (arcsec); observable only "
                        "as far as the vehicle turns and tilts; written as mg_*, ma_* columns (docs/filter.md)")
    g.add_argument("--mag-bias", type=_real(0.0, 1e6), default=0.0, metavar="SIGMA",
                   help="estimate the magnetometer's hard iron (body FRD) from this initial 1-sigma per axis: gauss "
                        "for run/replay (as MAVLink carries the field), MAG.csv's unit for nav (default 0: the samples "
                        "are calibrated, as autopilots send them)")
    g.add_argument("--wheel-lever-arm", type=_Vec3(), default="0,0,0", metavar="X,Y,Z",
                   help="wheel odometry (WHEEL_DISTANCE, nav's --wheel): the axle centre from the IMU, body frame FRD (m)")
    g.add_argument("--wheel-scale", type=_real(0.0, 100.0), metavar="PCT",
                   help="initial 1-sigma of the odometer's scale-factor error (%%), estimated and written as the ws "
                        "column (ppm) (default: the filter's, docs/filter.md)")
    g.add_argument("--wheel-sigma", type=_real(0.0, 100.0, above=True), metavar="M/S",
                   help="1-sigma of one odometer speed (m/s) (default: the filter's, docs/filter.md; nav: for rows "
                        "without a sigma)")
    if with_aiding:
        g.add_argument("--vision-drift", type=_real(0.0, 100.0), default=None, metavar="M/RTS",
                       help="random walk of the camera frame's origin, m/sqrt(s): how fast a VIO's position drifts "
                            "(0 for motion capture; default: the filter's, docs/filter.md)")
        g.add_argument("--vision-yaw-drift", type=_real(0.0, 3600.0), default=None, metavar="DEG/RTH",
                       help="random walk of the camera frame's heading, deg/sqrt(h) (default: the filter's)")
    for kind, what in DELAYED:
        g.add_argument(f"--{kind}-delay", type=_real(0.0, 1000.0), default=0.0, metavar="MS",
                       help=f"the {what} stamped t was measured MS ms earlier, at t - MS/1000, and is fused at that "
                            "time (default 0: the stamp is the time of measurement)")


def _smooth_option(g: argparse._ArgumentGroup) -> None:
    """--smooth (nav, replay): the fixed-interval smoothed solution (docs/postprocessing.md)."""
    g.add_argument("--smooth", action="store_true",
                   help="write the fixed-interval smoothed solution (Rauch-Tung-Striebel over the whole run: every "
                        "measurement, later ones too, informs every row) in the same columns instead of the forward "
                        "filter's; kept in a temporary file while it runs (TMPDIR; docs/postprocessing.md)")


DELAYED = (("gnss", "GNSS fix"), ("baro", "barometric height"), ("mag", "magnetometer sample"))  # --KIND-delay


def _delays(args: argparse.Namespace) -> dict[str, float]:
    """--gnss-delay, --baro-delay, --mag-delay (ms) as seconds by aiding kind (the ones given, non-zero)."""
    return {k: getattr(args, f"{k}_delay") / 1000.0 for k, _ in DELAYED if getattr(args, f"{k}_delay", 0.0)}


def _imu_spec(args: argparse.Namespace, extra_keys: tuple[str, ...] = ()) -> str | dict:
    """The grade name, or the keys of --imu-spec (a one-line error on a bad file); ``extra_keys`` are allowed too."""
    if getattr(args, "imu_spec", None) is None:
        return args.grade
    import tomllib

    from ..core.errmodel import SPEC_KEYS

    allowed = SPEC_KEYS + extra_keys
    try:
        keys = tomllib.loads(args.imu_spec.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"--imu-spec {args.imu_spec}: {exc}") from None
    unknown = sorted(set(keys) - set(allowed))
    if unknown:
        raise ValueError(f"--imu-spec {args.imu_spec}: unknown keys {', '.join(unknown)} (allowed: {', '.join(allowed)})")
    bad = [k for k, v in keys.items() if not isinstance(v, (int, float)) or isinstance(v, bool) or not v >= 0]
    if bad:
        raise ValueError(f"--imu-spec {args.imu_spec}: {', '.join(bad)} must be non-negative numbers")
    return {k: float(v) for k, v in keys.items()}


class _Words:
    """A comma list of allowed words (``at_least`` of them, ``cast`` applied), or the one word
    ``empty`` for the empty tuple: --aiding (``none``), --imus (``all``)."""

    def __init__(self, allowed: tuple[str, ...], empty: str, at_least: int = 1,
                 cast: Callable[[str], object] = str, sort: bool = False) -> None:
        self.allowed, self.empty, self.at_least, self.cast, self.sort = allowed, empty, at_least, cast, sort

    def describe(self, metavar: str | None = None) -> str:
        more = "" if self.at_least == 1 else f"{self.at_least} or more of "
        return f"{more}{','.join(self.allowed)} or {self.empty}"

    def __call__(self, text: str) -> tuple:
        if text.strip() == self.empty:
            return ()
        words = list(dict.fromkeys(w.strip() for w in text.split(",") if w.strip()))
        if self.sort:
            words.sort()
        if len(words) < self.at_least or any(w not in self.allowed for w in words):
            raise argparse.ArgumentTypeError(f"expected a comma list of {self.describe()}, got {text!r}")
        return tuple(self.cast(w) for w in words)


def _Aiding() -> _Words:
    """--aiding: a comma list of aiding kinds, or none."""
    return _Words(AIDING_WORDS, "none")


def _ImuList() -> _Words:
    """--imus: all, or two or more IMU numbers 0..2."""
    return _Words(("0", "1", "2"), "all", at_least=2, cast=int, sort=True)


class _Outage:
    """START,END: an interval of sensor time (s)."""

    def describe(self, metavar: str | None = None) -> str:
        return "START,END with 0 <= START < END"

    def __call__(self, text: str) -> tuple[float, float]:
        import math

        try:
            a, b = (float(x) for x in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected START,END (s), got {text!r}") from None
        if not (math.isfinite(a) and math.isfinite(b) and 0.0 <= a < b):
            raise argparse.ArgumentTypeError(f"expected START,END with 0 <= START < END, got {text!r}")
        return a, b


class _Disturbance:
    """START,END,N,E,D: an interval of sensor time (s) and a field (gauss, NED)."""

    def describe(self, metavar: str | None = None) -> str:
        return "START,END,N,E,D with 0 <= START < END (s) and a field in gauss"

    def __call__(self, text: str) -> tuple[float, ...]:
        import math

        try:
            v = tuple(float(x) for x in text.split(","))
        except ValueError:
            v = ()
        if len(v) != 5 or not all(math.isfinite(x) for x in v) or not 0.0 <= v[0] < v[1] \
                or max(abs(x) for x in v[2:]) > 10.0:
            raise argparse.ArgumentTypeError(f"expected START,END,N,E,D with 0 <= START < END (s) and a field of "
                                             f"at most 10 gauss per axis, got {text!r}")
        return v


class _Date:
    """``--date``: a UTC date YYYY-MM-DD or a decimal year, 1900..2100, returned as a decimal year."""

    __name__ = "date"
    metavar = "YYYY-MM-DD|YEAR"

    def describe(self, metavar: str | None = None) -> str:
        return "a date YYYY-MM-DD or a decimal year in 1900..2100"

    def __call__(self, text: str) -> float:
        import datetime as dt

        text = str(text).strip()
        try:
            d = dt.datetime.strptime(text, "%Y-%m-%d").replace(tzinfo=dt.timezone.utc)
            y = d.year + (d - d.replace(month=1, day=1)).total_seconds() / (
                d.replace(year=d.year + 1, month=1, day=1) - d.replace(month=1, day=1)).total_seconds()
        except ValueError:
            try:
                y = float(text)
            except ValueError:
                y = math.nan
        if not (math.isfinite(y) and 1900.0 <= y <= 2100.0):
            raise argparse.ArgumentTypeError(f"expected {self.describe()}, got {text!r}")
        return y


def _magnetic_options(g: argparse._ArgumentGroup, date_default: str) -> None:
    """``--declination`` and ``--date``: the magnetic declination, by default the World Magnetic
    Model's at the position and date (docs/conventions.md "Magnetic field")."""
    g.add_argument("--declination", type=_real(-180.0, 180.0), default=None, metavar="DEG",
                   help="magnetic declination (east positive) for the magnetometer; default: the World Magnetic "
                        "Model's at the initial position and the date")
    g.add_argument("--date", type=_Date(), default=None, metavar="YYYY-MM-DD",
                   help=f"the date for the magnetic model (or a decimal year); default: {date_default}")


class _Vec3:
    """X,Y,Z: three finite numbers."""

    def describe(self, metavar: str | None = None) -> str:
        return "three numbers X,Y,Z"

    def __call__(self, text: str) -> tuple[float, float, float]:
        import math

        try:
            v = tuple(float(x) for x in text.split(","))
        except ValueError:
            v = ()
        if len(v) != 3 or not all(math.isfinite(x) and abs(x) < 1e3 for x in v):
            raise argparse.ArgumentTypeError(f"expected three numbers X,Y,Z (m, below 1000), got {text!r}")
        return v  # type: ignore[return-value]


def _scenario_error(name: str, exc: Exception) -> str:
    """One line for a scenario that cannot be loaded."""
    if isinstance(exc, UnicodeDecodeError):
        return (f"{name}: expected a scenario TOML file (UTF-8 text), found bytes that are not text "
                f"({exc.reason} at byte {exc.start})")
    if isinstance(exc, OSError):
        return f"{name}: cannot read: {exc.strerror or exc}"
    return str(exc)


def _nav_options(p: argparse.ArgumentParser) -> None:
    """Navigation options shared by run, replay (docs/conventions.md ``mavins run``)."""
    g = p.add_argument_group("navigation")
    g.add_argument("--lat", type=_real(-90.0, 90.0), metavar="DEG", help="initial latitude (else the vehicle's first good GPS fix)")
    g.add_argument("--lon", type=_real(-180.0, 180.0), metavar="DEG", help="initial longitude")
    g.add_argument("--alt", type=_real(-1e4, 1e6), metavar="M", help="initial ellipsoidal height")
    g.add_argument("--heading", type=_Heading(), default="auto", metavar="DEG|SOURCE",
                   help="initial yaw in degrees, or a source: vehicle (its ATTITUDE), mag (magnetometer), "
                        "gyrocompass (navigation-grade gyros), vision (a camera's attitude: its frame's x axis as "
                        "north), auto (vehicle, else a dual-antenna GNSS yaw, else mag, else vision when it is the "
                        "only position aiding, else gyrocompass, or with coarse gyros the heading from GNSS "
                        "velocity once moving)")
    g.add_argument("--gnss-yaw-offset", type=_real(-180.0, 180.0), default=0.0, metavar="DEG",
                   help="azimuth of the dual-antenna GNSS baseline in the body (FRD, 0 = along x, 90 = to the right): "
                        "the vehicle's heading is the receiver's yaw (GPS_RAW_INT yaw) minus this")
    _magnetic_options(g, "the vehicle's (SYSTEM_TIME; a log's GPS time), else today's")
    g.add_argument("--gyro-bias", choices=("estimate", "none"), default="estimate",
                   help="estimate = remove the mean gyro minus Earth rate of the static window (not with gyrocompass)")
    g.add_argument("--align", type=_real(0.0), default=10.0, metavar="S", help="static coarse alignment window (sensor time)")
    g.add_argument("--rate", type=_real(0.0, 1e4, above=True), default=50.0, metavar="HZ", help="output rate in sensor time")
    g.add_argument("--imu", default="auto", choices=("auto", "highres", "raw", "scaled", "scaled2", "scaled3"),
                   help="IMU message to navigate on (auto = the first one seen)")
    g.add_argument("--imu-id", type=_positive_int(0, 255), default=None, metavar="ID", help="id field of HIGHRES_IMU/RAW_IMU to use")
    g.add_argument("--imus", type=_ImuList(), default=None, metavar="all|ID,ID..",
                   help="fuse several IMUs with fault detection and isolation: HIGHRES_IMU ids, or RAW_IMU, "
                        "SCALED_IMU2, SCALED_IMU3 as 0, 1, 2; all = every one seen in the first second "
                        "(docs/redundancy.md)")
    g.add_argument("--false-alarm", type=_real(0.0, 0.5, above=True), default=1e-6, metavar="P",
                   help="with --imus: design false-alarm probability of each test")
    g.add_argument("--raw-acc-scale", type=_real(**POSITIVE), default=9.80665e-3, metavar="M_S2",
                   help="RAW_IMU accelerometer scale, m/s^2 per count (ArduPilot: 1 mG)")
    g.add_argument("--raw-gyro-scale", type=_real(**POSITIVE), default=1e-3, metavar="RAD_S",
                   help="RAW_IMU gyro scale, rad/s per count (ArduPilot: 1 mrad/s)")
    g.add_argument("--target-system", type=_positive_int(*SYSID), default=None, metavar="SYSID", help="accept IMU data only from this system")
    g.add_argument("--max-accel", type=_real(**POSITIVE), default=16 * 9.80665, metavar="M_S2", help="accelerometer range")
    g.add_argument("--max-gyro", type=_real(**POSITIVE), default=2000.0, metavar="DEG_S", help="gyro range")
    g.add_argument("--geoid-height", type=_real(-200.0, 200.0), default=0.0, metavar="M",
                   help="geoid undulation N: ellipsoidal height = AMSL altitude + N (GNSS input without an "
                        "ellipsoidal height, GLOBAL_POSITION_INT output)")
    g.add_argument("--max-gap", type=_real(**POSITIVE), default=1.0, metavar="S",
                   help="a longer gap in sensor time is not integrated and marks the solution degraded")
    g.add_argument("--config", type=Path, metavar="FILE.toml", help="TOML file with any of these options (command line wins)")
    _strapdown_options(p.add_argument_group("strapdown (as mavins nav)"))
    _filter_options(p.add_argument_group("aided navigation (docs/filter.md)"))


_ODOMETRY_FRAMES = {"frd": 20, "ned": 1}  # MAV_FRAME_LOCAL_FRD, MAV_FRAME_LOCAL_NED


_IMU_NAMES = {"auto": "auto", "highres": "HIGHRES_IMU", "raw": "RAW_IMU", "scaled": "SCALED_IMU",
              "scaled2": "SCALED_IMU2", "scaled3": "SCALED_IMU3"}


def _typed_options(parser: argparse.ArgumentParser, argv: Sequence[str]) -> set[str]:
    """The destinations of the options typed on the command line (``--x V`` or ``--x=V``), so that
    --config never overrides them, even with a typed value equal to the default."""
    sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
    parsers = [parser] + (list(sub.choices.values()) if sub is not None else [])
    strings = {o: a.dest for p in parsers for a in p._actions for o in a.option_strings}
    typed = set()
    for tok in argv:
        if tok == "--":
            break
        if tok.startswith("-"):
            name = tok.split("=", 1)[0]
            if name in strings:
                typed.add(strings[name])
    return typed


def _apply_config(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Fill options from --config, except those typed on the command line (which win)."""
    path = getattr(args, "config", None)
    if path is None:
        return
    import tomllib

    def fail(msg: str) -> None:  # one line, like every other bad input (no usage: the command line was fine)
        parser.exit(EXIT_USAGE, f"{parser.prog}: error: --config {path}: {msg}\n")

    try:
        doc = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        fail(f"expected a TOML file (UTF-8 text), found bytes that are not text ({exc.reason} at byte {exc.start})")
    except OSError as exc:
        fail(f"cannot read: {exc.strerror or exc}")
    except tomllib.TOMLDecodeError as exc:
        fail(f"not valid TOML: {exc}")
    actions = {a.dest: a for a in parser._actions}
    for key, value in doc.items():
        dest = key.replace("-", "_")
        if not hasattr(args, dest) or dest not in actions:
            fail(f"unknown option {key!r}")
        action = actions[dest]
        try:  # the same checks as on the command line
            if action.nargs == 0:  # a flag
                if not isinstance(value, bool):
                    raise argparse.ArgumentTypeError(f"expected true or false, got {value!r}")
            elif isinstance(value, (bool, dict)) or (isinstance(value, list) and action.nargs is None
                                                      and not isinstance(action, argparse._AppendAction)):
                raise argparse.ArgumentTypeError(f"expected a single value, got {value!r}")
            elif action.type is not None and not isinstance(value, list):
                value = action.type(str(value))
            if action.choices is not None and value not in action.choices:
                raise argparse.ArgumentTypeError(f"expected one of {', '.join(map(str, action.choices))}, "
                                                 f"got {value!r}")
        except (argparse.ArgumentTypeError, ValueError, TypeError) as exc:
            fail(f"{key}: {exc}")
        if dest not in getattr(args, "typed", set()):
            setattr(args, dest, value)


def _engine_config(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from ..live.engine import EngineConfig

    heading: float | str = args.heading
    try:
        heading = float(args.heading)
    except (TypeError, ValueError):
        pass
    from ..live.livefilter import FilterSettings

    flt = FilterSettings(spec=_imu_spec(args), aiding=args.aiding, gate=args.gate, lever_arm=args.lever_arm,
                         delays=_delays(args), sigma_mag_bias=args.mag_bias, scale_factors=args.scale_factors,
                         misalignment=args.misalignment, smooth=getattr(args, "smooth", False),
                         wheel_lever_arm=tuple(args.wheel_lever_arm),
                         **({} if args.wheel_scale is None else {"wheel_scale": args.wheel_scale / 100.0}),
                         **({} if args.wheel_sigma is None else {"sigma_wheel": args.wheel_sigma}),
                         **({} if getattr(args, "vision_drift", None) is None else {"vision_drift": args.vision_drift}),
                         **({} if getattr(args, "vision_yaw_drift", None) is None
                            else {"vision_yaw_drift": args.vision_yaw_drift}))
    from ..core.settings import strapdown_from_options

    strapdown = strapdown_from_options(args)
    if strapdown.frame != "geographic" and flt.aiding:
        raise ValueError(f"--frame {strapdown.frame} navigates free inertial only (the filter works in the "
                         "geographic frame): add --aiding none")
    return EngineConfig(lat=args.lat, lon=args.lon, alt=args.alt, heading=heading, declination=args.declination,
                        gnss_yaw_offset=args.gnss_yaw_offset,
                        mag_year=args.date, align=args.align, rate=args.rate, gyro_bias=args.gyro_bias, max_gap=args.max_gap,
                        filter=flt, geoid_height=args.geoid_height, **strapdown.keywords())


def _ingest_config(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from ..link.ingest import IngestConfig

    import math

    return IngestConfig(message=_IMU_NAMES[args.imu], imu_id=args.imu_id, target_system=args.target_system,
                        raw_acc_scale=args.raw_acc_scale, raw_gyro_scale=args.raw_gyro_scale,
                        max_accel=args.max_accel, max_gyro=math.radians(args.max_gyro),
                        imus=getattr(args, "imus", None), false_alarm=getattr(args, "false_alarm", 1e-6))


def _setup_logging(verbose: bool) -> None:
    import logging

    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
