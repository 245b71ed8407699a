"""Named unit converters: the only place datasheet units meet SI.

Inside gyroarray everything is SI: angles in rad, rates in rad/s, time in s.
Files, the CLI and reports speak the units of IEEE Std 952 and of
``shared/spec/effects.md``; they convert through these functions, never
through magic constants.

=====================  ===============  ====================
quantity               datasheet unit   SI unit
=====================  ===============  ====================
angle                  deg              rad
rate                   deg/s, deg/h     rad/s
ARW  (N)               deg/√h           rad/√s
bias instability (B)   deg/h            rad/s
RRW  (K)               deg/h/√h         rad/s/√s
rate ramp (R)          deg/h²           rad/s²
quantization (Q)       deg              rad
specific force         g                m/s²
accel. bias instab.    mg               m/s²
VRW  (N_a)             m/s/√h           m/s/√s = m/s²/√Hz
accel. RW  (K_a)       m/s²/√h          m/s²/√s
g-sensitivity          (deg/s)/g        (rad/s)/(m/s²)
=====================  ===============  ====================

One g is the standard gravity g0 = 9.80665 m/s² (``shared/spec/effects.md``).
"""

from __future__ import annotations

import math

from gyroarray.core.constants import G0_M_S2

RAD_PER_DEG = math.pi / 180.0
S_PER_H = 3600.0
RT_S_PER_RT_H = 60.0  # √3600


def deg_to_rad(x):
    """Angle [deg] -> [rad]."""
    return x * RAD_PER_DEG


def rad_to_deg(x):
    """Angle [rad] -> [deg]."""
    return x / RAD_PER_DEG


def deg_s_to_rad_s(x):
    """Rate [deg/s] -> [rad/s]."""
    return x * RAD_PER_DEG


def rad_s_to_deg_s(x):
    """Rate [rad/s] -> [deg/s]."""
    return x / RAD_PER_DEG


def deg_h_to_rad_s(x):
    """Rate or bias instability [deg/h] -> [rad/s]."""
    return x * RAD_PER_DEG / S_PER_H


def rad_s_to_deg_h(x):
    """Rate or bias instability [rad/s] -> [deg/h]."""
    return x / RAD_PER_DEG * S_PER_H


def arw_deg_rt_h_to_rad_rt_s(x):
    """Angle random walk N [deg/√h] -> [rad/√s]."""
    return x * RAD_PER_DEG / RT_S_PER_RT_H


def arw_rad_rt_s_to_deg_rt_h(x):
    """Angle random walk N [rad/√s] -> [deg/√h]."""
    return x / RAD_PER_DEG * RT_S_PER_RT_H


def rrw_deg_h_rt_h_to_rad_s_rt_s(x):
    """Rate random walk K [deg/h/√h] -> [rad/s/√s]."""
    return x * RAD_PER_DEG / (S_PER_H * RT_S_PER_RT_H)


def rrw_rad_s_rt_s_to_deg_h_rt_h(x):
    """Rate random walk K [rad/s/√s] -> [deg/h/√h]."""
    return x / RAD_PER_DEG * (S_PER_H * RT_S_PER_RT_H)


def ramp_deg_h2_to_rad_s2(x):
    """Rate ramp R [deg/h²] -> [rad/s²]."""
    return x * RAD_PER_DEG / (S_PER_H * S_PER_H)


def ramp_rad_s2_to_deg_h2(x):
    """Rate ramp R [rad/s²] -> [deg/h²]."""
    return x / RAD_PER_DEG * (S_PER_H * S_PER_H)


def ppm_to_ratio(x):
    """Parts per million [ppm] -> ratio [-]."""
    return x * 1e-6


def ratio_to_ppm(x):
    """Ratio [-] -> parts per million [ppm]."""
    return x / 1e-6


def per_deg_s_to_per_rad_s(x):
    """Quadratic coefficient [1/(deg/s)] -> [1/(rad/s)].

    ``y [deg/s] = k2 · u [deg/s]²`` reads ``y [rad/s] = k2_SI · u [rad/s]²``
    in SI with ``k2_SI = k2 · (180/π)``.
    """
    return x / RAD_PER_DEG


def per_rad_s_to_per_deg_s(x):
    """Quadratic coefficient [1/(rad/s)] -> [1/(deg/s)]."""
    return x * RAD_PER_DEG


def g_to_m_s2(x):
    """Specific force [g] -> [m/s²] (g0 = 9.80665 m/s²)."""
    return x * G0_M_S2


def m_s2_to_g(x):
    """Specific force [m/s²] -> [g]."""
    return x / G0_M_S2


def deg_s_per_g_to_rad_s_per_m_s2(x):
    """g-sensitivity [(deg/s)/g] -> [(rad/s)/(m/s²)]."""
    return x * RAD_PER_DEG / G0_M_S2


def rad_s_per_m_s2_to_deg_s_per_g(x):
    """g-sensitivity [(rad/s)/(m/s²)] -> [(deg/s)/g]."""
    return x / RAD_PER_DEG * G0_M_S2


def mg_to_m_s2(x):
    """Specific force [mg] (milli-g0) -> [m/s²]."""
    return x * 1e-3 * G0_M_S2


def m_s2_to_mg(x):
    """Specific force [m/s²] -> [mg] (milli-g0)."""
    return x / (1e-3 * G0_M_S2)


def vrw_m_s_rt_h_to_si(x):
    """Velocity random walk [m/s/√h] -> [m/s/√s] (= m/s²/√Hz)."""
    return x / RT_S_PER_RT_H


def vrw_si_to_m_s_rt_h(x):
    """Velocity random walk [m/s/√s] (= m/s²/√Hz) -> [m/s/√h]."""
    return x * RT_S_PER_RT_H


def accel_rw_m_s2_rt_h_to_si(x):
    """Acceleration random walk [m/s²/√h] -> [m/s²/√s]."""
    return x / RT_S_PER_RT_H


def accel_rw_si_to_m_s2_rt_h(x):
    """Acceleration random walk [m/s²/√s] -> [m/s²/√h]."""
    return x * RT_S_PER_RT_H
