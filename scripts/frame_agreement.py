"""The four mechanisation frames against each other and against the simulator's truth, mid-latitude.

The mid-latitude flight of tests/core/test_mechanisations.py: a great circle from 45 deg N, 20 deg E
at course 60 deg, 250 m/s, 10 km, height held, 1340 s, 2 samples per update, with and without
the rocking (3 deg at 9 s in roll, 1.5 deg at 13 s in pitch). For each rate and each frame, the
largest ECEF position (m), C_b^e attitude (rad) and ECEF velocity (m/s) difference over the
whole flight from --frame geographic and from the simulator's truth (docs/algorithms.md,
"Mechanisation frames", accuracy).

Run from the repository root (about 20 s per rate)::

    .venv/bin/python scripts/frame_agreement.py [--rate 50 --rate 25 ...]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mavins.core import earth
from mavins.core.rotation import quat_to_dcm
from mavins.core.runner import navigate
from sim.polar import EarthFixedMotion, simulate

FRAMES = ("geographic", "wander", "free", "inertial")
ROCK = {"roll": 3.0, "roll_period": 9.0, "pitch": 1.5, "pitch_period": 13.0}


def _earth_fixed(sol: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ECEF position, C_b^e and ECEF velocity of each row (rows in degrees as navigate() returns them)."""
    cne = [earth.cne_from_latlon(math.radians(a), math.radians(b)) for a, b in sol[:, 1:3]]
    r = np.array([earth.lla_to_ecef(math.radians(a), math.radians(b), c) for a, b, c in sol[:, 1:4]])
    c = np.array([m @ quat_to_dcm(q) for m, q in zip(cne, sol[:, 10:14])])
    v = np.array([m @ x for m, x in zip(cne, sol[:, 4:7])])
    return r, c, v


def _largest(a: tuple, b: tuple) -> tuple[float, float, float]:
    d = np.einsum("nij,nkj->nik", a[1], b[1])
    att = 0.5 * np.linalg.norm(np.stack([d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0],
                                         d[:, 1, 0] - d[:, 0, 1]], axis=1), axis=1)
    return (float(np.linalg.norm(a[0] - b[0], axis=1).max()), float(att.max()),
            float(np.linalg.norm(a[2] - b[2], axis=1).max()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, action="append", help="IMU rate (Hz), repeatable; default 50")
    args = parser.parse_args()
    print("rate_hz,rocking,frame,against,position_m,attitude_rad,velocity_m_s")
    for rate in args.rate or [50.0]:
        for rocking in (True, False):
            m = EarthFixedMotion("great_circle", 45.0, 20.0, 10000.0, 60.0, 250.0, **(ROCK if rocking else {}),
                                 t=1340.0)
            res = simulate(m, rate)
            sols = {f: navigate(res.t, res.dtheta, res.dv, res.init(), frame=f, vertical="hold") for f in FRAMES}
            truth = res.truth[np.searchsorted(res.truth[:, 0], sols["geographic"][:, 0])]
            fixed = {f: _earth_fixed(s) for f, s in sols.items()}
            fixed["truth"] = _earth_fixed(truth)
            for f in FRAMES:
                for against in ("geographic", "truth"):
                    if f != against:
                        pos, att, vel = _largest(fixed[f], fixed[against])
                        print(f"{rate:g},{'yes' if rocking else 'no'},{f},{against},{pos:.2e},{att:.2e},{vel:.2e}")


if __name__ == "__main__":
    main()
