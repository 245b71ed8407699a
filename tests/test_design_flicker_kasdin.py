"""Kasdin 1/f noise from switch-on in the design predictor (``design --flicker``, issue 43 item 3):
the exact moments (:func:`gyroarray.design.moments.kasdin_moments`) against a numpy Monte Carlo of
Kasdin's filter through the built estimator, and against exact impulse-response sums where the
sensor's Butterworth filter makes the modes complex.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import gammaln

from gyroarray.core import units
from gyroarray.core.layout import Layout
from gyroarray.design.budget import error_budget
from gyroarray.design.moments import FLICKER_WORDS, flicker_moments, kasdin_coefficients, kasdin_moments
from gyroarray.design.noise_sources import SensorBandwidth
from gyroarray.design.search_space import DesignSpace
from gyroarray.design.sensor_response import cascade
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.names import BIAS_INSTABILITY
from gyroarray.estimators import get_estimator

DT = 0.01
N_GYROS = 5


def _h(n: int) -> np.ndarray:
    """Kasdin's α = 1 coefficients from the Gamma function (not the package's recursion)."""
    j = np.arange(n, dtype=float)
    return np.exp(gammaln(j + 0.5) - gammaln(0.5) - gammaln(j + 1.0))


def _fitted(name: str, kw: dict):
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                        ModelEntry("rrw", None, {"k_deg_h_rt_h": 600.0}),
                        ModelEntry(BIAS_INSTABILITY, None, {"b_deg_h": 20.0})))
    lay = Layout.conical(1, N_GYROS, np.deg2rad(54.74))
    return get_estimator(name)(**kw).fit(lay, model, DT), model, lay.H


def test_kasdin_coefficients_are_the_gamma_ratio():
    """h_j = Γ(j + 1/2)/(Γ(1/2) j!): exp of a difference of log-Gammas near 40 loses ~1e-11
    relative, hence 1e-9."""
    np.testing.assert_allclose(kasdin_coefficients(5000), _h(5000), rtol=1e-9)


def test_kasdin_angle_against_monte_carlo():
    """The BI angle at the horizon (the budget's row, Kasdin) against 400 numpy Kasdin runs
    through the estimator's own ``estimate``: inside the Monte Carlo's 95 % interval of the
    mean square angle (mean ± 1.96 standard errors; 400 runs give about ±10 %, against the
    factor ≈ 2 that separates the flicker models, which the second assertion checks)."""
    est, model, H = _fitted("gls", {"lowpass_hz": 2.0})
    n, runs = 2000, 400
    b = units.deg_h_to_rad_s(20.0)
    row = error_budget(est.linear_system(), H, model, n_samples=n, dt_s=DT, settle_s=2.0,
                       flicker_model="kasdin").terms[BIAS_INSTABILITY]
    circ = error_budget(est.linear_system(), H, model, n_samples=n, dt_s=DT, settle_s=2.0,
                        flicker_model="circular").terms[BIAS_INSTABILITY]
    rng = np.random.default_rng(20260504)
    h = _h(n)
    m = 2 * n
    hf = np.fft.rfft(h, m)
    ang2 = np.empty(runs)
    for r in range(runs):
        w = rng.standard_normal((n, N_GYROS))
        x = b * np.fft.irfft(np.fft.rfft(w, m, axis=0) * hf[:, None], m, axis=0)[:n]   # b_k = B Σ h_j w_{k−j}
        e = est.estimate(x)                      # the true rate is zero: the estimate is the error
        ang2[r] = np.sum((DT * e.sum(axis=0)) ** 2)
    mean, se = ang2.mean(), ang2.std(ddof=1) / np.sqrt(runs)
    pred2 = units.deg_to_rad(row["angle_deg"]) ** 2
    assert mean - 1.96 * se <= pred2 <= mean + 1.96 * se
    # the circular model's angle lies far outside that interval (below it)
    assert units.deg_to_rad(circ["angle_deg"]) ** 2 < mean - 1.96 * se


@pytest.mark.parametrize("order", [1, 2])
def test_kasdin_moments_exact_with_sensor_filter(order):
    """With the gyros' own low-pass cascaded (order 2: a complex pole pair), the moments equal
    exact sums over the impulse-response matrix (1e-9 relative: rounding only)."""
    est, _, _ = _fitted("kf_array", {"bandwidth_hz": 3.0})
    sensor = SensorBandwidth(cutoff_hz=np.full(N_GYROS, 8.0), order=np.full(N_GYROS, order), dt_s=DT)
    sys = cascade(est.linear_system(), sensor)
    n, k0 = 160, 30
    bi = np.linspace(1e-5, 3e-5, N_GYROS)
    A, K, C, X0 = (np.asarray(v) for v in (sys.A, sys.K, sys.C, sys.X0))
    h = _h(n)
    Z = np.zeros((n, N_GYROS, n, N_GYROS))
    for i in range(n):
        for j in range(N_GYROS):
            Z[i:, j, i, j] = h[:n - i]
    Z = Z.reshape(n, N_GYROS, -1)
    x = X0 @ Z[0]
    F = np.empty((n, 3, n * N_GYROS), dtype=np.result_type(A, K, C, float))
    for k in range(n):
        x = A @ x + K @ Z[k]
        F[k] = C @ x
    F = np.real(F).reshape(n, 3, n, N_GYROS) * bi                    # innovations of std B
    ms = np.einsum("kaij,kbij->ab", F[k0:], F[k0:]) / (n - k0)
    sw, sf = F[k0:].sum(axis=0), F.sum(axis=0)
    m = kasdin_moments(sys, bi, n, k0, DT)
    np.testing.assert_allclose(m.ms_window, ms, rtol=1e-9, atol=1e-9 * np.max(np.abs(ms)))
    np.testing.assert_allclose(m.sum_window, np.einsum("aij,bij->ab", sw, sw), rtol=1e-9,
                               atol=1e-9 * np.max(np.abs(sw)) ** 2)
    np.testing.assert_allclose(m.sum_full, np.einsum("aij,bij->ab", sf, sf), rtol=1e-9,
                               atol=1e-9 * np.max(np.abs(sf)) ** 2)


def test_flicker_model_dispatch_and_statement():
    """flicker_moments dispatches by name (an unknown one is refused); the design space defaults
    to Kasdin, and each statement names its model and what the other gives."""
    from gyroarray.core.errors import InputError
    est, _, _ = _fitted("gls", {"lowpass_hz": 2.0})
    sys = est.linear_system()
    bi = np.full(N_GYROS, 1e-5)
    a = flicker_moments(sys, bi, 300, 50, DT, model="kasdin")
    b = kasdin_moments(sys, bi, 300, 50, DT)
    np.testing.assert_array_equal(a.sum_full, b.sum_full)
    with pytest.raises(InputError, match="flicker model"):
        flicker_moments(sys, bi, 300, 50, DT, model="pink")
    assert DesignSpace().flicker_model == "kasdin"
    assert "circular" in FLICKER_WORDS["kasdin"] and "Kasdin" in FLICKER_WORDS["circular"]
    with pytest.raises(InputError):
        DesignSpace(flicker_model="pink")
