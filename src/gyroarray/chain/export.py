"""Noise files for VIO/INS tools, with their convention stated and a round-trip check.

``gyroarray export MODEL.toml --format F --rate-hz R`` writes one gyro's noise in the fields
and units of a robotics tool. Every format describes the same two processes, white rate noise
and a random-walk bias, in one of two conventions:

* **continuous-time densities** of a two-sided white PSD (Kalibr, OpenVINS, ORB-SLAM3, MATLAB):
  the white density σ_c [rad/s/√Hz] is the IEEE Std 952 ARW coefficient N [rad/√s]
  (ADEV = N/√τ), the walk density σ_w [rad/s²/√Hz] is the RRW coefficient K [rad/s/√s]
  (ADEV = K·√(τ/3)); the tool discretises them at its rate R: one sample's white noise
  σ_d = σ_c·√R, one step's bias increment σ_c,walk·√(1/R).
  - Kalibr wiki "IMU Noise Model" (github.com/ethz-asl/kalibr/wiki/IMU-Noise-Model):
    ``gyroscope_noise_density`` and ``gyroscope_random_walk`` are the continuous-time σ_g and
    σ_bg; σ_gd = σ_g/√Δt, σ_bgd = σ_bg·√Δt.
  - OpenVINS reads Kalibr's ``kalibr_imu_chain.yaml`` (config/euroc_mav/) and discretises in
    its propagator: ``Qc = sigma_w_2 / dt``, ``sigma_wb_2 * dt``.
  - ORB-SLAM3 ``IMU.NoiseGyro``/``IMU.GyroWalk`` are the same densities; Tracking.cc builds
    ``IMU::Calib(Tbc, Ng*sf, Na*sf, Ngw/sf, Naw/sf)`` with ``sf = sqrt(IMU.Frequency)``: a
    wrong frequency moves the noise and the walk in opposite directions.
  - MATLAB ``gyroparams``: NoiseDensity [(rad/s)/√Hz] = N, RandomWalk [(rad/s)·√Hz] = K,
    BiasInstability [rad/s] = B (MathWorks "Inertial Sensor Noise Analysis Using Allan
    Variance" sets them from the Allan fit this way); the sample rate is imuSensor's.
* **discrete-time standard deviations** per sample (VINS-Fusion ``gyr_n``/``gyr_w``):
  integration_base.h puts ``GYR_N²`` on the gyro reading at each end of a mid-point step with
  a weight ``0.5·dt`` and ``GYR_W²`` on the bias with weight ``dt``: ``gyr_n`` is one sample's
  standard deviation σ_c·√R [rad/s] and ``gyr_w`` the bias rate per step σ_w·√R [rad/s²]
  (bias increment ``gyr_w·dt = σ_w·√dt``). The EuRoC pair shows both conventions on one
  sensor: Kalibr 1.6968e-4 / 1.9393e-5 at 200 Hz, VINS-Fusion 0.01 / 1e-4; 0.01/1.6968e-4 =
  58.9 = √200 (14.1, the conversion) × 4.17 (an inflation the authors chose).

None of these filters has bias instability (flicker), a Gauss-Markov bias or quantization
(MATLAB has bias instability). Their share of the Allan variance is carried by a stand-in
random walk K_eq added to the walk, K_tot² = K² + K_eq²: with u(τ) the Allan variance of the
terms the format cannot hold, τ₁ the averaging time where u first reaches the ARW line N²/τ
(below it the white noise dominates), K_eq² = max over τ ≥ τ₁ of 3·u(τ)/τ, so that the
stand-in line K_eq²·τ/3 ≥ u(τ) for every τ ≥ τ₁ (for a flat bias-instability floor
(0.664 B)² = 2 ln2/π·B², K_eq = 0.664·B·√(3/τ₁)); it is within a factor 2 of the floor in
ADEV up to τ₂ = 4·τ₁ and above it beyond. Each file's header says so.

``--inflate auto``: the factor f on both numbers that makes a discrete Kalman filter that
knows only white noise + random walk (at the exported values, at the rate) consistent on a
record simulated from the full model: the filter estimates the bias of a still gyro from the
mean rate over update windows of 1 sample to 10 s; its normalised innovation squared
(NIS = ν²/S, expectation 1 when the model is right) is averaged per window, and
f = √(largest mean NIS). Scaling Q and R by f² leaves the gain unchanged and divides NIS by
f², so f makes the worst window consistent. Unmodelled slow effects (bias instability,
Gauss-Markov, temperature) raise NIS at the long windows; quantization at one sample.

``--verify`` simulates a record from the file's numbers as the tool reads them (its
convention and rate), re-identifies N and K with the Allan noise fit
(:func:`gyroarray.analysis.allan.allan_analysis`) and checks (a) the round trip: each
re-identified value within 3σ of the value the file means (N with the white-like term
K²dt²/6 of a walk sampled at the rate, :func:`sampled_walk_n2`); (b) the model's Allan deviation
(all its noise terms, times the inflation) inside the simulated record's 95 % interval at
90 % of the averaging times or more. A file failing either is flagged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import cast

import numpy as np
from scipy import optimize, signal

from gyroarray import __version__
from gyroarray.analysis.allan import allan_analysis, confidence_interval
from gyroarray.analysis.noise_fit import TERM_CONSTANTS, term_basis
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.physics import flicker_noise, gauss_markov_avar
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.sim.effects import simulate_readings
from gyroarray.sim.lab import lab_temperature
from gyroarray.effects.names import ARW, BIAS_INSTABILITY, GAUSS_MARKOV, QUANTIZATION, RATE_RAMP, RRW, TEMPERATURE_BIAS

__all__ = ["FORMATS", "SUFFIXES", "MAX_SIM_SAMPLES", "GyroNoise", "StandIn", "gyro_noise", "choose_axis", "model_gyros",
           "stand_in", "check_exportable", "sampled_walk_n2", "exported_values", "tool_discrete", "render",
           "simulate_model", "window_nis", "auto_inflation", "verify_export", "export_noise"]

#: The formats and what each file is.
FORMATS = {
    "kalibr": "Kalibr imu.yaml (continuous-time densities)",
    "openvins": "OpenVINS kalibr_imu_chain.yaml (continuous-time densities)",
    "vins": "VINS-Fusion config snippet (discrete-time per-sample standard deviations)",
    "orbslam3": "ORB-SLAM3 settings snippet (continuous-time densities, √rate inside)",
    "matlab": "MATLAB gyroparams snippet (.m; IEEE N, K, B)",
}

#: Allowed suffixes of --out for each format.
SUFFIXES = {"kalibr": (".yaml", ".yml"), "openvins": (".yaml", ".yml"), "vins": (".yaml", ".yml"),
            "orbslam3": (".yaml", ".yml"), "matlab": (".m",)}

#: Effects the simulation of a still gyro runs (the others need motion, a site or are
#: array-wide; they are listed as not simulated).
SIMULATED = (ARW, RRW, BIAS_INSTABILITY, GAUSS_MARKOV, QUANTIZATION, RATE_RAMP,
             TEMPERATURE_BIAS)

#: Most samples a simulated record has (--verify, --inflate auto): 2^21, 2.9 h at 200 Hz.
MAX_SIM_SAMPLES = 2 ** 21

#: IMU rates exported for [Hz] (as ``plan``'s: below 1 mHz no white-noise region is left, above
#: 1 MHz no gyro output exists).
MIN_RATE_HZ, MAX_RATE_HZ = 1e-3, 1e6

#: Longest filter update window of --inflate auto [s].
MAX_WINDOW_S = 10.0

_C_B = cast(float, TERM_CONSTANTS["oadev"]["b"])            # 2 ln2/π: flicker Allan variance per B²


@dataclass(frozen=True)
class GyroNoise:
    """One gyro's noise in SI, as the export sees it.

    Parameters
    ----------
    gyro : int
        1-based gyro.
    n_rad_rt_s : float
        ARW N [rad/√s] = white rate density [rad/s/√Hz].
    k_rad_s_rt_s : float
        RRW K [rad/s/√s] = walk density [rad/s²/√Hz].
    b_rad_s : float
        Bias instability B [rad/s] (0: none).
    q_rad : float
        Quantization Q [rad] (0: none).
    r_rad_s2 : float
        Rate ramp R [rad/s²] (0: none).
    gm : tuple of (float, float)
        Gauss-Markov terms (σ [rad/s], τc [s]).
    entries : tuple of ModelEntry
        The model's entries for this gyro (an all-gyros entry unless the gyro has its own).
    """

    gyro: int
    n_rad_rt_s: float
    k_rad_s_rt_s: float
    b_rad_s: float = 0.0
    q_rad: float = 0.0
    r_rad_s2: float = 0.0
    gm: tuple = ()
    entries: tuple = field(default=(), repr=False)

    def model_avar(self, taus_s, *, with_b: bool = True, dt_s: float = 0.0) -> np.ndarray:
        """Allan variance of every term of the model [(rad/s)²] at ``taus_s`` [s] (flicker as
        its flat floor; temperature left out). ``dt_s`` > 0: the random walk sampled at that
        step [s], whose Allan variance is K²τ/3 + K²dt²/(6τ) (a white-like term)."""
        taus = np.asarray(taus_s, dtype=float)
        out = (sampled_walk_n2(self.n_rad_rt_s, self.k_rad_s_rt_s, dt_s) * term_basis("oadev", "n", taus)
               + self.k_rad_s_rt_s ** 2 * term_basis("oadev", "k", taus)
               + self.q_rad ** 2 * term_basis("oadev", "q", taus)
               + self.r_rad_s2 ** 2 * term_basis("oadev", "r", taus))
        if with_b:
            out = out + _C_B * self.b_rad_s ** 2 * np.ones_like(taus)
        for sigma, tau_c in self.gm:
            out = out + gauss_markov_avar(taus, sigma, tau_c)
        return out


def sampled_walk_n2(n_rad_rt_s: float, k_rad_s_rt_s: float, dt_s: float) -> float:
    """N² [rad²/s] of white noise N plus a random walk K sampled every ``dt_s`` [s].

    The Allan variance of a sampled walk (one step of variance K²dt) averaged over m samples is
    K²dt(2m² + 1)/(6m) = K²τ/3 + K²dt²/(6τ): a white-FM term N² = K²dt²/6 the continuous
    formula lacks (tiny next to any real ARW; what a round trip of N = 0 re-identifies).
    """
    return n_rad_rt_s ** 2 + k_rad_s_rt_s ** 2 * dt_s ** 2 / 6.0


def gyro_noise(model: NoiseModel, gyro: int) -> GyroNoise:
    """The noise of gyro ``gyro`` of ``model`` (an entry for the gyro overrides an all-gyros
    entry of the same effect).

    Raises
    ------
    InputError
        No white noise (``arw``) for that gyro: there is nothing to export.
    """
    chosen: dict[str, ModelEntry] = {}
    for e in model:
        if e.gyro is None and e.effect not in chosen:
            chosen[e.effect] = e
    for e in model:
        if e.gyro == gyro:
            chosen[e.effect] = e
    if ARW not in chosen:
        have = sorted({e.gyro for e in model if e.effect == ARW and e.gyro is not None})
        hint = f" (gyros with one: {', '.join(map(str, have))}; pick one with --gyro)" if have else ""
        raise InputError(f"the model has no arw entry for gyro {gyro}: a noise file needs the "
                         f"white noise{hint}")

    def si(effect, key):
        return float(chosen[effect].si_params.get(key, 0.0)) if effect in chosen else 0.0
    gm: tuple[tuple[float, float], ...] = ()
    if GAUSS_MARKOV in chosen:
        p = chosen[GAUSS_MARKOV].si_params
        gm = ((float(p["sigma_rad_s"]), float(p["tau_s"])),)
    return GyroNoise(gyro=gyro, n_rad_rt_s=si(ARW, "n_rad_rt_s"),
                     k_rad_s_rt_s=si(RRW, "k_rad_s_rt_s"),
                     b_rad_s=si(BIAS_INSTABILITY, "b_rad_s"), q_rad=si(QUANTIZATION, "q_rad"),
                     r_rad_s2=si(RATE_RAMP, "r_rad_s2"), gm=gm,
                     entries=tuple(chosen.values()))


def model_gyros(model: NoiseModel) -> list[int]:
    """The gyros a model describes: those with an entry of their own, else [1] (all-gyros
    entries only: every gyro alike)."""
    own = sorted({e.gyro for e in model if e.gyro is not None})
    return own or [1]


#: τ grid on which :func:`choose_axis` compares the gyros' model ADEV [s] (0.01 s to 1000 s,
#: 4 points per decade).
AXIS_TAUS_S = np.logspace(-2, 3, 21)


def choose_axis(model: NoiseModel, axis: str | int) -> tuple[GyroNoise, str, list[dict]]:
    """The noise a file is written with, what it is, and every gyro's numbers.

    ``axis``: ``"worst"`` (default of ``export``; what allan_variance_ros writes): the gyro whose
    model Allan variance is largest on average over :data:`AXIS_TAUS_S` (mean of log σ², every
    term the model has), so the file understates no axis's noise at most τ; ``"mean"`` (what
    imu_utils writes): the gyros' mean ARW, RRW and bias instability (other terms dropped, said
    so); an int: that gyro. Returns (noise, one line saying which, [{gyro, N, K, B} per gyro] in
    datasheet units).
    """
    gyros = model_gyros(model)
    noises = []
    for g in gyros:
        try:
            noises.append(gyro_noise(model, g))
        except InputError:
            continue                      # a gyro without white noise (e.g. one effect of its own)
    if isinstance(axis, int) or (isinstance(axis, str) and axis.isdigit()):
        k = int(axis)
        chosen = gyro_noise(model, k)
        what = f"gyro {k} (as asked)"
    elif not noises:
        chosen = gyro_noise(model, gyros[0])          # raises, naming what is missing
        what = ""
    elif axis == "worst":
        score = [float(np.mean(np.log(np.maximum(n.model_avar(AXIS_TAUS_S), 1e-300)))) for n in noises]
        chosen = noises[int(np.argmax(score))]
        what = (f"gyro {chosen.gyro}, the worst of the model's {len(noises)} gyros (the largest model ADEV "
                f"on average over tau 0.01-1000 s)" if len(noises) > 1 else f"gyro {chosen.gyro}, the model's only one")
    elif axis == "mean":
        m = len(noises)
        mean = GyroNoise(gyro=0, n_rad_rt_s=float(np.mean([n.n_rad_rt_s for n in noises])),
                         k_rad_s_rt_s=float(np.mean([n.k_rad_s_rt_s for n in noises])),
                         b_rad_s=float(np.mean([n.b_rad_s for n in noises])))
        entries = [ModelEntry(ARW, None, {"n_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(mean.n_rad_rt_s))})]
        if mean.k_rad_s_rt_s > 0:
            entries.append(ModelEntry(RRW, None, {"k_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(
                mean.k_rad_s_rt_s))}))
        if mean.b_rad_s > 0:
            entries.append(ModelEntry(BIAS_INSTABILITY, None, {"b_deg_h": float(units.rad_s_to_deg_h(mean.b_rad_s))}))
        dropped = sorted({e.effect for n in noises for e in n.entries} - {ARW, RRW, BIAS_INSTABILITY})
        chosen = GyroNoise(gyro=0, n_rad_rt_s=mean.n_rad_rt_s, k_rad_s_rt_s=mean.k_rad_s_rt_s,
                           b_rad_s=mean.b_rad_s, entries=tuple(entries))
        what = (f"the mean of the model's {m} gyros (ARW, RRW, bias instability)"
                + (f"; left out: {', '.join(dropped)}" if dropped else ""))
    else:
        raise InputError(f"--axis must be worst, mean or a gyro number, got {axis!r}")
    table = [{"gyro": n.gyro, "n_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(n.n_rad_rt_s)),
              "k_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(n.k_rad_s_rt_s)),
              "b_deg_h": float(units.rad_s_to_deg_h(n.b_rad_s))} for n in noises]
    return chosen, what, table


@dataclass(frozen=True)
class StandIn:
    """The random walk that stands in for the terms a format cannot hold.

    Parameters
    ----------
    k_eq_rad_s_rt_s : float
        K_eq [rad/s/√s] (0: nothing to stand in for).
    tau1_s, tau2_s : float
        It bounds their Allan deviation from τ₁ [s] on, within a factor 2 up to τ₂ [s].
    covers : tuple of str
        The terms it stands in for.
    """

    k_eq_rad_s_rt_s: float
    tau1_s: float
    tau2_s: float
    covers: tuple


def stand_in(noise: GyroNoise, rate_hz: float, *, keeps_b: bool) -> StandIn:
    """The stand-in random walk K_eq for bias instability (unless the format ``keeps_b``) and
    Gauss-Markov terms (module docstring)."""
    covers = tuple(name for name, on in ((BIAS_INSTABILITY, noise.b_rad_s > 0 and not keeps_b),
                                         (GAUSS_MARKOV, bool(noise.gm))) if on)
    if not covers:
        return StandIn(0.0, math.nan, math.nan, ())
    taus = np.logspace(math.log10(1.0 / rate_hz), 8.0, 801)

    def unmodelled(t):
        u = np.zeros_like(t)
        if BIAS_INSTABILITY in covers:
            u = u + _C_B * noise.b_rad_s ** 2
        for sigma, tau_c in noise.gm:
            u = u + gauss_markov_avar(t, sigma, tau_c)
        return u
    u = unmodelled(taus)
    above = np.flatnonzero(u >= noise.n_rad_rt_s ** 2 / taus)
    i1 = int(above[0]) if above.size else int(np.argmax(u * taus))
    tau1 = float(taus[i1])
    if above.size and 0 < i1 and noise.n_rad_rt_s > 0:   # the crossing, between two grid points
        tau1 = float(optimize.brentq(
            lambda t: float(unmodelled(np.array([t]))[0]) - noise.n_rad_rt_s ** 2 / t,
            float(taus[i1 - 1]), tau1, rtol=1e-12))
    later = taus >= tau1
    grid = np.concatenate([[tau1], taus[later]])
    k_eq2 = float(np.max(3.0 * unmodelled(grid) / grid))
    return StandIn(math.sqrt(k_eq2), tau1, 4.0 * tau1, covers)


def check_exportable(noise: GyroNoise, fmt: str, rate_hz: float) -> None:
    """Refuse a gyro the format's reader would refuse, or whose model means nothing at the rate.

    * No white noise (N = 0): every tool inverts the measurement noise; Kalibr's reader
      (``kalibr_common/ConfigReader.py``, ``checkGyroStatistics``) refuses a
      ``gyroscope_noise_density`` <= 0, and so a file of zeros.
    * Kalibr: its reader refuses ``gyroscope_random_walk`` <= 0 too (no rrw, bias instability
      or Gauss-Markov term to make a walk of).
    * A Gauss-Markov correlation time below the sample step 1/rate: sampled at the rate the
      process is white noise of per-sample σ (what the simulation draws) but its continuous
      Allan variance is 2σ²τc/τ, a different level; the file's stand-in walk has no meaning
      there. τc >= 1/rate_hz is required (export at --rate-hz >= 1/τc, or fold it into arw).

    Raises
    ------
    InputError
    """
    if not noise.n_rad_rt_s > 0:
        reader = ("a Kalibr noise density of 0 is refused by Kalibr's reader" if fmt in ("kalibr", "openvins")
                  else f"a {fmt} white noise of 0 makes the tool's measurement covariance singular")
        raise InputError(f"the model has no white noise for gyro {noise.gyro} (arw n_deg_rt_h = 0): "
                         f"{reader}; give the arw entry a value > 0")
    if fmt == "kalibr":
        k_eq = stand_in(noise, rate_hz, keeps_b=False).k_eq_rad_s_rt_s
        if not math.hypot(noise.k_rad_s_rt_s, k_eq) > 0:
            raise InputError(f"the model has no random walk for gyro {noise.gyro} (rrw, "
                             "bias_instability or gauss_markov): a Kalibr gyroscope_random_walk "
                             "of 0 is refused by Kalibr's reader; give an rrw entry a value > 0")
    for sigma, tau_c in noise.gm:
        if sigma > 0 and tau_c < 1.0 / rate_hz:
            raise InputError(f"gauss_markov tau_s = {tau_c:g} s of gyro {noise.gyro} is shorter than "
                             f"the sample step at --rate-hz {rate_hz:g} ({1.0 / rate_hz:g} s): at this "
                             f"rate it is white noise, not a bias; tau_s must be >= 1/rate "
                             f"(export at --rate-hz >= {1.0 / tau_c:g}, or fold it into arw)")


def exported_values(noise: GyroNoise, fmt: str, rate_hz: float, inflate: float = 1.0) -> dict:
    """The numbers of the file, by field name, in the format's units.

    Parameters
    ----------
    noise : GyroNoise
    fmt : str
        One of :data:`FORMATS`.
    rate_hz : float
        The rate the tool runs the IMU at [Hz].
    inflate : float
        Factor on the white and walk numbers (and B for MATLAB) [-].

    Returns
    -------
    dict
        Field -> value (e.g. ``gyroscope_noise_density`` [rad/s/√Hz]).
    """
    keeps_b = fmt == "matlab"
    k_eq = stand_in(noise, rate_hz, keeps_b=keeps_b).k_eq_rad_s_rt_s
    n = inflate * noise.n_rad_rt_s
    k = inflate * math.sqrt(noise.k_rad_s_rt_s ** 2 + k_eq ** 2)
    if fmt in ("kalibr", "openvins"):
        return {"gyroscope_noise_density": n, "gyroscope_random_walk": k, "update_rate": rate_hz}
    if fmt == "orbslam3":
        return {"IMU.NoiseGyro": n, "IMU.GyroWalk": k, "IMU.Frequency": rate_hz}
    if fmt == "vins":
        root = math.sqrt(rate_hz)
        return {"gyr_n": n * root, "gyr_w": k * root}
    if fmt == "matlab":
        return {"NoiseDensity": n, "RandomWalk": k, "BiasInstability": inflate * noise.b_rad_s,
                "SampleRate": rate_hz}
    raise InputError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")


def tool_discrete(fmt: str, values: dict, rate_hz: float) -> tuple[float, float]:
    """How the tool reads the file: one sample's white-noise σ [rad/s] and one step's bias
    increment σ [rad/s] at ``rate_hz``."""
    root = math.sqrt(rate_hz)
    if fmt in ("kalibr", "openvins"):
        return values["gyroscope_noise_density"] * root, values["gyroscope_random_walk"] / root
    if fmt == "orbslam3":                           # Ng*sf, Ngw/sf (Tracking.cc)
        return values["IMU.NoiseGyro"] * root, values["IMU.GyroWalk"] / root
    if fmt == "vins":                               # GYR_N per sample, GYR_W·dt per step
        return values["gyr_n"], values["gyr_w"] / rate_hz
    if fmt == "matlab":
        return values["NoiseDensity"] * root, values["RandomWalk"] / root
    raise InputError(f"unknown format {fmt!r}")


def _num(x: float) -> str:
    return f"{x:.6e}"


def _header(noise: GyroNoise, fmt: str, rate_hz: float, inflate: float, why: str,
            source: str, comment: str, axis: tuple | None = None) -> list[str]:
    si = stand_in(noise, rate_hz, keeps_b=fmt == "matlab")
    n_dh = units.arw_rad_rt_s_to_deg_rt_h(noise.n_rad_rt_s)
    k_dh = units.rrw_rad_s_rt_s_to_deg_h_rt_h(noise.k_rad_s_rt_s)
    discrete = fmt == "vins"
    lines = [
        f"gyroarray {__version__} export --format {fmt}: "
        + (f"gyro {noise.gyro}" if axis is None else axis[0]) + f" of {source}",
        f"model: ARW N = {n_dh:.6g} deg/√h = {noise.n_rad_rt_s:.6e} rad/s/√Hz; "
        f"RRW K = {k_dh:.6g} deg/h/√h = {noise.k_rad_s_rt_s:.6e} rad/s²/√Hz",
        ("convention: DISCRETE-time, per sample at the rate below: gyr_n = σ_c·√rate [rad/s] "
         "(one sample's white-noise σ), gyr_w = σ_w·√rate [rad/s²] (bias increment per step "
         "gyr_w·dt = σ_w·√dt), as VINS-Fusion's integration_base.h propagates them"
         if discrete else
         "convention: CONTINUOUS-time densities of a TWO-sided white PSD (σ_c = IEEE ARW N, "
         "ADEV = N/√τ; σ_w = IEEE RRW K, ADEV = K·√(τ/3)); the tool discretises at its rate: "
         "σ_d = σ_c·√rate, bias step σ_w/√rate"),
        f"rate assumed: {rate_hz:g} Hz" + (" (the discrete values are wrong at any other rate)"
                                          if discrete or fmt == "orbslam3" else ""),
    ]
    if fmt == "orbslam3":
        lines.append("ORB-SLAM3 multiplies NoiseGyro by √IMU.Frequency and divides GyroWalk by it "
                     "(Tracking.cc: IMU::Calib(Tbc, Ng*sf, Na*sf, Ngw/sf, Naw/sf)): keep "
                     "IMU.Frequency the true rate")
    if si.covers:
        k_eq = units.rrw_rad_s_rt_s_to_deg_h_rt_h(si.k_eq_rad_s_rt_s)
        lines.append(
            f"bias instability / Gauss-Markov: not in this format; a stand-in random walk "
            f"K_eq = {k_eq:.6g} deg/h/√h for {' + '.join(si.covers)} is added in quadrature to K "
            f"(K_tot² = K² + K_eq²): its ADEV line K_eq·√(τ/3) bounds theirs for τ >= "
            f"{si.tau1_s:.4g} s (where they reach the ARW line) and is within a factor 2 up to "
            f"{si.tau2_s:.4g} s; above that it overstates the drift")
    elif noise.b_rad_s > 0 and fmt == "matlab":
        lines.append("bias instability: BiasInstability = B (IEEE coefficient, ADEV floor "
                     "0.664·B)")
    else:
        lines.append("bias instability: none in the model; the walk is the fitted RRW")
    lost = [e.effect for e in noise.entries if e.effect in (QUANTIZATION, RATE_RAMP,
                                                            TEMPERATURE_BIAS)]
    if lost:
        lines.append(f"not representable here: {', '.join(lost)} (see --inflate auto)")
    if axis is not None and len(axis[1]) > 1:
        lines.append("every gyro of the model (ARW deg/√h, RRW deg/h/√h, BI deg/h): " + "; ".join(
            f"{g['gyro']}: {g['n_deg_rt_h']:.4g}, {g['k_deg_h_rt_h']:.4g}, {g['b_deg_h']:.4g}" for g in axis[1])
            + " (--axis worst|mean|K chooses)")
    lines.append(f"inflation: ×{inflate:.4g} on both numbers ({why})")
    lines.append("accelerometer: not measured by gyroarray; fill in the accelerometer fields "
                 "from your own Allan fit")
    return [f"{comment} {line}" for line in lines]


def render(noise: GyroNoise, fmt: str, rate_hz: float, *, inflate: float = 1.0,
           why: str = "none asked", source: str = "MODEL.toml", axis: tuple | None = None) -> str:
    """The file's text: the comment header, then the fields."""
    v = exported_values(noise, fmt, rate_hz, inflate)
    if fmt == "matlab":
        head = _header(noise, fmt, rate_hz, inflate, why, source, "%", axis)
        body = ["gyro = gyroparams( ...",
                f"    'NoiseDensity', {_num(v['NoiseDensity'])}, ...    % (rad/s)/sqrt(Hz)",
                f"    'RandomWalk', {_num(v['RandomWalk'])}, ...      % (rad/s)*sqrt(Hz)",
                f"    'BiasInstability', {_num(v['BiasInstability'])});  % rad/s",
                f"sampleRate = {rate_hz!r};   % Hz: imu = imuSensor('SampleRate', sampleRate, "
                "'Gyroscope', gyro);",
                "% accel = accelparams(...);  % fill in from your accelerometer's Allan fit"]
        return "\n".join(head + body) + "\n"
    head = ["%YAML:1.0"] if fmt in ("openvins", "vins", "orbslam3") else []
    head += _header(noise, fmt, rate_hz, inflate, why, source, "#", axis)
    if fmt == "kalibr":
        body = ["rostopic: /imu0",
                f"update_rate: {rate_hz!r}   # Hz",
                "# accelerometer_noise_density: FILL_IN   # [ m / s^2 / sqrt(Hz) ] (continuous)",
                "# accelerometer_random_walk: FILL_IN     # [ m / s^3 / sqrt(Hz) ]",
                f"gyroscope_noise_density: {_num(v['gyroscope_noise_density'])}   "
                "# [ rad / s / sqrt(Hz) ] (continuous)",
                f"gyroscope_random_walk: {_num(v['gyroscope_random_walk'])}     "
                "# [ rad / s^2 / sqrt(Hz) ]"]
    elif fmt == "openvins":
        eye4 = ["    - [1.0, 0.0, 0.0, 0.0]", "    - [0.0, 1.0, 0.0, 0.0]",
                "    - [0.0, 0.0, 1.0, 0.0]", "    - [0.0, 0.0, 0.0, 1.0]"]
        body = (["imu0:", "  T_i_b:"] + eye4 +
                ["  # accelerometer_noise_density: FILL_IN  # [ m / s^2 / sqrt(Hz) ]",
                 "  # accelerometer_random_walk: FILL_IN    # [ m / s^3 / sqrt(Hz) ]",
                 f"  gyroscope_noise_density: {_num(v['gyroscope_noise_density'])}  "
                 "# [ rad / s / sqrt(Hz) ]",
                 f"  gyroscope_random_walk: {_num(v['gyroscope_random_walk'])}    "
                 "# [ rad / s^2 / sqrt(Hz) ]",
                 "  rostopic: /imu0", "  time_offset: 0.0", f"  update_rate: {rate_hz!r}",
                 '  model: "kalibr"'])
    elif fmt == "vins":
        body = ["# acc_n: FILL_IN   # accelerometer measurement noise standard deviation",
                f"gyr_n: {_num(v['gyr_n'])}   # gyroscope measurement noise standard deviation "
                "[rad/s], per sample",
                "# acc_w: FILL_IN   # accelerometer bias random walk noise standard deviation",
                f"gyr_w: {_num(v['gyr_w'])}   # gyroscope bias random walk noise standard "
                "deviation [rad/s^2], per step"]
    else:                                            # orbslam3
        body = [f"IMU.NoiseGyro: {_num(v['IMU.NoiseGyro'])}   # rad/s/sqrt(Hz) (continuous)",
                f"IMU.GyroWalk: {_num(v['IMU.GyroWalk'])}    # rad/s^2/sqrt(Hz)",
                "# IMU.NoiseAcc: FILL_IN   # m/s^2/sqrt(Hz)",
                "# IMU.AccWalk: FILL_IN    # m/s^3/sqrt(Hz)",
                f"IMU.Frequency: {rate_hz!r}   # Hz"]
    return "\n".join(head + body) + "\n"


def _sim_model(noise: GyroNoise) -> tuple[NoiseModel, list[str]]:
    keep, dropped = [], []
    for e in noise.entries:
        if e.effect in SIMULATED:
            keep.append(ModelEntry(e.effect, None, dict(e.params)))
        else:
            dropped.append(e.effect)
    return NoiseModel(tuple(keep)), dropped


def simulate_model(noise: GyroNoise, rate_hz: float, n: int, rng: np.random.Generator
                   ) -> tuple[np.ndarray, list[str]]:
    """A still record of the gyro's full model (its stochastic effects, temperature through a
    25 -> 35 °C warm-up), and the effects not simulated."""
    model, dropped = _sim_model(noise)
    dt = 1.0 / rate_hz
    time_s = np.arange(n) * dt
    temp = lab_temperature(time_s) if any(e.effect == TEMPERATURE_BIAS for e in model) else None
    out = simulate_readings(model, np.zeros((n, 3)), np.array([[1.0, 0.0, 0.0]]), dt, rng,
                            time_s=time_s, temp_c=temp)
    return out[:, 0], dropped


def _record_samples(rate_hz: float, seconds: float) -> int:
    return int(min(MAX_SIM_SAMPLES, max(4096, round(seconds * rate_hz))))


def window_nis(rate: np.ndarray, rate_hz: float, n_c: float, k_c: float, window: int) -> float:
    """Mean NIS of a scalar Kalman filter of the bias of a still gyro, updated with the mean
    rate over ``window`` samples; white density ``n_c`` [rad/s/√Hz] and walk ``k_c``
    [rad/s²/√Hz] (steady state; the first tenth of the record or 20 time constants left out)."""
    dt_w = window / rate_hz
    y = rate[: (rate.size // window) * window].reshape(-1, window).mean(axis=1)
    r = n_c ** 2 / dt_w
    q = k_c ** 2 * dt_w
    if q <= 0:                                       # no walk: the running mean
        k = np.arange(y.size)
        prior = np.concatenate([[0.0], np.cumsum(y)[:-1] / np.maximum(k[1:], 1)])
        s = r + r / np.maximum(k, 1)
        start = max(10, y.size // 10)
    else:
        p = 0.5 * (q + math.sqrt(q * q + 4.0 * q * r))           # steady-state prior variance
        gain = p / (p + r)
        prior = signal.lfilter([0.0, gain], [1.0, gain - 1.0], y)
        s = np.full(y.size, p + r)
        start = min(max(y.size // 10, int(20.0 / gain)), y.size // 2)
    nu = y[start:] - prior[start:]
    return float(np.mean(nu ** 2 / s[start:]))


def auto_inflation(noise: GyroNoise, fmt: str, rate_hz: float, rng: np.random.Generator,
                   seconds: float = 7200.0) -> dict:
    """The inflation that makes a white + walk filter at the exported values consistent on a
    record of the full model (module docstring).

    Returns
    -------
    dict
        ``factor`` [-], ``nis`` (window [s] -> mean NIS at factor 1), ``record_s`` [s],
        ``not_simulated`` (effects left out) and ``why`` (one line).
    """
    n = _record_samples(rate_hz, seconds)
    rate, dropped = simulate_model(noise, rate_hz, n, rng)
    sigma_d, sigma_b = tool_discrete(fmt, exported_values(noise, fmt, rate_hz), rate_hz)
    n_c, k_c = sigma_d / math.sqrt(rate_hz), sigma_b * math.sqrt(rate_hz)
    windows = sorted({int(w) for w in np.unique(np.round(np.logspace(
        0.0, math.log10(max(1.0, min(MAX_WINDOW_S * rate_hz, n / 1000))), 5)))})
    nis = {w / rate_hz: window_nis(rate, rate_hz, n_c, k_c, w) for w in windows}
    worst_w = max(nis, key=lambda w: nis[w])
    factor = math.sqrt(nis[worst_w])
    why = (f"√ of the largest mean NIS, {nis[worst_w]:.3g} at {worst_w:.3g} s windows, of a "
           f"bias filter at the exported values on {n / rate_hz:.0f} s simulated from the full "
           f"model")
    return {"factor": factor, "nis": {f"{w:.6g}": v for w, v in nis.items()},
            "record_s": n / rate_hz, "not_simulated": dropped, "why": why}


def verify_export(noise: GyroNoise, fmt: str, rate_hz: float, inflate: float,
                  rng: np.random.Generator, seconds: float = 7200.0) -> dict:
    """Round trip of a file: simulate what the tool's reading of it generates, re-identify
    N and K, compare (module docstring).

    Returns
    -------
    dict
        ``passed``; ``record_s``; per coefficient the value the file means, the re-identified
        value, its 1σ and z; ``band``: the fraction of averaging times where the model's ADEV
        (× inflate) lies in the simulated record's 95 % interval, the worst τ and ratio;
        ``problems`` (one line each).
    """
    values = exported_values(noise, fmt, rate_hz, inflate)
    sigma_d, sigma_b = tool_discrete(fmt, values, rate_hz)
    n = _record_samples(rate_hz, seconds)
    dt = 1.0 / rate_hz
    rate = sigma_d * rng.standard_normal(n) + np.cumsum(sigma_b * rng.standard_normal(n))
    terms: tuple[str, ...] = ("n", "k")
    b_file = values.get("BiasInstability", 0.0)
    if fmt == "matlab" and b_file > 0:
        rate = rate + flicker_noise(n, dt, [b_file], [rng])[:, 0]
        terms = ("n", "b", "k")
    a = allan_analysis(rate, dt, terms=terms)
    k_file = sigma_b / math.sqrt(dt)
    meant = {"n": math.sqrt(sampled_walk_n2(sigma_d * math.sqrt(dt), k_file, dt)), "k": k_file,
             "b": b_file}
    names = {"n": ("arw_deg_rt_h", units.arw_rad_rt_s_to_deg_rt_h),
             "k": ("rrw_deg_h_rt_h", units.rrw_rad_s_rt_s_to_deg_h_rt_h),
             "b": ("bi_deg_h", units.rad_s_to_deg_h)}
    out: dict = {"record_s": n * dt, "coefficients": {}, "problems": []}
    for t in terms:
        got, sig = a.fit.coefficient(t)
        name, conv = names[t]
        z = (got - meant[t]) / sig if sig else math.inf
        out["coefficients"][name] = {"file": float(conv(meant[t])), "reidentified": float(conv(got)),
                                     "sigma": None if sig is None else float(conv(sig)),
                                     "z": float(z)}
        if not abs(z) <= 3.0:
            out["problems"].append(f"{name}: the file means {conv(meant[t]):.4g}, the round trip "
                                   f"gives {conv(got):.4g} (z = {z:.2g}, more than 3σ)")
    low, high = confidence_interval(a.adev_rad_s, a.edf, 0.95)
    model_dev = inflate * np.sqrt(noise.model_avar(a.taus_s, dt_s=dt))
    inside = (model_dev >= low) & (model_dev <= high)
    ratio = model_dev / a.adev_rad_s
    worst = int(np.argmax(np.abs(np.log(ratio))))
    out["band"] = {"inside_fraction": float(inside.mean()), "n_taus": int(inside.size),
                   "worst_tau_s": float(a.taus_s[worst]), "worst_model_over_file": float(ratio[worst])}
    under = int(np.count_nonzero(model_dev > high))     # the file understates: overconfident
    over = int(np.count_nonzero(model_dev < low))       # the file overstates: conservative
    out["band"].update({"file_understates": under, "file_overstates": over})
    if inside.mean() < 0.9:
        out["problems"].append(
            f"the model's ADEV lies outside the file's 95 % interval at {under + over} of "
            f"{inside.size} averaging times (the file understates it at {under}: a filter would "
            f"be overconfident there; overstates it at {over}: conservative; worst τ = "
            f"{a.taus_s[worst]:.4g} s, model/file = {ratio[worst]:.3g}): the format cannot "
            "reproduce the model's ADEV")
    out["passed"] = not out["problems"]
    return out


def export_noise(model: NoiseModel, gyro: int | str, fmt: str, rate_hz: float, *,
                 inflate: float | str = 1.0, verify: bool = False, seed: int = 0,
                 source: str = "MODEL.toml") -> tuple[str, dict]:
    """The file's text and a JSON-ready summary (what ``gyroarray export`` writes and prints).

    Parameters
    ----------
    model : NoiseModel
    gyro : int or {"worst", "mean"}
        1-based gyro, or the axis rule of :func:`choose_axis`.
    fmt : str
        One of :data:`FORMATS`.
    rate_hz : float
        IMU rate the tool runs at [Hz].
    inflate : float or "auto"
        Factor on both numbers, or derived (:func:`auto_inflation`).
    verify : bool
        Run :func:`verify_export`.
    seed : int
        Seed of the simulations.
    source : str
        The model file's name, for the header.
    """
    if fmt not in FORMATS:
        raise InputError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
    if not (math.isfinite(rate_hz) and MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ):
        raise InputError(f"--rate-hz must be in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {rate_hz!r}")
    noise, what, every = choose_axis(model, gyro)
    check_exportable(noise, fmt, rate_hz)
    rng = np.random.default_rng(seed)
    summary: dict = {"format": fmt, "gyro": noise.gyro if noise.gyro else None, "axis": what,
                     "gyros": every, "rate_hz": rate_hz}
    if inflate == "auto":
        auto = auto_inflation(noise, fmt, rate_hz, rng)
        factor, why = auto["factor"], auto["why"]
        summary["inflate_auto"] = auto
    else:
        factor, why = float(inflate), ("as asked" if float(inflate) != 1.0 else "none asked")
    text = render(noise, fmt, rate_hz, inflate=factor, why=why, source=source, axis=(what, every))
    si = stand_in(noise, rate_hz, keeps_b=fmt == "matlab")
    summary.update({
        "inflate": factor, "values": exported_values(noise, fmt, rate_hz, factor),
        "convention": "discrete per sample" if fmt == "vins" else "continuous, two-sided PSD",
        "stand_in": {"covers": list(si.covers),
                     "k_eq_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(si.k_eq_rad_s_rt_s)),
                     "tau1_s": si.tau1_s if si.covers else None,
                     "tau2_s": si.tau2_s if si.covers else None},
    })
    if verify:
        summary["verify"] = verify_export(noise, fmt, rate_hz, factor, rng)
    return text, summary
