"""The Earth's magnetic field (mavins/core/magmodel.py) against the World Magnetic Model's own test values.

Expected values: NOAA NCEI / BGS, "The US/UK World Magnetic Model for 2025-2030: test values"
(WMM2025testvalues.pdf, published with the WMM2025 coefficients): decimal year, height above the
WGS-84 ellipsoid (km), geodetic latitude and longitude (deg), and the field's north X, east Y and
down Z components (nT, printed to 0.1 nT) and declination D (deg, printed to 0.01 deg). A right
answer is within half the last printed digit: 0.05 nT and 0.005 deg.
"""

from __future__ import annotations

import math

import pytest

from mavins.core import magmodel

NT_TOL = 0.05  # half of the printed 0.1 nT
DEG_TOL = 0.005  # half of the printed 0.01 deg

# year, h (km), lat, lon, X, Y, Z (nT), D (deg)
WMM2025_TEST_VALUES = (
    (2025.0, 0.0, 80.0, 0.0, 6521.6, 145.9, 54791.5, 1.28),
    (2025.0, 0.0, 0.0, 120.0, 39677.8, -109.6, -10580.2, -0.16),
    (2025.0, 0.0, -80.0, 240.0, 6117.5, 15751.9, -52022.5, 68.78),
    (2025.0, 100.0, 80.0, 0.0, 6216.0, 92.4, 52598.8, 0.85),
    (2025.0, 100.0, 0.0, 120.0, 37688.6, -96.2, -10152.1, -0.15),
    (2025.0, 100.0, -80.0, 240.0, 5907.6, 14780.3, -49540.7, 68.21),
    (2027.5, 0.0, 80.0, 0.0, 6500.8, 294.5, 54869.4, 2.59),
    (2027.5, 0.0, 0.0, 120.0, 39701.6, -167.4, -10381.8, -0.24),
    (2027.5, 0.0, -80.0, 240.0, 6200.7, 15730.3, -51783.7, 68.49),
    (2027.5, 100.0, 80.0, 0.0, 6196.7, 233.8, 52670.5, 2.16),
    (2027.5, 100.0, 0.0, 120.0, 37711.5, -148.7, -9969.8, -0.23),
    (2027.5, 100.0, -80.0, 240.0, 5984.0, 14760.1, -49317.7, 67.93),
)


@pytest.mark.parametrize("year,h_km,lat,lon,x,y,z,d", WMM2025_TEST_VALUES)
def test_field_matches_the_published_test_values(year, h_km, lat, lon, x, y, z, d) -> None:
    """Components and declination at each published point (longitude 240 is -120: wrapped), the
    inclination and intensity as the components give them (I = atan2(Z, hypot(X, Y)), F = |B|)."""
    f = magmodel.field_at(lat, lon, h_km * 1000.0, year)
    assert abs(f.north - x) <= NT_TOL and abs(f.east - y) <= NT_TOL and abs(f.down - z) <= NT_TOL, f
    assert abs(f.declination - d) <= DEG_TOL, f
    # the printed components are good to 0.05 nT: I and F follow from them to ~1e-5 deg and 0.1 nT
    assert abs(f.inclination - math.degrees(math.atan2(z, math.hypot(x, y)))) <= 1e-3
    assert abs(f.intensity - math.sqrt(x * x + y * y + z * z)) <= 0.1
    assert f.model == "WMM-2025" and not f.extrapolated


def test_each_date_takes_the_release_that_covers_it() -> None:
    """A 2019 flight takes WMM2015 (valid 2015-2020), a 2026 one WMM2025; a date after the last
    release's five years is extrapolated with its secular variation and flagged."""
    assert magmodel.field_at(47.4, 8.5, 500.0, 2019.5).model.startswith("WMM-2015")
    assert magmodel.field_at(47.4, 8.5, 500.0, 2022.0).model == "WMM-2020"
    assert magmodel.field_at(47.4, 8.5, 500.0, 2026.9).model == "WMM-2025"
    late = magmodel.field_at(47.4, 8.5, 500.0, 2031.0)
    assert late.model == "WMM-2025" and late.extrapolated
    early = magmodel.field_at(47.4, 8.5, 500.0, 2005.0)
    assert early.model == "WMM-2010" and early.extrapolated


def test_the_years_each_side_of_the_shipped_releases() -> None:
    """2010.0 is the first release's first day (not extrapolated), 2030.0 the day after the last one's
    five years (extrapolated); the pole itself has a field (D undefined there, I and F not)."""
    assert not magmodel.field_at(47.4, 8.5, 500.0, 2010.0).extrapolated
    assert magmodel.field_at(47.4, 8.5, 500.0, 2030.0).extrapolated
    assert not magmodel.field_at(47.4, 8.5, 500.0, 2029.999).extrapolated
    pole = magmodel.field_at(90.0, 0.0, 0.0, 2025.0)
    assert 80.0 < pole.inclination < 90.0 and 50000.0 < pole.intensity < 60000.0


@pytest.mark.parametrize("zone", ["Etc/GMT-14", "Etc/GMT+12"])
def test_today_is_the_utc_date_whatever_the_local_zone(zone: str) -> None:
    """this_year() counts from today's 00:00 UTC, not the machine's local midnight nor local date: in a zone
    14 h ahead or 12 h behind UTC it is the same number as computed here from the UTC date."""
    import datetime as dt
    import os
    import time

    old = os.environ.get("TZ")
    os.environ["TZ"] = zone
    time.tzset()
    try:
        y = magmodel.this_year()
        today = dt.datetime.now(dt.timezone.utc).date()
    finally:
        if old is None:
            os.environ.pop("TZ", None)
        else:
            os.environ["TZ"] = old
        time.tzset()
    start = dt.date(today.year, 1, 1)
    days = (dt.date(today.year + 1, 1, 1) - start).days
    assert abs(y - (today.year + (today - start).days / days)) < 1e-12


def test_declination_moves_with_the_secular_variation_between_test_dates() -> None:
    """Between the two published dates the model changes by what the published values change by
    (at 80 N, 0 E: D from 1.28 to 2.59 deg in 2.5 years), each within the printed rounding."""
    d0 = magmodel.field_at(80.0, 0.0, 0.0, 2025.0).declination
    d1 = magmodel.field_at(80.0, 0.0, 0.0, 2027.5).declination
    assert abs((d1 - d0) - (2.59 - 1.28)) <= 2 * DEG_TOL


@pytest.mark.parametrize("lat,lon,h,year", [(91.0, 0.0, 0.0, 2026.0), (math.nan, 0.0, 0.0, 2026.0),
                                            (0.0, math.inf, 0.0, 2026.0), (0.0, 0.0, 0.0, math.nan)])
def test_impossible_points_are_refused(lat, lon, h, year) -> None:
    with pytest.raises(ValueError, match="no magnetic field"):
        magmodel.field_at(lat, lon, h, year)


def test_decimal_year_of_unix_times() -> None:
    """2025-01-01T00:00Z is 2025.0 (UNIX 1735689600); 2025-07-02T12:00Z is half of 2025's 365 days
    (1751457600); 2028-07-02T00:00Z half of leap 2028's 366 (1846108800)."""
    assert magmodel.decimal_year(1735689600.0) == 2025.0
    assert abs(magmodel.decimal_year(1751457600.0) - 2025.5) < 1e-12
    assert abs(magmodel.decimal_year(1846108800.0) - 2028.5) < 1e-12


def test_plausible_unix_tells_a_date_from_a_boot_clock() -> None:
    """2000-01-01 (946684800 s) to 2100-01-01 (4102444800 s) is a date; 12 days since boot is not."""
    assert magmodel.plausible_unix(946684800.0) and magmodel.plausible_unix(1.7e9)
    assert not magmodel.plausible_unix(946684799.0) and not magmodel.plausible_unix(1.0e6)
    assert not magmodel.plausible_unix(4102444800.0) and not magmodel.plausible_unix(math.nan)


def test_today_is_one_value_all_day() -> None:
    """this_year() is today's 00:00 UTC as a decimal year: a whole number of days into the year, so a live
    run and its replay later the same day use the same field."""
    import datetime as dt

    y = magmodel.this_year()
    today = dt.datetime.now(dt.timezone.utc).date()
    start = dt.date(today.year, 1, 1)
    days = (dt.date(today.year + 1, 1, 1) - start).days
    assert abs(y - (today.year + (today - start).days / days)) < 1e-12 or \
        dt.datetime.now(dt.timezone.utc).date() != today  # the day changed under the test
