"""How well ``fdi`` does what it claims: false alarms, minimum detectable faults, delays, done-when.

Not a speed benchmark (minutes). Prints four tables and writes
``bench_out/fdi_study.json``:

A. False alarms on clean records against the set rate: at 100 Hz (Scheme 1,
   N = 6, paper 003 noise) and, for the default 0.01/h, on the same per-sample
   problem at 1 Hz (tracker time constant 60 samples, windows × 100) where
   thousands of hours are affordable. Counted as :meth:`FaultDetector.false_alarms`.
B. Per layout (Scheme 1/2 × N = 4, 5, 6, 8, paper noise, 100 Hz): the minimum
   detectable step, drift and noise ratio (theory: non-centrality over the
   signature energy) next to the measured detection probability of a step of
   that size (P_MD = 0.5 design: >= 0.5 expected), and the median detection
   delay of 2× and 5× that step next to the matched-window bound (the
   shortest window whose non-centrality reaches the threshold: there that
   window alone fires half the time, so the median is at most that).
C. The issue's done-when on ``scenarios/faults`` with several seeds each:
   right gyro and kind, onset within 2 s (step, stuck), 10 s (noise), 150 s
   (drift); not isolable for N = 4 (except a stuck gyro, named by its flat
   line); no alarm on the clean runs.

Run: ``python benchmarks/fdi_study.py [--hours H] [--seeds S]``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# ruff: noqa: E402

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np

from gyroarray.core.gdop import optimal_alpha
from gyroarray.estimators.fdi import FaultDetector, minimum_detectable
from gyroarray.core.layout import Layout
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.sim.scenario import load_scenario, simulate
from gyroarray.core.units import rad_s_to_deg_s

ROOT = Path(__file__).resolve().parents[1]
DT = 0.01
PAPER = [{"effect": "arw", "n_deg_rt_h": 0.1}, {"effect": "rrw", "k_deg_h_rt_h": 600.0}]
TOL = {"step": 2.0, "stuck": 2.0, "noise": 10.0, "drift": 150.0}


def _model(*entries):
    return NoiseModel.from_toml({"effects": list(entries)})


def _cone(scheme, n):
    return Layout.conical(scheme, n, optimal_alpha(scheme, n).alpha_rad)


# -- A. false alarms -------------------------------------------------------------------

def false_alarm_study(hours_100hz: float, hours_1hz: float) -> dict:
    out = {}
    lay = _cone(1, 6)
    m = _model(*PAPER)
    dets = {r: FaultDetector(far_per_h=r).fit(lay, m, DT) for r in (3.0, 0.01)}
    counts = {r: {"total": 0, "step": 0, "drift": 0, "variance": 0} for r in dets}
    rng = np.random.default_rng(160)
    h = 0.0
    while h < hours_100hz:
        z = simulate_readings(m, np.zeros((360_000, 3)), lay, DT, rng)
        for r, det in dets.items():
            fa = det.false_alarms(z)
            counts[r]["total"] += int(fa["samples"].size)
            for f, c in fa["per_family"].items():
                counts[r][f] += c
        h += 1.0
    for r in dets:
        out[f"100Hz_{r:g}_per_h"] = {"hours": h, "set_per_h": r, **counts[r],
                                     "measured_per_h": counts[r]["total"] / h,
                                     "design_per_family": r / 3 * h}
    # the per-sample problem at 1 Hz: windows x 100, tracker time constant 60 samples
    m1 = _model({"effect": "arw", "n_deg_rt_h": 6.0}, {"effect": "rrw", "k_deg_h_rt_h": 360.0})
    det = FaultDetector(far_per_h=0.01, drift_window_s=60000.0, variance_window_s=4000.0).fit(lay, m1, 1.0)
    total, h1 = 0, 0.0
    while h1 < hours_1hz:
        z = simulate_readings(m1, np.zeros((720_000, 3)), lay, 1.0, rng)
        total += int(det.false_alarms(z)["samples"].size)
        h1 += 200.0
    out["1Hz_0.01_per_h"] = {"hours": h1, "set_per_h": 0.01, "total": total,
                             "measured_per_h": total / h1,
                             "poisson_95": [float(v) / h1 for v in _poisson_ci(total)]}
    return out


def _poisson_ci(k: int) -> tuple[float, float]:
    from scipy import stats
    lo = 0.0 if k == 0 else stats.chi2.ppf(0.025, 2 * k) / 2
    return lo, stats.chi2.ppf(0.975, 2 * k + 2) / 2


# -- B. minimum detectable faults and delays per layout -------------------------------------

def layout_study(trials: int) -> list:
    rows = []
    rng = np.random.default_rng(161)
    for scheme in (1, 2):
        for n in (4, 5, 6, 8):
            lay = _cone(scheme, n)
            m = _model(*PAPER)
            det = FaultDetector().fit(lay, m, DT)
            md50 = minimum_detectable(lay, m, 0.01, 0.5, dt_s=DT)
            md999 = minimum_detectable(lay, m, 0.01, 0.001, dt_s=DT)
            g = 0                                                  # gyro 1: isolable wherever N > 4
            row = {"scheme": scheme, "n": n,
                   "mds_step_deg_s_p50": float(rad_s_to_deg_s(md50["step_rad_s"][g])),
                   "mds_step_deg_s_p999": float(rad_s_to_deg_s(md999["step_rad_s"][g])),
                   "mds_drift_deg_s2_p50": float(rad_s_to_deg_s(md50["drift_rad_s2"][g])),
                   "mds_noise_ratio_p50": float(md50["noise_ratio"][g]),
                   "stuck_static_s_p50": float(md50["stuck_static_s"][g]),
                   "isolable": bool(md50["isolable"][g])}
            Ls = det.design_.scales["step"]
            row["p_detect_at_mds50"] = _p_detect(det, lay, m, g, md50["step_rad_s"][g],
                                                 Ls[-1] * DT, trials, rng)
            for k in (2, 5):
                size = k * md50["step_rad_s"][g]
                d_med = _median_delay(det, lay, m, g, size, trials, rng)
                row[f"delay_s_{k}x_measured_median"] = d_med
                row[f"delay_s_{k}x_theory"] = _delay_theory(det.design_, g, size)
            rows.append(row)
            print(f"  S{scheme} N={n}: MDS step {row['mds_step_deg_s_p50']:.4f} deg/s (P_MD 0.5), "
                  f"{row['mds_step_deg_s_p999']:.4f} (0.001); P(detect | MDS50) {row['p_detect_at_mds50']:.2f}; "
                  f"delay 2x {row['delay_s_2x_measured_median']:.3f} s (theory {row['delay_s_2x_theory']:.3f}), "
                  f"5x {row['delay_s_5x_measured_median']:.3f} s (theory {row['delay_s_5x_theory']:.3f}); "
                  f"drift {row['mds_drift_deg_s2_p50']:.2e} deg/s2, noise x{row['mds_noise_ratio_p50']:.3f}, "
                  f"stuck at rest {row['stuck_static_s_p50']:.1f} s, isolable {row['isolable']}", flush=True)
    return rows


def _step_record(lay, m, gyro, size, onset_s, length_s, rng):
    n = int(round(length_s / DT))
    z = simulate_readings(m, np.zeros((n, 3)), lay, DT, rng)
    z[int(round(onset_s / DT)):, gyro] += size
    return z


def _p_detect(det, lay, m, gyro, size, window_s, trials, rng) -> float:
    onset = 10.0
    hits = 0
    for _ in range(trials):
        z = _step_record(lay, m, gyro, size, onset, onset + window_s + 1.0, rng)
        res = det.detect(z)
        hits += any(onset <= a.detected_s <= onset + window_s for a in res.alarms)
    return hits / trials


def _median_delay(det, lay, m, gyro, size, trials, rng) -> float:
    onset = 10.0
    delays = []
    for _ in range(trials):
        z = _step_record(lay, m, gyro, size, onset, onset + 5.0, rng)
        res = det.detect(z)
        after = [a.detected_s - onset for a in res.alarms if a.detected_s >= onset]
        delays.append(after[0] if after else math.inf)
    return float(np.median(delays))


def _delay_theory(design, gyro, size) -> float:
    """The matched-window median: the first window whose non-centrality reaches u."""
    u = design.thresholds["step"]
    for L in design.scales["step"]:
        if size * math.sqrt(design.energies[("step", gyro, L)]) >= u:
            return (L - 1) * DT
    return math.inf


# -- C. the done-when on scenarios/faults ---------------------------------------------------

def done_when_study(seeds: int) -> dict:
    files = sorted((ROOT / "src" / "gyroarray" / "data" / "scenarios" / "faults").glob("*.toml"))
    tally = {}
    for f in files:
        sc = load_scenario(f)
        kind = f.stem.rsplit("_", 1)[1]
        faults = [e for e in sc.model.entries if e.effect.startswith("fault_")]
        clean = NoiseModel(tuple(e for e in sc.model.entries if not e.effect.startswith("fault_")))
        det = FaultDetector().fit(sc.layout, clean, 1 / sc.sample_rate_hz)
        for s in range(seeds):
            res_sim = simulate(dataclasses.replace(sc, seed=sc.seed + 1000 * s))
            res = det.detect(res_sim.readings_rad_s, res_sim.truth.time_s)
            ok = _judge(res.alarms, faults, sc.layout.n_gyros, kind)
            t = tally.setdefault(f"S{sc.layout.scheme} N={sc.layout.n_gyros} {kind}", [0, 0, []])
            t[0] += ok
            t[1] += 1
            if not ok:
                t[2].append([(a.gyro, a.kind, round(a.onset_s, 2), round(a.detected_s, 2)) for a in res.alarms])
    for name, (ok, total, bad) in tally.items():
        print(f"  {name:<16} {ok}/{total}" + (f"  misses: {bad[:2]}" if bad else ""), flush=True)
    return {k: {"ok": v[0], "runs": v[1], "failures": v[2]} for k, v in tally.items()}


def _judge(alarms, faults, n_gyros, kind) -> bool:
    if kind == "clean":
        return not alarms
    f = faults[0]
    start = float(f.params["start_s"])
    hits = [a for a in alarms if a.detected_s >= start]
    if not hits or len(alarms) != len(hits):
        return False
    a = hits[0]
    right_gyro = (a.gyro is None and not a.isolated) if (n_gyros == 4 and kind != "stuck") \
        else a.gyro == f.gyro
    return right_gyro and a.kind == kind and abs(a.onset_s - start) <= TOL[kind]


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hours", type=float, default=40.0, help="clean hours at 100 Hz (A)")
    p.add_argument("--hours-1hz", type=float, default=4000.0, help="clean hours at 1 Hz (A)")
    p.add_argument("--trials", type=int, default=60, help="trials per layout and size (B)")
    p.add_argument("--seeds", type=int, default=5, help="seeds per scenario (C)")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    print("A. false alarms on clean records", flush=True)
    far = false_alarm_study(args.hours, args.hours_1hz)
    for k, v in far.items():
        print(f"  {k}: {v}", flush=True)
    print("B. minimum detectable faults and delays per layout (paper 003 noise, 100 Hz)", flush=True)
    layouts = layout_study(args.trials)
    print("C. done-when on scenarios/faults", flush=True)
    dw = done_when_study(args.seeds)
    out = {"false_alarms": far, "layouts": layouts, "done_when": dw,
           "seconds": time.perf_counter() - t0}
    path = ROOT / "bench_out" / "fdi_study.json"
    path.parent.mkdir(exist_ok=True)
    path.write_text(json.dumps(out, indent=2, default=str))
    print(f"wrote {path} ({out['seconds']:.0f} s)")
    return out


if __name__ == "__main__":
    main()
