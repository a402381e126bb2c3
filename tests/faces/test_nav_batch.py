"""`mavins nav --each`: many files, each navigated on its own on a process pool.

The expected solution of each file is `mavins nav` run on that file alone; a bad
file is reported in one line and leaves nothing, while the others are written.
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from mavins.common import files
from support import ENV, MAVINS

INIT = {"t": 0.0, "lat": 45.0, "lon": 7.0, "h": 100.0, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 0.0, "pitch": 0.0,
        "yaw": 30.0}


def _mavins(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MAVINS, *map(str, args)], cwd=cwd, env=ENV, capture_output=True, text=True, timeout=300,
                          check=False)


def _run_dir(d: Path, seed: int, yaw: float) -> None:
    """A folder as `mavins sim` leaves it: imu.csv and init.json."""
    rng = np.random.default_rng(seed)
    n = 300
    t = 0.005 * np.arange(1, n + 1)
    dtheta = rng.normal(0.0, 1e-4, (n, 3))
    dv = rng.normal(0.0, 1e-3, (n, 3)) + [0.0, 0.0, -9.80665 * 0.005]
    d.mkdir(parents=True)
    files.write_table(d / "imu.csv", files.INCREMENT_COLUMNS, np.column_stack([t, dtheta, dv]))
    (d / "init.json").write_text(json.dumps({**INIT, "yaw": yaw}))


@pytest.fixture(scope="module")
def farm(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("farm")
    for i in range(3):
        _run_dir(root / "runs" / f"r{i}", seed=i, yaw=10.0 * i)
    bad = root / "runs" / "bad"
    bad.mkdir()
    (bad / "imu.csv").write_text("t,x\n0.1,2\n")
    (bad / "init.json").write_text(json.dumps(INIT))
    return root


def _alone(root: Path, name: str) -> np.ndarray:
    out = root / f"alone_{name}.csv"
    proc = _mavins("nav", f"runs/{name}/imu.csv", "--init", f"runs/{name}/init.json", "-o", out, cwd=root)
    assert proc.returncode == 0, proc.stderr
    return files.read_table(out, files.SOLUTION_COLUMNS)


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_each_file_as_if_alone_and_a_bad_file_reported(farm: Path, jobs: str) -> None:
    out = farm / f"out{jobs}"
    proc = _mavins("nav", "--each", "runs/r0/imu.csv", "runs/r1/imu.csv", "runs/bad/imu.csv", "runs/r2/imu.csv",
                   "-o", out, "--jobs", jobs, cwd=farm)
    assert proc.returncode == 2, proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if "error" in ln]
    assert len(errors) == 1 and "runs/bad/imu.csv: line 1: missing column(s)" in errors[0], proc.stderr
    assert "3 of 4 files navigated" in proc.stderr
    assert not (out / "bad").exists()  # nothing left for the bad file
    for i in range(3):
        got = files.read_table(out / f"r{i}" / "imu.nav.csv", files.SOLUTION_COLUMNS)
        want = _alone(farm, f"r{i}")
        assert got.view(np.int64).tolist() == want.view(np.int64).tolist()  # each from its own init.json
    assert sorted(p.name for p in out.iterdir()) == ["r0", "r1", "r2", "summary.csv"]
    summary = (out / "summary.csv").read_text().splitlines()
    assert [ln.split(",", 1)[0] for ln in summary[1:]] == ["runs/r0/imu.csv", "runs/r1/imu.csv", "runs/bad/imu.csv",
                                                           "runs/r2/imu.csv"]
    assert "missing column(s)" in summary[3] and summary[3].split(",")[1] == ""  # the bad file: error, no output


def test_each_on_a_dask_cluster_writes_what_local_processes_write(farm: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--each --cluster ADDRESS`` on a real distributed.LocalCluster (two worker processes): the same solution
    files, byte for byte, and the same summary as ``--jobs 2``, but for the output folder."""
    distributed = pytest.importorskip("distributed")
    from mavins.cli import main

    monkeypatch.chdir(farm)
    args = ["nav", "--each", "runs/r0/imu.csv", "runs/bad/imu.csv", "runs/r2/imu.csv"]
    assert main([*args, "-o", "local_c", "--jobs", "2"]) == 2
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc:
        assert main([*args, "-o", "remote_c", "--cluster", lc.scheduler_address]) == 2
    for name in ("r0/imu.nav.csv", "r2/imu.nav.csv"):
        assert (farm / "local_c" / name).read_bytes() == (farm / "remote_c" / name).read_bytes()
    local = (farm / "local_c" / "summary.csv").read_text().replace("local_c", "OUT")
    assert local == (farm / "remote_c" / "summary.csv").read_text().replace("remote_c", "OUT")


def test_one_init_for_all_and_parquet_outputs(farm: Path) -> None:
    files.write_table(farm / "runs" / "r1" / "imu.parquet", files.INCREMENT_COLUMNS,
                      files.read_table(farm / "runs" / "r1" / "imu.csv", files.INCREMENT_COLUMNS))
    proc = _mavins("nav", "--each", "runs/r1/imu.parquet", "runs/r2/imu.csv", "--init", "runs/r1/init.json",
                   "-o", "one", cwd=farm)
    assert proc.returncode == 0, proc.stderr
    a = files.read_table(farm / "one" / "r1" / "imu.nav.parquet", files.SOLUTION_COLUMNS)
    assert a.view(np.int64).tolist() == _alone(farm, "r1").view(np.int64).tolist()
    b = files.read_table(farm / "one" / "r2" / "imu.nav.csv", files.SOLUTION_COLUMNS)
    assert b[0, 9] != _alone(farm, "r2")[0, 9]  # r2 started from r1's heading, not its own


@pytest.mark.parametrize("argv, says", [
    (["runs/r0/imu.csv", "--init", "runs/r0/init.json", "-o", "x.csv", "--jobs", "2"], "--jobs goes with --each"),
    (["runs/r0/imu.csv", "-o", "x.csv"], "--init INIT.json is required"),
    (["--each", "runs/r0/imu.csv", "runs/r0/imu.csv", "-o", "dup"], "would write the same solution"),
    (["--each", "runs/r0/imu.csv", "-o", "g", "--gnss", "g.csv"], "cannot go with it"),
])
def test_batch_usage_errors_are_one_line(farm: Path, argv: list[str], says: str) -> None:
    proc = _mavins("nav", *argv, cwd=farm)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], proc.stderr
    assert not (farm / "x.csv").exists() and not (farm / "dup").exists() and not (farm / "g").exists()
