"""Estimators declare what the design needs (issue 43, item 2): design tags, and a plugin
estimator with a linear system designed like a built-in.

Outside truth, written here with plain numpy: the plugin's fitted linear system is a static
3×N weight matrix W (A = 0), so its rate error on white + random-walk gyro noise is
e_k = W (v_k + b_k), b_k = Σ_{i<=k} ε_i, and the window mean square per axis is
(W R Wᵀ)_aa + mean_k(k + 1) (W Q Wᵀ)_aa over the scored samples k0..n−1; its 3-axis RMS is
the design's worst case at the one ρ given (fixed weights, no filter: nothing else enters).
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from hostile import assert_contract, run_cli

from gyroarray.core.layout import Layout
from gyroarray.design.search_space import design_refusal, design_tags, fitted_weights
from gyroarray.estimators import unregister
from gyroarray.estimators.base import DesignTags, Estimator

PLUGIN = '''
import numpy as np
from gyroarray.estimators import Estimator
from gyroarray.estimators.base import LinearSystem


class DiagWLS(Estimator):
    """Least squares weighted by each gyro's own white variance, correlation ignored."""
    name = "diag_wls"
    description = "least squares weighted by the gyros' own white variances (no correlation)"
    _design_tags = {"rho_weighted": False}       # its weights do not use the correlation

    def __init__(self):
        pass

    def _fit(self, H, noise, dt_s):
        R = noise.R(dt_s)
        d = 1.0 / np.diag(R)
        self.weights_ = np.linalg.solve(H.T @ (d[:, None] * H), H.T * d)
        self.covariance_ = self.weights_ @ R @ self.weights_.T

    def _estimate(self, z):
        return np.ascontiguousarray(z @ self.weights_.T)

    def linear_system(self):
        self._check_fitted()
        m, eye = np.array(self.weights_), np.eye(3)
        return LinearSystem(A=np.zeros((3, 3)), K=m, C=eye, X0=np.zeros_like(m), lam=np.zeros(3),
                            S=eye, S_inv=eye)
'''

ARW, RRW, RHO, RATE, HORIZON, SETTLE = 0.1, 60.0, 0.3, 100.0, 60.0, 2.0


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    p = tmp_path_factory.mktemp("est_plugin") / "diag_wls.py"
    p.write_text(PLUGIN)
    spec = importlib.util.spec_from_file_location("diag_wls_test_copy", p)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    yield p, mod.DiagWLS
    unregister("diag_wls")


def _levels():
    dt = 1.0 / RATE
    s = math.radians(ARW) / 60.0 / math.sqrt(dt)                   # white σ per sample [rad/s]
    q = (math.radians(RRW) / 3600.0 / 60.0) ** 2 * dt               # walk increment variance [rad²/s²]
    return dt, s, q


def _corr(n, rho):
    return (1.0 - rho) * np.eye(n) + rho * np.ones((n, n))


def test_builtin_tags_and_refusals():
    # the tags say what the design search dispatched on by name before
    assert design_tags("kf_array") == DesignTags(linear_system=True, weights="gls", rho_weighted=True,
                                                 bandwidth_param="bandwidth_hz", channel_filter="kf",
                                                 bias_states="array", needs_rrw_for_bias_states=True)
    assert design_tags("kf_single").weights == "ols" and not design_tags("kf_single").rho_weighted
    assert design_tags("ols").bandwidth_optional and design_tags("naive").bandwidth_param is None
    assert design_refusal("gls") is None
    # the offline bound and the fault detector are no fixed linear filters: refused, with why
    assert "linear system" in design_refusal("bound")
    assert "linear system" in design_refusal("fdi")
    assert "unknown estimator" in design_refusal("no_such_estimator")


def test_plugin_tags_default_from_the_class(plugin):
    _, cls = plugin
    t = cls.design_tags()
    # linear_system is detected (the class overrides it); the class's own override is merged
    assert t.linear_system and t.weights is None and not t.rho_weighted and t.bandwidth_param is None

    class NoSystem(Estimator):                                       # not registered
        description = "x"
    assert not NoSystem.design_tags().linear_system and NoSystem.design_tags().rho_weighted


def test_fitted_weights_are_the_linear_systems_gain(plugin, designed):
    # ``designed`` ran the CLI, which loaded the plugin file and registered diag_wls
    dt, s, _ = _levels()
    rng = np.random.default_rng(5)
    H = rng.standard_normal((4, 6, 3))
    D = np.diag(s * np.array([1, 1, 3, 1, 1.5, 1.0]))
    R = D @ _corr(6, 0.2) @ D
    W = fitted_weights("diag_wls", H, R, dt)
    d = 1.0 / np.diag(R)
    for g in range(4):
        ref = np.linalg.solve(H[g].T @ (d[:, None] * H[g]), H[g].T * d)
        np.testing.assert_allclose(W[g], ref, rtol=1e-12, atol=0)      # the same closed form


def _design(path, *extra):
    o = run_cli(["design", "--recommend", "--plugin", path, "--estimators", "diag_wls,gls",
                 "--arw", ARW, "--rrw", RRW, "--rho", RHO, "--n", 6, "--objective", "rate",
                 "--rate-hz", RATE, "--horizon-s", HORIZON, "--json", *extra], timeout=300)
    assert_contract(o)
    assert o.code == 0, o.err
    return o.json


def _closed_form_ms(W, n_gyros):
    """Window mean square (3,) per axis [rad²/s²] of static weights W on white + walk noise."""
    dt, s, q = _levels()
    n, k0 = int(round(HORIZON * RATE)), int(round(SETTLE * RATE))
    C = _corr(n_gyros, RHO)
    kk = np.mean(np.arange(k0, n) + 1.0)
    return np.diag(W @ (s * s * C) @ W.T) + kk * np.diag(W @ (q * C) @ W.T)


@pytest.fixture(scope="module")
def designed(plugin):
    path, _ = plugin
    return _design(path)


def test_a_linear_plugin_takes_part_and_its_worst_case_is_its_weights(plugin, designed):
    _, cls = plugin
    ours = [d for d in designed["designs"] if d["estimator"] == "diag_wls"]
    assert ours, "the plugin estimator took no part in the design"
    dt, s, _ = _levels()
    for d in ours[:4]:
        H = np.asarray(d["axes"], float)
        e = cls().fit(Layout(H), _noise(6), dt)
        W = np.asarray(e.linear_system().K)
        ref = math.degrees(math.sqrt(np.sum(_closed_form_ms(W, 6))))
        # the predictor's window sums and ours are the same finite sums: 1e-9 relative
        assert d["worst_case"]["rms_3axis_deg_s"] == pytest.approx(ref, rel=1e-9)
    # the plugin ignores the correlation, GLS uses it: at ρ = 0.3 GLS is at least as good
    gls = [d for d in designed["designs"] if d["estimator"] == "gls"]
    assert gls[0]["worst_case"]["rms_3axis_deg_s"] <= ours[0]["worst_case"]["rms_3axis_deg_s"] * (1 + 1e-9)


def _noise(n):
    from gyroarray.estimators.noise import ArrayNoise
    dt, s, q = _levels()
    C = _corr(n, RHO)
    return ArrayNoise(arw_rad_rt_s=np.full(n, s * math.sqrt(dt)), rrw_rad_s_rt_s=np.full(n, math.sqrt(q / dt)),
                      corr_arw=C, corr_rrw=C)


@pytest.mark.slow   # ~10 s: 30 runs of 6000 samples through the plugin
def test_monte_carlo_confirms_the_plugin_prediction(plugin, designed):
    _, cls = plugin
    d = next(d for d in designed["designs"] if d["estimator"] == "diag_wls")
    dt, s, q = _levels()
    H = np.asarray(d["axes"], float)
    e = cls().fit(Layout(H), _noise(6), dt)
    n, k0, runs = int(round(HORIZON * RATE)), int(round(SETTLE * RATE)), 30
    L = np.linalg.cholesky(_corr(6, RHO))
    rng = np.random.default_rng(43)
    ms = []
    for _ in range(runs):
        v = rng.standard_normal((n, 6)) @ L.T * s
        b = np.cumsum(rng.standard_normal((n, 6)) @ L.T * math.sqrt(q), axis=0)
        err = e.estimate(v + b)                                      # truth 0: the estimate is the error
        ms.append(np.mean(np.sum(err[k0:] ** 2, axis=1)))
    ms = np.degrees(np.sqrt(np.asarray(ms))) ** 2                      # [deg²/s²]
    pred = d["worst_case"]["rms_3axis_deg_s"] ** 2
    # 95 % t interval of the mean of 30 runs' mean squares (each a positive quadratic form:
    # the mean is close to normal at 30 runs; t(29) = 2.045)
    half = 2.045 * ms.std(ddof=1) / math.sqrt(runs)
    assert abs(ms.mean() - pred) <= half, (ms.mean(), pred, half)
