"""core/smoother.py, the Rauch-Tung-Striebel recursion of the closed-loop filter, against closed forms.

A random walk ``x_{k+1} = x_k + w_k`` (var q per step) seen by a fix at the first epoch (the forward
filter's posterior variance there p0) and one at the last (variance r), nothing between: given both, the
state at epoch k combines what the first fix says (variance ``p0 + k q``) with what the last says
(variance ``r + (N - k) q``), independent of each other (the two-filter form of the smoother, which the
RTS recursion equals for a linear Gaussian model: Fraser & Potter, IEEE TAC 14(4), 1969):

    P^s_k = 1 / (1 / (p0 + k q) + 1 / (r + (N - k) q)),   x^s_k = P^s_k (x0 / (p0 + k q) + z / (r + (N - k) q))

The forward filter's records: ``P^+_k = P^-_k = p0 + k q`` for k < N, and at N ``P^-_N = p0 + N q``,
``P^+_N = P^-_N r / (P^-_N + r)``, the correction ``dx_N = K (x0 - z)`` (predicted minus measured times
the gain ``K = P^-_N / (P^-_N + r)``) that moved the nominal from x0 to the posterior.
"""

from __future__ import annotations

import numpy as np
import pytest

from mavins.core import smoother


def random_walk(n_ep: int, p0: float, q: float, r: float, x0: float, z: float):  # type: ignore[no-untyped-def]
    pm = p0 + q * np.arange(n_ep)
    pp = pm.copy()
    k_gain = pm[-1] / (pm[-1] + r)
    pp[-1] = pm[-1] * r / (pm[-1] + r)
    dx = np.zeros((n_ep, 1))
    dx[-1, 0] = k_gain * (x0 - z)
    phi = np.ones((n_ep, 1, 1))
    return pp.reshape(n_ep, 1, 1), pm.reshape(n_ep, 1, 1), phi, dx


@pytest.mark.parametrize("p0, q, r", [(4.0, 0.5, 1.0), (0.01, 2.0, 3.0), (1.0, 1e-6, 1e-4)])
def test_a_random_walk_between_two_fixes_is_the_two_filter_combination(p0: float, q: float, r: float) -> None:
    n_ep, x0, z = 11, 0.3, 2.0
    e, ps, bad = smoother.backward(*random_walk(n_ep, p0, q, r, x0, z))
    assert bad == 0
    k = np.arange(n_ep)
    fwd, bwd = p0 + k * q, r + (n_ep - 1 - k) * q
    want_p = 1.0 / (1.0 / fwd + 1.0 / bwd)
    want_x = want_p * (x0 / fwd + z / bwd)
    # P^s = P^+ + A (P^s - P^-) A^T cancels P^+ down to P^s: rounding of a few ulp of P^+ per epoch
    tol = 16 * n_ep * np.finfo(float).eps * float(np.max(fwd / want_p))
    np.testing.assert_allclose(ps[:, 0, 0], want_p, rtol=tol)
    nominal = np.full(n_ep, x0)
    nominal[-1] = x0 - (p0 + (n_ep - 1) * q) / (p0 + (n_ep - 1) * q + r) * (x0 - z)  # the posterior at N
    np.testing.assert_allclose(nominal - e[:, 0], want_x, rtol=1e-12, atol=1e-15)  # smoothed = nominal - error
    assert e[-1, 0] == 0.0


def test_a_state_that_takes_no_part_stays_out() -> None:
    """A second state with zero variance throughout (not estimated): the first state's smoothing is that of
    the scalar case, the second keeps e = 0 and zero variance, and no epoch is counted singular."""
    n_ep = 8
    pp1, pm1, phi1, dx1 = random_walk(n_ep, 4.0, 0.5, 1.0, 0.3, 2.0)
    pp, pm, phi = (np.zeros((n_ep, 2, 2)) for _ in range(3))
    pp[:, 0, 0], pm[:, 0, 0], phi[:, 0, 0], phi[:, 1, 1] = pp1[:, 0, 0], pm1[:, 0, 0], 1.0, 1.0
    dx = np.zeros((n_ep, 2))
    dx[:, 0] = dx1[:, 0]
    dx[-1, 1] = 5.0  # a correction of a state without variance cannot reach the others
    e, ps, bad = smoother.backward(pp, pm, phi, dx)
    e1, ps1, _ = smoother.backward(pp1, pm1, phi1, dx1)
    assert bad == 0
    np.testing.assert_array_equal(e[:, 0], e1[:, 0])
    np.testing.assert_array_equal(ps[:, 0, 0], ps1[:, 0, 0])
    assert not e[:, 1].any() and not ps[:, 1, 1].any()


def test_an_epoch_without_a_positive_definite_prior_keeps_the_forward_estimate() -> None:
    """P^- not positive definite over its active states (here a negative variance): that epoch's gain is
    zero, so its smoothed error is 0 and its covariance the forward P^+; it is counted."""
    pp, pm, phi, dx = random_walk(5, 4.0, 0.5, 1.0, 0.3, 2.0)
    pm[2, 0, 0] = -1.0
    e, ps, bad = smoother.backward(pp, pm, phi, dx)
    assert bad == 0  # a negative diagonal is not active: nothing to invert, the epoch before keeps e = 0
    assert e[1, 0] == 0.0 and ps[1, 0, 0] == pp[1, 0, 0]
    pm2 = np.zeros((5, 2, 2))
    pm2[:, 0, 0] = pm[:, 0, 0]
    pm2[:, 1, 1] = 1.0
    pm2[3, 0, 1] = pm2[3, 1, 0] = 10.0  # active but not positive definite
    pp2, phi2 = np.zeros((5, 2, 2)), np.zeros((5, 2, 2))
    pp2[:, 0, 0], pp2[:, 1, 1], phi2[:, 0, 0], phi2[:, 1, 1] = pp[:, 0, 0], 1.0, 1.0, 1.0
    e, ps, bad = smoother.backward(pp2, pm2, phi2, np.zeros((5, 2)))
    assert bad == 1 and np.array_equal(ps[2], pp2[2])
