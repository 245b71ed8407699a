"""The gyros' noise the design search takes: :class:`GyroNoise` (alike gyros, or each gyro its own
levels from a per-gyro model) and the reading of a noise model into it.

Datasheet units in the fields (deg/√h, deg/h/√h, deg/h, s); :func:`kept_levels` and :func:`kept_covariances`
give the per-sample SI levels [rad²/s²] of the kept gyros.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any, cast

import numpy as np

from gyroarray.core import units
from gyroarray.core.gdop import correlation_matrix
from gyroarray.core.errors import InputError
from gyroarray.design.moments import check_flicker_model
from gyroarray.design.noise_sources import noise_sources, replace_noise
from gyroarray.design.predict import MODELLED
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.terms import (CorrelationTerm, FlickerTerm, GaussMarkovTerm, WalkTerm, WhiteTerm,
                                     root_sum_square)
from gyroarray.effects.names import ARW, BANDWIDTH, BIAS_INSTABILITY, CORRELATION, GAUSS_MARKOV, G_SENSITIVITY, RRW
from gyroarray.estimators.noise import model_terms, per_gyro


#: Lowest ARW of a gyro the design takes [deg/√h]: below it the white variance per sample
#: underflows (cli.design.MIN_ARW_DEG_RT_H, the --arw floor, is the same).
MIN_ARW_DEG_RT_H = 1e-9

#: The frames the gyros' correlated (common-mode) noise may live in (``design --common-mode``):
#: ``output`` — it adds to every gyro's output with the same sign, whatever the gyro's mounting
#: sense (correlation (1 − ρ)I + ρ11ᵀ); ``axis`` — it follows each gyro's sensing axis, so a
#: gyro mounted reversed sees it reversed ((1 − ρ)I + ρssᵀ, s the mounting signs ±1): then
#: reversing gyros buys nothing.
COMMON_MODES = ("output", "axis")

#: The common-mode frames in words (the decision's assumptions).
COMMON_MODE_WORDS = {
    "output": ("output frame: the correlated noise adds to every gyro's output with the same sign, "
               "whatever its mounting sense (a common electrical or digital path after the sensing "
               "element); correlation (1 − ρ)I + ρ11ᵀ, so reversed gyros move it into the parity space"),
    "axis": ("axis frame: the correlated noise follows each gyro's sensing axis (a shared vibration, "
             "or a supply seen through the sensing element), so a gyro mounted reversed sees it "
             "reversed; correlation (1 − ρ)I + ρssᵀ with s the mounting signs, so reversing gyros "
             "buys nothing"),
}


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
    common_mode : {"output", "axis"}
        The frame the correlated noise lives in (:data:`COMMON_MODES`): ``output`` (the
        correlation as given, whatever the mounting senses) or ``axis`` (the correlation
        between gyros j and k multiplied by s_j·s_k, s the mounting signs: :meth:`correlation`).
    sources : dict
        Where each value came from ("user", "default", "model FILE").
    ignored : tuple of str
        Effects of a source model that the predictor does not model.
    open_from : int or None
        A per-gyro model that is valid for any N >= this many gyros (an all-gyros entry plus
        per-gyro entries, docs/model-format.md: the gyros it does not name take the all-gyros
        entries); ``per_gyro`` then holds its first gyros until :meth:`sized` lengthens it.
        None: alike gyros, or a per-gyro model whose gyro count fixes N.
    rho_bi : float or None
        Common correlation of the gyros' bias instability (flicker) [-] (``design --rho-bi``);
        None: the ARW correlation (ρ, or the model's ARW matrix), whatever ρ the condition
        takes (:meth:`with_rho` keeps it following). The predictor's flicker covariance is
        B Bᵀ ∘ that correlation (:meth:`correlation` with ``which`` = bias_instability); the
        simulator's flicker stays independent between gyros.
    """

    arw_deg_rt_h: float
    rrw_deg_h_rt_h: float = 0.0
    bi_deg_h: float = 0.0
    gm_sigma_deg_h: float = 0.0
    gm_tau_s: float = 0.0
    rho_arw: float = 0.0
    rho_rrw: float = 0.0
    common_mode: str = "output"
    sources: dict = field(default_factory=dict)
    ignored: tuple[str, ...] = ()
    per_gyro: dict | None = field(default=None, compare=False)
    corr_arw: np.ndarray | None = field(default=None, compare=False, repr=False)
    corr_rrw: np.ndarray | None = field(default=None, compare=False, repr=False)
    model: Any = field(default=None, compare=False, repr=False)
    open_from: int | None = field(default=None, compare=False)
    rho_bi: float | None = None

    @property
    def rho_bi_value(self) -> float:
        """The bias instability's common correlation in effect [-] (:attr:`rho_bi`, else the ARW ρ)."""
        return self.rho_arw if self.rho_bi is None else float(self.rho_bi)

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
        if self.rho_bi is not None and not (math.isfinite(self.rho_bi) and -1.0 < self.rho_bi < 1.0):
            raise InputError(f"rho_bi must be in (-1, 1), got {self.rho_bi!r}")
        if self.common_mode not in COMMON_MODES:
            raise InputError(f"the common-mode frame must be one of {', '.join(COMMON_MODES)}, "
                             f"got {self.common_mode!r}")

    def in_frame(self, common_mode: str) -> "GyroNoise":
        """The same gyros with their correlated noise in the frame ``common_mode``
        (:data:`COMMON_MODES`)."""
        return replace(self, common_mode=str(common_mode))

    def correlation(self, n: int, which: str = ARW, keep=None, signs=None) -> np.ndarray:
        """The correlation of the kept gyros' noise on an array mounted with ``signs`` [-].

        Parameters
        ----------
        n : int
            Gyros kept.
        which : {ARW, RRW, BIAS_INSTABILITY}
            The white noise (ARW), the walk increments (RRW) or the flicker (bias instability:
            :attr:`rho_bi` equicorrelated, or, when None, the ARW correlation).
        keep : sequence of int, optional
            0-based gyros (rows of the array) kept (None: the first ``n``); a per-gyro model's matrix
            and ``signs`` are indexed by them.
        signs : sequence of float, optional
            The mounting sign (±1) of every gyro of the array, in its row order (None: every gyro +).

        Returns
        -------
        ndarray (n, n)
            The model's matrix (per-gyro noise) or the equicorrelated one; in the axis frame
            multiplied element-wise by s sᵀ of the kept gyros' signs (the output frame ignores
            the signs).
        """
        c = _corr_of(self, n, keep, which)
        if self.common_mode != "axis" or signs is None:
            return c
        s = np.asarray(signs, dtype=float)
        s = s[:n] if keep is None else s[list(keep)]
        if np.all(s > 0):
            return c
        return c * np.outer(s, s)

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
            # the model kept beside the typical gyro: its deterministic all-gyros effects (a
            # temperature coefficient, a plugin's term) reach the error budget (details.budget_model)
            return replace(typical, model=model)
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

    def noise_model(self, n_gyros: int, keep=None, signs=None):
        """This noise on every gyro of an N-gyro array, as a NoiseModel (for the simulator).

        Per-gyro noise: gyro k of the model on gyro k of the array; ``keep`` (0-based indices
        of the model's gyros, len ``n_gyros``): the gyros left after a failure, renumbered.
        ``signs``: the mounting sign (±1) of every gyro of the array (row order); in the axis frame
        (:attr:`common_mode`) the correlation becomes the matrix of :meth:`correlation`."""
        if self._frame_flips(n_gyros, keep, signs):
            return self._per_gyro_model(n_gyros, keep, signs)
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

    def _frame_flips(self, n_gyros: int, keep, signs) -> bool:
        """Whether the axis frame turns the correlation of the kept gyros into a matrix."""
        if self.common_mode != "axis" or signs is None or not (self.rho_arw or self.rho_rrw
                                                               or self.corr_arw is not None
                                                               or self.corr_rrw is not None):
            return False
        s = np.asarray(signs, dtype=float)
        s = s[:n_gyros] if keep is None else s[[int(k) for k in keep]]
        return bool(np.any(s < 0))

    def _levels(self, n_levels: int) -> dict:
        """Per gyro the levels (:data:`PER_GYRO_KEYS`): its own, or the alike gyro's on each."""
        if self.per_gyro is not None:
            return self.per_gyro
        return {ARW: np.full(n_levels, self.arw_deg_rt_h), RRW: np.full(n_levels, self.rrw_deg_h_rt_h),
                "bi": np.full(n_levels, self.bi_deg_h), "gm_sigma": np.full(n_levels, self.gm_sigma_deg_h),
                "gm_tau": np.full(n_levels, self.gm_tau_s)}

    def _per_gyro_model(self, n_gyros: int, keep, signs=None):
        idx = list(range(n_gyros)) if keep is None else [int(k) for k in keep]
        n_levels = self.n_levels if self.per_gyro is not None else max(idx) + 1
        if len(idx) != n_gyros or max(idx) >= cast(int, n_levels):      # set with per_gyro
            raise ValueError(f"keep {idx} does not give {n_gyros} of the model's {n_levels} gyros")
        p = self._levels(cast(int, n_levels))
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
            if signs is not None:                       # the axis frame: (1 − ρ)I + ρssᵀ (or S C S)
                sub = self.correlation(n_gyros, ARW if key == "rho_arw" else RRW, idx, signs)
                if np.any(sub != np.eye(len(idx))):
                    corr[key] = [[float(v) for v in row] for row in sub]
            elif mat is not None:
                sub = np.asarray(mat, dtype=float)[np.ix_(idx, idx)]
                if np.any(sub != np.eye(len(idx))):
                    corr[key] = [[float(v) for v in row] for row in sub]
            elif rho:
                corr[key] = float(rho)
        if corr:
            entries.append(ModelEntry(CORRELATION, None, corr))
        model = NoiseModel(tuple(entries), description="the model's gyros, each its own noise"
                           if self.per_gyro is not None else "typical gyro of the design search, "
                           "its correlated noise in the gyros' axis frame")
        model.check(n_gyros)
        return model

    def to_json_dict(self) -> dict:
        out: dict[str, Any] = {"arw_deg_rt_h": self.arw_deg_rt_h, "rrw_deg_h_rt_h": self.rrw_deg_h_rt_h,
               "bi_deg_h": self.bi_deg_h, "gm_sigma_deg_h": self.gm_sigma_deg_h,
               "gm_tau_s": self.gm_tau_s, "rho_arw": self.rho_arw, "rho_rrw": self.rho_rrw,
               "rho_bi": self.rho_bi_value}
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


def kept_levels(g: GyroNoise, n: int, keep, dt: float):
    """Per gyro (the kept ones): white variance per sample [rad²/s²], walk increment variance
    per sample [rad²/s²], flicker B² [rad²/s²], Gauss–Markov σ² [rad²/s²]."""
    p = cast(dict, g.per_gyro)                          # per-gyro noise only
    idx = list(range(n)) if keep is None else list(keep)
    return (units.arw_deg_rt_h_to_rad_rt_s(p[ARW][idx]) ** 2 / dt,
            units.rrw_deg_h_rt_h_to_rad_s_rt_s(p[RRW][idx]) ** 2 * dt,
            units.deg_h_to_rad_s(p["bi"][idx]) ** 2, units.deg_h_to_rad_s(p["gm_sigma"][idx]) ** 2)


def _corr_of(g: GyroNoise, n: int, keep, which: str) -> np.ndarray:
    """The correlation of the kept gyros: the model's matrix when it has one, else equicorrelated."""
    if which == BIAS_INSTABILITY:
        if g.rho_bi is None:
            return _corr_of(g, n, keep, ARW)                # default: follows the ARW correlation
        return equicorrelation(n, float(g.rho_bi))
    mat = g.corr_arw if which == ARW else g.corr_rrw
    if mat is None:
        return equicorrelation(n, g.rho_arw if which == ARW else g.rho_rrw)
    idx = list(range(n)) if keep is None else list(keep)
    return np.asarray(mat, dtype=float)[np.ix_(idx, idx)]


def kept_covariances(g: GyroNoise, n: int, keep, dt: float, signs=None) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample white covariance R and walk increment covariance Q of the kept gyros [rad²/s²]
    (``signs``: the array's mounting signs, per gyro in row order, for the axis frame: :meth:`GyroNoise.correlation`)."""
    s2, q, _, _ = kept_levels(g, n, keep, dt)
    s, qs = np.sqrt(s2), np.sqrt(q)
    return (np.outer(s, s) * g.correlation(n, ARW, keep, signs),
            np.outer(qs, qs) * g.correlation(n, RRW, keep, signs))


@lru_cache(maxsize=512)
def equicorrelation(n: int, rho: float) -> np.ndarray:
    """The equicorrelated N×N matrix (cached, read-only)."""
    c = correlation_matrix(n, rho)
    c.setflags(write=False)
    return c


def bi_covariance_correlation(g: GyroNoise, n: int, keep=None, signs=None) -> np.ndarray:
    """The correlation of the kept gyros' flicker (bias instability) [-]: :meth:`GyroNoise.correlation`
    with ``which`` = bias_instability (in the gyros' common-mode frame, ``signs`` the array's
    mounting signs in row order)."""
    return g.correlation(n, BIAS_INSTABILITY, keep, signs)


def predictor_noise(g: GyroNoise, noise_model, n: int, keep, signs, dt: float,
                    flicker_model: str = "circular"):
    """The predictor's :class:`~gyroarray.design.noise_sources.NoiseSources` of ``noise_model``
    on the kept gyros, with the flicker of ``g`` correlated (:func:`bi_covariance_correlation`)
    and the flicker model ``flicker_model`` (:data:`gyroarray.design.moments.FLICKER_MODELS`).

    Parameters
    ----------
    g : GyroNoise
    noise_model : NoiseModel
        The kept gyros' model (as simulated).
    n : int
        Gyros kept.
    keep, signs
        As :meth:`GyroNoise.correlation`.
    dt : float
        Sample period [s].
    flicker_model : str
    """
    ns = noise_sources(noise_model, n, dt)
    return replace_noise(ns, bi_corr=bi_covariance_correlation(g, n, keep, signs),
                         flicker_model=check_flicker_model(flicker_model))
