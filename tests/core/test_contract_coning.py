"""N-sample coning and sculling coefficients, checked through what the navigation does.

The coefficients are typed here from docs/conventions.md ``--samples`` (the
optimal N-sample algorithms of Lee, Yoon et al. 1990 and Ignagni 1990/1996,
oldest sample first), never imported from mavins. They are pinned twice:

1. by theory alone: with them, the classic-coning error series of each
   N-sample algorithm starts at (W T)^(2N+1) per update (every lower order
   cancels, which is what "optimal" means), and its leading term is Ignagni's
   published drift: (W T)^4/960, (W T)^6/204120 and (W T)^8/82575360 times
   W sin^2(beta) for N = 2, 3, 4;
2. by behaviour: exact increments of a classic coning motion (and of a classic
   sculling motion) run through ``mavins.core.runner.navigate`` with
   ``earth_model="none"`` must end with exactly the error that the typed
   coefficients predict in closed form. The motion is chosen so that every
   coefficient of every N is visible: a coefficient 1 % off moves the result
   by more than 20 times the tolerance (asserted in each test, from the
   closed form alone).

Classic coning (derivation in ``coning_increments``): attitude
``q(t) = [cos(b/2), sin(b/2) cos Wt, sin(b/2) sin Wt, 0]`` has the body rate
``w = [-W sin b sin Wt, W sin b cos Wt, -2 W sin^2(b/2)]``. With increments
over samples of length h and lambda = W h, ``(dtheta_i x dtheta_j)_z = 4
sin^2 b sin^2(lambda/2) sin((j - i) lambda)`` and the exact coning term of an
update of length T is ``sin^2 b (W T - sin W T)/2`` ([TW11] 11.2.3). Both are
the same in every update, so the z error of the body attitude grows by
``e = alg - exact`` per update: after M updates it is M e (z component of the
error rotation vector in the body frame, signed).

Classic sculling: angle ``phi = theta sin Wt`` about x, specific force
``f = [0, A sin Wt, 0]``. ``(dth_i x dv_j + dv_i x dth_j)_z = 4 theta A/W
sin^2(lambda/2) sin((j - i) lambda)`` and the exact sculling term
``1/2 int (alpha x f + v x w) dt`` is ``theta A/(2W) (W T - sin W T)`` per
update (the coning form with sin^2 b -> theta A/W, Ignagni 1998), again phase
independent, so the down velocity ends at truth + M e.

Tolerances: the closed forms are first order in the small angle; what they
neglect is third order (the Bortz term 1/12 alpha x (alpha x w) of the
rotation vector has a z part ~ sin^4 b (W T)^3 per update; for sculling the
z velocity's next term is theta^3 A T), plus the small tilt of the body z axis
(cos 2b ~ 1 - 2 b^2, relative) and double round-off (1e-15 of the state per
update). ``tol = 1e-6 |M e| + M (sin^4 b (W T)^3 + round-off)``.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from mavins.core.runner import navigate

# docs/conventions.md --samples: N-sample coefficients k_{N-1} .. k_1, oldest sample first
COEFFS: dict[int, list[Fraction]] = {
    1: [],
    2: [Fraction(2, 3)],
    3: [Fraction(9, 20), Fraction(27, 20)],
    4: [Fraction(54, 105), Fraction(92, 105), Fraction(214, 105)],
    5: [Fraction(250, 504), Fraction(525, 504), Fraction(650, 504), Fraction(1375, 504)],
    6: [Fraction(2315, 4620), Fraction(4558, 4620), Fraction(7296, 4620), Fraction(7834, 4620),
        Fraction(15797, 4620)],
}
# Ignagni's published leading drift terms: drift = W sin^2 b (W T)^(2N) / D_N
PUBLISHED_D = {2: 960, 3: 204120, 4: 82575360}

H = 0.01  # sample interval (s)
W = 50.0  # rad/s: lambda = W h = 0.5 rad, so sin(m lambda) >= 0.48 for m = 1..5: every coefficient counts
UPDATES = 300  # attitude updates per run


# --- theory only ------------------------------------------------------------------
def _series(coef: list[Fraction], n: int, order: int) -> dict[int, Fraction]:
    """Taylor coefficients in x = W T of (algorithm - exact) per update, per sin^2 b, up to x^order."""
    def sin_series(a: Fraction) -> dict[int, Fraction]:
        return {2 * k + 1: Fraction((-1) ** k) * a ** (2 * k + 1) / math.factorial(2 * k + 1)
                for k in range(order // 2 + 1) if 2 * k + 1 <= order}

    # 4 sin^2(lambda/2) = 2 (1 - cos lambda), lambda = x/n
    two_minus_cos = {2 * k: -2 * Fraction((-1) ** k) * Fraction(1, n) ** (2 * k) / math.factorial(2 * k)
                     for k in range(1, order // 2 + 1)}
    out: dict[int, Fraction] = {}
    for i, k in enumerate(coef):
        for p1, c1 in two_minus_cos.items():
            for p2, c2 in sin_series(Fraction(n - 1 - i, n)).items():
                if p1 + p2 <= order:
                    out[p1 + p2] = out.get(p1 + p2, Fraction(0)) + k * c1 * c2
    for p, c in sin_series(Fraction(1)).items():  # exact: (x - sin x)/2
        out[p] = out.get(p, Fraction(0)) + c / 2
    out[1] = out.get(1, Fraction(0)) - Fraction(1, 2)
    return {p: c for p, c in out.items() if c != 0}


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_typed_coefficients_are_the_optimal_ones(n: int) -> None:
    """Optimality: every order below (W T)^(2N+1) cancels exactly (rational arithmetic), and the
    leading term is the published drift for N = 2, 3, 4. A typo in the typed table fails here."""
    s = _series(COEFFS[n], n, 2 * n + 3)
    assert min(s) == 2 * n + 1, f"N={n}: error series starts at order {min(s)}"
    lead = s[2 * n + 1]
    assert lead < 0  # the algorithms under-compensate at the leading order
    if n in PUBLISHED_D:
        assert -1 / lead == PUBLISHED_D[n]


# --- behaviour ---------------------------------------------------------------------
def alg_minus_exact(coef: list[float], n: int, lam: float) -> float:
    """Per update and per unit of sin^2 b (coning) or theta A/W (sculling): alg - exact."""
    alg = 4.0 * math.sin(lam / 2.0) ** 2 * sum(k * math.sin((n - 1 - i) * lam) for i, k in enumerate(coef))
    wt = n * lam
    return alg - 0.5 * (wt - math.sin(wt))


def visibility(n: int, lam: float) -> float:
    """Smallest change of alg - exact (same units) when one coefficient is 1 % off."""
    base = [float(k) for k in COEFFS[n]]
    out = math.inf
    for i in range(len(base)):
        c = list(base)
        c[i] *= 1.01
        out = min(out, abs(alg_minus_exact(c, n, lam) - alg_minus_exact(base, n, lam)))
    return out


def qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product [w, x, y, z]."""
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vector of a unit quaternion (shortest)."""
    q = q if q[0] >= 0 else -q
    v = q[1:]
    s = np.linalg.norm(v)
    return v * (2.0 * math.atan2(s, q[0]) / s) if s > 0 else np.zeros(3)


def coning_increments(beta: float, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Sample times and exact angle increments of classic coning (closed form).

    q(t) = [c, s cos Wt, s sin Wt, 0] (c, s = cos, sin of beta/2): w = 2 q* (x) dq/dt =
    [-W sin b sin Wt, W sin b cos Wt, -2 W s^2], whose integral over (t1, t2] is
    [sin b (cos Wt2 - cos Wt1), sin b (sin Wt2 - sin Wt1), -2 W s^2 (t2 - t1)].
    """
    k = np.arange(n_samples + 1)
    t = k * H
    sb, s2 = math.sin(beta), math.sin(beta / 2) ** 2
    dth = np.stack([sb * np.diff(np.cos(W * t)), sb * np.diff(np.sin(W * t)), -2 * W * s2 * np.diff(t)], -1)
    return t[1:], dth


def coning_truth(beta: float, t: float) -> np.ndarray:
    return np.array([math.cos(beta / 2), math.sin(beta / 2) * math.cos(W * t), math.sin(beta / 2) * math.sin(W * t),
                     0.0])


BETA = math.radians(0.02)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6])
def test_coning_drift_is_what_the_typed_coefficients_predict(n: int) -> None:
    """The attitude error about the cone axis after M updates equals M (alg - exact) sin^2 b.

    N = 1 applies no correction (the contract): its error is -M x exact, 2.6e-6 rad per update
    here. For N >= 2 a 1 % error in any coefficient moves the result by ``visibility`` x M x
    sin^2 b; asserted > 20 x the tolerance before the run.
    """
    lam = W * H
    t, dth = coning_increments(BETA, n * UPDATES)
    sol = navigate(t, dth, np.zeros_like(dth), dict(t=0.0, lat=0.0, lon=0.0, h=0.0, vn=0.0, ve=0.0, vd=0.0,
                                                    roll=math.degrees(BETA), pitch=0.0, yaw=0.0),
                   samples=n, earth_model="none")
    assert len(sol) == UPDATES and sol[-1, 0] == pytest.approx(t[-1], abs=1e-12)
    q_est = sol[-1, 10:14]
    q_true = coning_truth(BETA, t[-1])
    err = rotvec(qmul(q_true * np.array([1, -1, -1, -1]), q_est))  # body-frame error q_true^-1 q_est
    s2 = math.sin(BETA) ** 2
    coef = [float(k) for k in COEFFS[n]]
    predicted = UPDATES * alg_minus_exact(coef, n, lam) * s2
    wt = n * lam
    tol = 1e-6 * abs(predicted) + UPDATES * (s2 * s2 * wt**3 + 1e-15)
    if n >= 2:
        assert visibility(n, lam) * UPDATES * s2 > 20 * tol, "the motion must show every coefficient"
    print(f"\nN={n}: z error {err[2]:.6e} rad, predicted {predicted:.6e} rad, tol {tol:.1e}")
    assert err[2] == pytest.approx(predicted, abs=tol)


def sculling_truth_v(theta: float, accel: float, t_end: float) -> tuple[float, float]:
    """(v_y, v_z) of int_0^t C(t) f dt with C = Rx(theta sin Wt), f = [0, A sin Wt, 0]: the y axis
    turned by phi is [0, cos phi, sin phi]. Gauss-Legendre, 12 nodes per 0.01 s (integrand
    analytic; error far below 1e-15 m/s)."""
    edges = np.linspace(0.0, t_end, int(round(t_end / H)) + 1)
    x, w = np.polynomial.legendre.leggauss(12)
    a, b = edges[:-1, None], edges[1:, None]
    tt = (a + b) / 2 + (b - a) / 2 * x
    ww = (b - a) / 2 * w
    f = accel * np.sin(W * tt)
    phi = theta * np.sin(W * tt)
    return float(np.sum(ww * f * np.cos(phi))), float(np.sum(ww * f * np.sin(phi)))


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6])
def test_sculling_drift_is_what_the_typed_coefficients_predict(n: int) -> None:
    """The down velocity after M updates is truth + M (alg - exact) theta A/W (sculling uses the
    same coefficients as coning: conventions.md). Gravity of the laboratory mode is constant, taken
    at the start: gamma_e = 9.7803253359 m/s^2 exactly at latitude 0, height 0 (TR8350.2)."""
    theta, accel = 1e-3, 10.0
    lam = W * H
    k = np.arange(n * UPDATES + 1)
    tk = k * H
    dth = np.zeros((len(tk) - 1, 3))
    dv = np.zeros_like(dth)
    dth[:, 0] = theta * np.diff(np.sin(W * tk))
    dv[:, 1] = accel / W * -np.diff(np.cos(W * tk))
    sol = navigate(tk[1:], dth, dv, dict(t=0.0, lat=0.0, lon=0.0, h=0.0, vn=0.0, ve=0.0, vd=0.0, roll=0.0,
                                         pitch=0.0, yaw=0.0), samples=n, earth_model="none")
    t_end = tk[-1]
    _, vz_true = sculling_truth_v(theta, accel, t_end)
    gamma_e = 9.7803253359
    measured = sol[-1, 6] - gamma_e * t_end - vz_true
    unit = theta * accel / W
    predicted = UPDATES * alg_minus_exact([float(c) for c in COEFFS[n]], n, lam) * unit
    tol = 1e-6 * abs(predicted) + 10 * theta**3 * accel * t_end + UPDATES * 1e-15 * gamma_e * t_end
    if n >= 2:
        assert visibility(n, lam) * UPDATES * unit > 20 * tol
    print(f"\nN={n}: vz error {measured:.6e} m/s, predicted {predicted:.6e}, tol {tol:.1e}")
    assert measured == pytest.approx(predicted, abs=tol)
