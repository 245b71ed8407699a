"""The Allan/Hadamard deviation figure of :func:`gyroarray.analysis.allan.allan_analysis` results.

Moved out of :mod:`gyroarray.analysis.allan` (issue 29: analysis computes, reports draw).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from gyroarray.analysis.allan import AllanAnalysis
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.outputs import save_figure

__all__ = ["plot_allan"]


def plot_allan(analyses: Mapping[str, AllanAnalysis], path, *, force: bool = True) -> Path:
    """Log-log plot of deviation curves with confidence bands and fits.

    Parameters
    ----------
    analyses : mapping of str to AllanAnalysis
        Curves by legend label.
    path : str or os.PathLike
        Output image file; the format follows the suffix (png, pdf, svg).
    force : bool
        Replace an existing file (atomically, :mod:`gyroarray.core.outputs`).

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    InputError
        Empty ``analyses``.

    Notes
    -----
    Deviation in deg/h (via :func:`gyroarray.core.units.rad_s_to_deg_h`) against
    tau in s; each curve with its confidence band shaded and the fitted
    noise model dashed in the same colour.  Uses matplotlib's Agg canvas
    directly (no pyplot, no global backend change).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib only to draw
    from matplotlib.figure import Figure  # lazy: matplotlib only to draw

    if not analyses:
        raise InputError("plot_allan needs at least one analysis")
    fig = Figure(figsize=(7.0, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    kinds = set()
    for i, (label, an) in enumerate(analyses.items()):
        color = f"C{i % 10}"
        kinds.add(an.kind)
        to_deg_h = units.rad_s_to_deg_h
        ax.fill_between(an.taus_s, to_deg_h(an.ci_low_rad_s),
                        to_deg_h(an.ci_high_rad_s), color=color, alpha=0.2,
                        linewidth=0)
        ax.plot(an.taus_s, to_deg_h(an.adev_rad_s), "o-", color=color,
                markersize=3, label=f"{label} ({an.kind})")
        grid = np.geomspace(an.taus_s[0], an.taus_s[-1], 200)
        ax.plot(grid, to_deg_h(np.sqrt(an.fit.model_avar(grid))), "--",
                color=color, linewidth=1.0, label=f"{label} fit")
    ax.set_xscale("log")
    ax.set_yscale("log")
    name = {"oadev": "Allan deviation", "ohdev": "Hadamard deviation"}
    ax.set_xlabel("averaging time τ [s]")
    ax.set_ylabel((name[kinds.pop()] if len(kinds) == 1 else "deviation")
                  + " [deg/h]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    first = next(iter(analyses.values()))
    ax.set_title(f"shaded: {first.confidence:.1%} confidence")
    return save_figure(fig, path, force=force, dpi=120)
