"""What the mutation runs found unchecked in mavins/core/align.py (docs/testing.md).

In-process and fast. The sensor readings at rest are built from the physics
typed here ([ZS1] ch. 1: ``f^b = -C_n^b [0, 0, g]``, ``w^b = C_n^b w_ie^n``,
``m^b = C_n^b m^n``; C_b^n = Rz(yaw) Ry(pitch) Rx(roll), FRD body, NED), never
from align.py or mavins' rotation helpers; the alignment must give back the
attitude they were built from, in every quadrant.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import align
from support import wrap_rad

G = 9.80665
OMEGA = 7.292115e-5  # rad/s, WGS-84 Earth rate


def c_bn(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    ry = np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
    rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


ATTITUDES = [(r, p, y) for r in (0.0, 0.3, -0.4, 2.5) for p in (0.0, 0.2, -0.35)
             for y in (0.0, 0.7, 2.0, -1.2, -2.9, math.pi / 2, -math.pi / 2)]


@pytest.mark.parametrize("roll, pitch, yaw", ATTITUDES)
def test_level_gives_roll_and_pitch(roll, pitch, yaw):
    f_b = c_bn(roll, pitch, yaw).T @ np.array([0.0, 0.0, -G])
    r, p = align.level(f_b)
    assert r == pytest.approx(roll, abs=1e-12)
    assert p == pytest.approx(pitch, abs=1e-12)


def test_level_formula_at_a_known_point():
    # 30 deg right wing down, level pitch: f^b = -g [0, sin 30, cos 30]
    r, p = align.level(np.array([0.0, -G * 0.5, -G * math.sqrt(3) / 2]))
    assert r == pytest.approx(math.radians(30), abs=1e-14)
    assert p == pytest.approx(0.0, abs=1e-14)
    # 10 deg nose up: f^b = -g [-sin 10, 0, cos 10]
    r, p = align.level(np.array([G * math.sin(math.radians(10)), 0.0, -G * math.cos(math.radians(10))]))
    assert r == pytest.approx(0.0, abs=1e-14)
    assert p == pytest.approx(math.radians(10), abs=1e-14)


@pytest.mark.parametrize("roll, pitch, yaw", ATTITUDES)
@pytest.mark.parametrize("lat", [math.radians(47.4), math.radians(-33.9)])
def test_gyrocompass_gives_yaw(roll, pitch, yaw, lat):
    w_n = OMEGA * np.array([math.cos(lat), 0.0, -math.sin(lat)])
    w_b = c_bn(roll, pitch, yaw).T @ w_n
    assert wrap_rad(align.gyrocompass(w_b, roll, pitch) - yaw) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("roll, pitch, yaw", ATTITUDES)
@pytest.mark.parametrize("decl", [0.0, math.radians(12.0), math.radians(-7.5)])
def test_mag_heading_gives_yaw_with_declination(roll, pitch, yaw, decl):
    inc = math.radians(64.0)  # dip: mostly down, as at mid latitudes
    m_n = 0.48 * np.array([math.cos(inc) * math.cos(decl), math.cos(inc) * math.sin(decl), math.sin(inc)])
    m_b = c_bn(roll, pitch, yaw).T @ m_n
    assert wrap_rad(align.mag_heading(m_b, roll, pitch, decl) - yaw) == pytest.approx(0.0, abs=1e-12)


def test_mag_heading_declination_defaults_to_zero():
    m_b = np.array([0.2, -0.2, 0.4])  # level, field to the north-west in body axes
    assert align.mag_heading(m_b, 0.0, 0.0) == pytest.approx(math.radians(45.0), abs=1e-14)
