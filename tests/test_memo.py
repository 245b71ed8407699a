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
