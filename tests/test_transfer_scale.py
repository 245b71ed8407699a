"""The scale factor on a moving rig from the lines of its motion (issue 32, item 4).

On a rig that sweeps back and forth, the reference's power sits in lines at
the sweep's fundamental and harmonics. The gain |H| = |Y/X| there, read at
f → 0 over the harmonics (gradient-corrected), is the scale factor with no
plateau, no latency and no reference-noise bias
(:mod:`gyroarray.analysis.transfer`). Outside truth written here: a numpy
rig with a known scale factor, and on the shared MPU-6050 record a plain DFT
of the whole sweep cycles at the fundamental and a plain plateau regression.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from gyroarray.analysis.transfer import NoSpectralLines, cross_spectral_gain, line_responses
from gyroarray.effects.fitting import EffectFit
from gyroarray.effects.scale_factor import cross_spectral_scale, reconcile_scale

from hostile import assert_contract, run_cli

MPU = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "mpu6050_yaw_medium_raw.csv.gz"

#: The rig's true scale-factor error [-].
S_TRUE = 0.006


def _rig(rng: np.random.Generator, *, s=S_TRUE, duration_s=300.0, dt_s=0.01, f0_hz=0.47, amp_deg_s=147.0,
         ramp_s=0.08, encoder_deg=0.088, encoder_noise_deg=0.3, delay_s=0.012, cutoff_hz=25.0,
         gyro_noise_deg_s=0.5):
    """A stepper sweep (a square wave of rate with ramps of ``ramp_s``) seen by a noisy encoder
    (angle read with white noise of ``encoder_noise_deg``, rounded to ``encoder_deg`` and
    differentiated: the reference = true rate + the encoder's noise, 42 deg/s rms) and by a gyro: (1 + s)·(the true rate delayed by ``delay_s`` through a first-order
    low-pass at ``cutoff_hz``, none if None) + white noise + a bias. Returns (t, true rate, reference, gyro, dt)
    [s, deg/s]."""
    n = int(round(duration_s / dt_s))
    t = np.arange(n) * dt_s
    square = amp_deg_s * np.sign(np.sin(2 * np.pi * f0_hz * t + 0.3))
    k = int(round(ramp_s / dt_s))
    u = np.convolve(square, np.ones(k) / k, mode="same")
    angle = np.cumsum(u) * dt_s + rng.uniform(0.0, encoder_deg)
    enc = np.round((angle + encoder_noise_deg * rng.standard_normal(n)) / encoder_deg) * encoder_deg
    ref = np.concatenate([[u[0]], np.diff(enc) / dt_s])
    d = int(round(delay_s / dt_s))
    late = np.concatenate([np.full(d, u[0]), u[:-d]])
    seen = late
    if cutoff_hz is not None:
        b, a = signal.butter(1, cutoff_hz, fs=1.0 / dt_s)
        seen = signal.lfilter(b, a, late, zi=signal.lfilter_zi(b, a) * late[0])[0]
    y = (1.0 + s) * seen + gyro_noise_deg_s * rng.standard_normal(n) + 0.3
    return t, u, ref, y, dt_s


def _ols_slope(y, x) -> float:
    return float(np.linalg.lstsq(np.column_stack([np.ones_like(x), x]), y, rcond=None)[0][1])


def test_the_lines_read_the_scale_factor_where_a_plain_regression_on_the_noisy_encoder_reads_low():
    """s = 0.6 %: the lines' gain at f → 0 within 2σ of it. The plain OLS slope of the gyro on
    the recorded (noisy) reference reads low: by the errors-in-variables attenuation
    var(n)/(var(u) + var(n)), shown here against the same regression on the true rate, and
    further by the lag and the low-pass at the ramps."""
    _, u, ref, y, dt = _rig(np.random.default_rng(7))
    g = cross_spectral_gain(y, ref, dt)
    s_x = g.gain - 1.0
    assert abs(s_x - S_TRUE) <= 2.0 * g.sigma, (s_x, g.sigma)
    assert len(g.lines) >= 2 and g.slope_per_hz2 < 0          # the low-pass, corrected over the harmonics
    s_noisy, s_true_rate = _ols_slope(y, ref) - 1.0, _ols_slope(y, u) - 1.0
    noise = ref - u
    attenuation = np.var(noise) / (np.var(u) + np.var(noise))
    assert attenuation > 0.03                                   # a coarse encoder: a few per cent
    assert (1.0 + s_true_rate) * (1.0 - attenuation) == pytest.approx(1.0 + s_noisy, abs=0.1 * attenuation)
    assert s_noisy < S_TRUE - 10.0 * g.sigma and s_noisy < s_x - 10.0 * g.sigma, (s_noisy, s_x, g.sigma)


def test_its_sigma_is_honest_over_rigs():
    """z = (estimate − s)/σ over 30 rigs: mean about 0, spread about 1 (σ neither too small nor
    too large)."""
    z = []
    for seed in range(30):
        _, _, ref, y, dt = _rig(np.random.default_rng(100 + seed), duration_s=120.0)
        g = cross_spectral_gain(y, ref, dt)
        z.append((g.gain - 1.0 - S_TRUE) / g.sigma)
    z = np.array(z)
    assert abs(z.mean()) < 0.6 and 0.6 < z.std() < 1.5, z.round(2)


def test_the_gain_not_the_in_phase_part_a_latency_turns_the_phase_only():
    """A 12 ms lag turns H by 2π·f·τ: Re H reads low by 1 − cos(2π·f·τ) (0.5 % at the 5th harmonic,
    2.3 Hz), |H| does not."""
    _, _, ref, y, dt = _rig(np.random.default_rng(3), cutoff_hz=None)
    lines = line_responses(y, ref, dt, 0.47)
    fifth = next(ln for ln in lines if ln.harmonic == 5)
    drop = 1.0 - np.cos(2 * np.pi * fifth.freq_hz * 0.012)
    assert fifth.h.real == pytest.approx(fifth.gain * (1.0 - drop), abs=3 * fifth.sigma)
    assert fifth.gain - fifth.h.real > 5 * fifth.sigma


def test_a_motion_without_lines_gives_no_estimate_and_says_why():
    rng = np.random.default_rng(5)
    dt = 0.01
    u = np.cumsum(rng.standard_normal(20000)) * 0.5          # a wandering rate: no line
    with pytest.raises(NoSpectralLines, match="no spectral line"):
        cross_spectral_gain(u * 1.006, u, dt)
    why = cross_spectral_scale(np.radians(u) * 0.006, np.column_stack([0 * u, 0 * u, np.radians(u)]),
                               np.array([0.0, 0.0, 1.0]), dt)
    assert isinstance(why, str) and "no spectral line" in why


def _fit(ppm: float, sigma: float) -> EffectFit:
    return EffectFit("scale_factor", 3, {"ppm": ppm}, {"ppm": sigma}, 5.0, "gyro 3 residual rises",
                     {"identifiable": True})


def test_the_cross_spectral_one_is_kept_only_when_consistent_more_precise_and_lowering_chi2():
    """Issue 44 item 2: the time-domain value is kept unless the cross-spectral one agrees with it
    within CONSISTENT_Z (1.96) combined σ, is the more precise and lowers the residual's χ²."""
    _, _, ref, y, dt = _rig(np.random.default_rng(7))
    xs = cross_spectral_gain(y, ref, dt)
    ppm_x = (xs.gain - 1.0) * 1e6
    # 3000 ppm away with σ 700 and 130: 4.2 combined σ, so one is biased: the slope is kept, said so
    far = reconcile_scale(_fit(ppm_x - 3000.0, 700.0), xs)
    assert far.params["ppm"] == ppm_x - 3000.0 and far.extra["kept"] == "time_domain"
    assert far.extra["cross_spectral"]["ppm"] == pytest.approx(ppm_x)
    assert "time domain" in far.evidence and "cross-spectral" in far.evidence
    assert "times their combined σ" in far.evidence and "one of them is biased" in far.evidence
    assert "check the reference" in far.evidence and "keeps the time-domain one" in far.evidence
    # 300 ppm away: consistent, the lines the more precise, and their value explains the residual
    near = reconcile_scale(_fit(ppm_x - 300.0, 700.0), xs)
    assert near.params["ppm"] == pytest.approx(ppm_x) and near.sigma["ppm"] == pytest.approx(xs.sigma * 1e6)
    assert near.extra["kept"] == "cross_spectral" and near.extra["chi2_change"] < 0
    assert "agree within 1.96 times" in near.extra["reconciled"] and "lag" in near.extra["reconciled"]
    joint = reconcile_scale(_fit(ppm_x - 3000.0, 700.0), xs, joint_with_nonlinearity=True)
    assert joint.extra["kept"] == "time_domain" and "curvature" in joint.evidence
    # a cross-spectral value far less precise than the slope, 1.09 combined σ away (our bench: 3002.7
    # ± 5.0 against 36935 ± 31024 ppm): consistent but not the more precise: the slope is kept;
    # 3.5 combined σ away it is not consistent either
    from dataclasses import replace as _replace
    loose = _replace(xs, sigma=31024e-6)
    spread = reconcile_scale(_fit(ppm_x - 33932.0, 5.0), loose)
    assert spread.extra["kept"] == "time_domain" and spread.params["ppm"] == ppm_x - 33932.0
    assert "not the more precise" in spread.extra["reconciled"]
    beyond = reconcile_scale(_fit(ppm_x - 3.5 * 31024.0, 5.0), loose)
    assert beyond.extra["kept"] == "time_domain" and "one of them is biased" in beyond.extra["reconciled"]
    none = reconcile_scale(_fit(4000.0, 700.0), "the motion has no spectral line")
    assert none.params["ppm"] == 4000.0 and none.evidence == "gyro 3 residual rises"
    assert none.extra["cross_spectral"] is None


def test_fit_shows_both_estimates_and_names_a_disagreement(tmp_path):
    """``gyroarray fit --add scale_factor`` on a one-gyro rig record (60 s, the noisy encoder): the
    notes give the time-domain and the cross-spectral scale factor with their σ and which one the
    model keeps. Here the time domain reads about -81 000 ± 4700 ppm (the encoder's noise
    attenuates the slope, and the lag), the lines +5900 ± 130 (within 2σ of the rig's 6000 ppm):
    some 18 combined σ apart. By issue 44 item 2's rule the time-domain one is kept, and the note
    says that one of them is biased and to check the reference."""
    t, _, ref, y, dt = _rig(np.random.default_rng(11), duration_s=60.0)
    path = tmp_path / "rig.csv"
    rows = "\n".join(f"{a!r},{b!r},0.0,0.0,{c!r}" for a, b, c in zip(t.tolist(), y.tolist(), ref.tolist()))
    path.write_text("time_s,gyro1,ref_x,ref_y,ref_z\n" + rows + "\n")
    (tmp_path / "rig.toml").write_text("sample_rate_hz = 100.0\n[layout]\naxes = [[0.0, 0.0, 1.0]]\n")
    o = run_cli(["fit", path, "--add", "scale_factor:1", "--runs", "3", "--json"])
    assert_contract(o)
    res = json.loads(o.out)
    said = [n for n in res["notes"] if n.startswith("scale factor on gyro 1: time domain")]
    assert len(said) == 1 and "times their combined σ" in said[0], res["notes"]
    assert "one of them is biased" in said[0] and "the model keeps the time-domain one" in said[0]
    sf = next(e for e in res["effects"] if e["effect"] == "scale_factor")
    ppm, sigma = sf["params"]["ppm"], sf["sigma"]["ppm"]
    assert f"time domain {ppm:.0f} ± {sigma:.0f} ppm" in said[0], (said, sf)
    cross = float(said[0].split("cross-spectral ")[1].split(" ±")[0])
    cross_sigma = float(said[0].split("cross-spectral ")[1].split(" ±")[1].split(" ppm")[0])
    assert ppm < cross - 5 * cross_sigma
    assert abs(cross - S_TRUE * 1e6) <= 2.0 * cross_sigma, said


# -- the shared MPU-6050 record ------------------------------------------------------------

def _whole_cycle_dft_ppm(y: np.ndarray, ref: np.ndarray, dt: float) -> tuple[float, float]:
    """(fundamental [Hz], scale factor [ppm]) by a plain DFT of reference and gyro at the sweep's
    fundamental over the largest whole number of its cycles: |Y(f0)/R(f0)| − 1 (the magnitude: the
    gyro's latency turns the phase only)."""
    n = ref.size
    pad = 16 * n                                                          # bins 1/16 of 1/(n·dt)
    p = np.abs(np.fft.rfft(ref - ref.mean(), pad)) ** 2
    f0 = (int(np.argmax(p[16:])) + 16) / (pad * dt)
    t = np.arange(n) * dt
    m = int(round(int(n * dt * f0) / (f0 * dt)))                          # whole cycles
    e = np.exp(-2j * np.pi * f0 * t[:m])
    return float(f0), float((abs(np.sum(y[:m] * e) / np.sum(ref[:m] * e)) - 1.0) * 1e6)


def _plateau_ppm(y: np.ndarray, ref: np.ndarray, dt: float, guard: int) -> tuple[float, float]:
    """(scale factor, its σ) [ppm] by OLS of the gyro on the reference over the plateaus, where the
    reference's slope is small: each run of samples at least ``guard`` samples from a reversal
    (a sign change of the 0.2 s mean of the reference) averaged to one point, so that the
    reference's own noise (a differentiated encoder) averages out instead of attenuating the
    slope."""
    sign = np.sign(np.convolve(ref, np.ones(21) / 21, mode="same"))
    rev = np.flatnonzero(np.diff(sign) != 0)
    ym, rm = [], []
    for a, b in zip(rev[:-1], rev[1:]):
        if b - a - 2 * guard >= 20:
            ym.append(y[a + guard:b - guard].mean())
            rm.append(ref[a + guard:b - guard].mean())
    X = np.column_stack([np.ones(len(rm)), rm])
    beta, *_ = np.linalg.lstsq(X, np.array(ym), rcond=None)
    res = np.array(ym) - X @ beta
    cov = np.linalg.inv(X.T @ X) * (res @ res) / (len(ym) - 2)
    return float((beta[1] - 1.0) * 1e6), float(np.sqrt(cov[1, 1]) * 1e6)


@pytest.mark.skipif(not MPU.exists(), reason="needs ../shared/measurements/real")
def test_mpu_record_lines_agree_with_a_plain_dft_and_a_plateau_regression():
    """The shared record (--repair: its duplicate stamps, and its reference re-derived over the
    uniform grid its stamps lied about, core/stamps.py), gyro 3 on the shaft. The lines read
    +5949 ± 54 ppm (harmonics 1, 3, 5, 7, 9 of the 0.468 Hz sweep, the encoder's 2nd harmonic
    left out: the gyro does not show it; |H| rises toward the gyro's resonance and is read at
    f → 0, +78 ppm at f0). Written here: the whole-cycle DFT at the fundamental reads +6063,
    against the lines' fit at f0 (+6027) within 1σ; the plateau regression +5956 / +6081 / +5986
    ± 73 / 106 / 57 over guards of 5, 10, 15 samples from the reversals, each within 2σ combined
    (95 %). Before the reference was corrected: lines +5240 ± 130, DFT +5340, plateaus +5210 to
    +5340; the time-domain candidate +3909 ± 742 ppm. The issue's +0.59–0.60 % is what the lines
    read now."""
    from gyroarray.core.measurement import read_measurement
    m = read_measurement(MPU, repair=True)
    y, ref, dt = m.gyro_deg_s[:, 2], m.ref_deg_s[:, 2], m.dt_s
    omega = np.radians(m.ref_deg_s)
    xs = cross_spectral_scale(np.radians(y) - omega[:, 2], omega, np.array([0.0, 0.0, 1.0]), dt)
    assert not isinstance(xs, str), xs
    ppm, sigma = (xs.gain - 1.0) * 1e6, xs.sigma * 1e6
    assert 0.4676 < xs.fundamental_hz < 0.4678 and len(xs.lines) >= 3
    f0, dft_ppm = _whole_cycle_dft_ppm(y, ref, dt)
    assert f0 == pytest.approx(xs.fundamental_hz, rel=1e-4)
    at_f0 = ppm + xs.slope_per_hz2 * 1e6 * f0 ** 2                         # the lines' fit at f0
    assert abs(dft_ppm - at_f0) <= sigma, (dft_ppm, at_f0, sigma)
    assert [ln.harmonic for ln in xs.not_shown] == [2]                    # the encoder's own line
    assert 5900 - sigma <= ppm <= 6000 + sigma, (ppm, sigma)              # the issue's +0.59–0.60 %
    for guard in (5, 10, 15):
        plateau, plateau_sigma = _plateau_ppm(y, ref, dt, guard)
        assert abs(plateau - ppm) <= 2.0 * np.hypot(sigma, plateau_sigma), (guard, plateau, plateau_sigma, ppm, sigma)


@pytest.mark.slow   # the MPU record diagnosed and fitted (40 s): make score
@pytest.mark.skipif(not MPU.exists(), reason="needs ../shared/measurements/real")
def test_mpu_diagnose_and_fit_show_both_and_keep_the_lines():
    """The candidate's time-domain slope reads +4664 ± 741 ppm (the reference corrected for its
    stamps; +3909 before), under the plateau regression by more than their combined σ; the lines
    +5949 ± 54. They differ by more than their combined σ: the evidence shows both and says the
    model keeps the lines' value, and ``fit --add scale_factor:3`` keeps it (within 2σ combined,
    95 %, of the plateau regression: +6081 ± 106 at a 10-sample guard), saying so in its notes."""
    from gyroarray.chain.compare import ModelComparison
    from gyroarray.core.measurement import read_measurement
    m = read_measurement(MPU, repair=True)
    plateau, plateau_sigma = _plateau_ppm(m.gyro_deg_s[:, 2], m.ref_deg_s[:, 2], m.dt_s, 10)
    comp = ModelComparison(m, n_runs=3)
    before, after = comp.fit([("scale_factor", 3)])
    sf = next(t for t in before.candidates if (t.effect, t.gyro) == ("scale_factor", 3))
    assert "time domain" in sf.evidence and "cross-spectral" in sf.evidence and sf.fit.extra["kept"] == "cross_spectral"
    td = sf.fit.extra["time_domain"]
    assert plateau - td["ppm"] > np.hypot(td["sigma_ppm"], plateau_sigma)          # the slope reads low
    kept = after.fits[("scale_factor", 3)]
    assert kept.extra["kept"] == "cross_spectral"
    assert abs(kept.params["ppm"] - plateau) <= 2.0 * np.hypot(kept.sigma["ppm"], plateau_sigma), (kept.params, plateau)
    assert any(n.startswith("scale factor on gyro 3: time domain") and "keeps the cross-spectral one" in n
               for n in after.notes)


def test_an_encoder_harmonic_the_gyro_does_not_show_does_not_pull_the_lines():
    """Issue 44's outside check: the rig's reference with a 2nd-harmonic error of the encoder (a
    line of 4 deg/s at 2 f0, the size of the gyro's own fundamental-line error 0.6 % x 147 x 4/pi
    = 1.1 deg/s, here ~3.5x it): the square wave of rate has no even harmonics, so the gyro shows
    no line there, |h| within 3 sigma of 0, and the estimate leaves it out (``not_shown``), within
    2 sigma of the truth; read with it, the f^2 extrapolation would be pulled (it is the MPU
    record's +32 % with its reference corrected for its stamps)."""
    t, u, ref, y, dt = _rig(np.random.default_rng(7))
    bad = ref + 4.0 * np.sin(2 * np.pi * 2 * 0.47 * t + 1.0)
    g = cross_spectral_gain(y, bad, dt)
    assert [ln.harmonic for ln in g.not_shown] == [2], g.describe()
    assert all(ln.harmonic % 2 == 1 for ln in g.lines)
    assert abs(g.gain - 1.0 - S_TRUE) <= 2.0 * g.sigma, (g.gain - 1.0, g.sigma)
    assert "harmonic(s) 2 of the reference left out" in g.describe()
    clean = cross_spectral_gain(y, ref, dt)
    assert clean.not_shown == () and [ln.harmonic for ln in clean.lines] == [ln.harmonic for ln in g.lines]
