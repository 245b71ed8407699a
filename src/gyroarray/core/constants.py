"""Physical constants, in SI, each with its source (one module for all of them)."""

from __future__ import annotations

__all__ = ["EARTH_RATE_RAD_S", "G0_M_S2", "PPM"]

#: Earth's rotation rate relative to inertial space [rad/s] (WGS 84 / IERS).
EARTH_RATE_RAD_S = 7.2921150e-5

#: Standard gravity g0 [m/s²] (CGPM 1901; the unit of ``deg_s_per_g``).
G0_M_S2 = 9.80665

#: One part per million [-].
PPM = 1e-6
