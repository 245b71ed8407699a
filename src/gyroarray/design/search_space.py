"""What the design search varies and under which conditions: :class:`DesignSpace`, the grids
of cone angle [rad] and bandwidth [Hz], the objectives, and the sizing of an open per-gyro
model to the space's largest N (:func:`sized_for`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from gyroarray.design.predict import (SensorBandwidth, Swing)
from gyroarray.core.sensor import bandwidth_sos
from gyroarray.effects.model import ModelEntry
from gyroarray.effects.names import BANDWIDTH, G_SENSITIVITY
from gyroarray.design.gyro_noise import (GyroNoise, model_gyro_refusal)


#: The estimators the search compares (the registry's linear ones).
ESTIMATORS = ("kf_array", "kf_single", "gls", "ols", "naive")

#: The per-sample weights each estimator's fused channel is built on (the array KF filters the
#: GLS channel, the single-gyro KF the OLS channel; any other estimator is its own weights).
WEIGHT_KIND = {"kf_array": "gls", "kf_single": "ols"}
#: The bandwidth a filter is held at when no motion is given to trade it against [Hz].
DEFAULT_BANDWIDTH_HZ = 10.0


#: Cone angles per scheme on the search grid.
ALPHA_POINTS = 100

#: Bandwidths per decade on the search grid.
BW_PER_DECADE = 8

#: Designs whose objectives differ by less than this share are reported as equivalent.
EQUIVALENT_SHARE = 0.01


def sized_for(g: GyroNoise, space: "DesignSpace", notes: list | None = None
              ) -> tuple[GyroNoise, "DesignSpace"]:
    """``g`` with the levels of the space's largest N (an open per-gyro model,
    :attr:`GyroNoise.open_from`; anything else as it is) and the space.

    An N below the highest gyro the model names is refused (:func:`model_gyro_refusal`), unless
    the N list is the default one and ``notes`` is given: then it is left out, with a note.
    """
    if g.open_from is None:
        return g, space
    short = [n for n in space.ns if n < g.open_from]
    if short:
        srcs = space.__dict__.get("_sources", {})
        keep = tuple(n for n in space.ns if n >= g.open_from)
        if notes is None or srcs.get("ns") != "default" or not keep:
            raise model_gyro_refusal(g.model, short[0])
        notes.append(f"N = {', '.join(map(str, short))}: the model names gyro {g.open_from}; left out")
        space = replace(space, ns=keep)
        object.__setattr__(space, "_sources", srcs)
    return g.sized(max(space.ns)), space


@dataclass(frozen=True)
class DesignSpace:
    """What the search varies and under which conditions (every default recorded).

    Attributes
    ----------
    rate_hz : float
        Sample rate [Hz].
    horizon_s : float
        Run length T the accuracy refers to [s].
    ns : tuple of int
        Numbers of gyros N.
    schemes : tuple of int
    estimators : tuple of str
    failures : int
        Gyros that may fail while a 3-axis rate must remain.
    bandwidth_hz : tuple of float
        (lo, hi) range searched [Hz]; lo == hi: fixed.
    swing : Swing or None
        A swing about each body axis.
    motion : ndarray (n, 3) or None
        A commanded body rate instead of a swing [rad/s].
    motion_name : str
    settle_s : float
        Start-up excluded from the window metrics [s].
    alpha_points : int
    sensor_bandwidth : (float, int) or None
        The gyros' own low-pass, (cut-off [Hz], order 1 or 2), as the spec's
        ``bandwidth`` effect on every gyro: cascaded before every estimator.
    g_sensitivity_deg_s_per_g : (float, float, float) or None
        Every gyro's g-sensitivity, platform frame [(deg/s)/g] (the spec's
        ``g_sensitivity`` on every gyro); its rate error is reported beside
        the noise terms, not ranked.
    specific_force_m_s2 : ndarray (n, 3) or None
        The specific force at the platform origin over the run (a motion
        profile's truth) [m/s²]; None: the level table at rest, [0, 0, g0].
    objective : {"rate", "angle"} or None
        What the designs are ranked on: the 3-axis RMS of the rate error about
        the truth, or the angle error at the horizon; None: ``angle`` when the
        user gave the horizon, else ``rate``.
    design_rho : float or None
        The ρ the estimator's weights are built for [-]; None: chosen min-max
        over the ρ range.
    far_per_h, p_md : float
        False-alarm rate [1/h] and missed-detection probability [-] of the
        minimum detectable bias (with failures >= 1).
    mdb_max : float or None
        Largest minimum detectable bias a design may have [deg/s] (None: no limit).
    """

    rate_hz: float = 100.0
    horizon_s: float = 600.0
    ns: tuple[int, ...] = (4, 5, 6, 8)
    schemes: tuple[int, ...] = (1, 2)
    estimators: tuple[str, ...] = ESTIMATORS
    failures: int = 0
    bandwidth_hz: tuple[float, float] = (DEFAULT_BANDWIDTH_HZ, DEFAULT_BANDWIDTH_HZ)
    swing: Swing | None = None
    motion: np.ndarray | None = None
    motion_name: str = "at rest"
    settle_s: float = 2.0
    alpha_points: int = ALPHA_POINTS
    sensor_bandwidth: tuple[float, int] | None = None
    g_sensitivity_deg_s_per_g: tuple[float, float, float] | None = None
    specific_force_m_s2: np.ndarray | None = None
    objective: str | None = None
    design_rho: float | None = None
    far_per_h: float = 0.01
    p_md: float = 0.001
    mdb_max: float | None = None

    def __post_init__(self):
        if self.sensor_bandwidth is not None:
            fc, order = self.sensor_bandwidth
            bandwidth_sos(fc, order, self.dt_s)                     # order 1/2, 0 < fc < Nyquist

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz

    def sensor(self, n_gyros: int = 1):
        """The gyros' own filter as :class:`gyroarray.design.predict.SensorBandwidth` (None: none)."""
        if self.sensor_bandwidth is None:
            return None
        fc, order = self.sensor_bandwidth
        return SensorBandwidth(cutoff_hz=np.full(n_gyros, float(fc)),
                               order=np.full(n_gyros, int(order)), dt_s=self.dt_s)

    def sensor_entries(self) -> tuple:
        """The sensor's ``bandwidth`` and ``g_sensitivity`` as model entries on every gyro."""
        out = []
        if self.sensor_bandwidth is not None:
            out.append(ModelEntry(BANDWIDTH, None, {"cutoff_hz": float(self.sensor_bandwidth[0]),
                                                      "order": int(self.sensor_bandwidth[1])}))
        if self.g_sensitivity_deg_s_per_g is not None:
            out.append(ModelEntry(G_SENSITIVITY, None,
                                  {"deg_s_per_g": tuple(float(v) for v in self.g_sensitivity_deg_s_per_g)}))
        return tuple(out)

    @property
    def n_samples(self) -> int:
        from gyroarray.sim.table import n_samples  # lazy: loads mujoco
        return n_samples(self.horizon_s, self.rate_hz)


def bandwidth_grid(space: DesignSpace, est: str) -> list[float | None]:
    """The bandwidths an estimator is tried at (None: its unfiltered form)."""
    if est == "naive":
        return [None]
    lo, hi = space.bandwidth_hz
    nyq = 0.5 * space.rate_hz
    hi = min(hi, 0.45 * space.rate_hz)
    lo = min(lo, hi)
    grid = [lo] if lo == hi else list(np.geomspace(lo, hi, max(2, int(round(
        BW_PER_DECADE * math.log10(hi / lo))) + 1)))
    out: list[float | None] = [float(f) for f in grid if 0 < f < nyq]
    if est in ("gls", "ols") and lo != hi:
        out.append(None)                                             # no low-pass
    return out


def alpha_grid(scheme: int, points: int) -> np.ndarray:
    hi = 90.0 if scheme == 1 else 180.0
    return np.deg2rad(np.linspace(hi / points, hi - (hi / points if scheme == 2 else 0.0), points))


#: The ranking objectives: 3-axis RMS of the rate error, or the angle error at the horizon.
OBJECTIVES = ("rate", "angle")


def resolve_objective(space: DesignSpace) -> str:
    """The ranking objective: the space's, else ``angle`` when the user gave a horizon."""
    if space.objective is not None:
        return space.objective
    return "angle" if space.__dict__.get("_sources", {}).get("horizon_s") == "user" else "rate"


#: The objectives in words.
OBJECTIVE_WORDS = {"rate": "3-axis RMS of the rate error about the truth over the horizon [deg/s]",
                   "angle": "3-axis angle error at the horizon (root-sum-square over the axes) [deg]"}


def weight_kind(est: str) -> str:
    """The per-sample weights (``gls``, ``ols``, ``naive``) the fused channel of estimator ``est``
    is built on (:data:`WEIGHT_KIND`, the one place of this mapping)."""
    return WEIGHT_KIND.get(est, est)
