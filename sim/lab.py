"""A simulated lab run: the kind of record ``gyroarray compare`` is made for.

:func:`lab_run` builds a :class:`~gyroarray.measurement.Measurement` the
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

Units: SI inside; ``gyro_deg_s``/``ref_deg_s`` of the measurement in deg/s.
"""

from __future__ import annotations

import math

import numpy as np

from gyroarray.layout import Layout
from gyroarray.measurement import Measurement, Site
from gyroarray.sim.effects import simulate_readings
from gyroarray.sim.model import NoiseModel
from gyroarray.units import RAD_PER_DEG

__all__ = ["lab_profile", "lab_temperature", "lab_run"]


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


def lab_temperature(time_s: np.ndarray, start_c: float = 25.0, rise_c: float = 10.0,
                    tau_s: float = 900.0) -> np.ndarray:
    """Warm-up after power-on [°C]: start + rise·(1 − exp(−t/τ))."""
    t = np.asarray(time_s, float) - float(time_s[0])
    return start_c + rise_c * (1.0 - np.exp(-t / tau_s))


def lab_run(model: NoiseModel, layout: Layout, rng: np.random.Generator, *,
            rate_hz: float = 50.0, static_s: float = 600.0, motion_s: float = 300.0,
            tail_s: float = 300.0, latitude_deg: float | None = 34.25, heading_deg: float = 0.0,
            temperature: bool = True, reference: bool = True, description: str = "") -> Measurement:
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
    description : str
        Sidecar text.

    Returns
    -------
    Measurement
    """
    from gyroarray.analysis.earth_fit import attitude_from_rates

    dt = 1.0 / float(rate_hz)
    n = int(round((static_s + motion_s + tail_s) * rate_hz))
    t = np.arange(n) * dt
    ref = lab_profile(t, static_s, motion_s)
    temp = lab_temperature(t)
    site = None if latitude_deg is None else Site(latitude_deg * RAD_PER_DEG, heading_deg * RAD_PER_DEG)
    kw = {"time_s": t, "temp_c": temp}
    if any(e.effect == "earth_rate" for e in model):
        kw["attitude"] = attitude_from_rates(ref, dt)
        kw["site"] = site
    y = simulate_readings(model, ref, layout, dt, rng, **kw)
    return Measurement(time_s=t, gyro_deg_s=y / RAD_PER_DEG, layout=layout, sample_rate_hz=float(rate_hz),
                       ref_deg_s=ref / RAD_PER_DEG if reference else None,
                       temp_c=temp if temperature else None, site=site,
                       description=description or "simulated lab run (gyroarray.sim.lab)")
