"""What the mutation runs found unchecked in mavins/core/strapdown.py (docs/testing.md).

The strapdown kernels in-process, a few samples each (they run as plain Python under
``./dev mutate``), against closed forms typed here, never computed by mavins:

* rest on the rotating Earth and steady flight due east along a parallel: the sensors
  are constant, ``w^b = C_n^b (w_ie^n + w_en^n)``, ``f^b = C_n^b ((2 w_ie^n + w_en^n) x v^n
  - [0, 0, gamma])`` (the navigation equation with dv/dt = 0, [TW11] 3.5 / eq. 3.69), and the
  solution is ``lat = L0``, ``h = h0``, ``lon = lon0 + v_E t/((R_E + h) cos L)``, v and C_b^n
  constant; WGS-84 and Somigliana gravity from tests/support.py (NIMA TR8350.2), in all four
  ``--frame`` mechanisations;
* laboratory mode (``--earth none``, docs/conventions.md "Earth model"): constant acceleration
  gives ``v = v0 + a t`` and the position of each ``--position`` rule in closed form; the
  N-sample coning and sculling coefficients of docs/conventions.md ``--samples``, Savage's
  rotation compensation, the ``--order`` tables, the piecewise-linear sampled-rate sums of
  docs/algorithms.md, ``--vertical hold``;
* the j-cycle return codes, ``skip_to``, ``state_time``, ``frame_limit``, ``make_config``.

Sample intervals are powers of two (1/128 s), so every sample time and their sums are exact.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import strapdown as sd
from mavins.core.jit import for_frame
from support import E2, OMEGA, A, cbn, gamma

DT = 1.0 / 128.0
LAT0, LON0, H0 = math.radians(45.3), math.radians(7.6), 350.0
ATT = (math.radians(4.0), math.radians(-7.0), math.radians(123.0))
EPS = 2.0 ** -52


# --- the tests' own forms (WGS-84, rotations) ---------------------------------------------------
def radii(lat: float) -> tuple[float, float]:
    """Meridian and prime-vertical radii (m), WGS-84 (NIMA TR8350.2 eq. 4-18, 4-15)."""
    d = 1.0 - E2 * math.sin(lat) ** 2
    return A * (1.0 - E2) / d ** 1.5, A / math.sqrt(d)


def skew(v) -> np.ndarray:
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def expm(phi) -> np.ndarray:
    """Rodrigues: exp([phi x]) = I + sin p/p [phi x] + (1 - cos p)/p^2 [phi x]^2."""
    p = float(np.linalg.norm(phi))
    k = skew(phi)
    return np.eye(3) + math.sin(p) / p * k + (1.0 - math.cos(p)) / p ** 2 * k @ k


def savage(phi, dv) -> np.ndarray:
    """Savage's rotation compensation (docs/conventions.md --samples):
    (1 - cos p)/p^2 phi x dv + (1 - sin p/p)/p^2 phi x (phi x dv)."""
    phi, dv = np.asarray(phi, float), np.asarray(dv, float)
    p = float(np.linalg.norm(phi))
    if p == 0.0:
        return np.zeros(3)
    c = np.cross(phi, dv)
    return (1.0 - math.cos(p)) / p ** 2 * c + (1.0 - math.sin(p) / p) / p ** 2 * np.cross(phi, c)


def dcm_of_quat(q) -> np.ndarray:
    """C_b^n of a Hamilton quaternion [w, x, y, z] (docs/conventions.md "Frames and attitude")."""
    w, x, y, z = q
    return np.array([[w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]])


def qmul(p, q) -> np.ndarray:
    """Hamilton product (p0 q0 - p.q, p0 q + q0 p + p x q)."""
    p, q = np.asarray(p, float), np.asarray(q, float)
    return np.concatenate(([p[0] * q[0] - p[1:] @ q[1:]], p[0] * q[1:] + q[0] * p[1:] + np.cross(p[1:], q[1:])))


def euler(c: np.ndarray) -> np.ndarray:
    """ZYX roll, pitch, yaw of C_b^n = Rz(yaw) Ry(pitch) Rx(roll)."""
    return np.array([math.atan2(c[2, 1], c[2, 2]), math.asin(-c[2, 0]), math.atan2(c[1, 0], c[0, 0])])


def wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def check_row(row, t, lat, lon, h, v, c, *, pos=1e-15, hm=1e-9, vel=1e-12, att=1e-14):
    """One output row t,lat,lon,h,vn,ve,vd,roll,pitch,yaw,qw,qx,qy,qz (docs/conventions.md "Files")."""
    assert row.shape == (14,)
    assert row[0] == t
    assert abs(row[1] - lat) <= pos and abs(row[2] - lon) <= pos, (row[1] - lat, row[2] - lon)
    assert abs(row[3] - h) <= hm, row[3] - h
    np.testing.assert_allclose(row[4:7], v, rtol=0, atol=vel)
    np.testing.assert_allclose(wrap(row[7:10] - euler(c)), 0.0, rtol=0, atol=att)
    q = row[10:14]
    assert q[0] >= 0.0
    assert abs(q @ q - 1.0) <= 8 * EPS
    np.testing.assert_allclose(dcm_of_quat(q), c, rtol=0, atol=att)


def run(cfg, s, t, th, dv):
    out = np.full((len(t), 14), np.nan)
    m = sd.run_increments(s, cfg, np.asarray(t, float), np.ascontiguousarray(th, float),
                          np.ascontiguousarray(dv, float), out)
    return out[:m]


# --- make_config, kernel_frame ------------------------------------------------------------------
def test_make_config_vector():
    # layout of strapdown.py's configuration vector: samples, dcm, order, earth, ortho, vhold,
    # coning, position rule, l_every, sampled, frame (defaults: docs/conventions.md)
    np.testing.assert_array_equal(sd.make_config(), [2, 0, 0, 1, 1, 0, 1, 1, 1, 0, 0])
    cfg = sd.make_config(samples=3, attitude="dcm", order="2", earth_model="none", orthonormalize_every=4,
                         vertical="hold", coning=True, position="simpson", l_every=5, imu_rates="sampled")
    np.testing.assert_array_equal(cfg, [3, 1, 2, 0, 4, 1, 1, 2, 5, 1, 0])
    cfg = sd.make_config(samples=6, attitude="quaternion", order="4", coning=False, position="rectangular",
                         vertical="free", imu_rates="averaged", frame="inertial")
    np.testing.assert_array_equal(cfg, [6, 0, 4, 1, 1, 0, 0, 0, 1, 0, 3])
    assert sd.make_config(samples=1, coning=True)[6] == 0.0  # N = 1 applies no correction
    assert sd.make_config(samples=2, coning=True)[6] == 1.0
    assert sd.make_config(order="1")[2] == 1.0 and sd.make_config(order="3")[2] == 3.0
    assert sd.make_config(frame="wander")[10] == 1.0 and sd.make_config(frame="free")[10] == 2.0
    assert [sd.kernel_frame(sd.make_config(frame=f)) for f in ("geographic", "wander", "free", "inertial")] == \
        [0, 1, 1, 3]


def test_make_config_refuses():
    for frame in ("wander", "free", "inertial"):
        with pytest.raises(ValueError, match=rf"^frame '{frame}' needs the WGS-84 Earth \(earth_model wgs84\)$"):
            sd.make_config(frame=frame, earth_model="none")
    with pytest.raises(ValueError, match="samples"):
        sd.make_config(samples=7)
    with pytest.raises(ValueError, match="position"):
        sd.make_config(position="euler")


# --- steady states on the WGS-84 Earth -----------------------------------------------------------
def steady_sensors(lat, h, ve, att):
    """Constant w^b, f^b of a vehicle at attitude att flying due east at ve (m/s) along the parallel at
    lat, h (rest for ve = 0): dv^n/dt = C_b^n f^b - (2 w_ie + w_en) x v + [0, 0, gamma] = 0 and
    C_b^n constant, so w_ib^b = C_n^b (w_ie^n + w_en^n) ([TW11] 3.5)."""
    r_n, r_e = radii(lat)
    w_ie = np.array([OMEGA * math.cos(lat), 0.0, -OMEGA * math.sin(lat)])
    w_en = np.array([ve / (r_e + h), 0.0, -ve * math.tan(lat) / (r_e + h)])
    v = np.array([0.0, ve, 0.0])
    c = cbn(*att)
    f_n = np.cross(2 * w_ie + w_en, v) - np.array([0.0, 0.0, float(gamma(lat, h))])
    return c.T @ (w_ie + w_en), c.T @ f_n, c


FRAMES = ["geographic", "wander", "free", "inertial"]


def steady_run(frame, lat, ve, att=ATT, n=24, samples=2, bias=0.0, t0=0.0, state=False, alpha=0.0, **kw):
    w, f, c = steady_sensors(lat, H0, ve, att)
    f = f + c.T @ np.array([0.0, 0.0, bias])  # a vertical accelerometer error (for --vertical hold)
    cfg = sd.make_config(samples=samples, frame=frame, **kw)
    s = sd.init_state(t0, lat, LON0, H0, np.array([0.0, ve, 0.0]), *att)
    turn_azimuth(s, alpha, lat, c, [0.0, ve, 0.0])
    t = t0 + DT * np.arange(1, n + 1)
    rows = run(cfg, s, t, np.tile(w * DT, (n, 1)), np.tile(f * DT, (n, 1)))
    return (rows, c, s) if state else (rows, c)


# Tolerances: the updates' truncation is third order in the frame's turn per update (< 2e-6 rad,
# so < 1e-17 relative); what remains is round-off: ~1 ulp of lat (1e-16 rad) and of the
# velocity (100 m/s: 1.4e-14) per update, ~1 ulp of the attitude per update.
@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("lat,ve,t0", [(LAT0, 0.0, 0.0), (LAT0, 150.0, 0.0), (math.radians(-33.8), -120.0, 0.0),
                                       (LAT0, 150.0, 100.0)])
def test_steady_flight_along_a_parallel(frame, lat, ve, t0):
    rows, c = steady_run(frame, lat, ve, t0=t0, alpha=0.7 if frame in ("wander", "free") and t0 else 0.0)
    assert len(rows) == 12
    r_e = radii(lat)[1]
    for k, row in enumerate(rows, 1):
        t = 2 * k * DT
        check_row(row, t0 + t, lat, LON0 + ve * t / ((r_e + H0) * math.cos(lat)), H0, [0.0, ve, 0.0], c,
                  pos=2e-15, hm=2e-8, vel=5e-13, att=2e-14)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("how", ["run_rates", "push_increment", "push_rate", "sampled"])
def test_steady_flight_fed_each_way(frame, how):
    """The same closed form through every entry point: averaged rates (dtheta = w dt exactly), increments and rates
    pushed one by one, and sampled rates (constant rates: trapezoid exact, every coning and sculling term a cross
    product of parallel vectors, 0) with a row at the start time."""
    w, f, c = steady_sensors(LAT0, H0, 150.0, ATT)
    t0, n = 100.0, 16
    cfg = sd.make_config(frame=frame, imu_rates="sampled" if how == "sampled" else "averaged")
    s = sd.init_state(t0, LAT0, LON0, H0, np.array([0.0, 150.0, 0.0]), *ATT)
    kf = sd.kernel_frame(cfg)
    t = t0 + DT * np.arange(1, n + 1)
    rows = []
    if how in ("run_rates", "sampled"):
        tt = t if how == "run_rates" else np.concatenate(([t0], t))
        out = np.full((n, 14), np.nan)
        rows = out[:sd.run_rates(s, cfg, tt, np.tile(w, (len(tt), 1)), np.tile(f, (len(tt), 1)), out)]
    else:
        push = for_frame(sd.push_increment if how == "push_increment" else sd.push_rate, kf)
        row = np.empty(14)
        for ti in t:
            if (push(s, cfg, ti, w * DT, f * DT) if how == "push_increment" else push(s, cfg, ti, w, f)) == 1:
                for_frame(sd.solution_row, kf)(s, cfg, row)
                rows.append(row.copy())
    assert len(rows) == n // 2
    r_e = radii(LAT0)[1]
    for k, row in enumerate(rows, 1):
        t = 2 * k * DT
        check_row(row, t0 + t, LAT0, LON0 + 150.0 * t / ((r_e + H0) * math.cos(LAT0)), H0, [0.0, 150.0, 0.0], c,
                  pos=2e-15, hm=2e-8, vel=5e-13, att=2e-14)


def turn_azimuth(s, alpha, lat, c, v):
    """A wander/free state whose azimuth has turned by alpha (docs/algorithms.md "Mechanisation frames"):
    C_w^e = C_n^e Rz(alpha), v^w = Rz(-alpha) v^n, C_b^w = Rz(-alpha) C_b^n (q: qz(-alpha) (x) q_nb)."""
    if not alpha:
        return
    rz = np.array([[math.cos(alpha), -math.sin(alpha), 0.0], [math.sin(alpha), math.cos(alpha), 0.0], [0, 0, 1.0]])
    s[sd.S.CNE:sd.S.CNE + 9] = (cne(lat, LON0) @ rz).ravel()
    s[sd.S.C:sd.S.C + 9] = (rz.T @ c).ravel()
    s[sd.S.Q:sd.S.Q + 4] = qmul([math.cos(alpha / 2), 0.0, 0.0, -math.sin(alpha / 2)], s[sd.S.Q:sd.S.Q + 4])
    s[sd.S.V:sd.S.V + 3] = s[sd.S.VP:sd.S.VP + 3] = rz.T @ np.asarray(v, float)


def kinematics(lat, lon, h, v, t, steps=16):
    """lat, lon, h after t (s) at constant NED velocity v: lat' = v_N/(R_N + h), lon' = v_E/((R_E + h) cos L),
    h' = -v_D (docs/conventions.md), integrated by RK4 (error ~ (t/steps)^4, far below round-off)."""
    def rate(y):
        r_n, r_e = radii(y[0])
        return np.array([v[0] / (r_n + y[2]), v[1] / ((r_e + y[2]) * math.cos(y[0])), -v[2]])

    y, dt = np.array([lat, lon, h]), t / steps
    for _ in range(steps):
        k1 = rate(y)
        k2 = rate(y + dt / 2 * k1)
        k3 = rate(y + dt / 2 * k2)
        k4 = rate(y + dt * k3)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return y


V_GEN = np.array([60.0, 150.0, -8.0])


@pytest.mark.parametrize("frame,attitude,alpha", [(f, "quaternion", 0.0) for f in FRAMES] +
                         [("geographic", "dcm", 0.0), ("inertial", "dcm", 0.0), ("wander", "quaternion", 0.7),
                          ("free", "dcm", -0.4)])
@pytest.mark.parametrize("vertical", ["free", "hold"])
def test_constant_velocity_flight(frame, vertical, attitude, alpha):
    """North, east and up at once: the sensors of constant NED velocity at the start point (f^n = (2 w_ie + w_en) x v
    - g, w = C_n^b (w_ie + w_en), held constant) give v = v0 and the position of the kinematics. What the
    constant sensors miss along the path bounds the error: gravity's height gradient 2 gamma/a |v_D| = 2.5e-5
    m/s^3 and its latitude gradient 0.052 sin 2L v_N/R_N = 5e-7 m/s^3 (v: 2.6e-5 t^2/2, 5e-8 m/s at 1/16 s), and
    w_in's change with latitude (< 1e-9 rad/s^2: 2e-12 rad of attitude); lat and lon also to the round-off of
    C_n^e's elements (1 ulp each per update) and of the reference's 16 steps, 3e-15 rad. --vertical hold: h = h0
    and v_D = its initial value (docs/conventions.md); the l cycle still places its mid-interval point at h0 - T/2
    v_D, so the transport rate's radius is |v_D| T/2 off (1e-8 relative)."""
    lat = LAT0
    r_n, r_e = radii(lat)
    w_ie = np.array([OMEGA * math.cos(lat), 0.0, -OMEGA * math.sin(lat)])
    w_en = np.array([V_GEN[1] / (r_e + H0), -V_GEN[0] / (r_n + H0), -V_GEN[1] * math.tan(lat) / (r_e + H0)])
    c = cbn(*ATT)
    f = c.T @ (np.cross(2 * w_ie + w_en, V_GEN) - np.array([0.0, 0.0, float(gamma(lat, H0))]))
    w = c.T @ (w_ie + w_en)
    t0, n = 50.0, 8
    cfg = sd.make_config(frame=frame, vertical=vertical, attitude=attitude)
    s = sd.init_state(t0, lat, LON0, H0, V_GEN.copy(), *ATT)
    turn_azimuth(s, alpha, lat, c, V_GEN)
    rows = run(cfg, s, t0 + DT * np.arange(1, n + 1), np.tile(w * DT, (n, 1)), np.tile(f * DT, (n, 1)))
    assert len(rows) == 4
    pos_now = for_frame(sd.position, sd.kernel_frame(cfg))(s, cfg)  # what the filter reads: the last row's
    assert pos_now == pytest.approx(tuple(rows[-1][1:4]), rel=0, abs=1e-15)
    T = 2 * DT
    for k, row in enumerate(rows, 1):
        t = k * T
        la, lo, h = kinematics(lat, LON0, H0, V_GEN if vertical == "free" else [V_GEN[0], V_GEN[1], 0.0], t)
        vel = 2.6e-5 * t * t / 2 + 1e-12
        pos = vel * t / r_n + 3e-15 + (abs(V_GEN[2]) * DT / r_e * abs(lo - LON0) if vertical == "hold" else 0.0)
        check_row(row, t0 + t, la, lo, h, V_GEN, c, pos=pos, hm=vel * t + 1e-8, vel=vel, att=2e-12)


def test_azimuth_of_the_wander_and_free_frames():
    """At rest the wander frame keeps its azimuth (alpha = 0: no vertical transport rate), the free-azimuth frame
    does not turn about its vertical in inertial space, so its azimuth from north grows as Omega sin L t
    ([ZS] 2.2, 2.3). alpha from C_w^e = C_n^e Rz(alpha), third row (cos L cos alpha, -cos L sin alpha, -sin L)."""
    for frame, rate in (("wander", 0.0), ("free", OMEGA * math.sin(LAT0))):
        rows, _, s = steady_run(frame, LAT0, 0.0, state=True)
        c = s[sd.S.CNE:sd.S.CNE + 9]
        alpha = math.atan2(-c[7], c[6])
        assert alpha == pytest.approx(rate * 24 * DT, rel=1e-9, abs=1e-17)


def cne(lat, lon):
    """C_n^e of the NED frame at lat, lon ([TW11] 3.4)."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0.0, -sl]])


@pytest.mark.parametrize("xi", [[1e-3, -2e-3, 5e-4], [0.0099, 0.0, 0.0], [0.0, 0.01, 0.0], [0.3, -0.2, 0.4],
                                [2.0e-6, 1.5e-6, -1e-6]])
def test_position_rotation(xi):
    """C_n^e <- C_n^e exp([xi x]) (docs/conventions.md "Navigation-frame rotation"; Rodrigues), on both sides of the
    series limit |xi| = 0.01 rad."""
    s = sd.init_state(0.0, LAT0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
    c0 = cne(LAT0, LON0)
    s[sd.S.CNE:sd.S.CNE + 9] = c0.ravel()
    sd._rotate_position(s, *xi)
    np.testing.assert_allclose(s[sd.S.CNE:sd.S.CNE + 9], (c0 @ expm(xi)).ravel(), rtol=0, atol=4e-16)


def test_wander_frame_exactly_at_a_pole():
    """Exactly at a pole the wander angle is 0 and the longitude that of w's y axis as east (docs/conventions.md
    "--frame"): the velocity and attitude are reported as held."""
    lon = 0.7
    cfg = sd.make_config(frame="wander")
    s = sd.init_state(0.0, LAT0, LON0, H0, np.array([1.0, 2.0, 0.5]), *ATT)
    s[sd.S.CNE:sd.S.CNE + 9] = [-math.cos(lon), -math.sin(lon), 0.0, -math.sin(lon), math.cos(lon), 0.0, 0.0, 0.0,
                                -1.0]  # cne(90 deg, lon) with cos L exactly 0
    assert for_frame(sd.position, sd.WANDER)(s, cfg) == (math.pi / 2, pytest.approx(lon, abs=1e-16), H0)
    row = np.empty(14)
    for_frame(sd.solution_row, sd.WANDER)(s, cfg, row)
    check_row(row, 0.0, math.pi / 2, lon, H0, [1.0, 2.0, 0.5], cbn(*ATT), pos=2e-16, hm=0.0, vel=0.0, att=1e-15)


@pytest.mark.parametrize("frame", FRAMES)
def test_reported_at_gimbal_lock(frame):
    """Pitch exactly 90 deg: roll is reported 0 and yaw as yaw - roll (C_b^n = Rz(y) Ry(90 deg) Rx(r) depends on
    y - r only); the branch holds within 1e-15 of sin pitch = 1, so the angles to sqrt(2e-15) = 5e-8 rad."""
    att = (0.3, math.pi / 2, 1.1)
    rows, _ = steady_run(frame, LAT0, 0.0, att=att, n=2)
    assert len(rows) == 1
    assert rows[0][7] == 0.0
    assert rows[0][8] == pytest.approx(math.pi / 2, abs=5e-8)
    assert rows[0][9] == pytest.approx(0.8, abs=5e-8)


@pytest.mark.parametrize("m", [1, 2])
def test_inertial_gravitation(m):
    """The inertial frame's gravitation at each l cycle: G = g - Omega^2 [x, y, 0] (plumb gravity less the centrifugal
    term, [ZS1] eq. 1-3-26) at the mid-interval point, turned into ECI by Omega (t_mid - t0), plus from the third l
    cycle on (G_l - 2 G_l-1 + G_l-2)/(24 M^2) (docs/algorithms.md "Mechanisation frames": the midpoint rule's T^2/24
    G''), held for M updates. At rest the mid-interval point is r^e itself (to (T/2)^3/12 Omega^3 r = 1e-13 m)."""
    t0 = 100.0
    w, f, c = steady_sensors(LAT0, H0, 0.0, ATT)
    cfg = sd.make_config(frame="inertial", l_every=m)
    s = sd.init_state(t0, LAT0, LON0, H0, np.zeros(3), *ATT)
    r_n, r_e = radii(LAT0)
    sl, cl, so, co = math.sin(LAT0), math.cos(LAT0), math.sin(LON0), math.cos(LON0)
    x, y = (r_e + H0) * cl * co, (r_e + H0) * cl * so
    g = float(gamma(LAT0, H0))
    ge = np.array([-g * cl * co - OMEGA ** 2 * x, -g * cl * so - OMEGA ** 2 * y, -g * sl])
    T = 2 * DT

    def eci(k):  # the l cycle of update k (1-based): mid-interval time t0 + (k - 1/2) T
        th = OMEGA * (k - 0.5) * T
        return np.array([math.cos(th) * ge[0] - math.sin(th) * ge[1], math.sin(th) * ge[0] + math.cos(th) * ge[1],
                         ge[2]])

    push = for_frame(sd.push_increment, sd.INERTIAL)
    ls = []
    for k in range(1, 4 * m + 1):
        push(s, cfg, t0 + (2 * k - 1) * DT, w * DT, f * DT)
        assert push(s, cfg, t0 + 2 * k * DT, w * DT, f * DT) == 1
        if (k - 1) % m == 0:
            ls.append(k)
        want = eci(ls[-1])
        if len(ls) >= 3:
            want = want + (eci(ls[-1]) - 2 * eci(ls[-2]) + eci(ls[-3])) / (24 * m * m)
        got = np.array([s[sd.S.GH], s[sd.S.GH + 1], s[sd.S.G]])
        # The first update has no v(k-2): its point r + T/2 v lies on the chord, r Omega^2 T^2/8 = 1.0e-6 m above the
        # circle, 2 gamma/a of that = 3.2e-12 m/s^2 in G, which reaches the third l cycle's term divided by 24 M^2.
        # With M = 2 the held G misses Omega |G_h| T^2 = 1.2e-7 m/s over each pair of updates, which moves r^i by
        # ~1e-8 m by the fourth l cycle: g/R of that, 2e-14 m/s^2.
        tol = {1: 4e-12, 3: 4e-12 / (24 * m * m) + 1e-14}.get(len(ls), 1e-14 if m == 1 else 4e-14)
        np.testing.assert_allclose(got, want, rtol=0, atol=tol)


@pytest.mark.parametrize("frame", ["geographic", "inertial"])
def test_steady_flight_dcm_and_truncated_orders(frame):
    """C_b^n stays put: the body turns by sigma = C_n^b zeta, undone by the frame's turn; --order and
    the DCM form change that only in sigma's third order (|sigma| ~ 1e-6 rad here)."""
    for kw in ({"attitude": "dcm"}, {"attitude": "dcm", "order": "2"}, {"order": "2"}):
        rows, c = steady_run(frame, LAT0, 150.0, **kw)
        r_e = radii(LAT0)[1]
        for k, row in enumerate(rows, 1):
            t = 2 * k * DT
            check_row(row, t, LAT0, LON0 + 150.0 * t / ((r_e + H0) * math.cos(LAT0)), H0, [0.0, 150.0, 0.0], c,
                      pos=2e-15, hm=2e-8, vel=5e-13, att=2e-14)


@pytest.mark.parametrize("frame", FRAMES)
def test_vertical_hold(frame):
    """--vertical hold keeps h and v_D at their initial values (docs/conventions.md): a 0.5 m/s^2
    vertical accelerometer error then changes nothing; without hold v_D = -0.5 t."""
    rows, c = steady_run(frame, LAT0, 150.0, bias=-0.5, vertical="hold")
    r_e = radii(LAT0)[1]
    T = 2 * DT
    # The inertial frame holds after the velocity step, so inside each update the vertical velocity error
    # v_D = b t reaches the east equation's Coriolis and transport terms, (2 Omega cos L + v_E/(R_E + h)) v_D
    # ([TW11] 11.3, v' = f + g - (2 w_ie + w_en) x v, its east row): (Omega cos L + v_E/(2 (R_E + h))) b T^2 per
    # update (7.7e-9 m/s here), a second-order term of the update; the local-level frames hold v_D before
    # those terms.
    leak = (OMEGA * math.cos(LAT0) + 150.0 / (2.0 * (r_e + H0))) * -0.5 * T * T
    for k, row in enumerate(rows, 1):
        t = k * T
        vel = 5e-13
        if frame == "inertial":
            assert row[5] - 150.0 == pytest.approx(k * leak, rel=1e-3, abs=0)
            row = row.copy()
            row[5] = 150.0
            # which the north row's Coriolis and transport terms, (2 Omega + v_E/R) at most, turn north
            vel += (2.0 * OMEGA + 150.0 / r_e) * abs(k * leak) * t / 2.0
        check_row(row, t, LAT0, LON0 + 150.0 * t / ((r_e + H0) * math.cos(LAT0)), H0, [0.0, 150.0, 0.0], c,
                  pos=2e-15, hm=2e-8, vel=vel, att=2e-14)
    rows, _ = steady_run(frame, LAT0, 150.0, bias=-0.5)
    t = 2 * DT * np.arange(1, 13)
    # f_D 0.5 m/s^2 too low (more negative): v_D = -0.5 t, h = h0 + 0.25 t^2 (trapezoid: exact), but for the
    # gravity gradient 2 gamma/a = 3.1e-6 s^-2 over the climb (< 2e-9 m/s by t = 0.19 s); the inertial
    # frame's height to the ulp of |r| (9e-10 m)
    np.testing.assert_allclose(rows[:, 6], -0.5 * t, rtol=0, atol=1e-8)
    np.testing.assert_allclose(rows[:, 3], H0 + 0.25 * t * t, rtol=0, atol=4e-9)


@pytest.mark.parametrize("l_every", [1, 3])
@pytest.mark.parametrize("samples", [1, 3, 6])
def test_samples_and_l_every_in_steady_flight(samples, l_every):
    """Constant sensors: every N and M give the same closed form, one row per N samples (the trailing
    samples that do not fill an update are not used)."""
    n = 20
    rows, c = steady_run("geographic", LAT0, 150.0, n=n, samples=samples, l_every=l_every)
    assert len(rows) == n // samples
    r_e = radii(LAT0)[1]
    for k, row in enumerate(rows, 1):
        t = samples * k * DT
        check_row(row, t, LAT0, LON0 + 150.0 * t / ((r_e + H0) * math.cos(LAT0)), H0, [0.0, 150.0, 0.0], c,
                  pos=2e-15, hm=2e-8, vel=5e-13, att=2e-14)


# --- laboratory mode ------------------------------------------------------------------------------
def lab_position(pn, pe, pd):
    """earth = none: the NED offset through the start point's radii (docs/conventions.md)."""
    r_n, r_e = radii(LAT0)
    return LAT0 + pn / (r_n + H0), LON0 + pe / ((r_e + H0) * math.cos(LAT0)), H0 - pd


A_N = np.array([0.7, -0.4, 0.25])
V0 = np.array([1.5, -2.0, 0.5])


@pytest.mark.parametrize("attitude", ["quaternion", "dcm"])
@pytest.mark.parametrize("rule", ["rectangular", "trapezoidal", "simpson"])
def test_constant_acceleration(rule, attitude):
    """v = v0 + a t; position after k updates of T: rectangular v0 t + a T^2 k(k-1)/2, trapezoidal v0 t +
    a t^2/2, Simpson (-v(k-2) + 8 v(k-1) + 5 v(k))/12 T with v(-1) = v0: v0 t + a T^2 (k^2/2 - 1/12)
    (docs/conventions.md "Position rules"; test_contract_cli's closed forms)."""
    c = cbn(*ATT)
    g = float(gamma(LAT0, H0))
    f = c.T @ (A_N - np.array([0.0, 0.0, g]))  # f = a - g (docs/conventions.md "Sensor data")
    n = 30
    cfg = sd.make_config(samples=3, earth_model="none", position=rule, attitude=attitude)
    s = sd.init_state(0.0, LAT0, LON0, H0, V0.copy(), *ATT)
    rows = run(cfg, s, DT * np.arange(1, n + 1), np.zeros((n, 3)), np.tile(f * DT, (n, 1)))
    assert len(rows) == 10
    assert for_frame(sd.position, sd.GEOGRAPHIC)(s, cfg) == tuple(rows[-1][1:4])  # what the filter reads
    T = 3 * DT
    for k, row in enumerate(rows, 1):
        t = k * T
        extra = {"rectangular": k * (k - 1) / 2, "trapezoidal": k * k / 2, "simpson": k * k / 2 - 1 / 12}[rule]
        p = V0 * t + A_N * T * T * extra
        check_row(row, t, *lab_position(*p), V0 + A_N * t, c, pos=1e-16, hm=1e-12, vel=2e-14, att=1e-15)


def test_constant_acceleration_vertical_hold():
    """--vertical hold: h = h0 and v_D = the initial v_D, the horizontal as without it (trapezoid)."""
    c = cbn(*ATT)
    f = c.T @ (A_N - np.array([0.0, 0.0, float(gamma(LAT0, H0))]))
    n = 12
    cfg = sd.make_config(earth_model="none", vertical="hold")
    s = sd.init_state(0.0, LAT0, LON0, H0, V0.copy(), *ATT)
    rows = run(cfg, s, DT * np.arange(1, n + 1), np.zeros((n, 3)), np.tile(f * DT, (n, 1)))
    for k, row in enumerate(rows, 1):
        t = 2 * k * DT
        p = V0 * t + A_N * t * t / 2
        lat, lon, _ = lab_position(*p)
        check_row(row, t, lat, lon, H0, [V0[0] + A_N[0] * t, V0[1] + A_N[1] * t, V0[2]], c,
                  pos=1e-16, hm=0.0, vel=2e-14, att=1e-15)


# N-sample coning/sculling coefficients, oldest sample first (docs/conventions.md --samples)
CONING = {1: [], 2: [2 / 3], 3: [9 / 20, 27 / 20], 4: [54 / 105, 92 / 105, 214 / 105],
          5: [250 / 504, 525 / 504, 650 / 504, 1375 / 504],
          6: [2315 / 4620, 4558 / 4620, 7296 / 4620, 7834 / 4620, 15797 / 4620]}
TH = np.array([[0.011, -0.023, 0.017], [-0.019, 0.008, 0.026], [0.021, 0.015, -0.012], [0.004, -0.027, -0.02],
               [-0.016, 0.022, 0.009], [0.025, 0.003, 0.018]])
DV = np.array([[0.031, -0.052, -0.077], [0.064, 0.011, -0.081], [-0.027, 0.045, -0.069], [0.018, -0.036, -0.09],
               [0.052, 0.029, -0.072], [-0.041, 0.013, -0.085]])


def one_update(samples, th, dv, coning=True, attitude="quaternion", order="exact"):
    """One update of the lab frame from ATT and V0 over increments th, dv; the rows and the state."""
    cfg = sd.make_config(samples=samples, earth_model="none", coning=coning, attitude=attitude, order=order,
                         orthonormalize_every=0)
    s = sd.init_state(0.0, LAT0, LON0, H0, V0.copy(), *ATT)
    return run(cfg, s, DT * np.arange(1, samples + 1), th, dv), s


def lab_expect(sigma, dv_body, scul, T, c_body=None):
    """One update from rest of the lab frame: C1 = C0 B(sigma), v1 = v0 + C0 (V + rot + scul) + g T,
    trapezoidal position."""
    c0 = cbn(*ATT)
    c1 = c0 @ (expm(sigma) if c_body is None else c_body)
    v1 = V0 + c0 @ (dv_body + savage(sigma, dv_body) + scul) + np.array([0.0, 0.0, float(gamma(LAT0, H0))]) * T
    p = (V0 + v1) / 2 * T
    return lab_position(*p), v1, c1


@pytest.mark.parametrize("attitude", ["quaternion", "dcm"])
@pytest.mark.parametrize("coning", [True, False])
@pytest.mark.parametrize("samples", [1, 2, 3, 4, 5, 6])
def test_one_update_of_n_samples(samples, coning, attitude):
    """sigma = sum dtheta + [sum_{i<N} k_i dtheta_i] x dtheta_N; sculling sum_{i<N} k_i (dtheta_i x dv_N + dv_i x
    dtheta_N) (the same coefficients); none for N = 1 or --no-coning (docs/conventions.md --samples)."""
    th, dv = TH[:samples], DV[:samples]
    rows, _ = one_update(samples, th, dv, coning, attitude)
    assert len(rows) == 1
    k = CONING[samples] if coning else []
    sigma = th.sum(0) + sum((k[i] * np.cross(th[i], th[-1]) for i in range(len(k))), np.zeros(3))
    scul = sum((k[i] * (np.cross(th[i], dv[-1]) + np.cross(dv[i], th[-1])) for i in range(len(k))), np.zeros(3))
    pos, v1, c1 = lab_expect(sigma, dv.sum(0), scul, samples * DT)
    check_row(rows[0], samples * DT, *pos, v1, c1, pos=1e-16, hm=1e-12, vel=1e-15, att=1e-15)


def quat_table(order, s2):
    """(a_c, a_s) of docs/conventions.md --order (quaternion)."""
    return {1: (1.0, 0.5), 2: (1 - s2 / 8, 0.5), 3: (1 - s2 / 8, 0.5 - s2 / 48),
            4: (1 - s2 / 8 + s2 * s2 / 384, 0.5 - s2 / 48)}[order]


def dcm_table(order, s2):
    """(a1, a2) of docs/conventions.md --order (DCM)."""
    return {1: (1.0, 0.0), 2: (1.0, 0.5), 3: (1 - s2 / 6, 0.5), 4: (1 - s2 / 6, 0.5 - s2 / 24)}[order]


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("attitude", ["quaternion", "dcm"])
def test_one_update_truncated_orders(order, attitude):
    """A 0.14 rad body rotation: the update is C0 (I + a1 [s x] + a2 [s x]^2) (DCM, never re-orthonormalised) or
    q0 (x) [a_c, a_s sigma], normalised (quaternion)."""
    th, dv = TH[:2] * 3, DV[:2]
    rows, st = one_update(2, th, dv, True, attitude, str(order))
    sigma = th.sum(0) + 2 / 3 * np.cross(th[0], th[1])
    scul = 2 / 3 * (np.cross(th[0], dv[1]) + np.cross(dv[0], th[1]))
    s2 = float(sigma @ sigma)
    if attitude == "dcm":
        a1, a2 = dcm_table(order, s2)
        body = np.eye(3) + a1 * skew(sigma) + a2 * skew(sigma) @ skew(sigma)
    else:
        ac, as_ = quat_table(order, s2)
        r = np.concatenate(([ac], as_ * sigma))
        body = dcm_of_quat(r / np.linalg.norm(r))
    pos, v1, c1 = lab_expect(sigma, dv.sum(0), scul, 2 * DT, c_body=body)
    row = rows[0]
    if attitude == "quaternion":
        check_row(row, 2 * DT, *pos, v1, c1, pos=1e-16, hm=1e-12, vel=1e-15, att=1e-15)
    else:  # C is not a rotation: compare it in the state, and what the row reports of it
        np.testing.assert_allclose(row[1:7], [*pos, *v1], rtol=0, atol=1e-15)
        np.testing.assert_allclose(st[sd.S.C:sd.S.C + 9], c1.ravel(), rtol=0, atol=1e-15)
        assert row[7] == pytest.approx(math.atan2(c1[2, 1], c1[2, 2]), abs=1e-15)
        assert row[9] == pytest.approx(math.atan2(c1[1, 0], c1[0, 0]), abs=1e-15)


@pytest.mark.parametrize("attitude", ["quaternion", "dcm"])
@pytest.mark.parametrize("order", [0, 1, 2, 3, 4])
@pytest.mark.parametrize("step", [0.45, 0.004])
def test_rotation_about_one_axis(step, order, attitude):
    """Eight updates of a rotation s about body x from level, north: the attitude is Rx(8 theta) with theta
    = s (exact), 2 atan(a_s s/a_c) (quaternion, normalised each update) or atan(a1 s/(1 - a2 s^2)) (DCM:
    the unnormalised update scales the y-z block by r = |(1 - a2 s^2, a1 s)| each time; never
    re-orthonormalised here). 8 x 0.45 rad passes half a turn: the reported quaternion keeps q_w >= 0."""
    n = 8
    cfg = sd.make_config(samples=1, earth_model="none", attitude=attitude, order=str(order) if order else "exact",
                         orthonormalize_every=0)
    s = sd.init_state(0.0, LAT0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
    g = float(gamma(LAT0, H0))
    rows = run(cfg, s, DT * np.arange(1, n + 1), np.tile([step, 0.0, 0.0], (n, 1)), np.zeros((n, 3)))  # free fall
    s2 = step * step
    if order == 0:
        theta, r = step, 1.0
    elif attitude == "quaternion":
        ac, as_ = quat_table(order, s2)
        theta, r = 2 * math.atan2(as_ * step, ac), 1.0
    else:
        a1, a2 = dcm_table(order, s2)
        theta, r = math.atan2(a1 * step, 1 - a2 * s2), math.hypot(1 - a2 * s2, a1 * step)
    for k, row in enumerate(rows, 1):
        ang = k * theta
        assert row[7] == pytest.approx(wrap(ang), abs=4e-15 * k)
        assert row[8] == 0.0 and row[9] == 0.0
        np.testing.assert_allclose(row[4:7], [0.0, 0.0, g * k * DT], rtol=0, atol=1e-15)
        if attitude == "quaternion":
            q = np.array([math.cos(ang / 2), math.sin(ang / 2), 0.0, 0.0])
            q = -q if q[0] < 0 else q
            assert row[10] >= 0.0
            np.testing.assert_allclose(row[10:14], q, rtol=0, atol=4e-15 * k)
        else:
            cst = s[sd.S.C:sd.S.C + 9] if k == n else None
            if cst is not None:
                want = r ** k * np.array([1.0 / r ** k, 0, 0, 0, math.cos(ang), -math.sin(ang), 0, math.sin(ang),
                                          math.cos(ang)])
                np.testing.assert_allclose(cst, want, rtol=0, atol=1e-14 * r ** k)


@pytest.mark.parametrize("every", [1, 3])
def test_dcm_reorthonormalisation_schedule(every):
    """--orthonormalize-every K with the first-order DCM update: C <- C - 1/2 (C C^T - I) C ([TW11] 11.2.1,
    orthogonalisation) after updates K, 2K, ...; the update's own growth r = sqrt(1 + s^2) otherwise."""
    n, step = 6, 0.05
    cfg = sd.make_config(samples=1, earth_model="none", attitude="dcm", order="1", orthonormalize_every=every)
    s = sd.init_state(0.0, LAT0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
    body = np.eye(3) + skew([step, 0.0, 0.0])
    c = np.eye(3)
    f = for_frame(sd.push_increment, sd.GEOGRAPHIC)
    for k in range(1, n + 1):
        assert f(s, cfg, k * DT, np.array([step, 0.0, 0.0]), np.zeros(3)) == 1
        c = c @ body
        if k % every == 0:
            c = c - 0.5 * (c @ c.T - np.eye(3)) @ c
        np.testing.assert_allclose(s[sd.S.C:sd.S.C + 9], c.ravel(), rtol=0, atol=1e-15)


# --- rates: averaged and sampled ----------------------------------------------------------------
W0, W1 = 0.3, 2.0  # rad/s, rad/s^2: w_x(t) = W0 + W1 t


@pytest.mark.parametrize("first_at_t0", [True, False])
@pytest.mark.parametrize("mode", ["sampled", "averaged"])
def test_rate_ramp_about_one_axis(mode, first_at_t0):
    """A linear rate about body x: sampled, the trapezoid increments integrate it exactly, roll = W0 t + W1 t^2/2;
    averaged, each row is the mean over its interval, roll = sum w(t_i) dt (docs/conventions.md "Files", IMU
    rates). Without a row at the start time the first sampled row holds back to it. Rows before the start are
    skipped (-1 s here)."""
    n = 8
    cfg = sd.make_config(samples=2, earth_model="none", imu_rates=mode)
    s = sd.init_state(0.0, LAT0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
    t = DT * np.arange(0 if first_at_t0 else 1, n + 1)
    t = np.concatenate(([-1.0], t))
    w = np.zeros((len(t), 3))
    w[:, 0] = W0 + W1 * t
    w[0, 0] = 50.0  # before the start: ignored
    g = float(gamma(LAT0, H0))
    f = np.zeros((len(t), 3))  # free fall: v = [0, 0, gamma t]
    out = np.full((len(t), 14), np.nan)
    m = sd.run_rates(s, cfg, t, w, f, out)
    assert m == 4
    for k, row in enumerate(out[:m], 1):
        tk = 2 * k * DT
        if mode == "averaged":
            ts = DT * np.arange(1, 2 * k + 1)
            roll = float(np.sum(W0 + W1 * ts) * DT)
        elif first_at_t0:
            roll = W0 * tk + W1 * tk * tk / 2
        else:
            roll = W0 * tk + W1 * tk * tk / 2 + W1 * DT * DT / 2  # w(dt) held over (0, dt]
        assert row[0] == tk
        assert row[7] == pytest.approx(roll, rel=0, abs=4e-15)
        np.testing.assert_allclose(row[4:7], [0.0, 0.0, g * tk], rtol=0, atol=1e-15)


def sampled_sums(w, f, h):
    """The piecewise-linear sampled-rate sums of docs/algorithms.md ("Sampled rates"): per sample j,
    dtheta_j = (w0 + w1) h/2, dv_j likewise, coning += 1/2 alpha_{j-1} x dtheta_j + h^2/12 w0 x w1,
    sculling += 1/2 (alpha_{j-1} x dv_j + v_{j-1} x dtheta_j) + h^2/12 (w0 x f1 + f0 x w1)."""
    al, ve, co, sc = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    for j in range(1, len(w)):
        dth, dvj = (w[j - 1] + w[j]) * h / 2, (f[j - 1] + f[j]) * h / 2
        co = co + 0.5 * np.cross(al, dth) + h * h / 12 * np.cross(w[j - 1], w[j])
        sc = sc + 0.5 * (np.cross(al, dvj) + np.cross(ve, dth)) + h * h / 12 * (np.cross(w[j - 1], f[j]) +
                                                                             np.cross(f[j - 1], w[j]))
        al, ve = al + dth, ve + dvj
    return al, ve, co, sc


WS = np.array([[1.3, -2.1, 0.7], [-0.9, 1.8, 2.4], [2.2, 0.6, -1.5], [0.4, -1.7, 1.1], [-1.6, 0.3, 2.0],
               [0.8, 2.5, -0.6], [-2.0, -0.4, 1.4]])
FS = np.array([[2.1, -3.3, -9.0], [-1.2, 4.4, -10.6], [3.6, 0.8, -8.1], [-2.5, 1.9, -9.9], [1.7, -2.2, -9.4],
               [-0.6, 3.1, -10.2], [2.8, -1.4, -8.7]])


@pytest.mark.parametrize("samples", [1, 2, 3])
def test_sampled_rates_two_updates(samples):
    """Instantaneous samples at 0, dt, ..., 2N dt: each update's sigma = alpha + coning, V = sum dv, sculling as
    docs/algorithms.md, the sums starting afresh at each update from its first interval (whose start sample is the
    last one of the update before); N = 1 applies neither. Lab frame: C_k = C_k-1 exp([sigma_k x]), v_k = v_k-1 +
    C_k-1 (V_k + rot + scul_k) + g T, trapezoidal position."""
    w, f = WS[:2 * samples + 1], FS[:2 * samples + 1]
    cfg = sd.make_config(samples=samples, earth_model="none", imu_rates="sampled")
    s = sd.init_state(0.0, LAT0, LON0, H0, V0.copy(), *ATT)
    out = np.full((4, 14), np.nan)
    rows = out[:sd.run_rates(s, cfg, DT * np.arange(2 * samples + 1), w, f, out)]
    assert len(rows) == 2
    T = samples * DT
    c, v, p = cbn(*ATT), V0.copy(), np.zeros(3)
    for k in range(2):
        al, vv, co, sc = sampled_sums(w[k * samples:(k + 1) * samples + 1], f[k * samples:(k + 1) * samples + 1], DT)
        if samples == 1:
            co, sc = np.zeros(3), np.zeros(3)
        sigma = al + co
        v1 = v + c @ (vv + savage(sigma, vv) + sc) + np.array([0.0, 0.0, float(gamma(LAT0, H0))]) * T
        p = p + (v + v1) / 2 * T
        c, v = c @ expm(sigma), v1
        check_row(rows[k], (k + 1) * T, *lab_position(*p), v, c, pos=1e-16, hm=1e-12, vel=4e-15, att=2e-15)


def test_body_to_nav_is_the_states_attitude_live():
    """strapdown.body_to_nav: the state's C_b^n row-major, the Euler product of its initial angles, and a view:
    what an update writes, the engine's next read sees."""
    s = sd.init_state(0.0, LAT0, LON0, H0, np.zeros(3), 0.3, -0.2, 1.1)
    c = sd.body_to_nav(s)
    np.testing.assert_allclose(c.reshape(3, 3), cbn(0.3, -0.2, 1.1), rtol=0, atol=4e-16)
    cfg = sd.make_config(samples=1)
    push = for_frame(sd.push_increment, sd.GEOGRAPHIC)
    push(s, cfg, 0.01, np.array([0.0, 0.0, 0.05]), np.zeros(3))  # turned 0.05 rad about body z
    assert c[0] == sd.body_to_nav(s)[0] and abs(math.atan2(c[3], c[0]) - 1.1) > 0.04


# --- the j cycle: return codes, clocks -------------------------------------------------------------
def test_return_codes_and_clock():
    """1: an update done, 0: buffered, -1: t not after the last accepted sample (strapdown.push_increment)."""
    cfg = sd.make_config(samples=2, earth_model="none")
    s = sd.init_state(5.0, LAT0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
    push = for_frame(sd.push_increment, sd.GEOGRAPHIC)
    z = g = np.zeros(3)  # free fall: v_D = gamma times the integrated time
    gm = float(gamma(LAT0, H0))
    assert sd.state_time(s) == 5.0
    assert push(s, cfg, 5.0, z, g) == -1
    assert push(s, cfg, 4.0, z, g) == -1
    assert push(s, cfg, 5.0 + DT, z, g) == 0
    assert push(s, cfg, 5.0 + DT, z, g) == -1
    assert sd.state_time(s) == 5.0
    assert push(s, cfg, 5.0 + 2 * DT, z, g) == 1
    assert sd.state_time(s) == 5.0 + 2 * DT
    pushs = for_frame(sd.push_increment_s, sd.GEOGRAPHIC)
    assert pushs(s, cfg, 5.0 + 3 * DT, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) == 0
    # skip_to: the clock moves on (never back); the next sample covers only its own interval
    sd.skip_to(s, 4.0)
    assert push(s, cfg, 5.0 + 3 * DT, z, g) == -1
    sd.skip_to(s, 7.0)
    assert push(s, cfg, 7.0, z, g) == -1
    assert push(s, cfg, 7.0 + DT, np.array([0.01, 0.0, 0.0]), g) == 1
    assert sd.state_time(s) == 7.0 + DT
    row = np.empty(14)
    for_frame(sd.solution_row, sd.GEOGRAPHIC)(s, cfg, row)
    assert row[0] == 7.0 + DT and row[7] == pytest.approx(0.01, abs=1e-17)
    # two updates of 2 dt each (the second: dt before the skip, dt after it); the skipped time not integrated
    np.testing.assert_allclose(row[4:7], [0.0, 0.0, 4 * DT * gm], rtol=0, atol=1e-15)


def test_rate_codes():
    """Averaged rates: dtheta = w dt; sampled: a sample at the start only opens the interval (0), one before it or
    a repeated time is rejected (-1); after skip_to a sampled stream opens a fresh interval."""
    g = z = np.zeros(3)  # free fall
    gm = float(gamma(LAT0, H0))
    cfg = sd.make_config(samples=1, earth_model="none")
    s = sd.init_state(1.0, LAT0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
    push = for_frame(sd.push_rate, sd.GEOGRAPHIC)
    assert push(s, cfg, 1.0, z, g) == -1
    assert push(s, cfg, 0.5, z, g) == -1
    assert push(s, cfg, 1.0 + DT, np.array([2.0, 0.0, 0.0]), g) == 1
    row = np.empty(14)
    for_frame(sd.solution_row, sd.GEOGRAPHIC)(s, cfg, row)
    assert row[7] == 2.0 * DT
    cfg = sd.make_config(samples=1, earth_model="none", imu_rates="sampled")
    s = sd.init_state(1.0, LAT0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
    pushs = for_frame(sd.push_rate_scalars, sd.GEOGRAPHIC)
    assert pushs(s, cfg, 0.5, 0.0, 0.0, 0.0, *g) == -1
    assert pushs(s, cfg, 1.0, 1.0, 0.0, 0.0, *g) == 0
    assert pushs(s, cfg, 1.0, 1.0, 0.0, 0.0, *g) == -1
    assert pushs(s, cfg, 1.0 + DT, 3.0, 0.0, 0.0, *g) == 1
    for_frame(sd.solution_row, sd.GEOGRAPHIC)(s, cfg, row)
    assert row[7] == 2.0 * DT  # (1 + 3)/2 dt
    assert pushs(s, cfg, 1.0 + DT, 100.0, 0.0, 0.0, *g) == -1  # rejected: the next interval starts from 3
    assert pushs(s, cfg, 1.0 + 2 * DT, 3.0, 0.0, 0.0, *g) == 1
    for_frame(sd.solution_row, sd.GEOGRAPHIC)(s, cfg, row)
    assert row[7] == pytest.approx(5.0 * DT, abs=1e-16)
    sd.skip_to(s, 2.0)
    assert pushs(s, cfg, 2.0, 5.0, 0.0, 0.0, *g) == 0  # opens a fresh interval at the new clock
    assert pushs(s, cfg, 2.0 + DT, 7.0, 0.0, 0.0, *g) == 1
    for_frame(sd.solution_row, sd.GEOGRAPHIC)(s, cfg, row)
    assert row[7] == pytest.approx(5.0 * DT + 6.0 * DT, abs=1e-16)
    np.testing.assert_allclose(row[4:7], [0.0, 0.0, 3 * DT * gm], rtol=0, atol=1e-15)


def test_fresh_state_row_and_position():
    """Before any update every frame reports the initial state."""
    v = np.array([3.0, -4.0, 0.5])
    for frame in FRAMES:
        cfg = sd.make_config(frame=frame)
        s = sd.init_state(2.5, LAT0, LON0, H0, v.copy(), *ATT)
        kf = sd.kernel_frame(cfg)
        lat, lon, h = for_frame(sd.position, kf)(s, cfg)
        assert (lat, lon, h) == pytest.approx((LAT0, LON0, H0), rel=0, abs=1e-15)
        row = np.empty(14)
        for_frame(sd.solution_row, kf)(s, cfg, row)
        check_row(row, 2.5, LAT0, LON0, H0, v, cbn(*ATT), pos=1e-15, hm=1e-9, vel=1e-14, att=1e-15)
    cfg = sd.make_config(earth_model="none")
    s = sd.init_state(2.5, LAT0, LON0, H0, v.copy(), *ATT)
    assert for_frame(sd.position, 0)(s, cfg) == pytest.approx((LAT0, LON0, H0), rel=0, abs=1e-15)


# --- the geographic frame's latitude limit -----------------------------------------------------------
LIMIT = math.radians(89.5)  # docs/conventions.md "--frame": |lat| 89.5 deg


def test_frame_limit():
    """Beyond |lat| 89.5 deg the geographic frame flags the state with the time of the update that went there."""
    for lat0, vn, flagged in ((LIMIT - 1e-7, 200.0, True), (LIMIT - 1e-6, 200.0, False),
                              (-LIMIT + 1e-7, -200.0, True), (LIMIT - 1e-7, -200.0, False)):
        w, f, c = steady_sensors(lat0, H0, 0.0, (0.0, 0.0, 0.0))
        cfg = sd.make_config()
        s = sd.init_state(3.0, lat0, LON0, H0, np.array([vn, 0.0, 0.0]), 0.0, 0.0, 0.0)
        assert sd.frame_limit(s) is None
        n = 4
        run(cfg, s, 3.0 + DT * np.arange(1, n + 1), np.tile(w * DT, (n, 1)), np.tile(f * DT, (n, 1)))
        # the first update's mid-latitude lat0 + T/2 vn/(R_N + h) (1.2e-7 rad) is beyond for the first two
        assert sd.frame_limit(s) == (3.0 if flagged else None)
    for lat0 in (LIMIT, -LIMIT):  # exactly at the limit is not beyond it
        w, f, c = steady_sensors(lat0, H0, 0.0, (0.0, 0.0, 0.0))
        s = sd.init_state(3.0, lat0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
        run(sd.make_config(), s, 3.0 + DT * np.arange(1, 3), np.tile(w * DT, (2, 1)), np.tile(f * DT, (2, 1)))
        assert sd.frame_limit(s) is None


@pytest.mark.parametrize("lat", [-math.radians(89.7), math.radians(89.7)])
def test_clamped_beyond_the_limit(lat):
    """At rest at 89.7 deg the Earth rate and gravity are taken at +-89.5 deg (the sign of the latitude): the
    attitude then turns by (w_ie(89.5) - w_ie(89.7)) t, below 3e-7 rad/s, and v_D grows by (gamma(89.5) -
    gamma(89.7)) t."""
    w, f, c = steady_sensors(lat, H0, 0.0, ATT)
    cfg = sd.make_config()
    s = sd.init_state(0.0, lat, LON0, H0, np.zeros(3), *ATT)
    n = 16
    rows = run(cfg, s, DT * np.arange(1, n + 1), np.tile(w * DT, (n, 1)), np.tile(f * DT, (n, 1)))
    assert sd.frame_limit(s) == 0.0
    lim = math.copysign(LIMIT, lat)
    dg = float(gamma(lim, H0) - gamma(lat, H0))
    for k, row in enumerate(rows, 1):
        t = 2 * k * DT
        assert row[6] == pytest.approx(dg * t, rel=1e-3, abs=1e-14)
        assert np.max(np.abs(wrap(row[7:10] - np.array(ATT)))) < 3e-7 * t + 1e-14


def test_velocity_step():
    """One velocity update as docs/algorithms.md writes it: v(k) = v(k-1) + (I - 1/2 [zeta x] + 1/12 [zeta x]^2 +
    1/12 [dzeta x]) C_b^n (V + rot(sigma, V) + dv_scul) + [g - (2 w_ie + w_en) x v_mid] T (Savage's frame rotation
    to second order, [SAV98] part 2), with rates and angles large enough that every term shows: the kernel
    drops the third-order 1/72 zeta x (dzeta x u), which bounds the difference."""
    s = sd.init_state(0.0, LAT0, LON0, H0, np.array([12.0, -7.0, 1.5]), *ATT)
    w_ie, w_en, g = np.array([3e-4, -1e-4, -2e-4]), np.array([1e-4, 2e-4, -3e-4]), 9.81
    s[sd.S.WIE:sd.S.WIE + 3], s[sd.S.WEN:sd.S.WEN + 3], s[sd.S.G] = w_ie, w_en, g
    T = 0.25
    sigma, dv, scul = np.array([0.02, -0.01, 0.03]), np.array([0.4, -0.3, -2.4]), np.array([1e-3, -2e-3, 5e-4])
    zeta, dzeta, vm = np.array([2e-3, -1e-3, 1.5e-3]), np.array([1e-5, 2e-5, -1e-5]), np.array([13.0, -6.0, 1.0])
    got = np.array(sd._velocity_step(s, T, *sigma, *dv, *scul, *zeta, *dzeta, *vm))
    u = cbn(*ATT) @ (dv + savage(sigma, dv) + scul)
    u = u - 0.5 * np.cross(zeta, u) + np.cross(zeta, np.cross(zeta, u)) / 12 + np.cross(dzeta, u) / 12
    want = np.array([12.0, -7.0, 1.5]) + u + (np.array([0.0, 0.0, g]) - np.cross(2 * w_ie + w_en, vm)) * T
    tol = np.linalg.norm(zeta) * np.linalg.norm(dzeta) * np.linalg.norm(u) / 72 + 1e-14
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)


def test_init_state_slots():
    """A fresh state holds the initial values where the kernels read them (strapdown.py's state layout): time, C_b^n and
    q_nb of ATT (ZYX), v (also as the update before), C_n^e of lat/lon ([TW11] 3.4), h, the start point, gravity
    there (Somigliana) and 1/(R_N + h), which places the first update's mid-interval latitude."""
    v = np.array([3.0, -4.0, 0.5])
    s = sd.init_state(2.5, LAT0, LON0, H0, v, *ATT)
    assert s.shape == (131,) and s[sd.S.T] == 2.5 and s[sd.S.TJ] == 2.5
    c = cbn(*ATT)
    np.testing.assert_allclose(s[sd.S.C:sd.S.C + 9], c.ravel(), rtol=0, atol=4e-16)
    np.testing.assert_allclose(dcm_of_quat(s[sd.S.Q:sd.S.Q + 4]), c, rtol=0, atol=1e-15)
    assert s[sd.S.Q] > 0.0
    assert list(s[sd.S.V:sd.S.V + 3]) == list(v) and list(s[sd.S.VP:sd.S.VP + 3]) == list(v)
    np.testing.assert_allclose(s[sd.S.CNE:sd.S.CNE + 9], cne(LAT0, LON0).ravel(), rtol=0, atol=2e-16)
    assert (s[sd.S.H], s[sd.S.LAT0], s[sd.S.LON0], s[sd.S.H0], s[sd.S.VD0]) == (H0, LAT0, LON0, H0, 0.5)
    assert (s[sd.S.LATC], s[sd.S.LONC]) == (LAT0, LON0)
    assert s[sd.S.G0] == pytest.approx(float(gamma(LAT0, H0)), rel=4e-16, abs=0)
    assert s[sd.S.KN] == pytest.approx(1.0 / (radii(LAT0)[0] + H0), rel=4e-16, abs=0)
    assert s[sd.S.NK] == 0.0 and s[sd.S.NJ] == 0.0 and s[sd.S.NL] == 0.0 and s[sd.S.INI] == 0.0


@pytest.mark.parametrize("frame,l_every", [("geographic", 1), ("geographic", 2), ("geographic", 3), ("wander", 1),
                                           ("wander", 3),
                                           ("free", 1), ("inertial", 1)])
def test_vertical_flight(frame, l_every):
    """Climbing straight up at 8 m/s from rest horizontally: f^n = 2 w_ie x v - [0, 0, gamma(h(t))] (w_en = 0), each
    increment's gravity integrated exactly (Simpson: gamma is quadratic in h, h linear in t), so v, lat, lon stay
    and h = h0 + 8 t to round-off. With --l-every M gravity is taken at the mid-interval height of the l cycle
    and held for M updates (docs/conventions.md "Mid-interval terms"): update j then gains (gamma(h_l) -
    gamma(h_j)) T of v_D, h_j = h0 + 8 (j - 1/2) T its own mid-interval height, l = the update that last ran
    the l cycle; that v_D error meets the Coriolis term, 2 Omega cos L |dv_D| of v_E per second at most."""
    vd, n, samples = -8.0, 24, 2
    c = cbn(*ATT)
    w_ie = np.array([OMEGA * math.cos(LAT0), 0.0, -OMEGA * math.sin(LAT0)])
    cor = np.cross(2 * w_ie, [0.0, 0.0, vd])
    t = DT * np.arange(n + 1)
    hgt = lambda tt: H0 - vd * tt  # noqa: E731
    g_int = DT / 6 * (gamma(LAT0, hgt(t[:-1])) + 4 * gamma(LAT0, hgt(t[:-1] + DT / 2)) + gamma(LAT0, hgt(t[1:])))
    dv = np.array([c.T @ (cor * DT - np.array([0.0, 0.0, gi])) for gi in g_int])
    cfg = sd.make_config(samples=samples, frame=frame, l_every=l_every)
    s = sd.init_state(0.0, LAT0, LON0, H0, np.array([0.0, 0.0, vd]), *ATT)
    rows = run(cfg, s, t[1:], np.tile(c.T @ w_ie * DT, (n, 1)), dv)
    T = samples * DT
    vz, h = vd, H0
    for j, row in enumerate(rows, 1):
        jl = (j - 1) // l_every * l_every + 1
        vz_new = vz + float(gamma(LAT0, H0 - vd * (jl - 0.5) * T) - gamma(LAT0, H0 - vd * (j - 0.5) * T)) * T
        h -= (vz + vz_new) / 2 * T  # trapezoidal rule
        vz = vz_new
        # inertial: r^i += v T rounds to the ulp of |r^i| (9.3e-10 m) at each update, and |v^i| (330 m/s) has an
        # ulp of 5.7e-14 m/s; else ~1 ulp of h and v per update
        hm, vel = (1e-9 * j, 4e-13) if frame == "inertial" else (1e-10, 2e-14)
        vel += 2 * OMEGA * math.cos(LAT0) * abs(vz - vd) * j * T
        check_row(row, j * T, LAT0, LON0, h, [0, 0, vz], c, pos=2e-15, hm=hm, vel=vel, att=2e-14)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("lat,accel,att", [(0.0, 20.0, ATT), (0.0, 0.0, (0.0, 0.0, 0.0)), (LAT0, 20.0, ATT)])
def test_east_acceleration_along_a_parallel(frame, lat, accel, att):
    """From rest, accelerating due east at a along a parallel (h fixed): v_E = a t, lon = lon0 + a t^2/(2 R cos L),
    R = R_E + h; the frame rate w_in = [Omega cos L + v_E/R, 0, -Omega sin L - v_E tan L/R] grows each update, so
    the velocity step's 1/12 dzeta term and the mid-interval extrapolation are exercised with a closed form.
    Sensors: w^b = C_n^b w_in (linear in t: its increments exact), f^n = (2 w_ie + w_en) x v + [0, a, -gamma]
    (quadratic in t: Simpson exact). The Coriolis term at v_mid = v(t + T/2) misses T^3/24 of its second derivative
    (2e-14 m/s per update), the third-order terms of the rate ramp (below). Level and north at the equator with
    a = 0: rest, where the inertial frame's ECI z velocity stays exactly 0."""
    c = cbn(*att)
    big_r = radii(lat)[1] + H0
    sl, cl, tl = math.sin(lat), math.cos(lat), math.tan(lat)
    g = float(gamma(lat, H0))
    n = 16
    t = DT * np.arange(n + 1)
    ve = accel * t

    def f_n(v):
        return np.array([(2 * OMEGA * sl + v * tl / big_r) * v, accel, (2 * OMEGA * cl + v / big_r) * v - g])

    w_int = np.array([c.T @ (np.array([OMEGA * cl, 0.0, -OMEGA * sl]) * DT
                             + (ve[i] + ve[i + 1]) / 2 * DT / big_r * np.array([1.0, 0.0, -tl])) for i in range(n)])
    dv = np.array([c.T @ (DT / 6 * (f_n(ve[i]) + 4 * f_n((ve[i] + ve[i + 1]) / 2) + f_n(ve[i + 1]))) for i in range(n)])
    cfg = sd.make_config(frame=frame)
    s = sd.init_state(0.0, lat, LON0, H0, np.zeros(3), *att)
    rows = run(cfg, s, t[1:], w_int, dv)
    assert len(rows) == n // 2
    for k, row in enumerate(rows, 1):
        tk = 2 * k * DT
        # inertial: the ulp of |v^i| (465 m/s), 5.7e-14. The updates are exact to second order in T; the third-order
        # terms of the rate ramp |dw/dt| = a/(R cos L), 1/12 T^3 dw/dt x f for the body's and again for the frame's
        # rotation (docs/algorithms.md), bound what is left: |dw/dt| |f| T^3/6 per update (the first update, with no
        # earlier frame rate, has no dzeta at all: the same size)
        ramp = accel / (big_r * cl) * math.hypot(accel, g) * (2 * DT)**3 / 6
        vel = (4e-13 if frame == "inertial" else 2e-14 * k) + k * ramp
        check_row(row, tk, lat, LON0 + accel * tk * tk / (2 * big_r * cl), H0, [0.0, accel * tk, 0.0], c, pos=2e-15,
                  hm=2e-9 * (k + 1) if frame == "inertial" else 1e-10, vel=vel, att=2e-14)  # r^i: 3 ulps a step


def test_first_mid_velocity():
    """The first update of a local-level frame has no v(k-2): v_mid = (v(0) + v_pred(1))/2 with v_pred(1) the velocity
    update from v(0) (docs/algorithms.md), its zeta = (w_ie + w_en) T at the l cycle's point, lat0 + T/2 v_N/(R_N +
    h0), h0 - T/2 v_D, gravity there (Somigliana); as in test_velocity_step, with dzeta = 0."""
    v0 = np.array([60.0, 150.0, -8.0])
    s = sd.init_state(0.0, LAT0, LON0, H0, v0.copy(), *ATT)
    cfg = sd.make_config()
    T = 1.0 / 64.0
    sigma, dv, scul = np.array([0.01, -0.02, 0.015]), np.array([0.3, -0.2, -0.15]), np.array([1e-4, -2e-4, 5e-5])
    got = np.array(sd._first_mid_velocity(s, cfg, sd.GEOGRAPHIC, T, *sigma, *dv, *scul))  # frame 3rd: not for_frame
    r_n, r_e = radii(LAT0)
    lm, hm = LAT0 + T / 2 * v0[0] / (r_n + H0), H0 - T / 2 * v0[2]
    r_n, r_e = radii(lm)
    w_ie = np.array([OMEGA * math.cos(lm), 0.0, -OMEGA * math.sin(lm)])
    w_en = np.array([v0[1] / (r_e + hm), -v0[0] / (r_n + hm), -v0[1] * math.tan(lm) / (r_e + hm)])
    zeta = (w_ie + w_en) * T
    u = cbn(*ATT) @ (dv + savage(sigma, dv) + scul)
    u = u - 0.5 * np.cross(zeta, u) + np.cross(zeta, np.cross(zeta, u)) / 12
    v1 = v0 + u + (np.array([0.0, 0.0, float(gamma(lm, hm))]) - np.cross(2 * w_ie + w_en, v0)) * T
    np.testing.assert_allclose(got, (v0 + v1) / 2, rtol=0, atol=1e-14)


def test_exact_order_below_the_series_limit():
    """--order exact with |sigma| = 0.0099 rad, just inside the series of (cos s/2 - 1, sin(s/2)/s): 16 updates about
    body x turn roll by 16 s (Rodrigues) to round-off, 1e-17 rad per update."""
    n, step = 16, 0.0099
    cfg = sd.make_config(samples=1, earth_model="none")
    s = sd.init_state(0.0, LAT0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
    rows = run(cfg, s, DT * np.arange(1, n + 1), np.tile([step, 0.0, 0.0], (n, 1)), np.zeros((n, 3)))
    for k, row in enumerate(rows, 1):
        assert row[7] == pytest.approx(k * step, rel=0, abs=2e-17 * k + 2e-17)


@pytest.mark.parametrize("frame", ["wander", "free"])
def test_wander_l_cycle_point(frame):
    """The wander/free l cycle takes the Earth rate Omega r and gravity at the mid-interval point, whose C_w^e third row
    is r + T/2 r x rho ([ZS] 2.2; docs/algorithms.md): flying north at 60 m/s with azimuth 0 that is the NED third
    row at L + T/2 v_N/(R_N + h) (and, free, azimuth Omega sin L T/2), to its second order (T/2 |rho|)^2/2."""
    v = np.array([60.0, 0.0, 0.0])
    r_n, r_e = radii(LAT0)
    w_ie = np.array([OMEGA * math.cos(LAT0), 0.0, -OMEGA * math.sin(LAT0)])
    w_en = np.array([0.0, -v[0] / (r_n + H0), 0.0])
    c = cbn(*ATT)
    f = c.T @ (np.cross(2 * w_ie + w_en, v) - np.array([0.0, 0.0, float(gamma(LAT0, H0))]))
    cfg = sd.make_config(frame=frame)
    s = sd.init_state(0.0, LAT0, LON0, H0, v.copy(), *ATT)
    run(cfg, s, DT * np.arange(1, 3), np.tile(c.T @ (w_ie + w_en) * DT, (2, 1)), np.tile(f * DT, (2, 1)))
    lm = LAT0 + DT * v[0] / (r_n + H0)  # T/2 = DT
    am = OMEGA * math.sin(LAT0) * DT if frame == "free" else 0.0  # the free azimuth turns at Omega sin L
    second = (DT * math.hypot(v[0] / (r_n + H0), am / DT)) ** 2 / 2  # |r + T/2 r x rho| - 1
    np.testing.assert_allclose(s[sd.S.WIE:sd.S.WIE + 3],
                               OMEGA * np.array([math.cos(lm) * math.cos(am), -math.cos(lm) * math.sin(am),
                                                 -math.sin(lm)]), rtol=0, atol=OMEGA * (second + 4e-15))
    assert s[sd.S.G] == pytest.approx(float(gamma(lm, H0)), rel=1e-14, abs=0)


def test_inertial_gravitation_second_difference():
    """The inertial l cycle's quadrature term (G_l - 2 G_l-1 + G_l-2)/(24 M^2) (docs/algorithms.md) on all three
    components: three l cycles at heights 0, 100 and 400 m over one point, with ECI = ECEF at the l cycle's
    mid-interval time and no velocity, so the point is r^i itself and G = g - Omega^2 [x, y, 0] there ([ZS1] eq.
    1-3-26; normal gravity along the ellipsoid normal, Somigliana)."""
    T = 0.02
    cfg = sd.make_config(frame="inertial")
    s = sd.init_state(0.0, LAT0, LON0, H0, np.zeros(3), 0.0, 0.0, 0.0)
    s[sd.S.T], s[sd.S.T0] = -T / 2, 0.0  # mid-interval time = t0: ECI = ECEF
    r_e = radii(LAT0)[1]
    sl, cl, so, co = math.sin(LAT0), math.cos(LAT0), math.sin(LON0), math.cos(LON0)
    gs = []
    for h in (0.0, 100.0, 400.0):
        x, y = (r_e + h) * cl * co, (r_e + h) * cl * so
        s[sd.S.RI:sd.S.RI + 3] = x, y, (r_e * (1 - E2) + h) * sl
        sd._l_cycle_inertial(s, cfg, T, 0.0, 0.0, 0.0)
        g = float(gamma(LAT0, h))
        gs.append(np.array([-g * cl * co - OMEGA ** 2 * x, -g * cl * so - OMEGA ** 2 * y, -g * sl]))
    want = gs[2] + (gs[2] - 2 * gs[1] + gs[0]) / 24
    # the geodetic round trip of r to an ulp of |r| (1e-9 m) moves G by 2 gamma/a of it: 3e-15 m/s^2
    np.testing.assert_allclose([s[sd.S.GH], s[sd.S.GH + 1], s[sd.S.G]], want, rtol=0, atol=2e-14)


def test_the_state_layout_is_declared_once() -> None:
    """strapdown.STATE_LAYOUT is the one declaration of the state vector: ``S.<NAME>`` is its slot's running
    offset, in the declaration's order, the slots tile 0 .. S_SIZE without gap or overlap, and the sizes are
    those of what they hold (a quaternion 4, a DCM 9, six 3-vectors of increments 18, the 2 x 2
    transport-rate matrix 4). No index is typed anywhere else: the module holds no other S_<NAME>."""
    names = [f.name for f in sd.STATE_LAYOUT]
    assert len(set(names)) == len(names)
    assert list(sd.S._fields) == names
    at = 0
    for f in sd.STATE_LAYOUT:
        assert getattr(sd.S, f.name) == at, f.name
        at += f.size
    assert at == sd.S_SIZE == 131
    size = {f.name: f.size for f in sd.STATE_LAYOUT}
    assert (size["Q"], size["C"], size["CNE"], size["BTH"], size["BDV"], size["MW"], size["GH"]) == (4, 9, 9, 18, 18,
                                                                                                     4, 2)
    assert all(size[n] == 3 for n in ("V", "VP", "PF", "WIE", "WEN", "CONE", "SCUL", "ACCA", "ACCV", "PW", "PFO",
                                      "RI", "GP", "GPP"))
    assert sorted(k for k in vars(sd) if k.startswith("S_")) == ["S_SIZE"]


def test_a_kernel_reads_the_state_by_the_named_index() -> None:
    """A kernel compiled with ``S.<NAME>`` reads the slot the declaration gives it: init_state's values land
    at the offsets counted from STATE_LAYOUT by hand here (t at 0, q_nb after it, C_b^n after q, v^n after C)."""
    v = np.array([1.0, -2.0, 0.5])
    s = sd.init_state(3.0, 0.7, 0.2, 100.0, v, 0.0, 0.0, 0.0)
    assert s[0] == 3.0  # T
    np.testing.assert_array_equal(s[1:5], [1.0, 0.0, 0.0, 0.0])  # Q: the identity rotation
    np.testing.assert_array_equal(s[5:14], np.eye(3).ravel())  # C
    np.testing.assert_array_equal(s[14:17], v)  # V
