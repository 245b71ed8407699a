"""The parity-statistics figure of ``gyroarray fdi --plot``.

Moved out of :mod:`gyroarray.chain.fdi_score` (issue 29: the chain computes, reports draw).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gyroarray.core.outputs import save_figure

__all__ = ["plot_fdi"]


def plot_fdi(result, path, title: str = "", *, force: bool = True) -> Path:
    """The detector's statistics against their thresholds over time, onsets marked.

    Parameters
    ----------
    result : FdiResult
        From ``detect(..., trace=True)``.
    path : str or os.PathLike
        Output image (format from the suffix: png, svg, pdf).
    title : str
    force : bool
        Replace an existing file (:func:`gyroarray.core.outputs.save_figure`).

    Notes
    -----
    Each family's largest |statistic|/threshold over directions and windows
    (1 = the threshold) of the first scan (until the first exclusion);
    dashed: the fitted onsets, dotted: the alarms. matplotlib's Agg canvas.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib only to draw
    from matplotlib.figure import Figure  # lazy: matplotlib only to draw

    fig = Figure(figsize=(8.0, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    t = result.time_s
    ratio = result.trace.get("ratio", {}) if result.trace else {}
    k0 = result.trace.get("start", 0) if result.trace else 0
    for i, (fam, r) in enumerate(ratio.items()):
        tt = t[k0:k0 + r.size]
        ax.plot(tt, np.maximum(r, 1e-3), color=f"C{i}", linewidth=0.7,
                label=f"{fam} (max over gyros and windows)")
    ax.axhline(1.0, color="k", linewidth=1.0, label="threshold")
    for a in result.alarms:
        ax.axvline(a.onset_s, color="r", linestyle="--", linewidth=1.0)
        ax.axvline(a.detected_s, color="r", linestyle=":", linewidth=1.0)
        g = "not isolable" if a.gyro is None else f"gyro {a.gyro}"
        ax.annotate(f"{a.kind}, {g}", (a.onset_s, 1.0), xytext=(3, 10), textcoords="offset points",
                    color="r", fontsize="small")
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("|statistic| / threshold [-]")
    ax.set_title(title or "parity statistics (dashed: fitted onset, dotted: alarm)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small", loc="upper left")
    return save_figure(fig, path, force=force, dpi=120)
