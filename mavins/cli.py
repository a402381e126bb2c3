"""The ``mavins`` command line: parses options and calls in, nothing more.

Heavy modules (numba kernels, pymavlink, rerun) are imported only inside the
subcommand that needs them, so ``mavins --help`` answers at once.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from collections.abc import Callable, Iterable, Sequence

from .common.argcheck import checked

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
HEADING_WORDS = ("auto", "gyrocompass", "mag", "vehicle")  # engine.HEADING_WORDS (not imported: --help stays light)
AIDING_WORDS = ("gnss", "baro", "mag", "zupt")  # aiding.AIDING_KINDS, likewise


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


def _add_nav(sub: argparse._SubParsersAction) -> None:
    p = _subparser(sub, "nav", "strapdown solution from IMU files (offline)",
                   "Integrate an IMU file (increments or rates, docs/conventions.md columns) from an initial "
                   "state and write the navigation solution, one row per attitude update at the time of "
                   "its last sample. Trailing samples that do not fill an update are not used.")
    p.add_argument("imu", type=Path, nargs="+", metavar="IMU.csv",
                   help="increments (t,dtheta_*,dv_*) or rates (t,gyro_*,acc_*); several files (same times, "
                        "same body frame) are monitored and fused first (docs/redundancy.md)")
    p.add_argument("--init", type=Path, metavar="INIT.json",
                   help="initial state JSON (required, except with --each: then each file's own init.json)")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="NAV.csv",
                   help="solution CSV (or .parquet) to write; with --each a folder")
    p.add_argument("--input", choices=("increments", "rates"), default="increments", help="what the IMU file holds")
    b = p.add_argument_group("batch (many files, each on its own)")
    b.add_argument("--each", action="store_true",
                   help="navigate every IMU file on its own (not fused): each solution goes to "
                        "OUTPUT/<folder>/<name>.nav.csv, a bad file is reported and the others go on")
    b.add_argument("--jobs", type=_positive_int(1, 1024), default=None, metavar="N",
                   help="with --each: worker processes (default: every core)")
    _strapdown_options(p)
    g = p.add_argument_group("aided navigation (with --gnss, --baro, --mag and/or --rest; docs/filter.md)")
    g.add_argument("--gnss", type=Path, metavar="GNSS.csv",
                   help="GNSS fixes: t,lat,lon,h [,sigma_h,sigma_v,vn,ve,vd,sigma_vel] (docs/conventions.md)")
    g.add_argument("--baro", type=Path, metavar="BARO.csv", help="barometric height: t,h [,sigma]")
    g.add_argument("--mag", type=Path, metavar="MAG.csv",
                   help="calibrated magnetometer, body FRD, any unit: t,mx,my,mz [,sigma] (sigma: heading noise of "
                        "one sample, deg, default 3)")
    g.add_argument("--mag-unit", choices=("gauss", "mgauss", "uT", "nT"),
                   help="MAG.csv's unit (mavins sim writes uT): the magnetic model's strength then checks the "
                        "samples and sets the hard iron's model (--mag-bias); default: any unit, not checked")
    _magnetic_options(g, "today's")
    g.add_argument("--rest", type=_Outage(), action="append", metavar="START,END",
                   help="the vehicle stood still over this interval of sensor time (s): a zero-velocity update at "
                        "every attitude update inside it and a zero-rate update (the gyro bias) at its end; "
                        "repeatable")
    _filter_options(g, with_aiding=False)
    p.add_argument("--timing", action="store_true", help="print read/compute/write seconds to stderr")
    r = p.add_argument_group("redundant IMUs (several IMU files; noise from --grade/--imu-spec; docs/redundancy.md)")
    r.add_argument("--fdi-log", type=Path, metavar="FDI.csv",
                   help="write the fault events: t,event,imu,sensor,axis,statistic,threshold (header only: no fault)")
    r.add_argument("--false-alarm", type=_real(0.0, 0.5, above=True), default=1e-6, metavar="P",
                   help="design false-alarm probability of each test")
    p.set_defaults(func=_cmd_nav)


def _strapdown_options(p: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """The strapdown settings nav, run and replay share, built from their one definition
    (mavins/core/settings.py; docs/conventions.md ``mavins nav``)."""
    from .core.settings import SETTINGS

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
                       help="comma list of gnss,baro,mag,zupt to use from the stream, or none (free inertial)")
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
    for kind, what in DELAYED:
        g.add_argument(f"--{kind}-delay", type=_real(0.0, 1000.0), default=0.0, metavar="MS",
                       help=f"the {what} stamped t was measured MS ms earlier, at t - MS/1000, and is fused at that "
                            "time (default 0: the stamp is the time of measurement)")


DELAYED = (("gnss", "GNSS fix"), ("baro", "barometric height"), ("mag", "magnetometer sample"))  # --KIND-delay


def _delays(args: argparse.Namespace) -> dict[str, float]:
    """--gnss-delay, --baro-delay, --mag-delay (ms) as seconds by aiding kind (the ones given, non-zero)."""
    return {k: getattr(args, f"{k}_delay") / 1000.0 for k, _ in DELAYED if getattr(args, f"{k}_delay", 0.0)}


def _imu_spec(args: argparse.Namespace, extra_keys: tuple[str, ...] = ()) -> str | dict:
    """The grade name, or the keys of --imu-spec (a one-line error on a bad file); ``extra_keys`` are allowed too."""
    if getattr(args, "imu_spec", None) is None:
        return args.grade
    import tomllib

    from .core.errmodel import SPEC_KEYS

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


def _cmd_nav(args: argparse.Namespace) -> int:
    from .common import files
    from .nav import NavOptions, run_nav

    from .core.settings import strapdown_from_options

    opts = NavOptions(input=args.input, strapdown=strapdown_from_options(args), timing=args.timing)
    if args.each:
        return _cmd_nav_each(args, opts)
    if args.jobs is not None:
        print("mavins nav: error: --jobs goes with --each (several files, each navigated on its own)", file=sys.stderr)
        return EXIT_USAGE
    if args.init is None:
        print("mavins nav: error: --init INIT.json is required (the initial state)", file=sys.stderr)
        return EXIT_USAGE
    try:
        if len(args.imu) > 1 or args.fdi_log is not None:
            return _cmd_nav_fdi(args, opts)
        if args.gnss is None and args.baro is None and args.mag is None and args.rest is None:
            rows = run_nav(args.imu[0], args.init, args.output, opts)
        else:
            from .nav import AidingFiles, run_nav_aided

            rows, counts = run_nav_aided(args.imu[0], args.init, args.output, opts,
                                         AidingFiles(args.gnss, args.baro, args.mag, args.declination,
                                                     tuple(args.rest or ()), args.date, _delays(args),
                                                     args.mag_bias, args.scale_factors, args.mag_unit,
                                                     args.misalignment),
                                         _imu_spec(args), args.lever_arm, args.gate)
            for kind, (ok, bad) in counts.items():
                if ok or bad:
                    print(f"mavins nav: {kind}: {ok} accepted, {bad} rejected (gate {args.gate:g} sigma)",
                          file=sys.stderr)
    except (files.DataFileError, files.ResourceError, ValueError) as exc:
        print(f"mavins nav: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    print(f"mavins nav: wrote {rows} solution rows to {args.output}", file=sys.stderr)
    return 0


def _cmd_nav_each(args: argparse.Namespace, opts: object) -> int:
    """``mavins nav --each A.csv B.csv ... -o DIR``: a batch on every core; exit 2 if any file failed."""
    from .common import files
    from .nav import run_nav_batch

    bad = [name for name, v in (("--gnss", args.gnss), ("--baro", args.baro), ("--mag", args.mag),
                                ("--rest", args.rest), ("--fdi-log", args.fdi_log)) if v is not None]
    if bad:
        print(f"mavins nav: error: --each navigates free inertial; {', '.join(bad)} cannot go with it",
              file=sys.stderr)
        return EXIT_USAGE
    try:
        results = run_nav_batch(args.imu, args.init, args.output, opts, jobs=args.jobs)  # type: ignore[arg-type]
    except (files.DataFileError, files.ResourceError, ValueError) as exc:
        print(f"mavins nav: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    failed = 0
    for _imu, out, rows, err in results:
        if err is None:
            print(f"mavins nav: wrote {rows} solution rows to {out}", file=sys.stderr)
        else:
            failed += 1
            print(f"mavins nav: error: {err}", file=sys.stderr)
    print(f"mavins nav: {len(results) - failed} of {len(results)} files navigated", file=sys.stderr)
    return EXIT_USAGE if failed else 0


def _cmd_nav_fdi(args: argparse.Namespace, opts: object) -> int:
    """``mavins nav IMU0.csv IMU1.csv ... [--fdi-log FDI.csv]``: parse, call mavins.navfdi, report."""
    from .common import files
    from .navfdi import run_nav_fdi, strapdown_keywords

    try:
        if any(v is not None for v in (args.gnss, args.baro, args.mag, args.rest)):
            raise ValueError("several IMU files with --gnss/--baro/--mag/--rest are not supported (the fused "
                             "solution is free inertial)")
        rows, events = run_nav_fdi(args.imu, args.init, args.output, args.fdi_log, rates=args.input == "rates",
                                   strapdown=strapdown_keywords(opts), spec=_imu_spec(args),
                                   false_alarm=args.false_alarm)
    except (files.DataFileError, files.ResourceError, ValueError) as exc:
        print(f"mavins nav: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    for e in events:
        where = f" IMU {e.imu} {e.sensor} {e.axis}" if e.imu is not None else f" {e.sensor}"
        print(f"mavins nav: t={e.t:.3f} s: {e.event}{where} (statistic {e.statistic:.4g}, threshold "
              f"{e.threshold:.4g})", file=sys.stderr)
    print(f"mavins nav: fused {len(args.imu)} IMUs, {len(events)} fault event(s); wrote {rows} solution rows "
          f"to {args.output}", file=sys.stderr)
    return 0


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
    p.add_argument("--gnss-rate", type=_real(0.0, 100.0), default=1.0, metavar="HZ",
                   help="GNSS fixes per second written to gnss.csv (with baro.csv; 0 = none; docs/simulator.md)")
    p.add_argument("--gnss-outage", type=_Outage(), metavar="START,END",
                   help="no GNSS fix between these sensor times (s), in files and when streaming")
    p.add_argument("--gnss-latency", type=_real(0.0, 1000.0), default=0.0, metavar="MS",
                   help="with --stream: each GPS_RAW_INT is sent this long after its fix was measured and stamped "
                        "when sent, as an autopilot stamps a receiver's late output (test run's --gnss-delay)")
    p.add_argument("--mag-rate", type=_real(0.0, 100.0), default=0.0, metavar="HZ",
                   help="magnetometer samples per second written to mag.csv, or streamed in HIGHRES_IMU (0 = none; "
                        "the World Magnetic Model's field at the start on --date, 0.3 uT noise; docs/simulator.md)")
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
    from .common import files
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
            from sim.aiding import BaroConfig, GnssConfig, MagConfig, simulate_aiding

            outages = (tuple(args.gnss_outage),) if args.gnss_outage else ()
            gnss_on = args.gnss_rate > 0
            aiding = simulate_aiding(run, GnssConfig(rate=args.gnss_rate, outages=outages) if gnss_on else None,
                                     BaroConfig() if gnss_on else None,
                                     _sim_mag(MagConfig, run, args) if args.mag_rate > 0 else None) \
                if gnss_on or args.mag_rate > 0 else None
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

    from .common.progress import Progress

    outages = (tuple(args.gnss_outage),) if args.gnss_outage else ()
    try:
        with Progress("stream", run_duration(scenario, args.duration), "s") as bar:
            stats = stream(itertools.chain([run], pieces), args.stream,
                           StreamOptions(msg=args.msg, imu_rates=args.imu_rates, speed=speed, sysid=args.sysid,
                                         imus=args.imus, seed=args.seed, gnss_outages=outages,
                                         gnss_latency=args.gnss_latency / 1000.0, mag_rate=args.mag_rate,
                                         mag=_sim_mag(MagConfig, run, args)),
                           progress=bar)
    except (ValueError, OSError) as exc:  # a piece that could not be made, or the link
        print(f"mavins sim: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    print(f"mavins sim: streamed {stats.imu_messages} IMU messages to {args.stream}", file=sys.stderr)
    return 0


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
                        "gyrocompass (navigation-grade gyros), auto (vehicle, else a dual-antenna GNSS yaw, else "
                        "mag, else gyrocompass, or with coarse gyros the heading from GNSS velocity once moving)")
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
    from .live.engine import EngineConfig

    heading: float | str = args.heading
    try:
        heading = float(args.heading)
    except (TypeError, ValueError):
        pass
    from .live.livefilter import FilterSettings

    flt = FilterSettings(spec=_imu_spec(args), aiding=args.aiding, gate=args.gate, lever_arm=args.lever_arm,
                         delays=_delays(args), sigma_mag_bias=args.mag_bias, scale_factors=args.scale_factors,
                         misalignment=args.misalignment)
    from .core.settings import strapdown_from_options

    strapdown = strapdown_from_options(args)
    if strapdown.frame != "geographic" and flt.aiding:
        raise ValueError(f"--frame {strapdown.frame} navigates free inertial only (the filter works in the "
                         "geographic frame): add --aiding none")
    return EngineConfig(lat=args.lat, lon=args.lon, alt=args.alt, heading=heading, declination=args.declination,
                        gnss_yaw_offset=args.gnss_yaw_offset,
                        mag_year=args.date, align=args.align, rate=args.rate, gyro_bias=args.gyro_bias, max_gap=args.max_gap,
                        filter=flt, geoid_height=args.geoid_height, **strapdown.keywords())


def _ingest_config(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    from .link.ingest import IngestConfig

    import math

    return IngestConfig(message=_IMU_NAMES[args.imu], imu_id=args.imu_id, target_system=args.target_system,
                        raw_acc_scale=args.raw_acc_scale, raw_gyro_scale=args.raw_gyro_scale,
                        max_accel=args.max_accel, max_gyro=math.radians(args.max_gyro),
                        imus=getattr(args, "imus", None), false_alarm=getattr(args, "false_alarm", 1e-6))


def _add_run(sub: argparse._SubParsersAction) -> None:
    p = _subparser(sub, "run", "the MAVLink INS service",
                   "Connect to a MAVLink stream, align on the IMU, navigate on sensor time and publish "
                   "ATTITUDE, ATTITUDE_QUATERNION, LOCAL_POSITION_NED, GLOBAL_POSITION_INT, ODOMETRY and HEARTBEAT. "
                   "Stops cleanly on Ctrl-C or SIGTERM.")
    p.add_argument("--master", default="udpin:127.0.0.1:14551", metavar="URL",
                   help="pymavlink connection string to read (udpin:/udpout:/tcp:/serial device)")
    p.add_argument("--out", action="append", default=[], metavar="URL", help="extra output link (repeatable)")
    p.add_argument("--sysid", type=_positive_int(*SYSID), default=None, metavar="ID",
                   help="our system id (default: the vehicle's)")
    p.add_argument("--compid", type=_positive_int(1, 255), default=191, metavar="ID",
                   help="our component id (191 = onboard computer)")
    p.add_argument("--tlog", type=Path, metavar="FILE", help="record every received message (replayable)")
    p.add_argument("-o", "--output", type=Path, metavar="NAV.csv", help="also write each output set as a solution row")
    p.add_argument("--request-imu", type=_real(0.0, 1e4, above=True), metavar="HZ", help="ask the autopilot for HIGHRES_IMU at HZ")
    p.add_argument("--rerun", type=Path, metavar="FILE.rrd", help="record to a Rerun file")
    p.add_argument("--rerun-serve", action="store_true", help="serve the recording for a live Rerun viewer")
    p.add_argument("--duration", type=_real(**POSITIVE), metavar="S", help="stop after S seconds of wall time")
    p.add_argument("--signing-key", type=Path, metavar="FILE",
                   help="MAVLink 2 signing key (32 bytes or 64 hex digits, mode 600): input must be signed, "
                        "output is signed (see 'mavins key')")
    p.add_argument("--peer-timeout", type=_real(**POSITIVE), default=10.0, metavar="S",
                   help="stop sending to a listening link's peer after S seconds of silence")
    p.add_argument("--max-peers", type=_positive_int(1), default=8, metavar="N", help="most peers a listening link sends to")
    a = p.add_argument_group("for autopilots and ground stations (docs/autopilots.md)")
    a.add_argument("--odometry-frame", choices=("frd", "ned"), default="frd",
                   help="ODOMETRY frame_id: MAV_FRAME_LOCAL_FRD or MAV_FRAME_LOCAL_NED")
    a.add_argument("--gps-input", action="store_true",
                   help="also publish GPS_INPUT at 5 Hz (ArduPilot GPS_TYPE 14 takes the solution as a GPS)")
    a.add_argument("--set-origin", action="store_true",
                   help="send SET_GPS_GLOBAL_ORIGIN to the vehicle once aligned (ArduPilot without GPS)")
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
    from .common.files import DataFileError, check_outputs

    master = Path(args.master.split(",")[0])  # a serial device or a log file is an input too
    key_state = args.signing_key.with_name(args.signing_key.name + ".timestamp") if args.signing_key else None
    try:  # live logs (-o, --tlog, --rerun) are written as they come, so a crash keeps them: no temp-and-rename
        check_outputs({"-o": args.output, "--tlog": args.tlog, "--rerun": args.rerun},
                      {"--master": master if master.exists() else None, "--signing-key": args.signing_key,
                       "--signing-key's timestamp file": key_state, "--config": args.config})
    except DataFileError as exc:
        print(f"mavins run: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    _setup_logging(args.verbose)
    from .link.publish import PublishConfig
    from .service import Service, ServiceConfig

    try:
        engine_cfg = _engine_config(args)
    except ValueError as exc:
        print(f"mavins run: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    from .link.links import PeerPolicy
    from .link.signing import KeyFileError, load_key

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
                        publish=PublishConfig(geoid_height=args.geoid_height, gps_input=args.gps_input,
                                              set_origin=args.set_origin,
                                              odometry_frame=_ODOMETRY_FRAMES[args.odometry_frame]))
    try:
        svc = Service(engine_cfg, ingest_cfg, cfg)
    except OSError as exc:
        print(f"mavins run: error: cannot open a link: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.rerun or args.rerun_serve:
        from .record.recorder import Recorder

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
    print(f"mavins run: ready: listening on {args.master}", file=sys.stderr, flush=True)
    _say("run", svc.run(stop).lines())
    return 0


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
    from .common.files import DataFileError, ResourceError, check_outputs
    from .replay import replay

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
                   help="what the service aids with from the simulator's stream (gnss,baro,mag,zupt), or none")
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

    from .common.files import DataFileError, ResourceError, check_outputs
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
    from .demo import run_demo

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


def _add_key(sub: argparse._SubParsersAction) -> None:
    p = _subparser(sub, "key", "make a MAVLink 2 signing key file",
                   "Write a 32-byte signing key (as 64 hex digits, file mode 600). With --passphrase the key is "
                   "SHA-256 of the passphrase, the same key MAVProxy's 'signing setup PASSPHRASE' uses; without, a "
                   "random key.")
    p.add_argument("file", type=Path, metavar="FILE")
    p.add_argument("--passphrase", help="derive the key from a passphrase (MAVProxy's convention)")
    p.add_argument("--force", action="store_true", help="overwrite an existing file")
    p.set_defaults(func=_cmd_key)


def _cmd_key(args: argparse.Namespace) -> int:
    import secrets

    from .link.signing import key_from_passphrase

    if args.file.exists() and not args.force:
        print(f"mavins key: error: {args.file} exists (use --force to overwrite)", file=sys.stderr)
        return EXIT_USAGE
    try:
        key = key_from_passphrase(args.passphrase) if args.passphrase else secrets.token_bytes(32)
    except UnicodeEncodeError:
        print("mavins key: error: the passphrase must be ASCII (MAVProxy hashes its ASCII bytes)", file=sys.stderr)
        return EXIT_USAGE
    from .common.files import DataFileError, atomic_output

    if args.file.is_dir():
        print(f"mavins key: error: {args.file} is a directory, expected a file to write", file=sys.stderr)
        return EXIT_USAGE
    try:  # mode 600 from the first byte; renamed into place (an existing key is replaced whole, or kept)
        with atomic_output(args.file, mode=0o600) as tmp, open(tmp, "w", encoding="ascii") as fh:
            fh.write(key.hex() + "\n")
    except (DataFileError, OSError) as exc:
        text = str(exc) if isinstance(exc, DataFileError) else f"{args.file}: cannot write: {exc.strerror or exc}"
        print(f"mavins key: error: {text}", file=sys.stderr)
        return EXIT_USAGE
    print(f"mavins key: wrote {args.file} (mode 600)", file=sys.stderr)
    return 0


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

    from .analysis import AnalysisOptions, run_analyze
    from .core import covariance
    from .common.parallel import JobError

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


def _add_review(sub: argparse._SubParsersAction) -> None:
    from .record.review import DESCRIPTION, add_arguments, run

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
    _show_ranges(parser)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("mavins")
    except PackageNotFoundError:
        return "unknown"


_EXTRA_COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [_add_sim, _add_run, _add_replay, _add_demo, _add_review, _add_key,
                                                                     _add_analyze]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mavins`` console script."""
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    args.typed = _typed_options(parser, argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    import signal
    import threading

    previous = None
    if args.command in OFFLINE_COMMANDS and threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _terminate)  # unwind like Ctrl-C: temporary outputs removed
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        print("mavins: interrupted", file=sys.stderr)
        return 130
    except _Terminated:
        print("mavins: terminated", file=sys.stderr)
        return 143
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


OFFLINE_COMMANDS = ("nav", "sim", "replay", "review", "key", "analyze")


class _Terminated(BaseException):
    """SIGTERM in an offline tool: raised so that every temporary output is removed on the way out."""


def _terminate(signum: int, frame: object) -> None:
    raise _Terminated()


if __name__ == "__main__":
    sys.exit(main())
