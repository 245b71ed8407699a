"""``earth_rate``: the Earth's rotation sensed through the table attitude.

The fit side of ``earth_rate``: static offsets that follow the table attitude.

Model (frames and signs as in :mod:`gyroarray.sim.effects`, "Frames and
signs"): gyro k senses, on top of the table rate, the Earth's rate in the
platform frame, h_k · R_iᵀ ω_ie,L with

    ω_ie,L = Ω (cos φ cos ψ, −cos φ sin ψ, sin φ)

(φ latitude, ψ the site heading of the platform x axis at t = 0, R_i the
platform -> local-level rotation at sample i, R_0 = I). With
(c, s) = (Ω cos φ, Ω sin φ) this is linear:

    e_k,i = c · x_h,k,i + s · x_v,k,i + b_k,i + w_k,i
    x_h,k,i = h_k · R_iᵀ (cos ψ, −sin ψ, 0),   x_v,k,i = h_k · R_iᵀ (0, 0, 1)

with b_k the gyro's random-walk bias (unknown start) and w_k its white
noise. Each gyro is fitted by :func:`gyroarray.analysis.gls.gls_rw`
(its own r, q); the per-gyro normal equations are added (information form,
Σ C_k⁻¹ and Σ C_k⁻¹ β_k; the gyros' noises are taken as independent) into
one (c, s) with covariance. A constant regressor is absorbed by the unknown
bias, so only attitude *changes* make (c, s) identifiable: a record at one
attitude cannot tell the Earth's rate from the starting biases.

The attitude comes from integrating the reference rates
(:func:`attitude_from_rates`), unless given.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.analysis.gls import gls_rw, NotIdentifiableError
from gyroarray.analysis.memo import by_content, freeze
from gyroarray.core.jit import njit
from gyroarray.core.constants import EARTH_RATE_RAD_S
from gyroarray.effects.fitting import chi2_to_z, EffectFit, pm
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.core.physics import earth_rate_platform
from gyroarray.effects.protocol import Effect, Kind, Param, Stage
from gyroarray.core.units import RAD_PER_DEG, deg_to_rad


class EarthRate(Effect):
    """Needs ``site``; its ``latitude_deg`` must equal the site latitude
    (1e-9 rad), the heading comes from the site. Adds ω_ie,P = R_iᵀ ω_ie,L to
    the rate every gyro senses (frames in :mod:`gyroarray.core.physics`).

    Fit: offsets that change with the attitude as Ω would, on every gyro at
    once (:func:`gyroarray.effects.earth_rate.fit_earth_rate`; slow: tested
    again with the random walk re-estimated without it). The fit weighs the
    gyros as independent; under a modelled noise correlation ρ > 0 the
    variance of a combination of gyros grows by at most 1 + (N − 1)ρ, so its
    z is deflated by the root (a scoring run with ρ_arw = 0.16 on 5 gyros gave
    a false z of 4.3 without it).
    """

    name = "earth_rate"
    order = 16
    per_gyro = False
    stage = Stage.SENSE
    kind = Kind.ARRAY
    predicts = True
    slow = True
    needs = frozenset({"ref", "motion", "site"})
    model_needs = frozenset({"ref"})      # calibrated: the attitude comes from the reference rate
    sim_needs = frozenset({"site", "attitude"})   # Ω of the site, seen through the attitude
    params = (Param("latitude_deg", "deg", "latitude_rad", deg_to_rad, lo=-90.0, hi=90.0,
                    doc="site latitude (heading from the site)"),)
    doc = "Earth's rotation sensed through the table attitude"

    def simulate(self, state, act, streams):
        ctx = state.ctx
        lat = act.p["latitude_rad"]
        if ctx.site is None:
            raise InputError(f"{act.label}: earth_rate needs the site's heading: pass "
                             "site=(latitude_rad, heading_rad)")
        site_lat, heading = ctx.site
        if abs(site_lat - lat) > 1e-9:
            raise InputError(f"{act.label}: latitude_deg = {math.degrees(lat):.9g} disagrees with the "
                             f"site latitude {math.degrees(site_lat):.9g} deg", column="latitude_deg")
        w = earth_rate_platform(lat, heading, ctx.n, ctx.attitude)
        return replace(state, frame_rate=state.frame_rate + w)

    def fit(self, ctx, gyro, E):
        site = ctx.site
        heading = site.heading_rad / RAD_PER_DEG if site is not None else 0.0
        return fit_earth_rate(E, ctx.H, ctx.ref, ctx.t, ctx.dt, ctx.r, ctx.q, heading,
                              None if site is None else site.latitude_rad / RAD_PER_DEG,
                              attitude=ctx.attitude)

    def test(self, ctx, gyro):
        f = ctx.fitted(self, gyro, ctx.E)
        rho = _largest_correlation(ctx)
        if rho <= 0.0 or not np.isfinite(f.z):
            return f
        factor = math.sqrt(1.0 + (ctx.N - 1) * rho)
        return replace(f, z=float(f.z) / factor, extra={**f.extra, "z_independent": float(f.z),
                                                        "correlation_deflation": factor})

    def example(self, rng, n_gyros, max_rate_deg_s):
        _draw.gyro(rng, n_gyros)
        return None, {"latitude_deg": 34.25}      # the site of the scoring sessions' sidecar


def _largest_correlation(ctx) -> float:
    """The largest mean off-diagonal ρ (ARW or RRW) of the model's correlation, 0 without one."""
    rho = 0.0
    for e in ctx.entries("correlation"):
        for key in ("rho_arw", "rho_rrw"):
            v = np.asarray(e.params.get(key, 0.0), float)
            if v.ndim == 2:
                v = v[~np.eye(v.shape[0], dtype=bool)].mean() if v.shape[0] > 1 else np.float64(0.0)
            rho = max(rho, float(v))
    return rho


# -- fit ----------------------------------------------------------------------------------
#: Attitude changes below this [rad] count as "one attitude" (not identifiable).
STATIC_ATTITUDE_RAD = 1e-9


def _skew(v: np.ndarray) -> np.ndarray:
    """Skew matrices [v]× of an (n, 3) array, shape (n, 3, 3)."""
    z = np.zeros(v.shape[0])
    x, y, w = v[:, 0], v[:, 1], v[:, 2]
    return np.stack([np.stack([z, -w, y], -1),
                     np.stack([w, z, -x], -1),
                     np.stack([-y, x, z], -1)], -2)


def _expm_so3(phi: np.ndarray) -> np.ndarray:
    """exp([φ]×) of rotation vectors (n, 3) by Rodrigues, shape (n, 3, 3)."""
    th2 = np.einsum("ij,ij->i", phi, phi)
    th = np.sqrt(th2)
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th2 / 6.0 + th2 * th2 / 120.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th2 / 24.0 + th2 * th2 / 720.0, (1.0 - np.cos(ths)) / (ths * ths))
    k = _skew(phi)
    return np.eye(3) + a[:, None, None] * k + b[:, None, None] * np.matmul(k, k)


def attitude_from_rates(ref_rad_s, dt_s: float) -> np.ndarray:
    """Platform -> local-level rotations from the body rates, R_0 = I.

    Parameters
    ----------
    ref_rad_s : array_like, shape (n, 3)
        Rate of the platform relative to the Earth, platform frame [rad/s]
        (the measurement's ``ref_*`` in rad/s).
    dt_s : float
        Sample step [s].

    Returns
    -------
    ndarray, shape (n, 3, 3)
        R_i with v_L = R_i v_P.

    Notes
    -----
    Sample-hold (left rectangle): ω_i is held over [t_i, t_{i+1}) and each
    step is the exact rotation R_{i+1} = R_i · exp([ω_i dt]×) (Rodrigues),
    accumulated in order by a compiled loop (numba) that copies R through the
    samples where the table stands still (1e6 samples: 0.02 s, against 15 s for
    a batched prefix scan).

    Against the simulator's own attitude (MuJoCo's quaternion, integrated at
    the physics step, passed to ``simulate_readings`` by
    :func:`gyroarray.sim.scenario.simulate`): during the holds of a
    multi-position profile at 100 Hz the two agree to ~1e-11 rad (tested at
    1e-9); *during* a move they differ by up to ~max|ω|·dt/2 (the
    within-sample motion the samples cannot resolve; left, right or
    trapezoid holds all leave this), which leaves the Earth-rate signal
    essentially untouched (Ω × 3e-3 rad ≈ 2e-7 rad/s on the moving samples
    only). At 10 Hz the holds agree to ~4e-7 rad.
    """
    w = np.asarray(ref_rad_s, dtype=float)
    if w.ndim != 2 or w.shape[1] != 3 or w.shape[0] < 1:
        raise ValueError(f"ref_rad_s must be (n, 3), got shape {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("ref_rad_s contains a non-finite value")
    dt = float(dt_s)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt_s must be a positive number, got {dt_s!r}")
    n = w.shape[0]
    moving = np.flatnonzero(np.any(w[:-1] != 0.0, axis=1))
    steps = _expm_so3(w[moving] * dt) if moving.size else np.empty((0, 3, 3))
    return _accumulate(n, moving, steps)


def attitude_across_gaps(ref_rad_s, dt_s: float, gaps: dict[int, float]) -> np.ndarray:
    """:func:`attitude_from_rates` of a record with gaps: the rotation over each gap integrated.

    Parameters
    ----------
    ref_rad_s : array_like, shape (n, 3)
        Rate of the platform relative to the Earth, platform frame [rad/s], at the samples the
        record has (the gaps' samples are missing).
    dt_s : float
        Sample step [s] between samples without a gap between them.
    gaps : dict of int to float
        ``{i: step_s}``: the step from sample ``i`` to ``i + 1`` spans a gap of ``step_s`` [s]
        (more than one sample step).

    Returns
    -------
    ndarray, shape (n, 3, 3)
        R_i with v_L = R_i v_P, on the record's own clock: a part after a gap starts at the
        attitude the platform had turned to, not at the attitude before the gap.

    Notes
    -----
    Between samples without a gap this is :func:`attitude_from_rates` (sample-hold, the same
    bits). Over a gap the rate is unknown; it is taken as the mean of the two rates that bound
    the gap, held for the gap's length: exact for a constant rate, second order in the gap for a
    smooth one. Without the gap's length, stitching the parts would drop the rotation the
    platform made during the gap (``ω · gap``: a 1 s gap at 10 deg/s turns the Earth-rate and
    gravity projections of every later sample by 10°).
    """
    w = np.asarray(ref_rad_s, dtype=float)
    if not gaps:
        return attitude_from_rates(w, dt_s)
    if w.ndim != 2 or w.shape[1] != 3 or w.shape[0] < 1:
        raise ValueError(f"ref_rad_s must be (n, 3), got shape {w.shape}")
    n = w.shape[0]
    phi = w[:-1] * float(dt_s)
    for i, step in gaps.items():
        if not (0 <= i < n - 1 and math.isfinite(step) and step > 0):
            raise ValueError(f"gap at step {i} of {step!r} s is outside the record or not positive")
        phi[i] = 0.5 * (w[i] + w[i + 1]) * float(step)
    moving = np.flatnonzero(np.any(phi != 0.0, axis=1))
    steps = _expm_so3(phi[moving]) if moving.size else np.empty((0, 3, 3))
    return _accumulate(n, moving, steps)


@njit(cache=True)
def _accumulate(n, moving, steps):  # pragma: no cover - compiled
    """R_0 = I; R_{i+1} = R_i · S_i at the ``moving`` steps, R_{i+1} = R_i elsewhere."""
    out = np.empty((n, 3, 3))
    for a in range(3):
        for b in range(3):
            out[0, a, b] = 1.0 if a == b else 0.0
    j = 0
    for i in range(n - 1):
        if j < moving.size and moving[j] == i:
            for a in range(3):
                for b in range(3):
                    acc = 0.0
                    for c in range(3):
                        acc += out[i, a, c] * steps[j, c, b]
                    out[i + 1, a, b] = acc
            j += 1
        else:
            out[i + 1] = out[i]
    return out


def earth_rate_regressors(attitude: np.ndarray, H: np.ndarray, heading_deg: float) -> np.ndarray:
    """The two regressors of every gyro, shape (n, N, 2): (x_h, x_v) of the module docstring."""
    return _regressors(attitude, H, heading_deg)


@by_content(maxsize=4)
def _regressors(attitude: np.ndarray, H: np.ndarray, heading_deg: float) -> np.ndarray:
    """:func:`earth_rate_regressors`, kept by content (read-only): a diagnosis fits the Earth's
    rate again on every record a rival's fit cut, through the same attitudes (0.2 s each on
    46 min at 100 Hz)."""
    psi = math.radians(float(heading_deg))
    u_h = np.array([math.cos(psi), -math.sin(psi), 0.0])
    u_v = np.array([0.0, 0.0, 1.0])
    # R_iᵀ u in the platform frame: (R_iᵀ u)_a = Σ_b R_i[b, a] u_b
    p_h = np.einsum("nba,b->na", attitude, u_h)
    p_v = np.einsum("nba,b->na", attitude, u_v)
    return freeze(np.stack([p_h @ H.T, p_v @ H.T], axis=-1))


def _gyro_information(e, X, r, q):
    """(C⁻¹, C⁻¹β, χ²_resid, dof, used) of one gyro; rank-deficient X reduced by its span."""
    try:
        fit = gls_rw(e, X, r, q)
    except NotIdentifiableError:
        pass
    else:
        info = np.linalg.inv(fit.cov)
        return info, info @ fit.beta, float(fit.chi2), int(fit.dof), 2
    # one combination of the two regressors may still vary (e.g. a gyro on
    # the rotation axis): fit along the direction in which X changes.
    d = np.diff(X, axis=0)
    _, sv, vt = np.linalg.svd(d, full_matrices=False)
    if sv.size == 0 or not sv[0] > 0:
        return None
    v = vt[0]
    try:
        fit = gls_rw(e, X @ v, r, q)
    except NotIdentifiableError:
        return None
    w = 1.0 / float(fit.cov[0, 0])
    return w * np.outer(v, v), w * float(fit.beta[0]) * v, float(fit.chi2), int(fit.dof), 1


def _not_identifiable(why: str, **extra) -> EffectFit:
    return EffectFit(effect="earth_rate", gyro=None, params={"latitude_deg": float("nan")},
                     sigma={}, z=0.0,
                     evidence=f"{why}: the Earth's rate cannot be told from the unknown gyro "
                              "biases; a multi-position or rotating record is needed",
                     extra={"identifiable": False, "reason": why, **extra})


@by_content(maxsize=4)
def _attitude_change(att: np.ndarray) -> float:
    """Largest rotation angle [rad] of the attitudes away from the first one (kept by content)."""
    tr = np.einsum("nji,ji->n", att, att[0])                 # trace(R_0ᵀ R_i)
    # acos loses precision near 0: use the skew part as well
    rel = np.einsum("nji,jk->nik", att, att[0])              # R_iᵀ R_0
    skew = 0.5 * np.stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0],
                           rel[:, 1, 0] - rel[:, 0, 1]], -1)
    return float(np.max(np.arctan2(np.linalg.norm(skew, axis=1), 0.5 * (tr - 1.0))))


def _pooled_information(e: np.ndarray, X: np.ndarray, rv: np.ndarray, qv: np.ndarray) -> tuple:
    """Information matrix and vector of (c, s) summed over the gyros that see them, with the
    residual χ², its dof and the number of gyros used."""
    ng = e.shape[1]
    info = np.zeros((2, 2))
    vec = np.zeros(2)
    chi2_res, dof_res, used = 0.0, 0, 0
    for k in range(ng):
        got = _gyro_information(e[:, k], X[:, k, :], float(rv[k]), float(qv[k]))
        if got is None:
            continue
        ik, vk, c2, dof, _ = got
        info += ik
        vec += vk
        chi2_res += c2
        dof_res += dof
        used += 1
    return info, vec, chi2_res, dof_res, used


def _latitude_and_magnitude(c: float, s: float, cov: np.ndarray) -> tuple:
    """Latitude [deg] and magnitude [Ω] of (c, s) with their 1σ by the delta method."""
    m2 = c * c + s * s
    m = math.sqrt(m2)
    lat = math.degrees(math.atan2(s, c))
    if m > 0:
        g_lat = np.array([-s, c]) / m2
        g_mag = np.array([c, s]) / (m * EARTH_RATE_RAD_S)
        lat_sig = math.degrees(math.sqrt(max(float(g_lat @ cov @ g_lat), 0.0)))
        mag_sig = math.sqrt(max(float(g_mag @ cov @ g_mag), 0.0))
    else:
        lat_sig = mag_sig = float("inf")
    mag = m / EARTH_RATE_RAD_S
    return lat, lat_sig, mag, mag_sig


def fit_earth_rate(E, H, ref_rad_s, time_s, dt_s: float, r, q, heading_deg: float,
                   latitude_deg_site: float | None = None, *, attitude=None) -> EffectFit:
    """Fit ``earth_rate`` (array-wide): offsets that change with attitude as Ω would.

    Parameters
    ----------
    E : array_like, shape (n, N)
        Residuals gyro − H·ref [rad/s], starting biases unknown.
    H : array_like, shape (N, 3)
        Nominal unit sensitive axes, platform frame [-].
    ref_rad_s : array_like, shape (n, 3)
        Table rate of the platform relative to the Earth, platform frame [rad/s].
    time_s : array_like, shape (n,)
        Sample times [s] (uniform; only its length is checked).
    dt_s : float
        Sample step [s] (attitude integration).
    r, q : array_like, shape (N,) (or scalars)
        Per-gyro white variance N²/dt and random-walk increment variance
        K²·dt [rad²/s²] (:func:`~gyroarray.analysis.gls.gls_rw`).
    heading_deg : float
        Site heading of the platform x axis at t = 0 [deg] (spec convention).
    latitude_deg_site : float, optional
        The site latitude, for comparison only (``extra["site_latitude_deg"]``,
        ``extra["site_offset_sigma"]``).
    attitude : array_like, shape (n, 3, 3), optional
        Platform -> local-level rotations; default
        :func:`attitude_from_rates` of ``ref_rad_s``.

    Returns
    -------
    EffectFit
        ``params = {"latitude_deg": atan2(s, c)}`` with its σ (delta method);
        ``z`` = chi2_to_z(βᵀC⁻¹β, 2) of β = (c, s); ``extra``: ``c_rad_s``,
        ``s_rad_s``, ``cov_rad2_s2``, ``magnitude_ratio`` = |β|/Ω and
        ``magnitude_ratio_sigma``, ``chi2_beta``, ``identifiable``,
        ``attitude_change_rad`` (largest rotation from the start),
        ``n_gyros_used``, ``chi2_resid``, ``dof_resid``. Not identifiable
        (one attitude, or rotations that leave a component constant):
        z = 0, ``identifiable`` False, latitude NaN.
    """
    e = np.asarray(E, dtype=float)
    if e.ndim != 2:
        raise ValueError(f"E must be (n, N), got shape {e.shape}")
    n, ng = e.shape
    h = np.asarray(H, dtype=float)
    if h.shape != (ng, 3):
        raise ValueError(f"H must be ({ng}, 3), got shape {h.shape}")
    w = np.asarray(ref_rad_s, dtype=float)
    if w.shape != (n, 3):
        raise ValueError(f"ref_rad_s must be ({n}, 3), got shape {w.shape}")
    if np.shape(time_s) != (n,):
        raise ValueError(f"time_s must have shape ({n},), got {np.shape(time_s)}")
    rv = np.broadcast_to(np.asarray(r, dtype=float), (ng,))
    qv = np.broadcast_to(np.asarray(q, dtype=float), (ng,))
    if attitude is None:
        att = attitude_from_rates(w, dt_s)
    else:
        att = np.asarray(attitude, dtype=float)
        if att.shape != (n, 3, 3):
            raise ValueError(f"attitude must be ({n}, 3, 3), got shape {att.shape}")
    change = _attitude_change(att)
    site = {} if latitude_deg_site is None else {"site_latitude_deg": float(latitude_deg_site)}
    if not change > STATIC_ATTITUDE_RAD:
        return _not_identifiable(f"the record stays at one attitude (largest change "
                                 f"{change:.2g} rad)", attitude_change_rad=change, **site)

    X = earth_rate_regressors(att, h, heading_deg)
    info, vec, chi2_res, dof_res, used = _pooled_information(e, X, rv, qv)
    scale = np.sqrt(np.diag(info))
    if used == 0 or not np.any(scale > 0):
        return _not_identifiable("the attitude changes leave the Earth's rate along the gyros "
                                 "constant", attitude_change_rad=change, **site)
    if not np.all(scale > 0) or np.linalg.cond(info / np.outer(scale, scale)) > 1e12:
        return _not_identifiable("the attitude changes move only one component of the "
                                 "Earth's rate (e.g. turns about the vertical alone)",
                                 attitude_change_rad=change, **site)
    cov = np.linalg.inv(info)
    cov = 0.5 * (cov + cov.T)
    beta = cov @ vec
    c, s = float(beta[0]), float(beta[1])
    chi2_beta = float(beta @ info @ beta)
    z = chi2_to_z(chi2_beta, 2)

    lat, lat_sig, mag, mag_sig = _latitude_and_magnitude(c, s, cov)

    extra = {"identifiable": True, "c_rad_s": c, "s_rad_s": s, "cov_rad2_s2": cov.tolist(),
             "chi2_beta": chi2_beta, "dof_beta": 2, "magnitude_ratio": mag,
             "magnitude_ratio_sigma": mag_sig, "attitude_change_rad": change,
             "n_gyros_used": used, "chi2_resid": chi2_res, "dof_resid": dof_res, **site}
    if latitude_deg_site is not None and lat_sig > 0 and math.isfinite(lat_sig):
        extra["site_offset_sigma"] = (lat - float(latitude_deg_site)) / lat_sig
    if z > 3:
        evidence = (f"static offsets change with attitude as the Earth's rate at "
                    f"{pm(lat, lat_sig)}° latitude would (magnitude {pm(mag, mag_sig)} Ω)")
        if latitude_deg_site is not None:
            evidence += f"; site latitude {float(latitude_deg_site):.4g}°"
    else:
        evidence = (f"no Earth's rate seen in the attitude-dependent offsets (z = {z:.2f}; "
                    f"magnitude {pm(mag, mag_sig)} Ω)")
    return EffectFit(effect="earth_rate", gyro=None, params={"latitude_deg": lat},
                     sigma={"latitude_deg": lat_sig}, z=z, evidence=evidence, extra=extra)
