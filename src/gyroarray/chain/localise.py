"""Where it fails: localise what a noise model leaves unexplained in a residual.

When no effect of the library explains a record's excess, one sentence
("none of the effects explains it") is not enough to act on. This module
takes the residual of a comparison (the measurement minus what the model
predicts, every gyro) and says *where* it departs from the model:

* **τ range** and sign of the Allan-deviation excess against the model's
  ADEV band (:func:`adev_excess`);
* **frequency band** of the residual's PSD excess or deficit against the
  model PSD, with its **shape** (:func:`psd_findings`): a roll-off at the top
  of the band is fitted as a low-pass (slope −20·p dB/decade above a corner
  fc: "looks like a low-pass at ≈ fc Hz"), compared with the library's
  ``bandwidth`` (order 1 or 2, same discrete filter as the simulator) and,
  when the record moves, tested for the lag a causal filter of that
  magnitude must have (:func:`lag_on_motion`): a zero-phase (non-causal)
  filter has the roll-off and no lag; a narrow peak is a line (frequency,
  amplitude); an excess at the bottom of the band is a 1/f-type region
  (its PSD slope); anything else a band with its corner;
* **time window** where the short-τ noise level changes (dynamic Allan
  variance, :func:`gyroarray.analysis.davar.davar`), marked when it
  coincides with table motion (:func:`time_windows`);
* **which gyros**: per-gyro findings with the same cause are merged and
  name their gyros; :attr:`Localisation.gyro_scores` ranks the gyros;
* **correlation** of the residual with every channel the record has (rate,
  rate², angular acceleration, specific force, temperature, dT/dt, time),
  with degrees of freedom corrected for autocorrelation
  (:func:`channel_correlations`).

Findings are ranked by a z-like score (the size of the departure in
standard errors of its own statistic) and compared with one critical value,
the Šidák two-sided value at a family-wise false-alarm rate ``alpha`` over
all the tests made (:func:`critical_z`). The module is pure: arrays in,
a :class:`Localisation` out; it knows nothing of measurement files or of
:mod:`gyroarray.chain.compare`.

Statistics
----------
PSD: Welch, Hann window, 50 % overlap, per-segment mean removed; with K
segments the estimate has ν = 2K/(1 + 2c²), c = 0.167 the Hann window's
overlap correlation, equivalent degrees of freedom (Percival & Walden 1993,
§6.17). Ratios P/S are averaged in 1/10-decade bins; a bin of b Welch
frequencies has ν_b = ν·max(1, b/1.5) (the Hann window's noise bandwidth is
1.5 bins) and its mean ratio is scored by the χ²_ν_b/ν_b tails
(:func:`chi2_z`). ADEV: the band is the model's
``band_level`` (two-sided) interval, read as a log-normal spread,
z = ln(σ/σ_mid)/(ln(hi/lo)/(2 z_band)). Correlations: block means, Pearson
r, n_eff = B(1 − ρ_x ρ_y)/(1 + ρ_x ρ_y) with ρ the lag-1 autocorrelations
of the two block series (Bretherton et al. 1999, eq. 31), Student t with
n_eff − 2 degrees of freedom turned into a normal z. Lag: the residual is
regressed on [1, u̇, ü] (u the gyro's reference rate) in B = 8 contiguous
blocks of moving samples; the lag is the mean of −coef(u̇), its standard
error the spread of the blocks over √B (batch means: no assumption on the
residual's colour).

A causal low-pass of corner ωc = 2π fc delays a slow signal by its
low-frequency group delay: 1/ωc (order 1), √2/ωc (order-2 Butterworth), in
general 1/(ωc sin(π/2p)) for a Butterworth of order p. On motion the
residual then carries −τ_g·u̇; a zero-phase filter with the same magnitude
carries none.

References
----------
D. B. Percival, A. T. Walden, "Spectral Analysis for Physical Applications",
Cambridge 1993. C. S. Bretherton et al., "The effective number of spatial
degrees of freedom of a time-varying field", J. Climate 12, 1999.
L. Galleani, P. Tavella, "The dynamic Allan variance", IEEE TUFFC 56(3), 2009.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np
from scipy import ndimage, optimize, special

from gyroarray.analysis.allan import deviation, edf
from gyroarray.analysis.davar import davar
from gyroarray.analysis.spectrum import welch
from gyroarray.core.errors import InputError

__all__ = ["Finding", "ChannelCorrelation", "Localisation", "localise", "critical_z", "chi2_z",
           "davar_window",
           "baseline_psd", "default_nperseg", "residual_psd", "adev_excess", "psd_findings", "fit_lowpass",
           "LowPassFit", "lag_on_motion", "time_windows", "channel_correlations", "record_channels",
           "butterworth_group_delay", "bandwidth_gain2"]

#: Family-wise false-alarm rate of the significance tests [-].
ALPHA = 0.01
#: Hann window: correlation of 50 %-overlapping segments, noise bandwidth [bins].
_HANN_OVERLAP_C, _HANN_ENBW = 0.167, 1.5
#: Log-frequency bins per decade for the PSD ratio.
BINS_PER_DECADE = 10
#: Half-width of a line's surroundings in the fine spectrum [bins].
LINE_HALF_WIDTH = 10
#: Batches of moving samples for the lag regression.
LAG_BLOCKS = 8
#: A low-pass is fitted down to this PSD ratio (20 dB): below, floors (spectral
#: leakage, quantization, aliasing near Nyquist) take over in real records.
LOWPASS_FLOOR = 0.01
#: A deficit at the top of the band is a low-pass only when its last bin falls below this
#: fraction (−3 dB) of the level before it: a deficit that stays flat is the model's level.
LOWPASS_DROP = 0.5
#: Normal σ from the median absolute deviation [-].
MAD_TO_SIGMA = 1.4826
#: A time window during which the table moves at least this fraction of the
#: time is reported as motion-driven, and left out of the noise-level baseline.
MOVING_FRACTION = 0.1


# =============================================================================
# Results
# =============================================================================

@dataclass(frozen=True)
class Finding:
    """One localised departure from the model.

    Attributes
    ----------
    kind : str
        ``"adev"`` (τ range), ``"lowpass"`` (roll-off at the top of the
        band), ``"line"``, ``"low_frequency"`` (1/f-type region),
        ``"band_excess"``, ``"band_deficit"``, ``"time_window"``,
        ``"channel"`` (correlation with a channel).
    gyros : tuple of int
        1-based gyros that show it.
    score : float
        Significance, in standard errors of its statistic (largest over the
        gyros) [-].
    summary : str
        One sentence, datasheet units where they help (Hz, s, deg/s).
    details : Mapping
        The numbers, SI (rad/s, s) and Hz, per gyro where they differ.
    """

    kind: str
    gyros: tuple[int, ...]
    score: float
    summary: str
    details: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ChannelCorrelation:
    """Correlation of one gyro's residual with one channel.

    Attributes
    ----------
    channel : str
    gyro : int
        1-based.
    r : float
        Pearson correlation of the block means [-].
    slope : float
        Residual per unit of the channel [rad/s per channel unit].
    n_eff : float
        Effective number of independent block pairs [-].
    z : float
        Normal score of the correlation [-] (signed).
    """

    channel: str
    gyro: int
    r: float
    slope: float
    n_eff: float
    z: float


@dataclass(frozen=True, eq=False)
class Localisation:
    """What :func:`localise` found, ranked, and the spectra behind it (for figures).

    Attributes
    ----------
    findings : tuple of Finding
        Significant findings, most significant first.
    z_crit : float
        The critical value every score was compared with [-].
    gyro_scores : ndarray, shape (N,)
        Largest score of any finding naming each gyro (0: none) [-].
    psd_freq_hz : ndarray, shape (m,)
        Welch frequencies [Hz].
    psd_residual : ndarray, shape (N, m)
        One-sided PSD of each gyro's residual [(rad/s)²/Hz].
    psd_model : ndarray, shape (N, m), or None
        The model's one-sided PSD at the same frequencies [(rad/s)²/Hz].
    psd_edf : float
        Degrees of freedom of each Welch value [-].
    adev_taus_s : ndarray, shape (k,), or None
    adev_residual : ndarray, shape (N, k), or None
        Allan deviation of the residual at the band's taus [rad/s].
    correlations : tuple of ChannelCorrelation
        Every channel × gyro tested, strongest first.
    notes : tuple of str
        What could not be tested and why.
    """

    findings: tuple[Finding, ...]
    z_crit: float
    gyro_scores: np.ndarray
    psd_freq_hz: np.ndarray
    psd_residual: np.ndarray
    psd_model: np.ndarray | None
    psd_edf: float
    adev_taus_s: np.ndarray | None = None
    adev_residual: np.ndarray | None = None
    correlations: tuple[ChannelCorrelation, ...] = ()
    notes: tuple[str, ...] = ()

    def of_kind(self, kind: str) -> tuple[Finding, ...]:
        """The findings of one kind, ranked."""
        return tuple(f for f in self.findings if f.kind == kind)

    def summary(self) -> list[str]:
        """One line per finding, ranked."""
        return [f"[{f.score:.1f}] {f.summary}" for f in self.findings]

    def to_dict(self) -> dict:
        """JSON-ready: the ranked findings (SI and Hz, as in ``details``), z_crit, gyro scores, notes."""
        return {"z_crit": self.z_crit, "gyro_scores": [float(x) for x in self.gyro_scores],
                "findings": [{"kind": f.kind, "gyros": list(f.gyros), "score": float(f.score),
                              "summary": f.summary, "details": plain_json(f.details)}
                             for f in self.findings],
                "notes": list(self.notes)}


def plain_json(x):
    """Mappings, sequences and numpy scalars as plain JSON values (NaN/inf as None)."""
    if isinstance(x, Mapping):
        return {str(k): plain_json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [plain_json(v) for v in x]
    if isinstance(x, (bool, np.bool_)) or x is None or isinstance(x, str):
        return None if x is None else (x if isinstance(x, str) else bool(x))
    v = float(x)
    return v if math.isfinite(v) else None


# =============================================================================
# Helpers
# =============================================================================

def critical_z(n_tests: int, alpha: float = ALPHA) -> float:
    """Šidák two-sided critical z for ``n_tests`` tests at family-wise rate ``alpha``."""
    a = -math.expm1(math.log1p(-alpha) / max(int(n_tests), 1))   # 1 − (1 − α)^(1/K)
    return float(-special.ndtri(a / 2.0))


def _gyros_text(gyros) -> str:
    g = sorted(gyros)
    return f"gyro {g[0]}" if len(g) == 1 else "gyros " + ", ".join(str(x) for x in g)


def _fmt(x: float) -> str:
    return f"{x:.3g}"


def butterworth_group_delay(cutoff_hz: float, order: float) -> float:
    """Low-frequency group delay of a causal Butterworth low-pass, 1/(ωc sin(π/2p)) [s]."""
    return 1.0 / (2.0 * math.pi * cutoff_hz * math.sin(math.pi / (2.0 * max(order, 0.5))))


def baseline_psd(freq_hz, arw_rad_rt_s, rrw_rad_s_rt_s=0.0) -> np.ndarray:
    """One-sided rate PSD of angle and rate random walk [(rad/s)²/Hz].

    Parameters
    ----------
    freq_hz : array_like, shape (m,)
        Frequencies [Hz].
    arw_rad_rt_s, rrw_rad_s_rt_s : float or array_like, shape (N,)
        ARW N [rad/√s] and RRW K [rad/s/√s] of each gyro.

    Returns
    -------
    ndarray, shape (N, m) (or (m,) for scalars)
        S(f) = 2N² + 2(K/2π)²/f² (IEEE Std 952: two-sided N² and
        (K/2π)²/f² give σ² = N²/τ and K²τ/3); f = 0 gets the white part only.
    """
    f = np.asarray(freq_hz, dtype=float)
    n = np.asarray(arw_rad_rt_s, dtype=float)[..., None]
    k = np.asarray(rrw_rad_s_rt_s, dtype=float)[..., None]
    with np.errstate(divide="ignore"):
        rw = np.where(f > 0, 2.0 * (k / (2.0 * np.pi)) ** 2 / np.where(f > 0, f, 1.0) ** 2, 0.0)
    out = 2.0 * n ** 2 + rw
    return out[0] if out.shape[0] == 1 and np.ndim(arw_rad_rt_s) == 0 else out


def default_nperseg(n: int) -> int:
    """Welch segment of an n-sample record: the power of two nearest n/32, within [256, 65536], at most n."""
    nperseg = int(2 ** round(math.log2(max(n / 32.0, 1.0))))
    return int(min(max(nperseg, 256), 65536, n))


def residual_psd(residual, dt_s: float, nperseg: int | None = None
                 ) -> tuple[np.ndarray, np.ndarray, float]:
    """Welch PSD of each column (Hann, 50 % overlap) and its degrees of freedom.

    Parameters
    ----------
    residual : array_like, shape (n, N)
        [rad/s].
    dt_s : float
        Sample step [s].
    nperseg : int, optional
        Segment length; default the power of two nearest n/32, within
        [256, 65536] and at most n.

    Returns
    -------
    freq_hz : ndarray, shape (m,)
    psd : ndarray, shape (N, m)
        One-sided [(rad/s)²/Hz].
    nu : float
        Equivalent degrees of freedom of each value [-].
    """
    e = np.asarray(residual, dtype=float)
    n = e.shape[0]
    if nperseg is None:
        nperseg = default_nperseg(n)
    f, p = welch(e, 1.0 / dt_s, nperseg, nperseg // 2, window="hann", detrend="constant", axis=0)
    k = 1 + (n - nperseg) // (nperseg // 2)
    nu = 2.0 * k / (1.0 + 2.0 * _HANN_OVERLAP_C ** 2)
    return f, p.T, float(nu)


def _check_residual(residual, dt_s) -> tuple[np.ndarray, float]:
    e = np.asarray(residual, dtype=float)
    if e.ndim == 1:
        e = e[:, None]
    if e.ndim != 2 or e.shape[0] < 512:
        raise InputError(f"residual must be (n, N) with n >= 512 samples, got shape {e.shape}")
    if not np.all(np.isfinite(e)):
        raise InputError("residual contains a non-finite value")
    dt = float(dt_s)
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"dt_s must be > 0, got {dt_s!r}")
    return e, dt


# =============================================================================
# τ range: the ADEV band
# =============================================================================

def adev_excess(residual, dt_s: float, taus_s, band_lo, band_hi, *, z_crit: float,
                band_level: float = 0.95) -> tuple[list[Finding], np.ndarray]:
    """Where each gyro's Allan deviation leaves the model's band.

    Parameters
    ----------
    residual : array_like, shape (n, N)
        [rad/s].
    dt_s : float
        [s].
    taus_s : array_like, shape (k,)
        Averaging times of the band, multiples of ``dt_s`` [s].
    band_lo, band_hi : array_like, shape (N, k)
        The model's ADEV band [rad/s].
    z_crit : float
        Critical score.
    band_level : float
        Two-sided probability the band covers [-].

    Returns
    -------
    findings : list of Finding
        One per gyro and contiguous τ range outside the band that reaches
        ``z_crit`` somewhere (kind ``"adev"``).
    adev : ndarray, shape (N, k)
        The residual's Allan deviation [rad/s].
    """
    e, dt = _check_residual(residual, dt_s)
    taus = np.asarray(taus_s, dtype=float)
    lo, hi = (np.broadcast_to(np.asarray(b, dtype=float), (e.shape[1], taus.size)) for b in
              (band_lo, band_hi))
    z_band = float(-special.ndtri((1.0 - band_level) / 2.0))
    adev = np.vstack([deviation(e[:, k], dt, taus=taus).dev for k in range(e.shape[1])])
    out = []
    for k in range(e.shape[1]):
        mid = np.sqrt(lo[k] * hi[k])
        s = np.log(hi[k] / lo[k]) / (2.0 * z_band)
        z = np.log(adev[k] / mid) / np.where(s > 0, s, np.inf)
        sign = np.where(adev[k] > hi[k], 1, np.where(adev[k] < lo[k], -1, 0))
        for a, b in _runs_of(sign):
            if np.abs(z[a:b]).max() < z_crit:
                continue
            up = sign[a] > 0
            ratio = (adev[k, a:b] / hi[k, a:b]).max() if up else (adev[k, a:b] / lo[k, a:b]).min()
            out.append(Finding("adev", (k + 1,), float(np.abs(z[a:b]).max()),
                               f"ADEV {'above' if up else 'below'} the model band for τ "
                               f"{_span(taus[a], taus[b - 1])} s ({'up' if up else 'down'} "
                               f"to {ratio:.2f}× its {'upper' if up else 'lower'} edge)",
                               {"tau_lo_s": float(taus[a]), "tau_hi_s": float(taus[b - 1]),
                                "sign": int(sign[a]), "ratio": float(ratio)}))
    return out, adev


def _span(a: float, b: float) -> str:
    return _fmt(a) if a == b else f"{_fmt(a)}–{_fmt(b)}"


def _runs_of(sign: np.ndarray) -> list[tuple[int, int]]:
    """[a, b) runs of equal non-zero values."""
    runs, a = [], None
    for i, s in enumerate(list(sign) + [0]):
        if a is not None and s != sign[a]:
            runs.append((a, i))
            a = None
        if a is None and s != 0:
            a = i
    return runs


# =============================================================================
# Frequency band: the PSD ratio and its shape
# =============================================================================

@dataclass(frozen=True)
class LowPassFit:
    """A low-pass fitted to the ratio of residual to model PSD.

    Attributes
    ----------
    cutoff_hz : float
        −3 dB frequency (PSD ratio g/2) of the free-slope fit
        g/(1 + (f/f0)^(2p))^m, m = ``passes`` [Hz].
    slope_db_decade : float
        −20·p·m [dB/decade] far above the corner.
    gain : float
        g, the level below the corner relative to the model [-].
    bandwidth_order : int
        The library order (1 or 2) that fits best.
    bandwidth_cutoff_hz : float
        Its cut-off (the simulator's discrete filter) [Hz].
    chi2_free, chi2_bandwidth : float
        χ² of the two fits over the same bins [-].
    dof : int
        Number of bins minus the free fit's 3 parameters.
    passes : int
        m of the free fit: 1 a Butterworth-shaped |H|², 2 its square (a
        filter run forward and backward, ``filtfilt``), whichever fits best.
    """

    cutoff_hz: float
    slope_db_decade: float
    gain: float
    bandwidth_order: int
    bandwidth_cutoff_hz: float
    chi2_free: float
    chi2_bandwidth: float
    dof: int
    passes: int = 1

    @property
    def library_fits(self) -> bool:
        """The library's ``bandwidth`` explains the magnitude about as well as the free fit."""
        return self.chi2_bandwidth - self.chi2_free <= max(10.0, 0.25 * self.chi2_free)

    @property
    def order(self) -> float:
        """p of the free fit [-]."""
        return -self.slope_db_decade / 20.0


def _log_bins(f: np.ndarray) -> list[np.ndarray]:
    """Indices of the Welch frequencies in 1/BINS_PER_DECADE-decade bins (DC left out)."""
    pos = np.flatnonzero(f > 0)
    edges = np.arange(math.floor(math.log10(f[pos[0]]) * BINS_PER_DECADE),
                      math.ceil(math.log10(f[pos[-1]]) * BINS_PER_DECADE) + 2) / BINS_PER_DECADE
    which = np.digitize(np.log10(f[pos]), edges)
    return [pos[which == b] for b in np.unique(which)]


def _binned(ratio: np.ndarray, f: np.ndarray, nu: float, bins) -> tuple[np.ndarray, ...]:
    """Bin centres [Hz], mean ratios, degrees of freedom, z of each log bin."""
    fc = np.array([math.exp(np.mean(np.log(f[b]))) for b in bins])
    r = np.array([float(np.mean(ratio[b])) for b in bins])
    nub = np.array([nu * max(1.0, b.size / _HANN_ENBW) for b in bins])
    return fc, r, nub, chi2_z(r, nub)


def chi2_z(ratio, nu) -> np.ndarray:
    """Normal score of a mean ratio r = χ²_ν/ν (exact tails; > 0 for an excess).

    z = Φ⁻¹(P(χ²_ν ≤ ν r)) below 1 and −Φ⁻¹(P(χ²_ν > ν r)) above; where the
    tail underflows, the log-normal approximation ln r/√(2/ν).
    """
    r, v = np.broadcast_arrays(np.asarray(ratio, dtype=float), np.asarray(nu, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        low = special.ndtri(special.chdtr(v, v * r))
        high = -special.ndtri(special.chdtrc(v, v * r))
        z = np.where(r < 1.0, low, high)
    approx = np.log(r) / np.sqrt(2.0 / v)
    return np.where(np.isfinite(z), z, approx)


def _averaging(f: np.ndarray, bins) -> tuple[np.ndarray, np.ndarray]:
    """The fine frequencies of ``bins`` and the matrix that averages over each bin."""
    idx = np.concatenate(bins)
    A = np.zeros((len(bins), idx.size))
    j = 0
    for i, b in enumerate(bins):
        A[i, j:j + b.size] = 1.0 / b.size
        j += b.size
    return f[idx], A


def _weighted_fit(lr: np.ndarray, shape: np.ndarray, w: np.ndarray) -> tuple[float, np.ndarray]:
    """ln g (weighted mean of ln r − shape) and the weighted residuals."""
    g = float(np.sum(w * (lr - shape)) / np.sum(w))
    return g, np.sqrt(w) * (lr - shape - g)


def _lowpass_free(ff, A, lr, w):
    """Fit ln r ≈ ln g + ln(bin mean of (1 + (f/f0)^(2p))^(−m)), m = 1 and 2: (fc, p·m, g, χ², m).

    fc is the −3 dB point of the best shape, f0·(2^(1/m) − 1)^(1/(2p)).
    """
    lf = np.log(ff)
    best = None
    for m in (1, 2):
        def shape(q, m=m):
            return np.log(A @ np.exp(-m * np.logaddexp(0.0, 2.0 * q[1] * (lf - q[0]))))

        def resid(q, shape=shape):
            return _weighted_fit(lr, shape(q), w)[1]

        for p0 in (1.0, 2.0, 4.0):
            for c0 in np.quantile(lf, [0.5, 0.9]):
                sol = optimize.least_squares(resid, [c0, p0],
                                             bounds=([lf.min() - 2, 0.25], [lf.max() + 2, 12.0]))
                # the single pass is preferred unless the double one fits clearly better
                cost = sol.cost + (0.0 if m == 1 else 2.0)
                if best is None or cost < best[0]:
                    best = (cost, sol, m, shape)
    _, sol, m, shape = best
    g, _ = _weighted_fit(lr, shape(sol.x), w)
    f0, p = math.exp(sol.x[0]), float(sol.x[1])
    fc = f0 * (2.0 ** (1.0 / m) - 1.0) ** (1.0 / (2.0 * p))
    return fc, p * m, math.exp(g), float(2.0 * sol.cost), m


def bandwidth_gain2(freq_hz, cutoff_hz: float, order: int, dt_s: float) -> np.ndarray:
    """|H|² of the library's discrete ``bandwidth`` filter (:func:`gyroarray.core.sensor.bandwidth_sos`).

    The bilinear transform pre-warped at fc maps the analog Butterworth onto
    1/(1 + (tan(π f dt)/tan(π fc dt))^(2·order)) exactly (what ``sosfreqz``
    of those sections gives, at a fraction of its cost).
    """
    x = np.tan(np.pi * np.asarray(freq_hz, dtype=float) * dt_s) / math.tan(math.pi * cutoff_hz * dt_s)
    return 1.0 / (1.0 + x ** (2 * order))


def _lowpass_library(ff, A, lr, w, dt_s):
    """Best ``bandwidth`` (order 1 or 2, the simulator's discrete filter): (order, fc, χ²)."""
    nyq = 0.5 / dt_s
    best = (1, float("nan"), float("inf"))
    for order in (1, 2):
        def chi2(lfc, order=order):
            fc = min(math.exp(lfc), 0.999 * nyq)
            shape = np.log(np.maximum(A @ bandwidth_gain2(ff, fc, order, dt_s), 1e-300))
            return float(np.sum(_weighted_fit(lr, shape, w)[1] ** 2))

        grid = np.linspace(math.log(ff.min()), math.log(0.999 * nyq), 60)
        i = int(np.argmin([chi2(x) for x in grid]))
        sol = optimize.minimize_scalar(chi2, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, 59)]),
                                       method="bounded")
        if sol.fun < best[2]:
            best = (order, min(math.exp(sol.x), 0.999 * nyq), float(sol.fun))
    return best


def fit_lowpass(freq_hz, bins, ratio, nu_bins, dt_s: float) -> LowPassFit:
    """Fit a low-pass to log-binned PSD ratios (residual / model).

    Parameters
    ----------
    freq_hz : array_like, shape (m,)
        The fine (Welch) frequencies [Hz].
    bins : sequence of int arrays, length b
        Indices into ``freq_hz`` of each bin; the model is averaged over a
        bin exactly as the data were (a steep roll-off changes within one).
    ratio : array_like, shape (b,)
        Mean ratio of the residual's PSD to the model's in each bin [-].
    nu_bins : array_like, shape (b,)
        Degrees of freedom of each bin [-] (weights ν/2 on ln ratio).
    dt_s : float
        Sample step [s] (the library filter is the simulator's discrete one).

    Returns
    -------
    LowPassFit
    """
    ff, A = _averaging(np.asarray(freq_hz, dtype=float), list(bins))
    lr = np.log(np.asarray(ratio, dtype=float))
    w = np.asarray(nu_bins, dtype=float) / 2.0               # 1/var(ln r̄) = ν/2
    fc, p, g, chi2, m = _lowpass_free(ff, A, lr, w)
    order, fc_lib, chi2_lib = _lowpass_library(ff, A, lr, w, dt_s)
    return LowPassFit(cutoff_hz=fc, slope_db_decade=-20.0 * p, gain=g, bandwidth_order=order,
                      bandwidth_cutoff_hz=fc_lib, chi2_free=chi2, chi2_bandwidth=chi2_lib,
                      dof=max(int(lr.size) - 3, 1), passes=m)


def _lines(f, p, s, nu, gyro, z_crit_fine) -> list[Finding]:
    """Narrow peaks in the fine spectrum: above the model and above their own surroundings.

    A bin is a line when it is a local maximum and both P/S and P/(the
    median of P over ±``LINE_HALF_WIDTH`` bins) pass the one-sided χ²_ν/ν
    threshold at the Šidák level of all bins: a broad excess (a hump, the
    spectrum of a transient) is not a line.
    """
    ratio = p / s
    background = ndimage.median_filter(p, size=2 * LINE_HALF_WIDTH + 1, mode="nearest")
    crit = float(special.chdtri(nu, special.ndtr(-z_crit_fine)) / nu)
    out = []
    df = f[1] - f[0]
    for j in np.flatnonzero((ratio > crit) & (p > crit * background)):
        if j == 0 or (j + 1 < ratio.size and ratio[j + 1] > ratio[j]) or ratio[j - 1] > ratio[j]:
            continue
        win = slice(max(j - 2, 1), j + 3)
        power = float(np.sum(np.maximum(p[win] - s[win], 0.0)) * df)
        z = float(chi2_z(ratio[j], nu))
        amp = math.sqrt(2.0 * power)
        out.append(Finding("line", (gyro,), z, f"a line at {_fmt(f[j])} Hz (amplitude ≈ "
                           f"{_fmt(math.degrees(amp))} deg/s)",
                           {"freq_hz": float(f[j]), "amp_rad_s": amp, "ratio": float(ratio[j])}))
    return out


def psd_findings(freq_hz, psd, model_psd, nu: float, dt_s: float, *, z_crit: float,
                 rate=None) -> list[Finding]:
    """Bands where each gyro's residual PSD leaves the model's, with their shapes.

    Parameters
    ----------
    freq_hz : array_like, shape (m,)
        Welch frequencies [Hz].
    psd, model_psd : array_like, shape (N, m)
        One-sided PSD of the residual and of the model [(rad/s)²/Hz].
    nu : float
        Degrees of freedom of each Welch value [-].
    dt_s : float
        Sample step [s].
    z_crit : float
        Critical score (log bins); lines use the Šidák value over every fine bin.
    rate : array_like, shape (n, N), optional
        Reference rate along each gyro [rad/s] with the residual, to test a
        low-pass for the lag on motion; see :func:`lag_on_motion` (passed as
        ``(rate, residual)`` by :func:`localise`).

    Returns
    -------
    list of Finding
        Per gyro: ``"lowpass"``, ``"line"``, ``"low_frequency"``,
        ``"band_excess"``, ``"band_deficit"``.
    """
    f = np.asarray(freq_hz, dtype=float)
    P, S = np.atleast_2d(psd), np.atleast_2d(model_psd)
    bins = _log_bins(f)
    z_fine = critical_z(f.size * P.shape[0])
    out: list[Finding | None] = []
    for k in range(P.shape[0]):
        ok = S[k] > 0
        lines = _lines(f, P[k], np.where(ok, S[k], np.inf), nu, k + 1, z_fine)
        out += lines
        fb, rb, nub, zb = _binned(P[k] / np.where(ok, S[k], np.inf), f, nu, bins)
        sign = np.where(zb > z_crit, 1, np.where(zb < -z_crit, -1, 0))
        excess = np.maximum(P[k] - S[k], 0.0)
        for a, b in _grow(sign, zb):
            # the share of the region's excess power that its lines carry
            lo, hi = bins[a][0], bins[b - 1][-1]
            total = float(excess[lo:hi + 1].sum())
            in_lines = sum(float(excess[max(j - 2, 0):j + 3].sum()) for j in
                           np.searchsorted(f, [x.details["freq_hz"] for x in lines]) if lo <= j <= hi)
            out.append(_classify(k + 1, a, b, f, bins, fb, rb, nub, zb, in_lines >= 0.5 * total,
                                 dt_s, rate))
    return [x for x in out if x is not None]


def _grow(sign: np.ndarray, z: np.ndarray) -> list[tuple[int, int]]:
    """Runs of significant bins, each extended over its neighbours of the same sign with |z| > 2."""
    out: list[tuple[int, int]] = []
    for a, b in _runs_of(sign):
        s = sign[a]
        while a > 0 and s * z[a - 1] > 2.0:
            a -= 1
        while b < z.size and s * z[b] > 2.0:
            b += 1
        if out and a <= out[-1][1] and np.sign(z[out[-1][0]]) == s:
            a = out.pop()[0]
        out.append((a, b))
    return out


def _classify(gyro, a, b, f, bins, fb, rb, nub, zb, lines_explain, dt_s, rate) -> Finding | None:
    """Name one region [a, b) of log bins of one gyro (None: its lines explain it)."""
    top = b >= fb.size - 1
    score = float(np.abs(zb[a:b]).max())
    span = {"f_lo_hz": float(fb[a]), "f_hi_hz": float(fb[b - 1])}
    if zb[a] < 0 and top and rb[-1] < LOWPASS_DROP * _flat_level(fb, rb, a, b):
        return _lowpass_finding(gyro, a, f, bins, fb, rb, nub, zb, dt_s, score, rate)
    if zb[a] < 0:
        return Finding("band_deficit", (gyro,), score, f"less noise than the model between "
                       f"{_fmt(fb[a])} and {_fmt(fb[b - 1])} Hz (down to {rb[a:b].min():.2f}×)",
                       {**span, "ratio": float(rb[a:b].min())})
    excess = np.maximum(rb[a:b] - 1.0, 0.0)
    if lines_explain:
        return None
    if a == 0:
        sl = _slope(fb[a:b], excess)
        kind = ("1/f (flicker-like)" if -1.5 < sl <= -0.5 else "1/f² (random-walk-like)"
                if -2.5 < sl <= -1.5 else f"∝ f^{sl:.1f}")
        return Finding("low_frequency", (gyro,), score, f"excess below {_fmt(fb[b - 1])} Hz, "
                       f"PSD {kind}", {**span, "psd_slope": sl, "ratio": float(rb[a:b].max())})
    i = a + int(np.argmax(rb[a:b]))
    return Finding("band_excess", (gyro,), score, f"excess between {_fmt(fb[a])} and "
                   f"{_fmt(fb[b - 1])} Hz (peak {rb[i]:.2f}× the model at {_fmt(fb[i])} Hz)",
                   {**span, "peak_hz": float(fb[i]), "ratio": float(rb[i])})


def _slope(f: np.ndarray, excess: np.ndarray) -> float:
    """Slope of ln(excess) against ln f (PSD ∝ f^slope); 0 with fewer than 2 usable bins."""
    ok = excess > 0
    if np.count_nonzero(ok) < 2:
        return 0.0
    return float(np.polyfit(np.log(f[ok]), np.log(excess[ok]), 1)[0])


def _flat_level(fb: np.ndarray, rb: np.ndarray, a: int, b: int) -> float:
    """The PSD ratio before a deficit region [a, b) of log bins: its median over the decade below
    fb[a] (at least 3 bins), else over the region itself (a level offset, not a roll-off)."""
    below = (fb >= fb[a] / 10.0) & (np.arange(fb.size) < a)
    return float(np.median(rb[below] if np.count_nonzero(below) >= 3 else rb[a:b]))


def _lowpass_finding(gyro, a, f, bins, fb, rb, nub, zb, dt_s, score, rate) -> Finding:
    """A deficit reaching the top of the band: fit the low-pass, test its lag."""
    # a decade of the flat part before the deficit, without bins in excess (motion, lines),
    # down to 20 dB below the model (floors: leakage, quantization, aliasing)
    # (excess judged against the level of that decade: a model whose white level was
    # calibrated on the filtered short τ sits below the flat part)
    near = fb >= fb[a] / 10.0
    level = _flat_level(fb, rb, a, fb.size)
    use = near & (rb >= LOWPASS_FLOOR * level) & (chi2_z(rb / level, nub) < 2.0)
    fit = fit_lowpass(f, [bins[i] for i in np.flatnonzero(use)], rb[use], nub[use], dt_s)
    p_round = max(1, round(fit.order))
    if fit.library_fits:
        k = fit.bandwidth_order
        text = (f"looks like a low-pass at ≈ {_fmt(fit.bandwidth_cutoff_hz)} Hz (magnitude fits "
                f"bandwidth order {k}: {-20 * k} dB/decade)")
        tau_g = butterworth_group_delay(fit.bandwidth_cutoff_hz, k)
    else:
        how = ("steeper than" if fit.order > 2.5 else "shallower than" if fit.order < 0.75
               else "not the shape of")
        text = (f"looks like a low-pass at ≈ {_fmt(fit.cutoff_hz)} Hz ({fit.slope_db_decade:.0f} "
                f"dB/decade above it, order ≈ {fit.order:.1f}: {how} bandwidth's; nearest "
                f"bandwidth order {fit.bandwidth_order} at {_fmt(fit.bandwidth_cutoff_hz)} Hz"
                + ("; the shape of a Butterworth run forward and backward" if fit.passes == 2 else "")
                + ")")
        tau_g = butterworth_group_delay(fit.cutoff_hz, p_round)
    if abs(math.log(fit.gain)) > math.log(1.5):
        text += f" (below it the PSD is {fit.gain:.2g}× the model's)"
    details = {"cutoff_hz": fit.cutoff_hz, "slope_db_decade": fit.slope_db_decade,
               "gain": fit.gain, "bandwidth_order": fit.bandwidth_order,
               "bandwidth_cutoff_hz": fit.bandwidth_cutoff_hz, "library_fits": fit.library_fits,
               "chi2_free": fit.chi2_free, "chi2_bandwidth": fit.chi2_bandwidth,
               "passes": fit.passes, "expected_lag_s": tau_g, "causal": None}
    if rate is not None:
        u, e = rate
        lag = lag_on_motion(e[:, gyro - 1], u[:, gyro - 1], dt_s)
        if lag is not None:
            text += ", " + _lag_verdict(lag, tau_g, details)
    return Finding("lowpass", (gyro,), score, text, details)


def _lag_verdict(lag, tau_g: float, details: dict) -> str:
    tau, se = lag
    details.update(lag_s=tau, lag_se_s=se)
    tol = max(4.0 * se, 0.25 * tau_g)
    if abs(tau) < tol:
        details["causal"] = False
        return (f"not causal: no lag on motion (lag {tau * 1e3:.2g} ± {se * 1e3:.2g} ms; a causal "
                f"filter of this magnitude lags {tau_g * 1e3:.3g} ms)")
    if abs(tau - tau_g) < tol:
        details["causal"] = True
        return (f"causal: lags {tau * 1e3:.3g} ± {se * 1e3:.2g} ms on motion, as a filter of "
                f"this magnitude does ({tau_g * 1e3:.3g} ms)")
    details["causal"] = None
    return (f"lags {tau * 1e3:.3g} ± {se * 1e3:.2g} ms on motion, not the {tau_g * 1e3:.3g} ms "
            "of a causal filter of this magnitude")


def lag_on_motion(residual_k, rate_k, dt_s: float, *, blocks: int = LAG_BLOCKS
                  ) -> tuple[float, float] | None:
    """Delay of a gyro on motion: the residual regressed on the rate's derivatives.

    Parameters
    ----------
    residual_k : array_like, shape (n,)
        Residual of one gyro [rad/s].
    rate_k : array_like, shape (n,)
        Reference rate along that gyro's axis [rad/s].
    dt_s : float
        [s].
    blocks : int
        Batches of moving samples.

    Returns
    -------
    (lag_s, se_s) or None
        Mean of −coef(u̇) over the batches of the regression residual ≈
        c + b₁u̇ + b₂ü, and its batch-means standard error [s]; None when
        the record has too little motion (fewer than 100 moving samples per
        batch, or a singular batch).

    Notes
    -----
    A causal filter with low-frequency group delay τ gives y ≈ u − τu̇, so
    the residual y − u ≈ −τu̇; a zero-phase filter gives no u̇ term. Moving
    samples: |u̇| above 5 % of its largest value.
    """
    e = np.asarray(residual_k, dtype=float)
    u = np.asarray(rate_k, dtype=float)
    ud = np.gradient(u, dt_s)
    udd = np.gradient(ud, dt_s)
    peak = np.abs(ud).max()
    if not peak > 0:
        return None
    moving = np.flatnonzero(np.abs(ud) > 0.05 * peak)
    if moving.size < 100 * blocks:
        return None
    taus: list[float] = []
    for part in np.array_split(moving, blocks):
        X = np.column_stack([np.ones(part.size), ud[part], udd[part]])
        coef, _, rank, _ = np.linalg.lstsq(X, e[part], rcond=None)
        if rank < 3:
            return None
        taus.append(-coef[1])
    tau = np.array(taus)
    return float(tau.mean()), float(tau.std(ddof=1) / math.sqrt(blocks))


# =============================================================================
# Time window: dynamic Allan variance
# =============================================================================

def davar_window(n: int) -> int:
    """Default DAVAR window of :func:`time_windows`: n/64 within [256, n/4] [samples]."""
    return int(min(max(n // 64, 256), n // 4))


def time_windows(residual, dt_s: float, time_s, *, z_crit: float, moving=None,
                 window: int | None = None) -> list[Finding]:
    """Time spans where a gyro's short-τ noise level departs from its record median.

    Parameters
    ----------
    residual : array_like, shape (n, N)
        [rad/s].
    dt_s : float
        [s].
    time_s : array_like, shape (n,)
        [s].
    z_crit : float
    moving : array_like of bool, shape (n,), optional
        Samples where the table moves.
    window : int, optional
        DAVAR window [samples]; default n/64 within [256, n/4].

    Returns
    -------
    list of Finding
        Kind ``"time_window"``; ``details["moving_fraction"]`` says how much
        of the span the table moved (from ``MOVING_FRACTION`` on, the summary
        says so: a motion-driven residual, not a change of noise level). The
        noise-level baseline is the median over windows where the table is
        still (all windows when fewer than 3 are); the spread of ln σ² is
        the larger of the χ² value for white noise and 1.4826 × the median
        absolute deviation over those windows.
    """
    e, dt = _check_residual(residual, dt_s)
    n = e.shape[0]
    t = np.asarray(time_s, dtype=float)
    L = window or davar_window(n)
    nu = float(edf("oadev", L + 1, 1, 0))
    out = []
    mv = np.zeros(n, dtype=bool) if moving is None else np.asarray(moving, dtype=bool)
    for k in range(e.shape[1]):
        d = davar(e[:, k], dt, window=L, taus=[dt], step=max(L // 2, 1), extension="none")
        v = d.adev_rad_s[:, 0] ** 2
        # a window whose output does not change at all (a stuck gyro) has v = 0: floored so
        # its z is finite (a log of 0 made z and the score −inf/inf, and the JSON invalid)
        frozen = v <= 0.0
        pos = v[~frozen]
        v = np.maximum(v, 1e-12 * (float(np.median(pos)) if pos.size else 1.0))
        frac_w = np.array([mv[s0:s0 + ln].mean() for s0, ln in zip(d.start, d.window_length)])
        still = frac_w < MOVING_FRACTION
        ref = np.log(v[still] if np.count_nonzero(still) >= 3 else v)
        base = float(np.exp(np.median(ref)))
        # spread of ln v: χ² theory for white noise, or what the still windows show when
        # wider (coloured noise, e.g. a low-passed one, has fewer degrees of freedom)
        spread = max(math.sqrt(2.0 / nu), MAD_TO_SIGMA * float(np.median(np.abs(ref - np.log(base)))))
        z = np.log(v / base) / spread
        sign = np.where(z > z_crit, 1, np.where(z < -z_crit, -1, 0))
        for a, b in _runs_of(sign):
            i0 = int(max(d.start[a], 0))
            i1 = int(min(d.start[b - 1] + d.window_length[b - 1], n))
            frac = float(np.mean(mv[i0:i1]))
            ratio = float(np.exp(np.mean(np.log(v[a:b] / base))))
            what = ("the output stops changing (stuck)" if np.any(frozen[a:b]) else
                    "while the table moves: a motion-driven residual (see the channels), "
                    "not a change of noise level" if frac >= MOVING_FRACTION else
                    f"noise level × {math.sqrt(ratio):.2f} (short-τ ADEV)")
            out.append(Finding("time_window", (k + 1,), float(np.abs(z[a:b]).max()),
                               f"from {_fmt(t[i0])} to {_fmt(t[i1 - 1])} s: {what}",
                               {"t0_s": float(t[i0]), "t1_s": float(t[i1 - 1]),
                                "variance_ratio": ratio, "moving_fraction": frac}))
    return out


# =============================================================================
# Channels
# =============================================================================

def _block_means(x: np.ndarray, b: int) -> np.ndarray:
    m = x.shape[0] // b
    return x[: m * b].reshape(m, b, *x.shape[1:]).mean(axis=1)


def _lag1(x: np.ndarray) -> float:
    x = x - x.mean()
    d = float(np.dot(x, x))
    return float(np.dot(x[1:], x[:-1]) / d) if d > 0 else 0.0


def channel_correlations(residual, channels: Mapping[str, np.ndarray], *,
                         n_blocks: int = 500) -> list[ChannelCorrelation]:
    """Correlation of every gyro's residual with every channel, autocorrelation-corrected.

    Parameters
    ----------
    residual : array_like, shape (n, N)
        [rad/s].
    channels : Mapping[str, ndarray]
        Name → values, shape (n,) (the same for every gyro) or (n, N) (one
        column per gyro).
    n_blocks : int
        Block means the correlation is computed on.

    Returns
    -------
    list of ChannelCorrelation
        Every (channel, gyro) with a non-constant channel, largest |z| first.
    """
    e = np.asarray(residual, dtype=float)
    b = max(1, e.shape[0] // n_blocks)
    eb = _block_means(e, b)
    out = []
    for name, values in channels.items():
        cb = _block_means(np.asarray(values, dtype=float), b)
        for k in range(e.shape[1]):
            y = cb if cb.ndim == 1 else cb[:, k]
            x = eb[:, k]
            yc, xc = y - y.mean(), x - x.mean()
            vy, vx = float(np.dot(yc, yc)), float(np.dot(xc, xc))
            if not (vy > 0 and vx > 0):
                continue
            r = float(np.dot(xc, yc) / math.sqrt(vx * vy))
            rho = _lag1(x) * _lag1(y)
            n_eff = float(np.clip(x.size * (1.0 - rho) / (1.0 + rho), 3.0, x.size))
            t = r * math.sqrt((n_eff - 2.0) / max(1.0 - r * r, 1e-300))
            z = float(-special.ndtri(special.stdtr(n_eff - 2.0, -abs(t)))) * np.sign(r)
            out.append(ChannelCorrelation(name, k + 1, r, float(np.dot(xc, yc) / vy), n_eff,
                                          float(min(abs(z), 40.0) * np.sign(z))))
    return sorted(out, key=lambda c: -abs(c.z))


#: The slope of the residual on a channel in datasheet units: channel -> (factor from SI, text).
_DEG_H = 180.0 / math.pi * 3600.0
_SLOPE_UNITS = {"time": (_DEG_H * 3600.0, "deg/h per hour"),
                "rate": (1e6, "ppm of the rate"),
                "rate²": (math.pi / 180.0, "deg/s per (deg/s)²"),
                "angular acceleration": (1e3, "ms (residual per angular acceleration)"),
                "temperature": (_DEG_H, "deg/h per °C"),
                "dT/dt": (_DEG_H, "deg/h per °C/s"),
                **{f"acc_{a}": (180.0 / math.pi * 9.80665, "deg/s per g") for a in "xyz"}}


def _channel_findings(corrs, z_crit) -> list[Finding]:
    out = []
    for c in corrs:
        if abs(c.z) < z_crit:
            continue
        k, unit = _SLOPE_UNITS.get(c.channel, (1.0, "rad/s per unit"))
        out.append(Finding("channel", (c.gyro,), abs(c.z),
                           f"residual follows {c.channel} (r = {c.r:+.2f}, slope {c.slope * k:.3g} "
                           f"{unit})", {"channel": c.channel, "r": c.r, "slope": c.slope,
                                        "n_eff": c.n_eff}))
    return out


def record_channels(n, n_gyros, rate, angular_accel, acc, temp_c, time_s, dt, extra
                    ) -> dict[str, np.ndarray]:
    """The channels :func:`localise` correlates the residual with, name -> (n,) or (n, N).

    ``time`` [s] always; with ``rate`` (n, N) [rad/s]: ``rate``, ``rate²``,
    ``angular acceleration`` [rad/s²] (``angular_accel`` or the rate's
    derivative); with ``acc`` (n, 3) [m/s²]: ``acc_x``, ``acc_y``, ``acc_z``;
    with ``temp_c`` (n,) [°C]: ``temperature``, ``dT/dt`` [°C/s]; then
    ``extra``. InputError on a wrong shape or a non-finite value.
    """
    ch: dict[str, np.ndarray] = {"time": np.asarray(time_s, dtype=float)}
    if rate is not None:
        ch["rate"] = rate
        ch["rate²"] = rate ** 2
        ch["angular acceleration"] = (np.gradient(rate, dt, axis=0) if angular_accel is None
                                      else np.asarray(angular_accel, dtype=float))
    elif angular_accel is not None:
        ch["angular acceleration"] = np.asarray(angular_accel, dtype=float)
    if acc is not None:
        a = np.asarray(acc, dtype=float)
        if a.shape != (n, 3):
            raise InputError(f"acc must be ({n}, 3) [m/s²], got shape {a.shape}")
        for j, axis in enumerate("xyz"):
            ch[f"acc_{axis}"] = a[:, j]
    if temp_c is not None:
        tc = np.asarray(temp_c, dtype=float)
        ch["temperature"] = tc
        ch["dT/dt"] = np.gradient(tc, dt)
    for name, v in (extra or {}).items():
        ch[str(name)] = np.asarray(v, dtype=float)
    for name, v in ch.items():
        if v.shape[0] != n or v.ndim > 2 or (v.ndim == 2 and v.shape[1] != n_gyros) \
                or not np.all(np.isfinite(v)):
            raise InputError(f"channel {name!r} must be {n} finite samples, one value or one per "
                             f"gyro ({n_gyros}), got shape {v.shape}")
    return ch


# =============================================================================
# The whole localisation
# =============================================================================

def _merge_key(f: Finding) -> tuple[tuple, tuple[float, float] | None]:
    """What must be equal to merge two findings, and the span that must overlap (or None)."""
    d = f.details
    if f.kind == "lowpass":
        return ("lowpass", d["library_fits"], d.get("causal")), None
    if f.kind == "line":
        return ("line", round(math.log(d["freq_hz"]) / 0.02)), None
    if f.kind == "channel":
        return ("channel", d["channel"], d["r"] > 0), None
    if f.kind == "adev":
        return ("adev", d["sign"]), (math.log(d["tau_lo_s"]), math.log(d["tau_hi_s"]))
    if f.kind == "time_window":
        return (("time_window", d["moving_fraction"] >= MOVING_FRACTION), (d["t0_s"], d["t1_s"]))
    return (f.kind,), (math.log(d["f_lo_hz"]), math.log(d["f_hi_hz"]))


def _overlap(a: tuple[float, float], b: tuple[float, float]) -> bool:
    """Spans sharing at least half of the shorter one (a point span: inside the other)."""
    common = min(a[1], b[1]) - max(a[0], b[0])
    shorter = min(a[1] - a[0], b[1] - b[0])
    return common >= 0.5 * shorter if shorter > 0 else common >= 0


def _merge(findings: list[Finding]) -> list[Finding]:
    """One finding per cause: the same kind on several gyros at about the same place."""
    groups: list[tuple[tuple, tuple[float, float] | None, list[Finding]]] = []
    for f in sorted(findings, key=lambda x: -x.score):
        key, span = _merge_key(f)
        for gkey, gspan, members in groups:
            if gkey == key and (span is None or (gspan is not None and _overlap(gspan, span))) and \
                    not set(f.gyros) & {g for m in members for g in m.gyros}:
                members.append(f)
                break
        else:
            groups.append((key, span, [f]))
    out = []
    for _, _, group in groups:
        best = group[0]
        gyros = tuple(sorted({g for f in group for g in f.gyros}))
        per_gyro = {f.gyros[0]: dict(f.details) for f in group}
        out.append(replace(best, gyros=gyros, summary=f"{_gyros_text(gyros)}: {best.summary}",
                           details=MappingProxyType({**best.details, "per_gyro": per_gyro})))
    return out


def localise(residual, dt_s: float, *, time_s=None, taus_s=None, band_lo=None, band_hi=None,
             band_level: float = 0.95, band_samples=None, model_psd=None, rate=None,
             angular_accel=None, acc=None,
             temp_c=None, extra_channels: Mapping[str, np.ndarray] | None = None,
             alpha: float = ALPHA, nperseg: int | None = None) -> Localisation:
    """Localise a model's unexplained residual: τ range, frequency band and shape, time, gyros, channels.

    Parameters
    ----------
    residual : array_like, shape (n, N)
        Measurement minus the model's prediction, each gyro [rad/s]; uniform
        sampling.
    dt_s : float
        Sample step [s].
    time_s : array_like, shape (n,), optional
        Sample times [s]; default ``arange(n)·dt``.
    taus_s, band_lo, band_hi : array_like, optional
        The model's ADEV band: taus (k,) [s] and per-gyro bounds (N, k)
        [rad/s] covering ``band_level`` (two-sided).
    band_level : float
        Coverage of the band [-].
    band_samples : slice or array_like of bool, optional
        The samples of ``residual`` the ADEV band describes (a model band
        simulated over the static part only); default all.
    model_psd : callable or array_like, optional
        The model's one-sided rate PSD [(rad/s)²/Hz]: ``model_psd(freq_hz)``
        returning (N, m), or an (N, m) array at the Welch frequencies of
        :func:`residual_psd` (same ``nperseg``). See :func:`baseline_psd`.
    rate : array_like, shape (n, N), optional
        Reference rate along each gyro's axis (H·ω_ref) [rad/s]: channels
        ``rate``, ``rate²``, ``angular acceleration`` (its derivative unless
        ``angular_accel`` is given); motion for the lag test and the time
        windows.
    angular_accel : array_like, shape (n, N), optional
        Angular acceleration along each gyro's axis [rad/s²].
    acc : array_like, shape (n, 3), optional
        Specific force at the platform origin [m/s²]: channels
        ``acc_x``, ``acc_y``, ``acc_z``.
    temp_c : array_like, shape (n,), optional
        Temperature [°C]: channels ``temperature``, ``dT/dt``.
    extra_channels : Mapping[str, array_like], optional
        More channels, (n,) or (n, N).
    alpha : float
        Family-wise false-alarm rate of all the tests [-].
    nperseg : int, optional
        Welch segment length (default in :func:`residual_psd`).

    Returns
    -------
    Localisation
        Findings ranked by score; only those past the Šidák critical value.

    Raises
    ------
    InputError
        Shapes, non-finite values, n < 512.
    """
    e, dt = _check_residual(residual, dt_s)
    n, N = e.shape
    t = np.arange(n) * dt if time_s is None else np.asarray(time_s, dtype=float)
    u = None if rate is None else np.asarray(rate, dtype=float)
    channels = record_channels(n, N, u, angular_accel, acc, temp_c, t, dt, extra_channels)
    f, P, nu = residual_psd(e, dt, nperseg)
    S = None
    if model_psd is not None:
        S = np.asarray(model_psd(f) if callable(model_psd) else model_psd, dtype=float)
        S = np.broadcast_to(S, (N, f.size))
    n_bins = len(_log_bins(f))
    n_taus = 0 if taus_s is None else np.size(taus_s)
    L = davar_window(n)
    n_windows = 1 + (n - L) // max(L // 2, 1)
    n_tests = N * (n_taus + (n_bins if S is not None else 0) + len(channels) + n_windows)
    z_crit = critical_z(n_tests, alpha)
    findings, notes, adev = [], [], None
    if taus_s is not None and band_lo is not None and band_hi is not None:
        eb = e if band_samples is None else e[band_samples]
        found, adev = adev_excess(eb, dt, taus_s, band_lo, band_hi, z_crit=z_crit,
                                  band_level=band_level)
        findings += found
    if S is not None:
        findings += psd_findings(f, P, S, nu, dt, z_crit=z_crit,
                                 rate=None if u is None else (u, e))
    else:
        notes.append("no model PSD: the frequency band was not localised")
    if u is None:
        notes.append("no reference rate: a low-pass cannot be tested for the lag on motion")
    moving = None if u is None else _moving(u, dt)
    findings += time_windows(e, dt, t, z_crit=z_crit, moving=moving)
    corrs = channel_correlations(e, channels)
    findings += _channel_findings(corrs, z_crit)
    merged = sorted(_merge(findings), key=lambda x: -x.score)
    scores = np.zeros(N)
    for x in merged:
        for g in x.gyros:
            scores[g - 1] = max(scores[g - 1], x.score)
    return Localisation(findings=tuple(merged), z_crit=z_crit, gyro_scores=scores,
                        psd_freq_hz=f, psd_residual=P, psd_model=None if S is None else np.array(S),
                        psd_edf=nu, adev_taus_s=None if taus_s is None else np.asarray(taus_s, float),
                        adev_residual=adev, correlations=tuple(corrs), notes=tuple(notes))


def _moving(u: np.ndarray, dt: float) -> np.ndarray:
    """Samples where any gyro's reference rate or its change is above 1 % of its largest value."""
    ud = np.gradient(u, dt, axis=0)
    m = np.zeros(u.shape[0], dtype=bool)
    for x in (u, ud):
        peak = np.abs(x).max(axis=0)
        m |= np.any(np.abs(x) > 0.01 * np.where(peak > 0, peak, np.inf), axis=1)
    return m
