"""The DAVAR heat map of a :class:`gyroarray.analysis.davar.DavarResult`.

Moved out of :mod:`gyroarray.analysis.davar` (issue 29: analysis computes, reports draw).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gyroarray.analysis.davar import DavarResult
from gyroarray.core import units
from gyroarray.core.outputs import save_figure

__all__ = ["plot_davar"]


def _cell_edges(centres: np.ndarray, result: DavarResult | None, *,
                exp: bool = False) -> np.ndarray:
    """Edges of the cells around sorted ``centres`` (midpoints, the outer
    cells as wide as their neighbours; one centre: the window's span, or a
    factor 2 around it when ``exp``); ``exp``: ``centres`` are logarithms
    and the edges are returned exponentiated."""
    if centres.size == 1:
        if exp:
            half = 0.5 * math.log(2.0)
        else:
            assert result is not None                  # the window's span
            half = 0.5 * result.tau0_s * float(result.window_length[0])
        edges = np.array([centres[0] - half, centres[0] + half])
    else:
        mid = 0.5 * (centres[1:] + centres[:-1])
        edges = np.concatenate([[2.0 * centres[0] - mid[0]], mid,
                                [2.0 * centres[-1] - mid[-1]]])
    return np.exp(edges) if exp else edges


def plot_davar(result: DavarResult, path, *, title: str | None = None,
               force: bool = True) -> Path:
    """Heat map of the dynamic deviation with the ARW and length tracks.

    Parameters
    ----------
    result : DavarResult
        From :func:`davar`.
    path : str or os.PathLike
        Output image; the format follows the suffix (png, pdf, svg).
    title : str, optional
        Figure title.
    force : bool
        Replace an existing file (atomically, :mod:`gyroarray.core.outputs`).

    Returns
    -------
    pathlib.Path
        The written file.

    Notes
    -----
    Top: deviation [deg/h] over window centre [s] (x) and averaging time
    [s] (y, log), logarithmic colour scale.  Middle: ARW [deg/√h] with its
    confidence band.  Bottom: window length [samples].  Uses matplotlib's
    Agg canvas directly (no pyplot, no global backend change).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib only to draw
    from matplotlib.colors import LogNorm  # lazy: matplotlib only to draw
    from matplotlib.figure import Figure  # lazy: matplotlib only to draw

    t = result.time_s
    adev = units.rad_s_to_deg_h(result.adev_rad_s)
    arw = units.arw_rad_rt_s_to_deg_rt_h
    fig = Figure(figsize=(8.0, 8.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax_map, ax_arw, ax_len = fig.subplots(
        3, 1, sharex=True, gridspec_kw={"height_ratios": (3, 1.4, 1)})
    positive = adev[adev > 0]
    norm = (LogNorm(vmin=positive.min(), vmax=positive.max())
            if positive.size else None)
    mesh = ax_map.pcolormesh(_cell_edges(t, result), _cell_edges(
        np.log(result.taus_s), None, exp=True), adev.T, norm=norm,
        shading="flat", cmap="viridis")
    ax_map.set_yscale("log")
    ax_map.set_ylabel("averaging time τ [s]")
    fig.colorbar(mesh, ax=ax_map,
                 label=f"{'Allan' if result.kind == 'oadev' else 'Hadamard'}"
                       " deviation [deg/h]")
    ax_arw.fill_between(t, arw(result.arw_ci_low_rad_rt_s),
                        arw(result.arw_ci_high_rad_rt_s), color="C0",
                        alpha=0.25, linewidth=0,
                        label=f"{result.confidence:.1%} confidence")
    marker = "o" if t.size == 1 else None
    ax_arw.plot(t, arw(result.arw_rad_rt_s), color="C0", linewidth=1.0,
                marker=marker, label=f"ARW ({result.arw_method})")
    ax_arw.set_ylabel("ARW [deg/√h]")
    ax_arw.legend(fontsize="small", loc="upper right")
    ax_len.plot(t, result.window_length, color="C1", linewidth=1.0,
                marker=marker)
    ax_len.set_ylabel("window [samples]")
    ax_len.set_xlabel("window centre [s]")
    for ax in (ax_map, ax_arw, ax_len):
        ax.grid(True, alpha=0.3)
    if title is None:
        name = "A-DAVAR" if result.adaptive else "DAVAR"
        title = (f"{name}: {result.n_windows} windows, {result.extension} "
                 "extension" if t.size > 1 else
                 f"{name}: one window of {int(result.window_length[0])} "
                 "samples")
    fig.suptitle(title)
    return save_figure(fig, path, force=force, dpi=120)
