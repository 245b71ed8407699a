"""Speed of :mod:`gyroarray.analysis.davar` against per-window references.

Targets (absolute, on this machine; ratios are reported, not targets):

* A-DAVAR of the paper's 6000-sample experiment (step 1: 6000 windows of
  400-600 samples, 8 octave taus): <= 2 s;
* fixed DAVAR of 1e6 samples with L = 60 000 and the default step L/10 =
  6000 (167 windows, mirror extension, 15 octave taus up to L/3): <= 10 s.

References, timed in the same run on the same seeded data:

* fixed: ``allantools.oadev(window, rate, data_type="freq", taus=...)``
  called on every mirror-extended window (``numpy.pad(mode="symmetric")``);
* adaptive: the work a straightforward implementation does with the same
  window lengths: ``scipy.stats.kurtosis`` of the window and of its front
  at every sample, and ``allantools.oadev`` of every window.

Both also check that the deviations agree (max relative difference).  The
first call of ``davar`` (numba compile or cache load) is outside the
timing.  A third line times the fixed case with step L/100 (1667 windows)
to show that the cost is per window.

Run: ``python benchmarks/bench_davar.py``.  Reports, never asserts.
"""

from __future__ import annotations

import os

import numpy as np

from _timing import best_of

TARGET_ADAPTIVE_S = 2.0
TARGET_FIXED_S = 10.0


def _reference_fixed(y, big_l, step, taus, tau0):
    """allantools.oadev on every mirror-extended window."""
    import allantools

    pad = (big_l + 1) // 2 + 1
    x = np.pad(y, pad, mode="symmetric")
    starts = np.arange(0, y.size, step) - big_l // 2 + pad
    return np.array([allantools.oadev(x[a:a + big_l], rate=1.0 / tau0,
                                      data_type="freq", taus=taus)[1]
                     for a in starts])


def _reference_adaptive(y, lengths, l_tail, taus, tau0):
    """Kurtosis of every window and its front, allantools per window."""
    import allantools
    from scipy import stats

    pad = (int(lengths.max()) + 1) // 2 + 1
    x = np.pad(y, pad, mode="symmetric")
    out = np.empty((y.size, taus.size))
    for p, big_l in enumerate(lengths):
        a = p + pad - big_l // 2
        w = x[a:a + big_l]
        stats.kurtosis(w, fisher=False, bias=True)
        stats.kurtosis(w[:big_l - l_tail], fisher=False, bias=True)
        out[p] = allantools.oadev(w, rate=1.0 / tau0, data_type="freq",
                                  taus=taus)[1]
    return out


def main(n_fixed: int = 1_000_000, window: int = 60_000, repeats: int = 3,
         seed: int = 373) -> dict:
    """Run the benchmark, print a table and return the numbers.

    Parameters
    ----------
    n_fixed : int
        Samples of the fixed-window case.
    window : int
        Window length of the fixed case [samples]; step ``window // 10``.
    repeats : int
        Timed repetitions (best is kept), for ours and the references.
    seed : int
        Seed of the ``numpy.random.Generator`` producing the data.

    Returns
    -------
    dict
        Times [s], speed ratios (reference / ours), agreement with the
        references and PASS flags of the absolute targets.
    """
    import numba

    from davar_paper import paper_signal

    from gyroarray.analysis.davar import AdaptiveWindow, davar

    rng = np.random.default_rng(seed)
    y_paper = paper_signal(rng, sigma_rad_s=1.0)
    y_long = rng.standard_normal(n_fixed)
    step = window // 10

    davar(y_paper, 1.0, adaptive=True)                  # compile / load
    t_ad, res_ad = best_of(lambda: davar(y_paper, 1.0, adaptive=True),
                           repeats)
    t_ad_ref, ref_ad = best_of(lambda: _reference_adaptive(
        y_paper, res_ad.window_length, AdaptiveWindow().l_tail,
        res_ad.taus_s, 1.0), repeats)

    t_fx, res_fx = best_of(lambda: davar(y_long, 1.0, window=window),
                           repeats)
    t_fx_ref, ref_fx = best_of(lambda: _reference_fixed(
        y_long, window, step, res_fx.taus_s, 1.0), repeats)
    t_fine, res_fine = best_of(lambda: davar(y_long, 1.0, window=window,
                                             step=window // 100), repeats)

    def rel(a, b):
        return float(np.max(np.abs(a / b - 1.0)))

    result = {
        "numba_threads": numba.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "adaptive": {"n": int(y_paper.size), "windows": res_ad.n_windows,
                     "taus": int(res_ad.taus_s.size), "ours_s": t_ad,
                     "reference_s": t_ad_ref, "speedup": t_ad_ref / t_ad,
                     "max_rel_diff": rel(res_ad.adev_rad_s, ref_ad)},
        "fixed": {"n": n_fixed, "window": window, "step": step,
                  "windows": res_fx.n_windows,
                  "taus": int(res_fx.taus_s.size), "ours_s": t_fx,
                  "reference_s": t_fx_ref, "speedup": t_fx_ref / t_fx,
                  "max_rel_diff": rel(res_fx.adev_rad_s, ref_fx)},
        "fixed_fine": {"step": window // 100, "windows": res_fine.n_windows,
                       "ours_s": t_fine},
    }
    result["pass"] = {"adaptive": t_ad <= TARGET_ADAPTIVE_S,
                      "fixed": t_fx <= TARGET_FIXED_S}

    def flag(ok):
        return "PASS" if ok else "FAIL"

    a, f, g = result["adaptive"], result["fixed"], result["fixed_fine"]
    print(f"gyroarray.analysis.davar benchmark ({result['numba_threads']} "
          f"numba threads, {result['cpu_count']} CPUs, best of {repeats})")
    print(f"{'case':<44}{'ours [s]':>9}{'ref [s]':>9}{'ratio':>8}"
          f"{'target':>9}{'':>6}")
    label_a = f"A-DAVAR {a['n']} samples, {a['windows']} windows"
    label_f = (f"DAVAR {n_fixed:.0e}, L={window}, step {step}, "
               f"{f['windows']} windows")
    label_g = (f"DAVAR {n_fixed:.0e}, L={window}, step {g['step']}, "
               f"{g['windows']} windows")
    print(f"{label_a:<44}{a['ours_s']:>9.3f}{a['reference_s']:>9.2f}"
          f"{a['speedup']:>7.1f}x{'<= 2 s':>9}"
          f"{flag(result['pass']['adaptive']):>6}")
    print(f"{label_f:<44}{f['ours_s']:>9.3f}{f['reference_s']:>9.2f}"
          f"{f['speedup']:>7.1f}x{'<= 10 s':>9}"
          f"{flag(result['pass']['fixed']):>6}")
    print(f"{label_g:<44}{g['ours_s']:>9.3f}")
    print("  references: adaptive = scipy.stats.kurtosis x2 + allantools."
          "oadev per window; fixed = allantools.oadev per window")
    print(f"  agreement with allantools: max rel. diff {a['max_rel_diff']:.1e}"
          f" (adaptive), {f['max_rel_diff']:.1e} (fixed)")
    return result


if __name__ == "__main__":
    main()
