"""The error analysis in a Rerun recording (``mavins analyze`` writes DIR/analysis.rrd).

Entities (timeline ``time``, seconds from the scenario start), each with three
scalars north, east, down:

* ``/analysis/covariance/position`` (m), ``.../velocity`` (m/s),
  ``.../attitude`` (deg): the covariance's 1-sigma;
* ``/analysis/montecarlo/...``: the Monte Carlo runs' sample sigma, the same units.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

QUANTITIES = (("position", slice(0, 3)), ("velocity", slice(3, 6)), ("attitude", slice(6, 9)))


def write_analysis(path: Path, t: np.ndarray, covariance: np.ndarray, montecarlo: np.ndarray) -> None:
    """Write the two (n, 9) sigma tables (SIGMA_COLUMNS order: m, m/s, deg) at times t (s) to a .rrd file."""
    import rerun as rr

    rec = rr.RecordingStream("mavins_analyze")
    rec.set_sinks(rr.FileSink(str(path)))
    rec.set_log_time_enabled(False)
    index = [rr.TimeColumn("time", duration=np.asarray(t, dtype=float) - float(t[0]))]
    for kind, table in (("covariance", covariance), ("montecarlo", montecarlo)):
        for name, cols in QUANTITIES:
            rec.send_columns(f"/analysis/{kind}/{name}", indexes=index,
                             columns=rr.Scalars.columns(scalars=np.ascontiguousarray(table[:, cols])))
    rec.flush(timeout_sec=10.0)
    rec.disconnect()
