"""The simulate side of the effects: exact checks on the chain.

Deterministic effects are checked against their defining formula to
floating-point rounding (tolerances beside each assertion); stochastic ones
here only for reproducibility, stream independence and the burst window
(the statistical re-identification is ``test_effects_reidentify.py``).
"""

from __future__ import annotations

import math
from decimal import Decimal, getcontext

import numpy as np
import pytest
from scipy import stats

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.constants import EARTH_RATE_RAD_S
from gyroarray.effects import REGISTRY
from gyroarray.effects.names import QUANTIZATION
from gyroarray.core.physics import fractional_delay, gauss_markov_avar, tilted_axes
from gyroarray.sim.effects import resolve, simulate_readings
from gyroarray.effects.protocol import Stage
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.core.units import (deg_h_to_rad_s, deg_s_to_rad_s, deg_to_rad, rad_s_to_deg_s,
                             ramp_deg_h2_to_rad_s2)

DT = 0.01
TRIAD = Layout.triad()
CONE6 = Layout.conical(1, 6, math.acos(1 / math.sqrt(3)))
CONE5_S2 = Layout.conical(2, 5, deg_to_rad(60.0))


def model(*entries: dict) -> NoiseModel:
    return NoiseModel.from_toml({"effects": list(entries)})


def run(m, omega, layout=TRIAD, seed=0, **kw):
    return simulate_readings(m, omega, layout, DT, np.random.default_rng(seed), **kw)


def sweep(n=2001, peak_deg_s=300.0):
    """A rate about every axis at once, different on each, covering ±peak (platform frame)."""
    t = np.arange(n) * DT
    w = deg_s_to_rad_s(peak_deg_s) * np.column_stack(
        [np.sin(2 * np.pi * 0.37 * t), np.cos(2 * np.pi * 0.23 * t), np.linspace(-1, 1, n)])
    return t, w


# -- the chain with no effect ---------------------------------------------

def test_empty_model_reads_the_sensed_rate_exactly():
    _, w = sweep()
    y = run(NoiseModel(), w, CONE6)
    np.testing.assert_array_equal(y, w @ CONE6.H.T)  # same expression: bitwise


# -- stage 1: sensing --------------------------------------------------------

def test_misalignment_axis_replaces_the_nominal_axis():
    true = np.array([0.02, -0.01, 1.0])
    true /= np.linalg.norm(true)
    _, w = sweep()
    m = model({"effect": "misalignment", "gyro": 3, "axis": true.tolist()})
    y = run(m, w, TRIAD)
    # a·ω with |ω| ~ 5 rad/s (and a renormalised once): a few ulp of 5, i.e. ~1e-15
    np.testing.assert_allclose(y[:, 2], w @ true, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(y[:, :2], w @ TRIAD.H[:2].T)         # other gyros untouched


def _true_axes(m, layout):
    """Recover the true axes from unit rates about x, y, z (exact: y = A ω)."""
    return run(m, np.eye(3), layout).T


@pytest.mark.parametrize("layout", [CONE6, CONE5_S2], ids=["scheme1", "scheme2"])
@pytest.mark.parametrize("azimuth_deg", [0.0, 90.0, 200.0])
def test_misalignment_tilt_has_the_stated_angle_and_direction(layout, azimuth_deg):
    tilt = 0.7
    m = model({"effect": "misalignment", "tilt_deg": tilt, "tilt_azimuth_deg": azimuth_deg})
    a = _true_axes(m, layout)
    h = layout.H
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1.0, atol=1e-15)
    angle = np.arccos(np.clip(np.sum(a * h, axis=1), -1, 1))
    # arccos near 1 loses precision: |Δangle| <= eps/sin(angle) ≈ 2e-16/0.012 ≈ 2e-14
    np.testing.assert_allclose(angle, deg_to_rad(tilt), atol=1e-12)
    if azimuth_deg == 0.0:
        cone = ~np.all(np.abs(h - [0, 0, 1]) < 1e-12, axis=1)
        # toward +z: every cone gyro's angle from +z shrinks by exactly the tilt
        np.testing.assert_allclose(np.arccos(a[cone, 2]), np.arccos(h[cone, 2]) - deg_to_rad(tilt),
                                   atol=1e-12)
    if azimuth_deg == 90.0:
        # horizontal tilt toward increasing azimuth: z unchanged and the azimuth grows
        cone = ~np.all(np.abs(h - [0, 0, 1]) < 1e-12, axis=1)
        dz = a[cone, 2] - np.cos(deg_to_rad(tilt)) * h[cone, 2]
        np.testing.assert_allclose(dz, 0.0, atol=1e-15)
        az = np.arctan2(a[cone, 1], a[cone, 0]) - np.arctan2(h[cone, 1], h[cone, 0])
        assert np.all(np.mod(az, 2 * np.pi) < 0.1)


def test_tilt_of_a_polar_axis_goes_toward_plus_x_then_plus_y():
    a = tilted_axes(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]), [0.1, 0.1], [0.0, np.pi / 2])
    np.testing.assert_allclose(a, [[math.sin(0.1), 0, math.cos(0.1)],
                                   [0, math.sin(0.1), math.cos(0.1)]], atol=1e-16)


def test_earth_rate_static_level_heading_0():
    lat = deg_to_rad(34.25)
    m = model({"effect": "earth_rate", "latitude_deg": 34.25})
    y = run(m, np.zeros((10, 3)), TRIAD, site=(lat, 0.0))
    # x north, y west, z up: Ω cos φ, 0, Ω sin φ (one multiply and a cos/sin each: 1e-15 absolute
    # is ~1e-11 relative, far above rounding)
    np.testing.assert_allclose(y[:, 0], EARTH_RATE_RAD_S * math.cos(lat), rtol=0, atol=1e-15)
    np.testing.assert_allclose(y[:, 1], 0.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(y[:, 2], EARTH_RATE_RAD_S * math.sin(lat), rtol=0, atol=1e-15)


def test_earth_rate_heading_turns_about_up():
    # heading 90°: x is north turned 90° about up = west; y = up × x = south
    lat = deg_to_rad(-20.0)
    m = model({"effect": "earth_rate", "latitude_deg": -20.0})
    y = run(m, np.zeros((4, 3)), TRIAD, site=(lat, deg_to_rad(90.0)))
    np.testing.assert_allclose(y[0], EARTH_RATE_RAD_S * np.array([0.0, -math.cos(lat), math.sin(lat)]),
                               rtol=0, atol=1e-15)


def test_earth_rate_follows_the_attitude():
    lat, n = deg_to_rad(45.0), 500
    m = model({"effect": "earth_rate", "latitude_deg": 45.0})
    # platform turned 90° about its x axis (R = Rx(90°), platform -> level): platform y points up
    rx = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    y = run(m, np.zeros((n, 3)), TRIAD, attitude=np.broadcast_to(rx, (n, 3, 3)), site=(lat, 0.0))
    np.testing.assert_allclose(y[0], EARTH_RATE_RAD_S * np.array([math.cos(lat), math.sin(lat), 0.0]),
                               rtol=0, atol=1e-15)
    # spinning about up at rate r: platform x at angle r t from north, toward west
    r = deg_s_to_rad_s(10.0)
    t = np.arange(n) * DT
    c, s = np.cos(r * t), np.sin(r * t)
    rz = np.zeros((n, 3, 3))
    rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = c, -s, s, c, 1.0
    w = np.column_stack([np.zeros(n), np.zeros(n), np.full(n, r)])
    y = run(m, w, TRIAD, attitude=rz, site=(lat, 0.0))
    omega = EARTH_RATE_RAD_S
    np.testing.assert_allclose(y[:, 0], omega * math.cos(lat) * c, rtol=0, atol=1e-15)
    np.testing.assert_allclose(y[:, 1], -omega * math.cos(lat) * s, rtol=0, atol=1e-15)
    np.testing.assert_allclose(y[:, 2], r + omega * math.sin(lat), rtol=0, atol=1e-15)


def test_earth_rate_refuses_missing_or_contradicting_site():
    m = model({"effect": "earth_rate", "latitude_deg": 34.25})
    with pytest.raises(InputError, match="needs the site's heading"):
        run(m, np.zeros((4, 3)))
    with pytest.raises(InputError, match="disagrees with the site latitude"):
        run(m, np.zeros((4, 3)), site=(deg_to_rad(30.0), 0.0))


# -- stage 2: latency --------------------------------------------------------

@pytest.mark.parametrize("delay_s", [0.0, 0.004, 0.0137, 0.05])
def test_latency_delays_a_sinusoid_within_the_lagrange_bound(delay_s):
    f, amp = 2.0, deg_s_to_rad_s(50.0)
    n = 3000
    t = np.arange(n) * DT
    w = np.zeros((n, 3))
    w[:, 2] = amp * np.sin(2 * np.pi * f * t + 0.3)
    y = run(model({"effect": "latency", "delay_s": delay_s}), w)
    k = int(math.floor(delay_s / DT))
    keep = slice(k + 2, n - 1)  # start-up (held first sample) and the last sample excluded
    expect = amp * np.sin(2 * np.pi * f * (t - delay_s) + 0.3)
    # cubic Lagrange error <= (3/128)·A·(ω dt)⁴ (fractional_delay Notes), plus rounding
    bound = 3 / 128 * amp * (2 * np.pi * f * DT) ** 4 + 1e-15
    err = np.abs(y[keep, 2] - expect[keep])
    assert err.max() <= bound
    if delay_s in (0.0, 0.05):  # whole samples: an exact shift of the input samples
        np.testing.assert_array_equal(y[k:, 2], w[:n - k, 2])
    else:
        assert err.max() > 0.05 * bound  # the bound is not vacuous


def test_fractional_delay_start_up_holds_the_first_sample():
    x = np.arange(10.0)[:, None] + 5.0
    y = fractional_delay(x, [3.5])
    np.testing.assert_array_equal(y[:2, 0], 5.0)            # before the record: held
    np.testing.assert_allclose(y[6:, 0], x[6:, 0] - 3.5, atol=1e-13)  # a line is reproduced exactly


def test_latency_longer_than_the_record_is_refused():
    with pytest.raises(InputError, match="not shorter than the record"):
        run(model({"effect": "latency", "delay_s": 1.0}), np.zeros((50, 3)))


# -- stage 3: scale ----------------------------------------------------------

def test_scale_factor_slope_is_exact():
    _, w = sweep()
    y = run(model({"effect": "scale_factor", "ppm": 6000}), w)
    u = w @ TRIAD.H.T
    # y = u + s·u against (1 + s)·u: a few ulps, so 1e-12 relative is a wide margin
    np.testing.assert_allclose(y, (1 + 6000e-6) * u, rtol=1e-12, atol=0)
    slope = np.linalg.lstsq(u[:, :1], y[:, 0], rcond=None)[0][0]
    assert slope == pytest.approx(1.006, rel=1e-12)


def test_scale_nonlinearity_coefficient_is_exact_in_deg_s():
    k2 = 2.5e-4  # per deg/s
    _, w = sweep()
    y = run(model({"effect": "scale_nonlinearity", "k2_per_deg_s": k2}), w)
    u_deg = rad_s_to_deg_s(w @ TRIAD.H.T)
    y_deg = rad_s_to_deg_s(y)
    np.testing.assert_allclose(y_deg, u_deg + k2 * u_deg ** 2, rtol=1e-12, atol=1e-12)
    coef = np.polyfit(u_deg[:, 0], y_deg[:, 0], 2)
    assert coef[0] == pytest.approx(k2, rel=1e-9)   # lstsq on exact data: conditioning ~1e-10
    assert coef[1] == pytest.approx(1.0, rel=1e-9)


def test_scale_factor_and_nonlinearity_share_one_input():
    _, w = sweep()
    y = run(model({"effect": "scale_factor", "ppm": -3000},
                  {"effect": "scale_nonlinearity", "k2_per_deg_s": 1e-4}), w)
    u = w @ TRIAD.H.T
    k2_si = 1e-4 * 180 / math.pi
    np.testing.assert_allclose(y, (1 - 3000e-6) * u + k2_si * u ** 2, rtol=1e-12, atol=1e-18)


# -- stage 4: additive -------------------------------------------------------

def test_constant_bias_and_per_gyro_override():
    n = 100
    y = run(model({"effect": "constant_bias", "bias_deg_h": 10.0},
                  {"effect": "constant_bias", "gyro": 2, "bias_deg_h": -4.0}), np.zeros((n, 3)))
    np.testing.assert_array_equal(y[:, [0, 2]], deg_h_to_rad_s(10.0))
    np.testing.assert_array_equal(y[:, 1], deg_h_to_rad_s(-4.0))


def test_rate_ramp_is_r_times_time():
    n = 500
    t = 1000.0 + np.arange(n) * DT
    y = run(model({"effect": "rate_ramp", "gyro": 1, "r_deg_h2": 36.0}), np.zeros((n, 3)), time_s=t)
    np.testing.assert_allclose(y[:, 0], ramp_deg_h2_to_rad_s2(36.0) * t, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(y[:, 1:], 0.0)


def test_sinusoid_amplitude_and_phase_by_least_squares():
    amp, f, ph = 0.02, 1.3, 40.0
    n = 4000
    t = np.arange(n) * DT
    y = run(model({"effect": "sinusoid", "amp_deg_s": amp, "freq_hz": f, "phase_deg": ph}),
            np.zeros((n, 3)))[:, 1]
    a = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
    c_sin, c_cos = np.linalg.lstsq(a, y, rcond=None)[0]
    # amp·sin(ωt + φ) = amp cos φ sin ωt + amp sin φ cos ωt; exact data: rounding only
    assert math.hypot(c_sin, c_cos) == pytest.approx(deg_s_to_rad_s(amp), rel=1e-12)
    assert math.atan2(c_cos, c_sin) == pytest.approx(deg_to_rad(ph), abs=1e-12)


def test_sinusoid_above_nyquist_is_refused():
    with pytest.raises(InputError, match="Nyquist"):
        run(model({"effect": "sinusoid", "amp_deg_s": 1.0, "freq_hz": 50.0}), np.zeros((10, 3)))


def test_temperature_bias_follows_temp_exactly():
    n = 300
    temp = 25.0 + 10.0 * np.sin(np.arange(n) / 50.0)
    y = run(model({"effect": "temperature_bias", "deg_h_per_c": 3.0, "t0_c": 25.0}), np.zeros((n, 3)),
            temp_c=temp)
    expect = np.broadcast_to(deg_h_to_rad_s(3.0) * (temp - 25.0)[:, None], y.shape)
    np.testing.assert_allclose(y, expect, rtol=1e-15, atol=0)  # the same product: rounding only
    with pytest.raises(InputError, match="needs the temperature history"):
        run(model({"effect": "temperature_bias", "deg_h_per_c": 3.0, "t0_c": 25.0}), np.zeros((n, 3)))


def test_burst_scales_the_white_variance_inside_its_window():
    n, ratio = 200_000, 4.0
    m = model({"effect": "arw", "n_deg_rt_h": 0.5},
              {"effect": "burst", "start_s": 500.0, "end_s": 1500.0, "variance_ratio": ratio})
    y = run(m, np.zeros((n, 3)), seed=11)
    t = np.arange(n) * DT
    inside = (t >= 500.0) & (t < 1500.0)
    s_in = y[inside].var(axis=0, ddof=1)
    s_out = y[~inside].var(axis=0, ddof=1)
    # ratio of sample variances / true ratio ~ F(n_in − 1, n_out − 1): two-sided 99.9 % interval
    d1, d2 = inside.sum() - 1, (~inside).sum() - 1
    lo, hi = stats.f.ppf([0.0005, 0.9995], d1, d2)
    assert np.all((s_in / s_out / ratio > lo) & (s_in / s_out / ratio < hi))
    # and outside the window the ARW is untouched (same draws as without the burst)
    y0 = run(model({"effect": "arw", "n_deg_rt_h": 0.5}), np.zeros((n, 3)), seed=11)
    np.testing.assert_array_equal(y[~inside], y0[~inside])
    np.testing.assert_allclose(y[inside], 2.0 * y0[inside], rtol=1e-15)


def test_common_mode_rho_1_gives_one_source_for_every_gyro():
    m = model({"effect": "arw", "n_deg_rt_h": 0.3},
              {"effect": "correlation", "rho_arw": 1.0, "common_mode": True})
    y = run(m, np.zeros((1000, 3)))
    np.testing.assert_array_equal(y[:, 0], y[:, 1])
    np.testing.assert_array_equal(y[:, 0], y[:, 2])


# -- stages 5 and 6 ----------------------------------------------------------

def test_quantization_noise_is_a_uniform_angle_error_of_variance_q2():
    """The angle the output integrates to stays within half a step q/2 = √3·Q of the input's
    (plus the start), and its error is uniform with variance Q²: 3Q²/τ² in the Allan variance."""
    q_deg = 1e-3
    half = math.sqrt(3) * deg_to_rad(q_deg)
    n = 20000
    _, w = sweep(n, 20.0)
    y = run(model({"effect": "quantization", "q_deg": q_deg}), w, seed=3)
    gap = np.cumsum(y - w @ TRIAD.H.T, axis=0) * DT          # e_k − e_{−1}
    assert np.abs(gap).max() < 2 * half * (1 + 1e-9)
    e = gap - gap.mean(axis=0)                               # e_k up to the (common) start value
    assert np.abs(e).max() < 2 * half
    # variance of a uniform on [−q/2, q/2): q²/12 = Q²; the sample variance of 20 000 draws has
    # relative sd √(0.8/20 000) = 0.6 % (kurtosis 1.8): ±3 % is 5 sd
    np.testing.assert_allclose(e.var(axis=0), deg_to_rad(q_deg) ** 2, rtol=0.03)
    # independent from sample to sample: lag-1 autocorrelation within ±4/√n
    for j in range(3):
        r1 = np.corrcoef(e[1:, j], e[:-1, j])[0, 1]
        assert abs(r1) < 4 / math.sqrt(n)


def test_saturation_clips_last_and_exactly():
    _, w = sweep()
    r = 100.0
    m = model({"effect": "constant_bias", "bias_deg_h": 36000.0},   # 10 deg/s, added before the clip
              {"effect": "saturation", "range_deg_s": r})
    y = run(m, w)
    expect = np.clip(w @ TRIAD.H.T + deg_h_to_rad_s(36000.0), -deg_s_to_rad_s(r), deg_s_to_rad_s(r))
    np.testing.assert_array_equal(y, expect)
    assert np.any(y == deg_s_to_rad_s(r)) and np.any(y == -deg_s_to_rad_s(r))


# -- randomness --------------------------------------------------------------

def every_effect() -> list[dict]:
    """One entry of every registered effect (the registry, no hand list): its scoring example
    (``Effect.example``), else its typical value, else its placeholder; drawn with a fixed seed,
    with a saturation range well above the 100 deg/s of :func:`_run17`'s sweep."""
    rng = np.random.default_rng(17)
    out = []
    for eff in REGISTRY.values():
        case = eff.example(rng, CONE6.n_gyros, np.full(CONE6.n_gyros, 800.0))
        if case is None:
            try:
                case = None, eff.typical(rng)
            except NotImplementedError:
                case = (1 if eff.per_gyro else None), eff.placeholder()
        gyro, params = case
        out.append({"effect": eff.name, **({} if gyro is None else {"gyro": gyro}), **params})
    return out


def _run17(seed, layout=CONE6, n=1000):
    t, w = sweep(n, 100.0)
    return run(model(*every_effect()), w, layout, seed=seed, temp_c=25 + t, site=(deg_to_rad(34.25), 0.3))


def test_every_effect_is_in_the_bit_test_model():
    assert [e.effect for e in model(*every_effect())] == list(REGISTRY)    # each a valid entry
    assert len(REGISTRY) >= 24                      # the spec's effects and the four faults


def test_same_seed_same_bits_different_seed_different():
    a, b, c = _run17(7), _run17(7), _run17(8)
    assert a.tobytes() == b.tobytes()
    # a quantized gyro outputs whole counts of its step (the spec's counter, no draw of its own):
    # two seeds give the same count wherever the noise does not carry the angle across a step
    # boundary differently (here about 40 % of the samples differ), every other output differs
    counter = {e.gyro - 1 for e in model(*every_effect()) if e.effect == QUANTIZATION}
    other = [g for g in range(a.shape[1]) if g not in counter]
    assert counter and np.mean(a[:, other] != c[:, other]) > 0.99
    assert np.mean(a[:, sorted(counter)] != c[:, sorted(counter)]) > 0.2


def test_the_generator_is_consumed_once_per_run():
    rng = np.random.default_rng(5)
    m = model({"effect": "arw", "n_deg_rt_h": 0.1})
    y1 = simulate_readings(m, np.zeros((100, 3)), TRIAD, DT, rng)
    y2 = simulate_readings(m, np.zeros((100, 3)), TRIAD, DT, rng)
    assert not np.array_equal(y1, y2)               # the caller's generator advanced
    ref = np.random.default_rng(5)
    ref.integers(0, 2**32, size=4, dtype=np.uint64)  # what one run takes from it
    y2b = simulate_readings(m, np.zeros((100, 3)), TRIAD, DT, ref)
    np.testing.assert_array_equal(y2, y2b)


def test_adding_an_effect_leaves_the_other_draws_alone():
    n = 2000
    base = model({"effect": "arw", "n_deg_rt_h": 0.2}, {"effect": "rrw", "k_deg_h_rt_h": 5.0})
    y0 = run(base, np.zeros((n, 3)), seed=9)
    more = base.with_effect(ModelEntry("gauss_markov", 2, {"sigma_deg_h": 10.0, "tau_s": 3.0}))
    more = more.with_effect(ModelEntry("bias_instability", None, {"b_deg_h": 1.0}))
    y1 = run(more.without_effect("bias_instability"), np.zeros((n, 3)), seed=9)
    np.testing.assert_array_equal(y1[:, [0, 2]], y0[:, [0, 2]])
    gm_only = run(model({"effect": "gauss_markov", "gyro": 2, "sigma_deg_h": 10.0, "tau_s": 3.0}),
                  np.zeros((n, 3)), seed=9)
    np.testing.assert_allclose(y1[:, 1], y0[:, 1] + gm_only[:, 1], rtol=0, atol=1e-18)
    # ARW on another gyro does not change gyro 1's ARW either
    y2 = run(model({"effect": "arw", "gyro": 1, "n_deg_rt_h": 0.2}), np.zeros((n, 3)), seed=9)
    y3 = run(model({"effect": "arw", "gyro": 1, "n_deg_rt_h": 0.2},
                   {"effect": "arw", "gyro": 3, "n_deg_rt_h": 0.7}), np.zeros((n, 3)), seed=9)
    np.testing.assert_array_equal(y2[:, 0], y3[:, 0])


# -- the plan ----------------------------------------------------------------

def test_chain_order_follows_the_stages():
    plan = resolve(model(*every_effect()), 6)
    stages = [eff.stage for eff, _ in plan]
    assert stages == sorted(stages)
    names = [eff.name for eff, _ in plan]
    before_faults = [eff.name for eff, _ in plan if eff.stage < Stage.FAULT]
    assert names[0] in ("misalignment", "earth_rate") and before_faults[-1] == "saturation"
    assert names.index("correlation") < names.index("arw")
    assert REGISTRY["quantization"].stage == Stage.QUANTIZE


@pytest.mark.parametrize("kw,fragment", [
    ({"time_s": np.arange(10) * 0.02}, "uniformly spaced"),
    ({"temp_c": np.zeros(9)}, "temp_c must be 10"),
    ({"attitude": np.ones((10, 3, 3))}, "not orthonormal"),
    ({"site": (3.0, 0.0)}, "not a valid site"),
])
def test_bad_run_inputs_are_refused(kw, fragment):
    with pytest.raises(InputError, match=fragment):
        run(NoiseModel(), np.zeros((10, 3)), **kw)


def test_bad_truth_shape_and_gyro_beyond_the_layout():
    with pytest.raises(InputError, match=r"\(n, 3\)"):
        run(NoiseModel(), np.zeros((10, 2)))
    with pytest.raises(InputError, match=r"effects\[0\].*gyro 4 does not exist"):
        run(model({"effect": "constant_bias", "gyro": 4, "bias_deg_h": 1.0}), np.zeros((10, 3)))


# -- Gauss–Markov Allan variance (the start of its fit side) -----------------

def test_gauss_markov_avar_limits_and_series_join():
    sigma, tc = 2.0, 5.0
    # τ ≪ τc: RRW with K² = 2σ²/τc, AVAR = K²τ/3; τ ≫ τc: ARW with N² = 2σ²τc, AVAR = N²/τ
    assert gauss_markov_avar(1e-6, sigma, tc) == pytest.approx(2 * sigma**2 / tc * 1e-6 / 3, rel=1e-6)
    assert gauss_markov_avar(1e6, sigma, tc) == pytest.approx(2 * sigma**2 * tc / 1e6, rel=1e-5)
    # both sides of the switch to the series at x = τ/τc = 1e-3 against the closed form in
    # 50-digit decimal arithmetic: the series' next term is x³/8 relative (1e-10), the expm1
    # form cancels to ~6 eps/x² (7e-10) just above the switch
    getcontext().prec = 50
    for x in ("0.000999", "0.001001", "0.3", "7"):
        xd = Decimal(x)
        bracket = 1 - (3 - 4 * (-xd).exp() + (-2 * xd).exp()) / (2 * xd)
        exact = float(2 * Decimal(sigma) ** 2 / xd * bracket)
        assert gauss_markov_avar(float(x) * tc, sigma, tc) == pytest.approx(exact, rel=1e-9)
    # peak of the deviation near 1.89 τc at ≈ 0.618 σ
    taus = np.geomspace(0.1, 100, 20001) * tc
    dev = np.sqrt(gauss_markov_avar(taus, sigma, tc))
    assert taus[np.argmax(dev)] / tc == pytest.approx(1.89, abs=0.01)
    assert dev.max() / sigma == pytest.approx(0.618, abs=0.001)
