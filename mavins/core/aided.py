"""Aided navigation: the strapdown solution with the closed-loop error-state filter, over whole arrays.

:func:`run_aided` is the compiled batch driver (the same increment rows as
strapdown.run_increments); :func:`navigate_aided` is its thin Python shell in
the style of runner.navigate. Per IMU row: subtract the current bias
estimates (``dtheta - b_g dt``, ``dv - b_a dt``), push the row through
strapdown.push_increment; per attitude (k) update: decay the Gauss-Markov
bias estimates, propagate P (every ``predict_every`` updates over the summed
interval, with the interval's mean C_b^n and specific force), apply every
measurement stamped at or before the update's time (kalman.py, late-fix rule
there), write one output row.

Output row (kernel units; :func:`to_file_units` gives the contract's file
units), ROW_SIZE columns: the 14 solution columns of strapdown.solution_row
(radians), then the 1-sigma of the filter ``sigma_n,e,d`` (m),
``sigma_vn,ve,vd`` (m/s), ``sigma_att_n,e,d`` (rad, of phi), the bias
estimates ``bg_x,y,z`` (rad/s), ``ba_x,y,z`` (m/s^2) and their 1-sigma
``sigma_bg_x,y,z``, ``sigma_ba_x,y,z`` (these 35 are the contract's,
OUT_COLUMNS). A bias and its sigma are those of the sum of the constant and
the Gauss-Markov parts (errmodel.py). Then, for each block of STATE_BLOCKS
(gyro and accelerometer scale factor and misalignment, magnetometer hard
iron), its estimate and 1-sigma (``sg_x ... sigma_sg_x ...``, ``mg_xy ...
sigma_mg_xy ...``): a solution file carries them where the filter estimates
them (:func:`file_columns`).

Measurement rows (kernel units, each sorted by time; rows before the start
are skipped):

* GNSS ``t, lat, lon (rad), h (m), vn, ve, vd (m/s), sigma_h, sigma_v (m),
  sigma_vel (m/s)``: position used when lat, lon, h are finite, velocity
  when vn, ve are (vd empty: the horizontal rows only, as GPS_RAW_INT's speed
  and course give), unless the row's position failed the gate (a glitch:
  its velocity is counted rejected, not logged; the live path does the same
  and drops the fix's dual-antenna heading too); one kernel for both paths,
  :func:`apply_gnss`;
* baro ``t, h (m), sigma (m)``: h is barometric height with an unknown
  offset the filter estimates (state X_BARO);
* mag ``t, mx, my, mz (body FRD, any unit), sigma (rad)``: heading through
  kalman.mag_heading with the given declination, less the hard-iron
  estimate (state X_MB, estimated when its initial sigma is above 0); a
  sample whose inclination disagrees with the model's (``mag_incl``) by
  more than MAG_INCL_GATE is counted disturbed (kind ``mag_disturbed``) and
  not applied (:func:`apply_mag`, the live path's too);
* static ``t0, t1, sigma_v (m/s), sigma_w (rad/s)``: at rest in [t0, t1]:
  a ZUPT at every attitude update inside, and at the first update at or
  after t1 a ZARU with the mean raw gyro rate of the IMU rows inside
  (sigma_w <= 0: gyro ARW / sqrt(window)). The ZARU's variance also holds
  the bias's own walk between the window's mean and its end, ``(2
  sigma_gm^2 / tau + K^2) T / 3`` (a random walk's end minus its mean over
  T); the correlation between the averaged gyro noise and the attitude
  error it also drove is neglected.
"""

from __future__ import annotations

import math
import tempfile
from typing import Any, Mapping, Sequence

import numpy as np
from numba import literally

from . import errmodel as em
from . import kalman as kf
from . import smoother as sm
from . import strapdown as sd
from .strapdown import GEOGRAPHIC
from .errmodel import NX
from .jit import kernel
from .runner import initial_state

K_GNSS_POS = 0
K_GNSS_VEL = 1
K_BARO = 2
K_MAG = 3
K_ZUPT = 4
K_ZARU = 5
K_MAG_DISTURBED = 6
K_WHEEL = 7
K_NHC = 8
KIND_NAMES = ("gnss_pos", "gnss_vel", "baro", "mag", "zupt", "zaru", "mag_disturbed", "wheel", "nhc")

GNSS_COLUMNS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "sigma_h", "sigma_v", "sigma_vel")
BARO_COLUMNS = ("t", "h", "sigma")
MAG_COLUMNS = ("t", "mx", "my", "mz", "sigma")
STATIC_COLUMNS = ("t0", "t1", "sigma_v", "sigma_w")
WHEEL_COLUMNS = ("t", "speed", "sigma")
LOG_COLUMNS = ("t", "kind", "nis", "dof", "accepted", "ratio")

FILTER_COLUMNS = (
    "sigma_n", "sigma_e", "sigma_d",
    "sigma_vn", "sigma_ve", "sigma_vd",
    "sigma_att_n", "sigma_att_e", "sigma_att_d",
    "bg_x", "bg_y", "bg_z",
    "ba_x", "ba_y", "ba_z",
    "sigma_bg_x", "sigma_bg_y", "sigma_bg_z",
    "sigma_ba_x", "sigma_ba_y", "sigma_ba_z",
)  # fmt: skip
FILTER_GROUPS = ("sigma_pos", "sigma_vel", "sigma_att", "bg", "ba", "sigma_bg", "sigma_ba")  # FILTER_COLUMNS by 3
OUT_COLUMNS = sd.OUT_COLUMNS + FILTER_COLUMNS
OUT_SIZE = len(OUT_COLUMNS)  # 35: the contract's 14 solution and 21 filter columns
STATE_BLOCKS = ("SG", "SA", "MG", "MA", "MB", "WS")  # errmodel.STATE blocks after the contract's columns, where estimated
_BLOCK = {b.name: b for b in em.STATE}


def block_columns(block: str, prefix: str = "") -> tuple[str, ...]:
    """The column names of an error-state block's estimate (``prefix`` ""; ``sigma_`` its 1-sigma): the block's
    name in lower case and each element's label, ``sg_x`` ... ; a single value has the name alone (``ws``)."""
    return tuple(f"{prefix}{block.lower()}_{a}" if a else f"{prefix}{block.lower()}" for a in _BLOCK[block].labels)


STATE_COLUMNS = tuple(c for b in STATE_BLOCKS for p in ("", "sigma_") for c in block_columns(b, p))
ROW_COLUMNS = OUT_COLUMNS + STATE_COLUMNS
ROW_SIZE = len(ROW_COLUMNS)
_STATE_BLOCK_X = tuple(em.OFFSET[b] for b in STATE_BLOCKS)  # their first indices in the error state
_STATE_BLOCK_N = tuple(_BLOCK[b].size for b in STATE_BLOCKS)  # and their sizes
ACC_SIZE = 19  # the pending propagation: sum C T (9), f^n T (3), T, angle and velocity increments (body, 3 + 3)
MAG_INCL_GATE = math.radians(20.0)  # rad: a sample whose inclination differs more from the model's is disturbed
MAG_RESET_AFTER = 50  # consecutive rejected magnetometer samples after which the hard iron is reset (apply_mag)
MAG_STRENGTH_GATE = 0.2  # gauss: likewise for its strength (PX4 EKF2_MAG_CHK_STR), in the sample's unit where it is known

SMOOTH_DT = 1.0  # s: the smoother's epochs between measurements are at most this far apart (navigate_aided)
NHC_EVERY = 0.1  # s: the non-holonomic constraint's interval (the live path's: engine, FilterSettings)
DEFAULT_SIGMA_WHEEL = 0.05  # m/s: a wheel odometer's speed noise (docs/filter.md)
DEFAULT_WHEEL_SCALE = 0.02  # its scale factor's initial 1-sigma (2 %)
DEFAULT_SIGMA_NHC = 0.1  # m/s: the constraint's sideways and vertical body velocity
DEFAULT_VISION_DRIFT = 0.01  # m/sqrt(s): a camera frame's origin walks (a VIO's drift; docs/filter.md)
DEFAULT_VISION_YAW_DRIFT = 1.0  # deg/sqrt(h): and its heading
DEFAULT_SIGMA_H = 2.5  # m (docs/conventions.md GNSS file)
DEFAULT_SIGMA_V = 5.0  # m
DEFAULT_SIGMA_VEL = 0.3  # m/s
DEFAULT_SIGMA_BARO = 0.5  # m
DEFAULT_SIGMA_MAG = math.radians(3.0)  # rad
DEFAULT_SIGMA_ZUPT = 0.01  # m/s
_DEG_H = math.degrees(1.0) * 3600.0  # rad/s -> deg/h


@kernel
def _propagate(s: np.ndarray, cfg: np.ndarray, spec: np.ndarray, P: np.ndarray, acc: np.ndarray, frame: int) -> None:
    """Propagate P over the pending interval ``acc[12]`` with its mean C (acc[0:9]), f^n (acc[9:12]), body
    rate and specific force (acc[13:16], acc[16:19]: increments summed over the interval); an ``acc`` with
    NX x NX more values also chains the propagation's Phi into the smoother's transition (smoother.py)."""
    literally(frame)
    if acc.shape[0] < ACC_SIZE or P.shape[0] != NX or P.shape[1] != NX:
        raise ValueError("the propagation needs acc of ACC_SIZE values and P of NX x NX")
    T = acc[12]
    if not T > 0.0:
        return
    c = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            c[i, j] = acc[3 * i + j] / T
    f_n = acc[9:12] / T
    lat, lon, h = sd.position(s, cfg, frame)
    F = em.system_matrix(c, s[sd.S.V : sd.S.V + 3], lat, h, f_n, spec, cfg[sd.CFG_EARTH] > 0.5)
    em.motion_columns(F, c, acc[13:16] / T, acc[16:19] / T, spec)
    predict_active(P, F, em.noise_density(spec), T)
    if acc.shape[0] >= ACC_SIZE + NX * NX:  # a smoothed run: the transition since the last epoch (smoother.py)
        sm.chain_transition(acc[ACC_SIZE:], em.transition(F, T))
    for i in range(ACC_SIZE):
        acc[i] = 0.0


@kernel
def predict_active(P: np.ndarray, F: np.ndarray, q: np.ndarray, T: float) -> None:
    """``P <- Phi P Phi^T + Qd`` over T seconds (errmodel.discretise_density, kalman.predict) on the states that
    take part: the navigation errors and every state with variance or driving noise. A state with neither
    (not estimated: a zero 1-sigma, a camera frame not placed) has a zero row and column in P, and its row of
    F is at most its own diagonal (errmodel: the sensor errors are random constants, walks or first-order
    Gauss-Markov; tests/core/test_errmodel.py), so its rows and columns of Phi P Phi^T and Qd stay zero and
    the others do not depend on it: leaving it out is exact and saves the cube of its share of the work."""
    n = P.shape[0]
    keep = np.empty(n, np.int64)
    m = 0
    for i in range(n):
        if i < em.X_SENSORS or P[i, i] > 0.0 or q[i] > 0.0:
            keep[m] = i
            m += 1
    Fa = np.empty((m, m))
    Pa = np.empty((m, m))
    qa = np.empty(m)
    for a in range(m):
        qa[a] = q[keep[a]]
        for b in range(m):
            Fa[a, b] = F[keep[a], keep[b]]
            Pa[a, b] = P[keep[a], keep[b]]
    phi, qd = em.discretise_density(Fa, qa, T)
    kf.predict(Pa, phi, qd)
    for a in range(m):
        for b in range(m):
            P[keep[a], keep[b]] = Pa[a, b]


@kernel
def flush_propagation(s: np.ndarray, cfg: np.ndarray, spec: np.ndarray, P: np.ndarray, acc: np.ndarray,
                      frame: int) -> None:
    """Propagate P over what has accumulated since the last propagation (before an update)."""
    literally(frame)
    _propagate(s, cfg, spec, P, acc, frame)


@kernel
def after_k_update(s: np.ndarray, cfg: np.ndarray, spec: np.ndarray, P: np.ndarray, bias: np.ndarray,
                   acc: np.ndarray, sums: np.ndarray, predict_every: int, frame: int) -> float:
    """The filter's share of one attitude (k) update, shared by the batch and the live paths.

    ``sums`` holds the bias-corrected angle (0:3, rad) and velocity (3:6, m/s)
    increments summed since the last update and (6) the time of that update;
    they are turned into the interval's mean C_b^n and specific force in n,
    accumulated in ``acc`` for the next propagation, and reset. The
    Gauss-Markov bias estimates decay over the interval (their expected value,
    errmodel.py), and P is propagated every ``predict_every`` updates.
    Returns the interval T (s). ``frame`` is strapdown.kernel_frame of cfg.
    """
    literally(frame)
    tk = s[sd.S.T]
    T = tk - sums[6]
    sums[6] = tk
    c = s[sd.S.C : sd.S.C + 9]
    for a in range(3):
        acc[9 + a] += c[3 * a] * sums[3] + c[3 * a + 1] * sums[4] + c[3 * a + 2] * sums[5]
    for a in range(9):
        acc[a] += c[a] * T
    acc[12] += T
    for a in range(6):
        acc[13 + a] += sums[a]
        sums[a] = 0.0
    if spec[em.SP_GYRO_GM] > 0.0:
        e = np.exp(-T / spec[em.SP_GYRO_TAU])
        for a in range(3):
            bias[kf.B_GG + a] *= e
    if spec[em.SP_ACC_GM] > 0.0:
        e = np.exp(-T / spec[em.SP_ACC_TAU])
        for a in range(3):
            bias[kf.B_GA + a] *= e
    if int(s[sd.S.NK]) % predict_every == 0:
        _propagate(s, cfg, spec, P, acc, frame)
    return T


@kernel
def push_rate_aided(s: np.ndarray, cfg: np.ndarray, spec: np.ndarray, P: np.ndarray, bias: np.ndarray,
                    acc: np.ndarray, sums: np.ndarray, t: float, wx: float, wy: float, wz: float, fx: float,
                    fy: float, fz: float, predict_every: int, frame: int) -> int:
    """The live path: one rate sample (rad/s, m/s^2, FRD) corrected by the estimates (kalman.correct_gyro),
    through strapdown.push_rate_scalars, then :func:`after_k_update` when it completed a k
    update. Same return codes and ``frame`` as push_rate_scalars."""
    literally(frame)
    dt = t - s[sd.S.TJ]
    cwx, cwy, cwz = kf.correct_gyro3(bias, wx, wy, wz, 1.0)
    cfx, cfy, cfz = kf.correct_accel3(bias, fx, fy, fz, 1.0)
    r = sd.push_rate_scalars(s, cfg, t, cwx, cwy, cwz, cfx, cfy, cfz, frame)
    if r < 0:
        return r
    if dt > 0.0:
        sums[0] += cwx * dt
        sums[1] += cwy * dt
        sums[2] += cwz * dt
        sums[3] += cfx * dt
        sums[4] += cfy * dt
        sums[5] += cfz * dt
    if r == 1:
        after_k_update(s, cfg, spec, P, bias, acc, sums, predict_every, frame)
    return r


@kernel
def keep_or_undo(kept: bool, P: np.ndarray, acc: np.ndarray, P0: np.ndarray, acc0: np.ndarray) -> None:
    """After a measurement: unless it changed the filter (``kept``), put P and the pending propagation ``acc``
    back as they were before it (``P0``, ``acc0``), so that a rejected measurement leaves no trace, not
    even the propagation it split in two (the batch and the live path alike)."""
    if not kept:
        for i in range(P.shape[0]):
            for j in range(P.shape[1]):
                P[i, j] = P0[i, j]
        for i in range(acc.shape[0]):
            acc[i] = acc0[i]


@kernel
def _record(
    log: np.ndarray, n_log: int, counts: np.ndarray, t: float, kind: int, dof: int, nis: float, ratio: float, ok: bool
) -> int:
    """Count one measurement and log it while the log has room; returns the new log length."""
    if ok:
        counts[kind, 0] += 1
    else:
        counts[kind, 1] += 1
    if n_log < log.shape[0]:
        log[n_log, 0] = t
        log[n_log, 1] = kind
        log[n_log, 2] = nis
        log[n_log, 3] = dof
        log[n_log, 4] = 1.0 if ok else 0.0
        log[n_log, 5] = ratio
        return n_log + 1
    return n_log


# Status of one part of a measurement (apply_gnss, apply_mag): accepted, rejected by the gate, no value in the
# row, or left out because the fix's position failed the gate (a glitch).
ACCEPTED, REJECTED, ABSENT, GLITCH = 1, 0, -1, 2


@kernel
def apply_gnss(s: np.ndarray, cfg: np.ndarray, bias: np.ndarray, P: np.ndarray, lat: float, lon: float, h: float,
               v_m: np.ndarray, w_ib: np.ndarray, lever: np.ndarray, late: float, T: float, sig_h: float,
               sig_v: float, sig_vel: float, gate: float, free: np.ndarray
               ) -> tuple[int, int, float, float, int, int, float, float]:
    """One GNSS fix taken ``late`` s before the solution, for the batch and the live path alike: the
    position (lat, lon rad, ellipsoidal h m; when all are finite; kalman.gnss_position), then the NED
    velocity ``v_m`` (m/s; when north and east are finite; kalman.gnss_velocity over the attitude interval
    T with the body rate w_ib; only its horizontal rows when the down component is NaN, as GPS_RAW_INT's
    ground speed and course give: kalman.horizontal_rows). A fix whose position fails the gate is a glitch:
    its velocity is left out too (status GLITCH). Returns, for the position then the velocity,
    ``(status, rows, nis, ratio)``: status ACCEPTED, REJECTED, ABSENT or GLITCH (rows, nis and ratio 0
    for a part not applied)."""
    ps, pr, pnis, pratio = ABSENT, 0, 0.0, 0.0
    if np.isfinite(lat) and np.isfinite(lon) and np.isfinite(h):
        nu, H, R = kf.gnss_position(s, cfg, lat, lon, h, lever, late, sig_h, sig_v)
        pnis, pratio, ok = kf.apply_update(s, cfg, bias, P, H, nu, R, gate, free)
        ps, pr = (ACCEPTED if ok else REJECTED), nu.shape[0]
    vs, vr, vnis, vratio = ABSENT, 0, 0.0, 0.0
    if np.isfinite(v_m[0]) and np.isfinite(v_m[1]):
        if ps == REJECTED:
            vs = GLITCH
        else:
            nu, H, R = kf.gnss_velocity(s, v_m, w_ib, lever, late, T, sig_vel)
            if not np.isfinite(v_m[2]):
                nu, H, R = kf.horizontal_rows(nu, H, R)
            vnis, vratio, ok = kf.apply_update(s, cfg, bias, P, H, nu, R, gate, free)
            vs, vr = (ACCEPTED if ok else REJECTED), nu.shape[0]
    return ps, pr, pnis, pratio, vs, vr, vnis, vratio


@kernel
def mag_stats(P: np.ndarray) -> np.ndarray:
    """apply_mag's running sums at the filter's start (kalman.MAG_STATS): none yet, and the hard iron's
    initial variance from P (the value its covariance is reset to)."""
    incl = np.zeros(kf.MAG_STATS)
    incl[4] = P[em.X_MB, em.X_MB]
    return incl


@kernel
def apply_mag(s: np.ndarray, cfg: np.ndarray, bias: np.ndarray, P: np.ndarray, incl: np.ndarray, m_b: np.ndarray,
              w_ib: np.ndarray, late: float, declination: float, sigma: float, incl_model: float,
              strength_model: float, strength_gate: float, gate: float, free: np.ndarray) -> tuple[int, float, float]:
    """One magnetometer sample (body FRD) taken ``late`` s before the solution, for the batch and the live
    path alike: less the hard-iron estimate, levelled (kalman.mag_level); checked against the Earth model's
    inclination (rad) with MAG_INCL_GATE and its strength (the sample's unit) with ``strength_gate`` (same
    unit) (kalman.mag_disturbed; NaN: not checked), both widened by the hard iron's 3 sigma (the largest
    axis; on the inclination over the model's strength); then the heading update (kalman.mag_heading) at the
    model's field: its tan I, and its horizontal strength ``F cos I`` for the hard-iron column; without a
    model figure, the running means ``incl`` of the accepted samples (kalman.MAG_STATS), which an accepted
    sample joins. After MAG_RESET_AFTER rejections in a row the hard iron's covariance is reset to its
    initial variance ``incl[4]`` (none when 0). Returns ``(status, nis, ratio)``: status 1 accepted, 0
    rejected by the gate, 2 rejected and the hard iron reset, -1 disturbed (not applied).
    """
    m_n = kf.mag_level(s, cfg, bias, m_b, w_ib, late)
    # the checks allow for the hard iron not learnt yet: 3 sigma of its largest axis on the strength, and
    # that over the model's strength on the inclination
    hard = 0.0
    for i in range(3):
        hard = max(hard, 3.0 * np.sqrt(max(P[em.X_MB + i, em.X_MB + i], 0.0)))
    gate_incl = MAG_INCL_GATE
    if np.isfinite(strength_model) and strength_model > 0.0:
        gate_incl += np.arctan(hard / strength_model)
    if kf.mag_disturbed(m_n, incl_model, strength_model if np.isfinite(strength_gate) else np.nan, gate_incl,
                        strength_gate + hard):
        return -1, np.nan, np.nan
    tan_i = np.tan(incl_model) if np.isfinite(incl_model) else kf.mag_inclination(incl, m_n)
    if np.isfinite(incl_model) and np.isfinite(strength_model):
        horizontal = strength_model * np.cos(incl_model)
    else:
        horizontal = kf.mag_horizontal(incl, m_n)
    nu, H, R = kf.mag_heading(s, m_n, declination, tan_i, horizontal, sigma)
    nis, ratio, ok = kf.apply_update(s, cfg, bias, P, H, nu, R, gate, free)
    if ok:
        kf.mag_accept(incl, m_n)
        incl[3] = 0.0
        return 1, nis, ratio
    incl[3] += 1.0
    if incl[3] >= MAG_RESET_AFTER and incl[4] > 0.0:
        # persistently rejected with a hard iron estimated: a wrong early estimate (the heading's
        # nonlinearity in a large hard iron) holds the gate shut; forget it (its prior, no correlation),
        # as PX4 EKF2 resets its magnetometer states
        for i in range(3):
            j = em.X_MB + i
            for k in range(P.shape[0]):
                P[j, k] = 0.0
                P[k, j] = 0.0
            P[j, j] = incl[4]
        incl[3] = 0.0
        return 2, nis, ratio
    return 0, nis, ratio


@kernel
def filter_row(P: np.ndarray, bias: np.ndarray, out: np.ndarray) -> None:
    """Write the filter's columns (kernel units) after the 14 solution columns of ``out``: the contract's
    21, then, when ``out`` has ROW_SIZE values, each STATE_BLOCKS block's estimate and 1-sigma."""
    filter_sigmas(P, out)
    filter_estimates(bias, out, 1.0, 0.0)


@kernel
def filter_estimates(bias: np.ndarray, out: np.ndarray, scale: float, keep: float) -> None:
    """The estimate columns of a row (filter_row's layout) from a bias vector (kalman.B_* layout):
    ``out = keep out + scale estimate`` (1, 0 writes them, whatever ``out`` held, NaN included; -1, 1
    subtracts a correction's)."""
    k = OUT_SIZE
    if out.shape[0] >= ROW_SIZE:
        for b in range(len(_STATE_BLOCK_X)):
            x0, n = _STATE_BLOCK_X[b], _STATE_BLOCK_N[b]
            for i in range(n):
                _blend(out, k + i, bias[x0 - em.X_SENSORS + i], scale, keep)
            k += 2 * n
    g = kf.gyro_bias_total(bias)
    a = kf.accel_bias_total(bias)
    for i in range(3):
        _blend(out, 23 + i, g[i], scale, keep)
        _blend(out, 26 + i, a[i], scale, keep)


@kernel
def _blend(out: np.ndarray, c: int, value: float, scale: float, keep: float) -> None:
    """``out[c] = keep out[c] + scale value``; with keep 0 the old value is not read (it may be NaN)."""
    if keep == 0.0:
        out[c] = scale * value
    else:
        out[c] = keep * out[c] + scale * value


@kernel
def filter_sigmas(P: np.ndarray, out: np.ndarray) -> None:
    """The 1-sigma columns of a row (filter_row's layout) from P: position, velocity, attitude, the total
    gyro and accelerometer biases (constant plus Gauss-Markov, their covariance included) and, when
    ``out`` has ROW_SIZE values, each STATE_BLOCKS block's."""
    k = OUT_SIZE
    if out.shape[0] >= ROW_SIZE:  # a row of the contract's 35 columns only has no room for them
        for b in range(len(_STATE_BLOCK_X)):
            x0, n = _STATE_BLOCK_X[b], _STATE_BLOCK_N[b]
            for i in range(n):
                out[k + n + i] = np.sqrt(max(P[x0 + i, x0 + i], 0.0))
            k += 2 * n
    for i in range(3):
        out[14 + i] = np.sqrt(max(P[em.X_DP + i, em.X_DP + i], 0.0))
        out[17 + i] = np.sqrt(max(P[em.X_DV + i, em.X_DV + i], 0.0))
        out[20 + i] = np.sqrt(max(P[em.X_PHI + i, em.X_PHI + i], 0.0))
    for i in range(3):
        g, a = em.X_BG + i, em.X_GG + i
        out[29 + i] = np.sqrt(max(P[g, g] + P[a, a] + 2.0 * P[g, a], 0.0))
        g, a = em.X_BA + i, em.X_GA + i
        out[32 + i] = np.sqrt(max(P[g, g] + P[a, a] + 2.0 * P[g, a], 0.0))


@kernel
def run_aided(
    s: np.ndarray,
    cfg: np.ndarray,
    t: np.ndarray,
    dtheta: np.ndarray,
    dv: np.ndarray,
    gnss: np.ndarray,
    baro: np.ndarray,
    mag: np.ndarray,
    static: np.ndarray,
    spec: np.ndarray,
    lever: np.ndarray,
    declination: float,
    mag_incl: float,
    mag_strength: float,
    mag_strength_gate: float,
    gate: float,
    predict_every: int,
    P: np.ndarray,
    bias: np.ndarray,
    out: np.ndarray,
    counts: np.ndarray,
    log: np.ndarray,
    p_hist: np.ndarray,
    p_every: int,
    store: np.ndarray,
    active: np.ndarray,
    smooth_dt: float,
    wheel: np.ndarray,
    wheel_lever: np.ndarray,
    nhc_sigma: float,
) -> tuple[int, int, int]:
    """Batch aided navigation over increment rows; returns (output rows, NIS log rows, smoother epochs).

    ``s``, ``P`` (NX x NX) and ``bias`` (kalman.B_SIZE) are updated in place
    and can be passed to a following call over the next rows; measurement
    rows at or before the state's last update are then skipped (a fresh
    state uses those at its own time), and a rest interval must lie within
    one call. ``mag_incl`` (rad) and ``mag_strength`` (the magnetometer's
    unit) are the Earth model's field, ``mag_strength_gate`` the strength
    check in that unit (NaN: none; :func:`apply_mag`).
    ``out`` needs ``len(t) // N``
    rows of ROW_SIZE; ``counts`` is (7, 2) accepted/rejected per kind
    (KIND_NAMES), ``log`` (L, 6) receives ``t, kind, nis, dof, accepted,
    ratio`` per measurement while it has room. ``p_hist`` (H, NX, NX)
    receives P after every ``p_every``-th output row (rows p_every - 1,
    2 p_every - 1, ...) while it has room; pass an empty array to skip. Row
    layouts in the module docstring.

    ``store`` (E, smoother.store_width(len(active))) receives the smoother's epochs
    (smoother.record, over the ``active`` state indices) while it has room: the first
    output row, every row at which a measurement is due (the propagation is
    completed first, so that P^- is the prior at that time) and, between them,
    a row at least every ``smooth_dt`` s where P was just propagated. An
    empty store records nothing and leaves the filter as without it.

    ``wheel`` rows ``t, speed (m/s), sigma (m/s)``: the odometer's forward
    speed at the axle centre ``wheel_lever`` (m, body FRD; kalman.wheel_speed).
    ``nhc_sigma`` > 0: the non-holonomic constraint (kalman.nhc, that sigma in
    m/s) at the first update every NHC_EVERY s.
    """
    if out.shape[1] < ROW_SIZE or counts.shape[0] < len(KIND_NAMES) or (log.shape[0] > 0 and log.shape[1] < 6) \
            or P.shape[0] != NX or P.shape[1] != NX or bias.shape[0] != kf.B_SIZE:
        raise ValueError("run_aided: out needs ROW_SIZE columns, counts a row per kind, log 6 columns, P NX x NX, "
                         "bias B_SIZE values")
    t_start = s[sd.S.T]
    cont = s[sd.S.NK] > 0.0  # a continued run: rows at its time were used by the call before
    ig = 0
    while ig < gnss.shape[0] and (gnss[ig, 0] < t_start or (cont and gnss[ig, 0] == t_start)):
        ig += 1
    ib = 0
    while ib < baro.shape[0] and (baro[ib, 0] < t_start or (cont and baro[ib, 0] == t_start)):
        ib += 1
    im = 0
    while im < mag.shape[0] and (mag[im, 0] < t_start or (cont and mag[im, 0] == t_start)):
        im += 1
    iz = 0
    while iz < static.shape[0] and static[iz, 1] < t_start:
        iz += 1
    iw = 0
    while iw < wheel.shape[0] and (wheel[iw, 0] < t_start or (cont and wheel[iw, 0] == t_start)):
        iw += 1
    t_nhc = t_start  # the constraint's next time: every NHC_EVERY s from the start, at the first update after
    gm_g = spec[em.SP_GYRO_GM] > 0.0
    smoothing = store.shape[0] > 0
    acc = np.zeros(ACC_SIZE + NX * NX if smoothing else ACC_SIZE)
    if smoothing:
        sm.reset_transition(acc[ACC_SIZE:])
    n_ep = 0
    t_ep = -np.inf
    Pm = np.empty((0, 0))
    s_prior = np.empty(0)
    bias_prior = np.empty(0)
    sums = np.zeros(7)
    sums[6] = s[sd.S.T]
    raw_sum = np.zeros(3)
    raw_t = 0.0
    dth_c = np.empty(3)
    dv_c = np.empty(3)
    w_ib = np.zeros(3)
    v_m = np.empty(3)
    m_b = np.empty(3)
    incl = mag_stats(P)  # running sums over the accepted magnetometer samples (apply_mag)
    n_out = 0
    n_log = 0
    for i in range(t.shape[0]):
        dt = t[i] - s[sd.S.TJ]
        if not dt > 0.0:
            continue
        dth_c[0], dth_c[1], dth_c[2] = kf.correct_gyro3(bias, dtheta[i, 0], dtheta[i, 1], dtheta[i, 2], dt)
        dv_c[0], dv_c[1], dv_c[2] = kf.correct_accel3(bias, dv[i, 0], dv[i, 1], dv[i, 2], dt)
        for a in range(3):
            sums[a] += dth_c[a]
            sums[3 + a] += dv_c[a]
        if iz < static.shape[0] and static[iz, 0] < t[i] <= static[iz, 1]:
            for a in range(3):
                raw_sum[a] += dtheta[i, a]
            raw_t += dt
        if sd.push_increment(s, cfg, t[i], dth_c, dv_c, GEOGRAPHIC) != 1:
            continue
        tk = s[sd.S.T]
        T = tk - sums[6]
        for a in range(3):
            w_ib[a] = sums[a] / T
        after_k_update(s, cfg, spec, P, bias, acc, sums, predict_every, GEOGRAPHIC)
        epoch = False
        if smoothing:
            due = (ig < gnss.shape[0] and gnss[ig, 0] <= tk) or (ib < baro.shape[0] and baro[ib, 0] <= tk) \
                or (im < mag.shape[0] and mag[im, 0] <= tk) or (iz < static.shape[0] and static[iz, 0] <= tk) \
                or (iw < wheel.shape[0] and wheel[iw, 0] <= tk) or (nhc_sigma > 0.0 and tk >= t_nhc)
            epoch = due or n_out == 0 or (acc[12] == 0.0 and tk - t_ep >= smooth_dt)
            if epoch:
                _propagate(s, cfg, spec, P, acc, GEOGRAPHIC)  # P^- at tk: nothing pending
                Pm, s_prior, bias_prior = P.copy(), s.copy(), bias.copy()

        # each measurement row: P propagated to it, updated; a row that changed nothing (rejected, disturbed,
        # no value) leaves P and the pending propagation as they were (_keep_or_undo)
        while ig < gnss.shape[0] and gnss[ig, 0] <= tk:
            P0, acc0, kept = P.copy(), acc.copy(), False
            _propagate(s, cfg, spec, P, acc, GEOGRAPHIC)
            row = gnss[ig]
            v_m[0], v_m[1], v_m[2] = row[4], row[5], row[6]
            ps, pr, pnis, pratio, vs, vr, vnis, vratio = apply_gnss(
                s, cfg, bias, P, row[1], row[2], row[3], v_m, w_ib, lever, tk - row[0], T, row[7], row[8], row[9],
                gate, kf.ALL)
            if ps != ABSENT:
                n_log = _record(log, n_log, counts, row[0], K_GNSS_POS, pr, pnis, pratio, ps == ACCEPTED)
            if vs == GLITCH:  # a fix whose position failed the gate is a glitch: its velocity too
                counts[K_GNSS_VEL, 1] += 1
            elif vs != ABSENT:
                n_log = _record(log, n_log, counts, row[0], K_GNSS_VEL, vr, vnis, vratio, vs == ACCEPTED)
            kept = ps == ACCEPTED or vs == ACCEPTED
            keep_or_undo(kept, P, acc, P0, acc0)
            ig += 1
        while ib < baro.shape[0] and baro[ib, 0] <= tk:
            P0, acc0, kept = P.copy(), acc.copy(), False
            _propagate(s, cfg, spec, P, acc, GEOGRAPHIC)
            if np.isfinite(baro[ib, 1]):
                nu, H, R = kf.baro_height(s, bias, baro[ib, 1], tk - baro[ib, 0], baro[ib, 2])
                nis, ratio, ok = kf.apply_update(s, cfg, bias, P, H, nu, R, gate, kf.ALL)
                n_log = _record(log, n_log, counts, baro[ib, 0], K_BARO, 1, nis, ratio, ok)
                kept = ok
            keep_or_undo(kept, P, acc, P0, acc0)
            ib += 1
        while im < mag.shape[0] and mag[im, 0] <= tk:
            P0, acc0, kept = P.copy(), acc.copy(), False
            _propagate(s, cfg, spec, P, acc, GEOGRAPHIC)
            m_b[0], m_b[1], m_b[2] = mag[im, 1], mag[im, 2], mag[im, 3]
            if np.isfinite(m_b[0]) and np.isfinite(m_b[1]) and np.isfinite(m_b[2]):
                status, nis, ratio = apply_mag(s, cfg, bias, P, incl, m_b, w_ib, tk - mag[im, 0], declination,
                                               mag[im, 4], mag_incl, mag_strength, mag_strength_gate, gate,
                                               kf.ALL)
                if status < 0:
                    counts[K_MAG_DISTURBED, 1] += 1
                else:
                    n_log = _record(log, n_log, counts, mag[im, 0], K_MAG, 1, nis, ratio, status == 1)
                kept = status >= 1
            keep_or_undo(kept, P, acc, P0, acc0)
            im += 1
        while iw < wheel.shape[0] and wheel[iw, 0] <= tk:
            P0, acc0, kept = P.copy(), acc.copy(), False
            _propagate(s, cfg, spec, P, acc, GEOGRAPHIC)
            if np.isfinite(wheel[iw, 1]):
                nu, H, R = kf.wheel_speed(s, bias, wheel[iw, 1], w_ib, wheel_lever, tk - wheel[iw, 0], T,
                                          wheel[iw, 2])
                nis, ratio, ok = kf.apply_update(s, cfg, bias, P, H, nu, R, gate, kf.ALL)
                n_log = _record(log, n_log, counts, wheel[iw, 0], K_WHEEL, 1, nis, ratio, ok)
                kept = ok
            keep_or_undo(kept, P, acc, P0, acc0)
            iw += 1
        if nhc_sigma > 0.0 and tk >= t_nhc:
            P0, acc0 = P.copy(), acc.copy()
            _propagate(s, cfg, spec, P, acc, GEOGRAPHIC)
            nu, H, R = kf.nhc(s, nhc_sigma)
            nis, ratio, ok = kf.apply_update(s, cfg, bias, P, H, nu, R, gate, kf.ALL)
            n_log = _record(log, n_log, counts, tk, K_NHC, 2, nis, ratio, ok)
            keep_or_undo(ok, P, acc, P0, acc0)
            while t_nhc <= tk:
                t_nhc += NHC_EVERY
        while iz < static.shape[0] and static[iz, 0] <= tk:
            if tk <= static[iz, 1]:
                P0, acc0 = P.copy(), acc.copy()
                _propagate(s, cfg, spec, P, acc, GEOGRAPHIC)
                nu, H, R = kf.zupt(s, static[iz, 2])
                nis, ratio, ok = kf.apply_update(s, cfg, bias, P, H, nu, R, gate, kf.ALL)
                n_log = _record(log, n_log, counts, tk, K_ZUPT, nu.shape[0], nis, ratio, ok)
                keep_or_undo(ok, P, acc, P0, acc0)
            if tk < static[iz, 1]:
                break
            if raw_t > 0.0:
                P0, acc0 = P.copy(), acc.copy()
                _propagate(s, cfg, spec, P, acc, GEOGRAPHIC)
                sig = static[iz, 3]
                if not sig > 0.0:
                    sig = spec[em.SP_GYRO_ARW] / np.sqrt(raw_t)
                nu, H, R = kf.zaru(s, cfg, bias, raw_sum / raw_t, sig)
                # the window mean differs from the bias at its end by the bias's own walk:
                # variance (2 sigma_gm^2 / tau + K^2) T / 3 per axis over a window of T
                walk = spec[em.SP_GYRO_RRW] ** 2
                if gm_g:
                    walk += 2.0 * spec[em.SP_GYRO_GM] ** 2 / spec[em.SP_GYRO_TAU]
                for a in range(3):
                    R[a, a] += walk * raw_t / 3.0
                nis, ratio, ok = kf.apply_update(s, cfg, bias, P, H, nu, R, gate, kf.ALL)
                n_log = _record(log, n_log, counts, tk, K_ZARU, nu.shape[0], nis, ratio, ok)
                keep_or_undo(ok, P, acc, P0, acc0)
            for a in range(3):
                raw_sum[a] = 0.0
            raw_t = 0.0
            iz += 1

        row_out = out[n_out]
        sd.solution_row(s, cfg, row_out[0:14], GEOGRAPHIC)
        filter_row(P, bias, row_out)
        if epoch:
            dx = sm.nominal_difference(s_prior, bias_prior, s, bias, cfg)
            n_ep = sm.record(store, n_ep, tk, n_out, Pm, P, acc[ACC_SIZE:], dx, active)
            t_ep = tk
        n_out += 1
        if n_out % p_every == 0:
            j = n_out // p_every - 1
            if j < p_hist.shape[0]:
                p_hist[j, :, :] = P
    _propagate(s, cfg, spec, P, acc, GEOGRAPHIC)  # P at the state's time for a following call
    return n_out, n_log, n_ep


@kernel
def smooth_rows(out: np.ndarray, n_out: int, row_epoch: np.ndarray, store: np.ndarray, n_ep: int,
                active: np.ndarray) -> None:
    """The forward rows ``out[:n_out]`` (kernel units) made smoothed in place, from a store after
    smoother.backward; ``row_epoch[j]`` is how many epochs had been recorded when row j was written.

    Row j's nominal is the posterior of its last epoch k (= row_epoch[j] - 1) carried forward, on the
    way to the prior of epoch k + 1: its error and covariance are interpolated linearly in time between
    ``e^s_k, P^s_k`` and ``e^s_{k+1} + dx_{k+1}, P^s_{k+1}`` (at t_k: those of epoch k; at t_{k+1}, a row
    written before that epoch's measurements: its prior's); docs/postprocessing.md bounds what this leaves
    out. The row is corrected by that error (smoother.correct_solution; the estimates less the error's,
    filter_estimates) and takes that covariance's sigmas (filter_sigmas). Rows before the first epoch and
    from the last on keep the forward values, as the last epoch does (e^s_N = 0, P^s_N = P^+_N)."""
    na = active.shape[0]
    o_dx, o_e, o_pm, o_pp, o_phi = sm.store_slots(na)
    e = np.zeros(NX)
    Ps = np.zeros((NX, NX))
    for j in range(n_out):
        k = row_epoch[j] - 1
        if k < 0 or k + 1 >= n_ep:
            continue
        a, b = store[k], store[k + 1]
        w = 1.0
        if b[sm.EP_T] > a[sm.EP_T]:
            w = min(max((out[j, 0] - a[sm.EP_T]) / (b[sm.EP_T] - a[sm.EP_T]), 0.0), 1.0)
        for p in range(na):
            e[active[p]] = (1.0 - w) * a[o_e + p] + w * (b[o_e + p] + b[o_dx + p])
            for q in range(na):
                Ps[active[p], active[q]] = (1.0 - w) * a[o_pp + p * na + q] + w * b[o_pp + p * na + q]
        row = out[j]
        sm.correct_solution(row, e)
        filter_estimates(e[em.X_SENSORS:], row, -1.0, 1.0)
        filter_sigmas(Ps, row)


def _columns(rows: Any, width: int, defaults: Sequence[float], name: str) -> np.ndarray:
    """Rows padded to ``width`` columns; missing columns and NaN sigmas take ``defaults`` (None = NaN)."""
    if rows is None:
        return np.empty((0, width))
    arr = np.atleast_2d(np.asarray(rows, dtype=np.float64))
    if arr.size == 0:
        return np.empty((0, width))
    if arr.shape[1] > width:
        raise ValueError(f"{name}: at most {width} columns, got {arr.shape[1]}")
    out = np.full((arr.shape[0], width), np.nan)
    out[:, : arr.shape[1]] = arr
    for j, d in enumerate(defaults):
        if d is not None:
            col = out[:, j]
            col[~np.isfinite(col)] = d
    if np.any(np.diff(out[:, 0]) < 0.0):
        raise ValueError(f"{name}: rows must be sorted by time")
    return np.ascontiguousarray(out)


def unit_factors(columns: Sequence[str]) -> np.ndarray:
    """Per column of a solution row, the factor from kernel to file units: degrees for lat, lon, the Euler
    angles and sigma_att; deg/h for the gyro bias and its sigma; ppm for the scale factors (the wheel
    odometer's too), arcsec for the misalignments (the spec keys' units) and their sigma; 1 for everything
    else."""
    deg = math.degrees(1.0)
    by_name = {n: deg for n in ("lat", "lon", "roll", "pitch", "yaw", "sigma_att_n", "sigma_att_e", "sigma_att_d")}
    for a in "xyz":
        by_name[f"bg_{a}"] = by_name[f"sigma_bg_{a}"] = _DEG_H
        for blk in ("sg", "sa"):
            by_name[f"{blk}_{a}"] = by_name[f"sigma_{blk}_{a}"] = 1e6
    for blk in ("MG", "MA"):
        for c in block_columns(blk) + block_columns(blk, "sigma_"):
            by_name[c] = 1.0 / em.ARCSEC
    for c in block_columns("WS") + block_columns("WS", "sigma_"):
        by_name[c] = 1e6
    return np.array([by_name.get(n, 1.0) for n in columns])


def to_file_units(rows: np.ndarray, columns: Sequence[str] | None = None) -> np.ndarray:
    """Aided rows in kernel units to the contract's file units (:func:`unit_factors`); ``columns``
    names the rows' columns (default: the first of ROW_COLUMNS)."""
    names = ROW_COLUMNS[: rows.shape[1]] if columns is None else columns
    return rows * unit_factors(names)


def column_groups(columns: Sequence[str]) -> tuple[tuple[str, tuple[str, ...], tuple[int, ...]], ...]:
    """The filter's columns among ``columns`` grouped by quantity (the Rerun recording's ``/filter/<name>``):
    the contract's 21 in threes (FILTER_GROUPS), then each STATE_BLOCKS block's estimate and 1-sigma
    (``sg``, ``sigma_sg``, ``mg``, ...); each as (name, its column names, their indices in ``columns``), only
    the groups whose columns are all there."""
    where = {c: i for i, c in enumerate(columns)}
    groups = [(g, FILTER_COLUMNS[3 * k:3 * k + 3]) for k, g in enumerate(FILTER_GROUPS)]
    for b in STATE_BLOCKS:
        for p in ("", "sigma_"):
            groups.append((f"{p}{b.lower()}", block_columns(b, p)))
    return tuple((g, names, tuple(where[c] for c in names)) for g, names in groups if all(c in where for c in names))


def file_columns(spec: np.ndarray, mag_bias: float) -> np.ndarray:
    """The indices into a ROW_SIZE row of a solution file's columns: the contract's 35, then the
    scale-factor and misalignment blocks the spec estimates (errmodel SP_*_SCALE, SP_*_MIS > 0), the
    hard iron when its initial 1-sigma ``mag_bias`` is above 0 and the wheel odometer's scale factor when
    the spec has one (SP_WHEEL_SCALE > 0; docs/filter.md)."""
    estimated = {"SG": spec[em.SP_GYRO_SCALE] > 0.0, "SA": spec[em.SP_ACC_SCALE] > 0.0,
                 "MG": spec[em.SP_GYRO_MIS] > 0.0, "MA": spec[em.SP_ACC_MIS] > 0.0, "MB": mag_bias > 0.0,
                 "WS": spec[em.SP_WHEEL_SCALE] > 0.0}
    idx = list(range(OUT_SIZE))
    k = OUT_SIZE
    for name, n in zip(STATE_BLOCKS, _STATE_BLOCK_N):
        if estimated[name]:
            idx += range(k, k + 2 * n)
        k += 2 * n
    return np.array(idx, dtype=np.int64)


def navigate_aided(
    imu: np.ndarray,
    init: Mapping[str, float],
    gnss: np.ndarray | None = None,
    baro: np.ndarray | None = None,
    *,
    mag: np.ndarray | None = None,
    static: np.ndarray | Sequence[Sequence[float]] | None = None,
    spec: str | em.ImuSpec | Mapping[str, float] = "consumer",
    lever_arm: Sequence[float] = (0.0, 0.0, 0.0),
    gate: float = 5.0,
    samples: int = 2,
    predict_every: int = 1,
    declination: float = 0.0,
    mag_inclination: float | None = None,
    mag_strength: float | None = None,
    mag_strength_gate: float | None = None,
    mag_bias: float = 0.0,
    scale_factors: bool = False,
    misalignment: bool = False,
    baro_offset_sigma: float = 50.0,
    baro_drift: float = 0.0,
    covariance_every: int = 0,
    file_units: bool = True,
    smooth: bool = False,
    smooth_dt: float = SMOOTH_DT,
    wheel: np.ndarray | None = None,
    wheel_lever_arm: Sequence[float] = (0.0, 0.0, 0.0),
    wheel_scale: float = DEFAULT_WHEEL_SCALE,
    nhc: float = 0.0,
    **options: Any,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Aided navigation over a whole recording.

    Args:
        imu: (N, 7) increment rows ``t, dtheta_xyz (rad), dv_xyz (m/s)``.
        init: the contract's initial state (degrees, m, m/s), optionally with
            ``sigma_pos`` (m, default 10), ``sigma_vel`` (m/s, 1),
            ``sigma_level`` (deg, 1), ``sigma_yaw`` (deg, 10).
        gnss: rows ``t, lat, lon (deg), h (m)`` optionally followed by
            ``vn, ve, vd (m/s), sigma_h, sigma_v (m), sigma_vel (m/s)``
            (defaults 2.5, 5, 0.3; NaN position = no fix, NaN velocity = none).
        baro: rows ``t, h (m)`` optionally ``sigma`` (m, default 0.5).
        mag: rows ``t, mx, my, mz`` (calibrated, body FRD) optionally
            ``sigma`` (deg of heading, default 3).
        static: rows ``t0, t1`` optionally ``sigma_v`` (m/s, default 0.01),
            ``sigma_w`` (deg/h; default ARW / sqrt(window)): rest intervals
            for ZUPT and ZARU.
        spec: a grade name, an ImuSpec or the contract's spec keys.
        lever_arm: GNSS antenna from the IMU, body FRD (m).
        gate: reject above this many sigma (normalised innovation); <= 0 off.
        samples: samples per attitude update (strapdown N).
        predict_every: attitude updates per covariance propagation.
        declination: magnetic declination (deg, east positive).
        mag_inclination: the Earth model's inclination (deg): the disturbance check and the heading's model;
            None: no check, the samples' mean.
        mag_strength: the model's strength in the samples' unit (the hard iron's model); None: their mean.
        mag_strength_gate: the strength check in that unit (aided.MAG_STRENGTH_GATE gauss); None: none.
        mag_bias: initial 1-sigma of the magnetometer's hard iron per axis (its unit); 0: not estimated.
        scale_factors: estimate the grade's (or spec keys') scale factors (errmodel.spec_of).
        misalignment: likewise their misalignments.
        baro_offset_sigma: initial 1-sigma of the baro offset (m).
        baro_drift: random walk of the baro offset (m/sqrt(s)).
        covariance_every: keep the full P after every this many output rows
            (stats ``P_history``, (M // covariance_every, NX, NX)); 0 = none.
        file_units: return rows in file units (:func:`to_file_units`), else kernel units.
        smooth: return the fixed-interval smoothed rows (smoother.py, :func:`smooth_rows`) instead of the
            forward filter's; the epochs and the rows are kept in an unlinked temporary file
            (:func:`scratch`), so memory holds what the system pages in.
        smooth_dt: with ``smooth``, an epoch at least every this many seconds between measurements (s).
        wheel: rows ``t, speed (m/s)`` optionally ``sigma`` (m/s, default DEFAULT_SIGMA_WHEEL): a wheel
            odometer's forward speed (kalman.wheel_speed), its scale factor estimated from ``wheel_scale``
            (initial 1-sigma, dimensionless) at the axle centre ``wheel_lever_arm`` (m, body FRD).
        nhc: > 0: the non-holonomic constraint of a wheeled vehicle with this sigma (m/s) every NHC_EVERY s.
        options: other strapdown.make_config options.

    Returns:
        ``(rows, stats)``: (M, ROW_SIZE) output rows (:func:`file_columns` picks a file's), and ``counts`` (kind ->
        (accepted, rejected)), ``nis`` (log rows, LOG_COLUMNS), ``P`` (final),
        ``bias`` (kalman.B_* layout), ``baro_offset`` (m), ``P_history``,
        ``state`` (s), ``spec`` (the process-model vector used), with ``smooth`` also ``epochs`` (the
        smoother's epoch count) and ``singular`` (epochs whose prior could not be inverted).
    """
    cfg = sd.make_config(samples=samples, **options)
    if predict_every < 1:
        raise ValueError("predict_every must be >= 1")
    wh = _columns(wheel, 3, (None, None, DEFAULT_SIGMA_WHEEL), "wheel")
    sp = em.make_spec(spec, baro_drift, scale_factors, misalignment, float(wheel_scale) if wh.shape[0] else 0.0)
    if not (math.isfinite(nhc) and nhc >= 0.0):
        raise ValueError(f"nhc must be finite and >= 0, got {nhc!r}")
    s = initial_state(init)
    imu = np.asarray(imu, dtype=np.float64)
    if imu.ndim != 2 or imu.shape[1] != 7:
        raise ValueError(f"imu must have shape (N, 7), got {imu.shape}")
    t = np.ascontiguousarray(imu[:, 0])
    n_nhc = int((t[-1] - t[0]) / NHC_EVERY) + 2 if nhc > 0.0 and t.shape[0] else 0  # constraints at most
    dth = np.ascontiguousarray(imu[:, 1:4])
    dvel = np.ascontiguousarray(imu[:, 4:7])

    g = _columns(gnss, 10, (None,) * 7 + (DEFAULT_SIGMA_H, DEFAULT_SIGMA_V, DEFAULT_SIGMA_VEL), "gnss")
    g[:, 1:3] = np.radians(g[:, 1:3])
    b = _columns(baro, 3, (None, None, DEFAULT_SIGMA_BARO), "baro")
    m = _columns(mag, 5, (None, None, None, None, math.degrees(DEFAULT_SIGMA_MAG)), "mag")
    m[:, 4] = np.radians(m[:, 4])
    z = _columns(static, 4, (None, None, DEFAULT_SIGMA_ZUPT, 0.0), "static")
    z[:, 3] /= _DEG_H

    P = kf.initial_covariance(
        sp,
        float(init.get("sigma_pos", 10.0)),
        float(init.get("sigma_vel", 1.0)),
        math.radians(float(init.get("sigma_level", 1.0))),
        math.radians(float(init.get("sigma_yaw", 10.0))),
        float(baro_offset_sigma),
        float(mag_bias),
    )
    bias = np.zeros(kf.B_SIZE)
    lever = np.asarray(lever_arm, dtype=np.float64).reshape(3)
    n_out = t.shape[0] // int(cfg[sd.CFG_SAMPLES]) + 1
    if not smooth_dt > 0.0:
        raise ValueError("smooth_dt must be > 0")
    active = np.flatnonzero(np.diag(P) > 0.0)
    if smooth:
        out = scratch((n_out, ROW_SIZE))
        n_ep = epoch_bound(t, g, b, m, z, float(smooth_dt)) + wh.shape[0] + n_nhc
        store = scratch((min(n_ep, n_out), sm.store_width(active.shape[0])))
    else:
        out = np.empty((n_out, ROW_SIZE))
        store = np.empty((0, sm.store_width(active.shape[0])))
    counts = np.zeros((len(KIND_NAMES), 2), dtype=np.int64)
    # one row per fix, baro, mag and attitude update (ZUPT), and per rest window a ZARU and the second
    # ZUPT of an update shared by two windows (one ends where the next starts)
    # (and one per wheel row and constraint)
    log = np.empty((2 * g.shape[0] + b.shape[0] + m.shape[0] + n_out + 2 * z.shape[0] + wh.shape[0] + n_nhc,
                    len(LOG_COLUMNS)))
    if covariance_every < 0:
        raise ValueError("covariance_every must be >= 0")
    p_every = int(covariance_every) if covariance_every > 0 else n_out + 1
    p_hist = np.zeros((n_out // p_every if covariance_every > 0 else 0, NX, NX))
    rows, n_log, n_ep = run_aided(
        s, cfg, t, dth, dvel, g, b, m, z, sp, lever, math.radians(declination),
        math.nan if mag_inclination is None else math.radians(mag_inclination),
        math.nan if mag_strength is None else float(mag_strength),
        math.nan if mag_strength_gate is None else float(mag_strength_gate), float(gate), int(predict_every),
        P, bias, out, counts, log, p_hist, p_every, store, active, float(smooth_dt), wh,
        np.asarray(wheel_lever_arm, dtype=np.float64).reshape(3), float(nhc),
    )
    result = out[:rows]
    singular = 0
    if smooth:
        singular = sm.backward(store, n_ep, active.shape[0])
        row_epoch = np.searchsorted(store[:n_ep, sm.EP_ROW], np.arange(rows), side="right")
        smooth_rows(out, rows, row_epoch, store, n_ep, active)
    stats: dict[str, Any] = {
        "counts": {name: (int(counts[k, 0]), int(counts[k, 1])) for k, name in enumerate(KIND_NAMES)},
        "nis": log[:n_log],
        "P": P,
        "bias": bias,
        "baro_offset": float(bias[kf.B_BARO]),
        "P_history": p_hist[: rows // p_every] if covariance_every > 0 else p_hist,
        "state": s,
        "spec": sp,
    }
    if smooth:
        stats["epochs"], stats["singular"] = n_ep, singular
        if file_units:
            result *= unit_factors(ROW_COLUMNS)  # in place: the rows may be larger than memory
        return result, stats
    return (to_file_units(result) if file_units else result), stats


def scratch(shape: tuple[int, int]) -> np.ndarray:
    """A float64 array of ``shape`` backed by an unlinked temporary file (the system's temporary
    directory, TMPDIR): the operating system pages it, and frees it when the last view goes."""
    with tempfile.TemporaryFile(prefix="mavins-") as fh:
        fh.truncate(max(1, shape[0] * shape[1]) * 8)
        return mapped(fh, shape)


def mapped(fh: Any, shape: tuple[int, int]) -> np.ndarray:
    """The float64 array of ``shape`` in the open file ``fh``, writable and mapped (not read into memory): the
    kernels take it as a plain array."""
    return np.asarray(np.memmap(fh, dtype=np.float64, mode="r+", shape=shape))


def epoch_bound(t: np.ndarray, gnss: np.ndarray, baro: np.ndarray, mag: np.ndarray, static: np.ndarray,
                smooth_dt: float) -> int:
    """At most how many smoother epochs run_aided records over these rows: one per measurement row, per
    IMU row inside a rest window (a ZUPT each) and per window (its ZARU), one per ``smooth_dt`` of the
    recording, and the first."""
    n = gnss.shape[0] + baro.shape[0] + mag.shape[0] + 2 * static.shape[0] + 2
    for t0, t1 in static[:, :2]:
        n += int(np.count_nonzero((t > t0) & (t <= t1)))
    if t.shape[0]:
        n += int((t[-1] - t[0]) / smooth_dt) + 1
    return n


__all__ = [
    "BARO_COLUMNS",
    "GNSS_COLUMNS",
    "KIND_NAMES",
    "LOG_COLUMNS",
    "MAG_COLUMNS",
    "NX",
    "OUT_COLUMNS",
    "OUT_SIZE",
    "ROW_COLUMNS",
    "ROW_SIZE",
    "STATIC_COLUMNS",
    "apply_mag",
    "file_columns",
    "filter_row",
    "navigate_aided",
    "run_aided",
    "to_file_units",
]
