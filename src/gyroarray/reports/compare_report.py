"""The model-vs-measurement report: one self-contained HTML file and a Markdown twin.

:func:`write_compare_report` draws what :class:`gyroarray.chain.compare.ModelComparison`
found, for people who would rather look than read:

1. **headline**: the measurement (gyros, layout, duration, rate, what columns
   it has), the model, and the **discrepancy** ``D = max z / z_crit`` (Šidák,
   family-wise ``alpha`` over the K tests; D <= 1: consistent);
2. **the error falling** (a ladder of several steps): D after each added effect;
3. **effects found**: the final model's effects, params ± 1σ in the spec's
   units, and the baseline ARW/RRW of every gyro;
4. **what is still unexplained**: when the model is not consistent, the
   ranked localisation of the final step (``Analysis.localisation``: τ range,
   frequency band and shape, time window, gyros, channels) with the residual
   PSD against the model's Monte-Carlo PSD band and the residual against
   every channel of the record; else the unexplained sentences;
5. **candidates**: the best candidate effects of the final (and the first) step;
6. **where the model fails**, per gyro, for the *first* step (what a user wants
   to see before fitting anything):

   * measured ADEV against the model's Monte-Carlo 95 % band;
   * the residual, binned, against each regressor of a deterministic effect
     (rate about the gyro's axis, rate about the other axes, rate²,
     angular acceleration, temperature, time), each panel labelled with the
     z of its candidate; the fast regressors after removing the "fitted
     bias" (the residual's mean over the static samples of 30 s blocks,
     linear in time), temperature and time only after removing its static
     mean (the fitted bias would take their slow signal with it);
   * the residual's amplitude spectral density with the sinusoid candidates;
   * the correlation between gyros;
   * the ARW in sliding windows (dynamic Allan deviation at τ₀) with the
     burst candidate;

   and the ADEV band again after the last step;
7. the notes of the analysis.

The HTML has its figures as ``data:image/png;base64`` URIs, its style inline
and no script: it opens anywhere, offline. The Markdown twin has the same
tables and links the same figures, written as PNG files into
``<md stem>_figures/`` beside it.

SI inside; deg/h, deg/s, deg/√h... only on the axes and in the tables
(through :mod:`gyroarray.core.units`).
"""

from __future__ import annotations

import html
import math
import time
from pathlib import Path

import numpy as np
from scipy import stats

from gyroarray.core import units
from gyroarray.chain.compare import Analysis
from gyroarray.chain.compare_figures import (BIAS_BLOCK_S, REGRESSORS, ArwTrackFigure, ChannelPanel,
                                             CompareFigures, LocalisePsd, PsdFigure, RegressorFigure,
                                             XcorrFigure, channel_candidate, channel_effects,
                                             channel_in_model, compare_figures)
from gyroarray.effects import REGISTRY, get_effect
from gyroarray.core.errors import InputError
from gyroarray.reports.design_plots import agg_figure, figure_png
from gyroarray.reports.report import Doc, format_value

__all__ = ["write_compare_report", "section_unexplained"]

#: Candidates listed per step.
TOP = 15
#: Resolution of the figures [dpi] (the HTML stays a few MB for 8 gyros).
DPI = 88

_RED, _GREEN, _GREY = "#c0392b", "#1e8449", "0.45"

_EXTRA_CSS = f"""
.headline {{ display: flex; gap: 2em; align-items: center; flex-wrap: wrap;
  border: 1px solid #ddd; border-radius: 6px; padding: 0.8em 1.2em; margin: 1em 0; }}
.big {{ font-size: 3.2em; font-weight: 700; line-height: 1.1; }}
.big.ok {{ color: {_GREEN}; }} .big.bad {{ color: {_RED}; }}
.verdict {{ font-size: 1.3em; font-weight: 600; }}
.why {{ color: #555; font-size: 0.92em; max-width: 46em; }}
table.facts th {{ text-align: left; font-weight: 600; }} table.facts td {{ text-align: left; }}
"""


# -- small helpers ---------------------------------------------------------------

def _d(x: float) -> str:
    """A discrepancy as printed everywhere (headline, tables, figures)."""
    x = float(x)
    if not math.isfinite(x):
        return "–"
    return f"{x:.3g}" if x < 1e4 else f"{x:.3e}"


def _z(x) -> str:
    if x is None or np.isnan(x):
        return "–"
    if np.isinf(x):
        return "∞" if x > 0 else "−∞"
    return f"{x:.3g}" if abs(x) < 1e4 else f"{x:.2e}"


def _pm(v, s) -> str:
    if isinstance(v, (list, tuple, np.ndarray)):
        return "(" + ", ".join(format_value(float(x)) for x in np.ravel(v)) + ")"
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        return str(v)
    if s is None or not np.isfinite(s):
        return format_value(float(v))
    return f"{format_value(float(v))} ± {format_value(float(s), 2)}"


def _raw(doc: Doc, html_text: str, md_text: str):
    """Already-escaped HTML and its Markdown."""
    doc.html.append(html_text)
    doc.md += [md_text, ""]


def _grid(n: int, ncols: int, w: float, h: float, *, title: bool = True):
    """A figure of ``n`` panels of ``w`` × ``h`` inches in rows of ``ncols``.

    Placed by hand (fixed margins in inches for the labels and the title):
    a constrained layout draws every figure twice, which doubles the
    report's time.
    """
    # deferred: matplotlib loads only when a figure is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    ncols = max(1, min(ncols, n))
    nrows = math.ceil(n / ncols)
    W = w * ncols
    top = (0.42 if W >= 10.0 else 0.7) if title else 0.08     # narrow: the legend below the title
    H = h * nrows + top
    fig = Figure(figsize=(W, H))
    FigureCanvasAgg(fig)
    left, right, bottom, above = 0.72, 0.14, 0.48, 0.3     # inside each cell [in]
    axs = []
    for k in range(n):
        i, j = divmod(k, ncols)
        x0 = j * w + left
        y0 = H - top - (i + 1) * h + bottom
        axs.append(fig.add_axes((x0 / W, y0 / H, (w - left - right) / W, (h - bottom - above) / H)))
    return fig, axs


def _log_ticks(ax, x: bool = True, y: bool = True):
    """Plain tick labels on log axes (1, 2, 5 per decade when the range is short), no minor ticks.

    Minor log ticks cost most of a figure's drawing time and their labels
    crowd the small panels.
    """
    from matplotlib import ticker  # deferred: matplotlib loads only when a figure is drawn
    ax.minorticks_off()
    for on, axis, lim in ((x, ax.xaxis, ax.get_xlim()), (y, ax.yaxis, ax.get_ylim())):
        if not on:
            continue
        lo, hi = (max(v, 1e-300) for v in lim)
        decades = abs(math.log10(hi / lo))
        subs = (1.0, 2.0, 5.0) if decades < 1.6 else (1.0,)
        axis.set_major_locator(ticker.LogLocator(base=10.0, subs=subs, numticks=8))
        axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_locator(ticker.NullLocator())


def _header(fig, title: str, axs):
    """Title at the top left, one legend of every labelled artist at the top right."""
    if title:
        fig.text(0.06 / fig.get_figwidth(), 1 - 0.1 / fig.get_figheight(), title, fontsize=10,
                 va="top", ha="left")
    seen: dict[str, object] = {}                       # label -> its first artist
    for ax in axs:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(lab, h)
    if not seen:
        return
    W, H = fig.get_figwidth(), fig.get_figheight()
    if W >= 10.0:
        fig.legend(list(seen.values()), list(seen.keys()), loc="upper right", ncols=min(len(seen), 5),
                   fontsize=7.5, frameon=False, bbox_to_anchor=(1 - 0.1 / W, 1.0))
    else:
        fig.legend(list(seen.values()), list(seen.keys()), loc="upper left", ncols=min(len(seen), 3),
                   fontsize=7, frameon=False, bbox_to_anchor=(0.0, 1 - 0.28 / H))


def _baseline() -> list[str]:
    return [e.name for e in REGISTRY.values() if e.baseline]


def _model_text(model, n_gyros: int) -> str:
    """``baseline ARW + RRW on every gyro + scale_factor (gyro 2) + ...``."""
    have = {(e.effect, e.gyro) for e in model}
    base = _baseline()
    full = all((eff, g) in have for eff in base for g in range(1, n_gyros + 1))
    rest = [e.label for e in model if not (full and e.effect in base)]
    head = [f"baseline {' + '.join(b.upper() for b in base)} on every gyro"] if full else []
    return " + ".join(head + rest)


def _candidate(analysis, effect: str, gyro):
    return next((t for t in analysis.candidates if t.effect == effect and t.gyro == gyro), None)


def _status(analysis, channel: str, gyro) -> tuple[str, str]:
    """(text, colour) of a channel's effect for a panel title: its candidate z, "in model" or "not tested"."""
    e = channel_in_model(analysis, channel, gyro)
    if e is not None:
        return f"{e.effect}: in model", _GREEN
    t = channel_candidate(analysis, channel, gyro)
    if t is None:
        names = channel_effects(channel)
        return f"{names[0] if names else channel}: not tested", _GREY
    effect = t.effect
    if np.isnan(t.z):
        return f"{effect}: not identifiable here", _GREY
    if analysis.significant(t):
        return f"{effect}: z = {_z(t.z)} (significant)", _RED
    return f"{effect}: z = {_z(t.z)}", "0.15"


def _record_text(comp, analysis) -> str:
    """``the whole record (0–480 s)`` / ``the longest static part (0–240 s)``."""
    a, b = analysis.record.start or 0, analysis.record.stop if analysis.record.stop is not None else comp.n
    span = f"{comp.t[a]:.0f}–{comp.t[b - 1] + comp.dt:.0f} s"
    return f"the whole record ({span})" if (a, b) == (0, comp.n) else f"the longest static part ({span})"


def _band_tests(analysis) -> dict:
    return {t.gyro: t for t in analysis.tests if t.kind == "adev_band"}


# -- figures ---------------------------------------------------------------------

def _ladder_fig(steps) -> bytes:
    """Discrepancy after each step (log y) with the line D = 1."""
    d = np.array([a.discrepancy for _, a in steps], float)
    labels = ["start"] + [f"+ {e}" + ("" if g is None else f":{g}") for (e, g), _ in steps[1:]]
    fig, axs = agg_figure(max(5.0, 1.3 * len(steps) + 2.0), 3.8)
    ax = axs[0]
    x = np.arange(len(steps))
    dd = np.maximum(d, 1e-3)
    colors = [_GREEN if v <= 1.0 else _RED for v in d]
    ax.bar(x, dd, color=colors, alpha=0.85, width=0.6)
    ax.plot(x, dd, "-", color="0.3", lw=1)
    for xi, v in zip(x, d):
        ax.annotate(_d(v), (xi, max(v, 1e-3)), xytext=(0, 3), textcoords="offset points",
                    ha="center", va="bottom", fontsize=9, fontweight="bold")
    ax.axhline(1.0, color="k", lw=1, ls="--")
    ax.text(x[-1] + 0.45, 1.0, " D = 1", va="bottom", ha="right", fontsize=8)
    ax.set_yscale("log")
    lo = min(0.3, dd.min() / 2.0)
    ax.set_ylim(lo, max(3.0, dd.max() * 3.0))
    _log_ticks(ax, x=False)
    ax.set_xticks(x, labels, fontsize=8, rotation=20 if len(steps) > 4 else 0)
    ax.set(ylabel="discrepancy D [-]", title="Discrepancy after each step (green: consistent)")
    ax.grid(alpha=0.3, axis="y")
    return figure_png(fig, DPI)


def _adev_fig(analysis, n_gyros: int, title: str) -> bytes:
    """Measured ADEV against the model's 95 % Monte-Carlo band, one panel per gyro."""
    a = analysis.adev
    taus = np.asarray(a["taus_s"], float)
    to = units.rad_s_to_deg_h
    band = _band_tests(analysis)
    runs = int(np.shape(a["mc"])[0])
    tq = float(stats.t.ppf(0.975, max(runs - 1, 1)))    # the band's own edge (compare._adev_band)
    fig, axs = _grid(n_gyros, 4, 3.4, 2.9)
    for g, ax in enumerate(axs):
        ax.fill_between(taus, to(a["lo"][g]), to(a["hi"][g]), color="C0", alpha=0.22, lw=0,
                        label="model 95 % band")
        ax.loglog(taus, to(a["median"][g]), "--", color="C0", lw=1.2, label="model median")
        t = band.get(g + 1)
        tk = np.asarray(t.extra.get("t", []), float) if t is not None else np.array([])
        out = np.abs(tk) > tq if tk.size == taus.size else np.zeros(taus.size, bool)
        ax.loglog(taus, to(a["measured"][g]), "-", color="k", lw=0.8)
        ax.loglog(taus[~out], to(a["measured"][g][~out]), "o", color="k", ms=3, label="measured")
        if out.any():
            ax.loglog(taus[out], to(a["measured"][g][out]), "o", color=_RED, ms=4,
                      label="measured, outside the band")
        if t is not None:
            sig = analysis.significant(t)
            ax.set_title(f"gyro {g + 1}: band z = {_z(t.z)}" + (" (significant)" if sig else ""),
                         fontsize=9, color=_RED if sig else "0.15", y=1.0, pad=4)
        else:
            ax.set_title(f"gyro {g + 1}", fontsize=9, y=1.0, pad=4)
        _log_ticks(ax)
        ax.grid(alpha=0.3)
        ax.set_xlabel("τ [s]", fontsize=8)
        ax.set_ylabel("ADEV [deg/h]", fontsize=8)
        ax.tick_params(labelsize=7)
    _header(fig, title, axs)
    return figure_png(fig, DPI)


def _regressor_fig(rf: RegressorFigure, analysis) -> bytes:
    """Binned residual of gyro ``rf.gyro`` against every available regressor."""
    g = rf.gyro - 1
    panels = rf.panels
    fig, axs = _grid(len(panels), 3, {1: 7.0, 2: 5.0}.get(len(panels), 4.2), 3.0)
    for ax, pan in zip(axs, panels):
        key = pan.key
        xb, yb, sb = pan.binned.x, pan.binned.mean, pan.binned.stderr
        if xb.size:
            ax.errorbar(xb, yb, yerr=2.0 * sb, fmt="o", ms=3, color="C0", ecolor="C0", elinewidth=1,
                        capsize=2, label="binned mean ± 2 standard errors")
        if key == "time":
            ax.plot(rf.time_s, rf.bias_deg_h, "-", color="C1", lw=1,
                    label=f"fitted bias (static samples, {BIAS_BLOCK_S:.0f} s blocks)")
        text, color = _status(analysis, key, g + 1)
        if pan.line_label is not None:
            lc = color if color != "0.15" else _GREY
            if pan.line_y_deg_h is not None:
                ax.plot(pan.line_x, pan.line_y_deg_h, "--", color=lc, lw=1.2,
                        label="significant candidate's fit")
            ax.text(0.02, 0.97, pan.line_label, transform=ax.transAxes, va="top", ha="left",
                    fontsize=7, color=lc)
        ax.axhline(0.0, color="0.6", lw=0.7)
        ax.set_xlabel(pan.label, fontsize=8)
        ax.set_ylabel("residual [deg/h]", fontsize=8)
        ax.set_title(text, fontsize=9, color=color, y=1.0, pad=4)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    _header(fig, f"Gyro {g + 1}: residual against the regressors"
            + (" of the deterministic effects" if len(panels) > 2 else ""), axs)
    return figure_png(fig, DPI)


def _asd_axes(ax):
    """Log ticks, grid and labels of an amplitude-spectral-density panel."""
    _log_ticks(ax)
    ax.grid(alpha=0.3)
    ax.set_xlabel("frequency [Hz]", fontsize=8)
    ax.set_ylabel("ASD [deg/h/√Hz]", fontsize=8)
    ax.tick_params(labelsize=7)


def _psd_fig(p: PsdFigure, analysis) -> bytes:
    """Residual ASD per gyro over the record, with the sinusoid candidates and the model's level."""
    f = p.freq_hz
    N = p.asd_deg_h_rt_hz.shape[1]
    fig, axs = _grid(N, 4, 3.4, 2.9)
    for g, ax in enumerate(axs):
        ax.loglog(f, p.asd_deg_h_rt_hz[:, g], color="0.72", lw=0.5, label="residual (Welch)")
        ax.loglog(p.freq_binned_hz, p.asd_binned_deg_h_rt_hz[:, g], color="k", lw=1.1,
                  label="residual, log-binned")
        white = p.white_deg_h_rt_hz[g]
        if white is not None:
            ax.axhline(white, color="C0", ls="--", lw=1, label="model ARW level")
            model = p.model_deg_h_rt_hz[g]
            if model is not None:
                ax.loglog(f, model, color="C0", lw=1, alpha=0.7, label="model ARW + RRW")
            lo, hi = ax.get_ylim()
            if white > 0:     # at least a decade around the white level: the noise looks calm
                ax.set_ylim(min(lo, white / 2.5) if lo > 0 else white / 2.5, max(hi, white * 2.5))
        title, color = f"gyro {g + 1}", "0.15"
        t = channel_candidate(analysis, "spectrum", g + 1)
        e = channel_in_model(analysis, "spectrum", g + 1)
        fq = math.nan
        if e is not None and (e.effect, g + 1) in analysis.fits:
            fq = float(analysis.fits[(e.effect, g + 1)].params.get("freq_hz", math.nan))
            title, color = f"gyro {g + 1}: {e.effect} {fq:.4g} Hz in model", _GREEN
        elif t is not None and t.fit is not None and np.isfinite(t.fit.params.get("freq_hz", np.nan)):
            fq = float(t.fit.params["freq_hz"])
            sig = analysis.significant(t)
            title = f"gyro {g + 1}: {t.effect} {fq:.4g} Hz, z = {_z(t.z)}"
            color = _RED if sig else "0.15"
        if np.isfinite(fq) and f[0] <= fq <= f[-1]:
            ax.axvline(fq, color=color if color != "0.15" else _GREY, lw=1, ls=":",
                       label="line candidate")
        ax.set_title(title, fontsize=9, color=color, y=1.0, pad=4)
        _asd_axes(ax)
    _header(fig, "Residual amplitude spectral density", axs)
    return figure_png(fig, DPI)


def _xcorr_fig(x: XcorrFigure, comp, analysis) -> tuple[bytes, str]:
    """Correlation between the gyros' residuals: fast (sample differences) and slow (block means)."""
    n, nb, slow = x.n_samples, x.n_blocks, x.slow
    N = x.fast.shape[0]
    mats = [(x.fast, "first differences of the samples\n(the ARW part)")]
    if slow is not None:
        mats.append((slow, f"first differences of {x.block_s:.3g} s means\n(the slow part, {nb} means)"))
    side = max(3.6, 0.5 * N + 0.6)
    fig, axs = agg_figure(side * len(mats) + 0.8, side - 0.1, len(mats))
    off = ~np.eye(N, dtype=bool)
    vmax = max(0.05, max(float(np.max(np.abs(m[off]))) for m, _ in mats) * 1.1)
    im = None
    for ax, (m, title) in zip(axs, mats):
        shown = np.where(off, m, np.nan)
        im = ax.imshow(shown, cmap="RdBu_r", vmin=-vmax, vmax=vmax)
        for i in range(N):
            for j in range(N):
                if i != j and N <= 10:
                    v = f"{m[i, j]:.2f}"
                    ax.text(j, i, "0.00" if v == "-0.00" else v, ha="center", va="center",
                            fontsize=7 if N > 6 else 8)
        ticks = range(N)
        ax.set_xticks(ticks, [str(k + 1) for k in ticks], fontsize=7)
        ax.set_yticks(ticks, [str(k + 1) for k in ticks], fontsize=7)
        ax.set_xlabel("gyro", fontsize=8)
        ax.set_ylabel("gyro", fontsize=8)
        ax.set_title(title, fontsize=9)
    fig.colorbar(im, ax=list(axs), shrink=0.8, label="correlation [-]")
    text, _ = _status(analysis, "xcorr", None)
    sd = 1.0 / math.sqrt(max(n - 2, 1))
    spread = f"±{2 * sd:.2g} (left)" + (f" and ±{2 / math.sqrt(max(nb - 2, 1)):.2g} (right)"
                                        if slow is not None else "")
    caption = (f"Correlation between the gyros' residuals over {_record_text(comp, analysis)}; "
               f"{text}. Independent gyros scatter by about {spread} (2σ).")
    return figure_png(fig, DPI), caption


def _arw_track_fig(a: ArwTrackFigure, comp, analysis) -> tuple[bytes, str]:
    """ARW in sliding windows (dynamic Allan deviation at τ₀) per gyro, with the burst candidate."""
    n, N = comp.n, a.arw_deg_rt_h.shape[1]
    fig, axs = _grid(N, 2, 6.0, 2.5)
    rec = analysis.record
    r0, r1 = rec.start or 0, rec.stop if rec.stop is not None else n
    burst_t = channel_candidate(analysis, "window", None)
    burst_e = channel_in_model(analysis, "window", None)
    shade = None
    if burst_e is not None:
        shade = (float(burst_e.params["start_s"]), float(burst_e.params["end_s"]), _GREEN,
                 f"{burst_e.effect} in the model")
    elif burst_t is not None and burst_t.fit is not None and analysis.significant(burst_t):
        p = burst_t.fit.params
        shade = (float(p["start_s"]), float(p["end_s"]), _RED,
                 f"{burst_t.effect} candidate, z = {_z(burst_t.z)}")
    for g, ax in enumerate(axs):
        tc = a.time_s
        arw = a.arw_deg_rt_h[:, g]
        ax.fill_between(tc, a.ci_low_deg_rt_h[:, g], a.ci_high_deg_rt_h[:, g], color="k",
                        alpha=0.15, lw=0, label="1σ band")
        ax.plot(tc, arw, color="k", lw=0.9, label=f"ARW in {a.window_s:.0f} s windows")
        level, _ = analysis.baseline_noise(g + 1)
        lo, hi = float(np.min(arw)), float(np.max(arw))
        if level is not None:
            ax.axhline(level, color="C0", ls="--", lw=1, label="model ARW")
            lo, hi = min(lo, 0.85 * level), max(hi, 1.15 * level)   # wiggles of a few % look calm
        ax.set_ylim(lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo))
        if r0 > 0:
            ax.axvspan(float(comp.t[0]), float(comp.t[r0 - 1]), color="#f1ead8", lw=0,
                       label="not in the stochastic tests' record")
        if r1 < n:
            ax.axvspan(float(comp.t[r1]), float(comp.t[-1]), color="#f1ead8", lw=0,
                       label="not in the stochastic tests' record")
        if shade is not None:
            ax.axvspan(shade[0], shade[1], color=shade[2], alpha=0.18, lw=0, label=shade[3])
        ax.set_title(f"gyro {g + 1}", fontsize=9, y=1.0, pad=4)
        ax.set_ylabel("ARW [deg/√h]", fontsize=8)
        ax.set_xlabel("time [s]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    _header(fig, "Non-stationarity: ARW in sliding windows", axs)
    if burst_t is not None:
        what = (f"{burst_t.effect} candidate z = {_z(burst_t.z)}"
                + (" (significant, shaded)" if analysis.significant(burst_t) else "") + ": "
                + burst_t.evidence)
    elif burst_e is not None:
        what = f"{burst_e.effect}: in the model (shaded)"
    else:
        what = " / ".join(channel_effects("window")) + ": not tested"
    caption = (f"ARW of the residual in sliding {a.window_s:.0f} s windows (dynamic Allan deviation "
               f"at τ₀, step {a.step_s:.3g} s) against the model's ARW; {what}.")
    return figure_png(fig, DPI), caption


# -- sections ----------------------------------------------------------------------

def _section_headline(doc: Doc, comp, steps, alpha: float):
    m = comp.m
    first, final = steps[0][1], steps[-1][1]
    doc.h2("Result")
    dur = float(comp.t[-1] - comp.t[0] + comp.dt)
    n_tests = sum(1 for t in final.tests if np.isfinite(t.z))
    ok = final.consistent
    verdict = ("consistent with the model: yes" if ok else "consistent with the model: no")
    why = (f"D ≤ 1: consistent with the model; D = max z / z_crit, Šidák family-wise "
           f"{alpha * 100:g} % over K = {n_tests} tests (z_crit = {final.z_crit:.3g}).")
    start = ""
    if len(steps) > 1:
        k = len(steps) - 1
        start = (f"Started at D = {_d(first.discrepancy)} with {_model_text(first.model, comp.N)}; "
                 f"{k} effect{'s' if k > 1 else ''} added.")
    _raw(doc,
         f'<div class="headline"><div><div class="note">discrepancy</div>'
         f'<div class="big {"ok" if ok else "bad"}">D = {html.escape(_d(final.discrepancy))}</div></div>'
         f'<div><div class="verdict">{html.escape(verdict)}</div>'
         + (f'<div>{html.escape(start)}</div>' if start else "")
         + f'<div class="why">{html.escape(why)}</div></div></div>',
         f"**Discrepancy D = {_d(final.discrepancy)}** — {verdict}.\n\n"
         + (start + "\n\n" if start else "") + why)
    rate = 1.0 / comp.dt
    rows = [["measurement", m.source or "(not read from a file)"],
            ["description", m.description or "–"],
            ["gyros", comp.N],
            ["layout", m.layout.name],
            ["duration [s]", f"{dur:.1f} ({dur / 60:.1f} min, {comp.n} samples)"],
            ["sample rate [Hz]", f"{rate:.4g}" + (f" (sidecar {m.sample_rate_hz:g})"
                                                  if abs(m.sample_rate_hz - rate) > 1e-6 * rate else "")],
            ["reference rate", "yes" if comp.ref is not None else "no (taken as static)"],
            ["temperature", "no" if comp.temp is None else
             f"yes ({np.min(comp.temp):.1f}–{np.max(comp.temp):.1f} °C)"],
            ["static part", (f"{int(np.sum(comp.static))} samples "
                             f"({np.sum(comp.static) * comp.dt:.0f} s), longest "
                             f"{(comp.longest[1] - comp.longest[0]) * comp.dt:.0f} s")],
            ["model", _model_text(final.model, comp.N)],
            ["discrepancy D", _d(final.discrepancy)],
            ["consistent", "yes" if ok else "no"]]
    _raw(doc, '<table class="facts"><tbody>' + "".join(
        f"<tr><th>{html.escape(k)}</th><td>{html.escape(format_value(v))}</td></tr>" for k, v in rows)
        + "</tbody></table>",
        "| item | value |\n|---|---|\n" + "\n".join(f"| {k} | {format_value(v).replace('|', chr(92) + '|')} |"
                                             for k, v in rows))


def _section_ladder(doc: Doc, steps):
    doc.h2("The error falling")
    doc.p("Each step adds one effect (the ladder: the most significant candidate of the step "
          "before; compare --model: the model's effects in their order) and recalibrates the "
          "whole model; the discrepancy should fall to 1 or below.")
    doc.figure("ladder", _ladder_fig(steps), "Discrepancy D after each step (log scale; dashed: D = 1)")
    rows, flags = [], []
    for i, (added, a) in enumerate(steps):
        eff, g = (added if added is not None else ("–", None))
        rows.append([i, "start" if added is None else eff, "–" if g is None else g,
                     _d(a.discrepancy), a.consistent])
        flags.append(not a.consistent)
    doc.table(["step", "effect added", "gyro", "discrepancy D", "consistent"], rows, flags)


def _section_effects(doc: Doc, final, n_gyros: int):
    doc.h2("Effects found")
    rows = []
    for e in final.model:
        if get_effect(e.effect).baseline:
            continue
        f = final.fits.get((e.effect, e.gyro))
        params = dict(f.params) if f is not None else dict(e.params)
        sigma = dict(f.sigma) if f is not None else {}
        eff = get_effect(e.effect)
        for k, v in params.items():
            if k not in eff.param_names:
                continue
            rows.append([e.effect, "all" if e.gyro is None else e.gyro, k, _pm(v, sigma.get(k)),
                         eff.param(k).unit])
    if rows:
        doc.p("The final model's effects beyond the baseline, refitted on this measurement "
              "(± 1σ; spec units).")
        doc.table(["effect", "gyro", "parameter", "value ± 1σ", "unit"], rows)
    else:
        doc.p("No effect beyond the baseline (ARW + RRW on every gyro) is in the model.", "note")
    band = _band_tests(final)
    doc.h3("Baseline noise per gyro")
    brow, flags = [], []
    for g in range(1, n_gyros + 1):
        (n, sn), (k, sk) = final.baseline_noise(g, sigma=True)
        t = band.get(g)
        brow.append([g, "–" if n is None else _pm(n, sn), "–" if k is None else _pm(k, sk),
                     _z(t.z) if t is not None else "–",
                     "–" if t is None else not final.significant(t)])
        flags.append(t is not None and final.significant(t))
    doc.table(["gyro", "ARW [deg/√h]", "RRW [deg/h/√h]", "ADEV band z", "ADEV within band"],
              brow, flags)


def _finding_marks(ax, loc, gyro: int):
    """Draw one gyro's spectral findings on a PSD panel: cut-offs, lines, bands."""
    for f in loc.findings:
        if gyro not in f.gyros:
            continue
        d = f.details.get("per_gyro", {}).get(gyro, f.details)
        if f.kind == "lowpass":
            ax.axvline(d["cutoff_hz"], color=_RED, lw=1.2, label="low-pass cut-off (−3 dB)")
        elif f.kind == "line":
            ax.axvline(d["freq_hz"], color=_RED, lw=1, ls=":", label="line")
        elif f.kind in ("band_excess", "band_deficit", "low_frequency"):
            ax.axvspan(d["f_lo_hz"], d["f_hi_hz"], color=_RED, alpha=0.1, lw=0,
                       label="band off the model")


def _localise_psd_fig(comp, final, lp: LocalisePsd) -> bytes:
    """Residual PSD of every gyro (whole record) against the model's Monte-Carlo PSD band."""
    loc, a = final.localised, final.adev
    f, P, fb, Pb = lp.freq_hz, lp.psd, lp.freq_binned_hz, lp.psd_binned
    to = units.rad_s_to_deg_h
    fig, axs = _grid(comp.N, 4, 3.4, 2.9)
    for g, ax in enumerate(axs):
        ax.fill_between(f, to(np.sqrt(a["psd_lo"][g, 1:])), to(np.sqrt(a["psd_hi"][g, 1:])),
                        color="C0", alpha=0.22, lw=0, label="model 95 % band")
        ax.loglog(f, to(np.sqrt(a["psd_mean"][g, 1:])), "--", color="C0", lw=1, label="model mean")
        ax.loglog(f, to(np.sqrt(P[:, g])), color="0.72", lw=0.5, label="residual (Welch)")
        ax.loglog(fb, to(np.sqrt(Pb[:, g])), color="k", lw=1.1, label="residual, log-binned")
        _finding_marks(ax, loc, g + 1)
        bad = loc.gyro_scores[g] > loc.z_crit
        ax.set_title(f"gyro {g + 1}" + (f": score {loc.gyro_scores[g]:.1f}" if bad else ""),
                     fontsize=9, color=_RED if bad else "0.15", y=1.0, pad=4)
        _asd_axes(ax)
    _header(fig, "Residual spectrum against the model's band", axs)
    return figure_png(fig, DPI)


def _localise_channels_fig(comp, final, panels: list[ChannelPanel]) -> bytes:
    """Binned residual (mean removed) against every channel of the record, all gyros per panel."""
    loc = final.localised
    fig, axs = _grid(len(panels), 3, 3.6, 2.9)
    for ax, pan in zip(axs, panels):
        name, unit = pan.name, pan.unit
        for g, b in enumerate(pan.per_gyro):
            if b.x.size:
                ax.errorbar(b.x, b.mean, yerr=2.0 * b.stderr, fmt="o-", ms=2.5, lw=0.8, capsize=0,
                            color=f"C{g % 10}", label=f"gyro {g + 1}")
        c = next((c for c in loc.correlations if c.channel == name), None)
        bad = c is not None and abs(c.z) > loc.z_crit
        ax.set_title(name if c is None else f"{name}: r = {c.r:+.2f} (gyro {c.gyro}), |z| = "
                     f"{abs(c.z):.1f}", fontsize=9, color=_RED if bad else "0.15", y=1.0, pad=4)
        ax.grid(alpha=0.3)
        ax.set_xlabel(f"{name} [{unit}]", fontsize=8)
        ax.set_ylabel("residual [deg/h]", fontsize=8)
        ax.tick_params(labelsize=7)
    _header(fig, "Residual against each channel of the record", axs)
    return figure_png(fig, DPI)


def _section_localisation(doc: Doc, comp, final, figures: CompareFigures):
    """The ranked findings of the localisation and their figures."""
    loc = final.localised
    doc.h3("Where it fails")
    doc.p(f"What no effect explains, localised and ranked (score: the departure in standard "
          f"errors of its own statistic; every finding is past the 1 % family-wise critical "
          f"{loc.z_crit:.3g}). The residual is the output minus H·ref minus the model's "
          "deterministic part, the whole record.")
    doc.table(["score", "kind", "gyros", "finding"],
              [[f"{f['score']:.1f}", f["kind"], ", ".join(map(str, f["gyros"])), f["sentence"]]
               for f in final.localisation], [True] * len(final.localisation))
    assert figures.localise_psd is not None                 # computed for a localised step
    doc.figure("localise_psd", _localise_psd_fig(comp, final, figures.localise_psd),
               "Residual PSD (as ASD) of each gyro over the whole record against the model's "
               f"95 % band (the same {final.adev['mc'].shape[0]} Monte-Carlo runs as the ADEV band, "
               "per Welch frequency); red: the localised cut-offs, lines and bands.")
    doc.figure("localise_channels", _localise_channels_fig(comp, final, figures.localise_channels),
               "Binned residual (mean removed, ± 2 standard errors) against every channel the "
               "record has; titles: the strongest correlation (block means, autocorrelation-"
               "corrected), red past the critical value.")


def section_unexplained(doc: Doc, final, comp=None, figures: CompareFigures | None = None):
    """Draw what the final step leaves unexplained; its localisation (with ``comp``) from
    ``figures`` (:func:`gyroarray.chain.compare_figures.compare_figures`)."""
    doc.h2("What is still unexplained")
    left = [t for t in final.candidates if final.significant(t)]
    sentences = [] if final.localisation else final.unexplained()
    if final.consistent and not left and not sentences:
        doc.p("Nothing left unexplained: no candidate effect and no ADEV band test is significant "
              f"(every z ≤ z_crit = {final.z_crit:.3g}).")
        return
    for s in sentences:
        doc.p(s[0].upper() + s[1:] + ".")
    if left:
        doc.p(f"{len(left)} significant candidate effect(s) left (z > z_crit = {final.z_crit:.3g}):")
        doc.table(["effect", "gyro", "z", "evidence"],
                  [[t.effect, "all" if t.gyro is None else t.gyro, _z(t.z), t.evidence] for t in left],
                  [True] * len(left))
    band = [t for t in final.tests if t.kind == "adev_band" and final.significant(t)]
    if band and not sentences and not final.localisation:
        doc.p("ADEV outside the model's band (explained by a significant candidate above): "
              + "; ".join(t.evidence for t in band) + ".")
    if (final.localisation and final.localised is not None and comp is not None
            and figures is not None and figures.localise_psd is not None):
        _section_localisation(doc, comp, final, figures)


def _candidate_table(doc: Doc, a):
    c = a.candidates[:TOP]
    doc.table(["effect", "gyro", "z", "significant", "evidence"],
              [[t.effect, "all" if t.gyro is None else t.gyro, _z(t.z), a.significant(t), t.evidence]
               for t in c], [a.significant(t) for t in c])
    band = sorted(_band_tests(a).values(), key=lambda t: t.gyro)
    if band:
        doc.table(["ADEV band", "z", "significant", "evidence"],
                  [[f"gyro {t.gyro}", _z(t.z), a.significant(t), t.evidence] for t in band],
                  [a.significant(t) for t in band])


def _section_candidates(doc: Doc, steps):
    doc.h2("Candidates")
    first, final = steps[0][1], steps[-1][1]
    n_final = len(final.candidates)
    doc.p(f"Every effect of the spec not in the model, on every gyro it can act on, fitted to the "
          f"residual; z ≈ N(0, 1) when the effect is absent. Red rows: z > z_crit. "
          f"The best {min(TOP, n_final)} of {n_final}, then the ADEV band test of every gyro.")
    if len(steps) > 1:
        doc.h3(f"After the last step (D = {_d(final.discrepancy)}, z_crit = {final.z_crit:.3g})")
    _candidate_table(doc, final)
    if len(steps) > 1:
        doc.h3(f"Before fitting (D = {_d(first.discrepancy)}, z_crit = {first.z_crit:.3g})")
        _candidate_table(doc, first)


def _section_diagnostics(doc: Doc, comp, steps, figures: CompareFigures):
    first, final = steps[0][1], steps[-1][1]
    N = comp.N
    doc.h2("Where the model fails" + (" (before fitting)" if len(steps) > 1 else ""))
    what = f"first step (model: {_model_text(first.model, N)})" if len(steps) > 1 else "model"
    doc.p(f"Diagnostics of the {what}: red titles mark a significant test (z > z_crit = "
          f"{first.z_crit:.3g}).")
    doc.h3("Allan deviation against the model's band")
    doc.figure("adev_first", _adev_fig(first, N, "Measured ADEV vs the model's 95 % band"),
               f"Measured ADEV of the residual over {_record_text(comp, first)} against the "
               f"calibrated model's 95 % Monte-Carlo band ({first.adev['mc'].shape[0]} runs); red "
               f"points leave the band.")

    doc.h3("Residual against the regressors")
    have = ", ".join(REGRESSORS[k][0].split(" [")[0] for k in figures.regressor_keys)
    doc.p(f"Binned mean of the residual (± 2 standard errors) against {have}. Rate, other axes, "
          f"rate² and acceleration: the slowly varying bias (mean over the static samples of each "
          f"{BIAS_BLOCK_S:.0f} s block, linear in time) removed first; temperature and time: only "
          "the mean over the static samples removed (the fitted bias would take the slow signal "
          "with it; it is drawn on the time panel). Dashed: the candidate's fit. "
          + ("" if figures.has_ref else "No reference rate: the rate panels are left out. "
             if comp.ref is None else "The table never turns: the rate panels are left out. ")
          + ("" if figures.has_temp else "No temperature: the temperature panel is left out."))
    for rf in figures.regressors:
        doc.figure(f"regressors_g{rf.gyro}", _regressor_fig(rf, first),
                   f"Gyro {rf.gyro}: residual against the regressors")

    doc.h3("Residual spectrum")
    doc.figure("psd", _psd_fig(figures.psd, first),
               f"Amplitude spectral density of the residual (Welch, over {_record_text(comp, first)}, "
               "where the stochastic tests read it) with the model's ARW level and ARW + RRW curve; "
               "dotted: the sinusoid candidate's frequency, its z in the panel title (red: "
               "significant).")

    if figures.xcorr is not None:
        doc.h3("Correlation between gyros")
        png, cap = _xcorr_fig(figures.xcorr, comp, first)
        doc.figure("xcorr", png, cap)

    doc.h3("Non-stationarity: ARW in sliding windows")
    png, cap = _arw_track_fig(figures.arw_track, comp, first)
    doc.figure("arw_track", png, cap)

    if len(steps) > 1:
        doc.h2("After the last step")
        doc.figure("adev_final", _adev_fig(final, N, f"After the last step: measured ADEV vs the "
                                                     f"model's band (D = {_d(final.discrepancy)})"),
                   f"Measured ADEV of the residual over {_record_text(comp, final)} against the "
                   f"final model's 95 % Monte-Carlo band.")


def _section_notes(doc: Doc, comp, steps):
    doc.h2("Notes")
    final = steps[-1][1]
    notes = list(final.notes)
    if len(steps) > 1:
        notes = [f"before fitting: {n}" for n in steps[0][1].notes if n not in final.notes] + notes
    notes += [f"reading the file: {n}" for n in comp.m.notes]
    if not notes:
        doc.p("None.", "note")
    for n in notes:
        doc.p(n, "note")


def _check_steps(comp, steps):
    if not isinstance(steps, (list, tuple)) or not steps:
        raise InputError("steps must be the non-empty list of (added, Analysis) of comp.ladder()")
    for i, s in enumerate(steps):
        if not (isinstance(s, (list, tuple)) and len(s) == 2 and isinstance(s[1], Analysis)):
            raise InputError(f"steps[{i}] must be (added (effect, gyro) or None, Analysis)")
        a = s[1]
        if a.residual_rad_s.shape != (comp.n, comp.N):
            raise InputError(f"steps[{i}] is the analysis of another measurement: residual shape "
                             f"{a.residual_rad_s.shape}, this comparison {(comp.n, comp.N)}")


# -- the report ----------------------------------------------------------------------

def write_compare_report(comp, steps, out_html, out_md=None, *, title: str | None = None,
                         force: bool = True, figures: CompareFigures | None = None) -> dict:
    """Write the model-vs-measurement report (see the module docstring).

    Parameters
    ----------
    comp : gyroarray.chain.compare.ModelComparison
        The comparison (measurement, regressors, static mask).
    steps : list of (tuple or None, Analysis)
        :meth:`~gyroarray.chain.compare.ModelComparison.ladder` output: ``(None,
        analysis)`` first, then ``((effect, gyro), analysis)`` per added
        effect; or :meth:`~gyroarray.chain.compare.ModelComparison.steps_to_model`
        (``compare --model``); a single step for ``compare`` of the baseline.
    out_html : path
        The HTML file (figures embedded), must end in ``.html``.
    out_md : path, optional
        The Markdown twin, must end in ``.md``; its figures go to
        ``<stem>_figures/`` beside it.
    title : str, optional
        Page title (default: "Model vs measurement: <measurement>").
    force : bool
        Replace existing output files (the CLI passes ``--force``; it has
        checked the paths before the analysis, :mod:`gyroarray.core.outputs`).
    figures : CompareFigures, optional
        The figures' data (:func:`gyroarray.chain.compare_figures.compare_figures`,
        e.g. read back with ``CompareFigures.from_dict``); default: computed by the chain
        from ``comp`` and ``steps``. Nothing else is computed here.

    Returns
    -------
    dict
        ``html``, ``markdown`` (path or None), ``figures`` (count),
        ``figure_names``, ``steps`` (``added`` [effect, gyro] or None,
        ``discrepancy`` [-], ``consistent``), ``discrepancy`` (per step),
        ``html_bytes``, ``seconds``.

    Raises
    ------
    InputError
        Wrong file suffixes, empty or malformed ``steps``.
    """
    t_start = time.perf_counter()
    out_html = Path(out_html)
    if out_html.suffix.lower() not in (".html", ".htm"):
        raise InputError("the report must end in .html", file=str(out_html))
    if out_md is not None and Path(out_md).suffix.lower() != ".md":
        raise InputError("the Markdown twin must end in .md", file=str(out_md))
    _check_steps(comp, steps)
    steps = list(steps)
    if figures is None:
        figures = compare_figures(comp, steps)
    label = Path(comp.m.source).name if comp.m.source else "measurement not read from a file"
    doc = Doc(title or f"Model vs measurement: {label}")
    _section_headline(doc, comp, steps, comp.alpha)
    if len(steps) > 1:
        _section_ladder(doc, steps)
    _section_effects(doc, steps[-1][1], comp.N)
    section_unexplained(doc, steps[-1][1], comp, figures)
    _section_candidates(doc, steps)
    _section_diagnostics(doc, comp, steps, figures)
    _section_notes(doc, comp, steps)

    stamp = time.strftime("%Y-%m-%d %H:%M", time.localtime())
    subtitle = f"{stamp} · {label} · {comp.N} gyros · {comp.n_runs} Monte-Carlo runs per band"
    md_path = doc.write(out_html, out_md, subtitle, css=_EXTRA_CSS, force=force)
    rows = [{"added": None if added is None else [added[0], added[1]],
             "discrepancy": float(a.discrepancy), "consistent": bool(a.consistent)}
            for added, a in steps]
    return {"html": str(out_html), "markdown": None if md_path is None else str(md_path),
            "figures": len(doc.figures), "figure_names": [n for n, _ in doc.figures],
            "steps": rows, "discrepancy": [r["discrepancy"] for r in rows],
            "html_bytes": out_html.stat().st_size, "seconds": time.perf_counter() - t_start}
