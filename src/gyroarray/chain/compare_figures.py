"""The data of the compare report's figures, computed from a comparison and its analyses.

:func:`compare_figures` turns a :class:`~gyroarray.chain.compare.ModelComparison`
and the steps of its ladder into a :class:`CompareFigures`: every number the
model-vs-measurement report (:mod:`gyroarray.reports.compare_report`) draws
beyond what the :class:`~gyroarray.chain.compare.Analysis` already holds:

* the first step's residual binned against each regressor of a deterministic
  effect, the "fitted bias" removed first (:class:`RegressorFigure`), with the
  candidate's fitted line (``Effect.channel_line``);
* the residual's amplitude spectral density (Welch, log-binned) with the
  model's ARW level and ARW + RRW curve (:class:`PsdFigure`);
* the correlation between the gyros' residuals, fast and slow (:class:`XcorrFigure`);
* the ARW in sliding windows (DAVAR at τ₀, :class:`ArwTrackFigure`);
* for a localised final step: the residual PSD (log-binned) and the residual
  binned against every channel of the record (:class:`ChannelPanel`).

Every class has ``to_dict``/``from_dict`` (JSON: arrays as lists, NaN as null).
SI inside the computation; the stored values carry their display unit in
their names (``_deg_h``, ``_deg_h_rt_hz``, ``_deg_rt_h``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from scipy.signal import welch

from gyroarray.analysis.davar import davar
from gyroarray.chain.localise import record_channels
from gyroarray.core import units
from gyroarray.effects import REGISTRY, get_effect

__all__ = ["BIAS_BLOCK_S", "ARW_WINDOW_S", "N_BINS", "MIN_BIN", "REGRESSORS", "CHANNEL_UNITS",
           "Binned", "RegressorPanel", "RegressorFigure", "PsdFigure", "XcorrFigure",
           "ArwTrackFigure", "ChannelPanel", "LocalisePsd", "CompareFigures", "fitted_bias",
           "binned", "log_binned", "model_asd_deg_h", "residual_correlation", "Regressors",
           "channel_effects", "channel_candidate", "channel_in_model", "compare_figures"]

#: Blocks [s] of the slowly varying "fitted bias" removed before the fast regressors are binned.
BIAS_BLOCK_S = 30.0
#: Window [s] of the sliding ARW (dynamic Allan deviation at τ₀).
ARW_WINDOW_S = 60.0
#: Bins of a residual-vs-regressor panel, and the fewest samples a bin needs to be drawn.
N_BINS = 24
MIN_BIN = 20
#: Points of the time panel's fitted-bias line (the series is thinned to about this many).
BIAS_POINTS = 600

#: Regressor panels: record channel -> (axis label, what the record needs). The
#: candidate drawn on a panel is the effect whose ``channel`` it is (``Effect.channel``).
REGRESSORS = {
    "rate": ("rate about its axis h·ω [deg/s]", "ref"),
    "other": ("rate about the other axes [deg/s]", "ref"),
    "rate2": ("rate² (h·ω)² [deg²/s²]", "ref"),
    "accel": ("angular acceleration d(h·ω)/dt [deg/s²]", "ref"),
    "temp": ("temperature [°C]", "temp"),
    "time": ("time [s]", None),
}

#: Channels of the localisation: display unit and the factor from SI.
CHANNEL_UNITS = {"time": ("s", 1.0), "rate": ("deg/s", 1.0 / units.RAD_PER_DEG),
                 "rate²": ("deg²/s²", units.RAD_PER_DEG ** -2),
                 "angular acceleration": ("deg/s²", 1.0 / units.RAD_PER_DEG),
                 "temperature": ("°C", 1.0), "dT/dt": ("°C/s", 1.0)}


# -- JSON of nested dataclasses with arrays ------------------------------------------

def _enc(v):
    if isinstance(v, _Json):
        return v.to_dict()
    if isinstance(v, np.ndarray):
        a = np.asarray(v, float)
        return {"shape": list(a.shape), "data": [None if not math.isfinite(x) else float(x)
                                                 for x in a.ravel()]}
    if isinstance(v, (list, tuple)):
        return [_enc(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return None if not math.isfinite(float(v)) else float(v)
    if isinstance(v, (np.integer, np.bool_)):
        return v.item()
    return v


def _arr(d) -> np.ndarray:
    return np.array([math.nan if x is None else x for x in d["data"]], float).reshape(d["shape"])


class _Json:
    """``to_dict``/``from_dict`` of a dataclass: arrays, nested classes, lists of them."""

    _arrays: tuple[str, ...] = ()
    _nested: dict = {}
    _floats: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """JSON-ready dict (arrays as ``{"shape", "data"}``, NaN as None)."""
        return {f.name: _enc(getattr(self, f.name)) for f in fields(self)}   # type: ignore[arg-type]

    @classmethod
    def from_dict(cls, d: dict):
        """The inverse of :meth:`to_dict`."""
        kw: dict = {}
        for f in fields(cls):                                                 # type: ignore[arg-type]
            v = d[f.name]
            if v is None:
                kw[f.name] = math.nan if f.name in cls._floats else None
            elif f.name in cls._arrays:
                kw[f.name] = [None if x is None else _arr(x) for x in v] if isinstance(v, list) \
                    else _arr(v)
            elif f.name in cls._nested:
                sub = cls._nested[f.name]
                kw[f.name] = [sub.from_dict(x) for x in v] if isinstance(v, list) else sub.from_dict(v)
            else:
                kw[f.name] = v
        return cls(**kw)


# -- the figure data ------------------------------------------------------------------

@dataclass
class Binned(_Json):
    """A series binned in ``x``: bin centres, means and standard errors of the means."""

    x: np.ndarray
    mean: np.ndarray
    stderr: np.ndarray
    _arrays = ("x", "mean", "stderr")


@dataclass
class RegressorPanel(_Json):
    """One panel: the residual [deg/h] binned against one regressor (its ``label`` has the unit).

    ``line_x``/``line_y_deg_h``: the candidate's fitted line (``line_y_deg_h`` None
    when the candidate is not significant: only its ``line_label`` is shown).
    """

    key: str
    label: str
    binned: Binned
    line_x: np.ndarray | None = None
    line_y_deg_h: np.ndarray | None = None
    line_label: str | None = None
    _arrays = ("line_x", "line_y_deg_h")
    _nested = {"binned": Binned}


@dataclass
class RegressorFigure(_Json):
    """Gyro ``gyro`` (from 1): its panels and the fitted bias [deg/h] over time [s] (thinned)."""

    gyro: int
    panels: list[RegressorPanel]
    time_s: np.ndarray
    bias_deg_h: np.ndarray
    _arrays = ("time_s", "bias_deg_h")
    _nested = {"panels": RegressorPanel}


@dataclass
class PsdFigure(_Json):
    """Residual ASD [deg/h/√Hz] per gyro (columns) over ``freq_hz`` and log-binned.

    ``white_deg_h_rt_hz``: the model's ARW level per gyro (None: no ARW);
    ``model_deg_h_rt_hz``: its ARW + RRW curve per gyro (None: no RRW).
    """

    freq_hz: np.ndarray
    asd_deg_h_rt_hz: np.ndarray
    freq_binned_hz: np.ndarray
    asd_binned_deg_h_rt_hz: np.ndarray
    white_deg_h_rt_hz: list
    model_deg_h_rt_hz: list
    _arrays = ("freq_hz", "asd_deg_h_rt_hz", "freq_binned_hz", "asd_binned_deg_h_rt_hz",
               "model_deg_h_rt_hz")


@dataclass
class XcorrFigure(_Json):
    """Correlation [-] between the gyros' residuals: of the samples' first differences
    (``fast``) and of the first differences of ``block_s`` means (``slow``, None with
    fewer than 8 blocks); ``n_samples``, ``n_blocks``: what each was computed from."""

    fast: np.ndarray
    slow: np.ndarray | None
    block_s: float
    n_samples: int
    n_blocks: int
    _arrays = ("fast", "slow")


@dataclass
class ArwTrackFigure(_Json):
    """ARW [deg/√h] of each gyro's residual (columns) in sliding windows (DAVAR at τ₀),
    at the windows' centres ``time_s`` [s], with its 1σ band."""

    window_s: float
    step_s: float
    time_s: np.ndarray
    arw_deg_rt_h: np.ndarray
    ci_low_deg_rt_h: np.ndarray
    ci_high_deg_rt_h: np.ndarray
    _arrays = ("time_s", "arw_deg_rt_h", "ci_low_deg_rt_h", "ci_high_deg_rt_h")


@dataclass
class ChannelPanel(_Json):
    """The residual [deg/h] (mean removed) binned against one channel (display ``unit``), per gyro."""

    name: str
    unit: str
    per_gyro: list[Binned]
    _nested = {"per_gyro": Binned}


@dataclass
class LocalisePsd(_Json):
    """The localisation's residual PSD [rad²/s²/Hz] per gyro (columns), without the DC bin,
    and log-binned."""

    freq_hz: np.ndarray
    psd: np.ndarray
    freq_binned_hz: np.ndarray
    psd_binned: np.ndarray
    _arrays = ("freq_hz", "psd", "freq_binned_hz", "psd_binned")


@dataclass
class CompareFigures(_Json):
    """Everything the compare report's figures draw beyond the analyses themselves.

    Attributes
    ----------
    regressor_keys : list of str
        The regressors the record has (:data:`REGRESSORS` keys).
    has_ref, has_temp : bool
        The record has a turning reference rate / a temperature.
    regressors : list of RegressorFigure
        One per gyro, of the first step.
    psd : PsdFigure
        Of the first step, over its record.
    xcorr : XcorrFigure or None
        Of the first step (None: one gyro).
    arw_track : ArwTrackFigure
        Of the first step.
    localise_psd : LocalisePsd or None
        Of the final step when it has a localisation.
    localise_channels : list of ChannelPanel
        Of the final step when it has a localisation (empty otherwise).
    """

    regressor_keys: list[str]
    has_ref: bool
    has_temp: bool
    regressors: list[RegressorFigure]
    psd: PsdFigure
    xcorr: XcorrFigure | None
    arw_track: ArwTrackFigure
    localise_psd: LocalisePsd | None = None
    localise_channels: list[ChannelPanel] = field(default_factory=list)
    _nested = {"regressors": RegressorFigure, "psd": PsdFigure, "xcorr": XcorrFigure,
               "arw_track": ArwTrackFigure, "localise_psd": LocalisePsd,
               "localise_channels": ChannelPanel}


# -- the computations -------------------------------------------------------------------

def fitted_bias(E: np.ndarray, t: np.ndarray, static: np.ndarray) -> np.ndarray:
    """Per-gyro mean of ``E`` over the static samples of each BIAS_BLOCK_S block, linear in time."""
    blk = np.floor((t - t[0]) / BIAS_BLOCK_S).astype(np.int64)
    nb = int(blk[-1]) + 1
    w = static.astype(float)
    cnt = np.bincount(blk, weights=w, minlength=nb)
    tc = np.bincount(blk, weights=w * t, minlength=nb)
    ok = cnt >= max(10, 0.05 * BIAS_BLOCK_S / max(t[1] - t[0], 1e-12))
    if not ok.any():
        ok = cnt > 0
    out = np.empty_like(E)
    for g in range(E.shape[1]):
        s = np.bincount(blk, weights=w * E[:, g], minlength=nb)
        out[:, g] = np.interp(t, tc[ok] / cnt[ok], s[ok] / cnt[ok])
    return out


def binned(x: np.ndarray, y: np.ndarray, full_range: bool = False):
    """Centres, means and standard errors of ``y`` in N_BINS uniform bins of ``x``."""
    if full_range:
        lo, hi = float(x.min()), float(x.max())
    else:
        lo, hi = (float(v) for v in np.percentile(x, [0.5, 99.5]))
    if not hi > lo:
        return np.array([]), np.array([]), np.array([])
    edges = np.linspace(lo, hi, N_BINS + 1)
    keep = (x >= lo) & (x <= hi)
    i = np.clip(np.searchsorted(edges, x[keep], side="right") - 1, 0, N_BINS - 1)
    yk = y[keep]
    c = np.bincount(i, minlength=N_BINS).astype(float)
    s = np.bincount(i, weights=yk, minlength=N_BINS)
    s2 = np.bincount(i, weights=yk * yk, minlength=N_BINS)
    ok = c >= MIN_BIN
    m = s[ok] / c[ok]
    var = np.maximum(s2[ok] / c[ok] - m * m, 0.0) * c[ok] / (c[ok] - 1.0)
    return 0.5 * (edges[:-1] + edges[1:])[ok], m, np.sqrt(var / c[ok])


def log_binned(f: np.ndarray, p: np.ndarray, per_decade: int = 20):
    """Mean of a spectrum in log-spaced frequency bins (the level, for the eye)."""
    edges = np.logspace(math.log10(f[0]), math.log10(f[-1]) + 1e-9, max(
        2, int(per_decade * math.log10(f[-1] / f[0])) + 1))
    i = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, edges.size - 2)
    c = np.bincount(i, minlength=edges.size - 1)
    ok = c > 0
    fc = np.bincount(i, weights=np.log(f), minlength=edges.size - 1)[ok] / c[ok]
    out = np.stack([np.bincount(i, weights=p[:, g], minlength=edges.size - 1)[ok] / c[ok]
                    for g in range(p.shape[1])], axis=1)
    return np.exp(fc), out


def model_asd_deg_h(f_hz: np.ndarray, n_deg_rt_h: float, k_deg_h_rt_h: float) -> np.ndarray:
    """One-sided ASD [deg/h/√Hz] of ARW N [deg/√h] + RRW K [deg/h/√h] at ``f_hz``.

    S(f) = 2 N² + K² / (2 π² f²) [rad²/s²/Hz] with N [rad/√s], K [rad/s/√s]
    (white: two-sided N², one-sided twice that; random walk: two-sided
    K² / (4 π² f²)).
    """
    n = units.arw_deg_rt_h_to_rad_rt_s(n_deg_rt_h)
    k = units.rrw_deg_h_rt_h_to_rad_s_rt_s(k_deg_h_rt_h)
    f = np.asarray(f_hz, float)
    return units.rad_s_to_deg_h(np.sqrt(2.0 * n ** 2 + k ** 2 / (2.0 * math.pi ** 2 * f ** 2)))


def residual_correlation(X: np.ndarray) -> np.ndarray:
    """Correlation [-] between the columns' first differences."""
    d = np.diff(X, axis=0)
    d = d - d.mean(axis=0)
    s = np.sqrt(np.sum(d * d, axis=0))
    s[s == 0] = 1.0
    return (d.T @ d) / np.outer(s, s)


def channel_effects(channel: str) -> list[str]:
    """The effects whose residual follows ``channel`` (``Effect.channel``), registry order."""
    return [e.name for e in REGISTRY.values() if e.channel == channel]


def channel_candidate(analysis, channel: str, gyro):
    """The best candidate (first in rank) of the effects of ``channel`` on ``gyro``."""
    names = set(channel_effects(channel))
    return next((t for t in analysis.candidates if t.effect in names and t.gyro == gyro), None)


def channel_in_model(analysis, channel: str, gyro):
    """The model entry of an effect of ``channel`` on ``gyro``, or None."""
    names = set(channel_effects(channel))
    return next((e for e in analysis.model if e.effect in names and e.gyro == gyro), None)


class Regressors:
    """The regressors of one comparison and the fitted bias of one analysis's residual."""

    def __init__(self, comp, analysis):
        self.comp = comp
        self.t = np.asarray(comp.t, float)
        self.E = np.asarray(analysis.residual_rad_s, float)
        self.static = np.asarray(analysis.static, bool)
        self.bias = fitted_bias(self.E, self.t, self.static)
        self.has_ref = comp.ref is not None and comp.moving     # a table that never turns: no rates
        self.has_temp = comp.temp is not None
        self.keys = [k for k, (_, need) in REGRESSORS.items()
                     if need is None or (need == "ref" and self.has_ref)
                     or (need == "temp" and self.has_temp)]

    def values(self, key: str, g: int, analysis) -> tuple[np.ndarray, str]:
        """(regressor in display units, axis label) of gyro index ``g``."""
        label = REGRESSORS[key][0]
        if key == "time":
            return self.t, label
        if key == "temp":
            return np.asarray(self.comp.temp, float), label
        h = self.comp.H[g]
        ref = np.asarray(self.comp.ref, float)
        u = units.rad_s_to_deg_s(ref @ h)
        if key == "rate":
            return u, label
        if key == "rate2":
            return u * u, label
        if key == "accel":
            return np.gradient(u, self.comp.dt), label
        # rate about the other axes, signed along the direction of the tilt the residual shows
        perp = units.rad_s_to_deg_s(ref - np.outer(ref @ h, h))
        d = self._tilt_direction(g, perp, analysis)
        if d is None:
            return np.linalg.norm(perp, axis=1), label.replace("[deg/s]", "(norm) [deg/s]")
        return perp @ d, label.replace("[deg/s]", "(toward the tilt) [deg/s]")

    def _tilt_direction(self, g: int, perp: np.ndarray, analysis):
        t = channel_candidate(analysis, "other", g + 1)
        h = self.comp.H[g]
        if t is not None and t.fit is not None and "axis" in t.fit.extra:
            a = np.asarray(t.fit.extra["axis"], float)
            v = a - (a @ h) * h
            if np.linalg.norm(v) > 0:
                return v / np.linalg.norm(v)
        moving = ~self.static
        if moving.sum() < 3 * MIN_BIN:
            return None
        y = self.E[moving, g] - self.bias[moving, g]
        beta, *_ = np.linalg.lstsq(perp[moving], y, rcond=1e-8)
        nb = float(np.linalg.norm(beta))
        return beta / nb if nb > 0 else None


def _fit_line(key: str, analysis, g: int, xb, yb, sb):
    """(x, y [deg/h] or None, label) of the panel's candidate fit, or None.

    The candidate is the effect whose ``channel`` the panel shows; its
    ``Effect.channel_line`` gives the line. The line (y) only for a
    significant candidate: the fit of an absent effect can be large and
    uncertain, and a steep line across flat points would say the opposite of
    its z; the label (value ± 1σ) always.
    """
    t = channel_candidate(analysis, key, g + 1)
    if t is None or t.fit is None or not np.isfinite(t.z) or xb.size < 2:
        return None
    x = np.linspace(xb.min(), xb.max(), 50)
    w = 1.0 / np.maximum(sb, 1e-12) ** 2
    xm, ym = float(np.average(xb, weights=w)), float(np.average(yb, weights=w))
    line = get_effect(t.effect).channel_line(t.fit, x, xm, ym)
    if line is None:
        return None
    return (x, line[0] if analysis.significant(t) else None, line[1])


def _regressor_figure(reg: Regressors, analysis, g: int) -> RegressorFigure:
    to = units.rad_s_to_deg_h
    e = reg.E[:, g]
    e_fast = to(e - reg.bias[:, g])
    offset = float(np.mean(e[reg.static])) if reg.static.any() else float(np.mean(e))
    e_slow = to(e - offset)
    thin = max(1, reg.t.size // BIAS_POINTS)
    panels = []
    for key in reg.keys:
        x, label = reg.values(key, g, analysis)
        y = e_slow if key in ("temp", "time") else e_fast
        xb, yb, sb = binned(x, y, full_range=key == "time")
        line = _fit_line(key, analysis, g, xb, yb, sb) if xb.size else None
        panels.append(RegressorPanel(key=key, label=label, binned=Binned(xb, yb, sb),
                                     line_x=None if line is None else line[0],
                                     line_y_deg_h=None if line is None else line[1],
                                     line_label=None if line is None else line[2]))
    return RegressorFigure(gyro=g + 1, panels=panels, time_s=reg.t[::thin],
                           bias_deg_h=to(reg.bias[::thin, g] - offset))


def _psd_figure(comp, analysis) -> PsdFigure:
    E = np.asarray(analysis.residual_rad_s, float)[analysis.record]
    n, N = E.shape
    nper = int(min(n, max(256, min(8192, n // 8))))
    f, P = welch(E, fs=1.0 / comp.dt, nperseg=nper, axis=0, detrend="linear")
    f, P = f[1:], P[1:]
    fb, Pb = log_binned(f, P)
    to = units.rad_s_to_deg_h
    white, model = [], []
    for g in range(N):
        a, k = analysis.baseline_noise(g + 1)
        white.append(None if a is None else float(model_asd_deg_h(np.array([f[-1]]), a, 0.0)[0]))
        model.append(model_asd_deg_h(f, a, k) if a is not None and k is not None else None)
    return PsdFigure(freq_hz=f, asd_deg_h_rt_hz=to(np.sqrt(P)), freq_binned_hz=fb,
                     asd_binned_deg_h_rt_hz=to(np.sqrt(Pb)), white_deg_h_rt_hz=white,
                     model_deg_h_rt_hz=model)


def _xcorr_figure(comp, analysis) -> XcorrFigure:
    E = np.asarray(analysis.residual_rad_s, float)[analysis.record]
    n, N = E.shape
    fast = residual_correlation(E)
    blk = max(1, int(round(max(1.0, n * comp.dt / 200.0) / comp.dt)))
    nb = n // blk
    slow = residual_correlation(E[:nb * blk].reshape(nb, blk, N).mean(axis=1)) if nb >= 8 else None
    return XcorrFigure(fast=fast, slow=slow, block_s=float(blk * comp.dt), n_samples=int(n),
                       n_blocks=int(nb))


def _arw_track_figure(comp, analysis) -> ArwTrackFigure:
    E = np.asarray(analysis.residual_rad_s, float)
    n, N = E.shape
    dt = comp.dt
    window = int(min(max(64, round(ARW_WINDOW_S / dt)), max(64, n // 8)))
    step = max(1, window // 4)
    to = units.arw_rad_rt_s_to_deg_rt_h
    cols = [davar(E[:, g], dt, window=window, step=step, taus=[dt], extension="mirror")
            for g in range(N)]
    return ArwTrackFigure(window_s=float(window * dt), step_s=float(step * dt),
                          time_s=float(comp.t[0]) + cols[0].time_s,
                          arw_deg_rt_h=np.stack([to(c.arw_rad_rt_s) for c in cols], axis=1),
                          ci_low_deg_rt_h=np.stack([to(c.arw_ci_low_rad_rt_s) for c in cols], axis=1),
                          ci_high_deg_rt_h=np.stack([to(c.arw_ci_high_rad_rt_s) for c in cols], axis=1))


def _localise(comp, final) -> tuple[LocalisePsd, list[ChannelPanel]]:
    loc = final.localised
    f = loc.psd_freq_hz[1:]
    P = loc.psd_residual[:, 1:].T
    fb, Pb = log_binned(f, P)
    rate = None if comp.ref is None else comp.ref @ comp.H.T
    chans = record_channels(comp.n, comp.N, rate, None, comp.acc, comp.temp, comp.t, comp.dt, None)
    E = final.residual_rad_s - final.residual_rad_s.mean(axis=0)
    to = units.rad_s_to_deg_h
    panels = []
    for name, v in chans.items():
        unit, k = CHANNEL_UNITS.get(name, ("m/s²", 1.0))
        per = []
        for g in range(comp.N):
            xc, m, se = binned((v if v.ndim == 1 else v[:, g]) * k, E[:, g])
            per.append(Binned(xc, to(m), to(se)))
        panels.append(ChannelPanel(name=name, unit=unit, per_gyro=per))
    return LocalisePsd(freq_hz=f, psd=P, freq_binned_hz=fb, psd_binned=Pb), panels


def compare_figures(comp, steps) -> CompareFigures:
    """The figure data of a comparison's report (module docstring).

    Parameters
    ----------
    comp : gyroarray.chain.compare.ModelComparison
    steps : list of (tuple or None, Analysis)
        The ladder (first step: the model before fitting; last: the final model).

    Returns
    -------
    CompareFigures
    """
    first, final = steps[0][1], steps[-1][1]
    reg = Regressors(comp, first)
    loc_psd: LocalisePsd | None = None
    loc_ch: list[ChannelPanel] = []
    if final.localisation and final.localised is not None:
        loc_psd, loc_ch = _localise(comp, final)
    return CompareFigures(regressor_keys=list(reg.keys), has_ref=bool(reg.has_ref),
                          has_temp=bool(reg.has_temp),
                          regressors=[_regressor_figure(reg, first, g) for g in range(comp.N)],
                          psd=_psd_figure(comp, first),
                          xcorr=_xcorr_figure(comp, first) if comp.N >= 2 else None,
                          arw_track=_arw_track_figure(comp, first),
                          localise_psd=loc_psd, localise_channels=loc_ch)
