"""IEEE Std 952 noise terms from an Allan (or Hadamard) variance curve.

The model (IEEE Std 952-1997, Annex C) is a sum of independent terms, each a
power law in the averaging time ``tau`` [s]::

    sigma^2(tau) = sum_i A_i tau^i,   i = -2, -1, 0, +1, +2

with ``A_i = c_i P_i^2``; ``P_i`` is the datasheet coefficient of the term,
``c_i`` a constant of the term and of the variance (:data:`TERM_CONSTANTS`).
Everything here is SI: rates in rad/s, ``tau`` in s.  Datasheet units appear
only in :meth:`NoiseFit.to_datasheet_dict`, through :mod:`gyroarray.core.units`.

This module knows nothing about how the variance was estimated; the
equivalent degrees of freedom come in as a function (see
:func:`fit_noise_terms`), which :func:`gyroarray.analysis.allan.allan_analysis`
supplies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple, Sequence

import numpy as np
from scipy.optimize import brentq, nnls

from gyroarray.core import units
from gyroarray.core.errors import InputError

from gyroarray.analysis.avar_covariance import AvarCovariance

__all__ = [
    "TERMS",
    "TERM_EXPONENTS",
    "TERM_ALPHA",
    "TERM_CONSTANTS",
    "NoiseFit",
    "term_basis",
    "term_from_curve",
    "fit_noise_terms",
    "RRWBound",
    "rrw_adev_bound",
    "RRW_BOUND_TAIL",
]

#: The five IEEE Std 952 terms, in order of the exponent of tau in the
#: variance:
#: quantization (angle) Q, angle random walk N, bias instability B, rate random
#: walk K, rate ramp R.
TERMS = ("q", "n", "b", "k", "r")

#: Exponent ``i`` of tau in the variance, ``sigma^2 = A tau^i``.
TERM_EXPONENTS = {"q": -2, "n": -1, "b": 0, "k": 1, "r": 2}

#: Power-law exponent ``alpha`` of the rate (fractional-frequency) PSD,
#: ``S(f) ~ f^alpha``, used to pick the equivalent degrees of freedom.
#: Quantization = white PM (+2), ARW = white FM (0), bias instability =
#: flicker FM (-1), RRW = random-walk FM (-2); the rate ramp is a drift and is
#: treated as random-walk FM (-2), the most conservative type the EDF formulas
#: cover.
TERM_ALPHA = {"q": 2, "n": 0, "b": -1, "k": -2, "r": -2}

_LN2 = math.log(2.0)
_LN3 = math.log(3.0)

#: Order of the phase difference of each variance (Allan 2, Hadamard 3).
KIND_ORDER = {"oadev": 2, "ohdev": 3}

#: ``c_i`` of ``A_i = c_i P_i^2`` for each variance.  ``None``: the variance is
#: blind to the term (the Hadamard variance cancels a rate ramp).
#: Derivations in the Notes of :func:`term_basis`.
TERM_CONSTANTS: dict[str, dict[str, float | None]] = {
    "oadev": {"q": 3.0, "n": 1.0, "b": 2.0 * _LN2 / math.pi, "k": 1.0 / 3.0,
              "r": 0.5},
    "ohdev": {"q": 10.0 / 3.0, "n": 1.0,
              "b": (4.0 * _LN2 - 1.5 * _LN3) / math.pi, "k": 1.0 / 6.0,
              "r": None},
}

# SI name and datasheet converter of each coefficient.
_SI_NAME = {"q": "q_rad", "n": "n_rad_rt_s", "b": "b_rad_s",
            "k": "k_rad_s_rt_s", "r": "r_rad_s2"}
_DATASHEET = {
    "q": ("q_deg", units.rad_to_deg),
    "n": ("arw_deg_rt_h", units.arw_rad_rt_s_to_deg_rt_h),
    "b": ("bi_deg_h", units.rad_s_to_deg_h),
    "k": ("rrw_deg_h_rt_h", units.rrw_rad_s_rt_s_to_deg_h_rt_h),
    "r": ("r_deg_h2", units.ramp_rad_s2_to_deg_h2),
}


def _check_kind(kind: str) -> None:
    if kind not in TERM_CONSTANTS:
        raise InputError(f"unknown deviation kind {kind!r}; expected one of "
                         f"{sorted(TERM_CONSTANTS)}")


def term_basis(kind: str, term: str, taus_s) -> np.ndarray:
    """Variance of one noise term with unit coefficient, ``g(tau) = c tau^i``.

    Parameters
    ----------
    kind : {"oadev", "ohdev"}
        Allan or Hadamard variance.
    term : {"q", "n", "b", "k", "r"}
        The noise term (see :data:`TERMS`).
    taus_s : array_like
        Averaging times [s].

    Returns
    -------
    numpy.ndarray
        ``g(tau)`` [s^i]: the variance [(rad/s)^2] of the term is
        ``P^2 g(tau)`` for the coefficient ``P`` in SI units (Q [rad],
        N [rad/√s], B [rad/s], K [rad/s/√s], R [rad/s²]).

    Raises
    ------
    InputError
        Unknown kind or term, or a term the variance cannot see (rate ramp
        in the Hadamard variance).

    Notes
    -----
    Allan variance (IEEE Std 952-1997 Annex C, El-Sheimy et al. 2008):

    .. math::

        \\sigma^2 = \\frac{3Q^2}{\\tau^2} + \\frac{N^2}{\\tau}
        + \\frac{2\\ln 2}{\\pi}B^2 + \\frac{K^2\\tau}{3}
        + \\frac{R^2\\tau^2}{2}

    Hadamard variance: the transfer function of the overlapping Hadamard
    variance is :math:`|H(f)|^2 = \\tfrac{8}{3}\\sin^6(\\pi f\\tau)/
    (\\pi f\\tau)^2` against :math:`2\\sin^4(\\pi f\\tau)/(\\pi f\\tau)^2`
    for Allan.  Integrating the one-sided rate PSDs of IEEE Std 952
    (:math:`N^2\\cdot 2`, :math:`B^2/(\\pi f)`, :math:`K^2/(2\\pi^2 f^2)`):
    white rate gives :math:`N^2/\\tau` (as Allan), flicker rate gives
    :math:`(4\\ln 2 - \\tfrac32\\ln 3)B^2/\\pi` (from
    :math:`\\int_0^\\infty \\sin^6u/u^3\\,du = (24\\ln 2 - 9\\ln 3)/16`),
    rate random walk gives :math:`K^2\\tau/6` (from
    :math:`\\int_0^\\infty\\sin^6 u/u^4\\,du = \\pi/8`).  For quantization
    (white angle noise of variance :math:`Q^2`) the third difference has
    variance :math:`20Q^2`, so :math:`\\sigma_H^2 = 20Q^2/(6\\tau^2)`
    (Allan: :math:`6Q^2/(2\\tau^2)`).  A rate ramp has zero third
    difference: the Hadamard variance does not see it.

    References
    ----------
    .. [1] IEEE Std 952-1997, "IEEE Standard Specification Format Guide and
       Test Procedure for Single-Axis Interferometric Fiber Optic Gyros",
       Annex C.
    .. [2] N. El-Sheimy, H. Hou, X. Niu, "Analysis and modeling of inertial
       sensors using Allan variance", IEEE Trans. Instrum. Meas. 57(1), 2008.
    .. [3] W. J. Riley, "Handbook of Frequency Stability Analysis",
       NIST SP 1065, 2008, sec. 5.2.7 (Hadamard variance).
    """
    _check_kind(kind)
    if term not in TERM_EXPONENTS:
        raise InputError(f"unknown noise term {term!r}; expected one of "
                         f"{TERMS}")
    c = TERM_CONSTANTS[kind][term]
    if c is None:
        raise InputError(f"the {kind} variance is blind to term {term!r}")
    taus = np.asarray(taus_s, dtype=float)
    return c * taus ** TERM_EXPONENTS[term]


def term_from_curve(taus_s, dev, term: str, *, kind: str = "oadev",
                    method: str = "tangent") -> float:
    """Coefficient of one noise term read off a deviation curve (slope method).

    Parameters
    ----------
    taus_s : array_like
        Averaging times [s] of the chosen points.
    dev : array_like
        Allan (or Hadamard) deviation at those times [rad/s].
    term : {"q", "n", "b", "k", "r"}
        The term whose slope line is placed.
    kind : {"oadev", "ohdev"}, default "oadev"
        Which variance ``dev`` is.
    method : {"tangent", "mean"}, default "tangent"
        ``"tangent"``: the highest line of the term's slope lying on or below
        every point (the classic tangent read by eye; since all terms add,
        ``dev`` >= each term's line in expectation, so this is the tightest
        such bound).  ``"mean"``: the line through the geometric mean of the
        points (fixed slope, least squares in log-log), as in the ``avlr``
        function of the R package ``avar``.

    Returns
    -------
    float
        The coefficient in SI units: Q [rad], N [rad/√s], B [rad/s],
        K [rad/s/√s] or R [rad/s²].

    Notes
    -----
    With :math:`g(\\tau)` of :func:`term_basis`, each point gives the estimate
    :math:`p_j = \\sigma(\\tau_j)/\\sqrt{g(\\tau_j)}`; ``"tangent"`` returns
    :math:`\\min_j p_j`, ``"mean"`` returns
    :math:`\\exp(\\overline{\\ln p_j})`.
    For ARW this is N read at :math:`\\tau = 1` s on the :math:`-1/2` line,
    for RRW K read at :math:`\\tau = 3` s on the :math:`+1/2` line, for bias
    instability the flat line divided by :math:`\\sqrt{2\\ln 2/\\pi} = 0.664`.

    References
    ----------
    .. [1] IEEE Std 952-1997, Annex C (slope method).
    .. [2] S. Guerrier, R. Molinari, et al., R package ``avar``, function
       ``avlr`` (github.com/SMAC-Group/avar).
    """
    taus = np.asarray(taus_s, dtype=float)
    d = np.asarray(dev, dtype=float)
    if taus.shape != d.shape or taus.ndim != 1 or taus.size == 0:
        raise InputError("taus_s and dev must be 1-D arrays of the same, "
                         "non-zero length")
    if not (np.all(np.isfinite(d)) and np.all(d > 0) and np.all(taus > 0)):
        raise InputError("term_from_curve needs finite, positive taus_s "
                         "and dev")
    p = d / np.sqrt(term_basis(kind, term, taus))
    if method == "tangent":
        return float(np.min(p))
    if method == "mean":
        return float(np.exp(np.mean(np.log(p))))
    raise InputError(f"unknown method {method!r}; expected 'tangent' or "
                     "'mean'")


@dataclass(frozen=True)
class NoiseFit:
    """IEEE Std 952 noise coefficients fitted to a variance curve (SI units).

    A coefficient is ``None`` when its term was not fitted (not requested, or
    invisible to the variance: rate ramp with the Hadamard variance); a sigma
    is ``None`` when it cannot be computed (singular information matrix).

    Parameters
    ----------
    kind : str
        "oadev" or "ohdev": the variance that was fitted.
    terms : tuple of str
        The fitted terms, a subset of :data:`TERMS`.
    method : str
        "gls" (correlated estimates) or "wls" (independent), see
        :func:`fit_noise_terms`.
    q_rad, q_rad_sigma : float or None
        Quantization Q [rad] and its 1-sigma uncertainty [rad].
    n_rad_rt_s, n_rad_rt_s_sigma : float or None
        Angle random walk N [rad/√s] and 1-sigma [rad/√s].
    b_rad_s, b_rad_s_sigma : float or None
        Bias instability B [rad/s] and 1-sigma [rad/s].
    k_rad_s_rt_s, k_rad_s_rt_s_sigma : float or None
        Rate random walk K [rad/s/√s] and 1-sigma [rad/s/√s].
    r_rad_s2, r_rad_s2_sigma : float or None
        Rate ramp R [rad/s²] and 1-sigma [rad/s²].
    clamped : tuple of str
        Fitted terms the non-negativity constraint holds at zero.
    coef : numpy.ndarray, shape (5,)
        ``A_i`` of ``sigma^2 = sum A_i tau^i`` for i = -2..2 [(rad/s)² s^-i]
        (zero for terms not fitted).
    coef_cov : numpy.ndarray, shape (5, 5)
        Covariance of ``coef`` from the least squares of the active
        (non-clamped) terms; zero rows/columns elsewhere.
    taus_s : numpy.ndarray
        Averaging times of the fitted points [s].
    alpha : numpy.ndarray of int
        Noise type (rate PSD exponent) per tau, from the dominant term.
    edf : numpy.ndarray
        Equivalent degrees of freedom per tau used for the final weights.
    chi2 : float
        Generalised residual sum of squares ``r' Sigma^-1 r`` of the final
        fit [-].
    dof : int
        Number of points minus number of active terms.
    model_error : float
        Relative model error added to every point so that ``chi2 = dof``
        [-]; 0 when the model explains the scatter (see
        :func:`fit_noise_terms`).
    n_iter : int
        Reweighting iterations of the final fit.
    slope_n_rad_rt_s, slope_k_rad_s_rt_s, slope_b_rad_s : float
        Slope-method readings N [rad/√s], K [rad/s/√s], B [rad/s] (tangent
        lines from below, :func:`term_from_curve`).
    tau_bi_s : float
        Averaging time of the minimum of the deviation curve [s].
    """

    kind: str
    terms: tuple
    method: str
    q_rad: float | None
    q_rad_sigma: float | None
    n_rad_rt_s: float | None
    n_rad_rt_s_sigma: float | None
    b_rad_s: float | None
    b_rad_s_sigma: float | None
    k_rad_s_rt_s: float | None
    k_rad_s_rt_s_sigma: float | None
    r_rad_s2: float | None
    r_rad_s2_sigma: float | None
    clamped: tuple
    coef: np.ndarray = field(repr=False)
    coef_cov: np.ndarray = field(repr=False)
    taus_s: np.ndarray = field(repr=False)
    alpha: np.ndarray = field(repr=False)
    edf: np.ndarray = field(repr=False)
    chi2: float
    dof: int
    model_error: float
    n_iter: int
    slope_n_rad_rt_s: float
    slope_k_rad_s_rt_s: float
    slope_b_rad_s: float
    tau_bi_s: float

    def coefficient(self, term: str) -> tuple[float | None, float | None]:
        """Value and 1-sigma of one coefficient in SI units.

        Parameters
        ----------
        term : {"q", "n", "b", "k", "r"}
            The noise term.

        Returns
        -------
        (value, sigma) : tuple of float or None
            Q [rad], N [rad/√s], B [rad/s], K [rad/s/√s] or R [rad/s²] and
            its sigma in the same unit (see the fields of this class).
        """
        if term not in TERMS:
            raise InputError(f"unknown noise term {term!r}; expected one of "
                             f"{TERMS}")
        name = _SI_NAME[term]
        return getattr(self, name), getattr(self, name + "_sigma")

    def model_avar(self, taus_s) -> np.ndarray:
        """Fitted variance ``sum A_i tau^i`` of the model.

        Parameters
        ----------
        taus_s : array_like
            Averaging times [s].

        Returns
        -------
        numpy.ndarray
            Model variance [(rad/s)²] (Allan or Hadamard, as fitted).
        """
        taus = np.asarray(taus_s, dtype=float)
        out = np.zeros_like(taus)
        for c, term in zip(self.coef, TERMS):
            if c > 0:
                out = out + c * taus ** TERM_EXPONENTS[term]
        return out

    def to_datasheet_dict(self) -> dict:
        """The fit in datasheet units, for the CLI and JSON reports.

        Returns
        -------
        dict
            Keys ``arw_deg_rt_h`` [deg/√h], ``bi_deg_h`` [deg/h],
            ``rrw_deg_h_rt_h`` [deg/h/√h], ``q_deg`` [deg], ``r_deg_h2``
            [deg/h²], each with a ``*_sigma`` (1-sigma, same unit); the
            slope-method readings ``slope_arw_deg_rt_h``,
            ``slope_rrw_deg_h_rt_h``, ``slope_bi_deg_h``; and ``tau_bi_s``
            [s].  Values are floats or ``None`` (never NaN).
        """
        out: dict = {}
        for term in ("n", "b", "k", "q", "r"):
            key, conv = _DATASHEET[term]
            value, sigma = self.coefficient(term)
            out[key] = None if value is None else float(conv(value))
            out[key + "_sigma"] = None if sigma is None else float(conv(sigma))
        out["slope_arw_deg_rt_h"] = float(
            units.arw_rad_rt_s_to_deg_rt_h(self.slope_n_rad_rt_s))
        out["slope_rrw_deg_h_rt_h"] = float(
            units.rrw_rad_s_rt_s_to_deg_h_rt_h(self.slope_k_rad_s_rt_s))
        out["slope_bi_deg_h"] = float(units.rad_s_to_deg_h(self.slope_b_rad_s))
        out["tau_bi_s"] = float(self.tau_bi_s)
        return {k: (None if isinstance(v, float) and not math.isfinite(v)
                    else v) for k, v in out.items()}


def whitened_nnls(g: np.ndarray, y: np.ndarray, white) -> tuple:
    """NNLS of ``W (g a - y)`` (``W = white(.)``), columns scaled to unit norm.

    Returns the coefficients and the whitened design matrix ``W g``. An
    empty system (no rows or no terms) gives zeros without calling NNLS (its
    native code aborts the process on one); an all-zero column gets 0.
    """
    x = white(g)
    if x.ndim != 2 or x.shape[0] == 0 or x.shape[1] == 0:
        return np.zeros(x.shape[1] if x.ndim == 2 else 0), x
    scale = np.linalg.norm(x, axis=0)
    if not np.all(scale > 0):
        scale = np.where(scale > 0, scale, np.inf)              # its coefficient: 0
    a_scaled, _ = nnls(np.where(np.isinf(scale), 0.0, x / scale), white(y))
    return a_scaled / scale, x


def _coefficient_sigma(a: float, sigma_a: float, c: float) -> float:
    """1-sigma of ``P = sqrt(A/c)`` from ``A`` and its sigma (see Notes of
    :func:`fit_noise_terms`)."""
    root = math.sqrt(a)
    return max(root - math.sqrt(max(a - sigma_a, 0.0)),
               math.sqrt(a + sigma_a) - root) / math.sqrt(c)


def _covariance(x: np.ndarray) -> np.ndarray | None:
    """``(X' X)^-1`` computed on unit-norm columns; ``None`` if singular."""
    scale = np.linalg.norm(x, axis=0)
    xs = x / scale
    info = xs.T @ xs
    if np.linalg.cond(info) > 1e12:
        return None
    return np.linalg.inv(info) / np.outer(scale, scale)


# --------------------------------------------------------------------------
# Correlation between the variance estimates at different taus


#: Correlation models by (factors, counts, order): the chain fits many series of one length
#: (building one costs ~25 ms).
_CORR_CACHE: dict = {}


def _estimate_correlation(m: np.ndarray, n_terms: np.ndarray, d: int, terms: tuple):
    """``v -> correlation matrix`` of the estimates (:meth:`AvarCovariance.correlation`),
    the model reused for the same factors, counts and order."""
    key = (m.astype(np.int64).tobytes(), n_terms.astype(np.int64).tobytes(), d)
    hit = _CORR_CACHE.get(key)
    if hit is None:
        if len(_CORR_CACHE) >= 16:
            _CORR_CACHE.pop(next(iter(_CORR_CACHE)))
        hit = _CORR_CACHE[key] = AvarCovariance(m, n_terms, d)
    terms = tuple(terms)
    return lambda v: hit.correlation(v, terms)


def _whitener(rel_cov: np.ndarray, scale: np.ndarray):
    """``W`` with ``W' W = (D Q D)^-1``, ``D = diag(scale)``, ``Q = rel_cov``.

    ``Q`` is the covariance relative to ``scale`` (well conditioned); its
    eigenvalues are clipped at 1e-12 of the largest (it is built from
    approximations and must stay positive definite).
    """
    w, v = np.linalg.eigh(rel_cov)
    w = np.maximum(w, 1e-12 * w.max())
    inv_sqrt = (v / np.sqrt(w)) @ v.T / scale[None, :]
    return lambda arr: inv_sqrt @ arr


class _Solution(NamedTuple):
    """One converged reweighting loop of :func:`fit_noise_terms`."""

    a: np.ndarray
    alpha: np.ndarray
    nu: np.ndarray
    x: np.ndarray
    white: Callable
    chi2: float
    n_iter: int


#: Search interval of log10 of the relative model error.
_LOG_EPS_RANGE = (-8.0, 2.0)


def root_log_eps(excess: Callable[[float], float]) -> float:
    """log10(eps) where ``excess`` (chi2 - dof, decreasing in eps) crosses zero.

    ``excess`` is only piecewise monotonic (the NNLS active set can change
    with eps), so both ends of the interval may have the same sign on short
    records. Brent is used where the ends bracket a root; otherwise the
    first point of a half-decade grid where the excess is <= 0 (the end of
    the interval if there is none).
    """
    lo, hi = _LOG_EPS_RANGE
    f_lo, f_hi = excess(lo), excess(hi)
    if f_lo > 0 > f_hi:
        return brentq(excess, lo, hi, xtol=1e-2)  # eps to ~2 %
    if f_lo <= 0:
        return lo
    for log_eps in np.arange(lo + 0.5, hi + 0.25, 0.5):
        if excess(log_eps) <= 0:
            return float(log_eps)
    return hi


def _checked_terms(kind: str, terms: Sequence[str] | None, n_taus: int,
                   method: str, max_iter: int) -> tuple:
    """The terms to fit in canonical order, after checking the fit options."""
    if terms is None:
        terms = tuple(t for t in TERMS if TERM_CONSTANTS[kind][t] is not None)
    else:
        terms = tuple(terms)
        unknown = [t for t in terms if t not in TERMS]
        if unknown or len(set(terms)) != len(terms) or not terms:
            raise InputError(f"terms must be distinct names from {TERMS}, "
                             f"got {terms!r}")
        terms = tuple(t for t in TERMS if t in terms)  # canonical order
    blind = [t for t in terms if TERM_CONSTANTS[kind][t] is None]
    if blind:
        raise InputError(f"the {kind} variance is blind to term(s) {blind}")
    if n_taus < len(terms):
        raise InputError(f"{n_taus} averaging times cannot determine "
                         f"{len(terms)} noise terms; use more taus or fewer "
                         "terms")
    if method not in ("gls", "wls"):
        raise InputError(f"unknown fit method {method!r}; expected 'gls' or "
                         "'wls'")
    if max_iter < 1:
        raise InputError("max_iter must be at least 1")
    return terms


def _full_coefficients(terms: tuple, a: np.ndarray, active: np.ndarray,
                       cov_active: np.ndarray | None) -> tuple:
    """Coefficients and covariance of the fitted terms placed on all TERMS."""
    coef = np.zeros(len(TERMS))
    coef_cov = np.zeros((len(TERMS), len(TERMS)))
    idx = np.array([TERMS.index(t) for t in terms])
    coef[idx] = a
    if cov_active is not None:
        ia = idx[active]
        coef_cov[np.ix_(ia, ia)] = cov_active
    return coef, coef_cov


def _term_values(kind: str, terms: tuple, a: np.ndarray, active: np.ndarray,
                 cov_active: np.ndarray | None,
                 cov_full: np.ndarray | None) -> dict:
    """SI coefficient and 1-sigma of every term (None where not fitted)."""
    values: dict = {}
    for j, term in enumerate(terms):
        c = TERM_CONSTANTS[kind][term]
        assert c is not None                                   # blind terms were refused above
        name = _SI_NAME[term]
        values[name] = math.sqrt(a[j] / c)
        sigma = None
        if active[j] and cov_active is not None:
            k = int(np.count_nonzero(active[:j]))
            sigma = _coefficient_sigma(a[j], math.sqrt(cov_active[k, k]), c)
        elif not active[j] and cov_full is not None and cov_full[j, j] > 0:
            sigma = _coefficient_sigma(0.0, math.sqrt(cov_full[j, j]), c)
        values[name + "_sigma"] = sigma
    for term in TERMS:
        values.setdefault(_SI_NAME[term], None)
        values.setdefault(_SI_NAME[term] + "_sigma", None)
    return values


def _with_model_error(sol: _Solution, corr, g: np.ndarray, dof: int, iterate,
                      max_iter: int) -> tuple:
    """Refit with the relative model error eps that makes chi2 = dof: (solution, eps [-]).

    The search holds the correlation between taus at that of the
    model-error-free fit (it depends on the coefficients only through the
    terms' shares at each tau): ~5x fewer matrix builds; the final fit
    updates it again.
    """
    start = sol.a
    fixed = None if corr is None else corr((g * start).T)

    def excess(log_eps):
        # chi2 to ~1e-6 is plenty for eps to the search's ~2 %
        return iterate(start, corr, 10.0 ** log_eps, fixed, rtol=1e-6,
                       cap=min(max_iter, 20)).chi2 - dof

    model_error = 10.0 ** root_log_eps(excess)
    return iterate(start, corr, model_error), model_error


class _Reweighting(NamedTuple):
    """The reweighting loop of :func:`fit_noise_terms` (its steps 1–3 and the GLS step 4)."""

    g: np.ndarray             # columns tau^i: the fitted A_i are those of sum A_i tau^i
    y: np.ndarray             # variance at each tau
    term_alpha: np.ndarray    # noise type of each term
    noise_types: np.ndarray   # every type that can occur, sorted
    edf_table: np.ndarray     # EDF of every point for each of them (computed once)
    max_iter: int

    @classmethod
    def build(cls, taus, y, terms, edf_of_alpha, max_iter) -> "_Reweighting":
        term_alpha = np.array([TERM_ALPHA[t] for t in terms])
        noise_types = np.unique(np.append(term_alpha, 0))
        edf_table = np.array([np.asarray(edf_of_alpha(np.full(taus.size, a)), dtype=float)
                              for a in noise_types])
        g = np.column_stack([taus ** TERM_EXPONENTS[t] for t in terms])
        return cls(g, y, term_alpha, noise_types, edf_table, max_iter)

    def solve(self, a, corr, eps, fixed=None):
        """Noise types and weights from ``a`` (None: the data), then refit.

        ``fixed``: a correlation matrix to use instead of ``corr(a)``.
        """
        g, y = self.g, self.y
        size = y.size
        if a is None:
            alpha = np.zeros(size, dtype=np.int64)   # white FM
            model = y
        else:
            contrib = g * a
            alpha = self.term_alpha[np.argmax(contrib, axis=1)]
            model = contrib.sum(axis=1)
            model = np.where(model > 0, model, y)
        nu = self.edf_table[np.searchsorted(self.noise_types, alpha), np.arange(size)]
        rel_sd = np.sqrt(2.0 / nu)        # sd of the estimate / variance
        rel_cov = (np.eye(size) if corr is None
                   else fixed if fixed is not None else corr((g * a).T))
        rel_cov = rel_cov * np.outer(rel_sd, rel_sd) + eps ** 2 * np.eye(size)
        white = _whitener(rel_cov, model)
        a_new, x = whitened_nnls(g, y, white)
        return a_new, alpha, nu, x, white

    def iterate(self, a, corr, eps, fixed=None, rtol=1e-9, cap=None) -> _Solution:
        """Reweight until the noise types and coefficients settle."""
        alpha: np.ndarray | None = None
        for n_iter in range(1, (self.max_iter if cap is None else cap) + 1):
            a_new, new_alpha, nu, x, white = self.solve(a, corr, eps, fixed)
            settled = (a is not None and alpha is not None and np.array_equal(new_alpha, alpha)
                       and np.allclose(a_new, a, rtol=rtol, atol=0.0))
            a, alpha = a_new, new_alpha
            if settled:
                break
        resid = white(self.g @ a - self.y)
        assert alpha is not None                     # the loop ran at least once
        return _Solution(a, alpha, nu, x, white, float(resid @ resid), n_iter)


def fit_noise_terms(result, edf_of_alpha: Callable[[np.ndarray], np.ndarray],
                    *, terms: Sequence[str] | None = None,
                    method: str = "gls", max_iter: int = 50) -> NoiseFit:
    """Fit IEEE Std 952 noise terms to a deviation curve, with 1-sigma errors.

    Parameters
    ----------
    result : AllanResult
        The deviation curve (:class:`gyroarray.analysis.allan.AllanResult`;
        uses ``kind``, ``taus_s`` [s], ``dev`` [rad/s], ``m``, ``n_terms``).
    edf_of_alpha : callable
        ``edf_of_alpha(alpha) -> edf``: equivalent degrees of freedom [-] of
        each point, shape (k,), given the noise type (integer rate-PSD
        exponent, shape (k,)) assumed at each point.  Must act point by
        point: it is called once per noise type with a constant array.
    terms : sequence of str, optional
        Terms to fit, a subset of :data:`TERMS`; default all the variance can
        see (``"r"`` is excluded for "ohdev").
    method : {"gls", "wls"}, default "gls"
        ``"wls"``: points weighted by their variance, taken as independent.
        ``"gls"``: generalised least squares with the correlation between
        the estimates at different taus (see Notes).
    max_iter : int, default 50
        Maximum iterations of each reweighting loop.

    Returns
    -------
    NoiseFit

    Raises
    ------
    InputError
        Non-positive or non-finite deviations, fewer points than terms, a
        term the variance cannot see, unknown method.

    Notes
    -----
    The estimate of the variance at one tau is approximately
    :math:`\\hat\\sigma^2 \\sim \\sigma^2\\chi^2_\\nu/\\nu` with :math:`\\nu`
    the equivalent degrees of freedom, so
    :math:`\\mathrm{var}(\\hat\\sigma^2) \\approx 2\\sigma^4/\\nu`.  The fit
    minimises :math:`r^T\\Sigma^{-1}r`, :math:`r_j = \\hat\\sigma^2_j -
    \\sum_i A_i\\tau_j^{i}`, with :math:`A_i \\ge 0` (``scipy.optimize.nnls``
    on
    the whitened rows, columns scaled to unit norm), iterating:

    1. first pass: every point white FM (:math:`\\alpha=0`),
       :math:`s_j = \\hat\\sigma^2_j\\sqrt{2/\\nu_j}`, :math:`\\Sigma`
       diagonal;
    2. the term with the largest share :math:`A_i\\tau_j^i` of the fitted
       variance at :math:`\\tau_j` sets the noise type :math:`\\alpha_j`
       (:data:`TERM_ALPHA`), :math:`\\nu_j` is recomputed and
       :math:`s_j = \\sigma^2_{model,j}\\sqrt{2/\\nu_j}` uses the *model*
       variance (weights from the data would favour points that happen to
       be low and bias the fit down);
    3. refit; stop when the noise types no longer change and the
       coefficients change by less than 1e-9 relative;
    4. ``"gls"`` only: :math:`\\Sigma_{jk} = \\rho_{jk}s_js_k` with the
       correlation :math:`\\rho_{jk}` of the estimates at :math:`\\tau_j,
       \\tau_k` predicted from the fitted model (Gaussian noise, phase
       structure function of each term; adjacent octaves correlate by about
       0.5 for white FM, 0.7 flicker FM, 0.9 random-walk FM, and 0.4-0.5 at
       any distance for white PM), then steps 2-3 again with this
       :math:`\\Sigma`;
    5. model error: if the final :math:`\\chi^2 = r^T\\Sigma^{-1}r` exceeds
       the degrees of freedom (points minus active terms), the data scatter
       more than the model and the EDF allow (real sensors: filters,
       Gauss-Markov bumps, temperature).  A relative error
       :math:`\\epsilon`, independent between taus, is added,
       :math:`\\Sigma \\to \\Sigma + \\mathrm{diag}(\\epsilon\\,
       \\sigma^2_{model})^2`, with :math:`\\epsilon` solved (``brentq`` on
       :math:`\\log\\epsilon`) so that :math:`\\chi^2` equals the degrees of
       freedom, and the fit repeated (the Birge-ratio idea, applied where
       the model is worst instead of scaling all errors).  Without it the
       points at short tau, whose EDF reaches 1e5-1e6, pin the fit to any
       0.1%-level misfit there and the long-tau terms come out wrong with
       tiny sigmas.

    Uncertainties: the covariance of the active (non-zero) coefficients is
    :math:`(X^T\\Sigma^{-1}X)^{-1}` (absolute weights; the residual scale is
    not estimated from the data).  The coefficient
    :math:`P_i = \\sqrt{A_i/c_i}` gets the larger distance from :math:`P_i`
    to the images of the ends of the 1-sigma interval of :math:`A_i`
    (clipped at 0),

    .. math::

        \\sigma_P = \\max\\left(\\sqrt{A_i}
                   - \\sqrt{\\max(A_i - \\sigma_A, 0)},\\;
                   \\sqrt{A_i + \\sigma_A} - \\sqrt{A_i}\\right)/\\sqrt{c_i},

    which is the delta method :math:`\\sigma_A/(2\\sqrt{c_iA_i})` to first
    order when :math:`\\sigma_A \\ll A_i` (slightly above it: the square
    root is concave) and stays finite as :math:`A_i \\to 0`, where the delta
    method diverges.  A term clamped at zero gets
    :math:`\\sqrt{\\sigma_A/c_i}`, with :math:`\\sigma_A` from the
    information matrix including that term: its 1-sigma upper limit, the
    size of term the data could just detect at 1 sigma.

    Ignoring the correlations (``"wls"``) makes the sigmas too small by a
    factor of about 1.5 on octave taus; ``"gls"`` gives z-scores with
    standard deviations of 0.94-1.02 (simulated gyros, 200 seeds, see
    ``tests/test_allan_fit.py``).

    References
    ----------
    .. [1] IEEE Std 952-1997, Annex C.
    .. [2] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST
       SP 1065, 2008, sec. 5.3 (confidence intervals, EDF).
    .. [3] C. A. Greenhall, W. J. Riley, "Uncertainty of stability variances
       based on finite differences", Proc. 35th PTTI Meeting, 2003
       (structure-function method for the estimator covariance).
    .. [4] C. L. Lawson, R. J. Hanson, "Solving Least Squares Problems",
       1974 (NNLS).
    """
    kind = result.kind
    _check_kind(kind)
    taus = np.asarray(result.taus_s, dtype=float)
    y = np.asarray(result.dev, dtype=float) ** 2
    if not (np.all(np.isfinite(y)) and np.all(y > 0)):
        raise InputError("the deviation must be finite and positive at every "
                         "tau to fit noise terms (is the input constant?)")
    terms = _checked_terms(kind, terms, taus.size, method, max_iter)

    rw = _Reweighting.build(taus, y, terms, edf_of_alpha, max_iter)
    g, iterate = rw.g, rw.iterate
    sol = iterate(None, None, 0.0)
    corr = None
    if method == "gls":
        corr = _estimate_correlation(np.asarray(result.m),
                                     np.asarray(result.n_terms),
                                     KIND_ORDER[kind], terms)
        sol = iterate(sol.a, corr, 0.0)
    model_error = 0.0
    dof = taus.size - np.count_nonzero(sol.a > 0)
    if dof > 0 and sol.chi2 > dof:
        # The model does not explain the scatter: add the relative model
        # error eps that makes chi2 = dof (Birge ratio idea).
        sol, model_error = _with_model_error(sol, corr, g, dof, iterate, max_iter)
    a, alpha, nu, x = sol.a, sol.alpha, sol.nu, sol.x

    active = a > 0
    cov_active = _covariance(x[:, active]) if active.any() else None
    cov_full = _covariance(x)

    coef, coef_cov = _full_coefficients(terms, a, active, cov_active)
    values = _term_values(kind, terms, a, active, cov_active, cov_full)

    dev = np.sqrt(y)
    return NoiseFit(
        kind=kind,
        terms=terms,
        method=method,
        clamped=tuple(t for t, on in zip(terms, active) if not on),
        coef=coef,
        coef_cov=coef_cov,
        taus_s=taus.copy(),
        alpha=alpha,
        edf=nu,
        chi2=sol.chi2,
        dof=int(taus.size - np.count_nonzero(active)),
        model_error=model_error,
        n_iter=sol.n_iter,
        slope_n_rad_rt_s=term_from_curve(taus, dev, "n", kind=kind),
        slope_k_rad_s_rt_s=term_from_curve(taus, dev, "k", kind=kind),
        slope_b_rad_s=term_from_curve(taus, dev, "b", kind=kind),
        tau_bi_s=float(taus[int(np.argmin(dev))]),
        **values,
    )


#: One-sided tail of the ADEV's upper confidence bound that caps a random walk's K (95 %: on the ADIS
#: record's first half 212 / 325 / 351 deg/h/√h; at 3σ the last octaves' few degrees of freedom
#: leave 411 / 445 / 486, no bound at all on a fitted 248 / 167 / 337) [-].
RRW_BOUND_TAIL = 0.05


class RRWBound(NamedTuple):
    """The largest rate random walk a record's own ADEV allows (:func:`rrw_adev_bound`).

    Attributes
    ----------
    k_max : float
        K_max [rad/s/√s].
    tau_s : float
        The τ whose bound sets it [s].
    adev : float
        The measured ADEV there [rad/s].
    adev_upper : float
        Its upper confidence bound [rad/s].
    edf : float
        Its equivalent degrees of freedom [-].
    """

    k_max: float
    tau_s: float
    adev: float
    adev_upper: float
    edf: float


def rrw_adev_bound(rate_rad_s, dt_s: float, *, tail: float = RRW_BOUND_TAIL) -> RRWBound:
    """The +1/2-slope line through the lowest ADEV upper bound: K <= K_max.

    Parameters
    ----------
    rate_rad_s : array_like, shape (n,)
        The stochastic record [rad/s], uniform step ``dt_s``.
    dt_s : float
        Sample step [s].
    tail : float
        One-sided tail of each τ's upper bound [-].

    Returns
    -------
    RRWBound

    Notes
    -----
    A rate random walk K alone has ADEV K·√(τ/3); no other term of the record can make the
    ADEV smaller than that, so at every octave τ the truth satisfies K·√(τ/3) <= σ_up(τ), the
    measured ADEV's upper bound from its χ² distribution (ν from Greenhall's sampled EDF for a
    random walk, α = −2, the fewest degrees of freedom of the five terms at long τ: the widest,
    safest bound), and

        K_max = min over τ of σ_up(τ)·√(3/τ).

    The minimum is where the ADEV bends up least, normally the last octaves. Issue 44: on the ADIS
    record's first half (raw outputs) the ADEV points alone give 74 / 211 / 234 deg/h/√h, their 95 %
    upper bounds 212 / 325 / 351, where the ladder fitted 248 / 167 / 337.
    """
    from gyroarray.analysis.allan import confidence_interval, edf, oadev       # deferred: allan imports this module
    res = oadev(np.asarray(rate_rad_s, dtype=float), float(dt_s), "octave")
    ok = np.isfinite(res.dev) & (res.dev > 0)
    if not ok.any():
        raise InputError("the record has no Allan deviation to bound its random walk")
    nu = np.asarray(edf("oadev", res.n_phase, res.m, np.full(res.m.size, -2)), dtype=float)
    nu = np.where(np.isfinite(nu) & (nu > 0), nu, 1.0)
    _, hi = confidence_interval(res.dev, nu, confidence=1.0 - 2.0 * tail)
    kmax = np.where(ok, hi * np.sqrt(3.0 / res.taus_s), np.inf)
    j = int(np.argmin(kmax))
    return RRWBound(float(kmax[j]), float(res.taus_s[j]), float(res.dev[j]), float(hi[j]), float(nu[j]))
