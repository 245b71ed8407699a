"""``fault_noise``: from ``start_s`` on, the gyro's white (ARW) part × ``ratio``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gyroarray.effects import _draw
from gyroarray.effects.faults.base import START, FaultEffect
from gyroarray.effects.faults import physics as faults
from gyroarray.effects.protocol import Explained, Param, Stage, identity


class FaultNoise(FaultEffect):
    """The gyro's ARW draw (after the cross-gyro correlation, where ``burst``
    scales it too) × ``ratio`` from ``start_s`` on.

    Fit: the GLR of a change of the innovation variance over the onset
    (:func:`gyroarray.effects.faults.scan.fit_fault`). In a model it is
    simulated in the Monte-Carlo band, and the stochastic record is brought
    back to the gyro's level before the onset (:meth:`whiten`).

    Join-aware (``reads_joins``): on a stitched record the tracker starts again at each join,
    the samples within :data:`~gyroarray.effects.faults.scan.JOIN_GUARD` of a join carry no
    innovation and are left out of the variance scan (and the differences across a join out of
    the ratio), and no onset within ``JOIN_GUARD`` scanned samples of a join is a candidate.
    """

    name = "fault_noise"
    order = 24
    fault_kind = "noise"
    reads_joins = True
    stage = Stage.SHAPE
    stochastic = True
    rivals = ("burst",)
    params = (START, Param("ratio", "-", "ratio", identity, lo=0.0,
                           doc="factor on the gyro's ARW (white) part"))
    doc = "fault: the white (ARW) part × ratio from start_s on"

    def placeholder(self):
        return {"start_s": 1.0, "ratio": 1.0}

    def simulate(self, state, act, streams):
        ctx = state.ctx
        old = state.white.arw_gain                           # a burst's (n,), if any
        gain = np.ones((ctx.n, ctx.n_gyros))
        if old is not None:
            gain *= old[:, None] if old.ndim == 1 else old
        gain[:, act.cols] *= faults.noise_gain(ctx.time_s, act.p["start_s"], act.p["ratio"])
        return replace(state, white=replace(state.white, arw_gain=gain))

    def whiten(self, ctx, entry, x, t):
        after = t >= float(entry.params["start_s"])
        if not after.any():
            return x
        g = int(entry.gyro) - 1
        x = x.copy()
        level = x[after, g].mean()
        x[after, g] = level + (x[after, g] - level) / max(float(entry.params["ratio"]), 1e-6)
        return x

    def test(self, ctx, gyro):
        """The candidate test, except on a quiet quantized counter (the spec's ``quantization`` in
        its correlated regime: output on a coarse grid, the angle moving by less than a couple of
        steps per sample): its increments are mostly 0 with rare ±1 steps, runs of zeros have no
        variance at all, and a Gaussian variance scan reads them as a noise change (a counter of
        step 0.0069 deg whose first 1.5 s read 0: ratio 1e150 at z 211). Not identifiable there."""
        f = super().test(ctx, gyro)
        lat = ctx.effect("quantization").lattice(ctx, int(gyro))
        if not (lat["correlated"] and np.isfinite(f.z) and f.z > 3.0):
            return f
        return replace(f, extra={**f.extra, "identifiable": False,
                                 "reason": (f"the output lies on a grid (angle step {np.degrees(lat['step_rad']):.4g} deg) "
                                            f"and moves by {lat['counts_sd']:.2g} steps per sample: a quiet "
                                            "quantized counter, whose increments a variance scan cannot read")})

    @staticmethod
    def _burst_reading(mine, burst, ctx) -> tuple[bool, bool, float]:
        """(the burst's window reaches an end of the record, only ``mine``'s gyro changed, the
        largest |z| of the others)."""
        t0, t1 = float(ctx.t[0]), float(ctx.t[-1]) + ctx.dt
        margin = max(float(burst.extra.get("block_s", 0.0)), 3.0 * float(burst.sigma.get("end_s", 0.0)),
                     3.0 * float(burst.sigma.get("start_s", 0.0)))
        s, e = float(burst.params["start_s"]), float(burst.params["end_s"])
        to_end = s <= t0 + margin or e >= t1 - margin
        pz = np.abs(np.asarray(burst.extra.get("per_gyro_z", []), float))
        g = int(mine.gyro) - 1
        others = np.delete(pz, g) if 0 <= g < pz.size else pz
        worst = float(others.max()) if others.size else 0.0
        return to_end, worst <= ctx.z_crit, worst

    def prefer(self, mine, other, ctx):
        """A change of the noise on this gyro alone that lasts to the end of the record is this
        fault; the burst's window then reaches an end and the other gyros do not change."""
        if other.effect != "burst":
            return None
        to_end, alone, worst = self._burst_reading(mine, other, ctx)
        if to_end and alone:
            return Explained(f"; but only gyro {mine.gyro} changed (the others |z| <= {worst:.1f}) and the "
                             f"change lasts to the end of the record: a noise fault of gyro {mine.gyro}")
        return None

    def concede(self, mine, other, ctx):
        if other.effect != "burst":
            return None
        to_end, alone, worst = self._burst_reading(mine, other, ctx)
        if not to_end:
            return Explained(f"; but the noise comes back at {other.params['end_s']:.1f} s: a burst, not a "
                             "fault (a fault lasts to the end)")
        if not alone:
            return Explained(f"; but the other gyros changed too (|z| up to {worst:.1f}): a burst, not a "
                             f"fault of gyro {mine.gyro}")
        return None

    def example(self, rng, n_gyros, max_rate_deg_s):
        g = _draw.gyro(rng, n_gyros)
        return g, {"start_s": _draw.u(rng, 200.0, 2000.0), "ratio": _draw.u(rng, 2.0, 5.0)}
