"""The bag topic across ``convert`` -> ``fit`` -> ``export`` (issue 42): ``convert`` writes the
topics into the measurement's sidecar (``topics = ["/husky/imu"]``), the reader reads them back
(checked: an array of non-empty strings, at most one per gyro; a bad one is refused naming the
sidecar and its line), and ``fit`` / ``export`` carry them as they do when they read the bag
itself. A sidecar without ``topics`` reads as before.

The topic is ``/husky/imu``, not the export's default ``/imu0``: a file that says ``/husky/imu``
can only have it from the bag.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from gyroarray.core.errors import InputError
from gyroarray.core.measurement import read_measurement
from tests.hostile import assert_contract, axes_sidecar, run_cli, write_measurement
from tests.test_bags import record, write_bag

TOPIC = "/husky/imu"


def _sidecar(path: Path) -> Path:
    name = path.name
    stem = name[:-7] if name.endswith(".csv.gz") else name[:-8] if name.endswith(".parquet") else name[:-4]
    return path.with_name(stem + ".toml")


@pytest.mark.parametrize("kind,out_name", [("bag", "rec.csv.gz"), ("mcap", "rec.parquet")])
def test_streamed_convert_writes_the_topic_and_reads_it_back(tmp_path, kind, out_name):
    path = write_bag(tmp_path, "one", kind, {TOPIC: record(5)})
    out = tmp_path / out_name
    o = run_cli(["convert", path, "--topic", TOPIC, "--out", out, "--json"])
    assert_contract(o)
    assert o.code == 0 and o.json["streamed"] is True
    assert tomllib.loads(_sidecar(out).read_text())["topics"] == [TOPIC]
    back, bag = read_measurement(out), read_measurement(path)
    assert back.topics == bag.topics == (TOPIC,)
    assert not any("unknown key" in n for n in back.notes)       # a key the reader knows


def test_whole_record_convert_keeps_every_topic_in_gyro_order(tmp_path):
    """Two topics (an array: not streamed, through write_measurement): both, in the bag's order."""
    path = write_bag(tmp_path, "two", "bag", {"/b/imu": record(6), "/a/imu": record(7)})
    out = tmp_path / "arr.csv"
    o = run_cli(["convert", path, "--topic", "/b/imu,/a/imu", "--out", out, "--json"])
    assert_contract(o)
    assert o.code == 0 and o.json["streamed"] is False and o.json["n_gyros"] == 6
    back = read_measurement(out)
    assert back.topics == ("/b/imu", "/a/imu") == read_measurement(path, topic="/b/imu,/a/imu").topics


def test_a_sidecar_without_topics_reads_as_before(tmp_path):
    t = np.arange(100) / 50.0
    g = np.random.default_rng(1).normal(0.0, 0.05, (100, 1))
    p = write_measurement(tmp_path, "plain", t, g, sidecar=axes_sidecar(1))
    m = read_measurement(p)
    assert m.topics == () and not any("topics" in n for n in m.notes)


@pytest.mark.parametrize("value,line,said", [
    ('"/imu0"', 2, "topics must be an array of strings"),
    ('[1]', 2, "topics[0] must be a string"),
    ('[""]', 2, "topics[0] must be a non-empty topic name"),
    ('[\n  "/imu0",\n  "/imu1",\n]', 2, "names 2 topics for 1 gyro"),
    ('[\n  "/imu0\\n",\n]', 2, "without control characters"),
], ids=["a_string", "a_number", "empty", "more_than_gyros", "a_newline"])
def test_bad_topics_are_refused_naming_the_sidecar_and_line(tmp_path, value, line, said):
    t = np.arange(100) / 50.0
    g = np.random.default_rng(2).normal(0.0, 0.05, (100, 1))
    side = axes_sidecar(1).replace("sample_rate_hz = 50.0\n", f"sample_rate_hz = 50.0\ntopics = {value}\n")
    p = write_measurement(tmp_path, "bad", t, g, sidecar=side)
    with pytest.raises(InputError) as e:
        read_measurement(p)
    assert e.value.file == str(tmp_path / "bad.toml") and e.value.line == line and said in e.value.message
    o = run_cli(["allan", p])                                    # the CLI: one line, exit 2
    assert_contract(o, f"bad.toml, line {line}, column topics")
    assert o.code == 2 and said in o.err


@pytest.mark.slow
def test_convert_then_fit_then_export_carries_the_topic(tmp_path):
    """The documented flow: ``convert BAG --topic T``, ``fit REC --out m.toml``, ``export m.toml
    --format kalibr``: the model's ``topic`` and the file's ``rostopic`` are the bag's, as when the
    bag is fitted directly (3000 messages at 200 Hz: 15 s, over the 2048 samples fit needs)."""
    path = write_bag(tmp_path, "run", "bag", {TOPIC: record(8, n=3000)})
    rec = tmp_path / "rec.csv.gz"
    assert run_cli(["convert", path, "--topic", TOPIC, "--out", rec]).code == 0
    for source, model in ((rec, tmp_path / "m.toml"), (path, tmp_path / "direct.toml")):
        o = run_cli(["fit", source, "--out", model, "--json"])
        assert_contract(o)
        assert o.code == 0, o.err
        assert f'topic = "{TOPIC}"' in model.read_text()
    out = tmp_path / "imu.yaml"
    o = run_cli(["export", tmp_path / "m.toml", "--format", "kalibr", "--rate-hz", "200",
                 "--out", out, "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    assert o.json["topic"] == {"topic": TOPIC, "why": "the topic the model was fitted on"}
    assert f"rostopic: {json.dumps(TOPIC)}" in out.read_text()
