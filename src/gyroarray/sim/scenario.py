"""Scenario files and the simulation chain: table → effects → readings → measurement.

A scenario (TOML, data only: nothing in it is evaluated or imported) says
what to simulate:

.. code-block:: toml

    name = "paper003_static_s1_n6"          # output stem; [A-Za-z0-9_.-]
    description = "paper 003 §4.1, Scheme 1, N = 6"
    sample_rate_hz = 100.0                  # gyro sample rate [Hz]
    duration_s = 3600.0                     # optional: cut the profile short [s]
    seed = 20230329                         # the run's numpy.random.Generator seed
    acc_columns = true                      # optional (default false): also write
                                            # acc_x, acc_y, acc_z [m/s²]

    [layout]                                # as in a measurement sidecar
    scheme = 1
    n_gyros = 6
    alpha_deg = 54.7356                     # or: axes = [[x, y, z], ...]
    # positions_m = [[0.03, 0, 0], ...]     # optional: gyro positions [m] (default 0)

    [motion]
    profile = "p003_static_1h"              # a shipped profile (scenarios/profiles/)
    # profile = "my_profile.toml"           # or a file, relative to this scenario

    [site]                                  # optional (earth_rate needs it)
    latitude_deg = 34.25
    heading_deg = 0.0

    [temperature]                           # optional; exported as temp_c [°C]
    points = [[0.0, 25.0], [3600.0, 31.0]]  # (time_s, temp_c), piecewise linear
    # or: start_c = 25.0, end_c = 31.0, tau_s = 900.0   (first-order approach)
    # or: constant_c = 25.0

    effects = [                             # the noise model, one line per effect
      { effect = "arw", n_deg_rt_h = 0.1 },
      { effect = "rrw", k_deg_h_rt_h = 600.0 },
    ]

Unknown keys are refused with the key named. The chain (pvlib's ModelChain
in spirit): the rate table produces the truth for the profile (cached on
disk, layout-independent), the effects turn it into gyro readings, and the
readings are exported in the measurement format with ``ref_*`` = the
realised table rate and ``temp_c``, so a simulated run goes wherever a lab
measurement goes.

The effects see the specific force the table really makes: MuJoCo's
accelerometer at the platform origin (gravity through the gimbal attitude,
g0 = 9.80665 m/s²) and the angular acceleration, carried to each gyro's
``positions_m`` (``g_sensitivity``). ``acc_columns = true`` writes that
specific force at the origin as ``acc_x``, ``acc_y``, ``acc_z`` (exact, no
accelerometer noise); the layout's ``positions_m``, when given, is written
to the sidecar.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gyroarray.core import units
from gyroarray.effects import get_effect
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.limits import MAX_RATE_DEG_S, check_memory
from gyroarray.core.tomlio import TomlDoc, load_toml, toml_number, toml_table, toml_type
from gyroarray.core.measurement import (Measurement, Site, parse_layout, parse_site,
                                   write_measurement)
from gyroarray.core.outputs import check_output, check_output_dir
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.sim.profiles import Profile, RateCSV, Sinusoid, load_profile
from gyroarray.sim.table import TableParams
from gyroarray.sim.truth import Truth, compute_truth
from gyroarray.core.data import data_path

_TOP_KEYS = {"name", "description", "sample_rate_hz", "duration_s", "seed", "layout", "motion",
             "site", "temperature", "effects", "acc_columns"}
_NAME_RE = re.compile(r"^[A-Za-z0-9_.-]{1,100}$")


@dataclass(frozen=True)
class TemperatureProfile:
    """Temperature at the array over time.

    Exactly one form is set: ``points`` (piecewise linear in time, held
    constant outside), ``(start_c, end_c, tau_s)`` (first-order approach
    T(t) = end + (start − end)·exp(−t/τ)), or ``constant_c``.

    Parameters
    ----------
    points : tuple of (float, float), optional
        (time [s], temperature [°C]) with strictly increasing times.
    start_c, end_c : float, optional
        Initial and final temperature [°C].
    tau_s : float, optional
        Time constant [s].
    constant_c : float, optional
        Constant temperature [°C].
    """

    points: tuple[tuple[float, float], ...] | None = None
    start_c: float | None = None
    end_c: float | None = None
    tau_s: float | None = None
    constant_c: float | None = None

    def at(self, time_s: np.ndarray) -> np.ndarray:
        """Temperature [°C] at ``time_s`` [s]."""
        t = np.asarray(time_s, dtype=float)
        if self.points is not None:
            pts = np.asarray(self.points, dtype=float)
            return np.interp(t, pts[:, 0], pts[:, 1])
        if self.constant_c is not None:
            return np.full(t.shape, float(self.constant_c))
        assert self.start_c is not None and self.end_c is not None and self.tau_s is not None
        return self.end_c + (self.start_c - self.end_c) * np.exp(-t / self.tau_s)


@dataclass(frozen=True)
class Scenario:
    """A simulation scenario, read from TOML (see the module docstring).

    Parameters
    ----------
    name : str
        Output file stem.
    layout : Layout
    profile : Profile
        The commanded motion.
    sample_rate_hz : float
        Gyro sample rate [Hz].
    model : NoiseModel
        The effects.
    seed : int
        Seed of the run's ``numpy.random.Generator``.
    duration_s : float or None
        Cut the profile to this duration [s] (None: the whole profile).
    site : Site or None
    temperature : TemperatureProfile or None
    description : str
    source : str or None
        The scenario file.
    acc_columns : bool
        Write the specific force at the platform origin (``acc_*``).
    """

    name: str
    layout: Layout
    profile: Profile
    sample_rate_hz: float
    model: NoiseModel
    seed: int
    duration_s: float | None = None
    site: Site | None = None
    temperature: TemperatureProfile | None = None
    description: str = ""
    source: str | None = None
    acc_columns: bool = False


def load_scenario(path) -> Scenario:
    """Read and strictly validate a scenario file.

    Raises
    ------
    InputError
        Naming the file, the key and (where it can be found) the line.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("scenario file not found", file=str(path))
    doc = load_toml(path, "scenario file")
    d = doc.data
    unknown = sorted(set(d) - _TOP_KEYS)
    if unknown:
        raise doc.error(f"unknown key {unknown[0]!r} (known: {', '.join(sorted(_TOP_KEYS))})",
                        unknown[0])
    for table in ("layout", "motion", "site", "temperature"):
        misplaced = sorted(set(d.get(table) or ()) & _TOP_KEYS) if isinstance(d.get(table), dict) else []
        if misplaced:
            raise doc.error(f"{misplaced[0]!r} landed inside [{table}]: in TOML, top-level keys "
                            f"such as {misplaced[0]} must come before the first [table] header",
                            f"{table}.{misplaced[0]}")
    for key in ("name", "sample_rate_hz", "seed", "layout", "motion"):
        if key not in d:
            raise doc.error(f"{key} is missing", key)
    name = d["name"]
    if not (isinstance(name, str) and _NAME_RE.match(name)):
        raise doc.error(f"name must be 1-100 characters of A-Z a-z 0-9 _ . - (it names the "
                        f"output files), got {toml_type(name)}", "name")
    description = d.get("description", "")
    if not isinstance(description, str):
        raise doc.error(f"description must be a string, got {toml_type(description)}",
                        "description")
    rate = toml_number(doc, d["sample_rate_hz"], "sample_rate_hz")
    if rate <= 0:
        raise doc.error(f"sample_rate_hz must be > 0, got {rate!r}", "sample_rate_hz")
    seed = d["seed"]
    if not (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < 2**63):
        raise doc.error(f"seed must be a whole number in [0, 2^63), got {toml_type(seed)}", "seed")
    duration = None
    if "duration_s" in d:
        duration = toml_number(doc, d["duration_s"], "duration_s")
        if duration <= 0:
            raise doc.error(f"duration_s must be > 0, got {duration!r}", "duration_s")
    acc_columns = d.get("acc_columns", False)
    if not isinstance(acc_columns, bool):
        raise doc.error(f"acc_columns must be true or false, got {toml_type(acc_columns)}",
                        "acc_columns")
    layout, _ = parse_layout(doc)
    profile = _parse_motion(doc, path, duration)
    if duration is not None and duration > profile.duration_s + 1e-9:
        raise doc.error(f"duration_s = {duration:g} s is longer than the motion profile "
                        f"({profile.duration_s:g} s)", "duration_s")
    effects = d.get("effects", [])
    try:
        model = NoiseModel.from_toml({"effects": effects}, n_gyros=layout.n_gyros)
    except InputError as err:
        key = err.column if isinstance(err.column, str) else "effects"
        raise InputError(err.message, file=str(path), line=doc.line_of("effects"), column=key) from None
    scenario = Scenario(name=name, layout=layout, profile=profile, sample_rate_hz=rate, model=model,
                        seed=seed, duration_s=duration, site=parse_site(doc),
                        temperature=parse_temperature(doc), description=description,
                        source=str(path), acc_columns=acc_columns)
    validate_scenario(scenario, doc)
    return scenario


def validate_scenario(scenario: Scenario, doc, what: str = "simulate") -> None:
    """The checks that need the whole scenario, each naming ``doc``'s file, line and key.

    Samples (at least :data:`MIN_SCENARIO_SAMPLES`, a rate up to
    :data:`MAX_SAMPLE_RATE_HZ`), memory for ``what`` (:func:`check_size`),
    effects that must fit the run (a sinusoid below Nyquist, a latency
    shorter than the run) and the table's rate and acceleration limits.
    Sweeps run it on every scenario before any runs.
    """
    _check_run_shape(scenario, doc)
    check_size(scenario, what, doc)
    _check_effects_fit_run(scenario, doc)
    _check_profile_nyquist(scenario)
    _check_table_limits(scenario, doc)


#: Fewest samples a scenario may produce (an Allan curve and a score need a few
#: hundred; two samples are not a run).
MIN_SCENARIO_SAMPLES = 100
#: Fastest sample rate a scenario may ask for [Hz] (MEMS gyros output at most
#: tens of kHz).
MAX_SAMPLE_RATE_HZ = 1e6
#: Peak memory per sample [bytes] of simulating (``simulate``) and of scoring
#: every estimator (``run``): a + b·N doubles, N gyros (measured with
#: tracemalloc on 600 s at 100 Hz, N = 4 and 8, the table truth included;
#: rounded up).
_DOUBLES_PER_SAMPLE = {"simulate": (80, 5), "run": (130, 5)}


def _duration_key(scenario: Scenario, doc: TomlDoc) -> str:
    return "duration_s" if "duration_s" in doc.data else "sample_rate_hz"


def run_duration_s(scenario: Scenario) -> float:
    """How long the scenario runs [s]: ``duration_s`` or the whole profile."""
    return scenario.duration_s if scenario.duration_s is not None else scenario.profile.duration_s


def _check_run_shape(scenario: Scenario, doc: TomlDoc) -> None:
    rate, duration = scenario.sample_rate_hz, run_duration_s(scenario)
    if rate > MAX_SAMPLE_RATE_HZ:
        raise doc.error(f"sample_rate_hz = {rate:g} Hz is above the {MAX_SAMPLE_RATE_HZ:g} Hz a "
                        "gyro array simulation supports", "sample_rate_hz")
    n = duration * rate
    if n < MIN_SCENARIO_SAMPLES:
        raise doc.error(f"{duration:g} s at {rate:g} Hz gives {n:.3g} samples; a run needs at least "
                        f"{MIN_SCENARIO_SAMPLES} (lengthen duration_s or raise sample_rate_hz)",
                        _duration_key(scenario, doc))


def memory_needed(scenario: Scenario, what: str = "simulate") -> float:
    """Estimated peak memory [bytes] of simulating (``"simulate"``) or scoring (``"run"``) it."""
    a, b = _DOUBLES_PER_SAMPLE[what]
    n = run_duration_s(scenario) * scenario.sample_rate_hz
    return 8.0 * n * (a + b * scenario.layout.n_gyros)


def check_size(scenario: Scenario, what: str = "simulate", doc: TomlDoc | None = None) -> None:
    """Refuse a scenario whose ``what`` (simulate or run) would exceed the memory budget.

    Raises
    ------
    InputError
        Naming the scenario file, the size needed and the way out.
    """
    duration = run_duration_s(scenario)
    hours = f"{duration / 3600:g} h" if duration >= 3600 else f"{duration:g} s"
    key = "duration_s" if scenario.duration_s is not None else "sample_rate_hz"
    line = doc.line_of(key) if doc is not None else None
    check_memory(memory_needed(scenario, what),
                 f"{what} of {hours} at {scenario.sample_rate_hz:g} Hz x {scenario.layout.n_gyros} gyros",
                 "shorten duration_s or lower sample_rate_hz", file=scenario.source, line=line,
                 column=key)


def _check_effects_fit_run(scenario: Scenario, doc: TomlDoc) -> None:
    """Effects whose parameters must fit this run (``Effect.check_run``, then ``check_record``: a
    sinusoid below Nyquist, a latency shorter than it) and whose simulation needs a temperature the
    scenario lacks (``"temp"`` in ``Effect.sim_needs``)."""
    duration = run_duration_s(scenario)
    for i, e in enumerate(scenario.model.entries):
        key = f"effects[{i}]"
        eff = get_effect(e.effect)
        if "temp" in eff.sim_needs and scenario.temperature is None:
            raise InputError(f"{key} ({e.effect}) needs a temperature: add a [temperature] "
                             "table (points, start_c/end_c/tau_s or constant_c)", file=doc.name,
                             line=doc.line_of("effects"), column=key)
        try:        # every effect's own rules on this run's rate and span (a cut-off below Nyquist)
            eff.check_run(e.params, scenario.sample_rate_hz, duration)
            eff.check_record(e.params, 1.0 / scenario.sample_rate_hz, duration)
        except InputError as err:
            raise InputError(f"{key} ({e.effect}): {err.message}", file=doc.name, line=doc.line_of("effects"),
                             column=f"{key}.{err.column}" if err.column else key) from None


#: Content of a rate CSV above the scenario's Nyquist frequency is refused when its
#: strongest line there exceeds this share of the strongest line below it [-] (the corners of
#: linear interpolation between rows stay orders of magnitude under it).
_ALIAS_SHARE = 0.01
#: Points of the uniform grid the spectrum of a rate CSV is taken on (at most).
_ALIAS_GRID = 2**20


def _check_profile_nyquist(scenario: Scenario) -> None:
    """Refuse motion the scenario's samples cannot represent: a ``sinusoid`` segment at or
    above the Nyquist frequency, or a ``rate_csv`` whose rows (sampled faster than the
    scenario) hold a line above it; each named with the profile's (or CSV's) file and key,
    the frequency and the Nyquist limit (issue 28: a 1000 Hz swing in a 100 Hz run gave an
    attenuation of 2.9e9). Only segments that start within the run are looked at."""
    prof = scenario.profile
    rate = scenario.sample_rate_hz
    nyquist = 0.5 * rate
    end = run_duration_s(scenario)
    way_out = ("raise sample_rate_hz above {f2:g} Hz or slow the motion down (the gyros would "
               "alias it)")
    for i, seg in enumerate(prof.segments):
        if not any(p.segment == i for p in prof.pieces) or prof.segment_span(i)[0] >= end:
            continue
        if isinstance(seg, Sinusoid) and seg.frequency_hz >= nyquist:
            raise InputError(f"segment {i + 1} (sinusoid): frequency_hz = {seg.frequency_hz:g} Hz is "
                             f"not below the Nyquist frequency {nyquist:g} Hz of the scenario's "
                             f"sample_rate_hz = {rate:g} Hz; "
                             + way_out.format(f2=2 * seg.frequency_hz),
                             file=prof.source, column=f"segment[{i + 1}].frequency_hz")
        if isinstance(seg, RateCSV):
            found = _csv_line_above(seg, rate)
            if found is not None:
                freq, axis, amp = found
                raise InputError(f"segment {i + 1} (rate_csv): the commanded rates hold a line at "
                                 f"{freq:.4g} Hz ({amp:.3g} deg/s), above the Nyquist frequency "
                                 f"{nyquist:g} Hz of the scenario's sample_rate_hz = {rate:g} Hz "
                                 f"(rows {np.min(np.diff(seg.time_s)):.3g} s apart); "
                                 + way_out.format(f2=2 * freq) + ", or low-pass the rates",
                                 file=seg.file, column=("wx_deg_s", "wy_deg_s", "wz_deg_s")[axis])


def _csv_line_above(seg, rate_hz: float):
    """``(frequency [Hz], axis, amplitude [deg/s])`` of the strongest line of a rate CSV above
    ``rate_hz / 2`` when it exceeds :data:`_ALIAS_SHARE` of the strongest line below, else None.
    Rows no closer than the scenario's samples cannot hold such a line (None at once)."""
    t, w = seg.time_s, seg.omega_rad_s
    gaps = np.diff(t)
    if gaps.min() >= 1.0 / rate_hz:
        return None
    h = max(float(gaps.min()), float(t[-1]) / _ALIAS_GRID)
    if h >= 1.0 / rate_hz:                   # the grid cannot resolve the Nyquist frequency
        h = 0.5 / rate_hz
        if t[-1] / h > 4 * _ALIAS_GRID:
            return None
    tg = np.arange(0.0, float(t[-1]), h)
    if tg.size < 8:
        return None
    f = np.fft.rfftfreq(tg.size, h)
    above = f > 0.5 * rate_hz
    below = ~above
    below[0] = False                          # the mean is no line
    best = None
    for k in range(3):
        wg = np.interp(tg, t, w[:, k])
        amp = 2.0 * np.abs(np.fft.rfft(wg - wg.mean())) / tg.size
        if not above.any():
            return None
        j = int(np.argmax(np.where(above, amp, -1.0)))
        ref = float(amp[below].max()) if below.any() else 0.0
        if amp[j] > max(_ALIAS_SHARE * ref, 1e-12) and (best is None or amp[j] > best[2]):
            best = (float(f[j]), k, float(amp[j]))
    if best is None:
        return None
    return best[0], best[1], float(units.rad_s_to_deg_s(best[2]))


def _check_table_limits(scenario: Scenario, doc: TomlDoc) -> None:
    """Refuse a profile that commands the table beyond its rate or acceleration limits."""
    rate, accel = command_extremes(scenario.profile, run_duration_s(scenario))
    limits = TableParams
    for value, limit, what, unit in ((rate, limits.max_rate_deg_s, "gimbal rate", "deg/s"),
                                     (accel, limits.max_accel_deg_s2, "gimbal acceleration", "deg/s²")):
        if not value <= limit:
            raise doc.error(f"the motion profile {scenario.profile.source or ''} commands a {what} of "
                            f"{value:.4g} {unit}, beyond the rate table's {limit:g} {unit} "
                            "(TableParams)", "motion.profile")


_EXTREMES: dict = {}


def command_extremes(profile: Profile, duration_s: float, per_piece: int = 200) -> tuple[float, float]:
    """Cached :func:`_command_extremes` (profiles are immutable; keyed by fingerprint)."""
    key = (profile.fingerprint, float(duration_s), per_piece)
    if key not in _EXTREMES:
        if len(_EXTREMES) > 256:
            _EXTREMES.clear()
        _EXTREMES[key] = _command_extremes(profile, duration_s, per_piece)
    return _EXTREMES[key]


def _command_extremes(profile: Profile, duration_s: float, per_piece: int = 200) -> tuple[float, float]:
    """Largest commanded gimbal rate [deg/s] and acceleration [deg/s²] over ``duration_s``.

    The command is evaluated on ``per_piece`` points of each profile piece
    (at most 200 000 points in all); the acceleration is the finite
    difference of the rates.
    """
    pieces = [p for p in profile.pieces if p.t0 < duration_s]
    per = max(2, min(per_piece, 200_000 // max(len(pieces), 1)))
    t = np.unique(np.concatenate([np.linspace(p.t0, min(p.t1, duration_s), per) for p in pieces]))
    with np.errstate(all="ignore"):
        qd = profile.command(t).qd_rad_s
        step = np.diff(t)
        acc = np.abs(np.diff(qd, axis=0)) / step[:, None]
        rate = float(np.max(np.abs(qd))) if qd.size else 0.0
        accel = float(np.max(acc)) if acc.size else 0.0
    return units.rad_to_deg(rate), units.rad_to_deg(accel)


def _parse_motion(doc: TomlDoc, path: Path, until_s: float | None = None) -> Profile:
    """The motion profile, built only as far as ``until_s`` (the scenario's duration) needs:
    a rate CSV's rows beyond it are never integrated (:class:`~gyroarray.sim.profiles.Profile`)."""
    t = toml_table(doc, "motion", {"profile"})
    ref = t.get("profile") if t is not None else None
    if not isinstance(ref, str) or not ref:
        raise doc.error("motion.profile must name a profile: a shipped one (e.g. "
                        "'p003_static_1h') or a .toml file relative to the scenario", "motion.profile")
    return load_profile(resolve_profile(ref, path.parent, doc), until_s=until_s)


def shipped_profiles() -> list[str]:
    """Names of the motion profiles shipped in ``scenarios/profiles/``."""
    folder = data_path("scenarios").joinpath("profiles")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def resolve_profile(ref: str, base: Path, doc: TomlDoc | None = None) -> Path:
    """The file of a profile reference: a path relative to ``base`` or a shipped name."""
    candidate = base / ref
    if ref.endswith(".toml") or "/" in ref or "\\" in ref:
        if candidate.is_file():
            return candidate
        message = f"motion profile file {ref!r} not found (looked in {base})"
    else:
        shipped = data_path("scenarios").joinpath("profiles").joinpath(ref + ".toml")
        if shipped.is_file():
            return Path(str(shipped))
        message = (f"unknown shipped motion profile {ref!r} (shipped: {', '.join(shipped_profiles())}; "
                   "a file needs its .toml suffix)")
    if doc is None:
        raise InputError(message)
    raise doc.error(message, "motion.profile")


def parse_temperature(doc: TomlDoc) -> TemperatureProfile | None:
    t = toml_table(doc, "temperature", {"points", "start_c", "end_c", "tau_s", "constant_c"})
    if t is None:
        return None
    forms = {"points": {"points"}, "exponential": {"start_c", "end_c", "tau_s"},
             "constant": {"constant_c"}}
    given = set(t)
    match = [name for name, keys in forms.items() if given == keys]
    if not match:
        raise doc.error("temperature takes exactly one form: points = [[time_s, temp_c], ...], "
                        "or start_c + end_c + tau_s, or constant_c", "temperature")
    if match[0] == "points":
        pts = t["points"]
        ok = isinstance(pts, list) and len(pts) >= 1 and all(
            isinstance(p, list) and len(p) == 2 for p in pts)
        if not ok:
            raise doc.error("temperature.points must be a list of [time_s, temp_c] pairs",
                            "temperature.points")
        values = [(toml_number(doc, a, "temperature.points"), toml_number(doc, b, "temperature.points"))
                  for a, b in pts]
        if any(b[0] <= a[0] for a, b in zip(values, values[1:])):
            raise doc.error("temperature.points times must be strictly increasing",
                            "temperature.points")
        return TemperatureProfile(points=tuple(values))
    if match[0] == "constant":
        return TemperatureProfile(constant_c=toml_number(doc, t["constant_c"], "temperature.constant_c"))
    start, end, tau = (toml_number(doc, t[k], f"temperature.{k}") for k in ("start_c", "end_c", "tau_s"))
    if tau <= 0:
        raise doc.error(f"temperature.tau_s must be > 0, got {tau!r}", "temperature.tau_s")
    return TemperatureProfile(start_c=start, end_c=end, tau_s=tau)


# -- the chain ------------------------------------------------------------------

@dataclass(frozen=True)
class SimulationResult:
    """What one scenario run produced.

    Attributes
    ----------
    scenario : Scenario
    truth : Truth
        The table's realised motion (layout-independent).
    readings_rad_s : ndarray, shape (n, N)
        Gyro outputs [rad/s].
    temp_c : ndarray, shape (n,) or None
        Temperature [°C].
    """

    scenario: Scenario
    truth: Truth
    readings_rad_s: np.ndarray
    temp_c: np.ndarray | None

    def to_measurement(self) -> Measurement:
        """The run in the measurement format (deg/s at the edge, via the named converters)."""
        sc = self.scenario
        desc = sc.description or f"simulated scenario {sc.name}"
        return Measurement(
            time_s=self.truth.time_s,
            gyro_deg_s=units.rad_s_to_deg_s(self.readings_rad_s),
            layout=sc.layout, sample_rate_hz=sc.sample_rate_hz,
            ref_deg_s=units.rad_s_to_deg_s(self.truth.omega_body_rad_s),
            temp_c=self.temp_c, site=sc.site,
            description=f"{desc} (gyroarray simulate, seed {sc.seed})",
            acc_m_s2=self.truth.specific_force_m_s2 if sc.acc_columns else None)


def simulate(scenario: Scenario, *, cache: bool = True, rng: np.random.Generator | None = None
             ) -> SimulationResult:
    """Run a scenario: table truth (cached) → effects → readings.

    Parameters
    ----------
    scenario : Scenario
    cache : bool
        Use the on-disk truth cache (see :func:`gyroarray.sim.truth.compute_truth`).
    rng : numpy.random.Generator, optional
        Overrides the scenario's seed (sweeps derive one per scenario).
    """
    truth = compute_truth(scenario.profile, scenario.sample_rate_hz,
                          duration_s=scenario.duration_s, cache=cache)
    temp = None if scenario.temperature is None else scenario.temperature.at(truth.time_s)
    site = None if scenario.site is None else (scenario.site.latitude_rad, scenario.site.heading_rad)
    rng = np.random.default_rng(scenario.seed) if rng is None else rng
    readings = simulate_readings(scenario.model, truth.omega_body_rad_s, scenario.layout,
                                 1.0 / scenario.sample_rate_hz, rng, time_s=truth.time_s,
                                 attitude=truth.rotation_matrices, temp_c=temp, site=site,
                                 specific_force=truth.specific_force_m_s2,
                                 angular_accel=truth.angular_accel_rad_s2)
    _check_readings(scenario, readings)
    return SimulationResult(scenario=scenario, truth=truth, readings_rad_s=readings, temp_c=temp)


def _check_readings(scenario: Scenario, readings_rad_s: np.ndarray) -> None:
    """Refuse a run whose effects drive a gyro beyond what any gyro can output."""
    with np.errstate(all="ignore"):
        peak = float(np.max(np.abs(units.rad_s_to_deg_s(readings_rad_s)), initial=0.0))
    if not peak <= MAX_RATE_DEG_S:
        raise InputError(f"the simulated outputs reach {peak:.4g} deg/s, beyond the {MAX_RATE_DEG_S:g} "
                         "deg/s a gyro can output: an effect's parameters are too large for this run "
                         f"(noise densities grow with sqrt(sample_rate_hz = {scenario.sample_rate_hz:g}))",
                         file=scenario.source, column="effects")


def scenario_files(scenario: Scenario) -> list[Path]:
    """Every file a scenario was read from: the scenario, its profile and the profile's rate CSVs."""
    files = [scenario.source, getattr(scenario.profile, "source", None)]
    files += [getattr(seg, "file", None) for seg in getattr(scenario.profile, "segments", ())]
    return [Path(f) for f in files if f]


def output_files(scenario: Scenario, out_dir) -> tuple[Path, Path]:
    """The measurement :func:`simulate_to_files` writes: ``out_dir/<name>.csv.gz`` and ``.toml``."""
    out = Path(out_dir)
    return out / f"{scenario.name}.csv.gz", out / f"{scenario.name}.toml"


def simulate_to_files(scenario: Scenario, out_dir, *, cache: bool = True, force: bool = False
                      ) -> tuple[Path, Path, SimulationResult]:
    """Simulate and write ``out_dir/<name>.csv.gz`` + ``<name>.toml`` (measurement format).

    Nothing the scenario was read from is ever written over (also with
    ``force``); an existing output is replaced only with ``force``
    (:mod:`gyroarray.core.outputs`). The paths are checked before simulating.
    """
    out = check_output_dir(out_dir)
    for path in output_files(scenario, out):
        check_output(path, inputs=scenario_files(scenario), force=force)
    result = simulate(scenario, cache=cache)
    csv_path, toml_path = write_measurement(result.to_measurement(), output_files(scenario, out)[0],
                                            force=force)
    return csv_path, toml_path, result
