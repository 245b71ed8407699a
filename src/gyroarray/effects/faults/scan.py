"""Fault fitting: onset and size of a step, drift, stuck or noise fault, with 1σ.

The data model is the project's baseline gyro error (``shared/spec/effects.md``):
a series y_k = b_k + v_k + f_k [rad/s] with white noise v (variance r = N²/dt
per sample, the ARW), a random-walk bias b (increments of variance q = K²·dt,
the RRW; its start unknown) and a fault f that starts at an unknown onset θ
and lasts to the end. The same model describes one gyro's residual (output
minus the projected reference rate) and each whitened parity component of an
array (:mod:`gyroarray.estimators.fdi`), so both use the functions here.

Method (Willsky & Jones' GLR on Kalman innovations)
----------------------------------------------------
1. A scalar Kalman filter tracks the bias (random walk + unit white noise
   after dividing by √r), started diffuse on the first sample, with the
   exact time-varying gain (:func:`rw_gains`, closed form). Its normalised
   innovations ε_k = ν_k/√S_k are i.i.d. N(0, 1) when there is no fault and
   the noise model is right (ε_0 = 0: the first sample only starts the
   filter).
2. A fault enters the innovations through a known signature (steady-state
   gain K, a = 1 − K, S = innovation variance):

   * step of size f:     f·aⁿ/√S, n = k − θ (the tracker absorbs it with
     time constant dt/K);
   * drift of rate ρ:    ρ·dt·(1 − aⁿ)/(K√S) (the tracker lags a ramp by
     ρ·dt/K: that offset is all a drift leaves once it is older than dt/K);
   * noise × ratio:      innovation variance λ_b → λ_a, λ_a/λ_b = 1 + (ratio² − 1)·w,
     w = 2/((2 − K)·S) the share of the innovation variance that is this
     white noise (both levels free: a calibration on the faulty record has
     neither); the scan finds the onset on the innovations, the ratio is then
     read from the first differences, which need neither r nor q
     (:func:`_difference_ratio`);
   * stuck: the output stops moving (white noise ratio 0 and no bias walk);
     with the raw output at hand, the exact run of repeated values.
3. For every candidate onset θ the size is the least-squares fit of the
   signature (a linear Gaussian model), and the log-likelihood gain is
   ΔLL(θ) = (Σ g ε)²/(2 Σ g²) (means) or the two-level variance GLR
   (:func:`profile_variance_change`). The onset maximises ΔLL (GLR over the onset); its
   1σ is the spread of the profile likelihood exp(ΔLL(θ)) over the onsets
   (:func:`onset_sigma`); the size's 1σ is 1/√(Σ g²) at the fitted onset.
4. The z-score: the p-value of max_θ |Y(θ)| under "no fault", Y the signed
   root of 2ΔLL, from the expected number of up-crossings of the level by
   the Gaussian sequence Y(θ) (exact lag-one correlations, bivariate normal
   up-crossing probability via Owen's T; p = 1 − exp(−E[#up-crossings]));
   z = Φ⁻¹(1 − p), so z ≈ N(0, 1) when the fault is absent.

Bias memory: with K = 0 (no RRW) the filter would average the whole past
and a late fault would barely move the innovations; q is floored at
(dt/``bias_memory_s``)²·r, i.e. the tracker forgets the bias with a time
constant of at most ``bias_memory_s`` (default 600 s). The cost: a drift
slower than that memory shows only as the offset ρ·τ, τ = dt/K.

Everything is SI (rad/s, rad/s², s); spec units only in :attr:`FaultFit.params`.

References
----------
A. S. Willsky, H. L. Jones, "A generalized likelihood ratio approach to the
detection and estimation of jumps in linear systems", IEEE TAC 21(1), 1976.
M. Basseville, I. V. Nikiforov, *Detection of Abrupt Changes*, 1993, §2.4, §7.2.
D. Siegmund, B. Yakir, *The Statistics of Gene Mapping*, 2007, ch. 4 (up-crossings).
"""

from __future__ import annotations

import functools
import math
import zlib
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import optimize, signal, special, stats

from gyroarray.analysis.memo import by_content
from gyroarray.core.errors import InputError
from gyroarray.core.units import rad_s_to_deg_s

__all__ = ["KINDS", "FaultFit", "rw_gains", "steady_gain", "rw_innovations", "reverse_ar1",
           "step_energy", "ramp_energy", "upcrossing_prob", "overshoot_nu", "clump_rate",
           "chi2_glr_pvalue", "noise_share",
           "profile_means", "profile_variance", "profile_variance_change", "onset_sigma",
           "stuck_run",
           "fit_fault", "fit_faults", "DEFAULT_BIAS_MEMORY_S"]

#: The fault kinds, in the spec's order (effect name = ``"fault_" + kind``).
KINDS = ("step", "drift", "stuck", "noise")

#: Longest time constant of the bias tracker [s] (module docstring).
DEFAULT_BIAS_MEMORY_S = 600.0

#: Fewest samples after the onset for a variance fit (its Gaussian tail approximation).
MIN_VARIANCE_SAMPLES = 20

#: Samples on each side of a join of stitched parts (``breaks`` of :func:`fit_fault`) within
#: which no step or drift onset is scanned: a join is a known break whose offset the stitched
#: fit already has free, and a step there is that offset (the CATS tag's full record: g1 and g3
#: "steps" at 183 603–183 606 s, its join). As many as a fault needs on each side of its onset at
#: the record's ends (:data:`gyroarray.effects.faults.base.MIN_RUN`).
JOIN_GUARD = 32


# -- the bias tracker -------------------------------------------------------

def steady_gain(q) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state gain K and innovation variance S of the bias tracker.

    Parameters
    ----------
    q : array_like
        Random-walk increment variance per sample, in units of the white
        noise variance [-] (q/r), > 0.

    Returns
    -------
    K, S : ndarray
        P⁻ = (q + √(q² + 4q))/2 (the Riccati fixed point), K = P⁻/(P⁻ + 1),
        S = P⁻ + 1.
    """
    q = np.asarray(q, dtype=float)
    p = 0.5 * (q + np.sqrt(q * q + 4.0 * q))                 # P⁻ = P⁺ + q, P⁺ = P⁻/(P⁻ + 1)
    return p / (p + 1.0), p + 1.0


def rw_gains(q: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Time-varying gain and innovation variance of the diffuse bias tracker.

    Parameters
    ----------
    q : float
        Random-walk increment variance per sample / white noise variance [-], >= 0.
    n : int
        Number of samples.

    Returns
    -------
    K, S : ndarray, shape (n,)
        Gain and innovation variance at each sample; sample 0 starts the
        filter (m̂₀ = y₀, P⁺₀ = 1): K₀ = 1, S₀ = inf.

    Notes
    -----
    P⁻_{k+1} = (P⁻_k(1 + q) + q)/(P⁻_k + 1) is a Möbius map with fixed
    points p₁ > 0 > p₂ (roots of P² − qP − q = 0); (P⁻_k − p₁)/(P⁻_k − p₂)
    = Z₁κ^{k−1} with κ = (p₂ + 1)/(p₁ + 1) and P⁻₁ = 1 + q. For q = 0 the
    filter is the running mean: P⁻_k = 1/k.
    """
    k = np.arange(1, n, dtype=float)
    if q <= 0.0:
        pm = 1.0 / k
    else:
        root = math.sqrt(q * q + 4.0 * q)
        p1, p2 = 0.5 * (q + root), 0.5 * (q - root)
        log_kappa = math.log1p(p2) - math.log1p(p1)
        z1 = (1.0 + q - p1) / (1.0 + q - p2)
        if z1 == 0.0:
            pm = np.full(k.shape, p1)
        else:
            zk = np.sign(z1) * np.exp((k - 1.0) * log_kappa + math.log(abs(z1)))
            pm = (p1 - p2 * zk) / (1.0 - zk)
    K = np.concatenate([[1.0], pm / (pm + 1.0)])
    S = np.concatenate([[np.inf], pm + 1.0])
    return K, S


@by_content(maxsize=8)
def rw_innovations(y, q) -> np.ndarray:
    """Normalised innovations of the diffuse bias tracker, per column.

    Parameters
    ----------
    y : array_like, shape (n,) or (n, m)
        Series in units of their white noise σ [-] (y/√r).
    q : float or array_like, shape (m,)
        Random-walk increment variance per sample / white variance [-], >= 0.

    Returns
    -------
    ndarray, same shape as ``y``
        ε_k = (y_k − m̂_{k−1})/√S_k, i.i.d. N(0, 1) under the model; ε₀ = 0.

    Notes
    -----
    m̂_k = a_k m̂_{k−1} + K_k y_k (a_k = 1 − K_k). While the gain still moves
    (until it is within 1e-12 of K) the recursion is evaluated in closed
    form, m̂_k = A_k(y₀ + Σ_{i<=k} K_i y_i/A_i), A_k = Π a_i (a cumulative
    sum; A stays above e^{-40} there); then ``scipy.signal.lfilter`` with
    the constant gain.
    """
    y = np.asarray(y, dtype=float)
    one = y.ndim == 1
    Y = y[:, None] if one else y
    n, m = Y.shape
    qs = np.broadcast_to(np.asarray(q, dtype=float), (m,))
    out = np.zeros_like(Y)
    for j in range(m):
        out[:, j] = _innovations_1(Y[:, j], float(qs[j]))
    out.flags.writeable = False                              # cached by content: shared, never changed
    return out[:, 0] if one else out


def _innovations_1(y: np.ndarray, q: float) -> np.ndarray:
    n = y.size
    if n < 2:
        return np.zeros(n)
    K, S = rw_gains(q, n)
    if q > 0.0:
        k_ss = steady_gain(q)[0]
        moving = np.flatnonzero(np.abs(K[1:] - k_ss) > 1e-12 * k_ss)
        n_t = min(n, int(moving[-1]) + 2 if moving.size else 1)
    else:
        n_t = n
    m_hat = np.empty(n)
    a = 1.0 - K[1:n_t]
    log_a = np.concatenate([[0.0], np.cumsum(np.log(a))])            # ln A_k, A_0 = 1
    if log_a[-1] < -600.0:                                           # cannot happen: see Notes
        raise FloatingPointError("bias tracker transient too long")  # pragma: no cover
    terms = np.concatenate([[y[0]], K[1:n_t] * y[1:n_t] * np.exp(-log_a[1:])])
    m_hat[:n_t] = np.exp(log_a) * np.cumsum(terms)                   # m̂_k = A_k(y₀ + Σ K_i y_i/A_i)
    if n_t < n:
        k_ss = K[-1]
        zi = [(1.0 - k_ss) * m_hat[n_t - 1]]
        m_hat[n_t:] = signal.lfilter([k_ss], [1.0, -(1.0 - k_ss)], y[n_t:], zi=zi)[0]
    eps = np.zeros(n)
    eps[1:] = (y[1:] - m_hat[:-1]) / np.sqrt(S[1:])                  # ε = ν/√S
    return eps


def reverse_ar1(x: np.ndarray, a) -> np.ndarray:
    """w_θ = x_θ + a·w_{θ+1} along axis 0 (w_{n−1} = x_{n−1}), per column.

    Parameters
    ----------
    x : ndarray, shape (n,) or (n, m)
    a : float or array_like, shape (m,)
        Coefficient per column, |a| <= 1.

    Returns
    -------
    ndarray, same shape as ``x``
        The discounted sums Σ_{s>=θ} a^{s−θ} x_s over the rest of the record.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        return signal.lfilter([1.0], [1.0, -float(a)], x[::-1])[::-1]
    aa = np.broadcast_to(np.asarray(a, dtype=float), (x.shape[1],))
    out = np.empty_like(x)
    for j in range(x.shape[1]):
        out[:, j] = signal.lfilter([1.0], [1.0, -aa[j]], x[::-1, j])[::-1]
    return out


# -- signature energies ------------------------------------------------------

def _geo(a, length):
    """Σ_{n<length} aⁿ (a may be 1)."""
    a = np.asarray(a, dtype=float)
    length = np.asarray(length, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = -np.expm1(length * np.log(a)) / (1.0 - a)
    return np.where(a >= 1.0, length, g)


def step_energy(a, S, length):
    """Σ_{n<M} (aⁿ/√S)²: energy of a unit step's innovation signature over M samples."""
    return _geo(np.asarray(a) ** 2, length) / np.asarray(S)


def ramp_energy(a, K, S, length):
    """Σ_{n<M} ((1 − aⁿ)/(K√S))²: energy of a unit per-sample ramp's signature.

    For K = 0 the signature is n/√S (the limit), energy Σ n²/S.
    """
    a, K, S = (np.asarray(v, dtype=float) for v in (a, K, S))
    M = np.asarray(length, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = (M - 2.0 * _geo(a, M) + _geo(a * a, M)) / (K * K * S)
    return np.where(K > 0, e, (M - 1.0) * M * (2.0 * M - 1.0) / 6.0 / S)


# -- calibration: up-crossings and block p-values ------------------------------

def upcrossing_prob(u, r) -> np.ndarray:
    """P(|Y₀| <= u < |Y₁|) for a standard bivariate normal pair with correlation r.

    Parameters
    ----------
    u : array_like
        Level (> 0).
    r : array_like
        Correlation of consecutive values, in [−1, 1].

    Returns
    -------
    ndarray
        2·(2T(u, α) − J), α = √((1 − r)/(1 + r)), T Owen's T function and
        J = P(Y₀ < −u, Y₁ > u) = Φ̄(u) − 2T(u, 1/α): the expected number of
        up-crossings of |Y| through u per step of a stationary Gaussian
        sequence with lag-one correlation r (exact).

    Notes
    -----
    P(Y₀ <= h, Y₁ <= h) = Φ(h) − 2T(h, √((1 − r)/(1 + r))) (Owen 1956), so
    P(Y₀ <= h < Y₁) = 2T(h, α).
    """
    u = np.asarray(u, dtype=float)
    r = np.clip(np.asarray(r, dtype=float), -1.0 + 1e-15, 1.0 - 1e-15)
    alpha = np.sqrt((1.0 - r) / (1.0 + r))
    one_side = 2.0 * special.owens_t(u, alpha)
    joint = np.maximum(special.ndtr(-u) - 2.0 * special.owens_t(u, 1.0 / alpha), 0.0)
    return np.maximum(2.0 * (one_side - joint), 0.0)


def overshoot_nu(x) -> np.ndarray:
    """Siegmund's discreteness correction ν(x) ≈ (2/x)(Φ(x/2) − 1/2)/((x/2)Φ(x/2) + φ(x/2)); ν(0) = 1."""
    x = np.asarray(x, dtype=float)
    h = 0.5 * np.maximum(x, 1e-12)
    nu = (special.ndtr(h) - 0.5) / h / (h * special.ndtr(h) + np.exp(-0.5 * h * h) / math.sqrt(2 * math.pi))
    return np.where(x > 1e-9, nu, 1.0)


def clump_rate(u, mu_rough, mu_smooth=0.0) -> np.ndarray:
    """Expected number of excursions ("clumps") of |Y| above u per step.

    Parameters
    ----------
    u : array_like
        Level (> 0).
    mu_rough : array_like
        Rough part of 1 − r(1) [-]: what the samples entering and leaving the
        window at its edges move (a moving sum of L samples: 1/L).
    mu_smooth : array_like
        Smooth part of 1 − r(1) [-]: what the slow change of the interior
        weights moves (≈ λ₂/2 of a differentiable process).

    Returns
    -------
    ndarray
        2·u·φ(u)·μ·ν(u√(2μ)) (μ = ``mu_rough``) + the up-crossings of the
        smooth part, never more than :func:`upcrossing_prob` with
        r = 1 − μ_rough − μ_smooth.

    Notes
    -----
    Rough part: Siegmund & Yakir's local approximation for a sequence whose
    correlation falls like 1 − μ|δ| near δ = 0: P(max_{k<=n} Y_k > u) ≈
    1 − exp(−n·u φ(u) μ ν(u√(2μ))), doubled for |Y|; it counts excursions,
    which jitter across u several times (one alarm to a user). Smooth part:
    a differentiable process crosses once per excursion, so its exact
    up-crossing probability is its excursion rate (Rice).
    """
    u = np.asarray(u, dtype=float)
    mr = np.clip(np.asarray(mu_rough, dtype=float), 0.0, 2.0)
    ms = np.clip(np.asarray(mu_smooth, dtype=float), 0.0, 2.0)
    phi = np.exp(-0.5 * u * u) / math.sqrt(2.0 * math.pi)
    sy = 2.0 * u * phi * mr * overshoot_nu(u * np.sqrt(2.0 * mr))
    smooth = np.where(ms > 0, upcrossing_prob(u, 1.0 - ms), 0.0)
    return np.minimum(sy + smooth, upcrossing_prob(u, 1.0 - mr - ms))


def _glr_roots(g: float, L: int) -> tuple[float, float]:
    """λ_lo < 1 < λ_hi with L/2·(λ − 1 − ln λ) = g."""
    c = 2.0 * g / L
    f = lambda lam: lam - 1.0 - math.log(lam) - c           # noqa: E731
    lo = optimize.brentq(f, max(math.exp(-1.0 - c) * 0.5, 1e-300), 1.0) if c > 0 else 1.0
    hi = optimize.brentq(f, 1.0, 2.0 + 2.0 * c) if c > 0 else 1.0
    return lo, hi


def chi2_glr_pvalue(g: float, L: int, sides: str = "both") -> float:
    """P(L/2·(λ̂ − 1 − ln λ̂) > g) for λ̂ = χ²_L/L (no variance change).

    Parameters
    ----------
    g : float
        Log-likelihood-ratio level [-].
    L : int
        Number of unit-variance samples in the block.
    sides : {"both", "up", "down"}
        Count an increase, a decrease, or both.
    """
    lo, hi = _glr_roots(g, L)
    p_lo = stats.chi2.cdf(L * lo, L) if sides in ("both", "down") else 0.0
    p_hi = stats.chi2.sf(L * hi, L) if sides in ("both", "up") else 0.0
    return float(p_lo + p_hi)


#: Onsets beyond which :func:`_analytic_max_p` sums the clump rates on a grid (the rates change
#: with the distance to either end of the record, fast only near the ends).
_EXACT_ONSETS = 4096


def _onset_grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(indices, weights) whose weighted sum of a function of the onset that changes smoothly
    with the distance to either end stands for its sum over all n onsets: every onset within
    256 of an end, a geometric grid between, trapezoid weights (the sum of the weights is n)."""
    d = np.unique(np.round(np.geomspace(256, n, 512)).astype(np.int64))
    idx = np.unique(np.concatenate([np.arange(min(256, n)), d[d < n], n - 1 - d[d < n],
                                    np.arange(max(n - 256, 0), n)]))
    idx = idx[(idx >= 0) & (idx < n)]
    gaps = np.diff(idx).astype(float)
    w = np.zeros(idx.size)
    w[:-1] += 0.5 * gaps
    w[1:] += 0.5 * gaps
    w[0] += 0.5
    w[-1] += 0.5
    return idx, w


def _analytic_max_p(y_abs: float, mu_rough, mu_smooth=0.0) -> float:
    """Tail approximation of P(max |Y| >= y): 1 − exp(−(2Φ̄(y) + Σ clump rates)).

    Beyond 4096 onsets the sum is taken on :func:`_onset_grid` (0.02 s per
    call on 1.2e5 onsets otherwise: Owen's T at every onset, and a diagnosis
    asks for it dozens of times; the grid's sum agrees to < 0.1 % of p,
    ``tests/test_faults.py``)."""
    if not np.isfinite(y_abs):
        return 0.0
    mr = np.asarray(mu_rough, dtype=float)
    ms = np.asarray(mu_smooth, dtype=float)
    if mr.ndim == 1 and mr.size > _EXACT_ONSETS:
        idx, w = _onset_grid(mr.size)
        rates = clump_rate(y_abs, mr[idx], ms[idx] if ms.ndim == 1 and ms.size == mr.size else ms)
        total = float(np.sum(w * rates))
    else:
        total = float(np.sum(clump_rate(y_abs, mr, ms)))
    expected = 2.0 * special.ndtr(-y_abs) + total
    return float(-np.expm1(-expected))


#: Monte Carlo draws of the null maximum (per kind and record shape; cached).
NULL_DRAWS = 200
_NULL_SEED = 20260516
#: Samples per bias-tracker time constant kept when the null is simulated on a shorter record.
_NULL_SAMPLES_PER_TAU = 32


@functools.lru_cache(maxsize=64)
def _null_maxima(kind: str, n: int, q: float, draws: int) -> np.ndarray:
    """Sorted maxima over the onset of the fit statistic on ``draws`` fault-free records.

    Step and drift: the innovations are i.i.d. N(0, 1), and for a slow tracker
    the law of the maximum depends on the record length in tracker time
    constants n·K only, so it is simulated on n' = min(n, 32·n·K/(K'…))
    samples with the same n·K (at least 32 samples per time constant).
    Variance kinds ("noise" two-sided, "stuck" decrease only): on n samples.
    """
    rng = np.random.default_rng([_NULL_SEED, zlib.crc32(kind.encode()), n, draws])
    out = np.empty(draws)
    if kind in ("step", "drift"):
        K = float(steady_gain(q)[0])
        n_sim = int(min(n, max(4096, math.ceil(_NULL_SAMPLES_PER_TAU * n * K))))
        K_sim = min(K * n / n_sim, 0.5)
        q_sim = K_sim * K_sim / (1.0 - K_sim)                 # K = P⁻/(P⁻+1), q = P⁻²/(P⁻+1)
        K_sim, S_sim = (float(v) for v in steady_gain(q_sim))
        onsets = np.arange(n_sim - 1)
        for i in range(draws):
            e = rng.standard_normal(n_sim)
            num, den, _, _ = profile_means(e[:, None], [1.0 - K_sim], [K_sim], [S_sim],
                                        np.ones((1, 1)), kind, onsets)
            out[i] = float(np.max(np.abs(num[:, 0]) / np.sqrt(den[:, 0])))
    else:
        onsets = _variance_onsets(n)
        for i in range(draws):
            dll, lam, _ = profile_variance_change(rng.standard_normal(n), onsets)
            if kind == "stuck":
                dll = np.where(lam < 1.0, dll, 0.0)
            out[i] = float(np.sqrt(2.0 * np.max(dll)))
    out.sort()
    return out


def _null_pvalue(stat: float, null: np.ndarray, tail, anchors: dict | None = None) -> float:
    """P(max >= stat): the Monte Carlo in the bulk, the analytic tail beyond its 95 % point.

    ``tail(y)`` is an analytic tail approximation; beyond the Monte Carlo's
    95 % quantile it is rescaled to agree with the Monte Carlo there.
    """
    R = null.size
    q95 = float(null[int(0.95 * (R - 1))])
    if stat <= q95:                                           # mid-p: ties (a mass at 0) count half
        return (1.0 + np.sum(null > stat) + 0.5 * np.sum(null == stat)) / (1.0 + R)
    anchor = (1.0 + np.sum(null >= q95)) / (1.0 + R)
    if anchors is not None:                                   # tail(q95) of one record shape, once
        if q95 not in anchors:
            anchors[q95] = tail(q95)
        t_anchor = anchors[q95]
    else:
        t_anchor = tail(q95)
    if not t_anchor > 0:
        return anchor * 1e-3
    return float(min(anchor, tail(stat) * anchor / t_anchor))


def _z_of_p(p: float) -> float:
    """z = Φ⁻¹(1 − p), within ±8.3 (p in [1e-16, 1 − 1e-16]); inf for p = 0."""
    if p <= 0.0:
        return math.inf
    return float(-special.ndtri(min(max(p, 1e-16), 1.0 - 1e-16)))


#: Below this p-value the z of a scan statistic is read from the statistic itself (:func:`_z_of_scan`).
_P_FLOOR = 1e-16


def _z_of_logp(log_p: float) -> float:
    """z with log Φ̄(z) = ``log_p`` (natural log), finite down to any log_p (a diagnosis ranks
    a fault against effects whose z runs into the thousands)."""
    if log_p >= math.log(_P_FLOOR):
        return _z_of_p(math.exp(log_p))
    f = lambda z: float(special.log_ndtr(-z)) - log_p         # noqa: E731  decreasing in z
    hi = math.sqrt(-2.0 * log_p) + 1.0                        # log Φ̄(z) < −z²/2 for z > 1
    return float(optimize.brentq(f, 8.0, hi))


def _anchors(key) -> dict:
    """The tail(q95) cache of one record shape (bounded: a long session sees many shapes)."""
    if len(_ANCHORS) > 256:
        _ANCHORS.clear()
    return _ANCHORS.setdefault(key, {})


def _solve_y16(pvalue) -> float:
    """y with p(y) = 1e-16: regula falsi on ln p against y² (nearly linear in the tail, so a few
    evaluations of the costly p), bisection where that stalls. A function of ``pvalue`` alone
    (its bracket does not depend on the statistic that asked), so the cached y₁₆ and every z
    read from it are the same bits whatever fit came first."""
    target = math.log(_P_FLOOR)

    def f(y):
        p = pvalue(y)
        return (math.log(p) if p > 0.0 else -1e300) - target

    lo, hi = 0.0, 64.0                                        # f(lo) > 0 >= f(hi)
    fhi = f(hi)
    while fhi >= 0.0:                                         # a scan over very many onsets
        lo, hi = hi, 2.0 * hi
        fhi = f(hi)
    flo = math.inf
    y, side = (9.0 if lo == 0.0 else 0.5 * (lo + hi)), 0
    for _ in range(60):
        fy = f(y)
        if abs(fy) < 1e-3:                                    # ln p within 0.1 %: y within ~1e-4
            return y
        if fy >= 0.0:
            lo, flo = y, fy
            if side == 1:                                     # Illinois: the stale end counts half
                fhi *= 0.5
            side = 1
        else:
            hi, fhi = y, fy
            if side == -1:
                flo *= 0.5
            side = -1
        if hi - lo <= 1e-6 * hi:
            break
        if math.isfinite(flo) and fhi > -1e299:               # false position in y²
            y = math.sqrt(lo * lo + flo * (hi * hi - lo * lo) / (flo - fhi))
            if not lo < y < hi:
                y = 0.5 * (lo + hi)
        else:
            y = 0.5 * (lo + hi)
    return 0.5 * (lo + hi)


#: y₁₆ of :func:`_z_of_scan` per record shape (kind, samples, tracker): the tail's p(y) is costly
#: (an up-crossing sum over every onset) and a diagnosis fits the same gyro many times.
_Y16: dict = {}
#: tail(q95) of :func:`_null_pvalue` per record shape (same keys).
_ANCHORS: dict = {}


def _z_of_scan(stat: float, pvalue, key=None) -> float:
    """z of a scan statistic (the maximum over the onset of a signed-root likelihood ratio).

    ``pvalue(y)`` is P(max >= y) under no fault. Where it is at least 1e-16,
    z = Φ⁻¹(1 − p). Beyond, the tail of a Gaussian maximum is
    log p = −y²/2 + O(log y), as is log Φ̄(z) = −z²/2 + O(log z), so
    z² − y² tends to a constant: it is read where p = 1e-16 and carried on,
    z = √(z₁₆² + y² − y₁₆²). z then keeps ranking larger faults higher
    instead of stopping at 8.3 (or jumping to inf where p underflows).
    """
    if not np.isfinite(stat):
        return math.inf
    p = pvalue(stat)
    if p >= _P_FLOOR:
        return _z_of_p(p)
    y16 = _Y16.get(key) if key is not None else None
    if y16 is None:
        y16 = _solve_y16(pvalue)
        if key is not None:
            if len(_Y16) > 256:
                _Y16.clear()
            _Y16[key] = y16
    z16 = float(-special.ndtri(_P_FLOOR))
    return float(math.sqrt(max(z16 * z16 + stat * stat - y16 * y16, z16 * z16)))


# -- profiles over the onset -------------------------------------------------

def profile_means(eps: np.ndarray, a, K, S, coef: np.ndarray, kind: str, onsets: np.ndarray):
    """GLR of a step or a drift fault over candidate onsets, the fault lasting to the end.

    Parameters
    ----------
    eps : ndarray, shape (M, m)
        Normalised innovations of the m components (rows = samples).
    a, K, S : array_like, shape (m,)
        Steady-state 1 − K, gain and innovation variance of each component.
    coef : ndarray, shape (m, G)
        Fault direction of each of G candidates: the fault adds
        ``size·coef[:, g]`` to the (white-normalised) components.
    kind : {"step", "drift"}
        Signature (module docstring); a drift's size is its per-sample
        increment ρ·dt.
    onsets : ndarray of int, shape (T,)
        Candidate onsets (row indices of ``eps``).

    Returns
    -------
    num, den : ndarray, shape (T, G)
        Σ g·ε and Σ g² of each candidate's signature from the onset to the
        last row: size = num/den, its 1σ = 1/√den, ΔLL = num²/(2 den).
    mu_rough, mu_smooth : ndarray, shape (T − 1, G)
        1 − r(1) of Y(θ) = num/√den between consecutive onsets, split into
        the part of the sample entering at the onset and the part of the
        interior weights (:func:`clump_rate`).
    """
    eps = np.asarray(eps, dtype=float)
    M = eps.shape[0]
    a, K, S = (np.broadcast_to(np.asarray(v, dtype=float), (eps.shape[1],)) for v in (a, K, S))
    w = reverse_ar1(eps, a)                                   # Σ_{s>=θ} a^{s−θ} ε_s
    length = (M - onsets)[:, None].astype(float)              # samples from θ to the end
    c2 = coef**2 / S[:, None]                                 # (m, G)
    if kind == "step":
        per = w[onsets] / np.sqrt(S)                          # (T, m): Σ aⁿ ε /√S
        num = per @ coef
        e_comp = step_energy(a[None, :], S[None, :], length) * S[None, :]
        den = e_comp @ c2
        # onset sample: weight 1 (rough); interior: g(n+1) − g(n) = −K aⁿ (smooth)
        rough = np.broadcast_to(np.sum(c2, axis=0), den[:-1].shape)
        smooth = (step_energy(a[None, :], S[None, :], length[1:]) * S[None, :] * K[None, :]**2) @ c2
    elif kind == "drift":
        tail = np.cumsum(eps[::-1], axis=0)[::-1]             # Σ_{s>=θ} ε_s
        kk = np.where(K > 0, K, 1.0)
        per = (tail[onsets] - w[onsets]) / (kk * np.sqrt(S))  # Σ (1 − aⁿ) ε/(K√S)
        num = per @ coef
        e_comp = ramp_energy(a[None, :], K[None, :], S[None, :], length) * S[None, :]
        den = e_comp @ c2
        # onset sample: weight 0; interior: g(n+1) − g(n) = aⁿ
        rough = np.zeros_like(den[:-1])
        smooth = (step_energy(a[None, :], S[None, :], length[1:]) * S[None, :]) @ c2
    else:
        raise ValueError(f"kind must be 'step' or 'drift', got {kind!r}")
    empty = den <= 1e-12 * np.max(den, axis=0, keepdims=True)  # a drift's first sample: no signal
    num = np.where(empty, 0.0, num)
    den = np.where(empty, 1.0, den)
    scale = 2.0 * np.sqrt(den[:-1] * den[1:])
    return num, den, rough / scale, smooth / scale


def profile_variance(x: np.ndarray, onsets: np.ndarray):
    """GLR of a variance change from each onset to the end, per column.

    Parameters
    ----------
    x : ndarray, shape (M, G)
        Unit-variance white series (one per candidate direction).
    onsets : ndarray of int, shape (T,)

    Returns
    -------
    dll : ndarray, shape (T, G)
        M_θ/2·(λ̂ − 1 − ln λ̂), λ̂ = mean of x² from θ to the end.
    lam : ndarray, shape (T, G)
        λ̂.
    count : ndarray, shape (T,)
        M_θ, the samples from θ to the end.
    """
    x2 = np.asarray(x, dtype=float) ** 2
    tail = np.cumsum(x2[::-1], axis=0)[::-1]
    count = (x2.shape[0] - onsets).astype(float)
    lam = tail[onsets] / count[:, None]
    lam_safe = np.maximum(lam, 1e-300)
    dll = 0.5 * count[:, None] * (lam_safe - 1.0 - np.log(lam_safe))
    return dll, lam, count


def profile_variance_change(x: np.ndarray, onsets: np.ndarray):
    """GLR of a variance change at each onset, both levels unknown (one series).

    Parameters
    ----------
    x : ndarray, shape (M,)
        White series whose level need not be known.
    onsets : ndarray of int, shape (T,)
        Candidate onsets; each leaves samples on both sides.

    Returns
    -------
    dll : ndarray, shape (T,)
        M/2·ln λ̂ − M_b/2·ln λ̂_b − M_a/2·ln λ̂_a (λ̂ the mean of x² over the
        whole, before θ, from θ on).
    ratio : ndarray, shape (T,)
        λ̂_a/λ̂_b, the variance after over before.
    count : ndarray, shape (T,)
        M_a, samples from θ on.

    Notes
    -----
    Unlike :func:`profile_variance` it does not trust the noise model's
    level: a calibration made on a record whose noise rose half-way has a
    level between the two, and only the ratio after/before is right.
    """
    x2 = np.asarray(x, dtype=float) ** 2
    M = x2.size
    c = np.concatenate([[0.0], np.cumsum(x2)])
    mb = onsets.astype(float)
    ma = M - mb
    lb = np.maximum(c[onsets] / mb, 1e-300)
    la = np.maximum((c[M] - c[onsets]) / ma, 1e-300)
    lall = max(c[M] / M, 1e-300)
    dll = 0.5 * (M * math.log(lall) - mb * np.log(lb) - ma * np.log(la))
    return dll, la / lb, ma


def onset_sigma(dll: np.ndarray, positions: np.ndarray | None = None) -> tuple[int, float]:
    """Best onset and its 1σ from the profile likelihood over the onsets.

    Parameters
    ----------
    dll : ndarray, shape (T,)
        Log-likelihood gain ΔLL(θ) of each candidate onset.
    positions : ndarray, shape (T,), optional
        The onsets (sample indices); default 0 .. T − 1.

    Returns
    -------
    best : int
        Index of the maximum.
    sigma : float
        √(Σ w (θ − θ̂)²) with w ∝ exp(ΔLL(θ) − max), in samples: the spread
        of the profile likelihood over the onsets (a flat-prior posterior).
        A change-point's likelihood is jagged, so the curvature or the
        ΔLL >= max − ½ interval would understate it. At least 1/√12 (the grid).
    """
    pos = np.arange(dll.size, dtype=float) if positions is None else np.asarray(positions, float)
    best = int(np.argmax(dll))
    w = np.exp(dll - dll[best])
    w /= w.sum()
    return best, max(math.sqrt(float(np.sum(w * (pos - pos[best]) ** 2))), 1.0 / math.sqrt(12.0))


def stuck_run(output: np.ndarray, end: int | None = None) -> int:
    """Start of the run of identical values that ends at ``end`` (default: the last sample).

    Returns the index of the first sample of the run (the run has
    ``end − start + 1`` samples; a stuck gyro's onset is ``start + 1``, the
    first repeated value).
    """
    y = np.asarray(output)
    e = y.size - 1 if end is None else int(end)
    same = y[:e + 1] == y[e]
    diff = np.flatnonzero(~same)
    return int(diff[-1] + 1) if diff.size else 0


# -- the fit of one residual series -------------------------------------------

@dataclass(frozen=True)
class FaultFit:
    """A fitted fault on one series.

    Attributes
    ----------
    kind : str
        ``step``, ``drift``, ``stuck`` or ``noise``.
    onset_s, onset_sigma_s : float
        Fitted start time and its 1σ (profile likelihood) [s].
    size, size_sigma : float
        Step [rad/s], drift rate [rad/s²], noise amplitude ratio [-]; NaN for stuck.
    z : float
        Significance: ≈ N(0, 1) when there is no such fault (module docstring).
    dll : float
        Log-likelihood gain of the fault at the fitted onset [-].
    params, params_sigma : dict
        The effect's parameters in spec units (``start_s``, ``size_deg_s`` /
        ``rate_deg_s2`` / ``ratio``) and their 1σ.
    notes : tuple of str
    """

    kind: str
    onset_s: float
    onset_sigma_s: float
    size: float
    size_sigma: float
    z: float
    dll: float
    params: dict = field(default_factory=dict)
    params_sigma: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def effect(self) -> str:
        """The spec's effect name, ``fault_<kind>``."""
        return "fault_" + self.kind

    def to_json_dict(self) -> dict:
        return {"effect": self.effect, "params": dict(self.params),
                "params_sigma": dict(self.params_sigma), "z": self.z, "dll": self.dll,
                "onset_s": self.onset_s, "onset_sigma_s": self.onset_sigma_s,
                "notes": list(self.notes)}


def _check_series(residual, dt_s, r, q, time_s):
    y = np.asarray(residual, dtype=float)
    if y.ndim != 1 or y.size < 3 * MIN_VARIANCE_SAMPLES:
        raise InputError(f"a fault fit needs a 1-D residual of >= {3 * MIN_VARIANCE_SAMPLES} "
                         f"samples, got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise InputError("the residual contains a non-finite value")
    dt = float(dt_s)
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"dt_s must be > 0 [s], got {dt_s!r}")
    if not (math.isfinite(r) and r > 0) or not (math.isfinite(q) and q >= 0):
        raise InputError(f"noise variances must be r > 0 and q >= 0 per sample, got r = {r!r}, q = {q!r}")
    t = np.arange(y.size) * dt if time_s is None else np.asarray(time_s, dtype=float)
    if t.shape != y.shape:
        raise InputError(f"time_s has shape {t.shape}, the residual {y.shape}")
    return y, dt, t


def _pieces(n: int, breaks) -> list[tuple[int, int]] | None:
    """The stitched pieces [start, stop) of an n-sample series cut at ``breaks`` (first samples of
    the parts after the first; those outside [1, n − 1] ignored), or None (one piece)."""
    if breaks is None:
        return None
    b = np.unique(np.asarray(breaks, dtype=int).ravel())
    b = b[(b >= 1) & (b < n)]
    if b.size == 0:
        return None
    edges = [0, *(int(v) for v in b), n]
    return list(zip(edges[:-1], edges[1:]))


def fit_fault(kind: str, residual_rad_s, dt_s: float, r: float, q: float, *, time_s=None,
              output_rad_s=None, bias_memory_s: float = DEFAULT_BIAS_MEMORY_S,
              skip=None, breaks=None) -> FaultFit:
    """Fit one fault (onset and size with 1σ, and z) to one gyro's residual.

    Parameters
    ----------
    kind : {"step", "drift", "stuck", "noise"}
        The fault (effect ``fault_<kind>`` of the spec).
    residual_rad_s : array_like, shape (n,)
        The gyro's error series [rad/s]: output − h·(reference rate), or
        what a calibrated model leaves; its start bias need not be removed.
    dt_s : float
        Sample period [s].
    r : float
        White (ARW) variance per sample, N²/dt [rad²/s²].
    q : float
        Random-walk (RRW) increment variance per sample, K²·dt [rad²/s²].
    time_s : array_like, shape (n,), optional
        Sample times [s] (default k·dt).
    output_rad_s : array_like, shape (n,), optional
        The gyro's raw output [rad/s]: a stuck fault is the run of repeated
        values at its end (exact onset). Without it the stuck fit is the
        variance collapse of the residual (static records only).
    bias_memory_s : float
        Longest bias-tracker time constant [s] (module docstring).
    skip : array_like of bool, shape (n,), optional
        Samples without the gyro's noise (a clip's plateau, where a model
        already explains the output): the noise scan leaves them out (their
        innovations and the differences that touch them).
    breaks : array_like of int, optional
        First sample of each stitched part after the first (a record joined from still
        parts, each with its own free offset): the bias tracker starts again, diffuse,
        :data:`JOIN_GUARD` samples after each (the join's step is that offset, not a fault),
        the samples within :data:`JOIN_GUARD` of a join carry no innovation, a step or drift
        is scanned within its own part (its signature ends at the next join) and no onset
        within :data:`JOIN_GUARD` samples of a join is a candidate.

    Returns
    -------
    FaultFit

    Notes
    -----
    Method in the module docstring. A stuck gyro with the output given:
    onset = first repeated sample, its 1σ dt/√12 (the sample grid); z from
    the run length against the probability p₀ that two consecutive values of
    this gyro coincide before the run (p₀^run, p₀ >= 1/(samples + 2)).
    """
    if kind not in KINDS:
        raise InputError(f"unknown fault kind {kind!r} (known: {', '.join(KINDS)})")
    y, dt, t = _check_series(residual_rad_s, dt_s, float(r), float(q), time_s)
    qn = max(q / r, (dt / float(bias_memory_s)) ** 2)
    pieces = _pieces(y.size, breaks)
    if pieces is None:
        eps = rw_innovations(y / math.sqrt(r), qn)
    else:
        # the tracker starts again, diffuse, JOIN_GUARD samples after each join, and the samples
        # within JOIN_GUARD of a join carry no innovation: the settling of a part's edge (a still
        # mask's last samples of motion) is the join's offset too, not a fault
        eps = np.zeros(y.size)
        for j, (a_, b_) in enumerate(pieces):
            lo = a_ + (JOIN_GUARD if j > 0 else 0)
            hi = b_ - (JOIN_GUARD if j < len(pieces) - 1 else 0)
            if hi - lo >= 2:
                eps[lo:hi] = rw_innovations(y[lo:hi] / math.sqrt(r), qn)
    K, S = (float(v) for v in steady_gain(qn))
    a = 1.0 - K
    if kind in ("step", "drift"):
        if pieces is None:
            return _fit_mean(kind, eps[1:], a, K, S, qn, t[1:], dt, r)
        return _fit_mean_pieces(kind, eps[1:], a, K, S, qn, t[1:], dt, r, pieces)
    if kind == "noise":
        if pieces is not None:
            return _fit_noise_pieces(eps, y, K, S, t, dt, pieces, skip)
        if skip is None:
            return _difference_ratio(_fit_noise(eps[1:], K, S, t[1:], dt), y, t)
        keep = ~np.asarray(skip, bool)
        return _difference_ratio(_fit_noise(eps[1:][keep[1:]], K, S, t[1:][keep[1:]], dt), y, t, keep)
    if output_rad_s is not None:
        out = np.asarray(output_rad_s, dtype=float)
        if out.shape != y.shape:
            raise InputError(f"output_rad_s has shape {out.shape}, the residual {y.shape}")
        return _fit_stuck_output(out, t, dt)
    fit = _fit_noise(eps[1:], K, S, t[1:], dt, sides="down")
    return FaultFit("stuck", fit.onset_s, fit.onset_sigma_s, math.nan, math.nan, fit.z, fit.dll,
                    {"start_s": fit.onset_s}, {"start_s": fit.onset_sigma_s},
                    ("no raw output: onset from the collapse of the residual's noise (static records)",))


#: Grid of n·K on which the step and drift nulls are simulated, points per decade.
_NK_PER_DECADE = 16


def _null_q(n: int, K: float) -> float:
    """The q (per unit r) whose tracker gain puts n·K on a grid of 16 points per decade.

    The null's law moves with n·K only (:func:`_null_maxima`), and slowly (the
    maximum of a scan grows like √(2 ln(n·K))): a 15 % step in n·K moves its
    quantiles by < 1 %. On the grid the gyros of a record, and the records of one
    length, share one simulation (0.07 s each, ten per analysis otherwise); the
    grid point is a function of (n, K), so the bits never depend on what ran before.
    """
    nk = max(n * K, 1e-300)
    Kq = min(10.0 ** (round(math.log10(nk) * _NK_PER_DECADE) / _NK_PER_DECADE) / n, 0.5)
    return Kq * Kq / (1.0 - Kq)                               # K = P/(P + 1), q = P²/(P + 1), P = K/(1 − K)


def _fit_mean(kind, eps, a, K, S, qn, t, dt, r) -> FaultFit:
    onsets = np.arange(eps.size - 1)
    num, den, mr, ms = profile_means(eps[:, None], [a], [K], [S], np.ones((1, 1)), kind, onsets)
    return _scan_fault(kind, eps.size, K, qn, t, dt, r, num[:, 0], den[:, 0], mr[:, 0], ms[:, 0])


def _scan_fault(kind, n_eps, K, qn, onset_t, dt, r, num, den, mr, ms, rows=None, notes=()) -> FaultFit:
    """The fault of a profile scan (:func:`profile_means`'s ``num, den, mr, ms`` per onset): the
    best onset (its time in ``onset_t`` [s]; ``rows``: the onsets' sample rows, for its 1σ), its
    size or rate and their 1σ, and z against the null of a record of ``n_eps`` innovations."""
    dll = num * num / (2.0 * den)
    best, sig_k = onset_sigma(dll, rows)
    size = num[best] / den[best] * math.sqrt(r)               # rad/s (step) or rad/s per sample
    sigma = math.sqrt(r / den[best])
    null = _null_maxima(kind, n_eps, _null_q(n_eps, K), NULL_DRAWS)
    key = (kind, n_eps, float(qn))
    anchors = _anchors(key)
    z = _z_of_scan(math.sqrt(2.0 * dll[best]),
                   lambda y: _null_pvalue(y, null, lambda u: _analytic_max_p(u, mr, ms), anchors), key=key)
    onset, onset_sig = float(onset_t[best]), sig_k * dt
    if kind == "step":
        params = {"start_s": onset, "size_deg_s": float(rad_s_to_deg_s(size))}
        psig = {"start_s": onset_sig, "size_deg_s": float(rad_s_to_deg_s(sigma))}
        return FaultFit("step", onset, onset_sig, float(size), sigma, z, float(dll[best]), params, psig, notes)
    rate, rate_sig = size / dt, sigma / dt
    params = {"start_s": onset, "rate_deg_s2": float(rad_s_to_deg_s(rate))}
    psig = {"start_s": onset_sig, "rate_deg_s2": float(rad_s_to_deg_s(rate_sig))}
    return FaultFit("drift", onset, onset_sig, float(rate), float(rate_sig), z, float(dll[best]),
                    params, psig, notes)


def _fit_mean_pieces(kind, eps, a, K, S, qn, t, dt, r, pieces) -> FaultFit:
    """:func:`_fit_mean` on a stitched series: each part scanned on its own innovations (a fault's
    signature ends at the next join, where the tracker starts again), no onset within
    :data:`JOIN_GUARD` samples of a join; the onset and its 1σ over every part's onsets, the null
    that of one record of the same length (the scan has fewer onsets: conservative).

    ``eps``, ``t``: from the second sample on (as :func:`_fit_mean`); ``pieces``: [start, stop)
    of the parts in samples of the whole series."""
    nums, dens, mrs, mss, pos = [], [], [], [], []
    for j, (a_, b_) in enumerate(pieces):
        lo, hi = max(a_ - 1, 0), b_ - 1                      # the part's rows of eps
        first = lo + (JOIN_GUARD if j > 0 else 0)            # onset rows θ: the fault from sample θ + 1
        last = hi - 1 - (JOIN_GUARD if j < len(pieces) - 1 else 0)
        if last - first < 2:
            continue
        onsets = np.arange(first, last + 1) - lo
        num, den, mr, ms = profile_means(eps[lo:hi, None], [a], [K], [S], np.ones((1, 1)), kind, onsets)
        nums.append(num[:, 0])
        dens.append(den[:, 0])
        mrs.append(mr[:, 0])
        mss.append(ms[:, 0])
        pos.append(onsets + lo)
    if not pos:                                              # every part within its joins' guard
        return FaultFit(kind, float(t[0]), math.inf, 0.0, math.inf, -math.inf, 0.0,
                        {"start_s": float(t[0]), ("size_deg_s" if kind == "step" else "rate_deg_s2"): 0.0},
                        {"start_s": math.inf, ("size_deg_s" if kind == "step" else "rate_deg_s2"): math.inf},
                        (f"stitched parts too short for a {kind} scan {JOIN_GUARD} samples from each join",))
    num, den, mr, ms = (np.concatenate(v) for v in (nums, dens, mrs, mss))
    onset_rows = np.concatenate(pos)
    note = (f"{len(pieces)} stitched parts: the bias tracker starts again after each join, and nothing within "
            f"{JOIN_GUARD} samples of one is scanned (a join's step is its part's own offset)",)
    return _scan_fault(kind, eps.size, K, qn, t[onset_rows], dt, r, num, den, mr, ms, onset_rows, note)


def _difference_ratio(fit: FaultFit, y: np.ndarray, t: np.ndarray, keep=None) -> FaultFit:
    """The noise fault's ratio read from the residual's first differences at the fitted onset.

    Differences remove the bias and its walk: var(Δy) = 2r + q, q ≪ r for a
    MEMS gyro at its sample rate (K = 8 deg/h/√h and N = 0.1 deg/√h at 50 Hz:
    q/r ≈ 2e-7), so ratio² = var(Δy after)/var(Δy before) needs neither r nor
    q. The innovations' ratio needs both, and a calibration on the faulty
    record inflates q (the raised tail reads as random walk): 5.1 for 3.1 set.
    1σ: the sample variance of white noise's differences (lag-one correlation
    −1/2) has var(s²)/σ⁴ = 2(1 + 2·¼)/n = 3/n, so σ(ln λ) = √(3/n_a + 3/n_b).
    The onset, its 1σ and z stay the innovations' (a scan with the bias tracked).
    """
    d, td = np.diff(y), t[1:]
    if keep is not None:                                      # differences between kept samples only
        both = keep[1:] & keep[:-1]
        d, td = d[both], td[both]
    k = int(np.searchsorted(td, fit.onset_s))                 # first difference after the onset
    na, nb = d.size - k, k
    if na < 2 or nb < 2:
        return fit
    va, vb = float(np.mean((d[k:] - d[k:].mean()) ** 2)), float(np.mean((d[:k] - d[:k].mean()) ** 2))
    if not (va > 0.0 and vb > 0.0):
        return fit
    ratio = math.sqrt(va / vb)
    sig = 0.5 * ratio * math.sqrt(3.0 / na + 3.0 / nb)
    return FaultFit("noise", fit.onset_s, fit.onset_sigma_s, ratio, sig, fit.z, fit.dll,
                    {**fit.params, "ratio": ratio}, {**fit.params_sigma, "ratio": sig}, fit.notes)


def noise_share(K: float, S: float) -> float:
    """w = 2/((2 − K)·S): share of the innovation variance that is the white noise itself."""
    return 2.0 / ((2.0 - K) * S)


def _variance_onsets(n: int) -> np.ndarray:
    """Onsets of a variance fit: at least MIN_VARIANCE_SAMPLES on each side."""
    return np.arange(MIN_VARIANCE_SAMPLES, max(n - MIN_VARIANCE_SAMPLES, MIN_VARIANCE_SAMPLES + 1))


#: Lags summed by :func:`_variance_dof_factor` (a sensor filter at a tenth of the sample rate
#: correlates its noise over a few samples; 64 keeps the estimate's own noise, 64/n, small).
_DOF_LAGS = 64


def _variance_dof_factor(eps: np.ndarray) -> float:
    """1 + 2 Σₖ ρₖ² (k = 1…64): how much a sample variance of ``eps`` scatters more than the
    white-noise χ² the variance scan assumes (var(s²) = 2σ⁴(1 + 2Σρₖ²)/n for a Gaussian series).

    A gyro's own low-pass (or a Gauss–Markov) leaves its innovations
    correlated: the scan's log-likelihood ratio is then a quasi-likelihood
    inflated by this factor, and it is divided by it (a 4.7 Hz 2nd-order
    filter at 50 Hz read as a noise drop of 0.61 at z 4.9 in its last
    second). A change of the variance alone correlates nothing, so a real
    noise fault keeps its ratio.
    """
    x = np.asarray(eps, float) - float(np.mean(eps))
    n = x.size
    lags = min(_DOF_LAGS, n // 8)
    if lags < 1:
        return 1.0
    c0 = float(x @ x)
    if not c0 > 0.0:
        return 1.0
    rho = np.array([float(x[:-k] @ x[k:]) for k in range(1, lags + 1)]) / c0   # 64 dots: 3x an FFT's speed
    return float(1.0 + 2.0 * np.sum(rho * rho))


#: Longest record the variance scan's null is simulated on (:func:`_variance_null_pvalue`).
_VARIANCE_NULL_MAX_N = 1 << 17


def _variance_null_pvalue(sides: str, n: int, rr: np.ndarray, anchors: dict):
    """p(y) = P(max over the onsets of the variance scan >= y) with no fault, on n samples.

    Up to 2¹⁷ samples: the Monte Carlo null of :func:`_null_pvalue`. Longer
    (the ADIS16405's 1e6: 200 draws of 1e6 normals and their scans, 6 s): it
    is simulated on m = 2¹⁷ and carried to n by the clumps. The maximum
    exceeds y when at least one excursion does, and excursions are nearly a
    Poisson count, so −ln(1 − p) is their expected number, which grows with
    the record as the analytic clump sum Λ(y) does:
    −ln(1 − p_n(y)) = −ln(1 − p_m(y))·Λ_n(y)/Λ_m(y). Only a ratio of the
    analytic sums enters, not their level.
    """
    kind = "stuck" if sides == "down" else "noise"
    if n <= _VARIANCE_NULL_MAX_N:
        null = _null_maxima(kind, n, 0.0, NULL_DRAWS)
        return lambda y: _null_pvalue(y, null, lambda u: _analytic_max_p(u, rr), anchors)
    m = _VARIANCE_NULL_MAX_N
    null = _null_maxima(kind, m, 0.0, NULL_DRAWS)
    ma = m - _variance_onsets(m).astype(float)                # the scan's count on m samples, as rr's
    rr_m = 1.0 - np.sqrt(ma[1:] / ma[:-1])
    sub = _anchors((sides, m))

    def p(y):
        pm = _null_pvalue(y, null, lambda u: _analytic_max_p(u, rr_m), sub)
        if pm >= 1.0:
            return 1.0
        lam_n, lam_m = -math.log1p(-_analytic_max_p(y, rr)), -math.log1p(-_analytic_max_p(y, rr_m))
        if not lam_m > 0.0:
            return pm
        return float(-math.expm1(math.log1p(-pm) * lam_n / lam_m))
    return p


def _fit_noise_pieces(eps, y, K, S, t, dt, pieces, skip=None) -> FaultFit:
    """The noise fault on a stitched series (``eps``: :func:`fit_fault`'s per-part innovations,
    the whole series' rows; ``pieces``: the parts [start, stop) in samples).

    Read are the samples that carry an innovation: not within :data:`JOIN_GUARD` of a join, not a
    part's first scanned sample (where its tracker starts, ε = 0), not ``skip``. An onset is a
    candidate only with :data:`JOIN_GUARD` read samples between it and every join (a noise change
    at a join is the next part's own level); the ratio reads the differences between read
    samples only (none across a join)."""
    n = y.size
    keep = np.zeros(n, bool)
    for j, (a_, b_) in enumerate(pieces):
        lo = a_ + (JOIN_GUARD if j > 0 else 0)
        hi = b_ - (JOIN_GUARD if j < len(pieces) - 1 else 0)
        if hi - lo >= 2:
            keep[lo + 1:hi] = True                           # lo: the tracker's start, ε = 0
    if skip is not None:
        keep &= ~np.asarray(skip, bool)
    rows = np.flatnonzero(keep)
    if rows.size < 3 * MIN_VARIANCE_SAMPLES:
        return FaultFit("noise", float(t[0]), math.inf, 1.0, math.inf, -math.inf, 0.0,
                        {"start_s": float(t[0]), "ratio": 1.0}, {"start_s": math.inf, "ratio": math.inf},
                        (f"stitched parts too short for a noise scan {JOIN_GUARD} samples from each join",))
    onsets = _variance_onsets(rows.size)
    joins = np.array([a_ for a_, _ in pieces[1:]], dtype=int)
    # read samples between each onset and each join: JOIN_GUARD at least on the onset's side
    k_join = np.searchsorted(rows, joins)                    # read rows before each join
    near = np.zeros(onsets.size, bool)
    for kj in k_join:
        near |= np.abs(onsets - kj) < JOIN_GUARD
    if near.all():
        return FaultFit("noise", float(t[0]), math.inf, 1.0, math.inf, -math.inf, 0.0,
                        {"start_s": float(t[0]), "ratio": 1.0}, {"start_s": math.inf, "ratio": math.inf},
                        (f"stitched parts too short for a noise scan {JOIN_GUARD} samples from each join",))
    note = (f"{len(pieces)} stitched parts: the bias tracker starts again after each join, the samples "
            f"within {JOIN_GUARD} of one are not read and no onset within {JOIN_GUARD} read samples of one "
            "is scanned (a join's noise is its part's own)",)
    fit = _fit_noise(eps[rows], K, S, t[rows], dt, onsets=onsets[~near])
    fit = replace(fit, notes=fit.notes + note)
    return _difference_ratio(fit, y, t, keep)


def _fit_noise(eps, K, S, t, dt, sides: str = "both", onsets=None) -> FaultFit:
    """The variance scan of ``eps`` over ``onsets`` (default :func:`_variance_onsets`: every onset
    with MIN_VARIANCE_SAMPLES on each side); the null that of every onset (conservative when
    fewer are scanned)."""
    all_onsets = _variance_onsets(eps.size)
    onsets = all_onsets if onsets is None else np.asarray(onsets)
    dll, lam, count = profile_variance_change(eps, onsets)
    dll = dll / _variance_dof_factor(eps)
    if sides == "down":
        dll = np.where(lam < 1.0, dll, 0.0)
    best, sig_k = onset_sigma(dll, onsets)
    w = noise_share(K, S)
    ratio = math.sqrt(max(0.0, 1.0 + (lam[best] - 1.0) / w))
    before = float(onsets[best])
    lam_sig = lam[best] * math.sqrt(2.0 / count[best] + 2.0 / before)   # ratio of two χ² means
    ratio_sig = lam_sig / (2.0 * w * max(ratio, 1e-12))
    count_all = (eps.size - all_onsets).astype(float)         # the null's: every onset (conservative)
    rr = 1.0 - np.sqrt(count_all[1:] / count_all[:-1])        # 1 − corr of running sums of x²
    key = (sides, eps.size)
    anchors = _anchors(key)
    z = _z_of_scan(math.sqrt(2.0 * dll[best]), _variance_null_pvalue(sides, eps.size, rr, anchors), key=key)
    onset, onset_sig = float(t[onsets[best]]), sig_k * dt
    params = {"start_s": onset, "ratio": ratio}
    psig = {"start_s": onset_sig, "ratio": ratio_sig}
    return FaultFit("noise", onset, onset_sig, ratio, ratio_sig, z, float(dll[best]), params, psig)


#: Fewest runs of identical outputs before the terminal one from which their own length
#: distribution is the null (fewer: the i.i.d. repeat probability).
STUCK_MIN_RUNS = 50
#: Quantile of the earlier runs' lengths above which their excess is read as geometric (the
#: tail the terminal run is compared with).
STUCK_TAIL_QUANTILE = 0.9


def run_lengths(output: np.ndarray) -> np.ndarray:
    """Lengths of the runs of identical consecutive values of ``output``, in order [samples]."""
    y = np.asarray(output)
    if y.size == 0:
        return np.zeros(0, dtype=np.int64)
    edges = np.flatnonzero(y[1:] != y[:-1]) + 1
    return np.diff(np.r_[0, edges, y.size]).astype(np.int64)


#: Fewest earlier runs beyond the threshold u, and distinct lengths among them, from which their
#: excess is fitted a generalized Pareto law (fewer: geometric).
STUCK_GPD_MIN = (30, 5)


def log_p_run_at_least(lengths: np.ndarray, run: int) -> tuple[float, str]:
    """log P(one run >= ``run``) from the record's own earlier run lengths, and how it was read.

    A quantized output whose bias wanders slowly (a quiet counter of a few levels) repeats in
    long clusters: its runs are far longer than independent repeats at the record's repeat
    rate would give, and heavy-tailed (numpy counters at 0.15-0.4 LSB of white noise and a
    slow walk, each record cut at the end of its longest run: z 2-75 under the i.i.d. rate).
    So the terminal run is compared with the record's own runs (peaks over a threshold): up
    to the :data:`STUCK_TAIL_QUANTILE` quantile u of their lengths the empirical survival
    (Laplace); beyond it the excess over u follows a generalized Pareto law fitted by maximum
    likelihood (scipy.stats.genpareto, shape ξ held >= 0: never a lighter tail than
    geometric, i.e. than independent repeats), or, with too few long runs to fit one
    (:data:`STUCK_GPD_MIN`), a geometric excess whose ratio is read from their mean excess.
    Independent repeats give geometric runs, ξ = 0: the law of the i.i.d. test, read from the
    runs instead of the samples.
    """
    L = np.asarray(lengths, dtype=float)
    k = L.size
    u = max(2.0, float(np.floor(np.quantile(L, STUCK_TAIL_QUANTILE))))
    if run <= u:
        return math.log((np.sum(L >= run) + 1.0) / (k + 1.0)), "its earlier runs' lengths"
    tail = L[L >= u] - u
    log_tail = math.log((tail.size + 1.0) / (k + 1.0))
    if tail.size >= STUCK_GPD_MIN[0] and np.unique(tail).size >= STUCK_GPD_MIN[1]:
        ex = tail + 0.5     # whole samples: the excess is the floor of a continuous one
        xi, _, scale = stats.genpareto.fit(ex, floc=0.0)
        if not (math.isfinite(xi) and math.isfinite(scale) and scale > 0):
            xi = 0.0
        xi = max(float(xi), 0.0)
        if xi == 0.0:
            # the exponential whose floor is the geometric excess of this mean m: its
            # ratio m/(1+m) is e^(-1/scale)
            scale = 1.0 / math.log1p(1.0 / max(float(np.mean(tail)), 1e-12))
        log_sf = float(stats.genpareto.logsf(run - u, xi, 0.0, scale))  # P(floor >= run - u)
        return (log_tail + log_sf, f"the tail of its earlier runs (beyond {u:.0f} samples, "
                f"generalized Pareto, shape {xi:.2g}, scale {scale:.3g} samples)")
    ratio = (tail.sum() + 0.5) / (tail.sum() + tail.size + 1.0)    # geometric excess, Laplace
    return (log_tail + (run - u) * math.log(ratio),
            f"the tail of its earlier runs (beyond {u:.0f} samples, geometric, ratio {ratio:.3g})")


def _fit_stuck_output(out: np.ndarray, t: np.ndarray, dt: float) -> FaultFit:
    start = stuck_run(out)
    run = out.size - start                                    # samples in the terminal run
    lengths = run_lengths(out[:start])                        # the runs before the terminal one
    if lengths.size >= STUCK_MIN_RUNS:
        log_p, how = log_p_run_at_least(lengths, run)         # one run this long ...
        log_np = math.log(lengths.size + 1.0) + log_p         # ... among the record's runs
        said = f"against {how}, {lengths.size} runs"
    else:
        before = out[:start + 1]
        same = int(np.sum(before[1:] == before[:-1]))
        p0 = (same + 1.0) / (before.size + 1.0)               # Laplace: never 0
        log_p = (run - 1) * math.log(p0)                      # P(run − 1 repeats) = p0^(run−1)
        log_np = math.log(out.size) + log_p                   # anywhere in the record
        said = f"p0 = {p0:.3g} before it"
    log_pmax = math.log(-math.expm1(-math.exp(log_np))) if log_np > -20 else log_np   # 1 − e^(−n·p)
    z = _z_of_logp(min(log_pmax, 0.0)) if run >= 2 else -math.inf
    onset_i = min(start + 1, out.size - 1)
    onset = float(t[onset_i])
    sig = dt / math.sqrt(12.0)
    return FaultFit("stuck", onset, sig, math.nan, math.nan, z, float(-log_p) if run >= 2 else 0.0,
                    {"start_s": onset}, {"start_s": sig},
                    (f"terminal run of {run} identical outputs ({said})",))


def fit_faults(residual_rad_s, dt_s: float, r: float, q: float, **kw) -> dict[str, FaultFit]:
    """:func:`fit_fault` for every kind: ``{kind: FaultFit}``."""
    return {k: fit_fault(k, residual_rad_s, dt_s, r, q, **kw) for k in KINDS}
