"""Figures and tables of docs/redundancy.md: detection delay against fault size (simulation beside
the non-central chi-square theory), false alarms over 10 h against the design, six-sensor sets.

    .venv/bin/python scripts/redundancy_study.py [--trials N] [--out docs/images/redundancy_delay.png]

Three consumer IMUs at rest (the simulator's full error model), 100 Hz, the gyro set of
mavins.core.fdi with its defaults (0.5 s window, 60 s bias tracker, P_fa = 1e-6 per test). A fault
on IMU 1's x gyro starts 70 s in (after the tracker has settled) at a random phase of the window.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from mavins.core import redundancy as rd
from mavins.core.errmodel import spec_from_grade
from mavins.core.fdi import ImuSetMonitor, ParityMonitor
from sim import errors, faults

RATE = 100.0
WINDOW = 0.5
TAU_BIAS = 60.0
P_FA = 1e-6
T_FAULT = 70.0
HORIZON = 20.0
STEPS = (0.03, 0.04, 0.05, 0.06, 0.08, 0.1, 0.2, 0.5)  # deg/s
RAMPS = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5)  # deg/s^2


def _model() -> errors.ImuErrorModel:
    m = errors.grade("consumer")
    return dataclasses.replace(m, jitter_sigma=0.0, drop_probability=0.0)


def _sigma() -> float:
    s = spec_from_grade("consumer")
    return rd.window_sigma(s.gyro_arw, WINDOW, TAU_BIAS, s.gyro_gm, s.gyro_tau, s.gyro_rrw)


def simulate_delay(kind: str, size: float, trials: int, rng: np.random.Generator) -> np.ndarray:
    """Detection delays (s; NaN when not within HORIZON) of ``trials`` runs with random onset phase."""
    n = int((T_FAULT + HORIZON) * RATE)
    t = np.arange(1, n + 1) / RATE
    dt = np.full(n, 1.0 / RATE)
    zero = np.zeros((n, 3))
    H = rd.triad_rows([np.eye(3)] * 3)
    model = _model()
    delays = np.full(trials, np.nan)
    for k in range(trials):
        seed = int(rng.integers(1 << 31))
        m = np.concatenate([errors.apply(model, t, zero, zero, seed + i, t_start=0.0)[1] for i in range(3)], axis=1)
        start = T_FAULT + float(rng.uniform(0.0, WINDOW))
        value = math.radians(size)
        f = faults.Fault(kind, 1, "gyro", 0, start, math.inf, value)
        m[:, 3] = faults.apply_channel(f, m[:, 3], t - 1.0 / RATE, t)
        mon = ParityMonitor(H, _sigma(), window=round(WINDOW * RATE), window_s=WINDOW, false_alarm=P_FA,
                            tau_bias=TAU_BIAS, calibration=10, holdoff=20)
        _, events = mon.process(t, m, dt)
        hits = [e.t for e in events if e.event == "detected" and e.t > start]
        if hits:
            delays[k] = hits[0] - start
    return delays


_PD_GRID = np.concatenate(([0.0], np.geomspace(1e-3, 2e4, 600)))
_PD: np.ndarray | None = None


def _pd(lam: float) -> float:
    """Detection probability at non-centrality ``lam`` (tabulated once, interpolated; 1 past the table)."""
    global _PD
    if _PD is None:
        thr = rd.chi2_quantile(P_FA, 6, upper=True)
        _PD = np.array([rd.detection_probability(x, 6, thr) for x in _PD_GRID])
    return float(np.interp(lam, _PD_GRID, _PD, right=1.0))


def theory_delay(kind: str, size: float, phases: int = 40) -> tuple[float, float]:
    """Expected delay (s) and the probability of detection within HORIZON, from the non-central
    chi-square: window k after the onset has mean parity ``r_k v_j`` with ``|v_j|^2 = 2/3`` (three
    triads), ``r_k`` the fault's window mean minus what the bias tracker (weight T/tau_bias per window)
    has taken of it; detection in window k has probability ``1 - F(thr; 6, r_k^2 |v_j|^2 / s^2)`` and
    windows are taken as independent (the white noise dominates the window error)."""
    s2 = _sigma() ** 2
    alpha = WINDOW / TAU_BIAS
    f = math.radians(size)
    n_win = int(HORIZON / WINDOW)
    total_delay = total_pd = 0.0
    for c in (np.arange(phases) + 0.5) / phases:  # part of the first window the fault covers
        ends = c * WINDOW + WINDOW * np.arange(n_win)  # window ends after the onset, s
        starts = np.maximum(ends - WINDOW, 0.0)
        if kind == "step":
            mean = f * (ends - starts) / WINDOW
        else:  # window mean of slope (t - onset) over the covered part
            mean = f * 0.5 * (ends**2 - starts**2) / WINDOW
        beta = 0.0
        alive = 1.0
        exp_delay = 0.0
        for k in range(n_win):
            r = mean[k] - beta
            pd = _pd(r * r * (2.0 / 3.0) / s2)
            exp_delay += alive * pd * ends[k]
            alive *= 1.0 - pd
            beta += alpha * r  # the tracker moves b along P e_j by alpha times the residual
            if alive < 1e-12:
                break
        total_delay += exp_delay / max(1.0 - alive, 1e-300)
        total_pd += 1.0 - alive
    return total_delay / phases, total_pd / phases


def false_alarms(hours: float, seed: int) -> list[tuple[float, str, int, float]]:
    """(design P, sensor, alarms, expected) over ``hours`` of the consumer model at the window level."""
    model = errors.grade("consumer")
    model = dataclasses.replace(model, gyro=dataclasses.replace(model.gyro, quantization=0.0),
                                accel=dataclasses.replace(model.accel, quantization=0.0),
                                jitter_sigma=0.0, drop_probability=0.0)
    n = round(hours * 3600.0 / WINDOW)
    t = WINDOW * np.arange(1, n + 1)
    zero = np.zeros((n, 3))
    draws = [errors.apply(model, t, zero, zero, seed + k, t_start=0.0) for k in range(3)]
    dth = np.stack([d[1] for d in draws], axis=1)
    dv = np.stack([d[2] for d in draws], axis=1)
    rows = []
    for p in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6):
        mon = ImuSetMonitor(3, spec_from_grade("consumer"), WINDOW, false_alarm=p)
        mon.process(t, dth, dv, np.full(n, WINDOW))
        for part in (mon.gyro, mon.accel):
            st = part.statistics()
            rows.append((p, part.name, int(np.sum(st[:, 1] > st[:, 2])), st.shape[0] * p))
    return rows


def configurations() -> list[tuple[str, int, float, float, float]]:
    """(name, N, GDOP, smallest angle between parity columns deg, isolable) of sensor sets."""
    out = []
    sets = {
        "1 triad": np.eye(3),
        "2 triads": rd.triad_rows([np.eye(3)] * 2),
        "3 triads": rd.triad_rows([np.eye(3)] * 3),
        "4 axes (triad + 1,1,1)": np.vstack([np.eye(3), np.ones(3) / math.sqrt(3.0)]),
        "5 axes, 54.7 deg cone": rd.cone_axes(5),
        "6 axes, dodecahedron": rd.dodecahedron_axes(),
        "6 axes, 54.7 deg cone": rd.cone_axes(6),
    }
    for name, H in sets.items():
        n = H.shape[0]
        angle = math.nan
        iso = 0.0
        if n > 3:
            V = rd.parity_matrix(H)
            u = V / np.linalg.norm(V, axis=0)
            cos = np.abs(u.T @ u)[~np.eye(n, dtype=bool)]
            angle = math.degrees(math.acos(min(1.0, float(cos.max()))))
            iso = float(rd.isolable(V).mean())
        out.append((name, n, rd.gdop(H), angle, iso))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs/images/redundancy_delay.png")
    ap.add_argument("--seed", type=int, default=14)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"window sigma {_sigma():.4g} rad/s; threshold {rd.chi2_quantile(P_FA, 6, upper=True):.4f} (6 dof)")
    print("\n| configuration | N | GDOP | smallest angle between parity columns | isolable |")
    print("|---|---|---|---|---|")
    for name, n, g, ang, iso in configurations():
        a = "-" if math.isnan(ang) else f"{ang:.2f} deg"
        print(f"| {name} | {n} | {g:.4f} | {a} | {'all' if iso == 1 else 'none' if iso == 0 else f'{iso:.0%}'} |")
    print("\n| design P per test | sensor | alarms in 10 h | expected |")
    print("|---|---|---|---|")
    for p, name, k, e in false_alarms(10.0, 2024):
        print(f"| {p:g} | {name} | {k} | {e:.2f} |")
    results = {}
    print("\n| fault | size | detected (sim) | mean delay sim (s) | theory (s) | P(detect) theory |")
    print("|---|---|---|---|---|---|")
    for kind, sizes, unit in (("step", STEPS, "deg/s"), ("ramp", RAMPS, "deg/s^2")):
        rows = []
        for size in sizes:
            d = simulate_delay(kind, size, args.trials, rng)
            th, pd = theory_delay(kind, size)
            ok = d[np.isfinite(d)]
            mean = float(ok.mean()) if ok.size else math.nan
            lo, hi = (np.percentile(ok, [10, 90]) if ok.size else (math.nan, math.nan))
            rows.append((size, mean, lo, hi, th, ok.size / d.size, pd))
            print(f"| {kind} | {size:g} {unit} | {ok.size / d.size:.0%} | {mean:.3f} | {th:.3f} | {pd:.3f} |")
        results[kind] = (np.array(rows), unit)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, kind in zip(axes, ("step", "ramp")):
        r, unit = results[kind]
        ax.errorbar(r[:, 0], r[:, 1], yerr=[r[:, 1] - r[:, 2], r[:, 3] - r[:, 1]], fmt="o", capsize=3,
                    label=f"simulation ({args.trials} runs: mean, 10-90 %)")
        fine = np.geomspace(r[0, 0], r[-1, 0], 60)
        ax.plot(fine, [theory_delay(kind, s)[0] for s in fine], "-", label="non-central chi-square theory")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xticks(r[:, 0], [f"{v:g}" for v in r[:, 0]], fontsize=8)
        ax.set_xlabel(f"{kind} size ({unit})")
        ax.set_ylabel("detection delay (s)")
        ax.set_title(f"gyro {kind}, 3 consumer IMUs, 0.5 s window, P_fa 1e-6")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
