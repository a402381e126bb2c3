"""The one place that imports pymavlink: MAVLink 2, common dialect (CONVENTIONS.md)."""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402  (MAVLINK20 must be set before this import)
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

mavutil.set_dialect("common")

__all__ = ["mavlink", "mavutil"]
