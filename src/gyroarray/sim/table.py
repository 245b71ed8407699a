"""A 3-axis rate table in MuJoCo: the gimbals, their servos, the sensors, the run.

The table (:class:`RateTable`) is an outer gimbal about the local vertical, a
middle gimbal and an inner gimbal carrying the platform (hinge joints, axes
z, x, y; at zero angles the platform frame is the local-level frame; see
:mod:`gyroarray.sim.profiles` for the kinematics). All centres of mass lie on
the intersection of the axes, so gravity exerts no torque. The MJCF model is
generated; given a :class:`gyroarray.core.layout.Layout` the platform carries one
site per gyro, at the gyro's position (``layout.positions_m``, zero when not
given), whose z axis is the gyro's sensitive axis, with one MuJoCo ``gyro``
sensor each, and beside it a site aligned with the platform frame with one
MuJoCo ``accelerometer`` (the specific force at the gyro, platform frame).
The truth model always has, on a site at the platform origin aligned with the
platform frame, a reference 3-axis gyro (ω_body), an ``accelerometer`` (the
specific force f_0 at the origin), a ``frameangacc`` (angular acceleration)
and a ``framequat`` (attitude), and joint encoders (``jointpos``,
``jointvel``).

Specific force. Gravity is the spec's g0 = 9.80665 m/s² along −z of the
world (the local-level frame); an accelerometer reads a − g, so at rest,
level, z up, f_0 = [0, 0, +g0]. The platform origin is the intersection of
the gimbal axes and never moves, so f_0 = Rᵀ [0, 0, g0] and a point r of the
platform reads f = f_0 + α × r + ω × (ω × r), all in the platform frame,
with α = dω/dt the angular acceleration (the body-frame derivative of ω_body
equals Rᵀ of the world-frame one). MuJoCo's accelerometers and
``frameangacc`` are computed in the same forward pass as the gyros, from the
same state, so the site readings satisfy that identity to rounding (tests).
The acceleration is the *realised* one: ``implicitfast`` advances the
velocity by dt·(M + dt·D)⁻¹ f (D the servo and bearing damping), while the
acceleration sensors of MuJoCo's own forward pass see M⁻¹ f, 18 % larger
in a 20 Hz servo loop stepped at 1 kHz. So after the run the acceleration
sensors of each sample are evaluated again by MuJoCo
(``mj_rnePostConstraint``, ``mj_sensorAcc``) with qacc = (q̇_{j+1} − q̇_j)/dt,
the acceleration the integrator applied over the step that starts at the
sample. MuJoCo's world does not rotate: the Earth's rate is left out of the
centripetal term (|Ω_E|² r < 3e-10 m/s² at 5 cm).

The servo of each gimbal is PD on the commanded angle and rate plus a
viscous-friction feedforward, three MuJoCo actuators per joint::

    τ = kp (q_c - q) + kv (q̇_c - q̇) + c q̇_c          (position, velocity, motor)

With joint damping ``c`` and the inertia ``I`` seen by the joint, the error
``e = q_c - q`` obeys ``I ë + (kv + c) ė + kp e = I q̈_c``: no steady error
at constant rate, and a closed loop ``(kp + (kv + c) s) / (I s² + (kv + c) s + kp)``
from commanded to realised angle (and rate). Gains place that loop at a
natural frequency ``bandwidth_hz`` and damping ratio ``damping_ratio`` for the
nominal inertia of each joint (the diagonal of the mass matrix at zero
angles): ``kp = I ωn²``, ``kv = 2 ζ I ωn - c``.

There is no acceleration feedforward, so a swing at frequency f is realised
with an amplitude ratio ≈ 1 + (f / bandwidth_hz)² (1.0007 at 0.5 Hz for
20 Hz): a real, reported table error (:class:`Tracking`), part of the truth.

Physics runs with MuJoCo's ``implicitfast`` integrator at
``dt = 1 / (k fs)``, the smallest integer ``k`` giving at least
``min_physics_rate_hz``, so each reading falls on a physics step. The
sensors of step j see the state at ``t_j = j dt``; the control applied
during step j is the command at ``t_j + dt/2`` (a half-step preview that
cancels the half-step delay of the semi-implicit Euler update, which would
otherwise lag the table by ``π f dt`` rad: 0.09° at 0.5 Hz). Long runs
use :func:`mujoco.rollout.rollout` (the step loop in C) in chunks; a hold
whose state has become a bitwise fixed point of the step map is not stepped
further but repeated — exactly what stepping would give.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import ClassVar

import mujoco
import numpy as np
from mujoco import rollout as _rollout

from gyroarray.core.errors import InputError
from gyroarray.core.constants import G0_M_S2
from gyroarray.core.units import rad_s_to_deg_s, rad_to_deg

from gyroarray.sim.profiles import Profile, gimbal_quaternion, load_profile

__all__ = ["TableParams", "RateTable", "TableRun", "Tracking", "SegmentTracking", "rotation_matrices",
           "tracking_report", "steps_per_sample", "n_samples"]

JOINTS = ("outer", "middle", "inner")
#: Physics steps per rollout call (memory: ~ CHUNK × 20 doubles).
CHUNK_STEPS = 20_000
#: Steps per rollout call inside a hold, to detect the rest state early.
HOLD_PROBE_STEPS = 1_000

# sensor layout of every table model (gyro sites follow: N gyros, then N accelerometers)
_S_GYRO, _S_QUAT, _S_ENC, _S_RATE = slice(0, 3), slice(3, 7), slice(7, 10), slice(10, 13)
_S_ACC, _S_ANGACC, _S_SITES = slice(13, 16), slice(16, 19), 19


@dataclass(frozen=True)
class TableParams:
    """Mechanics and servo of the rate table.

    Parameters
    ----------
    outer_inertia_kg_m2, middle_inertia_kg_m2, inner_inertia_kg_m2 : tuple of 3 float
        Principal moments of each gimbal (the inner one with the platform) about
        its own x, y, z axes at zero angles [kg·m²].
    masses_kg : tuple of 3 float
        Masses of the outer, middle, inner gimbal [kg] (no effect: balanced).
    damping_n_m_s : tuple of 3 float
        Viscous friction of the outer, middle, inner bearing [N·m·s/rad].
    bandwidth_hz : float
        Natural frequency of each position loop [Hz].
    damping_ratio : float
        Damping ratio of each position loop [-].
    min_physics_rate_hz : float
        Lowest physics rate [Hz]; the step is ``1/(k fs)`` with integer k.

    Attributes
    ----------
    max_rate_deg_s : float
        Fastest gimbal rate the table is commanded to [deg/s] (a scenario
        asking for more is refused when it loads).
    max_accel_deg_s2 : float
        Largest gimbal acceleration commanded [deg/s²].
    """

    max_rate_deg_s: ClassVar[float] = 1000.0
    max_accel_deg_s2: ClassVar[float] = 10000.0

    outer_inertia_kg_m2: tuple = (1.2, 1.2, 2.0)
    middle_inertia_kg_m2: tuple = (0.5, 0.35, 0.5)
    inner_inertia_kg_m2: tuple = (0.08, 0.10, 0.12)
    masses_kg: tuple = (40.0, 15.0, 5.0)
    damping_n_m_s: tuple = (0.8, 0.3, 0.05)
    bandwidth_hz: float = 20.0
    damping_ratio: float = 0.7
    min_physics_rate_hz: float = 1000.0

    def __post_init__(self):
        for name in ("outer_inertia_kg_m2", "middle_inertia_kg_m2", "inner_inertia_kg_m2",
                     "masses_kg", "damping_n_m_s"):
            v = tuple(float(x) for x in getattr(self, name))
            if len(v) != 3 or not all(math.isfinite(x) and x >= 0 for x in v):
                raise InputError(f"{name} must be 3 finite numbers >= 0, got {v!r}")
            object.__setattr__(self, name, v)
        for name in ("outer_inertia_kg_m2", "middle_inertia_kg_m2", "inner_inertia_kg_m2",
                     "masses_kg"):
            if min(getattr(self, name)) <= 0:
                raise InputError(f"{name} must be > 0")
        for name in ("bandwidth_hz", "damping_ratio", "min_physics_rate_hz"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be > 0, got {v!r}")
            object.__setattr__(self, name, v)

    @property
    def nominal_inertia_kg_m2(self) -> np.ndarray:
        """Inertia seen by each joint at zero angles (mass-matrix diagonal) [kg·m²]."""
        o, m, i = self.outer_inertia_kg_m2, self.middle_inertia_kg_m2, self.inner_inertia_kg_m2
        return np.array([o[2] + m[2] + i[2], m[0] + i[0], i[1]])

    @property
    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """Servo gains ``kp`` [N·m/rad] and ``kv`` [N·m·s/rad] per joint."""
        wn = 2 * math.pi * self.bandwidth_hz
        inertia = self.nominal_inertia_kg_m2
        kp = inertia * wn ** 2
        kv = 2 * self.damping_ratio * inertia * wn - np.array(self.damping_n_m_s)
        if np.any(kv <= 0):
            raise InputError("bearing damping exceeds the servo damping: raise bandwidth_hz "
                             "or damping_ratio")
        return kp, kv

    @property
    def settle_s(self) -> float:
        """Time for servo transients to decay by e⁻²⁰, ``20 / (ζ ωn)`` [s]."""
        return 20.0 / (self.damping_ratio * 2 * math.pi * self.bandwidth_hz)


def steps_per_sample(sample_rate_hz: float, min_physics_rate_hz: float) -> int:
    """Smallest integer k with ``k · fs >= min_physics_rate_hz`` [-]."""
    fs = float(sample_rate_hz)
    if not (math.isfinite(fs) and fs > 0):
        raise InputError(f"sample rate must be > 0 Hz, got {sample_rate_hz!r}")
    return max(1, math.ceil(min_physics_rate_hz / fs - 1e-9))


def n_samples(duration_s: float, sample_rate_hz: float) -> int:
    """Number of samples ``k/fs`` in [0, duration) [-]."""
    x = duration_s * sample_rate_hz
    return max(1, math.ceil(round(x, 9)))


# =============================================================================
# Tracking report
# =============================================================================

@dataclass(frozen=True)
class SegmentTracking:
    """How well the table followed one profile segment.

    Parameters
    ----------
    index : int
        Segment number, from 1 as in the file.
    kind, label : str
    start_s, end_s : float
        Span of the segment in the run [s] (clipped to the run).
    rms_error_rad_s, max_error_rad_s : float
        RMS and largest norm of realised minus commanded body rate [rad/s].
    steady_rate_error_rad_s : tuple of float
        Constant-rate levels: mean realised rate about the axis minus the
        commanded rate, after the servo settled [rad/s].
    steady_cross_axis_rad_s : tuple of float
        Constant-rate levels: largest realised rate across the axis after
        settling [rad/s] (gimbals deflected by gyroscopic torques when the
        platform's inertia is not symmetric about the spin axis).
    amplitude_ratio : float or None
        Sinusoids: realised / commanded amplitude about the axis at the swing
        frequency (least-squares sine fit after settling) [-].
    phase_lag_rad : float or None
        Sinusoids: commanded minus realised phase [rad] (> 0: realised lags).
    hold_attitude_error_rad : float or None
        Holds: largest angle between realised and commanded attitude after
        settling [rad].
    """

    index: int
    kind: str
    label: str
    start_s: float
    end_s: float
    rms_error_rad_s: float
    max_error_rad_s: float
    steady_rate_error_rad_s: tuple = ()
    steady_cross_axis_rad_s: tuple = ()
    amplitude_ratio: float | None = None
    phase_lag_rad: float | None = None
    hold_attitude_error_rad: float | None = None


@dataclass(frozen=True)
class Tracking:
    """Realised vs commanded motion over a run.

    Parameters
    ----------
    rms_error_rad_s, max_error_rad_s : float
        Over the whole run [rad/s].
    settle_s : float
        Servo settling time excluded from steady-state windows [s].
    segments : tuple of SegmentTracking
    """

    rms_error_rad_s: float
    max_error_rad_s: float
    settle_s: float
    segments: tuple = ()

    def to_dict(self) -> dict:
        """Plain data (for JSON)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "Tracking":
        """Inverse of :meth:`to_dict`."""
        segs = tuple(SegmentTracking(**{**s,
                                        "steady_rate_error_rad_s": tuple(s["steady_rate_error_rad_s"]),
                                        "steady_cross_axis_rad_s": tuple(s["steady_cross_axis_rad_s"])})
                     for s in d["segments"])
        return cls(rms_error_rad_s=d["rms_error_rad_s"], max_error_rad_s=d["max_error_rad_s"],
                   settle_s=d["settle_s"], segments=segs)

    def table(self) -> str:
        """A text table in datasheet units (deg/s, deg)."""
        rows = [f"{'seg':>3} {'kind':<15} {'label':<14} {'rms err':>10} {'max err':>10} "
                f"{'steady err':>11} {'cross-axis':>11} {'amp ratio':>12} {'lag':>10} {'hold att':>10}",
                f"{'':>3} {'':<15} {'':<14} {'[deg/s]':>10} {'[deg/s]':>10} {'[deg/s]':>11} "
                f"{'[deg/s]':>11} {'[-]':>12} {'[deg]':>10} {'[deg]':>10}"]
        for s in self.segments:
            steady = (f"{rad_s_to_deg_s(max(s.steady_rate_error_rad_s, key=abs)):11.3e}"
                      if s.steady_rate_error_rad_s else f"{'-':>11}")
            cross = (f"{rad_s_to_deg_s(max(s.steady_cross_axis_rad_s)):11.3e}"
                     if s.steady_cross_axis_rad_s else f"{'-':>11}")
            amp = f"{s.amplitude_ratio:12.9f}" if s.amplitude_ratio is not None else f"{'-':>12}"
            lag = f"{rad_to_deg(s.phase_lag_rad):10.2e}" if s.phase_lag_rad is not None else f"{'-':>10}"
            att = (f"{rad_to_deg(s.hold_attitude_error_rad):10.2e}"
                   if s.hold_attitude_error_rad is not None else f"{'-':>10}")
            rows.append(f"{s.index:>3} {s.kind:<15} {s.label[:14]:<14} "
                        f"{rad_s_to_deg_s(s.rms_error_rad_s):10.3e} "
                        f"{rad_s_to_deg_s(s.max_error_rad_s):10.3e} {steady} {cross} {amp} {lag} {att}")
        rows.append(f"all: rms {rad_s_to_deg_s(self.rms_error_rad_s):.3e} deg/s, "
                    f"max {rad_s_to_deg_s(self.max_error_rad_s):.3e} deg/s")
        return "\n".join(rows)


def _sine_fit(t, y, f_hz):
    """Least squares y ≈ a sin(2πft) + b cos(2πft) + c: amplitude, phase of A sin(2πft + φ)."""
    w = 2 * math.pi * f_hz
    X = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    (a, b, _), *_ = np.linalg.lstsq(X, y, rcond=None)
    return math.hypot(a, b), math.atan2(b, a)


def _angle_between(qa, qb):
    """Rotation angle between unit quaternions (rows, w x y z) [rad], accurate near 0."""
    wa, va = qa[..., :1], qa[..., 1:]
    wb, vb = qb[..., :1], qb[..., 1:]
    # qa* ⊗ qb = (wa wb + va·vb, wa vb - wb va - va × vb)
    w = np.abs(wa[..., 0] * wb[..., 0] + np.sum(va * vb, axis=-1))
    v = wa * vb - wb * va - np.cross(va, vb)
    return 2 * np.arctan2(np.linalg.norm(v, axis=-1), w)


def tracking_report(profile: Profile, time_s, omega_body_rad_s, command_body_rad_s, quat_wxyz,
                    command_quat_wxyz, settle_s: float) -> Tracking:
    """Compare realised with commanded motion, segment by segment.

    Parameters
    ----------
    profile : Profile
    time_s : ndarray, shape (n,)
        Sample times [s].
    omega_body_rad_s, command_body_rad_s : ndarray, shape (n, 3)
        Realised and commanded body rates [rad/s].
    quat_wxyz, command_quat_wxyz : ndarray, shape (n, 4)
        Realised and commanded attitude [-].
    settle_s : float
        Time after a change of command left out of steady-state statistics [s].

    Returns
    -------
    Tracking
    """
    t = np.asarray(time_s)
    err = np.linalg.norm(omega_body_rad_s - command_body_rad_s, axis=1)
    segs = []
    for i, seg in enumerate(profile.segments):
        t0, t1 = profile.segment_span(i)
        m = (t >= t0) & (t < t1)
        if not np.any(m):
            continue
        steady, cross, amp, lag, att = [], [], None, None, None
        for p in profile.pieces:
            if p.segment != i:
                continue
            w = (t >= p.t0 + settle_s) & (t < p.t1)
            if p.role == "rate" and np.count_nonzero(w):
                proj = omega_body_rad_s[w] @ p.axis
                steady.append(float(np.mean(proj) - p.r0))
                perp = omega_body_rad_s[w] - proj[:, None] * p.axis
                cross.append(float(np.max(np.linalg.norm(perp, axis=1))))
            elif p.role == "sine":
                # at least one whole period after settling, within the run
                if (min(t[-1], p.t1) - (p.t0 + settle_s)) * p.frequency_hz >= 1:
                    tt = t[w] - p.t0
                    a_r, ph_r = _sine_fit(tt, omega_body_rad_s[w] @ p.axis, p.frequency_hz)
                    a_c, ph_c = _sine_fit(tt, command_body_rad_s[w] @ p.axis, p.frequency_hz)
                    amp = a_r / a_c
                    lag = float((ph_c - ph_r + math.pi) % (2 * math.pi) - math.pi)
            elif p.role == "hold" and np.count_nonzero(w):
                e = float(np.max(_angle_between(quat_wxyz[w], command_quat_wxyz[w])))
                att = e if att is None else max(att, e)
        segs.append(SegmentTracking(
            index=i + 1, kind=seg.kind, label=seg.label, start_s=float(t0),
            end_s=float(min(t1, t[-1])), rms_error_rad_s=float(np.sqrt(np.mean(err[m] ** 2))),
            max_error_rad_s=float(err[m].max()), steady_rate_error_rad_s=tuple(steady),
            steady_cross_axis_rad_s=tuple(cross), amplitude_ratio=amp, phase_lag_rad=lag,
            hold_attitude_error_rad=att))
    return Tracking(rms_error_rad_s=float(np.sqrt(np.mean(err ** 2))),
                    max_error_rad_s=float(err.max()), settle_s=float(settle_s),
                    segments=tuple(segs))


# =============================================================================
# The table
# =============================================================================

@dataclass(frozen=True, eq=False)
class TableRun:
    """What the table did, sampled at the gyro sample rate.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Sample times ``k / fs`` [s].
    omega_body_rad_s : ndarray, shape (n, 3)
        Reference gyro: platform angular velocity relative to the local-level
        frame, in the platform frame [rad/s].
    quat_wxyz : ndarray, shape (n, 4)
        Platform attitude, platform -> local level (``framequat``) [-].
    joint_angles_rad, joint_rates_rad_s : ndarray, shape (n, 3)
        Encoders (outer, middle, inner) [rad], [rad/s].
    command_body_rad_s : ndarray, shape (n, 3)
        Commanded body rate [rad/s].
    command_joint_rad : ndarray, shape (n, 3)
        Commanded gimbal angles [rad].
    site_rates_rad_s : ndarray, shape (n, N) or None
        Each gyro site's MuJoCo ``gyro`` sensor along its z (sensitive) axis
        [rad/s], when the run was made with a layout.
    specific_force_m_s2 : ndarray, shape (n, 3)
        MuJoCo ``accelerometer`` at the platform origin: specific force f_0,
        platform frame [m/s²] (+g0 on z at rest, level).
    angular_accel_rad_s2 : ndarray, shape (n, 3)
        MuJoCo ``frameangacc`` of the platform, rotated into the platform
        frame: α = dω_body/dt [rad/s²].
    site_specific_force_m_s2 : ndarray, shape (n, N, 3) or None
        MuJoCo ``accelerometer`` at each gyro's position, platform frame
        [m/s²], when the run was made with a layout.
    tracking : Tracking
    physics_dt_s : float
        Physics time step [s].
    steps_per_sample : int
    stepped, repeated : int
        Physics steps computed by MuJoCo and steps repeated at a rest fixed point.
    """

    time_s: np.ndarray
    omega_body_rad_s: np.ndarray
    quat_wxyz: np.ndarray
    joint_angles_rad: np.ndarray
    joint_rates_rad_s: np.ndarray
    command_body_rad_s: np.ndarray
    command_joint_rad: np.ndarray
    site_rates_rad_s: np.ndarray | None
    specific_force_m_s2: np.ndarray
    angular_accel_rad_s2: np.ndarray
    site_specific_force_m_s2: np.ndarray | None
    tracking: Tracking
    physics_dt_s: float
    steps_per_sample: int
    stepped: int = 0
    repeated: int = 0


def _f(x: float) -> str:
    return repr(float(x))


def _v(v) -> str:
    return " ".join(_f(x) for x in v)


@dataclass(frozen=True)
class RateTable:
    """A 3-axis rate table simulated in MuJoCo.

    Parameters
    ----------
    params : TableParams
    """

    params: TableParams = field(default_factory=TableParams)

    def timestep(self, sample_rate_hz: float) -> tuple[float, int]:
        """Physics step [s] and the integer number of steps per sample."""
        k = steps_per_sample(sample_rate_hz, self.params.min_physics_rate_hz)
        return 1.0 / (k * float(sample_rate_hz)), k

    def mjcf(self, layout=None, *, timestep_s: float = 1e-3) -> str:
        """The MJCF model of the table, with one gyro site per axis of ``layout``.

        Parameters
        ----------
        layout : gyroarray.core.layout.Layout, optional
            Sensitive axes in the platform frame and positions (zero when
            not given); None: reference sensors only.
        timestep_s : float
            Physics time step [s].

        Returns
        -------
        str
            MJCF XML.
        """
        p = self.params
        kp, kv = p.gains
        c = p.damping_n_m_s
        inertias = (p.outer_inertia_kg_m2, p.middle_inertia_kg_m2, p.inner_inertia_kg_m2)
        axes = ("0 0 1", "1 0 0", "0 1 0")
        sites = []
        n_sites = 0
        if layout is not None:
            sens_axes = np.asarray(layout.H, dtype=float)
            n_sites = sens_axes.shape[0]
            pos = (np.zeros_like(sens_axes) if getattr(layout, "positions_m", None) is None
                   else np.asarray(layout.positions_m, dtype=float))
            for k, a in enumerate(sens_axes, start=1):
                sites.append(f'<site name="gyro{k}" pos="{_v(pos[k - 1])}" zaxis="{_v(a)}" '
                             f'size="0.008" rgba="0.9 0.5 0.1 1"/>')
            for k in range(1, n_sites + 1):    # platform-aligned, for the accelerometers
                sites.append(f'<site name="acc{k}" pos="{_v(pos[k - 1])}" size="0.004"/>')
        geoms = (
            '<geom type="box" size="0.02 0.34 0.02" pos="0 0 -0.30" rgba="0.3 0.3 0.35 1"/>'
            '<geom type="box" size="0.02 0.02 0.30" pos="0 0.34 0" rgba="0.3 0.3 0.35 1"/>'
            '<geom type="box" size="0.02 0.02 0.30" pos="0 -0.34 0" rgba="0.3 0.3 0.35 1"/>',
            '<geom type="box" size="0.27 0.015 0.015" pos="0 0 0.25" rgba="0.5 0.5 0.6 1"/>'
            '<geom type="box" size="0.27 0.015 0.015" pos="0 0 -0.25" rgba="0.5 0.5 0.6 1"/>'
            '<geom type="box" size="0.015 0.015 0.25" pos="0.27 0 0" rgba="0.5 0.5 0.6 1"/>'
            '<geom type="box" size="0.015 0.015 0.25" pos="-0.27 0 0" rgba="0.5 0.5 0.6 1"/>',
            '<geom type="box" size="0.15 0.15 0.01" rgba="0.2 0.5 0.8 1"/>',
        )
        bodies_open, bodies_close = [], []
        for j, name in enumerate(JOINTS):
            bodies_open.append(
                f'<body name="{name}">'
                f'<joint name="{name}" type="hinge" axis="{axes[j]}" damping="{_f(c[j])}"/>'
                f'<inertial pos="0 0 0" mass="{_f(p.masses_kg[j])}" diaginertia="{_v(inertias[j])}"/>'
                f'{geoms[j]}')
            bodies_close.append("</body>")
        actuators = []
        for j, name in enumerate(JOINTS):
            actuators.append(f'<position name="pos_{name}" joint="{name}" kp="{_f(kp[j])}"/>')
        for j, name in enumerate(JOINTS):
            actuators.append(f'<velocity name="vel_{name}" joint="{name}" kv="{_f(kv[j])}"/>')
        for name in JOINTS:
            actuators.append(f'<motor name="ff_{name}" joint="{name}"/>')
        sensors = ['<gyro name="ref_gyro" site="platform"/>',
                   '<framequat name="attitude" objtype="site" objname="platform"/>']
        sensors += [f'<jointpos name="enc_{n}" joint="{n}"/>' for n in JOINTS]
        sensors += [f'<jointvel name="rate_{n}" joint="{n}"/>' for n in JOINTS]
        sensors += ['<accelerometer name="ref_acc" site="platform"/>',
                    '<frameangacc name="ref_angacc" objtype="site" objname="platform"/>']
        sensors += [f'<gyro name="gyro{k}" site="gyro{k}"/>' for k in range(1, n_sites + 1)]
        sensors += [f'<accelerometer name="acc{k}" site="acc{k}"/>' for k in range(1, n_sites + 1)]
        nl = "\n"
        return f"""<mujoco model="gyroarray_rate_table">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{_f(timestep_s)}" integrator="implicitfast" gravity="0 0 {_f(-G0_M_S2)}">
    <flag contact="disable" constraint="disable"/>
  </option>
  <worldbody>
    <light pos="0 -1.5 2" dir="0 0.6 -0.8"/>
    <geom type="cylinder" size="0.4 0.05" pos="0 0 -0.40" rgba="0.2 0.2 0.2 1"/>
    {"".join(bodies_open)}
      <site name="platform" size="0.01" rgba="0.1 0.8 0.1 1"/>
      {(nl + "      ").join(sites)}
    {"".join(bodies_close)}
  </worldbody>
  <actuator>
    {(nl + "    ").join(actuators)}
  </actuator>
  <sensor>
    {(nl + "    ").join(sensors)}
  </sensor>
</mujoco>
"""

    def model(self, layout=None, *, timestep_s: float = 1e-3) -> mujoco.MjModel:
        """The compiled MuJoCo model (see :meth:`mjcf`)."""
        return mujoco.MjModel.from_xml_string(self.mjcf(layout, timestep_s=timestep_s))

    def _step_profile(self, model, profile: Profile, dt: float, K: int, n: int,
                      skip_rest: bool) -> tuple:
        """Step the servo-driven table through ``profile`` and keep every K-th step's sensors.

        Returns (sensordata (n, nsensordata), joint rates after each sample's step (n, nv),
        steps stepped, steps repeated from a bitwise-fixed rest state).
        """
        n_steps = (n - 1) * K + 1              # sensors of step j are at t = j dt (pre-step)
        data = mujoco.MjData(model)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        nstate = mujoco.mj_stateSize(model, spec)
        x = np.zeros(nstate)
        mujoco.mj_getState(model, data, x, spec)
        nsens = model.nsensordata
        sens = np.empty((n, nsens))
        qvel_next = np.empty((n, model.nv))        # joint rates after each sample's step
        vel = slice(1 + model.nq, 1 + model.nq + model.nv)    # in the FULLPHYSICS state
        cap = max(CHUNK_STEPS, HOLD_PROBE_STEPS)
        sbuf = np.empty((1, cap, nstate))
        dbuf = np.empty((1, cap, nsens))
        damping = np.array(self.params.damping_n_m_s)
        # hold spans as ranges of step indices j whose control time (j + 1/2) dt lies in them
        holds = [(_first_ctrl_step(a, dt), _first_ctrl_step(b, dt)) for a, b in profile.hold_spans()]
        stepped = repeated = 0
        j = 0
        while j < n_steps:
            hold_end = None
            if skip_rest:
                hold_end = next((min(b, n_steps) for a, b in holds if a <= j < b), None)
            m = min(CHUNK_STEPS if hold_end is None else HOLD_PROBE_STEPS, n_steps - j)
            if hold_end is not None:
                m = min(m, hold_end - j)
            elif skip_rest:     # stop where the next long hold starts
                m = min([m] + [a - j for a, b in holds if a > j and b - a > 2 * HOLD_PROBE_STEPS])
            steps = np.arange(j, j + m)
            # servo command previewed by half a step: compensates the half-step delay of
            # the semi-implicit Euler update (see the module notes)
            cmd = profile.command(np.minimum((steps + 0.5) * dt, profile.duration_s))
            ctrl = np.concatenate([cmd.q_rad, cmd.qd_rad_s, cmd.qd_rad_s * damping], axis=1)
            _rollout.rollout(model, data, x[None], ctrl[None], state=sbuf[:, :m],
                             sensordata=dbuf[:, :m])
            stepped += m
            on = steps % K == 0
            sens[steps[on] // K] = dbuf[0, :m][on]
            qvel_next[steps[on] // K] = sbuf[0, :m][on][:, vel]
            x = sbuf[0, m - 1].copy()
            j += m
            if (hold_end is not None and j < hold_end and m >= 2
                    and np.array_equal(sbuf[0, m - 1, 1:], sbuf[0, m - 2, 1:])):
                # x_j == x_{j-1} under a constant command: every later step gives the
                # same state and the same sensors (those of step j-1) until the hold ends
                k0, k1 = -(-j // K), -(-hold_end // K)
                sens[k0:k1] = dbuf[0, m - 1]
                qvel_next[k0:k1] = sbuf[0, m - 1, vel]
                repeated += hold_end - j
                j = hold_end
                x[0] = j * dt
        return sens, qvel_next, stepped, repeated

    def run(self, profile, sample_rate_hz: float, *, layout=None, duration_s: float | None = None,
            skip_rest: bool = True) -> TableRun:
        """Run a profile and read the sensors at ``sample_rate_hz``.

        Parameters
        ----------
        profile : Profile or path
            The motion profile (a path is read with ``load_profile``).
        sample_rate_hz : float
            Gyro sample rate fs [Hz]; samples at ``k / fs`` in [0, duration).
        layout : Layout, optional
            Also read one MuJoCo gyro per sensitive axis and one MuJoCo
            accelerometer per gyro position.
        duration_s : float, optional
            Run only the first ``duration_s`` of the profile [s].
        skip_rest : bool
            Repeat a rest state that is a bitwise fixed point instead of
            stepping it (exact; False steps everything, for checking).

        Returns
        -------
        TableRun
        """
        if not isinstance(profile, Profile):
            profile = load_profile(profile)
        fs = float(sample_rate_hz)
        dt, K = self.timestep(fs)
        T = profile.duration_s if duration_s is None else float(duration_s)
        if not (math.isfinite(T) and 0 < T <= profile.duration_s * (1 + 1e-12)):
            raise InputError(f"duration must be in (0, {profile.duration_s:g}] s, got {duration_s!r}",
                             file=profile.source)
        n = n_samples(T, fs)
        model = self.model(layout, timestep_s=dt)
        sens, qvel_next, stepped, repeated = self._step_profile(model, profile, dt, K, n, skip_rest)
        _realised_acceleration_sensors(model, sens, qvel_next, dt)
        time_s = np.arange(n) / fs
        cmd = profile.command(time_s)
        site = site_f = None
        if layout is not None:
            n_g = int(np.asarray(layout.H).shape[0])
            site = sens[:, _S_SITES:_S_SITES + 3 * n_g][:, 2::3].copy()   # z of each gyro site
            site_f = sens[:, _S_SITES + 3 * n_g:_S_SITES + 6 * n_g].reshape(n, n_g, 3).copy()
        quat = sens[:, _S_QUAT].copy()
        # frameangacc is in the world frame: α_body = Rᵀ α_world
        alpha = np.einsum("nji,nj->ni", rotation_matrices(quat), sens[:, _S_ANGACC])
        tracking = tracking_report(profile, time_s, sens[:, _S_GYRO], cmd.omega_body_rad_s, quat,
                                   gimbal_quaternion(cmd.q_rad), self.params.settle_s)
        return TableRun(time_s=time_s, omega_body_rad_s=sens[:, _S_GYRO].copy(), quat_wxyz=quat,
                        joint_angles_rad=sens[:, _S_ENC].copy(),
                        joint_rates_rad_s=sens[:, _S_RATE].copy(),
                        command_body_rad_s=cmd.omega_body_rad_s, command_joint_rad=cmd.q_rad,
                        site_rates_rad_s=site, specific_force_m_s2=sens[:, _S_ACC].copy(),
                        angular_accel_rad_s2=alpha, site_specific_force_m_s2=site_f,
                        tracking=tracking, physics_dt_s=dt,
                        steps_per_sample=K, stepped=stepped, repeated=repeated)


def _realised_acceleration_sensors(model, sens: np.ndarray, qvel_next: np.ndarray,
                                   dt: float) -> None:
    """Re-evaluate the acceleration-stage sensors at the realised joint acceleration.

    ``sens`` (n, nsensordata) is changed in place in its acceleration-stage
    columns (accelerometers, ``frameangacc``); the state of sample j is read
    from its encoders (``jointpos``, ``jointvel``) and the acceleration is
    qacc = (``qvel_next`` − q̇_j)/dt. Consecutive samples with the same state
    and acceleration (holds) are evaluated once.
    """
    cols = np.concatenate([np.arange(model.sensor_adr[i], model.sensor_adr[i] + model.sensor_dim[i])
                           for i in range(model.nsensor)
                           if model.sensor_needstage[i] == mujoco.mjtStage.mjSTAGE_ACC])
    qacc = (qvel_next - sens[:, _S_RATE]) / dt
    key = np.hstack([sens[:, _S_ENC], sens[:, _S_RATE], qacc])
    new = np.ones(key.shape[0], dtype=bool)
    new[1:] = np.any(key[1:] != key[:-1], axis=1)
    rows = np.flatnonzero(new)
    vals = np.empty((rows.size, cols.size))
    data = mujoco.MjData(model)
    for r, i in enumerate(rows):
        data.qpos[:] = key[i, 0:3]
        data.qvel[:] = key[i, 3:6]
        mujoco.mj_forward(model, data)          # positions and velocities of sample i
        data.qacc[:] = key[i, 6:9]              # the acceleration the integrator applied
        mujoco.mj_rnePostConstraint(model, data)
        mujoco.mj_sensorAcc(model, data)
        vals[r] = data.sensordata[cols]
    sens[:, cols] = vals[np.cumsum(new) - 1]


def rotation_matrices(quat_wxyz: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z) -> rotation matrices, shape (n, 3, 3) [-]."""
    w, x, y, z = (quat_wxyz[:, k] for k in range(4))
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def _first_ctrl_step(t: float, dt: float) -> int:
    """Smallest j >= 0 with (j + 1/2)·dt >= t, as computed in floating point."""
    j = max(0, math.ceil(t / dt - 0.5))
    while j > 0 and (j - 0.5) * dt >= t:
        j -= 1
    while (j + 0.5) * dt < t:
        j += 1
    return j
