"""Model vs measurement: calibrate a noise model to a recorded run, find where it fails.

The chain (after pvlib's ModelChain: one object, named steps, every
intermediate kept in the :class:`Analysis` a report can show). It never names
an effect: it loops over the registry (:mod:`gyroarray.effects`), and each
effect says what it needs, how it is fitted and how it enters the model
(:mod:`gyroarray.effects.protocol`).

1. **residual** ``E = gyro − H·ref`` [rad/s] of every gyro (``H`` the
   layout's axes, ``ref`` the table's reference rate; without a reference
   ``E`` is the output itself, and if the outputs show the array turning
   (:func:`gyroarray.analysis.motion.still_mask`) only their still parts,
   stitched, are diagnosed);
2. **calibrate** (:meth:`ModelComparison.calibrate`): the ARW/RRW variances
   ``r``, ``q`` on the longest static part, and the model's effects that
   predict a deterministic part backfitted under that noise (two passes);
3. **deterministic candidates**: every effect not in the model whose test
   reads the residual, on every gyro it can act on; each has a significance
   ``z`` (≈ N(0, 1) when the effect is absent, large positive when present);
4. **stochastic record**: the whole run when no deterministic test is
   significant (a dynamic part the model explains adds information), else the
   longest static part (an unexplained scale factor would otherwise read as
   noise); also the static part when the model's noise depends on the motion
   (an effect's ``static_noise``); brought back to the model's stationary
   level (:meth:`~gyroarray.effects.protocol.Effect.whiten`);
5. **noise**: each gyro's Allan fit with the model's noise terms, and the
   candidates that read the stochastic record;
6. **model band**: the calibrated stochastic part of the model simulated
   ``n_runs`` times over the same record (:func:`gyroarray.sim.effects.simulate_readings`,
   the record's own clock), its ADEV per gyro against the measured one; a
   per-gyro z says whether the measured ADEV leaves the band at any τ;
7. **rank**: candidates by z, rivals (effects that explain the same excess on
   one gyro, ``Effect.rivals``) by how well they fit it (``Effect.prefer``);
   the **discrepancy** is the largest z of all the tests over the critical
   value that keeps the family-wise false-alarm rate at ``alpha`` (1 %):

       D = max_k z_k / z_crit(K),   z_crit(K) = Φ⁻¹((1 − alpha)^(1/K))

   (Šidák, K tests; an effect of the model that would otherwise be a
   candidate counts as a test it passed, so fitting a candidate in does not
   shrink the family and raise D by itself). D <= 1: no test, candidate effect or ADEV band, says
   the model is wrong (``consistent``); D = 3 means the worst test is three
   times as far out as a 1 % family-wise alarm. A candidate is
   ``significant`` when its z exceeds z_crit.

Units: SI inside; spec units only in ``EffectFit.params`` and the model.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import optimize, special, stats

from gyroarray.analysis.memo import by_content, clear_all, content_key
from gyroarray.analysis.allan import averaging_factors, oadev
from gyroarray.effects.earth_rate import attitude_across_gaps, attitude_from_rates
from gyroarray.effects.fitting import EffectFit, chi2_to_z, z_from_log_p
from gyroarray.chain.localise import Localisation, plain_json, default_nperseg, residual_psd
from gyroarray.chain.localise import localise as localise_residual
from gyroarray.analysis.motion import still_mask
from gyroarray.analysis.deviations import MIN_CUT_PART, contiguous_segments, cut_at_segments
from gyroarray.analysis.pipeline import PipelineReport, detect_pipeline, held_samples, passband_change
from gyroarray.effects.outliers import MOTION_RAW, Outliers, clean_spikes
from gyroarray.analysis.reference_noise import describe as describe_own_noise
from gyroarray.analysis.reference_noise import reference_own_noise
from gyroarray.analysis.gls import RWWhitener
from gyroarray.analysis.white_level import pooled_white_level, white_walk_fit
from gyroarray.effects.stochastic import fit_gyro_noise
from gyroarray.effects import REGISTRY, did_you_mean, effect_names, get_effect
from gyroarray.effects import names
from gyroarray.core.errors import InputError
from gyroarray.core.limits import check_memory, format_size, max_memory
from gyroarray.core.measurement import Measurement, relative_time_s, true_runs
from gyroarray.core.parallel import available_cpus, map_runs
from gyroarray.sim.effects import sim_context, simulate_on, simulate_readings
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.protocol import Effect, Explained, FitContext, Kind, drop_kept
from gyroarray.core.sensor import gravity_specific_force, rigid_body_specific_force
from gyroarray.core.units import (RAD_PER_DEG, arw_deg_rt_h_to_rad_rt_s, arw_rad_rt_s_to_deg_rt_h, rad_s_to_deg_h,
                                  rrw_deg_h_rt_h_to_rad_s_rt_s)

__all__ = ["ALPHA", "LADDER_BEST_TIE", "LADDER_RULE", "LADDER_RETRY_SHARE", "Test", "Analysis",
           "ModelComparison", "baseline_model", "best_step", "holdout_candidates", "check_record_needs", "critical_z", "ladder_improves", "parse_add",
           "parse_add_all", "record_lacks",
           "split_measurement"]

#: Family-wise false-alarm rate of the discrepancy.
ALPHA = 0.01

#: Samples (record × gyros × runs) from which the Monte-Carlo band runs on every CPU.
_PARALLEL_MIN_SAMPLES = 20_000_000

#: A sample is static when every reference component is within this [rad/s] (0.01 deg/s).
STATIC_RAD_S = 0.01 * RAD_PER_DEG

#: Shortest static part that calibrates the noise [samples] (6 octaves up to n/8 and more).
MIN_STATIC = 2048

#: Shortest still part kept when a record without reference is stitched [samples].
MIN_STILL_PART = 256

#: Monte-Carlo runs of the model band.
N_RUNS = 40


def critical_z(n_tests: int, alpha: float = ALPHA) -> float:
    """One-sided normal critical value of ``n_tests`` tests at family-wise ``alpha`` (Šidák)."""
    k = max(int(n_tests), 1)
    # 1 − (1 − alpha)^(1/k), accurately for large k
    p = -math.expm1(math.log1p(-alpha) / k)
    return float(-special.ndtri(p))


def _baseline_effects() -> list[Effect]:
    return [e for e in REGISTRY.values() if e.baseline]


def baseline_model(n_gyros: int) -> NoiseModel:
    """The baseline effects (ARW + RRW) on every gyro; their values are placeholders that calibration refits."""
    entries = [ModelEntry(eff.name, g, eff.placeholder())
               for g in range(1, n_gyros + 1) for eff in _baseline_effects()]
    names = " + ".join(e.name.upper() for e in _baseline_effects())
    return NoiseModel(tuple(entries), description=f"baseline: {names} on every gyro")


def parse_add(text: str, n_gyros: int) -> tuple[str, int | None]:
    """``EFFECT[:GYRO]`` of ``--add`` -> (effect, gyro or None); InputError when wrong.

    One entry: an effect that acts on one gyro at a time needs its gyro here;
    :func:`parse_add_all` reads ``EFFECT`` and ``EFFECT:all`` of such an effect
    as every gyro (what ``fit --add`` takes).
    """
    name, _, g = str(text).partition(":")
    name = name.strip()
    eff = REGISTRY.get(name)
    if eff is None:
        raise InputError(f"--add {text}: unknown effect {name!r}{did_you_mean(name, effect_names())} "
                         f"(effects: {', '.join(effect_names())})")
    if not g:
        if eff.per_gyro:
            raise InputError(f"--add {text}: {name} acts on one gyro at a time; say which, e.g. "
                             f"{name}:1 (gyros 1..{n_gyros}), or {name}:all for every gyro")
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


def parse_add_all(text: str, n_gyros: int) -> tuple[list[tuple[str, int | None]], str | None]:
    """``EFFECT[:GYRO]`` or ``EFFECT:all`` of ``fit --add`` -> ([(effect, gyro or None), ...], note).

    An effect that acts on one gyro at a time (``Effect.per_gyro``), given
    without a gyro or with ``:all``, is added to every gyro 1..``n_gyros``
    (one entry, fitted on its own, per gyro), and the note says so; anything
    else is :func:`parse_add`'s one entry and no note. InputError when wrong
    (``:all`` of an array-wide effect included).
    """
    name, sep, g = str(text).partition(":")
    name = name.strip()
    eff = REGISTRY.get(name)
    every = eff is not None and eff.per_gyro and (not sep or g.strip().lower() == "all")
    if not every:
        if eff is not None and not eff.per_gyro and g.strip().lower() == "all":
            raise InputError(f"--add {text}: {name} acts on the whole array; write just {name}")
        return [parse_add(text, n_gyros)], None
    adds: list[tuple[str, int | None]] = [(name, k) for k in range(1, n_gyros + 1)]
    note = (f"--add {text}: {name} acts on one gyro at a time; added to every gyro "
            f"(1..{n_gyros}), each fitted on its own (say {name}:K for one gyro)")
    return adds, note


#: What each record need of :data:`~gyroarray.effects.protocol.RECORD_NEEDS` is, in the words of
#: the measurement format (what to add to the record).
_RECORD_DATA = {
    "ref": "the reference rate (columns ref_x, ref_y, ref_z)",
    "temp": "the temperature (column temp_c)",
    "site": "the site (a [site] table with latitude_deg and heading_deg in the sidecar)",
    "acc": "the specific force (columns acc_x, acc_y, acc_z) or the reference rate",
    "positions": "the gyro positions (positions_m in the sidecar's [layout])",
}


def record_lacks(measurement: Measurement, need: str) -> str | None:
    """What ``measurement`` lacks of the record data ``need`` (``Effect.model_needs``), or None."""
    m = measurement
    missing = {"ref": m.ref_rad_s is None, "temp": m.temp_c is None, "site": m.site is None,
               "acc": m.acc_m_s2 is None and m.ref_rad_s is None,
               "positions": getattr(m.layout, "positions_m", None) is None}.get(need, False)
    return _RECORD_DATA[need] if missing else None


def check_record_needs(model: NoiseModel | None, measurement: Measurement, *, fixed: bool = False) -> None:
    """Refuse, before any work, a model that the record cannot carry.

    Every entry's effect declares the record data it needs
    (:attr:`~gyroarray.effects.protocol.Effect.model_needs`, or
    ``predict_needs`` when the parameters are kept ``fixed``, a validation)
    and the rules its parameters must meet on this record's sample step and
    span (:meth:`~gyroarray.effects.protocol.Effect.check_record`: a cut-off
    below Nyquist).

    Raises
    ------
    InputError
        Naming the model file, the entry's line and ``effects[i]``, the effect
        and gyro, the missing data (or the key) and the way out.
    """
    if model is None:
        return
    record = measurement.source or "the measurement"
    dt = float(measurement.dt_s)
    span = float(relative_time_s(measurement)[-1]) + dt if len(measurement.time_s) else 0.0
    for i, e in enumerate(model):
        eff = get_effect(e.effect)
        for need in sorted(eff.predict_needs if fixed else eff.model_needs):
            what = record_lacks(measurement, need)
            if what is None:
                continue
            way = "add it to the record or remove the entry from the model"
            if need in eff.model_needs and need not in eff.predict_needs:
                way += (" (with --validate its parameters stay fixed and the record without it is "
                        "analysed as static)")
            raise model.located(i, InputError(f"{e.label} needs {what}, which {record} lacks: {way}"))
        try:
            eff.check_record(e.params, dt, span)
        except InputError as err:
            raise model.located(i, InputError(f"{e.label} on {record}: {err.message}",
                                              column=err.column)) from None


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
    #: (effect, gyro) of a higher-ranked rival that explains this candidate away: with the
    #: rival's fit taken out of the record its test is no longer significant.
    explained_by: tuple | None = None


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
        The effect tests, best (largest z, rivals by fit) first.
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
    r, q : ndarray (N,)
        White and random-walk increment variances per sample [rad²/s²].
    context : FitContext
        What the fit sides read in this analysis.
    localisation : list of dict
        Where the model fails (:meth:`ModelComparison.localise`), ranked: each
        finding's ``kind``, ``gyros``, ``score`` (standard errors of its own
        statistic), ``sentence`` and ``details`` (numbers, unit in each key:
        ``_hz``, ``_s``, ``_rad_s``); empty when the model is consistent or
        nothing is localised.
    localised : Localisation or None
        The whole localisation (spectra, correlations) for the report's figures.
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
    context: FitContext | None = None
    localisation: list = field(default_factory=list)
    localised: Localisation | None = None
    #: The record's data pipeline (:meth:`PipelineReport.to_json_dict`) when one is seen, else None.
    pipeline: dict | None = None

    @property
    def consistent(self) -> bool:
        return bool(self.discrepancy <= 1.0)

    @property
    def excess(self) -> float:
        """Σ (z − z_crit)² over the significant tests: how much is left to explain, all tests at once."""
        return float(sum((t.z - self.z_crit) ** 2 for t in self.tests if self.significant(t)))

    def significant(self, test: Test) -> bool:
        """z above the critical z, and not explained away by a higher-ranked rival."""
        return bool(np.isfinite(test.z) and test.z > self.z_crit and test.explained_by is None)

    def unexplained(self) -> list[str]:
        """Plain sentences for significant ADEV-band tests on gyros without a significant candidate.

        A significant per-gyro candidate explains its gyro's band; of the
        array-wide ones only those that change each gyro's own ADEV
        (``Effect.changes_adev``: a burst, not a correlation or the Earth's rate).
        """
        explained = {t.gyro for t in self.candidates if self.significant(t)}
        array_wide = any(t.gyro is None and self.significant(t) and get_effect(t.effect).changes_adev
                         for t in self.candidates)
        out = []
        for t in self.tests:
            if t.kind == "adev_band" and self.significant(t) and t.gyro not in explained and not array_wide:
                out.append(t.evidence + f"; none of the {len(effect_names())} effects explains it")
        return out

    def baseline_noise(self, gyro: int, sigma: bool = False):
        """(N [deg/√h], K [deg/h/√h]) of the gyro's calibrated baseline (None where not fitted);
        with ``sigma``: ((N, σ_N), (K, σ_K))."""
        out: dict[str, tuple[float | None, float | None]] = {"white": (None, None), "walk": (None, None)}
        for eff in _baseline_effects():
            f = self.fits.get((eff.name, gyro))
            if f is None or eff.baseline_term not in out:
                continue
            key = eff.params[0].name
            out[eff.baseline_term] = (float(f.params[key]), f.sigma.get(key))
        if sigma:
            return out["white"], out["walk"]
        return out["white"][0], out["walk"][0]

    def to_json_dict(self) -> dict:
        """The ``diagnose --json`` object."""
        return {
            "discrepancy": _finite(self.discrepancy),
            "consistent": self.consistent,
            "candidates": [{"effect": t.effect, "gyro": t.gyro, "score": _finite(t.z),
                            "significant": self.significant(t),
                            "explained_by": None if t.explained_by is None else
                            {"effect": t.explained_by[0], "gyro": t.explained_by[1]},
                            "evidence": t.evidence}
                           for t in self.candidates],
            "z_crit": self.z_crit,
            "n_tests": len(self.tests),
            "adev_band": [{"gyro": t.gyro, "z": _finite(t.z), "significant": self.significant(t),
                           "evidence": t.evidence} for t in self.tests if t.kind == "adev_band"],
            "unexplained": self.unexplained(),
            "shared_effects": [{k: v for k, v in d.items() if k != "z"} for d in self.shared_effects()],
            "motion_locked": self.motion_locked(),
            "localisation": list(self.localisation),
            "notes": list(self.notes),
            **({"pipeline": self.pipeline} if self.pipeline else {}),
        }

    def where_it_fails(self, top: int = 6) -> list[str]:
        """Text lines: the ranked localisation (its top findings), else the unexplained sentences."""
        if not self.localisation:
            un = self.unexplained()
            return ["unexplained:"] + [f"  {u}" for u in un] if un else []
        crit = self.localised.z_crit if self.localised is not None else math.nan
        lines = [f"where it fails (ranked; score in standard errors of each statistic, critical "
                 f"{crit:.2f}):"]
        lines += [f"  [{f['score']:.1f}] {f['sentence']}" for f in self.localisation[:top]]
        if len(self.localisation) > top:
            lines.append(f"  ... {len(self.localisation) - top} more (--json)")
        return lines

    def motion_locked(self) -> list[dict]:
        """Motion-locked responses: spikes or a step whose times sit on the reference's events
        (reversals, plateau edges, jerks; :mod:`gyroarray.analysis.motion_events`), named so and
        not as outliers or a fault. Each is the candidate fit's ``motion_locked`` dict: ``kind``
        ("motion_locked"), ``candidate`` (the effect it would have been), ``gyro``, ``n_events``,
        ``window_s``, ``fraction_near``, ``fraction_chance``, ``p_value`` and ``sentence``."""
        return [dict(t.fit.extra["motion_locked"]) for t in self.candidates
                if t.fit is not None and "motion_locked" in t.fit.extra]

    def motion_lines(self) -> list[str]:
        """Text lines of :meth:`motion_locked` (empty when none)."""
        found = self.motion_locked()
        return (["motion-locked responses (tested against the reference's events, not outliers or faults):"]
                + [f"  {d['sentence']}" for d in found]) if found else []

    def shared_effects(self) -> list[dict]:
        """Effects that act one gyro at a time and are significant on all, or most, gyros alike.

        The rule (:data:`SHARED_RULE`): an effect is *on all gyros* when it is
        a significant candidate on every gyro of an array of two or more, *on
        most gyros* when on at least three quarters of four or more; and in
        both cases each numeric parameter of every gyro's fit (each component
        of a vector) lies within 25 % of the gyros' median, or within 3σ of its
        own fit from it. Each is ``{"effect", "gyros", "all", "params"}``, the
        params as ``{name: [min, max]}`` over the gyros (spec units), best z first.
        """
        n_gyros = int(self.residual_rad_s.shape[1]) if self.residual_rad_s.ndim == 2 else 0
        by_effect: dict = {}
        for t in self.candidates:
            if t.gyro is None or t.fit is None or not self.significant(t):
                continue
            by_effect.setdefault(t.effect, []).append(t)
        out = []
        for name, tests in by_effect.items():
            gyros = sorted({t.gyro for t in tests})
            every = n_gyros >= 2 and len(gyros) == n_gyros
            most = n_gyros >= 4 and len(gyros) >= 0.75 * n_gyros
            if not (every or most):
                continue
            spans = _similar_params([t.fit for t in tests])
            if spans is None:
                continue
            out.append({"effect": name, "gyros": gyros, "all": every, "params": spans,
                        "z": float(max(t.z for t in tests))})
        out.sort(key=lambda d: -d["z"])
        return out

    def shared_lines(self) -> list[str]:
        """Text lines of :meth:`shared_effects` (empty when none)."""
        lines = []
        for d in self.shared_effects():
            where = ("on all gyros" if d["all"] else
                     f"on most gyros ({len(d['gyros'])} of {self.residual_rad_s.shape[1]}: "
                     f"{', '.join(map(str, d['gyros']))})")
            params = ", ".join(f"{k} {_span_text(v)}" for k, v in d["params"].items())
            add = d["effect"] if d["all"] else " ".join(f"--add {d['effect']}:{g}" for g in d["gyros"])
            lines.append(f"  {d['effect']} {where}: significant on each, with similar parameters"
                         + (f" ({params})" if params else "")
                         + (f"; gyroarray fit --add {add} adds it to every gyro" if d["all"]
                            else f"; gyroarray fit {add} adds it to these"))
        return ["the same effect on every gyro (" + SHARED_RULE + "):"] + lines if lines else []

    def effects_json(self) -> list[dict]:
        """The calibrated model's effects with params and sigma (``fit --json``)."""
        out = []
        for entry in self.model:
            f = self.fits.get((entry.effect, entry.gyro))
            out.append({"effect": entry.effect, "gyro": entry.gyro, "params": _entry_params(entry),
                        "sigma": {} if f is None else {k: _finite(v) for k, v in f.sigma.items()}})
        return out


#: When :meth:`Analysis.shared_effects` says an effect is on all (most) gyros, as the text states it.
SHARED_RULE = ("significant on every gyro, or on at least 3/4 of 4 or more, each parameter within 25 % "
               "of the gyros' median or 3 sigma of it")


def _similar_params(fits) -> dict | None:
    """{param: [min, max]} over ``fits`` when each numeric parameter (each component of a vector)
    of every fit is within 25 % of the fits' median or within 3σ of its own fit from it, else None."""
    spans = {}
    for key in fits[0].params:
        vals, sigs = [], []
        for f in fits:
            v = f.params.get(key)
            if isinstance(v, bool) or v is None:
                return None
            try:
                arr = np.atleast_1d(np.asarray(v, dtype=float))
                sg = np.broadcast_to(np.asarray(f.sigma.get(key, 0.0), dtype=float), arr.shape)
            except (TypeError, ValueError):
                if any(g.params.get(key) != v for g in fits):
                    return None
                break                                        # a text parameter, the same on all
            vals.append(arr)
            sigs.append(sg)
        else:
            if not vals or any(v.shape != vals[0].shape for v in vals):
                return None
            V, S = np.array(vals), np.array(sigs)
            med = np.median(V, axis=0)
            ok = (np.abs(V - med) <= 0.25 * np.abs(med)) | (np.abs(V - med) <= 3.0 * np.nan_to_num(S))
            if not np.all(ok):
                return None
            if V.shape[1] == 1:
                spans[key] = [float(V.min()), float(V.max())]
    return spans


def _span_text(v) -> str:
    lo, hi = v
    return f"{lo:.3g}" if f"{lo:.3g}" == f"{hi:.3g}" else f"{lo:.3g}–{hi:.3g}"


def _finite(x):
    """A float, or None where not finite (a list of them for a vector)."""
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_finite(v) for v in x]
    x = float(x)
    return x if math.isfinite(x) else None


def _lowpass_effects() -> list[str]:
    """The registry's causal low-pass effects (``Effect.lowpass``)."""
    return [name for name, eff in REGISTRY.items() if eff.lowpass]


def _noise_term_kwargs(ctx: FitContext, entries, gyro: int) -> dict:
    """:func:`fit_gyro_noise`'s keywords from the gyro's model entries (``Effect.noise_term``):
    their baseline terms, a Gauss–Markov τc, the white column's shape and a ramp taken out."""
    kw: dict = {"model_terms": ()}
    for e in entries:
        if e.gyro != gyro:
            continue
        term = get_effect(e.effect).noise_term(ctx, e)
        kw["model_terms"] += tuple(term.get("terms", ()))
        for key in ("gm_tau_s", "white_shape", "ramp_taken_out", "quant_shape"):
            if key in term:
                kw[key] = term[key]
    return kw


def _finding_dict(f, a: Analysis) -> dict:
    """One localisation finding as ``Analysis.localisation`` keeps it; a non-causal low-pass on
    gyros where ``bandwidth`` is a significant candidate or in the model says what that misses."""
    d = {"kind": f.kind, "gyros": list(f.gyros), "score": float(f.score), "sentence": f.summary,
         "details": plain_json(f.details)}
    lowpass = _lowpass_effects()
    if f.kind == "lowpass" and f.details.get("causal") is False and lowpass:
        with_bw = sorted({t.gyro for t in a.candidates if t.effect in lowpass and a.significant(t)}
                         | {e.gyro for e in a.model if e.effect in lowpass and e.gyro is not None})
        on = [g for g in f.gyros if g in with_bw]
        if on:
            fits = "its magnitude fits, but " if f.details.get("library_fits") else ""
            d["sentence"] += (f"; {lowpass[0]} (significant or in the model on gyro{'s' if len(on) > 1 else ''} "
                              f"{', '.join(map(str, on))}): {fits}it is causal and would put a lag of "
                              f"≈ {f.details['expected_lag_s'] * 1e3:.3g} ms on the motion that the record "
                              "does not have (a zero-phase filter, e.g. a decimation filter applied "
                              "offline, is not in the library)")
    return d


def _entry_params(entry: ModelEntry) -> dict:
    """The entry's parameters only (its 1σ, which the model file also carries, is ``sigma`` beside)."""
    d = entry.to_dict()
    for key in ("effect", "gyro", "sigma"):
        d.pop(key, None)
    return d


def _prediction_error(t: Test, entry: ModelEntry) -> Test:
    """A test of a model's own effect on what its prediction leaves: the refit is the error δ of
    the model's parameters; where the model carries their 1σ (σ_M, from the record it was fitted
    on) and the refit has its own (σ_T), each is judged against √(σ_T² + σ_M²): both records'
    uncertainty, z from the χ² of those ratios, at most the refit's own z."""
    f = t.fit
    terms = []
    absolute = get_effect(entry.effect).refit_absolute
    keys = f.sigma if absolute and f is not None else entry.sigma
    for k in keys:
        s_m = entry.sigma.get(k, 0.0)
        s_t = f.sigma.get(k) if f is not None else None
        if f is None or s_t is None or k not in f.params:
            continue
        got = f.params[k]
        if absolute:                      # the refit is the parameter: its error is the difference
            got = np.asarray(got, float) - np.asarray(entry.params[k], float)
        d, st, sm = (np.atleast_1d(np.asarray(x, float)) for x in (got, s_t, s_m))
        if d.shape == st.shape == sm.shape and np.all(np.isfinite(d)) and np.all(st > 0):
            terms += list(d / np.sqrt(st ** 2 + sm ** 2))
    z = t.z
    if terms:
        z = chi2_to_z(float(np.sum(np.square(terms))), len(terms))
        if np.isfinite(t.z):
            # what the model fails to predict is no more evident than the refit's own detection
            # in the residual. A refit whose parameters are not errors of the model's (a line
            # found again at another frequency: its frequency, to 1e-5 Hz, is not a δ) would
            # otherwise read astronomically: the ADIS16405's 20.4 Hz line, at 19.9 Hz in the
            # held-out half, gave z = 1.6e6 where the line left in the residual has z = 11.7
            z = min(z, t.z)
    elif absolute:                        # nothing to compare: the test says only that it is there
        z = math.nan
    return replace(t, z=float(z), evidence="prediction error of the model's " + t.evidence
                   + (f" (against the model's own 1σ too: z = {z:.1f})" if terms else ""),
                   extra={**t.extra, "prediction_error": True, "z_without_model_sigma": t.z})


def _sigma_of(f: EffectFit, params: dict) -> dict:
    """The fit's finite 1σ of the entry's parameters (a vector's only when every component has one)."""
    out = {}
    for k, v in f.sigma.items():
        if k not in params or v is None:
            continue
        a = np.asarray(v, dtype=float)
        if a.size and np.all(np.isfinite(a)) and np.all(a >= 0):
            out[k] = float(a) if a.ndim == 0 else tuple(float(x) for x in a)
    return out


def _model_of(ctx: FitContext) -> NoiseModel:
    """The model ``ctx`` calibrates (:meth:`ModelComparison._context` always sets it)."""
    assert ctx.model is not None, "a comparison's fit context carries the model it calibrates"
    return ctx.model


#: Length of the instrument's mean [s] when the reference is found to carry noise of its own and
#: --ref-smooth is not given (at least 5 samples): long enough that a differentiated encoder's
#: lines are gone from it (the MPU-6050's 15 Hz: 0.2 % through two 21-sample means). Its rounding
#: of the turns biases nothing: it is only in the instrument.
INSTRUMENT_S = 0.2


def _own_noise_note(d: dict, instrument_s: float) -> str:
    """The note for a reference axis with noise of its own (:func:`reference_own_noise`)."""
    return (describe_own_noise(d) + ". Fitted against it plainly, scale factor, nonlinearity, misalignment and "
            "latency would be pulled off by it (errors in variables): they are fitted against it with the "
            f"reference averaged twice over {instrument_s:g} s as instrument; the other tests read it as recorded "
            "(--ref-smooth SECONDS smooths it for them too)")


def _smoothed_and_instrument(ref: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
    """The reference's centred mean over ``length`` samples and the instrument of the regressions
    on it: that mean taken twice (a triangle), whose side lobes pass the square of the single
    mean's (a reference's noise line at 15 Hz: 0.2 % instead of 4.7 % through 21 samples at
    100 Hz); what it does to the turns biases nothing, being only in the instrument."""
    once = _centred_mean(ref, length)
    return once, _centred_mean(once, length)


def _centred_mean(x: np.ndarray, length: int) -> np.ndarray:
    """Centred moving average of each column over ``length`` samples (odd; shrinking at the ends)."""
    if length <= 1:
        return x
    half = length // 2
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    i = np.arange(x.shape[0])
    lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, x.shape[0])
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def _zeros_like_outputs(n: int, N: int) -> np.ndarray:
    return np.zeros((n, N))


#: Peak memory of a comparison (diagnose, fit, validate, ladder) per sample and column of the
#: record [bytes]: 18 float64 copies. Measured: ``diagnose`` of 1e7 samples x 4 gyros peaked at
#: 5.21 GiB (RSS), 17.5 times the 0.30 GiB of the gyro columns (the Monte-Carlo band's run: the
#: simulated noise, its random walk's cumsum, ADEV and Welch work arrays, on top of the record,
#: its residual and the fits' copies).
COMPARISON_BYTES_PER_CELL = 18 * 8
#: What the interpreter and the libraries hold before any record is read [bytes].
FIXED_BYTES = 400 * 2**20


def comparison_memory(n: int, columns: int) -> int:
    """Estimated peak memory [bytes] of comparing a record of ``n`` samples x ``columns``
    columns (gyros + reference + temperature + specific force) with a model, whole command."""
    return FIXED_BYTES + COMPARISON_BYTES_PER_CELL * int(n) * int(columns)


def _check_comparison_memory(measurement: Measurement, n: int, n_gyros: int, name: str) -> None:
    """Refuse, before any copy, a comparison whose peak would pass the memory budget."""
    cols = n_gyros + sum(k for x, k in ((measurement.ref_rad_s, 3), (measurement.temp_c, 1),
                                           (measurement.acc_m_s2, 3)) if x is not None)
    need, budget = comparison_memory(n, cols), max_memory()
    if need <= budget:
        return
    fits = max((budget - FIXED_BYTES) // (COMPARISON_BYTES_PER_CELL * cols), 0)
    check_memory(need, f"comparing {n} samples x {cols} columns with the model",
                 f"analyse at most {fits} samples (a shorter part of the record, or the record "
                 f"decimated to a lower rate; about {format_size(COMPARISON_BYTES_PER_CELL * cols)} "
                 "per sample)", file=name)


class ModelComparison:
    """Compare a measurement with a noise model (the chain of the module docstring).

    Parameters
    ----------
    measurement : Measurement
        The recorded run.
    model : NoiseModel, optional
        Effects to calibrate (default :func:`baseline_model`); the baseline
        effects are added on every gyro that lacks them.
    n_runs : int
        Monte-Carlo runs of the model band.
    seed : int
        Seed of the band's ``numpy.random.Generator`` (results are bit-identical per seed).
    alpha : float
        Family-wise false-alarm rate of the discrepancy.
    ref_smooth_s : float
        Smooth the reference rate by a centred moving average of this length [s] before
        anything reads it (``--ref-smooth``): a reference with noise of its own (a
        differentiated encoder) is an errors-in-variables problem, and its noise would be
        read as the gyros'. 0: the reference as recorded.
    workers : int, optional
        Threads for the Monte-Carlo band (same bits for any number); default every CPU
        on large records (:meth:`_workers`), one on small ones.

    A record whose reference never stands still (no static part of ``MIN_STATIC``
    samples) is calibrated on what the reference does not explain over the whole
    record: the white level from the residual's first differences (a high-pass:
    the deterministic part of a residual moves slowly), the random walk from its
    Allan fit; the notes say so.
    """

    def __init__(self, measurement: Measurement, model: NoiseModel | None = None, *,
                 n_runs: int = N_RUNS, seed: int = 0, alpha: float = ALPHA, ref_smooth_s: float = 0.0,
                 workers: int | None = None):
        self.m = measurement
        self.workers = workers
        self.name = measurement.source or "measurement"
        self.n_runs = int(n_runs)
        self.seed = int(seed)
        self.alpha = float(alpha)
        self.H = np.asarray(measurement.layout.axes, float)
        self.N = self.H.shape[0]
        self.dt = float(measurement.dt_s)
        self.t = relative_time_s(measurement)   # epoch stamps: differences to the first are exact
        self.n = self.t.size
        _check_comparison_memory(measurement, self.n, self.N, self.name)
        # the simulator's clock: uniform at dt from the first sample (the
        # measured clock may jitter by a fraction of a step)
        self.t_sim = self.t[0] + np.arange(self.n) * self.dt
        self.y = np.asarray(measurement.gyro_rad_s, float)
        self.ref = measurement.ref_rad_s
        self.ref_raw = self.ref_instrument = None
        self.setup_notes: list[str] = []
        span = self.n * self.dt
        if not (math.isfinite(ref_smooth_s) and 0.0 <= ref_smooth_s <= span):
            raise InputError(f"--ref-smooth {ref_smooth_s:g} s must be from 0 to the record's "
                             f"{span:.6g} s (a moving average longer than the record flattens all its "
                             "motion)", file=self.name)
        if ref_smooth_s and self.ref is not None:
            self.ref_raw = self.ref
            k = max(int(round(ref_smooth_s / self.dt)), 1)
            self.ref, self.ref_instrument = _smoothed_and_instrument(self.ref, k)
            self.setup_notes.append(
                f"the reference rate is smoothed by a centred {ref_smooth_s:g} s moving average (--ref-smooth): "
                "its own noise is not read as the gyros'; motion faster than about "
                f"{1.0 / ref_smooth_s:.3g} Hz is flattened in it. Scale factor, nonlinearity, misalignment and "
                "latency are fitted against the reference as recorded with the smoothed one (averaged twice) as "
                "instrument "
                "(errors in variables: neither the reference's noise nor the smoothing biases them)")
        self.temp = None if measurement.temp_c is None else np.asarray(measurement.temp_c, float)
        self.acc = None if measurement.acc_m_s2 is None else np.asarray(measurement.acc_m_s2, float)
        self.positions = measurement.layout.positions_m
        model = baseline_model(self.N) if model is None else model
        model.check(self.N)
        self.given_model = model
        self.model = self._with_baseline(model)
        self._check_usable()
        self.parts: list[tuple[int, int]] = []      # stitched still parts, [start, stop) of the new record
        self.parts_s: list[tuple[float, float]] = []  # ... and where they were in the measurement [s]
        self._attitude: np.ndarray | None = None     # platform -> level (attitude()); set by a cut at gaps
        if self.ref is None or len(self.segments) > 1:
            self._keep_still_parts()
        self.E0 = self.y - (self.ref @ self.H.T if self.ref is not None else 0.0)
        if self.ref is not None:
            self.static = np.all(np.abs(self.ref) <= STATIC_RAD_S, axis=1)
        else:
            self.static = np.ones(self.n, bool)
        runs = [r for r in true_runs(self.static) if r[1] - r[0] >= MIN_STATIC]
        self.continuous = False
        if not runs and self.ref is not None and self.n >= MIN_STATIC:
            longest = max((b - a for a, b in true_runs(self.static)), default=0)
            self.continuous = True
            runs = [(0, self.n)]
            self.setup_notes.append(
                f"no static part (the longest stretch with the reference within 0.01 deg/s is "
                f"{longest * self.dt:.1f} s): the noise is calibrated on what the reference does not "
                "explain over the whole record (white level from the residual's first differences)")
        if not runs:
            longest = max((b - a for a, b in true_runs(self.static)), default=0)
            raise InputError(f"no static part long enough to calibrate the noise: the longest stretch "
                             f"with the reference rate within 0.01 deg/s is {longest} samples "
                             f"({longest * self.dt:.1f} s), at least {MIN_STATIC} samples "
                             f"({MIN_STATIC * self.dt:.1f} s) are needed", file=self.name)
        self.static_runs = runs
        self.longest = max(runs, key=lambda r: r[1] - r[0])
        self.moving = self.ref is not None and bool(np.any(~self.static))
        if self.moving and self.ref_raw is None:
            assert self.ref is not None                # moving: the reference says so
            own = reference_own_noise(self.ref, self.y, self.H, self.dt)
            if own:
                # errors in variables: the regressions on the reference are instrumented by it
                # averaged twice over INSTRUMENT_S, the other tests read it as recorded
                k = max(int(round(INSTRUMENT_S / self.dt)), 5)
                self.ref_raw = self.ref
                self.ref_instrument = _smoothed_and_instrument(self.ref, k)[1]
                self.setup_notes += [_own_noise_note(d, k * self.dt) for d in own]
        self._force: np.ndarray | None = None
        self._sim_inputs: dict = {}                 # site -> checked simulator inputs (simulate_entry)
        self._entry_sims = _KeptSims()              # entry -> what it adds (simulate_entry), by live columns
        self._rq_kept: dict = {}                    # content of (e, gyro, shape) -> (r, q) (_noise_rq)

    # -- set-up -----------------------------------------------------------
    def _keep_still_parts(self) -> None:
        """Keep the parts the fits can read, stitched: the still ones of a record without a
        reference, cut at the gaps of ``time_s`` of a record read with ``--gaps``.

        A record without ``ref_*`` that moves (a hand-turned board, a table
        run without its log) would read its motion as noise. Its still parts
        of at least ``MIN_STILL_PART`` samples are stitched into one record,
        each part's mean replaced by the first part's (the bias steps with the
        orientation: Earth rate, g-sensitivity), so the diagnosis sees noise
        only; τ beyond a part's length and the drift between parts are lost.
        The deterministic fits do not take those means as given: each part's
        offset is a free parameter of their regressions (``FitContext.parts``,
        ``breaks`` of :func:`~gyroarray.analysis.gls.gls_rw`), else the
        equalised means would absorb part of a temperature signal.

        A record with gaps (:attr:`segments`, steps over
        :data:`~gyroarray.analysis.deviations.GAP_FACTOR` periods) is cut at them
        (:func:`~gyroarray.analysis.deviations.cut_at_segments`: pieces of at least
        :data:`~gyroarray.analysis.deviations.MIN_CUT_PART` samples) and stitched the same way,
        so that no difference, Allan average or random walk of the fits runs across a gap (what
        ``allan --gaps`` pools); with a reference rate each part's mean *residual* is set to
        the first part's (the outputs keep their motion), and the reference is cut with them.
        """
        gapped = len(self.segments) > 1
        if self.ref is None:
            still = still_mask(self.y, self.H, self.dt)
            if still.all() and not gapped:
                return
            runs = ([(0, self.n)] if still.all() else
                    [(a, b) for a, b in true_runs(still) if b - a >= MIN_STILL_PART])
        else:
            still, runs = None, [(0, self.n)]
        self.cut_for_motion = still is not None and not bool(still.all())
        if gapped:
            runs = cut_at_segments(runs, self.segments)
        total = sum(b - a for a, b in runs)
        if total < MIN_STATIC and (still is None or still.all()):
            raise InputError(
                f"the record has {len(self.segments) - 1} gap(s) in time_s and its contiguous parts "
                f"(at least {MIN_CUT_PART} samples each) add up to {total} samples ({total * self.dt:.1f} s), at least "
                f"{MIN_STATIC} samples ({MIN_STATIC * self.dt:.1f} s) are needed to calibrate the noise",
                file=self.name)
        if total < MIN_STATIC:
            assert still is not None                 # the case of a record with gaps is refused above
            longest = max((b - a for a, b in true_runs(still)), default=0)
            raise InputError(
                f"no reference rate (ref_x, ref_y, ref_z) and the outputs show motion for "
                f"{(~still).sum() * self.dt:.0f} s of {self.n * self.dt:.0f} s: the still parts add up to "
                f"{total * self.dt:.1f} s (longest {longest * self.dt:.1f} s; parts shorter than "
                f"{MIN_STILL_PART * self.dt:.1f} s not counted), at least {MIN_STATIC * self.dt:.1f} s are "
                f"needed to calibrate the noise; record a longer static part or add the reference rate",
                file=self.name)
        if self.ref is None:
            first = self.y[runs[0][0]:runs[0][1]].mean(axis=0)
            pieces = [self.y[a:b] - self.y[a:b].mean(axis=0) + first for a, b in runs]
        else:
            e0 = self.y - self.ref @ self.H.T
            first = e0[runs[0][0]:runs[0][1]].mean(axis=0)
            pieces = [self.y[a:b] + (first - e0[a:b].mean(axis=0)) for a, b in runs]
        start = 0
        for a, b in runs:
            self.parts.append((start, start + b - a))
            # where the part was in the measurement [s] (its own clock: the gaps included)
            self.parts_s.append((float(self.t[a]), float(self.t[b - 1] + self.dt)))
            start += b - a
        idx = np.concatenate([np.arange(a, b) for a, b in runs])
        if self.ref is not None and gapped:
            # the attitude on the record's own clock, the rotation over each gap integrated
            # (attitude_across_gaps), then cut with the samples: stitching the reference first
            # would drop what the platform turned during the gaps
            across = [b - 1 for _, b in self.segments[:-1]]
            gaps = {i: round((self.t[i + 1] - self.t[i]) / self.dt) * self.dt for i in across}
            att = np.array(attitude_across_gaps(self.ref, self.dt, gaps)[idx])
            att.flags.writeable = False
            self._attitude = att
        self.y = np.concatenate(pieces)
        self.temp = None if self.temp is None else self.temp[idx]
        self.acc = None if self.acc is None else self.acc[idx]
        if self.ref is not None:
            self.ref = self.ref[idx]
            self.ref_raw = None if self.ref_raw is None else self.ref_raw[idx]
            self.ref_instrument = None if self.ref_instrument is None else self.ref_instrument[idx]
        self.n = idx.size
        self.t = self.t_sim = self.t[0] + np.arange(self.n) * self.dt

    def _workers(self, n: int) -> int:
        """Threads for the Monte-Carlo band of an n-sample record: ``workers`` when given, else
        every CPU once the band is big enough to repay them (about 2e7 samples), as many as the
        memory budget holds (a run keeps about 16 arrays of the record's size)."""
        if self.workers is not None:
            return max(int(self.workers), 1)
        if n * self.N * self.n_runs < _PARALLEL_MIN_SAMPLES:
            return 1
        per_run = 16 * 8 * n * self.N
        return max(1, min(available_cpus(), int(max_memory() // per_run)))

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
        """The model with the baseline on every gyro and per-gyro entries for every all-gyros one."""
        own = {(e.effect, e.gyro) for e in model}            # the entries the model names per gyro
        have = set(own)
        for e in model:
            if get_effect(e.effect).baseline and e.gyro is None:
                have |= {(e.effect, g) for g in range(1, self.N + 1)}
        out = model
        for g in range(1, self.N + 1):
            for eff in _baseline_effects():
                if (eff.name, g) not in have:
                    out = out.with_effect(ModelEntry(eff.name, g, eff.placeholder()))
        entries = []
        for e in out:
            if e.gyro is None and get_effect(e.effect).per_gyro:    # a gyro's own entry wins
                entries += [ModelEntry(e.effect, g, dict(e.params)) for g in range(1, self.N + 1)
                            if (e.effect, g) not in own]
            else:
                entries.append(e)
        return NoiseModel(tuple(entries), description=model.description, source=model.source)

    def _check_usable(self):
        """Refuse a record too short to calibrate the noise, or whose clock jitters by more than a
        quarter step; find its gaps (:attr:`segments`: the contiguous runs of samples between steps
        over :data:`~gyroarray.analysis.deviations.GAP_FACTOR` periods, one run without gaps, and
        :attr:`missing`: the samples they lack), which :meth:`_keep_still_parts` cuts the record at."""
        if self.n < MIN_STATIC:
            raise InputError(f"too short for a diagnosis: {self.n} samples ({self.n * self.dt:.1f} s); "
                             f"at least {MIN_STATIC} samples of a static part are needed to "
                             f"calibrate the noise", file=self.name)
        self.segments, self.missing = contiguous_segments(self.t, self.dt)
        steps = np.diff(self.t)
        across = np.array([b - 1 for _, b in self.segments[:-1]], dtype=int)   # the steps over a gap
        within = np.delete(steps, across)
        if within.size and np.max(np.abs(within - self.dt)) > 0.25 * self.dt:
            raise InputError("the sample times are not uniform (the Allan and regression fits need "
                             "a uniform step between gaps); resample or repair the record first", file=self.name)
        self.cut_for_motion = False  # set by _keep_still_parts when still parts are kept
        if len(self.segments) == 1:
            self.t = self.t_sim      # jitter below a quarter step: the fits use the uniform clock
        # with gaps the measured clock stays until the record is cut at them (_keep_still_parts)

    def gap_summary(self) -> dict | None:
        """The gaps the record was cut at (None without gaps): ``gaps``, ``missing_samples``,
        ``parts`` (the contiguous parts the fits read) and ``samples`` (theirs, in all)."""
        if len(self.segments) < 2:
            return None
        return {"gaps": len(self.segments) - 1, "missing_samples": int(self.missing),
                "parts": len(self.parts), "samples": int(self.n)}

    # -- services of the fit context ----------------------------------------
    def attitude(self):
        """Platform -> local-level rotations integrated from the reference (cached), or None."""
        if self._attitude is None and self.ref is not None:
            # an array of its own (numba's has a foreign base), read-only: its digest is kept by
            # the content caches that read it many times (memo.freeze); the same values
            self._attitude = np.array(attitude_from_rates(self.ref, self.dt))
            self._attitude.flags.writeable = False
        return self._attitude

    def effect(self, name: str) -> Effect:
        return get_effect(name)

    def simulate_entry(self, entry: ModelEntry) -> np.ndarray:
        """What one model entry adds to the outputs [rad/s], (n, N): simulated alone on the reference.

        Kept by the entry's content (the ranking and the slow effects' refits predict the same
        fitted entry again on each record they cut), a new array each call, the same bits."""
        key = _entry_key(entry)
        hit = None if key is None else self._entry_sims.get(key)
        if hit is not None:
            return hit.dense()
        out = self._simulate_entry(entry)
        if key is not None:
            self._entry_sims.put(key, out)
        return out

    def _simulate_entry(self, entry: ModelEntry) -> np.ndarray:
        truth = self.ref if self.ref is not None else np.zeros((self.n, 3))
        s = self.m.site
        site = None
        if s is not None:
            lat = float(entry.params["latitude_deg"]) * RAD_PER_DEG if "latitude_deg" in entry.params \
                else s.latitude_rad
            site = (lat, s.heading_rad)
        elif "latitude_deg" in entry.params:
            site = (float(entry.params["latitude_deg"]) * RAD_PER_DEG, 0.0)
        if site not in self._sim_inputs:             # the record's inputs, checked once per site
            if len(self._sim_inputs) >= 8:
                self._sim_inputs = {k: v for k, v in list(self._sim_inputs.items())[:1]}
            if self._sim_inputs:
                # another site of the same record: the same checked arrays (read-only), shared; the
                # site checked as sim_context checks it (on two samples). Each site's own copy of
                # the record was 60 MB on 46 min of 6 gyros, and a fitted Earth rate asks for many.
                first = next(iter(self._sim_inputs.values()))
                probe = sim_context(truth[:2], self.m.layout, self.dt, site=site)
                self._sim_inputs[site] = replace(first, site=probe.site)
            else:
                self._sim_inputs[site] = sim_context(truth, self.m.layout, self.dt, time_s=self.t_sim,
                                                     temp_c=self.temp, site=site, specific_force=self.acc,
                                                     attitude=self.attitude() if self.ref is not None else None)
        sim = simulate_on(NoiseModel((entry,)), self._sim_inputs[site], np.random.default_rng(0))
        sensed = getattr(self, "_sensed_truth", None)
        if sensed is None:                           # truth @ H.T, the same bits every entry: made once
            sensed = self._sensed_truth = truth @ self.H.T
            sensed.flags.writeable = False
        return sim - sensed

    def specific_force(self) -> np.ndarray:
        """Specific force at each gyro (n, N, 3) [m/s²] (cached): ``acc`` or gravity through the
        attitude at the origin, plus the lever-arm terms of the reference's rate and acceleration."""
        if self._force is None:
            omega = self.ref if self.ref is not None else np.zeros((self.n, 3))
            f0 = self.acc if self.acc is not None else gravity_specific_force(self.attitude(), self.n)
            pos = self.positions if self.positions is not None else np.zeros((self.N, 3))
            self._force = rigid_body_specific_force(f0, omega, np.gradient(omega, self.dt, axis=0), pos)
            self._force.flags.writeable = False        # read by content many times (memo.freeze)
        return self._force

    def _context(self, model: NoiseModel) -> FitContext:
        """The fit context of one analysis of ``model`` (record fields filled, analysis fields empty)."""
        ctx = FitContext(name=self.name, H=self.H, t=self.t, dt=self.dt, y=self.y, E0=self.E0, ref=self.ref,
                         temp=self.temp, acc=self.acc, positions=self.positions, site=self.m.site,
                         static=self.static, longest=self.longest, moving=self.moving, model=model,
                         ref_raw=self.ref_raw, ref_instrument=self.ref_instrument,
                         parts=tuple(self.parts) if len(self.parts) > 1 else ())
        ctx.services = _Services(self, ctx)
        return ctx

    # -- one effect's fit ---------------------------------------------------
    def _fitted(self, ctx: FitContext, eff: Effect, gyro: int | None, E: np.ndarray) -> EffectFit:
        """Fit ``eff`` on residual E (its own contribution included).

        A slow effect (temperature, Earth rate, rate ramp) is fitted twice:
        the noise's q, which decides how much slow drift is forgiven, is
        estimated again on the residual without the first fit's contribution
        (a real drift inflates q and would hide itself).
        """
        f = eff.fit(ctx, gyro, E)
        if not eff.slow or not np.isfinite(f.z) or f.z < 2.0:
            return f
        entry = self._entry_from_fit(eff, f, ModelEntry(eff.name, gyro, eff.placeholder()))
        clean = ctx.equalised(E - eff.predict(ctx, entry))
        q2 = np.array(ctx.q, dtype=float, copy=True)
        for g in (range(self.N) if gyro is None else [gyro - 1]):
            q2[g] = self._noise_rq(clean[:, g], g + 1, **self._allan_shape(ctx, ctx.model, g + 1, 1))[1]
        return eff.fit(replace(ctx, q=q2), gyro, E)

    def _noise_rq(self, e: np.ndarray, gyro: int, white_shape=None) -> tuple[float, float]:
        """White variance r = N²/dt and random-walk increment variance q = K²·dt [rad²/s²] of one gyro.

        r from the Allan fit of the longest static part (ARW is always well
        determined). q, which decides how much slow drift the regressions
        forgive, is the larger of (a) its maximum-likelihood value on all
        static samples, the random walk running through the dynamic gaps
        (exact likelihood of :class:`~gyroarray.analysis.gls.RWWhitener`),
        and (b) the Allan fit's K + 2σ_K: a drift the Allan variance cannot
        tell from RRW (a flicker floor, a short record where K is 0 ± σ) must
        not make a slow regressor (temperature, ramp, Earth rate) significant.
        ``white_shape``: the Allan fit reads its white column so (what the model
        shapes at short τ, a sensor's own filter, is not white noise:
        :meth:`_allan_shape`).
        """
        key = content_key(e, int(gyro), white_shape)
        if key is not None and key in self._rq_kept:
            return self._rq_kept[key]
        r, base = self._white_r(e, gyro, white_shape)
        k_up = rrw_deg_h_rt_h_to_rad_s_rt_s(base[1].params["k_deg_h_rt_h"]
                                            + 2.0 * base[1].sigma.get("k_deg_h_rt_h", 0.0))
        q_up = max(k_up ** 2 * self.dt, 1e-12 * r)
        # stitched parts: the walk does not run across a join (each part its own offset, as the
        # regressions fit it); the step a join leaves is the orientation's, not random walk
        breaks = np.array([a for a, _ in self.parts[1:]], dtype=int) if len(self.parts) > 1 else None
        q_ml = _ml_q(e, r, np.ones(self.n, bool) if self.continuous else self.static, breaks)
        if key is not None:
            if len(self._rq_kept) >= 512:
                self._rq_kept.clear()
            self._rq_kept[key] = (r, max(q_ml, q_up))
        return r, max(q_ml, q_up)

    def _white_r(self, e: np.ndarray, gyro: int, white_shape=None) -> tuple:
        """(r = N²/dt [rad²/s²], the baseline Allan fit it came from) of :meth:`_noise_rq`: N from the
        fit of the longest static part, or, on a record that never stands still, from a
        high-pass (the robust spread of the first differences)."""
        a, b = self.longest
        if len(self.parts) > 1:
            # stitched still parts: the Allan fit reads the longest part alone; across a join it
            # reads the step each part's own offset leaves (a temperature between parts) as random
            # walk, and that K + 2σ sets q, which decides what the slow regressors may explain
            a, b = max(self.parts, key=lambda p: p[1] - p[0])
        base = fit_gyro_noise(e[a:b], self.dt, gyro, white_shape=white_shape, **self.pipeline_fit_kw())
        n_rad = arw_deg_rt_h_to_rad_rt_s(base[0].params["n_deg_rt_h"])
        if len(self.parts) > 1:
            # the white level of every still part, pooled, at the τ where white noise dominates
            # (:meth:`pooled_white`): one part read alone left gyro 1 of the MIMU4444 board at
            # 0.28 deg/√h where its ADEV·√τ on that part was >= 0.82 at every τ
            n_rad = self.white_level(n_rad, e)[0]
        if self.continuous:                    # the white level from a high-pass: first differences
            d = np.diff(e)
            n_rad = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2.0) * math.sqrt(self.dt)
        return max(n_rad ** 2 / self.dt, 1e-30), base

    def white_level(self, n_fit: float, e: np.ndarray) -> tuple[float, bool]:
        """(N [rad/√s], whether it is the pooled reading) of one gyro on stitched still parts: the
        Allan fit's ``n_fit`` while it lies within :data:`WHITE_AGREE` σ of the pooled reading
        at τ ≈ 1 s (:meth:`pooled_white`; white noise: the fit reads every τ, the more precise),
        else the pooled reading (a real gyro's short-τ humps, lines and quantization pull the
        fit off the level its angle error sees)."""
        n1, s1 = self.pooled_white(e)
        if s1 > 0 and abs(n_fit - n1) <= WHITE_AGREE * s1:
            return float(n_fit), False
        return float(n1), True

    def pooled_white(self, e: np.ndarray) -> tuple[float, float]:
        """(N, its 1σ) [rad/√s] of one gyro's residual ``e`` (n,) on stitched still parts: the
        Allan deviation pooled over the parts, never across a join, read at τ ≈ 1 s, N = σ(τ)·√τ
        (:func:`~gyroarray.analysis.white_level.pooled_white_level`; what ``fuse`` and the
        ``[array]`` table read). Kept by content."""
        key = ("pooled_white",) + (content_key(e) or (id(e),))
        hit = self._rq_kept.get(key)
        if hit is None:
            lev = pooled_white_level(np.asarray(e, float), self.dt, self.parts)
            if lev is None:                       # no part longer than 2 s: the fit's reading
                ww = white_walk_fit(np.asarray(e, float)[:, None], self.dt, parts=self.parts)
                hit = (float(ww.arw_rad_rt_s[0]), float(np.nan_to_num(ww.arw_sigma[0])))
            else:
                hit = (float(lev[0][0]), float(lev[1][0]))
            if content_key(e) is not None:
                self._rq_kept[key] = hit
        return hit

    # -- the chain, step by step -----------------------------------------------
    def analyse(self, model: NoiseModel | None = None) -> Analysis:
        """Calibrate ``model`` (default: this comparison's) and run every test."""
        model = self.model if model is None else self._with_baseline(model)
        ctx = self._context(model)
        notes: list[str] = []
        self._leave_out(ctx, notes)
        fits = self.calibrate(ctx)
        assert ctx.E is not None and ctx.r is not None and ctx.q is not None   # set by calibrate
        for e in model:                        # glitches the model knows of out of the record
            ctx.E = get_effect(e.effect).clean(ctx, e, ctx.E)
        self._motion_clean(ctx, notes)
        tests = self._deterministic_candidates(ctx, notes)
        self._stochastic_record(ctx, tests, notes)
        fits.update(self._noise(ctx, tests, notes))
        # what a fitted entry says beside its value (a scale factor's two estimates, reconciled)
        notes += [f.extra["reconciled"] for f in fits.values() if f.extra.get("reconciled")]
        cal = NoiseModel(tuple(e if (e.effect, e.gyro) not in fits else
                               self._entry_from_fit(get_effect(e.effect), fits[(e.effect, e.gyro)], e)
                               for e in model), description=model.description)
        adev, band_tests = self._adev_band(cal, ctx.E, ctx.rec)
        tests += band_tests
        cands, zc, disc = self._rank(ctx, tests, absorbed=self._absorbed(model))
        notes += self.setup_notes + self._record_notes() + self._pipeline_notes()
        return Analysis(model=cal, fits=fits, tests=tests, candidates=cands, discrepancy=float(disc),
                        z_crit=zc, residual_rad_s=ctx.E, raw_residual_rad_s=self.E0, record=ctx.rec,
                        static=self.static, adev=adev, notes=notes, r=ctx.r, q=ctx.q, context=ctx,
                        pipeline=self._pipeline_json())

    def validate(self) -> Analysis:
        """Does the model, fitted on another record, predict this one? (``compare --validate``)

        Every parameter of the model stays as it is: the white and random-walk
        variances come from its baseline, the deterministic effects predict
        with their own parameters, the stochastic part is simulated as it is
        for the band. Only each gyro's starting bias (the random walk's free
        start) belongs to this record. The tests: every effect not in the
        model (as in :meth:`analyse`), each deterministic effect of the model
        tested again on what its prediction leaves (its prediction error: z ≈
        N(0, 1) when the model's parameters hold here), and the ADEV against
        the model's band; D has the same meaning as in :meth:`analyse`.
        """
        have = {(e.effect, e.gyro) for e in self.given_model}
        for eff in _baseline_effects():
            missing = [g for g in range(1, self.N + 1) if (eff.name, g) not in have
                       and (eff.name, None) not in have]
            if missing:
                raise InputError(f"--validate needs a fitted model: it has no {eff.name} for gyro(s) "
                                 f"{', '.join(map(str, missing))} (write the model with gyroarray fit --out "
                                 "or ladder --model-out)", file=self.name)
        model = self.model
        ctx = self._context(model)
        where = model.description or "another record"
        notes = [f"validation: every parameter of the model ({where}) is fixed; only each gyro's "
                 "starting bias is fitted to this record"]
        self._leave_out(ctx, notes)
        ctx.r, ctx.q = self._model_rq(model)
        preds = _zeros_like_outputs(self.n, self.N)
        for e in model:
            pred = get_effect(e.effect).predict(ctx, e)
            if pred is not None:
                preds = preds + pred
        ctx.E = ctx.equalised(self.E0 - preds)
        for e in model:
            ctx.E = get_effect(e.effect).clean(ctx, e, ctx.E)
        ctx.r = self._test_white_level(ctx.r, ctx.E)
        tests = self._deterministic_candidates(ctx, notes)
        self._stochastic_record(ctx, tests, notes)
        for e in model:                        # the prediction error of each deterministic effect
            eff = get_effect(e.effect)         # (after the stochastic record: a line's test reads it)
            if eff.predicts and eff.candidate and not eff.why_not(ctx):
                before = len(tests)
                self._test(ctx, eff, e.gyro, tests, notes)
                if len(tests) > before:
                    tests[-1] = _prediction_error(tests[-1], e)
        self._noise(ctx, tests, notes, refit=False)
        adev, band_tests = self._adev_band(model, ctx.E, ctx.rec)
        tests += band_tests
        cands, zc, disc = self._rank(ctx, tests)
        notes += self.setup_notes + self._record_notes() + self._pipeline_notes()
        return self.localise(Analysis(
            model=model, fits={}, tests=tests, candidates=cands, discrepancy=float(disc), z_crit=zc,
            residual_rad_s=ctx.E, raw_residual_rad_s=self.E0, record=ctx.rec, static=self.static,
            adev=adev, notes=notes, r=ctx.r, q=ctx.q, context=ctx, pipeline=self._pipeline_json()))

    def _test_white_level(self, r_model: np.ndarray, E: np.ndarray) -> np.ndarray:
        """The white variance the validation's tests whiten with [rad²/s²]: the larger of the
        model's ARW and this record's white level (:meth:`_white_r`, as the calibration reads it).

        A test's white level is the noise its statistic is judged against, not a parameter the
        validation checks (the band does that). A model may carry its white noise in another
        term: the ADIS16405's gyro 3, fitted with a 0.04 s Gauss–Markov hump, has N = 0, and
        whitening with r = 0 made a 0.003 deg/s line (3.7σ by a plain least-squares fit) a
        false alarm of probability 1e-4278. The record's level is its baseline fit without the
        model's shapes (a filter's white shape would raise it by a few per cent)."""
        r = np.array(r_model, dtype=float, copy=True)
        for g in range(self.N):
            r[g] = max(r[g], self._white_r(E[:, g], g + 1)[0])
        return r

    def _model_rq(self, model: NoiseModel) -> tuple[np.ndarray, np.ndarray]:
        """r = N²/dt and q = K²·dt per gyro [rad²/s²] from the model's baseline, as it is."""
        r, q = np.zeros(self.N), np.zeros(self.N)
        for e in model:
            eff = get_effect(e.effect)
            if not eff.baseline or e.gyro is None:
                continue
            v = float(e.si_params[eff.params[0].si_name])
            if eff.baseline_term == "white":
                r[e.gyro - 1] = v * v / self.dt
            elif eff.baseline_term == "walk":
                q[e.gyro - 1] = v * v * self.dt
        r = np.maximum(r, 1e-30)
        return r, np.maximum(q, 1e-12 * r)

    def _leave_out(self, ctx: FitContext, notes: list) -> None:
        """Samples the regressions leave out, as the model's entries ask (a burst's window)."""
        masks = []
        for e in _model_of(ctx):
            m = get_effect(e.effect).exclude(ctx, e)
            if m is not None and m.any():
                masks.append(m)
                t = self.t[m]
                notes.append(f"deterministic fits leave out the {e.label} window ({t[0]:.0f}–{t[-1] + self.dt:.0f} s)")
        ctx.use = ~np.any(masks, axis=0) if masks else None

    def calibrate(self, ctx: FitContext) -> dict:
        """Step 2: r, q per gyro on the longest static part and the model's deterministic effects.

        The deterministic model is not known before r, q, nor r, q before it:
        two passes. Sets ``ctx.r``, ``ctx.q`` and ``ctx.E``; returns the fits.
        """
        model = _model_of(ctx)
        det = [e for e in model if get_effect(e.effect).predicts]
        preds = {(e.effect, e.gyro): _zeros_like_outputs(self.n, self.N) for e in det}
        current = {(e.effect, e.gyro): e for e in model}
        fits: dict[tuple[str, int | None], EffectFit] = {}
        r, q = np.zeros(self.N), np.zeros(self.N)
        ctx.r, ctx.q = r, q
        for it in range(2):
            E = ctx.equalised(self.E0 - sum(preds.values(), _zeros_like_outputs(self.n, self.N)))
            for g in range(self.N):
                r[g], q[g] = self._noise_rq(E[:, g], g + 1, **self._allan_shape(ctx, current.values(), g + 1, it))
            if not det:
                break
            for e in det:
                key = (e.effect, e.gyro)
                eff = get_effect(e.effect)
                others = sum((p for k, p in preds.items() if k != key), _zeros_like_outputs(self.n, self.N))
                fits[key] = self._fitted(ctx, eff, e.gyro, self.E0 - others)
                current[key] = self._entry_from_fit(eff, fits[key], e)
                pred = eff.predict(ctx, current[key])
                assert pred is not None                  # det: only effects that predict
                preds[key] = pred
        # stitched parts: the fits kept each part's offset free; the residual the stochastic
        # analysis reads has the parts' means set equal again, as the outputs were stitched
        ctx.E = ctx.equalised(self.E0 - sum(preds.values(), _zeros_like_outputs(self.n, self.N)))
        return fits

    def _motion_clean(self, ctx: FitContext, notes: list) -> None:
        """Spikes locked to the reference's events out of the residual the tests read.

        On each gyro without outliers in the model, the spikes
        (:func:`~gyroarray.effects.outliers.find_spikes`) whose runs start near
        the reference's reversals, plateau edges and jerks more often than
        chance (:func:`~gyroarray.effects.outliers.motion_lock`) and lie near an
        event are replaced by their neighbours' median, as a model's outliers
        are: a response to the motion is neither noise (quantization, a
        correlation, a burst), nor a line, nor a step. The residual before is
        kept (``ctx.cache[MOTION_RAW]``) for the outliers test, which names the
        response (:meth:`Analysis.motion_locked`); a note says what was taken out.
        """
        if ctx.ref is None or not self.moving or ctx.E is None:
            return
        eff = get_effect(Outliers.name)
        assert isinstance(eff, Outliers)
        in_model = {e.gyro for e in _model_of(ctx) if e.effect == Outliers.name}
        E, out, said = ctx.E, None, []
        level = ctx.at_model_level(E, self.t)[:ctx.noise_end]
        for g in range(self.N):
            if g + 1 in in_model:
                continue
            idx = eff.motion_locked_spikes(ctx, g + 1, level[:, g])
            if not idx.size:
                continue
            out = np.array(E, copy=True) if out is None else out
            out[:, g] = clean_spikes(E[:, g], idx)
            said.append(f"{idx.size} on gyro {g + 1}")
        if out is None:
            return
        ctx.cache[MOTION_RAW] = (out, E)
        ctx.E = out
        notes.append("spikes locked to the reference's events (motion-locked responses, not outliers) are "
                     "replaced by their neighbours' median before the other tests read the record: "
                     + ", ".join(said))

    @staticmethod
    def _allan_shape(ctx: FitContext, entries, gyro: int, it: int) -> dict:
        """What the gyro's model entries change in its calibration's Allan fit (none before they
        are fitted): the white column's shape (:func:`_noise_term_kwargs`)."""
        if it == 0:
            return {}
        kw = _noise_term_kwargs(ctx, entries, gyro)
        return {k: kw[k] for k in ("white_shape",) if k in kw}

    def _targets(self, eff: Effect, in_model: set) -> list:
        """The gyros (or None for the array) an effect would be tested on, not in the model."""
        targets = list(range(1, self.N + 1)) if eff.per_gyro else [None]
        return [g for g in targets if (eff.name, g) not in in_model]

    def _candidate_effects(self, ctx: FitContext, reads: str, notes: list) -> list:
        """(effect, gyros) of the candidates reading ``reads``; notes say which cannot be tested."""
        in_model = {(e.effect, e.gyro) for e in _model_of(ctx)}
        out = []
        for eff in REGISTRY.values():
            if eff.baseline or not eff.candidate or eff.reads != reads:
                continue
            why = eff.why_not(ctx)
            if why:
                notes.append(f"{eff.name}: not tested, {why}")
                continue
            targets = self._targets(eff, in_model)
            if targets:
                out.append((eff, targets))
        return out

    def _test(self, ctx: FitContext, eff: Effect, gyro: int | None, tests: list, notes: list) -> None:
        f = eff.test(ctx, gyro)
        if f.extra.get("identifiable", True) is False:
            where = eff.name if gyro is None else f"{eff.name} on gyro {gyro}"
            notes.append(f"{where}: not identifiable ({f.extra.get('reason', f.evidence)})")
            return
        tests.append(Test("effect", f.effect, f.gyro, float(f.z) if f.z is not None else math.nan,
                          f.evidence, fit=f))

    def _deterministic_candidates(self, ctx: FitContext, notes: list) -> list:
        """Step 3: every effect not in the model whose test reads the residual."""
        tests: list[Test] = []
        for eff, targets in self._candidate_effects(ctx, "residual", notes):
            for g in targets:
                self._test(ctx, eff, g, tests, notes)
        return tests

    def _stochastic_record(self, ctx: FitContext, tests: list, notes: list) -> None:
        """Step 4: the record the stochastic tests read (``ctx.rec``, ``ctx.Er``, ``ctx.tr``).

        Static when a deterministic test already exceeds the critical value of
        the whole family (the tests to come counted: the candidates that read
        the stochastic record, one ADEV band per gyro), or when the model's
        noise depends on the motion.
        """
        model = _model_of(ctx)
        in_model = {(e.effect, e.gyro) for e in model}
        n_stoch = self.N + sum(len(self._targets(eff, in_model)) for eff in REGISTRY.values()
                               if eff.candidate and not eff.baseline and eff.reads == "noise"
                               and not eff.why_not(ctx))
        det_z = [t.z for t in tests if np.isfinite(t.z)]
        zc = critical_z(len(det_z) + n_stoch + self._absorbed(model), self.alpha)
        det_sig = max(det_z, default=-math.inf) > zc
        reasons = [r for r in (get_effect(e.effect).static_noise_in(ctx, e) for e in model) if r]
        ctx.static_record = bool(reasons)
        a, b = self.longest
        assert ctx.E is not None                         # set by calibrate
        E = ctx.E
        if det_sig and self.continuous:
            # no static part to retreat to: the significant deterministic candidates' own fits are
            # taken out of what the stochastic tests read (a tilted axis's square wave read as a
            # Gauss–Markov hump 12x its own z, which no model could lower by adding the line
            # beside it). Their own tests, and the band, still read the residual as it is.
            ctx.rec = slice(0, self.n)
            E, taken = self._provisional_clean(ctx, tests, zc)
            notes.append("stochastic tests on the whole record (no static part) with the fits of the "
                         f"significant deterministic candidates taken out: {', '.join(taken) or 'none'}")
        elif det_sig or reasons:
            ctx.rec = slice(a, b)
            why = "a deterministic effect is unexplained" if det_sig else reasons[0]
            notes.append(f"stochastic tests on the longest static part ({a * self.dt + self.t[0]:.0f}–"
                         f"{b * self.dt + self.t[0]:.0f} s): {why}")
        else:
            ctx.rec = slice(0, self.n)
        end = ctx.noise_end
        lo, hi, _ = ctx.rec.indices(self.n)
        if lo < end < hi and end - lo >= MIN_STATIC:
            # a part the model leaves out to the end (a gyro frozen from its onset on) is no noise
            # record of that gyro: the stochastic tests read what comes before it
            ctx.rec = slice(lo, end)
            notes.append(f"stochastic tests end at {self.t[end]:.0f} s: the model leaves out the samples "
                         "from there on")
        ctx.tr = self.t[ctx.rec]
        ctx.Er = ctx.at_model_level(E[ctx.rec].copy(), ctx.tr)

    @staticmethod
    def _provisional_clean(ctx: FitContext, tests: list, z_crit: float) -> tuple[np.ndarray, list]:
        """The residual with the significant deterministic candidates' fits taken out, strongest
        first, each refitted on what the ones before it left (a rival of one taken out, which
        read the same excess, is then no longer significant and stays); (residual, labels)."""
        order = sorted((t for t in tests if t.kind == "effect" and t.fit is not None and np.isfinite(t.z)
                        and t.z > z_crit and get_effect(t.effect).predicts), key=lambda t: -t.z)
        cur, taken = ctx, []
        for t in order:
            eff = get_effect(t.effect)
            f = eff.test(cur, t.gyro)
            if not (np.isfinite(f.z) and f.z > z_crit):
                continue
            pred = cur.fit_prediction(eff, f)
            if pred is None:
                continue
            cur = cur.without(pred)
            taken.append(eff.name + ("" if f.gyro is None else f" on gyro {f.gyro}"))
        assert cur.E is not None
        return cur.E, taken

    def _noise(self, ctx: FitContext, tests: list, notes: list, refit: bool = True) -> dict:
        """Step 5: the model's noise terms (``refit``) and the candidates that read the stochastic record."""
        model = _model_of(ctx)
        assert ctx.E is not None                         # set by calibrate
        fits: dict[tuple[str, int | None], EffectFit] = {}
        per_gyro: list[tuple[Effect, list]] = []
        array_wide: list[tuple[Effect, list]] = []
        for eff, targets in self._candidate_effects(ctx, "noise", notes):
            (per_gyro if eff.per_gyro else array_wide).append((eff, targets))
        for g in range(1, self.N + 1):
            for e in model:
                eff = get_effect(e.effect)
                if refit and e.gyro == g and eff.kind is Kind.NOISE and not eff.predicts:
                    fits[(e.effect, g)] = eff.fit(ctx, g, ctx.E)
            for eff, targets in per_gyro:
                if g in targets:
                    self._test(ctx, eff, g, tests, notes)
        for eff, _ in array_wide:
            self._test(ctx, eff, None, tests, notes)
        for e in model:
            eff = get_effect(e.effect)
            if refit and (e.effect, e.gyro) not in fits and not eff.predicts and eff.kind is not Kind.NOISE:
                fits[(e.effect, e.gyro)] = eff.fit(ctx, e.gyro, ctx.E)
        return fits

    def _absorbed(self, model: NoiseModel) -> int:
        """The model's entries that would be candidate tests without it (an effect the ladder or
        the user fitted in): counted in the family of the analysis, so that fitting a candidate in
        does not shrink the family and raise D by itself (the same worst test over a smaller
        family's critical z: a 2.7 Hz line fitted on gyro 2 moved D 12.048 -> 12.075 while gyro 1's
        line, z 41.49, stayed the worst test). Conservative: a passed test more, never fewer."""
        n = 0
        for e in model:
            eff = get_effect(e.effect)
            if eff.candidate and not eff.baseline and e.gyro in self._targets(eff, set()):
                n += 1
        return n

    def _rank(self, ctx: FitContext, tests: list, absorbed: int = 0) -> tuple[list, float, float]:
        """Step 7: candidates by z, rivals by fit; the critical z and the discrepancy.

        The family is the finite tests and the ``absorbed`` model entries that would be
        candidates without the model (:meth:`_absorbed`)."""
        cands = sorted((t for t in tests if t.kind == "effect"),
                       key=lambda t: -t.z if np.isfinite(t.z) else math.inf)
        finite = [t.z for t in tests if np.isfinite(t.z)]
        zc = critical_z(len(finite) + absorbed, self.alpha)
        ctx.z_crit = zc
        cands = self._pipeline_explains(ctx, _rank_rivals(ctx, cands, zc))
        drop_kept(ctx)                     # the winners' predictions the rivals' tests were cut by
        worst = max(finite, default=0.0)
        return cands, zc, max(worst, 0.0) / zc

    def pipeline(self) -> PipelineReport:
        """The record's data pipeline (held samples, a brick-wall roll-off), read once on the
        outputs as recorded (:func:`~gyroarray.analysis.pipeline.detect_pipeline`)."""
        if getattr(self, "_pipeline", None) is None:
            self._pipeline = detect_pipeline(self.y, self.dt)
        return self._pipeline

    def pipeline_fit_kw(self) -> dict:
        """:func:`fit_gyro_noise`'s ``min_tau_s`` on a record decimated through a brick-wall filter:
        the Allan fits start at :attr:`PipelineReport.tau_s`, above the τ the filter shapes (no
        noise term is fitted to the processing); empty otherwise (the fits as they were)."""
        p = self.pipeline()
        return {"min_tau_s": p.tau_s} if p.filtered else {}

    def _pipeline_json(self) -> dict | None:
        """:attr:`Analysis.pipeline`: the report's JSON when the record was processed, else None."""
        p = self.pipeline()
        return p.to_json_dict() if p.processed else None

    def _pipeline_notes(self) -> list[str]:
        """The pipeline's verdict as a note (none for a record that shows no processing)."""
        p = self.pipeline()
        if not p.processed:
            return []
        if not (p.held or p.filtered):
            return [p.verdict() + " (reported only: no test is changed by it)"]
        return [p.verdict() + " (no effect is forced there: spikes next to held samples are not outliers, a "
                "low-pass at the roll-off and noise terms read only at those τ are the pipeline's, a noise "
                "change not seen below the roll-off is not a fault)"]

    def _pipeline_explains(self, ctx: FitContext, cands: list) -> list:
        """Candidates whose evidence the record's pipeline explains, marked ``explained_by``
        ("pipeline", None) with the reason (not significant of their own; they stay in D's family).

        * A causal low-pass (``Effect.lowpass``) whose cut-off lies at or above half the brick-wall
          roll-off's corner: the fit reads the decimation filter's fall.
        * A noise term read on the ADEV (its fit's ``extra["band_s"]``) only at τ where the
          processing shapes the ADEV (:attr:`PipelineReport.tau_s`: a Gauss–Markov hump or a
          flattening at the decimation filter's τ).
        * A change of the noise level (``fault_noise``, ``burst``) that is not seen where the
          processing does not act: with the held samples bridged and in the band below the
          roll-off (:func:`~gyroarray.analysis.pipeline.passband_change`, |z| < 3 on every gyro
          it names).

        Only significant candidates are read. Spikes next to held samples are left out by the
        outliers test itself."""
        pipe = self.pipeline()
        if not (pipe.held or pipe.filtered) or ctx.E is None:
            return cands                     # a resampling alone is reported, no test changed
        out = []
        for t in cands:
            if t.fit is None or t.explained_by is not None or not t.z > ctx.z_crit:
                out.append(t)
                continue
            why = None
            eff = get_effect(t.effect)
            cut = t.fit.params.get("cutoff_hz")
            band = t.fit.extra.get("band_s")
            if eff.lowpass and pipe.corner_hz is not None and isinstance(cut, (int, float)) \
                    and cut >= 0.5 * pipe.corner_hz:
                why = (f"; but the record was decimated through a brick-wall filter with its corner at "
                       f"{pipe.corner_hz:.3g} Hz: this low-pass is the processing's, not the sensor's")
            elif (isinstance(band, (list, tuple)) and len(band) == 2 and pipe.tau_s > 0
                  and float(band[1]) <= pipe.tau_s):
                why = (f"; but it is read at τ {float(band[0]):.2g}–{float(band[1]):.2g} s only, where the record's "
                       f"processing shapes the ADEV (τ below {pipe.tau_s:.2g} s): the pipeline's, not the sensor's")
            elif t.effect in (names.FAULT_NOISE, names.BURST) and "start_s" in t.fit.params:
                k0 = int(np.clip(np.searchsorted(ctx.t, float(t.fit.params["start_s"])), 0, ctx.n - 1))
                k1 = (None if "end_s" not in t.fit.params else
                      int(np.clip(np.searchsorted(ctx.t, float(t.fit.params["end_s"])), k0, ctx.n)))
                gyros = [t.gyro] if t.gyro is not None else list(range(1, self.N + 1))
                seen = [passband_change(ctx.E[:, g - 1], self.dt, k0, pipe, held=held_samples(self.y[:, g - 1]),
                                        stop=k1) for g in gyros]
                ratio, z = max(seen, key=lambda rz: rz[1])
                if z < 3.0:
                    band = (f"below {0.7 * pipe.corner_hz:.3g} Hz" if pipe.corner_hz is not None
                            else f"below {0.25 / self.dt:.3g} Hz")
                    what = "a fault" if t.effect == names.FAULT_NOISE else "a burst"
                    why = (f"; but where the processing does not act (held samples bridged, {band}) the noise "
                           f"changes by {ratio:.3g}x at most (z = {z:.1f}): the record's pipeline, not {what}")
            out.append(t if why is None else replace(t, evidence=t.evidence + why, explained_by=("pipeline", None)))
        return out

    def _record_notes(self) -> list[str]:
        """What a record without a reference rate, or with gaps, cannot show."""
        gaps = self.gap_summary()
        out = [] if gaps is None else [
            f"{gaps['gaps']} gap(s) in time_s ({gaps['missing_samples']} sample(s) missing): fitted on "
            f"its {gaps['parts']} contiguous part(s) ({gaps['samples']} samples), stitched with each part's "
            f"mean {'residual ' if self.ref is not None else ''}set to the first's for the noise (the "
            f"deterministic fits keep one free offset per part); no Allan average or random walk is read "
            f"across a gap, and times are on the stitched record"]
        if self.ref is not None:
            return out
        needing = ", ".join(e.name for e in REGISTRY.values() if "ref" in e.needs)
        if gaps is not None and not self.cut_for_motion:
            return out + [f"no reference rate: {needing} need ref_x, ref_y, ref_z"]
        if gaps is not None:
            return out + [f"no reference rate: the outputs show motion, so only their still parts, cut at "
                          f"the gaps, are diagnosed; {needing} need ref_x, ref_y, ref_z"]
        if self.parts:
            span = self.parts_s[-1][1] - self.parts_s[0][0]
            whole = self.m.time_s[-1] - self.m.time_s[0] + self.dt
            lengths = [(b - a) * self.dt for a, b in self.parts]
            return [f"no reference rate: the outputs show motion, so only their {len(self.parts)} still "
                    f"parts ({self.n * self.dt:.0f} s of the {whole:.0f} s record, {min(lengths):.0f}–"
                    f"{max(lengths):.0f} s each, over {span:.0f} s) are "
                    f"diagnosed, stitched with each part's mean set to the first's for the noise (the "
                    f"deterministic fits keep one free offset per part): times are on the "
                    f"stitched record, τ beyond a part's length and the drift between parts are not seen; "
                    f"{needing} need ref_x, ref_y, ref_z"]
        return ["no reference rate: the outputs show no motion, the record is taken as static; "
                f"{needing} need ref_x, ref_y, ref_z"]

    # -- the model ------------------------------------------------------------------
    def _entry_from_fit(self, eff: Effect, f: EffectFit, old: ModelEntry) -> ModelEntry:
        """A model entry with the fitted parameters (keeping what the fit does not set) and their 1σ."""
        try:
            params = eff.clip(eff.entry_params(f, old.params), self.N)
            return ModelEntry(old.effect, old.gyro, params, _sigma_of(f, params))
        except InputError:
            return old

    def entry_for(self, effect: str, gyro: int | None, analysis: Analysis) -> ModelEntry:
        """The model entry of a candidate, with the parameters of its fit in ``analysis``."""
        t = next((t for t in analysis.candidates if (t.effect, t.gyro) == (effect, gyro)), None)
        eff = get_effect(effect)
        ctx = analysis.context
        label = effect + ("" if gyro is None else f":{gyro}")
        named = ctx is not None and any(c.gyro == gyro and c.fit is not None and c.fit.extra.get("tested_as") == effect
                                        for c in analysis.candidates)
        if t is not None and t.fit is not None:
            f = t.fit
        elif (not eff.candidate or named) and ctx is not None:
            # fitted on request only, or its test named another effect (a line whose phase
            # wanders, tested as a sinusoid, named a narrowband line): fitted as asked
            f = self._fitted(ctx, eff, gyro, analysis.residual_rad_s)
        else:
            why = None if ctx is None else eff.why_not(ctx)
            if why:
                raise InputError(f"cannot add {effect}: it {why}", file=self.name)
            if (effect, gyro) in {(e.effect, e.gyro) for e in analysis.model}:
                raise InputError(f"cannot add {label}: it is already in the model", file=self.name)
            raise InputError(f"cannot add {label}: it is not identifiable on this record "
                             "(see the notes of diagnose)", file=self.name)
        params = eff.clip(eff.entry_params(f, {}), self.N)
        return ModelEntry(effect, gyro, params, _sigma_of(f, params))

    def _adev_band(self, cal: NoiseModel, E: np.ndarray, rec: slice):
        """Measured ADEV vs the model's Monte-Carlo band, one test per gyro."""
        x = E[rec]
        n = x.shape[0]
        m = averaging_factors(n + 1, self.dt)
        m = m[m <= n // 10]
        # what each calibrated entry puts into the band (Effect.band_entries)
        band_ctx = self._context(cal)
        band_ctx.E, band_ctx.rec = E, rec
        sub = NoiseModel(tuple(b for e in cal for b in get_effect(e.effect).band_entries(band_ctx, e)))
        taus = m * self.dt
        meas = np.array([oadev(x[:, g], self.dt, taus=taus).dev for g in range(self.N)])
        tr = self.t_sim[rec]
        # the measurement's own reference rates (quantization sees them); noise = output − H·ref
        truth = self.ref[rec] if self.ref is not None else np.zeros((n, 3))
        sensed = truth @ self.H.T
        # what the band's own deterministic entries make of the reference (a filter's lag on the
        # motion): taken out like the model's deterministic part is taken out of the measurement
        det = NoiseModel(tuple(e for e in sub if get_effect(e.effect).predicts))
        if len(det.entries):
            sensed = simulate_readings(det, truth, self.H, self.dt, np.random.default_rng(0), time_s=tr)
        nperseg = min(default_nperseg(self.n), n)

        inputs = sim_context(truth, self.H, self.dt, time_s=tr)          # checked once for every run

        def one_run(k: int) -> tuple[np.ndarray, np.ndarray]:
            """Run k of the band: the ADEV of each gyro (N, taus) and its Welch PSD (N, freqs)."""
            rng = np.random.default_rng([self.seed, k])
            s = simulate_on(sub, inputs, rng) - sensed
            if rec == slice(0, self.n):
                s = self._like_parts(s)
            dev = np.array([oadev(s[:, g], self.dt, taus=taus).dev for g in range(self.N)])
            return dev, residual_psd(s, self.dt, nperseg)[1]

        runs = map_runs(one_run, self.n_runs, self._workers(n))
        mc = np.array([r[0] for r in runs])
        psds = [r[1] for r in runs]
        f_hz = np.fft.rfftfreq(nperseg, self.dt)
        tests = []
        M = self.n_runs
        L = np.log(mc)
        mu = L.mean(axis=0)
        sd = L.std(axis=0, ddof=1) * math.sqrt(1.0 + 1.0 / M)
        tq = stats.t.ppf(0.975, M - 1)
        for g in range(self.N):
            tk = (np.log(meas[g]) - mu[g]) / sd[g]
            log_p = math.log(2.0) + stats.t.logsf(np.abs(tk), M - 1)       # two-sided, in logs
            log_pmin = float(np.min(log_p))
            pmin = math.exp(log_pmin)
            log_pg = (math.log(-math.expm1(taus.size * math.log1p(-min(pmin, 1 - 1e-16)))) if pmin > 1e-12
                      else log_pmin + math.log(taus.size))
            z = z_from_log_p(log_pg)
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
        psd = np.array(psds)
        band = {"taus_s": taus, "measured": meas, "mc": mc,
                "lo": np.exp(mu - tq * sd), "hi": np.exp(mu + tq * sd), "median": np.exp(mu),
                "psd_freq_hz": f_hz, "psd_nperseg": nperseg, "psd_mean": psd.mean(axis=0),
                "psd_lo": np.quantile(psd, 0.025, axis=0), "psd_hi": np.quantile(psd, 0.975, axis=0)}
        return band, tests

    # -- where it fails -------------------------------------------------------
    def localise(self, a: Analysis, force: bool = False) -> Analysis:
        """Localise what the model leaves (:func:`gyroarray.chain.localise.localise`); sets
        ``a.localisation`` and ``a.localised`` and returns ``a``.

        Run when the model is not consistent (or ``force``). The residual is
        the analysis's: output − H·ref − the calibrated model's deterministic
        prediction, every gyro, the whole record; the ADEV band is the
        analysis's Monte-Carlo band over the samples it describes, the model
        PSD the mean Welch PSD of the same runs (so every noise effect of the
        model is in it); the channels are what the record has (H·ref, its
        square and derivative, ``acc_*``, temperature and dT/dt, time). A
        low-pass that the library's ``bandwidth`` would model in magnitude but
        that does not lag on motion is said so (a zero-phase filter, outside
        the causal ``bandwidth``).
        """
        if a.consistent and not force:
            a.localisation, a.localised = [], None
            return a
        band = a.adev
        loc = localise_residual(a.residual_rad_s, self.dt, time_s=self.t, taus_s=band["taus_s"],
                                band_lo=band["lo"], band_hi=band["hi"], band_samples=a.record,
                                model_psd=band["psd_mean"], nperseg=band["psd_nperseg"],
                                rate=None if self.ref is None else self.ref @ self.H.T,
                                acc=self.acc, temp_c=self.temp, alpha=self.alpha)
        a.localised = loc
        a.localisation = [_finding_dict(f, a) for f in loc.findings]
        return a

    def _mimics(self, a: Analysis, notes: list) -> set:
        """(effect, gyro) the ladder must not add: on a gyro whose spectrum a non-causal low-pass
        shapes (the localisation of ``a``), every effect that reads the noise, and the rivals of
        ``bandwidth``, would only mimic a filter the library does not have."""
        self.localise(a)
        gyros = sorted({g for f in a.localisation if f["kind"] == "lowpass"
                        and f["details"].get("causal") is False for g in f["gyros"]})
        if not gyros:
            return set()
        rivals = {r for name in _lowpass_effects() for r in (name, *get_effect(name).rivals)}
        out = set()
        for t in a.candidates:
            eff = get_effect(t.effect)
            mimic = eff.reads == "noise" or t.effect in rivals
            if mimic and (t.gyro in gyros or (t.gyro is None and eff.changes_adev)):
                out.add((t.effect, t.gyro))
        note = (f"the ladder adds no noise effect on gyro{'s' if len(gyros) > 1 else ''} "
                f"{', '.join(map(str, gyros))}: a low-pass that does not lag on motion (not causal) shapes "
                "its spectrum, which no effect of the library models (see where it fails)")
        if out and note not in notes:
            notes.append(note)
        return out

    # -- the user's loop ------------------------------------------------------
    def diagnose(self) -> Analysis:
        """The calibrated model's analysis, localised where no effect explains it."""
        clear_all()                              # what it returns never depends on the calls before
        return self.localise(self.analyse())

    def steps_to_model(self) -> list[tuple[tuple | None, Analysis]]:
        """The error falling from the baseline to this comparison's model, one effect at a time.

        ``[(None, baseline), ((effect, gyro), baseline + the effects so far), ...]``
        in the model's order (what ``compare --model`` reports); just
        ``[(None, analysis)]`` when the model is the baseline.
        """
        clear_all()
        base = [e for e in self.model if get_effect(e.effect).baseline]
        extra = [e for e in self.model if not get_effect(e.effect).baseline]
        model = NoiseModel(tuple(base), description=self.model.description, source=self.model.source)
        steps: list[tuple[tuple | None, Analysis]] = [(None, self.analyse(model))]
        for e in extra:
            model = model.with_effect(e)
            steps.append(((e.effect, e.gyro), self.analyse(model)))
        self.localise(steps[-1][1])
        return steps

    def fit(self, add=()) -> tuple[Analysis, Analysis]:
        """(before, after): the model calibrated, then with the ``add`` effects fitted in."""
        clear_all()
        before = self.analyse()
        model = self.model
        for effect, gyro in add:
            if (effect, gyro) in {(e.effect, e.gyro) for e in model}:
                continue
            model = model.with_effect(self.entry_for(effect, gyro, before))
        after = self.analyse(model) if model is not self.model else before
        return before, after

    def ladder(self, max_steps: int = 8, max_tries: int = 6) -> list[tuple[tuple | None, Analysis]]:
        """[(added (effect, gyro) or None, analysis), ...]: add the best significant candidate until consistent.

        One rule keeps a step and refuses one (:func:`ladder_improves`, stated
        as :data:`LADDER_RULE` in the output): a step is kept only if it
        lowers the discrepancy D, or leaves D exactly where it was (its worst
        test is one the step does not touch; the Monte-Carlo band draws each
        effect and gyro from its own keyed stream, so an untouched test keeps
        its z, and a candidate fitted in stays in the family, :meth:`_absorbed`)
        and lowers the excess Σ (z − z_crit)² of the significant tests
        ("where it was": within :data:`LADDER_TIE`, the BLAS summation order's
        last bits, which the thread count changes).
        D therefore never rises at a kept step (beyond that), and the last step is the best
        model the ladder saw: every analysis it tried and refused had a
        larger (D, excess), every one it kept a smaller one than the step
        before. (Before, a step could raise D by up to 2 %, and on a thermal
        record with a one-minute knock five such steps took D from 35.73 to
        36.23.)

        **The best step.** At each step every eligible candidate is tried
        (the ``max_tries`` most significant that were not refused at a z
        within 1 of their present one, and the refused ones due for another
        try), each as a whole analysis, and of those that improve the one
        that lowers D most is kept (:func:`best_step`: D's within
        :data:`LADDER_BEST_TIE` relative are tied, then the lower excess,
        then the higher-ranked candidate: a choice that does not hang on the
        BLAS summation order's last bits). A trial that makes the model
        consistent ends the search (the consistency criterion stops the
        ladder; its D ≤ 1 is below that of every trial before it, which
        were not consistent): the candidates after it are not tried. On
        ``benchmarks/bench_compare.py`` the scale factor of gyro 5, tried
        first, is consistent at once; trying the four other significant
        candidates too (13 s each) would take the ladder from 31 to about
        85 s against its 60 s target. Before, the first candidate that
        improved was kept: on the MPU-6050 record small D falls
        (quantization, narrowband lines, misalignment) used up the steps
        before the scale factor of gyro 3 was tried. The step's note names
        the improving candidates it passed over, with their D. A refusal
        is noted in the last analysis's ``notes``. A refused candidate is tried again when its z
        has grown by more than 1, or, once a later step has been kept, when
        its refused trial took out at least :data:`LADDER_RETRY_SHARE` of its
        gyro's residual variance (of the whole array's for an array-wide
        effect): a large deterministic part displaced by the steps before it
        (a temperature term refused while a knock's side effects dominated)
        gets its chance after them. A refused candidate whose test has become
        the worst one (its z sets D) is tried again too: it was refused while
        another test set D (on the MPU-6050 record gyro 2's line, z 151, raised
        D from 61.74 to 61.87 at the second step and then, untouched, set D at
        43.6 for every step after). Each try is a whole analysis (on the
        ADIS16405 a bias instability on gyro 3, refused at every step, took
        the ladder from 65 to 116 s), so a candidate that explains little
        waits for its z to grow. Six tries a step, not three: on the MPU-6050
        record the three first (gyro 2's short-τ excess, read as
        quantization, a hump or a filter) make D worse, and with three tries
        the ladder stopped before the scale factor of gyro 3.
        """
        clear_all()                              # a ladder starts from empty caches (memo.clear_all)
        steps: list[tuple[tuple | None, Analysis]] = [(None, self.analyse())]
        model = self.model
        refused: list[str] = []
        refused_z: dict = {}                     # (effect, gyro) -> z when last refused
        share: dict = {}                         # (effect, gyro) -> variance share of its refused trial
        retry: set = set()                       # refused with a large share, a step kept since
        chosen: list[str] = []                   # the steps that beat other improving trials
        for _ in range(max_steps):
            cur = steps[-1][1]
            if cur.consistent:
                break
            taken = None
            blocked = self._mimics(cur, refused)
            eligible = [t for t in cur.candidates if cur.significant(t)
                        and (t.effect, t.gyro) not in blocked]
            fresh = [t for t in eligible
                     if t.z > refused_z.get((t.effect, t.gyro), -math.inf) + 1.0][:max_tries]
            tried = {(t.effect, t.gyro) for t in fresh}
            # refused ones due again: a large share displaced by the steps since, or the worst test
            # now (its z sets D; it was refused while another test set it)
            worst = cur.discrepancy * cur.z_crit * (1.0 - LADDER_BEST_TIE)
            again = [t for t in eligible if (t.effect, t.gyro) not in tried
                     and ((t.effect, t.gyro) in retry or ((t.effect, t.gyro) in refused_z and t.z >= worst))]
            kept: list = []                      # (rank, key, trial) of every trial that improves
            for rank, t in enumerate(fresh + again):
                key = (t.effect, t.gyro)
                trial = self.analyse(model.with_effect(self.entry_for(t.effect, t.gyro, cur)))
                retry.discard(key)
                if ladder_improves(cur, trial):
                    kept.append((rank, key, trial))
                    if trial.consistent:         # the ladder's goal: it stops here (below every other D tried)
                        break
                    continue
                refused_z[key] = t.z
                share[key] = _variance_share(cur, trial, t.gyro)
                refused.append(f"the ladder did not add {t.effect}"
                               + ("" if t.gyro is None else f" on gyro {t.gyro}") + ": "
                               + _refusal_text(cur, trial, share[key]))
            if kept:
                taken = best_step(kept)
                if len(kept) > 1:
                    chosen.append(_passed_text(cur, taken, kept))
            if taken is None:
                break
            steps.append(taken)
            model = taken[1].model
            retry |= {k for k, v in share.items() if v >= LADDER_RETRY_SHARE and k != taken[0]}
        if refused or chosen:
            steps[-1][1].notes.extend(chosen + refused)
        self.localise(steps[-1][1])
        return steps


#: σ of the pooled white reading at 1 s within which a stitched record's Allan fit keeps its own N
#: (:meth:`ModelComparison.white_level`) [-].
WHITE_AGREE = 2.0


#: The ladder's rule, as its output states it (:func:`ladder_improves`).
LADDER_RULE = ("a step is kept only if it lowers the discrepancy D, or leaves D unchanged and lowers "
               "the excess (the sum of (z - z_crit)^2 over the significant tests); of the candidates "
               "tried at a step (the 6 most significant, and those tried again; a trial that makes the "
               "model consistent ends the search) the one that lowers D most is taken (D's within 1e-6 "
               "relative are tied: then the lower excess, then the higher-ranked candidate); D never "
               "rises at a kept step, and the last step is the best model the ladder saw")

#: Share of a gyro's residual variance that a refused ladder candidate took out in its trial
#: from which it is tried again after a later step is kept (a large deterministic part).
LADDER_RETRY_SHARE = 0.10


#: Relative difference within which two trials' D (then their excess) are one level when the ladder
#: picks its best step (:func:`best_step`): far above the BLAS summation order's last bits (2.3e-13
#: relative between 1 and 8 OpenBLAS threads, :data:`LADDER_TIE`) and far below a step that means
#: anything (the smallest real one seen moved D by 4e-3 relative; D's own Monte-Carlo sd at 40 runs
#: is of order 1e-2): two candidates this close explain the record equally well, and the higher-ranked
#: one (the larger z) is taken, so the choice does not hang on the last bits.
LADDER_BEST_TIE = 1e-6


def best_step(kept: list) -> tuple:
    """The ladder's step among the trials that improve (:func:`ladder_improves`): the one that lowers D most.

    ``kept`` is ``[(rank, (effect, gyro), trial), ...]``, ``rank`` the candidate's place in
    the order the ladder tried them (the current analysis's ranking, largest z first, then the
    candidates tried again). The rule: the lowest D; trials within :data:`LADDER_BEST_TIE`
    (relative) of it are tied, and among them the lowest excess Σ (z − z_crit)², again
    within :data:`LADDER_BEST_TIE`; what is still tied goes to the lowest rank. Returns
    ``((effect, gyro), trial)``.
    """
    if not kept:
        raise ValueError("best_step needs at least one improving trial")

    def near(a: float, b: float) -> bool:
        return a == b or abs(a - b) <= LADDER_BEST_TIE * max(abs(a), abs(b))
    d_min = min(tr.discrepancy for _, _, tr in kept)
    low = [k for k in kept if near(k[2].discrepancy, d_min)]
    e_min = min(tr.excess for _, _, tr in low)
    low = [k for k in low if near(k[2].excess, e_min)]
    rank, key, trial = min(low, key=lambda k: k[0])
    return key, trial


def _label(key) -> str:
    return key[0] + ("" if key[1] is None else f" on gyro {key[1]}")


def _passed_text(cur: Analysis, taken: tuple, kept: list) -> str:
    """The note of a step that beat other improving trials: each one's D (or excess, when D stayed)."""
    others = sorted((k for k in kept if k[1] != taken[0]), key=lambda k: (k[2].discrepancy, k[0]))
    return (f"the ladder added {_label(taken[0])} (D {cur.discrepancy:.4g} -> {taken[1].discrepancy:.4g}, "
            f"excess {taken[1].excess:.4g}), the largest fall of the {len(kept)} candidates that lowered it; "
            "passed over: " + "; ".join(f"{_label(k[1])} (D {k[2].discrepancy:.4g}, excess {k[2].excess:.4g})"
                                        for k in others))


def ladder_improves(cur: Analysis, trial: Analysis) -> bool:
    """The ladder's one rule (:data:`LADDER_RULE`): does ``trial`` improve on ``cur``?

    True when D falls, or D stays exactly as it was and the excess
    Σ (z − z_crit)² of the significant tests falls (the pair (D, excess),
    compared in that order, falls). "Stays" and "falls" are read beyond
    :data:`LADDER_TIE` (relative): two D's that differ only by the BLAS
    summation order are one D, so the decision does not depend on the
    thread count.
    """
    d0, d1 = cur.discrepancy, trial.discrepancy
    if not math.isfinite(d1):
        return False
    if not _same_level(d0, d1):
        return d1 < d0
    return bool(trial.excess < cur.excess and not _same_level(cur.excess, trial.excess))


#: Relative difference within which two analyses' D (or excess) are the same number: an untouched
#: test recomputed in a trial keeps its z only up to the summation order of the BLAS products
#: around it, which the thread count changes (the MPU-6050 ladder at 1 and 8 OpenBLAS threads:
#: D apart by at most 2.3e-13 relative, the excess by 1.3e-13); the smallest step it took moved
#: D by 4e-3 and the excess by 5e-3 relative. 1e-9 is four orders above the one, six below the other.
LADDER_TIE = 1e-9


def _same_level(a: float, b: float) -> bool:
    """``a`` and ``b`` equal within :data:`LADDER_TIE` (relative): one D, or one excess, for the ladder."""
    return a == b or abs(a - b) <= LADDER_TIE * max(abs(a), abs(b))


def _variance_share(cur: Analysis, trial: Analysis, gyro: int | None) -> float:
    """Share of the residual variance (of ``gyro``, or every gyro) that ``trial`` took out of ``cur``'s."""
    cols = slice(None) if gyro is None else slice(gyro - 1, gyro)
    before = float(np.var(cur.residual_rad_s[:, cols]))
    after = float(np.var(trial.residual_rad_s[:, cols]))
    if not (before > 0.0 and math.isfinite(after)):
        return 0.0
    return max(0.0, 1.0 - after / before)


def _refusal_text(cur: Analysis, trial: Analysis, share: float) -> str:
    """Why the ladder refused a step: D (and the excess where D stays), and a large variance share."""
    if _same_level(trial.discrepancy, cur.discrepancy):
        text = (f"the discrepancy would stay at {cur.discrepancy:.4g} and the excess would go from "
                f"{cur.excess:.4g} to {trial.excess:.4g}")
    else:
        text = (f"the discrepancy would go from {cur.discrepancy:.4g} to {trial.discrepancy:.4g}")
    if share >= LADDER_RETRY_SHARE:
        text += (f" (it takes out {100 * share:.0f} % of the residual variance: tried again after "
                 "any later step the ladder keeps)")
    return text


def _frozen(v):
    """A hashable stand-in of one parameter value (numbers, strings, sequences, arrays by content)."""
    if isinstance(v, (list, tuple)):
        return tuple(_frozen(x) for x in v)
    key = content_key(v)
    if key is None:
        raise TypeError
    return type(v).__name__, key[0]                 # 1, 1.0 and True apart


def _entry_key(entry: ModelEntry):
    """(effect, gyro, parameters) of an entry as a dict key, or None (a value that is not plain)."""
    try:
        return (entry.effect, entry.gyro, tuple((k, _frozen(v)) for k, v in sorted(entry.params.items())))
    except TypeError:
        return None


class _KeptSim:
    """One entry's simulated contribution (n, N) kept by its live columns (the others +0.0)."""

    __slots__ = ("shape", "cols", "values")

    def __init__(self, x: np.ndarray):
        self.shape = x.shape
        live = np.flatnonzero(np.ascontiguousarray(x).view(np.uint64).any(axis=0)) if x.ndim == 2 \
            else np.arange(0)
        self.cols = None if x.ndim != 2 or live.size == x.shape[1] else live
        self.values = np.array(x if self.cols is None else x[:, self.cols])

    @property
    def nbytes(self) -> int:
        return int(self.values.nbytes)

    def dense(self) -> np.ndarray:
        if self.cols is None:
            return self.values.copy()
        out = np.zeros(self.shape)
        out[:, self.cols] = self.values
        return out


class _KeptSims:
    """The latest entries' contributions, within :data:`KEPT_SIMS_BYTES`."""

    def __init__(self):
        self._d: dict = {}

    def get(self, key):
        hit = self._d.pop(key, None)
        if hit is not None:
            self._d[key] = hit                      # the latest last
        return hit

    def put(self, key, x: np.ndarray) -> None:
        if x.dtype != np.float64:
            return
        kept = _KeptSim(x)
        self._d.pop(key, None)
        self._d[key] = kept
        while len(self._d) > 1 and sum(v.nbytes for v in self._d.values()) > KEPT_SIMS_BYTES:
            self._d.pop(next(iter(self._d)))


#: Memory the kept entry simulations may hold [bytes] (:meth:`ModelComparison.simulate_entry`).
KEPT_SIMS_BYTES = 64 * 2 ** 20


class _Services:
    """What a :class:`FitContext` asks the comparison for (kept apart so effects never import the chain)."""

    def __init__(self, comp: ModelComparison, ctx: FitContext):
        # the context by a weak reference: ctx.services -> self -> ctx would be a cycle, and a
        # context the ranking cuts (its E and Er, two copies of the record) would wait for the
        # garbage collector, not its last reference (1.1 GB of them on a 46 min, 6-gyro record)
        self.comp, self._ctx = comp, weakref.ref(ctx)
        self._noise: dict = {}

    @property
    def ctx(self) -> FitContext:
        ctx = self._ctx()
        assert ctx is not None                 # asked through the context, which is alive
        return ctx

    def attitude(self):
        return self.comp.attitude()

    def effect(self, name: str) -> Effect:
        return get_effect(name)

    def model_entry(self, effect: str, gyro: int | None, params) -> ModelEntry:
        return ModelEntry(effect, gyro, params)

    def simulate_entry(self, entry: ModelEntry) -> np.ndarray:
        return self.comp.simulate_entry(entry)

    def noise_rq(self, e: np.ndarray, gyro: int) -> tuple[float, float]:
        return self.comp._noise_rq(e, gyro)

    def fitted(self, eff: Effect, gyro: int | None, E: np.ndarray) -> EffectFit:
        return self.comp._fitted(self.ctx, eff, gyro, E)

    def _terms(self, gyro: int) -> list:
        return [e for e in _model_of(self.ctx) if e.gyro == gyro and get_effect(e.effect).kind is Kind.NOISE
                and not get_effect(e.effect).baseline and not get_effect(e.effect).predicts]

    def gyro_noise(self, gyro: int) -> dict:
        """The gyro's Allan fit on the stochastic record with the model's noise terms (cached)."""
        if gyro not in self._noise:
            assert self.ctx.Er is not None               # set by the stochastic-record step
            fl = fit_gyro_noise(self.ctx.Er[:, gyro - 1], self.comp.dt, gyro,
                                **_noise_term_kwargs(self.ctx, _model_of(self.ctx), gyro),
                                **self.comp.pipeline_fit_kw())
            fits = {f.effect: f for f in fl}
            if len(self.comp.parts) > 1 and self.ctx.E is not None and names.ARW in fits:
                # stitched still parts: the model's white level is the one every command reads,
                # pooled over all the parts (ModelComparison.pooled_white), not the one part's
                f = fits[names.ARW]
                e = self.ctx.E[:, gyro - 1]
                n, pooled = self.comp.white_level(float(arw_deg_rt_h_to_rad_rt_s(f.params["n_deg_rt_h"])), e)
                if pooled:
                    sn = self.comp.pooled_white(e)[1]
                    fits[names.ARW] = replace(
                        f, params={**f.params, "n_deg_rt_h": float(arw_rad_rt_s_to_deg_rt_h(n))},
                        sigma={**f.sigma, "n_deg_rt_h": float(arw_rad_rt_s_to_deg_rt_h(sn))},
                        extra={**f.extra, "allan_fit_n_deg_rt_h": f.params.get("n_deg_rt_h"),
                               "white_level": "ADEV(1 s)·√(1 s) pooled over the still parts (the Allan "
                                              f"fit's N is more than {WHITE_AGREE:g}σ from it)"})
            self._noise[gyro] = fits
        return self._noise[gyro]

    def specific_force(self) -> np.ndarray:
        return self.comp.specific_force()

    def derive(self, ctx: FitContext) -> "_Services":
        return _Services(self.comp, ctx)

    def noise_terms(self, gyro: int) -> list:
        return [self.gyro_noise(gyro)[e.effect] for e in self._terms(gyro)
                if e.effect in self.gyro_noise(gyro)]


def _rank_rivals(ctx: FitContext, cands: list, z_crit: float) -> list:
    """Order rivals for the same excess on one gyro by how well they fit it, not by z.

    Rivals (``Effect.rivals``) are both significant when either is present:
    each soaks up part of the other's excess (a bias instability and a
    Gauss–Markov hump; a scale factor and a tilted axis; a curvature that
    also looks like a slope; a warm-up temperature and a rate ramp). Among
    the significant rivals of one gyro, an effect ranks above another it
    declares as a rival when its :meth:`~gyroarray.effects.protocol.Effect.prefer`
    gives a reason; the winner takes the place of the first of them and each
    one it beats says why it ranks lower. A reason that is an
    :class:`~gyroarray.effects.protocol.Explained` (with the winner taken out the
    rival's test is no longer significant) marks the rival ``explained_by`` the
    winner: it is then not a significant candidate of its own. (On the scoring runs of
    benchmarks/diagnosis_score.py: true B gave χ² 9–13 against 26–42 for the
    hump; a true hump 4–10 against 59–158 for the flat term, on 11 dof.)
    """
    out = list(cands)
    cache: dict = {}

    def beats(a: Test, b: Test) -> str | None:
        # candidates with a fit (sig below): effect tests, their effect named
        assert a.effect is not None and b.effect is not None and a.fit is not None and b.fit is not None
        key = (a.effect, a.gyro, b.effect, b.gyro)
        if key not in cache:
            ea, eb = get_effect(a.effect), get_effect(b.effect)
            if b.effect in ea.rivals:
                cache[key] = ea.prefer(a.fit, b.fit, ctx)
            elif a.effect in eb.rivals:                  # only b names a: b decides both ways
                cache[key] = eb.concede(b.fit, a.fit, ctx)
            else:
                cache[key] = None
        return cache[key]

    def related(a: Test, b: Test) -> bool:
        assert a.effect is not None and b.effect is not None   # candidates: effect tests
        return b.effect in get_effect(a.effect).rivals or a.effect in get_effect(b.effect).rivals

    sig = [i for i, t in enumerate(out) if t.fit is not None and np.isfinite(t.z) and t.z > z_crit]
    seen: set = set()
    for i in sig:
        if i in seen:
            continue
        group, todo = [i], [i]                     # the connected rivals of out[i] on its gyro
        while todo:
            k = todo.pop()
            for j in sig:
                same = out[j].gyro == out[k].gyro or out[j].gyro is None or out[k].gyro is None
                if j not in group and same and related(out[k], out[j]):
                    group.append(j)
                    todo.append(j)
        seen |= set(group)
        if len(group) < 2:
            continue
        positions = sorted(group)
        remaining = [out[p] for p in positions]
        ordered, noted = [], set()
        while remaining:
            champ = remaining[0]
            for other in remaining[1:]:
                if beats(other, champ):
                    champ = other
            ordered.append(champ)
            rest = []
            for t in remaining:
                if t is champ:
                    continue
                why = beats(champ, t)
                if why and (t.effect, t.gyro) not in noted:
                    noted.add((t.effect, t.gyro))
                    t = replace(t, evidence=t.evidence + why,
                                explained_by=(champ.effect, champ.gyro) if isinstance(why, Explained) else None)
                rest.append(t)
            remaining = rest
        for p, t in zip(positions, ordered):
            out[p] = t
    return out


@by_content(maxsize=16)
def _ml_q(e: np.ndarray, r: float, use: np.ndarray, breaks: np.ndarray | None = None) -> float:
    """Maximum-likelihood random-walk increment variance q of ``e`` on the ``use`` samples, r fixed
    (``breaks``: first samples of stitched parts, no increment taken across them).

    Cached by content: a ladder step leaves most gyros' residuals as they were (0.14 s per call
    on 1e6 samples, six calls per analysis of the ADIS16405)."""
    w = RWWhitener(e.size, r, r, use, breaks)       # the differences and their links, built once

    def nll(lq):
        # RWWhitener(e.size, r, exp(lq), use, breaks): its whitened e and log det, the same bits
        z, logdet = w.whiten_at(e, r, math.exp(lq))
        return 0.5 * (logdet + float(z @ z))
    lo, hi = math.log(1e-12 * r), math.log(r) + 3.0
    res = optimize.minimize_scalar(nll, bounds=(lo, hi), method="bounded", options={"xatol": 0.05})
    return float(math.exp(res.x))


def split_measurement(m: Measurement, fraction: float) -> tuple[Measurement, Measurement]:
    """The first (1 − ``fraction``) of a record and the rest, by samples (``ladder --holdout``).

    Raises InputError for a fraction outside (0, 1) or a part too short to analyse.
    """
    if not 0.0 < fraction < 1.0:
        raise InputError(f"--holdout must be a fraction in (0, 1), got {fraction:g}")
    n = m.time_s.size
    k = int(round(n * (1.0 - fraction)))
    if min(k, n - k) < MIN_STATIC:
        raise InputError(f"--holdout {fraction:g} leaves a part of {min(k, n - k)} samples; each part "
                         f"needs at least {MIN_STATIC} (a static part to calibrate on)", file=m.source)

    def part(a, b, what):
        return replace(m, time_s=m.time_s[a:b], gyro_deg_s=m.gyro_deg_s[a:b],
                        ref_deg_s=None if m.ref_deg_s is None else m.ref_deg_s[a:b],
                        temp_c=None if m.temp_c is None else m.temp_c[a:b],
                        acc_m_s2=None if m.acc_m_s2 is None else m.acc_m_s2[a:b],
                        source=f"{m.source or 'measurement'} ({what})")
    t = m.time_s
    return (part(0, k, f"{t[0]:.0f}–{t[k - 1]:.0f} s, fitted"),
            part(k, n, f"{t[k]:.0f}–{t[-1]:.0f} s, held out"))



#: Candidates whose held-out D the structure verdict of ``ladder --holdout`` reads at most
#: (:func:`holdout_candidates`; each costs a whole analysis of the fitted part and a validation of
#: the held-out one), as many as the ladder tries at a step.
HOLDOUT_TRIES = 6


def holdout_candidates(comp: ModelComparison, final: Analysis, held: Measurement, *,
                       held_out: Analysis | None = None, max_tries: int = HOLDOUT_TRIES,
                       ref_smooth_s: float = 0.0) -> list[dict]:
    """What lowers the held-out D most: each candidate fitted in on the fitted part, then validated held out.

    The candidates are the fitted part's significant ones (``final``, the ladder's last
    analysis, in its ranking), then the held-out part's significant ones that the fitted part
    can fit (``held_out``: the ladder's model validated there), at most ``max_tries`` in
    all. Each is added to ``final``'s model, the model recalibrated on the fitted part
    (:meth:`ModelComparison.analyse`, as a ladder step) and its parameters, fixed, validated on
    ``held`` (:meth:`ModelComparison.validate`, as ``compare --validate``).

    Parameters
    ----------
    comp : ModelComparison
        The comparison of the fitted part (the one the ladder ran on).
    final : Analysis
        The ladder's last analysis on the fitted part.
    held : Measurement
        The held-out part of the record.
    held_out : Analysis, optional
        The ladder's model validated on ``held`` (its significant candidates are tried too).
    max_tries : int
        Candidates tried at most [-].
    ref_smooth_s : float
        The held-out comparison's reference smoothing [s] (``--ref-smooth``, as the fitted part's).

    Returns
    -------
    list of dict
        ``effect``, ``gyro`` (None: array-wide), ``fitted_discrepancy`` and
        ``holdout_discrepancy`` [-] (D of the fitted part with the candidate, and of the
        held-out part under that model; NaN where the candidate could not be fitted, with
        ``why``), lowest held-out D first (ties within :data:`LADDER_BEST_TIE` relative by
        the order tried).
    """
    order: list = []
    for t in final.candidates:
        if final.significant(t) and (t.effect, t.gyro) not in order:
            order.append((t.effect, t.gyro))
    have = {(e.effect, e.gyro) for e in final.model}
    own = {(t.effect, t.gyro) for t in final.candidates if t.fit is not None}
    if held_out is not None:
        for t in held_out.candidates:
            key = (t.effect, t.gyro)
            if held_out.significant(t) and key not in order and key not in have and key in own:
                order.append(key)
    rows = []
    for rank, (effect, gyro) in enumerate(order[:max_tries]):
        row = {"effect": effect, "gyro": gyro, "fitted_discrepancy": math.nan,
               "holdout_discrepancy": math.nan, "rank": rank}
        try:
            trial = comp.analyse(final.model.with_effect(comp.entry_for(effect, gyro, final)))
            row["fitted_discrepancy"] = float(trial.discrepancy)
            model = NoiseModel(trial.model.entries, description=f"the ladder on {comp.name} + {_label((effect, gyro))}")
            v = ModelComparison(held, model, n_runs=comp.n_runs, seed=comp.seed, alpha=comp.alpha,
                                ref_smooth_s=ref_smooth_s, workers=comp.workers)
            row["holdout_discrepancy"] = float(v.validate().discrepancy)
        except InputError as err:
            row["why"] = err.message
        rows.append(row)

    def d_of(r):
        d = r["holdout_discrepancy"]
        return d if math.isfinite(d) else math.inf
    best = sorted(rows, key=lambda r: (d_of(r), r["rank"]))
    if best and math.isfinite(d_of(best[0])):              # ties at the best by the order tried
        d0 = d_of(best[0])
        tied = [r for r in best if math.isfinite(d_of(r))
                and abs(d_of(r) - d0) <= LADDER_BEST_TIE * max(abs(d0), abs(d_of(r)))]
        rest = [r for r in best if r not in tied]
        best = sorted(tied, key=lambda r: r["rank"]) + rest
    for r in best:
        del r["rank"]
    return best
