"""``temperature_bias``: a bias that follows ``temp_c``."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import optimize, signal

from gyroarray.analysis.gls import gls_rw, GLSFit, NotIdentifiableError, RWWhitener
from gyroarray.analysis.memo import by_content
from gyroarray.effects.fitting import (as_vector, chi2_to_z, EffectFit, fit_extra, not_identifiable, pm, Z_EVIDENT,
                                       z_two_sided)
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, identity, same_noise_preference, with_term
from gyroarray.effects.terms import TemperatureTerm, spread
from gyroarray.core.units import deg_h_to_rad_s, rad_s_to_deg_h, rrw_rad_s_rt_s_to_deg_h_rt_h

#: Each half of a record must span this much temperature [°C], and this share of the whole
#: record's span, for the cross-half test (a warm-up that is over by mid-record is not two periods).
MIN_SPAN_C = 0.5
MIN_SPAN_SHARE = 0.3


class TemperatureBias(RegressionEffect):
    """coeff·(temp_c − t0_c).

    Fit: the regression of the residual on the temperature under ARW + a
    random-walk bias (:func:`gyroarray.effects.temperature_bias.fit_temperature_bias`),
    the walk profiled with the temperature in the model (``profile``: the
    calibration's q, read with the drift in it, is only its upper end; a smooth
    warm-up under a small walk otherwise hides in it), with a thermal-lag column
    (dT/dt of the smoothed reading) when the data ask for it; the levels'
    coefficient (an ordinary regression with an intercept, no random walk) is
    reported beside it. The CATS tag's gyro 2: 92 ± 8 with a
    lag of about 246 s; without the lag column 60 ± 3, the levels 96.
    ``t0_c`` and a constant bias are one parameter: the fit returns the
    coefficient relative to the first temperature.

    Test: a cross-half prediction when each half of the record spans at least
    0.5 °C and 30 % of the whole record's span: the coefficient fitted on one half, its sign and size carried to
    the other (under the walk profiled without it), where the score of the regression in that direction is ≈ N(0, 1)
    without a temperature effect (the two directions averaged); a coefficient
    that does not transfer between the halves is not significant. Otherwise
    the whole record's likelihood ratio with the walk profiled under both, over
    its simulated null mean (:func:`blocked_walk_profile`), and the evidence says why.
    """

    name = "temperature_bias"
    order = 12
    stage = Stage.ADD
    needs = frozenset({"temp"})
    model_needs = predict_needs = frozenset({"temp"})     # bias = k·(temp_c − t0): nothing without it
    sim_needs = frozenset({"temp"})
    slow = True
    rivals = ("rate_ramp",)
    channel = "temp"
    scored = ("deg_h_per_c",)
    params = (Param("deg_h_per_c", "deg/h/°C", "rad_s_per_c", deg_h_to_rad_s, doc="bias per °C"),
              Param("t0_c", "°C", "t0_c", identity, lo=-273.15, doc="temperature of zero bias"))
    doc = "bias proportional to temp_c − t0_c"

    def placeholder(self):
        return {"deg_h_per_c": 0.0, "t0_c": 25.0}

    def predictor_term(self, act, n_gyros):
        """A deterministic error c_i·ΔT for a stated temperature swing ΔT [K] about the
        temperature the bias was calibrated at (none stated: left out)."""
        return TemperatureTerm(spread(act, "rad_s_per_c", n_gyros))

    def simulate(self, state, act, streams):
        temp = state.ctx.temp_c
        if temp is None:
            raise InputError(f"{act.label}: temperature_bias needs the temperature history: "
                             "pass temp_c (one value per sample, °C)")
        return with_term(state, act.cols, (temp[:, None] - act.p["t0_c"]) * act.p["rad_s_per_c"])

    def _rates(self, ctx) -> dict:
        """The record's thermal-lag columns (one temperature for every gyro and every refit)."""
        key = ("temperature_rates",)
        if key not in ctx.cache:
            ctx.cache[key] = temperature_rates(ctx.temp, ctx.dt)
        return ctx.cache[key]

    def regress(self, ctx, gyro, e, r, q):
        f = fit_temperature_bias(e, ctx.temp, ctx.t, ctx.dt, r, q, gyro, use=ctx.use, rates=self._rates(ctx),
                                 parts=ctx.parts, profile=True)
        if not f.extra.get("identifiable", True):
            return f
        # the levels' coefficient beside it: an ordinary regression with an intercept (one per
        # stitched part), the random walk taken as nothing (what a plain regression of bias on
        # temperature gives)
        X = np.column_stack([ctx.part_intercepts(e.size), ctx.temp - ctx.temp.mean()])
        keep = slice(None) if ctx.use is None else ctx.use
        levels = float(rad_s_to_deg_h(np.linalg.lstsq(X[keep], e[keep], rcond=None)[0][-1]))
        return replace(f, extra={**f.extra, "levels_deg_h_per_c": levels})

    def test(self, ctx, gyro):
        f = ctx.fitted(self, gyro, ctx.E)
        cross = self._cross_half(ctx, int(gyro), f)
        return f if cross is None else cross

    def _cross_half(self, ctx, gyro: int, whole: EffectFit) -> EffectFit | None:
        """The whole record's fit with a z from the cross-half prediction, or None (halves too flat)."""
        g = gyro - 1
        n = ctx.n
        halves = (slice(0, n // 2), slice(n // 2, n))
        temp = ctx.temp
        need = max(MIN_SPAN_C, MIN_SPAN_SHARE * float(np.ptp(temp)))
        if min(float(np.ptp(temp[h])) for h in halves) < need:
            return replace(whole, evidence=whole.evidence + f" (one half of the record spans less than "
                                                               f"{need:.2g} °C: no cross-half check)")
        # the walk profiled without the temperature (the test's null: its maximum likelihood
        # there, where the profile with the temperature can fall to nothing when the walk looks
        # like the reading); the calibration's q, read with the drift in it, when it did not run
        r, q = float(ctx.r[g]), float(whole.extra.get("q_without", ctx.q[g]))
        sm = whole.extra.get("lag_smoothing_s")         # the whole fit's thermal-lag column, if any
        X = temperature_columns(temp, None if sm is None else self._rates(ctx)[sm])
        betas, scores = [], []
        for fit_on, other in (halves, halves[::-1]):
            use_fit = None if ctx.use is None else ctx.use[fit_on]
            try:
                fa = gls_rw(ctx.E[fit_on, g], X[fit_on], r, q, use=use_fit, breaks=breaks_within(ctx.parts, fit_on))
            except (NotIdentifiableError, ValueError):
                return None
            beta = float(fa.beta[0])
            betas.append(beta)
            use_other = None if ctx.use is None else ctx.use[other]
            try:                               # the score on the other half, in the direction found
                fb = gls_rw(ctx.E[other, g], X[other], r, q, use=use_other, breaks=breaks_within(ctx.parts, other))
            except (NotIdentifiableError, ValueError):
                return None
            scores.append(math.copysign(1.0, beta) * float(fb.beta[0] / fb.sigma[0]))
        z = float(sum(scores) / math.sqrt(2.0))
        k = [float(rad_s_to_deg_h(b)) for b in betas]
        lv = whole.extra.get("levels_deg_h_per_c")
        ev = (f"{whole.evidence}; halves {k[0]:.3g} and {k[1]:.3g} deg/h/°C, each confirmed on the other "
              f"half with z = {scores[0]:.1f} and {scores[1]:.1f}"
              + (f"; the levels alone (no random walk) give {lv:.3g}" if lv is not None else ""))
        return replace(whole, z=z, evidence=ev,
                       extra={**whole.extra, "z_whole": float(whole.z), "half_coefficients": k,
                              "cross_scores": scores})

    def prefer(self, mine, other, ctx):
        return same_noise_preference(self, mine, other, ctx)

    def channel_line(self, fit, x, xm, ym):
        return ym + fit.params["deg_h_per_c"] * (x - xm), self._label(fit, "deg_h_per_c", unit=" deg/h/°C")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"deg_h_per_c": _draw.u(rng, 10.0, 60.0, True) * rng.choice([-1, 1]),
                                          "t0_c": 25.0}


# -- fit ----------------------------------------------------------------------------------
# -- temperature and rate ramp -------------------------------------------------------

#: Smoothing times of the temperature reading before its derivative is taken [s] (a zero-phase
#: second-order low-pass at 1/T_s): a thermometer's read noise is white, and its derivative
#: would otherwise be noise (the CATS tag's reading: 0.028 °C rms, lag-1 correlation of its
#: differences −0.50).
LAG_SMOOTHING_S = (30.0, 100.0, 300.0, 1000.0)

#: χ² drop at which the thermal-lag column enters the temperature fit: χ²(1) at 1 % after the
#: choice among the smoothings of :data:`LAG_SMOOTHING_S` (Bonferroni, 0.25 % each).
LAG_CHI2 = 9.14


def temperature_rates(temp_c, dt_s: float) -> dict[float, np.ndarray]:
    """The thermal-lag columns a record allows: dT/dt of the temperature reading [°C/s],
    smoothed (zero-phase second-order Butterworth low-pass at 1/T_s, then central
    differences), for each T_s of :data:`LAG_SMOOTHING_S` within [8·dt, span/8]."""
    temp = np.asarray(temp_c, dtype=float)
    out = {}
    for sm in LAG_SMOOTHING_S:
        if not 8.0 * dt_s <= sm <= dt_s * temp.size / 8.0:
            continue
        b, a = signal.butter(2, min(2.0 * dt_s / sm, 0.99))     # cut-off over Nyquist
        pad = min(temp.size - 1, int(3 * sm / dt_s))
        out[sm] = np.gradient(signal.filtfilt(b, a, temp, padtype="odd", padlen=pad), dt_s)
    return out


def temperature_columns(temp: np.ndarray, rate: np.ndarray | None = None) -> np.ndarray:
    """The temperature fit's regressors (n, 1 or 2): T − T_0, and the thermal-lag column."""
    return (temp - temp[0])[:, None] if rate is None else np.column_stack([temp - temp[0], rate])


def breaks_within(parts, piece: slice) -> np.ndarray | None:
    """The part starts (:attr:`~gyroarray.effects.protocol.FitContext.breaks`) of stitched ``parts``
    that fall inside ``piece`` (a slice of the record with a step of 1), relative to its start."""
    if len(parts) < 2:
        return None
    lo, hi = piece.start or 0, piece.stop
    b = np.array([a - lo for a, _ in parts[1:] if lo < a and (hi is None or a < hi)], dtype=int)
    return b if b.size else None


#: Smallest random-walk increment variance the walk profile scans, per unit of the white
#: variance r [-] (a walk of 1e-12·r per sample: none over any record this package reads).
PROFILE_Q_FLOOR = 1e-12

#: Tolerance of the walk profile's bounded search, in ln q [-] (5 % in q: the likelihood is
#: flat to far less than 0.1 in log-likelihood over it).
PROFILE_XATOL = 0.05


def profile_walk(e, X, r: float, q_max: float, *, use=None, breaks=None,
                 xatol: float = PROFILE_XATOL) -> tuple[float, float, float, float]:
    """The random walk profiled with and without the regressors: the likelihood-ratio test of ``X``.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual [rad/s].
    X : array_like, shape (n, p)
        Regressors [rad/s per unit of their coefficient].
    r : float
        White variance per sample N²/dt [rad²/s²], held fixed (short τ pin it down).
    q_max : float
        Largest random-walk increment variance scanned [rad²/s²]: the calibration's q,
        read from a residual with the drift still in it (an upper bound of the walk).
    use, breaks
        As :func:`~gyroarray.analysis.gls.gls_rw`.
    xatol : float
        Tolerance of the search in ln q [-] (default :data:`PROFILE_XATOL`).

    Returns
    -------
    (q1, q0, lr, loglik1) : tuple of float
        The maximum-likelihood q [rad²/s²] with ``X`` (β profiled) and without it, in
        [1e-12·r, q_max]; lr = 2·(ℓ₁ − ℓ₀) >= 0, the likelihood ratio of β ≠ 0 with the walk
        profiled under both (≈ χ²(p) without the regressors); ℓ₁ [-] the log-likelihood
        with them.

    Notes
    -----
    The calibration's q is the larger of the walk's maximum likelihood and the Allan fit's
    K + 2σ on the residual, with the drift in it: a smooth warm-up of 24 deg/h reads as a random
    walk (K 9.8 deg/h/√h where the record's own is 3) and hides itself, σ of the coefficient
    four times its value under the true walk. Profiled, the walk is what the record leaves once
    the regressors are fitted with it; the ratio of the two maxima is the test, as the rate
    ramp's (K profiled under both, :mod:`gyroarray.effects.stochastic`).
    """
    e = np.asarray(e, dtype=float)
    X = np.asarray(X, dtype=float)
    X = X[:, None] if X.ndim == 1 else X
    n = e.size
    lo = math.log(PROFILE_Q_FLOOR * r)
    hi = max(math.log(max(float(q_max), PROFILE_Q_FLOOR * r)), lo)
    w = RWWhitener(n, r, math.exp(hi), use, breaks)        # the differences and their links, built once

    def nll(lq: float, cols: bool) -> float:
        q = math.exp(lq)
        zy, logdet = w.whiten_at(e, r, q)
        rss = _dot(zy, zy)
        if cols:
            za = np.column_stack([w.whiten_at(X[:, j], r, q)[0] for j in range(X.shape[1])])
            beta = np.linalg.lstsq(za, zy, rcond=None)[0]
            res = zy - za @ beta
            rss = _dot(res, res)
        return 0.5 * (logdet + rss)

    out = []
    for cols in (True, False):
        if hi - lo < xatol:
            lq = hi
        else:
            sol = optimize.minimize_scalar(lambda u: nll(u, cols), bounds=(lo, hi), method="bounded",
                                           options={"xatol": xatol})
            lq = float(sol.x) if nll(float(sol.x), cols) <= nll(hi, cols) else hi   # the bound itself
        out.append((math.exp(lq), nll(lq, cols)))
    (q1, l1), (q0, l0) = out
    const = 0.5 * w.m * math.log(2.0 * math.pi)
    return q1, q0, max(2.0 * (l0 - l1), 0.0), -(l1 + const)


#: Blocks the null calibration of the walk profile reads the record in (about; block means of
#: at least one sample each): the temperature is smooth, so block means keep its information.
NULL_BLOCKS = 1000

#: Records simulated for the null calibration of the walk profile's likelihood ratio.
NULL_DRAWS = 128

#: Walks of the null calibration, as fractions of the top of the profile's range [-] (K at
#: 1, 1/2 and 1/4 of it): the factor is the largest null mean among them. The ratio's null mean
#: is not monotone in the walk (the 1-hour warm-up of :func:`blocked_walk_profile`, range up to
#: K 10 deg/h/√h, 300 records each: 0.81 / 1.10 / 1.44 / 1.58 / 1.61 / 1.52 / 1.40 at K 0.3 / 1 /
#: 2 / 3 / 4.5 / 6 / 10), so the top alone would not bound it for every walk the range allows.
NULL_WALKS = (1.0, 0.25, 0.0625)

#: Likelihood ratio below which the null calibration is not simulated (factor 1): z <= 1.75
#: before it, below the z of 2 at which a slow effect is refitted and far below any test's.
NULL_SKIP_LR = 4.0

#: Tolerance in ln q of the null calibration's profiles [-] (25 % in q: the ratio's error is
#: second order in it, far below the spread of its mean over :data:`NULL_DRAWS` records).
NULL_XATOL = 0.25

#: Seed of the null calibration's generator (fixed: the bits never depend on what ran before).
NULL_SEED = 20261203


def _block_index(n: int, size: int, use=None, breaks=None) -> tuple[np.ndarray, np.ndarray | None]:
    """Sample indices (m, size) of whole blocks of ``size`` consecutive used samples, none across a
    break or an unused sample, and the first block of each new piece after the first (or None)."""
    keep = np.ones(n, bool) if use is None else np.asarray(use, bool)
    cut = np.zeros(n, bool)
    if breaks is not None:
        cut[np.asarray(breaks, dtype=int)] = True
    prev = np.r_[False, keep[:-1]]
    run_a = np.flatnonzero(keep & (~prev | cut))            # a run of used samples starts
    nxt = np.r_[keep[1:], False] & ~np.r_[cut[1:], False]
    run_b = np.flatnonzero(keep & ~nxt) + 1                  # ... and ends
    starts: list[int] = []
    firsts: list[int] = []
    for i, j in zip(run_a, run_b):
        nb = (int(j) - int(i)) // size
        if nb:
            firsts.append(len(starts))
            starts.extend(range(int(i), int(i) + nb * size, size))
    idx = np.asarray(starts, dtype=np.int64)[:, None] + np.arange(size, dtype=np.int64)[None, :]
    b = np.asarray(firsts[1:], dtype=int)
    return idx, (b if b.size else None)


def block_size(n: int, r: float, q_max: float) -> int:
    """Samples per block of the walk profile's block means: n/:data:`NULL_BLOCKS` (at least 1),
    halved until the walk within a block moves the means' white part by at most 1 % for any q
    up to ``q_max`` [rad²/s²] (r the white variance per sample [rad²/s²])."""
    size = max(1, n // NULL_BLOCKS)
    while size > 1 and q_max * (size * size - 1) / 6.0 > 0.01 * r:
        size //= 2
    return size


def blocked_walk_profile(e, X, r: float, q_max: float, *, use=None,
                         breaks=None) -> tuple[float, float, float, float]:
    """:func:`profile_walk` of ``e`` on ``X`` read on block means, and its null mean.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual [rad/s].
    X : array_like, shape (n,)
        The regressor [rad/s per unit of its coefficient].
    r, q_max : float
        White variance per sample and the walk's upper end [rad²/s²] (:func:`profile_walk`).
    use, breaks
        As :func:`~gyroarray.analysis.gls.gls_rw`.

    Returns
    -------
    (q1, q0, lr, factor) : tuple of float
        The profiled walk per sample with and without ``X`` [rad²/s²], the likelihood ratio
        and its mean on :data:`NULL_DRAWS` records simulated without ``X`` (fixed seed
        :data:`NULL_SEED`; never below 1; :func:`_null_mean`), the largest over the walks of
        :data:`NULL_WALKS`: lr/factor is at most ≈ χ²(1) without the regressor, for the walks
        up to q_max.

    Notes
    -----
    Block means of ``size`` samples (:func:`block_size`; whole blocks within each run of used
    samples and each piece) have differences that are exactly the MA(1) of white noise
    r/size − q(size² − 1)/(6·size) and a walk of q·size per block: white + walk again, the
    first term within 1 % of r/size by the choice of size. A smooth regressor loses nothing
    to them, and the profile and its null simulation cost O(n/size).

    The walk of an hour-long record is read from a few of its longest τ only, and a smooth
    regressor lives there too: without it, the ratio with the walk profiled under both has a
    mean of 1.5–1.8, not 1 (an exponential warm-up, τ 900 s, 1 h, ARW 0.3 deg/√h, RRW
    3–10 deg/h/√h, 150 records), and χ²(1) would call about 1 % of such records significant
    at z 3.47 instead of 0.03 %. The ratio over its simulated mean (a Bartlett factor) is
    what the test reads.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    size = block_size(n, r, q_max)
    idx, bb = _block_index(n, size, use, breaks)
    if idx.shape[0] < 16:                                   # too few blocks: the samples themselves
        idx, bb, size = _block_index(n, 1, use, breaks) + (1,)
    eb = e[idx].mean(axis=1)
    xb = np.asarray(X, dtype=float)[idx].mean(axis=1)
    rb, qb_max = r / size, q_max * size
    q1, q0, lr, _ = profile_walk(eb, xb, rb, qb_max, breaks=bb)
    # the factor (>= 1) only lowers z: below NULL_SKIP_LR it decides nothing and is not simulated
    factor = 1.0 if lr < NULL_SKIP_LR else max(_null_mean(xb, rb, qb_max, qb_max * f, bb) for f in NULL_WALKS)
    return q1 / size, q0 / size, lr, factor


@by_content(maxsize=96)
def _null_mean(xb: np.ndarray, rb: float, qb_max: float, qb: float, bb) -> float:
    """Mean of :func:`profile_walk`'s ratio (walk up to ``qb_max``) on :data:`NULL_DRAWS` records
    of white ``rb`` + walk ``qb`` without the regressor ``xb`` (block means, pieces from ``bb``),
    never below 1. Cached by content: a ladder step leaves most gyros as they were."""
    m = xb.size
    rng = np.random.default_rng(NULL_SEED)
    total = 0.0
    for _ in range(NULL_DRAWS):
        y = math.sqrt(rb) * rng.standard_normal(m) + np.cumsum(math.sqrt(qb) * rng.standard_normal(m))
        total += profile_walk(y, xb, rb, qb_max, breaks=bb, xatol=NULL_XATOL)[2]
    return max(total / NULL_DRAWS, 1.0)


def _lag_columns(e, temp, r: float, q: float, use, base: GLSFit,
                 rates: dict, breaks=None) -> tuple[GLSFit, float | None, GLSFit | None, float | None]:
    """The fit with the thermal-lag column beside T − T_0, when it lowers χ² by more than
    :data:`LAG_CHI2` (the best smoothing of ``rates``), else ``base`` and None; then the best fit
    with the column and its smoothing whether or not it entered (None, None: no column fits)."""
    best, best_s = base, None
    cand, cand_s = None, None
    for sm, rate in rates.items():
        try:
            fit = gls_rw(e, temperature_columns(temp, rate), r, q, use=use, breaks=breaks)
        except NotIdentifiableError:     # dT/dt ∝ T − const (an exponential approach) or flat
            continue
        if cand is None or fit.chi2 < cand.chi2:
            cand, cand_s = fit, sm
        if fit.chi2 < best.chi2 - (LAG_CHI2 if best_s is None else 0.0):
            best, best_s = fit, sm
    return best, best_s, cand, cand_s


def _lead_of(fit: GLSFit) -> tuple[float, float]:
    """(τ, σ_τ) [s] of a fit with the thermal-lag column: τ = d/c (the gyro leads the reading by
    τ; −τ is the lag −d/c of bias = c·T + d·dT/dt), σ by the delta method from its covariance."""
    b, c, cov = float(fit.beta[0]), float(fit.beta[1]), fit.cov
    lead = c / b
    var = cov[1, 1] / b ** 2 - 2.0 * c * cov[0, 1] / b ** 3 + c ** 2 * cov[0, 0] / b ** 4
    return lead, math.sqrt(max(var, 0.0))


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """Σ a·b of two vectors, summed by numpy (no BLAS thread pool for an O(n) product)."""
    return float(np.sum(a * b))


#: Shifts of the lag scan (:func:`thermal_lag_scan`): this many on each side of zero.
SCAN_STEPS = 40

#: Blocks the lag scan's long-run residual variance is read from (block means).
SCAN_BLOCKS = 50

#: Largest difference between the dT/dt fit's lag and the lag scan's at which the two agree,
#: in their combined σ (two estimates of one lag from one record, weighted differently: the
#: changes and the levels).
LAG_AGREE = 2.0


def thermal_lag_scan(e, temp_c, dt_s: float, max_shift_s: float, *, parts=(), use=None) -> tuple[float, float]:
    """The thermal lag from the levels: the residual variance of ``e`` against the temperature
    shifted by s, scanned over s.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual [rad/s].
    temp_c : array_like, shape (n,)
        Temperature reading [°C].
    dt_s : float
        Sample step [s].
    max_shift_s : float
        Largest shift scanned, each way [s] (:data:`SCAN_STEPS` steps each side of 0, at least
        one sample each).
    parts : sequence of (int, int), optional
        Stitched parts ``[start, stop)``: one free intercept each, and the shifted temperature
        is read within its own part (the reading at the part's edge beyond it).
    use : array_like of bool, shape (n,), optional
        Samples to include.

    Returns
    -------
    (lead_s, sigma_s) : tuple of float
        The shift of least residual variance, as a lead [s] (the gyro follows the reading
        ``lead_s`` early: e ≈ c·T(t + lead_s); a lag is a negative lead), refined by a parabola
        through the three shifts about the minimum, and its 1σ from the parabola's curvature
        (Δχ² = 1 with χ² = RSS / (n·σ²_LR), σ²_LR the residual's long-run variance per sample
        from :data:`SCAN_BLOCKS` block means: a slowly varying regressor's least-squares
        variance under correlated noise). σ = inf when the minimum is at the scan's edge.

    Notes
    -----
    An ordinary least-squares regression per shift (one intercept per part), independent of
    the GLS fit and of the dT/dt column's smoothing: a cross-check of the first-order lag
    −d/c of :func:`fit_temperature_bias`, which reads the changes.
    """
    e = np.asarray(e, dtype=float)
    temp = np.asarray(temp_c, dtype=float)
    n = e.size
    pts = list(parts) if len(parts) >= 2 else [(0, n)]
    keep = np.ones(n, bool) if use is None else np.asarray(use, bool)
    step = max(float(max_shift_s) / SCAN_STEPS, dt_s)
    shifts = step * np.arange(-SCAN_STEPS, SCAN_STEPS + 1)
    e_c = np.empty(n)
    for a, b in pts:                                        # the residual less its part's mean
        k = keep[a:b]
        e_c[a:b] = e[a:b] - (e[a:b][k].mean() if k.any() else 0.0)
    e_c[~keep] = 0.0
    ee = _dot(e_c, e_c)

    def shifted(s: float) -> np.ndarray:
        """The temperature reading shifted by s [s] within each part, less its part's mean."""
        x = np.empty(n)
        for a, b in pts:
            i = np.arange(b - a, dtype=float)
            x[a:b] = np.interp(i + s / dt_s, i, temp[a:b])
            k = keep[a:b]
            x[a:b] -= x[a:b][k].mean() if k.any() else 0.0
        x[~keep] = 0.0
        return x

    rss = np.empty(shifts.size)
    for j, s in enumerate(shifts):
        x = shifted(float(s))
        xx = _dot(x, x)
        rss[j] = ee - (_dot(x, e_c) ** 2 / xx if xx > 0 else 0.0)
    j = int(np.argmin(rss))
    if j in (0, shifts.size - 1):
        return float(shifts[j]), math.inf
    y0, y1, y2 = rss[j - 1], rss[j], rss[j + 1]
    curv = (y0 - 2.0 * y1 + y2) / (2.0 * step ** 2)         # RSS ≈ RSS_min + curv·(s − ŝ)²
    lead = float(shifts[j] + 0.5 * step * (y0 - y2) / (y0 - 2.0 * y1 + y2)) if curv > 0 else float(shifts[j])
    # the residual at the minimum, its long-run variance per sample from block means
    x = shifted(lead)
    xx = _dot(x, x)
    res = e_c - (_dot(x, e_c) / xx) * x if xx > 0 else e_c
    m = int(keep.sum())
    blk = max(m // SCAN_BLOCKS, 1)
    used = res[keep]
    nb = used.size // blk
    means = used[:nb * blk].reshape(nb, blk).mean(axis=1) if nb else np.zeros(1)
    lrv = max(blk * float(np.mean(means ** 2)), float(np.mean(used ** 2)))
    if not (curv > 0 and lrv > 0):
        return lead, math.inf
    return lead, math.sqrt(lrv / curv)


def fit_temperature_bias(e, temp_c, time_s, dt_s: float, r: float, q: float, gyro: int,
                         *, use=None, rates: dict | None = None, parts=(), profile: bool = False) -> EffectFit:
    """Temperature-dependent bias: residual following the temperature.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual [rad/s].
    temp_c : array_like, shape (n,)
        Temperature reading at the array [°C].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`~gyroarray.analysis.gls.gls_rw`).
    rates : dict, optional
        The thermal-lag columns, :func:`temperature_rates` of ``temp_c`` (a caller
        fitting several gyros on one temperature computes them once). Default:
        computed here.
    parts : sequence of (int, int), optional
        Stitched still parts ``[start, stop)`` (re-orientations between them): one
        free offset per part in every regression (``breaks`` of
        :func:`~gyroarray.analysis.gls.gls_rw`, one intercept per part in the lag
        scan). Default: one record.
    profile : bool
        Profile the random walk with the temperature in the model (:func:`profile_walk`, q in
        [1e-12·r, q]): the coefficient and the lag column are fitted at the profiled q, z is
        the likelihood ratio with the walk profiled under both (χ²(1) without a temperature
        effect) and σ the larger of the GLS σ at the profiled q and |k|/√LR (the walk's own
        uncertainty widens it, as the rate ramp's). ``extra``'s ``chi2``, ``dof`` and
        ``loglik`` stay those at the given q, comparable with the rival regressions under the
        same noise. Default: at the given q (z the Wald ratio).

    Returns
    -------
    EffectFit
        ``temperature_bias``: ``deg_h_per_c`` with sigma, and
        ``t0_c = temp_c[0]`` without sigma. ``extra``: ``thermal_lag_s`` and its
        ``thermal_lag_sigma_s`` (a lead, the gyro ahead of the reading [s]; None without
        the lag column), ``lag_smoothing_s`` (None without the lag column),
        ``thermal_lag_resolved`` (the lag is reported), ``lag_scan_s`` and
        ``lag_scan_sigma_s`` (the lag scan's lead, :func:`thermal_lag_scan`, when run).

    Notes
    -----
    ::

        e_t = k·(T_t + τ·dT_t/dt − T_0) + b_t + w_t,   T_0 = temp_c[0]

    The temperature of zero bias t0 is not identifiable: k·(T − t0) =
    k·(T − T_0) + k·(T_0 − t0), and the constant joins the unknown starting
    bias. So ``t0_c`` is reported as the first temperature (the model then
    starts with the fitted starting bias, as the baseline does).

    τ is a thermal lag between the thermometer and the gyro (first order: the
    gyro's own temperature is T + τ·dT/dt). It is a nuisance: ``shared/spec``'s
    ``temperature_bias`` has no lag, and the calibrated model predicts k·(T − t0).
    Without it, a fast temperature change (the CATS tag: 16 → 9 °C in 10 min)
    has a smaller response than the slow cycle, and the GLS, which reads the
    coefficient from the changes, gives 60 deg/h/°C on its gyro 2 where the
    levels give 96 and the sensor's two other periods 93 and 93; with the lag
    column (τ ≈ 246 s) 92 ± 8 in `compare`. The column is dT/dt of the reading smoothed at
    one of :data:`LAG_SMOOTHING_S` (the best, within [8·dt, span/8]), and it
    enters only when it lowers the GLS χ² by more than :data:`LAG_CHI2` (a
    pre-test at 1 %: without a lag the coefficient keeps the power of the
    one-column fit). A first-order approach to a final temperature has dT/dt ∝
    T − const: the lag is then not identifiable and the column stays out.

    The lag is reported only when the record resolves it: the column entered,
    |τ| > 2σ_τ (σ by the delta method), and a lag scan of the levels
    (:func:`thermal_lag_scan`, an ordinary regression on the shifted reading)
    resolves it too (its own |lag| > 2σ) and agrees with it within :data:`LAG_AGREE`
    combined σ. Otherwise the
    evidence says "thermal lag not resolved by this record (|lag| < X s)", X =
    |τ| + 2σ_τ of the best fit with the column (when the scan resolves a lag the
    fit does not agree with, the larger of that and |τ_scan| + 2σ_scan; both are
    stated). The coefficient is the fit's either way: with the column when it
    entered by the χ² pre-test, whether or not the lag is reported.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    as_vector(time_s, n, "time_s")
    temp = as_vector(temp_c, n, "temp_c")
    t0 = float(temp[0])
    breaks = (np.array([a for a, _ in parts[1:]], dtype=int) if len(parts) >= 2 else None)
    try:
        fit = gls_rw(e, temp - t0, r, q, use=use, breaks=breaks)
    except NotIdentifiableError as err:
        return not_identifiable("temperature_bias", gyro, {"deg_h_per_c": 0.0, "t0_c": t0},
                                 "the temperature does not change", err)
    given = fit                          # at the given (r, q): the χ² the rival regressions are compared on
    q_fit, lr, walk = q, None, {}
    if profile:
        q_fit, q_none, lr_raw, factor = blocked_walk_profile(e, temp - t0, r, q, use=use, breaks=breaks)
        lr = lr_raw / factor
        fit = gls_rw(e, temp - t0, r, q_fit, use=use, breaks=breaks)
        walk = {"q_profiled": q_fit, "q_without": q_none, "walk_lr": lr_raw, "walk_lr_factor": factor,
                "chi2_profiled": fit.chi2}
    rates = temperature_rates(temp, dt_s) if rates is None else rates
    fit, sm, cand, cand_sm = _lag_columns(e, temp, r, q_fit, use, fit, rates, breaks)
    if profile and sm is not None:       # the same columns at the given q
        given = gls_rw(e, temperature_columns(temp, rates[sm]), r, q, use=use, breaks=breaks)
    b, s = float(fit.beta[0]), float(fit.sigma[0])
    if lr is not None:                   # the walk's own uncertainty: σ at least |k|/√LR
        if lr > 0.0:
            s = max(s, abs(b) / math.sqrt(lr))
        walk["chi2_profiled"] = fit.chi2
    k, ks = rad_s_to_deg_h(b), rad_s_to_deg_h(s)
    t = b / s
    z = z_two_sided(t) if lr is None else chi2_to_z(lr, 1)
    if lr is not None:
        k_walk = [rrw_rad_s_rt_s_to_deg_h_rt_h(math.sqrt(v / dt_s)) for v in (q_fit, walk["q_without"])]
        walk_txt = (f"; the random walk profiled: K = {k_walk[0]:.3g} deg/h/√h with the temperature, "
                    f"{k_walk[1]:.3g} without (the calibration's {rrw_rad_s_rt_s_to_deg_h_rt_h(math.sqrt(q / dt_s)):.3g}"
                    f", read with the drift in it), likelihood ratio {lr_raw:.3g} over its mean {factor:.3g} "
                    f"on records without a temperature effect")
    else:
        walk_txt = ""
    lag = lag_s = scan = scan_s = None
    resolved = False
    reach = 0.0                          # the lag scan's range each way [s], when it runs
    lag_txt = ""
    if sm is not None:                   # τ = d/k, its σ by the delta method from the fit's covariance
        lag, lag_s = _lead_of(fit)
    if cand is not None and float(cand.beta[0]) != 0.0:
        if sm is None:
            lead, lead_s = _lead_of(cand)
        else:                            # the lag column entered: lag, lag_s were set just above
            assert lag is not None and lag_s is not None
            lead, lead_s = lag, lag_s
        if sm is not None and abs(lead) > 2.0 * lead_s:
            # the cross-check: a lag scan of the levels over a range the fit's lag and σ ask for
            span = min(b_ - a_ for a_, b_ in parts) if len(parts) >= 2 else n
            reach = min(max(2.0 * abs(lead) + 4.0 * lead_s, 20.0 * dt_s), span * dt_s / 4.0)
            scan, scan_s = thermal_lag_scan(e, temp, dt_s, reach, parts=parts, use=use)
            resolved = (abs(scan) > 2.0 * scan_s
                        and abs(scan - lead) <= LAG_AGREE * math.sqrt(lead_s ** 2 + scan_s ** 2))
        if resolved:
            assert scan is not None and scan_s is not None   # resolved only after the scan ran
            way = "leading" if lead > 0 else "lagging"
            lag_txt = (f", the gyro {way} the temperature reading by {pm(abs(lead), lead_s)} s (a thermal lag, "
                       f"fitted as a dT/dt term on the reading smoothed over {sm:.0f} s; a lag scan of the "
                       f"levels gives {pm(abs(scan), scan_s)} s)")
        elif scan is None or scan_s is None:   # the dT/dt term does not see a lag (set together)
            lag_txt = f", thermal lag not resolved by this record (|lag| < {abs(lead) + 2.0 * lead_s:.3g} s)"
        elif not math.isfinite(scan_s):  # the levels have no least residual within the scan
            lag_txt = (f", thermal lag not resolved by this record (the dT/dt term reads the gyro ahead of the "
                       f"reading by {pm(lead, lead_s)} s, a lag scan of the levels finds no minimum within "
                       f"±{reach:.3g} s)")
        else:                            # two estimates that do not agree: a bound that covers both
            bound = max(abs(lead) + 2.0 * lead_s, abs(scan) + 2.0 * scan_s)
            lag_txt = (f", thermal lag not resolved by this record (|lag| < {bound:.3g} s: the dT/dt term reads "
                       f"the gyro ahead of the reading by {pm(lead, lead_s)} s, a lag scan of the levels by "
                       f"{pm(scan, scan_s)} s)")
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} residual follows the temperature: {pm(k, ks)} deg/h per °C "
              f"relative to {t0:.2f} °C{lag_txt}{walk_txt}; the model has no temperature term")
    else:
        ev = (f"gyro {gyro} residual shows no significant temperature dependence "
              f"({pm(k, ks)} deg/h per °C, z = {z:.1f}{lag_txt}{walk_txt})")
    extra = fit_extra(fit, t=t, thermal_lag_s=lag, thermal_lag_sigma_s=lag_s, lag_smoothing_s=sm,
                      thermal_lag_resolved=resolved, lag_scan_s=scan, lag_scan_sigma_s=scan_s, **walk)
    if profile:                          # the rivals' comparison reads the χ² at the noise they share
        extra.update(chi2=given.chi2, dof=given.dof, loglik=given.loglik)
    return EffectFit("temperature_bias", gyro, {"deg_h_per_c": k, "t0_c": t0}, {"deg_h_per_c": ks},
                     z, ev, extra)
