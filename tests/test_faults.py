"""The four fault effects: simulated as the spec says, and fitted (onset and size with 1σ).

Outside truth: the spec's table and definitions (exact formulas, to the last
bit where the simulator has no randomness), filterpy's Kalman filter for the
bias tracker, scipy's bivariate normal for the up-crossing probability, and
the χ² distribution for the block variance test.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from gyroarray.effects.faults import scan as ff
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.effects import REGISTRY
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.protocol import Stage
from gyroarray.effects.model import NoiseModel
from gyroarray.core.units import deg_s_to_rad_s

SPEC = Path(__file__).resolve().parents[2] / "shared" / "spec" / "effects.md"
DT = 0.01
CONE6 = Layout.conical(1, 6, math.acos(1 / math.sqrt(3)))


def model(*entries: dict) -> NoiseModel:
    return NoiseModel.from_toml({"effects": list(entries)})


def run(m, omega, layout=CONE6, seed=0, **kw):
    return simulate_readings(m, omega, layout, DT, np.random.default_rng(seed), **kw)


def swing(n=3000):
    t = np.arange(n) * DT
    return t, deg_s_to_rad_s(50.0) * np.column_stack([np.sin(2 * np.pi * 0.3 * t),
                                                       np.cos(2 * np.pi * 0.2 * t), np.sin(t)])


# -- the registry matches the spec's faults table --------------------------------------

def _spec_faults() -> dict:
    """{name: [param, ...]} of the spec's "Faults" table (3 columns: name | params | output)."""
    text = SPEC.read_text(encoding="utf-8")
    section = text[text.index("### Faults"):]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 3 and cells[0].startswith("`fault_"):
            rows[cells[0].strip("`")] = re.findall(r"`([a-z0-9_]+)`", cells[1])
    return rows


def test_the_four_faults_are_registered_with_the_spec_parameters():
    spec = _spec_faults()
    assert list(spec) == ["fault_step", "fault_drift", "fault_stuck", "fault_noise"]
    for name, params in spec.items():
        eff = REGISTRY[name]
        assert eff.per_gyro and list(eff.param_names) == params, name
    assert REGISTRY["fault_step"].param("size_deg_s").unit == "deg/s"
    assert REGISTRY["fault_drift"].param("rate_deg_s2").unit == "deg/s²"
    # step/drift/stuck act on the final output, after quantization and saturation
    assert all(REGISTRY[f].stage > Stage.SATURATE for f in ("fault_step", "fault_drift", "fault_stuck"))
    assert REGISTRY["fault_noise"].stage == Stage.SHAPE


@pytest.mark.parametrize("entry", [
    {"effect": "fault_step", "start_s": 1.0, "size_deg_s": 0.1},
    {"effect": "fault_stuck", "start_s": 1.0},
])
def test_a_fault_needs_its_gyro(entry):
    with pytest.raises(InputError, match="gyro"):
        model(entry)


def test_a_negative_noise_ratio_is_refused():
    with pytest.raises(InputError, match="ratio"):
        model({"effect": "fault_noise", "gyro": 1, "start_s": 1.0, "ratio": -1.0})


# -- simulate: exact formulas --------------------------------------------------------

def test_step_and_drift_add_to_the_saturated_output():
    t, w = swing()
    base = [{"effect": "saturation", "range_deg_s": 30.0}]
    clean = run(model(*base), w)
    y = run(model(*base, {"effect": "fault_step", "gyro": 2, "start_s": 10.0, "size_deg_s": 0.5},
                  {"effect": "fault_drift", "gyro": 4, "start_s": 12.5, "rate_deg_s2": 0.02}), w)
    on = t >= 10.0
    np.testing.assert_array_equal(y[~on, 1], clean[~on, 1])
    # after saturation: a clipped gyro reads range + size (the step is not clipped)
    np.testing.assert_allclose(y[on, 1], clean[on, 1] + deg_s_to_rad_s(0.5), rtol=0, atol=1e-15)
    assert np.max(y[:, 1]) > deg_s_to_rad_s(30.0) + deg_s_to_rad_s(0.5) - 1e-12
    ramp = np.where(t >= 12.5, (t - 12.5) * deg_s_to_rad_s(0.02), 0.0)
    np.testing.assert_allclose(y[:, 3], clean[:, 3] + ramp, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(y[:, [0, 2, 4, 5]], clean[:, [0, 2, 4, 5]])


def test_stuck_repeats_the_last_quantized_value_forever():
    t, w = swing()
    base = [{"effect": "arw", "n_deg_rt_h": 0.1}, {"effect": "quantization", "q_deg": 1e-4}]
    clean = run(model(*base), w, seed=3)
    y = run(model(*base, {"effect": "fault_stuck", "gyro": 5, "start_s": 7.005}), w, seed=3)
    i0 = int(np.searchsorted(t, 7.005))                       # first sample with t >= start
    np.testing.assert_array_equal(y[:i0, 4], clean[:i0, 4])
    assert np.all(y[i0:, 4] == clean[i0 - 1, 4])               # the quantized value, bit for bit
    np.testing.assert_array_equal(y[:, :4], clean[:, :4])       # no other draw moved


def test_stuck_before_the_first_sample_is_refused():
    with pytest.raises(InputError, match="no value before"):
        run(model({"effect": "fault_stuck", "gyro": 1, "start_s": 0.0}), np.zeros((10, 3)))


def test_noise_fault_scales_the_arw_draw_only():
    n = 2000
    t = np.arange(n) * DT
    arw = {"effect": "arw", "n_deg_rt_h": 0.2}
    rrw = {"effect": "rrw", "k_deg_h_rt_h": 50.0}
    burst = {"effect": "burst", "start_s": 5.0, "end_s": 12.0, "variance_ratio": 4.0}
    fault = {"effect": "fault_noise", "gyro": 3, "start_s": 8.0, "ratio": 3.0}
    white = run(model(arw, burst), np.zeros((n, 3)), seed=4)
    y = run(model(arw, rrw, burst, fault), np.zeros((n, 3)), seed=4)
    walk = run(model(rrw), np.zeros((n, 3)), seed=4)
    gain = np.where(t >= 8.0, 3.0, 1.0)                        # on top of the burst's √4
    np.testing.assert_allclose(y[:, 2], gain * white[:, 2] + walk[:, 2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(y[:, [0, 1, 3]], white[:, [0, 1, 3]] + walk[:, [0, 1, 3]],
                               rtol=0, atol=1e-15)


def test_a_fault_after_the_record_changes_nothing():
    _, w = swing(500)
    clean = run(model({"effect": "arw", "n_deg_rt_h": 0.1}), w, seed=1)
    y = run(model({"effect": "arw", "n_deg_rt_h": 0.1},
                  {"effect": "fault_stuck", "gyro": 1, "start_s": 99.0},
                  {"effect": "fault_step", "gyro": 2, "start_s": 99.0, "size_deg_s": 1.0}), w, seed=1)
    np.testing.assert_array_equal(y, clean)


# -- the bias tracker and the calibration pieces ----------------------------------------

def test_bias_tracker_innovations_match_filterpy():
    from filterpy.kalman import KalmanFilter
    rng = np.random.default_rng(2)
    q, n = 0.05, 400
    y = np.cumsum(rng.standard_normal(n) * math.sqrt(q)) + rng.standard_normal(n) + 30.0
    eps = ff.rw_innovations(y, q)
    kf = KalmanFilter(dim_x=1, dim_z=1)
    kf.x = np.array([[y[0]]])
    kf.P = np.array([[1.0]])                                   # started on the first sample
    kf.F, kf.H, kf.R, kf.Q = (np.eye(1), np.eye(1), np.eye(1), np.array([[q]]))
    ref = [0.0]
    for k in range(1, n):
        kf.predict()
        kf.update(np.array([[y[k]]]))
        ref.append(float(kf.y[0, 0]) / math.sqrt(float(kf.S[0, 0])))
    # the closed-form gain vs filterpy's sequential Riccati: rounding only
    np.testing.assert_allclose(eps, ref, rtol=0, atol=1e-9)
    K, S = ff.steady_gain(q)
    assert abs(kf.K[0, 0] - K) < 1e-12 and abs(kf.S[0, 0] - S) < 1e-12


@pytest.mark.parametrize("r", [-0.5, 0.0, 0.6, 0.98])
def test_upcrossing_probability_against_the_bivariate_normal(r):
    u = 2.2                                                    # where scipy's cdf is accurate
    mvn = stats.multivariate_normal(mean=[0, 0], cov=[[1, r], [r, 1]])
    # P(|Y0| <= u, |Y1| > u) = P(|Y0| <= u) − P(|Y0| <= u, |Y1| <= u)
    inner = mvn.cdf([u, u]) - mvn.cdf([-u, u]) - mvn.cdf([u, -u]) + mvn.cdf([-u, -u])
    want = (1 - 2 * stats.norm.sf(u)) - inner
    assert ff.upcrossing_prob(u, r) == pytest.approx(want, rel=1e-4, abs=1e-7)


def test_block_variance_glr_pvalue_is_the_chi2_tail():
    L, g = 64, 6.0
    lo, hi = ff._glr_roots(g, L)
    for lam in (lo, hi):                                       # both roots sit on the level
        assert 0.5 * L * (lam - 1 - math.log(lam)) == pytest.approx(g, rel=1e-9)
    want = stats.chi2.cdf(L * lo, L) + stats.chi2.sf(L * hi, L)
    assert ff.chi2_glr_pvalue(g, L) == pytest.approx(want, rel=1e-12)
    # and by simulation: 200 000 blocks, binomial 4σ
    x = np.random.default_rng(0).chisquare(L, 200_000) / L
    hits = np.mean(0.5 * L * (x - 1 - np.log(x)) > g)
    sd = math.sqrt(want * (1 - want) / x.size)
    assert abs(hits - want) < 4 * sd


# -- the fit side: onset and size with 1σ, z under the null ---------------------------

N_ARW = math.radians(0.1 / 60)            # 0.1 deg/√h [rad/√s]
K_RRW = math.radians(600 / 3600 / 60)     # 600 deg/h/√h [rad/s/√s]
R = N_ARW**2 / DT
Q = K_RRW**2 * DT


def _residual(seed, n=12000, fault=None):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    y = np.cumsum(rng.standard_normal(n) * math.sqrt(Q)) + rng.standard_normal(n) * math.sqrt(R) + 1e-3
    if fault == "step":
        y = y + (t >= 60.0) * deg_s_to_rad_s(0.03)
    elif fault == "drift":
        y = y + np.where(t >= 40.0, (t - 40.0) * deg_s_to_rad_s(0.004), 0.0)
    elif fault == "noise":
        white = rng.standard_normal(n) * math.sqrt(R)
        y = y + np.where(t >= 70.0, 0.8 * white, 0.0)           # ratio √(1 + 0.8²) = 1.281
    return t, y


@pytest.mark.parametrize("kind,param,true,start", [
    ("step", "size_deg_s", 0.03, 60.0),
    ("drift", "rate_deg_s2", 0.004, 40.0),
    ("noise", "ratio", math.sqrt(1 + 0.8**2), 70.0),
])
def test_fit_recovers_onset_and_size_within_their_sigma(kind, param, true, start):
    pulls, onset_pulls = [], []
    for seed in range(12):
        t, y = _residual(100 + seed, fault=kind)
        f = ff.fit_fault(kind, y, DT, R, Q, time_s=t)
        assert f.z > 3.0, (seed, f)                            # clearly present
        pulls.append((f.params[param] - true) / f.params_sigma[param])
        onset_pulls.append((f.onset_s - start) / max(f.onset_sigma_s, DT))
    pulls = np.array(pulls)
    # 12 pulls of N(0, 1): mean within 3/√12 = 0.87, rms below 1.6 (χ²₁₂ 99.5 % is 28.3 -> 1.54)
    assert abs(pulls.mean()) < 0.87 and math.sqrt(np.mean(pulls**2)) < 1.6, pulls
    # onsets: the profile-likelihood half-width covers the truth at least half the time
    assert np.mean(np.abs(onset_pulls) <= 1.5) >= 0.5, onset_pulls


def test_stuck_fit_from_the_output_is_exact():
    t, y = _residual(7)
    out = y.copy()
    out[5000:] = out[4999]
    f = ff.fit_fault("stuck", y, DT, R, Q, time_s=t, output_rad_s=out)
    assert f.onset_s == t[5000] and f.z > 8
    assert ff.fit_fault("stuck", y, DT, R, Q, time_s=t, output_rad_s=y).z < 3


def test_z_is_standard_normal_without_a_fault():
    # 48 clean residuals x 4 kinds; the Monte Carlo null is cached per shape, so cheap
    zs = {k: [] for k in ff.KINDS}
    for seed in range(48):
        t, y = _residual(1000 + seed, n=6000)
        for k in ff.KINDS:
            zs[k].append(ff.fit_fault(k, y, DT, R, Q, time_s=t).z)
    for k, v in zs.items():
        v = np.array(v)
        # mean of 48 N(0, 1) within 3/√48 = 0.43 (+ 0.15 for the 200-draw null);
        # sd within [0.65, 1.35] (χ²₄₇ 0.5–99.5 % is [0.70, 1.32] in sd, plus the null's)
        assert abs(v.mean()) < 0.58 and 0.65 < v.std() < 1.35, (k, v.mean(), v.std())


# -- z beyond p = 1e-16, and the speed-ups of the tail (diagnosis ranks faults against other effects)

@pytest.mark.parametrize("log_p", [-40.0, -1000.0, -1e5])
def test_z_of_log_p_inverts_the_normal_tail(log_p):
    z = ff._z_of_logp(log_p)
    assert stats.norm.logsf(z) == pytest.approx(log_p, rel=1e-9)


def test_scan_z_carries_on_past_the_float_floor_continuously():
    """p(y) = 1000·2Φ̄(y) (a scan over many onsets): its z solves ln Φ̄(z) = ln 2000 + ln Φ̄(y),
    computable exactly in logs; the carried z = √(z₁₆² + y² − y₁₆²) agrees to 0.05 out to y = 50
    and has no jump where p crosses 1e-16 (it used to stop at 8.3, then jump to inf)."""
    def p(y):
        return min(1.0, 2000.0 * float(stats.norm.sf(y)))

    for y in (12.0, 20.0, 50.0):
        exact = ff._z_of_logp(math.log(2000.0) + stats.norm.logsf(y))
        assert ff._z_of_scan(y, p) == pytest.approx(exact, abs=0.05)
    y16 = ff._solve_y16(p)
    assert p(y16) == pytest.approx(1e-16, rel=1e-2)
    below, above = ff._z_of_scan(y16 - 1e-6, p), ff._z_of_scan(y16 + 1e-6, p)
    assert abs(above - below) < 1e-3
    zs = [ff._z_of_scan(y, p) for y in np.linspace(5.0, 60.0, 40)]
    assert np.all(np.diff(zs) > 0)


def test_the_tail_sum_on_the_onset_grid_equals_the_full_sum():
    """The clump rates summed on the grid (ends dense, geometric between) against every onset."""
    rng = np.random.default_rng(3)
    n = 60000
    for kind, qn in (("step", 1e-7), ("step", 1e-2), ("drift", 1e-4)):
        K, S = (float(v) for v in ff.steady_gain(qn))
        _, _, mr, ms = ff.profile_means(rng.standard_normal((n, 1)), [1.0 - K], [K], [S],
                                        np.ones((1, 1)), kind, np.arange(n - 1))
        for y in (3.0, 6.0, 10.0):
            full = float(np.sum(ff.clump_rate(y, mr[:, 0], ms[:, 0])))
            idx, w = ff._onset_grid(mr.shape[0])
            grid = float(np.sum(w * ff.clump_rate(y, mr[idx, 0], ms[idx, 0])))
            assert grid == pytest.approx(full, rel=1e-4)


def test_noise_fault_ratio_holds_when_the_random_walk_is_overestimated():
    """A calibration on the faulty record inflates q (the raised tail reads as a walk): the ratio
    read from the first differences does not care. 40 records of 20 000 samples, ratio 3 from the
    middle, q given 1e6 times too large: the mean ratio is within 3 standard errors of 3, and the
    reported 1σ matches the spread over the records within its sampling error (χ², 39 dof: ±35 %)."""
    r, q_true, n = 1.0, 1e-8, 20000
    rng = np.random.default_rng(11)
    got, sig = [], []
    for _ in range(40):
        w = rng.standard_normal(n)
        w[n // 2:] *= 3.0
        y = w + np.cumsum(rng.standard_normal(n) * math.sqrt(q_true))
        f = ff.fit_fault("noise", y, 0.01, r, 1e6 * q_true)
        got.append(f.params["ratio"])
        sig.append(f.params_sigma["ratio"])
    got = np.asarray(got)
    assert abs(got.mean() - 3.0) < 3.0 * got.std(ddof=1) / math.sqrt(got.size)
    assert 0.65 < got.std(ddof=1) / np.mean(sig) < 1.35


def test_variance_scan_is_deflated_by_the_noise_colour():
    """1 + 2Σρₖ² of an AR(1) with coefficient φ is 1 + 2φ²/(1 − φ²) (closed form)."""
    rng = np.random.default_rng(4)
    phi = 0.8
    from scipy import signal as sg
    x = sg.lfilter([1.0], [1.0, -phi], rng.standard_normal(400000))
    assert ff._variance_dof_factor(x) == pytest.approx(1.0 + 2.0 * phi ** 2 / (1.0 - phi ** 2), rel=0.05)
    assert ff._variance_dof_factor(rng.standard_normal(400000)) == pytest.approx(1.0, abs=0.01)


def test_variance_null_carried_to_a_longer_record_matches_its_monte_carlo():
    """Beyond 2¹⁷ samples the null is simulated on 2¹⁷ and carried by the clump ratio. Against 200
    direct draws on 2¹⁸: the carried p at the draws' 50/80/90 % quantiles is within 3 binomial σ."""
    n = 1 << 18
    onsets = ff._variance_onsets(n)
    rng = np.random.default_rng(8)
    mx = np.sort([math.sqrt(2.0 * ff.profile_variance_change(rng.standard_normal(n), onsets)[0].max())
                  for _ in range(200)])
    ma = n - onsets.astype(float)
    p = ff._variance_null_pvalue("both", n, 1.0 - np.sqrt(ma[1:] / ma[:-1]), {})
    for q in (0.5, 0.8, 0.9):
        want = 1.0 - q
        assert abs(p(float(mx[int(q * 199)])) - want) < 3.0 * math.sqrt(want * q / 200)


def _static_triad(n: int, seed: int):
    """A plain-numpy static triad [rad/s]: white 0.5 deg/s per sample and a random walk of
    1e-4 deg/s per sample, no gyroarray simulator."""
    rng = np.random.default_rng(seed)
    w = 0.5 * rng.standard_normal((n, 3)) + np.cumsum(1e-4 * rng.standard_normal((n, 3)), axis=0)
    return deg_s_to_rad_s(w)


def test_a_step_on_the_first_or_last_samples_is_not_called_a_fault():
    """A jump of the last three samples (the MPU-6050 record ends in its stepper's reversal) and
    of the first three (a turn-on transient) put a fault's onset within a few samples of an end
    of the record: not identifiable as faults, and said so (the first three also read as a
    noise drop from 0.22 s). The same step 3000 samples before the end is a fault,
    and its onset is where the record (plain numpy, written here) puts it."""
    from gyroarray.chain.compare import ModelComparison
    from gyroarray.core.measurement import Measurement

    n = 30000
    y = _static_triad(n, 11)
    y[-3:, 1] += deg_s_to_rad_s(4.0)                    # gyro 2: the last three samples
    y[:3, 2] += deg_s_to_rad_s(4.0)                     # gyro 3: the first three
    y[n - 3000:, 0] += deg_s_to_rad_s(0.3)              # gyro 1: a real step, 30 s before the end
    m = Measurement(time_s=DT * np.arange(n), gyro_deg_s=np.degrees(y), layout=Layout.triad(),
                    sample_rate_hz=1 / DT)
    a = ModelComparison(m, n_runs=3).analyse()
    notes = " ".join(a.notes)
    assert re.search(r"fault_step on gyro 2: not identifiable \(onset 299\.9\d* ± [^)]*record's end", notes), notes
    assert re.search(r"fault_step on gyro 3: not identifiable \(onset 0\.0\d* ± [^)]*record's start", notes), notes
    assert re.search(r"fault_noise on gyro 3: not identifiable \(onset 0\.\d* ± [^)]*record's start", notes), notes
    by = {(t.effect, t.gyro): t for t in a.candidates}
    # z 11–13 before: step, drift and noise on gyro 2, noise on gyro 3
    assert not {("fault_step", 2), ("fault_drift", 2), ("fault_noise", 2), ("fault_step", 3),
                ("fault_noise", 3)} & set(by)
    assert not any(a.significant(t) for t in a.candidates if t.effect.startswith("fault_") and t.gyro != 1)
    step = by[("fault_step", 1)]
    assert a.significant(step)
    start, sig = step.fit.params["start_s"], step.fit.extra["onset_sigma_s"]
    assert abs(start - DT * (n - 3000)) <= max(3.0 * sig, DT), (start, sig)
