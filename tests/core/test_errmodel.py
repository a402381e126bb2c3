"""The filter's error model (mavins/core/errmodel.py) against the strapdown kernel and closed forms.

1. Linearisation: the real strapdown (strapdown.init_state / push_increment)
   runs over exact simulator increments twice, from the truth and from a
   perturbed state (phi, dv, dp, and gyro/accelerometer biases added to the
   increments); the difference after T seconds is compared with ``Phi(T) dx0``,
   Phi the product of the per-update transition matrices of the model's F
   along the unperturbed run. The residual r(eps) of the scaled perturbation
   ``eps dx0`` is written r = a eps + b eps^2: a (what F gets wrong to first
   order) must vanish to the model's neglected terms, b is the second order.
2. Biases: a constant accelerometer bias moves the position by ``1/2 b t^2``
   and a gyro bias by ``g b t^3 / 6`` (level, at rest), both in the model and
   in the strapdown, up to the Schuler and Coriolis terms.
3. Schuler: the stationary F has the eigenfrequencies ``sqrt(g/R) +- Omega
   sin L`` (Schuler split by Foucault), ``Omega`` and the real pair
   ``+-sqrt(2 g/R)`` of the unstable vertical channel.

Errors are estimate minus truth, with the contract's attitude error
``C(est) = exp([phi x]) C(true)`` and position error in NED metres; the
helpers below compute them from two strapdown states independently of the
code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import earth
from mavins.core import errmodel as em
from mavins.core import strapdown as sd
from mavins.core.jit import for_frame
from mavins.core.rotation import dcm_to_euler, dcm_to_rotvec, euler_to_dcm, rotvec_to_dcm
from sim import errors
from sim.generate import generate
from sim.scenarios import Scenario, load

RATE = 100.0
OMEGA = 7.292115e-5
A_WGS = 6378137.0
F_WGS = 1.0 / 298.257223563
E2 = F_WGS * (2.0 - F_WGS)


def gamma_h(lat: float, h: float) -> float:
    """Normal gravity of docs/conventions.md, written out again."""
    s2 = math.sin(lat) ** 2
    g = 9.7803253359 * (1 + 0.00193185265241 * s2) / math.sqrt(1 - E2 * s2)
    return g * (1 - 2 / A_WGS * (1 + F_WGS + 0.00344978650684 - 2 * F_WGS * s2) * h + 3 * h * h / A_WGS**2)


def mean_radius(lat: float, h: float) -> float:
    s2 = math.sin(lat) ** 2
    r_n = A_WGS * (1 - E2) / (1 - E2 * s2) ** 1.5
    r_e = A_WGS / math.sqrt(1 - E2 * s2)
    return math.sqrt(r_n * r_e) + h


@pytest.fixture(scope="module")
def flight():
    """The flight scenario without its random vibration (exact increments), 80 s at 100 Hz."""
    sc = load("flight")
    doc = {k: v for k, v in sc.doc.items() if k != "perturbations"}
    return generate(Scenario("flight_quiet", sc.source, doc), duration=80.0, rate=RATE, seed=0, grade="ideal").exact


CFG = sd.make_config(samples=2)
SPEC = em.make_spec("consumer")


def perturbed_state(row: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """Strapdown state at a truth row (file units) with the error dx (phi, dv, dp) injected."""
    lat, lon, h = math.radians(row[1]), math.radians(row[2]), row[3]
    r_n, r_e = earth.radii(lat)
    c = rotvec_to_dcm(dx[0:3]) @ euler_to_dcm(*np.radians(row[7:10]))
    e = dcm_to_euler(c)
    return sd.init_state(
        row[0], lat + dx[6] / (r_n + h), lon + dx[7] / ((r_e + h) * math.cos(lat)), h - dx[8],
        row[4:7] + dx[3:6], e[0], e[1], e[2],
    )


def state_error(sp: np.ndarray, sr: np.ndarray) -> np.ndarray:
    """(phi, dv, dp) of state sp against the reference sr."""
    cp = sp[sd.S.C : sd.S.C + 9].reshape(3, 3)
    cr = sr[sd.S.C : sd.S.C + 9].reshape(3, 3)
    lp, op, hp = for_frame(sd.position, sd.GEOGRAPHIC)(sp, CFG)
    lr, orr, hr = for_frame(sd.position, sd.GEOGRAPHIC)(sr, CFG)
    r_n, r_e = earth.radii(lr)
    dp = [(lp - lr) * (r_n + hr), (op - orr) * (r_e + hr) * math.cos(lr), -(hp - hr)]
    return np.concatenate([dcm_to_rotvec(cp @ cr.T), sp[sd.S.V : sd.S.V + 3] - sr[sd.S.V : sd.S.V + 3], dp])


def run_strapdown(exact, j: int, n: int, dx: np.ndarray, transitions: list | None = None) -> np.ndarray:
    """Strapdown from truth row j over increment rows j..j+n-1 with the error dx.

    Biases enter as ``measured = true + b`` with no estimate, i.e. b = -dx_bias.
    With ``transitions``, appends the model's Phi of every attitude update
    (F at the update's mean C, velocity and specific force).
    """
    s = perturbed_state(exact.truth[j], dx)
    bg, ba = -dx[em.X_BG : em.X_BG + 3], -dx[em.X_BA : em.X_BA + 3]
    t_all = np.concatenate(([exact.t0], exact.t))
    dv_sum = np.zeros(3)
    c_old = s[sd.S.C : sd.S.C + 9].reshape(3, 3).copy()
    v_old = s[sd.S.V : sd.S.V + 3].copy()
    t_old = s[sd.S.T]
    for i in range(j, j + n):
        dt = t_all[i + 1] - t_all[i]
        dv = exact.dv[i] + ba * dt
        dv_sum += dv
        if for_frame(sd.push_increment, sd.GEOGRAPHIC)(s, CFG, exact.t[i], exact.dtheta[i] + bg * dt, dv) == 1:
            if transitions is not None:
                c_new = s[sd.S.C : sd.S.C + 9].reshape(3, 3).copy()
                v_new = s[sd.S.V : sd.S.V + 3].copy()
                T = s[sd.S.T] - t_old
                c_mid = 0.5 * (c_old + c_new)
                lat, _, h = for_frame(sd.position, sd.GEOGRAPHIC)(s, CFG)
                F = em.system_matrix(c_mid, 0.5 * (v_old + v_new), lat, h, c_mid @ dv_sum / T, SPEC, True)
                transitions.append(em.transition(F, T))
                c_old, v_old, t_old = c_new, v_new, s[sd.S.T]
            dv_sum[:] = 0.0
    return s


def test_linearisation_against_the_strapdown(flight) -> None:
    """10 s through the flight's first turn (t = 70..80 s: bank, yaw rate, 3.5 m/s^2 sideways).

    Response to dx0 (phi ~ 3 mrad, dv ~ 0.1 m/s, dp ~ 5 m, gyro bias ~ 3e-4
    rad/s, accelerometer bias ~ 0.02 m/s^2) is ~3 mrad, 0.1 m/s, 6 m.
    First-order part a of the residual: what F neglects to first order
    (radius derivatives, third-order terms of each 20 ms step, mean C and f
    over a step) is of relative order 1e-5; bound 1e-4 of each block's
    response. Second-order part b: the leading products of errors are the
    attitude error rotating the other errors, so per block
    ``|b| <= 2 phi_max |response|`` with phi_max = |phi0| + |bg| T.
    """
    j, n, T = 7000, 1000, 10.0
    dx0 = np.zeros(em.NX)
    dx0[0:3] = [1e-3, -2e-3, 3e-3]
    dx0[3:6] = [0.1, -0.05, 0.08]
    dx0[6:9] = [5.0, -3.0, 2.0]
    dx0[em.X_BG : em.X_BG + 3] = [2e-4, -1e-4, 3e-4]
    dx0[em.X_BA : em.X_BA + 3] = [0.01, -0.02, 0.015]
    phis: list[np.ndarray] = []
    ref = run_strapdown(flight, j, n, np.zeros(em.NX), phis)
    assert len(phis) == n // 2
    phi = np.eye(em.NX)
    for p in phis:
        phi = p @ phi
    lin = (phi @ dx0)[:9]
    r = {eps: state_error(run_strapdown(flight, j, n, eps * dx0), ref) - eps * lin for eps in (1.0, 0.5)}
    a = 4.0 * r[0.5] - r[1.0]
    b = 2.0 * r[1.0] - 4.0 * r[0.5]
    phi_max = np.linalg.norm(dx0[0:3]) + np.linalg.norm(dx0[em.X_BG : em.X_BG + 3]) * T
    for blk in (slice(0, 3), slice(3, 6), slice(6, 9)):
        scale = np.linalg.norm(lin[blk])
        assert np.linalg.norm(a[blk]) <= 1e-4 * scale, (blk, a[blk], lin[blk])
        assert np.linalg.norm(b[blk]) <= 2.0 * phi_max * scale, (blk, b[blk], lin[blk])
        assert np.linalg.norm(b[blk]) > 10.0 * np.linalg.norm(a[blk])  # the residual is second order


def stationary_row(lat_deg: float, h: float, yaw_deg: float) -> np.ndarray:
    row = np.zeros(14)
    row[1], row[2], row[3], row[9] = lat_deg, 8.5, h, yaw_deg
    return row


class Static:
    """Exact increments of a vehicle at rest and level: Earth rate and -g (FRD) per interval."""

    def __init__(self, lat_deg: float, h: float, yaw_deg: float, duration: float) -> None:
        lat = math.radians(lat_deg)
        n = int(round(duration * RATE))
        self.t0 = 0.0
        self.t = np.arange(1, n + 1) / RATE
        c_nb = euler_to_dcm(0.0, 0.0, math.radians(yaw_deg)).T
        w_b = c_nb @ np.array([OMEGA * math.cos(lat), 0.0, -OMEGA * math.sin(lat)])
        self.g = gamma_h(lat, h)
        self.dtheta = np.tile(w_b / RATE, (n, 1))
        self.dv = np.tile(c_nb @ np.array([0.0, 0.0, -self.g]) / RATE, (n, 1))
        self.truth = stationary_row(lat_deg, h, yaw_deg)[None, :]


def model_response(lat_deg: float, h: float, g: float, dx0: np.ndarray, T: float, step: float = 0.02) -> np.ndarray:
    """Phi(T) dx0 of the stationary model (heading north, level) in steps of ``step`` s."""
    lat = math.radians(lat_deg)
    F = em.system_matrix(np.eye(3), np.zeros(3), lat, h, np.array([0.0, 0.0, -g]), SPEC, True)
    x = dx0.copy()
    p = em.transition(F, step)
    for _ in range(int(round(T / step))):
        x = p @ x
    return x


def test_accelerometer_bias_gives_half_b_t_squared() -> None:
    """A constant accelerometer bias b, heading north, level: dp = 1/2 b t^2 per axis.

    Closed form ``measured = true + b`` uncompensated: dba = -b, ddv/dt = b,
    dp = b t^2 / 2. Neglected over t = 10 s: Coriolis ``2 Omega x v`` with
    v = b t, relative 2 Omega t / 3 = 5e-4 on the other horizontal axis;
    Schuler and gravity gradient (w_s t)^2 / 12 ~ 1e-5. Bound: 1e-3 of 1/2 |b| t^2.
    """
    T = 10.0
    b = np.array([0.01, -0.02, 0.015])
    static = Static(47.4, 488.0, 0.0, T)
    expected = 0.5 * b * T * T
    dx0 = np.zeros(em.NX)
    dx0[em.X_BA : em.X_BA + 3] = -b
    model = model_response(47.4, 488.0, static.g, dx0, T)[6:9]
    tol = 1e-3 * 0.5 * np.linalg.norm(b) * T * T
    np.testing.assert_allclose(model, expected, atol=tol)
    n = static.t.size
    ref = run_strapdown(static, 0, n, np.zeros(em.NX))
    biased = run_strapdown(static, 0, n, dx0)
    np.testing.assert_allclose(state_error(biased, ref)[6:9], expected, atol=tol)


def test_gyro_bias_gives_g_b_t_cubed_over_six() -> None:
    """A north gyro bias b (level, heading north): phi_N = b t, dv_E = g b t^2/2, dp_E = g b t^3/6.

    ``C(est) = exp(phi) C``: a rotation error about north tilts the computed
    vertical so that f^n(est) gains ``phi x f = (0, g phi_N, 0)``. Neglected:
    the Schuler feedback of dv_E on phi_N, relative (w_s t)^2 / 20 = 8e-6 at
    t = 10 s, and Earth-rate coupling Omega t ~ 7e-4. Bound: 2e-3 relative.
    """
    T = 10.0
    b = 1e-4
    static = Static(47.4, 488.0, 0.0, T)
    dx0 = np.zeros(em.NX)
    dx0[em.X_BG] = -b
    g = static.g
    x = model_response(47.4, 488.0, g, dx0, T)
    assert x[0] == pytest.approx(b * T, rel=2e-3)
    assert x[4] == pytest.approx(g * b * T**2 / 2, rel=2e-3)
    assert x[7] == pytest.approx(g * b * T**3 / 6, rel=2e-3)
    n = static.t.size
    err = state_error(run_strapdown(static, 0, n, dx0), run_strapdown(static, 0, n, np.zeros(em.NX)))
    assert err[0] == pytest.approx(b * T, rel=2e-3)
    assert err[4] == pytest.approx(g * b * T**2 / 2, rel=2e-3)
    assert err[7] == pytest.approx(g * b * T**3 / 6, rel=2e-3)


@pytest.mark.parametrize("lat_deg", [47.4, 0.0])
def test_schuler_foucault_and_vertical_eigenvalues(lat_deg: float) -> None:
    """Stationary F (phi, dv, dp): +-i (w_s +- Omega sin L), +-i Omega, +-sqrt(2 g/R), 0.

    Schuler ``w_s = sqrt(g/R)``, R = sqrt(R_N R_E) + h: period 84.4 min;
    the Foucault split ``Omega sin L`` and the Earth-rate mode hold to
    (Omega / w_s)^2 ~ 0.3 %; bound 1 %.
    """
    lat, h = math.radians(lat_deg), 488.0
    g = gamma_h(lat, h)
    R = mean_radius(lat, h)
    w_s = math.sqrt(g / R)
    assert 2 * math.pi / w_s / 60.0 == pytest.approx(84.4, rel=1e-2)
    F = em.system_matrix(euler_to_dcm(0.0, 0.0, 0.3), np.zeros(3), lat, h, np.array([0.0, 0.0, -g]), SPEC, True)
    ev = np.linalg.eigvals(F[:9, :9])
    osc = np.sort(ev[ev.imag > 1e-9].imag)
    real = np.sort(ev[np.abs(ev.imag) < 1e-9].real)
    assert osc.size == 3 and real.size == 3
    split = OMEGA * math.sin(lat)
    assert osc[0] == pytest.approx(OMEGA, rel=1e-2)
    assert osc[1] == pytest.approx(w_s - split, rel=1e-2)
    assert osc[2] == pytest.approx(w_s + split, rel=1e-2)
    assert 2 * math.pi / (0.5 * (osc[1] + osc[2])) / 60.0 == pytest.approx(84.4, rel=1e-2)
    assert real[0] == pytest.approx(-math.sqrt(2 * g / R), rel=1e-2)
    assert abs(real[1]) < 1e-12
    assert real[2] == pytest.approx(math.sqrt(2 * g / R), rel=1e-2)


def test_discretisation_against_the_matrix_exponential() -> None:
    """Phi = I + FT + (FT)^2/2 and the trapezoidal Qd against exact references.

    References: expm by a 20-term series; Qd by Van Loan's block exponential.
    Phi's truncation is ``sum_{k>=3} (FT)^k / k!``, bounded elementwise by the
    same series of |FT|. The trapezoidal Qd is exact in its O(T) terms (the
    white noise on phi and dv) and errs in the O(T^3) and higher ones (e.g.
    position: q_v T^3/2 for q_v T^3/3); what matters is the propagated
    covariance: over 60 s of 20 ms steps those errors sum to a fraction of
    order (T/t)^2 of the accumulated variance, bound 1e-4.
    """
    lat, h, g = math.radians(47.4), 488.0, 9.8
    c = euler_to_dcm(0.1, -0.05, 1.0)
    F = em.system_matrix(c, np.array([10.0, -3.0, 1.0]), lat, h, c @ np.array([0.5, 2.0, -g]), SPEC, True)
    T = 0.02
    phi, qd = em.discretise(F, SPEC, T)

    def series(m: np.ndarray, start: int) -> np.ndarray:
        out = np.zeros_like(m)
        term = np.eye(m.shape[0])
        for k in range(1, 20):
            term = term @ m / k
            if k >= start:
                out = out + term
        return out

    n = em.NX
    ft = F * T
    expm = np.eye(n) + series(ft, 1)
    assert np.all(np.abs(phi - expm) <= 1.01 * series(np.abs(ft), 3) + 1e-15)

    q = np.diag(em.noise_density(SPEC))
    vl = np.zeros((2 * n, 2 * n))
    vl[:n, :n] = -F
    vl[:n, n:] = q
    vl[n:, n:] = F.T
    e = np.eye(2 * n) + series(vl * T, 1)
    qd_ref = e[n:, n:].T @ e[:n, n:]
    assert np.array_equal(qd, qd.T)
    np.testing.assert_allclose(np.diag(qd)[:6], np.diag(qd_ref)[:6], rtol=1e-4)

    p = np.eye(n) * 1e-12
    p_ref = p.copy()
    for _ in range(3000):
        p = phi @ p @ phi.T + qd
        p_ref = expm @ p_ref @ expm.T + qd_ref
    np.testing.assert_allclose(np.diag(p)[:15], np.diag(p_ref)[:15], rtol=1e-4)


def test_spec_from_grade_is_the_simulators_model() -> None:
    """The filter's figures are the simulator's (sim/errors.py grade models), SI units."""
    for name in em.GRADES:
        m = errors.grade(name)
        s = em.spec_from_grade(name)
        assert s.gyro_arw == m.gyro.random_walk
        assert s.gyro_bias == m.gyro.turn_on_bias_sigma
        assert s.gyro_gm == m.gyro.bias_instability_sigma
        assert s.gyro_tau == m.gyro.bias_instability_tau
        assert s.gyro_rrw == m.gyro.rate_random_walk
        assert s.accel_vrw == m.accel.random_walk
        assert s.accel_bias == m.accel.turn_on_bias_sigma
        assert s.accel_gm == m.accel.bias_instability_sigma
        assert s.accel_tau == m.accel.bias_instability_tau
        assert s.accel_rrw == m.accel.rate_random_walk
    with pytest.raises(ValueError):
        em.spec_from_grade("ideal")


def test_spec_from_contract_keys() -> None:
    """deg/sqrt(h) -> rad/sqrt(s) is pi/180/60, deg/h -> rad/s is pi/180/3600, m/s/sqrt(h) -> /60."""
    keys = {"gyro_arw": 0.15, "gyro_bias": 3.0, "gyro_bias_instability": 1.0, "gyro_bias_tau": 300.0,
            "accel_vrw": 0.06, "accel_bias": 0.01, "accel_bias_instability": 5e-4, "accel_bias_tau": 200.0}
    s = em.spec_from_keys(keys)
    assert s.gyro_arw == pytest.approx(0.15 * math.pi / 180 / 60)
    assert s.gyro_bias == pytest.approx(3.0 * math.pi / 180 / 3600)
    assert s.gyro_gm == pytest.approx(math.pi / 180 / 3600)
    assert s.gyro_tau == 300.0
    assert s.accel_vrw == pytest.approx(0.001)
    assert (s.accel_bias, s.accel_gm, s.accel_tau) == (0.01, 5e-4, 200.0)
    back = em.spec_to_keys(s)
    for k, v in keys.items():
        assert back[k] == pytest.approx(v)
    const = em.spec_from_keys({"gyro_arw": 0.1, "gyro_bias": 1.0, "accel_vrw": 0.05, "accel_bias": 0.002})
    assert const.gyro_gm == 0.0 and const.accel_gm == 0.0
    F = em.system_matrix(np.eye(3), np.zeros(3), 0.8, 0.0, np.array([0, 0, -9.8]), const.as_array(), True)
    assert np.all(F[em.X_GG :, em.X_GG :] == 0.0)  # constant bias: no Gauss-Markov dynamics
    with pytest.raises(ValueError):
        em.spec_from_keys({"gyro_bias_instability": 1.0})
