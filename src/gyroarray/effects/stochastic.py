"""Fit side of the noise, array and time effects (``shared/spec/effects.md``).

Public API
----------
* :func:`fit_gyro_noise` ``(e, dt_s, gyro)``: one gyro's baseline terms
  ``arw`` and ``rrw`` and the stochastic effects ``bias_instability``,
  ``quantization``, ``rate_ramp``, ``gauss_markov``.
* :func:`~gyroarray.effects.correlation.fit_correlation` ``(E, dt_s)``: array-wide ``correlation``,
  ``rho_arw`` and ``rho_rrw`` (scalar, with the N×N matrix in ``extra``).
* :func:`~gyroarray.effects.burst.fit_burst` ``(E, time_s, dt_s)``: array-wide ``burst`` window.

All return :class:`~gyroarray.effects.fitting.EffectFit`. The input is
the residual of a static record (output minus the reference rate and the
starting bias) [rad/s] at a uniform step; SI inside, the spec's units only
in ``params``/``sigma``, through :mod:`gyroarray.core.units`.

Significance
------------
Every z is ≈ N(0, 1) when the effect is absent and the noise is ARW + RRW
(Gaussian), and large and positive when it is present:

================  ==========================================================
bias_instability  Wald Â/σ_Â of a flat column added to the Allan GLS
quantization      Wald Â/σ_Â of a τ⁻² column
rate_ramp         likelihood ratio (time domain, K profiled) -> chi2_to_z(·, 1)
gauss_markov      maximum over τc of Â/σ_Â, p-value of the maximum simulated
correlation       (ρ/σ₀)² -> chi2_to_z(·, 1), σ₀ the exact σ without correlation
burst             maximum likelihood ratio over windows, calibrated null tail
================  ==========================================================

For a linear model with fixed Σ the Wald ratio is the signed root of the
likelihood-ratio χ²(1); it is kept signed (a negative z says the data lie
below ARW + RRW there). The z of each effect as measured under the null:
``benchmarks/stochastic_fit_validation.md``.

Allan variance GLS (``bias_instability``, ``quantization``, ``gauss_markov``, baseline)
--------------------------------------------------------------------------------------
Overlapping Allan variance at octave τ = m·dt up to m = n/8 (the last
octaves have a few skewed degrees of freedom). Model Σ_t P_t² g_t(τ) with
the columns of :func:`~gyroarray.analysis.noise_fit.term_basis` (N², B², K²,
Q²) and :func:`~gyroarray.core.physics.gauss_markov_avar` (σ², exact sampled
form), fitted by unconstrained GLS (coefficients may be negative, so Â/σ_Â
is symmetric under the null), Σ recomputed from the fitted model three times.

Σ is the exact finite-record covariance of the estimates for Gaussian noise,
:meth:`~gyroarray.analysis.avar_covariance.AvarCovariance.covariance` (the
model :func:`~gyroarray.analysis.noise_fit.fit_noise_terms` reads its
large-record correlation from): white FM, random-walk FM, flicker FM, the
exact AR(1) variogram of a sampled Gauss–Markov rate and the white-PM
spikes of quantization, added before squaring; the cross-covariance of two
series for the correlation test.

Bias instability and quantization: one column more than the baseline, z =
Â/σ_Â, the coefficient √Â with the 1σ of ``noise_fit`` (the larger distance
to √(Â ± σ_Â); for Â <= 0 the value is 0 and the 1σ √σ_Â, the size just
detectable). Where the baseline does not describe the short τ (χ² tail
probability below ``_REF_P``: a filter or a hump the model lacks), the
bias-instability column is read on the octaves the K reference fit reads
(:func:`_rrw_reference`): a Wald ratio on a curve the baseline cannot fit is
no test, and there the baseline reads a flicker floor as random walk.

Gauss–Markov: τc scanned on 4 points per octave from 4·dt to τ_max/2; at
each, the GLS with the baseline's Σ gives W(τc) = σ̂²/σ(σ̂²), a linear form
c(τc)ᵀ ỹ of the whitened curve ỹ (≈ N(0, I) under the null). The null
distribution of max W is that of the maximum of a Gaussian vector with the
known correlations c(τc₁)·c(τc₂): simulated (10 000 draws, fixed seed);
beyond 20 exceedances, the Šidák form 1 − (1 − Φ̄(w))^M with M the effective
number of tests read at the 99th percentile. The estimate: τc refined
(bounded Brent) around the best grid point, Σ from the fitted model, τc
again, σ's from the whitened Jacobian in (N², K², σ², ln τc).

Rate ramp (time domain)
-----------------------
A ramp is a mean of the rate increments, which the Allan variance sees only
through its last, skewed octaves. With block means of L samples
(256 blocks), Δ_j = x̄_{j+1} − x̄_j = R·L·dt + an MA(1) process; for block j
= samples jL+1 .. (j+1)L of x = c + R t + b + w (b a random walk of
increments K²dt, w white of variance N²/dt):

    var Δ = K²dt (2L² + 1)/(3L) + 2N²/(dt L),
    cov(Δ_j, Δ_{j+1}) = K²dt (L² − 1)/(6L) − N²/(dt L)

(from Δ_j = Σ_s ((s−1)/L) ε_{jL+s} + Σ_s ((L−s+1)/L) ε_{(j+1)L+s} for the
increments ε; differencing removes c exactly). The banded Gaussian
likelihood is maximised with R free and with R = 0, N² from the Allan fit
and K² profiled in both (a short record cannot tell a random-walk drift from
a ramp without it; with K fixed at the Allan estimate, 3 of 21 practice
gyros gave |z| ≈ 3.8). z = chi2_to_z(LR, 1) (R is signed); σ_R the larger of
the GLS σ at the fitted K and |R|/√LR. A ramp with z > 3 is subtracted
before the Allan fits.

Correlation
-----------
Cross Allan covariances at the same octaves, ĉ_ik(τ) = mean(z_i z_k)/(2m²)
(one pass of second differences and an N×N product per τ), have
E ĉ_ik = ρᵃ_ik N_i N_k/τ + ρʳ_ik K_i K_k τ/3: short τ see the ARW, long τ the
RRW, and a GLS on the two columns weighs them, instead of a chosen τ. Σ
without correlation is exact (Isserlis: Σ_l w C^i C^k, the 2ΣC² of an
auto-variance halved, from both gyros' fitted models), plus the fitted cross
term ½ΣC^{ik}² twice. ρ_ik = coefficient/√(product of the gyros' own
coefficients), σ₀ its exact σ without correlation (per-pair z), its 1σ
(1 − ρ²)σ₀ (Fisher). The scalar (equicorrelated) ρ is the 1/σ₀²-weighted
mean of the pairs (uncorrelated without correlation, so its σ₀ is exact and
gives z); its 1σ comes from the Olkin–Siotani covariance of correlation
estimates at the common ρ. A family is used only on gyros where its
coefficient is above 3σ (the RRW of a short record often is not).

Burst
-----
Haar differences h_j = (e_{2j+1} − e_{2j})/√2: for white rate noise iid
N(0, σ²), σ² × ratio inside the window (the RRW adds K²dt/2, ~1e-4 of it);
whitened across gyros by the record's covariance (the burst multiplies
every gyro's ARW, correlated part included, by the same factor, so the
whitening is the same inside and out), u_j = |h̃_j|² ~ ratio_j·χ²_r. For a
window with its own variance the exact log-likelihood ratio against one
variance is

    LR = D log(U/D) − D_in log(U_in/D_in) − D_out log(U_out/D_out)

(U sums of u, D degrees of freedom). All windows of a grid of B = 256 blocks
(fewer on short records, >= 16 Haar samples per block) are scanned from
cumulative sums, O(n) + O(B²); then each boundary moves to its best Haar
sample within a block of the grid's, alternately (3 passes), and its 1σ is
the posterior sd under a flat prior (exp(LR/2) over the positions) combined
with dt for the discreteness. Ratio: (U_in/D_in)/(U_out/D_out), 1σ
ratio·√(2/D_in + 2/D_out).

z: the grid maximum of LR has, under the null, a distribution that depends
on B only (the Gaussian limit; tested at 100 and 10 000 degrees of freedom
per block: the same). It was simulated (40 000 maxima per B = 16 .. 256,
1000 degrees of freedom per block) and fitted, over its upper 70 %, by
P(max LR > x) = 1 − exp(−A x^β e^{−x/2}) (:data:`~gyroarray.effects.burst._BURST_NULL`).
Below the median z is approximate: the fitted p is a little small there, so
z is pulled toward 0 (the null's 1 % quantile gives z ≈ −2.0 instead of
−2.33).

Cross-check: a fixed-window DAVAR (:func:`~gyroarray.analysis.davar.davar`,
ARW read at τ0) of the most affected gyro, ``extra["davar"]``: its ARW²
inside the window over outside agrees with ``variance_ratio``.

References
----------
.. [1] IEEE Std 952-1997, Annex C.
.. [2] C. A. Greenhall, W. J. Riley, "Uncertainty of stability variances
   based on finite differences", Proc. 35th PTTI Meeting, 2003.
.. [3] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST SP
   1065, 2008.
.. [4] I. Olkin, M. Siotani, "Asymptotic distribution of functions of a
   correlation matrix", 1976; K. Pearson, L. N. G. Filon, Phil. Trans. A
   191, 1898.
.. [5] D. Siegmund, "Approximate tail probabilities for the maxima of some
   random fields", Ann. Probab. 16(2), 1988 (form of the scan tail).
.. [6] L. Galleani, P. Tavella, "The dynamic Allan variance", IEEE Trans.
   UFFC 56(3), 2009.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import linalg, optimize, stats

from gyroarray.analysis.allan_gls import band, band_text, columns, Curve, curve, deg_h, gls, root_sigma
from gyroarray.analysis.noise_fit import term_basis
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.effects.fitting import as_dt, as_rate, chi2_to_z, EffectFit, nk_extra
from gyroarray.effects.gauss_markov import fit_gauss_markov

__all__ = ["fit_gyro_noise"]


# --------------------------------------------------------------------------
# Rate ramp: GLS on block means in the time domain

#: Number of block means of the rate-ramp fit.
_RAMP_BLOCKS = 256


def _ramp_terms(x: np.ndarray, dt_s: float):
    """Differences of block means Δ_j = x̄_{j+1} − x̄_j and the block length L."""
    n = x.size
    L = max(1, n // _RAMP_BLOCKS)
    nb = n // L
    return np.diff(x[:nb * L].reshape(nb, L).mean(axis=1)), L


def _ramp_loglik(d: np.ndarray, L: int, dt_s: float, n2: float, k2: float, free: bool):
    """Gaussian log-likelihood of the block-mean differences (up to a constant)
    with R estimated (``free``) or R = 0; returns (loglik, R, σ_R given K, w) with
    R = (w · d)/(L·dt): the GLS weights w of the differences (None when not ``free``)."""
    white = n2 / (dt_s * L)
    c0 = k2 * dt_s * (2.0 * L * L + 1.0) / (3.0 * L) + 2.0 * white
    c1 = k2 * dt_s * (L * L - 1.0) / (6.0 * L) - white
    band = np.zeros((2, d.size))
    band[0, 1:] = c1
    band[1, :] = c0
    try:
        chol = linalg.cholesky_banded(band, lower=False)
    except linalg.LinAlgError:
        return -math.inf, math.nan, math.nan, None
    sol = linalg.cho_solve_banded((chol, False), np.column_stack([np.ones(d.size), d]))
    logdet = 2.0 * float(np.sum(np.log(chol[-1])))
    step = L * dt_s
    if free:
        info = float(np.sum(sol[:, 0]))
        mu = float(np.sum(sol[:, 1])) / info
        r, sr, w = mu / step, 1.0 / math.sqrt(info) / step, sol[:, 0] / info
    else:
        mu, r, sr, w = 0.0, 0.0, math.nan, None
    q = float(d @ sol[:, 1]) - mu * float(np.sum(sol[:, 1]))
    return -0.5 * (logdet + q), r, sr, w


def _ramp_fit(x: np.ndarray, dt_s: float, n2: float, k2: float, k2_sigma: float):
    """Rate ramp R [rad/s²], its 1σ, the likelihood ratio of R ≠ 0 and the weights g of the
    samples with R·dt = g · x (None where R is not estimable: :func:`_walk_after_ramp`).

    Time domain, exact Gaussian likelihood of the differences of block
    means (module docstring): Δ_j = R·L·dt + an MA(1) process whose two
    autocovariances are linear in N² and K². N² comes from the Allan fit
    (short τ pin it down); K² is profiled (maximised over) under both
    hypotheses, because a short record cannot tell a random-walk drift from
    a ramp without it, and the Allan K of a short record is poor. The
    likelihood ratio is χ²(1) without a ramp.
    """
    d, L = _ramp_terms(x, dt_s)
    if d.size < 8 or not n2 > 0:
        return math.nan, math.nan, math.nan, None
    top = math.sqrt(max(k2, 0.0) + 3.0 * max(k2_sigma, 0.0))
    top = 10.0 * top if top > 0 else 10.0 * math.sqrt(n2) / (L * dt_s)

    def best(free):
        sol = optimize.minimize_scalar(lambda v: -_ramp_loglik(d, L, dt_s, n2, v * v, free)[0],
                                       bounds=(0.0, top), method="bounded",
                                       options={"xatol": 1e-3 * top})
        return _ramp_loglik(d, L, dt_s, n2, sol.x ** 2, free)

    l1, r, sr, w = best(True)
    l0 = best(False)[0]
    lr = max(2.0 * (l1 - l0), 0.0)
    if lr > 0 and r != 0:
        sr = max(sr, abs(r) / math.sqrt(lr))      # the K uncertainty widens the conditional σ
    g = None
    if w is not None:
        # R·L·dt = Σ_j w_j (x̄_{j+1} − x̄_j): block b's mean carries w_{b−1} − w_b, each of its L samples 1/L
        c = (np.concatenate([[0.0], w]) - np.concatenate([w, [0.0]])) / (L * L)
        g = np.zeros(x.size)
        g[:c.size * L] = np.repeat(c, L)
    return r, sr, lr, g


def _walk_after_ramp(g: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The expected overlapping Allan variance of a random walk with a ramp taken out, over the
    walk's own, at the averaging factors ``m``.

    The ramp taken out is ρ·i (i the sample) with ρ = g · x linear in the record x (the GLS of
    :func:`_ramp_fit`). For a unit random walk, Cov(x_a, x_b) = min(a, b) + c, so with
    h_a = Cov(x_a, ρ) = Σ_i g_i min(a, i) (Σ g = 0 drops c) and D_s the difference of the
    m-sample means at s + m and s, E[(D_s − mρ)²] = E[D_s²] − 2m·Cov(D_s, ρ) + m²·Var ρ,
    E[D_s²] = (2m² + 1)/(3m), Var ρ = Σ g_i h_i; Cov(D_s, ρ) are differences of block means of
    h, averaged over the n − 2m + 1 positions s. O(n) per factor.

    The fit reads K from the Allan variance of what is left: the ramp took out part of the walk
    (the slope it had), most at the longest τ (a Brownian bridge's K²τ/3·(1 − 3τ/(2T)) for the
    ramp read from the ends). Without this, on plain-numpy records of 20 min, N 0.5 deg/√h,
    K 30 deg/h/√h and a ramp, K read 8.0 ± 2.3 % low against the same records without it.
    """
    n = g.size
    i = np.arange(n, dtype=float)
    g0 = np.cumsum(g)
    h = np.cumsum(g * i) + i * (g0[-1] - g0)
    var_rho = float(g @ h)
    big_h = np.concatenate([[0.0], np.cumsum(h)])
    out = np.empty(len(m))
    for k, mm in enumerate(np.asarray(m, dtype=np.int64)):
        e = (big_h[2 * mm:] - 2.0 * big_h[mm:n + 1 - mm] + big_h[:n + 1 - 2 * mm]) / mm
        d2 = (2.0 * mm * mm + 1.0) / (3.0 * mm)
        out[k] = (d2 - 2.0 * mm * float(e.mean()) + mm * mm * var_rho) / d2
    return np.clip(out, 1e-3, 1.0)


def _baseline_fits(cv, base, label: str, gyro: int, common: dict) -> list[EffectFit]:
    """The ``arw`` and ``rrw`` entries: the baseline fit's N and K with their Wald ratios."""
    out: list[EffectFit] = []
    for j, (effect, key, conv, slope) in enumerate((
            ("arw", "n_deg_rt_h", units.arw_rad_rt_s_to_deg_rt_h, "−1/2"),
            ("rrw", "k_deg_h_rt_h", units.rrw_rad_s_rt_s_to_deg_h_rt_h, "+1/2"))):
        a, sa = float(base.a[j]), float(math.sqrt(base.cov[j, j]))
        p, sp = root_sigma(a, sa)
        share = columns(cv, ("n", "k"))[:, j] * max(a, 0.0) / np.maximum(base.model, 1e-300)
        where, meas, _ = band_text(cv, band(cv, share), base.model)
        out.append(EffectFit(
            effect=effect, gyro=gyro, params={key: float(conv(p))}, sigma={key: float(conv(sp))},
            z=a / sa if sa > 0 else math.inf,
            evidence=(f"{label} ADEV follows slope {slope} for {where} ({meas:.3g} deg/h): "
                      f"{'N' if j == 0 else 'K'} = {conv(p):.3g} ± {conv(sp):.2g} {_UNIT[key]}"),
            extra={"chi2": base.chi2, "dof": base.dof, **common}))
    return out


#: χ² tail probability at which the K reference fit takes its octaves as described (:func:`_rrw_reference`).
_REF_P = 1e-3

#: Wald ratio of the flicker coefficient above which the K reference fit keeps its flicker column.
_REF_FLOOR_Z = 3.0

#: The flicker (bias instability) test reads the octaves of the K reference fit (a module switch
#: for studies; per process).
_FLOOR_FROM_REFERENCE = True


def _rrw_reference(cv: Curve, names: tuple, gm_tau_s: float | None, label: str, gyro: int,
                   common: dict) -> tuple[EffectFit, EffectFit, tuple | None, Curve]:
    """The ``arw`` and ``rrw`` entries: N and K read where the slopes are, not from what the model lacks.

    ``names``: the baseline's columns. Two things make ARW + RRW alone read a
    random walk the data rule out, and both are kept out of K here:

    * a flicker floor: when the model has no ``b`` column, one is fitted beside
      N and K and kept when its Wald ratio is above :data:`_REF_FLOOR_Z` (K is
      the +1/2 slope, not a floor ARW + RRW can reach only with a random walk);
    * short-τ structure the model does not describe (a sensor's filter, a
      hump): the octaves start at the first one from which the fit's χ² has a
      tail probability above :data:`_REF_P` (never fewer than six octaves).

    The octaves end where the other fits' do, at an eighth of the record. On
    the ADIS16405 (calibrated K 185 / 296 / 265 deg/h/√h against the point ADEV
    bounds min ADEV(τ)·√(3/τ) of 42 / 141 / 152) K reads 76 ± 33 / 125 ± 43 /
    201 ± 33. On ARW + RRW records neither change almost ever acts (a flicker
    column always in would read K 12 % low with 1.7 times the scatter on 2000 s
    records of K = 20 deg/h/√h: K² is clipped at 0 more often).

    Returns the ``arw`` and ``rrw`` entries of that fit; when a flicker column was added here and
    kept, (B and its 1σ as :func:`~gyroarray.analysis.allan_gls.root_sigma` gives them [rad/s], the first τ
    [s]), else None; and the curve from the first octave used (the flicker
    test reads the same octaves: :func:`fit_gyro_noise`).
    """
    start = 0
    while True:
        sub = cv if start == 0 else replace(cv, taus=cv.taus[start:], m=cv.m[start:], y=cv.y[start:],
                                            white=None if cv.white is None else cv.white[start:],
                                            walk=None if cv.walk is None else cv.walk[start:],
                                            quant=None if cv.quant is None else cv.quant[start:],
                                            cov=cv.cov.block(start))
        used = names if "b" in names else names + ("b",)
        fit = gls(sub, used, gm_tau_s)
        if used is not names and not fit.a[-1] > _REF_FLOOR_Z * math.sqrt(fit.cov[-1, -1]):
            fit, used = gls(sub, names, gm_tau_s), names     # the floor's column only where there is one
        if fit.dof <= 0 or stats.chi2.sf(fit.chi2, fit.dof) > _REF_P or cv.m.size - start <= 6:
            break
        start += 1
    arw, rrw = _baseline_fits(sub, fit, label, gyro, common)
    rrw = replace(rrw, extra={**rrw.extra, "k_from_tau_s": float(sub.taus[0]),
                              "k_with_flicker_column": "b" in used})
    arw = replace(arw, extra={**arw.extra, "n_from_tau_s": float(sub.taus[0]),
                              "n_with_flicker_column": "b" in used})
    if used is names:
        return arw, rrw, None, sub
    return arw, rrw, (*root_sigma(float(fit.a[-1]), float(math.sqrt(fit.cov[-1, -1]))), float(sub.taus[0])), sub


#: Relative difference of the reference octaves' white level from the per-sample one below which
#: the per-sample level stands (:func:`_white_level`): the ADEV band's own width at τ = dt on a
#: record of ~1e5 samples is a few per cent; the levels a filter or a hump separate differ by
#: 15-20 % (the ADIS16405: 2.10 against 2.44 deg/√h).
_WHITE_SAME = 0.10


def _white_level(per_sample: EffectFit, reference: EffectFit, sub: Curve, cv: Curve) -> EffectFit:
    """The ``arw`` entry: the white level that reproduces the ADEV where the model describes it.

    On a record whose short τ the baseline describes (``sub is cv``) it is the
    baseline's N, as fitted from the first octave. Where a filter, lines or a
    hump shape the short τ (the octaves of the K reference fit start later),
    N is read beside K on those octaves: the per-sample level, which counts
    the lines and bumps (or misses what a filter takes away), is a different
    figure, kept in ``extra["per_sample_n_deg_rt_h"]``. On the ADIS16405's
    gyro 1 (still, 2.78 h at 100 Hz) the per-sample N is 2.10 deg/√h, the
    ADEV at τ = 1 s is 1.17 times the line it draws (a filter under 0.05 s),
    and N read from τ ≥ the reference's first octave follows the ADEV there.
    Where the two levels agree (within 3σ or :data:`_WHITE_SAME`) the per-sample
    level stands: the octaves were left for a chance χ².
    """
    if sub is cv:
        return per_sample
    key = "n_deg_rt_h"
    n_ps, s_ps = per_sample.params[key], per_sample.sigma.get(key, math.nan)
    n_ref, s_ref = reference.params[key], reference.sigma.get(key, math.nan)
    if abs(n_ref - n_ps) <= max(3.0 * math.hypot(s_ref, s_ps), _WHITE_SAME * n_ps):
        # the two levels agree: the octaves were left for a chance χ², not for a filter or a hump
        # (a pure ARW + RRW record whose first octaves failed the reference χ² by chance read N
        # 0.1046 ± 0.0011 there against 0.1004 ± 0.0003 per sample, the scenario's 0.1: the
        # model's band at τ = dt then sat above the record, an ADEV-band false alarm at z 6)
        return per_sample
    tau0 = float(sub.taus[0])
    return replace(reference, evidence=(f"{reference.evidence} (read from τ >= {tau0:.3g} s, where the "
                                        f"model describes the ADEV; per-sample level {n_ps:.3g} deg/√h)"),
                   extra={**reference.extra, "per_sample_n_deg_rt_h": n_ps,
                          "per_sample_n_sigma_deg_rt_h": s_ps})


def _with_reference_b(bi: EffectFit, ref_b: tuple | None) -> EffectFit:
    """The ``bias_instability`` entry with B read beside K in the reference fit (its z unchanged:
    the test is the baseline's). The test's own column, fitted from the first octave, reads a
    short-τ structure the model lacks as flicker (the ADIS16405's gyro 2: 55 deg/h, where its
    ADEV minimum gives 46 and the reference fit 36)."""
    if ref_b is None or not bi.z > 3.0:     # no floor seen: the test's own reading stands
        return bi
    p, sp, tau0 = ref_b
    key = "b_deg_h"
    b, sb = float(units.rad_s_to_deg_h(p)), float(units.rad_s_to_deg_h(sp))
    return replace(bi, params={key: b}, sigma={key: sb},
                   evidence=f"{bi.evidence}; read with K from τ >= {tau0:.3g} s: B = {b:.3g} ± {sb:.2g} deg/h",
                   extra={**bi.extra, "b_test_deg_h": bi.params[key]})


def _extra_column_fits(cv, base, terms: tuple, gm: tuple, gm_tau_s: float | None, label: str,
                       gyro: int, common: dict) -> list[EffectFit]:
    """The ``bias_instability`` and ``quantization`` entries: one more Allan column each."""
    out: list[EffectFit] = []
    for term, effect, key, conv, what in (
            ("b", "bias_instability", "b_deg_h", units.rad_s_to_deg_h, "flattens"),
            ("q", "quantization", "q_deg", units.rad_to_deg, "falls as τ^−1")):
        names = ("n", "k") + tuple(t for t in terms if t != term) + gm + (term,)
        if term in terms:
            f = gls(cv, names, gm_tau_s)
        else:
            f = gls(cv, names, gm_tau_s, a0=np.append(base.a, 0.0))
        a, sa = float(f.a[-1]), float(math.sqrt(f.cov[-1, -1]))
        z = a / sa
        p, sp = root_sigma(a, sa)
        g = term_basis("oadev", term, cv.taus)
        rest = columns(cv, names[:-1], gm_tau_s) @ np.maximum(f.a[:-1], 0.0)  # the rest of the fit
        share = g * max(a, sa) / (np.maximum(rest, 0.0) + g * max(a, sa))
        idx = band(cv, share)
        where, meas, pred = band_text(cv, idx, rest)
        sym = "B" if term == "b" else "Q"
        fitted = f"{sym} = {conv(p):.3g} ± {conv(sp):.2g} {_UNIT[key]}"
        if z > 3:
            evidence = (f"{label} ADEV {what} at {meas:.3g} deg/h for {where} ({fitted}); "
                        f"ARW + RRW alone predicts {pred:.3g} there")
        else:
            evidence = (f"{label} ADEV {meas:.3g} deg/h for {where} against {pred:.3g} from "
                        f"ARW + RRW: no {effect.replace('_', ' ')} seen ({fitted}, z = {z:.1f})")
        out.append(EffectFit(
            effect=effect, gyro=gyro, params={key: float(conv(p))}, sigma={key: float(conv(sp))},
            z=float(z), evidence=evidence,
            extra={"chi2": f.chi2, "dof": f.dof, **nk_extra(f),
                   "band_s": [float(cv.taus[idx[0]]), float(cv.taus[idx[-1]])],
                   "adev_deg_h": meas, "baseline_adev_deg_h": pred, **common}))
    return out


def _ramp_entry(r: float, sr: float, z_r: float, lr: float, span: float, label: str, gyro: int,
                common: dict) -> EffectFit:
    """The ``rate_ramp`` entry (time domain, signed: z from the two-sided tail)."""
    if not (math.isfinite(r) and math.isfinite(sr) and math.isfinite(z_r)):
        return EffectFit(effect="rate_ramp", gyro=gyro, params={"r_deg_h2": 0.0}, z=0.0,
                         evidence=f"{label}: rate ramp not estimable (no ARW seen)",
                         extra={"lr": lr, **common})
    r_deg = float(units.ramp_rad_s2_to_deg_h2(r))
    sr_deg = float(units.ramp_rad_s2_to_deg_h2(sr))
    drift = f"{deg_h(r * span):.3g} deg/h over the {span:.0f} s record"
    if z_r > 3:
        ev = (f"{label} rate drifts R = {r_deg:.3g} ± {sr_deg:.2g} deg/h² ({drift}); "
              f"ARW + RRW alone give a ramp of 0 ± {sr_deg:.2g}")
    else:
        ev = (f"{label} shows no rate ramp beyond ARW + RRW: R = {r_deg:.3g} ± {sr_deg:.2g} deg/h² "
              f"({drift}, z = {z_r:.1f})")
    return EffectFit(effect="rate_ramp", gyro=gyro, params={"r_deg_h2": r_deg},
                     sigma={"r_deg_h2": sr_deg}, z=float(z_r), evidence=ev,
                     extra={"lr": lr, **common})


def fit_gyro_noise(e, dt_s: float, gyro: int, *, model_terms: tuple = (),
                   gm_tau_s: float | None = None, min_tau_s: float = 0.0,
                   white_shape=None, ramp_taken_out: bool = False, quant_shape=None) -> list[EffectFit]:
    """Baseline noise and the non-baseline stochastic effects of one gyro.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual of a static record [rad/s]: output minus reference rate and
        starting bias, uniform step. n >= 256 (6 octaves up to n/8).
    dt_s : float
        Sample step [s].
    gyro : int
        1-based gyro number (labels and ``EffectFit.gyro``).
    model_terms : tuple of {"b", "q"}
        Terms the noise model already has (bias instability, quantization):
        they join ARW and RRW in the baseline every other term is tested
        against, and the EffectFit of a model term is its fit in that
        baseline (its z is then its own Wald ratio, not a test of absence).
    gm_tau_s : float, optional
        The model has a Gauss–Markov term of this correlation time [s]: it
        joins the baseline the same way (the returned ``gauss_markov`` is
        its own fit, τc refitted).
    min_tau_s : float
        Shortest averaging time of the fits [s] (the octaves start at the
        first power-of-two multiple of dt at or above it): what the model
        shapes below it (a sensor's own low-pass) is left out; never later
        than the sixth-longest octave τ (the fit needs 6).
    white_shape : callable, optional
        ``white_shape(m)``: the white term's Allan variance over N²/τ at the
        averaging factors ``m`` [-] (a sensor's own low-pass:
        :func:`~gyroarray.analysis.psd_fit.filtered_white_avar_ratio`); it
        multiplies the N² column, so N is the noise before the filter even
        where the filter still lowers the variance by a few per cent.
    quant_shape : callable, optional
        ``quant_shape(m)``: the quantization term's Allan variance over 3Q²/τ² at the averaging
        factors ``m`` [-] (a counter whose angle moves by less than a step per sample: its error
        is correlated; :meth:`~gyroarray.effects.quantization.Quantization.noise_term`); it
        multiplies the Q² column.
    ramp_taken_out : bool
        A ramp fitted by GLS was taken out of ``e`` before (a model's ``rate_ramp``): the
        random walk's column is then the walk with a ramp taken out
        (:func:`_walk_after_ramp`, with the weights of this function's own ramp estimator,
        the same GLS on block means), and no ramp is taken out here again.

    Returns
    -------
    list of EffectFit
        In this order: ``arw`` (``n_deg_rt_h``), ``rrw`` (``k_deg_h_rt_h``),
        ``bias_instability`` (``b_deg_h``), ``quantization`` (``q_deg``),
        ``rate_ramp`` (``r_deg_h2``), ``gauss_markov`` (``sigma_deg_h``,
        ``tau_s``); every parameter with its 1σ, except ``tau_s`` when the
        fitted Gauss–Markov amplitude is not positive.

    Notes
    -----
    ``arw`` and ``rrw`` are the baseline fit (N², K² by GLS on the Allan
    variance) and their z the Wald ratio of the coefficient; where the
    baseline does not describe the short τ (a filter, lines, a hump), both are
    read on the octaves from which it does (:func:`_rrw_reference`), so N is
    the white level that reproduces the ADEV at those τ, and the per-sample
    level is ``extra["per_sample_n_deg_rt_h"]`` (:func:`_white_level`). For each other
    term z ≈ N(0, 1) when the term is absent and the noise is ARW + RRW:
    ``bias_instability`` and ``quantization`` the Wald ratio Â/σ_Â of one
    more GLS column; ``rate_ramp`` the two-sided normal score of a
    time-domain likelihood ratio with K profiled; ``gauss_markov`` the score
    of the maximum over correlation times, calibrated for the scan (module
    docstring). A ramp with z > 3 is removed before the Allan fits
    (``extra["ramp_removed"]``). ``extra`` holds χ² and dof of the fit and of
    the baseline, N and K of the fit with the term (``n_deg_rt_h``,
    ``k_deg_h_rt_h`` and their ``_sigma``), the τ band of the evidence with
    the measured and the ARW + RRW ADEV there [deg/h].

    Speed: 0.03–0.10 s per gyro of 46 min at 100 Hz (276 000 samples;
    0.25–0.82 s for 8 gyros on a shared 2-core machine).
    """
    x = as_rate(e, "e", 1)
    dt = as_dt(dt_s)
    if isinstance(gyro, bool) or not isinstance(gyro, (int, np.integer)) or gyro < 1:
        raise InputError(f"gyro must be a 1-based gyro number, got {gyro!r}")
    gyro = int(gyro)
    label = f"gyro {gyro}"
    n = x.size
    m_min = 1 if not min_tau_s > dt else 2 ** int(math.ceil(math.log2(min_tau_s / dt)))
    cv = curve(x, dt, m_min=m_min, white_shape=white_shape, quant_shape=quant_shape)
    terms = tuple(t for t in ("b", "q") if t in model_terms)
    if set(model_terms) - {"b", "q"}:
        raise ValueError(f"model_terms must be a subset of ('b', 'q'), got {model_terms!r}")
    gm = () if gm_tau_s is None else ("gm",)
    base_names = ("n", "k") + terms + gm
    base = gls(cv, base_names, gm_tau_s)

    # rate ramp first (time domain); a significant ramp is removed before the
    # Allan fits, which would otherwise read it as RRW or bias instability
    r, sr, lr, g = _ramp_fit(x, dt, float(base.a[0]), float(base.a[1]), float(math.sqrt(base.cov[1, 1])))
    z_r = chi2_to_z(lr, 1) if math.isfinite(lr) else math.nan
    ramp_removed = bool(z_r > 3.0) and g is not None and not ramp_taken_out
    if (ramp_removed or ramp_taken_out) and g is not None:
        # the random walk's column as the ramp taken out leaves it (:func:`_walk_after_ramp`)
        cv = curve(x - r * dt * np.arange(n) if ramp_removed else x, dt, cov=cv.cov, m_min=m_min,
                    white_shape=white_shape, walk_shape=lambda mm: _walk_after_ramp(g, mm),
                    quant_shape=quant_shape)
        base = gls(cv, base_names, gm_tau_s)
    common = {"chi2_baseline": base.chi2, "dof_baseline": base.dof, "ramp_removed": ramp_removed}

    out = _baseline_fits(cv, base, label, gyro, common)                        # ARW, RRW
    arw_ref, out[1], ref_b, sub = _rrw_reference(cv, base_names, gm_tau_s, label, gyro, common)
    out[0] = _white_level(out[0], arw_ref, sub, cv)
    extra = _extra_column_fits(cv, base, terms, gm, gm_tau_s, label, gyro, common)  # B, Q
    if sub is not cv and _FLOOR_FROM_REFERENCE:
        # the short τ hold structure the model does not describe (a filter, a hump): the baseline
        # fitted there reads the flicker floor as random walk (the ADIS16405's gyro 1, once its
        # hump and filter are modelled: K 186, B 9.6 ± 9.6, z 0.9, while the octaves the model
        # does describe give K 74 beside a floor the model then lacks). The flicker test reads
        # the octaves the K reference fit reads; on a record the model describes (sub is cv) it
        # is the test as before. Its χ² stays the whole curve's: the rivals (a Gauss–Markov hump)
        # are compared on one curve (AIC), and the later octaves alone would always fit better.
        b_sub = _extra_column_fits(sub, gls(sub, base_names, gm_tau_s), terms, gm, gm_tau_s,
                                   label, gyro, common)[0]
        extra[0] = replace(b_sub, extra={**b_sub.extra, "chi2": extra[0].extra["chi2"],
                                         "dof": extra[0].extra["dof"], "z_from_tau_s": float(sub.taus[0])})
    out += [_with_reference_b(extra[0], ref_b), extra[1]]
    out.append(_ramp_entry(r, sr, z_r, lr, n * dt, label, gyro, common))
    out.append(fit_gauss_markov(cv, base, label, gyro, common, terms))
    return out


_UNIT = {"n_deg_rt_h": "deg/√h", "k_deg_h_rt_h": "deg/h/√h", "b_deg_h": "deg/h", "q_deg": "deg"}
