"""The band-limited Whittle fit and its bound (gyroarray.analysis.whittle.choose_band, crb's
``band_hz``; issue 45 item 1).

Outside truth: the Fisher information of the band written in numpy from the white + walk
spectra; numpy white + walk records passed through a scipy.signal FIR low-pass; the shared
ADIS16405 against the Allan GLS's five-term reading (B 33.4 ± 2.8 deg/h on gyro 1).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from gyroarray.analysis import crb, whittle
from gyroarray.core import units
from gyroarray.core.errors import InputError

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
ADIS = SHARED / "measurements" / "real" / "adis16405_static.csv.gz"
needs_shared = pytest.mark.skipif(not ADIS.is_file(), reason="../shared (read-only project data) not beside the repo")

N_, K_, DT = 1e-3, 1e-3, 0.01            # τ_K = 1 s, 100 Hz (Nyquist 50 Hz)
N_SAMPLES = 20_000                       # T = 200 s = 200 τ_K
CUT_HZ, TAPS = 15.0, 401                 # the FIR's cutoff: transition ≈ 14.6–15.4 Hz


def _white_walk(rng, n):
    return N_ / math.sqrt(DT) * rng.standard_normal(n) + np.cumsum(K_ * math.sqrt(DT) * rng.standard_normal(n))


def _filtered(rng):
    """A white + walk rate through a 401-tap FIR low-pass at 15 Hz (its start-up cut off)."""
    h = signal.firwin(TAPS, CUT_HZ, fs=1.0 / DT)
    return signal.lfilter(h, 1.0, _white_walk(rng, N_SAMPLES + TAPS))[TAPS:]


def test_band_information_is_the_numpy_sum_over_the_band():
    values, n, band = {"n": N_, "k": K_}, 5001, (0.2, 12.5)
    m = n - 1
    j = np.arange(1, m // 2 + 1)
    f = j / m / DT
    j = j[(f >= band[0]) & (f <= band[1])]
    s2 = np.sin(np.pi * j / m) ** 2
    sn, sk = 4 * s2 * N_ ** 2 / DT, np.full(len(j), K_ ** 2 * DT)
    g = np.stack([2 * sn / (sn + sk), 2 * sk / (sn + sk)])           # ∂log S/∂log θ
    want = g @ g.T                                                   # no Nyquist ordinate in the band
    _, got = crb.fisher(values, DT, n_samples=n, band_hz=band)
    assert np.allclose(got, want, rtol=1e-12)
    # the whole band [0, Nyquist] is the record's bound; a band gives less information
    full = crb.crb(values, DT, n_samples=n)
    assert crb.crb(values, DT, n_samples=n, band_hz=(0.0, 50.0)).sd == pytest.approx(full.sd, rel=1e-12)
    assert crb.crb(values, DT, n_samples=n, band_hz=band).sd["n"] > full.sd["n"]


def test_long_part_band_integral_matches_the_exact_sum(monkeypatch):
    values, n, band = {"n": N_, "k": K_, "b": 2e-4}, 400_001, (0.01, 20.0)
    exact = crb.fisher(values, DT, n_samples=n, band_hz=band)[1]
    monkeypatch.setattr(crb, "EXACT_FREQ", 2048)      # most of the band as the grid integral
    approx = crb.fisher(values, DT, n_samples=n, band_hz=band)[1]
    assert np.allclose(approx, exact, rtol=2e-3)


def test_bad_band_is_refused():
    with pytest.raises(InputError):
        crb.crb({"n": N_, "k": K_}, DT, n_samples=1000, band_hz=(5.0, 1.0))
    with pytest.raises(InputError):
        whittle.choose_band(np.zeros(1000), DT, f_lo_hz=60.0)


def test_band_limited_fit_recovers_a_low_passed_record_and_the_full_band_does_not():
    rng = np.random.default_rng(20261204)
    records = 20
    cover = {"n": 0, "k": 0}
    full_n, full_k, bands = [], [], []
    for _ in range(records):
        y = _filtered(rng)
        choice = whittle.choose_band(y, DT)
        bands.append(choice.band_hz[1])
        fit = whittle.fit_whittle(y, DT, ("n", "k"), band_hz=choice.band_hz)
        for p, v in (("n", N_), ("k", K_)):
            # the 95 % interval from the band's information (σ = √κ × the band's CRB)
            assert fit.sigma[p] == pytest.approx(math.sqrt(fit.inflation) * fit.crb[p], rel=1e-6)
            cover[p] += abs(fit.values[p] - v) <= 1.96 * fit.sigma[p]
        full = whittle.fit_whittle(y, DT, ("n", "k"))
        full_n.append(full.values["n"] / N_)
        full_k.append(full.values["k"] / K_)
    # the rule's half-octave bins down from 50 Hz: the FIR's transition (14.6–15.4 Hz) lies in
    # [12.5, 17.7] Hz, whose mean power falls ~40 % under the pilot fit: the band ends at 12.5 Hz
    assert bands == [pytest.approx(12.5)] * records
    # coverage of a 95 % interval: Bin(20, 0.95) falls to 15 or fewer with probability 0.016
    # (an unbiased efficient fit); a fit biased by one σ covers ~83 % and fails this 1/3 of the time
    assert cover["n"] >= 16 and cover["k"] >= 16, cover
    # the full band fits the stop band's missing power: N and K both far off (measured N ≈ 0,
    # K ≈ 29 × the truth; an unbiased fit lies within 20 % of K with 95 % confidence)
    assert max(abs(v - 1.0) for v in full_n) > 0.5 and min(full_n) < 0.5
    assert min(full_k) > 3.0


def test_unfiltered_record_keeps_the_whole_band():
    rng = np.random.default_rng(7)
    kept = sum(not whittle.choose_band(_white_walk(rng, N_SAMPLES), DT).cut for _ in range(10))
    # on a record the pilot model follows, a bin departs by chance (|ratio − 1| > max(5 %, 3σ),
    # σ with the pilot's own error): measured on 200 such records (seed 99), 5 cut (2.5 %, a cost
    # in N's efficiency only). At 2.5 %, 3 or more cuts of 10 happen with probability 0.002
    assert kept >= 8


def test_stated_band_is_used_as_stated():
    rng = np.random.default_rng(3)
    y = _white_walk(rng, 5000)
    choice = whittle.choose_band(y, DT, f_lo_hz=0.1, f_hi_hz=20.0)
    assert choice.band_hz == (0.1, 20.0) and choice.rule == "stated" and choice.cut
    fit = whittle.fit_whittle(y, DT, ("n", "k"), band_hz=choice.band_hz)
    assert fit.band_hz == (0.1, 20.0)
    # the band costs N information: its bound above the whole record's, the efficiency below 1/κ
    assert fit.crb["n"] > fit.crb_full["n"] and fit.efficiency_full["n"] < fit.efficiency["n"]


@needs_shared
@pytest.mark.slow
def test_adis_gyro1_band_limited_bias_instability_against_the_allan_fit():
    from gyroarray.core.measurement import read_measurement
    meas = read_measurement(ADIS)
    x, dt = meas.gyro_rad_s[:, 0], meas.dt_s
    choice = whittle.choose_band(x, dt)
    # the ADIS's internal filter: power falls 8 % under the pilot fit in [12.5, 17.7] Hz, 46 % at
    # 35–50 Hz (measured); the band ends at 12.5 Hz
    assert choice.band_hz[1] == pytest.approx(12.5) and choice.cut
    band = whittle.fit_whittle(x, dt, ("n", "k", "b"), band_hz=choice.band_hz)
    full = whittle.fit_whittle(x, dt, ("n", "k", "b"))
    b_band = float(units.rad_s_to_deg_h(band.values["b"]))
    b_full = float(units.rad_s_to_deg_h(full.values["b"]))
    # the Allan GLS five-term fit: B 33.4 ± 2.8 deg/h. Measured: band 27.6 ± 2.4, full band 201.
    # Within a factor 1.5 of the Allan value (its interval ± 3σ is 25–42); the full band 6 × off
    assert 33.4 / 1.5 <= b_band <= 33.4 * 1.5
    assert b_full > 33.4 * 3
