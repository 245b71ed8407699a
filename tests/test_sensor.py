"""The sensor-response effects: ``bandwidth`` and ``g_sensitivity`` (spec definitions).

Outside truth: the continuous H(jω) of the spec written here from its
formula (not the module's), the bilinear transform's frequency map, a
least-squares sine fit of the filtered signal, scipy's own ``lfilter`` of
the (b, a) design, and the g-sensitivity closed form
bias = (k · f_k)/g0 with f_k = f_0 + α × r_k + ω × (ω × r_k) written here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.effects import REGISTRY
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.protocol import Stage
from gyroarray.effects.model import NoiseModel
from gyroarray.core.sensor import (bandwidth_filter, bandwidth_sos, bandwidth_warped_frequency,
                                  g_sensitivity_bias)
from gyroarray.core.units import deg_h_to_rad_s, deg_s_to_rad_s, deg_to_rad

G0 = 9.80665
FS = 100.0
DT = 1.0 / FS
CONE4 = Layout.conical(1, 4, math.acos(1 / math.sqrt(3)))


def H(f, fc, order):
    """The spec's H(s) at s = j2πf: 1/(1 + s/ωc) or 1/(1 + √2 s/ωc + s²/ωc²)."""
    s = 2j * math.pi * np.asarray(f) / (2 * math.pi * fc)
    return 1 / (1 + s) if order == 1 else 1 / (1 + math.sqrt(2) * s + s**2)


def model(*entries, n=4):
    return NoiseModel.from_toml({"effects": list(entries)}, n_gyros=n)


# -- bandwidth: the discrete filter against the continuous H(jω) -------------

@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("fc", [1.0, 10.0, 30.0])
def test_discrete_response_is_the_continuous_one_at_the_warped_frequency(order, fc):
    f = np.linspace(0.001, 0.2, 400) * FS                     # up to 0.2 fs
    _, hd = signal.sosfreqz(bandwidth_sos(fc, order, DT), worN=f, fs=FS)
    # bilinear with pre-warping at fc: H_d(f) = H(f'), f' = fc tan(πf dt)/tan(πfc dt), exactly
    fw = fc * np.tan(np.pi * f * DT) / math.tan(math.pi * fc * DT)
    np.testing.assert_allclose(fw, bandwidth_warped_frequency(f, fc, DT), rtol=1e-15)
    np.testing.assert_allclose(hd, H(fw, fc, order), rtol=0, atol=1e-12)   # measured 3e-14
    # -3 dB at the cut-off, unit gain at DC
    _, h_c = signal.sosfreqz(bandwidth_sos(fc, order, DT), worN=[0.0, fc], fs=FS)
    np.testing.assert_allclose(np.abs(h_c), [1.0, 1 / math.sqrt(2)], rtol=1e-12)
    # against H(jω) itself: the warping bound. |d ln|H|/d ln ω| and |d arg H/d ln ω| are at
    # most the order for these filters, so both errors are <= order·|ln(f'/f)|
    bound = order * np.abs(np.log(fw / f))
    hc = H(f, fc, order)
    assert np.all(np.abs(np.log(np.abs(hd) / np.abs(hc))) <= bound + 1e-12)
    assert np.all(np.abs(np.angle(hd / hc)) <= bound + 1e-12)
    # in numbers, below 0.1 fs with the cut-off at or below 0.1 fs: <= 0.6 dB and 1.3 deg
    # (measured 0.58 dB / 0.27 deg at fc = 1 Hz, 0.06 dB / 1.26 deg at fc = 10 Hz)
    low = f <= 0.1 * FS
    if fc <= 0.1 * FS:
        assert 20 * np.log10(np.abs(hd[low] / hc[low])).__abs__().max() < 0.6
        assert np.degrees(np.abs(np.angle(hd[low] / hc[low]))).max() < 1.3


@pytest.mark.parametrize("order,fc,f", [(1, 5.0, 2.0), (2, 12.0, 1.0), (2, 12.0, 8.0)])
def test_filtered_sine_has_the_designed_gain_and_lag(order, fc, f):
    t = np.arange(3000) * DT
    y = bandwidth_filter(np.sin(2 * math.pi * f * t), DT, fc, order)
    keep = t > 5.0                                            # past the start (steady state)
    X = np.column_stack([np.sin(2 * math.pi * f * t), np.cos(2 * math.pi * f * t)])[keep]
    (a, b), *_ = np.linalg.lstsq(X, y[keep], rcond=None)
    _, (hd,) = signal.sosfreqz(bandwidth_sos(fc, order, DT), worN=[f], fs=FS)
    assert math.hypot(a, b) == pytest.approx(abs(hd), rel=1e-9)
    assert math.atan2(b, a) == pytest.approx(np.angle(hd), abs=1e-9)
    assert np.angle(hd) < 0                                   # a lag: causal, not zero-phase
    # scipy's transfer-function form of the same design, run by lfilter, agrees
    bb, aa = signal.butter(order, fc, fs=FS)
    zi = signal.lfilter_zi(bb, aa) * 0.0
    np.testing.assert_allclose(y, signal.lfilter(bb, aa, np.sin(2 * math.pi * f * t), zi=zi)[0],
                               rtol=0, atol=1e-12)


def test_filter_is_causal_and_starts_in_steady_state():
    rng = np.random.default_rng(1)
    x = 0.3 + 0.01 * rng.standard_normal((500, 3))
    x[0] = 0.3                                                # a turn-on bias, held since before
    y = bandwidth_filter(x, DT, [2.0, 10.0, 40.0], [1, 2, 2])
    c = np.full((50, 2), 0.3)
    np.testing.assert_allclose(bandwidth_filter(c, DT, 5.0, 2), c, rtol=1e-14)   # no transient
    # a change at sample k leaves every output before k exactly as it was
    x2 = x.copy()
    x2[200:] += 1.0
    y2 = bandwidth_filter(x2, DT, [2.0, 10.0, 40.0], [1, 2, 2])
    np.testing.assert_array_equal(y2[:200], y[:200])
    assert np.all(np.abs(y2[200:] - y[200:]).max(axis=0) > 0.5)


def test_bad_filters_are_refused():
    with pytest.raises(InputError, match="below the Nyquist frequency"):
        bandwidth_filter(np.zeros(10), DT, 50.0, 1)
    with pytest.raises(InputError, match="order = 3 .* out of range"):
        model({"effect": "bandwidth", "cutoff_hz": 5.0, "order": 3})
    with pytest.raises(InputError, match=r"order must be 1 \(first order\) or 2"):
        model({"effect": "bandwidth", "cutoff_hz": 5.0, "order": 1.5})
    with pytest.raises(InputError, match="cutoff_hz"):
        model({"effect": "bandwidth", "cutoff_hz": 0.0, "order": 1})
    m = model({"effect": "bandwidth", "gyro": 2, "cutoff_hz": 60.0, "order": 1})
    with pytest.raises(InputError, match=r"effects\[0\] \(bandwidth\): cutoff_hz = 60 Hz .*Nyquist"):
        simulate_readings(m, np.zeros((10, 3)), CONE4, DT, np.random.default_rng(0))


# -- the order the effects act in (spec) -------------------------------------

def test_bandwidth_acts_after_sensing_and_noise_before_quantization_and_saturation():
    assert (Stage.ADD < REGISTRY["bandwidth"].stage < REGISTRY["quantization"].stage
            < REGISTRY["saturation"].stage)
    assert REGISTRY["g_sensitivity"].stage == Stage.ADD
    n = 2000
    t = np.arange(n) * DT
    w = deg_s_to_rad_s(200.0) * np.column_stack([np.sin(2 * math.pi * 0.7 * t),
                                                 np.sin(2 * math.pi * 1.3 * t), np.cos(t)])
    k = [0.1, -0.05, 0.2]
    q_deg, r_deg_s, ppm, bias = 2e-4, 150.0, 3000.0, 36000.0
    m = model({"effect": "scale_factor", "ppm": ppm},
              {"effect": "constant_bias", "bias_deg_h": bias},
              {"effect": "g_sensitivity", "deg_s_per_g": k},
              {"effect": "bandwidth", "cutoff_hz": 4.0, "order": 2},
              {"effect": "quantization", "q_deg": q_deg},
              {"effect": "saturation", "range_deg_s": r_deg_s})
    rng = np.random.default_rng(3)
    y = simulate_readings(m, w, CONE4, DT, rng, time_s=t)
    # by hand: u = H ω; (1 + s) u + b + k·f/g0 (level, at the origin: f = [0, 0, g0]); filter;
    # the spec's counter (increments of the rounded integrated angle, step √12·Q); clip
    u = w @ CONE4.H.T
    x = u + ppm * 1e-6 * u + deg_h_to_rad_s(bias) + deg_s_to_rad_s(k[2])
    x = bandwidth_filter(x, DT, 4.0, 2)
    step = math.sqrt(12.0) * deg_to_rad(q_deg)
    x = np.diff(np.round(np.cumsum(x * DT, axis=0) / step), axis=0, prepend=0.0) * (step / DT)
    x = np.clip(x, -deg_s_to_rad_s(r_deg_s), deg_s_to_rad_s(r_deg_s))
    np.testing.assert_allclose(y, x, rtol=0, atol=1e-12)
    assert np.any(np.abs(y) == deg_s_to_rad_s(r_deg_s))     # the clip did act


# -- g_sensitivity: the closed form ------------------------------------------

def test_g_sensitivity_bias_is_k_dot_f_over_g0_at_each_gyro():
    rng = np.random.default_rng(4)
    n = 300
    w = rng.normal(0, 2.0, (n, 3))                            # rad/s
    alpha = rng.normal(0, 20.0, (n, 3))                       # rad/s²
    f0 = rng.normal(0, G0, (n, 3))                            # m/s²
    r = np.array([[0.03, 0, 0.01], [0, 0.05, 0], [-0.02, 0.01, 0.1], [0, 0, 0]])
    layout = CONE4.with_positions(r)
    k = np.array([[0.1, 0.0, 0.02], [0.0, -0.2, 0.0], [0.05, 0.05, 0.05], [0.0, 0.0, 0.15]])
    m = model(*({"effect": "g_sensitivity", "gyro": g + 1, "deg_s_per_g": k[g].tolist()}
                for g in range(4)))
    y = simulate_readings(m, w, layout, DT, np.random.default_rng(0), specific_force=f0,
                          angular_accel=alpha)
    fk = (f0[:, None] + np.cross(alpha[:, None], r[None]) +
          np.cross(w[:, None], np.cross(w[:, None], r[None])))        # n × N × 3
    bias_deg_s = np.einsum("nkj,kj->nk", fk, k) / G0
    # y − Hω cancels a rate of up to 8 rad/s: rounding 8·2⁻⁵² ≈ 2e-15 rad/s
    np.testing.assert_allclose(y - w @ layout.H.T, deg_s_to_rad_s(bias_deg_s), rtol=1e-12,
                               atol=4e-15)
    # the pure function, in SI
    np.testing.assert_allclose(g_sensitivity_bias(deg_s_to_rad_s(k) / G0, fk),
                               deg_s_to_rad_s(bias_deg_s), rtol=1e-13)


def test_without_the_truth_gravity_comes_from_the_attitude():
    # level, then turned 90° about x: z up becomes -y up; gravity then reads on +y
    n = 10
    R = np.repeat(np.eye(3)[None], n, axis=0)
    R[5:] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]               # platform -> level, Rx(90°)
    m = model({"effect": "g_sensitivity", "deg_s_per_g": [0.0, 0.3, 0.1]}, n=3)
    y = simulate_readings(m, np.zeros((n, 3)), Layout.triad(), DT, np.random.default_rng(0),
                          attitude=R)
    np.testing.assert_allclose(y[:5], deg_s_to_rad_s(0.1), rtol=1e-12)      # f = [0, 0, g0]
    np.testing.assert_allclose(y[5:], deg_s_to_rad_s(0.3), rtol=1e-12)      # f = Rᵀ g = [0, g0, 0]


def test_g_sensitivity_needs_a_vector():
    with pytest.raises(InputError, match=r"deg_s_per_g must be 3 numbers"):
        model({"effect": "g_sensitivity", "deg_s_per_g": 0.1})
    with pytest.raises(InputError, match=r"specific_force must be \(5, 3\)"):
        simulate_readings(model({"effect": "g_sensitivity", "deg_s_per_g": [0, 0, 1]}, n=3),
                          np.zeros((5, 3)), Layout.triad(), DT, np.random.default_rng(0),
                          specific_force=np.zeros((4, 3)))
