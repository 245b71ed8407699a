"""Allan deviation of single gyros beside the fused output: the data of a report's ADEV figure.

The design report draws, for one simulated record, the Allan deviation of every
single gyro's error and of the fused x/y/z error, with the √(3/N) reference
(paper 003 Figs. 14 and 22). This module computes those curves once
(:func:`single_vs_fused`) into a :class:`AdevFigure` that the reports only draw
and that is saved as JSON beside the outputs (:meth:`AdevFigure.to_dict`,
:meth:`AdevFigure.from_dict`), so a report re-renders without re-simulating.

SI inside: deviations [rad/s], τ [s]; the fitted ARW is in deg/√h (its name says so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gyroarray.analysis.allan import allan_analysis

__all__ = ["AdevCurve", "AdevFigure", "single_vs_fused"]


@dataclass
class AdevCurve:
    """One Allan-deviation curve with its 1σ confidence band.

    Attributes
    ----------
    label : str
        ``"gyro k"`` (a single gyro's error, k from 1) or ``"fused x"`` (y, z).
    taus_s : numpy.ndarray
        Averaging times [s].
    adev_rad_s, ci_low_rad_s, ci_high_rad_s : numpy.ndarray
        Allan deviation and its 1σ confidence bounds (Greenhall EDF) [rad/s].
    arw_fit_deg_rt_h : float
        ARW of the curve's IEEE Std 952 fit [deg/√h] (NaN when the fit has none).
    """

    label: str
    taus_s: np.ndarray
    adev_rad_s: np.ndarray
    ci_low_rad_s: np.ndarray
    ci_high_rad_s: np.ndarray
    arw_fit_deg_rt_h: float = math.nan

    @property
    def single(self) -> bool:
        """A single gyro's curve (not a fused axis)."""
        return self.label.startswith("gyro")

    def to_dict(self) -> dict:
        """JSON-ready dict (lists of floats; NaN as None)."""
        return {"label": self.label, "taus_s": _floats(self.taus_s),
                "adev_rad_s": _floats(self.adev_rad_s), "ci_low_rad_s": _floats(self.ci_low_rad_s),
                "ci_high_rad_s": _floats(self.ci_high_rad_s),
                "arw_fit_deg_rt_h": _float(self.arw_fit_deg_rt_h)}

    @classmethod
    def from_dict(cls, d: dict) -> "AdevCurve":
        """The inverse of :meth:`to_dict`."""
        return cls(label=str(d["label"]), taus_s=_array(d["taus_s"]),
                   adev_rad_s=_array(d["adev_rad_s"]), ci_low_rad_s=_array(d["ci_low_rad_s"]),
                   ci_high_rad_s=_array(d["ci_high_rad_s"]),
                   arw_fit_deg_rt_h=math.nan if d.get("arw_fit_deg_rt_h") is None
                   else float(d["arw_fit_deg_rt_h"]))


@dataclass
class AdevFigure:
    """The curves of one "single gyros vs fused output" figure and what its caption says.

    Attributes
    ----------
    title : str
        The figure's title (what was simulated).
    estimator : str
        The estimator that fused the readings.
    n_gyros : int
        Gyros of the array (the √(3/N) reference uses it).
    dt_s : float
        Sample interval [s].
    record_s : float
        Length of the analysed record after the settling [s].
    curves : list of AdevCurve
        Every single gyro (``"gyro k"``), then the fused axes (``"fused x"``, ...).
    seed : int or None
        Seed of the simulated record.
    rho : float or None
        Correlation between the gyros' noise of the record [-] (None: not stated).
    predicted_arw_long_deg_rt_h : list of float
        The predictor's long-τ fused ARW per axis x, y, z [deg/√h] (empty: none).
    """

    title: str
    estimator: str
    n_gyros: int
    dt_s: float
    record_s: float
    curves: list[AdevCurve] = field(default_factory=list)
    seed: int | None = None
    rho: float | None = None
    predicted_arw_long_deg_rt_h: list[float] = field(default_factory=list)

    @property
    def singles(self) -> list[AdevCurve]:
        """The single gyros' curves."""
        return [c for c in self.curves if c.single]

    @property
    def fused(self) -> list[AdevCurve]:
        """The fused axes' curves."""
        return [c for c in self.curves if not c.single]

    @property
    def reference_factor(self) -> float:
        """√(3/N) [-]: what averaging N alike gyros gives per axis at long τ."""
        return math.sqrt(3.0 / self.n_gyros)

    def to_dict(self) -> dict:
        """JSON-ready dict (see :meth:`from_dict`)."""
        return {"title": self.title, "estimator": self.estimator, "n_gyros": int(self.n_gyros),
                "dt_s": float(self.dt_s), "record_s": float(self.record_s),
                "seed": None if self.seed is None else int(self.seed),
                "rho": _float(self.rho) if self.rho is not None else None,
                "predicted_arw_long_deg_rt_h": [_float(v) for v in self.predicted_arw_long_deg_rt_h],
                "curves": [c.to_dict() for c in self.curves]}

    @classmethod
    def from_dict(cls, d: dict) -> "AdevFigure":
        """The inverse of :meth:`to_dict`."""
        return cls(title=str(d["title"]), estimator=str(d["estimator"]), n_gyros=int(d["n_gyros"]),
                   dt_s=float(d["dt_s"]), record_s=float(d["record_s"]),
                   curves=[AdevCurve.from_dict(c) for c in d["curves"]],
                   seed=None if d.get("seed") is None else int(d["seed"]),
                   rho=None if d.get("rho") is None else float(d["rho"]),
                   predicted_arw_long_deg_rt_h=[math.nan if v is None else float(v)
                                                for v in d.get("predicted_arw_long_deg_rt_h", [])])


def single_vs_fused(single_err_rad_s, fused_err_rad_s, dt_s: float, *, title: str, estimator: str,
                    seed: int | None = None, rho: float | None = None,
                    predicted_arw_long_deg_rt_h=(), record_s: float | None = None) -> AdevFigure:
    """Allan analysis of every single gyro's error and every fused axis's error.

    Parameters
    ----------
    single_err_rad_s : array_like, shape (n, N)
        Each gyro's reading minus its true rate [rad/s].
    fused_err_rad_s : array_like, shape (n, 3)
        The fused body rate minus the truth, x/y/z [rad/s].
    dt_s : float
        Sample interval [s].
    title, estimator : str
        What the figure shows, and the estimator that fused the readings.
    seed, rho : optional
        The record's seed and the gyros' correlation [-], for the caption.
    predicted_arw_long_deg_rt_h : sequence of float
        The predictor's long-τ fused ARW per axis [deg/√h], for the caption.
    record_s : float, optional
        The record's length as the caption states it [s] (default: samples × dt).

    Returns
    -------
    AdevFigure
    """
    single = np.asarray(single_err_rad_s, float)
    fused = np.asarray(fused_err_rad_s, float)
    series = [(f"gyro {k + 1}", single[:, k]) for k in range(single.shape[1])]
    series += [(f"fused {a}", fused[:, i]) for i, a in enumerate("xyz")]
    curves = []
    for label, x in series:
        an = allan_analysis(x, dt_s)
        curves.append(AdevCurve(label=label, taus_s=an.taus_s, adev_rad_s=an.adev_rad_s,
                                ci_low_rad_s=an.ci_low_rad_s, ci_high_rad_s=an.ci_high_rad_s,
                                arw_fit_deg_rt_h=_nan(an.fit.to_datasheet_dict().get("arw_deg_rt_h"))))
    return AdevFigure(title=title, estimator=estimator, n_gyros=single.shape[1], dt_s=float(dt_s),
                      record_s=float(single.shape[0] * dt_s if record_s is None else record_s),
                      curves=curves, seed=seed, rho=rho,
                      predicted_arw_long_deg_rt_h=[float(v) for v in predicted_arw_long_deg_rt_h])


def _nan(v) -> float:
    return math.nan if v is None else float(v)


def _float(v) -> float | None:
    return None if v is None or not math.isfinite(float(v)) else float(v)


def _floats(a) -> list:
    return [_float(v) for v in np.asarray(a, float)]


def _array(v) -> np.ndarray:
    return np.array([math.nan if x is None else float(x) for x in v], float)
