"""``fault_stuck``: from ``start_s`` on, the last value the gyro gave before ``start_s``, forever."""

from __future__ import annotations

from gyroarray.effects._fault import START, FaultEffect
from gyroarray.errors import InputError
from gyroarray.effects import _fault_physics as faults
from gyroarray.effects.protocol import with_cols


class FaultStuck(FaultEffect):
    """A frozen final output (after quantization and saturation).

    Fit: the run of repeated outputs at the end of the record (exact onset);
    its z from the run's length against how often the gyro repeated a value
    before (:func:`gyroarray.analysis.fault_fit.fit_fault`). In a model the
    samples from the onset on carry no information on the noise: the
    regressions leave them out (:meth:`exclude`).
    """

    name = "fault_stuck"
    order = 23
    fault_kind = "stuck"
    params = (START,)
    doc = "fault: the last value before start_s, forever"

    def simulate(self, state, act, streams):
        try:
            y = faults.stuck(state.x[:, act.cols], state.ctx.time_s, act.p["start_s"])
        except InputError as err:
            raise InputError(f"{act.label}: {err.message}", column=err.column) from None
        return with_cols(state, act.cols, y)

    def exclude(self, ctx, entry):
        after = ctx.t >= float(entry.params["start_s"])
        return after if after.any() and not after.all() else None
