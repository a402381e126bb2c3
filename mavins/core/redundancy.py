"""Redundant inertial sensors: fusion, parity space, fault detection and isolation (pure).

The model (Zhang & Sun, *Strapdown Inertial Navigation Systems*, sec. 5.1;
Sturza 1988, sec. "Measurement model") for ``n`` single-axis sensors that
measure one 3-vector ``x`` (angular rate or specific force, body frame FRD)::

    m = H x + b + e        m, b, e: (n,);  H: (n, 3), one unit row per sensor axis

A triad is three rows of ``H`` (its rotation from body to sensor axes), so a
set of IMUs mounted in the same frame stacks identity blocks. With per-sensor
noise sigmas ``s_i`` the set is whitened by ``W = diag(1/s_i)`` first.

* Fused estimate, weighted least squares (Sturza 1988, "least-squares
  estimate"): ``x = (H^T W^2 H)^-1 H^T W^2 m``.
* Parity matrix ``V`` (Potter & Suman 1977, parity equations; Sturza 1988,
  "parity vector"): the ``(n-3, n)`` rows span the null space of
  ``(W H)^T``, so ``V W H = 0`` and ``V V^T = I``; parity vector
  ``p = V W m`` does not depend on ``x`` and, without fault, is N(0, I).
* Detection: ``p^T p`` against the chi-square threshold with ``n - 3``
  degrees of freedom for a false-alarm probability per test (Sturza 1988,
  "detection"; the textbook's sec. 5.3).
* Isolation: the generalised likelihood test picks the sensor ``j`` whose
  parity column ``v_j`` best explains ``p``, ``argmax (v_j^T p)^2 / |v_j|^2``
  (Potter & Suman 1977; Sturza 1988, "isolation"). Two sensors whose columns
  are parallel cannot be told apart: with two triads in one frame each axis has
  two measurements and a one-dimensional parity, so a fault is detected but not
  isolated.
* Optimal configuration of ``N`` single-axis sensors (textbook sec. 5.2):
  ``H^T H = (N/3) I``; figure of merit ``GDOP = sqrt(trace((H^T H)^-1))``,
  ``3/sqrt(N)`` at the optimum.

The chi-square functions (regularised incomplete gamma, quantile, non-central
distribution) are written here because scipy is not a dependency. Everything
run per sample is one compiled kernel, :func:`monitor_run`.

References: M. A. Sturza, "Navigation system integrity monitoring using
redundant measurements", NAVIGATION (J. ION) 35(4), 1988; J. E. Potter and
M. C. Suman, "Thresholdless redundancy management with arrays of skewed
instruments", AGARDograph 224, 1977; Zhang & Sun, ch. 5 (contents in the
project's references); Abramowitz & Stegun (A&S), *Handbook of Mathematical
Functions*, ch. 6 and 26.
"""

from __future__ import annotations

import math

import numpy as np

from .jit import kernel

#: |cos| between two parity columns above which the two sensors cannot be told apart.
PARALLEL_COS = 1.0 - 1e-9

# ----------------------------------------------------------------------------------------------------------------
# Chi-square distribution


def _gamma_series(a: float, x: float) -> float:
    """Regularised lower incomplete gamma P(a, x) by its series (A&S 6.5.29), for x < a + 1."""
    term = 1.0 / a
    total = term
    ap = a
    for _ in range(100000):
        ap += 1.0
        term *= x / ap
        total += term
        if abs(term) < abs(total) * 1e-17:
            break
    return total * math.exp(-x + a * math.log(x) - math.lgamma(a))


def _gamma_cfrac(a: float, x: float) -> float:
    """Regularised upper incomplete gamma Q(a, x) by its continued fraction (A&S 6.5.31), for x >= a + 1,
    evaluated with the modified Lentz method."""
    tiny = 1e-300
    b = x + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-16:
            break
    return h * math.exp(-x + a * math.log(x) - math.lgamma(a))


def gamma_pq(a: float, x: float) -> tuple[float, float]:
    """``(P(a, x), Q(a, x))``, the regularised incomplete gamma functions (A&S 6.5.1, 6.5.3)."""
    if x <= 0.0:
        return 0.0, 1.0
    if x < a + 1.0:
        p = _gamma_series(a, x)
        return p, 1.0 - p
    q = _gamma_cfrac(a, x)
    return 1.0 - q, q


def chi2_cdf(x: float, dof: int) -> float:
    """P(X <= x) for X chi-square with ``dof`` degrees of freedom: ``P(dof/2, x/2)`` (A&S 26.4.19)."""
    return gamma_pq(0.5 * dof, 0.5 * x)[0]


def chi2_sf(x: float, dof: int) -> float:
    """P(X > x) for X chi-square with ``dof`` degrees of freedom: ``Q(dof/2, x/2)`` (A&S 26.4.19)."""
    return gamma_pq(0.5 * dof, 0.5 * x)[1]


def chi2_pdf(x: float, dof: int) -> float:
    """Chi-square density (A&S 26.4.1)."""
    if x <= 0.0:
        return 0.0
    k = 0.5 * dof
    return math.exp((k - 1.0) * math.log(x) - 0.5 * x - k * math.log(2.0) - math.lgamma(k))


def normal_isf(p: float) -> float:
    """z with P(Z > z) = p for a standard normal Z, by Newton on ``log(erfc(z/sqrt 2)/2)`` (A&S 26.2.29)."""
    if not 0.0 < p < 1.0:
        raise ValueError(f"probability must be in (0, 1), got {p!r}")
    if p > 0.5:
        return -normal_isf(1.0 - p)
    z = math.sqrt(-2.0 * math.log(p))  # above the root for p < 0.5 (Chernoff bound)
    for _ in range(200):
        q = 0.5 * math.erfc(z / math.sqrt(2.0))
        dens = math.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
        step = (math.log(q) - math.log(p)) * q / dens
        z += step
        if abs(step) < 1e-14 * max(1.0, abs(z)):
            break
    return z


def chi2_quantile(q: float, dof: int, *, upper: bool = False) -> float:
    """x with P(X <= x) = q (or, with ``upper``, P(X > x) = q) for chi-square ``dof``.

    Start: Wilson-Hilferty, ``x = k (1 - 2/(9k) + z sqrt(2/(9k)))^3`` (A&S 26.4.17); where that is not
    positive (a small lower-tail probability p: q, or 1 - q with ``upper``), the first term of the
    incomplete gamma series, ``P(X <= x) ~ (x/2)^(k/2) / Gamma(k/2 + 1)`` (A&S 6.5.29), solved for x.
    Then Newton on the log of the tail probability, ``x <- x - (log F(x) - log q) F(x) / f(x)`` with F
    the chosen tail and f the density (A&S 26.4.1), kept inside a bracket so that it cannot leave
    (0, inf).
    """
    if not 0.0 < q < 1.0:
        raise ValueError(f"probability must be in (0, 1), got {q!r}")
    if dof < 1:
        raise ValueError(f"degrees of freedom must be >= 1, got {dof}")
    k = float(dof)
    z = normal_isf(q) if upper else -normal_isf(q)
    x = k * (1.0 - 2.0 / (9.0 * k) + z * math.sqrt(2.0 / (9.0 * k))) ** 3
    if x <= 0.0:
        p_low = 1.0 - q if upper else q
        x = max(2.0 * math.exp((math.log(p_low) + math.lgamma(0.5 * k + 1.0)) * 2.0 / k), 1e-300)
    lo, hi = 0.0, math.inf
    target = math.log(q)
    for _ in range(300):
        p_low, p_up = gamma_pq(0.5 * k, 0.5 * x)
        tail = p_up if upper else p_low
        if tail <= 0.0:
            f = -math.inf
        else:
            f = math.log(tail) - target
        # the upper tail falls with x, the lower one rises: keep the root bracketed
        if (f > 0.0) == upper:
            lo = x
        else:
            hi = x
        dens = chi2_pdf(x, dof)
        if tail > 0.0 and dens > 0.0:
            step = f * tail / dens
            new = x + step if upper else x - step
        else:
            new = math.nan
        if not (lo < new < hi):
            new = 0.5 * (lo + hi) if math.isfinite(hi) else 2.0 * x
        if abs(new - x) <= 1e-14 * x:
            return new
        x = new
    return x


def ncx2_cdf(x: float, dof: int, lam: float) -> float:
    """P(X <= x) for the non-central chi-square with ``dof`` and non-centrality ``lam``:
    the Poisson mixture ``sum_j e^{-lam/2} (lam/2)^j / j! P(dof/2 + j, x/2)`` (A&S 26.4.25)."""
    if lam <= 0.0:
        return chi2_cdf(x, dof)
    h = 0.5 * lam
    mode = int(h)
    width = int(12.0 * math.sqrt(h + 1.0)) + 30
    total = 0.0
    for j in range(max(0, mode - width), mode + width + 1):
        w = math.exp(-h + j * math.log(h) - math.lgamma(j + 1.0))
        total += w * gamma_pq(0.5 * dof + j, 0.5 * x)[0]
    return min(max(total, 0.0), 1.0)


def detection_probability(lam: float, dof: int, threshold: float) -> float:
    """P(p^T p > threshold) when p ~ N(mu, I) with ``|mu|^2 = lam`` (Sturza 1988, "detection")."""
    return 1.0 - ncx2_cdf(threshold, dof, lam)


# ----------------------------------------------------------------------------------------------------------------
# The measurement model and its parity space


def triad_rows(rotations: list[np.ndarray] | np.ndarray) -> np.ndarray:
    """``H`` of a set of triads: the stacked rotations body -> sensor axes, (3k, 3)."""
    rots = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    return rots.reshape(-1, 3).copy()


def _weights(n: int, sigma: np.ndarray | float | None) -> np.ndarray:
    if sigma is None:
        return np.ones(n)
    s = np.broadcast_to(np.asarray(sigma, dtype=float), (n,))
    if not np.all(s > 0.0):
        raise ValueError("sensor sigmas must be positive")
    return 1.0 / s


def fusion_matrix(H: np.ndarray, sigma: np.ndarray | float | None = None) -> np.ndarray:
    """``G = (H^T W^2 H)^-1 H^T W^2`` (3, n): the weighted least-squares estimate ``x = G m``
    (Sturza 1988, least-squares estimate; with W = I it is ``(H^T H)^-1 H^T``)."""
    H = np.asarray(H, dtype=float)
    w2 = _weights(H.shape[0], sigma) ** 2
    hw = H * w2[:, None]
    return np.linalg.solve(H.T @ hw, hw.T)


def fuse(H: np.ndarray, m: np.ndarray, sigma: np.ndarray | float | None = None) -> np.ndarray:
    """Least-squares estimate of ``x`` from the measurements ``m`` (n,) or (N, n)."""
    return np.asarray(m, dtype=float) @ fusion_matrix(H, sigma).T


def parity_matrix(H: np.ndarray, sigma: np.ndarray | float | None = None) -> np.ndarray:
    """``V`` (n - 3, n): orthonormal rows spanning the null space of ``(W H)^T``, so ``V W H = 0`` and
    ``V V^T = I`` (Potter & Suman 1977; Sturza 1988, parity vector). The last ``n - 3`` left singular
    vectors of ``W H`` (its full SVD ``W H = U S R^T``; the columns of U past the rank are orthogonal to
    the range of ``W H``). Raises ValueError when the sensors do not observe all three axes."""
    H = np.asarray(H, dtype=float)
    n = H.shape[0]
    if H.ndim != 2 or H.shape[1] != 3 or n < 3:
        raise ValueError(f"H must be (n, 3) with n >= 3, got {H.shape}")
    hw = H * _weights(n, sigma)[:, None]
    u, s, _ = np.linalg.svd(hw, full_matrices=True)
    if s[-1] <= 1e-9 * s[0]:
        raise ValueError("the sensor axes do not span three dimensions")
    return u[:, 3:].T.copy()


def parity_vector(V: np.ndarray, m: np.ndarray, sigma: np.ndarray | float | None = None) -> np.ndarray:
    """``p = V W m``: (n - 3,) or (N, n - 3) for (N, n) measurements."""
    m = np.asarray(m, dtype=float)
    return (m * _weights(m.shape[-1], sigma)) @ V.T


def test_statistic(p: np.ndarray) -> np.ndarray | float:
    """``p^T p`` of whitened parity vectors (last axis): chi-square with ``n - 3`` degrees of freedom
    without fault (Sturza 1988, detection)."""
    return np.sum(np.square(p), axis=-1)


def isolation_scores(V: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``(v_j^T p)^2 / |v_j|^2`` for every sensor j (the generalised likelihood ratio of a fault on j,
    Potter & Suman 1977; Sturza 1988, isolation). Columns of zero norm score 0."""
    norms = np.sum(V * V, axis=0)
    proj = np.asarray(p, dtype=float) @ V
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norms > 1e-24, proj * proj / np.where(norms > 1e-24, norms, 1.0), 0.0)


def isolable(V: np.ndarray) -> np.ndarray:
    """Per sensor: whether a fault on it can be told from a fault on any other sensor, i.e. its parity
    column is non-zero and parallel to no other column."""
    n = V.shape[1]
    norms = np.sqrt(np.sum(V * V, axis=0))
    ok = norms > 1e-12
    if V.shape[0] == 0:
        return np.zeros(n, dtype=bool)
    unit = V / np.where(ok, norms, 1.0)
    cos = np.abs(unit.T @ unit)
    np.fill_diagonal(cos, 0.0)
    return ok & ~np.any(cos > PARALLEL_COS, axis=1)


def isolate(V: np.ndarray, p: np.ndarray) -> int:
    """The sensor the generalised likelihood test picks, or -1 when that sensor is not isolable."""
    scores = isolation_scores(V, p)
    j = int(np.argmax(scores))
    return j if isolable(V)[j] else -1


def reconfigure(H: np.ndarray, active: np.ndarray, sigma: np.ndarray | float | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """``(G, V)`` of the active sensors, widened to all ``n`` columns with zeros for the dropped ones
    (so the same measurement vector can be used before and after)."""
    H = np.asarray(H, dtype=float)
    n = H.shape[0]
    act = np.asarray(active, dtype=bool)
    w = _weights(n, sigma)
    G = np.zeros((3, n))
    G[:, act] = fusion_matrix(H[act], 1.0 / w[act])
    k = int(act.sum()) - 3
    V = np.zeros((max(k, 0), n))
    if k > 0:
        V[:, act] = parity_matrix(H[act], 1.0 / w[act])
    return G, V


# ----------------------------------------------------------------------------------------------------------------
# Sensor configurations (textbook sec. 5.2)


def gdop(H: np.ndarray) -> float:
    """``sqrt(trace((H^T H)^-1))``: the rms error of the fused 3-vector per unit sensor noise
    (textbook sec. 5.2). ``3/sqrt(N)`` for an optimal set of N sensors."""
    H = np.asarray(H, dtype=float)
    return float(np.sqrt(np.trace(np.linalg.inv(H.T @ H))))


#: Half-angle of the optimal cone: ``H^T H = diag(N/2 sin^2 a, N/2 sin^2 a, N cos^2 a)`` is ``N/3 I``
#: when ``tan^2 a = 2`` (textbook sec. 5.2), 54.7356 deg.
OPTIMAL_CONE_HALF_ANGLE = math.atan(math.sqrt(2.0))


def cone_axes(n: int, half_angle: float = OPTIMAL_CONE_HALF_ANGLE) -> np.ndarray:
    """``n`` unit sensor axes (n, 3) on a cone of ``half_angle`` (rad) about body z, at azimuths
    ``2 pi i / n`` from body x (textbook sec. 5.2). Optimal (``H^T H = n/3 I``) for n >= 3 at the
    default half-angle."""
    if n < 3:
        raise ValueError(f"a cone needs at least 3 sensors, got {n}")
    az = 2.0 * np.pi * np.arange(n) / n
    sa, ca = math.sin(half_angle), math.cos(half_angle)
    return np.column_stack([sa * np.cos(az), sa * np.sin(az), np.full(n, ca)])


def dodecahedron_axes() -> np.ndarray:
    """The six sensor axes normal to the face pairs of a regular dodecahedron (6, 3) (textbook sec. 5.2):
    two in each body plane, at +-atan(1/phi) = +-31.7175 deg about a body axis (phi the golden ratio),
    every pair of axes 63.4349 deg apart; ``H^T H = 2 I``."""
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    axes = np.array([[0.0, 1.0, phi], [0.0, -1.0, phi], [1.0, phi, 0.0], [-1.0, phi, 0.0],
                     [phi, 0.0, 1.0], [phi, 0.0, -1.0]])
    return axes / math.sqrt(1.0 + phi * phi)


# ----------------------------------------------------------------------------------------------------------------
# Noise of a window average


def window_sigma(white: float, window: float, tau_bias: float, gm: float = 0.0, tau_gm: float = math.inf,
                 rrw: float = 0.0) -> float:
    """1-sigma of one sensor's window-average residual after the parity bias tracker (rate units).

    ``white`` is the random walk (rad/sqrt(s) or m/s/sqrt(s)); averaged over ``window`` s its variance
    is ``white^2 / window`` (IEEE Std 952, angle random walk). The tracker is a first-order low-pass of
    time constant ``tau_bias``: what it leaves of a Gauss-Markov bias (1-sigma ``gm``, correlation time
    ``tau_gm``) is the high-pass output, variance ``gm^2 tau_bias / (tau_bias + tau_gm)`` (integral of
    the process spectrum ``2 gm^2/tau_gm / (w^2 + 1/tau_gm^2)`` times ``|s tau_b/(1 + s tau_b)|^2``); of
    a rate random walk (density ``rrw``) the tracking error of the low-pass, variance
    ``rrw^2 tau_bias / 2`` (steady state of ``de/dt = -e/tau_b + w``). The tracker's own white-noise
    error is accounted for in :func:`monitor_run`.
    """
    var = white * white / window
    if gm > 0.0 and math.isfinite(tau_gm):
        var += gm * gm * tau_bias / (tau_bias + tau_gm)
    var += rrw * rrw * tau_bias / 2.0
    return math.sqrt(var)


# ----------------------------------------------------------------------------------------------------------------
# The per-sample kernel

#: Return codes of :func:`monitor_run`.
RUN_DONE, RUN_DETECTED, RUN_CLEARED, RUN_RECOVERED = 0, 1, 2, 3
#: Layout of the kernel's float state vector.
ST_ACC_DT, ST_ACC_N, ST_WINDOWS, ST_ALARM, ST_CLEAR, ST_BVAR, ST_NLOG, ST_SIZE = range(8)


@kernel
def monitor_run(m: np.ndarray, dt: np.ndarray, t: np.ndarray, i0: int, win: int, st: np.ndarray,
                acc: np.ndarray, b: np.ndarray, H: np.ndarray, G: np.ndarray, V: np.ndarray,
                active: np.ndarray, thr: float, thr1: float, excl_sigma: np.ndarray, excl_count: np.ndarray,
                alpha: float, n_cal: int, holdoff: int, p_out: np.ndarray, fused: np.ndarray,
                log: np.ndarray, m_is_rate: bool) -> tuple[int, int, int]:
    """Parity-space monitoring of one sensor set, sample by sample, from row ``i0`` of ``m``.

    ``m`` (N, n) increments (rad or m/s) over intervals ``dt`` (s) ending at ``t`` (with ``m_is_rate``:
    rates, rad/s or m/s^2, each standing for the interval; ``fused`` is then a rate too). Every ``win``
    samples the window mean rate ``y = sum m / sum dt`` is tested: ``p = V (y - b)`` with ``V`` the
    whitened parity matrix widened to n columns (:func:`reconfigure`, times ``W``), statistic
    ``p^T p / (1 + v)`` against ``thr``, where ``v`` is the variance of the bias estimate ``b`` in units
    of the sensor variance (``v_k = (1 - a)^2 v_{k-1} + a^2`` for an exponential average of weight a).
    ``b`` (rate units) follows the part of ``y`` the parity space sees, ``b += a ((y - b) - H G (y - b))``
    on the active rows, with ``a = 1/k`` (the running mean) during the first ``n_cal`` windows (no test)
    and for as long as ``1/k > alpha``, ``alpha`` afterwards; it is frozen while the statistic is over the
    threshold. Every sample's fused
    estimate ``G (m - b dt)`` goes to ``fused``; each tested window appends ``(t, statistic, thr)`` to
    ``log``. A dropped sensor j is checked against the fused estimate, ``((y_j - b_j) - h_j x)^2 /
    excl_sigma_j^2`` against ``thr1``.

    Returns ``(next row, code, sensor)``: RUN_DONE at the end of ``m``; RUN_DETECTED when a window's
    statistic first exceeds the threshold (``p_out`` holds its p); RUN_CLEARED after ``holdoff``
    windows under the threshold in the alarm state; RUN_RECOVERED when dropped sensor ``sensor`` was
    consistent for ``holdoff`` windows.
    """
    n_rows, n = m.shape
    k_par = V.shape[0]
    y = np.empty(n)
    e = np.empty(n)
    for i in range(i0, n_rows):
        scale = 1.0 if m_is_rate else dt[i]
        for r in range(n):
            acc[r] += m[i, r] * dt[i] if m_is_rate else m[i, r]
        st[ST_ACC_DT] += dt[i]
        st[ST_ACC_N] += 1.0
        for a in range(3):
            s = 0.0
            for r in range(n):
                s += G[a, r] * (m[i, r] - b[r] * scale)
            fused[i, a] = s
        if st[ST_ACC_N] < win or st[ST_ACC_DT] <= 0.0:
            continue
        for r in range(n):
            y[r] = acc[r] / st[ST_ACC_DT]
            e[r] = y[r] - b[r]
            acc[r] = 0.0
        st[ST_ACC_DT] = 0.0
        st[ST_ACC_N] = 0.0
        st[ST_WINDOWS] += 1.0
        k = st[ST_WINDOWS]
        x0 = x1 = x2 = 0.0
        for r in range(n):
            x0 += G[0, r] * e[r]
            x1 += G[1, r] * e[r]
            x2 += G[2, r] * e[r]
        calibrating = k <= n_cal
        weight = 1.0 / k if (calibrating or 1.0 / k > alpha) else alpha
        stat = 0.0
        if not calibrating and k_par > 0:
            for q in range(k_par):
                s = 0.0
                for r in range(n):
                    s += V[q, r] * e[r]
                p_out[q] = s
                stat += s * s
            stat /= 1.0 + st[ST_BVAR]
            nl = int(st[ST_NLOG])
            if nl < log.shape[0]:
                log[nl, 0] = t[i]
                log[nl, 1] = stat
                log[nl, 2] = thr
                st[ST_NLOG] = nl + 1.0
        over = (not calibrating) and k_par > 0 and stat > thr
        if not over:
            for r in range(n):
                if active[r] > 0.0:
                    b[r] += weight * (e[r] - (H[r, 0] * x0 + H[r, 1] * x1 + H[r, 2] * x2))
            st[ST_BVAR] = (1.0 - weight) ** 2 * st[ST_BVAR] + weight * weight
        if calibrating:
            continue
        if over:
            st[ST_CLEAR] = 0.0
            if st[ST_ALARM] == 0.0:
                return i + 1, RUN_DETECTED, -1
        elif st[ST_ALARM] > 0.0:
            st[ST_CLEAR] += 1.0
            if st[ST_CLEAR] >= holdoff:
                st[ST_CLEAR] = 0.0
                return i + 1, RUN_CLEARED, -1
        for r in range(n):
            if active[r] > 0.0:
                continue
            z = (e[r] - (H[r, 0] * x0 + H[r, 1] * x1 + H[r, 2] * x2)) / excl_sigma[r]
            if z * z <= thr1:
                excl_count[r] += 1.0
                if excl_count[r] >= holdoff:
                    excl_count[r] = 0.0
                    return i + 1, RUN_RECOVERED, r
            else:
                excl_count[r] = 0.0
    return n_rows, RUN_DONE, -1
