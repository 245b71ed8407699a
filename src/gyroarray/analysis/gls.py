"""Exact generalised least squares under ARW white noise plus a random-walk bias.

The solver of the effects' regression fits (their model and conventions:
:mod:`gyroarray.effects.fitting`): e_t = X_t β + b_t + w_t with w white of
variance r, b a random walk of variance q per step and an unknown start.
It knows no effect. Units: SI inside.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyroarray.core.jit import njit

__all__ = ["MAX_COND", "GLSFit", "NotIdentifiableError", "RWWhitener", "gls_rw"]


#: Largest accepted condition number of the column-scaled normal matrix.
MAX_COND = 1e12


# -- the engine ----------------------------------------------------------------

class NotIdentifiableError(ValueError):
    """The regressors cannot be estimated from these samples.

    A regressor that vanishes after differencing (no rate about the axis, a
    constant temperature) or regressors that are collinear (condition number
    of the column-scaled normal matrix above :data:`MAX_COND`).
    """


@dataclass(frozen=True, eq=False)
class GLSFit:
    """Result of :func:`gls_rw`.

    Attributes
    ----------
    beta : ndarray, shape (p,)
        Estimated coefficients [unit of y / unit of the column of X].
    cov : ndarray, shape (p, p)
        Covariance of ``beta``, (ΔXᵀΣ⁻¹ΔX)⁻¹ [same units squared].
    chi2 : float
        Generalised residual sum of squares (Δy − ΔXβ)ᵀΣ⁻¹(Δy − ΔXβ) [-];
        ≈ χ²(dof) when the model is right.
    loglik : float
        Log-likelihood of the differences at ``beta`` [-],
        −½ (m log 2π + log det Σ + chi2); the diffuse (restricted)
        likelihood of y. Comparable between fits of the same y and use
        (other regressors, other r and q).
    n : int
        Samples used.
    n_diff : int
        Differences m (samples used minus one per run of used samples).
    n_segments : int
        Runs of consecutive used samples with at least two samples.
    """

    beta: np.ndarray
    cov: np.ndarray
    chi2: float
    loglik: float
    n: int
    n_diff: int
    n_segments: int

    @property
    def dof(self) -> int:
        """Degrees of freedom of ``chi2``: n_diff − p."""
        return self.n_diff - len(self.beta)

    @property
    def sigma(self) -> np.ndarray:
        """1σ of ``beta`` (√diag cov)."""
        return np.sqrt(np.diag(self.cov))


@njit(cache=True)
def _rw_pivots(link, rho):  # pragma: no cover - compiled
    """Bidiagonal Cholesky factor of the normalised differenced covariance.

    Σ̃ = tridiag(−ρ·link, 1, −ρ·link) = L Lᵀ, L lower bidiagonal with
    diagonal l_i and sub-diagonal −c_i:
        c_i = ρ·link_i / l_{i−1},   l_i = √(1 − c_i²),   c_0 = 0, l_0 = 1.
    Returns 1/l, c and log det Σ̃ = Σ log l_i². Once l_i repeats exactly
    (the recursion has reached its fixed point in floating point) it is
    copied until the next segment starts. l_i² >= 1/2 (ρ <= 1/2), so the
    product of 256 of them is taken before each log.
    """
    m = link.size
    il = np.empty(m)
    cv = np.empty(m)
    logdet = 0.0
    prod = 1.0
    lprev = 1.0
    fixed = False
    for i in range(m):
        if i > 0 and link[i]:
            if fixed:
                ci = cv[i - 1]
                l2 = lprev * lprev
                li = lprev
            else:
                ci = rho / lprev
                l2 = 1.0 - ci * ci
                li = math.sqrt(l2)
                fixed = li == lprev
        else:
            fixed = False
            ci = 0.0
            l2 = 1.0
            li = 1.0
        cv[i] = ci
        il[i] = 1.0 / li
        lprev = li
        prod *= l2
        if (i & 255) == 255:
            logdet += math.log(prod)
            prod = 1.0
    return il, cv, logdet + math.log(prod)


@njit(cache=True)
def _rw_forward(il, cv, b):  # pragma: no cover - compiled
    """In place, every column of b (m, k): z_i = (x_i + c_i z_{i−1}) / l_i (solves L z = x)."""
    m, k = b.shape
    prev = np.zeros(k)
    for i in range(m):
        ci = cv[i]
        li = il[i]
        for j in range(k):
            z = (b[i, j] + ci * prev[j]) * li
            b[i, j] = z
            prev[j] = z


@njit(cache=True, inline="always")
def _rw_delta(x, idx, dense, i):  # pragma: no cover - compiled
    """Δ_i of :meth:`RWWhitener.diff`: x[i+1] − x[i] when ``dense``, else x[idx_i] − x[idx_i − 1]."""
    if dense:
        return x[i + 1] - x[i]
    j = idx[i]
    return x[j] - x[j - 1]


@njit(cache=True)
def _rw_whiten1(il, cv, x, idx, dense, scale):  # pragma: no cover - compiled
    """:meth:`RWWhitener.whiten` of one column x (n,) in one pass, the same bits: Δ_i (x[i+1] − x[i]
    when ``dense``, else x[idx_i] − x[idx_i − 1]), z_i = (Δ_i + c_i z_{i−1}) / l_i, times ``scale``
    (the gathers of :meth:`~RWWhitener.diff` cost 5x the recursion on a record with gaps)."""
    m = il.size
    out = np.empty(m)
    prev = 0.0
    for i in range(m):
        z = (_rw_delta(x, idx, dense, i) + cv[i] * prev) * il[i]
        prev = z
        out[i] = z * scale
    return out


#: The ``idx`` :func:`_rw_whiten1` is passed when the differences are dense (not read).
_NO_IDX = np.zeros(0, dtype=np.int64)


@njit(cache=True)
def _gram(za, zy):  # pragma: no cover - compiled
    """One pass: G = AᵀA, Aᵀy and yᵀy for A = za (m, p), y = zy (m,)."""
    m, p = za.shape
    g = np.zeros((p, p))
    aty = np.zeros(p)
    yy = 0.0
    for i in range(m):
        y = zy[i]
        yy += y * y
        for j in range(p):
            a = za[i, j]
            aty[j] += a * y
            for k in range(j + 1):
                g[j, k] += a * za[i, k]
    for j in range(p):
        for k in range(j):
            g[k, j] = g[j, k]
    return g, aty, yy


@njit(cache=True)
def _residual(za, zy, beta):  # pragma: no cover - compiled
    """One pass: |y − Aβ|² and Aᵀ(y − Aβ)."""
    m, p = za.shape
    atr = np.zeros(p)
    rr = 0.0
    for i in range(m):
        r = zy[i]
        for j in range(p):
            r -= za[i, j] * beta[j]
        rr += r * r
        for j in range(p):
            atr[j] += za[i, j] * r
    return rr, atr


class RWWhitener:
    """The whitening transform of the baseline noise for one (n, r, q, use).

    Maps a length-n column x to z = L̃⁻¹Δx/√s (m values), with Δ the first
    differences between consecutive used samples (none into a sample of
    ``breaks``: the start of a new piece with its own offset), s = q + 2r and
    Σ = s·L̃L̃ᵀ the covariance of the differenced noise. Under the baseline
    model the whitened residual is iid N(0, 1). Built once, it whitens any
    number of columns in O(m) each (the sinusoid and latency searches reuse
    it).
    """

    def __init__(self, n: int, r: float, q: float, use=None, breaks=None):
        r, q = float(r), float(q)
        if not (math.isfinite(r) and math.isfinite(q) and r >= 0.0 and q >= 0.0 and r + q > 0.0):
            raise ValueError(f"r and q must be finite, >= 0 and not both 0, got r={r!r}, q={q!r}")
        self.n = int(n)
        self.idx: np.ndarray | None
        if breaks is not None and len(breaks):
            # a new piece starts at each break (its own unknown start): the difference into it is
            # not taken, exactly as a per-piece intercept column would fit it away
            b = np.asarray(breaks, dtype=int)
            if b.ndim != 1 or np.any((b < 1) | (b >= max(self.n, 1))):
                raise ValueError(f"breaks must be sample indices in [1, {self.n - 1}], got {b!r}")
            u = np.ones(self.n, dtype=bool) if use is None else np.asarray(use, dtype=bool)
            if u.shape != (n,):
                raise ValueError(f"use must be {n} booleans, got shape {u.shape}")
            later = np.flatnonzero(u[1:] & u[:-1]) + 1
            self.idx = later[~np.isin(later, b)]
            m = self.idx.size
            self.n_used = int(u.sum())
            link = np.zeros(m, dtype=np.bool_)
            link[1:] = np.diff(self.idx) == 1
        elif use is None:
            self.idx = None                                  # differences y[1:] − y[:-1]
            m = max(self.n - 1, 0)
            self.n_used = self.n
            link = np.ones(m, dtype=np.bool_)
        else:
            u = np.asarray(use, dtype=bool)
            if u.shape != (n,):
                raise ValueError(f"use must be {n} booleans, got shape {u.shape}")
            self.idx = np.flatnonzero(u[1:] & u[:-1]) + 1    # the later sample of each Δ
            m = self.idx.size
            self.n_used = int(u.sum())
            link = np.zeros(m, dtype=np.bool_)
            link[1:] = np.diff(self.idx) == 1                # Δ_j and Δ_{j+1} share a sample
        if m:
            link[0] = False
        self.m = m
        self.n_segments = int(m - link.sum()) if m else 0
        self.s = q + 2.0 * r
        rho = r / self.s
        self.link = link
        self.il, self.cv, self.logdet_norm = _rw_pivots(link, rho)
        self.logdet = m * math.log(self.s) + self.logdet_norm   # log det Σ

    @property
    def later(self) -> np.ndarray:
        """Index of the later sample of each difference, shape (m,)."""
        return np.arange(1, self.n) if self.idx is None else self.idx

    def diff(self, *cols) -> np.ndarray:
        """Δ of the columns of the arrays ``cols`` ((n,) or (n, k) each), shape (m, K), Fortran order."""
        arrays = [np.asarray(c, dtype=float) for c in cols]
        arrays = [c[:, None] if c.ndim == 1 else c for c in arrays]
        out = np.empty((self.m, sum(c.shape[1] for c in arrays)), order="F")
        j = 0
        for c in arrays:
            for i in range(c.shape[1]):
                if self.idx is None:
                    np.subtract(c[1:, i], c[:-1, i], out=out[:, j])
                else:
                    np.subtract(c[self.idx, i], c[self.idx - 1, i], out=out[:, j])
                j += 1
        return out

    def whiten(self, *cols) -> np.ndarray:
        """z = L̃⁻¹Δx/√s of the columns of ``cols``: (m,) for one 1-D x, else (m, K) (Fortran)."""
        if len(cols) == 1 and np.ndim(cols[0]) == 1:
            x = np.asarray(cols[0], dtype=float)
            if x.shape == (self.n,):            # one column, one pass (:func:`_rw_whiten1`)
                idx = _NO_IDX if self.idx is None else self.idx
                return _rw_whiten1(self.il, self.cv, x, idx, self.idx is None, 1.0 / math.sqrt(self.s))
        b = self.diff(*cols)
        _rw_forward(self.il, self.cv, b)
        b *= 1.0 / math.sqrt(self.s)
        return b[:, 0] if (len(cols) == 1 and np.ndim(cols[0]) == 1) else b

    def whiten_at(self, x, r: float, q: float) -> tuple[np.ndarray, float]:
        """(z, log det Σ) of one column x (n,) under other variances (r, q) [x's unit squared] on
        the same samples (n, use, breaks): the same bits as ``RWWhitener(n, r, q, use,
        breaks)``'s :meth:`whiten` of x and its ``logdet``, without building that whitener (a
        likelihood scanned over q)."""
        r, q = float(r), float(q)
        if not (math.isfinite(r) and math.isfinite(q) and r >= 0.0 and q >= 0.0 and r + q > 0.0):
            raise ValueError(f"r and q must be finite, >= 0 and not both 0, got r={r!r}, q={q!r}")
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n,):
            raise ValueError(f"x must have shape ({self.n},), got {x.shape}")
        s = q + 2.0 * r
        idx = _NO_IDX if self.idx is None else self.idx
        il, cv, logdet_norm = _rw_pivots(self.link, r / s)      # the pivots of ρ = r/s, links kept
        z = _rw_whiten1(il, cv, x, idx, self.idx is None, 1.0 / math.sqrt(s))
        return z, self.m * math.log(s) + logdet_norm

    def fit_whitened(self, zy: np.ndarray, za: np.ndarray, zi: np.ndarray | None = None) -> GLSFit:
        """GLS from whitened data zy (m,) and regressors za (m, p); with whitened instruments
        ``zi`` (m, p), the instrumental-variables estimate (:meth:`fit_iv_whitened`)."""
        if zi is not None:
            return self.fit_iv_whitened(zy, za, zi)
        p = za.shape[1]
        if self.m < p + 1:
            raise ValueError(f"{self.m} differences cannot fit {p} parameters")
        if p == 0:
            yy = float(zy @ zy)
            if not math.isfinite(yy):
                raise ValueError("y and X must be finite on the used samples")
            beta, cov, chi2 = np.zeros(0), np.zeros((0, 0)), yy
        else:
            g, aty, yy = _gram(za, zy)
            if not (math.isfinite(yy) and np.all(np.isfinite(g))):
                raise ValueError("y and X must be finite on the used samples")
            d = np.sqrt(np.diag(g))
            if not np.all(d > 0):
                raise NotIdentifiableError(
                    f"regressor(s) {np.flatnonzero(~(d > 0)).tolist()} vanish after "
                    "differencing (constant over every segment)")
            gn = g / np.outer(d, d)                          # column-scaled normal matrix
            w = np.linalg.eigvalsh(gn)
            if not w[0] > w[-1] / MAX_COND:
                cond = w[-1] / w[0] if w[0] > 0 else math.inf
                raise NotIdentifiableError(f"regressors are collinear (condition number {cond:.3g} "
                                           "of the scaled normal matrix)")
            gi = np.linalg.inv(gn)
            bn = gi @ (aty / d)
            rr, atr = _residual(za, zy, bn / d)              # explicit residual
            step = gi @ (atr / d)                            # one step of iterative refinement
            bn = bn + step
            chi2 = rr - float(step @ (atr / d))              # |res − A·step|², Gn·step = Aᵀres
            beta = bn / d
            cov = gi / np.outer(d, d)
            cov = 0.5 * (cov + cov.T)
        loglik = -0.5 * (self.m * math.log(2.0 * math.pi) + self.logdet + chi2)
        return GLSFit(beta=beta, cov=cov, chi2=chi2, loglik=loglik, n=self.n_used,
                      n_diff=self.m, n_segments=self.n_segments)

    def fit_iv_whitened(self, zy: np.ndarray, za: np.ndarray, zi: np.ndarray) -> GLSFit:
        """Instrumental-variables GLS from whitened data zy (m,), regressors za (m, p) and
        instruments zi (m, p): β = (ZᵀA)⁻¹Zᵀz, χ² = |z − Aβ|², cov = c·(ZᵀA)⁻¹ZᵀZ(AᵀZ)⁻¹ with
        c = max(χ²/(m − p), 1).

        For regressors read from a reference with noise of its own (errors in
        variables): the instruments are the same columns read from a smoothed
        reference, correlated with the motion and not with the reference's noise,
        so β is not pulled toward 0 (or beyond) by that noise.
        """
        p = za.shape[1]
        if self.m < p + 1:
            raise ValueError(f"{self.m} differences cannot fit {p} parameters")
        if zi.shape != za.shape:
            raise ValueError(f"instruments must have the regressors' shape {za.shape}, got {zi.shape}")
        zia = zi.T @ za
        if not (np.all(np.isfinite(zia)) and np.all(np.isfinite(zy))):
            raise ValueError("y, X and the instruments must be finite on the used samples")
        d = np.sqrt(np.abs(np.diag(zia)))
        if not np.all(d > 0):
            raise NotIdentifiableError(f"instrument(s) {np.flatnonzero(~(d > 0)).tolist()} do not see their "
                                       "regressor after differencing")
        gn = zia / np.outer(d, d)
        sv = np.linalg.svd(gn, compute_uv=False)
        if not sv[-1] > sv[0] / MAX_COND:
            raise NotIdentifiableError(f"instruments and regressors are collinear (condition number "
                                       f"{sv[0] / sv[-1] if sv[-1] > 0 else math.inf:.3g})")
        inv = np.linalg.inv(gn) / np.outer(d, d)             # (ZᵀA)⁻¹
        beta = inv @ (zi.T @ zy)
        res = zy - za @ beta
        beta = beta + inv @ (zi.T @ res)                     # one step of iterative refinement
        res = zy - za @ beta
        chi2 = float(res @ res)
        # the residual also holds the reference's own noise, which the baseline's (r, q) do not
        # describe: the covariance is scaled by χ²/dof when that is above 1
        scale = max(chi2 / max(self.m - p, 1), 1.0)
        cov = scale * (inv @ (zi.T @ zi) @ inv.T)
        cov = 0.5 * (cov + cov.T)
        loglik = -0.5 * (self.m * math.log(2.0 * math.pi) + self.logdet + chi2)
        return GLSFit(beta=beta, cov=cov, chi2=chi2, loglik=loglik, n=self.n_used,
                      n_diff=self.m, n_segments=self.n_segments)

    def fit(self, y, x, z=None) -> GLSFit:
        """GLS of y (n,) on x (n, p); with instruments z (n, p), the IV estimate."""
        if z is None:
            w = self.whiten(x, y)
            return self.fit_whitened(w[:, -1], w[:, :-1])
        w = self.whiten(x, z, y)
        p = w.shape[1] // 2
        return self.fit_iv_whitened(w[:, -1], w[:, :p], w[:, p:2 * p])


def gls_rw(y, X, r: float, q: float, *, use=None, Z=None, breaks=None) -> GLSFit:
    """Exact GLS for a regression under white noise plus a random-walk bias.

    Parameters
    ----------
    y : array_like, shape (n,)
        Observations [rad/s] (any unit; r and q in its square).
    X : array_like, shape (n, p) or (n,)
        Regressors, p >= 0 [unit of y / unit of β].
    r : float
        Variance of the white noise w_t [rad²/s²] (N²/dt for ARW N).
    q : float
        Variance of the random-walk increments v_t [rad²/s²] (K²·dt for
        RRW K). 0 = a constant unknown bias.
    use : array_like of bool, shape (n,), optional
        Samples to include. Differences are taken only between consecutive
        used samples that are adjacent in time; each run of used samples is
        an independent piece with its own unknown start (a run of one sample
        carries no information).
    Z : array_like, shape of X, optional
        Instruments, one per regressor: the instrumental-variables GLS
        (:meth:`RWWhitener.fit_iv_whitened`), for regressors with errors of
        their own (read from a noisy reference).
    breaks : array_like of int, optional
        Samples at which a new piece starts (the first sample of each stitched
        part after the first): the difference into a break is not taken, so
        each piece has its own free offset. Exactly the GLS with one intercept
        column per piece (a unit vector after differencing) added to X.

    Returns
    -------
    GLSFit

    Raises
    ------
    ValueError
        Bad shapes, non-finite used values, r, q < 0 or both 0, fewer than
        p + 1 differences.
    NotIdentifiableError
        A regressor vanishes after differencing, or the regressors are
        collinear.

    Notes
    -----
    Model and method::

        y_t  = X_t β + b_t + w_t,   b_t = b_{t−1} + v_t,  b_0 diffuse
        Δy_t = ΔX_t β + ε_t,        ε_t = v_t + w_t − w_{t−1}      (b_0 gone)
        Σ = cov(ε) = tridiag(−r, q + 2r, −r)                          (per segment)
        Σ = s L̃L̃ᵀ,  s = q + 2r,  L̃ lower bidiagonal                  (Cholesky)
        z = L̃⁻¹Δy/√s,  A = L̃⁻¹ΔX/√s                                  (whitening)
        β̂ = (AᵀA)⁻¹Aᵀz,  cov(β̂) = (AᵀA)⁻¹,  χ² = |z − Aβ̂|²

    Differencing is a full-rank transform of (y_1, Δy) and y_1 only informs
    the free start b_0, so this is exactly the GLS of the undifferenced
    model with b_0 as a free parameter (checked against a dense GLS in the
    tests to 1e-10). Segments: the differences of two runs share no sample
    and no increment, so Σ is block-tridiagonal with a zero off-diagonal
    between runs; one factorisation handles every run.

    The factor is the scalar recursion c_i = ρ/l_{i−1}, l_i = √(1 − c_i²)
    (ρ = r/s <= 1/2, no cancellation); it and the forward substitution are
    two O(m·(p+1)) compiled loops (numba). AᵀA and Aᵀz are summed in one
    more pass, scaled to a unit diagonal and their condition checked; β is
    refined once from the explicit residual (a last pass).

    q = 0: Σ = r·tridiag(−1, 2, −1) is positive definite with condition
    ≈ 4n²/π² (2e12 at n = 2.2e6), but the recursion is benign
    (l_i² = (i+1)/(2i) exactly) and the whitened data z_i are cumulative
    sums whose rounding grows like √n·eps. Measured against an OLS with an
    intercept (the exact answer for q = 0, by QR) at n = 2.2e6, p = 2:
    relative error of β 9e-14 and of χ² 2e-13 (the same as for q > 0);
    ``test_gls_rw_q0_large_n_equals_ols_with_intercept`` checks 1e-9 at
    n = 200 000. The kernels sum sequentially (deterministic, rounding
    ~√n·eps).

    Speed (2 cores shared with other jobs, load average ≈ 3; numba kernels
    compiled and cached in ``__pycache__``, the first call of a new process
    loads them, the very first compiles them in ~2 s): n = 2.2e6, p = 2:
    0.09 s per call (median of 9; 0.12 s with q = 0, where the factor
    never reaches its fixed point); p = 4: 0.15 s; with a mask of 733
    segments: 0.14 s. O(n·p) time, O(n·p) memory.
    """
    yv = np.asarray(y, dtype=float)
    xv = np.asarray(X, dtype=float)
    if yv.ndim != 1:
        raise ValueError(f"y must be 1-D, got shape {yv.shape}")
    n = yv.size
    if xv.ndim == 1:
        xv = xv[:, None]
    if xv.ndim != 2 or xv.shape[0] != n:
        raise ValueError(f"X must be ({n}, p), got shape {np.shape(X)}")
    zv = None
    if Z is not None:
        zv = np.asarray(Z, dtype=float)
        zv = zv[:, None] if zv.ndim == 1 else zv
        if zv.shape != xv.shape:
            raise ValueError(f"Z must have the shape of X {xv.shape}, got {zv.shape}")
    return RWWhitener(n, r, q, use, breaks).fit(yv, xv, zv)
