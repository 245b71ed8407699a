"""Run every benchmark (``benchmarks/bench_*.py``) and print its ratios.

Each benchmark module has ``main() -> dict``: it times gyroarray against the
reference library doing the same job in the same run (allantools, pandas,
filterpy, ...) and prints a table with the ratio and the target. Speed
targets live here, never in timed unit tests.

Usage: ``make bench`` or ``python benchmarks/run.py [NAME ...]``; results are
also written as JSON to ``bench_out/results.json``.
"""

from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # the benchmarks share benchmarks/_timing.py


def _load(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main(argv: list[str]) -> int:
    wanted = set(argv)
    results = {}
    for path in sorted(HERE.glob("bench_*.py")):
        name = path.stem.removeprefix("bench_")
        if wanted and name not in wanted:
            continue
        print(f"\n=== {name} ===", flush=True)
        t0 = time.perf_counter()
        results[name] = _load(path).main()
        print(f"({name}: {time.perf_counter() - t0:.1f} s)", flush=True)
    out = HERE.parent / "bench_out"
    out.mkdir(exist_ok=True)
    (out / "results.json").write_text(json.dumps(results, indent=2, default=str))
    print(f"\nwrote {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
