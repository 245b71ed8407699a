"""``fault_step``: from ``start_s`` on, the gyro outputs its normal output + ``size_deg_s``."""

from __future__ import annotations

from gyroarray.effects import _draw
from gyroarray.effects.faults.base import MEAN_RIVALS, START, MeanFault
from gyroarray.effects.faults import physics as faults
from gyroarray.effects.protocol import Param, with_cols
from gyroarray.core.units import deg_s_to_rad_s


class FaultStep(MeanFault):
    """A step on the final output (after quantization and saturation).

    Fit: the GLR of a step over the onset on the gyro's residual, its
    bias tracked as a random walk (:func:`gyroarray.effects.faults.scan.fit_fault`).
    In a model it is a deterministic part (:meth:`predict`).

    On a record stitched from still parts (``FitContext.parts``) a join is a known
    break whose offset the stitched fit already has free: the tracker starts again
    at each join and no onset within :data:`~gyroarray.effects.faults.scan.JOIN_GUARD`
    samples of one is a candidate (``reads_joins``).
    """

    name = "fault_step"
    order = 21
    fault_kind = "step"
    reads_joins = True
    rivals = MEAN_RIVALS + ("fault_drift",)
    params = (START, Param("size_deg_s", "deg/s", "size_rad_s", deg_s_to_rad_s,
                           doc="step added to the output"))
    doc = "fault: output + size from start_s on"

    def simulate(self, state, act, streams):
        x = state.x[:, act.cols]
        return with_cols(state, act.cols, faults.step(x, state.ctx.time_s, act.p["start_s"],
                                                      act.p["size_rad_s"]))

    def example(self, rng, n_gyros, max_rate_deg_s):
        g = _draw.gyro(rng, n_gyros)
        return g, {"start_s": _draw.u(rng, 200.0, 2200.0),
                   "size_deg_s": _draw.sign(rng) * _draw.u(rng, 0.02, 0.2, True)}
