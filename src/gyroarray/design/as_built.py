"""The array as built (``design --layout-from``): each estimator's fused accuracy on a
recorded array's axes, its Allan deviation [deg/s] exact through the estimator's impulse
response.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.design.predict import (AXES, cascade, noise_sources, predict_system)
from gyroarray.effects.names import CORRELATION
from gyroarray.estimators import available, get_estimator
from gyroarray.design.details import budget_model
from gyroarray.design.gyro_noise import (GyroNoise, model_gyro_count, per_gyro_noise)


#: The estimators predicted on an array as built (those registered; ``svo`` when it is).
AS_BUILT_ESTIMATORS = ("gls", "ols", "kf_array", "svo", "naive")

#: Longest impulse response kept for a filter's Allan variance [samples].
MAX_IMPULSE = 1 << 16


def impulse_response(sys, tol: float = 1e-12, max_len: int = MAX_IMPULSE) -> np.ndarray:
    """h_j = C Aʲ K (L, 3, N) of a :class:`~gyroarray.estimators.base.LinearSystem`, cut where
    the slowest mode has decayed below ``tol`` (at most ``max_len`` samples)."""
    lam = np.asarray(sys.lam)
    amax = float(np.max(np.abs(lam))) if lam.size else 0.0
    L = 1 if amax <= 0 else int(min(max_len, max(1, math.ceil(math.log(tol) / math.log(min(amax, 1 - 1e-15))))))
    cs = sys.C @ sys.S                                                # (3, D)
    bk = sys.S_inv @ sys.K                                            # (D, N)
    powers = lam[None, :] ** np.arange(L)[:, None]                   # (L, D)
    h = np.einsum("ad,ld,dn->lan", cs, powers, bk)
    return np.real(h)


def allan_variance_linear(h: np.ndarray, R: np.ndarray, Q: np.ndarray, m: int) -> np.ndarray:
    """Allan variance (3,) [rad²/s²] at τ = m·dt of the output of impulse response h (L, 3, N)
    driven by white noise of per-sample covariance R and a random walk of per-sample increment
    covariance Q (stationary: the start-up left out).

    With g the Allan filter (−1/m on m samples, then +1/m on m samples), c = g ∗ h:
    σ² = ½ Σ_j c_jᵀ R c_j (white) + ½ Σ_j d_jᵀ Q d_j (walk), d_j = Σ_{i<=j} c_i."""
    L = h.shape[0]
    g = np.concatenate([np.full(m, -1.0 / m), np.full(m, 1.0 / m)])
    P = 1 << int(math.ceil(math.log2(2 * m + L)))
    c = np.fft.irfft(np.fft.rfft(g, P)[:, None, None] * np.fft.rfft(h, P, axis=0), P, axis=0)[:2 * m + L - 1]
    d = np.cumsum(c, axis=0)
    white = 0.5 * np.einsum("jan,nk,jak->a", c, R, c)
    walk = 0.5 * np.einsum("jan,nk,jak->a", d, Q, d)
    return white + walk


def _gm_avar(sigma2: np.ndarray, tau_c: np.ndarray, tau: float) -> np.ndarray:
    """Allan variance of first-order Gauss–Markov noise of variance σ² and correlation time τc
    at τ: σ²(τc/τ)²(2τ/τc − 3 + 4e^{−τ/τc} − e^{−2τ/τc}) [unit of σ²] (0 where τc = 0)."""
    out = np.zeros_like(np.asarray(sigma2, dtype=float))
    ok = (tau_c > 0) & (sigma2 > 0)
    x = tau / tau_c[ok]
    out[ok] = sigma2[ok] * (2.0 * x - 3.0 + 4.0 * np.exp(-x) - np.exp(-2.0 * x)) / x ** 2
    return out


def as_built_taus(dt_s: float, duration_s: float) -> list[float]:
    """Octave averaging times from dt to a ninth of the record (at most 2¹⁵ samples) [s]."""
    out, m = [], 1
    while m * dt_s <= duration_s / 9.0 and m <= 1 << 15:
        out.append(m * dt_s)
        m *= 2
    return out or [dt_s]


def predict_as_built(model, axes: np.ndarray, dt_s: float, *, n_samples: int,
                     estimators=None, taus=None, settle_s: float = 2.0, source: str = "model") -> dict:
    """Each estimator's fused accuracy on an array as built (``design --layout-from``).

    Parameters
    ----------
    model : NoiseModel
        The array's model: per-gyro parameters (every effect, a plugin's included) and, where it
        has one, the ``[array]`` table's white and walk correlation (:func:`per_gyro_noise`).
    axes : ndarray (N, 3)
        The mounted unit axes of the measurement [-].
    dt_s : float
        Sample period [s].
    n_samples : int
        Run length for the RMS and the angle error (the record's length).
    estimators : sequence of str, optional
        Default :data:`AS_BUILT_ESTIMATORS` that are registered.
    taus : sequence of float, optional
        Averaging times [s] (default :func:`as_built_taus`).

    Returns
    -------
    dict
        ``estimators``: per estimator per axis ``adev_deg_s`` (list of {tau_s, adev_deg_s}),
        ``arw_deg_rt_h`` (the long-τ white level through the DC gain), ``rms_deg_s`` and
        ``angle_deg`` (the full predictor over the run); ``taus_s``, ``n_gyros``, ``noise``
        (the per-gyro levels used), ``ignored_effects``, ``notes``.

    Notes
    -----
    The Allan deviation is exact for the white and walk parts through the estimator's impulse
    response (:func:`allan_variance_linear`, covariances R and Q of the whole array); flicker
    and Gauss–Markov terms pass the DC gain T₀ (independent between gyros): flicker at its
    floor (2 ln 2/π)·Σ T₀² B², Gauss–Markov by its closed form.
    """
    H = np.asarray(axes, dtype=float)
    N = H.shape[0]
    nm = model_gyro_count(model)
    if nm > N:
        raise InputError(f"the model names gyro {nm}, but the measurement has {N} gyros", file=source)
    typical = GyroNoise._typical(model, source)
    g = per_gyro_noise(model, typical, source) if nm else typical
    if nm and nm < N:
        raise InputError(f"the model names {nm} gyros, the measurement has {N}: give every gyro its "
                         "parameters (gyroarray fit --out on this record)", file=source)
    full = budget_model(g, range(N))
    noise = noise_sources(full, N, dt_s)
    known = [e for e in AS_BUILT_ESTIMATORS if e in set(available())]
    if estimators is not None:
        unknown = [e for e in estimators if e not in set(available())]
        if unknown or not list(estimators):
            raise InputError(f"--estimators: {unknown[0] if unknown else '(none)'} is not an estimator "
                             f"(known: {', '.join(sorted(available()))}; default {', '.join(known)})")
    names = list(dict.fromkeys(estimators)) if estimators is not None else known
    taus = list(taus) if taus is not None else as_built_taus(dt_s, n_samples * dt_s)
    notes = []
    out: dict[str, Any] = {}
    flicker_floor = 2.0 * math.log(2.0) / math.pi
    rrw_on = bool(np.any(np.diag(noise.Qb) > 0))
    for name in names:
        kw: dict = {}
        if name == "kf_array" and not rrw_on:
            kw["bias_states"] = False
        try:
            est = get_estimator(name)(**kw).fit(Layout(H), full, dt_s)
        except InputError as err:
            notes.append(f"{name}: not predicted ({err})")
            continue
        sys = est.linear_system()
        csys = cascade(sys, noise.sensor)
        h = impulse_response(csys)
        if h.shape[0] >= MAX_IMPULSE:
            notes.append(f"{name}: its impulse response was cut at {MAX_IMPULSE} samples (a slow mode)")
        t0 = h.sum(axis=0)                                            # (3, N) DC gain
        p = predict_system(sys, noise, H, n=int(n_samples), settle_s=settle_s, name=name)
        per_axis = {}
        adev = []
        for tau in taus:
            m = max(1, int(round(tau / dt_s)))
            av = allan_variance_linear(h, noise.R, noise.Qb, m)
            av = av + flicker_floor * (t0 ** 2) @ (noise.bi_rad_s ** 2)
            av = av + (t0 ** 2) @ _gm_avar(noise.gm_sigma_rad_s ** 2, np.asarray(noise.gm_tau_s, float), m * dt_s)
            adev.append((m * dt_s, np.sqrt(np.maximum(av, 0.0))))
        arw = units.arw_rad_rt_s_to_deg_rt_h(np.sqrt(np.maximum(np.einsum("ai,ij,aj->a", t0, noise.R, t0) * dt_s, 0)))
        for a, ax in enumerate(AXES):
            per_axis[ax] = {"adev_deg_s": [{"tau_s": float(t), "adev_deg_s": float(units.rad_s_to_deg_s(v[a]))}
                                           for t, v in adev],
                            "arw_deg_rt_h": float(arw[a]),
                            "rms_deg_s": p.axes[ax]["rms_deg_s"], "angle_deg": p.axes[ax]["angle_deg"]}
        out[name] = per_axis
    if not out:
        raise InputError("no estimator could be predicted on this array: " + "; ".join(notes))
    return {"estimators": out, "taus_s": [float(t) for t in taus], "n_gyros": N,
            "horizon_s": float(n_samples * dt_s), "dt_s": float(dt_s),
            "noise": g.to_json_dict(), "per_gyro": g.per_gyro is not None,
            CORRELATION: ("the model's [array] / correlation matrices" if g.corr_arw is not None
                            or g.corr_rrw is not None else f"rho = {g.rho_arw:g}"),
            "ignored_effects": list(noise.ignored), "notes": notes}
