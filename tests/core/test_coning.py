"""What the mutation runs found unchecked in mavins/core/coning.py (docs/testing.md).

Expected values typed from docs/conventions.md ``--samples``: the optimal N-sample
coefficients (Lee, Yoon et al. 1990; Ignagni 1996), ``dphi = [sum_{i<N} k_{N-i}
dtheta_i] x dtheta_N``, sculling with the same coefficients ``sum_{i<N} k_{N-i}
(dtheta_i x dv_N + dv_i x dtheta_N)`` (Ignagni 1998), Savage's rotation
compensation ``(1 - cos p)/p^2 (phi x dv) + (1 - sin(p)/p)/p^2 phi x (phi x dv)``,
and the rate-sample forms of docs/algorithms.md (``h^2/12 w0 x w1``,
``h^2/12 (w0 x f1 + f0 x w1)``). Cross products by numpy; the two Savage
coefficients from their Taylor series in exact rational arithmetic (so the
reference carries no cancellation error). Nothing is taken from the module.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from mavins.core import coning

# docs/conventions.md --samples, oldest sample first
TYPED = {
    2: [2 / 3],
    3: [9 / 20, 27 / 20],
    4: [54 / 105, 92 / 105, 214 / 105],
    5: [250 / 504, 525 / 504, 650 / 504, 1375 / 504],
    6: [2315 / 4620, 4558 / 4620, 7296 / 4620, 7834 / 4620, 15797 / 4620],
}

RNG = np.random.default_rng(20)


def test_coefficient_table():
    """Rows 2..6 hold the typed coefficients, the rest of the table is zero; at most 6 samples."""
    assert coning.MAX_SAMPLES == 6
    assert coning.CONING_COEFFS.shape == (7, 5)
    for n in range(7):
        row = coning.CONING_COEFFS[n]
        want = TYPED.get(n, [])
        np.testing.assert_array_equal(row[:len(want)], want)
        np.testing.assert_array_equal(row[len(want):], 0.0)


def increments(n: int, off: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    th = RNG.normal(0.0, 0.01, (n, 3))
    dv = RNG.normal(0.0, 0.1, (n, 3))
    buf = np.concatenate([RNG.normal(size=off), th.ravel(), dv.ravel(), RNG.normal(size=4)])
    return buf, th, dv


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6])
@pytest.mark.parametrize("off", [0, 5])
def test_nsample_coning(n, off):
    buf, th, _ = increments(n, off)
    k = TYPED.get(n, [])
    acc = sum((k[i] * th[i] for i in range(n - 1)), np.zeros(3))
    want = np.cross(acc, th[n - 1])
    got = coning.nsample_coning(buf, off, n)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-20)
    if n == 1:
        assert got == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6])
@pytest.mark.parametrize("off", [0, 5])
def test_nsample_sculling(n, off):
    buf, th, dv = increments(n, off)
    k = TYPED.get(n, [])
    want = sum((k[i] * (np.cross(th[i], dv[n - 1]) + np.cross(dv[i], th[n - 1])) for i in range(n - 1)),
               np.zeros(3))
    got = coning.nsample_sculling(buf, off, off + 3 * n, n)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-20)


def savage_coefficients(p2: float) -> tuple[float, float]:
    """``(1 - cos p)/p^2 = sum (-1)^j p^2j/(2j+2)!`` and ``(1 - sin p/p)/p^2 = sum (-1)^j p^2j/(2j+3)!``,
    summed exactly for the given double p^2 and rounded once."""
    x = Fraction(p2)
    a = sum(Fraction((-1) ** j) * x ** j / math.factorial(2 * j + 2) for j in range(30))
    b = sum(Fraction((-1) ** j) * x ** j / math.factorial(2 * j + 3) for j in range(30))
    return float(a), float(b)


# angles below the series limit (p < 1e-2), at it, and well above it (closed form)
PHIS = [(1e-6, -2e-6, 3e-6), (0.004, 0.005, -0.006), (0.0099, 0.0, 0.0), (0.0, 0.0099999, 0.0), (0.01, 0.0, 0.0),
        (0.3, -0.2, 0.25), (1.2, 0.9, -1.5), (0.0, 0.0, 3.0)]


@pytest.mark.parametrize("phi", PHIS)
def test_rotation_compensation(phi):
    phi = np.array(phi)
    dv = np.array([0.7, -1.3, 9.81 * 0.01])
    p2 = float(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
    a, b = savage_coefficients(p2)
    want = a * np.cross(phi, dv) + b * np.cross(phi, np.cross(phi, dv))
    got = np.array(coning.rotation_compensation(*phi, *dv))
    # the closed form (p >= 1e-2) loses about eps/p^2 to cancellation in 1 - cos p and 1 - sin p/p
    rel = 1e-15 if p2 < 1e-4 else max(1e-15, 4e-16 / p2)
    scale = np.linalg.norm(phi) * np.linalg.norm(dv)
    np.testing.assert_allclose(got, want, rtol=0, atol=rel * scale)


def test_rotation_compensation_first_terms():
    """``1/2 phi x dv + 1/6 phi x (phi x dv)`` to first order (conventions.md): the coefficients
    at p -> 0 are 1/2 and 1/6."""
    phi = np.array([1e-9, 0.0, 0.0])
    dv = np.array([0.0, 1.0, 0.0])
    got = coning.rotation_compensation(*phi, *dv)
    assert got[2] == pytest.approx(0.5e-9, rel=1e-15, abs=0)
    assert got[1] == pytest.approx(-1e-18 / 6.0, rel=1e-14, abs=0)


@pytest.mark.parametrize("h", [0.01, 0.0025])
def test_rate_coning_and_sculling(h):
    w0, w1 = np.array([0.3, -0.2, 0.5]), np.array([-0.1, 0.4, 0.25])
    f0, f1 = np.array([0.5, -0.3, -9.8]), np.array([1.5, 0.2, -9.7])
    np.testing.assert_allclose(coning.rate_coning(*w0, *w1, h), h * h / 12.0 * np.cross(w0, w1), rtol=1e-14, atol=0)
    np.testing.assert_allclose(coning.rate_sculling(*w0, *f0, *w1, *f1, h),
                               h * h / 12.0 * (np.cross(w0, f1) + np.cross(f0, w1)), rtol=1e-14, atol=0)


@pytest.mark.parametrize("px", [2.0 ** -7, 2.0 ** -4, 0.5])
def test_rotation_compensation_coefficients_exactly(px):
    """With phi = [px, 0, 0] and dv = [0, 1, 0] the result is ``[0, -b px^2, a px]``; for px a power of
    two both Savage coefficients come out unrounded, so each is compared with its exact value to two
    ulp (the series branch at px = 2^-7, where the p^4 terms are 1e-11 and 2e-12 of a and b)."""
    out = coning.rotation_compensation(px, 0.0, 0.0, 0.0, 1.0, 0.0)
    a, b = savage_coefficients(px * px)
    assert out[0] == 0.0
    ulp = 2.0 * 2.0 ** -53
    tol = ulp if px < 0.01 else 8e-16 / (px * px)  # the closed form's cancellation (see above)
    assert out[2] / px == pytest.approx(a, rel=max(tol, 2 * ulp), abs=0)
    assert -out[1] / (px * px) == pytest.approx(b, rel=max(tol, 2 * ulp), abs=0)
