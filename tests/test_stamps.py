"""Stamps that lie (issue 44 item 3): a reference differentiated over wrong stamps is named
as biased, and undoing numpy.gradient over the stamps recovers the rate on the uniform grid."""

from pathlib import Path

import numpy as np
import pytest

from gyroarray.core.measurement import read_measurement
from gyroarray.core.stamps import corrected_reference, stamps_lie, undo_gradient

MPU = Path("/work/shared/measurements/real/mpu6050_yaw_medium_raw.csv.gz")
DT = 0.01            # nominal period [s]
F0 = 0.47            # rotation frequency of the numpy rig [Hz]
AMP = 120.0          # rotation amplitude [deg]


def _rig(rng, n=6000):
    """Uniform true times, stamps off by whole ms (0 at both ends), a sine rotation [deg]."""
    T = np.arange(n) * DT
    e = rng.choice([-1e-3, 0.0, 0.0, 0.0, 1e-3], size=n)
    e[0] = e[-1] = 0.0
    angle = AMP * np.sin(2 * np.pi * F0 * T)
    return T, T + e, angle


def test_undo_gradient_is_the_inverse_of_numpy_gradient_over_any_stamps():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.5, 1.5, 500)) * DT
    th = np.cumsum(rng.normal(size=500))
    th -= th[0]
    # exact algebra: only rounding (1e-16 relative, times the condition of the banded solve)
    assert np.allclose(undo_gradient(t, np.gradient(th, t)), th, rtol=0, atol=1e-9)


def test_a_reference_derived_over_lying_stamps_is_named_and_recovered():
    rng = np.random.default_rng(2)
    T, stamps, angle = _rig(rng)
    ref = np.gradient(angle, stamps)            # the logger's reference, over the wrong stamps
    gyro = np.gradient(angle, T)                # a physical rate on the uniform samples
    v = stamps_lie(stamps, gyro, ref, DT)
    # true stamps would give slope 1; uniform samples give 0 exactly up to the local-rate
    # estimate (neighbours +-2 on a 2.1-s sine: curvature error < 1e-3)
    assert v.lie and abs(v.slope) < 0.02 and v.z_true > 50, v
    assert abs(v.gyro_jump_slope) < 0.05, v       # the gyro does not jump with the stamps
    c = corrected_reference(stamps, ref, DT)
    assert c.period_s == pytest.approx(DT, rel=1e-12)
    truth = np.gradient(angle, DT)                # what numpy.gradient gives on the true grid
    # no noise: exact inversion, the error is the solve's rounding (~1e-12 of the rate)
    assert np.max(np.abs(c.ref - truth)) <= 1e-9 * np.max(np.abs(truth))
    assert c.bias_rms > 0.1                       # the recorded reference was off (deg/s)
    # numpy.gradient over jittered stamps reads uniform increments high (x + 1/x >= 2)
    assert c.scale_ppm > 100, c.scale_ppm


def test_a_really_jittered_clock_is_not_called_lying():
    rng = np.random.default_rng(3)
    T, stamps, _ = _rig(rng)
    angle = AMP * np.sin(2 * np.pi * F0 * stamps)  # sampled at the jittered times: stamps true
    ref = np.gradient(angle, stamps)
    v = stamps_lie(stamps, ref, ref, DT)
    assert not v.lie and abs(v.slope - 1.0) < 0.05, v


def test_a_clock_without_jitter_gives_no_verdict():
    T = np.arange(3000) * DT
    ref = np.gradient(50 * np.sin(T), T)
    v = stamps_lie(T, ref, ref, DT)
    assert not v.lie and v.n_steps == 0


def _dft_ppm(gyro, ref):
    """|G|/|R| - 1 [ppm] at the fundamental, by a DFT over whole cycles (the frequency that
    maximises the reference's line, bounded search on the uniform grid)."""
    from scipy.optimize import minimize_scalar

    n = np.arange(ref.size)

    def line(x, f, m):
        return np.sum(x[:m] * np.exp(-2j * np.pi * f * n[:m]))

    coarse = np.linspace(0.002, 0.008, 601)
    f = coarse[int(np.argmax([abs(line(ref, f, 20000)) for f in coarse]))]
    f = minimize_scalar(lambda x: -abs(line(ref, x, ref.size)), bounds=(f - 2e-5, f + 2e-5),
                        method="bounded").x
    m = int(round(int(ref.size * f) / f))
    return (abs(line(gyro, f, m)) / abs(line(ref, f, m)) - 1.0) * 1e6


@pytest.mark.skipif(not MPU.exists(), reason="shared MPU record not present")
def test_the_shared_mpu_reference_is_named_biased_by_its_stamps():
    m = read_measurement(MPU, repair=True)
    note = next(n for n in m.notes if "biased by its stamps" in n)
    assert "ref_z" in note and "ref_x" not in note and "ppm in scale" in note
    # the verdict and bias size, from the file's own columns
    import pandas as pd
    v = pd.read_csv(MPU, comment="#").to_numpy()
    v = v[np.concatenate(([True], ~np.all(v[1:] == v[:-1], axis=1)))]
    verdict = stamps_lie(v[:, 0], v[:, 3], v[:, 6], DT)
    # measured 0.052 +- 0.010 (93 sigma from true stamps); a 9-ms step's increment is 1.00 of
    # its neighbours', 0.90 if the stamps were true; the gyro does not jump with the stamps
    assert verdict.lie and verdict.slope < 0.2 and verdict.z_true > 30, verdict
    assert 0.97 < verdict.ratio_short < 1.03 and abs(verdict.gyro_jump_slope) < 0.1, verdict
    # 149 804 rows + 27 missing samples at the 20-ms gaps: period 10.0107 ms, not the sidecar's 10
    assert verdict.n_slots == 149831 and verdict.period_s == pytest.approx(0.0100107, rel=2e-5)
    c = corrected_reference(v[:, 0], v[:, 6], DT)
    # measured: rms 3.18 deg/s, +854 ppm in scale (the estimate: the rate reads 0.09 % high)
    assert 2.0 < c.bias_rms < 5.0 and 600 < c.scale_ppm < 1100, c
    assert f"{c.scale_ppm:+.0f} ppm in scale" in note


@pytest.mark.skipif(not MPU.exists(), reason="shared MPU record not present")
def test_with_the_correction_on_the_dft_scale_factor_is_the_settled_one(monkeypatch):
    import gyroarray.core.measurement as gm

    monkeypatch.setattr(gm, "CORRECT_LYING_REFERENCE", False)
    raw = read_measurement(MPU, repair=True)
    monkeypatch.setattr(gm, "CORRECT_LYING_REFERENCE", True)            # the default
    m = read_measurement(MPU, repair=True)
    assert any("biased by its stamps" in n and "repaired: replaced" in n for n in m.notes)
    assert m.n_samples == raw.n_samples and np.array_equal(m.gyro_deg_s, raw.gyro_deg_s)
    # the outside check: whole-cycle DFT at the fundamental (0.468 Hz) of gyro 3 against the
    # reference. Measured +6037 ppm corrected (10 blocks: mean 6076, sem 47 ppm) against +5295
    # from the file's ref_z; the settled number is +0.59-0.60 %: the band is 1.7 sem of
    # the blocks' spread either side of it, and the uncorrected one is 13 sem below.
    g3 = m.gyro_deg_s[:, 2]
    corrected = _dft_ppm(g3, m.ref_deg_s[:, 2])
    assert 5850 < corrected < 6200, corrected
    assert 5000 < _dft_ppm(g3, raw.ref_deg_s[:, 2]) < 5450


@pytest.mark.slow
@pytest.mark.skipif(not MPU.exists(), reason="shared MPU record not present")
def test_fit_scale_factor_after_repair_is_within_one_sigma_of_the_settled_number(capsys):
    """Issue 44's Done-when: with the reference corrected for its stamps (the default under
    --repair) and the cross-spectral estimate reading only the lines the gyro shows (the
    encoder's 2nd harmonic left out), gyro 3 reads 5949 +- 54 ppm (measured), within 1 sigma of
    +0.59-0.60 %; before either change 5238 +- 128."""
    import re

    from gyroarray.cli.main import main

    rc = main(["fit", str(MPU), "--add", "scale_factor:3", "--repair"])
    out = capsys.readouterr().out
    assert rc in (0, None) and "biased by its stamps" in out
    ppm = float(re.search(r"scale_factor \(gyro 3\): ppm = ([-0-9.e+]+)", out).group(1))
    sig = re.search(r"scale factor on gyro 3: .*?cross-spectral [-0-9.]+ ± ([0-9.]+) ppm", out)
    sigma = float(sig.group(1)) if sig else 200.0
    assert 5900 - sigma <= ppm <= 6000 + sigma, out
