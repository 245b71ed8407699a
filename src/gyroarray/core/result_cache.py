"""Saved results beside the outputs, keyed by a hash of their inputs (issue 29: results in, pictures out).

A report re-renders from results that the chain, the predictor or the sweep
computed once: the hypothesis checks of the paper comparison
(``DIR/hypotheses.json``), the Allan-deviation curves of a re-simulated record
(``DIR/adev.json``). Each file maps a key to one result's JSON dict::

    {"schema": 1, "kind": "hypotheses", "gyroarray": "0.1.0", "entries": {KEY: {...}, ...}}

The key (:func:`input_key`) is the SHA-256 of everything the result depends on
(the check's table, the scenario file's bytes, the estimator, the seed ...) and
of the package version, so a result of other inputs or of another version is
never read: it is recomputed and the entry replaced. A file that does not parse,
of another schema or kind, is ignored the same way (never trusted blindly). A
folder that cannot be written leaves the results uncached (:attr:`ResultCache.why_not`).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from gyroarray import __version__
from gyroarray.core.errors import InputError
from gyroarray.core.limits import read_json
from gyroarray.core.outputs import write_text

__all__ = ["CACHE_SCHEMA", "input_key", "file_digest", "ResultCache"]

#: Version of the cache files' layout; a file of another schema is ignored.
CACHE_SCHEMA = 1


def input_key(*parts) -> str:
    """SHA-256 (hex) of ``parts`` as canonical JSON, with the package version and the schema.

    Parameters
    ----------
    *parts
        JSON-serialisable inputs of a result (dicts are sorted by key; other
        objects are written with ``str``).
    """
    text = json.dumps([CACHE_SCHEMA, __version__, *parts], sort_keys=True, default=str,
                      separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def file_digest(path) -> str:
    """SHA-256 (hex) of a file's bytes ("" when it cannot be read: the key then changes)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return ""


class ResultCache:
    """One JSON file of saved results of one kind, read once, written on :meth:`save`.

    Parameters
    ----------
    path : path-like or None
        The file (``None``: nothing is read or written, every lookup misses).
    kind : str
        What the file holds (``"hypotheses"``, ``"adev"``); a file of another kind is ignored.
    """

    def __init__(self, path, kind: str):
        self.path = None if path is None else Path(path)
        self.kind = kind
        self.entries: dict[str, dict] = {}
        self.hits = 0
        self.misses = 0
        self.why_not = ""                  # why the file was not written (empty: written or clean)
        self._dirty = False
        if self.path is not None and self.path.is_file():
            try:
                data = read_json(self.path, f"{kind} results")
            except InputError:
                data = None                # unreadable: recomputed and replaced on save
            if (isinstance(data, dict) and data.get("schema") == CACHE_SCHEMA
                    and data.get("kind") == kind and isinstance(data.get("entries"), dict)):
                self.entries = {k: v for k, v in data["entries"].items() if isinstance(v, dict)}

    def get(self, key: str) -> dict | None:
        """The saved result of ``key``, or None (counted as a hit or a miss)."""
        hit = self.entries.get(key)
        if hit is None:
            self.misses += 1
        else:
            self.hits += 1
        return hit

    def put(self, key: str, value: dict) -> None:
        """Keep ``value`` (a JSON-ready dict) under ``key``; written by :meth:`save`."""
        self.entries[key] = value
        self._dirty = True

    def save(self) -> Path | None:
        """Write the file atomically if something was added; None when not written (see ``why_not``)."""
        if self.path is None or not self._dirty:
            return None
        text = json.dumps({"schema": CACHE_SCHEMA, "kind": self.kind, "gyroarray": __version__,
                           "entries": self.entries}, indent=1, sort_keys=True, allow_nan=False)
        try:
            out = write_text(self.path, text + "\n", force=True)
        except InputError as err:
            self.why_not = err.message
            return None
        self._dirty = False
        return out
