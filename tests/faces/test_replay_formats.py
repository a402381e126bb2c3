"""`mavins replay` on an ArduPilot DataFlash .bin, and options from a --config TOML file."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np

from sim.generate import generate
from sim.scenarios import load

IMU_FMT = "QBffffffIIfBBHH"
IMU_COLS = "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"


def _record(msg_type: int, fmt: str, *values: object) -> bytes:
    return b"\xa3\x95" + bytes([msg_type]) + struct.pack("<" + fmt, *values)


def _fmt(msg_type: int, name: str, fmt: str, cols: str) -> bytes:
    size = 3 + struct.calcsize("<" + fmt.replace("N", "16s").replace("Z", "64s").replace("n", "4s"))
    return _record(128, "BB4s16s64s", msg_type, size, name.encode(), fmt.encode(), cols.encode())


def write_dataflash(path: Path, t: np.ndarray, gyro: list[np.ndarray], accel: list[np.ndarray]) -> None:
    """A minimal ArduPilot log: the FMT of FMT and of IMU, then IMU rows for each instance."""
    buf = bytearray(_fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"))
    buf += _fmt(130, "IMU", IMU_FMT, IMU_COLS)
    for i, ti in enumerate(t):
        for inst, (g, a) in enumerate(zip(gyro, accel)):
            buf += _record(130, IMU_FMT, int(round(ti * 1e6)), inst, *g[i], *a[i], 0, 0, 40.0, 1, 1, 400, 400)
    path.write_bytes(bytes(buf))


def assert_crossings(t: np.ndarray, rate: float, t_end: float) -> None:
    """Output sets: the first update after alignment, then one each time sensor time crosses
    a multiple of 1/rate (docs/conventions.md --rate), up to the end of the log."""
    k = np.floor(t * rate + 1e-9)
    assert np.all(np.diff(k) == 1), np.diff(k)
    assert t_end - t[-1] < 1.0 / rate


def _mavins(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mavins.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


def test_replay_ardupilot_bin_selects_the_instance(tmp_path: Path) -> None:
    run = generate(load("static"), duration=20.0, rate=200.0, grade="ideal")
    dt = np.diff(np.concatenate(([run.exact.t0], run.t)))[:, None]
    w, f = run.dtheta / dt, run.dv / dt
    # instance 1 is the good one; instance 0 reads a constant 0.05 rad/s z rate (below the
    # alignment's motion threshold, so it aligns and then turns)
    bad_w = w + np.array([0.0, 0.0, 0.05])
    t = run.t + 100.0  # a boot time that does not start at zero
    path = tmp_path / "flight.bin"
    write_dataflash(path, t, [bad_w, w], [f, f])
    init = run.init()
    common = ["--lat", init.lat, "--lon", init.lon, "--alt", init.h, "--heading", init.yaw, "--align", 2,
              "--gyro-bias", "none"]
    good = _mavins("replay", path, "-o", tmp_path / "good.csv", "--imu-id", 1, *common)
    assert good.returncode == 0, good.stderr
    sol = np.loadtxt(tmp_path / "good.csv", delimiter=",", skiprows=1)
    # static, ideal sensors (float32 in the log): attitude stays at the truth to float32 resolution
    assert np.max(np.abs(sol[:, 9] - init.yaw)) < 1e-3 and np.max(np.abs(sol[:, 7:9])) < 1e-3
    assert_crossings(sol[:, 0], 50.0, t_end=t[-1])
    bad = _mavins("replay", path, "-o", tmp_path / "bad.csv", "--imu-id", 0, *common)
    assert bad.returncode == 0, bad.stderr
    bad_sol = np.loadtxt(tmp_path / "bad.csv", delimiter=",", skiprows=1)
    t0, yaw0 = bad_sol[:, 0], bad_sol[:, 9]
    # instance 0 turns at 0.05 rad/s: its solution does, so the instance choice took effect
    assert abs(np.degrees(0.05 * (t0[50] - t0[0])) - ((yaw0[50] - yaw0[0]) % 360)) < 0.01


def test_config_file_options_and_command_line_wins(tmp_path: Path) -> None:
    run = generate(load("static"), duration=10.0, rate=100.0, grade="ideal")
    dt = np.diff(np.concatenate(([run.exact.t0], run.t)))[:, None]
    path = tmp_path / "log.bin"
    write_dataflash(path, run.t, [run.dtheta / dt], [run.dv / dt])
    init = run.init()
    cfg = tmp_path / "nav.toml"
    cfg.write_text(f"lat = {init.lat}\nlon = {init.lon}\nalt = {init.h}\nheading = \"{init.yaw}\"\n"
                   "align = 2.0\nrate = 10.0\ngyro-bias = \"none\"\n")
    res = _mavins("replay", path, "-o", tmp_path / "a.csv", "--config", cfg)
    assert res.returncode == 0, res.stderr
    assert_crossings(np.loadtxt(tmp_path / "a.csv", delimiter=",", skiprows=1)[:, 0], 10.0, t_end=run.t[-1])
    res = _mavins("replay", path, "-o", tmp_path / "b.csv", "--config", cfg, "--rate", 25)
    assert res.returncode == 0, res.stderr
    # the command line wins over the file's rate
    assert_crossings(np.loadtxt(tmp_path / "b.csv", delimiter=",", skiprows=1)[:, 0], 25.0, t_end=run.t[-1])
    # a typed value equal to the default still wins over the file (50 is --rate's default)
    res = _mavins("replay", path, "-o", tmp_path / "d.csv", "--config", cfg, "--rate=50")
    assert res.returncode == 0, res.stderr
    assert_crossings(np.loadtxt(tmp_path / "d.csv", delimiter=",", skiprows=1)[:, 0], 50.0, t_end=run.t[-1])
    cfg.write_text("speed_of_light = 3\n")
    res = _mavins("replay", path, "-o", tmp_path / "c.csv", "--config", cfg)
    assert res.returncode == 2 and "unknown option 'speed_of_light'" in res.stderr
