"""Offline tools on bad input: a clear error, a non-zero exit, nothing destroyed, nothing left behind.

The rule (docs/reliability.md, "Offline tools on bad input"), for every
subcommand: an input that cannot be what it claims (wrong format, empty, no
IMU message of the chosen kind), an output that is also an input, a request
too large for the machine, or a numeric option out of its range is refused
with one line on stderr (what was expected, what was found) and exit code 2,
and no file is created, truncated or changed. Outputs are written beside
their target and renamed into place only on success, so Ctrl-C or SIGTERM
leaves nothing behind either. A damaged or cut log replays what it can and
says how much it skipped and where.

Everything runs in process through ``mavins.cli.main`` (the console script's
entry point), so the whole table takes seconds; each case compares a snapshot
of its working directory (names, sizes, contents, modification times, hidden
files included) before and after.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import random
import re
import signal
import struct
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mavins import cli
from mavins.common import files
from mavins.common.files import DataFileError, ResourceError
from mavins.link.mavlink import mavlink
from mavins.replay import open_log

REPO = Path(__file__).resolve().parents[2]
ULG = REPO / "data" / "px4-sample" / "sample.ulg"
PX4_ARGS = ["--lat", "47.4", "--lon", "8.5", "--alt", "500", "--align", "2", "--heading", "-35"]
POSITION = ["--lat", "47.0", "--lon", "8.0", "--alt", "500"]
NAV_ARGS = [*POSITION, "--heading", "0", "--align", "1", "--gyro-bias", "none"]
INIT = {"t": 0.0, "lat": 47.0, "lon": 8.0, "h": 500.0, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 0.0, "pitch": 0.0,
        "yaw": 30.0}
G = 9.80665


# -- running the command line in process ------------------------------------------------------


def run_cli(*argv: object) -> tuple[int, str]:
    """(exit code, stderr) of ``mavins ARGV`` run in this process."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = cli.main([str(a) for a in argv])
        except SystemExit as exc:  # argparse
            code = exc.code if isinstance(exc.code, int) else 1
    return code, err.getvalue()


def snapshot(root: Path) -> dict[str, tuple[int, str, int, int]]:
    """Every file and folder under ``root``: size, content hash, mtime, mode."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st_ = p.lstat()
            digest = hashlib.sha1(p.read_bytes()).hexdigest() if p.is_file() and not p.is_symlink() else "dir"
            out[str(p.relative_to(root))] = (st_.st_size, digest, st_.st_mtime_ns, st_.st_mode)
    return out


def error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if "error:" in line]


def assert_refused(code: int, stderr: str, words: list[str], *, usage: bool = False) -> str:
    """Exit 2, no traceback, one error line holding ``words``; nothing else on stderr unless argparse usage."""
    assert "Traceback" not in stderr, stderr
    assert code == 2, f"exit {code}:\n{stderr}"
    errors = error_lines(stderr)
    assert len(errors) == 1, f"expected one error line:\n{stderr}"
    line = errors[0]
    assert line.startswith("mavins"), line
    if not usage:
        lines = [ln for ln in stderr.splitlines() if ln.strip()]
        assert lines == [line], f"expected exactly one stderr line:\n{stderr}"
    for w in words:
        assert w in line, f"{w!r} not in: {line}"
    return line


# -- input files --------------------------------------------------------------------------------


def record(t: float, frame: bytes) -> bytes:
    return struct.pack(">Q", int(round(t * 1e6))) + frame


def tlog(seconds: float = 3.0, rate: float = 100.0, *, imu: bool = True, t0: float = 1000.0) -> bytes:
    """A tlog of a vehicle at rest, level: HIGHRES_IMU at ``rate`` (or none) and a HEARTBEAT each second."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    out = bytearray()
    for i in range(int(seconds * rate)):
        t = t0 + i / rate
        if i % int(rate) == 0:
            hb = mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0)
            out += record(t, hb.pack(mav))
        if imu:
            m = mav.highres_imu_encode(int(round(t * 1e6)), 0.0, 0.0, -G, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                       0.0, 0b111111, 0)
            out += record(t, m.pack(mav))
    return bytes(out)


IMU_FMT, IMU_COLS = "QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"


def _df_record(msg_type: int, fmt: str, *values: object) -> bytes:
    return b"\xa3\x95" + bytes([msg_type]) + struct.pack("<" + fmt, *values)


def _df_fmt(msg_type: int, name: str, fmt: str, cols: str) -> bytes:
    size = 3 + struct.calcsize("<" + fmt.replace("N", "16s").replace("Z", "64s").replace("n", "4s"))
    return _df_record(128, "BB4s16s64s", msg_type, size, name.encode(), fmt.encode(), cols.encode())


def dataflash(seconds: float = 3.0, rate: float = 100.0, *, imu: bool = True) -> bytes:
    """An ArduPilot DataFlash log: the FMT of FMT and of IMU, then IMU records of a vehicle at rest."""
    buf = bytearray(_df_fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"))
    buf += _df_fmt(130, "IMU", IMU_FMT, IMU_COLS)
    if imu:
        for i in range(int(seconds * rate)):
            buf += _df_record(130, IMU_FMT, 100_000_000 + i * int(1e6 / rate), 0, 0.0, 0.0, 0.0, 0.0, 0.0, -G,
                              0, 0, 40.0, 1, 1, 400, 400)
    return bytes(buf)


def imu_csv(n: int = 40) -> str:
    from sim.motion import stationary

    m = stationary(INIT["lat"], INIT["h"], INIT["roll"], INIT["pitch"], INIT["yaw"], 0.01, n)
    rows = np.column_stack([m.t, m.dtheta, m.dv])
    return ",".join(files.INCREMENT_COLUMNS) + "\n" + files.format_rows(rows)


def rrd_file(path: Path) -> None:
    """A small valid Rerun recording."""
    import rerun as rr

    rec = rr.RecordingStream("mavins-test")
    rec.set_sinks(rr.FileSink(str(path)))
    rec.log("/x", rr.Scalars(1.0))
    rec.flush(timeout_sec=10.0)
    rec.disconnect()


_RNG = random.Random(20261125)
RANDOM = bytes(_RNG.getrandbits(8) for _ in range(5000))
STATIC_TOML = (REPO / "sim" / "scenarios" / "static.toml").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def rrd_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    p = tmp_path_factory.mktemp("rrd") / "valid.rrd"
    rrd_file(p)
    return p.read_bytes()


@pytest.fixture
def world(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rrd_bytes: bytes) -> Path:
    """A working directory with good and bad inputs of every kind; the cases run in it."""
    w = tmp_path / "w"
    w.mkdir()
    ulg_head = ULG.read_bytes()[:300_000]
    content: dict[str, bytes | str] = {
        "imu.csv": imu_csv(), "init.json": json.dumps(INIT), "empty.csv": "", "header.csv": imu_csv().split("\n")[0] + "\n",
        "rand.csv": RANDOM, "badjson.json": '{"t": 0.0, "lat": 47.0 "lon": 8.0}', "lat95.json": json.dumps({**INIT, "lat": 95}),
        "existing.csv": "precious\n",
        "good.tlog": tlog(), "hb.tlog": tlog(imu=False), "rand.tlog": RANDOM, "empty.tlog": b"",
        "px4.tlog": ulg_head, "df.tlog": dataflash(), "good.bin": dataflash(), "fmtonly.bin": dataflash(imu=False),
        "rand.bin": RANDOM, "empty.bin": b"", "rand.ulg": RANDOM, "empty.ulg": b"", "tlog.ulg": tlog(),
        "defs.ulg": ULG.read_bytes()[:20_000], "log.csv": "t,x\n1,2\n",
        "my.toml": STATIC_TOML, "empty.toml": "", "bad.toml": "duration = = 1\n", "rand.toml": RANDOM,
        "key.hex": "ab" * 32 + "\n", "rand.key": RANDOM[:100], "rate0.toml": "rate = 0\n", "cfg.toml": "rate = 10\n",
        "not.toml": RANDOM, "valid.rrd": rrd_bytes, "rand.rrd": b"RRF2" + RANDOM, "empty.rrd": b"",
        "tlog.rrd": tlog(0.5), "ulg.rrd": ulg_head[:1000], "blocker": "",
    }
    for name, data in content.items():
        (w / name).write_bytes(data if isinstance(data, bytes) else data.encode("utf-8"))
    os.chmod(w / "key.hex", 0o600)
    os.chmod(w / "rand.key", 0o600)
    (w / "sub").mkdir()
    (w / "outdir2").mkdir()
    (w / "outdir2" / "truth.csv").write_text(STATIC_TOML, encoding="utf-8")  # a scenario named like an output
    (w / "link.csv").symlink_to("imu.csv")
    monkeypatch.chdir(w)
    return w


# -- the table: (id, argv, words the one error line must hold) -----------------------------------

NAV = ["--init", "init.json", "-o", "out.csv"]
CASES: list[tuple[str, list[str], list[str]]] = [
    # nav
    ("issue1-nav-output-is-the-imu-input", ["nav", "imu.csv", "--init", "init.json", "-o", "imu.csv"],
     ["imu.csv", "also the input IMU"]),
    ("nav-output-is-the-init-input", ["nav", "imu.csv", "--init", "init.json", "-o", "init.json"],
     ["also the input --init"]),
    ("nav-output-is-the-input-through-a-symlink", ["nav", "imu.csv", "--init", "init.json", "-o", "link.csv"],
     ["also the input IMU"]),
    ("nav-output-is-a-directory", ["nav", "imu.csv", "--init", "init.json", "-o", "sub"], ["directory"]),
    ("nav-output-under-a-file", ["nav", "imu.csv", "--init", "init.json", "-o", "blocker/out.csv"], ["cannot write"]),
    ("nav-imu-missing", ["nav", "nofile.csv", *NAV], ["nofile.csv", "no such file"]),
    ("nav-imu-empty", ["nav", "empty.csv", *NAV], ["empty.csv", "empty", "expected"]),
    ("nav-imu-header-only", ["nav", "header.csv", *NAV], ["header.csv", "no data rows"]),
    ("nav-imu-random-bytes", ["nav", "rand.csv", *NAV], ["rand.csv", "line"]),
    ("nav-imu-is-a-tlog", ["nav", "good.tlog", *NAV], ["good.tlog"]),
    ("nav-rates-columns-absent", ["nav", "imu.csv", *NAV, "--input", "rates"], ["line 1", "gyro_x"]),
    ("nav-init-bad-json", ["nav", "imu.csv", "--init", "badjson.json", "-o", "out.csv"], ["invalid JSON"]),
    ("nav-init-latitude-95", ["nav", "imu.csv", "--init", "lat95.json", "-o", "out.csv"], ["lat", "outside"]),
    ("nav-bad-input-keeps-the-existing-output", ["nav", "rand.csv", "--init", "init.json", "-o", "existing.csv"],
     ["rand.csv"]),
    # sim
    ("issue4-sim-duration-1e9", ["sim", "static", "--duration", "1e9", "-o", "simout"],
     ["100,000,000,000 samples", "memory", "GiB", "available"]),
    ("sim-rate-too-high-for-memory", ["sim", "static", "--rate", "1e6", "--duration", "1e5", "-o", "simout"],
     ["memory"]),
    ("sim-less-than-one-sample", ["sim", "static", "--duration", "1e-6", "-o", "simout"], ["less than one IMU sample"]),
    ("sim-scenario-missing", ["sim", "nosuch.toml", "-o", "simout"], ["nosuch.toml", "no such scenario"]),
    ("sim-scenario-random-bytes", ["sim", "rand.toml", "-o", "simout"], ["rand.toml", "expected a scenario TOML"]),
    ("sim-scenario-empty", ["sim", "empty.toml", "-o", "simout"], ["empty.toml"]),
    ("sim-scenario-bad-toml", ["sim", "bad.toml", "-o", "simout"], ["bad.toml"]),
    ("sim-output-dir-is-a-file", ["sim", "static", "--duration", "1", "-o", "imu.csv"], ["expected a directory"]),
    ("sim-output-is-the-scenario", ["sim", "outdir2/truth.csv", "--duration", "1", "-o", "outdir2"],
     ["also the input SCENARIO"]),
    # run (every check happens before a link is opened)
    ("run-signing-key-missing", ["run", "--signing-key", "nokey"], ["nokey", "cannot read"]),
    ("run-signing-key-random-bytes", ["run", "--signing-key", "rand.key"], ["rand.key", "32 raw bytes"]),
    ("run-output-is-the-signing-key", ["run", "--signing-key", "key.hex", "-o", "key.hex"],
     ["also the input --signing-key"]),
    ("run-tlog-and-output-one-file", ["run", "--tlog", "x.tlog", "-o", "x.tlog"], ["name the same file"]),
    ("run-rerun-is-the-config", ["run", "--config", "cfg.toml", "--rerun", "cfg.toml"], ["also the input --config"]),
    ("run-output-is-the-master-log", ["run", "--master", "good.tlog", "-o", "good.tlog"], ["also the input --master"]),
    ("issue6-run-rate-0-from-config", ["run", "--config", "rate0.toml"], ["rate", "outside"]),
    ("run-config-not-toml", ["run", "--config", "not.toml"], ["--config", "not.toml"]),
    # replay
    ("issue2-replay-random-bytes-tlog", ["replay", "rand.tlog", "-o", "out.csv", *NAV_ARGS],
     ["rand.tlog", "expected a MAVLink telemetry log", "no valid MAVLink message"]),
    ("issue2-replay-empty-tlog", ["replay", "empty.tlog", "-o", "out.csv", *NAV_ARGS], ["empty.tlog", "empty"]),
    ("issue2-replay-random-bytes-bin", ["replay", "rand.bin", "-o", "out.csv", *NAV_ARGS],
     ["rand.bin", "expected an ArduPilot DataFlash log", "found bytes"]),
    ("issue2-replay-ulog-named-tlog", ["replay", "px4.tlog", "-o", "out.csv", *NAV_ARGS],
     ["expected a MAVLink telemetry log", "found a PX4 ULog", "rename it to .ulg"]),
    ("issue3-replay-random-bytes-ulg", ["replay", "rand.ulg", "-o", "out.csv", *NAV_ARGS],
     ["rand.ulg", "expected a PX4 ULog"]),
    ("replay-empty-bin", ["replay", "empty.bin", "-o", "out.csv", *NAV_ARGS], ["empty"]),
    ("replay-empty-ulg", ["replay", "empty.ulg", "-o", "out.csv", *NAV_ARGS], ["empty"]),
    ("replay-tlog-named-ulg", ["replay", "tlog.ulg", "-o", "out.csv", *NAV_ARGS], ["expected a PX4 ULog"]),
    ("replay-dataflash-named-tlog", ["replay", "df.tlog", "-o", "out.csv", *NAV_ARGS],
     ["found an ArduPilot DataFlash log", "rename it to .bin"]),
    ("replay-ulog-cut-in-its-definitions", ["replay", "defs.ulg", "-o", "out.csv", *NAV_ARGS],
     ["sensor_combined", "found none"]),
    ("replay-unknown-log-type", ["replay", "log.csv", "-o", "out.csv", *NAV_ARGS], ["unknown log type"]),
    ("replay-log-missing", ["replay", "nofile.tlog", "-o", "out.csv", *NAV_ARGS], ["no such file"]),
    ("replay-tlog-without-imu", ["replay", "hb.tlog", "-o", "out.csv", *NAV_ARGS],
     ["expected IMU messages", "found none among", "HEARTBEAT"]),
    ("replay-other-imu-kind", ["replay", "good.tlog", "-o", "out.csv", *NAV_ARGS, "--imu", "raw"],
     ["expected RAW_IMU messages", "found only", "HIGHRES_IMU"]),
    ("replay-other-imu-id", ["replay", "good.tlog", "-o", "out.csv", *NAV_ARGS, "--imu-id", "3"],
     ["with id 3", "found only", "HIGHRES_IMU id 0"]),
    ("replay-bin-without-imu-records", ["replay", "fmtonly.bin", "-o", "out.csv", *NAV_ARGS], ["no IMU record"]),
    ("replay-no-initial-position", ["replay", "good.tlog", "-o", "out.csv", "--heading", "0", "--align", "1"],
     ["no solution rows", "--lat"]),
    ("replay-log-shorter-than-the-alignment", ["replay", "good.tlog", "-o", "out.csv", *POSITION, "--align", "100"],
     ["no solution rows", "alignment"]),
    ("replay-output-is-the-log", ["replay", "good.tlog", "-o", "good.tlog", *NAV_ARGS], ["also the input LOG"]),
    ("replay-rerun-is-the-log", ["replay", "good.tlog", "-o", "out.csv", "--rerun", "good.tlog", *NAV_ARGS],
     ["--rerun is also the input LOG"]),
    ("replay-output-and-rerun-one-file", ["replay", "good.tlog", "-o", "x.rrd", "--rerun", "x.rrd", *NAV_ARGS],
     ["name the same file"]),
    ("replay-output-is-the-config", ["replay", "good.tlog", "-o", "cfg.toml", "--config", "cfg.toml"],
     ["also the input --config"]),
    ("replay-bad-log-keeps-the-existing-output", ["replay", "rand.tlog", "-o", "existing.csv", *NAV_ARGS],
     ["rand.tlog"]),
    # demo (checked before the simulator, the service or the recording start)
    ("demo-scenario-missing", ["demo", "--scenario", "nosuch.toml", "--no-rerun"], ["no such scenario"]),
    ("demo-scenario-random-bytes", ["demo", "--scenario", "rand.toml", "--no-rerun"], ["expected a scenario TOML"]),
    ("demo-duration-too-large", ["demo", "--duration", "1e9", "--no-rerun"], ["memory"]),
    ("demo-recording-is-the-scenario", ["demo", "--scenario", "my.toml", "--rerun", "my.toml"],
     ["also the input --scenario"]),
    # review
    ("issue5-review-not-a-recording", ["review", "good.tlog", "--screenshot", "x.png"],
     ["expected a Rerun recording", "found"]),
    ("review-recording-named-rrd-is-a-tlog", ["review", "tlog.rrd", "--screenshot", "x.png"],
     ["expected a Rerun recording"]),
    ("review-ulog-named-rrd", ["review", "ulg.rrd", "--screenshot", "x.png"], ["found a PX4 ULog"]),
    ("review-random-bytes-after-the-magic", ["review", "rand.rrd", "--screenshot", "x.png"],
     ["not a readable Rerun recording"]),
    ("review-empty", ["review", "empty.rrd", "--screenshot", "x.png"], ["empty"]),
    ("review-missing", ["review", "none.rrd", "--screenshot", "x.png"], ["no such recording"]),
    ("review-screenshot-is-the-input", ["review", "valid.rrd", "--screenshot", "valid.rrd"], ["also the input"]),
    ("review-screenshot-is-a-directory", ["review", "valid.rrd", "--screenshot", "sub"], ["directory"]),
    # analyze
    ("analyze-unknown-scenario", ["analyze", "nosuch", "--runs", "2", "-o", "an"], ["no such scenario"]),
    ("analyze-output-is-a-file", ["analyze", "static", "--runs", "2", "-o", "good.tlog"], ["names a file"]),
    ("analyze-imu-spec-missing", ["analyze", "static", "--runs", "2", "-o", "an", "--imu-spec", "none.toml"],
     ["--imu-spec", "none.toml"]),
    # key
    ("key-exists", ["key", "key.hex"], ["exists", "--force"]),
    ("key-is-a-directory", ["key", "sub", "--force"], ["directory"]),
    ("key-under-a-file", ["key", "blocker/k.hex"], ["cannot write"]),
]


def test_the_table_covers_every_subcommand() -> None:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert {c[1][0] for c in CASES} == set(sub.choices), "a subcommand has no bad-input case"


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_exit_2_and_nothing_written(world: Path, case) -> None:  # type: ignore[no-untyped-def]
    _, argv, words = case
    before = snapshot(world)
    code, stderr = run_cli(*argv)
    assert_refused(code, stderr, words)
    assert snapshot(world) == before, "a file was created, changed or left behind"


# -- numeric options: every one validated at parse time, its range in --help ---------------------

REQUIRED = {"nav": ["imu.csv", "--init", "init.json", "-o", "out.csv"], "sim": ["static", "-o", "simout"],
            "run": [], "replay": ["good.tlog", "-o", "out.csv"], "demo": [], "review": ["valid.rrd", "--screenshot", "x.png"],
            "key": ["new.key"], "analyze": ["static", "--runs", "2", "-o", "an"]}


def _numeric_options() -> list[tuple[str, str, object]]:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out = []
    for name, p in sub.choices.items():
        for a in p._actions:
            if a.option_strings and (hasattr(a.type, "describe") or a.type in (int, float)):
                out.append((name, a.option_strings[-1], a))
    return out


def _bad_values(kind: object) -> list[str]:
    """Values outside an option's range (and not numbers at all)."""
    if isinstance(kind, cli._Range):
        vals = ["abc", "1.5x"]
        if kind.kind is float:
            vals += ["nan", "inf", "-inf"]
        else:
            vals += ["1.5"]
        if kind.lo is not None:
            vals.append(str(kind.lo) if kind.lo_open else str(kind.lo - 1))
        if kind.hi is not None:
            vals.append(str(kind.hi * 2 + 1))
        return vals
    if isinstance(kind, cli._Words):  # --aiding (none), --imus (all)
        return {"none": ["gps", "gnss,foo", ","], "all": ["0", "0,3", "a,b", "any"]}[kind.empty]
    name = type(kind).__name__
    return {"_Heading": ["400", "-361", "nan", "north"], "_Speed": ["0", "-1", "nan", "fast"],
            "_Size": ["10x10", "20000x900", "abc"], "_Seconds": ["0", "-5", "nan", "soon"],
            "_Vec3": ["1,2", "1,2,nan", "1,2,5000", "abc"],
            "_Outage": ["5,1", "-1,2", "nan,3", "abc"],
            "_Date": ["2025-13-01", "1899", "2100.5", "nan", "soon"],
            "_Disturbance": ["5,1,0,0,0.1", "1,2,0,0", "1,2,0,0,nan", "1,2,0,0,11", "abc"]}[name]


NUMERIC = _numeric_options()


def test_every_numeric_option_is_validated_with_its_range_in_help() -> None:
    assert len(NUMERIC) >= 35, len(NUMERIC)
    for cmd, opt, action in NUMERIC:
        assert hasattr(action.type, "describe"), f"mavins {cmd} {opt}: type={action.type!r} checks no range"
        rng = action.type.describe(action.metavar if isinstance(action.metavar, str) else None)
        assert rng.split(" in ")[-1] in (action.help or ""), f"mavins {cmd} {opt}: --help does not show {rng!r}"
        if action.default is not None and action.default != argparse.SUPPRESS:  # the defaults are in range
            action.type(str(action.default) if not isinstance(action.default, tuple) else "x".join(
                map(str, action.default)))


@pytest.mark.parametrize("cmd,opt,action", NUMERIC, ids=[f"{c}{o}" for c, o, _ in NUMERIC])
def test_numeric_option_out_of_range_is_refused_at_parse_time(world: Path, cmd: str, opt: str, action) -> None:  # type: ignore[no-untyped-def]
    before = snapshot(world)
    for value in _bad_values(action.type):
        code, stderr = run_cli(cmd, *REQUIRED[cmd], f"{opt}={value}")
        line = assert_refused(code, stderr, [opt], usage=True)
        assert "usage:" in stderr, stderr
        assert value in line or repr(value) in line, line
    assert snapshot(world) == before


def test_heading_words_are_the_engines() -> None:
    from mavins.live import engine

    assert cli.HEADING_WORDS == engine.HEADING_WORDS


def test_aiding_words_are_the_filters() -> None:
    from mavins.live import livefilter

    assert cli.AIDING_WORDS == livefilter.AIDING_KINDS


def test_issue6_run_rate_0_and_other_non_positive_service_values(world: Path) -> None:
    for argv in (["--rate", "0"], ["--rate", "-50"], ["--duration", "0"], ["--duration", "-1"], ["--align", "-1"],
                 ["--max-gap", "0"], ["--peer-timeout", "0"], ["--max-peers", "0"], ["--request-imu", "0"],
                 ["--samples", "0"], ["--sysid", "0"], ["--compid", "256"], ["--rate", "nan"]):
        code, stderr = run_cli("run", *argv)
        assert_refused(code, stderr, [argv[0]], usage=True)


# -- damaged logs replay what they can, and say so ---------------------------------------------


def _replay_ok(world: Path, log: str, *extra: str) -> str:
    code, stderr = run_cli("replay", log, "-o", "out.csv", *extra)
    assert code == 0, stderr
    assert "Traceback" not in stderr, stderr
    rows = (world / "out.csv").read_text().splitlines()
    assert rows[0].startswith("t,lat,lon") and len(rows) > 10
    assert not [p for p in world.iterdir() if p.name.startswith(".")], "temporary files left behind"
    return stderr


def test_intact_logs_replay_without_a_warning(world: Path) -> None:
    for log in ("good.tlog", "good.bin"):
        stderr = _replay_ok(world, log, *NAV_ARGS)
        assert "warning" not in stderr, stderr


def test_issue7_ulog_cut_at_45_percent_says_it_ended_early(world: Path) -> None:
    data = ULG.read_bytes()
    (world / "cut.ulg").write_bytes(data[: int(0.45 * len(data))])
    stderr = _replay_ok(world, "cut.ulg", *PX4_ARGS)
    assert "the log ends early" in stderr and "incomplete" in stderr, stderr
    assert "replayed what could be read" in stderr and "sensor time" in stderr, stderr


def test_cut_tlog_and_bin_say_where_they_end(world: Path) -> None:
    t = tlog(3.0)
    (world / "cut.tlog").write_bytes(t[: len(t) // 2 + 7])
    b = dataflash(3.0)
    (world / "cut.bin").write_bytes(b[: len(b) // 2 + 5])
    for log in ("cut.tlog", "cut.bin"):
        stderr = _replay_ok(world, log, *NAV_ARGS)
        assert "the log ends early: its last record, from byte" in stderr, stderr


def test_garbage_inside_a_log_is_skipped_and_located(world: Path) -> None:
    junk = bytes(range(1, 200))  # no 0xFD/0xFE: nothing in it looks like a record
    t = tlog(3.0)
    (world / "junk.tlog").write_bytes(t[:5000] + junk + t[5000:])
    stderr = _replay_ok(world, "junk.tlog", *NAV_ARGS)
    m = re.search(r"junk.tlog: skipped (\d+) unreadable bytes .* in 1 place: byte (\d+) \(\d+ bytes, after sensor "
                  r"time 10\d\d\.\d+ s\)", stderr)
    assert m, stderr
    # the record the junk fell into (it starts at most one record before byte 5000) and the junk itself
    assert 5000 - 300 < int(m.group(2)) <= 5000 and 199 < int(m.group(1)) < 199 + 300, stderr
    b = dataflash(3.0)
    cut = 2 * (3 + struct.calcsize("<BB4s16s64s")) + 50 * (3 + struct.calcsize("<" + IMU_FMT))  # after 50 IMU records
    (world / "junk.bin").write_bytes(b[:cut] + junk + b[cut:])
    stderr = _replay_ok(world, "junk.bin", *NAV_ARGS)
    assert "junk.bin: skipped 199 unreadable bytes" in stderr and f"byte {cut} (199 bytes, after sensor time" in stderr, \
        stderr


# -- Ctrl-C and SIGTERM leave nothing behind -------------------------------------------------------


def _interrupt_on(monkeypatch: pytest.MonkeyPatch, target: object, name: str, after: int,
                  how: Callable[[], None]) -> None:
    original = getattr(target, name)
    calls = [0]

    def wrapper(*a, **k):  # type: ignore[no-untyped-def]
        calls[0] += 1
        if calls[0] > after:
            how()
        return original(*a, **k)

    monkeypatch.setattr(target, name, wrapper)


def _ctrl_c() -> None:
    raise KeyboardInterrupt


def _sigterm() -> None:
    os.kill(os.getpid(), signal.SIGTERM)


@pytest.mark.parametrize("how,code", [(_ctrl_c, 130), (_sigterm, 143)], ids=["ctrl-c", "sigterm"])
def test_interrupted_writers_leave_the_old_output_and_no_temporary(world: Path, monkeypatch: pytest.MonkeyPatch,
                                                                   how, code: int) -> None:  # type: ignore[no-untyped-def]
    import mavins.live.pipeline

    previous = signal.getsignal(signal.SIGTERM)
    before = snapshot(world)
    with monkeypatch.context() as m:
        _interrupt_on(m, files, "write_rows", 0, how)  # nav: while writing the solution
        assert run_cli("nav", "imu.csv", "--init", "init.json", "-o", "existing.csv")[0] == code
    with monkeypatch.context() as m:
        _interrupt_on(m, mavins.live.pipeline.Pipeline, "handle", 100, how)  # replay: halfway through the log
        assert run_cli("replay", "good.tlog", "-o", "existing.csv", "--rerun", "new.rrd", *NAV_ARGS)[0] == code
    with monkeypatch.context() as m:
        _interrupt_on(m, files, "write_table", 1, how)  # sim: between its files
        assert run_cli("sim", "static", "--duration", "2", "-o", "simout")[0] == code
    assert snapshot(world) == before
    assert signal.getsignal(signal.SIGTERM) == previous, "the SIGTERM handler is put back"


def test_successful_writers_replace_in_one_step_and_leave_no_temporary(world: Path) -> None:
    os.chmod(world / "existing.csv", 0o640)
    code, stderr = run_cli("nav", "imu.csv", "--init", "init.json", "-o", "existing.csv")
    assert code == 0, stderr
    assert (world / "existing.csv").read_text().startswith("t,lat,lon")
    assert (world / "existing.csv").stat().st_mode & 0o777 == 0o640, "an existing output keeps its mode"
    code, stderr = run_cli("key", "new.key")
    assert code == 0, stderr
    assert (world / "new.key").stat().st_mode & 0o777 == 0o600
    code, stderr = run_cli("sim", "static", "--duration", "1", "-o", "a/b/simout")
    assert code == 0, stderr
    assert sorted(p.name for p in (world / "a/b/simout").iterdir()) == sorted(
        ["imu.csv", "imu_rates.csv", "truth.csv", "init.json", "gnss.csv", "baro.csv"])
    hidden = [p for p in world.rglob(".*")]
    assert not hidden, f"temporary files left behind: {hidden}"


def test_review_without_a_viewer_writes_nothing(world: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A valid recording where the viewer cannot be found (an empty PATH hides Xvfb, installed or
    not): exit 1 (viewer), one line, and no PNG, not even an empty one or a temporary file."""
    from mavins.record.review import ViewerUnavailable, check_dependencies

    empty = world.parent / "empty-path"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))
    with pytest.raises(ViewerUnavailable):
        check_dependencies()
    before = snapshot(world)
    code, stderr = run_cli("review", "valid.rrd", "--screenshot", "x.png")
    assert code == 1 and len(error_lines(stderr)) == 1 and "Traceback" not in stderr, stderr
    assert snapshot(world) == before


# -- chunked nav: bit-identical to the whole-array run, errors still name their line -------------


def test_nav_in_chunks_is_bit_identical_and_locates_errors(world: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from mavins.core.runner import navigate

    text = imu_csv(503)
    (world / "long.csv").write_text(text, encoding="utf-8")
    from mavins import nav

    monkeypatch.setattr(files, "CHUNK_BYTES", 1000)  # about 6 rows a chunk: 80 chunks, updates across borders
    monkeypatch.setattr(nav, "PIECE_ROWS", 5)  # and each chunk integrated in pieces of 5 rows (writer thread)
    for samples in ("1", "2", "3", "6"):
        code, stderr = run_cli("nav", "long.csv", "--init", "init.json", "-o", "sol.csv", "--samples", samples)
        assert code == 0, stderr
        got = np.loadtxt(world / "sol.csv", delimiter=",", skiprows=1, ndmin=2)
        data = files.read_table(world / "long.csv", files.INCREMENT_COLUMNS)
        want = navigate(data[:, 0], data[:, 1:4], data[:, 4:7], INIT, samples=int(samples))
        assert got.shape == want.shape and np.array_equal(got.view(np.uint64), want.view(np.uint64)), samples
    lines = text.splitlines()
    cells = lines[399].split(",")
    cells[3] = "nan"
    lines[399] = ",".join(cells)
    (world / "nan.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    code, stderr = run_cli("nav", "nan.csv", "--init", "init.json", "-o", "sol2.csv")
    assert_refused(code, stderr, ["line 400", "dtheta_z", "not finite"])
    assert not (world / "sol2.csv").exists()
    lines = text.splitlines()
    cells = lines[399].split(",")
    cells[0] = lines[397].split(",")[0]  # the time of two rows before
    lines[399] = ",".join(cells)
    (world / "back.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    code, stderr = run_cli("nav", "back.csv", "--init", "init.json", "-o", "sol2.csv")
    assert_refused(code, stderr, ["line 400", "does not increase"])


def test_resource_estimates() -> None:
    """The checks refuse with the estimate; sizes that fit pass."""
    files.check_resources("tiny", memory=1, disk=1, disk_at=Path("."))
    with pytest.raises(ResourceError, match=r"needs about .* of memory, the machine has .* available"):
        files.check_resources("huge", memory=1e18)
    with pytest.raises(ResourceError, match=r"needs about .* of disk"):
        files.check_resources("huge", disk=1e18, disk_at=Path("."))


# -- fuzz: the tlog, DataFlash and ULog readers never raise anything but DataFileError -----------

FUZZ_EXAMPLES = int(os.environ.get("MAVINS_FUZZ_EXAMPLES", "300"))
SAMPLES = {".tlog": tlog(1.0), ".bin": dataflash(1.0), ".ulg": ULG.read_bytes()[:120_000]}


@st.composite
def log_files(draw: st.DrawFn) -> tuple[str, bytes]:
    suffix = draw(st.sampled_from(sorted(SAMPLES)))
    base = SAMPLES[suffix]
    kind = draw(st.sampled_from(["random", "cut", "mutated", "cut_mutated", "other_format"]))
    if kind == "random":
        prefix = draw(st.sampled_from([b"", b"ULog\x01\x12\x35", b"\xa3\x95", b"\x00" * 8 + b"\xfd"]))
        return suffix, prefix + draw(st.binary(max_size=3000))
    if kind == "other_format":
        return suffix, SAMPLES[draw(st.sampled_from(sorted(SAMPLES)))][: draw(st.integers(0, 5000))]
    data = bytearray(base)
    if kind in ("cut", "cut_mutated"):
        data = data[: draw(st.integers(0, len(data)))]
    if kind in ("mutated", "cut_mutated") and data:
        for _ in range(draw(st.integers(1, 12))):
            i = draw(st.integers(0, len(data) - 1))
            op = draw(st.sampled_from(["flip", "insert", "delete", "zero_run"]))
            if op == "flip":
                data[i] ^= 1 << draw(st.integers(0, 7))
            elif op == "insert":
                data[i:i] = draw(st.binary(min_size=1, max_size=40))
            elif op == "delete":
                del data[i : i + draw(st.integers(1, 40))]
            else:
                data[i : i + 64] = bytes(min(64, len(data) - i))
            if not data:
                break
    return suffix, bytes(data)


@settings(max_examples=FUZZ_EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow],
          derandomize=True)
@given(log_files())
def test_fuzz_log_readers_never_raise_anything_else(sample: tuple[str, bytes]) -> None:
    suffix, data = sample
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"log{suffix}"
        path.write_bytes(data)
        try:
            messages, report = open_log(path)
            n = 0
            for frac, msg in messages:
                assert 0.0 <= frac <= 1.0 + 1e-9
                assert isinstance(msg.get_type(), str)
                n += 1
        except (DataFileError, ResourceError):
            return
        assert all(0 <= s < report.size and s + length <= report.size for s, length, _ in report.skipped), \
            report.skipped
        assert report.cut_at is None or 0 <= report.cut_at < report.size
        for line in report.lines():
            assert str(path) in line


@settings(max_examples=max(FUZZ_EXAMPLES // 3, 10), deadline=None,
          suppress_health_check=[HealthCheck.too_slow], derandomize=True)
@given(log_files())
def test_fuzz_replay_command_exit_0_or_2_and_only_complete_outputs(sample: tuple[str, bytes]) -> None:
    suffix, data = sample
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"log{suffix}"
        path.write_bytes(data)
        out = Path(d) / "out.csv"
        code, stderr = run_cli("replay", path, "-o", out, *NAV_ARGS, "--align", "0.2")
        assert "Traceback" not in stderr, stderr
        assert code in (0, 2), stderr
        left = sorted(p.name for p in Path(d).iterdir())
        if code == 2:
            assert len(error_lines(stderr)) == 1, stderr
            assert left == [path.name], left
        else:
            assert left == sorted([path.name, "out.csv"]), left
            assert out.read_text().startswith("t,lat,lon")


def test_nav_first_increment_at_the_initial_time_is_refused_with_plain_numbers(tmp_path: Path) -> None:
    """An increment row at the initial state's time covers (t[-1], t[0]], before the start: `mavins nav`
    exits 2 with one line giving both times as numbers (not numpy reprs) and writes nothing."""
    text = imu_csv(5)
    t0 = float(text.splitlines()[1].split(",")[0])
    (tmp_path / "imu.csv").write_text(text, encoding="utf-8")
    (tmp_path / "init.json").write_text(json.dumps(dict(INIT, t=t0)), encoding="utf-8")
    code, stderr = run_cli("nav", tmp_path / "imu.csv", "--init", tmp_path / "init.json", "-o", tmp_path / "nav.csv")
    assert_refused(code, stderr, [f"imu.csv: line 2, column 't': first increment time {t0!r} is not after the "
                                  f"initial state's t = {t0!r}"])
    assert not (tmp_path / "nav.csv").exists()
