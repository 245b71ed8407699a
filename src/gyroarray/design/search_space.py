"""What the design search varies and under which conditions: :class:`DesignSpace`, the grids
of cone angle [rad] and bandwidth [Hz], the objectives, and the sizing of an open per-gyro
model to the space's largest N (:func:`sized_for`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from gyroarray.design.moments import FLICKER_MODEL, check_flicker_model
from gyroarray.design.predict import (SensorBandwidth, Swing)
from gyroarray.core.sensor import bandwidth_sos
from gyroarray.effects.model import ModelEntry
from gyroarray.effects.names import BANDWIDTH, G_SENSITIVITY
from gyroarray.design.gyro_noise import (GyroNoise, model_gyro_refusal)
from gyroarray.design.robust import fixed_weights
from gyroarray.core.errors import InputError
from gyroarray.estimators import get_estimator
from gyroarray.estimators.base import DesignTags
from gyroarray.estimators.noise import ArrayNoise
from gyroarray.core.layout import Layout


#: The estimators the search compares by default (the registry's linear built-ins); any
#: estimator whose :meth:`~gyroarray.estimators.base.Estimator.design_tags` say it has a linear
#: system can be searched (:func:`design_tags`).
ESTIMATORS = ("kf_array", "kf_single", "gls", "ols", "naive")

#: The per-sample weights the built-ins' fused channels are built on, as their design tags
#: declare them (``DesignTags.weights``; kept for importers, :func:`weight_kind` reads the tags).
WEIGHT_KIND = {"kf_array": "gls", "kf_single": "ols"}

#: The closed-form per-sample weights the fast channel model knows (:func:`gyroarray.design.robust.fixed_weights`).
CLOSED_FORM_WEIGHTS = ("gls", "ols", "naive")

_TAGS: dict[type, DesignTags] = {}


def design_tags(est: str) -> DesignTags:
    """The design tags of the estimator registered as ``est`` (a plugin's as well)."""
    cls = get_estimator(est)
    if cls not in _TAGS:
        _TAGS[cls] = cls.design_tags()  # type: ignore[attr-defined]
    return _TAGS[cls]


def design_refusal(est: str) -> str | None:
    """Why estimator ``est`` cannot take part in the design search (None: it can)."""
    try:
        t = design_tags(est)
    except InputError as err:
        return str(err)
    if not t.linear_system:
        return (f"estimator {est!r} declares no linear system (design tags: linear_system False): "
                "the design search predicts only fixed linear filters")
    return None


#: Fitted weights by (estimator, layout, design covariances) (a plugin's weights are read from
#: its fitted linear system; the screening asks for the same ones at both ends of the ρ range).
_FITTED: dict = {}
_FITTED_MAX = 4096


def fitted_weights(est: str, H: np.ndarray, R: np.ndarray, dt: float,
                   Q: np.ndarray | None = None) -> np.ndarray:
    """Per-sample weights (G, 3, N) of estimator ``est`` read from its fitted linear system.

    The estimator (default hyperparameters) is fitted on each layout of ``H`` (G, N, 3) [-] for
    the white-noise covariance ``R`` (N, N) of one sample [rad²/s²] and the random-walk
    covariance ``Q`` (N, N) of one sample's increment [rad²/s²] (None: none), and sample period
    ``dt`` [s]; the weights are the DC gain (3, N) of its linear system (the per-sample weights
    of a static estimator, exactly).
    """
    H = np.asarray(H, dtype=float)
    R = np.asarray(R, dtype=float)
    n = H.shape[1]
    sd = np.sqrt(np.diag(R))
    Qm = np.zeros((n, n)) if Q is None else np.asarray(Q, dtype=float)
    qd = np.sqrt(np.maximum(np.diag(Qm), 0.0))
    corr_q = np.eye(n) if not np.all(qd > 0) else Qm / np.outer(qd, qd)
    noise = ArrayNoise(arw_rad_rt_s=sd * math.sqrt(dt), rrw_rad_s_rt_s=qd / math.sqrt(dt),
                       corr_arw=R / np.outer(sd, sd), corr_rrw=corr_q)
    cls = get_estimator(est)
    key0 = (est, R.tobytes(), Qm.tobytes(), float(dt))
    out = np.empty((H.shape[0], 3, n))
    for i, h in enumerate(H):
        key = key0 + (h.tobytes(),)
        if key not in _FITTED:
            if len(_FITTED) >= _FITTED_MAX:
                _FITTED.clear()
            e = cls().fit(Layout(h), noise, dt)
            _FITTED[key] = np.asarray(e.linear_system().dc_gain(), dtype=float)
        out[i] = _FITTED[key]
    return out


def design_weights(est: str, H: np.ndarray, R: np.ndarray, dt: float,
                   Q: np.ndarray | None = None) -> np.ndarray:
    """Per-sample weights (G, 3, N) the fused channel of ``est`` is built on, for the design
    covariances ``R``, ``Q`` [rad²/s²] of one sample: closed form where its tags name the weights
    (:func:`gyroarray.design.robust.fixed_weights`), else read from the fitted estimator
    (:func:`fitted_weights`)."""
    kind = weight_kind(est)
    if kind in CLOSED_FORM_WEIGHTS:
        return fixed_weights(kind, H, R)
    return fitted_weights(est, H, R, dt, Q)
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
    flicker_model : {"circular", "kasdin"}
        The bias instability's (flicker) model of the ranking and the error budget
        (``design --flicker``, :data:`gyroarray.design.moments.FLICKER_MODELS`): Kasdin's 1/f
        from switch-on (the default) or the simulator's circular stationary 1/f.
    temperature_swing_k : float or None
        The temperature's departure from the one the biases were calibrated at [K]
        (``design --temperature-swing``): its amplitude with ``temperature_period_s``, a
        constant departure without; None: not stated (temperature terms left out, listed).
    temperature_period_s : float or None
        Period of a sinusoidal temperature swing [s] (``design --temperature-period``).
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
    flicker_model: str = FLICKER_MODEL
    temperature_swing_k: float | None = None
    temperature_period_s: float | None = None

    def __post_init__(self):
        check_flicker_model(self.flicker_model)
        if self.sensor_bandwidth is not None:
            fc, order = self.sensor_bandwidth
            bandwidth_sos(fc, order, self.dt_s)                     # order 1/2, 0 < fc < Nyquist

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz

    def temperature_history(self) -> np.ndarray | None:
        """ΔT(t) over the run [K] (n_samples,): C·sin(2π t / P) with a period P, else the
        constant C; None when no temperature swing is stated."""
        if self.temperature_swing_k is None:
            return None
        n = self.n_samples
        if self.temperature_period_s is None:
            return np.full(n, float(self.temperature_swing_k))
        t = np.arange(n) * self.dt_s
        return float(self.temperature_swing_k) * np.sin(2.0 * np.pi * t / float(self.temperature_period_s))

    def temperature_statement(self) -> str:
        """The stated temperature swing in words (the assumptions)."""
        if self.temperature_swing_k is None:
            return ("not stated: temperature terms are left out (listed as ignored); --temperature-swing C "
                    "[K] (and --temperature-period S) evaluates them")
        if self.temperature_period_s is None:
            return (f"a constant departure of {self.temperature_swing_k:g} K from the calibration temperature "
                    "over the run (--temperature-swing)")
        return (f"ΔT(t) = {self.temperature_swing_k:g} K · sin(2π t / {self.temperature_period_s:g} s) about the "
                "calibration temperature (--temperature-swing, --temperature-period)")

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
    """The bandwidths an estimator is tried at (None: its unfiltered form), by its design tags:
    none without a bandwidth hyperparameter; the unfiltered form as well where it is optional."""
    tags = design_tags(est)
    if tags.bandwidth_param is None:
        return [None]
    lo, hi = space.bandwidth_hz
    nyq = 0.5 * space.rate_hz
    hi = min(hi, 0.45 * space.rate_hz)
    lo = min(lo, hi)
    grid = [lo] if lo == hi else list(np.geomspace(lo, hi, max(2, int(round(
        BW_PER_DECADE * math.log10(hi / lo))) + 1)))
    out: list[float | None] = [float(f) for f in grid if 0 < f < nyq]
    if tags.bandwidth_optional and lo != hi:
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


def weight_kind(est: str) -> str | None:
    """The per-sample weights (``gls``, ``ols``, ``naive``) the fused channel of estimator ``est``
    is built on, as its design tags declare them (``DesignTags.weights``); None: read from the
    fitted estimator (:func:`fitted_weights`)."""
    return design_tags(est).weights
