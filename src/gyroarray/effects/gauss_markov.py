"""``gauss_markov``: first-order Gauss–Markov rate noise (ADEV hump near 1.89·τc)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import optimize, special

from gyroarray.effects import _draw
from gyroarray.core.physics import gauss_markov_noise
from gyroarray.effects.protocol import NoiseTermEffect, Param, Stage, identity, with_term
from gyroarray.effects.terms import GaussMarkovTerm, spread
from gyroarray.core.units import deg_h_to_rad_s
from gyroarray.analysis.allan_gls import (avar_normal_score, band, band_text, columns, Curve, deg_h, Gls,
                                          gls, root_sigma, solve, split)
from gyroarray.core.physics import gauss_markov_avar
from gyroarray.effects.fitting import EffectFit, nk_extra, ruled_out, z_from_log_p

#: Longest correlation time a model may give [s] (about 30 years): over any record the process is
#: then a random walk (the hump sits at 1.89·τc), and beyond it τc² overflows the Allan model.
MAX_TAU_S = 1e9


class GaussMarkov(NoiseTermEffect):
    """Exact AR(1) discretisation with a stationary start (:func:`gyroarray.core.physics.gauss_markov_noise`).

    Fit: a hump of the gyro's Allan model, the correlation time scanned and
    the z calibrated for the scan (:mod:`gyroarray.effects.stochastic`).
    """

    name = "gauss_markov"
    order = 6
    stage = Stage.ADD
    rivals = ("bias_instability", "quantization")
    params = (Param("sigma_deg_h", "deg/h", "sigma_rad_s", deg_h_to_rad_s, lo=0.0, doc="stationary σ"),
              Param("tau_s", "s", "tau_s", identity, lo=0.0, lo_open=True, hi=MAX_TAU_S,
                    doc="correlation time τc"))
    doc = "first-order Gauss–Markov rate noise"

    def predictor_term(self, act, n_gyros):
        """Gauss–Markov noise: stationary σ [rad/s], correlation time τc [s]."""
        return GaussMarkovTerm(spread(act, "sigma_rad_s", n_gyros), spread(act, "tau_s", n_gyros))

    def simulate(self, state, act, streams):
        ctx = state.ctx
        z = streams.normals(self.name, act.cols, ctx.n)
        return with_term(state, act.cols,
                         gauss_markov_noise(ctx.n, ctx.dt_s, act.p["sigma_rad_s"], act.p["tau_s"], z))

    def noise_term(self, ctx, entry):
        return {"gm_tau_s": float(entry.params["tau_s"])}

    def entry_params(self, fit, old):
        params = super().entry_params(fit, old)
        if params.get("sigma_deg_h", 0.0) <= 0:
            params["sigma_deg_h"] = 0.0
        return params

    def free_parameters(self, fit):
        return 2

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"sigma_deg_h": _draw.u(rng, 50.0, 300.0, True),
                                          "tau_s": _draw.u(rng, 0.2, 20.0, True)}


# -- fit ----------------------------------------------------------------------------------
# --------------------------------------------------------------------------
# Gauss-Markov: profile over the correlation time

#: Correlation times scanned per octave, and the Monte Carlo draws that
#: calibrate the maximum over them.
_GM_PER_OCTAVE = 4
_GM_DRAWS = 10000


def _max_calibration(c: np.ndarray, seed: int = 20240601) -> np.ndarray:
    """Simulated maxima of the standardised statistics c_gᵀ z (z ~ N(0, I)),
    columns of ``c`` normalised: the null distribution of a one-sided scan."""
    rng = np.random.default_rng(seed)
    cn = c / np.linalg.norm(c, axis=0)
    return np.sort((rng.standard_normal((_GM_DRAWS, c.shape[0])) @ cn).max(axis=1))


def _scan_log_p(w_obs: float, maxima: np.ndarray) -> tuple[float, float]:
    """log of the one-sided p-value of a scan maximum, and the effective
    number of tests M (from the 99th percentile q of the simulated maxima,
    M = 0.01/Φ̄(q)).

    Where the Monte Carlo has fewer than 20 exceedances the Šidák form
    p = 1 − (1 − Φ̄(w))^M is used instead (its far tail M·Φ̄(w)).
    """
    q99 = maxima[int(0.99 * maxima.size)]
    m_eff = 0.01 / special.ndtr(-q99)
    count = maxima.size - np.searchsorted(maxima, w_obs, side="left")
    if count >= 20:                        # mid-p: finite z when every draw exceeds w
        return math.log((count + 0.5) / (maxima.size + 1.0)), m_eff
    log_tail = float(special.log_ndtr(-w_obs))
    if log_tail > -30:
        return math.log(-math.expm1(m_eff * math.log1p(-math.exp(log_tail)))), m_eff
    return math.log(m_eff) + log_tail, m_eff


def _gm_grid(cv: Curve) -> np.ndarray:
    """Correlation times scanned: 4·dt .. τ_max/2, ``_GM_PER_OCTAVE`` per octave."""
    lo = 4.0 * cv.dt_s
    hi = 0.5 * cv.taus[-1]
    count = max(2, round(_GM_PER_OCTAVE * math.log2(hi / lo)) + 1)
    return np.geomspace(lo, hi, count)


def _gm_stat(cv: Curve, white: np.ndarray, tau_c: float, terms: tuple = ()) -> tuple[float, np.ndarray]:
    """Standardised GM amplitude â/σ_â (columns n, k, the model's ``terms``,
    gm at ``tau_c``, fixed whitener) and its weight vector in the whitened
    space (unit norm)."""
    xw = white @ columns(cv, ("n", "k") + tuple(terms) + ("gm",), tau_c)
    s = np.linalg.norm(xw, axis=0)
    xs = xw / s
    try:
        inv = np.linalg.inv(xs.T @ xs)
    except np.linalg.LinAlgError:
        inv = np.linalg.pinv(xs.T @ xs)
    c = xs @ inv[:, -1]                      # â·s = cᵀ ỹ, var = ‖c‖²
    norm = float(np.linalg.norm(c))
    return float(c @ (white @ cv.y)) / norm, c / norm


def _refine_tau(cv: Curve, white: np.ndarray, lo: float, hi: float, terms: tuple = ()) -> float:
    """τc maximising the standardised GM amplitude with a fixed whitener."""
    sol = optimize.minimize_scalar(lambda u: -_gm_stat(cv, white, math.exp(u), terms)[0],
                                   bounds=(math.log(lo), math.log(hi)), method="bounded",
                                   options={"xatol": 1e-3})
    return float(math.exp(sol.x))


def _gm_covariance(cv: Curve, fit: Gls, tau_c: float, terms: tuple = ()) -> np.ndarray:
    """Covariance of (N², K², the model's terms, σ², ln τc) from the whitened Jacobian."""
    h = 1e-4
    g_up = gauss_markov_avar(cv.taus, 1.0, tau_c * math.exp(h), cv.dt_s)
    g_dn = gauss_markov_avar(cv.taus, 1.0, tau_c * math.exp(-h), cv.dt_s)
    jac = np.column_stack([columns(cv, ("n", "k") + tuple(terms) + ("gm",), tau_c),
                           max(fit.a[-1], 0.0) * (g_up - g_dn) / (2 * h)])
    jw = fit.white @ jac
    s = np.linalg.norm(jw, axis=0)
    s = np.where(s > 0, s, 1.0)
    xs = jw / s
    return np.linalg.pinv(xs.T @ xs) / np.outer(s, s)


#: The Gauss–Markov scan's z reads the Allan variances made Gaussian (:func:`_gaussianised`).
_GAUSSIANISE = True


def _gaussianised(cv: Curve, base: Gls, names: tuple) -> np.ndarray:
    """The curve's Allan variances made Gaussian (:func:`~gyroarray.analysis.allan_gls.avar_normal_score`) about the baseline
    fit, each octave's degrees of freedom from the fit's covariance model (ν = 2μ²/var).

    Null study (benchmarks/gm_null_tail.py, 3000 plain-numpy records of ARW + RRW each): the
    scan's z exceeded 3.5 on 0.20 % / 0.07 % of records (2400 s / 1200 s; a normal z: 0.023 %),
    now on 0.03 % / 0 %; a short hump is found as before (σ = 6 deg/h, τc = 1 s: z > 3.5 on
    99.3 % of records, median z 8.2 -> 7.4)."""
    coef, _ = split(names, base.a, None)
    var = np.diag(cv.cov.covariance(coef, None))
    mu = np.maximum(base.model, 1e-300)
    nu = np.maximum(2.0 * mu ** 2 / np.maximum(var, 1e-300), 1.0)
    return avar_normal_score(cv.y, mu, nu)


def fit_gauss_markov(cv: Curve, base: Gls, label: str, gyro, common: dict,
                      terms: tuple = ()) -> EffectFit:
    grid = _gm_grid(cv)
    stats = np.empty(grid.size)
    vecs = np.empty((cv.taus.size, grid.size))
    names = ("n", "k") + tuple(terms) + ("gm",)
    j = len(names) - 1                      # index of the GM amplitude
    for i, tc in enumerate(grid):
        stats[i], vecs[:, i] = _gm_stat(cv, base.white, tc, terms)
    maxima = _max_calibration(vecs)
    i = int(np.argmax(stats))
    # the scan's z reads each octave's Allan variance made Gaussian (same weights vecs: they
    # depend on the columns and Σ only); the estimate below starts from the plain scan's best τc
    yg = base.white @ _gaussianised(cv, base, names[:-1]) if _GAUSSIANISE else base.white @ cv.y
    log_p, m_eff = _scan_log_p(float(np.max(vecs.T @ yg)), maxima)
    z = z_from_log_p(log_p)

    # the estimate: τc refined between the neighbours of the best grid point,
    # then the covariance from the fitted model, then τc again
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    tc = _refine_tau(cv, base.white, lo, hi, terms)
    f = gls(cv, names, tc, n_iter=2, a0=np.append(base.a[:j], 0.0))
    tc = _refine_tau(cv, f.white, max(tc / 2.0, grid[0]), min(tc * 2.0, grid[-1]), terms)
    # final coefficients at the refined τc with the same Sigma (τc moved
    # little; a new Gauss-Markov covariance profile costs 30 ms)
    a_new, cov_a, chi2 = solve(cv.y, columns(cv, names, tc), f.white)
    f = Gls(a=a_new, cov=cov_a, chi2=chi2, dof=f.dof, white=f.white,
             model=columns(cv, names, tc) @ a_new)
    cov = _gm_covariance(cv, f, tc, terms)
    a, sa = float(f.a[j]), float(math.sqrt(max(cov[j, j], 0.0)))
    s, ss = root_sigma(a, sa)
    params = {"sigma_deg_h": float(deg_h(s)), "tau_s": float(tc)}
    sigma = {"sigma_deg_h": float(deg_h(ss))}
    if a > 0 and cov[j + 1, j + 1] > 0:
        sigma["tau_s"] = float(tc * math.sqrt(cov[j + 1, j + 1]))
    g = gauss_markov_avar(cv.taus, 1.0, tc, cv.dt_s)
    rest = columns(cv, names[:-1]) @ np.maximum(f.a[:j], 0.0)
    share = g * max(a, sa) / (np.maximum(rest, 0.0) + g * max(a, sa))
    idx = band(cv, share)
    where, meas, pred = band_text(cv, idx, rest)
    peak: dict = {}
    fitted = (f"σ = {params['sigma_deg_h']:.3g} ± {sigma['sigma_deg_h']:.2g} deg/h, τc = {tc:.3g}"
              + (f" ± {sigma['tau_s']:.2g} s" if "tau_s" in sigma else " s"))
    if z > 3 and not a > 0:
        # the scan's score (against the baseline's Σ) sees an excess, but refitted with the hump's
        # own Σ the amplitude is not positive: the excess is not of this shape, and the hump is
        # not a candidate (its z becomes the refitted amplitude's Wald ratio, <= 0)
        evidence = (f"{label} ADEV exceeds ARW + RRW ({meas:.3g} against {pred:.3g} deg/h for {where}; "
                    f"scan z = {z:.1f}), but a Gauss–Markov hump does not fit it: its σ² comes out "
                    f"<= 0 ({fitted})")
        z = a / sa if sa > 0 else 0.0
    elif z > 3:
        # read at the hump's peak (the octave nearest 1.89·τc): a band average mixes τ where the
        # rest of the fit is above the data with τ where it is below
        k = int(np.argmin(np.abs(np.log(cv.taus / (1.89 * tc)))))
        at = (float(deg_h(math.sqrt(cv.y[k]))), float(deg_h(math.sqrt(max(rest[k], 0.0)))),
              float(deg_h(math.sqrt(max(rest[k] + max(a, 0.0) * g[k], 0.0)))))
        peak = {"peak_tau_s": float(cv.taus[k]), "peak_adev_deg_h": at[0], "peak_rest_adev_deg_h": at[1],
                "peak_model_adev_deg_h": at[2]}
        evidence = (f"{label} ADEV has a hump near 1.9·τc = {1.89 * tc:.3g} s: {at[0]:.3g} deg/h at "
                    f"τ = {cv.taus[k]:.3g} s, where the fit's ARW + RRW give {at[1]:.3g} and with the "
                    f"hump {at[2]:.3g} ({fitted}; {where})")
    else:
        evidence = (f"{label} ADEV shows no Gauss–Markov hump: best τc = {tc:.3g} s gives {fitted} "
                    f"(z = {z:.1f} after the scan over {grid.size} correlation times)")
    out = EffectFit(effect="gauss_markov", gyro=gyro, params=params, sigma=sigma, z=float(z),
                    evidence=evidence,
                    extra={"chi2": f.chi2, "dof": f.dof, **nk_extra(f), "scan_max": float(stats[i]),
                           "n_eff_tests": float(m_eff),
                           "tau_grid_s": [float(grid[0]), float(grid[-1])],
                           "band_s": [float(cv.taus[idx[0]]), float(cv.taus[idx[-1]])],
                           "adev_deg_h": meas, "baseline_adev_deg_h": pred, **peak, **common})
    return cap_by_adev(out, cv, f, names, tc)


#: Peak of a first-order Gauss–Markov ADEV over its stationary σ, and where it is (τ/τc) [-]:
#: the maximum of g(x) = (2/x)·[1 − (3 − 4e^{−x} + e^{−2x})/(2x)], σ²_A(τ) = σ²·g(τ/τc).
GM_PEAK_ADEV_OVER_SIGMA, GM_PEAK_X = 0.61736, 1.8926

#: One-sided tail of the measured Allan variance's upper bound in :func:`cap_by_adev` [-] (3σ).
ADEV_BOUND_TAIL = 0.00135


def gm_sigma_bound(cv: Curve, nu, tau_c: float) -> tuple[float, float]:
    """The largest σ of a Gauss–Markov process of correlation time ``tau_c`` that the measured
    Allan variance allows, and the τ that sets it.

    Parameters
    ----------
    cv : Curve
        The measured Allan variance at octave τ [(rad/s)²].
    nu : array_like, shape (T,)
        Equivalent degrees of freedom of each estimate [-].
    tau_c : float
        Correlation time [s].

    Returns
    -------
    (float, float)
        σ_max [rad/s] and the τ where it is set [s].

    Notes
    -----
    A GM's Allan variance is σ²·g(τ/τc) with g the sampled form of
    (2/x)·[1 − (3 − 4e^{−x} + e^{−2x})/(2x)] (:func:`~gyroarray.core.physics.gauss_markov_avar`),
    largest at x = 1.8926, where √g = 0.6174: the hump's ADEV peak is 0.617·σ (0.437·√(q_c·τc) in
    terms of the driving density q_c = 2σ²/τc). No other term of the record can make its ADEV
    smaller than the GM's own, so at every τ

        σ²·g(τ/τc) <= σ²_A,up(τ) = σ̂²_A(τ)·ν/χ²_ν(ADEV_BOUND_TAIL)

    and σ_max = min over τ of √(σ²_A,up/g).
    """
    g1 = gauss_markov_avar(cv.taus, 1.0, tau_c, cv.dt_s)
    nu = np.maximum(np.asarray(nu, dtype=float), 1.0)
    up = cv.y * nu / special.chdtri(nu, 1.0 - ADEV_BOUND_TAIL)
    ratio = np.where(g1 > 0, up / np.maximum(g1, 1e-300), np.inf)
    k = int(np.argmin(ratio))
    return float(math.sqrt(max(ratio[k], 0.0))), float(cv.taus[k])


def cap_by_adev(fit: EffectFit, cv: Curve, f: Gls, names: tuple, tau_c: float) -> EffectFit:
    """``fit`` refused when its σ is beyond what the record's own ADEV allows (issue 44: the MPU
    record's gyro 3 σ of 6.1e5 deg/h).

    Parameters
    ----------
    fit : EffectFit
        The Gauss–Markov fit.
    cv : Curve
        The Allan variance it was fitted on.
    f : Gls
        The fit (its model gives each estimate's degrees of freedom, ν = 2μ²/var).
    names : tuple
        The fit's columns.
    tau_c : float
        Its correlation time [s].

    Returns
    -------
    EffectFit
        With ``extra["sigma_max_deg_h"]``; refused when σ − 3σ_σ > σ_max (:func:`gm_sigma_bound`).
    """
    coef, gm = split(names, f.a, tau_c)
    try:
        var = np.diag(cv.cov.covariance(coef, gm))
    except (ValueError, FloatingPointError):
        return fit
    mu = np.maximum(np.asarray(f.model, dtype=float), 1e-300)
    nu = 2.0 * mu ** 2 / np.maximum(var, 1e-300)
    s_max, at_tau = gm_sigma_bound(cv, nu, tau_c)
    smax_deg_h = float(deg_h(s_max))
    s, ss = float(fit.params["sigma_deg_h"]), float(fit.sigma.get("sigma_deg_h", 0.0))
    numbers = {"sigma_max_deg_h": smax_deg_h, "sigma_max_at_tau_s": at_tau}
    fit = replace(fit, extra=dict(fit.extra, **numbers))
    if s - 3.0 * ss <= smax_deg_h:
        return fit
    k = int(np.argmin(np.abs(cv.taus - at_tau)))
    return ruled_out(fit, f"a Gauss–Markov σ of {s:.3g} deg/h (τc = {tau_c:.3g} s) would put "
                          f"{s * math.sqrt(float(gauss_markov_avar(np.array([at_tau]), 1.0, tau_c, cv.dt_s)[0])):.3g} "
                          f"deg/h into the ADEV at τ = {at_tau:.3g} s, where the record's own ADEV is "
                          f"{float(deg_h(math.sqrt(cv.y[k]))):.3g} deg/h (its 3σ upper bound caps σ at "
                          f"{smax_deg_h:.3g} deg/h)", **numbers)
