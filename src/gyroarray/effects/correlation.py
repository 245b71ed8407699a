"""``correlation``: cross-gyro correlation of the ARW and RRW noise."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import special

from gyroarray.effects.fits.effect_fit import EffectFit, z_from_log_p
from gyroarray.effects.fits.stochastic_fit import fit_correlation
from gyroarray.core.gdop import correlation_matrix
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Effect, Kind, Mixer, Param, Stage


def _rho_si(x):
    return float(x) if np.ndim(x) == 0 else np.asarray(x, dtype=float)


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
    (:func:`gyroarray.effects.fits.stochastic_fit.fit_correlation`); its two
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
    params = {"rho_arw": float(fa.params["rho_arw"]) if fa else 0.0,
              "rho_rrw": float(fr.params["rho_rrw"]) if fr else 0.0}
    sigma = {}
    for f in fits:
        sigma.update(f.sigma)
    best = max(fits, key=lambda f: f.z if f.z is not None and np.isfinite(f.z) else -math.inf)
    return EffectFit(name, None, params, sigma, z, best.evidence,
                     extra={"rho_arw_fit": fa.extra if fa else None,
                            "rho_rrw_fit": fr.extra if fr else None})
