"""Parity-space self-calibration (issue 31, item 4): scale factor and axis errors of each gyro of a
moving array from its parity alone, against a numpy-written moving array with known errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gyroarray.chain.parity import Z_OFF, saturated_mask, self_calibrate, tilt_axes
from gyroarray.cli.main import main

from hostile import assert_contract, run_cli, write_measurement

DT = 0.01


def _axes8() -> np.ndarray:
    """8 skewed unit axes (two tilted cones of 4), rank 3."""
    rows = []
    for k in range(8):
        a = 2 * np.pi * k / 4 + (np.pi / 4 if k >= 4 else 0.0)
        el = np.radians(35.0 if k < 4 else -50.0)
        rows.append([np.cos(el) * np.cos(a), np.cos(el) * np.sin(a), np.sin(el)])
    return np.array(rows)


def _tilt_basis(H):
    """The two unit vectors ⟂ h_i the test's errors are written in (independent of the library):
    Gram–Schmidt of the two body axes other than the one h_i is closest to."""
    U, W = np.empty_like(H), np.empty_like(H)
    for i, h in enumerate(H):
        k = int(np.argmax(np.abs(h)))
        a, b = [j for j in range(3) if j != k]
        u = np.eye(3)[a] - h[a] * h
        u /= np.linalg.norm(u)
        w = np.eye(3)[b] - h[b] * h - (np.eye(3)[b] @ u) * u
        U[i], W[i] = u, w / np.linalg.norm(w)
    return U, W


def _gauge_free(theta, H, U, W):
    """θ = (s, a, c) per gyro minus its projection on the errors E = H A no parity sees."""
    cols = []
    for r in range(3):
        for c in range(3):
            A = np.zeros((3, 3))
            A[r, c] = 1.0
            E = H @ A
            cols.append(np.c_[np.sum(E * H, 1), np.sum(E * U, 1), np.sum(E * W, 1)].ravel())
    G = np.linalg.qr(np.array(cols).T)[0]
    return theta - G @ (G.T @ theta)


def _moving(rng, H, s, tilt, n=6000, sigma=None):
    """Readings y = (H + E) ω + bias + white noise of a body turning about all three axes."""
    t = np.arange(n) * DT
    om = np.stack([3.0 * np.sin(2 * np.pi * 0.31 * t), 2.5 * np.sin(2 * np.pi * 0.17 * t + 1.0),
                   3.5 * np.sin(2 * np.pi * 0.23 * t + 2.0)], axis=1)
    U, W = _tilt_basis(H)
    E = s[:, None] * H + tilt[:, :1] * U + tilt[:, 1:] * W
    sigma = np.full(H.shape[0], 0.01) if sigma is None else sigma
    bias = rng.normal(0.0, 0.01, H.shape[0])
    return om @ (H + E).T + bias + sigma * rng.normal(size=(n, H.shape[0])), sigma


def _z(cal, H, s, tilt):
    U, W = _tilt_basis(H)
    truth = _gauge_free(np.c_[s, tilt].ravel(), H, U, W)
    est = np.c_[cal.scale_ppm * 1e-6, cal.tilt_mrad * 1e-3].ravel()
    sig = np.c_[cal.scale_sigma_ppm * 1e-6, cal.tilt_sigma_mrad * 1e-3].ravel()
    return (est - truth) / sig


def test_tilt_axes_are_the_tests_basis():
    H = _axes8()
    U, W, names = tilt_axes(H)
    U2, W2 = _tilt_basis(H)
    assert np.allclose(U, U2) and np.allclose(W, W2)
    assert np.allclose(np.sum(U * H, 1), 0) and np.allclose(np.sum(W * H, 1), 0)
    assert np.allclose(np.sum(U * W, 1), 0) and len(names) == 8


def test_known_scale_factor_and_misalignment_within_2_sigma_after_the_gauge():
    rng = np.random.default_rng(31)
    H = _axes8()
    s = rng.normal(0.0, 0.01, 8)                       # 1 % scale factors
    tilt = rng.normal(0.0, 0.005, (8, 2))              # 5 mrad tilts
    y, sig = _moving(rng, H, s, tilt)
    cal = self_calibrate(y, H, DT, R=np.diag(sig ** 2), gauge="mean")
    z = _z(cal, H, s, tilt)
    assert np.all(np.isfinite(z))
    assert np.mean(np.abs(z) < 2.0) >= 0.9 and np.max(np.abs(z)) < 3.5, np.round(z, 2)
    # the gauge: Hᵀ E = 0 (errors relative to the array's mean)
    assert np.allclose(H.T @ cal.E, 0.0, atol=1e-9)
    assert cal.significant and cal.explained > 0.5
    # and the errors are far from the noise: the estimate is not 0 by accident
    assert np.max(np.abs(cal.scale_ppm)) > 20 * np.max(cal.scale_sigma_ppm)


def test_sigma_is_calibrated_over_repeated_draws():
    rng = np.random.default_rng(7)
    H = _axes8()
    s = rng.normal(0.0, 0.01, 8)
    tilt = rng.normal(0.0, 0.005, (8, 2))
    zs = []
    for _ in range(12):
        y, sig = _moving(rng, H, s, tilt, n=4000)
        zs.append(_z(self_calibrate(y, H, DT, R=np.diag(sig ** 2), gauge="mean"), H, s, tilt))
    zs = np.array(zs)
    # 12 draws × 24 terms (15 free after the 9 of the gauge): the z scatter is about 1
    assert 0.8 < float(np.std(zs)) < 1.25, float(np.std(zs))
    assert abs(float(np.mean(zs))) < 0.2


def test_the_gyro_that_is_off_is_named():
    rng = np.random.default_rng(3)
    H = _axes8()
    s = np.zeros(8)
    tilt = np.zeros((8, 2))
    s[2] = 0.03                                       # gyro 3: +3 % scale factor
    tilt[5, 1] = 0.02                                 # gyro 6: 20 mrad tilt
    y, sig = _moving(rng, H, s, tilt)
    cal = self_calibrate(y, H, DT, R=np.diag(sig ** 2))          # the majority gauge
    assert set(cal.off) == {3, 6}, np.round(cal.z, 1)
    # few gyros off, the rest agree: their errors come out as they are, not spread by a mean
    est = np.c_[cal.scale_ppm * 1e-6, cal.tilt_mrad * 1e-3]
    sg = np.c_[cal.scale_sigma_ppm * 1e-6, cal.tilt_sigma_mrad * 1e-3]
    assert np.all(np.abs(est - np.c_[s, tilt]) < 4 * sg), np.round((est - np.c_[s, tilt]) / sg, 1)
    # the mean gauge spreads them: every gyro's terms move, the sum per column is the gauge's
    mean = self_calibrate(y, H, DT, R=np.diag(sig ** 2), gauge="mean")
    assert np.allclose(H.T @ mean.E, 0.0, atol=1e-9)
    assert mean.chi2 == pytest.approx(cal.chi2, rel=1e-2)       # the test hardly sees the gauge
    assert Z_OFF == 3.0


def test_no_error_no_finding():
    rng = np.random.default_rng(11)
    H = _axes8()
    y, sig = _moving(rng, H, np.zeros(8), np.zeros((8, 2)))
    cal = self_calibrate(y, H, DT, R=np.diag(sig ** 2))
    assert not cal.significant and cal.p_value > 1e-3
    assert np.all(np.abs(cal.z) < 4.5)


def test_turning_about_one_axis_leaves_terms_not_identified():
    rng = np.random.default_rng(5)
    H = _axes8()
    n = 4000
    t = np.arange(n) * DT
    om = np.c_[np.zeros(n), np.zeros(n), 3.0 * np.sin(2 * np.pi * 0.3 * t)]
    y = om @ H.T + 1e-7 * rng.normal(size=(n, 8))          # x and y not even excited by noise
    cal = self_calibrate(y, H, DT)
    assert np.isnan(cal.scale_sigma_ppm).any() or np.isnan(cal.tilt_sigma_mrad).any()
    assert any("not identified" in n for n in cal.notes)
    d = cal.to_json_dict()
    json.dumps(d, allow_nan=False)                     # not identified = null, never NaN


def test_saturated_samples_are_found():
    y = np.zeros((100, 4))
    y[40:50, 1] = 5.0                                  # gyro 2 clips at 5 rad/s
    y[:, 0] = np.linspace(-1, 1, 100)                  # gyro 1 never repeats its extreme
    mask, clip = saturated_mask(y, guard=1)
    assert clip[1] == 5.0 and np.isnan(clip[0])
    assert mask[39:51].all() and not mask[:38].any() and not mask[52:].any()


# -- the command -------------------------------------------------------------------------------

def _axes_sidecar(H, rate_hz):
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in h) + "]" for h in H)
    return f"sample_rate_hz = {rate_hz!r}\n[layout]\naxes = [{rows}]\n"


def _record(tmp_path, moving: bool):
    rng = np.random.default_rng(2)
    H = _axes8()
    n = 8000
    k = np.arange(n)
    still = (k < 3000) | (k >= 5000)                   # still, 20 s turning, still again
    s = np.zeros(8)
    s[4] = 0.02
    y, sig = _moving(rng, H, s, np.zeros((8, 2)), n=n)
    if moving:
        y[still] = 0.01 * rng.normal(size=(int(still.sum()), 8)) + 0.002
    else:
        y = 0.01 * rng.normal(size=(n, 8))
    deg = np.degrees(y)
    return write_measurement(tmp_path, "moving" if moving else "static", np.arange(n) * DT, deg,
                             sidecar=_axes_sidecar(H, 1.0 / DT))


def test_cli_parity_names_the_gyro(tmp_path, capsys):
    path = _record(tmp_path, True)
    assert main(["parity", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    cal = out["calibration"]
    assert set(cal["gyros"]) == {str(g) for g in range(1, 9)}
    g5 = cal["gyros"]["5"]
    assert g5["off"] and g5["scale_factor_ppm"] > 10 * g5["scale_factor_sigma_ppm"]
    assert set(g5) >= {"scale_factor_ppm", "scale_factor_sigma_ppm", "misalignment_mrad",
                       "misalignment_sigma_mrad", "misalignment_toward", "z", "off"}
    zmax = {g: max(abs(v) for v in d["z"]) for g, d in cal["gyros"].items()}
    assert max(zmax, key=zmax.get) == "5"


def test_cli_parity_static_record_has_no_calibration(tmp_path):
    # a static record gives no answer: exit 2 with the reason, never a null calibration
    path = _record(tmp_path, False)
    o = run_cli(["parity", path, "--json"])
    assert_contract(o, "static.csv")
    assert o.code == 2 and "the record has no motion" in o.err


def test_cli_parity_refuses_three_gyros(tmp_path):
    rng = np.random.default_rng(0)
    path = write_measurement(tmp_path, "three", np.arange(200) * 0.02, rng.normal(size=(200, 3)))
    o = run_cli(["parity", path])
    assert_contract(o, "three.csv")
    assert o.code == 2 and "at least 4 gyros" in o.err


@pytest.mark.parametrize("flag", ["--json", None])
def test_cli_parity_text_and_json_run(tmp_path, flag):
    path = _record(tmp_path, True)
    o = run_cli(["parity", path] + ([flag] if flag else []))
    assert_contract(o, "moving.csv")
    assert o.code == 0
    if flag is None:
        assert "scale factor" in o.out and "gauge" in o.out
