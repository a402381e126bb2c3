"""GNSS messages the service reads (GPS_RAW_INT, GPS_INPUT, HIL_GPS): what counts as a fix.

Expected values come from the MAVLink message definitions (common.xml: GPS_FIX_TYPE,
units of each field) and docs/filter.md (accuracy limit), never from the decoder.
"""
from __future__ import annotations

import pytest

from mavins.link.mavlink import mavlink
from mavins.pipeline import GNSS_MAX_SIGMA, gnss_fix, gnss_invalid

ENC = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
LAT, LON = 473977420, 85455940  # 1e-7 deg


def _decoded(msg: object) -> object:
    return mavlink.MAVLink(None).decode(bytearray(msg.pack(ENC)))  # type: ignore[attr-defined]


def _raw(fix_type: int = 3, lat: int = LAT, lon: int = LON, h_acc: int = 0, v_acc: int = 0) -> object:
    return _decoded(ENC.gps_raw_int_encode(5_000_000, fix_type, lat, lon, 488000, 80, 120, 0, 0, 12,
                                           alt_ellipsoid=0, h_acc=h_acc, v_acc=v_acc))


@pytest.mark.parametrize("fix_type", [3, 4, 5, 6, 7, 8])
def test_3d_fix_types_are_fixes(fix_type: int) -> None:
    fix = gnss_fix(_raw(fix_type), geoid_height=47.0)
    assert fix is not None and gnss_invalid(fix) is None
    t, lat, lon, h = fix[:4]
    assert (t, lat, lon) == (5.0, LAT * 1e-7, LON * 1e-7)
    assert h == 488.0 + 47.0  # AMSL mm -> m, plus the geoid height when alt_ellipsoid is absent


@pytest.mark.parametrize("fix_type", [0, 1, 2, 9, 106, 255])
def test_no_fix_and_undefined_fix_types_are_not_fixes(fix_type: int) -> None:
    assert gnss_fix(_raw(fix_type), geoid_height=0.0) is None


@pytest.mark.parametrize("lat, lon", [(900_000_001, LON), (-900_000_001, LON), (LAT, 1_800_000_001),
                                      (LAT, -2_147_483_648)])
def test_coordinates_outside_their_range_are_rejected(lat: int, lon: int) -> None:
    fix = gnss_fix(_raw(lat=lat, lon=lon), geoid_height=0.0)
    assert fix is not None and gnss_invalid(fix) == "out_of_range"


def test_accuracy_from_the_message_and_its_limit() -> None:
    fix = gnss_fix(_raw(h_acc=1500, v_acc=3000), geoid_height=0.0)  # mm
    assert fix is not None and fix[5:7] == (1.5, 3.0) and gnss_invalid(fix) is None
    at_limit = int(GNSS_MAX_SIGMA * 1000)
    assert gnss_invalid(gnss_fix(_raw(h_acc=at_limit, v_acc=at_limit), 0.0)) is None
    assert gnss_invalid(gnss_fix(_raw(h_acc=at_limit + 1), 0.0)) == "inaccurate"
    assert gnss_invalid(gnss_fix(_raw(v_acc=4_294_967_294), 0.0)) == "inaccurate"


def test_gps_input_with_non_finite_values_is_rejected() -> None:
    msg = _decoded(ENC.gps_input_encode(5_000_000, 0, 0, 0, 0, 3, LAT, LON, float("nan"), 1.0, 1.0,
                                        0.0, 0.0, 0.0, 0.2, 1.5, 3.0, 12))
    fix = gnss_fix(msg, geoid_height=0.0)
    assert fix is not None and gnss_invalid(fix) == "out_of_range"
