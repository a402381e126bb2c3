"""The Earth's main magnetic field at a position and date: the World Magnetic Model.

Declination D, inclination I and intensity F as the World Magnetic Model
(NOAA NCEI / BGS, WMM2025 technical report, eqs. 1-19: the spherical-harmonic
synthesis of degree 12 with its secular variation, on the WGS-84 ellipsoid)
gives them, computed by the ``pygeomag`` package, which ships the official
coefficient files (WMM2010, WMM2015, WMM2020, WMM2025; MIT licence, no network
access). The release whose five-year span holds the date is used; a date before
2010 or from 2030 on is extrapolated with the nearest release (its secular
variation) and flagged ``extrapolated``. docs/conventions.md "Magnetic field".
"""

from __future__ import annotations

import datetime as _dt
import functools
import math
from typing import NamedTuple

FIRST_YEAR, END_YEAR = 2010.0, 2030.0  # the span the shipped releases cover


class MagField(NamedTuple):
    """The main field at one point: angles in degrees (D east of true north, I below the
    horizontal), components in nT (north, east, down), the release that gave them."""

    declination: float
    inclination: float
    intensity: float
    north: float
    east: float
    down: float
    model: str
    extrapolated: bool


@functools.lru_cache(maxsize=8)
def _model(release_year: float):  # type: ignore[no-untyped-def]
    from pygeomag import GeoMag

    return GeoMag(base_year=release_year)


def _release(year: float) -> float:
    """The first year of the five-year release that covers ``year`` (clamped to the shipped ones)."""
    y = min(max(year, FIRST_YEAR), END_YEAR - 1e-6)
    return float(int((y - FIRST_YEAR) // 5.0) * 5 + FIRST_YEAR)


def field_at(lat_deg: float, lon_deg: float, h_m: float, year: float) -> MagField:
    """The World Magnetic Model's field at geodetic latitude/longitude (deg), ellipsoidal
    height (m) and decimal year. Raises ValueError for a latitude outside [-90, 90] or a
    value that is not finite."""
    if not all(math.isfinite(v) for v in (lat_deg, lon_deg, h_m, year)) or abs(lat_deg) > 90.0:
        raise ValueError(f"no magnetic field at lat {lat_deg!r}, lon {lon_deg!r}, h {h_m!r} m, year {year!r}")
    lon = (lon_deg + 180.0) % 360.0 - 180.0
    release = _release(year)
    gm = _model(release)
    r = gm.calculate(glat=float(lat_deg), glon=float(lon), alt=float(h_m) / 1000.0, time=float(year),
                     allow_date_outside_lifespan=True)
    outside = not FIRST_YEAR <= year < END_YEAR
    return MagField(float(r.d), float(r.i), float(r.f), float(r.x), float(r.y), float(r.z), str(gm.model), outside)


def decimal_year(unix_s: float) -> float:
    """A UNIX time (s, UTC) as a decimal year: the year plus the elapsed fraction of it
    (the WMM's time argument; 2025-07-02 12:00 is 2025.5)."""
    t = _dt.datetime.fromtimestamp(float(unix_s), tz=_dt.timezone.utc)
    start = _dt.datetime(t.year, 1, 1, tzinfo=_dt.timezone.utc)
    end = _dt.datetime(t.year + 1, 1, 1, tzinfo=_dt.timezone.utc)
    return t.year + (t - start).total_seconds() / (end - start).total_seconds()


def this_year() -> float:
    """Today's date (the system clock, UTC, at 00:00: one value all day, so that a live run and its
    replay on the same day agree to the bit) as a decimal year."""
    now = _dt.datetime.now(tz=_dt.timezone.utc)
    return decimal_year(_dt.datetime(now.year, now.month, now.day, tzinfo=_dt.timezone.utc).timestamp())


UNIX_2000 = 946684800.0  # s: 2000-01-01T00:00:00Z; an earlier 'UNIX time' is a clock since boot
UNIX_2100 = 4102444800.0  # s: 2100-01-01T00:00:00Z


def plausible_unix(unix_s: float) -> bool:
    """Whether a time (s) can be a UNIX date of a recording (2000 to 2100), not a boot clock."""
    return math.isfinite(unix_s) and UNIX_2000 <= unix_s < UNIX_2100
