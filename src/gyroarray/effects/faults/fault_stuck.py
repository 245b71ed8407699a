"""``fault_stuck``: from ``start_s`` on, the last value the gyro gave before ``start_s``, forever."""

from __future__ import annotations

import numpy as np

from gyroarray.effects import _draw
from gyroarray.effects.faults.base import MEAN_RIVALS, START, FaultEffect
from gyroarray.core.errors import InputError
from gyroarray.effects.faults import physics as faults
from gyroarray.effects.protocol import no_longer_seen, with_cols


class FaultStuck(FaultEffect):
    """A frozen final output (after quantization and saturation).

    Fit: the run of repeated outputs at the end of the record (exact onset);
    its z from the run's length against how often the gyro repeated a value
    before (:func:`gyroarray.effects.faults.scan.fit_fault`). In a model the
    samples from the onset on carry no information on the noise: the
    regressions leave them out (:meth:`exclude`), the stochastic tests end
    at the onset, and its prediction (the reference's projection frozen at
    the onset, minus the projection) takes the rate out of the residual there,
    for the tests that read the whole record.
    """

    name = "fault_stuck"
    order = 23
    fault_kind = "stuck"
    predicts = True
    #: a frozen output is a flat residual that is minus the rate: it reads as a clip, a scale
    #: factor of −100 %, a tilt, a step, a drop of the noise, ...; its run of identical values
    #: is what nothing else makes
    rivals = MEAN_RIVALS + ("fault_step", "fault_drift", "fault_noise", "quantization", "gauss_markov",
                            "bias_instability", "outliers")
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

    def prefer(self, mine, other, ctx):
        """A significant frozen run ranks first on its gyro: every other fit there reads the frozen
        output. Explained when the other's test, with the samples from the onset left out, is no
        longer significant."""
        if not (np.isfinite(mine.z) and mine.z > ctx.z_crit) or other.gyro not in (None, mine.gyro):
            return None
        start = float(mine.params["start_s"])
        after = ctx.t >= start
        what = f"; but gyro {mine.gyro}'s output is frozen from {start:.2f} s on, and this fit reads it"
        if not after.any() or after.all():
            return what
        return no_longer_seen(ctx.leaving_out(after), other, ctx,
                              f"gyro {mine.gyro}'s frozen output from {start:.2f} s left out") or what

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"start_s": _draw.u(rng, 300.0, 2200.0)}
