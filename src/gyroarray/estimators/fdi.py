"""Fault detection, isolation and recovery (FDI) on a redundant gyro array: parity space.

A gyro array reads z = Hω + b + v (N gyros, N > 3): N − 3 combinations of the
readings do not see the body rate. The detector watches them, finds a faulty
gyro (``fault_step``, ``fault_drift``, ``fault_stuck``, ``fault_noise`` of
``shared/spec/effects.md``), names it when the geometry allows, and fuses the
rate again without it.

The chain (one stage each)
--------------------------
1. **Parity.** With R = L Lᵀ the ARW covariance of one sample (correlation
   included), W = L⁻¹ whitens the readings; V (m×N, m = N − 3) is an
   orthonormal basis of the left null space of W H: V W H = 0, V Vᵀ = I.
   p = P z with P = V W then has P H = 0 and white noise of covariance I,
   whatever the correlation, so a correlated array raises no more false
   alarms than an uncorrelated one. V is rotated so that the parity random
   walk P Q_b Pᵀ is diagonal (still V Vᵀ = I).
2. **Bias tracking.** The unknown starting biases and their RRW move p:
   each of the m components gets the scalar Kalman bias tracker of
   :mod:`gyroarray.effects.faults.scan` (random walk q_i + unit white noise,
   diffuse start, exact time-varying gain). Its normalised innovations ε are
   i.i.d. N(0, I) without a fault. The tracker's time constant is
   τ_i = dt/K_i, at most ``bias_memory_s``: the cost is that a drift slower
   than that is seen only through the offset ρ·τ it leaves, so the
   smallest detectable drift rate ∝ 1/(τ·√window) (:func:`minimum_detectable`).
3. **Detection.** A fault on gyro j adds size·P[:, j] to p; its trace in ε
   is known (Willsky–Jones signature: aⁿ for a step, (1 − aⁿ)/K for a
   drift). Three families of tests, each a GLR per distinct parity direction:

   * steps and stuck gyros (under motion): the step signature fitted on a
     window of the last L samples, onset at its start (L = 1, 2, 4, ... up
     to 4τ): Y = Σ g ε/√Σ g², a N(0, 1) under no fault;
   * drifts: the same with the ramp signature, L = 2, 4, ... up to
     ``drift_window_s``;
   * noise faults: the variance of ε along the gyro's direction over
     non-overlapping blocks of L samples (L = 32 up to ``variance_window_s``),
     the one-sided χ²_L GLR L/2(λ̂ − 1 − ln λ̂) for λ̂ > 1 (0 otherwise). A
     noise fault is an *increase* of a gyro's noise: a decrease is what a
     real gyro does between orientations and vibration states (the MIMU4444
     board: its z gyros' white levels move by x2–4 between still parts), and
     no fault of the spec makes a gyro quieter but a stuck one, which has its
     own test. Where a gyro's level changes along the record without a fault
     (:func:`noise_spread`), λ̂ is read against the top of its band;
   * stuck gyros (flat line): a run of exactly repeated outputs longer than
     the gyro's own repeats make plausible (probability :data:`STUCK_RUN_P`
     under its repeat share before the run, :func:`flat_alarm`). At rest a
     stuck gyro's parity only loses its noise (a variance *decrease*), so
     this, not the variance family, finds it; under motion the step family
     does too.

4. **Thresholds** from the false-alarm rate per hour (``far_per_h``, a third
   to each family), analytically: a block test's tail is an exact χ²
   probability (the upper tail only); a sliding window test is a stationary Gaussian sequence
   whose excursion rate above u is :func:`~gyroarray.effects.faults.scan.clump_rate`
   (Siegmund–Yakir for the window edges, Rice for the interior, from the
   exact lag-one correlation of the weights). The family's rate is the sum
   over its directions and windows (a union bound, tight at these levels);
   u is solved for it. A false alarm is an excursion: the alarm re-arms once
   every statistic has been under its threshold for the window that fired.
   Checked by simulation (``tests/test_fdi.py``, ``benchmarks/bench_fdi.py``).
5. **Isolation.** After an alarm, each gyro's signature (and each kind) is
   fitted over the candidate onsets (GLR, :func:`profile_means`,
   :func:`profile_variance`); the gyro is named when its log-likelihood beats
   every gyro with another parity direction by ln(``isolation_odds``)
   (odds 99:1 by default), re-tried on 0, 1, 2, 4, ... s of data after the
   alarm up to ``isolation_s``; the kind, onset and size are then refitted
   on that whole stretch. Gyros whose parity directions are parallel
   (all four of an N = 4 array: m = 1) cannot be told apart: "detected, not
   isolable" — never a guess. A gyro whose output repeats the same value
   from before the alarm on (run longer than its pre-fault repeats make
   plausible at 1e-9) is stuck, whatever N: the flat line names it.
6. **Recovery.** From the isolation on, the isolated gyro is excluded and
   the rate re-fused by GLS on the N − 1 others (HᵀR⁻¹H re-solved);
   detection goes on with their parity (N − 1 > 3). :meth:`estimate` returns
   that fault-tolerant GLS rate, so ``fdi`` is also a fusion estimator.

Levels read on the record
-------------------------
The tests work per sample, so R is the variance of one sample. A noise
model's ARW (``gyroarray fit``, a fusion chain's Allan fit) is the white
level at τ >= 1 s, below the per-sample level of a MEMS gyro with vibration
lines (the MIMU4444 board: x2–5 in variance). With still parts in the record
each gyro's per-sample level is therefore read there
(:func:`per_sample_noise`; without a model :func:`estimate_noise`), the
model keeping its correlations and, where larger, its RRW; the wander of a
gyro's level between still parts is learned as the top of a no-fault band
(:func:`noise_spread`), and a level that rises on every gyro at once widens
that part's tests (:func:`gyroarray.chain.fdi_score.test_record`).

Why it sits in the estimator registry: it takes the same fit (layout, noise
model, dt), and its :meth:`estimate` is a rate estimator (GLS with the fit's
weights that drops an isolated gyro; the detection itself runs as on a
record, :meth:`FaultDetector.detect_record`), so the conformance suite is
meaningful for it and ``run --estimators fdi`` scores the fused error with
recovery. It is not among the
chain's default estimators, so design sweeps are unchanged.

References
----------
J. E. Potter, M. C. Suman, "Thresholdless redundancy management with arrays
of skewed instruments", AGARDograph 224, 1977. M. A. Sturza, "Navigation
system integrity monitoring using redundant measurements", Navigation 35(4),
1988. A. S. Willsky, H. L. Jones, IEEE TAC 21(1), 1976. M. Basseville,
I. V. Nikiforov, *Detection of Abrupt Changes*, 1993.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg, optimize, special, stats

from gyroarray.effects.faults import scan as ff
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.analysis.motion import still_mask
from gyroarray.core.measurement import true_runs
from gyroarray.core.units import rad_s_to_deg_s

from gyroarray.estimators.base import Estimator, readonly, check_readings, register
from gyroarray.estimators.kf_array import gls_weights
from gyroarray.estimators.noise import ArrayNoise, array_noise

__all__ = ["FaultDetector", "ParityDesign", "Alarm", "FdiResult", "parity_matrix",
           "design_parity", "minimum_detectable", "minimum_detectable_step", "isolability",
           "estimate_noise", "noise_spread", "band_ratio", "variance_glr", "flat_alarm", "stuck_run_needed",
           "model_noise", "far_range_per_h", "parity_is_zero",
           "KIND_UNITS",
           "MIN_RECORD_SAMPLES", "MAX_WINDOW_SAMPLES"]

#: Unit of ``Alarm.size`` per kind (JSON ``size_unit``).
KIND_UNITS = {"step": "deg/s", "drift": "deg/s^2", "stuck": "deg/s", "noise": "ratio"}

#: Two parity directions with |cos| above this are the same direction (not isolable).
COLLINEAR_COS = 1.0 - 1e-9

#: Shortest variance block [samples].
VARIANCE_MIN_BLOCK = 32

#: Shortest start of a record the noise is estimated on when no model is given [s].
REFERENCE_SPAN_S = 60.0

#: Probability a stuck run of repeated outputs may have under the gyro's normal behaviour.
STUCK_RUN_P = 1e-9

#: Fewest samples ``gyroarray fdi`` analyses: one shortest variance block after the first
#: innovation (ε₀ is skipped), so every test family can run at least once; it also gives the
#: noise estimate (:func:`estimate_noise`) three octaves of adjacent means for its two unknowns.
MIN_RECORD_SAMPLES = VARIANCE_MIN_BLOCK + 1

#: Fewest samples the noise estimate fits on (two octaves, m = 1 and 2, of >= 8 means each).
MIN_NOISE_SAMPLES = 16

#: Length of the chunks of the still parts the per-gyro levels and their spread are read on [s].
NOISE_CHUNK_S = 10.0

#: Fewest samples of such a chunk.
MIN_CHUNK_SAMPLES = 64

#: A gyro's level changes between chunks count as real when Cochran's Q has a p-value below this.
SPREAD_P = 1e-3

#: Largest rise of a gyro's variance between neighbouring chunks that is a creeping level, not a
#: noise fault's onset (:func:`noise_spread`) [-].
SPREAD_JUMP = 1.5

#: κ = exp(SPREAD_Z·τ), τ the between-chunk standard deviation of a gyro's ln variance [-].
SPREAD_Z = 3.0

#: Longest test window [samples], whatever the windows in seconds and the sample rate: the
#: thresholds are calibrated on signature weights of that length (memory ∝ window × N), so
#: 600 s at 1 MHz would otherwise need 2^29-sample arrays. 2^20 leaves every rate up to
#: 1.7 kHz with its 600 s drift window unchanged.
MAX_WINDOW_SAMPLES = 2 ** 20

#: Smallest false-alarm rate the thresholds are solved for [1/h] (once per 10^8 years; the
#: Gaussian levels stay far inside the solver's bracket at any sample rate).
FAR_MIN_PER_H = 1e-12

#: Largest false-alarm rate as a share of the samples [-]: more than one alarm per 100
#: samples is not a false-alarm rate a threshold can be set for (the tests fire at their
#: lowest level already).
FAR_MAX_PER_SAMPLE = 0.01

#: Parity below this share of the readings' norm is zero to rounding (:func:`parity_is_zero`).
PARITY_ZERO_RTOL = 1e-9

_FAMILIES = ("step", "drift", "variance")


# -- parity space ------------------------------------------------------------

def parity_matrix(H: np.ndarray, R: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Parity matrix of an array: V with V (W H) = 0, V Vᵀ = I, and P = V W.

    Parameters
    ----------
    H : ndarray, shape (N, 3)
        Unit sensitive axes [-].
    R : ndarray, shape (N, N), optional
        Covariance of one sample of the white noise [rad²/s²]; default I
        (then W = I and P = V).

    Returns
    -------
    V : ndarray, shape (N − 3, N)
        Orthonormal rows spanning the left null space of W H [-].
    P : ndarray, shape (N − 3, N)
        V W, W = L⁻¹ (R = L Lᵀ): P H = 0, P R Pᵀ = I [1/(rad/s)].
    """
    H = np.asarray(H, dtype=float)
    n = H.shape[0]
    if R is None:
        W = np.eye(n)
    else:
        try:
            L = np.linalg.cholesky(R)
        except np.linalg.LinAlgError:
            raise InputError("the white-noise covariance of the model is not positive definite "
                             "(an ARW too small to represent in double precision, or correlations "
                             "of ±1): give every gyro an ARW it can have, e.g. n_deg_rt_h = 0.01, "
                             "and correlations within (−1, 1)") from None
        W = linalg.solve_triangular(L, np.eye(n), lower=True)
    V = linalg.null_space((W @ H).T).T                        # rows ⟂ columns of W H
    return V, V @ W


@dataclass(frozen=True, eq=False)
class ParityDesign:
    """Everything the detector precomputes for one set of active gyros.

    Attributes
    ----------
    gyros : tuple of int
        0-based indices of the active gyros (columns of the readings).
    V, P : ndarray, shape (m, n_a)
        Rotated parity basis (V W H = 0, V Vᵀ = I) and operator P = V W.
    q, K, S : ndarray, shape (m,)
        Per component: random-walk variance per sample (units of the white
        variance, floored by the bias memory), steady-state gain, innovation
        variance.
    coef : ndarray, shape (m, n_a)
        Fault direction of each gyro in p: P[:, j] [1/(rad/s)].
    groups : tuple of tuple of int
        Active-gyro positions (into ``gyros``) sharing one parity direction.
    var_dir : ndarray, shape (m, n_a)
        Unit direction in ε of each gyro's white noise (variance tests).
    white_share : ndarray, shape (n_a,)
        Share of the variance along ``var_dir`` that is the gyro's own white noise.
    scales : dict
        Window lengths [samples] per family.
    thresholds : dict
        u of the step and drift families (on |Y|), the GLR level of the
        variance family.
    far_per_h : dict
        Design false-alarm rate per family [1/h] (each a third of the total).
    stats : dict
        Per family: list of (group, L, weights …) the scan evaluates.
    gls : ndarray, shape (3, n_a)
        GLS weights of the active gyros.
    var_band : ndarray, shape (2, n_a) or None
        Lowest and highest variance ratio along each gyro's ``var_dir`` that
        is still no fault (the gyros' own level changes, :func:`noise_spread`);
        None: exactly 1 (the noise levels are known).
    """

    gyros: tuple
    V: np.ndarray
    P: np.ndarray
    q: np.ndarray
    K: np.ndarray
    S: np.ndarray
    coef: np.ndarray
    groups: tuple
    var_dir: np.ndarray
    white_share: np.ndarray
    scales: dict
    thresholds: dict
    far_per_h: dict
    gls: np.ndarray
    energies: dict = field(default_factory=dict)
    var_band: np.ndarray | None = None

    @property
    def m(self) -> int:
        """Parity dimension N − 3."""
        return int(self.P.shape[0])

    @property
    def a(self) -> np.ndarray:
        return 1.0 - self.K

    def __eq__(self, other) -> bool:
        if not isinstance(other, ParityDesign):
            return NotImplemented
        arrays = ("V", "P", "q", "K", "S", "coef", "var_dir", "white_share", "gls")
        return (self.gyros == other.gyros and self.groups == other.groups
                and self.scales == other.scales and self.thresholds == other.thresholds
                and self.far_per_h == other.far_per_h
                and all(np.array_equal(getattr(self, k), getattr(other, k)) for k in arrays)
                and ((self.var_band is None and other.var_band is None)
                     or (self.var_band is not None and other.var_band is not None
                         and np.array_equal(self.var_band, other.var_band))))

    __hash__ = None  # type: ignore[assignment]


def _groups(coef: np.ndarray) -> tuple:
    """Gyros with parallel (or anti-parallel) parity directions, grouped."""
    n = coef.shape[1]
    norms = np.linalg.norm(coef, axis=0)
    unit = coef / np.where(norms > 0, norms, 1.0)
    out, seen = [], set()
    for j in range(n):
        if j in seen:
            continue
        if norms[j] == 0:
            grp = [j]
        else:
            grp = [k for k in range(n) if k not in seen and norms[k] > 0
                   and abs(float(unit[:, j] @ unit[:, k])) >= COLLINEAR_COS]
        seen.update(grp)
        out.append(tuple(grp))
    return tuple(out)


def _pow2_scales(lo: float, hi: float) -> tuple:
    lo = max(int(lo), 1)
    out = []
    L = 1
    while L <= hi:
        if L >= lo:
            out.append(L)
        L *= 2
    return tuple(out) or (lo,)


def window_weights(kind: str, a, K, S, c, L: int) -> np.ndarray:
    """Signature weights h_i(n), n < L, of one gyro direction c (m,) -> (L, m)."""
    n = np.arange(L)[:, None]
    if kind == "step":
        return c[None, :] * a[None, :] ** n / np.sqrt(S)[None, :]
    return c[None, :] * (1.0 - a[None, :] ** n) / (K * np.sqrt(S))[None, :]


def _window_roughness(h: np.ndarray) -> tuple[float, float, float]:
    """Energy E = Σh², and 1 − r(1) split into edges (rough) and interior (smooth)."""
    E = float(np.sum(h * h))
    edges = float(np.sum(h[0] ** 2) + np.sum(h[-1] ** 2)) if h.shape[0] > 1 else 2.0 * E
    interior = float(np.sum(np.diff(h, axis=0) ** 2)) if h.shape[0] > 1 else 0.0
    return E, edges / (2.0 * E), interior / (2.0 * E)


def _solve_level(rate_fn, target: float, lo: float = 0.5, hi: float = 60.0) -> float:
    """The level x with rate_fn(x) = target (rate decreasing in x), on a log scale.

    Raises
    ------
    InputError
        ``target`` below the rate at ``hi`` (a false-alarm rate too small to
        set a threshold for; :func:`far_range_per_h` keeps callers away from it).
    """
    if not (math.isfinite(target) and target > 0):
        raise InputError(f"far_per_h gives a false-alarm probability per sample of {target!r}: "
                         "it must be finite and > 0")
    f = lambda x: math.log(max(rate_fn(x), 1e-300)) - math.log(target)   # noqa: E731
    if f(lo) < 0:
        return lo
    if f(hi) > 0:
        raise InputError(f"far_per_h gives a false-alarm probability per sample of {target:.3g}, "
                         f"too small to set a threshold for (the level would be above {hi:g}); "
                         f"use far_per_h >= {FAR_MIN_PER_H:g} [1/h]")
    return optimize.brentq(f, lo, hi, xtol=1e-10)


def far_range_per_h(dt_s: float) -> tuple[float, float]:
    """Range of false-alarm rates the thresholds can be set for at a sample period [1/h].

    Parameters
    ----------
    dt_s : float
        Sample period [s].

    Returns
    -------
    (float, float)
        :data:`FAR_MIN_PER_H` and :data:`FAR_MAX_PER_SAMPLE` of the samples
        in an hour (3600/dt).
    """
    return FAR_MIN_PER_H, FAR_MAX_PER_SAMPLE * 3600.0 / float(dt_s)


def design_parity(H: np.ndarray, noise: ArrayNoise, dt_s: float, gyros=None, *,
                  far_per_h: float = 0.01, bias_memory_s: float = ff.DEFAULT_BIAS_MEMORY_S,
                  drift_window_s: float = 600.0, variance_window_s: float = 40.0,
                  variance_tolerance=None) -> ParityDesign:
    """Parity, trackers, windows and thresholds for a set of active gyros.

    Parameters
    ----------
    H : ndarray, shape (N, 3)
        Sensitive axes of the whole array [-].
    noise : ArrayNoise
        ARW, RRW and their correlations (the whole array).
    dt_s : float
        Sample period [s].
    gyros : sequence of int, optional
        0-based active gyros (default all); at least 4.
    far_per_h : float
        Total false-alarm rate [1/h], a third per family.
    bias_memory_s, drift_window_s, variance_window_s : float
        Longest tracker time constant, drift window and variance block [s].
        Every window is also at most :data:`MAX_WINDOW_SAMPLES` samples.
    variance_tolerance : array_like, shape (N,), optional
        Per gyro (whole array), the factor κ ≥ 1 by which its white variance
        may change without a fault (:func:`noise_spread`); the variance test
        of a direction then fires only beyond the band its gyros' κ allow
        (``ParityDesign.var_band``). Default: 1 (levels known exactly).

    Returns
    -------
    ParityDesign
    """
    idx = tuple(range(H.shape[0])) if gyros is None else tuple(int(g) for g in gyros)
    Ha = H[list(idx)]
    R = noise.R(dt_s)[np.ix_(idx, idx)]
    Qb = noise.Qb(dt_s)[np.ix_(idx, idx)]
    V, P = parity_matrix(Ha, R)
    m = V.shape[0]
    if m == 0:
        raise InputError(f"{len(idx)} gyros leave no parity: fault detection needs at least 4")
    qp = P @ Qb @ P.T                                         # parity random walk (white = I)
    lam, U = np.linalg.eigh(0.5 * (qp + qp.T))
    V, P = U.T @ V, U.T @ P
    q = np.maximum(lam, (dt_s / float(bias_memory_s)) ** 2)
    K, S = ff.steady_gain(q)
    coef = P.copy()
    groups = _groups(coef)
    vd = coef / np.sqrt(S)[:, None]
    vn = np.linalg.norm(vd, axis=0)
    var_dir = vd / np.where(vn > 0, vn, 1.0)
    share = _white_share(P, R, var_dir, K, S)
    band = None
    if variance_tolerance is not None:
        kap = np.broadcast_to(np.asarray(variance_tolerance, dtype=float), (H.shape[0],))[list(idx)]
        if np.any(kap > 1.0):
            share_all = _white_shares(P, R, var_dir, K, S)
            hi = 1.0 + share_all @ (kap - 1.0)
            lo = np.maximum(1.0 - share_all @ (1.0 - 1.0 / kap), 1e-6)
            band = np.vstack([lo, hi])
    drift_n = min(drift_window_s / dt_s, MAX_WINDOW_SAMPLES)     # windows in samples, bounded
    var_n = min(variance_window_s / dt_s, MAX_WINDOW_SAMPLES)
    scales = {
        "step": _pow2_scales(1, max(1.0, min(4.0 / float(np.min(K)), drift_n))),
        "drift": _pow2_scales(max(2.0, min(2.0 / float(np.max(K)), drift_n)), max(2.0, drift_n)),
        "variance": _pow2_scales(VARIANCE_MIN_BLOCK, var_n),
    }
    G, _ = gls_weights(Ha, R)
    design = ParityDesign(gyros=idx, V=V, P=P, q=q, K=K, S=S, coef=coef, groups=groups,
                          var_dir=var_dir, white_share=share, scales=scales, thresholds={},
                          far_per_h={}, gls=G, var_band=band)
    _calibrate(design, far_per_h, dt_s)
    return design


def _white_share(P, R, d, K, S) -> np.ndarray:
    """Share of Var(dⱼᵀε) that gyro j's own white noise makes (as if uncorrelated).

    Gyro j's white noise enters p as σⱼ² cⱼcⱼᵀ; the tracker passes white
    noise to the innovation with weights [1, −K, −Ka, −Ka², ...], so the
    covariance it adds to ε is cⱼcⱼᵀ ∘ (1 + KᵢKₖ/(1 − aᵢaₖ))/√(SᵢSₖ) σⱼ².
    """
    a = 1.0 - K
    kern = (1.0 + np.outer(K, K) / (1.0 - np.outer(a, a))) / np.sqrt(np.outer(S, S))
    sig2 = np.diag(R)
    out = np.empty(P.shape[1])
    for j in range(P.shape[1]):
        v = d[:, j] * P[:, j]
        out[j] = sig2[j] * float(np.sum(np.outer(v, v) * kern))
    return out


def _white_shares(P, R, d, K, S) -> np.ndarray:
    """Share of Var(dⱼᵀε) that gyro k's own white noise makes (as if uncorrelated): (n_a, n_a).

    Gyro k's white noise enters p as σₖ² cₖcₖᵀ; the tracker passes white
    noise to the innovation with weights [1, −K, −Ka, −Ka², ...], so the
    covariance it adds to ε is cₖcₖᵀ ∘ (1 + KᵢKₗ/(1 − aᵢaₗ))/√(SᵢSₗ) σₖ²;
    row j is that seen along dⱼ (the diagonal: a gyro's own share).
    """
    a = 1.0 - K
    kern = (1.0 + np.outer(K, K) / (1.0 - np.outer(a, a))) / np.sqrt(np.outer(S, S))
    sig2 = np.diag(R)
    v = d.T[:, None, :] * P.T[None, :, :]                     # (j, k, m): dⱼ ∘ cₖ
    return sig2[None, :] * np.einsum("jki,il,jkl->jk", v, kern, v)


def band_ratio(lam: np.ndarray, band: np.ndarray | None) -> np.ndarray:
    """A variance ratio relative to the no-fault band, one-sided: λ/hi above its top, 1 below.

    Parameters
    ----------
    lam : ndarray, shape (..., G)
        Block variance ratios along G directions [-].
    band : ndarray, shape (2, G) or None
        Lowest and highest ratio that is no fault (None: the point 1). Only
        the top counts: a noise fault is an increase (module docstring).

    Returns
    -------
    ndarray
        The ratio the one-sided χ² GLR is evaluated at, >= 1 (composite
        null: every level up to the top of the band).
    """
    hi = 1.0 if band is None else band[1]
    return np.maximum(lam / hi, 1.0)


def variance_glr(lam: np.ndarray, band: np.ndarray | None, L: int) -> np.ndarray:
    """One-sided χ²_L GLR of blocks of L samples: L/2·(λ_b − 1 − ln λ_b), λ_b = :func:`band_ratio`.

    Parameters
    ----------
    lam : ndarray, shape (..., G)
        Block variance ratios (mean of L squared unit-variance innovations) [-].
    band : ndarray, shape (2, G) or None
        No-fault band (:attr:`ParityDesign.var_band`).
    L : int
        Block length [samples].

    Returns
    -------
    ndarray
        The statistic, 0 for a block at or below the band's top.
    """
    lb = band_ratio(np.maximum(lam, 1e-300), band)
    return 0.5 * L * (lb - 1.0 - np.log(lb))


def _calibrate(design: ParityDesign, far_per_h: float, dt_s: float) -> None:
    """Thresholds of the three families, each at far_per_h/3 (module docstring, step 4)."""
    target = far_per_h / 3.0 * dt_s / 3600.0                 # per sample, per family
    a, K, S = design.a, design.K, design.S
    reps = [g[0] for g in design.groups if np.linalg.norm(design.coef[:, g[0]]) > 0]
    thresholds, far, energies = {}, {}, {}
    for fam in ("step", "drift"):
        rough, smooth = [], []
        for j in reps:
            for L in design.scales[fam]:
                h = window_weights(fam, a, K, S, design.coef[:, j], L)
                E, mr, ms = _window_roughness(h)
                energies[(fam, j, L)] = E
                rough.append(mr)
                smooth.append(ms)
        rough_a, smooth_a = np.array(rough), np.array(smooth)
        rate = lambda u: float(np.sum(ff.clump_rate(u, rough_a, smooth_a)))   # noqa: E731
        u = _solve_level(rate, target)
        thresholds[fam] = u
        far[fam] = rate(u) * 3600.0 / dt_s
    n_dir = len(reps)
    Ls = design.scales["variance"]
    # one-sided: only an increase alarms (P(χ²_L/L > λ_hi(g)) per block of L samples)
    vrate = lambda g: n_dir * sum(ff.chi2_glr_pvalue(g, L, "up") / L for L in Ls)   # noqa: E731
    g = _solve_level(vrate, target, lo=1.0, hi=400.0)
    thresholds["variance"] = g
    far["variance"] = vrate(g) * 3600.0 / dt_s
    for j in range(design.coef.shape[1]):                     # every gyro's own energies
        for fam in ("step", "drift"):
            for L in design.scales[fam]:
                if (fam, j, L) not in energies:
                    h = window_weights(fam, a, K, S, design.coef[:, j], L)
                    energies[(fam, j, L)] = float(np.sum(h * h))
    object.__setattr__(design, "thresholds", thresholds)
    object.__setattr__(design, "far_per_h", far)
    object.__setattr__(design, "energies", energies)


# -- results -----------------------------------------------------------------

@dataclass(frozen=True)
class Alarm:
    """One detected fault.

    Attributes
    ----------
    gyro : int or None
        1-based faulty gyro; None when it cannot be isolated.
    kind : str
        ``step``, ``drift``, ``stuck`` or ``noise``.
    onset_s, onset_sigma_s : float
        Fitted fault start [s] and its 1σ (profile likelihood).
    detected_s : float
        Time of the alarm (first statistic over its threshold) [s].
    isolated_s : float or None
        When the isolation was decided (and the gyro excluded) [s].
    size, size_sigma : float
        Step [deg/s], drift rate [deg/s²], stuck value [deg/s] or noise
        amplitude ratio [-] (``size_unit``), with 1σ.
    size_unit : str
    isolated : bool
    candidates : tuple of int
        1-based gyros that explain the fault equally well (not isolable).
    evidence : str
        One line: the test that fired and why this gyro and kind.
    family : str
        Test family that fired (``step``, ``drift``, ``variance``).
    window_s : float
        Its window [s].
    statistic, threshold : float
        Value and threshold of the statistic that fired.
    """

    gyro: int | None
    kind: str
    onset_s: float
    onset_sigma_s: float
    detected_s: float
    isolated_s: float | None
    size: float
    size_sigma: float
    size_unit: str
    isolated: bool
    candidates: tuple
    evidence: str
    family: str
    window_s: float
    statistic: float
    threshold: float

    def to_json_dict(self) -> dict:
        """The issue's alarm object."""
        return {"gyro": self.gyro, "kind": self.kind, "onset_s": self.onset_s,
                "detected_s": self.detected_s, "size": self.size, "size_unit": self.size_unit,
                "isolated": self.isolated, "evidence": self.evidence}


@dataclass(frozen=True)
class FdiResult:
    """What :meth:`FaultDetector.detect` found on a record.

    Attributes
    ----------
    alarms : tuple of Alarm
    exclusions : tuple of (int, int)
        (sample index from which, 0-based gyro) excluded by the recovery.
    time_s : ndarray, shape (n,)
    trace : dict
        For plots: per family the largest |statistic|/threshold at each
        sample of the first scan (``ratio``), and the first scan's end.
    notes : tuple of str
    """

    alarms: tuple
    exclusions: tuple
    time_s: np.ndarray
    trace: dict = field(default_factory=dict)
    notes: tuple = ()


# -- the detector --------------------------------------------------------------

#: Samples within this many of a clipped output are left out as well (the outputs' filters
#: smear the clip over a few samples) [samples].
SATURATION_GUARD = 2
#: A gyro clips when at least this many samples repeat its largest |output| exactly [-].
MIN_CLIP_RUN = 3
#: Factor on the innovations of a stretch watched by the flat-line test only (no parity statistic
#: can reach its threshold) [-].
FLAT_ONLY_SCALE = 1e9


def saturated_mask(y: np.ndarray, *, guard: int = SATURATION_GUARD) -> tuple[np.ndarray, np.ndarray]:
    """Samples at which some gyro reads its output limit.

    A gyro clips when at least :data:`MIN_CLIP_RUN` samples repeat its largest
    |output| exactly (a quantised noise value does not repeat at the extreme
    of a record that turns).

    Parameters
    ----------
    y : ndarray, shape (n, N)
        Outputs [rad/s].
    guard : int
        Samples also marked on each side of a clipped one.

    Returns
    -------
    mask : ndarray of bool, shape (n,)
        True where any gyro is at (or within ``guard`` samples of) its limit.
    clip_rad_s : ndarray, shape (N,)
        Each gyro's limit [rad/s]; NaN for a gyro that does not clip.
    """
    y = np.asarray(y, dtype=float)
    a = np.abs(y)
    top = a.max(axis=0) if y.shape[0] else np.zeros(y.shape[1])
    at = (a >= top[None, :]) & (top[None, :] > 0)
    clips = at.sum(axis=0) >= MIN_CLIP_RUN
    clip = np.where(clips, top, np.nan)
    mask = (at & clips[None, :]).any(axis=1)
    if guard > 0 and mask.any():
        idx = np.flatnonzero(mask)
        grown = np.zeros_like(mask)
        for d in range(-guard, guard + 1):
            j = idx + d
            grown[j[(j >= 0) & (j < mask.size)]] = True
        mask = grown
    return mask, clip




#: Moving over still variance of the whitened parity's first differences above which the parity
#: is said to follow the motion (a calibration's business, not a fault's) [-].
MOTION_PARITY_RATIO = 2.0


def motion_follows_parity(z: np.ndarray, P: np.ndarray, still: np.ndarray, sat: np.ndarray) -> bool:
    """Does the parity of the moving, unclipped samples spread more than :data:`MOTION_PARITY_RATIO`
    times the still samples' (first differences of ``z @ Pᵀ``, the whitened parity, so the
    biases and their walk drop out)? On the MIMU4444 board x25-90; on a simulated array ~1."""
    p = np.asarray(z, float) @ np.asarray(P, float).T
    d = np.diff(p, axis=0) ** 2
    keep_s = still[1:] & still[:-1]
    keep_m = ~still[1:] & ~still[:-1] & ~sat[1:] & ~sat[:-1]
    if keep_s.sum() < 2 or keep_m.sum() < 2:
        return False
    return float(d[keep_m].mean()) > MOTION_PARITY_RATIO * float(d[keep_s].mean())


def common_scale(z: np.ndarray, R: np.ndarray) -> float:
    """√max(1, median over the gyros of a stretch's variance over R's diagonal) [-]: a level that
    rises on every gyro at once is the environment, not one gyro's noise fault."""
    v = np.var(z, axis=0, ddof=1) / np.diag(R)
    return math.sqrt(max(1.0, float(np.median(v))))


def clips_broken(raw: np.ndarray, z: np.ndarray, watched: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """``z`` with the samples ``watched`` by the flat line only taken from the raw outputs, each
    gyro's repeats at its own output limit broken (every other one moved by an ulp): a clipped
    gyro repeats its limit, it is not stuck."""
    n = raw.shape[0]
    at = np.abs(raw) >= np.nan_to_num(clip, nan=np.inf)[None, :]
    odd = (np.arange(n) % 2 == 1)[:, None]
    zr = np.where(at & odd, np.nextafter(raw, np.inf), raw)
    return np.where(watched[:, None], zr, z)


@register("fdi")
class FaultDetector(Estimator):
    """Parity-space fault detection, isolation and recovery (module docstring).

    Parameters
    ----------
    far_per_h : float
        False-alarm rate the thresholds are set for [1/h] (default 0.01).
    isolation_odds : float
        Likelihood ratio the named gyro must reach against every other
        parity direction [-] (default 99).
    isolation_s : float
        Longest wait after an alarm for the isolation [s] (default 120; at
        least the window of the test that fired). It stops as soon as the
        odds are reached: a step isolates within a second, a drift near its
        minimum detectable rate may need a minute.
    bias_memory_s : float
        Longest bias-tracker time constant [s] (default 600).
    drift_window_s : float
        Longest drift window [s] (default 600).
    variance_window_s : float
        Longest variance block [s] (default 40).
    variance_tolerance : array_like, shape (N,), optional
        Per gyro, the factor κ ≥ 1 its white variance may change by without a
        fault (:func:`noise_spread`; default None: the levels are known).

    Attributes
    ----------
    design_ : ParityDesign
        Parity, trackers, windows and thresholds of the whole array.
    parity_ : ndarray, shape (N − 3, N)
        P: P H = 0, P R Pᵀ = I [1/(rad/s)].
    V_ : ndarray, shape (N − 3, N)
        V W H = 0, V Vᵀ = I [-].
    thresholds_ : dict
        ``step``/``drift``: u on |Y|; ``variance``: GLR level.
    far_design_per_h_ : dict
        Analytic false-alarm rate per family [1/h].
    isolable_ : bool
        Every gyro has its own parity direction.
    weights_ : ndarray, shape (3, N)
        GLS weights with every gyro.
    covariance_ : ndarray, shape (3, 3)
        (HᵀR⁻¹H)⁻¹ [rad²/s²] (no fault).
    """

    description = "parity-space fault detection, isolation and recovery (GLS without the faulty gyro)"

    def __init__(self, *, far_per_h=0.01, isolation_odds=99.0, isolation_s=120.0,
                 bias_memory_s=ff.DEFAULT_BIAS_MEMORY_S, drift_window_s=600.0,
                 variance_window_s=40.0, variance_tolerance=None):
        self.far_per_h = far_per_h
        self.variance_tolerance = variance_tolerance
        self.isolation_odds = isolation_odds
        self.isolation_s = isolation_s
        self.bias_memory_s = bias_memory_s
        self.drift_window_s = drift_window_s
        self.variance_window_s = variance_window_s

    # -- fit ---------------------------------------------------------------
    def _hyper(self) -> dict:
        out = {}
        for name in ("far_per_h", "isolation_odds", "isolation_s", "bias_memory_s",
                     "drift_window_s", "variance_window_s"):
            v = getattr(self, name)
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise InputError(f"{name} must be a number, got {v!r}") from None
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be finite and > 0, got {v!r}")
            out[name] = v
        if out["isolation_odds"] <= 1.0:
            raise InputError(f"isolation_odds must be > 1, got {out['isolation_odds']!r}")
        return out

    def _fit(self, H, noise, dt_s):
        hp = self._hyper()
        lo, hi = far_range_per_h(dt_s)
        if not lo <= hp["far_per_h"] <= hi:
            raise InputError(f"far_per_h must be between {lo:g} and {hi:g} [1/h] at a "
                             f"{1.0 / dt_s:g} Hz sample rate (at most one false alarm per "
                             f"{1.0 / FAR_MAX_PER_SAMPLE:g} samples), got {hp['far_per_h']!r}")
        if H.shape[0] < 4:
            raise InputError(f"fault detection needs at least 4 gyros (N − 3 parity checks), "
                             f"the layout has {H.shape[0]}")
        self._cache = {}
        design = self._design(H, noise, dt_s, tuple(range(H.shape[0])), hp)
        G, cov = gls_weights(H, noise.R(dt_s))
        self.design_ = design
        self.parity_ = readonly(design.P)
        self.V_ = readonly(design.V)
        self.thresholds_ = dict(design.thresholds)
        self.far_design_per_h_ = dict(design.far_per_h)
        self.isolable_ = all(len(g) == 1 for g in design.groups) and design.m >= 2
        self.weights_ = readonly(G)
        self.covariance_ = readonly(cov)

    def _tolerance(self, n: int):
        kap = getattr(self, "variance_tolerance", None)
        if kap is None:
            return None
        try:
            kap = np.broadcast_to(np.asarray(kap, dtype=float), (n,))
        except ValueError:
            raise InputError(f"variance_tolerance must be one number or one per gyro ({n}), got "
                             f"{getattr(self, 'variance_tolerance')!r}") from None
        if not np.all(np.isfinite(kap) & (kap >= 1.0)):
            raise InputError("variance_tolerance must be finite and >= 1 (a factor on the variance)")
        return kap

    def _design(self, H, noise, dt_s, gyros, hp=None) -> ParityDesign:
        hp = hp or self._hyper()
        key = tuple(gyros)
        cache = self.__dict__.setdefault("_cache", {})
        if key not in cache:
            cache[key] = design_parity(H, noise, dt_s, gyros, far_per_h=hp["far_per_h"],
                                       bias_memory_s=hp["bias_memory_s"],
                                       drift_window_s=hp["drift_window_s"],
                                       variance_window_s=hp["variance_window_s"],
                                       variance_tolerance=self._tolerance(H.shape[0]))
        return cache[key]

    # -- estimate (fault-tolerant GLS) ------------------------------------------
    def _estimate(self, z):
        return fuse(z, self.H_, self.noise_, self.dt_s_, self.detect_record(z).exclusions)

    def detect_record(self, readings_rad_s, time_s=None) -> FdiResult:
        """:meth:`detect` as ``gyroarray fdi`` runs it on a record, with this fit's noise as a model.

        The noise the detector was fitted with is read as a model (its ARW a
        long-τ white level, as a fusion chain fits it): on a record with still
        parts each gyro's per-sample level, its RRW where larger, and the
        wander of its level between still parts are read there
        (:func:`per_sample_noise`, :func:`noise_spread`), a detector with
        those levels tests the still parts each on its own, and the motion
        is watched for a stuck gyro only (:func:`clips_broken`). A
        record without still parts (or none found) is :meth:`detect`-ed as
        it is. :meth:`estimate` fuses (GLS with this fit's weights) without
        the gyros this excludes.

        Parameters
        ----------
        readings_rad_s : array_like, shape (n, N)
            Gyro outputs [rad/s].
        time_s : array_like, shape (n,), optional
            Sample times [s] (default k·dt).

        Returns
        -------
        FdiResult
        """
        self._check_fitted()
        z = check_readings(readings_rad_s, self.n_gyros_)
        dt = self.dt_s_
        try:
            still = still_mask(z, self.H_, dt)
        except InputError:                                     # too short to tell: as it is
            still = None
        if still is None or not still.any() or z.shape[0] < MIN_RECORD_SAMPLES:
            return self.detect(z, time_s)
        noise, _ = per_sample_noise(self.noise_, z, dt, still)
        if noise is self.noise_:
            return self.detect(z, time_s)
        kap, _ = noise_spread(z, dt, still, reference=np.asarray(noise.arw_rad_rt_s) ** 2 / dt)
        det = FaultDetector(**{**self.get_params(), "variance_tolerance":
                               kap if np.any(kap > 1.0) else None}).fit(Layout(self.H_), noise, dt)
        # the still parts each on its own (widened by their common level), the motion watched for
        # a stuck gyro only; gyroarray fdi (chain.fdi_score.test_record) also takes the parity
        # self-calibration out of the motion, which a fusion estimator does not need for that
        n = z.shape[0]
        if still.all():
            return det.detect(z, time_s)
        t = np.arange(n) * dt if time_s is None else np.asarray(time_s, dtype=float)
        R = det.noise_.R(dt)
        sat, clip = saturated_mask(z)
        scale = np.ones(n)
        for a, b in true_runs(still):
            scale[a:b] = common_scale(z[a:b], R) if b - a >= MIN_RECORD_SAMPLES else 1.0
        watched = np.zeros(n, dtype=bool)
        if motion_follows_parity(z, det.design_.P, still, sat):
            # the parity follows the rate (a real board's scale-factor and axis errors): the motion
            # is watched for a stuck gyro only
            parts: list[tuple] = [(a, b, scale[a:b]) for a, b in true_runs(still) if b - a >= MIN_RECORD_SAMPLES]
            for a, b in true_runs(~still):
                if b - a >= MIN_RECORD_SAMPLES:
                    parts.append((a, b, FLAT_ONLY_SCALE))
                    watched[a:b] = True
        else:                                   # tested through the motion, around clipped samples
            parts = [(a, b, scale[a:b]) for a, b in true_runs(~sat) if b - a >= MIN_RECORD_SAMPLES]
        parts.sort(key=lambda x: x[0])
        return det.detect_parts(clips_broken(z, z, watched, clip), parts, t)

    def false_alarms(self, readings_rad_s) -> dict:
        """Every alarm a clean record raises, without isolation or exclusion.

        Parameters
        ----------
        readings_rad_s : array_like, shape (n, N)
            Gyro outputs [rad/s] of a record without fault.

        Returns
        -------
        dict
            :func:`alarm_events` (``samples``, ``family``, ``per_family``) and
            ``hours`` (record length [h]).
        """
        self._check_fitted()
        z = check_readings(readings_rad_s, self.n_gyros_)
        eps = ff.rw_innovations(z @ self.design_.P.T, self.design_.q)
        out = alarm_events(eps, self.design_)
        out["hours"] = z.shape[0] * self.dt_s_ / 3600.0
        return out

    # -- detect ------------------------------------------------------------------
    def detect(self, readings_rad_s, time_s=None, *, trace: bool = False,
               innovation_scale=None, exclude=()) -> FdiResult:
        """Find, isolate and exclude faulty gyros in a record.

        Parameters
        ----------
        readings_rad_s : array_like, shape (n, N)
            Gyro outputs [rad/s].
        time_s : array_like, shape (n,), optional
            Sample times [s] (default k·dt).
        trace : bool
            Keep the statistics of the first scan for a plot.
        innovation_scale : array_like, shape (n,), optional
            Known excess spread (>= 1) of the parity at each sample, e.g. the
            part of a moving array's parity that follows the motion beyond its
            fitted scale-factor and axis errors
            (:meth:`gyroarray.chain.parity.ParityCalibration.excess_scale`): the
            innovations are divided by it, so the tests keep their false-alarm
            rate where the array disagrees with itself for a known reason, at
            the cost of sensitivity there. Default: 1.
        exclude : sequence of int
            0-based gyros left out from the start (already excluded).

        Returns
        -------
        FdiResult
        """
        self._check_fitted()
        z = check_readings(readings_rad_s, self.n_gyros_)
        n = z.shape[0]
        t = np.arange(n) * self.dt_s_ if time_s is None else np.asarray(time_s, dtype=float)
        if t.shape != (n,):
            raise InputError(f"time_s has shape {t.shape}, the readings {n} samples")
        hp = self._hyper()
        scale = None
        if innovation_scale is not None:
            scale = np.asarray(innovation_scale, dtype=float)
            if scale.shape != (n,) or not np.all(np.isfinite(scale) & (scale >= 1.0)):
                raise InputError(f"innovation_scale must be {n} finite numbers >= 1, got shape "
                                 f"{scale.shape}")
        active = [g for g in range(self.n_gyros_) if g not in {int(e) for e in exclude}]
        k0, tr = 0, {}
        alarms: list[Alarm] = []
        excl: list[tuple[int, int]] = []
        notes: list[str] = []
        while n - k0 >= 3 and len(active) >= 4:
            design = self._design(self.H_, self.noise_, self.dt_s_, tuple(active), hp)
            eps = ff.rw_innovations(z[k0:, active] @ design.P.T, design.q)
            if scale is not None:
                eps = eps / scale[k0:, None]
            hit = _scan(eps, design, trace=trace and not alarms, flat=flat_alarm(z[k0:, active]))
            if trace and not alarms:
                tr = {"ratio": hit.pop("trace"), "start": k0}
            if hit["k"] is None:
                break
            alarm, k_iso, gyro = _characterize(z, t, k0, eps, design, hit, hp, self.dt_s_)
            alarms.append(alarm)
            if gyro is None:
                notes.append(f"alarm at {alarm.detected_s:.2f} s not isolated: detection stops "
                             "there (the faulty gyro cannot be excluded)")
                break
            excl.append((k_iso, gyro))
            active.remove(gyro)
            k0 = k_iso
            if len(active) < 4:
                notes.append(f"{len(active)} gyros left after excluding gyro {gyro + 1}: no "
                             "parity to watch any more")
                break
        return FdiResult(alarms=tuple(alarms), exclusions=tuple(excl), time_s=t, trace=tr,
                         notes=tuple(notes))


    def detect_parts(self, readings_rad_s, parts, time_s=None, *, trace: bool = False) -> FdiResult:
        """:meth:`detect` on stretches of a record only (e.g. its still parts), in order.

        A gyro excluded in one stretch stays excluded in the next; each stretch
        starts its bias trackers afresh. Samples outside the stretches are not
        tested (their trace is 0).

        Parameters
        ----------
        readings_rad_s : array_like, shape (n, N)
        parts : sequence of (int, int) or (int, int, scale)
            [start, stop) sample ranges, increasing, each of at least
            :data:`MIN_RECORD_SAMPLES` samples (shorter ones are skipped);
            ``scale`` (a number or b − a numbers >= 1) is the stretch's
            ``innovation_scale`` (:meth:`detect`).
        time_s : array_like, shape (n,), optional
        trace : bool

        Returns
        -------
        FdiResult
            Alarms and exclusions (sample indices of the whole record) of all stretches.
        """
        self._check_fitted()
        z = check_readings(readings_rad_s, self.n_gyros_)
        n = z.shape[0]
        t = np.arange(n) * self.dt_s_ if time_s is None else np.asarray(time_s, dtype=float)
        alarms, excl, notes = [], [], []
        ratio = {f: np.zeros(n) for f in _FAMILIES} if trace else None
        out_of: set[int] = set()
        for part in parts:
            a, b = int(part[0]), int(part[1])
            if b - a < MIN_RECORD_SAMPLES or self.n_gyros_ - len(out_of) < 4:
                continue
            sc = None
            if len(part) > 2 and part[2] is not None:
                sc = np.broadcast_to(np.asarray(part[2], dtype=float), (b - a,))
                sc = None if np.all(sc == 1.0) else sc
            r = self.detect(z[a:b], t[a:b], trace=trace, exclude=sorted(out_of),
                            innovation_scale=sc)
            alarms += list(r.alarms)
            excl += [(k + a, g) for k, g in r.exclusions]
            out_of.update(g for _, g in r.exclusions)
            notes += list(r.notes)
            if trace and r.trace:
                assert ratio is not None                       # set whenever trace is
                s0 = a + int(r.trace["start"])
                for f in _FAMILIES:
                    v = r.trace["ratio"][f]
                    ratio[f][s0:s0 + v.size] = v
        tr = {"ratio": ratio, "start": 0} if trace else {}
        return FdiResult(alarms=tuple(alarms), exclusions=tuple(excl), time_s=t, trace=tr,
                         notes=tuple(notes))


# -- scan: the three families -----------------------------------------------------

def _window_stats(fam: str, wn, cs, design, reps, L, stop: int) -> np.ndarray:
    """Y_{j,L}(k) of the gyros ``reps`` for k = L−1 .. stop−1 (onset k − L + 1): (rows, G).

    ``wn`` is the reverse AR(1) sum w of ε with a zero row appended (w_n = 0),
    ``cs`` the cumulative sum of ε with a zero row prepended (C_{−1} = 0).
    Σ_{n<L} aⁿ ε_{θ+n} = w_θ − a^L w_{θ+L}; Σ_{n<L} ε_{θ+n} = C_{θ+L−1} − C_{θ−1}.
    """
    rows = max(stop - L + 1, 0)
    a, K, S = design.a, design.K, design.S
    s_step = wn[:rows] - (a ** L)[None, :] * wn[L:L + rows]
    if fam == "step":
        per = s_step / np.sqrt(S)[None, :]
    else:
        per = (cs[L:L + rows] - cs[:rows] - s_step) / (K * np.sqrt(S))[None, :]
    E = np.array([design.energies[(fam, j, L)] for j in reps])
    return per @ (design.coef[:, reps] / np.sqrt(E)[None, :])


def _scan(eps: np.ndarray, design: ParityDesign, *, trace: bool = False, flat=None) -> dict:
    """First sample where a statistic crosses its threshold, and which one.

    ``flat`` is :func:`flat_alarm` of the same stretch (a stuck gyro's flat line).
    """
    n = eps.shape[0]
    best: dict[str, Any] = {"k": None}
    k_first = n                                                # earliest crossing so far
    if flat is not None and 1 <= flat[0] < n:
        k_first = flat[0]
        best = {"k": flat[0], "family": "flat", "rep": flat[1], "L": flat[2],
                "value": float(flat[2]), "threshold": float(flat[2])}
    ratio = {f: np.zeros(n) for f in _FAMILIES} if trace else {}
    if n < 2:
        return {**best, "trace": ratio} if trace else best
    w = ff.reverse_ar1(eps, design.a)
    wn = np.vstack([w, np.zeros((1, w.shape[1]))])
    cs = np.vstack([np.zeros((1, eps.shape[1])), np.cumsum(eps, axis=0)])
    reps = [g[0] for g in design.groups if np.linalg.norm(design.coef[:, g[0]]) > 0]
    for fam in ("step", "drift"):
        u = design.thresholds[fam]
        for L in design.scales[fam]:
            stop = n if trace else k_first
            if L > stop - 1:
                break
            Y = np.abs(_window_stats(fam, wn, cs, design, reps, L, stop))
            if trace:
                np.maximum(ratio[fam][L - 1:], Y.max(axis=1) / u, out=ratio[fam][L - 1:])
            rows = np.flatnonzero((Y > u).any(axis=1))
            rows = rows[(rows + L - 1 >= 1) & (rows + L - 1 < k_first)]   # not on ε₀ alone
            if rows.size:
                i = int(rows[0])
                gi = int(np.argmax(Y[i]))
                k_first = i + L - 1
                best = {"k": k_first, "family": fam, "rep": reps[gi], "L": L,
                        "value": float(Y[i, gi]), "threshold": u}
    g = design.thresholds["variance"]
    x = eps[:, :] @ design.var_dir[:, reps]
    for L in design.scales["variance"]:
        nb = (n - 1) // L
        if nb < 1:
            break
        blocks = (x[1:1 + nb * L] ** 2).reshape(nb, L, -1).sum(axis=1)   # skip ε₀
        lam = np.maximum(blocks / L, 1e-300)
        G = variance_glr(lam, None if design.var_band is None else design.var_band[:, reps], L)
        if trace:                                              # known at each block's end
            r = np.repeat(G.max(axis=1) / g, L)[:max(n - L, 0)]
            np.maximum(ratio["variance"][L:L + r.size], r, out=ratio["variance"][L:L + r.size])
        over = np.flatnonzero((G > g).any(axis=1))
        if over.size:
            b = int(over[0])
            k = (b + 1) * L                                    # the block's last sample
            if k < k_first:
                gi = int(np.argmax(G[b]))
                k_first = k
                best = {"k": k, "family": "variance", "rep": reps[gi], "L": L,
                        "value": float(G[b, gi]), "threshold": g, "lam": float(lam[b, gi])}
    if trace:
        best["trace"] = ratio
    return best


def alarm_events(eps: np.ndarray, design: ParityDesign) -> dict:
    """Every excursion of every statistic over its threshold (no isolation, no exclusion).

    An excursion of one statistic (family, window L, any direction) starts
    where it exceeds after more than L samples under and ends at its last
    exceedance; overlapping excursions of different statistics are one
    alarm. Used to count false alarms on clean records.

    Returns
    -------
    dict
        ``samples``: start sample of each alarm; ``family``: the family that
        fired first; ``per_family``: the count of each family's own excursions.
    """
    n = eps.shape[0]
    w = ff.reverse_ar1(eps, design.a)
    wn = np.vstack([w, np.zeros((1, w.shape[1]))])
    cs = np.vstack([np.zeros((1, eps.shape[1])), np.cumsum(eps, axis=0)])
    reps = [g[0] for g in design.groups if np.linalg.norm(design.coef[:, g[0]]) > 0]
    spans = []                                                # (start, end, family)
    for fam in ("step", "drift"):
        u = design.thresholds[fam]
        for L in design.scales[fam]:
            if L > n - 1:
                break
            over = (np.abs(_window_stats(fam, wn, cs, design, reps, L, n)) > u).any(axis=1)
            ks = np.flatnonzero(over) + L - 1
            spans += [(a, b, fam) for a, b in _clumps(ks[ks >= 1], L)]
    g = design.thresholds["variance"]
    x = eps @ design.var_dir[:, reps]
    for L in design.scales["variance"]:
        nb = (n - 1) // L
        if nb < 1:
            break
        lam = (x[1:1 + nb * L] ** 2).reshape(nb, L, -1).sum(axis=1) / L
        over = (variance_glr(lam, None if design.var_band is None else design.var_band[:, reps], L)
                > g).any(axis=1)
        spans += [(a, b, "variance") for a, b in _clumps((np.flatnonzero(over) + 1) * L, L)]
    per = {f: sum(1 for s in spans if s[2] == f) for f in _FAMILIES}
    spans.sort()
    merged, end = [], -1
    for a, b, fam in spans:
        if a > end:
            merged.append((a, fam))
        end = max(end, b)
    return {"samples": np.array([k for k, _ in merged], dtype=np.int64),
            "family": [f for _, f in merged], "per_family": per}


def _clumps(ks: np.ndarray, gap: int) -> list:
    """(first, last) exceedance of each run of exceedances no more than ``gap`` apart."""
    if ks.size == 0:
        return []
    cut = np.flatnonzero(np.diff(ks) > gap)
    first = np.concatenate([[0], cut + 1])
    last = np.concatenate([cut, [ks.size - 1]])
    return [(int(ks[i]), int(ks[j])) for i, j in zip(first, last)]


# -- characterisation: kind, onset, size, isolation ----------------------------------

def _characterize(z, t, k0, eps, design: ParityDesign, hit: dict, hp: dict, dt: float):
    """Fit every gyro × kind around the alarm; isolate; return (Alarm, k_iso, gyro or None)."""
    n = eps.shape[0]
    k = hit["k"]                                               # relative to k0
    L = hit["L"]
    lo = max(1, k - 2 * L - int(round(2.0 / dt)))              # earliest onset considered
    log_odds = math.log(hp["isolation_odds"])
    wait_s = max(hp["isolation_s"], L * dt)                   # a slow test's fault isolates slowly
    horizons = [0.0] + [2.0 ** i for i in range(0, 64) if 2.0 ** i < wait_s] + [wait_s]
    horizon = int(round(wait_s / dt))                          # data the final fit may use
    fits: dict[str, Any] = {}
    for h_s in horizons:
        E = min(n - 1, k + int(round(h_s / dt)))
        fits = _fit_segment(eps, design, lo, k, E)
        stuck = _stuck_candidates(z, k0, design, lo + k0, k + k0, E + k0)
        order = sorted(range(len(design.groups)), key=lambda gi: -fits["best_dll"][gi])
        g1 = order[0]
        margin = (fits["best_dll"][g1] - fits["best_dll"][order[1]]) if len(order) > 1 else 0.0
        if len(stuck) == 1:
            return _alarm_stuck(z, t, k0, design, hit, stuck[0], fits, E, dt)
        if len(design.groups[g1]) == 1 and len(order) > 1 and margin >= log_odds:
            final = _fit_segment(eps, design, lo, k, min(n - 1, max(E, k + horizon)))
            return _alarm_fit(z, t, k0, design, hit, final, g1, E, True, margin, dt,
                              hp["isolation_odds"])
        if E >= n - 1:
            break
    order = sorted(range(len(design.groups)), key=lambda gi: -fits["best_dll"][gi])
    margin = (fits["best_dll"][order[0]] - fits["best_dll"][order[1]]) if len(order) > 1 else 0.0
    return _alarm_fit(z, t, k0, design, hit, fits, order[0], None, False, margin, dt,
                      hp["isolation_odds"])


def _fit_segment(eps, design: ParityDesign, lo: int, k: int, E: int) -> dict:
    """Profiles of step, drift and variance for every gyro, onset in [lo, k], fault to E."""
    seg = eps[lo:E + 1]
    onsets = np.arange(0, k - lo + 1)
    out: dict[str, Any] = {"lo": lo}
    for kind in ("step", "drift"):
        num, den, _, _ = ff.profile_means(seg, design.a, design.K, design.S, design.coef, kind,
                                          onsets)
        out[kind] = (num, den, num * num / (2.0 * den))
    x = seg @ design.var_dir
    var_on = onsets[onsets <= max(seg.shape[0] - 8, 0)]
    if var_on.size == 0:
        var_on = onsets[:1]
    _, lam, count = ff.profile_variance(x, var_on)
    # one-sided, against the top of the no-fault band (as the variance family): a level at or
    # below it explains nothing
    top = np.ones(x.shape[1]) if design.var_band is None else design.var_band[1]
    lb = np.maximum(lam / top[None, :], 1.0)
    dll = 0.5 * count[:, None] * (lb - 1.0 - np.log(lb))
    out["noise"] = (lam, count, dll, var_on)
    best = []
    for grp in design.groups:
        j = grp[0]
        best.append(max(float(out["step"][2][:, j].max()), float(out["drift"][2][:, j].max()),
                        float(dll[:, j].max())))
    out["best_dll"] = best
    return out


def flat_alarm(z: np.ndarray) -> tuple[int, int, int] | None:
    """The first sample at which a gyro's run of identical outputs becomes implausible.

    Parameters
    ----------
    z : ndarray, shape (n, G)
        Outputs of the active gyros from the stretch's start [rad/s].

    Returns
    -------
    (k, column, run) or None
        Sample k (into ``z``) at which column's run of repeats reaches ``run``
        samples, the shortest its repeat share before the run makes as rare as
        :data:`STUCK_RUN_P`; None when no run does.

    Notes
    -----
    A run starting at sample s, after b = max(s, 1) samples of which r
    repeat their predecessor, has p₀ = (r + 1)/(b + 1) (a repeat share with
    one pseudo-count each way); under independent repeats a run of R
    samples has probability p₀^(R − 1), so it is a stuck gyro from R =
    1 + ⌈ln :data:`STUCK_RUN_P` / ln p₀⌉ on. The same rule isolates a stuck
    gyro (:func:`_stuck_candidates`), so the alarm and its isolation agree.
    Continuous (simulated) outputs never repeat: a run of 3 samples is
    stuck after a few hundred; a quantised real gyro (MPU-9150, 0.061 deg/s
    steps, 4–18 % repeats at rest) needs 9–14.
    """
    best: tuple[int, int, int] | None = None
    log_p = math.log(STUCK_RUN_P)
    for c in range(z.shape[1]):
        col = z[:, c]
        same = np.r_[False, col[1:] == col[:-1]]              # sample i repeats sample i − 1
        if not same.any():
            continue
        cum = np.cumsum(same)
        d = np.diff(np.r_[0, same.astype(np.int8), 0])
        first = np.flatnonzero(d == 1)                        # first repeated sample of each run
        stop = np.flatnonzero(d == -1)                        # one past its last
        s = first - 1                                         # the run's first sample
        b = np.maximum(s, 1)
        r = cum[b - 1]                                        # repeats among samples 0 .. b − 1
        p0 = (r + 1.0) / (b + 1.0)
        with np.errstate(divide="ignore"):
            need = np.where(p0 < 1.0, 1.0 + np.ceil(log_p / np.log(np.minimum(p0, 1.0 - 1e-16))),
                            np.inf)
        ok = np.flatnonzero(stop - s >= need)
        if ok.size:
            i = int(ok[0])
            k = int(s[i] + need[i] - 1)
            if best is None or k < best[0]:
                best = (k, c, int(need[i]))
    return best


def _stuck_candidates(z, k0, design, lo, k, E) -> list:
    """Active gyros whose output has repeated one value from before the alarm to E."""
    out = []
    for pos, g in enumerate(design.gyros):
        col = z[:, g]
        start = ff.stuck_run(col, E)
        if start > k or start < k0:
            continue
        run = E - start + 1
        before = col[k0:max(start, k0 + 1)]
        same = int(np.sum(before[1:] == before[:-1])) if before.size > 1 else 0
        p0 = (same + 1.0) / (before.size + 1.0)
        if (run - 1) * math.log(p0) <= math.log(STUCK_RUN_P):
            out.append((pos, start))
    return out


def _kind_fit(fits, j: int, kind: str, design, dt: float):
    """(onset index in segment, onset σ [samples], size, σ, dll) of gyro position j."""
    if kind in ("step", "drift"):
        num, den, dll = fits[kind]
        b, bsig = ff.onset_sigma(dll[:, j])
        size, sig = num[b, j] / den[b, j], 1.0 / math.sqrt(den[b, j])
        if kind == "drift":
            size, sig = size / dt, sig / dt
        return b, bsig, size, sig, float(dll[b, j])
    lam, count, dll, var_on = fits["noise"]
    b, bsig = ff.onset_sigma(dll[:, j], var_on)
    w = design.white_share[j]
    ratio = math.sqrt(max(0.0, 1.0 + (lam[b, j] - 1.0) / w))
    lam_sig = lam[b, j] * math.sqrt(2.0 / count[b])
    return (int(var_on[b]), bsig, ratio, lam_sig / (2.0 * w * max(ratio, 1e-12)), float(dll[b, j]))


def _best_kind(fits, j: int) -> str:
    vals = {"step": fits["step"][2][:, j].max(), "drift": fits["drift"][2][:, j].max(),
            "noise": fits["noise"][2][:, j].max()}
    return max(vals, key=lambda kind: vals[kind])


def _alarm_fit(z, t, k0, design, hit, fits, gi, E, isolated, margin, dt, odds):
    grp = design.groups[gi]
    j = max(grp, key=lambda p: float(np.linalg.norm(design.coef[:, p])))   # smallest size
    kind = _best_kind(fits, j)
    b, bsig, size, sig, dll = _kind_fit(fits, j, kind, design, dt)
    onset_k = k0 + fits["lo"] + b
    if kind == "noise":
        size_out, sig_out = size, sig
    else:
        size_out, sig_out = float(rad_s_to_deg_s(size)), float(rad_s_to_deg_s(sig))
    gyro = design.gyros[j] if isolated else None
    cands = tuple(design.gyros[p] + 1 for p in grp)
    det = k0 + hit["k"]
    fam, L = hit["family"], hit["L"]
    iso_text = (f"isolated: gyro {gyro + 1}'s {kind} fits better than any other parity direction "
                f"by ln LR = {margin:.1f} (needs ln {odds:g} = {math.log(odds):.1f})"
                if isolated else
                ("detected, not isolable: " + (f"gyros {', '.join(map(str, cands))} share one parity "
                                               f"direction (size given for gyro {design.gyros[j] + 1})"
                                               if len(grp) > 1 else
                                               f"best gyro {cands[0]} ahead by only ln LR = {margin:.1f}, "
                                               f"needs ln {odds:g}")))
    evidence = (f"{fam} test over {L * dt:g} s: |statistic| {abs(hit['value']):.3g} > threshold "
                f"{hit['threshold']:.3g}; {kind} fit: onset {t[onset_k]:.3f} ± {bsig * dt:.3f} s, "
                f"size {size_out:.4g} ± {sig_out:.2g} {KIND_UNITS[kind]}; {iso_text}")
    alarm = Alarm(gyro=None if gyro is None else gyro + 1, kind=kind, onset_s=float(t[onset_k]),
                  onset_sigma_s=bsig * dt, detected_s=float(t[det]),
                  isolated_s=None if E is None else float(t[k0 + E]), size=size_out,
                  size_sigma=sig_out, size_unit=KIND_UNITS[kind], isolated=bool(isolated),
                  candidates=cands, evidence=evidence, family=fam, window_s=L * dt,
                  statistic=float(hit["value"]), threshold=float(hit["threshold"]))
    return alarm, (None if E is None else k0 + E + 1), gyro


def _alarm_stuck(z, t, k0, design, hit, cand, fits, E, dt):
    pos, start = cand
    g = design.gyros[pos]
    onset_k = min(start + 1, z.shape[0] - 1)
    det = k0 + hit["k"]
    value = float(rad_s_to_deg_s(z[start, g]))
    test = ("flat-line test: " if hit["family"] == "flat" else
            f"{hit['family']} test over {hit['L'] * dt:g} s: |statistic| {abs(hit['value']):.3g} > "
            f"threshold {hit['threshold']:.3g}; ")
    evidence = (f"{test}gyro {g + 1} has output {value:.6g} deg/s for "
                f"{k0 + E - start + 1} samples since {t[start]:.3f} s (a run its earlier outputs make "
                f"implausible at p < {STUCK_RUN_P:g}): stuck, isolated by the flat line")
    alarm = Alarm(gyro=g + 1, kind="stuck", onset_s=float(t[onset_k]), onset_sigma_s=dt / math.sqrt(12.0),
                  detected_s=float(t[det]), isolated_s=float(t[k0 + E]), size=value, size_sigma=0.0,
                  size_unit=KIND_UNITS["stuck"], isolated=True, candidates=(g + 1,),
                  evidence=evidence, family=hit["family"], window_s=hit["L"] * dt,
                  statistic=float(hit["value"]), threshold=float(hit["threshold"]))
    return alarm, k0 + E + 1, g


# -- recovery ------------------------------------------------------------------

def fuse(z: np.ndarray, H: np.ndarray, noise: ArrayNoise, dt_s: float, exclusions=()) -> np.ndarray:
    """GLS body rate, re-solved without each excluded gyro from its exclusion on.

    Parameters
    ----------
    z : ndarray, shape (n, N)
        Readings [rad/s].
    H : ndarray, shape (N, 3)
    noise : ArrayNoise
    dt_s : float
    exclusions : sequence of (int, int)
        (first sample, 0-based gyro) pairs, in time order.

    Returns
    -------
    ndarray, shape (n, 3)
        ω̂ = (HₐᵀRₐ⁻¹Hₐ)⁻¹HₐᵀRₐ⁻¹ zₐ over the active gyros a of each stretch [rad/s].
    """
    n, N = z.shape
    R = noise.R(dt_s)
    out = np.empty((n, 3))
    bounds = [0] + [int(k) for k, _ in exclusions] + [n]
    active = list(range(N))
    for i in range(len(bounds) - 1):
        if i > 0:
            active.remove(int(exclusions[i - 1][1]))
        s, e = bounds[i], bounds[i + 1]
        if e <= s:
            continue
        G, _ = gls_weights(H[active], R[np.ix_(active, active)])
        out[s:e] = z[s:e][:, active] @ G.T
    return out


# -- design figures: minimum detectable faults, isolability ----------------------

def _as_noise(layout, noise, n: int) -> ArrayNoise:
    return noise if isinstance(noise, ArrayNoise) else array_noise(noise, n)


def minimum_detectable(layout: Layout, noise, far_per_h: float = 0.01, p_md: float = 0.001, *,
                       dt_s: float = 0.01, bias_memory_s: float = ff.DEFAULT_BIAS_MEMORY_S,
                       drift_window_s: float = 600.0, variance_window_s: float = 40.0,
                       design: ParityDesign | None = None, repeat_share=None) -> dict:
    """Smallest fault of each kind on each gyro that the detector finds with probability 1 − p_md.

    Parameters
    ----------
    layout : Layout
    noise : NoiseModel or ArrayNoise
    far_per_h : float
        False-alarm rate the thresholds are set for [1/h].
    p_md : float
        Missed-detection probability [-].
    dt_s : float
        Sample period [s].
    bias_memory_s, drift_window_s, variance_window_s : float
        As :class:`FaultDetector`.
    design : ParityDesign, optional
        A design already made for these gyros (the other settings are then its own).
    repeat_share : array_like, shape (N,), optional
        Share of each gyro's healthy samples that repeat the previous output
        [-] (quantised outputs); default that of a continuous output after one
        shortest block, 1/33.

    Returns
    -------
    dict
        ``step_rad_s`` (N,): (u + Φ⁻¹(1 − p_md))/√E_j, E_j the energy of gyro
        j's step signature over the longest step window (its non-centrality
        per unit step); ``drift_rad_s2`` (N,): the same with the ramp
        signature over the longest drift window (``drift_window_s``), i.e.
        found within that time; ``noise_ratio`` (N,): the smallest ratio > 1
        whose variance the longest block detects (exact χ², one-sided, beyond
        the no-fault band); ``stuck_static_s`` (N,): the run of repeated
        outputs the flat-line test needs to call a gyro stuck
        (:func:`stuck_run_needed`) [s]; ``isolable`` (N,) bool; ``u_step``,
        ``u_drift``, ``g_variance``. inf where a gyro has no parity (its
        faults are invisible).

    Notes
    -----
    A matched window statistic is N(δ, 1) with δ = size·√E, so it crosses u
    with probability Φ(δ − u) + Φ(−δ − u) ≈ 1 − p_md at δ = u + Φ⁻¹(1 − p_md).
    For white noise, one sample and no bias tracking this is Baarda's and
    Sturza's minimum detectable bias δ₀σⱼ/√(1 − hⱼᵀ(HᵀH)⁻¹hⱼ) (tests).
    """
    H = layout.H if isinstance(layout, Layout) else np.asarray(layout, dtype=float)
    nz = _as_noise(layout, noise, H.shape[0])
    d = design or design_parity(H, nz, dt_s, far_per_h=far_per_h, bias_memory_s=bias_memory_s,
                                drift_window_s=drift_window_s, variance_window_s=variance_window_s)
    zb = float(special.ndtri(1.0 - p_md))
    N = H.shape[0]
    # without a record: continuous outputs, the repeat share the flat test reads after a block
    share = np.broadcast_to(np.asarray(1.0 / (VARIANCE_MIN_BLOCK + 1.0) if repeat_share is None
                                       else repeat_share, dtype=float), (N,))
    step, drift, ratio, stuck = (np.full(N, np.inf) for _ in range(4))
    iso = np.zeros(N, dtype=bool)
    for grp in d.groups:
        for p in grp:
            iso[d.gyros[p]] = len(grp) == 1 and d.m >= 2
    for p, g in enumerate(d.gyros):
        if np.linalg.norm(d.coef[:, p]) == 0:
            continue
        Ls, Ld = d.scales["step"][-1], d.scales["drift"][-1]
        step[g] = (d.thresholds["step"] + zb) / math.sqrt(d.energies[("step", p, Ls)])
        drift[g] = (d.thresholds["drift"] + zb) / math.sqrt(d.energies[("drift", p, Ld)]) / dt_s
        ratio[g] = _variance_detectable(d, p, p_md)
        # a stuck gyro at rest: the flat line (its parity only loses noise, which the one-sided
        # variance test does not call a fault): the run its repeat share makes implausible
        stuck[g] = float(stuck_run_needed(share[g])) * dt_s
    return {"step_rad_s": step, "drift_rad_s2": drift, "noise_ratio": ratio,
            "stuck_static_s": stuck, "isolable": iso, "u_step": d.thresholds["step"],
            "u_drift": d.thresholds["drift"], "g_variance": d.thresholds["variance"],
            "drift_window_s": d.scales["drift"][-1] * dt_s, "p_md": p_md, "far_per_h": far_per_h}


def _variance_detectable(d: ParityDesign, p: int, p_md: float) -> float:
    """Smallest noise amplitude ratio > 1 the longest block finds with probability 1 − p_md."""
    g = d.thresholds["variance"]
    w = d.white_share[p]
    hi_band = 1.0 if d.var_band is None else float(d.var_band[1, p])
    L = d.scales["variance"][-1]
    _, hi = ff._glr_roots(g, L)

    def power(lam, L=L, hi=hi):                              # P(GLR > g) when Var = λ (one-sided)
        return stats.chi2.sf(L * hi / lam, L)
    lam = optimize.brentq(lambda x: power(x) - (1.0 - p_md), 1.0 + 1e-9, 1e6) \
        if power(1e6) > 1.0 - p_md else math.inf
    lam = lam * hi_band                                       # beyond the no-fault band
    return math.sqrt(1.0 + (lam - 1.0) / w) if math.isfinite(lam) else math.inf


def stuck_run_needed(repeat_share) -> np.ndarray:
    """Samples of repeated output the flat-line test needs to call a gyro stuck (:func:`flat_alarm`).

    Parameters
    ----------
    repeat_share : array_like
        Share of a gyro's samples that repeat the previous one when healthy [-].

    Returns
    -------
    ndarray
        1 + ⌈ln :data:`STUCK_RUN_P` / ln p₀⌉ [samples] (inf for p₀ >= 1).
    """
    p0 = np.asarray(repeat_share, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((p0 > 0) & (p0 < 1), 1.0 + np.ceil(math.log(STUCK_RUN_P) / np.log(
            np.clip(p0, 1e-300, 1.0 - 1e-16))), np.where(p0 <= 0, 2.0, np.inf))


def minimum_detectable_step(layout: Layout, noise, far_per_h: float = 0.01, p_md: float = 0.001,
                            **kw) -> np.ndarray:
    """Minimum detectable step per gyro [rad/s] (N,): ``minimum_detectable(...)["step_rad_s"]``."""
    return minimum_detectable(layout, noise, far_per_h, p_md, **kw)["step_rad_s"]


def isolability(layout: Layout, noise=None, *, dt_s: float = 0.01) -> dict:
    """Which single faults the layout's parity can attribute to one gyro.

    Parameters
    ----------
    layout : Layout
    noise : NoiseModel or ArrayNoise, optional
        The ARW covariance whitens the parity; default identical, uncorrelated.

    Returns
    -------
    dict
        ``parity_dim`` (N − 3), ``isolable`` (every gyro its own direction and
        N − 3 >= 2), ``groups`` (lists of 1-based gyros sharing a direction),
        ``max_cos`` (largest |cos| between two different directions: near 1,
        isolation needs more data).
    """
    H = layout.H if isinstance(layout, Layout) else np.asarray(layout, dtype=float)
    N = H.shape[0]
    R = None if noise is None else _as_noise(layout, noise, N).R(dt_s)
    _, P = parity_matrix(H, R)
    groups = _groups(P) if P.shape[0] else tuple((j,) for j in range(N))
    norms = np.linalg.norm(P, axis=0)
    unit = P / np.where(norms > 0, norms, 1.0)
    reps = [g[0] for g in groups]
    cos = [abs(float(unit[:, a] @ unit[:, b])) for i, a in enumerate(reps) for b in reps[i + 1:]]
    return {"parity_dim": int(P.shape[0]),
            "isolable": bool(P.shape[0] >= 2 and all(len(g) == 1 for g in groups)),
            "groups": [[j + 1 for j in g] for g in groups],
            "max_cos": max(cos) if cos else 1.0}


# -- noise from the record itself ---------------------------------------------------

def parity_is_zero(readings_rad_s, H) -> bool:
    """Whether every sample's parity is zero to rounding: the outputs are exactly consistent.

    Parameters
    ----------
    readings_rad_s : ndarray, shape (n, N)
        Gyro outputs [rad/s].
    H : ndarray, shape (N, 3)
        Sensitive axes [-].

    Returns
    -------
    bool
        ‖V z_k‖ <= :data:`PARITY_ZERO_RTOL`·‖z_k‖ at every sample k (V the
        orthonormal parity basis of H; the test does not depend on the noise
        weighting, whose parity spans the same null space). True for
        identical gyros on a layout whose axes share one elevation, constant
        outputs of a body at rest, and simulated noise-free arrays.

    Notes
    -----
    Why such a record has no fault rather than a refusal: a single-gyro
    fault of any kind (step, drift, stuck, noise) of non-zero size on a gyro
    the parity sees adds size·P[:, j] ≠ 0 to the parity. A parity that is
    zero at every sample is therefore proof that no such fault is present;
    the detector's statistics, which would read the missing noise as a
    variance collapse of *every* parity direction at once (no single-gyro
    fault looks like that), are not run on it.
    """
    z = np.asarray(readings_rad_s, dtype=float)
    V, _ = parity_matrix(H)
    if V.shape[0] == 0 or z.shape[0] == 0:
        return False
    p = np.linalg.norm(z @ V.T, axis=1)
    return bool(np.all(p <= PARITY_ZERO_RTOL * np.linalg.norm(z, axis=1)))


def _white_and_walk(e: np.ndarray) -> tuple[float, float]:
    """(σ², q) per sample of one series, each raised by 2σ of its fit (:func:`estimate_noise`).

    A series without variation at any octave (noise-free, constant) gives
    (0, 0): there is nothing to fit, and NNLS is never called on it. At least
    :data:`MIN_NOISE_SAMPLES` samples (two octaves) are needed. An octave whose
    differences are mostly exact zeros (outputs quantised coarser than their
    noise) takes their plain mean square: its MAD is 0 though the gyro moves.
    """
    n = e.size
    if n < MIN_NOISE_SAMPLES:
        raise InputError(f"the noise estimate needs at least {MIN_NOISE_SAMPLES} samples, got {n}")
    A, d_sizes, b = [], [], []
    for m in _pow2_scales(1, max(1, n // 16)):
        nb = n // m
        if nb < 8:
            break
        d = np.diff(e[:nb * m].reshape(nb, m).mean(axis=1))          # adjacent means of m
        v = (1.4826 * np.median(np.abs(d - np.median(d)))) ** 2        # robust variance
        ad = np.abs(d)
        if np.mean(ad <= 1e-9 * ad.max()) >= 0.5 and ad.max() > 0.0:
            # quantised outputs: half the differences or more are 0 LSB (to rounding) and the
            # MAD says 0 where the gyro does move; the plain variance does not
            v = float(np.mean(d * d))
        A.append([2.0 / m, (2.0 * m * m + 1.0) / (3.0 * m)])          # 2σ²/m + q(2m² + 1)/(3m)
        b.append(v)
        d_sizes.append(d.size)
    top = max(b)
    if not (math.isfinite(top) and top > 0.0):                         # no variation to fit
        return 0.0, 0.0
    # 1/(v √(2/M)); an octave whose MAD is 0 (quantised outputs) is weighted as 1e-12 of the
    # largest variance rather than 1/1e-300, which would overflow AᵀA
    W = [math.sqrt(M / 2.0) / max(v, 1e-12 * top, 1e-300) for M, v in zip(d_sizes, b)]
    Aw = np.array(A) * np.array(W)[:, None]
    sol, _ = optimize.nnls(Aw, np.array(b) * np.array(W))
    cov = np.linalg.pinv(Aw.T @ Aw)                                    # rows have unit variance
    return (max(sol[0] + 2.0 * math.sqrt(max(cov[0, 0], 0.0)), 1e-300),
            sol[1] + 2.0 * math.sqrt(max(cov[1, 1], 0.0)))


def _reference_chunks(still: np.ndarray, dt_s: float, *, everything: bool = False) -> list:
    """The chunks [a, b) the per-gyro levels are read on: the first still runs up to a quarter of
    the still samples (at least :data:`REFERENCE_SPAN_S`; all of them with ``everything``), each
    cut into pieces of about :data:`NOISE_CHUNK_S` (at least :data:`MIN_CHUNK_SAMPLES`)."""
    still = np.asarray(still, dtype=bool)
    runs = [(a, b) for a, b in true_runs(still) if b - a >= MIN_CHUNK_SAMPLES]
    total = sum(b - a for a, b in runs)
    want = total if everything else max(total // 4, int(round(REFERENCE_SPAN_S / dt_s)))
    chunk = max(MIN_CHUNK_SAMPLES, int(round(NOISE_CHUNK_S / dt_s)))
    out, got = [], 0
    for a, b in runs:
        if got >= want:
            break
        b = min(b, a + (want - got)) if want - got >= MIN_CHUNK_SAMPLES else b
        k = max(1, (b - a) // chunk)
        edges = np.linspace(a, b, k + 1).round().astype(int)
        out += [(int(x), int(y)) for x, y in zip(edges[:-1], edges[1:])]
        got += b - a
    return out


def _chunk_variances(z: np.ndarray, chunks: list) -> tuple[np.ndarray, np.ndarray]:
    """Per chunk and gyro the sample variance about the chunk's mean (C, N), and each chunk's size."""
    v = np.array([np.var(z[a:b], axis=0, ddof=1) for a, b in chunks])
    return v, np.array([b - a for a, b in chunks], dtype=float)


def noise_spread(readings_rad_s, dt_s: float, still, *, reference=None) -> tuple[np.ndarray, list]:
    """How much each gyro's white level changes along a record without a fault: κ per gyro.

    Parameters
    ----------
    readings_rad_s : ndarray, shape (n, N)
        Gyro outputs [rad/s].
    dt_s : float
        Sample step [s].
    still : ndarray of bool, shape (n,)
        Still samples (:func:`~gyroarray.analysis.motion.still_mask`).
    reference : array_like, shape (N,), optional
        The per-sample white variance each gyro's tests are designed with
        [rad²/s²]; κ is then the top of the gyro's no-fault band over it
        (default: over the centre of its chunk levels).

    Returns
    -------
    kappa : ndarray, shape (N,)
        Factor κ ≥ 1 on the variance that is no fault (``variance_tolerance``
        of :class:`FaultDetector`).
    notes : list of str

    Notes
    -----
    Every still part, cut into chunks of about :data:`NOISE_CHUNK_S`, gives
    per chunk a sample variance v_c (n_c samples): all of them, since a
    level that changes with the orientation shows only over several
    orientations (the robust spread below is not moved by a minority of
    chunks, e.g. those a noise fault covers). Without a level change ln v_c
    scatters with variance 2/(n_c − 1) only; Cochran's Q = Σ (ln v_c −
    mean)²/(2/(n_c − 1)) is then χ² with C − 1 dof. Where its p-value is
    below :data:`SPREAD_P` the between-chunk scatter τ² (robust variance of
    ln v_c minus the sampling part) is real: real MEMS gyros' noise changes
    with the orientation and the vibration lines they pick up (the MIMU4444
    record: a factor 0.4–1.5 between orientations on two of its gyros), and
    κ = exp(:data:`SPREAD_Z`·τ): the level of the gyro's worst credible
    part, its median part level raised by SPREAD_Z of their spread (over
    ``reference``: exp(median ln v_c + SPREAD_Z·τ)/reference, at least 1).
    The median and the MAD make it a property of the healthy majority of
    the parts: a noise fault that covers a minority of them neither moves
    nor widens it. Elsewhere κ = 1 (a simulated white record keeps the exact
    χ² test).

    A fault lasts to the end of the record, so it may cover most of the
    still parts. With ``reference`` the band is therefore read where no noise
    fault reaches: a noise fault only raises a gyro's level, so the spread τ
    is taken from the chunks below the healthy start (the median of the
    reference span's chunks, :func:`estimate_noise`), mirrored, and the top
    is that start raised by SPREAD_Z·τ, or the highest level (2σ low) the
    gyro came back from (a later chunk back within that band) or reached
    gradually from it (no rise above :data:`SPREAD_JUMP` between neighbouring
    chunks: a warming board's level creeps, a noise fault has an onset). A
    noise fault x3 in amplitude over the last 45 % of a record's still parts
    is found (``tests/test_fdi_real_board.py``); experiment 1's gyro 22,
    whose level creeps x1.5 over 8 min, is no fault.
    """
    z = np.asarray(readings_rad_s, dtype=float)
    N = z.shape[1]
    chunks = _reference_chunks(still, dt_s, everything=True)
    kap, _ = _chunk_spread(z, chunks, N)
    held = np.ones(N, dtype=bool)
    if reference is not None and len(chunks) >= 3 and np.any(kap > 1.0):
        ref = np.broadcast_to(np.asarray(reference, dtype=float), (N,))
        v, nc = _chunk_variances(z, chunks)
        rv, _ = _chunk_variances(z, _reference_chunks(still, dt_s))
        lv = np.log(np.maximum(v, 1e-300))
        anchor = np.median(np.log(np.maximum(rv, 1e-300)), axis=0)     # the healthy start
        samp = float(np.mean(2.0 / (nc - 1.0)))
        below = lv < anchor[None, :]
        n_below = below.sum(axis=0)
        d2 = np.where(below, (lv - anchor[None, :]) ** 2, 0.0).sum(axis=0) / np.maximum(n_below, 1)
        tau = np.sqrt(np.maximum(d2 - samp, 0.0))
        held = n_below >= 3
        # a noise fault only raises a gyro's level, from its onset to the end: the wander is read
        # below the healthy start (mirrored), where no noise fault reaches, and every level the
        # gyro came back from (a later chunk back within that band) is credible too
        band = anchor + SPREAD_Z * tau
        later = np.vstack([np.minimum.accumulate(lv[::-1], axis=0)[::-1][1:],
                           np.full((1, N), np.inf)])               # lowest level after chunk c
        lcb = lv - 2.0 * np.sqrt(2.0 / (nc[:, None] - 1.0))        # chunk level, 2σ low
        back = np.where(later <= band[None, :], lcb, -np.inf).max(axis=0)
        # and every level it reached gradually from that band (no rise above SPREAD_JUMP between
        # neighbouring chunks on the way): a noise fault starts at an onset, a warming board's
        # level creeps (experiment 1's gyro 22: x1.5 over 8 min)
        step = math.log(SPREAD_JUMP)
        chain = lv[0] <= band
        crept = np.where(chain, lcb[0], -np.inf)
        for c in range(1, lv.shape[0]):
            chain = (lv[c] <= band) | (chain & (lv[c] - lv[c - 1] <= step))
            crept = np.maximum(crept, np.where(chain, lcb[c], -np.inf))
        top = np.exp(np.maximum(band, np.maximum(back, crept))) / ref
        kap = np.where(kap > 1.0, np.where(held, np.maximum(top, 1.0), kap), 1.0)
    real = kap > 1.0
    notes = []
    if real.any():
        notes.append("white level changes between still parts beyond chance (no fault: the "
                     "variance test allows it): " + ", ".join(
                         f"gyro {j + 1} x{kap[j]:.2f}" for j in np.flatnonzero(real)))
    return kap, notes


def _chunk_spread(z: np.ndarray, chunks: list, N: int) -> tuple[np.ndarray, np.ndarray]:
    """(κ, centre) per gyro over chunks: exp(SPREAD_Z·τ) where Cochran's Q says the levels change
    (else 1), and exp(median ln v_c) [rad²/s²] (:func:`noise_spread`)."""
    kap = np.ones(N)
    if len(chunks) < 3:
        return kap, np.full(N, np.nan) if not chunks else np.median(_chunk_variances(z, chunks)[0], axis=0)
    v, nc = _chunk_variances(z, chunks)
    if not np.all(v > 0):
        return kap, np.median(v, axis=0)
    lv = np.log(v)
    samp = 2.0 / (nc - 1.0)
    Q = np.sum((lv - lv.mean(axis=0)) ** 2 / samp[:, None], axis=0)
    pv = stats.chi2.sf(Q, len(chunks) - 1)
    tau2 = (1.4826 * np.median(np.abs(lv - np.median(lv, axis=0)), axis=0)) ** 2 - float(np.mean(samp))
    real = (pv < SPREAD_P) & (tau2 > 0)
    kap[real] = np.exp(SPREAD_Z * np.sqrt(tau2[real]))
    return kap, np.exp(np.median(lv, axis=0))


def estimate_noise(readings_rad_s, layout: Layout, dt_s: float, ref_rad_s=None, *,
                   still=None) -> tuple[ArrayNoise, list]:
    """ARW and RRW of each gyro estimated robustly from the record (no model given).

    Parameters
    ----------
    readings_rad_s : ndarray, shape (n, N)
    layout : Layout
    dt_s : float
    ref_rad_s : ndarray, shape (n, 3), optional
        Reference rate: per-gyro residuals z − H·ref.
    still : ndarray of bool, shape (n,), optional
        Without a reference: the still samples
        (:func:`~gyroarray.analysis.motion.still_mask`). Each gyro's own
        levels are then read on them (below); without it (or with too few
        still samples) the parity of unweighted V is used (identical,
        uncorrelated gyros assumed).

    Returns
    -------
    ArrayNoise, list of str (notes)

    Notes
    -----
    Only the first quarter of the record (at least ``REFERENCE_SPAN_S``) is
    used: a fault lasts to the end of the record, so the start is the
    healthy reference. Adjacent means of m samples differ with variance 2σ²/m + q(2m² + 1)/(3m)
    (white σ² = N²/dt, random walk q = K²dt per sample). That variance is
    read as (1.4826·MAD)² of the differences at m = 1, 2, 4, ... n/16 (the
    MAD ignores the few differences a step or a short fault touches) and
    (σ², q) fitted by non-negative least squares, each octave weighted by its
    relative standard error √(2/M) (M differences); each is then raised by
    twice its standard error, so an estimated model errs toward fewer false
    alarms. Correlations are taken as 0.

    With ``still`` and no reference, each gyro's output on a still platform
    is its own noise (plus a constant rate): the first still runs up to a
    quarter of the still samples (at least ``REFERENCE_SPAN_S``) are cut into
    chunks of about :data:`NOISE_CHUNK_S`; a gyro's white variance per sample
    is the median over the chunks of its variance about the chunk's mean
    (robust to a chunk a fault or a knock touches; quantization noise
    included, as it is in the outputs), raised by twice the median's
    standard error; its RRW is fitted as above on the still runs (each
    minus its mean). Gyros differ (a real board: ARW 0.7–4 deg/√h), so their
    parity is weighted by their own levels (heterogeneous R).

    Raises
    ------
    InputError
        Fewer than :data:`MIN_NOISE_SAMPLES` samples, or a reference span in
        which most gyros (or the parity) do not vary at all: there is no
        noise to set thresholds from (give a model instead).
    """
    z = np.asarray(readings_rad_s, dtype=float)
    H = layout.H
    notes = []
    if ref_rad_s is None and still is not None:
        chunks = _reference_chunks(still, dt_s)
        if sum(b - a for a, b in chunks) >= MIN_NOISE_SAMPLES * 4 and chunks:
            return _still_noise(z, H, dt_s, chunks)
    if ref_rad_s is not None:
        e = z - np.asarray(ref_rad_s, dtype=float) @ H.T
        notes.append("noise estimated from the record (gyro output − H·ref, robust MAD of "
                     "adjacent means): ARW and RRW per gyro, no correlation")
    else:
        V, _ = parity_matrix(H)
        e = z @ V.T
        notes.append("noise estimated from the record (parity of the readings, robust MAD of "
                     "adjacent means): one ARW and RRW for every gyro, no correlation (no "
                     "reference rate to tell the gyros apart)")
    n_all = e.shape[0]
    n = min(n_all, max(n_all // 4, int(round(REFERENCE_SPAN_S / dt_s)), MIN_NOISE_SAMPLES))
    e = e[:n]
    notes.append(f"noise taken from the first {n * dt_s:.4g} s of the record (a fault lasts to the "
                 "end of a record, so its start is the healthy reference)")
    s2, q = np.array([_white_and_walk(e[:, c]) for c in range(e.shape[1])]).T
    if not (np.all(np.isfinite(s2)) and np.all(np.isfinite(q)) and float(np.median(s2)) > 0.0):
        raise InputError(f"the first {n * dt_s:.4g} s of the record (the span the noise is "
                         "estimated on) have no noise: the gyros' outputs there are exactly "
                         "consistent (identical, constant or noise-free?), so no threshold can be "
                         "set from them; give --model MODEL.toml with the gyros' ARW and RRW")
    floor = 1e-6 * float(np.median(s2))
    if np.any(s2 <= floor):
        bad = np.flatnonzero(s2 <= floor) + 1
        notes.append(f"gyro(s) {', '.join(map(str, bad))} barely move in the reference span: their "
                     "white noise is floored at 1e-6 of the median")
        s2 = np.maximum(s2, floor)
    if ref_rad_s is None:
        s2 = np.full(H.shape[0], float(np.median(s2)))
        q = np.full(H.shape[0], float(np.median(q)))
    arw = np.sqrt(s2 * dt_s)                                   # N = σ√dt
    rrw = np.sqrt(q / dt_s)                                    # K = √(q/dt)
    eye = np.eye(H.shape[0])
    return ArrayNoise(arw, rrw, eye, eye), notes


def _still_noise(z: np.ndarray, H: np.ndarray, dt_s: float, chunks: list) -> tuple[ArrayNoise, list]:
    """Each gyro's white and walk levels from still chunks (:func:`estimate_noise` with ``still``)."""
    v, nc = _chunk_variances(z, chunks)
    C = len(chunks)
    with np.errstate(divide="ignore"):
        lv = np.log(np.maximum(v, 1e-300))
    level = np.exp(np.median(lv, axis=0))
    if C >= 3:
        se = 1.2533 * 1.4826 * np.median(np.abs(lv - np.median(lv, axis=0)), axis=0) / math.sqrt(C)
    else:
        se = np.zeros(z.shape[1])
    se = np.maximum(se, math.sqrt(2.0 / max(float(nc.sum()) - 1.0, 1.0)))
    s2 = level * np.exp(2.0 * se)
    span = sum(b - a for a, b in chunks) * dt_s
    top = max(float(np.max(np.abs(z[a:b]))) for a, b in chunks)
    if not (np.all(np.isfinite(s2)) and float(np.median(level)) > (PARITY_ZERO_RTOL * top) ** 2):
        raise InputError(f"the still parts the noise is estimated on ({span:.4g} s) have no noise: "
                         "the gyros' outputs there are constant (to rounding), so no threshold can be set from "
                         "them; give --model MODEL.toml with the gyros' ARW and RRW")
    notes = [f"noise estimated from the record's still parts (the first {span:.4g} s of them, "
             f"{C} chunk(s)): each gyro's own white level (median chunk variance) and RRW, no "
             "correlation; heterogeneous gyros are weighted by their own levels"]
    floor = 1e-6 * float(np.median(s2))
    if np.any(s2 <= floor):
        bad = np.flatnonzero(s2 <= floor) + 1
        notes.append(f"gyro(s) {', '.join(map(str, bad))} barely move in the reference span: their "
                     "white noise is floored at 1e-6 of the median")
        s2 = np.maximum(s2, floor)
    runs: list[tuple[int, int]] = []
    for a, b in chunks:                                        # chunks of one run joined again
        if runs and runs[-1][1] == a:
            runs[-1] = (runs[-1][0], b)
        else:
            runs.append((a, b))
    x = np.concatenate([z[a:b] - z[a:b].mean(axis=0) for a, b in runs])
    q = np.array([_white_and_walk(x[:, j])[1] if x.shape[0] >= MIN_NOISE_SAMPLES else 0.0
                  for j in range(z.shape[1])])
    eye = np.eye(H.shape[0])
    ratio = np.sqrt(s2 / np.median(s2))
    if ratio.max() / ratio.min() > 1.5:
        notes.append("white level per gyro over the median: " + ", ".join(
            f"{j + 1}: {r:.2f}" for j, r in enumerate(ratio)))
    return ArrayNoise(np.sqrt(s2 * dt_s), np.sqrt(q / dt_s), eye, eye), notes


def per_sample_noise(noise: ArrayNoise, readings_rad_s, dt_s: float, still) -> tuple[ArrayNoise, list]:
    """A noise model's white levels read per sample on the record's still parts.

    Parameters
    ----------
    noise : ArrayNoise
        The model's levels: ARW N [rad/√s] (a white level at τ >= 1 s, as
        ``gyroarray fit`` and the Allan fits give), RRW [rad/s/√s] and
        correlations.
    readings_rad_s : ndarray, shape (n, N)
        Gyro outputs [rad/s].
    dt_s : float
        Sample step [s].
    still : ndarray of bool, shape (n,) or None
        Still samples (:func:`~gyroarray.analysis.motion.still_mask`).

    Returns
    -------
    ArrayNoise, list of str (notes)
        The model's correlations with each gyro's white level of one sample as
        the record's still parts give it (:func:`estimate_noise` with
        ``still``: the median chunk variance, raised by two standard errors)
        and the larger of the model's RRW and the one the still parts show
        (the bias trackers must follow the bias the record has: a fitted RRW
        of 0 ± σ is a walk not seen at the model's τ, not a bias that cannot
        move). The model unchanged without enough still samples.

    Notes
    -----
    The parity tests work per sample: their white level is the variance of
    one sample, σ². A model's ARW N is the white level of averages over τ
    >= 1 s; a MEMS gyro with vibration lines (MPU-9150: 5–31 Hz at 62.5 Hz)
    and quantisation has σ² well above N²/dt (the MIMU4444 board: x2–5), so
    thresholds set from N²/dt read every healthy sample as a fault. The
    level of one sample is a property of the record (its sample rate,
    filters, mounting), so it is read there, for every gyro; the model keeps
    what a record's still parts cannot give as well: the walk and the
    correlations.
    """
    z = np.asarray(readings_rad_s, dtype=float)
    if still is None:
        return noise, []
    chunks = _reference_chunks(still, dt_s)
    if not chunks or sum(b - a for a, b in chunks) < MIN_NOISE_SAMPLES * 4:
        return noise, []
    try:
        rec, _ = _still_noise(z, np.zeros((z.shape[1], 3)), dt_s, chunks)
    except InputError:
        return noise, []
    model = np.asarray(noise.arw_rad_rt_s, dtype=float)
    ratio = rec.arw_rad_rt_s / np.maximum(model, 1e-300)
    rrw = np.maximum(np.asarray(noise.rrw_rad_s_rt_s, dtype=float), rec.rrw_rad_s_rt_s)
    raised = np.flatnonzero(rrw > np.asarray(noise.rrw_rad_s_rt_s, dtype=float))
    notes = [f"the model's ARW is a long-tau white level, not one sample's: every gyro's per-sample "
             f"white level is read on the record's still parts (x{float(ratio.min()):.2f}–"
             f"{float(ratio.max()):.2f} the model's N/sqrt(dt)); the model's correlations are kept, "
             "and its RRW where the still parts show no larger one"
             + (f" (raised on gyro(s) {', '.join(str(j + 1) for j in raised)})" if raised.size else "")]
    return ArrayNoise(rec.arw_rad_rt_s, rrw, noise.corr_arw, noise.corr_rrw,
                      noise.ignored_effects), notes


def model_noise(model, n_gyros: int) -> ArrayNoise:
    """A noise model's white and walk levels with its ``[array]`` table's correlations.

    Parameters
    ----------
    model : NoiseModel
        Per-gyro ``arw``/``rrw`` entries (and ``correlation``); an optional
        ``[array]`` table (:class:`gyroarray.effects.model.ArrayNoise`) whose
        ``white_correlation`` and ``walk_correlation`` replace the rows and
        columns of the gyros it names (0 between a named and an unnamed gyro).
    n_gyros : int

    Returns
    -------
    ArrayNoise
        What the detector designs with: a heterogeneous, correlated R.

    Raises
    ------
    InputError
        The combined correlation is not positive definite.
    """
    base = array_noise(model, n_gyros)
    table = getattr(model, "array", None)
    if table is None or not tuple(getattr(table, "gyros", ()) or ()):
        return base
    named = [g - 1 for g in table.gyros if 1 <= g <= n_gyros]
    rows = [i for i, g in enumerate(table.gyros) if 1 <= g <= n_gyros]
    corr = {}
    for key, default in (("white_correlation", base.corr_arw), ("walk_correlation", base.corr_rrw)):
        mat = getattr(table, key, None)
        out = np.array(default, dtype=float, copy=True)
        if mat is not None and named:
            m = np.asarray(mat, dtype=float)
            out[named, :] = 0.0
            out[:, named] = 0.0
            out[np.ix_(named, named)] = m[np.ix_(rows, rows)]
        corr[key] = out
    return ArrayNoise(base.arw_rad_rt_s, base.rrw_rad_s_rt_s, corr["white_correlation"],
                      corr["walk_correlation"], base.ignored_effects)
