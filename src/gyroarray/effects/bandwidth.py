"""``bandwidth``: the gyro's own low-pass filter."""

from __future__ import annotations

import functools
import math
from functools import partial

import numpy as np
from scipy import optimize, signal

from gyroarray.effects.fitting import EffectFit, transfer_limit
from gyroarray.analysis.psd_fit import EFFECTIVE_TESTS, filter_z, filtered_white_avar_ratio, fit_psd
from gyroarray.analysis.gls import RWWhitener
from gyroarray.analysis.memo import ContentMemo, by_content, freeze
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, explains_away, identity, with_cols
from gyroarray.effects.terms import SensorFilter, spread
from gyroarray.core.sensor import bandwidth_filter, bandwidth_sos

#: Lowest cut-off a model may give [Hz]: a time constant of about two days, beyond any gyro's
#: own low-pass (below it the filter's pole rounds to 1 and the filter to an integrator).
MIN_CUTOFF_HZ = 1e-6


def _filter_response(f_hz, cutoff_hz: float, *, order: int, dt_s: float) -> np.ndarray:
    """H(f) of the sampled filter the simulator applies (:func:`bandwidth_sos`) at f [Hz]."""
    fc = min(max(float(cutoff_hz), MIN_CUTOFF_HZ), 0.499 / dt_s)
    _, hz = signal.sosfreqz(bandwidth_sos(fc, int(order), float(dt_s)), worN=np.asarray(f_hz, dtype=float),
                            fs=1.0 / dt_s)
    return hz


@functools.lru_cache(maxsize=512)
def _sos_zi(cutoff_hz: float, order: int, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The filter's sections and their unit steady state (:func:`bandwidth_filter`'s, made once)."""
    sos = bandwidth_sos(cutoff_hz, order, dt_s)
    return sos, signal.sosfilt_zi(sos)


def _lowpassed(u: np.ndarray, dt_s: float, cutoff_hz: float, order: int) -> np.ndarray:
    """:func:`bandwidth_filter` of one signal (n,), the same bits, its design made once per
    (cut-off, order, step) (the motion's likelihood scans the same grid on every residual)."""
    sos, zi = _sos_zi(float(cutoff_hz), int(round(float(order))), float(dt_s))
    y, _ = signal.sosfilt(sos, u, zi=zi * u[0])
    return y


#: Below this the filter's state is taken as decayed (still a normal number: no denormal slow-down).
_DECAYED = 1e-200


@functools.lru_cache(maxsize=512)
def _state_gain(cutoff_hz: float, order: int, dt_s: float) -> np.ndarray:
    """Per state variable j, twice max_n |h_j[n]|, h_j the zero-input output from the unit state
    e_j (by linearity, |y[n]| <= sum_j |z_j| max|h_j| once the input is zero for good)."""
    sos, _ = _sos_zi(cutoff_hz, order, dt_s)
    k = sos.shape[0] * 2
    out = np.empty(k)
    for j in range(k):
        z = np.zeros((sos.shape[0], 2))
        z.flat[j] = 1.0
        peak, length = 0.0, 0
        while True:         # until the response has decayed far below its peak
            h, z = signal.sosfilt(sos, np.zeros(4096), zi=z)
            peak, length = max(peak, float(np.abs(h).max())), length + h.size
            if np.abs(z).max() < 1e-12 * peak or length > 10 ** 7:
                break
        out[j] = 2.0 * peak if length <= 10 ** 7 else np.inf
    return out


#: Leading exact zeros of the sensed rate worth skipping (a table record's static start).
_LEAD_MIN = 4096
#: Samples of the leading zeros filtered to check that the filter sits at its zero fixed point.
_LEAD_PROBE = 64


def _zero_lead(sos: np.ndarray, zi0: np.ndarray, lead: int) -> np.ndarray | None:
    """The filter's state after ``lead`` zero samples from the state ``zi0``, when the outputs there
    are all +0.0 (their bits zero): filtered over a probe of :data:`_LEAD_PROBE` zeros, then one
    more; when the state after the probe and after the step are both all +0.0 and so is the step's
    output, the filter is at its fixed point (zero in, zero state: zero out, the same zero state),
    and it stays there to the end of the zeros. Else None (filter the zeros as they are)."""
    if lead < _LEAD_MIN:
        return None
    y, z = signal.sosfilt(sos, np.zeros(_LEAD_PROBE), zi=zi0)
    y1, z1 = signal.sosfilt(sos, np.zeros(1), zi=z)
    bits = np.concatenate([y, y1, z.reshape(-1), z1.reshape(-1)]).view(np.uint64)
    if bits.any():
        return None
    return z1


def _residual_minus_filter(e: np.ndarray, u: np.ndarray, t0: int, dt_s: float,
                           cutoff_hz: float, order: int, lead: int = 0,
                           out: np.ndarray | None = None) -> np.ndarray:
    """``e - (_lowpassed(u, ...) - u)``, the same bits, where ``u[t0:]`` is exactly zero: filtered
    until the state has decayed below a bound under which ``e - y`` rounds to ``e`` on the rest of
    the tail (checked against the tail's smallest |e|), the rest is ``e`` itself; else in full
    (a decaying zero-input response passes through denormal numbers, each sosfilt step 3-7x slower).

    ``lead``: ``u[:lead]`` is exactly zero too (the static start): where the filter sits at its
    zero fixed point there (:func:`_zero_lead`), its output is +0.0, ``e - (+0.0 - +0.0)`` is
    ``e - 0.0`` bit for bit, and the filter starts again after the zeros from the same zero state.
    ``out``: an (n,) float64 array to write the result into (a scratch buffer the caller reuses:
    fresh arrays of this size are fresh pages, each call's page faults); each element is the same
    two subtractions, ``y - u`` then ``e - (y - u)``, the same bits."""
    n = u.size
    sos, zi = _sos_zi(float(cutoff_hz), int(round(float(order))), float(dt_s))
    out = np.empty(n) if out is None else out
    # y - u up to where the state has decayed reads u only: kept by content (the same gyro's
    # grid on every record cut by another fit: 240 of the 889 of a 46-min, 5-gyro diagnosis)
    slot = _FILTERED.slot(u, float(cutoff_hz), int(round(float(order))), float(dt_s), int(t0), int(lead))
    kept = slot.get("head")
    if kept is None:
        z_lead = None
        if 0 < lead < t0 and u[0] == 0.0:
            z_lead = _zero_lead(sos, zi * u[0], lead)
        if z_lead is not None:
            first = lead
            y, z = signal.sosfilt(sos, u[lead:t0], zi=z_lead)
        else:
            first = 0
            y, z = signal.sosfilt(sos, u[:t0], zi=zi * u[0])
        np.subtract(y, u[first:t0], out=out[first:t0])
        m = t0
        while m < n and np.abs(z).max() >= _DECAYED:
            yk, z = signal.sosfilt(sos, u[m:m + 4096], zi=z)
            np.subtract(yk, u[m:m + yk.size], out=out[m:m + yk.size])
            m += yk.size
        kept = slot["head"] = (first, m, freeze(out[first:m].copy()), z)
        np.subtract(e[first:m], out[first:m], out=out[first:m])
    else:
        first, m, head, z = kept
        np.subtract(e[first:m], head, out=out[first:m])
    if first:
        np.subtract(e[:first], 0.0, out=out[:first])            # e - (+0.0 - +0.0)
    if m < n:
        gain = _state_gain(float(cutoff_hz), int(round(float(order))), float(dt_s))
        bound = float(np.abs(z).reshape(-1) @ gain) + 1e-300     # + the denormal steps' rounding
        tail = e[m:]
        small = float(np.abs(tail).min())
        if not (small > 0.0 and bound < 0.25 * float(np.spacing(small))):
            yk, _ = signal.sosfilt(sos, u[m:], zi=z)
            np.subtract(yk, u[m:], out=out[m:])
            np.subtract(tail, out[m:], out=out[m:])
        else:
            out[m:] = tail          # e - (y - 0) with |y| < a quarter ulp of e: e
    return out


#: :func:`_residual_minus_filter`'s filtered sensed rate y − u up to where the filter's state has
#: decayed (first, end, y − u, state), by the content of u and the filter: 64 of about 0.5 MB on a
#: 46-min, 100 Hz table record (a bandwidth test's grid is 48).
_FILTERED = ContentMemo(maxsize=64)


#: The motion's likelihood results (grid, refined fit, values) by the content of the residual,
#: sensed rate, noise and samples they read: a rival's test on a record cut by another gyro's fit
#: reads this gyro's residual as it was, bit for bit.
_MOTION_MEMO = ContentMemo(maxsize=32)


@by_content(maxsize=8)
def _sensed_rate(ref: np.ndarray, H: np.ndarray, gyro: int) -> np.ndarray:
    """``ref @ H[gyro - 1]``, read-only, kept by content: every bandwidth test of the gyro (on
    every cut record) reads it, and its digest is then kept (memo.freeze)."""
    return freeze(ref @ H[gyro - 1])


class _MotionLR:
    """2·Δℓ(fc, order) of the residual ``e`` with the filter's effect on the sensed rate ``u``
    removed (``memo``: what was already computed on the same content)."""

    def __init__(self, e, u, dt, r, q, use):
        self.e, self.u, self.dt, self.r, self.q, self.use = e, np.asarray(u, dtype=float), float(dt), r, q, use
        self.memo = _MOTION_MEMO.slot(e, self.u, self.dt, float(r), float(q), use)
        self._w = None
        self._buf = None                  # the residual's scratch (one call at a time per instance)
        nz = np.flatnonzero(self.u)
        t0 = int(nz[-1]) + 1 if nz.size else 1
        # a zero tail of the sensed rate long enough to skip (the static end of a table record)
        self._t0 = t0 if self.u.size - t0 > 4096 and np.isfinite(self.u).all() else None
        # and its leading zeros (the static start), skipped where the filter rests at zero there
        # (samples whose bits are all zero: +0.0, not a -0.0, which the filter could carry on)
        bits = self.u.view(np.uint64) if self.u.dtype == np.float64 and self.u.ndim == 1 else None
        live = np.flatnonzero(bits) if bits is not None else np.zeros(1, int)
        self._lead = int(live[0]) if live.size else 0

    def _whitener(self):
        if self._w is None:
            w = RWWhitener(self.e.size, self.r, self.q, self.use)
            z0 = w.whiten(self.e)
            self._w = (w, float(z0 @ z0))
        return self._w

    def __call__(self, fc: float, order: int) -> float:
        w, base = self._whitener()
        if (self._t0 is not None and isinstance(self.e, np.ndarray) and self.e.dtype == np.float64
                and self.e.shape == self.u.shape):
            if self._buf is None:
                self._buf = np.empty(self.u.size)
            d = _residual_minus_filter(self.e, self.u, self._t0, self.dt, fc, order, self._lead, self._buf)
        else:
            d = self.e - (_lowpassed(self.u, self.dt, fc, order) - self.u)
        z = w.whiten(d)
        return base - float(z @ z)

    def at(self, fc: float, order: int) -> float:
        """The value at one (fc, order), kept."""
        key = ("at", float(fc), int(order))
        if key not in self.memo:
            self.memo[key] = self(fc, order)
        return self.memo[key]


class Bandwidth(RegressionEffect):
    """The spec's causal low-pass on everything the sensing element produces
    (after misalignment, scale factor, g-sensitivity and the noise terms,
    before quantization and saturation): order 1 H(s) = 1/(1 + s/ωc), order 2
    the Butterworth; simulated by the bilinear transform pre-warped at the
    cut-off, the state started at the first sample's steady state
    (:func:`gyroarray.core.sensor.bandwidth_filter`).

    Fit, from what the record has:

    * the spectrum of the stochastic record (every record): the white noise
      above the cut-off falls as |H|² (:func:`gyroarray.analysis.psd_fit.fit_psd`;
      order and cut-off by likelihood, z calibrated for the scan);
    * with a reference that moves: the amplitude loss and lag of the sensed
      rate, the record's own H·ref filtered and compared with the residual
      under ARW + a random-walk bias, profiled over the cut-off for both orders.

    Detection adds the two likelihood ratios (they read independent parts of
    the record: the noise and the motion); the cut-off and order come from the
    motion when it sees the filter clearly (2Δℓ > 25), else from the spectrum
    (a Welch fit is biased by about 1 % in the cut-off at these record sizes). Rivals: a latency also lags the
    motion, but leaves the spectrum flat; a Gauss–Markov hump raises the low
    frequencies, but flattens back to the white level, where a filter keeps
    falling (compared by the spectrum's likelihood, same number of parameters).
    """

    name = "bandwidth"
    own_column = True                  # its test reads its gyro's column of the residual only
    order = 18
    stage = Stage.FILTER
    stochastic = True
    reads = "noise"
    rivals = ("gauss_markov", "latency")
    channel = "spectrum_rolloff"
    scored = ("cutoff_hz", "order")
    params = (Param("cutoff_hz", "Hz", "cutoff_hz", identity, lo=MIN_CUTOFF_HZ,
                    doc="−3 dB frequency of the gyro's internal low-pass (below Nyquist)"),
              Param("order", "-", "order", identity, lo=1.0, hi=2.0,
                    doc="1: H(s) = 1/(1 + s/ωc); 2: Butterworth"))
    refit_absolute = True           # the spectrum gives the cut-off itself, whatever the model
    lowpass = True                  # the library's causal low-pass (where it fails names it)
    doc = "the gyro's own causal low-pass filter"

    def check(self, params, gyro, n_gyros):
        if params["order"] not in (1, 2):
            raise InputError(f"order must be 1 (first order) or 2 (Butterworth), got "
                             f"{params['order']!r}", column="order")

    def check_record(self, params, dt_s, span_s):
        nyquist = 0.5 / dt_s
        if params["cutoff_hz"] >= nyquist:
            raise InputError(f"cutoff_hz = {params['cutoff_hz']:g} Hz must be below the Nyquist frequency "
                             f"{nyquist:g} Hz (half the sample rate; the samples cannot show a filter above it: "
                             "lower cutoff_hz or remove the entry)", column="cutoff_hz")

    def placeholder(self):
        return {"cutoff_hz": 1.0, "order": 1}

    def entry_params(self, fit, old):
        params = super().entry_params(fit, old)
        if "order" in params:
            params["order"] = int(round(params["order"]))
        return params

    def noise_term(self, ctx, entry):
        """The gyro's Allan fits read every τ with the filtered white column
        (:func:`filtered_white_avar_ratio`, exact for the sampled filter): N is read before the
        filter, and where the filter acts most (τ = dt, where the record's ADEV is known to a
        fraction of a per cent) the model's band is the record's. Started at the 5 %-clean τ
        instead, N had 2.5× the spread and the band at τ = dt failed on 3 of 12 scored cases
        (z up to 6.6), while a quantization after the filter was not seen at all."""
        fc, order = float(entry.params["cutoff_hz"]), int(entry.params["order"])
        return {"white_shape": partial(filtered_white_avar_ratio, fc, order, ctx.dt)}

    def predictor_term(self, act, n_gyros):
        """A modifier: every reading passes the gyro's own filter (cut-off [Hz], order)."""
        return SensorFilter(spread(act, "cutoff_hz", n_gyros), spread(act, "order", n_gyros))

    def simulate(self, state, act, streams):
        try:
            y = bandwidth_filter(state.x[:, act.cols], state.ctx.dt_s, act.p["cutoff_hz"], act.p["order"])
        except InputError as err:
            raise InputError(f"{act.label}: {err.message}", column=err.column) from None
        return with_cols(state, act.cols, y)

    # -- fit side ----------------------------------------------------------------
    def _psd(self, ctx, gyro: int, E: np.ndarray | None = None):
        """The spectral fit of the gyro's stochastic record (its longest static part before
        the record is chosen, while the model is calibrated)."""
        key = ("bandwidth_psd", gyro, ctx.Er is not None)
        if key not in ctx.cache:
            if ctx.Er is not None:
                x = ctx.Er[:, gyro - 1]
            else:
                a, b = ctx.longest
                x = (ctx.E0 if E is None else E)[a:b, gyro - 1]
            ctx.cache[key] = fit_psd(x, ctx.dt)
        return ctx.cache[key]

    def _motion_lr(self, ctx, gyro: int, e: np.ndarray, r: float, q: float):
        """2·Δℓ(fc, order) of the residual with the filter's effect on the sensed rate removed, or None."""
        if ctx.ref is None or not ctx.moving:
            return None
        return _MotionLR(e, _sensed_rate(ctx.ref, ctx.H, int(gyro)), ctx.dt, r, q, ctx.use)

    def fit(self, ctx, gyro, E):
        """Order and cut-off by the joint likelihood of the spectrum and (with motion) the motion."""
        g = int(gyro)
        psd = self._psd(ctx, g, E)
        nyq = 0.5 / ctx.dt
        motion = self._motion_lr(ctx, g, E[:, g - 1], float(ctx.r[g - 1]), float(ctx.q[g - 1]))

        fcs = np.geomspace(0.01 * nyq, 0.95 * nyq, 24)
        memo = {} if motion is None else motion.memo
        if motion is not None and "grid" not in memo:
            memo["grid"] = {o: np.array([motion(fc, o) for fc in fcs]) for o in (1, 2)}
        mgrid = memo.get("grid")
        # the motion measures the filter directly (a sensed rate of known shape); the spectrum
        # through a Welch estimate whose fit is biased by about 1 % in fc at these record sizes:
        # when the motion sees the filter clearly, it alone gives the cut-off
        use_motion = mgrid is not None and max(mgrid[1].max(), mgrid[2].max()) > 25.0
        order = 1
        if use_motion:
            # the order from both: on a swing an order-2 filter at a higher cut-off lags and
            # attenuates much like an order-1 filter (motion 2Δℓ within 0.4 %), its roll-off does not
            order = max((1, 2), key=lambda k: mgrid[k].max() + psd.lr_filter_order.get(k, 0.0))
            # a best cut-off at the grid's end is no roll-off the motion measured
            use_motion = 0 < int(np.argmax(mgrid[order])) < fcs.size - 1

        if use_motion:
            if ("fit", order) not in memo:
                memo[("fit", order)] = self._motion_fit(motion, mgrid[order], order, fcs)
            fc, s_fc = memo[("fit", order)]
        else:          # the spectrum's own fit: its better family (continuous or digital), refined
            fc, order, s_fc = psd.filter_cutoff_hz, psd.filter_order, psd.filter_cutoff_sigma_hz
            if not fc < 0.95 * nyq:      # the continuous family scans past Nyquist: no roll-off here
                fc, s_fc = 0.95 * nyq, math.nan
        lr_motion = 0.0 if motion is None else max(motion.at(fc, order), 0.0)
        lr = max(psd.lr_filter, 0.0) + lr_motion
        z = filter_z(lr, n_tests=EFFECTIVE_TESTS if motion is None else 2.0 * EFFECTIVE_TESTS)
        sigma = {"cutoff_hz": float(s_fc)} if math.isfinite(s_fc) else {}
        where = "the noise spectrum" + (" and the motion" if lr_motion > 0 else "")
        if z > 3:
            ev = (f"gyro {g}: {where} show{'' if lr_motion > 0 else 's'} a low-pass of order {order} at "
                  f"{fc:.4g}" + (f" ± {s_fc:.2g}" if math.isfinite(s_fc) else "") + " Hz (−3 dB)")
        else:
            ev = f"gyro {g}: no low-pass seen in {where} (best {fc:.3g} Hz, order {order}, z = {z:.1f})"
        fit = EffectFit(self.name, g, {"cutoff_hz": float(fc), "order": int(order)}, sigma, z=float(z),
                        evidence=ev, extra={"lr_psd": float(psd.lr_filter), "lr_motion": float(lr_motion),
                                            "lr_gm_psd": float(psd.lr_gm), "family": psd.filter_family})
        if ctx.ref is None or not ctx.moving:
            return fit
        # the motion's lines: a low-pass must give the amplitude ratios and the dispersion of the
        # phase delay the gyro shows at every line it shows (a delay the model lacks left free;
        # issue 44: 12.84 Hz order 1 would give |H(h5)|/|H(h1)| 0.946, measured 0.994)
        u = _sensed_rate(ctx.ref, ctx.H, g)
        x = u if ctx.ref_raw is None else ctx.ref_raw @ ctx.H[g - 1]        # the reference as recorded
        return transfer_limit(fit, E[:, g - 1] + u, x, ctx.dt, partial(_filter_response, order=int(order), dt_s=ctx.dt),
                              "cutoff_hz", f"a {fc:.4g} Hz low-pass of order {order}", use=ctx.use, free_delay=True,
                              lower=MIN_CUTOFF_HZ)

    @staticmethod
    def _motion_fit(total, ll: np.ndarray, order: int, fcs) -> tuple[float, float]:
        """(cut-off [Hz], 1σ [Hz]) of one order from the motion's likelihood ``ll`` on the grid
        ``fcs``, refined."""
        i = int(np.argmax(ll))
        fc, best = float(fcs[i]), float(ll[i])
        s_fc = math.nan
        if 0 < i < fcs.size - 1:                       # refine between the neighbours, then the curvature
            lo, hi = math.log(fcs[i - 1]), math.log(fcs[i + 1])
            res = optimize.minimize_scalar(lambda u: -total(math.exp(u), order), bounds=(lo, hi),
                                           method="bounded", options={"xatol": 2e-4})
            if -res.fun > best:
                fc, best = math.exp(res.x), -res.fun
            h = 0.005
            d2 = (total(fc * math.exp(h), order) - 2 * best + total(fc * math.exp(-h), order)) / (2 * h * h)
            if d2 < 0:
                s_fc = fc * math.sqrt(-1.0 / d2)
        return fc, s_fc

    def test(self, ctx, gyro):
        return self.fit(ctx, gyro, ctx.E)

    def prefer(self, mine, other, ctx):
        if other.effect == "gauss_markov":
            psd = self._psd(ctx, int(mine.gyro))
            if psd.lr_filter > psd.lr_gm:
                return (f"; but a low-pass at {mine.params['cutoff_hz']:.3g} Hz fits the spectrum better "
                        f"(2Δℓ {psd.lr_filter:.1f} against {psd.lr_gm:.1f}: it keeps falling to Nyquist)")
            return None
        if other.effect == "latency":
            if mine.extra.get("lr_psd", 0.0) > 9.0:     # the spectrum rolls off: a filter, not a delay
                return (f"; but the noise spectrum rolls off as a {mine.params['cutoff_hz']:.3g} Hz low-pass "
                        f"(2Δℓ {mine.extra['lr_psd']:.1f}), which a delay does not do")
            return None
        return explains_away(self, mine, other, ctx)

    def concede(self, mine, other, ctx):
        if other.effect == "gauss_markov":
            psd = self._psd(ctx, int(mine.gyro))
            if psd.lr_gm > psd.lr_filter:
                return (f"; but a Gauss–Markov hump fits the spectrum better (2Δℓ {psd.lr_gm:.1f} "
                        f"against {psd.lr_filter:.1f}: it flattens back to the white level)")
        # a lag the motion shows and a spectrum without a significant roll-off (2Δℓ <= 9, where
        # prefer() takes the filter): a delay. The motion's filter would cut the noise too, and
        # at the cut-offs a lag of a few samples implies the spectrum sees it (a 11 ms lag at
        # 50 Hz: 11.6 Hz, the PSD at 20 Hz a quarter of its low-frequency level). A threshold of 1
        # left 2Δℓ of 1–9 (a flat spectrum's χ² gives that a third of the time) to a coin flip
        # of z: the independent generator's 11.2 ms delay was named a filter (z 291.25 vs 291.23).
        if other.effect == "latency" and mine.extra.get("lr_psd", 0.0) <= 9.0 and mine.extra.get("lr_motion", 0) > 0:
            return (f"; but the noise spectrum shows no roll-off where the filter would cut "
                    f"(2Δℓ {mine.extra.get('lr_psd', 0.0):.1f}): a delay, not a filter")
        return None

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"cutoff_hz": _draw.u(rng, 3.0, 15.0, True),
                                          "order": int(rng.integers(1, 3))}
