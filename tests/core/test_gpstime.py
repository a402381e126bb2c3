"""GPS time against UTC (mavins/core/gpstime.py), with expected values from the calendar.

GPS week 0 began 1980-01-06T00:00:00 (GPS = UTC then); GPS time runs 18 s ahead of UTC since
2017-01-01 (IERS Bulletin C). Week 2347 began on Sunday 2024-12-29 at 00:00:00 GPS, which is
2024-12-28T23:59:42Z (2347 weeks x 7 days after 1980-01-06: 16429 days later, counted here with
the datetime module).
"""

from __future__ import annotations

import datetime as dt
import math

import pytest

from mavins.core.gpstime import gps_week_ms, unix_of_gps


def unix(*ymdhms: int) -> float:
    return dt.datetime(*ymdhms, tzinfo=dt.timezone.utc).timestamp()


def test_week_2347_starts_on_sunday_2024_12_29_gps() -> None:
    start = dt.datetime(1980, 1, 6, tzinfo=dt.timezone.utc) + dt.timedelta(weeks=2347)
    assert start.date() == dt.date(2024, 12, 29) and start.weekday() == 6
    assert gps_week_ms(start.timestamp() - 18.0) == (2347, 0)  # 23:59:42 UTC the day before


def test_new_year_2025_is_three_days_and_18_s_into_week_2347() -> None:
    """2025-01-01T00:00:00Z = 00:00:18 GPS, Wednesday: (3 x 86400 + 18) s = 259218000 ms into the week."""
    assert gps_week_ms(unix(2025, 1, 1)) == (2347, 259_218_000)


def test_the_week_rolls_over_at_its_last_millisecond() -> None:
    """One millisecond before week 2347 is the last of week 2346; a half millisecond before rounds into the
    new week, not to ms 604800000 of the old one."""
    t0 = unix(2024, 12, 28, 23, 59, 42)
    assert gps_week_ms(t0 - 0.001) == (2346, 604_799_999)
    assert gps_week_ms(t0 - 0.0004) == (2347, 0)


def test_utc_of_a_gps_week_and_millisecond() -> None:
    """The inverse: week 2347, ms 259218000 is 2025-01-01T00:00:00Z; week 0 or unknown is no time."""
    assert unix_of_gps(2347, 259_218_000) == pytest.approx(unix(2025, 1, 1), abs=1e-6)
    assert math.isnan(unix_of_gps(0, 1000)) and math.isnan(unix_of_gps(math.nan, 0)) and math.isnan(unix_of_gps(5, math.inf))
