"""The part of a noise model the estimators design with: white noise, random walk, correlation.

A :class:`~gyroarray.effects.model.NoiseModel` lists effect entries in the
spec's units; each effect declares what it contributes
(:meth:`~gyroarray.effects.protocol.Effect.predictor_term`, the terms of
:mod:`gyroarray.effects.terms`), and :func:`model_terms` asks every entry
for it: nothing here names an effect. :func:`array_noise` reduces the
declared white-noise and random-walk terms to per-gyro levels in SI and the
correlation modifier to the two N×N correlation matrices, exactly as the
simulator draws them (``src/gyroarray/sim/effects.py``): white noise has
σ = N/√dt per sample, random-walk increments σ = K√dt, and the correlation
gives Σ_ij = C_ij σ_i σ_j for both (several white or walk terms on one gyro
add their variances). A model with an ``[array]`` table (a fitted array's
cross-covariance, :class:`~gyroarray.effects.model.ArrayNoise`) gives C from
its ``white_correlation`` and ``walk_correlation`` for the gyros it names
(:func:`table_correlation`) instead of the one-ρ ``correlation`` entry; the
per-gyro levels stay the effect entries'.

The other effects of the model (no white, walk or correlation term) are kept
in :attr:`ArrayNoise.ignored_effects` so a report can say what the
estimators did not model.
"""

from __future__ import annotations

from dataclasses import dataclass

import math

import numpy as np

from gyroarray.core.errors import InputError

__all__ = ["ArrayNoise", "array_noise", "model_terms", "per_gyro", "baseline_effect", "table_correlation"]


def _frozen(a, shape) -> np.ndarray:
    out = np.array(a, dtype=float, copy=True)
    if out.shape != shape:
        raise InputError(f"expected shape {shape}, got {out.shape}")
    if not np.all(np.isfinite(out)):
        raise InputError("noise parameters must be finite")
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class ArrayNoise:
    """White and random-walk noise of an N-gyro array, in SI.

    Parameters
    ----------
    arw_rad_rt_s : ndarray, shape (N,)
        Angle random walk N_i of each gyro [rad/√s] (> 0).
    rrw_rad_s_rt_s : ndarray, shape (N,)
        Rate random walk K_i of each gyro [rad/s/√s] (>= 0).
    corr_arw : ndarray, shape (N, N)
        Correlation matrix of the ARW noise [-] (positive definite).
    corr_rrw : ndarray, shape (N, N)
        Correlation matrix of the RRW increments [-] (positive semi-definite).
    ignored_effects : tuple of str
        Effects of the source model that the estimators do not model.
    zero_arw_ok : bool, default False
        True: an ARW of 0 is accepted (R is then singular): only for the
        estimators that use the layout alone (``ols``, ``naive``).
    """

    arw_rad_rt_s: np.ndarray
    rrw_rad_s_rt_s: np.ndarray
    corr_arw: np.ndarray
    corr_rrw: np.ndarray
    ignored_effects: tuple[str, ...] = ()
    zero_arw_ok: bool = False

    def __post_init__(self):
        n = np.size(self.arw_rad_rt_s)
        object.__setattr__(self, "arw_rad_rt_s", _frozen(self.arw_rad_rt_s, (n,)))
        object.__setattr__(self, "rrw_rad_s_rt_s", _frozen(self.rrw_rad_s_rt_s, (n,)))
        object.__setattr__(self, "corr_arw", _frozen(self.corr_arw, (n, n)))
        object.__setattr__(self, "corr_rrw", _frozen(self.corr_rrw, (n, n)))
        object.__setattr__(self, "ignored_effects", tuple(self.ignored_effects))
        if np.any(self.arw_rad_rt_s < 0) or (np.any(self.arw_rad_rt_s == 0) and not self.zero_arw_ok):
            raise InputError("every gyro needs a positive angle random walk: the estimators "
                             "weight the gyros by their white noise")
        if np.any(self.rrw_rad_s_rt_s < 0):
            raise InputError("rate random walk must be >= 0")
        try:
            np.linalg.cholesky(self.corr_arw)
        except np.linalg.LinAlgError:
            raise InputError("the ARW correlation matrix is not positive definite: the "
                             "measurement noise covariance R would be singular") from None

    def __eq__(self, other) -> bool:
        if not isinstance(other, ArrayNoise):
            return NotImplemented
        return (self.ignored_effects == other.ignored_effects
                and all(np.array_equal(getattr(self, k), getattr(other, k))
                        for k in ("arw_rad_rt_s", "rrw_rad_s_rt_s", "corr_arw", "corr_rrw")))

    __hash__ = None  # type: ignore[assignment]

    @property
    def n_gyros(self) -> int:
        """Number of gyros N."""
        return int(self.arw_rad_rt_s.size)

    @classmethod
    def identical(cls, n_gyros: int, arw_rad_rt_s: float, rrw_rad_s_rt_s: float = 0.0,
                  rho_arw: float = 0.0, rho_rrw: float = 0.0) -> "ArrayNoise":
        """N gyros with equal noise and equicorrelation ρ (SI units)."""
        eye, one = np.eye(n_gyros), np.ones((n_gyros, n_gyros))
        return cls(np.full(n_gyros, float(arw_rad_rt_s)), np.full(n_gyros, float(rrw_rad_s_rt_s)),
                   (1 - rho_arw) * eye + rho_arw * one, (1 - rho_rrw) * eye + rho_rrw * one)

    def R(self, dt_s: float) -> np.ndarray:
        """Covariance of one sample of the white measurement noise [rad²/s²].

        Σ_ij = C_ij σ_i σ_j with σ_i = N_i/√dt.
        """
        s = self.arw_rad_rt_s / np.sqrt(dt_s)
        return self.corr_arw * np.outer(s, s)

    def Qb(self, dt_s: float) -> np.ndarray:
        """Covariance of one bias increment (RRW over one sample) [rad²/s²].

        Σ_ij = C_ij s_i s_j with s_i = K_i √dt.
        """
        s = self.rrw_rad_s_rt_s * np.sqrt(dt_s)
        return self.corr_rrw * np.outer(s, s)


def model_terms(noise_model, n_gyros: int) -> list:
    """Each effect of a model with its declared predictor term, in the model's order.

    The entries of one effect are resolved per gyro (an entry with ``gyro = k``
    overrides the all-gyros entry for gyro k; the parameters of a gyro no entry
    covers are NaN) and handed to its
    :meth:`~gyroarray.effects.protocol.Effect.predictor_term`.

    Parameters
    ----------
    noise_model : NoiseModel
    n_gyros : int

    Returns
    -------
    list of (Effect, PredictorTerm or None)
        One pair per effect of the model; None: the effect declares no term.
    """
    from gyroarray.effects import get_effect  # lazy: loads gyroarray.effects and its plugins
    from gyroarray.effects.protocol import Active  # lazy: with the registry above
    groups: dict = {}
    for entry in noise_model.entries:
        groups.setdefault(entry.effect, []).append(entry)
    out = []
    for name, items in groups.items():
        eff = get_effect(name)
        if not eff.per_gyro:
            act = Active(np.arange(n_gyros), items[0].si_params, name)
        else:
            per: dict = {}
            for entry in sorted(items, key=lambda e: e.gyro is not None):   # all gyros, then overrides
                if entry.gyro is None:
                    per.update(dict.fromkeys(range(n_gyros), entry))
                elif entry.gyro <= n_gyros:
                    per[entry.gyro - 1] = entry
            cols = np.array(sorted(per), dtype=np.int64)
            p = {prm.si_name: _stack([per[c].si_params.get(prm.si_name) for c in cols], prm.kind)
                 for prm in eff.params}
            act = Active(cols, p, name)
        out.append((eff, eff.predictor_term(act, n_gyros)))
    return out


def _stack(values: list, kind: str) -> np.ndarray:
    """Per-gyro values as one array, NaN (a NaN row for a vector) where absent."""
    if kind in ("axis", "vector"):
        return np.array([np.full(3, np.nan) if v is None else v for v in values], dtype=float)
    return np.array([np.nan if v is None else v for v in values], dtype=float)


def baseline_effect(source: str):
    """The registered effect that is the baseline's ``source`` term (``"white"``, ``"walk"``:
    :attr:`~gyroarray.effects.protocol.Effect.baseline_term`), for messages that name the way out."""
    from gyroarray.effects import REGISTRY  # lazy: loads gyroarray.effects and its plugins
    return next(e for e in REGISTRY.values() if e.baseline and e.baseline_term == source)


def _example(eff) -> str:
    """``{effect = "NAME", key = value}``: an entry of ``eff`` the user may add."""
    kv = ", ".join(f"{k} = {v:g}" for k, v in eff.placeholder().items())
    return f'{{effect = "{eff.name}", {kv}}}'


def per_gyro(model, effect: str, key: str, n_gyros: int) -> np.ndarray:
    """Per-gyro SI value of a per-gyro effect (NaN where absent); gyro=k overrides all."""
    out = np.full(n_gyros, np.nan)
    for e in model.entries:
        if e.effect == effect and e.gyro is None:
            out[:] = e.si_params[key]
    for e in model.entries:
        if e.effect == effect and e.gyro is not None:
            out[e.gyro - 1] = e.si_params[key]
    return out


def array_noise(noise_model, n_gyros: int, require_arw: bool = True) -> ArrayNoise:
    """The white, random-walk and correlation part of a noise model for an N-gyro array.

    Parameters
    ----------
    noise_model : NoiseModel
        Entries in the spec's units; an entry with ``gyro = k`` overrides the
        all-gyros entry of the same effect for gyro k.
    n_gyros : int
        Number of gyros N.
    require_arw : bool, default True
        False: a gyro without white noise (or with a level of 0) gets a white-noise
        level of 0 [rad/√s] instead of a refusal (estimators that only use the
        layout, :attr:`~gyroarray.estimators.base.Estimator.needs_arw`).

    Returns
    -------
    ArrayNoise

    Raises
    ------
    InputError
        The model fails :meth:`NoiseModel.check`, a gyro has no white noise (the
        estimators weight the gyros by their white noise), a white level of zero,
        or a white correlation whose covariance is singular (a common mode
        with ρ = 1: every gyro sees the same white noise).

    Notes
    -----
    With an ``[array]`` table, its correlation matrices replace the ``correlation``
    entry's between the gyros the table names (:func:`table_correlation`).
    """
    from gyroarray.effects.model import NoiseModel  # lazy: loads gyroarray.effects and its plugins
    if not isinstance(noise_model, NoiseModel):
        raise InputError(f"noise_model must be a NoiseModel, got {type(noise_model).__name__}")
    # lazy: loads gyroarray.effects and its plugins
    from gyroarray.effects.terms import CorrelationTerm, WalkTerm, WhiteTerm, root_sum_square
    noise_model.check(n_gyros)
    terms = model_terms(noise_model, n_gyros)
    white = [t.n_rad_rt_s for _, t in terms if isinstance(t, WhiteTerm)]
    walk = [t.k_rad_s_rt_s for _, t in terms if isinstance(t, WalkTerm)]
    corr = [t for _, t in terms if isinstance(t, CorrelationTerm)]
    arw = root_sum_square(white) if white else np.full(n_gyros, np.nan)
    missing = np.flatnonzero(np.isnan(arw)) + 1
    if not require_arw:
        arw = np.nan_to_num(arw, nan=0.0)
    elif missing.size:
        eff = baseline_effect(WhiteTerm.source)
        raise InputError(
            f"the noise model has no angle random walk ({eff.name!r}) for gyro(s) "
            f"{', '.join(map(str, missing))}: the estimators need the white-noise level of every "
            f"gyro; add e.g. {_example(eff)}")
    zero = np.flatnonzero(arw <= 0) + 1
    if zero.size and require_arw:
        raise InputError(f"{baseline_effect(WhiteTerm.source).name} is 0 on gyro(s) "
                         f"{', '.join(map(str, zero))}: the estimators need a "
                         "positive white-noise level on every gyro (R must be positive definite)")
    rrw = np.nan_to_num(root_sum_square(walk) if walk else np.full(n_gyros, np.nan), nan=0.0)
    c_arw = c_rrw = np.eye(n_gyros)
    if corr:
        c_arw = np.eye(n_gyros) if corr[0].white is None else corr[0].white
        c_rrw = np.eye(n_gyros) if corr[0].walk is None else corr[0].walk
    table = getattr(noise_model, "array", None)          # the [array] table of a fitted array
    high = None if table is None else getattr(table, "white_n_high_deg_rt_h", None)
    if high is not None:
        # a model fitted on several records: each gyro is designed with the high end of its
        # credible white level on a new record (a gyro that wanders is weighted by its worst
        # credible level, not its mean: docs/model-format.md)
        from gyroarray.core.units import arw_deg_rt_h_to_rad_rt_s
        assert table is not None
        for g, v in zip(table.gyros, high):
            if 1 <= g <= n_gyros and math.isfinite(v) and v > 0:
                arw[g - 1] = max(float(arw[g - 1]), float(arw_deg_rt_h_to_rad_rt_s(v)))
    if table is not None:
        every = list(range(1, n_gyros + 1))
        c_arw = table_correlation(table, "white_correlation", every, c_arw)
        c_rrw = table_correlation(table, "walk_correlation", every, c_rrw)
    used = (WhiteTerm, WalkTerm, CorrelationTerm)
    ignored = tuple(sorted(eff.name for eff, t in terms if not isinstance(t, used)))
    return ArrayNoise(arw, rrw, c_arw, c_rrw, ignored, zero_arw_ok=not require_arw)


def table_correlation(table, key: str, gyros, default: np.ndarray) -> np.ndarray:
    """A correlation matrix of a model's ``[array]`` table for the gyros ``gyros``.

    Parameters
    ----------
    table : ArrayNoise (the ``[array]`` table, :class:`gyroarray.effects.model.ArrayNoise`)
        The table.
    key : {"white_correlation", "walk_correlation"}
        Which matrix.
    gyros : sequence of int
        1-based gyros of the rows and columns wanted, in order.
    default : ndarray, shape (len(gyros), len(gyros))
        The correlation without the table [-].

    Returns
    -------
    ndarray, shape (len(gyros), len(gyros))
        The table's entries between the gyros it names, 0 between a named and an unnamed
        gyro, ``default`` between unnamed ones; ``default`` when the table has no such
        matrix or names none of ``gyros`` [-].
    """
    mat = getattr(table, key, None)
    names = list(getattr(table, "gyros", ()) or ())
    if mat is None or not names:
        return default
    mat = np.asarray(mat, dtype=float)
    where = {g: i for i, g in enumerate(names)}
    gyros = list(gyros)
    named = [j for j, k in enumerate(gyros) if k in where]
    if not named:
        return default
    out = np.array(default, dtype=float, copy=True)
    out[named, :] = 0.0
    out[:, named] = 0.0
    rows = [where[gyros[j]] for j in named]
    out[np.ix_(named, named)] = mat[np.ix_(rows, rows)]
    return out
