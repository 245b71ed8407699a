"""``gyroarray check``: run the paper scenarios and compare metrics with stated bounds.

The bounds live in ``scenarios/thresholds.toml`` (data only), one ``[[check]]``
table per bound::

    [[check]]
    scenario = "paper003/static_s1_n6_rhob_0"   # file under scenarios/, without .toml
    quick_duration_s = 300                      # run length of the quick check [s]
    estimator = "kf_array"
    axis = "all"                                # x, y, z or all
    metric = "sigma_1_deg_s"                    # a column of RunResult.table
    min = 0.0118                                # and/or max

Checks are grouped by (scenario, duration), so each scenario is simulated
once, with the union of the estimators its checks name (plus ``bound`` when
a check asks for ``efficiency``).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from gyroarray.chain.fdi_score import FDI_METRICS
from gyroarray.chain import run as chain_run   # chain_run.run_scenario: looked up at each call
from gyroarray.core.errors import InputError
from gyroarray.core.tomlio import load_toml
from gyroarray.core.data import data_path
from gyroarray.estimators import available

#: Metrics a check may bound (columns of :attr:`gyroarray.chain.run.RunResult.table`).
METRICS = ("sigma_1_deg_s", "mean_error_deg_s", "rms_deg_s", "angle_error_deg", "reduction",
           "attenuation", "phase_deg",
           "arw_deg_rt_h", "bi_deg_h", "rrw_deg_h_rt_h", "arw_reduction", "bi_reduction",
           "rrw_reduction", "noise_density_deg_s_rt_hz", "efficiency") + FDI_METRICS
_KEYS = {"scenario", "quick_duration_s", "estimator", "axis", "metric", "min", "max"}
_REQUIRED = ("scenario", "quick_duration_s", "estimator", "axis", "metric")
_AXES = ("x", "y", "z")


def scenarios_dir() -> Path:
    """The shipped ``scenarios/`` folder."""
    return Path(str(data_path("scenarios")))


def default_thresholds() -> Path:
    return scenarios_dir() / "thresholds.toml"


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def load_thresholds(path) -> list[dict]:
    """Read and strictly validate a thresholds file; InputError names the file and key."""
    path = Path(path)
    f = str(path)
    data = load_toml(path, "thresholds file").data
    unknown = sorted(set(data) - {"check"})
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r} (known: check)", file=f, column=unknown[0])
    checks = data.get("check")
    if not isinstance(checks, list) or not checks or not all(isinstance(c, dict) for c in checks):
        raise InputError("no [[check]] tables", file=f, column="check")
    base = scenarios_dir() if path.resolve() == default_thresholds().resolve() else path.parent
    out = []
    for i, c in enumerate(checks):
        where = f"check[{i}]"
        bad = sorted(set(c) - _KEYS)
        if bad:
            raise InputError(f"unknown key {bad[0]!r} (known: {', '.join(sorted(_KEYS))})",
                             file=f, column=f"{where}.{bad[0]}")
        for key in _REQUIRED:
            if key not in c:
                raise InputError(f"{key} is missing", file=f, column=f"{where}.{key}")
        for key in ("scenario", "estimator", "axis", "metric"):
            if not isinstance(c[key], str) or not c[key]:
                raise InputError(f"{key} must be a non-empty string", file=f, column=f"{where}.{key}")
        if c["metric"] not in METRICS:
            raise InputError(f"unknown metric {c['metric']!r} (known: {', '.join(METRICS)})",
                             file=f, column=f"{where}.metric")
        if c["axis"] not in _AXES + ("all",):
            raise InputError(f"axis must be x, y, z or all, got {c['axis']!r}", file=f,
                             column=f"{where}.axis")
        if c["estimator"] not in available():
            raise InputError(f"unknown estimator {c['estimator']!r} (available: "
                             f"{', '.join(available())})", file=f, column=f"{where}.estimator")
        if not _is_number(c["quick_duration_s"]) or c["quick_duration_s"] <= 0:
            raise InputError("quick_duration_s must be a number > 0 [s]", file=f,
                             column=f"{where}.quick_duration_s")
        if "min" not in c and "max" not in c:
            raise InputError("a check needs min and/or max", file=f, column=where)
        for key in ("min", "max"):
            if key in c and not _is_number(c[key]):
                raise InputError(f"{key} must be a finite number", file=f, column=f"{where}.{key}")
        if "min" in c and "max" in c and c["min"] > c["max"]:
            raise InputError(f"min {c['min']} > max {c['max']}", file=f, column=f"{where}.min")
        scen = base / (c["scenario"] + ".toml")
        if not scen.is_file():
            raise InputError(f"scenario {c['scenario']!r} not found ({scen})", file=f,
                             column=f"{where}.scenario")
        out.append({**c, "file": scen})
    return out


def bound_text(check: dict) -> str:
    lo, hi = check.get("min"), check.get("max")
    if lo is not None and hi is not None:
        return f"[{lo:g}, {hi:g}]"
    return f"≥ {lo:g}" if lo is not None else f"≤ {hi:g}"


def _passes(value, check: dict) -> bool:
    if value is None or not isinstance(value, (int, float)) or not math.isfinite(value):
        return False
    return ("min" not in check or value >= check["min"]) and ("max" not in check or value <= check["max"])


def run_check(path=None, *, quick: bool = True) -> dict:
    """Run every check of a thresholds file (default: the shipped one).

    Parameters
    ----------
    path : path-like, optional
        Thresholds file; default ``scenarios/thresholds.toml``.
    quick : bool
        Cut each scenario to its ``quick_duration_s`` (False: the full scenario).

    Returns
    -------
    dict
        ``{"passed": bool, "results": [{"scenario", "metric", "estimator", "axis",
        "bound", "value", "pass"}, ...]}``; a missing or non-finite value fails.
    """
    from gyroarray.sim.scenario import load_scenario  # lazy: loads mujoco
    checks = load_thresholds(default_thresholds() if path is None else path)
    groups: dict[tuple, list[dict]] = {}
    for c in checks:
        key = (c["scenario"], float(c["quick_duration_s"]) if quick else None)
        groups.setdefault(key, []).append(c)
    results = []
    for (name, duration), group in groups.items():
        scenario = load_scenario(group[0]["file"])
        if duration is not None:
            full = scenario.duration_s or scenario.profile.duration_s
            scenario = replace(scenario, duration_s=min(duration, full))
        names = list(dict.fromkeys(c["estimator"] for c in group))
        if any(c["metric"] == "efficiency" for c in group) and "bound" not in names:
            names.append("bound")
        table = chain_run.run_scenario(scenario, names).table
        for c in group:
            for axis in (_AXES if c["axis"] == "all" else (c["axis"],)):
                row = table[(table.estimator == c["estimator"]) & (table.axis == axis)]
                value = row[c["metric"]].iloc[0] if len(row) else None
                value = None if value is None or (isinstance(value, float) and math.isnan(value)) \
                    else float(value)
                results.append({"scenario": name, "metric": c["metric"], "estimator": c["estimator"],
                                "axis": axis, "bound": bound_text(c), "value": value,
                                "pass": _passes(value, c)})
    return {"passed": all(r["pass"] for r in results), "results": results}


def format_check(result: dict) -> str:
    """The check result as a text table (one line per metric and axis)."""
    head = ("scenario", "estimator", "axis", "metric", "bound", "value", "result")
    rows = [(r["scenario"], r["estimator"], r["axis"], r["metric"], str(r["bound"]),
             "—" if r["value"] is None else f"{r['value']:.4g}", "pass" if r["pass"] else "FAIL")
            for r in result["results"]]
    widths = [max(len(h), *(len(row[i]) for row in rows)) if rows else len(h)
              for i, h in enumerate(head)]
    line = lambda cells: "  ".join(c.ljust(w) for c, w in zip(cells, widths)).rstrip()
    n_fail = sum(not r["pass"] for r in result["results"])
    out = [line(head), line(["-" * w for w in widths]), *map(line, rows),
           f"{len(rows) - n_fail}/{len(rows)} passed" + ("" if result["passed"] else f", {n_fail} FAILED")]
    return "\n".join(out)
