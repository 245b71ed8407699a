"""Motion profiles: gimbal kinematics, the commanded trajectory, and the file format.

Outside truth: scipy's Euler-angle rotations for the gimbal attitude, finite
differences for every derivative, an independent quaternion integration for
the ``rate_csv`` kinematics, and the papers' own numbers for their profiles.
No physics runs here (see test_table.py).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from gyroarray.core.errors import InputError
from gyroarray.sim.profiles import (ConstantRate, MultiPosition, Orientation, Profile, RateCSV,
                                    RateSteps, Sinusoid, Static, body_jacobian, body_rate,
                                    gimbal_for_up_axis, gimbal_quaternion, gimbal_rotation,
                                    joint_rates, load_profile, up_vector)
from gyroarray.core.units import deg_s_to_rad_s, deg_to_rad

PROFILES = Path(__file__).resolve().parents[1] / "src" / "gyroarray" / "data" / "scenarios" / "profiles"
RNG_SEED = 20240611


# -- kinematics --------------------------------------------------------------

def test_gimbal_attitude_is_intrinsic_zxy_euler():
    rng = np.random.default_rng(RNG_SEED)
    q = rng.uniform(-4, 4, (200, 3))
    ref = Rotation.from_euler("ZXY", q)     # intrinsic: Rz(q_o) Rx(q_m) Ry(q_i)
    # both are products of three exact rotations: agree to a few ulps
    np.testing.assert_allclose(gimbal_rotation(q), ref.as_matrix(), rtol=0, atol=2e-15)
    quat = gimbal_quaternion(q)
    sref = ref.as_quat(scalar_first=True)
    sign = np.sign(np.sum(quat * sref, axis=1))[:, None]
    np.testing.assert_allclose(quat, sign * sref, rtol=0, atol=2e-15)
    np.testing.assert_array_equal(gimbal_rotation(np.zeros(3)), np.eye(3))


def test_body_jacobian_is_the_derivative_of_the_attitude():
    rng = np.random.default_rng(RNG_SEED + 1)
    q = rng.uniform(-3, 3, (100, 3))
    qd = rng.normal(size=(100, 3))
    h = 1e-5
    dR = (gimbal_rotation(q + h * qd) - gimbal_rotation(q - h * qd)) / (2 * h)
    W = np.einsum("nji,njk->nik", gimbal_rotation(q), dR)      # Rᵀ Ṙ = [ω]×
    w_fd = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    # central difference: truncation h²|q̇|³/6 ~ 1e-9, rounding 1e-16/h ~ 1e-11
    np.testing.assert_allclose(body_rate(q, qd), w_fd, rtol=0, atol=1e-8)
    np.testing.assert_allclose(np.linalg.det(body_jacobian(q)), np.cos(q[:, 1]), atol=1e-15)


def test_joint_rates_invert_the_jacobian_away_from_gimbal_lock():
    rng = np.random.default_rng(RNG_SEED + 2)
    q = rng.uniform(-3, 3, (300, 3))
    q[:, 1] = rng.uniform(-1.4, 1.4, 300)          # |cos q_m| >= 0.17
    w = rng.normal(size=(300, 3))
    # cond(J) <= 1/0.17: error <= ~10 ulp
    np.testing.assert_allclose(body_rate(q, joint_rates(q, w)), w, rtol=0, atol=1e-14)


def test_up_axis_orientation_points_the_axis_up_and_keeps_the_outer_gimbal():
    rng = np.random.default_rng(RNG_SEED + 3)
    axes = rng.normal(size=(100, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    axes = np.vstack([axes, np.eye(3), -np.eye(3)])
    for a in axes:
        q = gimbal_for_up_axis(a, [0.7, 0.2, 5.0])
        np.testing.assert_allclose(up_vector(q), a, rtol=0, atol=2e-15)
        assert q[0] == 0.7
        assert abs(q[2] - 5.0) <= math.pi + 1e-12        # inner angle taken nearest
    # body y up is gimbal lock: any inner angle works, so the inner gimbal stays
    assert gimbal_for_up_axis([0, 1, 0], [0.7, 0.2, 5.0])[2] == 5.0


# -- commanded trajectories ---------------------------------------------------

def _fd_check(profile: Profile, n=2000, seed=0):
    """q̇_c against a central difference of q_c, at times away from piece boundaries."""
    rng = np.random.default_rng(seed)
    h = 1e-5
    edges = np.array([p.t0 for p in profile.pieces] + [profile.duration_s])
    t = rng.uniform(0, profile.duration_s, n)
    t = t[np.min(np.abs(t[:, None] - edges[None, :]), axis=1) > 10 * h]
    c = profile.command(t)
    fd = (profile.command(t + h).q_rad - profile.command(t - h).q_rad) / (2 * h)
    return c, fd


@pytest.mark.parametrize("name", ["example_multi_axis", "example_six_position", "example_rate_csv",
                                  "p002_swing_20dps_0p5hz", "p002_constant_80dps"])
def test_commanded_angles_rates_and_body_rate_are_consistent(name):
    p = load_profile(PROFILES / f"{name}.toml")
    c, fd = _fd_check(p)
    # truncation h²/6·|q⃛| (|q⃛| < 100 rad/s³ here) ~ 2e-9; rounding |q|·1e-16/h ~ 1e-9;
    # rate_csv: Hermite interpolation of RK4 nodes (h = 10 ms) adds ~1e-8
    np.testing.assert_allclose(c.qd_rad_s, fd, rtol=0, atol=5e-7)
    np.testing.assert_allclose(body_rate(c.q_rad, c.qd_rad_s), c.omega_body_rad_s, rtol=0, atol=1e-14)


def test_constant_rate_command_is_exact_rate_times_axis():
    a = (0.6, 0.0, 0.8)
    r = deg_s_to_rad_s(30.0)
    p = Profile((ConstantRate(axis=a, rate_rad_s=r, duration_s=4.0, ramp_s=2.0, align_s=3.0),))
    assert p.duration_s == 3.0 + 2.0 + 4.0 + 2.0
    hold = p.command(np.linspace(5.0, 9.0, 101, endpoint=False))
    np.testing.assert_array_equal(hold.omega_body_rad_s, r * np.array(a)[None, :].repeat(101, 0))
    # after alignment the axis points up, so only the outer gimbal turns
    np.testing.assert_allclose(up_vector(hold.q_rad), np.array(a)[None, :].repeat(101, 0), atol=1e-15)
    np.testing.assert_array_equal(hold.qd_rad_s[:, 1:], 0.0)
    # a minimum-jerk ramp covers half the angle of the full rate: ∫ s = 1/2
    outer = p.command(np.array([3.0, 5.0, 9.0, 11.0])).q_rad[:, 0]
    np.testing.assert_allclose(np.diff(outer), [r * 2.0 / 2, r * 4.0, r * 2.0 / 2], rtol=1e-14)
    # ramps start and end at rest, with zero acceleration (C² joints)
    c = p.command(np.array([3.0, 11.0]))
    np.testing.assert_allclose(c.omega_body_rad_s, 0.0, atol=1e-17)


def test_rate_about_minus_axis_turns_the_outer_gimbal_backwards_without_flipping():
    r = deg_s_to_rad_s(10.0)
    p = Profile((ConstantRate(axis=(0, 0, -1), rate_rad_s=r, duration_s=1.0, ramp_s=0.0),))
    c = p.command(np.array([0.5]))
    np.testing.assert_array_equal(c.q_rad[0, 1:], 0.0)        # no re-orientation needed
    assert c.qd_rad_s[0, 0] == -r
    np.testing.assert_array_equal(c.omega_body_rad_s[0], [0.0, 0.0, -r])


def test_sinusoid_command_matches_the_formula():
    A, f, phi = deg_s_to_rad_s(20.0), 0.5, deg_to_rad(30.0)
    p = Profile((Sinusoid(axis=(0, 0, 1), amplitude_rad_s=A, frequency_hz=f, duration_s=10.0,
                          phase_rad=phi),))
    t = np.linspace(0, 10.0, 1001)
    c = p.command(t)
    np.testing.assert_allclose(c.omega_body_rad_s[:, 2], A * np.sin(2 * np.pi * f * t + phi),
                               rtol=0, atol=1e-16)
    np.testing.assert_allclose(c.q_rad[:, 0],
                               A / (2 * np.pi * f) * (np.cos(phi) - np.cos(2 * np.pi * f * t + phi)),
                               rtol=0, atol=1e-15)


def test_rate_steps_levels_and_holds():
    rates = (5.0, -10.0, 20.0)
    p = Profile((RateSteps(axis=(1, 0, 0), rates_rad_s=tuple(deg_s_to_rad_s(r) for r in rates),
                           hold_s=(2.0, 3.0, 4.0), ramp_s=1.0, align_s=2.0),))
    assert p.duration_s == 2.0 + 4 * 1.0 + 9.0
    mids = np.array([2.0 + 1 + 1.0, 2.0 + 1 + 2 + 1 + 1.5, 2.0 + 1 + 2 + 1 + 3 + 1 + 2.0])
    np.testing.assert_array_equal(p.command(mids).omega_body_rad_s[:, 0],
                                  [deg_s_to_rad_s(r) for r in rates])


def _quat_integrate(t_rows, w_rows, q0):
    """Independent check: integrate q̇ = ½ q ⊗ (0, ω) row interval by row interval
    (ω is linear, hence smooth, inside each) with tight tolerances."""
    def rhs(t, q, ta, tb, wa, wb):
        w = wa + (wb - wa) * (t - ta) / (tb - ta)
        a, b, c, d = q
        return 0.5 * np.array([-b * w[0] - c * w[1] - d * w[2],
                               a * w[0] + c * w[2] - d * w[1],
                               a * w[1] - b * w[2] + d * w[0],
                               a * w[2] + b * w[1] - c * w[0]])
    q = np.asarray(q0, dtype=float)
    for k in range(len(t_rows) - 1):
        args = (t_rows[k], t_rows[k + 1], w_rows[k], w_rows[k + 1])
        q = solve_ivp(rhs, args[:2], q, method="DOP853", rtol=1e-13, atol=1e-14, args=args).y[:, -1]
    return q


def test_rate_csv_follows_the_csv_and_integrates_the_attitude():
    p = load_profile(PROFILES / "example_rate_csv.toml")
    seg = p.segments[0]
    assert isinstance(seg, RateCSV) and seg.time_s.size == 201
    # the commanded body rate is the CSV, exactly at its rows
    c = p.command(seg.time_s)
    np.testing.assert_allclose(c.omega_body_rad_s, seg.omega_rad_s, rtol=0, atol=1e-15)
    # the gimbal angles reproduce the attitude obtained by integrating the rates directly
    q_end = _quat_integrate(seg.time_s, seg.omega_rad_s, np.array([1.0, 0, 0, 0]))
    q_cmd = gimbal_quaternion(p.command(np.array([seg.duration_s])).q_rad[0])
    angle = 2 * math.asin(min(1.0, np.linalg.norm(
        (Rotation.from_quat(q_cmd, scalar_first=True).inv()
         * Rotation.from_quat(q_end, scalar_first=True)).as_quat()[:3])))
    # RK4 with h <= 10 ms on rates ~0.3 rad/s: local error ~h⁵|ω|⁵/100 ~ 1e-15, 1000 steps
    assert angle < 1e-10


def test_paper_profiles_hold_the_papers_numbers():
    expected = {  # file: (kind, amplitude or rate [deg/s], frequency [Hz], duration [s])
        "p003_static_1h": ("static", None, None, 3600.0),
        "p002_constant_10dps": ("constant_rate", 10.0, None, 300.0),
        "p002_constant_30dps": ("constant_rate", 30.0, None, 300.0),
        "p002_constant_50dps": ("constant_rate", 50.0, None, 300.0),
        "p002_constant_80dps": ("constant_rate", 80.0, None, 300.0),
        "p002_swing_20dps_0p1hz": ("sinusoid", 20.0, 0.1, 600.0),
        "p002_swing_20dps_0p3hz": ("sinusoid", 20.0, 0.3, 600.0),
        "p002_swing_20dps_0p5hz": ("sinusoid", 20.0, 0.5, 600.0),
        "p003_sine_5dps_0p03hz": ("sinusoid", 5.0, 0.03, 600.0),   # 5 sin(0.06πt), T = 1/6 h
        "p003_swing_5dps_0p05hz": ("sinusoid", 5.0, 0.05, 600.0),
        "p003_swing_5dps_0p1hz": ("sinusoid", 5.0, 0.1, 600.0),
    }
    found = {p.stem for p in PROFILES.glob("p00*.toml")}
    assert found == set(expected)
    for name, (kind, value, f, dur) in expected.items():
        p = load_profile(PROFILES / f"{name}.toml")
        (seg,) = p.segments
        assert seg.kind == kind and seg.duration_s == dur
        if kind == "constant_rate":
            assert seg.rate_rad_s == deg_s_to_rad_s(value) and seg.axis == (0.0, 0.0, 1.0)
        if kind == "sinusoid":
            assert seg.amplitude_rad_s == deg_s_to_rad_s(value) and seg.frequency_hz == f
            assert seg.axis == (0.0, 0.0, 1.0) and seg.phase_rad == 0.0
            # whole periods: the swing starts and ends at rest
            assert abs(seg.duration_s * f - round(seg.duration_s * f)) < 1e-9


def test_every_shipped_profile_loads():
    names = sorted(p.name for p in PROFILES.glob("*.toml"))
    assert len(names) >= 14
    for name in names:
        assert load_profile(PROFILES / name).duration_s > 0


# -- fingerprints ---------------------------------------------------------------

def test_fingerprint_covers_every_byte_of_toml_and_csv(tmp_path):
    toml = (PROFILES / "example_rate_csv.toml").read_bytes()
    csv = (PROFILES / "example_rate_csv.csv").read_bytes()
    (tmp_path / "p.toml").write_bytes(toml)
    (tmp_path / "example_rate_csv.csv").write_bytes(csv)
    base = load_profile(tmp_path / "p.toml").fingerprint
    assert base == load_profile(PROFILES / "example_rate_csv.toml").fingerprint   # content only
    (tmp_path / "p.toml").write_bytes(toml + b"\n# a comment\n")
    assert load_profile(tmp_path / "p.toml").fingerprint != base
    (tmp_path / "p.toml").write_bytes(toml)
    (tmp_path / "example_rate_csv.csv").write_bytes(csv.replace(b"0.050000,", b"0.050001,", 1))
    assert load_profile(tmp_path / "p.toml").fingerprint != base


def test_programmatic_profiles_fingerprint_their_values():
    a = Profile((Static(duration_s=10.0),))
    assert a.fingerprint == Profile((Static(duration_s=10.0),)).fingerprint
    assert a.fingerprint != Profile((Static(duration_s=10.0 + 1e-12),)).fingerprint


# -- bad input ------------------------------------------------------------------

SEG = ('[[segment]]\nkind = "constant_rate"\naxis = [0, 0, 1]\nrate_deg_s = 10.0\n'
       'duration_s = 5.0\nramp_s = 1.0\n')

BAD = [  # id, TOML text, CSV text or None, (file is 'toml'|'csv', column, line)
    ("unknown top key", 'foo = 1\n' + SEG, None, ("toml", "foo", 1)),
    ("unknown segment key", SEG + "rate_dps = 3\n", None, ("toml", "segment[1].rate_dps", 7)),
    ("unknown kind", '[[segment]]\nkind = "spin"\nduration_s = 1\n', None, ("toml", "segment[1].kind", 2)),
    ("missing kind", '[[segment]]\nduration_s = 1\n', None, ("toml", "segment[1].kind", 1)),
    ("negative duration", SEG.replace("duration_s = 5.0", "duration_s = -5.0"), None,
     ("toml", "segment[1].duration_s", 5)),
    ("zero axis", SEG.replace("[0, 0, 1]", "[0, 0, 0]"), None, ("toml", "segment[1].axis", 3)),
    ("non-unit axis", SEG.replace("[0, 0, 1]", "[0, 0, 2]"), None, ("toml", "segment[1].axis", 3)),
    ("axis of 2 numbers", SEG.replace("[0, 0, 1]", "[0, 1]"), None, ("toml", "segment[1].axis", 3)),
    ("non-numeric rate", SEG.replace("10.0", '"ten"'), None, ("toml", "segment[1].rate_deg_s", 4)),
    ("boolean ramp", SEG.replace("ramp_s = 1.0", "ramp_s = true"), None, ("toml", "segment[1].ramp_s", 6)),
    ("nan rate", SEG.replace("10.0", "nan"), None, ("toml", "segment[1].rate_deg_s", 4)),
    ("missing ramp", SEG.replace("ramp_s = 1.0\n", ""), None, ("toml", "segment[1].ramp_s", 1)),
    ("zero frequency", '[[segment]]\nkind = "sinusoid"\naxis = [0,0,1]\namplitude_deg_s = 5\n'
     'frequency_hz = 0\nduration_s = 10\n', None, ("toml", "segment[1].frequency_hz", 5)),
    ("hold list length", '[[segment]]\nkind = "rate_steps"\naxis = [0,0,1]\nrates_deg_s = [1, 2]\n'
     'hold_s = [1, 2, 3]\nramp_s = 1\n', None, ("toml", "segment[1].hold_s", 5)),
    ("orientation change without transition",
     '[[segment]]\nkind = "static"\nduration_s = 5\nup_axis = [1, 0, 0]\n', None,
     ("toml", "segment[1].transition_s", 1)),
    ("axis not up without align_s", SEG + SEG.replace("[0, 0, 1]", "[1, 0, 0]"), None,
     ("toml", "segment[2].align_s", 7)),
    ("no segments", 'description = "empty"\n', None, ("toml", "segment", None)),
    ("TOML syntax", SEG + "ramp_s = = 2\n", None, ("toml", 10, 7)),
    ("missing CSV", '[[segment]]\nkind = "rate_csv"\nfile = "nope.csv"\n', None,
     ("toml", "segment[1].file", 3)),
    ("non-numeric CSV cell", '[[segment]]\nkind = "rate_csv"\nfile = "r.csv"\n',
     "# rates\ntime_s,wx_deg_s,wy_deg_s,wz_deg_s\n0,0,0,0\n1,0,abc,0\n", ("csv", "wy_deg_s", 4)),
    ("CSV time not increasing", '[[segment]]\nkind = "rate_csv"\nfile = "r.csv"\n',
     "time_s,wx_deg_s,wy_deg_s,wz_deg_s\n0,0,0,0\n1,0,0,0\n1,0,0,0\n", ("csv", "time_s", 4)),
    ("CSV unknown column", '[[segment]]\nkind = "rate_csv"\nfile = "r.csv"\n',
     "time_s,wx_deg_s,wy_deg_s,wz_deg_s,wq\n0,0,0,0,0\n1,0,0,0,0\n", ("csv", "wq", 1)),
    ("CSV missing column", '[[segment]]\nkind = "rate_csv"\nfile = "r.csv"\n',
     "time_s,wx_deg_s,wy_deg_s\n0,0,0\n1,0,0\n", ("csv", "wz_deg_s", 1)),
    ("CSV short row", '[[segment]]\nkind = "rate_csv"\nfile = "r.csv"\n',
     "time_s,wx_deg_s,wy_deg_s,wz_deg_s\n0,0,0,0\n1,0,0\n", ("csv", None, 3)),
    # 30 deg/s about x from level for 4 s turns the middle gimbal through 80 deg at t = 80/30 s
    ("CSV to gimbal lock", '[[segment]]\nkind = "rate_csv"\nfile = "r.csv"\n',
     "time_s,wx_deg_s,wy_deg_s,wz_deg_s\n" + "".join(f"{k * 0.5},30,0,0\n" for k in range(9)),
     ("csv", "time_s", 2 + 6)),
]


@pytest.mark.parametrize("name,toml,csv,where", BAD, ids=[b[0] for b in BAD])
def test_bad_profiles_are_refused_with_file_key_and_line(tmp_path, name, toml, csv, where):
    path = tmp_path / "bad.toml"
    path.write_text(toml, encoding="utf-8")
    files = [path]
    if csv is not None:
        (tmp_path / "r.csv").write_text(csv, encoding="utf-8")
        files.append(tmp_path / "r.csv")
    before = [f.read_bytes() for f in files]
    with pytest.raises(InputError) as info:
        load_profile(path)
    err = info.value
    which, column, line = where
    assert err.file == str(path if which == "toml" else tmp_path / "r.csv")
    assert err.column == column
    assert err.line == line
    assert str(err).startswith(err.file)          # the CLI prints one line naming the file
    assert "\n" not in str(err)
    assert [f.read_bytes() for f in files] == before


def test_segment_values_are_checked_in_si_too():
    with pytest.raises(InputError, match="duration_s must be > 0"):
        Static(duration_s=0.0)
    with pytest.raises(InputError, match="not a unit vector"):
        ConstantRate(axis=(1, 1, 0), rate_rad_s=1.0, duration_s=1.0, ramp_s=0.0)
    with pytest.raises(InputError, match="exactly one"):
        Orientation()
    with pytest.raises(InputError, match="at least one"):
        MultiPosition(orientations=(), hold_s=1.0, transition_s=1.0)
    with pytest.raises(InputError, match="start at 0"):
        RateCSV(time_s=[1.0, 2.0], omega_rad_s=np.zeros((2, 3)))
    with pytest.raises(InputError, match="at least one"):
        Profile(())
