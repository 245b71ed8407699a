"""Issue 30, item 6: the report says why (decision block, ρ captions, titles, paper checks).

The design result is tests/data/design_small.json: ``gyroarray design --recommend --arw 0.1
--rrw 600 --rate-hz 100 --horizon-s 600 --swing 5,0.03 --n 4,6 --failures 1
--rho-range=-0.1,0.5 --estimators gls,kf_array --check 4`` (per_rho dropped, 8 designs kept).
"""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from gyroarray.core.data import data_path
from gyroarray.design.evidence import mirror_comparison, what_would_change
from gyroarray.reports.decision import decision_block, equivalence_rows, pct, write_sections
from gyroarray.reports.design_plots import array_fig, design_fig, title_overlaps
from gyroarray.reports.report import Doc

DATA = Path(__file__).parent / "data" / "design_small.json"


@pytest.fixture(scope="module")
def res() -> dict:
    return json.loads(DATA.read_text(encoding="utf-8"))


def _md(res: dict, fn=decision_block) -> str:
    doc = Doc("t")
    fn(doc, res)
    return "\n".join(doc.md)


def test_decision_block_says_what_to_build_and_why(res):
    md = _md(res)
    # the array with its mounting sense, in words, from the JSON
    assert ("Mounting: gyro 1 on +z; gyros 2–6 on the cone at 115.10° from +z; gyros 5, 6 "
            "mounted reversed (axis negated).") in md
    # the design rho of the estimator and the objective
    assert "its weights built once for the design ρ = 0.06214 (chosen min-max over the ρ range)" in md
    assert "Objective: angle (the 3-axis angle error at the horizon), ranked by its worst case over ρ in [-0.1, 0.5]" in md
    # the worst case (rho, failed gyro) with its accuracy (rate and angle)
    assert ("Worst case: at ρ = -0.1 with gyro 1 failed: 0.07189 deg/s 3-axis RMS about the truth, "
            "34.08 deg angle error at the horizon (600 s).") in md
    # the runner-up's worst case
    assert "its worst case at ρ = 0.5 with gyro 6 failed: 0.07274 deg/s" in md
    # what would change the choice (from the JSON)
    assert "What would change the choice:" in md and "* fewer gyros" in md
    # the error budget as a table, at its rho, the largest term marked
    assert "Error budget of the recommendation at ρ = -0.1, gyro 1 failed (its worst case)" in md
    assert "| rrw | 0.06969 | 34.08 | largest RMS / largest angle |" in md
    assert "| arw | 0.01552 | 0.05927 |  |" in md
    # why the mounting (reversed gyros): design against its mirror, the mirror from the check
    assert "Why this mounting:" in md
    assert "0.07189 deg/s 3-axis RMS (ρ = -0.1, gyro 1 failed) against 0.09685 deg/s for its mounting mirror" in md


def test_alpha_above_90_says_the_axial_gyro_argument_with_numbers(res):
    r = copy.deepcopy(res)
    rec = r["recommended"]
    rec.update(alpha_deg=119.21, n=8, mounting_signs=[1] * 8, design_rho=0.5, mounting="gyro 1 on +z")
    r["check"] = None                               # no mirror in the JSON: evidence.py computes it
    md = _md(r)
    assert "α = 119.21° > 90° is the 60.79° cone with its axial gyro mounted reversed (on −z)" in md
    assert "moves the common-mode noise into the parity space" in md
    mc = mirror_comparison(rec, (-0.1, 0.5), 1)
    assert f"{mc['design']['gdop']:.4g}" in md and f"{mc['mirror']['gdop']:.4g}" in md
    assert "for its mirror (α = 60.79°, every gyro +" in md


def test_mirror_comparison_is_the_fixed_weight_gdop(res):
    rec = res["recommended"]
    mc = mirror_comparison(rec, rec["rho_range"], 1)
    # the design's own worst white-noise GDOP after 1 failure is recommend()'s number
    assert mc["design"]["gdop"] == pytest.approx(rec["worst_gdop_after_failures"], rel=1e-6)
    assert mc["ratio"] > 1.2                        # the reversed gyros pay off under correlation
    # at rho = 0 alone the mirror is the same array up to signs: identical
    same = mirror_comparison(dict(rec, design_rho=0.0), (0.0, 0.0), 0)
    assert same["ratio"] == pytest.approx(1.0, rel=1e-9)


def test_what_would_change_from_the_designs_when_the_json_has_none(res):
    r = dict(res, what_changes_the_choice=None)
    lines = what_would_change(r)
    assert lines[0].startswith("the runner-up (scheme 1, N = 6") and "1.19 % worse" in lines[0]
    assert any(s.startswith("fewer gyros: the best N = 4 design") for s in lines)
    md = _md(r)
    assert "1.19 % worse in the worst case" in md


def test_tables_say_their_rho(res):
    md = _md(res, lambda doc, x: write_sections(doc, x))
    head = next(line for line in md.splitlines() if line.startswith("| rank |"))
    assert "| worst at ρ | worst: failed |" in head and "| at ρ |" in head
    assert "| design | at (true ρ, failures) |" in md
    assert "mounting mirror: scheme 2, N = 6, alpha = 115.10 deg, kf_array (15 Hz) | ρ = 0.5, gyro 1 failed" in md
    ft = next(line for line in md.splitlines() if line.startswith("| scheme | N | α [deg] | reversed | at ρ |"))
    assert ft


def test_equivalence_wording_and_reasons(res):
    assert pct(0.009987) == "0.9987 %"
    assert pct(0.01) == "1 %"
    r = copy.deepcopy(res)
    # a group as recommend() of this session's start wrote it (S1 N = 8 merged with S2 N = 6 in
    # the demo): reasons that do not apply, and a spread printed as "1 % (< 1 %)"
    r["equivalent"] = [{"members": [5, 6, 7, 8], "spread": -0.000117, "reason": (
        "identical by theory: the Kalman filters are the low-passed least squares times their DC "
        "gain q_ω/(q_ω + q_b), which is close to 1 at this bandwidth; both schemes reach the "
        "isotropic optimum HᵀC⁻¹H ∝ I at their own cone angle, so their GDOP (and every "
        "prediction) is the same; the predictions differ by 1 % (< 1 %), less than any run "
        "would resolve: choose by cost, mounting or fault tolerance")}]
    rows = {tuple(x["members"]): x for x in equivalence_rows(r)}
    row = rows[(5, 6, 7, 8)]
    # S1 N=4 and S2 N=4 [gyro 4 reversed] have different GDOPs: the isotropic reason is dropped
    assert "isotropic" not in row["reason"] and any("isotropic" in d for d in row["dropped"])
    assert "(< 1 %)" not in row["reason"] and "differ by 1 %" not in row["reason"]
    assert "their worst cases differ by 0.1641 %" in row["reason"]
    md = _md(r, lambda doc, x: write_sections(doc, x))
    assert "(< 1 %)" not in md and "identical by theory" not in md


def test_gdop_figure_titles_do_not_overlap():
    assert title_overlaps(design_fig()) == []


def test_array_figure_is_the_array_as_mounted(res):
    rec = res["recommended"]
    fig = array_fig(rec["axes"], "t", rec["mounting_signs"])
    ax = fig.axes[0]
    arrows = ax.collections
    assert len(arrows) == rec["n"]
    red = [c for c in arrows if np.allclose(c.get_color()[0][:3], (0.839, 0.153, 0.157), atol=1e-2)]
    assert len(red) == sum(s < 0 for s in rec["mounting_signs"]) == 2
    # the arrow tips point along the mounted axes (signs included), not the mirror's
    for c, v in zip(arrows, rec["axes"]):
        seg = np.asarray(c._segments3d[0])
        tip = seg[np.argmax(np.linalg.norm(seg, axis=1))]   # the end away from the origin
        assert np.allclose(tip / np.linalg.norm(tip), v, atol=1e-6)


def test_paper_checks_withdrawn_and_replaced():
    from gyroarray.chain.hypotheses import METRICS, check_entry
    f = Path(str(data_path("scenarios"))) / "paper_values.toml"
    doc = tomllib.loads(f.read_text(encoding="utf-8"))
    checks = [(e, c) for e in doc["experiment"] for c in e.get("check", [])]
    names = {c["name"] for _, c in checks}
    for gone in ("p003_t3_0_low_bandwidth", "p003_t4_0_low_bandwidth", "p003_t8_narrow_kf",
                 "p003_t9_per_axis_q_omega", "p002_t4_0p1_kf_20hz"):
        assert gone not in names
    text = " ".join(c["hypothesis"] for _, c in checks)
    assert "0.5 % high" not in text and "0.64" not in text and "chosen by the predictor" not in text
    # no check is decided by an Allan ARW/RRW fit of a low-passed output (that fit returns 0)
    for _, c in checks:
        bw = c.get("estimator_params", {}).get("bandwidth_hz")
        metrics = {v["metric"] for v in c["values"]}
        assert not (bw is not None and bw < 5 and metrics & {"arw_deg_rt_h", "rrw_deg_h_rt_h"})
    # paper 002's constant gain of about 0.9 is what is tested now
    gain = [c for _, c in checks if c["name"].endswith("constant_gain")]
    assert len(gain) == 2 and "estimator_amplitude_ratio" in METRICS
    assert {round(c["values"][0]["value"], 4) for c in gain} == {0.8953, 0.8992}
    for j, c in enumerate(gain):
        check_entry(c, f"check[{j}]", str(f))


def test_the_report_states_the_frame_the_flicker_model_and_the_mdb_window(res):
    """Issue 43: what the design rests on is in the report as in the text output: the
    common-mode frame with the other frame's decision, the flicker model, and the MDB as stated
    (window, threshold, rho grid, tied gyros)."""
    r = copy.deepcopy(res)
    rec = r["recommended"]
    rec["mdb_statement"] = ("minimum detectable bias step 0.03686 deg/s, worst over ρ in [-0.1, 0.5] "
                            "(largest at ρ = 0.035, 41-point grid), a tie of gyros 1, 2 (equal within "
                            "0.001): the parity detector's step test over a 0.2 s window")
    r["assumptions"]["common_mode"] = {"value": "output", "source": "default",
                                       "unit": "the correlation is between the gyros' outputs"}
    r["assumptions"]["flicker_model"] = {"value": "circular", "unit": "circular flicker: stated"}
    r["common_mode"] = {"chosen": "output", "frames": {
        "output": {"statement": "output frame: 27.92 deg worst"},
        "axis": {"statement": "axis frame: 34.96 deg as built, 30.78 deg at its best"}}}
    md = _md(r)
    assert "Detection: minimum detectable bias step 0.03686 deg/s" in md and "0.2 s window" in md
    assert "a tie of gyros 1, 2" in md
    assert "Common mode: the output frame (default): the correlation is between the gyros' outputs." in md
    assert "axis frame: 34.96 deg as built, 30.78 deg at its best" in md
    assert "Flicker model: circular flicker: stated." in md
    del rec["mdb_statement"]
    rec.update(mdb_deg_s=0.05, mdb_worst_gyros=[3, 4])
    assert "worst gyros (tied): 3, 4" in _md(r)
