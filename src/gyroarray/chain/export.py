"""Noise files for VIO/INS tools, with their convention stated, read back with the consumer's parser.

``gyroarray export MODEL.toml --format F --rate-hz R`` writes the gyro's and the accelerometer's
noise in the fields and units of a robotics tool. Every format describes the same two processes
per sensor, white noise and a random-walk bias, in one of two conventions:

* **continuous-time densities** of a two-sided white PSD (Kalibr, OpenVINS, ORB-SLAM3, MATLAB):
  the white density σ_c [rad/s/√Hz] is the IEEE Std 952 ARW coefficient N [rad/√s]
  (ADEV = N/√τ), the walk density σ_w [rad/s²/√Hz] is the RRW coefficient K [rad/s/√s]
  (ADEV = K·√(τ/3)); the tool discretises them at its rate R: one sample's white noise
  σ_d = σ_c·√R, one step's bias increment σ_w·√(1/R). The accelerometer's are the IEEE Std 1293
  velocity random walk [m/s²/√Hz = m/s/√s] and acceleration random walk [m/s³/√Hz].
  - Kalibr wiki "IMU Noise Model" (github.com/ethz-asl/kalibr/wiki/IMU-Noise-Model):
    ``gyroscope_noise_density`` and ``gyroscope_random_walk`` are the continuous-time σ_g and
    σ_bg; σ_gd = σ_g/√Δt, σ_bgd = σ_bg·√Δt (``accelerometer_*`` alike). Its reader
    (``kalibr_common/ConfigReader.py``, ``ImuParameters``) requires the six keys of
    :data:`REQUIRED` and refuses a density or walk <= 0.
  - OpenVINS >= 2.7 reads ``kalibr_imu_chain.yaml`` with ``cv::FileStorage``
    (``ov_core/src/utils/opencv_yaml_parse.h``); ``ov_msckf/src/core/VioManagerOptions.h`` requires
    the four noise keys and the intrinsics ``Tw``, ``Ta``, ``R_IMUtoACC``, ``R_IMUtoGYRO``, ``Tg``
    under ``imu0`` (a missing one: "unable to parse all parameters"); its propagator uses
    ``sigma_w_2 / dt``, ``sigma_wb_2 * dt``. gyroarray does not know the IMU's intrinsics: the
    file writes them as identity (``Tg`` zeros), which is OpenVINS' own default, and says so.
  - ORB-SLAM3 ``IMU.NoiseGyro``/``IMU.GyroWalk``/``IMU.NoiseAcc``/``IMU.AccWalk`` are the same
    densities; Tracking.cc builds ``IMU::Calib(Tbc, Ng*sf, Na*sf, Ngw/sf, Naw/sf)`` with
    ``sf = sqrt(IMU.Frequency)``: a wrong frequency moves the noise and the walk in opposite
    directions. ``Tracking::ParseIMUParamFile`` requires ``IMU.Frequency`` to be an integer
    (``node.isInt()``) and the noises reals (``node.isReal()``).
  - MATLAB ``gyroparams``/``accelparams``: NoiseDensity = N, RandomWalk = K, BiasInstability = B
    (MathWorks "Inertial Sensor Noise Analysis Using Allan Variance" sets them from the Allan fit
    this way); the sample rate is imuSensor's.
* **discrete-time standard deviations** per sample (VINS-Fusion ``acc_n``/``gyr_n``,
  ``acc_w``/``gyr_w``): ``integration_base.h`` (``midPointIntegration``) propagates the
  preintegration covariance with ``V·noise·Vᵀ`` where ``noise`` holds ``GYR_N²`` for the reading
  at each end of the step, both with the weight ``V = 0.5·dt``, and ``GYR_W²`` for the bias with
  ``V = dt``. One step's attitude variance is therefore 2·(0.5·dt)²·GYR_N² = GYR_N²·dt²/2, while
  continuous white noise of density σ_c puts σ_c²·dt on it: GYR_N = √2·σ_c·√R, **√2 times one
  sample's σ** (the covariance treats the two readings of a step as independent, though each
  reading is shared by two steps). The bias: GYR_W²·dt² per step against σ_w²·dt, so
  GYR_W = σ_w·√R (bias increment per step ``gyr_w·dt = σ_w·√dt``). ``acc_n``/``acc_w`` alike
  (V = 0.5·R·dt on each reading's velocity, dt on the bias). The EuRoC pair: Kalibr
  1.6968e-4 / 1.9393e-5 at 200 Hz, VINS-Fusion 0.01 / 1e-4; the code's mapping gives 2.400e-3
  and 2.743e-4, so the published gyr_n is 4.17× the mapping (an inflation the authors chose) and
  the published gyr_w 0.36× it (a deflation; read as a density it would be 5.2× Kalibr's): the
  published numbers are tuning, not a convention.

None of these filters has bias instability (flicker), a Gauss-Markov bias or quantization
(MATLAB has bias instability). Their share of the Allan variance is carried by a stand-in
random walk K_eq added to the walk, K_tot² = K² + K_eq²: with u(τ) the Allan variance of the
terms the format cannot hold, τ₁ the averaging time where u first reaches the ARW line N²/τ
(below it the white noise dominates), K_eq² = max over τ ≥ τ₁ of 3·u(τ)/τ, so that the
stand-in line K_eq²·τ/3 ≥ u(τ) for every τ ≥ τ₁ (for a flat bias-instability floor
(0.664 B)² = 2 ln2/π·B², K_eq = 0.664·B·√(3/τ₁)); it is within a factor 2 of the floor in
ADEV up to τ₂ = 4·τ₁ and above it beyond. Each file's header says so. The accelerometer's bias
instability is handled alike (m/s units).

``--inflate auto``: the factor f on both gyro numbers that makes a discrete Kalman filter that
knows only white noise + random walk (at the exported values, at the rate) consistent on a
record simulated from the full model: the filter estimates the bias of a still gyro from the
mean rate over update windows of 1 sample to 10 s; its normalised innovation squared
(NIS = ν²/S, expectation 1 when the model is right) is averaged per window, and
f = max(1, √(largest mean NIS)): never below 1 (a factor < 1, a scatter of the simulation,
would make the file claim less noise than the model has). Scaling Q and R by f² leaves the
gain unchanged and divides NIS by f², so f makes the worst window consistent. Unmodelled slow
effects (bias instability, Gauss-Markov, temperature) raise NIS at the long windows;
quantization at one sample. The accelerometer's numbers are not inflated by ``auto`` (no
accelerometer model is simulated); an explicit ``--inflate X`` scales them too.

``--inflate measured``: the factor measured on a record with a reference pose topic
(:func:`measured_inflation`, :func:`gyroarray.chain.inflation.inflation_for_export`): the
motion-weighted white density over the model's static N of the exported axis, never below 1,
on the gyro's numbers only; its four lines (levels, reference noise, time offset, held-out
NIS) go into the header.

``--verify`` re-reads the WRITTEN file with the consumer's parser semantics (:func:`read_back`:
``cv2.FileStorage`` for the OpenCV formats, a YAML loader for Kalibr, the pinned required keys
and types of :data:`REQUIRED`, a ``name = value;`` parser for MATLAB), converts back to N, K
(and the accelerometer's) and refuses a missing or misspelled key, a wrong type (a float
``IMU.Frequency``), a density or walk <= 0, and a value that is not the model's. Then, without
a record, it simulates a record from the numbers read back as the tool reads them (its
convention and rate), re-identifies N and K with the Allan noise fit
(:func:`gyroarray.analysis.allan.allan_analysis`) and checks (a) the round trip: each
re-identified value within 3σ of the value the file means (N with the white-like term
K²dt²/6 of a walk sampled at the rate, :func:`sampled_walk_n2`); (b) the model's Allan deviation
(all its noise terms, times the inflation) inside the simulated record's 95 % interval at
90 % of the averaging times or more. With a record (``--record MEAS``,
:func:`record_check`) the file's ADEV as the tool reads it (N²/τ + K²τ/3, B's floor for MATLAB)
is compared τ by τ with the measurement's ADEV and its 95 % interval over its still parts: where
the file falls below the interval it fails, naming each τ and the ratio. The interval it fails
against is family-wise (each of the n τ at 1 - 0.05/n, Bonferroni), so that a file holding the
record's true white + walk fails on at most 5 % of records; the per-τ 95 % count is reported. A file failing any
check is flagged.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
from scipy import optimize, signal

from gyroarray import __version__
from gyroarray.analysis.allan import allan_analysis, confidence_interval
from gyroarray.analysis.noise_fit import TERM_CONSTANTS, term_basis
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.physics import flicker_noise, gauss_markov_avar
from gyroarray.effects import did_you_mean
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.sim.effects import simulate_readings
from gyroarray.sim.lab import lab_temperature
from gyroarray.effects.names import ARW, BIAS_INSTABILITY, GAUSS_MARKOV, QUANTIZATION, RATE_RAMP, RRW, TEMPERATURE_BIAS

__all__ = ["FORMATS", "SUFFIXES", "REQUIRED", "MAX_SIM_SAMPLES", "GyroNoise", "AccelChoice", "StandIn", "ReadBack",
           "Export", "gyro_noise", "choose_axis", "choose_accel", "model_gyros", "stand_in", "check_exportable",
           "orbslam3_frequency", "sampled_walk_n2", "exported_values", "tool_discrete", "render", "read_back",
           "simulate_model", "window_nis", "auto_inflation", "verify_export", "record_check", "verify_file",
           "build_export", "measured_inflation", "export_noise"]

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

#: z of the one-sided 95 % upper bound a file gets for a walk the record did not resolve (the
#: fit held it at 0 with a 1σ beside it): K_up = 1.645 σ. Every consumer needs a walk > 0 (Kalibr's
#: reader refuses 0; the others freeze the bias at its first value), and the bound is the largest
#: walk the record allows at 95 %: a filter tuned with it is conservative, never overconfident.
WALK_BOUND_Z = 1.6448536269514722


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
    k_sigma_rad_s_rt_s : float
        The fit's 1σ of a walk it held at 0 [rad/s/√s], when ``k_rad_s_rt_s`` is its upper bound
        (:func:`gyro_noise`); 0 when K is an estimate (or no σ is known).
    """

    gyro: int
    n_rad_rt_s: float
    k_rad_s_rt_s: float
    b_rad_s: float = 0.0
    q_rad: float = 0.0
    r_rad_s2: float = 0.0
    gm: tuple = ()
    entries: tuple = field(default=(), repr=False)
    k_sigma_rad_s_rt_s: float = 0.0

    @property
    def walk_is_bound(self) -> bool:
        """True when ``k_rad_s_rt_s`` is the upper bound :data:`WALK_BOUND_Z` σ of a walk the
        fit did not resolve (σ [rad/s/√s] in ``k_sigma_rad_s_rt_s``), not an estimate."""
        return self.k_sigma_rad_s_rt_s > 0

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
    k, b = si(RRW, "k_rad_s_rt_s"), si(BIAS_INSTABILITY, "b_rad_s")
    k_sigma = 0.0
    if RRW in chosen and not k > 0 and not b > 0 and not gm:
        sig = chosen[RRW].sigma.get("k_deg_h_rt_h")
        if isinstance(sig, (int, float)) and math.isfinite(sig) and sig > 0:
            # a walk the fit held at 0 (not resolved by its record): its upper bound, said so
            k_sigma = float(units.rrw_deg_h_rt_h_to_rad_s_rt_s(sig))
            k = WALK_BOUND_Z * k_sigma
    return GyroNoise(gyro=gyro, n_rad_rt_s=si(ARW, "n_rad_rt_s"), k_rad_s_rt_s=k,
                     b_rad_s=b, q_rad=si(QUANTIZATION, "q_rad"),
                     r_rad_s2=si(RATE_RAMP, "r_rad_s2"), gm=gm,
                     entries=tuple(chosen.values()), k_sigma_rad_s_rt_s=k_sigma)


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
        bound = [str(n.gyro) for n in noises if n.walk_is_bound]
        what = (f"the mean of the model's {m} gyros (ARW, RRW, bias instability)"
                + (f"; left out: {', '.join(dropped)}" if dropped else "")
                + (f"; the RRW of gyro(s) {', '.join(bound)} is its 95 % upper bound (not resolved)"
                   if bound else ""))
    else:
        raise InputError(f"--axis must be worst, mean or a gyro number, got {axis!r}")
    table = [{"gyro": n.gyro, "n_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(n.n_rad_rt_s)),
              "k_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(n.k_rad_s_rt_s)),
              "k_is_upper_bound": n.walk_is_bound,
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



#: The fields each consumer requires, as its own reader reads them (the sources and commits are
#: named in tests/test_export_consumers.py): Kalibr ``ImuParameters`` (a missing key: "Field ...
#: missing"; <= 0 refused), OpenVINS ``VioManagerOptions.h`` + ``ROS1Visualizer.cpp`` under
#: ``imu0`` (a missing key: "unable to parse all parameters"), VINS-Fusion ``parameters.cpp``
#: (a missing key reads silently as 0.0), ORB-SLAM3 ``Tracking::ParseIMUParamFile`` (isInt /
#: isReal), MATLAB (the snippet's properties and ``sampleRate``).
REQUIRED = {
    "kalibr": ("rostopic", "update_rate", "accelerometer_noise_density", "accelerometer_random_walk",
               "gyroscope_noise_density", "gyroscope_random_walk"),
    "openvins": ("accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
                 "gyroscope_random_walk", "Tw", "Ta", "R_IMUtoACC", "R_IMUtoGYRO", "Tg", "rostopic"),
    "vins": ("acc_n", "gyr_n", "acc_w", "gyr_w"),
    "orbslam3": ("IMU.NoiseGyro", "IMU.NoiseAcc", "IMU.GyroWalk", "IMU.AccWalk", "IMU.Frequency"),
    "matlab": ("gyro.NoiseDensity", "gyro.RandomWalk", "accel.NoiseDensity", "accel.RandomWalk", "sampleRate"),
}

#: The field of each quantity, by format: gn/gk the gyro's white/walk, an/ak the accelerometer's,
#: gb/ab the bias instabilities (MATLAB only), rate the rate field (None: the format has none).
FIELDS: dict[str, dict[str, str | None]] = {
    "kalibr": {"gn": "gyroscope_noise_density", "gk": "gyroscope_random_walk",
               "an": "accelerometer_noise_density", "ak": "accelerometer_random_walk", "rate": "update_rate"},
    "openvins": {"gn": "gyroscope_noise_density", "gk": "gyroscope_random_walk",
                 "an": "accelerometer_noise_density", "ak": "accelerometer_random_walk", "rate": "update_rate"},
    "vins": {"gn": "gyr_n", "gk": "gyr_w", "an": "acc_n", "ak": "acc_w", "rate": None},
    "orbslam3": {"gn": "IMU.NoiseGyro", "gk": "IMU.GyroWalk", "an": "IMU.NoiseAcc", "ak": "IMU.AccWalk",
                 "rate": "IMU.Frequency"},
    "matlab": {"gn": "NoiseDensity", "gk": "RandomWalk", "gb": "BiasInstability", "an": "AccelNoiseDensity",
               "ak": "AccelRandomWalk", "ab": "AccelBiasInstability", "rate": "SampleRate"},
}

#: MATLAB: the value names of :func:`exported_values` -> the snippet's ``name = value;`` names.
MATLAB_NAMES = {"NoiseDensity": "gyro.NoiseDensity", "RandomWalk": "gyro.RandomWalk",
                "BiasInstability": "gyro.BiasInstability", "AccelNoiseDensity": "accel.NoiseDensity",
                "AccelRandomWalk": "accel.RandomWalk", "AccelBiasInstability": "accel.BiasInstability",
                "SampleRate": "sampleRate"}

#: Default IMU topic of Kalibr/OpenVINS files when the model names none and --topic is not given.
DEFAULT_TOPIC = "/imu0"

#: Largest relative change ORB-SLAM3's integer IMU.Frequency may make to the rate (1 %: the
#: discretised noise moves by √(f/R), 0.5 % at most); beyond it the export is refused.
MAX_FREQUENCY_ROUNDING = 0.01

#: Relative agreement of a value read back with the value meant (6 significant digits written).
READ_BACK_RTOL = 2e-6

#: The MATLAB snippet's comment where the model has no bias instability: the property is left
#: unset rather than written 0. gyroparams/accelparams default BiasInstability to 0, so an
#: imuSensor built from the snippet simulates none either way; writing ``= 0`` would state that
#: the sensor has none, which the model does not know (the fit did not resolve one).
MATLAB_NO_BI = ("the model has no bias-instability term (not fitted or not resolved by its record: "
                "`gyroarray fit --add bias_instability`); gyroparams' default (0) then applies, so "
                "imuSensor simulates none: that is the model's lack of a B, not a measured B = 0")

_FIT_HINT = ("fit it with `gyroarray fit --out` on a record with acc_x, acc_y, acc_z columns (or add an "
             "[accelerometer] table to the model)")


@dataclass(frozen=True)
class AccelChoice:
    """The accelerometer's noise a file is written with, in SI.

    Parameters
    ----------
    n_m_s2_rt_hz : float or None
        Velocity random walk N_a [m/s²/√Hz = m/s/√s] (None: not in the model).
    k_m_s3_rt_hz : float or None
        Acceleration random walk K_a [m/s³/√Hz = m/s²/√s] (None: not in the model).
    b_m_s2 : float or None
        Bias instability B [m/s²] (None: not in the model).
    what : str
        Which axis (or rule) the numbers are, or why there are none.
    table : list of dict
        Every axis's terms in datasheet units (m/s/√h, m/s²/√h, mg; None where absent).
    why_missing : str
        Why a missing term is missing ("" when none is).
    partial : dict
        By model key (``n_m_s_rt_h``, ``k_m_s2_rt_h``, ``b_mg``) of a term some axes lack: which
        axes the number is from and why the others lack it (one line).
    """

    n_m_s2_rt_hz: float | None
    k_m_s3_rt_hz: float | None
    b_m_s2: float | None
    what: str
    table: list = field(default_factory=list)
    why_missing: str = ""
    partial: dict = field(default_factory=dict)

    def as_noise(self) -> "GyroNoise":
        """The same IEEE algebra as a gyro's (white, walk, flicker floor) in m/s units, for
        :func:`stand_in` (0 where a term is absent)."""
        return GyroNoise(gyro=0, n_rad_rt_s=self.n_m_s2_rt_hz or 0.0, k_rad_s_rt_s=self.k_m_s3_rt_hz or 0.0,
                         b_rad_s=self.b_m_s2 or 0.0)


#: The accelerometer terms of the model's ``[accelerometer]`` table: (name in text, datasheet unit).
_ACC_TEXT = {"n_m_s_rt_h": ("velocity random walk", "m/s/√h"),
             "k_m_s2_rt_h": ("acceleration random walk", "m/s²/√h"), "b_mg": ("bias instability", "mg")}


def _hours(seconds: float) -> str:
    return f"{seconds / units.S_PER_H:.3g} h"


def accel_axis_cause(acc, key: str, axis: str) -> str:
    """Why the model's ``[accelerometer]`` table has no ``key`` on ``axis``: the fit's estimate,
    its z and the record length it was fitted on, and how long a record ``plan --sensor acc``
    predicts would resolve it; for a table without that record (written before), its notes."""
    name, unit = _ACC_TEXT[key]
    entry = (acc.unresolved.get(key) or {}).get(axis)
    if entry is None:
        notes = "; ".join(acc.notes)
        return (f"{name} not resolved on acc_{axis} by the record the model was fitted on"
                + (f" ({notes})" if notes else "") + ": a longer record would resolve it "
                "(refit, then `gyroarray plan --sensor acc --model M.toml`)")
    est, sig = entry.get("estimate", 0.0), entry.get("sigma")
    on = f" over {_hours(acc.record_s)} of record" if acc.record_s else ""
    if est > 0 and sig:
        found = f"{name} on acc_{axis} is {est:.3g} ± {sig:.2g} {unit} (z = {est / sig:.2f} < 2){on}"
    else:
        found = f"{entry.get('why') or name + ' held at 0 by the fit'}{on}"
    need = entry.get("resolve_s")
    if need is None:
        plan = ("; no record length can be planned from a zero estimate (a record several times "
                "longer would show whether the term is there)" if not est > 0 else "")
    elif acc.record_s and need <= acc.record_s:
        plan = (f"; plan --sensor acc predicts {_hours(need)} would resolve it, no more than the record "
                "had: the record scatters more than white + walk + floor predict (more record, or a "
                "quieter one)")
    else:
        plan = f"; a record of about {_hours(need)} would resolve it (plan --sensor acc, z >= 2)"
    return "not resolved, so left out: " + found + plan


def choose_accel(model: NoiseModel, axis: str | int) -> AccelChoice:
    """The accelerometer's numbers for ``axis``: ``"worst"`` the largest value of each term over
    the axes (as allan_variance_ros), ``"mean"`` the mean per term (as imu_utils); a gyro number
    (``--axis K`` names a gyro, not an accelerometer axis): the worst, said so. A term some axes
    lack (not resolved there) is taken from the axes that have it, and ``partial`` says which
    and why; a term no axis has is missing, and ``why_missing`` gives the cause (no table: no
    acc columns; a term not resolved: its z, the record length, the length that would resolve it)."""
    acc = model.accelerometer
    if acc is None:
        return AccelChoice(None, None, None, "none: the model has no [accelerometer] table",
                           why_missing=f"the model has no [accelerometer] table; {_FIT_HINT}")
    conv = {"n_m_s_rt_h": units.vrw_m_s_rt_h_to_si, "k_m_s2_rt_h": units.accel_rw_m_s2_rt_h_to_si,
            "b_mg": units.mg_to_m_s2}
    table = [{"axis": a, **{key: (None if getattr(acc, key) is None or getattr(acc, key)[i] is None
                                  else float(getattr(acc, key)[i])) for key in conv}}
             for i, a in enumerate(acc.axes)]
    rule = axis if axis in ("worst", "mean") else "worst"
    pick = max if rule == "worst" else (lambda v: sum(v) / len(v))
    out, partial = {}, {}
    lack = acc.missing_axes
    for key, f in conv.items():
        v = [x for x in (getattr(acc, key) or ()) if x is not None]
        out[key] = float(f(pick(v))) if v else None
        if v and key in lack:
            have = [a for a in acc.axes if a not in lack[key]]
            partial[key] = (f"{_ACC_TEXT[key][0]} from acc_{', acc_'.join(have)} only ({rule}); "
                            + "; ".join(f"acc_{a}: {accel_axis_cause(acc, key, a)}" for a in lack[key]))
    axes = ", ".join(acc.axes)
    if rule == "worst":
        what = (f"the worst of the accelerometer's axes {axes} (the largest value of each term)"
                + ("; --axis names a gyro, so the accelerometer takes the worst" if axis not in ("worst", "mean")
                   else ""))
    else:
        what = f"the mean of the accelerometer's axes {axes} (each term)"
    for key in ("n_m_s_rt_h", "k_m_s2_rt_h"):
        # a term no axis resolved, held at 0 by the fit with a 1σ on every axis: each axis's one-
        # sided 95 % upper bound (estimate + WALK_BOUND_Z σ), the rule's pick of them, said so
        entries = [(acc.unresolved.get(key) or {}).get(a) or {} for a in acc.axes]
        sig = [e.get("sigma") for e in entries]
        if out[key] is not None or not all(isinstance(x, (int, float)) and math.isfinite(x) and x > 0
                                           for x in sig):
            continue
        up = [max(float(e.get("estimate") or 0.0), 0.0) + WALK_BOUND_Z * float(cast(float, x))
              for e, x in zip(entries, sig)]
        out[key] = float(conv[key](pick(up)))
        name, unit = _ACC_TEXT[key]
        partial[key] = (f"{name}: NOT RESOLVED on any axis by the record the model was fitted on; the file "
                        f"holds the one-sided 95 % upper bound (estimate + {WALK_BOUND_Z:.4g}σ, {rule} of "
                        + ", ".join(f"acc_{a} {u:.4g}" for a, u in zip(acc.axes, up))
                        + f" {unit}), the largest the record allows: conservative, never a 0; "
                        + "; ".join(f"acc_{a}: {accel_axis_cause(acc, key, a)}" for a in acc.axes))
    missing = [key for key in ("n_m_s_rt_h", "k_m_s2_rt_h") if out[key] is None]
    why = ""
    if missing:
        causes = []
        for key in missing:
            if key in acc.unresolved:
                causes += [f"acc_{a}: {accel_axis_cause(acc, key, a)}" for a in acc.axes]
            else:                       # a table written before it said why per axis: its notes
                causes.append(accel_axis_cause(acc, key, ", acc_".join(acc.axes)))
        why = ("the model's [accelerometer] table has no " + " or ".join(missing) + " on any axis: "
               + "; ".join(causes))
    return AccelChoice(out["n_m_s_rt_h"], out["k_m_s2_rt_h"], out["b_mg"], what, table, why, partial)


def accel_walk(accel: AccelChoice, rate_hz: float, *, keeps_b: bool) -> tuple[float | None, StandIn]:
    """The accelerometer's walk the file gets [m/s³/√Hz] (K_a with the stand-in for its bias
    instability in quadrature, as the gyro's) and the stand-in; None when there is neither a
    walk nor a bias instability, or no white noise to place the stand-in."""
    none = StandIn(0.0, math.nan, math.nan, ())
    if accel.n_m_s2_rt_hz is None:
        return accel.k_m_s3_rt_hz, none
    si = stand_in(accel.as_noise(), rate_hz, keeps_b=keeps_b) if accel.b_m_s2 else none
    if accel.k_m_s3_rt_hz is None and not si.covers:
        return None, si
    return math.hypot(accel.k_m_s3_rt_hz or 0.0, si.k_eq_rad_s_rt_s), si


def orbslam3_frequency(rate_hz: float) -> tuple[int, str]:
    """ORB-SLAM3's ``IMU.Frequency``: an integer (``Tracking::ParseIMUParamFile`` refuses any other
    node type), the rate rounded when within :data:`MAX_FREQUENCY_ROUNDING`; and a note ("" when
    the rate is an integer).

    Raises
    ------
    InputError
        A rate below 1 Hz or further than 1 % from an integer.
    """
    f = int(round(rate_hz))
    if f < 1 or abs(f - rate_hz) > MAX_FREQUENCY_ROUNDING * rate_hz:
        raise InputError(f"ORB-SLAM3 reads IMU.Frequency as an integer (Tracking::ParseIMUParamFile: "
                         f"node.isInt()), and --rate-hz {rate_hz:g} is {abs(f - rate_hz) / rate_hz:.2%} from "
                         f"the nearest one, {f} (at most {MAX_FREQUENCY_ROUNDING:.0%} is rounded): give the "
                         "rate as an integer number of Hz the tool will run at")
    if f == rate_hz:
        return f, ""
    return f, (f"IMU.Frequency: --rate-hz {rate_hz:g} rounded to {f} (ORB-SLAM3 reads an integer); its "
               f"discretised noise is then √({f}/{rate_hz:g}) = {math.sqrt(f / rate_hz):.5f} × the one at "
               f"{rate_hz:g} Hz")


def exported_values(noise: GyroNoise, fmt: str, rate_hz: float, inflate: float = 1.0,
                    accel: AccelChoice | None = None, accel_inflate: float | None = None) -> dict:
    """The numbers of the file, by field name, in the format's units.

    Parameters
    ----------
    noise : GyroNoise
    fmt : str
        One of :data:`FORMATS`.
    rate_hz : float
        The rate the tool runs the IMU at [Hz].
    inflate : float
        Factor on the gyro's white and walk numbers (and B for MATLAB) [-].
    accel : AccelChoice, optional
        The accelerometer's numbers; a term it lacks is left out (never a 0).
    accel_inflate : float, optional
        Factor on the accelerometer's numbers [-] (default ``inflate``).

    Returns
    -------
    dict
        Field -> value (e.g. ``gyroscope_noise_density`` [rad/s/√Hz]); VINS-Fusion's per-sample
        values carry the √2 of its mid-point covariance (module docstring).
    """
    keeps_b = fmt == "matlab"
    k_eq = stand_in(noise, rate_hz, keeps_b=keeps_b).k_eq_rad_s_rt_s
    n = inflate * noise.n_rad_rt_s
    k = inflate * math.sqrt(noise.k_rad_s_rt_s ** 2 + k_eq ** 2)
    fa = inflate if accel_inflate is None else accel_inflate
    an = ak = ab = None
    if accel is not None:
        walk, _ = accel_walk(accel, rate_hz, keeps_b=keeps_b)
        an = None if accel.n_m_s2_rt_hz is None else fa * accel.n_m_s2_rt_hz
        ak = None if walk is None else fa * walk
        ab = None if accel.b_m_s2 is None else fa * accel.b_m_s2
    names = FIELDS.get(fmt)
    if names is None:
        raise InputError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
    if fmt == "vins":                                # per sample: √(2R) on the white, √R on the walk
        white, walk_f = math.sqrt(2.0 * rate_hz), math.sqrt(rate_hz)
    else:
        white = walk_f = 1.0
    out: dict = {}
    if an is not None:
        out[names["an"]] = an * white
    if ak is not None:
        out[names["ak"]] = ak * walk_f
    out[names["gn"]] = n * white
    out[names["gk"]] = k * walk_f
    if fmt == "matlab":
        if noise.b_rad_s > 0:        # else left out: gyroparams' default 0 would claim "no BI"
            out["BiasInstability"] = inflate * noise.b_rad_s
        if ab is not None:
            out["AccelBiasInstability"] = ab
    if fmt == "orbslam3":
        out["IMU.Frequency"] = orbslam3_frequency(rate_hz)[0]
    elif names["rate"] is not None:
        out[names["rate"]] = rate_hz
    return out


def tool_discrete(fmt: str, values: dict, rate_hz: float, *, sensor: str = "g") -> tuple[float, float]:
    """How the tool reads the file: one sample's white-noise σ [rad/s] and one step's bias
    increment σ [rad/s] at ``rate_hz`` (``sensor="a"``: the accelerometer's, [m/s²])."""
    names = FIELDS[fmt]
    white, walk = values[names[sensor + "n"]], values[names[sensor + "k"]]
    root = math.sqrt(rate_hz)
    if fmt == "vins":                               # GYR_N²·dt²/2 per step: σ_d = GYR_N/√2; GYR_W·dt
        return white / math.sqrt(2.0), walk / rate_hz
    if fmt == "orbslam3":                           # Ng*sf, Ngw/sf (Tracking.cc)
        root = math.sqrt(values.get("IMU.Frequency", rate_hz))
    return white * root, walk / root


def to_continuous(fmt: str, values: dict, rate_hz: float) -> dict:
    """The file's numbers as continuous densities in SI: ``gyro_n`` [rad/s/√Hz], ``gyro_k``
    [rad/s²/√Hz], ``acc_n`` [m/s²/√Hz], ``acc_k`` [m/s³/√Hz], ``gyro_b`` [rad/s], ``acc_b``
    [m/s²] (MATLAB); None where the file has no such field."""
    names = FIELDS[fmt]
    if fmt == "vins":
        wf, kf = 1.0 / math.sqrt(2.0 * rate_hz), 1.0 / math.sqrt(rate_hz)
    else:
        wf = kf = 1.0
    out = {}
    for key, role, f in (("gyro_n", "gn", wf), ("gyro_k", "gk", kf), ("acc_n", "an", wf), ("acc_k", "ak", kf),
                         ("gyro_b", "gb", 1.0), ("acc_b", "ab", 1.0)):
        name = names.get(role)
        out[key] = None if name is None or values.get(name) is None else float(values[name]) * f
    return out


def _num(x: float) -> str:
    return f"{x:.6e}"


def _topic_line(topic: str, topic_why: str) -> str:
    return f"rostopic: {topic} ({topic_why})"


def _header(noise: GyroNoise, fmt: str, rate_hz: float, inflate: float, why: str,
            source: str, comment: str, axis: tuple | None = None, accel: AccelChoice | None = None,
            topic: tuple | None = None, accel_inflate: float | None = None,
            measured_lines: list[str] | None = None) -> list[str]:
    si = stand_in(noise, rate_hz, keeps_b=fmt == "matlab")
    n_dh = units.arw_rad_rt_s_to_deg_rt_h(noise.n_rad_rt_s)
    k_dh = units.rrw_rad_s_rt_s_to_deg_h_rt_h(noise.k_rad_s_rt_s)
    discrete = fmt == "vins"
    lines = [
        f"gyroarray {__version__} export --format {fmt}: "
        + (f"gyro {noise.gyro}" if axis is None else axis[0]) + f" of {source}",
        f"model: ARW N = {n_dh:.6g} deg/√h = {noise.n_rad_rt_s:.6e} rad/s/√Hz; "
        f"RRW K = {k_dh:.6g} deg/h/√h = {noise.k_rad_s_rt_s:.6e} rad/s²/√Hz",
        ("convention: DISCRETE-time, per sample at the rate below: gyr_n = √2·σ_c·√rate [rad/s] "
         "(√2 × one sample's white-noise σ: integration_base.h's mid-point covariance puts GYR_N² "
         "with the weight 0.5·dt on each of a step's two readings, GYR_N²·dt²/2 per step, against "
         "σ_c²·dt of the continuous noise), gyr_w = σ_w·√rate [rad/s²] (V = dt on GYR_W: bias "
         "increment per step gyr_w·dt = σ_w·√dt); acc_n, acc_w alike [m/s², m/s³]"
         if discrete else
         "convention: CONTINUOUS-time densities of a TWO-sided white PSD (σ_c = IEEE ARW N, "
         "ADEV = N/√τ; σ_w = IEEE RRW K, ADEV = K·√(τ/3); the accelerometer's: VRW and acceleration "
         "random walk); the tool discretises at its rate: σ_d = σ_c·√rate, bias step σ_w/√rate"),
        f"rate assumed: {rate_hz:g} Hz" + (" (the discrete values are wrong at any other rate)"
                                          if discrete or fmt == "orbslam3" else ""),
    ]
    if fmt == "orbslam3":
        lines.append("ORB-SLAM3 multiplies NoiseGyro/NoiseAcc by √IMU.Frequency and divides "
                     "GyroWalk/AccWalk by it (Tracking.cc: IMU::Calib(Tbc, Ng*sf, Na*sf, Ngw/sf, "
                     "Naw/sf)): keep IMU.Frequency the true rate; it is an integer (ParseIMUParamFile)")
        note = orbslam3_frequency(rate_hz)[1]
        if note:
            lines.append(note)
        lines.append("merge these keys into your ORB-SLAM3 settings file: IMU.T_b_c1 (camera-IMU "
                     "extrinsics) is the camera calibration's, not gyroarray's")
    if fmt == "vins":
        lines.append("merge these keys into your VINS-Fusion config (imu_topic, g_norm and the "
                     "extrinsics are not gyroarray's); a key missing there is read as 0.0 silently")
    if topic is not None and fmt in ("kalibr", "openvins"):
        lines.append(_topic_line(*topic))
    if fmt == "openvins":
        lines.append("intrinsics: Tw, Ta, R_IMUtoACC, R_IMUtoGYRO are identity and Tg zeros because "
                     "gyroarray does not know this IMU's intrinsics (scale, misalignment, "
                     "g-sensitivity); they are OpenVINS' defaults (VioManagerOptions.h) and required "
                     "keys: replace them with a calibration's (e.g. Kalibr's imu model) if you have one; "
                     "T_i_b identity: the body frame is the IMU's")
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
    elif noise.walk_is_bound:
        sig_dh = units.rrw_rad_s_rt_s_to_deg_h_rt_h(noise.k_sigma_rad_s_rt_s)
        lines.append(f"walk: NOT RESOLVED by the record the model was fitted on (RRW K = 0 ± {sig_dh:.4g} "
                     f"deg/h/√h, 1σ): the file holds its one-sided 95 % upper bound K = "
                     f"{WALK_BOUND_Z:.4g}σ = {k_dh:.4g} deg/h/√h, the largest walk that record allows, so "
                     f"a filter tuned with it is conservative (a walk of 0 is refused by Kalibr's reader "
                     f"and freezes the bias in the others); a longer still record resolves it "
                     f"(`gyroarray plan`)")
    else:
        lines.append("bias instability: none in the model; the walk is the fitted RRW")
    lost = [e.effect for e in noise.entries if e.effect in (QUANTIZATION, RATE_RAMP,
                                                            TEMPERATURE_BIAS)]
    if lost:
        lines.append(f"not representable here: {', '.join(lost)} (see --inflate auto)")
    if axis is not None and len(axis[1]) > 1:
        lines.append("every gyro of the model (ARW deg/√h, RRW deg/h/√h, BI deg/h): " + "; ".join(
            f"{g['gyro']}: {g['n_deg_rt_h']:.4g}, {'≤ ' if g.get('k_is_upper_bound') else ''}"
            f"{g['k_deg_h_rt_h']:.4g}, {g['b_deg_h']:.4g}" for g in axis[1])
            + " (--axis worst|mean|K chooses)")
    lines.append(f"inflation: ×{inflate:.4g} on the gyro's numbers ({why})"
                 + ("" if accel is None or accel.n_m_s2_rt_hz is None else
                    f"; ×{inflate if accel_inflate is None else accel_inflate:.4g} on the accelerometer's"))
    lines += list(measured_lines or ())
    lines += _accel_header(accel, fmt, rate_hz)
    return [f"{comment} {line}" for line in lines]


def _accel_header(accel: AccelChoice | None, fmt: str, rate_hz: float) -> list[str]:
    """The header's accelerometer lines: which axis, the terms, the bias instability's mapping,
    and each required field that is missing, with why."""
    names = FIELDS[fmt]
    file_name = (lambda v: MATLAB_NAMES[v]) if fmt == "matlab" else (lambda v: v)
    if accel is None or accel.n_m_s2_rt_hz is None and accel.k_m_s3_rt_hz is None:
        why = accel.why_missing if accel is not None else f"no accelerometer given; {_FIT_HINT}"
        return [f"{file_name(names['an'])}: MISSING — {why}",
                f"{file_name(names['ak'])}: MISSING — {why}",
                "the file is incomplete: its consumer needs both (never written as 0)"]
    out = [f"accelerometer: {accel.what}; per axis (VRW m/s/√h, acc. RW m/s²/√h, BI mg): " + "; ".join(
        f"{r['axis']}: {_opt(r['n_m_s_rt_h'])}, {_opt(r['k_m_s2_rt_h'])}, {_opt(r['b_mg'])}" for r in accel.table)]
    walk, si = accel_walk(accel, rate_hz, keeps_b=fmt == "matlab")
    if si.covers:
        out.append(f"accelerometer bias instability: not in this format; a stand-in random walk "
                   f"K_eq = {si.k_eq_rad_s_rt_s:.6e} m/s³/√Hz is added in quadrature to the acceleration "
                   f"random walk (bounds the floor for τ >= {si.tau1_s:.4g} s, within ×2 up to {si.tau2_s:.4g} s)")
    elif accel.b_m_s2 and fmt == "matlab":
        out.append("accelerometer bias instability: accel.BiasInstability = B [m/s²]")
    elif accel.b_m_s2 and accel.n_m_s2_rt_hz is None:
        out.append("accelerometer bias instability: dropped (no VRW to place its stand-in walk)")
    for key, line in accel.partial.items():
        out.append(f"accelerometer {line}")
    if accel.k_m_s3_rt_hz is None and walk is not None and accel.why_missing:
        out.append(f"{file_name(names['ak'])}: the bias-instability stand-in only, no acceleration random "
                   f"walk — {accel.why_missing}")
    for role, value in (("an", accel.n_m_s2_rt_hz), ("ak", walk)):
        if value is None:
            out.append(f"{file_name(names[role])}: MISSING — {accel.why_missing}")
    if accel.n_m_s2_rt_hz is None or walk is None:
        out.append("the file is incomplete: its consumer needs every accelerometer field (never written as 0)")
    return out


def _opt(x) -> str:
    return "—" if x is None else f"{x:.4g}"


def missing_fields(fmt: str, values: dict) -> list[str]:
    """The consumer's required fields (:data:`REQUIRED`) the values leave out."""
    have = {MATLAB_NAMES.get(k, k) for k in values} if fmt == "matlab" else set(values)
    return [f for f in REQUIRED[fmt] if f not in have and f not in ("rostopic", "Tw", "Ta", "R_IMUtoACC",
                                                                      "R_IMUtoGYRO", "Tg")]


_EYE3 = ["[1.0, 0.0, 0.0]", "[0.0, 1.0, 0.0]", "[0.0, 0.0, 1.0]"]
_ZERO3 = ["[0.0, 0.0, 0.0]"] * 3


def render(noise: GyroNoise, fmt: str, rate_hz: float, *, inflate: float = 1.0,
           why: str = "none asked", source: str = "MODEL.toml", axis: tuple | None = None,
           accel: AccelChoice | None = None, topic: tuple | None = None,
           accel_inflate: float | None = None, measured_lines: list[str] | None = None) -> str:
    """The file's text: the comment header, then the fields.

    ``topic``: (topic, why) for Kalibr/OpenVINS (default :data:`DEFAULT_TOPIC`, said so). A
    missing accelerometer term leaves its key out; the header says which and why.
    ``measured_lines``: the lines of a measured inflation (:func:`measured_inflation`), put
    after the inflation line as comments.
    """
    if topic is None:
        topic = (DEFAULT_TOPIC, "the default: the model names no topic; --topic T sets it")
    v = exported_values(noise, fmt, rate_hz, inflate, accel, accel_inflate)
    names = FIELDS[fmt]
    comment = "%" if fmt == "matlab" else "#"
    head = _header(noise, fmt, rate_hz, inflate, why, source, comment, axis, accel, topic, accel_inflate,
                   measured_lines)

    def line(role, unit, indent=""):
        key = names[role]
        return [] if key not in v else [f"{indent}{key}: {_num(v[key])}   # {unit}"]
    if fmt == "matlab":
        body = ["gyro = gyroparams;"]
        for key, unit in (("NoiseDensity", "(rad/s)/sqrt(Hz)"), ("RandomWalk", "(rad/s)*sqrt(Hz)"),
                          ("BiasInstability", "rad/s"), ("AccelNoiseDensity", "(m/s^2)/sqrt(Hz)"),
                          ("AccelRandomWalk", "(m/s^2)*sqrt(Hz)"), ("AccelBiasInstability", "m/s^2")):
            if key == "AccelNoiseDensity":
                body.append("accel = accelparams;")
            if key in v:
                body.append(f"{MATLAB_NAMES[key]} = {_num(v[key])};   % {unit}")
            elif key == "BiasInstability":
                body.append(f"% {MATLAB_NAMES[key]} not set: {MATLAB_NO_BI}")
            elif key == "AccelBiasInstability" and accel is not None and accel.n_m_s2_rt_hz is not None:
                body.append(f"% {MATLAB_NAMES[key]} not set: the model's [accelerometer] table has no "
                            "bias instability on any axis (not resolved by its record); accelparams' "
                            "default (0) then applies: the model's lack of a B, not a measured B = 0")
        body.append(f"sampleRate = {rate_hz!r};   % Hz: imu = imuSensor('accel-gyro', 'SampleRate', "
                    "sampleRate, 'Gyroscope', gyro, 'Accelerometer', accel);")
        return "\n".join(head + body) + "\n"
    head = (["%YAML:1.0"] if fmt in ("openvins", "vins", "orbslam3") else []) + head
    if fmt == "kalibr":
        body = [f"rostopic: {json.dumps(topic[0])}",
                f"update_rate: {rate_hz!r}   # Hz"]
        body += line("an", "[ m / s^2 / sqrt(Hz) ] (continuous)") + line("ak", "[ m / s^3 / sqrt(Hz) ]")
        body += line("gn", "[ rad / s / sqrt(Hz) ] (continuous)") + line("gk", "[ rad / s^2 / sqrt(Hz) ]")
    elif fmt == "openvins":
        eye4 = ["[1.0, 0.0, 0.0, 0.0]", "[0.0, 1.0, 0.0, 0.0]", "[0.0, 0.0, 1.0, 0.0]", "[0.0, 0.0, 0.0, 1.0]"]
        body = ["imu0:", "  T_i_b:"] + [f"    - {r}" for r in eye4]
        body += line("an", "[ m / s^2 / sqrt(Hz) ]", "  ") + line("ak", "[ m / s^3 / sqrt(Hz) ]", "  ")
        body += line("gn", "[ rad / s / sqrt(Hz) ]", "  ") + line("gk", "[ rad / s^2 / sqrt(Hz) ]", "  ")
        body += ['  model: "kalibr"   # the intrinsics below in Kalibr\'s convention (identity: none known)']
        for name, rows in (("Ta", _EYE3), ("R_IMUtoACC", _EYE3), ("Tw", _EYE3), ("R_IMUtoGYRO", _EYE3),
                           ("Tg", _ZERO3)):
            body += [f"  {name}:"] + [f"    - {r}" for r in rows]
        body += [f"  rostopic: {json.dumps(topic[0])}", "  time_offset: 0.0", f"  update_rate: {rate_hz!r}"]
    elif fmt == "vins":
        body = line("an", "accelerometer measurement noise σ [m/s^2], per sample (√2 inside)")
        body += line("gn", "gyroscope measurement noise σ [rad/s], per sample (√2 inside)")
        body += line("ak", "accelerometer bias random walk [m/s^3], per step: increment acc_w·dt")
        body += line("gk", "gyroscope bias random walk [rad/s^2], per step: increment gyr_w·dt")
    else:                                            # orbslam3
        body = line("gn", "rad/s/sqrt(Hz) (continuous)") + line("gk", "rad/s^2/sqrt(Hz)")
        body += line("an", "m/s^2/sqrt(Hz)") + line("ak", "m/s^3/sqrt(Hz)")
        body.append(f"IMU.Frequency: {v['IMU.Frequency']:d}   # Hz, an integer (ParseIMUParamFile: isInt)")
    return "\n".join(head + body) + "\n"


@dataclass(frozen=True)
class ReadBack:
    """A written file as its consumer reads it.

    Parameters
    ----------
    fmt : str
    values : dict
        Field -> number as read, named as :func:`exported_values` names them.
    si : dict
        The numbers as continuous densities in SI (:func:`to_continuous`).
    rate_hz : float or None
        The file's rate field [Hz] (VINS-Fusion has none: the rate asked).
    problems : tuple of str
        What the consumer would refuse or misread (missing or misspelled key, wrong type, a
        density or walk <= 0).
    parser : str
        What read it.
    """

    fmt: str
    values: dict
    si: dict
    rate_hz: float | None
    problems: tuple
    parser: str

    @property
    def passed(self) -> bool:
        return not self.problems


def _opencv_tree(text: str) -> tuple[Any, str]:
    """The OpenCV YAML text as Python objects (int, float, str, list, dict), read by
    ``cv2.FileStorage`` (OpenCV's own YAML reader, what VINS-Fusion, ORB-SLAM3 and OpenVINS use);
    without OpenCV installed, by a YAML loader after the ``%YAML:1.0`` line (the same types)."""
    try:
        import cv2  # deferred: the OpenCV formats' consumer parser, a test dependency
    except ImportError:
        body = re.sub(r"\A%YAML:1\.0[^\n]*\n", "", text)
        return _yaml_load(body), "a YAML loader (OpenCV not installed: pip install opencv-python-headless)"

    def conv(node):
        if node.isMap():
            return {k: conv(node.getNode(k)) for k in node.keys()}
        if node.isSeq():
            return [conv(node.at(i)) for i in range(node.size())]
        if node.isInt():
            return int(node.real())
        if node.isReal():
            return float(node.real())
        if node.isString():
            return node.string()
        return None
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except cv2.error as err:
        raise ValueError(f"OpenCV cannot parse it: {str(err).strip().splitlines()[-1]}") from None
    if not fs.isOpened():
        raise ValueError("OpenCV cannot open it")
    tree = conv(fs.root())
    fs.release()
    return tree, f"cv2.FileStorage (OpenCV {cv2.__version__})"


def _yaml_load(text: str):
    """YAML as Kalibr's reader loads it (PyYAML ``safe_load``; ruamel's safe loader without it)."""
    try:
        # deferred: Kalibr's own loader (PyYAML), only for a re-read
        import yaml  # type: ignore[import-untyped]
        try:
            return yaml.safe_load(text)
        except yaml.YAMLError as err:
            raise ValueError(f"not YAML: {str(err).splitlines()[0]}") from None
    except ImportError:
        # deferred: the fallback loader (a dependency) only where PyYAML is absent
        from ruamel.yaml import YAML, YAMLError
        try:
            return YAML(typ="safe", pure=True).load(text)
        except YAMLError as err:
            raise ValueError(f"not YAML: {str(err).splitlines()[0]}") from None


_MATLAB_LINE = re.compile(r"^\s*([A-Za-z]\w*(?:\.\w+)?)\s*=\s*(.*?)\s*;?\s*$")
_MATLAB_PROPS = ("NoiseDensity", "RandomWalk", "BiasInstability", "MeasurementRange", "Resolution",
                 "ConstantBias", "AxesMisalignment", "TemperatureBias", "TemperatureScaleFactor",
                 "AccelerationBias", "NoiseType", "BiasInstabilityCoefficients")


def _matlab_tree(text: str) -> dict:
    """``name = value;`` lines of a MATLAB snippet (comments after ``%``): numbers as float, the
    constructors (``gyroparams``) as their name."""
    out: dict = {}
    for line in text.splitlines():
        m = _MATLAB_LINE.match(line.split("%", 1)[0])
        if not m:
            continue
        name, value = m.group(1), m.group(2)
        try:
            out[name] = float(value)
        except ValueError:
            out[name] = value
    return out


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def read_back(text: str, fmt: str, rate_hz: float | None = None) -> ReadBack:
    """Read a written file as its consumer does (module docstring) and convert it back.

    Parameters
    ----------
    text : str
        The file's content.
    fmt : str
        One of :data:`FORMATS`.
    rate_hz : float, optional
        The rate the tool runs at [Hz] (VINS-Fusion's file has none; the others are checked
        against it).

    Returns
    -------
    ReadBack
    """
    problems: list[str] = []
    names = FIELDS[fmt]
    try:
        if fmt == "kalibr":
            tree, parser = _yaml_load(text), "yaml.safe_load (Kalibr's ConfigReader)"
        elif fmt == "matlab":
            tree, parser = _matlab_tree(text), "name = value; lines (MATLAB)"
        else:
            tree, parser = _opencv_tree(text)
    except ValueError as err:
        return ReadBack(fmt, {}, to_continuous(fmt, {}, rate_hz or 1.0), None, (str(err),), fmt)
    if fmt == "openvins":
        if not isinstance(tree, dict) or not isinstance(tree.get("imu0"), dict):
            close = did_you_mean("imu0", list(tree) if isinstance(tree, dict) else [])
            return ReadBack(fmt, {}, to_continuous(fmt, {}, rate_hz or 1.0), None,
                            (f"no imu0 map: OpenVINS reads every IMU key under imu0{close}",), parser)
        node = tree["imu0"]
    else:
        node = tree if isinstance(tree, dict) else {}
        if not isinstance(tree, dict):
            problems.append(f"the file is not a map of keys (read as {type(tree).__name__})")
    present = list(node)
    walks = {names["gk"], names["ak"]}
    values: dict = {}
    file_names = {MATLAB_NAMES[k]: k for k in MATLAB_NAMES} if fmt == "matlab" else {}
    for key in REQUIRED[fmt]:
        if key not in node:
            problems.append(f"required field {key!r} missing{did_you_mean(key, [p for p in present if p not in REQUIRED[fmt]])}")
            continue
        v = node[key]
        short = file_names.get(key, key)
        if key in ("Tw", "Ta", "R_IMUtoACC", "R_IMUtoGYRO", "Tg"):
            if not (isinstance(v, list) and len(v) == 3 and all(isinstance(r, list) and len(r) == 3
                                                               and all(_is_number(x) for x in r) for r in v)):
                problems.append(f"{key} must be a 3x3 matrix (3 rows of 3 numbers), got {v!r}")
            continue
        if key == "rostopic":
            if not isinstance(v, str) or not v:
                problems.append(f"rostopic must be a string (Kalibr: checkRosTopic), got {v!r}")
            continue
        if key == "IMU.Frequency":
            if not (isinstance(v, int) and not isinstance(v, bool)):
                problems.append(f"IMU.Frequency must be an integer (ORB-SLAM3's ParseIMUParamFile: "
                                f"node.isInt()), got {v!r}")
                continue
        elif fmt == "orbslam3" and not isinstance(v, float):
            problems.append(f"{key} must be a real number (ORB-SLAM3's ParseIMUParamFile: node.isReal()), "
                            f"got {v!r}")
            continue
        if not _is_number(v):
            problems.append(f"{key} must be a number, got {v!r}")
            continue
        if not v > 0:
            what = ("walk" if short in walks else "rate" if short == names["rate"] or key == "sampleRate"
                    else "density")
            problems.append(f"{key} = {v!r}: a {what} <= 0 (the consumer refuses it or makes its filter "
                            "singular)" if what != "walk" else
                            f"{key} = {v!r}: a walk <= 0 makes the filter's bias a constant "
                            "(Kalibr's reader refuses it)")
            continue
        values[short] = v
    if fmt == "matlab":
        for name in node:
            base, _, prop = name.partition(".")
            if prop and base in ("gyro", "accel") and prop not in _MATLAB_PROPS:
                problems.append(f"{name}: gyroparams/accelparams have no property {prop!r}"
                                f"{did_you_mean(prop, _MATLAB_PROPS)} (MATLAB: Unrecognized property)")
        for name in ("gyro.BiasInstability", "accel.BiasInstability"):
            if name in node:
                v = node[name]
                if not (_is_number(v) and v >= 0):
                    problems.append(f"{name} must be a number >= 0, got {v!r}")
                else:
                    values[file_names[name]] = v
    file_rate = None
    if fmt == "vins":
        file_rate = rate_hz
    else:
        rk = "sampleRate" if fmt == "matlab" else names["rate"]
        file_rate = node.get(rk) if _is_number(node.get(rk)) else None
        if file_rate is not None and rate_hz is not None and not math.isclose(file_rate, rate_hz, rel_tol=0.01):
            problems.append(f"{rk} = {file_rate!r} Hz, but the rate asked is {rate_hz:g} Hz")
        if fmt in ("openvins",) and file_rate is None:
            problems.append("update_rate missing or not a number")
    rate = float(file_rate or rate_hz or 1.0)
    return ReadBack(fmt, values, to_continuous(fmt, values, rate), file_rate, tuple(problems), parser)


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
        ``factor`` [-] (>= 1; ``raw_factor`` unclamped, ``clamped``), ``nis`` (window [s] -> mean
        NIS at factor 1), ``record_s`` [s],
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
    raw = math.sqrt(nis[worst_w])
    factor = max(1.0, raw)
    why = (f"√ of the largest mean NIS, {nis[worst_w]:.3g} at {worst_w:.3g} s windows, of a "
           f"bias filter at the exported values on {n / rate_hz:.0f} s simulated from the full "
           f"model" + ("" if raw >= 1.0 else
                       f"; {raw:.4g} clamped at 1: a factor below 1 would make the file claim less "
                       "noise than the model has (it is the simulation's scatter)"))
    return {"factor": factor, "raw_factor": raw, "clamped": raw < 1.0,
            "nis": {f"{w:.6g}": v for w, v in nis.items()},
            "record_s": n / rate_hz, "not_simulated": dropped, "why": why}



def verify_export(noise: GyroNoise, fmt: str, rate_hz: float, inflate: float,
                  rng: np.random.Generator, seconds: float = 7200.0, values: dict | None = None) -> dict:
    """Round trip of a file: simulate what the tool's reading of it generates, re-identify
    N and K, compare (module docstring).

    ``values``: the file's numbers as read back (:func:`read_back`); default what the export
    writes (:func:`exported_values`).

    Returns
    -------
    dict
        ``passed``; ``record_s``; per coefficient the value the file means, the re-identified
        value, its 1σ and z; ``band``: the fraction of averaging times where the model's ADEV
        (× inflate) lies in the simulated record's 95 % interval, the worst τ and ratio;
        ``problems`` (one line each).
    """
    if values is None:
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




#: Fewest samples of a still part the record check reads (as ``allan``'s still parts).
MIN_STILL_PART = 256


def record_parts(meas) -> tuple[list[tuple[int, int]], list[str]]:
    """The still, contiguous parts of a measurement ``[start, stop)`` and what was left out: the
    still parts :func:`gyroarray.analysis.motion.still_mask` finds in the gyro outputs (a record
    with a reference rate: where it is below 0.2 deg/h), each cut at gaps in the time stamps; as
    ``gyroarray allan`` reads a record."""
    # deferred: the motion detector and the pooled deviation load only for --record
    from gyroarray.analysis.deviations import contiguous_segments, cut_at_segments
    from gyroarray.analysis.motion import still_mask
    from gyroarray.core.measurement import true_runs
    n, dt = meas.n_samples, meas.dt_s
    notes: list[str] = []
    parts = [(0, n)]
    if meas.has_reference:
        still = np.abs(np.deg2rad(meas.ref_deg_s)).max(axis=1) <= units.deg_h_to_rad_s(0.2)
    else:
        try:
            still = still_mask(meas.gyro_rad_s, meas.layout.axes, dt)
        except InputError:                    # too short to find motion in: all of it
            still = np.ones(n, bool)
    if not still.all():
        parts = [(a, b) for a, b in true_runs(still) if b - a >= MIN_STILL_PART]
        notes.append(f"read over {len(parts)} still part(s), {sum(b - a for a, b in parts) * dt:.1f} s of "
                     f"{n * dt:.1f} s (motion is not noise)")
    segments, missing = contiguous_segments(meas.time_s, dt)
    if len(segments) > 1:
        parts = cut_at_segments(parts, segments)
        notes.append(f"{len(segments) - 1} gap(s) in the time stamps: the parts are cut there")
    if not parts:
        raise InputError("the record has no still, contiguous part of at least "
                         f"{MIN_STILL_PART} samples to compare the file with", file=str(meas.source))
    return parts, notes


def _compare_band(series: np.ndarray, parts, dt: float, n_c: float, k_c: float, b: float, *,
                  what: str, conv, unit: str) -> dict:
    """The file's ADEV (white n_c, walk k_c, flicker floor of b) against one series' measured ADEV
    and 95 % interval, τ by τ; ``conv`` turns SI into ``unit`` for the text."""
    # deferred: the pooled deviation over parts (the analysis layer)
    from gyroarray.analysis.deviations import analyse_parts
    a = analyse_parts([series[p:q] for p, q in parts], dt, "octave", "oadev", confidence=0.95)
    taus = a.taus_s
    file_dev = np.sqrt(sampled_walk_n2(n_c, k_c, dt) * term_basis("oadev", "n", taus)
                       + k_c ** 2 * term_basis("oadev", "k", taus) + _C_B * b ** 2)
    ratio = file_dev / a.adev_rad_s
    # fail against the family-wise band: each τ at 1 - 0.05/n_τ (Bonferroni), so that a file that
    # is the truth fails on at most 5 % of records (each τ at 95 %: on ~25 % of 17-τ records,
    # tests/test_export_consumers.py); the 95 % band per τ is reported beside
    low_fw, _ = confidence_interval(a.adev_rad_s, a.edf, 1.0 - 0.05 / taus.size)
    below = file_dev < low_fw
    below95 = file_dev < a.ci_low_rad_s
    above = file_dev > a.ci_high_rad_s
    i_min = int(np.argmin(a.adev_rad_s))
    return {"what": what, "taus_s": [float(t) for t in taus],
            f"measured_{unit}": [float(conv(x)) for x in a.adev_rad_s],
            f"ci_low_{unit}": [float(conv(x)) for x in a.ci_low_rad_s],
            f"ci_high_{unit}": [float(conv(x)) for x in a.ci_high_rad_s],
            f"file_{unit}": [float(conv(x)) for x in file_dev],
            "file_over_measured": [float(r) for r in ratio],
            f"ci_low_familywise_{unit}": [float(conv(x)) for x in low_fw],
            "below": [{"tau_s": float(taus[i]), "file_over_measured": float(ratio[i]),
                       "ci_low_over_measured": float(low_fw[i] / a.adev_rad_s[i])}
                      for i in np.flatnonzero(below)],
            "familywise_confidence": 1.0 - 0.05 / taus.size,
            "n_below": int(below.sum()), "n_below_95": int(below95.sum()), "n_above": int(above.sum()),
            "n_taus": int(taus.size),
            "min_tau_s": float(taus[i_min]), "file_over_measured_at_min": float(ratio[i_min])}


def record_check(meas, fmt: str, file_si: dict, noise: GyroNoise, gyros: list[int],
                 accel: bool = True, accel_why: str = "") -> dict:
    """The file (as read back, ``file_si`` of :func:`read_back`) against a measurement's ADEV band.

    Parameters
    ----------
    meas : Measurement
        The record (:func:`gyroarray.core.measurement.read_measurement`).
    fmt : str
    file_si : dict
        The file's continuous densities in SI.
    noise : GyroNoise
        The model's gyro noise (what the format drops is said from it).
    gyros : list of int
        The record's gyros (1-based) the file stands for.
    accel : bool
        Also compare the accelerometer fields with the record's ``acc_*`` columns (when both are
        there): every axis, the file being the worst (or mean) of them.
    accel_why : str
        Why the file lacks an accelerometer field (the export's cause), said when it is not
        checked.

    Returns
    -------
    dict
        ``parts_notes``, ``gyros`` (one :func:`_compare_band` dict per gyro), ``accelerometer``
        (per axis, or None), ``accelerometer_not_checked`` (``{"field", "why"}`` per
        accelerometer field not compared: the record has no acc columns, or the file lacks it),
        ``drops`` (one line or None) and ``problems`` (one per series with τ where the file is
        below the measured band).
    """
    parts, notes = record_parts(meas)
    dt = meas.dt_s
    out: dict = {"record": str(meas.source), "record_s": float(meas.n_samples * dt), "parts_notes": notes,
                 "gyros": [], "accelerometer": None, "accelerometer_not_checked": [], "problems": []}
    if file_si.get("gyro_n") is None or file_si.get("gyro_k") is None:
        out["problems"].append("the file's gyro fields could not be read back: nothing to compare")
        return out
    for k in gyros:
        if not 1 <= k <= meas.layout.n_gyros:
            raise InputError(f"--record has {meas.layout.n_gyros} gyro(s); the file is for gyro {k}",
                             file=str(meas.source))
        c = _compare_band(meas.gyro_rad_s[:, k - 1], parts, dt, file_si["gyro_n"], file_si["gyro_k"],
                          file_si.get("gyro_b") or 0.0, what=f"gyro {k}", conv=units.rad_s_to_deg_h,
                          unit="deg_h")
        out["gyros"].append(c)
        if c["n_below"]:
            out["problems"].append(
                f"gyro {k}: the file's ADEV is below the record's family-wise 95 % interval at {c['n_below']} of "
                f"{c['n_taus']} τ: " + ", ".join(f"τ = {b['tau_s']:.4g} s ({b['file_over_measured']:.2f}×)"
                                               for b in c["below"]) + " (file/measured)")
    worst = min(out["gyros"], key=lambda c: c["file_over_measured_at_min"])
    if noise.b_rad_s > 0:
        held = ("as BiasInstability" if fmt == "matlab" else
                "only as a stand-in random walk (white + walk is all the format holds)")
        taus = np.asarray(worst["taus_s"])
        share = _C_B * noise.b_rad_s ** 2 / noise.model_avar(taus)
        i = int(np.argmax(share))                 # where the bias instability matters most
        without = math.sqrt(1.0 - float(share[i]))
        out["drops"] = (f"the model's bias instability B = {units.rad_s_to_deg_h(noise.b_rad_s):.4g} deg/h "
                        f"(ADEV floor {units.rad_s_to_deg_h(0.664 * noise.b_rad_s):.4g} deg/h) is kept {held}; "
                        f"at τ = {taus[i]:.4g} s, where it is {share[i]:.0%} of the model's Allan variance, "
                        f"white + walk alone give {without:.2f}× the model's ADEV, and the file's ADEV is "
                        f"{worst['file_over_measured'][i]:.2f}× the measured")
        out["drops_at"] = {"tau_s": float(taus[i]), "b_share": float(share[i]),
                           "white_walk_over_model": without,
                           "file_over_measured": float(worst["file_over_measured"][i])}
    elif fmt != "matlab":
        out["drops"] = (f"the format holds white + walk only; at τ = {worst['min_tau_s']:.4g} s (the record's "
                        f"ADEV minimum, where a bias instability would show) the file's ADEV is "
                        f"{worst['file_over_measured_at_min']:.2f}× the measured")
    else:
        out["drops"] = None
    if accel:
        names = FIELDS[fmt]
        field_of = (lambda r: MATLAB_NAMES[str(names[r])]) if fmt == "matlab" else (lambda r: str(names[r]))
        for role, key in (("an", "acc_n"), ("ak", "acc_k")):
            why = None
            if not meas.has_acc:
                why = "the record has no acc_x, acc_y, acc_z columns"
            elif file_si.get(key) is None:
                why = ("the file has no readable " + field_of(role)
                       + (f" ({accel_why})" if accel_why else ""))
            if why is not None:
                out["accelerometer_not_checked"].append({"field": field_of(role), "why": why})
    if accel and meas.has_acc and file_si.get("acc_n") is not None and file_si.get("acc_k") is not None:
        acc = []
        for i, axis in enumerate("xyz"):
            c = _compare_band(meas.acc_m_s2[:, i], parts, dt, file_si["acc_n"], file_si["acc_k"],
                              file_si.get("acc_b") or 0.0, what=f"accelerometer {axis}",
                              conv=lambda x: x, unit="m_s2")
            acc.append(c)
            if c["n_below"]:
                out["problems"].append(
                    f"accelerometer {axis}: the file's ADEV is below the record's family-wise 95 % interval at "
                    f"{c['n_below']} of {c['n_taus']} τ: " + ", ".join(
                        f"τ = {b['tau_s']:.4g} s ({b['file_over_measured']:.2f}×)" for b in c["below"]))
        out["accelerometer"] = acc
    below = [b["file_over_measured"] for c in out["gyros"] + (out["accelerometer"] or []) for b in c["below"]]
    # the smallest factor on the file's numbers (--inflate X: densities, so ADEV, times X) that lifts
    # it above the band at every τ where it fails; None when it fails nowhere
    out["inflate_needed"] = float(1.0 / min(below)) if below else None
    return out


@dataclass(frozen=True)
class Export:
    """What :func:`build_export` prepared: the numbers, the file's text and the JSON summary."""

    noise: GyroNoise
    accel: AccelChoice
    fmt: str
    rate_hz: float
    inflate: float
    accel_inflate: float
    text: str
    summary: dict


def build_export(model: NoiseModel, axis: int | str, fmt: str, rate_hz: float, *,
                 inflate: float | str = 1.0, seed: int = 0, source: str = "MODEL.toml",
                 topic: str | None = None, measured: tuple[dict, list[str]] | None = None) -> Export:
    """The file's text and a JSON-ready summary (what ``gyroarray export`` writes and prints).

    Parameters
    ----------
    model : NoiseModel
    axis : int or {"worst", "mean"}
        1-based gyro, or the axis rule of :func:`choose_axis` (the accelerometer:
        :func:`choose_accel`).
    fmt : str
        One of :data:`FORMATS`.
    rate_hz : float
        IMU rate the tool runs at [Hz].
    inflate : float or "auto"
        Factor on the numbers, or derived (:func:`auto_inflation`, never below 1, gyro only).
    seed : int
        Seed of the simulations.
    source : str
        The model file's name, for the header.
    topic : str, optional
        The IMU topic of Kalibr/OpenVINS files (default the model's ``topic``, else
        :data:`DEFAULT_TOPIC`, said so).
    measured : (dict, list of str), optional
        A measured inflation (:func:`measured_inflation`): its summary and header lines;
        ``inflate`` is then its factor [-] (on the gyro's numbers only: the accelerometer's
        stay ×1). The summary goes under ``inflate_measured``, the lines into the header.
    """
    if fmt not in FORMATS:
        raise InputError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
    if not (math.isfinite(rate_hz) and MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ):
        raise InputError(f"--rate-hz must be in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {rate_hz!r}")
    if fmt == "orbslam3":
        orbslam3_frequency(rate_hz)
    noise, what, every = choose_axis(model, axis)
    check_exportable(noise, fmt, rate_hz)
    accel = choose_accel(model, axis)
    if topic is not None:
        topic_pair = (topic, "as given by --topic")
    elif model.topic is not None:
        topic_pair = (model.topic, "the topic the model was fitted on")
    else:
        topic_pair = (DEFAULT_TOPIC, "the default: the model names no topic; --topic T sets it")
    rng = np.random.default_rng(seed)
    summary: dict = {"format": fmt, "gyro": noise.gyro if noise.gyro else None, "axis": what,
                     "gyros": every, "rate_hz": rate_hz}
    if fmt in ("kalibr", "openvins"):
        summary["topic"] = {"topic": topic_pair[0], "why": topic_pair[1]}
    measured_lines = None
    if inflate == "auto":
        auto = auto_inflation(noise, fmt, rate_hz, rng)
        factor, why, accel_factor = auto["factor"], auto["why"], 1.0
        summary["inflate_auto"] = auto
    elif measured is not None:
        m_summary, measured_lines = measured
        factor, accel_factor = float(inflate), 1.0
        if not (math.isfinite(factor) and factor >= 1.0):
            raise InputError(f"a measured inflation is a factor >= 1, got {factor!r}")
        if m_summary.get("method") == "parity":
            why = f"measured {m_summary['from']}, the lines below"
        else:
            why = (f"measured from {m_summary['reference']} topic {m_summary['reference_topic']}, "
                   "the lines below")
        summary["inflate_measured"] = m_summary
    else:
        factor = float(inflate)
        why, accel_factor = ("as asked" if factor != 1.0 else "none asked"), factor
    text = render(noise, fmt, rate_hz, inflate=factor, why=why, source=source, axis=(what, every),
                  accel=accel, topic=topic_pair, accel_inflate=accel_factor, measured_lines=measured_lines)
    si = stand_in(noise, rate_hz, keeps_b=fmt == "matlab")
    values = exported_values(noise, fmt, rate_hz, factor, accel, accel_factor)
    missing = missing_fields(fmt, values)
    summary.update({
        "inflate": factor, "accel_inflate": accel_factor, "values": values,
        "convention": "discrete per sample" if fmt == "vins" else "continuous, two-sided PSD",
        "stand_in": {"covers": list(si.covers),
                     "k_eq_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(si.k_eq_rad_s_rt_s)),
                     "tau1_s": si.tau1_s if si.covers else None,
                     "tau2_s": si.tau2_s if si.covers else None},
        "accelerometer": {"axis": accel.what, "axes": accel.table,
                          "n_m_s2_rt_hz": accel.n_m_s2_rt_hz, "k_m_s3_rt_hz": accel.k_m_s3_rt_hz,
                          "b_m_s2": accel.b_m_s2, "why_missing": accel.why_missing or None,
                          "partial": dict(accel.partial)},
        "walk": {"upper_bound": noise.walk_is_bound,
                 "k_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(noise.k_rad_s_rt_s)),
                 "fit_sigma_deg_h_rt_h": (float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(noise.k_sigma_rad_s_rt_s))
                                          if noise.walk_is_bound else None),
                 "bound_z": WALK_BOUND_Z if noise.walk_is_bound else None},
        "missing_fields": missing,
        "warnings": ([f"the file lacks {', '.join(missing)}: "
                      + (accel.why_missing or f"no accelerometer; {_FIT_HINT}")
                      + "; its consumer will refuse it (or, VINS-Fusion, read 0)"] if missing else []),
    })
    if fmt == "orbslam3" and orbslam3_frequency(rate_hz)[1]:
        summary["warnings"].append(orbslam3_frequency(rate_hz)[1])
    return Export(noise, accel, fmt, rate_hz, factor, accel_factor, text, summary)


def measured_inflation(model: NoiseModel, axis: int | str, meas_path, reference_path,
                       reference_topic: str | None, *, imu_topic: str | None = None,
                       time_offset_s: float | str = "estimate", seed: int = 0,
                       window_s: float = 1.0, levels=None, holdout: float = 0.3
                       ) -> tuple[float, dict, list[str]]:
    """``--inflate measured``: the inflation of the exported axis measured on a record with a
    reference pose topic (:func:`gyroarray.chain.inflation.inflation_for_export`).

    Parameters
    ----------
    model : NoiseModel
    axis : int or {"worst", "mean"}
        As :func:`build_export`: the axis whose N, K [SI] are the static values; ``"mean"`` pools
        the record's three axes (gyro index 0), else the exported gyro (1-3: x, y, z).
    meas_path : str or os.PathLike
        The IMU record (a bag with an IMU topic, or a CSV with gyros 1-3 on x, y, z).
    reference_path : str or os.PathLike or None
        The bag with the reference topic; None: the inflation is measured from the parity
        residual of ``meas_path``, a record of more than 3 gyros
        (:func:`gyroarray.chain.inflation_parity.parity_inflation_for_export`; the model's
        per-gyro white levels give the static parity density).
    reference_topic : str or None
        Its PoseStamped or Odometry topic (None with the parity).
    imu_topic : str, optional
        The record's IMU topic (default its one IMU topic).
    time_offset_s : float or "estimate"
        Added to the IMU stamps [s] (not read by the parity).
    seed : int
        Seed of the factor's interval.
    window_s : float
        The measurement's window [s].
    levels : sequence of float, optional
        Bin edges of the rate level [rad/s] (default the measurement's own).
    holdout : float
        Fraction of each motion level held out for the NIS check [-].

    Returns
    -------
    factor : float
        [-], >= 1.
    summary : dict
    header_lines : list of str
        Four ASCII lines, without comment marks.
    """
    # deferred: the inflation measurement (and its bag readers) loads only for --inflate measured
    from gyroarray.chain.inflation import DEFAULT_LEVELS_RAD_S, inflation_for_export
    noise, _, _ = choose_axis(model, axis)
    edges = DEFAULT_LEVELS_RAD_S if levels is None else tuple(levels)
    index = 0 if axis == "mean" else noise.gyro
    if reference_path is None:
        from gyroarray.chain.inflation_parity import parity_inflation_for_export  # deferred
        return parity_inflation_for_export(
            meas_path, model, noise.n_rad_rt_s, "the axes pooled" if index == 0 else f"gyro {index}",
            imu_topic=imu_topic, rng=np.random.default_rng(seed), window_s=window_s, holdout=holdout,
            levels=edges)
    if reference_topic is None:
        raise InputError("--inflate measured with --reference needs --reference-topic (the pose or odometry topic)")
    return inflation_for_export(meas_path, reference_path, reference_topic, noise.n_rad_rt_s,
                                noise.k_rad_s_rt_s, index, imu_topic=imu_topic,
                                time_offset_s=time_offset_s, rng=np.random.default_rng(seed),
                                window_s=window_s, holdout=holdout, levels=edges)


def verify_file(exp: Export, text: str, *, record=None, seed: int = 0, seconds: float = 7200.0,
                gyros: list[int] | None = None) -> dict:
    """``--verify``: read the written ``text`` back as its consumer does, compare with the numbers
    meant, then the simulated round trip (no record) or the record's ADEV band (``record``, a
    Measurement).

    Returns
    -------
    dict
        ``read_back`` (parser, values, problems), ``round_trip`` (:func:`verify_export`, without a
        record) or ``record`` (:func:`record_check`), ``problems`` and ``passed``.
    """
    rb = read_back(text, exp.fmt, exp.rate_hz)
    problems = list(rb.problems)
    meant = exp.summary["values"]
    for key, want in meant.items():
        got = rb.values.get(key)
        if got is not None and not math.isclose(got, want, rel_tol=READ_BACK_RTOL):
            name = MATLAB_NAMES.get(key, key) if exp.fmt == "matlab" else key
            problems.append(f"{name} = {got!r} in the file, but the model means {want:.6e} "
                            f"({got / want:.4g}× it)" if want else f"{name} = {got!r}, the model means 0")
    out: dict = {"read_back": {"parser": rb.parser, "values": rb.values, "problems": list(rb.problems),
                               "si": rb.si}}
    names = FIELDS[exp.fmt]
    readable = names["gn"] in rb.values and names["gk"] in rb.values
    if record is None and readable:
        rt = verify_export(exp.noise, exp.fmt, exp.rate_hz, exp.inflate, np.random.default_rng(seed), seconds,
                           values={**meant, **rb.values})
        out.update({k: rt[k] for k in ("record_s", "coefficients", "band")})
        out["round_trip"] = {"passed": rt["passed"], "problems": rt["problems"]}
        problems += rt["problems"]
    elif record is not None:
        if gyros is None:
            gyros = [exp.noise.gyro] if exp.noise.gyro else list(range(1, record.layout.n_gyros + 1))
        rc = record_check(record, exp.fmt, rb.si, exp.noise, gyros, accel_why=exp.accel.why_missing)
        out["record"] = rc
        problems += rc["problems"]
    out["problems"] = problems
    out["passed"] = not problems
    return out


def export_noise(model: NoiseModel, gyro: int | str, fmt: str, rate_hz: float, *,
                 inflate: float | str = 1.0, verify: bool = False, seed: int = 0,
                 source: str = "MODEL.toml", topic: str | None = None, record=None) -> tuple[str, dict]:
    """The file's text and a JSON-ready summary (:func:`build_export`); ``verify``: the summary's
    ``verify`` is :func:`verify_file` on that text (``record``: a Measurement to compare with)."""
    exp = build_export(model, gyro, fmt, rate_hz, inflate=inflate, seed=seed, source=source, topic=topic)
    if verify:
        exp.summary["verify"] = verify_file(exp, exp.text, record=record, seed=seed)
    return exp.text, exp.summary
