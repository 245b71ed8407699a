"""gyroarray.chain.check: thresholds files, grouping, pass/fail and strict validation."""

import shutil
from pathlib import Path

import pytest

from gyroarray.chain.check import format_check, load_thresholds, run_check
from gyroarray.core.errors import InputError

ROOT = Path(__file__).resolve().parents[1] / "src" / "gyroarray" / "data" / "scenarios"


@pytest.fixture()
def folder(tmp_path):
    """A scenario copied next to the thresholds files (checks resolve relative to them)."""
    shutil.copy(ROOT / "paper003" / "static_s1_n6_rhob_0.toml", tmp_path / "s1n6.toml")
    return tmp_path


def _write(folder, text):
    p = folder / "thresholds.toml"
    p.write_text(text)
    return p


GLS_ARW = """
[[check]]
scenario = "s1n6"
quick_duration_s = 60
estimator = "gls"
axis = "all"
metric = "arw_reduction"
min = {lo}
max = {hi}
"""
KF_Z = """
[[check]]
scenario = "s1n6"
quick_duration_s = 60
estimator = "kf_array"
axis = "z"
metric = "sigma_1_deg_s"
max = 1.0
"""


def test_passing_file_runs_each_scenario_once(folder, monkeypatch):
    import gyroarray.chain.run as chain
    calls = []
    real = chain.run_scenario
    monkeypatch.setattr(chain, "run_scenario", lambda sc, names: calls.append(list(names)) or real(sc, names))
    # theory: GLS ARW reduction sqrt(N/3) = 1.414 for N = 6; ±15 % for a 60 s Allan fit
    res = run_check(_write(folder, GLS_ARW.format(lo=1.2, hi=1.63) + KF_Z))
    assert res["passed"] is True
    assert len(calls) == 1 and set(calls[0]) == {"gls", "kf_array"}   # grouped: one run
    rows = res["results"]
    assert [r["axis"] for r in rows] == ["x", "y", "z", "z"]
    gls = [r["value"] for r in rows[:3]]
    assert gls == pytest.approx([1.414] * 3, rel=0.15)
    assert rows[0]["bound"] == "[1.2, 1.63]" and rows[3]["bound"] == "≤ 1"
    assert rows[3]["scenario"] == "s1n6" and rows[3]["estimator"] == "kf_array"
    text = format_check(res)
    assert "arw_reduction" in text and "4/4 passed" in text and "FAIL" not in text


def test_failing_bound_fails(folder):
    # GLS cannot reach an ARW reduction of 2.2 (theory: sqrt(2)); the example bound
    res = run_check(_write(folder, GLS_ARW.format(lo=2.2, hi=3.0)))
    assert res["passed"] is False
    assert all(not r["pass"] for r in res["results"])
    assert "FAIL" in format_check(res) and "0/3 passed, 3 FAILED" in format_check(res)


def test_efficiency_adds_bound_estimator(folder):
    text = KF_Z.replace("sigma_1_deg_s", "efficiency").replace("max = 1.0", "max = 1.05")
    res = run_check(_write(folder, text))
    # efficiency = 1σ(offline smoother) / 1σ(kf_array) <= 1 (+ estimation noise)
    assert res["passed"] and 0.5 < res["results"][0]["value"] <= 1.05


@pytest.mark.parametrize("text, key, words", [
    ("[[check]]\nscenario='s1n6'\nquick_duration_s=60\nestimator='gls'\naxis='x'\nmetric='reduction'\nmin=1\nfoo=2\n",
     "check[0].foo", "unknown key 'foo'"),
    ("bar = 1\n[[check]]\n", "bar", "unknown key 'bar'"),
    ("[[check]]\nscenario='s1n6'\nquick_duration_s=60\nestimator='gls'\naxis='x'\nmetric='reduction'\n",
     "check[0]", "min and/or max"),
    ("[[check]]\nscenario='s1n6'\nquick_duration_s=60\nestimator='gls'\naxis='w'\nmetric='reduction'\nmin=1\n",
     "check[0].axis", "axis must be"),
    ("[[check]]\nscenario='s1n6'\nquick_duration_s=60\nestimator='gls'\naxis='x'\nmetric='speed'\nmin=1\n",
     "check[0].metric", "unknown metric 'speed'"),
    ("[[check]]\nscenario='s1n6'\nquick_duration_s=60\nestimator='magic'\naxis='x'\nmetric='reduction'\nmin=1\n",
     "check[0].estimator", "unknown estimator 'magic'"),
    ("[[check]]\nscenario='nope'\nquick_duration_s=60\nestimator='gls'\naxis='x'\nmetric='reduction'\nmin=1\n",
     "check[0].scenario", "not found"),
    ("[[check]]\nscenario='s1n6'\nquick_duration_s=-1\nestimator='gls'\naxis='x'\nmetric='reduction'\nmin=1\n",
     "check[0].quick_duration_s", "> 0"),
    ("[[check]]\nscenario='s1n6'\nquick_duration_s=60\nestimator='gls'\naxis='x'\nmetric='reduction'\nmin='big'\n",
     "check[0].min", "finite number"),
    ("[[check]]\nscenario='s1n6'\nquick_duration_s=60\nestimator='gls'\naxis='x'\nmetric='reduction'\nmin=2\nmax=1\n",
     "check[0].min", "min 2 > max 1"),
    ("[[check]]\nquick_duration_s=60\nestimator='gls'\naxis='x'\nmetric='reduction'\nmin=1\n",
     "check[0].scenario", "scenario is missing"),
    ("", "check", "no [[check]]"),
])
def test_bad_files_refused(folder, text, key, words):
    path = _write(folder, text)
    with pytest.raises(InputError) as err:
        load_thresholds(path)
    assert err.value.file == str(path) and err.value.column == key
    assert words in str(err.value)


def test_bad_toml_and_missing_file(folder):
    with pytest.raises(InputError, match="TOML syntax error"):
        load_thresholds(_write(folder, "[[check]\n"))
    with pytest.raises(InputError, match="not found"):
        run_check(folder / "absent.toml")


def test_shipped_thresholds_valid():
    checks = load_thresholds(ROOT / "thresholds.toml")
    assert len(checks) >= 10 and all(Path(c["file"]).is_file() for c in checks)
