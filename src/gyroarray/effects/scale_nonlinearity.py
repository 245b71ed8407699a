"""``scale_nonlinearity``: output += k2·input² (residual ∝ rate²)."""

from __future__ import annotations

import math

from gyroarray.effects.fitting import EffectFit
from gyroarray.effects.scale_factor import fit_scale_and_nonlinearity
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, with_term
from gyroarray.core.units import per_deg_s_to_per_rad_s


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
        return fit_scale_nonlinearity(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use, instrument=inst)

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
