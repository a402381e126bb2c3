"""Where the geographic frame degrades near a pole: its error against the wander frame by closest approach.

The polar_flight motion (250 m/s at 10 km, rocking, 50 Hz, height held) is flown on great
circles that pass the North Pole at 50, 20, 11, 5, 2 and 1 km (the course from 88.5 deg N is
asin(distance / 167 km)); for each, the largest ECEF position and NED velocity difference
between --frame geographic and --frame wander over the run. The wander frame has no tan L
(docs/algorithms.md), so the difference is the geographic frame's own error. The kernel stops
the geographic frame at |lat| 89.5 deg (strapdown.GEO_LAT_LIMIT); to measure what lies beyond,
this script lifts that limit, which it can only do with the kernels run as plain Python
(NUMBA_DISABLE_JIT=1, set here; a few minutes).

Run from the repository root::

    .venv/bin/python scripts/geographic_pole_limit.py
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np

os.environ["NUMBA_DISABLE_JIT"] = "1"
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mavins.core import earth
from mavins.core import strapdown as sd
from mavins.core.runner import navigate
from sim.polar import EarthFixedMotion, simulate

ROCK = {"roll": 3.0, "roll_period": 9.0, "pitch": 1.5, "pitch_period": 13.0}


def _ecef(sol: np.ndarray) -> np.ndarray:
    return np.array([earth.lla_to_ecef(math.radians(a), math.radians(b), c) for a, b, c in sol[:, 1:4]])


def main() -> None:
    sd.GEO_LAT_LIMIT = math.inf
    print("| closest approach (km) | max latitude (deg) | geographic - wander, position (m) | velocity (m/s) |")
    print("|---|---|---|---|")
    for d_km in (50, 20, 11, 5, 2, 1):
        course = math.degrees(math.asin(d_km / 167.0))
        m = EarthFixedMotion("great_circle", 88.5, 20.0, 10000.0, course, 250.0, **ROCK, t=1340.0)
        res = simulate(m, 50.0)
        a = navigate(res.t, res.dtheta, res.dv, res.init(), frame="geographic", vertical="hold")
        b = navigate(res.t, res.dtheta, res.dv, res.init(), frame="wander", vertical="hold")
        pos = np.linalg.norm(_ecef(a) - _ecef(b), axis=1).max()
        vel = np.abs(a[:, 4:7] - b[:, 4:7]).max()
        print(f"| {d_km} | {res.truth[:, 1].max():.4f} | {pos:.3g} | {vel:.3g} |")


if __name__ == "__main__":
    main()
