"""Every malformed file of the corpus is refused with its own located message.

The corpus (``tests/data/bad/``) and the expectations come from
``tests/bad_corpus.py``; a test below checks that the committed files are
exactly what that module generates, so the two cannot drift apart.
"""

from __future__ import annotations

import hashlib
import importlib.util
import sys
from pathlib import Path

import pytest

from gyroarray.core.errors import InputError
from gyroarray.core.measurement import read_measurement

_HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("bad_corpus", _HERE / "bad_corpus.py")
bad_corpus = importlib.util.module_from_spec(_spec)
sys.modules["bad_corpus"] = bad_corpus   # dataclasses look their module up
_spec.loader.exec_module(bad_corpus)

CASES = bad_corpus.cases()
CORPUS = bad_corpus.CORPUS_DIR


def digest(paths) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in paths if p.exists()}


def test_corpus_is_large_and_messages_are_distinct():
    assert len(CASES) >= 40
    # each rule has its own wording: cases sharing a fragment break the same rule
    # in two ways (e.g. 5 vs 3 fields), never two rules with one message
    by_fragment = {}
    for case in CASES:
        by_fragment.setdefault(case.fragment, []).append(case.name)
    shared = {f: names for f, names in by_fragment.items() if len(names) > 1}
    assert shared == {
        "wrong number of fields: 5, the header has 4": ["too_many_fields", "trailing_comma"],
        "not a valid gzip file": ["not_gzip", "truncated_gzip"],
        "layout.axes must be an array of [x, y, z] rows of numbers":
            ["axes_not_rows_of_3", "axes_strings"],
    }


def test_committed_corpus_equals_generated(tmp_path):
    generated = bad_corpus.write_corpus(tmp_path)
    committed = sorted(p for p in CORPUS.iterdir() if p.is_file())
    assert [p.name for p in committed] == [p.name for p in generated]
    assert digest(committed) == digest(generated), "run: python tests/bad_corpus.py"


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_bad_file_is_refused_with_located_message(case):
    csv_path = CORPUS / case.csv_name
    toml_path = CORPUS / case.toml_name
    before = digest([csv_path, toml_path])
    with pytest.raises(InputError) as info:
        read_measurement(csv_path, repair=case.repair)
    err = info.value
    assert case.fragment in err.message
    assert err.file == str(toml_path if case.file == "toml" else csv_path)
    assert (err.line, err.column) == (case.line, case.column)
    assert "\n" not in str(err)                                # one line for the CLI
    assert digest([csv_path, toml_path]) == before             # nothing modified
    assert sorted(p.name for p in CORPUS.iterdir() if p.name.startswith(case.name + ".")) \
        == sorted([case.csv_name] + ([case.toml_name] if case.toml is not None else []))
