"""Which array to build: the design search behind ``gyroarray design --recommend``.

For gyros that are alike (one datasheet, or the typical gyro of a fitted
model), the search runs scheme × N × cone angle α × estimator × bandwidth
through the analytic predictor (:mod:`gyroarray.design.predict`) and ranks the
designs by the predicted RMS of the rate error about the truth over the
horizon (root-sum-square over the body axes, random-walk drift included).

The fast path. On a conical layout with identical, equicorrelated gyros the
problem falls apart into one scalar channel per body axis:

* a per-sample estimator (``gls``, ``ols``, ``naive``) with weights m_a gives
  y_a = ω_a + m_aᵀ(b + v): white variance m_aᵀRm_a, random-walk variance
  m_aᵀQ_bm_a, flicker Σ m_ai² B², whatever the layout; the low-pass acts on y_a;
* ``kf_single`` is the same single-gyro filter on every gyro, so it commutes
  with the OLS combination: the filter acts on the OLS channel;
* ``kf_array`` decouples when HᵀR⁻¹H is diagonal and every whitened axis is
  an eigenvector of the whitened bias covariance (every conical layout when
  the ARW and RRW correlations are equal; Scheme 1 always): it is the
  single-input KF on the GLS channel, designed for that channel's noise.

A channel filter's unit responses (:func:`gyroarray.design.predict.channel_response`)
are computed once per bandwidth, so every α and N is a weighted sum of them.
The gyros' own low-pass (``DesignSpace.sensor_bandwidth``, the spec's
``bandwidth`` on every gyro) commutes with every per-sample combination of
alike gyros, so it is cascaded in front of each channel filter
(:func:`gyroarray.design.predict.cascade`): the noise and the motion pass it, and the
swing response splits into the estimator's and the sensor's factors
(:func:`tracking_limit` says which one limits tracking). A g-sensitivity
(``DesignSpace.g_sensitivity_deg_s_per_g``) is reported beside the noise:
per gyro k · f, fused through the design's DC gain.

The decision (:func:`decide`) treats what the user does not know as
conditions: every design is scored by its worst case over the ρ range (found
continuously) × every set of k failed gyros, with the estimator built once for
a design ρ (weights fixed; after a failure recomputed for the same design ρ on
the gyros left); the mounting sense of each gyro is searched
(:mod:`gyroarray.design.robust`), the objective is the rate or the angle error,
and designs tying within 1 % are ranked by their typical case. The fast channel
model screens; the first :data:`EXACT_TOP` designs, the recommendation, the
runner-up and the mounting mirror are then re-scored exactly
(:func:`rescore_exact`: the registry's estimator built for the design ρ on the
gyros left, :func:`gyroarray.design.predict.predict` at both ends of the ρ
range, the error of a fixed estimator being linear in ρ) and re-ranked.

The tests check the fast path against the full predictor. Where
``kf_array`` does not decouple (Scheme 2 with unequal ARW and RRW
correlation) it is predicted exactly by the full predictor at the cone angle
and bandwidth found for ``kf_single``, and the assumptions say so.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from types import ModuleType
from typing import Any, Callable, cast

import numpy as np
from scipy.optimize import minimize_scalar

from gyroarray.analysis.replicates import mean_ci, replicate_rng, rms_ci
from gyroarray.core import units
from gyroarray.core.constants import G0_M_S2
from gyroarray.core.gdop import gdop_batch, correlation_matrix, fault_tolerance, worst_gdop_over_rho
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout, conical_axes
from gyroarray.design.predict import (AXES, MODELLED, SensorBandwidth, Swing, cascade, channel_filter,
                                      channel_response, g_sensitivity_error, noise_sources, predict,
                                      predict_system, settle_start, swing_truth)
from gyroarray.core.sensor import bandwidth_sos
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.terms import (CorrelationTerm, FlickerTerm, GaussMarkovTerm, WalkTerm, WhiteTerm,
                                     root_sum_square)
from gyroarray.design.robust import (fixed_weights, kept_sets, mirror_pattern, mounted_axes,
                                     mounting_patterns, mounting_words, worst_over_interval)
from gyroarray.effects.names import ARW, BANDWIDTH, BIAS_INSTABILITY, CONSTANT_BIAS, CORRELATION, GAUSS_MARKOV, G_SENSITIVITY, MISALIGNMENT, QUANTIZATION, RRW, SCALE_FACTOR, SCALE_NONLINEARITY, TEMPERATURE_BIAS
from gyroarray.estimators import available, get_estimator
from gyroarray.estimators.fdi import minimum_detectable
from gyroarray.estimators.noise import model_terms, per_gyro
from gyroarray.sim.effects import simulate_readings

__all__ = ["GyroNoise", "DesignSpace", "recommend", "design_label", "ESTIMATORS", "DEFAULT_BANDWIDTH_HZ"]

#: The estimators the search compares (the registry's linear ones).
ESTIMATORS = ("kf_array", "kf_single", "gls", "ols", "naive")
#: The bandwidth a filter is held at when no motion is given to trade it against [Hz].
DEFAULT_BANDWIDTH_HZ = 10.0

#: Lowest ARW of a gyro the design takes [deg/√h]: below it the white variance per sample
#: underflows (cli.design.MIN_ARW_DEG_RT_H, the --arw floor, is the same).
MIN_ARW_DEG_RT_H = 1e-9
#: Cone angles per scheme on the search grid.
ALPHA_POINTS = 100
#: Bandwidths per decade on the search grid.
BW_PER_DECADE = 8
#: Designs whose objectives differ by less than this share are reported as equivalent.
EQUIVALENT_SHARE = 0.01


@dataclass(frozen=True)
class GyroNoise:
    """The noise of one gyro of the array (every gyro alike), datasheet units.

    Attributes
    ----------
    arw_deg_rt_h : float
        Angle random walk N [deg/√h] (> 0).
    rrw_deg_h_rt_h : float
        Rate random walk K [deg/h/√h].
    bi_deg_h : float
        Bias instability B [deg/h].
    gm_sigma_deg_h, gm_tau_s : float
        First-order Gauss–Markov σ [deg/h] and τc [s] (σ = 0: none).
    rho_arw, rho_rrw : float
        Common correlation of the gyros' ARW and of their RRW increments [-].
    sources : dict
        Where each value came from ("user", "default", "model FILE").
    ignored : tuple of str
        Effects of a source model that the predictor does not model.
    open_from : int or None
        A per-gyro model that is valid for any N >= this many gyros (an all-gyros entry plus
        per-gyro entries, docs/model-format.md: the gyros it does not name take the all-gyros
        entries); ``per_gyro`` then holds its first gyros until :meth:`sized` lengthens it.
        None: alike gyros, or a per-gyro model whose gyro count fixes N.
    """

    arw_deg_rt_h: float
    rrw_deg_h_rt_h: float = 0.0
    bi_deg_h: float = 0.0
    gm_sigma_deg_h: float = 0.0
    gm_tau_s: float = 0.0
    rho_arw: float = 0.0
    rho_rrw: float = 0.0
    sources: dict = field(default_factory=dict)
    ignored: tuple[str, ...] = ()
    per_gyro: dict | None = field(default=None, compare=False)
    corr_arw: np.ndarray | None = field(default=None, compare=False, repr=False)
    corr_rrw: np.ndarray | None = field(default=None, compare=False, repr=False)
    model: Any = field(default=None, compare=False, repr=False)
    open_from: int | None = field(default=None, compare=False)

    @property
    def n_gyros(self) -> int | None:
        """The gyro count a per-gyro model fixes (None: alike gyros, or an open per-gyro model
        (:attr:`open_from`): any N)."""
        return None if self.per_gyro is None or self.open_from is not None else self.n_levels

    @property
    def n_levels(self) -> int | None:
        """How many gyros' own levels ``per_gyro`` holds (None: alike gyros)."""
        return None if self.per_gyro is None else int(len(self.per_gyro[ARW]))

    def sized(self, n_gyros: int) -> "GyroNoise":
        """An open per-gyro model (:attr:`open_from`) with the levels of gyros 1..``n_gyros``
        (at least): the named gyros their own, every other gyro the all-gyros entries'. The
        correlation state (a ρ set by :meth:`with_rho`, or the model's) is kept. Anything else:
        itself.

        Raises
        ------
        InputError
            ``n_gyros`` below :attr:`open_from`: the model names a gyro the array lacks.
        """
        if self.open_from is None or cast(int, self.n_levels) >= n_gyros:
            return self
        if n_gyros < self.open_from:
            raise model_gyro_refusal(self.model, n_gyros)
        base = replace(self, per_gyro=None, corr_arw=None, corr_rrw=None, open_from=None)
        full = per_gyro_noise(self.model, base, self.sources.get("per_gyro", "model"), n_gyros=n_gyros)
        return replace(full, rho_arw=self.rho_arw, rho_rrw=self.rho_rrw, sources=self.sources,
                       corr_arw=None if self.corr_arw is None else full.corr_arw,
                       corr_rrw=None if self.corr_rrw is None else full.corr_rrw,
                       open_from=self.open_from)

    def __post_init__(self):
        if not (math.isfinite(self.arw_deg_rt_h) and MIN_ARW_DEG_RT_H <= self.arw_deg_rt_h):
            raise InputError(f"the gyros need an angle random walk of at least {MIN_ARW_DEG_RT_H:g} "
                             f"deg/√h (below it the white variance per sample underflows), got "
                             f"{self.arw_deg_rt_h!r}")
        for k in ("rrw_deg_h_rt_h", "bi_deg_h", "gm_sigma_deg_h", "gm_tau_s"):
            v = getattr(self, k)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"{k} must be finite and >= 0, got {v!r}")
        for k in ("rho_arw", "rho_rrw"):
            v = getattr(self, k)
            if not (math.isfinite(v) and -1.0 < v < 1.0):
                raise InputError(f"{k} must be in (-1, 1), got {v!r}")

    @classmethod
    def from_model(cls, model, source: str = "model", *, alike: bool = True) -> "GyroNoise":
        """The gyros of a noise model.

        ``alike`` (the default, ``design --alike``): the typical gyro, each effect's quadratic
        mean over its gyros, a correlation matrix reduced to the mean of its off-diagonal
        entries. Otherwise, when the model names gyros (per-gyro entries, as ``fit --out``
        writes, or an ``[array]`` table), every gyro keeps its own parameters
        (:func:`per_gyro_noise`); the scalar fields still hold the quadratic means.
        """
        typical = cls._typical(model, source)
        if alike:
            return typical
        return per_gyro_noise(model, typical, source)

    @classmethod
    def _typical(cls, model, source: str) -> "GyroNoise":
        n = max([e.gyro or 1 for e in model.entries] + [1])

        def qmean(effect, key):
            v = per_gyro(model, effect, key, n)
            v = v[np.isfinite(v)]
            return float(np.sqrt(np.mean(v ** 2))) if v.size else 0.0
        arw = units.arw_rad_rt_s_to_deg_rt_h(qmean(ARW, "n_rad_rt_s"))
        if arw <= 0:
            raise InputError(f"the model has no angle random walk ({ARW!r}): the estimators need "
                             "the white-noise level of the gyros", file=source)
        rho: dict[str, Any] = {"rho_arw": 0.0, "rho_rrw": 0.0}
        for e in model.entries:
            if e.effect == CORRELATION:
                for k in rho:
                    r = np.asarray(e.si_params[k], dtype=float)
                    rho[k] = float(r) if r.ndim == 0 else float(
                        (r.sum() - np.trace(r)) / (r.size - r.shape[0]))
        tau = per_gyro(model, GAUSS_MARKOV, "tau_s", n)
        tau = tau[np.isfinite(tau)]
        src = {k: source for k in (ARW, RRW, "bi", GAUSS_MARKOV, "rho_arw", "rho_rrw")}
        # the sensor's own effects come in through DesignSpace
        modelled = tuple(m for m in MODELLED if m not in (BANDWIDTH, G_SENSITIVITY))
        return cls(arw_deg_rt_h=arw,
                   rrw_deg_h_rt_h=units.rrw_rad_s_rt_s_to_deg_h_rt_h(qmean(RRW, "k_rad_s_rt_s")),
                   bi_deg_h=units.rad_s_to_deg_h(qmean(BIAS_INSTABILITY, "b_rad_s")),
                   gm_sigma_deg_h=units.rad_s_to_deg_h(qmean(GAUSS_MARKOV, "sigma_rad_s")),
                   gm_tau_s=float(np.mean(tau)) if tau.size else 0.0, sources=src,
                   ignored=tuple(sorted({e.effect for e in model.entries} - set(modelled))), **rho)

    def with_rho(self, rho: float) -> "GyroNoise":
        """The same gyros with a common correlation ρ of ARW and RRW (the condition varied;
        a model's correlation matrices give way to it, the per-gyro levels stay)."""
        return replace(self, rho_arw=float(rho), rho_rrw=float(rho), corr_arw=None, corr_rrw=None)

    def noise_model(self, n_gyros: int, keep=None):
        """This noise on every gyro of an N-gyro array, as a NoiseModel (for the simulator).

        Per-gyro noise: gyro k of the model on gyro k of the array; ``keep`` (0-based indices
        of the model's gyros, len ``n_gyros``): the gyros left after a failure, renumbered."""
        if self.per_gyro is not None:
            return self._per_gyro_model(n_gyros, keep)
        entries = [ModelEntry(ARW, None, {"n_deg_rt_h": self.arw_deg_rt_h})]
        if self.rrw_deg_h_rt_h > 0:
            entries.append(ModelEntry(RRW, None, {"k_deg_h_rt_h": self.rrw_deg_h_rt_h}))
        if self.bi_deg_h > 0:
            entries.append(ModelEntry(BIAS_INSTABILITY, None, {"b_deg_h": self.bi_deg_h}))
        if self.gm_sigma_deg_h > 0 and self.gm_tau_s > 0:
            entries.append(ModelEntry(GAUSS_MARKOV, None, {"sigma_deg_h": self.gm_sigma_deg_h,
                                                             "tau_s": self.gm_tau_s}))
        if self.rho_arw or self.rho_rrw:
            entries.append(ModelEntry(CORRELATION, None, {"rho_arw": self.rho_arw,
                                                            "rho_rrw": self.rho_rrw}))
        model = NoiseModel(tuple(entries), description="typical gyro of the design search")
        model.check(n_gyros)
        return model

    def _per_gyro_model(self, n_gyros: int, keep):
        idx = list(range(n_gyros)) if keep is None else [int(k) for k in keep]
        if len(idx) != n_gyros or max(idx) >= cast(int, self.n_levels):      # set with per_gyro
            raise ValueError(f"keep {idx} does not give {n_gyros} of the model's {self.n_levels} gyros")
        p = cast(dict, self.per_gyro)                   # called only when per_gyro is set
        entries = []
        for j, i in enumerate(idx):
            entries.append(ModelEntry(ARW, j + 1, {"n_deg_rt_h": float(p[ARW][i])}))
            if p[RRW][i] > 0:
                entries.append(ModelEntry(RRW, j + 1, {"k_deg_h_rt_h": float(p[RRW][i])}))
            if p["bi"][i] > 0:
                entries.append(ModelEntry(BIAS_INSTABILITY, j + 1, {"b_deg_h": float(p["bi"][i])}))
            if p["gm_sigma"][i] > 0 and p["gm_tau"][i] > 0:
                entries.append(ModelEntry(GAUSS_MARKOV, j + 1, {"sigma_deg_h": float(p["gm_sigma"][i]),
                                                                  "tau_s": float(p["gm_tau"][i])}))
        corr: dict[str, Any] = {}
        for key, mat, rho in (("rho_arw", self.corr_arw, self.rho_arw), ("rho_rrw", self.corr_rrw, self.rho_rrw)):
            if mat is not None:
                sub = np.asarray(mat, dtype=float)[np.ix_(idx, idx)]
                if np.any(sub != np.eye(len(idx))):
                    corr[key] = [[float(v) for v in row] for row in sub]
            elif rho:
                corr[key] = float(rho)
        if corr:
            entries.append(ModelEntry(CORRELATION, None, corr))
        model = NoiseModel(tuple(entries), description="the model's gyros, each its own noise")
        model.check(n_gyros)
        return model

    def to_json_dict(self) -> dict:
        out: dict[str, Any] = {"arw_deg_rt_h": self.arw_deg_rt_h, "rrw_deg_h_rt_h": self.rrw_deg_h_rt_h,
               "bi_deg_h": self.bi_deg_h, "gm_sigma_deg_h": self.gm_sigma_deg_h,
               "gm_tau_s": self.gm_tau_s, "rho_arw": self.rho_arw, "rho_rrw": self.rho_rrw}
        if self.per_gyro is not None:
            out["per_gyro"] = {k: [float(x) for x in v] for k, v in self.per_gyro.items()}
        return out


#: The per-gyro levels of :class:`GyroNoise` (datasheet units): ARW [deg/√h], RRW [deg/h/√h],
#: bias instability [deg/h], Gauss–Markov σ [deg/h] and τc [s].
PER_GYRO_KEYS = (ARW, RRW, "bi", "gm_sigma", "gm_tau")


def model_gyro_count(model) -> int:
    """The gyro count a model names: its highest per-gyro entry or ``[array]`` gyro (0: none)."""
    n = max([e.gyro or 0 for e in model.entries] + [0])
    table = getattr(model, "array", None)
    if table is not None and getattr(table, "gyros", None):
        n = max(n, max(table.gyros))
    return int(n)


def model_open_from(model) -> int | None:
    """The least N of a model valid for any N >= it (None: not such a model).

    docs/model-format.md: "a heterogeneous array is one all-gyros entry plus one entry for each
    gyro that differs". Such a model (an all-gyros ``arw`` entry, per-gyro entries naming gyros
    up to k, no ``[array]`` table, no N×N matrix) describes any array of N >= k gyros: gyro j
    > k takes the all-gyros entries. Its N is then the design's choice, not the model's.
    """
    n = max([e.gyro or 0 for e in model.entries] + [0])
    if n == 0 or getattr(model, "array", None) is not None:
        return None
    if not any(e.effect == ARW and e.gyro is None for e in model.entries):
        return None                     # the gyros it does not name would have no white level
    try:
        model.check(n + 1)              # a matrix-valued parameter fixes N: not open
    except InputError:
        return None
    return int(n)


def model_gyro_refusal(model, n_gyros: int) -> InputError:
    """The one-line refusal of an N below the highest gyro an open model names (its file and
    the entry's line)."""
    idx, top = max(((i, e.gyro) for i, e in enumerate(model.entries) if e.gyro is not None),
                   key=lambda t: t[1])
    return model.located(idx, InputError(
        f"{model.entries[idx].label}: N = {n_gyros} is refused: the model names gyro {top}, which an "
        f"array of {n_gyros} gyros lacks; give N >= {top} (--n), or --alike to reduce the model to "
        "one typical gyro", column="gyro"))


def _table_matrix(table, key: str, n: int, default: np.ndarray | None) -> np.ndarray | None:
    """An ``[array]`` correlation for gyros 1..n: its rows and columns of the gyros it names,
    0 between a named and an unnamed gyro, ``default`` (or the identity) between unnamed ones."""
    mat = getattr(table, key, None) if table is not None else None
    if mat is None:
        return default
    gyros = [int(g) - 1 for g in table.gyros]
    out = np.eye(n) if default is None else np.array(default, dtype=float, copy=True)
    out[gyros, :] = 0.0
    out[:, gyros] = 0.0
    out[np.ix_(gyros, gyros)] = np.asarray(mat, dtype=float)
    return out


def per_gyro_noise(model, typical: GyroNoise, source: str = "model", *,
                   n_gyros: int | None = None) -> GyroNoise:
    """The gyros of a model each with its own parameters (the model's gyro count fixes N, or,
    for a model valid for any N >= k (:func:`model_open_from`), ``open_from`` = k).

    The levels come from the terms the model's effects declare
    (:func:`gyroarray.estimators.noise.model_terms`): white, walk, flicker and Gauss–Markov
    per gyro; the correlation matrices from its correlation term, overridden by the
    ``[array]`` table's ``white_correlation`` / ``walk_correlation`` for the gyros it names.
    A model that names fewer than 3 gyros (no array, not open) gives ``typical`` back (alike
    gyros). ``n_gyros``: the levels of that many gyros (an open model only, :meth:`GyroNoise.sized`).
    """
    open_from = model_open_from(model)
    n = model_gyro_count(model)
    if n_gyros is not None:
        n = int(n_gyros)
    elif open_from is not None:
        n = max(n, 3)             # the named gyros (3 at least, a 3-axis rate) until sized
    elif n < 3:                   # names no array (0) or fewer gyros than a 3-axis rate needs
        return typical
    try:
        model.check(n)
        terms = model_terms(model, n)
    except InputError as err:
        raise err.with_file(source) from None
    of = {}
    for kind in (WhiteTerm, WalkTerm, FlickerTerm):
        attr = {WhiteTerm: "n_rad_rt_s", WalkTerm: "k_rad_s_rt_s", FlickerTerm: "b_rad_s"}[kind]
        vals = [np.asarray(getattr(t, attr), dtype=float) for _, t in terms if isinstance(t, kind)]
        of[kind] = np.nan_to_num(root_sum_square(vals), nan=0.0) if vals else np.zeros(n)
    arw = units.arw_rad_rt_s_to_deg_rt_h(of[WhiteTerm])
    if np.any(~(arw > 0)):
        bad = [k + 1 for k in np.flatnonzero(~(arw > 0))]
        raise InputError(f"the model gives no angle random walk for gyro(s) {', '.join(map(str, bad))}: "
                         "the estimators need every gyro's white-noise level (or use --alike)", file=source)
    gm_s, gm_t = np.zeros(n), np.zeros(n)
    for _, t in terms:
        if isinstance(t, GaussMarkovTerm):
            s_, t_ = np.nan_to_num(np.asarray(t.sigma_rad_s, float)), np.nan_to_num(np.asarray(t.tau_s, float))
            gm_s, gm_t = np.where(s_ > 0, s_, gm_s), np.where(s_ > 0, t_, gm_t)
    corr = next((t for _, t in terms if isinstance(t, CorrelationTerm)), None)
    c_w = None if corr is None or corr.white is None else np.asarray(corr.white, dtype=float)
    c_q = None if corr is None or corr.walk is None else np.asarray(corr.walk, dtype=float)
    table = getattr(model, "array", None)
    c_w = _table_matrix(table, "white_correlation", n, c_w)
    c_q = _table_matrix(table, "walk_correlation", n, c_q)
    per = {ARW: arw, RRW: units.rrw_rad_s_rt_s_to_deg_h_rt_h(of[WalkTerm]),
           "bi": units.rad_s_to_deg_h(of[FlickerTerm]), "gm_sigma": units.rad_s_to_deg_h(gm_s),
           "gm_tau": gm_t}
    per = {k: np.asarray(v, dtype=float) for k, v in per.items()}

    def off_mean(c, fallback):
        return fallback if c is None else float((c.sum() - np.trace(c)) / (c.size - n))
    return replace(typical, per_gyro=per, corr_arw=c_w, corr_rrw=c_q, model=model,
                   rho_arw=off_mean(c_w, typical.rho_arw), rho_rrw=off_mean(c_q, typical.rho_rrw),
                   sources={**typical.sources, "per_gyro": source}, open_from=open_from)


def sized_for(g: GyroNoise, space: "DesignSpace", notes: list | None = None
              ) -> tuple[GyroNoise, "DesignSpace"]:
    """``g`` with the levels of the space's largest N (an open per-gyro model,
    :attr:`GyroNoise.open_from`; anything else as it is) and the space.

    An N below the highest gyro the model names is refused (:func:`model_gyro_refusal`), unless
    the N list is the default one and ``notes`` is given: then it is left out, with a note.
    """
    if g.open_from is None:
        return g, space
    short = [n for n in space.ns if n < g.open_from]
    if short:
        srcs = space.__dict__.get("_sources", {})
        keep = tuple(n for n in space.ns if n >= g.open_from)
        if notes is None or srcs.get("ns") != "default" or not keep:
            raise model_gyro_refusal(g.model, short[0])
        notes.append(f"N = {', '.join(map(str, short))}: the model names gyro {g.open_from}; left out")
        space = replace(space, ns=keep)
        object.__setattr__(space, "_sources", srcs)
    return g.sized(max(space.ns)), space


def _levels(g: GyroNoise, n: int, keep, dt: float):
    """Per gyro (the kept ones): white variance per sample [rad²/s²], walk increment variance
    per sample [rad²/s²], flicker B² [rad²/s²], Gauss–Markov σ² [rad²/s²]."""
    p = cast(dict, g.per_gyro)                          # per-gyro noise only
    idx = list(range(n)) if keep is None else list(keep)
    return (units.arw_deg_rt_h_to_rad_rt_s(p[ARW][idx]) ** 2 / dt,
            units.rrw_deg_h_rt_h_to_rad_s_rt_s(p[RRW][idx]) ** 2 * dt,
            units.deg_h_to_rad_s(p["bi"][idx]) ** 2, units.deg_h_to_rad_s(p["gm_sigma"][idx]) ** 2)


def _corr_of(g: GyroNoise, n: int, keep, which: str) -> np.ndarray:
    """The correlation of the kept gyros: the model's matrix when it has one, else equicorrelated."""
    mat = g.corr_arw if which == ARW else g.corr_rrw
    if mat is None:
        return _corr(n, g.rho_arw if which == ARW else g.rho_rrw)
    idx = list(range(n)) if keep is None else list(keep)
    return np.asarray(mat, dtype=float)[np.ix_(idx, idx)]


def _cov(g: GyroNoise, n: int, keep, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample white covariance R and walk increment covariance Q of the kept gyros [rad²/s²]."""
    s2, q, _, _ = _levels(g, n, keep, dt)
    s, qs = np.sqrt(s2), np.sqrt(q)
    return np.outer(s, s) * _corr_of(g, n, keep, ARW), np.outer(qs, qs) * _corr_of(g, n, keep, RRW)


@dataclass(frozen=True)
class DesignSpace:
    """What the search varies and under which conditions (every default recorded).

    Attributes
    ----------
    rate_hz : float
        Sample rate [Hz].
    horizon_s : float
        Run length T the accuracy refers to [s].
    ns : tuple of int
        Numbers of gyros N.
    schemes : tuple of int
    estimators : tuple of str
    failures : int
        Gyros that may fail while a 3-axis rate must remain.
    bandwidth_hz : tuple of float
        (lo, hi) range searched [Hz]; lo == hi: fixed.
    swing : Swing or None
        A swing about each body axis.
    motion : ndarray (n, 3) or None
        A commanded body rate instead of a swing [rad/s].
    motion_name : str
    settle_s : float
        Start-up excluded from the window metrics [s].
    alpha_points : int
    sensor_bandwidth : (float, int) or None
        The gyros' own low-pass, (cut-off [Hz], order 1 or 2), as the spec's
        ``bandwidth`` effect on every gyro: cascaded before every estimator.
    g_sensitivity_deg_s_per_g : (float, float, float) or None
        Every gyro's g-sensitivity, platform frame [(deg/s)/g] (the spec's
        ``g_sensitivity`` on every gyro); its rate error is reported beside
        the noise terms, not ranked.
    specific_force_m_s2 : ndarray (n, 3) or None
        The specific force at the platform origin over the run (a motion
        profile's truth) [m/s²]; None: the level table at rest, [0, 0, g0].
    objective : {"rate", "angle"} or None
        What the designs are ranked on: the 3-axis RMS of the rate error about
        the truth, or the angle error at the horizon; None: ``angle`` when the
        user gave the horizon, else ``rate``.
    design_rho : float or None
        The ρ the estimator's weights are built for [-]; None: chosen min-max
        over the ρ range.
    far_per_h, p_md : float
        False-alarm rate [1/h] and missed-detection probability [-] of the
        minimum detectable bias (with failures >= 1).
    mdb_max : float or None
        Largest minimum detectable bias a design may have [deg/s] (None: no limit).
    """

    rate_hz: float = 100.0
    horizon_s: float = 600.0
    ns: tuple[int, ...] = (4, 5, 6, 8)
    schemes: tuple[int, ...] = (1, 2)
    estimators: tuple[str, ...] = ESTIMATORS
    failures: int = 0
    bandwidth_hz: tuple[float, float] = (DEFAULT_BANDWIDTH_HZ, DEFAULT_BANDWIDTH_HZ)
    swing: Swing | None = None
    motion: np.ndarray | None = None
    motion_name: str = "at rest"
    settle_s: float = 2.0
    alpha_points: int = ALPHA_POINTS
    sensor_bandwidth: tuple[float, int] | None = None
    g_sensitivity_deg_s_per_g: tuple[float, float, float] | None = None
    specific_force_m_s2: np.ndarray | None = None
    objective: str | None = None
    design_rho: float | None = None
    far_per_h: float = 0.01
    p_md: float = 0.001
    mdb_max: float | None = None

    def __post_init__(self):
        if self.sensor_bandwidth is not None:
            fc, order = self.sensor_bandwidth
            bandwidth_sos(fc, order, self.dt_s)                     # order 1/2, 0 < fc < Nyquist

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz

    def sensor(self, n_gyros: int = 1):
        """The gyros' own filter as :class:`gyroarray.design.predict.SensorBandwidth` (None: none)."""
        if self.sensor_bandwidth is None:
            return None
        fc, order = self.sensor_bandwidth
        return SensorBandwidth(cutoff_hz=np.full(n_gyros, float(fc)),
                               order=np.full(n_gyros, int(order)), dt_s=self.dt_s)

    def sensor_entries(self) -> tuple:
        """The sensor's ``bandwidth`` and ``g_sensitivity`` as model entries on every gyro."""
        out = []
        if self.sensor_bandwidth is not None:
            out.append(ModelEntry(BANDWIDTH, None, {"cutoff_hz": float(self.sensor_bandwidth[0]),
                                                      "order": int(self.sensor_bandwidth[1])}))
        if self.g_sensitivity_deg_s_per_g is not None:
            out.append(ModelEntry(G_SENSITIVITY, None,
                                  {"deg_s_per_g": tuple(float(v) for v in self.g_sensitivity_deg_s_per_g)}))
        return tuple(out)

    @property
    def n_samples(self) -> int:
        from gyroarray.sim.table import n_samples  # lazy: loads mujoco
        return n_samples(self.horizon_s, self.rate_hz)


# -- per-layout channel parameters ------------------------------------------------------

def _weights(kind: str, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Per-sample weights M (G, 3, N) of a stack of layouts H (G, N, 3)."""
    if kind == "gls":
        rih = np.linalg.solve(R[None], H)                            # R⁻¹ H
        return np.linalg.solve(np.einsum("gni,gnj->gij", H, rih), np.swapaxes(rih, 1, 2))
    if kind == "ols":
        return np.linalg.solve(np.einsum("gni,gnj->gij", H, H), np.swapaxes(H, 1, 2))
    if kind == "naive":
        return np.swapaxes(H, 1, 2) / np.sum(H * H, axis=1)[:, :, None]
    raise ValueError(kind)


@dataclass
class _Channels:
    """Per α and axis: the channel's noise levels for one estimator (SI, per sample)."""

    white: np.ndarray          # (G, 3)
    walk: np.ndarray
    flicker: np.ndarray        # B² per axis
    gm: np.ndarray
    ratio: np.ndarray | None   # kf_array: q/r the filter is designed for (G, 3)
    decoupled: bool
    kf_single_ratio: float = 0.0   # kf_single: q/r of one gyro
    bias: np.ndarray | None = None  # fixed weights: max |M H − I| per layout (≠ 0: biased by the motion)


def _channels(est: str, H: np.ndarray, g: GyroNoise, dt: float) -> _Channels:
    N = H.shape[1]
    s2 = units.arw_deg_rt_h_to_rad_rt_s(g.arw_deg_rt_h) ** 2 / dt
    q = units.rrw_deg_h_rt_h_to_rad_s_rt_s(g.rrw_deg_h_rt_h) ** 2 * dt
    ca, cr = correlation_matrix(N, g.rho_arw), correlation_matrix(N, g.rho_rrw)
    R, Qb = s2 * ca, q * cr
    kind = {"kf_array": "gls", "kf_single": "ols"}.get(est, est)
    M = _weights(kind, H, R)
    white = np.einsum("gai,ij,gaj->ga", M, R, M)
    walk = np.einsum("gai,ij,gaj->ga", M, Qb, M)
    m2 = np.sum(M * M, axis=2)
    b2 = m2 * units.deg_h_to_rad_s(g.bi_deg_h) ** 2
    gm = m2 * units.deg_h_to_rad_s(g.gm_sigma_deg_h) ** 2
    ratio, decoupled = None, True
    if est == "kf_array":
        ratio = walk / white
        # decoupled: whitened axes orthogonal and eigenvectors of the whitened bias covariance
        L = np.linalg.cholesky(R)
        ht = np.linalg.solve(L[None], H)
        qt = np.linalg.solve(L, np.linalg.solve(L, Qb).T)
        gram = np.einsum("gni,gnj->gij", ht, ht)
        off = np.abs(gram - np.einsum("gii->gi", gram)[:, :, None] * np.eye(3))
        qh = np.einsum("nm,gmi->gni", qt, ht)
        resid = qh - ht * (np.einsum("gni,gni->gi", ht, qh) / np.einsum("gni,gni->gi", ht, ht))[:, None, :]
        scale = np.max(np.abs(gram), axis=(1, 2))
        ok = np.isfinite(scale) & (scale > 0)
        decoupled = bool(np.all(off[ok] <= 1e-9 * scale[ok, None, None])
                         and np.all(np.abs(resid[ok]) <= 1e-9 * (np.max(np.abs(qt)) * np.sqrt(scale[ok]))[:, None, None]))
    return _Channels(white, walk, b2, gm, ratio, decoupled)


# -- the filters and their unit responses ----------------------------------------------------

class _FilterBank:
    """Channel filters and unit responses, built on demand and cached."""

    def __init__(self, space: DesignSpace, gm_tau_s: float, bi: bool):
        self.space = space
        self.n = space.n_samples
        self.k0 = settle_start(self.n, space.dt_s, space.settle_s)
        self.gm_tau = gm_tau_s if gm_tau_s > 0 else None
        self.bi = bi
        self.motion: np.ndarray | None
        if space.motion is not None:
            self.motion = np.asarray(space.motion, dtype=float)[:self.n]
        elif space.swing is not None:
            self.motion = swing_truth(space.swing, self.n, space.dt_s)
        else:
            self.motion = None
        self.swing_hz = None if space.swing is None else space.swing.frequency_hz
        self._cache: dict = {}

    def get(self, kind: str, bw: float | None, ratio: float | None = None):
        key = (kind, None if bw is None else float(bw), None if ratio is None else float(f"{ratio:.12g}"))
        if key not in self._cache:
            sys = channel_filter(kind, self.space.dt_s, bw, ratio)
            self._cache[key] = None if sys is None else channel_response(
                sys, self.space.dt_s, self.n, self.k0, bi=self.bi, gm_tau_s=self.gm_tau,
                motion=self.motion, swing_hz=self.swing_hz, sensor=self.space.sensor())
        return self._cache[key]


def _filter_kind(est: str) -> str:
    return {"kf_array": "kf", "kf_single": "kf", "gls": "lowpass", "ols": "lowpass"}.get(est, "none")


def _bandwidths(space: DesignSpace, est: str) -> list[float | None]:
    """The bandwidths an estimator is tried at (None: its unfiltered form)."""
    if est == "naive":
        return [None]
    lo, hi = space.bandwidth_hz
    nyq = 0.5 * space.rate_hz
    hi = min(hi, 0.45 * space.rate_hz)
    lo = min(lo, hi)
    grid = [lo] if lo == hi else list(np.geomspace(lo, hi, max(2, int(round(
        BW_PER_DECADE * math.log10(hi / lo))) + 1)))
    out: list[float | None] = [float(f) for f in grid if 0 < f < nyq]
    if est in ("gls", "ols") and lo != hi:
        out.append(None)                                             # no low-pass
    return out


@dataclass
class _Moments:
    """Per axis: the window moments of one design (SI) and its objective."""

    ms: np.ndarray             # (..., 3)
    sumw: np.ndarray
    sumf: np.ndarray


def _combine(ch: _Channels, sel, resp) -> _Moments:
    """Moments per axis of the channels ``sel`` (index into α) through the responses
    ``resp`` (one ChannelResponse per axis, or None: infeasible)."""
    out = []
    for part in range(3):
        v = np.zeros(ch.white[sel].shape)
        for a in range(3):
            r = resp[a]
            if r is None:
                v[..., a] = np.inf
                continue
            v[..., a] = (ch.white[sel][..., a] * r.white[part] + ch.walk[sel][..., a] * r.walk[part]
                         + ch.flicker[sel][..., a] * r.flicker[part]
                         + ch.gm[sel][..., a] * r.gauss_markov[part])
        out.append(v)
    return _Moments(*out)


def _add_motion(m: _Moments, resp) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Total ms, mean² over the window and sum² over the run per axis (noise + motion)."""
    ms, sumw2, sumf2 = m.ms.copy(), m.sumw.copy(), m.sumf.copy()
    for a in range(3):
        r = resp[a]
        if r is None or r.motion is None:
            continue
        mms, msw, msf = r.motion
        ms[..., a] += mms[a]
        sumw2[..., a] += msw[a] ** 2
        sumf2[..., a] += msf[a] ** 2
    return ms, sumw2, sumf2


#: The swing-response keys of a design's prediction: total, then its two factors.
_SPLIT_KEYS = ("amplitude_ratio", "phase_deg", "estimator_amplitude_ratio", "estimator_phase_deg",
               "sensor_amplitude_ratio", "sensor_phase_deg")


def _split(r) -> dict:
    """The swing response of a channel (None at rest): total, estimator's and sensor's."""
    return {k: getattr(r, k) for k in _SPLIT_KEYS}


def _with_sensor(model, space: DesignSpace, *, g_sensitivity: bool = True):
    """The noise model with the space's sensor bandwidth (and g-sensitivity) on every gyro.

    The Monte-Carlo check and the full predictor leave the g-sensitivity out
    (``g_sensitivity`` False), as the ranking does: it is reported on its own.
    """
    extra = tuple(e for e in space.sensor_entries() if g_sensitivity or e.effect != G_SENSITIVITY)
    return model if not extra else NoiseModel(tuple(model.entries) + extra,
                                              description=model.description)


def _r_matrix(n: int, g: GyroNoise, dt: float) -> np.ndarray:
    """Covariance of one white sample of the N gyros [rad²/s²]."""
    if g.per_gyro is not None:
        return _cov(g, n, None, dt)[0]
    return units.arw_deg_rt_h_to_rad_rt_s(g.arw_deg_rt_h) ** 2 / dt * correlation_matrix(n, g.rho_arw)


def _space_specific_force(space: DesignSpace) -> np.ndarray:
    """The specific force at the platform origin over the scored window (n, 3) [m/s²]:
    the motion profile's truth, else the level table at rest (a swing's few degrees of
    tilt are left out), [0, 0, g0]."""
    if space.specific_force_m_s2 is not None:
        return np.asarray(space.specific_force_m_s2, dtype=float)[:space.n_samples]
    return np.array([[0.0, 0.0, G0_M_S2]])


def _g_sensitivity(space: DesignSpace, dc_gain: np.ndarray) -> dict:
    """``g_sensitivity``: the RMS rate error of the space's g-sensitivity on its motion, per
    gyro and fused through the design's DC gain T₀ (3, N) (:func:`gyroarray.design.predict.g_sensitivity_error`);
    {} without one."""
    if space.g_sensitivity_deg_s_per_g is None:
        return {}
    T0 = np.asarray(dc_gain, dtype=float)
    N = T0.shape[1]
    k = np.tile(units.deg_s_per_g_to_rad_s_per_m_s2(np.asarray(space.g_sensitivity_deg_s_per_g,
                                                               dtype=float)), (N, 1))
    f0 = _space_specific_force(space)
    f = np.broadcast_to(f0[:, None, :], (f0.shape[0], N, 3))
    k0 = settle_start(f0.shape[0], space.dt_s, space.settle_s) if f0.shape[0] > 1 else 0
    r = g_sensitivity_error(k, f, T0, k0)
    fused = r["fused_rms_deg_s"]
    return {G_SENSITIVITY: {"per_gyro_rms_deg_s": float(np.mean(r["per_gyro_rms_deg_s"])),
                              "fused_rms_deg_s": fused,
                              "fused_rms_3axis_deg_s": float(math.sqrt(sum(v * v for v in fused.values())))}}


# -- the search --------------------------------------------------------------------------

def _alpha_grid(scheme: int, points: int) -> np.ndarray:
    hi = 90.0 if scheme == 1 else 180.0
    return np.deg2rad(np.linspace(hi / points, hi - (hi / points if scheme == 2 else 0.0), points))


def _survives(H: np.ndarray, rho: float, k: int) -> np.ndarray:
    """Worst-case GDOP (G,) over every choice of k failed gyros (inf: an axis is lost)."""
    G, N, _ = H.shape
    if k == 0:
        return gdop_batch(H, np.linalg.cholesky(correlation_matrix(N, rho)))
    if N - k < 3:
        return np.full(G, math.inf)
    worst = np.zeros(G)
    chol = np.linalg.cholesky(correlation_matrix(N - k, rho))
    for keep in itertools.combinations(range(N), N - k):
        worst = np.maximum(worst, gdop_batch(H[:, list(keep)], chol))
    return worst


def _evaluate(est, resp_of, ch: _Channels, sel) -> tuple[np.ndarray, _Moments]:
    """Objective (3-axis RMS² about the truth over the window) of channels ``sel``."""
    m = _combine(ch, sel, resp_of)
    ms, _, _ = _add_motion(m, resp_of)
    return np.sum(ms, axis=-1), m


@dataclass
class _Best:
    scheme: int
    n: int
    est: str
    alpha_rad: float
    bw: float | None
    objective: float
    resp: list
    rho: float


def _responses(bank: _FilterBank, est: str, bw, ch: _Channels, idx=None) -> list:
    """One channel response per axis for the design (kf_array: per its design ratio)."""
    kind = _filter_kind(est)
    if bw is None:
        kind = "none"
    if kind == "kf":
        if est == "kf_array":
            assert ch.ratio is not None                              # _channels sets it for kf_array
            ratios = ch.ratio[0 if idx is None else idx]
        else:
            ratios = np.full(3, ch.kf_single_ratio)
        return [bank.get("kf", bw, float(r)) for r in ratios]
    r = bank.get(kind, bw)
    return [r, r, r]


def _search_one(bank, space, g: GyroNoise, scheme: int, n: int, est: str, rho: float,
                alive: np.ndarray, alphas: np.ndarray, H: np.ndarray, evaluate: bool = True):
    """Best (α, bandwidth) of one scheme, N and estimator at one ρ (``evaluate`` False:
    only the channels)."""
    gr = g.with_rho(rho) if g.rho_arw == g.rho_rrw else g
    ch = _channels(est, H, gr, space.dt_s)
    ch.kf_single_ratio = _single_ratio(g, space)
    if est == "kf_array" and ch.decoupled:
        assert ch.ratio is not None                                  # _channels sets it for kf_array
        r0 = ch.ratio[alive][0] if alive.any() else ch.ratio[0]
        if np.any(np.abs(ch.ratio[alive] - r0) > 1e-9 * np.abs(r0) + 1e-300):
            ch.decoupled = False
    if not ch.decoupled or not evaluate:
        return None, ch
    best = None
    for bw in _bandwidths(space, est):
        resp = _responses(bank, est, bw, ch, idx=int(np.argmax(alive)) if alive.any() else 0)
        J, _ = _evaluate(est, resp, ch, slice(None))
        J = np.where(alive & np.isfinite(J), J, np.inf)
        k = int(np.argmin(J))
        if np.isfinite(J[k]):                       # ties (α and 180° − α at ρ = 0): the smaller α
            k = int(np.flatnonzero(J <= J[k] * (1.0 + 1e-9))[0])
        if np.isfinite(J[k]) and (best is None or J[k] < best.objective):
            best = _Best(scheme, n, est, float(alphas[k]), bw, float(J[k]), resp, rho)
    return best, ch


def _refine_alpha(best: _Best, space: DesignSpace, g: GyroNoise, alphas: np.ndarray,
                  failures: int) -> _Best:
    """Continuous α around the best grid point (bounded Brent), same bandwidth."""
    k = int(np.argmin(np.abs(alphas - best.alpha_rad)))
    lo = alphas[k - 1] if k > 0 else alphas[k] * 0.5
    hi = alphas[k + 1] if k + 1 < alphas.size else alphas[k]
    gr = g.with_rho(best.rho) if g.rho_arw == g.rho_rrw else g

    def f(alpha):
        H = conical_axes(best.scheme, best.n, np.array([alpha]))
        if failures and not np.isfinite(_survives(H, best.rho, failures)[0]):
            return math.inf
        ch = _channels(best.est, H, gr, space.dt_s)
        ch.kf_single_ratio = _single_ratio(g, space)
        J, _ = _evaluate(best.est, best.resp, ch, slice(None))
        return float(J[0]) if np.isfinite(J[0]) else math.inf
    if hi <= lo:
        return best
    res = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-7})
    if res.fun < best.objective:
        return replace(best, alpha_rad=float(res.x), objective=float(res.fun))
    return best


@lru_cache(maxsize=4096)
def _fault_tolerance(scheme: int, n: int, alpha_rad: float, rho: float) -> dict:
    """:func:`gyroarray.core.gdop.fault_tolerance` of a conical layout (cached; copy before changing)."""
    return fault_tolerance(Layout.conical(scheme, n, alpha_rad), rho)


def _design_dict(b: _Best, space: DesignSpace, g: GyroNoise, failures: int) -> dict:
    """The predicted metrics of one design (fast path), in datasheet units."""
    gr = g.with_rho(b.rho) if g.rho_arw == g.rho_rrw else g
    H = conical_axes(b.scheme, b.n, np.array([b.alpha_rad]))
    ch = _channels(b.est, H, gr, space.dt_s)
    m = _combine(ch, slice(None), b.resp)
    ms, sumw2, sumf2 = _add_motion(m, b.resp)
    n, dt = space.n_samples, space.dt_s
    nw = n - settle_start(n, dt, space.settle_s)
    mean2 = sumw2[0] / nw ** 2
    var = nw / (nw - 1.0) * (ms[0] - mean2)
    to = units.rad_s_to_deg_s
    pred = {}
    for a, ax in enumerate(AXES):
        r = b.resp[a]
        pred[ax] = {"rms_deg_s": float(to(math.sqrt(ms[0, a]))),
                    "std_deg_s": float(to(math.sqrt(max(var[a], 0.0)))),
                    "mean_deg_s": float(to(math.sqrt(mean2[a]))),
                    "angle_deg_at_horizon": float(units.rad_to_deg(dt * math.sqrt(sumf2[0, a]))),
                    "arw_long_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(
                        abs(r.dc_gain) * math.sqrt(ch.white[0, a] * dt))),
                    "rrw_long_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(
                        abs(r.dc_gain) * math.sqrt(ch.walk[0, a] / dt))),
                    "dc_gain": r.dc_gain, **_split(r)}
    ft = _fault_tolerance(b.scheme, b.n, b.alpha_rad, b.rho if g.rho_arw == g.rho_rrw else g.rho_arw)
    dcg = np.array([r.dc_gain for r in b.resp])
    kind = {"kf_array": "gls", "kf_single": "ols"}.get(b.est, b.est)
    gs = _g_sensitivity(space, dcg[:, None] * _weights(kind, H, _r_matrix(b.n, gr, space.dt_s))[0])
    return {"scheme": b.scheme, "n": b.n, "alpha_deg": float(np.degrees(b.alpha_rad)),
            "estimator": b.est, "bandwidth_hz": b.bw, "rho": b.rho,
            "rms_3axis_deg_s": float(to(math.sqrt(b.objective))),
            "predicted": pred, "gdop": ft["gdop"], **gs,
            "worst_gdop_after_failures": ft["worst_gdop_after"][str(failures)] if failures else ft["gdop"],
            "fault_tolerance": json.loads(json.dumps(ft))}


def _estimator_kwargs(est: str, bw, g: GyroNoise) -> dict:
    """The hyperparameters of estimator ``est`` as the predictor designs it: its bandwidth
    [Hz], and for the array KF no bias states when the gyros have no rate random walk (the
    fast path's walk/white ratio 0: the bias states would have no process noise and the gain
    no steady state)."""
    if est in ("kf_array", "kf_single"):
        kw: dict = {"bandwidth_hz": bw}
        if est == "kf_array" and not g.rrw_deg_h_rt_h > 0:
            kw["bias_states"] = False
        return kw
    return {"lowpass_hz": bw} if est in ("gls", "ols") else {}


def estimator_kwargs(est: str, bw, g: GyroNoise) -> dict:
    """The hyperparameters of estimator ``est`` at bandwidth ``bw`` [Hz] as the predictor designs
    it for the gyros ``g`` (what a simulation of the recommended design builds)."""
    return _estimator_kwargs(est, bw, g)


def generic_design(scheme, n, est, alpha, bw, rho, space: DesignSpace, g: GyroNoise,
                    failures: int) -> dict:
    """A design predicted by the full predictor (used where the fast path does not apply)."""
    gr = g.with_rho(rho) if g.rho_arw == g.rho_rrw else g
    layout = Layout.conical(scheme, n, alpha)
    model = gr.noise_model(n)
    e = get_estimator(est)(**_estimator_kwargs(est, bw, g)).fit(layout, model, space.dt_s)
    motion = space.motion[:space.n_samples] if space.motion is not None else None
    p = predict(e, _with_sensor(model, space, g_sensitivity=False), n_samples=space.n_samples,
                settle_s=space.settle_s, truth_rad_s=motion, swing=space.swing)
    rms2 = sum(units.deg_s_to_rad_s(v["rms_deg_s"]) ** 2 for v in p.axes.values())
    pred = {ax: {"rms_deg_s": v["rms_deg_s"], "std_deg_s": v["std_deg_s"],
                 "mean_deg_s": v["mean_deg_s"], "angle_deg_at_horizon": v["angle_deg"],
                 "arw_long_deg_rt_h": v["arw_long_deg_rt_h"],
                 "rrw_long_deg_h_rt_h": v["rrw_long_deg_h_rt_h"],
                 "dc_gain": v["dc_gain"], **{k: v.get(k) for k in _SPLIT_KEYS}}
            for ax, v in p.axes.items()}
    ft = _fault_tolerance(scheme, n, alpha, gr.rho_arw)
    return {"scheme": scheme, "n": n, "alpha_deg": float(np.degrees(alpha)), "estimator": est,
            "bandwidth_hz": bw, "rho": rho, "rms_3axis_deg_s": float(units.rad_s_to_deg_s(math.sqrt(rms2))),
            "predicted": pred, "gdop": ft["gdop"],
            **_g_sensitivity(space, e.linear_system().dc_gain()),
            "worst_gdop_after_failures": ft["worst_gdop_after"][str(failures)] if failures else ft["gdop"],
            "fault_tolerance": json.loads(json.dumps(ft)),
            "path": "full predictor (the array KF does not decouple here)"}


def _rank_key(d: dict) -> float:
    return d["rms_3axis_deg_s"] if math.isfinite(d["rms_3axis_deg_s"]) else math.inf


def _bank(space: DesignSpace, g: GyroNoise) -> "_FilterBank":
    """The filter bank of a search (one per space and noise shape; ρ does not enter it)."""
    cache = space.__dict__.setdefault("_banks", {})
    key = (g.gm_tau_s, g.bi_deg_h > 0)
    if key not in cache:
        cache[key] = _FilterBank(space, g.gm_tau_s, bi=g.bi_deg_h > 0)
    return cache[key]


def search(g: GyroNoise, space: DesignSpace, rho: float) -> tuple[list[dict], list[str]]:
    """Every scheme × N × estimator at its best cone angle and bandwidth, at one ρ, ranked.

    Returns the designs (best first) and notes (what was left out and why).
    """
    g, space = sized_for(g, space)
    bank = _bank(space, g)
    designs, notes = [], []
    for scheme in space.schemes:
        alphas = _alpha_grid(scheme, space.alpha_points)
        for n in space.ns:
            lo = -1.0 / (n - 1)
            if not (g.rho_arw == g.rho_rrw and rho > lo) and not (g.rho_arw != g.rho_rrw
                                                                  and min(g.rho_arw, g.rho_rrw) > lo):
                notes.append(f"scheme {scheme}, N = {n}: rho = {rho:g} is not a correlation N = {n} "
                             f"gyros can have (below -1/(N-1) = {lo:.4g}); left out")
                continue
            H = conical_axes(scheme, n, alphas)
            alive = np.isfinite(_survives(H, rho if g.rho_arw == g.rho_rrw else g.rho_arw,
                                          space.failures))
            if not alive.any():
                notes.append(f"scheme {scheme}, N = {n}: no cone angle keeps a 3-axis rate after "
                             f"{space.failures} failed gyro(s); left out")
                continue
            found: dict[str, _Best | None] = {}
            for est in space.estimators:
                best, ch = _search_one(bank, space, g, scheme, n, est, rho, alive, alphas, H)
                if best is None and est == "kf_array" and not ch.decoupled:
                    found[est] = None                                # after kf_single
                    continue
                if best is None:
                    notes.append(f"scheme {scheme}, N = {n}, {est}: no bandwidth in range is reachable")
                    continue
                best = _refine_alpha(best, space, g, alphas, space.failures)
                found[est] = best
                designs.append(_design_dict(best, space, g, space.failures))
            if "kf_array" in found and found["kf_array"] is None:
                ref = found.get("kf_single")
                if ref is not None:
                    designs.append(generic_design(scheme, n, "kf_array", ref.alpha_rad, ref.bw, rho,
                                                   space, g, space.failures))
                    notes.append(f"scheme {scheme}, N = {n}, kf_array: its z axis does not decouple "
                                 "(unequal ARW and RRW correlation); predicted by the full predictor "
                                 "at kf_single's cone angle and bandwidth")
    designs = _ranked(designs, space.estimators)
    designs = _refine_top_bandwidths(designs, g, space, rho)
    return designs, notes


#: Designs at the top of a ranking whose bandwidth is refined off the grid.
REFINE_TOP = 8


def _refine_top_bandwidths(designs: list[dict], g: GyroNoise, space: DesignSpace, rho: float) -> list[dict]:
    """Bounded Brent in log(bandwidth) between the grid neighbours, for the top designs."""
    lo, hi = space.bandwidth_hz
    if lo == hi:
        return designs
    out = list(designs)
    for i, d in enumerate(designs[:REFINE_TOP]):
        bw = d["bandwidth_hz"]
        if bw is None:
            continue
        grid = [f for f in _bandwidths(space, d["estimator"]) if f is not None]
        k = int(np.argmin(np.abs(np.log(np.array(grid) / bw))))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        alpha = math.radians(d["alpha_deg"])

        def f(logbw):
            e = generic_or_fast(d["scheme"], d["n"], d["estimator"], alpha, float(np.exp(logbw)),
                                 rho, g, space)
            return e["rms_3axis_deg_s"] if math.isfinite(e["rms_3axis_deg_s"]) else math.inf
        if b <= a:
            continue
        res = minimize_scalar(f, bounds=(math.log(a), math.log(b)), method="bounded",
                              options={"xatol": 1e-3})
        if res.fun < d["rms_3axis_deg_s"]:
            new = generic_or_fast(d["scheme"], d["n"], d["estimator"], alpha,
                                   float(round(math.exp(res.x), 3)), rho, g, space)
            new["rank"] = d.get("rank")
            out[i] = new
    return _ranked(out, space.estimators)


def _ranked(designs: list[dict], estimators) -> list[dict]:
    """Best RMS first; designs equal to 1e-9 are ordered by fault tolerance (worst GDOP
    after two failures), Scheme 1 first, a cone opening upwards, then the estimator order."""
    designs = sorted(designs, key=_rank_key)
    out, i = [], 0
    order = {e: k for k, e in enumerate(estimators)}
    while i < len(designs):
        j = i + 1
        while j < len(designs) and designs[j]["rms_3axis_deg_s"] <= designs[i]["rms_3axis_deg_s"] * (1 + 1e-9):
            j += 1
        out += sorted(designs[i:j], key=lambda d: (
            round(d.get("fault_tolerance", {}).get("worst_gdop_after", {}).get("2", math.inf), 9),
            d["scheme"], d["alpha_deg"] > 90.0, order.get(d["estimator"], 99)))
        i = j
    for k, d in enumerate(out):
        d["rank"] = k + 1
    return out


def _objective_value(d: dict) -> float:
    """What a design is ranked on: its worst case (decision) in the objective's unit, else the
    3-axis RMS of the single-ρ search."""
    wc = d.get("worst_case")
    if wc is not None:
        v = wc["rms_3axis_deg_s" if d.get("objective", "rate") == "rate" else "angle_deg"]
    else:
        v = d["rms_3axis_deg_s"]
    return v if math.isfinite(v) else math.inf


def _pct(share: float) -> str:
    """A share in percent with the digits that tell 0.9987 % from 1 %."""
    return f"{100.0 * share:.4g} %"


def _mirror_of(a: dict, b: dict) -> bool:
    """b is a's mounting mirror (same scheme and N, the cone at 180° − α or the other senses)."""
    if (a["scheme"], a["n"], a["estimator"]) != (b["scheme"], b["n"], b["estimator"]):
        return False
    sa, sb = a.get("mounting_signs"), b.get("mounting_signs")
    alpha_mirror = abs(a["alpha_deg"] + b["alpha_deg"] - 180.0) < 1e-3
    return alpha_mirror or (sa is not None and sb is not None and sa != sb
                            and abs(a["alpha_deg"] - b["alpha_deg"]) < 1e-3)


def equivalent_groups(designs: list[dict], share: float = EQUIVALENT_SHARE) -> list[dict]:
    """Designs that theory makes equal, and smaller arrays that reach the same worst case.

    Two kinds of group (best first), each with ``members`` (ranks), ``designs`` (labels),
    ``spread`` (largest relative difference of the objective), ``kind`` and ``reason``:

    * ``identical`` — same N, predictions equal to 1e-9: the same estimator in another form
      (kf_array = kf_single on a decoupled cone, gls = ols = naive where HᵀC⁻¹H is diagonal),
      the two schemes at their isotropic optimum, or the mounting mirror (identical at ρ = 0).
      Designs of different N, or merely close, are never merged;
    * ``fewer_gyros`` — a design with fewer gyros whose worst case lies within ``share`` of a
      larger array's: "k gyros saved at the same worst case", with the difference in percent.
    """
    groups = []
    used: set = set()
    for i, d in enumerate(designs):
        if i in used:
            continue
        base = _objective_value(d)
        members = [d]
        for j in range(i + 1, len(designs)):
            e = designs[j]
            if j in used or e["n"] != d["n"]:
                continue
            v = _objective_value(e)
            if math.isfinite(base) and abs(v - base) <= 1e-9 * max(abs(base), 1e-300):
                members.append(e)
                used.add(j)
        if len(members) > 1:
            spread = max(_objective_value(m) for m in members) / base - 1.0 if base > 0 else 0.0
            groups.append({"members": [m["rank"] for m in members],
                           "designs": [design_label(m) for m in members], "spread": spread,
                           "kind": "identical", "reason": _why_equal(members, spread)})
    # a smaller array at the same worst case (within the tie share): the gyros it saves
    best_by_n: dict = {}
    for d in designs:
        if math.isfinite(_objective_value(d)):
            best_by_n.setdefault(d["n"], d)
    ns = sorted(best_by_n)
    for big in reversed(ns):
        d = best_by_n[big]
        for small in ns:
            if small >= big:
                break
            e = best_by_n[small]
            vd, ve = _objective_value(d), _objective_value(e)
            if ve <= vd * (1.0 + share):
                diff = ve / vd - 1.0
                groups.append({"members": [e["rank"], d["rank"]],
                               "designs": [design_label(e), design_label(d)], "spread": diff,
                               "kind": "fewer_gyros",
                               "reason": (f"{big - small} gyro(s) saved at the same worst case: N = {small} "
                                          f"reaches {ve:.6g} against {vd:.6g} for N = {big} "
                                          f"({'+' if diff >= 0 else ''}{_pct(diff)}, within the "
                                          f"{_pct(share)} tie share)")})
                break
    return groups


def design_label(d: dict) -> str:
    """One line naming a design: ``scheme S, N = n, alpha = A deg, estimator (bandwidth)``."""
    bw = "no low-pass" if d["bandwidth_hz"] is None else f"{d['bandwidth_hz']:.3g} Hz"
    if d["estimator"] == "naive":
        bw = "no filter"
    rev = [k + 1 for k, v in enumerate(d.get("mounting_signs") or []) if v < 0]
    sense = "" if not rev else (" [gyro" + ("s " if len(rev) > 1 else " ") + ",".join(map(str, rev))
                                + " reversed]")
    return (f"scheme {d['scheme']}, N = {d['n']}, alpha = {d['alpha_deg']:.2f} deg{sense}, "
            f"{d['estimator']} ({bw})")


def _why_equal(members: list[dict], spread: float) -> str:
    """Why designs of one N have the same prediction (only reasons that apply are given)."""
    ests = {m["estimator"] for m in members}
    schemes = {m["scheme"] for m in members}
    bits = []
    if ests & {"kf_array", "kf_single"} == {"kf_array", "kf_single"}:
        bits.append("kf_array and kf_single are the same filter here: with alike gyros and equal "
                    "ARW/RRW correlation the array KF decouples per axis into the single-gyro KF "
                    "on the least-squares channel")
    if len(ests & {"gls", "ols", "naive"}) > 1:
        bits.append("gls, ols and naive have the same weights: HᵀC⁻¹H is diagonal and the axes "
                    "are eigenvectors of C on these cones")
    if len(schemes) > 1:
        bits.append("both schemes reach the isotropic optimum HᵀC⁻¹H ∝ I at their own cone angle, "
                    "so their GDOP (and every prediction) is the same")
    if any(_mirror_of(a, b) for a in members for b in members if a is not b):
        rhos = {tuple(m.get("rho_range") or [m.get("rho", 0.0)] * 2) for m in members}
        bits.append("mounting mirror: the same lines with the other sense, identical when the gyros' "
                    "noise is uncorrelated" + (" (ρ = 0 here)" if rhos <= {(0.0, 0.0)} else ""))
    if not bits:
        bits.append("the same N with predictions equal to 1e-9 (a symmetry of the array: a rotation "
                    "of the body frame or a global sign)")
    return (f"identical by theory (spread {_pct(spread)}): " if spread > 0 else "identical by theory: ") \
        + "; ".join(bits)


def recommend(g: GyroNoise, space: DesignSpace, *, rhos=None) -> dict:
    """Rank the designs and recommend one (the ``--recommend`` JSON object).

    Parameters
    ----------
    g : GyroNoise
    space : DesignSpace
    rhos : sequence of float, optional
        Correlations the gyros may have (ρ is a condition, not a choice): every
        design is scored continuously over [min, max] of them (and at each of
        them in ``rms_by_rho``). None: the ρ of ``g``.

    Returns
    -------
    dict
        ``recommended``, ``designs``, ``equivalent``, ``assumptions``, ``notes``,
        ``runner_up``, ``what_changes_the_choice``, ``objective``, ``decision``
        (one line), ``tie`` (when the recommendation tied), ``seconds`` and, with
        a ρ range, ``per_rho`` (the designs as built ranked at each ρ). Each design
        (:func:`decide`) carries ``axes``, ``mounting``, ``design_rho``,
        ``objective``, ``worst_case`` {rho, failed_gyros, rms_3axis_deg_s,
        angle_deg}, ``typical``, ``error_budget`` and, with failures,
        ``mdb_deg_s``.
    """
    t0 = time.perf_counter()
    single = rhos is None
    rho_list = [g.rho_arw] if single else [float(r) for r in rhos]
    notes: list[str] = []
    g, space = sized_for(g, space, notes)
    lo, hi = (g.rho_arw, g.rho_arw) if single else (min(rho_list), max(rho_list))
    designs, nt = decide(g, space, lo, hi, rhos_shown=None if single else rho_list)
    notes += nt
    if not designs:
        why = "; ".join(sorted(set(notes))[:3]) or "failures, rho or bandwidth"
        raise InputError(f"no design meets the requirements: {why}")
    rec = designs[0]
    other = [d for d in designs[1:] if (d["scheme"], d["n"]) != (rec["scheme"], rec["n"])]
    out: dict[str, Any] = {"recommended": _short(rec),
                           "runner_up": _short(other[0]) if other else None,
                           "designs": [_short(d) for d in designs],
                           "equivalent": equivalent_groups(designs),
                           "assumptions": assumptions(g, space, rho_list, single),
                           "what_changes_the_choice": _what_changes(designs, g, space, rho_list),
                           "notes": sorted(set(notes))}
    out.update(_decision_statement(designs, space, lo, hi))
    out["assumptions"]["objective"] = {"value": rec["objective"], "source": "user" if space.objective
                                       else "default (angle when a horizon is given, else rate)",
                                       "unit": OBJECTIVE_WORDS[rec["objective"]]}
    lim = tracking_limit(rec, space, g)
    if lim is not None:
        out["tracking_limit"] = lim
    gst = g_sensitivity_statement(rec, space)
    if gst is not None:
        out[G_SENSITIVITY] = {**rec[G_SENSITIVITY], "statement": gst}
    if not single:
        # the designs as decided (weights fixed at their design ρ), ranked at each true ρ
        out["per_rho"] = {}
        for r in rho_list:
            at = [d for d in designs if f"{r:g}" in d.get("rms_by_rho", {})]
            at = sorted(at, key=lambda d: d["rms_by_rho"][f"{r:g}"])[:10]
            out["per_rho"][f"{r:g}"] = [{**_short(d), "rms_3axis_deg_s": d["rms_by_rho"][f"{r:g}"],
                                         "rho": r} for d in at]
    out["seconds"] = time.perf_counter() - t0
    return out


def tracking_limit(d: dict, space: DesignSpace, g: GyroNoise | None = None) -> dict | None:
    """Whether the sensors' own bandwidth or the estimator limits tracking of the swing.

    On the design's worst-tracked axis, the tracking error per unit swing
    amplitude of the gyros' own filter, |1 − F| (amplitude loss and lag
    together), is set against the estimator's, |1 − T|; the fused output
    passes their product T·F. None without a sensor bandwidth.
    """
    if space.sensor_bandwidth is None:
        return None
    fc, order = space.sensor_bandwidth
    what = f"the gyros' own {fc:g} Hz order-{int(order)} low-pass"
    if space.swing is None:
        return {"limited_by": None,
                "statement": f"{what} is cascaded before the estimator in every prediction (noise and "
                             "motion); give --swing AMP,FREQ to learn whether it or the estimator limits tracking"}
    p = d["predicted"]
    ax = min(AXES, key=lambda a: p[a]["amplitude_ratio"])
    q = p[ax]
    sa, ea = q["sensor_amplitude_ratio"], q["estimator_amplitude_ratio"]
    est = d["estimator"] + ("" if d["bandwidth_hz"] is None else f" at {d['bandwidth_hz']:.3g} Hz")
    f = space.swing.frequency_hz
    def err(amp, lag_deg):                                           # |1 − A e^{−jφ}|
        return abs(1.0 - amp * np.exp(-1j * np.radians(lag_deg)))
    se, ee = err(sa, q["sensor_phase_deg"]), err(ea, q["estimator_phase_deg"])
    nums = (f"{what} passes {sa:.4f} of the amplitude with a lag of {q['sensor_phase_deg'] + 0.0:.3g} deg "
            f"(tracking error {100 * se:.3g} % of the swing), the {est} {ea:.4f} with "
            f"{q['estimator_phase_deg'] + 0.0:.3g} deg ({100 * ee:.3g} %); the fused output "
            f"{q['amplitude_ratio']:.4f} with {q['phase_deg'] + 0.0:.3g} deg")
    if se > ee:
        text = (f"the sensor bandwidth, not the {d['estimator']}, limits tracking at {f:g} Hz: {nums}. "
                "A wider estimator bandwidth cannot win back the sensors' loss; gyros with a wider "
                "internal filter can")
        by = "sensor"
    else:
        text = f"the {d['estimator']}, not the sensor bandwidth, limits tracking at {f:g} Hz: {nums}"
        by = "estimator"
    if g is not None:
        bare = generic_or_fast(d["scheme"], d["n"], d["estimator"], math.radians(d["alpha_deg"]),
                                d["bandwidth_hz"], d.get("rho", g.rho_arw), g,
                                replace(space, sensor_bandwidth=None))["rms_3axis_deg_s"]
        text += (f". With an ideal sensor this design would predict {bare:.4g} deg/s 3-axis RMS "
                 f"instead of {d['rms_3axis_deg_s']:.4g}")
    return {"limited_by": by, "axis": ax, "swing_hz": f, "statement": text,
            "rms_3axis_without_sensor_filter_deg_s": None if g is None else float(bare),
            "sensor_tracking_error_share": float(se), "estimator_tracking_error_share": float(ee),
            "sensor_amplitude_ratio": sa, "sensor_phase_deg": q["sensor_phase_deg"],
            "estimator_amplitude_ratio": ea, "estimator_phase_deg": q["estimator_phase_deg"],
            "amplitude_ratio": q["amplitude_ratio"], "phase_deg": q["phase_deg"]}


def g_sensitivity_statement(d: dict, space: DesignSpace) -> str | None:
    """The g-sensitivity's rate error of a design beside its noise RMS, in words."""
    gs = d.get(G_SENSITIVITY)
    if gs is None or space.g_sensitivity_deg_s_per_g is None:
        return None
    k = ", ".join(f"{v:g}" for v in space.g_sensitivity_deg_s_per_g)
    ratio = gs["fused_rms_3axis_deg_s"] / d["rms_3axis_deg_s"] if d["rms_3axis_deg_s"] > 0 else math.inf
    xyz = " / ".join(f"{gs['fused_rms_deg_s'][a]:.3g}" for a in AXES)
    where = "the motion profile" if space.specific_force_m_s2 is not None else "the level table (gravity on z)"
    return (f"g-sensitivity ({k}) (deg/s)/g on every gyro, on {where}: {gs['per_gyro_rms_deg_s']:.4g} deg/s "
            f"RMS per gyro, {gs['fused_rms_3axis_deg_s']:.4g} deg/s 3-axis on the fused output "
            f"(x/y/z {xyz}), "
            f"{ratio:.3g} x the design's predicted 3-axis RMS from noise and tracking "
            f"({d['rms_3axis_deg_s']:.4g} deg/s)"
            + ("; it dominates: calibrate it out or choose gyros with less" if ratio > 1 else "")
            + ". Not part of the ranking: a deterministic bias that a calibration of k removes")


def _short(d: dict) -> dict:
    """The JSON fields of one design (the issue's keys first)."""
    keys = ("rank", "scheme", "n", "alpha_deg", "estimator", "bandwidth_hz", "predicted",
            "worst_gdop_after_failures", "rms_3axis_deg_s", "gdop", "fault_tolerance", "rho",
            "worst_rms_3axis_deg_s", "rms_by_rho", G_SENSITIVITY, "path", "axes", "mounting",
            "mounting_signs", "design_rho", "design_rho_note", "objective", "rho_range", "worst_case",
            "typical", "oracle_worst_case", "error_budget", "mdb_deg_s", "mdb_per_gyro_deg_s",
            "mdb_worst_gyro", "far_per_h", "p_md", "tie", "excluded", "predicted_at", "scored")
    return {k: d[k] for k in keys if k in d}


def _evaluate_design(d: dict, g: GyroNoise, space: DesignSpace, rho: float) -> dict:
    """One fixed design (scheme, N, α, estimator, bandwidth) predicted at another ρ."""
    return generic_or_fast(d["scheme"], d["n"], d["estimator"], math.radians(d["alpha_deg"]),
                            d["bandwidth_hz"], rho, g, space)


def generic_or_fast(scheme, n, est, alpha, bw, rho, g, space) -> dict:
    gr = g.with_rho(rho) if g.rho_arw == g.rho_rrw else g
    H = conical_axes(scheme, n, np.array([alpha]))
    ch = _channels(est, H, gr, space.dt_s)
    ch.kf_single_ratio = _single_ratio(g, space)
    if not ch.decoupled:
        return generic_design(scheme, n, est, alpha, bw, rho, space, g, space.failures)
    bank = _bank(space, g)
    resp = _responses(bank, est, bw, ch)
    J, _ = _evaluate(est, resp, ch, slice(None))
    b = _Best(scheme, n, est, alpha, bw, float(J[0]), resp, rho)
    return _design_dict(b, space, g, space.failures)


def _single_ratio(g: GyroNoise, space: DesignSpace) -> float:
    """q_b / r of one gyro (the design ratio of kf_single's filter)."""
    return (units.rrw_deg_h_rt_h_to_rad_s_rt_s(g.rrw_deg_h_rt_h) ** 2 * space.dt_s ** 2
            / units.arw_deg_rt_h_to_rad_rt_s(g.arw_deg_rt_h) ** 2)


def worst_words(d: dict) -> str:
    """A design's worst case in words, by its objective: value, unit, true ρ and failed gyros
    (e.g. "27.92 deg angle error at the horizon (ρ = -0.1, gyro 3 failed)")."""
    wc = d.get("worst_case")
    if not wc:
        return f"{d['rms_3axis_deg_s']:.4g} deg/s 3-axis RMS (ρ = {d.get('rho', math.nan):.4g}, no failure)"
    failed = ("no failure" if not wc["failed_gyros"] else
              ("gyro " if len(wc["failed_gyros"]) == 1 else "gyros ")
              + ", ".join(map(str, wc["failed_gyros"])) + " failed")
    v = (f"{wc['angle_deg']:.4g} deg angle error at the horizon" if d.get("objective") == "angle"
         else f"{wc['rms_3axis_deg_s']:.4g} deg/s 3-axis RMS")
    return f"{v} (ρ = {wc['rho']:.4g}, {failed})"


def _more(d: dict, ref: dict) -> str:
    """``d``'s worst case against ``ref``'s, by the objective, as "12 % more" / "3 % less"."""
    key = "angle_deg" if d.get("objective") == "angle" and "worst_case" in d else "rms_3axis_deg_s"
    a = d["worst_case"][key] if "worst_case" in d else d[key]
    b = ref["worst_case"][key] if "worst_case" in ref else ref[key]
    share = 100.0 * (a / b - 1.0)
    return f"{abs(share):.0f} % {'more' if share >= 0 else 'less'}"


def _what_changes(designs: list[dict], g: GyroNoise, space: DesignSpace, rhos) -> list[str]:
    """Short sentences: what would change the recommendation."""
    rec = designs[0]
    out = []
    fewer = [d for d in designs if d["n"] < rec["n"]]
    if fewer:
        f = fewer[0]
        out.append(f"fewer gyros: the best N = {f['n']} design ({design_label(f)}) has a worst case of "
                   f"{worst_words(f)}, {_more(f, rec)} than the recommendation's {worst_words(rec)}")
    ft = rec.get("fault_tolerance", {})
    for k in ("1", "2"):
        if k in ft.get("three_axes_after", {}) and not ft["three_axes_after"][k]:
            alt = [d for d in designs if d.get("fault_tolerance", {}).get("three_axes_after", {}).get(k)]
            if alt:
                out.append(f"requiring a 3-axis rate after {k} failed gyro(s) (--failures {k}): "
                           f"{design_label(alt[0])}, worst case {worst_words(alt[0])}")
    if len(rhos) == 1:
        out.append("a correlation between the gyros: rerun with --rho-range LO,HI; the ranking "
                   "then holds per assumed ρ and the recommendation is the best worst case")
    if space.swing is None and space.motion is None:
        out.append("motion: at rest the bandwidth is a requirement (held at "
                   f"{space.bandwidth_hz[0]:g} Hz); with --swing or --motion it is traded against lag")
    return out


#: The error sources of a real gyro that a noise model may leave out, and why each matters.
_USUAL_EFFECTS = (
    (SCALE_FACTOR, "a rate error proportional to the body rate (ppm of the motion)"),
    (SCALE_NONLINEARITY, "a rate error growing with the square of the body rate"),
    (MISALIGNMENT, "each gyro's axis tilted from its mounted direction: cross-axis rate error"),
    (TEMPERATURE_BIAS, "a bias that follows the temperature swing"),
    (QUANTIZATION, "the output resolution (white angle noise)"),
    (CONSTANT_BIAS, "the turn-on bias: taken as calibrated at switch-on (biases start at zero)"),
)


def ignored_effects(g: GyroNoise, space: DesignSpace, budget_ignored=()) -> list[str]:
    """What the prediction leaves out, each as "name: why" (never empty while anything is).

    Parameters
    ----------
    g : GyroNoise
        Its ``ignored`` (effects of a source model the predictor does not model) and its
        model's effects (a usual error source absent from it is left out as zero).
    space : DesignSpace
        The g-sensitivity and the gyros' own low-pass, when stated.
    budget_ignored : sequence of str
        Effects the error budget could not evaluate on the stated motion
        (:attr:`gyroarray.design.budget.ErrorBudget.ignored`).

    Returns
    -------
    list of str
    """
    present = set() if g.model is None else {e.effect for e in g.model.entries}
    out = []
    for name in g.ignored:
        if (name == BANDWIDTH and space.sensor_bandwidth is not None) or (
                name == G_SENSITIVITY and space.g_sensitivity_deg_s_per_g is not None):
            continue
        out.append(f"{name}: in the model, not in the ranking's predictor (the error budget shows it "
                   "where the effect declares a term)")
    for name in budget_ignored:
        if not any(o.startswith(name + ":") for o in out):
            out.append(f"{name}: in the model, but the stated motion cannot excite or evaluate it "
                       "(e.g. a temperature coefficient without a temperature swing)")
    src = "the datasheet inputs" if g.model is None else "the model"
    for name, what in _USUAL_EFFECTS:
        if name not in present:
            out.append(f"{name}: not in {src}, taken as zero ({what})")
    if space.g_sensitivity_deg_s_per_g is None and G_SENSITIVITY not in present:
        out.append(f"{G_SENSITIVITY}: not in {src} (--g-sensitivity), taken as zero (a rate error "
                   "proportional to the specific force)")
    elif space.g_sensitivity_deg_s_per_g is not None:
        out.append(f"{G_SENSITIVITY}: stated; in the error budget and reported beside the ranking, "
                   "not ranked")
    if space.sensor_bandwidth is None and BANDWIDTH not in present:
        out.append(f"{BANDWIDTH}: not in {src} (--sensor-bandwidth), the gyros' own low-pass taken as flat")
    return out


def assumptions(g: GyroNoise, space: DesignSpace, rhos, single: bool) -> dict:
    """Every input of the search and where it came from (user / default / model)."""
    src = g.sources

    def item(value, source, unit=""):
        return {"value": value, "source": source, **({"unit": unit} if unit else {})}
    s = space.__dict__.get("_sources", {})
    return {
        ARW: item(g.arw_deg_rt_h, src.get(ARW, "user"), "deg/rt(h)"),
        RRW: item(g.rrw_deg_h_rt_h, src.get(RRW, "default"), "deg/h/rt(h)"),
        BIAS_INSTABILITY: item(g.bi_deg_h, src.get("bi", "default"), "deg/h"),
        GAUSS_MARKOV: item({"sigma_deg_h": g.gm_sigma_deg_h, "tau_s": g.gm_tau_s},
                             src.get(GAUSS_MARKOV, "default")),
        "rho": item(rhos[0] if single else list(rhos), src.get("rho_arw", "default"),
                    "common ARW and RRW correlation" if g.rho_arw == g.rho_rrw else
                    f"rho_arw {g.rho_arw:g}, rho_rrw {g.rho_rrw:g}"),
        "gyros": (item("alike: every gyro has the noise above (a model's gyros reduced to their "
                       "quadratic mean)", "assumption") if g.per_gyro is None else
                  item({"per_gyro": {k: [float(x) for x in v] for k, v in g.per_gyro.items()},
                        "statement": (f"each of the model's {g.n_gyros} gyros keeps its own parameters "
                                      f"(gyro k of the model at position k of the layout); the search is "
                                      f"over the layouts with N = {g.n_gyros}; the values above are "
                                      "quadratic means, shown for reference (--alike uses them instead)"
                                      if g.open_from is None else
                                      f"gyros 1–{g.open_from} of the model keep their own parameters "
                                      "(gyro k at position k of the layout), every other gyro the "
                                      "all-gyros entries (docs/model-format.md), listed above for "
                                      f"gyros 1–{g.n_levels}; the search is over N = "
                                      f"{', '.join(map(str, space.ns))}; the values above are quadratic "
                                      "means, shown for reference (--alike uses them instead)"),
                        CORRELATION: ("the model's matrices" if g.corr_arw is not None
                                        or g.corr_rrw is not None else "common ρ")},
                       src.get("per_gyro", "model"))),
        "rate_hz": item(space.rate_hz, s.get("rate_hz", "default"), "Hz"),
        "horizon_s": item(space.horizon_s, s.get("horizon_s", "default"), "s"),
        "settle_s": item(space.settle_s, "default", "s (start-up left out of the window metrics)"),
        "n": item(list(space.ns), s.get("ns", "default")),
        "schemes": item(list(space.schemes), "default"),
        "estimators": item(list(space.estimators), s.get("estimators", "default")),
        "failures": item(space.failures, s.get("failures", "default")),
        "motion": item(space.motion_name if space.swing is None else
                       {"swing_amplitude_deg_s": units.rad_s_to_deg_s(space.swing.amplitude_rad_s),
                        "swing_frequency_hz": space.swing.frequency_hz,
                        "about": "each body axis in turn"}, s.get("motion", "default")),
        "bandwidth_hz": item(list(space.bandwidth_hz), s.get("bandwidth_hz", "default"),
                             "searched range (lo = hi: fixed)"),
        "alpha_search": item(f"{space.alpha_points} cone angles per scheme (Scheme 1 in (0, 90], "
                             "Scheme 2 in (0, 180) deg), refined continuously", "default"),
        "objective": item("3-axis RMS of the rate error about the truth over the horizon "
                          "(random-walk drift included), from the analytic predictor", "definition"),
        "biases": item("start at zero (calibrated at switch-on), as the simulator draws them",
                       "assumption"),
        "ignored_effects": item(ignored_effects(g, space), "model"),
        "sensor_bandwidth": item(None if space.sensor_bandwidth is None else
                                 {"cutoff_hz": space.sensor_bandwidth[0], "order": space.sensor_bandwidth[1]},
                                 s.get("sensor_bandwidth", "default"),
                                 "every gyro's own low-pass, cascaded before the estimator (None: none)"),
        G_SENSITIVITY: item(None if space.g_sensitivity_deg_s_per_g is None else
                              list(space.g_sensitivity_deg_s_per_g), s.get(G_SENSITIVITY, "default"),
                              "(deg/s)/g, platform frame, every gyro alike; reported, not ranked"),
    }


# -- the Monte-Carlo check of the top designs ------------------------------------------

def _pick_for_check(designs: list[dict], top: int) -> list[dict]:
    """The first ``top`` designs of the ranking, one per distinct (layout, estimator family),
    plus the best ``naive`` design as the no-model baseline."""
    seen, out = set(), []
    for d in designs:
        # one of each set of designs the predictor says are the same (same layout, same RMS)
        key = (d["scheme"], d["n"], round(d["alpha_deg"], 3), f"{d['rms_3axis_deg_s']:.9g}")
        if key in seen:
            continue
        seen.add(key)
        out.append(d)
        if len(out) == top:
            break
    naive = next((d for d in designs if d["estimator"] == "naive"), None)
    if naive is not None and naive not in out:
        out.append(naive)
    return out


def monte_carlo_check(designs: list[dict], g: GyroNoise, space: DesignSpace, *,
                      replicates: int = 20, seed: int = 20260412, top: int = 4) -> dict:
    """Simulate the top designs with common random numbers and set the runs beside the prediction.

    Every replicate r draws the gyro noise from the same seed for every design
    (paired: gyro k's streams are the same in each layout), through the
    simulator's own effects (:func:`gyroarray.sim.effects.simulate_readings`)
    and the real estimators; the rate truth is the design's motion.

    Returns
    -------
    dict
        ``replicates``, ``seed``, ``designs``: per design its label, the
        predicted and simulated (RMS over the runs, 95 % CI) per axis of
        ``rms_deg_s``, ``std_deg_s``, ``mean_deg_s`` and ``angle_deg``, and
        ``paired``: the recommended design against each other one, the mean
        difference of the runs' 3-axis mean square with its 95 % CI
        (``resolved``: the interval excludes 0).
    """
    if g.open_from is not None:         # the designs' N only: a left-out N is not simulated
        g = g.sized(max(max(space.ns), g.open_from))
    if designs and "worst_case" in designs[0]:
        return check_decision(designs, g, space, replicates=replicates, seed=seed)
    picked = _pick_for_check(designs, top)
    n, dt = space.n_samples, space.dt_s
    k0 = settle_start(n, dt, space.settle_s)
    t = np.arange(n) * dt
    if space.motion is not None:
        truth = np.asarray(space.motion, dtype=float)[:n]
    elif space.swing is not None:
        truth = swing_truth(space.swing, n, dt)
    else:
        truth = np.zeros((n, 3))
    setups = []
    for d in picked:
        rho = d.get("rho", g.rho_arw)
        gr = g.with_rho(rho) if g.rho_arw == g.rho_rrw else g
        layout = Layout.conical(d["scheme"], d["n"], math.radians(d["alpha_deg"]))
        model = _with_sensor(gr.noise_model(d["n"]), space, g_sensitivity=False)
        bw = d["bandwidth_hz"]
        est = get_estimator(d["estimator"])(**_estimator_kwargs(d["estimator"], bw, g)).fit(layout, model, dt)
        setups.append((d, layout, model, est))
    per: list[list[np.ndarray]] = [[] for _ in setups]                                        # runs × (4 metrics × 3 axes)
    for r in range(int(replicates)):
        for j, (d, layout, model, est) in enumerate(setups):
            z = simulate_readings(model, truth, layout, dt, replicate_rng(seed, r), time_s=t)
            e = est.estimate(z) - truth
            w = e[k0:]
            per[j].append(np.stack([np.sqrt(np.mean(w ** 2, axis=0)), np.std(w, axis=0, ddof=1),
                                    np.mean(w, axis=0), dt * e.sum(axis=0)]))
    keys = ("rms_deg_s", "std_deg_s", "mean_deg_s", "angle_deg")
    conv = {"rms_deg_s": units.rad_s_to_deg_s, "std_deg_s": units.rad_s_to_deg_s,
            "mean_deg_s": units.rad_s_to_deg_s, "angle_deg": units.rad_to_deg}
    out_designs = []
    for j, (d, *_rest) in enumerate(setups):
        arr = np.array(per[j])                                        # (R, 4, 3)
        axes: dict[str, Any] = {}
        for a, ax in enumerate(AXES):
            axes[ax] = {}
            for m, key in enumerate(keys):
                mc = rms_ci(conv[key](arr[:, m, a]), gaussian=key in ("mean_deg_s", "angle_deg"))
                pk = "angle_deg_at_horizon" if key == "angle_deg" else key
                p = d["predicted"][ax][pk]
                axes[ax][key] = {"predicted": p, "monte_carlo": mc,
                                 "agrees": bool(mc["ci_low"] <= p <= mc["ci_high"])
                                 if mc["ci_low"] is not None else None}
        tot = rms_ci(units.rad_s_to_deg_s(np.sqrt(np.sum(arr[:, 0, :] ** 2, axis=1))))
        out_designs.append({"label": design_label(d), "rank": d.get("rank"), "scheme": d["scheme"],
                            "n": d["n"], "alpha_deg": d["alpha_deg"], "estimator": d["estimator"],
                            "bandwidth_hz": d["bandwidth_hz"],
                            "rms_3axis_deg_s": {"predicted": d["rms_3axis_deg_s"], "monte_carlo": tot},
                            "axes": axes})
    paired = []
    ms0 = np.sum(np.array(per[0])[:, 0, :] ** 2, axis=1)
    for j in range(1, len(setups)):
        diff = units.rad_s_to_deg_s(1.0) ** 2 * (np.sum(np.array(per[j])[:, 0, :] ** 2, axis=1) - ms0)
        s = mean_ci(diff)
        paired.append({"against": out_designs[j]["label"], "mean_square_difference_deg2_s2": s,
                       "resolved": None if s["ci_low"] is None else bool(s["ci_low"] > 0 or s["ci_high"] < 0)})
    checked = [c for dd in out_designs for ax in dd["axes"].values() for c in ax.values()
               if c["agrees"] is not None]
    return {"replicates": int(replicates), "seed": int(seed), "designs": out_designs,
            "paired": paired, "inside_95": sum(c["agrees"] for c in checked),
            "compared": len(checked)}


# -- the decision under uncertainty: ρ range, failures, mounting sense, fixed weights --------

#: The ranking objectives: 3-axis RMS of the rate error, or the angle error at the horizon.
OBJECTIVES = ("rate", "angle")
#: Estimators whose weights depend on the design ρ (the others are built without it).
RHO_WEIGHTED = ("gls", "kf_array")
#: Largest |M H − I| of fixed weights taken as unbiased [-].
BIAS_TOL = 1e-9
#: Design ρ values tried on the grid before the bounded refinement (min-max).
DESIGN_RHO_POINTS = 3
#: Designs at the top of the decision whose detection (MDB) and error budget are computed
#: (all of them with an MDB limit).
DETAIL_TOP = 12
#: Designs at the top of the screening re-scored exactly (the estimator as built, the full
#: predictor), besides the recommendation, the runner-up and the mounting mirror.
EXACT_TOP = 8


def resolve_objective(space: DesignSpace) -> str:
    """The ranking objective: the space's, else ``angle`` when the user gave a horizon."""
    if space.objective is not None:
        return space.objective
    return "angle" if space.__dict__.get("_sources", {}).get("horizon_s") == "user" else "rate"


def _noise_at(g: GyroNoise, rho: float | None) -> GyroNoise:
    """The gyros at a common correlation ρ (None, or unequal ARW/RRW ρ without a range: as given)."""
    return g if rho is None else g.with_rho(rho)


def fixed_channels(est: str, H: np.ndarray, g_design: GyroNoise, g_true: GyroNoise,
                   dt: float, keep=None) -> _Channels:
    """Per α and axis the channel noise of an estimator built for ``g_design`` and run on
    ``g_true`` (weights fixed at design; variances MᵀC_true M) [SI, per sample].

    Per-gyro noise: ``keep`` names the model's gyros in H's columns (0-based; None: all)."""
    N = H.shape[1]
    if g_true.per_gyro is not None:
        return _fixed_channels_per_gyro(est, H, g_design, g_true, dt, keep)
    s2 = units.arw_deg_rt_h_to_rad_rt_s(g_true.arw_deg_rt_h) ** 2 / dt
    q = units.rrw_deg_h_rt_h_to_rad_s_rt_s(g_true.rrw_deg_h_rt_h) ** 2 * dt
    Rd = s2 * _corr(N, g_design.rho_arw)
    kind = {"kf_array": "gls", "kf_single": "ols"}.get(est, est)
    M = fixed_weights(kind, H, Rd)
    Rt, Qt = s2 * _corr(N, g_true.rho_arw), q * _corr(N, g_true.rho_rrw)
    white = np.einsum("gai,ij,gaj->ga", M, Rt, M)
    walk = np.einsum("gai,ij,gaj->ga", M, Qt, M)
    m2 = np.sum(M * M, axis=2)
    ratio = None
    if est == "kf_array":
        Qd = q * _corr(N, g_design.rho_rrw)
        ratio = np.einsum("gai,ij,gaj->ga", M, Qd, M) / np.einsum("gai,ij,gaj->ga", M, Rd, M)
    ch = _Channels(white, walk, m2 * units.deg_h_to_rad_s(g_true.bi_deg_h) ** 2,
                   m2 * units.deg_h_to_rad_s(g_true.gm_sigma_deg_h) ** 2, ratio, True,
                   bias=np.max(np.abs(np.einsum("gan,gnb->gab", M, H) - np.eye(3)), axis=(1, 2)))
    ch.kf_single_ratio = q / s2                                     # q_b / r of one gyro
    return ch


def _fixed_channels_per_gyro(est: str, H: np.ndarray, g_design: GyroNoise, g_true: GyroNoise,
                             dt: float, keep) -> _Channels:
    """:func:`fixed_channels` with every gyro its own level (and the model's correlation)."""
    N = H.shape[1]
    Rd, Qd = _cov(g_design, N, keep, dt)
    Rt, Qt = _cov(g_true, N, keep, dt)
    _, _, b2, gm2 = _levels(g_true, N, keep, dt)
    kind = {"kf_array": "gls", "kf_single": "ols"}.get(est, est)
    M = fixed_weights(kind, H, Rd)
    white = np.einsum("gai,ij,gaj->ga", M, Rt, M)
    walk = np.einsum("gai,ij,gaj->ga", M, Qt, M)
    ratio = None
    if est == "kf_array":
        ratio = np.einsum("gai,ij,gaj->ga", M, Qd, M) / np.einsum("gai,ij,gaj->ga", M, Rd, M)
    ch = _Channels(white, walk, np.einsum("gai,i->ga", M * M, b2), np.einsum("gai,i->ga", M * M, gm2),
                   ratio, True, bias=np.max(np.abs(np.einsum("gan,gnb->gab", M, H) - np.eye(3)), axis=(1, 2)))
    s2, q, _, _ = _levels(g_true, N, keep, dt)
    ch.kf_single_ratio = float(np.mean(q) / np.mean(s2))             # the typical gyro's q_b / r
    return ch


@lru_cache(maxsize=512)
def _corr(n: int, rho: float) -> np.ndarray:
    """The equicorrelated N×N matrix (cached, read-only)."""
    c = correlation_matrix(n, rho)
    c.setflags(write=False)
    return c


def _scores(ch: _Channels, resp, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Both objectives squared (leading shape of the channels): Σ_axes mean square [rad²/s²]
    and Σ_axes angle² at the horizon [rad²]."""
    m = _combine(ch, slice(None), resp)
    ms, _, sumf2 = _add_motion(m, resp)
    return np.sum(ms, axis=-1), dt ** 2 * np.sum(sumf2, axis=-1)


def _stack(chs: list) -> _Channels:
    """Channels of several conditions stacked on a new leading axis."""
    c0 = chs[0]
    return _Channels(np.stack([c.white for c in chs]), np.stack([c.walk for c in chs]),
                     np.stack([c.flicker for c in chs]), np.stack([c.gm for c in chs]), None, True,
                     c0.kf_single_ratio)


@dataclass
class _Cand:
    """One candidate design of the decision search."""

    scheme: int
    n: int
    est: str
    signs: np.ndarray
    alpha_rad: float
    bw: float | None
    rho_d: float | None
    J: float


class _Decider:
    """Scores designs over ρ ∈ [lo, hi] × every set of k failed gyros with fixed weights."""

    def __init__(self, g: GyroNoise, space: DesignSpace, lo: float, hi: float, objective: str):
        self.g, self.space, self.lo, self.hi, self.objective = g, space, lo, hi, objective
        # a model's own correlation matrices stay unless a range (or --rho) replaces them
        self.ranged = hi > lo or (g.rho_arw == g.rho_rrw and g.corr_arw is None and g.corr_rrw is None)
        self.bank = _bank(space, g)
        self.dt = space.dt_s
        self._conds: dict = {}

    def cond(self, rho):
        key = None if not self.ranged else float(rho)
        if key not in self._conds:
            self._conds[key] = _noise_at(self.g, key)
        return self._conds[key]

    def ends(self):
        return [self.lo] if self.hi <= self.lo else [self.lo, self.hi]

    def channels(self, est, H, keep, rho_d, rho_t):
        gd = self.cond(self.lo if rho_d is None else rho_d)
        return fixed_channels(est, H[:, list(keep)], gd, self.cond(rho_t), self.dt, keep=list(keep))

    def resp(self, est, bw, ch):
        return _responses(self.bank, est, bw, ch, idx=0)

    def conditions(self, est, H, rho_d, *, with_combos: bool = False):
        """The filter's design channels (intact array at the design ρ) and the channels of every
        (kept set, end of the range) stacked on a leading axis (fixed weights: each variance is
        linear in ρ, so the worst ρ is an end); ``with_combos``: also the (kept set, ρ) of each."""
        G, n = H.shape[:2]
        keeps = kept_sets(n, self.space.failures)
        design = self.channels(est, H, keeps[0], rho_d, rho_d if rho_d is not None else self.lo)
        gd = self.cond(self.lo if rho_d is None else rho_d)
        if self.g.per_gyro is not None:          # each kept set has its own gyros' noise
            chs, combos = [], []
            for keep in keeps:
                for rt in self.ends():
                    chs.append(fixed_channels(est, H[:, list(keep)], gd, self.cond(rt), self.dt,
                                              keep=list(keep)))
                    combos.append((keep, rt))
            s_white, s_walk, s_flicker, s_gm = (np.stack([getattr(c, f) for c in chs])
                                                for f in ("white", "walk", "flicker", "gm"))
            stacked = _Channels(s_white, s_walk, s_flicker, s_gm, None, True, design.kf_single_ratio,
                                bias=np.stack([cast(np.ndarray, c.bias) for c in chs]))  # fixed weights set bias
            return (design, stacked, combos) if with_combos else (design, stacked)
        parts, combos = [], []
        for rt in self.ends():
            ch = fixed_channels(est, H, gd, self.cond(rt), self.dt)
            parts.append(ch)
            combos.append((keeps[0], rt))
        if len(keeps) > 1:                       # every failed set at once: (K·G, N − k, 3)
            Hk = np.concatenate([H[:, list(k)] for k in keeps[1:]], axis=0)
            for rt in self.ends():
                ch = fixed_channels(est, Hk, gd, self.cond(rt), self.dt)
                K = len(keeps) - 1
                k_white, k_walk, k_flicker, k_gm = (a.reshape(K, G, 3)
                                                    for a in (ch.white, ch.walk, ch.flicker, ch.gm))
                parts.append(_Channels(k_white, k_walk, k_flicker, k_gm, None, True, ch.kf_single_ratio,
                                       bias=cast(np.ndarray, ch.bias).reshape(K, G)))   # fixed weights set bias
                combos += [(k, rt) for k in keeps[1:]]
        arr = [np.concatenate([p_.__dict__[f][None] if p_.white.ndim == 2 else p_.__dict__[f]
                               for p_ in parts]) for f in ("white", "walk", "flicker", "gm")]
        bias = np.concatenate([cast(np.ndarray, p_.bias)[None] if p_.white.ndim == 2 else cast(np.ndarray, p_.bias)
                               for p_ in parts])
        a_white, a_walk, a_flicker, a_gm = arr
        stacked = _Channels(a_white, a_walk, a_flicker, a_gm, None, True, design.kf_single_ratio, bias=bias)
        return (design, stacked, combos) if with_combos else (design, stacked)

    def worst_pair(self, est, bw, design: _Channels, stacked: _Channels) -> tuple[np.ndarray, np.ndarray]:
        """Worst rate and angle objectives (G,) (squared) over the stacked conditions."""
        resp = self.resp(est, bw, design)
        if any(r is None for r in resp):
            inf = np.full(design.white.shape[0], np.inf)
            return inf, inf
        jr, ja = _scores(stacked, resp, self.dt)
        # weights that do not reproduce the motion (naive after a failure: HᵀH not diagonal)
        # leave a motion error the channel model does not hold: not a design that survives
        ok = np.isfinite(jr) & np.isfinite(ja) & (cast(np.ndarray, stacked.bias) <= BIAS_TOL)   # fixed weights
        jr, ja = np.where(ok, jr, np.inf), np.where(ok, ja, np.inf)
        return np.max(jr, axis=0), np.max(ja, axis=0)

    def worst(self, est, H, rho_d, bw) -> np.ndarray:
        """The objective's worst value (G,) (squared) over ρ's ends × kept sets."""
        jr, ja = self.worst_pair(est, bw, *self.conditions(est, H, rho_d))
        return jr if self.objective == "rate" else ja


def _alive(H: np.ndarray, failures: int) -> np.ndarray:
    """Layouts (G,) that keep a 3-axis rate intact and after every set of failed gyros."""
    ok = np.ones(H.shape[0], bool)
    for keep in kept_sets(H.shape[1], failures):
        ok &= np.isfinite(gdop_batch(H[:, list(keep)], np.eye(len(keep))))
    return ok


def _rho_grid(dec: _Decider, est: str) -> list:
    if est not in RHO_WEIGHTED or not dec.ranged:
        return [None]
    if dec.space.design_rho is not None:
        return [float(dec.space.design_rho)]
    if dec.hi <= dec.lo:
        return [dec.lo]
    return [float(r) for r in np.linspace(dec.lo, dec.hi, DESIGN_RHO_POINTS)]


def _grid_best(dec: _Decider, scheme: int, n: int, est: str) -> tuple[_Cand | None, np.ndarray]:
    """Best (pattern, α, bandwidth, design ρ) of one scheme, N, estimator on the grids."""
    space = dec.space
    alphas = _alpha_grid(scheme, space.alpha_points)
    best = None
    for signs in mounting_patterns(scheme, n):
        H = mounted_axes(scheme, n, alphas, signs)
        alive = _alive(H, space.failures)
        if not alive.any():
            continue
        Ha, al = H[alive], alphas[alive]
        for rd in _rho_grid(dec, est):
            design, stacked = dec.conditions(est, Ha, rd)
            # per α: the bandwidth that minimises the rate objective (a unit-DC-gain filter's
            # bandwidth barely moves the angle: ranked on angle alone the narrowest filter would
            # win and give up tracking the motion); the objective at that bandwidth
            bj = np.full(al.size, np.inf)
            bobj = np.full(al.size, np.inf)
            bbw: list = [None] * al.size
            for bw in _bandwidths(space, est):
                jr, ja = dec.worst_pair(est, bw, design, stacked)
                better = jr < bj
                bj = np.where(better, jr, bj)
                bobj = np.where(better, jr if dec.objective == "rate" else ja, bobj)
                for i in np.flatnonzero(better):
                    bbw[i] = bw
            k = int(np.argmin(bobj))
            if not np.isfinite(bobj[k]):
                continue
            k = int(np.flatnonzero(bobj <= bobj[k] * (1.0 + 1e-9))[0])     # ties: the smaller α
            if best is None or bobj[k] < best.J * (1.0 - 1e-9):            # ties: the first pattern
                best = _Cand(scheme, n, est, signs, float(al[k]), bbw[k], rd, float(bobj[k]))
    return best, alphas


def _refine(dec: _Decider, c: _Cand, alphas: np.ndarray, bandwidth: bool) -> _Cand:
    """Bounded Brent in α between the grid neighbours, then in the design ρ over the range,
    then (``bandwidth``) in log bandwidth between the grid neighbours."""
    def J(alpha, rd, bw, which=None):
        H = mounted_axes(c.scheme, c.n, np.array([alpha]), c.signs)
        if not _alive(H, dec.space.failures)[0]:
            return math.inf
        jr, ja = dec.worst_pair(c.est, bw, *dec.conditions(c.est, H, rd))
        return float((jr if (which or dec.objective) == "rate" else ja)[0])
    k = int(np.argmin(np.abs(alphas - c.alpha_rad)))
    lo = alphas[k - 1] if k > 0 else alphas[k] * 0.5
    hi = alphas[k + 1] if k + 1 < alphas.size else alphas[k]
    if hi > lo:
        res = minimize_scalar(lambda a: J(a, c.rho_d, c.bw), bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-7})
        if res.fun < c.J:
            c = replace(c, alpha_rad=float(res.x), J=float(res.fun))
    if c.rho_d is not None and dec.space.design_rho is None and dec.hi > dec.lo:
        res = minimize_scalar(lambda r: J(c.alpha_rad, r, c.bw), bounds=(dec.lo, dec.hi),
                              method="bounded", options={"xatol": 1e-6})
        if res.fun < c.J:
            c = replace(c, rho_d=float(res.x), J=float(res.fun))
    if bandwidth and c.bw is not None and dec.space.bandwidth_hz[0] != dec.space.bandwidth_hz[1]:
        grid = [f for f in _bandwidths(dec.space, c.est) if f is not None]
        k = int(np.argmin(np.abs(np.log(np.array(grid) / c.bw))))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        if b > a:                                   # the bandwidth: by the rate objective
            res = minimize_scalar(lambda lb: J(c.alpha_rad, c.rho_d, float(round(math.exp(lb), 3)), "rate"),
                                  bounds=(math.log(a), math.log(b)), method="bounded",
                                  options={"xatol": 1e-3})
            if res.fun < J(c.alpha_rad, c.rho_d, c.bw, "rate"):
                bw = float(round(math.exp(res.x), 3))
                c = replace(c, bw=bw, J=J(c.alpha_rad, c.rho_d, bw))
    return c


def _case(dec: _Decider, c: _Cand, H: np.ndarray, keep, rho_t: float, rho_d) -> dict:
    """Per axis and 3-axis: RMS rate error and angle error of one (kept set, true ρ)."""
    ch = dec.channels(c.est, H, keep, rho_d, rho_t)
    resp = dec.resp(c.est, c.bw, dec.channels(c.est, H, tuple(range(c.n)), rho_d,
                                               rho_d if rho_d is not None else dec.lo))
    m = _combine(ch, slice(None), resp)
    ms, sumw2, sumf2 = _add_motion(m, resp)
    to = units.rad_s_to_deg_s
    ang = units.rad_to_deg(dec.dt * np.sqrt(sumf2[0]))
    n = dec.space.n_samples
    nw = n - settle_start(n, dec.dt, dec.space.settle_s)
    mean2 = sumw2[0] / nw ** 2
    std = np.sqrt(np.maximum(nw / (nw - 1.0) * (ms[0] - mean2), 0.0))
    return {"rho": float(rho_t), "failed_gyros": [k + 1 for k in range(c.n) if k not in keep],
            "rms_3axis_deg_s": float(to(math.sqrt(np.sum(ms[0])))),
            "angle_deg": float(math.sqrt(np.sum(ang ** 2))),
            "per_axis": {ax: {"rms_deg_s": float(to(math.sqrt(ms[0, a]))),
                              "std_deg_s": float(to(std[a])), "mean_deg_s": float(to(math.sqrt(mean2[a]))),
                              "angle_deg": float(ang[a])} for a, ax in enumerate(AXES)},
            "_moments": (m, ms, sumw2, sumf2, ch, resp)}


def _worst_case(dec: _Decider, c: _Cand, H: np.ndarray, *, oracle: bool = False) -> dict:
    """The worst (true ρ, failed set) of a design, ρ found continuously for each kept set.

    ``oracle``: weights (and filter) follow the true ρ instead of the design ρ."""
    key = "rms_3axis_deg_s" if dec.objective == "rate" else "angle_deg"

    def rd(r):
        return (r if oracle else c.rho_d) if c.rho_d is not None else None
    # every kept set at the range's ends, then a continuous search in ρ on the worst set(s)
    # (fixed weights: linear in ρ, the search confirms an end; oracle: the worst may lie inside)
    ends = {keep: max(_case(dec, c, H, keep, r, rd(r))[key] for r in dec.ends())
            for keep in kept_sets(c.n, dec.space.failures)}
    top = sorted(ends, key=lambda k: -ends[k])[:2 if oracle else 1]
    worst = None
    for keep in top:
        # cast: mypy cannot infer a lambda whose default argument binds the loop's kept set
        v, r = worst_over_interval(cast("Callable[[float], float]",
                                        lambda rt, keep=keep: _case(dec, c, H, keep, rt, rd(rt))[key]),
                                   dec.lo, dec.hi, xatol=1e-6)
        if worst is None or v > worst[0]:
            worst = (v, r, keep)
    _, r, keep = cast(tuple, worst)                     # set: top holds at least one kept set
    return _case(dec, c, H, keep, r, rd(r))


def screening_is_exact(est: str, g: GyroNoise) -> bool:
    """Whether the screening's channel model is the estimator itself (then re-scoring changes
    nothing): per-sample weights with their low-pass always; ``kf_single`` on alike gyros (the
    same filter on every gyro commutes with the least-squares combination); never ``kf_array``
    (after a failure or with reversed gyros its bias states couple the axes)."""
    if est == "kf_array":
        return False
    return not (est == "kf_single" and g.per_gyro is not None)


def _prediction_case(p, keep, n: int, rho_t: float) -> dict:
    """A :func:`_case`-shaped dict from a full :class:`~gyroarray.design.predict.Prediction`."""
    ax = p.axes
    return {"rho": float(rho_t), "failed_gyros": [k + 1 for k in range(n) if k not in keep],
            "rms_3axis_deg_s": float(math.sqrt(sum(ax[a]["rms_deg_s"] ** 2 for a in AXES))),
            "angle_deg": float(math.sqrt(sum(ax[a]["angle_deg"] ** 2 for a in AXES))),
            "per_axis": {a: {k: float(ax[a][k]) for k in ("rms_deg_s", "std_deg_s", "mean_deg_s", "angle_deg")}
                         for a in AXES}}


def exact_predictions(dec: _Decider, c: _Cand, H: np.ndarray, extra_rhos=()) -> dict:
    """Every (kept set, true ρ at an end of the range) of a design predicted exactly.

    The estimator is built as the Monte-Carlo check builds it: the registry's estimator with
    :func:`estimator_kwargs`, fitted once per kept set for the design ρ on the gyros left
    (weights and filter recomputed on the remaining geometry); its linear system is then
    predicted (:func:`gyroarray.design.predict.predict`) with the noise of the true ρ on
    those gyros. With the estimator fixed, every error variance is linear in the true noise
    covariance, hence in ρ: the worst ρ of each kept set is an end of the range.

    Parameters
    ----------
    dec : _Decider
    c : _Cand
    H : ndarray (1, N, 3)
        The mounted axes [-].
    extra_rhos : sequence of float
        Further true ρ for the intact array (the typical case).

    Returns
    -------
    dict
        (kept set, ρ) -> Prediction.
    """
    space = dec.space
    motion = None if space.motion is None else np.asarray(space.motion, dtype=float)[:space.n_samples]
    gd = dec.cond(dec.lo if c.rho_d is None else c.rho_d)
    out = {}
    for keep in kept_sets(c.n, space.failures):
        Hk = H[0, list(keep)]
        est = get_estimator(c.est)(**_estimator_kwargs(c.est, c.bw, dec.g)).fit(
            Layout(Hk), _with_sensor(gd.noise_model(len(keep), keep), space, g_sensitivity=False), dec.dt)
        rts = list(dec.ends()) + (list(extra_rhos) if len(keep) == c.n else [])
        for rt in rts:
            if (keep, float(rt)) in out:
                continue
            model = _with_sensor(dec.cond(rt).noise_model(len(keep), keep), space, g_sensitivity=False)
            out[(keep, float(rt))] = predict(est, model, n_samples=space.n_samples, settle_s=space.settle_s,
                                             truth_rad_s=motion, swing=None if motion is not None else space.swing)
    return out


def rescore_exact(d: dict, dec: _Decider) -> None:
    """Replace a screened design's scores by the exact ones (:func:`exact_predictions`).

    ``worst_case`` (worst over the kept sets × the range's ends, by the objective),
    ``typical``, ``predicted`` / ``rms_3axis_deg_s`` / ``rho`` (the intact array at its worst
    end of the range), ``worst_rms_3axis_deg_s`` and ``rms_by_rho`` (linear in ρ between the
    ends, exact for a fixed estimator) are recomputed; ``scored`` says how. Designs whose
    screening is already exact (:func:`screening_is_exact`) are only marked.
    """
    c = d["_cand"]
    if screening_is_exact(c.est, dec.g):
        d["scored"] = "exact (the screening's channel model is this estimator)"
        return
    H = mounted_axes(c.scheme, c.n, np.array([c.alpha_rad]), c.signs)
    rho_typ = _nominal_rho(dec, c)
    preds = exact_predictions(dec, c, H, extra_rhos=(rho_typ,))
    key = "rms_3axis_deg_s" if dec.objective == "rate" else "angle_deg"
    cases = {k: _prediction_case(p, k[0], c.n, k[1]) for k, p in preds.items()}
    ends = [k for k in cases if k[1] in dec.ends()]
    wk = max(ends, key=lambda k: cases[k][key])
    full = tuple(range(c.n))
    ik = max((k for k in ends if k[0] == full), key=lambda k: cases[k][key])
    p = preds[ik]
    pred = {}
    for a in AXES:
        v = p.axes[a]
        pred[a] = {"rms_deg_s": v["rms_deg_s"], "std_deg_s": v["std_deg_s"], "mean_deg_s": v["mean_deg_s"],
                   "angle_deg_at_horizon": v["angle_deg"], "arw_long_deg_rt_h": v["arw_long_deg_rt_h"],
                   "rrw_long_deg_h_rt_h": v["rrw_long_deg_h_rt_h"], "dc_gain": v["dc_gain"],
                   **{k: v.get(k) for k in _SPLIT_KEYS}}
    d.update({"rho": ik[1], "rms_3axis_deg_s": cases[ik]["rms_3axis_deg_s"], "predicted": pred,
              "predicted_at": _predicted_at(ik[1], dec),
              "worst_case": cases[wk], "worst_rms_3axis_deg_s": cases[wk]["rms_3axis_deg_s"],
              "typical": {**cases[(full, float(rho_typ))], "failed_gyros": []}})
    if "rms_by_rho" in d and dec.hi > dec.lo:
        ms_lo = cases[(full, float(dec.lo))]["rms_3axis_deg_s"] ** 2
        ms_hi = cases[(full, float(dec.hi))]["rms_3axis_deg_s"] ** 2
        d["rms_by_rho"] = {r: math.sqrt(ms_lo + (float(r) - dec.lo) / (dec.hi - dec.lo) * (ms_hi - ms_lo))
                           for r in d["rms_by_rho"]}
    d["scored"] = ("exact: the estimator as built for the design ρ on the gyros left after each failure, "
                   "predicted by the full predictor at both ends of the ρ range (a fixed estimator's "
                   "error variance is linear in ρ)")


def _nominal_rho(dec: _Decider, c: _Cand) -> float:
    """The typical condition: the design ρ, else (ρ-free estimators) ρ = 0 if in range, else the
    range's middle."""
    if c.rho_d is not None:
        return c.rho_d
    return 0.0 if dec.lo <= 0.0 <= dec.hi else 0.5 * (dec.lo + dec.hi)


def _mdb(H: np.ndarray, dec: _Decider) -> dict:
    """Minimum detectable bias step per gyro [deg/s], worst over the ρ range's ends, from the
    parity detector (:func:`gyroarray.estimators.fdi.minimum_detectable`)."""
    cache = dec.space.__dict__.setdefault("_mdb_cache", {})
    key = (np.round(H, 9).tobytes(), dec.lo, dec.hi, dec.space.far_per_h, dec.space.p_md)
    if key not in cache:
        per = np.zeros(H.shape[0])
        for r in dec.ends():
            model = dec.cond(r).noise_model(H.shape[0])
            m = minimum_detectable(Layout(H), model, dec.space.far_per_h, dec.space.p_md,
                                   dt_s=dec.dt)
            per = np.maximum(per, units.rad_s_to_deg_s(np.asarray(m["step_rad_s"], dtype=float)))
        cache[key] = per
    per = cache[key]
    return {"mdb_deg_s": float(np.max(per)), "mdb_per_gyro_deg_s": [float(v) for v in per],
            "mdb_worst_gyro": int(np.argmax(per)) + 1, "far_per_h": dec.space.far_per_h,
            "p_md": dec.space.p_md}


def _error_budget(d: dict, dec: _Decider, c: _Cand, H: np.ndarray) -> dict:
    """The error budget of a design at its worst case: per term, RMS [deg/s] and angle [deg].

    SINGLE CALL SITE for :func:`gyroarray.design.budget.error_budget` (another module's;
    used when it exists), else the predictor's own noise terms of the fast path."""
    wc = d["worst_case"]
    keep = tuple(k for k in range(c.n) if k + 1 not in wc["failed_gyros"])
    budget_mod: ModuleType | None
    try:
        from gyroarray.design import budget as budget_mod  # lazy: optional module, being added
    except ImportError:
        budget_mod = None
    if budget_mod is not None and hasattr(budget_mod, "error_budget"):
        Hk = H[0, list(keep)]
        gd = dec.cond(c.rho_d if c.rho_d is not None else wc["rho"])
        est = get_estimator(c.est)(**_estimator_kwargs(c.est, c.bw, dec.g)).fit(
            Layout(Hk), gd.noise_model(len(keep), keep), dec.dt)
        motion = dec.space.swing if dec.space.swing is not None else (
            None if dec.space.motion is None else np.asarray(dec.space.motion)[:dec.space.n_samples])
        b = budget_mod.error_budget(est.linear_system(), Hk,
                                    _with_sensor(_budget_model(dec.cond(wc["rho"]), keep), dec.space),
                                    n_samples=dec.space.n_samples, dt_s=dec.dt,
                                    settle_s=dec.space.settle_s, motion=motion)
        return {"at": {"rho": wc["rho"], "failed_gyros": wc["failed_gyros"]}, **b.to_dict(),
                "ignored_effects": ignored_effects(dec.g, dec.space, b.ignored)}
    m, _, _, _, ch, resp = _case(dec, c, H, keep, wc["rho"], c.rho_d)["_moments"]
    terms = {}
    for name, level, field_ in (("white", ch.white, "white"), ("rate_random_walk", ch.walk, "walk"),
                                (BIAS_INSTABILITY, ch.flicker, "flicker"),
                                (GAUSS_MARKOV, ch.gm, GAUSS_MARKOV)):
        ms = sum(level[0, a] * getattr(resp[a], field_)[0] for a in range(3))
        sf = sum(level[0, a] * getattr(resp[a], field_)[2] for a in range(3))
        if ms > 0:
            terms[name] = {"rms_deg_s": float(units.rad_s_to_deg_s(math.sqrt(ms))),
                           "angle_deg": float(units.rad_to_deg(dec.dt * math.sqrt(sf)))}
    if resp[0].motion is not None:
        ms = sum(resp[a].motion[0][a] for a in range(3))
        sf = sum(resp[a].motion[2][a] ** 2 for a in range(3))
        terms["motion_tracking"] = {"rms_deg_s": float(units.rad_s_to_deg_s(math.sqrt(ms))),
                                    "angle_deg": float(units.rad_to_deg(dec.dt * math.sqrt(sf)))}
    return {"at": {"rho": wc["rho"], "failed_gyros": wc["failed_gyros"]}, "terms": terms,
            "ignored_effects": ignored_effects(dec.g, dec.space),
            "source": "fast-path noise terms (gyroarray.design.budget not available)"}


def _budget_model(g: GyroNoise, keep):
    """The model the error budget reads for the kept gyros: the user's own model (every effect,
    a plugin's included, its per-gyro entries renumbered to the kept gyros) with the
    condition's correlation in place of the model's; the typical gyro's model for alike gyros."""
    keep = list(keep)
    if g.model is None or g.per_gyro is None:
        return g.noise_model(len(keep), keep)
    from gyroarray.effects.terms import CorrelationTerm  # lazy: with the registry
    corr = {eff.name for eff, t in model_terms(g.model, cast(int, g.n_levels)) if isinstance(t, CorrelationTerm)}
    own = g.noise_model(len(keep), keep)
    own_corr = [e for e in own.entries if e.gyro is None]               # the condition's correlation
    pos = {k + 1: j + 1 for j, k in enumerate(keep)}
    entries = []
    for e in g.model.entries:
        if e.effect in corr:
            continue
        if e.gyro is None:
            entries.append(e)
        elif e.gyro in pos:
            entries.append(ModelEntry(e.effect, pos[e.gyro], dict(e.params), dict(e.sigma)))
    model = NoiseModel(tuple(entries) + tuple(own_corr), description=g.model.description)
    model.check(len(keep))
    return model


def _strip(case: dict) -> dict:
    return {k: v for k, v in case.items() if not k.startswith("_")}


def _predicted_at(rho: float, dec: _Decider) -> dict:
    """Where a design's ``predicted``, ``rms_3axis_deg_s`` and ``rho`` are: the intact array at
    the true ρ where its objective is worst over the range (weights for the design ρ)."""
    return {"rho": float(rho), "failed_gyros": [],
            "what": (f"the intact array at the true ρ = {rho:.4g} where its {dec.objective} objective is "
                     f"worst over ρ in [{dec.lo:g}, {dec.hi:g}] (the estimator built for the design ρ); "
                     "the worst case over failures is `worst_case`")}


def _decision_dict(dec: _Decider, c: _Cand, rhos_shown) -> dict:
    """Every field of one design of the decision (JSON units)."""
    space, g = dec.space, dec.g
    H = mounted_axes(c.scheme, c.n, np.array([c.alpha_rad]), c.signs)
    wc = _worst_case(dec, c, H)
    rho_typ = _nominal_rho(dec, c)
    typ = _case(dec, c, H, tuple(range(c.n)), rho_typ, c.rho_d)
    # the intact array at its worst ρ: the per-axis prediction (the old `predicted`)
    key = "rms_3axis_deg_s" if dec.objective == "rate" else "angle_deg"
    _, r_int = worst_over_interval(lambda r: _case(dec, c, H, tuple(range(c.n)), r, c.rho_d)[key],
                                   dec.lo, dec.hi)
    intact = _case(dec, c, H, tuple(range(c.n)), r_int, c.rho_d)
    m, ms, sumw2, sumf2, ch, resp = intact["_moments"]
    n, dt = space.n_samples, space.dt_s
    nw = n - settle_start(n, dt, space.settle_s)
    mean2 = sumw2[0] / nw ** 2
    var = nw / (nw - 1.0) * (ms[0] - mean2)
    to = units.rad_s_to_deg_s
    pred = {}
    for a, ax in enumerate(AXES):
        r = resp[a]
        pred[ax] = {"rms_deg_s": float(to(math.sqrt(ms[0, a]))),
                    "std_deg_s": float(to(math.sqrt(max(var[a], 0.0)))),
                    "mean_deg_s": float(to(math.sqrt(mean2[a]))),
                    "angle_deg_at_horizon": float(units.rad_to_deg(dt * math.sqrt(sumf2[0, a]))),
                    "arw_long_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(
                        abs(r.dc_gain) * math.sqrt(ch.white[0, a] * dt))),
                    "rrw_long_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(
                        abs(r.dc_gain) * math.sqrt(ch.walk[0, a] / dt))),
                    "dc_gain": r.dc_gain, **_split(r)}
    Hm = H[0]
    gd_rho, gd_r = worst_gdop_over_rho(Hm, dec.lo, dec.hi, 0)
    ft = fault_tolerance(Layout(Hm), rho_typ if dec.ranged else g.rho_arw)
    if space.failures:
        wg, _ = worst_gdop_over_rho(Hm, dec.lo, dec.hi, space.failures)
    else:
        wg = gd_rho
    kind = {"kf_array": "gls", "kf_single": "ols"}.get(c.est, c.est)
    gdes = dec.cond(c.rho_d if c.rho_d is not None else rho_typ)
    dcg = np.array([r.dc_gain for r in resp])
    gs = _g_sensitivity(space, dcg[:, None] * fixed_weights(kind, H, _r_matrix(c.n, gdes, dt))[0])
    d: dict[str, Any] = {
        "scheme": c.scheme, "n": c.n, "alpha_deg": float(np.degrees(c.alpha_rad)),
        "estimator": c.est, "bandwidth_hz": c.bw, "rho": r_int,
        "rms_3axis_deg_s": intact["rms_3axis_deg_s"], "predicted": pred,
        "predicted_at": _predicted_at(r_int, dec),
        "gdop": gd_rho,
        **gs, "worst_gdop_after_failures": wg, "fault_tolerance": json.loads(json.dumps(ft)),
        "axes": [[float(v) for v in row] for row in Hm],
        "mounting_signs": [int(s) for s in c.signs],
        "mounting": mounting_words(c.scheme, c.n, c.signs, float(np.degrees(c.alpha_rad))),
        "design_rho": c.rho_d, "objective": dec.objective,
        "rho_range": [dec.lo, dec.hi],
        "worst_case": _strip(wc), "typical": {**_strip(typ), "failed_gyros": []},
        "worst_rms_3axis_deg_s": wc["rms_3axis_deg_s"],
    }
    if c.rho_d is None and not dec.ranged and c.est in RHO_WEIGHTED:
        d["design_rho_note"] = (f"{c.est} is built for the model's own correlation matrices (no ρ range "
                                "given)")
    elif c.rho_d is None:
        d["design_rho_note"] = (f"{c.est} is built without ρ (its weights do not use the correlation); "
                                f"typical case at ρ = {rho_typ:g}")
    if c.est in RHO_WEIGHTED and dec.hi > dec.lo:
        d["oracle_worst_case"] = {**_strip(_worst_case(dec, c, H, oracle=True)),
                                  "note": "oracle: weights built for the true ρ (no real array knows it)"}
    if rhos_shown:
        d["rms_by_rho"] = {f"{r:g}": _case(dec, c, H, tuple(range(c.n)), r, c.rho_d)["rms_3axis_deg_s"]
                           for r in rhos_shown if dec.lo <= r <= dec.hi}
    d["_cand"] = c
    return d


def _add_details(d: dict, dec: _Decider) -> None:
    """The minimum detectable bias (failures >= 1) and the error budget of one design."""
    c = d.pop("_cand")
    H = mounted_axes(c.scheme, c.n, np.array([c.alpha_rad]), c.signs)
    if dec.space.failures:
        d.update(_mdb(H[0], dec))
    d["error_budget"] = _error_budget(d, dec, c, H)


def _rank_decision(designs: list[dict], objective: str, mdb_max: float | None) -> list[dict]:
    """Best worst case first; designs within 1 % of a group's first worst case are ranked by
    their typical case (and marked ``tie``); designs above ``mdb_max`` go last, ``excluded``."""
    key = "rms_3axis_deg_s" if objective == "rate" else "angle_deg"

    def w(d):
        v = d["worst_case"][key]
        return v if math.isfinite(v) else math.inf
    for d in designs:
        d.pop("tie", None)
    ok = [d for d in designs if mdb_max is None or (d.get("mdb_deg_s") or 0.0) <= mdb_max]
    bad = [d for d in designs if d not in ok]
    for d in bad:
        d["excluded"] = (f"minimum detectable bias {d['mdb_deg_s']:.4g} deg/s above --mdb-max "
                         f"{mdb_max:g} deg/s")
    out = []
    for part in (ok, bad):
        rest = sorted(part, key=w)
        i = 0
        while i < len(rest):
            j = i + 1
            while j < len(rest) and w(rest[j]) <= w(rest[i]) * (1.0 + EQUIVALENT_SHARE):
                j += 1
            grp = sorted(rest[i:j], key=lambda d: (d["typical"][key], w(d)))
            if len(grp) > 1:
                for d in grp:
                    d["tie"] = (f"worst case within {100 * EQUIVALENT_SHARE:g} % of "
                                f"{len(grp) - 1} other design(s): ranked by the typical case")
            out += grp
            i = j
    for k, d in enumerate(out):
        d["rank"] = k + 1
    return out


def decide(g: GyroNoise, space: DesignSpace, rho_lo: float, rho_hi: float, *,
           rhos_shown=None) -> tuple[list[dict], list[str]]:
    """Every scheme × N × estimator at its best mounting sense, cone angle, bandwidth and design
    ρ, scored by its worst case over ρ ∈ [lo, hi] × every set of k failed gyros with weights
    fixed at the design ρ; ranked (best worst case first).

    Parameters
    ----------
    g : GyroNoise
    space : DesignSpace
        ``failures`` (k), ``design_rho`` (None: min-max over the range),
        ``objective`` (None: :func:`resolve_objective`), ``mdb_max``.
    rho_lo, rho_hi : float
        The range of the gyros' common correlation [-] (lo == hi: one ρ).
    rhos_shown : sequence of float, optional
        ρ values at which ``rms_by_rho`` is reported.

    Returns
    -------
    (designs, notes)
    """
    objective = resolve_objective(space)
    if objective not in OBJECTIVES:
        raise InputError(f"the objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    g, space = sized_for(g, space)
    dec = _Decider(g, space, rho_lo, rho_hi, objective)
    notes = []
    cands = []
    for scheme in space.schemes:
        for n in space.ns:
            if n - space.failures < 3:
                notes.append(f"N = {n}: {space.failures} failed gyro(s) leave {n - space.failures}, "
                             "fewer than the 3 a 3-axis rate needs (N − failures must be ≥ 3); "
                             "left out")
                continue
            floor = -1.0 / (n - space.failures - 1) if n - space.failures > 1 else 0.0
            if dec.ranged and rho_lo <= floor:
                notes.append(f"scheme {scheme}, N = {n}: rho = {rho_lo:g} is not a correlation "
                             f"{n - space.failures} gyros can have (below {floor:.4g}); left out")
                continue
            for est in space.estimators:
                best, alphas = _grid_best(dec, scheme, n, est)
                if best is None:
                    notes.append(f"scheme {scheme}, N = {n}, {est}: no cone angle keeps an unbiased "
                                 f"3-axis rate after {space.failures} failed gyro(s) (naive: its per-axis "
                                 "projection is biased once HᵀH is not diagonal), or no bandwidth is "
                                 "reachable; left out")
                    continue
                cands.append((best, alphas))
    cands.sort(key=lambda t: t[0].J)
    if not cands:                       # nothing survives: recommend() refuses, with these notes
        return [], notes
    refined = [_refine(dec, c, a, bandwidth=i < REFINE_TOP) for i, (c, a) in enumerate(cands)]
    designs = _rank_decision([_decision_dict(dec, c, rhos_shown) for c in refined], objective, None)
    # the screening is approximate for the array KF: the top designs, then the recommendation
    # and the runner-up until both are exact, are re-scored with the estimator as built
    for d in designs[:EXACT_TOP]:
        rescore_exact(d, dec)
    while True:
        designs = _rank_decision(designs, objective, None)
        rec = designs[0]
        other = [d for d in designs[1:] if (d["scheme"], d["n"]) != (rec["scheme"], rec["n"])]
        todo = [d for d in [rec] + other[:1] if "scored" not in d]
        if not todo:
            break
        for d in todo:
            rescore_exact(d, dec)
    for d in designs:
        if "scored" not in d:
            d["scored"] = ("exact (the screening's channel model is this estimator)"
                           if screening_is_exact(d["estimator"], g) else
                           f"screening only (below the first {EXACT_TOP}): the single-input filter on "
                           "the fixed-weight least-squares channel")
    top = designs if space.mdb_max is not None else designs[:DETAIL_TOP]
    for d in top:
        _add_details(d, dec)
    for d in designs[len(top):]:
        d.pop("_cand")
        d["details_note"] = (f"detection (MDB) and error budget computed for the first {DETAIL_TOP} "
                             "designs only")
        if space.failures:
            d["mdb_deg_s"] = None
        d["error_budget"] = None
    if g.per_gyro is not None and g.open_from is not None:
        notes.append(f"the model's gyros 1–{g.open_from} keep their own noise (gyro k at position k), "
                     "every other gyro the model's all-gyros entries; the search is over the layouts "
                     f"with N = {', '.join(map(str, space.ns))} (--alike: one typical gyro)")
    elif g.per_gyro is not None:
        notes.append(f"the model's {g.n_gyros} gyros keep their own noise (gyro k at position k); the "
                     f"search is over the layouts with N = {g.n_gyros} (--alike: one typical gyro, any N)")
        if {"kf_array", "kf_single"} & set(space.estimators):
            notes.append("kf_array and kf_single on gyros with unequal noise are screened as the single-input "
                         "filter on the fixed-weight least-squares channel, designed for the typical "
                         f"gyro's q_b/r (each gyro's own filter differs); the first {EXACT_TOP} designs, the "
                         "recommendation and the runner-up are re-scored exactly")
    if "kf_array" in space.estimators and (space.failures or any(
            np.any(np.asarray(d["mounting_signs"]) < 0) for d in designs if d["estimator"] == "kf_array")):
        notes.append("kf_array after a failed gyro or with reversed gyros is screened as the single-input "
                     "KF on the fixed-weight GLS channel (exact on an intact symmetric cone, where the "
                     f"array KF decouples); the first {EXACT_TOP} designs, the recommendation and the "
                     "runner-up are then re-scored exactly (the filter as built on the gyros left, full "
                     "predictor) and re-ranked: each design's `scored` says which")
    return (_rank_decision(designs, objective, space.mdb_max) if space.mdb_max is not None
            else designs), notes


#: The objectives in words.
OBJECTIVE_WORDS = {"rate": "3-axis RMS of the rate error about the truth over the horizon [deg/s]",
                   "angle": "3-axis angle error at the horizon (root-sum-square over the axes) [deg]"}


def _decision_statement(designs: list[dict], space: DesignSpace, lo: float, hi: float) -> dict:
    """``objective``, ``decision`` (the recommendation's worst case in one line) and ``tie``."""
    rec = designs[0]
    wc = rec["worst_case"]
    failed = ("no failure" if not wc["failed_gyros"] else
              "gyro " + ", ".join(map(str, wc["failed_gyros"])) + " failed")
    rd = ("built without ρ" if rec["design_rho"] is None else f"weights built for ρ = {rec['design_rho']:.4g}")
    line = (f"ranked on the {rec['objective']} objective ({OBJECTIVE_WORDS[rec['objective']]}) by the worst "
            f"case over ρ in [{lo:g}, {hi:g}] x {space.failures} failed gyro(s); {design_label(rec)}, "
            f"{rec['mounting']}; {rd}; worst case at ρ = {wc['rho']:.4g}, {failed}: "
            f"{wc['rms_3axis_deg_s']:.4g} deg/s 3-axis RMS, {wc['angle_deg']:.4g} deg at the horizon")
    out = {"objective": rec["objective"], "decision": line}
    if "tie" in rec:
        out["tie"] = rec["tie"]
    return out


def _mirror_design(rec: dict, g: GyroNoise, space: DesignSpace) -> dict:
    """The recommendation with its mounting mirrored (:func:`gyroarray.design.robust.mirror_pattern`),
    same estimator, bandwidth and design ρ, scored the same way (exactly: :func:`rescore_exact`)."""
    lo, hi = rec["rho_range"]
    dec = _Decider(g, space, lo, hi, rec["objective"])
    alpha, signs = mirror_pattern(rec["scheme"], rec["alpha_deg"], np.asarray(rec["mounting_signs"], float))
    c = _Cand(rec["scheme"], rec["n"], rec["estimator"], signs, math.radians(alpha), rec["bandwidth_hz"],
              rec["design_rho"], math.nan)
    d = _decision_dict(dec, c, None)
    rescore_exact(d, dec)
    d.pop("_cand", None)
    return d


def honest_rms_ci(values, *, gaussian: bool = False) -> dict:
    """:func:`gyroarray.analysis.replicates.rms_ci` that never claims more than the runs show.

    Each run's mean square is a positive quadratic form of Gaussian noise, so it carries at
    least one degree of freedom: ν >= n runs. The Satterthwaite ν estimated from the spread
    of a few runs can be far larger than the truth when the error is dominated by a random
    walk (a handful of slow modes per run; four runs that happen to agree give a narrow
    interval around a low draw). The interval returned is the wider of the Satterthwaite one
    and the ν = n bound (exact for a zero-mean Gaussian; ``gaussian``: that one alone).
    """
    a = rms_ci(values, gaussian=True)
    if gaussian or a["ci_low"] is None:
        return a
    b = rms_ci(values)
    if b["ci_low"] is None:
        return a
    return {**a, "ci_low": min(a["ci_low"], b["ci_low"]), "ci_high": max(a["ci_high"], b["ci_high"]),
            "interval": "the wider of Satterthwaite and nu = n runs (at least one degree of freedom per run)"}


def check_decision(designs: list[dict], g: GyroNoise, space: DesignSpace, *, replicates: int = 20,
                   seed: int = 20260412) -> dict:
    """Monte Carlo of the decision: the recommendation, the runner-up and the mounting mirror,
    each at its own worst case (true ρ, failed gyros), with the estimator as built.

    Each design's estimator is fitted once, for its design ρ, on the gyros left after its worst
    failure (weights recomputed for the design ρ on the remaining geometry); the readings are
    simulated at its worst true ρ. Run r draws from the same seed in every design (paired runs),
    so the difference of two designs' 3-axis mean squares is judged run by run (Student-t
    interval of the paired differences).

    Returns
    -------
    dict
        ``replicates``, ``seed``, ``designs`` (per design: ``role``, ``label``, ``at`` {rho,
        failed_gyros}, per axis the predicted and simulated ``rms_deg_s`` and ``angle_deg`` with
        95 % intervals, ``rms_3axis_deg_s``, ``inside_95`` of ``compared``), ``paired`` (the
        recommendation against each other one), ``inside_95``, ``compared``.
    """
    rec = designs[0]
    other = [d for d in designs[1:] if (d["scheme"], d["n"]) != (rec["scheme"], rec["n"])] or designs[1:2]
    picked = [("recommended", rec)] + [("runner-up", d) for d in other[:1]]
    picked.append(("mounting mirror", _mirror_design(rec, g, space)))
    n, dt = space.n_samples, space.dt_s
    k0 = settle_start(n, dt, space.settle_s)
    t = np.arange(n) * dt
    if space.motion is not None:
        truth = np.asarray(space.motion, dtype=float)[:n]
    elif space.swing is not None:
        truth = swing_truth(space.swing, n, dt)
    else:
        truth = np.zeros((n, 3))
    ranged = ((g.rho_arw == g.rho_rrw and g.corr_arw is None and g.corr_rrw is None)
              or rec["rho_range"][1] > rec["rho_range"][0])
    setups = []
    for role, d in picked:
        wc = d["worst_case"]
        keep = [k for k in range(d["n"]) if k + 1 not in wc["failed_gyros"]]
        layout = Layout(np.asarray(d["axes"], dtype=float)[keep])
        rd = d["design_rho"] if d["design_rho"] is not None else wc["rho"]
        g_design = g.with_rho(rd) if ranged else g
        g_true = g.with_rho(wc["rho"]) if ranged else g
        est = get_estimator(d["estimator"])(**_estimator_kwargs(d["estimator"], d["bandwidth_hz"], g)).fit(
            layout, _with_sensor(g_design.noise_model(len(keep), keep), space, g_sensitivity=False), dt)
        model = _with_sensor(g_true.noise_model(len(keep), keep), space, g_sensitivity=False)
        setups.append((role, d, layout, model, est))
    per: list[list[np.ndarray]] = [[] for _ in setups]
    for r in range(int(replicates)):
        for j, (_, d, layout, model, est) in enumerate(setups):
            z = simulate_readings(model, truth, layout, dt, replicate_rng(seed, r), time_s=t)
            e = est.estimate(z) - truth
            w = e[k0:]
            per[j].append(np.stack([np.sqrt(np.mean(w ** 2, axis=0)), dt * e.sum(axis=0),
                                    np.std(w, axis=0, ddof=1), np.mean(w, axis=0)]))
    out_designs = []
    for j, (role, d, *_rest) in enumerate(setups):
        arr = np.array(per[j])                                        # (R, 4, 3)
        wc = d["worst_case"]
        axes_out: dict[str, Any]
        axes_out, inside, compared = {}, 0, 0
        for a, ax in enumerate(AXES):
            axes_out[ax] = {}
            for m, key, conv in ((0, "rms_deg_s", units.rad_s_to_deg_s), (2, "std_deg_s", units.rad_s_to_deg_s),
                                 (3, "mean_deg_s", units.rad_s_to_deg_s), (1, "angle_deg", units.rad_to_deg)):
                mc = honest_rms_ci(conv(arr[:, m, a]), gaussian=key in ("mean_deg_s", "angle_deg"))
                p = wc["per_axis"][ax][key]
                ok = None if mc["ci_low"] is None else bool(mc["ci_low"] <= p <= mc["ci_high"])
                axes_out[ax][key] = {"predicted": p, "monte_carlo": mc, "agrees": ok}
                if ok is not None:
                    compared += 1
                    inside += ok
        tot = honest_rms_ci(units.rad_s_to_deg_s(np.sqrt(np.sum(arr[:, 0, :] ** 2, axis=1))))
        out_designs.append({"role": role, "label": design_label(d), "mounting": d["mounting"],
                            "scheme": d["scheme"], "n": d["n"], "alpha_deg": d["alpha_deg"],
                            "estimator": d["estimator"], "bandwidth_hz": d["bandwidth_hz"],
                            "design_rho": d["design_rho"],
                            "at": {"rho": wc["rho"], "failed_gyros": wc["failed_gyros"]},
                            "rms_3axis_deg_s": {"predicted": wc["rms_3axis_deg_s"], "monte_carlo": tot},
                            "axes": axes_out, "inside_95": inside, "compared": compared})
    paired = []
    ms0 = np.sum(np.array(per[0])[:, 0, :] ** 2, axis=1)
    for j in range(1, len(setups)):
        diff = units.rad_s_to_deg_s(1.0) ** 2 * (np.sum(np.array(per[j])[:, 0, :] ** 2, axis=1) - ms0)
        st = mean_ci(diff)
        paired.append({"against": out_designs[j]["label"], "role": out_designs[j]["role"],
                       "mean_square_difference_deg2_s2": st,
                       "resolved": None if st["ci_low"] is None else bool(st["ci_low"] > 0 or st["ci_high"] < 0),
                       "note": "paired: run r uses the same seed in both designs; Student-t interval "
                               "of the per-run differences"})
    return {"replicates": int(replicates), "seed": int(seed), "designs": out_designs, "paired": paired,
            "inside_95": sum(d["inside_95"] for d in out_designs),
            "compared": sum(d["compared"] for d in out_designs),
            "what": "each design at its own worst case (true rho, failed gyros), estimator built for "
                    "its design rho on the remaining gyros"}


# -- the array as built: each estimator's fused accuracy on a recorded array's axes -------------

#: The estimators predicted on an array as built (those registered; ``svo`` when it is).
AS_BUILT_ESTIMATORS = ("gls", "ols", "kf_array", "svo", "naive")
#: Longest impulse response kept for a filter's Allan variance [samples].
MAX_IMPULSE = 1 << 16


def impulse_response(sys, tol: float = 1e-12, max_len: int = MAX_IMPULSE) -> np.ndarray:
    """h_j = C Aʲ K (L, 3, N) of a :class:`~gyroarray.estimators.base.LinearSystem`, cut where
    the slowest mode has decayed below ``tol`` (at most ``max_len`` samples)."""
    lam = np.asarray(sys.lam)
    amax = float(np.max(np.abs(lam))) if lam.size else 0.0
    L = 1 if amax <= 0 else int(min(max_len, max(1, math.ceil(math.log(tol) / math.log(min(amax, 1 - 1e-15))))))
    cs = sys.C @ sys.S                                                # (3, D)
    bk = sys.S_inv @ sys.K                                            # (D, N)
    powers = lam[None, :] ** np.arange(L)[:, None]                   # (L, D)
    h = np.einsum("ad,ld,dn->lan", cs, powers, bk)
    return np.real(h)


def allan_variance_linear(h: np.ndarray, R: np.ndarray, Q: np.ndarray, m: int) -> np.ndarray:
    """Allan variance (3,) [rad²/s²] at τ = m·dt of the output of impulse response h (L, 3, N)
    driven by white noise of per-sample covariance R and a random walk of per-sample increment
    covariance Q (stationary: the start-up left out).

    With g the Allan filter (−1/m on m samples, then +1/m on m samples), c = g ∗ h:
    σ² = ½ Σ_j c_jᵀ R c_j (white) + ½ Σ_j d_jᵀ Q d_j (walk), d_j = Σ_{i<=j} c_i."""
    L = h.shape[0]
    g = np.concatenate([np.full(m, -1.0 / m), np.full(m, 1.0 / m)])
    P = 1 << int(math.ceil(math.log2(2 * m + L)))
    c = np.fft.irfft(np.fft.rfft(g, P)[:, None, None] * np.fft.rfft(h, P, axis=0), P, axis=0)[:2 * m + L - 1]
    d = np.cumsum(c, axis=0)
    white = 0.5 * np.einsum("jan,nk,jak->a", c, R, c)
    walk = 0.5 * np.einsum("jan,nk,jak->a", d, Q, d)
    return white + walk


def _gm_avar(sigma2: np.ndarray, tau_c: np.ndarray, tau: float) -> np.ndarray:
    """Allan variance of first-order Gauss–Markov noise of variance σ² and correlation time τc
    at τ: σ²(τc/τ)²(2τ/τc − 3 + 4e^{−τ/τc} − e^{−2τ/τc}) [unit of σ²] (0 where τc = 0)."""
    out = np.zeros_like(np.asarray(sigma2, dtype=float))
    ok = (tau_c > 0) & (sigma2 > 0)
    x = tau / tau_c[ok]
    out[ok] = sigma2[ok] * (2.0 * x - 3.0 + 4.0 * np.exp(-x) - np.exp(-2.0 * x)) / x ** 2
    return out


def as_built_taus(dt_s: float, duration_s: float) -> list[float]:
    """Octave averaging times from dt to a ninth of the record (at most 2¹⁵ samples) [s]."""
    out, m = [], 1
    while m * dt_s <= duration_s / 9.0 and m <= 1 << 15:
        out.append(m * dt_s)
        m *= 2
    return out or [dt_s]


def predict_as_built(model, axes: np.ndarray, dt_s: float, *, n_samples: int,
                     estimators=None, taus=None, settle_s: float = 2.0, source: str = "model") -> dict:
    """Each estimator's fused accuracy on an array as built (``design --layout-from``).

    Parameters
    ----------
    model : NoiseModel
        The array's model: per-gyro parameters (every effect, a plugin's included) and, where it
        has one, the ``[array]`` table's white and walk correlation (:func:`per_gyro_noise`).
    axes : ndarray (N, 3)
        The mounted unit axes of the measurement [-].
    dt_s : float
        Sample period [s].
    n_samples : int
        Run length for the RMS and the angle error (the record's length).
    estimators : sequence of str, optional
        Default :data:`AS_BUILT_ESTIMATORS` that are registered.
    taus : sequence of float, optional
        Averaging times [s] (default :func:`as_built_taus`).

    Returns
    -------
    dict
        ``estimators``: per estimator per axis ``adev_deg_s`` (list of {tau_s, adev_deg_s}),
        ``arw_deg_rt_h`` (the long-τ white level through the DC gain), ``rms_deg_s`` and
        ``angle_deg`` (the full predictor over the run); ``taus_s``, ``n_gyros``, ``noise``
        (the per-gyro levels used), ``ignored_effects``, ``notes``.

    Notes
    -----
    The Allan deviation is exact for the white and walk parts through the estimator's impulse
    response (:func:`allan_variance_linear`, covariances R and Q of the whole array); flicker
    and Gauss–Markov terms pass the DC gain T₀ (independent between gyros): flicker at its
    floor (2 ln 2/π)·Σ T₀² B², Gauss–Markov by its closed form.
    """
    H = np.asarray(axes, dtype=float)
    N = H.shape[0]
    nm = model_gyro_count(model)
    if nm > N:
        raise InputError(f"the model names gyro {nm}, but the measurement has {N} gyros", file=source)
    typical = GyroNoise._typical(model, source)
    g = per_gyro_noise(model, typical, source) if nm else typical
    if nm and nm < N:
        raise InputError(f"the model names {nm} gyros, the measurement has {N}: give every gyro its "
                         "parameters (gyroarray fit --out on this record)", file=source)
    full = _budget_model(g, range(N))
    noise = noise_sources(full, N, dt_s)
    known = [e for e in AS_BUILT_ESTIMATORS if e in set(available())]
    if estimators is not None:
        unknown = [e for e in estimators if e not in set(available())]
        if unknown or not list(estimators):
            raise InputError(f"--estimators: {unknown[0] if unknown else '(none)'} is not an estimator "
                             f"(known: {', '.join(sorted(available()))}; default {', '.join(known)})")
    names = list(dict.fromkeys(estimators)) if estimators is not None else known
    taus = list(taus) if taus is not None else as_built_taus(dt_s, n_samples * dt_s)
    notes = []
    out: dict[str, Any] = {}
    flicker_floor = 2.0 * math.log(2.0) / math.pi
    rrw_on = bool(np.any(np.diag(noise.Qb) > 0))
    for name in names:
        kw: dict = {}
        if name == "kf_array" and not rrw_on:
            kw["bias_states"] = False
        try:
            est = get_estimator(name)(**kw).fit(Layout(H), full, dt_s)
        except InputError as err:
            notes.append(f"{name}: not predicted ({err})")
            continue
        sys = est.linear_system()
        csys = cascade(sys, noise.sensor)
        h = impulse_response(csys)
        if h.shape[0] >= MAX_IMPULSE:
            notes.append(f"{name}: its impulse response was cut at {MAX_IMPULSE} samples (a slow mode)")
        t0 = h.sum(axis=0)                                            # (3, N) DC gain
        p = predict_system(sys, noise, H, n=int(n_samples), settle_s=settle_s, name=name)
        per_axis = {}
        adev = []
        for tau in taus:
            m = max(1, int(round(tau / dt_s)))
            av = allan_variance_linear(h, noise.R, noise.Qb, m)
            av = av + flicker_floor * (t0 ** 2) @ (noise.bi_rad_s ** 2)
            av = av + (t0 ** 2) @ _gm_avar(noise.gm_sigma_rad_s ** 2, np.asarray(noise.gm_tau_s, float), m * dt_s)
            adev.append((m * dt_s, np.sqrt(np.maximum(av, 0.0))))
        arw = units.arw_rad_rt_s_to_deg_rt_h(np.sqrt(np.maximum(np.einsum("ai,ij,aj->a", t0, noise.R, t0) * dt_s, 0)))
        for a, ax in enumerate(AXES):
            per_axis[ax] = {"adev_deg_s": [{"tau_s": float(t), "adev_deg_s": float(units.rad_s_to_deg_s(v[a]))}
                                           for t, v in adev],
                            "arw_deg_rt_h": float(arw[a]),
                            "rms_deg_s": p.axes[ax]["rms_deg_s"], "angle_deg": p.axes[ax]["angle_deg"]}
        out[name] = per_axis
    if not out:
        raise InputError("no estimator could be predicted on this array: " + "; ".join(notes))
    return {"estimators": out, "taus_s": [float(t) for t in taus], "n_gyros": N,
            "horizon_s": float(n_samples * dt_s), "dt_s": float(dt_s),
            "noise": g.to_json_dict(), "per_gyro": g.per_gyro is not None,
            CORRELATION: ("the model's [array] / correlation matrices" if g.corr_arw is not None
                            or g.corr_rrw is not None else f"rho = {g.rho_arw:g}"),
            "ignored_effects": list(noise.ignored), "notes": notes}
