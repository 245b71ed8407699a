"""How often does a pure random walk break its own "point bound"? (issue 14, item 1)

    python benchmarks/rrw_point_bound.py [--records 40] [--seed 0]

The ADIS16405 check of issue 14 reads a cap on the rate random walk K from
the measured ADEV: K <= min over octave τ (up to a third of the record) of
ADEV(τ)·√(3/τ), since ADEV(τ) >= K·√(τ/3) for the expected Allan variance.
The measured ADEV at the last octaves has 2–3 degrees of freedom, so the
minimum of the noisy ratios falls below the true K on many records that are
nothing but ARW + RRW. This study simulates such records with plain numpy
(white noise plus a cumulative sum: no gyroarray code), reads the ADEV with
allantools at the octaves of the check, and counts how often the bound is
below the K that made the record; it also fits K with gyroarray's Allan fit
(``fit_gyro_noise``) and counts how often the fit exceeds the bound.

Records like the ADIS16405's: 1e6 samples at 100 Hz (2.78 h), N = 2.5
deg/√h, K = 76, 125, 200 deg/h/√h (its three gyros' fitted values).
"""

from __future__ import annotations

import argparse
import math

import allantools
import numpy as np

from gyroarray.effects.stochastic import fit_gyro_noise

DT, N_SAMPLES, ARW = 0.01, 1_000_000, 2.5


def one(rng: np.random.Generator, k_deg_h_rt_h: float) -> tuple[float, float, float]:
    """(point bound, fitted K, its 1σ) [deg/h/√h] of one simulated record."""
    n_rad = math.radians(ARW) / 60.0                      # deg/√h -> rad/√s
    k_rad = math.radians(k_deg_h_rt_h) / 3600.0 / 60.0    # deg/h/√h -> rad/s/√s
    x = rng.standard_normal(N_SAMPLES) * n_rad / math.sqrt(DT)
    x += np.cumsum(rng.standard_normal(N_SAMPLES)) * k_rad * math.sqrt(DT)
    xd = np.degrees(x) * 3600.0                           # deg/h
    m = 2.0 ** np.arange(0, int(math.log2(N_SAMPLES / 3)) + 1)
    t, ad, _, _ = allantools.oadev(xd, rate=1.0 / DT, data_type="freq", taus=m * DT)
    bound = float(np.min(ad / np.sqrt(t / 3.0))) * 60.0   # τ in s -> K in deg/h/√h
    rrw = next(f for f in fit_gyro_noise(x, DT, 1) if f.effect == "rrw")
    return bound, rrw.params["k_deg_h_rt_h"], rrw.sigma["k_deg_h_rt_h"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"{args.records} records per K of ARW {ARW} deg/√h + RRW K, {N_SAMPLES} samples at {1 / DT:g} Hz")
    print(f"{'K':>6} {'P(bound<K)':>11} {'bound/K 10/50/90 %':>22} {'P(fit>bound)':>13} "
          f"{'fit mean':>9} {'fit sd':>7} {'mean 1σ':>8}")
    for k in (76.0, 125.0, 200.0):
        r = np.array([one(rng, k) for _ in range(args.records)])
        q = np.quantile(r[:, 0] / k, [0.1, 0.5, 0.9])
        print(f"{k:6.0f} {np.mean(r[:, 0] < k):11.2f} {q[0]:7.2f}{q[1]:7.2f}{q[2]:7.2f}   "
              f"{np.mean(r[:, 1] > r[:, 0]):13.2f} {r[:, 1].mean():9.1f} {r[:, 1].std():7.1f} {r[:, 2].mean():8.1f}")


if __name__ == "__main__":
    main()
