"""Independent generator of gyro-array records, written only from the specs.

Why: ``benchmarks/diagnosis_score.py`` scores our diagnosis on records from
our own simulator, which only shows that our simulator and our fitter agree.
This module makes records the way an outside party would, from
``/work/shared/spec/effects.md``, ``/work/shared/spec/measurement-format.md``
and the practice protocol in ``/work/shared/measurements/README.md``. It
imports only numpy, scipy and the standard library, nothing from gyroarray,
and was written without reading the project's simulator or effect code.

What a case is (:func:`make_case`): a 50 Hz record of a conical array on a
3-axis rate table -- 20 min static, rate steps about z (10, 30, 50, 80 deg/s),
+-30 deg/s about x and about y, two swings about z, 5 min static -- while the
temperature rises from 25 degC. Every gyro has ARW, RRW and a turn-on bias,
plus ONE hidden effect from the spec with random parameters (one of the
spec's effects, or one of its four faults on one gyro: :data:`FAULTS`).
:func:`write_case` writes ``<stem>.csv.gz`` + ``<stem>.toml``.

The signal chain of one gyro (the spec's order, followed to the letter):

1. the true inertial rate of the platform (reference rate relative to the
   Earth, plus the Earth rate in the platform frame for ``earth_rate``),
   projected on the gyro's TRUE axis (``misalignment`` tilts it), delayed by
   ``latency``;
2. ``scale_factor`` and ``scale_nonlinearity`` on that sensed rate;
3. additive terms: ``g_sensitivity``, turn-on bias, RRW, ARW (``correlation``
   across gyros, ``burst`` window), bias instability, Gauss-Markov, rate
   ramp, sinusoid, temperature bias, outliers;
4. ``bandwidth``: causal low-pass on all of the above;
5. ``quantization`` (of the integrated angle), then ``saturation``;
6. faults, on the final output: ``fault_step`` adds ``size_deg_s``,
   ``fault_drift`` adds ``rate_deg_s2``*(t - ``start_s``), ``fault_stuck``
   repeats the last output before ``start_s``; ``fault_noise`` is the
   exception: it multiplies the white (ARW) draw of step 3 by ``ratio``.

Conventions chosen here where the spec leaves room (each is a place where an
outside generator and gyroarray could differ -- see the report):

* ARW N [deg/sqrt(h)]: white rate noise, sample sigma = (N/60)/sqrt(dt)
  deg/s, so ADEV(1 s) = N/60 deg/s.
* RRW K [deg/h/sqrt(h)]: random walk of the rate with increments
  sigma = (K/3600/60)*sqrt(dt) deg/s, so ADEV(tau) = K*sqrt(tau/3).
* Bias instability B [deg/h]: 1/f rate noise, two-sided PSD
  B^2/(2 pi f) (IEEE 952), i.e. one-sided B^2/(pi f), shaped by FFT; the
  ADEV floor is sqrt(2 ln2/pi) B = 0.664 B.
* Quantization Q [deg]: the spec's Q is the IEEE-952 coefficient of
  sigma^2 = 3 Q^2/tau^2. The integrated angle is quantized with the angle
  step S = sqrt(12) Q (uniform error variance S^2/12 = Q^2, and the Allan
  variance of a differenced white angle error is 3 sigma_x^2/tau^2), and the
  output is the difference of quantized angles / dt, the spec's definition:
  y_k = (round(theta_k/S) - round(theta_{k-1}/S)) S/dt, theta_k = sum_{j<=k}
  x_j dt of everything the gyro produces (after the bandwidth filter), from
  theta_{-1} = 0. (Quantizing with step Q
  itself would give sigma = Q/(2 tau), i.e. Q_ieee = Q/sqrt(12).) With little
  dither (angle moving < 1 step per sample at rest) the rounding error is
  not white, and the short-tau ADEV departs from sqrt(3) Q/tau by a factor
  0.6-1.3 (a real quantizer does this); :data:`QUANTIZATION_METHOD` =
  "white" adds an iid uniform angle error instead, the IEEE model exactly.
* Sinusoid: amp*sin(2 pi f t + phase), t from the first sample.
* Rate ramp: R*t, t from the first sample.
* Temperature bias: deg_h_per_c*(T - t0_c).
* Gauss-Markov: stationary AR(1), phi = exp(-dt/tau), started stationary.
* Outliers: Poisson number of single-sample spikes (rate_per_h), each
  N(0, size^2) (rms = size_deg_s), at random samples.
* Bandwidth: the spec's discretisation, the bilinear transform prewarped at
  the cut-off, i.e. ``scipy.signal.butter(order, cutoff_hz, fs=fs)`` (the
  digital -3 dB point is the cut-off), run causally with ``lfilter`` from the
  steady state of the first sample (``lfilter_zi * x[0]``).
  :data:`BANDWIDTH_METHOD` = "foh" switches, for diagnosis, to the continuous
  H(s) discretised exactly for a piecewise-linear input (first-order hold,
  ``cont2discrete('foh')``, which keeps the continuous low-frequency lag).
* Earth rate: heading is always 0 (platform x = north, y = west, z = up at
  t = 0), so the heading sign convention never matters; Earth rate in the
  level frame = w_e [cos(lat), 0, sin(lat)], rotated into the platform frame
  with the attitude integrated from the reference rates.
* g_sensitivity: f_0 = gravity specific force C^T [0, 0, g0] from the same
  attitude (positions zero, so no centripetal/tangential term); no acc_*
  columns are written. With :data:`LEVER_ARMS` the gyros sit at random
  ``positions_m`` (±0.25 m per component), f_k = f_0 + α × r_k + ω × (ω × r_k)
  with α the centred difference of the analytic rate, and f_0 is written as
  ``acc_x/y/z``.
* Misalignment: ``axis`` = the nominal axis tilted by ``tilt_deg`` towards a
  random direction perpendicular to it.
* Faults (spec, "Faults"): one gyro, from ``start_s`` to the end of the
  record. ``start_s`` is drawn in whole seconds, so it falls on a sample
  (50 Hz); the onset sample is the first with t >= ``start_s`` (that sample is
  already faulty), :func:`fault_onset_index`. Drift: t - ``start_s`` with t
  the record's own time (0 at the onset sample). Stuck: every sample from the
  onset equals the final output (after quantization and saturation) of the
  sample before it, bit for bit in the CSV. Noise: ``ratio`` scales the
  white draw's amplitude (its standard deviation, not its variance --
  unlike ``burst``'s ``variance_ratio``); RRW, bias and the rate are
  unchanged. Ranges (record 2184 s): step +-(0.02-0.2) deg/s, drift
  +-(2e-5-2e-4) deg/s^2 (magnitudes log-uniform), noise ratio 2-5; onset
  uniform in 10-90 % of the record (drift 10-75 %, so at least 546 s of it,
  >= 0.011 deg/s at the end).
"""

from __future__ import annotations

import gzip
import math
import zlib
from pathlib import Path

import numpy as np
from scipy import signal

# ---------------------------------------------------------------------------
# constants (SI inside)
# ---------------------------------------------------------------------------
FS_HZ = 50.0
DT_S = 1.0 / FS_HZ
G0 = 9.80665                      # m/s^2
EARTH_RATE_RAD_S = 7.2921150e-5   # rad/s
DEG = math.pi / 180.0             # rad per deg
BANDWIDTH_METHOD = "bilinear_prewarp"  # the spec's; or "foh", "bilinear" (any cont2discrete method)
QUANTIZATION_METHOD = "round"     # or "white" (the IEEE-952 model: iid uniform angle error)
LEVER_ARMS = False                # g_sensitivity: gyros at positions_m (±0.25 m) and acc_* columns

EFFECTS = ["bias_instability", "quantization", "rate_ramp", "gauss_markov", "sinusoid",
           "scale_factor", "scale_nonlinearity", "misalignment", "temperature_bias", "latency",
           "saturation", "correlation", "earth_rate", "burst", "bandwidth", "g_sensitivity",
           "outliers"]
FAULTS = ["fault_step", "fault_drift", "fault_stuck", "fault_noise"]   # spec "Faults": one gyro each
EFFECTS = EFFECTS + FAULTS
ARRAY_WIDE = {"correlation", "earth_rate", "burst"}

# spec units -> SI
def arw_sigma_rad_s(n_deg_rt_h: float, dt: float) -> float:
    """Sample sigma [rad/s] of white rate noise with ARW ``n`` deg/sqrt(h)."""
    return n_deg_rt_h / 60.0 * DEG / math.sqrt(dt)


def rrw_step_rad_s(k_deg_h_rt_h: float, dt: float) -> float:
    """Per-sample increment sigma [rad/s] of a rate random walk ``k`` deg/h/sqrt(h)."""
    return k_deg_h_rt_h / 3600.0 / 60.0 * DEG * math.sqrt(dt)


def deg_h_to_rad_s(x):
    return np.asarray(x, float) / 3600.0 * DEG


# ---------------------------------------------------------------------------
# noise processes (all return rad/s, shape (n,) unless said)
# ---------------------------------------------------------------------------
def white(rng, n: int, sigma: float) -> np.ndarray:
    return sigma * rng.standard_normal(n)


def random_walk(rng, n: int, step_sigma: float) -> np.ndarray:
    """Random walk starting at 0 (the turn-on bias carries the offset)."""
    x = np.cumsum(step_sigma * rng.standard_normal(n))
    return x - x[0]


def flicker(rng, n: int, dt: float, b_rad_s: float) -> np.ndarray:
    """1/f rate noise, IEEE-952 bias instability B: ADEV floor sqrt(2 ln2/pi) B = 0.664 B.

    IEEE 952 writes the PSD two-sided, S(f) = B^2/(2 pi f); the one-sided
    PSD shaped here is twice that, B^2/(pi f).

    FFT-shaped white noise over twice the length (the first half is kept, so
    the circular wrap does not show); the DC bin is zero.
    """
    m = 2 * n
    w = rng.standard_normal(m)                       # one-sided PSD 2*dt
    W = np.fft.rfft(w)
    f = np.fft.rfftfreq(m, dt)
    shape = np.zeros_like(f)
    shape[1:] = np.sqrt(b_rad_s ** 2 / (np.pi * f[1:]) / (2.0 * dt))
    return np.fft.irfft(W * shape, m)[:n]


def gauss_markov(rng, n: int, dt: float, sigma: float, tau: float) -> np.ndarray:
    """Stationary first-order Gauss-Markov process (AR(1)), sigma [rad/s], tau [s]."""
    phi = math.exp(-dt / tau)
    e = sigma * math.sqrt(1.0 - phi * phi) * rng.standard_normal(n)
    e[0] = sigma * rng.standard_normal()
    return signal.lfilter([1.0], [1.0, -phi], e)


def quantize_angle(rate: np.ndarray, dt: float, q_ieee_rad: float, rng=None) -> np.ndarray:
    """Angle quantization with IEEE-952 coefficient Q (step sqrt(12) Q); rate in, rate out.

    The integrated angle theta_k = sum_{j<=k} rate_j dt is rounded to the
    step S = sqrt(12) Q; the output is the first difference / dt (the first
    sample's angle counts from a zero angle before the record).
    """
    step = math.sqrt(12.0) * q_ieee_rad
    if QUANTIZATION_METHOD == "white":
        # diagnosis variant: the error the IEEE model assumes, independent of the signal
        e = step * rng.uniform(-0.5, 0.5, len(rate))
        return rate + np.diff(e, prepend=0.0) / dt
    theta = np.cumsum(rate * dt)
    tq = step * np.round(theta / step)
    return np.diff(tq, prepend=0.0) / dt


# ---------------------------------------------------------------------------
# faults (spec "Faults"): one gyro, from start_s to the end of the record
# ---------------------------------------------------------------------------
def fault_onset_index(t: np.ndarray, start_s: float) -> int:
    """Index of the first sample with t >= ``start_s`` [s] (1 us slack for the float time grid)."""
    return int(np.searchsorted(t, start_s - 1e-6, side="left"))


def fault_on_output(y: np.ndarray, t: np.ndarray, effect: str, params: dict) -> np.ndarray:
    """``fault_step`` / ``fault_drift`` / ``fault_stuck`` on one gyro's FINAL output.

    ``y`` [rad/s] is the gyro's output after quantization and saturation,
    ``t`` [s] the record's time; ``params`` in spec units (deg/s, deg/s^2, s).
    Returns a new array: from the onset sample on, y + size (step),
    y + rate*(t - start_s) (drift), or y[onset - 1] (stuck).
    """
    k0 = fault_onset_index(t, params["start_s"])
    out = np.array(y, float, copy=True)
    if effect == "fault_step":
        out[k0:] += params["size_deg_s"] * DEG
    elif effect == "fault_drift":
        out[k0:] += params["rate_deg_s2"] * DEG * np.clip(t[k0:] - params["start_s"], 0.0, None)
    elif effect == "fault_stuck":
        if k0 < 1:
            raise ValueError("fault_stuck needs a sample before start_s")
        out[k0:] = out[k0 - 1]
    else:
        raise ValueError(f"not an output fault: {effect!r}")
    return out


def fault_noise_gain(t: np.ndarray, start_s: float, ratio: float) -> np.ndarray:
    """Per-sample factor on one gyro's white (ARW) draw: 1 before ``start_s`` [s], ``ratio`` from it on."""
    g = np.ones(len(t))
    g[fault_onset_index(t, start_s):] = ratio
    return g


def lowpass_coeffs(cutoff_hz: float, order: int, fs: float, method: str | None = None):
    """(b, a) of the discretised spec filter: order 1 or 2 (Butterworth), -3 dB at cutoff."""
    method = method or BANDWIDTH_METHOD
    if method == "bilinear_prewarp":
        return signal.butter(order, cutoff_hz, fs=fs)
    wc = 2.0 * np.pi * cutoff_hz
    den = [1.0 / wc, 1.0] if order == 1 else [1.0 / wc ** 2, math.sqrt(2.0) / wc, 1.0]
    b, a, _ = signal.cont2discrete(([1.0], den), 1.0 / fs, method=method)
    b = np.atleast_1d(np.squeeze(b)).astype(float)
    a = np.asarray(a, float)
    return b / a[0], a / a[0]


def lowpass(x: np.ndarray, cutoff_hz: float, order: int, fs: float, method: str | None = None):
    """Causal filtering, initial state = steady state on x[0] (DC gain 1)."""
    b, a = lowpass_coeffs(cutoff_hz, order, fs, method)
    zi = signal.lfilter_zi(b, a) * x[0]
    y, _ = signal.lfilter(b, a, x, zi=zi)
    return y


# ---------------------------------------------------------------------------
# layout, motion, temperature, attitude
# ---------------------------------------------------------------------------
def cone_axes(scheme: int, n: int, alpha_deg: float) -> np.ndarray:
    """Unit axes (N, 3) of the spec's scheme 1 / scheme 2 conical layouts."""
    a = alpha_deg * DEG
    rows = []
    if scheme == 1:
        for k in range(1, n + 1):
            b = 2 * np.pi * (k - 1) / n
            rows.append([math.sin(a) * math.cos(b), math.sin(a) * math.sin(b), math.cos(a)])
    else:
        rows.append([0.0, 0.0, 1.0])
        for k in range(2, n + 1):
            b = 2 * np.pi * (k - 2) / (n - 1)
            rows.append([math.sin(a) * math.cos(b), math.sin(a) * math.sin(b), math.cos(a)])
    return np.array(rows)


STATIC_START_S = 1200.0
STATIC_END_S = 300.0


def _segments():
    """The motion program: list of (t_start, duration, axis, kind, args); deg/s, Hz, s."""
    segs, t = [], STATIC_START_S
    ez, ex, ey = np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    for amp in (10.0, 30.0, 50.0, 80.0):
        segs.append((t, 64.0, ez, "step", (amp, 1.0 + amp / 40.0)))
        t += 64.0
    for axis in (ex, ey):
        for amp in (30.0, -30.0):
            segs.append((t, 64.0, axis, "step", (amp, 1.5)))
            t += 64.0
    segs.append((t, 100.0, ez, "swing", (25.0, 0.125, 2.0)))
    t += 104.0
    segs.append((t, 64.0, ez, "swing", (6.0, 0.4, 2.0)))
    t += 68.0
    return segs, t + STATIC_END_S


def record_length_s() -> float:
    return _segments()[1]


def ref_rate_deg_s(t: np.ndarray) -> np.ndarray:
    """Reference rate (n, 3) [deg/s] of the table, body frame, relative to the Earth.

    Steps: raised-cosine ramp up over T_r (finite, continuous angular
    acceleration, at most amp*pi/(2 T_r)), plateau, the same ramp down, 2 s
    rest at both ends of a 64 s slot. Swings: amp*sin(2 pi f t') with a
    raised-cosine taper of 2 s at both ends.
    """
    t = np.asarray(t, float)
    out = np.zeros(t.shape + (3,))
    for t0, dur, axis, kind, args in _segments()[0]:
        u = t - t0
        inside = (u >= 0) & (u < dur)
        if not inside.any():
            continue
        u = u[inside]
        if kind == "step":
            amp, tr = args
            up0, down0 = 2.0, dur - 2.0 - tr
            w = np.ones_like(u)
            w = np.where(u < up0, 0.0, w)
            w = np.where((u >= up0) & (u < up0 + tr), 0.5 * (1 - np.cos(np.pi * (u - up0) / tr)), w)
            w = np.where((u >= down0) & (u < down0 + tr), 0.5 * (1 + np.cos(np.pi * (u - down0) / tr)), w)
            w = np.where(u >= down0 + tr, 0.0, w)
            r = amp * w
        else:
            amp, f, taper = args
            env = np.ones_like(u)
            env = np.where(u < taper, 0.5 * (1 - np.cos(np.pi * u / taper)), env)
            env = np.where(u > dur - taper, 0.5 * (1 - np.cos(np.pi * (dur - u) / taper)), env)
            r = amp * env * np.sin(2 * np.pi * f * u)
        out[inside] += r[:, None] * axis[None, :]
    return out


def temperature_c(t: np.ndarray, rise_c: float, tau_s: float) -> np.ndarray:
    """Array temperature [degC]: 25 + rise*(1 - exp(-t/tau)), a slow warm-up."""
    return 25.0 + rise_c * (1.0 - np.exp(-t / tau_s))


def _rotation(phi: np.ndarray) -> np.ndarray:
    """Rotation matrix exp([phi x]) (Rodrigues)."""
    th = float(np.linalg.norm(phi))
    if th < 1e-15:
        return np.eye(3)
    k = phi / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * (K @ K)


def attitude(t: np.ndarray) -> np.ndarray:
    """C_k (n, 3, 3): platform -> level frame (x north, y west, z up; heading 0 at t = 0).

    Integrated from the analytic reference rate with the midpoint rate of
    each step (exact here, since the table turns about one axis at a time).
    A level-frame vector v has platform components C_k^T v.
    """
    n = len(t)
    C = np.empty((n, 3, 3))
    cur = np.eye(3)
    mid = ref_rate_deg_s(0.5 * (t[1:] + t[:-1])) * DEG
    dts = np.diff(t)
    C[0] = cur
    for k in range(n - 1):
        w = mid[k]
        if w[0] != 0.0 or w[1] != 0.0 or w[2] != 0.0:
            cur = cur @ _rotation(w * dts[k])
        C[k + 1] = cur
    return C


# ---------------------------------------------------------------------------
# the case
# ---------------------------------------------------------------------------
def _rng(effect: str, seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(effect.encode())]))


def _signed(rng, lo, hi):
    return float(rng.uniform(lo, hi) * rng.choice([-1.0, 1.0]))


def _signed_log(rng, lo, hi):
    """Random sign times a log-uniform magnitude in [lo, hi]."""
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))) * rng.choice([-1.0, 1.0]))


def _draw_layout(rng) -> dict:
    if rng.uniform() < 0.7:
        n = int(rng.choice([4, 5, 6, 8]))
        alpha = float(rng.choice([54.7356, 54.7356, 45.0, 60.0]))
        return {"scheme": 1, "n_gyros": n, "alpha_deg": alpha}
    n = int(rng.choice([5, 6]))
    alpha = float(rng.choice([63.4349, 54.7356, 60.0]))
    return {"scheme": 2, "n_gyros": n, "alpha_deg": alpha}


def _tilted(axis: np.ndarray, tilt_deg: float, rng) -> np.ndarray:
    """Unit axis tilted by tilt_deg from ``axis`` towards a random perpendicular direction."""
    tmp = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(axis, tmp)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    psi = rng.uniform(0, 2 * np.pi)
    d = math.cos(psi) * u + math.sin(psi) * v
    a = tilt_deg * DEG
    out = math.cos(a) * axis + math.sin(a) * d
    return out / np.linalg.norm(out)


def _draw_params(effect: str, rng, T: float) -> dict:
    """Hidden effect's parameters in spec units (ranges a bit wider than ours)."""
    u = rng.uniform
    if effect == "bias_instability":
        return {"b_deg_h": float(u(4, 25))}
    if effect == "quantization":
        return {"q_deg": float(np.exp(u(np.log(4e-4), np.log(4e-3))))}
    if effect == "rate_ramp":
        return {"r_deg_h2": _signed(rng, 80, 750)}
    if effect == "gauss_markov":
        return {"sigma_deg_h": float(u(40, 350)), "tau_s": float(np.exp(u(np.log(0.15), np.log(30))))}
    if effect == "sinusoid":
        return {"amp_deg_s": float(u(0.008, 0.07)), "freq_hz": float(u(1.0, 22.0)),
                "phase_deg": float(u(0, 360))}
    if effect == "scale_factor":
        return {"ppm": _signed(rng, 800, 10000)}
    if effect == "scale_nonlinearity":
        return {"k2_per_deg_s": _signed(rng, 8e-6, 7.5e-5)}
    if effect == "misalignment":
        return {"tilt_deg": float(u(0.15, 1.2))}          # axis added once the gyro is known
    if effect == "temperature_bias":
        return {"deg_h_per_c": _signed(rng, 8, 75), "t0_c": 25.0}
    if effect == "latency":
        return {"delay_s": float(u(0.0015, 0.012))}
    if effect == "saturation":
        return {}                                          # range drawn from the gyro's max rate
    if effect == "correlation":
        return {"rho_arw": float(u(0.12, 0.6))}
    if effect == "earth_rate":
        return {"latitude_deg": float(u(20, 65) * rng.choice([-1.0, 1.0]))}
    if effect == "burst":
        start = float(np.round(u(60.0, T - 700.0)))
        dur = float(np.round(u(120.0, 600.0)))
        return {"start_s": start, "end_s": min(start + dur, T - 60.0), "variance_ratio": float(u(1.8, 7.0))}
    if effect == "bandwidth":
        return {"cutoff_hz": float(u(2.5, 18.0)), "order": int(rng.choice([1, 2]))}
    if effect == "g_sensitivity":
        mag = u(0.008, 0.25, 3) * rng.choice([-1.0, 1.0], 3)
        return {"deg_s_per_g": [float(x) for x in mag]}
    if effect == "outliers":
        return {"rate_per_h": float(u(50, 750)), "size_deg_s": float(u(0.4, 3.5))}
    # faults: onset in whole seconds (on a sample), 10-90 % of the record (drift 10-75 %)
    if effect == "fault_step":
        return {"start_s": float(np.round(u(0.1 * T, 0.9 * T))), "size_deg_s": _signed_log(rng, 0.02, 0.2)}
    if effect == "fault_drift":
        return {"start_s": float(np.round(u(0.1 * T, 0.75 * T))), "rate_deg_s2": _signed_log(rng, 2e-5, 2e-4)}
    if effect == "fault_stuck":
        return {"start_s": float(np.round(u(0.1 * T, 0.9 * T)))}
    if effect == "fault_noise":
        return {"start_s": float(np.round(u(0.1 * T, 0.9 * T))), "ratio": float(u(2.0, 5.0))}
    raise ValueError(f"unknown effect {effect!r}")


def make_case(effect: str, seed: int, with_fault: bool = True) -> dict:
    """One record with ARW + RRW + turn-on bias on every gyro and ONE hidden ``effect``.

    ``with_fault=False`` (a fault effect only; for :func:`selfcheck`) draws
    everything as usual but leaves the fault out, so the difference of the
    two records is the fault alone.

    Returns a dict: ``stem``, ``effect``, ``gyro`` (1-based or None),
    ``params`` (spec units, as in answers.json), ``layout`` (sidecar table),
    ``layout_name``, ``axes`` (nominal), ``site``, ``sample_rate_hz``,
    ``time_s``, ``gyro_deg_s`` (n, N), ``ref_deg_s`` (n, 3), ``temp_c``,
    ``baseline`` (per-gyro arw/rrw/bias in spec units).
    """
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}")
    rng = _rng(effect, seed)
    lay = _draw_layout(rng)
    N, dt = lay["n_gyros"], DT_S
    axes = cone_axes(lay["scheme"], N, lay["alpha_deg"])
    T = record_length_s()
    t = np.arange(int(round(T * FS_HZ))) * dt
    n = len(t)
    ref = ref_rate_deg_s(t)                                     # deg/s (written as is)
    temp = temperature_c(t, float(rng.uniform(6.0, 14.0)), float(rng.uniform(600.0, 1500.0)))
    # baseline
    arw = rng.uniform(0.08, 0.3, N)                              # deg/sqrt(h)
    rrw = rng.uniform(0.5, 8.0, N)                               # deg/h/sqrt(h)
    bias = rng.normal(0.0, 250.0, N)                             # deg/h
    gyro = None if effect in ARRAY_WIDE else int(rng.integers(1, N + 1))
    params = _draw_params(effect, rng, T)
    site = {"latitude_deg": 34.25, "heading_deg": 0.0}
    if effect == "earth_rate":
        site["latitude_deg"] = params["latitude_deg"]

    true_axes = axes.copy()
    if effect == "misalignment":
        true_axes[gyro - 1] = _tilted(axes[gyro - 1], params["tilt_deg"], rng)
        params["axis"] = [float(x) for x in true_axes[gyro - 1]]

    # 1. true inertial rate, rad/s, and the sensed rate on each true axis
    omega = ref * DEG
    C = None
    if effect in ("earth_rate", "g_sensitivity"):
        C = attitude(t)
    if effect == "earth_rate":
        lat = params["latitude_deg"] * DEG
        we_level = EARTH_RATE_RAD_S * np.array([math.cos(lat), 0.0, math.sin(lat)])
        omega = omega + np.einsum("kji,j->ki", C, we_level)     # C^T w
    sensed = omega @ true_axes.T                                  # (n, N) rad/s
    if effect == "latency":
        k = gyro - 1
        sensed[:, k] = (ref_rate_deg_s(t - params["delay_s"]) * DEG) @ true_axes[k]

    # 2. scale factor / nonlinearity
    out = sensed.copy()
    if effect == "scale_factor":
        out[:, gyro - 1] *= 1.0 + params["ppm"] * 1e-6
    if effect == "scale_nonlinearity":
        k2_si = params["k2_per_deg_s"] / DEG                     # 1/(rad/s)
        out[:, gyro - 1] += k2_si * sensed[:, gyro - 1] ** 2

    # 3. additive terms
    positions = acc = None
    if effect == "g_sensitivity":
        f0 = np.einsum("kji,j->ki", C, np.array([0.0, 0.0, G0]))  # m/s^2, platform frame
        d = np.asarray(params["deg_s_per_g"]) * DEG               # rad/s per g
        fk = f0
        if LEVER_ARMS:
            # the spec's f_k = f_0 + α × r_k + ω × (ω × r_k), r_k from positions_m; f_0 is
            # written as acc_x/y/z; α from the analytic rate by a centred difference
            positions = np.random.default_rng([seed, 7919]).uniform(-0.25, 0.25, (N, 3))
            r = positions[gyro - 1]
            h = 1e-4
            alpha = (ref_rate_deg_s(t + h) - ref_rate_deg_s(t - h)) * DEG / (2.0 * h)
            fk = f0 + np.cross(alpha, r) + np.cross(omega, np.cross(omega, r))
            acc = f0
        out[:, gyro - 1] += fk @ d / G0
    out += deg_h_to_rad_s(bias)[None, :]
    for k in range(N):
        out[:, k] += random_walk(rng, n, rrw_step_rad_s(rrw[k], dt))
    z = rng.standard_normal((n, N))
    if effect == "correlation":
        R = np.full((N, N), params["rho_arw"])
        np.fill_diagonal(R, 1.0)
        z = z @ np.linalg.cholesky(R).T
    wn = z * np.array([arw_sigma_rad_s(a, dt) for a in arw])[None, :]
    if effect == "burst":
        win = (t >= params["start_s"]) & (t < params["end_s"])
        wn[win] *= math.sqrt(params["variance_ratio"])
    if effect == "fault_noise" and with_fault:
        wn[:, gyro - 1] *= fault_noise_gain(t, params["start_s"], params["ratio"])
    out += wn
    k = None if gyro is None else gyro - 1
    if effect == "bias_instability":
        out[:, k] += flicker(rng, n, dt, float(deg_h_to_rad_s(params["b_deg_h"])))
    if effect == "gauss_markov":
        out[:, k] += gauss_markov(rng, n, dt, float(deg_h_to_rad_s(params["sigma_deg_h"])), params["tau_s"])
    if effect == "rate_ramp":
        out[:, k] += params["r_deg_h2"] / 3600.0 ** 2 * DEG * t
    if effect == "sinusoid":
        out[:, k] += params["amp_deg_s"] * DEG * np.sin(2 * np.pi * params["freq_hz"] * t
                                                        + params["phase_deg"] * DEG)
    if effect == "temperature_bias":
        out[:, k] += float(deg_h_to_rad_s(params["deg_h_per_c"])) * (temp - params["t0_c"])
    if effect == "outliers":
        m = rng.poisson(params["rate_per_h"] * T / 3600.0)
        idx = rng.choice(n, size=m, replace=False)
        out[idx, k] += params["size_deg_s"] * DEG * rng.standard_normal(m)
        params["n_spikes"] = int(m)

    # 4. bandwidth
    if effect == "bandwidth":
        out[:, k] = lowpass(out[:, k], params["cutoff_hz"], params["order"], FS_HZ)
    # 5. quantization, saturation
    if effect == "quantization":
        out[:, k] = quantize_angle(out[:, k], dt, params["q_deg"] * DEG, rng)
    if effect == "saturation":
        peak = float(np.max(np.abs(sensed[:, k]))) / DEG       # deg/s, noise-free
        hi = min(68.0, 0.9 * peak)
        lo = min(40.0, 0.85 * hi)
        params["range_deg_s"] = float(rng.uniform(lo, hi))
        params["peak_deg_s"] = peak
        rng_si = params["range_deg_s"] * DEG
        out[:, k] = np.clip(out[:, k], -rng_si, rng_si)
    # 6. faults on the final output (fault_noise acted on the white draw in 3.)
    if effect in ("fault_step", "fault_drift", "fault_stuck") and with_fault:
        out[:, k] = fault_on_output(out[:, k], t, effect, params)
        if effect == "fault_stuck":
            params["stuck_value_deg_s"] = float(out[fault_onset_index(t, params["start_s"]), k] / DEG)

    name = f"S{lay['scheme']}N{N}a{lay['alpha_deg']:.1f}"
    return {"stem": f"indep_{effect}_{seed}", "effect": effect, "gyro": gyro, "params": params,
            "layout": lay, "layout_name": name, "axes": axes, "site": site,
            "sample_rate_hz": FS_HZ, "time_s": t, "gyro_deg_s": out / DEG, "ref_deg_s": ref,
            "temp_c": temp, "positions_m": positions, "acc_m_s2": acc,
            "baseline": {"arw_deg_rt_h": arw.tolist(), "rrw_deg_h_rt_h": rrw.tolist(),
                         "bias_deg_h": bias.tolist()}}


# names in ``params`` that are bookkeeping, not effect parameters
BOOKKEEPING = {"n_spikes", "peak_deg_s", "stuck_value_deg_s"}


def effect_params(case: dict) -> dict:
    """The hidden effect's parameters as the spec names them (no bookkeeping keys)."""
    return {k: v for k, v in case["params"].items() if k not in BOOKKEEPING}


def write_case(case: dict, directory) -> Path:
    """Write ``<stem>.csv.gz`` + ``<stem>.toml`` (measurement-format.md); returns the CSV path."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    csv = d / f"{case['stem']}.csv.gz"
    N = case["gyro_deg_s"].shape[1]
    header = ",".join(["time_s"] + [f"gyro{k}" for k in range(1, N + 1)]
                      + ["ref_x", "ref_y", "ref_z", "temp_c"])
    data = np.column_stack([case["time_s"], case["gyro_deg_s"], case["ref_deg_s"], case["temp_c"]])
    fmt = ["%.4f"] + ["%.9e"] * N + ["%.7f"] * 3 + ["%.4f"]
    if case.get("acc_m_s2") is not None:
        header += ",acc_x,acc_y,acc_z"
        data = np.column_stack([data, case["acc_m_s2"]])
        fmt += ["%.7f"] * 3
    with gzip.open(csv, "wt", compresslevel=3, newline="\n") as fh:
        np.savetxt(fh, data, fmt=fmt, delimiter=",", header=header, comments="")
    lay, site = case["layout"], case["site"]
    toml = (f"sample_rate_hz = {case['sample_rate_hz']:.1f}\n"
            f"description = \"independent generator: {case['effect']} seed {case['stem']}\"\n\n"
            f"[layout]\nscheme = {lay['scheme']}\nn_gyros = {lay['n_gyros']}\n"
            f"alpha_deg = {lay['alpha_deg']}\n"
            + ("" if case.get("positions_m") is None else
               "positions_m = [" + ", ".join("[" + ", ".join(f"{v:.6f}" for v in p) + "]"
                                            for p in case["positions_m"]) + "]\n")
            + "\n"
            f"[site]\nlatitude_deg = {site['latitude_deg']!r}\nheading_deg = {site['heading_deg']!r}\n")
    (d / f"{case['stem']}.toml").write_text(toml)
    return csv


# ---------------------------------------------------------------------------
# self-check against closed forms
# ---------------------------------------------------------------------------
def _oadev(y: np.ndarray, dt: float, taus_s) -> np.ndarray:
    """Overlapping ADEV of rate samples y at cluster times taus_s (own, no deps)."""
    x = np.concatenate([[0.0], np.cumsum(y) * dt])           # angle
    out = []
    for tau in taus_s:
        m = int(round(tau / dt))
        d = x[2 * m:] - 2 * x[m:-m] + x[:-2 * m]
        out.append(math.sqrt(np.mean(d * d) / (2.0 * (m * dt) ** 2)))
    return np.array(out)


def _fault_checks(rng, dt: float, n: int) -> dict:
    """The four faults against closed forms: on a synthetic gyro, then through :func:`make_case`.

    Synthetic gyro (deg/s): 100 deg/h bias + ARW 0.2 deg/sqrt(h) (+ RRW
    4 deg/h/sqrt(h) and the quantizer where the check allows it), n samples,
    onset at 40 % of the record.

    * step: mean after - mean before = size, SE sigma sqrt(1/n1 + 1/n2);
    * drift: least-squares slope after the onset = rate, SE sigma/sqrt(S_tt);
    * stuck: peak-to-peak from the onset = 0 and the onset value equals the
      last sample before it, exactly;
    * noise: std of first differences after/before = ratio; 95 % CI
      1.96 ratio sqrt(3/4 (1/n1 + 1/n2)) (the variance of a first-difference
      sample variance is 3 sigma_d^4/n: lag-1 correlation -1/2);
    * make_case at seed 510, with and without the fault (same draws): the
      difference is size (step) / rate (t - start) (drift) on the fault's
      gyro from the onset and 0 everywhere else; stuck: constant from the
      onset, equal to the sample before, other gyros untouched; noise: the
      difference is (ratio - 1) x the white draw, whose std must be the
      gyro's ARW sigma N/60/sqrt(dt) (95 % CI 1.96/sqrt(2 n)), and 0 before.
    """
    res = {}
    t = np.arange(n) * dt
    start = float(np.round(0.4 * n * dt))
    sig = arw_sigma_rad_s(0.2, dt) / DEG                                   # deg/s per sample
    base = 100.0 / 3600.0 + white(rng, n, sig * DEG) / DEG                 # deg/s
    k0 = fault_onset_index(t, start)
    n1, n2 = k0, n - k0
    # step
    size = 0.03
    y = fault_on_output(base * DEG, t, "fault_step", {"start_s": start, "size_deg_s": size}) / DEG
    shift, se = float(y[k0:].mean() - y[:k0].mean()), sig * math.sqrt(1.0 / n1 + 1.0 / n2)
    res["fault_step mean shift [deg/s] (got, SE)"] = ((round(shift, 6), round(se, 6)), size)
    # drift
    rate = 1e-4
    y = fault_on_output(base * DEG, t, "fault_drift", {"start_s": start, "rate_deg_s2": rate}) / DEG
    u = t[k0:] - start
    uc = u - u.mean()
    slope = float(np.sum(uc * (y[k0:] - y[k0:].mean())) / np.sum(uc * uc))
    res["fault_drift slope after onset [deg/s^2] (got, SE)"] = (
        (float(f"{slope:.5g}"), float(f"{sig / math.sqrt(np.sum(uc * uc)):.2g}")), rate)
    res["fault_drift max |change| before onset [deg/s]"] = (float(np.max(np.abs(y[:k0] - base[:k0]))), 0.0)
    # stuck, on a realistic output: RRW, ARW and the quantizer
    yq = quantize_angle(base * DEG + random_walk(rng, n, rrw_step_rad_s(4.0, dt)), dt, 1e-3 * DEG, rng)
    y = fault_on_output(yq, t, "fault_stuck", {"start_s": start}) / DEG
    res["fault_stuck ptp after onset, onset - last before [deg/s]"] = (
        (float(np.ptp(y[k0:])), float(y[k0] - yq[k0 - 1] / DEG)), (0.0, 0.0))
    # noise
    ratio = 3.0
    w = white(rng, n, sig * DEG) * fault_noise_gain(t, start, ratio)
    y = (w + random_walk(rng, n, rrw_step_rad_s(4.0, dt))) / DEG
    got = float(np.std(np.diff(y[k0:])) / np.std(np.diff(y[:k0])))
    ci = 1.96 * ratio * math.sqrt(0.75 * (1.0 / n1 + 1.0 / n2))
    res["fault_noise first-diff std ratio after/before (got, 95% CI)"] = ((round(got, 4), round(ci, 4)), ratio)
    # through make_case: the fault alone is the difference of the two records
    for eff in FAULTS:
        c, c0 = make_case(eff, 510), make_case(eff, 510, with_fault=False)
        p, g = effect_params(c), c["gyro"] - 1
        tt = c["time_s"]
        j0 = fault_onset_index(tt, p["start_s"])
        d = c["gyro_deg_s"] - c0["gyro_deg_s"]
        other = np.delete(d, g, axis=1)
        rest = max(float(np.max(np.abs(other))), float(np.max(np.abs(d[:j0, g]))))
        if eff == "fault_step":
            got = (float(np.max(np.abs(d[j0:, g] - p["size_deg_s"]))), rest)
            res[f"make_case {eff} max|diff - size|, max|diff| elsewhere [deg/s]"] = (got, (0.0, 0.0))
        elif eff == "fault_drift":
            want = p["rate_deg_s2"] * (tt[j0:] - p["start_s"])
            got = (float(np.max(np.abs(d[j0:, g] - want))), rest)
            res[f"make_case {eff} max|diff - rate(t-start)|, max|diff| elsewhere [deg/s]"] = (got, (0.0, 0.0))
        elif eff == "fault_stuck":
            yk = c["gyro_deg_s"][:, g]
            got = (float(np.ptp(yk[j0:])), float(yk[j0] - yk[j0 - 1]), rest,
                   float(np.std(c0["gyro_deg_s"][j0:, g])))
            res[f"make_case {eff} ptp after, onset-before, max|diff| elsewhere, "
                "std unfaulted after [deg/s]"] = (got, (0.0, 0.0, 0.0, "> 0"))
        else:
            sw = float(np.std(d[j0:, g]) / (p["ratio"] - 1.0))
            want = arw_sigma_rad_s(c["baseline"]["arw_deg_rt_h"][g], dt) / DEG
            ci = 1.96 * want / math.sqrt(2.0 * (len(tt) - j0))
            res[f"make_case {eff} std(diff)/(ratio-1) (got, 95% CI), max|diff| elsewhere [deg/s]"] = (
                (round(sw, 6), round(ci, 6), rest), round(want, 6))
    return res


def selfcheck(verbose: bool = True) -> dict:
    """Generator vs closed forms; returns {check: (got, want)} (deg/s or deg/h as labelled)."""
    rng = np.random.default_rng(12345)
    dt, n = DT_S, 2 ** 18                                      # 87 min at 50 Hz
    res = {}
    # ARW: ADEV(1 s) = N/60 deg/s
    N_ = 0.2
    y = white(rng, n, arw_sigma_rad_s(N_, dt)) / DEG
    res["arw ADEV(1 s) [deg/s]"] = (_oadev(y, dt, [1.0])[0], N_ / 60.0)
    # RRW: ADEV(tau) = K sqrt(tau/3), averaged over realizations at tau = 200 s
    K = 4.0
    vals = np.mean([_oadev(random_walk(rng, n, rrw_step_rad_s(K, dt)) / DEG * 3600.0, dt, [50.0, 200.0]) ** 2
                    for _ in range(64)], axis=0)
    for tau, v in zip((50.0, 200.0), vals):
        res[f"rrw ADEV({tau:g} s) [deg/h], 64 runs"] = (math.sqrt(v), K / 60.0 * math.sqrt(tau / 3.0))
    # quantization: ADEV = sqrt(3) Q / tau (moving input so the error is white)
    Q = 1e-3
    move = 3.0 * DEG + white(rng, n, 1.0 * DEG)     # > one step per sample: white error
    yq = (quantize_angle(move, dt, Q * DEG, rng) - move) / DEG
    for tau in (0.02, 0.2, 2.0):
        res[f"quant ADEV({tau} s) [deg/s]"] = (_oadev(yq, dt, [tau])[0], math.sqrt(3.0) * Q / tau)
    # bias instability floor 0.664 B (mean ADEV over 5..100 s, averaged over realizations)
    B = 10.0
    taus = [5.0, 10.0, 20.0, 50.0, 100.0]
    ad = np.sqrt(np.mean([_oadev(flicker(rng, n, dt, float(deg_h_to_rad_s(B))) / DEG * 3600.0, dt, taus) ** 2
                          for _ in range(8)], axis=0))
    for tau, a in zip(taus, ad):
        res[f"BI ADEV({tau:g} s) [deg/h]"] = (a, 0.664 * B)
    try:
        import allantools
        yb = flicker(rng, n, dt, float(deg_h_to_rad_s(B))) / DEG * 3600.0
        t2, a2, _, _ = allantools.oadev(yb, rate=FS_HZ, data_type="freq", taus=np.array([10.0, 50.0]))
        res["BI allantools oadev(10,50 s) [deg/h], one realization"] = (a2.round(3).tolist(), 0.664 * B)
    except ImportError:
        pass
    # Gauss-Markov: stationary sigma and lag-tau autocorrelation e^-1
    s_, tau_c = 100.0, 2.0
    g = gauss_markov(rng, n, dt, float(deg_h_to_rad_s(s_)), tau_c) / DEG * 3600.0
    lag = int(round(tau_c / dt))
    res["GM sigma [deg/h]"] = (float(np.std(g)), s_)
    res["GM autocorr(tau)"] = (float(np.corrcoef(g[:-lag], g[lag:])[0, 1]), math.exp(-1.0))
    # bandwidth: |H| at cutoff from freqz, and the low-frequency lag vs continuous
    for fc in (3.0, 8.0, 15.0):
        for order in (1, 2):
            b, a = lowpass_coeffs(fc, order, FS_HZ)
            _, h = signal.freqz(b, a, worN=[fc, 0.2], fs=FS_HZ)
            lag_ms = -np.angle(h[1]) / (2 * np.pi * 0.2) * 1e3
            want_lag = (1.0 if order == 1 else math.sqrt(2.0)) / (2 * np.pi * fc) * 1e3
            res[f"bw fc={fc:g} o={order}: dB at fc / lag@0.2Hz ms"] = (
                (round(20 * np.log10(abs(h[0])), 2), round(lag_ms, 3)), (-3.01, round(want_lag, 3)))
    # attitude: Earth-rate and gravity in the platform frame stay of constant norm
    tt = np.arange(int(record_length_s() * FS_HZ)) * dt
    C = attitude(tt)
    f0 = np.einsum("kji,j->ki", C, np.array([0.0, 0.0, G0]))
    res["gravity norm max err [m/s^2]"] = (float(np.max(np.abs(np.linalg.norm(f0, axis=1) - G0))), 0.0)
    res["gravity at end of record (platform) [m/s^2]"] = (f0[-1].round(4).tolist(), [0, 0, G0])
    r = ref_rate_deg_s(tt)
    res["max |ref| [deg/s], max |ang acc| [deg/s^2]"] = (
        (float(np.abs(r).max()), float(np.abs(np.diff(r, axis=0)).max() / dt)), None)
    res.update(_fault_checks(rng, dt, n))
    if verbose:
        for k, (got, want) in res.items():
            print(f"{k:<50} got {got}   want {want}")
    return res


if __name__ == "__main__":
    selfcheck()
