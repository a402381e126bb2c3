"""The smoother on the live path (``mavins replay --smooth``): what the forward run keeps, in temporary files.

:class:`EpochLog` holds the filter's epochs (core/smoother.py's store rows), :class:`KeptRows` the output
rows and the epoch each was written after; :meth:`KeptRows.smooth` runs the backward pass
(smoother.backward) and corrects the rows (aided.smooth_rows) once the run is over. Both append to
unlinked temporary files (TMPDIR) as the run goes, so a long log keeps neither in memory.
"""

from __future__ import annotations

import math
import tempfile
from array import array

import numpy as np

from ..core import aided, smoother


class EpochLog:
    """The smoother's epochs of one live run over the ``active`` states, appended as they come;
    :meth:`store` maps them back. ``generation`` counts the filter's starts (and resets)."""

    def __init__(self, active: np.ndarray, generation: int = 0) -> None:
        self.active = np.ascontiguousarray(active, dtype=np.int64)
        self.generation = generation
        self.count = 0
        self.t_last = -math.inf
        self._row = np.zeros((1, smoother.store_width(self.active.shape[0])))
        self._fh = tempfile.TemporaryFile(prefix="mavins-epochs-")

    def record(self, t: float, Pm: np.ndarray, Pp: np.ndarray, acc: np.ndarray, dx: np.ndarray) -> None:
        """One epoch at t (s): P^-, P^+, the correction dx (NX) and the transition chained in ``acc``'s
        tail since the epoch before (restarted here)."""
        smoother.record(self._row, 0, t, self.count, Pm, Pp, acc[aided.ACC_SIZE:], dx, self.active)
        self._fh.write(self._row.tobytes())
        self.count += 1
        self.t_last = t

    def store(self) -> np.ndarray:
        """The epochs so far as one (count, width) array backed by the file, writable (the backward pass
        works in place)."""
        self._fh.flush()
        if self.count == 0:
            return np.zeros((0, self._row.shape[1]))
        return aided.mapped(self._fh, (self.count, self._row.shape[1]))


class KeptRows:
    """Output rows (kernel units, aided.ROW_SIZE: the solution and every filter column) kept for the
    smoother, each with the epoch log's generation and count when it was written."""

    def __init__(self) -> None:
        self.count = 0
        self._fh = tempfile.TemporaryFile(prefix="mavins-rows-")
        self._ref = array("q")
        self._gen = array("q")

    def add(self, row: np.ndarray, epochs: EpochLog | None) -> None:
        self._fh.write(np.ascontiguousarray(row, dtype=np.float64).tobytes())
        self._ref.append(0 if epochs is None else epochs.count)
        self._gen.append(-1 if epochs is None else epochs.generation)
        self.count += 1

    def smooth(self, epochs: EpochLog | None) -> tuple[np.ndarray, int]:
        """The rows smoothed over the last generation's epochs (rows of an earlier one, before a restart,
        keep the forward values), as a file-backed (count, ROW_SIZE) array in kernel units; and the number
        of epochs whose prior could not be inverted (smoother.backward)."""
        self._fh.flush()
        if self.count == 0:
            return np.zeros((0, aided.ROW_SIZE)), 0
        rows = aided.mapped(self._fh, (self.count, aided.ROW_SIZE))
        if epochs is None or epochs.count < 2:
            return rows, 0
        store = epochs.store()
        bad = smoother.backward(store, epochs.count, epochs.active.shape[0])
        gen = np.frombuffer(self._gen, dtype=np.int64)
        row_epoch = np.where(gen == epochs.generation, np.frombuffer(self._ref, dtype=np.int64), 0)
        aided.smooth_rows(rows, self.count, np.ascontiguousarray(row_epoch), store, epochs.count, epochs.active)
        return rows, int(bad)
