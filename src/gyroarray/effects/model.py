"""Noise models: a list of effect entries, read from and written to TOML.

A noise model is an ordered list of entries; each names one effect of
``shared/spec/effects.md`` (:data:`gyroarray.effects.REGISTRY`), the gyro
it applies to (1-based; omitted = every gyro, only for per-gyro effects) and
its parameters in the spec's units, exactly as the user wrote them. One line
of TOML per effect::

    description = "baseline plus a scale-factor error on gyro 2"
    effects = [
        {effect = "arw", n_deg_rt_h = 0.1},
        {effect = "rrw", k_deg_h_rt_h = 2.0},
        {effect = "correlation", rho_arw = 0.2},
        {effect = "scale_factor", gyro = 2, ppm = 6000},
        {effect = "misalignment", gyro = 3, tilt_deg = 0.5, tilt_azimuth_deg = 90},
    ]

The array-of-tables form (``[[effects]]`` blocks) is the same TOML and is
read the same way. A ``gyro = k`` entry overrides an all-gyros entry of the
same effect for gyro k; two entries for the same (effect, gyro) are refused.

Everything is validated when an entry is made: unknown effect (with the
closest name), unknown, missing or mistyped parameter, value out of bounds,
``gyro`` on an array-wide effect, rules across parameters. What depends on
the number of gyros N (``gyro`` <= N, a correlation matrix's size and
definiteness, a scalar ρ's lower bound −1/(N−1)) is checked by
:meth:`NoiseModel.check` (``from_toml(..., n_gyros=N)`` and the simulator
call it). Each problem is one :class:`~gyroarray.core.errors.InputError` naming the
file, the entry (``effects[i]``, 0-based as in the TOML array) and the key.

Models and entries are frozen; parameter mappings are read-only;
:meth:`NoiseModel.with_effect` returns a new model.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from gyroarray.core.errors import InputError
from gyroarray.core.layout import UNIT_NORM_TOL
from gyroarray.effects import REGISTRY, did_you_mean, get_effect
from gyroarray.effects.protocol import Effect, Param
from gyroarray.core.limits import MAX_RATE_DEG_S
from gyroarray.core.tomlio import load_toml

__all__ = ["ModelEntry", "NoiseModel"]

_NUMBER = (int, float, np.integer, np.floating)
_TOP_KEYS = ("effects", "description")


def _is_number(v) -> bool:
    return isinstance(v, _NUMBER) and not isinstance(v, (bool, np.bool_))


def _type_name(v) -> str:
    return {bool: "boolean", str: "string", list: "array", dict: "table"}.get(type(v), type(v).__name__)


def _number(prm: Param, value, label: str):
    if not _is_number(value):
        raise InputError(f"{label}: {prm.name} must be a number [{prm.unit}], got "
                         f"{_type_name(value)} {value!r}", column=prm.name)
    v = value.item() if isinstance(value, np.generic) else value
    if not math.isfinite(v):
        raise InputError(f"{label}: {prm.name} must be finite, got {v!r}", column=prm.name)
    return v


def _check_value(prm: Param, value, label: str):
    """The value, checked for type and bounds, as an immutable object."""
    if prm.kind == "flag":
        if not isinstance(value, (bool, np.bool_)):
            raise InputError(f"{label}: {prm.name} must be true or false, got "
                             f"{_type_name(value)} {value!r}", column=prm.name)
        return bool(value)
    if prm.kind == "axis":
        if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, (Sequence, np.ndarray)) \
                or len(value) != 3 or not all(_is_number(c) for c in value):
            raise InputError(f"{label}: {prm.name} must be 3 numbers [x, y, z], got {value!r}",
                             column=prm.name)
        a = tuple(_number(prm, c, label) for c in value)
        norm = math.sqrt(sum(c * c for c in a))
        if abs(norm - 1.0) > UNIT_NORM_TOL:
            raise InputError(f"{label}: {prm.name} {list(a)} is not a unit vector (norm {norm:.6g}, "
                             f"allowed 1 ± {UNIT_NORM_TOL:g})", column=prm.name)
        return a
    if prm.kind == "vector":
        if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, (Sequence, np.ndarray)) \
                or len(value) != 3 or not all(_is_number(c) for c in value):
            raise InputError(f"{label}: {prm.name} must be 3 numbers [x, y, z] [{prm.unit}], got "
                             f"{value!r}", column=prm.name)
        return tuple(_number(prm, c, label) for c in value)
    if prm.kind == "rho":
        if _is_number(value):
            r = _number(prm, value, label)
            if not -1.0 <= r <= 1.0:
                raise InputError(f"{label}: {prm.name} = {r:g} is not a correlation "
                                 "(must be in [-1, 1])", column=prm.name)
            return r
        rows = value if isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, str) else None
        if rows is None or len(rows) < 2 or any(
                isinstance(r, str) or not isinstance(r, (Sequence, np.ndarray)) or len(r) != len(rows)
                or not all(_is_number(c) for c in r) for r in rows):
            raise InputError(f"{label}: {prm.name} must be a number or a square N×N matrix "
                             f"(array of N arrays of N numbers), got {value!r}", column=prm.name)
        return tuple(tuple(_number(prm, c, label) for c in r) for r in rows)
    v = _number(prm, value, label)
    too_low = v <= prm.lo if prm.lo_open else v < prm.lo
    too_high = v >= prm.hi if prm.hi_open else v > prm.hi
    if too_low or too_high:
        raise InputError(f"{label}: {prm.name} = {v!r} [{prm.unit}] is out of range: must be "
                         f"{prm.bounds_text()}", column=prm.name)
    limit = PLAUSIBLE.get(prm.unit)
    if limit is not None and abs(v) > limit:
        raise InputError(f"{label}: {prm.name} = {v:g} [{prm.unit}] is beyond what a gyro can have "
                         f"(|{prm.name}| <= {limit:g} {prm.unit}: rates stay within "
                         f"{MAX_RATE_DEG_S:g} deg/s)", column=prm.name)
    return v


#: Largest magnitude of a parameter, by unit, that a physical gyro can have:
#: each keeps the rate it makes within :data:`~gyroarray.core.limits.MAX_RATE_DEG_S`
#: (1e5 deg/s = 3.6e8 deg/h) over an hour, or at a 1 Hz bandwidth for the
#: noise densities (N [deg/√h] / 60 = σ [deg/s] at 1 Hz). Beyond these a
#: value is a unit error, and the simulation's arithmetic would overflow.
PLAUSIBLE: Mapping[str, float] = MappingProxyType({
    "deg/√h": 60.0 * MAX_RATE_DEG_S,            # ARW: σ at 1 Hz = N/60
    "deg/h/√h": 3600.0 * MAX_RATE_DEG_S,        # RRW: K·√(1 h)
    "deg/h": 3600.0 * MAX_RATE_DEG_S,           # bias, instability, Gauss-Markov σ
    "deg/h²": 3600.0 * MAX_RATE_DEG_S,          # rate ramp over 1 h
    "deg/s": MAX_RATE_DEG_S,                    # sinusoid amplitude, saturation range
    "deg/h/°C": 36.0 * MAX_RATE_DEG_S,          # over 100 °C
    "ppm": 1e6,                                 # scale factor within ±100 %
    "1/(deg/s)": 0.1,                           # k2·ω² within 1e5 deg/s at 1000 deg/s
    "Hz": 1e6,
    "deg": 1e6,
    "°C": 1e4,
})


def _si(eff: Effect, params: Mapping[str, Any]) -> dict[str, Any]:
    out = {}
    for prm in eff.params:
        value = params.get(prm.name, prm.default)
        if value is not None:
            out[prm.si_name] = prm.to_si(value)
    return out


@dataclass(frozen=True)
class ModelEntry:
    """One effect in a noise model.

    Parameters
    ----------
    effect : str
        Effect name (``shared/spec/effects.md``).
    gyro : int or None
        1-based gyro for a per-gyro effect; None = every gyro (and always
        None for an array-wide effect).
    params : Mapping[str, object]
        Parameters in the spec's units, as written by the user; stored as a
        read-only mapping (arrays as tuples).
    sigma : Mapping[str, object]
        Optional 1σ of fitted parameters (same units; TOML key ``sigma``, a
        table), written by ``fit --out`` and ``ladder --model-out``: the
        uncertainty a model carries to a record it is validated on. Never
        simulated.

    Attributes
    ----------
    si_params : Mapping[str, object]
        The parameters converted to SI once (by ``Param.si_name``), defaults
        filled in; read-only.

    Raises
    ------
    InputError
        On any invalid name, gyro or parameter (``column`` = the key).
    """

    effect: str
    gyro: int | None = None
    params: Mapping[str, Any] = field(default_factory=dict)
    sigma: Mapping[str, Any] = field(default_factory=dict, compare=False)
    si_params: Mapping[str, Any] = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        try:
            eff = get_effect(self.effect)
        except InputError as err:
            raise InputError(err.message, column="effect") from None
        label = self.label
        if self.gyro is not None:
            if isinstance(self.gyro, (bool, np.bool_)) or not isinstance(self.gyro, (int, np.integer)) \
                    or self.gyro < 1:
                raise InputError(f"{label}: gyro must be an integer >= 1 (gyros are numbered "
                                 f"from 1), got {self.gyro!r}", column="gyro")
            if not eff.per_gyro:
                raise InputError(f"{label}: {eff.name} acts on the whole array; remove 'gyro'",
                                 column="gyro")
            object.__setattr__(self, "gyro", int(self.gyro))
        raw = self.params
        if not isinstance(raw, Mapping):
            raise InputError(f"{label}: params must be a mapping, got {_type_name(raw)}")
        checked = {}
        for key, value in raw.items():
            if key not in eff.param_names:
                raise InputError(f"{label}: unknown parameter {key!r}{did_you_mean(key, eff.param_names)} "
                                 f"(parameters of {eff.name}: {_param_list(eff)})", column=str(key))
            checked[key] = _check_value(eff.param(key), value, label)
        for prm in eff.params:
            if prm.required and prm.name not in checked:
                raise InputError(f"{label}: missing parameter {prm.name!r} [{prm.unit}] "
                                 f"({prm.doc})", column=prm.name)
        if eff.check is not None:
            try:
                eff.check(checked, self.gyro, None)
            except InputError as err:
                raise InputError(f"{label}: {err.message}", column=err.column) from None
        ordered = {p.name: checked[p.name] for p in eff.params if p.name in checked}
        object.__setattr__(self, "params", MappingProxyType(ordered))
        object.__setattr__(self, "sigma", MappingProxyType(_check_sigma(eff, self.sigma, label)))
        object.__setattr__(self, "si_params", MappingProxyType(_si(eff, ordered)))

    def __hash__(self):
        return hash((self.effect, self.gyro, tuple(self.params.items())))

    @property
    def label(self) -> str:
        """``arw (all gyros)`` / ``scale_factor (gyro 2)`` / ``correlation``."""
        eff = REGISTRY.get(self.effect)
        if eff is not None and not eff.per_gyro:
            return str(self.effect)
        return f"{self.effect} ({'all gyros' if self.gyro is None else f'gyro {self.gyro}'})"

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for TOML/JSON: ``effect``, ``gyro`` (if any), the parameters."""
        out: dict[str, Any] = {"effect": self.effect}
        if self.gyro is not None:
            out["gyro"] = self.gyro
        for key, value in self.params.items():
            out[key] = _plain(value)
        if self.sigma:
            out["sigma"] = {k: _plain(v) for k, v in self.sigma.items()}
        return out


def _check_sigma(eff: Effect, sigma, label: str) -> dict:
    """The ``sigma`` table: parameter names of the effect, non-negative finite numbers (a list
    for a vector parameter)."""
    if not isinstance(sigma, Mapping):
        raise InputError(f"{label}: sigma must be a table of parameter = 1σ, got {_type_name(sigma)}",
                         column="sigma")
    out = {}
    for key, value in sigma.items():
        if key not in eff.param_names:
            raise InputError(f"{label}: sigma of unknown parameter {key!r} (parameters of {eff.name}: "
                             f"{_param_list(eff)})", column=f"sigma.{key}")
        vals = value if isinstance(value, (list, tuple)) else [value]
        if not vals or not all(_is_number(v) and math.isfinite(v) and v >= 0 for v in vals):
            raise InputError(f"{label}: sigma.{key} must be a non-negative number (or one per "
                             f"component), got {value!r}", column=f"sigma.{key}")
        out[key] = tuple(float(v) for v in vals) if isinstance(value, (list, tuple)) else float(value)
    return out


def _param_list(eff: Effect) -> str:
    return ", ".join(f"{p.name} [{p.unit}]" for p in eff.params)


def _plain(value):
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def _located(err: InputError, index: int | None, file: str | None, line: int | None = None) -> InputError:
    """``err`` of one entry, located at ``effects[index]`` (and the file and line)."""
    where = f"effects[{index}]"
    column = where if err.column is None else f"{where}.{err.column}"
    return InputError(f"{where} {err.message}", file=file, line=line, column=column)


_EFFECT_KEY = re.compile(r"""(?:^|[{,\s])effect\s*=\s*["']""")
_EFFECTS_HEADER = re.compile(r"\s*\[\[\s*effects\s*\]\]")


def _entry_lines(text: str, n: int) -> tuple[int | None, ...]:
    """The 1-based line of each of the ``n`` entries of the ``effects`` array in a model's TOML
    text (its ``[[effects]]`` header, or the line of its ``effect = "..."`` key), for messages;
    all None when the text does not show them one by one (then messages name no line)."""
    headers, keys = [], []
    for number, line in enumerate(text.split("\n"), 1):
        code = line.split("#", 1)[0] if '"' not in line and "'" not in line else line
        if _EFFECTS_HEADER.match(code):
            headers.append(number)
        keys += [number] * len(_EFFECT_KEY.findall(code))
    for found in (headers, keys):
        if len(found) == n:
            return tuple(found)
    return (None,) * n


@dataclass(frozen=True)
class NoiseModel:
    """A noise model: the effects of a gyro array, one entry each.

    Parameters
    ----------
    entries : sequence of ModelEntry
        Stored as a tuple. No two entries for the same (effect, gyro).
    description : str
        Free text.
    source : str or None
        File it was read from (for messages; not compared).
    lines : tuple of (int or None)
        Line of each entry in that file (for messages; not compared; empty
        when unknown).
    """

    entries: tuple[ModelEntry, ...] = ()
    description: str = ""
    source: str | None = field(default=None, compare=False)
    lines: tuple = field(default=(), compare=False, repr=False)

    def __post_init__(self):
        entries = tuple(self.entries)
        seen: dict[tuple[str, int | None], int] = {}
        for i, e in enumerate(entries):
            if not isinstance(e, ModelEntry):
                raise TypeError(f"entries[{i}] must be a ModelEntry, got {type(e).__name__}")
            key = (e.effect, e.gyro)
            if key in seen:
                raise InputError(f"effects[{i}] duplicates effects[{seen[key]}]: both set "
                                 f"{e.label}", file=self.source, column=f"effects[{i}]")
            seen[key] = i
        if not isinstance(self.description, str):
            raise InputError(f"description must be a string, got {_type_name(self.description)}",
                             file=self.source, column="description")
        object.__setattr__(self, "entries", entries)

    # -- reading and writing --------------------------------------------
    @classmethod
    def from_toml(cls, source: str | os.PathLike | Mapping[str, Any], *,
                  n_gyros: int | None = None) -> "NoiseModel":
        """Read a model from a TOML file (path) or an already parsed TOML mapping.

        Parameters
        ----------
        source : str, PathLike or Mapping
            Path of a ``.toml`` file, or its parsed content.
        n_gyros : int, optional
            Number of gyros N: also run :meth:`check`.

        Raises
        ------
        InputError
            Unreadable file, bad TOML (with line and column), or an invalid
            model (naming ``effects[i]`` and the key).
        """
        if isinstance(source, Mapping):
            data, file, text = source, None, ""
        else:
            file = os.fspath(source)
            doc = load_toml(file, "noise model")
            data, text = doc.data, doc.text
        for key in data:
            if key not in _TOP_KEYS:
                raise InputError(f"unknown top-level key {key!r}{did_you_mean(key, _TOP_KEYS)} "
                                 f"(a noise model has: {', '.join(_TOP_KEYS)})", file=file, column=str(key))
        if "effects" not in data:
            raise InputError("no 'effects' array: write effects = [ {effect = \"arw\", "
                             "n_deg_rt_h = 0.1}, ... ]", file=file, column="effects")
        items = data["effects"]
        if not isinstance(items, list):
            raise InputError(f"'effects' must be an array of tables, got {_type_name(items)}",
                             file=file, column="effects")
        lines = _entry_lines(text, len(items))
        entries = []
        for i, item in enumerate(items):
            if not isinstance(item, Mapping):
                raise InputError(f"effects[{i}] must be a table {{effect = \"...\", ...}}, got "
                                 f"{_type_name(item)} {item!r}", file=file, column=f"effects[{i}]")
            if "effect" not in item:
                raise InputError(f"effects[{i}] has no 'effect' key (which effect is it?)",
                                 file=file, column=f"effects[{i}]")
            if not isinstance(item["effect"], str):
                raise InputError(f"effects[{i}] effect must be a name (string), got "
                                 f"{_type_name(item['effect'])} {item['effect']!r}",
                                 file=file, column=f"effects[{i}].effect")
            params = {k: v for k, v in item.items() if k not in ("effect", "gyro", "sigma")}
            try:
                entries.append(ModelEntry(item["effect"], item.get("gyro"), params, item.get("sigma", {})))
            except InputError as err:
                raise _located(err, i, file, lines[i]) from None
        model = cls(tuple(entries), description=data.get("description", ""), source=file, lines=lines)
        if n_gyros is not None:
            model.check(n_gyros)
        return model

    def to_dicts(self) -> list[dict[str, Any]]:
        """The entries as plain dicts (JSON output)."""
        return [e.to_dict() for e in self.entries]

    def to_toml(self) -> str:
        """TOML text, one line per effect; ``from_toml`` reads it back to an equal model."""
        lines = ["# gyroarray noise model (effects: shared/spec/effects.md)"]
        if self.description:
            lines.append(f"description = {_toml_value(self.description)}")
        if not self.entries:
            lines.append("effects = []")
        else:
            lines.append("effects = [")
            for d in self.to_dicts():
                body = ", ".join(f"{k} = {_toml_value(v)}" for k, v in d.items())
                lines.append(f"    {{{body}}},")
            lines.append("]")
        return "\n".join(lines) + "\n"

    # -- new models from old ----------------------------------------------
    def with_effect(self, entry: ModelEntry) -> "NoiseModel":
        """A new model with ``entry`` appended (this one is unchanged)."""
        if not isinstance(entry, ModelEntry):
            raise TypeError(f"entry must be a ModelEntry, got {type(entry).__name__}")
        return NoiseModel(self.entries + (entry,), description=self.description, source=self.source)

    def without_effect(self, effect: str, gyro: int | None = None) -> "NoiseModel":
        """A new model without the entry for (effect, gyro); KeyError if there is none."""
        kept = tuple(e for e in self.entries if (e.effect, e.gyro) != (effect, gyro))
        if len(kept) == len(self.entries):
            raise KeyError((effect, gyro))
        return NoiseModel(kept, description=self.description, source=self.source)

    # -- checks needing N -------------------------------------------------
    def check(self, n_gyros: int) -> None:
        """Check what depends on the number of gyros N.

        ``gyro`` <= N, and each effect's own N-dependent rules (correlation
        matrix N×N, symmetric, unit diagonal, positive definite; scalar ρ in
        (−1/(N−1), 1)).

        Raises
        ------
        InputError
            Naming ``effects[i]`` and the key.
        """
        if isinstance(n_gyros, bool) or not isinstance(n_gyros, (int, np.integer)) or n_gyros < 1:
            raise InputError(f"number of gyros must be an integer >= 1, got {n_gyros!r}")
        for i, e in enumerate(self.entries):
            if e.gyro is not None and e.gyro > n_gyros:
                raise _located(InputError(f"{e.label}: gyro {e.gyro} does not exist: the array "
                                          f"has {n_gyros} gyros", column="gyro"), i, self.source,
                               self.entry_line(i))
            eff = REGISTRY[e.effect]
            if eff.check is not None:
                try:
                    eff.check(e.params, e.gyro, int(n_gyros))
                except InputError as err:
                    raise _located(InputError(f"{e.label}: {err.message}", column=err.column),
                                   i, self.source, self.entry_line(i)) from None

    def entry_line(self, index: int) -> int | None:
        """Line of entry ``index`` in the file the model was read from, or None."""
        return self.lines[index] if 0 <= index < len(self.lines) else None

    def located(self, index: int, err: InputError) -> InputError:
        """``err`` about entry ``index``, located at ``effects[index]`` in the model's file and line."""
        return _located(err, index, self.source, self.entry_line(index))

    # -- container protocol -----------------------------------------------
    def __len__(self) -> int:
        return len(self.entries)

    def __iter__(self) -> Iterator[ModelEntry]:
        return iter(self.entries)
