"""Covariance of Allan (and Hadamard) variance estimates at several averaging factors.

One model serves every fit that weighs an Allan-variance curve by its
estimates' covariance: the datasheet fit of
:func:`~gyroarray.analysis.noise_fit.fit_noise_terms` (any difference
order, large-record correlation) and the per-effect GLS of
:mod:`~gyroarray.effects.stochastic` (Allan variance, exact
finite-record covariance, Gauss–Markov and cross-spectra).

For the phase differences z_j(i) = Σ_p b_p x(i + p m_j) (x the cumulative
rate, b the signed binomial weights of order d: (1, −2, 1) for the Allan
variance, (−1, 3, −3, 1) for the Hadamard variance) the cross-covariance at
lag l is

    C_jk(l) = −½ Σ_pq b_p b_q D(l + q m_k − p m_j),

D the generalised variogram of the phase (:func:`phase_variogram`,
:func:`gauss_markov_variogram`; white PM gives isolated spikes at the lags
p m_j − q m_k, :func:`spike_lags`). Independent noise terms add their C's
before squaring. For Gaussian noise cov(z², z'²) = 2C², so the estimates
σ̂²_j = Σ_i z_j(i)² / (2 m_j² M_j) (M_j = n + 1 − d m_j terms) have

    cov(σ̂²_j, σ̂²_k) = 2/(4 m_j² m_k² M_j M_k) · Σ_l w_jk(l) C_jk(l)²

with w_jk(l) the number of index pairs at lag l
(:meth:`AvarCovariance.covariance`). For a long record w → min(M_j, M_k)
and the correlation is S_jk / √(S_jj S_kk) · √(min M / max M), S = Σ_l C²
(:meth:`AvarCovariance.correlation`). The lags run over the integers when
there are few, else over ``npts`` midpoints of |l| <= 4d(m_j + m_k), wide
enough for the 1/l² tail of flicker noise.

References
----------
.. [1] C. A. Greenhall, W. J. Riley, "Uncertainty of stability variances
   based on finite differences", Proc. 35th PTTI Meeting, 2003.
.. [2] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST SP
   1065, 2008.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["AvarCovariance", "phase_variogram", "gauss_markov_variogram", "spike_lags"]


def phase_variogram(term: str, t, dt_s: float) -> np.ndarray:
    """Generalised variogram D(t) of the phase of one noise term, per unit coefficient.

    The phase is the cumulative sum of the sampled rate; ``t`` is a lag in
    samples. Terms of degree <= 2 in t are dropped (differences of order
    >= 2 annihilate them), so only the covariances of such differences,
    ``cov(z_j(i), z_k(i + l)) = -1/2 sum_pq b_p b_q D(l + q m_k - p m_j)``,
    are meaningful. The signs matter once terms mix.

    Parameters
    ----------
    term : {"n", "k", "b"}
        White FM (angle random walk, per N² = 1): ``|t|/dt``, exact for
        sampled white rate; random-walk FM (per K² = 1):
        ``-dt (|t|³ - |t|)/6``, exact for a sampled random walk (the m = 1
        Allan variance is K² dt); flicker FM (per B² = 1): ``-t² ln|t|/π``.
    t : array_like
        Lags [samples].
    dt_s : float
        Sampling step [s].

    Returns
    -------
    ndarray
        D(t) [rad² per unit coefficient].
    """
    a = np.abs(np.asarray(t, dtype=float))
    if term == "n":
        return a / dt_s
    if term == "k":
        return -(dt_s / 6.0) * (a ** 3 - a)
    if term == "b":
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(a > 0, -(a * a * np.log(a)) / math.pi, 0.0)
    raise ValueError(f"no phase variogram for term {term!r}")


def gauss_markov_variogram(t, dt_s: float, tau_c_s: float) -> np.ndarray:
    """D(t) of the phase of a sampled Gauss–Markov (AR(1)) rate, per σ² = 1.

    Exact for the AR(1) with φ = exp(−dt/τc): t(1 + φ)/(1 − φ) − 2φ(1 − φᵗ)/(1 − φ)²
    (t in samples, |t| taken; the terms of degree <= 2 kept, they cancel in the
    differences).
    """
    a = np.abs(np.asarray(t, dtype=float))
    u = -math.expm1(-dt_s / tau_c_s)                   # 1 − φ
    return a * (2.0 - u) / u - 2.0 * (1.0 - u) * (-np.expm1(-a * dt_s / tau_c_s)) / (u * u)


def spike_lags(b: np.ndarray, m_j: int, m_k: int) -> dict:
    """White-PM (quantization) covariance spikes of two phase differences.

    ``z_j(i) = sum_p b_p x(i + p m_j)`` and ``z_k`` likewise with white
    phase x: ``cov(z_j(i), z_k(i + l))`` is ``sum b_p b_q`` over the (p, q)
    with ``l = p m_j - q m_k`` (per unit phase variance).

    Returns
    -------
    dict
        Lag [samples] -> ``sum b_p b_q`` [-], lags in increasing order.
    """
    acc: dict = {}
    for p in range(len(b)):
        for q in range(len(b)):
            lag = p * int(m_j) - q * int(m_k)
            acc[lag] = acc.get(lag, 0.0) + float(b[p] * b[q])
    return {lag: acc[lag] for lag in sorted(acc)}


def _record_pairs(big_mj, big_mk, lags):
    """Number of index pairs (i, i') with i' − i = l in a record of M_j and M_k terms."""
    return np.clip(np.minimum(big_mj, big_mk - lags) - np.maximum(0.0, -lags), 0.0, None)


class AvarCovariance:
    """Covariance model of variance estimates at the averaging factors ``m``.

    Parameters
    ----------
    m : array_like of int
        Averaging factors [samples].
    n_terms : array_like of int
        Number of differences M_j averaged at each factor [-].
    order : int
        Order d of the phase difference (2 Allan, 3 Hadamard).
    dt_s : float
        Sampling step [s]; it scales the variograms (and so :meth:`covariance`),
        not :meth:`correlation`.
    npts : int
        Lag grid points per pair of factors.

    The per-term lag profiles C_jk(l) are computed once, on first use, and
    combined for each model by :meth:`covariance` or :meth:`correlation`.
    """

    def __init__(self, m, n_terms, order: int = 2, dt_s: float = 1.0, npts: int = 512):
        m = np.asarray(m, dtype=np.int64)
        big_m = np.asarray(n_terms, dtype=float)
        self.m, self.dt, self.size = m, float(dt_s), m.size
        self.b = np.array([(-1) ** (order - p) * math.comb(order, p) for p in range(order + 1)],
                          dtype=float)
        self.j, self.k = np.triu_indices(m.size)          # pairs of factors, j <= k
        mj = m[self.j].astype(float)[:, None]
        mk = m[self.k].astype(float)[:, None]
        half = 4.0 * order * (mj + mk)
        exact = (2.0 * half + 1.0 <= npts)[:, 0]
        self.step = np.where(exact, 1.0, 2.0 * half[:, 0] / npts)
        idx = np.arange(npts, dtype=float)[None, :]
        self.lags = np.where(exact[:, None], -half + idx, -half + self.step[:, None] * (idx + 0.5))
        # integer grids use the first 2 half + 1 slots; the rest are masked
        self.used = ~exact[:, None] | (idx <= 2.0 * half)
        self.mj, self.mk = mj, mk
        big_mj, big_mk = big_m[self.j][:, None], big_m[self.k][:, None]
        self.record_w = np.where(self.used, _record_pairs(big_mj, big_mk, self.lags), 0.0) * self.step[:, None]
        self.norm = 2.0 / (4.0 * (mj[:, 0] * mk[:, 0]) ** 2 * big_mj[:, 0] * big_mk[:, 0])
        self.m_factor = np.sqrt(np.minimum.outer(big_m, big_m) / np.maximum.outer(big_m, big_m))
        # white PM: spikes (Σ b_p b_q at l = p m_j − q m_k), flattened over the pairs, with the
        # linear-interpolation position of each on its pair's grid lags[pair, 0] + step[pair]·i
        per_pair = [spike_lags(self.b, int(mj[p, 0]), int(mk[p, 0])) for p in range(self.j.size)]
        self.spike_pair = np.concatenate([np.full(len(acc), p) for p, acc in enumerate(per_pair)])
        self.spike_lag = np.concatenate([np.array(list(acc), dtype=float) for acc in per_pair])
        self.spike_sum = np.concatenate([np.array(list(acc.values())) for acc in per_pair])
        self.spike_w = _record_pairs(big_mj[self.spike_pair, 0], big_mk[self.spike_pair, 0],
                                     self.spike_lag)
        pos = (self.spike_lag - self.lags[self.spike_pair, 0]) / self.step[self.spike_pair]
        self.spike_in = (pos >= 0.0) & (pos <= npts - 1)
        self.spike_i0 = np.clip(np.floor(pos), 0, npts - 2).astype(np.int64)
        self.spike_f = np.where(self.spike_in, pos - self.spike_i0, 0.0)
        self._profiles: dict = {}
        self._normalised: dict = {}

    # -- lag profiles ---------------------------------------------------------

    def _profile(self, d) -> np.ndarray:
        c = np.zeros_like(self.lags)
        for p, bp in enumerate(self.b):
            for q, bq in enumerate(self.b):
                c += -0.5 * bp * bq * d(self.lags + q * self.mk - p * self.mj)
        return np.where(self.used, c, 0.0)

    def profile(self, term: str) -> np.ndarray:
        """C_jk(l) of one power-law term per unit coefficient, shape (pairs, npts)."""
        if term not in self._profiles:
            self._profiles[term] = self._profile(lambda t: phase_variogram(term, t, self.dt))
        return self._profiles[term]

    def gm_profile(self, tau_c_s: float) -> np.ndarray:
        """C_jk(l) of a Gauss–Markov rate of correlation time ``tau_c_s`` [s] per σ² = 1."""
        key = ("gm", float(tau_c_s))
        if key not in self._profiles:
            if len(self._profiles) > 64:
                self._profiles = {t: v for t, v in self._profiles.items() if isinstance(t, str)}
            self._profiles[key] = self._profile(
                lambda t: gauss_markov_variogram(t, self.dt, float(tau_c_s)))
        return self._profiles[key]

    def _at_spikes(self, smooth: np.ndarray) -> np.ndarray:
        """A smooth profile at the spike lags (linear interpolation, 0 off the grid)."""
        pair, i0, f = self.spike_pair, self.spike_i0, self.spike_f
        return np.where(self.spike_in, (1.0 - f) * smooth[pair, i0] + f * smooth[pair, i0 + 1], 0.0)

    def _matrix(self, s: np.ndarray) -> np.ndarray:
        out = np.zeros((self.size, self.size))
        out[self.j, self.k] = s
        out[self.k, self.j] = s
        return out

    # -- exact covariance -----------------------------------------------------

    def _smooth(self, coef: dict, gm) -> np.ndarray:
        smooth = np.zeros_like(self.lags)
        for key in ("n", "k", "b"):
            a = coef.get(key, 0.0)
            if a != 0:
                smooth += a * self.profile(key)
        if gm is not None and gm[0] != 0:
            smooth += gm[0] * self.gm_profile(gm[1])
        return smooth

    def covariance(self, coef: dict, gm=None, other=None) -> np.ndarray:
        """Exact covariance of the estimates for a finite record [(rad/s)⁴].

        ``coef`` = {"q": Q², "n": N², "b": B², "k": K²} (SI; the coefficients
        of :func:`~gyroarray.analysis.noise_fit.term_basis`), ``gm`` =
        (σ² [(rad/s)²], τc [s]) or None. With ``other`` = (coef2, gm2): the
        covariance of the *cross* estimates mean(z¹_j z²_j)/(2m_j²) of two
        independent series with these models (Σ C¹C² instead of Σ C²).
        """
        s1 = self._smooth(coef, gm)
        coef2, gm2 = (coef, gm) if other is None else other
        s2 = s1 if other is None else self._smooth(coef2, gm2)
        s = np.sum(self.record_w * s1 * s2, axis=1)
        q1, q2 = coef.get("q", 0.0), coef2.get("q", 0.0)
        if q1 != 0 or q2 != 0:
            unit = self.spike_sum / self.dt ** 2
            sp1, sp2 = q1 * unit, q2 * unit
            s = s + np.bincount(self.spike_pair, minlength=s.size, weights=self.spike_w * (
                sp1 * sp2 + sp1 * self._at_spikes(s2) + sp2 * self._at_spikes(s1)))
        return self._matrix(s * self.norm)

    def block(self, start: int) -> "AvarCovariance":
        """The same model for the factors from index ``start`` on (a view)."""
        return _Block(self, start)  # type: ignore[return-value]

    # -- large-record correlation ------------------------------------------------

    def _normalised_profiles(self, terms: tuple) -> np.ndarray:
        """C_jk(l)/√(C_jj(0) C_kk(0)) of each non-white-PM term (terms, pairs, npts)."""
        if terms not in self._normalised:
            out = np.zeros((len(terms), self.j.size, self.lags.shape[1]))
            for it, term in enumerate(terms):
                if term == "q":
                    continue
                key = "k" if term == "r" else term       # a rate ramp is modelled as RW FM
                d = (lambda t, key=key: phase_variogram(key, t, self.dt))
                c0j = np.zeros(self.j.size)
                c0k = np.zeros(self.j.size)
                for p, bp in enumerate(self.b):
                    for q, bq in enumerate(self.b):
                        c0j += -0.5 * bp * bq * d((q - p) * self.mj[:, 0])
                        c0k += -0.5 * bp * bq * d((q - p) * self.mk[:, 0])
                out[it] = self.profile(key) / np.sqrt(c0j * c0k)[:, None]
            self._normalised[terms] = out
        return self._normalised[terms]

    def correlation(self, v: np.ndarray, terms: tuple) -> np.ndarray:
        """Correlation matrix of the estimates for per-term variances ``v`` (terms, factors).

        ``terms`` are keys of :data:`~gyroarray.analysis.noise_fit.TERM_ALPHA`;
        the large-record form (module docstring), independent of ``dt_s``.
        """
        terms = tuple(terms)
        v = np.maximum(v, 0.0)
        amp = np.sqrt(v[:, self.j] * v[:, self.k])      # (terms, pairs)
        wpm = np.array([t == "q" for t in terms])
        smooth = np.einsum("tp,tpl->pl", amp[~wpm], self._normalised_profiles(terms)[~wpm])
        s = np.sum(smooth * smooth, axis=1) * self.step
        if wpm.any():
            spike = amp[wpm].sum(axis=0)[self.spike_pair] * self.spike_sum / float(self.b @ self.b)
            s = s + np.bincount(self.spike_pair, weights=spike * spike + 2.0 * spike * self._at_spikes(smooth),
                                minlength=s.size)
        big_s = self._matrix(s)
        diag = np.sqrt(np.diag(big_s))
        return big_s / np.outer(diag, diag) * self.m_factor


class _Block:
    """:meth:`AvarCovariance.covariance` for the factors from ``start`` on."""

    def __init__(self, whole: AvarCovariance, start: int):
        self.whole, self.start = whole, start

    def covariance(self, coef, gm=None, other=None):
        return self.whole.covariance(coef, gm, other)[self.start:, self.start:]
