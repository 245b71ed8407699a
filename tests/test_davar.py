"""Dynamic Allan deviation, fixed and adaptive windows (src/gyroarray/analysis/davar.py).

Truth from outside:

* :func:`gyroarray.analysis.allan.deviation` itself (one window = the record)
  and allantools window by window;
* a straightforward re-implementation of the A-DAVAR recursion with
  ``scipy.stats.kurtosis`` (Song et al. 2018, sec. 4.2);
* the exact moments of the ARW estimate for Gaussian white noise: at
  ``tau0`` the window's Allan variance is the quadratic form
  ``sum (y[j+1] - y[j])^2 / (2 (L-1))``, so the mean of an ARW track over
  any set of windows has a computable expectation and standard deviation
  (:func:`_arw_mean_moments`; z-scores checked N(0, 1) over 60-300 seeds);
* the chi-square law of a deviation with the Greenhall EDF;
* the paper's simulated experiment (variance 1, 3 over 3000-4000 s) and its
  Table 1 nodes.

Seeds: the fixed seed is ``GYROARRAY_TEST_SEED`` (default 373, the paper's
article number); the robustness of every statistical assertion was checked
by running this file with 20 other seeds.
"""

from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import asdict
from pathlib import Path

import allantools
import numba
import numpy as np
import pytest
from scipy import stats

from gyroarray.core import units
from gyroarray.analysis.allan import (allan_analysis, confidence_interval,
                                      deviation, edf)
from gyroarray.analysis.davar import AdaptiveWindow, change_nodes, davar
from gyroarray.reports.davar_plots import plot_davar
from gyroarray.core.errors import InputError

# The paper's experiment (signal, Table 1) is a benchmark script, not part of the package.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from davar_paper import (PAPER_TABLE1, format_paper_table1, paper_signal,  # noqa: E402
                         paper_table1)

SEED = int(os.environ.get("GYROARRAY_TEST_SEED", "373"))

# |z| bound of the moment tests: two-sided 6e-5 per assertion for N(0, 1)
# (the z-scores are N(0, 1) within 0.1 in mean and sd, 300 seeds).
Z_MAX = 4.0
# Confidence of the per-window bounds: a 6000-window track at 8 taus is
# ~16 000 correlated tests; over 300 seeds the smallest one-sided tail
# probability per tau and tail was below 1e-5 in 1% of runs and never below
# 6e-8, so at 1 - 1e-9 a correct implementation fails about once in 1e4-1e5
# runs, while a deviation 25% off at tau0 (EDF 400) fails every time.
WIDE = 1.0 - 1e-9

SIGMA = units.deg_h_to_rad_s(0.5)     # white rate noise, 0.5 deg/h rms
TAU0 = 0.01                           # 100 Hz


def _white(seed: int, n: int = 6000, sigma: float = SIGMA) -> np.ndarray:
    return sigma * np.random.default_rng(seed).standard_normal(n)


def _mirror_index(j: np.ndarray, n: int) -> np.ndarray:
    """Record index of position ``j`` of the symmetric mirror extension."""
    j = np.asarray(j)
    return np.where(j < 0, -j - 1, np.where(j >= n, 2 * n - 1 - j, j))


def _arw_mean_moments(res, variance: np.ndarray, sel: np.ndarray
                      ) -> tuple[float, float]:
    """Expectation and sd of the mean ARW of the windows ``sel``.

    For independent Gaussian samples of variance ``variance[j]``, the ARW of
    a window at tau0 is ``N^2 = tau0/(2(L-1)) sum_j u_j^2`` over its L-1
    differences ``u_j = y[j+1] - y[j]`` (mirrored samples are the same
    random variables; the difference across a mirror junction is 0).
    ``E u_j^2 = v_j + v_{j+1}``, ``cov(u_j, u_{j+1}) = -v_{j+1}``, and for
    Gaussians ``cov(u^2, u'^2) = 2 cov(u, u')^2``.  The mean of ``N`` over
    the windows is linearised, ``N ~ mu + (N^2 - mu^2)/(2 mu)``; the
    neglected bias is ``-mu/(8 EDF)``, under 0.1 sd here.
    """
    tau0 = res.tau0_s
    n = variance.size
    a = res.start[sel]
    big_l = res.window_length[sel]
    lo = int(a.min())
    j = np.arange(lo, int((a + big_l - 1).max()))      # differences j, j+1
    r0, r1 = _mirror_index(j, n), _mirror_index(j + 1, n)
    junction = r0 == r1
    e_u2 = np.where(junction, 0.0, variance[r0] + variance[r1])
    pair = np.where(junction, -1, np.minimum(r0, r1))
    cum = np.concatenate([[0.0], np.cumsum(e_u2)])
    g = tau0 / (2.0 * (big_l - 1))
    mu = np.sqrt(g * (cum[a + big_l - 1 - lo] - cum[a - lo]))
    # coefficient of each u_j^2 in the (linearised) mean of N
    w = g / (2.0 * mu * a.size)
    coef = np.zeros(j.size + 1)
    np.add.at(coef, a - lo, w)
    np.add.at(coef, a + big_l - 1 - lo, -w)
    coef = np.cumsum(coef)[:-1]
    c = np.bincount(pair[~junction], weights=coef[~junction],
                    minlength=n - 1)
    v0, v1 = variance[:-1], variance[1:]
    var = (np.sum(2.0 * c ** 2 * (v0 + v1) ** 2)
           + 4.0 * np.sum(c[:-1] * c[1:] * v1[:-1] ** 2))
    return float(mu.mean()), float(math.sqrt(var))


def _z(res, variance, sel) -> float:
    mu, sd = _arw_mean_moments(res, variance, sel)
    return (float(np.mean(res.arw_rad_rt_s[sel])) - mu) / sd


# --------------------------------------------------------------------------
# Equivalences


@pytest.mark.parametrize("kind", ["oadev", "ohdev"])
def test_single_window_is_allan_deviation(kind):
    """The null model (window=None) and a record-long window without
    extension are the deviation of the record: bit-identical."""
    y = _white(SEED, 5000)
    taus = [0.01, 0.02, 0.05, 0.16, 1.0, 5.0]
    ref = deviation(y, TAU0, kind, taus)
    for res in (davar(y, TAU0, taus=taus, kind=kind),
                davar(y, TAU0, window=y.size, extension="none", taus=taus,
                      kind=kind)):
        assert res.n_windows == 1
        np.testing.assert_array_equal(res.adev_rad_s[0], ref.dev)
        np.testing.assert_array_equal(res.taus_s, ref.taus_s)
        assert res.time_s[0] == pytest.approx(0.5 * y.size * TAU0, rel=1e-15)
        assert res.window_length[0] == y.size
    # default taus: octaves up to a third of the window (paper sec. 4.1)
    res = davar(y, TAU0, kind=kind)
    np.testing.assert_array_equal(res.m, 2 ** np.arange(11))   # 1024 <= 5000/3
    np.testing.assert_array_equal(res.adev_rad_s[0],
                                  deviation(y, TAU0, kind, res.taus_s).dev)


def test_windows_match_allantools_and_mirror_definition():
    """Each window is allantools' OADEV of the mirror-extended record
    (y[-1-j] = y[j], y[n+j] = y[n-1-j], built here by hand): 1e-10
    relative (allantools sums in a different order)."""
    y = _white(SEED, 3000)
    n, big_l = y.size, 500
    res = davar(y, TAU0, window=big_l, step=250)
    ext = np.concatenate([y[::-1], y, y[::-1]])           # index j + n
    assert res.start[0] == -250 and res.time_s[0] == 0.0
    for a, length, dev in zip(res.start, res.window_length, res.adev_rad_s):
        seg = ext[a + n:a + n + length]
        _, ref, _, _ = allantools.oadev(seg, rate=1.0 / TAU0,
                                        data_type="freq", taus=res.taus_s)
        np.testing.assert_allclose(dev, ref, rtol=1e-10)


def test_adaptive_recursion_matches_reference():
    """Window lengths, flags and kurtosis against a plain re-implementation
    of Song et al. sec. 4.2 (kurtosis as in scipy.stats.kurtosis, checked
    on every 97th window): lengths and flags identical, kurtosis and
    contribution to 1e-9 relative (summation order)."""
    def kurt(w):
        d = w - w.mean()
        return np.mean(d ** 4) / np.mean(d ** 2) ** 2

    cases = [
        (paper_signal(np.random.default_rng(SEED)), AdaptiveWindow(),
         "mirror"),
        (_white(SEED + 1, 2500) * np.repeat([1.0, 2.0, 1.0],
                                            [1200, 400, 900]),
         AdaptiveWindow(l_max=301, l_min=101, l_tail=40, k2=3.2,
                        dl_shrink=4, dl_grow=2),
         "none"),
    ]
    for y, p, ext in cases:
        n = y.size
        res = davar(y, 1.0, adaptive=True, params=p, extension=ext)
        x = np.concatenate([y[::-1], y, y[::-1]])
        centres = (range(n) if ext == "mirror"
                   else range(p.l_max // 2, n - p.l_max + p.l_max // 2 + 1))
        length, k_ref, s_ref, f_ref = [], [], [], []
        big_l = p.l_max
        for c in centres:
            w = x[n + c - big_l // 2:n + c - big_l // 2 + big_l]
            k = kurt(w)
            km = kurt(w[:big_l - p.l_tail])
            if c % 97 == 0:
                assert k == pytest.approx(
                    stats.kurtosis(w, fisher=False, bias=True), rel=1e-12)
            s = abs(k - km) / k
            f = (not p.k1 <= k <= p.k2) and (not p.s1 <= s <= p.s2)
            length.append(big_l)
            k_ref.append(k)
            s_ref.append(s)
            f_ref.append(f)
            big_l = (max(p.l_min, big_l - p.dl_shrink) if f
                     else min(p.l_max, big_l + p.dl_grow))
        np.testing.assert_array_equal(res.window_length, length)
        np.testing.assert_array_equal(res.unstable, f_ref)
        np.testing.assert_allclose(res.kurtosis, k_ref, rtol=1e-9)
        np.testing.assert_allclose(res.contribution, s_ref, rtol=1e-9,
                                   atol=1e-12)
        assert res.window_length.min() < p.l_max     # the recursion moved


def test_window_length_rules_and_edges():
    """Paper eqs. 19-22 on the track: L in [L_min, L_max], steps of
    -dL1/+dL0 set by the flag, the leading edge fixed while shrinking and
    the trailing edge fixed while growing (dL = 2)."""
    p = AdaptiveWindow()
    res = davar(paper_signal(np.random.default_rng(SEED)), 1.0,
                adaptive=True)
    big_l, a, f = res.window_length, res.start, res.unstable
    assert p.l_min <= big_l.min() < p.l_max and big_l.max() == p.l_max
    expected = np.where(f[:-1], np.maximum(p.l_min, big_l[:-1] - 2),
                        np.minimum(p.l_max, big_l[:-1] + 2))
    np.testing.assert_array_equal(big_l[1:], expected)
    shrink = big_l[1:] < big_l[:-1]
    grow = big_l[1:] > big_l[:-1]
    assert shrink.any() and grow.any()
    np.testing.assert_array_equal((a + big_l)[1:][shrink],
                                  (a + big_l)[:-1][shrink])
    np.testing.assert_array_equal(a[1:][grow], a[:-1][grow])


@pytest.mark.parametrize("adaptive", [False, True])
def test_mirror_extension_full_edge_windows(adaptive):
    """With the mirror extension every window, edges included, has full
    length, is centred on a record sample from the first to the last, and
    gives finite numbers; the edge windows are the deviation of the mirrored
    samples."""
    y = paper_signal(np.random.default_rng(SEED))
    n = y.size
    res = (davar(y, 1.0, adaptive=True) if adaptive
           else davar(y, 1.0, window=600, step=1))
    np.testing.assert_array_equal(res.time_s, np.arange(n, dtype=float))
    assert res.window_length[0] == 600        # A-DAVAR starts at L_max
    if not adaptive:
        assert np.all(res.window_length == 600)
    for name in ("adev_rad_s", "arw_rad_rt_s", "arw_ci_low_rad_rt_s",
                 "arw_ci_high_rad_rt_s"):
        assert np.all(np.isfinite(getattr(res, name))), name
    if adaptive:
        assert np.all(np.isfinite(res.kurtosis))
        assert np.all(np.isfinite(res.contribution))
    first = np.concatenate([y[299::-1], y[:300]])
    np.testing.assert_array_equal(
        res.adev_rad_s[0], deviation(first, 1.0, "oadev", res.taus_s).dev)
    half = res.window_length[-1] // 2        # last window: centre n - 1
    last = np.concatenate([y[n - 1 - half:], y[:n - half:-1]])
    assert last.size == res.window_length[-1]
    np.testing.assert_array_equal(
        res.adev_rad_s[-1], deviation(last, 1.0, "oadev", res.taus_s).dev)


def test_extension_none_and_default_step():
    """extension="none": windows inside the record; default step of a fixed
    window is L/10, of A-DAVAR 1."""
    y = _white(SEED, 6000)
    res = davar(y, TAU0, window=600, extension="none")
    assert res.start[0] == 0 and res.start[-1] + 600 <= y.size
    np.testing.assert_array_equal(np.diff(res.start), 60)
    assert res.n_windows == (6000 - 600) // 60 + 1
    res = davar(y, TAU0, window=600)
    np.testing.assert_allclose(np.diff(res.time_s), 60 * TAU0, rtol=1e-12)
    res = davar(y, TAU0, adaptive=True, extension="none")
    assert res.start.min() >= 0
    assert (res.start + res.window_length).max() <= y.size
    np.testing.assert_allclose(np.diff(res.time_s), TAU0, rtol=1e-9)
    assert res.n_windows == 6000 - 600 + 1


# --------------------------------------------------------------------------
# Stationary white noise


@pytest.fixture(scope="module")
def stationary():
    y = _white(SEED, 6000)
    return y, davar(y, TAU0, window=600, step=1, confidence=WIDE)


def test_stationary_adev_within_single_window_ci(stationary):
    """Every window's deviation at every tau lies in the chi-square interval
    (level WIDE, Greenhall EDF of a 600-sample window, white FM) around the
    truth sigma sqrt(tau0/tau); the 68.27% intervals cover the truth in a
    fraction 0.684 +- 0.038 (sd over 100 seeds) of the window-tau cells:
    asserted within [0.55, 0.82] (3.5 sd)."""
    _, res = stationary
    truth = SIGMA * np.sqrt(TAU0 / res.taus_s)
    nu = edf("oadev", 601, res.m, 0)
    # the interval of an estimate around the truth: truth in [lo(est), hi(est)]
    est_low, est_high = confidence_interval(res.adev_rad_s, nu, WIDE)
    assert np.all((est_low <= truth) & (truth <= est_high))
    one_low, one_high = confidence_interval(res.adev_rad_s, nu)
    coverage = np.mean((one_low <= truth) & (truth <= one_high))
    assert 0.55 <= coverage <= 0.82, coverage


def test_stationary_arw_track_flat(stationary):
    """ARW track of stationary white noise: its mean over all windows and
    over each sixth of the record equals sigma sqrt(tau0) within Z_MAX sd
    (exact moments); every window's interval (level WIDE) holds the truth;
    the interval is the chi-square one of the tau0 point."""
    y, res = stationary
    truth = SIGMA * math.sqrt(TAU0)
    variance = np.full(y.size, SIGMA ** 2)
    mu, sd = _arw_mean_moments(res, variance, np.ones(res.n_windows, bool))
    assert mu == pytest.approx(truth, rel=5e-4)   # junction pairs: -1/600
    assert abs(_z(res, variance, np.ones(res.n_windows, bool))) < Z_MAX
    assert sd / truth < 0.012     # 1.1%: a 5% scale error is 4.5 sd away
    for part in np.array_split(np.arange(res.n_windows), 6):
        sel = np.zeros(res.n_windows, bool)
        sel[part] = True
        assert abs(_z(res, variance, sel)) < Z_MAX
    assert np.all((res.arw_ci_low_rad_rt_s <= truth)
                  & (truth <= res.arw_ci_high_rad_rt_s))
    low, high = confidence_interval(res.arw_rad_rt_s, edf("oadev", 601, 1, 0),
                                    WIDE)
    np.testing.assert_array_equal(res.arw_ci_low_rad_rt_s, low)
    np.testing.assert_array_equal(res.arw_ci_high_rad_rt_s, high)
    np.testing.assert_allclose(res.arw_rad_rt_s,
                               res.adev_rad_s[:, 0] * math.sqrt(TAU0),
                               rtol=1e-15)


def test_arw_fit_is_the_house_noise_fit():
    """arw="fit" is the IEEE Std 952 GLS fit of allan_analysis on the same
    window (identical), and each fitted N is within Z_MAX of its sigma of
    the truth."""
    y = _white(SEED, 20_000)
    res = davar(y, TAU0, window=5000, step=5000, extension="none", arw="fit")
    truth = SIGMA * math.sqrt(TAU0)
    assert res.n_windows == 4
    for a, length, n_fit, hi in zip(res.start, res.window_length,
                                    res.arw_rad_rt_s,
                                    res.arw_ci_high_rad_rt_s):
        ref = allan_analysis(y[a:a + length], TAU0, res.taus_s).fit
        assert n_fit == ref.n_rad_rt_s
        sigma = ref.n_rad_rt_s_sigma
        assert hi == pytest.approx(n_fit + sigma, rel=1e-3)  # 1 sigma band
        assert abs(n_fit - truth) < Z_MAX * sigma


# --------------------------------------------------------------------------
# The paper's experiment (Song et al. 2018, sec. 2.2 and 5, Table 1)


@pytest.fixture(scope="module")
def paper_runs():
    y = paper_signal(np.random.default_rng(SEED), sigma_rad_s=1.0)
    variance = np.ones(y.size)
    variance[3000:4000] = 3.0
    runs = {"DAVAR-400": davar(y, 1.0, window=400, step=1),
            "DAVAR-600": davar(y, 1.0, window=600, step=1),
            "A-DAVAR": davar(y, 1.0, adaptive=True)}
    return variance, runs


@pytest.mark.parametrize("method", ["DAVAR-400", "DAVAR-600", "A-DAVAR"])
def test_paper_arw_rises_by_sqrt3(paper_runs, method):
    """The ARW track follows the variance step: windows wholly inside
    3000-4000 s average sqrt(3) sigma sqrt(tau0), windows wholly before it
    sigma sqrt(tau0), the Table-1 intervals (centres in 0-2000 s and
    3000-4000 s) their exact mixtures; each within Z_MAX sd, and the ratio
    inside/before is sqrt(3) within Z_MAX combined relative sd (~3.5%)."""
    variance, runs = paper_runs
    res = runs[method]
    t, a = res.time_s, res.start
    e = a + res.window_length
    inside = (a >= 3000) & (e <= 4000)
    before = (a >= 0) & (e <= 3000)
    sels = {"inside": inside, "before": before,
            "centres 0-2000": t < 2000,
            "centres 3000-4000": (t >= 3000) & (t < 4000)}
    for name, sel in sels.items():
        assert sel.sum() >= 100, name
        assert abs(_z(res, variance, sel)) < Z_MAX, name
    mu_in, sd_in = _arw_mean_moments(res, variance, inside)
    mu_b, sd_b = _arw_mean_moments(res, variance, before)
    assert mu_in / mu_b == pytest.approx(math.sqrt(3.0), rel=1e-3)
    ratio = res.arw_rad_rt_s[inside].mean() / res.arw_rad_rt_s[before].mean()
    rel = math.hypot(sd_in / mu_in, sd_b / mu_b)
    assert ratio == pytest.approx(math.sqrt(3.0), rel=Z_MAX * rel)


def test_fixed_window_nodes_are_geometric(paper_runs):
    """DAVAR-L senses a change from c - L/2 to c + L/2: the paper's
    DAVAR-400 nodes exactly, and DAVAR-600's but for its 2702 (2700 here)."""
    _, runs = paper_runs
    for c, method in enumerate(("DAVAR-400", "DAVAR-600")):
        got = [change_nodes(runs[method], change)
               for change in (3000.0, 4000.0)]
        values = [got[0].beginning_s, got[0].end_s, got[1].beginning_s,
                  got[1].end_s]
        paper = [PAPER_TABLE1[k][c] for k in ("beginning_3000", "end_3000",
                                              "beginning_4000", "end_4000")]
        if method == "DAVAR-600":
            paper[0] = 2700.0
        assert values == paper


# Node bounds of A-DAVAR at the variance rise (3000 s).  Geometry: a window
# can sense the change only once its leading edge passes it (c - L_max/2 =
# 2700) and should before its centre does (c); it is back at L_max wholly
# after the change no earlier than c + L_max/2 = 3300 and, to be ready for
# the next change, before its leading edge reaches 4000 s (3700).
# Expectation: the kurtosis of a window holding a fraction p of variance-3
# samples is 3(1+8p)/(1+2p)^2, above K2 = 3.3 from p = 0.029 (17 samples:
# 2717 s).  For the drop (4000 s) it is 3(9-8q)/(3-2q)^2 with q the
# variance-1 fraction, above 3.3 from q = 0.21 (126 samples: 3826 s).
# 2000 seeds: the rise is missed in 1.0%, sensed at or after 3000 s in 0.2%,
# restored at or after 3700 s in 0.3% (median beginning 2732, end 3100,
# restore 3300; the paper's one realisation: 2703, 3156); the drop is sensed
# in 68% (median 3826).  The fixed-seed test therefore fails for ~1.5% of
# seeds, through the method's own missed detections.
def _assert_rise_nodes(res):
    nodes = change_nodes(res, 3000.0)
    assert 2700.0 <= nodes.beginning_s < 3000.0, nodes
    assert 3300.0 <= nodes.restore_s < 3700.0, nodes
    assert nodes.beginning_s <= nodes.end_s <= nodes.restore_s, nodes
    return nodes


def test_adaptive_nodes_fixed_seed(paper_runs):
    """A-DAVAR shrinks around the rise at 3000 s and recovers (bounds
    above), and the shortest window straddling the rise is shorter than the
    longest by at least half the range (2000 seeds: L_min in 96.8%, < 500
    in 98.6%)."""
    _, runs = paper_runs
    res = runs["A-DAVAR"]
    _assert_rise_nodes(res)
    straddle = (res.start < 3000) & (3000 < res.start + res.window_length)
    assert res.window_length[straddle].min() <= 500


@pytest.mark.slow
def test_adaptive_nodes_across_seeds():
    """20 seeds (SEED .. SEED+19), binomial/normal tails from 2000 seeds:
    the rise is sensed in >= 18 (P(< 18) = 1e-3); at most one beginning at
    or after 3000 s (P = 8e-4) and one restore at or after 3700 s
    (P = 2e-3); median beginning in [2700, 2800] (expected 2717 + detection
    delay; sd of the median 12 s) and median end in [3000, 3300] (ideal
    3200; sd 27 s); the drop is sensed in >= 7 (p = 0.68: P(< 7) = 2e-4)
    with median beginning 3826 +- 100 s (expected 3826, sd of the median
    ~30 s); in the stable 0-2000 s the windows are shortened 3.0% of the
    time on average (sd of a 20-seed mean 1.5%): asserted <= 10%."""
    begin, end, late_begin, late_restore, drops, quiet = [], [], 0, 0, [], []
    for seed in range(SEED, SEED + 20):
        y = paper_signal(np.random.default_rng(seed), sigma_rad_s=1.0)
        res = davar(y, 1.0, adaptive=True)
        rise = change_nodes(res, 3000.0)
        if math.isfinite(rise.beginning_s):
            begin.append(rise.beginning_s)
            end.append(rise.end_s)
            assert rise.beginning_s >= 2700.0 and rise.restore_s >= 3300.0
            late_begin += rise.beginning_s >= 3000.0
            late_restore += not rise.restore_s < 3700.0
        drop = change_nodes(res, 4000.0)
        if math.isfinite(drop.beginning_s):
            drops.append(drop.beginning_s)
        quiet.append(np.mean(res.window_length[res.time_s < 2000] < 600))
    assert len(begin) >= 18
    assert late_begin <= 1 and late_restore <= 1
    assert 2700.0 <= np.median(begin) <= 2800.0
    assert 3000.0 <= np.median(end) <= 3300.0
    assert len(drops) >= 7
    assert abs(np.median(drops) - 3826.0) <= 100.0
    assert np.mean(quiet) <= 0.10


def test_paper_table1_function():
    """paper_table1: the paper's cells, our cells per seed, geometric nodes
    of the fixed windows, the stationary ARW 1/60 deg/sqrt(h) = 16.67e-3
    (sigma = 1 deg/h at 1 s) within Z_MAX sd (2.0% each seed), JSON-ready
    and printable."""
    table = paper_table1(seeds=(SEED, SEED + 1))
    assert table.values.shape == (2, len(table.rows), 3)
    r = table.rows.index
    np.testing.assert_array_equal(table.paper[r("arw_3000_4000")],
                                  PAPER_TABLE1["arw_3000_4000"])
    np.testing.assert_array_equal(table.values[:, r("end_4000"), 0], 4200.0)
    np.testing.assert_array_equal(table.values[:, r("beginning_3000"), 1],
                                  2700.0)
    quiet = table.values[:, r("arw_0_2000"), :]
    assert np.all(np.abs(quiet / (1e3 / 60.0) - 1.0) < Z_MAX * 0.019)
    text = format_paper_table1(table)
    assert "Beginning (3000 s)" in text and "A-DAVAR" in text
    json.dumps(table.to_json_dict(), allow_nan=False)


# --------------------------------------------------------------------------
# Output, plot, edge cases


def test_json_dict_datasheet_units():
    y = paper_signal(np.random.default_rng(SEED))
    res = davar(y, 1.0, adaptive=True, step=50)
    d = json.loads(json.dumps(res.to_json_dict(), allow_nan=False))
    assert {"time_s", "window_length", "taus_s", "adev_deg_h",
            "arw_deg_rt_h"} <= set(d)
    assert len(d["adev_deg_h"]) == res.n_windows == 120
    assert len(d["adev_deg_h"][7]) == res.taus_s.size
    assert d["adev_deg_h"][7][2] == pytest.approx(
        res.adev_rad_s[7, 2] * 3600.0 * 180.0 / math.pi, rel=1e-14)
    assert d["arw_deg_rt_h"][7] == pytest.approx(
        res.arw_rad_rt_s[7] * 60.0 * 180.0 / math.pi, rel=1e-14)
    # 1 deg/h white noise at 1 s: ARW 1/60 deg/sqrt(h) (edf 400: 3.5% sd)
    assert np.median(d["arw_deg_rt_h"][:40]) == pytest.approx(1 / 60, rel=0.1)
    assert d["params"] == asdict(AdaptiveWindow())
    assert d["window_length"] == [int(v) for v in res.window_length]
    fixed = davar(y, 1.0, window=600).to_json_dict()
    assert fixed["params"] is None and fixed["kurtosis"] is None


def test_constant_record_is_unstable_not_nan():
    """Exactly constant data: kurtosis undefined (NaN) flags the window
    unstable, so it shrinks to L_min; deviations and ARW are 0, JSON has
    null (and is valid JSON)."""
    res = davar(np.zeros(2000), 1.0, adaptive=True)
    assert np.all(np.isnan(res.kurtosis)) and np.all(res.unstable)
    assert res.window_length[-1] == 400
    assert np.all(res.adev_rad_s == 0.0) and np.all(res.arw_rad_rt_s == 0.0)
    d = json.loads(json.dumps(res.to_json_dict(), allow_nan=False))
    assert d["kurtosis"][0] is None and d["contribution"][0] is None


@pytest.mark.parametrize("adaptive", [False, True, None])
def test_plot_writes_png(tmp_path, adaptive):
    y = paper_signal(np.random.default_rng(SEED))
    if adaptive is None:
        res = davar(y, 1.0)
    elif adaptive:
        res = davar(y, 1.0, adaptive=True, step=10)
    else:
        res = davar(y, 1.0, window=400)
    out = plot_davar(res, tmp_path / "davar.png")
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_numba_threads_restored():
    before = numba.get_num_threads()
    davar(_white(SEED, 3000), TAU0, window=300)
    assert numba.get_num_threads() == before


# --------------------------------------------------------------------------
# Bad input


def _nan_at_17():
    y = _white(SEED, 1000)
    y[17] = np.nan
    return y


BAD = [
    ("window longer than data", dict(window=1001), "longer than the record"),
    ("window zero", dict(window=0), "at least 1"),
    ("window float", dict(window=600.0), "whole number"),
    ("window too short", dict(window=2), "too short"),
    ("lmax longer than data",
     dict(adaptive=True, params=AdaptiveWindow(l_max=1200)),
     "longer than the record"),
    ("window with adaptive", dict(adaptive=True, window=500), "adaptive"),
    ("params without adaptive",
     dict(window=500, params=AdaptiveWindow(l_max=500, l_min=300)),
     "adaptive=True"),
    ("step zero", dict(window=500, step=0), "at least 1"),
    ("step without window", dict(step=10), "step needs a window"),
    ("unknown extension", dict(window=500, extension="zero"), "extension"),
    ("unknown arw", dict(window=500, arw="slope"), "ARW method"),
    ("arw tau0 without tau0", dict(window=500, taus=[0.02, 0.04]), "tau0"),
    ("taus too long", dict(window=500, taus=[0.01, 3.0]), "too long"),
    ("unknown kind", dict(window=500, kind="mdev"), "kind"),
    ("confidence", dict(window=500, confidence=1.0), "confidence"),
]


@pytest.mark.parametrize("case,kwargs,message", BAD, ids=[b[0] for b in BAD])
def test_bad_options_refused(case, kwargs, message):
    with pytest.raises(InputError, match=message):
        davar(_white(SEED, 1000), TAU0, **kwargs)


@pytest.mark.parametrize("data,tau0,message", [
    (_nan_at_17(), TAU0, "index 17"),
    (np.r_[np.ones(5), np.inf, np.ones(500)], TAU0, "index 5"),
    (np.ones((100, 2)), TAU0, "1-D"),
    (np.ones(100), 0.0, "positive"),
    (np.ones(100), float("nan"), "finite"),
])
def test_bad_data_refused(data, tau0, message):
    with pytest.raises(InputError, match=message):
        davar(data, tau0, window=50)


@pytest.mark.parametrize("kwargs,message", [
    (dict(l_max=400, l_min=600), "must not exceed l_max"),
    (dict(l_tail=398), "at least 4"),
    (dict(k1=3.4), "k1"),
    (dict(s1=0.1), "s1"),
    (dict(l_min=400.5), "whole number"),
    (dict(dl_grow=0), "at least 1"),
    (dict(k2=float("inf")), "finite"),
])
def test_bad_adaptive_params_refused(kwargs, message):
    with pytest.raises(InputError, match=message):
        AdaptiveWindow(**kwargs)


def test_bad_change_and_signal_arguments():
    res = davar(_white(SEED, 1000), TAU0, window=100)
    with pytest.raises(InputError, match="finite"):
        change_nodes(res, float("nan"))
    with pytest.raises(InputError, match="Generator"):
        paper_signal(np.random.default_rng(0).standard_normal)
