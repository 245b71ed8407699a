"""FDI with the array as it is (issue 31, item 3b): heterogeneous gyros are no fault, a moving
array's scale-factor and axis differences are a calibration finding, real faults still are found.

Every record is written here with numpy (not gyroarray's simulator)."""

from __future__ import annotations

import numpy as np
import pytest

from gyroarray.chain.fdi_score import analyse_measurement
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import read_measurement
from gyroarray.effects.model import NoiseModel
from gyroarray.estimators.fdi import FaultDetector, estimate_noise, model_noise, noise_spread
from gyroarray.estimators.noise import ArrayNoise

from hostile import assert_contract, run_cli, write_measurement

RATE = 50.0
DT = 1.0 / RATE
#: white level per sample of each gyro [deg/s]: 5x between the quietest and the noisiest
SIGMA = np.array([0.01, 0.05, 0.012, 0.03, 0.015, 0.02, 0.04, 0.011])


def _axes8() -> np.ndarray:
    rows = []
    for k in range(8):
        a = 2 * np.pi * k / 4 + (np.pi / 4 if k >= 4 else 0.0)
        el = np.radians(35.0 if k < 4 else -50.0)
        rows.append([np.cos(el) * np.cos(a), np.cos(el) * np.sin(a), np.sin(el)])
    return np.array(rows)


H = _axes8()


def _sidecar() -> str:
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in h) + "]" for h in H)
    return f"sample_rate_hz = {RATE!r}\n[layout]\naxes = [{rows}]\n"


def _write(tmp_path, name, deg):
    return write_measurement(tmp_path, name, np.arange(deg.shape[0]) * DT, deg, sidecar=_sidecar())


def _static(rng, n, sigma=SIGMA):
    bias = rng.normal(0.0, 0.2, 8)
    return bias + sigma * rng.normal(size=(n, 8))


def _fdi(path, *extra):
    o = run_cli(["fdi", path, "--json", *extra], timeout=300)
    assert_contract(o)
    assert o.code == 0, o.err
    return o.json


def test_heterogeneous_static_array_is_no_fault(tmp_path):
    rng = np.random.default_rng(1)
    deg = _static(rng, 6000)
    out = _fdi(_write(tmp_path, "hetero", deg))
    assert out["alarms"] == [], out["alarms"]
    assert any("each gyro's own white level" in n for n in out["notes"])
    assert "calibration" not in out                          # no motion: no calibration finding
    # the alike-gyro model this replaces reads the same record as faults
    z = np.radians(deg)
    alike = ArrayNoise.identical(8, float(np.radians(np.median(SIGMA))) * np.sqrt(DT))
    det = FaultDetector(drift_window_s=100.0, variance_window_s=40.0).fit(Layout(H), alike, DT)
    assert len(det.false_alarms(z)["samples"]) > 0


def test_per_gyro_levels_match_a_plain_numpy_estimate():
    rng = np.random.default_rng(2)
    z = np.radians(_static(rng, 6000))
    noise, notes = estimate_noise(z, Layout(H), DT, still=np.ones(6000, dtype=bool))
    sig = noise.arw_rad_rt_s / np.sqrt(DT)                   # per-sample σ
    ref = np.sqrt(np.var(z[:3000] - z[:3000].mean(0), axis=0, ddof=1))   # the first 60 s
    assert np.allclose(sig, ref, rtol=0.08)                  # raised by 2 SE of the median
    assert np.all(sig >= 0.98 * ref)
    assert np.allclose(sig, np.radians(SIGMA), rtol=0.1)
    assert np.allclose(noise.corr_arw, np.eye(8))


def test_a_real_step_on_a_heterogeneous_array_is_found(tmp_path):
    rng = np.random.default_rng(3)
    deg = _static(rng, 6000)
    deg[4000:, 2] += 0.1                                     # gyro 3 (σ 0.012): 0.1 deg/s step at 80 s
    out = _fdi(_write(tmp_path, "step", deg))
    a = out["alarms"][0]
    assert (a["gyro"], a["kind"]) == (3, "step") and abs(a["onset_s"] - 80.0) < 2.0
    assert abs(a["size"] - 0.1) < 0.02


def _moving(rng, s, tilt):
    """40 s still, 20 s turning about all axes (up to ~150 deg/s), 40 s still: readings (deg/s)."""
    n = 5000
    t = np.arange(n) * DT
    turn = (t >= 40.0) & (t < 60.0)
    env = np.where(turn, np.sin(np.pi * (t - 40.0) / 20.0) ** 2, 0.0)
    om = env[:, None] * np.c_[120 * np.sin(2 * np.pi * 0.5 * t), 90 * np.sin(2 * np.pi * 0.35 * t + 1),
                              150 * np.sin(2 * np.pi * 0.25 * t + 2)]
    U = np.empty_like(H)
    W = np.empty_like(H)
    for i, h in enumerate(H):                                # tilt directions ⟂ h_i
        u = np.cross(h, [0.0, 0.0, 1.0])
        U[i] = u / np.linalg.norm(u)
        W[i] = np.cross(h, U[i])
    E = s[:, None] * H + tilt[:, :1] * U + tilt[:, 1:] * W
    return om @ (H + E).T + _static(rng, n)


def test_moving_array_scale_factor_is_a_calibration_finding_not_a_fault(tmp_path):
    rng = np.random.default_rng(4)
    s = np.zeros(8)
    tilt = np.zeros((8, 2))
    s[4] = 0.02                                              # gyro 5: +2 % scale factor
    tilt[1, 0] = 0.01                                        # gyro 2: 10 mrad tilt
    deg = _moving(rng, s, tilt)
    path = _write(tmp_path, "moving", deg)
    out = _fdi(path)
    assert out["alarms"] == [], out["alarms"]
    cal = out["calibration"]
    assert cal["significant"] and set(cal["off"]) == {2, 5}, cal["off"]
    assert cal["gyros"]["5"]["scale_factor_ppm"] == pytest.approx(2e4, rel=0.05)
    assert any(n.startswith("calibration finding (not a fault)") for n in out["notes"])
    # without taking the fitted errors out, the same detector reads the motion as faults
    meas = read_measurement(path)
    _, _, det = analyse_measurement(meas)
    assert len(det.detect(meas.gyro_rad_s, meas.time_s).alarms) > 0


def test_level_that_changes_between_still_parts_is_tolerated(tmp_path):
    rng = np.random.default_rng(5)
    n = 10000                                                # 200 s
    sig = np.tile(SIGMA, (n, 1))
    block = (np.arange(n) // 1000) % 2 == 1                  # every other 20 s
    sig[block, 3] *= 1.8                                     # gyro 4's level: 1x, 1.8x, 1x, ...
    deg = rng.normal(0.0, 0.2, 8) + sig * rng.normal(size=(n, 8))
    z = np.radians(deg)
    kap, notes = noise_spread(z, DT, np.ones(n, dtype=bool))
    assert kap[3] > 1.5 and np.all(kap[np.arange(8) != 3] == 1.0), kap
    assert "gyro 4" in notes[0]
    out = _fdi(_write(tmp_path, "levels", deg))
    assert out["alarms"] == [], out["alarms"]
    # without the tolerance the variance test calls it a noise fault
    noise, _ = estimate_noise(z, Layout(H), DT, still=np.ones(n, dtype=bool))
    det = FaultDetector(drift_window_s=100.0, variance_window_s=40.0).fit(Layout(H), noise, DT)
    assert len(det.false_alarms(z)["samples"]) > 0


def test_noise_fault_beyond_the_tolerated_spread_is_still_found(tmp_path):
    rng = np.random.default_rng(6)
    deg = _static(rng, 8000)
    deg[6000:, 0] += SIGMA[0] * 3.0 * rng.normal(size=2000)   # gyro 1: σ x3.2 from 120 s
    out = _fdi(_write(tmp_path, "noisy", deg))
    assert out["alarms"] and out["alarms"][0]["gyro"] == 1
    assert out["alarms"][0]["kind"] == "noise"


ARRAY_MODEL = """effects = [{effect = "arw", n_deg_rt_h = 0.2}]

[array]
gyros = [1, 2]
white_n_deg_rt_h = [0.2, 0.2]
white_correlation = [[1.0, 0.6], [0.6, 1.0]]
"""


def test_a_models_array_table_gives_the_correlation(tmp_path):
    (tmp_path / "m.toml").write_text(ARRAY_MODEL)
    model = NoiseModel.from_toml(tmp_path / "m.toml", n_gyros=8)
    nz = model_noise(model, 8)
    assert nz.corr_arw[0, 1] == pytest.approx(0.6) and nz.corr_arw[0, 2] == 0.0
    assert np.allclose(np.diag(nz.corr_arw), 1.0)
    rng = np.random.default_rng(7)
    sig = np.radians(0.2 / 60.0) / np.sqrt(DT)               # 0.2 deg/√h per sample [rad/s]
    L = np.linalg.cholesky(nz.corr_arw)
    z = (rng.normal(size=(4000, 8)) @ L.T) * sig
    out = _fdi(_write(tmp_path, "corr", np.degrees(z)), "--model", tmp_path / "m.toml")
    assert out["alarms"] == []
    assert any("[array] table" in n for n in out["notes"])
