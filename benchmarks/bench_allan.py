"""Speed and memory of :mod:`gyroarray.analysis.allan` against allantools.

Targets (measured in the same run, on the same seeded data):

* OADEV of 1e7 rate samples at octave taus: >= 7x faster than
  ``allantools.oadev(y, rate=1, data_type="freq", taus="octave")``;
* OADEV of 1e6 samples at 100 log-spaced taus: >= 5x faster than allantools
  given the same taus;
* peak extra memory of one OADEV call <= 3x the input array.

Times are the best of ``repeats`` runs after a warm-up call (numba compiles,
or loads its cache, on the first call).  Memory is measured in a fresh
subprocess twice: the growth of the peak resident set size over the call
(Linux: the peak ``VmHWM`` is reset through ``/proc/self/clear_refs`` just
before; ``ru_maxrss`` cannot be used because importing and loading numba
peaks higher than the call itself), and the peak of ``tracemalloc`` (which
sees numpy's allocations but not numba's small internal arrays, hence
both).

Run: ``python benchmarks/bench_allan.py``.  Reports, never asserts.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from _timing import best_of

TARGET_OCTAVE = 7.0
TARGET_LOG = 5.0
TARGET_MEMORY = 3.0

_MEMORY_CHILD = r"""
import json, sys, tracemalloc
import numpy as np
from gyroarray.analysis.allan import oadev


def status(key):
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key):
                return int(line.split()[1]) * 1024


n, seed = int(sys.argv[1]), int(sys.argv[2])
y = np.random.default_rng(seed).standard_normal(n)
oadev(y[:10_000], 1.0)                     # compile / load the numba cache
with open("/proc/self/clear_refs", "w") as fh:
    fh.write("5")                          # reset the peak RSS (VmHWM)
before = status("VmRSS")
oadev(y, 1.0)
peak = status("VmHWM")
tracemalloc.start()
oadev(y, 1.0)
_, traced_peak = tracemalloc.get_traced_memory()
tracemalloc.stop()
print(json.dumps({"peak_rss_growth_bytes": peak - before,
                  "tracemalloc_peak_bytes": traced_peak,
                  "input_bytes": y.nbytes}))
"""


def _memory(n: int, seed: int) -> dict:
    """Peak extra memory of one oadev call, measured in a subprocess."""
    out = subprocess.run([sys.executable, "-c", _MEMORY_CHILD, str(n),
                          str(seed)], check=True, capture_output=True,
                         text=True, env=dict(os.environ))
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(n_octave: int = 10_000_000, n_log: int = 1_000_000,
         n_log_taus: int = 100, repeats: int = 3, seed: int = 952) -> dict:
    """Run the benchmark, print a table and return the numbers.

    Parameters
    ----------
    n_octave : int
        Samples for the octave-tau comparison.
    n_log : int
        Samples for the log-tau comparison.
    n_log_taus : int
        Requested number of log-spaced taus.
    repeats : int
        Timed repetitions (best is kept).
    seed : int
        Seed of the ``numpy.random.Generator`` producing the data.

    Returns
    -------
    dict
        Times [s], speed ratios (allantools / ours), memory ratio (extra
        bytes / input bytes), verification errors and PASS flags.
    """
    import allantools
    import numba

    from gyroarray.analysis.allan import oadev

    rng = np.random.default_rng(seed)
    y_oct = rng.standard_normal(n_octave)
    y_log = rng.standard_normal(n_log)

    # warm-up (numba compile or cache load) outside the timing
    oadev(y_oct[:10_000], 1.0)
    res_oct = oadev(y_oct, 1.0)
    t_ours_oct = best_of(lambda: oadev(y_oct, 1.0), repeats)[0]
    ref_oct = allantools.oadev(y_oct, rate=1.0, data_type="freq",
                               taus="octave")
    t_at_oct = best_of(lambda: allantools.oadev(
        y_oct, rate=1.0, data_type="freq", taus="octave"), repeats)[0]

    res_log = oadev(y_log, 1.0, n_log_taus)
    t_ours_log = best_of(lambda: oadev(y_log, 1.0, n_log_taus), repeats)[0]
    ref_log = allantools.oadev(y_log, rate=1.0, data_type="freq",
                               taus=res_log.taus_s)
    t_at_log = best_of(lambda: allantools.oadev(
        y_log, rate=1.0, data_type="freq", taus=res_log.taus_s), repeats)[0]

    mem = _memory(n_octave, seed)
    mem_ratio_rss = mem["peak_rss_growth_bytes"] / mem["input_bytes"]
    mem_ratio_traced = mem["tracemalloc_peak_bytes"] / mem["input_bytes"]
    mem_ratio = max(mem_ratio_rss, mem_ratio_traced)

    result = {
        "numba_threads": numba.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "octave": {
            "n": n_octave, "taus": int(res_oct.m.size),
            "ours_s": t_ours_oct, "allantools_s": t_at_oct,
            "speedup": t_at_oct / t_ours_oct,
            "max_rel_diff": float(np.max(np.abs(res_oct.dev / ref_oct[1]
                                                - 1.0))),
            "same_taus": bool(np.array_equal(res_oct.taus_s, ref_oct[0])),
        },
        "log": {
            "n": n_log, "taus": int(res_log.m.size),
            "ours_s": t_ours_log, "allantools_s": t_at_log,
            "speedup": t_at_log / t_ours_log,
            "max_rel_diff": float(np.max(np.abs(res_log.dev / ref_log[1]
                                                - 1.0))),
        },
        "memory": {**mem, "ratio_peak_rss": mem_ratio_rss,
                   "ratio_tracemalloc": mem_ratio_traced,
                   "ratio": mem_ratio},
    }
    result["pass"] = {
        "octave": result["octave"]["speedup"] >= TARGET_OCTAVE,
        "log": result["log"]["speedup"] >= TARGET_LOG,
        "memory": mem_ratio <= TARGET_MEMORY,
    }

    def flag(ok):
        return "PASS" if ok else "FAIL"

    print(f"gyroarray.analysis.allan benchmark ({result['numba_threads']} "
          f"numba threads, {result['cpu_count']} CPUs, best of {repeats})")
    print(f"{'case':<34}{'ours [s]':>10}{'allantools [s]':>16}"
          f"{'ratio':>8}{'target':>9}{'':>6}")
    o, g = result["octave"], result["log"]
    print(f"{'OADEV 1e7 octave (%d taus)' % o['taus']:<34}{o['ours_s']:>10.3f}"
          f"{o['allantools_s']:>16.3f}{o['speedup']:>7.1f}x{'>= 7x':>9}"
          f"{flag(result['pass']['octave']):>6}")
    print(f"{'OADEV 1e6 log (%d taus)' % g['taus']:<34}{g['ours_s']:>10.3f}"
          f"{g['allantools_s']:>16.3f}{g['speedup']:>7.1f}x{'>= 5x':>9}"
          f"{flag(result['pass']['log']):>6}")
    print(f"{'peak extra memory / input':<34}{'':>10}{'':>16}"
          f"{mem_ratio:>7.2f}x{'<= 3x':>9}{flag(result['pass']['memory']):>6}")
    print(f"  memory: peak-RSS growth {mem_ratio_rss:.2f}x, tracemalloc peak "
          f"{mem_ratio_traced:.2f}x of {mem['input_bytes'] / 1e6:.0f} MB "
          "input")
    print(f"  agreement with allantools: max rel. diff {o['max_rel_diff']:.1e}"
          f" (octave), {g['max_rel_diff']:.1e} (log); octave taus identical: "
          f"{o['same_taus']}")
    return result


if __name__ == "__main__":
    main()
