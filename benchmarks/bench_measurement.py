"""Speed of reading and writing measurement files.

Reference: plain ``pandas.read_csv(path, comment="#")`` on the same file, in
the same run — what a user would type, with no checks at all (no line
numbers, no field counts, no time or gap checks, no sidecar). Target: the
ADIS16405 file (1e6 rows × 7 columns, gzip) read well under 3 s, so that
``gyroarray allan`` on it finishes in <= 5 s end to end. Writing (exact
shortest-repr floats) is timed too, to a temporary directory.

Run: ``python benchmarks/bench_measurement.py`` or ``make bench``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pandas as pd
from _timing import best_of

from gyroarray.core.measurement import read_measurement, write_measurement

ADIS = (Path(__file__).resolve().parents[1].parent / "shared" / "measurements" / "real"
        / "adis16405_static.csv.gz")
TARGET_READ_S = 3.0


def main() -> dict:
    if not ADIS.is_file():
        print(f"skipped: {ADIS} not found (../shared beside the clone)")
        return {"skipped": str(ADIS)}
    t_read, m = best_of(lambda: read_measurement(ADIS))
    t_pandas, _ = best_of(lambda: pd.read_csv(ADIS, comment="#"))
    with tempfile.TemporaryDirectory() as d:
        t_write_csv, _ = best_of(lambda: write_measurement(m, Path(d) / "adis.csv"), repeat=1)
        t_write_gz, _ = best_of(lambda: write_measurement(m, Path(d) / "adis.csv.gz"), repeat=1)
        t_read_back, _ = best_of(lambda: read_measurement(Path(d) / "adis.csv"))

    rows = [("read_measurement (checked, exact)", t_read),
            ("pandas.read_csv(comment='#') (reference)", t_pandas),
            ("write_measurement .csv", t_write_csv),
            ("write_measurement .csv.gz", t_write_gz),
            ("read_measurement of the written .csv", t_read_back)]
    n_cols = 1 + m.n_gyros + 3 * m.has_reference + (m.temp_c is not None)
    print(f"ADIS16405: {m.n_samples} rows x {n_cols} columns")
    print(f"{'what':<44} {'time [s]':>9}")
    for name, t in rows:
        print(f"{name:<44} {t:9.3f}")
    ratio = t_read / t_pandas
    print(f"read_measurement / pandas.read_csv: {ratio:.2f}x "
          f"(target: read under {TARGET_READ_S:g} s: {t_read:.2f} s)")
    return {"read_s": t_read, "pandas_read_csv_s": t_pandas, "ratio_vs_pandas": ratio,
            "write_csv_s": t_write_csv, "write_csv_gz_s": t_write_gz,
            "read_written_csv_s": t_read_back, "target_read_s": TARGET_READ_S}


if __name__ == "__main__":
    main()
