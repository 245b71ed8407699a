"""Pure physics of a gyro array: the functions the simulator and the fitter share.

Nothing here knows about effects, models or files: rotations and the Earth's
rate, a fractional delay, coloured noise generators and the Allan variance of Gauss–Markov noise. Units are SI (rad, rad/s, s); the
frames and sign conventions are those of ``shared/spec/measurement-format.md``
(platform frame P, local-level frame L: z up, x at the heading from north,
turning about up).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy import fft as sfft
from scipy import signal

from gyroarray.core.constants import EARTH_RATE_RAD_S

__all__ = ["tilted_axes", "tilt_basis", "earth_rate_level", "earth_rate_platform", "fractional_delay",
           "flicker_noise", "gauss_markov_noise", "gauss_markov_avar"]


def tilted_axes(nominal: np.ndarray, tilt_rad, azimuth_rad) -> np.ndarray:
    """Nominal unit axes tilted by an angle in a documented direction.

    Parameters
    ----------
    nominal : ndarray, shape (m, 3)
        Nominal unit axes h, platform frame [-].
    tilt_rad : array_like, shape (m,)
        Angle θ between the nominal and the true axis [rad].
    azimuth_rad : array_like, shape (m,)
        Direction ψ of the tilt around h [rad].

    Returns
    -------
    ndarray, shape (m, 3)
        a = cos θ h + sin θ (cos ψ e1 + sin ψ e2).

    Notes
    -----
    e1 points from h toward +z in the vertical plane of h
    (e1 = (ẑ − (ẑ·h)h)/|ẑ × h|: ψ = 0 tilts a cone gyro toward the cone axis,
    i.e. decreases its cone angle); e2 = ẑ × h/|ẑ × h| is horizontal, toward
    increasing azimuth about +z (ψ = 90°). For h along ±z (|ẑ × h| < 1e-12):
    e1 = +x, e2 = +y.
    """
    h = np.asarray(nominal, dtype=float)
    th = np.asarray(tilt_rad, dtype=float)[:, None]
    ps = np.asarray(azimuth_rad, dtype=float)[:, None]
    e1, e2 = tilt_basis(h)
    return np.cos(th) * h + np.sin(th) * (np.cos(ps) * e1 + np.sin(ps) * e2)


def tilt_basis(nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The orthonormal directions (e1, e2) ⟂ h in which :func:`tilted_axes` tilts.

    Parameters
    ----------
    nominal : ndarray, shape (m, 3)
        Unit axes h [-].

    Returns
    -------
    e1, e2 : ndarray, shape (m, 3)
        e1 = (ẑ − (ẑ·h)h)/|ẑ × h| (toward +z), e2 = ẑ × h/|ẑ × h|
        (horizontal, increasing azimuth); for h along ±z (|ẑ × h| < 1e-12):
        e1 = +x, e2 = +y.
    """
    h = np.asarray(nominal, dtype=float)
    zhat = np.array([0.0, 0.0, 1.0])
    cross = np.cross(zhat, h)                                # ẑ × h
    s = np.linalg.norm(cross, axis=1, keepdims=True)
    polar = s[:, 0] < 1e-12
    s_safe = np.where(polar[:, None], 1.0, s)
    e1 = (zhat - h[:, 2:3] * h) / s_safe
    e2 = cross / s_safe
    e1[polar] = [1.0, 0.0, 0.0]
    e2[polar] = [0.0, 1.0, 0.0]
    return e1, e2


def earth_rate_level(latitude_rad: float, heading_rad: float) -> np.ndarray:
    """Earth rate in the local-level frame L [rad/s], shape (3,).

    ω_ie,L = Ω (cos φ cos ψ, −cos φ sin ψ, sin φ): x_L at heading ψ from
    north turning about up (counter-clockwise from above), z_L up.
    """
    c = math.cos(latitude_rad)
    return EARTH_RATE_RAD_S * np.array([c * math.cos(heading_rad),
                                        -c * math.sin(heading_rad),
                                        math.sin(latitude_rad)])


def earth_rate_platform(latitude_rad: float, heading_rad: float, n: int,
                        attitude: np.ndarray | None = None) -> np.ndarray:
    """Earth rate in the platform frame at each sample [rad/s], shape (n, 3).

    Parameters
    ----------
    latitude_rad, heading_rad : float
        Site latitude φ and heading ψ of the platform x axis at t = 0 [rad].
    n : int
        Number of samples.
    attitude : ndarray, shape (n, 3, 3), optional
        Platform -> local-level rotations R_i; None = R_i = I.

    Notes
    -----
    ω_ie,P(t_i) = R_iᵀ ω_ie,L (:func:`earth_rate_level`).
    """
    w = earth_rate_level(latitude_rad, heading_rad)
    if attitude is None:
        return np.broadcast_to(w, (n, 3)).copy()
    return w @ attitude                                      # (R_iᵀ ω_L)ᵀ = ω_Lᵀ R_i


def fractional_delay(x: np.ndarray, delay_samples) -> np.ndarray:
    """Delay each column of a uniformly sampled signal by a fractional number of samples.

    Parameters
    ----------
    x : ndarray, shape (n, m)
        Signal, one column per gyro.
    delay_samples : array_like, shape (m,)
        Delay of each column in samples (d/dt) [-], >= 0.

    Returns
    -------
    ndarray, shape (n, m)
        y_i = x(t_i − d).

    Notes
    -----
    With d = (k + f)·dt, k integer and f in [0, 1), x(t_i − d) is
    interpolated by the cubic Lagrange polynomial through the samples
    i−k−2, i−k−1, i−k, i−k+1 at s = −f (s = 0 at sample i−k):

        w₋₂ = −(s+1)s(s−1)/6,  w₋₁ = (s+2)s(s−1)/2,
        w₀ = −(s+2)(s+1)(s−1)/2,  w₁ = (s+2)(s+1)s/6.

    f = 0 is an exact shift (a delay within 1e-9 samples of a whole number is
    taken as whole). The interpolation error is
    x⁽⁴⁾(ξ)/24 · (s+2)(s+1)s(s−1)·dt⁴, and |(s+2)(s+1)s(s−1)| <= 9/16 on
    s in [−1, 0], so |error| <= (3/128)·max|x⁽⁴⁾|·dt⁴; for a sinusoid of
    amplitude A and angular frequency ω: <= (3/128)·A·(ω dt)⁴.

    Start-up and end: samples outside the record are taken as the first /
    last sample (the rate before the record is held at its first value).
    The first k+2 outputs and, when k = 0, the last one, use held values.
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    d = np.asarray(delay_samples, dtype=float)
    whole = np.round(d)
    d = np.where(np.abs(d - whole) < 1e-9, whole, d)        # 0.05 s / 0.01 s is 5, not 5 + 1e-15
    k = np.floor(d).astype(np.int64)
    s = -(d - k)                                             # position between nodes −1 and 0
    weights = (-(s + 1) * s * (s - 1) / 6, (s + 2) * s * (s - 1) / 2,
               -(s + 2) * (s + 1) * (s - 1) / 2, (s + 2) * (s + 1) * s / 6)
    y = np.empty_like(x)
    for j in range(x.shape[1]):
        # sample i - k + o (o = -2..1), held at the ends, is xp[i + o + 2]
        xp = np.concatenate([np.full(k[j] + 2, x[0, j]), x[:, j], x[-1:, j]])
        y[:, j] = sum(w[j] * xp[o + 2:o + 2 + n] for o, w in zip((-2, -1, 0, 1), weights))
    return y


def flicker_noise(n: int, dt_s: float, b_rad_s, gens: Sequence[np.random.Generator]) -> np.ndarray:
    """Flicker (1/f) rate noise whose Allan deviation plateau is 0.664·B.

    Parameters
    ----------
    n : int
        Number of samples.
    dt_s : float
        Sample step [s].
    b_rad_s : array_like, shape (m,)
        Bias instability coefficient B of each column [rad/s].
    gens : sequence of Generator, length m
        One stream per column; each gives M standard normals.

    Returns
    -------
    ndarray, shape (n, m)
        Rate noise [rad/s].

    Notes
    -----
    IEEE Std 952: bias instability is flicker noise with one-sided PSD
    S(f) = h₋₁/f, h₋₁ = B²/π, whose Allan variance is 2 ln 2·h₋₁ =
    (2 ln 2/π)·B² for every τ, i.e. σ = 0.6643·B.

    Frequency-domain shaping: unit white noise w of length
    M = next_fast_len(2n) (one-sided PSD 2·dt) is filtered by
    g(f) = √(h₋₁ / (2 dt f)) at the FFT frequencies f_j = j/(M dt), g(0) = 0,
    and the first n samples of the (circular) result are kept. The PSD is
    exactly B²/(π f) in expectation at every FFT frequency from 1/(M dt) to
    Nyquist; padding to 2n halves the lowest frequency and avoids the
    wrap-around of a length-n circle. The frequencies missing below
    1/(M dt) lower the Allan variance by about π²(τ/(2T))²/(2 ln 2): 0.1 % at
    T/40, 2 % at T/10. Measured (mean of 60 realisations of 2 h at 100 Hz):
    ADEV within 1 % of 0.664·B from τ = 8·dt to T/40; 9 % above at τ = dt,
    because the noise is sampled, not averaged over dt.

    References
    ----------
    IEEE Std 952-1997, Annex C. N. J. Kasdin, "Discrete simulation of colored
    noise and stochastic processes and 1/f^α power law noise generation",
    Proc. IEEE 83(5), 1995 (frequency-domain method, §IV).
    """
    b = np.asarray(b_rad_s, dtype=float)
    m_len = sfft.next_fast_len(2 * n, real=True)
    f = sfft.rfftfreq(m_len, dt_s)
    g = np.zeros_like(f)
    g[1:] = np.sqrt(1.0 / (2.0 * np.pi * dt_s * f[1:]))     # √(h₋₁/(2 dt f)) / B
    out = np.empty((n, len(b)))
    w = np.empty(m_len)
    for j, gen in enumerate(gens):                             # one gyro at a time: memory
        gen.standard_normal(out=w)
        out[:, j] = b[j] * sfft.irfft(sfft.rfft(w) * g, n=m_len)[:n]
    return out


def gauss_markov_noise(n: int, dt_s: float, sigma_rad_s, tau_s, z: np.ndarray) -> np.ndarray:
    """First-order Gauss–Markov rate noise, exact discretisation, stationary start.

    Parameters
    ----------
    n : int
        Number of samples.
    dt_s : float
        Sample step [s].
    sigma_rad_s : array_like, shape (m,)
        Stationary standard deviation σ [rad/s].
    tau_s : array_like, shape (m,)
        Correlation time τc [s].
    z : ndarray, shape (n, m)
        Standard normal draws.

    Returns
    -------
    ndarray, shape (n, m)

    Notes
    -----
    x₀ = σ z₀; x_k = φ x_{k−1} + σ √(1 − φ²) z_k, φ = exp(−dt/τc): the AR(1)
    recursion is the exact sampled process (autocovariance σ² e^{−|t|/τc}),
    run by ``scipy.signal.lfilter``.
    """
    sig = np.asarray(sigma_rad_s, dtype=float)
    tau = np.asarray(tau_s, dtype=float)
    out = np.empty((n, len(sig)))
    for j in range(len(sig)):
        phi = math.exp(-dt_s / tau[j])
        drive = sig[j] * math.sqrt(-math.expm1(-2.0 * dt_s / tau[j])) * z[:, j]  # σ√(1−φ²) z
        drive[0] = sig[j] * z[0, j]                                              # x₀ ~ N(0, σ²)
        out[:, j] = signal.lfilter([1.0], [1.0, -phi], drive)                    # x_k = φ x_{k−1} + w_k
    return out


def gauss_markov_avar(tau_s, sigma, tau_c, dt_s: float | None = None) -> np.ndarray:
    """Allan variance of first-order Gauss–Markov noise.

    Parameters
    ----------
    tau_s : array_like
        Averaging times τ [s] (multiples of ``dt_s`` when it is given).
    sigma : float
        Stationary standard deviation σ [any rate unit].
    tau_c : float
        Correlation time τc [s].
    dt_s : float, optional
        Sample step [s]: the exact Allan variance of the *sampled* process
        (what :func:`gauss_markov_noise` makes) averaged over m = τ/dt
        samples. None: the continuous-time closed form.

    Returns
    -------
    ndarray
        Allan variance [rate unit²].

    Notes
    -----
    Continuous time (the process averaged over τ):

        σ²(τ) = (2σ²τc/τ)·[1 − (τc/(2τ))(3 − 4e^{−τ/τc} + e^{−2τ/τc})]

    For x = τ/τc < 1e-3 the bracket is its series x²/3 − x³/4 + 7x⁴/60 (the
    closed form cancels there). The peak is ADEV ≈ 0.618·σ at τ ≈ 1.89·τc;
    for τ ≪ τc it is RRW with K² = 2σ²/τc, for τ ≫ τc ARW with N² = 2σ²τc.

    Sampled (x_k, autocovariance σ²φ^|j|, φ = e^{−dt/τc}), means of m
    samples: with u = 1 − φ and v = 1 − φ^m,

        σ²(m) = (σ²/m²)·[m + φ(2mu − 2v − v²)/u²]

    (Var of a mean minus the covariance of adjacent means). It exceeds the
    continuous form by a relative ≈ 1/(2m²) for τ ≪ τc (the sampled values
    are not averaged over dt): 50 % at m = 1, 3 % at m = 4, and a
    2-hour, 100 Hz record resolves that (measured χ² of 17 000 for 17
    degrees of freedom with the continuous form).
    """
    t = np.asarray(tau_s, dtype=float)
    if dt_s is not None:
        m = np.rint(t / dt_s)
        u = -math.expm1(-dt_s / tau_c)                       # 1 − φ
        phi = 1.0 - u
        v = -np.expm1(-m * dt_s / tau_c)                     # 1 − φ^m
        return sigma**2 / m**2 * (m + phi * (2 * m * u - 2 * v - v**2) / u**2)
    x = t / tau_c
    xs = np.maximum(x, 1e-300)
    closed = 1.0 - (-4.0 * np.expm1(-xs) + np.expm1(-2.0 * xs)) / (2.0 * xs)
    series = x**2 / 3.0 - x**3 / 4.0 + 7.0 * x**4 / 60.0
    bracket = np.where(x < 1e-3, series, closed)
    return 2.0 * sigma**2 / xs * bracket
