"""Regression on real data: the ADIS16405 static record (shared/measurements/real).

What `gyroarray diagnose` / `fit` find on it (closing notes of issue 6), kept
so a change that alters the finding is noticed: ARW + RRW alone does not
explain the record (D far above 1); gyros 1 and 2 have an ADEV excess that a bias
instability (z > 30) and a short-τc Gauss–Markov term (the sensor's internal
low-pass filter: τc ≈ 0.04 s, 4 samples) both pick up, the Gauss–Markov
far better (z ≈ 106 against ≈ 42, and it ranks first); with it fitted, a
flicker floor at τ 40–330 s is still there on gyros 1 and 2, and the ADEV
says so without gyroarray (allantools' ADEV against the other fitted terms'
closed forms); no gyro needs quantization (the ADEV at
the shortest τ is *below* the white-noise extrapolation, z << 0). The z's of
a 10 000 s record are far from the thresholds, so the assertions hold for
any band seed.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

ADIS = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "adis16405_static.csv.gz"


@pytest.mark.slow   # 15 s: make score
@pytest.mark.skipif(not ADIS.exists(), reason="shared/measurements/real not present")
def test_adis_excess_is_a_short_gauss_markov_not_quantization(cli):
    p = cli("diagnose", ADIS, "--runs", 10, "--json")
    d = json.loads(p.stdout)
    assert d["consistent"] is False and d["discrepancy"] > 10
    by = {(c["effect"], c["gyro"]): c for c in d["candidates"]}
    order = [(c["effect"], c["gyro"]) for c in d["candidates"]]
    for g in (1, 2):
        first = next(e for e, gg in order if gg == g)          # the gyro's first candidate
        assert first == "gauss_markov" and by[("gauss_markov", g)]["score"] > 80
        # the flat part is seen but ranks under the hump that explains it
        assert by[("bias_instability", g)]["significant"]
        assert order.index(("bias_instability", g)) > order.index(("gauss_markov", g))
        assert "Gauss–Markov hump fits the spectrum better" in by[("bandwidth", g)]["evidence"]
    for g in (1, 2, 3):
        assert not by[("quantization", g)]["significant"] and by[("quantization", g)]["score"] < -50
    assert any(n.startswith("scale_factor: not tested") for n in d["notes"])


@pytest.mark.skipif(not ADIS.exists(), reason="shared/measurements/real not present")
def test_adis_roll_off_agrees_with_a_plain_welch_ratio():
    """The spectral fit's low-pass on gyros 1 and 2 against a plain Welch estimate: the power at
    40–48 Hz over 5–15 Hz is what |H|² of the fitted filter gives (a 19.6 Hz line on gyro 3 is
    left out of its fit, not read as a roll-off)."""
    from scipy import signal

    from gyroarray.analysis.psd_fit import fit_psd
    from gyroarray.core.measurement import read_measurement

    m = read_measurement(ADIS)
    for g in (0, 1):
        x = m.gyro_rad_s[:, g]
        f, p = signal.welch(x - x.mean(), fs=1.0 / m.dt_s, nperseg=1024)
        lo, hi = (f >= 5) & (f <= 15), (f >= 40) & (f <= 48)
        measured = p[hi].mean() / p[lo].mean()
        fit = fit_psd(x, m.dt_s)
        fc, n = fit.filter_cutoff_hz, fit.filter_order
        h2 = lambda band: np.mean(1.0 / (1.0 + (f[band] / fc) ** (2 * n)))   # noqa: E731
        # the Welch ratio's own 1σ is about 0.4 % (≈ 2000 segments x 80 bins); the fit's W and R
        # shape the ratio by ~1 %: 3 %
        assert h2(hi) / h2(lo) == pytest.approx(measured, rel=0.03), (g + 1, fc, n, measured)


@pytest.mark.skipif(not ADIS.exists(), reason="shared/measurements/real not present")
def test_adis_cut_off_sigma_holds_up_on_the_other_half():
    """Gyro 3's cut-off fitted on each half of the record: 37.72 and 38.83 Hz. The profile's
    curvature alone gave ±0.074 and ±0.080 Hz, 10σ apart; the spectrum scatters about the fit
    11–20 times more than S·χ²_ν/ν (an excess at 3.6–11 Hz the model does not hold), and with
    σ scaled by √dispersion (quasi-likelihood) the halves are within 3σ of each other (2.6).
    The held-out half is the outside check."""
    from gyroarray.analysis.psd_fit import fit_psd
    from gyroarray.core.measurement import read_measurement

    x = read_measurement(ADIS).gyro_rad_s[:, 2]
    dt = 0.01
    a, b = (fit_psd(h - h.mean(), dt) for h in (x[: x.size // 2], x[x.size // 2:]))
    assert min(a.dispersion, b.dispersion) > 5.0
    diff = abs(a.filter_cutoff_hz - b.filter_cutoff_hz)
    assert 0.8 < diff < 3.0 * math.hypot(a.filter_cutoff_sigma_hz, b.filter_cutoff_sigma_hz)
    raw = math.hypot(a.filter_cutoff_sigma_hz / math.sqrt(a.dispersion),
                     b.filter_cutoff_sigma_hz / math.sqrt(b.dispersion))
    assert diff > 5.0 * raw


@pytest.mark.slow
@pytest.mark.skipif(not ADIS.exists(), reason="shared/measurements/real not present")
def test_adis_keeps_a_flicker_floor_once_the_filter_hump_is_fitted(adis_adev):
    """With the 0.04 s hump fitted, gyros 1 and 2 still show a flicker floor (B) at τ 80–330 s.

    Independent reading: allantools' ADEV there, less the closed forms of the
    other fitted terms (N²/τ, K²τ/3 and the first-order Gauss–Markov Allan
    variance σ²(τc/τ)²(2τ/τc − 3 + 4e^(−τ/τc) − e^(−2τ/τc))), is the floor's
    (2 ln 2/π)·B². That B agrees with the fitted B within 30 %: each octave's
    ADEV has 70–140 degrees of freedom (±8–12 % in B²) and the other terms'
    1σ move the remainder by about 10 %. (Until the flicker test read the
    octaves the model describes, it found no floor here: its baseline, fitted
    where the model misses the short τ by χ² 1394 for 15 dof, read the floor as
    K = 186 deg/h/√h, and the calibrated model then lay 40 % below the ADEV at
    164–328 s on gyro 1.)"""
    from gyroarray.chain.compare import ModelComparison
    from gyroarray.core.measurement import read_measurement

    comp = ModelComparison(read_measurement(ADIS), n_runs=10)
    _, after = comp.fit([("gauss_markov", 1), ("gauss_markov", 2)])
    by = {(t.effect, t.gyro): t for t in after.candidates}
    for g in (1, 2):
        bi = by[("bias_instability", g)]
        assert after.significant(bi), bi.evidence
        assert after.fits[("gauss_markov", g)].params["tau_s"] == pytest.approx(0.04, rel=0.1)
        n = after.fits[("arw", g)].params["n_deg_rt_h"] * 60.0              # deg/h·√s
        k = after.fits[("rrw", g)].params["k_deg_h_rt_h"] / 60.0            # deg/h/√s
        gm = after.fits[("gauss_markov", g)].params
        s2, tc = gm["sigma_deg_h"] ** 2, gm["tau_s"]
        t, ad = adis_adev[g - 1]
        sel = (t > 60.0) & (t < 400.0)                                        # 82, 164, 328 s
        r = t[sel] / tc
        others = n ** 2 / t[sel] + k ** 2 * t[sel] / 3.0 + s2 / r ** 2 * (2 * r - 3 + 4 * np.exp(-r) - np.exp(-2 * r))
        b_plain = math.sqrt(np.mean(ad[sel] ** 2 - others) / (2.0 * math.log(2.0) / math.pi))
        assert bi.fit.params["b_deg_h"] == pytest.approx(b_plain, rel=0.3), (g, b_plain)


def _point_bounds(adev):
    """min over octave τ of ADEV(τ)·√(3/τ) [deg/h/√h], per gyro."""
    return [float(np.min(ad / np.sqrt(t / 3.0))) * 60.0 for t, ad in adev]


@pytest.fixture(scope="module")
def adis_adev():
    """allantools' overlapping ADEV of gyros 1–3 at the octave τ up to a third of the record:
    [(τ [s], ADEV [deg/h])]."""
    import allantools

    from gyroarray.core.measurement import read_measurement
    m = read_measurement(ADIS)
    out = []
    for g in (1, 2, 3):
        x = m.gyro_rad_s[:, g - 1] * (180.0 / np.pi) * 3600.0                      # deg/h
        octs = 2.0 ** np.arange(0, int(np.log2(x.size / 3)) + 1) * m.dt_s
        t, ad, _, _ = allantools.oadev(x, rate=1.0 / m.dt_s, data_type="freq", taus=octs)
        out.append((t, ad))
    return out


@pytest.fixture(scope="module")
def adis_analysis():
    from gyroarray.chain.compare import ModelComparison
    from gyroarray.core.measurement import read_measurement
    m = read_measurement(ADIS)
    return m, ModelComparison(m, n_runs=3).analyse()


@pytest.mark.skipif(not ADIS.exists(), reason="shared/measurements/real not present")
def test_adis_rrw_respects_the_point_adev_bound_within_its_own_two_sigma(adis_analysis, adis_adev):
    """The point bound (42 / 141 / 152 deg/h/√h) is itself read from the last octaves, with 2–3
    degrees of freedom; K must not exceed it by more than its own 2σ. Before the K reference fit
    (flicker column, octaves where ARW + RRW + flicker fit) K was 185 / 296 / 265 ± 18–21."""
    _, a = adis_analysis
    for g, bound in zip((1, 2, 3), _point_bounds(adis_adev)):
        f = a.fits[("rrw", g)]
        assert f.params["k_deg_h_rt_h"] <= bound + 2.0 * f.sigma["k_deg_h_rt_h"], (g, bound, f.params)


@pytest.mark.skipif(not ADIS.exists(), reason="shared/measurements/real not present")
@pytest.mark.xfail(strict=True, reason=(
    "not met on gyros 1 and 3: K = 76 ± 33 and 201 ± 33 deg/h/√h against point bounds of 42 and "
    "152 (gyro 2: 125 ± 43 against 141 holds). Gyro 3's ADEV rises from 33 to 67 deg/h between "
    "328 and 1310 s, a +1/2 slope of K ≈ 185, and its last octave (2621 s, 75 deg/h, 2–3 degrees "
    "of freedom) sets the bound. The point bound is no bound for the truth: on records of pure "
    "ARW + RRW like these (numpy + allantools, benchmarks/rrw_point_bound.py) it is below the K "
    "that made the record on 70-75 % of them, so a fit that is right exceeds it as often"))
def test_adis_rrw_is_below_the_point_adev_bound(adis_analysis, adis_adev):
    """K·√(τ/3) ≤ ADEV(τ) at every octave τ up to a third of the record, ADEV from allantools.

    Kept as the issue states it, and expected to fail: benchmarks/rrw_point_bound.py simulates
    1e6-sample records of ARW 2.5 deg/√h + RRW K = 76 / 125 / 200 deg/h/√h with plain numpy
    (40 each) and reads the bound with allantools: it falls below the true K on 75 / 70 / 72 %
    of them (median bound/K 0.79 / 0.84 / 0.68). gyroarray's fit is unbiased there (mean 75.7 /
    125.2 / 204.5, sd 11.8 / 17.0 / 18.0 against a mean 1σ of 13.1 / 16.2 / 20.3) and exceeds the
    bound on 70 / 75 / 88 % of them; capping it at the bound would bias it low by design.
    The bound that holds is the one with its own 2σ (the test above)."""
    _, a = adis_analysis
    for g, bound in zip((1, 2, 3), _point_bounds(adis_adev)):
        assert a.fits[("rrw", g)].params["k_deg_h_rt_h"] <= bound, (g, bound)


@pytest.mark.skipif(not ADIS.exists(), reason="shared/measurements/real not present")
def test_adis_bias_instability_is_read_below_the_adev_floor(adis_analysis, adis_adev):
    """A flicker floor's ADEV is 0.664·B and every other term adds to it, so min ADEV / 0.664
    (allantools) bounds B from above: 38 and 46 deg/h on gyros 1–2. The test's own column,
    fitted from the first octave, read 46–55 (and 107 in an earlier release); B is now read
    beside K where ARW + RRW + flicker fit the curve."""
    _, a = adis_analysis
    by = {(t.effect, t.gyro): t for t in a.tests}
    for g in (1, 2):
        ceiling = float(np.min(adis_adev[g - 1][1])) / 0.664
        b = by[("bias_instability", g)].fit.params["b_deg_h"]
        assert 0.5 * ceiling < b <= ceiling, (g, b, ceiling)
