"""Issue 43 item 9: the design report's defects, each with a test that failed before its fix.

``ranged``: ``gyroarray design --recommend --arw 0.1 --rrw 600 --rate-hz 100 --horizon-s 600
--swing 5,0.03 --n 8 --failures 1 --rho-range=-0.1,0.5 --estimators gls`` (the demo's question on
its winning N and its GLS, ~4 s), run in this process. The demo recommends gyros 2, 4, 6, 8
reversed; reversing pays only at ρ > 0, so at ρ = −0.1 the un-reversed array (its mounting
mirror) is the better build: the issue measured 0.0484 against 0.0555 deg/s.
``small``: tests/data/design_small.json (a result with a Monte-Carlo check that simulated the
recommendation and its mounting mirror, both scheme 2, N = 6, α = 115.10°, kf_array).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

from gyroarray.analysis.adev_curves import AdevFigure
from gyroarray.reports.decision import (adev_fig, best_at_rho, motion_words, rho_candidates,
                                        robustness_rows, write_sections)
from gyroarray.reports.design_plots import accuracy_vs_n_fig, design_fig, recommended_gdop_line
from gyroarray.reports.report import WITHDRAWN_CHECKS, Doc, _section_paper, withdrawn_reason

SMALL = Path(__file__).parent / "data" / "design_small.json"


@pytest.fixture(scope="module")
def ranged(tmp_path_factory) -> dict:
    from gyroarray.cli.main import main
    out = tmp_path_factory.mktemp("ranged") / "design.json"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = main(["design", "--recommend", "--arw", "0.1", "--rrw", "600", "--rate-hz", "100",
                     "--horizon-s", "600", "--swing", "5,0.03", "--n", "8", "--failures", "1",
                     "--rho-range=-0.1,0.5", "--estimators", "gls", "--out", str(out), "--force"])
    assert code in (0, None)
    return json.loads(out.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def cands(ranged) -> dict:
    return rho_candidates(ranged)


@pytest.fixture(scope="module")
def small() -> dict:
    res = json.loads(SMALL.read_text(encoding="utf-8"))
    # its per_rho was dropped from the file: rebuilt as recommend() writes it (the designs as
    # decided, ranked by their intact 3-axis RMS at each ρ)
    res["per_rho"] = {f"{r:g}": sorted(({**d, "rms_3axis_deg_s": d["rms_by_rho"][f"{r:g}"], "rho": r}
                                        for d in res["designs"]), key=lambda d: d["rms_3axis_deg_s"])
                      for r in res["assumptions"]["rho"]["value"]}
    return res


def _md(res: dict) -> str:
    doc = Doc("t")
    write_sections(doc, res)
    return "\n".join(doc.md)


def _table(md: str, head: str) -> list[list[str]]:
    """The body rows of the Markdown table whose header line starts with ``head``."""
    lines = md.splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith(head))
    rows = []
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip("|").split("|")])
    return rows


def _independent_rms(d: dict, res: dict, rho_t: float) -> float:
    """3-axis RMS [deg/s] of design d intact at the true ρ, its estimator built for its design ρ,
    by the predictor called directly at that ρ (no interpolation in ρ)."""
    from gyroarray.core import units
    from gyroarray.core.layout import Layout
    from gyroarray.design.evidence import noise_and_space
    from gyroarray.design.predict import predict
    from gyroarray.design.recommend import estimator_kwargs
    from gyroarray.design.robust import mounted_axes
    from gyroarray.estimators import get_estimator
    g, space = noise_and_space(res["assumptions"])
    H = mounted_axes(d["scheme"], d["n"], np.array([math.radians(d["alpha_deg"])]),
                     np.asarray(d["mounting_signs"], dtype=float))[0]
    est = get_estimator(d["estimator"])(**estimator_kwargs(d["estimator"], d["bandwidth_hz"], g))
    est.fit(Layout(H), g.with_rho(d["design_rho"]).noise_model(d["n"]), space.dt_s)
    p = predict(est, g.with_rho(rho_t).noise_model(d["n"]), n_samples=space.n_samples,
                settle_s=space.settle_s, swing=space.swing)
    return float(units.rad_s_to_deg_s(math.sqrt(sum(units.deg_s_to_rad_s(v["rms_deg_s"]) ** 2
                                                    for v in p.axes.values()))))


# -- "Best design at that ρ" is the argmin of the scored candidates -------------------

@pytest.mark.slow       # the module's 4 s decision + the mirrors' predictions
def test_best_at_rho_is_the_minimum_over_the_candidates(ranged, cands):
    # the mirrors were scored: the predictor set up from the assumptions reproduces the
    # decision's own per-ρ scores of the recommendation (to REPRODUCE_RTOL = 1e-6)
    assert cands["mirror_note"] is None
    assert any(c["source"].startswith("mounting mirror") for c in cands["candidates"])
    md = _md(ranged)
    rows = _table(md, "| assumed ρ | best design at that ρ |")
    assert [r[0] for r in rows] == list(ranged["per_rho"])
    for r in rows:
        lowest = min(c["rms_by_rho"][r[0]] for c in cands["candidates"])
        # the table prints 4 significant digits: equal to that rounding
        assert float(r[3]) == pytest.approx(lowest, rel=5e-4)
        # no design the decision scored is better at that ρ than the one printed
        for d in ranged["designs"]:
            assert d["rms_by_rho"][r[0]] >= lowest * (1 - 1e-12)
    # at ρ = -0.1 the best is the un-reversed array, 0.0484 deg/s (the number, 3 digits),
    # below every design of the result (the old table's best, ~0.0555 here): reversal costs at ρ < 0
    b = best_at_rho(cands, "-0.1")
    assert all(s > 0 for s in b["mounting_signs"])
    assert b["rms_by_rho"]["-0.1"] == pytest.approx(0.0484, abs=5e-5)
    assert b["rms_by_rho"]["-0.1"] < 0.9 * min(d["rms_by_rho"]["-0.1"] for d in ranged["designs"])
    assert rows[0][1] == "scheme 1, N = 8, alpha = 54.74 deg, gls (17 Hz)"
    # at ρ = 0.5 reversal pays: the recommendation's pattern is best there (0.0378 against the
    # mirror's 0.0714 deg/s, the numbers)
    top = best_at_rho(cands, "0.5")
    assert top["mounting_signs"] == ranged["recommended"]["mounting_signs"]
    assert top["rms_by_rho"]["0.5"] == pytest.approx(0.0378, abs=5e-5)
    mirror = next(c for c in cands["candidates"] if all(s > 0 for s in c["mounting_signs"]))
    assert mirror["rms_by_rho"]["0.5"] == pytest.approx(0.0714, abs=5e-5)


@pytest.mark.slow       # the module's 4 s decision + the mirrors' predictions
def test_mirror_scores_are_the_predictor_at_each_rho(ranged, cands):
    # the mirrors are interpolated linearly in ρ between the range's ends (a fixed estimator's
    # error variance is linear in the true ρ): the predictor called directly at interior ρ
    # gives the same to rounding (1e-9 relative: two evaluations of one linear function)
    mirror = next(c for c in cands["candidates"] if c["source"].startswith("mounting mirror"))
    for r in ("0", "0.2", "0.35"):
        assert mirror["rms_by_rho"][r] == pytest.approx(_independent_rms(mirror, ranged, float(r)), rel=1e-9)
    # and the same computation reproduces the decision's own score of its recommendation
    rec = ranged["recommended"]
    assert _independent_rms(rec, ranged, 0.2) == pytest.approx(rec["rms_by_rho"]["0.2"], rel=1e-9)


# -- the Robustness table has rows ------------------------------------------------------

@pytest.mark.slow       # the module's 4 s decision + the mirrors' predictions
def test_robustness_table_is_filled(ranged, cands):
    md = _md(ranged)
    rows = _table(md, "| chosen for ρ̂ | design |")
    rob = robustness_rows(cands, ranged["recommended"])
    assert len(rows) == len(rob) >= 2          # before: the header only
    # every ρ̂ of the grid is named once, plus the min-max recommendation
    named = [x for r in rows[:-1] for x in r[0].split(", ")]
    assert sorted(named, key=float) == sorted(ranged["per_rho"], key=float)
    assert rows[-1][0] == "min-max (the recommendation)"
    # each cell: the design's score at that ρ and its excess over that ρ's best, +0.0 % on
    # the diagonal; the recommendation pays ~14.6 % at ρ = -0.1 (0.0555 / 0.0484 - 1)
    rhos = list(ranged["per_rho"])
    for x in rob:
        for r in (x["chosen_for"] if isinstance(x["chosen_for"], list) else []):
            assert x["at"][r][1] == pytest.approx(0.0, abs=1e-12)
    rec_row = rob[-1]
    assert rec_row["at"]["-0.1"][1] == pytest.approx(0.0555 / 0.0484 - 1.0, abs=0.01)
    assert rows[-1][2 + rhos.index("-0.1")].endswith("(+14.6 %)")


def test_robustness_table_has_rows_fast(small):
    md = _md(small)
    rows = _table(md, "| chosen for ρ̂ | design |")
    assert rows                                 # before: the header only (the result has no 'robustness')
    assert rows[-1][0] == "min-max (the recommendation)"
    rc = rho_candidates(small)
    # this file is of an older version: its own scores are not reproduced (1.3e-3), so the
    # mirrors are left out and the report says why
    assert rc["mirror_note"] is not None and "left out" in md
    for r, row in zip(small["per_rho"], _table(md, "| assumed ρ | best design at that ρ |")):
        assert float(row[3]) == pytest.approx(min(d["rms_by_rho"][r] for d in small["designs"]), rel=5e-4)


# -- the accuracy-vs-N figure: one condition, distinct labels ---------------------------

def test_accuracy_vs_n_one_condition_and_unique_labels(small):
    fig = accuracy_vs_n_fig(small)
    ax = fig.axes[0]
    labels = ax.get_legend_handles_labels()[1]
    assert len(labels) == len(set(labels))     # before: the two simulated scheme 2 entries were equal
    sim = [s for s in labels if s.startswith("simulated")]
    assert len(sim) == sum(c["rms_3axis_deg_s"]["monte_carlo"]["ci_low"] is not None
                           for c in small["check"]["designs"]) >= 2
    assert any("mounting mirror" in s for s in sim) and any("at ρ = 0.5, gyro 1 failed" in s for s in sim)
    # every drawn prediction is a worst case over the range × failures: the markers' y values
    # are the designs' worst_case RMS (before: the intact RMS at each design's own ρ)
    worst = {round(d["worst_case"]["rms_3axis_deg_s"], 12) for d in small["designs"]}
    intact = {round(d["rms_3axis_deg_s"], 12) for d in small["designs"]} - worst
    ys = {round(float(y), 12) for line in ax.lines for y in np.atleast_1d(line.get_ydata())
          if np.isfinite(y)}
    sim_y = {round(c["rms_3axis_deg_s"]["monte_carlo"][k], 12) for c in small["check"]["designs"]
             for k in ("value", "ci_low", "ci_high")}           # the error bars' markers and caps
    pred = ys - sim_y
    assert pred and pred <= worst and not (pred & intact)


# -- the GDOP-vs-ρ figure draws the array as mounted --------------------------------------

def test_recommended_gdop_line_is_the_reversed_array(small):
    rec = small["recommended"]
    r, g, label = recommended_gdop_line(rec, 41)
    assert label == "recommended, as mounted: N = 6, α = 115.10°, gyros 5, 6 reversed"
    # the GLS GDOP √trace((HᵀC⁻¹H)⁻¹) of the mounted axes (gyros 5, 6 negated), in numpy, at
    # every ρ of the line; the un-reversed cone's differs by > 10 % at ρ ≈ 0.5 (22 % here)
    H = np.asarray(rec["axes"], float)
    un = H * np.asarray(rec["mounting_signs"], float)[:, None]       # every gyro + (the paper's cone)
    assert np.sum(np.any(H != un, axis=1)) == 2

    def gd(A, rho):
        C = (1 - rho) * np.eye(6) + rho * np.ones((6, 6))
        return math.sqrt(np.trace(np.linalg.inv(A.T @ np.linalg.solve(C, A))))
    assert g == pytest.approx([gd(H, x) for x in r], rel=1e-9)
    k = int(np.argmin(abs(r - 0.5)))
    assert abs(g[k] / gd(un, r[k]) - 1.0) > 0.1


@pytest.mark.slow       # design_fig draws 6 panels of optimal-α searches (~5 s on a shared core)
def test_gdop_figure_draws_the_recommended_array_as_mounted(small):
    rec = small["recommended"]
    fig = design_fig(rec)
    panel = fig.axes[4]                         # row 2, scheme 2: GDOP vs ρ
    labels = panel.get_legend_handles_labels()[1]
    mine = [s for s in labels if s.startswith("recommended, as mounted")]
    assert mine == ["recommended, as mounted: N = 6, α = 115.10°, gyros 5, 6 reversed"]
    assert not any(s.startswith("recommended") for s in fig.axes[3].get_legend_handles_labels()[1])
    line = next(ln for ln in panel.lines if ln.get_label() == mine[0])
    r, g, _ = recommended_gdop_line(rec)
    assert np.array_equal(line.get_xdata(), r) and np.array_equal(line.get_ydata(), g)
    # the paper's lines say their mounting
    assert all(s.endswith("every gyro +") for s in labels if s != mine[0])


# -- the motion in words -------------------------------------------------------------------

def test_motion_is_described_as_simulated(small):
    from gyroarray.design.predict import Swing, swing_truth
    md = _md(small)
    row = next(line for line in md.splitlines() if line.startswith("| motion |"))
    assert "in turn" not in row and "about x, y and z at once" in row
    # what the check and the ADEV record simulate: the same rate on every axis at once
    w = swing_truth(Swing(math.radians(5.0), 0.03), 2000, 0.01)
    assert np.array_equal(w[:, 0], w[:, 1]) and np.array_equal(w[:, 1], w[:, 2]) and np.abs(w).max() > 0
    assert "8.66 deg/s" in motion_words(small["assumptions"]["motion"]["value"])   # √3 × 5


# -- the ADEV title fits ------------------------------------------------------------------

def test_adev_title_inside_the_figure(small):
    from gyroarray.analysis.adev_curves import AdevCurve
    taus = np.logspace(-2, 2, 9)
    ones = np.full_like(taus, 1e-4)

    def curve(label):
        return AdevCurve(label=label, taus_s=taus, adev_rad_s=ones, ci_low_rad_s=0.9 * ones,
                         ci_high_rad_s=1.1 * ones, arw_fit_deg_rt_h=0.1)
    a = AdevFigure(title="t", estimator="gls", n_gyros=8, dt_s=0.01, record_s=600.0,
                   curves=[curve(f"gyro {k + 1}") for k in range(8)] + [curve(f"fused {x}") for x in "xyz"],
                   seed=1, rho=-0.0836, predicted_arw_long_deg_rt_h=[0.06] * 3)
    fig, _ = adev_fig(small, a)
    fig.canvas.draw()
    box = fig.axes[0].title.get_window_extent(fig.canvas.get_renderer())
    W, Hh = fig.canvas.get_width_height()
    # before: one line of ~95 characters, wider than the 8.5-inch figure (clipped both sides)
    assert box.x0 >= 0 and box.x1 <= W and box.y1 <= Hh


# -- paper 002's constant-gain checks are withdrawn, with the reason -------------------------

def test_constant_gain_checks_withdrawn_with_reason():
    assert set(WITHDRAWN_CHECKS) == {"p002_t4_0p1_constant_gain", "p002_t4_0p5_constant_gain"}
    why = withdrawn_reason({"name": "p002_t4_0p1_constant_gain"})
    assert why.startswith("withdrawn") and "+12 %" in why and "only reject" in why
    assert withdrawn_reason({"name": "p003_t3_kf"}) is None
    assert withdrawn_reason({"name": "x", "withdrawn": "no model"}) == "withdrawn: no model"

    class Res:                                   # a ReportResults with one paper experiment
        paper = [object()]
        paper_vs_model = [{"title": "Paper 002 Table 4", "scenario": "s", "estimator": "kf_single",
                           "runs": 20, "flagged": True,
                           "values": [{"axis": "z", "metric": "attenuation", "paper": 1.0, "model_mean": 1.0,
                                       "model_sd": 0.0, "model_min": 1.0, "model_max": 1.0, "low": 1.0,
                                       "high": 1.0, "ratio": 1.0, "flag": True}],
                           "checks": [{"name": "p002_t4_0p1_constant_gain", "hypothesis": "h"}],
                           "check_results": ["never shown"]}]
    doc = Doc("t")
    _section_paper(doc, Res())
    md = "\n".join(doc.md)
    assert "Check p002_t4_0p1_constant_gain: withdrawn: this check can only reject" in md
    assert "Result: it" not in md and "never shown" not in md
    assert "its check is withdrawn" in md
