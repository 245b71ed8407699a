"""Each gyro's white level, read one way: the Allan variance pooled over still parts.

A real array's still record is a set of parts (hand-placed orientations of
~20 s, each with its own bias), not one long run. Reading a gyro's white level
from the longest part alone (25 s of 416 s on the MIMU4444 board) leaves it to
one part's luck; reading it across the joins of the stitched parts adds the
bias steps between orientations as slow noise. :func:`pooled_octave_avar`
reads every part and never differences across a join:

    σ²(mτ0) = Σ_p Σ_i (X_p,i+2m − 2X_p,i+m + X_p,i)² / (2 m² Σ_p M_p),

X_p the cumulative sum of part p's rate minus its own mean, M_p = n_p + 1 − 2m
the terms of part p (parts with M_p < 1 do not contribute at that m), and its
white-FM EDF the sum of the parts' (:func:`~gyroarray.analysis.allan.edf_simple`).
On one part it is the overlapping Allan variance (NIST SP 1065 eq. 11), bit for
bit what :func:`octave_avar` gives.

:func:`white_walk_fit` fits σ²(τ) = N²/τ + K²τ/3 at the octave τ where white
noise dominates (from 1 s, the IEEE Std 952 reading of ARW, up to what the parts
support), weighted by each point's standard error, with the sandwich covariance
of the estimates (:class:`~gyroarray.analysis.avar_covariance.AvarCovariance`,
per part, pooled with weights M_p/ΣM). This is the white level that ``fit``,
``fuse``, ``design --model`` and the ``[array]`` table share
(``docs/model-format.md``).

:func:`pooled_allan_covariance` is the cross term of the same estimator: the
Allan covariance matrix at τ between the gyros (Vaccaro & Zaki's cross Allan
variance, overlapping, pooled over the parts), whose diagonal is
:func:`pooled_octave_avar`'s.

References
----------
R. J. Vaccaro, A. S. Zaki, "Statistical modeling of rate gyros", IEEE Trans.
Instrum. Meas. 61(3), 2012. IEEE Std 952-1997, annex C. W. J. Riley, NIST SP
1065, 2008.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from gyroarray.analysis.allan import averaging_factors, edf_simple
from gyroarray.analysis.avar_covariance import AvarCovariance
from gyroarray.core import units

__all__ = ["WhiteWalk", "PooledAvar", "pooled_octave_avar", "pooled_allan_covariance", "white_walk_fit",
           "white_walk_of_avar", "white_m", "pooled_edf", "pooled_white_level", "PooledDeviation", "pooled_deviation", "nnls2", "octave_avar", "MIN_TAU_S", "FIT_SPAN", "PART_SPAN",
           "MIN_FIT_OCTAVES", "MIN_POOLED_EDF"]

#: Shortest τ of the white + walk fit [s] (IEEE Std 952: ARW read at τ = 1 s and beyond).
MIN_TAU_S = 1.0
#: Slowest octave τ of the fit on one part, as a fraction of its length [-].
FIT_SPAN = 1.0 / 8.0
#: Slowest octave τ of the fit pooled over several parts, as a fraction of the longest part [-]
#: (the parts' EDFs add: on 20 parts of 22 s, τ = 4 s has a pooled EDF of about 110).
PART_SPAN = 1.0 / 4.0
#: Fewest pooled white-FM EDF an octave of a pooled fit needs [-].
MIN_POOLED_EDF = 10.0
#: Fewest octaves of the white + walk fit.
MIN_FIT_OCTAVES = 3


@dataclass(frozen=True)
class WhiteWalk:
    """White + random-walk fit of C rate series [SI].

    Attributes
    ----------
    arw_rad_rt_s, arw_sigma : ndarray (C,)
        Angle random walk N and its 1σ [rad/√s].
    rrw_rad_s_rt_s, rrw_sigma : ndarray (C,)
        Rate random walk K and its 1σ [rad/s/√s].
    taus_s : ndarray or None
        The octave τ the fit read [s] (None: from the first differences).
    """

    arw_rad_rt_s: np.ndarray
    arw_sigma: np.ndarray
    rrw_rad_s_rt_s: np.ndarray
    rrw_sigma: np.ndarray
    taus_s: np.ndarray | None = None


@dataclass(frozen=True)
class PooledAvar:
    """Octave Allan variance pooled over parts (:func:`pooled_octave_avar`).

    Attributes
    ----------
    taus_s : ndarray (M,)
        Averaging times [s].
    avar : ndarray (M, C)
        Allan variance [rad²/s²].
    m : ndarray (M,)
        Averaging factors [samples].
    terms : ndarray (P, M)
        Second differences each part contributes at each m (0: the part is too short).
    edf : ndarray (M,)
        White-FM equivalent degrees of freedom, summed over the contributing parts [-].
    lengths : ndarray (P,)
        Samples of each part.
    """

    taus_s: np.ndarray
    avar: np.ndarray
    m: np.ndarray
    terms: np.ndarray
    edf: np.ndarray
    lengths: np.ndarray

    @property
    def adev(self) -> np.ndarray:
        """Allan deviation (M, C) [rad/s]."""
        return np.sqrt(np.maximum(self.avar, 0.0))


def _parts(n: int, parts) -> list[tuple[int, int]]:
    if parts is None or len(parts) == 0:
        return [(0, n)]
    out = [(int(a), int(b)) for a, b in parts]
    for a, b in out:
        if not (0 <= a < b <= n):
            raise ValueError(f"part [{a}, {b}) outside a record of {n} samples")
    return out


def _phase(seg: np.ndarray) -> np.ndarray:
    n = seg.shape[0]
    phase = np.zeros((n + 1, seg.shape[1]))
    np.cumsum(seg - seg.mean(axis=0), axis=0, out=phase[1:])
    return phase


def octave_avar(x, dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Overlapping Allan variance of each column at the octave τ (numpy, all columns at once).

    Parameters
    ----------
    x : array_like, shape (n, C)
        Rate samples [rad/s].
    dt_s : float
        Sample step [s].

    Returns
    -------
    taus_s : ndarray (M,)
        Averaging times [s].
    avar : ndarray (M, C)
        Allan variance [rad²/s²].
    m : ndarray (M,)
        Averaging factors.
    n_phase : int
        n + 1 phase points.

    Notes
    -----
    σ²(mτ0) = Σ_i (X_{i+2m} − 2X_{i+m} + X_i)² / (2 m² (n+1 − 2m)), X the cumulative sum
    of the rate minus its mean (NIST SP 1065 eq. 11, angle in rate·samples).
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    phase = _phase(x)
    m = averaging_factors(n + 1, dt_s, "octave")
    avar = np.empty((m.size, x.shape[1]))
    for i, mm in enumerate(m.tolist()):
        d = phase[2 * mm:] - 2.0 * phase[mm:n + 1 - mm] + phase[:n + 1 - 2 * mm]
        avar[i] = np.einsum("ij,ij->j", d, d) / (2.0 * mm * mm * (n + 1 - 2 * mm))
    return m * dt_s, avar, m, n + 1


def pooled_octave_avar(x, dt_s: float, parts=None) -> PooledAvar:
    """Overlapping Allan variance at the octave τ, pooled over ``parts`` (module docstring).

    Parameters
    ----------
    x : array_like, shape (n, C)
        Rate samples [rad/s] (the still parts, e.g. stitched end to end).
    dt_s : float
        Sample step [s].
    parts : list of (int, int), optional
        ``[start, stop)`` of each part in ``x``; default one part, the whole of ``x``.
        Nothing is differenced across a part's edge; each part's own mean is taken out.

    Returns
    -------
    PooledAvar
        The octave m = 1, 2, 4, ... up to the longest part's (at least one term in it).
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    n, c = x.shape
    pts = _parts(n, parts)
    lengths = np.array([b - a for a, b in pts], dtype=np.int64)
    longest = int(lengths.max())
    m = averaging_factors(longest + 1, dt_s, "octave")
    sums = np.zeros((m.size, c))
    terms = np.zeros((len(pts), m.size), dtype=np.int64)
    for p, (a, b) in enumerate(pts):
        np_ = b - a
        phase = _phase(x[a:b])
        for i, mm in enumerate(m.tolist()):
            k = np_ + 1 - 2 * mm
            if k < 1:
                break
            d = phase[2 * mm:] - 2.0 * phase[mm:np_ + 1 - mm] + phase[:np_ + 1 - 2 * mm]
            sums[i] += np.einsum("ij,ij->j", d, d)
            terms[p, i] = k
    total = terms.sum(axis=0)
    if len(pts) == 1:                          # bit for bit octave_avar's expression
        avar = np.empty_like(sums)
        for i, mm in enumerate(m.tolist()):
            avar[i] = sums[i] / (2.0 * mm * mm * (lengths[0] + 1 - 2 * mm))
    else:
        avar = sums / (2.0 * (m.astype(float) ** 2) * np.maximum(total, 1))[:, None]
    edf = np.zeros(m.size)
    for p in range(len(pts)):
        live = terms[p] > 0
        if live.any():
            edf[live] += np.asarray(edf_simple(int(lengths[p]) + 1, m[live], 0), dtype=float)
    return PooledAvar(m * dt_s, avar, m, terms, edf, lengths)


@dataclass(frozen=True)
class PooledDeviation:
    """The Allan deviation of one series pooled over parts, with its χ² interval (EDF summed over
    the parts), in the shape ``fuse --json`` writes (:meth:`to_json_dict`)."""

    taus_s: np.ndarray
    adev_rad_s: np.ndarray
    ci_low_rad_s: np.ndarray
    ci_high_rad_s: np.ndarray
    edf: np.ndarray
    confidence: float
    n_parts: int
    kind: str = "oadev"

    def to_json_dict(self) -> dict:
        """JSON-ready dict in deg/h (the keys of :meth:`~gyroarray.analysis.allan.AllanAnalysis.to_json_dict`)."""

        def deg_h(a):
            return [float(v) for v in units.rad_s_to_deg_h(np.asarray(a))]
        return {"kind": self.kind, "confidence": float(self.confidence),
                "taus_s": [float(t) for t in self.taus_s], "adev_deg_h": deg_h(self.adev_rad_s),
                "ci_low_deg_h": deg_h(self.ci_low_rad_s), "ci_high_deg_h": deg_h(self.ci_high_rad_s),
                "edf": [float(v) for v in self.edf],
                "pooled": f"overlapping ADEV pooled over {self.n_parts} parts, never across a join; "
                          "EDF (white FM) summed over the parts"}


def pooled_deviation(x, dt_s: float, parts, confidence: float) -> PooledDeviation:
    """:func:`pooled_octave_avar` of one series (n,) at the octave τ where it has a pooled EDF
    of at least 1, with the two-sided χ² interval at ``confidence``."""
    pa = pooled_octave_avar(np.asarray(x, float)[:, None], dt_s, parts)
    keep = pa.edf >= 1.0
    edf = pa.edf[keep]
    adev = pa.adev[keep, 0]
    lo_q, hi_q = (1.0 - confidence) / 2.0, (1.0 + confidence) / 2.0
    lo = adev * np.sqrt(edf / stats.chi2.ppf(hi_q, edf))
    hi = adev * np.sqrt(edf / stats.chi2.ppf(lo_q, edf))
    return PooledDeviation(pa.taus_s[keep], adev, lo, hi, edf, float(confidence), int(pa.lengths.size))


def pooled_allan_covariance(x, dt_s: float, m: int, parts=None) -> tuple[np.ndarray, int]:
    """Overlapping Allan covariance matrix at τ = m·dt, pooled over ``parts``.

    ``A_ij = Σ_p Σ_k d_p,i(k) d_p,j(k) / (2 m² Σ_p M_p)`` with d the second differences of
    each part's cumulative rate (its mean out) at lag m (:func:`pooled_octave_avar`); the
    diagonal is the pooled Allan variance. Positive semi-definite by construction.

    Parameters
    ----------
    x : array_like, shape (n, C)
        Rate samples [rad/s].
    dt_s : float
        Sample step [s] (unused by the value; kept for symmetry with the others).
    m : int
        Averaging factor [samples].
    parts : list of (int, int), optional
        As :func:`pooled_octave_avar`.

    Returns
    -------
    A : ndarray (C, C)
        Allan covariance [rad²/s²] (nan when no part has a term).
    terms : int
        Second differences pooled (Σ_p M_p).
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    n, c = x.shape
    mm = int(m)
    if mm < 1:
        raise ValueError(f"m must be >= 1, got {m}")
    acc = np.zeros((c, c))
    total = 0
    for a, b in _parts(n, parts):
        np_ = b - a
        if np_ + 1 - 2 * mm < 1:
            continue
        phase = _phase(x[a:b])
        d = phase[2 * mm:] - 2.0 * phase[mm:np_ + 1 - mm] + phase[:np_ + 1 - 2 * mm]
        acc += d.T @ d
        total += np_ + 1 - 2 * mm
    if total == 0:
        return np.full((c, c), np.nan), 0
    return acc / (2.0 * mm * mm * total), total


def white_m(dt_s: float, tau_s: float = MIN_TAU_S) -> int:
    """The averaging factor of the white reading: τ1/dt rounded half up, at least 1 [samples]
    (63 at 62.5 Hz)."""
    return max(int(math.floor(float(tau_s) / float(dt_s) + 0.5)), 1)


def pooled_edf(parts, m: int) -> float:
    """White-FM EDF of the overlapping Allan variance at m samples pooled over ``parts``: the
    parts' own EDFs summed, parts with no term at m left out [-]."""
    return float(sum(float(edf_simple(b - a + 1, m, 0)) for a, b in parts if b - a + 1 - 2 * m >= 1))


def pooled_white_level(x, dt_s: float, parts=None, tau_s: float = MIN_TAU_S):
    """Each column's white level read at τ1 ≈ ``tau_s``: N = σ(τ1)·√τ1, σ² the overlapping Allan
    variance pooled over ``parts`` (:func:`pooled_allan_covariance`'s diagonal), τ1 = m·dt with
    m = :func:`white_m`; its 1σ N/√(2·EDF), EDF the white-FM EDF summed over the parts.

    Returns
    -------
    (N [rad/√s], 1σ [rad/√s], τ1 [s], EDF) as arrays (C,), (C,), float, float; or None when no
    part is longer than 2m samples.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    pts = _parts(x.shape[0], parts)
    m = white_m(dt_s, tau_s)
    A, total = pooled_allan_covariance(x, dt_s, m, pts)
    if total == 0:
        return None
    edf = pooled_edf(pts, m)
    tau1 = m * float(dt_s)
    n = np.sqrt(np.maximum(np.diag(A), 0.0) * tau1)
    return n, n / math.sqrt(2.0 * max(edf, 1.0)), tau1, edf


def nnls2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """argmin ||a c − b|| over c >= 0 for a (M, 2) design (closed form: the unconstrained
    solution, else the better of the two one-column fits)."""
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    u = a / scale
    c, *_ = np.linalg.lstsq(u, b, rcond=None)
    if np.all(c >= 0):
        return c / scale
    best, best_r = np.zeros(2), float(b @ b)
    for j in range(2):
        cj = max(float(u[:, j] @ b), 0.0)            # unit column: the one-column fit
        r = float(np.sum((b - cj * u[:, j]) ** 2))
        if r < best_r:
            best, best_r = np.zeros(2), r
            best[j] = cj
    return best / scale


def _fit_columns(t, av, edf, a, covariance) -> WhiteWalk:
    """The weighted white + walk fit of each column of ``av`` (M, C) at ``t`` (module docstring);
    ``covariance(coef)``: the estimates' covariance under the fitted {"n": N², "k": K²}."""
    c = av.shape[1]
    arw, arw_s = np.zeros(c), np.full(c, np.nan)
    rrw, rrw_s = np.zeros(c), np.full(c, np.nan)
    for j in range(c):
        target = av[:, j]
        if not np.any(target > 0):
            continue
        model = target.copy()
        coef = np.zeros(2)
        for _ in range(2):
            se = np.maximum(model, 1e-300) * np.sqrt(2.0 / edf)
            coef = nnls2(a / se[:, None], target / se)
            model = a @ coef
        w = 1.0 / (np.maximum(model, 1e-300) * np.sqrt(2.0 / edf)) ** 2
        with np.errstate(all="ignore"):
            cov = np.linalg.pinv((a * w[:, None]).T @ a)
            # the octave estimates correlate (about 0.5 between neighbours for white FM): the
            # weighted fit's covariance is the sandwich B Σ Bᵀ, B = (AᵀWA)⁻¹AᵀW, with Σ the
            # exact finite-record covariance of the estimates under the fitted N² and K²
            # (taken as independent, (AᵀWA)⁻¹ gave z spreads of 1.2-1.3 on 120 s records)
            b = cov @ (a * w[:, None]).T
            sandwich = b @ covariance({"n": float(coef[0]), "k": float(coef[1])}) @ b.T
            if np.all(np.isfinite(sandwich)) and sandwich[0, 0] >= 0 and sandwich[1, 1] >= 0:
                cov = sandwich
        arw[j], rrw[j] = math.sqrt(max(coef[0], 0.0)), math.sqrt(max(coef[1], 0.0))
        # σ of sqrt(c): σ_c / (2 sqrt c), or sqrt(σ_c) at c = 0
        for v, s, out in ((arw[j], cov[0, 0], arw_s), (rrw[j], cov[1, 1], rrw_s)):
            sc = math.sqrt(max(s, 0.0))
            out[j] = sc / (2.0 * v) if v > 0 else math.sqrt(sc)
    return WhiteWalk(arw, arw_s, rrw, rrw_s, np.asarray(t, float))


def white_walk_of_avar(taus, avar, m, n_phase: int, min_tau_s: float = MIN_TAU_S) -> WhiteWalk | None:
    """:func:`white_walk_fit` of one part from its octave Allan variance (M, C) at ``taus`` [s]
    (averaging factors ``m``, ``n_phase`` phase points: n + 1 for n samples), e.g. a streamed
    one; None when fewer than two octaves are usable (the caller falls back on the differences)."""
    taus, avar, m = np.asarray(taus, float), np.asarray(avar, float), np.asarray(m)
    n = n_phase - 1
    use = np.flatnonzero(m <= max(FIT_SPAN * n, 2))
    slow = use[taus[use] >= min_tau_s * (1.0 - 1e-9)]
    use = slow if slow.size >= MIN_FIT_OCTAVES else use[-MIN_FIT_OCTAVES:]
    if use.size < 2:
        return None
    t, av = taus[use], avar[use]
    edf = np.asarray(edf_simple(n_phase, m[use], 0), dtype=float)
    a = np.column_stack([1.0 / t, t / 3.0])
    model_cov = AvarCovariance(m[use], n_phase - 2 * m[use], 2, float(t[0] / m[use][0]))
    return _fit_columns(t, av, edf, a, model_cov.covariance)


def _pooled_use(pa: PooledAvar, min_tau_s: float) -> np.ndarray:
    """The octaves of a pooled fit: m <= PART_SPAN of the longest part and a pooled EDF of at
    least MIN_POOLED_EDF; from ``min_tau_s`` on (the last MIN_FIT_OCTAVES below the bound
    when fewer are left)."""
    longest = int(pa.lengths.max())
    use = np.flatnonzero((pa.m <= max(PART_SPAN * longest, 2)) & (pa.edf >= MIN_POOLED_EDF))
    slow = use[pa.taus_s[use] >= min_tau_s * (1.0 - 1e-9)]
    return slow if slow.size >= MIN_FIT_OCTAVES else use[-MIN_FIT_OCTAVES:]


def white_walk_fit(x, dt_s: float, min_tau_s: float = MIN_TAU_S, parts=None) -> WhiteWalk:
    """ARW and RRW of each column from its octave Allan variance, pooled over ``parts``.

    σ²(τ) = N²/τ + K²τ/3 fitted at the octave τ from ``min_tau_s`` up to :data:`FIT_SPAN` of
    the record (one part) or :data:`PART_SPAN` of the longest part with a pooled EDF of at
    least :data:`MIN_POOLED_EDF` (several parts; the last :data:`MIN_FIT_OCTAVES` octaves
    below the bound when fewer are left) by non-negative least squares, each point weighted
    by its standard error σ²_model(τ)·sqrt(2/edf) (white-FM EDF; two passes: the weights
    from the measured, then from the fitted variance). 1σ of N and K from the sandwich
    covariance B Σ Bᵀ of the weighted fit, B = (AᵀWA)⁻¹AᵀW, Σ the exact finite-record
    covariance of the octave estimates under the fitted model
    (:class:`~gyroarray.analysis.avar_covariance.AvarCovariance`; pooled: Σ_p (M_p/ΣM)² Σ_p).
    A record too short for two octaves gets N from the spread of its first differences
    (σ_Δ/√2·√dt, within parts) and K = 0.

    On several parts N is the pooled reading at τ1 ≈ ``min_tau_s``, σ(τ1)·√τ1
    (:func:`pooled_white_level`, IEEE Std 952's reading of the τ^-1/2 line), and K the fit's:
    a real gyro's Allan curve between 1 s and a part's length is rarely white + walk (the
    MIMU4444 board's gyros carry humps of ×2-3 in ADEV·√τ there), and what a fused rate's
    ARW reads at 1 s is that level, not a fitted line through the humps.

    Parameters
    ----------
    x : array_like, shape (n, C)
        Rate samples [rad/s].
    dt_s : float
        Sample step [s].
    min_tau_s : float
        Shortest τ of the fit [s]. The default 1 s is the IEEE Std 952 reading of ARW (the
        τ^-1/2 line at τ = 1 s) extended to the white level over τ >= 1 s, which the angle
        error over seconds and longer sees; the shorter τ, where a sensor's own filter,
        vibration lines and quantization shape the variance of a real gyro (MIMU4444: lines
        at 5-31 Hz), are left out. On white noise every τ range gives the same N.
    parts : list of (int, int), optional
        ``[start, stop)`` parts of ``x`` (stitched still parts); default the whole of ``x``.

    Returns
    -------
    WhiteWalk
    """
    x = np.asarray(x, dtype=float)
    n, c = x.shape
    pts = _parts(n, parts)
    ww = None
    if len(pts) == 1 and pts[0] == (0, n):
        if n >= 8:
            taus, avar, m, n_phase = octave_avar(x, dt_s)
            ww = white_walk_of_avar(taus, avar, m, n_phase, min_tau_s)
    else:
        pa = pooled_octave_avar(x, dt_s, pts)
        use = _pooled_use(pa, min_tau_s)
        if use.size >= 2:
            t, av, mu = pa.taus_s[use], pa.avar[use], pa.m[use]
            a = np.column_stack([1.0 / t, t / 3.0])
            tau0 = float(t[0] / mu[0])
            total = pa.terms[:, use].sum(axis=0).astype(float)
            per_part = []
            for p in range(len(pts)):
                live = pa.terms[p, use] > 0
                if live.any():
                    cov = AvarCovariance(mu[live], pa.terms[p, use][live], 2, tau0)
                    per_part.append((np.flatnonzero(live), pa.terms[p, use][live] / total[live], cov))

            def covariance(coef: dict) -> np.ndarray:
                out = np.zeros((use.size, use.size))
                for idx, wgt, cov in per_part:
                    out[np.ix_(idx, idx)] += np.outer(wgt, wgt) * cov.covariance(coef)
                return out
            ww = _fit_columns(t, av, pa.edf[use], a, covariance)
            level = pooled_white_level(x, dt_s, pts, min_tau_s)
            if level is not None:                 # N: the pooled reading at τ1 (module docstring)
                n1, s1, _, _ = level
                ok = n1 > 0
                ww = WhiteWalk(np.where(ok, n1, ww.arw_rad_rt_s), np.where(ok, s1, ww.arw_sigma),
                               ww.rrw_rad_s_rt_s, ww.rrw_sigma, ww.taus_s)
    if ww is None:
        d = np.concatenate([np.diff(x[a:b], axis=0) for a, b in pts if b - a > 1] or [np.zeros((1, c))])
        arw = np.std(d, axis=0) / math.sqrt(2.0) * math.sqrt(dt_s)
        return WhiteWalk(arw, np.full(c, np.nan), np.zeros(c), np.full(c, np.nan))
    return ww
