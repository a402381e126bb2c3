"""The command line against closed forms: ``mavins nav`` position rules and ``--l-every``,
``mavins key``, ``mavins demo``, ``mavins review`` without a viewer, and the progress bar.

Every ``mavins`` here is a real subprocess (the installed console script); the IMU
files are written by the test from closed-form motions with 17 significant
digits (the contract's file precision), so the expected numbers are exact up to
double round-off.
"""

from __future__ import annotations

import json
import math
import os
import pty
import re
import select
import stat
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from support import ENV, GAMMA_E, MAVINS, OMEGA, gamma, mavins

def write_increments(path: Path, t: np.ndarray, dth: np.ndarray, dv: np.ndarray) -> None:
    rows = np.column_stack([t, dth, dv])
    with open(path, "w") as fh:
        fh.write("t,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z\n")
        for r in rows:
            fh.write(",".join(repr(float(x)) for x in r) + "\n")


def write_init(path: Path, **state: float) -> None:
    base = dict(t=0.0, lat=0.0, lon=0.0, h=0.0, vn=0.0, ve=0.0, vd=0.0, roll=0.0, pitch=0.0, yaw=0.0)
    base.update(state)
    path.write_text(json.dumps(base))


def nav(tmp: Path, imu: Path, init: Path, name: str, *opts: str) -> np.ndarray:
    out = tmp / f"{name}.csv"
    res = mavins("nav", str(imu), "--init", str(init), "-o", str(out), *opts, cwd=tmp)
    assert res.returncode == 0, res.stderr
    return np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)


# --- --position: rectangular, trapezoidal, simpson ------------------------------------
DT, N_SAMPLES, JERK, DURATION = 0.01, 2, 1.0, 10.0


@pytest.fixture(scope="module")
def jerk_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    """Constant jerk downwards from rest, laboratory frame: a = J t, v = J t^2/2, x = J t^3/6.

    f = a - g along down with g = gamma_e (latitude 0, height 0: the laboratory mode's constant
    gravity, TR8350.2's published value), so dv_z = J (t_k^2 - t_{k-1}^2)/2 - gamma_e dt exactly.
    """
    tmp = tmp_path_factory.mktemp("jerk")
    n = int(round(DURATION / DT))
    t = np.arange(1, n + 1) * DT
    tp = t - DT
    dv = np.zeros((n, 3))
    dv[:, 2] = JERK * (t * t - tp * tp) / 2 - GAMMA_E * DT
    write_increments(tmp / "imu.csv", t, np.zeros((n, 3)), dv)
    write_init(tmp / "init.json")
    return {rule: nav(tmp, tmp / "imu.csv", tmp / "init.json", rule, "--earth", "none", "--position", rule)
            for rule in ("rectangular", "trapezoidal", "simpson")}


def rule_closed_form(rule: str, m: int) -> float:
    """Down distance after m updates of T = N dt with v_k = J (kT)^2/2 exact at the updates.

    rectangular (v(k-1) T): J T^3/2 sum_{i<m} i^2 = J T^3 (m-1) m (2m-1)/12, error ~ -J t^2 T/4;
    trapezoidal: J T^3/4 sum (i^2 + (i+1)^2) = exact + m J T^3/12 (its -T^3/12 v'' per interval);
    simpson (-v(k-2) + 8 v(k-1) + 5 v(k))/12 T: exact for the parabola on every update but the
    first, where v(k-2) is the initial velocity 0 (= v(-T) of a resting start) and gives
    5/12 J T^2/2 T = 5 J T^3/24 for J T^3/6: exact + J T^3/24.
    """
    T = Fraction(N_SAMPLES) * Fraction(DT).limit_denominator(10**6)
    j = Fraction(JERK)
    sq = lambda k: Fraction(k * (k + 1) * (2 * k + 1), 6)  # noqa: E731  sum_{i<=k} i^2
    if rule == "rectangular":
        x = j * T**3 / 2 * sq(m - 1)
    elif rule == "trapezoidal":
        x = j * T**3 / 4 * (sq(m - 1) + sq(m))
    else:
        x = j * (m * T) ** 3 / 6 + j * T**3 / 24
    return float(x)


@pytest.mark.parametrize("rule", ["rectangular", "trapezoidal", "simpson"])
def test_position_rule_matches_its_closed_form(jerk_runs: dict[str, np.ndarray], rule: str) -> None:
    """Height = -(the rule's own sum) at every update. Round-off: h ~ 170 m accumulated over 500
    updates at 1e-16 relative each is ~1e-11 m; tolerance 1e-9 m. The rules differ from each other
    by 0.5 m (rectangular) and m J T^3/12 - J T^3/24 = 3.3e-4 m (trapezoid vs Simpson at the end),
    and Simpson from the exact J t^3/6 by J T^3/24 = 3.3e-7 m = 330 x the tolerance, so any rule
    swapped, reweighted or started differently fails."""
    sol = jerk_runs[rule]
    m = np.arange(1, len(sol) + 1)
    assert len(sol) == int(round(DURATION / DT)) // N_SAMPLES
    assert sol[:, 0] == pytest.approx(m * N_SAMPLES * DT, abs=1e-12)
    # velocity is exact at the updates whatever the rule
    np.testing.assert_allclose(sol[:, 6], JERK * (m * N_SAMPLES * DT) ** 2 / 2, rtol=0, atol=1e-11)
    expected = np.array([rule_closed_form(rule, int(k)) for k in m])
    np.testing.assert_allclose(-sol[:, 3], expected, rtol=0, atol=1e-9)


def test_position_rules_differ_on_accelerating_motion(jerk_runs: dict[str, np.ndarray]) -> None:
    """The three rules give three different heights (closed-form gaps, far above round-off)."""
    h = {k: v[-1, 3] for k, v in jerk_runs.items()}
    exact = -JERK * DURATION**3 / 6
    assert abs(h["rectangular"] - exact) > 0.4
    assert h["trapezoidal"] - h["simpson"] == pytest.approx(
        -(rule_closed_form("trapezoidal", 500) - rule_closed_form("simpson", 500)), abs=2e-9)
    assert abs(h["simpson"] - exact) == pytest.approx(JERK * (N_SAMPLES * DT) ** 3 / 24, abs=2e-9)


# --- --l-every ------------------------------------------------------------------------------
LAT_L = math.radians(45.0)
V_UP = 100.0
L_DURATION = 60.0


def climb_files(tmp: Path, v_up: float) -> tuple[Path, Path]:
    """Level, yaw 0, constant vertical speed v_up at latitude 45 deg on the rotating Earth.

    Truth (independent of mavins): v = [0, 0, -v_up], h = v_up t. Sensors from the NED
    navigation equation: w_ib^b = w_ie^n = [Omega cos L, 0, -Omega sin L] (no transport rate
    without horizontal speed) and f = dv/dt + 2 w_ie x v - g = [0, 2 Omega cos L v_up, -gamma(h(t))];
    dv_z by Simpson over each interval is exact (gamma is quadratic in h, h linear in t).
    """
    n = int(round(L_DURATION / DT))
    t = np.arange(1, n + 1) * DT
    ta = t - DT
    dth = np.tile([OMEGA * math.cos(LAT_L) * DT, 0.0, -OMEGA * math.sin(LAT_L) * DT], (n, 1))
    dv = np.zeros((n, 3))
    dv[:, 1] = 2 * OMEGA * math.cos(LAT_L) * v_up * DT
    dv[:, 2] = -DT / 6 * (gamma(LAT_L, v_up * ta) + 4 * gamma(LAT_L, v_up * (ta + DT / 2)) + gamma(LAT_L, v_up * t))
    imu, init = tmp / f"climb{v_up:g}.csv", tmp / f"climb{v_up:g}.json"
    write_increments(imu, t, dth, dv)
    write_init(init, lat=45.0, vd=-v_up)
    return imu, init


@pytest.fixture(scope="module")
def climb_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    tmp = tmp_path_factory.mktemp("climb")
    imu, init = climb_files(tmp, V_UP)
    rest_imu, rest_init = climb_files(tmp, 0.0)
    return {"1": nav(tmp, imu, init, "l1", "--l-every", "1"),
            "10": nav(tmp, imu, init, "l10", "--l-every", "10"),
            "rest1": nav(tmp, rest_imu, rest_init, "r1", "--l-every", "1"),
            "rest7": nav(tmp, rest_imu, rest_init, "r7", "--l-every", "7")}


def test_l_every_one_follows_the_truth(climb_runs: dict[str, np.ndarray]) -> None:
    """With the slow terms refreshed every update the climb is followed: the mid-interval
    extrapolation is exact for constant velocity, so what is left is gravity at the extrapolated
    midpoint versus its interval mean (gamma'' h-dot^2 T^2/24 ~ 1e-17 m/s^2) and round-off: 3000
    updates of one ulp of 100 m/s (1.4e-14) or of 6 km (9e-13 m) are 4e-11 m/s and 3e-9 m, times the
    vertical channel's growth exp(t sqrt(2g/R)) ~ 1.1 over 60 s. Tolerances 1e-8 m/s and 1e-7 m.
    (Gravity taken at the start of each interval instead of its middle would be off by
    gamma' v_up T/2 = 3e-6 m/s^2: 1.8e-4 m/s after 60 s.)"""
    s = climb_runs["1"]
    t = s[:, 0]
    np.testing.assert_allclose(s[:, 6], -V_UP, rtol=0, atol=1e-8)
    np.testing.assert_allclose(s[:, 3], V_UP * t, rtol=0, atol=1e-7)
    np.testing.assert_allclose(s[:, 4:6], 0.0, rtol=0, atol=1e-8)


def test_l_every_holds_gravity_for_m_updates(climb_runs: dict[str, np.ndarray]) -> None:
    """Held for M updates, gravity is on average (M - 1)/2 updates stale. Climbing, gravity falls at
    gamma' v_up (gamma' = d gamma/dh from the typed height series, -3.08e-6 s^-2), so the held value
    is larger by -gamma' v_up T (M-1)/2 on average and the down velocity of the M run exceeds the M = 1
    run by dv = -gamma' v_up T (M - 1)/2 t (1.66e-3 m/s after 60 s; 100 x a 1 % change of it is the
    tolerance's scale). What this neglects: the gravity change the height difference itself makes,
    relative |gamma'| t^2/6 = 1.9e-3, so the tolerance is |gamma'| t^2/3 relative."""
    s1, s10 = climb_runs["1"], climb_runs["10"]
    assert len(s1) == len(s10)
    g_prime = (gamma(LAT_L, 1.0) - gamma(LAT_L, -1.0)) / 2.0
    T = N_SAMPLES * DT
    t = s1[:, 0]
    whole = (np.arange(1, len(t) + 1) % 10) == 0  # at the end of whole blocks of 10 updates
    predicted = -g_prime * V_UP * T * (10 - 1) / 2 * t[whole]
    dv = s10[whole, 6] - s1[whole, 6]
    assert predicted[-1] > 1e-3
    np.testing.assert_allclose(dv, predicted, rtol=abs(g_prime) * L_DURATION**2 / 3, atol=1e-9)


def test_l_every_changes_nothing_when_nothing_changes(climb_runs: dict[str, np.ndarray]) -> None:
    """At rest the slow terms are the same at every update, so holding them for 7 updates must give
    the result of refreshing them every update, to round-off: heights within 1e-9 m, velocities
    within 1e-12 m/s, attitude quaternions within 1e-13. (A hold that skipped the first update
    would leave gravity and Earth rate zero for it: 0.2 m/s and 3e-6 deg.)"""
    r1, r7 = climb_runs["rest1"], climb_runs["rest7"]
    np.testing.assert_allclose(r7[:, 3:7], r1[:, 3:7], rtol=0, atol=1e-9)
    np.testing.assert_allclose(r7[:, 4:7], r1[:, 4:7], rtol=0, atol=1e-12)
    np.testing.assert_allclose(r7[:, 10:14], r1[:, 10:14], rtol=0, atol=1e-13)
    # ... and rest is rest: the truth, not another run
    np.testing.assert_allclose(r1[:, 4:7], 0.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r1[:, 3], 0.0, rtol=0, atol=1e-7)


# --- mavins key -------------------------------------------------------------------------------
def test_key_without_passphrase_is_random_32_bytes_mode_600(tmp_path: Path) -> None:
    """64 hex digits (+ newline) = 32 bytes, mode 600, a new key each time, an existing file kept."""
    keys = []
    for name in ("a.key", "b.key"):
        path = tmp_path / name
        res = mavins("key", str(path), cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
        text = path.read_text()
        assert re.fullmatch(r"[0-9a-f]{64}\n", text), repr(text)
        keys.append(bytes.fromhex(text.strip()))
    assert len(keys[0]) == 32 and keys[0] != keys[1]
    before = (tmp_path / "a.key").read_text()
    res = mavins("key", str(tmp_path / "a.key"), cwd=tmp_path)
    assert res.returncode == 2 and "exists" in res.stderr
    assert (tmp_path / "a.key").read_text() == before


# --- mavins demo, then mavins review of its recording without a viewer -------------------------
@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess, Path]:
    tmp = tmp_path_factory.mktemp("demo")
    rrd = tmp / "demo.rrd"
    res = mavins("demo", "--duration", "12", "--speed", "6", "--rerun", str(rrd), cwd=tmp)
    return res, rrd


NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|nan|inf)")


def test_demo_at_max_speed_loses_nothing(tmp_path: Path) -> None:
    """--speed max streams as fast as the service takes the messages (demo.KeepUp): over loopback UDP,
    whose socket holds a few hundred datagrams, the service takes every message streamed, with no sensor-time
    gap and no alignment restart (before, the dropped datagrams restarted the alignment into the take-off)."""
    res = mavins("demo", "--duration", "60", "--speed", "max", "--no-rerun", "--no-outage", cwd=tmp_path)
    assert res.returncode == 0, res.stdout + res.stderr
    m = re.search(r"messages streamed / taken by the service: (\d+) / (\d+)", res.stdout)
    assert m is not None, res.stdout
    assert int(m.group(1)) == int(m.group(2)) > 15000  # without the hold, one run here: 19565 streamed, 11088 taken
    log = res.stdout + res.stderr
    assert "gap of" not in log and "restarting it" not in log, log




def test_demo_prints_its_report(demo: tuple[subprocess.CompletedProcess, Path]) -> None:
    """Exit 0 and the report (demo.py DemoReport.lines): the output sets received, and the
    attitude, position and velocity errors against the simulator's truth, each line with finite,
    non-negative numbers. 12 s of the flight scenario aligned over 5 s (a rest, then the take-off):
    output sets were received, and the errors are small (generously: attitude below 1 deg,
    position below 10 m, velocity below 1 m/s; a max is at least the final value)."""
    res, rrd = demo
    assert res.returncode == 0, res.stdout + res.stderr
    report = {}
    for line in res.stdout.splitlines():
        if line.startswith("mavins demo: ") and ": " in line[len("mavins demo: "):] \
                and not line.startswith("mavins demo: recording written"):
            label, value = line[len("mavins demo: "):].split(": ", 1)
            report[label] = value
    out = res.stdout

    def numbers(prefix: str) -> dict[str, float]:
        keys = [k for k in report if prefix in k]
        assert len(keys) == 1, (prefix, out)
        text = report[keys[0]]
        vals = {m.group(1): float(m.group(2)) for m in re.finditer(r"(\w+) (" + NUMBER.pattern + r")", text)}
        vals["first"] = float(NUMBER.search(text).group(0))  # type: ignore[union-attr]
        for v in vals.values():
            assert math.isfinite(v) and v >= 0.0, (prefix, text)
        return vals

    assert numbers("published output sets received")["first"] > 0
    att = numbers("attitude error vs truth")
    pos = numbers("position error vs truth")
    vel = numbers("velocity error vs truth")
    for vals in (att, pos):
        if "max" in vals and "final" in vals:
            assert vals["final"] <= vals["max"], (vals, out)
    assert max(att.values()) < 1.0 and max(pos.values()) < 10.0 and vel["first"] < 1.0, out
    for text in report.values():  # every report line carries numbers, all finite
        nums = NUMBER.findall(text)
        assert nums and all(math.isfinite(float(x)) for x in nums), (text, out)
    assert f"recording written to {rrd}" in out and rrd.is_file() and rrd.read_bytes()[:3] == b"RRF"


def test_review_without_a_viewer_fails_in_one_line(demo: tuple[subprocess.CompletedProcess, Path],
                                                   tmp_path: Path) -> None:
    """With an empty PATH and no other environment (but the numba cache's home), Xvfb cannot be
    found: review.run documents "1 on viewer failure" (2 is for bad usage: a missing or
    unreadable recording). One line on stderr naming the package to install, no PNG, no traceback."""
    _, rrd = demo
    assert rrd.is_file()
    empty = tmp_path / "empty-path"
    empty.mkdir()
    env = {"PATH": str(empty)}
    for keep in ("HOME", "XDG_CACHE_HOME", "NUMBA_CACHE_DIR"):
        if keep in os.environ:
            env[keep] = os.environ[keep]
    out_png = tmp_path / "shot.png"
    res = subprocess.run([*MAVINS, "review", str(rrd), "--screenshot", str(out_png)], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=300)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 1, res.stderr
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("mavins review: error: ") and "xvfb" in lines[0].lower(), lines
    assert "Traceback" not in res.stderr and not out_png.exists()
    # bad usage is the other code: no such recording -> 2
    res = subprocess.run([*MAVINS, "review", str(tmp_path / "none.rrd"), "--screenshot", str(out_png)],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 2 and len([ln for ln in res.stderr.splitlines() if ln.strip()]) == 1, res.stderr


# --- mavins/common/progress.py --------------------------------------------------------------------------
PROGRESS_SCRIPT = """
from mavins.common.progress import Progress
with Progress("crunch", 10) as p:
    for i in range(11):
        p.update(i)
print("body done")
"""


def test_progress_is_silent_on_a_pipe() -> None:
    """stderr is a pipe (not a terminal): nothing at all is written to it; stdout is untouched."""
    res = subprocess.run([sys.executable, "-c", PROGRESS_SCRIPT], env=ENV, capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stderr == ""
    assert res.stdout == "body done\n"


def test_progress_draws_a_bar_on_a_terminal() -> None:
    """On a terminal: carriage-return redraws ``label [bar] pct% eta`` with a 30-character bar; the
    first update (0 %) and the last (done == total, always drawn) appear, the last with 30 '#', and
    the exit line ``label done in S s`` ends with a newline."""
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-c", PROGRESS_SCRIPT], env=ENV, stdout=subprocess.DEVNULL,
                            stderr=slave, stdin=subprocess.DEVNULL)
    os.close(slave)
    data = b""
    while True:
        r, _, _ = select.select([master], [], [], 120)
        if not r:
            break
        try:
            chunk = os.read(master, 4096)
        except OSError:  # EIO: the child closed the terminal
            break
        if not chunk:
            break
        data += chunk
    os.close(master)
    assert proc.wait(60) == 0
    text = data.decode().replace("\r\n", "\n")  # the terminal's own output processing (onlcr)
    frames = [f for f in text.split("\r") if f]
    assert re.fullmatch(r"crunch \[ {30}\]   0\.0% eta   0\.0 s", frames[0]), frames
    assert any(re.fullmatch(r"crunch \[#{30}\] 100\.0% eta   0\.0 s", f) for f in frames), frames
    assert re.fullmatch(r"crunch done in \d+\.\d s {40}\n", frames[-1]), frames
    for f in frames[:-1]:
        m = re.fullmatch(r"crunch \[(#*) *\] +(\d+\.\d)% eta +\d+\.\d s", f)
        assert m, f
        assert len(m.group(1)) == int(30 * float(m.group(2)) / 100 + 1e-9)
