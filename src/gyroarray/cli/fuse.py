"""``gyroarray fuse``: apply a registered estimator to a recorded array, write the fused body
rate as a measurement, and say what fusion bought (:mod:`gyroarray.chain.fuse`).

numpy and the chain are imported inside the command, so that building the parser does not
load them.
"""

from __future__ import annotations

import math
from pathlib import Path

from gyroarray.core.errors import InputError
from gyroarray.cli.common import add_bag_options, bag_options, add_force, add_plugin, finite_float, measurement_inputs, output, stream_reason

__all__ = ["add_parser", "cmd_fuse", "parse_exclude", "parse_params", "sidecar_path"]

#: Suffixes of the fused record (the measurement format's CSV, plain or gzip, or Parquet).
OUT_SUFFIXES = (".csv", ".csv.gz", ".parquet")


def parse_exclude(text: str | None) -> list[int]:
    """``"5,7"`` -> [5, 7] (1-based gyro numbers); one-line refusal of anything else."""
    if text is None:
        return []
    out = []
    for part in str(text).split(","):
        p = part.strip()
        if not p.isdigit() or int(p) < 1:
            raise InputError(f"--exclude must be a comma-separated list of gyro numbers (1-based), "
                             f"e.g. 5,7; got {str(text)[:60]!r}")
        out.append(int(p))
    return out


def parse_params(items) -> dict:
    """``["tau_s=2", "bias_states=false"]`` -> {"tau_s": 2.0, "bias_states": False}: numbers,
    true/false and none are converted, anything else stays a string."""
    out: dict = {}
    for item in items or ():
        key, sep, text = str(item).partition("=")
        key = key.strip()
        if not sep or not key.isidentifier():
            raise InputError(f"--param must be KEY=VALUE with KEY a hyperparameter name, got {str(item)[:60]!r}")
        low = text.strip().lower()
        if low in ("true", "false"):
            out[key] = low == "true"
        elif low in ("none", "null"):
            out[key] = None
        else:
            try:
                value = float(text)
            except ValueError:
                out[key] = text.strip()
                continue
            if not math.isfinite(value):
                raise InputError(f"--param {key}: the value must be finite, got {text!r}")
            out[key] = value
    return out


def sidecar_path(csv_path: Path) -> Path:
    """``F.csv.gz`` / ``F.csv`` -> ``F.toml`` beside it."""
    name = csv_path.name
    for suffix in (".csv.gz", ".csv", ".parquet"):
        if name.lower().endswith(suffix):
            return csv_path.with_name(name[: -len(suffix)] + ".toml")
    return csv_path.with_name(name + ".toml")


def _fmt(v, spec: str = ".4g") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def _text(out: dict, args) -> str:
    lines = [f"{args.measurement}: {out['n_samples']} samples at {1.0 / out['dt_s']:g} Hz; fused "
             f"{len(out['gyros_used'])} gyros with {out['estimator']}",
             f"estimator noise: {out['model_source']}",
             f"analysed: {out['analysed']}"]
    lines += [f"note: {n}" for n in out["notes"] if not n.startswith("no --model")]
    lines.append(f"{'axis':<5}{'fused ARW':>16}{'predicted':>11}{'best gyro':>11}{'its ARW':>9}"
                 f"{'gain':>7}   [deg/rt(h)]")
    for name, d in out["axes"].items():
        arw = d.get("arw_deg_rt_h")
        s = d.get("arw_deg_rt_h_sigma")
        fused = "-" if arw is None else (f"{arw:.4g} ± {s:.2g}" if s is not None and math.isfinite(s)
                                         else f"{arw:.4g}")
        lines.append(f"{name:<5}{fused:>16}{_fmt(d.get('predicted_arw_deg_rt_h')):>11}"
                     f"{_fmt(d.get('best_single_gyro'), 'd'):>11}{_fmt(d.get('best_single_arw_deg_rt_h')):>9}"
                     f"{_fmt(d.get('gain'), '.3g'):>7}")
    chk = out.get("model_check") or {}
    if chk.get("predicted_interval_deg_rt_h"):
        lines.append("model check: predicted fused ARW " + ", ".join(
            f"{a} {p:.4g} [{lo:.4g}, {hi:.4g}]" for a, p, (lo, hi) in
            zip("xyz", chk["predicted_arw_deg_rt_h"], chk["predicted_interval_deg_rt_h"]))
            + f" deg/rt(h) ({100 * chk['level']:.0f} %); gyros off the model: "
            + (", ".join(map(str, chk["off"])) or "none")
            + "; fused / OLS " + ", ".join(f"{v:.3g}" for v in chk.get("fused_over_ols", [])))
    x = out["axes"]["x"]
    if "taus_s" in x:
        conf = 100.0 * x["confidence"]
        lines.append(f"fused ADEV [deg/h], {conf:.1f} % CI:")
        lines.append(f"  {'tau_s':>9}" + "".join(f"{a:>30}" for a in out["axes"]))
        for i, tau in enumerate(x["taus_s"]):
            cells = []
            for d in out["axes"].values():
                if "taus_s" not in d or i >= len(d["taus_s"]):
                    cells.append(f"{'-':>30}")
                    continue
                cells.append(f"{d['adev_deg_h'][i]:>12.5g} [{d['ci_low_deg_h'][i]:.4g}, "
                             f"{d['ci_high_deg_h'][i]:.4g}]".rjust(30))
            lines.append(f"  {tau:>9.4g}" + "".join(cells))
    lines.append(out["gain_definition"])
    if out.get("out"):
        lines.append(f"wrote {out['out']} and {out['sidecar']}")
    else:
        lines.append("nothing written (no --out)")
    return "\n".join(lines)


def _validation_text(val: dict) -> list[str]:
    """Lines of ``--validate``: per axis the ARWs, the verdicts and the ADEV against both bands."""
    head = (f"validation: fitted on {val['fit_s']:.1f} s, held out {val['held_s']:.1f} s"
            if val["holdout"] is not None else f"validation of the model on {val['held_s']:.1f} s")
    lines = [f"{head} ({100 * val['level']:g} % prediction band, {val['runs']} runs)",
             f"{'axis':<5}{'best gyro':>10}{'its ARW':>9}{'fused ARW':>16}{'pred indep':>12}{'pred cov':>10}"
             "   [deg/rt(h)]"]
    for name, d in val["axes"].items():
        p = d["predicted"]
        fused = f"{d['measured_arw_deg_rt_h']:.4g} ± {d['measured_arw_deg_rt_h_sigma']:.2g}"
        lines.append(f"{name:<5}{_fmt(d['best_single_gyro'], 'd'):>10}{_fmt(d['best_single_arw_deg_rt_h']):>9}"
                     f"{fused:>16}{_fmt(p['independent']['arw_deg_rt_h']):>12}"
                     f"{_fmt(p['covariance']['arw_deg_rt_h']):>10}")
    for name, d in val["axes"].items():
        for kind in ("independent", "covariance"):
            lines.append(f"{name} {kind}: {d['predicted'][kind]['verdict']}")
    lines.append("fused ADEV [deg/h] held out, against the bands (* = outside):")
    for name, d in val["axes"].items():
        lines.append(f"  {name}: {'tau_s':>8}{'measured':>11}{'independent':>22}{'covariance':>22}")
        pi, pc = d["predicted"]["independent"], d["predicted"]["covariance"]
        for i, tau in enumerate(d["taus_s"]):
            cells = []
            for p in (pi, pc):
                flag = " " if p["inside"][i] is None else ("" if p["inside"][i] else "*")
                cells.append(f"{flag}[{p['band_low_deg_h'][i]:.4g}, {p['band_high_deg_h'][i]:.4g}]".rjust(22))
            lines.append(f"     {tau:>8.4g}{d['measured_adev_deg_h'][i]:>11.5g}" + "".join(cells))
    lines += [f"note: {n}" for n in val["notes"]]
    return lines


def _cmd_fuse_streamed(args, why: str, exclude, params, side) -> tuple[dict, str]:
    """``fuse`` on a record read in chunks (:mod:`gyroarray.chain.fuse_stream`)."""
    # deferred: the chain (numpy, numba) loads only when the command runs (a fast --help)
    from gyroarray.chain.fuse import sha256_of
    from gyroarray.chain.fuse_stream import streamed_fuse
    from gyroarray.core.measurement import record_head
    from gyroarray.effects.model import NoiseModel
    name = str(args.measurement)
    way = "; raise --max-memory to fuse it in memory" if why != "--stream" else "; leave out --stream"
    for flag, on in (("--validate", args.validate), ("--holdout", args.holdout is not None),
                     ("--repair", args.repair)):
        if on:
            raise InputError(f"{flag} needs the record in memory, and this one is streamed ({why}){way}",
                             file=name)
    head = record_head(args.measurement)
    model = None if args.model is None else NoiseModel.from_toml(args.model, n_gyros=head.n_gyros)
    src = Path(head.source)
    out = streamed_fuse(head, args.estimator, model=model,
                        model_name=None if args.model is None else str(args.model), exclude=exclude,
                        params=params, out=args.out, whole=args.all, site=head.site,
                        input_sha256=sha256_of(src) if args.out is not None else None,
                        sidecar_sha256=sha256_of(sidecar_path(src)) if args.out is not None else None,
                        sidecar=side, force=args.force)   # both named together at the end
    out.pop("sidecar_toml")
    out["notes"] = [*head.notes, f"streamed ({why})", *out["notes"]]
    if args.out is not None:
        out["out"], out["sidecar"] = str(args.out), str(side)
    return out, _text(out, args)


def cmd_fuse(args) -> tuple[dict, str]:
    # deferred: the chain (numpy, numba) loads only when the command runs (a fast --help)
    from gyroarray.chain.fuse import fuse, fused_files, fused_measurement, sha256_of, validate_fuse
    from gyroarray.core.measurement import parquet_bytes, read_measurement
    from gyroarray.core.outputs import write_many
    from gyroarray.effects.model import NoiseModel
    exclude = parse_exclude(args.exclude)
    params = parse_params(args.param)
    inputs = measurement_inputs(args)
    side = None
    if args.out is not None:
        output(args.out, args, "--out", inputs=inputs, suffixes=OUT_SUFFIXES)
        side = sidecar_path(Path(args.out))
        output(side, args, "--out (its sidecar)", inputs=inputs)
    if args.off_levels != "record" and args.model is None:
        raise InputError("--off-levels says what to do with a model's gyro whose level is off: add --model")
    why = stream_reason(args)
    if why is not None:
        return _cmd_fuse_streamed(args, why, exclude, params, side)
    meas = read_measurement(args.measurement, repair=args.repair, **bag_options(args))
    model = None
    if args.model is not None:
        model = NoiseModel.from_toml(args.model, n_gyros=meas.n_gyros)
    val = None
    if args.holdout is not None and not args.validate:
        raise InputError("--holdout is the part held out by --validate: add --validate")
    if args.validate:
        holdout = args.holdout if args.holdout is not None or model is not None else 0.5
        res, val = validate_fuse(meas, args.estimator, holdout=holdout, exclude=exclude, params=params,
                                 model=model, model_name=None if args.model is None else str(args.model),
                                 off_levels=args.off_levels)
    else:
        res = fuse(meas, args.estimator, model=model,
                   model_name=None if args.model is None else str(args.model), exclude=exclude,
                   params=params, off_levels=args.off_levels)
    out = res.to_json_dict()
    if val is not None:
        out["validation"] = val
    out["notes"] = [*meas.notes, *out["notes"]]
    if args.out is not None:
        csv_path = Path(meas.source) if meas.source else Path(args.measurement)
        csv_bytes, toml_bytes = fused_files(
            res, str(args.out).lower().endswith(".gz"), input_sha256=sha256_of(csv_path),
            sidecar_sha256=sha256_of(sidecar_path(csv_path)))
        if str(args.out).lower().endswith(".parquet"):
            csv_bytes = parquet_bytes(fused_measurement(res))
        write_many([(args.out, csv_bytes), (side, toml_bytes)], force=args.force)
        out["out"], out["sidecar"] = str(args.out), str(side)
    text = _text(out, args)
    if val is not None:
        text += "\n" + "\n".join(_validation_text(val))
    return out, text


def add_parser(sub) -> None:
    """The ``fuse`` subcommand."""
    p = sub.add_parser("fuse", help="fuse a recorded array with an estimator: the fused body rate as a "
                                    "measurement, its ADEV and the gain over the best single gyro")
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    add_bag_options(p)
    p.add_argument("--estimator", required=True, metavar="NAME",
                   help="registered estimator (gls, ols, kf_array, kf_single, naive, ...; "
                        "installed plugins too)")
    p.add_argument("--param", action="append", metavar="KEY=VALUE",
                   help="a hyperparameter of the estimator (repeatable), e.g. tau_s=2 (svo), "
                        "bandwidth_hz=5 (kf_array), lowpass_hz=10 (gls)")
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="noise of the gyros (arw, rrw, correlation) the estimator is designed with "
                        "(default: ARW + RRW per gyro fitted on the record's still part)")
    p.add_argument("--off-levels", choices=("record", "model"), default="record",
                   help="with --model: each gyro's white level on the record is checked against the "
                        "model's range first; a gyro outside it is designed with the record's own level "
                        "(record, the default) or the model's (model); the check is reported either way")
    p.add_argument("--exclude", metavar="K1,K2,...",
                   help="gyros to leave out (1-based, comma separated); constant gyros are left "
                        "out anyway")
    p.add_argument("--out", type=Path, metavar="FUSED.csv.gz",
                   help="write the fused body rate (gyro1..3 = x, y, z [deg/s]) and its sidecar "
                        "FUSED.toml")
    p.add_argument("--repair", action="store_true",
                   help="repair short gaps, missing values, exact duplicate rows and a jittering clock "
                        "(each listed)")
    p.add_argument("--validate", action="store_true",
                   help="fit the array model (per gyro ARW + RRW, the white and slow correlations) on the "
                        "first part of the still data, predict the fused ADEV per axis with its band (gyros "
                        "independent, and with the fitted covariance), and test it tau by tau on the rest "
                        "(with --model: the model's prediction on the whole record)")
    p.add_argument("--holdout", type=finite_float("--holdout"), metavar="FRACTION",
                   help="with --validate: the last FRACTION of the still data held out (0.5)")
    p.add_argument("--stream", action="store_true",
                   help="read the record in chunks, never whole (automatic for a record estimated "
                        "beyond 2 GiB or --max-memory; Parquet recommended): fixed linear estimators "
                        "(gls, ols, naive, svo with --model, kf_array, kf_single), the whole record analysed")
    p.add_argument("--all", action="store_true",
                   help="streamed: analyse a record without reference whole even when it moves")
    add_plugin(p)
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_fuse)
