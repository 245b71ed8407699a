"""Issue 28, items 4 and 5: counts and sizes checked before the work, physically plausible
profiles, and an RRW-only scenario that still scores an estimator.

Each case is a reproduction from the issue, run through ``gyroarray.cli.main.main`` in this
process (:func:`hostile.run_cli`). A refusal is proved to come before the work: the
function that would do the work is replaced by one that fails the test if it is reached,
or the number of scenarios built is counted.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from hostile import assert_contract, run_cli, write_measurement, write_scenario

N = 3000
DT = 0.02


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    folder = tmp_path_factory.mktemp("counts")
    rng = np.random.default_rng(28)
    write_measurement(folder, "plain", np.arange(N) * DT, rng.normal(0.0, 0.05, (N, 3)))
    write_scenario(folder, "tiny")
    return folder


def ok(o, name=None) -> dict:
    assert_contract(o, name)
    assert o.code == 0, o.err
    return o.json


def refused(o, name, *fragments) -> str:
    assert_contract(o, name)
    assert o.code == 2, (o.out[:300], o.err)
    for f in fragments:
        assert f in o.err, o.err
    return o.err


def _never(what):
    def fail(*a, **k):
        raise AssertionError(f"{what} was reached: the refusal came after the work started")
    return fail


# -- item 4: counts a user passes ------------------------------------------------------

@pytest.mark.parametrize("argv, option", [
    (["diagnose", "{d}/plain.csv", "--runs", "10000000"], "--runs"),
    (["compare", "{d}/plain.csv", "--runs", "5000", "--out", "{d}/r.html"], "--runs"),
    (["run", "{d}/tiny.toml", "--replicates", "1000000"], "--replicates"),
    (["design", "--recommend", "--arw", "0.1", "--check", "100000"], "--check"),
    (["sweep", "{d}/tiny.toml", "--out", "{d}/o", "--workers", "100000"], "--workers"),
    (["ladder", "{d}/plain.csv", "--max-steps", "100000", "--out", "{d}/l.html"], "--max-steps"),
])
def test_a_huge_count_is_refused_before_any_work(d, monkeypatch, argv, option):
    import gyroarray.chain.run
    import gyroarray.core.measurement
    import gyroarray.design.recommend
    import gyroarray.sim.scenario
    monkeypatch.setattr(gyroarray.core.measurement, "read_measurement", _never("reading the record"))
    monkeypatch.setattr(gyroarray.sim.scenario, "load_scenario", _never("reading the scenario"))
    monkeypatch.setattr(gyroarray.chain.run, "run_replicates", _never("the replicates"))
    monkeypatch.setattr(gyroarray.design.recommend, "recommend", _never("the design search"))
    o = run_cli([a.format(d=d) for a in argv], timeout=60)
    err = refused(o, option, "is more than", f"give {option}", "or less")
    assert "argument" in err or option in err


def test_band_runs_beyond_the_memory_budget_are_refused_before_the_band(d, monkeypatch):
    import gyroarray.chain.compare
    monkeypatch.setattr(gyroarray.chain.compare, "ModelComparison", _never("the model comparison"))
    o = run_cli(["diagnose", d / "plain.csv", "--runs", "1000", "--max-memory", "4M"], timeout=60)
    refused(o, "--runs 1000", "of memory", "lower --runs", "--max-memory")


def test_allan_taus_beyond_what_the_record_gives_is_clipped_with_a_note(d):
    """allan --taus 10000 on 3000 samples did not finish in 400 s."""
    o = run_cli(["allan", d / "plain.csv", "--gyro", "1", "--taus", "10000", "--json"], timeout=120)
    res = ok(o)
    from gyroarray.analysis.allan import MAX_FIT_TAUS
    taus = res["gyros"]["1"]["taus_s"]
    assert 40 <= len(taus) <= MAX_FIT_TAUS
    assert len(set(taus)) == len(taus) and taus == sorted(taus)
    note = next(n for n in res["notes"] if n.startswith("--taus 10000"))
    assert "3000 samples give" in note and f"analysed {len(taus)} of them" in note


def test_allan_taus_count_above_the_distinct_ones_says_so(tmp_path):
    write_measurement(tmp_path, "short", np.arange(100) * DT,
                      np.random.default_rng(1).normal(0.0, 0.05, (100, 3)))
    res = ok(run_cli(["allan", tmp_path / "short.csv", "--gyro", "2", "--taus", "500", "--json"]))
    taus = res["gyros"]["2"]["taus_s"]
    note = next(n for n in res["notes"] if n.startswith("--taus 500"))
    assert f"only {len(taus)} distinct" in note and len(taus) < 500


def test_allan_taus_list_longer_than_the_fit_takes_is_refused(d, monkeypatch):
    import gyroarray.core.measurement
    monkeypatch.setattr(gyroarray.core.measurement, "read_measurement", _never("reading the record"))
    taus = ",".join(f"{DT * k:g}" for k in range(1, 80))
    refused(run_cli(["allan", d / "plain.csv", "--taus", taus]), "--taus", "lists 79 taus",
            "at most 64")


# -- item 4: sweep grids -------------------------------------------------------------

SWEEP = """name = "g"
seed = 1
{top}
[base]
sample_rate_hz = 20.0
effects = [ {{ effect = "arw", n_deg_rt_h = 0.1 }} ]
[base.layout]
scheme = 1
n_gyros = 6
alpha_deg = 54.7356
[base.motion]
profile = "p003_static_1h"
[grid]
{grid}
"""


def _count_builds(monkeypatch) -> list:
    from gyroarray.sweep import sweep
    calls = []
    real = sweep._build_scenario

    def counted(*a, **k):
        calls.append(1)
        return real(*a, **k)
    monkeypatch.setattr(sweep, "_build_scenario", counted)
    return calls


def test_the_first_invalid_grid_value_is_refused_at_once(tmp_path, monkeypatch):
    """A 99,900-point grid whose last point was invalid was refused after 487 s: here
    40 x 25 = 1000 points, the last rho invalid for N = 6; at most a few dozen are built."""
    rhos = [0.001 * k for k in range(39)] + [-0.5]
    durs = [10.0 + k for k in range(25)]
    path = tmp_path / "g.toml"
    path.write_text(SWEEP.format(top="", grid=f"rho_arw = {rhos!r}\nduration_s = {durs!r}"))
    calls = _count_builds(monkeypatch)
    o = run_cli(["sweep", path, "--out", tmp_path / "o"], timeout=60)
    refused(o, "g.toml", "rho = -0.5", "grid.rho_arw")
    assert len(calls) < 3 * (len(rhos) + len(durs)), len(calls)
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_too_many_sweep_scenarios_are_refused_before_any_is_built(tmp_path, monkeypatch):
    path = tmp_path / "g.toml"
    path.write_text(SWEEP.format(top="replicates = 1000",
                                 grid=f"rho_arw = {[0.001 * k for k in range(101)]!r}"))
    calls = _count_builds(monkeypatch)
    o = run_cli(["sweep", path, "--out", tmp_path / "o"], timeout=60)
    refused(o, "g.toml", "101000 scenarios", "1000 replicates", "at most 100000")
    assert len(calls) == 1, len(calls)         # the base only


def test_a_valid_grid_still_expands_every_point(tmp_path):
    from gyroarray.sweep.sweep import load_sweep
    path = tmp_path / "g.toml"
    path.write_text(SWEEP.format(top="", grid="rho_arw = [0.0, 0.1, 0.2]\nduration_s = [10.0, 20.0]"))
    assert len(load_sweep(path)) == 6


# -- item 4: a profile's span beyond the scenario -------------------------------------

def _span_profile(folder: Path, span_s: float) -> str:
    (folder / "r.csv").write_text(f"time_s,wx_deg_s,wy_deg_s,wz_deg_s\n0,0,0,1\n{span_s!r},0,0,1\n")
    return '[[segment]]\nkind = "rate_csv"\nfile = "r.csv"\n'


def test_a_profile_spanning_1e9_s_runs_only_the_scenarios_20_s(tmp_path):
    """A 20 s scenario whose rate_csv spans 1e9 s: MemoryError, 745 GiB."""
    sc = write_scenario(tmp_path, "span", extra="duration_s = 20.0", profile="p.toml",
                        profile_text=_span_profile(tmp_path, 1e9))
    res = ok(run_cli(["simulate", sc, "--out", tmp_path / "out", "--json"], timeout=120))
    assert finite_numbers_ok(res)
    from gyroarray.sim.scenario import load_scenario
    s = load_scenario(sc)
    assert s.profile.duration_s == pytest.approx(20.0)
    assert s.profile.pieces[-1].t_nodes.size < 3000


def test_a_profile_span_that_is_run_whole_is_refused_with_file_line_and_span(tmp_path):
    sc = write_scenario(tmp_path, "span", profile="p.toml", profile_text=_span_profile(tmp_path, 1e9))
    o = run_cli(["run", sc], timeout=60)
    refused(o, "r.csv, line 3, column time_s", "span 1e+09 s", "at most 1e+06")
    assert o.cpu_s < 30


def finite_numbers_ok(res) -> bool:
    return all(math.isfinite(v) for v in _numbers(res))


def _numbers(obj):
    if isinstance(obj, float):
        yield obj
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from _numbers(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _numbers(v)


# -- item 5: content above the scenario's Nyquist frequency ------------------------------

SINE = ('[[segment]]\nkind = "sinusoid"\naxis = [0, 0, 1]\namplitude_deg_s = 1.0\n'
        'frequency_hz = {f!r}\nduration_s = 10.0\n')


def test_a_profile_sinusoid_above_nyquist_is_refused(tmp_path, monkeypatch):
    """1000 Hz in a 100 Hz scenario: run exited 0 with attenuation 2915539016.87."""
    import gyroarray.sim.scenario
    monkeypatch.setattr(gyroarray.sim.scenario, "simulate", _never("the simulation"))
    sc = write_scenario(tmp_path, "fast", rate=100.0, profile="sine.toml",
                        profile_text=SINE.format(f=1000.0))
    refused(run_cli(["run", sc]), "sine.toml, column segment[1].frequency_hz",
            "1000 Hz", "Nyquist frequency 50 Hz", "sample_rate_hz = 100 Hz")


def test_a_profile_sinusoid_below_nyquist_still_runs(tmp_path):
    sc = write_scenario(tmp_path, "slow", rate=100.0, profile="sine.toml",
                        profile_text=SINE.format(f=2.0))
    res = ok(run_cli(["run", sc, "--estimators", "naive", "--json"]))
    assert res


def _csv_profile(folder: Path, freq_hz: float, row_dt: float, n: int = 5001) -> str:
    t = [k * row_dt for k in range(n)]
    rows = "\n".join(f"{a!r},0,0,{5.0 * math.sin(2 * math.pi * freq_hz * a + 0.3)!r}" for a in t)
    (folder / "r.csv").write_text("time_s,wx_deg_s,wy_deg_s,wz_deg_s\n" + rows + "\n")
    return '[[segment]]\nkind = "rate_csv"\nfile = "r.csv"\n'


def test_a_rate_csv_with_content_above_nyquist_is_refused(tmp_path):
    sc = write_scenario(tmp_path, "fast", rate=100.0, profile="p.toml",
                        profile_text=_csv_profile(tmp_path, 1000.0, 0.0002))
    refused(run_cli(["run", sc]), "r.csv, column wz_deg_s", "Nyquist frequency 50 Hz", "above")


def test_a_rate_csv_sampled_fast_but_slow_in_content_runs(tmp_path):
    sc = write_scenario(tmp_path, "slow", rate=100.0, profile="p.toml",
                        profile_text=_csv_profile(tmp_path, 1.0, 0.001))
    ok(run_cli(["run", sc, "--estimators", "naive", "--json"]))


# -- item 5: an RRW-only scenario ---------------------------------------------------

RRW_ONLY = """name = "rrw"
sample_rate_hz = 20.0
seed = 1
duration_s = 30.0
effects = [ { effect = "rrw", k_deg_h_rt_h = 10.0 } ]
[layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356
[motion]
profile = "p003_static_1h"
"""


def test_an_rrw_only_scenario_scores_the_estimators_that_need_no_white_noise(tmp_path):
    """run on an RRW-only scenario exited 0 with every estimator skipped."""
    sc = tmp_path / "rrw.toml"
    sc.write_text(RRW_ONLY)
    o = run_cli(["run", sc, "--json"], timeout=120)
    res = ok(o)
    text = json.dumps(res)
    assert '"ols"' in text and '"naive"' in text
    o = run_cli(["run", sc], timeout=120)
    lines = o.out.splitlines()
    assert any(line.startswith("ols ") for line in lines) and any(line.startswith("naive ") for line in lines)
    assert any("skipped gls: the noise model has no angle random walk" in line for line in lines)


def test_an_rrw_only_scenario_named_estimator_that_needs_arw_is_refused(tmp_path):
    sc = tmp_path / "rrw.toml"
    sc.write_text(RRW_ONLY)
    refused(run_cli(["run", sc, "--estimators", "gls"]), "rrw.toml", "no angle random walk")


def test_davar_windows_beyond_the_memory_budget_are_refused_before_the_work(d, monkeypatch):
    import gyroarray.analysis.davar
    monkeypatch.setattr(gyroarray.analysis.davar, "davar", _never("the DAVAR"))
    o = run_cli(["davar", d / "plain.csv", "--gyro", "1", "--step", "1", "--max-memory", "2M"])
    refused(o, "plain.csv", "3000 windows (--step 1)", "give a larger --step")
