"""Speed of the noise injector (:func:`gyroarray.sim.effects.simulate_readings`).

Two models on an 8-gyro Scheme 1 array, 1 h at 100 Hz (360 000 samples per
gyro): the paper baseline (ARW + RRW + correlation of both) and a model with
all 17 effects. Prints the best of a few runs and the throughput in gyro
samples per second (samples × gyros / s). No speed target yet: the numbers
are for comparison between versions.
"""

from __future__ import annotations

import math

import numpy as np
from _timing import best_of

from gyroarray.core.layout import Layout
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.core.units import deg_s_to_rad_s, deg_to_rad

N_GYROS = 8
RATE_HZ = 100.0
DURATION_S = 3600.0
REPEATS = 3

BASELINE = [
    {"effect": "arw", "n_deg_rt_h": 0.1},
    {"effect": "rrw", "k_deg_h_rt_h": 10.0},
    {"effect": "correlation", "rho_arw": 0.2, "rho_rrw": 0.1},
]

ALL17 = BASELINE + [
    {"effect": "misalignment", "gyro": 1, "tilt_deg": 0.3},
    {"effect": "earth_rate", "latitude_deg": 34.25},
    {"effect": "latency", "delay_s": 0.003},
    {"effect": "scale_factor", "ppm": 500},
    {"effect": "scale_nonlinearity", "k2_per_deg_s": 1e-5},
    {"effect": "burst", "start_s": 600.0, "end_s": 900.0, "variance_ratio": 4.0},
    {"effect": "bias_instability", "b_deg_h": 5.0},
    {"effect": "rate_ramp", "r_deg_h2": 10.0},
    {"effect": "gauss_markov", "sigma_deg_h": 10.0, "tau_s": 20.0},
    {"effect": "sinusoid", "amp_deg_s": 0.01, "freq_hz": 3.0},
    {"effect": "constant_bias", "bias_deg_h": 20.0},
    {"effect": "temperature_bias", "deg_h_per_c": 0.5, "t0_c": 25.0},
    {"effect": "quantization", "q_deg": 1e-4},
    {"effect": "saturation", "range_deg_s": 400.0},
]


def _inputs(n: int):
    t = np.arange(n) / RATE_HZ
    w = np.zeros((n, 3))
    w[:, 2] = deg_s_to_rad_s(30.0) * np.sin(2 * np.pi * t / 60.0)
    yaw = np.cumsum(w[:, 2]) / RATE_HZ              # the platform turns about up
    c, s = np.cos(yaw), np.sin(yaw)
    att = np.zeros((n, 3, 3))
    att[:, 0, 0], att[:, 0, 1], att[:, 1, 0], att[:, 1, 1], att[:, 2, 2] = c, -s, s, c, 1.0
    return t, w, att, 25.0 + t / 360.0


def _time(model: NoiseModel, layout: Layout, n: int, **kw) -> float:
    _, w, _, _ = _inputs(n)
    rng = np.random.default_rng(0)
    return best_of(lambda: simulate_readings(model, w, layout, 1.0 / RATE_HZ, rng, **kw), REPEATS)[0]


def main() -> dict:
    n = int(round(DURATION_S * RATE_HZ))
    layout = Layout.conical(1, N_GYROS, math.acos(1 / math.sqrt(3)))
    t, _, att, temp = _inputs(n)
    results = {}
    print(f"simulate_readings: N = {N_GYROS}, {DURATION_S / 3600:g} h at {RATE_HZ:g} Hz "
          f"({n} samples per gyro), best of {REPEATS}")
    for name, effects, kw in (
            ("baseline (arw+rrw+correlation)", BASELINE, {}),
            ("all 17 effects", ALL17, {"attitude": att, "temp_c": temp,
                                       "site": (deg_to_rad(34.25), 0.0)})):
        model = NoiseModel.from_toml({"effects": effects}, n_gyros=N_GYROS)
        sec = _time(model, layout, n, **kw)
        rate = n * N_GYROS / sec
        print(f"  {name:32s} {sec:7.3f} s   {rate / 1e6:7.2f} M gyro samples/s")
        results[name] = {"seconds": sec, "gyro_samples_per_s": rate}
    return results


if __name__ == "__main__":
    main()
