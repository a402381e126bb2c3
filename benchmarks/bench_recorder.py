"""The Rerun recorder: RSS growth of a live recorder over 200,000 samples; ``--rerun-serve``
without a viewer: logging, ``close()`` and a whole ``mavins run --duration 1``.

Run from the repository root::

    .venv/bin/python benchmarks/bench_recorder.py [--quick]"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from service_harness import NOTES, ROOT, _row, _verdict, free_udp_port, log, mavins_cmd


# --- the recorder --------------------------------------------------------------------------
#: ``python -c`` script: a live Recorder fed ``n`` samples (250 Hz) and n/5 output sets; prints JSON with the
#: process's RSS after a warm-up fifth and at four points after it, and the file size at each.
_RECORDER_MEMORY = r"""
import gc, json, math, sys, time
from pathlib import Path
import numpy as np
from mavins.record.recorder import Recorder

def rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0

path, n = Path(sys.argv[1]), int(sys.argv[2])
rec = Recorder(path, serve=False, app="mavins-membench", live=True)
row = np.zeros(14); row[10] = 1.0
lat0, lon0 = math.radians(47.0), math.radians(8.0)
ned = np.zeros(3)

def feed(a, b):
    for i in range(a, b):
        t = 1.0 + i * 0.004
        rec.on_sample(t, (0.01, -0.02, 0.03 * math.sin(t)), (0.1, 0.2, -9.8))
        if i % 5 == 0:
            row[0] = t; row[1] = lat0 + 1e-7 * i; row[2] = lon0; row[3] = 400.0; row[9] = 0.1 * math.sin(t)
            ned[0] = 0.6 * i; ned[1] = 10.0 * math.sin(t / 10.0)
            rec.on_output(row, (47.0, 8.0, 400.0), ned)
        if i % 2500 == 0:
            rec.on_counters(t, {"time_backwards": i // 2500})
            rec.on_event(t, "INFO", f"event {i}")

warm = n // 5
t0 = time.perf_counter()
feed(0, warm); gc.collect(); time.sleep(0.2)
base, size0 = rss_mb(), path.stat().st_size
step = (n - warm) // 4
rss = []
for k in range(4):
    feed(warm + k * step, warm + (k + 1) * step)
    rss.append(rss_mb())
t_feed = time.perf_counter() - t0
rec.close()
print(json.dumps({"base": base, "rss": rss, "size0": size0, "size": path.stat().st_size, "feed_s": t_feed}))
"""


def recorder_memory(workdir: Path, n: int = 200_000) -> dict:
    rrd = workdir / "recorder_memory.rrd"
    proc = subprocess.run([sys.executable, "-c", _RECORDER_MEMORY, str(rrd), str(n)], capture_output=True, text=True,
                          timeout=1800, cwd=ROOT)
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else "recorder script failed")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["n"] = n
    return out


def recorder_serve(n: int = 20_000) -> dict:
    """A Recorder with the gRPC server and no viewer: seconds to log ``n`` samples (+ n/5 sets) and to close."""
    from mavins.record.recorder import Recorder

    with tempfile.TemporaryDirectory(prefix="bench_serve_") as tmp:
        t0 = time.perf_counter()
        rec = Recorder(Path(tmp) / "served.rrd", serve=True, app="mavins-servebench")
        row = np.zeros(14)
        row[10] = 1.0
        for i in range(n):
            t = i * 0.004
            rec.on_sample(t, (0.0, 0.0, 0.0), (0.0, 0.0, -9.8))
            if i % 5 == 0:
                row[0] = t
                rec.on_output(row, (47.0, 8.0, 400.0), np.zeros(3))
        t1 = time.perf_counter()
        rec.close()
        t2 = time.perf_counter()
    cli0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_serve_cli_") as tmp:
        proc = subprocess.run(mavins_cmd() + ["run", "--master", f"udpin:127.0.0.1:{free_udp_port()}", "--rerun",
                                              str(Path(tmp) / "live.rrd"), "--rerun-serve", "--duration", "1"],
                              capture_output=True, text=True, timeout=600, cwd=ROOT)
    cli = time.perf_counter() - cli0
    return {"n": n, "log_s": t1 - t0, "close_s": t2 - t1, "cli_s": cli, "cli_rc": proc.returncode}

def main(argv: Sequence[str] = ()) -> list[dict]:
    """The Rerun recorder's memory over a long run, and ``--rerun-serve`` without a viewer."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="50,000 samples instead of 200,000")
    args = p.parse_args(list(argv))
    NOTES.clear()
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench_recorder_") as tmp:
        work = Path(tmp)
        n_rec = 50_000 if args.quick else 200_000
        log(f"recorder: memory over {n_rec:,} samples")
        rm = recorder_memory(work, n_rec)
        written = (rm["size"] - rm["size0"]) / 2**20
        grown = max(rm["rss"]) - rm["base"]
        rows.append(_row(f"recorder: RSS growth over {n_rec:,} samples + {n_rec // 5:,} sets", samples=n_rec,
                         seconds=rm["feed_s"], rate=n_rec / rm["feed_s"], value=f"{grown:+.1f} MB",
                         goal=f"< 0.6 x written + 4 MB: {_verdict(grown < 0.6 * written + 4)}",
                         note=f"{written:.1f} MB written meanwhile; RSS {rm['base']:.0f} MB after a warm-up fifth"))
        log("recorder: --rerun-serve without a viewer")
        rs = recorder_serve()
        rows.append(_row(f"recorder --rerun-serve, no viewer: log {rs['n']:,} samples", samples=rs["n"],
                         seconds=rs["log_s"], rate=rs["n"] / rs["log_s"], goal=None,
                         note="+ a set every 5 samples"))
        rows.append(_row("recorder --rerun-serve, no viewer: close()", seconds=rs["close_s"],
                         goal=f"< 5 s: {_verdict(rs['close_s'] < 5)}"))
        rows.append(_row("mavins run --rerun-serve --duration 1, no viewer: process", seconds=rs["cli_s"],
                         goal=f"< 30 s: {_verdict(rs['cli_s'] < 30 and rs['cli_rc'] == 0)}",
                         note=f"exit code {rs['cli_rc']}; includes loading the kernels"))

    return rows


if __name__ == "__main__":
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)
