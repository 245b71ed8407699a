"""``scale_nonlinearity``: output += k2·input² (residual ∝ rate²)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.analysis.transfer import fundamental_hz, GYRO_LINE_Z, line_cap, line_responses, NoSpectralLines
from gyroarray.effects.fitting import EffectFit, pm, projected_rate, ruled_out, unchecked
from gyroarray.effects.scale_factor import fit_scale_and_nonlinearity
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, with_term
from gyroarray.core.units import per_deg_s_to_per_rad_s, per_rad_s_to_per_deg_s, rad_s_to_deg_s


class ScaleNonlinearity(RegressionEffect):
    """k2·u² on the same input u as the scale factor.

    Rival of the scale factor: on a record whose rates are mostly of one
    sign, k2·u² has a large linear part, so the scale factor's own z can
    exceed the nonlinearity's (which is tested *given* a scale factor). When
    both are significant and the scale factor fitted jointly with the
    curvature is not, the curvature alone explains the residual: it ranks first.
    """

    name = "scale_nonlinearity"
    own_column = True                  # its test reads its gyro's column of the residual only
    order = 10
    stage = Stage.SCALE
    needs = frozenset({"ref", "motion"})
    model_needs = frozenset({"ref"})      # calibrated: regressed on the reference rate
    rivals = ("scale_factor", "misalignment")
    channel = "rate2"
    params = (Param("k2_per_deg_s", "1/(deg/s)", "k2_per_rad_s", per_deg_s_to_per_rad_s,
                    doc="quadratic coefficient: output += k2·input² (deg/s)"),)
    doc = "quadratic scale-factor nonlinearity"

    def simulate(self, state, act, streams):
        return with_term(state, act.cols, act.p["k2_per_rad_s"] * state.u[:, act.cols] ** 2)  # k2·u²

    def regress(self, ctx, gyro, e, r, q):
        e, ref, inst = self.against_reference(ctx, gyro, e)
        fit = fit_scale_nonlinearity(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use, instrument=inst)
        if not fit.extra.get("identifiable", True) or not ctx.moving:
            return fit
        return cap_by_second_harmonic(fit, e, ref, ctx.H[gyro - 1], ctx.dt, use=ctx.use)

    def prefer(self, mine, other, ctx):
        if other.effect == "misalignment":
            # a curvature and a tilted axis both follow the motion's rates: the better fit (AIC)
            return super().prefer(mine, other, ctx)
        if other.effect != "scale_factor":
            return None
        zj = mine.extra.get("ppm_joint_z", math.inf)
        if zj < ctx.z_crit:
            return (f"; but with the curvature fitted the scale factor is "
                    f"{mine.extra['ppm_joint']:.0f} ppm (z = {zj:.1f}): the nonlinearity explains it")
        return None

    def channel_line(self, fit, x, xm, ym):
        return fit.params["k2_per_deg_s"] * x * 3600.0, "k2 " + self._label(fit, "k2_per_deg_s", unit=" /(deg/s)")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"k2_per_deg_s": _draw.u(rng, 1e-5, 6e-5, True) * rng.choice([-1, 1])}


# -- fit ----------------------------------------------------------------------------------
def fit_scale_nonlinearity(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float,
                           gyro: int, *, use=None, instrument=None) -> EffectFit:
    """Quadratic nonlinearity ``k2_per_deg_s``, fitted jointly with the scale factor.

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
        Samples to include.
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables) is fitted by instrumental variables, the columns read from
        ``omega_ref_rad_s`` instrumented by the same columns read from this.

    Returns
    -------
    EffectFit
        The second result of :func:`~gyroarray.effects.scale_factor.fit_scale_and_nonlinearity`.

    Notes
    -----
    ::

        e_t = s·u_t + k2_SI·u_t² + b_t + w_t,   k2 = k2_SI · π/180
    """
    return fit_scale_and_nonlinearity(e, omega_ref_rad_s, h, time_s, dt_s, r, q, gyro, use=use,
                                      instrument=instrument)[1]


def cap_by_second_harmonic(fit: EffectFit, e, omega_ref_rad_s, h, dt_s: float, *, use=None) -> EffectFit:
    """``fit`` refused when the gyro's own line at 2 f0 of a periodic motion rules its k2 out.

    Parameters
    ----------
    fit : EffectFit
        :func:`fit_scale_nonlinearity`'s result.
    e : array_like, shape (n,)
        The residual it was fitted on [rad/s].
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s].
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    dt_s : float
        Sample step [s].
    use : array_like of bool, shape (n,), optional
        Samples that may be read.

    Returns
    -------
    EffectFit
        ``fit`` with ``extra["k2_cap_per_deg_s"]``; refused (:func:`~gyroarray.effects.fitting.ruled_out`)
        when |k2| − GYRO_LINE_Z·σ_k2 exceeds the cap; with ``extra["limit_unchecked"]`` when
        the motion has no line to read.

    Notes
    -----
    A term k2·u² of a motion u periodic at f0 puts a line k2·U2(2 f0) at 2 f0, U2 the line of u²
    there. The gyro's output y = e + u holds that line and whatever else the rate has there, so,
    when the motion has no 2 f0 line of its own (the gyro does not show the reference's 2 f0
    line: what the reference has there is its own error, an encoder's harmonic)::

        |k2| <= |Y(2 f0)/U2(2 f0)| + GYRO_LINE_Z·σ = cap

    and, when the gyro shows the reference's 2 f0 line (an asymmetric swing: the reference is
    right there), the same with the residual's line E(2 f0) for Y(2 f0).

    with Y/U2 the instrumental-variable line ratio of
    :func:`~gyroarray.analysis.transfer.line_responses`. The candidate is ruled out when even
    its lower bound |k2| − GYRO_LINE_Z·σ_k2 is above the cap (its own spread and the line's
    both allowed). MPU-6050 record of issue 44: k2 = (−5.7 ± 1.1)e-4 per deg/s against a cap
    of 5.7e-5 from the gyro's 0.056 deg/s at 2 f0.
    """
    e = np.asarray(e, dtype=float)
    _, u = projected_rate(omega_ref_rad_s, h, e.size)
    try:
        f0 = fundamental_hz(u, dt_s)
    except NoSpectralLines as err:
        return unchecked(fit, f"no 2 f0 line to cap k2: {err}")
    # the motion's own 2 f0 line (an asymmetric swing) is in the gyro's output too: where the gyro
    # shows the reference's 2 f0 line, the residual's line is read instead (the reference right
    # there); where it does not, the reference's line is its own error and the output's is read
    try:
        ref_2f0 = [ln for ln in line_responses(e + u, u, dt_s, f0, use=use, max_harmonics=2) if ln.harmonic == 2]
    except NoSpectralLines:
        ref_2f0 = []
    motion_has_2f0 = bool(ref_2f0) and ref_2f0[0].gain > GYRO_LINE_Z * ref_2f0[0].sigma
    got = line_cap(e if motion_has_2f0 else e + u, u * u, dt_s, f0, 2, use=use)
    if isinstance(got, str):
        return unchecked(fit, f"no 2 f0 line to cap k2: {got}")
    ratio, sig = got
    cap_si = ratio + GYRO_LINE_Z * sig                                 # [1/(rad/s)]
    cap = float(per_rad_s_to_per_deg_s(cap_si))
    k2, s2 = float(fit.params["k2_per_deg_s"]), float(fit.sigma.get("k2_per_deg_s", 0.0))
    line_deg_s = float(rad_s_to_deg_s(ratio * _line_of_square(u, dt_s, f0)))
    numbers = {"k2_cap_per_deg_s": cap, "line_2f0_deg_s": line_deg_s, "f0_hz": float(f0),
               "line_read": "residual" if motion_has_2f0 else "output"}
    out = replace(fit, extra=dict(fit.extra, **numbers))
    if abs(k2) - GYRO_LINE_Z * s2 <= cap:
        return out
    return ruled_out(out, f"a rate² term k2 = {pm(k2, s2)} per deg/s would put a line at 2 f0 = {2 * f0:.4g} Hz "
                          f"that the gyro does not have (its {'residual' if motion_has_2f0 else 'output'} shows {line_deg_s:.3g} "
                          "deg/s there), which caps "
                          f"|k2| at {cap:.2g} per deg/s", **numbers)


def _line_of_square(u: np.ndarray, dt_s: float, f0_hz: float) -> float:
    """Amplitude of u²'s line at 2 f0 over whole cycles [unit of u²] (for the sentence only)."""
    cycles = int(f0_hz * u.size * dt_s)
    n = min(int(round(cycles / (f0_hz * dt_s))), u.size)
    x = u[:n] ** 2
    k = 2 * cycles
    c = np.exp(-2j * np.pi * k * np.arange(n) / n)
    return float(2.0 * abs(np.dot(x - x.mean(), c)) / n)
