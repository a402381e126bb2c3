"""Aided replay of a PX4 log against the autopilot's own estimate in the same log.

Runs ``mavins replay LOG`` with the log's own GNSS, barometer and magnetometer
(the default ``--aiding gnss,baro,mag``) and free inertial (``--aiding none``),
then compares each solution with what PX4 logged:

- horizontal: PX4's ``vehicle_global_position`` when logged, else its
  ``vehicle_local_position`` x/y where ``xy_valid``; when PX4 has no horizontal
  estimate at all (as in data/px4-gps-small, where EKF2 never passed its GPS
  checks), the log's own GPS fixes;
- vertical: the height change since the first solution row against PX4's
  (``-z`` of ``vehicle_local_position``: PX4's origin height is not logged, and
  heights on different datums differ by a constant), and the down velocity
  against PX4's ``vz``;
- attitude: the rotation angle between our ``q_nb`` and PX4's
  ``vehicle_attitude.q`` (both FRD body to NED, Hamilton, scalar first), and the
  heading difference.

The replays use ``--declination`` = the log's ``EKF2_MAG_DECL``, as PX4 does.
It prints a Markdown table (RMS, largest magnitude, final value; a final
value keeps its sign) and writes a PNG plot. Run from
the repository root::

    .venv/bin/python scripts/real_data_report.py [LOG.ulg] [--png docs/images/real-data-aided.png]
    .venv/bin/python scripts/real_data_report.py --defaults [--code CHECKOUT]

``--defaults`` instead replays every PX4 log in data/ with no options at all, as
a new user would, and prints one table row per log against PX4's estimate
(``--code`` runs another checkout's package, for a before/after comparison).

Bad input (no such log, not a ULog, no attitude or GPS topic): one line on
stderr, exit 2, and no plot is written.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np

from mavins.core import earth
from mavins.core.frames import north_east_error
from mavins.core.rotation import quat_angle_rows, wrap_pi
from mavins.common.files import DataFileError, atomic_output

LOG = ROOT / "data" / "px4-gps-small" / "sample_log_small.ulg"
PNG = ROOT / "docs" / "images" / "real-data-aided.png"
ALIGN_S = 1.0  # s of the log at rest used for the coarse alignment (the log holds 6.5 s)
OFFSET_N = 40.0  # m: the second pair of runs starts this far north of the first fix (see docs/real-data.md)
EXIT_USAGE = 2


@dataclass
class Reference:
    """What the log says besides the IMU: PX4's estimate and the GPS fixes (times in s, IMU clock)."""

    t_att: np.ndarray
    q_att: np.ndarray  # (n, 4) q_nb, w x y z
    t_lp: np.ndarray
    up: np.ndarray  # m: -z of vehicle_local_position (height above PX4's origin)
    vz: np.ndarray  # m/s, down
    epv: np.ndarray  # m: PX4's vertical 1-sigma
    evv: np.ndarray  # m/s
    t_hz: np.ndarray | None  # PX4's horizontal estimate (deg, deg) when it has one
    lat_hz: np.ndarray | None
    lon_hz: np.ndarray | None
    t_gps: np.ndarray
    lat_gps: np.ndarray  # deg
    lon_gps: np.ndarray
    h_gps: np.ndarray  # m, ellipsoidal
    eph: np.ndarray  # m, the receiver's stated 1-sigma
    epv_gps: np.ndarray
    sacc: np.ndarray  # m/s
    declination: float  # deg: EKF2_MAG_DECL


def _topic(ulog: object, name: str) -> dict | None:
    for d in ulog.data_list:  # type: ignore[attr-defined]
        if d.name == name and d.multi_id == 0 and len(d.data.get("timestamp", ())):
            return d.data
    return None


def read_reference(path: Path) -> Reference:
    """PX4's estimate and GPS fixes of a ULog (field units: PX4 msg/*.msg of the log's version)."""
    from pyulog import ULog

    try:
        ulog = ULog(str(path), ["vehicle_attitude", "vehicle_local_position", "vehicle_global_position",
                                "vehicle_gps_position", "sensor_gps"])
    except Exception as exc:  # noqa: BLE001  (pyulog raises plain exceptions on bad files)
        raise DataFileError(f"{path}: not a readable ULog: {exc}") from None
    att, lp = _topic(ulog, "vehicle_attitude"), _topic(ulog, "vehicle_local_position")
    gps = _topic(ulog, "vehicle_gps_position") or _topic(ulog, "sensor_gps")
    if att is None or lp is None or gps is None:
        raise DataFileError(f"{path}: expected vehicle_attitude, vehicle_local_position and a GPS topic")
    us = 1e-6  # ULog timestamps: us of the boot clock
    t_hz = lat_hz = lon_hz = None
    gp = _topic(ulog, "vehicle_global_position")
    if gp is not None:
        t_hz, lat_hz, lon_hz = gp["timestamp"] * us, gp["lat"], gp["lon"]  # float64 deg
    elif np.any(lp["xy_valid"]) and np.any(lp["ref_lat"]):
        ok = lp["xy_valid"] > 0
        lat0, lon0 = np.radians(lp["ref_lat"][ok]), np.radians(lp["ref_lon"][ok])
        r_n, r_e = earth.radii(lat0)  # x north, y east (m) from PX4's reference point, through its radii
        t_hz = lp["timestamp"][ok] * us
        lat_hz = np.degrees(lat0 + lp["x"][ok] / r_n)
        lon_hz = np.degrees(lon0 + lp["y"][ok] / (r_e * np.cos(lat0)))
    if "latitude_deg" in gps:  # sensor_gps from v1.14: float64 deg and m
        lat, lon, h = gps["latitude_deg"], gps["longitude_deg"], gps["altitude_ellipsoid_m"]
    else:  # int32 1e-7 deg and mm
        lat, lon, h = gps["lat"] * 1e-7, gps["lon"] * 1e-7, gps["alt_ellipsoid"] * 1e-3
    fix = gps["fix_type"] >= 3
    q = np.column_stack([att[f"q[{i}]"] for i in range(4)]).astype(float)
    return Reference(
        att["timestamp"] * us, q, lp["timestamp"] * us, -lp["z"].astype(float), lp["vz"].astype(float),
        lp["epv"].astype(float), lp["evv"].astype(float), t_hz, lat_hz, lon_hz,
        gps["timestamp"][fix] * us, lat[fix].astype(float), lon[fix].astype(float), h[fix].astype(float),
        gps["eph"][fix].astype(float), gps["epv"][fix].astype(float), gps["s_variance_m_s"][fix].astype(float),
        float(ulog.initial_parameters.get("EKF2_MAG_DECL", 0.0)),
    )


def replay_command(log: Path, out: Path, aiding: str, decl: float, start: tuple[float, float, float] | None) -> list[str]:
    """The ``mavins replay`` command line of one run."""
    cmd = ["mavins", "replay", str(log), "-o", str(out), "--align", f"{ALIGN_S:g}", "--declination", f"{decl:.2f}",
           "--aiding", aiding]
    if start is not None:
        cmd += ["--lat", f"{start[0]:.7f}", "--lon", f"{start[1]:.7f}", "--alt", f"{start[2]:.3f}"]
    return cmd


def run_replay(cmd: list[str], code: Path = ROOT) -> np.ndarray:
    """Run one replay (``mavins`` = this interpreter's module, from the checkout ``code``); its solution rows."""
    import os

    env = {**os.environ, "PYTHONPATH": str(code)}
    proc = subprocess.run([sys.executable, "-m", "mavins.cli", *cmd[1:]], check=False, capture_output=True, text=True,
                          cwd=code, env=env)
    if proc.returncode != 0:
        raise DataFileError(proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else "mavins replay failed")
    return np.loadtxt(cmd[cmd.index("-o") + 1], delimiter=",", skiprows=1, ndmin=2)


@dataclass
class Comparison:
    """Differences of one solution to the reference over time."""

    t_h: np.ndarray  # s: times of the horizontal comparison
    horiz: np.ndarray  # m
    bound_h: np.ndarray  # m: 3 x the reference's stated horizontal 1-sigma
    t: np.ndarray  # s: solution rows
    vert: np.ndarray  # m: our height change minus PX4's, since the first row
    bound_v: np.ndarray  # m: 3 sqrt(epv_gps^2 + epv_px4^2)
    vel_d: np.ndarray  # m/s: our down velocity minus PX4's
    att: np.ndarray  # deg: rotation angle between the attitudes
    level: np.ndarray  # deg: angle between the two body down axes (roll and pitch together)
    yaw: np.ndarray  # deg: our heading minus PX4's
    horiz_to: str  # what the horizontal comparison is against


def compare(sol: np.ndarray, ref: Reference) -> Comparison:
    """Our solution (contract columns) against PX4's estimate (and the GPS fixes for the horizontal)."""
    t = sol[:, 0]
    lat, lon = np.radians(sol[:, 1]), np.radians(sol[:, 2])
    if ref.t_hz is not None:
        keep = (ref.t_hz >= t[0]) & (ref.t_hz <= t[-1])
        t_h, lat_r, lon_r = ref.t_hz[keep], ref.lat_hz[keep], ref.lon_hz[keep]  # type: ignore[index]
        bound = np.full(len(t_h), np.nan)
        what = "PX4's horizontal position"
    else:
        keep = (ref.t_gps >= t[0]) & (ref.t_gps <= t[-1])
        t_h, lat_r, lon_r = ref.t_gps[keep], ref.lat_gps[keep], ref.lon_gps[keep]
        bound = 3.0 * ref.eph[keep]
        what = "the log's GPS fixes (PX4 logged no horizontal estimate)"
    lat_i, lon_i = np.interp(t_h, t, lat), np.interp(t_h, t, lon)
    horiz = np.array([math.hypot(*north_east_error(a, b, math.radians(c), math.radians(d)))
                      for a, b, c, d in zip(lat_i, lon_i, lat_r, lon_r)])
    up = np.interp(t, ref.t_lp, ref.up)
    vert = (sol[:, 3] - sol[0, 3]) - (up - up[0])
    epv_px4 = np.interp(t, ref.t_lp, ref.epv)
    epv_gps = np.interp(t, ref.t_gps, ref.epv_gps)
    vel_d = sol[:, 6] - np.interp(t, ref.t_lp, ref.vz)
    idx = np.clip(np.searchsorted(ref.t_att, t), 0, len(ref.t_att) - 1)  # PX4 logs attitude on the IMU's stamps
    q_ref = ref.q_att[idx]
    q_ref = q_ref / np.linalg.norm(q_ref, axis=1, keepdims=True)
    att = np.degrees(quat_angle_rows(np.ascontiguousarray(sol[:, 10:14]), np.ascontiguousarray(q_ref)))
    yaw_ref = np.arctan2(2 * (q_ref[:, 0] * q_ref[:, 3] + q_ref[:, 1] * q_ref[:, 2]),
                         1 - 2 * (q_ref[:, 2] ** 2 + q_ref[:, 3] ** 2))  # ZYX yaw of q_nb
    yaw = np.degrees([wrap_pi(a) for a in np.radians(sol[:, 9]) - yaw_ref])
    level = np.degrees(np.arccos(np.clip(np.sum(_down_axis(sol[:, 10:14]) * _down_axis(q_ref), axis=1), -1.0, 1.0)))
    return Comparison(t_h, horiz, bound, t, vert, 3.0 * np.hypot(epv_gps, epv_px4), vel_d, att, level, yaw, what)


def _down_axis(q: np.ndarray) -> np.ndarray:
    """The body z axis in NED, the third column of C(q) = C_b^n for rows of q_nb (w, x, y, z)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.column_stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def stats(x: np.ndarray) -> tuple[float, float, float]:
    """(RMS, largest magnitude, final value) of a series."""
    return float(np.sqrt(np.mean(x ** 2))), float(np.max(np.abs(x))), float(x[-1])


def table(runs: list[tuple[str, Comparison]]) -> str:
    """Markdown table: one row per quantity, one column per run, cells "RMS / max / final"."""
    lines = ["| quantity (RMS / max / final) | " + " | ".join(name for name, _ in runs) + " |",
             "|---|" + "---|" * len(runs)]
    for label, attr in (("horizontal (m)", "horiz"), ("vertical change (m)", "vert"),
                        ("down velocity (m/s)", "vel_d"), ("attitude angle (deg)", "att"),
                        ("level (deg)", "level"), ("heading (deg)", "yaw")):
        cells = ["{:.2f} / {:.2f} / {:.2f}".format(*stats(getattr(c, attr))) for _, c in runs]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(runs: list[tuple[str, Comparison]], png: Path) -> None:
    """Four panels against sensor time; written through a temporary file."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(5, 1, figsize=(8, 11), sharex=True)
    styles = ["-", "--", "-.", ":"]
    for (name, c), ls in zip(runs, styles):
        axes[0].plot(c.t_h, c.horiz, ls, marker=".", label=name)
        axes[1].plot(c.t, c.vert, ls, label=name)
        axes[2].plot(c.t, c.vel_d, ls, label=name)
        axes[3].plot(c.t, c.yaw, ls, label=name)
        axes[4].plot(c.t, c.level, ls, label=name)
    c0 = runs[0][1]
    if np.all(np.isfinite(c0.bound_h)):
        axes[0].plot(c0.t_h, c0.bound_h, "k:", label="3 x GPS eph")
    axes[0].set_yscale("log")
    axes[0].set_ylabel("horizontal (m)")
    axes[0].set_title(f"distance to {c0.horiz_to}", fontsize=9)
    axes[1].set_ylabel("height change\nminus PX4's (m)")
    axes[2].set_ylabel("down velocity\nminus PX4's (m/s)")
    axes[3].set_ylabel("heading\nminus PX4's (deg)")
    axes[4].set_ylabel("level: angle of\ndown axes (deg)")
    axes[4].set_xlabel("sensor time (s)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    with atomic_output(png) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)


DATA_LOGS = ("px4-sitl-events/sample_px4_events.ulg", "px4-gps-small/sample_log_small.ulg", "px4-sample/sample.ulg")


def defaults_table(code: Path) -> str:
    """Every PX4 log in data/ replayed the way a new user runs it, ``mavins replay LOG -o NAV.csv`` with no
    option, by the package in ``code``: a Markdown table against PX4's own estimate (RMS / max)."""
    lines = ["| log | rows | heading (deg) | level (deg) | horizontal (m) | height change (m) |", "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for name in DATA_LOGS:
            log = ROOT / "data" / name
            out = Path(tmp) / "nav.csv"
            try:
                ref = read_reference(log)
            except DataFileError:
                ref = None
            try:
                sol = run_replay(["mavins", "replay", str(log), "-o", str(out)], code)
            except DataFileError as exc:
                why = str(exc).replace(str(log), name).replace("mavins replay: error: ", "")
                lines.append(f"| {name} | no solution: {why} | | | | |")
                continue
            if ref is None:
                lines.append(f"| {name} | {len(sol)} | (no PX4 estimate with GPS in the log) | | | |")
                continue
            c = compare(sol, ref)
            cells = ["{:.2f} / {:.2f}".format(*stats(x)[:2]) for x in (c.yaw, c.level, c.horiz, c.vert)]
            lines.append(f"| {name} | {len(sol)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", type=Path, nargs="?", default=LOG, help="PX4 .ulg with GPS (default: %(default)s)")
    ap.add_argument("--png", type=Path, default=PNG, help="plot to write (default: %(default)s)")
    ap.add_argument("--defaults", action="store_true",
                    help="instead: every PX4 log in data/ replayed with no options against PX4's estimate")
    ap.add_argument("--code", type=Path, default=ROOT,
                    help="with --defaults: the checkout whose mavins replays (e.g. a worktree of an earlier "
                         "commit, for a before/after table; default: this one)")
    args = ap.parse_args(argv)
    if args.defaults:
        if not ((args.code / "mavins" / "cli.py").is_file() or (args.code / "mavins" / "cli").is_dir()):
            print(f"real_data_report: error: {args.code}: no mavins checkout there", file=sys.stderr)
            return EXIT_USAGE
        print(defaults_table(args.code.resolve()))
        return 0
    try:
        if not args.log.is_file():
            raise DataFileError(f"{args.log}: no such file")
        ref = read_reference(args.log)
        if len(ref.t_gps) == 0:
            raise DataFileError(f"{args.log}: no GPS fix (fix_type 3 or better) in the log")
        r_n = float(earth.radii(math.radians(ref.lat_gps[0]))[0])
        off = (float(ref.lat_gps[0]) + math.degrees(OFFSET_N / r_n), float(ref.lon_gps[0]), float(ref.h_gps[0]))
        runs: list[tuple[str, Comparison]] = []
        with tempfile.TemporaryDirectory() as tmp:
            for name, aiding, start in (("aided", "gnss,baro,mag", None), ("free inertial", "none", None),
                                        (f"aided, start {OFFSET_N:g} m N", "gnss,baro,mag", off),
                                        (f"free, start {OFFSET_N:g} m N", "none", off)):
                cmd = replay_command(args.log, Path(tmp) / "nav.csv", aiding, ref.declination, start)
                print("$ " + " ".join(cmd).replace(str(Path(tmp)) + "/", "").replace(str(ROOT) + "/", ""))
                runs.append((name, compare(run_replay(cmd), ref)))
        plot(runs, args.png)
    except (DataFileError, OSError) as exc:
        print(f"real_data_report: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    print()
    print(f"Horizontal: distance to {runs[0][1].horiz_to}. Vertical: height change since the first row "
          "minus PX4's. Attitude: angle between our q_nb and PX4's vehicle_attitude.")
    print()
    print(table(runs))
    c = runs[0][1]
    print()
    print(f"GPS stated 1-sigma over the replay: eph {ref.eph.min():.2f}-{ref.eph.max():.2f} m, "
          f"epv {ref.epv_gps.min():.2f}-{ref.epv_gps.max():.2f} m, speed {ref.sacc.min():.2f}-{ref.sacc.max():.2f} m/s; "
          f"horizontal bound 3 eph {c.bound_h.min():.1f}-{c.bound_h.max():.1f} m")
    print(f"plot: {args.png.relative_to(ROOT) if args.png.is_relative_to(ROOT) else args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
