"""The Allan-variance curve of one series and its GLS on the noise terms' columns.

The machinery of the Allan-variance fits of :mod:`gyroarray.effects.stochastic`
(method: that module's docstring): the overlapping Allan variance at octave
τ, the exact covariance model of its estimates, the GLS of it on the IEEE
terms' columns, and the helpers that read the result. It knows no effect.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from gyroarray.analysis.allan import deviation, edf_simple
from gyroarray.analysis.avar_covariance import AvarCovariance
from gyroarray.analysis.noise_fit import term_basis
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.physics import gauss_markov_avar

__all__ = ["Curve", "Gls", "factors", "cov_model", "curve", "cross_avar", "whitener", "solve", "split",
           "columns", "gls", "deg_h", "band", "band_text", "root_sigma", "avar_normal_score"]


# --------------------------------------------------------------------------
# Allan variance curve and its generalised least squares

#: Longest averaging factor used in the fits, as a fraction of the samples.
_M_MAX_FRACTION = 1.0 / 8.0


@dataclass(frozen=True, eq=False)
class Curve:
    """Overlapping Allan variance of one series at octave taus and the
    covariance model of its estimates."""

    dt_s: float
    n: int
    taus: np.ndarray          # [s]
    m: np.ndarray
    y: np.ndarray             # Allan variance [(rad/s)²]
    cov: AvarCovariance
    caps: dict | None = None  # upper bounds of the capped coefficients (:func:`_caps`)
    white: np.ndarray | None = None  # the white term's Allan variance over N²/τ at each factor (a filter)
    walk: np.ndarray | None = None   # the random walk's Allan variance over K²τ/3 at each factor (a ramp removed)
    quant: np.ndarray | None = None  # the quantizer's Allan variance over 3Q²/τ² at each factor (a quiet counter)


#: Covariance models by (samples, dt): the gyros of one record share one.
_COV_CACHE: dict = {}


def factors(n: int, m_min: int = 1) -> np.ndarray:
    """Octave averaging factors of the fits: m_min, 2·m_min, ... <= n·_M_MAX_FRACTION (m_min a power
    of 2), or the longest 6 when m_min would leave fewer."""
    m_max = max(8, int(_M_MAX_FRACTION * n))
    m = 2 ** np.arange(int(math.log2(m_max)) + 1, dtype=np.int64)
    if m.size < 6 or n - 2 * m[-1] < 2:
        raise InputError(f"{n} samples are too few for the noise fit: it needs at least 6 "
                         "octave taus (a record of >= 256 samples)")
    # a model that shapes the short τ (a very low filter cut-off) may ask to start where fewer
    # than 6 octaves are left: the fit then takes the record's longest 6
    return m[m >= m_min] if np.count_nonzero(m >= m_min) >= 6 else m[-6:]


def cov_model(n: int, dt_s: float, m_min: int = 1) -> AvarCovariance:
    key = (int(n), float(dt_s), int(m_min))
    cov = _COV_CACHE.get(key)
    if cov is None:
        if len(_COV_CACHE) >= 8:
            _COV_CACHE.clear()
        m = factors(n, m_min)
        cov = _COV_CACHE[key] = AvarCovariance(m, (n + 1) - 2 * m, 2, dt_s)
    return cov


def curve(x: np.ndarray, dt_s: float, cov: AvarCovariance | None = None, m_min: int = 1,
           white_shape=None, walk_shape=None, quant_shape=None) -> Curve:
    """``white_shape(m)`` / ``walk_shape(m)`` / ``quant_shape(m)``: the white / random-walk /
    quantization term's Allan variance over N²/τ / K²τ/3 / 3Q²/τ² at the factors ``m`` (a sensor's
    filter / a ramp taken out of the record / a counter whose angle error is not white)."""
    m = factors(x.size, m_min)
    res = deviation(x, dt_s, "oadev", m * float(dt_s))
    # the bounds read the octaves up to a third of the record (the fit stops at an eighth)
    m_long = 2 ** np.arange(int(math.log2(m[-1])) + 1, int(math.log2(max(x.size // 3, 1))) + 1)
    y_long = deviation(x, dt_s, "oadev", m_long * float(dt_s)).dev ** 2 if m_long.size else np.array([])
    m_all = np.concatenate([m, m_long])
    walk = None if walk_shape is None else np.asarray(walk_shape(m_all), dtype=float)
    return Curve(dt_s=float(dt_s), n=int(x.size), taus=m * float(dt_s), m=m,
                  y=res.dev ** 2, cov=cov_model(x.size, dt_s, m_min) if cov is None else cov,
                  caps=_caps(int(x.size), m_all * float(dt_s), m_all, np.concatenate([res.dev ** 2, y_long]),
                             walk=walk),
                  white=None if white_shape is None else np.asarray(white_shape(m), dtype=float),
                  walk=None if walk is None else walk[:m.size],
                  quant=None if quant_shape is None else np.asarray(quant_shape(m), dtype=float))


def cross_avar(X: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Overlapping Allan (co)variances of the columns of X at factors m:
    (K, N, N), [k, i, j] = mean(z_i z_j)/(2 m_k²) with z the second
    difference at lag m of the phase (cumulative sum of the rate)."""
    n, big_n = X.shape
    x = np.zeros((n + 1, big_n))
    np.cumsum(X - X.mean(axis=0), axis=0, out=x[1:])
    out = np.empty((m.size, big_n, big_n))
    for i, mm in enumerate(m):
        z = x[2 * mm:] - 2.0 * x[mm:n + 1 - mm] + x[:n + 1 - 2 * mm]
        out[i] = (z.T @ z) / (2.0 * float(mm) ** 2 * z.shape[0])
    return out


@dataclass(frozen=True, eq=False)
class Gls:
    """One GLS fit of Allan-variance columns."""

    a: np.ndarray          # coefficients
    cov: np.ndarray        # their covariance
    chi2: float
    dof: int
    white: np.ndarray      # W with W'W = Sigma^-1
    model: np.ndarray      # fitted variance per tau
    capped: tuple = ()     # coefficients held at the measured Allan variance's bound


def whitener(sigma: np.ndarray) -> np.ndarray:
    """W with W'W = Sigma^-1 (eigenvalues of the correlation clipped at 1e-12)."""
    d = np.sqrt(np.diag(sigma))
    w, vec = np.linalg.eigh(sigma / np.outer(d, d))
    w = np.maximum(w, 1e-12 * w.max())
    return (vec / np.sqrt(w)).T / d[None, :]


def solve(y: np.ndarray, G: np.ndarray, white: np.ndarray) -> tuple:
    """Weighted LS with a fixed whitener: coefficients, covariance, chi2."""
    xw = white @ G
    yw = white @ y
    s = np.linalg.norm(xw, axis=0)
    s = np.where(s > 0, s, 1.0)
    xs = xw / s
    info = xs.T @ xs
    inv = np.linalg.pinv(info)
    a = (inv @ (xs.T @ yw)) / s
    cov = inv / np.outer(s, s)
    r = xw @ a - yw
    return a, cov, float(r @ r)


def split(names: tuple, a: np.ndarray, tau_c: float | None):
    """Model coefficients by noise type (clipped at 0) for the covariance."""
    coef = {}
    gm = None
    for name, value in zip(names, a):
        if name == "gm":
            gm = (max(float(value), 0.0), tau_c)
        else:
            coef[name] = max(float(value), 0.0)
    return coef, gm


def columns(cv: Curve, names: tuple, tau_c: float | None = None) -> np.ndarray:
    cols = []
    for name in names:
        if name == "gm":
            cols.append(gauss_markov_avar(cv.taus, 1.0, tau_c, cv.dt_s))
        elif name == "n" and cv.white is not None:      # white noise through the sensor's filter
            cols.append(term_basis("oadev", name, cv.taus) * cv.white)
        elif name == "k" and cv.walk is not None:       # a random walk with a ramp taken out
            cols.append(term_basis("oadev", name, cv.taus) * cv.walk)
        elif name == "q" and cv.quant is not None:      # a quiet counter: its error follows the angle
            cols.append(term_basis("oadev", name, cv.taus) * cv.quant)
        else:
            cols.append(term_basis("oadev", name, cv.taus))
    return np.column_stack(cols)


#: Terms whose coefficient the measured Allan variance bounds from above at every τ (a random
#: walk's K²τ/3 and a flicker's (2 ln 2/π)B² can never exceed the measured variance).
_CAPPED = ("k", "b")


def _caps(n: int, taus: np.ndarray, m: np.ndarray, avar: np.ndarray, walk=None) -> dict:
    """Upper bounds of the capped coefficients: the smallest over τ (octaves to a third of the
    record) of the measured Allan variance's one-sided upper confidence bound at a 5 %
    family-wise level over those τ (χ² with the EDF of a random-walk FM estimate, the noise
    that dominates where the bound binds; Bonferroni), over the term's unit basis. What the
    data rule out at that level; a record of pure ARW + RRW leaves the free fit below it
    (tighter bounds, one standard error or 5 % per τ, held K low on 2–3 of 20 such records
    and made false bias instabilities of z 4–11); a fit that reads a hump as random walk is
    held at what the data allow."""
    nu = np.maximum(edf_simple(n + 1, m, -2), 1.0)
    hi = avar * nu / _CHI2_LOW(nu, 0.05 / max(len(taus), 1))
    shape = {"k": 1.0 if walk is None else walk}        # ``walk``: a ramp taken out (:class:`Curve`)
    return {name: float(np.min(hi / (term_basis("oadev", name, taus) * shape.get(name, 1.0))))
            for name in _CAPPED}


def _CHI2_LOW(nu, q):
    return stats.chi2.ppf(q, nu)


def gls(cv: Curve, names: tuple, tau_c: float | None = None, n_iter: int = 3,
         a0: np.ndarray | None = None) -> Gls:
    """GLS of the Allan variance on the columns ``names`` (``q``, ``n``, ``b``, ``k``: IEEE
    terms, coefficient P²; ``gm``: Gauss-Markov σ² at ``tau_c``), Sigma from the fitted model.

    A random-walk or flicker coefficient is held at the bound the measured Allan variance
    sets at every τ (:func:`_caps`) when the free fit would exceed it (the fit then explains
    a hump it has no term for with a random walk the data rule out: the ADIS16405's K of
    300 deg/h/√h against an ADEV that allows 42); its row of ``cov`` keeps the free fit's
    variance, and ``capped`` names it."""
    G = columns(cv, names, tau_c)
    a = a0
    if a is None:                       # start: relative errors from the data, independent
        a, _, _ = solve(cv.y, G, np.diag(1.0 / cv.y))
    caps = cv.caps or {}
    fixed: dict = {}
    for _ in range(n_iter):
        coef, gm = split(names, a, tau_c)
        sigma = cv.cov.covariance(coef, gm)
        if not np.all(np.diag(sigma) > 0):
            sigma = np.diag((cv.y * 1e-3) ** 2)
        white = whitener(sigma)
        a, cov, chi2 = solve(cv.y, G, white)
        for j, name in enumerate(names):
            if name in caps and (a[j] > caps[name] or name in fixed):
                fixed[name] = caps[name]
        if fixed:
            free = [j for j, nm in enumerate(names) if nm not in fixed]
            y = cv.y - sum(v * G[:, names.index(nm)] for nm, v in fixed.items())
            af, covf, chi2 = solve(y, G[:, free], white)
            a = np.array([fixed.get(nm, 0.0) for nm in names], float)
            a[free] = af
            cov_full = cov
            cov = np.zeros_like(cov_full)
            cov[np.ix_(free, free)] = covf
            for nm in fixed:
                j = names.index(nm)
                cov[j, j] = cov_full[j, j]
    return Gls(a=a, cov=cov, chi2=chi2, dof=int(cv.taus.size - G.shape[1] + len(fixed)), white=white,
                model=G @ a, capped=tuple(fixed))


# --------------------------------------------------------------------------
# Formatting helpers


def deg_h(x):
    return units.rad_s_to_deg_h(x)


def band(cv: Curve, share: np.ndarray) -> np.ndarray:
    """Taus where a term's share of the fitted variance is at least half its
    largest share (a contiguous run around the maximum)."""
    i = int(np.argmax(share))
    keep = share >= 0.5 * share[i]
    lo = i
    while lo > 0 and keep[lo - 1]:
        lo -= 1
    hi = i
    while hi < share.size - 1 and keep[hi + 1]:
        hi += 1
    return np.arange(lo, hi + 1)


def band_text(cv: Curve, idx: np.ndarray, base_model: np.ndarray) -> tuple[str, float, float]:
    """'τ a–b s', measured ADEV and baseline ADEV (deg/h, geometric means) on ``idx``."""
    meas = float(np.exp(np.mean(0.5 * np.log(cv.y[idx]))))
    pred = float(np.exp(np.mean(0.5 * np.log(np.maximum(base_model[idx], 1e-300)))))
    t0, t1 = cv.taus[idx[0]], cv.taus[idx[-1]]
    where = f"τ = {t0:.3g} s" if idx.size == 1 else f"τ {t0:.3g}–{t1:.3g} s"
    return where, deg_h(meas), deg_h(pred)


def root_sigma(a: float, sigma_a: float) -> tuple[float, float]:
    """P = √A and its 1σ: the larger distance to the images of A ± σ_A
    (the delta method σ_A/(2P) when σ_A ≪ A, finite at A <= 0, where P = 0
    and the 1σ is √σ_A: the size the data could just see)."""
    if not (math.isfinite(a) and math.isfinite(sigma_a)):
        return math.nan, math.nan
    if a <= 0:
        return 0.0, math.sqrt(max(sigma_a, 0.0))
    root = math.sqrt(a)
    return root, max(root - math.sqrt(max(a - sigma_a, 0.0)), math.sqrt(a + sigma_a) - root)


def avar_normal_score(y, mu, nu) -> np.ndarray:
    """Allan variances ``y`` ~ μ·χ²_ν/ν mapped to a Gaussian of the same mean μ and variance
    2μ²/ν (Wilson–Hilferty: (χ²_ν/ν)^(1/3) is nearly normal, mean 1 − 2/(9ν), variance 2/(9ν)).

    A linear statistic of the raw estimates inherits their right skew (skewness √(8/ν): 1.6 at
    the 3 degrees of freedom of a long octave), so an excess far out in its tail is far more
    likely than its normal calibration says. [1]_

    .. [1] E. B. Wilson, M. M. Hilferty, "The distribution of chi-square", PNAS 17, 1931.
    """
    y, mu, nu = (np.asarray(a, dtype=float) for a in (y, mu, nu))
    u = (np.cbrt(np.maximum(y / mu, 0.0)) - (1.0 - 2.0 / (9.0 * nu))) / np.sqrt(2.0 / (9.0 * nu))
    return mu * (1.0 + u * np.sqrt(2.0 / nu))
