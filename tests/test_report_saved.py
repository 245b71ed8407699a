"""A report of saved results re-renders without simulating (issue 29: results in, pictures out).

The first ``gyroarray report`` computes what needs a simulation (the named
hypothesis checks, the ADEV of the best static design and of the recommended
design) and saves it beside the inputs (``hypotheses.json`` and ``adev.json`` in
the sweep folders, ``<design stem>.adev.json``). A second report of the same
inputs reads them: every simulation and chain entry point is replaced by one
that raises, and the report still renders, with the same tables. A changed input
or a damaged file is recomputed (it reaches the raising entry points), never
read stale.
"""

from __future__ import annotations

import json
import os
import sys

import pytest

from gyroarray.analysis.adev_curves import AdevFigure
from gyroarray.chain.hypotheses import CHECKS_FILE, HypothesisCheck
from gyroarray.design.evidence import adev_file
from gyroarray.reports.report import render_report, write_report
from gyroarray.sweep.adev import ADEV_FILE
from gyroarray.sweep.report_results import collect_report_results
from gyroarray.sweep.runner import run_sweep
from hostile import run_cli

SCENARIO = """\
name = "tiny_static"
sample_rate_hz = 50.0
seed = 1
duration_s = 20.0
effects = [{ effect = "arw", n_deg_rt_h = 0.1 }, { effect = "rrw", k_deg_h_rt_h = 600.0 }]
[layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356
[motion]
profile = "p003_static_1h"
"""

DESIGN = """\
name = "tiny_design"
seed = 5
estimators = ["gls"]
base = "tiny_static"
[grid]
n_gyros = [4, 5]
"""

PAPER = """\
name = "tiny_paper"
seed = 6
replicates = 2
estimators = ["gls"]
scenarios = ["tiny_static"]
"""

VALUES = """\
[[experiment]]
title = "Tiny table"
scenario = "tiny_static"
estimator = "gls"
values = [{{ axis = "x", metric = "sigma_1_deg_s", value = 0.01 }}]
[[experiment.check]]
name = "tiny_ten_times_noisier"
hypothesis = "{hypothesis}"
effects = [{{ effect = "arw", n_deg_rt_h = 1.0 }}]
values = [{{ axis = "x", metric = "sigma_1_deg_s", value = 0.01 }}]
"""

#: Every entry point that simulates, runs the chain or computes a report's curves.
ENTRY_POINTS = ("simulate", "simulate_readings", "run_replicates", "run_scenario", "run_one",
                "run_sweep", "scenario_adev", "recommended_adev", "single_vs_fused",
                "allan_analysis", "recommend", "monte_carlo_check", "get_estimator")


class Simulated(AssertionError):
    """A simulation or chain entry point was called."""


def no_simulation(monkeypatch) -> list[str]:
    """Replace every entry point of every loaded gyroarray module by one that raises."""
    patched = []
    for name, mod in list(sys.modules.items()):
        if not (name == "gyroarray" or name.startswith("gyroarray.")) or mod is None:
            continue
        for attr in ENTRY_POINTS:
            if callable(getattr(mod, attr, None)):
                def boom(*args, _what=f"{name}.{attr}", **kw):
                    raise Simulated(f"{_what} called while rendering saved results")
                monkeypatch.setattr(mod, attr, boom)
                patched.append(f"{name}.{attr}")
    return patched


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    root = tmp_path_factory.mktemp("saved")
    old = os.environ.get("GYROARRAY_CACHE")
    os.environ["GYROARRAY_CACHE"] = str(root / "cache")
    try:
        (root / "tiny_static.toml").write_text(SCENARIO)
        (root / "design.toml").write_text(DESIGN)
        (root / "paper.toml").write_text(PAPER)
        (root / "values.toml").write_text(VALUES.format(hypothesis="The gyros were ten times noisier."))
        run_sweep(root / "design.toml", root / "design_out", workers=1, progress=False)
        run_sweep(root / "paper.toml", root / "paper_out", workers=1, progress=False)
        o = run_cli(["design", "--recommend", "--arw", "0.15", "--rrw", "1", "--n", "4,5",
                     "--rate-hz", "50", "--horizon-s", "60", "--rho-range=0,0.2",
                     "--estimators", "gls,kf_array", "--out", root / "d.json"], timeout=300)
        assert o.code == 0, o.err
        first = write_report([root / "design_out", root / "paper_out"], root / "first.html",
                             root / "first.md", design=root / "d.json",
                             paper_values=root / "values.toml")
    finally:
        if old is None:
            os.environ.pop("GYROARRAY_CACHE", None)
        else:
            os.environ["GYROARRAY_CACHE"] = old
    return root, first


def _md(path) -> str:
    return path.read_text().split("\n", 1)[1]       # without the subtitle (the time stamp)


@pytest.mark.slow   # the saved design report: its fixture simulates and renders a report (18 s): make score
def test_the_first_report_saves_what_it_simulated(saved):
    root, first = saved
    checks = json.loads((root / "paper_out" / CHECKS_FILE).read_text())
    assert checks["kind"] == "hypotheses" and len(checks["entries"]) == 1
    r = HypothesisCheck.from_dict(next(iter(checks["entries"].values())))
    assert r.name == "tiny_ten_times_noisier" and r.runs == 20 and r.verdict == "does not support"
    assert HypothesisCheck.from_dict(r.to_dict()) == r          # JSON round trip
    best = json.loads((root / "design_out" / ADEV_FILE).read_text())["entries"]
    assert len(best) == 1
    fig = AdevFigure.from_dict(next(iter(best.values())))
    assert fig.n_gyros in (4, 5) and len(fig.singles) == fig.n_gyros and len(fig.fused) == 3
    assert AdevFigure.from_dict(fig.to_dict()).to_dict() == fig.to_dict()
    rec = json.loads(adev_file(root / "d.json").read_text())["entries"]
    assert len(rec) == 1
    assert first["paper_vs_model"][0]["check_results"][0]["verdict"] == "does not support"
    assert first["figures"] >= 6                    # decision figures + adev_recommended + adev_best


@pytest.mark.slow   # the saved design report: its fixture simulates and renders a report (18 s): make score
def test_a_saved_result_renders_without_simulating(saved, tmp_path, monkeypatch):
    root, first = saved
    patched = no_simulation(monkeypatch)
    assert "gyroarray.sim.scenario.simulate" in patched and "gyroarray.chain.run.run_replicates" in patched
    again = write_report([root / "design_out", root / "paper_out"], tmp_path / "again.html",
                         tmp_path / "again.md", design=root / "d.json",
                         paper_values=root / "values.toml")
    assert again["figures"] == first["figures"]
    assert _md(tmp_path / "again.md").replace("again_figures", "first_figures") == _md(root / "first.md")
    assert again["paper_vs_model"] == first["paper_vs_model"]
    # the CLI too, and the render step alone from the collected results
    o = run_cli(["report", root / "design_out", root / "paper_out", "--design", root / "d.json",
                 "--paper-values", root / "values.toml", "--out", tmp_path / "cli.html", "--json"])
    assert o.code == 0, o.err
    res = collect_report_results([root / "paper_out"], paper_values=root / "values.toml")
    assert isinstance(res.paper_vs_model[0]["check_results"][0], HypothesisCheck)
    out = render_report(res, tmp_path / "render.html")
    assert out["paper_vs_model"][0]["check_results"] == first["paper_vs_model"][0]["check_results"]


@pytest.mark.slow   # the saved design report: its fixture simulates and renders a report (18 s): make score
def test_a_changed_input_is_recomputed_not_read_stale(saved, tmp_path, monkeypatch):
    root, _ = saved
    values = root / "changed_values.toml"           # beside the scenario file it names
    values.write_text(VALUES.format(hypothesis="Another hypothesis, the same effects."))
    no_simulation(monkeypatch)
    with pytest.raises(Simulated, match="run_replicates"):
        write_report([root / "paper_out"], tmp_path / "a.html", paper_values=values)
    # a damaged file of saved checks is not trusted either
    copy = tmp_path / "paper_copy"
    copy.mkdir()
    for p in (root / "paper_out").rglob("*"):
        if p.is_file():
            dst = copy / p.relative_to(root / "paper_out")
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.write_bytes(p.read_bytes())
    (copy / CHECKS_FILE).write_text("{ not json")
    with pytest.raises(Simulated, match="run_replicates"):
        write_report([copy], tmp_path / "b.html", paper_values=root / "values.toml")


def _compare_measurement():
    import math
    import numpy as np
    from gyroarray.core.layout import Layout
    from gyroarray.core.measurement import Measurement
    from gyroarray.core.units import deg_s_to_rad_s, rad_s_to_deg_s
    from gyroarray.effects.model import ModelEntry, NoiseModel
    from gyroarray.sim.effects import simulate_readings
    dt = 0.01
    t = np.arange(int(180.0 / dt)) * dt
    w = np.zeros((t.size, 3))
    mv = t >= 90.0
    w[mv, 2] = deg_s_to_rad_s(20.0) * np.sin(2 * math.pi * 0.2 * (t[mv] - 90.0))
    layout = Layout.conical(1, 4, math.radians(54.7356))
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.2}),
                        ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0})))
    y = simulate_readings(model, w, layout, dt, np.random.default_rng(4), time_s=t)
    return Measurement(time_s=t, gyro_deg_s=rad_s_to_deg_s(y), layout=layout, sample_rate_hz=100.0,
                       ref_deg_s=rad_s_to_deg_s(w), description="saved compare figures")


@pytest.mark.slow   # 11 s (a compare analysis and two renders): make score
def test_the_compare_report_renders_saved_figure_data(tmp_path, monkeypatch):
    from gyroarray.chain.compare import ModelComparison
    from gyroarray.chain.compare_figures import CompareFigures, compare_figures
    from gyroarray.reports.compare_report import write_compare_report
    comp = ModelComparison(_compare_measurement(), n_runs=10)
    steps = [(None, comp.analyse())]
    fresh = compare_figures(comp, steps)
    saved = tmp_path / "figures.json"
    saved.write_text(json.dumps(fresh.to_dict(), allow_nan=False))
    first = write_compare_report(comp, steps, tmp_path / "a.html", tmp_path / "a.md", figures=fresh)
    loaded = CompareFigures.from_dict(json.loads(saved.read_text()))
    assert loaded.to_dict() == fresh.to_dict()
    # rendering the saved data computes nothing: the figure computations raise
    for mod in ("gyroarray.chain.compare_figures", "gyroarray.reports.compare_report"):
        for attr in ("compare_figures", "davar", "welch", "record_channels", "fitted_bias", "binned",
                     "log_binned", "Regressors"):
            if hasattr(sys.modules[mod], attr):
                monkeypatch.setattr(sys.modules[mod], attr, _raise)
    again = write_compare_report(comp, steps, tmp_path / "b.html", tmp_path / "b.md", figures=loaded)
    assert again["figure_names"] == first["figure_names"]
    assert _md(tmp_path / "b.md").replace("b_figures", "a_figures") == _md(tmp_path / "a.md")
    with pytest.raises(Simulated):
        write_compare_report(comp, steps, tmp_path / "c.html")      # no data given: computed, here raising


def _raise(*args, **kw):
    raise Simulated("a figure computation was called while rendering saved figure data")
