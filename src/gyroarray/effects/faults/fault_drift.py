"""``fault_drift``: from ``start_s`` on, the output + ``rate_deg_s2``·(t − ``start_s``)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.effects import _draw
from gyroarray.effects.faults.base import MEAN_RIVALS, START, MeanFault
from gyroarray.effects.faults import physics as faults
from gyroarray.effects.faults.scan import JOIN_GUARD
from gyroarray.effects.protocol import Param, with_cols


class FaultDrift(MeanFault):
    """A ramp on the final output (after quantization and saturation).

    Fit: the GLR of a ramp over the onset on the gyro's residual, its bias
    tracked as a random walk: a ramp older than the tracker's time constant
    τ shows only as the offset rate·τ (:func:`gyroarray.effects.faults.scan.fit_fault`).
    In a model it is a deterministic part (:meth:`predict`).

    Join-aware like ``fault_step`` (``reads_joins``): on a stitched record the tracker starts
    again at each join, the ramp is scanned within its own part and no onset within
    :data:`~gyroarray.effects.faults.scan.JOIN_GUARD` samples of a join is a candidate (a join's
    offset is the part's own, free in the stitched fit). A drift whose onset lies within its own
    1σ (or ``JOIN_GUARD`` samples) after a join is not told from the part's start: the stitched
    parts' own ramp starting again with their equalised means (a warm-up drifting through both
    parts reads as a saw-tooth), not a fault (:meth:`test`).
    """

    name = "fault_drift"
    order = 22
    fault_kind = "drift"
    reads_joins = True
    rivals = MEAN_RIVALS + ("fault_step",)
    params = (START, Param("rate_deg_s2", "deg/s²", "rate_rad_s2", faults.deg_s2_to_rad_s2,
                           doc="drift rate: output + rate·(t − start_s)"))
    doc = "fault: output + rate·(t − start_s) from start_s on"

    def test(self, ctx, gyro):
        """:meth:`FaultEffect.test`, and on a stitched record a drift not told from a join (its
        onset within max(1σ, ``JOIN_GUARD`` samples) after one) is not identifiable."""
        f = super().test(ctx, gyro)
        breaks = ctx.breaks
        if breaks is None or not (np.isfinite(f.z) and f.z > 3.0) or f.extra.get("identifiable", True) is False:
            return f
        start, sig = float(f.params.get("start_s", math.nan)), float(f.extra.get("onset_sigma_s", 0.0))
        for b in breaks:
            tj = float(ctx.t[int(b)])
            if 0.0 <= start - tj < max(sig, JOIN_GUARD * ctx.dt):
                return replace(f, extra={**f.extra, "identifiable": False,
                                         "reason": (f"onset {start:.6g} ± {sig:.2g} s, not told from the join at "
                                                    f"{tj:.6g} s: the stitched part's own ramp starting again, "
                                                    "not a fault")})
        return f

    def simulate(self, state, act, streams):
        x = state.x[:, act.cols]
        return with_cols(state, act.cols, faults.drift(x, state.ctx.time_s, act.p["start_s"],
                                                       act.p["rate_rad_s2"]))

    def example(self, rng, n_gyros, max_rate_deg_s):
        g = _draw.gyro(rng, n_gyros)
        return g, {"start_s": _draw.u(rng, 200.0, 1800.0),
                   "rate_deg_s2": _draw.sign(rng) * _draw.u(rng, 2e-5, 2e-4, True)}
