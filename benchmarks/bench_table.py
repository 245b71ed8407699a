"""Speed of the MuJoCo rate table and its truth cache.

Reference: the same physics stepped by a Python loop over ``mujoco.mj_step``
(timed on 20 s of the swing and scaled), against ``mujoco.rollout`` in
chunks as :class:`gyroarray.sim.table.RateTable` runs it. Targets: a 1 h
static + 10 min swing at 100 Hz in seconds; a cache hit well under a second.
Also prints the tracking of the papers' profiles (full length).

Run: ``python benchmarks/bench_table.py`` or ``make bench``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import mujoco
from _timing import best_of
import numpy as np

from gyroarray.core.layout import Layout
from gyroarray.sim.profiles import Profile, Sinusoid, Static, load_profile
from gyroarray.sim.table import RateTable
from gyroarray.sim.truth import compute_truth, project
from gyroarray.core.units import deg_s_to_rad_s, deg_to_rad, rad_s_to_deg_s, rad_to_deg

PROFILES = Path(__file__).resolve().parents[1] / "src" / "gyroarray" / "data" / "scenarios" / "profiles"


def _python_loop_seconds(profile: Profile, fs: float, seconds: float) -> float:
    """Time a plain Python mj_step loop over the first ``seconds`` of the profile."""
    table = RateTable()
    dt, k = table.timestep(fs)
    model = table.model(None, timestep_s=dt)
    data = mujoco.MjData(model)
    damping = np.array(table.params.damping_n_m_s)
    n = int(round(seconds / dt))
    cmd = profile.command((np.arange(n) + 0.5) * dt)
    ctrl = np.concatenate([cmd.q_rad, cmd.qd_rad_s, cmd.qd_rad_s * damping], axis=1)
    out = np.empty((n // k + 1, 3))
    t0 = time.perf_counter()
    for j in range(n):
        data.ctrl[:] = ctrl[j]
        mujoco.mj_step(model, data)
        if j % k == 0:
            out[j // k] = data.sensordata[:3]
    return time.perf_counter() - t0


def main() -> dict:
    fs = 100.0
    table = RateTable()
    swing = load_profile(PROFILES / "p002_swing_20dps_0p5hz.toml")
    static = load_profile(PROFILES / "p003_static_1h.toml")
    combo = Profile((Static(duration_s=3600.0),
                     Sinusoid(axis=(0, 0, 1), amplitude_rad_s=deg_s_to_rad_s(20.0), frequency_hz=0.5,
                              duration_s=600.0)))
    results = {}
    rows = []

    t_static, run = best_of(lambda: table.run(static, fs), repeat=1)
    rows.append(("1 h static, 100 Hz (rest repeated)", t_static, run.stepped))
    t_static_all, run = best_of(lambda: table.run(static, fs, skip_rest=False), repeat=1)
    rows.append(("1 h static, 100 Hz (every step)", t_static_all, run.stepped))
    t_swing, run = best_of(lambda: table.run(swing, fs), repeat=1)
    rows.append(("10 min swing 20 deg/s 0.5 Hz, 100 Hz", t_swing, run.stepped))
    t_combo, run = best_of(lambda: table.run(combo, fs), repeat=1)
    rows.append(("1 h static + 10 min swing, 100 Hz", t_combo, run.stepped))
    t_loop20 = _python_loop_seconds(swing, fs, 20.0)
    t_loop = t_loop20 * 600.0 / 20.0
    rows.append(("10 min swing, Python mj_step loop (scaled from 20 s)", t_loop, 600_000))

    with tempfile.TemporaryDirectory() as cache:
        t_miss, truth = best_of(lambda: compute_truth(combo, fs, cache_dir=cache), repeat=1)
        t_hit, _ = best_of(lambda: compute_truth(combo, fs, cache_dir=cache), repeat=3)
    rows.append(("truth, 1 h static + swing: compute + write cache", t_miss, None))
    rows.append(("truth, 1 h static + swing: cache hit", t_hit, None))
    layouts = [Layout.conical(s, n, deg_to_rad(a)) for s in (1, 2) for n in (4, 5, 6, 8)
               for a in (45.0, 54.7356, 63.0)]
    t_proj, _ = best_of(lambda: [project(truth, lay) for lay in layouts], repeat=3)
    rows.append((f"project truth on {len(layouts)} layouts", t_proj, None))

    print(f"{'what':<56} {'time [s]':>9} {'steps':>10} {'µs/step':>8}")
    for name, t, steps in rows:
        per = f"{t / steps * 1e6:8.2f}" if steps else f"{'':>8}"
        print(f"{name:<56} {t:9.3f} {steps if steps else '':>10} {per}")
        results[name] = {"seconds": t, "physics_steps": steps}
    ratio = t_loop / t_swing
    print(f"rollout vs Python loop on the swing: {ratio:.2f}x faster "
          f"(target: 1 h static + 10 min swing in seconds: {t_combo:.1f} s)")
    results["rollout_speedup_vs_python_loop"] = ratio

    print("\nTracking of the papers' profiles (full length, 100 Hz):")
    print(f"{'profile':<26} {'rms err':>10} {'steady err':>11} {'amp ratio':>12} {'lag':>10}")
    print(f"{'':<26} {'[deg/s]':>10} {'[deg/s]':>11} {'[-]':>12} {'[deg]':>10}")
    tracking = {}
    for path in sorted(PROFILES.glob("p00*.toml")):
        tr = table.run(load_profile(path), fs).tracking
        (seg,) = tr.segments
        steady = (f"{rad_s_to_deg_s(seg.steady_rate_error_rad_s[0]):11.2e}"
                  if seg.steady_rate_error_rad_s else f"{'-':>11}")
        amp = f"{seg.amplitude_ratio:12.8f}" if seg.amplitude_ratio is not None else f"{'-':>12}"
        lag = f"{rad_to_deg(seg.phase_lag_rad):10.2e}" if seg.phase_lag_rad is not None else f"{'-':>10}"
        print(f"{path.stem:<26} {rad_s_to_deg_s(tr.rms_error_rad_s):10.2e} {steady} {amp} {lag}")
        tracking[path.stem] = tr.to_dict()
    results["tracking"] = tracking
    return results


if __name__ == "__main__":
    main()
