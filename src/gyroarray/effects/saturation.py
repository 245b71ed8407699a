"""``saturation``: the output clipped at ±range."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import special, stats

from gyroarray.core.units import rad_s_to_deg_s
from gyroarray.effects.fitting import as_vector, EffectFit, logp_to_z, num, pm, Z_EVIDENT
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, with_cols
from gyroarray.core.units import RAD_PER_DEG, deg_s_to_rad_s


class Saturation(RegressionEffect):
    """np.clip of the output at ±range: the last stage before faults.

    Fit: the plateau where the reference exceeds the range
    (:func:`gyroarray.effects.saturation.fit_saturation`). Its ranking score is
    the χ² the plateau explains, Σ (y − u)²/r where the reference is beyond
    it: a clipped output makes a scale factor look huge too. With a clip in
    the model the noise is read on the static part (no noise on a plateau).
    """

    name = "saturation"
    order = 14
    stage = Stage.SATURATE
    needs = frozenset({"ref", "motion"})
    model_needs = frozenset({"ref"})      # calibrated: the clip is read against the reference rate
    static_noise = "the model clips the output (no noise on the plateau)"
    channel = "rate"
    params = (Param("range_deg_s", "deg/s", "range_rad_s", deg_s_to_rad_s, lo=0.0, lo_open=True,
                    doc="output clipped at ±range"),)
    doc = "output clipped"

    def simulate(self, state, act, streams):
        r = act.p["range_rad_s"]
        return with_cols(state, act.cols, np.clip(state.x[:, act.cols], -r, r))

    def regress(self, ctx, gyro, e, r, q):
        u = ctx.ref @ ctx.H[gyro - 1]
        f = fit_saturation(u + e, u, r, gyro, use=ctx.use)
        if np.isfinite(f.z) and f.z >= 3.0:
            c = float(f.params["range_deg_s"]) * RAD_PER_DEG
            beyond = np.abs(u) > c + 3.0 * math.sqrt(r)
            z_eq = math.sqrt(float(np.sum(e[beyond] ** 2)) / r)
            f = replace(f, z=max(float(f.z), z_eq), extra={**f.extra, "z_plateau": float(f.z)})
        return f

    def predict(self, ctx, entry):
        """The clip acts on the input plus the gyro's bias b: on the plateau the residual is b, not 0."""
        truth = ctx.ref if ctx.ref is not None else np.zeros((ctx.n, 3))
        g = entry.gyro - 1
        a, b = ctx.longest
        u = truth @ ctx.H[g] + float(np.mean(ctx.E0[a:b, g]))
        c = float(entry.params["range_deg_s"]) * RAD_PER_DEG
        out = np.zeros((ctx.n, ctx.N))
        out[:, g] = np.clip(u, -c, c) - u
        return out

    def silent(self, ctx, entry):
        """The samples at the clip: the output sits on its full-scale code, no noise on it."""
        g = entry.gyro - 1
        c = float(entry.params["range_deg_s"]) * RAD_PER_DEG
        out = np.zeros((ctx.n, ctx.N), bool)
        out[:, g] = np.abs(ctx.y[:, g]) >= c * (1.0 - 1e-9)
        return out if out.any() else None

    def example(self, rng, n_gyros, max_rate_deg_s):
        g = _draw.gyro(rng, n_gyros)
        return g, {"range_deg_s": _draw.u(rng, 0.5, 0.85) * float(max_rate_deg_s[g - 1])}


# -- fit ----------------------------------------------------------------------------------
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
    z = logp_to_z(_log_chi2_cdf(x, nu))
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
    return logp_to_z(log_p), at_p, at_m, delta


def _saturation_evidence(gyro: int, z: float, rng: float, rng_s: float, count: int, frac: float,
                         spread: float, extra: dict) -> str:
    """The sentence that reports the plateau (or its absence)."""
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} output sits at ±{pm(rng, rng_s)} deg/s on {count} samples "
              f"({num(100 * frac, 2)} %) where the reference is beyond it (up to "
              f"{num(extra['u_max_deg_s'], 4)} deg/s), spread {num(spread, 2)} deg/s against "
              f"a noise σ of {num(extra['arw_sigma_deg_s'], 2)} deg/s: clipped")
    else:
        ev = (f"gyro {gyro} output beyond ±{num(rng, 4)} deg/s spreads {num(spread, 2)} deg/s, "
              f"like its noise σ {num(extra['arw_sigma_deg_s'], 2)} deg/s: no plateau (z = {z:.1f})")
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
    u = as_vector(u_rad_s, n, "u_rad_s")
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
              f"(max |output| {num(rng, 4)} deg/s, reference up to {num(extra['u_max_deg_s'], 4)} deg/s)")
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
