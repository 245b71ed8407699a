"""``latency``: the output lags the input (residual ∝ angular acceleration)."""

from __future__ import annotations

import math
from functools import partial

import numpy as np
from scipy import optimize

from gyroarray.analysis.gls import NotIdentifiableError, RWWhitener
from gyroarray.analysis.memo import by_content
from gyroarray.effects.fitting import (as_vector, chi2_to_z, EffectFit, fit_extra, not_identifiable, num, pm,
                                       projected_rate, transfer_limit, Z_EVIDENT, z_two_sided)
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.core.physics import fractional_delay
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, identity, with_cols


class Latency(RegressionEffect):
    """u_k(t) ← u_k(t − d): cubic Lagrange fractional delay of the sensed input
    (:func:`gyroarray.core.physics.fractional_delay`); before the record the first
    sample is held; a delay as long as the record is refused."""

    name = "latency"
    own_column = True                  # its test reads its gyro's column of the residual only
    order = 13
    stage = Stage.DELAY
    needs = frozenset({"ref", "motion"})
    model_needs = frozenset({"ref"})      # calibrated: regressed on the reference rate
    channel = "accel"
    params = (Param("delay_s", "s", "delay_s", identity, lo=0.0, doc="delay of the sensed input"),)
    doc = "output lags the input"

    def simulate(self, state, act, streams):
        ctx = state.ctx
        d = act.p["delay_s"] / ctx.dt_s
        if np.any(d >= ctx.n - 1):
            raise InputError(f"{act.label}: delay_s = {float(np.max(act.p['delay_s'])):g} s is not "
                             f"shorter than the record ({(ctx.n - 1) * ctx.dt_s:g} s)", column="delay_s")
        return with_cols(state, act.cols, fractional_delay(state.x[:, act.cols], d))

    def check_run(self, params, sample_rate_hz, duration_s):
        if params["delay_s"] >= duration_s:
            raise InputError(f"delay_s = {params['delay_s']:g} s is not shorter than the run "
                             f"({duration_s:g} s)", column="delay_s")

    def check_record(self, params, dt_s, span_s):
        if params["delay_s"] >= span_s - dt_s:
            raise InputError(f"delay_s = {params['delay_s']:g} s is not shorter than the record "
                             f"({span_s:g} s long)", column="delay_s")

    def regress(self, ctx, gyro, e, r, q):
        """The delay's fit, then its check against the motion's lines: a pure delay must give the
        phase delay the gyro shows at every line it shows, flat, with no loss of amplitude
        (:func:`~gyroarray.effects.fitting.transfer_limit`; issue 44: candidates of 7.89 and
        11.34 ms against a measured 12.15 ms)."""
        e, ref, inst = self.against_reference(ctx, gyro, e)
        fit = _fit_latency(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use, instrument=inst)
        if not fit.extra.get("identifiable", True) or not ctx.moving:
            return fit
        u = ref @ ctx.H[gyro - 1]
        d = float(fit.params["delay_s"])
        return transfer_limit(fit, e + u, u, ctx.dt, partial(_delay_response, dt_s=ctx.dt), "delay_s",
                              f"a pure delay of {d * 1e3:.4g} ms", use=ctx.use)

    def channel_line(self, fit, x, xm, ym):
        return -fit.params["delay_s"] * x * 3600.0, "delay " + self._label(fit, "delay_s", 1e3, " ms")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"delay_s": _draw.u(rng, 0.002, 0.01, True)}


# -- fit ----------------------------------------------------------------------------------
def _delay_response(f_hz, delay_s: float, dt_s: float | None = None) -> np.ndarray:
    """H(f) of the simulator's delay of ``delay_s`` [s] at f [Hz]: exp(−i 2π f d) without
    ``dt_s``; with it, the cubic Lagrange fractional delay's own response
    (:func:`~gyroarray.core.physics.fractional_delay`: e^{−iωk·dt} Σ_o w_o e^{iωo·dt}, o = −2..1),
    whose amplitude falls 0.1 % at f·dt = 0.1 for half a sample."""
    f = np.asarray(f_hz, dtype=float)
    if dt_s is None:
        return np.exp(-2j * np.pi * f * delay_s)
    d = max(float(delay_s), 0.0) / dt_s
    k = math.floor(d + 1e-9)
    s = -(d - k) if abs(d - round(d)) >= 1e-9 else 0.0
    w = (-(s + 1) * s * (s - 1) / 6, (s + 2) * s * (s - 1) / 2, -(s + 2) * (s + 1) * (s - 1) / 2,
         (s + 2) * (s + 1) * s / 6)
    om = 2j * np.pi * f * dt_s
    return np.exp(-om * k) * sum(wo * np.exp(om * o) for wo, o in zip(w, (-2, -1, 0, 1)))


# -- latency ---------------------------------------------------------------------

def _delay_bracket(d: float, dt: float) -> tuple[float, float]:
    """Where a delay refined from the linear estimate d [s] is looked for [s]."""
    return max(0.0, 0.5 * d - dt), 2.0 * d + 2.0 * dt


def _refine_delay(wh, ze: np.ndarray, e: np.ndarray, u: np.ndarray, du: np.ndarray, d: float,
                  dt: float) -> tuple:
    """Delay by χ² of the fractionally delayed rate: grid from the linear estimate d, Brent, one
    Gauss–Newton step; (delay [s], 1σ [s], z, extra entries)."""
    n = e.size
    chi2_0 = float(ze @ ze)

    def model(dd):
        return fractional_delay(u[:, None], [dd / dt])[:, 0] - u

    def chi2(dd):
        zr = ze - wh.whiten(model(dd))
        return float(zr @ zr)

    lo, hi = _delay_bracket(d, dt)
    grid = np.linspace(lo, hi, 9)
    vals = np.array([chi2(g) for g in grid])
    k = int(np.argmin(vals))
    for _ in range(3):                                   # minimum at the top: look further
        if k < grid.size - 1 or 2.0 * grid[-1] >= (n - 2) * dt:
            break
        grid = np.linspace(grid[-2], 2.0 * grid[-1], 9)
        vals = np.array([chi2(g) for g in grid])
        k = int(np.argmin(vals))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = optimize.minimize_scalar(chi2, bounds=(a, b), method="bounded",
                                   options={"xatol": 1e-3 * dt})
    dd = float(res.x)
    deriv = -fractional_delay(du[:, None], [dd / dt])[:, 0]
    zg = wh.whiten(deriv, e - model(dd))
    step = wh.fit_whitened(zg[:, 1], zg[:, :1])
    d_new = dd + float(step.beta[0])
    if d_new >= 0.0 and chi2(d_new) <= res.fun:
        dd = d_new
    chi2_d = chi2(dd)
    d, sd = dd, float(step.sigma[0])
    z = chi2_to_z(max(chi2_0 - chi2_d, 0.0), 1)
    return d, sd, z, dict(refined=True, chi2=chi2_d, chi2_no_delay=chi2_0,
                          grid_s=[float(g) for g in grid])


def _refine_delay_iv(wh, e: np.ndarray, u: np.ndarray, du: np.ndarray, dui: np.ndarray, d: float,
                     dt: float) -> tuple:
    """Delay by the instrumental-variables moment of the fractionally delayed rate: Gauss–Newton
    steps on Zᵀ(e − m(d)) = 0 with Z = −D_d u̇ of the smoothed reference (the χ² of
    :func:`_refine_delay` would read the reference's own noise); (delay [s], 1σ [s], z, extra)."""
    def at(dd):
        m = fractional_delay(u[:, None], [dd / dt])[:, 0] - u
        zg = wh.whiten(-fractional_delay(du[:, None], [dd / dt])[:, 0], e - m,
                       -fractional_delay(dui[:, None], [dd / dt])[:, 0])
        return zg[:, 0], zg[:, 1], zg[:, 2]

    d0, (lo, hi) = d, _delay_bracket(d, dt)                           # the χ² search's bracket
    for _ in range(6):
        zj, zr, zi = at(d)
        step = float(zi @ zr) / float(zi @ zj)
        d += step
        if not lo <= d <= hi:                      # the moment has no root near the start: keep it
            d = d0
            break
        if abs(step) < 1e-4 * dt:
            break
    zj, zr, zi = at(d)
    chi2 = float(zr @ zr)
    sd = math.sqrt(float(zi @ zi) * max(chi2 / max(zr.size - 1, 1), 1.0)) / abs(float(zi @ zj))
    return d, sd, z_two_sided(d / sd), dict(refined=d != d0, chi2=chi2, instrumented=True)


def _latency_evidence(gyro: int, z: float, d: float, sd: float, dt: float) -> str:
    """The sentence that reports the delay (or its absence)."""
    samples = d / dt
    if z >= Z_EVIDENT:
        lead = "lags" if d > 0 else "leads"
        ev = (f"gyro {gyro} residual follows the angular acceleration about its axis: the output "
              f"{lead} the reference by {pm(abs(d) * 1e3, sd * 1e3)} ms ({num(abs(samples), 3)} samples)")
    else:
        ev = (f"gyro {gyro} residual shows no significant response to the angular acceleration "
              f"about its axis (delay {pm(d * 1e3, sd * 1e3)} ms, z = {z:.1f})")
    return ev


def fit_latency(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float, gyro: int,
                *, use=None, refine: bool = True, instrument=None) -> EffectFit:
    """Latency: residual proportional to the angular acceleration about the axis.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual y − h·ω_ref [rad/s].
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s].
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s] (centred differences; the fractional delay).
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`~gyroarray.analysis.gls.gls_rw`).
    refine : bool
        Refine a significant delay longer than half a sample by the
        nonlinear search below.
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables); −u̇ is instrumented by the smoothed −u̇ and the refinement
        solves the instrumented moment (:func:`_refine_delay_iv`), z is then
        the Wald ratio d/σ.

    Returns
    -------
    EffectFit
        ``latency``: ``delay_s`` with sigma. A negative delay (output ahead
        of the reference) is reported as fitted.

    Notes
    -----
    Linear start (the sensed rate delayed by d, to first order)::

        u_t = h·ω_ref,t,  u̇_t = (u_{t+1} − u_{t−1})/(2 dt)  (one-sided at the ends)
        e_t = u(t − d) − u(t) + b_t + w_t ≈ d·(−u̇_t) + b_t + w_t

    → d₀, σ₀ by :func:`~gyroarray.analysis.gls.gls_rw`, z = two-sided significance of d₀/σ₀.

    Refinement (when ``refine``, d₀ > dt/2 and |d₀/σ₀| > 5): the exact model
    of the simulator, m_t(d) = D_d u_t − u_t with D_d the cubic Lagrange
    fractional delay (``gyroarray.core.physics.fractional_delay``), and
    χ²(d) = GLS χ² of e − m(d) with no regressor. A grid of 9 delays on
    [max(0, d₀/2 − dt), 2d₀ + 2dt], then a bounded Brent search between the
    neighbours of the grid minimum (the grid moves up, at most 3 times, while
    its minimum is its last point; Brent to 1e-3 samples), then one
    Gauss–Newton step (regressor ∂m/∂d = −D_d u̇, kept if χ² does not rise)
    that also gives σ_d. Then z = chi2_to_z(χ²(0) − χ²(d̂), 1) (the
    likelihood-ratio statistic). Cost at n = 2.2e6: about 1 s.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    as_vector(time_s, n, "time_s")
    _, u = projected_rate(omega_ref_rad_s, h, n)
    dt = float(dt_s)
    du = np.gradient(u, dt)
    dui = None if instrument is None else np.gradient(projected_rate(instrument, h, n)[1], dt)
    wh = RWWhitener(n, r, q, use)
    zz = wh.whiten(-du, e) if dui is None else wh.whiten(-du, e, -dui)
    try:
        fit = wh.fit_whitened(zz[:, 1], zz[:, :1], None if dui is None else zz[:, 2:3])
    except NotIdentifiableError as err:
        return not_identifiable("latency", gyro, {"delay_s": 0.0},
                                 "the rate about its axis never changes", err)
    d, sd = float(fit.beta[0]), float(fit.sigma[0])
    t = d / sd
    z = z_two_sided(t)
    extra = fit_extra(fit, t=t, d_linear_s=d, sigma_linear_s=sd, refined=False, instrumented=dui is not None)
    if refine and d > 0.5 * dt and abs(t) > 5.0:
        d, sd, z, more = (_refine_delay(wh, zz[:, 1], e, u, du, d, dt) if dui is None else
                          _refine_delay_iv(wh, e, u, du, dui, d, dt))
        extra.update(more)
    ev = _latency_evidence(gyro, z, d, sd, dt)
    return EffectFit("latency", gyro, {"delay_s": d}, {"delay_s": sd}, z, ev, extra)


#: :func:`fit_latency` by content: the ranking tests a rival again on records cut by other gyros'
#: fits, where this gyro's residual is as it was, bit for bit.
_fit_latency = by_content(maxsize=16)(fit_latency)
