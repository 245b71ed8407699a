"""``misalignment``: the true sensitive axis differs from the nominal one."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.effects.fits.regress import fit_misalignment
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.core.physics import tilted_axes
from gyroarray.effects.protocol import Param, RegressionEffect, Stage
from gyroarray.core.units import deg_to_rad


def _unit_axis(x):
    a = np.asarray(x, dtype=float)
    return a / np.linalg.norm(a)


class Misalignment(RegressionEffect):
    """Either ``axis`` (the true unit axis of one named gyro, platform frame, unit
    within 1e-3 and normalised) or ``tilt_deg`` θ (every gyro, or one): the
    nominal axis tilted by θ toward ``tilt_azimuth_deg`` ψ (default 0) around
    it, ψ = 0 toward +z (the cone angle shrinks), ψ = 90° horizontal toward
    increasing azimuth (:func:`gyroarray.core.physics.tilted_axes`). Not both.

    Fit: the residual against the rate about the two axes ⟂ h, with the
    (1 − cos θ)·u term; it returns tilt and azimuth (a model reads them back).
    """

    name = "misalignment"
    order = 11
    stage = Stage.SENSE
    needs = frozenset({"ref", "motion"})
    model_needs = frozenset({"ref"})      # calibrated: regressed on the reference rate
    rivals = ("scale_factor",)
    channel = "other"
    scored = ("tilt_deg", "tilt_azimuth_deg")
    params = (Param("axis", "-", "axis", _unit_axis, kind="axis", required=False,
                    doc="true unit sensitive axis, platform frame"),
              Param("tilt_deg", "deg", "tilt_rad", deg_to_rad, lo=0.0, hi=90.0, required=False,
                    doc="angle between the nominal and the true axis"),
              Param("tilt_azimuth_deg", "deg", "tilt_azimuth_rad", deg_to_rad, required=False,
                    default=0.0, extension=True,
                    doc="direction of the tilt around the nominal axis (0: toward +z)"))
    doc = "true sensitive axis differs from the nominal one"

    def check(self, params, gyro, n_gyros):
        has_axis, has_tilt = "axis" in params, "tilt_deg" in params
        if has_axis and has_tilt:
            raise InputError("give either 'axis' (the true axis) or 'tilt_deg', not both",
                             column="tilt_deg")
        if not (has_axis or has_tilt):
            raise InputError("needs 'axis' (true unit axis, platform frame) or 'tilt_deg'",
                             column="axis")
        if has_axis and gyro is None:
            raise InputError("'axis' is the true axis of one gyro: name the gyro "
                             "(or use 'tilt_deg' for every gyro)", column="axis")
        if "tilt_azimuth_deg" in params and not has_tilt:
            raise InputError("'tilt_azimuth_deg' goes with 'tilt_deg'", column="tilt_azimuth_deg")

    def placeholder(self):
        return {"tilt_deg": 0.0}

    def simulate(self, state, act, streams):
        p = act.p
        nominal = state.ctx.axes[act.cols]
        tilt = np.nan_to_num(p["tilt_rad"])
        az = np.nan_to_num(p["tilt_azimuth_rad"])
        true = np.where(np.isnan(p["axis"]).any(axis=1, keepdims=True),
                        tilted_axes(nominal, tilt, az), p["axis"])
        axes = state.axes.copy()
        axes[act.cols] = true
        return replace(state, axes=axes)

    def regress(self, ctx, gyro, e, r, q):
        e, ref, inst = self.against_reference(ctx, gyro, e)
        return fit_misalignment(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use, instrument=inst)

    def entry_params(self, fit, old):
        params = super().entry_params(fit, old)
        params.pop("axis", None)                 # the fit returns tilt and azimuth
        return params

    def free_parameters(self, fit):
        return int(fit.extra.get("dof_c", 2))     # a tilt seen in one direction only has one

    def channel_line(self, fit, x, xm, ym):
        # the panel's regressor is ω⊥ along the fitted tilt: the residual (a − h)·ω = sin(tilt)·that
        if "tilt_deg" not in fit.params or "axis" not in fit.extra:
            return None
        s = math.sin(math.radians(float(fit.params["tilt_deg"])))
        return s * x * 3600.0, "tilt " + self._label(fit, "tilt_deg", unit="°")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"tilt_deg": _draw.u(rng, 0.2, 1.0, True),
                                          "tilt_azimuth_deg": _draw.u(rng, 0.0, 360.0)}
