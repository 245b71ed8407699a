"""``scripts/docs_numbers.py`` (``make docs-numbers``): the docs' numbers come from a run (issue 42,
item 8). The fast tests check the markers and the rewriting; the slow one runs the commands and
checks the docs are up to date."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "docs_numbers.py"


def _script():
    spec = importlib.util.spec_from_file_location("docs_numbers", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


dn = _script()


def test_the_docs_markers_are_well_formed_and_known():
    assert dn.check_markers() == []
    text = (ROOT / "docs" / "export.md").read_text(encoding="utf-8")
    found = dn.regions(text, "export.md")
    assert [r for r, _, _ in found] == ["adis-plan"]
    assert "ADIS16405" in dn.body(text, "adis-plan")


@pytest.mark.parametrize("text, fragment", [
    ("<!-- numbers:a -->\n<!-- numbers:b -->\n<!-- /numbers -->\n", "opens inside"),
    ("x\n<!-- /numbers -->\n", "without an opening"),
    ("<!-- numbers:a -->\ntext\n", "never closed"),
    ("<!-- numbers:a -->\n<!-- /numbers -->\n<!-- numbers:a -->\n<!-- /numbers -->\n", "twice"),
    ("<!--numbers:a-->\n<!-- /numbers -->\n", "not a marker line"),
])
def test_malformed_markers_are_refused_with_their_line(text, fragment):
    with pytest.raises(dn.MarkerError, match=fragment):
        dn.regions(text, "p.md")


def test_only_the_marked_passage_is_rewritten():
    text = "head\n<!-- numbers:adis-plan -->\nold 6.6 h\n<!-- /numbers -->\ntail 6.6 h\n"
    new = dn.replace_regions(text, {"adis-plan": "new 8.1 h\nsecond line"})
    assert new == "head\n<!-- numbers:adis-plan -->\nnew 8.1 h\nsecond line\n<!-- /numbers -->\ntail 6.6 h\n"
    assert dn.replace_regions(new, {"adis-plan": "new 8.1 h\nsecond line"}) == new     # idempotent
    assert dn.replace_regions(text, {}) == text


def test_the_adis_passage_states_the_run_numbers():
    """The plan's numbers as issue 42 measured them (8.1 / 5.4 / 3.2 h) go into the text with the
    docs' roundings; no line is wider than the docs' 95 characters."""
    v = {"record_h": 2.7777777, "rate_hz": 100.0, "k": [75.937, 124.935, 200.617],
         "need_h": [8.1088, 5.4389, 3.1627], "at_record": [0.18094, 0.14414, 0.10754],
         "fit_sigma": [0.44044, 0.34496, 0.16307], "b1_deg_h": 33.39, "bi_need_h": 47.2,
         "bi_at_record": 0.602}
    text = dn.render_adis_plan(v)
    flat = " ".join(text.split())
    for part in ("2.78 h at 100 Hz", "K = 76, 125 and 201 deg/h/√h", "needs 8.1, 5.4 and 3.2 h",
                 "±18, ±14 and ±11 %", "±44, ±34 and ±16 %", "B ≈ 33 deg/h", "needs 47 h",
                 "gives ±60 %"):
        assert part in flat, (part, flat)
    assert max(len(line) for line in text.split("\n")) <= dn.WIDTH
    assert "`plan --bi`" in text                 # a code span is never split across lines


def test_make_has_the_target():
    make = (ROOT / "Makefile").read_text()
    assert "\ndocs-numbers: " in make and "scripts/docs_numbers.py" in make
    phony = next(line for line in make.splitlines() if line.startswith(".PHONY:"))
    assert "docs-numbers" in phony.split()


@pytest.mark.slow
@pytest.mark.skipif(not dn.ADIS.exists(), reason="shared/measurements/real not present")
def test_the_docs_numbers_are_up_to_date():
    """Runs fit, plan, allan and plan on the ADIS16405 record (~35 s): --check exits 0."""
    proc = subprocess.run([sys.executable, str(SCRIPT), "--check"], capture_output=True, text=True,
                          cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "up to date" in proc.stdout
