"""``temperature_bias``: a bias that follows ``temp_c``."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import signal

from gyroarray.analysis.gls import gls_rw, GLSFit, NotIdentifiableError
from gyroarray.effects.fitting import (as_vector, EffectFit, fit_extra, not_identifiable, pm, Z_EVIDENT,
                                       z_two_sided)
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, identity, same_noise_preference, with_term
from gyroarray.effects.terms import TemperatureTerm, spread
from gyroarray.core.units import deg_h_to_rad_s, rad_s_to_deg_h

#: Each half of a record must span this much temperature [°C], and this share of the whole
#: record's span, for the cross-half test (a warm-up that is over by mid-record is not two periods).
MIN_SPAN_C = 0.5
MIN_SPAN_SHARE = 0.3


class TemperatureBias(RegressionEffect):
    """coeff·(temp_c − t0_c).

    Fit: the regression of the residual on the temperature under ARW + a
    random-walk bias (:func:`gyroarray.effects.temperature_bias.fit_temperature_bias`),
    with a thermal-lag column (dT/dt of the smoothed reading) when the data ask
    for it; the levels' coefficient (an ordinary regression with an intercept,
    no random walk) is reported beside it. The CATS tag's gyro 2: 92 ± 8 with a
    lag of about 246 s; without the lag column 60 ± 3, the levels 96.
    ``t0_c`` and a constant bias are one parameter: the fit returns the
    coefficient relative to the first temperature.

    Test: a cross-half prediction when each half of the record spans at least
    0.5 °C and 30 % of the whole record's span: the coefficient fitted on one half, its sign and size carried to
    the other, where the score of the regression in that direction is ≈ N(0, 1)
    without a temperature effect (the two directions averaged); a coefficient
    that does not transfer between the halves is not significant. Otherwise
    the whole record's Wald z, and the evidence says why.
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
                                 parts=ctx.parts)
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
        r, q = float(ctx.r[g]), float(ctx.q[g])
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
                         *, use=None, rates: dict | None = None, parts=()) -> EffectFit:
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
    fit, sm, cand, cand_sm = _lag_columns(e, temp, r, q, use, fit,
                                          temperature_rates(temp, dt_s) if rates is None else rates, breaks)
    b, s = float(fit.beta[0]), float(fit.sigma[0])
    k, ks = rad_s_to_deg_h(b), rad_s_to_deg_h(s)
    t = b / s
    z = z_two_sided(t)
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
              f"relative to {t0:.2f} °C{lag_txt}; the model has no temperature term")
    else:
        ev = (f"gyro {gyro} residual shows no significant temperature dependence "
              f"({pm(k, ks)} deg/h per °C, z = {z:.1f}{lag_txt})")
    return EffectFit("temperature_bias", gyro, {"deg_h_per_c": k, "t0_c": t0}, {"deg_h_per_c": ks},
                     z, ev, fit_extra(fit, t=t, thermal_lag_s=lag, thermal_lag_sigma_s=lag_s, lag_smoothing_s=sm,
                                      thermal_lag_resolved=resolved, lag_scan_s=scan, lag_scan_sigma_s=scan_s))
