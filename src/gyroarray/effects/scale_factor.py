"""``scale_factor``: output = (1 + ppm·1e-6)·input (residual ∝ the sensed rate)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gyroarray.analysis.gls import gls_rw, GLSFit, NotIdentifiableError
from gyroarray.analysis.transfer import cross_spectral_gain, NoSpectralLines, ZeroFrequencyGain
from gyroarray.core.units import per_rad_s_to_per_deg_s, rad_s_to_deg_s, ratio_to_ppm
from gyroarray.effects.fitting import (as_vector, EffectFit, fit_extra, not_identifiable, num, pm,
                                       projected_rate, Z_EVIDENT, z_two_sided)
from gyroarray.effects import _draw
from gyroarray.effects.outliers import MOTION_RAW
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, with_term
from gyroarray.effects.terms import ScaleTerm, spread
from gyroarray.core.units import ppm_to_ratio


class ScaleFactor(RegressionEffect):
    """s·u added to the output, u the gyro's sensed input (after latency), s = ppm·1e-6."""

    name = "scale_factor"
    own_column = True                  # its test reads its gyro's column of the residual only
    order = 9
    stage = Stage.SCALE
    needs = frozenset({"ref", "motion"})
    model_needs = frozenset({"ref"})      # calibrated: regressed on the reference rate
    rivals = ("misalignment",)
    channel = "rate"
    params = (Param("ppm", "ppm", "ratio", ppm_to_ratio, lo=-1e6, lo_open=True,
                    doc="scale-factor error: output = (1 + ppm·1e-6)·input"),)
    doc = "scale-factor error"

    def predictor_term(self, act, n_gyros):
        """A deterministic error s_i·(h_i·ω) for the stated body rate (the nominal axis; the
        product with a misalignment is second order)."""
        return ScaleTerm(spread(act, "ratio", n_gyros))

    def simulate(self, state, act, streams):
        return with_term(state, act.cols, act.p["ratio"] * state.u[:, act.cols])          # s·u

    def regress(self, ctx, gyro, e, r, q):
        """The slope on the gyro's residual; with a curvature of this gyro in the model, the slope
        fitted jointly with a correction of it.

        The curvature's own fit is joint with a slope (:func:`fit_scale_and_nonlinearity`) that
        the model does not keep, so its residual holds exactly that slope, whose spread is the
        joint fit's: tested alone, with the smaller σ of a slope by itself, its z is wider than
        N(0, 1) wherever u and u² are collinear (rates mostly of one sign; seed 109: z 4.17 for
        no scale factor at all). Tested jointly, z is the joint slope over its own σ.

        On a moving rig the slope is set beside the gain at the motion's spectral lines
        (:func:`cross_spectral_scale`, :func:`reconcile_scale`): the evidence shows both, and
        the model keeps the cross-spectral one only where it agrees with the slope within their
        combined σ and lowers the residual's χ² (issue 44 item 2).
        """
        held = ctx.cache.get(MOTION_RAW)        # the residual before the motion-locked spikes were cleaned
        raw = held[1][:, gyro - 1] if held is not None and np.shares_memory(e, held[0]) else e
        e, ref, inst = self.against_reference(ctx, gyro, e)
        joint = any(x.gyro == gyro for x in ctx.entries("scale_nonlinearity"))
        if joint:
            fit = fit_scale_and_nonlinearity(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use,
                                             instrument=inst)[0]
        else:
            fit = fit_scale_factor(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use, instrument=inst)
        if not fit.extra.get("identifiable", True) or not ctx.moving:
            return fit
        # the lines read the output as recorded (less the model's deterministic part): the spikes at the
        # reversals are part of its response to the motion, and cleaning them would reshape it
        xs = cross_spectral_scale(self.against_reference(ctx, gyro, raw)[0], ref, ctx.H[gyro - 1], ctx.dt,
                                  use=ctx.use)
        return reconcile_scale(fit, xs, joint_with_nonlinearity=joint)

    def channel_line(self, fit, x, xm, ym):
        return fit.params["ppm"] * 1e-6 * x * 3600.0, self._label(fit, "ppm", unit=" ppm")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"ppm": _draw.u(rng, 1000.0, 8000.0, True) * rng.choice([-1, 1])}


# -- fit ----------------------------------------------------------------------------------
# -- scale factor and nonlinearity ---------------------------------------------

def fit_scale_factor(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float, gyro: int,
                     *, use=None, instrument=None) -> EffectFit:
    """Scale-factor error: residual proportional to the rate about the axis.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual y − h·ω_ref [rad/s].
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s].
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    time_s : array_like, shape (n,)
        Sample times [s] (uniform; only its length is used here).
    dt_s : float
        Sample step [s] (not used here; the common signature).
    r : float
        ARW variance per sample, N²/dt [rad²/s²].
    q : float
        RRW increment variance per sample, K²·dt [rad²/s²].
    gyro : int
        1-based gyro number (for the result).
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`~gyroarray.analysis.gls.gls_rw`).
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables) is fitted by instrumental variables, the columns read from
        ``omega_ref_rad_s`` instrumented by the same columns read from this.

    Returns
    -------
    EffectFit
        ``scale_factor``: ``ppm`` with sigma; z = two-sided significance.

    Notes
    -----
    ::

        e_t = s·u_t + b_t + w_t,   u_t = h·ω_ref,t,   ppm = s·1e6
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    as_vector(time_s, n, "time_s")
    _, u = projected_rate(omega_ref_rad_s, h, n)
    ui = None if instrument is None else projected_rate(instrument, h, n)[1]
    try:
        fit = gls_rw(e, u, r, q, use=use, Z=ui)
    except NotIdentifiableError as err:
        return not_identifiable("scale_factor", gyro, {"ppm": 0.0}, "there is no rate about its axis", err)
    return _scale_fit(fit, 0, gyro, joint_with_nonlinearity=False, instrumented=ui is not None)


def cross_spectral_scale(e, omega_ref_rad_s, h, dt_s: float, *, use=None) -> ZeroFrequencyGain | str:
    """The scale factor read from the lines of a periodic motion (no plateau needed).

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual y − h·ω_ref [rad/s], the scale factor's own part included.
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s], as recorded (its own noise is no bias here).
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    dt_s : float
        Sample step [s].
    use : array_like of bool, shape (n,), optional
        Samples to read (glitches the model leaves out are bridged).

    Returns
    -------
    ZeroFrequencyGain or str
        |H(0)| of the output e + u over u = h·ω_ref at the motion's fundamental
        and harmonics (:func:`~gyroarray.analysis.transfer.cross_spectral_gain`:
        an instrumental-variable ratio per line, its magnitude, so that a latency
        does not bias it, gradient-corrected over the harmonics to f → 0);
        s = gain − 1. A phrase saying why not when the motion has no usable line.
    """
    e = np.asarray(e, dtype=float)
    _, u = projected_rate(omega_ref_rad_s, h, e.size)
    try:
        return cross_spectral_gain(e + u, u, dt_s, use=use)
    except NoSpectralLines as err:
        return str(err)


#: Why the model keeps the cross-spectral scale factor when it is kept.
KEEP_CROSS_SPECTRAL = ("it agrees with the time-domain fit within their combined σ and keeping it lowers the "
                       "residual's χ² against no scale factor: |H| at the motion's lines, read at f → 0, does not "
                       "see the lag, the bandwidth and the reversal jerks that a slope on the rate also reads")

#: Why a cross-spectral value that disagrees with the time-domain fit is not kept (issue 44 item 2).
NOT_CROSS_SPECTRAL = ("the reference's own errors bend the lines (an encoder's 2nd harmonic read +30 % on 3 of "
                      "5 MPU variants, raising D 97.3 -> 114.1): a cross-spectral value is kept only where it "
                      "agrees with the time-domain fit")

#: Combined σ within which the two scale factors count as consistent (:func:`reconcile_scale`):
#: two unbiased estimates differ by more on 5 % of records (a two-sided 95 % test). The MPU
#: record's lines, +5949 ± 54 ppm, against the slope's +4682 ± 736 are 1.7σ apart and the more
#: precise: kept (the settled +0.59-0.60 %); our bench's lines, 36935 ± 31024 against 3002.7 ±
#: 5.0, are the less precise: not kept (keeping them saturated the gyro, D 157 -> 1262).
CONSISTENT_Z = 1.959963984540054


def _ppm(x: float) -> str:
    """A difference in ppm as read: whole ppm from 10 on."""
    return f"{x:.0f}" if abs(x) >= 10.0 else num(x, 2)


def chi2_change(ppm: float, ppm_t: float, sig_t: float) -> float:
    """The residual's GLS χ² with ``ppm`` taken out, less its χ² with no scale factor [-].

    The discrepancy D of the model is not known inside one effect's fit; this is what stands
    for it here: the regression's own quadratic form under the fitted ARW + walk,
    χ²(s) = χ²(ŝ) + ((s − ŝ)/σ̂)², so χ²(s) − χ²(0) = ((s − ŝ)² − ŝ²)/σ̂² (ŝ, σ̂ = ``ppm_t``,
    ``sig_t`` the time-domain fit, ppm). Negative: keeping s explains part of the residual;
    positive: it leaves more than no scale factor at all (the slope test's z rises after it).
    """
    return float(((ppm - ppm_t) ** 2 - ppm_t ** 2) / sig_t ** 2) if sig_t > 0 else 0.0


def reconcile_scale(fit: EffectFit, xs: ZeroFrequencyGain | str, *, joint_with_nonlinearity: bool = False) -> EffectFit:
    """The time-domain fit ``fit`` set beside the cross-spectral estimate ``xs``.

    Parameters
    ----------
    fit : EffectFit
        The regression's ``scale_factor`` (:func:`fit_scale_factor`).
    xs : ZeroFrequencyGain or str
        :func:`cross_spectral_scale`'s result, or why there is none.
    joint_with_nonlinearity : bool
        ``fit`` is the joint fit with a curvature (whose rate-squared term the
        lines' gain does not separate): the time-domain value is kept.

    Returns
    -------
    EffectFit
        With ``extra["cross_spectral"]`` (``ppm``, ``sigma_ppm``, ``lines_hz``,
        ``slope_per_hz2``, ``chi2``, ``dof``, ``method``; None when unavailable, with
        ``extra["cross_spectral_why"]``), ``extra["time_domain"]`` (``ppm``,
        ``sigma_ppm``), ``extra["kept"]`` (``"time_domain"`` or ``"cross_spectral"``),
        ``extra["chi2_change"]`` (:func:`chi2_change` of the kept value) and
        ``extra["reconciled"]`` (one sentence).

    Notes
    -----
    Issue 44 item 2: the time-domain value is kept unless the cross-spectral one is consistent
    with it (within :data:`CONSISTENT_Z` times their combined σ), the more precise, and lowers
    the discrepancy, read here as the
    residual's χ² against no scale factor (:func:`chi2_change` < 0: D itself is the whole
    model's, not known inside one fit). A value whose keeping raises that χ² is never kept:
    the time-domain value's change is −(ŝ/σ̂)² <= 0.
    """
    ppm_t, sig_t = float(fit.params["ppm"]), float(fit.sigma["ppm"])
    extra = dict(fit.extra, time_domain={"ppm": ppm_t, "sigma_ppm": sig_t}, kept="time_domain",
                 chi2_change=chi2_change(ppm_t, ppm_t, sig_t))
    if isinstance(xs, str):
        extra.update(cross_spectral=None, cross_spectral_why=xs)
        return replace(fit, extra=extra)
    ppm_x, sig_x = ratio_to_ppm(xs.gain - 1.0), ratio_to_ppm(xs.sigma)
    extra["cross_spectral"] = {"ppm": ppm_x, "sigma_ppm": sig_x, "lines_hz": [ln.freq_hz for ln in xs.lines],
                               "slope_per_hz2": xs.slope_per_hz2, "chi2": xs.chi2, "dof": xs.dof,
                               "method": xs.describe()}
    diff, comb = ppm_x - ppm_t, float(np.hypot(sig_t, sig_x))
    dchi = chi2_change(ppm_x, ppm_t, sig_t)
    both = (f"scale factor on gyro {fit.gyro}: time domain {pm(ppm_t, sig_t)} ppm, cross-spectral "
            f"{pm(ppm_x, sig_x)} ppm (from {xs.describe()})")
    params, sigma = fit.params, fit.sigma
    if joint_with_nonlinearity:
        said = (f"{both}: the model keeps the time-domain one, fitted jointly with the curvature, which the "
                "lines' gain does not separate")
    elif abs(diff) > CONSISTENT_Z * comb:
        said = (f"{both}: they differ by {_ppm(diff)} ppm, {abs(diff) / comb:.3g} times their combined σ "
                f"({_ppm(comb)} ppm), so one of them is biased (the reference's own lines bend the gain, or "
                f"its noise attenuates the slope): the model keeps the time-domain one: {NOT_CROSS_SPECTRAL}; "
                "check the reference")
    elif sig_x >= sig_t:
        said = (f"{both}: they agree within {CONSISTENT_Z:.3g} times their combined σ ({_ppm(comb)} ppm) and the "
                "cross-spectral one is not the more precise: the model keeps the time-domain one")
    elif dchi >= 0.0:
        said = (f"{both}: they agree within {CONSISTENT_Z:.3g} times their combined σ ({_ppm(comb)} ppm), but keeping the cross-spectral "
                f"one would raise the residual's χ² by {dchi:.3g} against no scale factor: the model keeps the "
                "time-domain one")
    else:
        said = (f"{both}: they agree within {CONSISTENT_Z:.3g} times their combined σ ({_ppm(comb)} ppm), the "
                "cross-spectral one is the more precise, and keeping it "
                f"changes the residual's χ² by {dchi:.3g} against no scale factor: the model keeps the "
                f"cross-spectral one: {KEEP_CROSS_SPECTRAL}")
        params, sigma = dict(fit.params, ppm=ppm_x), dict(fit.sigma, ppm=sig_x)
        extra.update(kept="cross_spectral", chi2_change=dchi)
    extra["reconciled"] = said
    return replace(fit, params=params, sigma=sigma, evidence=f"{fit.evidence}; {said}", extra=extra)


def _scale_fit(fit: GLSFit, i: int, gyro: int, **extra) -> EffectFit:
    b, s = float(fit.beta[i]), float(fit.sigma[i])
    ppm, ppm_s = ratio_to_ppm(b), ratio_to_ppm(s)
    t = b / s
    z = z_two_sided(t)
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} residual {'rises' if b > 0 else 'falls'} {num(abs(b) * 100, 2)} % of the "
              f"rate about its axis ({pm(ppm, ppm_s)} ppm); the model has no such slope")
    else:
        ev = (f"gyro {gyro} residual shows no significant slope with the rate about its axis "
              f"({pm(ppm, ppm_s)} ppm, z = {z:.1f})")
    return EffectFit("scale_factor", gyro, {"ppm": ppm}, {"ppm": ppm_s}, z, ev,
                     fit_extra(fit, t=t, **extra))


def fit_scale_and_nonlinearity(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float,
                               gyro: int, *, use=None, instrument=None) -> tuple[EffectFit, EffectFit]:
    """Scale factor and quadratic nonlinearity fitted jointly.

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
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`~gyroarray.analysis.gls.gls_rw`).
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables) is fitted by instrumental variables, the columns read from
        ``omega_ref_rad_s`` instrumented by the same columns read from this.

    Returns
    -------
    (EffectFit, EffectFit)
        ``scale_factor`` (``ppm``) and ``scale_nonlinearity``
        (``k2_per_deg_s``), each with its own sigma and z (the marginal
        two-sided test of its coefficient in the joint fit); the
        correlation of the two is in ``extra["corr"]`` of both.

    Notes
    -----
    ::

        e_t = s·u_t + k2_SI·u_t² + b_t + w_t,   u_t = h·ω_ref,t
        k2 [1/(deg/s)] = k2_SI [1/(rad/s)] · π/180

    (sim: y = (1 + s)·u + k2·u² in deg/s). Fitting u and u² together keeps a
    linear error out of k2 when the rate is not symmetric about zero.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    as_vector(time_s, n, "time_s")
    _, u = projected_rate(omega_ref_rad_s, h, n)
    ui = None if instrument is None else projected_rate(instrument, h, n)[1]
    try:
        fit = gls_rw(e, np.column_stack([u, u * u]), r, q, use=use,
                     Z=None if ui is None else np.column_stack([ui, ui * ui]))
    except NotIdentifiableError as err:
        why = "the rate about its axis does not vary enough to separate u from u²"
        return (not_identifiable("scale_factor", gyro, {"ppm": 0.0}, why, err),
                not_identifiable("scale_nonlinearity", gyro, {"k2_per_deg_s": 0.0}, why, err))
    corr = float(fit.cov[0, 1] / (fit.sigma[0] * fit.sigma[1]))
    sf = _scale_fit(fit, 0, gyro, joint_with_nonlinearity=True, corr=corr, instrumented=ui is not None)
    b, s = float(fit.beta[1]), float(fit.sigma[1])
    k2, k2_s = per_rad_s_to_per_deg_s(b), per_rad_s_to_per_deg_s(s)
    t = b / s
    z = z_two_sided(t)
    if use is not None:
        u = u[np.asarray(use, dtype=bool)]
    umax = float(rad_s_to_deg_s(np.max(np.abs(u))))
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} residual grows with the square of the rate about its axis "
              f"(k2 = {pm(k2, k2_s)} per deg/s, {num(k2 * umax * umax, 2)} deg/s at "
              f"{num(umax, 3)} deg/s); the model has no such curvature")
    else:
        ev = (f"gyro {gyro} residual shows no significant curvature with the rate about its axis "
              f"(k2 = {pm(k2, k2_s)} per deg/s, z = {z:.1f})")
    nl = EffectFit("scale_nonlinearity", gyro, {"k2_per_deg_s": k2}, {"k2_per_deg_s": k2_s}, z, ev,
                   fit_extra(fit, t=t, corr=corr, ppm_joint=sf.params["ppm"], ppm_joint_z=float(sf.z),
                          instrumented=ui is not None))
    return sf, nl
