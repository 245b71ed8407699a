"""``fault_step``: from ``start_s`` on, the gyro outputs its normal output + ``size_deg_s``."""

from __future__ import annotations

from gyroarray.effects._fault import START, FaultEffect
from gyroarray.effects import _fault_physics as faults
from gyroarray.effects.protocol import Param, with_cols
from gyroarray.units import deg_s_to_rad_s


class FaultStep(FaultEffect):
    """A step on the final output (after quantization and saturation).

    Fit: the GLR of a step over the onset on the gyro's residual, its
    bias tracked as a random walk (:func:`gyroarray.analysis.fault_fit.fit_fault`).
    In a model it is a deterministic part (:meth:`predict`).
    """

    name = "fault_step"
    order = 21
    fault_kind = "step"
    predicts = True
    params = (START, Param("size_deg_s", "deg/s", "size_rad_s", deg_s_to_rad_s,
                           doc="step added to the output"))
    doc = "fault: output + size from start_s on"

    def simulate(self, state, act, streams):
        x = state.x[:, act.cols]
        return with_cols(state, act.cols, faults.step(x, state.ctx.time_s, act.p["start_s"],
                                                      act.p["size_rad_s"]))
