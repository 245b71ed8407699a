"""Sweep files: one base scenario and a grid (and/or a list) of parameter variations.

A sweep file is TOML, data only (nothing in it is evaluated or imported):

.. code-block:: toml

    name = "design_quick"                  # [A-Za-z0-9_.-]
    description = "scheme/N/rho comparison at the optimal cone angle"
    seed = 20260101                        # the sweep seed
    estimators = ["kf_array", "gls", "ols", "naive"]   # optional (default: the chain's)

    base = "paper003/swing_s1_n6"          # a scenario file: relative to this file,
                                           # or under the shipped scenarios/ folder;
                                           # ".toml" may be left off
    # or inline, with the keys of a scenario file (name and seed come from the sweep):
    # [base]
    # sample_rate_hz = 100.0
    # duration_s = 30.0
    # effects = [{ effect = "arw", n_deg_rt_h = 0.1 }]
    # [base.layout]
    # scheme = 1
    # n_gyros = 6
    # alpha_deg = 54.7356
    # [base.motion]
    # profile = "p003_static_1h"

    [effect_sets]                          # optional: named effect lists for grid.effects
    paper = [{ effect = "arw", n_deg_rt_h = 0.1 }, { effect = "rrw", k_deg_h_rt_h = 600.0 }]

    [grid]                                 # every combination of these lists
    scheme = [1, 2]
    n_gyros = [4, 5, 6, 8]
    alpha_deg = ["optimal"]                # or numbers [deg]; "optimal": min GDOP for
                                           # that scheme, N and rho_arw
    rho_arw = [-0.2, 0.0, 0.5]             # the correlation effect's rho_arw [-]
    rho_rrw = [0.0]                        # ... and rho_rrw [-]
    motion = ["p003_static_1h", "p003_sine_5dps_0p03hz"]   # profiles (shipped or files)
    effects = ["paper"]                    # names of [effect_sets] ("base": the base's)
    duration_s = [30.0]                    # cut each run to this [s]

    [[points]]                             # optional explicit scenarios (added to the grid);
    scheme = 2                             # keys not given come from the base
    n_gyros = 6
    alpha_deg = 60.0

Other top-level keys:

.. code-block:: toml

    replicates = 5                         # run each scenario 5 times (seeds differ;
                                           # adds the parameter ``replicate`` = 0..4)
    paired = true                          # common random numbers: every design of a
                                           # replicate gets the same seed (from the sweep
                                           # seed and the replicate only), so differences
                                           # between designs are paired comparisons
    skip_invalid = true                    # grid combinations that make no valid
                                           # scenario (e.g. rho below -1/(N-1)) are
                                           # left out and listed (``Sweep.excluded``)
                                           # instead of refusing the sweep
    scenarios = ["paper003/swing_s1_n6", "paper003/swing_s1_n8"]
                                           # instead of base/grid/points: a list of
                                           # scenario files run as they are (resolved
                                           # like ``base``); the ``scenario`` column
                                           # of the results names the file

Every scenario gets an id derived from its parameter values only (a short
readable slug plus 12 hex digits of the SHA-256 of the canonical JSON of the
parameters), never from its position, and a seed derived from the sweep seed
and that id (:func:`scenario_seed`), so results do not depend on the order of
the grid values, on which scenarios run, or on the number of workers.

Parameters not given by the grid or a point come from the base. Each
scenario is fully checked at expansion (layout, profile, effects with N), so
an invalid sweep is refused before anything runs; each problem is one
:class:`~gyroarray.core.errors.InputError` naming the file and the key.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TypeGuard

import numpy as np

from gyroarray.core.gdop import optimal_alpha
from gyroarray.core.errors import InputError
from gyroarray.core.measurement import parse_layout, parse_site
from gyroarray.sim.profiles import load_profile
from gyroarray.core.tomlio import TomlDoc, load_toml
from gyroarray.core.data import data_path

__all__ = ["Sweep", "ScenarioSpec", "load_sweep", "scenario_id", "scenario_seed", "PARAM_KEYS"]

#: Keys a grid or a point may vary.
PARAM_KEYS = ("scheme", "n_gyros", "alpha_deg", "rho_arw", "rho_rrw", "motion", "effects",
              "duration_s")
_TOP_KEYS = {"name", "description", "seed", "estimators", "base", "grid", "points", "effect_sets",
             "replicates", "skip_invalid", "scenarios", "paired"}
MAX_REPLICATES = 1000
_BASE_KEYS = {"description", "sample_rate_hz", "duration_s", "layout", "motion", "site",
              "temperature", "effects"}
_REF_BASE_KEYS = _BASE_KEYS | {"name", "seed"}      # a scenario file's name/seed are ignored
_NAME_RE = re.compile(r"^[A-Za-z0-9_.-]{1,100}$")
_SLUG_BAD = re.compile(r"[^A-Za-z0-9_.-]+")
MAX_SCENARIOS = 100_000


def _type(v) -> str:
    return {bool: "boolean", str: "string", list: "array", dict: "table", int: "integer",
            float: "float"}.get(type(v), type(v).__name__)


def _is_num(v) -> TypeGuard[float]:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


_Doc = TomlDoc  # one TOML key locator for sidecars, scenarios and sweeps


def _read_doc(path: Path, what: str) -> _Doc:
    return load_toml(path, what)


# -- ids and seeds -------------------------------------------------------------

def _canonical(params: dict) -> str:
    return json.dumps({k: params[k] for k in sorted(params)}, sort_keys=True,
                      separators=(",", ":"), allow_nan=False)


def scenario_id(params: dict) -> str:
    """The stable id of a scenario: a readable slug + 12 hex of SHA-256(canonical JSON).

    Depends on the parameter values only (not on order or position).
    """
    digest = hashlib.sha256(_canonical(params).encode()).hexdigest()[:12]
    parts = []
    if params.get("scenario"):
        parts.append(str(params["scenario"]).replace("/", "."))
    if params.get("scheme") is not None:
        parts.append(f"s{params['scheme']}")
    parts.append(f"n{params['n_gyros']}")
    a = params.get("alpha_deg")
    if a is not None:
        parts.append("aopt" if a == "optimal" else f"a{a:g}")
    if params.get("rho_arw") is not None:
        parts.append(f"r{params['rho_arw']:g}")
    if params.get("rho_rrw") is not None:
        parts.append(f"q{params['rho_rrw']:g}")
    parts.append(params["motion"].rsplit("/", 1)[-1].removesuffix(".toml")[:24])
    if params.get("effects") not in (None, "base"):
        parts.append(str(params["effects"])[:16])
    if params.get("duration_s") is not None:
        parts.append(f"d{params['duration_s']:g}")
    if params.get("replicate") is not None:
        parts.append(f"rep{params['replicate']}")
    slug = _SLUG_BAD.sub("", "_".join(parts))[:96]
    return f"{slug}-{digest}"


def scenario_seed(sweep_seed: int, sid: str) -> int:
    """The seed of scenario ``sid``: SeedSequence(sweep_seed, spawn_key=SHA-256(sid)) → [0, 2^63)."""
    words = np.frombuffer(hashlib.sha256(sid.encode()).digest(), dtype="<u4")
    ss = np.random.SeedSequence(int(sweep_seed), spawn_key=tuple(int(w) for w in words))
    return int(ss.generate_state(1, np.uint64)[0] >> np.uint64(1))


@lru_cache(maxsize=1024)
def _optimal_alpha_deg(scheme: int, n: int, rho: float) -> float:
    return math.degrees(optimal_alpha(scheme, n, rho).alpha_rad)


# -- the expanded scenarios ----------------------------------------------------

@dataclass(frozen=True)
class ScenarioSpec:
    """One expanded scenario, as plain (picklable) data; :meth:`build` makes the Scenario.

    Attributes
    ----------
    id : str
    seed : int
        The run's ``numpy.random.Generator`` seed (from the sweep seed and the id).
    params : dict
        The sweep parameters (``PARAM_KEYS``; None where the base has none)
        plus ``alpha_deg_value`` (the resolved cone angle [deg]).
    data : dict
        The scenario as scenario-file keys (overrides applied).
    file : str
        The file the base came from (for messages).
    """

    id: str
    seed: int
    params: dict
    data: dict = field(repr=False)
    file: str = ""

    def build(self):
        """The :class:`gyroarray.sim.scenario.Scenario` (validated)."""
        return _build_scenario(self.data, self.id, self.seed, self.file)

    def row_params(self) -> dict:
        """The columns this scenario adds to each result row (units in the names)."""
        p = self.params
        return {"scenario_id": self.id, "scenario_seed": self.seed,
                "scheme": p["scheme"], "n_gyros": p["n_gyros"],
                "alpha_deg": p["alpha_deg_value"], "alpha_optimal": p["alpha_deg"] == "optimal",
                "rho_arw": p["rho_arw"], "rho_rrw": p["rho_rrw"], "motion": p["motion"],
                "effects": p["effects"], "duration_s": p["duration_s_value"],
                "sample_rate_hz": float(self.data["sample_rate_hz"]),
                "scenario": p.get("scenario") or "", "replicate": int(p.get("replicate") or 0)}


@dataclass(frozen=True)
class Sweep:
    """A parsed sweep file: name, seed, estimators and the expanded scenarios (sorted by id)."""

    name: str
    seed: int
    estimators: tuple[str, ...] | None
    scenarios: tuple[ScenarioSpec, ...]
    description: str = ""
    source: str | None = None
    sha256: str = ""
    #: (id, reason) of grid combinations left out by ``skip_invalid``.
    excluded: tuple[tuple[str, str], ...] = ()

    def __len__(self) -> int:
        return len(self.scenarios)

    def manifest(self) -> dict:
        """What identifies this sweep in an output folder (``sweep.json``)."""
        return {"format": 1, "name": self.name, "seed": self.seed, "source": self.source,
                "sweep_sha256": self.sha256,
                "estimators": None if self.estimators is None else list(self.estimators),
                "scenarios": [{"id": s.id, "seed": s.seed, "params": s.params}
                              for s in self.scenarios],
                "excluded": [{"id": i, "reason": r} for i, r in self.excluded]}


class _Prefixed(_Doc):
    """A scenario dict seen through the sweep file: keys named with a prefix (e.g. ``base.``)."""

    def __init__(self, doc: _Doc | None, data: dict, name: str, prefix: str):
        super().__init__(name, doc.text if doc is not None else "", data)
        self.doc, self.prefix = doc, prefix

    def line_of(self, key: str) -> int | None:
        return None if self.doc is None else self.doc.line_of(self.prefix + key)

    def error(self, message: str, key: str) -> InputError:
        return InputError(message, file=self.name, line=self.line_of(key), column=self.prefix + key)


def _build_scenario(data: dict, name: str, seed: int, file: str, doc: _Doc | None = None,
                    prefix: str = ""):
    from gyroarray.effects.model import NoiseModel  # lazy: loads numba
    from gyroarray.sim.scenario import (Scenario, parse_temperature,  # lazy: loads mujoco, numba
                                        resolve_profile, validate_scenario)

    view = _Prefixed(doc, data, file, prefix)
    rate = data.get("sample_rate_hz")
    if not _is_num(rate) or rate <= 0:
        raise view.error(f"sample_rate_hz must be a number > 0, got {_type(rate)} {rate!r}",
                         "sample_rate_hz")
    layout, _ = parse_layout(view)
    motion = data.get("motion")
    ref = motion.get("profile") if isinstance(motion, dict) else None
    if not isinstance(motion, dict) or set(motion) != {"profile"} or not isinstance(ref, str) or not ref:
        raise view.error("motion must be a table with one key, profile = \"<name or file>\"",
                         "motion")
    duration = data.get("duration_s")
    if duration is not None and (not _is_num(duration) or duration <= 0):
        raise view.error(f"duration_s must be a number > 0, got {_type(duration)} {duration!r}",
                         "duration_s")
    profile = _cached_profile(resolve_profile(ref, Path(data["_base_dir"]), view),
                              None if duration is None else float(duration))
    if duration is not None:
        if duration > profile.duration_s + 1e-9:
            raise view.error(f"duration_s = {duration:g} s is longer than the motion profile "
                             f"{ref!r} ({profile.duration_s:g} s)", "duration_s")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise view.error(f"description must be a string, got {_type(description)}", "description")
    try:
        model = NoiseModel.from_toml({"effects": data.get("effects", [])}, n_gyros=layout.n_gyros)
    except InputError as err:
        raise InputError(err.message, file=file, line=view.line_of("effects"),
                         column=prefix + (err.column if isinstance(err.column, str) else "effects")
                         ) from None
    scenario = Scenario(name=name, layout=layout, profile=profile, sample_rate_hz=float(rate),
                        model=model, seed=seed, duration_s=None if duration is None else float(duration),
                        site=parse_site(view), temperature=parse_temperature(view),
                        description=description, source=file)
    validate_scenario(scenario, view, "run")     # every scenario, before any runs
    return scenario


_PROFILES: dict = {}


def _cached_profile(path: Path, until_s: float | None = None):
    """:func:`~gyroarray.sim.profiles.load_profile` (as far as ``until_s`` needs), once per file
    version (a grid names a few profiles thousands of times)."""
    try:
        st = path.stat()
        key = (str(path.resolve()), st.st_mtime_ns, st.st_size, until_s)
    except OSError:
        return load_profile(path, until_s=until_s)      # refuses it, naming the file
    if key not in _PROFILES:
        if len(_PROFILES) > 64:
            _PROFILES.clear()
        _PROFILES[key] = load_profile(path, until_s=until_s)
    return _PROFILES[key]


# -- reading -------------------------------------------------------------------

def _shipped_dir() -> Path:
    return Path(str(data_path("scenarios")))


def _resolve_base(ref: str, here: Path, doc: _Doc, key: str = "base") -> Path:
    if not ref or "\\" in ref:
        raise doc.error(f"{key} must name a scenario file, got {ref!r}", key)
    names = [ref] if ref.endswith(".toml") else [ref + ".toml", ref]
    for folder in (here, _shipped_dir()):
        for n in names:
            p = folder / n
            if p.is_file():
                return p
    raise doc.error(f"{key}: scenario {ref!r} not found (looked in {here} and in the shipped "
                    f"scenarios {_shipped_dir()})", key)


def _check_value(key: str, v, where: str, doc: _Doc, effect_sets: dict):
    """One grid/point value, checked and normalised (numbers to float, ints kept)."""
    def bad(msg):
        return doc.error(f"{where}: {msg}, got {_type(v)} {v!r}", where)

    if key in ("scheme", "n_gyros"):
        if not isinstance(v, int) or isinstance(v, bool):
            raise bad(f"{key} must be an integer")
        if key == "scheme" and v not in (1, 2):
            raise bad("scheme must be 1 or 2")
        if key == "n_gyros" and not 3 <= v <= 1024:
            raise bad("n_gyros must be from 3 to 1024")
        return int(v)
    if key == "alpha_deg":
        if v == "optimal":
            return v
        if not _is_num(v) or not 0.0 < v <= 180.0:
            raise bad('alpha_deg must be a number in (0, 180] [deg] or "optimal"')
        return float(v)
    if key in ("rho_arw", "rho_rrw"):
        if not _is_num(v) or not -1.0 < v < 1.0:
            raise bad(f"{key} must be a number in (-1, 1)")
        return float(v)
    if key == "duration_s":
        if not _is_num(v) or v <= 0:
            raise bad("duration_s must be a number > 0 [s]")
        return float(v)
    if key == "motion":
        if not isinstance(v, str) or not v:
            raise bad("motion must name a profile (shipped name or .toml file)")
        return v
    if key == "effects":
        if not isinstance(v, str) or (v != "base" and v not in effect_sets):
            known = ", ".join(["base", *sorted(effect_sets)])
            raise bad(f"effects must name an effect set (known: {known})")
        return v
    raise AssertionError(key)


def _axis_owners() -> dict[str, str]:
    """Sweep axis -> the effect whose array-wide entry's parameter it sets (``Effect.sweep_axes``:
    ``rho_arw`` and ``rho_rrw`` of the correlation), for the axes of :data:`PARAM_KEYS`; the first
    effect in the registry's order that declares an axis owns it."""
    from gyroarray.effects import REGISTRY  # lazy: loads numba, as resolve_profile does in _apply
    owners: dict[str, str] = {}
    for e in REGISTRY.values():
        for k in e.sweep_axes:
            if k in PARAM_KEYS:
                owners.setdefault(k, e.name)
    return owners


def _array_entry(e, effect: str | None) -> bool:
    """Whether ``e`` (an entry of a scenario's effects list) is ``effect``'s array-wide entry."""
    return effect is not None and isinstance(e, dict) and e.get("effect") == effect and e.get("gyro") is None


def _base_params(data: dict) -> dict:
    lay: dict = data["layout"] if isinstance(data.get("layout"), dict) else {}
    cone = "axes" not in lay
    owner = _axis_owners()
    rho: dict[str, float | None] = {"rho_arw": None, "rho_rrw": None}
    for e in data.get("effects", []) or []:
        for k in rho:
            if _array_entry(e, owner.get(k)) and _is_num(e.get(k, 0.0)):
                rho[k] = float(e.get(k, 0.0))
    motion = data.get("motion", {}).get("profile") if isinstance(data.get("motion"), dict) else None
    return {"scheme": lay.get("scheme") if cone else None,
            "n_gyros": lay.get("n_gyros") if cone else (len(lay["axes"]) if isinstance(lay.get("axes"), list) else None),
            "alpha_deg": (float(lay["alpha_deg"]) if cone and _is_num(lay.get("alpha_deg")) else None),
            **rho, "motion": motion, "effects": "base",
            "duration_s": float(data["duration_s"]) if _is_num(data.get("duration_s")) else None}


def _apply(base: dict, base_params: dict, given: dict, effect_sets: dict, sweep_dir: Path,
           doc: _Doc, where: dict) -> tuple[dict, dict]:
    """(params, scenario data) of one point: ``given`` values over the base."""
    from gyroarray.sim.scenario import resolve_profile  # lazy: loads mujoco, numba

    p = dict(base_params)
    p.update(given)
    data = copy.deepcopy(base)
    if given.get("effects") not in (None, "base"):
        data["effects"] = copy.deepcopy(effect_sets[given["effects"]])
        if "rho_arw" not in given or "rho_rrw" not in given:    # rho from the set
            sp = _base_params({"effects": data["effects"]})
            for k in ("rho_arw", "rho_rrw"):
                if k not in given:
                    p[k] = sp[k]
    # layout
    lay: dict = data["layout"] if isinstance(data.get("layout"), dict) else {}
    if any(k in given for k in ("scheme", "n_gyros", "alpha_deg")):
        if "axes" in lay:
            k = next(k for k in ("scheme", "n_gyros", "alpha_deg") if k in given)
            raise doc.error(f"{where[k]}: the base layout has explicit axes; {k} needs a "
                            "conical base layout (scheme, n_gyros, alpha_deg)", where[k])
    if p["alpha_deg"] == "optimal":
        if p["scheme"] is None or p["n_gyros"] is None:
            raise doc.error(f'{where["alpha_deg"]}: "optimal" needs a conical layout',
                            where["alpha_deg"])
        try:
            p["alpha_deg_value"] = _optimal_alpha_deg(p["scheme"], p["n_gyros"], p["rho_arw"] or 0.0)
        except InputError as err:
            keys = sorted({where[k] for k in ("rho_arw", "n_gyros") if k in given}) or [where["alpha_deg"]]
            raise doc.error(f"{', '.join(keys)}: optimal alpha for scheme {p['scheme']}, "
                            f"N = {p['n_gyros']}, rho_arw = {p['rho_arw']}: {err.message}",
                            keys[0]) from None
    else:
        p["alpha_deg_value"] = p["alpha_deg"]
    if p["scheme"] is not None:
        data["layout"] = {"scheme": p["scheme"], "n_gyros": p["n_gyros"],
                          "alpha_deg": p["alpha_deg_value"]}
    # an effect's own axes (rho_arw, rho_rrw): its array-wide entry, replaced or added
    owner = _axis_owners()
    for name in dict.fromkeys(owner[k] for k in owner if k in given):
        effects = [e for e in data.get("effects", []) if not _array_entry(e, name)]
        old = [e for e in data.get("effects", []) if _array_entry(e, name)]
        entry = dict(old[0]) if old else {"effect": name}
        for k in owner:
            if owner[k] == name and k in given:
                entry[k] = given[k]
        data["effects"] = effects + [entry]
    # motion: resolved to a file now (grid refs relative to the sweep file)
    if "motion" in given:
        try:
            path = resolve_profile(given["motion"], sweep_dir)
        except InputError as err:
            raise doc.error(f"{where['motion']}: {err.message}", where["motion"]) from None
        data["motion"] = {"profile": str(path.resolve())}
        data["_base_dir"] = str(sweep_dir)
    if "duration_s" in given:
        data["duration_s"] = given["duration_s"]
    p["duration_s_value"] = data.get("duration_s")
    return p, data


@dataclass(frozen=True)
class _Base:
    data: dict
    params: dict
    file: str


_EXTRA_ID_KEYS = ("scenario", "replicate")     # in the id only when set (old ids unchanged)


def _load_base(base, sweep_dir: Path, doc: _Doc, key: str) -> _Base:
    """A base scenario (file reference or inline table), checked and with its parameters."""
    if isinstance(base, str):
        bpath = _resolve_base(base, sweep_dir, doc, key)
        bdoc = _read_doc(bpath, "base scenario")
        bdata, bprefix, bfile, allowed = dict(bdoc.data), "", str(bpath), _REF_BASE_KEYS
        bdata.pop("name", None), bdata.pop("seed", None)
        bdata["_base_dir"] = str(bpath.parent)
    elif isinstance(base, dict) and key == "base":
        bdoc, bprefix, bfile, allowed = doc, "base.", doc.name, _BASE_KEYS
        bdata = dict(base)
        bdata["_base_dir"] = str(sweep_dir)
    else:
        raise doc.error(f"base must be a scenario file name or a [base] table, got {_type(base)}",
                        key)
    unknown = sorted(set(bdata) - allowed - {"_base_dir"})
    if unknown:
        raise bdoc.error(f"unknown key {bprefix}{unknown[0]} (known: {', '.join(sorted(allowed))})",
                         bprefix + unknown[0])
    for k in ("sample_rate_hz", "layout", "motion"):
        if k not in bdata:
            raise bdoc.error(f"{bprefix}{k} is missing", bprefix + k)
    _build_scenario(bdata, "base", 0, bfile, bdoc, bprefix)     # the base itself is valid
    return _Base(data=bdata, params=_base_params(bdata), file=bfile)


def _check_estimators(estimators, doc: _Doc) -> tuple | None:
    """The estimator names of the sweep (None: all), checked against the registry."""
    if estimators is None:
        return None
    from gyroarray.estimators import available  # lazy: loads numba
    if not (isinstance(estimators, list) and estimators
            and all(isinstance(e, str) for e in estimators)):
        raise doc.error(f"estimators must be a non-empty array of names, got "
                        f"{_type(estimators)} {estimators!r}", "estimators")
    bad = [e for e in estimators if e not in available()]
    if bad:
        raise doc.error(f"unknown estimator {bad[0]!r} (available: {', '.join(available())})",
                        "estimators")
    if len(set(estimators)) != len(estimators):
        raise doc.error("estimators lists a name twice", "estimators")
    return tuple(estimators)


def _load_bases(d: dict, sweep_dir: Path, doc: _Doc) -> list[tuple[_Base, str | None]]:
    """The base scenario, or the listed scenario files with their names."""
    bases: list[tuple[_Base, str | None]] = []
    if "scenarios" in d:
        refs = d["scenarios"]
        if not (isinstance(refs, list) and refs and all(isinstance(r, str) for r in refs)):
            raise doc.error(f"scenarios must be a non-empty array of scenario file names, got "
                            f"{_type(refs)} {refs!r}", "scenarios")
        if len(set(refs)) != len(refs):
            raise doc.error("scenarios lists a file twice", "scenarios")
        for ref in refs:
            bases.append((_load_base(ref, sweep_dir, doc, "scenarios"), ref.removesuffix(".toml")))
    else:
        bases.append((_load_base(d["base"], sweep_dir, doc, "base"), None))
    return bases


def _check_effect_sets(d: dict, doc: _Doc) -> dict:
    """The named effect sets, each checked as a noise model."""
    effect_sets = d.get("effect_sets", {})
    if not isinstance(effect_sets, dict):
        raise doc.error(f"effect_sets must be a table, got {_type(effect_sets)}", "effect_sets")
    for k, v in effect_sets.items():
        if k == "base" or not _NAME_RE.match(k):
            raise doc.error(f"effect set name {k!r} must be [A-Za-z0-9_.-] and not 'base'",
                            f"effect_sets.{k}")
        if not isinstance(v, list):
            raise doc.error(f"effect_sets.{k} must be an array of effect tables, got {_type(v)}",
                            f"effect_sets.{k}")
        try:
            from gyroarray.effects.model import NoiseModel  # lazy: loads numba
            NoiseModel.from_toml({"effects": v})
        except InputError as err:
            raise doc.error(err.message, f"effect_sets.{k}"
                            + (f".{err.column}" if isinstance(err.column, str) else "")) from None
    return effect_sets


def _grid_combos(grid, doc: _Doc, effect_sets: dict
                 ) -> tuple[list[tuple[dict, dict]], list[tuple[dict, dict]]]:
    """(given values, where each came from) of every point of the grid; and the points to
    check first (:func:`_grid_probes`)."""
    combos: list[tuple[dict, dict]] = []
    if not isinstance(grid, dict):
        raise doc.error(f"grid must be a table, got {_type(grid)}", "grid")
    unknown = sorted(set(grid) - set(PARAM_KEYS))
    if unknown:
        raise doc.error(f"unknown key grid.{unknown[0]} (known: {', '.join(PARAM_KEYS)})",
                        f"grid.{unknown[0]}")
    axes = []
    for key in PARAM_KEYS:
        if key not in grid:
            continue
        vals = grid[key]
        if not isinstance(vals, list) or not vals:
            raise doc.error(f"grid.{key} must be a non-empty array of values, got "
                            f"{_type(vals)} {vals!r}", f"grid.{key}")
        if len(vals) > MAX_SCENARIOS:
            raise doc.error(f"grid.{key} lists {len(vals)} values; a sweep has at most "
                            f"{MAX_SCENARIOS} scenarios: split it into several sweeps", f"grid.{key}")
        norm = [_check_value(key, v, f"grid.{key}", doc, effect_sets) for v in vals]
        if len({json.dumps(v) for v in norm}) != len(norm):
            raise doc.error(f"grid.{key} lists a value twice: {vals!r}", f"grid.{key}")
        axes.append((key, norm))
    n = math.prod(len(v) for _, v in axes)
    if n > MAX_SCENARIOS:
        raise doc.error(f"the grid has {n} scenarios (" + " x ".join(f"{len(v)} {k}" for k, v in axes)
                        + f"), at most {MAX_SCENARIOS}: split it into several sweeps", "grid")
    for values in itertools.product(*[v for _, v in axes]):
        given = dict(zip([k for k, _ in axes], values))
        combos.append((given, {k: f"grid.{k}" for k in PARAM_KEYS}))
    return combos, _grid_probes(axes)


def _grid_probes(axes: list[tuple[str, list]]) -> list[tuple[dict, dict]]:
    """The grid points to check first: each value of each axis with the other axes at their
    first, then at their last values (at most twice the sum of the axis lengths points).

    A value that is invalid on its own (a duration beyond the motion, a correlation outside its
    bound for every N, ...) is then refused after a few builds instead of after the whole grid
    (issue 28: a 99,900-point grid whose last point was invalid was refused after 487 s).
    """
    where = {k: f"grid.{k}" for k in PARAM_KEYS}
    picked: dict[str, tuple[dict, dict]] = {}
    for pos in (0, -1):
        anchor = {k: v[pos] for k, v in axes}
        for key, values in axes:
            for v in values:
                probe = dict(anchor, **{key: v})
                picked.setdefault(json.dumps(probe, sort_keys=True), (probe, where))
    return list(picked.values())


def _point_combos(points, doc: _Doc, effect_sets: dict) -> list[tuple[dict, dict]]:
    """(given values, where each came from) of every listed point."""
    combos: list[tuple[dict, dict]] = []
    if not isinstance(points, list) or not all(isinstance(p, dict) for p in points):
        raise doc.error("points must be an array of tables ([[points]])", "points")
    for i, pt in enumerate(points):
        unknown = sorted(set(pt) - set(PARAM_KEYS))
        if unknown:
            raise doc.error(f"unknown key points[{i}].{unknown[0]} (known: "
                            f"{', '.join(PARAM_KEYS)})", f"points[{i}].{unknown[0]}")
        given = {k: _check_value(k, pt[k], f"points[{i}].{k}", doc, effect_sets)
                 for k in PARAM_KEYS if k in pt}
        combos.append((given, {k: f"points[{i}].{k}" for k in PARAM_KEYS}))
    return combos


def _expanded_point(path: Path, doc: _Doc, b: _Base, ref: str | None, given: dict, where: dict,
                    effect_sets: dict, seed: int, reps: list, paired: bool,
                    specs: dict[str, ScenarioSpec], excluded: dict[str, str] | None = None) -> None:
    """Build and check one point of the sweep (each replicate) into ``specs``.

    An invalid point is refused naming the sweep file and the keys that made it; with
    ``excluded`` (``skip_invalid``) it is recorded there, by id, instead.
    """
    try:
        params, data = _apply(b.data, b.params, given, effect_sets, path.parent, doc, where)
    except InputError as err:
        if excluded is None:
            raise
        excluded[scenario_id({k: given.get(k) for k in PARAM_KEYS})] = err.message
        return
    if ref is not None:
        params["scenario"] = ref
    for rep in reps:
        p = dict(params)
        if rep is not None:
            p["replicate"] = rep
        id_params = {k: p.get(k) for k in (*PARAM_KEYS, *_EXTRA_ID_KEYS)
                     if k in PARAM_KEYS or p.get(k) is not None}
        sid = scenario_id(id_params)
        if sid in specs:
            if specs[sid].params != p:      # a hash collision: never silently merge
                raise doc.error(f"two scenarios share the id {sid}", "grid")
            continue                         # the same scenario twice (grid ∪ points)
        seed_key = f"paired:{ref or ''}:{rep or 0}" if paired else sid
        spec = ScenarioSpec(id=sid, seed=scenario_seed(seed, seed_key), params=p, data=data,
                            file=b.file)
        try:
            spec.build()
        except InputError as err:
            if excluded is not None:
                excluded[sid] = err.message
                continue
            keys = [where[k] for k in given if k in ("rho_arw", "rho_rrw", "n_gyros",
                                                     "duration_s", "motion", "effects",
                                                     "alpha_deg", "scheme")]
            raise InputError(f"scenario {sid} ({_canonical(id_params)}): {err.message}",
                             file=str(path), line=err.line if err.file == str(path) else None,
                             column=(err.column if err.file == str(path) and not keys
                                     else ", ".join(sorted(set(keys))) or err.column)
                             ) from None
        specs[sid] = spec


def _expand_scenarios(path: Path, doc: _Doc, bases: list[tuple[_Base, str | None]],
                      combos: list[tuple[dict, dict]], effect_sets: dict, seed: int,
                      replicates: int | None, paired: bool, skip_invalid: bool,
                      probes: tuple | list[tuple[dict, dict]] = ()
                      ) -> tuple[dict[str, ScenarioSpec], dict[str, str]]:
    """Every (base, combination, replicate) built and checked, by id; and the excluded ones.

    The total is capped (:data:`MAX_SCENARIOS`) before anything is built, and without
    ``skip_invalid`` the ``probes`` (:func:`_grid_probes`, then each listed point) are checked
    first, so that the first invalid value is refused at once.
    """
    specs: dict[str, ScenarioSpec] = {}
    excluded: dict[str, str] = {}
    reps = [None] if replicates is None else list(range(replicates))
    total = len(bases) * len(combos) * len(reps)
    if total > MAX_SCENARIOS:
        parts = [f"{len(bases)} scenario files"] if len(bases) > 1 else []
        parts += [f"{len(combos)} grid points and points"] + (
            [f"{len(reps)} replicates"] if replicates is not None else [])
        raise doc.error(f"the sweep has {total} scenarios ({' x '.join(parts)}), at most "
                        f"{MAX_SCENARIOS}: split it into several sweeps or use fewer replicates",
                        "grid" if "grid" in doc.data else ("replicates" if replicates else "points"))
    if not skip_invalid:
        # points that are invalid on their own value are refused at once, not after the grid
        for b, ref in bases:
            for given, where in probes:
                _expanded_point(path, doc, b, ref, given, where, effect_sets, seed, reps[:1],
                                paired, {})
    for b, ref in bases:
        for given, where in combos:
            _expanded_point(path, doc, b, ref, given, where, effect_sets, seed, reps, paired, specs,
                            excluded if skip_invalid else None)
    return specs, excluded


def load_sweep(path) -> Sweep:
    """Read, strictly validate and expand a sweep file (see the module docstring).

    Raises
    ------
    InputError
        Naming the file and the key (and the line where it can be found).
    """
    path = Path(path)
    doc = _read_doc(path, "sweep file")
    d = doc.data
    unknown = sorted(set(d) - _TOP_KEYS)
    if unknown:
        raise doc.error(f"unknown key {unknown[0]!r} (known: {', '.join(sorted(_TOP_KEYS))})",
                        unknown[0])
    if "scenarios" in d:
        clash = sorted({"base", "grid", "points", "effect_sets"} & set(d))
        if clash:
            raise doc.error(f"scenarios (a list of scenario files) and {clash[0]} exclude each "
                            "other", clash[0])
    for key in ("name", "seed", "base" if "scenarios" not in d else "scenarios"):
        if key not in d:
            raise doc.error(f"{key} is missing", key)
    name = d["name"]
    if not (isinstance(name, str) and _NAME_RE.match(name)):
        raise doc.error(f"name must be 1-100 characters of A-Z a-z 0-9 _ . -, got {_type(name)} "
                        f"{name!r}", "name")
    seed = d["seed"]
    if not (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < 2**63):
        raise doc.error(f"seed must be a whole number in [0, 2^63), got {_type(seed)} {seed!r}",
                        "seed")
    description = d.get("description", "")
    if not isinstance(description, str):
        raise doc.error(f"description must be a string, got {_type(description)}", "description")
    estimators = _check_estimators(d.get("estimators"), doc)

    replicates = d.get("replicates")
    if replicates is not None and not (isinstance(replicates, int) and not isinstance(replicates, bool)
                                       and 1 <= replicates <= MAX_REPLICATES):
        raise doc.error(f"replicates must be a whole number from 1 to {MAX_REPLICATES}, got "
                        f"{_type(replicates)} {replicates!r}", "replicates")
    paired = d.get("paired", False)
    if not isinstance(paired, bool):
        raise doc.error(f"paired must be true or false, got {_type(paired)} {paired!r}", "paired")
    skip_invalid = d.get("skip_invalid", False)
    if not isinstance(skip_invalid, bool):
        raise doc.error(f"skip_invalid must be true or false, got {_type(skip_invalid)} "
                        f"{skip_invalid!r}", "skip_invalid")

    # the base (or the listed scenario files)
    bases = _load_bases(d, path.parent, doc)
    effect_sets = _check_effect_sets(d, doc)

    # grid and points
    combos: list[tuple[dict, dict]] = []           # (given values, where each came from)
    probes: list[tuple[dict, dict]] = []           # checked first (see _expand_scenarios)
    grid = d.get("grid")
    if grid is not None:
        grid_combos, probes = _grid_combos(grid, doc, effect_sets)
        combos += grid_combos
    points = d.get("points")
    if points is not None:
        if isinstance(points, list) and len(points) > MAX_SCENARIOS:
            raise doc.error(f"points lists {len(points)} scenarios, at most {MAX_SCENARIOS}: "
                            "split it into several sweeps", "points")
        point_combos = _point_combos(points, doc, effect_sets)
        combos += point_combos
        probes += point_combos
    if grid is None and points is None:
        combos.append(({}, {k: "base" for k in PARAM_KEYS}))

    specs, excluded = _expand_scenarios(path, doc, bases, combos, effect_sets, seed, replicates,
                                        paired, skip_invalid, probes)
    if not specs:
        raise doc.error("the sweep has no valid scenario"
                        + (f" (first problem: {next(iter(excluded.values()))})" if excluded else ""),
                        "grid" if "grid" in d else "base")
    return Sweep(name=name, seed=seed, estimators=estimators,
                 scenarios=tuple(specs[k] for k in sorted(specs)), description=description,
                 source=str(path), sha256=hashlib.sha256(doc.text.encode()).hexdigest(),
                 excluded=tuple(sorted(excluded.items())))
