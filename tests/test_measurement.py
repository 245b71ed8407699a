"""Reading and writing measurement files (``shared/spec/measurement-format.md``).

The real and practice files are read from ``../shared/measurements`` beside
the clone (never copied into the repository); the tests that need them are
skipped, with the reason, when it is absent.
"""

from __future__ import annotations

import gzip
import hashlib
import math
from pathlib import Path

import numpy as np
import pytest

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, Site, read_measurement, write_measurement
from gyroarray.core.units import deg_to_rad, rad_s_to_deg_s

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
MEASUREMENTS = SHARED / "measurements"
needs_shared = pytest.mark.skipif(
    not MEASUREMENTS.is_dir(),
    reason=f"shared measurements not found at {MEASUREMENTS} (CI puts ../shared beside the clone)")

ADIS = MEASUREMENTS / "real" / "adis16405_static.csv.gz"
MIMU = MEASUREMENTS / "real" / "mimu4444_array24.csv.gz"
PRACTICE = {p: MEASUREMENTS / "practice" / f"{p}.csv.gz"
            for p in ("p1_scale_factor", "p2_bias_instability", "p3_sinusoid", "p4_burst")}
ALL_SHARED = [ADIS, MIMU, *PRACTICE.values()]

BASE_TOML = """\
sample_rate_hz = 1.0
description = "test"

[layout]
scheme = 1
n_gyros = 3
alpha_deg = 54.7356
"""


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def put(directory: Path, stem: str, csv: str | bytes, toml: str = BASE_TOML,
        suffix: str = ".csv") -> Path:
    """Write a measurement pair; return the CSV path."""
    csv_path = directory / f"{stem}{suffix}"
    data = csv.encode("utf-8") if isinstance(csv, str) else csv
    csv_path.write_bytes(gzip.compress(data) if suffix.endswith(".gz") else data)
    (directory / f"{stem}.toml").write_text(toml, encoding="utf-8")
    return csv_path


def table(rows, header="time_s,gyro1,gyro2,gyro3") -> str:
    return header + "\n" + "\n".join(",".join(str(c) for c in r) for r in rows) + "\n"


def grid_rows(n=11):
    """Samples at 1 Hz, gyro1 = 2 t, gyro2 = t**2, gyro3 = -t (exact in binary)."""
    return [[float(t), 2.0 * t, float(t * t), -float(t)] for t in range(n)]


# =========================================================================
# Real and practice files
# =========================================================================
@pytest.fixture(scope="module")
def shared_reads():
    """Each shared file read once, with its hash before and after."""
    if not MEASUREMENTS.is_dir():
        pytest.skip(f"shared measurements not found at {MEASUREMENTS}")
    out = {}
    for path in ALL_SHARED:
        before = sha256(path)
        out[path] = (read_measurement(path), before, sha256(path))
    return out


@needs_shared
@pytest.mark.parametrize("path", ALL_SHARED, ids=lambda p: p.name)
def test_shared_file_reads_consistently_and_unchanged(shared_reads, path):
    m, before, after = shared_reads[path]
    assert before == after                               # never modified
    assert m.source == str(path)
    assert m.gyro_deg_s.shape == (m.n_samples, m.layout.n_gyros)
    assert np.all(np.diff(m.time_s) > 0)
    for a in (m.time_s, m.gyro_deg_s, m.ref_deg_s, m.temp_c):
        if a is not None:
            assert not a.flags.writeable
    # the sidecar's nominal rate agrees with time_s to 0.1 % in all six files
    assert 1.0 / m.dt_s == pytest.approx(m.sample_rate_hz, rel=1e-3)
    assert not any("sample_rate_hz" in n for n in m.notes)


@needs_shared
def test_adis_values(shared_reads):
    m = shared_reads[ADIS][0]
    assert (m.n_samples, m.n_gyros, m.has_reference, m.temp_c) == (1_000_000, 3, True, None)
    # first and last data lines of the file, exactly as printed there
    np.testing.assert_array_equal(m.gyro_deg_s[0], [-0.05, -0.3, 0.7])
    np.testing.assert_array_equal(m.gyro_deg_s[-1], [0.35, -0.2, -0.45])
    assert (m.time_s[0], m.time_s[1], m.time_s[-1]) == (0.0, 0.01, 9999.99)
    assert not m.ref_deg_s.any()                       # static: reference is zero
    np.testing.assert_array_equal(m.layout.axes, np.eye(3))
    assert m.dt_s == pytest.approx(0.01, rel=1e-9)       # median step of 4-decimal times
    assert m.site is None and m.notes == ()
    # quantized at 0.05 deg/s (README): every value is a multiple of 0.05 to 1e-9 deg/s
    k = m.gyro_deg_s[:1000] / 0.05
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)


@needs_shared
def test_mimu_values(shared_reads):
    m = shared_reads[MIMU][0]
    assert (m.n_samples, m.n_gyros, m.has_reference) == (37439, 24, False)
    assert m.ref_deg_s is None and m.ref_rad_s is None and m.temp_c is None
    assert (m.gyro_deg_s[0, 0], m.gyro_deg_s[0, 23], m.gyro_deg_s[1, 0]) == (
        -1.46341, 0.97561, -1.34146)
    assert (m.time_s[1], m.time_s[-1]) == (0.0157, 599.0077)
    np.testing.assert_array_equal(m.layout.axes[3:6], [[0, -1, 0], [-1, 0, 0], [0, 0, -1]])
    np.testing.assert_array_equal(m.layout.axes[:3], np.eye(3))
    assert m.dt_s == pytest.approx(0.016, rel=1e-9)


@needs_shared
def test_practice_p1_values_layout_and_site(shared_reads):
    m = shared_reads[PRACTICE["p1_scale_factor"]][0]
    assert (m.n_samples, m.n_gyros, m.has_reference) == (108000, 4, True)
    np.testing.assert_array_equal(
        m.gyro_deg_s[0], [1.0559921e-01, 6.4285486e-02, -2.8705239e-03, 9.1597308e-02])
    np.testing.assert_array_equal(m.ref_deg_s[0], [0.0, 0.0, 0.0])
    assert (m.temp_c[0], m.temp_c[2], m.temp_c[-1]) == (25.0, 25.001, 35.487)
    assert (m.time_s[-1], m.sample_rate_hz) == (2159.98, 50.0)
    assert m.layout.scheme == 1 and m.layout.alpha_rad == deg_to_rad(54.7356)
    np.testing.assert_array_equal(m.layout.axes,
                                  Layout.conical(1, 4, deg_to_rad(54.7356)).axes)
    # independent of Layout: gyro k at azimuth 90 (k-1) deg, 54.7356 deg from +z
    a, b = math.radians(54.7356), np.radians([0.0, 90.0, 180.0, 270.0])
    expected = np.column_stack([np.sin(a) * np.cos(b), np.sin(a) * np.sin(b),
                                np.full(4, np.cos(a))])
    np.testing.assert_allclose(m.layout.axes, expected, rtol=0, atol=1e-15)
    assert m.site == Site(deg_to_rad(34.25), 0.0)
    assert m.site.latitude_rad == pytest.approx(0.5977752688080579, rel=1e-15)


@needs_shared
def test_practice_p2_scheme2(shared_reads):
    m = shared_reads[PRACTICE["p2_bias_instability"]][0]
    assert m.layout.scheme == 2 and m.n_gyros == 6
    np.testing.assert_array_equal(m.layout.axes[0], [0.0, 0.0, 1.0])   # gyro 1 on +z
    cos_alpha = math.cos(math.radians(63.4349))
    np.testing.assert_allclose(m.layout.axes[1:, 2], cos_alpha, rtol=0, atol=1e-15)


@needs_shared
def test_real_file_round_trip(tmp_path, shared_reads):
    m = shared_reads[MIMU][0]
    csv_path, _ = write_measurement(m, tmp_path / "mimu.csv.gz")
    back = read_measurement(csv_path)
    assert np.array_equal(back.gyro_deg_s, m.gyro_deg_s)
    assert np.array_equal(back.time_s, m.time_s)
    assert np.array_equal(back.layout.axes, m.layout.axes)   # unit axes: norm exactly 1


# =========================================================================
# Write -> read round trip
# =========================================================================
def random_measurement(rng: np.random.Generator, n=50, n_gyros=5) -> Measurement:
    gyro = rng.normal(size=(n, n_gyros)) * 10.0 ** rng.integers(-300, 4, size=(n, n_gyros))
    gyro[0, :3] = [-0.0, 5e-324, -1e5]   # signed zero, subnormal, the largest rate accepted
    return Measurement(
        time_s=1e5 + 0.01 * np.arange(n) + rng.uniform(0, 1e-4, n), gyro_deg_s=gyro,
        layout=Layout.conical(2, n_gyros, deg_to_rad(63.6271)), sample_rate_hz=100.0,
        ref_deg_s=rng.normal(size=(n, 3)), temp_c=25.0 + rng.normal(size=n),
        site=Site(deg_to_rad(-30.4671), deg_to_rad(15.1881)), description="round trip, ünïcode")


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.uint64)


@pytest.mark.parametrize("suffix", [".csv", ".csv.gz"])
def test_round_trip_is_exact(tmp_path, suffix):
    m = random_measurement(np.random.default_rng(7))
    csv_path, toml_path = write_measurement(m, tmp_path / f"run{suffix}")
    assert (csv_path, toml_path) == (tmp_path / f"run{suffix}", tmp_path / "run.toml")
    back = read_measurement(csv_path)
    for name in ("time_s", "gyro_deg_s", "ref_deg_s", "temp_c"):
        np.testing.assert_array_equal(bits(getattr(back, name)), bits(getattr(m, name)))
    np.testing.assert_array_equal(back.layout.axes, m.layout.axes)
    assert back.layout.scheme == 2 and back.layout.alpha_rad == m.layout.alpha_rad
    assert back.site == m.site
    assert (back.description, back.sample_rate_hz) == (m.description, m.sample_rate_hz)


def test_written_files_look_like_the_spec(tmp_path):
    m = random_measurement(np.random.default_rng(1), n=3, n_gyros=3)
    csv_path, toml_path = write_measurement(m, tmp_path / "run.csv")
    lines = csv_path.read_text().splitlines()
    assert lines[0].startswith("#")
    assert lines[1] == "time_s,gyro1,gyro2,gyro3,ref_x,ref_y,ref_z,temp_c"
    assert lines[2].split(",")[1:4] == ["-0.0", "5e-324", "-100000.0"]
    toml = toml_path.read_text()
    # degrees as the user would write them, though rad_to_deg(deg_to_rad(x)) != x for
    # these three (e.g. 15.188099999999999)
    assert "alpha_deg = 63.6271\n" in toml and "scheme = 2\n" in toml
    assert "latitude_deg = -30.4671\n" in toml and "heading_deg = 15.1881\n" in toml


def test_explicit_axes_round_trip_within_one_ulp(tmp_path):
    axes = np.array([[1.0, 2.0, 2.0], [0.0, 3.0, 4.0], [1.0, 1.0, 1.0], [0.0, 0.0, -1.0]])
    layout = Layout.from_axes(axes / np.linalg.norm(axes, axis=1)[:, None])
    m = Measurement(time_s=[0.0, 1.0], gyro_deg_s=np.zeros((2, 4)), layout=layout,
                    sample_rate_hz=1.0)
    back = read_measurement(write_measurement(m, tmp_path / "x.csv")[0])
    # re-normalising printed unit vectors moves them by at most an ulp or so
    np.testing.assert_allclose(back.layout.axes, layout.axes, rtol=0, atol=1e-15)
    assert back.site is None and back.ref_deg_s is None and back.temp_c is None


def test_cone_outside_the_sidecar_range_is_written_as_axes(tmp_path):
    layout = Layout.conical(1, 3, deg_to_rad(-30.0))     # alpha_deg must be in [0, 180]
    m = Measurement(time_s=[0.0, 1.0], gyro_deg_s=np.ones((2, 3)), layout=layout,
                    sample_rate_hz=1.0)
    csv_path, toml_path = write_measurement(m, tmp_path / "neg.csv")
    assert "axes" in toml_path.read_text() and "scheme" not in toml_path.read_text()
    np.testing.assert_allclose(read_measurement(csv_path).layout.axes, layout.axes,
                               rtol=0, atol=1e-15)


def test_write_never_overwrites_the_source(tmp_path):
    src = put(tmp_path, "run", table(grid_rows()))
    toml = tmp_path / "run.toml"
    hashes = (sha256(src), sha256(toml))
    m = read_measurement(src)
    (tmp_path / "alias.csv").symlink_to(src)
    for target in (src, tmp_path / "run.csv.gz", tmp_path / "alias.csv"):
        with pytest.raises(InputError, match="refusing to overwrite"):
            write_measurement(m, target)
    assert (sha256(src), sha256(toml)) == hashes
    assert not (tmp_path / "run.csv.gz").exists()
    out, _ = write_measurement(m, tmp_path / "copy.csv")     # elsewhere is fine
    assert np.array_equal(read_measurement(out).gyro_deg_s, m.gyro_deg_s)


def test_write_refuses_other_suffixes(tmp_path):
    m = random_measurement(np.random.default_rng(2), n=3, n_gyros=3)
    with pytest.raises(InputError, match="must end in .csv or .csv.gz"):
        write_measurement(m, tmp_path / "run.txt")


# =========================================================================
# Reading details
# =========================================================================
def test_site_conversion(tmp_path):
    toml = BASE_TOML + "\n[site]\nlatitude_deg = -45.0\nheading_deg = 90.0\n"
    m = read_measurement(put(tmp_path, "s", table(grid_rows()), toml))
    assert m.site.latitude_rad == pytest.approx(-math.pi / 4, rel=1e-15)
    assert m.site.heading_rad == pytest.approx(math.pi / 2, rel=1e-15)


def test_extra_columns_and_unknown_keys_are_noted(tmp_path):
    rows = [r + [f"label {k}", 99] for k, r in enumerate(grid_rows())]
    toml = "operator = 'ada'\n" + BASE_TOML
    m = read_measurement(put(tmp_path, "x", table(rows, "time_s,gyro1,gyro2,gyro3,label,aux"),
                             toml))
    assert any("ignored extra column(s) label, aux" in n for n in m.notes)
    assert any("ignored unknown key(s) operator" in n for n in m.notes)
    np.testing.assert_array_equal(m.gyro_deg_s[:, 1], np.arange(11.0) ** 2)


def test_sample_rate_disagreement_is_noted(tmp_path):
    m = read_measurement(put(tmp_path, "r", table(grid_rows()),
                             BASE_TOML.replace("1.0", "2.0", 1)))
    assert m.sample_rate_hz == 2.0 and m.dt_s == 1.0
    assert any("sample_rate_hz = 2.0 but the median step of time_s gives 1 Hz" in n
               for n in m.notes)


def test_declared_units_are_converted(tmp_path):
    rows = [[1000.0 * t, g1, g2, g3] for t, g1, g2, g3 in grid_rows()]
    toml = BASE_TOML + '\n[units]\ntime = "ms"\ngyro = "rad/s"\n'
    m = read_measurement(put(tmp_path, "u", table(rows), toml))
    np.testing.assert_array_equal(m.time_s, np.arange(11.0))   # 1000 k / 1000 is exact
    np.testing.assert_allclose(m.gyro_deg_s[:, 0], 2 * np.arange(11.0) * 180 / math.pi,
                               rtol=1e-15)
    assert m.gyro_deg_s[3, 0] == rad_s_to_deg_s(6.0)
    assert sum("converted" in n for n in m.notes) == 2
    m_h = read_measurement(put(tmp_path, "h", table(grid_rows()),
                               BASE_TOML + '[units]\ngyro = "deg/h"\ntemp = "°C"\n'))
    np.testing.assert_array_equal(m_h.gyro_deg_s[:, 2], -np.arange(11.0) / 3600.0)


def test_comments_blank_lines_crlf_and_quotes(tmp_path):
    text = ('# top\r\n"time_s","gyro1","gyro2","gyro3"\r\n0,1,2,3\r\n# middle\r\n\r\n'
            '1,"4", 5 ,6\r\n2,7,8,9\r\n')
    m = read_measurement(put(tmp_path, "c", text))
    np.testing.assert_array_equal(m.gyro_deg_s, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    assert any("skipped 1 blank line(s) (first at line 5)" in n for n in m.notes)
    bad = text.replace("2,7,8,9", "2,7,x,9")
    with pytest.raises(InputError) as e:
        read_measurement(put(tmp_path, "d", bad))
    assert (e.value.line, e.value.column) == (7, "gyro2")


def test_problem_located_in_a_later_chunk(tmp_path):
    """Line numbers survive the chunked fallback, and -nan is a missing value there."""
    rows = [[k * 0.01, 0.5, -0.5, 1.5] for k in range(40000)]
    rows[30001][2] = "-nan"
    path = put(tmp_path, "big", "# one comment\n" + table(rows), suffix=".csv.gz")
    with pytest.raises(InputError) as e:
        read_measurement(path)
    assert (e.value.line, e.value.column) == (30001 + 3, "gyro2")
    assert "NaN value '-nan'" in e.value.message
    repaired = read_measurement(path, repair=True)
    assert repaired.gyro_deg_s[30001, 1] == -0.5          # between two -0.5 neighbours
    rows[35000][1] = "0.5.5"
    with pytest.raises(InputError) as e:
        read_measurement(put(tmp_path, "big2", "# one comment\n" + table(rows)))
    assert (e.value.line, e.value.column) == (35000 + 3, "gyro1")


def test_path_forms(tmp_path):
    csv_path = put(tmp_path, "run", table(grid_rows()))
    for given in (csv_path, tmp_path / "run.toml", tmp_path / "run", str(tmp_path / "run")):
        m = read_measurement(given)
        assert m.source == str(csv_path)
        np.testing.assert_array_equal(m.time_s, np.arange(11.0))
    (tmp_path / "run.csv.gz").write_bytes(gzip.compress(csv_path.read_bytes()))
    with pytest.raises(InputError, match="two measurement CSVs"):
        read_measurement(tmp_path / "run")
    with pytest.raises(InputError, match="measurement file not found"):
        read_measurement(tmp_path / "nothing.csv")


# =========================================================================
# Repair
# =========================================================================
def test_repair_inserts_gap_rows_and_fills_cells(tmp_path):
    rows = grid_rows()
    rows[7][2] = ""                          # gyro2 at t = 7 (line 9): empty cell
    del rows[4:6]                            # t = 4, 5 missing: a gap of 2 samples
    path = put(tmp_path, "gap", table(rows))
    before = (sha256(path), sha256(tmp_path / "gap.toml"))
    with pytest.raises(InputError, match="gap of 2 missing sample"):
        read_measurement(path)
    m = read_measurement(path, repair=True)
    assert (sha256(path), sha256(tmp_path / "gap.toml")) == before
    t = np.arange(11.0)
    np.testing.assert_array_equal(m.time_s, t)               # rows for t = 4, 5 inserted
    np.testing.assert_array_equal(m.gyro_deg_s[:, 0], 2 * t)  # linear: exact
    # gyro2 = t**2 on the samples; inserted rows are linear between t = 3 (9) and 6 (36)
    expected = t ** 2
    expected[[4, 5]] = [18.0, 27.0]
    expected[7] = (36.0 + 64.0) / 2                           # filled between t = 6 and 8
    np.testing.assert_array_equal(m.gyro_deg_s[:, 1], expected)
    assert any("inserted 2 sample(s) between line 5 (t = 3.0 s) and line 6 (t = 6.0 s)" in n
               for n in m.notes)
    assert any("repaired 1 missing value(s) in column gyro2 at line 7" in n for n in m.notes)


def test_repair_fills_a_run_of_five(tmp_path):
    rows = grid_rows()
    for k in range(2, 7):
        rows[k][3] = "nan"
    m = read_measurement(put(tmp_path, "run5", table(rows)), repair=True)
    np.testing.assert_array_equal(m.gyro_deg_s[:, 2], -np.arange(11.0))
    assert any("repaired 5 missing value(s) in column gyro3 at lines 4-8" in n
               for n in m.notes)
    rows[7][3] = "nan"                       # now six in a row
    with pytest.raises(InputError, match="run of 6 missing values"):
        read_measurement(put(tmp_path, "run6", table(rows)), repair=True)


def test_many_repairs_are_summarised(tmp_path):
    rows = grid_rows(40)
    for k in range(1, 37, 3):               # 12 isolated empty gyro1 cells
        rows[k][1] = ""
    m = read_measurement(put(tmp_path, "many", table(rows)), repair=True)
    np.testing.assert_array_equal(m.gyro_deg_s[:, 0], 2 * np.arange(40.0))
    repaired = [n for n in m.notes if "repaired 1 missing value(s) in column gyro1" in n]
    assert len(repaired) == 10
    assert m.notes[-1] == "... and 2 more runs of missing values repaired"


def test_failed_read_leaves_files_untouched(tmp_path):
    rows = grid_rows()
    rows[3][1] = "oops"
    path = put(tmp_path, "bad", table(rows), suffix=".csv.gz")
    before = (sha256(path), sha256(tmp_path / "bad.toml"))
    for repair in (False, True):
        with pytest.raises(InputError, match="non-numeric value 'oops'"):
            read_measurement(path, repair=repair)
    assert (sha256(path), sha256(tmp_path / "bad.toml")) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv.gz", "bad.toml"]


# =========================================================================
# The Measurement type
# =========================================================================
def small(**overrides) -> Measurement:
    kwargs = dict(time_s=[0.0, 0.5, 1.0], gyro_deg_s=np.arange(9.0).reshape(3, 3),
                  layout=Layout.triad(), sample_rate_hz=2.0)
    kwargs.update(overrides)
    return Measurement(**kwargs)


def test_measurement_views_and_read_only_copies():
    gyro = np.arange(9.0).reshape(3, 3)
    m = small(gyro_deg_s=gyro, ref_deg_s=np.full((3, 3), 180.0))
    assert gyro.flags.writeable                          # the caller's array is not frozen
    with pytest.raises(ValueError):
        m.gyro_deg_s[0, 0] = 1.0
    np.testing.assert_allclose(m.gyro_rad_s, np.radians(gyro), rtol=1e-15)
    np.testing.assert_allclose(m.ref_rad_s, np.pi, rtol=1e-15)
    assert (m.dt_s, m.n_samples, m.n_gyros, m.has_reference) == (0.5, 3, 3, True)
    assert small().ref_rad_s is None and not small().has_reference


@pytest.mark.parametrize("overrides", [
    dict(gyro_deg_s=np.zeros((3, 4))),                 # 4 columns, triad has 3 axes
    dict(time_s=[0.0, 1.0, 1.0]),                      # not strictly increasing
    dict(time_s=[0.0]), dict(gyro_deg_s=np.zeros((1, 3))),
    dict(ref_deg_s=np.zeros((3, 2))), dict(temp_c=np.zeros(2)),
    dict(gyro_deg_s=np.full((3, 3), np.nan)), dict(sample_rate_hz=0.0),
    dict(layout=Layout(axes=np.full((3, 3), 2.0))),    # not unit axes
], ids=["gyro-count", "time-order", "one-time", "gyro-rows", "ref-shape", "temp-shape",
        "nan", "rate", "non-unit"])
def test_measurement_refuses_inconsistent_data(overrides):
    with pytest.raises(ValueError):
        small(**overrides)


def test_site_refuses_impossible_latitude():
    with pytest.raises(ValueError):
        Site(2.0, 0.0)
    assert Site(deg_to_rad(90.0), 0.0).latitude_rad == math.pi / 2


def test_a_measurement_without_a_source_file_writes(tmp_path):
    """``source=""`` (a record built in memory, named nothing) is no file to protect: it writes
    (before: ``Path('').with_name`` raised ValueError in the overwrite guard)."""
    m = Measurement(time_s=np.arange(10) * 0.01, gyro_deg_s=np.ones((10, 3)), layout=Layout(np.eye(3)),
                    sample_rate_hz=100.0, source="")
    csv, toml = write_measurement(m, tmp_path / "x.csv")
    assert csv.exists() and toml.exists()
    assert np.array_equal(read_measurement(csv).gyro_deg_s, m.gyro_deg_s)
