"""Array noise model (issue 31, item 2): cross-covariance of the white and slow parts with CIs,
regularisation, shared lines, and the ``[array]`` table of the model file.

Outside truths are written here with plain numpy (Cholesky factors of known covariances,
``np.cov`` of first differences, the Allan block weights) and ``scipy.signal.coherence``,
never gyroarray's simulator.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal, stats

from gyroarray.analysis.array_covariance import (coherence_matrix, regularised, shared_lines,
                                                 slow_covariance, white_covariance)
from gyroarray.core.errors import InputError
from gyroarray.effects.model import ArrayNoise, ModelEntry, NoiseModel
from hostile import SIDECAR_3, assert_contract, run_cli, write_measurement

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
MIMU = SHARED / "measurements" / "real" / "mimu4444_array24.csv.gz"
LEVEL = 0.95


def _random_cov(rng, n: int, floor: float) -> np.ndarray:
    """A non-uniform SPD covariance: unequal variances, pair-dependent correlations."""
    a = rng.normal(size=(n, n))
    c = a @ a.T / n + floor * np.eye(n)
    s = np.exp(rng.uniform(-1.0, 1.0, n))            # variances differ up to e² ≈ 7×
    return c * np.outer(s, s)


def _corr(c: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.diag(c))
    return c / np.outer(d, d)


def _binomial_low(n_trials: int, p: float = LEVEL, k: float = 4.0) -> float:
    """Lowest acceptable coverage of ``n_trials`` interval checks (draws × elements): p − k·√(p(1−p)/n)
    (k = 4: the elements of one draw are not quite independent)."""
    return p - k * math.sqrt(p * (1 - p) / n_trials)


# -- white part -------------------------------------------------------------------

def test_white_covariance_is_numpy_cov_of_first_differences_over_two():
    rng = np.random.default_rng(1)
    x = rng.standard_normal((3000, 5)) @ np.linalg.cholesky(_random_cov(rng, 5, 0.5)).T
    w = white_covariance(x, 0.01)
    np.testing.assert_allclose(w.covariance, np.cov(np.diff(x, axis=0).T) / 2, rtol=1e-13, atol=0)
    # parts: no difference across a cut
    parts = [(0, 1000), (1200, 3000)]
    d = np.concatenate([np.diff(x[a:b], axis=0) for a, b in parts])
    wp = white_covariance(x, 0.01, parts=parts)
    np.testing.assert_allclose(wp.covariance, np.cov(d.T) / 2, rtol=1e-13, atol=0)
    assert wp.n_used == d.shape[0]


def test_white_ci_covers_the_truth_at_the_nominal_rate_on_repeated_draws():
    rng = np.random.default_rng(7)
    N, n, draws = 6, 2000, 200
    R = _random_cov(rng, N, 0.5)
    L, rt = np.linalg.cholesky(R), _corr(R)
    iu, iu1 = np.triu_indices(N), np.triu_indices(N, 1)
    cov_hit = rho_hit = 0
    est, half = [], []
    for _ in range(draws):
        w = white_covariance(rng.standard_normal((n, N)) @ L.T, 0.01, level=LEVEL)
        cov_hit += np.sum(((w.cov_lo <= R) & (R <= w.cov_hi))[iu])
        rho_hit += np.sum(((w.corr_lo <= rt) & (rt <= w.corr_hi))[iu1])
        est.append(w.correlation[iu1])
        half.append((w.corr_hi - w.corr_lo)[iu1] / 2)
    cov_cov, rho_cov = cov_hit / (draws * iu[0].size), rho_hit / (draws * iu1[0].size)
    print(f"white: coverage of covariances {cov_cov:.3f}, of correlations {rho_cov:.3f} (nominal {LEVEL})")
    assert _binomial_low(draws * iu[0].size) <= cov_cov, cov_cov
    assert _binomial_low(draws * iu1[0].size) <= rho_cov, rho_cov
    # not too wide either: the mean half-width is 1.96 × the spread of the estimates over draws
    ratio = np.mean(half, axis=0) / (stats.norm.ppf(0.975) * np.std(est, axis=0))
    assert 0.85 < float(np.median(ratio)) < 1.15, ratio
    # the MA(1) correction matters: ν = 2n/3, not n, for white noise
    assert np.allclose(w.dof[0, 0], 2 * (n - 1) / 3, rtol=0.1)


# -- simulated 8-gyro array with white and random-walk parts --------------------------

def _allan_weight_sum(m: int) -> float:
    """Σ c_l² of the random-walk increments in ȳ_{k+1} − ȳ_k (blocks of m): plain numpy."""
    w = np.concatenate([-np.ones(m), np.ones(m)]) / m        # weights of x_0 .. x_{2m-1}
    c = np.cumsum(w[::-1])[::-1][1:]                            # coefficient of increment l = 1 .. 2m-1
    return float(np.sum(c ** 2))


def test_eight_gyro_array_white_and_walk_recovered_within_their_intervals():
    rng = np.random.default_rng(11)
    N, n, dt, m, draws = 8, 20000, 0.01, 50, 20
    R = _random_cov(rng, N, 0.4)                                # white, per sample [rad²/s²]
    sd = np.sqrt(np.diag(R))
    # rate random walk increments per sample, its own correlations; at m = 50 the white part
    # is a quarter of each gyro's Allan variance
    Q = 4e-3 * _corr(_random_cov(rng, N, 0.4)) * np.outer(sd, sd)
    LR, LQ = np.linalg.cholesky(R), np.linalg.cholesky(Q)
    # E[Cov(Δx)/2] = R + Q/2; slow = E[A(m)] − E[Σ_w]/m = Q Σc²/2 − Q/(2m)
    white_truth = R + Q / 2
    slow_truth = Q * (_allan_weight_sum(m) / 2 - 1 / (2 * m))
    iu, iu1 = np.triu_indices(N), np.triu_indices(N, 1)
    hits = {"white cov": 0, "white rho": 0, "slow cov": 0, "slow rho": 0}
    for _ in range(draws):
        x = rng.standard_normal((n, N)) @ LR.T + np.cumsum(rng.standard_normal((n, N)) @ LQ.T, axis=0)
        w = white_covariance(x, dt)
        s = slow_covariance(x, dt, tau_s=m * dt, white=w)
        assert s.seen.all() and s.n_used == n // m - 1
        hits["white cov"] += np.sum(((w.cov_lo <= white_truth) & (white_truth <= w.cov_hi))[iu])
        hits["white rho"] += np.sum(((w.corr_lo <= _corr(R)) & (_corr(R) <= w.corr_hi))[iu1])
        hits["slow cov"] += np.sum(((s.cov_lo <= slow_truth) & (slow_truth <= s.cov_hi))[iu])
        hits["slow rho"] += np.sum(((s.corr_lo <= _corr(Q)) & (_corr(Q) <= s.corr_hi))[iu1])
    for key, h in hits.items():
        k = draws * (iu if "cov" in key else iu1)[0].size
        low = _binomial_low(k)
        print(f"{key}: coverage {h / k:.3f} (nominal {LEVEL}, lowest accepted {low:.3f})")
        assert low <= h / k <= 1.0, (key, h / k)
    # the white share matters: without removing Σ_w/m the slow estimate is biased high
    assert np.all(np.diag(s.covariance) < np.diag(s.covariance + w.covariance / m))


# -- definiteness -----------------------------------------------------------------

def test_not_positive_definite_is_refused_or_regularised_with_a_note():
    bad = np.array([[1.0, 0.9, -0.9], [0.9, 1.0, 0.9], [-0.9, 0.9, 1.0]])
    with pytest.raises(InputError, match="not positive definite"):
        regularised(bad, how="refuse", what="white", name="rec.csv")
    for how in ("clip", "shrink"):
        out, notes = regularised(bad, how=how, sigma=np.full((3, 3), 0.05), what="white")
        assert np.linalg.eigvalsh(out)[0] > 0 and np.allclose(np.diag(out), 1) and np.allclose(out, out.T)
        assert len(notes) == 1 and ("clipping" if how == "clip" else "shrinkage") in notes[0]
    good = np.array([[1.0, 0.3], [0.3, 1.0]])
    same, notes = regularised(good, how="shrink")
    assert same is good and notes == []


def test_slow_part_of_too_few_blocks_for_its_gyros_is_refused_or_shrunk():
    rng = np.random.default_rng(3)
    N, n = 8, 4000
    x = rng.standard_normal((n, N)) + np.cumsum(0.3 * rng.standard_normal((n, N)), axis=0)
    with pytest.raises(InputError, match="cannot be estimated from 6 block differences") as err:
        slow_covariance(x, 0.01, tau_s=5.7, name="rec.csv")
    assert str(err.value).startswith("rec.csv: ")
    s = slow_covariance(x, 0.01, tau_s=5.7, regularise="shrink")
    assert np.linalg.eigvalsh(s.correlation)[0] > 0
    assert any("shrinkage" in note for note in s.notes) and any("cannot be estimated" in n for n in s.notes)


# -- common mode ------------------------------------------------------------------

def test_coherence_equals_scipy_and_a_shared_line_is_named_with_its_gyros():
    rng = np.random.default_rng(5)
    N, n, dt = 8, 30000, 0.01
    R = _random_cov(rng, N, 0.5)
    x = rng.standard_normal((n, N)) @ np.linalg.cholesky(R).T
    f, coh, _ = coherence_matrix(x, dt, nperseg=256)
    f2, c2 = signal.coherence(x[:, 2], x[:, 5], fs=1 / dt, nperseg=256)
    np.testing.assert_allclose(f, f2)
    np.testing.assert_allclose(coh[:, 2, 5], c2, atol=1e-12)
    # correlated white noise is coherent at every frequency: no line
    assert shared_lines(x, dt) == []
    t = np.arange(n) * dt
    y = x.copy()
    y[:, [1, 3, 6]] += 0.4 * np.sin(2 * np.pi * 17.5 * t + 0.3)[:, None] * np.array([1.0, -1.0, 0.7])
    lines = shared_lines(y, dt)
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.gyros == (2, 4, 7) and abs(line.f_hz - 17.5) <= 1 / (256 * dt)
    assert line.f_lo_hz <= 17.5 <= line.f_hi_hz and line.n_pairs == 3


# -- the model file ----------------------------------------------------------------

OLD = '''description = "old"
effects = [
    {effect = "arw", n_deg_rt_h = 0.1},
    {effect = "correlation", rho_arw = 0.2},
]
'''

ARRAY = '''
[array]
gyros = [1, 2, 3]
white_n_deg_rt_h = [0.1, 0.25, 0.3]
white_correlation = [
    [1.0, 0.1, 0.0],
    [0.1, 1.0, -0.2],
    [0.0, -0.2, 1.0],
]
walk_tau_s = 4.096
walk_adev_deg_h = [1.5, 0.0, 2.0]
walk_correlation = [
    [1.0, 0.0, 0.3],
    [0.0, 1.0, 0.0],
    [0.3, 0.0, 1.0],
]
shared = [
    {f_hz = 17.5, band_hz = [17.2, 17.9], gyros = [1, 3], coherence = 0.56},
]
notes = [
    "slow part not seen on gyro 2",
]

[array.sigma]
white_correlation = [[0.0, 0.01, 0.01], [0.01, 0.0, 0.01], [0.01, 0.01, 0.0]]
'''


def test_old_model_files_read_unchanged(tmp_path):
    p = tmp_path / "old.toml"
    p.write_text(OLD)
    m = NoiseModel.from_toml(p, n_gyros=3)
    assert m.array is None and "[array]" not in m.to_toml()
    assert m.to_toml() == "# gyroarray noise model (effects: shared/spec/effects.md)\n" + OLD
    assert m.with_effect(ModelEntry("rrw", 2, {"k_deg_h_rt_h": 1.0})).array is None


def test_array_table_round_trips_exactly(tmp_path):
    p = tmp_path / "new.toml"
    p.write_text(OLD + ARRAY)
    m = NoiseModel.from_toml(p, n_gyros=3)
    assert isinstance(m.array, ArrayNoise) and m.array.gyros == (1, 2, 3)
    assert m.array.white_correlation[1][2] == -0.2 and m.array.shared[0]["gyros"] == (1, 3)
    text = m.to_toml()
    assert text == "# gyroarray noise model (effects: shared/spec/effects.md)\n" + OLD + ARRAY
    q = tmp_path / "again.toml"
    q.write_text(text)
    again = NoiseModel.from_toml(q)
    assert again == m and again.to_toml() == text
    assert m.with_effect(ModelEntry("rrw", 2, {"k_deg_h_rt_h": 1.0})).array == m.array


@pytest.mark.parametrize("key, value, what", [
    ("white_correlation", "[[1.0, 0.1], [0.1, 1.0]]", "must be a 3x3 matrix"),
    ("white_correlation", "[[1.0, 0.1, 0.0], [0.2, 1.0, 0.0], [0.0, 0.0, 1.0]]", "not symmetric"),
    ("white_correlation", "[[1.0, 0.9, -0.9], [0.9, 1.0, 0.9], [-0.9, 0.9, 1.0]]", "not positive definite"),
    ("walk_correlation", "[[1.0, 1.5, 0.0], [1.5, 1.0, 0.0], [0.0, 0.0, 1.0]]", "is not a correlation"),
    ("white_correlation", "[[0.9, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]", "1 on its diagonal"),
    ("white_n_deg_rt_h", "[0.1, -0.2, 0.3]", "non-negative numbers"),
    ("gyros", "[1, 1, 2]", "names a gyro twice"),
    ("whte_correlation", "[[1.0]]", "did you mean 'white_correlation'"),
])
def test_malformed_array_tables_are_refused_with_file_and_line(tmp_path, key, value, what):
    body = {"gyros": "[1, 2, 3]", key: value}
    if key.startswith("walk"):
        body["walk_tau_s"] = "2.0"
    text = "effects = []\n\n[array]\n" + "".join(f"{k} = {v}\n" for k, v in body.items())
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(InputError, match=what) as err:
        NoiseModel.from_toml(p)
    line = next(i for i, s in enumerate(text.split("\n"), 1) if s.startswith(key + " "))
    assert str(err.value).startswith(f"{p}, line {line}, column array.{key}: [array] "), str(err.value)


def test_a_malformed_array_table_is_one_line_exit_2_from_a_command(tmp_path):
    t = np.arange(600) * 0.02
    meas = write_measurement(tmp_path, "plain", t, np.random.default_rng(0).normal(0, 0.1, (600, 3)), SIDECAR_3)
    p = tmp_path / "bad.toml"
    p.write_text('effects = []\n\n[array]\ngyros = [1, 2, 3]\n'
                 'white_correlation = [[1.0, 0.1, 0.0], [0.2, 1.0, 0.0], [0.0, 0.0, 1.0]]\n')
    o = run_cli(["diagnose", meas, "--model", p], timeout=60)
    assert_contract(o, "bad.toml, line 5")
    assert o.code == 2 and "not symmetric" in o.err
    # a gyro beyond the array's
    p.write_text('effects = []\n\n[array]\ngyros = [1, 2, 5]\n')
    o = run_cli(["diagnose", meas, "--model", p], timeout=60)
    assert_contract(o, "bad.toml")
    assert o.code == 2 and "gyro 5 does not exist" in o.err


# -- the shared real array ------------------------------------------------------------

@pytest.mark.skipif(not MIMU.is_file(), reason="shared data not found")
def test_mimu4444_z_pairs_correlate_and_share_the_17_5_hz_line(tmp_path):
    from gyroarray.chain.array_model import array_model, with_array_model
    from gyroarray.core.measurement import read_measurement
    meas = read_measurement(MIMU)
    am = array_model(meas)
    H = np.asarray(meas.layout.axes)
    z = [k for k in range(24) if abs(H[k, 2]) > 0.5]
    sign = np.sign(H[z, 2])
    rho = (am.white.correlation[np.ix_(z, z)] * np.outer(sign, sign))[np.triu_indices(8, 1)]
    assert 0.01 < rho.mean() < 0.05 and np.all(rho > 0)           # issue 31: +0.026, all 28 positive
    zline = [s for s in am.shared if set(s.gyros) == {k + 1 for k in z}]
    assert len(zline) == 1 and 16.5 <= zline[0].f_hz <= 18.5 and zline[0].n_pairs == 28
    model = with_array_model(NoiseModel(), am)
    p = tmp_path / "array.toml"
    p.write_text(model.to_toml())
    assert NoiseModel.from_toml(p, n_gyros=24) == model


def test_array_model_of_a_measurement_writes_a_table_that_reads_back(tmp_path):
    from gyroarray.chain.array_model import array_model, with_array_model
    from gyroarray.core.layout import Layout
    from gyroarray.core.measurement import Measurement
    rng = np.random.default_rng(2)
    n, N = 6000, 4
    axes = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0.6, 0, 0.8]])
    R = _random_cov(rng, N, 0.5) * 1e-4
    g = rng.standard_normal((n, N)) @ np.linalg.cholesky(R).T
    meas = Measurement(time_s=np.arange(n) * 0.01, gyro_deg_s=g, layout=Layout(axes), sample_rate_hz=100.0,
                       source="board.csv")
    am = array_model(meas)
    assert am.gyros == (1, 2, 3, 4) and am.slow is not None
    np.testing.assert_allclose(am.white.covariance, np.cov(np.diff(np.radians(g), axis=0).T) / 2, rtol=1e-12)
    table = am.table()
    # white ARW [deg/√h] = ADEV(τ1) [deg/s] · √τ1 [√s] · 60, τ1 = 100 samples = 1 s (the level every
    # command reads: issue 41); the per-sample covariance stays in the JSON's "white"
    phase = np.vstack([np.zeros((1, N)), np.cumsum(g - g.mean(axis=0), axis=0)])
    d = phase[200:] - 2 * phase[100:-100] + phase[:-200]
    adev1 = np.sqrt((d ** 2).sum(axis=0) / (2.0 * 100 ** 2 * d.shape[0]))
    np.testing.assert_allclose(table.white_n_deg_rt_h, adev1 * 1.0 * 60, rtol=1e-5)
    assert table.white_tau_s == pytest.approx(1.0)
    model = with_array_model(NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),)), am)
    p = tmp_path / "m.toml"
    p.write_text(model.to_toml())
    assert NoiseModel.from_toml(p, n_gyros=N) == model
    short = Measurement(time_s=np.arange(300) * 0.01, gyro_deg_s=g[:300], layout=Layout(axes),
                        sample_rate_hz=100.0, source="short.csv")
    with pytest.raises(InputError, match="needs at least 512") as err:
        array_model(short)
    assert str(err.value).startswith("short.csv: ")
