"""The four gyro faults of ``shared/spec/effects.md``, as pure functions.

A fault starts at ``start_s`` on one gyro and lasts to the end of the record.
What the gyro outputs from ``start_s`` on (spec, "Faults"):

=============== ============================================================
``fault_step``  its normal output + ``size_deg_s``
``fault_drift`` its normal output + ``rate_deg_s2``·(t − ``start_s``)
``fault_stuck`` the last value it gave before ``start_s``, forever
``fault_noise`` its normal output with the white (ARW) part × ``ratio``
=============== ============================================================

Chain position (``src/gyroarray/sim/effects.py``): ``fault_step``, ``fault_drift`` and
``fault_stuck`` act on the gyro's final output, after ``quantization`` and
``saturation`` ("its normal output" is what the gyro would have given);
``fault_noise`` multiplies the gyro's ARW draw (after the cross-gyro
correlation mixing, like ``burst``) by ``ratio`` from ``start_s`` on.

"From ``start_s`` on" means the samples with ``time_s >= start_s``. Every
function here works on the columns it is given (one per faulty gyro) and
returns new arrays; SI units (rad/s, rad/s², s).
"""

from __future__ import annotations

import numpy as np

from gyroarray.core.errors import InputError
from gyroarray.core.units import RAD_PER_DEG

__all__ = ["deg_s2_to_rad_s2", "rad_s2_to_deg_s2", "fault_mask", "step", "drift", "stuck",
           "noise_gain"]


def deg_s2_to_rad_s2(x):
    """Rate change [deg/s²] -> [rad/s²] (missing from :mod:`gyroarray.core.units`)."""
    return x * RAD_PER_DEG


def rad_s2_to_deg_s2(x):
    """Rate change [rad/s²] -> [deg/s²]."""
    return x / RAD_PER_DEG


def fault_mask(time_s: np.ndarray, start_s) -> np.ndarray:
    """Where each fault is active: ``time_s >= start_s``.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Sample times [s].
    start_s : array_like, shape (m,)
        Fault start of each column [s].

    Returns
    -------
    ndarray of bool, shape (n, m)
    """
    return np.asarray(time_s, dtype=float)[:, None] >= np.asarray(start_s, dtype=float)[None, :]


def step(x: np.ndarray, time_s: np.ndarray, start_s, size_rad_s) -> np.ndarray:
    """A step on the output: y = x + size from ``start_s`` on.

    Parameters
    ----------
    x : ndarray, shape (n, m)
        The gyros' normal outputs [rad/s].
    time_s : ndarray, shape (n,)
        Sample times [s].
    start_s, size_rad_s : array_like, shape (m,)
        Start [s] and size [rad/s] of each column's step.

    Returns
    -------
    ndarray, shape (n, m)
    """
    return x + fault_mask(time_s, start_s) * np.asarray(size_rad_s, dtype=float)


def drift(x: np.ndarray, time_s: np.ndarray, start_s, rate_rad_s2) -> np.ndarray:
    """A ramp on the output: y = x + rate·(t − start) from ``start_s`` on.

    Parameters
    ----------
    x : ndarray, shape (n, m)
        The gyros' normal outputs [rad/s].
    time_s : ndarray, shape (n,)
        Sample times [s].
    start_s : array_like, shape (m,)
        Start of each column's drift [s].
    rate_rad_s2 : array_like, shape (m,)
        Drift rate [rad/s²].

    Returns
    -------
    ndarray, shape (n, m)
    """
    t = np.asarray(time_s, dtype=float)[:, None]
    start = np.asarray(start_s, dtype=float)
    return x + np.where(t >= start, (t - start) * np.asarray(rate_rad_s2, dtype=float), 0.0)


def stuck(x: np.ndarray, time_s: np.ndarray, start_s) -> np.ndarray:
    """A stuck output: from ``start_s`` on, the last value given before ``start_s``.

    Parameters
    ----------
    x : ndarray, shape (n, m)
        The gyros' normal outputs [rad/s].
    time_s : ndarray, shape (n,)
        Sample times [s].
    start_s : array_like, shape (m,)
        When each column sticks [s].

    Returns
    -------
    ndarray, shape (n, m)
        ``y[i] = x[i0 − 1]`` for every ``i >= i0``, i0 the first sample with
        ``time_s >= start_s``; unchanged when the fault starts after the record.

    Raises
    ------
    InputError
        ``start_s`` at or before the first sample: the gyro gave no value
        before it, so there is nothing to stick at.
    """
    t = np.asarray(time_s, dtype=float)
    y = np.array(x, dtype=float, copy=True)
    for j, s in enumerate(np.asarray(start_s, dtype=float)):
        i0 = int(np.searchsorted(t, s, side="left"))         # first sample with t >= start
        if i0 == 0:
            raise InputError(f"fault_stuck: start_s = {s:g} s is not after the first sample "
                             f"({t[0]:g} s): the gyro gave no value before it to stick at",
                             column="start_s")
        y[i0:, j] = y[i0 - 1, j]
    return y


def noise_gain(time_s: np.ndarray, start_s, ratio) -> np.ndarray:
    """Factor on each column's ARW draw: 1 before ``start_s``, ``ratio`` from it on.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Sample times [s].
    start_s, ratio : array_like, shape (m,)
        Start [s] and amplitude ratio [-] of each column's noise fault.

    Returns
    -------
    ndarray, shape (n, m)
    """
    return np.where(fault_mask(time_s, start_s), np.asarray(ratio, dtype=float), 1.0)
