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

import math

import numpy as np
import pytest

from mavins.core import aided, earth, kalman, smoother
from mavins.core import errmodel as em
from mavins.core import strapdown as sd
from mavins.core.jit import for_frame

NX = em.NX


def make_store(pp: np.ndarray, pm: np.ndarray, phi: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """A store (smoother.py) of E epochs over all n states of ``pp`` (P^+), ``pm`` (P^-), ``phi`` (row k: the
    transition from k to k + 1) and ``dx``: the layout written out by hand from the module docstring (t, row,
    dx, e, P^-, P^+, Phi from the epoch before), not through smoother.record."""
    n_ep, n = dx.shape
    store = np.zeros((n_ep, 2 + 2 * n + 3 * n * n))
    for k in range(n_ep):
        store[k, 0], store[k, 1] = 0.1 * k, 2 * k
        store[k, 2:2 + n] = dx[k]
        o = 2 + 2 * n
        store[k, o:o + n * n] = pm[k].ravel()
        store[k, o + n * n:o + 2 * n * n] = pp[k].ravel()
        store[k, o + 2 * n * n:] = phi[k - 1].ravel() if k > 0 else np.eye(n).ravel()  # the first: the start's
    return store


def backward(pp, pm, phi, dx):  # type: ignore[no-untyped-def]
    """smoother.backward over a store built from the arrays: (e, P^s, singular epochs)."""
    n_ep, n = dx.shape
    store = make_store(pp, pm, phi, dx)
    bad = smoother.backward(store, n_ep, n)
    o = 2 + 2 * n
    return store[:, 2 + n:o].copy(), store[:, o + n * n:o + 2 * n * n].reshape(n_ep, n, n).copy(), bad


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
    e, ps, bad = backward(*random_walk(n_ep, p0, q, r, x0, z))
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
    e, ps, bad = backward(pp, pm, phi, dx)
    e1, ps1, _ = backward(pp1, pm1, phi1, dx1)
    assert bad == 0
    np.testing.assert_array_equal(e[:, 0], e1[:, 0])
    np.testing.assert_array_equal(ps[:, 0, 0], ps1[:, 0, 0])
    assert not e[:, 1].any() and not ps[:, 1, 1].any()


def test_an_epoch_without_a_positive_definite_prior_keeps_the_forward_estimate() -> None:
    """P^- not positive definite over its active states (here a negative variance): that epoch's gain is
    zero, so its smoothed error is 0 and its covariance the forward P^+; it is counted."""
    pp, pm, phi, dx = random_walk(5, 4.0, 0.5, 1.0, 0.3, 2.0)
    pm[2, 0, 0] = -1.0
    e, ps, bad = backward(pp, pm, phi, dx)
    assert bad == 0  # a negative diagonal is not active: nothing to invert, the epoch before keeps e = 0
    assert e[1, 0] == 0.0 and ps[1, 0, 0] == pp[1, 0, 0]
    pm2 = np.zeros((5, 2, 2))
    pm2[:, 0, 0] = pm[:, 0, 0]
    pm2[:, 1, 1] = 1.0
    pm2[3, 0, 1] = pm2[3, 1, 0] = 10.0  # active but not positive definite
    pp2, phi2 = np.zeros((5, 2, 2)), np.zeros((5, 2, 2))
    pp2[:, 0, 0], pp2[:, 1, 1], phi2[:, 0, 0], phi2[:, 1, 1] = pp[:, 0, 0], 1.0, 1.0, 1.0
    e, ps, bad = backward(pp2, pm2, phi2, np.zeros((5, 2)))
    assert bad == 1 and np.array_equal(ps[2], pp2[2])
    assert np.isfinite(ps).all() and np.isfinite(e).all()  # the epochs before it go on from P^+
    pm2[4, 0, 1] = pm2[4, 1, 0] = 10.0  # a second one: both counted
    assert backward(pp2, pm2, phi2, np.zeros((5, 2)))[2] == 2


def test_no_epoch_or_one_is_left_as_it_is() -> None:
    """An empty store, and a store of one epoch (the last is its own smoothed estimate), are left alone."""
    assert smoother.backward(np.zeros((0, smoother.store_width(2))), 0, 2) == 0
    pp, pm, phi, dx = random_walk(1, 4.0, 0.5, 1.0, 0.3, 2.0)
    store = make_store(pp, pm, phi, dx)
    before = store.copy()
    assert smoother.backward(store, 1, 1) == 0
    np.testing.assert_array_equal(store, before)


def test_record_writes_the_active_states_in_the_documented_layout() -> None:
    """smoother.record over states (1, 4, 7) of random NX x NX matrices: the row make_store lays out by hand,
    the width store_width gives, and the transition product back at the identity."""
    rng = np.random.default_rng(3)
    Pm, Pp, phi = (rng.standard_normal((NX, NX)) for _ in range(3))
    dx = rng.standard_normal(NX)
    act = np.array([1, 4, 7])
    tail = phi.ravel().copy()
    store = np.zeros((2, smoother.store_width(3)))
    assert smoother.record(store, 0, 12.5, 7, Pm, Pp, tail, dx, act) == 1
    ix = np.ix_(act, act)
    want = make_store(Pp[ix][None], Pm[ix][None], np.zeros((1, 3, 3)), dx[act][None])[0]
    want[0], want[1] = 12.5, 7
    o = 2 + 2 * 3 + 2 * 9
    want[o:] = phi[ix].ravel()
    assert store.shape[1] == want.shape[0]
    np.testing.assert_array_equal(store[0], want)
    np.testing.assert_array_equal(tail.reshape(NX, NX), np.eye(NX))
    assert smoother.record(store, 2, 13.0, 8, Pm, Pp, tail, dx, act) == 2  # full: nothing more
    assert not store[1].any()


def test_chain_transition_is_the_product_of_the_propagations() -> None:
    """Two propagations after a reset: the tail holds Phi_2 Phi_1 (the later on the left)."""
    rng = np.random.default_rng(4)
    p1, p2 = rng.standard_normal((NX, NX)), rng.standard_normal((NX, NX))
    tail = np.full(NX * NX + 5, 9.0)
    smoother.reset_transition(tail)
    smoother.chain_transition(tail, p1)
    smoother.chain_transition(tail, p2)
    np.testing.assert_allclose(tail[:NX * NX].reshape(NX, NX), p2 @ p1, rtol=1e-13, atol=1e-12)
    assert np.all(tail[NX * NX:] == 9.0)


def moving_state() -> np.ndarray:
    return sd.init_state(0.0, math.radians(47.4), math.radians(8.5), 500.0, np.array([8.0, -3.0, 0.5]),
                         math.radians(15.0), math.radians(-10.0), math.radians(120.0))


CFG = sd.make_config(samples=2)


def an_error() -> np.ndarray:
    x = np.zeros(NX)
    x[0:9] = [2e-3, -1e-3, 5e-3, 0.3, -0.2, 0.1, 12.0, -7.0, 3.0]
    x[em.X_BG:em.X_BG + 3] = [1e-4, 2e-4, -3e-4]
    x[em.X_BA:em.X_BA + 3] = [0.01, -0.02, 0.03]
    x[em.X_BARO] = 1.5
    return x


def test_nominal_difference_inverts_feedback() -> None:
    """The error state between a nominal and kalman.feedback of it by x is x: attitude, velocity and
    sensors to rounding; position to the second order of the transport rotation, dp^2 tan L / R (12 m:
    2.5e-5 m)."""
    s_a, b_a = moving_state(), np.arange(kalman.B_SIZE) * 1e-3
    s_b, b_b, x = s_a.copy(), b_a.copy(), an_error()
    kalman.feedback(s_b, CFG, b_b, x.copy())
    got = smoother.nominal_difference(s_a, b_a, s_b, b_b, CFG)
    np.testing.assert_allclose(got[0:3], x[0:3], rtol=1e-12, atol=1e-16)
    np.testing.assert_allclose(got[3:6], x[3:6], rtol=0, atol=1e-14)
    np.testing.assert_allclose(got[6:9], x[6:9], rtol=0, atol=12.0 ** 2 * math.tan(math.radians(47.4)) / 6.3e6)
    np.testing.assert_allclose(got[em.X_SENSORS:], x[em.X_SENSORS:], rtol=0, atol=1e-15)


def test_nominal_difference_in_the_laboratory_is_the_displacement() -> None:
    """earth = none: position errors are the local displacement exactly (feedback moves S.PF by -dp)."""
    cfg = sd.make_config(samples=2, earth_model="none")
    s_a, b = moving_state(), np.zeros(kalman.B_SIZE)
    s_b, x = s_a.copy(), an_error()
    kalman.feedback(s_b, cfg, b.copy(), x.copy())
    got = smoother.nominal_difference(s_a, b, s_b, b, cfg)
    np.testing.assert_allclose(got[6:9], x[6:9], rtol=0, atol=1e-12)


def test_correct_solution_moves_a_row_as_feedback_moves_the_state() -> None:
    """The solution row of a state corrected by x equals its row corrected by x (correct_solution):
    attitude (quaternion, Euler) and velocity to rounding, position to the transport rotation's second
    order (as test_nominal_difference_inverts_feedback)."""
    s, x = moving_state(), an_error()
    row = np.empty(14)
    for_frame(sd.solution_row, sd.GEOGRAPHIC)(s, CFG, row)
    kalman.feedback(s, CFG, np.zeros(kalman.B_SIZE), x.copy())
    want = np.empty(14)
    for_frame(sd.solution_row, sd.GEOGRAPHIC)(s, CFG, want)
    smoother.correct_solution(row, x)
    np.testing.assert_allclose(row[7:14], want[7:14], rtol=0, atol=1e-14)
    np.testing.assert_allclose(row[4:7], want[4:7], rtol=0, atol=1e-14)
    tol = 12.0 ** 2 * math.tan(math.radians(47.4)) / 6.3e6
    assert abs(row[1] - want[1]) * 6.37e6 < tol and abs(row[2] - want[2]) * 4.3e6 < tol
    assert abs(row[3] - want[3]) < 1e-9


def test_smooth_rows_interpolates_between_epochs_and_keeps_the_rows_after_the_last() -> None:
    """Two epochs at rows 0 and 4 (t 10 and 12 s) over the north position and the x gyro bias: row 2 (t 11 s)
    is corrected by the mean of e^s_0 and e^s_1 + dx_1, its variance the mean of P^s_0 and P^s_1; row 0 by
    e^s_0 with P^s_0; rows 4 and 5 (the last epoch and after) keep the forward values."""
    act = np.array([em.X_DP, em.X_BG])
    na = 2
    store = np.zeros((2, smoother.store_width(na)))
    o_dx, o_e, o_pm, o_pp, o_phi = 2, 4, 6, 10, 14  # the module docstring's layout over two states, by hand
    assert smoother.store_slots(na) == (o_dx, o_e, o_pm, o_pp, o_phi)
    store[:, 0], store[:, 1] = (10.0, 12.0), (0, 4)
    store[0, o_e:o_e + 2] = (2.0, 1e-4)  # e^s_0: 2 m north, 1e-4 rad/s
    store[1, o_e:o_e + 2] = (0.0, 0.0)
    store[1, o_dx:o_dx + 2] = (4.0, 3e-4)
    store[0, o_pp:o_pp + 4] = (4.0, 0.0, 0.0, 1e-8)
    store[1, o_pp:o_pp + 4] = (16.0, 0.0, 0.0, 3e-8)
    out = np.zeros((6, aided.ROW_SIZE))
    lat = math.radians(47.0)
    out[:, 0] = 10.0 + np.arange(6) * 0.5
    out[:, 1], out[:, 3], out[:, 10] = lat, 100.0, 1.0  # latitude, height, identity attitude
    out[:, 23] = 5e-4  # forward gyro bias x
    out[:, 29] = 7e-3  # forward sigma_bg_x
    fwd = out.copy()
    aided.smooth_rows(out, 6, np.array([1, 1, 1, 1, 2, 2]), store, 2, act)
    r_n = earth.radii(lat)[0] + 100.0
    for j, (e_n, e_b, var_n, var_b) in {0: (2.0, 1e-4, 4.0, 1e-8), 2: (3.0, 2e-4, 10.0, 2e-8)}.items():
        assert out[j, 1] == pytest.approx(lat - e_n / r_n, abs=1e-15)
        assert out[j, 23] == pytest.approx(5e-4 - e_b, abs=1e-18)
        assert out[j, 14] == pytest.approx(math.sqrt(var_n), rel=1e-15)
        assert out[j, 29] == pytest.approx(math.sqrt(var_b), rel=1e-15)
    np.testing.assert_array_equal(out[4:], fwd[4:])


def test_a_row_written_before_its_epochs_measurements_takes_the_prior_error() -> None:
    """A row at t_1 written before epoch 1 was recorded (a late measurement applied after the row went out,
    as on the live path): its nominal is epoch 1's prior, so it is corrected by e^s_1 + dx_1 with P^s_1."""
    act = np.array([em.X_DP])
    store = np.zeros((2, smoother.store_width(1)))
    store[:, 0] = (0.0, 1.0)
    store[0, 3], store[1, 2] = 2.0, 4.0  # e^s_0 = 2 m; dx_1 = 4 m (e^s_1 = 0)
    store[0, 5], store[1, 5] = 4.0, 16.0  # P^s_0, P^s_1
    out = np.zeros((2, aided.ROW_SIZE))
    lat = math.radians(47.0)
    out[:, 0], out[:, 1], out[:, 10] = (1.0, 1.0), lat, 1.0
    aided.smooth_rows(out, 2, np.array([1, 2]), store, 2, act)
    r_n = earth.radii(lat)[0]
    assert out[0, 1] == pytest.approx(lat - 4.0 / r_n, abs=1e-15) and out[0, 14] == pytest.approx(4.0)
    assert out[1, 1] == lat and out[1, 14] == 0.0  # at the last epoch: the forward row


def test_filter_row_writes_over_whatever_the_row_held() -> None:
    """A row full of NaN (np.empty may hand out any bytes) gets every filter column written: none stays NaN."""
    out = np.full(aided.ROW_SIZE, np.nan)
    out[:14] = 0.0
    aided.filter_row(np.eye(NX), np.zeros(kalman.B_SIZE), out)
    assert np.isfinite(out).all()


def test_rows_before_the_first_epoch_and_between_epochs_at_one_time() -> None:
    """Row 0 written before any epoch keeps the forward values (and the rows after it are still smoothed);
    row 1 refers to epoch 0 while epoch 1 has the same time (two updates at one instant): it takes epoch 1's
    prior error, e^s_1 + dx_1; row 2, written after t_1 but before epoch 1 (a late measurement stamped
    earlier), is held at t_1, not carried beyond it."""
    act = np.array([em.X_DP])
    store = np.zeros((3, smoother.store_width(1)))
    store[:, 0] = (1.0, 1.0, 3.0)
    store[:, 3] = (1.0, 0.5, 0.0)  # e^s
    store[:, 2] = (0.0, 2.0, 4.0)  # dx
    store[:, 5] = (9.0, 9.0, 9.0)  # P^s
    lat = math.radians(47.0)
    out = np.zeros((3, aided.ROW_SIZE))
    out[:, 0], out[:, 1], out[:, 10] = (0.5, 1.0, 5.0), lat, 1.0
    fwd = out.copy()
    aided.smooth_rows(out, 3, np.array([0, 1, 2]), store, 3, act)
    r_n = earth.radii(lat)[0]
    np.testing.assert_array_equal(out[0], fwd[0])
    assert out[1, 1] == pytest.approx(lat - 2.5 / r_n, abs=1e-16) and out[1, 14] == 3.0
    assert out[2, 1] == pytest.approx(lat - 4.0 / r_n, abs=1e-16) and out[2, 14] == 3.0


@pytest.mark.parametrize("pitch, yaw", [(0.0, 30.0), (0.0, 179.9), (90.0, 30.0)])
def test_correct_solution_keeps_the_scalar_part_non_negative(pitch: float, yaw: float) -> None:
    """A heading correction (across 180 deg; at pitch 90 deg, where the Euler angles take the heading from
    the DCM's first two columns): the corrected row's quaternion keeps a non-negative scalar part and its
    Euler angles are those solution_row writes for the corrected state."""
    s = sd.init_state(0.0, math.radians(47.4), math.radians(8.5), 500.0, np.zeros(3), 0.0, math.radians(pitch),
                      math.radians(yaw))
    x = np.zeros(NX)
    x[2] = math.radians(-0.5)  # feedback turns the heading by +0.5 deg
    row, want = np.empty(14), np.empty(14)
    for_frame(sd.solution_row, sd.GEOGRAPHIC)(s, CFG, row)
    kalman.feedback(s, CFG, np.zeros(kalman.B_SIZE), x.copy())
    for_frame(sd.solution_row, sd.GEOGRAPHIC)(s, CFG, want)
    smoother.correct_solution(row, x)
    assert row[10] >= 0.0
    np.testing.assert_allclose(row[7:14], want[7:14], rtol=0, atol=1e-14)


def test_filter_sigmas_of_small_variances() -> None:
    """Every sigma column is the square root of its variance, below 1 too (P = 0.25 I: 0.5; the bias columns
    of the sum of two parts: sqrt(0.5))."""
    out = np.zeros(aided.ROW_SIZE)
    aided.filter_sigmas(0.25 * np.eye(NX), out)
    sig = [c for c in range(aided.ROW_SIZE) if aided.ROW_COLUMNS[c].startswith("sigma_")]
    want = [math.sqrt(0.5) if aided.ROW_COLUMNS[c][6:8] in ("bg", "ba") else 0.5 for c in sig]
    np.testing.assert_allclose(out[sig], want, rtol=1e-15)


def test_scratch_is_a_zeroed_writable_file_backed_array() -> None:
    a = aided.scratch((3, 4))
    assert a.shape == (3, 4) and a.dtype == np.float64 and not a.any()
    a[2, 3] = 5.0
    assert a[2, 3] == 5.0 and a.base is not None  # a view of the mapped file
    assert aided.scratch((0, 5)).shape == (0, 5)


def test_epoch_bound_counts_what_can_make_an_epoch() -> None:
    """Rows of 0.1 s from 1 to 11 s; 3 fixes, 2 baro, 1 magnetometer row; two rest windows holding 5 and 0 IMU rows,
    an epoch every 0.5 s: 3 + 2 + 1 + 2 x 2 windows + 2 + 5 + 0 + 10 / 0.5 + 1 = 38."""
    t = 1.0 + np.arange(0, 101) * 0.1
    g, b, m = np.zeros((3, 10)), np.zeros((2, 3)), np.zeros((1, 5))
    z = np.array([[2.0, 2.5, 0.0, 0.0], [20.0, 21.0, 0.0, 0.0]])
    assert aided.epoch_bound(t, g, b, m, z, 0.5) == 3 + 2 + 1 + 4 + 2 + 5 + 0 + 20 + 1
    assert aided.epoch_bound(t[:0], g, b, m, z[:0], 1.0) == 3 + 2 + 1 + 2
