"""Still parts of a gyro-array record that has no reference rate.

Motion means the platform turns, so every gyro sees ``H ω``. For a rank-3
layout the signals tested are the least-squares platform rate
``ω̂ = H⁺ y`` (M = 3), otherwise the gyro outputs themselves (M = N):

1. Blocks of ``L`` samples (``window_s``) have means ``m_b``; the baseline
   ``b_b`` is their running median over ``baseline_s``. Constant biases,
   drift and the Earth rate follow it; motion shorter than ``baseline_s/2``
   does not.
2. The standard error of a window mean is measured on the record:
   ``se = 1.4826 · median|m − b|``, which holds every noise faster than the
   baseline (white, Gauss–Markov, quantization, vibration), but at least
   ``σ̃/√L`` (quantized window means sit on a grid, where a median snaps low).
3. Local noise: each block's white-noise level ``σ_b`` is the mean absolute
   deviation of its first differences over √2 (a median is 0 on quantized
   data); ``se`` is scaled by its running median over ``noise_s`` divided by
   ``σ̃ = median σ_b``, clipped to [1, ``max_ratio``], so a burst raises its
   own threshold.
4. A sample moves when the mean of the window centred on it leaves the
   baseline by more than ``max(z · se, floor_rad_s)`` in any signal, or when
   its block is rough, ``σ_b > max_ratio · σ̃``: turning back and forth
   averages out in a window but not in the differences, and a noise burst
   stays far below a variance ratio of ``max_ratio² = 100``. Motion is
   dilated by ``guard_s`` on each side; still is the rest.

The medians assume the record is still most of the time. A constant rate
held much longer than ``baseline_s/2`` looks like a bias change: only its
start and end are found.

False alarms: on still data a window mean is about Gaussian around the
baseline with standard error ``se``, so one window exceeds ``z = 6`` with
probability ``2Φ(−6) = 2.0e-9``; the union bound over every sample and
signal (90 000 samples × 3 signals for 30 min at 50 Hz) gives at most 5e-4
per record, and overlapping windows are strongly correlated (the largest
deviation on the pure-noise records of the tests is 4–5 se). The default
floor ``2 Ω_E`` (30 deg/h) is the most the Earth-rate reading of a still
platform changes between two orientations; it also keeps the threshold
positive when quantization leaves no scatter at all. The parity space
``y − H ω̂`` is not used for the noise: it misses noise common to all
gyros, which ``ω̂`` carries.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import maximum_filter1d, median_filter

from gyroarray.core.errors import InputError
from gyroarray.core.constants import EARTH_RATE_RAD_S

__all__ = ["still_mask"]

#: Normal σ from the median absolute deviation: σ = MAD / Φ⁻¹(3/4) [-].
MAD_TO_SIGMA = 1.4826
#: Normal σ from the mean absolute deviation: σ = √(π/2) · mean|x − x̃| [-].
MEAN_AD_TO_SIGMA = float(np.sqrt(np.pi / 2.0))


def _dilate(mask: np.ndarray, k: int) -> np.ndarray:
    """True within ``k`` samples of a True sample."""
    return maximum_filter1d(mask.astype(np.uint8), 2 * k + 1) > 0 if k > 0 else mask


def still_mask(y_rad_s: np.ndarray, axes: np.ndarray, dt_s: float, *, window_s: float = 1.0,
               z: float = 6.0, guard_s: float = 1.0, baseline_s: float = 30.0,
               noise_s: float = 10.0, max_ratio: float = 10.0,
               floor_rad_s: float = 2.0 * EARTH_RATE_RAD_S) -> np.ndarray:
    """Samples at which the platform does not turn.

    Parameters
    ----------
    y_rad_s : array_like, shape (n, N)
        Gyro outputs along their sensitive axes [rad/s].
    axes : array_like, shape (N, 3)
        Unit sensitive axes in the platform frame [-].
    dt_s : float
        Sample step [s].
    window_s : float
        Averaging window [s] (at least 2 samples).
    z : float
        Threshold [standard errors of a window mean].
    guard_s : float
        Motion is extended by this much on each side [s] (start/stop transients).
    baseline_s : float
        Span of the running median that follows biases and drift [s].
    noise_s : float
        Span of the running median of the local white-noise level [s].
    max_ratio : float
        Local / typical white-noise σ [-] above which a block is motion, and
        the most a noise change may raise the threshold.
    floor_rad_s : float
        Smallest deviation of a window mean that counts as motion [rad/s].

    Returns
    -------
    ndarray of bool, shape (n,)
        True where the platform is still.

    Raises
    ------
    InputError
        Bad shapes, non-finite values, or fewer than 3 windows of samples.

    Notes
    -----
    The method and its false-alarm rate are in the module docstring.
    """
    y, h = np.asarray(y_rad_s, float), np.asarray(axes, float)
    if y.ndim != 2 or h.shape != (y.shape[1], 3):
        raise InputError(f"need y_rad_s (n, N) and axes (N, 3), got {y.shape} and {h.shape}")
    if not (np.isfinite(y).all() and np.isfinite(h).all() and dt_s > 0 and z > 0 and max_ratio >= 1):
        raise InputError("y_rad_s and axes must be finite, dt_s and z positive, max_ratio >= 1")
    L = max(2, round(window_s / dt_s))                          # samples per window
    n, B = y.shape[0], y.shape[0] // L                               # samples, blocks
    if B < 3:
        raise InputError(f"{n} samples are fewer than 3 windows of {L}")
    s = y @ np.linalg.pinv(h).T if np.linalg.matrix_rank(h) == 3 else y   # ω̂ = H⁺ y
    blocks = s[:B * L].reshape(B, L, -1)
    m = blocks.mean(axis=1)                                          # block means (B, M)
    d = np.diff(blocks, axis=1)
    # σ_b = √(π/2) · mean|Δs − med Δs| / √2
    sw = MEAN_AD_TO_SIGMA / np.sqrt(2.0) * np.abs(d - np.median(d, axis=1, keepdims=True)).mean(axis=1)
    kn, kb = 2 * int(noise_s / window_s / 2) + 1, 2 * int(baseline_s / window_s / 2) + 1
    base = median_filter(m, size=(kb, 1), mode="nearest")           # b = running median of m
    sig = np.median(sw, axis=0)                                      # σ̃ (M,)
    # se = max(1.4826 · median|m − b|, σ̃/√L)
    se = np.maximum(MAD_TO_SIGMA * np.median(np.abs(m - base), axis=0), sig / np.sqrt(L))
    sw_loc = median_filter(sw, size=(kn, 1), mode="nearest")
    ratio = np.divide(sw_loc, sig, out=np.ones_like(sw), where=sig > 0)
    rough = np.any(np.divide(sw, sig, out=np.zeros_like(sw), where=sig > 0) > max_ratio, axis=1)
    thr = np.maximum(z * se * np.clip(ratio, 1.0, max_ratio), floor_rad_s)   # (B, M)
    lo = np.clip(np.arange(n) - L // 2, 0, n)                       # centred windows [lo, hi),
    hi = np.clip(np.arange(n) - L // 2 + L, 0, n)                   # cut at the ends
    c = np.vstack([np.zeros((1, s.shape[1])), np.cumsum(s, axis=0)])
    k = (hi - lo)[:, None]
    mbar = (c[hi] - c[lo]) / k                                       # window means (n, M)
    blk = np.minimum(np.arange(n) // L, B - 1)                       # block of each sample
    # |m̄ − b| > thr · √(L/k)  (k < L samples in the windows cut at the ends)
    moving = np.any(np.abs(mbar - base[blk]) > thr[blk] * np.sqrt(L / k), axis=1) | rough[blk]
    return ~_dilate(moving, round(guard_s / dt_s))
