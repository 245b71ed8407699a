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

An optional ``[array]`` table (:class:`ArrayNoise`) carries what is between
the gyros of a recorded array: the correlation matrices of the white and slow
parts, the per-gyro levels that scale them, and the lines several gyros
share. Files without it read as before; a file with it round-trips exactly
(``docs/model-format.md``).

Models and entries are frozen; parameter mappings are read-only;
:meth:`NoiseModel.with_effect` returns a new model.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from gyroarray.core.errors import InputError
from gyroarray.core.layout import UNIT_NORM_TOL
from gyroarray.effects import REGISTRY, did_you_mean, get_effect
from gyroarray.effects.protocol import Effect, Param
from gyroarray.core.limits import MAX_RATE_DEG_S
from gyroarray.core.tomlio import load_toml

__all__ = ["ModelEntry", "NoiseModel", "ArrayNoise", "AccelNoise"]

_NUMBER = (int, float, np.integer, np.floating)
_TOP_KEYS = ("effects", "description", "topic", "array", "accelerometer")


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


#: Keys of the ``[array]`` table (:class:`ArrayNoise`).
ARRAY_KEYS = ("gyros", "white_n_deg_rt_h", "white_tau_s", "white_correlation", "white_n_low_deg_rt_h",
              "white_n_high_deg_rt_h", "records", "walk_tau_s", "walk_adev_deg_h",
              "walk_correlation", "shared", "notes", "sigma")
_ARRAY_MATRICES = ("white_correlation", "walk_correlation")
_ARRAY_VECTORS = ("white_n_deg_rt_h", "white_n_low_deg_rt_h", "white_n_high_deg_rt_h", "walk_adev_deg_h")
_SHARED_KEYS = ("f_hz", "band_hz", "gyros", "coherence")
#: Largest asymmetry, and departure of a diagonal from 1, of a correlation read from a file [-].
ARRAY_MATRIX_TOL = 1e-9


def _array_error(message: str, key: str, where) -> InputError:
    """An error about ``array.key``, located by ``where`` = (file, TomlDoc or None)."""
    file, doc = where
    column = f"array.{key}" if key else "array"
    line = doc.line_of(column) if doc is not None else None
    return InputError(f"[array] {message}", file=file, line=line, column=column)


def _gyro_list(value, key: str, where) -> tuple[int, ...]:
    if not isinstance(value, (list, tuple)) or not value or not all(
            isinstance(g, (int, np.integer)) and not isinstance(g, (bool, np.bool_)) and g >= 1 for g in value):
        raise _array_error(f"{key} must be a non-empty array of gyro numbers (integers >= 1), got {value!r}",
                           key, where)
    if len(set(int(g) for g in value)) != len(value):
        raise _array_error(f"{key} names a gyro twice: {list(value)!r}", key, where)
    return tuple(int(g) for g in value)


def _vector(value, key: str, n: int, where) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != n or not all(
            _is_number(v) and math.isfinite(v) and v >= 0 for v in value):
        raise _array_error(f"{key} must be {n} non-negative numbers (one per gyro of 'gyros'), got {value!r}",
                           key, where)
    return tuple(float(v) for v in value)


def _matrix(value, key: str, n: int, where) -> tuple[tuple[float, ...], ...]:
    """A correlation matrix n×n: numbers, |ρ| <= 1, unit diagonal, symmetric, positive definite."""
    if not isinstance(value, (list, tuple)) or len(value) != n or any(
            not isinstance(r, (list, tuple)) or len(r) != n for r in value):
        raise _array_error(f"{key} must be a {n}x{n} matrix (one row and column per gyro of 'gyros'), "
                           f"got {value!r}", key, where)
    for i, row in enumerate(value):
        for j, v in enumerate(row):
            if not (_is_number(v) and math.isfinite(v)):
                raise _array_error(f"{key}[{i}][{j}] must be a finite number, got {v!r}", key, where)
            if abs(v) > 1.0:
                raise _array_error(f"{key}[{i}][{j}] = {v!r} is not a correlation (|ρ| <= 1)", key, where)
    a = np.array(value, dtype=float)
    bad = np.flatnonzero(np.abs(np.diag(a) - 1.0) > ARRAY_MATRIX_TOL)
    if bad.size:
        i = int(bad[0])
        raise _array_error(f"{key}[{i}][{i}] = {float(a[i, i])!r}: a correlation matrix has 1 on its diagonal",
                           key, where)
    asym = np.abs(a - a.T)
    if asym.max() > ARRAY_MATRIX_TOL:
        r, c = np.unravel_index(int(np.argmax(asym)), a.shape)
        raise _array_error(f"{key} is not symmetric: [{r}][{c}] = {float(a[r, c])!r} but [{c}][{r}] = "
                           f"{float(a[c, r])!r} (a correlation matrix equals its transpose)",
                           key, where)
    low = float(np.linalg.eigvalsh(a)[0])
    if low <= 0.0:
        raise _array_error(f"{key} is not positive definite (smallest eigenvalue {low:.3g}): regularise it "
                           "(gyroarray's fit clips or shrinks it) or leave gyros out", key, where)
    return tuple(tuple(float(v) for v in row) for row in value)


@dataclass(frozen=True)
class ArrayNoise:
    """The ``[array]`` table of a noise model: the array's cross-covariance, as fitted.

    Per-gyro terms stay in the effect entries (``gyro = k``); this table adds what is
    between gyros: the correlation of the white part and of the slow part and the lines they
    share. A covariance is ``Σ_ij = ρ_ij s_i s_j`` with the per-gyro scales s (white: ARW
    ``white_n_deg_rt_h`` [deg/√h]; slow: Allan deviation ``walk_adev_deg_h`` [deg/h] at
    ``walk_tau_s``). The simulator does not read it (its correlation is the ``correlation``
    effect). Format: ``docs/model-format.md``.

    Parameters
    ----------
    gyros : tuple of int
        The 1-based gyros the rows and columns are, in order.
    white_n_deg_rt_h : tuple of float, optional
        White level (ARW) of each gyro [deg/√h].
    white_correlation : tuple of tuple of float, optional
        Correlation of the white part [-], symmetric, unit diagonal, positive definite.
    white_tau_s : float, optional
        Averaging time at which the white level and correlation were read [s] (σ(τ)·√τ and the
        Allan covariance at τ, pooled over the still parts); absent: per sample.
    white_n_low_deg_rt_h, white_n_high_deg_rt_h : tuple of float, optional
        A model fitted on several records: the credible range of each gyro's white level
        between records [deg/√h] (equal to ``white_n_deg_rt_h`` ± its 2σ for a gyro that does
        not wander); estimators are designed with the high end (``docs/model-format.md``).
    records : int, optional
        Number of records the table was fitted on.
    walk_tau_s : float, optional
        Averaging time at which the slow part was estimated [s] (needed with a walk term).
    walk_adev_deg_h : tuple of float, optional
        Allan deviation of each gyro's slow part at ``walk_tau_s`` (beyond white) [deg/h].
    walk_correlation : tuple of tuple of float, optional
        Correlation of the slow part [-] (0 for gyros where it was not seen).
    shared : tuple of Mapping
        Common-mode lines: ``{f_hz, band_hz = [lo, hi], gyros = [...], coherence}``.
    notes : tuple of str
        How the matrices were made (regularisation, what was left out).
    sigma : Mapping
        Optional 1σ of the matrices and vectors above, same shapes, same keys.
    """

    gyros: tuple = ()
    white_n_deg_rt_h: tuple | None = None
    white_correlation: tuple | None = None
    white_tau_s: float | None = None
    white_n_low_deg_rt_h: tuple | None = None
    white_n_high_deg_rt_h: tuple | None = None
    records: int | None = None
    walk_tau_s: float | None = None
    walk_adev_deg_h: tuple | None = None
    walk_correlation: tuple | None = None
    shared: tuple = ()
    notes: tuple = ()
    sigma: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, data, *, file: str | None = None, doc=None) -> "ArrayNoise":
        """Read and check an ``[array]`` table (parsed TOML).

        Raises
        ------
        InputError
            Unknown key, wrong size, asymmetric or not positive definite matrix, |ρ| > 1, a
            bad gyro list; naming the file, the line (when ``doc``, the file's
            :class:`~gyroarray.core.tomlio.TomlDoc`, is given) and ``array.KEY``.
        """
        where = (file, doc)
        if not isinstance(data, Mapping):
            raise _array_error(f"must be a table, got {_type_name(data)}", "", where)
        for key in data:
            if key not in ARRAY_KEYS:
                raise _array_error(f"unknown key {key!r}{did_you_mean(key, ARRAY_KEYS)} (the table has: "
                                   f"{', '.join(ARRAY_KEYS)})", str(key), where)
        if "gyros" not in data:
            raise _array_error("needs 'gyros', the gyro numbers of its rows: gyros = [1, 2, ...]", "gyros", where)
        gyros = _gyro_list(data["gyros"], "gyros", where)
        n = len(gyros)
        out: dict[str, Any] = {"gyros": gyros}
        for key in _ARRAY_VECTORS:
            if key in data:
                out[key] = _vector(data[key], key, n, where)
        for key in _ARRAY_MATRICES:
            if key in data:
                out[key] = _matrix(data[key], key, n, where)
        if "white_tau_s" in data:
            tau = data["white_tau_s"]
            if not (_is_number(tau) and math.isfinite(tau) and tau > 0):
                raise _array_error(f"white_tau_s must be a number > 0 [s], got {tau!r}", "white_tau_s", where)
            out["white_tau_s"] = float(tau)
        if "records" in data:
            k = data["records"]
            if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= 10_000:
                raise _array_error(f"records must be a whole number from 1 to 10000, got {k!r}", "records", where)
            out["records"] = int(k)
        for lo_key, hi_key in (("white_n_low_deg_rt_h", "white_n_high_deg_rt_h"),):
            if (lo_key in out) != (hi_key in out):
                raise _array_error(f"{lo_key} and {hi_key} come together (the range of each gyro's white level)",
                                   lo_key if lo_key not in out else hi_key, where)
            if lo_key in out and any(not (0 <= a <= b) for a, b in zip(out[lo_key], out[hi_key])):
                raise _array_error(f"{lo_key} must be >= 0 and at most {hi_key}, gyro by gyro", lo_key, where)
        if "walk_tau_s" in data:
            tau = data["walk_tau_s"]
            if not (_is_number(tau) and math.isfinite(tau) and tau > 0):
                raise _array_error(f"walk_tau_s must be a number > 0 [s], got {tau!r}", "walk_tau_s", where)
            out["walk_tau_s"] = float(tau)
        elif "walk_adev_deg_h" in out or "walk_correlation" in out:
            raise _array_error("a walk term needs walk_tau_s, the averaging time it was estimated at [s]",
                               "walk_tau_s", where)
        if "shared" in data:
            out["shared"] = _shared(data["shared"], gyros, where)
        if "notes" in data:
            notes = data["notes"]
            if not isinstance(notes, list) or not all(isinstance(s, str) for s in notes):
                raise _array_error(f"notes must be an array of strings, got {notes!r}", "notes", where)
            out["notes"] = tuple(notes)
        if "sigma" in data:
            out["sigma"] = _array_sigma(data["sigma"], out, n, where)
        return cls(**out)

    def __post_init__(self):
        # checked here too, so that a table made in code writes a file that reads back
        where = (None, None)
        plain = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in
                 (("gyros", self.gyros),) + tuple((k, getattr(self, k)) for k in _ARRAY_VECTORS + _ARRAY_MATRICES)}
        object.__setattr__(self, "gyros", _gyro_list(plain["gyros"], "gyros", where))
        n = len(self.gyros)
        for key in _ARRAY_VECTORS:
            if plain[key] is not None:
                object.__setattr__(self, key, _vector(plain[key], key, n, where))
        for key in _ARRAY_MATRICES:
            if plain[key] is not None:
                object.__setattr__(self, key, _matrix(plain[key], key, n, where))
        object.__setattr__(self, "shared", tuple(MappingProxyType(dict(s)) for s in self.shared))
        object.__setattr__(self, "notes", tuple(self.notes))
        object.__setattr__(self, "sigma", MappingProxyType(dict(self.sigma)))

    def __hash__(self):
        return hash((self.gyros, self.white_correlation, self.walk_correlation))

    def to_dict(self) -> dict[str, Any]:
        """Plain dict, keys in file order, absent terms left out."""
        out: dict[str, Any] = {"gyros": list(self.gyros)}
        for key in ("white_n_deg_rt_h", "white_tau_s", "white_correlation", "white_n_low_deg_rt_h",
                    "white_n_high_deg_rt_h", "records", "walk_tau_s", "walk_adev_deg_h", "walk_correlation"):
            value = getattr(self, key)
            if value is not None:
                out[key] = _plain(value)
        if self.shared:
            out["shared"] = [{k: _plain(v) for k, v in s.items()} for s in self.shared]
        if self.notes:
            out["notes"] = list(self.notes)
        if self.sigma:
            out["sigma"] = {k: _plain(v) for k, v in self.sigma.items()}
        return out

    def toml_lines(self) -> list[str]:
        """The ``[array]`` table as TOML lines (one matrix row per line)."""
        d = self.to_dict()
        sigma = d.pop("sigma", None)
        lines = ["", "[array]"]
        for key, value in d.items():
            if key in _ARRAY_MATRICES:
                lines.append(f"{key} = [")
                lines += [f"    {_toml_value(row)}," for row in value]
                lines.append("]")
            elif key in ("shared", "notes"):
                lines.append(f"{key} = [")
                lines += [f"    {_toml_value(item)}," for item in value]
                lines.append("]")
            else:
                lines.append(f"{key} = {_toml_value(value)}")
        if sigma:
            lines += ["", "[array.sigma]"] + [f"{k} = {_toml_value(v)}" for k, v in sigma.items()]
        return lines


def _shared(value, gyros: tuple, where) -> tuple:
    if not isinstance(value, list):
        raise _array_error(f"shared must be an array of tables {{f_hz, band_hz, gyros, coherence}}, got "
                           f"{_type_name(value)}", "shared", where)
    out = []
    for i, item in enumerate(value):
        key = f"shared[{i}]"
        if not isinstance(item, Mapping) or set(item) - set(_SHARED_KEYS) or "f_hz" not in item \
                or "gyros" not in item:
            raise _array_error(f"{key} must be a table with f_hz and gyros (optional band_hz, coherence), "
                               f"got {item!r}", "shared", where)
        f = item["f_hz"]
        if not (_is_number(f) and math.isfinite(f) and f > 0):
            raise _array_error(f"{key}.f_hz must be a frequency > 0 [Hz], got {f!r}", "shared", where)
        g = _gyro_list(item["gyros"], f"{key}.gyros", where)
        if set(g) - set(gyros):
            raise _array_error(f"{key}.gyros {list(g)} names gyros not in 'gyros'", "shared", where)
        entry: dict[str, Any] = {"f_hz": float(f)}
        if "band_hz" in item:
            b = item["band_hz"]
            if not (isinstance(b, list) and len(b) == 2 and all(_is_number(v) and math.isfinite(v) for v in b)
                    and 0 <= b[0] <= f <= b[1]):
                raise _array_error(f"{key}.band_hz must be [lo, hi] [Hz] around f_hz, got {b!r}", "shared", where)
            entry["band_hz"] = tuple(float(v) for v in b)
        entry["gyros"] = g
        if "coherence" in item:
            c = item["coherence"]
            if not (_is_number(c) and 0 <= c <= 1):
                raise _array_error(f"{key}.coherence must be in [0, 1], got {c!r}", "shared", where)
            entry["coherence"] = float(c)
        out.append(MappingProxyType(entry))
    return tuple(out)


def _array_sigma(value, have: dict, n: int, where) -> dict:
    if not isinstance(value, Mapping):
        raise _array_error(f"sigma must be a table, got {_type_name(value)}", "sigma", where)
    out = {}
    for key, v in value.items():
        if key not in have or key not in _ARRAY_MATRICES + _ARRAY_VECTORS:
            raise _array_error(f"sigma.{key}: a 1σ needs its term ({', '.join(k for k in _ARRAY_MATRICES + _ARRAY_VECTORS if k in have) or 'none here'})",
                               f"sigma.{key}", where)
        rows = v if key in _ARRAY_MATRICES else [v]
        if not isinstance(v, list) or len(rows) != (n if key in _ARRAY_MATRICES else 1) or any(
                not isinstance(r, list) or len(r) != n or not all(_is_number(c) and math.isfinite(c) and c >= 0
                                                                  for c in r) for r in rows):
            raise _array_error(f"sigma.{key} must have the shape of {key} with non-negative numbers, got {v!r}",
                               f"sigma.{key}", where)
        out[key] = (tuple(tuple(float(c) for c in r) for r in rows) if key in _ARRAY_MATRICES
                    else tuple(float(c) for c in v))
    return out


#: Keys of the ``[accelerometer]`` table (:class:`AccelNoise`).
ACCEL_KEYS = ("axes", "n_m_s_rt_h", "k_m_s2_rt_h", "b_mg", "sigma", "unresolved", "record_s", "notes")
#: The noise terms of the ``[accelerometer]`` table, each with its datasheet unit.
ACCEL_TERMS: Mapping[str, str] = MappingProxyType({
    "n_m_s_rt_h": "m/s/√h",     # velocity random walk N_a: ADEV = N_a/√τ
    "k_m_s2_rt_h": "m/s²/√h",   # acceleration random walk K_a: ADEV = K_a·√(τ/3)
    "b_mg": "mg",               # bias instability B: flat ADEV floor 0.664·B
})
#: Keys of one ``unresolved.TERM.AXIS`` entry: the fit's estimate and 1σ [the term's unit], the
#: record length that would resolve it [s] (``plan --sensor acc``), and why it is not resolved.
ACCEL_UNRESOLVED_KEYS = ("estimate", "sigma", "resolve_s", "why")
_ACCEL_AXES = ("x", "y", "z")


def _accel_error(message: str, key: str, where) -> InputError:
    """An error about ``accelerometer.key``, located by ``where`` = (file, TomlDoc or None)."""
    file, doc = where
    column = f"accelerometer.{key}" if key else "accelerometer"
    line = doc.line_of(column) if doc is not None else None
    return InputError(f"[accelerometer] {message}", file=file, line=line, column=column)


def _accel_axes(value, where) -> tuple[str, ...]:
    if isinstance(value, str) or not isinstance(value, (list, tuple)) or not value or not all(
            isinstance(a, str) and a in _ACCEL_AXES for a in value) or len(set(value)) != len(value):
        raise _accel_error(f"axes must be distinct names among {list(_ACCEL_AXES)}, got {value!r}",
                           "axes", where)
    return tuple(value)


def _accel_values(value, key: str, axes: tuple, where, *, positive: bool) -> tuple[float | None, ...] | None:
    """One term (or its 1σ) per axis of ``axes``: a list of one number per axis, or a table
    ``{axis = number}`` holding only the axes that resolve it (the others None); None when no
    axis has it."""
    unit = ACCEL_TERMS.get(key.split(".")[-1], "")
    what = "> 0" if positive else ">= 0"
    n = len(axes)
    if isinstance(value, Mapping):
        for a in value:
            if a not in axes:
                raise _accel_error(f"{key}: axis {a!r} is not among axes {list(axes)} (a table gives the "
                                   "axes that resolve the term, by name)", key, where)
        items = [value.get(a) for a in axes]
        if not value:
            raise _accel_error(f"{key} must name at least one axis (leave the term out when no axis "
                               "resolves it)", key, where)
    elif isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple, np.ndarray)) or len(value) != n:
        raise _accel_error(f"{key} must be {n} numbers {what} [{unit}] (one per axis of 'axes'), or a table "
                           f"{{axis = number}} of the axes that resolve it, got {value!r}", key, where)
    else:
        items = list(value)
        if isinstance(value, list) and any(v is None for v in items):   # a TOML list has no None
            raise _accel_error(f"{key} must be {n} numbers {what} [{unit}], got {value!r}", key, where)
    for i, v in enumerate(items):
        if v is not None and not (_is_number(v) and math.isfinite(v) and (v > 0 if positive else v >= 0)):
            raise _accel_error(f"{key}[{axes[i] if isinstance(value, Mapping) else i}] must be a finite number "
                               f"{what} [{unit}], got {v!r}", key, where)
    out = tuple(None if v is None else float(v) for v in items)
    return None if all(v is None for v in out) else out


def _accel_unresolved(value, terms_present: dict, axes: tuple, where) -> Mapping:
    """The ``unresolved`` table: by term, by axis without that term, what the fit found."""
    if not isinstance(value, Mapping):
        raise _accel_error(f"unresolved must be a table of term = {{axis = {{...}}}}, got {_type_name(value)}",
                           "unresolved", where)
    out = {}
    for term, by_axis in value.items():
        key = f"unresolved.{term}"
        if term not in ACCEL_TERMS:
            raise _accel_error(f"unresolved of unknown term {term!r}{did_you_mean(str(term), tuple(ACCEL_TERMS))}",
                               key, where)
        if not isinstance(by_axis, Mapping):
            raise _accel_error(f"{key} must be a table by axis, got {_type_name(by_axis)}", key, where)
        have = terms_present.get(term)
        entries = {}
        for axis, entry in by_axis.items():
            k2 = f"{key}.{axis}"
            if axis not in axes:
                raise _accel_error(f"{k2}: axis {axis!r} is not among axes {list(axes)}", k2, where)
            if have is not None and have[axes.index(axis)] is not None:
                raise _accel_error(f"{k2}: the table holds {term} for axis {axis}, so it is not unresolved",
                                   k2, where)
            if not isinstance(entry, Mapping):
                raise _accel_error(f"{k2} must be a table ({', '.join(ACCEL_UNRESOLVED_KEYS)}), got "
                                   f"{_type_name(entry)}", k2, where)
            clean: dict = {}
            for name, v in entry.items():
                if name not in ACCEL_UNRESOLVED_KEYS:
                    raise _accel_error(f"{k2}: unknown key {name!r}{did_you_mean(str(name), ACCEL_UNRESOLVED_KEYS)}",
                                       f"{k2}.{name}", where)
                if name == "why":
                    if not isinstance(v, str):
                        raise _accel_error(f"{k2}.why must be a string, got {v!r}", f"{k2}.why", where)
                    clean[name] = v
                    continue
                ok = _is_number(v) and math.isfinite(v) and (v > 0 if name == "resolve_s" else v >= 0)
                if not ok:
                    raise _accel_error(f"{k2}.{name} must be a finite number {'> 0' if name == 'resolve_s' else '>= 0'}"
                                       f", got {v!r}", f"{k2}.{name}", where)
                clean[name] = float(v)
            entries[axis] = MappingProxyType(clean)
        out[term] = MappingProxyType(entries)
    return MappingProxyType(out)


@dataclass(frozen=True)
class AccelNoise:
    """Accelerometer noise per axis (IEEE Std 1293 terms), in the file's datasheet units.

    The ``[accelerometer]`` table of a noise model (``docs/model-format.md``), written by
    ``fit --out`` from a record's ``acc_*`` columns. The simulator does not read it.

    Parameters
    ----------
    axes : tuple of str
        The accelerometer axes the values are for, in order (among ``x``, ``y``, ``z``).
    n_m_s_rt_h : tuple of float or None, optional
        Velocity random walk N_a per axis [m/s/√h]: ADEV(τ) = N_a/√τ (N_a/60 in m/s²/√Hz).
    k_m_s2_rt_h : tuple of float or None, optional
        Acceleration random walk K_a per axis [m/s²/√h]: ADEV(τ) = K_a·√(τ/3) (K_a/60 in m/s²/√s).
    b_mg : tuple of float or None, optional
        Bias instability B per axis [mg]: the flat ADEV floor 0.664·B.
    sigma : Mapping[str, tuple]
        1σ of the terms above, same keys, one per axis (None where the term is), same units.
    unresolved : Mapping[str, Mapping[str, Mapping]]
        By term, by axis that lacks it: ``estimate`` and ``sigma`` (the fit's value and 1σ, the
        term's unit), ``resolve_s`` (the record length [s] that would resolve it, when planned)
        and ``why``.
    record_s : float, optional
        Length of record the terms were fitted on [s].
    notes : tuple of str
        How the terms were fitted, or why one is missing.

    Each term is a tuple with one entry per axis, None on an axis that does not resolve it, or
    None for the term (no axis resolves it, or not fitted). In the file a term resolved on every
    axis is a list; one resolved on some is a table ``{axis = value}``.

    Raises
    ------
    InputError
        A wrong length, a value <= 0 or not finite, a sigma without its term.
    """

    axes: tuple[str, ...] = ("x", "y", "z")
    n_m_s_rt_h: tuple[float | None, ...] | None = None
    k_m_s2_rt_h: tuple[float | None, ...] | None = None
    b_mg: tuple[float | None, ...] | None = None
    sigma: Mapping[str, tuple] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    unresolved: Mapping[str, Mapping] = field(default_factory=dict)
    record_s: float | None = None

    def __post_init__(self):
        self._check((None, None))

    def _check(self, where) -> None:
        axes = _accel_axes(list(self.axes) if isinstance(self.axes, tuple) else self.axes, where)
        object.__setattr__(self, "axes", axes)
        present = {}
        for key in ACCEL_TERMS:
            value = getattr(self, key)
            if value is not None:
                object.__setattr__(self, key, _accel_values(value, key, axes, where, positive=True))
            present[key] = getattr(self, key)
        sigma = self.sigma
        if not isinstance(sigma, Mapping):
            raise _accel_error(f"sigma must be a table of term = [1σ per axis], got {_type_name(sigma)}",
                               "sigma", where)
        out = {}
        for key, value in sigma.items():
            if key not in ACCEL_TERMS:
                raise _accel_error(f"sigma of unknown term {key!r}{did_you_mean(str(key), tuple(ACCEL_TERMS))} "
                                   f"(terms: {', '.join(ACCEL_TERMS)})", f"sigma.{key}", where)
            if getattr(self, key) is None:
                raise _accel_error(f"sigma.{key}: a 1σ needs its term {key}", f"sigma.{key}", where)
            got = _accel_values(value, f"sigma.{key}", axes, where, positive=False)
            if got is None:
                continue
            term = getattr(self, key)
            extra = [a for a, s, v in zip(axes, got, term) if s is not None and v is None]
            if extra:
                raise _accel_error(f"sigma.{key}: a 1σ on axis {', '.join(extra)}, where the table has no {key}",
                                   f"sigma.{key}", where)
            out[key] = got
        object.__setattr__(self, "sigma", MappingProxyType(out))
        object.__setattr__(self, "unresolved", _accel_unresolved(self.unresolved, present, axes, where))
        if self.record_s is not None and not (_is_number(self.record_s) and math.isfinite(self.record_s)
                                              and self.record_s > 0):
            raise _accel_error(f"record_s must be a record length > 0 [s], got {self.record_s!r}", "record_s", where)
        if self.record_s is not None:
            object.__setattr__(self, "record_s", float(self.record_s))
        notes = self.notes
        if isinstance(notes, str) or not isinstance(notes, (list, tuple)) or not all(isinstance(s, str) for s in notes):
            raise _accel_error(f"notes must be an array of strings, got {notes!r}", "notes", where)
        object.__setattr__(self, "notes", tuple(notes))

    @classmethod
    def from_dict(cls, data, *, file: str | None = None, doc=None) -> "AccelNoise":
        """Read and check an ``[accelerometer]`` table (parsed TOML).

        Raises
        ------
        InputError
            Unknown key (with the closest name), wrong length, a value <= 0 or not finite, bad
            axes; naming the file, the line (when ``doc``, the file's
            :class:`~gyroarray.core.tomlio.TomlDoc`, is given) and ``accelerometer.KEY``.
        """
        where = (file, doc)
        if not isinstance(data, Mapping):
            raise _accel_error(f"must be a table, got {_type_name(data)}", "", where)
        for key in data:
            if key not in ACCEL_KEYS:
                raise _accel_error(f"unknown key {key!r}{did_you_mean(str(key), ACCEL_KEYS)} (the table has: "
                                   f"{', '.join(ACCEL_KEYS)})", str(key), where)
        obj = cls.__new__(cls)
        values = {"axes": data.get("axes", list(_ACCEL_AXES)), "sigma": data.get("sigma", {}),
                  "notes": data.get("notes", []), "unresolved": data.get("unresolved", {}),
                  "record_s": data.get("record_s")}
        values.update({k: data.get(k) for k in ACCEL_TERMS})
        for key, value in values.items():
            object.__setattr__(obj, key, value)
        obj._check(where)
        return obj

    def __hash__(self):
        return hash((self.axes, self.n_m_s_rt_h, self.k_m_s2_rt_h, self.b_mg))

    @property
    def missing(self) -> tuple[str, ...]:
        """The terms not in the table on any axis (not fitted or not resolved), in file order."""
        return tuple(k for k in ACCEL_TERMS if getattr(self, k) is None)

    @property
    def missing_axes(self) -> dict[str, tuple[str, ...]]:
        """By term, the axes that lack it (every axis for a term in :attr:`missing`); terms held
        on every axis are not listed."""
        out = {}
        for key in ACCEL_TERMS:
            value = getattr(self, key)
            lack = self.axes if value is None else tuple(a for a, v in zip(self.axes, value) if v is None)
            if lack:
                out[key] = lack
        return out

    def _file_value(self, value):
        """A per-axis tuple as the file writes it: a list when every axis has it, else a table."""
        if all(v is not None for v in value):
            return list(value)
        return {a: v for a, v in zip(self.axes, value) if v is not None}

    def to_dict(self) -> dict[str, Any]:
        """Plain dict, keys in file order, absent terms left out (a term some axes lack: a
        dict ``{axis: value}`` of the axes that have it)."""
        out: dict[str, Any] = {"axes": list(self.axes)}
        for key in ACCEL_TERMS:
            value = getattr(self, key)
            if value is not None:
                out[key] = self._file_value(value)
        if self.sigma:
            out["sigma"] = {k: self._file_value(v) for k, v in self.sigma.items()}
        if self.unresolved:
            out["unresolved"] = {t: {a: dict(e) for a, e in by.items()} for t, by in self.unresolved.items()}
        if self.record_s is not None:
            out["record_s"] = self.record_s
        if self.notes:
            out["notes"] = list(self.notes)
        return out

    def toml_lines(self) -> list[str]:
        """The ``[accelerometer]`` table as TOML lines."""
        d = self.to_dict()
        lines = ["", "[accelerometer]"]
        for key, value in d.items():
            if key == "notes":
                lines.append("notes = [")
                lines += [f"    {_toml_value(item)}," for item in value]
                lines.append("]")
            else:
                lines.append(f"{key} = {_toml_value(value)}")
        return lines


_GYRO_LIST_RE = re.compile(r"\b(gyros?|gyro\(s\)) (\d+(?:(?:, | and )\d+)*)")


def _renumber_text(text: str, gyros: list[int]) -> str:
    """A generated note's gyro numbers (``gyro 2``, ``gyro(s) 1, 3``) renamed k → gyros[k − 1]."""
    def sub(m):
        nums = re.sub(r"\d+", lambda d: str(gyros[int(d.group()) - 1]) if 1 <= int(d.group()) <= len(gyros)
                      else d.group(), m.group(2))
        return f"{m.group(1)} {nums}"
    return _GYRO_LIST_RE.sub(sub, text)


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
    array : ArrayNoise, optional
        The ``[array]`` table: correlations between gyros of the white and
        slow parts, shared lines (None: the file has none).
    accelerometer : AccelNoise, optional
        The ``[accelerometer]`` table: velocity and acceleration random walk and bias
        instability per axis (None: the file has none).
    topic : str, optional
        The bag IMU topic the model was fitted on (top-level ``topic = "/imu0"``).
    """

    entries: tuple[ModelEntry, ...] = ()
    description: str = ""
    source: str | None = field(default=None, compare=False)
    lines: tuple = field(default=(), compare=False, repr=False)
    array: ArrayNoise | None = None
    accelerometer: AccelNoise | None = None
    topic: str | None = None

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
        if self.array is not None and not isinstance(self.array, ArrayNoise):
            raise TypeError(f"array must be an ArrayNoise, got {type(self.array).__name__}")
        if self.accelerometer is not None and not isinstance(self.accelerometer, AccelNoise):
            raise TypeError(f"accelerometer must be an AccelNoise, got {type(self.accelerometer).__name__}")
        if self.topic is not None and (not isinstance(self.topic, str) or not self.topic):
            raise InputError(f"topic must be a non-empty string (the bag IMU topic, e.g. \"/imu0\"), got "
                             f"{_type_name(self.topic)} {self.topic!r}", file=self.source, column="topic")
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
            data, file, text, doc = source, None, "", None
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
        array = ArrayNoise.from_dict(data["array"], file=file, doc=doc) if "array" in data else None
        accel = (AccelNoise.from_dict(data["accelerometer"], file=file, doc=doc)
                 if "accelerometer" in data else None)
        topic = data.get("topic")
        if topic is not None and (not isinstance(topic, str) or not topic):
            raise InputError(f"topic must be a non-empty string (the bag IMU topic, e.g. \"/imu0\"), got "
                             f"{_type_name(topic)} {topic!r}", file=file,
                             line=doc.line_of("topic") if doc is not None else None, column="topic")
        model = cls(tuple(entries), description=data.get("description", ""), source=file, lines=lines,
                    array=array, accelerometer=accel, topic=topic)
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
        if self.topic is not None:
            lines.append(f"topic = {_toml_value(self.topic)}")
        if not self.entries:
            lines.append("effects = []")
        else:
            lines.append("effects = [")
            for d in self.to_dicts():
                body = ", ".join(f"{k} = {_toml_value(v)}" for k, v in d.items())
                lines.append(f"    {{{body}}},")
            lines.append("]")
        if self.array is not None:
            lines += self.array.toml_lines()
        if self.accelerometer is not None:
            lines += self.accelerometer.toml_lines()
        return "\n".join(lines) + "\n"

    # -- new models from old ----------------------------------------------
    def with_effect(self, entry: ModelEntry) -> "NoiseModel":
        """A new model with ``entry`` appended (this one is unchanged)."""
        if not isinstance(entry, ModelEntry):
            raise TypeError(f"entry must be a ModelEntry, got {type(entry).__name__}")
        return replace(self, entries=self.entries + (entry,), lines=())

    def without_effect(self, effect: str, gyro: int | None = None) -> "NoiseModel":
        """A new model without the entry for (effect, gyro); KeyError if there is none."""
        kept = tuple(e for e in self.entries if (e.effect, e.gyro) != (effect, gyro))
        if len(kept) == len(self.entries):
            raise KeyError((effect, gyro))
        return replace(self, entries=kept, lines=())

    def renumbered(self, gyros, n_gyros: int, note: str = "") -> "NoiseModel":
        """This model, fitted on a record of ``len(gyros)`` gyros cut from one of ``n_gyros``,
        with the cut record's gyro k named ``gyros[k − 1]`` (the full record's number).

        Per-gyro entries and the ``[array]`` table (its rows, its shared lines) take the full
        record's numbers; an all-gyros entry stays one (it is the analysed gyros' common value);
        a matrix-valued parameter (a ``correlation`` matrix) is placed in the ``n_gyros`` ×
        ``n_gyros`` one, the gyros left out uncorrelated (unit diagonal). ``note`` is appended
        to the description (and to the ``[array]`` notes): which gyros were left out and why.

        Raises
        ------
        ValueError
            ``gyros`` not distinct, increasing numbers in 1..``n_gyros``, or fewer than the
            model's own gyro numbers need.
        """
        gyros = [int(g) for g in gyros]
        if sorted(set(gyros)) != gyros or not gyros or gyros[0] < 1 or gyros[-1] > n_gyros:
            raise ValueError(f"gyros must be increasing numbers in 1..{n_gyros}, got {gyros}")
        used = [e.gyro for e in self.entries if e.gyro is not None]
        if self.array is not None:
            used += list(self.array.gyros)
        if used and max(used) > len(gyros):
            raise ValueError(f"the model names gyro {max(used)}, beyond the {len(gyros)} renumbered")
        rows = [g - 1 for g in gyros]

        def full(value, base):
            # an array-wide effect's N'×N' matrix (rows and columns are gyros) into the N×N one
            if not isinstance(value, (tuple, list)) or np.ndim(value) != 2 \
                    or np.shape(value) != (len(gyros), len(gyros)):
                return value
            out = base(n_gyros)
            out[np.ix_(rows, rows)] = np.asarray(value, dtype=float)
            return tuple(tuple(float(v) for v in r) for r in out)

        entries = []
        for e in self.entries:
            params, sigma = dict(e.params), dict(e.sigma)
            if not REGISTRY[e.effect].per_gyro:
                params = {k: full(v, np.eye) for k, v in params.items()}
                sigma = {k: full(v, lambda n: np.zeros((n, n))) for k, v in sigma.items()}
            entries.append(ModelEntry(e.effect, None if e.gyro is None else gyros[e.gyro - 1], params, sigma))
        array = self.array
        if array is not None:
            shared = tuple({**s, "gyros": tuple(gyros[g - 1] for g in s["gyros"])} for s in array.shared)
            array = replace(array, gyros=tuple(gyros[g - 1] for g in array.gyros), shared=shared,
                            notes=tuple(_renumber_text(t, gyros) for t in array.notes) + ((note,) if note else ()))
        description = self.description + (("; " if self.description else "") + note if note else "")
        return NoiseModel(tuple(entries), description=description, source=self.source, array=array,
                          accelerometer=self.accelerometer, topic=self.topic)

    def with_array(self, array: ArrayNoise | None) -> "NoiseModel":
        """A new model with the ``[array]`` table ``array`` (None: without one)."""
        return replace(self, array=array)

    # -- checks needing N -------------------------------------------------
    def check(self, n_gyros: int) -> None:
        """Check what depends on the number of gyros N.

        ``gyro`` <= N, and each effect's own N-dependent rules (correlation
        matrix N×N, symmetric, unit diagonal, positive definite; scalar ρ in
        (−1/(N−1), 1)), and the ``[array]`` table's gyros <= N.

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
        if self.array is not None and max(self.array.gyros) > n_gyros:
            raise InputError(f"[array] gyros {list(self.array.gyros)}: gyro {max(self.array.gyros)} does not "
                             f"exist: the array has {n_gyros} gyros", file=self.source, column="array.gyros")

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
