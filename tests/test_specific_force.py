"""The specific force the table makes: MuJoCo's accelerometers against the closed form.

Outside truth: the rigid-body closed form f = Rᵀg + α × r + ω × (ω × r)
written here from the table's realised attitude (scipy's quaternion
rotation, not the project's), rate and angular acceleration; the gimbal
kinematics (up vector = first column of J(q), checked against scipy in
test_profiles.py) applied to MuJoCo's encoders; and the derivative of the
realised rate (central differences, error bound from Taylor's theorem).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.sim.profiles import (ConstantRate, MultiPosition, Orientation, Profile, Sinusoid,
                                    Static, Tumble, up_vector)
from gyroarray.sim.table import RateTable
from gyroarray.sim.truth import compute_truth, specific_force
from gyroarray.core.units import deg_s_to_rad_s, deg_to_rad

G0 = 9.80665
TABLE = RateTable()

# every kind of motion: holds in other attitudes, a rate about an oblique axis, a swing,
# tumbles about y (tilted) and x (the middle gimbal turning through ±90 deg)
PROFILE = Profile((
    Static(duration_s=0.3),
    MultiPosition(orientations=(Orientation(up_axis=(1.0, 0.0, 0.0)),
                                Orientation(up_axis=(0.0, -0.6, 0.8))), hold_s=0.3, transition_s=0.4),
    ConstantRate(axis=(0.48, 0.64, 0.6), rate_rad_s=deg_s_to_rad_s(90.0), duration_s=0.5,
                 ramp_s=0.3, align_s=0.5),
    Sinusoid(axis=(1.0, 0.0, 0.0), amplitude_rad_s=deg_s_to_rad_s(60.0), frequency_hz=2.0,
             duration_s=1.0, align_s=0.5),
    Tumble(axis=(0.0, 1.0, 0.0), rate_rad_s=deg_s_to_rad_s(120.0), duration_s=1.0, ramp_s=0.3,
           tilt_rad=deg_to_rad(25.0), align_s=0.5),
    Tumble(axis=(0.6, 0.0, -0.8), rate_rad_s=deg_s_to_rad_s(-150.0), duration_s=1.5, ramp_s=0.3,
           align_s=0.5),
))
# gyros up to 15 cm from the origin, in every direction
POSITIONS = np.array([[0.05, 0.0, 0.01], [0.0, 0.08, -0.02], [-0.1, 0.03, 0.0],
                      [0.02, -0.04, 0.15], [0.0, 0.0, 0.0]])
LAYOUT = Layout.conical(2, 5, deg_to_rad(60.0)).with_positions(POSITIONS)


@pytest.fixture(scope="module")
def run():
    return TABLE.run(PROFILE, 100.0, layout=LAYOUT)


def closed_form(quat_wxyz, omega, alpha, r):
    """f = Rᵀ g + α × r + ω × (ω × r), g = [0, 0, g0] (up), platform frame."""
    R = Rotation.from_quat(quat_wxyz[:, [1, 2, 3, 0]]).as_matrix()      # platform -> level
    f0 = np.einsum("nji,j->ni", R, np.array([0.0, 0.0, G0]))             # Rᵀ g
    return f0 + np.cross(alpha, r) + np.cross(omega, np.cross(omega, r))


def test_mujoco_accelerometers_are_the_closed_form(run):
    w, a = run.omega_body_rad_s, run.angular_accel_rad_s2
    # the motion is rich enough that every term matters (else the check would be vacuous)
    assert np.abs(w).max(axis=0).min() > 1.0 and np.abs(a).max(axis=0).min() > 5.0   # rad/s, rad/s²
    f_sites = run.site_specific_force_m_s2
    for k, r in enumerate(POSITIONS):
        lever = np.abs(f_sites[:, k] - run.specific_force_m_s2).max()
        assert (lever > 0.5) == bool(r.any())                  # centripetal + tangential, m/s²
        # same state, same pass: rounding only (measured 1.1e-14 m/s²)
        np.testing.assert_allclose(f_sites[:, k], closed_form(run.quat_wxyz, w, a, r),
                                   rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.specific_force_m_s2, closed_form(run.quat_wxyz, w, a, np.zeros(3)),
                               rtol=0, atol=1e-9)


def test_origin_force_is_gravity_along_the_encoders_up_vector(run):
    # the origin does not move: f_0 = g0 · (the platform vector pointing up) = g0 J(q)[:, 0]
    np.testing.assert_allclose(run.specific_force_m_s2, G0 * up_vector(run.joint_angles_rad),
                               rtol=0, atol=1e-12)
    np.testing.assert_array_equal(run.specific_force_m_s2[0], [0.0, 0.0, G0])   # rest, level, z up


def test_truth_carries_the_force_at_every_gyro(run):
    truth = compute_truth(PROFILE, 100.0, cache=False)
    np.testing.assert_array_equal(truth.specific_force_m_s2, run.specific_force_m_s2)
    np.testing.assert_allclose(specific_force(truth, LAYOUT), run.site_specific_force_m_s2,
                               rtol=0, atol=1e-9)
    assert specific_force(truth, Layout.triad()).shape == (truth.n_samples, 3, 3)
    np.testing.assert_array_equal(specific_force(truth, Layout.triad())[:, 2],
                                  truth.specific_force_m_s2)   # no positions: all at the origin


def test_angular_acceleration_is_the_realised_one():
    f, amp = 1.0, deg_s_to_rad_s(20.0)
    p = Profile((Sinusoid(axis=(0.0, 0.0, 1.0), amplitude_rad_s=amp, frequency_hz=f,
                          duration_s=6.0),))
    run = TABLE.run(p, 100.0)
    dt, dt_phys = 0.01, run.physics_dt_s
    w, a = run.omega_body_rad_s[:, 2], run.angular_accel_rad_s2[:, 2]
    inner = slice(100, -100)                                   # past the start-up transient
    d = np.gradient(w, dt)[inner]
    W = 2 * math.pi * f
    # central differences err by <= dt²/6·|ω'''| = dt²/6·A W³; MuJoCo's acceleration of
    # sample j is the mean over the physics step after it: <= dt_phys/2·|α'| = dt_phys/2·A W²
    # (1.1e-3 and 6.9e-3 rad/s² here; the forward pass' own qacc is 18 % = 0.4 rad/s² off)
    bound = dt**2 / 6 * amp * W**3 + dt_phys / 2 * amp * W**2
    assert np.abs(a[inner] - d).max() <= 1.1 * bound
    assert np.abs(a[inner]).max() == pytest.approx(amp * W, rel=0.01)


def test_tumbles_turn_gravity_through_the_platform():
    r = deg_s_to_rad_s(60.0)
    p = Profile((Tumble(axis=(0.0, -1.0, 0.0), rate_rad_s=r, duration_s=5.7, ramp_s=0.3,
                        tilt_rad=deg_to_rad(30.0), align_s=0.5),
                 Tumble(axis=(1.0, 0.0, 0.0), rate_rad_s=r, duration_s=5.7, ramp_s=0.3, align_s=0.5),
                 Static(duration_s=0.5)))
    run = TABLE.run(p, 100.0)
    t, w, f = run.time_s, run.omega_body_rad_s, run.specific_force_m_s2
    full_y = (t > 1.3) & (t < 6.2)
    full_x = (t > 7.9) & (t < 13.3)         # after the servo settled (0.23 s)
    # ω = rate · axis at full rate (servo ripple only)
    np.testing.assert_allclose(w[full_y], np.broadcast_to([0.0, -r, 0.0], (full_y.sum(), 3)), atol=1e-6)
    np.testing.assert_allclose(w[full_x], np.broadcast_to([r, 0.0, 0.0], (full_x.sum(), 3)), atol=1e-6)
    # tilted y tumble: a constant g0 sin 30° on y, g0 cos 30° turning in x–z
    np.testing.assert_allclose(f[full_y, 1], G0 * 0.5, atol=1e-9)
    assert np.ptp(f[full_y, 0]) > 1.5 * G0 * math.cos(math.pi / 6)   # 294° of the turn
    # horizontal x tumble: gravity turns in y–z, none on x
    np.testing.assert_allclose(f[full_x, 0], 0.0, atol=1e-9)
    assert np.ptp(f[full_x, 1]) > 1.5 * G0 and np.ptp(f[full_x, 2]) > 1.5 * G0        # 324°
    # whole turns: back where the x tumble started (middle gimbal at the y tumble's 30°)
    np.testing.assert_allclose(f[-1], [0.0, G0 / 2, G0 * math.cos(math.pi / 6)], atol=1e-6)


@pytest.mark.parametrize("kw,fragment", [
    ({"axis": (0.6, 0.8, 0.0)}, "tumbles only about the platform y axis"),
    ({"axis": (1.0, 0.0, 0.0), "tilt_rad": 0.3}, "tilt_deg goes with a tumble about"),
    ({"axis": (0.0, 1.0, 0.0), "tilt_rad": 0.3}, "give align_s > 0"),
])
def test_impossible_tumbles_are_refused(kw, fragment):
    with pytest.raises(InputError, match=fragment):
        Profile((Tumble(rate_rad_s=1.0, duration_s=1.0, ramp_s=0.1, **kw),))
