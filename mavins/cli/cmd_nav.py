"""``mavins nav``: offline navigation of IMU files (strapdown, aided, redundant IMUs, batches)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .options import (
    EXIT_USAGE, _Outage, _delays, _filter_options, _fleet_option_alone, _fleet_options, _imu_spec, _magnetic_options,
    _real, _smooth_option, _strapdown_options, _subparser
)


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
    _fleet_options(b)
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
    g.add_argument("--wheel", type=Path, metavar="WHEEL.csv",
                   help="a wheel odometer's forward speed at the axle centre (--wheel-lever-arm): t,speed [,sigma] "
                        "(m/s); its scale factor is estimated (docs/filter.md)")
    g.add_argument("--nhc", action="store_true",
                   help="a wheeled vehicle: the non-holonomic constraint (no sideways and no vertical body velocity) "
                        "every 0.1 s")
    g.add_argument("--rest", type=_Outage(), action="append", metavar="START,END",
                   help="the vehicle stood still over this interval of sensor time (s): a zero-velocity update at "
                        "every attitude update inside it and a zero-rate update (the gyro bias) at its end; "
                        "repeatable")
    _filter_options(g, with_aiding=False)
    _smooth_option(g)
    p.add_argument("--timing", action="store_true", help="print read/compute/write seconds to stderr")
    r = p.add_argument_group("redundant IMUs (several IMU files; noise from --grade/--imu-spec; docs/redundancy.md)")
    r.add_argument("--fdi-log", type=Path, metavar="FDI.csv",
                   help="write the fault events: t,event,imu,sensor,axis,statistic,threshold (header only: no fault)")
    r.add_argument("--false-alarm", type=_real(0.0, 0.5, above=True), default=1e-6, metavar="P",
                   help="design false-alarm probability of each test")
    p.set_defaults(func=_cmd_nav)


def _cmd_nav(args: argparse.Namespace) -> int:
    from ..common import files
    from ..nav import NavOptions, run_nav

    from ..core.settings import strapdown_from_options

    opts = NavOptions(input=args.input, strapdown=strapdown_from_options(args), timing=args.timing)
    if args.each:
        return _cmd_nav_each(args, opts)
    refused = _fleet_option_alone(args, "nav", "several files, each navigated on its own")
    if refused is not None:
        return refused
    if args.init is None:
        print("mavins nav: error: --init INIT.json is required (the initial state)", file=sys.stderr)
        return EXIT_USAGE
    try:
        if len(args.imu) > 1 or args.fdi_log is not None:
            return _cmd_nav_fdi(args, opts)
        if args.gnss is None and args.baro is None and args.mag is None and args.rest is None \
                and args.wheel is None and not args.nhc:
            if args.smooth:
                print("mavins nav: error: --smooth smooths the aided solution: give --gnss, --baro, --mag, --rest, "
                      "--wheel or --nhc",
                      file=sys.stderr)
                return EXIT_USAGE
            rows = run_nav(args.imu[0], args.init, args.output, opts)
        else:
            from ..core.aided import DEFAULT_SIGMA_NHC
            from ..nav import AidingFiles, run_nav_aided

            rows, counts = run_nav_aided(args.imu[0], args.init, args.output, opts,
                                         AidingFiles(args.gnss, args.baro, args.mag, args.declination,
                                                     tuple(args.rest or ()), args.date, _delays(args),
                                                     args.mag_bias, args.scale_factors, args.mag_unit,
                                                     args.misalignment, args.smooth, args.wheel,
                                                     tuple(args.wheel_lever_arm),
                                                     None if args.wheel_scale is None else args.wheel_scale / 100.0,
                                                     args.wheel_sigma, DEFAULT_SIGMA_NHC if args.nhc else 0.0),
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
    from ..common import files
    from ..nav import run_nav_batch

    bad = [name for name, v in (("--gnss", args.gnss), ("--baro", args.baro), ("--mag", args.mag),
                                ("--rest", args.rest), ("--fdi-log", args.fdi_log), ("--wheel", args.wheel),
                                ("--nhc", args.nhc or None),
                                ("--smooth", args.smooth or None)) if v is not None]
    if bad:
        print(f"mavins nav: error: --each navigates free inertial; {', '.join(bad)} cannot go with it",
              file=sys.stderr)
        return EXIT_USAGE
    try:
        outcomes, summary = run_nav_batch(args.imu, args.init, args.output, opts,  # type: ignore[arg-type]
                                          jobs=args.jobs, cluster=args.cluster)
    except (files.DataFileError, files.ResourceError, ValueError, ImportError) as exc:
        print(f"mavins nav: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    failed = 0
    for o in outcomes:
        if not o.error:
            print(f"mavins nav: wrote {o.solution_rows} solution rows to {o.output}", file=sys.stderr)
        else:
            failed += 1
            print(f"mavins nav: error: {o.error}", file=sys.stderr)
    print(f"mavins nav: {len(outcomes) - failed} of {len(outcomes)} files navigated; summary in {summary}",
          file=sys.stderr)
    return EXIT_USAGE if failed else 0


def _cmd_nav_fdi(args: argparse.Namespace, opts: object) -> int:
    """``mavins nav IMU0.csv IMU1.csv ... [--fdi-log FDI.csv]``: parse, call mavins.navfdi, report."""
    from ..common import files
    from ..navfdi import run_nav_fdi, strapdown_keywords

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
