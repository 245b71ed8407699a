"""Cross-covariance of the noise of N gyros, with confidence intervals.

Statistics that know no effect: they read an N-gyro residual record
``x`` (n × N, rad/s, sample step ``dt_s``; the still part with the true rate
removed), optionally cut into ``parts`` (stitched still parts: nothing is
differenced or averaged across a cut).

White part (:func:`white_covariance`)
    ``Σ_w = Cov(Δx) / 2`` per sample, Δx the first differences within each
    part (``np.cov(np.diff(x, axis=0).T) / 2`` for one part). For white noise
    of per-sample covariance R, E[Σ_w] = R. The first differences are MA(1)
    (lag-1 autocorrelation −½ for white noise), so they are not independent:
    every element gets an effective number of degrees of freedom from
    Bartlett's formula, ``ν_ij = n / (1 + 2 Σ_{h=1..L} a_i(h) a_j(h))`` with
    a_i the measured autocorrelation of gyro i's differences (ν = 2n/3 for
    white noise), and a Wishart interval with ν_ij: χ² for a variance,
    normal for a covariance, Fisher z for a correlation.

Slow part (:func:`slow_covariance`)
    The Allan covariance matrix at τ = m·dt, ``A_ij(τ) = ½ mean[(ȳ_i,k+1 −
    ȳ_i,k)(ȳ_j,k+1 − ȳ_j,k)]`` over non-overlapping block means ȳ of m
    samples (the Haar wavelet covariance up to a factor 2, as GMWM/synimu use),
    less the white part's share Σ_w / m: ``S = A − Σ_w/m``. For a rate random
    walk of increment covariance Q per sample S = Q (m² − 1)/(3m) ≈ K_i K_j τ/3
    (ρ_S = the correlation of Q); for bias instability it is its Allan
    covariance at τ. The intervals count the block differences (K of them,
    Bartlett-corrected for consecutive differences sharing a block) and carry
    the white noise in them (delta method on the Wishart covariance of A). The
    slow correlation is defined only between gyros whose slow variance is
    seen (its lower bound > 0); other pairs are 0.

Definiteness (:func:`regularised`)
    A correlation matrix that is not positive definite, or that cannot be
    estimated (no more block differences than gyros), is refused
    (``"refuse"``: :class:`~gyroarray.core.errors.InputError`), clipped to
    the nearest positive definite matrix with unit diagonal (``"clip"``:
    eigenvalues raised to :data:`MIN_EIGENVALUE`), or shrunk toward the
    identity (``"shrink"``: the Schäfer–Strimmer/Ledoit–Wolf weight
    λ = Σ Var(ρ̂_ij) / Σ ρ̂_ij² over the pairs, raised if needed until the
    smallest eigenvalue is :data:`MIN_EIGENVALUE`); the note says which and by
    how much.

Common mode (:func:`shared_lines`)
    The magnitude-squared coherence of every pair of gyros (Welch, Hann, 50 %
    overlap, segments within parts; ``scipy.signal.coherence`` on one part).
    Without coherence P(C > c) = (1 − c)^(K_eff − 1) for K_eff independent
    segments; a bin of a pair is coherent above the Bonferroni threshold over
    every bin and pair, and stands out of the pair's broadband coherence (atanh
    of the coherency, σ ≈ 1/√(2 K_eff), above its median over frequency: a
    correlated white noise is coherent everywhere). Adjacent coherent bins form
    a band, named as a line shared by the gyros in its coherent pairs (at
    least ``min_gyros``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from gyroarray.analysis.white_level import pooled_allan_covariance, pooled_edf, white_m
from gyroarray.core.errors import InputError

__all__ = ["MatrixEstimate", "SharedLine", "MIN_EIGENVALUE", "white_covariance", "white_at_tau", "allan_covariance",
           "slow_covariance", "default_block", "regularised", "coherence_matrix", "shared_lines", "parts_of"]

#: Smallest eigenvalue a correlation matrix keeps after regularisation [-].
MIN_EIGENVALUE = 1e-3
#: Lags of the Bartlett correction of the degrees of freedom (first differences: 1 is exact
#: for white noise; more follow coloured noise).
WHITE_LAGS = 3
#: The same for block differences (consecutive ones share a block).
SLOW_LAGS = 2
#: Overlap correlation of Hann windows at 50 % overlap (Welch 1967): K_eff = K / (1 + 2 c²).
HANN_OVERLAP_C = 0.167


@dataclass(frozen=True)
class MatrixEstimate:
    """A cross-covariance matrix of N gyros with its intervals.

    Attributes
    ----------
    what : str
        ``"white"`` (per sample) or ``"slow"`` (Allan covariance at ``tau_s`` beyond the
        white part's share).
    tau_s : float
        Sample step (white) or averaging time (slow) [s].
    covariance, cov_lo, cov_hi : ndarray, shape (N, N)
        Estimate and interval per element [rad²/s²].
    correlation, corr_lo, corr_hi : ndarray, shape (N, N)
        Correlation, unit diagonal, and its interval [-] (after regularisation;
        0 with interval [0, 0] for pairs that cannot be estimated).
    corr_sigma : ndarray, shape (N, N)
        1σ of each correlation [-] (delta method, Fisher z mapped back).
    dof : ndarray, shape (N, N)
        Effective degrees of freedom of each element [-].
    n_used : int
        Differences the estimate averages (samples or block differences).
    level : float
        Two-sided confidence level of the intervals [-].
    seen : ndarray of bool, shape (N,)
        Gyros whose variance of this part is above 0 at ``level`` (always True for white).
    notes : tuple of str
        What was regularised and by how much, what was left out.
    """

    what: str
    tau_s: float
    covariance: np.ndarray
    cov_lo: np.ndarray
    cov_hi: np.ndarray
    correlation: np.ndarray
    corr_lo: np.ndarray
    corr_hi: np.ndarray
    corr_sigma: np.ndarray
    dof: np.ndarray
    n_used: int
    level: float
    seen: np.ndarray
    notes: tuple = field(default=())

    def to_json_dict(self) -> dict:
        """Plain lists for JSON (SI units)."""
        out = {"what": self.what, "tau_s": self.tau_s, "level": self.level, "n_used": self.n_used,
               "seen_gyros": [int(k) + 1 for k in np.flatnonzero(self.seen)], "notes": list(self.notes)}
        for key in ("covariance", "cov_lo", "cov_hi", "correlation", "corr_lo", "corr_hi", "corr_sigma"):
            out[key + ("_rad2_s2" if key.startswith("cov") else "")] = np.asarray(getattr(self, key)).tolist()
        return out


@dataclass(frozen=True)
class SharedLine:
    """A frequency band where several gyros are coherent: a common-mode term.

    Attributes
    ----------
    f_hz : float
        Frequency of the largest mean coherence in the band [Hz].
    f_lo_hz, f_hi_hz : float
        Band edges (bin centres ± half a bin) [Hz].
    gyros : tuple of int
        1-based gyros with at least one coherent pair in the band.
    coherence : float
        Mean magnitude-squared coherence over those gyros' pairs at ``f_hz`` [-].
    max_coherence : float
        Largest coherence of a pair in the band [-].
    n_pairs : int
        Coherent pairs in the band.
    threshold : float
        Coherence a pair's bin had to exceed [-].
    """

    f_hz: float
    f_lo_hz: float
    f_hi_hz: float
    gyros: tuple
    coherence: float
    max_coherence: float
    n_pairs: int
    threshold: float

    def to_dict(self) -> dict:
        """Plain dict (JSON, model file)."""
        return {"f_hz": self.f_hz, "band_hz": [self.f_lo_hz, self.f_hi_hz], "gyros": list(self.gyros),
                "coherence": self.coherence, "max_coherence": self.max_coherence, "n_pairs": self.n_pairs}

    def text(self) -> str:
        """``17.5 Hz (16.6–18.4 Hz) shared by gyros 3, 6, 9: coherence 0.31``."""
        return (f"{self.f_hz:.3g} Hz ({self.f_lo_hz:.3g}–{self.f_hi_hz:.3g} Hz) shared by gyros "
                f"{', '.join(map(str, self.gyros))}: mean coherence {self.coherence:.2f} "
                f"(max {self.max_coherence:.2f}, {self.n_pairs} coherent pairs)")


# -- inputs -----------------------------------------------------------------
def _record(x, dt_s: float, min_gyros: int = 1) -> tuple[np.ndarray, float]:
    a = np.asarray(x, dtype=float)
    if a.ndim != 2 or a.shape[1] < min_gyros:
        raise InputError(f"need a record of shape (n, N) with N >= {min_gyros} gyros, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError("the record holds a non-finite value")
    dt = float(dt_s)
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"the sample step must be finite and > 0, got {dt_s!r}")
    return a, dt


def parts_of(n: int, parts=None) -> list[tuple[int, int]]:
    """The parts ``[(start, stop), ...]`` of an n-sample record (default: one part), checked.

    Raises
    ------
    InputError
        A part outside [0, n], empty, or overlapping the one before.
    """
    if parts is None:
        return [(0, int(n))]
    out, last = [], 0
    for a, b in parts:
        a, b = int(a), int(b)
        if not (last <= a < b <= n):
            raise InputError(f"part ({a}, {b}) is not inside [0, {n}) after the previous part (ends {last}); "
                             "parts must be increasing, non-overlapping and non-empty")
        out.append((a, b))
        last = b
    return out


def _check_level(level: float) -> float:
    lv = float(level)
    if not 0.0 < lv < 1.0:
        raise InputError(f"the confidence level must be in (0, 1), got {level!r}")
    return lv


# -- Wishart intervals with a Bartlett-corrected dof ---------------------------
def _lag_products(segs: list[np.ndarray], max_lag: int, centre: np.ndarray | None) -> tuple[np.ndarray, int]:
    """Autocorrelation a_i(h), h = 1..max_lag, of each column, from segments (no lag across a cut)."""
    N = segs[0].shape[1]
    g = np.zeros((max_lag + 1, N))
    count = np.zeros(max_lag + 1)
    for s in segs:
        z = s if centre is None else s - centre
        for h in range(max_lag + 1):
            if z.shape[0] > h:
                g[h] += np.einsum("ti,ti->i", z[h:], z[:z.shape[0] - h])
                count[h] += z.shape[0] - h
    n = int(count[0])
    g = g / np.maximum(count, 1)[:, None]
    a = np.divide(g[1:], g[0], out=np.zeros_like(g[1:]), where=g[0] > 0)
    return a, n


def _dof(a: np.ndarray, n: int) -> np.ndarray:
    """ν_ij = n / (1 + 2 Σ_h a_i(h) a_j(h)) (Bartlett), at least 2."""
    denom = 1.0 + 2.0 * np.einsum("hi,hj->ij", a, a)
    return np.maximum(n / np.maximum(denom, 0.1), 2.0)


def _wishart_var(c: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """Var(ĉ_ij) = (c_ii c_jj + c_ij²) / ν_ij."""
    d = np.diag(c)
    return (np.outer(d, d) + c * c) / nu


def _cov_interval(c: np.ndarray, nu: np.ndarray, level: float, shift: np.ndarray | None = None):
    """Element intervals: χ² (Satterthwaite) on the diagonal, normal off it; ``shift`` is
    subtracted afterwards (the white share of an Allan covariance)."""
    z = stats.norm.ppf(0.5 + level / 2)
    se = np.sqrt(_wishart_var(c, nu))
    lo, hi = c - z * se, c + z * se
    d, v = np.diag(c), np.diag(nu)
    with np.errstate(divide="ignore", invalid="ignore"):
        dlo = d * v / stats.chi2.ppf(0.5 + level / 2, v)
        dhi = d * v / stats.chi2.ppf(0.5 - level / 2, v)
    idx = np.arange(c.shape[0])
    lo[idx, idx], hi[idx, idx] = dlo, dhi
    if shift is not None:
        lo, hi = lo - shift, hi - shift
    return lo, hi


def _corr_sigma(total: np.ndarray, part: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """1σ of ρ = S_ij/√(S_ii S_jj), S = ``part`` = ``total`` − fixed, by the delta method on the
    Wishart covariance of ``total`` with ν_ij (Fisher (1 − ρ²)/√ν when S = total)."""
    A = total
    a = np.diag(A)
    s = np.where(np.diag(part) > 0, np.diag(part), np.nan)     # no slow variance: no correlation
    ss = np.sqrt(np.outer(s, s))
    rho = part / ss
    gi = -rho / (2.0 * s)[:, None]                              # ∂ρ/∂A_ii
    gj = -rho / (2.0 * s)[None, :]                              # ∂ρ/∂A_jj
    g0 = 1.0 / ss                                               # ∂ρ/∂A_ij
    ai, aj = a[:, None], a[None, :]
    var = (g0 ** 2 * (ai * aj + A ** 2) + gi ** 2 * 2 * ai ** 2 + gj ** 2 * 2 * aj ** 2
           + 2 * g0 * gi * 2 * ai * A + 2 * g0 * gj * 2 * aj * A + 2 * gi * gj * 2 * A ** 2) / nu
    return np.sqrt(np.nan_to_num(np.maximum(var, 0.0), nan=0.0))


def _fisher(rho: np.ndarray, sigma: np.ndarray, level: float):
    """Interval of ρ from its 1σ, symmetric in Fisher z (se_z = σ/(1 − ρ²))."""
    z = stats.norm.ppf(0.5 + level / 2)
    r = np.clip(rho, -0.999999, 0.999999)
    fz, se = np.arctanh(r), sigma / (1.0 - r * r)
    return np.tanh(fz - z * se), np.tanh(fz + z * se)


def _correlation(c: np.ndarray, seen: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.where(seen, np.maximum(np.diag(c), 1e-300), 1.0))
    r = c / np.outer(d, d)
    keep = np.outer(seen, seen)
    r = np.where(keep, r, 0.0)
    np.fill_diagonal(r, 1.0)
    return r


# -- white part ---------------------------------------------------------------
def white_covariance(x, dt_s: float, *, parts=None, level: float = 0.95, regularise: str = "refuse",
                     max_lag: int = WHITE_LAGS, name: str | None = None) -> MatrixEstimate:
    """Cross-covariance of the white part: ``Cov(first differences) / 2`` per sample.

    Parameters
    ----------
    x : array_like, shape (n, N)
        Residual record [rad/s] (still, true rate removed).
    dt_s : float
        Sample step [s].
    parts : list of (start, stop), optional
        Parts of the record (stitched still parts); differences stay within a part.
    level : float
        Two-sided confidence level of the intervals [-].
    regularise : {"refuse", "clip", "shrink"}
        What to do with a correlation matrix that is not positive definite (:func:`regularised`).
    max_lag : int
        Lags of the Bartlett correction of the degrees of freedom.
    name : str, optional
        File the record came from (named in a refusal).

    Returns
    -------
    MatrixEstimate
        ``what = "white"``, ``tau_s = dt_s``; ``covariance`` equals
        ``np.cov(np.diff(x, axis=0).T) / 2`` on one part [rad²/s²].

    Raises
    ------
    InputError
        Bad record, fewer than N + 2 differences, a gyro with no white noise, or (``refuse``)
        a correlation matrix that is not positive definite.
    """
    X, dt = _record(x, dt_s)
    lv = _check_level(level)
    segs = [np.diff(X[a:b], axis=0) for a, b in parts_of(X.shape[0], parts) if b - a >= 2]
    N = X.shape[1]
    n = sum(s.shape[0] for s in segs)
    if n < N + 2:
        raise InputError(f"{n} first differences cannot estimate the white covariance of {N} gyros "
                         f"(at least {N + 2} are needed): record a longer still part", file=name)
    d = np.concatenate(segs)
    c = np.atleast_2d(np.cov(d.T)) / 2.0
    flat = np.flatnonzero(np.diag(c) <= 0)
    if flat.size:
        raise InputError(f"gyro(s) {', '.join(str(k + 1) for k in flat)} have no white noise (constant or "
                         "quantized to one level in every difference): leave them out", file=name)
    a, _ = _lag_products(segs, max_lag, d.mean(axis=0))
    nu = _dof(a, n)
    lo, hi = _cov_interval(c, nu, lv)
    seen = np.ones(N, bool)
    rho = _correlation(c, seen)
    sig = _corr_sigma(c, c, nu)
    np.fill_diagonal(sig, 0.0)
    rho, notes, sig = _regularised_with_sigma(rho, sig, regularise, "white", n, name)
    rlo, rhi = _fisher(rho, sig, lv)
    np.fill_diagonal(rlo, 1.0)
    np.fill_diagonal(rhi, 1.0)
    return MatrixEstimate("white", dt, c, lo, hi, rho, rlo, rhi, sig, nu, n, lv, seen, tuple(notes))


def white_at_tau(x, dt_s: float, *, parts=None, tau_s: float = 1.0, level: float = 0.95,
                 regularise: str = "refuse", name: str | None = None) -> MatrixEstimate:
    """Cross-covariance of the white part where white noise is read: the overlapping Allan
    covariance at τ1 ≈ ``tau_s``, pooled over ``parts``
    (:func:`~gyroarray.analysis.white_level.pooled_allan_covariance`).

    A per-sample covariance (:func:`white_covariance`) reads every frequency up to Nyquist:
    a narrow common-mode line (the MIMU4444 board's 17.6 Hz line on its 8 z gyros) makes the
    z pairs correlated +0.03…+0.07 per sample, while at τ >= 1 s, where a fused rate's ARW
    is read, they are uncorrelated (−0.014…+0.018). This estimate is the one a prediction at
    τ1 uses: the fused Allan variance of a static fusion w is exactly wᵀ A(τ1) w.

    Returns
    -------
    MatrixEstimate
        ``what = "white_tau"``, ``tau_s = τ1``; ``covariance`` = A(τ1) [rad²/s²] (N_i N_j ρ_ij
        / τ1 for white noise); ``dof`` the pooled white-FM EDF (every element); correlation
        intervals Fisher's with σ = (1 − ρ²)/√EDF. Unless ``regularise="refuse"``, the
        correlation is always shrunk toward the identity with the Schäfer–Strimmer weight
        (:func:`regularised`, ``force``): its pairs' noise would otherwise go into the weights.
    """
    X, dt = _record(x, dt_s)
    lv = _check_level(level)
    pts = parts_of(X.shape[0], parts)
    N = X.shape[1]
    m = white_m(dt, tau_s)
    A, total = pooled_allan_covariance(X, dt, m, pts)
    if total == 0:
        raise InputError(f"no still part is longer than {2 * m * dt:.3g} s: the white covariance at tau = "
                         f"{m * dt:.3g} s cannot be read", file=name)
    edf = pooled_edf(pts, m)
    flat = np.flatnonzero(np.diag(A) <= 0)
    if flat.size:
        raise InputError(f"gyro(s) {', '.join(str(k + 1) for k in flat)} have no noise at tau = {m * dt:.3g} s "
                         "(constant): leave them out", file=name)
    nu = np.full((N, N), max(edf, 2.0))
    lo, hi = _cov_interval(A, nu, lv)
    seen = np.ones(N, bool)
    rho = _correlation(A, seen)
    sig = (1.0 - rho ** 2) / np.sqrt(nu)
    np.fill_diagonal(sig, 0.0)
    # always shrunk toward the identity (Schäfer–Strimmer λ): weights optimised against a noisy
    # correlation predict their own fused ARW too low (MIMU4444, a model of one record's 276
    # correlations, σ 0.04 each: x predicted 6-9 % below what the next records measured)
    rho, notes, sig = _regularised_with_sigma(rho, sig, "shrink" if regularise != "refuse" else regularise,
                                              "white", int(total), name, force=regularise != "refuse")
    rlo, rhi = _fisher(rho, sig, lv)
    np.fill_diagonal(rlo, 1.0)
    np.fill_diagonal(rhi, 1.0)
    return MatrixEstimate("white_tau", m * dt, A, lo, hi, rho, rlo, rhi, sig, nu, int(total), lv, seen,
                          tuple(notes))


# -- slow part ----------------------------------------------------------------
def allan_covariance(x, m: int, *, parts=None) -> tuple[np.ndarray, list[np.ndarray]]:
    """Non-overlapping Allan covariance matrix at m samples.

    Parameters
    ----------
    x : array_like, shape (n, N)
        Record [rad/s].
    m : int
        Samples per block (τ = m·dt).
    parts : list of (start, stop), optional
        Blocks and their differences stay within a part.

    Returns
    -------
    A : ndarray, shape (N, N)
        ``½ mean[(ȳ_i,k+1 − ȳ_i,k)(ȳ_j,k+1 − ȳ_j,k)]`` [rad²/s²] (nan with no difference).
    diffs : list of ndarray
        The block differences of each part, shape (B_p − 1, N).
    """
    X = np.asarray(x, dtype=float)
    m = int(m)
    if m < 1:
        raise InputError(f"block length must be >= 1 sample, got {m}")
    diffs = []
    for a, b in parts_of(X.shape[0], parts):
        B = (b - a) // m
        if B >= 2:
            ybar = X[a:a + B * m].reshape(B, m, -1).mean(axis=1)
            diffs.append(np.diff(ybar, axis=0))
    if not diffs:
        return np.full((X.shape[1], X.shape[1]), np.nan), []
    D = np.concatenate(diffs)
    return D.T @ D / (2.0 * D.shape[0]), diffs


def default_block(parts: list[tuple[int, int]], n_gyros: int, min_diffs: int | None = None) -> int:
    """The longest octave block length m (samples) whose block differences, summed over the parts,
    number at least ``min_diffs`` (default max(2N, 30)); at least 2."""
    need = max(2 * n_gyros, 30) if min_diffs is None else int(min_diffs)
    m, best = 2, 2
    longest = max(b - a for a, b in parts)
    while m <= longest // 2:
        k = sum(max((b - a) // m - 1, 0) for a, b in parts)
        if k >= need:
            best = m
        m *= 2
    return best


def slow_covariance(x, dt_s: float, *, tau_s: float | None = None, parts=None, level: float = 0.95,
                    regularise: str = "refuse", white: MatrixEstimate | None = None,
                    max_lag: int = SLOW_LAGS, name: str | None = None, labels=None) -> MatrixEstimate:
    """Cross-covariance of the slow part: Allan covariance at τ less the white part's share.

    Parameters
    ----------
    x : array_like, shape (n, N)
        Residual record [rad/s].
    dt_s : float
        Sample step [s].
    tau_s : float, optional
        Averaging time [s], rounded to whole samples; default the longest octave τ with at
        least max(2N, 30) block differences (:func:`default_block`).
    parts : list of (start, stop), optional
        Parts of the record; blocks stay within a part.
    level : float
        Two-sided confidence level [-].
    regularise : {"refuse", "clip", "shrink"}
        What to do with a correlation matrix that is not positive definite, or that cannot be
        estimated (no more block differences than seen gyros).
    white : MatrixEstimate, optional
        The white part of the same record (computed when not given).
    max_lag : int
        Lags of the Bartlett correction over consecutive block differences.
    name : str, optional
        File the record came from (named in a refusal).
    labels : sequence of int, optional
        Gyro numbers of the columns, for the notes (default 1..N).

    Returns
    -------
    MatrixEstimate
        ``what = "slow"``: ``covariance`` = A(τ) − Σ_w/m [rad²/s²]; ``seen`` the gyros whose
        slow variance has its lower bound above 0; correlations only between those.

    Raises
    ------
    InputError
        Bad input, fewer than 2 block differences, or (``refuse``) a correlation that is not
        positive definite or cannot be estimated.
    """
    X, dt = _record(x, dt_s)
    lv = _check_level(level)
    pts = parts_of(X.shape[0], parts)
    N = X.shape[1]
    labels = list(range(1, N + 1)) if labels is None else [int(g) for g in labels]
    if white is None:
        white = white_covariance(X, dt, parts=pts, level=lv, regularise="clip", name=name)
    if tau_s is None:
        m = default_block(pts, N)
    else:
        if not (math.isfinite(tau_s) and tau_s > 0):
            raise InputError(f"tau must be finite and > 0 s, got {tau_s!r}", file=name)
        m = max(int(round(tau_s / dt)), 1)
    A, diffs = allan_covariance(X, m, parts=pts)
    K = sum(d.shape[0] for d in diffs)
    if K < 2:
        longest = max(b - a for a, b in pts) * dt
        raise InputError(f"tau = {m * dt:.6g} s leaves {K} block differences (the longest part is "
                         f"{longest:.6g} s): choose tau at most a third of a still part", file=name)
    a, _ = _lag_products(diffs, max_lag, None)
    nu = _dof(a, K)
    share = white.covariance / m
    S = A - share
    lo, hi = _cov_interval(A, nu, lv, shift=share)
    seen = np.diag(lo) > 0
    notes = []
    if not seen.all():
        notes.append(f"slow part at tau = {m * dt:.4g} s not seen (its variance is not above 0 at "
                     f"{lv:.0%}) on gyro(s) {', '.join(str(labels[k]) for k in np.flatnonzero(~seen))}: "
                     "their slow correlations are set to 0")
    rho = _correlation(S, seen)
    sig = _corr_sigma(A, S, nu)
    keep = np.outer(seen, seen)
    sig = np.where(keep, sig, 0.0)
    np.fill_diagonal(sig, 0.0)
    n_seen = int(seen.sum())
    if n_seen >= 2 and K <= n_seen:
        what = (f"the slow correlation of {n_seen} gyros cannot be estimated from {K} block differences "
                f"at tau = {m * dt:.4g} s (more than {n_seen} are needed)")
        if regularise == "refuse":
            raise InputError(what + ": use a shorter tau, a longer record, or regularise it", file=name)
        notes.append(what)
    rho, more, sig = _regularised_with_sigma(rho, sig, regularise, "slow", K, name,
                                             force=n_seen >= 2 and K <= n_seen)
    notes += more
    rlo, rhi = _fisher(rho, sig, lv)
    rlo, rhi = np.where(keep, rlo, 0.0), np.where(keep, rhi, 0.0)
    np.fill_diagonal(rlo, 1.0)
    np.fill_diagonal(rhi, 1.0)
    return MatrixEstimate("slow", m * dt, S, lo, hi, rho, rlo, rhi, sig, nu, K, lv, seen, tuple(notes))


# -- definiteness -------------------------------------------------------------
def _regularised_with_sigma(rho, sig, how, what, n, name, force=False):
    out, notes = regularised(rho, how=how, sigma=sig, what=what, name=name, force=force)
    if out is not rho:
        # a shrunk or clipped element moved by |Δρ|: its interval widens by that much
        sig = np.sqrt(sig ** 2 + (out - rho) ** 2)
    return out, notes, sig


def regularised(rho, *, how: str = "refuse", sigma=None, what: str = "", name: str | None = None,
                force: bool = False, min_eigenvalue: float = MIN_EIGENVALUE) -> tuple[np.ndarray, list[str]]:
    """A correlation matrix made positive definite, or refused.

    Parameters
    ----------
    rho : array_like, shape (N, N)
        Symmetric correlation matrix, unit diagonal [-].
    how : {"refuse", "clip", "shrink"}
        ``refuse``: InputError when the smallest eigenvalue is below ``min_eigenvalue``.
        ``clip``: nearest matrix with eigenvalues >= ``min_eigenvalue``, rescaled to unit
        diagonal. ``shrink``: (1 − λ) ρ + λ I with the Schäfer–Strimmer weight
        λ = Σ σ_ij² / Σ ρ_ij² (pairs i < j; needs ``sigma``), raised until positive definite.
    sigma : array_like, shape (N, N), optional
        1σ of each correlation (for ``shrink``).
    what : str
        Which matrix (``white``, ``slow``), for the note.
    name : str, optional
        File named in a refusal.
    force : bool
        Regularise even when positive definite (the matrix could not be estimated).
    min_eigenvalue : float
        Smallest eigenvalue kept [-].

    Returns
    -------
    rho : ndarray
        The input itself when nothing was done, else a new matrix.
    notes : list of str
        What was done and by how much.
    """
    r = np.asarray(rho, dtype=float)
    if r.shape[0] < 2:
        return r, []
    lam_min = float(np.linalg.eigvalsh(r)[0])
    if lam_min >= min_eigenvalue and not force:
        return r, []
    label = f"{what} correlation matrix".strip()
    if how == "refuse":
        raise InputError(f"the {label} is not positive definite (smallest eigenvalue {lam_min:.3g}): "
                         "too few independent samples for these gyros; record longer, leave gyros out, "
                         "or regularise it (clip or shrink)", file=name)
    iu = np.triu_indices(r.shape[0], 1)
    if how == "clip":
        w, v = np.linalg.eigh(r)
        out = (v * np.maximum(w, min_eigenvalue)) @ v.T
        d = np.sqrt(np.diag(out))
        out = out / np.outer(d, d)
        out = (out + out.T) / 2
        np.fill_diagonal(out, 1.0)
        k = int(np.sum(w < min_eigenvalue))
        note = (f"{label} regularised by eigenvalue clipping: {k} eigenvalue(s) below {min_eigenvalue:g} "
                f"(smallest {lam_min:.3g}) raised; largest change of a correlation "
                f"{np.max(np.abs(out - r)[iu]):.3g}")
        return out, [note]
    if how == "shrink":
        s = np.zeros_like(r) if sigma is None else np.asarray(sigma, float)
        num, den = float(np.sum(s[iu] ** 2)), float(np.sum(r[iu] ** 2))
        lam = min(max(num / den, 0.0), 1.0) if den > 0 else 1.0
        low = (1.0 - lam) * lam_min + lam
        if low < min_eigenvalue:    # λ_min((1−λ)ρ + λI) = (1−λ)λ_min + λ
            lam = (min_eigenvalue - lam_min) / (1.0 - lam_min)
        out = (1.0 - lam) * r
        np.fill_diagonal(out, 1.0)
        note = (f"{label} regularised by shrinkage toward the identity (Ledoit–Wolf/Schäfer–Strimmer): "
                f"λ = {lam:.3g} (smallest eigenvalue {lam_min:.3g} -> "
                f"{float(np.linalg.eigvalsh(out)[0]):.3g}); every correlation scaled by {1 - lam:.3g}")
        return out, [note]
    raise InputError(f"regularise must be refuse, clip or shrink, got {how!r}", file=name)


# -- common mode ---------------------------------------------------------------
def _components(n: int, edges: list[tuple[int, int]]) -> list[list[int]]:
    """Connected components (sorted node lists) of the graph ``edges`` on nodes 0..n−1 that have
    an edge."""
    root = list(range(n))

    def find(i):
        while root[i] != i:
            root[i] = root[root[i]]
            i = root[i]
        return i

    for i, j in edges:
        root[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for k in sorted({k for e in edges for k in e}):
        groups.setdefault(find(k), []).append(k)
    return sorted(groups.values())


#: A coherent pair links two gyros into one line's group when its coherence is at least this share
#: of the group's strongest pair [-]: a weak bridge (0.09–0.12) does not fold the MIMU4444 z
#: gyros' 17.6 Hz line (0.29–0.46 between them) into one group with 14 other gyros.
GROUP_SHARE = 0.5


def _line_groups(n: int, iu, sel, peak) -> list[list[int]]:
    """The groups of gyros that share one band's line: connected components of its coherent pairs
    ``sel`` (indices into the pairs ``iu``), each split where it hangs on pairs weaker than
    :data:`GROUP_SHARE` of its strongest (``peak``: each pair's largest coherence in the band);
    the gyros only such weak pairs reach form their own groups."""
    out: list[list[int]] = []
    edges = [(int(iu[0][p]), int(iu[1][p]), float(peak[p])) for p in sel]
    for comp in _components(n, [(i, j) for i, j, _ in edges]):
        mine = [(i, j, c) for i, j, c in edges if i in comp and j in comp]
        top = max(c for _, _, c in mine)
        strong = _components(n, [(i, j) for i, j, c in mine if c >= GROUP_SHARE * top])
        covered = {k for g in strong for k in g}
        weak = _components(n, [(i, j) for i, j, c in mine
                               if c < GROUP_SHARE * top and i not in covered and j not in covered])
        out += strong + weak
    return sorted(out)


#: Welch segments transformed at once (bounds the memory of a long record: 2048 × 256 × N).
SEGMENT_CHUNK = 2048


def _cross_spectra(X: np.ndarray, pts, nperseg: int) -> tuple[np.ndarray | None, int]:
    """Σ over Welch segments (within parts, Hann, 50 % overlap, mean removed) of X_i X_j*,
    shape (F, N, N), and the number of segments; chunked so memory stays bounded."""
    step = nperseg - nperseg // 2
    win = np.hanning(nperseg + 1)[:-1] if nperseg > 1 else np.ones(1)   # periodic Hann (scipy's)
    total, count = None, 0
    for a, b in pts:
        if b - a < nperseg:
            continue
        k = (b - a - nperseg // 2) // step
        for c0 in range(0, k, SEGMENT_CHUNK):
            starts = a + np.arange(c0, min(k, c0 + SEGMENT_CHUNK)) * step
            seg = X[starts[:, None] + np.arange(nperseg)[None, :]]          # (k, nperseg, N)
            seg = seg - seg.mean(axis=1, keepdims=True)
            Z = np.fft.rfft(seg * win[None, :, None], axis=1)
            S = np.einsum("sfi,sfj->fij", Z, Z.conj())
            total = S if total is None else total + S
            count += starts.size
    return total, count


def coherence_matrix(x, dt_s: float, *, parts=None, nperseg: int = 256) -> tuple[np.ndarray, np.ndarray, int]:
    """Magnitude-squared coherence of every pair of gyros (Welch, Hann, 50 % overlap).

    Parameters
    ----------
    x : array_like, shape (n, N)
        Record [rad/s].
    dt_s : float
        Sample step [s].
    parts : list of (start, stop), optional
        Segments stay within a part (parts shorter than ``nperseg`` are skipped).
    nperseg : int
        Samples per segment.

    Returns
    -------
    f_hz : ndarray, shape (F,)
        Frequencies [Hz].
    coh : ndarray, shape (F, N, N)
        Coherence |S_ij|² / (S_ii S_jj) [-] (``scipy.signal.coherence`` of a pair on one part).
    n_segments : int
        Segments averaged.
    """
    X, dt = _record(x, dt_s, 2)
    nperseg = int(nperseg)
    S, count = _cross_spectra(X, parts_of(X.shape[0], parts), nperseg)
    if S is None or count < 2:
        raise InputError(f"fewer than 2 segments of {nperseg} samples in the still parts: "
                         "no coherence can be estimated")
    S = S / count
    p = np.real(np.einsum("fii->fi", S))
    with np.errstate(divide="ignore", invalid="ignore"):
        coh = np.abs(S) ** 2 / (p[:, :, None] * p[:, None, :])
    coh = np.nan_to_num(coh, nan=0.0)
    return np.fft.rfftfreq(nperseg, dt), coh, int(count)


def shared_lines(x, dt_s: float, *, parts=None, nperseg: int | None = None, alpha: float = 0.01,
                 min_coherence: float = 0.05, min_gyros: int = 2) -> list[SharedLine]:
    """Frequency bands where several gyros are coherent (common-mode lines).

    Parameters
    ----------
    x : array_like, shape (n, N)
        Residual record [rad/s].
    dt_s : float
        Sample step [s].
    parts : list of (start, stop), optional
        Parts of the record.
    nperseg : int, optional
        Welch segment [samples]; default 256, or the largest power of 2 that fits the
        longest part.
    alpha : float
        Family-wise false-alarm probability over every bin and pair [-].
    min_coherence : float
        Smallest coherence called shared, whatever its significance [-].
    min_gyros : int
        Fewest gyros a band must join.

    Returns
    -------
    list of SharedLine
        By frequency. Empty when nothing is coherent.
    """
    X, dt = _record(x, dt_s, 2)
    pts = parts_of(X.shape[0], parts)
    if nperseg is None:
        longest = max(b - a for a, b in pts)
        nperseg = int(min(256, 2 ** int(math.floor(math.log2(max(longest, 8))))))
    f, coh, k = coherence_matrix(X, dt, parts=pts, nperseg=nperseg)
    N = X.shape[1]
    keff = k / (1.0 + 2.0 * HANN_OVERLAP_C ** 2)
    n_tests = max((f.size - 1) * N * (N - 1) // 2, 1)
    # P(C > c) = (1 − c)^(K_eff − 1) = α / n_tests
    thr = max(1.0 - (alpha / n_tests) ** (1.0 / max(keff - 1.0, 1.0)), min_coherence)
    iu = np.triu_indices(N, 1)
    pair = coh[:, iu[0], iu[1]]                           # (F, pairs)
    # above the pair's own broadband level (a correlated white noise is coherent everywhere):
    # atanh|γ̂| has σ ≈ 1/√(2 K_eff) whatever γ
    g = np.arctanh(np.sqrt(np.clip(pair, 0.0, 1.0 - 1e-12)))
    base = np.median(g[1:], axis=0)
    z = stats.norm.isf(alpha / n_tests)
    hot = (pair > thr) & (g - base > z / math.sqrt(2.0 * keff))
    hot[0] = False                                        # DC: the part means were removed
    df = f[1] - f[0]
    out: list[SharedLine] = []
    flagged = np.flatnonzero(hot.any(axis=1))
    bands: list[list[int]] = []
    for b in flagged:
        if bands and b - bands[-1][-1] <= 1:
            bands[-1].append(int(b))
        else:
            bands.append([int(b)])
    for bins in bands:
        sel = np.flatnonzero(hot[bins].any(axis=0))
        for gy in _line_groups(N, iu, sel, pair[bins].max(axis=0)):
            if len(gy) < min_gyros:
                continue
            own = [p for p in sel if iu[0][p] in gy and iu[1][p] in gy]
            mine = [b for b in bins if hot[b, own].any()]          # the bins of this group
            sub = coh[np.ix_(mine, gy, gy)]
            tri = np.triu_indices(len(gy), 1)
            mean = sub[:, tri[0], tri[1]].mean(axis=1)
            peak = int(np.argmax(mean))
            out.append(SharedLine(float(f[mine[peak]]), float(f[mine[0]] - df / 2),
                                  float(f[mine[-1]] + df / 2), tuple(g + 1 for g in gy), float(mean[peak]),
                                  float(pair[mine][:, own].max()), len(own), float(thr)))
    out.sort(key=lambda line: (line.f_lo_hz, line.gyros))
    return out
