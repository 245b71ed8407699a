"""Fusing a recorded array: any registered estimator applied to a measurement (issue 31, item 1).

:func:`fuse` takes a :class:`~gyroarray.core.measurement.Measurement` of N gyros and
returns the fused body rate (n, 3) of one estimator of :mod:`gyroarray.estimators`,
with what it did and what fusion bought:

1. **Gyros.** Constant gyros (dead or stuck: :func:`~gyroarray.core.measurement.constant_gyros`)
   and the gyros the caller excludes (1-based, as everywhere) are left out; the estimator
   is designed for the axes of the remaining ones. Fewer than 3 independent axes left is
   refused.
2. **Noise the estimator is designed with.** From a noise model (``arw``, ``rrw`` and the
   ``correlation`` entry, per gyro, through :func:`~gyroarray.estimators.noise.array_noise`;
   the rows and columns of the excluded gyros dropped), or, without one, fitted on the
   record's still part: per gyro, ARW N and RRW K from the octave Allan variance,
   σ²(τ) = N²/τ + K²τ/3, by weighted non-negative least squares (:func:`white_walk_fit`;
   no correlation between gyros).
3. **Where the noise is read** (the *analysed part*). With a reference rate: the whole
   record, as output − layout·ref (what ``gyroarray allan`` analyses). Without one: the
   still parts found in the outputs (:func:`~gyroarray.analysis.motion.still_mask`, parts
   of at least :data:`MIN_PART` samples), each part's own mean taken out and the parts
   joined (:func:`stitch`); τ beyond a part's length sees the joins.
4. **What fusion bought**, per body axis a, on the analysed part:
   the fused ADEV at the octave τ with its confidence interval
   (:func:`~gyroarray.analysis.allan.allan_analysis`, 1σ band), the fused ARW (the same
   white + walk fit as the single gyros), the best single gyro and the **gain**
   ``G_a = min_k (ARW_k / |h_ka|) / ARW_fused,a``: gyro k alone reads axis a as
   z_k / h_ka, so ARW_k/|h_ka| is the white noise it would give on that axis (for a gyro
   along ±a simply its ARW). G_a > 1: fusion beats the best gyro of the array on that axis.
   And the fused ARW the design noise predicts for the estimator (white part only, with the
   model's correlation): sqrt(diag(G R_c Gᵀ)), G the estimator's gain to slow changes
   (:meth:`~gyroarray.estimators.base.LinearSystem.dc_gain`), R_c the white noise's
   two-sided PSD [rad²/s]; None for an estimator that is not a fixed linear filter.

The fused record is a measurement of three "gyros" along the platform axes
(:func:`fused_measurement`): ``gyro1``, ``gyro2``, ``gyro3`` are the fused rate about x, y,
z [deg/s], with the input's reference, temperature and specific force, so ``allan``,
``davar``, ``compare`` and ``fdi`` read it as any other measurement; its sidecar's
``[fused]`` table says how it was made (:func:`fused_files`).

A record longer than memory is fused in chunks by :mod:`gyroarray.chain.fuse_stream` (the fixed
linear filters, the whole record analysed; ``gyroarray fuse --stream``).

Speed: the estimators run on the whole record at once (a static one is one matrix
product, a Kalman filter its steady-state recursion); on the 24-gyro MIMU4444 record
(37 439 samples) ``gyroarray fuse --estimator gls`` takes about 2.5 s of CPU, most of it
the imports and reading the file (``fdi``, a detector run sample by sample, about 30 s).
"""

from __future__ import annotations

import gzip
import hashlib
import math
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import tomli_w
from scipy import stats

from gyroarray import __version__
from gyroarray.analysis.allan import ONE_SIGMA, allan_analysis
from gyroarray.analysis.white_level import (WhiteWalk, nnls2, octave_avar, pooled_deviation,
                                            pooled_white_level, white_walk_fit, white_walk_of_avar)
from gyroarray.analysis.motion import still_mask
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.gdop import unobservable_reason
from gyroarray.core.layout import Layout
from gyroarray.core.limits import open_regular
from gyroarray.core.measurement import Measurement, constant_gyros, true_runs
from gyroarray.estimators import ArrayNoise, Estimator, get_estimator, make
from gyroarray.estimators.noise import array_noise, table_correlation
from gyroarray.estimators.svo import allan_covariance
from gyroarray.effects.names import ARW, CORRELATION

__all__ = ["MIN_PART", "AXES", "WhiteWalk", "FuseResult", "fuse", "still_parts", "stitch",
           "octave_avar", "white_walk_fit", "white_walk_of_avar", "design_rrw", "nnls2", "fused_measurement", "fused_files", "sha256_of",
           "split_parts", "joined", "fused_terms", "band_basis", "predicted_band", "tau_verdict", "validate_fuse",
           "resolve_estimator", "used_gyros", "check_geometry", "model_noise", "fitted_noise", "noise_of_model", "gain_of", "predicted_arw", "plain_params",
           "best_single_of", "axes_json", "fused_sidecar"]

#: Shortest still part [samples] kept for the noise analysis (as ``compare``'s).
MIN_PART = 256
#: Names of the body axes.
AXES = ("x", "y", "z")
#: Fewest samples of analysed part for the Allan fits (6 octaves up to n/8).
MIN_ANALYSED = 256
#: Smallest positive ARW of a model's gyro an estimator is designed with [deg/√h]: far below any
#: gyro built; below it N²/dt underflows towards 0 and the noise covariance is singular.
MIN_MODEL_ARW_DEG_RT_H = 1e-9
#: Largest ratio of two used gyros' model ARWs [-]: a gyro 1e4 times noisier than the best
#: carries 1e-8 of its weight (nothing a fused rate can show), while the noise covariance's
#: condition number (ratio²) beyond 1e8 stalls the Kalman designs (kf_array's bandwidth
#: search ran > 100 s at 1e5, "Eigenvalues did not converge" at 6e7).
MAX_MODEL_ARW_SPREAD = 1e4


# =========================================================================
# The analysed part and the white + walk fit
# =========================================================================
def still_parts(meas: Measurement, keep: list[int]) -> tuple[list[tuple[int, int]], str]:
    """Where the noise is read: ``[start, stop)`` sample ranges and what they are.

    Parameters
    ----------
    meas : Measurement
        The record.
    keep : list of int
        0-based columns of the gyros used (the still test looks at these only).

    Returns
    -------
    parts : list of (int, int)
        The whole record with a reference rate; else the still parts of at least
        :data:`MIN_PART` samples (empty when there is none).
    what : str
        One line for the output.
    """
    n = meas.n_samples
    if meas.has_reference:
        return [(0, n)], "the whole record, output minus layout·reference"
    y = meas.gyro_rad_s[:, keep]
    try:
        still = still_mask(y, meas.layout.axes[keep], meas.dt_s)
    except InputError:                        # fewer than 3 one-second windows: all of it
        return [(0, n)], "the whole record (too short to look for motion)"
    if still.all():
        return [(0, n)], "the whole record (no reference rate; the outputs show no motion)"
    parts = [(a, b) for a, b in true_runs(still) if b - a >= MIN_PART]
    total = sum(b - a for a, b in parts) * meas.dt_s
    return parts, (f"{len(parts)} still part(s), {total:.1f} s of {n * meas.dt_s:.1f} s (no "
                   "reference rate: still parts found in the outputs, each part's mean taken out)")


def stitch(x: np.ndarray, parts) -> np.ndarray:
    """The parts ``x[a:b]`` of a (n, C) series, each minus its own mean, joined end to end."""
    x = np.asarray(x, dtype=float)
    return np.concatenate([x[a:b] - x[a:b].mean(axis=0) for a, b in parts])


def joined(parts) -> list[tuple[int, int]]:
    """Where each part lies in :func:`stitch`'s output, ``[start, stop)``: the Allan fits pool
    them without differencing across a join (:func:`~gyroarray.analysis.white_level.white_walk_fit`)."""
    out, start = [], 0
    for a, b in parts:
        out.append((start, start + b - a))
        start += b - a
    return out


# =========================================================================
# Fusion
# =========================================================================
@dataclass(frozen=True, eq=False)
class FuseResult:
    """What :func:`fuse` did and found.

    Attributes
    ----------
    measurement : Measurement
        The input record.
    estimator : str
        Registry name of the estimator.
    params : dict
        Its hyperparameters.
    fused_rad_s : ndarray (n, 3)
        Fused body rate [rad/s].
    used : list of int
        The gyros fused (1-based, input numbering).
    excluded : list of int
        Left out because the caller asked (1-based).
    constant : list of int
        Left out because constant (1-based).
    noise : ArrayNoise
        The noise the estimator was designed with (the used gyros, in order).
    model_source : str
        Where that noise came from (a model file, or the fit on the record).
    parts : list of (int, int)
        Analysed part, ``[start, stop)`` sample ranges of the input.
    analysed : str
        One line on the analysed part.
    single : WhiteWalk or None
        White + walk fit of each used gyro on the analysed part (None: too little of it).
    fused_fit : WhiteWalk or None
        The same fit of the fused axes.
    adev : list of AllanAnalysis or None
        Fused ADEV with CIs per axis on the analysed part (None where it failed).
    predicted_arw_rad_rt_s : ndarray (3,) or None
        Fused ARW the design noise predicts (white part, module docstring).
    notes : list of str
        What the user should know.
    gain : ndarray (3, N') or None
        The estimator's gain to slow changes of the used gyros' readings
        (:meth:`~gyroarray.estimators.base.LinearSystem.dc_gain`; a static estimator's
        weights); None for an estimator that is not a fixed linear filter.
    time_constant_s : float or None
        Slowest time constant of the estimator's filter [s] (0 for a static estimator).
    """

    measurement: Measurement
    estimator: str
    params: dict
    fused_rad_s: np.ndarray
    used: list
    excluded: list
    constant: list
    noise: ArrayNoise
    model_source: str
    parts: list
    analysed: str
    single: WhiteWalk | None
    fused_fit: WhiteWalk | None
    adev: list | None
    predicted_arw_rad_rt_s: np.ndarray | None
    notes: list = field(default_factory=list)
    gain: np.ndarray | None = None
    time_constant_s: float | None = None
    model_check: dict | None = None

    def best_single(self) -> list[tuple[int | None, float]]:
        """Per axis: (best single gyro, 1-based, or None; its ARW on that axis [rad/√s])."""
        return best_single_of(self.single, self.used, self.measurement.layout.axes)

    def to_json_dict(self) -> dict:
        """The result in datasheet units (deg/h, deg/√h, deg/h/√h) for ``--json``."""
        arw = units.arw_rad_rt_s_to_deg_rt_h
        rrw = units.rrw_rad_s_rt_s_to_deg_h_rt_h
        m = self.measurement
        axes = axes_json(self.adev, self.fused_fit, self.best_single(), self.predicted_arw_rad_rt_s)
        single = None
        if self.single is not None:
            single = {str(k): {"arw_deg_rt_h": float(arw(self.single.arw_rad_rt_s[i])),
                               "arw_deg_rt_h_sigma": float(arw(self.single.arw_sigma[i])),
                               "rrw_deg_h_rt_h": float(rrw(self.single.rrw_rad_s_rt_s[i]))}
                      for i, k in enumerate(self.used)}
        return {
            "measurement": m.source, "n_samples": m.n_samples, "dt_s": m.dt_s,
            "estimator": self.estimator, "estimator_params": self.params,
            "model_source": self.model_source,
            "gyros_used": list(self.used), "excluded_gyros": list(self.excluded),
            "constant_gyros": list(self.constant),
            "design_noise": {
                "arw_deg_rt_h": [float(v) for v in arw(self.noise.arw_rad_rt_s)],
                "rrw_deg_h_rt_h": [float(v) for v in rrw(self.noise.rrw_rad_s_rt_s)],
                "correlated": bool(not np.array_equal(self.noise.corr_arw, np.eye(len(self.used))))},
            "analysed": self.analysed,
            "analysed_parts": [[int(a), int(b)] for a, b in self.parts],
            "analysed_parts_s": [[float(m.time_s[a] - m.time_s[0]), float(m.time_s[b - 1] - m.time_s[0] + m.dt_s)]
                                 for a, b in self.parts],
            "axes": axes, "single_gyros": single, "model_check": self.model_check,
            "gain_definition": "gain = min over used gyros k of (ARW_k / |h_k,axis|) / fused ARW "
                               "of the axis; ARWs from the same white + walk Allan fit on the "
                               "analysed part",
            "notes": list(self.notes),
        }


def best_single_of(single: WhiteWalk | None, used, axes) -> list[tuple[int | None, float]]:
    """Per axis: (best single gyro, 1-based, or None; its ARW on that axis [rad/√s]) of the
    ``used`` gyros' white + walk fit ``single``, ``axes`` the record's layout (N, 3)."""
    out: list[tuple[int | None, float]] = []
    if single is None:
        return [(None, math.nan)] * 3
    h = np.asarray(axes)[[k - 1 for k in used]]
    for a in range(3):
        proj = np.abs(h[:, a])
        ok = (proj > 1e-9) & (single.arw_rad_rt_s > 0)
        if not ok.any():
            out.append((None, math.nan))
            continue
        eq = np.where(ok, single.arw_rad_rt_s / np.where(ok, proj, 1.0), np.inf)
        j = int(np.argmin(eq))
        out.append((used[j], float(eq[j])))
    return out


def axes_json(adev, fused_fit: WhiteWalk | None, best, predicted) -> dict:
    """The ``axes`` object of ``fuse --json``: per axis the fused ADEV with its CI, the fused
    ARW, the best single gyro, the gain and the predicted ARW (datasheet units)."""
    arw = units.arw_rad_rt_s_to_deg_rt_h
    rrw = units.rrw_rad_s_rt_s_to_deg_h_rt_h
    axes: dict = {}
    for a, name in enumerate(AXES):
        d: dict = {}
        if adev is not None and adev[a] is not None:
            j = adev[a].to_json_dict()
            d.update({k: j[k] for k in ("kind", "confidence", "taus_s", "adev_deg_h",
                                        "ci_low_deg_h", "ci_high_deg_h", "edf")})
        if fused_fit is not None:
            d["arw_deg_rt_h"] = float(arw(fused_fit.arw_rad_rt_s[a]))
            d["arw_deg_rt_h_sigma"] = float(arw(fused_fit.arw_sigma[a]))
            d["rrw_deg_h_rt_h"] = float(rrw(fused_fit.rrw_rad_s_rt_s[a]))
        k, eq = best[a]
        d["best_single_gyro"] = k
        d["best_single_arw_deg_rt_h"] = None if k is None else float(arw(eq))
        f = d.get("arw_deg_rt_h")
        d["gain"] = (float(arw(eq)) / f) if (k is not None and f) else None
        d["predicted_arw_deg_rt_h"] = (None if predicted is None else float(arw(predicted[a])))
        axes[name] = d
    return axes


def resolve_estimator(estimator: str, params: dict) -> tuple[type[Estimator], Estimator]:
    """The registry class of ``estimator`` and an unfitted instance with ``params``; a bad name or
    hyperparameter is refused as ``--estimator``'s."""
    try:
        return cast("type[Estimator]", get_estimator(estimator)), make(estimator, **params)
    except InputError as err:
        raise InputError(f"--estimator: {err.message}") from None


def used_gyros(meas: Measurement, exclude) -> tuple[list[int], list[int], list[int], str | None]:
    """(used, excluded, constant, note on the constant ones), all 1-based."""
    n = meas.n_gyros
    excluded = sorted({int(k) for k in exclude})
    bad = [k for k in excluded if not 1 <= k <= n]
    if bad:
        raise InputError(f"--exclude {bad[0]} is out of range: the measurement has gyros 1..{n}",
                         file=meas.source)
    constant = [k for k in constant_gyros(meas) if k not in excluded]
    used = [k for k in range(1, n + 1) if k not in excluded and k not in constant]
    note = None
    if constant:
        which = "gyro " + str(constant[0]) if len(constant) == 1 else \
            "gyros " + ", ".join(map(str, constant))
        note = f"{which} left out: constant output (dead or stuck?)"
    return used, excluded, constant, note


def check_geometry(meas: Measurement, used, excluded, constant) -> None:
    left = []
    if excluded:
        left.append(f"--exclude {','.join(map(str, excluded))}")
    if constant:
        left.append(f"constant gyro(s) {','.join(map(str, constant))}")
    why_left = f" after leaving out {' and '.join(left)}" if left else ""
    if not used:
        raise InputError(f"no gyro left to fuse{why_left}: give fewer --exclude", file=meas.source)
    why = unobservable_reason(np.asarray(meas.layout.axes)[[k - 1 for k in used]])
    if why is not None:
        raise InputError(f"the {len(used)} gyro(s) left{why_left} do not span 3 independent "
                         f"axes ({why}): fusion needs a 3-axis rate; exclude fewer gyros",
                         file=meas.source)



def fitted_noise(arw: np.ndarray, ww: "WhiteWalk", used, notes: list, how: str = "") -> tuple[ArrayNoise, str]:
    """The estimator's noise without a model: per gyro ``arw`` [rad/√s] and the rate random walk
    :func:`design_rrw` gives from the white + walk fit ``ww``, no correlation between gyros; the
    notes say so (``how``: how the Allan variance was read) and name the gyros whose walk is
    designed with its 2σ bound. Returns (noise, its source text)."""
    rrw, floored = design_rrw(ww)
    noise = ArrayNoise(arw, rrw, np.eye(len(used)), np.eye(len(used)))
    source = ("fitted on the record's analysed part: per gyro ARW + RRW from the octave Allan "
              "variance, no correlation between gyros")
    notes.append("no --model: the estimator's noise was " + source + how)
    if floored:
        notes.append(f"the rate random walk of gyro(s) {', '.join(str(used[i]) for i in floored)} "
                     "is not resolved from 0 on this record: the estimator is designed with its "
                     "2-sigma upper bound (a drift the record cannot tell from none is not ruled out)")
    return noise, source


def noise_of_model(model, meas, used, needs_arw: bool, model_name: str | None,
                   notes: list) -> tuple[ArrayNoise, str]:
    """The estimator's noise from a model (:func:`model_noise`), with a note naming the model's
    effects the estimator does not use. Returns (noise, its source text)."""
    name = model_name or "the model"
    noise = model_noise(model, meas, used, needs_arw, name)
    if noise.ignored_effects:
        notes.append(f"the estimator models ARW, RRW and correlation only; the model's "
                     f"{', '.join(noise.ignored_effects)} are not used by it")
    return noise, f"model {name}"


def check_model_arw(arw: np.ndarray, used: list[int], model_name: str) -> None:
    """Refuse model ARWs [rad/√s] of the used gyros the estimators cannot be designed with:
    a positive one below :data:`MIN_MODEL_ARW_DEG_RT_H`, or two more than
    :data:`MAX_MODEL_ARW_SPREAD` apart (module constants say why)."""
    deg = np.array([units.arw_rad_rt_s_to_deg_rt_h(float(v)) for v in arw])
    tiny = [(used[i], deg[i]) for i in range(deg.size) if 0.0 < arw[i] and deg[i] < MIN_MODEL_ARW_DEG_RT_H]
    if tiny:
        k, v = tiny[0]
        raise InputError(f"the model's angle random walk of gyro {k} is {v:.3g} deg/√h: an "
                         f"estimator's white-noise covariance needs it in "
                         f"[{MIN_MODEL_ARW_DEG_RT_H:g}, 6e+06] deg/√h (far below any gyro built, "
                         "N²/dt is no longer representable)", file=model_name)
    pos = np.flatnonzero(arw > 0)
    if pos.size >= 2:
        lo, hi = pos[np.argmin(arw[pos])], pos[np.argmax(arw[pos])]
        if arw[hi] > MAX_MODEL_ARW_SPREAD * arw[lo]:
            raise InputError(f"the model's angle random walk of gyro {used[hi]} ({deg[hi]:.3g} deg/√h) "
                             f"is more than {MAX_MODEL_ARW_SPREAD:g} times gyro {used[lo]}'s "
                             f"({deg[lo]:.3g} deg/√h): it would carry under 1e-8 of the weight and "
                             f"the noise covariance is too ill-conditioned to design with; the used "
                             f"gyros' ARWs must lie within a factor {MAX_MODEL_ARW_SPREAD:g}: "
                             f"--exclude {used[hi]}, or correct the model", file=model_name)


def model_noise(model, meas: Measurement, used: list[int], needs_arw: bool, model_name: str) -> ArrayNoise:
    """The model's ARW/RRW/correlation for the used gyros (rows and columns of the others dropped)."""
    try:
        full = array_noise(model, meas.n_gyros, require_arw=False)
    except InputError as err:
        raise err.with_file(model_name) from None
    idx = [k - 1 for k in used]
    arw = full.arw_rad_rt_s[idx]
    if needs_arw and np.any(arw <= 0):
        bad = [used[i] for i in np.flatnonzero(arw <= 0).tolist()]
        raise InputError(f"the model gives no positive angle random walk ({ARW!r}) for gyro(s) "
                         f"{', '.join(map(str, bad))}: this estimator weights the gyros by their "
                         "white noise; add an arw entry for them, or --exclude them",
                         file=model_name)
    check_model_arw(arw, used, model_name)
    # the [array] table's correlations are in these already (array_noise reads it)
    c_arw, c_rrw = full.corr_arw[np.ix_(idx, idx)], full.corr_rrw[np.ix_(idx, idx)]
    try:
        return ArrayNoise(arw, full.rrw_rad_s_rt_s[idx], c_arw, c_rrw, full.ignored_effects,
                          zero_arw_ok=not needs_arw)
    except InputError as err:
        raise err.with_file(model_name) from None


def design_rrw(ww: WhiteWalk) -> tuple[np.ndarray, list[int]]:
    """The RRW an estimator is designed with: the fitted K where K² exceeds twice its 1σ,
    else the 2σ upper bound sqrt(2σ_K²) (a Kalman filter with bias states needs K > 0, and a
    drift the record cannot tell from none must not be ruled out). Returns (K [rad/s/√s],
    indices where the bound was used)."""
    k, sk = ww.rrw_rad_s_rt_s, np.nan_to_num(ww.rrw_sigma, nan=0.0)
    sig_c = np.where(k > 0, 2.0 * k * sk, sk ** 2)              # 1σ of K²
    low = k ** 2 < 2.0 * sig_c
    out = np.where(low, np.sqrt(2.0 * sig_c), k)
    return out, np.flatnonzero(low & (out > k)).tolist()


def plain_params(params: dict) -> dict:
    """Hyperparameters as JSON can hold them (arrays as nested lists, other objects by repr)."""
    out = {}
    for k, v in params.items():
        if isinstance(v, np.ndarray):
            out[k] = v.tolist()
        elif v is None or isinstance(v, (bool, int, float, str, list, tuple, dict)):
            out[k] = v
        else:
            out[k] = repr(v)
    return out


def gain_of(est, dt_s: float) -> tuple[np.ndarray | None, float | None]:
    """(gain to slow changes (3, N), slowest time constant [s]) of a fitted estimator, or
    (None, None) when it is not a fixed linear filter."""
    try:
        sysm = est.linear_system()
        g = sysm.dc_gain()
    except (InputError, np.linalg.LinAlgError, ValueError, AttributeError, NotImplementedError):
        return None, None
    lam = np.abs(np.asarray(sysm.lam))
    live = lam[(lam > 1e-12) & (np.abs(1.0 - lam) > 1e-12)]
    tc = 0.0 if live.size == 0 else float(-dt_s / np.log(np.max(live)))
    return np.asarray(g, dtype=float), tc


def predicted_arw(est, noise: ArrayNoise) -> np.ndarray | None:
    """sqrt(diag(G R_c Gᵀ)) [rad/√s], G the estimator's gain to slow changes (module docstring)."""
    try:
        g = est.linear_system().dc_gain()
    except (InputError, np.linalg.LinAlgError, ValueError):
        return None
    s = noise.arw_rad_rt_s
    rc = noise.corr_arw * np.outer(s, s)
    v = np.einsum("ai,ij,aj->a", g, rc, g)
    return np.sqrt(np.maximum(v, 0.0))


#: How ``fuse --model`` treats a gyro whose white level on the record lies outside the model's
#: range: ``"record"`` (default) designs the estimator with the record's own level for it,
#: ``"model"`` keeps the model's (the check is reported either way).
OFF_LEVELS = ("record", "model")
#: Confidence level of the model check [-] (the record's level and the model's range).
CHECK_LEVEL = 0.95
#: Worst fused ARW a model's weights may give against OLS on the same record before it is said [-].
OLS_MARGIN = 1.05


def model_levels(model, n_gyros: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each gyro's white level in a model: (central N, 1σ, low, high) [rad/√s], NaN where the model
    has none. Central and 1σ: the ``arw`` entry (its ``sigma``); low/high: the ``[array]`` table's
    credible range of a model fitted on several records, else central·exp(∓z·σ/N) (z the normal
    quantile of :data:`CHECK_LEVEL`)."""
    cen, sig = np.full(n_gyros, np.nan), np.zeros(n_gyros)
    every = None
    for e in model:
        if e.effect != ARW:
            continue
        v = float(e.params.get("n_deg_rt_h", np.nan))
        sv = float((e.sigma or {}).get("n_deg_rt_h", 0.0) or 0.0)
        if e.gyro is None:
            every = (v, sv)
        elif 1 <= e.gyro <= n_gyros:
            cen[e.gyro - 1], sig[e.gyro - 1] = v, sv
    if every is not None:
        fill = np.isnan(cen)
        cen[fill], sig[fill] = every
    z = float(stats.norm.ppf(0.5 + CHECK_LEVEL / 2))
    rel = np.where(cen > 0, sig / np.where(cen > 0, cen, 1.0), 0.0)
    low, high = cen * np.exp(-z * rel), cen * np.exp(z * rel)
    table = getattr(model, "array", None)
    if table is not None and getattr(table, "white_n_low_deg_rt_h", None) is not None:
        for g, lo, hi in zip(table.gyros, table.white_n_low_deg_rt_h, table.white_n_high_deg_rt_h):
            if 1 <= g <= n_gyros:
                low[g - 1], high[g - 1] = lo, hi
    to_si = units.arw_deg_rt_h_to_rad_rt_s
    return to_si(cen), to_si(sig), to_si(low), to_si(high)


def check_model(model, level: "WhiteWalk", used: list[int], n_gyros: int) -> dict:
    """Each used gyro's white level on the record (``level``: the pooled reading, with its 1σ)
    against the model's range (:func:`model_levels`): a gyro is *off* when the record's
    :data:`CHECK_LEVEL` interval and the model's range do not overlap. JSON-ready (deg/√h)."""
    cen, _, low, high = model_levels(model, n_gyros)
    z = float(stats.norm.ppf(0.5 + CHECK_LEVEL / 2))
    arw = units.arw_rad_rt_s_to_deg_rt_h
    gyros, off = {}, []
    for i, k in enumerate(used):
        n, s = float(level.arw_rad_rt_s[i]), float(np.nan_to_num(level.arw_sigma[i]))
        lo_r, hi_r = n * math.exp(-z * s / n) if n > 0 else 0.0, n * math.exp(z * s / n) if n > 0 else 0.0
        lo_m, hi_m = float(low[k - 1]), float(high[k - 1])
        bad = bool(np.isfinite(lo_m) and (hi_r < lo_m or lo_r > hi_m))
        gyros[str(k)] = {"record_n_deg_rt_h": float(arw(n)), "record_sigma_deg_rt_h": float(arw(s)),
                         "model_n_deg_rt_h": float(arw(cen[k - 1])), "model_low_deg_rt_h": float(arw(lo_m)),
                         "model_high_deg_rt_h": float(arw(hi_m)), "off": bad}
        if bad:
            off.append(k)
    return {"level": CHECK_LEVEL, "off": off, "gyros": gyros,
            "definition": "white level N = ADEV(tau1)*sqrt(tau1), tau1 ~ 1 s, pooled over the still parts; "
                          "a gyro is off when the record's interval and the model's range do not overlap"}


def _off_text(check: dict) -> str:
    parts = []
    for k in check["off"]:
        g = check["gyros"][str(k)]
        parts.append(f"gyro {k} {g['record_n_deg_rt_h']:.3g} (model {g['model_low_deg_rt_h']:.3g}-"
                     f"{g['model_high_deg_rt_h']:.3g})")
    return ", ".join(parts)


def fuse(meas: Measurement, estimator: str, *, model=None, model_name: str | None = None,
         exclude=(), params: dict | None = None, noise: ArrayNoise | None = None,
         noise_source: str | None = None, off_levels: str = "record") -> FuseResult:
    """Fuse a recorded array with a registered estimator (module docstring).

    Parameters
    ----------
    meas : Measurement
        The record (layout from its sidecar).
    estimator : str
        Registry name (:func:`gyroarray.estimators.available`).
    model : NoiseModel, optional
        Noise of the N gyros of the record (``arw``, ``rrw``, ``correlation`` are used);
        None: fitted on the analysed part (white + walk per gyro, no correlation).
    model_name : str, optional
        The model's file, for the messages and the provenance.
    exclude : iterable of int
        Gyros to leave out (1-based).
    params : dict, optional
        Hyperparameters of the estimator.
    noise : ArrayNoise, optional
        The noise of the gyros left after ``exclude`` and the constant ones, in order, to
        design the estimator with (instead of ``model`` or the fit; :func:`validate_fuse`).
    noise_source : str, optional
        Where ``noise`` came from (one line).

    Returns
    -------
    FuseResult

    Raises
    ------
    InputError
        Unknown estimator or hyperparameter, an excluded gyro out of range, fewer than 3
        independent axes left, a model without ARW for a used gyro (estimators that weight
        by it), or no model and no still part to fit the noise on; each names the file.
    """
    params = dict(params or {})
    cls, est = resolve_estimator(estimator, params)
    used, excluded, constant, const_note = used_gyros(meas, exclude)
    check_geometry(meas, used, excluded, constant)
    notes = [] if const_note is None else [const_note]
    idx = [k - 1 for k in used]
    dt = meas.dt_s
    y = meas.gyro_rad_s[:, idx]
    h = np.asarray(meas.layout.axes)[idx]
    parts, analysed = still_parts(meas, idx)
    total = sum(b - a for a, b in parts)
    enough = total >= MIN_ANALYSED
    e_single = None
    if enough:
        resid = y - meas.ref_rad_s @ h.T if meas.has_reference else y
        e_single = stitch(resid, parts)
    if noise is not None:
        if noise.n_gyros != len(used):
            raise ValueError(f"noise has {noise.n_gyros} gyros, {len(used)} are used")
        source = noise_source or "given"
    elif model is None:
        if not enough:
            raise InputError(f"no --model, and the record has {total * dt:.1f} s of still part to fit "
                             f"the gyros' noise on (at least {MIN_ANALYSED} samples are needed): give "
                             "--model M.toml (e.g. from gyroarray fit)", file=meas.source)
        assert e_single is not None
        ww = white_walk_fit(e_single, dt, parts=joined(parts))
        arw = ww.arw_rad_rt_s.copy()
        weak = arw <= 0
        if weak.any():                    # a walk alone: the white level from the differences
            d = np.diff(e_single[:, weak], axis=0)
            arw[weak] = np.maximum(np.std(d, axis=0) / math.sqrt(2.0) * math.sqrt(dt), 1e-30)
        noise, source = fitted_noise(arw, ww, used, notes)
    else:
        noise, source = noise_of_model(model, meas, used, cls.needs_arw, model_name, notes)
    check = None
    pred_noise = None
    pred_levels = None
    if model is not None and noise_source is None and enough:
        # the model against the record before it is used: each gyro's white level here
        if off_levels not in OFF_LEVELS:
            raise InputError(f"--off-levels must be one of {', '.join(OFF_LEVELS)}, got {off_levels!r}")
        here = white_walk_fit(cast(np.ndarray, e_single), dt, parts=joined(parts))
        check = check_model(model, here, used, meas.n_gyros)
        if check["off"]:
            what = (f"the white level of {_off_text(check)} deg/√h on this record lies outside the model's "
                    f"{CHECK_LEVEL:.0%} range")
            if off_levels == "record" and cls.needs_arw:
                arw = noise.arw_rad_rt_s.copy()
                for k in check["off"]:
                    arw[used.index(k)] = max(float(here.arw_rad_rt_s[used.index(k)]), 1e-30)
                noise = ArrayNoise(arw, noise.rrw_rad_s_rt_s, noise.corr_arw, noise.corr_rrw,
                                   noise.ignored_effects, zero_arw_ok=noise.zero_arw_ok)
                notes.append(what + ": the estimator is designed with the record's own level for "
                             f"gyro(s) {', '.join(map(str, check['off']))} (--off-levels record, the default; "
                             "--off-levels model keeps the model's)")
                source += f", the record's own white level for gyro(s) {', '.join(map(str, check['off']))}"
            else:
                notes.append(what + ": the model's levels are kept (--off-levels model)")
        check["action"] = off_levels if check["off"] else None
        # the prediction reads each gyro at the model's central level (the record's own for a
        # gyro found off, with --off-levels record), not at the high end the estimator is designed with
        cen, sig, _, _ = model_levels(model, meas.n_gyros)
        cen, sig = cen[[k - 1 for k in used]], sig[[k - 1 for k in used]]
        n_pred = np.where(np.isfinite(cen) & (cen > 0), cen, noise.arw_rad_rt_s)
        s_pred = np.where(np.isfinite(sig), sig, 0.0)
        if off_levels == "record":
            for k in check["off"]:
                i = used.index(k)
                n_pred[i] = noise.arw_rad_rt_s[i]
                s_pred[i] = float(np.nan_to_num(here.arw_sigma[i]))
        pred_noise = ArrayNoise(np.maximum(n_pred, 1e-30), noise.rrw_rad_s_rt_s, noise.corr_arw, noise.corr_rrw,
                                noise.ignored_effects, zero_arw_ok=noise.zero_arw_ok)
        lev1 = pooled_white_level(cast(np.ndarray, e_single)[:, :1], dt, joined(parts))
        pred_levels = (s_pred, 0.0 if lev1 is None else float(lev1[3]))
    if model is None and "allan_covariance" in est.get_params() and est.get_params()["allan_covariance"] is None:
        tau = est.get_params().get("tau_s")
        if isinstance(tau, (int, float)) and math.isfinite(tau) and tau > 0:
            assert e_single is not None
            mm = max(int(round(tau / dt)), 1)
            if 2 * mm <= e_single.shape[0]:
                # the diagonal only: N² cross terms from T/τ blocks over-fit (MIMU4444, weights
                # from its first 10 still parts, ADEV on the other 10 at τ = 8 s: x 10.9 deg/h
                # with the full matrix, 7.6 with its diagonal, 12.7 with gls)
                est.set_params(allan_covariance=np.diag(np.diag(allan_covariance(e_single, mm))))
                notes.append(f"{estimator}: weights from each gyro's Allan variance measured on the "
                             f"analysed part at tau = {mm * dt:g} s (no cross terms; in sample: the fused "
                             "ADEV there is optimised on the same data; validate on another record, or "
                             "give --model for weights from a model)")
    try:
        est.fit(Layout.from_axes(h, source=meas.source), noise, dt)
    except InputError as err:
        text = err.message if err.message.startswith(f"{estimator}:") else f"{estimator}: {err.message}"
        # with a model, what the estimator cannot be designed with is the model's noise
        raise InputError(text, file=meas.source if model is None else (model_name or meas.source)) from None
    fused = np.asarray(est.estimate(y), dtype=float)
    gain, tconst = gain_of(est, dt)
    if excluded:
        notes.append(f"gyro(s) {', '.join(map(str, excluded))} left out (--exclude)")
    adev: list[Any] | None
    single = fused_fit = adev = None
    if enough:
        e_fused = fused - meas.ref_rad_s if meas.has_reference else fused
        ef = stitch(e_fused, parts)
        both = white_walk_fit(np.hstack([cast(np.ndarray, e_single), ef]), dt, parts=joined(parts))
        c = len(used)
        single = WhiteWalk(*(v[:c] for v in (both.arw_rad_rt_s, both.arw_sigma, both.rrw_rad_s_rt_s,
                                              both.rrw_sigma)))
        fused_fit = WhiteWalk(*(v[c:] for v in (both.arw_rad_rt_s, both.arw_sigma, both.rrw_rad_s_rt_s,
                                                 both.rrw_sigma)))
        if check is not None and gain is not None and pred_levels is not None and pred_noise is not None:
            # the prediction's interval: the model's levels on a new record (their 1σ) and this
            # record's own sampling of the fused ADEV at τ1 (χ² with the pooled EDF)
            n2, n2_sd = fused_terms(gain, pred_noise.arw_rad_rt_s, pred_levels[0], pred_noise.corr_arw)
            rel_model = n2_sd / np.maximum(2.0 * n2, 1e-300)                  # 1σ of ln N_fused
            edf = max(pred_levels[1], 1.0)
            z = float(stats.norm.ppf(0.5 + CHECK_LEVEL / 2))
            lo_s = math.sqrt(edf / float(stats.chi2.ppf(0.5 + CHECK_LEVEL / 2, edf)))
            hi_s = math.sqrt(edf / float(stats.chi2.ppf(0.5 - CHECK_LEVEL / 2, edf)))
            p = np.sqrt(n2)
            lo = p * np.exp(-np.sqrt((z * rel_model) ** 2 + math.log(1.0 / lo_s) ** 2))
            hi = p * np.exp(np.sqrt((z * rel_model) ** 2 + math.log(hi_s) ** 2))
            arw_d = units.arw_rad_rt_s_to_deg_rt_h
            check["predicted_arw_deg_rt_h"] = [float(v) for v in arw_d(p)]
            check["predicted_interval_deg_rt_h"] = [[float(arw_d(a_)), float(arw_d(b_))] for a_, b_ in zip(lo, hi)]
            check["measured_arw_deg_rt_h"] = [float(v) for v in arw_d(fused_fit.arw_rad_rt_s)] \
                if fused_fit is not None else None
            check["interval"] = (f"{CHECK_LEVEL:.0%}: the model's levels on a new record (their 1σ, the "
                                 "between-record spread of a model fitted on several records) and the record's "
                                 f"own sampling of ADEV(tau1) (chi-square, EDF {edf:.0f})")
        if check is not None and gain is not None:
            # never silently worse than OLS on the same record
            assert fused_fit is not None
            e_ols = stitch((y - meas.ref_rad_s @ h.T if meas.has_reference else y) @ np.linalg.pinv(h).T, parts)
            ww_ols = white_walk_fit(e_ols, dt, parts=joined(parts))
            ratio = fused_fit.arw_rad_rt_s / np.maximum(ww_ols.arw_rad_rt_s, 1e-300)
            check["ols_arw_deg_rt_h"] = [float(v) for v in units.arw_rad_rt_s_to_deg_rt_h(ww_ols.arw_rad_rt_s)]
            check["fused_over_ols"] = [float(v) for v in ratio]
            worse = [AXES[a] for a in range(3) if ratio[a] > OLS_MARGIN]
            if worse:
                notes.append(f"with the model's weights the fused ARW is worse than plain OLS on this record on "
                             f"{', '.join(f'{a} (x{ratio[AXES.index(a)]:.2f})' for a in worse)}: the model's "
                             "levels or correlations do not hold here; refit on this record (gyroarray fit) or "
                             "fuse with --estimator ols")
        adev = []
        for a in range(3):
            try:
                with np.errstate(all="ignore"):
                    # stitched parts: the ADEV pooled within them (a τ beyond one part would
                    # read the joins), its interval from the parts' summed EDF
                    adev.append(allan_analysis(ef[:, a], dt) if len(parts) == 1 else
                                pooled_deviation(ef[:, a], dt, joined(parts), ONE_SIGMA))
            except (InputError, np.linalg.LinAlgError, ValueError, FloatingPointError) as err:
                adev.append(None)
                notes.append(f"fused {AXES[a]}: no ADEV ({getattr(err, 'message', err)})")
    else:
        notes.append(f"the analysed part is {total} samples, fewer than {MIN_ANALYSED}: no ADEV, "
                     "no ARW, no gain (the fused record is written all the same)")
    return FuseResult(measurement=meas, estimator=estimator, params=plain_params(est.get_params()),
                      fused_rad_s=fused, used=used, excluded=excluded, constant=constant,
                      noise=noise, model_source=source, parts=parts, analysed=analysed,
                      single=single, fused_fit=fused_fit, adev=adev,
                      predicted_arw_rad_rt_s=predicted_arw(est, noise if pred_noise is None else pred_noise),
                      notes=notes,
                      gain=gain, time_constant_s=tconst, model_check=check)


# =========================================================================
# Predict, then validate (issue 31, item 3)
# =========================================================================
#: Monte-Carlo runs of the prediction band.
VALIDATE_RUNS = 200
#: Two-sided level of the prediction band and of the measured CI [-].
VALIDATE_LEVEL = 0.95
#: Fraction of the τ inside the band at which a prediction is called consistent [-].
CONSISTENT_FRACTION = 0.9
#: τ below which a miss is read as "not white" (the white + walk fit starts here) [s].
SHORT_TAU_S = 1.0
#: Spread (median absolute deviation) of log(measured / predicted) over the missed τ below which
#: they are "a consistent factor" [-].
FACTOR_LOG_SPREAD = 0.15


def split_parts(parts, holdout: float) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Split ``[start, stop)`` parts in time order: the first ``1 − holdout`` of their samples
    to fit on, the rest held out (a part at the boundary is cut in two).

    Parameters
    ----------
    parts : list of (int, int)
    holdout : float
        Fraction held out, in (0, 1).

    Returns
    -------
    fit, held : list of (int, int)
    """
    total = sum(b - a for a, b in parts)
    cut = int(round((1.0 - holdout) * total))
    fit, held, seen = [], [], 0
    for a, b in parts:
        n = b - a
        if seen + n <= cut:
            fit.append((a, b))
        elif seen >= cut:
            held.append((a, b))
        else:
            k = a + cut - seen
            fit.append((a, k))
            held.append((k, b))
        seen += n
    return [p for p in fit if p[1] > p[0]], [p for p in held if p[1] > p[0]]


def fused_terms(w, level, level_sd, corr, corr_sd=None) -> tuple[np.ndarray, np.ndarray]:
    """The variance of a noise term on each fused axis, wᵀ (C ∘ s sᵀ) w, and its 1σ.

    Parameters
    ----------
    w : ndarray (3, N)
        The estimator's gain (a static estimator's weights) [-].
    level, level_sd : ndarray (N,)
        Per-gyro level s of the term (ARW N [rad/√s] or RRW K [rad/s/√s]) and its 1σ.
    corr : ndarray (N, N)
        Correlation of the term between the gyros [-].
    corr_sd : ndarray (N, N), optional
        1σ of the correlation (0 when not given).

    Returns
    -------
    q, q_sd : ndarray (3,)
        wᵀ Σ w per axis [level²] and its 1σ from the delta method (the levels and the
        correlations taken independent).
    """
    w = np.asarray(w, float)
    s = np.asarray(level, float)
    c = np.asarray(corr, float)
    cov = c * np.outer(s, s)
    q = np.einsum("ai,ij,aj->a", w, cov, w)
    ds = 2.0 * w * ((c * s[None, :]) @ w.T).T                    # ∂q_a/∂s_k = 2 w_k Σ_j C_kj w_j s_j
    var = (ds ** 2) @ (np.nan_to_num(np.asarray(level_sd, float)) ** 2)
    if corr_sd is not None:
        iu = np.triu_indices(s.size, 1)
        dc = 2.0 * w[:, iu[0]] * w[:, iu[1]] * (s[iu[0]] * s[iu[1]])[None, :]
        var = var + (dc ** 2) @ (np.nan_to_num(np.asarray(corr_sd, float))[iu] ** 2)
    return np.maximum(q, 0.0), np.sqrt(var)


def band_basis(dt_s: float, lengths, rng: np.random.Generator, runs: int = VALIDATE_RUNS):
    """Unit white and unit walk realisations on parts of the given lengths, as octave Allan
    variances: what :func:`predicted_band` scales (one simulation serves every axis).

    Each run simulates unit white noise u (variance 1 per sample) and a unit random walk v
    (increments of variance 1) on each part, takes each part's mean out and joins them as the
    measured part is (:func:`stitch`); the Allan variance of √a·u + √b·v is then
    a·A_uu + b·A_vv + 2√(ab)·A_uv.

    Returns
    -------
    taus_s : ndarray (M,)
    a_uu, a_vv, a_uv : ndarray (M, runs)
    """
    lengths = [int(n) for n in lengths if n > 0]
    u_parts, v_parts = [], []
    for m in lengths:
        u = rng.standard_normal((m, runs))
        v = np.cumsum(rng.standard_normal((m, runs)), axis=0)
        u_parts.append(u - u.mean(axis=0))
        v_parts.append(v - v.mean(axis=0))
    u, v = np.concatenate(u_parts), np.concatenate(v_parts)
    taus, a_uu, _, _ = octave_avar(u, dt_s)
    _, a_vv, _, _ = octave_avar(v, dt_s)
    _, a_ww, _, _ = octave_avar(u + v, dt_s)
    return taus, a_uu, a_vv, 0.5 * (a_ww - a_uu - a_vv)


def predicted_band(n2, n2_sd, k2, k2_sd, dt_s: float, basis, rng: np.random.Generator,
                   level: float = VALIDATE_LEVEL):
    """The fused ADEV a white + walk prediction gives on the held-out parts, with its band.

    Each run of ``basis`` (:func:`band_basis`) draws the fused white variance n2 and walk
    variance k2 from their 1σ (normal, kept >= 0) and scales the unit realisations: white
    σ² = n2/dt per sample, walk increments of variance k2·dt.

    Parameters
    ----------
    n2, n2_sd : float
        Fused white variance N² [rad²/s] and its 1σ.
    k2, k2_sd : float
        Fused walk variance K² [rad²/s³] and its 1σ.
    dt_s : float
        Sample step [s].
    basis : tuple
        :func:`band_basis` on the held-out parts.
    rng : numpy.random.Generator
    level : float
        Two-sided level of the band.

    Returns
    -------
    taus_s, adev, low, high : ndarray (M,)
        Octave τ [s], the predicted ADEV √E[σ²(τ)] and the band [rad/s].
    """
    taus, a_uu, a_vv, a_uv = basis
    runs = a_uu.shape[1]
    a = np.maximum(n2 + n2_sd * rng.standard_normal(runs), 0.0) / dt_s
    b = np.maximum(k2 + k2_sd * rng.standard_normal(runs), 0.0) * dt_s
    avar = a * a_uu + b * a_vv + 2.0 * np.sqrt(a * b) * a_uv
    q = (1.0 - level) / 2.0
    lo, hi = np.quantile(avar, [q, 1.0 - q], axis=1)
    return taus, np.sqrt(np.maximum(avar.mean(axis=1), 0.0)), np.sqrt(np.maximum(lo, 0.0)), np.sqrt(hi)


def tau_verdict(taus, measured, low, high, predicted, *, n2: float, k2: float, use=None,
                independent: bool = False) -> dict:
    """Inside or outside the prediction's band at each τ, and which term would explain a miss.

    Parameters
    ----------
    taus, measured, low, high, predicted : ndarray (M,)
        τ [s], the measured ADEV, the prediction's band and value [any one unit].
    n2, k2 : float
        The predicted fused white and walk variances (where the walk takes over:
        τ_c = √(3 n2 / k2)).
    use : ndarray of bool (M,), optional
        The τ the prediction holds at (default all).
    independent : bool
        The prediction takes the gyros independent (no cross-covariance).

    Returns
    -------
    dict
        ``inside`` (list of bool or None), ``fraction_inside``, ``consistent``
        (fraction >= :data:`CONSISTENT_FRACTION`), ``misses`` (ranges of τ outside, each with
        its side and the term that would explain it) and ``verdict`` (one line).
    """
    taus = np.asarray(taus, float)
    meas = np.asarray(measured, float)
    use = np.ones(taus.size, bool) if use is None else np.asarray(use, bool)
    inside = (meas >= np.asarray(low)) & (meas <= np.asarray(high))
    above = meas > np.asarray(high)
    k = int(use.sum())
    frac = float(inside[use].mean()) if k else math.nan
    tau_c = math.sqrt(3.0 * n2 / k2) if k2 > 0 else math.inf
    ratio = meas / np.maximum(np.asarray(predicted, float), 1e-300)
    out: dict[str, Any] = {"inside": [bool(v) if u else None for v, u in zip(inside, use)], "fraction_inside": frac,
           "n_tau": k, "consistent": bool(k and frac >= CONSISTENT_FRACTION),
           "walk_from_tau_s": None if not math.isfinite(tau_c) else tau_c, "misses": []}
    miss = use & ~inside
    # a consistent factor: the misses one unbroken run of tau on one side, reaching tau >= SHORT_TAU_S
    # (not short tau alone: that is the noise's shape there), with a nearly constant ratio
    ev = np.flatnonzero(use)
    mi = np.flatnonzero(miss)
    run = mi.size >= 3 and np.array_equal(ev[(ev >= mi[0]) & (ev <= mi[-1])], mi)
    same_side = mi.size > 0 and (np.all(above[mi]) or not np.any(above[mi]))
    logr = np.log(ratio[mi]) if mi.size else np.zeros(0)
    factor = float(np.exp(np.median(logr))) if logr.size else math.nan
    spread = float(np.median(np.abs(logr - np.median(logr)))) if logr.size else math.inf   # robust: long tau scatter
    if run and same_side and float(taus[mi[-1]]) >= SHORT_TAU_S and spread < FACTOR_LOG_SPREAD:
        mslow = miss.copy()
        miss = np.zeros_like(miss)
        why = ("the cross-covariance between the gyros: a correlation the prediction leaves out "
               f"(it {'raises' if factor > 1 else 'lowers'} the fused noise)") if independent else \
              ("the correlation between the gyros or their white level: the fitted covariance is off by "
               "about this factor squared")
        out["misses"].append({"from_tau_s": float(taus[mslow].min()), "to_tau_s": float(taus[mslow].max()),
                              "side": "above" if factor > 1 else "below", "factor": factor,
                              "term": CORRELATION, "explanation": f"a consistent factor {factor:.3g} at every "
                              f"tau from {taus[mi[0]]:.3g} to {taus[mi[-1]]:.3g} s: {why}"})
    idx = np.flatnonzero(miss)
    groups: list[list] = []
    for i in idx.tolist():
        region = "short" if taus[i] < SHORT_TAU_S else ("walk" if taus[i] >= tau_c else "white")
        key = (region, bool(above[i]))
        if groups and groups[-1][0] == key and groups[-1][-1] == i - 1:
            groups[-1].append(i)
        else:
            groups.append([key, i])
    for g in groups:
        (region, up), ii = g[0], g[1:]
        f = float(np.exp(np.mean(np.log(ratio[ii]))))
        term, why = _miss_term(region, up, independent)
        out["misses"].append({"from_tau_s": float(taus[ii[0]]), "to_tau_s": float(taus[ii[-1]]),
                              "side": "above" if up else "below", "factor": f, "term": term,
                              "explanation": why})
    out["misses"].sort(key=lambda m: m["from_tau_s"])
    head = (f"{'consistent' if out['consistent'] else 'NOT consistent'}: inside the band at "
            f"{int(inside[use].sum())} of {k} tau ({100.0 * frac:.0f} %)") if k else "no tau to test"
    tails = [f"{'above' if m['side'] == 'above' else 'below'} at tau {m['from_tau_s']:.3g}-{m['to_tau_s']:.3g} s "
             f"(x{m['factor']:.3g}): {m['explanation']}" for m in out["misses"]]
    out["verdict"] = head + ("; " + "; ".join(tails) if tails else "")
    return out


def _miss_term(region: str, up: bool, independent: bool) -> tuple[str, str]:
    """(term, explanation) of a miss in one τ region (:func:`tau_verdict`)."""
    if region == "short":
        return ("lines/bumps", "excess at short tau: vibration lines, bumps or quantization, not white noise "
                "(the white level is read at tau >= 1 s)") if up else \
               ("filter", "less than white at short tau: the sensor's own low-pass filter or correlated "
                "samples (the white level is read at tau >= 1 s)")
    if region == "walk":
        return ("walk/bias instability", "excess at long tau: a slow term beyond the fitted random walk "
                "(bias instability, temperature, a larger RRW)") if up else \
               ("walk", "below at long tau: the random walk is over-stated (or each part's mean taken out "
                "hides it)")
    corr = "a correlation between the gyros the prediction leaves out" if independent else \
        "the fitted correlation between the gyros"
    return ("white/correlation", f"{'excess' if up else 'deficit'} where white noise dominates: the white "
            f"level, or {corr}")


def _mapped(table, key: str, used: list[int], matrix, default: np.ndarray) -> np.ndarray:
    """``matrix`` (rows and columns the table's gyros) for the used gyros (:func:`table_correlation`)."""
    if matrix is None:
        return default
    view = type("_T", (), {"gyros": tuple(table.gyros), key: np.asarray(matrix, float)})
    return table_correlation(view, key, used, default)


def validate_fuse(meas: Measurement, estimator: str, *, holdout: float | None = 0.5, exclude=(),
                  params: dict | None = None, model=None, model_name: str | None = None,
                  seed: int = 0, runs: int = VALIDATE_RUNS, off_levels: str = "record") -> tuple[FuseResult, dict]:
    """Fit the array model on part of a record, predict the fused ADEV, and check it on the rest.

    1. The analysed part (:func:`still_parts`) is split in time (:func:`split_parts`): the
       first ``1 − holdout`` to fit on, the rest held out.
    2. On the fit part: per gyro, white N and walk K (:func:`white_walk_fit`, with their 1σ),
       and the array model's white and slow correlations
       (:func:`~gyroarray.chain.array_model.array_model`); with ``model``, its noise instead
       and the whole analysed part held out.
    3. The estimator is designed with that noise and fuses the record (:func:`fuse`).
    4. Prediction per axis a, with w_a the estimator's gain to slow changes: the fused white
       variance wᵀ(C_w ∘ N Nᵀ)w and walk variance wᵀ(C_k ∘ K Kᵀ)w, once with the fitted
       correlations ("covariance") and once with the gyros taken independent
       ("independent": C = I); σ²(τ) = n2/τ + k2 τ/3 on the held-out parts' lengths, with a
       Monte-Carlo band (:func:`predicted_band`: the held-out record's own scatter and the
       fit's 1σ).
    5. The measured fused ADEV on the held-out part (with its CI) against each band, τ by τ
       (:func:`tau_verdict`). An estimator that is not static is tested at τ >= 10 of its
       time constants only.

    Parameters
    ----------
    meas : Measurement
    estimator : str
    holdout : float or None
        Fraction held out (0 < f < 1); None with ``model``.
    exclude, params, model, model_name
        As :func:`fuse`.
    seed : int
        Seed of the Monte-Carlo band.
    runs : int
        Its runs.

    Returns
    -------
    result : FuseResult
        The fusion with the fitted (or given) noise.
    validation : dict
        Everything, JSON-ready (deg/h, deg/√h).

    Raises
    ------
    InputError
        As :func:`fuse`; a holdout outside (0, 1); a fit or held-out part too short.
    """
    # deferred on purpose: chain.array_model loads chain.compare (the simulator), which plain fuse does not need
    from gyroarray.chain.array_model import array_model
    name = meas.source
    if model is None and (holdout is None or not (0.0 < holdout < 1.0)):
        raise InputError(f"--holdout must be a fraction in (0, 1), got {holdout!r}", file=name)
    used, _, _, _ = used_gyros(meas, exclude)
    check_geometry(meas, used, sorted({int(k) for k in exclude}), [k for k in constant_gyros(meas)
                                                                     if k not in set(exclude)])
    idx = [k - 1 for k in used]
    dt = float(meas.dt_s)
    parts, _ = still_parts(meas, idx)
    y = meas.gyro_rad_s[:, idx]
    h = np.asarray(meas.layout.axes)[idx]
    resid = y - meas.ref_rad_s @ h.T if meas.has_reference else y
    notes: list[str] = []
    fitted_json = None
    if model is None:
        assert holdout is not None                 # the check above raises on a None holdout
        fit_p, held_p = split_parts(parts, float(holdout))
        n_fit, n_held = sum(b - a for a, b in fit_p), sum(b - a for a, b in held_p)
        if min(n_fit, n_held) < MIN_ANALYSED:
            raise InputError(f"--holdout {holdout:g} leaves {n_fit} samples to fit on and {n_held} to validate "
                             f"on; each needs at least {MIN_ANALYSED}: record a longer still part or change "
                             "--holdout", file=name)
        ww = white_walk_fit(stitch(resid, fit_p), dt, parts=joined(fit_p))
        mask = np.zeros(meas.n_samples, bool)
        for a, b in fit_p:
            mask[a:b] = True
        eye = np.eye(len(used))
        c_w, c_k, c_w_sd, c_k_sd = eye, eye, None, None
        try:
            arr = array_model(meas, still=mask)
        except InputError as err:
            arr = None
            notes.append(f"no array model on the fit part ({err.message}): the gyros taken independent")
        if arr is not None:
            tab = arr.table()
            c_w = table_correlation(tab, "white_correlation", used, eye)
            w_est = arr.white_tau if arr.white_tau is not None and arr.correlation_basis == "tau" else arr.white
            c_w_sd = _mapped(tab, "white_correlation", used, w_est.corr_sigma, np.zeros_like(eye))
            if arr.slow is not None:
                c_k = table_correlation(tab, "walk_correlation", used, eye)
                c_k_sd = _mapped(tab, "walk_correlation", used, arr.slow.corr_sigma, np.zeros_like(eye))
            fitted_json = tab.to_dict()
            notes += [f"array model: {n}" for n in arr.notes]
        arw = ww.arw_rad_rt_s.copy()
        weak = arw <= 0
        if weak.any():
            steps = np.diff(stitch(resid, fit_p)[:, weak], axis=0)
            arw[weak] = np.maximum(np.std(steps, axis=0) / math.sqrt(2.0) * math.sqrt(dt), 1e-30)
        rrw_design, _ = design_rrw(ww)
        noise = ArrayNoise(arw, rrw_design, c_w, c_k)
        total_fit = n_fit * dt
        res = fuse(meas, estimator, exclude=exclude, params=params, noise=noise,
                   noise_source=f"fitted on the first {1.0 - holdout:g} of the analysed part ({total_fit:.1f} s): "
                                "per gyro ARW + RRW, the array model's white and slow correlations")
        lev = (arw, np.nan_to_num(ww.arw_sigma), ww.rrw_rad_s_rt_s, np.nan_to_num(ww.rrw_sigma))
    else:
        if holdout is not None:
            raise InputError("--holdout splits the record to fit a model on; with --model the whole "
                             "record is validated: leave out --holdout or --model", file=name)
        res = fuse(meas, estimator, model=model, model_name=model_name, exclude=exclude, params=params,
                   off_levels=off_levels)
        fit_p, held_p = [], list(parts)
        if sum(b - a for a, b in held_p) < MIN_ANALYSED:
            raise InputError(f"the analysed part has {sum(b - a for a, b in held_p)} samples; validating "
                             f"needs at least {MIN_ANALYSED}", file=name)
        noise = res.noise
        zero = np.zeros(len(used))
        # the prediction reads each gyro at the model's central level with its 1σ on a new record
        # (a model fitted on several records: the between-record spread), not at the high end the
        # estimator is designed with; a gyro found off is read at the record's own level
        cen, sig, _, hi = model_levels(model, meas.n_gyros)
        idx_u = [k - 1 for k in used]
        n_c = np.where(np.isfinite(cen[idx_u]), cen[idx_u], noise.arw_rad_rt_s)
        s_c = np.where(np.isfinite(cen[idx_u]), sig[idx_u], 0.0)
        table = getattr(model, "array", None)
        if table is not None and getattr(table, "white_n_low_deg_rt_h", None) is not None:
            # several records: 1σ of a new record's level, from the credible range (±q·σ in ln N)
            q = float(stats.norm.ppf(0.975))                 # as levels_across's range
            s_c = np.where(np.isfinite(cen[idx_u]), n_c * np.log(np.maximum(hi[idx_u], 1e-300)
                                                                   / np.maximum(n_c, 1e-300)) / q, s_c)
        chk = res.model_check or {"off": []}
        for k in chk["off"]:
            if off_levels == "record":
                i = used.index(k)
                n_c[i] = noise.arw_rad_rt_s[i]
                s_c[i] = float(units.arw_deg_rt_h_to_rad_rt_s(chk["gyros"][str(k)]["record_sigma_deg_rt_h"]))
        lev = (n_c, s_c, noise.rrw_rad_s_rt_s, zero)
        c_w, c_k, c_w_sd, c_k_sd = noise.corr_arw, noise.corr_rrw, None, None
    if res.gain is None:
        raise InputError(f"{estimator} is not a fixed linear filter: its fused noise cannot be predicted "
                         "from the model; validate gls, ols, svo, kf_array or kf_single", file=name)
    w = res.gain
    eye = np.eye(len(used))
    # the 1σ of a fused level is at least what the same white + walk fit of the fused fit part
    # gives: the per-gyro levels' errors are correlated as their noise is, which the delta
    # method (errors taken independent) does not see
    floor_n = floor_k = np.zeros(3)
    if fit_p:
        fw = white_walk_fit(stitch(resid, fit_p) @ w.T, dt, parts=joined(fit_p))
        sn, sk = np.nan_to_num(fw.arw_sigma), np.nan_to_num(fw.rrw_sigma)
        floor_n = 2.0 * fw.arw_rad_rt_s * sn + sn ** 2
        floor_k = np.where(fw.rrw_rad_s_rt_s > 0, 2.0 * fw.rrw_rad_s_rt_s * sk, sk ** 2)
    preds = {}
    for kind, cw, ck, cws, cks in (("independent", eye, eye, None, None), ("covariance", c_w, c_k, c_w_sd, c_k_sd)):
        n2, n2_sd = fused_terms(w, lev[0], lev[1], cw, cws)
        k2, k2_sd = fused_terms(w, lev[2], lev[3], ck, cks)
        preds[kind] = (n2, np.maximum(n2_sd, floor_n), k2, np.maximum(k2_sd, floor_k))
    e_fused = res.fused_rad_s - meas.ref_rad_s if meas.has_reference else res.fused_rad_s
    ef = stitch(e_fused, held_p)
    lengths = [b - a for a, b in held_p]
    taus, avar_m, _, _ = octave_avar(ef, dt)
    held_ww = white_walk_fit(ef, dt, parts=joined(held_p))
    single_ww = white_walk_fit(stitch(resid, held_p), dt, parts=joined(held_p))
    tc = res.time_constant_s or 0.0
    use = taus >= 10.0 * tc * (1.0 - 1e-9) if tc > 0 else np.ones(taus.size, bool)
    if tc > 0:
        notes.append(f"{estimator} is a filter (slowest time constant {tc:.3g} s): the prediction from its "
                     f"gain to slow changes is tested at tau >= {10 * tc:.3g} s only")
    rng = np.random.default_rng(seed)
    basis = band_basis(dt, lengths, rng, runs)
    dh = units.rad_s_to_deg_h
    arw_u = units.arw_rad_rt_s_to_deg_rt_h
    axes: dict = {}
    for a, ax in enumerate(AXES):
        m_adev = np.sqrt(avar_m[:, a])
        d: dict = {"taus_s": [float(t) for t in taus], "measured_adev_deg_h": [float(v) for v in dh(m_adev)]}
        try:
            with np.errstate(all="ignore"):
                an = allan_analysis(ef[:, a], dt, confidence=VALIDATE_LEVEL)
            lo = np.interp(taus, an.taus_s, an.ci_low_rad_s)
            hi = np.interp(taus, an.taus_s, an.ci_high_rad_s)
            d["measured_ci_low_deg_h"] = [float(v) for v in dh(lo)]
            d["measured_ci_high_deg_h"] = [float(v) for v in dh(hi)]
        except (InputError, np.linalg.LinAlgError, ValueError, FloatingPointError):
            d["measured_ci_low_deg_h"] = d["measured_ci_high_deg_h"] = None
        d["measured_arw_deg_rt_h"] = float(arw_u(held_ww.arw_rad_rt_s[a]))
        d["measured_arw_deg_rt_h_sigma"] = float(arw_u(held_ww.arw_sigma[a]))
        proj = np.abs(h[:, a])
        ok = (proj > 1e-9) & (single_ww.arw_rad_rt_s > 0)
        if ok.any():
            eq = np.where(ok, single_ww.arw_rad_rt_s / np.where(ok, proj, 1.0), np.inf)
            j = int(np.argmin(eq))
            d["best_single_gyro"], d["best_single_arw_deg_rt_h"] = used[j], float(arw_u(eq[j]))
        else:
            d["best_single_gyro"] = d["best_single_arw_deg_rt_h"] = None
        d["predicted"] = {}
        for kind, (n2, n2_sd, k2, k2_sd) in preds.items():
            pt, padev, plo, phi = predicted_band(float(n2[a]), float(n2_sd[a]), float(k2[a]), float(k2_sd[a]),
                                                 dt, basis, rng)
            assert pt.size == taus.size
            v = tau_verdict(taus, m_adev, plo, phi, padev, n2=float(n2[a]), k2=float(k2[a]), use=use,
                            independent=kind == "independent")
            off_here = [k for k in (res.model_check or {}).get("off", []) if abs(h[used.index(k), a]) > 1e-9]
            if off_here:
                v["verdict"] += (f"; the model's white level does not hold on this record for gyro(s) "
                                 f"{', '.join(map(str, off_here))} ({_off_text(res.model_check or {})} deg/√h)")
                v["off_gyros"] = off_here
            d["predicted"][kind] = {
                "arw_deg_rt_h": float(arw_u(math.sqrt(n2[a]))),
                "arw_deg_rt_h_sigma": float(arw_u(n2_sd[a] / (2.0 * math.sqrt(n2[a])))) if n2[a] > 0 else None,
                "rrw_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(math.sqrt(k2[a]))),
                "adev_deg_h": [float(x) for x in dh(padev)], "band_low_deg_h": [float(x) for x in dh(plo)],
                "band_high_deg_h": [float(x) for x in dh(phi)], **v}
        axes[ax] = d
    t0 = float(meas.time_s[0])
    span = [[float(meas.time_s[a] - t0), float(meas.time_s[b - 1] - t0 + dt)] for a, b in held_p]
    val = {"estimator": estimator, "holdout": holdout, "level": VALIDATE_LEVEL, "runs": runs, "seed": seed,
           "static": tc == 0, "gyros_used": list(used),
           "fit_parts_s": [[float(meas.time_s[a] - t0), float(meas.time_s[b - 1] - t0 + dt)] for a, b in fit_p],
           "held_parts_s": span, "fit_s": sum(b - a for a, b in fit_p) * dt,
           "held_s": sum(lengths) * dt, "model": res.model_source,
           "fitted_array": fitted_json, "axes": axes, "notes": notes, "model_check": res.model_check,
           "method": ("prediction: per axis, n2 = w'(C_w o N N')w and k2 = w'(C_k o K K')w with w the "
                      "estimator's gain; white n2 + walk k2 simulated on the held-out parts "
                      f"({runs} runs, each part's mean out, the fit's 1-sigma drawn): the band is its "
                      f"{100 * VALIDATE_LEVEL:g} % range; 'independent' takes the gyros uncorrelated, "
                      "'covariance' uses the fitted correlations; inside = the measured ADEV in the band")}
    return res, val


# =========================================================================
# The fused record
# =========================================================================
#: The fused record's layout: gyro1, gyro2, gyro3 along the platform x, y, z.
FUSED_AXES = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def fused_measurement(res: FuseResult) -> Measurement:
    """The fused record as a 3-gyro measurement along the platform axes [deg/s].

    ``gyro1..3`` are the fused rate about x, y, z; time, reference, temperature, specific
    force and site are the input's.
    """
    m = res.measurement
    return Measurement(time_s=m.time_s, gyro_deg_s=units.rad_s_to_deg_s(res.fused_rad_s),
                       layout=Layout.from_axes(np.array(FUSED_AXES)), sample_rate_hz=m.sample_rate_hz,
                       ref_deg_s=m.ref_deg_s, temp_c=m.temp_c, site=m.site,
                       description=_description(res), acc_m_s2=m.acc_m_s2)


def _description(res: FuseResult) -> str:
    src = res.measurement.source or "a measurement"
    return (f"fused body rate of {src} by gyroarray fuse (estimator {res.estimator}, "
            f"{len(res.used)} gyros): gyro1, gyro2, gyro3 are the rate about the platform x, y, z axes")


def sha256_of(path) -> str | None:
    """SHA-256 of a file's bytes (hex), or None when it cannot be read or is no regular file
    (a FIFO, a device, a link to /dev/zero: never opened blocking, never read without end)."""
    h = hashlib.sha256()
    try:
        with open_regular(path) as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except (OSError, InputError):
        return None
    return h.hexdigest()


def _toml_params(params: dict) -> dict:
    """Hyperparameters TOML can hold (None means 'the default' and is left out)."""
    return {k: v for k, v in params.items() if isinstance(v, (bool, int, float, str))}


def _degrees(rad: float) -> float:
    """The shortest decimal degrees that convert back to ``rad`` exactly (15.1881, not
    15.188099999999999), else the plain conversion."""
    d0 = float(units.rad_to_deg(rad))
    near = [d0]
    for direction in (math.inf, -math.inf):
        d = d0
        for _ in range(4):
            d = math.nextafter(d, direction)
            near.append(d)
    exact = [d for d in near if units.deg_to_rad(d) == rad]
    return min(exact, key=lambda d: len(repr(d))) if exact else d0


def fused_files(res: FuseResult, gz: bool, *, input_sha256: str | None = None,
                sidecar_sha256: str | None = None) -> tuple[bytes, bytes]:
    """The fused record's CSV (gzip when ``gz``) and sidecar bytes, in the measurement format.

    The CSV has ``time_s``, ``gyro1..3`` [deg/s] and the input's ``ref_*``, ``temp_c`` and
    ``acc_*`` when present, each value the shortest decimal that reads back as the same
    double. The sidecar has ``sample_rate_hz``, ``description``, ``[layout]`` (unit axes
    x, y, z), the input's ``[site]`` and a ``[fused]`` table: estimator and its
    hyperparameters, model source, gyros used, excluded and constant, the design noise per
    used gyro, the input file and its SHA-256, and the gyroarray version.
    """
    fm = fused_measurement(res)
    m = res.measurement
    names = ["time_s", "gyro1", "gyro2", "gyro3"]
    blocks = [fm.time_s[:, None], fm.gyro_deg_s]
    if m.ref_deg_s is not None:
        names += ["ref_x", "ref_y", "ref_z"]
        blocks.append(m.ref_deg_s)
    if m.temp_c is not None:
        names.append("temp_c")
        blocks.append(m.temp_c[:, None])
    if m.acc_m_s2 is not None:
        names += ["acc_x", "acc_y", "acc_z"]
        blocks.append(m.acc_m_s2)
    table = np.hstack(blocks)
    row = ",".join(["%r"] * table.shape[1])          # %r of a float: the shortest round trip
    lines = [f"# written by gyroarray {__version__} (gyroarray fuse, estimator {res.estimator}): "
             "gyro1..3 = fused body rate about x, y, z [deg/s]", ",".join(names)]
    lines.extend(map(row.__mod__, map(tuple, table.tolist())))
    csv = ("\n".join(lines) + "\n").encode("utf-8")
    if gz:
        csv = gzip.compress(csv, compresslevel=6, mtime=0)
    toml = fused_sidecar(res.estimator, res.params, res.model_source, res.used, res.excluded,
                         res.constant, res.noise, str(m.source), m.sample_rate_hz, fm.description,
                         m.site, input_sha256=input_sha256, sidecar_sha256=sidecar_sha256)
    return csv, toml


def fused_sidecar(estimator: str, params: dict, model_source: str, used, excluded, constant,
                  noise: ArrayNoise, source: str, sample_rate_hz: float, description: str, site,
                  *, input_sha256: str | None = None, sidecar_sha256: str | None = None) -> bytes:
    """The fused record's sidecar (TOML bytes): see :func:`fused_files`."""
    arw = units.arw_rad_rt_s_to_deg_rt_h(noise.arw_rad_rt_s)
    rrw = units.rrw_rad_s_rt_s_to_deg_h_rt_h(noise.rrw_rad_s_rt_s)
    fused = {"estimator": estimator, "estimator_params": _toml_params(params),
             "model": model_source, "gyros_used": list(used),
             "excluded_gyros": list(excluded), "constant_gyros": list(constant),
             "design_arw_deg_rt_h": [float(v) for v in arw],
             "design_rrw_deg_h_rt_h": [float(v) for v in rrw],
             "input": source, "gyroarray_version": __version__,
             "columns": "gyro1, gyro2, gyro3: fused body rate about the platform x, y, z axes [deg/s]"}
    if input_sha256 is not None:
        fused["input_sha256"] = input_sha256
    if sidecar_sha256 is not None:
        fused["input_sidecar_sha256"] = sidecar_sha256
    doc: dict = {"sample_rate_hz": sample_rate_hz, "description": description,
                 "layout": {"axes": [list(r) for r in FUSED_AXES]}}
    if site is not None:
        doc["site"] = {"latitude_deg": _degrees(site.latitude_rad),
                       "heading_deg": _degrees(site.heading_rad)}
    doc["fused"] = fused
    return tomli_w.dumps(doc).encode("utf-8")
