"""The one place that imports pymavlink: MAVLink 2, ardupilotmega dialect (common plus ArduPilot's messages; docs/conventions.md)."""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402  (MAVLINK20 must be set before this import)
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

mavutil.set_dialect("ardupilotmega")

__all__ = ["mavlink", "mavutil", "parser"]


def parser() -> mavlink.MAVLink:
    """A MAVLink 2 parser that reports bad frames as BAD_DATA instead of raising."""
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    return p
