"""Records longer than memory (issue 34, item 4): Parquet measurements, and ``allan`` streamed.

* A Parquet file written here with pyarrow reads back bit-identical to the CSV of the record.
* ``allan`` streamed in several chunks (forced by a tiny ``--max-memory``, or ``--stream``)
  equals the in-memory analysis to 1e-12 at every octave tau, from Parquet and from CSV.GZ.
* A bad Parquet file (missing column, text column, NaN) is refused in one line naming the
  file, the column and the row, read whole or streamed; ``diagnose`` on a record beyond the
  memory budget is refused naming the budget and the way out.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from hostile import SIDECAR_3, assert_contract, run_cli, write_measurement
from gyroarray.core.measurement import read_measurement

N = 6000                   # samples: 12 octaves at 50 Hz, 24 chunks under --max-memory 512K
RATE = 50.0


def _record(seed: int = 7, n: int = N):
    """Time [s] and three gyros [deg/s] of a still record (white noise on a bias)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    g = 0.2 + 0.05 * rng.standard_normal((n, 3))
    return t, g


def _parquet(folder, name, columns: dict, sidecar: str = SIDECAR_3):
    path = folder / f"{name}.parquet"
    pq.write_table(pa.table(columns), path, row_group_size=1000)
    (folder / f"{name}.toml").write_text(sidecar)
    return path


def _columns(t, g) -> dict:
    return {"time_s": t, **{f"gyro{k + 1}": g[:, k] for k in range(g.shape[1])}}


def test_parquet_reads_bit_identical_to_the_csv(tmp_path):
    t, g = _record()
    csv = read_measurement(write_measurement(tmp_path, "r", t, g))
    par = read_measurement(_parquet(tmp_path, "p", _columns(t, g)))
    assert np.array_equal(par.time_s, csv.time_s) and np.array_equal(par.gyro_deg_s, csv.gyro_deg_s)
    assert np.array_equal(par.layout.axes, csv.layout.axes) and par.ref_deg_s is None
    # convert writes Parquet from the CSV, and it reads back the same (stem lookup included)
    o = run_cli(["convert", tmp_path / "r.csv", "--out", tmp_path / "c.parquet", "--json"])
    assert o.code == 0, o.err
    again = read_measurement(tmp_path / "c")
    assert np.array_equal(again.gyro_deg_s, csv.gyro_deg_s) and np.array_equal(again.time_s, csv.time_s)


def _adev(o) -> dict:
    assert o.code == 0, o.err
    out = json.loads(o.out)
    return out, {k: (np.array(v["taus_s"]), np.array(v["adev_deg_h"])) for k, v in out["gyros"].items()}


@pytest.mark.parametrize("fmt", ["parquet", "csv.gz"])
def test_streamed_allan_equals_in_memory(tmp_path, fmt):
    t, g = _record()
    csv = write_measurement(tmp_path, "r", t, g, gz=fmt == "csv.gz")
    path = csv if fmt == "csv.gz" else _parquet(tmp_path, "p", _columns(t, g))
    _, whole = _adev(run_cli(["allan", csv, "--json"]))
    out, streamed = _adev(run_cli(["allan", path, "--json", "--max-memory", "512K"]))
    assert out["streamed"]["chunk_rows"] * 3 < N                   # several chunks
    assert any("streamed (reading it whole would need" in n for n in out["notes"])
    assert whole.keys() == streamed.keys() == {"1", "2", "3"}
    for k in whole:
        assert np.array_equal(whole[k][0], streamed[k][0]) and len(whole[k][0]) == 12
        np.testing.assert_allclose(streamed[k][1], whole[k][1], rtol=1e-12, atol=0)


def test_stream_flag_and_reference_motion(tmp_path):
    """--stream streams any record; a moving reference is taken out as in memory."""
    t, g = _record(n=6000)
    rng = np.random.default_rng(3)
    ref = np.zeros((t.size, 3))
    ref[:, 2] = 5.0 * np.sin(2 * np.pi * 0.1 * t)
    from gyroarray.core.layout import Layout
    H = Layout.conical(1, 3, np.deg2rad(54.7356)).H
    g = g + ref @ np.asarray(H).T + 1e-3 * rng.standard_normal(g.shape)
    cols = {**_columns(t, g), "ref_x": ref[:, 0], "ref_y": ref[:, 1], "ref_z": ref[:, 2]}
    path = _parquet(tmp_path, "m", cols)
    _, whole = _adev(run_cli(["allan", path, "--json"]))
    out, streamed = _adev(run_cli(["allan", path, "--json", "--stream"]))
    assert out["signal"].startswith("gyro output minus layout")
    for k in whole:
        np.testing.assert_allclose(streamed[k][1], whole[k][1], rtol=1e-12, atol=0)


def test_streamed_moving_record_needs_all(tmp_path):
    t, g = _record(n=6000)
    g[3000:3500] += 30.0                                            # a turn, no reference
    path = _parquet(tmp_path, "mv", _columns(t, g))
    o = run_cli(["allan", path, "--stream"])
    assert_contract(o, "mv.parquet")
    assert o.code == 2 and "moves" in o.err and "--all" in o.err
    o = run_cli(["allan", path, "--stream", "--all", "--json"])
    assert o.code == 0, o.err
    assert any(n.startswith("--all: the whole record analysed") for n in json.loads(o.out)["notes"])


@pytest.mark.parametrize("stream", [False, True])
def test_bad_parquet_refused_by_file_column_row(tmp_path, stream):
    t, g = _record(n=3000)
    extra = ["--stream", "--max-memory", "512K"] if stream else []   # streamed: chunks of 256 rows
    cases = []
    cols = _columns(t, g)
    del cols["gyro2"]
    cases.append((_parquet(tmp_path, "missing", {**cols, "gyro3": g[:, 2]}), "gyro"))
    text = [repr(float(v)) for v in g[:, 1]]
    text[1233] = "abc"
    cases.append((_parquet(tmp_path, "text", {**_columns(t, g), "gyro2": text}), "row 1234"))
    nan = g.copy()
    nan[2000, 2] = np.nan
    cases.append((_parquet(tmp_path, "nan", _columns(t, nan)), "row 2001"))
    back = t.copy()
    back[1024] = back[1023]                  # the first row of the fifth 256-row chunk
    cases.append((_parquet(tmp_path, "back", _columns(back, g)), "row 1025, column time_s"))
    notime = _columns(t, g)
    del notime["time_s"]
    cases.append((_parquet(tmp_path, "notime", notime), "time_s"))
    for path, where in cases:
        o = run_cli(["allan", path, *extra])
        assert_contract(o, path.name)
        assert o.code == 2 and where in o.err, o.err
    o = run_cli(["allan", tmp_path / "text.parquet", *extra])
    assert "column gyro2" in o.err and "'abc'" in o.err
    o = run_cli(["allan", tmp_path / "nan.parquet", *extra])
    assert "column gyro3" in o.err and "NaN" in o.err
    (tmp_path / "junk.parquet").write_bytes(b"not parquet at all")
    (tmp_path / "junk.toml").write_text(SIDECAR_3)
    o = run_cli(["allan", tmp_path / "junk.parquet", *extra])
    assert_contract(o, "junk.parquet")
    assert o.code == 2 and "Parquet" in o.err


def test_diagnose_beyond_the_budget_refused_with_the_way_out(tmp_path):
    t, g = _record()
    path = _parquet(tmp_path, "big", _columns(t, g))
    o = run_cli(["diagnose", path, "--max-memory", "512K"])
    assert_contract(o, "big.parquet")
    assert o.code == 2 and "limit of 512 KiB" in o.err and "allan streams" in o.err, o.err


def test_streamed_csv_that_is_not_text_is_refused_fast(tmp_path):
    """A streamed CSV with NUL bytes or a line beyond 1 MiB is refused, not read into memory."""
    head = b"time_s,gyro1,gyro2,gyro3\n0,1,2,3\n0.02,1,2,3\n"
    (tmp_path / "nul.csv").write_bytes(head + b"\x00" * (2 << 20))
    (tmp_path / "long.csv").write_bytes(head + b"1" * (3 << 20) + b"\n")
    for name, what in (("nul.csv", "NUL byte"), ("long.csv", "a line longer than 1 MiB")):
        (tmp_path / name.replace(".csv", ".toml")).write_text(SIDECAR_3)
        o = run_cli(["allan", tmp_path / name, "--stream"])
        assert_contract(o, name)
        assert o.code == 2 and what in o.err and "MiB" in o.err, o.err
