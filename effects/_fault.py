"""What the four fault effects share (``fault_step``, ``fault_drift``, ``fault_stuck``, ``fault_noise``).

A fault starts at ``start_s`` on one gyro (``gyro`` required) and lasts to
the end of the record. The physics is in :mod:`gyroarray.effects._fault_physics`, the fit
(onset and size with 1σ, z ≈ N(0, 1) when absent) in
:func:`gyroarray.analysis.fault_fit.fit_fault`. The faults are not diagnosis
candidates (``candidate = False``): a model comparison fits one when asked
(``fit --add fault_step:K``); looking for faults is the detector's job
(``gyroarray fdi``, :mod:`gyroarray.estimators.fdi`).
"""

from __future__ import annotations

from typing import ClassVar

from gyroarray.analysis.effect_fit import EffectFit
from gyroarray.analysis.fault_fit import fit_fault
from gyroarray.errors import InputError
from gyroarray.effects.protocol import Effect, Kind, Param, Stage, identity

#: The fault's start parameter, shared by the four.
START = Param("start_s", "s", "start_s", identity, doc="fault start (time_s); it lasts to the end")


class FaultEffect(Effect):
    """Base of the four faults: one gyro, from ``start_s`` on; fit by :func:`fit_fault`."""

    fault_kind: ClassVar[str] = ""
    per_gyro = True
    stage = Stage.FAULT
    kind = Kind.TIME
    candidate = False
    channel = "time"

    def check(self, params, gyro, n_gyros):
        if gyro is None:
            raise InputError("a fault acts on one gyro (spec: gyro required): add gyro = k",
                             column="gyro")

    def placeholder(self):
        return {**super().placeholder(), "start_s": 1.0}

    def fit(self, ctx, gyro, E):
        g = int(gyro) - 1
        out = ctx.y[:, g] if self.fault_kind == "stuck" else None
        f = fit_fault(self.fault_kind, E[:, g], ctx.dt, float(ctx.r[g]), float(ctx.q[g]),
                      time_s=ctx.t, output_rad_s=out)
        size = [k for k in f.params if k != "start_s"]
        what = "" if not size else f", {size[0]} {f.params[size[0]]:.4g} ± {f.params_sigma[size[0]]:.2g}"
        evidence = (f"gyro {gyro} {self.fault_kind} from {f.onset_s:.3f} ± {f.onset_sigma_s:.3f} s{what}"
                    + (f" ({f.notes[0]})" if f.notes else ""))
        return EffectFit(self.name, int(gyro), dict(f.params), dict(f.params_sigma), z=f.z,
                         evidence=evidence, extra={"dll": f.dll, "onset_sigma_s": f.onset_sigma_s})

    def free_parameters(self, fit):
        return 2                                         # the onset and the size
