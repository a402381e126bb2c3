"""IMU grade presets: the datasheet figures behind ``--grade`` (one table for
the simulator and the filter).

The simulator (sim/errors.py) corrupts ideal increments with these figures;
the filter (core/errmodel.py) takes the same figures as its process model, so
a grade means the same sensor on both sides.

Conventions used to turn datasheet lines into model parameters:

* Angle / velocity random walk: datasheet ARW/VRW, or the rate / acceleration
  noise density (``deg/s/sqrt(Hz)`` is numerically an ARW in ``deg/sqrt(s)``).
  Conversions: ``deg/sqrt(h) -> rad/sqrt(s)``: ``* pi/180/60``;
  ``deg/s/sqrt(Hz) -> rad/sqrt(s)``: ``* pi/180``;
  ``ug/sqrt(Hz) -> m/s/sqrt(s)``: ``* 9.80665e-6``;
  ``m/s/sqrt(h) -> m/s/sqrt(s)``: ``/ 60``; ``ft/s/sqrt(h)``: ``* 0.3048/60``.
* Bias instability ``B`` (the floor of the Allan deviation): modelled as a
  Gauss-Markov process whose Allan-deviation peak equals ``B``, i.e.
  ``sigma = B / GM_ADEV_PEAK_RATIO`` (``= B / 0.6174``), reached at
  ``tau = 1.893 tau_c``.  ``deg/h -> rad/s``: ``* pi/180/3600``;
  ``ug -> m/s^2``: ``* 9.80665e-6``.  Datasheets do not give ``tau_c``: it is
  an assumption (row ``tau_c``).
* Rate random walk: datasheets do not give it; it is set so that its Allan
  line ``K sqrt(tau/3)`` meets ``B`` at ``tau = 10 tau_c``, i.e.
  ``K = B sqrt(3 / (10 tau_c))``.
* Turn-on bias sigma: MEMS datasheet tolerances (``+-x``) are read as 3-sigma
  limits (sigma = x/3); Honeywell figures are quoted as 1-sigma and used as is.
  Honeywell gives one gyro bias figure, used for both the turn-on sigma and
  ``B``; the HG1700 1 mg accelerometer bias is used as the turn-on sigma only,
  its in-run ``B`` is assumed.
* Scale factor, misalignment, g-sensitivity are deterministic fields.  Each
  preset is one representative unit: a magnitude (MEMS ``+-`` limits divided
  by 3, typical or assumed values as they are) times a fixed sign/size
  pattern, so runs are repeatable.
* Quantisation is the increment LSB: for the consumer part the 16-bit rate
  LSB times the 1 ms sample period of a 1 kHz read-out; for the ADIS16470 the
  LSB of its 32-bit delta-angle / delta-velocity registers.
* Jitter and drop probability describe the logging path, not the sensor;
  they are assumptions.

Sources: [MPU] InvenSense PS-MPU-6000A-00 rev 3.4 (MPU-6000/6050 product
specification), sections 6.1 and 6.2; [ICM] TDK InvenSense DS-000176 rev 1.0
(ICM-20602 datasheet); [ADI] Analog Devices ADIS16470 datasheet (rev C),
table 1; [HG17] Honeywell HG1700 IMU brochure (AG58 variant); [HG99]
Honeywell HG9900 IMU brochure (N61-1638-000-000).  Figures marked ``*`` were
quoted from the datasheet from memory and could not be re-checked against
the document when this table was written; ``assumed`` marks engineering
assumptions that no datasheet states.

Datasheet figures (or assumptions) per grade; ``rth`` = sqrt(hour):

=================  =====================  ======================  =====================  =====================
quantity           consumer               industrial              tactical               navigation
=================  =====================  ======================  =====================  =====================
reference part     ICM-20602 / MPU-6000   ADIS16470               HG1700-AG58            HG9900
gyro ARW           4 mdps/rtHz [ICM]      0.34 deg/rth [ADI]      0.125 deg/rth [HG17]   0.002 deg/rth [HG99]
gyro B             10 deg/h (assumed)     8 deg/h [ADI]           1 deg/h [HG17]         0.0035 deg/h [HG99]
gyro turn-on       +-1 deg/s* [ICM]       0.1 deg/s (assumed)     1 deg/h [HG17]         0.0035 deg/h [HG99]
gyro scale         +-1 % [ICM]            0.1 % (assumed)         150 ppm* [HG17]        5 ppm [HG99]
gyro misalign      +-2 % cross [MPU]      0.05 deg (assumed)      0.1 mrad (assumed)     20 urad (assumed)
gyro g-sens        0.1 deg/s/g [MPU]      0.01 deg/s/g (assumed)  0 (RLG, assumed)       0 (RLG, assumed)
gyro LSB           16.4 LSB/dps [MPU]     2160 deg/2^31* [ADI]    assumed                assumed
accel VRW          100 ug/rtHz [ICM]      0.037 m/s/rth* [ADI]    0.065 ft/s/rth [HG17]  10 ug/rtHz (assumed)
accel B            0.1 mg (assumed)       13 ug [ADI]             50 ug (assumed)        25 ug [HG99]
accel turn-on      +-25 mg* [ICM]         2 mg (assumed)          1 mg [HG17]            25 ug [HG99]
accel scale        +-3 % [MPU]            0.1 % (assumed)         300 ppm* [HG17]        100 ppm [HG99]
accel misalign     +-2 % cross [MPU]      0.05 deg (assumed)      0.1 mrad (assumed)     20 urad (assumed)
accel LSB          2048 LSB/g [MPU]       400 m/s/2^31* [ADI]     assumed                assumed
tau_c (both)       50 s (assumed)         100 s (assumed)         300 s (assumed)        3600 s (assumed)
timestamp jitter   50 us (assumed)        10 us (assumed)         1 us (assumed)         1 us (assumed)
drop probability   1e-4 (assumed)         1e-5 (assumed)          0                      0
=================  =====================  ======================  =====================  =====================

Resulting model values (turn-on: 1-sigma; scale, misalignment and
g-sensitivity: magnitude before the fixed pattern; LSB at 1 kHz for consumer):

=====================  ==========  ==========  ==========  ==========  =================
model value            consumer    industrial  tactical    navigation  unit
=====================  ==========  ==========  ==========  ==========  =================
gyro random_walk       6.981e-5    9.890e-5    3.636e-5    5.818e-7    rad/sqrt(s)
gyro B                 4.848e-5    3.879e-5    4.848e-6    1.697e-8    rad/s
gyro rate random walk  3.755e-6    2.124e-6    1.533e-7    1.549e-10   rad/s/sqrt(s)
gyro turn-on sigma     5.818e-3    1.745e-3    4.848e-6    1.697e-8    rad/s
gyro scale factor      3333        1000        150         5           ppm
gyro misalignment      6.667e-3    8.727e-4    1e-4        2e-5        rad
g-sensitivity          1.780e-4    1.780e-5    0           0           rad/s per m/s^2
gyro LSB               1.064e-6    1.756e-8    1e-7        1e-8        rad
accel random_walk      9.807e-4    6.167e-4    3.302e-4    9.807e-5    m/s/sqrt(s)
accel B                9.807e-4    1.275e-4    4.903e-4    2.452e-4    m/s^2
accel rate random walk 7.596e-5    6.983e-6    1.551e-5    2.238e-6    m/s^2/sqrt(s)
accel turn-on sigma    8.172e-2    1.961e-2    9.807e-3    2.452e-4    m/s^2
accel scale factor     10000       1000        300         100         ppm
accel misalignment     6.667e-3    8.727e-4    1e-4        2e-5        rad
accel LSB              4.788e-6    1.863e-7    1e-6        1e-7        m/s
=====================  ==========  ==========  ==========  ==========  =================

"""

from __future__ import annotations

import math
from dataclasses import dataclass

G0 = 9.80665  # m/s^2: standard gravity (CGPM 1901), the unit behind "g", "mg", "ug"
DEG = math.pi / 180.0
DEG_PER_H = DEG / 3600.0
DEG_PER_RTH = DEG / 60.0
UG = 1e-6 * G0
MG = 1e-3 * G0
FT = 0.3048

GM_ADEV_PEAK_RATIO: float = 0.6173642831
"""Peak Allan deviation of a first-order Gauss-Markov process divided by its sigma
(IEEE Std 952-1997, annex C, exponentially correlated noise)."""

GM_ADEV_PEAK_TAU_RATIO: float = 1.8926
"""Averaging time of that peak divided by the correlation time."""


@dataclass(frozen=True)
class TriadFigures:
    """One triad's figures as model values (u = rad/s for gyros, m/s^2 for accelerometers).

    random_walk: u*sqrt(s); bias_instability: the Allan floor B (u); tau_c: s;
    turn_on_sigma: 1-sigma per-run bias (u); scale_factor_ppm: magnitude (ppm);
    misalignment: magnitude (rad); quantization: increment LSB (rad or m/s).
    """

    random_walk: float
    bias_instability: float
    tau_c: float
    turn_on_sigma: float
    scale_factor_ppm: float
    misalignment: float
    quantization: float

    @property
    def gm_sigma(self) -> float:
        """Stationary sigma of the Gauss-Markov bias whose Allan peak is B: B / 0.6174 (u)."""
        return self.bias_instability / GM_ADEV_PEAK_RATIO

    @property
    def rate_random_walk(self) -> float:
        """K such that K sqrt(tau/3) meets B at tau = 10 tau_c: K = B sqrt(3 / (10 tau_c)) (u/sqrt(s))."""
        return self.bias_instability * math.sqrt(3.0 / (10.0 * self.tau_c))


@dataclass(frozen=True)
class GradeFigures:
    """A grade: both triads, the gyro g-sensitivity magnitude (rad/s per m/s^2) and the logging path."""

    gyro: TriadFigures
    accel: TriadFigures
    g_sensitivity: float
    jitter_sigma: float
    drop_probability: float


GRADE_FIGURES: dict[str, GradeFigures] = {
    "consumer": GradeFigures(
        TriadFigures(0.004 * DEG, 10.0 * DEG_PER_H, 50.0, 1.0 * DEG / 3.0, 1e4 / 3.0, 0.02 / 3.0, DEG / 16.4 * 1e-3),
        TriadFigures(100.0 * UG, 0.1 * MG, 50.0, 25.0 * MG / 3.0, 3e4 / 3.0, 0.02 / 3.0, G0 / 2048.0 * 1e-3),
        0.1 * DEG / G0, 50e-6, 1e-4),
    "industrial": GradeFigures(
        TriadFigures(0.34 * DEG_PER_RTH, 8.0 * DEG_PER_H, 100.0, 0.1 * DEG, 1000.0, 0.05 * DEG, 2160.0 * DEG / 2.0**31),
        TriadFigures(0.037 / 60.0, 13.0 * UG, 100.0, 2.0 * MG, 1000.0, 0.05 * DEG, 400.0 / 2.0**31),
        0.01 * DEG / G0, 10e-6, 1e-5),
    "tactical": GradeFigures(
        TriadFigures(0.125 * DEG_PER_RTH, 1.0 * DEG_PER_H, 300.0, 1.0 * DEG_PER_H, 150.0, 1e-4, 1e-7),
        TriadFigures(0.065 * FT / 60.0, 50.0 * UG, 300.0, 1.0 * MG, 300.0, 1e-4, 1e-6),
        0.0, 1e-6, 0.0),
    "navigation": GradeFigures(
        TriadFigures(0.002 * DEG_PER_RTH, 0.0035 * DEG_PER_H, 3600.0, 0.0035 * DEG_PER_H, 5.0, 20e-6, 1e-8),
        TriadFigures(10.0 * UG, 25.0 * UG, 3600.0, 25.0 * UG, 100.0, 20e-6, 1e-7),
        0.0, 1e-6, 0.0),
}

GRADES: tuple[str, ...] = tuple(GRADE_FIGURES)
"""Grades with sensor errors (the simulator adds ``ideal``: no errors at all)."""


def grade_figures(name: str) -> GradeFigures:
    """The figures of grade ``name``; ValueError naming the choices otherwise."""
    try:
        return GRADE_FIGURES[name]
    except KeyError:
        raise ValueError(f"unknown grade {name!r}; choose one of {GRADES}") from None
