"""GPS time against UTC: the one place the GPS epoch and the leap seconds are written.

GPS time counts from 1980-01-06T00:00:00Z in weeks of 604800 s and does not
take leap seconds: since 2017-01-01 it runs 18 s ahead of UTC (IS-GPS-200,
20.3.3.5.2.4; IERS Bulletin C). MAVLink carries it as a week number and the
milliseconds of that week (GPS_INPUT ``time_week``, ``time_week_ms``); ArduPilot
logs it as ``GWk`` and ``GMS``.
"""

from __future__ import annotations

import math

GPS_EPOCH_UNIX_S = 315964800.0  # s: 1980-01-06T00:00:00Z, the start of GPS week 0
GPS_LEAP_S = 18.0  # s: GPS - UTC since 2017-01-01 (IERS Bulletin C)
WEEK_S = 604800.0  # s in a GPS week


def gps_week_ms(unix_s: float) -> tuple[int, int]:
    """GPS week and millisecond of week of a UTC instant (UNIX s): ``g = unix - epoch + leap``,
    ``week = floor(g / WEEK_S)``, ``ms = round((g - week WEEK_S) 1000)`` (a rounding to the next week's
    first millisecond carries into the week)."""
    g = unix_s - GPS_EPOCH_UNIX_S + GPS_LEAP_S
    week = int(g // WEEK_S)
    ms = int(round((g - week * WEEK_S) * 1000.0))
    if ms >= int(WEEK_S * 1000):
        week, ms = week + 1, ms - int(WEEK_S * 1000)
    return week, ms


def unix_of_gps(week: float, ms_of_week: float) -> float:
    """The UTC instant (UNIX s) of a GPS week and millisecond of week; NaN if either is unknown
    (not finite, or week 0 and below: no time)."""
    if not (math.isfinite(week) and math.isfinite(ms_of_week)) or week <= 0:
        return math.nan
    return GPS_EPOCH_UNIX_S + week * WEEK_S + ms_of_week * 1e-3 - GPS_LEAP_S
