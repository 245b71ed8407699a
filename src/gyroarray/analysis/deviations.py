"""More of the deviations people use, over one or several contiguous parts of a record.

Rate samples play the role of fractional frequency ``y`` and their cumulative sum (in
rate x samples) the role of phase ``x`` (NIST SP 1065); every sum below is written on the
phase of one contiguous part, so that no difference ever spans a part boundary (a still
part between motions, or a segment between two dropped packets).

Public API
----------
* :data:`DEVIATION_KINDS`, :func:`canonical_kind`: ``oadev`` (overlapping Allan),
  ``mdev`` (modified Allan), ``hdev`` (Hadamard, non-overlapping), ``ohdev`` (overlapping Hadamard),
  ``totdev`` (total).
* :func:`deviation_sums`: the squared-difference sums and their counts of one part.
* :func:`pooled_deviation`: a deviation over several parts, each part's mean removed and
  the sums pooled (the variance is the sum of the parts' sums over the sum of their counts).
* :func:`contiguous_segments`: the runs of a time-stamp vector without dropped samples.
* :func:`noise_id_lag1`: Riley & Greenhall's lag-1 autocorrelation noise identification.
* :func:`edf_of`: the equivalent degrees of freedom each kind uses, and which formula.
* :func:`analyse_parts`: deviation, noise id, EDF, confidence interval and the IEEE noise fit
  over parts (what ``gyroarray allan`` uses beyond one whole-record oadev/ohdev).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gyroarray.analysis.allan import (ONE_SIGMA, AllanAnalysis, AllanResult, averaging_factors,
                                      check_tau0, confidence_interval, edf, edf_greenhall, edf_simple)
from gyroarray.analysis.noise_fit import fit_noise_terms
from gyroarray.core.errors import InputError

__all__ = ["DEVIATION_KINDS", "KIND_ALIASES", "GAP_FACTOR", "canonical_kind", "phase_of",
           "deviation_sums", "pooled_deviation", "contiguous_segments", "lag1_acf",
           "noise_id_lag1", "edf_of", "RANGE_KIND", "EDF_METHODS", "analyse_parts", "with_noise_id"]

#: The deviations: name -> what it is.
DEVIATION_KINDS = {"oadev": "overlapping Allan", "mdev": "modified Allan",
                   "hdev": "Hadamard (non-overlapping, Stable32's HDEV)",
                   "ohdev": "overlapping Hadamard", "totdev": "total (Allan, reflected ends)"}
#: Other names accepted for a kind (none since ``hdev`` became the non-overlapping Hadamard).
KIND_ALIASES: dict[str, str] = {}
#: A time step longer than this many nominal steps is a gap (as the measurement reader's).
GAP_FACTOR = 1.5
#: Fewest block means the lag-1 noise identification reads (Riley & Greenhall: about 30).
MIN_ID_POINTS = 30
#: Fewest block means of one part that the pooled lag-1 identification reads: each part's line
#: taken out biases its lag-1 autocorrelation low (white FM: δ −0.12 at 20 means, −0.2 at 12,
#: −0.35 at 8, −1 at 4, which reads as white PM and gave pieces between dropped samples EDFs of
#: several hundred at τ where they hold a few), so shorter parts are left out.
MIN_ID_PART_BLOCKS = MIN_ID_POINTS
#: The formula behind each kind's EDF (said in the JSON).
EDF_METHODS = {
    "oadev": "Greenhall & Riley (2003) algorithm, sampled phase (gyroarray.analysis.allan.edf)",
    "ohdev": "Greenhall & Riley (2003) algorithm, sampled phase (gyroarray.analysis.allan.edf)",
    "hdev": "Greenhall & Riley (2003) algorithm at m = 1 on the phase taken every m-th point "
            "(the non-overlapping estimate is the overlapping one of the decimated phase)",
    "mdev": "Greenhall & Riley (2003) algorithm for modified variances (filter factor 1)",
    "totdev": "NIST SP 1065 Table 7 (b N/m - c) for alpha 0, -1, -2; Table 5 (simple) otherwise",
}
# Normalisation of each kind's sums: var = sums / (norm * m**p * count) (x in rate x samples).
_NORM = {"oadev": (2.0, 2), "ohdev": (6.0, 2), "hdev": (6.0, 2), "mdev": (2.0, 4), "totdev": (2.0, 2)}
#: The kind whose tau range :func:`averaging_factors` uses for each kind (largest m).
RANGE_KIND = {"oadev": "oadev", "ohdev": "ohdev", "hdev": "ohdev", "mdev": "ohdev", "totdev": "oadev"}


def canonical_kind(kind: str) -> str:
    """The deviation name for ``kind`` (:data:`KIND_ALIASES`); refuses an unknown one."""
    k = KIND_ALIASES.get(kind, kind)
    if k not in DEVIATION_KINDS:
        raise InputError(f"unknown deviation kind {kind!r}; expected one of "
                         f"{sorted([*DEVIATION_KINDS, *KIND_ALIASES])}")
    return k


def phase_of(rate) -> np.ndarray:
    """Phase of rate samples: ``x_0 = 0``, ``x_{i+1} = x_i + y_i - ȳ`` [rate x samples].

    Parameters
    ----------
    rate : array_like, shape (n,)
        Rate samples [rad/s].

    Returns
    -------
    numpy.ndarray, shape (n + 1,)
        The integrated, mean-removed rate (multiply by the sample step for an angle [rad]).
    """
    y = np.asarray(rate, dtype=float)
    x = np.zeros(y.size + 1)
    np.cumsum(y - y.mean(), out=x[1:])
    return x


def deviation_sums(x, m, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Sums of squared differences of one part's phase, and their counts, per averaging factor.

    Parameters
    ----------
    x : array_like, shape (N,)
        Phase [rate x samples] (:func:`phase_of`).
    m : array_like of int
        Averaging factors.
    kind : {"oadev", "mdev", "hdev", "ohdev", "totdev"}

    Returns
    -------
    sums, counts : numpy.ndarray
        ``sums[i]`` over ``counts[i]`` summands at ``m[i]``; both 0 where the part is too short.

    Notes
    -----
    With :math:`\\Delta^2_i = x_{i+2m} - 2x_{i+m} + x_i` (NIST SP 1065):

    * oadev: :math:`\\sum_{i=0}^{N-2m-1}(\\Delta^2_i)^2`, count :math:`N-2m`, variance sum/(2 m² count);
    * mdev: :math:`\\sum_{j=0}^{N-3m}(\\sum_{i=j}^{j+m-1}\\Delta^2_i)^2` (a cumulative sum of
      :math:`\\Delta^2`), count :math:`N-3m+1`, variance sum/(2 m⁴ count) (eq. 14);
    * ohdev: third differences :math:`x_{i+3m}-3x_{i+2m}+3x_{i+m}-x_i`, count :math:`N-3m`,
      variance sum/(6 m² count) (eq. 20);
    * hdev: the same third differences at :math:`i = 0, m, 2m, \\dots` only (non-overlapping,
      Stable32's HDEV), count :math:`\\lfloor (N-1)/m \\rfloor - 2`, variance sum/(6 m² count);
    * totdev: the phase reflected at both ends, :math:`x^*_{-j} = 2x_0 - x_j`,
      :math:`x^*_{N-1+j} = 2x_{N-1} - x_{N-1-j}`, second differences centred on
      :math:`i = 1..N-2`, count :math:`N-2`, variance sum/(2 m² count) (eq. 25).
    """
    kind = canonical_kind(kind)
    x = np.asarray(x, dtype=float)
    n = x.size
    ms = np.atleast_1d(np.asarray(m, dtype=np.int64))
    sums, counts = np.zeros(ms.size), np.zeros(ms.size, dtype=np.int64)
    if kind == "totdev" and n >= 3:
        ext = np.concatenate([2.0 * x[0] - x[n - 2:0:-1], x, 2.0 * x[-1] - x[-2:0:-1]])
        mid = n - 2
    for i, mm in enumerate(ms.tolist()):
        if kind == "oadev" and n - 2 * mm >= 1:
            d = x[2 * mm:] - 2.0 * x[mm:n - mm] + x[:n - 2 * mm]
        elif kind == "ohdev" and n - 3 * mm >= 1:
            d = x[3 * mm:] - 3.0 * x[2 * mm:n - mm] + 3.0 * x[mm:n - 2 * mm] - x[:n - 3 * mm]
        elif kind == "hdev" and (n - 1) // mm >= 3:
            xs = x[::mm]
            d = xs[3:] - 3.0 * xs[2:-1] + 3.0 * xs[1:-2] - xs[:-3]
        elif kind == "mdev" and n - 3 * mm + 1 >= 1:
            d2 = x[2 * mm:] - 2.0 * x[mm:n - mm] + x[:n - 2 * mm]
            c = np.concatenate([[0.0], np.cumsum(d2)])
            d = c[mm:] - c[:-mm]
        elif kind == "totdev" and n >= 3 and mm <= n - 1:
            centre = mid + np.arange(1, n - 1)
            d = ext[centre - mm] - 2.0 * ext[centre] + ext[centre + mm]
        else:
            continue
        sums[i] = float(d @ d)
        counts[i] = d.size
    return sums, counts


def pooled_deviation(parts, tau0_s: float, kind: str = "oadev", taus="octave") -> AllanResult:
    """A deviation of rate over several contiguous parts, their Allan sums pooled.

    Parameters
    ----------
    parts : sequence of array_like
        Rate samples of each contiguous part [rad/s] (one array: the whole record).
    tau0_s : float
        Sample step [s].
    kind : {"oadev", "mdev", "hdev", "ohdev", "totdev"}
    taus : "octave", int or sequence of float
        Averaging times (:func:`~gyroarray.analysis.allan.averaging_factors`, over the
        longest part).

    Returns
    -------
    AllanResult
        ``dev`` [rad/s], ``n_terms`` the pooled count of summands, ``n_phase`` the phase
        points of the longest part.

    Raises
    ------
    InputError
        No part, non-finite values, too short for the kind, bad ``taus``.

    Notes
    -----
    Each part's own mean is removed (:func:`phase_of`); at each ``m`` the variance is
    :math:`\\sum_k S_k / (c\\, m^p \\sum_k n_k)`, the parts' sums :math:`S_k` over their counts
    :math:`n_k` (:func:`deviation_sums`), so no difference crosses a part boundary. It equals
    the count-weighted mean of the parts' variances, :math:`\\sum_k n_k\\sigma_k^2/\\sum_k n_k`.
    A part too short for an ``m`` adds nothing there.
    """
    kind = canonical_kind(kind)
    tau0 = check_tau0(tau0_s)
    arrays = [np.asarray(p, dtype=float).ravel() for p in parts]
    if not arrays or max(a.size for a in arrays) < 4:
        raise InputError(f"too few samples for {kind}: the longest contiguous part needs at "
                         "least 4")
    for a in arrays:
        if not np.all(np.isfinite(a)):
            raise InputError("rate has a non-finite value")
    n_phase = max(a.size for a in arrays) + 1
    m = averaging_factors(n_phase, tau0, taus, RANGE_KIND[kind])
    total, count = np.zeros(m.size), np.zeros(m.size, dtype=np.int64)
    for a in arrays:
        s, c = deviation_sums(phase_of(a), m, kind)
        total += s
        count += c
    norm, power = _NORM[kind]
    dev = np.sqrt(total / (norm * m.astype(float) ** power * count))
    return AllanResult(kind=kind, tau0_s=tau0, n_phase=int(n_phase), m=m, taus_s=m * tau0,
                       dev=dev, n_terms=count)


def contiguous_segments(time_s, dt_s: float | None = None) -> tuple[list[tuple[int, int]], int]:
    """``[start, stop)`` runs of samples with no dropped sample between them.

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Sample times [s], increasing.
    dt_s : float, optional
        Nominal step [s]; default the median step.

    Returns
    -------
    segments : list of (int, int)
        The runs; a step longer than :data:`GAP_FACTOR` nominal steps starts a new one.
    missing : int
        Samples missing in the gaps, ``round(step / dt) - 1`` each.
    """
    t = np.asarray(time_s, dtype=float)
    step = np.diff(t)
    if step.size == 0:
        return [(0, t.size)], 0
    dt = float(np.median(step)) if dt_s is None else float(dt_s)
    cut = np.flatnonzero(step > GAP_FACTOR * dt)
    edges = [0, *(cut + 1).tolist(), t.size]
    missing = int(np.sum(np.rint(step[cut] / dt) - 1)) if cut.size else 0
    return list(zip(edges[:-1], edges[1:])), missing



#: Shortest piece [samples] a still part keeps when it is cut at the gaps (:func:`cut_at_segments`).
MIN_CUT_PART = 4


def cut_at_segments(parts, segments) -> list[tuple[int, int]]:
    """``[start, stop)`` parts cut where ``segments`` (:func:`contiguous_segments`) end: the pieces of
    at least :data:`MIN_CUT_PART` samples, so that no difference spans a gap."""
    cut = [(max(a, c), min(b, e)) for a, b in parts for c, e in segments]
    return [(a, b) for a, b in cut if b - a >= MIN_CUT_PART]

def lag1_acf(x) -> float:
    """Lag-1 autocorrelation ``Σ(x_i − x̄)(x_{i+1} − x̄) / Σ(x_i − x̄)²`` (Riley & Greenhall eq. 2)."""
    x = np.asarray(x, dtype=float)
    d = x - x.mean()
    den = float(d @ d)
    return float(d[:-1] @ d[1:]) / den if den > 0 else 0.0


def _detrend(x: np.ndarray) -> np.ndarray:
    """``x`` less its least-squares line (closed form; as ``numpy.polyfit(t, x, 1)``)."""
    t = np.arange(x.size, dtype=float)
    t -= t.mean()
    c = x - x.mean()
    return c - t * (float(t @ c) / float(t @ t))


def noise_id_lag1(parts, m: int, *, dmax: int = 2) -> dict | None:
    """Power-law noise type at averaging factor ``m`` from the lag-1 autocorrelation.

    Parameters
    ----------
    parts : sequence of array_like
        Rate samples of each contiguous part [rad/s].
    m : int
        Averaging factor.
    dmax : int, default 2
        Most differences taken (2 for the Allan kinds, 3 for Hadamard).

    Returns
    -------
    dict or None
        ``alpha`` (the rate PSD exponent as an integer, +2 white PM .. -2 random-walk FM, below
        with ``dmax`` 3), ``alpha_float``, ``d`` (differences taken), ``rho`` [-]; None when the
        parts of at least :data:`MIN_ID_PART_BLOCKS` block means hold fewer than
        :data:`MIN_ID_POINTS` of them at this ``m``.

    Notes
    -----
    Riley & Greenhall (2004): the rate is averaged in non-overlapping blocks of ``m``
    samples, a line is removed from each part, and the series is differenced ``d`` times
    until :math:`\\delta = r_1/(1+r_1) < 0.25` (or ``d = dmax``), :math:`r_1` the lag-1
    autocorrelation (pooled over parts, each part's own mean removed); then
    :math:`\\alpha = -2(\\delta + d)`, reported rounded as :math:`-\\mathrm{round}(2\\delta) - 2d`.
    The same as ``allantools.autocorr_noise_id(y, m, data_type="freq")`` on one part.

    References
    ----------
    .. [1] W. J. Riley, C. A. Greenhall, "Power law noise identification using the lag 1
       autocorrelation", Proc. 18th European Frequency and Time Forum, 2004.
    """
    series = []
    for p in parts:
        y = np.asarray(p, dtype=float).ravel()
        b = y.size // m
        if b >= MIN_ID_PART_BLOCKS:
            series.append(_detrend(y[:b * m].reshape(b, m).mean(axis=1)))
    if sum(s.size for s in series) < MIN_ID_POINTS:
        return None
    d = 0
    while True:
        num = den = 0.0
        for s in series:
            if s.size < 2:
                continue
            c = s - s.mean()
            num += float(c[:-1] @ c[1:])
            den += float(c @ c)
        r1 = num / den if den > 0 else 0.0
        rho = r1 / (1.0 + r1)
        if rho < 0.25 or d >= dmax:
            return {"alpha": int(-round(2.0 * rho) - 2 * d), "alpha_float": -2.0 * (rho + d),
                    "d": d, "rho": rho}
        series = [np.diff(s) for s in series if s.size >= 2]
        d += 1


def edf_of(kind: str, n_phase: int, m, alpha) -> np.ndarray:
    """Equivalent degrees of freedom of one contiguous part, per averaging factor.

    Parameters
    ----------
    kind : {"oadev", "mdev", "hdev", "ohdev", "totdev"}
    n_phase : int
        Phase points of the part (rate samples + 1).
    m, alpha : array_like of int
        Averaging factors and noise types (rate PSD exponent, clipped to +2 .. -2).

    Returns
    -------
    numpy.ndarray
        EDF [-]; 0 where the part is too short for ``m``. The formula is :data:`EDF_METHODS`.
    """
    kind = canonical_kind(kind)
    ms = np.atleast_1d(np.asarray(m, dtype=np.int64))
    aa = np.clip(np.broadcast_to(np.asarray(alpha, dtype=np.int64), ms.shape), -2, 2)
    out = np.zeros(ms.size)
    for i, (mm, a) in enumerate(zip(ms.tolist(), aa.tolist())):
        if kind in ("oadev", "ohdev"):
            d = 2 if kind == "oadev" else 3
            if n_phase - d * mm >= 1:
                out[i] = float(edf(kind, n_phase, mm, a)[()])
        elif kind == "hdev":
            n_dec = (n_phase - 1) // mm + 1              # the phase taken every m-th point
            if n_dec >= 4:
                out[i] = float(edf("ohdev", n_dec, 1, a)[()])
        elif kind == "mdev":
            if n_phase - 3 * mm + 1 >= 1:
                out[i] = float(edf_greenhall(n_phase, mm, a, 2, modified=True)[()])
        elif mm <= n_phase - 1 and n_phase > 3:                 # totdev
            if a in (0, -1, -2):
                b, c = {0: (1.50, 0.0), -1: (1.17, 0.22), -2: (0.93, 0.36)}[a]
                out[i] = b * (n_phase / mm) - c
            elif n_phase - 2 * mm >= 1:
                out[i] = float(edf_simple(n_phase, mm, a)[()])
    return np.maximum(out, 0.0)


def analyse_parts(parts, tau0_s: float, taus="octave", kind: str = "oadev", *,
                  confidence: float = ONE_SIGMA, fit_method: str = "gls") -> AllanAnalysis:
    """Deviation, lag-1 noise identification, EDF, confidence interval and noise fit over parts.

    Parameters
    ----------
    parts : sequence of array_like
        Rate samples of each contiguous part [rad/s].
    tau0_s : float
        Sample step [s].
    taus : "octave", int or sequence of float
        Averaging times.
    kind : {"oadev", "mdev", "hdev", "ohdev", "totdev"}
    confidence : float
        Two-sided level of the bounds.
    fit_method : {"gls", "wls"}
        The IEEE Std 952 fit (:func:`~gyroarray.analysis.noise_fit.fit_noise_terms`).

    Returns
    -------
    AllanAnalysis
        ``info`` holds ``noise_id`` (per tau: ``alpha``, ``d``, ``rho`` or None),
        ``edf_method``, ``fit_from`` and ``parts`` (their count).

    Notes
    -----
    The IEEE terms are fitted to the overlapping Allan (or Hadamard) variance over the parts,
    whose term constants are known (:mod:`~gyroarray.analysis.noise_fit`): for ``mdev`` and
    ``totdev`` the fit is that of the oadev of the same parts, for ``hdev`` that of the ohdev
    (``fit_from``), and the curve and
    its confidence interval are the asked kind's. The EDF of pooled parts is the sum of the
    parts' EDFs (independent parts); each tau's noise type is the lag-1 identification
    (:func:`noise_id_lag1`; a tau with too few blocks takes the previous tau's type, the first
    white FM).
    """
    kind = canonical_kind(kind)
    arrays = [np.asarray(p, dtype=float).ravel() for p in parts]
    res = pooled_deviation(arrays, tau0_s, kind, taus)
    if np.any(~(res.dev > 0)):
        i = int(np.flatnonzero(~(res.dev > 0))[0])
        raise InputError(f"the {kind} is zero at tau = {float(res.taus_s[i]):g} s: "
                         "the rate is constant (or exactly linear there)")
    # the hdev's expectation is the ohdev's (the same third differences, fewer of them): fitted
    # from the ohdev, the more efficient estimate of the same curve
    fit_kind = kind if kind in ("oadev", "ohdev") else "ohdev" if kind == "hdev" else "oadev"
    fit_res = res if fit_kind == kind else pooled_deviation(arrays, tau0_s, fit_kind, res.taus_s)
    sizes = [a.size + 1 for a in arrays]

    def pooled_edf(k, m, alpha):
        return sum(edf_of(k, n, m, alpha) for n in sizes)

    fit = fit_noise_terms(fit_res, lambda alpha: np.maximum(pooled_edf(fit_kind, fit_res.m, alpha),
                                                             1e-3), method=fit_method)
    ids, alpha, last = [], [], 0
    for mm in res.m.tolist():
        nid = noise_id_lag1(arrays, mm, dmax=3 if kind in ("hdev", "ohdev") else 2)
        ids.append(nid)
        if nid is not None:
            last = nid["alpha"]
        alpha.append(last)
    nu = np.maximum(pooled_edf(kind, res.m, np.asarray(alpha)), 1e-3)
    low, high = confidence_interval(res.dev, nu, confidence)
    info = {"noise_id": [None if d is None else {"alpha": d["alpha"], "alpha_float": d["alpha_float"],
                                                 "d": d["d"], "rho": d["rho"]} for d in ids],
            "noise_id_method": "lag-1 autocorrelation (Riley & Greenhall 2004) of the tau-averaged, "
                               "differenced rate",
            "edf_method": EDF_METHODS[kind] + ", noise type per tau from the lag-1 identification"
                          + (", summed over the parts" if len(arrays) > 1 else ""),
            "edf_alpha": [int(a) for a in alpha],
            "fit_from": fit_kind, "parts": len(arrays)}
    return AllanAnalysis(kind=kind, tau0_s=res.tau0_s, taus_s=res.taus_s, m=res.m,
                         n_terms=res.n_terms, adev_rad_s=res.dev, ci_low_rad_s=low,
                         ci_high_rad_s=high, edf=nu, confidence=float(confidence), fit=fit,
                         info=info)


def with_noise_id(analysis: AllanAnalysis, rate) -> AllanAnalysis:
    """``analysis`` with the lag-1 noise identification per tau of ``rate`` in its ``info``."""
    dmax = 3 if analysis.kind == "ohdev" else 2
    ids = [noise_id_lag1([rate], mm, dmax=dmax) for mm in analysis.m.tolist()]
    info = {**analysis.info, "noise_id": ids,
            "noise_id_method": "lag-1 autocorrelation (Riley & Greenhall 2004) of the tau-averaged, "
                               "differenced rate",
            "edf_method": EDF_METHODS[analysis.kind] + ", noise type per tau from the noise fit"}
    return replace(analysis, info=info)

