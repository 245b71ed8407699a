"""Inflation measured from a redundant array's parity residual during motion (issue 42, item 6).

A numpy record of 6 gyros on a scheme-1 cone (54.7356°, rank 3): a still start, then cycles of
plateaus at 25 and 50 deg/s (the axis turning slowly), each cycle ending still. The white density
of every gyro grows with the rate: N0 on the still parts, 2·N0 at 25 deg/s, 3·N0 at 50 deg/s;
plateaus start and end on whole seconds, so every 1 s window has one true density. Each gyro
has its own constant bias and a random-walk bias (K). Checked: the density per level within its
interval of the truth, the interval as narrow as its χ² dof allow (so the check can fail), the
held-out NIS inside with the measured values and outside with the static ones, the static parity
density of a model against the hat-matrix form, the 3-gyro refusal, and the CLI path once.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroarray.chain.inflation_parity import (measure_parity_inflation, parity_basis,
                                              parity_inflation_for_export)
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement
from gyroarray.effects.model import NoiseModel
from hostile import write_measurement

FS_HZ = 50.0
N0 = 2e-3                 # static white density [rad/√s]
K = 1e-5                  # bias walk [rad/s/√s]
#: (duration [s], rate [deg/s], density multiplier [-]) of each plateau after the still start.
CYCLE = ((20.0, 25.0, 2.0), (20.0, 50.0, 3.0), (10.0, 0.0, 1.0))
STILL_S = 60.0
CYCLES = 6
#: the truth per level (the default levels: [0, 0.05), [0.2, 0.5) holds 25 deg/s = 0.436 rad/s,
#: [0.5, 1) holds 50 deg/s = 0.873 rad/s)
TRUTH = {0: 1.0, 2: 2.0, 3: 3.0}
LAYOUT = Layout.conical(1, 6, math.radians(54.7356))
SIDECAR = f"sample_rate_hz = {FS_HZ!r}\n[layout]\nscheme = 1\nn_gyros = 6\nalpha_deg = 54.7356\n"


def record(rng: np.random.Generator, layout: Layout = LAYOUT, n_scale=None):
    """(time [s], gyro readings [rad/s], n × N) of the plateau record on ``layout``; ``n_scale``:
    per-gyro multipliers of N0 (default 1 for every gyro)."""
    segs = [(STILL_S, 0.0, 1.0)] + list(CYCLE) * CYCLES
    rate = np.concatenate([np.full(int(s * FS_HZ), math.radians(r)) for s, r, _ in segs])
    mult = np.concatenate([np.full(int(s * FS_HZ), m) for s, _, m in segs])
    n = rate.size
    t = np.arange(n) / FS_HZ
    # a unit axis turning slowly (periods of about 2 and 3.4 min), |ω| = the plateau's rate
    u = np.stack([np.cos(0.05 * t) * np.cos(0.031 * t), np.sin(0.05 * t) * np.cos(0.031 * t),
                  np.sin(0.031 * t)], axis=1)
    H = layout.H
    ng = H.shape[0]
    scale = np.ones(ng) if n_scale is None else np.asarray(n_scale, float)
    bias = 0.01 * rng.standard_normal(ng) + np.cumsum(
        K * math.sqrt(1.0 / FS_HZ) * rng.standard_normal((n, ng)), axis=0)
    white = mult[:, None] * scale[None, :] * N0 * math.sqrt(FS_HZ) * rng.standard_normal((n, ng))
    return t, (rate[:, None] * u) @ H.T + bias + white


def measurement(t, y, layout: Layout = LAYOUT) -> Measurement:
    return Measurement(time_s=t, gyro_deg_s=units.rad_s_to_deg_s(y), layout=layout,
                       sample_rate_hz=FS_HZ, source="numpy record")


def model(n_rad_rt_s: float = N0, k: float = K) -> NoiseModel:
    return NoiseModel.from_toml({"effects": [
        {"effect": "arw", "n_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(n_rad_rt_s))},
        {"effect": "rrw", "k_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(k))}]})


@pytest.fixture(scope="module")
def rec():
    # seed 102; over seeds 100-139 (model given) the estimator is unbiased: mean N/N0 0.993,
    # 1.999, 3.009 (sd 0.044, 0.091, 0.141, as the intervals' width says), all three levels
    # inside their 95 % intervals in 34 of 40 (0.95³ = 0.86), the measured NIS inside its
    # interval in 38 of 40 (mean 1.031, sd 0.10)
    return record(np.random.default_rng(102))


def _check_levels(res):
    for L, truth in TRUTH.items():
        lv = res.levels[L]
        lo, hi = lv.ci_rad_rt_s
        # the 95 % interval of each level holds the truth (one fixed draw: a biased estimator,
        # e.g. one that missed the neighbours' share of the bias estimate, falls outside)
        assert lo <= truth * N0 <= hi, (L, lv.density_rad_rt_s / N0, lo / N0, hi / N0)
        # and it is no wider than its dof allow: ν = (N − 3)·n_L/(1 + 2/m), m ≥ 14 neighbours
        # (bias_span 15 less the adjacent one, at a record's edge), ln χ²_ν/ν has sd √(2/ν), so
        # hi/lo ≈ exp(2z/√(2ν)) in density; 10 % slack for the neighbour share's shift
        nu = 3 * lv.n_windows / (1 + 2 / 14)
        assert hi / lo <= 1.1 * math.exp(2 * 1.96 / math.sqrt(2 * nu)), (L, hi / lo, nu)
        assert lv.n_windows >= 60                      # each level is really measured
    assert res.levels[1].n_windows == 0                # no window between the plateaus' bins


def test_densities_per_level_and_held_out_nis_still_part(rec):
    """Without a model: the static density is the still level's; the densities per level hold
    the truth; the held-out NIS is inside 1 ± z√(2/n_eff + v) with the measured values and far
    outside with the static ones (at the motion mix 2 N0, 3 N0, N0 the static values give a mean
    NIS of about (4·20 + 9·20 + 10)/50 = 5.4)."""
    t, y = rec
    res = measure_parity_inflation(measurement(t, y))
    assert res.n_gyros == 6 and res.n_parity == 3 and res.static_source == "still part"
    _check_levels(res)
    # the still level's density is the static one: N0 within its own interval
    lo, hi = res.levels[0].ci_rad_rt_s
    assert lo <= N0 <= hi and res.static_n_rad_rt_s == res.levels[0].density_rad_rt_s
    meas, static = res.nis_check("measured"), res.nis_check("static")
    assert meas.n_eff == 3 * int((res.windows_holdout).sum()) and meas.n_eff >= 200
    assert meas.inside, meas
    assert not static.inside and static.mean_nis > 3.0, static
    # the factor: √(Σ w_L N_L²)/N_static over the fitted windows from the motion's start (2:2:1
    # of 25, 50 deg/s and the pauses: √((4·2 + 9·2 + 1)/5) = 2.32); its interval holds the truth
    # (without the pauses it would be √((4 + 9)/2) = 2.55, outside an interval about ±7 % wide)
    truth_f = math.sqrt((4 * 2 + 9 * 2 + 1) / 5)
    assert res.density_factor_ci[0] <= truth_f <= res.density_factor_ci[1], (res.density_factor, res.density_factor_ci)
    # the exported factor (the static filter times it consistent on the fitted motion windows)
    # holds it too, and its held-out NIS is inside
    assert res.factor_ci[0] <= truth_f <= res.factor_ci[1], (res.factor_for_export, res.factor_ci)
    assert res.nis_check("export").inside, res.nis_check("export")


def test_model_static_density_is_the_trace_form(rec):
    """With a model: the static parity density is √(tr(VᵀRV)/(N − 3)); for equal gyros that is
    N0 itself; for unequal ones it equals the hat-matrix form Σ_i R_ii (1 − h_iᵀ(HᵀH)⁻¹h_i)/(N − 3)
    (VVᵀ = I − H(HᵀH)⁻¹Hᵀ, computed without V)."""
    t, y = rec
    res = measure_parity_inflation(measurement(t, y), model=model())
    assert res.static_source == "model"
    assert res.static_n_rad_rt_s == pytest.approx(N0, rel=1e-9)      # units round trip only
    assert res.static_k_rad_s_rt_s == pytest.approx(K, rel=1e-9)
    _check_levels(res)
    assert res.nis_check("measured").inside
    assert not res.nis_check("static").inside
    # the static N is the truth here, so the factor's interval holds √((4·2 + 9·2 + 1)/5) = 2.32
    assert res.factor_ci[0] <= math.sqrt(27 / 5) <= res.factor_ci[1], res.factor_ci
    # unequal gyros: gyro k has N0·(1 + k/10)
    scale = 1 + np.arange(6) / 10
    entries = [{"effect": "arw", "gyro": k + 1,
                "n_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(s * N0))} for k, s in enumerate(scale)]
    res2 = measure_parity_inflation(measurement(t, y), model=NoiseModel.from_toml({"effects": entries}))
    H = LAYOUT.H
    lev = np.einsum("ij,jk,ik->i", H, np.linalg.inv(H.T @ H), H)
    want = math.sqrt(float(np.sum((scale * N0) ** 2 * (1 - lev))) / 3)
    assert res2.static_n_rad_rt_s == pytest.approx(want, rel=1e-9)
    assert np.allclose(parity_basis(H).T @ H, 0, atol=1e-12)


def test_a_triad_is_refused_with_what_is_needed(tmp_path):
    tri = Layout.triad()
    t, y = record(np.random.default_rng(1), layout=tri)
    with pytest.raises(InputError, match=r"more than 3 gyros.*--reference BAG --reference-topic T"):
        measure_parity_inflation(measurement(t[:6000], y[:6000], tri))
    path = write_measurement(tmp_path, "triad", t[:3000], units.rad_s_to_deg_s(y[:3000]),
                             sidecar=f"sample_rate_hz = {FS_HZ!r}\n[layout]\naxes = "
                                     "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n")
    with pytest.raises(InputError, match=r"has 3 gyros: give --reference BAG --reference-topic T") as err:
        parity_inflation_for_export(path, model(), N0, "gyro 1")
    assert err.value.file == str(path)


def test_cli_export_inflate_measured_from_the_parity(rec, tmp_path, cli):
    """``export MODEL --inflate measured --record ARRAY.csv`` (no --reference): the factor of the
    library call on the same file, in the header and the JSON; the gyro numbers × it; a triad
    record and a stray --reference-topic refused in one line, nothing written."""
    import json
    t, y = rec
    csv = write_measurement(tmp_path, "array", t, units.rad_s_to_deg_s(y), sidecar=SIDECAR)
    mpath = tmp_path / "m.toml"
    mpath.write_text(f'effects = [{{effect = "arw", n_deg_rt_h = {units.arw_rad_rt_s_to_deg_rt_h(N0)!r}}}, '
                     f'{{effect = "rrw", k_deg_h_rt_h = {units.rrw_rad_s_rt_s_to_deg_h_rt_h(K)!r}}}]\n')
    out = tmp_path / "imu.yaml"
    p = cli("export", mpath, "--format", "kalibr", "--rate-hz", FS_HZ, "--out", out, "--inflate",
            "measured", "--record", csv, "--json")
    got = json.loads(p.stdout)
    m = got["inflate_measured"]
    assert m["from"] == "from the parity residual of 6 gyros during motion" and m["method"] == "parity"
    want, _, lines = parity_inflation_for_export(csv, NoiseModel.from_toml(mpath), N0 * 1.0,
                                                 f"gyro {got['gyro']}", rng=np.random.default_rng(0))
    assert m["factor"] == pytest.approx(want, rel=1e-12) and want > 2.0   # the truth is 2.32
    assert got["values"]["gyroscope_noise_density"] == pytest.approx(want * N0, rel=1e-9)
    text = out.read_text()
    assert "from the parity residual of 6 gyros during motion" in text
    for line in lines[2:]:                                  # the NIS line, byte for byte
        assert f"# {line}\n" in text
    assert [c["label"] for c in m["nis"]] == ["measured", "static", "export"]
    # a triad record without --reference: refused, naming what is needed
    tri = write_measurement(tmp_path, "tri", t[:3000], units.rad_s_to_deg_s(y[:3000, :3]),
                            sidecar=f"sample_rate_hz = {FS_HZ!r}\n[layout]\naxes = "
                                    "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n")
    for extra, fragment in ((["--record", tri], "--reference BAG --reference-topic T"),
                            (["--record", csv, "--reference-topic", "/pose"], "read only with --reference")):
        bad = tmp_path / "bad.yaml"
        q = cli("export", mpath, "--format", "kalibr", "--rate-hz", FS_HZ, "--out", bad, "--inflate",
                "measured", *extra, check=False)
        assert q.returncode == 2 and fragment in q.stderr and len(q.stderr.strip().splitlines()) == 1, q.stderr
        assert not bad.exists()


def test_cli_inflate_window_levels_and_holdout_reach_the_measurement(rec, tmp_path, cli):
    """``--inflate-window``, ``--inflate-levels`` and ``--inflate-holdout`` are the library's
    ``window_s``, ``levels`` and ``holdout`` (the same factor to 1e-12); refused in one line
    without ``--inflate measured`` or with edges that do not increase, nothing written."""
    import json
    t, y = rec
    csv = write_measurement(tmp_path, "array", t, units.rad_s_to_deg_s(y), sidecar=SIDECAR)
    mpath = tmp_path / "m.toml"
    mpath.write_text(f'effects = [{{effect = "arw", n_deg_rt_h = {units.arw_rad_rt_s_to_deg_rt_h(N0)!r}}}, '
                     f'{{effect = "rrw", k_deg_h_rt_h = {units.rrw_rad_s_rt_s_to_deg_h_rt_h(K)!r}}}]\n')
    p = cli("export", mpath, "--format", "kalibr", "--rate-hz", FS_HZ, "--out", tmp_path / "w.yaml",
            "--inflate", "measured", "--record", csv, "--inflate-window", "0.5", "--inflate-levels",
            "0,0.05,0.6", "--inflate-holdout", "0.4", "--json")
    m = json.loads(p.stdout)["inflate_measured"]
    assert m["window_s"] == pytest.approx(0.5, rel=1e-9)
    assert [(lv["lo"], lv["hi"]) for lv in m["levels"]] == [(0.0, 0.05), (0.05, 0.6), (0.6, None)]
    want, _, _ = parity_inflation_for_export(csv, NoiseModel.from_toml(mpath), N0 * 1.0, "gyro 1",
                                             rng=np.random.default_rng(0), window_s=0.5, holdout=0.4,
                                             levels=(0.0, 0.05, 0.6, math.inf))
    assert m["factor"] == pytest.approx(want, rel=1e-12)
    for extra, fragment in ((["--inflate", "2", "--inflate-window", "0.5"], "read only with --inflate measured"),
                            (["--inflate", "measured", "--record", csv, "--inflate-levels", "0,0.5,0.2"],
                             "increasing finite rates")):
        bad = tmp_path / "bad.yaml"
        q = cli("export", mpath, "--format", "kalibr", "--rate-hz", FS_HZ, "--out", bad, *extra, check=False)
        assert q.returncode == 2 and fragment in q.stderr and len(q.stderr.strip().splitlines()) == 1, q.stderr
        assert not bad.exists()
