"""The model chain: scenario → table truth → effects → readings → estimators → metrics.

Like pvlib's ModelChain, one orchestrator runs the stages; each stage is a
slot filled by name (the estimators by their registry names). The result is
a table with one row per estimator × body axis and the units in the column
names, plus the single gyros as the reference every reduction factor is
taken against.

Metrics (per body axis; :mod:`gyroarray.analysis.metrics`):

``sigma_1_deg_s``, ``mean_error_deg_s``
    Standard deviation and mean of estimate − truth (paper 002 Eq. 19),
    after the first ``settle_s`` seconds (filter start-up).
``reduction``
    Single-gyro 1σ (mean over gyros of the 1σ of z_k − h_k·ω) / this 1σ.
``attenuation``, ``phase_deg``
    Sinusoidal profiles: fitted amplitude of the estimate / of the truth
    on the swing axis at the swing frequency, and phase lag [deg]
    (positive: the estimate lags). None elsewhere.
``arw_deg_rt_h``, ``bi_deg_h``, ``rrw_deg_h_rt_h`` (and ``*_sigma``)
    IEEE Std 952 terms of the error's Allan deviation, with 1σ.
``arw_reduction``, ``bi_reduction``, ``rrw_reduction``
    Mean single-gyro value / this value.
``noise_density_deg_s_rt_hz``
    √(median Welch PSD) of the error, 0.1 Hz to fs/4.
``efficiency``
    1σ of the best offline estimate (the ``bound`` estimator: time-varying
    KF + RTS smoother on the full model) / this 1σ (≤ 1 up to estimation
    noise for a causal estimator).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from . import units
from .analysis.allan import allan_analysis
from .analysis.metrics import attenuation_and_lag, noise_density
from .errors import InputError

AXES = ("x", "y", "z")
#: Filter start-up excluded from every metric [s].
SETTLE_S = 2.0
#: Estimators run when none are named.
DEFAULT_ESTIMATORS = ("kf_array", "kf_single", "gls", "ols", "naive", "bound")
#: A body axis "swings" when its fitted truth amplitude exceeds this share of the largest [-].
SWING_SHARE = 0.1
#: Whole swing periods a run must contain to report attenuation and phase.
MIN_SWING_PERIODS = 2.0


@dataclass(frozen=True)
class RunResult:
    """Metrics of one scenario run.

    Attributes
    ----------
    scenario : str
    table : pandas.DataFrame
        One row per (estimator, axis); units in the column names.
    single_gyro : pandas.DataFrame
        One row per gyro: the raw gyro error metrics.
    swing_hz : float or None
        Swing frequency the attenuation refers to [Hz].
    """

    scenario: str
    table: pd.DataFrame
    single_gyro: pd.DataFrame
    swing_hz: float | None = None
    notes: tuple[str, ...] = field(default=())

    def to_json_dict(self) -> dict:
        est: dict = {}
        for row in self.table.to_dict("records"):
            name, axis = row.pop("estimator"), row.pop("axis")
            est.setdefault(name, {})[axis] = row
        single = self.single_gyro.drop(columns=["gyro"]).mean(numeric_only=True).to_dict()
        single["gyros"] = {str(r.pop("gyro")): r for r in self.single_gyro.to_dict("records")}
        return {"scenario": self.scenario, "swing_hz": self.swing_hz, "estimators": est,
                "single_gyro": single, "notes": list(self.notes)}


def _allan_terms(error_rad_s: np.ndarray, dt_s: float) -> dict:
    fit = allan_analysis(error_rad_s, dt_s).fit.to_datasheet_dict()
    return {k: fit[k] for k in ("arw_deg_rt_h", "arw_deg_rt_h_sigma", "bi_deg_h", "bi_deg_h_sigma",
                                "rrw_deg_h_rt_h", "rrw_deg_h_rt_h_sigma")}


def error_metrics(error_rad_s: np.ndarray, dt_s: float) -> dict:
    """1σ, mean, noise density and Allan terms of one error series (datasheet units out)."""
    return {"sigma_1_deg_s": float(units.rad_s_to_deg_s(np.std(error_rad_s, ddof=1))),
            "mean_error_deg_s": float(units.rad_s_to_deg_s(np.mean(error_rad_s))),
            "noise_density_deg_s_rt_hz": float(units.rad_s_to_deg_s(noise_density(error_rad_s, dt_s))),
            **_allan_terms(error_rad_s, dt_s)}


def _ratio(a, b):
    return None if a is None or b is None or b == 0 else a / b


def swing_frequency(profile) -> tuple[float, tuple[float, float]] | None:
    """(frequency [Hz], (start, end) [s]) of the first sinusoid segment, if any."""
    for i, seg in enumerate(profile.segments):
        if getattr(seg, "kind", None) == "sinusoid":
            return float(seg.frequency_hz), tuple(profile.segment_span(i))
    return None


def score(estimates: dict[str, np.ndarray], truth_rad_s: np.ndarray, readings_rad_s: np.ndarray,
          layout, time_s: np.ndarray, dt_s: float, *, swing=None, settle_s: float = SETTLE_S,
          scenario: str = "") -> RunResult:
    """Score body-rate estimates against the truth (see the module docstring).

    Parameters
    ----------
    estimates : dict of str to ndarray (n, 3)
        Body-rate estimate per estimator name [rad/s].
    truth_rad_s : ndarray (n, 3)
        Realised table rate [rad/s].
    readings_rad_s : ndarray (n, N)
        Raw gyro outputs [rad/s] (the single-gyro reference).
    layout : Layout
    time_s : ndarray (n,)
    dt_s : float
    swing : (freq_hz, (start_s, end_s)), optional
    settle_s : float
        Start-up excluded from the metrics [s].
    """
    keep = time_s >= time_s[0] + settle_s
    if keep.sum() < 64:
        raise InputError(f"the run is too short to score: {keep.sum()} samples after the "
                         f"{settle_s:g} s start-up")
    gyro_err = (readings_rad_s - truth_rad_s @ layout.H.T)[keep]
    single = pd.DataFrame([{"gyro": k + 1, **error_metrics(gyro_err[:, k], dt_s)}
                           for k in range(gyro_err.shape[1])])
    ref = single.mean(numeric_only=True)

    swing_sel = swing_axes = None
    if swing is not None:
        freq, (t0, t1) = swing
        swing_sel = keep & (time_s >= t0) & (time_s <= t1)
        span_s = np.ptp(time_s[swing_sel]) if swing_sel.any() else 0.0
        if span_s * freq < MIN_SWING_PERIODS:
            # the run was cut before (most of) the swing: nothing to attenuate
            swing, swing_sel = None, None
    if swing is not None:
        amps = np.array([np.ptp(truth_rad_s[swing_sel, a]) for a in range(3)])
        swing_axes = amps >= SWING_SHARE * amps.max() if amps.max() > 0 else np.zeros(3, bool)

    rows = []
    for name, est in estimates.items():
        err = (est - truth_rad_s)[keep]
        for a, axis in enumerate(AXES):
            m = error_metrics(err[:, a], dt_s)
            att = lag = None
            if swing_sel is not None and swing_axes[a]:
                att, lag_rad = attenuation_and_lag(time_s[swing_sel], est[swing_sel, a],
                                                   truth_rad_s[swing_sel, a], swing[0])
                lag = float(units.rad_to_deg(lag_rad))
            rows.append({"estimator": name, "axis": axis, **m,
                         "reduction": _ratio(ref["sigma_1_deg_s"], m["sigma_1_deg_s"]),
                         "arw_reduction": _ratio(ref["arw_deg_rt_h"], m["arw_deg_rt_h"] or None),
                         "bi_reduction": _ratio(ref["bi_deg_h"], m["bi_deg_h"] or None),
                         "rrw_reduction": _ratio(ref["rrw_deg_h_rt_h"], m["rrw_deg_h_rt_h"] or None),
                         "attenuation": att, "phase_deg": lag})
    table = pd.DataFrame(rows)
    if "bound" in estimates:
        bound = table[table.estimator == "bound"].set_index("axis")["sigma_1_deg_s"]
        table["efficiency"] = [bound[ax] / s for ax, s in zip(table.axis, table.sigma_1_deg_s)]
    else:
        table["efficiency"] = None
    return RunResult(scenario=scenario, table=table, single_gyro=single,
                     swing_hz=None if swing is None else swing[0])


def run_scenario(scenario, estimator_names=None, *, cache: bool = True) -> RunResult:
    """Simulate a scenario and score each named estimator (default: all built-ins).

    Parameters
    ----------
    scenario : gyroarray.sim.scenario.Scenario
    estimator_names : sequence of str, optional
        Registry names (``gyroarray.estimators.available()``).
    cache : bool
        Use the rate-table truth cache.
    """
    from .estimators import available, get_estimator
    from .sim.scenario import simulate

    explicit = bool(estimator_names)
    names = list(estimator_names) if explicit else [n for n in DEFAULT_ESTIMATORS if n in available()]
    unknown = [n for n in names if n not in available()]
    if unknown:
        raise InputError(f"unknown estimator {unknown[0]!r} (available: {', '.join(available())})")
    res = simulate(scenario, cache=cache)
    dt = 1.0 / scenario.sample_rate_hz
    estimates, notes, fitted = {}, [], {}
    for name in names:
        try:
            est = fitted[name] = get_estimator(name)().fit(scenario.layout, scenario.model, dt)
        except InputError as err:
            # a named estimator that cannot serve this model is the user's error; a default
            # one is skipped and said so (e.g. bias-state KFs on a model without RRW)
            if explicit:
                raise InputError(err.message, file=scenario.source) from None
            notes.append(f"skipped {err.message}")
            continue
        estimates[name] = est.estimate(res.readings_rad_s)
    result = score(estimates, res.truth.omega_body_rad_s, res.readings_rad_s, scenario.layout,
                   res.truth.time_s, dt, swing=swing_frequency(scenario.profile), scenario=scenario.name)
    result = replace(result, notes=tuple(notes))
    if "fdi" in estimates:                     # the fault detector's scores (issue 16)
        from .analysis.fdi_score import add_fdi_metrics
        result = add_fdi_metrics(result, scenario, res, fitted["fdi"])
    return result
