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

from dataclasses import dataclass
from typing import Any

import numpy as np

from gyroarray.analysis.array_covariance import (MatrixEstimate, SharedLine, shared_lines, slow_covariance,
                                                 white_covariance)
from gyroarray.analysis.motion import still_mask
from gyroarray.chain.compare import MIN_STILL_PART, STATIC_RAD_S
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.measurement import Measurement, constant_gyros, true_runs
from gyroarray.effects.model import ArrayNoise, NoiseModel

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
    """

    gyros: tuple
    white: MatrixEstimate
    slow: MatrixEstimate | None
    shared: tuple
    parts_s: tuple
    notes: tuple

    def table(self) -> ArrayNoise:
        """The ``[array]`` table of a model file (correlations rounded to
        :data:`CORRELATION_DECIMALS` decimals where that keeps them positive definite)."""
        dt = self.white.tau_s
        sd = np.sqrt(np.diag(self.white.covariance))
        arw = units.arw_rad_rt_s_to_deg_rt_h(sd * np.sqrt(dt))
        nu = np.diag(self.white.dof)
        out: dict[str, Any] = {"gyros": self.gyros, "white_n_deg_rt_h": _sig(arw), "white_correlation": _rounded(self.white.correlation)}
        sigma: dict[str, Any] = {"white_n_deg_rt_h": _sig(arw / np.sqrt(2.0 * nu)),
                 "white_correlation": _rounded(self.white.corr_sigma)}
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
    notes += list(white.notes) + ([] if slow is None else list(slow.notes))
    return ArrayModel(tuple(int(g) for g in gyro_no), white, slow, shared, tuple(parts_s), tuple(notes))


def with_array_model(model: NoiseModel, fitted: ArrayModel) -> NoiseModel:
    """``model`` with the ``[array]`` table of ``fitted`` (its entries unchanged)."""
    return model.with_array(fitted.table())


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
    if comp.ref is not None:
        static = np.asarray(comp.static, bool)
        return static if static.shape == (n,) else None
    if not comp.parts_s:
        return np.ones(n, bool)
    t = np.asarray(m.time_s, float) - float(m.time_s[0])
    half = 0.5 * float(m.dt_s)
    still = np.zeros(n, bool)
    for a, b in comp.parts_s:
        still |= (t >= a - half) & (t < b - half)
    return still
