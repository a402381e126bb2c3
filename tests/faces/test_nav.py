"""What the mutation runs found unchecked in mavins/nav.py, the offline ``mavins nav`` (docs/testing.md).

Every input is a real file in tmp_path, written by hand with a few tens of samples: IMU increments
or rates in the contract's columns, the initial-state JSON, GNSS and baro files (docs/conventions.md
"Files", "Command line", "Aided navigation"). Expected values are closed forms: in laboratory mode
(``--earth none``) a level IMU at rest measures f = [0, 0, -gamma_h] at the start point and nothing
else, so the velocity stays zero and the position constant; a constant yaw rate w turns the heading
by exactly w * (t - t0). Errors are the one-line messages of docs/reliability.md "Offline tools on
bad input"; line numbers are counted by hand (the header is line 1).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import time
from pathlib import Path

import numpy as np
import pytest

from mavins import cli, nav
from mavins.common.fleet import SUMMARY_COLUMNS
from mavins.core.settings import Strapdown
from mavins.common.files import DataFileError
from support import gamma


SOLUTION = ["t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw", "qw", "qx", "qy", "qz"]
FILTER = ["sigma_n", "sigma_e", "sigma_d", "sigma_vn", "sigma_ve", "sigma_vd", "sigma_att_n", "sigma_att_e",
          "sigma_att_d", "bg_x", "bg_y", "bg_z", "ba_x", "ba_y", "ba_z", "sigma_bg_x", "sigma_bg_y", "sigma_bg_z",
          "sigma_ba_x", "sigma_ba_y", "sigma_ba_z"]
INC_HEADER = "t,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z"
RATE_HEADER = "t,gyro_x,gyro_y,gyro_z,acc_x,acc_y,acc_z"
T0, DT = 1.0, 0.01
LAT, LON, H, YAW = 45.0, 7.0, 100.0, 30.0
G = float(gamma(math.radians(LAT), H))
INIT = {"t": T0, "lat": LAT, "lon": LON, "h": H, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 0.0, "pitch": 0.0,
        "yaw": YAW}


def run(*argv: object) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli.main([str(a) for a in argv])
    return code, err.getvalue()


def write_init(tmp_path: Path, name: str = "init.json", **extra: object) -> Path:
    p = tmp_path / name
    p.write_text(json.dumps({**INIT, **extra}), encoding="utf-8")
    return p


def write_imu(tmp_path: Path, n: int, wz: float = 0.0, rates: bool = False, name: str | None = None,
              before: list[str] | None = None, t_first: float | None = None) -> Path:
    """n samples at 100 Hz after T0 of a level IMU at rest turning at wz rad/s about z: increments
    (dtheta_z = wz dt, dv_z = -gamma dt) or averaged rates; ``before`` are raw data lines put first."""
    p = tmp_path / (name or ("rates.csv" if rates else "imu.csv"))
    ts = [T0 + DT * (i + 1) for i in range(n)]
    if t_first is not None:
        ts[0] = t_first
    lines = list(before or [])
    prev = T0
    for t in ts:
        d = 1.0 if rates else t - prev
        lines.append(f"{t!r},0,0,{wz * d!r},0,0,{-G * d!r}")
        prev = t
    p.write_text((RATE_HEADER if rates else INC_HEADER) + "\n" + "".join(ln + "\n" for ln in lines),
                 encoding="utf-8")
    return p


def table(path: Path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text(encoding="utf-8").splitlines()
    return lines[0].split(","), np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]]).reshape(-1, len(
        lines[0].split(",")))


def opts(**kw: object) -> nav.NavOptions:
    inp = kw.pop("input", "increments")
    timing = kw.pop("timing", False)
    return nav.NavOptions(input=inp, strapdown=Strapdown(**kw), timing=timing)  # type: ignore[arg-type]


def assert_at_rest(sol: np.ndarray, yaw0: float = YAW, wz: float = 0.0) -> None:
    """Laboratory mode at rest: zero velocity, the start position, level, yaw = yaw0 + w (t - t0)."""
    assert np.all(np.abs(sol[:, 4:7]) < 1e-9)
    assert np.all(np.abs(sol[:, 1] - LAT) < 1e-12) and np.all(np.abs(sol[:, 2] - LON) < 1e-12)
    assert np.all(np.abs(sol[:, 3] - H) < 1e-9)
    assert np.all(np.abs(sol[:, 7:9]) < 1e-9)
    expect = yaw0 + np.degrees(wz * (sol[:, 0] - T0))
    assert np.all(np.abs(sol[:, 9] - expect) < 1e-9)


# ---- free inertial: run_nav -------------------------------------------------------------------------------------

@pytest.mark.parametrize("n,samples,rows", [(20, 2, 10), (21, 2, 10), (21, 3, 7), (23, 6, 3), (6, 6, 1), (5, 6, 0)])
def test_rows_one_per_update_at_the_last_sample_time(tmp_path: Path, n: int, samples: int, rows: int) -> None:
    """n samples with N per update give n // N rows (trailing samples unused), row k at the time of sample
    (k + 1) N; laboratory mode at rest keeps zero velocity and the start position."""
    imu, init, out = write_imu(tmp_path, n), write_init(tmp_path), tmp_path / "nav.csv"
    assert nav.run_nav(imu, init, out, opts(samples=samples, earth_model="none")) == rows
    header, sol = table(out)
    assert header == SOLUTION
    assert sol.shape[0] == rows
    np.testing.assert_allclose(sol[:, 0], T0 + DT * samples * np.arange(1, rows + 1), rtol=0, atol=1e-12)
    assert_at_rest(sol)


@pytest.mark.parametrize("rates", [False, True])
def test_a_constant_yaw_rate_turns_the_heading_by_rate_times_time(tmp_path: Path, rates: bool) -> None:
    """0.5 rad/s about z for 0.2 s, from increments or averaged rates: yaw = 30 deg + w (t - t0) at every row,
    through the command line; ``wrote 10 solution rows`` on stderr."""
    imu, init, out = write_imu(tmp_path, 20, wz=0.5, rates=rates), write_init(tmp_path), tmp_path / "nav.csv"
    code, err = run("nav", imu, "--init", init, "-o", out, "--earth", "none",
                    *(["--input", "rates"] if rates else []))
    assert code == 0, err
    assert err.strip() == f"mavins nav: wrote 10 solution rows to {out}"
    _, sol = table(out)
    assert sol.shape[0] == 10
    assert_at_rest(sol, wz=0.5)


def test_rates_rows_at_and_before_the_initial_time_start_nothing(tmp_path: Path) -> None:
    """Averaged rates: rows before the initial state's t are ignored (here wild values), so the solution is that
    of the file without them."""
    before = ["0.5,9,9,9,9,9,9", "0.99,9,9,9,9,9,9"]
    imu = write_imu(tmp_path, 20, wz=0.5, rates=True, before=before)
    out = tmp_path / "nav.csv"
    assert nav.run_nav(imu, write_init(tmp_path), out, opts(input="rates", earth_model="none")) == 10
    _, sol = table(out)
    np.testing.assert_allclose(sol[:, 0], T0 + 2 * DT * np.arange(1, 11), rtol=0, atol=1e-12)
    assert_at_rest(sol, wz=0.5)


def test_the_first_increment_must_be_after_the_initial_time(tmp_path: Path) -> None:
    """Row i covers (t[i-1], t[i]] with t[-1] the initial t: a first row at exactly t0 is refused in one line
    naming line 2 and column t; the next double after t0 is taken."""
    init = write_init(tmp_path)
    bad = write_imu(tmp_path, 4, t_first=T0, name="bad.csv")
    out = tmp_path / "nav.csv"
    with pytest.raises(DataFileError) as err:
        nav.run_nav(bad, init, out, opts())
    assert str(err.value) == (f"{bad}: line 2, column 't': first increment time 1.0 is not after the initial "
                              "state's t = 1.0 (row i covers (t[i-1], t[i]])")
    assert not out.exists()
    good = write_imu(tmp_path, 4, t_first=math.nextafter(T0, 2.0), name="good.csv")
    assert nav.run_nav(good, init, out, opts()) == 2


def test_a_rate_file_may_start_at_the_initial_time(tmp_path: Path) -> None:
    """Rates are not increments: a first rate row at t0 is no error (sampled rates start the first interval
    there), and a constant rate at rest still gives the closed-form heading."""
    row0 = [f"{T0!r},0,0,0.5,0,0,{-G!r}"]
    imu = write_imu(tmp_path, 20, wz=0.5, rates=True, before=row0)
    out = tmp_path / "nav.csv"
    assert nav.run_nav(imu, write_init(tmp_path), out,
                       opts(input="rates", imu_rates="sampled", earth_model="none")) == 10
    _, sol = table(out)
    assert_at_rest(sol, wz=0.5)


@pytest.mark.parametrize("lat,frame,ok", [(89.6, "geographic", False), (89.4, "geographic", True),
                                          (89.6, "wander", True)])
def test_the_geographic_frame_stops_beyond_89_5_deg(tmp_path: Path, lat: float, frame: str, ok: bool) -> None:
    """Beyond |lat| 89.5 deg the geographic frame refuses in one line (when it got there, which frames can go on)
    and leaves no solution; just below it, or in the wander frame, the file is navigated."""
    imu = write_imu(tmp_path, 4)
    init = write_init(tmp_path, lat=lat)
    out = tmp_path / "nav.csv"
    if ok:
        assert nav.run_nav(imu, init, out, opts(frame=frame)) == 2
        assert out.exists()
        return
    with pytest.raises(DataFileError) as err:
        nav.run_nav(imu, init, out, opts(frame=frame))
    m = re.fullmatch(rf"{re.escape(str(imu))}: the geographic frame cannot navigate beyond \|lat\| 89\.5 deg "
                     r"\(reached at t = (\S+) s\); use --frame wander, free or inertial", str(err.value))
    assert m, str(err.value)
    assert T0 <= float(m.group(1)) <= T0 + 4 * DT
    assert not out.exists()


def test_timing_is_one_line_of_plausible_seconds(tmp_path: Path) -> None:
    """``--timing`` prints ``timing: samples=N read_s=.. compute_s=.. write_s=..`` to stderr: N the IMU rows read,
    each figure non-negative, three decimals, together at most the wall time of the call."""
    imu, init, out = write_imu(tmp_path, 21), write_init(tmp_path), tmp_path / "nav.csv"
    t0 = time.perf_counter()
    code, err = run("nav", imu, "--init", init, "-o", out, "--timing")
    wall = time.perf_counter() - t0
    assert code == 0, err
    lines = err.splitlines()
    assert len(lines) == 2
    m = re.fullmatch(r"timing: samples=(\d+) read_s=(\d+\.\d{3}) compute_s=(\d+\.\d{3}) write_s=(\d+\.\d{3})",
                     lines[0])
    assert m, lines[0]
    assert int(m.group(1)) == 21
    secs = [float(m.group(i)) for i in (2, 3, 4)]
    assert all(s >= 0.0 for s in secs)
    assert sum(secs) <= wall + 0.002
    code, err = run("nav", imu, "--init", init, "-o", out)
    assert code == 0 and not any(ln.startswith("timing") for ln in err.splitlines())


def test_the_rate_and_increment_files_are_told_apart_by_their_columns(tmp_path: Path) -> None:
    """``--input increments`` reads the increment columns, so a rate file is refused for its missing column."""
    imu = write_imu(tmp_path, 4, rates=True)
    with pytest.raises(DataFileError, match="dtheta_x"):
        nav.run_nav(imu, write_init(tmp_path), tmp_path / "nav.csv", opts())


# ---- GNSS and baro files: read_aiding ---------------------------------------------------------------------------

def text(tmp_path: Path, body: str, name: str = "gnss.csv") -> Path:
    p = tmp_path / name
    p.write_text(body, encoding="utf-8")
    return p


def gnss(p: Path, no_fix: bool = True) -> np.ndarray:
    return nav.read_aiding(p, nav.GNSS_REQUIRED, nav.GNSS_OPTIONAL, no_fix_rows=no_fix)


def baro(p: Path) -> np.ndarray:
    return nav.read_aiding(p, nav.BARO_REQUIRED, nav.BARO_OPTIONAL)


def test_required_then_optional_columns_nan_where_absent(tmp_path: Path) -> None:
    """The result holds t,lat,lon,h then vn,ve,vd,sigma_h,sigma_v,sigma_vel whatever the file's order, extra
    columns ignored, spaces around names stripped, NaN for an absent column or an empty cell."""
    p = text(tmp_path, " sigma_v ,x,h,t,lon,vn,lat\n5,99,10,0.5,7,1.5,45\n,99,11,1.5,7.5,,46\n")
    np.testing.assert_array_equal(gnss(p), [[0.5, 45, 7, 10, 1.5, np.nan, np.nan, np.nan, 5, np.nan],
                                            [1.5, 46, 7.5, 11, np.nan, np.nan, np.nan, np.nan, np.nan, np.nan]])


@pytest.mark.parametrize("no_fix", [False, True])
def test_only_the_required_columns(tmp_path: Path, no_fix: bool) -> None:
    """A file of exactly t,lat,lon,h: its values, then six NaN columns, by either reader; equal times are no
    error."""
    p = text(tmp_path, "t,lat,lon,h\n0.5,45,7,10\n0.5,45.5,7.5,11\n2,46,8,12\n")
    out = gnss(p, no_fix)
    np.testing.assert_array_equal(out[:, :4], [[0.5, 45, 7, 10], [0.5, 45.5, 7.5, 11], [2, 46, 8, 12]])
    assert out.shape == (3, 10) and np.all(np.isnan(out[:, 4:]))


def test_a_header_only_file_has_no_rows(tmp_path: Path) -> None:
    """A baro file of a header t,h,sigma alone gives zero rows of t,h,sigma."""
    assert baro(text(tmp_path, "t,h,sigma\n", "baro.csv")).shape == (0, 3)


def test_baro_sigma_column(tmp_path: Path) -> None:
    """A baro file with sigma: t,h,sigma in that order whatever the file's order."""
    p = text(tmp_path, "sigma,h,t\n0.25,100.5,1\n0.75,101,2\n", "baro.csv")
    np.testing.assert_array_equal(baro(p), [[1, 100.5, 0.25], [2, 101, 0.75]])


def test_rows_without_a_position_are_no_fix(tmp_path: Path) -> None:
    """With no_fix_rows an empty or NaN position is read as NaN (no fix), not refused."""
    p = text(tmp_path, "t,lat,lon,h\n1,45,7,10\n2,,,\n3,nan,nan,nan\n")
    out = gnss(p)
    np.testing.assert_array_equal(out[:, 0], [1, 2, 3])
    assert np.all(np.isnan(out[1:, 1:4])) and np.all(np.isfinite(out[0, :4]))


@pytest.mark.parametrize("body,line", [("t,lat,lon,h\n0,1,2,3\n1,1,2,3\n2,1,2,3\n1.5,1,2,3\n", 5),
                                       ("t,lat,lon,h\n1,1,2,3\n0.5,1,2,3\n", 3),
                                       ("t,lat,lon,h,sigma_h\n0,1,2,3,1\n1,1,2,3,1\n0.5,1,2,3,1\n", 4)])
def test_time_going_back_names_its_line(tmp_path: Path, body: str, line: int) -> None:
    """A t smaller than the one before is refused in one line naming that row's line (header = line 1)."""
    p = text(tmp_path, body)
    with pytest.raises(DataFileError) as err:
        gnss(p, no_fix=False)
    assert str(err.value) == f"{p}: line {line}, column 't': time goes back"


@pytest.mark.parametrize("cell", ["", "nan", "inf"])
def test_a_time_that_is_not_a_finite_number(tmp_path: Path, cell: str) -> None:
    """An empty, NaN or infinite t is refused in one line naming its line and cell, as files.py's errors do (the
    position may be empty, the time may not)."""
    p = text(tmp_path, f"t,lat,lon,h\n1,45,7,10\n{cell},45,7,10\n")
    with pytest.raises(DataFileError) as err:
        gnss(p)
    assert str(err.value) == f"{p}: line 3, column 't': not a number: {cell!r}"


def test_missing_columns_are_named(tmp_path: Path) -> None:
    """Missing required columns are named in the order of the contract, with the header as read."""
    p = text(tmp_path, "lon, t,x\n1,2,3\n")
    with pytest.raises(DataFileError) as err:
        gnss(p)
    assert str(err.value) == f"{p}: missing column(s) lat, h (header: lon,t,x)"


def test_an_unreadable_file(tmp_path: Path) -> None:
    """A file that does not exist, or is not UTF-8 text, is refused in one line naming it."""
    p = tmp_path / "none.csv"
    with pytest.raises(DataFileError) as err:
        baro(p)
    assert str(err.value) == f"{p}: cannot read: No such file or directory"
    q = tmp_path / "bin.csv"
    q.write_bytes(b"t,h\xff\xfe\n1,2\n")
    with pytest.raises(DataFileError) as err:
        baro(q)
    assert str(err.value).startswith(f"{q}: cannot read: ") and "utf-8" in str(err.value)


# ---- the filter: run_nav_aided ----------------------------------------------------------------------------------

def aided(tmp_path: Path, *extra: object, n: int = 20, init: Path | None = None, imu: Path | None = None,
          gnss_rows: str = "", baro_rows: str | None = None) -> tuple[int, str, np.ndarray]:
    imu = imu or write_imu(tmp_path, n)
    init = init or write_init(tmp_path)
    g = text(tmp_path, "t,lat,lon,h\n" + gnss_rows)
    out = tmp_path / "nav.csv"
    args = ["nav", imu, "--init", init, "-o", out, "--gnss", g, *extra]
    if baro_rows is not None:
        args += ["--baro", text(tmp_path, "t,h\n" + baro_rows, "baro.csv")]
    code, err = run(*args)
    if code:
        return code, err, np.empty((0, 35))
    header, sol = table(out)
    assert header == SOLUTION + FILTER
    return code, err, sol


def test_without_fixes_the_filter_solution_is_the_free_inertial_one(tmp_path: Path) -> None:
    """A GNSS file without fixes: the 14 solution columns are those of free inertial (one row per update,
    zero velocity and the start position at rest), then the 21 filter columns; no count is printed."""
    code, err, sol = aided(tmp_path, "--grade", "tactical", "--earth", "none")
    assert code == 0, err
    assert err.strip() == f"mavins nav: wrote 10 solution rows to {tmp_path / 'nav.csv'}"
    assert sol.shape == (10, 35)
    np.testing.assert_allclose(sol[:, 0], T0 + 2 * DT * np.arange(1, 11), rtol=0, atol=1e-12)
    assert np.all(np.abs(sol[:, 4:7]) < 1e-6) and np.all(np.abs(sol[:, 3] - H) < 1e-6)


def test_the_initial_uncertainty_defaults(tmp_path: Path) -> None:
    """Without the sigma keys the first row's 1-sigma are the defaults, grown a little over 0.02 s: position 10 m,
    velocity 1 m/s, level 1 deg, yaw 10 deg."""
    code, err, sol = aided(tmp_path, "--grade", "tactical")
    assert code == 0, err
    r = sol[0]
    for col, v in (("sigma_n", 10), ("sigma_e", 10), ("sigma_d", 10), ("sigma_vn", 1), ("sigma_vd", 1),
                   ("sigma_att_n", 1), ("sigma_att_e", 1), ("sigma_att_d", 10)):
        assert v <= r[35 - 21 + FILTER.index(col)] < 1.01 * v, col


def test_the_initial_uncertainty_keys_are_taken(tmp_path: Path) -> None:
    """sigma_pos, sigma_vel, sigma_level, sigma_yaw of the initial-state JSON set the first row's 1-sigma."""
    init = write_init(tmp_path, sigma_pos=3, sigma_vel=0.5, sigma_level=2.5, sigma_yaw=20.0)
    code, err, sol = aided(tmp_path, "--grade", "tactical", init=init)
    assert code == 0, err
    r = sol[0]
    for col, v in (("sigma_n", 3), ("sigma_d", 3), ("sigma_ve", 0.5), ("sigma_att_e", 2.5), ("sigma_att_d", 20)):
        assert v <= r[14 + FILTER.index(col)] < 1.01 * v, col


@pytest.mark.parametrize("key,value", [("sigma_pos", 0), ("sigma_vel", 1e7), ("sigma_level", -1.0),
                                       ("sigma_yaw", True), ("sigma_pos", "3"), ("sigma_vel", None)])
def test_an_initial_uncertainty_must_be_a_positive_number_below_1e7(tmp_path: Path, key: str,
                                                                     value: object) -> None:
    """0, 1e7, a negative number, a boolean, a string or null is refused in one line naming the file and key."""
    init = write_init(tmp_path, **{key: value})
    code, err, _ = aided(tmp_path, init=init)
    assert code == 2
    assert err.strip() == f"mavins nav: error: {init}: {key} must be a positive number, got {value!r}"


def test_just_inside_the_uncertainty_bounds(tmp_path: Path) -> None:
    """The largest double below 1e7 is a valid sigma_pos (and gives that 1-sigma)."""
    big = math.nextafter(1e7, 0.0)
    code, err, sol = aided(tmp_path, init=write_init(tmp_path, sigma_pos=big))
    assert code == 0, err
    assert big <= sol[0, 14] < 1.01 * big


def test_a_fix_beyond_the_gate_is_rejected_and_counted(tmp_path: Path) -> None:
    """Two fixes at the start point and one 1 km north: with the default gate (5 sigma) the far one is rejected,
    with --gate 1000 accepted; the counts come out in one line per kind with the gate."""
    far = LAT + 1000.0 / 111_000.0
    rows = f"1.05,{LAT},{LON},{H}\n1.1,{far},{LON},{H}\n1.15,{LAT},{LON},{H}\n"
    code, err, sol = aided(tmp_path, gnss_rows=rows)
    assert code == 0, err
    assert err.splitlines()[0] == "mavins nav: gnss_pos: 2 accepted, 1 rejected (gate 5 sigma)"
    assert abs(sol[-1, 1] - LAT) < 1e-6
    code, err, sol = aided(tmp_path, "--gate", "1000", gnss_rows=rows)
    assert code == 0, err
    assert err.splitlines()[0] == "mavins nav: gnss_pos: 3 accepted, 0 rejected (gate 1000 sigma)"
    assert sol[-1, 1] - LAT > 100.0 / 111_000.0


def test_the_lever_arm_moves_the_antenna(tmp_path: Path) -> None:
    """A fix 20 m above the start point is where an antenna 20 m up (FRD z = -20) is: with that lever arm the
    height stays at the start; without it the fix pulls the height up by metres."""
    rows = f"1.05,{LAT},{LON},{H + 20.0}\n"
    code, err, sol = aided(tmp_path, "--lever-arm=0,0,-20", gnss_rows=rows)
    assert code == 0, err
    assert abs(sol[-1, 3] - H) < 0.01
    code, err, sol = aided(tmp_path, gnss_rows=rows)
    assert code == 0, err
    assert sol[-1, 3] - H > 5.0


def test_a_baro_file_is_taken(tmp_path: Path) -> None:
    """Baro readings are counted (accepted, none rejected) and a baro-only run writes the filter's columns."""
    code, err, sol = aided(tmp_path, baro_rows="1.05,100\n1.1,100\n1.15,100\n")
    assert code == 0, err
    assert err.splitlines()[0] == "mavins nav: baro: 3 accepted, 0 rejected (gate 5 sigma)"
    assert sol.shape == (10, 35)


def test_averaged_rates_give_the_increments_solution(tmp_path: Path) -> None:
    """Averaged rates times their interval are the increments (docs/conventions.md "Files"), so the filter's
    solution from the rate file equals the increments' one; rate rows at or before t0 are not used."""
    rows = f"1.05,{LAT},{LON},{H + 3.0}\n"
    code, err, want = aided(tmp_path, gnss_rows=rows, imu=write_imu(tmp_path, 20, wz=0.5))
    assert code == 0, err
    before = ["0.5,9,9,9,9,9,9", f"{T0!r},9,9,9,9,9,9"]
    rates = write_imu(tmp_path, 20, wz=0.5, rates=True, before=before)
    code, err, got = aided(tmp_path, "--input", "rates", gnss_rows=rows, imu=rates)
    assert code == 0, err
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_sampled_rates_are_refused_with_the_filter(tmp_path: Path) -> None:
    """The filter takes increments or averaged rates: sampled rates are refused in one line."""
    code, err, _ = aided(tmp_path, "--input", "rates", "--imu-rates", "sampled",
                         imu=write_imu(tmp_path, 20, rates=True))
    assert code == 2
    assert err.strip() == ("mavins nav: error: the filter takes increments or averaged rates; sampled rates are not "
                           "supported with --gnss/--baro/--mag/--rest")


@pytest.mark.parametrize("frame", ["wander", "free", "inertial"])
def test_the_filter_works_in_the_geographic_frame_only(tmp_path: Path, frame: str) -> None:
    """Another mechanisation frame with --gnss is refused in one line, and nothing is written."""
    code, err, _ = aided(tmp_path, "--frame", frame)
    assert code == 2
    assert err.strip() == (f"mavins nav: error: --frame {frame}: the filter (--gnss, --baro, --mag, --rest) works in the "
                           "geographic frame only")
    assert not (tmp_path / "nav.csv").exists()


def test_run_nav_aided_returns_rows_and_counts(tmp_path: Path) -> None:
    """Called directly: the rows written and the (accepted, rejected) counts by kind."""
    g = text(tmp_path, f"t,lat,lon,h\n1.05,{LAT},{LON},{H}\n")
    rows, counts = nav.run_nav_aided(write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv", opts(),
                                     nav.AidingFiles(g), "tactical", (0.0, 0.0, 0.0), 5.0)
    assert rows == 10
    assert counts["gnss_pos"] == (1, 0) and counts["baro"] == (0, 0)


def test_a_bad_filter_input_is_a_data_file_error(tmp_path: Path) -> None:
    """What the filter refuses (here an IMU spec with a negative noise) comes back as a DataFileError."""
    g = text(tmp_path, "t,lat,lon,h\n")
    with pytest.raises(DataFileError):
        nav.run_nav_aided(write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv", opts(),
                          nav.AidingFiles(g), {"gyro_arw": -1.0, "accel_vrw": 0.1}, (0.0, 0.0, 0.0), 5.0)


# ---- --each: batch_outputs and run_nav_batch --------------------------------------------------------------------

def test_batch_outputs_mirror_the_folders(tmp_path: Path) -> None:
    """OUT/<folder relative to the common folder>/<name before its first dot>.nav.csv (.nav.parquet for parquet);
    two inputs that would write one solution are refused."""
    a, b, c = tmp_path / "r" / "a" / "imu.csv", tmp_path / "r" / "b" / "x.imu.csv.gz", tmp_path / "r" / "c.parquet"
    out = tmp_path / "out"
    assert nav.batch_outputs([a, b, c], out) == [out / "a" / "imu.nav.csv", out / "b" / "x.nav.csv",
                                                 out / "c.nav.parquet"]
    with pytest.raises(DataFileError) as err:
        nav.batch_outputs([a, tmp_path / "r" / "a" / "imu.csv.gz"], out)
    assert str(err.value) == "--each: two inputs would write the same solution (same folder and name)"


def test_run_nav_batch_in_process(tmp_path: Path) -> None:
    """One job: each file with its own init.json, solutions as if alone; a bad file's one-line error in its row,
    no timing line even with --timing."""
    d1, d2 = tmp_path / "r1", tmp_path / "r2"
    d1.mkdir()
    d2.mkdir()
    write_imu(d1, 20)
    write_init(d1)
    write_imu(d2, 4, t_first=T0)
    write_init(d2)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        res, summary = nav.run_nav_batch([d1 / "imu.csv", d2 / "imu.csv"], None, tmp_path / "out",
                                         opts(earth_model="none", timing=True), jobs=1)
    assert not any(ln.startswith("timing") for ln in err.getvalue().splitlines())
    out1 = tmp_path / "out" / "r1" / "imu.nav.csv"
    assert [(o.input, o.output, o.solution_rows) for o in res] == [
        (str(d1 / "imu.csv"), str(out1), 10), (str(d2 / "imu.csv"), str(tmp_path / "out" / "r2" / "imu.nav.csv"), 0)]
    assert res[0].error == "" and res[0].state == "done"
    bad = (f"{d2 / 'imu.csv'}: line 2, column 't': first increment time 1.0 is not after the initial "
           "state's t = 1.0 (row i covers (t[i-1], t[i]])")
    assert res[1].error == bad
    # summary.csv: one row per file in the order given; the bad file's row has its error and no output
    rows = summary.read_text().splitlines()
    assert summary == tmp_path / "out" / "summary.csv" and rows[0].split(",") == list(SUMMARY_COLUMNS)
    assert rows[1].split(",")[:5] == [str(d1 / "imu.csv"), str(out1), "", "0", "10"]
    assert rows[1].split(",")[11:] == ["done", ""] and rows[2].startswith(f"{d2 / 'imu.csv'},,")
    assert rows[2].endswith(bad if "," not in bad else f'"{bad}"')
    _, sol = table(out1)
    assert sol.shape[0] == 10
    assert_at_rest(sol)
    shared = write_init(tmp_path, "shared.json", yaw=-45.0)
    res, _ = nav.run_nav_batch([d1 / "imu.csv"], shared, tmp_path / "out2", opts(earth_model="none"), jobs=1)
    _, sol = table(Path(res[0].output))
    assert_at_rest(sol, yaw0=-45.0)


def test_a_bad_filter_input_names_what_is_wrong(tmp_path: Path) -> None:
    """The filter's refusal comes back as the one-line error, its text kept."""
    g = text(tmp_path, "t,lat,lon,h\n")
    with pytest.raises(DataFileError, match=r"^gyro_arw must be finite and >= 0, got -"):
        nav.run_nav_aided(write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv", opts(),
                          nav.AidingFiles(g), {"gyro_arw": -1.0, "accel_vrw": 0.1}, (0.0, 0.0, 0.0), 5.0)


def test_baro_alone_without_gnss(tmp_path: Path) -> None:
    """``--baro`` without ``--gnss``: the baro readings are taken, one row per update with the filter's columns."""
    imu, init, out = write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv"
    b = text(tmp_path, "t,h\n1.05,100\n", "baro.csv")
    code, err = run("nav", imu, "--init", init, "-o", out, "--baro", b)
    assert code == 0, err
    assert err.splitlines() == ["mavins nav: baro: 1 accepted, 0 rejected (gate 5 sigma)",
                                f"mavins nav: wrote 10 solution rows to {out}"]
    header, sol = table(out)
    assert header == SOLUTION + FILTER and sol.shape == (10, 35)


def test_an_empty_baro_height_is_refused(tmp_path: Path) -> None:
    """Only GNSS rows may lack their value (no fix): an empty baro h is refused in one line naming line and
    column."""
    p = text(tmp_path, "t,h\n1,100\n2,\n", "baro.csv")
    with pytest.raises(DataFileError) as err:
        baro(p)
    assert str(err.value) == f"{p}: line 3, column 'h': not a number: ''"


@pytest.mark.parametrize("t_back", ["0.25", "-1"])
def test_time_going_back_after_equal_and_small_steps(tmp_path: Path, t_back: str) -> None:
    """Equal times and steps below 1 s before the step back do not move the line named: the row going back is
    line 5."""
    p = text(tmp_path, f"t,lat,lon,h\n0,45,7,10\n0,45,7,10\n0.5,45,7,10\n{t_back},45,7,10\n")
    for no_fix in (False, True):
        with pytest.raises(DataFileError) as err:
            gnss(p, no_fix)
        assert str(err.value) == f"{p}: line 5, column 't': time goes back"


@pytest.mark.parametrize("which", ["IMU", "--init", "--gnss", "--baro"])
def test_an_output_that_is_an_input_is_refused(tmp_path: Path, which: str) -> None:
    """``-o`` naming one of the inputs is refused in one line naming both options, and the input is kept."""
    imu, init = write_imu(tmp_path, 20), write_init(tmp_path)
    g = text(tmp_path, "t,lat,lon,h\n")
    b = text(tmp_path, "t,h\n1.05,100\n", "baro.csv")
    target = {"IMU": imu, "--init": init, "--gnss": g, "--baro": b}[which]
    before = target.read_bytes()
    aiding = ["--gnss", g, "--baro", b] if which in ("--gnss", "--baro") else []
    code, err = run("nav", imu, "--init", init, "-o", target, *aiding)
    assert code == 2
    assert err.strip() == (f"mavins nav: error: {target}: -o is also the input {which}: writing it would destroy "
                           "the input; choose another output file")
    assert target.read_bytes() == before
    if not aiding:
        code, err = run("nav", imu, "--init", init, "-o", target, "--baro", b)
        assert err.strip() == (f"mavins nav: error: {target}: -o is also the input {which}: writing it would "
                               "destroy the input; choose another output file")


def test_each_refuses_an_output_that_is_an_input(tmp_path: Path) -> None:
    """``--each`` checks every file's solution against its IMU file the same way."""
    d = tmp_path / "r"
    d.mkdir()
    imu = write_imu(d, 4, name="imu.nav.csv")
    write_init(d)
    with pytest.raises(DataFileError) as err:
        nav.run_nav_batch([imu], None, d, opts(), jobs=1)
    assert str(err.value) == (f"{imu}: -o is also the input IMU: writing it would destroy the input; choose "
                              "another output file")


def test_a_write_error_is_one_line(tmp_path: Path) -> None:
    """A solution the file system will not take (here beyond the process's file size limit) is refused in one
    line naming the output and the system's reason (its text, not Python's "[Errno 27]" form), and no solution is
    left."""
    import resource
    import signal

    imu, init, out = write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv"
    old_sig = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    old = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (64, old[1]))
    try:
        with pytest.raises(DataFileError) as err:
            nav.run_nav(imu, init, out, opts(earth_model="none"))
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, old)
        signal.signal(signal.SIGXFSZ, old_sig)
    assert re.fullmatch(rf"{re.escape(str(out))}: cannot write: [^\n]*File too large", str(err.value)), str(err.value)
    assert "[Errno" not in str(err.value)
    assert not out.exists()
    assert list(tmp_path.glob(".nav.csv.*")) == []


@pytest.mark.parametrize("name,body", [
    ("baro.csv", "t,h,sigma\n1,100,0.5\n2,abc,0.5\n"),
    ("baro.csv", "t,h,sigma\n1,100,0.5\n2,100\n3,100,0.5\n"),
    ("gnss.csv", "t,lat,lon,h\n1,45,7,10\n2,abc,7,10\n"),
    ("gnss.csv", "t,lat,lon,h\n1,45,7,10\n2,45,7\n3,45,7,10\n"),
])
def test_a_malformed_aiding_row_is_refused_whatever_the_columns(tmp_path: Path, name: str, body: str) -> None:
    """docs/reliability.md "Offline tools on bad input": an input that cannot be what it claims is an error. A
    cell that is not a number (neither empty nor NaN, the contract's no fix) or a row short of fields is refused
    naming line 3, as ``t,h`` alone is refused ("line 3, column 'h': not a number: 'abc'")."""
    p = text(tmp_path, body, name)
    with pytest.raises(DataFileError, match=r": line 3(,|:) "):
        nav.read_aiding(p, *((nav.BARO_REQUIRED, nav.BARO_OPTIONAL) if name == "baro.csv"
                             else (nav.GNSS_REQUIRED, nav.GNSS_OPTIONAL)), no_fix_rows=name == "gnss.csv")


def test_a_baro_height_may_not_be_empty_even_beside_an_optional_column(tmp_path: Path) -> None:
    """Only GNSS rows may lack their measurement (no fix): a baro row with an empty or NaN height is refused
    naming its line, with or without the optional sigma column; an empty sigma is NaN (the default applies)."""
    for body, cell in (("t,h,sigma\n1,100,0.5\n2,,0.5\n", "''"), ("t,h,sigma\n1,100,0.5\n2,nan,0.5\n", "'nan'")):
        p = text(tmp_path, body, "baro.csv")
        with pytest.raises(DataFileError) as err:
            baro(p)
        assert str(err.value) == f"{p}: line 3, column 'h': not a number: {cell}"
    got = baro(text(tmp_path, "t,h,sigma\n1,100,\n", "baro.csv"))
    assert got[0, :2].tolist() == [1.0, 100.0] and math.isnan(got[0, 2])


def test_blank_lines_are_skipped_not_the_end(tmp_path: Path) -> None:
    """A blank line between fixes is skipped and the rows after it are read (file lines still counted: an error
    after it names its own line)."""
    got = gnss(text(tmp_path, "t,lat,lon,h\n1,45,7,10\n\n2,46,8,20\n"))
    assert got[:, :4].tolist() == [[1.0, 45.0, 7.0, 10.0], [2.0, 46.0, 8.0, 20.0]]
    p = text(tmp_path, "t,lat,lon,h\n1,45,7,10\n\n2,x,8,20\n")
    with pytest.raises(DataFileError) as err:
        gnss(p)
    assert str(err.value) == f"{p}: line 4, column 'lat': not a number: 'x'"


def test_undecodable_bytes_after_the_header_are_one_line(tmp_path: Path) -> None:
    """A row that is not UTF-8 is refused as 'cannot read' with the decoder's reason, not a traceback: near the
    start (found while the header is read) and 40 kB in (found while the rows are read)."""
    for n in (1, 2000):
        p = tmp_path / f"gnss{n}.csv"
        p.write_bytes(b"t,lat,lon,h\n" + b"".join(b"%d,45,7,10\n" % i for i in range(1, n + 1)) + b"9999,\xff,7,10\n")
        with pytest.raises(DataFileError) as err:
            gnss(p)
        assert str(err.value).startswith(f"{p}: cannot read: 'utf-8' codec can't decode byte 0xff in position ")


# ---- --mag ----------------------------------------------------------------------------------------------------------

def mag_file(tmp_path: Path, rows: str, header: str = "t,mx,my,mz,sigma") -> Path:
    return text(tmp_path, header + "\n" + rows, "mag.csv")


BETA = math.radians(-27.0)  # a horizontal field 27 deg left of the body's x axis


@pytest.mark.parametrize("sigma_col,declination,want", [
    (",10", "5", 30.0 + 2.0 * 100.0 / (100.0 + 100.0)),  # the field says 32 deg; P = R: half way
    ("", "5", 30.0 + 2.0 * 100.0 / (100.0 + 9.0)),  # no sigma column: 3 deg
    (",10", "3", 30.0),  # the field says 30 deg: nothing to correct
    (",0.5", "5", 30.0 + 2.0 * 100.0 / (100.0 + 0.25)),  # a sigma below 1 deg is a sigma like any other
])
def test_a_magnetometer_sample_corrects_the_yaw(tmp_path: Path, sigma_col: str, declination: str,
                                               want: float) -> None:
    """Level at rest, yaw 30 deg with the initial sigma of 10 deg: a horizontal field seen 27 deg left of the body's
    x axis has the azimuth yaw - 27 deg, which must be the declination: with 5 deg the field says the yaw is 32 deg,
    and the scalar update moves the yaw by 2 deg P / (P + R) (no tilt coupling: the field has no vertical part;
    the tactical grade's heading variance grows by below 1e-9 deg^2 before the sample; laboratory mode, so that
    the Earth's rate does not turn the yaw)."""
    header = "t,mx,my,mz" + ("," + "sigma" if sigma_col else "")
    m = mag_file(tmp_path, f"1.055,{math.cos(BETA)!r},{math.sin(BETA)!r},0.0{sigma_col}\n", header)
    code, err, sol = aided(tmp_path, "--mag", m, "--declination", declination, "--grade", "tactical", "--earth", "none")
    assert code == 0, err
    assert "mavins nav: mag: 1 accepted, 0 rejected (gate 5 sigma)" in err
    assert sol[-1, 9] == pytest.approx(want, abs=1e-6)
    assert np.all(sol[sol[:, 0] < 1.055, 9] == pytest.approx(30.0, abs=1e-9))


@pytest.mark.parametrize("sigma,shown", [("0", "0.0"), ("-1", "-1.0")])
def test_a_magnetometer_sigma_must_be_positive(tmp_path: Path, sigma: str, shown: str) -> None:
    m = mag_file(tmp_path, f"1.02,1,0,0,0.5\n1.04,1,0,0,{sigma}\n")  # the first row is fine: line 3 is named
    code, err, _ = aided(tmp_path, "--mag", m)
    assert code == 2
    assert err == f"mavins nav: error: {m}: line 3, column 'sigma': must be positive (deg of heading), got {shown}\n"
    assert not (tmp_path / "nav.csv").exists()


def test_the_output_may_not_be_the_magnetometer_file(tmp_path: Path) -> None:
    m = mag_file(tmp_path, "1.05,1,0,0,3\n")
    before = m.read_bytes()
    code, err = run("nav", write_imu(tmp_path, 20), "--init", write_init(tmp_path), "-o", m, "--mag", m)
    assert code == 2
    assert err == (f"mavins nav: error: {m}: -o is also the input --mag: writing it would destroy the input; "
                   "choose another output file\n")
    assert m.read_bytes() == before


def test_mag_alone_runs_the_filter(tmp_path: Path) -> None:
    """``--mag`` without ``--gnss`` or ``--baro`` runs the filter: the filter's columns, the sample counted."""
    imu, init, out = write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv"
    m = mag_file(tmp_path, f"1.05,{math.cos(BETA)!r},{math.sin(BETA)!r},0.0,3\n")
    code, err = run("nav", imu, "--init", init, "-o", out, "--mag", m, "--declination", "3")
    assert code == 0, err
    assert "mavins nav: mag: 1 accepted, 0 rejected (gate 5 sigma)" in err
    header, sol = table(out)
    assert header == SOLUTION + FILTER and sol.shape[0] == 10


def test_several_imu_files_or_each_refuse_mag(tmp_path: Path) -> None:
    imu, init, out = write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv"
    imu2 = write_imu(tmp_path, 20, name="imu2.csv")
    m = mag_file(tmp_path, "1.05,1,0,0,3\n")
    code, err = run("nav", imu, imu2, "--init", init, "-o", out, "--mag", m)
    assert code == 2 and err == ("mavins nav: error: several IMU files with --gnss/--baro/--mag/--rest are not supported "
                                 "(the fused solution is free inertial)\n")
    code, err = run("nav", "--each", imu, "-o", tmp_path / "out", "--mag", m)
    assert code == 2 and err == "mavins nav: error: --each navigates free inertial; --mag cannot go with it\n"


# ---- --rest ---------------------------------------------------------------------------------------------------------

def test_rest_windows_are_sorted_and_may_not_overlap() -> None:
    assert nav.rest_windows(()) is None
    np.testing.assert_array_equal(nav.rest_windows(((5.0, 6.0), (1.0, 2.0), (2.0, 3.0))),
                                  [[1.0, 2.0], [2.0, 3.0], [5.0, 6.0]])
    with pytest.raises(ValueError) as e:
        nav.rest_windows(((1.0, 2.5), (2.0, 3.0)))
    assert str(e.value) == "--rest 1,2.5 and --rest 2,3 overlap"


def test_rest_alone_runs_the_filter(tmp_path: Path) -> None:
    """``--rest`` without aiding files: a zero-velocity update at each of the 10 attitude updates in (1.0, 1.2] and
    one zero-rate update at its end, counted; the filter's columns."""
    imu, init, out = write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv"
    code, err = run("nav", imu, "--init", init, "-o", out, "--rest", "1.0,1.2", "--earth", "none")
    assert code == 0, err
    assert "mavins nav: zupt: 10 accepted, 0 rejected (gate 5 sigma)" in err
    assert "mavins nav: zaru: 1 accepted, 0 rejected (gate 5 sigma)" in err
    header, sol = table(out)
    assert header == SOLUTION + FILTER and sol.shape[0] == 10


def test_overlapping_rests_are_one_line_and_no_output(tmp_path: Path) -> None:
    imu, init, out = write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv"
    code, err = run("nav", imu, "--init", init, "-o", out, "--rest", "1.1,1.2", "--rest", "1.0,1.15")
    assert code == 2 and err == "mavins nav: error: --rest 1,1.15 and --rest 1.1,1.2 overlap\n"
    assert not out.exists()


def test_several_imu_files_or_each_refuse_rest(tmp_path: Path) -> None:
    imu, init, out = write_imu(tmp_path, 20), write_init(tmp_path), tmp_path / "nav.csv"
    imu2 = write_imu(tmp_path, 20, name="imu2.csv")
    code, err = run("nav", imu, imu2, "--init", init, "-o", out, "--rest", "1,1.1")
    assert code == 2 and "several IMU files with --gnss/--baro/--mag/--rest are not supported" in err
    code, err = run("nav", "--each", imu, "-o", tmp_path / "out", "--rest", "1,1.1")
    assert code == 2 and err == "mavins nav: error: --each navigates free inertial; --rest cannot go with it\n"
