"""analysis.memo.by_content: the same result for the same content, a new one otherwise."""

from __future__ import annotations

import numpy as np

from gyroarray.analysis.memo import by_content


def test_results_are_reused_only_for_the_same_content():
    calls = []

    @by_content(maxsize=2)
    def f(x, scale, note=None):
        calls.append(1)
        return float(np.sum(x)) * scale

    x = np.arange(10.0)
    assert f(x, 2.0) == 90.0 and len(calls) == 1
    assert f(x.copy(), 2.0) == 90.0 and len(calls) == 1            # same bytes: from the cache
    assert f(np.asfortranarray(np.arange(10.0)), np.float64(2.0)) == 90.0 and len(calls) == 1
    y = x.copy()
    y[3] = np.nextafter(y[3], 10.0)                                   # one ulp: computed again
    f(y, 2.0)
    assert len(calls) == 2
    assert f(x, 3.0) == 135.0 and len(calls) == 3                     # another scalar
    assert f(x.astype(np.float32), 2.0) == 90.0 and len(calls) == 4   # another dtype
    assert f(x, 2.0, note=[1]) == 90.0 and len(calls) == 5            # a list: not cached
    assert f(x, 2.0, note=[1]) == 90.0 and len(calls) == 6
    f(x, 2.0)                                                          # evicted (maxsize 2): again
    assert len(calls) == 7


def test_a_frozen_arrays_digest_is_kept_and_a_writeable_one_is_hashed_again(monkeypatch):
    from gyroarray.analysis import memo

    hashed = []
    real = memo._sha256

    def counting(a):
        hashed.append(a.nbytes)
        return real(a)

    monkeypatch.setattr(memo, "_sha256", counting)
    calls = []

    @by_content(maxsize=4)
    def f(x):
        calls.append(1)
        return float(x.sum())

    w = np.arange(1000.0)                              # writeable: hashed on every call
    assert f(w) == f(w) == 499500.0 and len(hashed) == 2 and len(calls) == 1
    w[7] += 1.0                                        # mutated in place: a new digest, a new result
    assert f(w) == 499501.0 and len(hashed) == 3 and len(calls) == 2

    frozen = memo.freeze(np.arange(1000.0))
    assert not frozen.flags.writeable
    n = len(hashed)
    assert f(frozen) == f(frozen) == 499500.0 and len(hashed) == n + 1     # hashed once
    col = memo.freeze(np.arange(12.0).reshape(4, 3).copy())     # an owner of its memory
    assert f(col[:, 1]) == 22.0 and f(col[:, 1]) == 22.0 and len(hashed) == n + 2
    assert f(col[:, 2]) == 26.0 and len(hashed) == n + 3                   # another view: its own

    view = w[:10]
    view.flags.writeable = False                       # a read-only view of a writeable owner
    n = len(hashed)
    f(view)
    w[0] = 5.0                                         # the owner changes it: hashed again
    assert f(view) == float(w[:10].sum()) and len(hashed) == n + 2

    thawed = memo.freeze(np.arange(5.0))
    f(thawed)
    thawed.flags.writeable = True                      # made writeable again: no kept digest
    thawed[0] = 100.0
    assert f(thawed) == 110.0

    memo.clear_all()                                   # the kept digests go with the caches
    assert not memo._DIGESTS
    dead = memo.freeze(np.arange(3.0))
    f(dead)
    key = id(dead)
    assert key in memo._DIGESTS
    del dead                                           # freed: its digests go with it
    assert key not in memo._DIGESTS
