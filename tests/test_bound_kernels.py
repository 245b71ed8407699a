"""The numba KF + RTS kernels of ``bound`` against the former numpy loop.

``bound._smooth_reference`` is the original implementation (``kf_step`` and
one D×D solve per sample, stored gains C_k = P_k (P_k + Q)⁻¹). The kernels
run the same recursion (Joseph update, RTS with the gain applied as
I − Q P_{k+1|k}⁻¹ through a stored Cholesky factor), so the two agree up to
floating-point reassociation.

Tolerance, 1e-9 of the rate scale (max |ω| of the truth): the kernels sum
in a different order than numpy/LAPACK (and use Cholesky instead of LU
solves), so each step differs by a few ulp of the covariance and of the
state. The filter is stable on the observable subspace and neutral
(random walk) on the unobservable one, so these differences do not grow
faster than linearly over the n steps; they are amplified by the condition
numbers of S and P_{k+1|k} (up to ~1e6–1e7 here: the diffuse rate prior at
the start, and a gyro with 100× less RRW than the others). Worst case
≲ n · cond · eps ≈ 3e3 · 1e7 · 1e-16 ≈ 3e-6; observed 4e-14 .. 6e-11 (largest
in the first samples after the diffuse prior, then decaying to ~1e-12).
1e-9 sits well above the observed level and far below any difference of
the algorithm (a wrong sign, gain or time index shows at 1e-3 or more; the
smoother moves the states by ≥ 2e-3 of the rate scale here).
"""

from __future__ import annotations

import numpy as np
import pytest

from gyroarray.core import units
from gyroarray.core.gdop import optimal_alpha
from gyroarray.core.errors import InputError
from gyroarray.estimators import OfflineBound
from gyroarray.estimators.bound import smooth_reference
from gyroarray.core.layout import Layout
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import ModelEntry, NoiseModel

DT = 0.01
TOL = 1e-9                                           # relative to the rate scale, see above
N_SAMPLES = 2500

EQUAL = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                    ModelEntry("rrw", None, {"k_deg_h_rt_h": 600.0})))
# per-gyro different ARW and RRW (one gyro with 100x less RRW), correlated
UNEQUAL = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                      ModelEntry("arw", 2, {"n_deg_rt_h": 0.3}),
                      ModelEntry("arw", 3, {"n_deg_rt_h": 0.05}),
                      ModelEntry("rrw", None, {"k_deg_h_rt_h": 600.0}),
                      ModelEntry("rrw", 1, {"k_deg_h_rt_h": 6.0}),
                      ModelEntry("rrw", 3, {"k_deg_h_rt_h": 2000.0}),
                      ModelEntry("correlation", None, {"rho_arw": 0.2, "rho_rrw": -0.1})))
NO_RRW = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),))


def _layout(n_gyros: int) -> Layout:
    if n_gyros == 3:
        return Layout.triad()
    scheme = 2 if n_gyros == 4 else 1
    return Layout.conical(scheme, n_gyros, optimal_alpha(scheme, n_gyros).alpha_rad)


def _record(layout, model, n, seed):
    """A swing about a tilted axis plus the model's noise; truth (n, 3) and readings (n, N)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    w = np.outer(units.deg_s_to_rad_s(5.0) * np.sin(2 * np.pi * 0.3 * t), [0.3, -0.5, 0.8])
    w[:, 0] += units.deg_s_to_rad_s(1.0)
    z = simulate_readings(model, w, layout, DT, rng)
    return w, z


def _reference(est: OfflineBound, z):
    x0, P0 = est._prior(z[0])
    return smooth_reference(est._model, x0, P0, z)


CASES = [  # (N, model, hyperparameters, seed)
    (3, EQUAL, {}, 11),
    (3, UNEQUAL, {}, 12),
    (4, EQUAL, {}, 13),
    (4, UNEQUAL, {"bandwidth_hz": 2.0}, 14),
    (6, EQUAL, {}, 15),
    (6, UNEQUAL, {"q_omega": 1e-3}, 16),
    (8, EQUAL, {}, 17),
    (8, UNEQUAL, {}, 18),
]


@pytest.mark.parametrize("n_gyros, model, params, seed", CASES,
                         ids=[f"N{c[0]}-{'equal' if c[1] is EQUAL else 'unequal'}-{c[3]}"
                              for c in CASES])
def test_kernels_match_the_numpy_reference(n_gyros, model, params, seed):
    layout = _layout(n_gyros)
    est = OfflineBound(**params).fit(layout, model, DT)
    w, z = _record(layout, model, N_SAMPLES, seed)
    scale = np.max(np.abs(w))
    xs_ref, xsm_ref = _reference(est, z)
    xs, xsm = est.smooth(z)
    dev_filter = np.max(np.abs(xs - xs_ref)) / scale
    dev_smooth = np.max(np.abs(xsm - xsm_ref)) / scale
    assert dev_filter <= TOL, dev_filter
    assert dev_smooth <= TOL, dev_smooth
    # the comparison is not vacuous: the smoother moved the states well above TOL
    assert np.max(np.abs(xsm_ref - xs_ref)) / scale > 1e3 * TOL


def test_long_record_along_the_unobservable_directions():
    """20 000 samples (P_uu grows all along): no drift from the reference."""
    layout = _layout(4)
    est = OfflineBound().fit(layout, UNEQUAL, DT)
    w, z = _record(layout, UNEQUAL, 20_000, 21)
    xs_ref, xsm_ref = _reference(est, z)
    xs, xsm = est.smooth(z)
    scale = np.max(np.abs(w))
    assert np.max(np.abs(xs - xs_ref)) / scale <= TOL
    assert np.max(np.abs(xsm - xsm_ref)) / scale <= TOL


@pytest.mark.parametrize("n", [1, 2, 3])
def test_shortest_records(n):
    layout = _layout(6)
    est = OfflineBound().fit(layout, EQUAL, DT)
    w, z = _record(layout, EQUAL, 3, 5)                               # the simulator needs n >= 2
    w, z = w[:n], z[:n]
    xs_ref, xsm_ref = _reference(est, z)
    xs, xsm = est.smooth(z)
    scale = np.max(np.abs(w))
    np.testing.assert_allclose(xs, xs_ref, rtol=0, atol=TOL * scale)
    np.testing.assert_allclose(xsm, xsm_ref, rtol=0, atol=TOL * scale)
    np.testing.assert_array_equal(xsm[-1], xs[-1])


def test_deterministic_and_estimate_is_the_smoothed_rate():
    layout = _layout(8)
    est = OfflineBound().fit(layout, UNEQUAL, DT)
    _, z = _record(layout, UNEQUAL, 3000, 7)
    xs1, xsm1 = est.smooth(z)
    xs2, xsm2 = est.smooth(z.copy())
    np.testing.assert_array_equal(xs1, xs2)
    np.testing.assert_array_equal(xsm1, xsm2)
    # estimate() smooths in place (one (n, D) array): the same bits
    np.testing.assert_array_equal(est.estimate(z), xsm1[:, :3])


def test_no_rate_random_walk_is_refused():
    """Q_b = 0: P_{k+1|k} is singular and the RTS gain does not exist.

    The numpy reference fails there with LinAlgError; the kernels name the cause.
    """
    layout = _layout(6)
    est = OfflineBound(q_omega=1e-3).fit(layout, NO_RRW, DT)
    _, z = _record(layout, NO_RRW, 50, 3)
    with pytest.raises(np.linalg.LinAlgError):
        _reference(est, z)
    with pytest.raises(InputError, match="rate random walk"):
        est.estimate(z)
