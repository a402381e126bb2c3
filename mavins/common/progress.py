"""A small progress bar on stderr for long jobs (silent when stderr is not a terminal)."""

from __future__ import annotations

import sys
import time


class Progress:
    """``with Progress("simulate", total) as p: p.update(done)``; prints only on a TTY."""

    def __init__(self, label: str, total: float, unit: str = "") -> None:
        self.label = label
        self.total = max(float(total), 1e-12)
        self.unit = unit
        self.enabled = sys.stderr.isatty()
        self.t0 = time.monotonic()
        self._last = 0.0

    def __enter__(self) -> "Progress":
        return self

    def update(self, done: float) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.1 and done < self.total:
            return
        self._last = now
        frac = min(done / self.total, 1.0)
        bar = "#" * int(30 * frac)
        eta = (now - self.t0) * (1 - frac) / frac if frac > 0 else 0.0
        sys.stderr.write(f"\r{self.label} [{bar:<30}] {100 * frac:5.1f}% eta {eta:5.1f} s")
        sys.stderr.flush()

    def __exit__(self, *exc: object) -> None:
        if self.enabled:
            sys.stderr.write(f"\r{self.label} done in {time.monotonic() - self.t0:.1f} s{' ' * 40}\n")
            sys.stderr.flush()
