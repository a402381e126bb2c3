"""``mavins nav``: the strapdown solution from files (CONVENTIONS.md "Command line")."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

from . import files


@dataclass(frozen=True)
class NavOptions:
    """Options of ``mavins nav``, named as on the command line."""

    input: str = "increments"
    samples: int = 2
    no_coning: bool = False
    attitude: str = "quaternion"
    order: str = "exact"
    earth: str = "wgs84"
    orthonormalize_every: int = 1
    vertical: str = "free"
    imu_rates: str = "averaged"
    position: str = "trapezoidal"
    l_every: int = 1
    timing: bool = False


def run_nav(imu_path: Path, init_path: Path, out_path: Path, opts: NavOptions) -> int:
    """Read the IMU file and initial state, integrate, write the solution.

    Returns the number of solution rows written. Raises files.DataFileError
    for unusable input.
    """
    t_start = time.perf_counter()
    init = files.read_init(init_path)
    columns = files.INCREMENT_COLUMNS if opts.input == "increments" else files.RATE_COLUMNS
    table = files.read_table(imu_path, columns)
    if opts.input == "increments" and table[0, 0] <= init.t:
        raise files.DataFileError(
            f"{imu_path}: line 2, column 't': first increment time {table[0, 0]!r} is not after the "
            f"initial state's t = {init.t!r} (row i covers (t[i-1], t[i]])"
        )
    t_read = time.perf_counter()

    from .core.runner import navigate

    sol = navigate(
        table[:, 0],
        table[:, 1:4],
        table[:, 4:7],
        init.to_dict(),
        data=opts.input,
        samples=opts.samples,
        attitude=opts.attitude,
        order=opts.order,
        earth_model=opts.earth,
        orthonormalize_every=opts.orthonormalize_every,
        vertical=opts.vertical,
        coning=not opts.no_coning,
        position=opts.position,
        l_every=opts.l_every,
        imu_rates=opts.imu_rates,
    )
    t_compute = time.perf_counter()
    try:
        out_path.parent.mkdir(parents=True, exist_ok=True)
        files.write_table(out_path, files.SOLUTION_COLUMNS, sol)
    except OSError as exc:
        raise files.DataFileError(f"{out_path}: cannot write: {exc.strerror or exc}") from None
    t_write = time.perf_counter()
    if opts.timing:
        print(
            f"timing: samples={table.shape[0]} read_s={t_read - t_start:.3f} "
            f"compute_s={t_compute - t_read:.3f} write_s={t_write - t_compute:.3f}",
            file=sys.stderr,
        )
    return sol.shape[0]
