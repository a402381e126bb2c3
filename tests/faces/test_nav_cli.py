"""``mavins nav`` end to end: the real console script in a subprocess, on files in tmp_path.

Checks the command-line contract of docs/conventions.md ("Files" and "Command
line" -> ``mavins nav``): output columns and rows, round-trip values equal bit
for bit to the in-process :func:`mavins.core.runner.navigate`, every option,
and clean one-line errors (exit 2, no traceback) for unusable input.

The option runs are started together, two at a time, by one module fixture,
because each pays the interpreter, numba import and kernel-cache start-up.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from mavins.common import files
from sim.motion import stationary

SOLUTION_HEADER = "t,lat,lon,h,vn,ve,vd,roll,pitch,yaw,qw,qx,qy,qz"
INIT = {"t": 0.0, "lat": 45.0, "lon": 7.0, "h": 100.0, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 1.0, "pitch": 2.0, "yaw": 30.0}
TIMING_RE = re.compile(r"^timing: samples=(\d+) read_s=(\d+(?:\.\d+)?) compute_s=(\d+(?:\.\d+)?) write_s=(\d+(?:\.\d+)?)$")
CONTRACT_OPTIONS = (
    "--init",
    "-o",
    "--input",
    "--samples",
    "--no-coning",
    "--imu-rates",
    "--attitude",
    "--order",
    "--earth",
    "--orthonormalize-every",
    "--vertical",
    "--timing",
)
CONTRACT_CHOICES = ("increments", "rates", "averaged", "sampled", "quaternion", "dcm", "exact", "wgs84", "none", "free", "hold")
HEAVY_MODULES = ("numba", "pymavlink", "rerun")


# --- helpers ----------------------------------------------------------------


def _mavins_command() -> list[str]:
    """The installed console script next to the interpreter, else ``python -m mavins.cli``."""
    script = Path(sys.executable).parent / "mavins"
    if script.is_file():
        return [str(script)]
    return [sys.executable, "-m", "mavins.cli"]


MAVINS = _mavins_command()


def run_mavins(*args: object, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*MAVINS, *(str(a) for a in args)], cwd=cwd, capture_output=True, text=True, timeout=180
    )


def navigate(t, gyro, accel, init=INIT, **options) -> np.ndarray:
    from mavins.core.runner import navigate as nav

    return nav(np.asarray(t), np.asarray(gyro), np.asarray(accel), init, **options)


def write_increments(path: Path, t, dtheta, dv) -> None:
    files.write_table(path, files.INCREMENT_COLUMNS, np.column_stack([t, dtheta, dv]))


def write_init(path: Path, init: dict = INIT) -> None:
    path.write_text(json.dumps(init, indent=2) + "\n", encoding="utf-8")


def read_nav(path: Path) -> tuple[str, np.ndarray]:
    """Header line and values of a solution file, parsed with Python's own float()."""
    lines = path.read_text(encoding="utf-8").splitlines()
    rows = [[float(x) for x in line.split(",")] for line in lines[1:]]
    for i, row in enumerate(rows, start=2):
        assert len(row) == 14, f"{path}: line {i} has {len(row)} fields"
    return lines[0], np.array(rows, dtype=np.float64).reshape(-1, 14)


def assert_bitwise(got: np.ndarray, want: np.ndarray, what: str = "") -> None:
    assert got.shape == want.shape, f"{what}: shape {got.shape} != {want.shape}"
    same = got.view(np.uint64) == want.view(np.uint64)
    if not same.all():
        i, j = np.argwhere(~same)[0]
        diff = np.max(np.abs(got - want))
        raise AssertionError(
            f"{what}: not bit-identical; first at row {i}, column {SOLUTION_HEADER.split(',')[j]}: "
            f"{got[i, j]!r} != {want[i, j]!r} (max |diff| {diff:.3g})"
        )


def differs(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape != b.shape or not np.array_equal(a.view(np.uint64), b.view(np.uint64))


def significant_digits(text: str) -> str:
    """The significant digits of a decimal number's text ("0.00120" and "1.2e-3" -> "12")."""
    return text.lower().split("e")[0].lstrip("+-").replace(".", "").strip("0")


def assert_shortest_round_trip(cell: str, what: str = "") -> None:
    """``cell`` parses to a double and has no more significant digits than Python's repr of it
    (the shortest text that round-trips, Steele & White / Gay); spelling (1 vs 1.0, 1e-05 vs
    0.00001) is free."""
    value = float(cell)
    assert len(significant_digits(cell)) <= len(significant_digits(repr(value))), f"{what}{cell!r} is not shortest"
    assert float(repr(value)) == value


def stderr_lines(proc: subprocess.CompletedProcess[str]) -> list[str]:
    return [line for line in proc.stderr.splitlines() if line.strip()]


def timing_lines(proc: subprocess.CompletedProcess[str]) -> list[str]:
    return [line for line in proc.stderr.splitlines() if line.startswith("timing")]


# --- data -------------------------------------------------------------------

DT = 0.01
N_DYN = 61  # 61 = not a multiple of 2..6: trailing samples for every N > 1


def dynamic_increments() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A wobbling vehicle: stationary increments plus time-varying rates and forces.

    Not a closed-form truth; it only has to exercise coning, sculling, the
    attitude orders and the vertical channel so that options visibly matter.
    """
    m = stationary(INIT["lat"], INIT["h"], INIT["roll"], INIT["pitch"], INIT["yaw"], DT, N_DYN)
    tm = m.t - 0.5 * DT
    w = np.column_stack([0.4 * np.sin(2 * np.pi * 2.0 * tm), 0.3 * np.cos(2 * np.pi * 3.0 * tm), np.full(N_DYN, 0.2)])
    f = np.column_stack([0.5 * np.sin(2 * np.pi * tm), 0.3 * np.cos(4 * np.pi * tm), np.full(N_DYN, 0.05)])
    return m.t, m.dtheta + w * DT, m.dv + f * DT


def dynamic_rates() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rate rows of the dynamic motion, with two rows before the initial t and one at it.

    The rows before the initial t carry absurd values: the contract says they
    are ignored (for averaged and sampled rates alike).
    """
    t, dth, dv = dynamic_increments()
    w = dth / DT
    f = dv / DT
    tr = np.concatenate(([-0.02, -0.01, INIT["t"]], t))
    wr = np.vstack([[5.0, -5.0, 5.0], [5.0, -5.0, 5.0], w[0], w])
    fr = np.vstack([[50.0, 50.0, -50.0], [50.0, 50.0, -50.0], f[0], f])
    return tr, wr, fr


def lab_increments() -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """At rest in a non-rotating laboratory frame: no rotation, f^b = -C_n^b [0, 0, g(start)]."""
    from mavins.core import earth
    from mavins.core.rotation import euler_to_dcm

    g0 = earth.gravity(np.radians(INIT["lat"]), INIT["h"])
    c_bn = euler_to_dcm(np.radians(INIT["roll"]), np.radians(INIT["pitch"]), np.radians(INIT["yaw"]))
    f_b = c_bn.T @ np.array([0.0, 0.0, -g0])
    n = 40
    t = DT * np.arange(1, n + 1, dtype=np.float64)
    return t, np.zeros((n, 3)), np.tile(f_b * DT, (n, 1)), g0


# --- happy path -------------------------------------------------------------


def test_stationary_happy_path(tmp_path: Path) -> None:
    n = 21  # odd: the last sample does not fill an update with the default N = 2
    m = stationary(INIT["lat"], INIT["h"], INIT["roll"], INIT["pitch"], INIT["yaw"], DT, n)
    assert m.t0 == INIT["t"]
    imu, init, out = tmp_path / "IMU.csv", tmp_path / "INIT.json", tmp_path / "NAV.csv"
    write_increments(imu, m.t, m.dtheta, m.dv)
    write_init(init)
    # The file written is the data navigated: it round-trips exactly.
    back = files.read_table(imu, files.INCREMENT_COLUMNS)
    assert np.array_equal(back, np.column_stack([m.t, m.dtheta, m.dv]))

    proc = run_mavins("nav", imu, "--init", init, "-o", out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert not timing_lines(proc), "no timing line without --timing"

    header, got = read_nav(out)
    assert header == SOLUTION_HEADER
    for line in out.read_text(encoding="utf-8").splitlines()[1:]:
        for cell in line.split(","):
            assert_shortest_round_trip(cell)
    assert got.shape == (n // 2, 14)
    # One row per update, at the time of its last sample; the 21st sample is unused.
    assert np.array_equal(got[:, 0], m.t[1::2][: n // 2])
    assert got[-1, 0] == m.t[19]

    want = navigate(m.t, m.dtheta, m.dv, data="increments")
    assert_bitwise(got, want, "mavins nav vs navigate()")

    # A vehicle at rest with exact increments stays at rest.
    assert np.max(np.abs(got[:, 4:7])) < 1e-9
    assert np.allclose(got[:, 1:3], [INIT["lat"], INIT["lon"]], rtol=0, atol=1e-10)
    assert np.allclose(got[:, 3], INIT["h"], rtol=0, atol=1e-6)
    assert np.allclose(got[:, 7:10], [INIT["roll"], INIT["pitch"], INIT["yaw"]], rtol=0, atol=1e-9)
    assert np.allclose(np.linalg.norm(got[:, 10:14], axis=1), 1.0, rtol=0, atol=1e-15)


# --- options ----------------------------------------------------------------


def _option_runs() -> dict[str, tuple[str, list[str]]]:
    """name -> (input file key, extra arguments)."""
    runs: dict[str, tuple[str, list[str]]] = {}
    for n in (1, 3, 4, 5, 6):  # N = 2 is spelled out in the explicit-defaults run
        runs[f"samples{n}"] = ("dyn", ["--samples", str(n)])
    runs["no-coning"] = ("dyn", ["--no-coning"])
    runs["dcm"] = ("dyn", ["--attitude", "dcm"])
    for k in ("1", "2", "3", "4"):
        runs[f"order{k}"] = ("dyn", ["--order", k])
    runs["dcm-order2"] = ("dyn", ["--attitude", "dcm", "--order", "2"])
    runs["dcm-order1-ortho0"] = ("dyn", ["--attitude", "dcm", "--order", "1", "--orthonormalize-every", "0"])
    runs["dcm-order1-ortho3"] = ("dyn", ["--attitude", "dcm", "--order", "1", "--orthonormalize-every", "3"])
    runs["quat-ortho0"] = ("dyn", ["--orthonormalize-every", "0"])
    runs["earth-none"] = ("lab", ["--earth", "none"])
    runs["hold"] = ("dyn", ["--vertical", "hold"])
    runs["rates-default"] = ("rates", ["--input", "rates"])  # averaged; spelled out in explicit-defaults
    runs["rates-sampled"] = ("rates", ["--input", "rates", "--imu-rates", "sampled"])
    runs["explicit-defaults-timing"] = (
        "shuffled",
        [
            "--input", "increments", "--samples", "2", "--attitude", "quaternion", "--order", "exact",
            "--earth", "wgs84", "--orthonormalize-every", "1", "--vertical", "free",
            "--imu-rates", "averaged", "--timing",
        ],
    )  # fmt: skip
    return runs


@pytest.fixture(scope="module")
def option_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[subprocess.CompletedProcess[str], Path]]:
    d = tmp_path_factory.mktemp("nav_options")
    init = d / "INIT.json"
    write_init(init)
    t, dth, dv = dynamic_increments()
    write_increments(d / "dyn.csv", t, dth, dv)
    tr, wr, fr = dynamic_rates()
    files.write_table(d / "rates.csv", files.RATE_COLUMNS, np.column_stack([tr, wr, fr]))
    tl, thl, dvl, _ = lab_increments()
    write_increments(d / "lab.csv", tl, thl, dvl)
    # Extra columns (numeric and text, first, middle and last) and a different column order.
    order = ["dv_z", "t", "dtheta_y", "dv_x", "dtheta_z", "dtheta_x", "dv_y"]
    cols = {name: np.column_stack([t, dth, dv])[:, i] for i, name in enumerate(files.INCREMENT_COLUMNS)}
    with open(d / "shuffled.csv", "w", encoding="utf-8", newline="") as fh:
        fh.write("label," + ",".join(order[:3]) + ",temperature," + ",".join(order[3:]) + ",status\n")
        for i in range(t.shape[0]):
            vals = [repr(float(cols[c][i])) for c in order]
            fh.write(f"seg-{i % 3}," + ",".join(vals[:3]) + f",{20.0 + i}," + ",".join(vals[3:]) + ",ok go\n")

    runs = _option_runs()

    def one(item):
        name, (key, extra) = item
        out = d / f"NAV-{name}.csv"
        return name, (run_mavins("nav", d / f"{key}.csv", "--init", init, "-o", out, *extra), out)

    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(pool.map(one, runs.items()))


@pytest.fixture(scope="module")
def refs():
    """In-process references, memoised by option set."""
    cache: dict[tuple, np.ndarray] = {}
    data = {"dyn": dynamic_increments(), "rates": dynamic_rates(), "lab": lab_increments()[:3]}

    def ref(key: str = "dyn", **options) -> np.ndarray:
        k = (key, tuple(sorted(options.items())))
        if k not in cache:
            t, a, b = data[key]
            kind = "rates" if key == "rates" else "increments"
            cache[k] = navigate(t, a, b, data=kind, **options)
        return cache[k]

    return ref


def _ok(option_runs, name: str) -> np.ndarray:
    proc, out = option_runs[name]
    assert proc.returncode == 0, f"{name}: exit {proc.returncode}\n{proc.stderr}"
    assert "Traceback" not in proc.stderr
    header, got = read_nav(out)
    assert header == SOLUTION_HEADER
    return got


@pytest.mark.parametrize("n", range(1, 7))
def test_samples(option_runs, refs, n: int) -> None:
    got = _ok(option_runs, f"samples{n}" if n != 2 else "explicit-defaults-timing")
    t = dynamic_increments()[0]
    assert got.shape[0] == N_DYN // n
    assert np.array_equal(got[:, 0], t[n - 1 :: n][: N_DYN // n]), "one row per N samples, at the last one"
    assert_bitwise(got, refs(samples=n), f"--samples {n}")
    if n == 2:
        assert_bitwise(got, refs(), "--samples 2 is the default")
    else:
        assert differs(got, refs())


def test_no_coning(option_runs, refs) -> None:
    got = _ok(option_runs, "no-coning")
    assert_bitwise(got, refs(coning=False), "--no-coning")
    assert got.shape == refs().shape
    assert np.array_equal(got[:, 0], refs()[:, 0]), "--no-coning keeps the N-sample update"
    assert differs(got, refs()), "--no-coning changes nothing on a coning/sculling motion"
    # N = 1 applies no correction: --no-coning is then a no-op.
    assert_bitwise(refs(samples=1, coning=False), refs(samples=1), "samples=1 with and without coning")


def test_attitude_dcm(option_runs, refs) -> None:
    got = _ok(option_runs, "dcm")
    assert_bitwise(got, refs(attitude="dcm"), "--attitude dcm")
    assert differs(got, refs())
    # Same exact update in another representation: same solution to round-off.
    assert np.allclose(got, refs(), rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    "name, attitude, order",
    [("order1", "quaternion", "1"), ("order2", "quaternion", "2"), ("order3", "quaternion", "3"),
     ("order4", "quaternion", "4"), ("dcm-order2", "dcm", "2")],
)  # fmt: skip
def test_order(option_runs, refs, name: str, attitude: str, order: str) -> None:
    got = _ok(option_runs, name)
    assert_bitwise(got, refs(attitude=attitude, order=order), f"--attitude {attitude} --order {order}")
    assert differs(got, refs(attitude=attitude)), f"--order {order} equals --order exact"
    others = [o for o in ("1", "2", "3", "4") if o != order]
    for o in others:
        assert differs(got, refs(attitude=attitude, order=o)), f"--order {order} equals --order {o}"


def test_orders_converge_to_exact(refs) -> None:
    """Higher truncation orders get closer to the exact update (attitude quaternion)."""
    for attitude in ("quaternion", "dcm"):
        exact = refs(attitude=attitude)
        errs = [np.max(np.abs(refs(attitude=attitude, order=o)[:, 10:14] - exact[:, 10:14])) for o in "1234"]
        assert errs[0] > errs[1] > errs[2] >= errs[3] * 0.999, (attitude, errs)


def test_orthonormalize_every(option_runs, refs) -> None:
    never = _ok(option_runs, "dcm-order1-ortho0")
    every3 = _ok(option_runs, "dcm-order1-ortho3")
    assert_bitwise(never, refs(attitude="dcm", order="1", orthonormalize_every=0), "--orthonormalize-every 0")
    assert_bitwise(every3, refs(attitude="dcm", order="1", orthonormalize_every=3), "--orthonormalize-every 3")
    every1 = refs(attitude="dcm", order="1")
    assert differs(never, every1) and differs(every3, every1) and differs(never, every3)
    # A quaternion is normalised every update anyway: the option has no effect there.
    assert_bitwise(_ok(option_runs, "quat-ortho0"), refs(), "quaternion with --orthonormalize-every 0")


def test_earth_none_laboratory_rest(option_runs, refs) -> None:
    got = _ok(option_runs, "earth-none")
    assert_bitwise(got, refs("lab", earth_model="none"), "--earth none")
    assert differs(got, refs("lab")), "--earth none equals wgs84"
    # No rotation and dv = -g(start) dt: at rest in the non-rotating frame.
    assert np.max(np.abs(got[:, 4:7])) < 1e-12
    assert np.allclose(got[:, 1:4], [INIT["lat"], INIT["lon"], INIT["h"]], rtol=0, atol=1e-12)
    assert np.allclose(got[:, 7:10], [INIT["roll"], INIT["pitch"], INIT["yaw"]], rtol=0, atol=1e-12)
    # The same data on the rotating Earth misses the Earth rate: attitude drifts.
    wgs = refs("lab")
    assert np.max(np.abs(wgs[:, 9] - INIT["yaw"])) > 1e-6


def test_vertical_hold(option_runs, refs) -> None:
    got = _ok(option_runs, "hold")
    assert_bitwise(got, refs(vertical="hold"), "--vertical hold")
    assert np.all(got[:, 3] == INIT["h"]), "height column is not constant under --vertical hold"
    assert np.all(got[:, 6] == INIT["vd"]), "vd column is not constant under --vertical hold"
    free = refs()
    assert np.max(np.abs(free[:, 3] - INIT["h"])) > 1e-3, "test motion should move vertically when free"


@pytest.mark.parametrize("name, kind", [("rates-default", "averaged"), ("rates-sampled", "sampled")])
def test_input_rates(option_runs, refs, name: str, kind: str) -> None:
    got = _ok(option_runs, name)
    assert_bitwise(got, refs("rates", imu_rates=kind), name)
    # Rows before the initial t are ignored.
    tr, wr, fr = dynamic_rates()
    keep = tr >= INIT["t"]
    assert_bitwise(got, navigate(tr[keep], wr[keep], fr[keep], data="rates", imu_rates=kind), f"{name}, early rows dropped")
    inc = refs()
    assert got.shape == inc.shape
    assert np.array_equal(got[:, 0], inc[:, 0])
    if kind == "averaged":
        # rate * dt = increment: the increments solution to round-off.
        assert np.allclose(got, inc, rtol=0, atol=1e-9)
    else:
        assert differs(got, refs("rates", imu_rates="averaged"))
        assert not np.allclose(got, inc, rtol=0, atol=1e-9)


def test_extra_and_reordered_columns_with_timing(option_runs, refs) -> None:
    proc, _ = option_runs["explicit-defaults-timing"]
    got = _ok(option_runs, "explicit-defaults-timing")
    assert_bitwise(got, refs(), "reordered columns with extra ones, every default spelled out")
    lines = timing_lines(proc)
    assert len(lines) == 1, proc.stderr
    m = TIMING_RE.match(lines[0])
    assert m, f"timing line does not match: {lines[0]!r}"
    assert int(m.group(1)) == N_DYN


def test_solution_text_is_round_trip(option_runs) -> None:
    """Every float written is the shortest text that parses back to the same double."""
    for name, (proc, out) in option_runs.items():
        assert proc.returncode == 0, f"{name}: {proc.stderr}"
        lines = out.read_text(encoding="utf-8").splitlines()
        assert lines[0] == SOLUTION_HEADER, name
        for line in lines[1:]:
            for cell in line.split(","):
                assert_shortest_round_trip(cell, f"{name}: ")


def test_no_timing_line_without_option(option_runs) -> None:
    for name, (proc, _) in option_runs.items():
        if name != "explicit-defaults-timing":
            assert not timing_lines(proc), f"{name}: {proc.stderr}"


@pytest.mark.parametrize(
    "args, option",
    [
        (["--samples", "0"], "--samples"),
        (["--samples", "7"], "--samples"),
        (["--samples", "two"], "--samples"),
        (["--order", "5"], "--order"),
        (["--attitude", "euler"], "--attitude"),
        (["--earth", "flat"], "--earth"),
        (["--input", "raw"], "--input"),
        (["--imu-rates", "mean"], "--imu-rates"),
        (["--vertical", "fixed"], "--vertical"),
        (["--orthonormalize-every", "-1"], "--orthonormalize-every"),
    ],
)
def test_bad_option_values_rejected(tmp_path: Path, args: list[str], option: str) -> None:
    imu, init, out = tmp_path / "IMU.csv", tmp_path / "INIT.json", tmp_path / "NAV.csv"
    write_increments(imu, *dynamic_increments())
    write_init(init)
    proc = run_mavins("nav", imu, "--init", init, "-o", out, *args)
    assert proc.returncode == 2, proc.stderr
    assert "usage:" in proc.stderr and option in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists()


# --- bad files ----------------------------------------------------------------

BAD_N = 8  # data rows t = 0.01 .. 0.08, lines 2 .. 9


def _good_imu_lines() -> list[str]:
    m = stationary(INIT["lat"], INIT["h"], INIT["roll"], INIT["pitch"], INIT["yaw"], DT, BAD_N)
    lines = [",".join(files.INCREMENT_COLUMNS)]
    for i in range(BAD_N):
        lines.append(",".join(repr(float(x)) for x in [m.t[i], *m.dtheta[i], *m.dv[i]]))
    return lines


def _set_cell(lines: list[str], line_no: int, column: str, text: str) -> list[str]:
    lines = list(lines)
    cells = lines[line_no - 1].split(",")
    cells[files.INCREMENT_COLUMNS.index(column)] = text
    lines[line_no - 1] = ",".join(cells)
    return lines


def _drop_column(lines: list[str], column: str) -> list[str]:
    j = files.INCREMENT_COLUMNS.index(column)
    return [",".join(c for k, c in enumerate(line.split(",")) if k != j) for line in lines]


def _imu_case(lines: list[str] | None):
    return "\n".join(lines) + "\n" if lines is not None else None


GOOD = _good_imu_lines()
T = [line.split(",")[0] for line in GOOD]  # T[k] = the t text on line k + 1

# name -> (IMU text or None = no file, init text or None = default init, extra args,
#          which file the message names, [(line, column)] or a list of words the message must contain)
BAD_CASES = {
    "missing column": (_imu_case(_drop_column(GOOD, "dv_y")), None, [], "imu", ["line 1", "dv_y"]),
    "missing column t": (_imu_case(_drop_column(GOOD, "t")), None, [], "imu", ["line 1", "t"]),
    "rates columns absent": (_imu_case(GOOD), None, ["--input", "rates"], "imu", ["line 1", "gyro_x"]),
    "non-numeric": (_imu_case(_set_cell(GOOD, 5, "dv_y", "abc")), None, [], "imu", ["line 5", "dv_y", "abc"]),
    "short row": (_imu_case(GOOD[:3] + [GOOD[3].rsplit(",", 1)[0]] + GOOD[4:]), None, [], "imu", ["line 4", "dv_z"]),
    "repeated time": (_imu_case(_set_cell(GOOD, 6, "t", T[4])), None, [], "imu", ["line 6", "t"]),
    "backwards time": (_imu_case(_set_cell(GOOD, 6, "t", "0.035")), None, [], "imu", ["line 6", "t"]),
    "nan": (_imu_case(_set_cell(GOOD, 4, "dtheta_z", "nan")), None, [], "imu", ["line 4", "dtheta_z"]),
    "NaN in t": (_imu_case(_set_cell(GOOD, 3, "t", "NaN")), None, [], "imu", ["line 3", "t"]),
    "inf": (_imu_case(_set_cell(GOOD, 7, "dv_x", "inf")), None, [], "imu", ["line 7", "dv_x"]),
    "-inf": (_imu_case(_set_cell(GOOD, 9, "dtheta_y", "-inf")), None, [], "imu", ["line 9", "dtheta_y"]),
    "header only": (_imu_case(GOOD[:1]), None, [], "imu", []),
    "zero-byte file": ("", None, [], "imu", ["line 1"]),
    "missing IMU file": (None, None, [], "imu", []),
    "missing init file": (_imu_case(GOOD), "<none>", [], "init", []),
    "invalid JSON": (_imu_case(GOOD), '{\n  "t": 0.0,\n  "lat": 45.0 "lon": 7.0\n}\n', [], "init", ["line 3", "column 15"]),
    "init not an object": (_imu_case(GOOD), "[0, 45, 7]\n", [], "init", []),
    "init missing key": (_imu_case(GOOD), json.dumps({k: v for k, v in INIT.items() if k != "yaw"}), [], "init", ["yaw"]),
    "init non-numeric": (_imu_case(GOOD), json.dumps({**INIT, "h": "100 m"}), [], "init", ["h"]),
    "init bool": (_imu_case(GOOD), json.dumps({**INIT, "vn": True}), [], "init", ["vn"]),
    "init NaN": (_imu_case(GOOD), json.dumps({**INIT, "lon": float("nan")}), [], "init", ["lon"]),
    "init lat > 90": (_imu_case(GOOD), json.dumps({**INIT, "lat": 90.5}), [], "init", ["lat"]),
    "init lat < -90": (_imu_case(GOOD), json.dumps({**INIT, "lat": -91}), [], "init", ["lat"]),
    "first t equals init t": (_imu_case(GOOD), json.dumps({**INIT, "t": float(T[1])}), [], "imu", ["line 2", "t"]),
    "first t before init t": (_imu_case(GOOD), json.dumps({**INIT, "t": 0.05}), [], "imu", ["line 2", "t"]),
    # Line numbers count the lines of the file: a blank line in the data must not shift
    # them. Skipping the blank line (then: line 9, dv_x) or rejecting it (line 4) are both fine.
    "blank line before a bad value": (
        _imu_case(GOOD[:3] + [""] + _set_cell(GOOD, 8, "dv_x", "nan")[3:]),
        None,
        [],
        "imu",
        (["line 9", "dv_x"], ["line 4"]),
    ),
    "init not UTF-8": (_imu_case(GOOD), None, [], "init", []),  # bytes written below
}


def _word(msg: str, word: str) -> bool:
    return re.search(r"(?<![\w-])" + re.escape(word) + r"(?![\w-])", msg) is not None


def _assert_one_error_line(proc: subprocess.CompletedProcess[str], path: Path, words) -> str:
    """One clean error line naming ``path`` and ``words`` (or one of a tuple of word lists)."""
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = stderr_lines(proc)
    assert len(lines) == 1, f"expected exactly one stderr line, got {len(lines)}:\n{proc.stderr}"
    msg = lines[0]
    assert msg.startswith("mavins nav: error:"), msg
    assert str(path) in msg, f"message does not name {path}: {msg}"
    rest = msg.replace(str(path), "")
    alternatives = words if isinstance(words, tuple) else (words,)
    assert any(all(_word(rest, w) for w in ws) for ws in alternatives), (
        f"message does not say {' or '.join(repr(ws) for ws in alternatives)}: {msg}"
    )
    return msg


@pytest.mark.parametrize("case", list(BAD_CASES))
def test_bad_files(tmp_path: Path, case: str) -> None:
    imu_text, init_text, extra, names, words = BAD_CASES[case]
    imu, init, out = tmp_path / "IMU.csv", tmp_path / "INIT.json", tmp_path / "NAV.csv"
    if imu_text is not None:
        imu.write_text(imu_text, encoding="utf-8")
    if init_text is None:
        write_init(init)
    elif init_text != "<none>":
        init.write_text(init_text, encoding="utf-8")
    if case == "init not UTF-8":
        init.write_bytes(json.dumps({**INIT, "roll": "\u00e9"}, ensure_ascii=False).encode("latin-1"))
    proc = run_mavins("nav", imu, "--init", init, "-o", out, *extra)
    assert proc.returncode == 2, f"exit {proc.returncode}\n{proc.stderr}"
    _assert_one_error_line(proc, imu if names == "imu" else init, words)
    assert not out.exists(), "no solution file is written for unusable input"


def test_invalid_json_position_is_the_decoders(tmp_path: Path) -> None:
    """The line/column in the message are where the JSON breaks (cross-check of the case above)."""
    text = BAD_CASES["invalid JSON"][1]
    with pytest.raises(json.JSONDecodeError) as exc:
        json.loads(text)
    assert (exc.value.lineno, exc.value.colno) == (3, 15)


def test_imu_not_utf8_deep_in_file(tmp_path: Path) -> None:
    """A stray non-UTF-8 byte far into a long file (past the header's read buffer)."""
    m = stationary(INIT["lat"], INIT["h"], INIT["roll"], INIT["pitch"], INIT["yaw"], DT, 400)
    imu, init, out = tmp_path / "IMU.csv", tmp_path / "INIT.json", tmp_path / "NAV.csv"
    write_increments(imu, m.t, m.dtheta, m.dv)
    with open(imu, "ab") as fh:
        fh.write(b"4.01,\xe9,0,0,0,0,0\n")
    write_init(init)
    proc = run_mavins("nav", imu, "--init", init, "-o", out)
    assert proc.returncode == 2, f"exit {proc.returncode}\n{proc.stderr}"
    _assert_one_error_line(proc, imu, ["line 402"])


def test_unwritable_output_is_a_clean_error(tmp_path: Path) -> None:
    imu, init = tmp_path / "IMU.csv", tmp_path / "INIT.json"
    imu.write_text("\n".join(GOOD) + "\n", encoding="utf-8")
    write_init(init)
    blocker = tmp_path / "not_a_dir"
    blocker.write_text("", encoding="utf-8")
    out = blocker / "NAV.csv"
    proc = run_mavins("nav", imu, "--init", init, "-o", out)
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = stderr_lines(proc)
    assert len(lines) == 1 and lines[0].startswith("mavins nav: error:"), proc.stderr
    assert str(out) in lines[0] or str(blocker) in lines[0], lines[0]


# --- help and start-up ----------------------------------------------------------


def test_top_level_help() -> None:
    proc = run_mavins("--help")
    assert proc.returncode == 0, proc.stderr
    assert "nav" in proc.stdout
    assert proc.stdout.startswith("usage: mavins")


def test_python_m_mavins_cli_works() -> None:
    proc = subprocess.run([sys.executable, "-m", "mavins.cli", "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "nav" in proc.stdout


def test_nav_help_mentions_every_option() -> None:
    proc = run_mavins("nav", "--help")
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout
    for opt in CONTRACT_OPTIONS:
        assert _word(text, opt), f"'mavins nav --help' does not mention {opt}"
    for choice in CONTRACT_CHOICES:
        assert _word(text, choice), f"'mavins nav --help' does not mention {choice}"


def test_help_does_not_import_heavy_modules() -> None:
    code = (
        "import sys, json, contextlib, io\n"
        "import mavins.cli\n"
        "mavins.cli.build_parser()\n"
        "seen = {'build_parser': [m for m in %r if m in sys.modules]}\n"
        "for argv in (['--help'], ['nav', '--help']):\n"
        "    with contextlib.redirect_stdout(io.StringIO()):\n"
        "        try:\n"
        "            mavins.cli.main(argv)\n"
        "        except SystemExit:\n"
        "            pass\n"
        "    seen[' '.join(argv)] = [m for m in %r if m in sys.modules]\n"
        "print(json.dumps(seen))\n"
    ) % (HEAVY_MODULES, HEAVY_MODULES)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    seen = json.loads(proc.stdout)
    assert seen == {"build_parser": [], "--help": [], "nav --help": []}, seen
