"""The error budget's undetected fault (issue 43 item 3): a bias step at the MDB on the MDB's
worst gyro, present from t = 0 and never isolated, through the intact array's estimator to the
horizon. Outside check: the step pushed through the estimator's state-space recursion in numpy
(x̂_k = A x̂_{k−1} + K z_k from x̂_{−1} = X0 z_0, ω̂_k = C x̂_k), the sensor's filter applied by
scipy's sosfilt: a deterministic signal, so the row must agree to rounding (1e-9 relative).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from gyroarray.core import units
from gyroarray.core.layout import Layout
from gyroarray.core.sensor import bandwidth_sos
from gyroarray.design.budget import undetected_fault
from gyroarray.design.noise_sources import SensorBandwidth
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.estimators import get_estimator

DT = 0.01


def _numpy_step(sys, H: np.ndarray, gyro: int, step: float, n: int, k0: int,
                sensor_sos=None) -> tuple[float, float]:
    """(3-axis RMS over the window [deg/s], 3-axis angle at the horizon [deg]) of the step."""
    z = np.zeros((n, H.shape[0]))
    z[:, gyro - 1] = step
    if sensor_sos is not None:                   # started at the first sample's steady state
        zi = signal.sosfilt_zi(sensor_sos) * step
        z[:, gyro - 1], _ = signal.sosfilt(sensor_sos, z[:, gyro - 1], zi=zi)
    A, K, C, X0 = (np.real(np.asarray(m)) for m in (sys.A, sys.K, sys.C, sys.X0))
    x = X0 @ z[0]
    e = np.empty((n, 3))
    for k in range(n):
        x = A @ x + K @ z[k]
        e[k] = C @ x
    rms = np.sqrt(np.mean(np.sum(e[k0:] ** 2, axis=1)))
    ang = DT * np.linalg.norm(e.sum(axis=0))
    return float(units.rad_s_to_deg_s(rms)), float(units.rad_to_deg(ang))


def _fit(name: str, kw: dict, n_gyros: int = 6):
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                        ModelEntry("rrw", None, {"k_deg_h_rt_h": 600.0}),
                        ModelEntry("correlation", None, {"rho_arw": 0.2, "rho_rrw": 0.2})))
    lay = Layout.conical(2, n_gyros, np.deg2rad(60.0))
    return get_estimator(name)(**kw).fit(lay, model, DT), lay.H


@pytest.mark.parametrize("name,kw", [("gls", {"lowpass_hz": 2.0}), ("kf_array", {"bandwidth_hz": 3.0}),
                                     ("ols", {})])
@pytest.mark.parametrize("order", [0, 2])
def test_undetected_fault_row_against_numpy(name, kw, order):
    est, H = _fit(name, kw)
    n, settle, gyro, step = 1500, 2.0, 4, units.deg_s_to_rad_s(0.04)
    sensor = None if order == 0 else SensorBandwidth(cutoff_hz=np.full(6, 8.0), order=np.full(6, order), dt_s=DT)
    row = undetected_fault(est.linear_system(), 6, gyro, step, n_samples=n, dt_s=DT, settle_s=settle,
                           sensor=sensor)
    sos = None if order == 0 else bandwidth_sos(8.0, order, DT)
    rms, ang = _numpy_step(est.linear_system(), H, gyro, step, n, int(round(settle / DT)), sos)
    assert row["rms_deg_s"] == pytest.approx(rms, rel=1e-9)
    assert row["angle_deg"] == pytest.approx(ang, rel=1e-9)
    assert row["gyro"] == gyro and row["step_deg_s"] == pytest.approx(0.04, rel=1e-12)
    # a bias the estimator passes: the angle grows about linearly with the horizon
    assert ang > 0.5 * 0.04 * n * DT * np.min(np.linalg.norm(np.linalg.pinv(H)[:, gyro - 1:gyro], axis=0))


def test_undetected_fault_refuses_a_gyro_outside_the_array():
    est, _ = _fit("ols", {})
    with pytest.raises(ValueError, match="gyro 7"):
        undetected_fault(est.linear_system(), 6, 7, 1e-3, n_samples=100, dt_s=DT)


def test_recommendation_budget_carries_undetected_fault():
    """A decided design (failures 1): the budget's ``undetected_fault`` equals the numpy
    propagation of a step of the MDB on the MDB's worst gyro through the recommendation's
    estimator, rebuilt from its fields (axes, estimator, bandwidth, design ρ) on every gyro."""
    from gyroarray.design.gyro_noise import GyroNoise
    from gyroarray.design.recommend import recommend
    from gyroarray.design.search_space import DesignSpace
    g = GyroNoise(arw_deg_rt_h=0.1, rrw_deg_h_rt_h=600.0, bi_deg_h=10.0)
    space = DesignSpace(ns=(5,), horizon_s=20.0, failures=1, estimators=("gls",))
    r = recommend(g, space, rhos=[-0.1, 0.5])["recommended"]
    uf = r["error_budget"]["undetected_fault"]
    assert uf["gyro"] == r["mdb_worst_gyro"] and uf["step_deg_s"] == pytest.approx(r["mdb_deg_s"], rel=1e-12)
    assert f"gyro {uf['gyro']}" in uf["statement"] and f"{uf['step_deg_s']:.4g} deg/s" in uf["statement"]
    H = np.asarray(r["axes"], dtype=float)
    rd = r["design_rho"]
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                        ModelEntry("rrw", None, {"k_deg_h_rt_h": 600.0}),
                        ModelEntry("bias_instability", None, {"b_deg_h": 10.0}),
                        ModelEntry("correlation", None, {"rho_arw": rd, "rho_rrw": rd})))
    assert "bias_instability" in r["error_budget"]["terms"]
    est = get_estimator("gls")(lowpass_hz=r["bandwidth_hz"]).fit(Layout.from_axes(H), model, space.dt_s)
    rms, ang = _numpy_step(est.linear_system(), H, uf["gyro"], units.deg_s_to_rad_s(r["mdb_deg_s"]),
                           space.n_samples, int(round(space.settle_s / space.dt_s)))
    assert uf["rms_deg_s"] == pytest.approx(rms, rel=1e-9)
    assert uf["angle_deg"] == pytest.approx(ang, rel=1e-9)
