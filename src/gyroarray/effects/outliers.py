"""``outliers``: isolated single-sample spikes (heavy-tailed first differences, not a noise level)."""

from __future__ import annotations

import math

import numpy as np

from gyroarray.effects.fits.effect_fit import EffectFit
from gyroarray.effects.fits.outliers import clean_spikes, find_spikes
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Effect, Kind, Param, Stage, no_longer_seen, with_term
from gyroarray.core.units import deg_s_to_rad_s, rad_s_to_deg_s

#: Seconds per hour (the rate's unit).
_S_PER_H = 3600.0
#: Most spikes per hour a model may give [1/h]: one per sample at the highest sample rate a
#: scenario may have (1 MHz); beyond it the Poisson count of a run overflows.
MAX_RATE_PER_H = 1e6 * _S_PER_H


class Outliers(Effect):
    """Spikes on the output: in each gyro a Poisson number of them, ``rate_per_h``
    per hour on average, at samples drawn uniformly over the record (distinct),
    each of size N(0, ``size_deg_s``²) (rms ``size_deg_s``). They act on the
    output after the sensor's filter (a spike is one sample: a glitch of the
    output, not of the rate the sensing element sees) and before saturation.

    Fit (:mod:`gyroarray.effects.fits.outliers`): the samples that depart from
    their 5-sample running median by more than a Bonferroni threshold of the
    noise's robust σ are the spikes; z is the excess of the count beyond
    4.5σ over its Poisson expectation; the rms size by the truncated-normal
    likelihood of the detected values and the rate corrected for the spikes
    below the threshold. With outliers in the model the spikes are replaced
    by their median before any other fit reads the record (the noise fit, the
    ADEV and its band, the burst and the regressions): a robust record.
    Rivals: a burst or a Gauss–Markov read spikes as a raised noise level;
    once the spikes are out, they are no longer seen.
    """

    name = "outliers"
    order = 20
    stage = Stage.QUANTIZE          # after the filter and the quantization noise, before saturation
    kind = Kind.TIME
    reads = "noise"
    rivals = ("burst", "gauss_markov", "bias_instability", "sinusoid", "fault_noise")
    params = (Param("rate_per_h", "1/h", "rate_per_s", lambda x: x / _S_PER_H, lo=0.0, hi=MAX_RATE_PER_H,
                    doc="spikes per hour (mean of a Poisson count)"),
              Param("size_deg_s", "deg/s", "size_rad_s", deg_s_to_rad_s, lo=0.0,
                    doc="rms spike size (spikes ~ N(0, size²))"))
    scored = ("rate_per_h", "size_deg_s")
    doc = "isolated single-sample spikes"

    def simulate(self, state, act, streams):
        ctx = state.ctx
        term = np.zeros((ctx.n, len(act.cols)))
        span_s = ctx.n * ctx.dt_s
        for j, c in enumerate(act.cols):
            gen = streams.stream(self.name, int(c) + 1)
            k = int(min(gen.poisson(act.p["rate_per_s"][j] * span_s), ctx.n))
            where = gen.choice(ctx.n, size=k, replace=False)
            term[where, j] = gen.normal(0.0, act.p["size_rad_s"][j], k)
        return with_term(state, act.cols, term)

    # -- fit side -------------------------------------------------------------------
    def _spikes(self, ctx, gyro: int, x: np.ndarray, key: str):
        k = ("outliers", key, gyro)
        if k not in ctx.cache:
            ctx.cache[k] = find_spikes(x)
        return ctx.cache[k]

    def fit(self, ctx, gyro, E):
        g = int(gyro)
        in_model = any(e.effect == self.name and e.gyro == g for e in ctx.entries(self.name))
        # in the model its spikes are already out of the residual: they are counted on the raw one.
        # A spike is judged against the noise around it (a running median), and at a burst's
        # edges that median mixes the two levels: the first samples inside read as a crowd of
        # spikes (scored burst cases, right model: z 3.7 on one gyro). The model knows the level.
        x = ctx.at_model_level(ctx.E0 if in_model else E, ctx.t)[:, g - 1]
        x = x[:ctx.noise_end]                           # not what the model leaves out to the end (frozen)
        sp = self._spikes(ctx, g, x, "raw" if in_model else "residual")
        span_h = x.size * ctx.dt / _S_PER_H
        rate = sp.rate * x.size / span_h if span_h > 0 else 0.0
        size = float(rad_s_to_deg_s(sp.size)) if math.isfinite(sp.size) else 0.0
        sigma = {}
        if sp.index.size:
            sigma["rate_per_h"] = float(rate / math.sqrt(sp.index.size))       # Poisson
            if math.isfinite(sp.size_sigma):
                sigma["size_deg_s"] = float(rad_s_to_deg_s(sp.size_sigma))
        if sp.z > 3:
            held = ("; at most, since the size is held at the threshold/1.96: those seen are too few "
                    "to say how many lie below it") if sp.size_at_floor else ""
            ev = (f"gyro {g} has {sp.index.size} isolated spikes (rms {size:.3g} deg/s, {rate:.3g} per hour "
                  f"counting those below the {sp.threshold:.1f}σ threshold{held}; {sp.count_excess} second-difference "
                  f"clusters beyond {4.5:g}σ against {sp.expected:.2g} expected; first differences' excess kurtosis "
                  f"{sp.kurtosis:.3g})")
        else:
            ev = (f"gyro {g} shows no spikes ({sp.count_excess} second-difference clusters beyond 4.5σ against "
                  f"{sp.expected:.2g} expected, z = {sp.z:.1f})")
        return EffectFit(self.name, g, {"rate_per_h": float(rate), "size_deg_s": size}, sigma, z=float(sp.z),
                         evidence=ev, extra={"n_spikes": int(sp.index.size), "kurtosis": sp.kurtosis})

    def test(self, ctx, gyro):
        return self.fit(ctx, gyro, ctx.E)

    def _clean_index(self, ctx, entry, x: np.ndarray) -> np.ndarray:
        return find_spikes(x).index

    def exclude(self, ctx, entry):
        g = entry.gyro - 1
        mask = np.zeros(ctx.n, bool)
        mask[self._clean_index(ctx, entry, ctx.E0[:, g])] = True
        return mask if mask.any() else None

    def clean(self, ctx, entry, x):
        g = entry.gyro - 1
        x = np.array(x, copy=True)
        x[:, g] = clean_spikes(x[:, g], self._clean_index(ctx, entry, x[:, g]))
        return x

    def band_entries(self, ctx, entry):
        return []                           # the band is compared with the cleaned record

    def prefer(self, mine, other, ctx):
        g = int(mine.gyro)
        x = ctx.E[:, g - 1]
        idx = find_spikes(x).index
        if not idx.size:
            return None
        pred = np.zeros_like(ctx.E)
        pred[:, g - 1] = x - clean_spikes(x, idx)           # the spikes, as a "prediction" taken out
        return no_longer_seen(ctx.without(pred), other, ctx, f"the {idx.size} spikes of gyro {g} taken out")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"rate_per_h": _draw.u(rng, 60.0, 600.0, True),
                                          "size_deg_s": _draw.u(rng, 0.5, 3.0, True)}
