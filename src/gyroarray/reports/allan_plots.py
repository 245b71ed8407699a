"""The Allan/Hadamard deviation figure of :func:`gyroarray.analysis.allan.allan_analysis` results.

Moved out of :mod:`gyroarray.analysis.allan` (issue 29: analysis computes, reports draw). One
panel per sensor kind (issue 42): the gyros in deg/h, the accelerometer in m/s², never on one
axis (different units).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from gyroarray.analysis.allan import AllanAnalysis
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.outputs import save_figure

__all__ = ["DeviationPanel", "accel_panel", "gyro_panel", "plot_allan", "plot_allan_panels"]

_NAME = {"oadev": "Allan deviation", "ohdev": "Hadamard deviation", "mdev": "modified Allan deviation",
         "hdev": "Hadamard deviation", "totdev": "total deviation"}


def _identity(x):
    """SI values drawn as they are (the accelerometer's m/s²)."""
    return np.asarray(x, dtype=float)


@dataclass(frozen=True)
class DeviationPanel:
    """One panel of the deviation figure: curves of one sensor kind in one unit.

    Parameters
    ----------
    analyses : mapping of str to AllanAnalysis
        Curves by legend label; their ``*_rad_s`` fields hold the sensor's SI unit (rad/s for a
        gyro, m/s² for an accelerometer axis).
    unit : str
        The y unit drawn, as the axis label says it (``deg/h``, ``m/s²``).
    to_unit : callable
        SI -> ``unit`` (a :mod:`gyroarray.core.units` converter, or the identity for SI).
    title : str
        What the panel shows (``gyros``, ``accelerometer acc_x..z``).
    fit_labels : mapping of str to str, optional
        Legend text of each curve's fitted model (default ``"<label> fit"``), e.g. with its terms.
    """

    analyses: Mapping[str, AllanAnalysis]
    unit: str
    to_unit: Callable
    title: str = ""
    fit_labels: Mapping[str, str] | None = None


def gyro_panel(analyses: Mapping[str, AllanAnalysis], title: str = "") -> DeviationPanel:
    """The gyros' panel: rad/s drawn in deg/h (:func:`gyroarray.core.units.rad_s_to_deg_h`)."""
    return DeviationPanel(analyses, "deg/h", units.rad_s_to_deg_h, title)


def accel_panel(analyses: Mapping[str, AllanAnalysis], title: str = "accelerometer",
                fit_labels: Mapping[str, str] | None = None) -> DeviationPanel:
    """The accelerometer's panel: specific force drawn in m/s² (SI, as ``allan --sensor acc``
    prints and ``--json`` gives it under ``adev_m_s2``)."""
    return DeviationPanel(analyses, "m/s²", _identity, title, fit_labels)


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
    directly (no pyplot, no global backend change). One panel of
    :func:`plot_allan_panels`.
    """
    if not analyses:
        raise InputError("plot_allan needs at least one analysis")
    return plot_allan_panels([gyro_panel(analyses)], path, force=force)[0]


def plot_allan_panels(panels: Sequence[DeviationPanel], path, *,
                      force: bool = True) -> tuple[Path, dict]:
    """Deviation curves side by side, one panel per sensor kind (each its own unit).

    Parameters
    ----------
    panels : sequence of DeviationPanel
        The panels, left to right (e.g. :func:`gyro_panel`, :func:`accel_panel`).
    path : str or os.PathLike
        Output image file; the format follows the suffix (png, pdf, svg).
    force : bool
        Replace an existing file (atomically, :mod:`gyroarray.core.outputs`).

    Returns
    -------
    (pathlib.Path, dict)
        The written file, and what was drawn, read back from the figure's artists: by panel
        index (as a str), ``{"title", "unit", "ylabel", "curves"}``, ``curves`` by legend label
        ``{"taus_s": [s], "deviation": [unit], "ci_low": [unit], "ci_high": [unit],
        "fit_taus_s": [s], "fit": [unit]}`` (the band's edges from its polygon's vertices).

    Raises
    ------
    InputError
        No panel, or a panel without analyses.

    Notes
    -----
    As :func:`plot_allan` per panel: each curve with its confidence band shaded and the fitted
    noise model dashed in the same colour, log-log against tau in s.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib only to draw
    from matplotlib.figure import Figure  # lazy: matplotlib only to draw

    if not panels or any(not p.analyses for p in panels):
        raise InputError("plot_allan_panels needs at least one panel, each with at least one analysis")
    fig = Figure(figsize=(7.0 * len(panels), 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    drawn: dict = {}
    for j, panel in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), j + 1)
        kinds, curves = set(), {}
        conv = panel.to_unit
        for i, (label, an) in enumerate(panel.analyses.items()):
            color = f"C{i % 10}"
            kinds.add(an.kind)
            band = ax.fill_between(an.taus_s, conv(an.ci_low_rad_s), conv(an.ci_high_rad_s),
                                   color=color, alpha=0.2, linewidth=0)
            (curve,) = ax.plot(an.taus_s, conv(an.adev_rad_s), "o-", color=color,
                               markersize=3, label=f"{label} ({an.kind})")
            grid = np.geomspace(an.taus_s[0], an.taus_s[-1], 200)
            fit_label = (panel.fit_labels or {}).get(label, f"{label} fit")
            (fit,) = ax.plot(grid, conv(np.sqrt(an.fit.model_avar(grid))), "--",
                             color=color, linewidth=1.0, label=fit_label)
            curves[label] = _read_back(curve, band, fit)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("averaging time τ [s]")
        ylabel = (_NAME.get(kinds.pop(), "deviation") if len(kinds) == 1 else "deviation") + f" [{panel.unit}]"
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize="small")
        first = next(iter(panel.analyses.values()))
        ax.set_title((f"{panel.title}; " if panel.title else "") + f"shaded: {first.confidence:.1%} confidence")
        drawn[str(j)] = {"title": panel.title, "unit": panel.unit, "ylabel": ylabel, "curves": curves}
    return save_figure(fig, path, force=force, dpi=120), drawn


def _read_back(curve, band, fit) -> dict:
    """The numbers an ADEV curve, its band and its fit were drawn with, from the artists."""
    taus = np.asarray(curve.get_xdata(), dtype=float)
    vert = np.concatenate([p.vertices for p in band.get_paths()])
    low = [float(vert[vert[:, 0] == t, 1].min()) for t in taus]
    high = [float(vert[vert[:, 0] == t, 1].max()) for t in taus]
    return {"taus_s": taus.tolist(), "deviation": np.asarray(curve.get_ydata(), dtype=float).tolist(),
            "ci_low": low, "ci_high": high,
            "fit_taus_s": np.asarray(fit.get_xdata(), dtype=float).tolist(),
            "fit": np.asarray(fit.get_ydata(), dtype=float).tolist()}
