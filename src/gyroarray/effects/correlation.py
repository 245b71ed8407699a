"""``correlation``: cross-gyro correlation of the ARW and RRW noise."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import special, stats

from gyroarray.analysis.allan import edf
from gyroarray.analysis.allan_gls import columns, cov_model, cross_avar, Curve, factors, gls, solve, whitener
from gyroarray.effects.fitting import as_dt, as_rate, chi2_to_z, EffectFit, ruled_out, unchecked, z_from_log_p
from gyroarray.core.gdop import correlation_matrix
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Effect, Kind, Mixer, Param, Stage
from gyroarray.effects.terms import CorrelationTerm


def _rho_si(x):
    return float(x) if np.ndim(x) == 0 else np.asarray(x, dtype=float)


def _corr(rho, n: int, common_mode: bool, what: str) -> np.ndarray:
    """The N×N correlation matrix of a scalar ρ or a matrix (the predictor's, as simulated)."""
    if np.ndim(rho) == 0 and common_mode:
        r = float(rho)                       # e_k = √ρ c + √(1−ρ) z_k: same law, ρ = 1 allowed
        return (1.0 - r) * np.eye(n) + r * np.ones((n, n))
    try:
        return correlation_matrix(n, rho)
    except InputError as err:
        raise InputError(f"correlation {what}: {err.message}") from None


def _mixer(rho, common_mode: bool, n_gyros: int, common) -> Mixer | None:
    if np.ndim(rho) == 0 and rho == 0.0:
        return None
    if common_mode:
        return Mixer(common_rho=float(rho), common=common())
    return Mixer(chol=np.linalg.cholesky(correlation_matrix(n_gyros, rho)))


class Correlation(Effect):
    """``rho_arw`` / ``rho_rrw``: scalar ρ (equicorrelated) or N×N matrix C,
    applied to the unit draws e of ARW and to the RRW increments, so
    Σ_ij = C_ij σ_i σ_j.

    Default (``common_mode = false``): e = L z with C = L Lᵀ (Cholesky); C
    must be positive definite, so scalar ρ in (−1/(N−1), 1) — ρ = 1 is
    refused there. ``common_mode = true``: a scalar ρ in [0, 1] realised as
    one source c shared by every gyro, e_k = √ρ c + √(1−ρ) z_k (same law as
    the equicorrelated Cholesky for ρ < 1, different draws; ρ = 1 allowed).

    Fit: the correlation of the white parts and of the random-walk
    increments over every pair of gyros
    (:func:`gyroarray.effects.correlation.fit_correlation`); its two
    tests are one candidate, the larger z Šidák-corrected for 2.
    """

    name = "correlation"
    order = 15
    per_gyro = False
    stage = Stage.SHAPE
    kind = Kind.ARRAY
    stochastic = True
    reads = "noise"
    channel = "xcorr"
    scored = ("rho_arw",)
    params = (Param("rho_arw", "-", "rho_arw", _rho_si, kind="rho", required=False, default=0.0,
                    doc="ARW correlation: scalar ρ or N×N matrix"),
              Param("rho_rrw", "-", "rho_rrw", _rho_si, kind="rho", required=False, default=0.0,
                    doc="RRW correlation: scalar ρ or N×N matrix"),
              Param("common_mode", "-", "common_mode", bool, kind="flag", required=False, default=False,
                    extension=True, doc="scalar ρ realised as one common source: e = √ρ c + √(1−ρ) e_k"))
    doc = "cross-gyro correlation of the ARW and RRW noise"
    sweep_axes = ("rho_arw", "rho_rrw")

    def check(self, params, gyro, n_gyros):
        if "rho_arw" not in params and "rho_rrw" not in params:
            raise InputError("needs 'rho_arw' and/or 'rho_rrw'", column="rho_arw")
        common_mode = bool(params.get("common_mode", False))
        for key in ("rho_arw", "rho_rrw"):
            if key not in params:
                continue
            rho = params[key]
            if common_mode:
                if np.ndim(rho) != 0:
                    raise InputError("common_mode takes a scalar correlation, not a matrix", column=key)
                if not 0.0 <= rho <= 1.0:
                    raise InputError(f"with common_mode the correlation is the share of one common "
                                     f"source: must be in [0, 1], got {rho:g}", column=key)
                continue
            if np.ndim(rho) == 0 and rho == 1.0:
                raise InputError("rho = 1 has a singular covariance; for one source seen by every "
                                 "gyro set common_mode = true", column=key)
            if n_gyros is not None:
                try:
                    correlation_matrix(n_gyros, rho)
                except InputError as err:
                    raise InputError(err.message, column=key) from None

    def placeholder(self):
        return {"rho_arw": 0.0}

    def clip(self, params, n_gyros=None):
        out = super().clip(params, n_gyros)
        if n_gyros:
            lo = -1.0 / (n_gyros - 1) + 1e-6
            for k in ("rho_arw", "rho_rrw"):
                if k in out and np.ndim(out[k]) == 0:
                    out[k] = float(np.clip(out[k], lo, 0.999))
        return out

    def predictor_term(self, act, n_gyros):
        """A modifier: the N×N correlation matrices of the white and random-walk terms
        (a scalar ρ with ``common_mode`` is (1 − ρ)I + ρ11ᵀ, ρ = 1 allowed for the walk only).

        Raises
        ------
        InputError
            ``rho_arw = 1`` with ``common_mode`` (the white covariance is singular), or a
            correlation that is not one for ``n_gyros`` gyros.
        """
        p = act.p
        cm = bool(p["common_mode"])
        if cm and np.ndim(p["rho_arw"]) == 0 and float(p["rho_arw"]) == 1.0:
            raise InputError("correlation: rho_arw = 1 with common_mode makes every gyro see the "
                             "same white noise: the measurement covariance R is singular and no "
                             "estimator here is defined; use rho_arw < 1")
        return CorrelationTerm(white=_corr(p["rho_arw"], n_gyros, cm, "rho_arw"),
                               walk=_corr(p["rho_rrw"], n_gyros, cm, "rho_rrw"))

    def simulate(self, state, act, streams):
        ctx = state.ctx
        p = act.p
        cm = bool(p["common_mode"])

        def common(source):
            return lambda: streams.stream(self.name, 0, source).standard_normal(ctx.n)

        white = replace(state.white,
                        arw=_mixer(p["rho_arw"], cm, ctx.n_gyros, common(1)),
                        rrw=_mixer(p["rho_rrw"], cm, ctx.n_gyros, common(2)))
        return replace(state, white=white)

    def why_not(self, ctx):
        return "needs at least 2 gyros" if ctx.N < 2 else None

    def fit(self, ctx, gyro, E):
        return _merge(self.name, fit_correlation(ctx.Er, ctx.dt))

    def example(self, rng, n_gyros, max_rate_deg_s):
        _draw.gyro(rng, n_gyros)
        return None, {"rho_arw": _draw.u(rng, 0.15, 0.5), "rho_rrw": 0.0}


def _merge(name: str, fits: list[EffectFit]) -> EffectFit:
    """The ARW and RRW correlation tests as one candidate: the larger z, Šidák-corrected for 2."""
    by = {next(iter(f.params)): f for f in fits}
    fa, fr = by.get("rho_arw"), by.get("rho_rrw")
    zs = [f.z for f in fits if f.z is not None and np.isfinite(f.z)]
    zmax = max(zs, default=math.nan)
    if np.isfinite(zmax):
        log_p1 = float(special.log_ndtr(-zmax))
        p1 = math.exp(log_p1)
        log_p = math.log(-math.expm1(len(zs) * math.log1p(-p1))) if p1 > 1e-12 else log_p1 + math.log(len(zs))
        z = z_from_log_p(log_p)
    else:
        z = math.nan
    params = {"rho_arw": float(fa.params["rho_arw"]) if fa and "ruled_out" not in fa.extra else 0.0,
              "rho_rrw": float(fr.params["rho_rrw"]) if fr else 0.0}
    sigma = {}
    for f in fits:
        sigma.update(f.sigma)
    best = max(fits, key=lambda f: f.z if f.z is not None and np.isfinite(f.z) else -math.inf)
    evidence = best.evidence
    if fa is not None and "ruled_out" in fa.extra and best is not fa:
        evidence += f"; the ARW correlation is refused: {fa.extra['ruled_out']}"
    return EffectFit(name, None, params, sigma, z, evidence,
                     extra={"rho_arw_fit": fa.extra if fa else None,
                            "rho_rrw_fit": fr.extra if fr else None})


# -- fit ----------------------------------------------------------------------------------
# --------------------------------------------------------------------------
# Cross-gyro correlation of the ARW and RRW


#: A family (ARW, RRW) takes part in the correlation on the gyros where its
#: Allan coefficient is above this many σ.
_SEEN = 3.0


def _olkin_siotani(r: np.ndarray, pairs: list, nu: np.ndarray) -> np.ndarray:
    """Asymptotic covariance of sample correlations r_ij, r_kl of Gaussian
    data (Olkin & Siotani 1976; Pearson & Filon 1898), the pair estimates
    having ``nu`` effective degrees of freedom (covariance over √(ν_a ν_b))."""
    p = len(pairs)
    out = np.empty((p, p))
    for a, (i, j) in enumerate(pairs):
        for b, (k, l) in enumerate(pairs):
            v = (0.5 * r[i, j] * r[k, l] * (r[i, k] ** 2 + r[i, l] ** 2 + r[j, k] ** 2 + r[j, l] ** 2)
                 + r[i, k] * r[j, l] + r[i, l] * r[j, k]
                 - r[i, j] * r[i, k] * r[i, l] - r[j, i] * r[j, k] * r[j, l]
                 - r[k, i] * r[k, j] * r[k, l] - r[l, i] * r[l, j] * r[l, k])
            out[a, b] = v / math.sqrt(nu[a] * nu[b])
    return out


def _pair_correlations(cav: np.ndarray, cov, coefs: list, G: np.ndarray, pairs: list) -> tuple:
    """Per pair, the cross-covariance GLS normalised by the gyros' own coefficients: (rho, sigma
    without correlation), each shape (2, pairs) [-]."""
    rho = np.zeros((2, len(pairs)))
    s0 = np.zeros((2, len(pairs)))
    for p_, (i, k) in enumerate(pairs):
        y = cav[:, i, k]
        norm = np.array([math.sqrt(coefs[i]["n"] * coefs[k]["n"]),
                         math.sqrt(coefs[i]["k"] * coefs[k]["k"])])
        norm = np.where(norm > 0, norm, np.inf)
        # Isserlis: cov(z_i z_k, z_i' z_k') = C^ii' C^kk' + C^ik' C^ki'; summed over
        # the lags, Σ C^i C^k + Σ (C^ik)², where an auto-variance has 2 Σ C²:
        # half of covariance(); without correlation only the first term
        null = 0.5 * cov.covariance(coefs[i], other=(coefs[k], None))
        a, cov0, _ = solve(y, G, whitener(null))
        for _ in range(2):                    # Σ with the fitted cross-covariance
            cross = {"n": float(a[0]), "k": float(a[1])}
            a, _, _ = solve(y, G, whitener(null + 0.5 * cov.covariance(cross)))
        rho[:, p_] = a / norm
        s0[:, p_] = np.sqrt(np.diag(cov0)) / norm
    return rho, s0


def _family_correlation(fam: int, key: str, what: str, r: np.ndarray, sd0: np.ndarray,
                        seen: np.ndarray, pairs: list, big_n: int) -> EffectFit:
    """The entry of one family (0: ARW, 1: RRW) from the pairs' estimates r and null sigmas sd0."""
    ok = (np.isfinite(r) & np.isfinite(sd0) & (sd0 > 0)
          & np.array([seen[i, fam] and seen[k, fam] for i, k in pairs]))
    mat = np.eye(big_n)
    zmat = np.zeros((big_n, big_n))
    smat = np.zeros((big_n, big_n))
    for p_, (i, k) in enumerate(pairs):
        mat[i, k] = mat[k, i] = r[p_]
        zmat[i, k] = zmat[k, i] = chi2_to_z((r[p_] / sd0[p_]) ** 2, 1) if ok[p_] else math.nan
        smat[i, k] = smat[k, i] = (1.0 - min(r[p_] ** 2, 0.99)) * sd0[p_]
    if not ok.any():
        return EffectFit(
            effect="correlation", gyro=None, params={key: 0.0}, z=0.0,
            evidence=(f"{what} correlation not estimable: the {what[:3]} term is not seen "
                      f"(z > {_SEEN:g}) on two gyros"),
            extra={"family": key, "estimable": False, "matrix": mat.tolist(),
                   "seen": seen[:, fam].tolist()})
    w = np.where(ok, 1.0 / np.where(ok, sd0, 1.0) ** 2, 0.0)
    mean = float(np.sum(w * np.where(ok, r, 0.0)) / np.sum(w))
    sigma0 = float(1.0 / math.sqrt(np.sum(w)))
    z = chi2_to_z((mean / sigma0) ** 2, 1)
    # 1σ of the weighted mean: the pairs' covariance under equicorrelation
    # at the estimate (pairs sharing a gyro are correlated when ρ ≠ 0)
    rho_c = float(np.clip(mean, -0.99, 0.99))
    rc = np.full((big_n, big_n), rho_c)
    np.fill_diagonal(rc, 1.0)
    idx = [p_ for p_ in range(len(pairs)) if ok[p_]]
    c_os = _olkin_siotani(rc, [pairs[p_] for p_ in idx], 1.0 / sd0[idx] ** 2)
    wn = w[idx] / np.sum(w[idx])
    sigma = float(math.sqrt(max(wn @ c_os @ wn, 0.0)))
    # heterogeneity: the pairs around the common value, Fisher's (1 − ρ²)
    # at the common ρ (pairs sharing a gyro are correlated when ρ ≠ 0: a
    # guide, not an exact χ²)
    het = float(np.sum(((r[idx] - mean) / ((1.0 - min(mean ** 2, 0.99)) * sd0[idx])) ** 2))
    lo_ok = -1.0 / (big_n - 1) + 1e-3
    value = float(np.clip(mean, lo_ok, 0.999))
    rr = r[idx]
    spread = (f"pairs {rr.min():.3g} to {rr.max():.3g}" if len(idx) > 1 else "one pair")
    if z > 3:
        evidence = (f"the gyros' {what} noise is correlated: {key} = {mean:.3g} ± {sigma:.2g} "
                    f"over {len(idx)} pairs ({spread}, heterogeneity χ² = {het:.3g} for "
                    f"{len(idx) - 1} dof)")
    else:
        evidence = (f"no {what} correlation between the gyros: {key} = {mean:.3g} ± {sigma:.2g} "
                    f"over {len(idx)} pairs ({spread}, z = {z:.1f})")
    return EffectFit(
        effect="correlation", gyro=None, params={key: value}, sigma={key: sigma}, z=float(z),
        evidence=evidence,
        extra={"family": key, "estimable": True, "estimate": mean, "sigma_null": sigma0,
               "seen": seen[:, fam].tolist(),
               "matrix": mat.tolist(), "sigma_matrix": smat.tolist(), "z_matrix": zmat.tolist(),
               "heterogeneity_chi2": het, "heterogeneity_dof": len(idx) - 1})


def fit_correlation(E, dt_s: float) -> list[EffectFit]:
    """Cross-gyro correlation of the ARW and of the RRW (array-wide).

    Parameters
    ----------
    E : array_like, shape (n, N)
        Residuals of a static record [rad/s], one column per gyro, N >= 2.
    dt_s : float
        Sample step [s].

    Returns
    -------
    list of two EffectFit
        ``effect="correlation"``, ``gyro=None``: first ``{"rho_arw": ρ}``,
        then ``{"rho_rrw": ρ}`` (``extra["family"]`` says which). ρ is the
        equicorrelated (scalar) estimate, clipped to the admissible
        (−1/(N−1), 0.999); the unclipped one is ``extra["estimate"]``. Two
        entries because each has its own z; a model writer that keeps both
        must merge them into one ``correlation`` entry (array-wide effects
        appear once in a model).

    Notes
    -----
    Cross Allan covariance at octave τ, GLS on N²/τ and K²τ/3, normalised
    by each gyro's own coefficients (:mod:`gyroarray.effects.stochastic` docstring). z tests ρ ≠ 0
    (two-sided, ≈ N(0, 1) without correlation). ``extra``: ``matrix``
    (N×N, 1 on the diagonal, 0 for pairs left out), ``sigma_matrix``
    (Fisher (1 − ρ²)σ₀), ``z_matrix`` (per pair), ``sigma_null`` (σ of the
    scalar without correlation), ``heterogeneity_chi2`` / ``_dof`` (pairs
    about the scalar; a guide, pairs sharing a gyro are correlated when
    ρ ≠ 0), ``seen`` (gyros where the family's coefficient is above 3σ:
    only pairs of those are used; none: ``estimable`` False, z = 0).

    Speed: 0.23–0.40 s for 46 min × 8 gyros × 100 Hz.
    """
    X = as_rate(E, "E", 2)
    dt = as_dt(dt_s)
    n, big_n = X.shape
    if big_n < 2:
        raise InputError(f"the correlation needs at least 2 gyros, got {big_n}")
    m = factors(n)
    cov = cov_model(n, dt)
    cav = cross_avar(X, m)
    taus = m * dt
    curves = [Curve(dt_s=dt, n=n, taus=taus, m=m, y=cav[:, i, i].copy(), cov=cov)
              for i in range(big_n)]
    fits = [gls(cv, ("n", "k")) for cv in curves]
    coefs = [{"n": max(float(f.a[0]), 0.0), "k": max(float(f.a[1]), 0.0)} for f in fits]
    # a family's correlation is defined only between gyros where it is seen
    seen = np.array([[f.a[j] > _SEEN * math.sqrt(f.cov[j, j]) for j in (0, 1)] for f in fits])
    G = columns(curves[0], ("n", "k"))
    pairs = [(i, k) for i in range(big_n) for k in range(i + 1, big_n)]
    rho, s0 = _pair_correlations(cav, cov, coefs, G, pairs)
    out = [_family_correlation(fam, key, what, rho[fam], s0[fam], seen, pairs, big_n)
           for fam, key, what in ((0, "rho_arw", "ARW (short τ)"), (1, "rho_rrw", "RRW (long τ)"))]
    out[0] = _held_in_band(out[0], cav, coefs, m, taus, n, pairs, rho[0], rho[1])
    return out


#: Tail probability below which the per-τ correlations of the white band rule a single ρ_arw out [-].
P_BAND = 1e-3


def _held_in_band(fit: EffectFit, cav: np.ndarray, coefs: list, m: np.ndarray, taus: np.ndarray, n: int,
                  pairs: list, r: np.ndarray, r_walk: np.ndarray | None = None) -> EffectFit:
    """The ARW correlation refused when it does not hold across the band where it is read.

    ρ_arw is read from the cross Allan covariance at every octave through its N²/τ column: it is
    the white noise's correlation only where white noise makes the Allan variance. The check: per
    pair (i, k), at each octave τ where N²/τ is at least half of both gyros' ARW + RRW model, the
    correlation of that octave alone, ρ_τ = σ²_ik(τ)/√(σ²_ii(τ)·σ²_kk(τ)), against the model's
    at that τ, ρ̂_τ = (ρ̂_arw √(N²_i N²_k)/τ + ρ̂_rrw √(K²_i K²_k) τ/3)/√(model_ii · model_kk) (the
    walk's share there carries its own correlation ``r_walk``; without it, ρ̂_arw alone), with
    σ_τ = (1 − ρ̂_τ²)/√ν_τ (Fisher; ν_τ the overlapping ADEV's equivalent degrees of freedom
    for white noise, Greenhall's sampled EDF): χ² = Σ ((ρ_τ − ρ̂)/σ_τ)² over pairs and τ, with
    Σ (T_pair − 1) degrees of freedom. A line common to the gyros (the MPU record's 46.8 Hz in
    all three residuals) makes ρ_τ near 1 at the τ it sits in and lower elsewhere: p < P_BAND
    refuses ρ_arw, naming the τ where it differs most. Octaves are taken as independent (they
    nearly are for white noise); with fewer than 2 octaves in a pair's band it is not checked.
    """
    if not fit.extra.get("estimable", False):
        return fit
    nu = np.asarray(edf("oadev", n + 1, m, np.zeros(m.size, dtype=int)), dtype=float)
    chi2, dof, worst = 0.0, 0, None
    for p_, (i, k) in enumerate(pairs):
        if not (np.isfinite(r[p_]) and abs(r[p_]) < 1.0):
            continue
        wi = [coefs[j]["n"] / taus / np.maximum(coefs[j]["n"] / taus + coefs[j]["k"] * taus / 3.0, 1e-300)
              for j in (i, k)]
        band = (wi[0] >= 0.5) & (wi[1] >= 0.5) & (cav[:, i, i] > 0) & (cav[:, k, k] > 0)
        if np.count_nonzero(band) < 2:
            continue
        rt = cav[band, i, k] / np.sqrt(cav[band, i, i] * cav[band, k, k])
        tb = taus[band]
        rw = 0.0 if r_walk is None or not np.isfinite(r_walk[p_]) else float(np.clip(r_walk[p_], -1.0, 1.0))
        mod = [coefs[j]["n"] / tb + coefs[j]["k"] * tb / 3.0 for j in (i, k)]
        cross = (r[p_] * np.sqrt(coefs[i]["n"] * coefs[k]["n"]) / tb
                 + rw * np.sqrt(coefs[i]["k"] * coefs[k]["k"]) * tb / 3.0)
        rm = cross / np.sqrt(np.maximum(mod[0] * mod[1], 1e-300))        # the model's ρ at each τ
        st = (1.0 - rm ** 2) / np.sqrt(np.maximum(nu[band], 1.0))
        zt = (rt - rm) / st
        chi2 += float(zt @ zt)
        dof += int(band.sum()) - 1
        j = int(np.argmax(np.abs(zt)))
        if worst is None or abs(zt[j]) > worst[0]:
            worst = (abs(zt[j]), i + 1, k + 1, float(taus[band][j]), float(rt[j]), float(rm[j]),
                     float(taus[band][0]), float(taus[band][-1]))
    if dof <= 0 or worst is None:
        return unchecked(fit, "fewer than 2 octaves where white noise makes both gyros' Allan variance")
    p = float(stats.chi2.sf(chi2, dof))
    numbers = {"band_chi2": chi2, "band_dof": dof, "band_p": p}
    fit = replace(fit, extra={**fit.extra, **numbers})
    if p >= P_BAND:
        return fit
    _, gi, gk, tau, rt, rp, lo, hi = worst
    return ruled_out(fit, f"ρ_arw does not hold across the white band where it is read: octave by octave "
                          f"(τ {lo:.3g}–{hi:.3g} s) the gyros' correlation differs from one value by χ² = "
                          f"{chi2:.4g} for {dof} dof (p = {p:.2g}); gyros {gi} and {gk}: {rt:.3g} at "
                          f"τ = {tau:.3g} s against the model's {rp:.3g} there", **numbers)
