"""Model vs measurement: calibrate a noise model to a recorded run, find where it fails.

The chain (after pvlib's ModelChain: one object, explicit steps, every
intermediate kept as an attribute a report can show):

1. **residual** ``E = gyro − H·ref`` [rad/s] of every gyro (``H`` the
   layout's axes, ``ref`` the table's reference rate; without a reference
   ``E`` is the output itself, and if the outputs show the array turning
   (:func:`gyroarray.analysis.motion.still_mask`) only their still parts,
   stitched, are diagnosed);
2. **calibrate** the model to it: the baseline (``arw`` + ``rrw`` of every
   gyro, unknown starting biases) plus every effect the model names, each
   refitted by its fit side (:mod:`gyroarray.analysis.regress`,
   :mod:`~gyroarray.analysis.stochastic_fit`, :mod:`~gyroarray.analysis.earth_fit`):
   the ARW/RRW variances ``r``, ``q`` on the longest static part, the
   deterministic effects by GLS under that noise (backfitted, two passes),
   the stochastic ones on the residual left by the deterministic part;
3. **candidates**: every effect of the spec *not* in the model, on every
   gyro it can act on, fitted the same way; each has a significance ``z``
   (≈ N(0, 1) when the effect is absent, large positive when present);
4. **model band**: the calibrated stochastic part of the model simulated
   ``n_runs`` times over the same record (:func:`gyroarray.sim.effects.simulate_readings`,
   the record's own clock), its ADEV per gyro against the measured one; a
   per-gyro z says whether the measured ADEV leaves the band at any τ;
5. **discrepancy**: the largest z of all those tests over the critical
   value that keeps the family-wise false-alarm rate at ``alpha`` (1 %):

       D = max_k z_k / z_crit(K),   z_crit(K) = Φ⁻¹((1 − alpha)^(1/K))

   (Šidák, K tests). D <= 1: no test, candidate effect or ADEV band, says
   the model is wrong (``consistent``); D = 3 means the worst test is three
   times as far out as a 1 % family-wise alarm. A candidate is
   ``significant`` when its z exceeds z_crit.

Which record the stochastic tests read: the whole run when no deterministic
test is significant (a dynamic part that the model explains adds
information, e.g. a weak bias instability), else the longest static part
(an unexplained scale factor would otherwise read as noise); also the static
part when the model clips or quantizes the output. The burst test reads the
whole run unless the model clips (it looks at sample-to-sample differences,
which a slow deterministic residual barely touches).

Rivals: when two effects explain the same excess on one gyro, the better fit
is named first (AIC among bias instability / quantization / Gauss–Markov and
between scale factor and tilt; the joint fit for a curvature against a scale
factor; χ² under the same noise for a temperature slope against a rate
ramp), and the other says why it ranks lower.

Units: SI inside; spec units only in ``EffectFit.params`` and the model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import optimize, special, stats

from gyroarray.analysis.allan import averaging_factors, oadev
from gyroarray.analysis.earth_fit import attitude_from_rates, fit_earth_rate
from gyroarray.analysis.motion import still_mask
from gyroarray.analysis.effect_fit import EffectFit
from gyroarray.analysis.regress import (_RWWhitener, fit_latency, fit_misalignment, fit_rate_ramp, fit_saturation,
                                        fit_scale_factor, fit_scale_nonlinearity, fit_sinusoid,
                                        fit_temperature_bias)
from gyroarray.analysis.stochastic_fit import fit_burst, fit_correlation, fit_gyro_noise
from gyroarray.errors import InputError
from gyroarray.measurement import Measurement, _runs
from gyroarray.sim.effects import effect_names, get_effect, simulate_readings
from gyroarray.sim.model import ModelEntry, NoiseModel
from gyroarray.units import (RAD_PER_DEG, arw_deg_rt_h_to_rad_rt_s, rad_s_to_deg_h,
                             rrw_deg_h_rt_h_to_rad_s_rt_s)

__all__ = ["ALPHA", "Test", "Analysis", "ModelComparison", "baseline_model", "critical_z",
           "parse_add", "EFFECT_GROUPS"]

#: Family-wise false-alarm rate of the discrepancy.
ALPHA = 0.01

#: Relative rise of D a ladder step may cause: the Monte-Carlo band's scatter between
#: two calibrations (ADIS16405: a 19.6 Hz line added on gyro 3 moved D 3.71 -> 3.73,
#: the worst test being gyro 1's band, which the line does not touch).
LADDER_D_SLACK = 0.02

#: A sample is static when every reference component is within this [rad/s] (0.01 deg/s).
STATIC_RAD_S = 0.01 * RAD_PER_DEG

#: Shortest static part that calibrates the noise [samples] (6 octaves up to n/8 and more).
MIN_STATIC = 2048

#: Shortest still part kept when a record without reference is stitched [samples].
MIN_STILL_PART = 256

#: Monte-Carlo runs of the model band.
N_RUNS = 40

_PER_GYRO_NOISE = ("bias_instability", "quantization", "rate_ramp", "gauss_markov")
_NEEDS_REF = ("scale_factor", "scale_nonlinearity", "misalignment", "latency", "saturation",
              "earth_rate")
_DETERMINISTIC = ("scale_factor", "scale_nonlinearity", "misalignment", "latency", "saturation",
                  "temperature_bias", "earth_rate", "rate_ramp", "sinusoid", "constant_bias")
_SLOW = ("temperature_bias", "earth_rate", "rate_ramp")
_STOCHASTIC_SIM = ("arw", "rrw", "bias_instability", "quantization", "gauss_markov", "correlation",
                   "burst")

#: What each effect's fit reads, for the report and the "needs a reference" note.
EFFECT_GROUPS = {
    "stochastic": ("arw", "rrw", "bias_instability", "quantization", "rate_ramp", "gauss_markov"),
    "deterministic": ("sinusoid", "constant_bias", "scale_factor", "scale_nonlinearity",
                      "misalignment", "temperature_bias", "latency", "saturation"),
    "array": ("correlation", "earth_rate", "burst"),
}


def critical_z(n_tests: int, alpha: float = ALPHA) -> float:
    """One-sided normal critical value of ``n_tests`` tests at family-wise ``alpha`` (Šidák)."""
    k = max(int(n_tests), 1)
    # 1 − (1 − alpha)^(1/k), accurately for large k
    p = -math.expm1(math.log1p(-alpha) / k)
    return float(-special.ndtri(p))


def baseline_model(n_gyros: int, *, arw_deg_rt_h: float = 0.1, rrw_deg_h_rt_h: float = 10.0) -> NoiseModel:
    """``arw`` + ``rrw`` on every gyro (values are placeholders: calibration refits them)."""
    entries = []
    for g in range(1, n_gyros + 1):
        entries.append(ModelEntry("arw", g, {"n_deg_rt_h": arw_deg_rt_h}))
        entries.append(ModelEntry("rrw", g, {"k_deg_h_rt_h": rrw_deg_h_rt_h}))
    return NoiseModel(tuple(entries), description="baseline: ARW + RRW on every gyro")


def parse_add(text: str, n_gyros: int) -> tuple[str, int | None]:
    """``EFFECT[:GYRO]`` of ``--add`` -> (effect, gyro or None); InputError when wrong."""
    name, _, g = str(text).partition(":")
    name = name.strip()
    eff = get_effect(name) if name in effect_names() else None
    if eff is None:
        from gyroarray.sim.effects import did_you_mean
        raise InputError(f"--add {text}: unknown effect {name!r}{did_you_mean(name, effect_names())} "
                         f"(effects: {', '.join(effect_names())})")
    if not g:
        if eff.per_gyro:
            raise InputError(f"--add {text}: {name} acts on one gyro; say which, e.g. {name}:1 "
                             f"(gyros 1..{n_gyros})")
        return name, None
    if not eff.per_gyro:
        raise InputError(f"--add {text}: {name} acts on the whole array; write just {name}")
    try:
        gyro = int(g)
    except ValueError:
        raise InputError(f"--add {text}: gyro must be a number 1..{n_gyros}, got {g!r}") from None
    if not 1 <= gyro <= n_gyros:
        raise InputError(f"--add {text}: gyro {gyro} is not in 1..{n_gyros}")
    return name, gyro


@dataclass(frozen=True)
class Test:
    """One test of the model against the measurement.

    ``kind`` is ``"effect"`` (a candidate effect not in the model, ``fit``
    its fit) or ``"adev_band"`` (the measured ADEV of one gyro against the
    model's Monte-Carlo band). ``z`` ≈ N(0, 1) when the model is right.
    """

    kind: str
    effect: str | None
    gyro: int | None
    z: float
    evidence: str
    fit: EffectFit | None = None
    extra: dict = field(default_factory=dict)


@dataclass
class Analysis:
    """Everything one calibration + diagnosis produced (arrays in SI).

    Attributes
    ----------
    model : NoiseModel
        The calibrated model (the input model's effects, refitted, plus the baseline).
    fits : dict
        (effect, gyro) -> EffectFit of every effect of the model.
    tests : list of Test
        Every test, candidates and ADEV bands, in no order.
    candidates : list of Test
        The effect tests, best (largest z) first.
    discrepancy, z_crit : float
        Headline number and the critical z of the family.
    residual_rad_s : ndarray (n, N)
        Gyro − H·ref − the model's deterministic part.
    raw_residual_rad_s : ndarray (n, N)
        Gyro − H·ref.
    record : slice
        Samples the stochastic tests used.
    static : ndarray of bool (n,)
        Static samples.
    adev : dict
        ``taus_s`` (T,), ``measured`` (N, T), ``mc`` (runs, N, T) [rad/s].
    notes : list of str
        Said to the user (what was skipped and why).
    """

    model: NoiseModel
    fits: dict
    tests: list
    candidates: list
    discrepancy: float
    z_crit: float
    residual_rad_s: np.ndarray
    raw_residual_rad_s: np.ndarray
    record: slice
    static: np.ndarray
    adev: dict
    notes: list
    r: np.ndarray
    q: np.ndarray

    @property
    def consistent(self) -> bool:
        return bool(self.discrepancy <= 1.0)

    @property
    def excess(self) -> float:
        """Σ (z − z_crit)² over the significant tests: how much is left to explain, all tests at once."""
        return float(sum((t.z - self.z_crit) ** 2 for t in self.tests if self.significant(t)))

    def significant(self, test: Test) -> bool:
        return bool(np.isfinite(test.z) and test.z > self.z_crit)

    def unexplained(self) -> list[str]:
        """Plain sentences for significant ADEV-band tests on gyros without a significant candidate."""
        explained = {t.gyro for t in self.candidates if self.significant(t)}
        # of the array-wide effects only a burst changes a gyro's own ADEV
        # (a correlation or the Earth rate leaves it as it is)
        array_wide = any(t.effect == "burst" and self.significant(t) for t in self.candidates)
        out = []
        for t in self.tests:
            if t.kind == "adev_band" and self.significant(t) and t.gyro not in explained and not array_wide:
                out.append(t.evidence + f"; none of the {len(effect_names())} effects explains it")
        return out

    def to_json_dict(self) -> dict:
        """The ``diagnose --json`` object."""
        return {
            "discrepancy": _finite(self.discrepancy),
            "consistent": self.consistent,
            "candidates": [{"effect": t.effect, "gyro": t.gyro, "score": _finite(t.z),
                            "significant": self.significant(t), "evidence": t.evidence}
                           for t in self.candidates],
            "z_crit": self.z_crit,
            "n_tests": len(self.tests),
            "adev_band": [{"gyro": t.gyro, "z": _finite(t.z), "significant": self.significant(t),
                           "evidence": t.evidence} for t in self.tests if t.kind == "adev_band"],
            "unexplained": self.unexplained(),
            "notes": list(self.notes),
        }

    def effects_json(self) -> list[dict]:
        """The calibrated model's effects with params and sigma (``fit --json``)."""
        out = []
        for entry in self.model:
            f = self.fits.get((entry.effect, entry.gyro))
            out.append({"effect": entry.effect, "gyro": entry.gyro, "params": _entry_params(entry),
                        "sigma": {} if f is None else {k: _finite(v) for k, v in f.sigma.items()}})
        return out


def _finite(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _entry_params(entry: ModelEntry) -> dict:
    d = entry.to_dict()
    d.pop("effect", None)
    d.pop("gyro", None)
    return d


class ModelComparison:
    """Compare a measurement with a noise model (the chain of the module docstring).

    Parameters
    ----------
    measurement : Measurement
        The recorded run.
    model : NoiseModel, optional
        Effects to calibrate (default :func:`baseline_model`); ``arw`` and
        ``rrw`` are added on every gyro that lacks them.
    n_runs : int
        Monte-Carlo runs of the model band.
    seed : int
        Seed of the band's ``numpy.random.Generator`` (results are bit-identical per seed).
    alpha : float
        Family-wise false-alarm rate of the discrepancy.
    """

    def __init__(self, measurement: Measurement, model: NoiseModel | None = None, *,
                 n_runs: int = N_RUNS, seed: int = 0, alpha: float = ALPHA):
        self.m = measurement
        self.name = measurement.source or "measurement"
        self.n_runs = int(n_runs)
        self.seed = int(seed)
        self.alpha = float(alpha)
        self.H = np.asarray(measurement.layout.axes, float)
        self.N = self.H.shape[0]
        self.dt = float(measurement.dt_s)
        self.t = np.asarray(measurement.time_s, float)
        self.n = self.t.size
        # the simulator's clock: uniform at dt from the first sample (the
        # measured clock may jitter by a fraction of a step)
        self.t_sim = self.t[0] + np.arange(self.n) * self.dt
        self.y = np.asarray(measurement.gyro_rad_s, float)
        self.ref = measurement.ref_rad_s
        self.temp = None if measurement.temp_c is None else np.asarray(measurement.temp_c, float)
        model = baseline_model(self.N) if model is None else model
        model.check(self.N)
        self.model = self._with_baseline(model)
        self._check_usable()
        self.parts: list[tuple[int, int]] = []      # stitched still parts, [start, stop) of the new record
        self.parts_s: list[tuple[float, float]] = []  # ... and where they were in the measurement [s]
        if self.ref is None:
            self._keep_still_parts()
        self.E0 = self.y - (self.ref @ self.H.T if self.ref is not None else 0.0)
        if self.ref is not None:
            self.static = np.all(np.abs(self.ref) <= STATIC_RAD_S, axis=1)
        else:
            self.static = np.ones(self.n, bool)
        runs = [r for r in _runs(self.static) if r[1] - r[0] >= MIN_STATIC]
        if not runs:
            longest = max((b - a for a, b in _runs(self.static)), default=0)
            raise InputError(f"no static part long enough to calibrate the noise: the longest stretch "
                             f"with the reference rate within 0.01 deg/s is {longest} samples "
                             f"({longest * self.dt:.1f} s), at least {MIN_STATIC} samples "
                             f"({MIN_STATIC * self.dt:.1f} s) are needed", file=self.name)
        self.static_runs = runs
        self.longest = max(runs, key=lambda r: r[1] - r[0])
        self.moving = self.ref is not None and bool(np.any(~self.static))
        self._attitude = None
        self._det_use = None     # samples the regressions use (None = all); set per analysis

    # -- set-up -----------------------------------------------------------
    def _keep_still_parts(self) -> None:
        """No reference: keep the parts the outputs show still (:func:`~gyroarray.analysis.motion.still_mask`).

        A record without ``ref_*`` that moves (a hand-turned board, a table
        run without its log) would read its motion as noise. Its still parts
        of at least ``MIN_STILL_PART`` samples are stitched into one record,
        each part's mean replaced by the first part's (the bias steps with the
        orientation: Earth rate, g-sensitivity), so the diagnosis sees noise
        only; τ beyond a part's length and the drift between parts are lost.
        """
        still = still_mask(self.y, self.H, self.dt)
        if still.all():
            return
        runs = [(a, b) for a, b in _runs(still) if b - a >= MIN_STILL_PART]
        total = sum(b - a for a, b in runs)
        if total < MIN_STATIC:
            longest = max((b - a for a, b in _runs(still)), default=0)
            raise InputError(
                f"no reference rate (ref_x, ref_y, ref_z) and the outputs show motion for "
                f"{(~still).sum() * self.dt:.0f} s of {self.n * self.dt:.0f} s: the still parts add up to "
                f"{total * self.dt:.1f} s (longest {longest * self.dt:.1f} s; parts shorter than "
                f"{MIN_STILL_PART * self.dt:.1f} s not counted), at least {MIN_STATIC * self.dt:.1f} s are "
                f"needed to calibrate the noise; record a longer static part or add the reference rate",
                file=self.name)
        first = self.y[runs[0][0]:runs[0][1]].mean(axis=0)
        pieces, start = [], 0
        for a, b in runs:
            pieces.append(self.y[a:b] - self.y[a:b].mean(axis=0) + first)
            self.parts.append((start, start + b - a))
            self.parts_s.append((float(self.t[a]), float(self.t[b - 1] + self.dt)))
            start += b - a
        idx = np.concatenate([np.arange(a, b) for a, b in runs])
        self.y = np.concatenate(pieces)
        self.temp = None if self.temp is None else self.temp[idx]
        self.n = idx.size
        self.t = self.t_sim = self.t[0] + np.arange(self.n) * self.dt

    def _like_parts(self, x: np.ndarray) -> np.ndarray:
        """A simulated record treated as the stitched one: each part's mean set to the first part's."""
        if not self.parts:
            return x
        x = np.array(x, copy=True)
        a0, b0 = self.parts[0]
        first = x[a0:b0].mean(axis=0)
        for a, b in self.parts[1:]:
            x[a:b] += first - x[a:b].mean(axis=0)
        return x

    def _with_baseline(self, model: NoiseModel) -> NoiseModel:
        have = {(e.effect, e.gyro) for e in model}
        for e in model:
            if e.effect in ("arw", "rrw") and e.gyro is None:
                have |= {(e.effect, g) for g in range(1, self.N + 1)}
        out = model
        for g in range(1, self.N + 1):
            for eff, key, v in (("arw", "n_deg_rt_h", 0.1), ("rrw", "k_deg_h_rt_h", 10.0)):
                if (eff, g) not in have:
                    out = out.with_effect(ModelEntry(eff, g, {key: v}))
        # per-gyro entries for every effect written for "all gyros"
        entries = []
        for e in out:
            if e.gyro is None and get_effect(e.effect).per_gyro:
                entries += [ModelEntry(e.effect, g, dict(e.params)) for g in range(1, self.N + 1)
                            if (e.effect, g) not in have]
            else:
                entries.append(e)
        return NoiseModel(tuple(entries), description=model.description, source=model.source)

    def _check_usable(self):
        if self.n < MIN_STATIC:
            raise InputError(f"too short for a diagnosis: {self.n} samples ({self.n * self.dt:.1f} s); "
                             f"at least {MIN_STATIC} samples of a static part are needed to "
                             f"calibrate the noise", file=self.name)
        steps = np.diff(self.t)
        if np.max(np.abs(steps - self.dt)) > 0.25 * self.dt:
            raise InputError("the sample times are not uniform (the Allan and regression fits need "
                             "a uniform step); resample or repair the record first", file=self.name)
        self.t = self.t_sim          # jitter below a quarter step: the fits use the uniform clock

    @property
    def attitude(self):
        if self._attitude is None and self.ref is not None:
            self._attitude = attitude_from_rates(self.ref, self.dt)
        return self._attitude

    def _site(self, latitude_deg=None):
        s = self.m.site
        lat = latitude_deg * RAD_PER_DEG if latitude_deg is not None else (
            s.latitude_rad if s is not None else 0.0)
        return (lat, s.heading_rad if s is not None else 0.0)

    def _heading(self) -> float:
        return self.m.site.heading_rad / RAD_PER_DEG if self.m.site is not None else 0.0

    # -- the deterministic part's prediction ------------------------------
    def _prediction(self, entry: ModelEntry) -> np.ndarray:
        """What one deterministic effect adds to the outputs [rad/s], (n, N)."""
        truth = self.ref if self.ref is not None else np.zeros((self.n, 3))
        if entry.effect == "saturation":
            # the clip acts on the input plus the gyro's bias b: on the plateau
            # the residual is then b (no noise), as off it, not 0
            g = entry.gyro - 1
            a, b = self.longest
            u = truth @ self.H[g] + float(np.mean(self.E0[a:b, g]))
            c = float(entry.params["range_deg_s"]) * RAD_PER_DEG
            out = np.zeros((self.n, self.N))
            out[:, g] = np.clip(u, -c, c) - u
            return out
        kw = {"time_s": self.t_sim}
        if entry.effect == "temperature_bias":
            kw["temp_c"] = self.temp
        if entry.effect == "earth_rate":
            kw["attitude"] = self.attitude
            kw["site"] = self._site(float(entry.params["latitude_deg"]))
        sim = simulate_readings(NoiseModel((entry,)), truth, self.H, self.dt,
                                np.random.default_rng(0), **kw)
        return sim - truth @ self.H.T

    # -- one effect's fit ---------------------------------------------------
    def _fit_det(self, effect: str, gyro: int | None, E: np.ndarray, r, q) -> EffectFit:
        """Fit a deterministic effect on residual E (its own contribution included).

        The slow ones (temperature, Earth rate, rate ramp) are fitted twice:
        the noise's q, which decides how much slow drift is forgiven, is
        estimated again on the residual without the first fit's
        contribution (a real drift inflates q and would hide itself)."""
        f = self._fit_det_once(effect, gyro, E, r, q)
        if effect not in _SLOW or not np.isfinite(f.z) or f.z < 2.0:
            return f
        entry = self._entry_from_fit(f, ModelEntry(effect, gyro, _placeholder(effect, self)))
        clean = E - self._prediction(entry)
        q2 = np.array(q, dtype=float, copy=True)
        gyros = range(self.N) if gyro is None else [gyro - 1]
        for g in gyros:
            q2[g] = self._noise_rq(clean[:, g], g + 1)[1]
        return self._fit_det_once(effect, gyro, E, r, q2)

    def _fit_det_once(self, effect: str, gyro: int | None, E: np.ndarray, r, q) -> EffectFit:
        if gyro is None:
            if effect == "earth_rate":
                return fit_earth_rate(E, self.H, self.ref, self.t, self.dt, r, q, self._heading(),
                                      None if self.m.site is None else self.m.site.latitude_rad / RAD_PER_DEG,
                                      attitude=self.attitude)
            raise ValueError(effect)
        g = gyro - 1
        e, h, rr, qq = E[:, g], self.H[g], float(r[g]), float(q[g])
        args = (e, self.ref, h, self.t, self.dt, rr, qq, gyro)
        use = self._det_use
        if effect == "scale_factor":
            return fit_scale_factor(*args, use=use)
        if effect == "scale_nonlinearity":
            return fit_scale_nonlinearity(*args, use=use)
        if effect == "misalignment":
            return fit_misalignment(*args, use=use)
        if effect == "latency":
            return fit_latency(*args, use=use)
        if effect == "saturation":
            u = self.ref @ h
            f = fit_saturation(u + e, u, rr, gyro, use=use)
            if np.isfinite(f.z) and f.z >= 3.0:
                # ranking score: the χ² the plateau explains, Σ (y − u)²/r where
                # the reference is beyond it (a regression's z is the root of its
                # Δχ²; a clipped output makes a scale factor look huge too)
                c = float(f.params["range_deg_s"]) * RAD_PER_DEG
                beyond = np.abs(u) > c + 3.0 * math.sqrt(rr)
                z_eq = math.sqrt(float(np.sum(e[beyond] ** 2)) / rr)
                f = replace(f, z=max(float(f.z), z_eq), extra={**f.extra, "z_plateau": float(f.z)})
            return f
        if effect == "temperature_bias":
            return fit_temperature_bias(e, self.temp, self.t, self.dt, rr, qq, gyro, use=use)
        if effect == "rate_ramp":
            return fit_rate_ramp(e, self.t, self.dt, rr, qq, gyro, use=use)
        if effect == "sinusoid":
            return fit_sinusoid(e, self.t, self.dt, rr, qq, gyro, use=use)
        if effect == "constant_bias":
            a, b = self.longest
            x = e[a:b]
            span = (b - a) * self.dt
            var = rr / (b - a) + qq / self.dt * span / 3.0
            v = float(np.mean(x))
            s = math.sqrt(var)
            return EffectFit("constant_bias", gyro, {"bias_deg_h": float(rad_s_to_deg_h(v))},
                             {"bias_deg_h": float(rad_s_to_deg_h(s))}, z=0.0,
                             evidence=(f"gyro {gyro} starting bias {rad_s_to_deg_h(v):.4g} ± "
                                       f"{rad_s_to_deg_h(s):.2g} deg/h (part of the baseline's "
                                       f"unknown starting bias, never a candidate)"))
        raise ValueError(effect)

    def _available(self, effect: str) -> str | None:
        """None if the effect can be fitted on this measurement, else why not."""
        if effect in _NEEDS_REF and self.ref is None:
            return "needs the reference rate (ref_x, ref_y, ref_z)"
        if effect in _NEEDS_REF and not self.moving:
            return "needs a dynamic part (the table never turns)"
        if effect == "temperature_bias":
            if self.temp is None:
                return "needs the temperature (temp_c)"
            if np.ptp(self.temp) < 0.5:
                return "needs a temperature that changes (temp_c spans less than 0.5 °C)"
        if effect == "earth_rate" and self.m.site is None:
            return "needs the site ([site] heading_deg) of the sidecar"
        if effect == "correlation" and self.N < 2:
            return "needs at least 2 gyros"
        if effect == "constant_bias":
            return "is the baseline's unknown starting bias (always fitted)"
        return None

    def _noise_rq(self, e: np.ndarray, gyro: int) -> tuple[float, float]:
        """White variance r = N²/dt and random-walk increment variance q = K²·dt [rad²/s²] of one gyro.

        r from the Allan fit of the longest static part (ARW is always well
        determined). q, which decides how much slow drift the regressions
        forgive, is the larger of (a) its maximum-likelihood value on all
        static samples, the random walk running through the dynamic gaps
        (exact likelihood of :class:`~gyroarray.analysis.regress._RWWhitener`),
        and (b) the Allan fit's K + 2σ_K: a drift the Allan variance cannot
        tell from RRW (a flicker floor, a short record where K is 0 ± σ) must
        not make a slow regressor (temperature, ramp, Earth rate) significant.
        """
        a, b = self.longest
        base = fit_gyro_noise(e[a:b], self.dt, gyro)
        n_rad = arw_deg_rt_h_to_rad_rt_s(base[0].params["n_deg_rt_h"])
        k_up = rrw_deg_h_rt_h_to_rad_s_rt_s(base[1].params["k_deg_h_rt_h"]
                                            + 2.0 * base[1].sigma.get("k_deg_h_rt_h", 0.0))
        r = max(n_rad ** 2 / self.dt, 1e-30)
        q_up = max(k_up ** 2 * self.dt, 1e-12 * r)
        q_ml = _ml_q(e, r, q_up, self.static)
        return r, max(q_ml, q_up)

    # -- the chain ------------------------------------------------------------
    def analyse(self, model: NoiseModel | None = None) -> Analysis:
        """Calibrate ``model`` (default: this comparison's) and run every test."""
        model = self.model if model is None else self._with_baseline(model)
        notes = []
        # a burst in the model: its window's noise level is not the static part's
        # r, so the regressions (weighted by r) leave it out
        self._det_use = None
        burst = next((e for e in model if e.effect == "burst"), None)
        in_burst = None
        if burst is not None:
            in_burst = (self.t >= float(burst.params["start_s"])) & (self.t < float(burst.params["end_s"]))
            if in_burst.any() and not in_burst.all():
                self._det_use = ~in_burst
                notes.append(f"deterministic fits leave out the burst window "
                             f"({float(burst.params['start_s']):.0f}–{float(burst.params['end_s']):.0f} s)")
        in_model = {(e.effect, e.gyro) for e in model}
        fits: dict = {}

        # 1. r, q on the longest static part (deterministic model not yet known: iterate)
        det_entries = [e for e in model if e.effect in _DETERMINISTIC]
        preds = {(e.effect, e.gyro): np.zeros((self.n, self.N)) for e in det_entries}
        r = np.zeros(self.N)
        q = np.zeros(self.N)
        a, b = self.longest
        for it in range(2):
            E = self.E0 - sum(preds.values(), np.zeros((self.n, self.N)))
            for g in range(self.N):
                r[g], q[g] = self._noise_rq(E[:, g], g + 1)
            if not det_entries:
                break
            # 2. deterministic effects of the model, backfitted
            for e in det_entries:
                key = (e.effect, e.gyro)
                others = sum((p for k, p in preds.items() if k != key), np.zeros((self.n, self.N)))
                f = self._fit_det(e.effect, e.gyro, self.E0 - others, r, q)
                fits[key] = f
                entry = self._entry_from_fit(f, e)
                preds[key] = self._prediction(entry)
        E = self.E0 - sum(preds.values(), np.zeros((self.n, self.N)))

        tests: list[Test] = []
        # 3. deterministic candidates
        for effect in ("scale_factor", "scale_nonlinearity", "misalignment", "latency", "saturation",
                       "temperature_bias"):
            why = self._available(effect)
            if why:
                notes.append(f"{effect}: not tested, {why}")
                continue
            for g in range(1, self.N + 1):
                if (effect, g) in in_model:
                    continue
                f = self._fit_det(effect, g, E, r, q)
                tests.append(self._effect_test(f))
        why = self._available("earth_rate")
        if why:
            notes.append(f"earth_rate: not tested, {why}")
        elif ("earth_rate", None) not in in_model:
            f = self._fit_det("earth_rate", None, E, r, q)
            f = self._deflate_for_correlation(f, model)
            if f.extra.get("identifiable", True):
                tests.append(self._effect_test(f))
            else:
                notes.append("earth_rate: not identifiable (the attitude changes too little)")

        # 4. the record of the stochastic tests: static if a deterministic
        # test already exceeds the critical value of the whole family (the
        # tests to come counted: 4 noise terms and a sinusoid per gyro where
        # not in the model, correlation, burst, one ADEV band per gyro)
        n_stoch = self.N + sum((eff, g) not in in_model for g in range(1, self.N + 1)
                               for eff in _PER_GYRO_NOISE + ("sinusoid",))
        n_stoch += int(self.N >= 2 and ("correlation", None) not in in_model)
        n_stoch += int(burst is None)
        det_z = [t.z for t in tests if np.isfinite(t.z)]
        det_sig = max(det_z, default=-math.inf) > critical_z(len(det_z) + n_stoch, self.alpha)
        clipped = any(e.effect == "saturation" for e in model)
        quantized = any(e.effect == "quantization" for e in model)
        if det_sig or clipped or quantized:
            rec = slice(a, b)
            why = ("a deterministic effect is unexplained" if det_sig else
                   "the model clips the output (no noise on the plateau)" if clipped else
                   "the model quantizes the output angle (its noise depends on the rate)")
            notes.append(f"stochastic tests on the longest static part ({a * self.dt + self.t[0]:.0f}–"
                         f"{b * self.dt + self.t[0]:.0f} s): {why}")
        else:
            rec = slice(0, self.n)
        Er = E[rec].copy()
        tr = self.t[rec]
        if burst is not None:
            inside = in_burst[rec]
            if inside.any():   # the white part inside the window back to the level outside
                level = Er[inside].mean(axis=0)
                Er[inside] = level + (Er[inside] - level) / math.sqrt(
                    max(float(burst.params["variance_ratio"]), 1e-12))

        # 5. per-gyro noise: baseline and stochastic candidates / model terms
        for g in range(1, self.N + 1):
            terms = tuple(t for eff, t in (("bias_instability", "b"), ("quantization", "q"))
                          if (eff, g) in in_model)
            gm_entry = next((e for e in model if (e.effect, e.gyro) == ("gauss_markov", g)), None)
            fl = {f.effect: f for f in fit_gyro_noise(
                Er[:, g - 1], self.dt, g, model_terms=terms,
                gm_tau_s=None if gm_entry is None else float(gm_entry.params["tau_s"]))}
            fits[("arw", g)], fits[("rrw", g)] = fl["arw"], fl["rrw"]
            for eff in _PER_GYRO_NOISE:
                if eff == "rate_ramp" and ("rate_ramp", g) in in_model:
                    continue
                if (eff, g) in in_model:
                    fits[(eff, g)] = fl[eff]
                else:
                    tests.append(self._effect_test(fl[eff]))
            if ("sinusoid", g) not in in_model:
                qf = fits.get(("quantization", g))
                q_ang = 0.0 if qf is None else float(qf.params["q_deg"]) * RAD_PER_DEG
                tests.append(self._effect_test(fit_sinusoid(Er[:, g - 1], tr, self.dt, r[g - 1],
                                                            q[g - 1], g, q_angle_rad=q_ang)))

        # 6. array-wide: correlation, burst
        if self.N >= 2:
            cf = fit_correlation(Er, self.dt)
            merged = self._merge_correlation(cf)
            if ("correlation", None) in in_model:
                fits[("correlation", None)] = merged
            else:
                tests.append(self._effect_test(merged))
        else:
            notes.append("correlation: not tested, needs at least 2 gyros")
        # the burst on the whole record unless the model clips the output (no
        # noise on a plateau): it reads sample-to-sample differences, which a
        # slow deterministic residual barely touches, and a burst may run on
        # into the dynamic part
        Eb, tb = (E[rec], tr) if clipped else (E, self.t)
        if burst is not None:
            fits[("burst", None)] = fit_burst(Eb, tb, self.dt)
        else:
            tests.append(self._effect_test(fit_burst(Eb, tb, self.dt)))

        # 7. the calibrated model
        new_entries = []
        for e in model:
            f = fits.get((e.effect, e.gyro))
            new_entries.append(e if f is None else self._entry_from_fit(f, e))
        cal = NoiseModel(tuple(new_entries), description=model.description)

        # 8. ADEV band of the calibrated stochastic part
        adev, band_tests = self._adev_band(cal, E, rec)
        tests += band_tests

        cands = sorted((t for t in tests if t.kind == "effect"),
                       key=lambda t: -t.z if np.isfinite(t.z) else math.inf)
        finite = [t.z for t in tests if np.isfinite(t.z)]
        zc = critical_z(len(finite), self.alpha)
        cands = self._rank_drifts(cands, zc, E, r, q)
        cands = _rank_rivals(cands, zc, _NOISE_TERMS, "ADEV")
        cands = _rank_scale_terms(_rank_rivals(cands, zc, _AXIS_TERMS, "residual"), zc)
        worst = max(finite, default=0.0)
        disc = max(worst, 0.0) / zc
        if self.ref is None and self.parts:
            span = self.parts_s[-1][1] - self.parts_s[0][0]
            whole = self.m.time_s[-1] - self.m.time_s[0] + self.dt
            lengths = [(b - a) * self.dt for a, b in self.parts]
            notes.append(f"no reference rate: the outputs show motion, so only their {len(self.parts)} still "
                         f"parts ({self.n * self.dt:.0f} s of the {whole:.0f} s record, {min(lengths):.0f}–"
                         f"{max(lengths):.0f} s each, over {span:.0f} s) are "
                         f"diagnosed, stitched with each part's mean set to the first's: times are on the "
                         f"stitched record, τ beyond a part's length and the drift between parts are not seen; "
                         + ", ".join(_NEEDS_REF) + " need ref_x, ref_y, ref_z")
        elif self.ref is None:
            notes.append("no reference rate: the outputs show no motion, the record is taken as static; "
                         + ", ".join(_NEEDS_REF) + " need ref_x, ref_y, ref_z")
        return Analysis(model=cal, fits=fits, tests=tests, candidates=cands, discrepancy=float(disc),
                        z_crit=zc, residual_rad_s=E, raw_residual_rad_s=self.E0, record=rec,
                        static=self.static, adev=adev, notes=notes, r=r, q=q)

    # -- helpers ----------------------------------------------------------------
    def _rank_drifts(self, cands: list, z_crit: float, E, r, q) -> list:
        """A temperature slope against a rate ramp on one gyro: the better fit first.

        A warm-up temperature and time are nearly collinear over a record, so
        both candidates are significant when either drift is there, and their
        own z's come from different tests (a regression with q re-estimated,
        a time-domain likelihood ratio). Both are fitted again as regressions
        under the same noise (r, q) and the smaller χ² ranks first (one
        parameter each). On lab runs with a true 300 deg/h² ramp (seeds 7–12)
        the ramp's χ² was 1.9–3.0 lower every time, while the temperature's
        z was the larger in 5 of 6.
        """
        out = list(cands)
        pos = {(t.effect, t.gyro): i for i, t in enumerate(out)}
        for (eff, g), i in pos.items():
            j = pos.get(("rate_ramp", g))
            if eff != "temperature_bias" or j is None:
                continue
            if not (out[i].z > z_crit and out[j].z > z_crit):
                continue
            chi = {"temperature_bias": self._fit_det_once("temperature_bias", g, E, r, q).extra["chi2"],
                   "rate_ramp": self._fit_det_once("rate_ramp", g, E, r, q).extra["chi2"]}
            best, other = (j, i) if chi["rate_ramp"] < chi["temperature_bias"] else (i, j)
            b, o = out[best].effect, out[other].effect
            _prefer(out, best, [i, j], lambda _: f"; but {b.replace('_', ' ')} fits this drift better under "
                                                 f"the same noise (χ² {chi[b]:.1f} against {chi[o]:.1f}; "
                                                 f"the two are nearly collinear on this record)")
        return out

    def _deflate_for_correlation(self, f: EffectFit, model: NoiseModel) -> EffectFit:
        """An array-wide fit under correlated noise: its z over √(1 + (N − 1)ρ).

        The Earth-rate fit weighs the gyros as independent; with a common
        noise correlation ρ > 0 in the model the variance of a combination
        of the gyros grows by at most 1 + (N − 1)ρ (all weights of one
        sign), so the z is deflated by its root (conservative: a scoring
        run with ρ_arw = 0.16 on 5 gyros gave a false z of 4.3 without it).
        """
        corr = next((e for e in model if e.effect == "correlation"), None)
        if corr is None or not np.isfinite(f.z):
            return f
        rho = 0.0
        for key in ("rho_arw", "rho_rrw"):
            v = np.asarray(corr.params.get(key, 0.0), float)
            if v.ndim == 2:
                v = v[~np.eye(v.shape[0], dtype=bool)].mean() if v.shape[0] > 1 else np.float64(0.0)
            rho = max(rho, float(v))
        factor = math.sqrt(1.0 + (self.N - 1) * max(rho, 0.0))
        return replace(f, z=float(f.z) / factor, extra={**f.extra, "z_independent": float(f.z),
                                                        "correlation_deflation": factor})

    @staticmethod
    def _effect_test(f: EffectFit) -> Test:
        z = float(f.z) if f.z is not None else math.nan
        if not f.extra.get("identifiable", True):
            z = math.nan
        return Test("effect", f.effect, f.gyro, z, f.evidence, fit=f)

    @staticmethod
    def _merge_correlation(cf: list[EffectFit]) -> EffectFit:
        by = {next(iter(f.params)): f for f in cf}
        fa, fr = by.get("rho_arw"), by.get("rho_rrw")
        zs = [f.z for f in cf if f.z is not None and np.isfinite(f.z)]
        # two tests in one candidate: the larger z, Šidák-corrected for 2
        zmax = max(zs, default=math.nan)
        if np.isfinite(zmax):
            p = 1.0 - (1.0 - float(special.ndtr(-zmax))) ** len(zs)
            z = float(-special.ndtri(min(max(p, 1e-300), 1.0)))
        else:
            z = math.nan
        params = {"rho_arw": float(fa.params["rho_arw"]) if fa else 0.0,
                  "rho_rrw": float(fr.params["rho_rrw"]) if fr else 0.0}
        sigma = {}
        for f in cf:
            sigma.update(f.sigma)
        best = max(cf, key=lambda f: f.z if f.z is not None and np.isfinite(f.z) else -math.inf)
        return EffectFit("correlation", None, params, sigma, z, best.evidence,
                         extra={"rho_arw_fit": fa.extra if fa else None,
                                "rho_rrw_fit": fr.extra if fr else None})

    def _entry_from_fit(self, f: EffectFit, old: ModelEntry) -> ModelEntry:
        """A model entry with the fitted parameters (keeping what the fit does not set)."""
        params = dict(old.params)
        eff = get_effect(old.effect)
        for k, v in f.params.items():
            if k in eff.param_names and v is not None and np.isfinite(v):
                params[k] = float(v)
        if old.effect == "misalignment":
            params.pop("axis", None)
        if old.effect == "gauss_markov" and params.get("sigma_deg_h", 0.0) <= 0:
            params["sigma_deg_h"] = 0.0
        try:
            return ModelEntry(old.effect, old.gyro, _clip_params(old.effect, params, self.N))
        except InputError:
            return old

    def entry_for(self, effect: str, gyro: int | None, analysis: Analysis) -> ModelEntry:
        """The model entry of a candidate, with the parameters of its fit in ``analysis``."""
        t = next((t for t in analysis.candidates if (t.effect, t.gyro) == (effect, gyro)), None)
        eff = get_effect(effect)
        if t is not None and t.fit is not None:
            f = t.fit
        elif effect == "constant_bias":     # never a candidate, fitted on request
            f = self._fit_det(effect, gyro, analysis.residual_rad_s, analysis.r, analysis.q)
        else:
            why = self._available(effect)
            if why:
                raise InputError(f"cannot add {effect}: it {why}", file=self.name)
            raise InputError(f"cannot add {effect}" + (f":{gyro}" if gyro else "")
                             + ": it is already in the model", file=self.name)
        params = {}
        for p in eff.params:
            if p.name in f.params and f.params[p.name] is not None and np.isfinite(f.params[p.name]):
                params[p.name] = float(f.params[p.name])
        params = _clip_params(effect, params, self.N)
        return ModelEntry(effect, gyro, params)

    def _adev_band(self, cal: NoiseModel, E: np.ndarray, rec: slice):
        """Measured ADEV vs the model's Monte-Carlo band, one test per gyro."""
        x = E[rec]
        n = x.shape[0]
        m = averaging_factors(n + 1, self.dt)
        m = m[m <= n // 10]
        # quantization as the spec defines it (σ² = 3Q²/τ², what its fit measures):
        # white angle noise of standard deviation Q, differenced. The simulator's
        # angle counter is that only when the angle crosses many steps between
        # samples; a quantizer the noise barely dithers is a different process
        # (its ADEV is not 3Q²/τ²), which the band should not assume.
        quant = [(e.gyro - 1, float(e.params["q_deg"]) * RAD_PER_DEG) for e in cal
                 if e.effect == "quantization"]
        sub = NoiseModel(tuple(e for e in cal if e.effect in _STOCHASTIC_SIM and e.effect != "quantization"))
        taus = m * self.dt
        meas = np.array([oadev(x[:, g], self.dt, taus=taus).dev for g in range(self.N)])
        tr = self.t_sim[rec]
        # the measurement's own reference rates (quantization sees them); noise = output − H·ref
        truth = self.ref[rec] if self.ref is not None else np.zeros((n, 3))
        sensed = truth @ self.H.T
        mc = np.empty((self.n_runs, self.N, taus.size))
        for k in range(self.n_runs):
            rng = np.random.default_rng([self.seed, k])
            s = simulate_readings(sub, truth, self.H, self.dt, rng, time_s=tr) - sensed
            for g, q_rad in quant:
                s[:, g] += np.diff(rng.normal(0.0, q_rad, n + 1)) / self.dt
            if rec == slice(0, self.n):
                s = self._like_parts(s)
            for g in range(self.N):
                mc[k, g] = oadev(s[:, g], self.dt, taus=taus).dev
        tests = []
        M = self.n_runs
        L = np.log(mc)
        mu = L.mean(axis=0)
        sd = L.std(axis=0, ddof=1) * math.sqrt(1.0 + 1.0 / M)
        tq = stats.t.ppf(0.975, M - 1)
        for g in range(self.N):
            tk = (np.log(meas[g]) - mu[g]) / sd[g]
            p = 2.0 * stats.t.sf(np.abs(tk), M - 1)
            pmin = float(np.min(p))
            pg = -math.expm1(taus.size * math.log1p(-min(pmin, 1 - 1e-16)))
            z = float(-special.ndtri(max(pg, 1e-300)))
            out = np.abs(tk) > tq
            above = tk > tq
            below = tk < -tq
            if np.any(out):
                sel = above if above.sum() >= below.sum() else below
                i = np.flatnonzero(sel)
                word = "above" if sel is above else "below"
                ev = (f"gyro {g + 1} ADEV {word} the model's 95 % band for τ in "
                      f"{taus[i[0]]:.3g}–{taus[i[-1]]:.3g} s ({rad_s_to_deg_h(meas[g, i[0]]):.3g} deg/h "
                      f"at τ = {taus[i[0]]:.3g} s against {rad_s_to_deg_h(math.exp(mu[g, i[0]])):.3g})")
            else:
                ev = f"gyro {g + 1} ADEV within the model's 95 % band at every τ"
            tests.append(Test("adev_band", None, g + 1, z, ev,
                              extra={"t": tk.tolist(), "p_min": pmin}))
        band = {"taus_s": taus, "measured": meas, "mc": mc,
                "lo": np.exp(mu - tq * sd), "hi": np.exp(mu + tq * sd), "median": np.exp(mu)}
        return band, tests

    # -- the user's loop ------------------------------------------------------
    def diagnose(self) -> Analysis:
        return self.analyse()

    def steps_to_model(self) -> list[tuple[tuple | None, Analysis]]:
        """The error falling from the baseline to this comparison's model, one effect at a time.

        ``[(None, baseline), ((effect, gyro), baseline + the effects so far), ...]``
        in the model's order (what ``compare --model`` reports); just
        ``[(None, analysis)]`` when the model is the baseline.
        """
        extra = [e for e in self.model if e.effect not in ("arw", "rrw")]
        model = NoiseModel(tuple(e for e in self.model if e.effect in ("arw", "rrw")),
                           description=self.model.description, source=self.model.source)
        steps = [(None, self.analyse(model))]
        for e in extra:
            model = model.with_effect(e)
            steps.append(((e.effect, e.gyro), self.analyse(model)))
        return steps

    def fit(self, add=()) -> tuple[Analysis, Analysis]:
        """(before, after): the model calibrated, then with the ``add`` effects fitted in."""
        before = self.analyse()
        model = self.model
        for effect, gyro in add:
            if (effect, gyro) in {(e.effect, e.gyro) for e in model}:
                continue
            model = model.with_effect(self.entry_for(effect, gyro, before))
        after = self.analyse(model) if model is not self.model else before
        return before, after

    def ladder(self, max_steps: int = 8, max_tries: int = 3) -> list[tuple[tuple | None, Analysis]]:
        """[(added (effect, gyro) or None, analysis), ...]: add the best significant candidate until consistent.

        A step is kept only if it explains something without making the
        headline worse: the excess (Σ (z − z_crit)² of the significant tests)
        falls and D does not rise beyond the Monte-Carlo scatter of the band
        (``LADDER_D_SLACK``; D itself may stay put when its worst test is
        one the step does not touch). Otherwise the next significant
        candidate is tried (at most ``max_tries`` per step), and the
        refusals are noted in the last analysis's ``notes``.
        """
        steps = [(None, self.analyse())]
        model = self.model
        refused = []
        for _ in range(max_steps):
            cur = steps[-1][1]
            if cur.consistent:
                break
            taken = None
            for t in [t for t in cur.candidates if cur.significant(t)][:max_tries]:
                trial = self.analyse(model.with_effect(self.entry_for(t.effect, t.gyro, cur)))
                if (trial.excess < cur.excess
                        and trial.discrepancy <= cur.discrepancy * (1.0 + LADDER_D_SLACK)):
                    taken = ((t.effect, t.gyro), trial)
                    break
                refused.append(f"the ladder did not add {t.effect}"
                               + ("" if t.gyro is None else f" on gyro {t.gyro}")
                               + f": the discrepancy would go from {cur.discrepancy:.2f} to "
                                 f"{trial.discrepancy:.2f}")
            if taken is None:
                break
            steps.append(taken)
            model = taken[1].model
        if refused:
            steps[-1][1].notes.extend(refused)
        return steps


#: Rival explanations of one gyro's excess, with their free parameters (for the AIC): noise
#: terms of the ADEV, and the scale factor against a tilt of the axis (on a motion that turns
#: the gyro mostly about its own axis their regressors are nearly collinear).
_NOISE_TERMS = {"bias_instability": 1, "quantization": 1, "gauss_markov": 2}
_AXIS_TERMS = {"scale_factor": 1, "misalignment": 2}


def _rank_rivals(cands: list, z_crit: float, terms: dict, what: str) -> list:
    """Order rivals for the same excess on one gyro by how well they fit it, not by z.

    Noise terms: a bias instability and a Gauss–Markov hump (or quantization)
    on one gyro are both significant when either is present: each column
    soaks up part of the other's excess, and the two-parameter Gauss–Markov
    often scores the higher z. Axis terms: a scale factor and a tilt both
    follow the rate when the motion turns a gyro mostly about its own axis.
    Among the significant rivals of a gyro the one with the smallest AIC of
    its own fit, χ² + 2·(free parameters), takes the place of the first of
    them; the others keep their z and say why they rank lower. (On the
    scoring runs of benchmarks/diagnosis_score.py: true B gave χ² 9–13
    against 26–42 for the hump; a true hump 4–10 against 59–158 for the
    flat term, on 11 dof.)
    """
    out = list(cands)

    def k(t):       # free parameters; a tilt seen in one direction only has one
        return int(t.fit.extra.get("dof_c", terms[t.effect])) if t.effect == "misalignment" else terms[t.effect]
    for g in {t.gyro for t in out if t.effect in terms}:
        idx = [i for i, t in enumerate(out) if t.gyro == g and t.effect in terms
               and np.isfinite(t.z) and t.z > z_crit and t.fit is not None and "chi2" in t.fit.extra]
        if len(idx) < 2:
            continue
        aic = {i: float(out[i].fit.extra["chi2"]) + 2.0 * k(out[i]) for i in idx}
        best = min(idx, key=aic.get)
        name = out[best].effect.replace("_", " ")
        _prefer(out, best, idx, lambda i: f"; but {name} fits this {what} better "
                                          f"(AIC {aic[best]:.1f} against {aic[i]:.1f})")
    return out


def _prefer(out: list, best: int, idx: list, why) -> None:
    """out[best] takes the place of the first of out[idx]; each other one's evidence gets ``why(i)``."""
    for i in idx:
        if i != best:
            out[i] = replace(out[i], evidence=out[i].evidence + why(i))
    order = [out[best]] + [out[i] for i in idx if i != best]
    for i, t in zip(sorted(idx), order):
        out[i] = t


def _rank_scale_terms(cands: list, z_crit: float) -> list:
    """A curvature seen as a scale factor: the nonlinearity first when it explains the slope.

    On a record whose rates are mostly of one sign, k2·u² has a large linear
    part, so the scale factor's own z can exceed the nonlinearity's (which
    is tested *given* a scale factor). When the nonlinearity is significant
    and the scale factor, fitted jointly with it, is not, the curvature
    alone explains the residual: it ranks first.
    """
    out = list(cands)
    pos = {(t.effect, t.gyro): i for i, t in enumerate(out)}
    for (eff, g), i in pos.items():
        j = pos.get(("scale_factor", g))
        if eff != "scale_nonlinearity" or j is None or j > i:
            continue
        nl, sf = out[i], out[j]
        zj = nl.fit.extra.get("ppm_joint_z", math.inf) if nl.fit is not None else math.inf
        if nl.z > z_crit and sf.z > z_crit and zj < z_crit:
            _prefer(out, i, [j, i], lambda _: f"; but with the curvature fitted the scale factor is "
                                              f"{nl.fit.extra['ppm_joint']:.0f} ppm (z = {zj:.1f}): "
                                              f"the nonlinearity explains it")
    return out


def _placeholder(effect: str, comp) -> dict:
    """Valid parameters to build an entry that a fit then overwrites."""
    return {"temperature_bias": {"deg_h_per_c": 0.0, "t0_c": 25.0},
            "earth_rate": {"latitude_deg": 0.0},
            "rate_ramp": {"r_deg_h2": 0.0}}[effect]


def _ml_q(e: np.ndarray, r: float, q0: float, use: np.ndarray) -> float:
    """Maximum-likelihood random-walk increment variance q of ``e`` on the ``use`` samples, r fixed."""
    def nll(lq):
        w = _RWWhitener(e.size, r, math.exp(lq), use)
        z = w.whiten(e)
        return 0.5 * (w.logdet + float(z @ z))
    lo, hi = math.log(1e-12 * r), math.log(r) + 3.0
    res = optimize.minimize_scalar(nll, bounds=(lo, hi), method="bounded", options={"xatol": 0.05})
    return float(math.exp(res.x))


def _clip_params(effect: str, params: dict, n_gyros: int | None = None) -> dict:
    """Keep fitted parameters inside the spec's bounds (a fit may land on the edge)."""
    eff = get_effect(effect)
    out = {}
    for p in eff.params:
        if p.name not in params:
            continue
        v = params[p.name]
        if p.kind == "scalar" and isinstance(v, (int, float)) and not isinstance(v, bool):
            # open bounds: a hair inside
            lo = p.lo + (max(abs(p.lo), 1.0) * 1e-9 if p.lo_open else 0.0)
            hi = p.hi - (max(abs(p.hi), 1.0) * 1e-9 if p.hi_open else 0.0)
            v = float(min(max(v, lo), hi))
        out[p.name] = v
    if effect == "correlation" and n_gyros:
        lo = -1.0 / (n_gyros - 1) + 1e-6
        for k in ("rho_arw", "rho_rrw"):
            if k in out:
                out[k] = float(np.clip(out[k], lo, 0.999))
    if effect == "burst":
        if "variance_ratio" in out:
            out["variance_ratio"] = max(out["variance_ratio"], 1e-6)
    return out
