"""Issue 44 item 5: ``ladder --holdout``'s structure verdict names the candidate that lowers the
held-out D most, with the D values, not the fitted part's top candidate.

The record is built so that the two differ, and the truth is known: a static 3-gyro simulator
record (:func:`gyroarray.sim.lab.lab_run`, fixed seed) with a 2.7 Hz line on gyro 2 over the
whole record, and (added in numpy) a stronger 1.3 Hz line on gyro 1 in the first half only.
On the fitted (first) half gyro 1's line is the top candidate; the held-out half has no such
line (a model with it predicts a line that is not there), and what it lacks is gyro 2's line.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gyroarray.chain.compare import ModelComparison, holdout_candidates, split_measurement
from gyroarray.core.layout import Layout
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.sim.lab import lab_run

L3 = Layout.conical(1, 3, math.radians(54.7356))
BASE = (ModelEntry("arw", None, {"n_deg_rt_h": 0.3}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}))
ADIS = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "adis16405_static.csv.gz"


@pytest.fixture(scope="module")
def halves():
    model = NoiseModel(BASE + (ModelEntry("sinusoid", 2, {"amp_deg_s": 0.02, "freq_hz": 2.7, "phase_deg": 0.0}),))
    m = lab_run(model, L3, np.random.default_rng(7), static_s=400.0, motion_s=0.0, tail_s=0.0, rate_hz=20.0,
                temperature=False)
    t = m.time_s - m.time_s[0]
    y = np.array(m.gyro_deg_s, copy=True)
    y[t < 200.0, 0] += 0.05 * np.sin(2 * math.pi * 1.3 * t[t < 200.0])     # gyro 1's line: first half only
    return split_measurement(replace(m, gyro_deg_s=y), 0.5)


@pytest.mark.slow   # whole analyses of a ladder step (5 s idle, 10-14 s under load): make score
def test_the_verdict_names_what_lowers_the_held_out_d_not_the_top_candidate(halves):
    first, rest = halves
    comp = ModelComparison(first, n_runs=5)
    final = comp.analyse()
    top = [(t.effect, t.gyro) for t in final.candidates if final.significant(t)]
    assert top[0] == ("sinusoid", 1) and ("sinusoid", 2) in top, top
    va = ModelComparison(rest, NoiseModel(final.model.entries, description="the fitted half"), n_runs=5).validate()
    assert not va.consistent
    rows = holdout_candidates(comp, final, rest, held_out=va)
    by = {(r["effect"], r["gyro"]): r for r in rows}
    assert rows[0]["effect"] == "sinusoid" and rows[0]["gyro"] == 2, rows
    # gyro 2's line lowers the held-out D; gyro 1's does not (it predicts a line that is not there)
    assert by[("sinusoid", 2)]["holdout_discrepancy"] < va.discrepancy
    assert by[("sinusoid", 1)]["holdout_discrepancy"] > by[("sinusoid", 2)]["holdout_discrepancy"]
    # ... while on the fitted half gyro 1's line is the larger fall
    assert by[("sinusoid", 1)]["fitted_discrepancy"] < by[("sinusoid", 2)]["fitted_discrepancy"]
    ds = [r["holdout_discrepancy"] for r in rows if math.isfinite(r["holdout_discrepancy"])]
    assert ds == sorted(ds)


@pytest.mark.slow   # a 1-step ladder, its held-out validation and two candidates held out (10-20 s)
def test_the_cli_verdict_says_it_with_the_d_values(tmp_path):
    """``ladder --holdout 0.5 --max-steps 1 --json``: gyro 1's line (0.08 deg/s, the whole record)
    is the step; of what the fitted half still shows, gyro 3's line (0.04 deg/s, first half only)
    ranks above gyro 2's (0.02 deg/s, the whole record), which the old verdict listed first.
    The held-out D names gyro 2's line, with each candidate's D in the text and the JSON."""
    from gyroarray.core.measurement import write_measurement
    from hostile import run_cli
    model = NoiseModel(BASE + (ModelEntry("sinusoid", 1, {"amp_deg_s": 0.08, "freq_hz": 1.3, "phase_deg": 0.0}),
                               ModelEntry("sinusoid", 2, {"amp_deg_s": 0.02, "freq_hz": 2.7, "phase_deg": 0.0})))
    m = lab_run(model, L3, np.random.default_rng(8), static_s=400.0, motion_s=0.0, tail_s=0.0, rate_hz=20.0,
                temperature=False, description="three lines")
    t = m.time_s - m.time_s[0]
    y = np.array(m.gyro_deg_s, copy=True)
    y[t < 200.0, 2] += 0.04 * np.sin(2 * math.pi * 3.7 * t[t < 200.0])     # gyro 3's line: first half only
    path = tmp_path / "lines.csv"
    write_measurement(replace(m, gyro_deg_s=y, source="lines"), path)
    out = run_cli(["ladder", path, "--holdout", "0.5", "--max-steps", "1", "--runs", "5", "--json",
                   "--out", tmp_path / "r.html"], timeout=600.0)
    assert out.code == 0, out.err[-2000:]
    res = json.loads(out.out)
    assert [s["added"] for s in res["steps"][1:]] == [{"effect": "sinusoid", "gyro": 1}]
    h = res["holdout"]
    assert h["missing_terms"][:2] == ["sinusoid:3", "sinusoid:2"], h["missing_terms"]
    assert h["best_candidate"] == {"effect": "sinusoid", "gyro": 2}, h["by_candidate"]
    by = {(r["effect"], r["gyro"]): r for r in h["by_candidate"]}
    assert by[("sinusoid", 2)]["holdout_discrepancy"] < h["discrepancy"]
    assert by[("sinusoid", 3)]["holdout_discrepancy"] > by[("sinusoid", 2)]["holdout_discrepancy"]
    assert "the term it lacks is sinusoid:2" in h["structure"]
    assert f"-> {by[('sinusoid', 2)]['holdout_discrepancy']:.3g}" in h["structure"]


@pytest.mark.slow   # the ADIS16405 ladder on half the record and every candidate held out (minutes)
def test_on_the_adis_record_the_verdict_is_the_lowest_held_out_d(tmp_path):
    """The issue's case: ``ladder --holdout 0.5`` named correlation (its fitted half's top
    candidate), not the bias instability it also listed. Now it names the candidate whose
    held-out D is lowest of those it tried (each one fitted in on the fitted half and validated
    on the other: the D's are in the JSON and the text)."""
    if not ADIS.exists():
        pytest.skip("../shared/measurements not here")
    from hostile import run_cli
    out = run_cli(["ladder", ADIS, "--holdout", "0.5", "--json", "--out", tmp_path / "r.html"], timeout=3600.0)
    assert out.code == 0, out.err[-2000:]
    h = json.loads(out.out)["holdout"]
    rows = [r for r in h["by_candidate"] if r["holdout_discrepancy"] is not None
            and math.isfinite(r["holdout_discrepancy"])]
    if h["consistent"]:
        assert rows == []
        return
    assert rows, h
    lowest = min(rows, key=lambda r: r["holdout_discrepancy"])
    if lowest["holdout_discrepancy"] < h["discrepancy"]:
        assert h["best_candidate"] == {"effect": lowest["effect"], "gyro": lowest["gyro"]}
        name = lowest["effect"] if lowest["gyro"] is None else f"{lowest['effect']}:{lowest['gyro']}"
        assert f"the term it lacks is {name}" in h["structure"]
    else:
        assert h["best_candidate"] is None and "no candidate lowers the held-out D" in h["structure"]
