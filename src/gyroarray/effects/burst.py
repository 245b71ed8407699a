"""``burst``: the white noise level rises over a time window."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.analysis.davar import davar
from gyroarray.core import units
from gyroarray.effects.fitting import as_dt, as_rate, EffectFit, z_from_log_p
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Effect, Kind, Param, Stage, identity


class Burst(Effect):
    """ARW variance × ``variance_ratio`` for start_s <= time_s < end_s (ARW only,
    common-mode part included).

    Fit: a change of the white level in sample-to-sample differences, its
    window by profile likelihood and the z calibrated for the scan
    (:func:`gyroarray.effects.burst.fit_burst`); it reads the whole
    record (a slow deterministic residual barely touches differences, and a
    burst may run on into the dynamic part) unless the model's noise differs
    between still and moving parts (``static_noise``). With a burst in the
    model the regressions leave its window out, and the stochastic record is
    brought back to the level outside it.
    """

    name = "burst"
    order = 17
    per_gyro = False
    stage = Stage.SHAPE
    kind = Kind.TIME
    stochastic = True
    reads = "noise"
    changes_adev = True
    channel = "window"
    params = (Param("start_s", "s", "start_s", identity, doc="window start (time_s)"),
              Param("end_s", "s", "end_s", identity, doc="window end, exclusive"),
              Param("variance_ratio", "-", "variance_ratio", identity, lo=0.0,
                    doc="ARW variance multiplier inside the window"))
    doc = "ARW variance × ratio over [start_s, end_s)"

    def check(self, params, gyro, n_gyros):
        if not params["end_s"] > params["start_s"]:
            raise InputError(f"end_s = {params['end_s']:g} must be after start_s = {params['start_s']:g}",
                             column="end_s")

    def placeholder(self):
        return {"start_s": 0.0, "end_s": 1.0, "variance_ratio": 1.0}

    def clip(self, params, n_gyros=None):
        out = super().clip(params, n_gyros)
        if "variance_ratio" in out:
            out["variance_ratio"] = max(out["variance_ratio"], 1e-6)
        return out

    def simulate(self, state, act, streams):
        t = state.ctx.time_s
        inside = (t >= act.p["start_s"]) & (t < act.p["end_s"])
        gain = np.where(inside, math.sqrt(act.p["variance_ratio"]), 1.0)
        old = state.white.arw_gain
        gain = gain if old is None else (old * gain if old.ndim == 1 else old * gain[:, None])
        return replace(state, white=replace(state.white, arw_gain=gain))

    def fit(self, ctx, gyro, E):
        if ctx.static_record:
            x, t = E[ctx.rec], ctx.t[ctx.rec]
        else:                             # not what the model leaves out to the end (a frozen gyro)
            x, t = E[:ctx.noise_end], ctx.t[:ctx.noise_end]
        # at the model's level (a noise fault in the model is no burst), but not its own
        return fit_burst(ctx.at_model_level(x, t, but=(self.name, None)), t, ctx.dt)

    def _window(self, t, entry) -> np.ndarray:
        return (t >= float(entry.params["start_s"])) & (t < float(entry.params["end_s"]))

    def exclude(self, ctx, entry):
        inside = self._window(ctx.t, entry)
        return inside if inside.any() and not inside.all() else None

    def whiten(self, ctx, entry, x, t):
        inside = self._window(t, entry)
        if not inside.any():
            return x
        x = x.copy()
        level = x[inside].mean(axis=0)
        x[inside] = level + (x[inside] - level) / math.sqrt(max(float(entry.params["variance_ratio"]), 1e-12))
        return x

    def example(self, rng, n_gyros, max_rate_deg_s):
        _draw.gyro(rng, n_gyros)
        start = _draw.u(rng, 100.0, 1700.0)
        return None, {"start_s": start, "end_s": start + _draw.u(rng, 150.0, 400.0),
                      "variance_ratio": _draw.u(rng, 2.0, 6.0)}


# -- fit ----------------------------------------------------------------------------------
# --------------------------------------------------------------------------
# Burst: a window of raised ARW variance, common to all gyros

#: Most blocks of the change-point grid, and fewest Haar samples per block.
_BURST_MAX_BLOCKS = 256
_BURST_MIN_BLOCK = 16

#: Null distribution of the grid's maximum likelihood ratio, by number of
#: blocks B: P(max LR > x) = 1 − exp(−A x^β e^{−x/2}) (:mod:`gyroarray.effects.stochastic` docstring).
_BURST_NULL = {16: (6.156, 0.282), 32: (10.359, 0.402), 64: (12.955, 0.632), 128: (21.886, 0.699),
               256: (36.757, 0.754)}


def _burst_log_p(lr: float, blocks: int) -> float:
    """log P(max LR >= lr | no burst) for a grid of ``blocks`` blocks."""
    a, beta = _BURST_NULL[blocks]
    x = max(float(lr), 1e-12)
    log_lam = math.log(a) + beta * math.log(x) - 0.5 * x
    if log_lam < -30:
        return log_lam
    return math.log(-math.expm1(-math.exp(log_lam)))


def _segment_lr(u_in, d_in, u_tot, d_tot):
    """2 Δ log-likelihood of "variance differs on a segment" against "one
    variance" for sums ``u`` of squared unit-variance normals with ``d``
    degrees of freedom (vectorised over segments)."""
    u_out, d_out = u_tot - u_in, d_tot - d_in
    with np.errstate(divide="ignore", invalid="ignore"):
        lr = (d_tot * np.log(u_tot / d_tot) - d_in * np.log(u_in / d_in)
              - d_out * np.log(u_out / d_out))
    return np.where((d_in > 0) & (d_out > 0) & (u_in > 0) & (u_out > 0), lr, -np.inf)


def _profile_boundary(cu: np.ndarray, r: int, lo: int, hi: int, other: int, moving_start: bool):
    """Best position of one boundary (Haar index in [lo, hi]) with the other
    fixed, and the posterior mean and sd of the position (flat prior, the
    profile likelihood exp(LR/2))."""
    cand = np.arange(lo, hi + 1)
    cand = cand[cand < other] if moving_start else cand[cand > other]
    if cand.size == 0:
        return other, math.nan, math.nan
    i0, i1 = (cand, np.full(cand.size, other)) if moving_start else (np.full(cand.size, other), cand)
    u_in = cu[i1] - cu[i0]
    lr = _segment_lr(u_in, (i1 - i0) * float(r), cu[-1], (cu.size - 1) * float(r))
    best = int(cand[int(np.argmax(lr))])
    w = np.exp(0.5 * (lr - lr.max()))
    w /= w.sum()
    mean = float(w @ cand)
    return best, mean, float(math.sqrt(max(w @ (cand - mean) ** 2, 0.0)))


def _within_block_kurtosis(g: np.ndarray, edges: np.ndarray) -> float:
    """Excess kurtosis of the whitened Haar differences within the blocks of the grid, ≥ 0.

    For m iid normals, E[m Σg⁴/(Σg²)²] = 3m/(m + 2) (g/|g| is uniform on the sphere), so the
    mean over blocks and columns of m Σg⁴/(Σg²)² (m + 2)/m − 3 is 0 for Gaussian noise at any
    block length; a change of variance between blocks does not move it.
    """
    k = []
    for a, b in zip(edges[:-1], edges[1:]):
        blk = g[a:b]
        m = blk.shape[0]
        s2 = np.sum(blk * blk, axis=0)
        ok = s2 > 0
        if m >= 4 and ok.any():
            k.append(m * np.sum(blk[:, ok] ** 4, axis=0) / s2[ok] ** 2 * (m + 2) / m - 3.0)
    return max(float(np.mean(np.concatenate(k))), 0.0) if k else 0.0


def _refine_boundaries(cu: np.ndarray, r: int, edges: np.ndarray, a: int, b: int,
                       blocks: int) -> tuple:
    """Both boundaries of grid window (a, b) to one Haar sample: (i0, i1, s0, s1) [Haar samples]."""
    lo0, hi0 = edges[max(a - 1, 0)], edges[min(a + 1, blocks)]
    lo1, hi1 = edges[max(b - 1, 0)], edges[min(b + 1, blocks)]
    i0, i1 = int(edges[a]), int(edges[b])
    for _ in range(3):
        i0, _, s0 = _profile_boundary(cu, r, lo0, hi0, i1, True)
        i1, _, s1 = _profile_boundary(cu, r, lo1, hi1, i0, False)
    return i0, i1, s0, s1


def _per_gyro_ratios(h: np.ndarray, i0: int, i1: int, n2: int, heavy: float) -> tuple:
    """Variance ratio of each gyro's raw Haar differences in/out of the window, and its z."""
    hi_in = np.mean(h[i0:i1] ** 2, axis=0)
    hi_out = (np.sum(h[:i0] ** 2, axis=0) + np.sum(h[i1:] ** 2, axis=0)) / max(n2 - (i1 - i0), 1)
    per_gyro = hi_in / hi_out
    per_sd = per_gyro * math.sqrt((2.0 / max(i1 - i0, 1) + 2.0 / max(n2 - (i1 - i0), 1)) / heavy)
    per_z = (per_gyro - 1.0) / per_sd
    return per_gyro, per_z


def _burst_evidence(ratio: float, s_ratio: float, start_s: float, end_s: float,
                    per_gyro: np.ndarray, per_z: np.ndarray, z: float) -> str:
    """The sentence that reports the window (or that none stands out) and the gyros it shows on."""
    up = ratio >= 1.0
    rises = f"rises {math.sqrt(ratio):.3g}×" if up else f"drops to {math.sqrt(ratio):.3g}×"
    sig = np.abs(per_z) > 3.0
    each = ", ".join(f"{k + 1} ({math.sqrt(per_gyro[k]):.3g}×)" for k in np.flatnonzero(sig))
    if sig.all():
        who = f"on all gyros: {each}"
    elif sig.any():
        rest = np.sqrt(per_gyro[~sig])
        who = (f"on gyro{'s' if sig.sum() > 1 else ''} {each}; the others "
               + (f"{rest.min():.3g}–{rest.max():.3g}×" if rest.size > 1 else f"{rest[0]:.3g}×"))
    else:
        who = "on no single gyro"
    if z > 3:
        evidence = (f"ARW {rises} (variance {ratio:.3g} ± {s_ratio:.2g}×) between {start_s:.6g} s and "
                    f"{end_s:.6g} s {who}")
    else:
        evidence = (f"no burst: the strongest change of the ARW variance, {ratio:.3g}× between "
                    f"{start_s:.6g} s and {end_s:.6g} s, is within what a record of this length "
                    f"shows by chance (z = {z:.1f})")
    return evidence


def fit_burst(E, time_s, dt_s: float) -> EffectFit:
    """Window of raised (or lowered) ARW variance common to all gyros.

    Parameters
    ----------
    E : array_like, shape (n,) or (n, N)
        Residuals of a static record [rad/s] (a single gyro works too).
    time_s : array_like, shape (n,)
        Sample times [s], uniform at ``dt_s``; ``start_s`` and ``end_s``
        are on this clock (as the simulator's ``burst``).
    dt_s : float
        Sample step [s].

    Returns
    -------
    EffectFit
        ``effect="burst"``, ``gyro=None``, params ``start_s``, ``end_s``
        (exclusive), ``variance_ratio``, each with its 1σ; the window with
        the largest likelihood ratio whether or not it is significant (z
        says). ``extra``: ``lr_grid`` (the statistic z is calibrated on),
        ``lr`` (after refinement), ``blocks``, ``block_s``,
        ``dof_per_sample``, ``per_gyro_variance_ratio``, ``per_gyro_z``,
        ``davar`` (the DAVAR cross-check: variance ratio of the ARW track of
        the most affected gyro inside/outside the window).

    Notes
    -----
    Exact two-change-point likelihood on the whitened Haar differences,
    pooled over gyros; O(n) + O(blocks²); z from the calibrated null
    distribution of the grid's maximum likelihood ratio (module
    docstring). Resolution: one Haar sample (2 dt) for the boundaries;
    bursts shorter than about two blocks (record/128) lose power.

    Speed: 0.03–0.12 s for 46 min × 8 gyros × 100 Hz (with the DAVAR check).
    """
    X = as_rate(E, "E", 2)
    dt = as_dt(dt_s)
    n = X.shape[0]
    t = np.asarray(time_s, dtype=float)
    if t.shape != (n,) or not np.all(np.isfinite(t)):
        raise InputError(f"time_s must be {n} finite values, got shape {t.shape}")
    if n > 1 and not np.allclose(np.diff(t), dt, rtol=1e-6, atol=0.0):
        raise InputError(f"time_s must be uniformly spaced at dt_s = {dt:g} s")
    n2 = n // 2
    blocks = min(_BURST_MAX_BLOCKS, 2 ** math.floor(math.log2(max(n2 // _BURST_MIN_BLOCK, 1))))
    if blocks < 16:
        raise InputError(f"{n} samples are too few for the burst search: it needs at least "
                         f"{2 * 16 * _BURST_MIN_BLOCK}")

    # Haar differences: iid N(0, 2σ²)/2 per gyro for white noise, σ² × ratio
    # inside a burst; whitened across gyros (correlated ARW), so that
    # u_j = |h̃_j|² ~ ratio_j · χ²_r
    h = (X[1:2 * n2:2] - X[0:2 * n2:2]) * math.sqrt(0.5)
    c = (h.T @ h) / n2
    lam, vec = np.linalg.eigh(c)
    keep = lam > 1e-10 * lam.max()
    r = int(np.count_nonzero(keep))
    g = h @ (vec[:, keep] / np.sqrt(lam[keep]))
    u = np.einsum("ij,ij->i", g, g)
    cu = np.concatenate([[0.0], np.cumsum(u)])

    # exact two-change-point search on the block grid (all segments but the
    # whole record), O(blocks²) after the O(n) block sums
    edges = (np.arange(blocks + 1) * n2) // blocks
    ia, ib = np.triu_indices(blocks + 1, 1)
    sel = ~((ia == 0) & (ib == blocks))
    ia, ib = ia[sel], ib[sel]
    lr = _segment_lr(cu[edges[ib]] - cu[edges[ia]], (edges[ib] - edges[ia]) * float(r),
                     cu[-1], n2 * float(r))
    # heavy tails (real noise): var(g²) = 2 + κ, not 2, so the Gaussian LR is a quasi-likelihood
    # ratio that (2 + κ)/2 inflates; κ within blocks, so that a burst's own change of level
    # (a scale mixture across blocks) does not count as a tail
    heavy = 2.0 / (2.0 + _within_block_kurtosis(g, edges))
    lr = lr * heavy
    best = int(np.argmax(lr))
    lr_grid = float(lr[best])
    z = z_from_log_p(_burst_log_p(lr_grid, blocks))
    a, b = int(ia[best]), int(ib[best])

    # refine both boundaries to one Haar sample (2 dt) within a block of the grid's
    i0, i1, s0, s1 = _refine_boundaries(cu, r, edges, a, b, blocks)
    d_in = (i1 - i0) * float(r)
    d_out = (n2 - (i1 - i0)) * float(r)
    u_in = cu[i1] - cu[i0]
    ratio = float((u_in / d_in) / ((cu[-1] - u_in) / d_out))
    s_ratio = float(ratio * math.sqrt((2.0 / d_in + 2.0 / d_out) / heavy))
    lr_final = float(_segment_lr(np.array([u_in]), np.array([d_in]), cu[-1], n2 * float(r))[0]) * heavy

    # times: Haar sample j covers samples 2j and 2j + 1
    start_s = float(t[0] + 2 * i0 * dt)
    end_s = float(t[0] + 2 * i1 * dt)
    res = dt                              # half a Haar sample: rounding and discreteness
    s_start = float(math.hypot(2.0 * dt * (s0 if math.isfinite(s0) else 0.0), res))
    s_end = float(math.hypot(2.0 * dt * (s1 if math.isfinite(s1) else 0.0), res))

    # per gyro: variance ratio of the raw Haar differences on the same window
    per_gyro, per_z = _per_gyro_ratios(h, i0, i1, n2, heavy)
    davar_check = _davar_check(X, dt, t, i0, i1, int(np.argmax(np.abs(per_z))))

    evidence = _burst_evidence(ratio, s_ratio, start_s, end_s, per_gyro, per_z, z)
    return EffectFit(
        effect="burst", gyro=None,
        params={"start_s": start_s, "end_s": end_s, "variance_ratio": ratio},
        sigma={"start_s": s_start, "end_s": s_end, "variance_ratio": s_ratio},
        z=float(z), evidence=evidence,
        extra={"lr_grid": lr_grid, "lr": lr_final, "blocks": blocks, "block_s": float(2 * dt * n2 / blocks),
               "dof_per_sample": r, "per_gyro_variance_ratio": per_gyro.tolist(),
               "per_gyro_z": per_z.tolist(), "davar": davar_check})


def _davar_check(X, dt, t, i0, i1, gyro_index) -> dict:
    """Cross-check with the dynamic Allan variance of one gyro: the mean
    ARW² of fixed windows wholly inside the fitted window over that of the
    windows wholly outside (:func:`gyroarray.analysis.davar.davar`,
    ``arw="tau0"``)."""
    n = X.shape[0]
    length = 2 * (i1 - i0)
    window = int(min(max(64, length // 4), max(64, n // 8)))
    step = max(window // 2, n // 2000, 1)
    try:
        res = davar(X[:, gyro_index], dt, window=window, step=step, taus=[dt], extension="none")
    except InputError:
        return {}
    a = res.start
    inside = (a >= 2 * i0) & (a + res.window_length <= 2 * i1)
    outside = (a + res.window_length <= 2 * i0) | (a >= 2 * i1)
    if not inside.any() or not outside.any():
        return {"gyro": gyro_index + 1, "window_s": window * dt}
    n2 = res.arw_rad_rt_s ** 2
    return {"gyro": gyro_index + 1, "window_s": window * dt,
            "variance_ratio": float(n2[inside].mean() / n2[outside].mean()),
            "arw_inside_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(math.sqrt(n2[inside].mean()))),
            "arw_outside_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(math.sqrt(n2[outside].mean())))}
