"""Noise files of the tools users come from, read into a noise model with their true meanings.

``gyroarray import imu_utils|allan_variance_ros FILE --out MODEL.toml`` reads the YAML that
gaowenliang/imu_utils or ori-drs/allan_variance_ros writes and gives a
:class:`~gyroarray.effects.model.NoiseModel` (gyro entries, and the ``[accelerometer]`` table)
whose description and notes say where each number came from and how it was converted
(``docs/tool-conventions.md`` tabulates every tool's fields).

**imu_utils** (github.com/gaowenliang/imu_utils, ``src/imu_an.cpp`` ``writeYAML``, read at commit
2cdda91): an OpenCV ``%YAML:1.0`` file ``type: IMU``, ``name``, and ``Gyr`` / ``Acc`` maps, each
with ``unit`` (``" rad/s"``, ``" m/s^2"``) and ``avg-axis``, ``x-axis``, ``y-axis``, ``z-axis``
maps of ``gyr_n``, ``gyr_w`` (``acc_n``, ``acc_w``). Their meanings, from
``src/gyr_lib/fitallan_gyr.cpp`` (``acc_lib/fitallan_acc.cpp`` alike):

* ``gyr_n = getWhiteNoise() = sqrt(freq)·σ_fit(τ = 1 s)``: the fitted Allan deviation at 1 s
  times √(sample rate), i.e. one sample's standard deviation σ_d = N·√R [rad/s] (the README's
  "rad/s/√Hz" is wrong). So N = gyr_n/√R, and the rate R is needed (``rate_hz``).
* ``gyr_w = getBiasInstability() = min over τ of σ_fit(τ)``: the floor of the fitted Allan
  deviation [rad/s], 0.664·B for a flicker floor (IEEE Std 952), **not** a random walk. So
  B = gyr_w/√(2 ln2/π) (imu_utils' own ``getB`` divides by 0.6642824703). Where the ARW and RRW
  lines still add to the floor, the minimum is above 0.664·B: the B read is an upper bound.
* Inside, rad/s is multiplied by 57.3·3600 to "deg/h" and divided by the same to write rad/s:
  the 57.3 (not 180/π) cancels, the values are in true rad/s.
* ``avg-axis`` is the mean of the three axes; the per-axis values are imported, as gyro 1, 2, 3 =
  x, y, z (and accelerometer axes x, y, z). imu_utils writes no random walk (it fits K but does
  not write it): the model has none, and says so.

**allan_variance_ros** (github.com/ori-drs/allan_variance_ros, ``scripts/analysis.py``, read at
commit 1d54b60): a Kalibr ``imu.yaml`` with ``accelerometer_noise_density``,
``accelerometer_random_walk``, ``gyroscope_noise_density``, ``gyroscope_random_walk``,
``rostopic`` and ``update_rate``:

* ``*_noise_density``: the ADEV at τ = 1 s of a slope −½ line fitted (log-log, slope fixed) to
  the Allan deviation below τ = 10 s: the continuous density N [rad/s/√Hz = rad/√s; m/s²/√Hz].
* ``*_random_walk``: the ADEV at τ = 3 s of a slope +½ line fitted to the whole curve (every τ):
  the IEEE RRW coefficient K [rad/s²/√Hz; m/s³/√Hz] where the curve is that line.
* Each is the **worst** of the three axes (since commit 7a3a461, 2022-10-18; the mean before); the
  per-axis values are printed, not written, so one all-gyros entry (and the same value on the
  three accelerometer axes) is imported. The printed bias instability is not in the file.
* The gyro is analysed in deg/s and written ×π/180 (rad). With numpy ≥ 2 its ``repr`` writes
  ``np.float64(1.2e-4)``, which is read as the number.
* Without ``--config`` the script writes its defaults ``rostopic: '/sensors/imu'`` and
  ``update_rate: 400.0`` with ``#Make sure this is correct``: then the topic is not taken.

The same reader takes a Kalibr ``imu.yaml`` (same keys, same continuous convention).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from typing import Any

from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.limits import read_regular
from gyroarray.effects import did_you_mean
from gyroarray.effects.model import AccelNoise, ModelEntry, NoiseModel
from gyroarray.effects.names import ARW, BIAS_INSTABILITY, RRW

__all__ = ["TOOLS", "FLICKER_ADEV", "MAX_FILE_BYTES", "MIN_RATE_HZ", "MAX_RATE_HZ", "ToolFile",
           "read_tool_yaml", "import_imu_utils", "import_allan_variance_ros", "import_noise"]

#: The tools read, and what their file is.
TOOLS = {
    "imu_utils": "gaowenliang/imu_utils NAME_imu_param.yaml (per-sample σ and ADEV floor, per axis)",
    "allan_variance_ros": "ori-drs/allan_variance_ros imu.yaml (Kalibr continuous densities, worst axis)",
}

#: √(2 ln2/π) = 0.66428: the flat Allan deviation of bias instability B (flicker) is this × B
#: (IEEE Std 952; imu_utils' ``getB`` divides by 0.6642824703).
FLICKER_ADEV = math.sqrt(2.0 * math.log(2.0) / math.pi)

#: Largest file read [bytes]: the tools write a few hundred bytes.
MAX_FILE_BYTES = 1 << 20

#: Sample rates accepted for imu_utils' per-sample values [Hz] (as ``export``'s).
MIN_RATE_HZ, MAX_RATE_HZ = 1e-3, 1e6

_AXES = ("x", "y", "z")
_NP_FLOAT = re.compile(r"^\s*np\.float(?:16|32|64|128)?\((.*)\)\s*$")
_NUMBER_TEXT = re.compile(r"^\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*$")
_AVR_KEYS = ("accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
             "gyroscope_random_walk", "rostopic", "update_rate")
_AVR_DEFAULT_MARK = "Make sure this is correct"
_IMU_UTILS_TOP = ("type", "name", "Gyr", "Acc")
_IMU_UTILS_AXES = ("avg-axis", "x-axis", "y-axis", "z-axis")


@dataclass(frozen=True)
class ToolFile:
    """A tool's YAML file, parsed safely, with the place of every value for messages.

    Parameters
    ----------
    file : str
        The path as the user gave it.
    text : str
        The file's text (an OpenCV ``%YAML:1.0`` directive turned into a comment).
    data : object
        The parsed document (safe loader: no tags run).
    root : object
        The composed node tree (ruamel.yaml nodes) of the same text, for line and column.
    """

    file: str
    text: str
    data: Any
    root: Any

    def where(self, path: tuple, key: bool = False) -> tuple[int | None, int | None]:
        """1-based (line, column) of the value at key ``path`` (of its key when ``key``; the
        deepest part found)."""
        node, found = self.root, None
        for part in path:
            if node is None or not hasattr(node, "value") or not isinstance(node.value, list):
                break
            nxt = None
            for pair in node.value:
                if isinstance(pair, tuple) and getattr(pair[0], "value", None) == part:
                    nxt = pair[0] if key and part == path[-1] else pair[1]
                    break
            if nxt is None:
                break
            node = found = nxt
        if found is None:
            return (1, 1) if self.text else (None, None)
        mark = found.start_mark
        return mark.line + 1, mark.column + 1

    def error(self, message: str, path: tuple = (), key: bool = False) -> InputError:
        """An :class:`InputError` at the value of ``path`` in this file (at its key when ``key``)."""
        line, column = self.where(path, key)
        return InputError(message, file=self.file, line=line, column=column)

    def line_text(self, path: tuple) -> str:
        """The text of the line the value at ``path`` is on ("" when unknown)."""
        line, _ = self.where(path)
        lines = self.text.split("\n")
        return lines[line - 1] if line is not None and 0 < line <= len(lines) else ""


def read_tool_yaml(path, tool: str) -> ToolFile:
    """Read a tool's YAML output safely (ruamel.yaml's safe loader: tags never run).

    Parameters
    ----------
    path : str or PathLike
        The file.
    tool : str
        One of :data:`TOOLS`, for messages.

    Raises
    ------
    InputError
        Not a regular file, larger than :data:`MAX_FILE_BYTES`, not UTF-8, not YAML (with the
        line and column), or not a mapping at its top.
    """
    # deferred: ruamel.yaml loads only when a file is imported
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError
    name = os.fspath(path)
    raw = read_regular(path, f"{tool} file", max_bytes=MAX_FILE_BYTES)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise InputError(f"the {tool} file is not UTF-8 text (byte {err.start + 1})", file=name) from None
    if text.startswith("\ufeff"):
        text = text[1:]
    # OpenCV's FileStorage writes "%YAML:1.0", which is no YAML directive: made a comment (the
    # line numbers stay)
    text = re.sub(r"\A%YAML:[0-9.]+", lambda m: "#" + m.group()[1:], text)
    try:
        data = YAML(typ="safe", pure=True).load(text)
        root = YAML(typ="safe", pure=True).compose(text)
    except RecursionError:
        raise InputError(f"the {tool} file nests too deep to be read (a real one nests 3 levels)",
                         file=name) from None
    except YAMLError as err:
        mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
        problem = getattr(err, "problem", None) or " ".join(str(err).split())[:200]
        raise InputError(f"not valid YAML: {problem}", file=name,
                         line=None if mark is None else mark.line + 1,
                         column=None if mark is None else mark.column + 1) from None
    except (ValueError, TypeError, OverflowError) as err:   # a constructor refusing a value
        raise InputError(f"not valid YAML: {' '.join(str(err).split())[:200]}", file=name) from None
    if not isinstance(data, dict):
        kind = "empty" if data is None else f"a {type(data).__name__}"
        raise InputError(f"the {tool} file is {kind}, not a mapping of its fields "
                         f"({_expected(tool)})", file=name, line=1 if text else None)
    return ToolFile(name, text, data, root)


def _expected(tool: str) -> str:
    if tool == "imu_utils":
        return "type: IMU, name, Gyr: {unit, avg-axis, x-axis, y-axis, z-axis}, Acc: {...}"
    return ", ".join(_AVR_KEYS)


def _number(doc: ToolFile, value, path: tuple, *, np_repr: bool = False) -> float:
    """A positive finite number at ``path``."""
    label = ".".join(str(p) for p in path)
    v = value
    if isinstance(v, str) and np_repr:
        m = _NP_FLOAT.match(v)
        if m:
            v = m.group(1)
        if isinstance(v, str) and _NUMBER_TEXT.match(v):
            v = float(v)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        shown = "nothing (null)" if v is None else f"{type(v).__name__} {v!r}"[:80]
        raise doc.error(f"{label} must be a number, got {shown}", path)
    v = float(v)
    if not math.isfinite(v):
        raise doc.error(f"{label} must be finite, got {v!r}", path)
    if v <= 0.0:
        raise doc.error(f"{label} = {v!r}: the tool writes a positive value; a {v:g} is no "
                        "measurement (re-run the tool, or leave the field out)", path)
    return v


def _rate(rate_hz, what: str) -> float:
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, (int, float)) or not math.isfinite(rate_hz) \
            or not MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ:
        raise InputError(f"--rate-hz must be in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {rate_hz!r} "
                         f"({what})")
    return float(rate_hz)


def _entry(doc: ToolFile, effect: str, gyro: int | None, params: dict, path: tuple) -> ModelEntry:
    try:
        return ModelEntry(effect, gyro, params)
    except InputError as err:
        raise doc.error(f"{'.'.join(map(str, path))} converts to {effect} {err.message}", path) from None


def _accel(doc: ToolFile, path: tuple, **kwargs) -> AccelNoise:
    try:
        return AccelNoise(**kwargs)
    except InputError as err:
        raise doc.error(f"{'.'.join(map(str, path))} gives an accelerometer table that is refused: "
                        f"{err.message}", path) from None


def _g(x: float) -> str:
    return f"{x:.6g}"


# -- imu_utils ---------------------------------------------------------------------------------

def _imu_utils_block(doc: ToolFile, key: str, prefix: str, unit: str):
    """The per-axis (n, w) of ``Gyr`` or ``Acc``: ``{"x": (n, w), ...}`` or ``{"avg": (n, w)}``
    when only ``avg-axis`` is there; and the avg-axis pair (or None)."""
    block = doc.data[key]
    if not isinstance(block, dict):
        raise doc.error(f"{key} must be a map of unit, avg-axis, x-axis, y-axis, z-axis, got "
                        f"{type(block).__name__}", (key,))
    for k in block:
        if k not in ("unit",) + _IMU_UTILS_AXES:
            raise doc.error(f"{key}: unknown key {k!r}{did_you_mean(str(k), ('unit',) + _IMU_UTILS_AXES)} "
                            f"(imu_utils writes unit, {', '.join(_IMU_UTILS_AXES)})", (key, k), key=True)
    got_unit = block.get("unit")
    if got_unit is not None and (not isinstance(got_unit, str) or got_unit.strip() != unit):
        raise doc.error(f"{key}.unit is {got_unit!r}; imu_utils writes {unit!r} (its values are "
                        f"converted from {unit} only)", (key, "unit"))
    pairs = {}
    for axis in _IMU_UTILS_AXES:
        if axis not in block:
            continue
        sub = block[axis]
        if not isinstance(sub, dict):
            raise doc.error(f"{key}.{axis} must be a map of {prefix}_n and {prefix}_w, got "
                            f"{type(sub).__name__}", (key, axis))
        names = (f"{prefix}_n", f"{prefix}_w")
        for k in sub:
            if k not in names:
                lacking = tuple(n for n in names if n not in sub) or names
                raise doc.error(f"{key}.{axis}: unknown key {k!r}{did_you_mean(str(k), lacking)} "
                                f"(imu_utils writes {names[0]}, {names[1]})", (key, axis, k), key=True)
        for k in names:
            if k not in sub:
                raise doc.error(f"{key}.{axis} has no {k}", (key, axis))
        pairs[axis] = tuple(_number(doc, sub[k], (key, axis, k)) for k in names)
    per_axis = [a for a in ("x-axis", "y-axis", "z-axis") if a in pairs]
    if per_axis and len(per_axis) < 3:
        missing = sorted(set(("x-axis", "y-axis", "z-axis")) - set(per_axis))
        raise doc.error(f"{key} has {', '.join(per_axis)} but not {', '.join(missing)} (imu_utils "
                        "writes all three axes)", (key,))
    if not pairs:
        raise doc.error(f"{key} has no values (imu_utils writes {', '.join(_IMU_UTILS_AXES)})", (key,))
    avg = pairs.get("avg-axis")
    if per_axis:
        return {a[0]: pairs[a] for a in per_axis}, avg
    return {"avg": avg}, avg


def import_imu_utils(doc: ToolFile, rate_hz: float | None) -> tuple[NoiseModel, dict]:
    """An imu_utils ``NAME_imu_param.yaml`` as a noise model (module docstring: the meanings).

    Parameters
    ----------
    doc : ToolFile
        The file (:func:`read_tool_yaml`).
    rate_hz : float or None
        The IMU's sample rate R [Hz] the tool analysed: N = gyr_n/√R. Required.

    Returns
    -------
    model : NoiseModel
        ``arw`` and ``bias_instability`` per gyro (1, 2, 3 = x, y, z; one all-gyros pair when the
        file has only ``avg-axis``) and an ``[accelerometer]`` table (``n_m_s_rt_h``, ``b_mg``).
    summary : dict
        What was read and converted (JSON-ready).

    Raises
    ------
    InputError
        No rate; a missing, misspelled or non-positive field (with its line and column).
    """
    if rate_hz is None:
        raise InputError("imu_utils' gyr_n and acc_n are per-sample standard deviations "
                         "(√rate × the fitted ADEV at 1 s, fitallan_gyr.cpp getWhiteNoise): give the "
                         "IMU's sample rate with --rate-hz (imu_utils prints it as 'freq')",
                         file=doc.file)
    rate = _rate(rate_hz, "the rate imu_utils' gyr_n and acc_n were sampled at")
    data = doc.data
    for k in data:
        if k not in _IMU_UTILS_TOP:
            hint = (" (this looks like a Kalibr/allan_variance_ros imu.yaml: use "
                    "'gyroarray import allan_variance_ros')" if k in _AVR_KEYS else "")
            raise doc.error(f"unknown key {k!r}{did_you_mean(str(k), _IMU_UTILS_TOP)} (imu_utils writes "
                            f"{', '.join(_IMU_UTILS_TOP)}){hint}", (k,), key=True)
    if data.get("type", "IMU") != "IMU":
        raise doc.error(f"type is {data.get('type')!r}; imu_utils writes type: IMU", ("type",))
    if "Gyr" not in data:
        raise doc.error("no Gyr map: not an imu_utils NAME_imu_param.yaml (it has type: IMU, name, "
                        "Gyr, Acc)", ())
    name = data.get("name")
    name = None if name is None else str(name)
    root_rate = math.sqrt(rate)
    gyro_axes, gyro_avg = _imu_utils_block(doc, "Gyr", "gyr", "rad/s")
    entries, gyros = [], []
    for number, (axis, (n_d, w)) in enumerate(gyro_axes.items(), 1):
        gyro = None if axis == "avg" else number
        key = ("Gyr", "avg-axis" if axis == "avg" else f"{axis}-axis")
        n_si = n_d / root_rate                                   # σ_d = N·√R  ->  N [rad/√s]
        b_si = w / FLICKER_ADEV                                  # floor 0.664·B  ->  B [rad/s]
        n_deg = units.arw_rad_rt_s_to_deg_rt_h(n_si)
        b_deg = units.rad_s_to_deg_h(b_si)
        entries.append(_entry(doc, ARW, gyro, {"n_deg_rt_h": n_deg}, key + ("gyr_n",)))
        entries.append(_entry(doc, BIAS_INSTABILITY, gyro, {"b_deg_h": b_deg}, key + ("gyr_w",)))
        gyros.append({"gyro": gyro, "axis": axis, "gyr_n_rad_s": n_d, "gyr_w_rad_s": w,
                      "n_rad_rt_s": n_si, "n_deg_rt_h": n_deg, "b_rad_s": b_si, "b_deg_h": b_deg})
    which = ("gyro 1, 2, 3 = x-axis, y-axis, z-axis" if len(gyros) == 3
             else "avg-axis only (the mean of the three axes), one entry for every gyro")
    desc = (f"imported from {os.path.basename(doc.file)} (imu_utils{f', IMU {name!r}' if name else ''}) by "
            f"gyroarray import at --rate-hz {rate:g}: {which}. ARW N = gyr_n/√({rate:g} Hz): imu_utils' "
            "gyr_n [rad/s] is one sample's σ, √rate × its fitted ADEV at τ = 1 s (src/gyr_lib/"
            "fitallan_gyr.cpp getWhiteNoise), not a density. Bias instability B = gyr_w/0.66428 "
            "(√(2 ln2/π)): gyr_w [rad/s] is the minimum of its fitted ADEV (getBiasInstability), the "
            "flicker floor 0.664·B, not a random walk; an upper bound on B where ARW or RRW add to the "
            "floor. No rrw entry: imu_utils writes no rate random walk.")
    if len(gyros) == 3 and gyro_avg is not None:
        desc += f" Its avg-axis (not used): gyr_n {_g(gyro_avg[0])}, gyr_w {_g(gyro_avg[1])} rad/s."
    summary: dict = {"tool": "imu_utils", "file": doc.file, "name": name, "rate_hz": rate, "gyros": gyros}
    accel = None
    if "Acc" in data:
        acc_axes, acc_avg = _imu_utils_block(doc, "Acc", "acc", "m/s^2")
        n_vals = [units.vrw_si_to_m_s_rt_h(n_d / root_rate) for n_d, _ in acc_axes.values()]
        b_vals = [units.m_s2_to_mg(w / FLICKER_ADEV) for _, w in acc_axes.values()]
        only_avg = "avg" in acc_axes
        if only_avg:
            n_vals, b_vals = n_vals * 3, b_vals * 3
        notes = [f"imported from {os.path.basename(doc.file)} (imu_utils) at --rate-hz {rate:g}: "
                 + ("avg-axis only (the mean of the three axes), repeated on x, y, z; " if only_avg else "")
                 + f"velocity random walk N_a = acc_n/√({rate:g} Hz) (acc_n [m/s²] is one sample's σ, "
                 "√rate × the fitted ADEV at 1 s, src/acc_lib/fitallan_acc.cpp getWhiteNoise), in m/s/√h "
                 "(×60)",
                 "b_mg = acc_w/0.66428 (√(2 ln2/π)) in mg: acc_w [m/s²] is the minimum of the fitted "
                 "ADEV (getBiasInstability), the flicker floor 0.664·B, not a random walk",
                 "k_m_s2_rt_h missing: imu_utils writes no acceleration random walk"]
        if not only_avg and acc_avg is not None:
            notes.append(f"its avg-axis (not used): acc_n {_g(acc_avg[0])} m/s², acc_w {_g(acc_avg[1])} m/s²")
        accel = _accel(doc, ("Acc",), axes=_AXES, n_m_s_rt_h=tuple(n_vals), b_mg=tuple(b_vals),
                       notes=tuple(notes))
        summary["accelerometer"] = {"axes": list(_AXES), "n_m_s_rt_h": n_vals, "b_mg": b_vals,
                                    "missing": ["k_m_s2_rt_h"]}
    else:
        desc += " No [accelerometer] table: the file has no Acc map."
        summary["accelerometer"] = None
    model = NoiseModel(tuple(entries), description=desc, accelerometer=accel)
    summary["description"] = desc
    return model, summary


# -- allan_variance_ros ------------------------------------------------------------------------

def import_allan_variance_ros(doc: ToolFile, rate_hz: float | None = None) -> tuple[NoiseModel, dict]:
    """An allan_variance_ros ``imu.yaml`` (or a Kalibr ``imu.yaml``) as a noise model.

    Parameters
    ----------
    doc : ToolFile
        The file (:func:`read_tool_yaml`).
    rate_hz : float or None
        Not needed (the densities are continuous); when given and different from the file's
        ``update_rate``, the summary says so.

    Returns
    -------
    model : NoiseModel
        One all-gyros ``arw`` and ``rrw`` (the file's worst axis), an ``[accelerometer]``
        table (``n_m_s_rt_h``, ``k_m_s2_rt_h``, the same on x, y, z) when the file has the
        accelerometer fields, the ``topic`` when ``rostopic`` is not the script's default.
    summary : dict
        What was read and converted (JSON-ready).

    Raises
    ------
    InputError
        A missing, misspelled or non-positive field (with its line and column).
    """
    data = doc.data
    for k in data:
        if k not in _AVR_KEYS:
            hint = (" (this looks like an imu_utils file: use 'gyroarray import imu_utils')"
                    if k in _IMU_UTILS_TOP else "")
            lacking = tuple(n for n in _AVR_KEYS if n not in data) or _AVR_KEYS
            raise doc.error(f"unknown key {k!r}{did_you_mean(str(k), lacking)} (allan_variance_ros "
                            f"writes {', '.join(_AVR_KEYS)}){hint}", (k,), key=True)
    for k in ("gyroscope_noise_density", "gyroscope_random_walk"):
        if k not in data:
            raise doc.error(f"no {k}: allan_variance_ros writes {', '.join(_AVR_KEYS)}", ())
    n_si = _number(doc, data["gyroscope_noise_density"], ("gyroscope_noise_density",), np_repr=True)
    k_si = _number(doc, data["gyroscope_random_walk"], ("gyroscope_random_walk",), np_repr=True)
    n_deg = units.arw_rad_rt_s_to_deg_rt_h(n_si)
    k_deg = units.rrw_rad_s_rt_s_to_deg_h_rt_h(k_si)
    entries = (_entry(doc, ARW, None, {"n_deg_rt_h": n_deg}, ("gyroscope_noise_density",)),
               _entry(doc, RRW, None, {"k_deg_h_rt_h": k_deg}, ("gyroscope_random_walk",)))
    summary: dict = {"tool": "allan_variance_ros", "file": doc.file,
                     "gyros": [{"gyro": None, "axis": "worst",
                                "gyroscope_noise_density": n_si, "gyroscope_random_walk": k_si,
                                "n_deg_rt_h": n_deg, "k_deg_h_rt_h": k_deg}]}
    topic, notes = None, []
    if "rostopic" in data:
        raw = data["rostopic"]
        if not isinstance(raw, str) or not raw.strip():
            raise doc.error(f"rostopic must be a topic name, got {raw!r}"[:120], ("rostopic",))
        if _AVR_DEFAULT_MARK in doc.line_text(("rostopic",)):
            notes.append(f"rostopic {raw!r} is analysis.py's default (written without --config, "
                         "'#Make sure this is correct'): the topic is not taken")
        else:
            topic = raw.strip()
    update = None
    if "update_rate" in data:
        update = _number(doc, data["update_rate"], ("update_rate",), np_repr=True)
        if _AVR_DEFAULT_MARK in doc.line_text(("update_rate",)):
            notes.append(f"update_rate {update:g} is analysis.py's default (no --config)")
    if rate_hz is not None:
        rate = _rate(rate_hz, "not needed: the densities are continuous")
        if update is not None and abs(rate - update) > 1e-9 * update:
            notes.append(f"--rate-hz {rate:g} differs from the file's update_rate {update:g}; neither "
                         "enters the conversion (continuous densities)")
    summary["update_rate_hz"] = update
    desc = (f"imported from {os.path.basename(doc.file)} (allan_variance_ros scripts/analysis.py, a Kalibr "
            "imu.yaml) by gyroarray import: one entry for every gyro, the file's worst axis of x, y, z "
            "(the per-axis values are printed by the script, not written; before its commit 7a3a461 of "
            "2022-10-18 the mean of the three). ARW N = gyroscope_noise_density [rad/s/√Hz = rad/√s], "
            "the ADEV at τ = 1 s of a slope −½ line fitted below τ = 10 s; RRW K = gyroscope_random_walk "
            "[rad/s²/√Hz = rad/s/√s], the ADEV at τ = 3 s of a slope +½ line fitted to the whole curve; "
            "both continuous (IEEE Std 952), converted ×180/π·60 to deg/√h and ×180/π·3600·60 to "
            "deg/h/√h. The bias instability the script prints is not in the file: no bias_instability entry.")
    if notes:
        desc += " " + "; ".join(notes) + "."
    accel = None
    acc_keys = ("accelerometer_noise_density", "accelerometer_random_walk")
    present = [k for k in acc_keys if k in data]
    if present:
        na = _number(doc, data[acc_keys[0]], (acc_keys[0],), np_repr=True) if acc_keys[0] in data else None
        ka = _number(doc, data[acc_keys[1]], (acc_keys[1],), np_repr=True) if acc_keys[1] in data else None
        a_notes = [f"imported from {os.path.basename(doc.file)} (allan_variance_ros): the worst axis of "
                   "x, y, z, the same value on each (the per-axis values are not in the file)"]
        if na is not None:
            a_notes.append("n_m_s_rt_h = accelerometer_noise_density [m/s²/√Hz = m/s/√s] × 60 (ADEV at "
                           "τ = 1 s of the slope −½ line)")
        else:
            a_notes.append("n_m_s_rt_h missing: the file has no accelerometer_noise_density")
        if ka is not None:
            a_notes.append("k_m_s2_rt_h = accelerometer_random_walk [m/s³/√Hz = m/s²/√s] × 60 (ADEV at "
                           "τ = 3 s of the slope +½ line)")
        else:
            a_notes.append("k_m_s2_rt_h missing: the file has no accelerometer_random_walk")
        a_notes.append("b_mg missing: the bias instability the script prints is not in the file")
        accel = _accel(doc, (present[0],), axes=_AXES,
                       n_m_s_rt_h=None if na is None else (units.vrw_si_to_m_s_rt_h(na),) * 3,
                       k_m_s2_rt_h=None if ka is None else (units.accel_rw_si_to_m_s2_rt_h(ka),) * 3,
                       notes=tuple(a_notes))
        summary["accelerometer"] = {"axes": list(_AXES), "accelerometer_noise_density": na,
                                    "accelerometer_random_walk": ka,
                                    "n_m_s_rt_h": None if accel.n_m_s_rt_h is None else list(accel.n_m_s_rt_h),
                                    "k_m_s2_rt_h": None if accel.k_m_s2_rt_h is None else list(accel.k_m_s2_rt_h),
                                    "missing": list(accel.missing)}
    else:
        desc += " No [accelerometer] table: the file has no accelerometer fields."
        summary["accelerometer"] = None
    model = NoiseModel(entries, description=desc, accelerometer=accel, topic=topic)
    summary["topic"] = topic
    summary["notes"] = notes
    summary["description"] = desc
    return model, summary


_READERS = {"imu_utils": import_imu_utils, "allan_variance_ros": import_allan_variance_ros}


def import_noise(path, tool: str, rate_hz: float | None = None) -> tuple[NoiseModel, dict]:
    """Read ``tool``'s output file ``path`` into a noise model (what ``gyroarray import`` does).

    Parameters
    ----------
    path : str or PathLike
        The tool's YAML file (never modified).
    tool : str
        One of :data:`TOOLS`.
    rate_hz : float, optional
        The IMU's sample rate [Hz]; required for imu_utils (its values are per sample).

    Returns
    -------
    model : NoiseModel
    summary : dict
        The fields read, the converted values and the notes (JSON-ready).

    Raises
    ------
    InputError
        An unknown tool, or a file that is not the tool's output (file, line, column).
    """
    if tool not in _READERS:
        raise InputError(f"unknown tool {tool!r}{did_you_mean(tool, tuple(_READERS))}; expected one of "
                         f"{', '.join(_READERS)}")
    doc = read_tool_yaml(path, tool)
    return _READERS[tool](doc, rate_hz)
