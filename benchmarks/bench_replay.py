"""Replay of large logs: ``mavins replay`` against a bare pymavlink parse loop, and its memory.

* **Throughput.** A 1-hour tlog at 250 Hz made by the simulator (``static``
  scenario, ``sim.generate.generate`` + ``sim.stream.frames``: HIGHRES_IMU plus
  SIM_STATE, ATTITUDE, GPS_RAW_INT, SCALED_PRESSURE and HEARTBEAT, every frame
  written as a tlog record: 8-byte big-endian microseconds + the frame).
  Baseline, same file, same run: a fresh interpreter doing
  ``mavutil.mavlink_connection(tlog, dialect="common", robust_parsing=True)``
  and ``recv_msg()`` until None, counting messages (the exact reader
  ``mavins replay`` uses). Both are timed as whole processes (start to exit),
  so both pay their interpreter start-up; ratio = replay messages/s divided by
  baseline messages/s.
* **Memory.** A 1-hour tlog at 1 kHz (3.6 million HIGHRES_IMU frames of a
  static IMU, encoded with numpy, see service_harness.highres_frames) through
  ``mavins replay``; the parent samples the child's RSS (``/proc/PID/status``)
  every 0.2 s and its peak RSS (``VmHWM``, since exec) until it exits. "Flat" means RSS grew by
  less than max(5 MB, 2 %) from a quarter of the run to its end.

Run from the repository root::

    .venv/bin/python benchmarks/bench_replay.py [--quick] [--workdir DIR] [--profile]

``--workdir`` keeps the generated tlogs there (and reuses them next time).
``--profile`` also records a shorter replay with py-spy and prints where its
time goes.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (str(HERE), str(ROOT)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

os.environ.setdefault("MAVLINK20", "1")

from service_harness import (  # noqa: E402
    highres_frames,
    inclusive,
    line_text,
    mavins_cmd,
    py_spy_path,
    static_imu,
    top_functions,
    top_lines,
)

SIM_RATE = 250.0
SIM_SECONDS = 3600.0
MEM_RATE = 1000.0
MEM_SECONDS = 3600.0
EPOCH_USEC = 1_700_000_000_000_000  # tlog wall-clock stamps start here
GOAL_RATIO = 0.80

#: Footnotes printed under the table (filled by main()).
NOTES: list[str] = []
BASELINE = "bare pymavlink parse loop over the same tlog"


def span(seconds: float) -> str:
    return f"{seconds / 3600:g} h" if seconds >= 3600 else f"{seconds / 60:g} min"


def log(msg: str) -> None:
    print(f"[bench_replay] {msg}", file=sys.stderr, flush=True)


# --- the logs ---------------------------------------------------------------------
def build_sim_tlog(path: Path, seconds: float, rate: float) -> dict:
    """The ``static`` scenario for ``seconds`` at ``rate`` Hz, every streamed message as a tlog record."""
    from sim.generate import generate
    from sim.scenarios import load
    from sim.stream import StreamOptions, frames

    from mavins.link.mavlink import mavlink

    run = generate(load("static"), duration=seconds, rate=rate, grade="ideal")
    truth = run.exact.truth[-1]
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
    n = 0
    tmp = path.with_suffix(".part")
    with open(tmp, "wb", buffering=1 << 20) as fh:
        for t_s, msgs in frames(run, mav, StreamOptions()):
            stamp = (EPOCH_USEC + int(round(t_s * 1e6))).to_bytes(8, "big")
            for m in msgs:
                fh.write(stamp + m.pack(mav))
                mav.seq = (mav.seq + 1) % 256
                n += 1
    tmp.rename(path)
    info = {"messages": n, "imu": len(run.t), "roll": float(truth[7]), "pitch": float(truth[8]),
            "yaw": float(truth[9]), "lat": float(truth[1]), "lon": float(truth[2]), "h": float(truth[3])}
    path.with_suffix(".json").write_text(json.dumps(info))
    return info


def build_static_tlog(path: Path, seconds: float, rate: float) -> dict:
    """HIGHRES_IMU only, static IMU (service_harness's record), ``seconds`` at ``rate`` Hz."""
    gyro, accel = static_imu()
    n = int(round(seconds * rate))
    chunk = 256 * 2000  # a multiple of 256 keeps the sequence numbers continuous
    tmp = path.with_suffix(".part")
    with open(tmp, "wb") as fh:
        for a in range(0, n, chunk):
            b = min(n, a + chunk)
            fr, usec = highres_frames(b - a, rate, gyro, accel, t0_usec=int(round(1e6 + a * 1e6 / rate)))
            rec = np.empty((b - a, 8 + fr.shape[1]), dtype=np.uint8)
            rec[:, :8] = (usec + np.uint64(EPOCH_USEC)).astype(">u8").view(np.uint8).reshape(-1, 8)
            rec[:, 8:] = fr
            fh.write(rec.tobytes())
    tmp.rename(path)
    info = {"messages": n, "imu": n}
    path.with_suffix(".json").write_text(json.dumps(info))
    return info


def ensure(path: Path, build, *args) -> dict:  # type: ignore[no-untyped-def]
    meta = path.with_suffix(".json")
    if path.exists() and meta.exists():
        log(f"reusing {path}")
        return json.loads(meta.read_text())
    log(f"writing {path.name}")
    t0 = time.perf_counter()
    info = build(path, *args)
    log(f"  {info['messages']:,} messages, {path.stat().st_size / 1e6:.0f} MB in {time.perf_counter() - t0:.0f} s")
    return info


# --- the two readers ----------------------------------------------------------------
_BASELINE = r"""
import json, os, sys, time
t0 = time.perf_counter()
os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil
mavutil.set_dialect("common")
log = mavutil.mavlink_connection(sys.argv[1], dialect="common", robust_parsing=True)
t1 = time.perf_counter()
n = 0
while log.recv_msg() is not None:
    n += 1
t2 = time.perf_counter()
print(json.dumps({"messages": n, "import_s": t1 - t0, "loop_s": t2 - t1}))
"""


#: Reference (a what-if, not the baseline): the tlog split into records by hand and every frame
#: decoded by pymavlink's ``MAVLink.decode`` (CRC checked), without mavutil's file reader.
_DIRECT = r"""
import json, os, sys, time
t0 = time.perf_counter()
os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink
parser = mavlink.MAVLink(None)
parser.robust_parsing = True
decode = parser.decode
t1 = time.perf_counter()
n = bad = 0
with open(sys.argv[1], "rb") as fh:
    data = fh.read()
end, ofs = len(data), 0
while ofs + 10 <= end:
    stx, plen = data[ofs + 8], data[ofs + 9]
    if stx == 0xFD:
        flen = plen + 12 + (13 if data[ofs + 10] & 1 else 0)
    elif stx == 0xFE:
        flen = plen + 8
    else:
        bad += 1
        ofs += 1
        continue
    try:
        decode(bytearray(data[ofs + 8 : ofs + 8 + flen]))
        n += 1
    except mavlink.MAVError:
        bad += 1
    ofs += 8 + flen
t2 = time.perf_counter()
print(json.dumps({"messages": n, "bad": bad, "import_s": t1 - t0, "loop_s": t2 - t1}))
"""


def run_baseline(tlog: Path, script: str = _BASELINE) -> dict:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", script, str(tlog)], capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"baseline parse loop failed:\n{proc.stderr}")
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    res["wall_s"] = wall
    return res


def run_replay(tlog: Path, out_csv: Path, extra: Sequence[str] = (), sample_every: float = 0.2,
               wrap: Sequence[str] = ()) -> dict:
    """``mavins replay`` in a subprocess: wall time, RSS samples, max RSS, messages and final state."""
    cmd = list(wrap) + mavins_cmd() + ["replay", str(tlog), "-o", str(out_csv), *extra]
    err_path = out_csv.with_suffix(".stderr")
    with open(err_path, "w") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, cwd=ROOT)
        samples: list[tuple[float, float]] = []
        anon: list[float] = []
        file_: list[float] = []
        hwm = 0.0
        status = 0
        while True:
            # /proc/PID/status of a living child: VmHWM is the peak RSS since exec (wait4's ru_maxrss
            # would also count the forked parent's pages before exec)
            mem = proc_mem(proc.pid)
            if mem.get("VmRSS"):
                hwm = max(hwm, mem.get("VmHWM", 0.0))
                samples.append((time.perf_counter() - t0, mem["VmRSS"]))
                anon.append(mem.get("RssAnon", float("nan")))
                file_.append(mem.get("RssFile", float("nan")))
            pid, status, _ = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            time.sleep(sample_every)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
    text = err_path.read_text()
    if proc.returncode != 0:
        raise RuntimeError(f"mavins replay failed ({proc.returncode}):\n{text[-2000:]}")
    m = re.search(r"mavins replay: (\d+) messages, (\d+) solution rows.*final state (\w+)", text)
    return {"wall_s": wall, "rss": samples, "max_rss_mb": hwm, "anon": anon, "file": file_,
            "messages": int(m.group(1)) if m else 0, "rows": int(m.group(2)) if m else 0,
            "state": m.group(3) if m else "?", "stderr": text}


def proc_mem(pid: int) -> dict[str, float]:
    """VmRSS, VmHWM, RssAnon, RssFile of a process (MB); empty when it is gone."""
    out: dict[str, float] = {}
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for line in fh:
                key, _, rest = line.partition(":")
                if key in ("VmRSS", "VmHWM", "RssAnon", "RssFile"):
                    out[key] = int(rest.split()[0]) / 1024.0
    except OSError:
        return {}
    return out


def last_row(path: Path) -> np.ndarray | None:
    from service_harness import read_last_row

    return read_last_row(path)


def flatness(samples: list[tuple[float, float]], wall: float) -> tuple[bool, float, float, float]:
    """(flat, RSS at 25 % of the run, RSS at the end, growth MB) from (t, RSS MB) samples."""
    if len(samples) < 4:
        return False, float("nan"), float("nan"), float("nan")
    t = np.array([s[0] for s in samples])
    r = np.array([s[1] for s in samples])
    q = float(r[np.searchsorted(t, 0.25 * wall)]) if t[-1] > 0.25 * wall else float(r[0])
    end = float(r[-1])
    growth = end - q
    return growth < max(5.0, 0.02 * q), q, end, growth


REPLAY_PARTS = {
    "pymavlink tlog reader (recv_msg: read + parse)": r"(^|;)mavlogfile\.recv_msg|(^|;)mavfile\.recv_msg",
    "  MAVLink.parse_char / decode": r"(^|;)MAVLink\.(parse_char|decode) \(",
    "Pipeline.handle": r"(^|;)Pipeline\.handle \(",
    "  Ingest.sample": r"(^|;)Ingest\.sample \(",
    "  Engine.on_imu": r"(^|;)Engine\.on_imu \(",
    "  Engine._align_step": r"(^|;)Engine\._align_step \(",
    "Pipeline.take_events": r"(^|;)Pipeline\.take_events \(",
    "SolutionWriter.write": r"(^|;)SolutionWriter\.write \(",
    "Progress.update": r"(^|;)Progress\.update \(",
    "_tlog_messages (generator own work)": r"(^|;)_tlog_messages \([^;]*$",
    "replay() loop itself": r"(^|;)replay \([^;]*replay\.py[^;]*$",
}


def profile_replay(tlog: Path, work: Path, extra: Sequence[str]) -> list[str]:
    spy = py_spy_path()
    if spy is None:
        return ["py-spy not found (pip install py-spy, or set PY_SPY): no profile"]
    raw = work / "replay_profile.txt"
    cmd = [spy, "record", "-r", "200", "--format", "raw", "-o", str(raw), "--"] + mavins_cmd() + [
        "replay", str(tlog), "-o", str(work / "prof.csv"), *extra]
    subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if not raw.exists():
        return ["py-spy produced no profile"]
    top, total = top_functions(raw)
    incl = inclusive(raw, list(REPLAY_PARTS.values()))
    out = [f"py-spy, mavins replay {tlog.name}, {total} samples:"]
    out += [f"  {incl[p]:5.1f} % incl  {name}" for name, p in REPLAY_PARTS.items()]
    out.append("  top functions by self time (self %, inclusive %):")
    out += [f"  {s:5.1f} %  {i:5.1f} %  {n}" for n, s, i in top]
    out.append("  hottest lines of mavins itself (self %; C calls are charged to the line making them):")
    out += [f"  {pct:5.1f} %  {ref}  | {line_text(ref)}" for ref, pct in top_lines(raw)]
    return out


# --- driver -------------------------------------------------------------------------------
def _row(case: str, *, samples: int | None = None, seconds: float | None = None, rate: float | None = None,
         value: str | None = None, ratio: float | None = None, baseline: str | None = None,
         goal: str | None = None, note: str = "") -> dict:
    return {"case": case, "samples": samples, "seconds": seconds, "rate": rate, "value": value, "ratio": ratio,
            "baseline": baseline, "goal": goal, "note": note}


def main(argv: Sequence[str] = ()) -> list[dict]:
    """Replay throughput against the bare parse loop, and memory of a 1-hour 1 kHz replay."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="5-minute logs instead of 1-hour logs")
    p.add_argument("--sim-seconds", type=float, default=SIM_SECONDS, help="length of the 250 Hz simulator tlog")
    p.add_argument("--mem-seconds", type=float, default=MEM_SECONDS, help="length of the 1 kHz tlog")
    p.add_argument("--workdir", type=Path, default=None, help="keep (and reuse) the tlogs here")
    p.add_argument("--skip", action="append", default=[], choices=("throughput", "memory"))
    p.add_argument("--profile", action="store_true", help="also profile a replay with py-spy")
    args = p.parse_args(list(argv))
    if args.quick:
        args.sim_seconds, args.mem_seconds = 300.0, 300.0
    NOTES.clear()
    rows: list[dict] = []
    tmp = None
    if args.workdir is None:
        tmp = tempfile.mkdtemp(prefix="bench_replay_")
        work = Path(tmp)
    else:
        work = args.workdir
        work.mkdir(parents=True, exist_ok=True)
    try:
        sim_tlog = work / f"sim_static_{SIM_RATE:.0f}hz_{args.sim_seconds:.0f}s.tlog"
        if "throughput" not in args.skip or args.profile:
            info = ensure(sim_tlog, build_sim_tlog, args.sim_seconds, SIM_RATE)
        if "throughput" not in args.skip:
            mb = sim_tlog.stat().st_size / 1e6
            log("baseline: bare pymavlink parse loop")
            base = run_baseline(sim_tlog)
            log("reference: hand-split tlog + MAVLink.decode")
            direct = run_baseline(sim_tlog, _DIRECT)
            log("mavins replay")
            # the log's IMU is ideal: the filter is told so (--grade navigation), else its consumer-grade
            # default lets the heading wander (no magnetometer, at rest: docs/performance.md)
            rep = run_replay(sim_tlog, work / "replay_sim.csv", ["--grade", "navigation"])
            base_rate = base["messages"] / base["wall_s"]
            rep_rate = rep["messages"] / rep["wall_s"]
            ratio = rep_rate / base_rate
            row = last_row(work / "replay_sim.csv")
            if row is not None:
                dyaw = (row[9] - info["yaw"] + 180.0) % 360.0 - 180.0
                att = max(abs(row[7] - info["roll"]), abs(row[8] - info["pitch"]), abs(dyaw))
                check = f"final att err {att:.1e} deg, state {rep['state']}"
            else:
                check = f"no solution rows, state {rep['state']}"
            dur = span(args.sim_seconds)
            rows.append(_row(f"replay baseline: pymavlink recv_msg loop ({dur}, {SIM_RATE:.0f} Hz sim tlog)",
                             samples=base["messages"], seconds=base["wall_s"], rate=base_rate, ratio=1.0,
                             baseline="(is the baseline)",
                             note=f"{mb:.0f} MB; loop alone {base['loop_s']:.1f} s"))
            rows.append(_row(f"mavins replay ({dur}, {SIM_RATE:.0f} Hz sim tlog)", samples=rep["messages"],
                             seconds=rep["wall_s"], rate=rep_rate, ratio=ratio,
                             baseline="pymavlink recv_msg loop, same file",
                             goal=f">= 0.80x: {'met' if ratio >= GOAL_RATIO else 'NOT met'}",
                             note=f"{info['imu']:,} IMU, {rep['rows']:,} rows; {check}"))
            d_rate = direct["messages"] / direct["wall_s"]
            rows.append(_row(f"reference: tlog split + MAVLink.decode ({dur}, no mavutil)",
                             samples=direct["messages"], seconds=direct["wall_s"], rate=d_rate,
                             ratio=d_rate / base_rate, baseline="pymavlink recv_msg loop, same file",
                             note=f"what-if reader, CRC checked; loop alone {direct['loop_s']:.1f} s"))
            if rep["messages"] != base["messages"]:
                NOTES.append(f"replay counted {rep['messages']:,} messages, the baseline {base['messages']:,}")
            per_base = 1e6 * base["wall_s"] / base["messages"]
            per_rep = 1e6 * rep["wall_s"] / rep["messages"]
            NOTES.append(f"replay: {per_rep:.1f} us per message against {per_base:.1f} us for parsing alone "
                         f"(+{per_rep - per_base:.1f} us; {1e6 * (rep['wall_s'] - base['wall_s']) / info['imu']:.1f} "
                         f"us more per IMU sample); max RSS {rep['max_rss_mb']:.0f} MB")

        if "memory" not in args.skip:
            mem_tlog = work / f"static_{MEM_RATE:.0f}hz_{args.mem_seconds:.0f}s.tlog"
            minfo = ensure(mem_tlog, build_static_tlog, args.mem_seconds, MEM_RATE)
            from service_harness import ALT, HEADING, LAT, LON

            log("mavins replay of the 1 kHz tlog, sampling RSS")
            rep = run_replay(mem_tlog, work / "replay_mem.csv",
                             ["--lat", str(LAT), "--lon", str(LON), "--alt", str(ALT), "--heading", str(HEADING),
                              "--align", "1"])
            flat, q, end, growth = flatness(rep["rss"], rep["wall_s"])
            rss = np.array([s[1] for s in rep["rss"]]) if rep["rss"] else np.array([np.nan])
            anon = np.array(rep["anon"]) if rep["anon"] else np.array([np.nan])
            filem = np.array(rep["file"]) if rep["file"] else np.array([np.nan])
            a_flat, a_q, a_end, a_growth = flatness(list(zip([t for t, _ in rep["rss"]], anon)), rep["wall_s"])
            rows.append(_row(f"mavins replay memory ({span(args.mem_seconds)}, 1 kHz, {minfo['messages'] / 1e6:.1f} M msgs)",
                             samples=rep["messages"], seconds=rep["wall_s"],
                             rate=rep["messages"] / rep["wall_s"], value=f"max RSS {rep['max_rss_mb']:.0f} MB",
                             goal=f"flat: {'yes' if flat else 'NO'}",
                             note=f"RSS {q:.0f} MB at 25 % -> {end:.0f} MB at end ({growth:+.1f} MB); "
                                  f"anon {a_q:.0f} -> {a_end:.0f} MB ({'flat' if a_flat else 'NOT flat'}); "
                                  f"state {rep['state']}"))

            def at(arr: np.ndarray) -> str:
                return " / ".join(f"{float(arr[min(len(arr) - 1, int(f * (len(arr) - 1)))]):.0f}"
                                  for f in (0.1, 0.25, 0.5, 0.75, 1.0))

            NOTES.append(f"memory, 1 kHz replay, MB at 10/25/50/75/100 % of the run: RSS {at(rss)}; of which "
                         f"anonymous (heap) {at(anon)} and file-backed (mapped tlog, libraries) {at(filem)}; "
                         f"tlog {mem_tlog.stat().st_size / 1e6:.0f} MB")

        if args.profile:
            short = work / f"sim_static_{SIM_RATE:.0f}hz_300s.tlog"
            ensure(short, build_sim_tlog, 300.0, SIM_RATE)
            log("py-spy profile of a 5-minute replay")
            NOTES.extend(profile_replay(short, work, []))
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return rows


if __name__ == "__main__":
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)
