"""End-to-end CLI speed: `gyroarray --help`, and `gyroarray allan` on the ADIS16405 file (1e6 x 3).

Target: `gyroarray --help` <= 0.5 s on 2 cores, against `python -c pass` in the same run.

Target (issue 2): <= 5 s from process start to JSON out, a fresh process
each time (imports, numba cache load, reading, three OADEV + CI + fits).
Reference in the same run: what a user would script by hand — pandas.read_csv
then allantools.oadev (octave) on each gyro, in one fresh process, with no
confidence intervals and no fit.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from _timing import best_of

ADIS = (Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real"
        / "adis16405_static.csv.gz")
TARGET_S = 5.0

_BY_HAND = """
import sys, pandas as pd, allantools
df = pd.read_csv(sys.argv[1], comment="#")
for c in ("gyro1", "gyro2", "gyro3"):
    allantools.oadev(df[c].to_numpy(), rate=100.0, data_type="freq", taus="octave")
"""


def _run(argv: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


#: `gyroarray --help` from process start, on 2 cores (docs/layout.md: the parser is light).
HELP_TARGET_S = 0.5


def help_startup() -> dict:
    """`gyroarray --help` (the console script) against `python -c pass` in the same run: what the
    command line adds to the interpreter's own start (no numpy, scipy, numba: tests/test_startup.py)."""
    script = Path(sys.executable).with_name("gyroarray")
    cli = [str(script), "--help"] if script.exists() else [sys.executable, "-m", "gyroarray.cli", "--help"]
    _run(cli)  # the OS file cache and the .pyc files
    t_help, _ = best_of(lambda: _run(cli), 5)
    t_pass, _ = best_of(lambda: _run([sys.executable, "-c", "pass"]), 5)
    verdict = "PASS" if t_help <= HELP_TARGET_S else "FAIL"
    print("what                                                   time [s]")
    print(f"gyroarray --help                                       {t_help:8.3f}   target <= {HELP_TARGET_S:g} s  {verdict}")
    print(f"python -c pass (the interpreter's start)               {t_pass:8.3f}")
    print(f"ratio gyroarray --help / python -c pass: {t_help / t_pass:.2f}x")
    return {"help_s": t_help, "python_pass_s": t_pass, "help_target_s": HELP_TARGET_S,
            "help_pass": t_help <= HELP_TARGET_S}


def main() -> dict:
    startup = help_startup()
    if not ADIS.is_file():
        print(f"skipped: {ADIS} not found (../shared beside the clone)")
        return {"skipped": True, **startup}
    cli = [sys.executable, "-m", "gyroarray.cli.main", "allan", str(ADIS), "--json"]
    _run(cli)  # warm the numba cache and the OS file cache
    t_cli, _ = best_of(lambda: _run(cli), 3)
    t_hand, _ = best_of(lambda: _run([sys.executable, "-c", _BY_HAND, str(ADIS)]), 3)
    verdict = "PASS" if t_cli <= TARGET_S else "FAIL"
    print("what                                                   time [s]")
    print(f"gyroarray allan ADIS --json (3 gyros, CI + fits)       {t_cli:8.2f}   target <= {TARGET_S:g} s  {verdict}")
    print(f"by hand: pandas.read_csv + allantools.oadev x 3        {t_hand:8.2f}   (no CI, no fit)")
    print(f"ratio by-hand / gyroarray: {t_hand / t_cli:.2f}x")
    return {"cli_s": t_cli, "by_hand_s": t_hand, "target_s": TARGET_S, "pass": t_cli <= TARGET_S,
            **startup}


if __name__ == "__main__":
    main()
