"""The MuJoCo rate table, its truth and the truth cache.

Outside truth: the layout's own H (per-site MuJoCo gyros must equal H·ω),
the gimbal kinematics of test_profiles.py (checked there against scipy)
applied to MuJoCo's joint encoders, scipy's Euler rotations for commanded
orientations, an independent least-squares sine fit, and the closed-form
frequency response of the servo loop discretised as MuJoCo integrates it.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import gyroarray.sim.truth as truth_mod
from gyroarray.core.layout import Layout
from gyroarray.sim.profiles import (ConstantRate, MultiPosition, Orientation, Profile, Sinusoid,
                                    Static, body_rate, gimbal_quaternion, load_profile)
from gyroarray.sim.table import RateTable, TableParams, n_samples, steps_per_sample
from gyroarray.sim.truth import compute_truth, project, truth_key
from gyroarray.core.units import deg_s_to_rad_s, deg_to_rad

PROFILES = Path(__file__).resolve().parents[1] / "src" / "gyroarray" / "data" / "scenarios" / "profiles"
TABLE = RateTable()
MAGIC = math.acos(1 / math.sqrt(3))

MULTI_AXIS = """
[[segment]]
kind = "static"
duration_s = 0.5
[[segment]]
kind = "constant_rate"
axis = [0.48, 0.64, 0.6]
rate_deg_s = 40.0
duration_s = 1.0
ramp_s = 0.5
align_s = 1.0
[[segment]]
kind = "sinusoid"
axis = [1, 0, 0]
amplitude_deg_s = 30.0
frequency_hz = 1.0
duration_s = 2.0
align_s = 1.0
[[segment]]
kind = "rate_csv"
file = "r.csv"
[[segment]]
kind = "static"
gimbal_deg = [30, -20, 45]
transition_s = 1.0
duration_s = 0.5
"""
# rates on all three body axes at once
MULTI_CSV = "time_s,wx_deg_s,wy_deg_s,wz_deg_s\n" + "".join(
    f"{t:.2f},{20 * math.sin(math.pi * t):.6f},{25 * math.sin(math.pi * t / 2):.6f},"
    f"{-15 * math.sin(math.pi * t):.6f}\n" for t in np.arange(0, 2.01, 0.05))


@pytest.fixture(scope="module")
def multi_axis(tmp_path_factory):
    d = tmp_path_factory.mktemp("multi")
    (d / "r.csv").write_text(MULTI_CSV)
    (d / "p.toml").write_text(MULTI_AXIS)
    return load_profile(d / "p.toml")


def _layouts():
    rng = np.random.default_rng(7)
    explicit = rng.normal(size=(7, 3))
    out = [Layout.conical(s, n, a) for s in (1, 2) for n in (4, 5, 6, 8)
           for a in ([MAGIC] if s == 1 else [deg_to_rad(63.43)])]
    return out + [Layout.triad(), Layout.from_axes(explicit / np.linalg.norm(explicit, axis=1)[:, None]),
                  Layout.conical(1, 6, deg_to_rad(20.0))]


@pytest.mark.parametrize("layout", _layouts(), ids=repr)
def test_every_site_gyro_reads_H_omega(multi_axis, layout):
    run = TABLE.run(multi_axis, 100.0, layout=layout)
    w = run.omega_body_rad_s
    # real motion on every body axis (else the check below would be vacuous)
    assert np.all(np.max(np.abs(w), axis=0) > deg_s_to_rad_s(10.0))
    # one rigid platform: every site sees the same ω; only the site frames differ (rounding)
    np.testing.assert_allclose(run.site_rates_rad_s, w @ layout.H.T, rtol=0, atol=1e-9)
    truth = compute_truth(multi_axis, 100.0, cache=False)
    np.testing.assert_array_equal(truth.omega_body_rad_s, w)        # physics is layout-free
    np.testing.assert_allclose(project(truth, layout), run.site_rates_rad_s, rtol=0, atol=1e-9)


def test_reference_gyro_and_attitude_match_the_gimbal_kinematics(multi_axis):
    run = TABLE.run(multi_axis, 100.0)
    q, qd = run.joint_angles_rad, run.joint_rates_rad_s
    # MuJoCo's gyro and framequat against ω = J(q) q̇ and R = Rz Rx Ry from the encoders:
    # same numbers through two code paths, rounding only
    np.testing.assert_allclose(run.omega_body_rad_s, body_rate(q, qd), rtol=0, atol=1e-13)
    qc = gimbal_quaternion(q)
    sign = np.sign(np.sum(qc * run.quat_wxyz, axis=1))[:, None]
    np.testing.assert_allclose(run.quat_wxyz, sign * qc, rtol=0, atol=1e-13)
    # and the table did follow the command (tracking errors are small, not zero)
    assert 0 < run.tracking.rms_error_rad_s < 1e-3 * np.abs(run.command_body_rad_s).max()


@pytest.mark.parametrize("axis", [(0, 0, 1), (1, 0, 0), (0, -1, 0), (0.48, 0.64, 0.6)],
                         ids=["z", "x", "-y", "oblique"])
def test_constant_rate_is_realised_in_steady_state(axis):
    r = deg_s_to_rad_s(50.0)
    p = Profile((ConstantRate(axis=axis, rate_rad_s=r, duration_s=2.0, ramp_s=0.5, align_s=1.0),))
    run = TABLE.run(p, 100.0)
    a = np.array(axis, dtype=float)
    t0 = 1.0 + 0.5 + TABLE.params.settle_s
    win = (run.time_s >= t0) & (run.time_s < 3.5)
    w = run.omega_body_rad_s[win]
    along = w @ a
    # the servo has velocity and friction feedforward: no steady-state rate error, rounding
    # only (observed ~1e-13 relative); cos of the gimbal deflection below adds < 1e-10
    assert np.max(np.abs(along - r)) < 1e-9 * r
    (seg,) = run.tracking.segments
    assert seg.steady_rate_error_rad_s[0] == pytest.approx(np.mean(along) - r, abs=1e-15)
    # across the axis: gyroscopic torque ω²·ΔI (ΔI <= 0.04 kg m², ω = 0.87 rad/s) deflects the
    # inner gimbal by ~ τ/kp <= 0.03/1579 = 2e-5 rad; zero when the axis is a principal axis
    cross = np.linalg.norm(w - along[:, None] * a, axis=1)
    principal = np.count_nonzero(a) == 1
    assert np.max(cross) < (1e-12 if principal else 3e-5) * r
    assert seg.steady_cross_axis_rad_s[0] == pytest.approx(np.max(cross), rel=1e-12, abs=1e-18)


def _servo_response(f_hz, params: TableParams, dt):
    """Realised / commanded rate of the outer loop, as MuJoCo integrates it.

    implicitfast Euler with damping C = kv + c implicit, command previewed by dt/2:
        (I + dt C) v[j+1] = I v[j] + dt (kp (qc[j] - q[j]) + C q̇c[j]),  q[j+1] = q[j] + dt v[j+1]
    For a tone, z = exp(jω dt) and the preview multiplies by exp(jω dt/2).
    """
    kp, kv = params.gains
    I = params.nominal_inertia_kg_m2[0]       # level platform: mass matrix is diagonal
    C = kv[0] + params.damping_n_m_s[0]
    w = 2 * math.pi * f_hz
    z = np.exp(1j * w * dt)
    return (np.exp(1j * w * dt / 2) * dt * (kp[0] + 1j * w * C)
            / (1j * w * ((I + dt * C) * z - I + kp[0] * dt ** 2 * z / (z - 1))))


@pytest.mark.parametrize("amp_deg_s,f_hz,duration", [(20.0, 0.5, 6.0), (5.0, 0.05, 40.0)])
def test_sinusoid_amplitude_and_phase(amp_deg_s, f_hz, duration):
    A = deg_s_to_rad_s(amp_deg_s)
    p = Profile((Sinusoid(axis=(0, 0, 1), amplitude_rad_s=A, frequency_hz=f_hz, duration_s=duration),))
    run = TABLE.run(p, 100.0)
    (seg,) = run.tracking.segments
    # independent least-squares fit on the truth, same window (after settling)
    win = run.time_s >= TABLE.params.settle_s
    t = run.time_s[win]
    X = np.column_stack([np.sin(2 * np.pi * f_hz * t), np.cos(2 * np.pi * f_hz * t), np.ones_like(t)])
    (a, b, _), *_ = np.linalg.lstsq(X, run.omega_body_rad_s[win, 2], rcond=None)
    assert seg.amplitude_ratio == pytest.approx(math.hypot(a, b) / A, rel=1e-12)
    assert seg.phase_lag_rad == pytest.approx(-math.atan2(b, a), abs=1e-12)
    # the closed-form response of the discretised servo; the start transient has decayed
    # by e^-20 in the fit window, so agreement to ~1e-9 is expected
    H = _servo_response(f_hz, TABLE.params, run.physics_dt_s)
    assert seg.amplitude_ratio == pytest.approx(abs(H), abs=1e-9)
    assert seg.phase_lag_rad == pytest.approx(-np.angle(H), abs=1e-9)
    # the stated bounds: a 20 Hz loop gains |1 + (f/20)²|, lags < 0.01 deg
    assert abs(seg.amplitude_ratio - 1) < 1e-3
    assert abs(seg.phase_lag_rad) < deg_to_rad(0.01)


def test_static_hour_is_exactly_at_rest():
    run = TABLE.run(load_profile(PROFILES / "p003_static_1h.toml"), 100.0)
    assert run.time_s.shape == (360_000,)
    assert run.time_s[-1] == pytest.approx(3599.99, abs=1e-9)
    np.testing.assert_array_equal(run.omega_body_rad_s, 0.0)
    np.testing.assert_array_equal(run.quat_wxyz, np.tile([1.0, 0, 0, 0], (360_000, 1)))
    np.testing.assert_array_equal(run.joint_angles_rad, 0.0)
    assert run.repeated > 3_500_000               # the rest state was repeated, not stepped


def test_repeating_the_rest_state_is_exactly_what_stepping_gives():
    p = Profile((Static(duration_s=4.0, orientation=Orientation(up_axis=(1, 0, 0)), transition_s=1.0),
                 ConstantRate(axis=(0, 0, 1), rate_rad_s=0.3, duration_s=1.0, ramp_s=0.5, align_s=1.0),
                 Static(duration_s=3.0)))
    fast = TABLE.run(p, 100.0, skip_rest=True)
    slow = TABLE.run(p, 100.0, skip_rest=False)
    assert fast.repeated >= 2000 and slow.repeated == 0
    assert fast.stepped + fast.repeated == slow.stepped
    for name in ("omega_body_rad_s", "quat_wxyz", "joint_angles_rad", "joint_rates_rad_s"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name))


def test_multi_position_holds_the_commanded_orientations():
    ups = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0.6, 0, -0.8)]
    p = Profile((MultiPosition(orientations=tuple(Orientation(up_axis=u) for u in ups),
                               hold_s=1.0, transition_s=1.0),
                 Static(duration_s=1.0, orientation=Orientation(gimbal_rad=tuple(deg_to_rad(
                     np.array([30.0, -20.0, 45.0])))), transition_s=1.0)))
    run = TABLE.run(p, 100.0)
    R = Rotation.from_quat(run.quat_wxyz, scalar_first=True)
    for k, u in enumerate(ups):
        end = (2 * k + 2) * 100 - 1              # last sample of hold k
        up = R[end].inv().apply([0, 0, 1])        # body vector pointing up
        assert math.acos(min(1.0, float(up @ np.array(u)))) < 1e-6
    # the explicit gimbal angles: the attitude is Rz(30°) Rx(-20°) Ry(45°)
    ref = Rotation.from_euler("ZXY", [30.0, -20.0, 45.0], degrees=True)
    assert (ref.inv() * R[-1]).magnitude() < 1e-6
    (seg1, seg2) = run.tracking.segments
    assert seg1.hold_attitude_error_rad < 1e-6 and seg2.hold_attitude_error_rad < 1e-6


def test_sample_rates_fall_on_physics_steps():
    assert [steps_per_sample(fs, 1000.0) for fs in (100.0, 62.5, 50.0, 333.0, 1000.0, 2000.0)] == \
           [10, 16, 20, 4, 1, 1]
    assert n_samples(600.0, 62.5) == 37_500 and n_samples(10.005, 100.0) == 1001
    p = Profile((Sinusoid(axis=(0, 0, 1), amplitude_rad_s=0.3, frequency_hz=0.7, duration_s=3.2),))
    ref = TABLE.run(p, 1000.0)                  # dt = 1 ms, every step
    for fs, k in ((100.0, 10), (62.5, 16), (50.0, 20)):
        run = TABLE.run(p, fs)
        assert run.physics_dt_s == ref.physics_dt_s == 1e-3
        np.testing.assert_array_equal(run.omega_body_rad_s, ref.omega_body_rad_s[::k])
        np.testing.assert_allclose(run.time_s, np.arange(run.time_s.size) / fs, rtol=0, atol=0)


@pytest.mark.parametrize("name", sorted(p.stem for p in PROFILES.glob("*.toml")))
def test_shipped_profiles_run(name):
    p = load_profile(PROFILES / f"{name}.toml")
    T = min(p.duration_s, 20.0)
    truth = compute_truth(p, 100.0, duration_s=T, cache=False)
    assert truth.n_samples == n_samples(T, 100.0)
    assert np.all(np.isfinite(truth.omega_body_rad_s))
    peak = np.abs(truth.command_body_rad_s).max()
    # a 20 Hz servo follows these profiles to < 1e-2 of their peak rate (rms)
    assert truth.tracking.rms_error_rad_s <= 1e-2 * max(peak, 1e-9)


# -- cache -------------------------------------------------------------------------

@pytest.fixture
def counted(monkeypatch, tmp_path):
    calls = []
    real = truth_mod._run_table

    def run(*args, **kw):
        calls.append(args)
        return real(*args, **kw)

    monkeypatch.setattr(truth_mod, "_run_table", run)
    monkeypatch.setenv("GYROARRAY_CACHE", str(tmp_path / "cache"))
    return calls


SHORT = PROFILES / "p002_swing_20dps_0p5hz.toml"


def test_cache_hit_returns_identical_bits_without_recomputing(counted, tmp_path):
    a = compute_truth(SHORT, 100.0, duration_s=4.0)
    b = compute_truth(SHORT, 100.0, duration_s=4.0)
    assert len(counted) == 1
    for name in ("time_s", "omega_body_rad_s", "quat_wxyz", "command_body_rad_s", "joint_angles_rad"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
        assert not getattr(b, name).flags.writeable
    assert a.tracking == b.tracking and a.meta == b.meta
    files = list((tmp_path / "cache").iterdir())
    assert [f.suffix for f in files] == [".npz"]           # no temporary file left behind
    with np.load(files[0], allow_pickle=False) as z:        # plain arrays, no pickle
        assert z["omega_body_rad_s"].shape == (400, 3)


def test_cache_key_changes_with_every_input(tmp_path):
    toml = SHORT.read_bytes()
    (tmp_path / "p.toml").write_bytes(toml)
    base = truth_key(tmp_path / "p.toml", 100.0)
    assert base == truth_key(SHORT, 100.0)                  # content, not path
    assert truth_key(tmp_path / "p.toml", 62.5) != base
    assert truth_key(tmp_path / "p.toml", 100.0, duration_s=10.0) != base
    assert truth_key(tmp_path / "p.toml", 100.0, table=TableParams(bandwidth_hz=25.0)) != base
    (tmp_path / "p.toml").write_bytes(toml.replace(b"20.0", b"20.5", 1))
    assert truth_key(tmp_path / "p.toml", 100.0) != base
    (tmp_path / "p.toml").write_bytes(toml + b" ")
    assert truth_key(tmp_path / "p.toml", 100.0) != base
    # a CSV byte changes the key of the profile that reads it
    (tmp_path / "c.toml").write_bytes((PROFILES / "example_rate_csv.toml").read_bytes())
    csv = (PROFILES / "example_rate_csv.csv").read_bytes()
    (tmp_path / "example_rate_csv.csv").write_bytes(csv)
    k1 = truth_key(tmp_path / "c.toml", 100.0)
    (tmp_path / "example_rate_csv.csv").write_bytes(csv[:-2] + b"1\n")
    assert truth_key(tmp_path / "c.toml", 100.0) != k1


@pytest.mark.parametrize("damage", ["garbage", "truncated", "other key"])
def test_damaged_cache_file_is_ignored_and_recomputed(counted, tmp_path, damage):
    good = compute_truth(SHORT, 100.0, duration_s=2.0)
    path = tmp_path / "cache" / f"{good.meta.key}.npz"
    data = path.read_bytes()
    if damage == "garbage":
        path.write_bytes(b"not a zip file at all")
    elif damage == "truncated":
        path.write_bytes(data[: len(data) // 2])
    else:   # a valid file holding another truth under this name
        other = compute_truth(SHORT, 100.0, duration_s=3.0)
        os.replace(tmp_path / "cache" / f"{other.meta.key}.npz", path)
    again = compute_truth(SHORT, 100.0, duration_s=2.0)
    assert len(counted) == (3 if damage == "other key" else 2)
    np.testing.assert_array_equal(again.omega_body_rad_s, good.omega_body_rad_s)
    third = compute_truth(SHORT, 100.0, duration_s=2.0)      # rewritten: now a hit
    assert len(counted) == (3 if damage == "other key" else 2)
    np.testing.assert_array_equal(third.omega_body_rad_s, good.omega_body_rad_s)


def test_truth_attitude_forms_agree():
    truth = compute_truth(PROFILES / "example_six_position.toml", 50.0, duration_s=25.0, cache=False)
    R = Rotation.from_quat(truth.quat_wxyz, scalar_first=True).as_matrix()
    np.testing.assert_allclose(truth.rotation_matrices, R, rtol=0, atol=1e-14)
    assert truth.meta.steps_per_sample == 20 and truth.meta.physics_dt_s == 1e-3
