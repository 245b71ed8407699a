"""The residual's spectrum against three models: white + random walk, filtered, or with a Gauss–Markov hump.

A gyro's own low-pass filter (``bandwidth``) and a Gauss–Markov process both
put more power at low frequency than at high frequency, and in the Allan
deviation both look like a hump at short τ. Their spectra differ: a filter
keeps falling (−20 or −40 dB/decade) up to the Nyquist frequency, a
Gauss–Markov process flattens back to the white level. This module fits the
Welch periodogram of a residual with

* ``null``: S(f) = W + F/f + R/f² (ARW, bias instability and RRW: W = 2N²,
  F = B²/π, R = K²/(2π²), one-sided; the flicker term keeps a record's
  colored noise at low frequency from reading as a roll-off at high ones);
* ``filter``: S(f) = (W + F/f + R/f²)·|H(f)|² with the ``bandwidth`` response
  of order 1 or 2 at cut-off fc, in two families: the spec's continuous
  H (:func:`gyroarray.core.sensor.bandwidth_response`), scanned beyond the
  Nyquist frequency, where |H| → 1 and the filter becomes the null, so the
  two are nested; and the digital H_d of the bilinear transform
  (:func:`gyroarray.core.sensor.bandwidth_sos`: a zero at Nyquist, not
  nested, but what a digital filter is). The better of the two gives the
  estimate (a digitally filtered record fits H_d: order and cut-off right;
  H would trade a lower cut-off for a higher order);
* ``gauss_markov``: S(f) = W + F/f + R/f² + 4σ²τc/(1 + (2π f τc)²),

by maximum likelihood (each Welch estimate is S·χ²_ν/ν, neighbouring bins
counted once: :data:`_BIN_REDUNDANCY`; W, R and σ² by iteratively
reweighted least squares at each scanned fc or τc), so the
likelihoods compare directly: ``lr_filter`` and ``lr_gm`` are 2·Δℓ against
the null, and ``filter`` and ``gauss_markov`` are rivals with the same
number of free parameters (2 each).

Significance of the filter: the largest ``lr_filter`` over the scanned
cut-offs and both orders under the null is calibrated by the number of
effectively independent cut-offs (:data:`EFFECTIVE_TESTS`, measured on
white and white + random-walk records; see :func:`filter_z`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage, optimize, signal, special, stats

from gyroarray.analysis.memo import by_content
from gyroarray.analysis.spectrum import welch
from gyroarray.core.sensor import bandwidth_response, bandwidth_sos, bandwidth_warped_frequency

__all__ = ["PsdFit", "fit_psd", "filter_z", "EFFECTIVE_TESTS"]

#: Effectively independent tests of the cut-off scan (see :func:`filter_z`).
EFFECTIVE_TESTS = 1.0

#: Cut-offs scanned per decade, and the lowest as a fraction of the Nyquist frequency.
_PER_DECADE = 8
_LOWEST = 0.01
_TOP = 20.0


@dataclass(frozen=True)
class PsdFit:
    """Maximum-likelihood fits of one residual's Welch spectrum (module docstring).

    Attributes
    ----------
    freq_hz, psd : ndarray
        The Welch estimate [Hz], [rad²/s²/Hz] (one-sided).
    nu : float
        Degrees of freedom of each estimate.
    loglik_null : float
    filter_cutoff_hz, filter_order : float, int
        The best filter; ``filter_cutoff_sigma_hz`` its 1σ: the curvature of the profile, times
        √``dispersion`` when that is above 1.
    dispersion : float
        Dispersion of the best filter fit: the squared robust spread (1.4826·MAD) of the Pearson
        residuals (P/S − 1)·√(ν/2), 1 when the model holds the spectrum (each estimate is
        S·χ²_ν/ν, variance 2S²/ν), larger when it misses structure. Robust: a few bins under a
        filter's zero at Nyquist, where the window's leakage dominates, do not set it.
    filter_family : {"continuous", "digital"}
        Which response family fitted better.
    lr_filter : float
        2·(ℓ_filter − ℓ_null).
    lr_filter_order : dict
        Best 2·Δℓ per order.
    gm_sigma_rad_s, gm_tau_s : float
        The best Gauss–Markov hump.
    lr_gm : float
        2·(ℓ_gm − ℓ_null).
    white, walk : float
        W and R of the best filter fit (one-sided PSD coefficients; F, the flicker's, not kept).
    """

    freq_hz: np.ndarray
    psd: np.ndarray
    nu: float
    loglik_null: float
    filter_cutoff_hz: float
    filter_cutoff_sigma_hz: float
    filter_order: int
    filter_family: str
    lr_filter: float
    lr_filter_order: dict
    gm_sigma_rad_s: float
    gm_tau_s: float
    lr_gm: float
    white: float
    walk: float
    dispersion: float = 1.0


def _welch(x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, float]:
    n = x.size
    nper = int(min(1024, max(64, 2 ** int(math.log2(max(n // 16, 64))))))
    f, p = welch(x, 1.0 / dt, nper, detrend="linear")
    keep = slice(1, -1)                        # no DC, no Nyquist bin
    k = max((n - nper) // (nper // 2) + 1, 1)  # segments at 50 % overlap (Hann)
    nu = 2.0 * k * 0.95                        # Welch dof, Hann 50 %: ~1.9 per segment
    return f[keep], p[keep], nu


def _bin_redundancy(window: str = "hann", nperseg: int = 1024) -> float:
    """1 + 2 Σ_k ρ_k² for the Welch estimates of one window: how many times a sum over bins
    counts each independent piece of information.

    For white noise the windowed DFTs at bins j and j + k correlate by
    ρ_k = |Σ w² e^{−2πikn/L}| / Σ w² (Hann: 2/3 at k = 1, 1/6 at k = 2, 0 beyond), and
    their squared moduli by ρ_k². A log-likelihood that sums the bins as independent
    overstates every likelihood ratio of a smooth change of the spectrum by this factor,
    1 + 2(4/9 + 1/36) = 1.944 for Hann [1]_.

    .. [1] D. B. Percival, A. T. Walden, "Spectral Analysis for Physical Applications",
       1993, sec. 6.17 (correlation of tapered periodogram ordinates).
    """
    w2 = signal.get_window(window, nperseg) ** 2
    rho = np.abs(np.fft.fft(w2))[1:nperseg // 2] / w2.sum()
    return float(1.0 + 2.0 * np.sum(rho ** 2))


#: Information redundancy of neighbouring Hann-window Welch bins (:func:`_bin_redundancy`).
_BIN_REDUNDANCY = _bin_redundancy()


def _loglik(p: np.ndarray, s: np.ndarray, nu: float) -> float:
    """Welch log-likelihood of the spectrum ``s`` for the estimates ``p`` (each S·χ²_ν/ν), the
    bins' overlap counted once (:data:`_BIN_REDUNDANCY`)."""
    s = np.maximum(s, 1e-300)
    return float(-0.5 * nu / _BIN_REDUNDANCY * np.sum(np.log(s) + p / s))


def _linear_ml(p: np.ndarray, cols: np.ndarray, nu: float, iters: int = 8) -> tuple[np.ndarray, float]:
    """Non-negative coefficients of S = cols @ c by iteratively reweighted NNLS of the Welch
    likelihood (weights 1/S: the score of Σ ln S + P/S); (c, ℓ). An empty system (no bins
    or no terms) gives zero coefficients without calling NNLS (its native code aborts on one)."""
    if cols.ndim != 2 or cols.shape[0] == 0 or cols.shape[1] == 0:
        c = np.zeros(cols.shape[1] if cols.ndim == 2 else 0)
        return c, _loglik(p, np.zeros(np.shape(p)), nu)
    scale = np.maximum(np.abs(cols).max(axis=0), 1e-300)
    A = cols / scale
    w = 1.0 / np.maximum(p, 1e-300)
    c, _ = optimize.nnls(A * w[:, None], p * w)
    s = A @ c
    for _ in range(iters):
        if not np.all(s > 0):
            break
        w = 1.0 / s
        c_new, _ = optimize.nnls(A * w[:, None], p * w)
        s_new = A @ c_new
        if not np.all(s_new > 0):
            break
        if np.allclose(c_new, c, rtol=1e-6, atol=0):
            c, s = c_new, s_new
            break
        c, s = c_new, s_new
    return c / scale, _loglik(p, s, nu)


def _line_free(p: np.ndarray, nu: float, alpha: float = 0.01) -> np.ndarray:
    """Mask of the Welch bins free of spectral lines.

    A line (``sinusoid``: a 19.6 Hz tone on the ADIS16405's gyro 3) is a narrow peak that the
    broad models read as a roll-off or a hump. A bin is a line's when it exceeds the median of the
    15 bins around it (a monotone or smooth spectrum's median is its own level; a line moves no
    median) by the Bonferroni quantile of S·χ²_ν/ν over the bins; it and 2 bins on each side (the
    Hann window's leakage) are left out. The lowest 8 bins, where the random walk's 1/f² is steep
    against the window, are kept.
    """
    m = p.size
    keep = np.ones(m, bool)
    if m < 32:
        return keep
    med = ndimage.median_filter(p, size=15, mode="mirror")
    thr = float(stats.chi2.ppf(1.0 - alpha / m, nu) / nu)
    peak = p > thr * med
    peak[:8] = False
    if peak.any():
        keep = ~ndimage.binary_dilation(peak, iterations=2)
    return keep


@by_content()
def fit_psd(x, dt_s: float) -> PsdFit:
    """Fit the three spectral models to the residual ``x`` (n,) [rad/s] (module docstring).

    Bins under spectral lines are left out first (:func:`_line_free`).
    """
    x = np.asarray(x, dtype=float)
    dt = float(dt_s)
    f, p, nu = _welch(x - x.mean(), dt)
    keep = _line_free(p, nu)
    f, p = f[keep], p[keep]
    base = np.column_stack([np.ones_like(f), 1.0 / f, 1.0 / f ** 2])
    c0, l0 = _linear_ml(p, base, nu)
    nyq = 0.5 / dt
    fcs = np.geomspace(_LOWEST * nyq, _TOP * nyq, int(_PER_DECADE * math.log10(_TOP / _LOWEST)) + 1)

    def cols_at(fc: float, order: int, family: str) -> np.ndarray:
        """The (W, F, R) columns through the filter's |H|² at one cut-off."""
        ff = f if family == "continuous" else bandwidth_warped_frequency(f, fc, dt)
        return base * (np.abs(bandwidth_response(ff, fc, order)) ** 2)[:, None]

    def fit_at(fc: float, order: int, family: str) -> tuple[np.ndarray, float]:
        """(W, F, R) and ℓ of the filter model at one cut-off."""
        return _linear_ml(p, cols_at(fc, order, family), nu)

    prof = {}
    best: tuple[float, Any, Any, Any, Any] = (-math.inf, None, None, None, None)
    for family in ("continuous", "digital"):
        scan = fcs if family == "continuous" else fcs[fcs < 0.98 * nyq]
        for order in (1, 2):
            ll = np.empty(scan.size)
            for i, fc in enumerate(scan):
                c, ll[i] = fit_at(fc, order, family)
                if ll[i] > best[0]:
                    best = (ll[i], fc, order, c, family)
            prof[(family, order)] = (scan, ll)
    l_bw, fc, order, cb, family = best
    scan, ll = prof[(family, order)]
    i = int(np.argmin(np.abs(scan - fc)))
    if i == 0:
        # the likelihood still rises at the lowest cut-off scanned: the spectrum falls from the
        # bottom of the band (a random walk, a hump), which is no roll-off: the best cut-off
        # with a peak of its own, else none (the null)
        peaks = [(ll_[k], fam, o, k) for (fam, o), (sc, ll_) in prof.items()
                 for k in range(1, sc.size - 1) if ll_[k] > ll_[k - 1] and ll_[k] >= ll_[k + 1]]
        if peaks:
            _, family, order, i = max(peaks)
            scan, ll = prof[(family, order)]
            fc = float(scan[i])
            cb, l_bw = fit_at(fc, order, family)
        else:
            l_bw, cb = l0, c0
    sigma_fc = math.nan

    def profile(log_fc: float) -> tuple[float, np.ndarray]:
        c, lv = fit_at(math.exp(log_fc), order, family)
        return lv, c

    if 0 < i < scan.size - 1:                  # refine between the neighbours, then the curvature
        lo, hi = math.log(scan[i - 1]), math.log(scan[i + 1])
        res = optimize.minimize_scalar(lambda u: -profile(u)[0], bounds=(lo, hi), method="bounded",
                                       options={"xatol": 1e-4})
        if -res.fun > l_bw:
            l_bw, cb = -res.fun, profile(res.x)[1]
            fc = math.exp(res.x)
        h = 0.01
        u0 = math.log(fc)
        d2 = (profile(u0 + h)[0] - 2 * profile(u0)[0] + profile(u0 - h)[0]) / h ** 2
        if d2 < 0:
            sigma_fc = fc * math.sqrt(-1.0 / d2)
    # quasi-likelihood (McCullagh & Nelder, "Generalized Linear Models", 2nd ed., 1989, sec. 9.2):
    # a spectrum with structure the model does not hold (a hump, an excess between lines) scatters
    # about the fit more than S·χ²_ν/ν does, and the profile's curvature alone then claims a
    # precision the record does not have (the ADIS16405's gyro 3: ±0.08 Hz on each half of the
    # record, whose cut-offs differ by 1.1 Hz; dispersion 600–700)
    s_best = base @ c0 if cb is c0 else cols_at(fc, order, family) @ cb
    pearson = (p / np.maximum(s_best, 1e-300) - 1.0) * math.sqrt(nu / 2.0)
    dispersion = float((1.4826 * np.median(np.abs(pearson - np.median(pearson)))) ** 2)
    if math.isfinite(sigma_fc) and dispersion > 1.0:
        sigma_fc *= math.sqrt(dispersion)
    taus = np.geomspace(0.5 / (2 * math.pi * f[-1]), 5.0 / (2 * math.pi * f[0]), 60)
    l_gm, g_best = -math.inf, (math.nan, math.nan)
    for tau in taus:
        cols = np.column_stack([base, 4.0 * tau / (1.0 + (2 * math.pi * f * tau) ** 2)])
        c, lg = _linear_ml(p, cols, nu)
        if lg > l_gm:
            l_gm, g_best = lg, (math.sqrt(max(c[-1], 0.0)), tau)
    return PsdFit(freq_hz=f, psd=p, nu=nu, loglik_null=l0, filter_cutoff_hz=float(fc),
                  filter_cutoff_sigma_hz=float(sigma_fc), filter_order=int(order),
                  lr_filter=float(max(2 * (l_bw - l0), 0.0)),
                  lr_filter_order={o: float(max(2 * (max(prof[(fm, o)][1].max() for fm in
                                                             ("continuous", "digital")) - l0), 0.0))
                                   for o in (1, 2)},
                  filter_family=family,
                  gm_sigma_rad_s=float(g_best[0]), gm_tau_s=float(g_best[1]),
                  lr_gm=float(max(2 * (l_gm - l0), 0.0)), white=float(cb[0]), walk=float(cb[2]),
                  dispersion=dispersion)


def filter_z(lr: float, n_tests: float = EFFECTIVE_TESTS) -> float:
    """z of the largest filter likelihood ratio of the scan.

    P(max > lr) over ``n_tests`` independent tests, each a χ²₁/2 + δ₀/2
    mixture (the filter at the top of the scan is the null: a boundary).
    With the bins' overlap counted once (:data:`_BIN_REDUNDANCY`) the scan's
    maximum behaves as one such test: over 500 white + random-walk records
    each of 15 000, 60 000 and 120 000 samples at 50 Hz, P(z > 1) came out
    0.17 / 0.20 / 0.16 and P(z > 2) 0.022 / 0.026 / 0.032 (normal: 0.159,
    0.023). Summing the bins as independent, with 3 tests, gave P(z > 3) of
    0.010 at 15 000 samples (normal 0.0013).
    """
    lr = max(float(lr), 0.0) if math.isfinite(lr) else 0.0
    # log of the one-test tail: ½·erfc(√(lr/2)), in logs for large lr
    log_p1 = math.log(0.5) + float(special.log_ndtr(-math.sqrt(lr))) + math.log(2.0)
    p1 = math.exp(log_p1)
    log_p = math.log(-math.expm1(n_tests * math.log1p(-p1))) if p1 > 1e-12 else log_p1 + math.log(n_tests)
    if log_p > -700:
        return float(-special.ndtri(min(math.exp(log_p), 1.0 - 1e-16)))
    return float(math.sqrt(-2.0 * log_p))


def _response_length(cutoff_hz: float, dt_s: float) -> int:
    """Samples of the filter's impulse response followed: 40 time constants, 64 to 2^20."""
    return int(min(max(64, 40.0 / (cutoff_hz * dt_s)), 1 << 20))


def filtered_white_avar_ratio(cutoff_hz: float, order: int, dt_s: float, m) -> np.ndarray:
    """Allan variance of white noise through the ``bandwidth`` filter over that of the unfiltered
    noise, at the averaging factors ``m`` [-].

    From the digital filter's impulse response h: the filtered noise's
    autocovariance R(k) = Σ h_i h_{i+k}, the variogram of its integral
    D(m) = m R(0) + 2 Σ_{k<m} (m − k) R(k) (per dt², unit input), and
    σ²(m) ∝ (4 D(m) − D(2m))/(2m²), against 1/m for white noise. Exact for the
    sampled filter (the response is followed to 40 time constants, at most 2^20
    samples; beyond it the ratio is 1 to that precision).
    """
    m = np.atleast_1d(np.asarray(m, dtype=np.int64))
    sos = bandwidth_sos(cutoff_hz, order, dt_s)
    length = _response_length(cutoff_hz, dt_s)
    imp = np.zeros(length)
    imp[0] = 1.0
    h = signal.sosfilt(sos, imp)
    r = signal.fftconvolve(h, h[::-1])[length - 1:]               # R(0), R(1), ...
    k = np.arange(length, dtype=float)
    # D(j) = j R0 + 2 Σ_{k=1}^{j−1} (j − k) R(k) for j < length: cumulative sums of R and k R
    c_r = np.concatenate([[0.0], np.cumsum(r[1:])])                # Σ_{k=1}^{j} R(k)
    c_kr = np.concatenate([[0.0], np.cumsum(k[1:] * r[1:])])

    def big_d(j):
        j = np.asarray(j, dtype=np.int64)
        jj = np.minimum(j - 1, length - 1)
        return j * r[0] + 2.0 * (j * c_r[jj] - c_kr[jj])

    out = (4.0 * big_d(m) - big_d(2 * m)) / (2.0 * m)               # × m / m²
    return np.where(2 * m < length, out, 1.0)


def shortest_clean_tau(cutoff_hz: float, order: int, dt_s: float, tol: float = 0.05) -> float:
    """The shortest octave τ = 2^k·dt [s] at which white noise through the ``bandwidth`` filter
    has an Allan variance within ``tol`` of the unfiltered one (:func:`filtered_white_avar_ratio`)."""
    m = 2 ** np.arange(int(math.log2(_response_length(cutoff_hz, dt_s))) + 1)
    ratio = filtered_white_avar_ratio(cutoff_hz, order, dt_s, m)
    ok = np.flatnonzero(np.abs(ratio - 1.0) < tol)
    return float((m[ok[0]] if ok.size else m[-1]) * dt_s)
