"""Numba kernels behind :mod:`gyroarray.analysis.allan` (private).

Two kernels:

* :func:`integrate_rate` turns rate samples into phase (angle) samples,
  ``x[0] = 0``, ``x[i+1] = x[i] + (y[i] - offset)``, in one sequential pass
  (fixed summation order, hence deterministic).
* :func:`difference_sums` returns, for each averaging factor ``m``, the sum
  of squared ``order``-th differences of the phase at lag ``m``::

      order 2 (Allan):    S(m) = sum_i (x[i+2m] - 2 x[i+m] + x[i])^2
      order 3 (Hadamard):
          S(m) = sum_i (x[i+3m] - 3 x[i+2m] + 3 x[i+m] - x[i])^2

  over ``i = 0 .. n - order*m - 1``.

Design of :func:`difference_sums` (measured in ``benchmarks/bench_allan.py``):

* Cache blocking: the phase is cut into fixed blocks of ``BLOCK`` samples; for
  one block all averaging factors are summed before moving on, so for
  ``m < BLOCK`` the ``order+1`` streams ``x[i + k m]`` come from cache, and for
  octave taus the window ``x[i0 + 2m]`` of one ``m`` is the window
  ``x[i0 + m']`` of the next (``m' = 2m``).
* SIMD without fast-math: the inner loop adds into ``LANES`` independent
  partial sums (``acc[u] += d[j+u]^2``), an element-wise update LLVM's loop
  vectorizer turns into vector instructions under strict IEEE semantics (a
  single scalar accumulator cannot be vectorized without reassociation,
  and numba's SLP vectorizer is off by default).
* Parallel and deterministic: blocks are distributed over threads with
  ``prange``; each (block, m) partial sum is computed by one thread in a fixed
  order and stored, and the partials are added in block order afterwards.  The
  block partition does not depend on the number of threads, so the result is
  bit-identical for any thread count.

Nothing here validates its input; :mod:`gyroarray.analysis.allan` does.
"""

from __future__ import annotations

import numpy as np

from gyroarray.core.jit import njit, prange

#: Samples per cache block (512 KiB of float64 per window).
BLOCK = 65536
#: Independent partial sums in the inner loop (a multiple of the SIMD width).
LANES = 64


@njit(cache=True)
def integrate_rate(rate, offset, out):  # pragma: no cover - compiled
    """Cumulative sum of ``rate - offset`` into ``out`` (``out[0] = 0``).

    ``out`` must have ``rate.size + 1`` elements.  The phase is left in units
    of rate x samples (no ``tau0`` factor): the caller scales the result.
    """
    out[0] = 0.0
    s = 0.0
    for i in range(rate.size):
        s += rate[i] - offset
        out[i + 1] = s


@njit(inline="always")
def _squared_difference(w0, w1, w2, w3, j, order):  # pragma: no cover
    """Square of the ``order``-th difference at index ``j`` of the windows.

    ``w_k`` is the phase window starting ``k m`` samples after the block start.
    """
    if order == 2:
        d = w2[j] - 2.0 * w1[j] + w0[j]
    else:
        d = w3[j] - 3.0 * w2[j] + 3.0 * w1[j] - w0[j]
    return d * d


@njit(inline="always")
def _block_sum(x, i0, i1, m, order):  # pragma: no cover - compiled
    """Sum of squared differences for start indices ``i0 <= i < i1``."""
    length = i1 - i0
    # Windows x[i + k m]; slicing clamps at the end of x, and w3 is only read
    # for order 3 (where it is complete).
    w0 = x[i0:i1]
    w1 = x[i0 + m:i1 + m]
    w2 = x[i0 + 2 * m:i1 + 2 * m]
    w3 = x[i0 + 3 * m:i1 + 3 * m]
    acc = np.zeros(LANES)
    n_full = length - length % LANES
    for j in range(0, n_full, LANES):
        for u in range(LANES):
            acc[u] += _squared_difference(w0, w1, w2, w3, j + u, order)
    tail = 0.0
    for j in range(n_full, length):
        tail += _squared_difference(w0, w1, w2, w3, j, order)
    s = 0.0
    for u in range(LANES):
        s += acc[u]
    return s + tail


@njit(cache=True, parallel=True)
def difference_sums(x, ms, order, block):  # pragma: no cover - compiled
    """Sums of squared ``order``-th differences of ``x`` at lags ``ms``.

    Parameters
    ----------
    x : (n,) float64 array
        Phase samples.
    ms : (k,) int64 array
        Averaging factors, each with ``n - order*m >= 1``.
    order : int
        2 (Allan) or 3 (Hadamard).
    block : int
        Samples per cache block, normally :data:`BLOCK`.  Passed at run time
        on purpose: with a compile-time constant here LLVM generated code
        about 5x slower (measured, numba 0.68 / LLVM 22).

    Returns
    -------
    (k,) float64 array
        ``S(m)`` for each ``m``; the number of summands is ``n - order*m``.
    """
    n = x.size
    n_k = ms.size
    n_blocks = (n + block - 1) // block
    partial = np.zeros((n_blocks, n_k))
    for b in prange(n_blocks):
        i0 = b * block
        for k in range(n_k):
            i1 = min(i0 + block, n - order * ms[k])
            if i1 > i0:
                partial[b, k] = _block_sum(x, i0, i1, ms[k], order)
    out = np.zeros(n_k)
    for k in range(n_k):
        s = 0.0
        for b in range(n_blocks):
            s += partial[b, k]
        out[k] = s
    return out
