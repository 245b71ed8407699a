"""Regression fits of the deterministic effects of one gyro's residual.

The fit side of the deterministic effects of ``shared/spec/effects.md``
(the simulate side is :mod:`gyroarray.sim.effects`). Each fit takes the
residual of ONE gyro,

    e_t = y_t − h·ω_ref,t                          [rad/s]

(gyro output minus the nominal axis times the platform-frame reference
rate, what the caller computes), explains it by one effect's regressors
under the baseline noise model, and returns an
:class:`~gyroarray.effects.fits.effect_fit.EffectFit` with the parameters in the
spec's units.

Baseline noise (the model a measurement is compared with first)
--------------------------------------------------------------
ARW white noise plus an RRW random-walk bias with an unknown starting value:

    e_t = X_t β + b_t + w_t
    b_t = b_{t−1} + v_t,   v_t ~ N(0, q),  b_0 unknown (diffuse)
    w_t ~ N(0, r)

with r = N²/dt [rad²/s²] (ARW N [rad/√s]) and q = K²·dt [rad²/s²] (RRW K
[rad/s/√s]), given by the caller. :func:`gls_rw` is the exact generalised
least-squares engine for that model; every fit is one or a few calls of it.

Significance z
--------------
Every fit's ``z`` is a standard-normal quantile of a tail probability, so
z ≈ N(0, 1) when the effect is absent and the noise model is right, and
large positive when the effect is present whatever its sign:

* k regression parameters β with covariance C: z = chi2_to_z(βᵀC⁻¹β, k).
  For one parameter this is the two-sided test of t = β/σ (|z| ≈ |t| for
  large |t|; t itself is in ``extra["t"]``). A signed z = β/σ would make a
  strongly *negative* effect (−6000 ppm) look "absent" (z = −150), against
  the "large positive = present" rule of EffectFit.
* nonlinear searches (latency beyond the linear range, the sinusoid) and the
  saturation plateau: see their docstrings.

Units: SI inside (rad, rad/s, s); spec units only at the edge, through the
named converters of :mod:`gyroarray.core.units`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft
from scipy import optimize, signal, special, stats

from gyroarray.core._numba import njit
from gyroarray.analysis._memo import by_content
from gyroarray.effects.fits.effect_fit import EffectFit, chi2_to_z
from gyroarray.core.physics import fractional_delay, tilt_basis
from gyroarray.core.units import (per_rad_s_to_per_deg_s, rad_s_to_deg_h, rad_s_to_deg_s,
                             rad_to_deg, ramp_rad_s2_to_deg_h2, ratio_to_ppm)

__all__ = ["GLSFit", "NotIdentifiableError", "gls_rw", "misalignment_basis", "fit_scale_factor", "fit_scale_and_nonlinearity",
           "fit_scale_nonlinearity", "fit_misalignment", "fit_latency", "fit_temperature_bias",
           "fit_rate_ramp", "fit_sinusoid", "fit_saturation"]

#: z at and above which an evidence sentence states the signature as found.
Z_EVIDENT = 3.0

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
    differences between consecutive used samples, s = q + 2r and
    Σ = s·L̃L̃ᵀ the covariance of the differenced noise. Under the baseline
    model the whitened residual is iid N(0, 1). Built once, it whitens any
    number of columns in O(m) each (the sinusoid and latency searches reuse
    it).
    """

    def __init__(self, n: int, r: float, q: float, use=None):
        r, q = float(r), float(q)
        if not (math.isfinite(r) and math.isfinite(q) and r >= 0.0 and q >= 0.0 and r + q > 0.0):
            raise ValueError(f"r and q must be finite, >= 0 and not both 0, got r={r!r}, q={q!r}")
        self.n = int(n)
        if use is None:
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
        b = self.diff(*cols)
        _rw_forward(self.il, self.cv, b)
        b *= 1.0 / math.sqrt(self.s)
        return b[:, 0] if (len(cols) == 1 and np.ndim(cols[0]) == 1) else b

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


def gls_rw(y, X, r: float, q: float, *, use=None, Z=None) -> GLSFit:
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
    return RWWhitener(n, r, q, use).fit(yv, xv, zv)


# -- helpers of the fits -------------------------------------------------------

def _z1(t: float) -> float:
    """Two-sided significance of one parameter: z with P(N(0,1) > z) = P(|t| > |t_obs|)."""
    return chi2_to_z(t * t, 1)


def _num(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}g}"


def pm(v: float, s: float) -> str:
    """``v ± s`` with s to two significant digits and v to the same decimal place."""
    if not (math.isfinite(s) and s > 0):
        return f"{v:.4g}"
    es = math.floor(math.log10(s))
    dec = 1 - es
    if dec <= 7 and (abs(v) >= 1e-3 or dec <= 4) and max(abs(v), s) < 1e7:
        dec = max(dec, 0)
        return f"{v:.{dec}f} ± {s:.{dec}f}"
    ev = math.floor(math.log10(max(abs(v), s)))
    scale = 10.0 ** ev
    dec = max(ev - es + 1, 0)
    return f"({v / scale:.{dec}f} ± {s / scale:.{dec}f})e{ev:d}"


def _vec(x, n: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
    return a


def _projected_rate(omega_ref_rad_s, h, n: int) -> tuple[np.ndarray, np.ndarray]:
    w = np.asarray(omega_ref_rad_s, dtype=float)
    if w.shape != (n, 3):
        raise ValueError(f"omega_ref_rad_s must have shape ({n}, 3), got {w.shape}")
    hv = np.asarray(h, dtype=float)
    if hv.shape != (3,) or abs(np.linalg.norm(hv) - 1.0) > 1e-6:
        raise ValueError(f"h must be a unit 3-vector, got {hv!r}")
    return w, w @ hv


def _not_identifiable(effect: str, gyro: int, params: dict, why: str, err: Exception) -> EffectFit:
    return EffectFit(effect=effect, gyro=gyro, params=params, sigma={}, z=0.0,
                     evidence=f"gyro {gyro}: {why}, so {effect.replace('_', ' ')} cannot be seen "
                              "in these samples",
                     extra={"identifiable": False, "reason": str(err)})


def _extra(fit: GLSFit, **kw) -> dict:
    out = {"identifiable": True, "chi2": fit.chi2, "dof": fit.dof, "loglik": fit.loglik,
           "n_used": fit.n}
    out.update(kw)
    return out


# -- scale factor and nonlinearity ---------------------------------------------

def fit_scale_factor(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float, gyro: int,
                     *, use=None, instrument=None) -> EffectFit:
    """Scale-factor error: residual proportional to the rate about the axis.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual y − h·ω_ref [rad/s].
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s].
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    time_s : array_like, shape (n,)
        Sample times [s] (uniform; only its length is used here).
    dt_s : float
        Sample step [s] (not used here; the common signature).
    r : float
        ARW variance per sample, N²/dt [rad²/s²].
    q : float
        RRW increment variance per sample, K²·dt [rad²/s²].
    gyro : int
        1-based gyro number (for the result).
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`gls_rw`).
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables) is fitted by instrumental variables, the columns read from
        ``omega_ref_rad_s`` instrumented by the same columns read from this.

    Returns
    -------
    EffectFit
        ``scale_factor``: ``ppm`` with sigma; z = two-sided significance.

    Notes
    -----
    ::

        e_t = s·u_t + b_t + w_t,   u_t = h·ω_ref,t,   ppm = s·1e6
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    _vec(time_s, n, "time_s")
    _, u = _projected_rate(omega_ref_rad_s, h, n)
    ui = None if instrument is None else _projected_rate(instrument, h, n)[1]
    try:
        fit = gls_rw(e, u, r, q, use=use, Z=ui)
    except NotIdentifiableError as err:
        return _not_identifiable("scale_factor", gyro, {"ppm": 0.0}, "there is no rate about its axis", err)
    return _scale_fit(fit, 0, gyro, joint_with_nonlinearity=False, instrumented=ui is not None)


def _scale_fit(fit: GLSFit, i: int, gyro: int, **extra) -> EffectFit:
    b, s = float(fit.beta[i]), float(fit.sigma[i])
    ppm, ppm_s = ratio_to_ppm(b), ratio_to_ppm(s)
    t = b / s
    z = _z1(t)
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} residual {'rises' if b > 0 else 'falls'} {_num(abs(b) * 100, 2)} % of the "
              f"rate about its axis ({pm(ppm, ppm_s)} ppm); the model has no such slope")
    else:
        ev = (f"gyro {gyro} residual shows no significant slope with the rate about its axis "
              f"({pm(ppm, ppm_s)} ppm, z = {z:.1f})")
    return EffectFit("scale_factor", gyro, {"ppm": ppm}, {"ppm": ppm_s}, z, ev,
                     _extra(fit, t=t, **extra))


def fit_scale_and_nonlinearity(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float,
                               gyro: int, *, use=None, instrument=None) -> tuple[EffectFit, EffectFit]:
    """Scale factor and quadratic nonlinearity fitted jointly.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual y − h·ω_ref [rad/s].
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s].
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`gls_rw`).
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables) is fitted by instrumental variables, the columns read from
        ``omega_ref_rad_s`` instrumented by the same columns read from this.

    Returns
    -------
    (EffectFit, EffectFit)
        ``scale_factor`` (``ppm``) and ``scale_nonlinearity``
        (``k2_per_deg_s``), each with its own sigma and z (the marginal
        two-sided test of its coefficient in the joint fit); the
        correlation of the two is in ``extra["corr"]`` of both.

    Notes
    -----
    ::

        e_t = s·u_t + k2_SI·u_t² + b_t + w_t,   u_t = h·ω_ref,t
        k2 [1/(deg/s)] = k2_SI [1/(rad/s)] · π/180

    (sim: y = (1 + s)·u + k2·u² in deg/s). Fitting u and u² together keeps a
    linear error out of k2 when the rate is not symmetric about zero.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    _vec(time_s, n, "time_s")
    _, u = _projected_rate(omega_ref_rad_s, h, n)
    ui = None if instrument is None else _projected_rate(instrument, h, n)[1]
    try:
        fit = gls_rw(e, np.column_stack([u, u * u]), r, q, use=use,
                     Z=None if ui is None else np.column_stack([ui, ui * ui]))
    except NotIdentifiableError as err:
        why = "the rate about its axis does not vary enough to separate u from u²"
        return (_not_identifiable("scale_factor", gyro, {"ppm": 0.0}, why, err),
                _not_identifiable("scale_nonlinearity", gyro, {"k2_per_deg_s": 0.0}, why, err))
    corr = float(fit.cov[0, 1] / (fit.sigma[0] * fit.sigma[1]))
    sf = _scale_fit(fit, 0, gyro, joint_with_nonlinearity=True, corr=corr, instrumented=ui is not None)
    b, s = float(fit.beta[1]), float(fit.sigma[1])
    k2, k2_s = per_rad_s_to_per_deg_s(b), per_rad_s_to_per_deg_s(s)
    t = b / s
    z = _z1(t)
    if use is not None:
        u = u[np.asarray(use, dtype=bool)]
    umax = float(rad_s_to_deg_s(np.max(np.abs(u))))
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} residual grows with the square of the rate about its axis "
              f"(k2 = {pm(k2, k2_s)} per deg/s, {_num(k2 * umax * umax, 2)} deg/s at "
              f"{_num(umax, 3)} deg/s); the model has no such curvature")
    else:
        ev = (f"gyro {gyro} residual shows no significant curvature with the rate about its axis "
              f"(k2 = {pm(k2, k2_s)} per deg/s, z = {z:.1f})")
    nl = EffectFit("scale_nonlinearity", gyro, {"k2_per_deg_s": k2}, {"k2_per_deg_s": k2_s}, z, ev,
                   _extra(fit, t=t, corr=corr, ppm_joint=sf.params["ppm"], ppm_joint_z=float(sf.z),
                          instrumented=ui is not None))
    return sf, nl


def fit_scale_nonlinearity(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float,
                           gyro: int, *, use=None, instrument=None) -> EffectFit:
    """Quadratic nonlinearity ``k2_per_deg_s``, fitted jointly with the scale factor.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual y − h·ω_ref [rad/s].
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s].
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include.
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables) is fitted by instrumental variables, the columns read from
        ``omega_ref_rad_s`` instrumented by the same columns read from this.

    Returns
    -------
    EffectFit
        The second result of :func:`fit_scale_and_nonlinearity`.

    Notes
    -----
    ::

        e_t = s·u_t + k2_SI·u_t² + b_t + w_t,   k2 = k2_SI · π/180
    """
    return fit_scale_and_nonlinearity(e, omega_ref_rad_s, h, time_s, dt_s, r, q, gyro, use=use,
                                      instrument=instrument)[1]


# -- misalignment ----------------------------------------------------------------

def misalignment_basis(h) -> tuple[np.ndarray, np.ndarray]:
    """The orthonormal basis (e1, e2) ⟂ h of :func:`gyroarray.core.physics.tilted_axes` (one axis).

    Parameters
    ----------
    h : array_like, shape (3,)
        Nominal unit axis [-].

    Returns
    -------
    e1, e2 : ndarray, shape (3,)
        e1 = (ẑ − (ẑ·h)h)/|ẑ × h| (toward +z, tilt azimuth ψ = 0),
        e2 = ẑ × h/|ẑ × h| (horizontal, increasing azimuth, ψ = 90°);
        for h along ±z: e1 = +x, e2 = +y.
    """
    e1, e2 = tilt_basis(np.asarray(h, dtype=float)[None, :])
    return e1[0], e2[0]


def _tilt_fit(wh, zy0: np.ndarray, zu: np.ndarray, za: np.ndarray, seen, zi=None) -> tuple:
    """GLS of the tilt components c on the whitened perpendicular rates (along ``seen`` only
    when not None; instrumented by ``zi`` when given), the θ²/2·u term put back twice:
    (fit, c, cov, χ², dof)."""
    one_way = seen is not None
    cos_t = 1.0
    for _ in range(3):                       # plain fit, then the θ²/2·u term put back twice
        zy = zy0 + (1.0 - cos_t) * zu
        if one_way:
            fit = wh.fit_whitened(zy, (za @ seen)[:, None], None if zi is None else (zi @ seen)[:, None])
            c = seen * fit.beta[0]
            cov = np.outer(seen, seen) * fit.cov[0, 0]
            chi2 = float(fit.beta[0] ** 2 / fit.cov[0, 0])
            dof = 1
        else:
            fit = wh.fit_whitened(zy, za, zi)
            c, cov = fit.beta, fit.cov
            chi2 = float(c @ np.linalg.solve(cov, c))
            dof = 2
        cos_t = math.sqrt(max(1.0 - float(c @ c), 0.0))
    return fit, c, cov, chi2, dof


def _tilt_sigmas(c: np.ndarray, cov: np.ndarray, cn: float, sin_t: float, dof: int) -> dict:
    """1σ of the tilt [deg], and of its azimuth [deg] where the data measure it."""
    sigma = {}
    if cn > 0 and sin_t < 1.0:
        gt = c / (cn * math.sqrt(1.0 - sin_t ** 2))       # dθ/dc
        sigma["tilt_deg"] = float(rad_to_deg(math.sqrt(gt @ cov @ gt)))
    else:
        sigma["tilt_deg"] = float(rad_to_deg(math.sqrt(np.linalg.eigvalsh(cov)[-1])))
    cn_sigma = math.sqrt(c @ cov @ c) / cn if cn > 0 else math.inf
    if dof == 2 and cn > 3.0 * cn_sigma:                   # one direction: ψ is assumed, not measured
        gp = np.array([-c[1], c[0]]) / cn ** 2            # dψ/dc
        sigma["tilt_azimuth_deg"] = float(rad_to_deg(math.sqrt(gp @ cov @ gp)))
    return sigma


def _misalignment_evidence(gyro: int, z: float, tilt: float, psi: float, sigma: dict) -> str:
    """The sentence that reports the tilt (or its absence)."""
    if z >= Z_EVIDENT:
        az = (f" toward azimuth {pm(psi, sigma['tilt_azimuth_deg'])}° around it (0° = toward +z)"
              if "tilt_azimuth_deg" in sigma else "")
        ev = (f"gyro {gyro} residual follows the rate about axes perpendicular to its own: its true "
              f"axis is tilted {pm(tilt, sigma['tilt_deg'])}° from the nominal one{az}")
    else:
        ev = (f"gyro {gyro} residual shows no significant response to the rate about other axes "
              f"(tilt {pm(tilt, sigma['tilt_deg'])}°, z = {z:.1f})")
    return ev


def fit_misalignment(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float, gyro: int,
                     *, use=None, instrument=None) -> EffectFit:
    """True sensitive axis: residual proportional to the rate about other axes.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual y − h·ω_ref [rad/s].
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s].
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`gls_rw`).
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables) is fitted by instrumental variables, the columns read from
        ``omega_ref_rad_s`` instrumented by the same columns read from this.

    Returns
    -------
    EffectFit
        ``misalignment``: ``tilt_deg`` (with sigma) and ``tilt_azimuth_deg``
        (ψ; the true unit axis, platform frame, in ``extra["axis"]``), with sigma
        when the tilt exceeds 3 of its σ); z from the χ² of (c1, c2) with 2
        degrees of freedom (1 when the motion sees one direction only).

    Notes
    -----
    With the basis of :func:`misalignment_basis` (the convention of
    ``gyroarray.core.physics.tilted_axes``)::

        a   = cos θ h + sin θ (cos ψ e1 + sin ψ e2)            (true axis)
        e_t = (a − h)·ω_t + b_t + w_t
            = c1·(e1·ω_t) + c2·(e2·ω_t) + b_t + w_t − (1 − cos θ)·u_t
        c1 = sin θ cos ψ,  c2 = sin θ sin ψ
        θ = asin|c|,  ψ = atan2(c2, c1),  a = √(1 − |c|²) h + c1 e1 + c2 e2

    The last term of e_t, (1 − cos θ)·u ≈ θ²/2·u, is second order (a
    scale-factor-like −152 ppm at θ = 1°, which a table run resolves to
    ~10 ppm): it is put back with the θ of the previous fit and (c1, c2)
    refitted, twice (the change of θ² after the second pass is below 1e-6
    of it at θ = 1°). σ by the delta method from cov(c1, c2). When the motion leaves one direction of the
    (e1, e2) plane unseen (rotation about a single axis), the fit uses the
    seen direction only: the tilt component along it (the unseen component
    taken as 0, so ψ has no sigma), ``extra["unseen"]`` the unseen unit
    vector, 1 degree of freedom.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    _vec(time_s, n, "time_s")
    w, _ = _projected_rate(omega_ref_rad_s, h, n)
    hv = np.asarray(h, dtype=float)
    e1, e2 = misalignment_basis(hv)
    basis = np.column_stack([e1, e2])                      # (3, 2)
    x = w @ basis                                          # (n, 2)
    wh = RWWhitener(n, r, q, use)
    zx = wh.whiten(x, e, w @ hv)
    za, zy0, zu = zx[:, :2], zx[:, 2], zx[:, 3]
    zi = None if instrument is None else wh.whiten(_projected_rate(instrument, hv, n)[0] @ basis)
    g = za.T @ za
    lam, vec = np.linalg.eigh(g)
    unseen = None
    none = {"tilt_deg": 0.0, "tilt_azimuth_deg": 0.0}
    if not lam[1] > 0:
        return _not_identifiable("misalignment", gyro, none, "there is no rate about the axes "
                                 "perpendicular to its axis", NotIdentifiableError("no rate ⟂ h"))
    one_way = lam[0] < lam[1] / MAX_COND
    if one_way:
        seen = vec[:, 1]
        unseen = basis @ vec[:, 0]
    fit, c, cov, chi2, dof = _tilt_fit(wh, zy0, zu, za, seen if one_way else None, zi)
    z = chi2_to_z(chi2, dof)
    cn = float(np.hypot(c[0], c[1]))
    sin_t = min(cn, 1.0)
    axis = math.sqrt(1.0 - sin_t ** 2) * hv + c[0] * e1 + c[1] * e2
    axis = axis / np.linalg.norm(axis)
    tilt = rad_to_deg(math.asin(sin_t))
    psi_rad = math.atan2(c[1], c[0])
    psi = rad_to_deg(psi_rad)
    sigma = _tilt_sigmas(c, cov, cn, sin_t, dof)
    # tilt + azimuth (not also ``axis``: a model entry takes one form or the other);
    # the true axis itself is in extra["axis"]
    params = {"tilt_deg": float(tilt), "tilt_azimuth_deg": float(psi)}
    ev = _misalignment_evidence(gyro, z, tilt, psi, sigma)
    extra = _extra(fit, c=[float(v) for v in c], cov_c=cov.tolist(), chi2_c=chi2, dof_c=dof,
                   axis=[float(v) for v in axis], instrumented=zi is not None)
    if unseen is not None:
        extra["unseen"] = [float(v) for v in unseen]
        ev += "; the motion does not show a tilt toward " + \
            "(" + ", ".join(f"{v:.3f}" for v in unseen) + ")"
    return EffectFit("misalignment", gyro, params, sigma, z, ev, extra)


# -- latency ---------------------------------------------------------------------

def _delay_bracket(d: float, dt: float) -> tuple[float, float]:
    """Where a delay refined from the linear estimate d [s] is looked for [s]."""
    return max(0.0, 0.5 * d - dt), 2.0 * d + 2.0 * dt


def _refine_delay(wh, ze: np.ndarray, e: np.ndarray, u: np.ndarray, du: np.ndarray, d: float,
                  dt: float) -> tuple:
    """Delay by χ² of the fractionally delayed rate: grid from the linear estimate d, Brent, one
    Gauss–Newton step; (delay [s], 1σ [s], z, extra entries)."""
    n = e.size
    chi2_0 = float(ze @ ze)

    def model(dd):
        return fractional_delay(u[:, None], [dd / dt])[:, 0] - u

    def chi2(dd):
        zr = ze - wh.whiten(model(dd))
        return float(zr @ zr)

    lo, hi = _delay_bracket(d, dt)
    grid = np.linspace(lo, hi, 9)
    vals = np.array([chi2(g) for g in grid])
    k = int(np.argmin(vals))
    for _ in range(3):                                   # minimum at the top: look further
        if k < grid.size - 1 or 2.0 * grid[-1] >= (n - 2) * dt:
            break
        grid = np.linspace(grid[-2], 2.0 * grid[-1], 9)
        vals = np.array([chi2(g) for g in grid])
        k = int(np.argmin(vals))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = optimize.minimize_scalar(chi2, bounds=(a, b), method="bounded",
                                   options={"xatol": 1e-3 * dt})
    dd = float(res.x)
    deriv = -fractional_delay(du[:, None], [dd / dt])[:, 0]
    zg = wh.whiten(deriv, e - model(dd))
    step = wh.fit_whitened(zg[:, 1], zg[:, :1])
    d_new = dd + float(step.beta[0])
    if d_new >= 0.0 and chi2(d_new) <= res.fun:
        dd = d_new
    chi2_d = chi2(dd)
    d, sd = dd, float(step.sigma[0])
    z = chi2_to_z(max(chi2_0 - chi2_d, 0.0), 1)
    return d, sd, z, dict(refined=True, chi2=chi2_d, chi2_no_delay=chi2_0,
                          grid_s=[float(g) for g in grid])


def _refine_delay_iv(wh, e: np.ndarray, u: np.ndarray, du: np.ndarray, dui: np.ndarray, d: float,
                     dt: float) -> tuple:
    """Delay by the instrumental-variables moment of the fractionally delayed rate: Gauss–Newton
    steps on Zᵀ(e − m(d)) = 0 with Z = −D_d u̇ of the smoothed reference (the χ² of
    :func:`_refine_delay` would read the reference's own noise); (delay [s], 1σ [s], z, extra)."""
    def at(dd):
        m = fractional_delay(u[:, None], [dd / dt])[:, 0] - u
        zg = wh.whiten(-fractional_delay(du[:, None], [dd / dt])[:, 0], e - m,
                       -fractional_delay(dui[:, None], [dd / dt])[:, 0])
        return zg[:, 0], zg[:, 1], zg[:, 2]

    d0, (lo, hi) = d, _delay_bracket(d, dt)                           # the χ² search's bracket
    for _ in range(6):
        zj, zr, zi = at(d)
        step = float(zi @ zr) / float(zi @ zj)
        d += step
        if not lo <= d <= hi:                      # the moment has no root near the start: keep it
            d = d0
            break
        if abs(step) < 1e-4 * dt:
            break
    zj, zr, zi = at(d)
    chi2 = float(zr @ zr)
    sd = math.sqrt(float(zi @ zi) * max(chi2 / max(zr.size - 1, 1), 1.0)) / abs(float(zi @ zj))
    return d, sd, _z1(d / sd), dict(refined=d != d0, chi2=chi2, instrumented=True)


def _latency_evidence(gyro: int, z: float, d: float, sd: float, dt: float) -> str:
    """The sentence that reports the delay (or its absence)."""
    samples = d / dt
    if z >= Z_EVIDENT:
        lead = "lags" if d > 0 else "leads"
        ev = (f"gyro {gyro} residual follows the angular acceleration about its axis: the output "
              f"{lead} the reference by {pm(abs(d) * 1e3, sd * 1e3)} ms ({_num(abs(samples), 3)} samples)")
    else:
        ev = (f"gyro {gyro} residual shows no significant response to the angular acceleration "
              f"about its axis (delay {pm(d * 1e3, sd * 1e3)} ms, z = {z:.1f})")
    return ev


def fit_latency(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float, gyro: int,
                *, use=None, refine: bool = True, instrument=None) -> EffectFit:
    """Latency: residual proportional to the angular acceleration about the axis.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual y − h·ω_ref [rad/s].
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s].
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s] (centred differences; the fractional delay).
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`gls_rw`).
    refine : bool
        Refine a significant delay longer than half a sample by the
        nonlinear search below.
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables); −u̇ is instrumented by the smoothed −u̇ and the refinement
        solves the instrumented moment (:func:`_refine_delay_iv`), z is then
        the Wald ratio d/σ.

    Returns
    -------
    EffectFit
        ``latency``: ``delay_s`` with sigma. A negative delay (output ahead
        of the reference) is reported as fitted.

    Notes
    -----
    Linear start (the sensed rate delayed by d, to first order)::

        u_t = h·ω_ref,t,  u̇_t = (u_{t+1} − u_{t−1})/(2 dt)  (one-sided at the ends)
        e_t = u(t − d) − u(t) + b_t + w_t ≈ d·(−u̇_t) + b_t + w_t

    → d₀, σ₀ by :func:`gls_rw`, z = two-sided significance of d₀/σ₀.

    Refinement (when ``refine``, d₀ > dt/2 and |d₀/σ₀| > 5): the exact model
    of the simulator, m_t(d) = D_d u_t − u_t with D_d the cubic Lagrange
    fractional delay (``gyroarray.core.physics.fractional_delay``), and
    χ²(d) = GLS χ² of e − m(d) with no regressor. A grid of 9 delays on
    [max(0, d₀/2 − dt), 2d₀ + 2dt], then a bounded Brent search between the
    neighbours of the grid minimum (the grid moves up, at most 3 times, while
    its minimum is its last point; Brent to 1e-3 samples), then one
    Gauss–Newton step (regressor ∂m/∂d = −D_d u̇, kept if χ² does not rise)
    that also gives σ_d. Then z = chi2_to_z(χ²(0) − χ²(d̂), 1) (the
    likelihood-ratio statistic). Cost at n = 2.2e6: about 1 s.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    _vec(time_s, n, "time_s")
    _, u = _projected_rate(omega_ref_rad_s, h, n)
    dt = float(dt_s)
    du = np.gradient(u, dt)
    dui = None if instrument is None else np.gradient(_projected_rate(instrument, h, n)[1], dt)
    wh = RWWhitener(n, r, q, use)
    zz = wh.whiten(-du, e) if dui is None else wh.whiten(-du, e, -dui)
    try:
        fit = wh.fit_whitened(zz[:, 1], zz[:, :1], None if dui is None else zz[:, 2:3])
    except NotIdentifiableError as err:
        return _not_identifiable("latency", gyro, {"delay_s": 0.0},
                                 "the rate about its axis never changes", err)
    d, sd = float(fit.beta[0]), float(fit.sigma[0])
    t = d / sd
    z = _z1(t)
    extra = _extra(fit, t=t, d_linear_s=d, sigma_linear_s=sd, refined=False, instrumented=dui is not None)
    if refine and d > 0.5 * dt and abs(t) > 5.0:
        d, sd, z, more = (_refine_delay(wh, zz[:, 1], e, u, du, d, dt) if dui is None else
                          _refine_delay_iv(wh, e, u, du, dui, d, dt))
        extra.update(more)
    ev = _latency_evidence(gyro, z, d, sd, dt)
    return EffectFit("latency", gyro, {"delay_s": d}, {"delay_s": sd}, z, ev, extra)


# -- temperature and rate ramp -------------------------------------------------------

#: Smoothing times of the temperature reading before its derivative is taken [s] (a zero-phase
#: second-order low-pass at 1/T_s): a thermometer's read noise is white, and its derivative
#: would otherwise be noise (the CATS tag's reading: 0.028 °C rms, lag-1 correlation of its
#: differences −0.50).
LAG_SMOOTHING_S = (30.0, 100.0, 300.0, 1000.0)

#: χ² drop at which the thermal-lag column enters the temperature fit: χ²(1) at 1 % after the
#: choice among the smoothings of :data:`LAG_SMOOTHING_S` (Bonferroni, 0.25 % each).
LAG_CHI2 = 9.14


def temperature_rates(temp_c, dt_s: float) -> dict[float, np.ndarray]:
    """The thermal-lag columns a record allows: dT/dt of the temperature reading [°C/s],
    smoothed (zero-phase second-order Butterworth low-pass at 1/T_s, then central
    differences), for each T_s of :data:`LAG_SMOOTHING_S` within [8·dt, span/8]."""
    temp = np.asarray(temp_c, dtype=float)
    out = {}
    for sm in LAG_SMOOTHING_S:
        if not 8.0 * dt_s <= sm <= dt_s * temp.size / 8.0:
            continue
        b, a = signal.butter(2, min(2.0 * dt_s / sm, 0.99))     # cut-off over Nyquist
        pad = min(temp.size - 1, int(3 * sm / dt_s))
        out[sm] = np.gradient(signal.filtfilt(b, a, temp, padtype="odd", padlen=pad), dt_s)
    return out


def temperature_columns(temp: np.ndarray, rate: np.ndarray | None = None) -> np.ndarray:
    """The temperature fit's regressors (n, 1 or 2): T − T_0, and the thermal-lag column."""
    return (temp - temp[0])[:, None] if rate is None else np.column_stack([temp - temp[0], rate])


def _lag_columns(e, temp, r: float, q: float, use, base: GLSFit,
                 rates: dict) -> tuple[GLSFit, float | None]:
    """The fit with the thermal-lag column beside T − T_0, when it lowers χ² by more than
    :data:`LAG_CHI2` (the best smoothing of ``rates``), else ``base`` and None."""
    best, best_s = base, None
    for sm, rate in rates.items():
        try:
            fit = gls_rw(e, temperature_columns(temp, rate), r, q, use=use)
        except NotIdentifiableError:     # dT/dt ∝ T − const (an exponential approach) or flat
            continue
        if fit.chi2 < best.chi2 - (LAG_CHI2 if best_s is None else 0.0):
            best, best_s = fit, sm
    return best, best_s


def fit_temperature_bias(e, temp_c, time_s, dt_s: float, r: float, q: float, gyro: int,
                         *, use=None, rates: dict | None = None) -> EffectFit:
    """Temperature-dependent bias: residual following the temperature.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual [rad/s].
    temp_c : array_like, shape (n,)
        Temperature reading at the array [°C].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`gls_rw`).
    rates : dict, optional
        The thermal-lag columns, :func:`temperature_rates` of ``temp_c`` (a caller
        fitting several gyros on one temperature computes them once). Default:
        computed here.

    Returns
    -------
    EffectFit
        ``temperature_bias``: ``deg_h_per_c`` with sigma, and
        ``t0_c = temp_c[0]`` without sigma. ``extra``: ``thermal_lag_s`` and its
        ``thermal_lag_sigma_s``, ``lag_smoothing_s`` (None without the lag column).

    Notes
    -----
    ::

        e_t = k·(T_t + τ·dT_t/dt − T_0) + b_t + w_t,   T_0 = temp_c[0]

    The temperature of zero bias t0 is not identifiable: k·(T − t0) =
    k·(T − T_0) + k·(T_0 − t0), and the constant joins the unknown starting
    bias. So ``t0_c`` is reported as the first temperature (the model then
    starts with the fitted starting bias, as the baseline does).

    τ is a thermal lag between the thermometer and the gyro (first order: the
    gyro's own temperature is T + τ·dT/dt). It is a nuisance: ``shared/spec``'s
    ``temperature_bias`` has no lag, and the calibrated model predicts k·(T − t0).
    Without it, a fast temperature change (the CATS tag: 16 → 9 °C in 10 min)
    has a smaller response than the slow cycle, and the GLS, which reads the
    coefficient from the changes, gives 60 deg/h/°C on its gyro 2 where the
    levels give 96 and the sensor's two other periods 93 and 93; with the lag
    column (τ ≈ 246 s) 92 ± 8 in `compare`. The column is dT/dt of the reading smoothed at
    one of :data:`LAG_SMOOTHING_S` (the best, within [8·dt, span/8]), and it
    enters only when it lowers the GLS χ² by more than :data:`LAG_CHI2` (a
    pre-test at 1 %: without a lag the coefficient keeps the power of the
    one-column fit). A first-order approach to a final temperature has dT/dt ∝
    T − const: the lag is then not identifiable and the column stays out.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    _vec(time_s, n, "time_s")
    temp = _vec(temp_c, n, "temp_c")
    t0 = float(temp[0])
    try:
        fit = gls_rw(e, temp - t0, r, q, use=use)
    except NotIdentifiableError as err:
        return _not_identifiable("temperature_bias", gyro, {"deg_h_per_c": 0.0, "t0_c": t0},
                                 "the temperature does not change", err)
    fit, sm = _lag_columns(e, temp, r, q, use, fit, temperature_rates(temp, dt_s) if rates is None else rates)
    b, s = float(fit.beta[0]), float(fit.sigma[0])
    k, ks = rad_s_to_deg_h(b), rad_s_to_deg_h(s)
    t = b / s
    z = _z1(t)
    lag = lag_s = None
    lag_txt = ""
    if sm is not None:                   # τ = c/k, its σ by the delta method from the fit's covariance
        c, cov = float(fit.beta[1]), fit.cov
        lag = c / b
        lag_s = (abs(lag) * math.sqrt(max(cov[1, 1] / c ** 2 + cov[0, 0] / b ** 2 - 2.0 * cov[0, 1] / (b * c),
                                          0.0))) if c != 0 else math.inf
        lag_txt = (f", the gyro leading the temperature reading by {pm(lag, lag_s)} s (a thermal lag, "
                   f"fitted as a dT/dt term on the reading smoothed over {sm:.0f} s)")
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} residual follows the temperature: {pm(k, ks)} deg/h per °C "
              f"relative to {t0:.2f} °C{lag_txt}; the model has no temperature term")
    else:
        ev = (f"gyro {gyro} residual shows no significant temperature dependence "
              f"({pm(k, ks)} deg/h per °C, z = {z:.1f}{lag_txt})")
    return EffectFit("temperature_bias", gyro, {"deg_h_per_c": k, "t0_c": t0}, {"deg_h_per_c": ks},
                     z, ev, _extra(fit, t=t, thermal_lag_s=lag, thermal_lag_sigma_s=lag_s, lag_smoothing_s=sm))


def fit_rate_ramp(e, time_s, dt_s: float, r: float, q: float, gyro: int, *, use=None) -> EffectFit:
    """Rate ramp: a bias that grows linearly with time.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual [rad/s].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`gls_rw`).

    Returns
    -------
    EffectFit
        ``rate_ramp``: ``r_deg_h2`` with sigma.

    Notes
    -----
    ::

        e_t = R·t + b_t + w_t      (t = time_s, absolute; R·t_0 joins b_0)
        Δe_t = R·Δt + v_t + w_t − w_{t−1}

    i.e. R is the mean drift of the random walk; its σ is ≈ K/√T for RRW K
    over a record of T seconds.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    t = _vec(time_s, n, "time_s")
    try:
        fit = gls_rw(e, t - t[0], r, q, use=use)
    except NotIdentifiableError as err:
        return _not_identifiable("rate_ramp", gyro, {"r_deg_h2": 0.0}, "no time passes", err)
    b, s = float(fit.beta[0]), float(fit.sigma[0])
    rr, rs = ramp_rad_s2_to_deg_h2(b), ramp_rad_s2_to_deg_h2(s)
    tt = b / s
    z = _z1(tt)
    span = float(t[-1] - t[0])
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} bias drifts linearly: {pm(rr, rs)} deg/h², "
              f"{_num(rad_s_to_deg_h(b * span), 3)} deg/h over the {_num(span, 4)} s record, "
              "beyond what its rate random walk explains")
    else:
        ev = (f"gyro {gyro} bias shows no significant linear drift beyond its rate random walk "
              f"({pm(rr, rs)} deg/h², z = {z:.1f})")
    return EffectFit("rate_ramp", gyro, {"r_deg_h2": rr}, {"r_deg_h2": rs}, z, ev, _extra(fit, t=tt))


# -- sinusoid ------------------------------------------------------------------------

def _fast_len_below(n: int) -> int:
    """The largest FFT length <= n made of the factors 2, 3, 5, 7, 11 (fast for pocketfft)."""
    prev = getattr(sfft, "prev_fast_len", None)
    if prev is not None:
        return int(prev(n, real=True))
    k = n
    while k > 1:
        rest = k
        for f in (2, 3, 5, 7, 11):
            while rest % f == 0:
                rest //= f
        if rest == 1:
            return k
        k -= 1
    return 1


def _logp_to_z(log_p: float) -> float:
    """Standard-normal quantile z with P(N(0,1) > z) = exp(log_p), finite far out.

    χ²(2) has the tail exp(−x/2), so this is chi2_to_z(−2·log_p, 2).
    """
    if log_p > -700.0:
        return float(-special.ndtri(min(math.exp(log_p), 1.0 - 1e-16)))
    return chi2_to_z(-2.0 * log_p, 2)


#: Half-width of the periodogram window that sets a bin's local level [bins] (fewer on records of
#: fewer than 20 times as many bins), and the guard about the bin left out of it, a tenth of the
#: half-width: a real line wanders (the MPU-6050's 46.8 Hz line spreads over ±30 bins of a 25 min
#: record) and must not raise its own level.
_LEVEL_HALF = 2000

#: Bins above this many times the first pass's level are left out of the second (other lines).
_LEVEL_CLIP = 30.0

#: Periodograms of fewer bins keep the model's level (a window needs neighbours).
_LEVEL_MIN_BINS = 400

#: False: the model's level, as before (tests/test_regress.py shows the two apart). Read in this
#: process only, and not part of :func:`fit_sinusoid`'s cache key: a study calls ``__wrapped__``.
_LOCAL_LEVEL = True


def _window_mean(p: np.ndarray, keep: np.ndarray, half, guard) -> tuple:
    """Mean of ``p`` over the kept bins within ``half`` of each bin, those within ``guard`` left
    out (``half``, ``guard``: per bin or one for all): (mean, number of bins in it)."""
    c = np.concatenate([[0.0], np.cumsum(np.where(keep, p, 0.0))])
    ck = np.concatenate([[0], np.cumsum(keep)])
    i = np.arange(p.size)

    def window(a, b):
        lo, hi = np.clip(i + a, 0, p.size), np.clip(i + b, 0, p.size)
        return c[hi] - c[lo], ck[hi] - ck[lo]

    s_out, k_out = window(-half, half + 1)
    s_in, k_in = window(-guard, guard + 1)
    k = k_out - k_in
    return (s_out - s_in) / np.maximum(k, 1), k


def _local_level(p: np.ndarray) -> tuple:
    """Each bin's local level (:func:`_window_mean`, twice: the bins far above the first pass's
    level, other lines, left out of the second) and the number of bins it averages."""
    i = np.arange(p.size)
    # centred on the bin (a level that slopes, a filter's roll-off, averages to its value there),
    # so narrower towards the band's ends, never below 40 bins
    half = np.clip(np.minimum(i, p.size - 1 - i), 40, min(_LEVEL_HALF, max(40, p.size // 20)))
    guard = np.maximum(2, half // 10)
    level, _ = _window_mean(p, np.ones(p.size, bool), half, guard)
    return _window_mean(p, p <= _LEVEL_CLIP * level, half, guard)


def _line_detection(series: np.ndarray, pos: np.ndarray, first: int, n_det: int, dt: float,
                    r: float, q: float, q_angle_rad: float) -> tuple:
    """Strongest Fourier bin among the first n_det whitened values: (p_max, n_bins, log FAP, z,
    f_det [Hz]); p_max is the bin's ratio to its local level."""
    m_det = int(np.searchsorted(pos - first, n_det))       # whitened values among them
    n_bins = (n_det - 1) // 2                              # j = 1 .. ⌈N/2⌉ − 1
    if n_bins < 1 or m_det < 1:
        raise ValueError("too few samples for a periodogram")
    tested = np.abs(sfft.rfft(series[:n_det])[1:n_bins + 1]) ** 2 / m_det
    if q_angle_rad > 0:
        c = 1.0 - np.cos(2.0 * np.pi * np.arange(1, n_bins + 1) / n_det)
        tested /= 1.0 + (q_angle_rad / dt) ** 2 * (2.0 * c) ** 2 / (2.0 * r * c + q)
    if _LOCAL_LEVEL and n_bins >= _LEVEL_MIN_BINS:
        level, k = _local_level(tested)
        ratio = tested / np.maximum(level, np.finfo(float).tiny)
        log_tail = -k * np.log1p(ratio / k)                # P(F(2, 2k) > x) = (1 + x/k)^(−k)
        j = int(np.argmin(log_tail)) + 1
        p_max, log_p = float(ratio[j - 1]), float(log_tail[j - 1])
    else:
        j = int(np.argmax(tested)) + 1
        p_max = float(tested[j - 1])
        log_p = -p_max                                     # P(Exp(1) > x) = e^(−x)
    log_keep = n_bins * math.log1p(-math.exp(log_p)) if log_p > -700 else -n_bins * math.exp(log_p)
    log_fap = math.log(-math.expm1(log_keep)) if log_keep < -1e-300 else log_p + math.log(n_bins)
    z = _logp_to_z(log_fap)
    f_det = j / (n_det * dt)
    return p_max, n_bins, log_fap, z, f_det


def _padded_peak(series: np.ndarray, big_n: int, n_det: int, dt: float, f_det: float) -> tuple:
    """Parabolic peak of the zero-padded periodogram near f_det: (f1 [Hz], padded bin [Hz])."""
    # refinement: zero-padded periodogram of the whole series around f_det, parabola
    pad = 4 if big_n <= 2 ** 20 else 2
    n_pad = sfft.next_fast_len(pad * big_n, real=True)
    spec_pad = np.abs(sfft.rfft(series, n=n_pad)) ** 2
    df_pad = 1.0 / (n_pad * dt)
    centre = round(f_det / df_pad)
    w = max(2, math.ceil(n_pad / n_det))
    lo_i, hi_i = max(1, centre - w), min(spec_pad.size - 2, centre + w)
    i = lo_i + int(np.argmax(spec_pad[lo_i:hi_i + 1]))
    i = min(max(i, 1), spec_pad.size - 2)
    pm_, p0, pp = spec_pad[i - 1], spec_pad[i], spec_pad[i + 1]
    del spec_pad
    den = pm_ - 2.0 * p0 + pp
    delta = 0.5 * (pm_ - pp) / den if den < 0 else 0.0
    f1 = (i + float(np.clip(delta, -0.5, 0.5))) * df_pad
    return f1, df_pad


def _refine_frequency(wh, ze: np.ndarray, t: np.ndarray, f1: float, df_pad: float, nyq: float,
                      bin_hz: float) -> tuple:
    """Brent search of the GLS χ² near f1, then Gauss–Newton with ∂/∂f: (f, fit, cov or None)."""
    def lin(f):
        arg = 2.0 * np.pi * f * t
        sn, cs = np.sin(arg), np.cos(arg)
        return wh.fit_whitened(ze, wh.whiten(sn, cs)), sn, cs

    a_f = max(f1 - df_pad, 0.25 * df_pad)
    b_f = min(f1 + df_pad, nyq - 0.25 * df_pad)
    res = optimize.minimize_scalar(lambda f: lin(f)[0].chi2, bounds=(a_f, b_f), method="bounded",
                                   options={"xatol": 0.02 * bin_hz})
    f = float(res.x)
    fit, sn, cs = lin(f)
    cov = None
    for it in range(5):                                    # Gauss–Newton polish, with ∂/∂f
        a_s, a_c = fit.beta
        dfx = 2.0 * np.pi * t * (a_s * cs - a_c * sn)      # ∂/∂f of a_s sin + a_c cos
        try:
            full = wh.fit_whitened(ze, wh.whiten(sn, cs, dfx))
        except NotIdentifiableError:
            cov = None
            break
        cov, step = full.cov, float(full.beta[2])          # cov at the current f
        if it == 4 or not abs(step) > 1e-3 * math.sqrt(cov[2, 2]):
            break
        trial = lin(f + step)
        if not (0.0 < f + step < nyq and trial[0].chi2 <= fit.chi2):
            break
        f, (fit, sn, cs) = f + step, trial
    return f, fit, cov


def _sinusoid_evidence(gyro: int, f: float, f_s: float, amp_d: float, amp_s: float,
                       log_fap: float, n_bins: int, z: float) -> str:
    """The sentence that reports the strongest line (or its absence)."""
    fap_txt = f"{math.exp(log_fap):.2g}" if log_fap > -700 else f"1e{log_fap / math.log(10.0):.0f}"
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} residual has a line at {pm(f, f_s)} Hz of amplitude "
              f"{pm(amp_d, amp_s)} deg/s (false-alarm probability {fap_txt} over {n_bins} "
              "frequencies); the model has no sinusoid")
    else:
        ev = (f"gyro {gyro} residual has no significant line: the strongest, at {f:.4g} Hz "
              f"({_num(amp_d, 2)} deg/s), has false-alarm probability {fap_txt} over {n_bins} "
              f"frequencies (z = {z:.1f})")
    return ev


@by_content()
def fit_sinusoid(e, time_s, dt_s: float, r: float, q: float, gyro: int, use=None, *,
                 q_angle_rad: float = 0.0) -> EffectFit:
    """Sinusoidal rate error: the strongest line of the whitened residual.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual [rad/s].
    time_s : array_like, shape (n,)
        Sample times [s], uniform at dt_s (the phase refers to t = time_s).
    dt_s : float
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`gls_rw`).
    q_angle_rad : float
        Angle quantization Q [rad] the noise also has (white angle noise of
        standard deviation Q, σ² = 3Q²/τ²); 0 = none. Its blue spectrum
        would otherwise read as lines near Nyquist.

    Returns
    -------
    EffectFit
        ``sinusoid``: ``amp_deg_s``, ``freq_hz``, ``phase_deg`` with sigmas.

    Notes
    -----
    Model::

        e_t = A sin(2π f t + φ) + b_t + w_t = a_s sin 2πft + a_c cos 2πft + b_t + w_t
        A = √(a_s² + a_c²),  φ = atan2(a_c, a_s)

    Detection. z_i = L̃⁻¹Δe/√s, the residual whitened by the baseline noise
    (:func:`gls_rw`), is iid N(0, 1) without a line; placed at the times of
    its samples (zeros in the gaps of ``use``), the first N of them (N the
    largest fast FFT length <= the series, typically < 1 % shorter) have the
    periodogram P_j = |Σ z_i e^{−2πi j i/N}|²/m at the Fourier bins
    j = 1..⌈N/2⌉−1, iid Exp(1) (exact without gaps, approximate with them).
    A line at f adds ≈ m·A²|H(f)|²/4 to the bins near f, H the whitening
    filter (so a slow line competes with the random walk, as it should).
    With a quantization Q in the noise, the rate gets Δa/dt (a white, variance
    Q²), and each P_j is divided by its expected level in the whitened
    series, 1 + (Q²/dt²)(2 − 2cos ω_j)² / (2r(1 − cos ω_j) + q), ω_j = 2πj/N,
    which keeps it Exp(1).

    A line is a bin above its neighbours, so each P_j is read against its
    local level L_j, the mean of P over the bins within h = min(2000,
    M/20) of j (centred: within the bin's distance to the band's ends, at
    least 40), those within h/10 left out (a line that wanders keeps its
    power there), and in a second pass those above 30 times the first
    pass's level too (other lines): x_j = P_j/L_j is F(2, 2k_j) when the
    k_j bins are Exp(λ) about j, whatever λ, with the tail
    p_j = (1 + x_j/k_j)^(−k_j). So a baseline that is off, in level or in
    shape (a sensor's low-pass, a burst, a quantizer's Q read a few per cent
    off, spikes, a hump the model lacks), moves no bin's statistic: with the
    model's level instead, white noise 1.2 times the model's read z ≈ 2.6 on
    every record, and a 10 Hz Butterworth's roll-off z ≈ 4.3. The price is
    power: a line at the threshold needs a few per cent more amplitude. With
    p_min the smallest tail over the M bins (records of fewer than 400 bins
    keep the model's level, p_j = e^{−P_j}),

        FAP = 1 − (1 − p_min)^M,    z = Φ⁻¹(1 − FAP)

    so z is N(0, 1) without a line (the false-alarm probability is uniform).
    Only the M independent Fourier bins are tested: a line between two bins
    loses up to 60 % of its peak power there (scalloping), the price of an
    exact null distribution.

    Estimation. Parabolic interpolation of the zero-padded periodogram
    (4×, 2× beyond 2²⁰ samples) of the whole series around the detected bin
    gives f₁; a bounded Brent search of the GLS χ² of e on (sin, cos)
    within one padded bin of f₁ (to 0.02 bin) and Gauss–Newton steps with
    the regressor ∂/∂f (accepted while χ² decreases) give f̂; the final GLS
    on (sin, cos, ∂/∂f) at f̂ (the Cramér–Rao linearisation) gives
    (a_s, a_c) and the joint covariance with f, so σ_A and σ_φ include the
    frequency uncertainty (large for σ_φ when the record starts far from
    t = 0). Cost at n = 2.2e6: a few seconds (two FFTs and ~15 GLS).
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    t = _vec(time_s, n, "time_s")
    dt = float(dt_s)
    nyq = 0.5 / dt
    wh = RWWhitener(n, r, q, use)
    ze = wh.whiten(e)
    pos = wh.later
    first = int(pos[0])
    big_n = int(pos[-1]) - first + 1
    series = np.zeros(big_n)
    series[pos - first] = ze
    # detection on the largest fast FFT length (the first n_det positions; their
    # periodogram is as exact as the whole one's)
    n_det = _fast_len_below(big_n)
    p_max, n_bins, log_fap, z, f_det = _line_detection(series, pos, first, n_det, dt, r, q,
                                                       q_angle_rad)
    f1, df_pad = _padded_peak(series, big_n, n_det, dt, f_det)
    bin_hz = 1.0 / (big_n * dt)
    f, fit, cov = _refine_frequency(wh, ze, t, f1, df_pad, nyq, bin_hz)
    a_s, a_c = fit.beta
    if cov is None:
        cov = np.full((3, 3), np.nan)
        cov[:2, :2] = fit.cov
    amp = math.hypot(a_s, a_c)
    phase = math.atan2(a_c, a_s)
    ga = np.array([a_s, a_c]) / amp
    gp = np.array([-a_c, a_s]) / amp ** 2
    c2 = cov[:2, :2]
    amp_d, amp_s = rad_s_to_deg_s(amp), rad_s_to_deg_s(math.sqrt(ga @ c2 @ ga))
    ph_d, ph_s = rad_to_deg(phase), rad_to_deg(math.sqrt(gp @ c2 @ gp))
    f_s = math.sqrt(cov[2, 2]) if np.isfinite(cov[2, 2]) else math.nan
    params = {"amp_deg_s": float(amp_d), "freq_hz": f, "phase_deg": float(ph_d)}
    sigma = {"amp_deg_s": float(amp_s), "phase_deg": float(ph_s)}
    if math.isfinite(f_s):
        sigma["freq_hz"] = f_s
    extra = _extra(fit, p_max=p_max, n_bins=n_bins, log10_fap=log_fap / math.log(10.0),
                   bin_hz=bin_hz, f_detected_hz=f_det, chi2_no_line=float(ze @ ze))
    ev = _sinusoid_evidence(gyro, f, f_s, amp_d, amp_s, log_fap, n_bins, z)
    return EffectFit("sinusoid", gyro, params, sigma, z, ev, extra)


# -- saturation ------------------------------------------------------------------------

def _log_chi2_cdf(x: float, k: int) -> float:
    """log P(χ²(k) <= x), finite for tiny x (leading term of the lower incomplete gamma)."""
    if x <= 0.0:
        return -math.inf
    v = float(stats.chi2.logcdf(x, k))
    if math.isfinite(v) and v > -700.0:
        return v
    a = 0.5 * k
    return a * math.log(0.5 * x) - 0.5 * x - special.gammaln(a + 1.0)


def _inner_envelope(y: np.ndarray, u: np.ndarray, c_plus: float, c_minus: float,
                    block: int) -> float:
    """Largest |block median| of output − reference well inside the output range [rad/s]."""
    inner = (u < 0.9 * c_plus) & (u > -0.9 * c_minus)
    eres = (y - u)[inner]
    nb = eres.size // block
    if nb >= 1:
        env = float(np.max(np.abs(np.median(eres[:nb * block].reshape(nb, block), axis=1))))
    else:
        env = float(abs(np.median(eres))) if eres.size else 0.0
    return env


def _plateau_test(yp: np.ndarray, ym: np.ndarray, nu: int, ymax: float, r: float) -> tuple:
    """Spread of the outputs beyond the range about their means against the noise:
    (sum of squares [rad²/s²], z from the lower χ²_ν tail)."""
    s_sum = 0.0
    for part in (yp, ym):
        if part.size > 1:
            s_sum += float(np.sum((part - part.mean()) ** 2))
    floor = nu * (np.finfo(float).eps * ymax) ** 2
    x = max(s_sum, floor) / r
    z = _logp_to_z(_log_chi2_cdf(x, nu))
    return s_sum, z


def _tie_tol(ymax: float) -> float:
    """Two outputs this close are one output code [rad/s] (a few rounding units of the CSV)."""
    return 1e-9 * max(ymax, 1e-300)


def _tie_test(y: np.ndarray, yp: np.ndarray, ym: np.ndarray, c_plus: float, c_minus: float,
              sig: float) -> tuple[float, int, int, float]:
    """(z, count at +c₊, count at −c₋, δ [rad/s]) of exact repeats of the output's extreme codes
    where the reference is beyond.

    A digital clip outputs the same full-scale code on every clipped sample. Without clipping,
    an output quantized at δ (its smallest step between distinct values, the LSB) with noise σ
    takes one code with probability at most δ/(√(2π)·σ) (the largest mass of a normal binned at
    δ), so the count of samples at the extreme is at most Binomial(|T|, p₀) under "no clip";
    z from its upper tail. A float output (δ tiny) never repeats a value by chance."""
    tol = _tie_tol(max(c_plus, c_minus))
    n_t = yp.size + ym.size
    at_p, at_m = int(np.count_nonzero(yp >= c_plus - tol)), int(np.count_nonzero(ym <= -c_minus + tol))
    n_tie = at_p + at_m
    if n_t == 0 or n_tie <= 1 or not sig > 0:
        return 0.0, at_p, at_m, 0.0
    vals = np.unique(y)
    gaps = np.diff(vals)
    gaps = gaps[gaps > tol]
    delta = float(gaps.min()) if gaps.size else tol
    p0 = min(0.5, max(delta, tol) / (math.sqrt(2.0 * math.pi) * sig))
    log_p = float(stats.binom.logsf(n_tie - 1, n_t, p0))
    if not math.isfinite(log_p):            # beyond the float range: the Chernoff bound −n·KL(k/n ‖ p₀)
        k = n_tie / n_t
        log_p = -n_t * (k * math.log(k / p0) + ((1 - k) * math.log((1 - k) / (1 - p0)) if k < 1 else 0.0))
    return _logp_to_z(log_p), at_p, at_m, delta


def _saturation_evidence(gyro: int, z: float, rng: float, rng_s: float, count: int, frac: float,
                         spread: float, extra: dict) -> str:
    """The sentence that reports the plateau (or its absence)."""
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} output sits at ±{pm(rng, rng_s)} deg/s on {count} samples "
              f"({_num(100 * frac, 2)} %) where the reference is beyond it (up to "
              f"{_num(extra['u_max_deg_s'], 4)} deg/s), spread {_num(spread, 2)} deg/s against "
              f"a noise σ of {_num(extra['arw_sigma_deg_s'], 2)} deg/s: clipped")
    else:
        ev = (f"gyro {gyro} output beyond ±{_num(rng, 4)} deg/s spreads {_num(spread, 2)} deg/s, "
              f"like its noise σ {_num(extra['arw_sigma_deg_s'], 2)} deg/s: no plateau (z = {z:.1f})")
    return ev


def fit_saturation(gyro_rad_s, u_rad_s, r: float, gyro: int, *, use=None,
                   block: int = 256) -> EffectFit:
    """Clipping: the output sits on a plateau where the input is beyond it.

    Parameters
    ----------
    gyro_rad_s : array_like, shape (n,)
        Gyro output y [rad/s].
    u_rad_s : array_like, shape (n,)
        Expected input, h·ω_ref [rad/s].
    r : float
        ARW variance per sample, N²/dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include.
    block : int
        Block length for the bias envelope (below) [samples].

    Returns
    -------
    EffectFit
        ``saturation``: ``range_deg_s`` (the plateau level) with sigma, or,
        without a plateau, max|y| (a lower bound of the range) without sigma.

    Notes
    -----
    ::

        y_t = clip(u_t + b_t + w_t, −c, c)

    1. Plateau candidates: c₊ = max y, c₋ = −min y. Bias envelope β: the
       largest |median| of e = y − u over blocks of ``block`` samples with
       −0.9c₋ < u < 0.9c₊ (certainly unclipped); margin μ = 3√r + β.
       Beyond-plateau sets T₊ = {u > c₊ + μ}, T₋ = {u < −c₋ − μ}: there the
       reference says the input exceeds the largest output by more than the
       noise and the bias can explain.
    2. Without clipping, y_t on T± carries white noise of variance r and
       follows u (so it spreads at least that much); clipped, it is constant.
       Statistic: S = Σ_{T₊}(y − ȳ₊)² + Σ_{T₋}(y − ȳ₋)², ν = (|T₊| − 1)⁺ +
       (|T₋| − 1)⁺, and under "no clipping" S/r >= χ²(ν) stochastically:

           p = P(χ²(ν) <= S/r),   z = Φ⁻¹(1 − p)

       A flat plateau gives a tiny p (large z). Without clipping T± are
       (nearly always) empty or spread like the noise: z = 0 when ν = 0,
       otherwise z <= ~0 (negative when y follows u there). An exact
       digital plateau (S = 0) is floored at one rounding unit of c per
       sample, S >= ν·(eps·c)², to keep z finite.
    3. ``range_deg_s`` = mean |y| over T₊ ∪ T₋, σ = std/√|T|, at least one
       rounding unit eps·c (an exact plateau); asymmetric plateaus show up
       as a large σ, and c₊, c₋ are in ``extra``.
    """
    y = np.asarray(gyro_rad_s, dtype=float)
    n = y.size
    u = _vec(u_rad_s, n, "u_rad_s")
    r = float(r)
    if not (math.isfinite(r) and r > 0):
        raise ValueError(f"r must be a positive variance, got {r!r}")
    if use is not None:
        keep = np.asarray(use, dtype=bool)
        if keep.shape != (n,):
            raise ValueError(f"use must be {n} booleans, got shape {keep.shape}")
        y, u = y[keep], u[keep]
    sig = math.sqrt(r)
    c_plus, c_minus = float(np.max(y)), float(-np.min(y))
    ymax = max(c_plus, c_minus)
    env = _inner_envelope(y, u, c_plus, c_minus, block)
    mu = 3.0 * sig + env
    tp, tm = u > c_plus + mu, u < -c_minus - mu
    yp, ym = y[tp], y[tm]
    nu = max(yp.size - 1, 0) + max(ym.size - 1, 0)
    extra = {"c_plus_deg_s": float(rad_s_to_deg_s(c_plus)), "c_minus_deg_s": float(rad_s_to_deg_s(c_minus)),
             "margin_deg_s": float(rad_s_to_deg_s(mu)), "n_beyond": int(yp.size + ym.size),
             "u_max_deg_s": float(rad_s_to_deg_s(np.max(np.abs(u))))}
    if nu == 0:
        rng = float(rad_s_to_deg_s(ymax))
        ev = (f"gyro {gyro} output never sits on a plateau while the reference is beyond it "
              f"(max |output| {_num(rng, 4)} deg/s, reference up to {_num(extra['u_max_deg_s'], 4)} deg/s)")
        return EffectFit("saturation", gyro, {"range_deg_s": rng}, {}, 0.0, ev, extra)
    s_sum, z = _plateau_test(yp, ym, nu, ymax, r)
    mag = np.abs(np.concatenate([yp, ym]))
    c = float(mag.mean())
    c_s = float(mag.std(ddof=1) / math.sqrt(mag.size)) if mag.size > 1 else math.nan
    c_s = max(c_s, np.finfo(float).eps * c)                 # an exact plateau: one rounding unit
    z_tie, at_p, at_m, lsb = _tie_test(y, yp, ym, c_plus, c_minus, sig)
    extra.update(z_spread=float(z), n_at_extreme=at_p + at_m, z_ties=float(z_tie))
    if z_tie > max(z, 3.0):
        # the output repeats its extreme code where the reference is beyond it: the clip, even
        # where the input dips back under it between (a vibrating plateau); its level is that code
        z = z_tie
        c = (at_p * c_plus + at_m * c_minus) / max(at_p + at_m, 1)
        c_s = max(abs(c_plus - c_minus) / 2.0 if at_p and at_m else 0.0, lsb / 2.0, np.finfo(float).eps * c)
    rng, rng_s = float(rad_s_to_deg_s(c)), float(rad_s_to_deg_s(c_s))
    spread = float(rad_s_to_deg_s(math.sqrt(s_sum / nu)))
    extra.update(spread_deg_s=spread, arw_sigma_deg_s=float(rad_s_to_deg_s(sig)), dof=nu)
    frac = mag.size / n
    ev = _saturation_evidence(gyro, z, rng, rng_s, mag.size, frac, spread, extra)
    sigma = {"range_deg_s": rng_s} if math.isfinite(rng_s) else {}
    return EffectFit("saturation", gyro, {"range_deg_s": rng}, sigma, z, ev, extra)
