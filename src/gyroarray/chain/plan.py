"""How long to record: the record length at which each noise coefficient reaches a precision.

``gyroarray plan`` answers "how long must I record for ±10 % on K?" with the machinery
``gyroarray allan`` uses for its confidence intervals: the Allan variance of the model at the
octave averaging times of a record of length T, the equivalent degrees of freedom of each
point (:func:`gyroarray.analysis.allan.edf`, Greenhall's algorithm for sampled phase), the
correlation between the points and the generalised least-squares noise fit
(:func:`gyroarray.analysis.noise_fit.fit_noise_terms`). Fed the *noise-free* curve of the
model, that fit returns the model's coefficients exactly and, as their 1σ, the spread the
same fit would have on records of length T (its z-scores have standard deviations of
0.94-1.02 on simulated gyros: ``tests/test_allan_fit.py``; ``tests/test_plan.py`` checks the
prediction against the spread of fits on simulated records).

The half-width of a two-sided interval at confidence c is ``z·σ``, ``z = √2·erfinv(c)``
(1 at the 68.3 % of ``allan``'s bands). The 1σ falls about as 1/√T, in steps as octaves are
added; the length is found by iterating ``T ← T·(σ_rel/precision)²`` and keeping the
shortest length tried that meets the precision.

The accelerometer (``plan --sensor acc``) is planned the same way: its velocity random walk
N_a [m/s/√s], bias instability B [m/s²] and acceleration random walk K_a [m/s²/√s] have the
Allan variance of the gyro's N, B and K (IEEE Std 1293 and 952 share the power laws), and
``allan --sensor acc`` fits them with the same GLS fit (:mod:`gyroarray.analysis.accel`); only
the names and datasheet units differ (:data:`ACC_TERM_NAMES`).

The prediction is that of a fit of the planned terms only (the terms with a positive value):
the fit of a record that also has to find terms the plan leaves out scatters more.

SI inside (rad/s or m/s², s); datasheet units only in :meth:`Plan.to_json_dict`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from gyroarray.analysis.accel import ACC_TERMS
from gyroarray.analysis.allan import ONE_SIGMA, AllanResult, averaging_factors, edf
from gyroarray.analysis.noise_fit import fit_noise_terms, term_basis
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.effects.names import ARW, BIAS_INSTABILITY, RRW

__all__ = ["PLAN_TERMS", "TERM_NAMES", "ACC_TERM_NAMES", "SENSORS", "MAX_PLAN_S", "predicted_sigma",
           "plan_record", "Plan", "model_terms", "model_accel_terms"]

#: The coefficients planned for: ARW N [rad/√s], bias instability B [rad/s], RRW K [rad/s/√s].
PLAN_TERMS = ("n", "b", "k")

#: Datasheet name, unit and SI -> datasheet converter of each planned coefficient.
TERM_NAMES = {
    "n": ("arw_deg_rt_h", "deg/√h", units.arw_rad_rt_s_to_deg_rt_h),
    "b": ("bi_deg_h", "deg/h", units.rad_s_to_deg_h),
    "k": ("rrw_deg_h_rt_h", "deg/h/√h", units.rrw_rad_s_rt_s_to_deg_h_rt_h),
}

#: The accelerometer's planned coefficients (``plan --sensor acc``), as :data:`TERM_NAMES`: velocity
#: random walk N_a [m/s/√s], bias instability B [m/s²], acceleration random walk K_a [m/s²/√s]
#: SI, named and converted as ``allan --sensor acc`` reports them.
ACC_TERM_NAMES = {t: ACC_TERMS[t] for t in PLAN_TERMS}

#: The sensors planned for: the gyro (:data:`TERM_NAMES`) and the accelerometer (:data:`ACC_TERM_NAMES`).
SENSORS = ("gyro", "acc")

#: The option giving each coefficient, by sensor (named in refusals).
_OPTIONS = {"gyro": {"n": "--arw", "b": "--bi", "k": "--rrw"},
            "acc": {"n": "--vrw", "b": "--acc-bi", "k": "--acc-rw"}}

#: Longest record planned for [s] (ten years); beyond it a precision is reported unreachable.
MAX_PLAN_S = 10 * 365.25 * 86400.0

#: Fewest samples a planned record has (a few octaves of the Allan variance).
_MIN_SAMPLES = 64

#: Sample rates planned for [Hz]. Below 1 mHz the 64 samples of the shortest record already
#: take 18 h and no ARW region is left to see; above 1 MHz no gyro output exists, and a
#: 10-year record (3e14 samples at 1 MHz) stays well inside an int64 sample count.
MIN_RATE_HZ, MAX_RATE_HZ = 1e-3, 1e6

#: Smallest positive coefficient planned for, in its datasheet unit (deg/√h, deg/h, deg/h/√h):
#: far below any gyro built, and with the CLI's upper bounds (1e6, 1e7) every ratio of two
#: terms, and so every crossover time τ = (N/B)², √3·N/K, 3·B²/K² (times constants), stays a
#: representable double (the variances of the terms then differ by < 1e36).
MIN_COEF_DATASHEET = 1e-9

#: Largest coefficient planned for, datasheet unit, by sensor: for the gyro what a model may hold
#: (:data:`gyroarray.effects.model.PLAUSIBLE`, rates within 1e5 deg/s); for the accelerometer
#: (m/s/√h, mg, m/s²/√h) far above any built (a 1e6 mg bias instability is 1000 g), the
#: ``plan`` options' upper bounds, and like the gyro's within 1e15 of :data:`MIN_COEF_DATASHEET`.
_MAX_COEF_DATASHEET = {"gyro": {"n": 6e6, "b": 3.6e8, "k": 3.6e8},
                       "acc": {"n": 1e6, "b": 1e6, "k": 1e6}}

#: Finest relative 1σ any coefficient reaches within :data:`MAX_PLAN_S`: the ARW's at the
#: fastest rate (2.08e-7 for 10 years at 1 MHz, :func:`predicted_sigma`); a precision finer
#: than z times it is unreachable for every term and is refused.
MIN_SIGMA_REL = 2.0e-7

_ITERATIONS = 24


def _z(confidence: float) -> float:
    if not 0.0 < confidence < 1.0:
        raise InputError(f"confidence must be in (0, 1), got {confidence!r}")
    return float(math.sqrt(2.0) * special.erfinv(confidence))


def predicted_sigma(coef: dict, rate_hz: float, duration_s: float) -> dict:
    """The 1σ of each coefficient that the Allan noise fit of one record would have.

    Parameters
    ----------
    coef : dict
        ``{"n": N [rad/√s], "b": B [rad/s], "k": K [rad/s/√s]}``, or the accelerometer's
        ``{"n": N_a [m/s/√s], "b": B [m/s²], "k": K_a [m/s²/√s]}`` (the same arithmetic); terms
        with a zero (or missing) value are neither simulated nor fitted.
    rate_hz : float
        Sample rate [Hz].
    duration_s : float
        Record length [s].

    Returns
    -------
    dict
        ``term -> σ`` in the unit of the coefficient (None where the fit's information matrix
        is singular).

    Raises
    ------
    InputError
        No positive coefficient, or a record too short for an Allan variance.
    """
    terms = tuple(t for t in PLAN_TERMS if coef.get(t, 0.0) > 0.0)
    if not terms:
        raise InputError("give at least one positive noise coefficient (--arw, --bi or --rrw; "
                         "for the accelerometer --vrw, --acc-bi or --acc-rw)")
    dt = 1.0 / float(rate_hz)
    n = max(int(round(duration_s * rate_hz)), _MIN_SAMPLES)
    n_phase = n + 1
    m = averaging_factors(n_phase, dt, "octave", "oadev")
    taus = m * dt
    avar = sum(coef[t] ** 2 * term_basis("oadev", t, taus) for t in terms)
    curve = AllanResult(kind="oadev", tau0_s=dt, n_phase=n_phase, m=m, taus_s=taus,
                        dev=np.sqrt(avar), n_terms=n_phase - 2 * m)
    fit = fit_noise_terms(curve, lambda alpha: edf("oadev", n_phase, m, alpha), terms=terms)
    return {t: fit.coefficient(t)[1] for t in terms}


@dataclass(frozen=True)
class Plan:
    """Record lengths for a precision on each coefficient.

    Parameters
    ----------
    coef : dict
        The coefficients planned for, SI (``n`` [rad/√s], ``b`` [rad/s], ``k`` [rad/s/√s]; for
        the accelerometer ``n`` [m/s/√s], ``b`` [m/s²], ``k`` [m/s²/√s]).
    rate_hz : float
        Sample rate [Hz].
    precision : float
        Relative half-width asked for [-] (0.1 = ±10 %).
    confidence : float
        Two-sided confidence of the half-width.
    duration_s : dict
        ``term -> record length [s]`` reaching the precision (None: not within
        :data:`MAX_PLAN_S`).
    at_s : float or None
        A record length asked about [s] (``--at-h``), or None.
    at_precision : dict
        ``term -> relative half-width [-]`` a record of ``at_s`` gives (empty without it).
    sensor : str
        ``"gyro"`` or ``"acc"``: which names and datasheet units :meth:`to_json_dict` uses.
    """

    coef: dict
    rate_hz: float
    precision: float
    confidence: float
    duration_s: dict
    at_s: float | None
    at_precision: dict
    sensor: str = "gyro"

    @property
    def names(self) -> dict:
        """Datasheet name, unit and SI -> datasheet converter by term, for this sensor."""
        return ACC_TERM_NAMES if self.sensor == "acc" else TERM_NAMES

    def to_json_dict(self) -> dict:
        """The plan in datasheet units: per coefficient its value, the record length [s] and
        [h] for the precision, and the precision a record of ``at_s`` gives."""
        terms = {}
        for t, value in self.coef.items():
            name, unit, conv = self.names[t]
            d = self.duration_s.get(t)
            terms[name] = {"value": float(conv(value)), "unit": unit,
                           "record_s": d, "record_h": None if d is None else d / units.S_PER_H}
            if self.at_s is not None:
                terms[name]["precision_at_record"] = self.at_precision.get(t)
        return {"sensor": self.sensor, "rate_hz": self.rate_hz, "precision": self.precision,
                "confidence": self.confidence, "at_record_s": self.at_s, "terms": terms,
                "method": "1σ of the Allan GLS noise fit (allan's equivalent degrees of "
                          "freedom and correlations) on the model's noise-free curve"}


def _relative(coef, rate_hz, duration_s, z) -> dict:
    sig = predicted_sigma(coef, rate_hz, duration_s)
    return {t: (math.inf if s is None else z * s / coef[t]) for t, s in sig.items()}


def _length_for(term, coef, rate_hz, precision, z) -> float | None:
    """Shortest record length tried whose relative half-width on ``term`` <= precision."""
    t_min = _MIN_SAMPLES / rate_hz
    t = max(t_min, 1000.0 / rate_hz)
    best = None
    for _ in range(_ITERATIONS):
        rel = _relative(coef, rate_hz, t, z)[term]
        if rel <= precision:
            best = t if best is None else min(best, t)
            if rel >= 0.97 * precision or t <= t_min:
                break
        elif t >= MAX_PLAN_S:
            break
        ratio = min(rel / precision, 4.0) ** 2 if math.isfinite(rel) else 16.0
        step = min(max(ratio, 0.25), 16.0)
        if best is not None and t * step >= best:      # never above a length already enough
            step = min(step, 0.5 * (1.0 + best / t))
        t = min(max(t * step, t_min), MAX_PLAN_S)
    return best


def plan_record(coef: dict, rate_hz: float, precision: float, *,
                confidence: float = ONE_SIGMA, at_s: float | None = None,
                sensor: str = "gyro") -> Plan:
    """Record length at which each coefficient's confidence half-width reaches ``precision``.

    Parameters
    ----------
    coef : dict
        ``{"n": N [rad/√s], "b": B [rad/s], "k": K [rad/s/√s]}`` (zeros: not in the model); for
        ``sensor="acc"`` ``{"n": N_a [m/s/√s], "b": B [m/s²], "k": K_a [m/s²/√s]}``.
    rate_hz : float
        Sample rate [Hz].
    precision : float
        Relative half-width [-], in (0, 1).
    confidence : float, default :data:`~gyroarray.analysis.allan.ONE_SIGMA`
        Two-sided confidence of the interval (``allan``'s bands are 1σ).
    at_s : float, optional
        Also report the precision a record of this length [s] gives.
    sensor : {"gyro", "acc"}, default "gyro"
        The gyro's terms or the accelerometer's (names, units and bounds; the same arithmetic).

    Returns
    -------
    Plan

    Raises
    ------
    InputError
        A precision or confidence out of range, no positive coefficient, a bad rate.
    """
    if sensor not in SENSORS:
        raise InputError(f"sensor must be one of {SENSORS}, got {sensor!r}")
    names = ACC_TERM_NAMES if sensor == "acc" else TERM_NAMES
    if not (math.isfinite(rate_hz) and MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ):
        raise InputError(f"--rate-hz must be in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {rate_hz!r}")
    if not (math.isfinite(precision) and 0.0 < precision < 1.0):
        raise InputError(f"--precision must be between 0 and 100 %, got {precision:g}")
    z = _z(confidence)
    if precision < z * MIN_SIGMA_REL:
        raise InputError(f"--precision {precision:g} is finer than any noise coefficient can be "
                         f"measured within 10 years at up to {MAX_RATE_HZ:g} Hz (the best, ARW, "
                         f"reaches a relative 1σ of {MIN_SIGMA_REL:g}): give a precision in "
                         f"[{z * MIN_SIGMA_REL:.3g}, 1) at confidence {confidence:g}")
    for t in PLAN_TERMS:
        v = coef.get(t, 0.0)
        name, unit, conv = names[t]
        opt = _OPTIONS[sensor][t]
        hi = _MAX_COEF_DATASHEET[sensor][t]
        if not (math.isfinite(v) and v >= 0.0) or (v > 0.0 and not MIN_COEF_DATASHEET <= conv(v) <= hi):
            raise InputError(f"{opt} ({name}) must be 0 (not in the model) or in "
                             f"[{MIN_COEF_DATASHEET:g}, {hi:g}] {unit}, got {conv(v):g} {unit}")
    if at_s is not None and not (math.isfinite(at_s) and _MIN_SAMPLES / rate_hz <= at_s <= MAX_PLAN_S):
        raise InputError(f"--at-h must be in [{_MIN_SAMPLES / rate_hz / units.S_PER_H:.3g}, "
                         f"{MAX_PLAN_S / units.S_PER_H:g}] h at {rate_hz:g} Hz (at least "
                         f"{_MIN_SAMPLES} samples, at most 10 years), got {at_s / units.S_PER_H:g} h")
    coef = {t: float(coef[t]) for t in PLAN_TERMS if coef.get(t, 0.0) > 0.0}
    durations = {t: _length_for(t, coef, rate_hz, precision, z) for t in coef}
    at = {}
    if at_s is not None:
        at = {t: float(v) for t, v in _relative(coef, rate_hz, at_s, z).items()}
    return Plan(coef=coef, rate_hz=float(rate_hz), precision=float(precision),
                confidence=float(confidence), duration_s=durations, at_s=at_s,
                at_precision=at, sensor=sensor)


def model_terms(model, gyro: int) -> dict:
    """ARW, bias instability and RRW of one gyro of a noise model, SI.

    Parameters
    ----------
    model : NoiseModel
        The model (:class:`gyroarray.effects.model.NoiseModel`).
    gyro : int
        1-based gyro; an entry for that gyro overrides an all-gyros entry.

    Returns
    -------
    dict
        ``{"n": N [rad/√s], "b": B [rad/s], "k": K [rad/s/√s]}`` (0 where absent).
    """
    si = {ARW: ("n", "n_rad_rt_s"), BIAS_INSTABILITY: ("b", "b_rad_s"),
          RRW: ("k", "k_rad_s_rt_s")}
    out = {"n": 0.0, "b": 0.0, "k": 0.0}
    for overriding in (False, True):
        for e in model:
            if e.effect in si and (e.gyro == gyro if overriding else e.gyro is None):
                term, key = si[e.effect]
                out[term] = float(e.si_params[key])
    return out


def model_accel_terms(model, axis: str) -> dict:
    """Velocity random walk, bias instability and acceleration random walk of one accelerometer
    axis of a noise model's ``[accelerometer]`` table, SI.

    Parameters
    ----------
    model : NoiseModel
        The model (:class:`gyroarray.effects.model.NoiseModel`).
    axis : str
        ``"x"``, ``"y"`` or ``"z"``, one of the table's ``axes``.

    Returns
    -------
    dict
        ``{"n": N_a [m/s/√s], "b": B [m/s²], "k": K_a [m/s²/√s]}`` (0 where the table has no
        such term for that axis).

    Raises
    ------
    InputError
        The model has no ``[accelerometer]`` table, or not that axis.
    """
    table = model.accelerometer
    if table is None:
        raise InputError("the model has no [accelerometer] table (fit --out writes it from a record "
                         "with acc_x, acc_y, acc_z columns)", file=model.source)
    if axis not in table.axes:
        raise InputError(f"--axis {axis}: the model's [accelerometer] table has axes "
                         f"{', '.join(table.axes)}", file=model.source)
    i = table.axes.index(axis)
    si = {"n": ("n_m_s_rt_h", units.vrw_m_s_rt_h_to_si), "b": ("b_mg", units.mg_to_m_s2),
          "k": ("k_m_s2_rt_h", units.accel_rw_m_s2_rt_h_to_si)}
    out = {}
    for term, (key, conv) in si.items():
        values = getattr(table, key)
        out[term] = 0.0 if values is None or values[i] is None else float(conv(values[i]))
    return out
