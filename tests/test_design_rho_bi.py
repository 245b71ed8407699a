"""The gyros' bias instability (flicker) correlated between gyros in the design predictor
(``design --rho-bi``, issue 43 item 3): the error budget's BI row and the ranking's channels
against numpy computations with the correlated covariance B Bᵀ ∘ C.

The outside check builds the estimator's full impulse-response matrix with its own loop
(x̂_k = A x̂_{k−1} + K z_k from x̂_{−1} = X0 z_0, ω̂_k = C x̂_k) and Kasdin's 1/f filter
h_j = Γ(j + 1/2)/(Γ(1/2) j!) (here from scipy.special.gammaln, not the recursion the package
uses), so the second moments are exact sums: they must agree to rounding (1e-9 relative, well
inside the brief's 1e-6).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import gammaln

from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.design.budget import error_budget
from gyroarray.design.channels import fixed_channels
from gyroarray.design.gyro_noise import GyroNoise, predictor_noise
from gyroarray.design.screening import Decider
from gyroarray.design.search_space import DesignSpace
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.names import BIAS_INSTABILITY
from gyroarray.estimators import get_estimator

DT = 0.01
N_GYROS = 5
B_DEG_H = (8.0, 12.0, 10.0, 6.0, 15.0)         # a per-gyro bias instability [deg/h]


def _model(rho: float) -> NoiseModel:
    entries = [ModelEntry("arw", None, {"n_deg_rt_h": 0.1}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 600.0})]
    entries += [ModelEntry(BIAS_INSTABILITY, k + 1, {"b_deg_h": b}) for k, b in enumerate(B_DEG_H)]
    entries.append(ModelEntry("correlation", None, {"rho_arw": rho, "rho_rrw": rho}))
    return NoiseModel(tuple(entries))


def _system(name: str, kw: dict, rho: float):
    lay = Layout.conical(1, N_GYROS, np.deg2rad(54.74))
    est = get_estimator(name)(**kw).fit(lay, _model(rho), DT)
    return est.linear_system(), lay.H


def _impulse(sys, n: int) -> np.ndarray:
    """F (n, 3, n, N): ω̂_k's response to a unit Kasdin innovation of gyro j at sample i, from
    the estimator's own recursion run on every (i, j) input at once."""
    h = np.exp(gammaln(np.arange(n) + 0.5) - gammaln(0.5) - gammaln(np.arange(n) + 1.0))
    A, K, C, X0 = (np.real_if_close(np.asarray(m)) for m in (sys.A, sys.K, sys.C, sys.X0))
    N = K.shape[1]
    Z = np.zeros((n, N, n, N))                    # reading k of gyro m for the innovation (i, j)
    for i in range(n):
        for j in range(N):
            Z[i:, j, i, j] = h[:n - i]
    Z = Z.reshape(n, N, n * N)
    x = X0 @ Z[0]                                 # x̂_{-1} = X0 z_0, every input a column
    F = np.empty((n, 3, n * N))
    for k in range(n):
        x = A @ x + K @ Z[k]
        F[k] = C @ x
    return F.reshape(n, 3, n, N)


def _numpy_row(sys, cov: np.ndarray, n: int, k0: int) -> dict:
    """{rms_deg_s, angle_deg} of the flicker with innovation covariance ``cov`` (N, N) [rad²/s²]."""
    L = np.linalg.cholesky(cov)
    F = np.einsum("kaij,jl->kail", _impulse(sys, n), L)
    ms = np.einsum("kail,kail->", F[k0:], F[k0:]) / (n - k0)
    s = F.sum(axis=0)
    return {"rms_deg_s": float(units.rad_s_to_deg_s(np.sqrt(ms))),
            "angle_deg": float(units.rad_to_deg(DT * np.sqrt(np.einsum("ail,ail->", s, s))))}


@pytest.mark.parametrize("name,kw", [("gls", {"lowpass_hz": 2.0}), ("kf_array", {"bandwidth_hz": 2.0})])
@pytest.mark.parametrize("rho_bi", [0.0, 0.6, -0.2])
def test_budget_bi_row_matches_numpy_correlated(name, kw, rho_bi):
    """The budget's BI row with the flicker correlated by ρ_bi equals the exact numpy sums."""
    n, settle = 240, 0.5
    k0 = int(round(settle / DT))
    sys, H = _system(name, kw, 0.3)
    corr = (1.0 - rho_bi) * np.eye(N_GYROS) + rho_bi
    b = units.deg_h_to_rad_s(np.asarray(B_DEG_H))
    b_row = error_budget(sys, H, _model(0.3), n_samples=n, dt_s=DT, settle_s=settle,
                         bi_correlation=corr, flicker_model="kasdin").terms[BIAS_INSTABILITY]
    ref = _numpy_row(sys, np.outer(b, b) * corr, n, k0)
    for key in ("rms_deg_s", "angle_deg"):
        assert b_row[key] == pytest.approx(ref[key], rel=1e-9)


def test_budget_bi_row_moves_with_rho_bi():
    """On an un-reversed array the common mode reaches the fused rate: ρ_bi = 0.6 raises the BI
    angle above the independent one (the ratio is the numpy one, not just larger)."""
    n, settle = 240, 0.5
    sys, H = _system("gls", {"lowpass_hz": 2.0}, 0.0)
    rows = {r: error_budget(sys, H, _model(0.0), n_samples=n, dt_s=DT, settle_s=settle,
                            bi_correlation=(1 - r) * np.eye(N_GYROS) + r,
                            flicker_model="kasdin").terms[BIAS_INSTABILITY]["angle_deg"]
            for r in (0.0, 0.6)}
    b = units.deg_h_to_rad_s(np.asarray(B_DEG_H))
    refs = {r: _numpy_row(sys, np.outer(b, b) * ((1 - r) * np.eye(N_GYROS) + r), n, int(settle / DT))
            ["angle_deg"] for r in (0.0, 0.6)}
    assert rows[0.6] / rows[0.0] == pytest.approx(refs[0.6] / refs[0.0], rel=1e-9)
    assert rows[0.6] > 1.1 * rows[0.0]


def test_correlation_default_follows_arw_rho():
    """ρ_bi None follows the ARW ρ at every condition (with_rho); a given ρ_bi stays; the axis
    frame multiplies it by s sᵀ like the ARW correlation."""
    g = GyroNoise(arw_deg_rt_h=0.1, bi_deg_h=10.0)
    for r in (-0.1, 0.3):
        c = g.with_rho(r).correlation(4, BIAS_INSTABILITY)
        np.testing.assert_array_equal(c, (1 - r) * np.eye(4) + r)
    g2 = GyroNoise(arw_deg_rt_h=0.1, bi_deg_h=10.0, rho_bi=0.2).with_rho(0.5)
    assert g2.rho_bi_value == 0.2
    np.testing.assert_allclose(g2.correlation(4, BIAS_INSTABILITY), 0.8 * np.eye(4) + 0.2, rtol=0, atol=1e-15)
    s = np.array([1.0, -1.0, 1.0, -1.0])
    ca = g2.in_frame("axis").correlation(4, BIAS_INSTABILITY, signs=s)
    np.testing.assert_allclose(ca, (0.8 * np.eye(4) + 0.2) * np.outer(s, s), rtol=0, atol=1e-15)
    with pytest.raises(InputError, match="rho_bi"):
        GyroNoise(arw_deg_rt_h=0.1, rho_bi=1.0)


def test_ranking_channels_see_rho_bi():
    """The ranking's fixed channels: flicker level per axis = M (B² C_bi) Mᵀ (numpy), so ρ_bi
    enters the screening, for alike and for per-gyro noise."""
    from gyroarray.core.layout import conical_axes
    H = conical_axes(1, 6, np.deg2rad(np.array([54.74, 40.0])))          # (2, 6, 3)
    b = units.deg_h_to_rad_s(10.0)
    for rb in (0.0, 0.5):
        g = GyroNoise(arw_deg_rt_h=0.1, bi_deg_h=10.0, rho_arw=0.2, rho_rrw=0.2, rho_bi=rb)
        ch = fixed_channels("ols", H, g, g, DT)
        M = np.linalg.solve(np.einsum("gni,gnj->gij", H, H), np.swapaxes(H, 1, 2))
        cb = b ** 2 * ((1 - rb) * np.eye(6) + rb)
        np.testing.assert_allclose(ch.flicker, np.einsum("gai,ij,gaj->ga", M, cb, M), rtol=1e-12)


def test_exact_scoring_noise_carries_rho_bi():
    """The exact re-scoring's noise (predictor_noise): the flicker correlation of the condition
    and the space's flicker model."""
    g = GyroNoise(arw_deg_rt_h=0.1, bi_deg_h=10.0, rho_bi=0.4)
    space = DesignSpace(ns=(4,), horizon_s=5.0)
    dec = Decider(g, space, -0.1, 0.5, "rate")
    gt = dec.cond(0.5)
    ns = predictor_noise(gt, gt.noise_model(4), 4, None, None, DT, space.flicker_model)
    np.testing.assert_allclose(ns.bi_corr, 0.6 * np.eye(4) + 0.4, rtol=0, atol=1e-15)
    assert ns.flicker_model == space.flicker_model == "kasdin"


def test_cli_rho_bi_refused_outside_range(capsys):
    """--rho-bi outside (-1, 1) is refused in one line (exit 2), and outside --recommend too."""
    from gyroarray.cli.main import main
    code = main(["design", "--recommend", "--arw", "0.1", "--bi", "10", "--n", "4", "--rho-bi", "1.5"])
    _, err = capsys.readouterr()
    assert code == 2 and "rho_bi" in err and "Traceback" not in err
    code = main(["design", "--scheme", "1", "--n", "4", "--rho-bi", "0.2"])
    _, err = capsys.readouterr()
    assert code == 2 and "--rho-bi" in err and "Traceback" not in err
