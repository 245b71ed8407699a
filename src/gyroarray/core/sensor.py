"""The gyro as a physical device: its own low-pass filter and its g-sensitivity.

Pure functions (SI inside: rad/s, m/s², s, Hz for frequencies) for the two
sensor-response effects of ``shared/spec/effects.md``, and the rigid-body
kinematics that gives the specific force at each gyro. The effects
``bandwidth`` and ``g_sensitivity`` (:mod:`gyroarray.effects`) wrap them; the
fit side (:mod:`gyroarray.analysis.psd_fit`) reads the same definitions, so
they sit at the bottom of the package (``gyroarray.core.sensor`` re-exports
them).

``bandwidth``
    The gyro's internal low-pass filter, acting on everything the sensing
    element produces, after ``misalignment``, ``scale_factor``,
    ``g_sensitivity`` and the noise terms, before ``quantization`` and
    ``saturation``. Order 1: H(s) = 1/(1 + s/ωc); order 2 (Butterworth):
    H(s) = 1/(1 + √2 s/ωc + s²/ωc²); ωc = 2π·cutoff. Causal.
``g_sensitivity``
    bias_k = (k · f_k)/g0 [deg/s] with k = ``deg_s_per_g`` (a 3-vector,
    platform frame) and f_k the specific force at gyro k, platform frame:
    f_k = f_0 + α × r_k + ω × (ω × r_k). In SI the coefficient is
    k·(π/180)/g0 [(rad/s)/(m/s²)] (:func:`gyroarray.core.units.deg_s_per_g_to_rad_s_per_m_s2`)
    and the bias its dot product with f_k [rad/s].

Discretisation of the filter
----------------------------
The continuous H(s) is mapped to a digital filter at the sample rate
fs = 1/dt by the bilinear (Tustin) transform with pre-warping at the
cut-off, ``scipy.signal.butter(order, cutoff_hz, fs=fs, output="sos")``:

    s = ωc/tan(π fc dt) · (1 − z⁻¹)/(1 + z⁻¹)

so the digital response at frequency f equals the continuous one at a warped
frequency, H_d(e^{j2πf dt}) = H(j ωc tan(π f dt)/tan(π fc dt)): exact at 0
and at the cut-off (−3 dB there), a frequency error that grows toward
Nyquist (+3.3 % at f = 0.1 fs for a cut-off well below, +16 % at 0.2 fs),
and a magnitude error of at most ``order``·|ln(ω'/ω)| in ln|H| and in phase
(rad), since |d ln|H| / d ln ω| and |d arg H / d ln ω| are at most the order
for these two filters (tests/test_sensor.py measures it). The cut-off must
lie below the Nyquist frequency fs/2.

The filter runs as second-order sections (``scipy.signal.sosfilt``) whose
state starts at the steady state of the first input sample
(``sosfilt_zi`` × x₀): a signal that has been constant since before the
record (a turn-on bias, a table at rest) passes with no start-up transient.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from gyroarray.core.errors import InputError
from gyroarray.core.constants import G0_M_S2

__all__ = ["BANDWIDTH_ORDERS", "bandwidth_sos", "bandwidth_filter", "quantize_rate", "output_lattice_step", "bandwidth_response",
           "bandwidth_warped_frequency", "g_sensitivity_bias", "rigid_body_specific_force",
           "gravity_specific_force"]

#: Orders of the ``bandwidth`` filter the spec defines.
BANDWIDTH_ORDERS = (1, 2)


def _check_filter(cutoff_hz: float, order: int, dt_s: float) -> tuple[float, int, float]:
    fc, dt = float(cutoff_hz), float(dt_s)
    if order not in BANDWIDTH_ORDERS:
        raise InputError(f"bandwidth order must be 1 or 2 (Butterworth), got {order!r}",
                         column="order")
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"dt_s must be > 0, got {dt_s!r}")
    nyquist = 0.5 / dt
    if not (math.isfinite(fc) and 0 < fc < nyquist):
        raise InputError(f"cutoff_hz = {fc:g} Hz must be in (0, {nyquist:g}) Hz, below the "
                         f"Nyquist frequency of this run (dt = {dt:g} s)", column="cutoff_hz")
    return fc, int(order), dt


def bandwidth_sos(cutoff_hz: float, order: int, dt_s: float) -> np.ndarray:
    """The digital ``bandwidth`` filter as second-order sections.

    Parameters
    ----------
    cutoff_hz : float
        −3 dB frequency fc [Hz], 0 < fc < 1/(2 dt).
    order : {1, 2}
        1: H(s) = 1/(1 + s/ωc); 2: Butterworth.
    dt_s : float
        Sample step [s].

    Returns
    -------
    ndarray, shape (1, 6)
        ``scipy.signal`` second-order sections (bilinear with pre-warping at fc).
    """
    fc, n, dt = _check_filter(cutoff_hz, order, dt_s)
    return signal.butter(n, fc, btype="low", fs=1.0 / dt, output="sos")


def bandwidth_filter(x, dt_s: float, cutoff_hz, order) -> np.ndarray:
    """Causal low-pass of each column, started at the steady state of its first sample.

    Parameters
    ----------
    x : array_like, shape (n,) or (n, m)
        Signal, one column per gyro [any unit].
    dt_s : float
        Sample step [s].
    cutoff_hz : float or array_like, shape (m,)
        −3 dB frequency of each column [Hz].
    order : int or array_like, shape (m,)
        Filter order of each column (1 or 2).

    Returns
    -------
    ndarray, same shape as ``x``
        y = H_d(z) x, column by column.

    Notes
    -----
    # y = sosfilt(sos, x, zi = sosfilt_zi(sos)·x₀): the state is that of x₀
    # held forever, so a constant input comes out unchanged from sample 0.
    """
    a = np.asarray(x, dtype=float)
    y2 = a.reshape(a.shape[0], -1)
    m = y2.shape[1]
    fc = np.broadcast_to(np.asarray(cutoff_hz, dtype=float), (m,))
    orders = np.broadcast_to(np.asarray(order), (m,))
    out = np.empty_like(y2)
    for j in range(m):
        o = float(orders[j])
        if o != round(o):
            raise InputError(f"bandwidth order must be 1 or 2 (Butterworth), got {o:g}",
                             column="order")
        sos = bandwidth_sos(fc[j], int(round(o)), dt_s)
        zi = signal.sosfilt_zi(sos) * y2[0, j]
        out[:, j], _ = signal.sosfilt(sos, y2[:, j], zi=zi)
    return out.reshape(a.shape)


def quantize_rate(x, dt_s: float, step_rad) -> np.ndarray:
    """The spec's ``quantization``: the increments of a rounded integrated angle.

    Parameters
    ----------
    x : array_like, shape (n,) or (n, m)
        What the gyro produces before its counter, one column per gyro [rad/s].
    dt_s : float
        Sample step dt [s].
    step_rad : float or array_like, shape (m,)
        Angle step Δ = √12·Q of each column [rad]; a column of step 0 passes unchanged.

    Returns
    -------
    ndarray, same shape as ``x``
        y_k = (round(θ_k/Δ) − round(θ_{k−1}/Δ))·Δ/dt [rad/s], θ_k = Σ_{j<=k} x_j·dt,
        θ_{−1} = 0: every value an integer multiple of Δ/dt.

    Notes
    -----
    # θ is a float64 cumulative sum: its rounding error grows like √n·ulp(θ), far below Δ
    # (1e6 samples at 300 deg/s and 100 Hz: θ = 5.2e4 rad, ulp 7e-12 rad, the sum off the 80-bit
    # one by 1.7e-9 rad at most, 3e-5 of a 0.0035 deg step; 9 of the 1e6 counts differ by one, a
    # boundary crossed a sample early or late, as an input change of 2e-9 rad would do:
    # tests/test_spec_quantization.py). The counts round(θ/Δ) are integers below 2⁵³, so their
    # differences are exact.
    """
    a = np.asarray(x, dtype=float)
    x2 = a.reshape(a.shape[0], -1)
    step = np.broadcast_to(np.asarray(step_rad, dtype=float), (x2.shape[1],))
    out = np.array(x2, copy=True)
    dt = float(dt_s)
    for j in np.flatnonzero(step > 0):
        counts = np.round(np.cumsum(x2[:, j] * dt) / step[j])
        out[:, j] = np.diff(counts, prepend=0.0) * (step[j] / dt)
    return out.reshape(a.shape)


def output_lattice_step(y, max_levels: int = 4096) -> float:
    """The step c of the value grid a record's output lies on, or NaN when it lies on none.

    Parameters
    ----------
    y : array_like, shape (n,)
        One gyro's output [any unit].
    max_levels : int
        Most distinct grid values (spanned by the record) for the grid to count as coarse [-].

    Returns
    -------
    float
        c > 0 with every finite value an integer multiple of c (relative 1e-6 of c), and the
        values spanning at most ``max_levels`` steps; NaN otherwise (a continuous output, a grid
        finer than that, or fewer than two distinct values).

    Notes
    -----
    # A gcd of the distinct values: start from the smallest non-zero distance between them and
    # divide it while the values do not fit (a grid whose smallest seen distance is 2c or 3c),
    # then refine c by least squares over the values' integer indices.
    """
    v = np.asarray(y, dtype=float)
    v = np.unique(v[np.isfinite(v)])
    if v.size < 2:
        return math.nan
    span = float(v[-1] - v[0])
    d = np.diff(v)
    c0 = float(d.min())
    if not c0 > 0 or span / c0 > max_levels:
        return math.nan
    for div in range(1, 13):
        c = c0 / div
        k = np.round(v / c)
        if np.all(np.abs(v / c - k) < 1e-6):
            c = float(v @ k) / float(k @ k)           # least squares on the indices
            return c if np.all(np.abs(v / c - k) < 1e-6) else math.nan
    return math.nan


def bandwidth_response(freq_hz, cutoff_hz: float, order: int) -> np.ndarray:
    """The continuous frequency response H(j2πf) of the spec's filter.

    Parameters
    ----------
    freq_hz : array_like
        Frequencies f [Hz].
    cutoff_hz : float
        fc [Hz].
    order : {1, 2}

    Returns
    -------
    ndarray of complex
        H(j2πf) [-]: 1/(1 + jx) (order 1), 1/(1 + √2 jx − x²) (order 2), x = f/fc.
    """
    if order not in BANDWIDTH_ORDERS:
        raise InputError(f"bandwidth order must be 1 or 2 (Butterworth), got {order!r}",
                         column="order")
    s = 1j * np.asarray(freq_hz, dtype=float) / float(cutoff_hz)        # s/ωc
    if order == 1:
        return 1.0 / (1.0 + s)
    return 1.0 / (1.0 + math.sqrt(2.0) * s + s * s)


def bandwidth_warped_frequency(freq_hz, cutoff_hz: float, dt_s: float) -> np.ndarray:
    """The continuous frequency whose response the digital filter gives at ``freq_hz``.

    f' = fc · tan(π f dt)/tan(π fc dt) [Hz] (bilinear transform, pre-warped at fc):
    ``H_d(e^{j2πf dt}) = bandwidth_response(f', fc, order)`` exactly.
    """
    f = np.asarray(freq_hz, dtype=float)
    return float(cutoff_hz) * np.tan(np.pi * f * dt_s) / math.tan(math.pi * cutoff_hz * dt_s)


def g_sensitivity_bias(coeff_rad_s_per_m_s2, specific_force_m_s2) -> np.ndarray:
    """Rate bias of each gyro from the specific force it sees.

    Parameters
    ----------
    coeff_rad_s_per_m_s2 : array_like, shape (m, 3)
        g-sensitivity of each gyro, platform frame [(rad/s)/(m/s²)]
        (``deg_s_per_g``·(π/180)/g0).
    specific_force_m_s2 : array_like, shape (n, m, 3)
        Specific force f_k at each gyro, platform frame [m/s²].

    Returns
    -------
    ndarray, shape (n, m)
        bias_k = coeff_k · f_k [rad/s].
    """
    c = np.asarray(coeff_rad_s_per_m_s2, dtype=float)
    f = np.asarray(specific_force_m_s2, dtype=float)
    return np.einsum("nkj,kj->nk", f, c)


def rigid_body_specific_force(f0_m_s2, omega_rad_s, alpha_rad_s2, positions_m) -> np.ndarray:
    """f_k = f_0 + α × r_k + ω × (ω × r_k) for every sample and point.

    Parameters
    ----------
    f0_m_s2 : array_like, shape (n, 3)
        Specific force at the origin [m/s²].
    omega_rad_s, alpha_rad_s2 : array_like, shape (n, 3)
        Angular rate [rad/s] and acceleration [rad/s²] of the body, in the
        frame of ``f0`` (the platform frame: α = dω_body/dt).
    positions_m : array_like, shape (N, 3)
        Points r_k [m].

    Returns
    -------
    ndarray, shape (n, N, 3)
        [m/s²].
    """
    f0 = np.asarray(f0_m_s2, dtype=float)
    w = np.asarray(omega_rad_s, dtype=float)
    a = np.asarray(alpha_rad_s2, dtype=float)
    r = np.asarray(positions_m, dtype=float).reshape(-1, 3)
    out = np.empty((f0.shape[0], r.shape[0], 3))
    for k, rk in enumerate(r):               # one gyro at a time: memory (n, 3)
        if not rk.any():
            out[:, k] = f0
            continue
        out[:, k] = f0 + np.cross(a, rk) + np.cross(w, np.cross(w, rk))
    return out


def gravity_specific_force(attitude, n: int) -> np.ndarray:
    """Specific force at the platform origin from the attitude alone [m/s²], shape (n, 3).

    f_0 = Rᵀ [0, 0, g0] (the origin of the table does not move); ``attitude``
    None is the level platform, f_0 = [0, 0, g0].

    Parameters
    ----------
    attitude : ndarray, shape (n, 3, 3), or None
        Platform -> local-level rotation matrices R [-].
    n : int
        Number of samples.
    """
    up = np.array([0.0, 0.0, G0_M_S2])
    if attitude is None:
        return np.broadcast_to(up, (n, 3)).copy()
    return np.asarray(attitude, dtype=float)[:, 2, :] * G0_M_S2   # (Rᵀ e_z)ᵢ = R_zi
