"""Hostile Parquet files, and CSV headers that never end: refused before the work, within the budget.

Reproductions from a hostile-input campaign, each broken before (the cost then in brackets):

* 20,000 columns in 6 MB of Parquet (267 s of CPU before the refusal): the column count is
  checked against ``MAX_COLUMNS`` from the footer, before a name is matched or a sample read;
  the footer's length against the file and the budget before pyarrow parses it;
* row groups claiming -5 or 1e15 rows (``OSError: Negative size``, ``ArrowMemoryError: malloc
  of size 2251799813685248``), a footer whose rows do not add up, a column chunk holding other
  values than its row group's rows, a footer claiming 1000 rows over data of 500: refused from
  the footer (or when the row group's data ends), naming the row group and the column;
* an honest record beyond ``--max-memory``: streamed by ``allan``, refused by a command that
  reads it whole with the size needed and the way out (``--stream``, ``--max-memory``);
* a large text cell in a small file (600 MiB in 21 kB: 2.76 GB, then MemoryError): a
  non-numeric column is refused from its type and the footer's size, not decoded;
* a CSV (and a CSV.GZ) whose header line never ends (2 GiB sparse: 4.51 GB; its 2 MB gzip with
  ``--stream``: 5.04 GB): refused after 1 MiB as "line 1: the header line is longer than 1 MiB".

Lying footers are written here: a valid file from pyarrow, its footer (Thrift compact
``FileMetaData``) decoded by :func:`read_footer`, one field changed (``num_rows`` of the file,
of a row group, ``num_values`` of a column chunk), encoded again by :func:`write_footer` and
put back behind the unchanged data (the chunks' offsets count from the file's start, so they
stay right). Every CLI call runs in this process under an alarm (:func:`hostile.run_cli`); the
peak memory checks (slow) run the CLI in a child process and read its ``ru_maxrss``.
"""

from __future__ import annotations

import io
import json
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from gyroarray.core.limits import format_size
from gyroarray.core.measurement import MAX_COLUMNS, MAX_HEADER_BYTES, read_measurement
from hostile import SIDECAR_3, assert_contract, gzip_bomb, run_cli

RATE = 50.0


# -- a Parquet footer, decoded and encoded (Thrift compact protocol) -----------------------
_TRUE, _FALSE, _BYTE, _I16, _I32, _I64, _DOUBLE, _BINARY, _LIST, _SET, _MAP, _STRUCT = range(1, 13)


def _uvarint(buf: bytes, pos: int) -> tuple[int, int]:
    out = shift = 0
    while True:
        b = buf[pos]
        pos += 1
        out |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return out, pos


def _value(buf: bytes, pos: int, t: int):
    if t in (_TRUE, _FALSE):
        return t == _TRUE, pos
    if t == _BYTE:
        return buf[pos], pos + 1
    if t in (_I16, _I32, _I64):
        v, pos = _uvarint(buf, pos)
        return (v >> 1) ^ -(v & 1), pos                      # zigzag
    if t == _DOUBLE:
        return struct.unpack_from("<d", buf, pos)[0], pos + 8
    if t == _BINARY:
        n, pos = _uvarint(buf, pos)
        return bytes(buf[pos:pos + n]), pos + n
    if t in (_LIST, _SET):
        n, et = buf[pos] >> 4, buf[pos] & 0x0F
        pos += 1
        if n == 15:
            n, pos = _uvarint(buf, pos)
        items = []
        for _ in range(n):
            if et in (_TRUE, _FALSE):                           # a bool element: one byte
                v, pos = buf[pos] == 1, pos + 1
            else:
                v, pos = _value(buf, pos, et)
            items.append(v)
        return [et, items], pos
    if t == _STRUCT:
        return _struct(buf, pos)
    raise ValueError(f"Thrift type {t} is not used by Parquet's footer")


def _struct(buf: bytes, pos: int):
    fields, last = [], 0
    while True:
        head = buf[pos]
        pos += 1
        if head == 0:
            return fields, pos
        delta, t = head >> 4, head & 0x0F
        if delta:
            fid = last + delta
        else:
            v, pos = _uvarint(buf, pos)
            fid = (v >> 1) ^ -(v & 1)
        v, pos = _value(buf, pos, t)
        fields.append([fid, t, v])
        last = fid


def _w_uvarint(n: int) -> bytes:
    out = bytearray()
    while True:
        b, n = n & 0x7F, n >> 7
        out.append(b | 0x80 if n else b)
        if not n:
            return bytes(out)


def _w_int(n: int) -> bytes:
    return _w_uvarint((n << 1) ^ (n >> 63))


def _w_value(t: int, v) -> bytes:
    if t in (_TRUE, _FALSE):
        return b""
    if t == _BYTE:
        return bytes([v])
    if t in (_I16, _I32, _I64):
        return _w_int(v)
    if t == _DOUBLE:
        return struct.pack("<d", v)
    if t == _BINARY:
        return _w_uvarint(len(v)) + v
    if t in (_LIST, _SET):
        et, items = v
        head = (bytes([(len(items) << 4) | et]) if len(items) < 15
                else bytes([0xF0 | et]) + _w_uvarint(len(items)))
        return head + b"".join(bytes([1 if x else 2]) if et in (_TRUE, _FALSE) else _w_value(et, x)
                               for x in items)
    if t == _STRUCT:
        return _w_struct(v)
    raise ValueError(t)


def _w_struct(fields) -> bytes:
    out, last = bytearray(), 0
    for fid, t, v in fields:
        if t in (_TRUE, _FALSE):
            t = _TRUE if v else _FALSE
        d = fid - last
        out += bytes([(d << 4) | t]) if 0 < d <= 15 else bytes([t]) + _w_int(fid)
        out += _w_value(t, v)
        last = fid
    return bytes(out) + b"\x00"


def read_footer(raw: bytes):
    """(the bytes before the footer, the footer's ``FileMetaData`` as [field id, type, value])."""
    n = struct.unpack_from("<I", raw, len(raw) - 8)[0]
    meta, _ = _struct(raw[len(raw) - 8 - n:len(raw) - 8], 0)
    return raw[:len(raw) - 8 - n], meta


def write_footer(body: bytes, meta) -> bytes:
    """``body`` + the encoded footer + its length + ``PAR1``."""
    f = _w_struct(meta)
    return body + f + struct.pack("<I", len(f)) + b"PAR1"


def _field(fields, fid: int) -> list:
    return next(f for f in fields if f[0] == fid)


# FileMetaData: 3 num_rows, 4 row_groups; RowGroup: 1 columns, 3 num_rows; ColumnChunk:
# 3 meta_data; ColumnMetaData: 5 num_values (parquet.thrift)
def forged(raw: bytes, *, file_rows=None, group_rows=None, values=None) -> bytes:
    """``raw`` (a Parquet file) with its footer's row counts replaced where given."""
    body, meta = read_footer(raw)
    if file_rows is not None:
        _field(meta, 3)[2] = file_rows
    for rg in _field(meta, 4)[2][1]:
        if group_rows is not None:
            _field(rg, 3)[2] = group_rows
        for chunk in _field(rg, 1)[2][1]:
            if values is not None:
                _field(_field(chunk, 3)[2], 5)[2] = values
    return write_footer(body, meta)


# -- files ---------------------------------------------------------------------------------
def _columns(n: int, seed: int = 3) -> dict:
    rng = np.random.default_rng(seed)
    g = 0.2 + 0.05 * rng.standard_normal((n, 3))
    return {"time_s": np.arange(n) / RATE, **{f"gyro{k + 1}": g[:, k] for k in range(3)}}


def _parquet_bytes(columns: dict, **kw) -> bytes:
    sink = io.BytesIO()
    pq.write_table(pa.table(columns), sink, **kw)
    return sink.getvalue()


def _put(folder: Path, name: str, data: bytes, sidecar: str = SIDECAR_3) -> Path:
    path = folder / name
    path.write_bytes(data)
    stem = name[:-len(".csv.gz")] if name.endswith(".csv.gz") else path.stem
    (folder / f"{stem}.toml").write_text(sidecar)
    return path


def refused(o, path: Path, *words: str) -> str:
    """Exit 2, one stderr line naming the file and holding each of ``words``."""
    assert_contract(o, path.name)
    assert o.code == 2, (o.code, o.out[-300:], o.err)
    for w in words:
        assert w in o.err, (w, o.err)
    return o.err


WHOLE_AND_STREAMED = [[], ["--stream"]]


# -- the column count and the footer, before any data -------------------------------------

def _wide(tmp_path: Path, n_columns: int) -> Path:
    cols = {"time_s": np.array([0.0, 0.02])}
    cols.update({f"gyro{k}": np.zeros(2) for k in range(1, n_columns)})
    return _put(tmp_path, "wide.parquet", _parquet_bytes(cols, compression="none"))


def test_too_many_columns_refused_from_the_footer(tmp_path):
    """3,000 columns (time_s, gyro1..gyro2999) in 2 rows: refused by their count from the footer,
    before a name is matched or a sample read (read whole or streamed)."""
    path = _wide(tmp_path, 3000)
    for extra in WHOLE_AND_STREAMED:
        err = refused(run_cli(["allan", path, *extra], timeout=60), path,
                      "3000 columns", f"more than the {MAX_COLUMNS}")
        assert "nothing read beyond its footer" in err


@pytest.mark.slow
def test_twenty_thousand_columns_refused_from_the_footer(tmp_path):
    """The campaign's file: 20,001 columns (time_s, gyro1..gyro20000), 6 MB; the matching of
    names was quadratic (267 s of CPU before the refusal). Slow only for writing the file."""
    path = _wide(tmp_path, 20001)
    assert path.stat().st_size > 5e6
    refused(run_cli(["allan", path], timeout=60), path, "20001 columns", f"more than the {MAX_COLUMNS}")


def test_csv_header_of_twenty_thousand_columns_refused(tmp_path):
    """The same header as a CSV (190 kB, under the 1 MiB header limit): refused by its count, in
    memory and streamed."""
    header = ",".join(["time_s", *(f"gyro{k}" for k in range(1, 20001))])
    row = ",".join(["0"] * 20001)
    path = _put(tmp_path, "wide.csv", f"{header}\n{row}\n{row.replace('0', '1', 1)}\n".encode())
    for extra in WHOLE_AND_STREAMED:
        err = refused(run_cli(["allan", path, *extra], timeout=60), path, "20001 columns")
        assert "line 1" in err


def test_footer_length_beyond_the_file_refused(tmp_path):
    """The 4 bytes before the closing PAR1 say the footer is 100 MB in a file of 2.4 kB: refused
    before pyarrow reads it."""
    raw = bytearray(_parquet_bytes(_columns(50)))
    raw[-8:-4] = struct.pack("<I", 100_000_000)
    path = _put(tmp_path, "longfoot.parquet", bytes(raw))
    refused(run_cli(["allan", path]), path, "footer says it is 100000000 bytes",
            f"file's {len(raw)} bytes")
    (tmp_path / "short.parquet").write_bytes(b"PAR1PAR1")
    (tmp_path / "short.toml").write_text(SIDECAR_3)
    refused(run_cli(["allan", tmp_path / "short.parquet"]), tmp_path / "short.parquet",
            "not a readable Parquet file", "PAR1")


def test_footer_beyond_the_budget_refused(tmp_path):
    """A footer of 1.3 MB (3000 row groups of 2 rows) under --max-memory 64M: the footer cap
    there is 1 MiB (a 64th of the budget, at least 1 MiB): refused before pyarrow parses it."""
    raw = _parquet_bytes(_columns(6000), row_group_size=2)
    footer = struct.unpack("<I", raw[-8:-4])[0]
    assert footer > 1 << 20                   # what the test is about
    path = _put(tmp_path, "groups.parquet", raw)
    refused(run_cli(["allan", path, "--max-memory", "64M"]), path, "Parquet footer",
            "more than the 1 MiB gyroarray reads", "--max-memory")


# -- row counts the footer lies about ------------------------------------------------------

@pytest.mark.parametrize("extra", WHOLE_AND_STREAMED)
@pytest.mark.parametrize("forge, words", [
    ({"group_rows": -5}, ["row group 1 of 1", "-5 rows", "never negative"]),
    ({"file_rows": -5}, ["the footer says -5 rows, its row groups hold 1000"]),
    ({"file_rows": -5, "group_rows": -5}, ["row group 1 of 1", "-5 rows"]),
    ({"group_rows": 10**15}, ["1000000000000000 rows", "column time_s's data holds 1000 values"]),
    ({"file_rows": 10**15}, ["the footer says 1000000000000000 rows, its row groups hold 1000"]),
    ({"file_rows": 10**15, "group_rows": 10**15, "values": 10**15},
     ["1000000000000000 rows", "time_s data", "holds at most"]),
])
def test_forged_row_counts_refused_from_the_footer(tmp_path, forge, words, extra):
    """Negative and 1e15 row counts (pyarrow: ``OSError: Negative size``, a malloc of 2**51
    bytes) are refused from the footer, before any data is read, read whole or streamed."""
    honest = _parquet_bytes(_columns(1000))
    path = _put(tmp_path, "forged.parquet", forged(honest, **forge))
    err = refused(run_cli(["allan", path, "--max-memory", "200M", *extra]), path,
                  "corrupt or forged Parquet footer", *words)
    if "values" in forge:                      # the bound: 1024 rows per byte of time_s as encoded
        encoded = pq.ParquetFile(io.BytesIO(honest)).metadata.row_group(0).column(0)
        assert f"holds at most {1024 * encoded.total_uncompressed_size} rows" in err, err


@pytest.mark.parametrize("extra", WHOLE_AND_STREAMED)
def test_footer_claiming_more_rows_than_its_data_refused(tmp_path, extra):
    """A file of 500 rows whose footer says 1000 everywhere (file, row group, every column
    chunk's value count): pyarrow reads 500 rows without a word; refused as "the footer says 1000
    rows, the data holds 500" (whole: after the read; streamed: when the row group ends)."""
    raw = forged(_parquet_bytes(_columns(500)), file_rows=1000, group_rows=1000, values=1000)
    path = _put(tmp_path, "say1000.parquet", raw)
    refused(run_cli(["allan", path, *extra]), path, "the footer says 1000 rows, the data holds 500",
            "corrupt or forged Parquet footer")
    raw = forged(_parquet_bytes(_columns(500)), file_rows=1000, group_rows=1000)
    path = _put(tmp_path, "rows1000.parquet", raw)         # the chunks still say 500 values
    refused(run_cli(["allan", path, *extra]), path, "the footer says 1000 rows",
            "column time_s's data holds 500 values")


def test_forged_footer_refused_by_the_reader_itself(tmp_path):
    """:func:`read_measurement` (what every command reading a record whole uses) refuses the
    same footers, naming the file."""
    from gyroarray.core.errors import InputError
    for i, forge in enumerate(({"group_rows": -5}, {"group_rows": 10**15},
                               {"file_rows": 1000, "group_rows": 1000, "values": 1000})):
        rows = 500 if "values" in forge else 1000
        path = _put(tmp_path, f"f{i}.parquet", forged(_parquet_bytes(_columns(rows)), **forge))
        with pytest.raises(InputError, match="forged Parquet footer") as err:
            read_measurement(path)
        assert err.value.file == str(path)


def test_truncated_data_refused_from_the_footer(tmp_path):
    """8 kB cut from the middle of the data (the footer kept): the chunks beyond the cut lie
    outside the file's data, refused by row group and column before reading."""
    raw = _parquet_bytes(_columns(4000), compression="none")
    body, meta = read_footer(raw)
    cut = body[:len(body) // 2] + body[len(body) // 2 + 8192:]
    path = _put(tmp_path, "cut.parquet", write_footer(cut, meta))
    for extra in WHOLE_AND_STREAMED:
        refused(run_cli(["allan", path, *extra]), path, "row group 1 of 1",
                "lies outside the file's data", "corrupt or truncated Parquet file")


# -- the memory budget ---------------------------------------------------------------------

def test_honest_record_beyond_the_budget_streamed_or_refused_with_the_way_out(tmp_path):
    """20,000 honest rows (4 MB to read whole) under --max-memory 2M: ``allan`` streams them
    (the same ADEV as in memory, to 1e-12 relative), ``convert`` refuses with the size needed and
    the ways out."""
    path = _put(tmp_path, "long.parquet", _parquet_bytes(_columns(20000)))
    o = run_cli(["allan", path, "--json", "--max-memory", "2M"])
    assert_contract(o, path.name)
    assert o.code == 0, o.err
    streamed = o.json
    assert streamed["streamed"]["n_samples"] == 20000
    whole = run_cli(["allan", path, "--json"]).json
    for k in ("1", "2", "3"):
        a = np.asarray(streamed["gyros"][k]["adev_deg_h"], float)
        b = np.asarray(whole["gyros"][k]["adev_deg_h"], float)
        assert a.shape == b.shape and a.size >= 8
        np.testing.assert_allclose(a, b, rtol=1e-12)
    err = refused(run_cli(["convert", path, "--out", tmp_path / "out.csv.gz", "--max-memory", "2M"]),
                  path, "reading 20000 rows x 4 columns needs about", "limit of 2 MiB",
                  "--stream", "--max-memory")
    rg = pq.ParquetFile(path).metadata.row_group(0)
    pages = sum(rg.column(j).total_compressed_size + rg.column(j).total_uncompressed_size
                for j in range(4))
    need = 20000 * 4 * 40 + max(0, pages - 16 * 20000 * 4)   # 40 B a value, and the pages beyond 16
    assert f"needs about {format_size(need)} of memory" in err and need > 3.05 * 2**20, err
    assert not (tmp_path / "out.csv.gz").exists()


def test_large_text_cell_refused_from_the_schema_not_decoded(tmp_path):
    """A 20 MiB text cell in a 1.6 kB file (the campaign's was 600 MiB in 21 kB: decoded, 2.76 GB)
    under --max-memory 200M: the column's type and its size in the footer refuse it, nothing
    decoded (the search for the first non-number cell is for chunks of at most 12.5 MiB here)."""
    cols = _columns(2)
    cols["gyro2"] = pa.array(["x" * (20 << 20), "0.5"])
    raw = _parquet_bytes(cols, compression="zstd")
    assert len(raw) < 4096
    path = _put(tmp_path, "cell.parquet", raw)
    for extra in WHOLE_AND_STREAMED:
        refused(run_cli(["allan", path, "--max-memory", "200M", *extra]), path,
                "column gyro2 holds string values, not numbers", "20 MiB in a row group, not read",
                "float64")


def test_small_text_column_still_names_its_cell(tmp_path):
    """A small text column is still searched: the refusal names the row and the cell."""
    cols = _columns(300)
    text = [repr(float(v)) for v in cols["gyro2"]]
    text[122] = "abc"
    cols["gyro2"] = text
    path = _put(tmp_path, "text.parquet", _parquet_bytes(cols))
    refused(run_cli(["allan", path, "--max-memory", "200M"]), path, "row 123", "'abc'",
            "column gyro2")


# -- a CSV header that never ends -----------------------------------------------------------

def _sparse(path: Path, size: int) -> Path:
    with open(path, "wb") as fh:
        fh.truncate(size)                     # a hole: no disk, all zero bytes
    return path


@pytest.mark.parametrize("extra", WHOLE_AND_STREAMED)
def test_csv_header_that_never_ends_refused_after_1_mib(tmp_path, extra):
    """A sparse 2 GiB CSV of zero bytes (its header line never ends): plain ``allan`` (which
    streams it, judging by its size) reached 4.51 GB; now line 1 is refused after 1 MiB."""
    path = _sparse(tmp_path / "hole.csv", 2 << 30)
    (tmp_path / "hole.toml").write_text(SIDECAR_3)
    refused(run_cli(["allan", path, *extra]), path, "line 1", "the header line is longer than 1 MiB")


def test_csv_header_that_never_ends_refused_by_the_in_memory_reader(tmp_path):
    """``convert`` (read whole) and :func:`read_measurement`: the header's length is checked
    before the file is read (the 64 MiB of the file would fit the budget)."""
    from gyroarray.core.errors import InputError
    path = _put(tmp_path, "zeros.csv", b"time_s,gyro1,gyro2,gyro3" + b"0" * (64 << 20))
    refused(run_cli(["convert", path, "--out", tmp_path / "z.parquet"]), path, "line 1",
            "the header line is longer than 1 MiB")
    with pytest.raises(InputError, match="header line is longer than 1 MiB") as err:
        read_measurement(path)
    assert err.value.line == 1 and err.value.file == str(path)


@pytest.mark.parametrize("extra", WHOLE_AND_STREAMED)
def test_gzip_of_a_header_that_never_ends_refused(tmp_path, extra):
    """A 64 kB .csv.gz of 64 MiB zeros (the campaign's: 2 MB of 2 GiB, 5.04 GB with --stream):
    line 1 refused after 1 MiB decompressed."""
    path = gzip_bomb(tmp_path / "bomb.csv.gz", b"", b"\x00", 64 << 20)
    (tmp_path / "bomb.toml").write_text(SIDECAR_3)
    assert path.stat().st_size < 1 << 20
    refused(run_cli(["allan", path, *extra]), path, "line 1", "the header line is longer than 1 MiB")


def test_comment_lines_before_the_header_are_bounded(tmp_path):
    """A comment line that never ends, and 17 MiB of comments before any header: refused (the
    lines before the header are read 1 MiB at a time, 16 MiB in all)."""
    long = _put(tmp_path, "longc.csv", b"# a note\n#" + b"x" * (2 << 20) + b"\n")
    refused(run_cli(["allan", long, "--stream"]), long, "line 2", "a comment line is longer than 1 MiB")
    many = _put(tmp_path, "many.csv", (b"#" + b"x" * 1000 + b"\n") * 17000 + b"time_s,gyro1\n")
    refused(run_cli(["allan", many, "--stream"]), many, "no header line in the first")


def test_header_at_the_limit_is_read(tmp_path):
    """A header of exactly 1 MiB (the gyros, then 256 extra columns with long names) is still a
    header: the bound refuses only what is longer."""
    cols = _columns(400)
    names = list(cols) + [f"x{k:03d}".ljust(4000, "p") for k in range(256)]
    head = ",".join(names)
    names[-1] += "q" * (MAX_HEADER_BYTES - len(head))
    head = ",".join(names)
    assert len(head) == MAX_HEADER_BYTES
    pad = ",0" * 256
    rows = "\n".join(",".join(map(repr, (float(cols[c][i]) for c in cols))) + pad
                     for i in range(400))
    path = _put(tmp_path, "wide_head.csv", f"{head}\n{rows}\n".encode())
    m = read_measurement(path)
    assert m.n_samples == 400 and m.n_gyros == 3
    np.testing.assert_array_equal(m.gyro_deg_s[:, 1], cols["gyro2"])


# -- peak memory of the child process (slow: a fresh interpreter per call) -----------------

def _peak_rss_mb(argv) -> tuple[int, str, float]:
    """(exit status, stderr, peak RSS [MiB]) of ``gyroarray ARGV`` in a child of a child (its
    ``RUSAGE_CHILDREN`` holds that one call only)."""
    code = ("import resource, subprocess, sys, json\n"
            "p = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
            "print(json.dumps([p.returncode, p.stderr, "
            "resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024]))\n")
    cli = [sys.executable, "-m", "gyroarray.cli.main", *map(str, argv)]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", code, *cli], capture_output=True, text=True,
                         timeout=600, env=env, check=True)
    rc, err, rss = json.loads(out.stdout)
    return int(rc), err, float(rss)


@pytest.mark.slow
def test_peak_memory_within_the_budget(tmp_path):
    """Under --max-memory 100M, beside the same command on a 2-row file (the interpreter and its
    libraries): 2e6 honest rows streamed by ``allan`` stay within the budget; a 64 MiB text
    cell, a forged 1e15-row footer and a 2 GiB CSV whose header never ends are refused with
    less than 32 MiB beyond the interpreter."""
    small = _put(tmp_path, "small.parquet", _parquet_bytes(_columns(300)))
    _, _, base = _peak_rss_mb(["allan", small, "--max-memory", "100M", "--stream"])
    big = _put(tmp_path, "big.parquet", _parquet_bytes(_columns(2_000_000)))
    rc, err, rss = _peak_rss_mb(["allan", big, "--max-memory", "100M"])
    assert rc == 0, err
    assert rss - base < 100, (rss, base)
    cols = _columns(2)
    cols["gyro2"] = pa.array(["x" * (64 << 20), "0.5"])
    cell = _put(tmp_path, "cell.parquet", _parquet_bytes(cols, compression="zstd"))
    lie = _put(tmp_path, "lie.parquet", forged(_parquet_bytes(_columns(1000)), file_rows=10**15,
                                               group_rows=10**15, values=10**15))
    hole = _sparse(tmp_path / "hole.csv", 2 << 30)
    (tmp_path / "hole.toml").write_text(SIDECAR_3)
    for path in (cell, lie, hole):
        for extra in WHOLE_AND_STREAMED:
            rc, err, rss = _peak_rss_mb(["allan", path, "--max-memory", "100M", *extra])
            assert rc == 2 and path.name in err and len(err.strip().splitlines()) == 1, err
            assert rss - base < 32, (path.name, extra, rss, base)
