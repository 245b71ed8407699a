"""The one-column whitening kernels of :class:`RWWhitener` equal the general path bit for bit.

``whiten(x)`` of one column runs one fused pass (:func:`_rw_whiten1`) and ``whiten_at(x, r, q)``
builds the pivots of other variances on the same samples from the kept links (:func:`_rw_pivots`); the
diagnosis's ML scan of q (chain/compare.py ``_ml_q``) relies on both giving the bits of a
whitener built from scratch. Exact equality is the claim (the same floating-point operations in
the same order), so the tolerance is zero.
"""

from __future__ import annotations

import numpy as np
import pytest

from gyroarray.analysis.gls import RWWhitener, _rw_forward


def _samples(kind: str, n: int, rng: np.random.Generator):
    if kind == "dense":
        return None, None
    use = rng.random(n) > 0.05                      # 5 % of samples dropped
    if kind == "gaps":
        return use, None
    return use, np.array([n // 3, 2 * n // 3])      # gaps and two stitched parts


@pytest.mark.parametrize("kind", ["dense", "gaps", "breaks"])
def test_one_column_whiten_equals_general_path(kind):
    rng = np.random.default_rng(11)
    n = 5000
    use, breaks = _samples(kind, n, rng)
    x = np.cumsum(rng.standard_normal(n)) * 1e-4 + rng.standard_normal(n) * 1e-3
    w = RWWhitener(n, 1e-6, 3e-9, use, breaks)
    b = w.diff(x)                                   # the general path: diff, forward, scale
    _rw_forward(w.il, w.cv, b)
    b *= 1.0 / np.sqrt(w.s)
    z = w.whiten(x)
    assert z.shape == (w.m,)
    assert np.array_equal(z, b[:, 0])


@pytest.mark.parametrize("kind", ["dense", "gaps", "breaks"])
@pytest.mark.parametrize("q", [0.0, 1e-12, 3e-9, 2e-6])
def test_whiten_at_equals_a_fresh_whitener(kind, q):
    rng = np.random.default_rng(12)
    n = 4000
    use, breaks = _samples(kind, n, rng)
    x = rng.standard_normal(n) * 1e-3
    r = 1e-6
    base = RWWhitener(n, r, r, use, breaks)
    z, logdet = base.whiten_at(x, r, q)
    fresh = RWWhitener(n, r, q, use, breaks)
    assert np.array_equal(z, fresh.whiten(x))
    assert logdet == fresh.logdet


def test_whiten_at_refuses_bad_variances_and_shapes():
    w = RWWhitener(100, 1e-6, 1e-9)
    with pytest.raises(ValueError, match="r and q"):
        w.whiten_at(np.zeros(100), -1.0, 1e-9)
    with pytest.raises(ValueError, match="r and q"):
        w.whiten_at(np.zeros(100), 0.0, 0.0)
    with pytest.raises(ValueError, match="shape"):
        w.whiten_at(np.zeros(99), 1e-6, 1e-9)
