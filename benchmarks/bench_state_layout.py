"""The kernel's state: a float64 vector read by the named indices generated from strapdown.STATE_LAYOUT
(``s[S.V + 2]``, what the kernels use) against a numba record (a structured dtype with the same named
fields), on the same work.

The work is the heart of a strapdown step on the state, done 2,000,000 times, one helper call per step
as in the kernels: the attitude quaternion turned by a small rotation vector and renormalised, its DCM
rebuilt, the velocity advanced by the rotated specific force plus gravity, the previous velocity kept,
the step counter and time advanced: every field read and written through the layout. Four ways: the
float64 vector by index; a record array; the record as a view of the float64 vector (what Python hands
every kernel) taken once at the entry and passed to the helper; the view taken in every helper's call.
Then the two helpers as plain Python (NUMBA_DISABLE_JIT=1: what mutation testing and a debugger run),
20,000 steps. All compiled before timing; the best of 5 runs (3 in plain Python), interleaved, so that
the machine's load affects all alike; the results checked bit for bit. Ratio: time over the index's
(above 1: slower).

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

S = sd.S  # the kernels' named indices
RECORD = np.dtype((np.record, [(f.name.lower(), np.float64, (f.size,)) if f.size > 1 else (f.name.lower(), np.float64)
                               for f in sd.STATE_LAYOUT]))  # the same fields, named (attributes in plain Python too)


@numba.njit(cache=False)
def _step_offsets(s: np.ndarray, dth: np.ndarray, dv: np.ndarray, dt: float) -> None:
    """One step on the float64 vector through the named indices S.<NAME>."""
    q0, q1, q2, q3 = s[S.Q], s[S.Q + 1], s[S.Q + 2], s[S.Q + 3]
    h0, h1, h2 = 0.5 * dth[0], 0.5 * dth[1], 0.5 * dth[2]
    r0 = q0 - q1 * h0 - q2 * h1 - q3 * h2
    r1 = q1 + q0 * h0 + q2 * h2 - q3 * h1
    r2 = q2 + q0 * h1 + q3 * h0 - q1 * h2
    r3 = q3 + q0 * h2 + q1 * h1 - q2 * h0
    nrm = 1.0 / np.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    r0, r1, r2, r3 = r0 * nrm, r1 * nrm, r2 * nrm, r3 * nrm
    s[S.Q], s[S.Q + 1], s[S.Q + 2], s[S.Q + 3] = r0, r1, r2, r3
    s[S.C] = r0 * r0 + r1 * r1 - r2 * r2 - r3 * r3
    s[S.C + 1] = 2.0 * (r1 * r2 - r0 * r3)
    s[S.C + 2] = 2.0 * (r1 * r3 + r0 * r2)
    s[S.C + 3] = 2.0 * (r1 * r2 + r0 * r3)
    s[S.C + 4] = r0 * r0 - r1 * r1 + r2 * r2 - r3 * r3
    s[S.C + 5] = 2.0 * (r2 * r3 - r0 * r1)
    s[S.C + 6] = 2.0 * (r1 * r3 - r0 * r2)
    s[S.C + 7] = 2.0 * (r2 * r3 + r0 * r1)
    s[S.C + 8] = r0 * r0 - r1 * r1 - r2 * r2 + r3 * r3
    for i in range(3):
        s[S.VP + i] = s[S.V + i]
        s[S.V + i] += s[S.C + 3 * i] * dv[0] + s[S.C + 3 * i + 1] * dv[1] + s[S.C + 3 * i + 2] * dv[2]
    s[S.V + 2] += 9.80665 * dt
    s[S.NK] += 1.0
    s[S.T] += dt


@numba.njit(cache=False)
def _step_record(r, dth: np.ndarray, dv: np.ndarray, dt: float) -> None:  # noqa: ANN001 (a numba Record)
    """The same step on a record, by field name."""
    q, c, v, vp = r.q, r.c, r.v, r.vp
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
    r.nk += 1.0
    r.t += dt


@numba.njit(cache=False)
def _step_view(s: np.ndarray, dth: np.ndarray, dv: np.ndarray, dt: float) -> None:
    """The same step, the record taken over the float64 vector in this call."""
    _step_record(s.view(RECORD)[0], dth, dv, dt)


@numba.njit(cache=False)
def steps_offsets(s: np.ndarray, n: int, dth: np.ndarray, dv: np.ndarray, dt: float) -> float:
    for _ in range(n):
        _step_offsets(s, dth, dv, dt)
    return s[S.V] + s[S.C + 4]


@numba.njit(cache=False)
def steps_record(r: np.ndarray, n: int, dth: np.ndarray, dv: np.ndarray, dt: float) -> float:
    rec = r[0]
    for _ in range(n):
        _step_record(rec, dth, dv, dt)
    return rec.v[0] + rec.c[4]


@numba.njit(cache=False)
def steps_view_once(s: np.ndarray, n: int, dth: np.ndarray, dv: np.ndarray, dt: float) -> float:
    rec = s.view(RECORD)[0]  # once, at the entry: the helpers take the record
    for _ in range(n):
        _step_record(rec, dth, dv, dt)
    return s[S.V] + s[S.C + 4]


@numba.njit(cache=False)
def steps_view_each(s: np.ndarray, n: int, dth: np.ndarray, dv: np.ndarray, dt: float) -> float:
    for _ in range(n):
        _step_view(s, dth, dv, dt)
    return s[S.V] + s[S.C + 4]


def main(argv: Sequence[str] = ()) -> list[dict]:
    """Time the layouts on the same work; one row each and the ratio to the offsets."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="200,000 steps instead of 2,000,000")
    args = p.parse_args(list(argv))
    n = 200_000 if args.quick else 2_000_000
    dth, dv, dt = np.array([1e-4, -2e-4, 3e-4]), np.array([1e-3, 2e-3, -9.8e-2]), 0.01

    def fresh() -> tuple[np.ndarray, np.ndarray]:
        s = sd.init_state(0.0, 0.8, 0.1, 100.0, np.zeros(3), 0.0, 0.0, 0.5)
        r = np.zeros(1, dtype=RECORD)
        for f in sd.STATE_LAYOUT:
            at = getattr(sd.S, f.name)
            r[0][f.name.lower()] = s[at:at + f.size] if f.size > 1 else s[at]
        return s, r

    runs = {"offsets": (steps_offsets, "state by offsets (float64 vector, S.<NAME> from STATE_LAYOUT)"),
            "record": (steps_record, "state as a numba record (same named fields)"),
            "view_once": (steps_view_once, "record view of the float64 vector, taken once at the entry"),
            "view_each": (steps_view_each, "record view of the float64 vector, taken in every step's call")}

    def run_all(steps: int) -> dict[str, float]:
        s, r = fresh()
        args = {"offsets": s.copy(), "record": r, "view_once": s.copy(), "view_each": s.copy()}
        out, secs = {}, {}
        for name, (fn, _) in runs.items():
            t0 = time.perf_counter()
            out[name] = fn(args[name], steps, dth, dv, dt)
            secs[name] = time.perf_counter() - t0
        if len(set(out.values())) != 1:
            raise SystemExit(f"the layouts gave different results: {out}")
        return secs

    run_all(10)  # compiled here
    best = {name: np.inf for name in runs}
    for _ in range(5):  # interleaved: the machine's load falls on every layout alike
        for name, sec in run_all(n).items():
            best[name] = min(best[name], sec)
    rows = [{"case": case, "samples": n, "seconds": best[k], "rate": n / best[k],
             "value": f"{1e9 * best[k] / n:.2f} ns/step", "ratio": best[k] / best["offsets"],
             "baseline": "(is the baseline)" if k == "offsets" else "state by offsets"}
            for k, (_, case) in runs.items()]
    # plain Python (NUMBA_DISABLE_JIT=1: what mutation testing and a debugger run): the helpers' Python
    m = n // 100
    plain = {"offsets": np.inf, "record": np.inf}
    for _ in range(3):
        s, r = fresh()
        t0 = time.perf_counter()
        for _ in range(m):
            _step_offsets.py_func(s, dth, dv, dt)
        plain["offsets"] = min(plain["offsets"], time.perf_counter() - t0)
        rec = r[0]
        t0 = time.perf_counter()
        for _ in range(m):
            _step_record.py_func(rec, dth, dv, dt)
        plain["record"] = min(plain["record"], time.perf_counter() - t0)
        if s[S.V] != rec.v[0] or s[S.C + 4] != rec.c[4]:
            raise SystemExit("the layouts gave different results in plain Python")
    for k, case in (("offsets", "plain Python: state by offsets"), ("record", "plain Python: state as a record")):
        rows.append({"case": case, "samples": m, "seconds": plain[k], "rate": m / plain[k],
                     "value": f"{1e6 * plain[k] / m:.2f} us/step", "ratio": plain[k] / plain["offsets"],
                     "baseline": "(is the baseline)" if k == "offsets" else "plain Python: state by offsets"})
    NOTES.clear()
    NOTES.append(f"state layout: the same {n:,} steps bit for bit in every layout (checked); each step one helper call")
    return rows

if __name__ == "__main__":
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)
