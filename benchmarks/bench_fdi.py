"""Speed of the fault detector ``fdi`` against a plain numpy loop of the same detector.

Target (issue 16): ``FaultDetector.detect`` on 46 min × 8 gyros × 100 Hz
(276 000 samples, Scheme 1 at the optimal angle, paper 003 noise, a 0.1 deg/s
step on gyro 5 at 40 min, so the run includes one isolation, the exclusion
and the scan of the remaining 7 gyros) takes <= 5 s.

Reference in the same run: the same detector written as a per-sample loop (the
bias trackers updated sample by sample, each window statistic a numpy dot
product of the last L innovations with its signature, each variance block
summed at its end), run on a slice and scaled per sample (the slice holds no window
longer than itself, so the scaled loop time is a lower bound). On the slice the two
must give the same first alarm and the same statistics (|statistic|/threshold
per family) to 1e-9.

Run: ``python benchmarks/bench_fdi.py``. Reports, never asserts.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy (see bench_estimators.py)
# ruff: noqa: E402

import math

import numpy as np
from _timing import best_of

from gyroarray.effects.faults import scan as ff
from gyroarray.core.gdop import optimal_alpha
from gyroarray.estimators.fdi import FaultDetector, _scan, window_weights
from gyroarray.core.layout import Layout
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel

TARGET_S = 5.0
N_GYROS, DT = 8, 0.01
N_SAMPLES = int(46 * 60 / DT)
N_LOOP = 3000
MODEL = NoiseModel.from_toml({"effects": [{"effect": "arw", "n_deg_rt_h": 0.1},
                                          {"effect": "rrw", "k_deg_h_rt_h": 600.0}]})
FAULT = {"effect": "fault_step", "gyro": 5, "start_s": 2400.0, "size_deg_s": 0.1}


def _data(seed: int = 16):
    layout = Layout.conical(1, N_GYROS, optimal_alpha(1, N_GYROS).alpha_rad)
    m = NoiseModel.from_toml({"effects": [e.to_dict() for e in MODEL.entries] + [FAULT]})
    z = simulate_readings(m, np.zeros((N_SAMPLES, 3)), layout, DT, np.random.default_rng(seed))
    return layout, z


def loop_scan(z: np.ndarray, design) -> tuple[dict, dict]:
    """The detector's first scan as a per-sample loop: (first alarm, statistic traces)."""
    n, m = z.shape[0], design.m
    reps = [g[0] for g in design.groups]
    # scalar bias trackers, one per parity component, diffuse start
    K, S = zip(*(ff.rw_gains(float(q), n) for q in design.q))
    weights = {}
    for fam in ("step", "drift"):
        for L in design.scales[fam]:
            if L <= n - 1:
                h = np.stack([window_weights(fam, design.a, design.K, design.S, design.coef[:, j], L)
                              for j in reps], axis=2)            # (L, m, G)
                weights[(fam, L)] = h / np.sqrt(np.sum(h * h, axis=(0, 1)))[None, None, :]
    eps = np.zeros((n, m))
    m_hat = np.zeros(m)
    ratio = {f: np.zeros(n) for f in ("step", "drift", "variance")}
    first = {"k": None}
    var_dir = design.var_dir[:, reps]
    held = {}
    for k in range(n):
        p = design.P @ z[k]
        if k == 0:
            m_hat = p.copy()
        else:
            for i in range(m):
                nu = p[i] - m_hat[i]
                eps[k, i] = nu / math.sqrt(S[i][k])                # ε = ν/√S
                m_hat[i] += K[i][k] * nu                            # m̂ = m̂ + K ν
        for (fam, L), w in weights.items():
            if k >= L - 1:
                y = np.abs(np.einsum("lm,lmg->g", eps[k - L + 1:k + 1], w))
                u = design.thresholds[fam]
                ratio[fam][k] = max(ratio[fam][k], float(y.max()) / u)
                if first["k"] is None and k >= 1 and np.any(y > u):
                    first = {"k": k, "family": fam, "L": L}
        for L in design.scales["variance"]:
            if k >= L and k % L == 0:                              # a block ends (ε₀ skipped)
                x = eps[k - L + 1:k + 1] @ var_dir
                lam = np.maximum(np.sum(x * x, axis=0) / L, 1e-300)
                G = 0.5 * L * (lam - 1.0 - np.log(lam))
                g = design.thresholds["variance"]
                held[L] = float(G.max()) / g                       # shown until the next block ends
                if first["k"] is None and np.any(G > g):
                    first = {"k": k, "family": "variance", "L": L}
        ratio["variance"][k] = max(held.values(), default=0.0)
    return first, ratio


def main(repeat: int = 3) -> dict:
    layout, z = _data()
    fit_s, det = best_of(lambda: FaultDetector().fit(layout, MODEL, DT), 3)
    ours_s, res = best_of(lambda: det.detect(z), repeat)
    zs = z[:N_LOOP]
    loop_s, (first, ratio) = best_of(lambda: loop_scan(zs, det.design_), 1)
    eps = ff.rw_innovations(zs @ det.design_.P.T, det.design_.q)
    vec = _scan(eps, det.design_, trace=True)
    diff = max(float(np.max(np.abs(ratio[f][1:] - vec["trace"][f][1:]))) for f in ratio)
    loop_full_s = loop_s * N_SAMPLES / N_LOOP
    a = res.alarms[0] if res.alarms else None
    out = {"n_gyros": N_GYROS, "n_samples": N_SAMPLES, "fit_s": fit_s, "detect_s": ours_s,
           "target_s": TARGET_S, "loop_slice": N_LOOP, "loop_s_scaled": loop_full_s,
           "ratio": loop_full_s / ours_s, "max_abs_diff_vs_loop": diff,
           "same_first_alarm": first.get("k") == vec.get("k"),
           "alarm": None if a is None else {"gyro": a.gyro, "kind": a.kind, "onset_s": a.onset_s,
                                            "detected_s": a.detected_s, "isolated_s": a.isolated_s}}

    def ok(good):
        return "PASS" if good else "FAIL"
    print(f"fdi benchmark: N = {N_GYROS}, {N_SAMPLES} samples (46 min at 100 Hz), fit {fit_s:.2f} s")
    print(f"  detect (vectorised)       {ours_s:8.2f} s   target <= {TARGET_S:g} s   {ok(ours_s <= TARGET_S)}")
    print(f"  numpy loop (scaled)       {loop_full_s:8.1f} s   ({N_LOOP} samples in {loop_s:.2f} s)")
    print(f"  ratio loop/vectorised     {out['ratio']:8.0f}")
    print(f"  agreement on the slice: max |Δ statistic/threshold| {diff:.1e} (<= 1e-9: {ok(diff <= 1e-9)}),"
          f" same first alarm: {out['same_first_alarm']}")
    print(f"  alarm: {out['alarm']}")
    return out


if __name__ == "__main__":
    main()
