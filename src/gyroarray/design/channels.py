"""The fast channel model of the design search: per cone angle and body axis, the noise
levels of one estimator's fused channel (SI, per sample), the channel filters' unit responses
(:class:`_FilterBank`) and the window moments they give.

With weights built for the true noise (:func:`channel_levels`, the single-ρ search) or fixed at a
design ρ and run on another (:func:`fixed_channels`, the decision).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyroarray.core import units
from gyroarray.core.constants import G0_M_S2
from gyroarray.core.gdop import correlation_matrix
from gyroarray.design.predict import (AXES, channel_filter,
                                      channel_response, g_sensitivity_error, settle_start, swing_truth)
from gyroarray.effects.model import NoiseModel
from gyroarray.effects.names import ARW, BIAS_INSTABILITY, G_SENSITIVITY, RRW
from gyroarray.design.gyro_noise import (GyroNoise, kept_covariances, kept_levels)
from gyroarray.design.search_space import weight_kind, DesignSpace, design_tags, design_weights


def channel_weights(kind: str | None, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Per-sample weights M (G, 3, N) of a stack of layouts H (G, N, 3); ``kind`` one of
    gls, ols, naive (None, a plugin's weights read from its fitted system, is not built here)."""
    if kind == "gls":
        rih = np.linalg.solve(R[None], H)                            # R⁻¹ H
        return np.linalg.solve(np.einsum("gni,gnj->gij", H, rih), np.swapaxes(rih, 1, 2))
    if kind == "ols":
        return np.linalg.solve(np.einsum("gni,gnj->gij", H, H), np.swapaxes(H, 1, 2))
    if kind == "naive":
        return np.swapaxes(H, 1, 2) / np.sum(H * H, axis=1)[:, :, None]
    raise ValueError(f"no per-sample weights of kind {kind!r} (a plugin's are read from its fitted system)")


@dataclass
class Channels:
    """Per α and axis: the channel's noise levels for one estimator (SI, per sample)."""

    white: np.ndarray          # (G, 3)
    walk: np.ndarray
    flicker: np.ndarray        # B² per axis
    gm: np.ndarray
    ratio: np.ndarray | None   # kf_array: q/r the filter is designed for (G, 3)
    decoupled: bool
    kf_single_ratio: float = 0.0   # kf_single: q/r of one gyro
    bias: np.ndarray | None = None  # fixed weights: max |M H − I| per layout (≠ 0: biased by the motion)


def channel_levels(est: str, H: np.ndarray, g: GyroNoise, dt: float) -> Channels:
    N = H.shape[1]
    s2 = units.arw_deg_rt_h_to_rad_rt_s(g.arw_deg_rt_h) ** 2 / dt
    q = units.rrw_deg_h_rt_h_to_rad_s_rt_s(g.rrw_deg_h_rt_h) ** 2 * dt
    ca, cr = correlation_matrix(N, g.rho_arw), correlation_matrix(N, g.rho_rrw)
    R, Qb = s2 * ca, q * cr
    kind = weight_kind(est)
    M = channel_weights(kind, H, R)
    white = np.einsum("gai,ij,gaj->ga", M, R, M)
    walk = np.einsum("gai,ij,gaj->ga", M, Qb, M)
    m2 = np.sum(M * M, axis=2)
    b2 = np.einsum("gai,ij,gaj->ga", M, correlation_matrix(N, g.rho_bi_value), M) * units.deg_h_to_rad_s(g.bi_deg_h) ** 2
    gm = m2 * units.deg_h_to_rad_s(g.gm_sigma_deg_h) ** 2
    ratio, decoupled = None, True
    if est == "kf_array":
        ratio = walk / white
        # decoupled: whitened axes orthogonal and eigenvectors of the whitened bias covariance
        L = np.linalg.cholesky(R)
        ht = np.linalg.solve(L[None], H)
        qt = np.linalg.solve(L, np.linalg.solve(L, Qb).T)
        gram = np.einsum("gni,gnj->gij", ht, ht)
        off = np.abs(gram - np.einsum("gii->gi", gram)[:, :, None] * np.eye(3))
        qh = np.einsum("nm,gmi->gni", qt, ht)
        resid = qh - ht * (np.einsum("gni,gni->gi", ht, qh) / np.einsum("gni,gni->gi", ht, ht))[:, None, :]
        scale = np.max(np.abs(gram), axis=(1, 2))
        ok = np.isfinite(scale) & (scale > 0)
        decoupled = bool(np.all(off[ok] <= 1e-9 * scale[ok, None, None])
                         and np.all(np.abs(resid[ok]) <= 1e-9 * (np.max(np.abs(qt)) * np.sqrt(scale[ok]))[:, None, None]))
    return Channels(white, walk, b2, gm, ratio, decoupled)


class _FilterBank:
    """Channel filters and unit responses, built on demand and cached."""

    def __init__(self, space: DesignSpace, gm_tau_s: float, bi: bool):
        self.space = space
        self.n = space.n_samples
        self.k0 = settle_start(self.n, space.dt_s, space.settle_s)
        self.gm_tau = gm_tau_s if gm_tau_s > 0 else None
        self.bi = bi
        self.motion: np.ndarray | None
        if space.motion is not None:
            self.motion = np.asarray(space.motion, dtype=float)[:self.n]
        elif space.swing is not None:
            self.motion = swing_truth(space.swing, self.n, space.dt_s)
        else:
            self.motion = None
        self.swing_hz = None if space.swing is None else space.swing.frequency_hz
        self._cache: dict = {}

    def get(self, kind: str, bw: float | None, ratio: float | None = None):
        key = (kind, None if bw is None else float(bw), None if ratio is None else float(f"{ratio:.12g}"))
        if key not in self._cache:
            sys = channel_filter(kind, self.space.dt_s, bw, ratio)
            self._cache[key] = None if sys is None else channel_response(
                sys, self.space.dt_s, self.n, self.k0, bi=self.bi, gm_tau_s=self.gm_tau,
                motion=self.motion, swing_hz=self.swing_hz, sensor=self.space.sensor(),
                flicker_model=self.space.flicker_model)
        return self._cache[key]


def _filter_kind(est: str) -> str:
    """The filter on the fused channel of ``est`` (its design tags' ``channel_filter``)."""
    return design_tags(est).channel_filter


@dataclass
class _Moments:
    """Per axis: the window moments of one design (SI) and its objective."""

    ms: np.ndarray             # (..., 3)
    sumw: np.ndarray
    sumf: np.ndarray


def combine_moments(ch: Channels, sel, resp) -> _Moments:
    """Moments per axis of the channels ``sel`` (index into α) through the responses
    ``resp`` (one ChannelResponse per axis, or None: infeasible)."""
    out = []
    for part in range(3):
        v = np.zeros(ch.white[sel].shape)
        for a in range(3):
            r = resp[a]
            if r is None:
                v[..., a] = np.inf
                continue
            v[..., a] = (ch.white[sel][..., a] * r.white[part] + ch.walk[sel][..., a] * r.walk[part]
                         + ch.flicker[sel][..., a] * r.flicker[part]
                         + ch.gm[sel][..., a] * r.gauss_markov[part])
        out.append(v)
    return _Moments(*out)


def add_motion(m: _Moments, resp) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Total ms, mean² over the window and sum² over the run per axis (noise + motion)."""
    ms, sumw2, sumf2 = m.ms.copy(), m.sumw.copy(), m.sumf.copy()
    for a in range(3):
        r = resp[a]
        if r is None or r.motion is None:
            continue
        mms, msw, msf = r.motion
        ms[..., a] += mms[a]
        sumw2[..., a] += msw[a] ** 2
        sumf2[..., a] += msf[a] ** 2
    return ms, sumw2, sumf2


#: The swing-response keys of a design's prediction: total, then its two factors.
_SPLIT_KEYS = ("amplitude_ratio", "phase_deg", "estimator_amplitude_ratio", "estimator_phase_deg",
               "sensor_amplitude_ratio", "sensor_phase_deg")


def _split(r) -> dict:
    """The swing response of a channel (None at rest): total, estimator's and sensor's."""
    return {k: getattr(r, k) for k in _SPLIT_KEYS}


def predicted_axes(ms: np.ndarray, sumw2: np.ndarray, sumf2: np.ndarray, ch: Channels, resp,
                    space: DesignSpace) -> dict:
    """Per axis the prediction of one design (JSON units) from its window moments (SI: mean
    square [rad²/s²], squared window and run sums; :func:`add_motion`) and channels: RMS,
    standard deviation and mean of the rate error [deg/s], the angle at the horizon [deg], the
    long-τ ARW [deg/√h] and RRW [deg/h/√h] through the DC gain, and the swing response.

    The one place of this loop: the single-ρ search's designs and the decision's."""
    n, dt = space.n_samples, space.dt_s
    nw = n - settle_start(n, dt, space.settle_s)
    mean2 = sumw2[0] / nw ** 2
    var = nw / (nw - 1.0) * (ms[0] - mean2)
    to = units.rad_s_to_deg_s
    pred = {}
    for a, ax in enumerate(AXES):
        r = resp[a]
        pred[ax] = {"rms_deg_s": float(to(math.sqrt(ms[0, a]))),
                    "std_deg_s": float(to(math.sqrt(max(var[a], 0.0)))),
                    "mean_deg_s": float(to(math.sqrt(mean2[a]))),
                    "angle_deg_at_horizon": float(units.rad_to_deg(dt * math.sqrt(sumf2[0, a]))),
                    "arw_long_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(
                        abs(r.dc_gain) * math.sqrt(ch.white[0, a] * dt))),
                    "rrw_long_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(
                        abs(r.dc_gain) * math.sqrt(ch.walk[0, a] / dt))),
                    "dc_gain": r.dc_gain, **_split(r)}
    return pred


def prediction_axes(p) -> dict:
    """Per axis the prediction of one design (JSON units, the keys of :func:`predicted_axes`)
    from a full :class:`~gyroarray.design.predict.Prediction` ``p``."""
    pred = {}
    for a in AXES:
        v = p.axes[a]
        pred[a] = {"rms_deg_s": v["rms_deg_s"], "std_deg_s": v["std_deg_s"], "mean_deg_s": v["mean_deg_s"],
                   "angle_deg_at_horizon": v["angle_deg"], "arw_long_deg_rt_h": v["arw_long_deg_rt_h"],
                   "rrw_long_deg_h_rt_h": v["rrw_long_deg_h_rt_h"], "dc_gain": v["dc_gain"],
                   **{k: v.get(k) for k in _SPLIT_KEYS}}
    return pred


def with_sensor(model, space: DesignSpace, *, g_sensitivity: bool = True):
    """The noise model with the space's sensor bandwidth (and g-sensitivity) on every gyro.

    The Monte-Carlo check and the full predictor leave the g-sensitivity out
    (``g_sensitivity`` False), as the ranking does: it is reported on its own.
    """
    extra = tuple(e for e in space.sensor_entries() if g_sensitivity or e.effect != G_SENSITIVITY)
    return model if not extra else NoiseModel(tuple(model.entries) + extra,
                                              description=model.description)


def white_covariance(n: int, g: GyroNoise, dt: float, signs=None) -> np.ndarray:
    """Covariance of one white sample of the N gyros [rad²/s²] (``signs``: the mounting signs,
    for the axis frame of the common mode: :meth:`GyroNoise.correlation`)."""
    if g.per_gyro is not None:
        return kept_covariances(g, n, None, dt, signs)[0]
    return units.arw_deg_rt_h_to_rad_rt_s(g.arw_deg_rt_h) ** 2 / dt * g.correlation(n, ARW, None, signs)


def _space_specific_force(space: DesignSpace) -> np.ndarray:
    """The specific force at the platform origin over the scored window (n, 3) [m/s²]:
    the motion profile's truth, else the level table at rest (a swing's few degrees of
    tilt are left out), [0, 0, g0]."""
    if space.specific_force_m_s2 is not None:
        return np.asarray(space.specific_force_m_s2, dtype=float)[:space.n_samples]
    return np.array([[0.0, 0.0, G0_M_S2]])


def g_sensitivity_terms(space: DesignSpace, dc_gain: np.ndarray) -> dict:
    """``g_sensitivity``: the RMS rate error of the space's g-sensitivity on its motion, per
    gyro and fused through the design's DC gain T₀ (3, N) (:func:`gyroarray.design.predict.g_sensitivity_error`);
    {} without one."""
    if space.g_sensitivity_deg_s_per_g is None:
        return {}
    T0 = np.asarray(dc_gain, dtype=float)
    N = T0.shape[1]
    k = np.tile(units.deg_s_per_g_to_rad_s_per_m_s2(np.asarray(space.g_sensitivity_deg_s_per_g,
                                                               dtype=float)), (N, 1))
    f0 = _space_specific_force(space)
    f = np.broadcast_to(f0[:, None, :], (f0.shape[0], N, 3))
    k0 = settle_start(f0.shape[0], space.dt_s, space.settle_s) if f0.shape[0] > 1 else 0
    r = g_sensitivity_error(k, f, T0, k0)
    fused = r["fused_rms_deg_s"]
    return {G_SENSITIVITY: {"per_gyro_rms_deg_s": float(np.mean(r["per_gyro_rms_deg_s"])),
                              "fused_rms_deg_s": fused,
                              "fused_rms_3axis_deg_s": float(math.sqrt(sum(v * v for v in fused.values())))}}


def evaluate_channels(est, resp_of, ch: Channels, sel) -> tuple[np.ndarray, _Moments]:
    """Objective (3-axis RMS² about the truth over the window) of channels ``sel``."""
    m = combine_moments(ch, sel, resp_of)
    ms, _, _ = add_motion(m, resp_of)
    return np.sum(ms, axis=-1), m


def channel_responses(bank: _FilterBank, est: str, bw, ch: Channels, idx=None) -> list:
    """One channel response per axis for the design (kf_array: per its design ratio)."""
    kind = _filter_kind(est)
    if bw is None:
        kind = "none"
    if kind == "kf":
        if est == "kf_array":
            assert ch.ratio is not None                              # channel_levels sets it for kf_array
            ratios = ch.ratio[0 if idx is None else idx]
        else:
            ratios = np.full(3, ch.kf_single_ratio)
        return [bank.get("kf", bw, float(r)) for r in ratios]
    r = bank.get(kind, bw)
    return [r, r, r]


def estimator_kwargs(est: str, bw, g: GyroNoise) -> dict:
    """The hyperparameters of estimator ``est`` at bandwidth ``bw`` [Hz] as the predictor designs
    it for the gyros ``g`` (what a simulation of the recommended design builds): its bandwidth
    [Hz], and for the array KF no bias states when the gyros have no rate random walk (the
    fast path's walk/white ratio 0: the bias states would have no process noise and the gain
    no steady state)."""
    tags = design_tags(est)                     # what the estimator declares (its design tags)
    kw: dict = {} if tags.bandwidth_param is None else {tags.bandwidth_param: bw}
    if tags.needs_rrw_for_bias_states and not g.rrw_deg_h_rt_h > 0:
        kw["bias_states"] = False
    return kw


def filter_bank(space: DesignSpace, g: GyroNoise) -> "_FilterBank":
    """The filter bank of a search (one per space and noise shape; ρ does not enter it)."""
    cache = space.__dict__.setdefault("_banks", {})
    key = (g.gm_tau_s, g.bi_deg_h > 0)
    if key not in cache:
        cache[key] = _FilterBank(space, g.gm_tau_s, bi=g.bi_deg_h > 0)
    return cache[key]


def single_ratio(g: GyroNoise, space: DesignSpace) -> float:
    """q_b / r of one gyro (the design ratio of kf_single's filter)."""
    return (units.rrw_deg_h_rt_h_to_rad_s_rt_s(g.rrw_deg_h_rt_h) ** 2 * space.dt_s ** 2
            / units.arw_deg_rt_h_to_rad_rt_s(g.arw_deg_rt_h) ** 2)


def fixed_channels(est: str, H: np.ndarray, g_design: GyroNoise, g_true: GyroNoise,
                   dt: float, keep=None, signs=None) -> Channels:
    """Per α and axis the channel noise of an estimator built for ``g_design`` and run on
    ``g_true`` (weights fixed at design; variances MᵀC_true M) [SI, per sample].

    Per-gyro noise: ``keep`` names the model's gyros in H's columns (0-based; None: all).
    ``signs``: the mounting sign (±1) of every gyro of the array, in H's row order (H's rows are already
    mounted); each noise's correlation is formed in its own common-mode frame
    (:meth:`GyroNoise.correlation`: the axis frame multiplies it by s sᵀ of the kept gyros)."""
    N = H.shape[1]
    if g_true.per_gyro is not None:
        return _fixed_channels_per_gyro(est, H, g_design, g_true, dt, keep, signs)
    s2 = units.arw_deg_rt_h_to_rad_rt_s(g_true.arw_deg_rt_h) ** 2 / dt
    q = units.rrw_deg_h_rt_h_to_rad_s_rt_s(g_true.rrw_deg_h_rt_h) ** 2 * dt
    Rd = s2 * g_design.correlation(N, ARW, keep, signs)
    M = design_weights(est, H, Rd, dt, q * g_design.correlation(N, RRW, keep, signs))
    Rt, Qt = s2 * g_true.correlation(N, ARW, keep, signs), q * g_true.correlation(N, RRW, keep, signs)
    white = np.einsum("gai,ij,gaj->ga", M, Rt, M)
    walk = np.einsum("gai,ij,gaj->ga", M, Qt, M)
    m2 = np.sum(M * M, axis=2)
    ratio = None
    if est == "kf_array":
        Qd = q * g_design.correlation(N, RRW, keep, signs)
        ratio = np.einsum("gai,ij,gaj->ga", M, Qd, M) / np.einsum("gai,ij,gaj->ga", M, Rd, M)
    cb = g_true.correlation(N, BIAS_INSTABILITY, keep, signs)       # the flicker's correlation
    ch = Channels(white, walk, np.einsum("gai,ij,gaj->ga", M, cb, M) * units.deg_h_to_rad_s(g_true.bi_deg_h) ** 2,
                   m2 * units.deg_h_to_rad_s(g_true.gm_sigma_deg_h) ** 2, ratio, True,
                   bias=np.max(np.abs(np.einsum("gan,gnb->gab", M, H) - np.eye(3)), axis=(1, 2)))
    ch.kf_single_ratio = q / s2                                     # q_b / r of one gyro
    return ch


def _fixed_channels_per_gyro(est: str, H: np.ndarray, g_design: GyroNoise, g_true: GyroNoise,
                             dt: float, keep, signs=None) -> Channels:
    """:func:`fixed_channels` with every gyro its own level (and the model's correlation)."""
    N = H.shape[1]
    Rd, Qd = kept_covariances(g_design, N, keep, dt, signs)
    Rt, Qt = kept_covariances(g_true, N, keep, dt, signs)
    _, _, b2, gm2 = kept_levels(g_true, N, keep, dt)
    M = design_weights(est, H, Rd, dt, Qd)
    white = np.einsum("gai,ij,gaj->ga", M, Rt, M)
    walk = np.einsum("gai,ij,gaj->ga", M, Qt, M)
    ratio = None
    if est == "kf_array":
        ratio = np.einsum("gai,ij,gaj->ga", M, Qd, M) / np.einsum("gai,ij,gaj->ga", M, Rd, M)
    sb = np.sqrt(b2)
    cb = np.outer(sb, sb) * g_true.correlation(N, BIAS_INSTABILITY, keep, signs)   # flicker covariance
    ch = Channels(white, walk, np.einsum("gai,ij,gaj->ga", M, cb, M), np.einsum("gai,i->ga", M * M, gm2),
                   ratio, True, bias=np.max(np.abs(np.einsum("gan,gnb->gab", M, H) - np.eye(3)), axis=(1, 2)))
    s2, q, _, _ = kept_levels(g_true, N, keep, dt)
    ch.kf_single_ratio = float(np.mean(q) / np.mean(s2))             # the typical gyro's q_b / r
    return ch


def both_objectives(ch: Channels, resp, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Both objectives squared (leading shape of the channels): Σ_axes mean square [rad²/s²]
    and Σ_axes angle² at the horizon [rad²]."""
    m = combine_moments(ch, slice(None), resp)
    ms, _, sumf2 = add_motion(m, resp)
    return np.sum(ms, axis=-1), dt ** 2 * np.sum(sumf2, axis=-1)


def _stack(chs: list) -> Channels:
    """Channels of several conditions stacked on a new leading axis."""
    c0 = chs[0]
    return Channels(np.stack([c.white for c in chs]), np.stack([c.walk for c in chs]),
                     np.stack([c.flicker for c in chs]), np.stack([c.gm for c in chs]), None, True,
                     c0.kf_single_ratio)
