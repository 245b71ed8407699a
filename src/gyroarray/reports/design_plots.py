"""GDOP design figures (paper 003 Figs. 8–10) and the figure helpers the reports share."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from gyroarray.core.gdop import correlation_matrix, gdop, gdop_vs_alpha, optimal_alpha
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.outputs import PLOT_SUFFIXES, check_output_dir, save_figure
from gyroarray.core.units import deg_to_rad, rad_to_deg

NS = (4, 5, 6, 8)


def _rho_grid(n: int, count: int = 200) -> np.ndarray:
    """ρ strictly inside (−1/(N−1), 1), where the correlation matrix is PD."""
    lo = -1.0 / (n - 1)
    eps = 1e-3
    return np.linspace(lo + eps, 1.0 - eps, count)


def agg_figure(w=9.0, h=5.0, ncols=1):
    """A figure of ``ncols`` panels side by side on an Agg canvas (no pyplot state), and its axes."""
    # deferred: matplotlib loads only when a figure is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(w, h), layout="constrained")
    FigureCanvasAgg(fig)
    axs = fig.subplots(1, ncols, squeeze=False)[0]
    return fig, axs


def figure_png(fig, dpi=96) -> bytes:
    """The figure as PNG bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def design_figure(path, *, force: bool = True) -> Path:
    """Write the design figure to ``path`` (see :func:`design_fig`).

    Parameters
    ----------
    path : path-like
        Output image; the format follows the suffix (``.png``, ``.svg``, ``.pdf``).

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    if path.suffix.lower() not in PLOT_SUFFIXES:
        raise InputError(f"plot must end in .png, .svg or .pdf, got {path.name!r}", file=str(path))
    check_output_dir(path.parent, what="the plot's folder")
    return save_figure(design_fig(), path, force=force, dpi=110)


def recommended_gdop_line(rec: dict, count: int = 200) -> tuple[np.ndarray, np.ndarray, str]:
    """GDOP vs ρ of a recommended array as mounted (its ``axes``, reversed gyros included).

    Parameters
    ----------
    rec : dict
        A design of a ``design --recommend`` result (``n``, ``alpha_deg``, ``axes``,
        ``mounting_signs``).
    count : int
        Points on the ρ grid (strictly inside (−1/(N−1), 1)).

    Returns
    -------
    (rho [-], GDOP [-], legend label)
    """
    n = int(rec["n"])
    layout = Layout(np.asarray(rec["axes"], dtype=float))
    rhos = _rho_grid(n, count)
    g = np.array([gdop(layout, correlation_matrix(n, r)) for r in rhos])
    rev = [k + 1 for k, v in enumerate(rec.get("mounting_signs") or []) if v < 0]
    sense = ("gyro" + ("s " if len(rev) > 1 else " ") + ", ".join(map(str, rev)) + " reversed"
             if rev else "every gyro +")
    return rhos, g, f"recommended, as mounted: N = {n}, α = {rec['alpha_deg']:.2f}°, {sense}"


def design_fig(rec: dict | None = None):
    """The figure: GDOP vs α (both schemes, N = 4, 5, 6, 8, ρ = 0), GDOP vs α
    for several ρ (Scheme 1, N = 6), GDOP vs ρ at the ρ = 0 optimal α and the
    optimal α vs ρ (a matplotlib Figure on an Agg canvas; no pyplot state).

    ``rec``: a recommended design with ``axes`` (a ``design --recommend`` result's
    ``recommended``); its GDOP vs ρ as mounted (reversed gyros included,
    :func:`recommended_gdop_line`) is drawn bold on its scheme's GDOP-vs-ρ panel, beside
    the paper's arrays with every gyro +.
    """
    # deferred: matplotlib loads only when a figure is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    alphas_deg = np.linspace(5.0, 175.0, 341)
    alphas = deg_to_rad(alphas_deg)
    fig = Figure(figsize=(15, 8.5), layout="constrained")
    FigureCanvasAgg(fig)
    axs = fig.subplots(2, 3)
    for col, scheme in enumerate((1, 2)):
        ax = axs[0, col]
        for n in NS:
            g = gdop_vs_alpha(scheme, n, alphas, 0.0)
            line, = ax.plot(alphas_deg, g, label=f"N = {n}")
            opt = optimal_alpha(scheme, n, 0.0)
            ax.plot(rad_to_deg(opt.alpha_rad), opt.gdop, "o", color=line.get_color())
        ax.set(title=f"Scheme {scheme}: GDOP vs α, ρ = 0 [Fig. 8{'ab'[col]}]",
               xlabel="cone angle α [deg]", ylabel="GDOP [-]", ylim=(0.8, 3.5))
        ax.legend(loc="upper center")
        ax.grid(alpha=0.3)

    ax = axs[0, 2]
    for rho in (-0.18, -0.1, 0.0, 0.2, 0.5):
        g = gdop_vs_alpha(1, 6, alphas, rho)
        ax.plot(alphas_deg, g, label=f"ρ = {rho:g}")
    ax.set(title="Scheme 1, N = 6: GDOP vs α per ρ [Fig. 9]",
           xlabel="cone angle α [deg]", ylabel="GDOP [-]", xlim=(5, 90), ylim=(0.8, 3.0))
    ax.legend()
    ax.grid(alpha=0.3)

    for col, scheme in enumerate((1, 2)):
        ax = axs[1, col]
        for n in NS:
            alpha = optimal_alpha(scheme, n, 0.0).alpha_rad
            rhos = _rho_grid(n)
            layout = Layout.conical(scheme, n, alpha)
            ax.plot(rhos, [gdop(layout, correlation_matrix(n, r)) for r in rhos],
                    label=f"N = {n}, α = {rad_to_deg(alpha):.2f}°, every gyro +")
        if rec is not None and rec.get("axes") is not None and rec.get("scheme") == scheme:
            r_line, g_line, label = recommended_gdop_line(rec)
            ax.plot(r_line, g_line, "k-", lw=2.2, label=label)
        ax.set(title=f"Scheme {scheme}: GDOP vs ρ, α of ρ = 0 [Fig. 10{'ab'[col]}]",
               xlabel="ARW correlation ρ [-]", ylabel="GDOP [-]")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)

    ax = axs[1, 2]
    jumps = []
    for scheme, style in ((1, "-"), (2, "--")):
        for k, n in enumerate(NS):
            rhos = _rho_grid(n, 60)
            a = np.array([rad_to_deg(optimal_alpha(scheme, n, r).alpha_rad) for r in rhos])
            # the optimum changes branch (Scheme 2: the cone flips below the horizontal):
            # break the line there instead of drawing a vertical stroke through angles no
            # optimum takes
            cut = np.flatnonzero(np.abs(np.diff(a)) > 10.0)
            a_plot = a.copy()
            r_plot = rhos.copy()
            for c in cut[::-1]:
                jumps.append((scheme, n, 0.5 * (rhos[c] + rhos[c + 1])))
                a_plot = np.insert(a_plot, c + 1, np.nan)
                r_plot = np.insert(r_plot, c + 1, np.nan)
            ax.plot(r_plot, a_plot, style, color=f"C{k}", label=f"scheme {scheme}, N = {n}")
    ax.set(title="Optimal α vs ρ [Table 2]" + (" (gaps: branch jumps)" if jumps else ""),
           xlabel="ARW correlation ρ [-]", ylabel="optimal α [deg]")
    ax.legend(fontsize=7, ncol=2, title="solid: scheme 1, dashed: scheme 2", title_fontsize=7)
    ax.grid(alpha=0.3)

    fig.suptitle("gyroarray design analysis: GDOP = sqrt(trace((Hᵀ C⁻¹ H)⁻¹))")
    for ax in axs.flat:
        ax.title.set_fontsize(10)
    return fig


def title_overlaps(fig) -> list[tuple[str, str]]:
    """Pairs of panel titles (and the suptitle) whose drawn boxes intersect (empty: none overlap).

    Draws the figure on its canvas first, so the boxes are those of the laid-out figure.
    """
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    texts = [ax.title for ax in fig.axes if ax.get_title()]
    if fig._suptitle is not None:
        texts.append(fig._suptitle)
    boxes = [(t.get_text(), t.get_window_extent(r)) for t in texts]
    out = []
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            if boxes[i][1].overlaps(boxes[j][1]):
                out.append((boxes[i][0], boxes[j][0]))
    return out


def array_fig(axes, title: str = "", signs=None):
    """The array as mounted: each gyro's sensitive axis as an arrow from the origin, signs
    included (a reversed gyro's arrow points the other way, drawn red), numbered 1..N
    (a matplotlib Figure on an Agg canvas).

    Parameters
    ----------
    axes : array_like (N, 3)
        Unit vectors of the gyros as mounted [-] (``design --recommend``'s ``axes``).
    title : str
        The figure's title.
    signs : array_like (N,), optional
        ±1 per gyro (``mounting_signs``): −1 drawn red, as mounted reversed.
    """
    # deferred: matplotlib loads only when a figure is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    a = np.asarray(axes, dtype=float)
    sg = np.ones(len(a)) if signs is None else np.asarray(signs, dtype=float)
    fig = Figure(figsize=(5.5, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    for k, v in enumerate(a):
        rev = sg[k] < 0
        ax.quiver(0, 0, 0, v[0], v[1], v[2], color="C3" if rev else "C0", arrow_length_ratio=0.12, lw=1.6)
        ax.text(1.1 * v[0], 1.1 * v[1], 1.1 * v[2], str(k + 1), fontsize=9)
    ax.set(xlim=(-1, 1), ylim=(-1, 1), zlim=(-1, 1), xlabel="x", ylabel="y", zlabel="z")
    ax.set_box_aspect((1, 1, 1))
    if title:
        ax.set_title(title, fontsize=9)
    return fig


def plot_vs_n(ax, ns, ys, yerr=None, *, color, marker, label, offset: float = 0.0):
    """Values per number of gyros N: markers (error bars when given), joined only between
    consecutive N, so no line runs through an N that was not computed (e.g. N = 7)."""
    ns = np.asarray(ns, dtype=float)
    ys = np.asarray(ys, dtype=float)
    x = ns + offset
    if yerr is not None:
        ax.errorbar(x, ys, yerr=yerr, fmt=marker, color=color, ms=5, capsize=3, label=label)
    else:
        ax.plot(x, ys, marker, color=color, ms=5, label=label)
    for i in range(len(ns) - 1):
        if ns[i + 1] - ns[i] == 1:
            ax.plot(x[i:i + 2], ys[i:i + 2], "-", color=color, lw=1.0)
    ticks = set(getattr(ax, "_gyroarray_n_ticks", set())) | {int(n) for n in ns}
    ax._gyroarray_n_ticks = ticks
    ax.set_xticks(sorted(ticks))


def plot_series(ax, series: dict, *, rtol: float) -> list:
    """Series {(scheme, estimator): (N, values, error bars or None)} vs N: one marker per
    scheme, one colour per estimator; series equal to ``rtol`` are drawn once, their label
    naming them all. Returns the estimators in colour order."""
    merged: list[list] = []
    for k, (n, y, _) in series.items():
        for grp in merged:
            n0, y0, _ = series[grp[0]]
            if np.array_equal(n, n0) and np.allclose(y, y0, rtol=rtol, atol=0):
                grp.append(k)
                break
        else:
            merged.append([k])
    ests = sorted({k[1] for k in series})
    for grp in merged:
        n, y, e = series[grp[0]]
        scheme, est = grp[0]
        label = " = ".join(f"scheme {sc}, {es}" for sc, es in grp)
        plot_vs_n(ax, n, y, e, color=f"C{ests.index(est)}", marker="o" if scheme == 1 else "s",
                  label=label + (f"  (equal to {rtol:g})" if len(grp) > 1 else ""),
                  offset=0.04 * (ests.index(est) - len(ests) / 2) + (0.0 if scheme == 1 else 0.02))
    return ests


def _accuracy_value(d: dict) -> float:
    """The one condition the accuracy-vs-N figure draws: the design's worst case (over the ρ
    range × every set of failed gyros, the ranking's condition) when it has one, else its
    3-axis RMS at the result's one ρ [deg/s]."""
    wc = d.get("worst_case")
    return float(wc["rms_3axis_deg_s"] if wc else d["rms_3axis_deg_s"])


def _failed_words(gyros) -> str:
    g = list(gyros or [])
    return "intact" if not g else ("gyro " if len(g) == 1 else "gyros ") + ", ".join(map(str, g)) + " failed"


def accuracy_vs_n_fig(res: dict):
    """Predicted 3-axis RMS vs N per scheme and estimator (identical series merged), every
    point at one condition: each design's worst case over the ρ range × failures (the
    ranking's), or the result's one ρ without a range; the simulated check's 95 % interval
    as error bars at the checked designs, each simulated at its own worst case (the ρ and
    failed gyros in its legend entry, one entry per checked design)."""
    # deferred: matplotlib loads only when a figure is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(8.5, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    best: dict = {}
    for d in res["designs"]:
        key = (d["scheme"], d["estimator"])
        cur = best.setdefault(key, {})
        if d["n"] not in cur or _accuracy_value(d) < _accuracy_value(cur[d["n"]]):
            cur[d["n"]] = d
    series = {}
    for key, per_n in best.items():
        ns = sorted(per_n)
        series[key] = (np.array(ns), np.array([_accuracy_value(per_n[n]) for n in ns]), None)
    ests = plot_series(ax, series, rtol=1e-6)
    chk = (res.get("check") or {}).get("designs", [])
    labels: set = set()
    for i, c in enumerate(chk):
        mc = c["rms_3axis_deg_s"]["monte_carlo"]
        if mc["ci_low"] is None:
            continue
        color = f"C{ests.index(c['estimator'])}" if c["estimator"] in ests else "k"
        at = c.get("at") or {}
        where = (f" at ρ = {at['rho']:.3g}, {_failed_words(at.get('failed_gyros'))}"
                 if at.get("rho") is not None else "")
        label = f"simulated {c['role']}: {c['label']}" if c.get("role") else f"simulated: {c['label']}"
        label += where + " (95 % CI)"
        k = 2
        base = label
        while label in labels:
            label = f"{base} #{k}"
            k += 1
        labels.add(label)
        ax.errorbar([c["n"] + 0.12 + 0.06 * i], [mc["value"]],
                    yerr=[[mc["value"] - mc["ci_low"]], [mc["ci_high"] - mc["value"]]],
                    fmt="o" if c["scheme"] == 1 else "s", mfc="none", color=color, ms=6, capsize=3,
                    label=label)
    ranged = any(d.get("worst_case") for d in res["designs"])
    ax.set(xlabel="gyros N [-]", ylabel="3-axis RMS about the truth [deg/s]",
           title=("Predicted worst case per N (over the ρ range × failures; best design per "
                  "scheme and estimator)" if ranged else
                  "Predicted accuracy per N (best cone angle and bandwidth)"))
    ax.title.set_fontsize(10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=6)
    return fig
