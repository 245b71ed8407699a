"""Events of a reference rate, and whether candidate samples are locked to them.

A gyro on a moving table responds to the motion's events: a stepper's
reversal jerks the sensor, a plateau's edge is where the table's rate (and
the encoder's error) changes fastest. A train of "isolated spikes" or a
"step" whose times sit on those events is a response to the motion (a jerk
sensitivity, or the reference's own error there), not a random glitch. This
module knows no effect: it finds the events of a reference rate and tests
how many candidate samples fall near them against chance.

Events (:func:`reference_events`), on each component of the reference:

* **reversals**: the rate changes sign, with a dead band about zero of
  ``max(2 % of the component's largest |rate|, 5 σ)`` (σ the reference's own
  sample noise, from the robust spread of its first differences), so that
  noise about a zero rate makes no reversal; the event is the middle of the
  crossing of the dead band.
* **plateau edges**: the first and last sample of each run of at least
  :data:`MIN_PLATEAU_S` where the rate's change per sample is within
  ``max(5 % of the largest, 5 σ√2)``: where a constant rate begins and ends.
* **jerk peaks**: the largest |second difference| of the rate (∝ d²ω/dt²) in
  each cluster of samples beyond ``max(10 % of the largest, 8 σ₂)`` (σ₂ its
  robust spread).

A component whose largest |rate| is within :data:`MOTION_FLOOR_RAD_S` or
10 σ of zero does not move and gives no event.

Locking (:func:`locking_test`): the share of the record within
``window_samples`` of an event is the chance that a candidate placed at
random falls near one; the number of candidates near an event against a
binomial law with that chance gives the p-value. Candidates that come in
runs (a jerk response spans a few samples) are not independent: pass the
start of each run (:func:`cluster_starts`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from gyroarray.analysis.memo import by_content
from gyroarray.core.errors import InputError

__all__ = ["reference_events", "locking_test", "cluster_starts", "near_events",
           "window_samples", "MOTION_FLOOR_RAD_S", "MIN_PLATEAU_S", "WINDOW_S"]

#: A reference component whose largest |rate| is below this does not move [rad/s] (0.01 deg/s).
MOTION_FLOOR_RAD_S = math.radians(0.01)
#: Shortest constant-rate run whose two edges are events [s].
MIN_PLATEAU_S = 0.1
#: Dead band of a reversal, as a share of the component's largest |rate| [-].
REVERSAL_SHARE = 0.02
#: Largest change per sample on a plateau, as a share of the largest change [-].
PLATEAU_SHARE = 0.05
#: Smallest jerk peak, as a share of the largest |second difference| [-].
JERK_SHARE = 0.10
#: Smallest jerk peak in robust standard deviations of the second difference [-].
JERK_Z = 8.0
#: A candidate within this of an event is near it, by default [s] (a stepper rig's reversal
#: jerks start within 0.1 s of the reversal).
WINDOW_S = 0.1
#: Normal σ from the median absolute deviation [-].
_MAD_TO_SIGMA = 1.4826


def _robust_sigma(x: np.ndarray) -> float:
    return _MAD_TO_SIGMA * float(np.median(np.abs(x - np.median(x)))) if x.size else 0.0


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(starts, ends exclusive) of the runs of True in ``mask``."""
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def _component_events(r: np.ndarray, dt_s: float) -> list[np.ndarray]:
    """Reversals, plateau edges and jerk peaks of one reference component [rad/s]."""
    n = r.size
    d1 = np.diff(r)
    sigma = _robust_sigma(d1) / math.sqrt(2.0)             # the reference's own sample noise
    span = float(np.max(np.abs(r)))
    if not span > max(MOTION_FLOOR_RAD_S, 10.0 * sigma):
        return []
    out = []
    # reversals: sign changes outside a dead band about zero
    band = max(REVERSAL_SHARE * span, 5.0 * sigma)
    s = np.where(r > band, 1, np.where(r < -band, -1, 0))
    nz = np.flatnonzero(s)
    if nz.size > 1:
        flip = np.flatnonzero(s[nz[1:]] != s[nz[:-1]])
        out.append((nz[flip] + nz[flip + 1] + 1) // 2)
    # plateau edges: runs of a nearly constant rate
    step = float(np.max(np.abs(d1)))
    if step > 0:
        flat = np.abs(d1) <= max(PLATEAU_SHARE * step, 5.0 * sigma * math.sqrt(2.0))
        a, b = _runs(flat)
        long = (b - a) >= max(int(round(MIN_PLATEAU_S / dt_s)), 2)
        edges = np.concatenate((a[long], b[long]))
        out.append(edges[(edges > 0) & (edges < n - 1)])
    # jerk peaks: clusters of a large second difference, each at its largest
    if n >= 3:
        d2 = np.zeros(n)
        d2[1:-1] = np.abs(r[2:] - 2.0 * r[1:-1] + r[:-2])
        top = float(d2.max())
        if top > 0:
            hot = d2 > max(JERK_SHARE * top, JERK_Z * _robust_sigma(d2[1:-1]))
            a, b = _runs(hot)
            out.append(np.array([lo + int(np.argmax(d2[lo:hi])) for lo, hi in zip(a, b)], dtype=np.int64))
    return out


@by_content(maxsize=4)
def reference_events(ref_rad_s, dt_s: float) -> np.ndarray:
    """Sample indices of the events of a reference rate: reversals, plateau edges, jerk peaks.

    Parameters
    ----------
    ref_rad_s : array_like, shape (n, 3) or (n,)
        The reference angular rate [rad/s], one column per component (any
        frame: each component is read on its own).
    dt_s : float
        Sample period [s].

    Returns
    -------
    ndarray of int64, shape (k,)
        The events' sample indices (0 … n − 1), sorted, each once; empty when
        the reference does not move (module docstring for the rules).

    Raises
    ------
    InputError
        A reference that is not 1-D or 2-D, holds a non-finite value, or a
        ``dt_s`` that is not a positive number.

    Notes
    -----
    Kept by content (:func:`~gyroarray.analysis.memo.by_content`): every test that reads the
    motion's events asks for those of the same reference (each candidate's, on each record the
    ranking cuts); the result is read-only.
    """
    ref = np.asarray(ref_rad_s, dtype=float)
    if ref.ndim == 1:
        ref = ref[:, None]
    if ref.ndim != 2:
        raise InputError(f"the reference rate must have shape (n,) or (n, 3), got {ref.shape}")
    if not np.all(np.isfinite(ref)):
        raise InputError("the reference rate holds a non-finite value")
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise InputError(f"dt_s must be a positive number of seconds, got {dt_s!r}")
    parts = [e for j in range(ref.shape[1]) for e in _component_events(ref[:, j], float(dt_s))]
    out = np.unique(np.concatenate(parts).astype(np.int64)) if parts else np.array([], dtype=np.int64)
    out.flags.writeable = False
    return out


def cluster_starts(index, gap_samples: int) -> np.ndarray:
    """The first sample of each run of ``index`` whose members are at most ``gap_samples`` apart.

    Parameters
    ----------
    index : array_like of int
        Candidate sample indices (any order).
    gap_samples : int
        Largest distance [samples] between two members of one run.

    Returns
    -------
    ndarray of int64
        The runs' first samples, sorted.
    """
    idx = np.unique(np.asarray(index, dtype=np.int64))
    if idx.size == 0:
        return idx
    return idx[np.concatenate(([True], np.diff(idx) > int(gap_samples)))]


def window_samples(dt_s: float, window_s: float = WINDOW_S) -> int:
    """``window_s`` [s] in samples of ``dt_s`` [s], at least 1."""
    return max(int(round(window_s / dt_s)), 1)


def near_events(event_idx, n: int, window_samples: int) -> np.ndarray:
    """Mask (n,) of the samples within ``window_samples`` of an event (either side, inclusive)."""
    ev = np.asarray(event_idx, dtype=np.int64)
    w = int(window_samples)
    if n < 0 or w < 0:
        raise InputError(f"n and window_samples must be >= 0, got {n}, {window_samples}")
    if ev.size and (ev.min() < 0 or ev.max() >= n):
        raise InputError(f"event indices must lie in 0 … {n - 1}")
    mark = np.zeros(n + 1, dtype=np.int64)
    np.add.at(mark, np.clip(ev - w, 0, n), 1)
    np.add.at(mark, np.clip(ev + w + 1, 0, n), -1)
    return np.cumsum(mark[:n]) > 0


def locking_test(event_idx, candidate_idx, n: int, window_samples: int) -> tuple[float, float, float]:
    """How many candidates fall near a reference event, against chance.

    Parameters
    ----------
    event_idx : array_like of int
        Event sample indices (:func:`reference_events`), in 0 … n − 1.
    candidate_idx : array_like of int
        Candidate sample indices (spikes, step onsets), in 0 … n − 1; each is
        taken as independent (pass :func:`cluster_starts` for runs).
    n : int
        Samples in the record.
    window_samples : int
        A candidate is near an event when at most this many samples from it.

    Returns
    -------
    fraction_near : float
        Share of the candidates near an event [-] (0 without candidates).
    fraction_expected_by_chance : float
        Share of the record's samples near an event [-]: the chance that a
        candidate placed uniformly at random is near one.
    p_value : float
        P(K ≥ k) for K ~ Binomial(candidates, chance share), k the candidates
        near an event: small when the candidates are locked to the events
        (1 without candidates or events).

    Raises
    ------
    InputError
        Indices outside 0 … n − 1 or a negative window.
    """
    cand = np.asarray(candidate_idx, dtype=np.int64)
    covered = near_events(event_idx, int(n), window_samples)
    if cand.size and (cand.min() < 0 or cand.max() >= n):
        raise InputError(f"candidate indices must lie in 0 … {n - 1}")
    chance = float(covered.mean()) if n else 0.0
    if cand.size == 0:
        return 0.0, chance, 1.0
    k = int(np.count_nonzero(covered[cand]))
    p = float(stats.binom.sf(k - 1, cand.size, chance)) if k > 0 else 1.0
    return k / cand.size, chance, min(max(p, 0.0), 1.0)
