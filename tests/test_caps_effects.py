"""Issue 44 item 1: a candidate the record's own measurements rule out is refused, and says which.

Outside checks (numpy rigs, written here): a rate² term puts a line at 2 f0 of a periodic motion;
a low-pass and a delay have known transfer functions at the motion's lines; a Gauss–Markov
process has a closed-form Allan variance whose peak caps its σ.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from gyroarray.effects.scale_nonlinearity import cap_by_second_harmonic, fit_scale_nonlinearity

D = math.pi / 180.0
H_Z = np.array([0.0, 0.0, 1.0])


def _swing(n: int, dt: float, f0: float = 0.5, amp_deg_s: float = 150.0, clip: float = 4.0):
    """A symmetric yaw swing (a clipped sine: plateaus at ±amp, no 2 f0 line of its own) [rad/s]."""
    t = np.arange(n) * dt
    u = amp_deg_s * D * np.clip(clip * np.sin(2 * np.pi * f0 * t), -1.0, 1.0)
    ref = np.zeros((n, 3))
    ref[:, 2] = u
    return t, u, ref


#: ARW white σ per sample and RRW K of the rigs (an MPU-like 0.01 deg/s per sample, K 0.02 deg/s/√s).
SIGMA_W, K_RW = 0.01 * D, 0.02 * D


def _noise(rng, n, dt):
    return rng.normal(0.0, SIGMA_W, n) + np.cumsum(rng.normal(0.0, K_RW * math.sqrt(dt), n))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_genuine_rate_squared_term_is_found_and_a_transient_pulled_one_is_refused(seed):
    """k2 = 3e-5 per deg/s on a ±150 deg/s swing puts 0.1 deg/s at 2 f0: found (its cap, the
    gyro's own 2 f0 line + 3σ, is above it). Without it, a transient at every reversal shaped as
    the high-passed u² (a Gaussian smoothing of 80 ms taken out: 2 f0 keeps 1 − exp(−(2π·1·0.08)²/2)
    = 12 % of its line) pulls the GLS fit to k2 ≈ −4e-4 while the gyro's 2 f0 line stays at a
    tenth of that: the cap refuses it, naming the 2 f0 line."""
    rng = np.random.default_rng(seed)
    n, dt = 60000, 0.01
    t, u, ref = _swing(n, dt)
    r, q = SIGMA_W ** 2, K_RW ** 2 * dt
    k2 = 3e-5
    e = k2 / D * u ** 2 + _noise(rng, n, dt)
    f = cap_by_second_harmonic(fit_scale_nonlinearity(e, ref, H_Z, t, dt, r, q, 3), e, ref, H_Z, dt)
    assert "ruled_out" not in f.extra and f.z > 10.0, f.evidence
    # the fit within 4σ of the truth; the cap above the truth (it is an upper bound at 3σ)
    assert abs(f.params["k2_per_deg_s"] - k2) < 4.0 * f.sigma["k2_per_deg_s"] + 1e-7
    assert f.extra["k2_cap_per_deg_s"] > k2
    hp = u ** 2 - ndimage.gaussian_filter1d(u ** 2, 0.08 / dt, mode="wrap")
    e = -5e-4 / D * hp + _noise(rng, n, dt)
    fit = fit_scale_nonlinearity(e, ref, H_Z, t, dt, r, q, 3)
    assert fit.z > 10.0 and fit.params["k2_per_deg_s"] < -2e-4          # pulled by the transient
    f = cap_by_second_harmonic(fit, e, ref, H_Z, dt)
    assert f.z == 0.0 and "2 f0" in f.extra["ruled_out"] and f.extra["z_fitted"] == fit.z
    assert f.extra["k2_cap_per_deg_s"] < 0.5 * abs(fit.params["k2_per_deg_s"])


# -- bandwidth and latency against the motion's lines ----------------------------------------

def _lagged_record(seed: int, delay_s: float = 0.012, cutoff_hz: float | None = None, order: int = 1):
    """A swing seen through a pure delay (the simulator's cubic Lagrange) and, optionally, the
    simulator's sampled low-pass; white + walk noise. (y − u, u) [rad/s] and dt [s]."""
    from gyroarray.core.physics import fractional_delay
    from gyroarray.core.sensor import bandwidth_filter
    rng = np.random.default_rng(seed)
    n, dt = 60000, 0.01
    _, u, _ = _swing(n, dt, clip=2.0)
    y = fractional_delay(u[:, None], [delay_s / dt])[:, 0]
    if cutoff_hz is not None:
        y = bandwidth_filter(y[:, None], dt, np.array([cutoff_hz]), np.array([order]))[:, 0]
    return y - u + _noise(rng, n, dt), u, dt


def _candidate(effect: str, param: str, value: float, sigma: float):
    from gyroarray.effects.fitting import EffectFit
    return EffectFit(effect, 3, {param: value}, {param: sigma}, z=50.0, evidence="candidate")


@pytest.mark.parametrize("seed", [4, 5])
def test_a_delay_is_kept_at_its_value_and_refused_off_it(seed):
    """A 12 ms delay: the candidate 12.0 ± 0.1 ms passes (the lines' phase delay is flat at 12 ms),
    7.89 ± 0.1 ms and 11.34 ± 0.1 ms (the MPU record's) are refused, naming the phase delay;
    a 12.84 Hz first-order low-pass is refused even with a delay of its own left free (its
    amplitude falls 1.6 % from h1 to h5 and its phase delay falls; the record's do not)."""
    from functools import partial
    from gyroarray.effects.bandwidth import _filter_response
    from gyroarray.effects.fitting import transfer_limit
    from gyroarray.effects.latency import _delay_response
    e, u, dt = _lagged_record(seed)
    ok = transfer_limit(_candidate("latency", "delay_s", 0.012, 1e-4), e + u, u, dt, partial(_delay_response, dt_s=dt),
                        "delay_s", "a 12 ms delay")
    assert "ruled_out" not in ok.extra and ok.z == 50.0, ok.extra["transfer_check"]["sentence"]
    for d in (0.00789, 0.01134):
        no = transfer_limit(_candidate("latency", "delay_s", d, 1e-4), e + u, u, dt, partial(_delay_response, dt_s=dt),
                            "delay_s", f"a {d * 1e3:g} ms delay")
        assert no.z == 0.0 and "phase delay" in no.extra["ruled_out"], no.extra
    bw = transfer_limit(_candidate("bandwidth", "cutoff_hz", 12.84, 0.2), e + u, u, dt,
                        partial(_filter_response, order=1, dt_s=dt), "cutoff_hz", "a 12.84 Hz low-pass",
                        free_delay=True, lower=1e-6)
    assert bw.z == 0.0 and "low-pass" in bw.extra["ruled_out"]


@pytest.mark.parametrize("seed", [6, 7])
def test_a_genuine_low_pass_behind_a_delay_is_kept_and_a_delay_alone_is_refused_there(seed):
    """A 12.84 Hz first-order low-pass behind a 3 ms delay: the low-pass candidate (its delay left
    free) passes at its value and is refused 3 Hz off it (15σ of a 0.2 Hz fit); a pure delay, which
    cannot give the filter's amplitude loss and falling phase delay, is refused whatever its value
    near the lines' mean phase delay (15.4 ms at h1)."""
    from functools import partial
    from gyroarray.effects.bandwidth import _filter_response
    from gyroarray.effects.fitting import transfer_limit
    from gyroarray.effects.latency import _delay_response
    e, u, dt = _lagged_record(seed, delay_s=0.003, cutoff_hz=12.84)
    resp = partial(_filter_response, order=1, dt_s=dt)
    ok = transfer_limit(_candidate("bandwidth", "cutoff_hz", 12.84, 0.2), e + u, u, dt, resp, "cutoff_hz",
                        "a 12.84 Hz low-pass", free_delay=True, lower=1e-6)
    assert "ruled_out" not in ok.extra, ok.extra["transfer_check"]["sentence"]
    off = transfer_limit(_candidate("bandwidth", "cutoff_hz", 15.84, 0.2), e + u, u, dt, resp, "cutoff_hz",
                         "a 15.84 Hz low-pass", free_delay=True, lower=1e-6)
    assert off.z == 0.0
    lat = transfer_limit(_candidate("latency", "delay_s", 0.0154, 1e-3), e + u, u, dt, partial(_delay_response, dt_s=dt),
                         "delay_s", "a 15.4 ms delay")
    assert lat.z == 0.0, lat.extra["transfer_check"]


# -- Gauss–Markov σ against the record's own ADEV -------------------------------------------

def test_the_gauss_markov_adev_peak_is_0_617_sigma_at_1_89_tau_c_against_numpy():
    """The closed form's peak (GM_PEAK_ADEV_OVER_SIGMA at GM_PEAK_X·τc), against the overlapping
    ADEV of an AR(1) process made here in numpy (σ = 1, τc = 1 s, dt = 0.01 s, 2e6 samples): at
    τ = 1.89 s the record holds about 1e4 averages, a 1σ of the ADEV near 1 %; 3 % allowed (3σ)."""
    from gyroarray.core.physics import gauss_markov_avar
    from gyroarray.effects.gauss_markov import GM_PEAK_ADEV_OVER_SIGMA, GM_PEAK_X
    taus = np.geomspace(0.05, 20.0, 400)
    g = np.sqrt(gauss_markov_avar(taus, 1.0, 1.0))
    k = int(np.argmax(g))
    assert abs(g[k] - GM_PEAK_ADEV_OVER_SIGMA) < 1e-4 and abs(taus[k] - GM_PEAK_X) < 0.03
    dt, n, tc = 0.01, 2_000_000, 1.0
    phi = math.exp(-dt / tc)
    for seed in (11, 12, 13):
        rng = np.random.default_rng(seed)
        w = rng.normal(0.0, math.sqrt(1 - phi ** 2), n)
        x = np.empty(n)
        x[0] = rng.normal()
        from scipy import signal
        x[1:] = signal.lfilter([1.0], [1.0, -phi], w[1:], zi=[phi * x[0]])[0]
        m = int(round(GM_PEAK_X * tc / dt))
        c = np.concatenate([[0.0], np.cumsum(x)])
        avg = (c[m:] - c[:-m]) / m
        adev = math.sqrt(0.5 * np.mean((avg[m:] - avg[:-m]) ** 2))
        assert abs(adev / GM_PEAK_ADEV_OVER_SIGMA - 1.0) < 0.03, adev


@pytest.mark.parametrize("seed", [21, 22])
def test_a_genuine_hump_is_kept_and_a_sigma_beyond_the_adev_is_refused(seed):
    """White noise (σ_w 0.01 deg/s per sample at 100 Hz) plus a GM of σ 100 deg/h, τc 2 s: the
    fitted hump is kept and its σ_max (the ADEV's 3σ upper bound over √g, min over τ) is above the
    truth. The same record's bound refuses a σ ten times the truth: its ADEV would be 617 deg/h at
    τ ≈ 3.8 s, where the record shows about 62."""
    from gyroarray.core.physics import gauss_markov_noise
    from gyroarray.core.units import deg_h_to_rad_s
    from gyroarray.effects.gauss_markov import cap_by_adev
    from gyroarray.effects.stochastic import fit_gyro_noise
    rng = np.random.default_rng(seed)
    n, dt = 360_000, 0.01
    sig = float(deg_h_to_rad_s(100.0))
    x = rng.normal(0.0, SIGMA_W, n) + gauss_markov_noise(n, dt, np.array([sig]), np.array([2.0]),
                                                            rng.standard_normal((n, 1)))[:, 0]
    gm = next(f for f in fit_gyro_noise(x, dt, 1) if f.effect == "gauss_markov")
    assert gm.z > 5.0 and "ruled_out" not in gm.extra, gm.evidence
    assert gm.extra["sigma_max_deg_h"] > 100.0
    # the same curve and fit, a σ ten times the truth: refused, naming the ADEV
    from dataclasses import replace
    from gyroarray.analysis.allan_gls import curve, gls
    cv = curve(x, dt)
    tc = gm.params["tau_s"]
    f = gls(cv, ("n", "k", "gm"), tc)
    big = replace(gm, params=dict(gm.params, sigma_deg_h=1000.0), sigma={"sigma_deg_h": 10.0})
    out = cap_by_adev(big, cv, f, ("n", "k", "gm"), tc)
    assert out.z == 0.0 and "ADEV" in out.extra["ruled_out"], out.extra
    assert 100.0 < out.extra["sigma_max_deg_h"] < 300.0


# -- correlation in the band where it is read ------------------------------------------------

@pytest.mark.parametrize("seed", [31, 32])
def test_a_white_correlation_holds_octave_by_octave_and_a_common_line_is_refused(seed):
    """Three gyros sharing 36 % of their white noise (ρ = 0.6² = 0.36) plus a small walk: ρ_arw
    found (z > 10) and not refused (its octaves agree with one value: p > P_BAND). Independent
    white noise plus a 46.8 Hz line common to all three (the MPU record's): the GLS over all
    octaves reads a ρ_arw of about 0.3, which holds at no octave but the line's; refused."""
    from gyroarray.effects.correlation import P_BAND, fit_correlation
    rng = np.random.default_rng(seed)
    n, dt = 200_000, 0.01
    c = rng.normal(size=n)
    X = np.column_stack([0.6 * c + 0.8 * rng.normal(size=n) for _ in range(3)]) * 0.002 / math.sqrt(dt)
    X += np.cumsum(rng.normal(0.0, 1e-5 * math.sqrt(dt), (n, 3)), axis=0)
    f = fit_correlation(X, dt)[0]
    assert f.z > 10.0 and abs(f.params["rho_arw"] - 0.36) < 0.05 and f.extra["band_p"] > P_BAND, f.extra
    X = rng.normal(size=(n, 3)) * 0.002 / math.sqrt(dt) + 0.02 * np.sin(2 * np.pi * 46.8 * np.arange(n) * dt)[:, None]
    f = fit_correlation(X, dt)[0]
    assert f.z == 0.0 and "white band" in f.extra["ruled_out"] and f.extra["z_fitted"] > 10.0
