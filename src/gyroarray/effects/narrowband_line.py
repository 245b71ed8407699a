"""``narrowband_line``: a line whose phase wanders (a Lorentzian line of finite width).

An addition to the effects of ``shared/spec/effects.md`` (not in its list): a gyro's ringing
whose frequency drifts (a fast-sweep MPU record's 9.59 Hz line drifts by 0.8 cycles over 750 s)
is no fixed ``sinusoid``: a fixed phase fitted on one half is out of phase on the other, and
subtracting it there adds a line instead of removing one. This effect models the line as the
stationary process it is, amp·sin(2π f t + φ(t)) with φ a random walk, simulated in the model's
Monte-Carlo band rather than subtracted: what transfers between halves is its amplitude, centre
frequency and width, not its phase.
"""

from __future__ import annotations

import math

import numpy as np

from gyroarray.analysis.line_track import N_SEGMENTS, diffusion_of_linewidth, phase_track, tracked_line
from gyroarray.core.errors import InputError
from gyroarray.core.units import deg_s_to_rad_s, rad_s_to_deg_s
from gyroarray.effects.fitting import EffectFit, Z_EVIDENT, pm
from gyroarray.effects.protocol import Kind, Param, Stage, identity, no_longer_seen, Effect, with_term
from gyroarray.effects.sinusoid import fit_sinusoid, white_angle_noise
from gyroarray.effects.terms import LineTerm, spread

__all__ = ["NarrowbandLine", "fit_narrowband_line", "WANDER_Z", "line_of"]

#: z of the phase track's χ² (a fixed line's phases on a straight line) from which a line is a
#: narrowband process rather than a fixed sinusoid (one-sided p = 1e-4).
WANDER_Z = 3.72

#: rms phase drift over the record [rad], √(4πγ·span), from which a wandering line is named a
#: narrowband process: half a cycle. Below it the fixed sinusoid is kept (its subtraction still
#: takes most of the line out over a record of that length). On the shared MPU-6050 medium record
#: the 46.77 Hz line wanders by 1.4 rad (γ ≈ 1e-4 Hz, phase χ² ~5e4 on 14 dof): modelled as a
#: narrowband process there, the ladder ended at D 33 without the scale factor, against 14 with it
#: as a fixed line (not understood yet; kept as it was).
MIN_DRIFT_RAD = math.pi

#: Seed of the white noise that refills the tracker's band (:meth:`NarrowbandLine.whiten`).
_FILL_SEED = 20261128


class NarrowbandLine(Effect):
    """amp·sin(2π f t + φ(t)), φ a random walk of diffusion 4π·linewidth_hz [rad²/s].

    Its spectrum is a Lorentzian of half-width ``linewidth_hz`` about ``freq_hz`` (convention of
    :mod:`gyroarray.analysis.line_track`: var Δφ over T = 2π·2·linewidth·T). A noise term: it is
    simulated in the model's band and never subtracted; the stochastic tests read the record with
    the line tracked out (:meth:`whiten`). The candidate test is the ``sinusoid``'s: a line whose
    phase track departs from a straight line (z >= :data:`WANDER_Z`) by at least half a cycle rms
    over the record (:data:`MIN_DRIFT_RAD`) is reported as this effect.
    """

    name = "narrowband_line"
    order = 30          # after the spec's effects and the faults: an addition
    stage = Stage.ADD
    kind = Kind.NOISE
    stochastic = True
    candidate = False
    reads = "noise"
    channel = "spectrum"
    rivals = ("sinusoid", "gauss_markov", "bias_instability", "quantization")
    params = (Param("amp_deg_s", "deg/s", "amp_rad_s", deg_s_to_rad_s, lo=0.0, extension=True,
                    doc="amplitude (√2 × the line's rms)"),
              Param("freq_hz", "Hz", "freq_hz", identity, lo=0.0, extension=True,
                    doc="centre frequency (below Nyquist)"),
              Param("linewidth_hz", "Hz", "linewidth_hz", identity, lo=0.0, extension=True,
                    doc="half-width at half-maximum of the Lorentzian line (phase diffusion 4π·γ)"))
    doc = "a spectral line whose phase wanders (narrowband process; an addition to the spec)"

    def check_run(self, params, sample_rate_hz, duration_s):
        if params["freq_hz"] >= 0.5 * sample_rate_hz:
            raise InputError(f"freq_hz = {params['freq_hz']:g} Hz must be below the Nyquist frequency "
                             f"{0.5 * sample_rate_hz:g} Hz of sample_rate_hz = {sample_rate_hz:g} Hz",
                             column="freq_hz")

    def check_record(self, params, dt_s, span_s):
        if params["freq_hz"] >= 0.5 / dt_s:
            raise InputError(f"freq_hz = {params['freq_hz']:g} Hz must be below the Nyquist frequency "
                             f"{0.5 / dt_s:g} Hz (half the sample rate)", column="freq_hz")

    def predictor_term(self, act, n_gyros):
        """The line at its centre frequency, phase 0 (:class:`~gyroarray.effects.terms.LineTerm`:
        its mean square through the filter does not depend on the phase; its width is taken
        narrow beside the filter's features)."""
        amp = spread(act, "amp_rad_s", n_gyros)
        return LineTerm(amp, spread(act, "freq_hz", n_gyros), np.where(np.isnan(amp), np.nan, 0.0))

    def simulate(self, state, act, streams):
        ctx = state.ctx
        n = ctx.n
        out = np.empty((n, len(act.cols)))
        freq = np.broadcast_to(act.p["freq_hz"], (len(act.cols),))
        amp = np.broadcast_to(act.p["amp_rad_s"], (len(act.cols),))
        gam = np.broadcast_to(act.p["linewidth_hz"], (len(act.cols),))
        for j, c in enumerate(act.cols):
            if freq[j] >= 0.5 / ctx.dt_s:
                raise InputError(f"{act.label}: freq_hz must be below the Nyquist frequency "
                                 f"{0.5 / ctx.dt_s:g} Hz of this run (dt = {ctx.dt_s:g} s)", column="freq_hz")
            rng = streams.stream(self.name, int(c) + 1)
            phi0 = rng.uniform(0.0, 2.0 * math.pi)
            step = math.sqrt(diffusion_of_linewidth(float(gam[j])) * ctx.dt_s)
            phi = phi0 + np.cumsum(rng.standard_normal(n)) * step
            out[:, j] = amp[j] * np.sin(2.0 * np.pi * freq[j] * ctx.time_s + phi)
        return with_term(state, act.cols, out)

    def fit(self, ctx, gyro, E):
        g = int(gyro) - 1
        e, t = E[ctx.rec, g], ctx.t[ctx.rec]
        return fit_narrowband_line(e, t, ctx.dt, float(ctx.r[g]), float(ctx.q[g]), int(gyro))

    def test(self, ctx, gyro):
        g = int(gyro) - 1
        return fit_narrowband_line(ctx.Er[:, g], ctx.tr, ctx.dt, float(ctx.r[g]), float(ctx.q[g]), int(gyro),
                                   q_angle_rad=white_angle_noise(ctx, int(gyro)))

    def whiten(self, ctx, entry, x, t):
        """The record with the line tracked out of its gyro's column (its phase followed by a
        complex demodulate, :func:`~gyroarray.analysis.line_track.tracked_line`): what the
        stochastic tests read; the band still compares the record as it is with the simulated line."""
        if entry.gyro is None or x.shape[0] < 3:
            return x
        x = np.array(x, dtype=float, copy=True)
        g = entry.gyro - 1
        f, lw = float(entry.params["freq_hz"]), float(entry.params["linewidth_hz"])
        # the tracker takes the noise of its band (about ±1/width about f) out with the line: a dip
        # in the ADEV near τ = 1/(2f) that read as a τ^-1 excess beside it (quantization, z 4.1 on
        # a held-out half). The band is refilled with white noise of the model's level through the
        # same tracker (a fixed stream per gyro: the same record gives the same tests)
        r = float(ctx.r[g]) if ctx.r is not None else 0.0
        fill = np.random.default_rng([_FILL_SEED, entry.gyro]).standard_normal(x.shape[0]) * math.sqrt(max(r, 0.0))
        x[:, g] -= line_of(x[:, g], t, f, lw) - line_of(fill, t, f, lw)
        return x

    def prefer(self, mine, other, ctx):
        """The line tracked out of the record: the rival (a fixed line, a hump) no longer seen."""
        if mine.gyro is None or ctx.E is None:
            return None
        g = mine.gyro - 1
        pred = np.zeros_like(ctx.E)
        pred[:, g] = line_of(ctx.E[:, g], ctx.t, float(mine.params["freq_hz"]),
                             float(mine.params["linewidth_hz"]))
        why = no_longer_seen(ctx.without(pred), other, ctx, "the narrowband line tracked out")
        if why is None and other.effect == "sinusoid":
            return (f"; but its phase wanders (z = {mine.extra.get('wander_z', math.nan):.1f}): a fixed "
                    "phase does not transfer")
        return why

    def free_parameters(self, fit):
        return 3


def line_of(e, time_s, freq_hz: float, linewidth_hz: float) -> np.ndarray:
    """The narrowband line at ``freq_hz`` tracked in ``e`` (n,): a demodulate smoothed over a time
    in which the phase moves by about 0.2 rad rms (0.05/(4πγ)), at least 4 periods, at most a
    quarter of the record [unit of e]."""
    t = np.asarray(time_s, dtype=float)
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    width = 0.05 / diffusion_of_linewidth(linewidth_hz) if linewidth_hz > 0 else math.inf
    width = min(max(width, 4.0 / max(freq_hz, 1e-12)), max(span / 4.0, 0.0))
    return tracked_line(e, t, freq_hz, width)


def fit_narrowband_line(e, time_s, dt_s: float, r: float, q: float, gyro: int, use=None, *,
                        q_angle_rad: float = 0.0, n_seg: int = N_SEGMENTS) -> EffectFit:
    """The strongest line of the residual, and how its phase wanders.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual [rad/s].
    time_s : array_like, shape (n,)
        Sample times [s], uniform at ``dt_s`` [s].
    r, q : float
        ARW variance per sample and RRW increment variance [rad²/s²] (the line's detection,
        :func:`~gyroarray.effects.sinusoid.fit_sinusoid`).
    gyro : int
        1-based gyro.
    use : array_like of bool, optional
        Samples the detection uses.
    q_angle_rad : float
        Angle quantization Q [rad] of the noise (the detection's).
    n_seg : int
        Segments of the phase track.

    Returns
    -------
    EffectFit
        ``narrowband_line``: ``amp_deg_s`` (the segments' amplitudes A_k as √(mean A_k²), noise bias taken out: √2 × the line's rms),
        ``freq_hz`` (the mean frequency), ``linewidth_hz`` (γ, the Lorentzian half-width) with
        sigmas; ``z`` the line's detection; ``extra``: ``wander_z`` (the phase track's χ² as a z),
        ``linewidth_ci_hz`` (95 %), the fixed line's fit (``sinusoid``).

    Notes
    -----
    The line is found as :func:`~gyroarray.effects.sinusoid.fit_sinusoid` finds it; its phase is
    then read on ``n_seg`` segments at the fitted frequency and tested against a straight line
    (a fixed sinusoid), and γ follows from the variance of the phase increments
    (:func:`~gyroarray.analysis.line_track.phase_track`: var Δφ over T = 2π·2γ·T, the segment
    averages' (2/3) factor and the phase noise taken out).
    """
    fixed = fit_sinusoid(e, time_s, dt_s, r, q, gyro, use=use, q_angle_rad=q_angle_rad)
    f0 = float(fixed.params["freq_hz"])
    e = np.asarray(e, dtype=float)
    # segments of at least 8 samples and 2 periods of the line: fewer than 4 read no track
    k = min(int(n_seg), e.size // 8, int(e.size * float(dt_s) * f0 / 2.0))
    if k < 4:
        extra = {"identifiable": True, "wanders": False, "wander_z": math.nan, "line_z": float(fixed.z),
                 "sinusoid": fixed.params, "chi2": fixed.extra.get("chi2"),
                 "reason": "too few periods of the line for a phase track"}
        return EffectFit("narrowband_line", gyro, {"amp_deg_s": float(fixed.params["amp_deg_s"]), "freq_hz": f0,
                                                   "linewidth_hz": 0.0}, {}, float(fixed.z), fixed.evidence, extra)
    tr = phase_track(e, time_s, f0, k)
    amp_d = rad_s_to_deg_s(tr.amp_rms) if tr.amp_rms > 0 else float(fixed.params["amp_deg_s"])
    amp_s = float(np.std(tr.amp, ddof=1) / math.sqrt(tr.amp.size)) * rad_s_to_deg_s(1.0)
    f_s = float(np.std(np.diff(tr.phase_rad), ddof=1) / (2.0 * math.pi * np.mean(np.diff(tr.t_s)))
                / math.sqrt(max(tr.amp.size - 1, 1)))
    params = {"amp_deg_s": float(amp_d), "freq_hz": float(tr.freq_hz), "linewidth_hz": float(tr.linewidth_hz)}
    sigma = {"amp_deg_s": amp_s, "freq_hz": f_s, "linewidth_hz": float(tr.linewidth_sigma_hz)}
    lo, hi = tr.linewidth_ci_hz
    drift = math.sqrt(diffusion_of_linewidth(tr.linewidth_hz) * e.size * float(dt_s))
    wanders = bool(fixed.z >= Z_EVIDENT and tr.z >= WANDER_Z and drift >= MIN_DRIFT_RAD)
    if wanders:
        ev = (f"gyro {gyro} residual has a line at {pm(tr.freq_hz, f_s)} Hz whose phase wanders (linewidth "
              f"{tr.linewidth_hz:.3g} Hz, 95 % {lo:.3g}–{hi:.3g} Hz; phase track χ² {tr.chi2:.1f} on {tr.dof} dof "
              f"against a fixed line, z = {tr.z:.1f}): modelled as a narrowband process "
              f"(amplitude {amp_d:.4g} deg/s)")
    elif fixed.z >= Z_EVIDENT and tr.z >= WANDER_Z:
        ev = (f"gyro {gyro} residual has a line at {tr.freq_hz:.6g} Hz whose phase wanders by {drift:.2g} rad rms "
              f"over the record (linewidth {tr.linewidth_hz:.3g} Hz, phase track z = {tr.z:.1f}), less than half "
              "a cycle: kept as a fixed sinusoid")
    elif fixed.z >= Z_EVIDENT:
        ev = (f"gyro {gyro} residual has a line at {tr.freq_hz:.6g} Hz whose phase keeps a straight line "
              f"(phase track χ² {tr.chi2:.1f} on {tr.dof} dof, z = {tr.z:.1f}; linewidth {tr.linewidth_hz:.3g} Hz, "
              f"95 % up to {hi:.3g} Hz): a fixed sinusoid")
    else:
        ev = fixed.evidence
    extra = {"identifiable": True, "wanders": wanders, "wander_z": float(tr.z), "drift_rad": drift, "phase_chi2": tr.chi2, "phase_dof": tr.dof,
             "linewidth_ci_hz": [float(lo), float(hi)], "sinusoid": fixed.params, "line_z": float(fixed.z),
             "chi2": fixed.extra.get("chi2")}
    return EffectFit("narrowband_line", gyro, params, sigma, float(fixed.z), ev, extra)
