"""A reference with noise of its own (gyroarray.analysis.reference_noise).

For an exact reference r = ω and gyros g = ω + n the reference's part that is
not coherent with the gyros, P_rr·(1 − C), is P_ωω·P_nn/(P_ωω + P_nn) < P_nn <= P_gg
(closed form): the ratio stays below 1 at every frequency, whatever the noise.
Outside truth: the four practice records (an independent generator's rate
table, exact references) and the MPU-6050 stepper record (a differentiated
0.088° encoder, ../shared/measurements/real).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gyroarray.analysis.reference_noise import RATIO, reference_own_noise
from gyroarray.chain.compare import ModelComparison
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import read_measurement
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.core.units import deg_s_to_rad_s, deg_to_rad

SHARED = Path(__file__).resolve().parents[2] / "shared" / "measurements"
PRACTICE = sorted((SHARED / "practice").glob("*.csv.gz"))
MPU = SHARED / "real" / "mpu6050_yaw_medium_raw.csv.gz"
DT = 0.01


def _table(seed: int):
    """A triad on a table turning about z with plateaus and turns (150 deg/s, 20 s period), 10 min."""
    n = 60_000
    t = np.arange(n) * DT
    w = np.zeros((n, 3))
    w[:, 2] = deg_s_to_rad_s(150 * np.tanh(3 * np.sin(2 * np.pi * 0.05 * t)))
    m = NoiseModel.from_toml({"effects": [{"effect": "arw", "n_deg_rt_h": 0.5},
                                          {"effect": "rrw", "k_deg_h_rt_h": 50.0}]})
    y = simulate_readings(m, w, Layout.triad(), DT, np.random.default_rng(seed), time_s=t)
    return w, y


@pytest.mark.parametrize("path", PRACTICE, ids=[p.stem for p in PRACTICE])
def test_exact_references_of_an_independent_generator_are_not_flagged(path):
    m = read_measurement(path)
    assert reference_own_noise(m.ref_rad_s, m.gyro_rad_s, m.layout.axes, m.dt_s) == []


def test_an_encoder_reference_is_flagged_and_an_exact_one_is_not():
    w, y = _table(5)
    h = Layout.triad().H
    assert reference_own_noise(w, y, h, DT) == []
    step = deg_to_rad(0.088)                          # the angle quantized, then differentiated
    enc = w.copy()
    enc[:, 2] = np.gradient(np.round(np.cumsum(w[:, 2]) * DT / step) * step, DT)
    found = reference_own_noise(enc, y, h, DT)
    assert [d["axis"] for d in found] == [2]
    assert found[0]["max_ratio"] > RATIO and found[0]["excess_rms_deg_s"] > 0.5


@pytest.mark.skipif(not MPU.exists(), reason="needs ../shared/measurements/real")
def test_the_mpu_encoder_is_flagged_and_the_note_names_the_flag():
    m = read_measurement(MPU, repair=True)
    found = reference_own_noise(m.ref_rad_s, m.gyro_rad_s, m.layout.axes, m.dt_s)
    # 4.9 % of the bins with the reference re-derived over its proven grid (--repair, core/stamps.py;
    # 18 % before: the stamps' bias was read as the encoder's noise too), above MIN_FRACTION
    assert [d["axis"] for d in found] == [2] and found[0]["fraction"] > 0.03
    notes = ModelComparison(m, n_runs=1).setup_notes
    assert any("noise of its own" in n and "--ref-smooth" in n for n in notes)
    smoothed = ModelComparison(m, n_runs=1, ref_smooth_s=0.2).setup_notes
    assert not any("noise of its own" in n for n in smoothed)


@pytest.mark.skipif(not MPU.exists(), reason="needs ../shared/measurements/real")
def test_allan_says_which_gyro_reads_the_reference_noise(cli):
    """`allan --repair` on the MPU-6050 record fits Q ≈ 1.6° to gyro 3 (output minus the encoder
    rate): the note says that this gyro's ADEV holds the reference's noise; with --raw it is not
    said (the output alone)."""
    import json
    d = json.loads(cli("allan", MPU, "--repair", "--json").stdout)
    own = [n for n in d["notes"] if "noise of its own" in n]
    assert len(own) == 1 and "reference about z" in own[0] and "ADEV of gyro 3 " in own[0]
    raw = json.loads(cli("allan", MPU, "--repair", "--raw", "--json").stdout)
    assert not any("noise of its own" in n for n in raw["notes"])
