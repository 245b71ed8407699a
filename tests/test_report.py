"""gyroarray report: tables, paper-vs-model flags, self-contained HTML that a browser renders.

Two tiny sweeps are run once for the module (20 s runs): a design grid and a
"paper" sweep of one scenario file with 20 replicates (the fewest whose
percentiles make a 95 % band), compared with a paper-values file written here
whose numbers are set from the model's own runs (one inside, one far
outside), so the flags are known in advance.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest

from gyroarray.core.errors import InputError
from gyroarray.reports.browser import find_chromium, render_check
from gyroarray.reports.report import write_report
from gyroarray.sweep.report_results import (design_ranking, estimator_comparison, load_paper_values,
                                            load_sweep_dir, paper_vs_model)
from gyroarray.sweep.runner import run_sweep

SCENARIO = """\
name = "tiny_static"
sample_rate_hz = 100.0
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
estimators = ["kf_array", "gls", "bound"]
base = "tiny_static"
[grid]
n_gyros = [4, 6]
motion = ["p003_static_1h", "p003_sine_5dps_0p03hz"]
"""

PAPER = """\
name = "tiny_paper"
seed = 6
replicates = 20
estimators = ["kf_array", "gls"]
scenarios = ["tiny_static"]
"""


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    old = os.environ.get("GYROARRAY_CACHE")
    os.environ["GYROARRAY_CACHE"] = str(root / "cache")
    try:
        (root / "tiny_static.toml").write_text(SCENARIO)
        (root / "design.toml").write_text(DESIGN)
        (root / "paper.toml").write_text(PAPER)
        run_sweep(root / "design.toml", root / "design_out", workers=1, progress=False)
        run_sweep(root / "paper.toml", root / "paper_out", workers=1, progress=False)
    finally:
        if old is None:
            os.environ.pop("GYROARRAY_CACHE", None)
        else:
            os.environ["GYROARRAY_CACHE"] = old
    return root


def _paper_values(root: Path, inside: float, outside: float) -> Path:
    p = root / "values.toml"
    p.write_text(f"""\
[[experiment]]
title = "Tiny table"
scenario = "tiny_static"
estimator = "gls"
values = [
  {{ axis = "x", metric = "sigma_1_deg_s", value = {float(inside)!r} }},
  {{ axis = "single", metric = "sigma_1_deg_s", value = {float(outside)!r} }},
]
[[experiment.check]]
name = "tiny_ten_times_noisier"
hypothesis = "The gyros were ten times noisier."
effects = [{{ effect = "arw", n_deg_rt_h = 1.0 }}]
values = [{{ axis = "x", metric = "sigma_1_deg_s", value = {float(inside)!r} }}]
[[experiment]]
title = "Not run"
scenario = "paper003/swing_s1_n6"
estimator = "kf_array"
values = [{{ axis = "x", metric = "sigma_1_deg_s", value = 0.01 }}]
""")
    return p


@pytest.mark.slow   # with the module's sweeps (14 s) and a full render: make score
def test_paper_vs_model_flags_against_the_percentile_band(sweeps):
    rows = load_sweep_dir(sweeps / "paper_out").rows
    x = rows[(rows.estimator == "gls") & (rows.axis == "x")]["sigma_1_deg_s"].to_numpy()
    assert x.size == 20 and len(set(x)) == 20              # 20 replicates, 20 seeds
    lo, hi = np.percentile(x, 2.5), np.percentile(x, 97.5)
    single = (rows[rows.estimator == "gls"].eval("sigma_1_deg_s * reduction")
              .groupby(rows.scenario_id).mean())
    inside = 0.5 * (lo + hi)
    pvm = paper_vs_model(rows, load_paper_values(_paper_values(sweeps, inside, 10 * single.mean())))
    assert len(pvm) == 1                                    # the experiment not run is left out
    e = pvm[0]
    assert e["runs"] == 20 and e["flagged"] and e["checks"][0]["name"] == "tiny_ten_times_noisier"
    vx, vs = e["values"]
    assert vx["model_mean"] == pytest.approx(x.mean(), rel=1e-12)
    assert (vx["low"], vx["high"]) == pytest.approx((lo, hi), rel=1e-12)
    assert vx["low"] > 0                                    # a band of positive runs stays positive
    assert vx["flag"] is False and vx["ratio"] == pytest.approx(inside / x.mean())
    assert vs["flag"] is True and vs["ratio"] == pytest.approx(10.0, rel=1e-9)
    # just outside the band is flagged; with fewer than 20 runs there is no band and no verdict
    pvm2 = paper_vs_model(rows, load_paper_values(_paper_values(sweeps, hi * 1.001, single.mean())))
    assert pvm2[0]["values"][0]["flag"] is True
    few = rows[rows.replicate < 19]
    pvm3 = paper_vs_model(few, load_paper_values(_paper_values(sweeps, 10 * hi, single.mean())))
    v3 = pvm3[0]["values"][0]
    assert v3["flag"] is None and math.isnan(v3["low"]) and not pvm3[0]["flagged"]


def test_ranking_and_estimator_tables(sweeps):
    rows = load_sweep_dir(sweeps / "design_out").rows
    ranking = design_ranking(rows)
    assert "bound" not in set(ranking.estimator)           # not a design choice
    assert len(ranking) == 2 * 2 * 2                        # N x motion x estimator
    for motion, sub in ranking.groupby("motion"):
        assert list(sub["rank"]) == [1, 2, 3, 4]
        assert np.all(np.diff(sub.sigma_1_deg_s.to_numpy()) >= 0)
        # the mean over the three axes of the one run
        r = sub.iloc[0]
        sel = rows[(rows.motion == motion) & (rows.n_gyros == r.n_gyros)
                   & (rows.estimator == r.estimator)]
        assert r.sigma_1_deg_s == pytest.approx(sel.sigma_1_deg_s.mean(), rel=1e-12)
    comp = estimator_comparison(rows)
    b = comp[comp.estimator == "bound"]
    assert np.allclose(b.efficiency, 1.0)                   # the bound against itself
    # the offline smoother is at least as good as the causal KF (median over designs)
    k = comp[comp.estimator == "kf_array"]
    assert (k.efficiency.to_numpy() <= 1.02).all() and (k.efficiency.to_numpy() > 0.5).all()


@pytest.mark.slow   # with the module's sweeps (14 s) and a full render: make score
def test_report_files_are_self_contained(sweeps, tmp_path):
    values = _paper_values(sweeps, 0.01, 1.0)
    res = write_report([sweeps / "design_out", sweeps / "paper_out"], tmp_path / "r.html",
                       tmp_path / "r.md", paper_values=values)
    text = (tmp_path / "r.html").read_text()
    srcs = re.findall(r'<img src="([^"]+)"', text)
    assert len(srcs) == res["figures"] >= 5
    assert all(s.startswith("data:image/png;base64,") for s in srcs)
    assert not re.search(r'(src|href)="(https?:|//)', text)   # nothing from the network
    assert "<script" not in text
    for heading in ("Design ranking", "Allan deviation", "Estimator comparison", "Paper vs model"):
        assert heading in text
    assert 'class="flag"' in text
    # the explanation is printed with the simulation that tests it, and its verdict
    assert "Hypothesis: The gyros were ten times noisier." in text
    assert "Simulation tiny_ten_times_noisier" in text and "does not support" in text
    md = (tmp_path / "r.md").read_text()
    figs = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert len(figs) == res["figures"] and all((tmp_path / f).is_file() for f in figs)
    assert "| axis | metric | paper |" in md
    assert [s["paper"] for s in res["sweeps"]] == [False, True]
    assert res["best"][0]["estimator"] in ("kf_array", "gls")


@pytest.mark.slow
@pytest.mark.skipif(find_chromium() is None, reason="chromium not installed: apt-get install chromium")
def test_report_renders_in_chromium(sweeps, tmp_path):
    res = write_report([sweeps / "design_out", sweeps / "paper_out"], tmp_path / "r.html",
                       paper_values=_paper_values(sweeps, 0.01, 1.0))
    check = render_check(tmp_path / "r.html")
    assert check.ok, check.summary()
    assert check.images_total == check.images_loaded == res["figures"]
    assert check.console_errors == [] and check.network_requests == []


def test_cli_report_json_and_bad_input(sweeps, tmp_path, cli):
    r = cli("report", sweeps / "design_out", "--out", tmp_path / "a.html", "--json", check=False)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["html"] == str(tmp_path / "a.html") and out["markdown"] is None
    assert out["paper_vs_model"] == [] and out["best"]
    # not a sweep folder: one line, exit 2, nothing written
    r = cli("report", tmp_path, "--out", tmp_path / "b.html", check=False)
    assert r.returncode == 2 and "not a gyroarray sweep folder" in r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "b.html").exists()
    r = cli("report", sweeps / "design_out", "--out", tmp_path / "c.pdf", check=False)
    assert r.returncode == 2 and "must end in .html" in r.stderr
    bad = tmp_path / "bad_values.toml"
    bad.write_text('[[experiment]]\ntitle = "t"\nscenario = "s"\nestimator = "gls"\n'
                   'values = [{ axis = "w", metric = "sigma_1_deg_s", value = 1 }]\n')
    with pytest.raises(InputError) as info:
        load_paper_values(bad)
    assert info.value.column == "experiment[0].values[0]"


def test_shipped_paper_values_name_shipped_scenarios():
    from gyroarray.sweep.sweep import load_sweep
    root = Path(__file__).resolve().parents[1] / "src" / "gyroarray" / "data" / "scenarios"
    exps = load_paper_values()
    listed = {s.params["scenario"]
              for s in load_sweep(root / "sweeps" / "paper_reproduction.toml").scenarios}
    assert {e["scenario"] for e in exps} <= listed
    # no free-text explanation: every explanation is a named check of a hypothesis
    assert not any(e.get("reason") for e in exps)
    assert all((root / f"{e['scenario']}.toml").is_file() for e in exps)
    names = [c["name"] for e in exps for c in e.get("check", [])]
    assert len(names) == len(set(names)) >= 7   # issue 30: 5 unsound checks withdrawn, 2 added
