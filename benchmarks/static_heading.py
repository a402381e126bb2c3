"""Heading of the aided filter at rest without a magnetometer: error against its own 1-sigma.

The simulator's ``static`` scenario with an ideal IMU, streamed as MAVLink
(HIGHRES_IMU without magnetometer fields, GPS_RAW_INT at 5 Hz with 0.5 m
horizontal noise, SCALED_PRESSURE, ATTITUDE for the initial heading) by
``sim.stream.frames``, each frame packed and decoded, through the live
``Pipeline`` with the given grade (consumer by default, as ``mavins run`` and
``mavins replay``). One noise draw per stream seed. Printed: the heading error
and the filter's heading 1-sigma every 300 s, and at the end the normalised
error of every draw and their RMS (1 for a consistent filter).

Run from the repository root (about a minute per 40-minute draw)::

    .venv/bin/python benchmarks/static_heading.py                      # seeds 0-8, 2400 s, 100 Hz
    .venv/bin/python benchmarks/static_heading.py --grade navigation  # the grade this IMU really has
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Sequence

RATE_HZ = 100.0
TRUE_YAW_DEG = 30.0  # the static scenario's heading


def draw(seed: int, seconds: float, grade: str) -> list[tuple[float, float, float]]:
    """(t s, heading error deg, heading 1-sigma deg) every 300 s of one noise draw."""
    from sim.generate import generate
    from sim.scenarios import load
    from sim.stream import StreamOptions, frames

    from mavins.live.livefilter import FilterSettings
    from mavins.live.engine import EngineConfig
    from mavins.link.ingest import IngestConfig
    from mavins.link.mavlink import mavlink
    from mavins.live.pipeline import Pipeline

    run = generate(load("static"), duration=seconds, rate=RATE_HZ, grade="ideal", seed=seed)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
    dec = mavlink.MAVLink(None)
    cfg = EngineConfig(lat=None, lon=None, alt=None, heading="auto", align=10.0, rate=1.0,
                       filter=FilterSettings(spec=grade, aiding=("gnss", "baro", "mag")))
    pipe = Pipeline(cfg, IngestConfig())
    out_rows = []
    for _, msgs in frames(run, mav, StreamOptions(seed=seed)):
        for m in msgs:
            out = pipe.handle(dec.decode(bytearray(m.pack(mav))))
            if out is not None and out.unc is not None and int(out.row[0]) % 300 == 0:
                err = (math.degrees(out.row[9]) - TRUE_YAW_DEG + 180.0) % 360.0 - 180.0
                out_rows.append((float(out.row[0]), err, math.degrees(out.unc.sigma_att[2])))
    return out_rows


def main(argv: Sequence[str] = ()) -> None:
    p = argparse.ArgumentParser(prog="static_heading", description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="0,1,2,3,4,5,6,7,8", help="comma list of stream seeds (one draw each)")
    p.add_argument("--seconds", type=float, default=2400.0, help="length of each draw (s)")
    p.add_argument("--grade", default="consumer", choices=("consumer", "industrial", "tactical", "navigation"))
    args = p.parse_args(list(argv))
    finals = []
    for seed in (int(s) for s in args.seeds.split(",")):
        rows = draw(seed, args.seconds, args.grade)
        print(f"seed {seed}: " + " ".join(f"{t:.0f}s {e:+.1f}/{s:.1f}" for t, e, s in rows), flush=True)
        if rows:
            finals.append(rows[-1][1] / rows[-1][2])
    if finals:
        rms = math.sqrt(sum(x * x for x in finals) / len(finals))
        print(f"normalised heading error at the end: {' '.join(f'{x:+.2f}' for x in finals)}; RMS {rms:.2f} "
              f"over {len(finals)} draws ({args.grade} grade, {args.seconds:g} s)")


if __name__ == "__main__":
    main(sys.argv[1:])
