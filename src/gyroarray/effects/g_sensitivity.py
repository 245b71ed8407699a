"""``g_sensitivity``: a bias proportional to the specific force at the gyro."""

from __future__ import annotations

import math

import numpy as np

from gyroarray.effects.fitting import EffectFit, chi2_to_z
from gyroarray.analysis.gls import NotIdentifiableError, gls_rw
from gyroarray.analysis.memo import by_content
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, explains_away, with_term
from gyroarray.effects.terms import ForceTerm, spread
from gyroarray.core.sensor import g_sensitivity_bias
from gyroarray.core.units import deg_s_per_g_to_rad_s_per_m_s2, rad_s_per_m_s2_to_deg_s_per_g

#: A component of the specific force that moves less than this [m/s²] over the record
#: (0.01 g) is not identifiable: it joins the unknown starting bias.
MIN_SPAN_M_S2 = 0.0980665


def _g_sens_si(x):
    return deg_s_per_g_to_rad_s_per_m_s2(np.asarray(x, dtype=float))


class GSensitivity(RegressionEffect):
    """bias = (``deg_s_per_g`` · f_k)/g0 [deg/s], f_k = f_0 + α × r_k + ω × (ω × r_k)
    the specific force at gyro k, platform frame (``shared/spec/effects.md``;
    :mod:`gyroarray.core.sensor`).

    Fit: the residual regressed on the three components of f_k under ARW +
    a random-walk bias (:func:`gyroarray.analysis.gls.gls_rw`); f_0 from
    the record's ``acc_*`` columns, else gravity through the attitude
    integrated from ``ref_*`` (level, z up at t = 0), the lever-arm terms
    from ``positions_m``. Components that do not change over the record
    (< 0.01 g) join the starting bias and are reported as 0 without σ.
    z: the χ² of the fitted components (their covariance) as a normal score.
    Rivals: the Earth's rate and a tilted axis also change with attitude; the
    one that leaves the other unexplained ranks first.
    """

    name = "g_sensitivity"
    own_column = True                  # its test reads its gyro's column of the residual only
    order = 19
    stage = Stage.ADD
    needs = frozenset({"acc"})
    sim_needs = frozenset({"acc"})        # the specific force at each gyro (gravity through the attitude)
    slow = True
    rivals = ("earth_rate", "misalignment")
    channel = "acc"
    params = (Param("deg_s_per_g", "(deg/s)/g", "coeff_rad_s_per_m_s2", _g_sens_si, kind="vector",
                    doc="bias = deg_s_per_g · f_k / g0, f_k the specific force at the gyro (platform frame)"),)
    doc = "bias proportional to the specific force at the gyro"

    def predictor_term(self, act, n_gyros):
        """A deterministic error k_i·f_i for the stated specific force at each gyro."""
        return ForceTerm(spread(act, "coeff_rad_s_per_m_s2", n_gyros, (3,)))

    def simulate(self, state, act, streams):
        f = state.ctx.specific_force_m_s2[:, act.cols]                    # f_k, (n, m, 3)
        return with_term(state, act.cols, g_sensitivity_bias(act.p["coeff_rad_s_per_m_s2"], f))

    def placeholder(self):
        return {"deg_s_per_g": (0.0, 0.0, 0.0)}

    def why_not(self, ctx):
        why = super().why_not(ctx)
        if why is None and ctx.acc is None and not ctx.moving:
            return ("needs the specific force to change: acc_x, acc_y, acc_z, or a table that turns "
                    "the array through gravity")
        return why

    def regress(self, ctx, gyro, e, r, q):
        moving, Fm = _moving_force(ctx.specific_force(), int(gyro))
        moving = list(moving)
        coeff, sigma = np.zeros(3), np.full(3, math.nan)
        if not moving:
            return EffectFit(self.name, gyro, {"deg_s_per_g": (0.0, 0.0, 0.0)}, z=0.0,
                             evidence=f"gyro {gyro}: the specific force never changes, so a "
                                      "g-sensitivity cannot be told from the starting bias",
                             extra={"identifiable": False, "reason": "the specific force never changes"})
        try:
            fit = _gls_rw(e, Fm, r, q, use=ctx.use)
        except NotIdentifiableError as err:
            return EffectFit(self.name, gyro, {"deg_s_per_g": (0.0, 0.0, 0.0)}, z=0.0,
                             evidence=f"gyro {gyro}: the specific force components move together; "
                                      "g-sensitivity not identifiable", extra={"identifiable": False,
                                                                                "reason": str(err)})
        beta = fit.beta
        chi2 = float(beta @ np.linalg.solve(fit.cov, beta))
        z = chi2_to_z(chi2, len(moving))
        coeff[moving] = rad_s_per_m_s2_to_deg_s_per_g(beta)
        sigma[moving] = rad_s_per_m_s2_to_deg_s_per_g(fit.sigma)
        axes = "xyz"
        txt = ", ".join(f"{axes[j]} {coeff[j]:.3g} ± {sigma[j]:.2g}" for j in moving)
        if z > 3:
            ev = f"gyro {gyro} residual follows the specific force at the gyro: {txt} (deg/s)/g"
        else:
            ev = f"gyro {gyro} shows no g-sensitivity ({txt} (deg/s)/g, z = {z:.1f})"
        return EffectFit(self.name, gyro, {"deg_s_per_g": tuple(float(c) for c in coeff)},
                         {"deg_s_per_g": [float(s) for s in sigma]}, z=float(z), evidence=ev,
                         extra={"chi2": fit.chi2, "dof": fit.dof, "chi2_beta": chi2,
                                "components": [axes[j] for j in moving]})

    def prefer(self, mine, other, ctx):
        return explains_away(self, mine, other, ctx)

    def example(self, rng, n_gyros, max_rate_deg_s):
        g = _draw.gyro(rng, n_gyros)
        return g, {"deg_s_per_g": tuple(_draw.u(rng, 0.01, 0.2, True) * rng.choice([-1, 1])
                                        for _ in range(3))}


#: :func:`gls_rw` by content: the ranking tests a rival again on records cut by other gyros' fits,
#: where this gyro's residual is as it was, bit for bit.
_gls_rw = by_content(maxsize=16)(gls_rw)


@by_content(maxsize=8)
def _moving(force: np.ndarray, gyro: int) -> tuple:
    """The components j of gyro ``gyro``'s specific force (``force`` (n, N, 3)) whose span reaches
    :data:`MIN_SPAN_M_S2` (kept by content: the same for every test of the gyro on every cut)."""
    F = force[:, gyro - 1, :]
    return tuple(j for j in range(3) if float(np.ptp(F[:, j])) >= MIN_SPAN_M_S2)


def _moving_force(force: np.ndarray, gyro: int) -> tuple:
    """(:func:`_moving`, those components (n, len(j))): a view of ``force`` (a basic slice: any
    sorted subset of three components is one), not a copy; read-only where ``force`` is, so that
    :func:`_gls_rw` keeps its digest. The fit reads it column by column (its differences), the
    same values as a copy's."""
    moving = _moving(force, gyro)
    if not moving:
        return moving, force[:, gyro - 1, :0]
    step = moving[1] - moving[0] if len(moving) > 1 else 1
    assert all(b - a == step for a, b in zip(moving, moving[1:]))       # a progression: 0..2
    return moving, force[:, gyro - 1, moving[0]:moving[-1] + 1:step]
