"""The model chain: scenario → table truth → effects → readings → estimators → metrics.

Like pvlib's ModelChain, one orchestrator runs the stages; each stage is a
slot filled by name (the estimators by their registry names). The result is
a table with one row per estimator × body axis and the units in the column
names, plus the single gyros as the reference every reduction factor is
taken against.

Metrics (per body axis; :mod:`gyroarray.analysis.metrics`):

``sigma_1_deg_s``, ``mean_error_deg_s``, ``rms_deg_s``
    Standard deviation and mean of estimate − truth, and its RMS about the
    truth (paper 002 Eq. 19: √(1σ² + mean²), what drives attitude drift),
    after the first ``settle_s`` seconds (filter start-up).
``angle_error_deg``
    The integrated rate error over the whole run, dt·Σ (estimate − truth):
    the attitude error the run leaves (signed; its RMS over runs is the 1σ).
``reduction``
    Single-gyro 1σ (mean over gyros of the 1σ of z_k − h_k·ω) / this 1σ.
``attenuation``, ``phase_deg``
    Sinusoidal profiles: fitted amplitude of the estimate / of the truth
    on the swing axis at the swing frequency, and phase lag [deg]
    (positive: the estimate lags). None elsewhere. This is the total:
``sensor_amplitude_ratio``, ``sensor_phase_deg``
    the gyros' own share, measured on the raw gyros (each reading against its
    projected truth, weighted by the projected amplitude²): their internal
    low-pass (``bandwidth``), 1 and 0 without one;
``estimator_amplitude_ratio``, ``estimator_phase_deg``
    the array estimator's share, total / sensor (phases subtract).
``g_sensitivity_rms_deg_s``
    With a ``g_sensitivity`` in the model: the RMS over the scored window of
    the rate error it causes on this run's motion, T₀ e with e_i = k_i · f_i
    (f_i the specific force at gyro i from the truth, T₀ the estimator's DC
    gain: the pseudo-inverse for least squares); per gyro in ``single_gyro``.
    None for an estimator without a linear form.
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
from typing import Any

import numpy as np
import pandas as pd

from gyroarray.core import units
from gyroarray.analysis.allan import allan_analysis
from gyroarray.chain.fdi_score import add_fdi_metrics
from gyroarray.analysis.metrics import attenuation_and_lag, noise_density
from gyroarray.analysis.replicates import mean_ci, replicate_rng, rms_ci
from gyroarray.core.gdop import unobservable_reason
from gyroarray.core.errors import InputError
from gyroarray.effects import get_effect
from gyroarray.estimators import available, get_estimator
from gyroarray.design.predict import (g_sensitivity_coeffs, g_sensitivity_error, predict as _predict,
                               sensor_bandwidth, settle_start, swing_response)
from gyroarray.sim.profiles import Sinusoid

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
            "rms_deg_s": float(units.rad_s_to_deg_s(np.sqrt(np.mean(error_rad_s ** 2)))),
            "noise_density_deg_s_rt_hz": float(units.rad_s_to_deg_s(noise_density(error_rad_s, dt_s))),
            **_allan_terms(error_rad_s, dt_s)}


def _ratio(a, b):
    return None if a is None or b is None or b == 0 else a / b


def swing_frequency(profile) -> tuple[float, tuple[float, float]] | None:
    """(frequency [Hz], (start, end) [s]) of the first sinusoid segment, if any."""
    for i, seg in enumerate(profile.segments):
        if getattr(seg, "kind", None) == Sinusoid.kind:
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

    swing_sel: np.ndarray | None = None
    swing_axes: np.ndarray | None = None
    if swing is not None:
        freq, (t0, t1) = swing
        swing_sel = keep & (time_s >= t0) & (time_s <= t1)
        span_s = np.ptp(time_s[swing_sel]) if swing_sel.any() else 0.0
        if span_s * freq < MIN_SWING_PERIODS:
            # the run was cut before (most of) the swing: nothing to attenuate
            swing, swing_sel = None, None
    sensor: dict[str, Any] | None = None
    if swing is not None:
        amps = np.array([np.ptp(truth_rad_s[swing_sel, a]) for a in range(3)])
        swing_axes = amps >= SWING_SHARE * amps.max() if amps.max() > 0 else np.zeros(3, bool)
        sensor = _sensor_response(time_s[swing_sel], readings_rad_s[swing_sel],
                                  truth_rad_s[swing_sel] @ layout.H.T, swing[0])
        single["sensor_amplitude_ratio"] = sensor["per_gyro"][:, 0]
        single["sensor_phase_deg"] = sensor["per_gyro"][:, 1]

    rows = []
    for name, est in estimates.items():
        full = est - truth_rad_s
        err = full[keep]
        angle = units.rad_to_deg(dt_s * np.sum(full, axis=0))
        for a, axis in enumerate(AXES):
            m = error_metrics(err[:, a], dt_s)
            m["angle_error_deg"] = float(angle[a])
            att = lag = None
            split = {"sensor_amplitude_ratio": None, "sensor_phase_deg": None,
                     "estimator_amplitude_ratio": None, "estimator_phase_deg": None}
            if swing_sel is not None and swing_axes is not None and sensor is not None \
                    and swing_axes[a]:
                att, lag_rad = attenuation_and_lag(time_s[swing_sel], est[swing_sel, a],
                                                   truth_rad_s[swing_sel, a], swing[0])
                lag = float(units.rad_to_deg(lag_rad))
                sa, sp = sensor["amplitude_ratio"], sensor["phase_deg"]
                split = {"sensor_amplitude_ratio": sa, "sensor_phase_deg": sp,
                         "estimator_amplitude_ratio": att / sa if sa > 0 else None,
                         "estimator_phase_deg": lag - sp}
            rows.append({"estimator": name, "axis": axis, **m,
                         "reduction": _ratio(ref["sigma_1_deg_s"], m["sigma_1_deg_s"]),
                         "arw_reduction": _ratio(ref["arw_deg_rt_h"], m["arw_deg_rt_h"] or None),
                         "bi_reduction": _ratio(ref["bi_deg_h"], m["bi_deg_h"] or None),
                         "rrw_reduction": _ratio(ref["rrw_deg_h_rt_h"], m["rrw_deg_h_rt_h"] or None),
                         "attenuation": att, "phase_deg": lag, **split})
    table = pd.DataFrame(rows)
    if "bound" in estimates:
        bound = table[table.estimator == "bound"].set_index("axis")["sigma_1_deg_s"]
        table["efficiency"] = [bound[ax] / s for ax, s in zip(table.axis, table.sigma_1_deg_s)]
    else:
        table["efficiency"] = None
    return RunResult(scenario=scenario, table=table, single_gyro=single,
                     swing_hz=None if swing is None else swing[0])


def _sensor_response(time_s, readings_rad_s, projected_rad_s, freq_hz: float) -> dict:
    """The gyros' own amplitude ratio and lag at the swing frequency, measured.

    Each gyro's reading is fitted against its projected truth h_k·ω
    (:func:`attenuation_and_lag`); the array's value is the mean of the
    complex responses weighted by the projected amplitude² (gyros whose
    projected amplitude is below ``SWING_SHARE`` of the largest are left out).
    The predictor's share, [T diag(F) H]_aa / [T H]_aa, weights gyro k by
    T_ak h_ka instead: the same for alike gyros, and for any filters on an
    isotropic layout (HᵀH ∝ I) under a per-sample estimator (T ∝ Hᵀ).

    Returns
    -------
    dict
        ``amplitude_ratio`` [-], ``phase_deg`` [deg] (positive: the gyro lags),
        ``per_gyro``: ndarray (N, 2) of the two per gyro (NaN where left out).
    """
    amp = np.ptp(projected_rad_s, axis=0)
    use = amp >= SWING_SHARE * amp.max() if amp.max() > 0 else np.zeros(amp.size, bool)
    per = np.full((amp.size, 2), np.nan)
    z = 0j
    for k in np.flatnonzero(use):
        att, lag = attenuation_and_lag(time_s, readings_rad_s[:, k], projected_rad_s[:, k], freq_hz)
        per[k] = att, units.rad_to_deg(lag)
        z += amp[k] ** 2 * att * np.exp(-1j * lag)
    z /= np.sum(amp[use] ** 2) if use.any() else 1.0
    return {"amplitude_ratio": float(abs(z)), "phase_deg": float(-np.degrees(np.angle(z))),
            "per_gyro": per}


def _g_sensitivity_columns(result: RunResult, scenario, truth, fitted: dict, dt_s: float,
                           settle_s: float = SETTLE_S) -> RunResult:
    """Add the RMS rate error of the model's g-sensitivity on the run's motion (module docstring)."""
    from gyroarray.sim.truth import specific_force  # lazy: loads mujoco
    N = scenario.layout.n_gyros
    coeff = g_sensitivity_coeffs(scenario.model, N)
    if coeff is None:
        return result
    f = specific_force(truth, scenario.layout)                        # (n, N, 3)
    k0 = settle_start(f.shape[0], dt_s, settle_s)
    per = g_sensitivity_error(coeff, f, None, k0)["per_gyro_rms_deg_s"]
    single = result.single_gyro.copy()
    single["g_sensitivity_rms_deg_s"] = per
    table = result.table.copy()
    vals = []
    cache = {}
    for name, axis in zip(table.estimator, table.axis):
        if name not in cache:
            try:
                t0 = fitted[name].linear_system().dc_gain()
                cache[name] = g_sensitivity_error(coeff, f, t0, k0)["fused_rms_deg_s"]
            except (InputError, NotImplementedError, AttributeError, KeyError):
                cache[name] = None
        vals.append(None if cache[name] is None else cache[name][axis])
    table["g_sensitivity_rms_deg_s"] = vals
    return replace(result, table=table, single_gyro=single)


def check_fusable(scenario) -> None:
    """Refuse a scenario whose layout cannot give a 3-axis rate, with the reason."""
    why = unobservable_reason(scenario.layout.H)
    if why is not None:
        raise InputError(f"the layout cannot be fused: {why}", file=scenario.source,
                         column="layout")


def run_scenario(scenario, estimator_names=None, *, cache: bool = True,
                 rng: np.random.Generator | None = None, params: dict | None = None) -> RunResult:
    """Simulate a scenario and score each named estimator (default: all built-ins).

    Parameters
    ----------
    scenario : gyroarray.sim.scenario.Scenario
    estimator_names : sequence of str, optional
        Registry names (``gyroarray.estimators.available()``).
    cache : bool
        Use the rate-table truth cache.
    rng : numpy.random.Generator, optional
        Overrides the scenario's seed (replicates).
    params : dict, optional
        Hyperparameters per estimator name, e.g. ``{"kf_array": {"bandwidth_hz": 2.0}}``.

    Raises
    ------
    InputError
        Unknown estimator, or a layout whose axes leave a body axis unobservable.
    """
    from gyroarray.sim.scenario import simulate  # lazy: loads mujoco

    explicit = bool(estimator_names)
    names = list(estimator_names) if explicit else [n for n in DEFAULT_ESTIMATORS if n in available()]
    unknown = [n for n in names if n not in available()]
    if unknown:
        raise InputError(f"unknown estimator {unknown[0]!r} (available: {', '.join(available())})")
    check_fusable(scenario)
    try:
        res = simulate(scenario, cache=cache, rng=rng)
    except InputError as err:                  # e.g. a bandwidth cut-off above this run's Nyquist
        if err.file is not None:
            raise
        raise InputError(err.message, file=scenario.source, line=err.line, column=err.column) from None
    dt = 1.0 / scenario.sample_rate_hz
    estimates, notes, fitted = {}, [], {}
    for name in names:
        try:
            est = fitted[name] = get_estimator(name)(**(params or {}).get(name, {})).fit(
                scenario.layout, scenario.model, dt)
        except InputError as err:
            # a named estimator that cannot serve this model is the user's error; a default
            # one is skipped and said so (e.g. bias-state KFs on a model without RRW)
            if explicit:
                raise InputError(err.message, file=scenario.source) from None
            notes.append(f"skipped {err.message}" if err.message.startswith(name)
                         else f"skipped {name}: {err.message}")
            continue
        estimates[name] = est.estimate(res.readings_rad_s)
    if not estimates:
        raise InputError("no estimator applies to this scenario: " + "; ".join(
            dict.fromkeys(n.removeprefix("skipped ") for n in notes)), file=scenario.source)
    result = score(estimates, res.truth.omega_body_rad_s, res.readings_rad_s, scenario.layout,
                   res.truth.time_s, dt, swing=swing_frequency(scenario.profile), scenario=scenario.name)
    result = replace(result, notes=tuple(notes))
    result = _g_sensitivity_columns(result, scenario, res.truth, fitted, dt)
    if "fdi" in estimates:                     # the fault detector's scores (issue 16)
        result = add_fdi_metrics(result, scenario, res, fitted["fdi"])
    return result


# -- replicates -------------------------------------------------------------------

#: Chain metric that each predicted metric is compared with, and how the runs are pooled:
#: "rms": √(mean over runs of value²) (the predictor gives √E[x²]); "mean": the plain mean.
PREDICTED_VS_RUN = {"std_deg_s": ("sigma_1_deg_s", "rms"), "rms_deg_s": ("rms_deg_s", "rms"),
                    "mean_deg_s": ("mean_error_deg_s", "rms"), "angle_deg": ("angle_error_deg", "rms"),
                    "amplitude_ratio": ("attenuation", "mean"), "phase_deg": ("phase_deg", "mean"),
                    **{f"{part}_{m}": (f"{part}_{m}", "mean") for part in ("sensor", "estimator")
                       for m in ("amplitude_ratio", "phase_deg")}}



@dataclass(frozen=True)
class ReplicateResult:
    """K runs of one scenario with independent seeds, summarised.

    Attributes
    ----------
    scenario : str
    seed : int
    runs : tuple of RunResult
    predictions : dict
        estimator -> :class:`gyroarray.design.predict.Prediction` (linear estimators).
    notes : tuple of str
    """

    scenario: str
    seed: int
    runs: tuple
    predictions: dict
    notes: tuple[str, ...] = ()

    def summary(self) -> dict:
        """estimator -> axis -> metric -> {"mean", "ci_low", "ci_high", "n"}."""
        out: dict = {}
        tables = [r.table for r in self.runs]
        cols = [c for c in tables[0].columns if c not in ("estimator", "axis")]
        for name in dict.fromkeys(tables[0].estimator):
            for axis in AXES:
                vals: dict[str, list] = {c: [] for c in cols}
                for t in tables:
                    row = t[(t.estimator == name) & (t.axis == axis)]
                    for c in cols:
                        v = row[c].iloc[0] if len(row) else None
                        vals[c].append(None if v is None or (isinstance(v, float) and np.isnan(v))
                                       else float(v))
                out.setdefault(name, {})[axis] = {c: mean_ci(v) for c, v in vals.items()}
        return out

    def single_gyro_summary(self) -> dict:
        cols = [c for c in self.runs[0].single_gyro.columns if c != "gyro"]
        return {c: mean_ci([float(r.single_gyro[c].mean()) for r in self.runs]) for c in cols}

    def comparison(self) -> dict:
        """estimator -> axis -> predicted metric -> {"predicted", "monte_carlo", "agrees"}.

        ``monte_carlo`` pools the runs as the predictor defines the metric
        (:data:`PREDICTED_VS_RUN`); ``agrees``: the prediction lies inside the
        95 % interval (for each comparison alone: over many, about 5 % fall
        outside by chance).
        """
        out: dict = {}
        for name, pred in self.predictions.items():
            for axis in AXES:
                for key, (col, how) in PREDICTED_VS_RUN.items():
                    p = pred.axes[axis].get(key)
                    if p is None:
                        continue
                    vals = []
                    for r in self.runs:
                        row = r.table[(r.table.estimator == name) & (r.table.axis == axis)]
                        v = row[col].iloc[0] if len(row) else None
                        vals.append(None if v is None or (isinstance(v, float) and np.isnan(v)) else float(v))
                    if how == "rms":
                        mc = rms_ci(vals, gaussian=key in ("mean_deg_s", "angle_deg"))
                    else:
                        s = mean_ci(vals)
                        mc = {"value": s["mean"], "ci_low": s["ci_low"], "ci_high": s["ci_high"], "n": s["n"]}
                    if mc["value"] is None:
                        continue
                    tol = 1e-9 * max(1.0, abs(p))       # rounding (a per-sample estimator passes 1)
                    ok = (None if mc["ci_low"] is None
                          else bool(mc["ci_low"] - tol <= p <= mc["ci_high"] + tol))
                    out.setdefault(name, {}).setdefault(axis, {})[key] = {
                        "predicted": p, "monte_carlo": {**mc, "pooled": how}, "agrees": ok}
        return out


def run_replicates(scenario, estimator_names=None, *, replicates: int, seed: int | None = None,
                   cache: bool = True, predict: bool = True,
                   params: dict | None = None) -> ReplicateResult:
    """Run a scenario ``replicates`` times (seeds :func:`replicate_rng`) and predict each estimator.

    Parameters
    ----------
    scenario : Scenario
    estimator_names : sequence of str, optional
    replicates : int
        Number of runs K >= 1.
    seed : int, optional
        Root seed (default: the scenario's).
    cache : bool
    predict : bool
        Add the analytic prediction of every linear estimator (same truth, same noise model).
    params : dict, optional
        Hyperparameters per estimator name (as :func:`run_scenario`).
    """
    from gyroarray.sim.truth import compute_truth  # lazy: loads mujoco
    k = int(replicates)
    if k < 1:
        raise InputError(f"--replicates must be >= 1, got {replicates!r}")
    s = scenario.seed if seed is None else int(seed)
    runs = tuple(run_scenario(scenario, estimator_names, cache=cache, rng=replicate_rng(s, i),
                              params=params) for i in range(k))
    preds, notes = {}, list(runs[0].notes)
    if predict:
        truth = compute_truth(scenario.profile, scenario.sample_rate_hz,
                              duration_s=scenario.duration_s, cache=cache)
        dt = 1.0 / scenario.sample_rate_hz
        f = None
        if any("acc" in get_effect(e.effect).sim_needs for e in scenario.model.entries):
            from gyroarray.sim.truth import specific_force  # lazy: loads mujoco
            f = specific_force(truth, scenario.layout)
        for name in dict.fromkeys(runs[0].table.estimator):
            try:
                est = get_estimator(name)(**(params or {}).get(name, {})).fit(
                    scenario.layout, scenario.model, dt)
                preds[name] = _predict(est, scenario.model, n_samples=truth.time_s.size,
                                       truth_rad_s=truth.omega_body_rad_s, specific_force_m_s2=f)
            except InputError as err:
                notes.append(f"{name}: no prediction ({err.message})")
                continue
            sw = swing_frequency(scenario.profile)
            if sw is not None and runs[0].swing_hz is not None:
                preds[name] = _with_swing(preds[name], est, scenario.model, sw[0])
        ignored = sorted({i for p in preds.values() for i in p.ignored})
        if ignored:
            notes.append("the prediction leaves out " + ", ".join(ignored))
    return ReplicateResult(scenario=scenario.name, seed=s, runs=runs, predictions=preds,
                           notes=tuple(dict.fromkeys(notes)))


def _with_swing(pred, est, model, freq_hz: float):
    """Add the amplitude ratio and phase at the swing frequency (total, estimator, sensor)."""
    resp = swing_response(est.linear_system(), np.array(est.H_),
                          sensor_bandwidth(model, est.n_gyros_, est.dt_s_), freq_hz, est.dt_s_)
    axes = {ax: dict(pred.axes[ax], **resp[ax]) for ax in AXES}
    return replace(pred, axes=axes, swing_hz=freq_hz)
