"""What the four fault effects share (``fault_step``, ``fault_drift``, ``fault_stuck``, ``fault_noise``).

A fault starts at ``start_s`` on one gyro (``gyro`` required) and lasts to
the end of the record. The physics is in :mod:`gyroarray.effects.faults.physics`, the fit
(onset and size with 1σ, z ≈ N(0, 1) when absent) in
:func:`gyroarray.effects.faults.scan.fit_fault`. The faults are not diagnosis
candidates too: ``diagnose`` names a fault like any other missing effect,
and ``fit --add fault_step:K`` fits one. Watching a running array for faults
is the detector's job (``gyroarray fdi``, :mod:`gyroarray.estimators.fdi`).

Rivals. A fault's test reads the gyro's residual with its bias tracked as a
random walk, so a deterministic effect that moves the residual (a tilted
axis on the table's steps, a warm-up, a clip) also raises a step or a drift,
and a fault raises them in turn. Which one the record shows is decided by
explaining away, both ways (:func:`rank_against`): the one whose fit, taken
out of the record, leaves the other unseen ranks first; where each leaves
the other unseen (or neither does), their z's decide.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import ClassVar

import numpy as np

from gyroarray.analysis.memo import by_content
from gyroarray.analysis.motion_events import locking_test, near_events, reference_events, window_samples
from gyroarray.effects.fitting import EffectFit
from gyroarray.effects.faults.scan import fit_fault
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Effect, Kind, Param, Stage, explains_away, identity

#: The per-gyro deterministic effects whose fits also move a gyro's residual mean, rivals of a
#: step or a drift (each one's fit predicts what it takes out of the record).
MEAN_RIVALS = ("rate_ramp", "sinusoid", "scale_factor", "scale_nonlinearity", "misalignment",
               "temperature_bias", "latency", "saturation", "bandwidth", "g_sensitivity")


def rank_against(mine_effect: Effect, mine, other, ctx) -> str | None:
    """Why ``other`` ranks below ``mine`` when both predict: ``mine`` taken out leaves ``other``
    unseen and ``other`` taken out does not leave ``mine`` unseen (else None: each explains the
    other, or neither does, and the z's decide)."""
    why = explains_away(mine_effect, mine, other, ctx)
    if not why:
        return None
    if explains_away(ctx.effect(other.effect), other, mine, ctx):
        return None
    return why


#: :func:`fit_fault` by content: a ladder's steps leave most gyros' residuals as they were, bit
#: for bit (1.2 s of fault tests per analysis of the ADIS16405's 1e6 samples otherwise).
_fit_fault = by_content(maxsize=32)(fit_fault)

#: Samples a fault must have on each side of its onset to be told from a glitch at an end of the
#: record: fewer carry its size or its variance ratio on a handful of values (a variance ratio
#: on 31 degrees of freedom already has a 1σ of 25 %).
MIN_RUN = 32

#: The fault's start parameter, shared by the four.
START = Param("start_s", "s", "start_s", identity, doc="fault start (time_s); it lasts to the end")


class FaultEffect(Effect):
    """Base of the four faults: one gyro, from ``start_s`` on; fit by :func:`fit_fault`."""

    fault_kind: ClassVar[str] = ""
    #: The scan restarts at the joins of stitched parts (``breaks`` of :func:`fit_fault`).
    reads_joins: ClassVar[bool] = False
    per_gyro = True
    stage = Stage.FAULT
    kind = Kind.TIME
    candidate = True
    channel = "time"

    def check(self, params, gyro, n_gyros):
        if gyro is None:
            raise InputError("a fault acts on one gyro (spec: gyro required): add gyro = k",
                             column="gyro")

    def placeholder(self):
        return {**super().placeholder(), "start_s": 1.0}

    def fit(self, ctx, gyro, E):
        g = int(gyro) - 1
        # samples the model leaves out at the end (a frozen gyro from its onset on) are cut off;
        # a window inside the record (a burst) is read as it is: the scan needs a uniform clock.
        # Not for a frozen output's own fit: it reads the whole run (cut, it found its last sample)
        n = ctx.n if self.fault_kind == "stuck" else ctx.noise_end
        out = ctx.y[:n, g] if self.fault_kind == "stuck" else None
        # a noise fault in the model brought back to its level (not this fault's own entry: it is
        # what this fit reads)
        e = ctx.at_model_level(E[:n], ctx.t[:n], but=(self.name, int(gyro)))[:, g]
        quiet = np.zeros(n, bool)                        # a clip's plateau: no noise to read there
        for entry in ctx.model or ():
            m = ctx.effect(entry.effect).silent(ctx, entry)
            if m is not None:
                quiet |= m[:n, g]
        f = _fit_fault(self.fault_kind, e, ctx.dt, float(ctx.r[g]), float(ctx.q[g]),
                       time_s=ctx.t[:n], output_rad_s=out, skip=quiet if quiet.any() else None,
                       breaks=ctx.breaks if self.reads_joins else None)
        size = [k for k in f.params if k != "start_s"]
        what = "" if not size else f", {size[0]} {f.params[size[0]]:.4g} ± {f.params_sigma[size[0]]:.2g}"
        evidence = (f"gyro {gyro} {self.fault_kind} from {f.onset_s:.3f} ± {f.onset_sigma_s:.3f} s{what}"
                    + (f" ({f.notes[0]})" if f.notes else ""))
        return EffectFit(self.name, int(gyro), dict(f.params), dict(f.params_sigma), z=f.z,
                         evidence=evidence, extra={"dll": f.dll, "onset_sigma_s": f.onset_sigma_s})

    def test(self, ctx, gyro):
        """The candidate test; a fault whose onset cannot be told from the record's start (within
        3σ of it) is not identifiable as a fault: a step there is the unknown turn-on bias, a
        noise change a warm-up (the CATS tag's first 89 ± 102 s). Asked of a fit beyond z = 3
        only: one that sees nothing has no onset to speak of. A drift's onset is loose (± 50–200 s
        on the scoring records) and a drift from the start is a rate ramp, its rival: the ranking
        decides that.

        Nor is a step or noise change whose onset lies within :data:`MIN_RUN` samples of the start,
        nor any of the three whose onset lies within :data:`MIN_RUN` samples of the end or whose
        whole life after its onset lies within the onset's own 1σ: what it reads is a handful of
        samples, which a glitch makes as well (the MPU-6050 record ends in a reversal of its stepper, and its
        last three samples read as a step and a drift on gyros 1 and 2 from 1499.87 ± 10–120 s of
        1499.91). 1σ at the end, not 3σ: a drift's onset is loose, and a real one from 1800 ± 200 s
        of a 2200 s record is still there to see."""
        f = super().test(ctx, gyro)
        if not (self.fault_kind != "stuck" and np.isfinite(f.z) and f.z > 3.0):
            return f
        start, sig = float(f.params.get("start_s", math.nan)), float(f.extra.get("onset_sigma_s", 0.0))
        end = float(ctx.t[ctx.noise_end - 1]) + ctx.dt
        if self.fault_kind != "drift" and start - float(ctx.t[0]) < max(3.0 * sig, MIN_RUN * ctx.dt):
            why = "not told from the record's start: a turn-on transient, not a fault"
        elif end - start < max(sig, MIN_RUN * ctx.dt):
            why = (f"{end - start:.3g} s before the record's end ({end:.6g} s): too few samples after "
                   "it to tell a fault from a glitch of the last ones")
        else:
            return self._at_motion_event(ctx, int(gyro), f) if self.fault_kind == "step" else f
        return replace(f, extra={**f.extra, "identifiable": False,
                                 "reason": f"onset {start:.6g} ± {sig:.2g} s, {why}"})

    def _at_motion_event(self, ctx, gyro: int, f: EffectFit) -> EffectFit:
        """A step whose onset lies within :data:`~gyroarray.analysis.motion_events.WINDOW_S` of
        an event of the reference (a reversal, a plateau edge, a jerk) is fitted again with the
        samples near every event bridged (linear between the samples either side): a step that
        is no longer seen (z <= 3) was the gyro's response to the motion (a jerk sensitivity, or
        the reference's own error), and is named so (``extra["motion_locked"]``, z of the
        bridged fit), not a fault. A real step at an event stays: the levels either side of
        the bridge still differ."""
        if ctx.ref is None or not ctx.moving:
            return f
        key = ("motion_events",)
        if key not in ctx.cache:
            ctx.cache[key] = reference_events(ctx.ref, ctx.dt)
        n = ctx.noise_end
        ev = ctx.cache[key][ctx.cache[key] < n]
        w = window_samples(ctx.dt)
        i = int(np.clip(np.searchsorted(ctx.t[:n], float(f.params["start_s"])), 0, n - 1))
        if ev.size == 0 or not near_events(ev, n, w)[i]:
            return f
        near = near_events(ev, ctx.n, w)
        if near.all():
            return f
        E = np.array(ctx.E, dtype=float, copy=True)
        k = np.arange(ctx.n)
        E[near, gyro - 1] = np.interp(k[near], k[~near], E[~near, gyro - 1])
        g = self.fit(ctx, gyro, E)
        if not (np.isfinite(g.z) and g.z <= 3.0):
            return f
        _, chance, p = locking_test(ev, [i], n, w)
        sentence = (f"gyro {gyro}: motion-locked response: the step at {f.params['start_s']:.6g} s lies within "
                    f"{w * ctx.dt:g} s of the reference's reversals/plateau edges/jerks ({100 * chance:.1f} % of "
                    f"the record by chance) and, with the samples near them bridged, no step is seen (z = "
                    f"{g.z:.1f}, was {f.z:.1f}); a jerk sensitivity or the reference's own error, not a fault")
        lock = {"kind": "motion_locked", "candidate": self.name, "gyro": gyro, "n_events": 1,
                "window_s": w * ctx.dt, "fraction_near": 1.0, "fraction_chance": chance, "p_value": p,
                "z_bridged": float(g.z), "sentence": sentence}
        return replace(f, z=float(g.z), evidence=sentence, extra={**f.extra, "motion_locked": lock})

    def free_parameters(self, fit):
        return 2                                         # the onset and the size


class MeanFault(FaultEffect):
    """A step or a drift: a fault that moves the gyro's mean, ranked against the deterministic
    effects that move it too by explaining away both ways (:func:`rank_against`)."""

    predicts = True
    own_column = True          # its test reads its gyro's column of the residual only

    def prefer(self, mine, other, ctx):
        return rank_against(self, mine, other, ctx)

    def concede(self, mine, other, ctx):
        return rank_against(ctx.effect(other.effect), other, mine, ctx)
