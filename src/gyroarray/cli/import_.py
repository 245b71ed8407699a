"""``gyroarray import``: the output of imu_utils or allan_variance_ros as a gyroarray noise model,
with the tool's true meanings (:mod:`gyroarray.chain.importers`; ``docs/tool-conventions.md``).

The chain (ruamel.yaml, the effect registry) is imported inside the command, so that building
the parser (``gyroarray --help``, every other command) does not load it.
"""

from __future__ import annotations

from pathlib import Path

from gyroarray.cli.common import add_force, float_in, output

__all__ = ["add_parser", "cmd_import", "TOOL_NAMES"]

#: The tools (the keys of :data:`gyroarray.chain.importers.TOOLS`, listed here so that building
#: the parser loads nothing).
TOOL_NAMES = ("imu_utils", "allan_variance_ros")


def cmd_import(args):
    # deferred: the chain (ruamel.yaml, the effect registry) loads only when the command runs
    from gyroarray.chain.importers import import_noise
    from gyroarray.core.outputs import write_text
    out = output(args.out, args, "--out", inputs=[args.file], suffixes=(".toml",))
    model, summary = import_noise(args.file, args.tool, args.rate_hz)
    write_text(out, model.to_toml(), force=args.force)
    summary["out"] = str(out)
    summary["effects"] = model.to_dicts()
    lines = [f"wrote {out}: {args.tool} file {args.file} as a gyroarray noise model"]
    for g in summary["gyros"]:
        who = "every gyro" if g["gyro"] is None else f"gyro {g['gyro']} ({g['axis']})"
        if args.tool == "imu_utils":
            lines.append(f"  {who}: gyr_n {g['gyr_n_rad_s']:.6g} rad/s per sample -> ARW "
                         f"{g['n_deg_rt_h']:.5g} deg/√h (÷√{summary['rate_hz']:g} Hz); gyr_w "
                         f"{g['gyr_w_rad_s']:.6g} rad/s ADEV floor -> bias instability "
                         f"{g['b_deg_h']:.5g} deg/h (÷0.664)")
        else:
            lines.append(f"  {who} (the file's worst axis): gyroscope_noise_density "
                         f"{g['gyroscope_noise_density']:.6g} -> ARW {g['n_deg_rt_h']:.5g} deg/√h; "
                         f"gyroscope_random_walk {g['gyroscope_random_walk']:.6g} -> RRW "
                         f"{g['k_deg_h_rt_h']:.5g} deg/h/√h")
    acc = summary.get("accelerometer")
    if acc is None:
        lines.append("  accelerometer: none in the file (no [accelerometer] table)")
    else:
        parts = []
        if acc.get("n_m_s_rt_h"):
            parts.append("VRW " + ", ".join(f"{v:.4g}" for v in acc["n_m_s_rt_h"]) + " m/s/√h")
        if acc.get("k_m_s2_rt_h"):
            parts.append("acc. RW " + ", ".join(f"{v:.4g}" for v in acc["k_m_s2_rt_h"]) + " m/s²/√h")
        if acc.get("b_mg"):
            parts.append("BI " + ", ".join(f"{v:.4g}" for v in acc["b_mg"]) + " mg")
        lines.append(f"  accelerometer (x, y, z): {'; '.join(parts)}; missing: "
                     f"{', '.join(acc['missing']) or 'none'}")
    if summary.get("topic"):
        lines.append(f"  topic: {summary['topic']}")
    lines += [f"  note: {n}" for n in summary.get("notes", [])]
    lines.append("  (the model's description and [accelerometer].notes say where each number came from)")
    return summary, "\n".join(lines)


def add_parser(sub) -> None:
    """The ``import`` subcommand."""
    p = sub.add_parser("import", help="read imu_utils' or allan_variance_ros' output YAML into a "
                                      "noise model, with the tool's true meanings")
    p.add_argument("tool", choices=TOOL_NAMES,
                   help="imu_utils (NAME_imu_param.yaml: gyr_n per-sample σ, gyr_w ADEV floor) or "
                        "allan_variance_ros (imu.yaml: continuous densities, worst axis)")
    p.add_argument("file", type=Path, metavar="FILE.yaml", help="the tool's output (never modified)")
    p.add_argument("--out", type=Path, required=True, metavar="MODEL.toml",
                   help="the noise model to write")
    p.add_argument("--rate-hz", type=float_in("--rate-hz", 1e-3, 1e6, unit="Hz"), metavar="R",
                   help="the IMU's sample rate [Hz]; required for imu_utils, whose gyr_n and acc_n "
                        "are per-sample standard deviations")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_import)
