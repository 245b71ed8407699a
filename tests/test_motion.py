"""Still parts of a record without a reference (gyroarray.analysis.motion.still_mask).

Truth comes from the project's simulator (:func:`gyroarray.sim.lab.lab_run`,
whose reference rate says where the table turns) and from a real record
(MIMU4444, 8 MPU-9150 triads, hand-placed static orientations then hand
rotation). Records are deterministic (fixed seeds); tolerances are stated
beside each assertion.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import maximum_filter1d

from gyroarray.analysis.motion import still_mask
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import read_measurement
from gyroarray.sim.lab import lab_run
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.core.units import RAD_PER_DEG

REAL = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real"
needs_real = pytest.mark.skipif(not REAL.exists(), reason="shared/measurements/real not present")
MIMU = REAL / "mimu4444_array24.csv.gz"
ADIS = REAL / "adis16405_static.csv.gz"
MAGIC = math.radians(54.7356)
BASE = (ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 10.0}))
LAYOUTS = {"triad": Layout.triad(),
           "tetrahedron": Layout.conical(2, 4, math.acos(-1.0 / 3.0)),
           "S1N6": Layout.conical(1, 6, MAGIC),
           "S2N8": Layout.conical(2, 8, math.radians(60.0))}
NOISES = {
    "biases": (),
    "burst": (ModelEntry("burst", None, {"start_s": 600.5, "end_s": 840.5, "variance_ratio": 10.0}),),
    "gauss_markov": (ModelEntry("gauss_markov", None, {"sigma_deg_h": 100.0, "tau_s": 0.5}),),
    "sinusoid": (ModelEntry("sinusoid", None, {"amp_deg_s": 0.05, "freq_hz": 7.3}),),
    "quantization": (ModelEntry("quantization", None, {"q_deg": 5e-4}),),
    "drift": (ModelEntry("bias_instability", None, {"b_deg_h": 8.0}),
              ModelEntry("rate_ramp", None, {"r_deg_h2": 300.0}),
              ModelEntry("temperature_bias", None, {"deg_h_per_c": 20.0, "t0_c": 25.0})),
}


def _biases(n_gyros):
    """Turn-on biases up to 1 deg/s (3600 deg/h), different per gyro, alternating sign."""
    return tuple(ModelEntry("constant_bias", g, {"bias_deg_h": 3600.0 * (-1) ** g * g / n_gyros})
                 for g in range(1, n_gyros + 1))


def _mask(m, **kw):
    return still_mask(m.gyro_deg_s * RAD_PER_DEG, m.layout.axes, 1.0 / m.sample_rate_hz, **kw)


def _runs(mask, dt_s):
    """(start, stop) sample indices of the runs of True, and their lengths [s]."""
    e = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    runs = list(zip(e[::2], e[1::2]))
    return runs, np.array([(b - a) * dt_s for a, b in runs])


# -- a lab run: the mask against the reference ---------------------------------------

@pytest.mark.parametrize("name", ["triad", "S1N6"])
def test_lab_run_agrees_with_reference(name):
    """Mask vs truth (|ref| <= 0.01 deg/s), outside guard_s + window_s = 2 s of each transition.

    The model has ARW, RRW, per-gyro biases up to 1 deg/s, temperature drift and
    the Earth rate (which changes its projection as the table turns). At seed 5,
    for both layouts: 0 still samples among the 5 624 samples of true motion
    >= 1 deg/s (0 even without leaving out the transitions), and 100.0 % of the
    45 498 truly still samples found still (asserted: 0 and >= 95 %, the
    issue's rule).
    """
    layout = LAYOUTS[name]
    model = NoiseModel(BASE + _biases(layout.n_gyros) + (
        ModelEntry("temperature_bias", None, {"deg_h_per_c": 20.0, "t0_c": 25.0}),
        ModelEntry("earth_rate", None, {"latitude_deg": 34.25})))
    m = lab_run(model, layout, np.random.default_rng(5))
    still = _mask(m)
    rate = np.abs(m.ref_deg_s).max(axis=1)
    truth = rate <= 0.01
    edge = np.zeros(truth.size, bool)
    edge[np.flatnonzero(np.diff(truth.astype(np.int8)))] = True
    near = maximum_filter1d(edge.astype(np.uint8), 2 * round(2.0 * m.sample_rate_hz) + 3) > 0
    moving, resting = (rate >= 1.0) & ~near, truth & ~near
    assert moving.sum() > 5_000 and resting.sum() > 40_000       # the test has something to test
    assert not np.any(still & moving)
    assert (still & resting).sum() / resting.sum() >= 0.95


# -- pure noise: nothing moves -------------------------------------------------------

@pytest.mark.parametrize("seed", [21, 22])
@pytest.mark.parametrize("noise", list(NOISES))
@pytest.mark.parametrize("name", list(LAYOUTS))
def test_no_motion_on_pure_noise(name, noise, seed):
    """30 min still at 50 Hz (90 000 samples, 1800 windows, 3 or N signals): nothing flagged.

    Every record has per-gyro biases up to 1 deg/s plus one of: a 4-min burst of
    10x white-noise variance, Gauss-Markov 100 deg/h with tau 0.5 s (window
    means 8x the white-noise standard error: only a threshold measured on the
    window means passes), a 0.05 deg/s sinusoid at 7.3 Hz, angle quantization
    of 5e-4 deg (rate step 0.087 deg/s, 5x the white noise), or drift (bias
    instability, a rate ramp, a warm-up temperature bias). Zero false flags is
    the right assertion: a window mean exceeds z = 6 standard errors with
    probability 2e-9; the union bound over every sample and signal (3 for these
    rank-3 layouts) is 90 000 x 3 x 2e-9 = 5.4e-4 per record, 0.026 over these
    48 records, and overlapping windows make it far smaller (the largest
    deviation seen on these records is 4-5 standard errors).
    """
    layout = LAYOUTS[name]
    model = NoiseModel(BASE + _biases(layout.n_gyros) + NOISES[noise])
    m = lab_run(model, layout, np.random.default_rng(seed), static_s=1800.0, motion_s=0.0, tail_s=0.0)
    still = _mask(m)
    assert still.all(), f"{(~still).sum()} samples flagged, first at {m.time_s[np.argmin(still)]:.1f} s"


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("q_deg", [5e-4, 1e-3])
@pytest.mark.parametrize("layout", [LAYOUTS["tetrahedron"], Layout.conical(1, 4, MAGIC),
                                    LAYOUTS["S1N6"]], ids=["tetrahedron", "S1N4", "S1N6"])
def test_no_motion_on_coarsely_quantized_outputs(layout, q_deg, seed):
    """Angle quantization with steps 5-10x the white noise and no bias: nothing flagged.

    Most outputs are 0 and most first differences too, so median-based noise
    levels are 0 (or round-off) and window means sit on a grid; the
    mean-absolute-deviation level and the se >= σ̃/√L bound keep the threshold
    honest (with a median instead, 7 of these 12 records have 114 to 81 342 of
    their 90 000 samples flagged). Same false-alarm argument as above.
    """
    model = NoiseModel(BASE + (ModelEntry("quantization", None, {"q_deg": q_deg}),))
    m = lab_run(model, layout, np.random.default_rng(seed), static_s=1800.0, motion_s=0.0, tail_s=0.0)
    assert _mask(m).all()


@needs_real
def test_real_static_record_has_no_motion():
    """ADIS16405 triad static on a bench for 2.78 h at 100 Hz (1e6 samples): nothing flagged."""
    m = read_measurement(ADIS)
    assert _mask(m).all()


# -- the threshold and the guard -----------------------------------------------------

def test_threshold_is_z_standard_errors():
    """Turns of 10 s about x seen by S1N6 with biases and drift: 12 se moves, 2 se does not.

    se = σ √((HᵀH)⁻¹)ₓₓ / √L is the standard error of a 1 s window mean of ω̂ₓ
    (white noise σ per gyro, L = 50); the outputs carry per-gyro biases up to
    1 deg/s and per-gyro ramps up to 0.2 deg/s over the 600 s (a baseline that
    does not follow them inflates se and misses the 12 se turn). The threshold
    must lie within a factor (12/6, 6/2) of z·se: the turn lifts the running
    median by about 0.6 se, so missing the 12 se turn needs noise below -5 se,
    flagging the 2 se one noise above +4 se (6e-5 per window). Floor off, guard 0.
    """
    rng = np.random.default_rng(3)
    h = np.asarray(LAYOUTS["S1N6"].axes)
    n, sigma, L = 30_000, 1e-3, 50                               # 600 s at 50 Hz
    se = sigma * math.sqrt(np.linalg.inv(h.T @ h)[0, 0] / L)
    w = np.zeros((n, 3))
    w[10_000:10_500, 0] = 2.0 * se
    w[20_000:20_500, 0] = 12.0 * se
    bias = RAD_PER_DEG * np.linspace(-1.0, 1.0, 6)
    ramp = 0.2 * RAD_PER_DEG * np.outer(np.linspace(0.0, 1.0, n), [1.0, -0.5, 0.3, 0.8, -1.0, 0.2])
    y = w @ h.T + bias + ramp + sigma * rng.standard_normal((n, 6))
    still = still_mask(y, h, 0.02, guard_s=0.0, floor_rad_s=0.0)
    assert still[9_900:10_600].all()
    assert not still[20_025:20_476].any()                # windows wholly on the turn
    assert (~still).sum() < 600                          # the turn ± one window, nothing else


def test_rocking_is_motion():
    """Rocking ±20 deg/s at 2 Hz about x, 10 s, a slow 0.5 deg/s turn about x, 4 s, rocking, 10 s.

    Every 1 s window mean of the rocking is 0: only the rough-block rule sees
    it (first differences reach 20·2π·2/50 = 5 deg/s, 250x the white noise
    0.02 deg/s). Between the rocking the local noise level is ~200x the
    typical one; capped at max_ratio = 10 the threshold is
    10 · 6 · 0.02/√50 = 0.17 deg/s and the slow turn is found (uncapped,
    about 3 deg/s, 1.3 s of it pass as still).
    """
    rng = np.random.default_rng(7)
    n, a, b, c, d = 15_000, 6_000, 6_500, 6_700, 7_200
    t = np.arange(n) * 0.02
    w = np.zeros((n, 3))
    w[a:b, 0] = w[c:d, 0] = 20.0 * RAD_PER_DEG * np.sin(2.0 * math.pi * 2.0 * t[a:b])
    w[b:c, 0] = 0.5 * RAD_PER_DEG
    y = w + 0.02 * RAD_PER_DEG * rng.standard_normal((n, 3))
    still = still_mask(y, np.eye(3), 0.02)
    assert not still[a:d].any()
    assert still[:a - 100].all() and still[d + 100:].all()   # 100 samples = guard + window


@pytest.mark.parametrize("guard_s", [0.0, 1.0])
@pytest.mark.parametrize("axes", [np.eye(3), np.array([[0.0, 0.0, 1.0]]),
                                  np.array([[0.0, 0.0, 1.0], [0.0, 0.6, 0.8]])],
                         ids=["triad", "one gyro", "two gyros"])
def test_motion_span_is_window_plus_guard(axes, guard_s):
    """A 10 deg/s turn about z over samples [a, b): flagged exactly on [a - 24 - g, b + 24 + g].

    A centred 1 s window (L = 50, samples t - 25 .. t + 24) touches the turn
    from t = a - 24 to t = b + 24; one sample at 10 deg/s moves its mean by
    0.2 deg/s (3.5e-3 rad/s), 4x the threshold z·σ/√L = 8.5e-4 rad/s;
    g = guard_s / dt. Rank < 3 layouts test their outputs directly. a, b are
    block boundaries, so no block straddles the step.
    """
    rng = np.random.default_rng(4)
    n, a, b = 12_000, 5_000, 5_500
    w = np.zeros((n, 3))
    w[a:b, 2] = 10.0 * RAD_PER_DEG
    y = w @ axes.T + 1e-3 * rng.standard_normal((n, len(axes))) + 0.01 * RAD_PER_DEG
    still = still_mask(y, axes, 0.02, guard_s=guard_s)
    g = round(guard_s / 0.02)
    moving = np.flatnonzero(~still)
    assert moving[0] == a - 24 - g and moving[-1] == b + 24 + g and moving.size == b - a + 48 + 2 * g + 1


def test_threshold_follows_the_data_scale():
    """Scaling the outputs by 8 (exact in binary) changes nothing: no absolute constant but the floor."""
    layout = LAYOUTS["S1N6"]
    m = lab_run(NoiseModel(BASE + _biases(6)), layout, np.random.default_rng(6))
    y = m.gyro_deg_s * RAD_PER_DEG
    ref = still_mask(y, layout.axes, 0.02, floor_rad_s=0.0)
    assert 0.5 < ref.mean() < 0.95                                   # both states present
    assert np.array_equal(still_mask(8.0 * y, layout.axes, 0.02, floor_rad_s=0.0), ref)


# -- the real array --------------------------------------------------------------------

@pytest.fixture(scope="module")
def mimu():
    m = read_measurement(MIMU)
    return m, _mask(m)


@needs_real
def test_mimu_static_orientations_and_hand_rotation(mimu):
    """MIMU4444 (24 axes, 62.5 Hz, 599 s): 20 static orientations, then hand rotation.

    Found: 20 still runs of 22.8, 19.3, 19.5, 20.5, 20.8, 19.8, 20.5, 20.8,
    19.7, 20.1, 23.8, 19.5, 20.8, 20.4, 20.5, 20.2, 19.8, 20.8, 21.4, 25.4 s
    (0-494.6 s), separated by 3.3-5.0 s of motion (each re-placement takes
    about 1-2 s, plus 2 x 1.5 s of half-window and guard), then the hand rotation
    496.0-596.8 s (up to 2000 deg/s) wholly moving, then a 0.85 s still tail.
    """
    m, still = mimu
    dt = 1.0 / m.sample_rate_hz
    runs, lengths = _runs(still, dt)
    long = [r for r, s in zip(runs, lengths) if 10.0 <= s <= 40.0]
    assert len(long) >= 15                                 # 20 found
    assert m.time_s[long[-1][1] - 1] < 496.0               # all before the hand rotation
    hand = (m.time_s >= 496.5) & (m.time_s <= 596.5)
    assert not still[hand].any()
    rate = np.abs(m.gyro_deg_s @ np.linalg.pinv(m.layout.axes).T).max(axis=1)
    assert not np.any(still & (rate > 5.0))               # 5 deg/s is ~50 sigma of one sample of ω̂
    gaps = np.array([c - b for (_, b), (c, _) in itertools.pairwise(long)]) * dt
    assert gaps.max() < 6.0                                # re-placements are short (max 5.0 s)


@needs_real
def test_mimu_each_triad_alone_finds_the_same_runs(mimu):
    """Each of the 8 MPU-9150 triads alone finds the array's 20 runs, ends within 1 s.

    Independent sensors agree; 1 s = window_s (found: within 0.54 s).
    """
    m, still = mimu
    dt = 1.0 / m.sample_rate_hz
    y, axes = m.gyro_deg_s * RAD_PER_DEG, np.asarray(m.layout.axes)
    ref = np.array([r for r, s in zip(*_runs(still, dt)) if s >= 10.0])
    for k in range(8):
        cols = slice(3 * k, 3 * k + 3)
        runs, lengths = _runs(still_mask(y[:, cols], axes[cols], dt), dt)
        own = np.array([r for r, s in zip(runs, lengths) if s >= 10.0])
        assert own.shape == ref.shape, k
        assert np.abs(own - ref).max() * dt <= 1.0, k


# -- bad input ------------------------------------------------------------------------

@pytest.mark.parametrize("y, axes, dt, match", [
    (np.zeros((1000, 3)), np.eye(4)[:, :3], 0.02, "axes"),
    (np.zeros(1000), np.eye(3)[:1], 0.02, "y_rad_s"),
    (np.full((1000, 3), np.nan), np.eye(3), 0.02, "finite"),
    (np.zeros((1000, 3)), np.eye(3), 0.0, "positive"),
    (np.zeros((100, 3)), np.eye(3), 0.02, "3 windows"),
])
def test_bad_input_is_refused(y, axes, dt, match):
    with pytest.raises(InputError, match=match):
        still_mask(y, axes, dt)
