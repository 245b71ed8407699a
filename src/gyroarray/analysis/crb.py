"""Whittle Fisher information and Cramér–Rao bound (CRB) of a gyro record's noise terms (issue 45).

The bound is the smallest standard deviation any unbiased estimator of a noise coefficient can
have from one record of a given length, rate and gaps, for the model the record follows.

The model
---------
The record is the rate ω_k [rad/s] sampled every ``dt_s`` [s]. The likelihood is written for the
**first differences** d_k = ω_{k+1} − ω_k of each still part (a constant bias drops out, the rate
random walk becomes white, and every term below is stationary). The terms and the exact
discrete-time two-sided spectrum of their first differences, per cycle per sample (λ in cycles
per sample, var d = ∫_{-1/2}^{1/2} S(λ) dλ, unit (rad/s)²), with s = sin(πλ):

=========  =====================================  =========================================
term       parameters (SI)                        S_d(λ)
=========  =====================================  =========================================
``n``      ARW N [rad/√s] (white rate, N²/dt)     4 s² N² / dt
``k``      RRW K [rad/s/√s] (increments K√dt)     K² dt
``q``      quantization Q [rad] (white angle)     16 s⁴ Q² / dt²
``b``      bias instability B [rad/s] (flicker,   4 s² B² / (2π|λ|)
           one-sided PSD B²/(π f), ADEV 0.664 B)
``gm``     Gauss–Markov σ [rad/s], τc [s]          4 s² σ²(1 − φ²) / (1 − 2φ cos 2πλ + φ²),
           (AR(1), φ = e^{−dt/τc})                 parameters ``gm_sigma``, ``gm_tau``
=========  =====================================  =========================================

They are the processes the simulator makes (:mod:`gyroarray.effects`): ``arw`` (white σ = N/√dt),
``rrw`` (a cumulative sum of K√dt increments), ``quantization`` (Q² = Δ²/12, Allan 3Q²/τ²),
``gauss_markov`` (the exact AR(1)); the flicker term is the spectrum
:func:`gyroarray.core.physics.flicker_noise` shapes at the FFT frequencies (1/f noise has no
exact stationary sampled spectrum; the first difference makes it stationary at the frequencies
used). Only the ``n``, ``k``, ``q`` and ``gm`` spectra are exact.

The information
---------------
Whittle's approximation of the Gaussian likelihood of a part of ``m`` differences, over its
Fourier frequencies λ_j = j/m, j = 1 … m−1 (λ = 0 dropped: it holds the part's end-to-end
difference, not noise), gives the Fisher information

    I_ab = ½ Σ_{j=1}^{m−1} ∂log S(λ_j)/∂θ_a · ∂log S(λ_j)/∂θ_b

(the j and m−j terms are equal: the sum over the positive frequencies with weight 1, Nyquist ½).
Independent still parts add their informations; a part never crosses a gap. The CRB of θ_a is
√((I⁻¹)_aa). Above :data:`EXACT_FREQ` Fourier frequencies a part's sum is the exact sum over its
first :data:`EXACT_FREQ` frequencies plus m·∫ over the rest on a log-spaced midpoint grid
(:data:`GRID`); ``tests/test_crb.py`` checks the two agree.

For white + rate random walk and T ≫ τ_K = N/K the bound on K has the closed form
sd(K̂)/K = √(2 τ_K / T) (the Lorentzian integral of the K information, ``tests/test_crb.py``).

SI inside: rates rad/s, angles rad, times s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyroarray.core.errors import InputError

__all__ = ["TERMS", "PARAMS", "EXACT_FREQ", "GRID", "params_of", "diff_psd", "log_psd_grad",
           "part_lengths", "fisher", "crb", "Bound", "closed_form_k_rel", "crb_length"]

#: The noise terms the bound knows (see the module table).
TERMS = ("n", "k", "q", "b", "gm")

#: The parameters of each term, in order (SI: N [rad/√s], K [rad/s/√s], Q [rad], B [rad/s],
#: Gauss–Markov σ [rad/s] and τc [s]).
PARAMS = {"n": ("n",), "k": ("k",), "q": ("q",), "b": ("b",), "gm": ("gm_sigma", "gm_tau")}

#: Fourier frequencies of a part summed exactly; above, the rest as an integral.
EXACT_FREQ = 1 << 16

#: Points of the log-spaced grid the integral above :data:`EXACT_FREQ` uses.
GRID = 4096


def params_of(terms) -> tuple:
    """The parameter names of ``terms`` in order (``gm`` gives ``gm_sigma``, ``gm_tau``)."""
    out: list = []
    for t in terms:
        if t not in PARAMS:
            raise InputError(f"unknown noise term {t!r}: the bound knows {', '.join(TERMS)}")
        out.extend(PARAMS[t])
    if len(set(out)) != len(out):
        raise InputError(f"a noise term is given twice: {', '.join(terms)}")
    return tuple(out)


def _components(lam: np.ndarray, values: dict, dt_s: float) -> dict:
    """term -> (S_term(λ), {param: ∂S_term/∂log param}) for the terms in ``values``."""
    s2 = np.sin(np.pi * lam) ** 2
    out = {}
    if "n" in values:
        sn = 4.0 * s2 * values["n"] ** 2 / dt_s
        out["n"] = (sn, {"n": 2.0 * sn})
    if "k" in values:
        sk = np.full_like(lam, values["k"] ** 2 * dt_s)
        out["k"] = (sk, {"k": 2.0 * sk})
    if "q" in values:
        sq = 16.0 * s2 * s2 * values["q"] ** 2 / dt_s ** 2
        out["q"] = (sq, {"q": 2.0 * sq})
    if "b" in values:
        sb = 4.0 * s2 * values["b"] ** 2 / (2.0 * np.pi * np.abs(lam))
        out["b"] = (sb, {"b": 2.0 * sb})
    if "gm_sigma" in values:
        sig, tau = values["gm_sigma"], values["gm_tau"]
        phi = math.exp(-dt_s / tau)
        one_m_phi2 = -math.expm1(-2.0 * dt_s / tau)
        c = np.cos(2.0 * np.pi * lam)
        den = 1.0 - 2.0 * phi * c + phi * phi
        sg = 4.0 * s2 * sig ** 2 * one_m_phi2 / den
        dphi_dlogtau = phi * dt_s / tau                      # φ = e^{−dt/τ}: dφ/dlog τ = φ dt/τ
        dlog_dphi = -2.0 * phi / one_m_phi2 + 2.0 * (c - phi) / den
        out["gm"] = (sg, {"gm_sigma": 2.0 * sg, "gm_tau": sg * dlog_dphi * dphi_dlogtau})
    return out


def _check_values(values: dict, dt_s: float) -> None:
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        raise InputError(f"the sample step must be a positive number of seconds, got {dt_s!r}")
    if ("gm_sigma" in values) != ("gm_tau" in values):
        raise InputError("the Gauss–Markov term needs both gm_sigma [rad/s] and gm_tau [s]")
    for p, v in values.items():
        if p not in ("n", "k", "q", "b", "gm_sigma", "gm_tau"):
            raise InputError(f"unknown noise parameter {p!r}")
        if not (math.isfinite(v) and v > 0.0):
            raise InputError(f"noise parameter {p} must be a positive finite number (SI), got {v!r}")


def diff_psd(lam, values: dict, dt_s: float) -> np.ndarray:
    """Two-sided spectrum of the rate's first differences, per cycle per sample.

    Parameters
    ----------
    lam : array_like
        Frequencies λ [cycles/sample], 0 < |λ| <= ½.
    values : dict
        Parameter -> value, SI (``n`` [rad/√s], ``k`` [rad/s/√s], ``q`` [rad], ``b`` [rad/s],
        ``gm_sigma`` [rad/s] with ``gm_tau`` [s]); the terms absent are not in the model.
    dt_s : float
        Sample step [s].

    Returns
    -------
    ndarray
        S_d(λ) [(rad/s)² per cycle/sample].
    """
    _check_values(values, dt_s)
    lam = np.asarray(lam, dtype=float)
    comps = _components(lam, values, dt_s)
    return sum(c[0] for c in comps.values()) if comps else np.zeros_like(lam)


def log_psd_grad(lam, values: dict, dt_s: float, names: tuple | None = None) -> tuple:
    """S_d(λ) and ∂log S_d/∂log θ for each parameter.

    Parameters
    ----------
    lam : array_like
        Frequencies λ [cycles/sample].
    values : dict
        Parameter -> value, SI (as :func:`diff_psd`).
    dt_s : float
        Sample step [s].
    names : tuple, optional
        Parameter order of the rows (default: that of ``values``).

    Returns
    -------
    (ndarray, ndarray)
        S_d(λ) [(rad/s)² per cycle/sample], shape (L,), and the gradient, shape (P, L)
        (dimensionless: derivatives with respect to the log of each parameter).
    """
    _check_values(values, dt_s)
    lam = np.asarray(lam, dtype=float)
    names = tuple(values) if names is None else tuple(names)
    comps = _components(lam, values, dt_s)
    s = sum(c[0] for c in comps.values())
    derivs = {}
    for _, d in comps.values():
        derivs.update(d)
    g = np.stack([derivs[p] / s for p in names])
    return s, g


def part_lengths(n_samples: int | None = None, parts=None) -> list[int]:
    """Sample counts of the still parts: ``parts`` ((start, stop) sample ranges, stop exclusive)
    or the whole record of ``n_samples``; every part needs at least 3 samples."""
    if parts is None:
        if n_samples is None:
            raise InputError("give the record's sample count or its still parts")
        parts = [(0, int(n_samples))]
    out = []
    last = None
    for i, part in enumerate(parts):
        try:
            a, b = (int(v) for v in part)
        except (TypeError, ValueError):
            raise InputError(f"still part {i + 1} must be a (start, stop) sample range, got {part!r}") from None
        if a < 0 or b - a < 3:
            raise InputError(f"still part {i + 1} ({a}, {b}) must start at >= 0 and hold at least 3 samples")
        if n_samples is not None and b > n_samples:
            raise InputError(f"still part {i + 1} ({a}, {b}) runs past the record's {n_samples} samples")
        if last is not None and a < last:
            raise InputError(f"still part {i + 1} ({a}, {b}) overlaps or precedes the one before")
        last = b
        out.append(b - a)
    return out


def _part_fisher(m: int, values: dict, dt_s: float, names: tuple, band=None) -> np.ndarray:
    """Whittle information of one part of ``m`` first differences (positive frequencies), over
    the Fourier frequencies λ_j = j/m inside ``band`` ((lo, hi) in cycles/sample; default all
    but 0)."""
    half = m // 2
    j_lo, j_hi = 1, half
    if band is not None:
        j_lo = max(1, int(math.ceil(band[0] * m - 1e-9)))
        j_hi = min(half, int(math.floor(band[1] * m + 1e-9)))
    count = j_hi - j_lo + 1
    if count <= 0:
        return np.zeros((len(names), len(names)))
    if count <= EXACT_FREQ:
        j = np.arange(j_lo, j_hi + 1)
        w = np.ones(count)
        if m % 2 == 0 and j_hi == half:
            w[-1] = 0.5                                   # Nyquist: one real ordinate
        _, g = log_psd_grad(j / m, values, dt_s, names)
        return (g * w) @ g.T
    j = np.arange(j_lo, j_lo + EXACT_FREQ)
    _, g = log_psd_grad(j / m, values, dt_s, names)
    info = g @ g.T
    lo, hi = (j_lo + EXACT_FREQ - 0.5) / m, (j_hi + 0.5) / m if j_hi < half else 0.5
    edges = np.geomspace(lo, hi, GRID + 1)                # the rest: m·∫ over [lo, hi]
    mid = np.sqrt(edges[:-1] * edges[1:])
    _, g = log_psd_grad(mid, values, dt_s, names)
    return info + m * (g * np.diff(edges)) @ g.T


def fisher(values: dict, dt_s: float, *, n_samples: int | None = None, parts=None,
           band_hz=None) -> tuple:
    """Whittle Fisher information of the noise parameters for a record and its still parts.

    Parameters
    ----------
    values : dict
        Parameter -> true value, SI (``n`` [rad/√s], ``k`` [rad/s/√s], ``q`` [rad], ``b`` [rad/s],
        ``gm_sigma`` [rad/s], ``gm_tau`` [s]).
    dt_s : float
        Sample step [s].
    n_samples : int, optional
        Samples of the record (one part) when ``parts`` is not given.
    parts : sequence of (int, int), optional
        Still parts as sample ranges [start, stop); each is its own periodogram.
    band_hz : (float, float), optional
        Only the Fourier frequencies inside [lo, hi] Hz (the information of a band-limited
        likelihood, :func:`gyroarray.analysis.whittle.fit_whittle` with ``band_hz``); default
        all but 0.

    Returns
    -------
    (tuple, ndarray)
        The parameter names and the information matrix with respect to their logs, shape
        (P, P) (dimensionless; the information on θ itself is I_ab/(θ_a θ_b)).
    """
    _check_values(values, dt_s)
    names = tuple(values)
    lengths = part_lengths(n_samples, parts)
    band = None
    if band_hz is not None:
        lo, hi = (float(v) for v in band_hz)
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
            raise InputError(f"the frequency band must be 0 <= lo < hi Hz, got {band_hz!r}")
        band = (lo * dt_s, hi * dt_s)                      # cycles/sample
    info = np.zeros((len(names), len(names)))
    for n_part in lengths:
        info += _part_fisher(n_part - 1, values, dt_s, names, band)
    return names, info


@dataclass(frozen=True)
class Bound:
    """The CRB of each noise parameter.

    Parameters
    ----------
    values : dict
        Parameter -> value the bound is taken at, SI.
    sd : dict
        Parameter -> CRB standard deviation, the unit of the parameter (None: not identifiable,
        the information matrix is singular).
    rel : dict
        Parameter -> CRB standard deviation over the value [-].
    info : ndarray
        Fisher information with respect to the logs of the parameters, shape (P, P).
    duration_s : float
        Samples of all parts times the step [s].
    method : str
        How the bound is computed, in words.
    """

    values: dict
    sd: dict
    rel: dict
    info: np.ndarray
    duration_s: float
    method: str = ("Whittle Fisher information of the first differences of each still part, "
                   "exact discrete-time spectra (analysis.crb)")

    def to_json_dict(self) -> dict:
        """The bound as JSON (SI values; ``rel`` dimensionless)."""
        return {"values_si": {k: float(v) for k, v in self.values.items()},
                "crb_sd_si": {k: None if v is None else float(v) for k, v in self.sd.items()},
                "crb_rel": {k: None if v is None else float(v) for k, v in self.rel.items()},
                "duration_s": self.duration_s, "method": self.method}


def crb(values: dict, dt_s: float, *, n_samples: int | None = None, parts=None,
        band_hz=None) -> Bound:
    """Cramér–Rao bound of each noise parameter for a record of this length, rate and gaps.

    Parameters
    ----------
    values : dict
        Parameter -> true value, SI (as :func:`fisher`).
    dt_s : float
        Sample step [s].
    n_samples : int, optional
        Samples of the record when ``parts`` is not given.
    parts : sequence of (int, int), optional
        Still parts as sample ranges [start, stop).
    band_hz : (float, float), optional
        The bound of the likelihood over the Fourier frequencies inside [lo, hi] Hz only
        (default all but 0: the record's bound).

    Returns
    -------
    Bound
    """
    names, info = fisher(values, dt_s, n_samples=n_samples, parts=parts, band_hz=band_hz)
    sd, rel = {}, {}
    diag = np.diag(info).copy()
    ok = bool(np.all(np.isfinite(info)) and np.all(diag > 0.0))
    if ok:
        # the correlation form: terms whose informations differ by many decades (a tiny ARW
        # beside a large RRW) are judged by their correlation, not by the scales
        d = 1.0 / np.sqrt(diag)
        corr = info * np.outer(d, d)
        try:
            ok = np.linalg.cond(corr) < 1e12
            cov_corr = np.linalg.inv(corr) if ok else None
        except np.linalg.LinAlgError:
            ok = False
    for i, p in enumerate(names):
        r = math.sqrt(cov_corr[i, i]) * d[i] if ok and cov_corr is not None and cov_corr[i, i] > 0.0 else None
        rel[p] = r                                       # sd of log θ = relative sd of θ
        sd[p] = None if r is None else r * values[p]
    total = sum(part_lengths(n_samples, parts)) * dt_s
    if band_hz is None:
        return Bound(values=dict(values), sd=sd, rel=rel, info=info, duration_s=float(total))
    return Bound(values=dict(values), sd=sd, rel=rel, info=info, duration_s=float(total),
                 method=(f"Whittle Fisher information of the first differences of each still part over "
                         f"the Fourier frequencies in [{band_hz[0]:g}, {band_hz[1]:g}] Hz, exact "
                         "discrete-time spectra (analysis.crb)"))


def closed_form_k_rel(n_rad_rt_s: float, k_rad_s_rt_s: float, duration_s: float) -> float:
    """The white + walk bound on K for T ≫ τ_K: sd(K̂)/K = √(2 τ_K / T), τ_K = N/K [s].

    Parameters
    ----------
    n_rad_rt_s : float
        ARW N [rad/√s].
    k_rad_s_rt_s : float
        RRW K [rad/s/√s].
    duration_s : float
        Record length T [s].

    Returns
    -------
    float
        The relative 1σ bound [-].
    """
    return math.sqrt(2.0 * (n_rad_rt_s / k_rad_s_rt_s) / duration_s)


def crb_length(values: dict, rate_hz: float, param: str, rel_1sigma: float, *,
               min_samples: int = 64, max_s: float = 10 * 365.25 * 86400.0) -> float | None:
    """Shortest single-part record whose CRB relative 1σ on ``param`` reaches ``rel_1sigma``.

    Parameters
    ----------
    values : dict
        Parameter -> value, SI (as :func:`fisher`): the model the record follows.
    rate_hz : float
        Sample rate [Hz].
    param : str
        The parameter asked about (a key of ``values``).
    rel_1sigma : float
        Relative 1σ asked for [-] (a half-width p at confidence z: p/z).
    min_samples : int, default 64
        Fewest samples a record has.
    max_s : float, default ten years
        Longest record considered [s]; beyond it None.

    Returns
    -------
    float or None
        The record length T_CRB [s] (a whole number of samples over the rate), or None when
        the bound is not met within ``max_s``.

    Notes
    -----
    The bound falls about as 1/√T, so T ← T·(rel(T)/rel_1sigma)² converges in a few steps; the
    last steps bisect on whole sample counts (the relative bound is decreasing in T).
    """
    if param not in values:
        raise InputError(f"{param!r} is not a parameter of the model ({', '.join(values)})")
    if not (math.isfinite(rel_1sigma) and rel_1sigma > 0.0):
        raise InputError(f"the relative precision must be positive, got {rel_1sigma!r}")
    dt = 1.0 / float(rate_hz)
    n_max = int(max_s * rate_hz)

    def rel(n):
        r = crb(values, dt, n_samples=int(n)).rel[param]
        return math.inf if r is None else r

    n = max(min_samples, 1000)
    if rel(min_samples) <= rel_1sigma:
        return min_samples * dt
    lo, hi = min_samples, None                            # rel(lo) > target, rel(hi) <= target
    for _ in range(60):
        r = rel(n)
        if r <= rel_1sigma:
            hi = n if hi is None else min(hi, n)
        else:
            lo = max(lo, n)
        if hi is not None and hi - lo <= max(1, int(1e-5 * hi)):
            break
        if n >= n_max and r > rel_1sigma:
            return None
        step = (r / rel_1sigma) ** 2 if math.isfinite(r) else 16.0
        guess = int(math.ceil(n * min(max(step, 1.0 / 16.0), 16.0)))
        if hi is not None and not lo < guess < hi:
            guess = (lo + hi) // 2                         # bisect once the steps stall
        elif guess == n:
            guess = n + 1 if r > rel_1sigma else n - 1
        n = min(max(guess, min_samples), n_max)
    return None if hi is None else hi * dt
