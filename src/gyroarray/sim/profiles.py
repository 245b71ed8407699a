"""Motion profiles of the 3-axis rate table: TOML (and CSV) data to a commanded trajectory.

A profile is a sequence of segments read from a TOML file (``[[segment]]``
tables). Each segment becomes a few *pieces* of commanded gimbal motion; the
pieces are analytic (minimum-jerk moves and ramps, constant rates, sines) or,
for ``rate_csv``, the gimbal kinematics integrated from commanded body rates.
Everything inside is SI (rad, rad/s, s); the file keys carry their datasheet
units in their names (``rate_deg_s``, ``frequency_hz``, ``duration_s`` ...)
and are converted with :mod:`gyroarray.core.units`.

The gimbals
-----------
The table has an outer gimbal about the local vertical, a middle gimbal and an
inner gimbal carrying the platform. With gimbal angles ``q = (q_o, q_m, q_i)``
the platform attitude (platform -> local-level frame) is::

    R(q) = Rz(q_o) Rx(q_m) Ry(q_i)

so ``q = 0`` is the level platform (z up, x along the table's x axis, which is
the platform x axis at t = 0: ``heading_deg`` from north in the measurement
spec). The platform's angular velocity relative to the local-level frame, in
the platform frame, is ``ω = J(q) q̇`` with the columns of ``J`` the three
gimbal axes seen from the platform::

    J(q) = [ -sin q_i cos q_m   cos q_i   0 ]
           [  sin q_m           0         1 ]
           [  cos q_i cos q_m   sin q_i   0 ]        det J = cos q_m

The first column is the body vector that points up. A rate about a body axis
``a`` is made as real tables make it: the middle and inner gimbals turn the
platform until ``a`` (or ``-a``, whichever is nearer) points up, then the
outer gimbal turns, giving exactly ``ω = rate · a``. Arbitrary body rates
(``rate_csv``) invert the kinematics, ``q̇ = J(q)⁻¹ ω``; near the middle
gimbal's lock at ±90° the inversion is refused.

The file format
---------------
Top-level keys: ``description`` (string, optional) and the ``[[segment]]``
tables, run in order from the level platform at rest. Every segment has
``kind`` and an optional ``label``. Orientations are given either as
``up_axis = [x, y, z]`` — the platform axis that must point up (middle and
inner gimbals move, the outer gimbal stays) — or as
``gimbal_deg = [outer, middle, inner]`` — the table's angles, reached by the
shortest way (each joint moves less than 180°). Axes must be unit vectors to
within ``AXIS_NORM_TOL`` and are normalised.

================  =========================================================
kind              keys (required unless a default is shown)
================  =========================================================
static            duration_s; up_axis | gimbal_deg (default: stay);
                  transition_s (needed when the orientation changes)
multi_position    up_axes = [[x,y,z], ...] | gimbal_deg = [[o,m,i], ...];
                  hold_s; transition_s. Each position: transition, hold.
constant_rate     axis; rate_deg_s; duration_s (at full rate); ramp_s (up and
                  down, minimum-jerk); align_s = 0 (time to re-orient)
rate_steps        axis; rates_deg_s = [...]; hold_s (number or list); ramp_s
                  (between levels, from and back to 0); align_s = 0
sinusoid          axis; amplitude_deg_s; frequency_hz; duration_s;
                  phase_deg = 0; align_s = 0.  ω = A sin(2π f t + φ) · axis
tumble            axis; rate_deg_s; duration_s (at full rate); ramp_s;
                  tilt_deg = 0; align_s = 0. A continuous rotation about a
                  non-vertical axis, so gravity turns through the platform
                  frame: axis ±y turns the inner gimbal, the middle gimbal
                  first set to tilt_deg (the axis' elevation above the
                  horizon); an axis in the platform x–z plane turns the
                  middle gimbal (a horizontal axis; the inner gimbal first
                  set so that its axis is the middle gimbal's; tilt_deg must
                  be 0). ω = rate · axis. Other axes cannot tumble on this
                  table (refused).
rate_csv          file: CSV of commanded body rates, path relative to the
                  TOML file; columns time_s, wx_deg_s, wy_deg_s, wz_deg_s;
                  '#' lines are comments; time_s starts at 0, increasing;
                  rates linear between rows
================  =========================================================

Example::

    description = "six positions, then 30 deg/s about an oblique axis"
    [[segment]]
    kind = "multi_position"
    up_axes = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]
    hold_s = 60.0
    transition_s = 10.0
    [[segment]]
    kind = "constant_rate"
    axis = [0.57735, 0.57735, 0.57735]
    rate_deg_s = 30.0
    duration_s = 120.0
    ramp_s = 3.0
    align_s = 10.0

Nothing in a profile is executed or imported; unknown keys, wrong types and
bad values are refused with :class:`gyroarray.core.errors.InputError` naming the
file, the ``[[segment]]`` key (``segment[3].rate_deg_s``, segments counted
from 1) and, where it can be found, the line.
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import KW_ONLY, dataclass, field, fields
from pathlib import Path
from typing import NoReturn

import numpy as np

from gyroarray.core.errors import InputError
from gyroarray.core.limits import check_memory, read_regular
from gyroarray.core.tomlio import load_toml
from gyroarray.core.units import deg_s_to_rad_s, deg_to_rad, rad_to_deg


__all__ = [
    "AXIS_NORM_TOL", "GIMBAL_LOCK_MARGIN_RAD",
    "Orientation", "Static", "MultiPosition", "ConstantRate", "RateSteps", "Sinusoid", "Tumble",
    "RateCSV",
    "Profile", "Command", "load_profile", "read_rate_csv",
    "gimbal_rotation", "gimbal_quaternion", "body_jacobian", "body_rate", "joint_rates",
    "up_vector", "gimbal_for_up_axis",
]

#: Largest accepted | |axis| - 1 | for axes in profile files [-] (as layouts).
AXIS_NORM_TOL = 1e-3
#: ``rate_csv`` is refused when the middle gimbal comes closer than this to
#: ±90° (gimbal lock: det J = cos q_m) [rad].
GIMBAL_LOCK_MARGIN_RAD = deg_to_rad(10.0)
#: Largest RK4 step when integrating ``rate_csv`` kinematics [s].
CSV_MAX_STEP_S = 0.01
#: Most RK4 steps one ``rate_csv`` segment may take (10 000 s at CSV_MAX_STEP_S, or that
#: many rows): the integration is a Python loop of about 10 µs and 200 bytes a step.
CSV_MAX_STEPS = 1_000_000
#: Memory of one RK4 node of a ``rate_csv`` segment (nodes, angles, rates, interpolation)
#: [bytes], for :func:`gyroarray.core.limits.check_memory`.
_CSV_BYTES_PER_STEP = 200
#: Two joint configurations closer than this are the same orientation [rad].
SAME_ORIENTATION_RAD = 1e-12

_TWO_PI = 2.0 * math.pi


# =============================================================================
# Gimbal kinematics (pure functions, vectorised over leading dimensions)
# =============================================================================

def gimbal_rotation(q) -> np.ndarray:
    """Platform attitude ``R(q) = Rz(q_o) Rx(q_m) Ry(q_i)``.

    Parameters
    ----------
    q : array_like, shape (..., 3)
        Gimbal angles (outer, middle, inner) [rad].

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Rotation platform -> local-level frame [-].
    """
    q = np.asarray(q, dtype=float)
    c1, s1 = np.cos(q[..., 0]), np.sin(q[..., 0])
    c2, s2 = np.cos(q[..., 1]), np.sin(q[..., 1])
    c3, s3 = np.cos(q[..., 2]), np.sin(q[..., 2])
    R = np.empty(q.shape[:-1] + (3, 3))
    # Rz(q1) Rx(q2) Ry(q3), multiplied out
    R[..., 0, 0] = c1 * c3 - s1 * s2 * s3
    R[..., 0, 1] = -s1 * c2
    R[..., 0, 2] = c1 * s3 + s1 * s2 * c3
    R[..., 1, 0] = s1 * c3 + c1 * s2 * s3
    R[..., 1, 1] = c1 * c2
    R[..., 1, 2] = s1 * s3 - c1 * s2 * c3
    R[..., 2, 0] = -c2 * s3
    R[..., 2, 1] = s2
    R[..., 2, 2] = c2 * c3
    return R


def gimbal_quaternion(q) -> np.ndarray:
    """Platform attitude as a unit quaternion (w, x, y, z), platform -> local level.

    Parameters
    ----------
    q : array_like, shape (..., 3)
        Gimbal angles (outer, middle, inner) [rad].

    Returns
    -------
    ndarray, shape (..., 4)
        ``qz(q_o) ⊗ qx(q_m) ⊗ qy(q_i)`` [-].
    """
    q = np.asarray(q, dtype=float)
    a, b, c = q[..., 0] / 2, q[..., 1] / 2, q[..., 2] / 2
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    # (ca + sa k)(cb + sb i) = ca cb + ca sb i + sa cb k + sa sb j
    w1, x1, y1, z1 = ca * cb, ca * sb, sa * sb, sa * cb
    # ... ⊗ (cc + sc j)
    return np.stack([w1 * cc - y1 * sc,
                     x1 * cc - z1 * sc,
                     w1 * sc + y1 * cc,
                     z1 * cc + x1 * sc], axis=-1)


def body_jacobian(q) -> np.ndarray:
    """Body-frame Jacobian ``J(q)`` with ``ω_body = J(q) q̇``.

    Parameters
    ----------
    q : array_like, shape (..., 3)
        Gimbal angles [rad].

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Columns: outer, middle and inner gimbal axes in the platform frame [-].
    """
    q = np.asarray(q, dtype=float)
    c2, s2 = np.cos(q[..., 1]), np.sin(q[..., 1])
    c3, s3 = np.cos(q[..., 2]), np.sin(q[..., 2])
    J = np.zeros(q.shape[:-1] + (3, 3))
    J[..., 0, 0], J[..., 1, 0], J[..., 2, 0] = -s3 * c2, s2, c3 * c2
    J[..., 0, 1], J[..., 2, 1] = c3, s3
    J[..., 1, 2] = 1.0
    return J


def body_rate(q, qd) -> np.ndarray:
    """Platform angular velocity ``ω = J(q) q̇`` in the platform frame [rad/s].

    Parameters
    ----------
    q : array_like, shape (..., 3)
        Gimbal angles [rad].
    qd : array_like, shape (..., 3)
        Gimbal rates [rad/s].
    """
    return np.einsum("...ij,...j->...i", body_jacobian(q), np.asarray(qd, dtype=float))


def joint_rates(q, omega_body) -> np.ndarray:
    """Gimbal rates ``q̇ = J(q)⁻¹ ω`` for a body rate (closed form).

    Parameters
    ----------
    q : array_like, shape (..., 3)
        Gimbal angles [rad]; the middle angle must not be ±90° (gimbal lock).
    omega_body : array_like, shape (..., 3)
        Angular velocity in the platform frame [rad/s].

    Returns
    -------
    ndarray, shape (..., 3)
        Gimbal rates [rad/s].

    Notes
    -----
    From the rows of J: ``q̇_o = (cos q_i ω_z - sin q_i ω_x) / cos q_m``,
    ``q̇_m = cos q_i ω_x + sin q_i ω_z``, ``q̇_i = ω_y - sin q_m q̇_o``.
    """
    q = np.asarray(q, dtype=float)
    w = np.asarray(omega_body, dtype=float)
    c2, s2 = np.cos(q[..., 1]), np.sin(q[..., 1])
    c3, s3 = np.cos(q[..., 2]), np.sin(q[..., 2])
    q1d = (c3 * w[..., 2] - s3 * w[..., 0]) / c2
    q2d = c3 * w[..., 0] + s3 * w[..., 2]
    q3d = w[..., 1] - s2 * q1d
    return np.stack([q1d, q2d, q3d], axis=-1)


def up_vector(q) -> np.ndarray:
    """The platform-frame vector that points up, ``R(q)ᵀ e_z`` [-].

    Parameters
    ----------
    q : array_like, shape (..., 3)
        Gimbal angles [rad].
    """
    return body_jacobian(q)[..., :, 0]


def _nearest(angle: float, current: float) -> float:
    """``angle`` plus a multiple of 2π, nearest to ``current`` [rad]."""
    return angle + _TWO_PI * round((current - angle) / _TWO_PI)


def gimbal_for_up_axis(axis, q_current) -> np.ndarray:
    """Gimbal angles that point the platform axis ``axis`` up, outer gimbal unchanged.

    Parameters
    ----------
    axis : array_like, shape (3,)
        Unit platform axis to point up [-].
    q_current : array_like, shape (3,)
        Present gimbal angles [rad]; the outer angle is kept and the inner
        angle is taken modulo 2π nearest to the present one.

    Returns
    -------
    ndarray, shape (3,)
        ``(q_o, asin a_y, atan2(-a_x, a_z))`` [rad].
    """
    a = np.asarray(axis, dtype=float)
    qc = np.asarray(q_current, dtype=float)
    q2 = math.asin(min(1.0, max(-1.0, float(a[1]))))
    if math.hypot(a[0], a[2]) < 1e-12:      # body y up: any inner angle works, keep it
        q3 = float(qc[2])
    else:
        q3 = _nearest(math.atan2(-a[0], a[2]), float(qc[2]))
    return np.array([float(qc[0]), q2, q3])


# =============================================================================
# Segments (SI, frozen)
# =============================================================================

def _unit3(v, what: str) -> tuple[float, float, float]:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{what} must be 3 finite numbers, got {v!r}")
    n = float(np.linalg.norm(a))
    if abs(n - 1.0) > AXIS_NORM_TOL:
        raise InputError(f"{what} {a.tolist()} is not a unit vector (norm {n:.6g}, "
                         f"allowed 1 ± {AXIS_NORM_TOL:g})")
    x, y, z = (float(c) for c in a / n)
    return x, y, z


def _positive(value, what: str, *, allow_zero: bool = False) -> float:
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise InputError(f"{what} must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")
    return v


@dataclass(frozen=True)
class Orientation:
    """A platform orientation on the table: exactly one of the two fields.

    Parameters
    ----------
    up_axis : tuple of 3 float, optional
        Unit platform axis that points up [-]; the outer gimbal stays.
    gimbal_rad : tuple of 3 float, optional
        Gimbal angles (outer, middle, inner) [rad], reached the short way.
    """

    up_axis: tuple | None = None
    gimbal_rad: tuple | None = None

    def __post_init__(self):
        if (self.up_axis is None) == (self.gimbal_rad is None):
            raise InputError("an orientation needs exactly one of up_axis or gimbal angles")
        if self.up_axis is not None:
            object.__setattr__(self, "up_axis", _unit3(self.up_axis, "up_axis"))
        else:
            g = np.asarray(self.gimbal_rad, dtype=float)
            if g.shape != (3,) or not np.all(np.isfinite(g)):
                raise InputError(f"gimbal angles must be 3 finite numbers, got {self.gimbal_rad!r}")
            object.__setattr__(self, "gimbal_rad", tuple(float(x) for x in g))

    def target(self, q_current) -> np.ndarray:
        """Gimbal angles of this orientation, starting from ``q_current`` [rad]."""
        qc = np.asarray(q_current, dtype=float)
        if self.up_axis is not None:
            return gimbal_for_up_axis(self.up_axis, qc)
        assert self.gimbal_rad is not None                      # one of the two is given
        return np.array([_nearest(g, c) for g, c in zip(self.gimbal_rad, qc)])


@dataclass(frozen=True)
class Static:
    """Hold still for ``duration_s``, after an optional move to ``orientation``.

    Parameters
    ----------
    duration_s : float
        Hold time [s], > 0.
    orientation : Orientation, optional
        Where to hold; None keeps the present orientation.
    transition_s : float
        Minimum-jerk move time before the hold [s], >= 0; needed (> 0) when
        the orientation changes.
    label : str
    """

    duration_s: float
    orientation: Orientation | None = None
    transition_s: float = 0.0
    label: str = ""
    kind = "static"

    def __post_init__(self):
        object.__setattr__(self, "duration_s", _positive(self.duration_s, "duration_s"))
        object.__setattr__(self, "transition_s",
                           _positive(self.transition_s, "transition_s", allow_zero=True))


@dataclass(frozen=True)
class MultiPosition:
    """Several static positions, each reached by a minimum-jerk move then held.

    Parameters
    ----------
    orientations : tuple of Orientation
        The positions, in order (at least one).
    hold_s : float
        Hold time at each position [s], > 0.
    transition_s : float
        Move time before each position [s], > 0.
    label : str
    """

    orientations: tuple
    hold_s: float
    transition_s: float
    label: str = ""
    kind = "multi_position"

    def __post_init__(self):
        o = tuple(self.orientations)
        if not o or not all(isinstance(x, Orientation) for x in o):
            raise InputError("multi_position needs at least one orientation")
        object.__setattr__(self, "orientations", o)
        object.__setattr__(self, "hold_s", _positive(self.hold_s, "hold_s"))
        object.__setattr__(self, "transition_s", _positive(self.transition_s, "transition_s"))


@dataclass(frozen=True)
class ConstantRate:
    """A constant rate about a platform axis, with minimum-jerk ramps up and down.

    Parameters
    ----------
    axis : tuple of 3 float
        Unit platform axis [-].
    rate_rad_s : float
        Rate about ``axis`` (right hand) [rad/s].
    duration_s : float
        Time at the full rate [s], > 0; the segment lasts
        ``align_s + 2 ramp_s + duration_s``.
    ramp_s : float
        Ramp time from and back to rest [s], >= 0 (0: a rate step).
    align_s : float
        Move time to point the axis up first [s], >= 0.
    label : str
    """

    axis: tuple
    rate_rad_s: float
    duration_s: float
    ramp_s: float
    align_s: float = 0.0
    label: str = ""
    kind = "constant_rate"

    def __post_init__(self):
        object.__setattr__(self, "axis", _unit3(self.axis, "axis"))
        r = float(self.rate_rad_s)
        if not math.isfinite(r):
            raise InputError(f"rate must be finite, got {self.rate_rad_s!r}")
        object.__setattr__(self, "rate_rad_s", r)
        object.__setattr__(self, "duration_s", _positive(self.duration_s, "duration_s"))
        object.__setattr__(self, "ramp_s", _positive(self.ramp_s, "ramp_s", allow_zero=True))
        object.__setattr__(self, "align_s", _positive(self.align_s, "align_s", allow_zero=True))


@dataclass(frozen=True)
class RateSteps:
    """A staircase of rates about one axis: ramp, hold, ramp, hold, ..., ramp to rest.

    Parameters
    ----------
    axis : tuple of 3 float
        Unit platform axis [-].
    rates_rad_s : tuple of float
        The rate levels [rad/s].
    hold_s : tuple of float
        Hold time at each level [s], > 0 (one per level).
    ramp_s : float
        Minimum-jerk ramp time between levels [s], >= 0.
    align_s : float
        Move time to point the axis up first [s], >= 0.
    label : str
    """

    axis: tuple
    rates_rad_s: tuple
    hold_s: tuple
    ramp_s: float
    align_s: float = 0.0
    label: str = ""
    kind = "rate_steps"

    def __post_init__(self):
        object.__setattr__(self, "axis", _unit3(self.axis, "axis"))
        rates = tuple(float(r) for r in self.rates_rad_s)
        if not rates or not all(math.isfinite(r) for r in rates):
            raise InputError(f"rates must be a non-empty list of finite numbers, got {self.rates_rad_s!r}")
        holds = self.hold_s
        if np.ndim(holds) == 0:
            holds = (holds,) * len(rates)
        holds = tuple(_positive(h, "hold_s") for h in holds)
        if len(holds) != len(rates):
            raise InputError(f"hold_s has {len(holds)} values for {len(rates)} rates")
        object.__setattr__(self, "rates_rad_s", rates)
        object.__setattr__(self, "hold_s", holds)
        object.__setattr__(self, "ramp_s", _positive(self.ramp_s, "ramp_s", allow_zero=True))
        object.__setattr__(self, "align_s", _positive(self.align_s, "align_s", allow_zero=True))


@dataclass(frozen=True)
class Sinusoid:
    """``ω = A sin(2π f t + φ) · axis``, t from the start of the swing.

    Parameters
    ----------
    axis : tuple of 3 float
        Unit platform axis [-].
    amplitude_rad_s : float
        Rate amplitude A [rad/s], > 0.
    frequency_hz : float
        Swing frequency f [Hz], > 0.
    duration_s : float
        Swing time [s], > 0 (a whole number of periods ends at rest when φ = 0).
    phase_rad : float
        Initial phase φ [rad]; a non-zero ``sin φ`` starts with a rate step.
    align_s : float
        Move time to point the axis up first [s], >= 0.
    label : str
    """

    axis: tuple
    amplitude_rad_s: float
    frequency_hz: float
    duration_s: float
    phase_rad: float = 0.0
    align_s: float = 0.0
    label: str = ""
    kind = "sinusoid"

    def __post_init__(self):
        object.__setattr__(self, "axis", _unit3(self.axis, "axis"))
        object.__setattr__(self, "amplitude_rad_s", _positive(self.amplitude_rad_s, "amplitude"))
        object.__setattr__(self, "frequency_hz", _positive(self.frequency_hz, "frequency_hz"))
        object.__setattr__(self, "duration_s", _positive(self.duration_s, "duration_s"))
        p = float(self.phase_rad)
        if not math.isfinite(p):
            raise InputError(f"phase must be finite, got {self.phase_rad!r}")
        object.__setattr__(self, "phase_rad", p)
        object.__setattr__(self, "align_s", _positive(self.align_s, "align_s", allow_zero=True))


@dataclass(frozen=True)
class Tumble:
    """A continuous rotation about a non-vertical platform axis (one gimbal turning).

    Parameters
    ----------
    axis : tuple of 3 float
        Unit platform axis [-]: ±y (the inner gimbal turns) or any axis with
        y = 0 (the middle gimbal turns; its axis is horizontal).
    rate_rad_s : float
        Rate about ``axis`` (right hand) [rad/s].
    duration_s : float
        Time at the full rate [s], > 0; the segment lasts
        ``align_s + 2 ramp_s + duration_s`` and turns the platform by
        ``rate·(duration_s + ramp_s)``.
    ramp_s : float
        Minimum-jerk ramp time from and back to rest [s], >= 0.
    tilt_rad : float
        y-axis tumble: elevation of the tumble axis above the horizon, set
        with the middle gimbal [rad], in [−π/2, π/2]; must be 0 for an x–z
        axis.
    align_s : float
        Move time to the start orientation [s], >= 0.
    label : str
    """

    axis: tuple
    rate_rad_s: float
    duration_s: float
    ramp_s: float
    tilt_rad: float = 0.0
    align_s: float = 0.0
    label: str = ""
    kind = "tumble"

    def __post_init__(self):
        object.__setattr__(self, "axis", _unit3(self.axis, "axis"))
        for name in ("rate_rad_s", "tilt_rad"):
            v = float(getattr(self, name))
            if not math.isfinite(v):
                raise InputError(f"{name} must be finite, got {getattr(self, name)!r}")
            object.__setattr__(self, name, v)
        if abs(self.tilt_rad) > math.pi / 2:
            raise InputError(f"tilt must be within ±90 deg, got {rad_to_deg(self.tilt_rad):g} deg")
        object.__setattr__(self, "duration_s", _positive(self.duration_s, "duration_s"))
        object.__setattr__(self, "ramp_s", _positive(self.ramp_s, "ramp_s", allow_zero=True))
        object.__setattr__(self, "align_s", _positive(self.align_s, "align_s", allow_zero=True))


@dataclass(frozen=True, eq=False)
class RateCSV:
    """Arbitrary commanded body rates, linear between rows.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Times from the start of the segment [s]: starts at 0, increasing.
    omega_rad_s : ndarray, shape (n, 3)
        Commanded body rates in the platform frame [rad/s].
    file : str
        Where the rows came from (for messages and the fingerprint).
    line_numbers : tuple of int, optional
        1-based file line of each row (for messages).
    label : str
    """

    time_s: np.ndarray
    omega_rad_s: np.ndarray
    file: str = "<rates>"
    line_numbers: tuple | None = None
    label: str = ""
    kind = "rate_csv"

    def __post_init__(self):
        t = np.array(self.time_s, dtype=float)
        w = np.array(self.omega_rad_s, dtype=float)
        if t.ndim != 1 or t.size < 2 or w.shape != (t.size, 3):
            raise InputError(f"rate_csv needs >= 2 rows of (time, wx, wy, wz), got shapes "
                             f"{t.shape} and {w.shape}", file=self.file)
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(w))):
            raise InputError("rate_csv values must be finite", file=self.file)
        if t[0] != 0.0 or np.any(np.diff(t) <= 0):
            raise InputError("time_s must start at 0 and increase strictly", file=self.file)
        for a in (t, w):
            a.setflags(write=False)
        object.__setattr__(self, "time_s", t)
        object.__setattr__(self, "omega_rad_s", w)

    @property
    def duration_s(self) -> float:
        """Duration of the segment [s]: the last ``time_s``."""
        return float(self.time_s[-1])

    def line_of(self, row: int) -> int | None:
        """File line of row ``row`` (0-based), if known."""
        if self.line_numbers is None:
            return None
        return int(self.line_numbers[min(max(row, 0), len(self.line_numbers) - 1)])


_SEGMENT_TYPES = (Static, MultiPosition, ConstantRate, RateSteps, Sinusoid, Tumble, RateCSV)


# =============================================================================
# Pieces: the commanded gimbal trajectory
# =============================================================================

def _minjerk(tau):
    """s(τ) = 10τ³ - 15τ⁴ + 6τ⁵, its derivative and its integral, τ clipped to [0, 1]."""
    t = np.clip(tau, 0.0, 1.0)
    t2 = t * t
    t3 = t2 * t
    s = t3 * (10.0 + t * (-15.0 + 6.0 * t))
    ds = 30.0 * t2 * (1.0 + t * (-2.0 + t))
    S = t2 * t2 * (2.5 + t * (-3.0 + t))       # ∫0^τ s = 2.5τ⁴ - 3τ⁵ + τ⁶ (S(1) = 1/2)
    return s, ds, S


@dataclass(frozen=True, eq=False)
class _Piece:
    """A span [t0, t1) of commanded motion belonging to one segment."""

    t0: float
    t1: float
    segment: int           # 0-based index into Profile.segments
    role: str              # transition | align | hold | ramp | rate | sine | csv

    @property
    def is_hold(self) -> bool:
        return False

    def eval(self, t_local):  # pragma: no cover - abstract
        raise NotImplementedError


@dataclass(frozen=True, eq=False)
class _JointMove(_Piece):
    """Minimum-jerk move of all gimbals from q_from to q_to (a hold when equal)."""

    _: KW_ONLY
    q_from: np.ndarray
    q_to: np.ndarray

    @property
    def is_hold(self) -> bool:
        return bool(np.all(self.q_from == self.q_to))

    def eval(self, t_local):
        n = t_local.shape[0]
        if self.is_hold:
            q = np.broadcast_to(self.q_to, (n, 3)).copy()
            return q, np.zeros((n, 3)), np.zeros((n, 3))
        T = self.t1 - self.t0
        s, ds, _ = _minjerk(t_local / T)
        dq = self.q_to - self.q_from
        q = self.q_from + s[:, None] * dq
        qd = (ds / T)[:, None] * dq
        return q, qd, body_rate(q, qd)


@dataclass(frozen=True, eq=False)
class _GimbalRamp(_Piece):
    """One gimbal only: body rate r0 -> r1 about ``axis`` (minimum jerk; r0 = r1: constant).

    The outer gimbal (``joint`` 0) for rates about the vertical; the middle
    or inner one (1, 2) for a tumble.
    """

    _: KW_ONLY
    q_base: np.ndarray
    axis: np.ndarray            # the commanded body axis a (ω = rate · a)
    sign: float = 1.0           # σ: σ a is the gimbal's axis, q̇_joint = σ rate
    r0: float = 0.0
    r1: float = 0.0
    level: int = -1             # index of the rate level for role 'rate'
    joint: int = 0              # 0 outer, 1 middle, 2 inner

    def eval(self, t_local):
        T = self.t1 - self.t0
        if self.r0 == self.r1:
            rate = np.full(t_local.shape, self.r0)
            angle = self.r0 * t_local
        else:
            s, _, S = _minjerk(t_local / T)
            rate = self.r0 + (self.r1 - self.r0) * s
            angle = self.r0 * t_local + (self.r1 - self.r0) * T * S
        return _outer_motion(self.q_base, self.sign, self.axis, rate, angle, self.joint)


@dataclass(frozen=True, eq=False)
class _OuterSine(_Piece):
    """Outer gimbal only: body rate A sin(2π f t + φ) about ``axis``."""

    _: KW_ONLY
    q_base: np.ndarray
    axis: np.ndarray
    sign: float = 1.0
    amplitude: float = 0.0
    frequency_hz: float = 0.0
    phase: float = 0.0

    def eval(self, t_local):
        w = _TWO_PI * self.frequency_hz
        arg = w * t_local + self.phase
        rate = self.amplitude * np.sin(arg)
        angle = self.amplitude / w * (math.cos(self.phase) - np.cos(arg))
        return _outer_motion(self.q_base, self.sign, self.axis, rate, angle)


def _outer_motion(q_base, sign, axis, rate, angle, joint=0):
    n = rate.shape[0]
    q = np.broadcast_to(q_base, (n, 3)).copy()
    q[:, joint] += sign * angle
    qd = np.zeros((n, 3))
    qd[:, joint] = sign * rate
    return q, qd, rate[:, None] * axis


@dataclass(frozen=True, eq=False)
class _CSVMotion(_Piece):
    """Gimbal angles integrated from commanded body rates (cubic Hermite between RK4 nodes)."""

    _: KW_ONLY
    t_nodes: np.ndarray
    q_nodes: np.ndarray
    qd_nodes: np.ndarray
    t_csv: np.ndarray
    w_csv: np.ndarray

    def eval(self, t_local):
        tn, qn, qdn = self.t_nodes, self.q_nodes, self.qd_nodes
        k = np.clip(np.searchsorted(tn, t_local, side="right") - 1, 0, tn.size - 2)
        h = (tn[k + 1] - tn[k])[:, None]
        u = ((t_local - tn[k]) / h[:, 0])[:, None]
        # cubic Hermite basis
        h00 = (1 + 2 * u) * (1 - u) ** 2
        h10 = u * (1 - u) ** 2
        h01 = u * u * (3 - 2 * u)
        h11 = u * u * (u - 1)
        q = h00 * qn[k] + h10 * h * qdn[k] + h01 * qn[k + 1] + h11 * h * qdn[k + 1]
        w = np.stack([np.interp(t_local, self.t_csv, self.w_csv[:, j]) for j in range(3)], axis=1)
        return q, joint_rates(q, w), w


@dataclass(frozen=True, eq=False)
class Command:
    """The commanded table motion on a time grid.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Times [s].
    q_rad : ndarray, shape (n, 3)
        Commanded gimbal angles (outer, middle, inner) [rad].
    qd_rad_s : ndarray, shape (n, 3)
        Commanded gimbal rates [rad/s].
    omega_body_rad_s : ndarray, shape (n, 3)
        Commanded platform angular velocity in the platform frame [rad/s].
    """

    time_s: np.ndarray
    q_rad: np.ndarray
    qd_rad_s: np.ndarray
    omega_body_rad_s: np.ndarray


def _show(v) -> list:
    """A vector for messages: 6 decimals, no negative zeros."""
    return (np.round(np.asarray(v, dtype=float), 6) + 0.0).tolist()


class _Builder:
    """Turns segments into pieces, keeping track of the gimbal angles."""

    def __init__(self, source: str | None):
        self.source = source
        self.q = np.zeros(3)
        self.t = 0.0
        self.pieces: list[_Piece] = []

    def fail(self, i: int, seg, key: str, message: str) -> NoReturn:
        raise InputError(f"segment {i + 1} ({seg.kind}): {message}", file=self.source,
                         column=f"segment[{i + 1}].{key}")

    def add(self, piece: _Piece):
        self.pieces.append(piece)
        self.t = piece.t1

    def move(self, i, role, q_to, T):
        self.add(_JointMove(self.t, self.t + T, i, role, q_from=self.q.copy(), q_to=np.array(q_to)))
        self.q = np.array(q_to, dtype=float)

    def orient(self, i, seg, orientation: Orientation, T: float, key: str, role="transition"):
        target = orientation.target(self.q)
        changes = np.max(np.abs(target - self.q)) > SAME_ORIENTATION_RAD
        if changes and T <= 0:
            self.fail(i, seg, key, f"the orientation changes (gimbals from "
                      f"{_show(rad_to_deg(self.q))} to {_show(rad_to_deg(target))} deg); give {key} > 0, "
                      "the time of the move")
        if T > 0:
            self.move(i, role, target if changes else self.q, T)

    def align(self, i, seg, axis) -> float:
        """Point ±axis up (the nearer sign); returns the sign σ."""
        a = np.asarray(axis)
        up = up_vector(self.q)
        sign = 1.0 if float(up @ a) >= 0 else -1.0
        aligned = np.linalg.norm(up - sign * a) <= 1e-9
        if not aligned:
            target = gimbal_for_up_axis(sign * a, self.q)
            if seg.align_s <= 0:
                self.fail(i, seg, "align_s",
                          f"the axis {_show(a)} does not point up at the start of "
                          f"the segment (up is {_show(up)} in the platform frame); "
                          "give align_s > 0, the time to re-orient the platform")
            self.move(i, "align", target, seg.align_s)
            # the target points σa up up to rounding; command ω = rate·a exactly anyway
        elif seg.align_s > 0:
            self.move(i, "align", self.q, seg.align_s)
        return sign

    def outer_ramp(self, i, role, a, sign, r0, r1, T, level=-1, joint=0):
        if T <= 0:
            return
        p = _GimbalRamp(self.t, self.t + T, i, role, q_base=self.q.copy(), axis=np.array(a),
                        sign=sign, r0=r0, r1=r1, level=level, joint=joint)
        self.add(p)
        _, _, S = _minjerk(np.array([1.0]))
        angle = r0 * T + (r1 - r0) * T * float(S[0]) if r0 != r1 else r0 * T
        step = np.zeros(3)
        step[joint] = sign * angle
        self.q = self.q + step

    def tumble(self, i, seg: "Tumble"):
        """Set the other gimbals, then turn the middle (x–z axis) or inner (±y) gimbal."""
        a = np.asarray(seg.axis)
        if abs(abs(a[1]) - 1.0) <= 1e-9:
            joint, sign = 2, float(np.sign(a[1]))            # J[:, 2] = e_y
            target = np.array([self.q[0], seg.tilt_rad, self.q[2]])
        elif abs(a[1]) <= 1e-9:
            if seg.tilt_rad != 0.0:
                self.fail(i, seg, "tilt_deg", "tilt_deg goes with a tumble about ±y; an axis in "
                          "the x–z plane turns the middle gimbal, whose axis is horizontal")
            joint, sign = 1, 1.0                             # J[:, 1] = (cos q_i, 0, sin q_i) = a
            target = np.array([self.q[0], self.q[1], _nearest(math.atan2(a[2], a[0]), self.q[2])])
        else:
            self.fail(i, seg, "axis", f"this table tumbles only about the platform y axis (inner "
                      f"gimbal) or an axis in the x–z plane (middle gimbal), not {_show(a)}")
        if np.max(np.abs(target - self.q)) > SAME_ORIENTATION_RAD:
            if seg.align_s <= 0:
                self.fail(i, seg, "align_s", f"the tumble starts from gimbals "
                          f"{_show(rad_to_deg(target))} deg, not the present "
                          f"{_show(rad_to_deg(self.q))} deg; give align_s > 0, the time to get there")
            self.move(i, "align", target, seg.align_s)
        elif seg.align_s > 0:
            self.move(i, "align", self.q, seg.align_s)
        r = seg.rate_rad_s
        self.outer_ramp(i, "ramp", seg.axis, sign, 0.0, r, seg.ramp_s, joint=joint)
        self.outer_ramp(i, "rate", seg.axis, sign, r, r, seg.duration_s, level=0, joint=joint)
        self.outer_ramp(i, "ramp", seg.axis, sign, r, 0.0, seg.ramp_s, joint=joint)

    def segment(self, i, seg):
        if isinstance(seg, Static):
            if seg.orientation is not None:
                self.orient(i, seg, seg.orientation, seg.transition_s, "transition_s")
            elif seg.transition_s > 0:
                self.fail(i, seg, "transition_s", "transition_s needs up_axis or gimbal_deg")
            self.move(i, "hold", self.q, seg.duration_s)
        elif isinstance(seg, MultiPosition):
            for o in seg.orientations:
                self.orient(i, seg, o, seg.transition_s, "transition_s")
                self.move(i, "hold", self.q, seg.hold_s)
        elif isinstance(seg, ConstantRate):
            sign = self.align(i, seg, seg.axis)
            r = seg.rate_rad_s
            self.outer_ramp(i, "ramp", seg.axis, sign, 0.0, r, seg.ramp_s)
            self.outer_ramp(i, "rate", seg.axis, sign, r, r, seg.duration_s, level=0)
            self.outer_ramp(i, "ramp", seg.axis, sign, r, 0.0, seg.ramp_s)
        elif isinstance(seg, RateSteps):
            sign = self.align(i, seg, seg.axis)
            prev = 0.0
            for k, (r, h) in enumerate(zip(seg.rates_rad_s, seg.hold_s)):
                self.outer_ramp(i, "ramp", seg.axis, sign, prev, r, seg.ramp_s)
                self.outer_ramp(i, "rate", seg.axis, sign, r, r, h, level=k)
                prev = r
            self.outer_ramp(i, "ramp", seg.axis, sign, prev, 0.0, seg.ramp_s)
        elif isinstance(seg, Sinusoid):
            sign = self.align(i, seg, seg.axis)
            p = _OuterSine(self.t, self.t + seg.duration_s, i, "sine", q_base=self.q.copy(),
                           axis=np.array(seg.axis), sign=sign, amplitude=seg.amplitude_rad_s,
                           frequency_hz=seg.frequency_hz, phase=seg.phase_rad)
            self.add(p)
            q_end, _, _ = p.eval(np.array([seg.duration_s]))
            self.q = q_end[0]
        elif isinstance(seg, Tumble):
            self.tumble(i, seg)
        elif isinstance(seg, RateCSV):
            self.csv(i, seg)
        else:  # pragma: no cover - guarded by Profile
            raise TypeError(f"not a segment: {seg!r}")

    def csv(self, i, seg: RateCSV):
        t_csv, w_csv = seg.time_s, seg.omega_rad_s
        _check_csv_steps(i, seg)
        # RK4 nodes: the CSV rows, subdivided so that no step exceeds CSV_MAX_STEP_S
        nodes = [np.array([0.0])]
        for a, b in zip(t_csv[:-1], t_csv[1:]):
            m = max(1, math.ceil((b - a) / CSV_MAX_STEP_S - 1e-9))
            nodes.append(a + (b - a) * np.arange(1, m + 1) / m)
        tn = np.concatenate(nodes)
        tn[-1] = t_csv[-1]
        wx, wy, wz = (np.interp(tn, t_csv, w_csv[:, j]) for j in range(3))
        qn = np.empty((tn.size, 3))
        qn[0] = self.q
        lock = math.sin(GIMBAL_LOCK_MARGIN_RAD)   # |cos q_m| must stay above this

        def f(q1, q2, q3, w0, w1, w2):
            # q̇ = J(q)⁻¹ ω (scalar closed form of joint_rates)
            c2, s2, c3, s3 = math.cos(q2), math.sin(q2), math.cos(q3), math.sin(q3)
            d1 = (c3 * w2 - s3 * w0) / c2
            return d1, c3 * w0 + s3 * w2, w1 - s2 * d1

        def refuse(t_at):
            row = int(np.searchsorted(t_csv, t_at, side="left"))
            raise InputError(
                f"segment {i + 1} (rate_csv): the commanded rates drive the middle gimbal to "
                f"within {rad_to_deg(GIMBAL_LOCK_MARGIN_RAD):g} deg of ±90 deg (gimbal lock) at "
                f"t = {t_at:.6g} s of the segment; this table cannot follow them from this "
                "orientation", file=seg.file, line=seg.line_of(row), column="time_s")

        q1, q2, q3 = (float(x) for x in self.q)
        if abs(math.cos(q2)) < lock:
            refuse(0.0)
        for k in range(tn.size - 1):
            h = tn[k + 1] - tn[k]
            wa = (wx[k], wy[k], wz[k])
            wb = (wx[k + 1], wy[k + 1], wz[k + 1])
            wm = tuple((x + y) / 2 for x, y in zip(wa, wb))   # ω is linear between rows
            k1 = f(q1, q2, q3, *wa)
            k2 = f(q1 + h / 2 * k1[0], q2 + h / 2 * k1[1], q3 + h / 2 * k1[2], *wm)
            k3 = f(q1 + h / 2 * k2[0], q2 + h / 2 * k2[1], q3 + h / 2 * k2[2], *wm)
            k4 = f(q1 + h * k3[0], q2 + h * k3[1], q3 + h * k3[2], *wb)
            q1 += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            q2 += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            q3 += h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
            if abs(math.cos(q2)) < lock:
                refuse(float(tn[k + 1]))
            qn[k + 1] = (q1, q2, q3)
        wn = np.stack([wx, wy, wz], axis=1)
        qdn = joint_rates(qn, wn)
        for a in (tn, qn, qdn):
            a.setflags(write=False)
        self.add(_CSVMotion(self.t, self.t + seg.duration_s, i, "csv", t_nodes=tn, q_nodes=qn,
                            qd_nodes=qdn, t_csv=t_csv, w_csv=w_csv))
        self.q = qn[-1].copy()


def _check_csv_steps(i: int, seg: RateCSV) -> None:
    """Refuse a ``rate_csv`` segment whose integration would take more than
    :data:`CSV_MAX_STEPS` RK4 steps (or more memory than the budget), before any is taken;
    the message names the CSV file, the row where the cap is passed and the span."""
    t = seg.time_s
    steps = np.maximum(1.0, np.ceil(np.diff(t) / CSV_MAX_STEP_S - 1e-9))
    total = float(steps.sum())
    if total > CSV_MAX_STEPS:
        row = int(np.searchsorted(np.cumsum(steps), CSV_MAX_STEPS, side="left")) + 1
        raise InputError(
            f"segment {i + 1} (rate_csv): the rates span {seg.duration_s:.6g} s in {t.size} rows, "
            f"{total:.3g} integration steps of at most {CSV_MAX_STEP_S:g} s; at most "
            f"{CSV_MAX_STEPS:.3g} are integrated (passed at t = {float(t[row]):.6g} s): cut the "
            "file to the span that is run (a scenario's duration_s reads only the rows it needs)",
            file=seg.file, line=seg.line_of(row), column="time_s")
    check_memory(total * _CSV_BYTES_PER_STEP,
                 f"integrating the {seg.duration_s:.6g} s of rate_csv segment {i + 1} "
                 f"({total:.3g} steps)", "cut the file to the span that is run",
                 file=seg.file, line=seg.line_of(t.size - 1), column="time_s")


def _csv_until(seg: RateCSV, until_s: float) -> RateCSV:
    """The first ``until_s`` of a ``rate_csv`` segment: the rows before it and one row at it
    (rates linear between rows, so the kept part is the same motion)."""
    t, w = seg.time_s, seg.omega_rad_s
    j = int(np.searchsorted(t, until_s, side="left"))      # t[j-1] < until_s <= t[j]
    if j < 1:
        j = 1
    t_end = max(float(until_s), float(t[j - 1]) + CSV_MAX_STEP_S * 1e-6)
    w_end = [np.interp(t_end, t, w[:, k]) for k in range(3)]
    lines = None if seg.line_numbers is None else tuple(seg.line_numbers[:j]) + (seg.line_of(j),)
    return RateCSV(time_s=np.append(t[:j], t_end), omega_rad_s=np.vstack([w[:j], w_end]),
                   file=seg.file, line_numbers=lines, label=seg.label)


# =============================================================================
# Profile
# =============================================================================

def _canonical(obj) -> str:
    """A deterministic text of segment data (floats exact) for fingerprints."""
    if isinstance(obj, float):
        return float(obj).hex()
    if isinstance(obj, (int, str, bool)) or obj is None:
        return repr(obj)
    if isinstance(obj, np.ndarray):
        return "nd:" + hashlib.sha256(np.ascontiguousarray(obj, dtype=float).tobytes()).hexdigest()
    if isinstance(obj, (tuple, list)):
        return "(" + ",".join(_canonical(x) for x in obj) + ")"
    if hasattr(obj, "__dataclass_fields__"):
        return (type(obj).__name__ + "{" +
                ",".join(f"{f.name}={_canonical(getattr(obj, f.name))}" for f in fields(obj)) + "}")
    raise TypeError(f"cannot fingerprint {type(obj).__name__}")


@dataclass(frozen=True, eq=False)
class Profile:
    """A motion profile: segments run in order from the level table at rest.

    Parameters
    ----------
    segments : tuple of segment
        :class:`Static`, :class:`MultiPosition`, :class:`ConstantRate`,
        :class:`RateSteps`, :class:`Sinusoid`, :class:`Tumble` or :class:`RateCSV`.
    description : str
    source : str, optional
        The file it was read from (for messages).
    fingerprint : str, optional
        Content hash (hex). :func:`load_profile` hashes the bytes of the TOML
        file and of every CSV it reads; otherwise the segment values are hashed.
    until_s : float, optional
        Only what the first ``until_s`` seconds need [s]: a ``rate_csv``
        segment running past it is cut there (its later rows are never
        integrated) and the segments after it are left out; the profile then
        lasts ``until_s`` and its fingerprint says so. Other profiles are
        unchanged.

    Raises
    ------
    InputError
        When the segments cannot be run (e.g. an orientation change without a
        transition time, a rate_csv that reaches gimbal lock).
    """

    segments: tuple
    description: str = ""
    source: str | None = None
    fingerprint: str = ""
    until_s: float | None = None
    _pieces: tuple = field(default=(), init=False, repr=False)

    def __post_init__(self):
        segs = tuple(self.segments)
        if not segs:
            raise InputError("a profile needs at least one [[segment]]", file=self.source,
                             column="segment")
        for s in segs:
            if not isinstance(s, _SEGMENT_TYPES):
                raise InputError(f"not a profile segment: {s!r}", file=self.source)
        object.__setattr__(self, "segments", segs)
        if not self.fingerprint:
            text = _canonical(segs) + "|" + self.description
            object.__setattr__(self, "fingerprint", hashlib.sha256(text.encode()).hexdigest())
        b = _Builder(self.source)
        for i, s in enumerate(segs):
            if (self.until_s is not None and isinstance(s, RateCSV)
                    and b.t + s.duration_s > self.until_s + 1e-9):
                # the rest is never run: not integrated
                if b.t < self.until_s - 1e-9:
                    s = _csv_until(s, self.until_s - b.t)
                    b.segment(i, s)
                    segs = segs[:i] + (s,)
                else:
                    segs = segs[:i]
                object.__setattr__(self, "segments", segs)
                object.__setattr__(self, "fingerprint", hashlib.sha256(
                    f"{self.fingerprint}|until {float(self.until_s).hex()}".encode()).hexdigest())
                break
            b.segment(i, s)
        object.__setattr__(self, "_pieces", tuple(b.pieces))

    # -- queries -------------------------------------------------------------
    @property
    def duration_s(self) -> float:
        """Total duration [s]."""
        return float(self._pieces[-1].t1)

    @property
    def pieces(self) -> tuple:
        """The commanded pieces (internal representation, read-only)."""
        return self._pieces

    def segment_span(self, index: int) -> tuple[float, float]:
        """Start and end time of segment ``index`` (0-based) [s]."""
        ps = [p for p in self._pieces if p.segment == index]
        return ps[0].t0, ps[-1].t1

    def command(self, time_s) -> Command:
        """The commanded gimbal trajectory and body rate at ``time_s``.

        Parameters
        ----------
        time_s : array_like, shape (n,)
            Times in [0, duration_s] [s].

        Returns
        -------
        Command
        """
        t = np.atleast_1d(np.asarray(time_s, dtype=float))
        if t.size and (t.min() < 0 or t.max() > self.duration_s * (1 + 1e-12)):
            raise ValueError(f"times must lie in [0, {self.duration_s}] s")
        starts = np.array([p.t0 for p in self._pieces])
        which = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self._pieces) - 1)
        q = np.empty((t.size, 3))
        qd = np.empty((t.size, 3))
        w = np.empty((t.size, 3))
        for k in np.unique(which):
            m = which == k
            p = self._pieces[k]
            q[m], qd[m], w[m] = p.eval(t[m] - p.t0)
        return Command(t, q, qd, w)

    def hold_spans(self) -> list[tuple[float, float]]:
        """Spans of constant command (holds) [s]: where the table can rest."""
        return [(p.t0, p.t1) for p in self._pieces if p.is_hold]


# =============================================================================
# Reading files
# =============================================================================

_TOP_KEYS = ("description", "segment")
_KEYS = {
    Static.kind: ("kind", "label", "duration_s", "up_axis", "gimbal_deg", "transition_s"),
    MultiPosition.kind: ("kind", "label", "up_axes", "gimbal_deg", "hold_s", "transition_s"),
    ConstantRate.kind: ("kind", "label", "axis", "rate_deg_s", "duration_s", "ramp_s", "align_s"),
    RateSteps.kind: ("kind", "label", "axis", "rates_deg_s", "hold_s", "ramp_s", "align_s"),
    Sinusoid.kind: ("kind", "label", "axis", "amplitude_deg_s", "frequency_hz", "duration_s",
                    "phase_deg", "align_s"),
    Tumble.kind: ("kind", "label", "axis", "rate_deg_s", "duration_s", "ramp_s", "tilt_deg",
                  "align_s"),
    RateCSV.kind: ("kind", "label", "file"),
}
_CSV_COLUMNS = ("time_s", "wx_deg_s", "wy_deg_s", "wz_deg_s")


def _key_line(text: str, seg: int | None, key: str) -> int | None:
    """1-based line of ``key`` in the ``seg``-th [[segment]] (None: top level), if plain TOML.

    A key missing from its segment gives the line of the segment's header.
    """
    header = re.compile(r"^\s*\[\[\s*segment\s*\]\]")
    table = re.compile(r"^\s*\[")
    keyre = re.compile(r"^\s*\"?" + re.escape(key) + r"\"?\s*=")
    count, where, start = 0, 0, None   # where: 0 top level, k the k-th segment, -1 another table
    for n, line in enumerate(text.splitlines(), start=1):
        if header.match(line):
            count += 1
            where = count
            if count == seg:
                start = n
        elif table.match(line):
            where = -1
        elif where == (0 if seg is None else seg) and keyre.match(line):
            return n
    return start      # a missing key: the line of its [[segment]] header


class _Reader:
    """Typed access to one [[segment]] table, with located errors."""

    def __init__(self, table: dict, index: int, kind: str, file: str, text: str):
        self.t, self.i, self.kind, self.file, self.text = table, index, kind, file, text

    def fail(self, key: str, message: str) -> NoReturn:
        raise InputError(f"segment {self.i} ({self.kind}): {message}", file=self.file,
                         line=_key_line(self.text, self.i, key),
                         column=f"segment[{self.i}].{key}")

    def has(self, key):
        return key in self.t

    def number(self, key, *, default=None, minimum=None, strict=False):
        if key not in self.t:
            if default is None:
                self.fail(key, f"missing key {key}")
            return default
        v = self.t[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(key, f"{key} must be a number, got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            self.fail(key, f"{key} must be finite, got {v!r}")
        if minimum is not None and (v < minimum or (strict and v == minimum)):
            self.fail(key, f"{key} must be {'>' if strict else '>='} {minimum:g}, got {v:g}")
        return v

    def numbers(self, key, *, length=None, minimum=None, strict=False):
        v = self.t.get(key)
        if v is None:
            self.fail(key, f"missing key {key}")
        if not isinstance(v, list) or not v:
            self.fail(key, f"{key} must be a non-empty list of numbers, got {v!r}")
        if length is not None and len(v) != length:
            self.fail(key, f"{key} must have {length} numbers, got {len(v)}")
        out = []
        for x in v:
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                self.fail(key, f"{key} must hold finite numbers, got {x!r}")
            if minimum is not None and (x < minimum or (strict and x == minimum)):
                self.fail(key, f"{key} values must be {'>' if strict else '>='} {minimum:g}, got {x:g}")
            out.append(float(x))
        return out

    def axis(self, key, value=None):
        v = self.numbers(key, length=3) if value is None else value
        a = np.array(v)
        n = float(np.linalg.norm(a))
        if n == 0:
            self.fail(key, f"{key} is the zero vector")
        if abs(n - 1.0) > AXIS_NORM_TOL:
            self.fail(key, f"{key} {v} is not a unit vector (norm {n:.6g}, allowed "
                      f"1 ± {AXIS_NORM_TOL:g}); give a unit vector")
        return tuple(a / n)

    def rows(self, key):
        v = self.t.get(key)
        if not isinstance(v, list) or not v or not all(isinstance(r, list) for r in v):
            self.fail(key, f"{key} must be a non-empty list of [x, y, z] rows, got {v!r}")
        out = []
        for r in v:
            if len(r) != 3 or any(isinstance(x, bool) or not isinstance(x, (int, float))
                                  or not math.isfinite(x) for x in r):
                self.fail(key, f"{key} rows must be 3 finite numbers, got {r!r}")
            out.append([float(x) for x in r])
        return out

    def orientation(self, up_key, gimbal_key, *, many: bool):
        has_up, has_g = up_key in self.t, gimbal_key in self.t
        if has_up and has_g:
            self.fail(gimbal_key, f"give either {up_key} or {gimbal_key}, not both")
        if not has_up and not has_g:
            return None
        if many:
            if has_up:
                return tuple(Orientation(up_axis=self.axis(up_key, r)) for r in self.rows(up_key))
            return tuple(Orientation(gimbal_rad=tuple(deg_to_rad(x) for x in r))
                         for r in self.rows(gimbal_key))
        if has_up:
            return Orientation(up_axis=self.axis(up_key))
        return Orientation(gimbal_rad=tuple(deg_to_rad(x) for x in self.numbers(gimbal_key, length=3)))

    def label(self):
        v = self.t.get("label", "")
        if not isinstance(v, str):
            self.fail("label", f"label must be a string, got {v!r}")
        return v


def _segment_from_table(r: _Reader, base_dir: Path, csv_bytes: list):
    k = r.kind
    if k == Static.kind:
        o = r.orientation("up_axis", "gimbal_deg", many=False)
        return Static(duration_s=r.number("duration_s", minimum=0, strict=True), orientation=o,
                      transition_s=r.number("transition_s", default=0.0, minimum=0),
                      label=r.label())
    if k == MultiPosition.kind:
        o = r.orientation("up_axes", "gimbal_deg", many=True)
        if o is None:
            r.fail("up_axes", "missing key up_axes (or gimbal_deg)")
        return MultiPosition(orientations=o, hold_s=r.number("hold_s", minimum=0, strict=True),
                             transition_s=r.number("transition_s", minimum=0, strict=True),
                             label=r.label())
    if k == ConstantRate.kind:
        return ConstantRate(axis=r.axis("axis"), rate_rad_s=deg_s_to_rad_s(r.number("rate_deg_s")),
                            duration_s=r.number("duration_s", minimum=0, strict=True),
                            ramp_s=r.number("ramp_s", minimum=0),
                            align_s=r.number("align_s", default=0.0, minimum=0), label=r.label())
    if k == RateSteps.kind:
        rates = r.numbers("rates_deg_s")
        if isinstance(r.t.get("hold_s"), list):
            holds = r.numbers("hold_s", minimum=0, strict=True)
            if len(holds) != len(rates):
                r.fail("hold_s", f"hold_s has {len(holds)} values for {len(rates)} rates")
        else:
            holds = [r.number("hold_s", minimum=0, strict=True)] * len(rates)
        return RateSteps(axis=r.axis("axis"), rates_rad_s=tuple(deg_s_to_rad_s(x) for x in rates),
                         hold_s=tuple(holds), ramp_s=r.number("ramp_s", minimum=0),
                         align_s=r.number("align_s", default=0.0, minimum=0), label=r.label())
    if k == Sinusoid.kind:
        return Sinusoid(axis=r.axis("axis"),
                        amplitude_rad_s=deg_s_to_rad_s(r.number("amplitude_deg_s", minimum=0,
                                                                strict=True)),
                        frequency_hz=r.number("frequency_hz", minimum=0, strict=True),
                        duration_s=r.number("duration_s", minimum=0, strict=True),
                        phase_rad=deg_to_rad(r.number("phase_deg", default=0.0)),
                        align_s=r.number("align_s", default=0.0, minimum=0), label=r.label())
    if k == Tumble.kind:
        tilt = r.number("tilt_deg", default=0.0)
        if abs(tilt) > 90.0:
            r.fail("tilt_deg", f"tilt_deg must be within ±90 deg, got {tilt:g}")
        return Tumble(axis=r.axis("axis"), rate_rad_s=deg_s_to_rad_s(r.number("rate_deg_s")),
                      duration_s=r.number("duration_s", minimum=0, strict=True),
                      ramp_s=r.number("ramp_s", minimum=0), tilt_rad=deg_to_rad(tilt),
                      align_s=r.number("align_s", default=0.0, minimum=0), label=r.label())
    if k == RateCSV.kind:
        name = r.t.get("file")
        if not isinstance(name, str) or not name:
            r.fail("file", f"file must be the path of a CSV file, got {name!r}")
        path = base_dir / name
        try:
            data = read_regular(path, "rate CSV file")
        except InputError as e:
            r.fail("file", f"CSV file {str(path)!r}: {e.message}")
        csv_bytes.append((name, data))
        t, w, lines = _parse_rate_csv(data, str(path))
        return RateCSV(time_s=t, omega_rad_s=w, file=str(path), line_numbers=tuple(lines),
                       label=r.label())
    raise AssertionError(k)  # pragma: no cover


def _parse_rate_csv(data: bytes, file: str):
    """Rows of a rate CSV: time [s], body rates [rad/s], file lines."""
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"not UTF-8 text ({e.reason})", file=file) from None
    header: list[str] | None = None
    cols: list[int] = []
    times: list[float] = []
    rates: list[list[float]] = []
    lines: list[int] = []
    for n, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if header is None:
            header = cells
            unknown = [c for c in cells if c not in _CSV_COLUMNS]
            if unknown:
                raise InputError(f"unknown column {unknown[0]!r}; the columns are "
                                 f"{', '.join(_CSV_COLUMNS)}", file=file, line=n, column=unknown[0])
            for c in _CSV_COLUMNS:
                if cells.count(c) != 1:
                    what = "missing" if c not in cells else "repeated"
                    raise InputError(f"column {c!r} is {what}", file=file, line=n, column=c)
            cols = [cells.index(c) for c in _CSV_COLUMNS]
            continue
        if len(cells) != len(header):
            raise InputError(f"row has {len(cells)} cells, the header has {len(header)}",
                             file=file, line=n)
        vals = []
        for name, j in zip(_CSV_COLUMNS, cols):
            try:
                v = float(cells[j])
            except ValueError:
                raise InputError(f"not a number: {cells[j]!r}", file=file, line=n,
                                 column=name) from None
            if not math.isfinite(v):
                raise InputError(f"not a finite number: {cells[j]!r}", file=file, line=n,
                                 column=name)
            vals.append(v)
        if not times and vals[0] != 0.0:
            raise InputError(f"time_s must start at 0, got {cells[cols[0]]}", file=file, line=n,
                             column="time_s")
        if times and vals[0] <= times[-1]:
            raise InputError(f"time_s must increase strictly ({vals[0]:g} after {times[-1]:g})",
                             file=file, line=n, column="time_s")
        times.append(vals[0])
        rates.append(vals[1:])
        lines.append(n)
    if header is None:
        raise InputError("empty CSV: no header row", file=file)
    if len(times) < 2:
        raise InputError("a rate CSV needs at least 2 rows", file=file)
    return np.array(times), deg_s_to_rad_s(np.array(rates)), lines


def read_rate_csv(path) -> RateCSV:
    """Read a CSV of commanded body rates (columns time_s, wx_deg_s, wy_deg_s, wz_deg_s).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    RateCSV
    """
    p = Path(path)
    data = read_regular(p, "rate CSV file")
    t, w, lines = _parse_rate_csv(data, str(p))
    return RateCSV(time_s=t, omega_rad_s=w, file=str(p), line_numbers=tuple(lines))


def load_profile(path, until_s: float | None = None) -> Profile:
    """Read a motion profile from a TOML file (see the module docstring for the format).

    Parameters
    ----------
    path : str or Path
        The TOML file; ``rate_csv`` files are relative to its folder.
    until_s : float, optional
        Build only what the first ``until_s`` seconds need [s] (see
        :class:`Profile`): a scenario's ``duration_s``.

    Returns
    -------
    Profile
        Its fingerprint hashes the TOML bytes and every CSV's bytes.

    Raises
    ------
    InputError
        For any problem, naming the file, the key and (where found) the line.
    """
    p = Path(path)
    file = str(path)
    loaded = load_toml(p, "profile")
    raw, text, doc = loaded.raw, loaded.text, loaded.data
    for key in doc:
        if key not in _TOP_KEYS:
            raise InputError(f"unknown key {key!r}; allowed at the top: {', '.join(_TOP_KEYS)}",
                             file=file, line=_key_line(text, None, key), column=key)
    desc = doc.get("description", "")
    if not isinstance(desc, str):
        raise InputError("description must be a string", file=file, column="description")
    tables = doc.get("segment")
    if tables is None:
        raise InputError("no [[segment]] tables: a profile needs at least one", file=file,
                         column="segment")
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise InputError("segment must be an array of tables ([[segment]])", file=file,
                         column="segment")
    segments: list = []
    csv_bytes: list[tuple[str, bytes]] = []
    for i, table in enumerate(tables, start=1):
        kind = table.get("kind")
        if kind is None:
            raise InputError(f"segment {i}: missing key kind (one of {', '.join(_KEYS)})",
                             file=file, line=_key_line(text, i, "kind"), column=f"segment[{i}].kind")
        if kind not in _KEYS:
            raise InputError(f"segment {i}: unknown kind {kind!r} (one of {', '.join(_KEYS)})",
                             file=file, line=_key_line(text, i, "kind"),
                             column=f"segment[{i}].kind")
        r = _Reader(table, i, kind, file, text)
        for key in table:
            if key not in _KEYS[kind]:
                r.fail(key, f"unknown key {key!r} for kind {kind}; allowed: "
                       f"{', '.join(_KEYS[kind][1:])}")
        segments.append(_segment_from_table(r, p.parent, csv_bytes))
    h = hashlib.sha256(b"gyroarray-profile\0" + raw)
    for name, data in csv_bytes:
        h.update(b"\0csv\0" + name.encode() + b"\0" + data)
    try:
        return Profile(segments=tuple(segments), description=desc, source=file,
                       fingerprint=h.hexdigest(), until_s=until_s)
    except InputError as e:
        if e.line is None and e.file == file and isinstance(e.column, str):
            m = re.fullmatch(r"segment\[(\d+)\]\.(\w+)", e.column)
            if m:
                raise InputError(e.message, file=file, line=_key_line(text, int(m.group(1)), m.group(2)),
                                 column=e.column) from None
        raise
