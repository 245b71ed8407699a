"""The one TOML loader: every TOML file gyroarray reads comes through :func:`load_toml`.

Sidecars, scenarios, profiles, noise models, sweeps, thresholds and paper
values are all data. Before a user's TOML costs memory or a stack, it is
checked to be:

* a regular file (a FIFO, a device or a folder is refused without
  blocking, :func:`gyroarray.core.limits.open_regular`) of at most
  :data:`MAX_TOML_BYTES`;
* UTF-8 text (the line and character column of a bad byte are named);
* valid TOML (the parser's line and column are named);
* nested at most :data:`MAX_DEPTH` tables/arrays deep, with no string longer
  than :data:`MAX_STRING_CHARS` and no key longer than :data:`MAX_KEY_CHARS`.

Each refusal is one :class:`~gyroarray.core.errors.InputError`. The parsed
document comes back as a :class:`TomlDoc`, which also finds the line of a
key for later messages (``doc.error(message, "layout.alpha_deg")``).

The grammar every format shares is here too: :func:`toml_number` (a finite
number), :func:`toml_table` (a sub-table with known keys) and the words of a
refusal (:func:`toml_type`, :func:`short_repr`).

Python 3.10 has no :mod:`tomllib`; the same parser is the ``tomli`` package
there (a dependency for that version), imported here and nowhere else.
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

from gyroarray.core.errors import InputError
from gyroarray.core.limits import read_regular

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10: the same parser as a package
    import tomli as tomllib

__all__ = ["MAX_TOML_BYTES", "MAX_DEPTH", "MAX_STRING_CHARS", "MAX_KEY_CHARS", "TomlDoc", "utf8_text",
           "load_toml", "loads_toml", "TOMLDecodeError", "short_repr", "toml_type", "is_number",
           "finite_number", "toml_number", "toml_table"]

#: Largest TOML file read [bytes] (the biggest shipped one is a few KiB).
MAX_TOML_BYTES = 16 * 2**20
#: Deepest nesting of tables and arrays [-] (the formats need 4).
MAX_DEPTH = 32
#: Longest string value [characters] (a description, a path).
MAX_STRING_CHARS = 2**20
#: Longest key [characters].
MAX_KEY_CHARS = 256

TOMLDecodeError = tomllib.TOMLDecodeError
_POS_RE = re.compile(r"\s*\(at line (\d+), column (\d+)\)\s*$")
_OPEN = {ord("["), ord("{")}
_CLOSE = {ord("]"), ord("}")}


class TomlDoc:
    """A parsed TOML file and its text, to name keys (and find their lines) in errors.

    ``line_of`` understands ``[table]`` and ``[[array]]`` headers and
    ``key[i].leaf`` paths; a key it cannot find points at its table's line.

    Attributes
    ----------
    name : str
        The file as the user named it.
    text : str
        Its text.
    data : dict
        The parsed document.
    raw : bytes
        Its bytes (for fingerprints).
    """

    _TABLE_RE = re.compile(r"\s*\[\[?\s*([A-Za-z0-9_.-]+)\s*\]\]?\s*(?:#.*)?$")
    _KEY_RE = re.compile(r"\s*([A-Za-z0-9_-]+)\s*=")

    def __init__(self, name: str, text: str, data: dict, raw: bytes = b""):
        self.name, self.text, self.data, self.raw = name, text, data, raw

    def line_of(self, key: str) -> int | None:
        parts = re.sub(r"\[\d+\]", "", key).split(".")
        table, leaf = ".".join(parts[:-1]), parts[-1]
        current = ""
        for number, line in enumerate(self.text.split("\n"), 1):
            header = self._TABLE_RE.match(line)
            if header:
                current = header.group(1)
                if current == key:
                    return number
                continue
            k = self._KEY_RE.match(line)
            if k and k.group(1) == leaf and current == table:
                return number
        if table:   # a dotted key inside a table, or an inline table: the table's line
            return self.line_of(table)
        return None

    def error(self, message: str, key: str) -> InputError:
        return InputError(message, file=self.name, line=self.line_of(key), column=key)


def utf8_text(data: bytes, name: str) -> str:
    """Decode UTF-8, or refuse naming the file, line and character column."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line_start = data.rfind(b"\n", 0, e.start) + 1
        line = data.count(b"\n", 0, e.start) + 1
        column = len(data[line_start:e.start].decode("utf-8", "replace")) + 1
        raise InputError(f"not valid UTF-8 text (byte 0x{data[e.start]:02x})",
                         file=name, line=line, column=column) from None


def _too_deep_at(text: str) -> tuple[int, int] | None:
    """(line, column) where brackets first nest deeper than MAX_DEPTH (outside strings/comments)."""
    depth, line, col_start, quote, i = 0, 1, 0, "", 0
    n = len(text)
    while i < n:
        c = text[i]
        if c == "\n":
            line, col_start = line + 1, i + 1
            if quote in ('"', "'"):
                quote = ""
        elif quote:
            if c == "\\" and quote in ('"', '"""'):
                i += 1
            elif text.startswith(quote, i):
                i += len(quote) - 1
                quote = ""
        elif c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j - 1
        elif c in "\"'":
            quote = c * 3 if text.startswith(c * 3, i) else c
            i += len(quote) - 1
        elif ord(c) in _OPEN:
            depth += 1
            if depth > MAX_DEPTH:
                return line, i - col_start + 1
        elif ord(c) in _CLOSE:
            depth = max(depth - 1, 0)
        i += 1
    return None


def _check_shape(data: dict, name: str, text: str) -> None:
    """Depth, string and key length of a parsed document (iterative: no recursion)."""
    stack: list[tuple[dict | list, int, str]] = [(data, 1, "")]
    while stack:
        node, depth, path = stack.pop()
        if depth > MAX_DEPTH:
            raise _TooDeep(path)
        items = node.items() if isinstance(node, dict) else enumerate(node)
        for k, v in items:
            if isinstance(k, str) and len(k) > MAX_KEY_CHARS:
                raise InputError(f"a key of {len(k)} characters: keys are at most {MAX_KEY_CHARS}",
                                 file=name, column=f"{path}.{k[:20]}...".lstrip("."))
            where = f"{path}[{k}]" if isinstance(k, int) else f"{path}.{k}".lstrip(".")
            if isinstance(v, str) and len(v) > MAX_STRING_CHARS:
                raise InputError(f"a string of {len(v)} characters in {where}: strings are at most "
                                 f"{MAX_STRING_CHARS} characters", file=name, column=where)
            if isinstance(v, (dict, list)):
                stack.append((v, depth + 1, where))


def loads_toml(text: str, name: str) -> dict:
    """Parse TOML text with the shape caps; InputError names ``name``, line and column."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        msg = str(e).splitlines()[0] if str(e) else "invalid TOML"
        pos = _POS_RE.search(msg)
        line = getattr(e, "lineno", None) or (int(pos.group(1)) if pos else None)
        col = getattr(e, "colno", None) or (int(pos.group(2)) if pos else None)
        msg = _POS_RE.sub("", getattr(e, "msg", msg))
        raise InputError(f"TOML syntax error: {msg}", file=name, line=line, column=col) from None
    except RecursionError:
        raise _too_deep(text, name) from None
    except (ValueError, MemoryError) as e:      # the parser's own limits
        raise InputError(f"TOML error: {str(e).split(';')[0]}", file=name) from None
    try:
        _check_shape(data, name, text)
    except _TooDeep:
        raise _too_deep(text, name) from None
    return data


class _TooDeep(Exception):
    """Raised by the shape check; the location is found in the text afterwards."""


def _too_deep(text: str, name: str) -> InputError:
    at = _too_deep_at(text) or (None, None)
    return InputError(f"TOML nested more than {MAX_DEPTH} levels deep", file=name, line=at[0],
                      column=at[1])


def load_toml(path, what: str = "TOML file") -> TomlDoc:
    """Read, check and parse a TOML file the user named (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
    what : str
        What the file is, for messages (``"sidecar"``, ``"scenario file"``).
    """
    name = str(path)
    raw = read_regular(Path(path), what, max_bytes=MAX_TOML_BYTES)
    text = utf8_text(raw, name)
    return TomlDoc(name, text, loads_toml(text, name), raw)


# -- the grammar the formats share: values and tables of a parsed document ---------------------

def short_repr(v, limit: int = 40) -> str:
    """repr of a value, cut to ``limit`` characters, on one line."""
    r = repr(v)
    return r if len(r) <= limit else r[:limit] + "..."


def toml_type(v) -> str:
    """What a TOML value is, in words, with the value: ``a string ('x')``."""
    kinds = ((bool, "a boolean"), (int, "an integer"), (float, "a number"),
             (str, "a string"), (list, "an array"), (dict, "a table"))
    for t, word in kinds:
        if isinstance(v, t):
            return f"{word} ({short_repr(v)})"
    return f"a {type(v).__name__} ({short_repr(v)})"


def is_number(v) -> bool:
    """Whether ``v`` is a TOML number (an integer or a float; a boolean is not)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def finite_number(v) -> float | None:
    """float(v) for a TOML number (not bool) if finite, else None."""
    if not is_number(v):
        return None
    try:
        x = float(v)
    except OverflowError:            # TOML integers are unbounded
        return None
    return x if math.isfinite(x) else None


def toml_number(doc: TomlDoc, v, key: str) -> float:
    """A finite TOML number (int or float, not bool); refused at the line of ``key``."""
    if not is_number(v):
        raise doc.error(f"{key} must be a number, got {toml_type(v)}", key)
    x = finite_number(v)
    if x is None:
        raise doc.error(f"{key} must be finite, got {short_repr(v)}", key)
    return x


def toml_table(doc: TomlDoc, key: str, allowed: set[str]) -> dict | None:
    """The sub-table ``key`` (None if absent), refusing unknown keys in it."""
    t = doc.data.get(key)
    if t is None:
        return None
    if not isinstance(t, dict):
        raise doc.error(f"{key} must be a table ([{key}]), got {toml_type(t)}", key)
    unknown = sorted(set(t) - allowed)
    if unknown:
        raise doc.error(f"unknown key {key}.{unknown[0]} (known: {', '.join(sorted(allowed))})",
                        f"{key}.{unknown[0]}")
    return t
