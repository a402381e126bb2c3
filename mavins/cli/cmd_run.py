"""``mavins run``: the live MAVLink INS service."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .options import (
    EXIT_USAGE, POSITIVE, SYSID, _ODOMETRY_FRAMES, _apply_config, _engine_config, _ingest_config, _nav_options,
    _positive_int, _real, _say, _setup_logging, _subparser
)


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
    p.add_argument("-o", "--output", type=Path, metavar="NAV.csv", help="also write each output set as a solution row (a CSV is written once a second; .parquet by the suffix, complete at the stop)")
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


def _cmd_run(args: argparse.Namespace) -> int:
    import signal
    import threading

    _apply_config(args, args.parser)
    from ..common.files import DataFileError, check_outputs

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
    from ..link.publish import PublishConfig
    from ..service import Service, ServiceConfig

    try:
        engine_cfg = _engine_config(args)
    except ValueError as exc:
        print(f"mavins run: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    from ..link.links import PeerPolicy
    from ..link.signing import KeyFileError, load_key

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
        from ..record.recorder import Recorder

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
