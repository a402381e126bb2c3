"""``mavins nav``: the strapdown solution from files (docs/conventions.md "Command line")."""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .common import files
from .common.fleet import Outcome, batch_outputs, write_summary
from .core.settings import Strapdown


@dataclass(frozen=True)
class NavOptions:
    """Options of ``mavins nav``: what the file holds, the strapdown settings, --timing."""

    input: str = "increments"
    strapdown: Strapdown = field(default_factory=Strapdown)
    timing: bool = False


SOLUTION_ROW_BYTES = 14 * 21  # typical text of one solution row (17 significant digits, commas)
PIECE_ROWS = 1 << 17  # IMU rows integrated per kernel call: the writer formats one piece while the next runs


def run_nav(imu_path: Path, init_path: Path, out_path: Path, opts: NavOptions) -> int:
    """Read the IMU file and initial state, integrate, write the solution.

    The file is read, integrated and written in pieces of rows with one kernel
    state carried across them (bit-identical to a whole-array run), so memory
    stays flat however long the file is. Three things overlap: numba loads the
    kernel from its cache while pyarrow parses the file, and a writer thread
    formats each piece of the solution while the next piece is integrated
    (pyarrow releases the GIL). The solution goes to a temporary file beside
    ``out_path``, renamed into place only when the whole file was good.
    Returns the number of solution rows written. Raises files.DataFileError
    for unusable input (or an output that is also an input) and
    files.ResourceError when the solution would not fit on the disk.

    ``--timing`` reports the main thread's seconds: ``read_s`` parsing,
    ``compute_s`` integrating (and waiting for the kernel), ``write_s``
    waiting for the writer and the final flush and rename.
    """
    from concurrent.futures import Future, ThreadPoolExecutor

    from .core import strapdown as sd
    from .core.runner import initial_state

    t_start = time.perf_counter()
    files.check_outputs({"-o": out_path}, {"IMU": imu_path, "--init": init_path})
    init = files.read_init(init_path)
    columns = files.INCREMENT_COLUMNS if opts.input == "increments" else files.RATE_COLUMNS
    reader = files.TableReader(imu_path, columns)
    est_rows = reader.estimated_rows() // opts.strapdown.samples
    files.check_resources(f"the solution ({est_rows:,} rows, estimated)", disk=est_rows * SOLUTION_ROW_BYTES,
                          disk_at=out_path.parent)
    cfg = sd.make_config(**opts.strapdown.keywords())
    run = sd.run_increments if opts.input == "increments" else sd.run_rates
    state = initial_state(init.to_dict())
    t_read = time.perf_counter() - t_start
    t_compute = t_write = 0.0
    rows = 0
    # the pool is left first: it waits for the writer before atomic_output renames or removes the file
    with files.atomic_output(out_path) as tmp, ThreadPoolExecutor(2, thread_name_prefix="mavins-nav") as pool:
        none = np.empty((0, 7))  # no rows, as views of a table: only loads (or compiles) the kernel run calls
        loading = pool.submit(run, state.copy(), cfg, none[:, 0], none[:, 1:4], none[:, 4:7], np.empty((1, sd.OUT_SIZE)))
        # two solution buffers, taken in turn: the writer formats one while the kernel fills the other
        buffers = [np.empty((PIECE_ROWS // opts.strapdown.samples + 1, sd.OUT_SIZE)) for _ in range(2)]
        pieces = 0
        writing: Future | None = None
        t0 = time.perf_counter()
        try:
            with files.TableWriter(tmp, files.SOLUTION_COLUMNS) as writer:
                first = True
                for table in reader.chunks():
                    if first and opts.input == "increments" and table[0, 0] <= init.t:
                        raise files.first_increment_error(imu_path, table[0, 0], init.t)
                    first = False
                    t1 = time.perf_counter()
                    t_read += t1 - t0
                    loading.result()
                    for a in range(0, table.shape[0], PIECE_ROWS):
                        piece = table[a:a + PIECE_ROWS]
                        out = buffers[pieces % 2]  # not the one the writer may still hold
                        pieces += 1
                        m = run(state, cfg, piece[:, 0], piece[:, 1:4], piece[:, 4:7], out)  # views: no copies
                        t2 = time.perf_counter()
                        t_compute += t2 - t1
                        if writing is not None:
                            writing.result()  # one piece in the writer at a time: memory stays flat
                        # the writer thread turns the rows into file units (degrees) and formats them while
                        # the kernel fills the other buffer
                        writing = pool.submit(_write_rows, writer, out[:m])
                        rows += m
                        t1 = time.perf_counter()
                        t_write += t1 - t2
                    t0 = time.perf_counter()
                t_read += time.perf_counter() - t0
                t0 = time.perf_counter()
                if writing is not None:
                    writing.result()
                t_limit = sd.frame_limit(state)
                if t_limit is not None:
                    raise files.DataFileError(
                        f"{imu_path}: the geographic frame cannot navigate beyond |lat| "
                        f"{np.degrees(sd.GEO_LAT_LIMIT):g} deg (reached at t = {t_limit:.6g} s); "
                        "use --frame wander, free or inertial"
                    )
        except OSError as exc:  # the reader turns its own errors into DataFileError: this is the output
            raise files.DataFileError(f"{out_path}: cannot write: {exc.strerror or exc}") from None
    t_write += time.perf_counter() - t0  # flush and rename
    if opts.timing:
        print(
            f"timing: samples={reader.rows} read_s={t_read:.3f} "
            f"compute_s={t_compute:.3f} write_s={t_write:.3f}",
            file=sys.stderr,
        )
    return rows


def _write_rows(writer: "files.TableWriter", rows: np.ndarray) -> None:
    """Solution rows (kernel units) converted in place to file units (degrees: runner.to_file_units) and
    written (the writer thread of run_nav)."""
    from .core.runner import to_file_units

    writer.write(to_file_units(rows, copy=False))


GNSS_REQUIRED = ("t", "lat", "lon", "h")
GNSS_OPTIONAL = ("vn", "ve", "vd", "sigma_h", "sigma_v", "sigma_vel")
BARO_REQUIRED = ("t", "h")
BARO_OPTIONAL = ("sigma",)
MAG_REQUIRED = ("t", "mx", "my", "mz")
MAG_OPTIONAL = ("sigma",)
WHEEL_REQUIRED = ("t", "speed")
WHEEL_OPTIONAL = ("sigma",)


MAG_UNITS = {"gauss": 1e-5, "mgauss": 1e-2, "uT": 1e-3, "nT": 1.0}  # per nT, the magnetic model's unit


@dataclass(frozen=True)
class AidingFiles:
    """The aiding inputs of ``mavins nav``: files (None = not given), the magnetic declination (deg, east
    positive; None: the World Magnetic Model's at the initial position on ``year``, a decimal year,
    None: today), the rest intervals ``(start, end)`` (s, sensor time)."""

    gnss: Path | None = None
    baro: Path | None = None
    mag: Path | None = None
    declination: float | None = None
    rest: tuple[tuple[float, float], ...] = ()
    year: float | None = None
    delays: dict[str, float] = field(default_factory=dict)  # s by kind (gnss, baro, mag): measured before the t column
    mag_bias: float = 0.0  # initial 1-sigma of the magnetometer's hard iron (the file's unit); 0: not estimated
    scale_factors: bool = False  # estimate the grade's (or the spec's) gyro and accelerometer scale factors
    mag_unit: str | None = None  # the magnetometer file's unit (MAG_UNITS), None: not known
    misalignment: bool = False  # estimate the grade's (or the spec's) gyro and accelerometer misalignments
    smooth: bool = False  # write the fixed-interval smoothed solution instead of the forward filter's
    wheel: Path | None = None  # a wheel odometer's forward speed: t,speed [,sigma] (m/s)
    wheel_lever_arm: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, body FRD: the odometer's axle centre
    wheel_scale: float | None = None  # its scale factor's initial 1-sigma (dimensionless; None: aided's default)
    wheel_sigma: float | None = None  # m/s: the speed noise of rows without a sigma (None: aided's default)
    nhc: float = 0.0  # m/s: the non-holonomic constraint's sigma; 0: not applied

    def field_at(self, lat_deg: float, lon_deg: float, h_m: float) -> dict[str, float | None]:
        """navigate_aided's magnetic keywords at the initial position: the declination (deg), the given one
        else the model's; the model's inclination (deg) and, with ``mag_unit``, its strength and the strength
        check in that unit. No model figures with a given declination: a file's field is the user's to state
        (it may be synthetic), where the live path's is the Earth's (docs/filter.md)."""
        if self.declination is not None:
            return {"declination": float(self.declination)}
        from .core import magmodel

        year = self.year if self.year is not None else magmodel.this_year()
        f = magmodel.field_at(lat_deg, lon_deg, h_m, year)
        out: dict[str, float | None] = {"declination": f.declination, "mag_inclination": f.inclination}
        if self.mag_unit is not None:
            per_nt = MAG_UNITS[self.mag_unit]
            out["mag_strength"] = f.intensity * per_nt
            from .core.aided import MAG_STRENGTH_GATE

            out["mag_strength_gate"] = MAG_STRENGTH_GATE / MAG_UNITS["gauss"] * per_nt  # gauss -> nT -> the file's
        return out


def rest_windows(rest: tuple[tuple[float, float], ...]) -> np.ndarray | None:
    """``--rest`` intervals sorted by start, as core/aided.py's static rows ``t0, t1``; overlapping ones are
    refused (ValueError naming both)."""
    if not rest:
        return None
    ordered = sorted(rest)
    for (a0, a1), (b0, b1) in zip(ordered, ordered[1:]):
        if b0 < a1:
            raise ValueError(f"--rest {a0:g},{a1:g} and --rest {b0:g},{b1:g} overlap")
    return np.array(ordered, dtype=float)


def read_aiding(path: Path, required: tuple[str, ...], optional: tuple[str, ...],
                no_fix_rows: bool = False) -> np.ndarray:
    """A GNSS or baro file (docs/conventions.md "Aided navigation"): the required columns, then
    the optional ones (NaN where absent or empty), rows sorted by t. With ``no_fix_rows`` (GNSS)
    the required columns after t may be empty or NaN too: such a row is no fix."""
    try:
        with open(path, encoding="utf-8") as fh:
            header = [c.strip() for c in fh.readline().strip().split(",")]
    except (OSError, UnicodeDecodeError) as exc:
        raise files.DataFileError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    missing = [c for c in required if c not in header]
    if missing:
        raise files.DataFileError(f"{path}: missing column(s) {', '.join(missing)} (header: {','.join(header)})")
    cols = required + tuple(c for c in optional if c in header)
    strict = cols == required and not no_fix_rows  # the fast reader refuses empty and NaN cells
    if strict:
        data = files.read_table(path, required, strictly_increasing=False)
    else:
        may_be_empty = set(optional) | (set(required[1:]) if no_fix_rows else set())
        data = _aiding_rows(path, header, cols, may_be_empty)
    if data.shape[0] and np.any(np.diff(data[:, 0]) < 0.0):
        row = int(np.argmax(np.diff(data[:, 0]) < 0.0)) + 3
        raise files.DataFileError(f"{path}: line {row}, column 't': time goes back")
    out = np.full((data.shape[0], len(required) + len(optional)), np.nan)
    for j, c in enumerate(cols):
        out[:, (required + optional).index(c)] = data[:, j]
    return out


def _aiding_rows(path: Path, header: list[str], cols: tuple[str, ...], may_be_empty: set[str]) -> np.ndarray:
    """The columns ``cols`` of an aiding file, row by row: an empty or NaN cell is NaN in the columns
    ``may_be_empty`` (absent measurement, GNSS no fix) and refused elsewhere; any other cell must be a
    finite number, and a row must hold every column of the header (one-line errors, as files.py's)."""
    idx = [header.index(c) for c in cols]
    rows: list[list[float]] = []
    try:
        with open(path, encoding="utf-8") as fh:
            fh.readline()
            for lineno, line in enumerate(fh, start=2):
                if not line.strip():
                    continue
                cells = line.rstrip("\r\n").split(",")
                if len(cells) < len(header):
                    raise files.DataFileError(files.missing_field(path, lineno, header[len(cells)], len(cells)))
                row = []
                for c, j in zip(cols, idx):
                    cell = cells[j].strip()
                    empty = cell == "" or cell.lower() == "nan"
                    try:
                        v = math.nan if empty else float(cell)
                    except ValueError:
                        v = math.inf  # not a number: refused below
                    if not (math.isfinite(v) or (empty and c in may_be_empty)):
                        raise files.DataFileError(files.not_a_number(path, lineno, c, cells[j]))
                    row.append(v)
                rows.append(row)
    except (OSError, UnicodeDecodeError) as exc:
        raise files.DataFileError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    return np.array(rows, dtype=float).reshape(len(rows), len(cols))


def run_nav_aided(imu_path: Path, init_path: Path, out_path: Path, opts: NavOptions, aiding: AidingFiles,
                  spec: str | dict, lever_arm: tuple[float, float, float], gate: float) -> tuple[int, dict]:
    """``mavins nav --gnss/--baro/--mag/--rest``: the strapdown solution with the error-state filter
    (core/aided.py), written with the filter's 21 columns after the 14 solution columns.
    Returns the rows written and the measurement counts (accepted, rejected) by kind.

    ``--timing`` prints the contract's line (``read_s`` the IMU and aiding files, ``compute_s`` the
    aided run, ``write_s`` the solution) followed by ``strapdown_s``, the same samples through the
    free-inertial kernel alone (run once more for the figure), and ``filter_s = compute_s -
    strapdown_s``, the filter's own share."""
    import json

    from .core import aided

    t_start = time.perf_counter()

    if opts.strapdown.frame != "geographic":
        raise ValueError(f"--frame {opts.strapdown.frame}: the filter (--gnss, --baro, --mag, --rest) works in the "
                         "geographic frame only")
    static = rest_windows(aiding.rest)
    files.check_outputs({"-o": out_path}, {"IMU": imu_path, "--init": init_path, "--gnss": aiding.gnss,
                                          "--baro": aiding.baro, "--mag": aiding.mag})
    init = files.read_init(init_path)
    init_keys = init.to_dict()
    try:  # the optional initial uncertainty keys of the initial-state JSON
        raw = json.loads(Path(init_path).read_text())
        for k in ("sigma_pos", "sigma_vel", "sigma_level", "sigma_yaw"):
            if k in raw:
                v = raw[k]
                if not isinstance(v, (int, float)) or isinstance(v, bool) or not 0.0 < v < 1e7:
                    raise files.DataFileError(f"{init_path}: {k} must be a positive number, got {v!r}")
                init_keys[k] = float(v)
    except (OSError, ValueError) as exc:
        if isinstance(exc, files.DataFileError):
            raise
        raise files.DataFileError(f"{init_path}: {exc}") from None
    if opts.input == "rates" and opts.strapdown.imu_rates == "sampled":
        raise files.DataFileError("the filter takes increments or averaged rates; sampled rates are not supported "
                                  "with --gnss/--baro/--mag/--rest")
    columns = files.INCREMENT_COLUMNS if opts.input == "increments" else files.RATE_COLUMNS
    imu = files.read_table(imu_path, columns)
    if opts.input == "rates":
        imu = imu[imu[:, 0] > init.t]
        dt = np.diff(np.concatenate(([init.t], imu[:, 0])))[:, None]
        imu = np.column_stack([imu[:, 0], imu[:, 1:7] * dt])
    gnss = read_aiding(aiding.gnss, GNSS_REQUIRED, GNSS_OPTIONAL, no_fix_rows=True) if aiding.gnss is not None else None
    baro = read_aiding(aiding.baro, BARO_REQUIRED, BARO_OPTIONAL) if aiding.baro is not None else None
    mag = read_aiding(aiding.mag, MAG_REQUIRED, MAG_OPTIONAL) if aiding.mag is not None else None
    wheel = read_aiding(aiding.wheel, WHEEL_REQUIRED, WHEEL_OPTIONAL) if aiding.wheel is not None else None
    if wheel is not None and aiding.wheel_sigma is not None:
        wheel[~np.isfinite(wheel[:, 2]), 2] = aiding.wheel_sigma
    if wheel is not None and np.any(wheel[:, 2] <= 0.0):
        row = int(np.argmax(wheel[:, 2] <= 0.0))
        raise files.DataFileError(f"{aiding.wheel}: line {row + 2}, column 'sigma': must be positive (m/s), got "
                                  f"{float(wheel[row, 2])!r}")
    for kind, table in (("gnss", gnss), ("baro", baro), ("mag", mag)):  # --KIND-delay: measured at t - delay
        if table is not None and aiding.delays.get(kind, 0.0):
            table[:, 0] -= aiding.delays[kind]
    if mag is not None and np.any(mag[:, 4] <= 0.0):
        row = int(np.argmax(mag[:, 4] <= 0.0))
        raise files.DataFileError(f"{aiding.mag}: line {row + 2}, column 'sigma': must be positive (deg of "
                                  f"heading), got {float(mag[row, 4])!r}")
    t_read = time.perf_counter() - t_start
    field = aiding.field_at(init.lat, init.lon, init.h) if mag is not None else {"declination": 0.0}
    if opts.strapdown.earth_model == "none":  # a laboratory has no Earth field to check against
        field = {"declination": field["declination"]}
    try:
        rows, stats = aided.navigate_aided(
            imu, init_keys, gnss, baro, mag=mag, static=static, spec=spec, lever_arm=lever_arm, gate=gate,
            mag_bias=aiding.mag_bias, **field,
            scale_factors=aiding.scale_factors, misalignment=aiding.misalignment, smooth=aiding.smooth,
            wheel=wheel, wheel_lever_arm=aiding.wheel_lever_arm, nhc=aiding.nhc,
            **({} if aiding.wheel_scale is None else {"wheel_scale": aiding.wheel_scale}),
            **{k: v for k, v in opts.strapdown.keywords().items() if k != "imu_rates"})
    except ValueError as exc:
        raise files.DataFileError(str(exc)) from None
    t_compute = time.perf_counter() - t_start - t_read
    with files.atomic_output(out_path) as tmp:
        keep = aided.file_columns(stats["spec"], aiding.mag_bias)
        files.write_table(tmp, tuple(aided.ROW_COLUMNS[i] for i in keep), rows, keep)
    t_write = time.perf_counter() - t_start - t_read - t_compute
    if aiding.smooth:
        from .core.smoother import described

        print(f"mavins nav: {described(stats['epochs'], stats['singular'])}", file=sys.stderr)
    if opts.timing:
        t_sd = _strapdown_seconds(imu, init_keys, opts)
        print(f"timing: samples={imu.shape[0]} read_s={t_read:.3f} compute_s={t_compute:.3f} write_s={t_write:.3f} "
              f"strapdown_s={t_sd:.3f} filter_s={max(t_compute - t_sd, 0.0):.3f}", file=sys.stderr)
    return rows.shape[0], stats["counts"]


def _strapdown_seconds(imu: np.ndarray, init: dict, opts: NavOptions) -> float:
    """Seconds the free-inertial kernel takes over the same increment rows (--timing's strapdown_s)."""
    from .core import strapdown as sd
    from .core.runner import initial_state

    cfg = sd.make_config(**opts.strapdown.keywords())
    state = initial_state(init)
    t, dth, dv = (np.ascontiguousarray(imu[:, a:b]) for a, b in ((0, 1), (1, 4), (4, 7)))
    out = np.empty((imu.shape[0] // opts.strapdown.samples + 1, sd.OUT_SIZE))
    sd.run_increments(state.copy(), cfg, np.empty(0), np.empty((0, 3)), np.empty((0, 3)), out[:1])  # loaded
    t0 = time.perf_counter()
    sd.run_increments(state, cfg, t[:, 0], dth, dv, out)
    return time.perf_counter() - t0


def _batch_job(job: tuple[Path, Path, Path, NavOptions]) -> Outcome:
    """One file of a batch: its outcome (common/fleet.py), with the solution's rows, or the one-line error."""
    imu, init, out, opts = job
    outcome = Outcome(str(imu), str(out))
    try:
        outcome.solution_rows = run_nav(imu, init, out, opts)
    except (files.DataFileError, files.ResourceError, ValueError, OSError) as exc:
        outcome.error = str(exc)
    else:
        outcome.state = "done"
    return outcome


def _warm(opts: NavOptions) -> None:
    """Load or compile the kernel ``run_nav`` will call, on two dummy samples."""
    from .core import strapdown as sd
    from .core.runner import rest_state

    cfg = sd.make_config(**opts.strapdown.keywords())
    run = sd.run_increments if opts.input == "increments" else sd.run_rates
    table = np.zeros((2, 7))  # views of a table, as run_nav passes them
    table[:, 0] = (0.01, 0.02)
    run(rest_state(), cfg, table[:, 0], table[:, 1:4], table[:, 4:7], np.empty((3, sd.OUT_SIZE)))


def run_nav_batch(imu_paths: list[Path], init_path: Path | None, out_dir: Path, opts: NavOptions,
                  jobs: int | None = None, cluster: str | None = None) -> tuple[list[Outcome], Path]:
    """``mavins nav --each``: every IMU file navigated on its own, on ``jobs`` local processes or the Dask
    cluster at ``cluster``, then ``OUT_DIR/summary.csv`` (common/fleet.py).

    Each file's initial state is ``init_path`` or, without it, the ``init.json``
    beside the file (what ``mavins sim`` writes). A bad file does not stop the
    others: its error comes back in its outcome; each solution is written atomically.
    Returns the outcomes, in the order of the files, and the summary's path.
    """
    from .common.parallel import run_jobs

    outs = batch_outputs(imu_paths, out_dir)
    inits = [init_path if init_path is not None else p.parent / "init.json" for p in imu_paths]
    for imu, out in zip(imu_paths, outs):
        files.check_outputs({"-o": out}, {"IMU": imu})
    _warm(opts)  # compiled (or loaded) once here; the forked workers inherit it
    jobs_list = [(imu, init, out, dataclasses.replace(opts, timing=False))
                 for imu, init, out in zip(imu_paths, inits, outs)]
    outcomes = run_jobs(_batch_job, jobs_list, jobs=min(jobs or len(jobs_list), len(jobs_list)), cluster=cluster,
                        label="mavins nav --each")
    return outcomes, write_summary(out_dir, outcomes)
