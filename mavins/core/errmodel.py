"""Error model of the strapdown solution in the NED frame (the filter's system model).

Error state (docs/conventions.md "Aided navigation"; every error is *estimate minus
truth*), declared once in :data:`STATE` (named blocks; every index, size and the
bias vector's layout derive from it)::

    x[0:3]   phi   attitude error (rad), C_b^n(true) = (I - [phi x]) C_b^n(est)
    x[3:6]   dv    velocity error (m/s, NED)
    x[6:9]   dp    position error (m, NED): dp_N = (R_N + h) dL,
                   dp_E = (R_E + h) cos L dlambda, dp_D = -dh
    x[9:12]  bg    gyro bias, constant and random-walk part (rad/s)
    x[12:15] ba    accelerometer bias, constant and random-walk part (m/s^2)
    x[15:18] gg    gyro bias, first-order Gauss-Markov part (rad/s)
    x[18:21] ga    accelerometer bias, Gauss-Markov part (m/s^2)
    x[21]    ob    barometer offset (m)
    x[22:25] sg    gyro scale-factor error (dimensionless, 1e-6 = 1 ppm)
    x[25:28] sa    accelerometer scale-factor error (dimensionless)
    x[28:34] mg    gyro misalignment, the off-diagonal m_xy m_xz m_yx m_yz m_zx m_zy (rad)
    x[34:40] ma    accelerometer misalignment, likewise (rad)
    x[40:43] mb    magnetometer hard-iron bias (body FRD, the magnetometer's unit)
    x[43]    ws    wheel odometer scale-factor error (dimensionless)
    x[44:47] vp    external vision frame's origin (m, NED from the vision reference point)
    x[47]    vy    external vision frame's heading (rad): the angle about down from north to its x axis

The first 15 are the contract's. A sensor bias (``measured = true + b``) is
``b = b_const + b_gm``: a turn-on constant, slowly walking (rate random walk),
plus a first-order Gauss-Markov process (the "bias instability" of the spec).
One state per axis cannot carry both: a Gauss-Markov state would decay the
turn-on part towards zero (wrong), a random constant would ignore the
instability. So the Gauss-Markov part gets its own states after the
contract's 15 (the contract allows more states to follow), and the bias the
filter reports is the sum. Without an instability figure those states stay at
zero variance and do nothing.

Continuous model ``dx/dt = F x + G w``. With ``phi`` as defined above (the
attitude error of P. D. Groves, *Principles of GNSS, Inertial, and Multisensor
Integrated Navigation Systems*, 2nd ed., Artech House, 2013, section 14.2.4,
local-navigation-frame system model, where ``C(est) = (I + [dpsi x]) C(true)``,
i.e. ``dpsi = phi``, and errors are estimate minus truth), the blocks are::

    dphi/dt = -[w_in x] phi + F_phi,v dv + F_phi,p dp - C (bg + gg) + C n_g
    ddv/dt  = -[f^n x] phi + F_v,v dv + F_v,p dp - C (ba + ga) + C n_a
    ddp/dt  = dv + F_p,p dp
    dbg/dt  = n_rrw,g                 dba/dt = n_rrw,a
    dgg/dt  = -gg / tau_g + n_gm,g    dga/dt = -ga / tau_a + n_gm,a
    dob/dt  = n_baro
    dsg/dt  = dsa/dt = dmg/dt = dma/dt = dmb/dt = dws/dt = 0     (random constants)
    dvp/dt  = n_vision                dvy/dt = n_vision,yaw      (the camera's drift, random walks)

Scale factor (Titterton & Weston, Strapdown Inertial Navigation Technology,
2nd ed., 2004, ch. 12, sensor error model ``dw = B + S w``; KF-GINS's state):
``measured = (1 + s) true + b`` per axis, corrected as ``(measured - b) /
(1 + s)`` (kalman.correct_gyro); to first order the corrected rate is off by
``-(db + diag(w) ds)``, so the scale-factor columns are the bias columns
times the body rate or specific force: ``dphi/dt += -C diag(w_ib^b) sg``,
``ddv/dt += -C diag(f^b) sa``.

Misalignment (the same sensor model's off-diagonal part, ``dw = B + S w + M w``
with M zero on its diagonal: axis non-orthogonality and mounting): ``measured
= (I + S + M) true + b``, corrected to first order as ``u - M u`` with ``u =
(measured - b) / (1 + s)`` (kalman.correct_gyro3). The corrected rate is then
off by ``-dM w``: element m_ij (row i, column j) of the gyro's enters as
``dphi/dt += -C[:, i] w_j``, of the accelerometer's as ``ddv/dt += -C[:, i]
f_j`` (:func:`motion_columns`). Only rotation about axis j (specific force
along it) makes m_ij observable: a level multicopter sees the accelerometer's
m_xz, m_yz (gravity along z) and little else, a vehicle that turns and banks
more of them. The magnetometer's hard iron enters only its measurement
(kalman.mag_heading).

with ``w_in = w_ie + w_en`` and ``f^n = C f^b``. ``F_phi,v``, ``F_phi,p``
(here with dp in metres: the latitude column divided by R_N + h, the height
column with the sign of dp_D = -dh) and ``F_v,v``, ``F_v,p`` are Groves's
local-frame blocks (14.2.4; his F_12, F_13, F_22, F_23; the book was not at
hand when this was written, so the equation numbers are not cited), derived
again below from the contract's Earth rate, transport rate and gravity and
checked against the strapdown kernel itself (tests/core/test_errmodel.py):

* ``dphi = -w_in x phi + C dw_ib - dw_in`` with ``dw_ib = -bg - gg + n_g``
  and ``dw_in`` the change of ``w_ie + w_en`` with dv, dL = dp_N/(R_N+h) and
  dh = -dp_D (radius derivatives neglected, as Groves does);
* ``ddv = (C(est) - C) f^b + C df^b - (2 w_ie + w_en) x dv + v x (2 dw_ie
  + dw_en) + dg``, with ``(C(est) - C) f^b = phi x f^n``;
* gravity: ``dg_D = (d gamma_h/dh) dh = -(d gamma_h/dh) dp_D`` from the
  contract's normal-gravity formula, ``-d gamma_h/dh = gamma [2/a (1 + f + m
  - 2 f sin^2 L) - 6 h/a^2]`` (about ``2 g/(R + h)``): the unstable vertical
  channel;
* position, differentiating the definitions of dp (not the curvilinear
  errors): ``ddp_N = dv_N + (v_N dp_D - v_D dp_N)/(R_N + h)``,
  ``ddp_E = dv_E + (v_E dp_D - v_D dp_E)/(R_E + h) + tan L (v_E dp_N -
  v_N dp_E)/(R_N + h)``, ``ddp_D = dv_D``.

Validity: the model is first order in the errors. Its largest neglected
terms are ``1/2 phi x (phi x f^n)``: ``1/2 g (phi_N^2 + phi_E^2)`` on the
vertical and ``-1/2 g phi_D phi_h`` on the horizontal specific force. With
the simulator's consumer turn-on biases (8 mg, 0.33 deg/s) a level error the
data cannot yet separate from the accelerometer bias (about 0.3 deg in hover
or at rest) makes these larger than the sigma of the estimated accelerometer
bias, and a heading estimate drifting by degrees at rest lets the filter
believe in a tilt/bias separation that is not there; the filter is then
measurably over-confident (tests/core/test_aided_filter.py describes the runs).

Discretisation over a filter step T: ``Phi = I + F T + (F T)^2 / 2`` and
``Qd = (Phi Qc Phi^T + Qc) T / 2``, the trapezoidal rule applied to
``Qd = int_0^T Phi(s) G Qc G^T Phi(s)^T ds`` (Groves 2nd ed., section 3.2.3,
system-noise covariance approximations; the equation numbers there were not
checked against the book here). The noise is isotropic per sensor, so
``G Qc G^T = Qc`` with the densities: gyro ARW^2 (rad^2/s), accelerometer
VRW^2 (m^2/s^3), rate random walk K^2, Gauss-Markov driving noise
``2 sigma^2 / tau`` (stationary variance sigma^2), baro offset drift^2.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
import dataclasses
from dataclasses import dataclass

from typing import NamedTuple

import numpy as np

from . import earth, grades
from .jit import kernel

# --- error-state layout: declared once -------------------------------------
class Block(NamedTuple):
    """A named block of the error state: its name (``X_<NAME>`` is its first index), size, unit and
    meaning; ``sensor``: a sensor error the feedback keeps as an estimate (kalman's bias vector)."""

    name: str
    size: int
    unit: str
    what: str
    sensor: bool = False

    @property
    def labels(self) -> tuple[str, ...]:
        """Its elements' names in column names: ``x y z`` for a vector, ``xy xz yx yz zx zy`` for the six
        off-diagonal elements of a 3 x 3 matrix (:data:`OFF_DIAGONAL`), none for a scalar."""
        return {1: ("",), 3: ("x", "y", "z"), 6: tuple("xyz"[i] + "xyz"[j] for i, j in OFF_DIAGONAL)}[self.size]


OFF_DIAGONAL = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))  # (row, column) of a misalignment block's elements


STATE = (
    Block("PHI", 3, "rad", "attitude error phi: C_b^n(true) = (I - [phi x]) C_b^n(est)"),
    Block("DV", 3, "m/s", "velocity error, NED"),
    Block("DP", 3, "m", "position error, NED: dp_N = (R_N + h) dL, dp_E = (R_E + h) cos L dlambda, dp_D = -dh"),
    Block("BG", 3, "rad/s", "gyro bias, constant and random-walk part", sensor=True),
    Block("BA", 3, "m/s^2", "accelerometer bias, constant and random-walk part", sensor=True),
    Block("GG", 3, "rad/s", "gyro bias, first-order Gauss-Markov part", sensor=True),
    Block("GA", 3, "m/s^2", "accelerometer bias, Gauss-Markov part", sensor=True),
    Block("BARO", 1, "m", "barometer offset", sensor=True),
    Block("SG", 3, "1", "gyro scale-factor error", sensor=True),
    Block("SA", 3, "1", "accelerometer scale-factor error", sensor=True),
    Block("MG", 6, "rad", "gyro misalignment (off-diagonal, row-major)", sensor=True),
    Block("MA", 6, "rad", "accelerometer misalignment (off-diagonal, row-major)", sensor=True),
    Block("MB", 3, "mag", "magnetometer hard-iron bias, body FRD (the magnetometer's unit)", sensor=True),
    Block("WS", 1, "1", "wheel odometer scale-factor error: measured speed = (1 + k) true speed", sensor=True),
    # external vision (a VIO camera, motion capture): where its local frame sits (kalman.vision_position)
    Block("VP", 3, "m", "vision frame's origin, NED metres from the vision reference point", sensor=True),
    Block("VY", 1, "rad", "vision frame's heading: rotation about down from north to its x axis", sensor=True),
)
OFFSET = {b.name: sum(a.size for a in STATE[:i]) for i, b in enumerate(STATE)}  # block -> first index
NX = sum(b.size for b in STATE)
# the blocks' first indices as module constants (numba takes module-level ints as compile-time constants)
X_PHI, X_DV, X_DP = OFFSET["PHI"], OFFSET["DV"], OFFSET["DP"]
X_BG, X_BA, X_GG, X_GA, X_BARO = OFFSET["BG"], OFFSET["BA"], OFFSET["GG"], OFFSET["GA"], OFFSET["BARO"]
X_SG, X_SA, X_MG, X_MA, X_MB = OFFSET["SG"], OFFSET["SA"], OFFSET["MG"], OFFSET["MA"], OFFSET["MB"]
X_WS, X_VP, X_VY = OFFSET["WS"], OFFSET["VP"], OFFSET["VY"]
N_CONTRACT = OFFSET["GG"]  # the contract's states (attitude ... accelerometer bias); the rest follow them
X_SENSORS = min(OFFSET[b.name] for b in STATE if b.sensor)  # the sensor errors run from here to the end

# --- process-model vector (SI units) --------------------------------------
SP_GYRO_ARW = 0  # rad/sqrt(s)
SP_GYRO_BIAS = 1  # initial 1-sigma of the constant gyro bias (rad/s)
SP_GYRO_GM = 2  # stationary 1-sigma of the Gauss-Markov gyro bias (rad/s)
SP_GYRO_TAU = 3  # its correlation time (s)
SP_GYRO_RRW = 4  # gyro rate random walk (rad/s/sqrt(s))
SP_ACC_VRW = 5  # m/s/sqrt(s)
SP_ACC_BIAS = 6  # m/s^2
SP_ACC_GM = 7  # m/s^2
SP_ACC_TAU = 8  # s
SP_ACC_RRW = 9  # m/s^2/sqrt(s)
SP_BARO_DRIFT = 10  # random walk of the barometer offset (m/sqrt(s))
SP_GYRO_SCALE = 11  # initial 1-sigma of the gyro scale-factor error (dimensionless; 0: not estimated)
SP_ACC_SCALE = 12  # likewise of the accelerometer's
SP_GYRO_MIS = 13  # initial 1-sigma of each gyro misalignment element (rad; 0: not estimated)
SP_ACC_MIS = 14  # likewise of the accelerometer's
SP_WHEEL_SCALE = 15  # initial 1-sigma of the wheel odometer's scale-factor error (dimensionless; 0: not estimated)
SP_VISION_DRIFT = 16  # random walk of the vision frame's origin (m/sqrt(s)): a camera's position drift
SP_VISION_YAW_DRIFT = 17  # random walk of its heading (rad/sqrt(s))
SP_SIZE = 18

_DEG = math.pi / 180.0
_DEG_PER_H = _DEG / 3600.0
_DEG_PER_RTH = _DEG / 60.0


@dataclass(frozen=True)
class ImuSpec:
    """The filter's IMU noise and bias model, SI units.

    ``*_gm`` is the stationary 1-sigma of the first-order Gauss-Markov part
    with correlation time ``*_tau``; 0 means a constant bias. ``*_rrw`` is a
    rate random walk of the constant part (the simulator's grades have one;
    the contract's spec keys do not, so it is 0 when read from them).
    """

    gyro_arw: float = 0.0  # rad/sqrt(s)
    gyro_bias: float = 0.0  # rad/s
    gyro_gm: float = 0.0  # rad/s
    gyro_tau: float = 3600.0  # s
    gyro_rrw: float = 0.0  # rad/s/sqrt(s)
    accel_vrw: float = 0.0  # m/s/sqrt(s)
    accel_bias: float = 0.0  # m/s^2
    accel_gm: float = 0.0  # m/s^2
    accel_tau: float = 3600.0  # s
    accel_rrw: float = 0.0  # m/s^2/sqrt(s)
    gyro_scale: float = 0.0  # 1-sigma scale-factor error per axis (dimensionless, 1e-6 = 1 ppm); 0: not estimated
    accel_scale: float = 0.0  # likewise
    gyro_misalignment: float = 0.0  # 1-sigma of each off-diagonal misalignment element (rad); 0: not estimated
    accel_misalignment: float = 0.0  # likewise

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
            object.__setattr__(self, name, value)
        for name in ("gyro_tau", "accel_tau"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be > 0")

    def as_array(self, baro_drift: float = 0.0) -> np.ndarray:
        """The process-model vector (``SP_*`` layout) the kernels take; baro_drift in m/sqrt(s)."""
        sp = np.zeros(SP_SIZE)
        sp[SP_GYRO_ARW] = self.gyro_arw
        sp[SP_GYRO_BIAS] = self.gyro_bias
        sp[SP_GYRO_GM] = self.gyro_gm
        sp[SP_GYRO_TAU] = self.gyro_tau
        sp[SP_GYRO_RRW] = self.gyro_rrw
        sp[SP_ACC_VRW] = self.accel_vrw
        sp[SP_ACC_BIAS] = self.accel_bias
        sp[SP_ACC_GM] = self.accel_gm
        sp[SP_ACC_TAU] = self.accel_tau
        sp[SP_ACC_RRW] = self.accel_rrw
        sp[SP_BARO_DRIFT] = float(baro_drift)
        sp[SP_GYRO_SCALE] = self.gyro_scale
        sp[SP_ACC_SCALE] = self.accel_scale
        sp[SP_GYRO_MIS] = self.gyro_misalignment
        sp[SP_ACC_MIS] = self.accel_misalignment
        return sp


SPEC_KEYS = (
    "gyro_arw",
    "gyro_bias",
    "gyro_bias_instability",
    "gyro_bias_tau",
    "accel_vrw",
    "accel_bias",
    "accel_bias_instability",
    "accel_bias_tau",
    "gyro_scale",
    "accel_scale",
    "gyro_misalignment",
    "accel_misalignment",
)
ARCSEC = math.pi / (180.0 * 3600.0)  # rad: the spec keys' misalignment unit


def spec_from_keys(keys: Mapping[str, float]) -> ImuSpec:
    """ImuSpec from the contract's spec keys (file units).

    ``gyro_arw`` deg/sqrt(h), ``gyro_bias`` and ``gyro_bias_instability``
    deg/h, ``gyro_bias_tau`` s, ``accel_vrw`` m/s/sqrt(h), ``accel_bias`` and
    ``accel_bias_instability`` m/s^2, ``accel_bias_tau`` s. A missing
    instability means a constant bias; a missing key otherwise means 0.
    ``gyro_scale`` and ``accel_scale`` (ppm, 1-sigma) select the scale-factor
    states, ``gyro_misalignment`` and ``accel_misalignment`` (arcsec, 1-sigma of
    each element) the misalignment states (absent: not estimated).
    """

    def get(name: str) -> float:
        return float(keys.get(name, 0.0))

    def tau(name: str, inst: str) -> float:
        if get(inst) > 0.0:
            if name not in keys or not float(keys[name]) > 0.0:
                raise ValueError(f"{inst} needs {name} > 0 (s)")
            return float(keys[name])
        return 3600.0

    return ImuSpec(
        gyro_arw=get("gyro_arw") * _DEG_PER_RTH,
        gyro_bias=get("gyro_bias") * _DEG_PER_H,
        gyro_gm=get("gyro_bias_instability") * _DEG_PER_H,
        gyro_tau=tau("gyro_bias_tau", "gyro_bias_instability"),
        accel_vrw=get("accel_vrw") / 60.0,
        accel_bias=get("accel_bias"),
        accel_gm=get("accel_bias_instability"),
        accel_tau=tau("accel_bias_tau", "accel_bias_instability"),
        gyro_scale=get("gyro_scale") * 1e-6,
        accel_scale=get("accel_scale") * 1e-6,
        gyro_misalignment=get("gyro_misalignment") * ARCSEC,
        accel_misalignment=get("accel_misalignment") * ARCSEC,
    )


def spec_to_keys(spec: ImuSpec) -> dict[str, float]:
    """The contract's spec keys (file units) of an ImuSpec (rate random walk is not among them)."""
    return {
        "gyro_arw": spec.gyro_arw / _DEG_PER_RTH,
        "gyro_bias": spec.gyro_bias / _DEG_PER_H,
        "gyro_bias_instability": spec.gyro_gm / _DEG_PER_H,
        "gyro_bias_tau": spec.gyro_tau,
        "accel_vrw": spec.accel_vrw * 60.0,
        "accel_bias": spec.accel_bias,
        "accel_bias_instability": spec.accel_gm,
        "accel_bias_tau": spec.accel_tau,
        "gyro_scale": spec.gyro_scale * 1e6,
        "accel_scale": spec.accel_scale * 1e6,
        "gyro_misalignment": spec.gyro_misalignment / ARCSEC,
        "accel_misalignment": spec.accel_misalignment / ARCSEC,
    }


GRADES = grades.GRADES


def spec_from_grade(name: str, scale_factors: bool = False, misalignment: bool = False) -> ImuSpec:
    """ImuSpec with the figures of grade ``name`` (core/grades.py, the simulator's too).

    The simulator draws ``bias = turn-on + Gauss-Markov + rate random walk``:
    the initial sigma is the turn-on sigma, the Gauss-Markov sigma and tau and
    the rate random walk are taken as they are; with ``scale_factors`` the
    scale-factor magnitude (ppm) as the 1-sigma of the scale-factor states
    (else they are not estimated), with ``misalignment`` the misalignment
    magnitude (rad) as the 1-sigma of each misalignment element. G-sensitivity,
    quantisation, timestamp jitter and dropped samples are not in this model.
    """
    f = grades.grade_figures(name)
    return ImuSpec(
        gyro_arw=f.gyro.random_walk,
        gyro_bias=f.gyro.turn_on_sigma,
        gyro_gm=f.gyro.gm_sigma,
        gyro_tau=f.gyro.tau_c,
        gyro_rrw=f.gyro.rate_random_walk,
        accel_vrw=f.accel.random_walk,
        accel_bias=f.accel.turn_on_sigma,
        accel_gm=f.accel.gm_sigma,
        accel_tau=f.accel.tau_c,
        accel_rrw=f.accel.rate_random_walk,
        gyro_scale=f.gyro.scale_factor_ppm * 1e-6 if scale_factors else 0.0,
        accel_scale=f.accel.scale_factor_ppm * 1e-6 if scale_factors else 0.0,
        gyro_misalignment=f.gyro.misalignment if misalignment else 0.0,
        accel_misalignment=f.accel.misalignment if misalignment else 0.0,
    )


def spec_of(spec: str | ImuSpec | Mapping[str, float], scale_factors: bool = False,
            misalignment: bool = False) -> ImuSpec:
    """ImuSpec from a grade name, an ImuSpec (as it is) or the contract's spec keys; the scale factors of the
    grade or of the keys (``gyro_scale``/``accel_scale``, one of them then needed) only with ``scale_factors``
    (the filter estimates them then: ``--scale-factors``), the misalignments likewise only with
    ``misalignment`` (``gyro_misalignment``/``accel_misalignment``: ``--misalignment``)."""
    if isinstance(spec, str):
        return spec_from_grade(spec, scale_factors, misalignment)
    if isinstance(spec, ImuSpec):
        return spec
    out = spec_from_keys(spec)
    if not scale_factors:
        out = dataclasses.replace(out, gyro_scale=0.0, accel_scale=0.0)
    elif not (out.gyro_scale > 0.0 or out.accel_scale > 0.0):
        raise ValueError("--scale-factors with an IMU spec needs gyro_scale and/or accel_scale (ppm) in it")
    if not misalignment:
        out = dataclasses.replace(out, gyro_misalignment=0.0, accel_misalignment=0.0)
    elif not (out.gyro_misalignment > 0.0 or out.accel_misalignment > 0.0):
        raise ValueError("--misalignment with an IMU spec needs gyro_misalignment and/or accel_misalignment "
                         "(arcsec) in it")
    return out


def make_spec(spec: str | ImuSpec | Mapping[str, float], baro_drift: float = 0.0,
              scale_factors: bool = False, misalignment: bool = False, wheel_scale: float = 0.0,
              vision_drift: float = 0.0, vision_yaw_drift: float = 0.0) -> np.ndarray:
    """Process-model vector from a grade name, an ImuSpec or the contract's spec keys (:func:`spec_of`);
    ``wheel_scale``: the wheel odometer's initial scale-factor 1-sigma (dimensionless; 0: no odometer);
    ``vision_drift`` (m/sqrt(s)), ``vision_yaw_drift`` (rad/sqrt(s)): random walks of a camera's frame."""
    for name, v in (("wheel_scale", wheel_scale), ("vision_drift", vision_drift),
                    ("vision_yaw_drift", vision_yaw_drift)):
        if not (math.isfinite(v) and v >= 0.0):
            raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
    sp = spec_of(spec, scale_factors, misalignment).as_array(baro_drift)
    sp[SP_WHEEL_SCALE] = wheel_scale
    sp[SP_VISION_DRIFT] = vision_drift
    sp[SP_VISION_YAW_DRIFT] = vision_yaw_drift
    return sp


# --- small dense linear algebra (explicit loops: numba's np.dot needs SciPy) --


@kernel
def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` for 2-D arrays."""
    n, k = a.shape
    m = b.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for p in range(k):
            aip = a[i, p]
            if aip != 0.0:
                for j in range(m):
                    out[i, j] += aip * b[p, j]
    return out


@kernel
def matmul_bt(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b.T`` for 2-D arrays (:func:`matmul` on the transposed view)."""
    return matmul(a, b.T)


@kernel
def _set_block(m: np.ndarray, r: int, c: int, b: np.ndarray, scale: float) -> None:
    for i in range(3):
        for j in range(3):
            m[r + i, c + j] = scale * b[i, j]


@kernel
def _set_skew(m: np.ndarray, r: int, c: int, v: np.ndarray, scale: float) -> None:
    """Write ``scale [v x]`` into the 3x3 block at (r, c)."""
    m[r, c] = 0.0
    m[r, c + 1] = -scale * v[2]
    m[r, c + 2] = scale * v[1]
    m[r + 1, c] = scale * v[2]
    m[r + 1, c + 1] = 0.0
    m[r + 1, c + 2] = -scale * v[0]
    m[r + 2, c] = -scale * v[1]
    m[r + 2, c + 1] = scale * v[0]
    m[r + 2, c + 2] = 0.0


@kernel
def gravity_gradient(lat: float, h: float) -> float:
    """``-d gamma_h / dh`` (1/s^2) of the contract's normal gravity, about 2 g/(R + h)."""
    s2 = np.sin(lat) ** 2
    g0 = earth.GAMMA_E * (1.0 + earth.K_SOMIGLIANA * s2) / np.sqrt(1.0 - earth.E2 * s2)
    return g0 * (2.0 / earth.A * (1.0 + earth.F + earth.M_RATIO - 2.0 * earth.F * s2) - 6.0 * h / (earth.A * earth.A))


@kernel
def system_matrix(
    c: np.ndarray, v: np.ndarray, lat: float, h: float, f_n: np.ndarray, spec: np.ndarray, earth_on: bool
) -> np.ndarray:
    """Continuous error dynamics F (NX x NX) at one point of the trajectory, without the
    scale-factor and misalignment columns (:func:`motion_columns` adds them where the motion is known).

    ``c`` = C_b^n, ``v`` NED velocity (m/s), lat (rad), h (m), ``f_n`` the
    specific force in n (m/s^2). ``earth_on`` False is the contract's
    laboratory mode (no Earth rate, transport rate or gravity gradient).
    Equations in the module docstring.
    """
    F = np.zeros((NX, NX))
    vn, ve, vd = v[0], v[1], v[2]
    if earth_on:
        r_n, r_e = earth.radii(lat)
        rn = r_n + h
        re = r_e + h
        sl, cl = np.sin(lat), np.cos(lat)
        tl = sl / cl
        om = earth.OMEGA
        w_ie = np.array([om * cl, 0.0, -om * sl])
        w_en = np.array([ve / re, -vn / rn, -ve * tl / re])
        # d w_ie / d dp (only through dL = dp_N / rn) and d w_en / d(dv, dp).
        dwie_p = np.zeros((3, 3))
        dwie_p[0, 0] = -om * sl / rn
        dwie_p[2, 0] = -om * cl / rn
        dwen_v = np.zeros((3, 3))
        dwen_v[0, 1] = 1.0 / re
        dwen_v[1, 0] = -1.0 / rn
        dwen_v[2, 1] = -tl / re
        dwen_p = np.zeros((3, 3))
        dwen_p[0, 2] = ve / (re * re)
        dwen_p[1, 2] = -vn / (rn * rn)
        dwen_p[2, 0] = -ve / (re * rn * cl * cl)
        dwen_p[2, 2] = -ve * tl / (re * re)
        gg = gravity_gradient(lat, h)
    else:
        rn = re = 1.0
        tl = 0.0
        w_ie = np.zeros(3)
        w_en = np.zeros(3)
        dwie_p = np.zeros((3, 3))
        dwen_v = np.zeros((3, 3))
        dwen_p = np.zeros((3, 3))
        gg = 0.0

    # Attitude: -[w_in x] phi - d w_in.
    _set_skew(F, X_PHI, X_PHI, w_ie + w_en, -1.0)
    _set_block(F, X_PHI, X_DV, dwen_v, -1.0)
    _set_block(F, X_PHI, X_DP, dwie_p + dwen_p, -1.0)
    _set_block(F, X_PHI, X_BG, c, -1.0)
    _set_block(F, X_PHI, X_GG, c, -1.0)

    # Velocity: phi x f^n - (2 w_ie + w_en) x dv + v x (2 dw_ie + dw_en) + dg.
    _set_skew(F, X_DV, X_PHI, f_n, -1.0)
    vx = np.zeros((3, 3))
    _set_skew(vx, 0, 0, v, 1.0)
    fvv = np.zeros((3, 3))
    _set_skew(fvv, 0, 0, 2.0 * w_ie + w_en, -1.0)
    dvv = np.zeros((3, 3))
    dvp = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            a_v = 0.0
            a_p = 0.0
            for k in range(3):
                a_v += vx[i, k] * dwen_v[k, j]
                a_p += vx[i, k] * (2.0 * dwie_p[k, j] + dwen_p[k, j])
            dvv[i, j] = fvv[i, j] + a_v
            dvp[i, j] = a_p
    dvp[2, 2] += gg
    _set_block(F, X_DV, X_DV, dvv, 1.0)
    _set_block(F, X_DV, X_DP, dvp, 1.0)
    _set_block(F, X_DV, X_BA, c, -1.0)
    _set_block(F, X_DV, X_GA, c, -1.0)

    # Position (NED metres).
    for i in range(3):
        F[X_DP + i, X_DV + i] = 1.0
    if earth_on:
        F[X_DP, X_DP] = -vd / rn
        F[X_DP, X_DP + 2] = vn / rn
        F[X_DP + 1, X_DP] = ve * tl / rn
        F[X_DP + 1, X_DP + 1] = -vd / re - vn * tl / rn
        F[X_DP + 1, X_DP + 2] = ve / re

    # Gauss-Markov bias parts.
    if spec[SP_GYRO_GM] > 0.0:
        for i in range(3):
            F[X_GG + i, X_GG + i] = -1.0 / spec[SP_GYRO_TAU]
    if spec[SP_ACC_GM] > 0.0:
        for i in range(3):
            F[X_GA + i, X_GA + i] = -1.0 / spec[SP_ACC_TAU]
    return F


@kernel
def motion_columns(F: np.ndarray, c: np.ndarray, w_b: np.ndarray, f_b: np.ndarray, spec: np.ndarray) -> None:
    """Write the columns of the errors proportional to the motion into F (module docstring; Titterton &
    Weston ch. 12, ``dw = B + S w + M w``), with ``w_b`` (rad/s) and ``f_b`` (m/s^2) the body rate and
    specific force: scale factors ``-C diag(w_b)`` on phi (gyro), ``-C diag(f_b)`` on dv (accelerometer);
    misalignment element m_ij ``-C[:, i] w_j`` on phi, ``-C[:, i] f_j`` on dv. Only for the errors the
    spec estimates (1-sigma > 0); the others stay decoupled."""
    for i in range(3):
        for j in range(3):
            if spec[SP_GYRO_SCALE] > 0.0:
                F[X_PHI + i, X_SG + j] = -c[i, j] * w_b[j]
            if spec[SP_ACC_SCALE] > 0.0:
                F[X_DV + i, X_SA + j] = -c[i, j] * f_b[j]
    for k in range(6):
        r, col = OFF_DIAGONAL[k]
        for i in range(3):
            if spec[SP_GYRO_MIS] > 0.0:
                F[X_PHI + i, X_MG + k] = -c[i, r] * w_b[col]
            if spec[SP_ACC_MIS] > 0.0:
                F[X_DV + i, X_MA + k] = -c[i, r] * f_b[col]


@kernel
def noise_density(spec: np.ndarray) -> np.ndarray:
    """Diagonal of ``G Qc G^T`` (NX): white-noise densities driving each state."""
    q = np.zeros(NX)
    for i in range(3):
        q[X_PHI + i] = spec[SP_GYRO_ARW] ** 2
        q[X_DV + i] = spec[SP_ACC_VRW] ** 2
        q[X_BG + i] = spec[SP_GYRO_RRW] ** 2
        q[X_BA + i] = spec[SP_ACC_RRW] ** 2
        if spec[SP_GYRO_GM] > 0.0:
            q[X_GG + i] = 2.0 * spec[SP_GYRO_GM] ** 2 / spec[SP_GYRO_TAU]
        if spec[SP_ACC_GM] > 0.0:
            q[X_GA + i] = 2.0 * spec[SP_ACC_GM] ** 2 / spec[SP_ACC_TAU]
    q[X_BARO] = spec[SP_BARO_DRIFT] ** 2
    for i in range(3):
        q[X_VP + i] = spec[SP_VISION_DRIFT] ** 2
    q[X_VY] = spec[SP_VISION_YAW_DRIFT] ** 2
    return q


@kernel
def transition(F: np.ndarray, T: float) -> np.ndarray:
    """Second-order transition matrix ``Phi = I + F T + (F T)^2 / 2``."""
    n = F.shape[0]
    ft = F * T
    phi = matmul(ft, ft) * 0.5
    for i in range(n):
        for j in range(n):
            phi[i, j] += ft[i, j]
        phi[i, i] += 1.0
    return phi


@kernel
def discretise(F: np.ndarray, spec: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Qd)`` over a step of T seconds (trapezoidal Qd, module docstring)."""
    return discretise_density(F, noise_density(spec), T)


@kernel
def discretise_density(F: np.ndarray, q: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Phi, Qd)`` over T seconds for white-noise densities ``q`` (diagonal of G Qc G^T, one per state).

    ``Phi = I + F T + (F T)^2 / 2``, ``Qd = (Phi Qc Phi^T + Qc) T / 2`` (module
    docstring; any state size, so the error analysis' augmented model uses it too).
    """
    phi = transition(F, T)
    n = F.shape[0]
    pq = phi.copy()
    for i in range(n):
        for j in range(n):
            pq[i, j] *= q[j]
    qd = matmul_bt(pq, phi)
    for i in range(n):
        qd[i, i] += q[i]
    for i in range(n):
        for j in range(n):
            qd[i, j] *= 0.5 * T
    for i in range(n):
        for j in range(i + 1, n):
            m = 0.5 * (qd[i, j] + qd[j, i])
            qd[i, j] = m
            qd[j, i] = m
    return phi, qd
