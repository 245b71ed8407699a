"""``fault_drift``: from ``start_s`` on, the output + ``rate_deg_s2``·(t − ``start_s``)."""

from __future__ import annotations

from gyroarray.effects import _draw
from gyroarray.effects.faults.base import MEAN_RIVALS, START, MeanFault
from gyroarray.effects.faults import physics as faults
from gyroarray.effects.protocol import Param, with_cols


class FaultDrift(MeanFault):
    """A ramp on the final output (after quantization and saturation).

    Fit: the GLR of a ramp over the onset on the gyro's residual, its bias
    tracked as a random walk: a ramp older than the tracker's time constant
    τ shows only as the offset rate·τ (:func:`gyroarray.effects.faults.scan.fit_fault`).
    In a model it is a deterministic part (:meth:`predict`).
    """

    name = "fault_drift"
    order = 22
    fault_kind = "drift"
    rivals = MEAN_RIVALS + ("fault_step",)
    params = (START, Param("rate_deg_s2", "deg/s²", "rate_rad_s2", faults.deg_s2_to_rad_s2,
                           doc="drift rate: output + rate·(t − start_s)"))
    doc = "fault: output + rate·(t − start_s) from start_s on"

    def simulate(self, state, act, streams):
        x = state.x[:, act.cols]
        return with_cols(state, act.cols, faults.drift(x, state.ctx.time_s, act.p["start_s"],
                                                       act.p["rate_rad_s2"]))

    def example(self, rng, n_gyros, max_rate_deg_s):
        g = _draw.gyro(rng, n_gyros)
        return g, {"start_s": _draw.u(rng, 200.0, 1800.0),
                   "rate_deg_s2": _draw.sign(rng) * _draw.u(rng, 2e-5, 2e-4, True)}
