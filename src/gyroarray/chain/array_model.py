"""The array noise model of a recorded array: what is between its gyros.

:func:`array_model` reads a measurement's still part (the reference removed
when there is one; without one, the parts
:func:`~gyroarray.analysis.motion.still_mask` finds still, each part's mean
removed), and estimates with :mod:`gyroarray.analysis.array_covariance`

* the cross-covariance and correlation of the white part, with intervals;
* the same of the slow part (Allan covariance at a long τ beyond the white
  share), between the gyros where it is seen;
* the lines several gyros share (coherent bands), named as common mode.

A correlation matrix that is not positive definite, or that the record is
too short to estimate, is refused (``regularise="refuse"``, an
:class:`~gyroarray.core.errors.InputError` naming the file) or regularised
with a note (``"clip"``, ``"shrink"``). The result becomes the ``[array]``
table of a model file (:meth:`ArrayModel.table`, :class:`~gyroarray.effects.model.ArrayNoise`;
``docs/model-format.md``); the per-gyro terms stay the effect entries that
``fit`` writes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import stats

from gyroarray.analysis.array_covariance import (MatrixEstimate, SharedLine, shared_lines, slow_covariance,
                                                 white_at_tau, white_covariance)
from gyroarray.analysis.motion import still_mask
from gyroarray.analysis.white_level import pooled_white_level
from gyroarray.chain.compare import MIN_STILL_PART, STATIC_RAD_S
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.measurement import Measurement, constant_gyros, true_runs
from gyroarray.effects.model import ArrayNoise, ModelEntry, NoiseModel
from gyroarray.effects.names import ARW

__all__ = ["ArrayModel", "still_residual", "array_model", "with_array_model", "comparison_still"]

#: Fewest still samples the array model reads [-] (two 1 s blocks of differences at 100 Hz
#: for 8 gyros are far too few; 512 gives the white part ~340 degrees of freedom).
MIN_ARRAY_SAMPLES = 512
#: Decimals kept of a correlation written to a model file [-].
CORRELATION_DECIMALS = 6


@dataclass(frozen=True)
class ArrayModel:
    """The fitted cross-covariance of an array.

    Attributes
    ----------
    gyros : tuple of int
        1-based gyros of the rows (constant gyros left out).
    white : MatrixEstimate
        White part, per sample.
    slow : MatrixEstimate or None
        Slow part at ``slow.tau_s`` (None when the record is too short for one).
    shared : tuple of SharedLine
        Common-mode lines (gyro numbers are the measurement's).
    parts_s : tuple of (float, float)
        The still parts read, [start, stop) in the record's time [s].
    notes : tuple of str
        What was left out, regularised, or could not be estimated.
    white_tau : MatrixEstimate or None
        White part where white noise is read: the Allan covariance at τ1 ≈ 1 s pooled over
        the still parts (:func:`~gyroarray.analysis.array_covariance.white_at_tau`); the
        table's white level and correlation come from it (None: from the per-sample ``white``,
        a record with no part longer than 2 s).
    """

    gyros: tuple
    white: MatrixEstimate
    slow: MatrixEstimate | None
    shared: tuple
    parts_s: tuple
    notes: tuple
    white_tau: MatrixEstimate | None = None
    correlation_basis: str = "sample"

    def table(self) -> ArrayNoise:
        """The ``[array]`` table of a model file (correlations rounded to
        :data:`CORRELATION_DECIMALS` decimals where that keeps them positive definite).

        ``white_n_deg_rt_h`` is each gyro's white level read as every command reads it (σ(τ1)·√τ1,
        pooled over the still parts: ``fit``'s ``arw`` entries, ``fuse``'s single gyros), and
        ``white_correlation`` the correlation at the same τ1 (``white_tau_s``); the per-sample
        correlation (every frequency up to Nyquist, common-mode lines included) is in the
        JSON's ``white`` only."""
        w = self.white if self.white_tau is None else self.white_tau
        c = self.white_tau if self.white_tau is not None and self.correlation_basis == "tau" else self.white
        tau = w.tau_s
        sd = np.sqrt(np.diag(w.covariance))
        arw = units.arw_rad_rt_s_to_deg_rt_h(sd * np.sqrt(tau))
        nu = np.diag(w.dof)
        out: dict[str, Any] = {"gyros": self.gyros, "white_n_deg_rt_h": _sig(arw),
                               "white_correlation": _rounded(c.correlation)}
        if self.white_tau is not None:
            out["white_tau_s"] = float(tau)
        sigma: dict[str, Any] = {"white_n_deg_rt_h": _sig(arw / np.sqrt(2.0 * nu)),
                                 "white_correlation": _rounded(c.corr_sigma)}
        if self.slow is not None:
            s = np.diag(self.slow.covariance)
            adev = units.rad_s_to_deg_h(np.sqrt(np.maximum(s, 0.0)) * self.slow.seen)
            se = (np.diag(self.slow.cov_hi) - np.diag(self.slow.cov_lo)) / (2 * 1.959963984540054)
            sd_adev = np.where(adev > 0, units.rad_s_to_deg_h(se / (2 * np.sqrt(np.maximum(s, 1e-300)))),
                               units.rad_s_to_deg_h(np.sqrt(np.maximum(se, 0.0))))
            out.update(walk_tau_s=float(self.slow.tau_s), walk_adev_deg_h=_sig(adev),
                       walk_correlation=_rounded(self.slow.correlation))
            sigma.update(walk_adev_deg_h=_sig(sd_adev), walk_correlation=_rounded(self.slow.corr_sigma))
        shared = tuple({"f_hz": _sig1(s.f_hz), "band_hz": (_sig1(s.f_lo_hz), _sig1(s.f_hi_hz)), "gyros": s.gyros,
                        "coherence": round(s.coherence, 4)} for s in self.shared)
        return ArrayNoise(**out, shared=shared, notes=self.notes, sigma=sigma)

    def to_json_dict(self) -> dict:
        """Plain dict for ``--json`` (SI units in the matrices, the table in the file's units)."""
        return {"gyros": list(self.gyros), "white": self.white.to_json_dict(),
                "white_tau": None if self.white_tau is None else self.white_tau.to_json_dict(),
                "slow": None if self.slow is None else self.slow.to_json_dict(),
                "shared": [s.to_dict() for s in self.shared], "parts_s": [list(p) for p in self.parts_s],
                "notes": list(self.notes), "table": self.table().to_dict()}

    def text_lines(self) -> list[str]:
        """Lines for a command's text output."""
        iu = np.triu_indices(len(self.gyros), 1)
        r = self.white.correlation[iu]
        lines = [f"array model ({len(self.gyros)} gyros, {sum(b - a for a, b in self.parts_s):.1f} s still):",
                 f"  white correlation: mean {r.mean():+.4f}, range {r.min():+.4f} .. {r.max():+.4f}" if r.size
                 else "  white correlation: one gyro"]
        if self.slow is not None:
            seen = int(self.slow.seen.sum())
            lines.append(f"  slow part at tau = {self.slow.tau_s:.4g} s: seen on {seen} of {len(self.gyros)} gyros")
        lines += [f"  shared: {s.text()}" for s in self.shared] or ["  shared lines: none"]
        return lines + [f"  note: {n}" for n in self.notes]


def _sig(x) -> tuple:
    return tuple(_sig1(v) for v in np.asarray(x, float))


def _sig1(v: float) -> float:
    return float(f"{float(v):.6g}")


def _rounded(r: np.ndarray) -> tuple:
    """Rounded rows; the full values when rounding would lose definiteness or symmetry."""
    q = np.round(np.asarray(r, float), CORRELATION_DECIMALS)
    if np.allclose(np.diag(q), 1.0) and np.linalg.eigvalsh(q)[0] <= 0:
        q = np.asarray(r, float)
    return tuple(tuple(float(v) for v in row) for row in q)


def still_residual(measurement: Measurement, *, gyros=None,
                   still=None) -> tuple[np.ndarray, list, list, list[str]]:
    """The still part of a record with the true rate removed.

    Parameters
    ----------
    measurement : Measurement
        The record.
    gyros : sequence of int, optional
        0-based columns to keep (default all).
    still : ndarray of bool, shape (n,), optional
        Samples known still (e.g. from a diagnosis that found them already); default
        the reference's static samples, or :func:`~gyroarray.analysis.motion.still_mask`.

    Returns
    -------
    x : ndarray, shape (n, N')
        Residual [rad/s]: still parts stitched, each part's mean removed (with a reference,
        the gyro output less ``H·ref`` first).
    parts : list of (int, int)
        Parts of ``x``.
    parts_s : list of (float, float)
        Where they were in the record [s].
    notes : list of str

    Raises
    ------
    InputError
        Fewer than :data:`MIN_ARRAY_SAMPLES` still samples (naming the file).
    """
    name = measurement.source or "measurement"
    y = np.asarray(measurement.gyro_rad_s, float)
    H = np.asarray(measurement.layout.axes, float)
    dt = float(measurement.dt_s)
    notes: list[str] = []
    if measurement.ref_rad_s is not None:
        ref = measurement.ref_rad_s
        y = y - ref @ H.T
    if still is not None:
        still = np.asarray(still, bool)
        if still.shape != (y.shape[0],):
            raise ValueError(f"still must have shape ({y.shape[0]},), got {still.shape}")
        what = "given still"
    elif measurement.ref_rad_s is not None:
        still = np.all(np.abs(measurement.ref_rad_s) <= STATIC_RAD_S, axis=1)
        what = "static (the reference within 0.01 deg/s)"
    else:
        still = still_mask(y, H, dt)
        what = "still (no reference: found from the outputs)"
    runs = [(a, b) for a, b in true_runs(still) if b - a >= MIN_STILL_PART]
    total = sum(b - a for a, b in runs)
    if total < MIN_ARRAY_SAMPLES:
        raise InputError(f"the {what} parts of at least {MIN_STILL_PART} samples add up to {total} samples "
                         f"({total * dt:.1f} s); the array model needs at least {MIN_ARRAY_SAMPLES}: record a "
                         "longer still part", file=name)
    if len(runs) > 1 or runs[0] != (0, y.shape[0]):
        notes.append(f"read the {len(runs)} {what} part(s), {total * dt:.1f} s of {y.shape[0] * dt:.1f} s")
    cols = slice(None) if gyros is None else list(gyros)
    pieces, parts, parts_s, start = [], [], [], 0
    t = measurement.time_s - measurement.time_s[0]
    for a, b in runs:
        seg = y[a:b][:, cols]
        pieces.append(seg - seg.mean(axis=0))
        parts.append((start, start + b - a))
        parts_s.append((float(t[a]), float(t[b - 1] + dt)))
        start += b - a
    return np.concatenate(pieces), parts, parts_s, notes


def array_model(measurement: Measurement, *, tau_s: float | None = None, regularise: str = "shrink",
                level: float = 0.95, lines: bool = True, still=None) -> ArrayModel:
    """Fit the array noise model (cross-covariances, shared lines) of a measurement.

    Parameters
    ----------
    measurement : Measurement
        A record of N >= 2 gyros with a still part.
    tau_s : float, optional
        Averaging time of the slow part [s]; default the longest octave τ with at least
        max(2N, 30) block differences in the still parts.
    regularise : {"refuse", "clip", "shrink"}
        A correlation matrix that is not positive definite or cannot be estimated.
    level : float
        Confidence level of the intervals [-].
    lines : bool
        Look for shared lines (coherence).
    still : ndarray of bool, shape (n,), optional
        Samples known still (:func:`still_residual`).

    Returns
    -------
    ArrayModel

    Raises
    ------
    InputError
        Fewer than 2 gyros with output, too short a still part, or (``refuse``) a matrix that
        is not positive definite; each naming the measurement file.
    """
    name = measurement.source or "measurement"
    dead = constant_gyros(measurement)
    keep = [k for k in range(measurement.n_gyros) if k + 1 not in dead]
    if len(keep) < 2:
        raise InputError(f"the array model needs at least 2 gyros with output, got {len(keep)}", file=name)
    x, parts, parts_s, notes = still_residual(measurement, gyros=keep, still=still)
    if dead:
        notes.append(f"gyro(s) {', '.join(map(str, dead))} constant: left out of the array model")
    dt = float(measurement.dt_s)
    try:
        white = white_covariance(x, dt, parts=parts, level=level, regularise=regularise, name=name)
        try:
            white_tau = white_at_tau(x, dt, parts=parts, level=level, regularise=regularise, name=name)
        except InputError as err:
            if regularise == "refuse" and "cannot be read" not in err.message:
                raise
            white_tau = None
            notes.append(f"white level and correlation per sample: {err.message}")
        assert white is not None
        try:
            slow = slow_covariance(x, dt, tau_s=tau_s, parts=parts, level=level, regularise=regularise,
                                   white=white, name=name, labels=[k + 1 for k in keep])
        except InputError as err:
            if regularise == "refuse" or "block differences" not in err.message:
                raise
            slow = None
            notes.append(f"no slow part: {err.message}")
        found: list[SharedLine] = shared_lines(x, dt, parts=parts) if lines else []
    except InputError as err:
        raise err.with_file(name) from None
    gyro_no = np.asarray([k + 1 for k in keep])
    shared = tuple(SharedLine(s.f_hz, s.f_lo_hz, s.f_hi_hz, tuple(int(gyro_no[g - 1]) for g in s.gyros),
                              s.coherence, s.max_coherence, s.n_pairs, s.threshold) for s in found)
    basis = "sample"
    if white_tau is not None:
        basis, why = correlation_basis(white, white_tau, np.asarray(measurement.layout.axes, float)[keep])
        notes.append(why)
    notes += (list(white.notes if basis == "sample" or white_tau is None else white_tau.notes)
              + ([] if slow is None else list(slow.notes)))
    return ArrayModel(tuple(int(g) for g in gyro_no), white, slow, shared, tuple(parts_s), tuple(notes),
                      white_tau, basis)


#: Level of the test that keeps the per-sample white correlation [-].
BASIS_LEVEL = 0.99


def correlation_basis(per_sample: MatrixEstimate, at_tau: MatrixEstimate, axes: np.ndarray) -> tuple[str, str]:
    """Which white correlation a model keeps, ``"sample"`` or ``"tau"``, and why (one line).

    The per-sample correlation is the more precise (every difference of the record: ~60 times
    the EDF of the Allan covariance at τ1 ≈ 1 s), but it reads every frequency up to Nyquist,
    where a narrow common-mode line moves it; at τ1 it is what a fused ARW reads. Where it
    matters is the fused rate: with each gyro's level N at τ1 and the least-squares weights w of
    the layout, the fused white variance of each axis wᵀ(C ∘ NNᵀ)w under the per-sample
    correlation against under the one at τ1 (as measured). The per-sample correlation is kept
    while every axis's ratio is within the τ1 estimate's own :data:`BASIS_LEVEL` interval (χ²
    with its EDF); else the correlation at τ1, shrunk (the MIMU4444 board: the z gyros' 17.6 Hz
    line makes the per-sample correlation predict the fused z ARW 8-20 % high)."""
    n = per_sample.correlation.shape[0]
    if n < 2 or axes.shape != (n, 3) or np.linalg.matrix_rank(axes) < 3:
        return "sample", "white correlation per sample (no 3-axis layout to test it on)"
    lev = np.sqrt(np.diag(at_tau.covariance))
    sd = lev.copy()
    raw = at_tau.covariance / np.outer(sd, sd)
    w = np.linalg.pinv(axes)
    v_ps = np.einsum("ai,ij,aj->a", w, per_sample.correlation * np.outer(lev, lev), w)
    v_t = np.einsum("ai,ij,aj->a", w, raw * np.outer(lev, lev), w)
    ratio = v_ps / np.maximum(v_t, 1e-300)
    edf = float(at_tau.dof[0, 0])
    lo = edf / float(stats.chi2.ppf(0.5 + BASIS_LEVEL / 2, edf))
    hi = edf / float(stats.chi2.ppf(0.5 - BASIS_LEVEL / 2, edf))
    txt = ", ".join(f"{a} x{r:.3f}" for a, r in zip("xyz", ratio))
    if np.all((ratio >= lo) & (ratio <= hi)):
        return "sample", (f"white correlation per sample: on the fused axes it gives the variance the one at "
                          f"tau = {at_tau.tau_s:.3g} s gives ({txt}, within [{lo:.3f}, {hi:.3f}]), more precisely")
    return "tau", (f"white correlation at tau = {at_tau.tau_s:.3g} s, where the fused ARW is read: the per-sample "
                   f"one would give the fused axes {txt} of its variance (outside [{lo:.3f}, {hi:.3f}]: a "
                   "common-mode line or a short-tau term moves it)")


def with_array_model(model: NoiseModel, fitted: ArrayModel) -> NoiseModel:
    """``model`` with the ``[array]`` table of ``fitted`` (its entries unchanged), whose white level
    is the model's ``arw`` entry for each gyro that has one: a model file carries one ARW per
    gyro (``fit`` keeps the Allan fit's N where it agrees with the pooled reading at 1 s within
    2σ, :meth:`~gyroarray.chain.compare.ModelComparison.white_level`)."""
    table = fitted.table()
    own = {e.gyro: float(e.params["n_deg_rt_h"]) for e in model
           if e.effect == ARW and e.gyro is not None and "n_deg_rt_h" in e.params}
    if own and table.white_n_deg_rt_h is not None:
        table = replace(table, white_n_deg_rt_h=tuple(own.get(g, v) for g, v in zip(table.gyros,
                                                                                   table.white_n_deg_rt_h)))
    return model.with_array(table)


def comparison_still(comp) -> np.ndarray | None:
    """The still samples a :class:`~gyroarray.chain.compare.ModelComparison` read, as a mask of
    its measurement (so :func:`array_model` need not look for them again).

    Parameters
    ----------
    comp : ModelComparison

    Returns
    -------
    ndarray of bool, shape (n,), or None
        With a reference rate: its static samples; without one: the still parts it kept
        (all samples when it kept the whole record); None when the parts cannot be mapped back.
    """
    m = comp.m
    n = int(m.n_samples)
    gaps = getattr(comp, "segments", [(0, n)])[1:]
    if comp.ref is not None and not gaps:
        static = np.asarray(comp.static, bool)
        return static if static.shape == (n,) else None
    if comp.ref is not None:
        return None        # with gaps the static mask is of the stitched record: not mapped back
    if not comp.parts_s:
        return np.ones(n, bool)
    t = np.asarray(m.time_s, float) - float(m.time_s[0])
    half = 0.5 * float(m.dt_s)
    still = np.zeros(n, bool)
    for a, b in comp.parts_s:
        still |= (t >= a - half) & (t < b - half)
    # a record read with --gaps: the first sample after each gap is left out, so that no run of
    # the mask (and no difference of the array model) spans a gap
    for a, _ in gaps:
        still[a] = False
    return still


# -- several records of one array: what carries over -------------------------------------------
#: Significance below which a gyro's white level is said to wander between records [-]
#: (the heterogeneity χ² of its per-record levels; a family of 24 gyros at 1e-3 keeps the
#: chance of one false "wanders" near 2 %).
WANDER_ALPHA = 1e-3
#: Smallest between-record ratio (largest / smallest level) called a wander [-]: the board's
#: stable gyros stay within ±10 % between experiments.
WANDER_RATIO = 1.25
#: Two-sided level of the credible range of a gyro's white level on a new record [-].
RANGE_LEVEL = 0.95


@dataclass(frozen=True)
class RecordLevels:
    """Each gyro's white level on one record (:func:`record_levels`).

    Attributes
    ----------
    source : str
        The record's file.
    gyros : tuple of int
        1-based gyros.
    n_rad_rt_s, sigma : ndarray (C,)
        White level N = σ(τ1)·√τ1 pooled over the still parts and its 1σ [rad/√s].
    tau_s : float
        τ1 [s].
    still_s : float
        Still time read [s].
    """

    source: str
    gyros: tuple
    n_rad_rt_s: np.ndarray
    sigma: np.ndarray
    tau_s: float
    still_s: float


def record_levels(measurement: Measurement, gyros=None, *, still=None) -> RecordLevels:
    """The white level of each gyro of one record, read as every command reads it
    (:func:`~gyroarray.analysis.white_level.pooled_white_level` on :func:`still_residual`).

    Parameters
    ----------
    measurement : Measurement
    gyros : sequence of int, optional
        1-based gyros (default every gyro with output).
    still : ndarray of bool, optional
        As :func:`still_residual`.

    Raises
    ------
    InputError
        Too short a still part, or none longer than 2τ1 (naming the file).
    """
    name = measurement.source or "measurement"
    if gyros is None:
        dead = constant_gyros(measurement)
        gyros = [k for k in range(1, measurement.n_gyros + 1) if k not in dead]
    x, parts, _, _ = still_residual(measurement, gyros=[g - 1 for g in gyros], still=still)
    lev = pooled_white_level(x, float(measurement.dt_s), parts)
    if lev is None:
        raise InputError("no still part is longer than 2 s: the white level (ADEV at 1 s) cannot be read",
                         file=name)
    return RecordLevels(name, tuple(int(g) for g in gyros), lev[0], lev[1], float(lev[2]),
                        float(x.shape[0] * measurement.dt_s))


@dataclass(frozen=True)
class LevelsAcross:
    """Each gyro's white level across several records (:func:`levels_across`).

    Attributes (arrays per gyro, SI [rad/√s] unless stated)
    ----------
    gyros : tuple of int
    per_record : ndarray (R, C)
        The level on each record.
    central : ndarray (C,)
        Random-effects mean (geometric): the level of the ``arw`` entries.
    sigma_new : ndarray (C,)
        1σ of ln N on a new record [-]: the mean's standard error and the between-record spread.
    low, high : ndarray (C,)
        Credible range on a new record (:data:`RANGE_LEVEL`, normal quantile), at least the
        per-record levels' own range.
    spread : ndarray (C,)
        Between-record standard deviation of ln N (DerSimonian–Laird τ) [-].
    ratio : ndarray (C,)
        Largest over smallest per-record level [-].
    p : ndarray (C,)
        Heterogeneity p-value (χ² of the per-record levels about their weighted mean).
    wanders : ndarray of bool (C,)
        p < :data:`WANDER_ALPHA` and ratio > :data:`WANDER_RATIO`.
    sources : tuple of str
    """

    gyros: tuple
    per_record: np.ndarray
    central: np.ndarray
    sigma_new: np.ndarray
    low: np.ndarray
    high: np.ndarray
    spread: np.ndarray
    ratio: np.ndarray
    p: np.ndarray
    wanders: np.ndarray
    sources: tuple

    def text_lines(self) -> list[str]:
        arw = units.arw_rad_rt_s_to_deg_rt_h
        lines = [f"white level across {len(self.sources)} records (N = ADEV(1 s)·√(1 s), pooled still parts):"]
        w = np.flatnonzero(self.wanders)
        if not w.size:
            lines.append("  every gyro stable between the records")
        for i in w:
            lines.append(f"  gyro {self.gyros[i]} wanders x{self.ratio[i]:.2f} between records "
                         f"({', '.join(f'{v:.3g}' for v in arw(self.per_record[:, i]))} deg/√h); "
                         f"designed with {arw(self.high[i]):.3g} deg/√h, its worst credible level")
        return lines

    def to_json_dict(self) -> dict:
        arw = units.arw_rad_rt_s_to_deg_rt_h
        return {"sources": list(self.sources), "level": RANGE_LEVEL,
                "definition": "N = ADEV(tau1)*sqrt(tau1), tau1 ~ 1 s, pooled over each record's still parts; "
                              "random-effects (DerSimonian-Laird) mean of ln N across records",
                "gyros": {str(g): {"per_record_n_deg_rt_h": [float(v) for v in arw(self.per_record[:, i])],
                                   "n_deg_rt_h": float(arw(self.central[i])),
                                   "low_deg_rt_h": float(arw(self.low[i])), "high_deg_rt_h": float(arw(self.high[i])),
                                   "between_record_sd_ln": float(self.spread[i]), "ratio": float(self.ratio[i]),
                                   "p": float(self.p[i]), "wanders": bool(self.wanders[i])}
                          for i, g in enumerate(self.gyros)}}


def levels_across(records: list[RecordLevels]) -> LevelsAcross:
    """Combine per-record white levels of one array (random effects on ln N).

    y_r = ln N_r with variance s_r² = (σ_r/N_r)²; Cochran's Q = Σ w_r (y_r − ȳ_w)², w = 1/s²;
    τ² = max(0, (Q − (R − 1)) / (Σw − Σw²/Σw)) (DerSimonian–Laird); the mean μ = Σ w*_r y_r / Σ w*_r
    with w* = 1/(s² + τ²); a new record's ln N ~ μ ± z √(τ² + 1/Σw*) (z the normal quantile of
    :data:`RANGE_LEVEL`), widened to the per-record levels' own range. One record: τ = 0.
    """
    gyros = records[0].gyros
    for r in records[1:]:
        if r.gyros != gyros:
            raise InputError(f"the records do not have the same gyros with output ({list(gyros)} against "
                             f"{list(r.gyros)}): fit them on the same gyros", file=r.source)
    N = np.vstack([r.n_rad_rt_s for r in records])
    S = np.vstack([r.sigma for r in records])
    R = N.shape[0]
    y = np.log(np.maximum(N, 1e-300))
    s2 = np.maximum((S / np.maximum(N, 1e-300)) ** 2, 1e-12)
    w = 1.0 / s2
    yw = (w * y).sum(axis=0) / w.sum(axis=0)
    Q = (w * (y - yw) ** 2).sum(axis=0)
    if R > 1:
        c = w.sum(axis=0) - (w ** 2).sum(axis=0) / w.sum(axis=0)
        tau2 = np.maximum(0.0, (Q - (R - 1)) / np.maximum(c, 1e-300))
        p = stats.chi2.sf(Q, R - 1)
    else:
        tau2, p = np.zeros(N.shape[1]), np.ones(N.shape[1])
    # the normal quantile, as DerSimonian–Laird's own intervals: Student's t with R − 1 dof put a
    # gyro seen at 0.82 and 2.47 deg/√h on two records at 2.7e5 deg/√h (t = 12.7), a weight of 0
    q = float(stats.norm.ppf(0.5 + RANGE_LEVEL / 2))
    ws = 1.0 / (s2 + tau2)
    mu = (ws * y).sum(axis=0) / ws.sum(axis=0)
    sd_new = np.sqrt(tau2 + 1.0 / ws.sum(axis=0))
    ratio = N.max(axis=0) / np.maximum(N.min(axis=0), 1e-300)
    wanders = (p < WANDER_ALPHA) & (ratio > WANDER_RATIO)
    low = np.minimum(np.exp(mu - q * sd_new), N.min(axis=0))
    high = np.maximum(np.exp(mu + q * sd_new), N.max(axis=0))
    return LevelsAcross(gyros, N, np.exp(mu), sd_new, low, high, np.sqrt(tau2), ratio, p, wanders,
                        tuple(r.source for r in records))


def with_levels(model: NoiseModel, across: LevelsAcross, note: str | None = None) -> NoiseModel:
    """``model`` with each gyro's ``arw`` entry and the ``[array]`` white level set to ``across``'s
    central level (1σ: a new record's), and the table's credible range, ``records`` and a note
    naming the gyros that wander (with their ratio)."""
    arw_u = units.arw_rad_rt_s_to_deg_rt_h
    idx = {g: i for i, g in enumerate(across.gyros)}
    entries = []
    for e in model:
        if e.effect == ARW and e.gyro in idx:
            i = idx[e.gyro]
            n = float(arw_u(across.central[i]))
            entries.append(ModelEntry(ARW, e.gyro, {**dict(e.params), "n_deg_rt_h": n},
                                      sigma={"n_deg_rt_h": float(n * across.sigma_new[i])}))
        else:
            entries.append(e)
    out = NoiseModel(tuple(entries), description=model.description, source=model.source)
    table = model.array
    if table is None:
        return out
    names = list(table.gyros)
    cen, lo, hi = (tuple(_sig1(arw_u(v[idx[g]])) if g in idx else float("nan") for g in names)
                   for v in (across.central, across.low, across.high))
    wand = [f"gyro {g} x{across.ratio[idx[g]]:.2f}" for g in names if g in idx and across.wanders[idx[g]]]
    notes = tuple(table.notes) + (((note,) if note else ())
                                  + (f"white level across {len(across.sources)} records: "
                                     + (f"wandering {', '.join(wand)} (designed with the high end of the range)"
                                        if wand else "every gyro stable"),))
    sigma = dict(table.sigma)
    sigma["white_n_deg_rt_h"] = tuple(_sig1(arw_u(across.central[idx[g]]) * across.sigma_new[idx[g]])
                                      for g in names)
    return out.with_array(replace(table, white_n_deg_rt_h=cen, white_n_low_deg_rt_h=lo,
                                  white_n_high_deg_rt_h=hi, records=len(across.sources), notes=notes,
                                  sigma=sigma))
