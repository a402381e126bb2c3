"""What the mutation runs found unchecked in mavins/link/ingest.py (docs/testing.md).

In-process and fast (no service, no subprocess), so that mutmut can run them
for every mutant. Messages are real pymavlink messages: encoded by a sender
with a system/component id, packed to bytes and parsed back. Expected values
are typed from the contract (docs/conventions.md "MAVLink": HIGHRES_IMU in SI
units; RAW_IMU and SCALED_IMU/2/3 int16 in mG and mrad/s, gauss as mgauss;
ArduPilot's SCALED_IMU carries ``time_boot_ms``), never taken from ingest.py.
"""

from __future__ import annotations

import math

import pytest

from mavins.link.ingest import Ingest, IngestConfig
from mavins.link.mavlink import mavlink

# Typed from the standards, not imported from the code under test.
STD_GRAVITY = 9.80665  # m/s^2 per g (CGPM 1901, used by MAVLink's "mG")
ALL_HIGHRES = 0b1_1111_1111  # HIGHRES_IMU fields_updated bits 0..8: acc, gyro, mag
ACC_GYRO = 0b11_1111  # bits 0..5 (MAVLink HIGHRES_IMU_UPDATED_FLAGS)
RANGE_ACC = 16 * STD_GRAVITY  # default accelerometer range +-16 g (docs/conventions.md)
RANGE_GYRO = 2000.0 * math.pi / 180.0  # default gyro range +-2000 deg/s


def wire(make, sysid: int = 1, compid: int = 1):
    """A message as it arrives: encoded by (sysid, compid), packed, parsed back."""
    tx = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    buf = make(tx).pack(tx)
    rx = mavlink.MAVLink(None)
    msg = rx.decode(bytearray(buf))
    assert msg.get_srcSystem() == sysid and msg.get_srcComponent() == compid
    return msg


def highres(t_us=1_000_000, acc=(0.5, -0.25, -9.75), gyr=(0.125, -0.0625, 0.03125), mag=(0.25, -0.125, 0.5),
            fields=ALL_HIGHRES, imu_id=0, **kw):
    return wire(lambda m: m.highres_imu_encode(t_us, *acc, *gyr, *mag, 1013.0, 0.0, 0.0, 20.0, fields, imu_id),
                **kw)


def raw(t_us=1_000_000, acc=(100, -200, -1000), gyr=(10, -20, 30), mag=(250, -125, 500), imu_id=0, **kw):
    return wire(lambda m: m.raw_imu_encode(t_us, *acc, *gyr, *mag, imu_id, 0), **kw)


def scaled(kind="SCALED_IMU", t_ms=1000, acc=(100, -200, -1000), gyr=(10, -20, 30), mag=(250, -125, 500), **kw):
    enc = {"SCALED_IMU": "scaled_imu_encode", "SCALED_IMU2": "scaled_imu2_encode",
           "SCALED_IMU3": "scaled_imu3_encode"}[kind]
    return wire(lambda m: getattr(m, enc)(t_ms, *acc, *gyr, *mag, 0), **kw)


def approx(a, b, rel=1e-12):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x == pytest.approx(y, rel=rel, abs=1e-15), (a, b)


# --- scaling and field mapping, one message kind at a time -------------------------------

def test_highres_is_si_units_and_every_field_lands_in_place():
    ing = Ingest()
    s = ing.sample(highres(t_us=2_500_000, sysid=7, compid=42))
    assert s is not None
    assert s.t == pytest.approx(2.5, rel=1e-15)
    approx(s.accel, (0.5, -0.25, -9.75))
    approx(s.gyro, (0.125, -0.0625, 0.03125))
    approx(s.mag, (0.25, -0.125, 0.5))
    assert (s.sysid, s.compid) == (7, 42)
    assert ing.accepted == 1 and ing.last_reason is None and not ing.rejected


def test_raw_imu_default_scales_are_mg_mrad_s_and_mgauss():
    s = Ingest().sample(raw(t_us=3_000_000, acc=(1000, -2000, 500), gyr=(1000, -250, 125), mag=(250, -125, 500)))
    assert s is not None
    assert s.t == pytest.approx(3.0, rel=1e-15)
    approx(s.accel, (STD_GRAVITY, -2 * STD_GRAVITY, 0.5 * STD_GRAVITY))
    approx(s.gyro, (1.0, -0.25, 0.125))
    approx(s.mag, (0.25, -0.125, 0.5))


def test_raw_imu_scales_are_settings():
    cfg = IngestConfig(raw_acc_scale=0.01, raw_gyro_scale=0.002, raw_mag_scale=0.004)
    s = Ingest(cfg).sample(raw(acc=(100, -200, 300), gyr=(10, -20, 30), mag=(1, 2, -3)))
    assert s is not None
    approx(s.accel, (1.0, -2.0, 3.0))
    approx(s.gyro, (0.02, -0.04, 0.06))
    approx(s.mag, (0.004, 0.008, -0.012))


def test_default_raw_scales():
    cfg = IngestConfig()
    assert cfg.raw_acc_scale == pytest.approx(STD_GRAVITY / 1000, rel=1e-15)
    assert cfg.raw_gyro_scale == pytest.approx(1e-3, rel=1e-15)
    assert cfg.raw_mag_scale == pytest.approx(1e-3, rel=1e-15)
    assert cfg.max_accel == pytest.approx(RANGE_ACC, rel=1e-15)
    assert cfg.max_gyro == pytest.approx(RANGE_GYRO, rel=1e-15)
    assert cfg.message == "auto" and cfg.imu_id is None and cfg.target_system is None


@pytest.mark.parametrize("kind", ["SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3"])
def test_scaled_imu_is_mg_mrad_s_mgauss_and_time_boot_ms(kind):
    s = Ingest().sample(scaled(kind, t_ms=4321, acc=(1000, -500, 250), gyr=(1000, -500, 2), mag=(250, -125, 500),
                               sysid=3, compid=9))
    assert s is not None
    assert s.t == pytest.approx(4.321, rel=1e-15)
    approx(s.accel, (STD_GRAVITY, -0.5 * STD_GRAVITY, 0.25 * STD_GRAVITY))
    approx(s.gyro, (1.0, -0.5, 0.002))
    approx(s.mag, (0.25, -0.125, 0.5))
    assert (s.sysid, s.compid) == (3, 9)


def test_scaled_imu_scales_do_not_follow_the_raw_settings():
    cfg = IngestConfig(raw_acc_scale=1.0, raw_gyro_scale=1.0, raw_mag_scale=1.0)
    s = Ingest(cfg).sample(scaled(acc=(1000, 0, 0), gyr=(1000, 0, 0), mag=(1000, 0, 0)))
    approx(s.accel, (STD_GRAVITY, 0.0, 0.0))
    approx(s.gyro, (1.0, 0.0, 0.0))
    approx(s.mag, (1.0, 0.0, 0.0))


# --- magnetometer presence -----------------------------------------------------------------

def test_highres_without_mag_bits_has_no_mag():
    assert Ingest().sample(highres(fields=ACC_GYRO)).mag is None


def test_highres_with_only_some_mag_bits_has_no_mag():
    assert Ingest().sample(highres(fields=ACC_GYRO | 0b0_1100_0000)).mag is None


def test_all_zero_mag_means_no_mag_and_one_nonzero_axis_is_a_mag():
    assert Ingest().sample(raw(mag=(0, 0, 0))).mag is None
    assert Ingest().sample(scaled(mag=(0, 0, 0))).mag is None
    assert Ingest().sample(highres(mag=(0.0, 0.0, 0.0))).mag is None
    s = Ingest().sample(raw(mag=(0, 0, 7)))
    approx(s.mag, (0.0, 0.0, 0.007))


# --- fields_updated -------------------------------------------------------------------------

@pytest.mark.parametrize("bit", range(6))
def test_highres_missing_any_acc_or_gyro_bit_is_rejected(bit):
    ing = Ingest()
    assert ing.sample(highres(fields=ALL_HIGHRES & ~(1 << bit))) is None
    assert ing.rejected == {"fields_missing": 1} and ing.last_reason == "fields_missing"
    assert ing.accepted == 0


def test_highres_with_exactly_the_acc_gyro_bits_is_accepted():
    assert Ingest().sample(highres(fields=ACC_GYRO)) is not None


def test_highres_with_extra_bits_is_accepted():
    assert Ingest().sample(highres(fields=0xFFFF)) is not None


# --- finite values and sensor range ---------------------------------------------------------

@pytest.mark.parametrize("axis", range(6))
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_non_finite_acc_or_gyro_on_any_axis_is_rejected(axis, bad):
    v = [0.5, -0.25, -9.75, 0.125, -0.0625, 0.03125]
    v[axis] = bad
    ing = Ingest()
    assert ing.sample(highres(acc=v[:3], gyr=v[3:])) is None
    assert ing.rejected == {"non_finite": 1} and ing.last_reason == "non_finite"


@pytest.mark.parametrize("axis", range(3))
@pytest.mark.parametrize("sign", [1, -1])
def test_accel_range_is_16_g_on_every_axis_both_signs(axis, sign):
    over = [0, 0, 0]
    over[axis] = sign * 16001  # mG: just over 16 g
    ing = Ingest()
    assert ing.sample(raw(acc=over)) is None
    assert ing.rejected == {"out_of_range": 1} and ing.last_reason == "out_of_range"
    inside = [0, 0, 0]
    inside[axis] = sign * 15999
    assert Ingest().sample(raw(acc=inside)) is not None


@pytest.mark.parametrize("axis", range(3))
@pytest.mark.parametrize("sign", [1, -1])
def test_gyro_range_is_2000_deg_s_on_every_axis_both_signs(axis, sign):
    # 2000 deg/s = 34.9066 rad/s; counts of 2 mrad/s (int16 holds no 34907):
    # 17454 counts = 34.908 rad/s is over, 17453 = 34.906 inside
    cfg = IngestConfig(raw_gyro_scale=0.002)
    over = [0, 0, 0]
    over[axis] = sign * 17454
    ing = Ingest(cfg)
    assert ing.sample(raw(gyr=over)) is None
    assert ing.rejected == {"out_of_range": 1}
    inside = [0, 0, 0]
    inside[axis] = sign * 17453
    assert Ingest(cfg).sample(raw(gyr=inside)) is not None


def test_range_limits_are_inclusive_and_settings():
    cfg = IngestConfig(max_accel=8.0, max_gyro=2.0)
    for acc, gyr in (((8.0, -8.0, 8.0), (2.0, -2.0, 2.0)),):
        assert Ingest(cfg).sample(highres(acc=acc, gyr=gyr)) is not None
    for k in range(3):
        a = [0.0, 0.0, 0.0]
        a[k] = -8.5
        assert Ingest(cfg).sample(highres(acc=a, gyr=(0.0, 0.0, 0.0))) is None
        g = [0.0, 0.0, 0.0]
        g[k] = -2.5
        assert Ingest(cfg).sample(highres(acc=(0.0, 0.0, 0.0), gyr=g)) is None


# --- time -----------------------------------------------------------------------------------

def test_time_must_strictly_increase():
    ing = Ingest()
    assert ing.sample(highres(t_us=1_000_000)) is not None
    assert ing.sample(highres(t_us=1_000_000)) is None
    assert ing.last_reason == "duplicate_time"
    assert ing.sample(highres(t_us=999_999)) is None
    assert ing.last_reason == "time_backwards"
    s = ing.sample(highres(t_us=1_000_001))
    assert s is not None and s.t == pytest.approx(1.000001, rel=1e-15)
    assert ing.last_reason is None
    assert ing.rejected == {"duplicate_time": 1, "time_backwards": 1}
    assert ing.accepted == 2
    assert ing.sample(highres(t_us=1_000_002)) is not None
    assert ing.accepted == 3


def test_rejected_sample_does_not_move_the_clock():
    ing = Ingest()
    assert ing.sample(highres(t_us=1_000_000)) is not None
    assert ing.sample(highres(t_us=2_000_000, acc=(float("nan"), 0.0, 0.0))) is None
    assert ing.sample(highres(t_us=1_500_000)) is not None


def test_reset_time_allows_an_earlier_time():
    ing = Ingest()
    assert ing.sample(highres(t_us=5_000_000)) is not None
    ing.reset_time()
    assert ing.last_t is None
    s = ing.sample(highres(t_us=1_000_000))
    assert s is not None and s.t == pytest.approx(1.0)


# --- which stream ---------------------------------------------------------------------------

def test_non_imu_messages_are_ignored_not_counted():
    ing = Ingest()
    hb = wire(lambda m: m.heartbeat_encode(18, 8, 0, 0, 4))
    assert ing.sample(hb) is None
    assert not ing.rejected and ing.accepted == 0 and ing.locked_message is None


def test_auto_locks_onto_the_first_stream_kind_and_id():
    ing = Ingest()
    assert ing.sample(highres(t_us=1_000_000)) is not None
    assert (ing.locked_message, ing.locked_id, ing.locked_system) == ("HIGHRES_IMU", 0, 1)
    assert ing.sample(raw(t_us=2_000_000)) is None
    assert ing.last_reason == "other_imu"
    assert ing.sample(highres(t_us=3_000_000, imu_id=1)) is None
    assert ing.last_reason == "other_imu"
    assert ing.sample(highres(t_us=4_000_000, sysid=2)) is None
    assert ing.last_reason == "other_system"
    assert ing.rejected == {"other_imu": 2, "other_system": 1}
    assert ing.sample(highres(t_us=5_000_000)) is not None


def test_raw_imu_id_is_locked():
    ing = Ingest()
    assert ing.sample(raw(t_us=1_000_000, imu_id=2)) is not None
    assert ing.locked_id == 2
    assert ing.sample(raw(t_us=2_000_000, imu_id=0)) is None
    assert ing.sample(raw(t_us=3_000_000, imu_id=2)) is not None


def test_scaled_imu_kinds_are_separate_streams():
    ing = Ingest()
    assert ing.sample(scaled("SCALED_IMU2", t_ms=1000)) is not None
    assert ing.sample(scaled("SCALED_IMU", t_ms=2000)) is None
    assert ing.sample(scaled("SCALED_IMU3", t_ms=3000)) is None
    assert ing.sample(scaled("SCALED_IMU2", t_ms=4000)) is not None


@pytest.mark.parametrize("want, make", [
    ("HIGHRES_IMU", lambda: highres()), ("RAW_IMU", lambda: raw()), ("SCALED_IMU", lambda: scaled("SCALED_IMU")),
    ("SCALED_IMU2", lambda: scaled("SCALED_IMU2")), ("SCALED_IMU3", lambda: scaled("SCALED_IMU3")),
])
def test_selected_message_is_taken_and_others_rejected(want, make):
    ing = Ingest(IngestConfig(message=want.lower()))
    assert ing.sample(make()) is not None
    other = raw(t_us=9_000_000) if want != "RAW_IMU" else highres(t_us=9_000_000)
    ing2 = Ingest(IngestConfig(message=want))
    assert ing2.sample(other) is None
    assert ing2.rejected == {"other_imu": 1}
    assert ing2.locked_message is None


def test_imu_id_setting_selects_the_id():
    ing = Ingest(IngestConfig(imu_id=1))
    assert ing.sample(highres(t_us=1_000_000, imu_id=0)) is None
    assert ing.rejected == {"other_imu": 1} and ing.locked_message is None
    assert ing.sample(highres(t_us=2_000_000, imu_id=1)) is not None
    assert ing.locked_id == 1


def test_imu_id_setting_does_not_apply_to_scaled_imu():
    # SCALED_IMU has no id field: its id is 0 (the first of a kind)
    ing = Ingest(IngestConfig(imu_id=0))
    assert ing.sample(scaled()) is not None


def test_target_system_setting():
    ing = Ingest(IngestConfig(target_system=5))
    assert ing.sample(highres(t_us=1_000_000, sysid=4)) is None
    assert ing.rejected == {"other_system": 1} and ing.last_reason == "other_system"
    s = ing.sample(highres(t_us=2_000_000, sysid=5))
    assert s is not None and s.sysid == 5
    assert ing.locked_system == 5


def test_last_reason_is_cleared_by_the_next_imu_message():
    ing = Ingest()
    assert ing.sample(highres(fields=0)) is None
    assert ing.last_reason == "fields_missing"
    assert ing.sample(highres()) is not None
    assert ing.last_reason is None
