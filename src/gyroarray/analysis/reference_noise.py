"""Does the reference rate carry noise of its own? (a differentiated encoder, a vibrating sensor)

A reference read from a shaft encoder is the derivative of a quantized angle:
it holds power the gyros never see. Regressions on it (scale factor,
latency, misalignment) are then errors-in-variables problems, pulled off by
that noise (the MPU-6050 stepper record: scale factor -1.0 % against +0.5 %
on its plateaus).

The test compares, per reference axis that moves, the reference's part that
is not coherent with the gyros' estimate of the same rate, P_rr·(1 − C), with
the gyros' own spectrum P_gg (Welch, both). For an exact reference
r = ω and gyros g = ω + n: P_rr·(1 − C) = P_ωω·P_nn/(P_ωω + P_nn) < P_nn <= P_gg,
so the ratio stays below 1 (measured: at most 0.30 over the 12 axes of the
four practice records); a reference with noise of its own exceeds it where
that noise is (up to 6.5 on the MPU-6050 record, in 94 of 513 bins).
"""

from __future__ import annotations

import math

import numpy as np

from gyroarray.core.units import rad_s_to_deg_s

__all__ = ["reference_own_noise", "describe", "RATIO", "MIN_FRACTION"]

#: Ratio P_rr·(1 − C)/P_gg above which a frequency bin holds the reference's own noise.
RATIO = 2.0

#: Fraction of the bins above :data:`RATIO` from which an axis is reported.
MIN_FRACTION = 0.01

#: Welch segment length [samples] (at most; a quarter of the record on short ones).
NPERSEG = 1024


def reference_own_noise(ref_rad_s, gyro_rad_s, axes, dt_s: float) -> list[dict]:
    """Reference axes whose rate carries power the gyros do not see.

    Parameters
    ----------
    ref_rad_s : array_like, shape (n, 3)
        Reference rate [rad/s].
    gyro_rad_s : array_like, shape (n, N)
        Gyro outputs [rad/s].
    axes : array_like, shape (N, 3)
        Sensitive axes [-]; the gyros' estimate of the rate is the least-squares
        one, so they must span 3 dimensions (else nothing is reported).
    dt_s : float
        Sample step [s].

    Returns
    -------
    list of dict
        One per flagged axis: ``axis`` (0, 1, 2), ``fraction`` of the bins above
        :data:`RATIO`, ``max_ratio``, ``peak_hz`` (the bin of the largest
        ratio), ``band_hz`` (the lowest and highest flagged bin) and
        ``excess_rms_deg_s`` (√ of Σ (P_rr·(1 − C) − P_gg)⁺ Δf: the reference's own
        noise beyond the gyros', a lower bound). Empty when none is flagged.
    """
    from scipy import signal   # lazy: only a moving record with a reference asks

    ref = np.asarray(ref_rad_s, dtype=float)
    g = np.asarray(gyro_rad_s, dtype=float)
    h = np.asarray(axes, dtype=float)
    n = ref.shape[0]
    if n < 64 or np.linalg.matrix_rank(h) < 3:
        return []
    est = g @ np.linalg.pinv(h).T                       # the gyros' rate about x, y, z
    fs = 1.0 / float(dt_s)
    nper = int(min(NPERSEG, max(n // 4, 16)))
    out = []
    for a in range(3):
        r = ref[:, a]
        if not np.std(r) > 0:
            continue
        f, prr = signal.welch(r, fs=fs, nperseg=nper)
        _, pgg = signal.welch(est[:, a], fs=fs, nperseg=nper)
        _, prg = signal.csd(r, est[:, a], fs=fs, nperseg=nper)
        ok = (pgg > 0) & (prr > 0)
        # P_rr·(1 − C), C = |P_rg|²/(P_rr·P_gg) the magnitude-squared coherence (scipy's coherence
        # from the same three spectra)
        own = np.where(ok, prr - np.abs(prg) ** 2 / np.where(ok, pgg, 1.0), 0.0)
        ratio = np.where(ok, own / np.where(ok, pgg, 1.0), 0.0)
        over = ratio > RATIO
        frac = float(np.mean(over))
        if frac < MIN_FRACTION or over.sum() < 3:
            continue
        k = int(np.argmax(ratio))
        excess = float(np.sum(np.maximum(own - pgg, 0.0)) * (f[1] - f[0]))
        out.append({"axis": a, "fraction": frac, "max_ratio": float(ratio[k]), "peak_hz": float(f[k]),
                    "band_hz": (float(f[over].min()), float(f[over].max())),
                    "excess_rms_deg_s": float(rad_s_to_deg_s(math.sqrt(excess)))})
    return out


def describe(d: dict) -> str:
    """The sentence for one flagged axis of :func:`reference_own_noise` (no remedy: the caller's)."""
    lo, hi = d["band_hz"]
    return (f"the reference about {'xyz'[d['axis']]} carries noise of its own: in {100 * d['fraction']:.0f} % of "
            f"the frequency bins ({lo:.3g}–{hi:.3g} Hz) it holds power the gyros do not see, up to "
            f"{d['max_ratio']:.2g}× theirs at {d['peak_hz']:.3g} Hz (at least {d['excess_rms_deg_s']:.2g} deg/s rms "
            "beyond them)")
