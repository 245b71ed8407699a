"""Welch power spectral density, batched.

``scipy.signal.welch`` detrends its segments one at a time (a Python call
per segment). :func:`welch` computes the same estimate (Hann or any scipy
window, 50 % overlap by default, ``"constant"`` or ``"linear"``
detrending, one-sided density, mean over segments) with the segments as one
strided array, detrended and transformed in blocks. It equals
``scipy.signal.welch`` to rounding (``tests/test_spectrum.py``).
``benchmarks/bench_spectrum.py`` prints the speed ratio: 24x on the spectral
fit's many short segments (linear detrend), 1.1x on the band's few long
ones (there the FFTs dominate).
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import signal

__all__ = ["welch"]

#: Segments transformed at once (bounds the temporary arrays at ~16 segments per column).
_BLOCK = 16


def welch(x, fs: float, nperseg: int, noverlap: int | None = None, *, window="hann",
          detrend: str | bool = "constant", axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """One-sided Welch PSD along ``axis``: (frequencies [Hz], PSD [unit²/Hz]).

    Parameters
    ----------
    x : array_like
        Series [unit], samples along ``axis``.
    fs : float
        Sample rate [Hz].
    nperseg : int
        Segment length [samples], at most the series' length.
    noverlap : int, optional
        Overlap [samples]; default ``nperseg // 2``.
    window : str or tuple
        ``scipy.signal.get_window`` specification (periodic form, as scipy's welch).
    detrend : {"constant", "linear", False}
        What is removed from each segment before the window.
    axis : int
        Axis of the samples.

    Returns
    -------
    freq_hz : ndarray, shape (nperseg // 2 + 1,)
    psd : ndarray
        ``x``'s shape with ``axis`` replaced by the frequencies, as ``scipy.signal.welch``.
    """
    a = np.moveaxis(np.asarray(x, dtype=float), axis, -1)
    n = a.shape[-1]
    nperseg = int(nperseg)
    step = nperseg - (nperseg // 2 if noverlap is None else int(noverlap))
    if not 0 < nperseg <= n or step <= 0:
        raise ValueError(f"need 0 < nperseg <= {n} and noverlap < nperseg")
    if detrend not in ("constant", "linear", False):
        raise ValueError(f"detrend must be 'constant', 'linear' or False, got {detrend!r}")
    win = signal.get_window(window, nperseg)
    k = 1 + (n - nperseg) // step
    segs = sliding_window_view(a, nperseg, axis=-1)[..., ::step, :][..., :k, :]
    if detrend == "linear":
        t = np.arange(nperseg, dtype=float) - 0.5 * (nperseg - 1)
        t /= np.sqrt(t @ t)
    acc = np.zeros(a.shape[:-1] + (nperseg // 2 + 1,))
    for i0 in range(0, k, _BLOCK):
        s = segs[..., i0:i0 + _BLOCK, :]
        if detrend:
            s = s - s.mean(axis=-1, keepdims=True)
            if detrend == "linear":                       # least-squares line: mean and slope
                s = s - (s @ t)[..., None] * t
        spec = np.fft.rfft(s * win, axis=-1)
        acc += (spec.real ** 2 + spec.imag ** 2).sum(axis=-2)
    acc *= 1.0 / (fs * float(win @ win) * k)
    acc[..., 1:-1 if nperseg % 2 == 0 else None] *= 2.0     # one-sided: not DC nor Nyquist
    return np.fft.rfftfreq(nperseg, 1.0 / fs), np.moveaxis(acc, -1, axis)
