"""The fit side of ``earth_rate`` (src/gyroarray/effects/earth_rate.py), on simulator data."""

import math

import numpy as np
import pytest
from gyroarray.effects.earth_rate import attitude_from_rates, fit_earth_rate
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.sim.truth import compute_truth
from scipy.spatial.transform import Rotation
from gyroarray.core.data import data_path

FS = 100.0
DT = 1.0 / FS
LAT = 34.25
HEADING_DEG = 17.0          # non-zero: exercises the heading sign
ARW = 0.05                  # deg/√h
RRW = 0.5                   # deg/h/√h (small)
SIX_POSITION = data_path("scenarios") / "profiles" / "example_six_position.toml"

_H = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0],
               [1.0, -1.0, 0.0]])
H = _H / np.linalg.norm(_H, axis=1)[:, None]


def r_q(arw=ARW, rrw=RRW):
    n = math.radians(arw) / 60.0                 # rad/√s
    k = math.radians(rrw) / 3600.0 / 60.0        # rad/s/√s
    return n * n / DT, k * k * DT


def model(earth: bool, arw=ARW, rrw=RRW) -> NoiseModel:
    eff = [{"effect": "arw", "n_deg_rt_h": arw}, {"effect": "rrw", "k_deg_h_rt_h": rrw}]
    if earth:
        eff.append({"effect": "earth_rate", "latitude_deg": LAT})
    return NoiseModel.from_toml({"effects": eff})


SITE = (math.radians(LAT), math.radians(HEADING_DEG))


@pytest.fixture(scope="module")
def truth(tmp_path_factory):
    """Six positions, 60 s holds, 10 s moves, 100 Hz (the simulator's own attitude)."""
    return compute_truth(SIX_POSITION, FS, cache_dir=tmp_path_factory.mktemp("truth"))


def residuals(truth, seed, earth, **kw):
    w = truth.omega_body_rad_s
    y = simulate_readings(model(earth, **kw), w, H, DT, np.random.default_rng(seed),
                          time_s=truth.time_s, attitude=truth.rotation_matrices, site=SITE)
    return y - w @ H.T


def fit(truth, e, **kw):
    r, q = r_q(**kw)
    return fit_earth_rate(e, H, truth.omega_body_rad_s, truth.time_s, DT, np.full(5, r),
                          np.full(5, q), HEADING_DEG, LAT)


def rot_angle(a, b):
    return np.linalg.norm(Rotation.from_matrix(np.einsum("nji,njk->nik", a, b)).as_rotvec(), axis=1)


def test_attitude_constant_rate_is_exact():
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    n, dt = 5000, 0.01
    w = np.tile(0.7 * axis, (n, 1))
    got = attitude_from_rates(w, dt)
    want = Rotation.from_rotvec(np.arange(n)[:, None] * dt * w).as_matrix()
    assert np.allclose(got[0], np.eye(3))
    assert rot_angle(got, want).max() < 1e-11


def test_attitude_left_sample_hold():
    rng = np.random.default_rng(3)
    w = rng.normal(size=(4, 3))
    got = attitude_from_rates(w, 0.1)
    want = np.eye(3)
    for i in range(3):
        want = want @ Rotation.from_rotvec(w[i] * 0.1).as_matrix()
    assert np.allclose(got[3], want, atol=1e-14, rtol=0)


def test_attitude_agrees_with_simulator(truth):
    """Integrated ref rates vs the attitude simulate() passes to earth_rate (MuJoCo's)."""
    w = truth.omega_body_rad_s
    got = attitude_from_rates(w, DT)
    err = rot_angle(truth.rotation_matrices, got)
    still = np.linalg.norm(w, axis=1) < 1e-9
    assert still.mean() > 0.8
    assert err[still].max() < 1e-9                 # the holds, where Earth rate is measured
    # during moves: within-sample motion the samples cannot resolve
    assert err.max() < np.abs(w).max() * DT


def test_earth_rate_found(truth):
    f = fit(truth, residuals(truth, 20240611, True))
    assert f.effect == "earth_rate" and f.gyro is None
    assert f.extra["identifiable"]
    lat, sig = f.params["latitude_deg"], f.sigma["latitude_deg"]
    assert abs(lat - LAT) < max(2 * sig, 1.0), (lat, sig)
    assert f.z > 5
    assert abs(f.extra["magnitude_ratio"] - 1) < max(3 * f.extra["magnitude_ratio_sigma"], 0.05)
    assert "latitude" in f.evidence and "±" in f.evidence


def test_earth_rate_found_low_noise_with_given_attitude(truth):
    e = residuals(truth, 7, True, arw=0.01, rrw=0.1)
    r, q = r_q(arw=0.01, rrw=0.1)
    f = fit_earth_rate(e, H, truth.omega_body_rad_s, truth.time_s, DT, r, q, HEADING_DEG,
                       attitude=truth.rotation_matrices)
    assert abs(f.params["latitude_deg"] - LAT) < max(2 * f.sigma["latitude_deg"], 1.0)
    assert f.z > 5


def test_absent_z_is_null(truth):
    # Without earth_rate, z ~ N(0, 1): P(|z| > 3) = 0.0027 per seed; over 10
    # independent seeds P(at least 2 exceed) = 1 − (1−p)^10 − 10 p (1−p)^9 ≈ 3.3e-4,
    # so "at most 1" fails by chance about once in 3000 runs (seeds fixed anyway).
    zs = []
    for seed in range(100, 110):
        f = fit(truth, residuals(truth, seed, False))
        assert f.extra["identifiable"]
        zs.append(f.z)
    zs = np.array(zs)
    assert np.sum(np.abs(zs) > 3) <= 1, zs
    assert np.all(np.isfinite(zs))


def test_static_record_not_identifiable():
    n = 20000
    w = np.zeros((n, 3))
    t = np.arange(n) * DT
    y = simulate_readings(model(True), w, H, DT, np.random.default_rng(11), time_s=t, site=SITE)
    r, q = r_q()
    f = fit_earth_rate(y - w @ H.T, H, w, t, DT, r, q, HEADING_DEG, LAT)
    assert f.extra["identifiable"] is False
    assert f.z == 0.0
    assert "multi-position or rotating" in f.evidence


def test_turns_about_vertical_only_not_identifiable():
    """Rotation about up leaves the vertical component constant: latitude not separable."""
    n = 20000
    w = np.zeros((n, 3))
    w[5000:6000, 2] = math.radians(90.0) / 10.0   # 90° about z over 10 s
    t = np.arange(n) * DT
    att = attitude_from_rates(w, DT)
    y = simulate_readings(model(True), w, H, DT, np.random.default_rng(12), time_s=t,
                          attitude=att, site=SITE)
    r, q = r_q()
    f = fit_earth_rate(y - w @ H.T, H, w, t, DT, r, q, HEADING_DEG)
    assert f.extra["identifiable"] is False
    assert f.z == 0.0


def _gapped_turn(n=12000, dt=0.01, cut=(8000, 8100)):
    """A rate 0 for 60 s, then 10 deg/s about a tilted axis; the samples of ``cut`` dropped."""
    w = np.zeros((n, 3))
    w[6000:] = np.radians(10.0) * np.array([0.6, 0.0, 0.8])
    keep = np.r_[0:cut[0], cut[1]:n]
    return w, dt, keep


def test_attitude_across_a_gap_keeps_the_turn_made_during_it():
    """The 1 s gap of a 10 deg/s turn: the attitude after it equals the uncut record's (a constant
    rate: exact, 1e-12), where the stitched reference would read it 10° behind; without gaps the
    same bits as :func:`attitude_from_rates`."""
    from gyroarray.effects.earth_rate import attitude_across_gaps
    w, dt, keep = _gapped_turn()
    full = attitude_from_rates(w, dt)
    i = 8000 - 1                                           # the step over the gap
    got = attitude_across_gaps(w[keep], dt, {i: 101 * dt})
    np.testing.assert_allclose(got, full[keep], atol=1e-12)
    stitched = attitude_from_rates(w[keep], dt)
    turned = Rotation.from_matrix(stitched[-1].T @ full[-1]).magnitude()
    assert math.degrees(turned) == pytest.approx(10.0, abs=1e-6)   # what stitching dropped
    np.testing.assert_array_equal(attitude_across_gaps(w, dt, {}), full)
    with pytest.raises(ValueError, match="outside the record"):
        attitude_across_gaps(w[keep], dt, {keep.size - 1: 1.0})


def test_a_comparison_cut_at_gaps_reads_the_attitude_on_the_records_clock():
    """``fit --gaps`` with a reference: the comparison's attitude (Earth rate, gravity) at the kept
    samples is the uncut record's, the turn made during the gap included."""
    from gyroarray.chain.compare import ModelComparison
    from gyroarray.core.layout import Layout
    from gyroarray.core.measurement import Measurement
    w, dt, keep = _gapped_turn()
    rng = np.random.default_rng(3)
    y = np.degrees(w + 1e-4 * rng.standard_normal(w.shape))
    m = Measurement(time_s=dt * np.arange(w.shape[0])[keep], gyro_deg_s=y[keep], layout=Layout.triad(),
                    sample_rate_hz=1 / dt, ref_deg_s=np.degrees(w[keep]))
    comp = ModelComparison(m, n_runs=2)
    assert comp.gap_summary()["missing_samples"] == 100
    full = attitude_from_rates(w, dt)
    np.testing.assert_allclose(comp.attitude(), full[keep], atol=1e-9)
