"""``mavins replay``: the live pipeline over recorded logs.

1. Replay equals live. ``mavins run --tlog X.tlog -o live.csv`` serves a real
   UDP stream from the simulator (a subprocess, paced); ``mavins replay X.tlog
   -o replay.csv`` with the same navigation options must write the same file,
   byte for byte: the service navigates on sensor time only, and the tlog keeps
   every message it handled, in order (docs/conventions.md "MAVLink").
2. Real data. ``data/px4-sample/sample.ulg`` (PX4, hand-moved board, then at
   rest; data/README.md) replayed with the position given (the log has no GPS),
   ``--align 2`` (the board rests only for the first 2.2 s) and ``--heading`` =
   PX4's own yaw at the end of the alignment window (a .ulg replay has no
   ATTITUDE message). The solution must track PX4's attitude estimate
   (``truth.csv.gz``) within ``PX4_LIMIT_DEG`` over the whole log, and the
   default ``--gyro-bias estimate`` must be what makes that possible: without it
   the ~0.2 deg/s bias of this board drifts the attitude by over 10 deg.

Limit for (2): PX4's estimate is a filter output, not truth (meta.json
"reference"). data/README.md's own check, a perfect 10 s integration of these
gyros with the rest bias removed, already differs from it by up to 1.5 deg
during the motion; here the bias comes from 2 s of rest only and the
integration runs 67 s, so 3 deg is "within a few degrees" with about 1 deg of
room over what was measured (max 1.95 deg, docs/service.md).
"""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from support import EVENT_TIMEOUT_S, REPO, free_udp_port, mavins, quat_angle_deg, running_service, wait_until_read

PX4 = REPO / "data" / "px4-sample"

START = ("47.397742", "8.545594", "488.0")  # sim/scenarios/flight.toml [start]
PX4_ALIGN_S = 2.0
PX4_LIMIT_DEG = 3.0
PX4_NO_BIAS_MIN_DEG = 10.0  # without the bias estimate: 0.21 deg/s over 67 s is ~14 deg


# -- 1. replay equals live -----------------------------------------------------------
NAV_OPTIONS = ["--lat", START[0], "--lon", START[1], "--alt", START[2], "--heading", "vehicle", "--align", "5",
               "--rate", "25", "--samples", "3"]


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, str]:
    """A consumer-grade stream (noise, bias, timing jitter, dropped samples) served live: (tlog, csv, log)."""
    tmp_path = tmp_path_factory.mktemp("live")
    port = free_udp_port()
    tlog, live_csv = tmp_path / "live.tlog", tmp_path / "live.csv"
    log_path = tmp_path / "service.log"
    with running_service(log_path, "--master", f"udpin:127.0.0.1:{port}", "--tlog", str(tlog), "-o", str(live_csv),
                         *NAV_OPTIONS, cwd=tmp_path, stop_timeout=EVENT_TIMEOUT_S) as svc:
        sim = mavins("sim", "flight", "--grade", "consumer", "--seed", "3", "--duration", "40", "--speed", "10",
                     "--stream", f"udpout:127.0.0.1:{port}", cwd=tmp_path)
        assert sim.returncode == 0, sim.stderr
        wait_until_read(port, svc)  # the service has read everything queued (an event, not a pause)
    service_log = log_path.read_text()
    assert svc.returncode == 0, service_log
    return tlog, live_csv, service_log


def test_replay_of_the_live_tlog_writes_the_same_solution(live: tuple[Path, Path, str], tmp_path: Path) -> None:
    tlog, live_csv, service_log = live
    assert "final state: NAVIGATING" in service_log, service_log
    rows_live = live_csv.read_text().splitlines()
    assert len(rows_live) > 30 * 25, f"{len(rows_live)} rows: the live run navigated for ~35 s at 25 Hz"
    again = tmp_path / "replay.csv"
    res = mavins("replay", str(tlog), "-o", str(again), *NAV_OPTIONS, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "final state NAVIGATING" in res.stderr and "heading from vehicle ATTITUDE" in res.stderr, res.stderr
    assert again.read_bytes() == live_csv.read_bytes(), "replay differs from live"


def test_replay_to_parquet_holds_the_same_doubles(live: tuple[Path, Path, str], tmp_path: Path) -> None:
    """docs/conventions.md "Files": a table named as CSV may be written as .parquet, float64 columns of the same names."""
    import pyarrow.parquet as pq

    tlog, live_csv, _ = live
    out = tmp_path / "replay.parquet"
    res = mavins("replay", str(tlog), "-o", str(out), *NAV_OPTIONS, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    table = pq.read_table(out)
    header = live_csv.read_text().split("\n", 1)[0].split(",")
    want = np.loadtxt(live_csv, delimiter=",", skiprows=1, ndmin=2)
    got = np.column_stack([table.column(c).to_numpy() for c in table.column_names])
    assert table.column_names == header and got.shape == want.shape
    assert np.array_equal(got.view(np.int64), want.view(np.int64))  # bit for bit, NaN included


def test_replay_with_other_options_differs(live: tuple[Path, Path, str], tmp_path: Path) -> None:
    """Control: the identity above is not an accident of options being ignored."""
    tlog, live_csv, _ = live
    other = [*NAV_OPTIONS[:-2], "--samples", "2"]
    res = mavins("replay", str(tlog), "-o", str(tmp_path / "other.csv"), *other, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    a = live_csv.read_text().splitlines()
    b = (tmp_path / "other.csv").read_text().splitlines()
    assert a[0] == b[0] and a[1:] != b[1:]


# -- 2. real data: PX4 -----------------------------------------------------------------
def _px4_truth() -> np.ndarray:
    with gzip.open(PX4 / "truth.csv.gz", "rt") as fh:
        return np.loadtxt(fh, delimiter=",", skiprows=1)  # t,qw,qx,qy,qz,roll,pitch,yaw


def _px4_align_end() -> float:
    """Sensor time at which a --align 2 alignment ends: the first sample at or after t0 + 2 s."""
    with gzip.open(PX4 / "imu_rates.csv.gz", "rt") as fh:
        t = np.loadtxt(fh, delimiter=",", skiprows=1, usecols=0)
    return float(t[np.searchsorted(t, t[0] + PX4_ALIGN_S)])


def px4_errors(nav_csv: Path, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solution times and the angle (deg) between our attitude and PX4's at those times (nlerp of truth)."""
    nav = np.loadtxt(nav_csv, delimiter=",", skiprows=1)
    t = nav[:, 0]
    q = nav[:, 10:14]
    i = np.clip(np.searchsorted(truth[:, 0], t), 1, len(truth) - 1)
    t0, t1 = truth[i - 1, 0], truth[i, 0]
    q0, q1 = truth[i - 1, 1:5], truth[i, 1:5]
    q1 = np.where((np.sum(q0 * q1, 1) < 0)[:, None], -q1, q1)
    w = ((t - t0) / (t1 - t0))[:, None]
    qt = (1 - w) * q0 + w * q1
    qt /= np.linalg.norm(qt, axis=1)[:, None]
    return t, quat_angle_deg(qt, q)


@pytest.fixture(scope="module")
def px4_setup() -> tuple[np.ndarray, float, list[str]]:
    truth = _px4_truth()
    t_end = _px4_align_end()
    yaw0 = float(np.interp(t_end, truth[:, 0], np.unwrap(truth[:, 7], period=360.0)))
    opts = ["--lat", "47.4", "--lon", "8.5", "--alt", "500", "--align", str(PX4_ALIGN_S), "--heading", f"{yaw0:.3f}"]
    return truth, yaw0, opts


def test_px4_ulg_tracks_px4_attitude(tmp_path: Path, px4_setup) -> None:
    truth, yaw0, opts = px4_setup
    assert -40.0 < yaw0 < -30.0  # data/README.md: about -33.7 deg
    out = tmp_path / "px4.csv"
    res = mavins("replay", str(PX4 / "sample.ulg"), "-o", str(out), *opts, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "final state NAVIGATING" in res.stderr, res.stderr
    t, err = px4_errors(out, truth)
    # the solution covers the log from the end of the alignment to the end
    assert t[0] < _px4_align_end() + 0.05 and t[-1] > 181.0
    # the motion (hand-moved, up to ~28 deg away from the start attitude) is inside the checked span
    moving = (t > 114.8) & (t < 118.7)
    assert moving.sum() > 100
    print(f"\nPX4 sample.ulg vs PX4 attitude: max {err.max():.3f} deg (t = {t[err.argmax()]:.2f} s), "
          f"final {err[-1]:.3f} deg, during the motion max {err[moving].max():.3f} deg")
    assert err.max() < PX4_LIMIT_DEG


def test_px4_gyro_bias_estimate_is_what_keeps_it_on_track(tmp_path: Path, px4_setup) -> None:
    truth, _, opts = px4_setup
    out = tmp_path / "px4-nobias.csv"
    res = mavins("replay", str(PX4 / "sample.ulg"), "-o", str(out), *opts, "--gyro-bias", "none", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    _, err = px4_errors(out, truth)
    print(f"\nPX4 sample.ulg with --gyro-bias none: final {err[-1]:.2f} deg")
    assert err[-1] > PX4_NO_BIAS_MIN_DEG


# --- a fleet: replay --each ------------------------------------------------------------------------------------
FLEET = [REPO / "data" / "px4-sitl-events" / "sample_px4_events.ulg",  # GPS, baro, magnetometer: navigates
         REPO / "data" / "px4-sample" / "sample.ulg",  # no GPS and no --lat/--lon/--alt: no initial position
         REPO / "data" / "px4-gps-small" / "sample_log_small.ulg"]  # 6.5 s of IMU: too short to align


def _summary(path: Path) -> list[dict[str, str]]:
    import csv

    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_replay_each_reports_every_log_and_a_bad_one_stops_nothing(tmp_path: Path) -> None:
    """``mavins replay --each`` over three real PX4 logs: the SITL flight is replayed into OUT/<folder>/<name>
    .nav.csv (the same bytes as replaying it alone), the two that cannot give a solution are reported in
    their rows with the reason and get no file, and OUT/summary.csv has one row per log in the order given;
    exit 2 because some failed. The SITL row: its solution rows are the file's, its GNSS fixes accepted and
    none rejected, its worst test ratio below 1 (every fix passed the gate), its final 1-sigma that of the
    file's last row, its state NAVIGATING."""
    from mavins.cli import main

    out = tmp_path / "out"
    assert main(["replay", "--each", *map(str, FLEET), "-o", str(out), "--jobs", "1"]) == 2
    rows = _summary(out / "summary.csv")
    assert [r["input"] for r in rows] == [str(p) for p in FLEET]
    ok, no_fix, short = rows
    nav_csv = out / "px4-sitl-events" / "sample_px4_events.nav.csv"
    assert ok["output"] == str(nav_csv) and ok["error"] == "" and ok["state"] == "NAVIGATING"
    header, *body = nav_csv.read_text().splitlines()
    assert int(ok["solution_rows"]) == len(body)
    last = dict(zip(header.split(","), body[-1].split(",")))
    for axis in "ned":
        assert float(ok[f"sigma_{axis}"]) == pytest.approx(float(last[f"sigma_{axis}"]), rel=1e-9)
    assert int(ok["gnss_accepted"]) > 100 and int(ok["gnss_rejected"]) == 0
    assert 0.0 < float(ok["worst_ratio"]) < 1.0
    t = [float(line.split(",", 1)[0]) for line in body]
    assert t[-1] - t[0] < float(ok["duration_s"])  # the IMU ran before the first solution (waiting, aligning)
    assert int(ok["samples"]) > 100 * float(ok["duration_s"])  # PX4 SITL's IMU runs at 250 Hz
    assert "no initial position" in no_fix["error"] and no_fix["output"] == "" and no_fix["state"] == ""
    assert "did not finish" in short["error"] and short["output"] == ""
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == [
        "px4-sitl-events/sample_px4_events.nav.csv", "summary.csv"]
    alone = tmp_path / "alone.csv"
    assert main(["replay", str(FLEET[0]), "-o", str(alone)]) == 0
    assert alone.read_bytes() == nav_csv.read_bytes()


def test_replay_each_on_a_dask_cluster_gives_the_same_fleet(tmp_path: Path) -> None:
    """``--cluster ADDRESS`` on a real distributed.LocalCluster (two worker processes): the same solution
    files and the same summary as on local processes, but for the output folder."""
    distributed = pytest.importorskip("distributed")
    from mavins.cli import main

    local, remote = tmp_path / "local", tmp_path / "remote"
    assert main(["replay", "--each", *map(str, FLEET[:2]), "-o", str(local), "--jobs", "2"]) == 2
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc:
        assert main(["replay", "--each", *map(str, FLEET[:2]), "-o", str(remote), "--cluster",
                     lc.scheduler_address]) == 2
    name = Path("px4-sitl-events") / "sample_px4_events.nav.csv"
    assert (local / name).read_bytes() == (remote / name).read_bytes()
    a, b = _summary(local / "summary.csv"), _summary(remote / "summary.csv")
    for r in a + b:
        r["output"] = Path(r["output"]).name if r["output"] else ""
    assert a == b


def test_replay_of_several_logs_needs_each(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Several logs without --each, --jobs or --cluster without --each, --rerun with --each, and an -o that is a
    file with --each are refused with one line, exit 2, nothing written."""
    from mavins.cli import main

    afile = tmp_path / "afile"
    afile.write_text("keep")
    for argv, say in ((["replay", *map(str, FLEET[:2]), "-o", str(tmp_path / "x.csv")], "replay them with --each"),
                      (["replay", str(FLEET[0]), "-o", str(tmp_path / "x.csv"), "--jobs", "2"], "--jobs goes with"),
                      (["replay", str(FLEET[0]), "-o", str(tmp_path / "x.csv"), "--cluster", "tcp://h:1"],
                       "--cluster goes with"),
                      (["replay", "--each", str(FLEET[0]), "-o", str(tmp_path / "d"), "--rerun", "r.rrd"],
                       "--rerun records one log"),
                      (["replay", "--each", str(FLEET[0]), "-o", str(afile)], "-o names a folder")):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("mavins replay: error: ") and say in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"] and afile.read_text() == "keep"


def test_replay_smooth_writes_the_smoothed_solution_and_records_it_beside_the_forward(
        live: tuple[Path, Path, str], tmp_path: Path) -> None:
    """--smooth: the same columns and times as the forward replay (the live run's file), other values (every
    fix now informs every row), the epoch count on stderr; the Rerun file holds the smoothed attitude,
    position and sigma series beside the forward ones (one row per solution row, at most 20000) and the
    smoothed path in the 3D view. The last row, the last epoch's, is the forward one's to the last digit."""
    from rerun.chunk import RrdReader

    tlog, live_csv, _ = live
    out, rrd = tmp_path / "smooth.csv", tmp_path / "smooth.rrd"
    res = mavins("replay", str(tlog), "-o", str(out), "--smooth", "--rerun", str(rrd), *NAV_OPTIONS, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "mavins replay: smoothed over " in res.stderr, res.stderr
    fwd = live_csv.read_text().splitlines()
    smo = out.read_text().splitlines()
    assert smo[0] == fwd[0] and len(smo) == len(fwd)
    f, s = (np.array([[float(x) for x in ln.split(",")] for ln in rows[1:]]) for rows in (fwd, smo))
    np.testing.assert_array_equal(s[:, 0], f[:, 0])
    assert np.any(s[:, 1:4] != f[:, 1:4])
    np.testing.assert_allclose(s[-1], f[-1], rtol=1e-15, atol=0)
    counts: dict[tuple[str, bool], int] = {}
    for ch in RrdReader(str(rrd)).stream():
        counts[(ch.entity_path, ch.is_static)] = counts.get((ch.entity_path, ch.is_static), 0) + ch.num_rows
    for path in ("/plots/attitude/smoothed", "/plots/position/smoothed", "/filter/sigma_pos/smoothed"):
        assert counts.get((path, False)) == min(len(smo) - 1, 20000), (path, counts)
    assert counts.get(("/world/trajectory/smoothed", True)) == 1


def test_replay_smooth_needs_the_filter(live: tuple[Path, Path, str], tmp_path: Path) -> None:
    tlog, _, _ = live
    res = mavins("replay", str(tlog), "-o", str(tmp_path / "x.csv"), "--smooth", "--aiding", "none", *NAV_OPTIONS,
                 cwd=tmp_path)
    assert res.returncode == 2
    assert res.stderr.strip() == "mavins replay: error: --smooth smooths the aided solution: it cannot go with --aiding none"
    assert not (tmp_path / "x.csv").exists()
