"""The kernel's state: a float64 vector read by generated offsets (strapdown.STATE_LAYOUT, what the kernels
use) against a numba record (a structured dtype with the same named fields), on the same work.

The work is the heart of a strapdown step on the state, done 2,000,000 times: the attitude quaternion
turned by a small rotation vector and renormalised, its DCM rebuilt, the velocity advanced by the rotated
specific force plus gravity, the previous velocity kept, the step counter and time advanced: every field
read and written through the layout, as the kernel does. Both kernels are compiled before timing; the best
of 5 runs of each, interleaved, so that the machine's load affects both alike. Ratio: the record's time
over the offsets' (above 1: the record is slower).

Run from the repository root::

    .venv/bin/python benchmarks/bench_state_layout.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Sequence

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from mavins.core import strapdown as sd  # noqa: E402

NOTES: list[str] = []
BASELINE = "the same work on the float64 state vector by offsets (what the kernels use)"

S_T, S_Q, S_C, S_V, S_VP, S_NK = sd.S_T, sd.S_Q, sd.S_C, sd.S_V, sd.S_VP, sd.S_NK
RECORD = np.dtype([(f.name.lower(), np.float64, (f.size,)) if f.size > 1 else (f.name.lower(), np.float64)
                   for f in sd.STATE_LAYOUT])  # the same fields, named


@numba.njit(cache=False)
def steps_offsets(s: np.ndarray, n: int, dth: np.ndarray, dv: np.ndarray, dt: float) -> float:
    for _ in range(n):
        q0, q1, q2, q3 = s[S_Q], s[S_Q + 1], s[S_Q + 2], s[S_Q + 3]
        h0, h1, h2 = 0.5 * dth[0], 0.5 * dth[1], 0.5 * dth[2]
        r0 = q0 - q1 * h0 - q2 * h1 - q3 * h2
        r1 = q1 + q0 * h0 + q2 * h2 - q3 * h1
        r2 = q2 + q0 * h1 + q3 * h0 - q1 * h2
        r3 = q3 + q0 * h2 + q1 * h1 - q2 * h0
        nrm = 1.0 / np.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
        r0, r1, r2, r3 = r0 * nrm, r1 * nrm, r2 * nrm, r3 * nrm
        s[S_Q], s[S_Q + 1], s[S_Q + 2], s[S_Q + 3] = r0, r1, r2, r3
        s[S_C] = r0 * r0 + r1 * r1 - r2 * r2 - r3 * r3
        s[S_C + 1] = 2.0 * (r1 * r2 - r0 * r3)
        s[S_C + 2] = 2.0 * (r1 * r3 + r0 * r2)
        s[S_C + 3] = 2.0 * (r1 * r2 + r0 * r3)
        s[S_C + 4] = r0 * r0 - r1 * r1 + r2 * r2 - r3 * r3
        s[S_C + 5] = 2.0 * (r2 * r3 - r0 * r1)
        s[S_C + 6] = 2.0 * (r1 * r3 - r0 * r2)
        s[S_C + 7] = 2.0 * (r2 * r3 + r0 * r1)
        s[S_C + 8] = r0 * r0 - r1 * r1 - r2 * r2 + r3 * r3
        for i in range(3):
            s[S_VP + i] = s[S_V + i]
            s[S_V + i] += s[S_C + 3 * i] * dv[0] + s[S_C + 3 * i + 1] * dv[1] + s[S_C + 3 * i + 2] * dv[2]
        s[S_V + 2] += 9.80665 * dt
        s[S_NK] += 1.0
        s[S_T] += dt
    return s[S_V] + s[S_C + 4]


@numba.njit(cache=False)
def steps_record(r: np.ndarray, n: int, dth: np.ndarray, dv: np.ndarray, dt: float) -> float:
    s = r[0]
    q, c, v, vp = s.q, s.c, s.v, s.vp
    for _ in range(n):
        q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
        h0, h1, h2 = 0.5 * dth[0], 0.5 * dth[1], 0.5 * dth[2]
        r0 = q0 - q1 * h0 - q2 * h1 - q3 * h2
        r1 = q1 + q0 * h0 + q2 * h2 - q3 * h1
        r2 = q2 + q0 * h1 + q3 * h0 - q1 * h2
        r3 = q3 + q0 * h2 + q1 * h1 - q2 * h0
        nrm = 1.0 / np.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
        r0, r1, r2, r3 = r0 * nrm, r1 * nrm, r2 * nrm, r3 * nrm
        q[0], q[1], q[2], q[3] = r0, r1, r2, r3
        c[0] = r0 * r0 + r1 * r1 - r2 * r2 - r3 * r3
        c[1] = 2.0 * (r1 * r2 - r0 * r3)
        c[2] = 2.0 * (r1 * r3 + r0 * r2)
        c[3] = 2.0 * (r1 * r2 + r0 * r3)
        c[4] = r0 * r0 - r1 * r1 + r2 * r2 - r3 * r3
        c[5] = 2.0 * (r2 * r3 - r0 * r1)
        c[6] = 2.0 * (r1 * r3 - r0 * r2)
        c[7] = 2.0 * (r2 * r3 + r0 * r1)
        c[8] = r0 * r0 - r1 * r1 - r2 * r2 + r3 * r3
        for i in range(3):
            vp[i] = v[i]
            v[i] += c[3 * i] * dv[0] + c[3 * i + 1] * dv[1] + c[3 * i + 2] * dv[2]
        v[2] += 9.80665 * dt
        s.nk += 1.0
        s.t += dt
    return v[0] + c[4]


def main(argv: Sequence[str] = ()) -> list[dict]:
    """Time both layouts on the same work; one row each and the ratio."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="200,000 steps instead of 2,000,000")
    args = p.parse_args(list(argv))
    n = 200_000 if args.quick else 2_000_000
    dth, dv, dt = np.array([1e-4, -2e-4, 3e-4]), np.array([1e-3, 2e-3, -9.8e-2]), 0.01

    def fresh() -> tuple[np.ndarray, np.ndarray]:
        s = sd.init_state(0.0, 0.8, 0.1, 100.0, np.zeros(3), 0.0, 0.0, 0.5)
        r = np.zeros(1, dtype=RECORD)
        for f in sd.STATE_LAYOUT:
            r[0][f.name.lower()] = s[sd.S_OFFSET[f.name]:sd.S_OFFSET[f.name] + f.size] if f.size > 1 \
                else s[sd.S_OFFSET[f.name]]
        return s, r

    s, r = fresh()
    a, b = steps_offsets(s, 10, dth, dv, dt), steps_record(r, 10, dth, dv, dt)  # compiled here
    if a != b:
        raise SystemExit("the two layouts gave different results")
    best = {"offsets": np.inf, "record": np.inf}
    for _ in range(5):
        s, r = fresh()
        t0 = time.perf_counter()
        a = steps_offsets(s, n, dth, dv, dt)
        best["offsets"] = min(best["offsets"], time.perf_counter() - t0)
        t0 = time.perf_counter()
        b = steps_record(r, n, dth, dv, dt)
        best["record"] = min(best["record"], time.perf_counter() - t0)
        if a != b:
            raise SystemExit("the two layouts gave different results")
    NOTES.clear()
    NOTES.append(f"state layout: the same {n:,} steps bit for bit in both layouts (checked)")
    return [
        {"case": "state by offsets (float64 vector, S_* from STATE_LAYOUT)", "samples": n,
         "seconds": best["offsets"], "rate": n / best["offsets"], "value": f"{1e9 * best['offsets'] / n:.2f} ns/step",
         "ratio": 1.0, "baseline": "(is the baseline)"},
        {"case": "state as a numba record (same named fields)", "samples": n, "seconds": best["record"],
         "rate": n / best["record"], "value": f"{1e9 * best['record'] / n:.2f} ns/step",
         "ratio": best["record"] / best["offsets"], "baseline": "state by offsets"},
    ]


if __name__ == "__main__":
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)
