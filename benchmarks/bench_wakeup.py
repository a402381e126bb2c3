"""What waking up costs: the live per-sample path timed after different pauses.

The service sleeps in ``select()`` between datagrams; at 1 kHz it wakes a
thousand times a second. This benchmark times the same work per datagram as
the service does between two waits (``decode_one`` of a HIGHRES_IMU frame,
then ``Pipeline.handle``, filter on, GNSS 5 Hz; frames of bench_filter's
consumer-grade flight) in one process, preceded each time by:

* nothing (back to back: the in-process figure of bench_filter);
* a sweep over 8 MB of memory (data caches evicted, the core kept busy);
* a 0.9 ms busy wait (the core kept busy, nothing evicted);
* a 0.9 ms sleep (the core goes idle, as in the service at 1 kHz).

The difference between the last row and the first is what the same Python
costs after an idle pause on this machine; it is why the whole service
process at 1 kHz uses several times the in-process figure
(docs/performance.md, "Waking up" and "Profile of what remains").

Run from the repository root::

    .venv/bin/python benchmarks/bench_wakeup.py
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

NOTES: list[str] = []
BASELINE = "back to back (no pause), same run"


def _pause(kind: str) -> Callable[[], None]:
    big = np.zeros(1 << 20)  # 8 MB of float64
    if kind == "sweep":
        def f() -> None:
            np.add(big, 1.0, out=big)
    elif kind == "spin":
        def f() -> None:
            end = time.perf_counter() + 0.0009
            while time.perf_counter() < end:
                pass
    elif kind == "sleep":
        def f() -> None:
            time.sleep(0.0009)
    else:
        def f() -> None:
            return None
    return f


def measure(seconds: float) -> dict[str, tuple[float, float, float]]:
    """Per pause kind: median decode, median and mean decode + handle (us per datagram)."""
    import bench_filter as bf

    from mavins.link.decode import decode_one

    frames, times, init, _ = bf.live_frames(seconds + 3.0)
    k0 = int(np.searchsorted(times, times[0] + 3.0))
    out: dict[str, tuple[float, float, float]] = {}
    for kind in ("none", "sweep", "spin", "sleep"):
        pipe = bf._pipeline(init, ("gnss",))
        for b in frames[:k0]:
            pipe.handle(decode_one(b))
        pause = _pause(kind)
        td, tall = [], []
        clock = time.perf_counter_ns
        for b in frames[k0:]:
            pause()
            t0 = clock()
            m = decode_one(b)
            t1 = clock()
            pipe.handle(m)
            t2 = clock()
            td.append(t1 - t0)
            tall.append(t2 - t0)
        out[kind] = (float(np.median(td)) / 1e3, float(np.median(tall)) / 1e3, float(np.mean(tall)) / 1e3)
    return out


def main(argv: Sequence[str] = ()) -> list[dict]:
    p = argparse.ArgumentParser(prog="bench_wakeup", description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=10.0, help="seconds of 1 kHz frames timed per pause kind")
    p.add_argument("--quick", action="store_true", help="3 s per pause kind")
    args = p.parse_args(list(argv))
    seconds = 3.0 if args.quick else args.seconds
    load0 = os.getloadavg()[0]
    res = measure(seconds)
    base = res["none"][2]
    labels = {"none": "back to back", "sweep": "after an 8 MB memory sweep", "spin": "after a 0.9 ms busy wait",
              "sleep": "after a 0.9 ms sleep (idle, as the service at 1 kHz)"}
    rows = []
    for kind, (dec, med, mean) in res.items():
        rows.append({"case": f"decode + Pipeline.handle, {labels[kind]}", "samples": int(seconds * 1000),
                     "value": f"mean {mean:.1f} us (median {med:.1f}, decode {dec:.1f})",
                     "ratio": mean / base, "baseline": BASELINE})
    NOTES[:] = [f"load average {load0:.2f} at the start, {os.getloadavg()[0]:.2f} at the end; "
                f"{os.cpu_count()} cores"]
    return rows


if __name__ == "__main__":
    for r in main(sys.argv[1:]):
        print(f"{r['case']:<75} {r['value']:<45} {r['ratio']:.2f}x")
    print("\n".join(NOTES))
