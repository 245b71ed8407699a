"""The phase track of a spectral line: is its phase a straight line (a fixed sinusoid), or does it
wander (a narrowband process, a line of finite width)?

Convention (phase diffusion). A line ``A sin(2π f₀ t + φ(t))`` whose phase is a Wiener process,
``var[φ(t + T) − φ(t)] = D·T``, has the autocovariance ``(A²/2) cos(2π f₀ τ) exp(−D|τ|/2)``,
whose spectrum is a Lorentzian of half-width at half-maximum ``γ = D/(4π)`` [Hz] about f₀. So

    var Δφ over T = 4π·γ·T = 2π · 2γ · T        (γ = ``linewidth_hz``)

and a line drifting by ``c`` cycles (rms) over ``T`` has ``γ = π c²/T``. The phase of a segment,
read by a least-squares sinusoid at f₀, is the phase averaged over the segment; adjacent
segment averages of a Wiener process of length T differ by ``var = (2/3)·D·T``, which the
linewidth estimate uses.

Units: SI (s, Hz, rad, the series in any unit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal, stats

__all__ = ["PhaseTrack", "phase_track", "tracked_line", "diffusion_of_linewidth", "N_SEGMENTS"]

#: Segments the phase is read on (16: a drift of a cycle over the record is ~0.4 rad a segment,
#: safely unwrapped, and the linewidth's estimate has 14 degrees of freedom).
N_SEGMENTS = 16


def diffusion_of_linewidth(linewidth_hz: float) -> float:
    """Phase diffusion D [rad²/s] of a Lorentzian line of half-width ``linewidth_hz`` [Hz]: 4πγ."""
    return 4.0 * math.pi * float(linewidth_hz)


@dataclass(frozen=True)
class PhaseTrack:
    """The phase of a line read on segments, and what it says (module docstring).

    Attributes
    ----------
    t_s, phase_rad, sigma_rad, amp : ndarray (K,)
        Segment centres [s], unwrapped phases and their 1σ [rad], amplitudes [series unit].
    chi2, dof : float, int
        χ² of the phases about their weighted straight line (a fixed frequency), K − 2 dof.
    z : float
        Its significance (N(0, 1) for a fixed line).
    linewidth_hz, linewidth_sigma_hz : float
        γ [Hz] from the variance of the phase increments (noise taken out), and its 1σ.
    linewidth_ci_hz : tuple
        95 % interval of γ [Hz] (χ² of the increments' variance).
    freq_hz : float
        The line's mean frequency [Hz] (f₀ plus the mean phase increment's).
    amp_rms : float
        The amplitude of the process (√2 × its rms) [series unit]: mean A_k² (read again on
        segments short enough that the phase moves by ~0.2 rad rms in one, D·T <= 0.04, at
        least 10 periods) less the noise's bias, divided by the coherence a segment keeps, E|mean_T e^{iφ}|² = 2(x − 1 + e^{−x})/x²
        with x = D·T/2 (a wandering phase averages part of the line out of each segment).
    """

    t_s: np.ndarray
    phase_rad: np.ndarray
    sigma_rad: np.ndarray
    amp: np.ndarray
    chi2: float
    dof: int
    z: float
    linewidth_hz: float
    linewidth_sigma_hz: float
    linewidth_ci_hz: tuple
    freq_hz: float
    amp_rms: float


def phase_track(e, time_s, freq_hz: float, n_seg: int = N_SEGMENTS) -> PhaseTrack:
    """Read the phase of the line at ``freq_hz`` on ``n_seg`` equal segments of ``e``.

    Parameters
    ----------
    e : array_like, shape (n,)
        The series (a residual) [any unit], uniform in time.
    time_s : array_like, shape (n,)
        Its times [s].
    freq_hz : float
        The line's frequency [Hz] (a fixed-line fit's).
    n_seg : int
        Segments (at least 4).

    Returns
    -------
    PhaseTrack

    Notes
    -----
    Each segment: least squares of e on (1, sin 2πf₀t, cos 2πf₀t) gives (a_s, a_c), the phase
    φ_k = atan2(a_c, a_s) and amplitude A_k; σ_φk = σ_c/A_k, σ_c² the variance of one coefficient
    read from the segment residual's projections 3–6 Fourier bins either side of f₀ (the noise's
    level at the line, coloured or not).
    The phases are unwrapped along k. χ² of φ_k about their weighted straight line (α + βt_k,
    a fixed line whose frequency may be off) on K − 2 dof is the test of a fixed line. The
    increments d_k = φ_{k+1} − φ_k less their mean have variance (2/3)·4πγ·T + σ_φk² + σ_φk+1²
    (T the segment length), hence γ̂ with the noise taken out, its 95 % interval from χ²(K − 2)
    and σ_γ = (s²/((2/3)4πT))·√(2/(K − 2)).
    """
    e = np.asarray(e, dtype=float)
    t = np.asarray(time_s, dtype=float)
    k_seg = int(max(4, n_seg))
    edges = np.linspace(0, e.size, k_seg + 1).astype(int)
    ph, sg, amp, tc, var_w, n_k = [], [], [], [], [], []
    for a, b in zip(edges[:-1], edges[1:]):
        ts, es = t[a:b], e[a:b]
        arg = 2.0 * np.pi * freq_hz * (ts - t[0])
        X = np.column_stack([np.ones(ts.size), np.sin(arg), np.cos(arg)])
        beta, *_ = np.linalg.lstsq(X, es, rcond=None)
        res = es - X @ beta
        w2 = float(np.var(np.diff(res))) / 2.0
        a_k = math.hypot(beta[1], beta[2])
        ph.append(math.atan2(beta[2], beta[1]))
        amp.append(a_k)
        sg.append(math.sqrt(max(_neighbour_variance(res, ts, freq_hz), 1e-300)) / max(a_k, 1e-300))
        tc.append(float(ts.mean()))
        var_w.append(w2)
        n_k.append(ts.size)
    phase = np.unwrap(np.array(ph))
    sigma = np.array(sg)
    tcs = np.array(tc)
    amps = np.array(amp)
    w = 1.0 / sigma ** 2
    X = np.column_stack([np.ones(k_seg), tcs - tcs.mean()])
    coef = np.linalg.solve(X.T @ (X * w[:, None]), X.T @ (w * phase))
    chi2 = float(np.sum(w * (phase - X @ coef) ** 2))
    dof = k_seg - 2
    z = float(-stats.norm.ppf(max(stats.chi2.sf(chi2, dof), 1e-300)))
    seg_s = float(np.mean(np.diff(tcs)))
    d = np.diff(phase)
    s2 = float(np.var(d, ddof=1)) if d.size > 1 else 0.0
    noise = float(np.mean(sigma[:-1] ** 2 + sigma[1:] ** 2))
    scale = (2.0 / 3.0) * 4.0 * math.pi * seg_s
    gamma = max(s2 - noise, 0.0) / scale
    dof_d = max(d.size - 1, 1)
    ci = (max(s2 * dof_d / stats.chi2.ppf(0.975, dof_d) - noise, 0.0) / scale,
          max(s2 * dof_d / stats.chi2.ppf(0.025, dof_d) - noise, 0.0) / scale)
    g_sig = (s2 / scale) * math.sqrt(2.0 / dof_d)
    freq = float(freq_hz + np.mean(d) / (2.0 * math.pi * seg_s))
    bias = float(np.mean([2.0 * v / (m / 2.0) for v, m in zip(var_w, n_k)]))
    # the amplitude on shorter segments, over which the phase moves little (x = D·T/2 <= 0.02)
    diff = diffusion_of_linewidth(gamma)
    short = min(seg_s, max(0.04 / diff if diff > 0 else seg_s, 10.0 / max(freq_hz, 1e-12)))
    k_amp = int(min(max(k_seg, round(e.size * (t[1] - t[0]) / short)), e.size // 8)) if e.size > 1 else k_seg
    if k_amp > k_seg:
        mean_a2, bias_a2, t_amp = _short_amplitude(e, t, freq_hz, k_amp)
    else:
        mean_a2, bias_a2, t_amp = float(np.mean(amps ** 2)), bias, seg_s
    # a segment's fit sees the mean of A·e^{iφ} over it: E|mean|² = A²·c(x), x = D·T/2
    x = 0.5 * diff * t_amp
    coherence = 2.0 * (x - 1.0 + math.exp(-x)) / (x * x) if x > 1e-6 else 1.0 - x / 3.0
    amp_rms = math.sqrt(max(mean_a2 - bias_a2, 0.0) / coherence)
    return PhaseTrack(tcs, phase, sigma, amps, chi2, dof, z, gamma, g_sig, ci, freq, amp_rms)


#: Offsets of the neighbouring frequencies that read the noise at the line [1/segment length].
_NEIGHBOURS = np.array([-6, -5, -4, -3, 3, 4, 5, 6])


def _neighbour_variance(res: np.ndarray, ts: np.ndarray, freq_hz: float) -> float:
    """The variance of one coefficient (a_s or a_c) of a sinusoid fitted at ``freq_hz`` to the noise of
    ``res``: the mean |c|²/2 of the projections c = (2/n) Σ res·e^{−i2πft} at the frequencies 3–6
    Fourier bins of the segment on either side (the noise's own level at the line, coloured or not,
    where the first differences would read a white level)."""
    # the segment demodulated at f₀: its Fourier bins j are the frequencies f₀ + j/span
    z = res * np.exp(-2j * np.pi * freq_hz * (ts - ts[0]))
    c = (2.0 / ts.size) * np.fft.fft(z)[_NEIGHBOURS % ts.size]
    return float(np.mean(np.abs(c) ** 2)) / 2.0


def tracked_line(e, time_s, freq_hz: float, width_s: float) -> np.ndarray:
    """The line at ``freq_hz`` as a complex demodulate follows it: e·e^{−i2πf₀t} smoothed by a Hann
    window of ``width_s`` [s] (a low-pass of about 2/width_s Hz about f₀, which rejects the image
    at 2f₀), brought back up: 2·Re(z̄(t)·e^{i2πf₀t}) [unit of e], shape (n,). What a narrowband
    line contributes to the series, its phase and amplitude followed."""
    e = np.asarray(e, dtype=float)
    t = np.asarray(time_s, dtype=float)
    if e.size < 3:
        return np.zeros_like(e)
    dt = float(t[1] - t[0])
    m = int(min(max(3, round(width_s / dt)), e.size))
    win = np.hanning(m + 2)[1:-1]
    rot = np.exp(-2j * np.pi * freq_hz * (t - t[0]))
    z = (e - e.mean()) * rot
    num = signal.fftconvolve(z, win, mode="same")
    den = signal.fftconvolve(np.ones(e.size), win, mode="same")
    return 2.0 * np.real(num / den * np.conj(rot))


def _short_amplitude(e: np.ndarray, t: np.ndarray, freq_hz: float, k: int) -> tuple:
    """(mean A_k², the noise's bias of it, block length [s]) on ``k`` equal blocks of ``e`` (the
    remainder left out): least squares of each block on (1, sin, cos), batched."""
    m = e.size // k
    eb = e[:k * m].reshape(k, m)
    arg = (2.0 * np.pi * freq_hz * (t[:k * m] - t[0])).reshape(k, m)
    X = np.stack([np.ones_like(arg), np.sin(arg), np.cos(arg)], axis=2)        # (k, m, 3)
    gram = np.einsum("kmi,kmj->kij", X, X)
    beta = np.linalg.solve(gram, np.einsum("kmi,km->ki", X, eb)[..., None])[..., 0]
    res = eb - np.einsum("kmi,ki->km", X, beta)
    w2 = np.var(np.diff(res, axis=1), axis=1) / 2.0
    a2 = beta[:, 1] ** 2 + beta[:, 2] ** 2
    return float(np.mean(a2)), float(np.mean(2.0 * w2 / (m / 2.0))), m * float(t[1] - t[0])
