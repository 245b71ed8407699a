#!/usr/bin/env python3
"""Regenerate the numbers the docs quote from the runs that produce them (``make docs-numbers``).

A docs page marks a generated passage with an opening and a closing HTML comment, each on its
own line (MyST and GitHub render neither)::

    <!-- numbers:adis-plan -->
    For the ADIS16405 ... needs 8.1, 5.4 and 3.2 h ...
    <!-- /numbers -->

Each name in :data:`REGIONS` has the pages it appears in, the ``gyroarray`` commands that
produce its numbers (run here, with ``--json``, through this interpreter's ``python -m
gyroarray.cli``) and the text written from their output. The passage between the markers is
replaced by that text; nothing else in the page is touched, and a page is rewritten
atomically (:func:`gyroarray.core.outputs.write_text`) only when it changes.

Usage::

    python scripts/docs_numbers.py            # run the commands, rewrite the passages
    python scripts/docs_numbers.py --check    # exit 1 and name the passages that are stale
    python scripts/docs_numbers.py --markers  # only check that the markers are well formed (fast)

``adis-plan`` (docs/export.md): ``gyroarray fit`` of the shared ADIS16405 static record (2.78 h at
100 Hz, ARW + RRW per gyro), ``gyroarray plan --model`` on that fit at 100 Hz with ``--at-h`` the
record's length, ``gyroarray allan`` for gyro 1's bias instability, and ``gyroarray plan`` of
gyro 1 with it (about 35 s in all).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The shared data folder (``shared/measurements/real/...``), beside the repository.
SHARED = Path(os.environ.get("GYROARRAY_SHARED", ROOT.parent / "shared"))

OPEN = re.compile(r"^<!-- numbers:([a-z0-9][a-z0-9-]*) -->[ \t]*$")
CLOSE = re.compile(r"^<!-- /numbers -->[ \t]*$")
#: Any line that looks like a marker (a misspelt one is refused, not ignored).
LOOSE = re.compile(r"<!--\s*/?\s*numbers\b")

#: Width the generated paragraphs are wrapped at [characters] (the docs' own).
WIDTH = 95


class MarkerError(ValueError):
    """A docs page whose markers are not well formed (file and 1-based line in the message)."""


def regions(text: str, name: str = "<text>") -> list[tuple[str, int, int]]:
    """The marked passages of a page: (region name, first body line, end line), 0-based line
    indices, the body being ``lines[first:end]`` (between the opening and the closing marker).

    Raises
    ------
    MarkerError
        A marker inside another's passage, a closing marker without its opening one, an opening
        one without its closing one, a name twice in a page, a misspelt marker line.
    """
    out, current = [], None
    seen: set[str] = set()
    for i, line in enumerate(text.split("\n")):
        opened, closed = OPEN.match(line), CLOSE.match(line)
        if not opened and not closed and LOOSE.search(line):
            raise MarkerError(f"{name}:{i + 1}: not a marker line: write '<!-- numbers:NAME -->' or "
                              f"'<!-- /numbers -->' alone on a line, got {line.strip()[:60]!r}")
        if opened:
            if current is not None:
                raise MarkerError(f"{name}:{i + 1}: 'numbers:{opened.group(1)}' opens inside "
                                  f"'numbers:{current[0]}' (line {current[1]})")
            if opened.group(1) in seen:
                raise MarkerError(f"{name}:{i + 1}: 'numbers:{opened.group(1)}' appears twice")
            seen.add(opened.group(1))
            current = (opened.group(1), i + 1)
        elif closed:
            if current is None:
                raise MarkerError(f"{name}:{i + 1}: '<!-- /numbers -->' without an opening marker")
            out.append((current[0], current[1], i))
            current = None
    if current is not None:
        raise MarkerError(f"{name}:{current[1]}: 'numbers:{current[0]}' is never closed")
    return out


def replace_regions(text: str, bodies: dict[str, str], name: str = "<text>") -> str:
    """``text`` with the passage of each region named in ``bodies`` replaced by its body (the
    others, and everything outside the markers, unchanged)."""
    lines = text.split("\n")
    for region, first, end in reversed(regions(text, name)):
        if region in bodies:
            lines[first:end] = bodies[region].rstrip("\n").split("\n")
    return "\n".join(lines)


def body(text: str, region: str, name: str = "<text>") -> str | None:
    """The current passage of ``region`` in ``text`` (None when the page does not mark it)."""
    lines = text.split("\n")
    for r, first, end in regions(text, name):
        if r == region:
            return "\n".join(lines[first:end])
    return None


def wrap(text: str, width: int = WIDTH) -> str:
    """``text`` wrapped at ``width`` on spaces (no hyphenation; a ``±16`` and a code span stay
    whole)."""
    import textwrap
    flat = re.sub(r"`[^`]*`", lambda m: m.group().replace(" ", "\0"), " ".join(text.split()))
    lines = textwrap.wrap(flat, width=width, break_long_words=False, break_on_hyphens=False)
    return "\n".join(line.replace("\0", " ") for line in lines)


def gyroarray(*args: str) -> dict:
    """Run ``gyroarray ARGS --json`` in this interpreter; its JSON output."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS", "1"))
    proc = subprocess.run([sys.executable, "-m", "gyroarray.cli", *args, "--json"], capture_output=True,
                          text=True, cwd=ROOT, env=env)
    if proc.returncode != 0:
        raise SystemExit(f"docs_numbers: 'gyroarray {' '.join(args)}' failed (exit {proc.returncode}): "
                         f"{proc.stderr.strip()[-500:]}")
    return json.loads(proc.stdout)


# -- adis-plan: docs/export.md, the ADIS16405 plan -----------------------------------------------

ADIS = SHARED / "measurements" / "real" / "adis16405_static.csv.gz"


def compute_adis_plan() -> dict:
    """The numbers of the ``adis-plan`` passage, from fit, plan, allan and plan again."""
    if not ADIS.exists():
        raise SystemExit(f"docs_numbers: {ADIS} is missing (set GYROARRAY_SHARED to the shared folder)")
    rate, record_h = _record()
    with tempfile.TemporaryDirectory(prefix="docs-numbers-") as tmp:
        model = Path(tmp) / "adis_fit.toml"
        gyroarray("fit", str(ADIS), "--out", str(model))
        fitted = _entries(model)
        plan = gyroarray("plan", "--model", str(model), "--rate-hz", f"{rate:g}", "--at-h", f"{record_h:.6g}")
    allan = gyroarray("allan", str(ADIS))
    n1, k = fitted["arw"][1]["n_deg_rt_h"], {g: p["k_deg_h_rt_h"] for g, p in fitted["rrw"].items()}
    b1 = float(allan["gyros"]["1"]["fit"]["bi_deg_h"])
    plan_bi = gyroarray("plan", "--arw", repr(n1), "--bi", repr(b1), "--rrw", repr(k[1]),
                        "--rate-hz", f"{rate:g}", "--at-h", f"{record_h:.6g}")
    rrw = [g["terms"]["rrw_deg_h_rt_h"] for g in plan["gyros"]]
    bi_rrw = plan_bi["gyros"][0]["terms"]["rrw_deg_h_rt_h"]
    return {"record_h": record_h, "rate_hz": rate, "k": [k[g] for g in sorted(k)],
            "need_h": [t["record_h"] for t in rrw], "at_record": [t["precision_at_record"] for t in rrw],
            "fit_sigma": [t["model_sigma_rel"] for t in rrw], "b1_deg_h": b1,
            "bi_need_h": bi_rrw["record_h"], "bi_at_record": bi_rrw["precision_at_record"]}


def _entries(model: Path) -> dict:
    """The fitted model's entries, ``{effect: {gyro: params}}``, as gyroarray reads them."""
    from gyroarray.effects.model import NoiseModel
    out: dict = {}
    for e in NoiseModel.from_toml(model).entries:
        out.setdefault(e.effect, {})[e.gyro] = dict(e.params)
    return out


def _record() -> tuple[float, float]:
    """The ADIS record's rate [Hz] (its sidecar) and length [h] (its rows at that rate)."""
    import gzip
    import tomllib
    rate = float(tomllib.loads(ADIS.with_name("adis16405_static.toml").read_text())["sample_rate_hz"])
    with gzip.open(ADIS, "rt") as fh:
        rows = sum(1 for line in fh if line[:1].isdigit() or line[:1] in "-+.")
    return rate, rows / rate / 3600.0


def _list(values, fmt) -> str:
    """``a, b and c`` of the values formatted by ``fmt``."""
    parts = [fmt(v) for v in values]
    return ", ".join(parts[:-1]) + " and " + parts[-1] if len(parts) > 1 else parts[0]


def _pct(x: float) -> str:
    return f"±{100 * x:.0f}"


def render_adis_plan(v: dict) -> str:
    """The ``adis-plan`` passage from :func:`compute_adis_plan`'s numbers."""
    hours = _list(v["need_h"], lambda h: f"{h:.2g}")
    text = (
        f"For the ADIS16405 of `shared/measurements/real/` ({v['record_h']:.3g} h at {v['rate_hz']:g} Hz, "
        f"`gyroarray fit` ARW + RRW per gyro: K = {_list(v['k'], lambda x: f'{x:.0f}')} deg/h/√h), "
        f"±10 % on K needs {hours} h; a {v['record_h']:.3g} h record is predicted to give "
        f"{_list(v['at_record'], _pct)} %, while the fit on the real record reports "
        f"{_list(v['fit_sigma'], _pct)} % (its model-error term: the sensor is not white + walk only). "
        f"With the bias-instability floor `gyroarray allan` finds (B ≈ {v['b1_deg_h']:.2g} deg/h on "
        f"gyro 1), ±10 % on K = {v['k'][0]:.0f} deg/h/√h needs {v['bi_need_h']:.2g} h and "
        f"{v['record_h']:.3g} h gives {_pct(v['bi_at_record'])} %. (Generated by `make docs-numbers`: "
        "`fit`, `plan --model`, `allan`, `plan --bi`; scripts/docs_numbers.py.)")
    return wrap(text)


#: Region name -> (pages, compute, render).
REGIONS = {
    "adis-plan": (("docs/export.md",), compute_adis_plan, render_adis_plan),
}


def pages() -> list[Path]:
    """Every docs page that can hold markers."""
    return sorted((ROOT / "docs").glob("*.md"))


def check_markers() -> list[str]:
    """Problems with the markers of every docs page (empty: well formed, every name known and
    found in the pages :data:`REGIONS` names for it)."""
    problems, found = [], {}
    for page in pages():
        rel = page.relative_to(ROOT).as_posix()
        try:
            for region, _, _ in regions(page.read_text(encoding="utf-8"), rel):
                found.setdefault(region, []).append(rel)
        except MarkerError as err:
            problems.append(str(err))
    for region, rels in found.items():
        if region not in REGIONS:
            problems.append(f"{', '.join(rels)}: unknown region 'numbers:{region}' (known: "
                            f"{', '.join(REGIONS)})")
    for region, (want, _, _) in REGIONS.items():
        for rel in want:
            if rel not in found.get(region, []):
                problems.append(f"{rel}: has no 'numbers:{region}' passage")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="run the commands and exit 1 if a passage differs (nothing written)")
    parser.add_argument("--markers", action="store_true", help="only check the markers (no commands run)")
    parser.add_argument("--only", action="append", choices=sorted(REGIONS), help="these regions only")
    args = parser.parse_args(argv)
    problems = check_markers()
    if problems:
        print("\n".join(f"docs_numbers: {p}" for p in problems), file=sys.stderr)
        return 2
    if args.markers:
        print(f"docs_numbers: markers well formed ({', '.join(REGIONS)})")
        return 0
    stale = []
    for region in args.only or REGIONS:
        rels, compute, render = REGIONS[region]
        new = render(compute())
        for rel in rels:
            page = ROOT / rel
            text = page.read_text(encoding="utf-8")
            if body(text, region, rel) == new:
                print(f"docs_numbers: {rel} numbers:{region} is up to date")
                continue
            stale.append(f"{rel} numbers:{region}")
            if not args.check:
                from gyroarray.core.outputs import write_text
                write_text(page, replace_regions(text, {region: new}, rel), force=True)
                print(f"docs_numbers: {rel} numbers:{region} rewritten")
    if args.check and stale:
        print("docs_numbers: stale (run 'make docs-numbers'): " + "; ".join(stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
