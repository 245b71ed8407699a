"""Tapered Whittle maximum-likelihood fit of a gyro record's noise terms (issue 45).

The fit reads the terms of :mod:`gyroarray.analysis.crb` (ARW ``n``, RRW ``k``, quantization
``q``, bias instability ``b``, Gauss–Markov ``gm``) from the **first differences** of the rate
of each still part, never across a join: each part has its own periodogram and the parts'
log-likelihoods add.

Taper and band
--------------
Each part's differences d_t (t = 0 … m−1) are multiplied by a split-cosine-bell (Tukey) taper
h_t, cosine ramps over a fraction ``taper`` of the part (half at each end, default
:data:`TAPER`), normalised Σ h_t² = 1, so that the periodogram I_j = |Σ h_t d_t e^{−2πi jt/m}|²
has expectation ≈ S_d(λ_j) [(rad/s)² per cycle/sample]. Without a taper the white noise's
first difference telescopes to its two end samples, whose power (≈ 2N²/(m dt) at every
frequency) swamps the rate random walk's K²dt at the low frequencies that carry K (K read far
too high). The band is the Fourier frequencies λ_j = j/m, j = 1 … ⌊m/2⌋ (λ = 0, the part's
end-to-end difference, is left out; Nyquist has weight ½), or those inside ``band_hz``.

A record whose sensor filters its rate has ordinates near Nyquist that no noise model of the
table follows (the ADIS16405: the full-band fit reads B = 201 deg/h where the Allan fit reads
33). :func:`choose_band` picks the band from the record (:data:`BAND_RULE`: the first
half-octave bin whose mean periodogram departs from a pilot fit on the lower quarter by more
than max(:data:`FLAT_TOL`, :data:`FLAT_Z` σ) ends it) and :func:`model_check` tells whether a
fitted model follows the record over its band. ``tests/test_whittle_band.py`` checks both on
numpy records through a scipy FIR low-pass and on the ADIS16405.

The negative log-likelihood Σ_parts Σ_j w_j [log S(λ_j) + I_j/S(λ_j)] is minimised over the log
of each parameter (L-BFGS-B with the analytic gradient), from the periodogram levels and from
starts with each minor term (``q``, ``b``, ``gm``) 5 × higher, the lowest kept.

Sigmas and efficiency
---------------------
The tapered Whittle estimator's asymptotic covariance is the inverse Whittle information times
the taper's variance inflation κ = m Σh⁴/(Σh²)² (Dahlhaus 1983; κ = 1 untapered, 1.026 for the default 5 %
Tukey taper, 35/18 for a full Hann taper). ``sigma`` is that covariance at the fitted values;
``crb`` is the bound of :func:`gyroarray.analysis.crb.crb` at the fitted values for the same
parts and the same band (the Fisher information over the band's ordinates: the bound of the
likelihood maximised), ``efficiency`` the CRB variance over the estimator's, 1/κ (asymptotic,
for a record that follows the fitted model); ``crb_full`` and ``efficiency_full`` are the
whole record's bound and the efficiency against it (what the band costs). ``tests/test_whittle.py`` checks the RMSE of K̂ against the CRB
on simulated white + walk records.

SI inside: rates rad/s, angles rad, times s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from gyroarray.analysis import crb as _crb
from gyroarray.core.errors import InputError

__all__ = ["TAPER", "FLAT_TOL", "FLAT_Z", "PILOT_TERMS", "PILOT_FRACTION", "MIN_BIN", "WhittleFit",
           "BandChoice", "tukey", "taper_inflation", "periodograms", "fit_whittle", "bin_ratios",
           "choose_band", "model_check", "BAND_RULE"]

#: Default taper fraction: the share of each part under the cosine ramps (half at each end).
TAPER = 0.05
#: The band rule (:func:`choose_band`): a half-octave bin of ordinates departs from the pilot
#: model when its mean of I_j/S(λ_j) is below 1 − max(FLAT_TOL, FLAT_Z·σ_b), σ_b = √(κ/n_b) its
#: sampling sd (each ratio is a unit exponential, n_b ordinates, taper inflation κ).
FLAT_TOL = 0.05
#: See :data:`FLAT_TOL`: the departure must also be this many sampling σ of the bin.
FLAT_Z = 3.0
#: The model fitted on the pilot band to judge the bins above it (white + walk + flicker: the
#: low frequencies of every record the bins are read against).
PILOT_TERMS = ("n", "k", "b")
#: The pilot band's top as a fraction of the Nyquist frequency.
PILOT_FRACTION = 0.25
#: Fewest ordinates in a bin the rule judges (a bin with fewer is never a departure).
MIN_BIN = 32

#: The band rule in words (``allan`` and the docs print it).
BAND_RULE = (f"f_hi: fit {'+'.join(PILOT_TERMS)} on [f_lo, {PILOT_FRACTION:g}·Nyquist], then, in "
             f"half-octave bins down from Nyquist, the first bin at or above half that top whose "
             f"mean periodogram over the fitted spectrum departs from 1 by more than max({FLAT_TOL:g}, "
             f"{FLAT_Z:g}·σ_bin) (σ_bin: the bin's sampling sd and the pilot fit's) ends the band at its lower edge (Nyquist if none; refitted on the "
             "shorter band while the fall lies inside the pilot band); f_lo: the lowest Fourier "
             "frequency")


def tukey(m: int, fraction: float) -> np.ndarray:
    """Split-cosine-bell taper of ``m`` points, cosine ramps over ``fraction`` of them (half at
    each end), normalised to Σ h² = 1."""
    if not 0.0 <= fraction <= 1.0:
        raise InputError(f"the taper fraction must be in [0, 1], got {fraction!r}")
    h = np.ones(m)
    ramp = int(math.floor(fraction * m / 2.0))
    if ramp > 0:
        x = (np.arange(ramp) + 0.5) / ramp
        r = 0.5 * (1.0 - np.cos(np.pi * x))
        h[:ramp] = r
        h[m - ramp:] = r[::-1]
    return h / math.sqrt(float(h @ h))


def taper_inflation(h: np.ndarray) -> float:
    """Variance inflation κ = m Σh⁴ / (Σh²)² of a taper (1 for none)."""
    h2 = h * h
    return float(len(h) * (h2 @ h2) / h2.sum() ** 2)


def periodograms(x, parts=None, taper: float = TAPER, dt_s: float | None = None, band_hz=None):
    """Tapered periodogram of the first differences of each still part.

    Parameters
    ----------
    x : array_like, shape (n,)
        Rate [rad/s].
    parts : sequence of (int, int), optional
        Still parts [start, stop) in samples (default: the whole record).
    taper : float, default :data:`TAPER`
        Tukey taper fraction.
    dt_s : float, optional
        Sample step [s], needed with ``band_hz``.
    band_hz : (float, float), optional
        Keep the frequencies inside [lo, hi] Hz.

    Returns
    -------
    list of (ndarray, ndarray, ndarray, float)
        Per part: frequencies λ_j [cycles/sample], weights w_j, periodogram I_j
        [(rad/s)² per cycle/sample] and the taper's inflation κ.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise InputError(f"the Whittle fit takes one gyro's rate (1-D), got shape {x.shape}")
    _crb.part_lengths(len(x), parts)
    parts = [(0, len(x))] if parts is None else [(int(a), int(b)) for a, b in parts]
    out = []
    for a, b in parts:
        seg = x[a:b]
        if not np.all(np.isfinite(seg)):
            raise InputError(f"still part ({a}, {b}) holds a non-finite rate")
        d = np.diff(seg)
        m = len(d)
        h = tukey(m, taper)
        half = m // 2
        spec = np.fft.rfft(h * d)[1:half + 1]
        per = spec.real ** 2 + spec.imag ** 2
        lam = np.arange(1, half + 1) / m
        w = np.ones(half)
        if m % 2 == 0:
            w[-1] = 0.5
        if band_hz is not None:
            if dt_s is None:
                raise InputError("a frequency band needs the sample step")
            f = lam / dt_s
            keep = (f >= band_hz[0]) & (f <= band_hz[1])
            lam, w, per = lam[keep], w[keep], per[keep]
        out.append((lam, w, per, taper_inflation(h)))
    return out


@dataclass(frozen=True)
class WhittleFit:
    """A tapered Whittle fit of the noise terms.

    Parameters
    ----------
    terms : tuple
        Terms fitted (``n``, ``k``, ``q``, ``b``, ``gm``).
    values : dict
        Parameter -> fitted value, SI (``n`` [rad/√s], ``k`` [rad/s/√s], ``q`` [rad],
        ``b`` [rad/s], ``gm_sigma`` [rad/s], ``gm_tau`` [s]).
    sigma : dict
        Parameter -> 1σ of the estimator (inverse Whittle information at the fit, times the
        taper's inflation), unit of the parameter.
    crb : dict
        Parameter -> CRB standard deviation at the fitted values for these parts, unit of the
        parameter.
    efficiency : dict
        Parameter -> CRB variance over the estimator's asymptotic variance [-].
    taper : float
        Tukey taper fraction.
    band : str
        The frequencies used, in words.
    n_freq : int
        Periodogram ordinates used, all parts.
    converged : bool
        Whether the optimiser reported convergence.
    nll : float
        Whittle negative log-likelihood at the fit.
    inflation : float
        Taper variance inflation κ (ordinate-weighted mean over parts).
    notes : list of str
        What the fit could not do (a singular information, an optimiser that stopped).
    crb_full : dict
        Parameter -> CRB standard deviation of the whole record (every Fourier frequency but
        0), unit of the parameter; equal to ``crb`` without a band.
    efficiency_full : dict
        Parameter -> ``crb_full`` variance over the estimator's [-]: what the band costs.
    band_hz : (float, float) or None
        The band [Hz] the fit used (None: all frequencies).
    """

    terms: tuple
    values: dict
    sigma: dict
    crb: dict
    efficiency: dict
    taper: float
    band: str
    n_freq: int
    converged: bool
    nll: float
    inflation: float
    notes: list = field(default_factory=list)
    crb_full: dict = field(default_factory=dict)
    efficiency_full: dict = field(default_factory=dict)
    band_hz: tuple | None = None

    def to_json_dict(self) -> dict:
        """The fit as JSON (SI)."""
        def f(d):
            return {k: None if v is None else float(v) for k, v in d.items()}
        return {"method": "tapered Whittle maximum likelihood on the first differences of each still part",
                "terms": list(self.terms), "values_si": f(self.values), "sigma_si": f(self.sigma),
                "crb_si": f(self.crb), "efficiency": f(self.efficiency), "taper": "Tukey",
                "taper_fraction": self.taper, "band": self.band, "n_freq": self.n_freq,
                "converged": self.converged, "nll": self.nll, "inflation": self.inflation,
                "notes": list(self.notes), "crb_full_band_si": f(self.crb_full),
                "efficiency_full_band": f(self.efficiency_full),
                "band_hz": None if self.band_hz is None else list(self.band_hz)}


def _start(pgs, names, dt_s) -> dict:
    """Rough starting values from the periodogram levels where each term dominates."""
    lam = np.concatenate([p[0] for p in pgs])
    per = np.concatenate([p[2] for p in pgs])
    order = np.argsort(lam)
    lam, per = lam[order], per[order]
    q = max(1, len(lam) // 8)
    hi_l, hi_p = lam[-q:], per[-q:]
    lo_p = per[:max(3, min(len(per), 8))]
    s2_hi = np.sin(np.pi * hi_l) ** 2
    level_lo = float(np.mean(lo_p))
    start = {}
    for p in names:
        if p == "n":
            start[p] = math.sqrt(max(float(np.mean(hi_p / (4.0 * s2_hi))) * dt_s, 1e-300))
        elif p == "k":
            start[p] = math.sqrt(max(level_lo / dt_s, 1e-300))
        elif p == "q":
            start[p] = 0.5 * math.sqrt(max(float(np.mean(hi_p / (16.0 * s2_hi ** 2))), 1e-300)) * dt_s
        elif p == "b":
            lam_lo = lam[:len(lo_p)]
            v = np.mean(lo_p * 2.0 * np.pi * lam_lo / (4.0 * np.sin(np.pi * lam_lo) ** 2))
            start[p] = 0.3 * math.sqrt(max(float(v), 1e-300))
        elif p == "gm_tau":
            start[p] = math.sqrt(dt_s * len(lam) * dt_s)
        elif p == "gm_sigma":
            start[p] = 0.3 * math.sqrt(max(level_lo / dt_s, 1e-300) * math.sqrt(dt_s * len(lam) * dt_s))
    return start


def fit_whittle(x, dt_s: float, terms=("n", "k"), *, parts=None, taper: float = TAPER,
                band_hz=None, start: dict | None = None) -> WhittleFit:
    """Fit the noise terms of one gyro's still parts by tapered Whittle maximum likelihood.

    Parameters
    ----------
    x : array_like, shape (n,)
        Rate [rad/s].
    dt_s : float
        Sample step [s].
    terms : sequence of str, default ("n", "k")
        Terms of the model (see :mod:`gyroarray.analysis.crb`).
    parts : sequence of (int, int), optional
        Still parts [start, stop) in samples (default: the whole record).
    taper : float, default :data:`TAPER`
        Tukey taper fraction (0: no taper).
    band_hz : (float, float), optional
        Frequencies used [Hz] (default: all Fourier frequencies but 0).
    start : dict, optional
        Starting values, SI (default: from the periodogram levels).

    Returns
    -------
    WhittleFit
    """
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        raise InputError(f"the sample step must be a positive number of seconds, got {dt_s!r}")
    terms = tuple(terms)
    names = _crb.params_of(terms)
    pgs = periodograms(x, parts, taper, dt_s, band_hz)
    n_freq = sum(len(p[0]) for p in pgs)
    if n_freq < 4 * len(names):
        raise InputError(f"the still parts give {n_freq} periodogram ordinates: too few to fit "
                         f"{len(names)} noise parameters")
    if np.all(np.concatenate([p[2] for p in pgs]) == 0.0):
        raise InputError("the rate is constant over the still parts: no noise to fit")
    lam = np.concatenate([p[0] for p in pgs])
    w = np.concatenate([p[1] for p in pgs])
    per = np.concatenate([p[2] for p in pgs])
    x0 = _start(pgs, names, dt_s) if start is None else {p: float(start[p]) for p in names}
    theta0 = np.log([x0[p] for p in names])
    scale = float(np.sum(w))

    def nll(theta):
        vals = dict(zip(names, np.exp(theta)))
        s, g = _crb.log_psd_grad(lam, vals, dt_s, names)
        r = per / s
        f = float(np.sum(w * (np.log(s) + r)))
        grad = g @ (w * (1.0 - r))
        return f / scale, grad / scale

    # the log-likelihood is flat in the log of a term driven towards 0, so a minor term started
    # too low can stay there: also start with each minor term 5 × higher, keep the lowest
    starts = [theta0] + [theta0 + math.log(5.0) * (np.array(names) == p)
                         for p in names if p in ("q", "b", "gm_sigma")]
    res = None
    with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
        for t0 in starts:
            r = optimize.minimize(nll, t0, jac=True, method="L-BFGS-B",
                                  bounds=[(t - 40.0, t + 40.0) for t in theta0],
                                  options={"maxiter": 500, "ftol": 1e-13, "gtol": 1e-9})
            if res is None or r.fun < res.fun:
                res = r
    assert res is not None                          # starts holds theta0 at least
    values = dict(zip(names, np.exp(res.x).tolist()))
    notes = []
    # the information of the fitted model over the ordinates used (band and parts)
    _, g = _crb.log_psd_grad(lam, values, dt_s, names)
    info = (g * w) @ g.T
    sizes = np.array([len(p[0]) for p in pgs], dtype=float)
    kappa = float(np.sum(sizes * np.array([p[3] for p in pgs])) / sizes.sum())
    sigma = {p: None for p in names}
    try:
        cov = np.linalg.inv(info)
        if np.all(np.diag(cov) > 0.0) and np.linalg.cond(info) < 1e14:
            sigma = {p: math.sqrt(kappa * cov[i, i]) * values[p] for i, p in enumerate(names)}
        else:
            notes.append("the Whittle information is singular: a term is not resolved by this record")
    except np.linalg.LinAlgError:
        notes.append("the Whittle information is singular: a term is not resolved by this record")
    parts_list = [(0, len(np.asarray(x)))] if parts is None else parts
    # the bound of the likelihood the fit maximises (the band's ordinates), and the record's
    bound = _crb.crb(values, dt_s, parts=parts_list, band_hz=band_hz)
    full = bound if band_hz is None else _crb.crb(values, dt_s, parts=parts_list)
    efficiency = {p: (None if sigma[p] is None or bound.sd[p] is None
                      else (bound.sd[p] / sigma[p]) ** 2) for p in names}
    efficiency_full = {p: (None if sigma[p] is None or full.sd[p] is None
                           else (full.sd[p] / sigma[p]) ** 2) for p in names}
    band = ("all Fourier frequencies of each part's first differences but 0 (Nyquist weight ½)"
            if band_hz is None else f"Fourier frequencies in [{band_hz[0]:g}, {band_hz[1]:g}] Hz")
    if not res.success:
        notes.append(f"the optimiser stopped: {res.message}")
    return WhittleFit(terms=terms, values=values, sigma=sigma, crb=dict(bound.sd),
                      efficiency=efficiency, taper=float(taper), band=band, n_freq=int(n_freq),
                      converged=bool(res.success), nll=float(res.fun * scale), inflation=kappa,
                      notes=notes, crb_full=dict(full.sd), efficiency_full=efficiency_full,
                      band_hz=None if band_hz is None else (float(band_hz[0]), float(band_hz[1])))


@dataclass(frozen=True)
class BandChoice:
    """The frequency band a band-limited Whittle fit uses, and why.

    Parameters
    ----------
    band_hz : (float, float)
        [f_lo, f_hi] [Hz].
    rule : str
        How ``band_hz`` was chosen, in words.
    cut : bool
        Whether f_hi lies below the Nyquist frequency (the record departs from the model there).
    bins : list of dict
        The half-octave bins judged: ``f_lo_hz``, ``f_hi_hz``, ``n`` (ordinates), ``ratio`` (mean
        of I/S over the pilot fit), ``sigma`` (its sampling sd), ``departs`` (by the rule).
    pilot : WhittleFit or None
        The pilot fit the bins are read against (None when the band was given).
    """

    band_hz: tuple
    rule: str
    cut: bool
    bins: list
    pilot: WhittleFit | None

    def to_json_dict(self) -> dict:
        """The band as JSON (Hz)."""
        return {"band_hz": list(self.band_hz), "rule": self.rule, "cut_below_nyquist": self.cut,
                "bins": [dict(b) for b in self.bins],
                "pilot_model": None if self.pilot is None else list(self.pilot.terms)}


def _pooled(pgs, f_lo_hz: float, dt_s: float):
    lam = np.concatenate([p[0] for p in pgs])
    w = np.concatenate([p[1] for p in pgs])
    per = np.concatenate([p[2] for p in pgs])
    kap = np.concatenate([np.full(len(p[0]), p[3]) for p in pgs])
    keep = lam / dt_s >= f_lo_hz
    return lam[keep], w[keep], per[keep], kap[keep]


def bin_ratios(pgs, values: dict, dt_s: float, f_lo_hz: float = 0.0, cov=None) -> list:
    """Mean periodogram over a model's spectrum in half-octave bins down from Nyquist.

    Parameters
    ----------
    pgs : list
        :func:`periodograms` of the record (every frequency).
    values : dict
        The model, SI (as :func:`gyroarray.analysis.crb.diff_psd`).
    dt_s : float
        Sample step [s].
    f_lo_hz : float, default 0
        Lowest frequency binned [Hz].
    cov : ndarray, shape (P, P), optional
        Covariance of the model's log parameters (in the order of ``values``) when the model is
        itself an estimate: its spread of log S over the bin adds to ``sigma``.

    Returns
    -------
    list of dict
        Bins by rising frequency: ``f_lo_hz``, ``f_hi_hz`` [Hz], ``n`` (ordinates), ``ratio``
        (weighted mean of I_j/S(λ_j), 1 where the model holds) and ``sigma`` (its sd [-]:
        √(κ/n_b + ḡᵀ·cov·ḡ), ḡ the bin's mean ∂log S/∂log θ).
    """
    lam, w, per, kap = _pooled(pgs, f_lo_hz, dt_s)
    if not len(lam):
        return []
    model, grad = _crb.log_psd_grad(lam, values, dt_s)
    r = per / model
    f = lam / dt_s
    nyq = 0.5 / dt_s
    lowest = max(float(f.min()), f_lo_hz)
    count = max(1, int(math.ceil(2.0 * math.log2(nyq / lowest) + 1e-9)))
    edges = nyq * 2.0 ** (-0.5 * np.arange(count + 1))[::-1]
    idx = np.clip(np.searchsorted(edges, f, side="left") - 1, 0, count - 1)
    out = []
    for b in range(count):
        sel = idx == b
        n_b = int(sel.sum())
        if not n_b:
            continue
        wb = w[sel]
        var = float(np.mean(kap[sel])) / n_b
        if cov is not None:
            gb = grad[:, sel].mean(axis=1)
            var += max(float(gb @ cov @ gb), 0.0)
        out.append({"f_lo_hz": float(edges[b]), "f_hi_hz": float(edges[b + 1]), "n": n_b,
                    "ratio": float(np.sum(wb * r[sel]) / np.sum(wb)),
                    "sigma": float(math.sqrt(var))})
    return out


def _falls(b: dict) -> bool:
    """Whether a bin departs from the model (either way: a filter's fall, a line's rise)."""
    return b["n"] >= MIN_BIN and abs(b["ratio"] - 1.0) > max(FLAT_TOL, FLAT_Z * b["sigma"])


def choose_band(x, dt_s: float, *, parts=None, taper: float = TAPER, f_lo_hz: float = 0.0,
                f_hi_hz: float | None = None) -> BandChoice:
    """The band [f_lo, f_hi] a band-limited Whittle fit of this record uses (:data:`BAND_RULE`).

    A record whose sensor filters its rate (a decimation or anti-alias filter) has periodogram
    ordinates near Nyquist that no white + walk + flicker model follows: fitted, they pull the
    ARW down and the low-frequency terms with it. The rule keeps the frequencies below the first
    half-octave bin whose power departs clearly (by more than :data:`FLAT_TOL` and
    :data:`FLAT_Z` sampling σ, either way: a filter's fall, a line's rise) from a pilot fit of
    :data:`PILOT_TERMS` on the lower quarter of the band. A quantization rise near Nyquist is
    then outside the band too: the ``q`` term is fitted only where its rise lies inside it.

    Parameters
    ----------
    x : array_like, shape (n,)
        Rate [rad/s].
    dt_s : float
        Sample step [s].
    parts : sequence of (int, int), optional
        Still parts [start, stop) in samples (default: the whole record).
    taper : float, default :data:`TAPER`
        Tukey taper fraction.
    f_lo_hz : float, default 0
        Lowest frequency [Hz] (0: from the lowest Fourier frequency).
    f_hi_hz : float, optional
        Highest frequency [Hz]: when given, the band is [f_lo, f_hi] as stated, no rule.

    Returns
    -------
    BandChoice
    """
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        raise InputError(f"the sample step must be a positive number of seconds, got {dt_s!r}")
    nyq = 0.5 / dt_s
    if not (math.isfinite(f_lo_hz) and 0.0 <= f_lo_hz < nyq):
        raise InputError(f"the band's lower edge must be in [0, {nyq:g}) Hz, got {f_lo_hz!r}")
    if f_hi_hz is not None:
        if not (math.isfinite(f_hi_hz) and f_lo_hz < f_hi_hz):
            raise InputError(f"the band's upper edge must be above its lower edge {f_lo_hz:g} Hz, "
                             f"got {f_hi_hz!r}")
        hi = min(float(f_hi_hz), nyq)
        return BandChoice(band_hz=(float(f_lo_hz), hi), rule="stated", cut=hi < nyq, bins=[], pilot=None)
    pgs = periodograms(x, parts, taper, dt_s)
    hi = PILOT_FRACTION * nyq
    pilot, bins = None, []
    for _ in range(12):                               # each pass halves the pilot band at least
        if hi <= f_lo_hz:
            break
        try:
            pilot = fit_whittle(x, dt_s, PILOT_TERMS, parts=parts, taper=taper, band_hz=(f_lo_hz, hi))
        except InputError:
            break                                     # too few ordinates for the pilot: keep hi
        # the pilot is an estimate: its covariance (κ × the inverse information of its band)
        # widens the bins it is extrapolated to
        _, info = _crb.fisher(pilot.values, dt_s, n_samples=len(np.asarray(x)), parts=parts,
                              band_hz=(f_lo_hz, hi))
        cov = pilot.inflation * np.linalg.pinv(info)
        bins = bin_ratios(pgs, pilot.values, dt_s, f_lo_hz, cov=cov)
        new_hi = nyq
        for b in bins:
            if b["f_lo_hz"] >= 0.5 * hi * (1.0 - 1e-9) and _falls(b):
                new_hi = b["f_lo_hz"]
                break
        if new_hi >= hi * (1.0 - 1e-9):
            hi = new_hi                               # the pilot band holds: up to the first fall
            break
        hi = new_hi                                   # a fall inside the pilot band: refit below it
    for b in bins:
        b["departs"] = bool(_falls(b))
    return BandChoice(band_hz=(float(f_lo_hz), float(hi)), rule=BAND_RULE, cut=hi < nyq * (1.0 - 1e-9),
                      bins=bins, pilot=pilot)


def model_check(x, dt_s: float, fit: WhittleFit, *, parts=None, taper: float = TAPER) -> tuple:
    """Whether a fitted model follows the record over the fit's band: every half-octave bin of
    at least :data:`MIN_BIN` ordinates has its mean I/S within 1 ± max(:data:`FLAT_TOL`,
    :data:`FLAT_Z`·σ_bin).

    Parameters
    ----------
    x : array_like, shape (n,)
        Rate [rad/s].
    dt_s : float
        Sample step [s].
    fit : WhittleFit
        The fit (its values and band).
    parts : sequence of (int, int), optional
        Still parts [start, stop) in samples (default: the whole record).
    taper : float, default :data:`TAPER`
        Tukey taper fraction.

    Returns
    -------
    (bool, dict or None)
        Passed, and the worst bin (the largest |ratio − 1| over its allowance) or None.
    """
    pgs = periodograms(x, parts, taper, dt_s, fit.band_hz)
    bins = bin_ratios(pgs, fit.values, dt_s, 0.0 if fit.band_hz is None else fit.band_hz[0])
    worst, score = None, -math.inf
    for b in bins:
        if b["n"] < MIN_BIN:
            continue
        sc = abs(b["ratio"] - 1.0) / max(FLAT_TOL, FLAT_Z * b["sigma"])
        if sc > score:
            worst, score = b, sc
    return (score <= 1.0), worst
