"""``gyroarray fuse`` (issue 31, item 1): a recorded array fused by a registered estimator.

Outside truth: the fused ADEV on the MIMU4444 record's still parts is recomputed here with
plain numpy (least-squares fusion of the raw CSV columns, overlapping Allan variance from
cumulative sums) and must agree to 1e-9; the fused file must read back as a measurement and
be analysed by ``allan``, ``davar`` and ``compare``.
"""

from __future__ import annotations

import gzip
import hashlib
import os
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

from hostile import assert_contract, run_cli, write_measurement

MIMU = Path(__file__).resolve().parents[1].parent / "shared" / "measurements" / "real" / "mimu4444_array24.csv.gz"
if not MIMU.exists():                                  # the checkout's sibling, or the usual place
    MIMU = Path("/work/shared/measurements/real/mimu4444_array24.csv.gz")
CUT_S = 150.0                      # the first 150 s: 7 still orientations and the moves between
DEG_H = 3600.0                     # deg/s -> deg/h


def _read_csv(path: Path, until_s: float = np.inf) -> tuple[list[str], np.ndarray]:
    """Header and values of a measurement CSV (the rows before ``until_s`` after the first),
    with numpy alone (comments skipped)."""
    opener = gzip.open if path.name.endswith(".gz") else open
    with opener(path, "rt") as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    t = np.array([float(ln.split(",", 1)[0]) for ln in lines[1:]])
    rows = int(np.searchsorted(t - t[0], until_s))
    return lines[0].strip().split(","), np.loadtxt(lines[1:1 + rows], delimiter=",", ndmin=2)


def _axes(sidecar: Path) -> np.ndarray:
    with open(sidecar, "rb") as fh:
        return np.array(tomllib.load(fh)["layout"]["axes"], dtype=float)


def _oadev(x: np.ndarray, m: int) -> np.ndarray:
    """Overlapping Allan deviation of each column at averaging factor m [unit of x]."""
    phase = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x - x.mean(axis=0), axis=0)])
    d = phase[2 * m:] - 2 * phase[m:-m] + phase[:-2 * m]
    return np.sqrt((d ** 2).sum(axis=0) / (2.0 * m * m * (phase.shape[0] - 2 * m)))


def _stitched(z: np.ndarray, parts) -> np.ndarray:
    return np.concatenate([z[a:b] - z[a:b].mean(axis=0) for a, b in parts])


@pytest.fixture(scope="module")
def cut(tmp_path_factory):
    """The first CUT_S seconds of the MIMU4444 record (CSV + sidecar), and its arrays."""
    if not MIMU.exists():
        pytest.skip("the shared MIMU4444 record is not here")
    folder = tmp_path_factory.mktemp("fuse")
    names, values = _read_csv(MIMU, CUT_S)
    t = values[:, 0]
    gyro = values[:, [names.index(f"gyro{k}") for k in range(1, 25)]]
    sidecar = MIMU.with_name("mimu4444_array24.toml").read_text()
    path = write_measurement(folder, "mimu_cut", t, gyro, sidecar=sidecar, gz=True)
    return {"path": path, "t": t, "gyro": gyro, "H": _axes(folder / "mimu_cut.toml"),
            "folder": folder}


def _fuse(cut, *extra, name=None) -> dict:
    argv = ["fuse", cut["path"], "--json", *extra]
    o = run_cli(argv)
    assert o.code == 0, o.err
    return o.json


def _pooled_oadev(x: np.ndarray, parts, m: int) -> np.ndarray:
    """Overlapping Allan deviation pooled over still parts (each part's mean out, no difference
    across a join): Σ_parts Σ d² / (2 m² Σ terms), parts shorter than 2m + 1 left out."""
    num, den = 0.0, 0
    for a, b in parts:
        if b - a + 1 - 2 * m < 1:
            continue
        s = x[a:b] - x[a:b].mean(axis=0)
        phase = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(s, axis=0)])
        d = phase[2 * m:] - 2 * phase[m:-m] + phase[:-2 * m]
        num = num + (d ** 2).sum(axis=0)
        den += d.shape[0]
    return np.sqrt(num / (2.0 * m * m * den))


def _check_adev(res: dict, fused_deg_s: np.ndarray) -> int:
    """The JSON's fused ADEV at 0.1-10 s equals numpy's pooled over the same still parts (never
    across a join: issue 41); returns the number of τ compared."""
    parts = res["analysed_parts"]
    dt = res["dt_s"]
    compared = 0
    for a, axis in enumerate("xyz"):
        d = res["axes"][axis]
        for tau, adev in zip(d["taus_s"], d["adev_deg_h"]):
            if not 0.1 <= tau <= 10.0:
                continue
            m = int(round(tau / dt))
            ours = (_pooled_oadev(fused_deg_s[:, a:a + 1], parts, m)[0] if len(parts) > 1 else
                    _oadev(_stitched(fused_deg_s, parts)[:, a:a + 1], m)[0]) * DEG_H
            assert adev == pytest.approx(ours, rel=1e-9), (axis, tau)
            compared += 1
    return compared


def test_ols_fused_adev_equals_numpy_least_squares(cut):
    res = _fuse(cut, "--estimator", "ols")
    parts = res["analysed_parts"]
    # the still parts are still: a 1 s mean of the LS rate moves by far less than the hand
    # placements between them (tens of deg/s), and they cover most of the cut
    ls = np.linalg.lstsq(cut["H"], cut["gyro"].T, rcond=None)[0].T          # (n, 3) deg/s
    assert len(parts) >= 5 and sum(b - a for a, b in parts) * res["dt_s"] > 0.6 * CUT_S
    for a, b in parts:
        k = 62
        means = np.array([ls[i:i + k].mean(axis=0) for i in range(a, b - k, k)])
        assert np.ptp(means, axis=0).max() < 0.5, (a, b)
    assert _check_adev(res, ls) >= 3 * 6
    # the gain is the best single gyro's ARW on the axis over the fused ARW
    for axis, d in res["axes"].items():
        assert d["gain"] == pytest.approx(d["best_single_arw_deg_rt_h"] / d["arw_deg_rt_h"])
        a = "xyz".index(axis)
        along = [k for k in res["gyros_used"] if abs(cut["H"][k - 1, a]) > 0.99]
        best = min(res["single_gyros"][str(k)]["arw_deg_rt_h"] for k in along)
        assert d["best_single_arw_deg_rt_h"] == pytest.approx(best)
        assert d["best_single_gyro"] in along


def test_gls_uses_the_fitted_noise_and_equals_numpy(cut):
    res = _fuse(cut, "--estimator", "gls")
    arw = np.array(res["design_noise"]["arw_deg_rt_h"])
    assert res["design_noise"]["correlated"] is False and "fitted" in res["model_source"]
    w = 1.0 / arw ** 2                                    # R⁻¹ up to a factor
    h = cut["H"]
    g = np.linalg.solve(h.T @ (w[:, None] * h), (h * w[:, None]).T)         # (HᵀWH)⁻¹HᵀW
    assert _check_adev(res, cut["gyro"] @ g.T) >= 3 * 6
    # weighting by the gyros' own noise is not worse than OLS on any axis (white level)
    ols = _fuse(cut, "--estimator", "ols")
    for axis in "xyz":
        assert res["axes"][axis]["arw_deg_rt_h"] <= 1.05 * ols["axes"][axis]["arw_deg_rt_h"]
    for key in ("measurement", "estimator", "model_source", "gyros_used", "excluded_gyros",
                "constant_gyros", "design_noise", "analysed", "analysed_parts", "analysed_parts_s",
                "axes", "single_gyros", "gain_definition", "notes"):
        assert key in res, key
    for d in res["axes"].values():
        for key in ("taus_s", "adev_deg_h", "ci_low_deg_h", "ci_high_deg_h", "confidence",
                    "arw_deg_rt_h", "arw_deg_rt_h_sigma", "best_single_gyro",
                    "best_single_arw_deg_rt_h", "gain", "predicted_arw_deg_rt_h"):
            assert key in d, key
        lo, mid, hi = (np.array(d[k]) for k in ("ci_low_deg_h", "adev_deg_h", "ci_high_deg_h"))
        assert np.all(lo < mid) and np.all(mid < hi)


def test_exclude_leaves_gyros_out_and_refits_the_geometry(cut):
    res = _fuse(cut, "--estimator", "ols", "--exclude", "1,4")
    used = [k for k in range(1, 25) if k not in (1, 4)]
    assert res["gyros_used"] == used and res["excluded_gyros"] == [1, 4]
    h = cut["H"][[k - 1 for k in used]]
    ls = np.linalg.lstsq(h, cut["gyro"][:, [k - 1 for k in used]].T, rcond=None)[0].T
    assert _check_adev(res, ls) >= 3 * 6


@pytest.mark.parametrize("exclude, words", [
    ("1,5,7,11,13,17,19,23", "do not span 3 independent axes"),         # every x gyro
    (",".join(map(str, range(1, 25))), "no gyro left"),
    ("25", "out of range"),
    ("0,x", "comma-separated list"),
])
def test_bad_exclude_is_one_line(cut, exclude, words):
    o = run_cli(["fuse", cut["path"], "--estimator", "gls", "--exclude", exclude])
    assert_contract(o)
    assert o.code == 2 and words in o.err, o.err
    if "gyro" in words or "axes" in words or "range" in words:
        assert str(cut["path"]) in o.err


def test_output_reads_back_and_other_commands_analyse_it(cut):
    out = cut["folder"] / "fused.csv.gz"
    res = _fuse(cut, "--estimator", "ols", "--out", out)
    from gyroarray.core.measurement import read_measurement
    m = read_measurement(out)
    assert m.n_gyros == 3 and np.array_equal(m.layout.axes, np.eye(3))
    assert np.array_equal(m.time_s, cut["t"]) and not m.has_reference
    ls = np.linalg.lstsq(cut["H"], cut["gyro"].T, rcond=None)[0].T
    np.testing.assert_allclose(m.gyro_deg_s, ls, rtol=1e-9, atol=1e-12)
    side = tomllib.loads(out.with_name("fused.toml").read_text())
    assert side["fused"]["estimator"] == "ols" and side["fused"]["gyros_used"] == list(range(1, 25))
    assert side["fused"]["input_sha256"] == hashlib.sha256(cut["path"].read_bytes()).hexdigest()
    assert res["out"] == str(out)


def test_allan_davar_compare_read_the_fused_file(tmp_path):
    path = _white_array(tmp_path, "array")
    out = tmp_path / "fused.csv"
    f = run_cli(["fuse", path, "--estimator", "gls", "--out", out, "--json"])
    assert f.code == 0, f.err
    a = run_cli(["allan", out, "--json"])
    assert a.code == 0, a.err
    assert set(a.json["gyros"]) == {"1", "2", "3"}
    # allan's ADEV of gyro1 (fused x) is fuse's (the whole record is still here)
    fx = f.json["axes"]["x"]
    ax = a.json["gyros"]["1"]
    assert ax["adev_deg_h"][:len(fx["adev_deg_h"])] == pytest.approx(fx["adev_deg_h"], rel=1e-9)
    d = run_cli(["davar", out, "--gyro", "3", "--window", "256", "--step", "256", "--json"])
    assert d.code == 0, d.err
    rep = tmp_path / "fused_report.html"
    c = run_cli(["compare", out, "--runs", "2", "--out", rep, "--json"])
    assert c.code == 0, c.err
    assert rep.exists()


def test_output_guarded(cut):
    out = cut["folder"] / "guarded.csv.gz"
    _fuse(cut, "--estimator", "ols", "--out", out)
    before = out.read_bytes()
    o = run_cli(["fuse", cut["path"], "--estimator", "gls", "--out", out])
    assert_contract(o, str(out))
    assert o.code == 2 and "exists" in o.err and out.read_bytes() == before
    # --force replaces a symbolic link at the name, never its target
    target = cut["folder"] / "target.csv.gz"
    target.write_bytes(b"keep me")
    link = cut["folder"] / "link.csv.gz"
    os.symlink(target, link)
    o = run_cli(["fuse", cut["path"], "--estimator", "ols", "--out", link, "--force"])
    assert o.code == 0, o.err
    assert target.read_bytes() == b"keep me" and not link.is_symlink()
    # never the input
    o = run_cli(["fuse", cut["path"], "--estimator", "ols", "--out", cut["path"], "--force"])
    assert_contract(o)
    assert o.code == 2 and "input" in o.err


def _white_array(folder: Path, name: str, *, constant: int | None = None) -> Path:
    """A 4-gyro tetrahedral array at rest, white noise of different levels (numpy)."""
    rng = np.random.default_rng(31)
    n, dt = 4000, 0.02
    sig = np.array([0.05, 0.1, 0.2, 0.05])                 # deg/s per sample
    g = rng.normal(0.0, 1.0, (n, 4)) * sig
    if constant is not None:
        g[:, constant - 1] = 0.125
    side = ('sample_rate_hz = 50.0\n[layout]\naxes = [[0.9428, 0.0, -0.3333], [-0.4714, 0.8165, -0.3333], '
            '[-0.4714, -0.8165, -0.3333], [0.0, 0.0, 1.0]]\n')
    return write_measurement(folder, name, np.arange(n) * dt, g, sidecar=side)


def test_constant_gyro_left_out_and_model_used(tmp_path):
    path = _white_array(tmp_path, "dead", constant=2)
    o = run_cli(["fuse", path, "--estimator", "gls", "--json"])
    # 3 gyros left of a tetrahedron span 3 axes: fused, gyro 2 named
    assert o.code == 0, o.err
    assert o.json["constant_gyros"] == [2] and 2 not in o.json["gyros_used"]
    assert any("gyro 2" in n and "constant" in n for n in o.json["notes"])
    model = tmp_path / "model.toml"
    model.write_text("effects = [\n" + ",\n".join(
        f'  {{effect = "arw", gyro = {k}, n_deg_rt_h = {v}}}' for k, v in
        enumerate((0.3, 0.6, 1.2, 0.3), 1)) + "\n]\n")
    path = _white_array(tmp_path, "alive")
    r = run_cli(["fuse", path, "--estimator", "gls", "--model", model, "--off-levels", "model", "--json"])
    assert r.code == 0, r.err
    assert r.json["design_noise"]["arw_deg_rt_h"] == pytest.approx([0.3, 0.6, 1.2, 0.3])
    assert str(model) in r.json["model_source"]
    # the record's levels (0.05-0.2 deg/s per sample at 50 Hz: 0.42, 0.85, 1.70, 0.42 deg/√h) are
    # 1.41x the model's, beyond the record's own 95 % interval (EDF ~115 at 1 s: ±13 %): by default
    # each gyro is named and designed with the record's level
    d = run_cli(["fuse", path, "--estimator", "gls", "--model", model, "--json"])
    assert d.code == 0, d.err
    assert d.json["model_check"]["off"] == [1, 2, 3, 4]
    assert d.json["design_noise"]["arw_deg_rt_h"] == pytest.approx(
        [d.json["model_check"]["gyros"][str(k)]["record_n_deg_rt_h"] for k in range(1, 5)])
    assert any("outside the model's 95% range" in n for n in d.json["notes"])
    # a model without arw for a used gyro: refused, naming the model
    model.write_text('effects = [{effect = "arw", gyro = 1, n_deg_rt_h = 0.3}]\n')
    b = run_cli(["fuse", path, "--estimator", "gls", "--model", model])
    assert_contract(b, str(model))
    assert b.code == 2


def test_bad_input_is_one_line(tmp_path, cut):
    path = _white_array(tmp_path, "plain")
    o = run_cli(["fuse", path, "--estimator", "nope"])
    assert_contract(o)
    assert o.code == 2 and "--estimator" in o.err and "gls" in o.err
    no_layout = write_measurement(tmp_path, "nolayout", np.arange(300) * 0.02,
                                  np.zeros((300, 3)) + np.arange(3), sidecar="sample_rate_hz = 50.0\n")
    o = run_cli(["fuse", no_layout, "--estimator", "gls"])
    assert_contract(o, "nolayout.toml")
    assert o.code == 2
    lonely = tmp_path / "lonely.csv"
    lonely.write_text("time_s,gyro1,gyro2,gyro3\n0,0,0,0\n0.02,0,0,0\n")
    o = run_cli(["fuse", lonely, "--estimator", "gls"])
    assert_contract(o, "lonely")
    assert o.code == 2
    o = run_cli(["fuse", path, "--estimator", "gls", "--out", tmp_path / "x.txt"])
    assert_contract(o, "x.txt")
    assert o.code == 2


def test_whole_record_under_ten_seconds(tmp_path):
    """The issue's 'done when': the whole 24-gyro record fused with GLS in under 10 s (CPU time
    of this process, which a machine shared with other jobs does not inflate)."""
    if not MIMU.exists():
        pytest.skip("the shared MIMU4444 record is not here")
    start = time.process_time()
    o = run_cli(["fuse", MIMU, "--estimator", "gls", "--out", tmp_path / "F.csv.gz", "--json"])
    cpu = time.process_time() - start
    assert o.code == 0, o.err
    assert cpu < 10.0
    res = o.json
    assert len(res["analysed_parts"]) >= 15                        # ~20 still orientations
    for d in res["axes"].values():
        assert d["gain"] > 1.2                                      # fusion beats every single gyro


# -- 3a: variance-optimal static weights (svo) ---------------------------------------------

def _numpy_walk_array(seed: int = 3):
    """6 gyros on a cone, equal white noise, a strong rate random walk on gyros 1 and 2 (numpy)."""
    from gyroarray.core.layout import Layout
    lay = Layout.conical(1, 6, np.deg2rad(54.7356))
    dt, n = 0.01, 60000
    arw = np.full(6, np.deg2rad(1.0) / 60.0)                      # 1 deg/√h [rad/√s]
    rrw = np.deg2rad(np.array([5000.0, 5000.0, 1.0, 1.0, 1.0, 1.0])) / 3600.0 / 60.0
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(n, 6)) * arw / np.sqrt(dt) + np.cumsum(rng.normal(size=(n, 6)) * rrw * np.sqrt(dt),
                                                                  axis=0)
    return lay, dt, arw, rrw, z


def test_svo_beats_gls_at_its_tau_on_heterogeneous_slow_noise():
    from gyroarray.estimators import ArrayNoise, make
    lay, dt, arw, rrw, z = _numpy_walk_array()
    noise = ArrayNoise(arw, rrw, np.eye(6), np.eye(6))
    tau = 5.0
    m = int(round(tau / dt))
    gls = make("gls").fit(lay, noise, dt)
    svo = make("svo", tau_s=tau).fit(lay, noise, dt)
    np.testing.assert_allclose(svo.weights_ @ lay.axes, np.eye(3), atol=1e-12)    # unity gain
    a_gls, a_svo = (_oadev(e.estimate(z), m) for e in (gls, svo))
    assert np.all(a_svo < 0.8 * a_gls), (a_svo, a_gls)             # ~0.57 on this array
    # it pays for it at short τ, where the white noise decides and gls is the optimum
    assert np.all(_oadev(svo.estimate(z), 1) > _oadev(gls.estimate(z), 1))
    # the predicted Allan deviation at τ (N²/τ + K²τ/3 per gyro) holds for the realisation
    np.testing.assert_allclose(a_svo, np.sqrt(svo.allan_variance_), rtol=0.25)
    # white noise alone: the Allan covariance is R/τ·dt and svo is gls
    white = ArrayNoise(arw, np.zeros(6), np.eye(6), np.eye(6))
    np.testing.assert_allclose(make("svo", tau_s=tau).fit(lay, white, dt).weights_,
                               make("gls").fit(lay, white, dt).weights_, rtol=1e-10, atol=1e-14)


def test_svo_through_fuse(tmp_path):
    path = _white_array(tmp_path, "svo")
    o = run_cli(["fuse", path, "--estimator", "svo", "--param", "tau_s=2", "--json"])
    assert o.code == 0, o.err
    assert o.json["estimator_params"]["tau_s"] == 2.0
    assert any("Allan variance measured" in n for n in o.json["notes"])
    bad = run_cli(["fuse", path, "--estimator", "svo", "--param", "tau=2"])
    assert_contract(bad)
    assert bad.code == 2 and "tau" in bad.err
