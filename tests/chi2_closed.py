"""Chi-square tails in closed form (Abramowitz & Stegun 26.4.4, 26.4.5), for tests' expected values.

``qK(x)`` is P(X > x) for K degrees of freedom; ``upper(tail, p)`` the x with tail(x) = p by
bisection, to the last bit. Independent of mavins.core.redundancy, which the tests check with them.
"""

from __future__ import annotations

import math
from typing import Callable


def dens(z: float) -> float:
    """Standard normal density."""
    return math.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)


def phi(z: float) -> float:
    """Standard normal distribution function."""
    return 0.5 * math.erfc(-z / math.sqrt(2.0))


def q1(x: float) -> float:
    """1 dof: P(Z^2 > x) = erfc(sqrt(x/2)) (26.4.4)."""
    return math.erfc(math.sqrt(0.5 * x))


def q2(x: float) -> float:
    return math.exp(-0.5 * x)  # 26.4.5


def q3(x: float) -> float:
    return math.erfc(math.sqrt(0.5 * x)) + 2.0 * dens(math.sqrt(x)) * math.sqrt(x)  # 26.4.4


def p3(x: float) -> float:
    """1 - Q for 3 dof, without the cancellation of 1 - q3 (26.4.4)."""
    return math.erf(math.sqrt(0.5 * x)) - 2.0 * dens(math.sqrt(x)) * math.sqrt(x)


def q5(x: float) -> float:
    r = math.sqrt(x)
    return math.erfc(r / math.sqrt(2.0)) + 2.0 * dens(r) * (r + r**3 / 3.0)  # 26.4.4


def q6(x: float) -> float:
    return math.exp(-0.5 * x) * (1.0 + 0.5 * x + x * x / 8.0)  # 26.4.5


def log_q10(x: float) -> float:
    """log Q(x | 10) = -x/2 + log(sum_(r<5) (x/2)^r / r!) (26.4.5), in logs where Q underflows."""
    u = 0.5 * x
    return -u + math.log(sum(u**r / math.factorial(r) for r in range(5)))


def upper(tail: Callable[[float], float], p: float) -> float:
    """x with tail(x) = p, by bisection on a closed-form tail (to the last bit)."""
    lo, hi = 0.0, 1000.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if tail(mid) > p else (lo, mid)
    return 0.5 * (lo + hi)
