"""``gauss_markov``: first-order Gauss–Markov rate noise (ADEV hump near 1.89·τc)."""

from __future__ import annotations

from gyroarray.effects import _draw
from gyroarray.core.physics import gauss_markov_noise
from gyroarray.effects.protocol import NoiseTermEffect, Param, Stage, identity, with_term
from gyroarray.core.units import deg_h_to_rad_s

#: Longest correlation time a model may give [s] (about 30 years): over any record the process is
#: then a random walk (the hump sits at 1.89·τc), and beyond it τc² overflows the Allan model.
MAX_TAU_S = 1e9


class GaussMarkov(NoiseTermEffect):
    """Exact AR(1) discretisation with a stationary start (:func:`gyroarray.core.physics.gauss_markov_noise`).

    Fit: a hump of the gyro's Allan model, the correlation time scanned and
    the z calibrated for the scan (:mod:`gyroarray.effects.fits.stochastic_fit`).
    """

    name = "gauss_markov"
    order = 6
    stage = Stage.ADD
    rivals = ("bias_instability", "quantization")
    params = (Param("sigma_deg_h", "deg/h", "sigma_rad_s", deg_h_to_rad_s, lo=0.0, doc="stationary σ"),
              Param("tau_s", "s", "tau_s", identity, lo=0.0, lo_open=True, hi=MAX_TAU_S,
                    doc="correlation time τc"))
    doc = "first-order Gauss–Markov rate noise"

    def simulate(self, state, act, streams):
        ctx = state.ctx
        z = streams.normals(self.name, act.cols, ctx.n)
        return with_term(state, act.cols,
                         gauss_markov_noise(ctx.n, ctx.dt_s, act.p["sigma_rad_s"], act.p["tau_s"], z))

    def noise_term(self, ctx, entry):
        return {"gm_tau_s": float(entry.params["tau_s"])}

    def entry_params(self, fit, old):
        params = super().entry_params(fit, old)
        if params.get("sigma_deg_h", 0.0) <= 0:
            params["sigma_deg_h"] = 0.0
        return params

    def free_parameters(self, fit):
        return 2

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"sigma_deg_h": _draw.u(rng, 50.0, 300.0, True),
                                          "tau_s": _draw.u(rng, 0.2, 20.0, True)}
