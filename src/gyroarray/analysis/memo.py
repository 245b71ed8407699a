"""Results of pure analysis functions reused for inputs of the same content.

A ladder analyses one record again after each step; the tests of the gyros
a step did not touch then read the same residual, bit for bit. A function
decorated with :func:`by_content` keeps its last results keyed by the
content of its arguments (arrays by dtype, shape and a SHA-256 digest of
their bytes; numbers and strings by value), so such a call is answered
from the cache: the same result, not an approximation. Calls with any other
kind of argument are not cached. Thread-safe (the Monte-Carlo band runs on
threads).

The digest of an array made read-only where it was created (:func:`freeze`) is kept by the
array's identity: a record's clock, reference and residuals are read by many tests, each keyed
by content, and were hashed again on every call (5 s of a 46-min, 5-gyro diagnosis). Kept only
for an array that cannot change: read-only itself, a view of (or itself) an array that owns its
memory and is read-only too; dropped when that array is freed. A writeable array is hashed on
every call.
"""

from __future__ import annotations

import functools
import hashlib
import threading
import weakref
from collections import OrderedDict

import numpy as np

__all__ = ["by_content", "content_key", "ContentMemo", "clear_all", "freeze"]

#: Every cache this module made (the functions' and the memos' clear methods), for
#: :func:`clear_all`.
_CACHES: list = []


def clear_all() -> None:
    """Empty every content cache of the process.

    A command (a ladder, a diagnosis) starts from empty caches, so that what it returns never
    depends on what the process computed before it: the caches hold only results of pure
    functions of their arguments, but a module constant changed between two calls (a test's
    monkeypatch, a user's experiment) would otherwise be answered with the old constant's result.
    """
    for clear in list(_CACHES):
        clear()
    with _DIGEST_LOCK:
        _DIGESTS.clear()


class _Uncacheable(Exception):
    pass


def freeze(*arrays):
    """Make each ndarray of ``arrays`` read-only (None and other objects pass as they are) and
    return the first (or all, for several): what the caller created and will not change, so
    that its digest is kept (:func:`_digest`). Only for an array no writeable view of which
    has been handed out: a frozen array must not change while it lives."""
    for a in arrays:
        if isinstance(a, np.ndarray):
            a.flags.writeable = False
    return arrays[0] if len(arrays) == 1 else arrays


#: id(owner) -> (weakref to the owner, {view key: digest}): the digests of read-only views of a
#: read-only array that owns its memory (:func:`_digest`); an entry leaves with its owner.
_DIGESTS: dict = {}
_DIGEST_LOCK = threading.Lock()


def _forget(owner_id: int) -> None:
    # without the lock (one dict operation, atomic): the owner's finalizer may run inside a
    # garbage collection that an allocation under the lock started, in the same thread
    _DIGESTS.pop(owner_id, None)


def _owner(a: np.ndarray) -> np.ndarray | None:
    """The array that owns ``a``'s memory, when it and ``a`` are read-only, else None."""
    if a.flags.writeable:
        return None
    o = a
    while isinstance(o.base, np.ndarray):
        o = o.base
    if o.base is not None or o.flags.writeable:          # memory of another object, or changeable
        return None
    return o


def _sha256(a: np.ndarray) -> bytes:
    c = np.ascontiguousarray(a)
    # SHA-256: 2.5x BLAKE2b's speed here (the CPU's SHA extensions), the same use of a digest
    return hashlib.sha256(c.view(np.uint8).reshape(-1).data).digest()


def _digest(a: np.ndarray) -> bytes:
    """SHA-256 of ``a``'s bytes (C order), kept for a read-only view of a read-only owner."""
    owner = _owner(a)
    if owner is None:
        return _sha256(a)
    key = (a.__array_interface__["data"][0], a.shape, a.strides, a.dtype.str)
    with _DIGEST_LOCK:
        hit = _DIGESTS.get(id(owner))
        if hit is not None and hit[0]() is owner:
            d = hit[1].get(key)
            if d is not None:
                return d
    d = _sha256(a)
    with _DIGEST_LOCK:
        hit = _DIGESTS.get(id(owner))
        if hit is None or hit[0]() is not owner:
            views: dict = {}
            hit = _DIGESTS[id(owner)] = (weakref.ref(owner), views)
            weakref.finalize(owner, _forget, id(owner))
        hit[1][key] = d
    return d


def _part(v):
    if isinstance(v, np.ndarray):
        if v.dtype.hasobject:
            raise _Uncacheable
        return ("nd", v.dtype.str, v.shape, _digest(v))
    if isinstance(v, np.generic):
        return v.item()
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    raise _Uncacheable


def by_content(maxsize: int = 16):
    """Decorator: cache the ``maxsize`` latest results of a pure function by argument content."""
    def deco(fn):
        cache: OrderedDict = OrderedDict()
        lock = threading.Lock()

        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            try:
                key = (tuple(_part(a) for a in args), tuple(sorted((k, _part(v)) for k, v in kwargs.items())))
            except _Uncacheable:
                return fn(*args, **kwargs)
            with lock:
                if key in cache:
                    cache.move_to_end(key)
                    return cache[key]
            out = fn(*args, **kwargs)
            with lock:
                cache[key] = out
                while len(cache) > maxsize:
                    cache.popitem(last=False)
            return out

        def cache_clear():
            with lock:
                cache.clear()
        wrapper.cache_clear = cache_clear
        _CACHES.append(cache_clear)
        return wrapper
    return deco


def content_key(*args):
    """The key :func:`by_content` would give these arguments, or None when one cannot be keyed."""
    try:
        return tuple(_part(a) for a in args)
    except _Uncacheable:
        return None


class ContentMemo:
    """The ``maxsize`` latest dicts of results, one per content key (:func:`content_key`): for a
    computation with several steps on the same arrays, each step's result kept under its own
    name. Thread-safe as :func:`by_content`."""

    def __init__(self, maxsize: int = 16):
        self.maxsize = int(maxsize)
        self._d: OrderedDict = OrderedDict()
        self._lock = threading.Lock()
        _CACHES.append(self.clear)

    def slot(self, *args) -> dict:
        """The results dict of these arguments (a fresh, unkept one when they cannot be keyed)."""
        key = content_key(*args)
        if key is None:
            return {}
        with self._lock:
            d = self._d.get(key)
            if d is None:
                d = self._d[key] = {}
                while len(self._d) > self.maxsize:
                    self._d.popitem(last=False)
            else:
                self._d.move_to_end(key)
            return d

    def clear(self) -> None:
        with self._lock:
            self._d.clear()
