"""``gyroarray simulate``, ``run``, ``sweep`` and ``report``: a scenario into a measurement, a
scenario scored per estimator (once or over replicates), a sweep of scenarios into a dataset and
the design report of sweep folders, with their text.

The simulator, the estimators (numba), the sweep runner and the report (matplotlib) are imported
inside the commands, so that building the parser (``gyroarray --help``) does not load them.
"""

from __future__ import annotations

from pathlib import Path

from gyroarray.cli.common import (EXIT_FAIL, EXIT_OK, add_force, add_plugin, count, nonneg_int,
                                  output)
from gyroarray.core.errors import InputError
from gyroarray.core.units import rad_s_to_deg_s, rad_to_deg

__all__ = ["add_parser", "cmd_simulate", "cmd_run", "cmd_sweep", "cmd_report", "tracking_datasheet"]


def tracking_datasheet(tracking) -> list[dict]:
    """The rate table's tracking report per segment, in deg/s and deg (the CLI edge)."""
    def opt(x, conv):
        return None if x is None else conv(x)
    return [{"segment": s.index, "kind": s.kind, "label": s.label, "start_s": s.start_s,
             "end_s": s.end_s, "rms_error_deg_s": rad_s_to_deg_s(s.rms_error_rad_s),
             "max_error_deg_s": rad_s_to_deg_s(s.max_error_rad_s),
             "steady_rate_error_deg_s": [rad_s_to_deg_s(v) for v in s.steady_rate_error_rad_s],
             "amplitude_ratio": s.amplitude_ratio,
             "phase_lag_deg": opt(s.phase_lag_rad, rad_to_deg),
             "hold_attitude_error_deg": opt(s.hold_attitude_error_rad, rad_to_deg)}
            for s in tracking.segments]


def cmd_simulate(args) -> tuple[dict, str]:
    from gyroarray.sim.scenario import load_scenario, simulate_to_files  # deferred: the simulator (numba)
    scenario = load_scenario(args.scenario)
    csv_path, toml_path, result = simulate_to_files(scenario, args.out, cache=not args.no_cache,
                                                    force=args.force)
    params = [_plain_params(e.params) for e in scenario.model.entries]
    effects = [{"effect": e.effect, "gyro": e.gyro, "params": p}
               for e, p in zip(scenario.model.entries, params)]
    out = {"scenario": scenario.name, "measurement": str(csv_path), "sidecar": str(toml_path),
           "n_samples": int(result.truth.time_s.size), "n_gyros": scenario.layout.n_gyros,
           "sample_rate_hz": scenario.sample_rate_hz, "seed": scenario.seed,
           "effects": effects, "tracking": tracking_datasheet(result.truth.tracking)}
    lines = [f"simulated {scenario.name}: {out['n_samples']} samples x {out['n_gyros']} gyros "
             f"at {scenario.sample_rate_hz:g} Hz (seed {scenario.seed})",
             f"wrote {csv_path}", f"wrote {toml_path}", "effects:"]
    lines += [f"  {e.effect}" + (f" (gyro {e.gyro})" if e.gyro else "")
              + ": " + ", ".join(f"{k} = {v}" for k, v in p.items())
              for e, p in zip(scenario.model.entries, params)]
    lines += ["rate table tracking (realised vs commanded):", result.truth.tracking.table()]
    return out, "\n".join(lines)


def _plain_params(params) -> dict:
    import numpy as np  # deferred: numpy (a fast --help)
    return {k: (np.asarray(v).tolist() if isinstance(v, (list, tuple, np.ndarray)) else v)
            for k, v in params.items()}


_RUN_COLUMNS = (("sigma_1_deg_s", "1sigma[deg/s]", ".4g"), ("reduction", "reduct.", ".3g"),
                ("attenuation", "atten.", ".5f"), ("phase_deg", "phase[deg]", ".3g"),
                ("arw_deg_rt_h", "ARW[deg/rt h]", ".4g"), ("bi_deg_h", "BI[deg/h]", ".4g"),
                ("rrw_deg_h_rt_h", "RRW[deg/h/rt h]", ".4g"), ("efficiency", "effic.", ".3f"))


def cmd_run(args) -> tuple[dict, str]:
    # deferred: the simulator and the estimators (numba) load only when the command runs (a fast --help)
    from gyroarray.chain.run import run_scenario
    from gyroarray.estimators import available
    from gyroarray.sim.scenario import check_size, load_scenario
    names = [n.strip() for n in args.estimators.split(",") if n.strip()] if args.estimators else None
    if names is not None:
        unknown = [n for n in names if n not in available()]
        if unknown or not names:
            raise InputError(f"--estimators: unknown estimator {(unknown or [args.estimators])[0]!r} "
                             f"(available: {', '.join(available())})")
    scenario = load_scenario(args.scenario)
    check_size(scenario, "run")
    if args.replicates is not None or args.seed is not None:
        return _run_replicates(args, scenario, names)
    result = run_scenario(scenario, names, cache=not args.no_cache)
    out = result.to_json_dict()

    def cell(v, fmt):
        return "-" if v is None or (isinstance(v, float) and v != v) else format(v, fmt)
    head = f"{'estimator':<10} {'axis':<4} " + " ".join(f"{h:>15}" for _, h, _ in _RUN_COLUMNS)
    lines = [f"scenario {scenario.name}" + (f" (swing {result.swing_hz:g} Hz)" if result.swing_hz else ""), head]
    for row in result.table.to_dict("records"):
        lines.append(f"{row['estimator']:<10} {row['axis']:<4} "
                     + " ".join(f"{cell(row.get(k), f):>15}" for k, _, f in _RUN_COLUMNS))
    lines += [f"note: {n}" for n in result.notes]
    lines += _sensor_lines(result)
    sg = out["single_gyro"]
    lines.append(f"single gyro (mean of {len(sg['gyros'])}): 1sigma {sg['sigma_1_deg_s']:.4g} deg/s, "
                 f"ARW {sg['arw_deg_rt_h']:.4g} deg/rt(h), BI {sg['bi_deg_h']:.4g} deg/h, "
                 f"RRW {sg['rrw_deg_h_rt_h']:.4g} deg/h/rt(h)")
    return out, "\n".join(lines)


def _sensor_lines(result) -> list[str]:
    """The sensors' share of the swing response and the g-sensitivity's rate error, in words."""
    lines = []
    t, sg = result.table, result.single_gyro
    if "sensor_amplitude_ratio" in sg and sg["sensor_amplitude_ratio"].notna().any():
        sw = t[t.sensor_amplitude_ratio.notna()]
        r = sw.iloc[0]
        lines.append(f"swing {result.swing_hz:g} Hz: the gyros' own response (measured on the raw "
                     f"gyros) {r.sensor_amplitude_ratio:.5f}, lag {r.sensor_phase_deg:.3g} deg; "
                     "each estimator's attenuation = its own share x the sensors':")
        for row in sw.itertuples():
            lines.append(f"  {row.estimator:<10} {row.axis}: total {row.attenuation:.5f} "
                         f"({row.phase_deg:.3g} deg) = estimator {row.estimator_amplitude_ratio:.5f} "
                         f"({row.estimator_phase_deg:.3g} deg) x sensor {row.sensor_amplitude_ratio:.5f} "
                         f"({row.sensor_phase_deg:.3g} deg)")
    if "g_sensitivity_rms_deg_s" in sg:
        per = ", ".join(f"{v:.4g}" for v in sg["g_sensitivity_rms_deg_s"])
        lines.append(f"g-sensitivity rate error on this motion (RMS over the scored window, deg/s): "
                     f"per gyro {per}")
        for name, grp in t.groupby("estimator", sort=False):
            v = grp.g_sensitivity_rms_deg_s.tolist()
            if all(x is not None and x == x for x in v):
                lines.append(f"  {name:<10} fused (DC gain x per-gyro) x/y/z: "
                             + " / ".join(f"{x:.4g}" for x in v))
    return lines


_REP_COLUMNS = (("sigma_1_deg_s", "1sigma[deg/s]"), ("rms_deg_s", "RMS[deg/s]"),
                ("angle_error_deg", "angle@T[deg]"), ("attenuation", "atten."),
                ("phase_deg", "phase[deg]"))


def _run_replicates(args, scenario, names) -> tuple[dict, str]:
    from gyroarray.chain.run import run_replicates  # deferred: the simulator and the estimators (numba)
    k = 1 if args.replicates is None else args.replicates
    rep = run_replicates(scenario, names, replicates=k, seed=args.seed, cache=not args.no_cache)
    summ = rep.summary()
    comp = rep.comparison()
    checked = [c for e in comp.values() for a in e.values() for c in a.values() if c["agrees"] is not None]
    inside = sum(c["agrees"] for c in checked)
    out = {"scenario": rep.scenario, "replicates": k, "seed": rep.seed,
           "swing_hz": rep.runs[0].swing_hz, "estimators": summ,
           "single_gyro": rep.single_gyro_summary(), "predicted": comp,
           "agreement": {"compared": len(checked), "inside_95": inside,
                         "note": "each comparison at 95 %: about 5 % fall outside by chance"},
           "notes": list(rep.notes)}

    def ci(d):
        if d["mean"] is None:
            return "-"
        if d["ci_low"] is None:
            return f"{d['mean']:.4g}"
        return f"{d['mean']:.4g} [{d['ci_low']:.3g}, {d['ci_high']:.3g}]"
    lines = [f"scenario {scenario.name}: {k} runs (seed {rep.seed}), mean and 95 % CI of the mean",
             f"{'estimator':<10} {'axis':<4} " + " ".join(f"{h:>30}" for _, h in _REP_COLUMNS)]
    for name, axes in summ.items():
        for axis, m in axes.items():
            lines.append(f"{name:<10} {axis:<4} " + " ".join(f"{ci(m[c]) if c in m else '-':>30}"
                                                              for c, _ in _REP_COLUMNS))
    if comp:
        lines += ["", "predicted vs these runs (RMS over runs for std/RMS/mean/angle; mean for "
                      "amplitude and phase; 95 % CI):"]
        for name, axes in comp.items():
            for axis, m in axes.items():
                cells = []
                for key, c in m.items():
                    mc = c["monte_carlo"]
                    tag = "" if c["agrees"] is None else (" ok" if c["agrees"] else " OUTSIDE")
                    rng = "" if mc["ci_low"] is None else f" [{mc['ci_low']:.3g}, {mc['ci_high']:.3g}]"
                    cells.append(f"{key} {c['predicted']:.4g} vs {mc['value']:.4g}{rng}{tag}")
                lines.append(f"  {name:<10} {axis}: " + "; ".join(cells))
        lines.append(f"{inside} of {len(checked)} predictions inside the runs' 95 % CI "
                     "(about 5 % fall outside by chance)")
    lines += [f"note: {n}" for n in rep.notes]
    return out, "\n".join(lines)


def cmd_sweep(args):
    from gyroarray.sweep.runner import run_sweep  # deferred: the sweep runner (pandas, numba, dask)
    if args.workers is not None and args.scheduler is not None:
        raise InputError("gyroarray sweep: --workers and --scheduler exclude each other")
    if args.dask is not None and (args.workers is not None or args.scheduler is not None):
        raise InputError("gyroarray sweep: --dask excludes --workers and --scheduler (give one: "
                         "--dask local:N, --workers N or --scheduler tcp://HOST:PORT)")
    summary = run_sweep(args.sweep, args.out, workers=args.workers or 1,
                        scheduler=args.scheduler, dask=args.dask,
                        progress=None if not args.json else False)
    lines = [f"sweep {summary['sweep']}: {summary['scenarios']} scenarios, ran {summary['ran']}, "
             f"skipped {summary['skipped']} (already done), failed {len(summary['failed'])}, "
             f"{summary['rows_written']} rows in {summary['seconds']:.1f} s -> {summary['dataset']}"]
    prof = summary.get("profile") or {}
    if prof.get("workers"):
        phases = ", ".join(f"{k} {v:.1f}" for k, v in prof["phases_s"].items())
        n_w = summary.get("workers") or len(prof["workers"])     # a remote cluster: those seen
        span = max(sum(prof["phases_s"].values()), 1e-9)
        lines.append(f"time [s]: {phases}; {n_w} worker(s) ran scenarios "
                     f"{100 * prof['busy_s'] / (n_w * span):.0f} % of the time, with a core "
                     f"{100 * prof['cpu_s'] / max(prof['busy_s'], 1e-9):.0f} % of theirs "
                     "(--json: profile)")
    lines += [f"failed {f['id']}: {f['error']}" for f in summary["failed"]]
    lines += [f"note: {n}" for n in summary.get("notes", [])]
    lines += [f"left out (skip_invalid) {x['id']}: {x['reason']}" for x in summary["excluded"]]
    return summary, "\n".join(lines), (EXIT_OK if summary["complete"] else EXIT_FAIL)


def cmd_report(args):
    # deferred: the report (pandas, matplotlib) loads only when the command runs (a fast --help)
    from gyroarray.core.outputs import markdown_figures, same_path
    from gyroarray.reports.report import write_report
    if args.top < 1:
        raise InputError("gyroarray report: --top must be >= 1")
    for i, d in enumerate(args.dirs):
        twice = next((e for e in args.dirs[:i] if same_path(d, e)), None)
        if twice is not None:
            raise InputError(f"the sweep folder is given twice ({twice} and {d}): its results "
                             "would count twice", file=str(d))
    inputs = [args.paper_values] if args.paper_values is not None else []
    if args.design is not None:
        inputs.append(args.design)
    output(args.out, args, "--out", inputs=inputs, suffixes=(".html", ".htm"))
    output(args.md, args, "--md", inputs=inputs, suffixes=(".md",))
    if args.md is not None:      # its figures beside it, checked before the work too
        markdown_figures(args.md, inputs=inputs, force=args.force)
    res = write_report(args.dirs, args.out, args.md, design=args.design,
                       paper_values=args.paper_values, top=args.top, force=args.force)
    lines = [f"report: {res['html']}" + (f" (Markdown twin {res['markdown']})" if res["markdown"] else "")
             + f", {res['figures']} figures, {res['seconds']:.1f} s"]
    if res.get("decision"):
        lines += res["decision"]["summary"]
    for b in res["best"]:
        lines.append(f"best for {b['motion']}: scheme {b['scheme']}, N = {b['n_gyros']}, "
                     f"alpha = {b['alpha_deg']:.2f} deg, rho_arw = {b['rho_arw']}, {b['estimator']}: "
                     f"1-sigma {b['sigma_1_deg_s']:.4g} deg/s")
    flagged = [(e["title"], v) for e in res["paper_vs_model"] for v in e["values"] if v["flag"]]
    n_all = sum(len(e["values"]) for e in res["paper_vs_model"])
    if n_all:
        lines.append(f"paper vs model: {n_all - len(flagged)} of {n_all} published values inside "
                     "the model's 95 % band")
    lines += [f"note: {n}" for n in res["notes"]]
    return res, "\n".join(lines)


def add_parser(sub) -> None:
    """The ``simulate``, ``run``, ``sweep`` and ``report`` subcommands."""
    p = sub.add_parser("simulate", help="simulate a scenario into a measurement (CSV.GZ + TOML)")
    p.add_argument("scenario", type=Path, metavar="SCENARIO.toml")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    p.add_argument("--no-cache", action="store_true", help="recompute the rate-table truth")
    add_force(p)
    add_plugin(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_simulate)
    p.plugin_help = True

    p = sub.add_parser("run", help="simulate a scenario and score fusion estimators")
    p.add_argument("scenario", type=Path, metavar="SCENARIO.toml")
    p.add_argument("--estimators", metavar="A,B,...",
                   help="registry names (default: kf_array, kf_single, gls, ols, naive, bound)")
    p.add_argument("--no-cache", action="store_true", help="recompute the rate-table truth")
    add_plugin(p)
    p.add_argument("--replicates", type=count("--replicates"), metavar="K",
                   help="run K times with independent seeds: mean and 95 %% CI of every metric, "
                        "beside the analytic prediction")
    p.add_argument("--seed", type=nonneg_int("--seed"), metavar="S",
                   help="root seed of the replicates (default: the scenario's seed)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_run)
    p.plugin_help = True

    p = sub.add_parser("sweep", help="run a sweep of scenarios in parallel into a Parquet dataset (resumable)")
    p.add_argument("sweep", type=Path, metavar="SWEEP.toml")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    p.add_argument("--workers", type=count("--workers"), metavar="K",
                   help="local worker processes (default 1; at most 4 per CPU, and as many as "
                        "the memory budget holds at about 320 MiB each plus the largest scenario's arrays)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a Dask distributed scheduler")
    p.add_argument("--dask", metavar="local:N",
                   help="start a Dask LocalCluster of N single-thread worker processes, run there, "
                        "close it after (N: as for --workers; each worker bounded at its share of "
                        "--max-memory)")
    p.add_argument("--json", action="store_true", help="print one JSON object (no progress bar)")
    p.set_defaults(func=cmd_sweep)
    p.plugin_help = True

    p = sub.add_parser("report", help="design comparison report (HTML + Markdown) from sweep folders")
    p.add_argument("dirs", type=Path, nargs="*", metavar="DIR", help="gyroarray sweep --out folders")
    p.add_argument("--design", type=Path, metavar="FILE.json",
                   help="a gyroarray design --recommend --out result: the decision opens the report")
    p.add_argument("--out", type=Path, required=True, metavar="REPORT.html")
    p.add_argument("--md", type=Path, metavar="REPORT.md", help="also write a Markdown twin")
    p.add_argument("--paper-values", type=Path, metavar="FILE",
                   help="paper values to compare with (default: the shipped scenarios/paper_values.toml)")
    p.add_argument("--top", type=int, default=15, metavar="K", help="designs listed per motion (15)")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_report)

