"""The accelerometer's noise: the Allan deviation of ``acc_x..z`` and its IEEE Std 1293 terms.

The Allan machinery of :mod:`gyroarray.analysis.allan` is unit-agnostic in SI: fed a specific
force [m/s²] instead of a rate [rad/s], its ``*_rad_s`` fields hold m/s² and its noise fit's
coefficients are the accelerometer's (IEEE Std 1293, the same power laws as IEEE Std 952):

* ``n`` — velocity random walk N_a [m/s/√s = m/s²/√Hz]: ADEV(τ) = N_a/√τ;
* ``k`` — acceleration random walk K_a [m/s²/√s]: ADEV(τ) = K_a·√(τ/3);
* ``b`` — bias instability B [m/s²]: the flat ADEV floor 0.664·B.

A constant (gravity on z at rest, a level offset) does not change the ADEV. The terms are
fitted exactly as ``gyroarray allan`` fits a gyro's (the same taus, kinds, EDF, confidence
intervals, generalised least squares with every term the deviation can see, non-negative);
a term is *resolved* on an axis when the fit keeps it (not held at zero by the
non-negativity constraint) and it stands out of its own 1σ at :data:`RESOLVED_Z` (the value
at least that many σ). SI inside; datasheet units (m/s/√h, m/s²/√h, mg) only in
:meth:`AccelFit.to_json_dict`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gyroarray.analysis.allan import AllanAnalysis, allan_analysis
from gyroarray.analysis.deviations import analyse_parts, with_noise_id
from gyroarray.core import units
from gyroarray.core.errors import InputError

__all__ = ["ACC_AXES", "ACC_TERMS", "RESOLVED_Z", "AccelFit", "accel_analyses", "accel_fit",
           "analysis_json"]

#: The accelerometer axes, in column order (``acc_x``, ``acc_y``, ``acc_z``).
ACC_AXES = ("x", "y", "z")

#: The accelerometer terms reported, by noise-fit term: (JSON key, datasheet unit, SI -> datasheet).
ACC_TERMS = {
    "n": ("vrw_m_s_rt_h", "m/s/√h", units.vrw_si_to_m_s_rt_h),
    "k": ("accel_rw_m_s2_rt_h", "m/s²/√h", units.accel_rw_si_to_m_s2_rt_h),
    "b": ("bi_mg", "mg", units.m_s2_to_mg),
}

#: A term is resolved when its value is at least this many of its 1σ [-] (and the fit keeps it).
RESOLVED_Z = 2.0

_TERM_TEXT = {"n": "velocity random walk", "k": "acceleration random walk", "b": "bias instability"}


def accel_analyses(acc_m_s2, dt_s: float, parts=None, taus="octave", kind: str = "oadev",
                   axes=ACC_AXES) -> tuple[dict[str, AllanAnalysis], dict[str, str]]:
    """The Allan analysis of each accelerometer axis, as ``gyroarray allan`` does a gyro's.

    Parameters
    ----------
    acc_m_s2 : array_like, shape (n, 3)
        Specific force [m/s²], columns x, y, z.
    dt_s : float
        Sample step [s].
    parts : list of (int, int), optional
        ``[start, stop)`` sample ranges analysed (default the whole record); several, or a kind
        beyond oadev/ohdev, go through :func:`~gyroarray.analysis.deviations.analyse_parts`.
    taus : "octave", int or sequence of float
        Averaging times [s].
    kind : str
        ``oadev``, ``mdev``, ``hdev``, ``ohdev`` or ``totdev``.
    axes : sequence of str
        Which axes to analyse.

    Returns
    -------
    (analyses, skipped) : dict, dict
        The :class:`~gyroarray.analysis.allan.AllanAnalysis` by axis (its ``*_rad_s`` fields in
        m/s², its fit's coefficients in the SI units of the module docstring), and why an axis was
        not analysed (a constant column, a fit that fails), by axis.
    """
    acc = np.asarray(acc_m_s2, dtype=float)
    n = acc.shape[0]
    parts = list(parts) if parts else [(0, n)]
    analyses, skipped = {}, {}
    for axis in axes:
        col = acc[:, ACC_AXES.index(axis)]
        if not np.ptp(col[np.concatenate([np.arange(a, b) for a, b in parts])]):
            skipped[axis] = f"acc_{axis} not analysed: the column is constant (no noise recorded)"
            continue
        try:
            with np.errstate(all="ignore"):
                if parts == [(0, n)] and kind in ("oadev", "ohdev"):
                    analyses[axis] = with_noise_id(allan_analysis(col, dt_s, taus, kind=kind), col)
                else:
                    analyses[axis] = analyse_parts([col[a:b] for a, b in parts], dt_s, taus, kind)
        except InputError as err:
            skipped[axis] = f"acc_{axis} not analysed: {err.message}"
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as err:
            skipped[axis] = f"acc_{axis} not analysed: the noise fit failed on its data ({err})"
    return analyses, skipped


def _resolved(analysis: AllanAnalysis, term: str) -> tuple[float | None, float | None, str]:
    """``(value, sigma, why)`` of one term [SI]: value None (and why) when not resolved."""
    fit = analysis.fit
    value, sigma = fit.coefficient(term)
    name = _TERM_TEXT[term]
    if term not in fit.terms or value is None:
        return None, None, f"{name} not fitted (the deviation does not see it)"
    if term in fit.clamped or not value > 0:
        return None, None, f"{name} held at 0 by the fit (the record does not show it)"
    if sigma is None or not math.isfinite(sigma):
        return None, None, f"{name} has no 1σ (singular fit)"
    if value < RESOLVED_Z * sigma:
        return None, None, (f"{name} {ACC_TERMS[term][2](value):.3g} ± {ACC_TERMS[term][2](sigma):.2g} "
                            f"{ACC_TERMS[term][1]} is within {RESOLVED_Z:g}σ of 0")
    return float(value), float(sigma), ""


@dataclass(frozen=True)
class AccelFit:
    """The accelerometer's noise terms per axis, as fitted (SI units).

    Parameters
    ----------
    axes : tuple of str
        The analysed axes, in order.
    analyses : dict
        The Allan analysis by axis (``*_rad_s`` fields in m/s²).
    values, sigmas : dict
        By term (``n`` [m/s/√s], ``k`` [m/s²/√s], ``b`` [m/s²]): one value (1σ) per analysed axis,
        None on an axis that does not resolve it (as the gyros: each axis keeps what it
        resolves), or None for the term when no analysed axis resolves it.
    per_axis : dict
        By term, by axis: ``(value, sigma, why)`` (value None where not resolved, and why).
    estimates : dict
        By term, by axis: ``(value, sigma, z)``, the fit's estimate whether resolved or not
        (SI; value 0 when not fitted or held at 0, sigma and z None when there is none).
    skipped : dict
        Why an axis was not analysed, by axis.
    notes : tuple of str
        What is missing and why (never a 0 in its place).
    """

    axes: tuple
    analyses: dict = field(repr=False)
    values: dict
    sigmas: dict
    per_axis: dict = field(repr=False)
    skipped: dict
    notes: tuple
    estimates: dict = field(default_factory=dict, repr=False)

    def to_json_dict(self) -> dict:
        """JSON-ready terms in datasheet units: by term key (``vrw_m_s_rt_h``,
        ``accel_rw_m_s2_rt_h``, ``bi_mg``) a list per axis (null on an axis that does not resolve
        it) or None, the same with ``_sigma``, and ``axes``, ``notes``, ``not_analysed``."""
        out: dict = {"axes": list(self.axes)}
        for term, (key, _, conv) in ACC_TERMS.items():
            v, s = self.values[term], self.sigmas[term]
            out[key] = None if v is None else [None if x is None else float(conv(x)) for x in v]
            out[key + "_sigma"] = None if s is None else [None if x is None else float(conv(x)) for x in s]
        out["notes"] = list(self.notes)
        out["not_analysed"] = dict(self.skipped)
        return out


def accel_fit(acc_m_s2, dt_s: float, parts=None, taus="octave", kind: str = "oadev") -> AccelFit:
    """The accelerometer's terms: :func:`accel_analyses`, each term kept where resolved.

    Returns
    -------
    AccelFit
        A term is given on each analysed axis that resolves it, None on the others (``notes``
        say on which axis it is not resolved, and why), as the gyros' terms are kept per gyro.

    Raises
    ------
    InputError
        No axis can be analysed (every reason in one line).
    """
    analyses, skipped = accel_analyses(acc_m_s2, dt_s, parts, taus, kind)
    if not analyses:
        raise InputError("no accelerometer axis can be analysed: " + "; ".join(skipped.values()))
    axes = tuple(analyses)
    values: dict[str, tuple | None] = {}
    sigmas: dict[str, tuple | None] = {}
    per_axis: dict[str, dict] = {}
    notes = list(skipped.values())
    estimates: dict[str, dict] = {}
    for term, (key, unit, _) in ACC_TERMS.items():
        got = {a: _resolved(analyses[a], term) for a in axes}
        per_axis[term] = got
        estimates[term] = {a: _estimate(analyses[a], term) for a in axes}
        if all(g[0] is None for g in got.values()):
            values[term] = sigmas[term] = None
        else:
            values[term] = tuple(g[0] for g in got.values())
            sigmas[term] = tuple(g[1] for g in got.values())
        lacking = [a for a, g in got.items() if g[0] is None]
        if lacking:
            why = "; ".join(f"acc_{a}: {got[a][2]}" for a in lacking)
            held = [a for a in axes if a not in lacking]
            notes.append(f"{key} [{unit}] not resolved on {', '.join('acc_' + a for a in lacking)}, so not "
                         f"given there" + (f" (given for {', '.join('acc_' + a for a in held)})" if held else "")
                         + f": {why}")
    return AccelFit(axes=axes, analyses=analyses, values=values, sigmas=sigmas, per_axis=per_axis,
                    skipped=skipped, notes=tuple(notes), estimates=estimates)


def _estimate(analysis: AllanAnalysis, term: str) -> tuple[float, float | None, float | None]:
    """``(value, sigma, z)`` of one term as fitted [SI], resolved or not: value 0 when the term is
    not fitted or held at 0; sigma None without a finite 1σ; z = value/sigma."""
    fit = analysis.fit
    value, sigma = fit.coefficient(term)
    if term not in fit.terms or value is None or term in fit.clamped or not value > 0:
        value = 0.0
    sigma = None if sigma is None or not math.isfinite(sigma) or not sigma > 0 else float(sigma)
    return float(value), sigma, (None if sigma is None else float(value) / sigma)


def analysis_json(analysis: AllanAnalysis) -> dict:
    """One axis's Allan analysis, JSON-ready in accelerometer units: ``kind``, ``confidence``,
    ``taus_s`` [s], ``adev_m_s2``, ``ci_low_m_s2``, ``ci_high_m_s2`` [m/s²], ``edf`` [-], and
    ``fit``: each term of :data:`ACC_TERMS` with its ``_sigma`` (None when not fitted) and
    ``resolved``, the model error and the clamped terms."""
    fit: dict = {}
    for term, (key, _, conv) in ACC_TERMS.items():
        value, sigma = analysis.fit.coefficient(term)
        fit[key] = None if value is None else float(conv(value))
        fit[key + "_sigma"] = None if sigma is None or not math.isfinite(sigma) else float(conv(sigma))
        fit[key + "_resolved"] = _resolved(analysis, term)[0] is not None
    fit["model_error"] = float(analysis.fit.model_error)
    fit["clamped"] = list(analysis.fit.clamped)
    return {"kind": analysis.kind, "confidence": float(analysis.confidence),
            "taus_s": [float(t) for t in analysis.taus_s],
            "adev_m_s2": [float(v) for v in analysis.adev_rad_s],
            "ci_low_m_s2": [float(v) for v in analysis.ci_low_rad_s],
            "ci_high_m_s2": [float(v) for v in analysis.ci_high_rad_s],
            "edf": [float(v) for v in analysis.edf], "fit": fit}
