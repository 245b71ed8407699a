"""Speed of :func:`gyroarray.analysis.spectrum.welch` against ``scipy.signal.welch``.

The job of the Monte-Carlo band: the Welch PSD (Hann, 50 % overlap,
constant detrend) of a 1e6-sample, 3-gyro record with 2^15-sample segments;
and the spectral fit's (linear detrend, 1024-sample segments, 276 000
samples). Target: >= 2x faster, equal to 1e-12 of the largest value.
Reports, never asserts.
"""

from __future__ import annotations

import numpy as np
from _timing import best_of
from scipy import signal

from gyroarray.analysis.spectrum import welch

TARGET = 2.0


def main() -> dict:
    rng = np.random.default_rng(0)
    jobs = [("band: 1e6 x 3, nperseg 32768, constant", rng.standard_normal((1_000_000, 3)), 32768, "constant"),
            ("fit: 276 000, nperseg 1024, linear", rng.standard_normal(276_000), 1024, "linear")]
    out = {}
    print(f"{'job':<42} {'scipy s':>8} {'ours s':>8} {'ratio':>7} {'target':>7} {'max rel diff':>13}")
    for name, x, nper, det in jobs:
        t_ref, (_, p_ref) = best_of(lambda: signal.welch(x, fs=100.0, window="hann", nperseg=nper,
                                                         detrend=det, axis=0), 3)
        t_our, (_, p_our) = best_of(lambda: welch(x, 100.0, nper, detrend=det, axis=0), 3)
        diff = float(np.max(np.abs(p_our - p_ref)) / np.max(p_ref))
        ratio = t_ref / t_our
        print(f"{name:<42} {t_ref:8.3f} {t_our:8.3f} {ratio:6.1f}x {TARGET:6.0f}x {diff:13.1e}  "
              f"{'ok' if ratio >= TARGET and diff < 1e-12 else 'MISS'}")
        out[name] = {"scipy_s": t_ref, "ours_s": t_our, "ratio": ratio, "max_rel_diff": diff}
    return out


if __name__ == "__main__":
    main()
