"""The malformed-measurement corpus: each case, its files and its expected refusal.

Every case is a small measurement pair (``<case>.csv`` or ``<case>.csv.gz``
plus ``<case>.toml``) that breaks exactly one rule of
``shared/spec/measurement-format.md`` (or of the reader's documented
choices), with the fragment of the message and the location (file, line,
column) that :func:`gyroarray.core.measurement.read_measurement` must report.

The files are committed under ``tests/data/bad/``; regenerate them with::

    python tests/bad_corpus.py

Generation is deterministic (no timestamps; gzip members are written with
stored deflate blocks, so the bytes do not depend on the zlib build), and
``tests/test_measurement_bad.py`` checks that the committed files equal what
this module generates.

Layout of the base case: two comment lines, the header on line 3, then 20
samples at 10 Hz, so sample k (0-based) is on line ``4 + k``.
"""

from __future__ import annotations

import struct
import sys
import zlib
from dataclasses import dataclass
from pathlib import Path

#: Where the corpus is committed.
CORPUS_DIR = Path(__file__).resolve().parent / "data" / "bad"

HEADER = "time_s,gyro1,gyro2,gyro3"
N_ROWS = 20
FIRST_ROW_LINE = 4

BASE_TOML = """\
sample_rate_hz = 10.0
description = "bad-corpus base case"

[layout]
scheme = 1
n_gyros = 3
alpha_deg = 54.7356
"""

_LAYOUT_CONE = "[layout]\nscheme = 1\nn_gyros = 3\nalpha_deg = 54.7356\n"


@dataclass(frozen=True)
class Case:
    """One malformed measurement and the refusal it must produce.

    Parameters
    ----------
    name : str
        File stem of the case.
    csv : bytes
        Content of the CSV file exactly as written (already compressed or
        corrupted for gzip cases).
    toml : bytes or None
        Content of the sidecar; None: no sidecar is written.
    fragment : str
        Text the error message must contain.
    file : {"csv", "toml"}
        Which of the two files the message must name.
    line : int or None
        Expected 1-based line (None: the message gives no line).
    column : str, int or None
        Expected column (CSV column name, character column or TOML key).
    gz : bool
        The CSV is named ``<name>.csv.gz``.
    repair : bool
        Read with ``repair=True`` (the case must be refused even then).
    """

    name: str
    csv: bytes
    toml: bytes | None
    fragment: str
    file: str
    line: int | None
    column: str | int | None
    gz: bool = False
    repair: bool = False

    @property
    def csv_name(self) -> str:
        return f"{self.name}.csv.gz" if self.gz else f"{self.name}.csv"

    @property
    def toml_name(self) -> str:
        return f"{self.name}.toml"


# -- building blocks ----------------------------------------------------------
def base_rows() -> list[list[str]]:
    """20 samples at 10 Hz: time and three gyro readings, as cell strings."""
    return [[f"{k / 10:.1f}", f"{0.01 * k:.2f}", f"{-0.02 * k:.2f}", f"{0.5 + 0.01 * k:.2f}"]
            for k in range(N_ROWS)]


def line_of(k: int) -> int:
    """File line of sample k of the base case."""
    return FIRST_ROW_LINE + k


def csv_text(rows=None, header: str = HEADER, comments=("bad corpus", "10 Hz, 3 gyros")) -> str:
    """CSV text: comment lines, header, rows (lists of cells or raw strings)."""
    rows = base_rows() if rows is None else rows
    lines = [f"# {c}" for c in comments] + [header]
    lines += [r if isinstance(r, str) else ",".join(r) for r in rows]
    return "\n".join(lines) + "\n"


def with_cell(k: int, j: int, value: str) -> list[list[str]]:
    """Base rows with cell (sample k, column j) replaced."""
    rows = base_rows()
    rows[k][j] = value
    return rows


def toml_text(replace: dict[str, str] | None = None, append: str = "") -> str:
    """The base sidecar with whole lines replaced (old line -> new text) and text appended."""
    text = BASE_TOML
    for old, new in (replace or {}).items():
        assert old in text, old
        text = text.replace(old, new)
    return text + append


def gzip_stored(data: bytes) -> bytes:
    """A gzip member with stored (uncompressed) deflate blocks: the same bytes everywhere."""
    deflate = zlib.compressobj(0, zlib.DEFLATED, -15)
    body = deflate.compress(data) + deflate.flush()
    header = b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\xff"   # no name, mtime 0, OS unknown
    return header + body + struct.pack("<II", zlib.crc32(data), len(data) & 0xFFFFFFFF)


def _case(name, fragment, *, csv=None, toml=None, file="csv", line=None, column=None,
          gz=False, repair=False, no_toml=False) -> Case:
    csv_bytes = csv if isinstance(csv, bytes) else (csv or csv_text()).encode("utf-8")
    toml_bytes = None if no_toml else (toml if isinstance(toml, bytes)
                                       else (toml or BASE_TOML).encode("utf-8"))
    return Case(name, csv_bytes, toml_bytes, fragment, file, line, column, gz, repair)


# -- the cases ----------------------------------------------------------------
def _csv_structure_cases() -> list[Case]:
    rows_long = base_rows()
    rows_long[3].append("9.9")
    rows_short = base_rows()
    rows_short[8] = rows_short[8][:3]
    rows_trailing = base_rows()
    rows_trailing[5].append("")
    rows_spaces = base_rows()
    rows_spaces.insert(6, "   ")
    rows_cr = base_rows()
    rows_cr[3] = ",".join(rows_cr[3][:2]) + "\r" + ",".join(rows_cr[3][2:])
    text = csv_text().encode()
    return [
        _case("empty_file", "empty file", csv=b""),
        _case("comments_only", "no header line", csv="# nothing\n# here\n"),
        _case("header_only", "no data rows after the header", csv=csv_text([]), line=3),
        _case("one_sample", "too few samples: 1, at least 2 needed",
              csv=csv_text(base_rows()[:1]), line=4),
        _case("too_many_fields", "wrong number of fields: 5, the header has 4",
              csv=csv_text(rows_long), line=line_of(3)),
        _case("too_few_fields", "wrong number of fields: 3, the header has 4",
              csv=csv_text(rows_short), line=line_of(8)),
        _case("trailing_comma", "wrong number of fields: 5, the header has 4",
              csv=csv_text(rows_trailing), line=line_of(5)),
        _case("whitespace_line", "wrong number of fields: 1, the header has 4",
              csv=csv_text(rows_spaces), line=line_of(6)),
        _case("bare_carriage_return", "carriage return (\\r) inside a line",
              csv=csv_text(rows_cr), line=line_of(3)),
        _case("not_utf8", "not valid UTF-8 text (byte 0xff)",
              csv=csv_text(with_cell(4, 2, "ZZ")).encode().replace(b"ZZ", b"\xff"),
              line=line_of(4), column=len("0.4,0.04,") + 1),
        _case("not_gzip", "not a valid gzip file", csv=text, gz=True),
        _case("truncated_gzip", "not a valid gzip file", csv=gzip_stored(text)[:-30], gz=True),
        _case("gzip_named_csv", "gzip-compressed but its name does not end in .gz",
              csv=gzip_stored(text)),
    ]


def _header_cases() -> list[Case]:
    def header_case(name, fragment, header, column=None, extra_cells=0):
        rows = [r + ["0.0"] * extra_cells for r in base_rows()]
        return _case(name, fragment, csv=csv_text(rows, header=header), line=3, column=column)

    return [
        header_case("missing_time_column", "required column time_s is missing",
                    "t,gyro1,gyro2,gyro3"),
        header_case("no_gyro_columns", "no gyro columns", "time_s,g1,g2,g3"),
        header_case("gyro_numbering_gap", "gyro4 is out of sequence, gyro3 is missing",
                    "time_s,gyro1,gyro2,gyro4", column="gyro4"),
        header_case("gyro_leading_zero", "gyro01 is out of sequence, gyro1 is missing",
                    "time_s,gyro01,gyro2,gyro3", column="gyro01"),
        header_case("duplicate_column", "duplicate column name 'gyro2' (columns 3 and 5)",
                    "time_s,gyro1,gyro2,gyro3,gyro2", column="gyro2", extra_cells=1),
        header_case("empty_column_name", "header field 3 is empty",
                    "time_s,gyro1,,gyro2,gyro3", column=3, extra_cells=1),
        header_case("partial_reference", "ref_x, ref_y and ref_z must be given together; "
                    "found only ref_x, ref_y", "time_s,gyro1,gyro2,gyro3,ref_x,ref_y",
                    column="ref_x", extra_cells=2),
        _case("gyro_count_mismatch", "gyro count does not match the layout: 3 gyro column(s)",
              toml=toml_text({"n_gyros = 3": "n_gyros = 4"}), line=3),
        header_case("partial_acc", "acc_x, acc_y and acc_z must be given together; found "
                    "only acc_x, acc_z (acc_y missing)", "time_s,gyro1,gyro2,gyro3,acc_x,acc_z",
                    column="acc_x", extra_cells=2),
    ]


def _cell_cases() -> list[Case]:
    quoted = base_rows()
    quoted[3][1] = '"0.3x"'
    note_rows = [r + ["ok"] for r in base_rows()]
    note_rows[2][4] = '"two\nlines"'          # a quoted cell spanning lines 6 and 7
    note_rows[4][2] = "bad"                   # sample 4 is now on line 4 + 4 + 1
    mid_comments = [",".join(r) for r in with_cell(9, 3, "x9")]
    mid_comments[4:4] = ["# a comment in the middle", ""]   # two extra lines before sample 4
    acc_rows = [r + ["0.0", "0.0", "9.80665"] for r in base_rows()]
    acc_rows[5][5] = "-inf"
    return [
        _case("non_numeric_cell", "non-numeric value 'abc' in column gyro2",
              csv=csv_text(with_cell(2, 2, "abc")), line=line_of(2), column="gyro2"),
        _case("non_numeric_time", "non-numeric value '0.4s' in column time_s",
              csv=csv_text(with_cell(4, 0, "0.4s")), line=line_of(4), column="time_s"),
        _case("nul_byte", "non-numeric value '0.1\\x00' in column gyro1",
              csv=csv_text(with_cell(2, 1, "0.1\x00")), line=line_of(2), column="gyro1"),
        _case("infinite_value", "infinite value 'inf' in column gyro1",
              csv=csv_text(with_cell(1, 1, "inf")), line=line_of(1), column="gyro1"),
        _case("overflow_value", "value '1e999' overflows to infinity in column gyro2",
              csv=csv_text(with_cell(1, 2, "1e999")), line=line_of(1), column="gyro2"),
        _case("infinite_acc", "infinite value '-inf' in column acc_y",
              csv=csv_text(acc_rows, header=HEADER + ",acc_x,acc_y,acc_z"), line=line_of(5),
              column="acc_y"),
        _case("nan_cell", "NaN value 'NaN' in column gyro1 (1 missing value(s), line 10); "
              "rerun with --repair", csv=csv_text(with_cell(6, 1, "NaN")),
              line=line_of(6), column="gyro1"),
        _case("empty_cell", "empty cell in column gyro3 (1 missing value(s), line 11)",
              csv=csv_text(with_cell(7, 3, "")), line=line_of(7), column="gyro3"),
        _case("quoted_bad_cell", "non-numeric value '0.3x' in column gyro1",
              csv=csv_text(quoted), line=line_of(3), column="gyro1"),
        _case("bad_cell_after_multiline_field", "non-numeric value 'bad' in column gyro2",
              csv=csv_text(note_rows, header=HEADER + ",note"), line=line_of(4) + 1,
              column="gyro2"),
        _case("bad_cell_after_mid_comments", "non-numeric value 'x9' in column gyro3",
              csv=csv_text(mid_comments), line=line_of(9) + 2, column="gyro3"),
    ]


def _time_and_repair_cases() -> list[Case]:
    def drop(first, stop):
        return base_rows()[:first] + base_rows()[stop:]

    def nan_rows(ks, j, token):
        rows = base_rows()
        for k in ks:
            rows[k][j] = token
        return rows

    return [
        _case("time_decreasing", "time_s is not strictly increasing: 0.3 s at line 9 "
              "follows 0.4 s at line 8", csv=csv_text(with_cell(5, 0, "0.3")),
              line=line_of(5), column="time_s"),
        _case("time_repeated", "time_s is not strictly increasing: 0.4 s at line 9 "
              "follows 0.4 s at line 8", csv=csv_text(with_cell(5, 0, "0.4")),
              line=line_of(5), column="time_s"),
        _case("time_missing", "empty cell in column time_s: sample times cannot be missing",
              csv=csv_text(with_cell(4, 0, "")), line=line_of(4), column="time_s",
              repair=True),
        _case("short_gap", "gap of 2 missing sample(s) between line 7 (t = 0.3 s) and "
              "line 8 (t = 0.6 s)", csv=csv_text(drop(4, 6)), line=8, column="time_s"),
        _case("gap_too_long", "gap of 7 missing sample(s) between line 7 (t = 0.3 s) and "
              "line 8 (t = 1.1 s) (nominal period 0.1 s); gaps longer than 5 samples "
              "cannot be repaired", csv=csv_text(drop(4, 11)), line=8, column="time_s",
              repair=True),
        _case("missing_run_too_long", "run of 6 missing values in column gyro2 (NaN value "
              "'nan', lines 9-14) is longer than 5 samples",
              csv=csv_text(nan_rows(range(5, 11), 2, "nan")), line=line_of(5),
              column="gyro2", repair=True),
        _case("missing_at_start", "missing value(s) at the start of column gyro1 (empty "
              "cell, line 4) cannot be interpolated", csv=csv_text(nan_rows([0], 1, "")),
              line=line_of(0), column="gyro1", repair=True),
        _case("missing_at_end", "missing value(s) at the end of column gyro3 (NaN value "
              "'NaN', lines 22-23) cannot be interpolated",
              csv=csv_text(nan_rows([18, 19], 3, "NaN")), line=line_of(18), column="gyro3",
              repair=True),
    ]


def _sidecar_cases() -> list[Case]:
    def side(name, fragment, toml, line=None, column=None):
        return _case(name, fragment, toml=toml, file="toml", line=line, column=column)

    rate = "sample_rate_hz = 10.0\n"
    axes = ("[layout]\naxes = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], "
            "[0.0, 0.5, 0.5]]\n")
    site = "\n[site]\nlatitude_deg = 34.25\nheading_deg = 0.0\n"
    pos = ("[0.02, 0.0, 0.0]", "[-0.01, 0.0173, 0.0]", "[-0.01, -0.0173, 0.0]")
    return [
        _case("missing_sidecar", "missing sidecar", file="toml", no_toml=True),
        side("toml_syntax_error", "TOML syntax error: Illegal character '\\n'",
             toml_text({'"bad-corpus base case"': '"unterminated'}), line=2, column=28),
        side("toml_duplicate_key", "TOML syntax error: Cannot overwrite a value",
             toml_text(append="n_gyros = 3\n"), line=8, column=12),
        side("toml_integer_too_long", "TOML error: Exceeds the limit (4300 digits)",
             toml_text(append="big = 1" + "0" * 5000 + "\n")),
        side("toml_nested_too_deep", "TOML nested more than 32 levels deep",
             toml_text(append="deep = " + "[" * 5000 + "]" * 5000 + "\n"), line=8, column=40),
        side("toml_not_utf8", "not valid UTF-8 text (byte 0xe9)",
             toml_text({"base case": "caf\xe9"}).encode("latin-1"), line=2, column=30),
        side("sample_rate_missing", "sample_rate_hz is missing",
             toml_text({rate: ""}), column="sample_rate_hz"),
        side("sample_rate_zero", "sample_rate_hz must be > 0, got 0.0",
             toml_text({rate: "sample_rate_hz = 0.0\n"}), line=1, column="sample_rate_hz"),
        side("sample_rate_negative", "sample_rate_hz must be > 0, got -10.0",
             toml_text({rate: "sample_rate_hz = -10\n"}), line=1, column="sample_rate_hz"),
        side("sample_rate_string", "sample_rate_hz must be a number, got a string ('fast')",
             toml_text({rate: 'sample_rate_hz = "fast"\n'}), line=1,
             column="sample_rate_hz"),
        side("sample_rate_infinite", "sample_rate_hz must be finite, got inf",
             toml_text({rate: "sample_rate_hz = inf\n"}), line=1, column="sample_rate_hz"),
        side("description_not_string", "description must be a string, got an integer (42)",
             toml_text({'"bad-corpus base case"': "42"}), line=2, column="description"),
        side("layout_missing", "[layout] is missing",
             toml_text({_LAYOUT_CONE: ""}), column="layout"),
        side("layout_not_table", "layout must be a table ([layout]), got an integer (3)",
             toml_text({_LAYOUT_CONE: "layout = 3\n"}), line=4, column="layout"),
        side("layout_incomplete", "layout is incomplete: give axes, or all of scheme, "
             "n_gyros and alpha_deg (missing: alpha_deg)",
             toml_text({"alpha_deg = 54.7356\n": ""}), line=4, column="layout"),
        side("layout_unknown_key", "unknown key layout.alpha (known: alpha_deg, axes, "
             "n_gyros, positions_m, scheme)", toml_text({"alpha_deg": "alpha"}), line=7,
             column="layout.alpha"),
        side("scheme_not_1_or_2", "layout.scheme must be 1 or 2, got an integer (3)",
             toml_text({"scheme = 1": "scheme = 3"}), line=5, column="layout.scheme"),
        side("n_gyros_too_small", "layout.n_gyros must be an integer from 3 to 1024, got an "
             "integer (2)", toml_text({"n_gyros = 3": "n_gyros = 2"}), line=6,
             column="layout.n_gyros"),
        side("n_gyros_float", "layout.n_gyros must be an integer from 3 to 1024, got a "
             "number (3.0)", toml_text({"n_gyros = 3": "n_gyros = 3.0"}), line=6,
             column="layout.n_gyros"),
        side("n_gyros_huge", "layout.n_gyros must be an integer from 3 to 1024, got an "
             "integer (1" + "0" * 38, toml_text({"n_gyros = 3": "n_gyros = 1" + "0" * 400}),
             line=6, column="layout.n_gyros"),
        side("sample_rate_overflows", "sample_rate_hz must be finite, got 1" + "0" * 39,
             toml_text({"sample_rate_hz = 10.0": "sample_rate_hz = 1" + "0" * 400}), line=1,
             column="sample_rate_hz"),
        side("axis_overflows", "layout.axes must hold finite numbers",
             toml_text({_LAYOUT_CONE: "[layout]\naxes = [[1" + "0" * 400 + ", 0, 0]]\n"}),
             line=5, column="layout.axes"),
        side("alpha_not_numeric", "layout.alpha_deg must be a number, got a string ('abc')",
             toml_text({"54.7356": '"abc"'}), line=7, column="layout.alpha_deg"),
        side("alpha_out_of_range", "layout.alpha_deg must be in [0, 180] deg, got 200.0",
             toml_text({"54.7356": "200"}), line=7, column="layout.alpha_deg"),
        side("axis_not_unit", "axis of gyro 3 [0.0, 0.5, 0.5] is not a unit vector",
             toml_text({_LAYOUT_CONE: axes}), line=5, column="layout.axes"),
        side("axes_not_rows_of_3", "layout.axes must be an array of [x, y, z] rows of "
             "numbers", toml_text({_LAYOUT_CONE: "[layout]\naxes = [[1.0, 0.0], [0.0, 1.0]]\n"}),
             line=5, column="layout.axes"),
        side("positions_count", "positions_m has 2 rows but the layout has 3 gyros",
             toml_text(append=f"positions_m = [{pos[0]}, {pos[1]}]\n"), line=8,
             column="layout.positions_m"),
        side("positions_not_rows", "layout.positions_m must be an array of [x, y, z] rows "
             "of numbers (metres, one per gyro)",
             toml_text(append="positions_m = [[0.02, 0.0], [0.0, 0.02], [0.0, 0.0]]\n"),
             line=8, column="layout.positions_m"),
        side("positions_not_finite", "layout.positions_m must hold finite numbers",
             toml_text(append=f"positions_m = [[nan, 0.0, 0.0], {pos[1]}, {pos[2]}]\n"),
             line=8, column="layout.positions_m"),
        side("positions_in_mm", "positions_m of gyro 2 is 20 m from the platform origin "
             "(more than 10 m: positions are in metres",
             toml_text(append=f"positions_m = [{pos[0]}, [0.0, 20.0, 0.0], {pos[2]}]\n"),
             line=8, column="layout.positions_m"),
        side("axes_strings", "layout.axes must be an array of [x, y, z] rows of numbers",
             toml_text({_LAYOUT_CONE: '[layout]\naxes = [["1", "0", "0"]]\n'}), line=5,
             column="layout.axes"),
        side("latitude_out_of_range", "site.latitude_deg must be in [-90, 90] deg, got 95.0",
             toml_text(append=site.replace("34.25", "95")), line=10,
             column="site.latitude_deg"),
        side("latitude_not_numeric", "site.latitude_deg must be a number, got a string",
             toml_text(append=site.replace("34.25", '"north"')), line=10,
             column="site.latitude_deg"),
        side("site_incomplete", "site.heading_deg is missing",
             toml_text(append=site.replace("heading_deg = 0.0\n", "")), line=9,
             column="site"),
        side("site_unknown_key", "unknown key site.altitude_m",
             toml_text(append=site + "altitude_m = 12.0\n"), line=12,
             column="site.altitude_m"),
        side("unknown_unit", "unknown unit 'furlong/fortnight' for units.gyro",
             toml_text(append='\n[units]\ngyro = "furlong/fortnight"\n'), line=10,
             column="units.gyro"),
        side("unit_not_string", "unknown unit 1 for units.time",
             toml_text(append="\n[units]\ntime = 1\n"), line=10, column="units.time"),
        side("units_unknown_key", "unknown key units.pressure",
             toml_text(append='\n[units]\npressure = "hPa"\n'), line=10,
             column="units.pressure"),
    ]


def cases() -> list[Case]:
    """Every case of the corpus, in a fixed order, names unique."""
    all_cases = (_csv_structure_cases() + _header_cases() + _cell_cases()
                 + _time_and_repair_cases() + _sidecar_cases())
    names = [c.name for c in all_cases]
    assert len(names) == len(set(names)), "case names must be unique"
    return all_cases


def write_corpus(directory: Path) -> list[Path]:
    """Write every case's files into ``directory``, removing stale case files.

    Returns
    -------
    list of Path
        The files written, sorted.
    """
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for case in cases():
        written.append(directory / case.csv_name)
        written[-1].write_bytes(case.csv)
        if case.toml is not None:
            written.append(directory / case.toml_name)
            written[-1].write_bytes(case.toml)
    keep = set(written)
    for stale in directory.iterdir():
        if stale.is_file() and stale not in keep and stale.name.endswith(
                (".csv", ".csv.gz", ".toml")):
            stale.unlink()
    return sorted(written)


def main(argv=None) -> int:
    target = Path(argv[0]) if argv else CORPUS_DIR
    files = write_corpus(target)
    print(f"wrote {len(cases())} cases ({len(files)} files) to {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
