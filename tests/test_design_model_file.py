"""A model file written as docs/model-format.md instructs, designed with (issue 43, item 6).

The doc: "`gyro = k` (1-based) applies the entry to gyro k only. It overrides an all-gyros entry
of the same effect, so a heterogeneous array is one all-gyros entry plus one entry for each gyro
that differs." Such a model describes any array of N >= the highest gyro it names; the design
searches the N asked for, gyro 3 keeping its own level.

Outside truth: the ordering of three models' worst cases. With fixed weights M (nonzero on every
gyro: GLS on finite noise), the white variance M R Mᵀ is strictly increasing in each gyro's level,
so for every design f_alike(d) < f_noisy(d) < f_all_noisy(d); taking the minimum over designs,
min f_alike <= f_alike(d_noisy*) < min f_noisy <= f_noisy(d_all*) < min f_all_noisy: strict.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from hostile import assert_contract, run_cli

# the documented example, copied from docs/model-format.md ("Effects: the per-gyro terms")
DOC_EXAMPLE = '''description = "fitted to board.csv by gyroarray fit"
effects = [
    {effect = "arw", n_deg_rt_h = 0.1},
    {effect = "rrw", k_deg_h_rt_h = 2.0},
    {effect = "arw", gyro = 3, n_deg_rt_h = 0.45, sigma = {n_deg_rt_h = 0.01}},
    {effect = "correlation", rho_arw = 0.2},
    {effect = "scale_factor", gyro = 2, ppm = 6000},
]
'''
NOISY_LINE = '    {effect = "arw", gyro = 3, n_deg_rt_h = 0.45, sigma = {n_deg_rt_h = 0.01}},\n'
FAST = ("--estimators", "gls", "--objective", "rate", "--horizon-s", 60, "--rate-hz", 100)


def _write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _design(model: Path, *extra) -> dict:
    o = run_cli(["design", "--recommend", "--model", model, "--n", 6, *FAST, "--json", *extra], timeout=300)
    assert_contract(o)
    assert o.code == 0, o.err
    return o.json


def _worst(res: dict) -> float:
    return res["recommended"]["worst_case"]["rms_3axis_deg_s"]


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("models")
    assert NOISY_LINE in DOC_EXAMPLE
    alike = DOC_EXAMPLE.replace(NOISY_LINE, "")
    return {"doc": _write(d, "doc.toml", DOC_EXAMPLE),
            "alike": _write(d, "alike.toml", alike),
            "all_noisy": _write(d, "all_noisy.toml", alike.replace("n_deg_rt_h = 0.1}", "n_deg_rt_h = 0.45}"))}


def test_documented_model_gives_a_six_gyro_design_with_gyro_3_noisy(models):
    res = _design(models["doc"])
    assert res["recommended"]["n"] == 6 and {d["n"] for d in res["designs"]} == {6}
    # gyro 3 has its own level, the others the all-gyros entry (overridden, not added)
    assert res["assumptions"]["gyros"]["value"]["per_gyro"]["arw"] == pytest.approx(
        [0.1, 0.1, 0.45, 0.1, 0.1, 0.1], rel=1e-12)
    worst = _worst(res)
    alike, all_noisy = _worst(_design(models["alike"])), _worst(_design(models["all_noisy"]))
    # strict ordering (module docstring); the all-noisy array is 4.5x noisier in ARW everywhere
    assert alike < worst < all_noisy


def test_documented_model_with_one_failure(models):
    res = _design(models["doc"], "--failures", 1)
    rec = res["recommended"]
    assert rec["n"] == 6 and len(rec["worst_case"]["failed_gyros"]) == 1
    assert res["assumptions"]["gyros"]["value"]["per_gyro"]["arw"][2] == pytest.approx(0.45, rel=1e-12)
    # losing a gyro costs accuracy: the worst case over failed sets exceeds the intact typical case
    assert rec["worst_case"]["rms_3axis_deg_s"] > rec["typical"]["rms_3axis_deg_s"]


def test_a_model_naming_gyro_7_refuses_n_6(tmp_path):
    p = _write(tmp_path, "m7.toml", DOC_EXAMPLE.replace("gyro = 3,", "gyro = 7,"))
    o = run_cli(["design", "--recommend", "--model", p, "--n", 6, *FAST, "--json"])
    assert_contract(o, str(p))
    assert o.code == 2 and len(o.err.strip().splitlines()) == 1, o.err
    assert str(p) in o.err and "gyro 7" in o.err and "N = 6" in o.err
