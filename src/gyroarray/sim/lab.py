"""A simulated lab run: the kind of record ``gyroarray compare`` is made for.

:func:`lab_run` builds a :class:`~gyroarray.core.measurement.Measurement` the
way a rate-table session goes: a static part (noise calibration), a
dynamic part that excites every deterministic effect, a static tail. The
reference is the table's rate (exact), the outputs come from
:func:`~gyroarray.sim.effects.simulate_readings` with the given noise
model, the temperature warms up as a board does after power-on.

Dynamic part (rates relative to the Earth, platform frame), in blocks that
repeat until ``motion_s`` is filled:

* rate steps of ±10, ±30, ±60 deg/s about x, y and z in turn, each held
  8 s, reached by 1 s ramps (angular acceleration up to 60 deg/s²), with a
  4 s pause after each, at the new attitude (the Earth rate then projects
  differently: ``earth_rate`` is identifiable);
* a 20 s sinusoidal swing about (x + y + z)/√3 of 40 deg/s at 0.5 Hz
  (every gyro sees a rate about its axis and about the others, and
  ±126 deg/s² of acceleration: latency).

``protocol="table"`` is instead the session of the practice measurements'
README (``../shared/measurements/README.md``), a 3-axis rate table: after
the static part, rate steps about z of 10, 30, 50, 80 deg/s, then +30 and
−30 deg/s about x and about y (each 60 s: 2 s smooth ramps, 56 s hold), a
120 s swing about z of 20 deg/s at 0.1 Hz and a 60 s one of 5 deg/s at
0.5 Hz (``motion_s`` = 900 s of it), the static tail. It is how
``benchmarks/diagnosis_score.py`` scores the diagnosis on records shaped
like the held-out set's.

Units: SI inside; ``gyro_deg_s``/``ref_deg_s`` of the measurement in deg/s.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gyroarray.effects import get_effect
from gyroarray.effects.earth_rate import attitude_from_rates
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, Site
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.core.units import RAD_PER_DEG

__all__ = ["lab_profile", "table_profile", "lab_temperature", "lab_run"]


def _ramp_hold(t: np.ndarray, t0: float, level: float, ramp: float, hold: float) -> np.ndarray:
    """0 → level in ``ramp`` s, held ``hold`` s, back to 0 in ``ramp`` s, starting at t0."""
    a = np.clip((t - t0) / ramp, 0.0, 1.0)
    b = np.clip((t - (t0 + ramp + hold)) / ramp, 0.0, 1.0)
    return level * (a - b)


def lab_profile(time_s: np.ndarray, static_s: float, motion_s: float) -> np.ndarray:
    """Reference rate [rad/s], shape (n, 3): static, the dynamic blocks, static."""
    t = np.asarray(time_s, float) - float(time_s[0])
    out = np.zeros((t.size, 3))
    t0 = float(static_s)
    end = t0 + float(motion_s)
    ramp, hold, pause = 1.0, 8.0, 4.0
    seg = 2 * ramp + hold + pause
    while True:
        for axis in range(3):
            for level in (10.0, -30.0, 60.0, -10.0, 30.0, -60.0):
                if t0 + seg > end:
                    return out
                out[:, axis] += _ramp_hold(t, t0, level * RAD_PER_DEG, ramp, hold)
                t0 += seg
        swing = 20.0
        if t0 + swing + pause > end:
            return out
        inside = (t >= t0) & (t < t0 + swing)
        w = 40.0 * RAD_PER_DEG * np.sin(2.0 * math.pi * 0.5 * (t[inside] - t0))
        out[inside] += w[:, None] / math.sqrt(3.0)
        t0 += swing + pause


def _smooth_step(t: np.ndarray, t0: float, level: float, ramp: float, hold: float) -> np.ndarray:
    """0 → level by a smoothstep (3x² − 2x³) of ``ramp`` s, held ``hold`` s, back to 0 the same way."""
    up = np.clip((t - t0) / ramp, 0.0, 1.0)
    down = np.clip((t - (t0 + ramp + hold)) / ramp, 0.0, 1.0)
    return level * (up * up * (3.0 - 2.0 * up) - down * down * (3.0 - 2.0 * down))


def table_profile(time_s: np.ndarray, static_s: float, motion_s: float = 900.0) -> np.ndarray:
    """Reference rate [rad/s], shape (n, 3), of the 3-axis table session (``protocol="table"``).

    Blocks (deg/s, platform frame), cut at ``static_s + motion_s``: z 10, 30,
    50, 80; x +30, −30; y +30, −30 (60 s each: 2 s ramps, 56 s hold); z
    swing 20 at 0.1 Hz for 120 s; z swing 5 at 0.5 Hz for 60 s (both faded in
    and out over 2 s).
    """
    t = np.asarray(time_s, float) - float(time_s[0])
    out = np.zeros((t.size, 3))
    t0, end = float(static_s), float(static_s) + float(motion_s)
    steps = [(2, 10.0), (2, 30.0), (2, 50.0), (2, 80.0), (0, 30.0), (0, -30.0), (1, 30.0), (1, -30.0)]
    for axis, level in steps:
        if t0 + 60.0 > end:
            return out
        out[:, axis] += _smooth_step(t, t0, level * RAD_PER_DEG, 2.0, 56.0)
        t0 += 60.0
    for amp, f, length in ((20.0, 0.1, 120.0), (5.0, 0.5, 60.0)):
        if t0 + length > end:
            return out
        # amplitude faded in and out by the same 2 s smooth ramps
        envelope = _smooth_step(t, t0, 1.0, 2.0, length - 4.0)
        out[:, 2] += envelope * amp * RAD_PER_DEG * np.sin(2.0 * math.pi * f * (t - t0))
        t0 += length
    return out


def lab_temperature(time_s: np.ndarray, start_c: float = 25.0, rise_c: float = 10.0,
                    tau_s: float = 900.0, wobble_c: float = 0.0, wobble_period_s: float = 1300.0) -> np.ndarray:
    """Warm-up after power-on [°C]: start + rise·(1 − exp(−t/τ)) + wobble·sin(2πt/period)."""
    t = np.asarray(time_s, float) - float(time_s[0])
    return (start_c + rise_c * (1.0 - np.exp(-t / tau_s))
            + wobble_c * np.sin(2.0 * math.pi * t / wobble_period_s))


def lab_run(model: NoiseModel, layout: Layout, rng: np.random.Generator, *,
            rate_hz: float = 50.0, static_s: float = 600.0, motion_s: float = 300.0,
            tail_s: float = 300.0, latitude_deg: float | None = 34.25, heading_deg: float = 0.0,
            temperature: bool = True, reference: bool = True, protocol: str = "steps",
            description: str = "") -> Measurement:
    """A simulated rate-table session of ``layout`` with the effects of ``model``.

    Parameters
    ----------
    model : NoiseModel
        The effects (spec units).
    layout : Layout
        The array.
    rng : numpy.random.Generator
        The only randomness.
    rate_hz : float
        Sample rate [Hz].
    static_s, motion_s, tail_s : float
        Lengths of the static part, the dynamic part and the static tail [s].
    latitude_deg, heading_deg : float
        Site [deg] (``earth_rate``); latitude None = no ``[site]``.
    temperature, reference : bool
        Record ``temp_c`` / ``ref_*``.
    protocol : {"steps", "table"}
        The dynamic part: this module's steps and swings about x, y, z and
        (1,1,1)/√3, or the practice set's table session (see the module
        docstring; its natural lengths are static 1200 s, motion 900 s,
        tail 300 s).
    description : str
        Sidecar text.

    Returns
    -------
    Measurement
    """
    dt = 1.0 / float(rate_hz)
    n = int(round((static_s + motion_s + tail_s) * rate_hz))
    t = np.arange(n) * dt
    if protocol not in ("steps", "table"):
        raise ValueError(f"protocol must be 'steps' or 'table', not {protocol!r}")
    ref = (lab_profile if protocol == "steps" else table_profile)(t, static_s, motion_s)
    # the table session's room: a faster, larger warm-up with a slow wobble (practice README)
    temp = lab_temperature(t) if protocol == "steps" else lab_temperature(t, rise_c=12.0, wobble_c=0.5)
    site = None if latitude_deg is None else Site(latitude_deg * RAD_PER_DEG, heading_deg * RAD_PER_DEG)
    kw: dict[str, Any] = {"time_s": t, "temp_c": temp}
    needs = frozenset().union(*(get_effect(e.effect).sim_needs for e in model))
    if "site" in needs:
        kw["site"] = site
    if needs & {"attitude", "acc"}:
        kw["attitude"] = attitude_from_rates(ref, dt)      # gravity moves with the attitude too
    y = simulate_readings(model, ref, layout, dt, rng, **kw)
    return Measurement(time_s=t, gyro_deg_s=y / RAD_PER_DEG, layout=layout, sample_rate_hz=float(rate_hz),
                       ref_deg_s=ref / RAD_PER_DEG if reference else None,
                       temp_c=temp if temperature else None, site=site,
                       description=description or "simulated lab run (gyroarray.sim.lab)")
