"""Hostile inputs for the CLI: builders of measurement, scenario and TOML files, and the contract check.

The contract (issue 17): every input ends in exit 0 with finite numbers, or
exit 2 with exactly one stderr line ``gyroarray: FILE...: what is wrong``;
never exit 1 (an internal error), never a traceback, never a hang (each
call runs under an alarm).

Used by ``tests/test_hostile.py`` (the corpus, one case per finding) and
``tests/test_fuzz.py`` (hypothesis strategies).
"""

from __future__ import annotations

import contextlib
import gzip
import io
import json
import math
import os
import signal
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SIDECAR_3 = 'sample_rate_hz = 50.0\n[layout]\nscheme = 1\nn_gyros = 3\nalpha_deg = 54.7356\n'


def axes_sidecar(n_gyros: int, rate_hz: float = 50.0) -> str:
    """A sidecar with explicit unit axes (any N >= 1)."""
    rows = []
    for k in range(n_gyros):
        a = 2 * math.pi * k / max(n_gyros, 1)
        rows.append(f"[{0.8 * math.cos(a)!r}, {0.8 * math.sin(a)!r}, 0.6]")
    return f"sample_rate_hz = {rate_hz!r}\n[layout]\naxes = [{', '.join(rows)}]\n"


def write_measurement(folder: Path, name: str, time_s, gyro, sidecar: str = SIDECAR_3,
                      gz: bool = False, header: str | None = None) -> Path:
    """``folder/name.csv[.gz]`` + ``name.toml``; values written with repr (exact)."""
    gyro = np.atleast_2d(np.asarray(gyro, dtype=float))
    head = header or ",".join(["time_s"] + [f"gyro{k + 1}" for k in range(gyro.shape[1])])
    body = "\n".join(",".join(map(repr, map(float, (t, *row)))) for t, row in zip(time_s, gyro))
    text = (head + "\n" + body + "\n").encode()
    path = folder / (name + (".csv.gz" if gz else ".csv"))
    path.write_bytes(gzip.compress(text, mtime=0) if gz else text)
    (folder / (name + ".toml")).write_text(sidecar)
    return path


def gzip_bomb(path: Path, head: bytes, filler: bytes, total: int) -> Path:
    """A gzip file of ``head`` then ``filler`` repeated to ``total`` bytes (compresses ~1000x)."""
    c = zlib.compressobj(9, zlib.DEFLATED, 31)
    out = [c.compress(head)]
    piece = filler * max(1, (1 << 20) // len(filler))
    for _ in range(max(1, total // len(piece))):
        out.append(c.compress(piece))
    out.append(c.flush())
    path.write_bytes(b"".join(out))
    return path


SCENARIO = '''name = "{name}"
sample_rate_hz = {rate}
seed = 1
{extra}
effects = [ {{ effect = "arw", n_deg_rt_h = 0.1 }}, {effects} ]

[layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356

[motion]
profile = "{profile}"
'''


def write_scenario(folder: Path, name: str, *, rate=20.0, extra: str = "", effects: str = "",
                   profile: str = "static10.toml", profile_text: str | None = None) -> Path:
    """A scenario file (4-gyro tetrahedral array) and, unless given, a 10 s static profile."""
    prof = folder / profile
    if profile_text is not None:
        prof.write_text(profile_text)
    elif not prof.exists():
        prof.write_text('[[segment]]\nkind = "static"\nduration_s = 10.0\n')
    path = folder / f"{name}.toml"
    path.write_text(SCENARIO.format(name=name, rate=rate, extra=extra, effects=effects,
                                    profile=profile))
    return path


def tiny_sweep(*, rate_hz: float = 50.0, duration_s: float = 5.0, estimators=None) -> str:
    """A sweep file of one short scenario (4-gyro tetrahedral array, ARW only, a shipped
    swing): what the sweep-bookkeeping and scheduler refusals need, and nothing slow."""
    names = ", ".join('"' + e + '"' for e in estimators or ())
    est = "" if estimators is None else f"estimators = [{names}]\n"
    return (f'name = "tiny"\nseed = 7\n{est}[base]\nsample_rate_hz = {rate_hz!r}\n'
            f'duration_s = {duration_s!r}\neffects = [{{ effect = "arw", n_deg_rt_h = 0.1 }}]\n'
            "[base.layout]\nscheme = 1\nn_gyros = 4\nalpha_deg = 54.7356\n"
            '[base.motion]\nprofile = "p003_sine_5dps_0p03hz"\n')


class Hang(Exception):
    """A call ran past its alarm."""


@contextlib.contextmanager
def alarm(seconds: float):
    """Raise :class:`Hang` in the block after ``seconds`` (main thread, POSIX)."""
    def ring(signum, frame):
        raise Hang(f"no answer within {seconds} s")
    old = signal.signal(signal.SIGALRM, ring)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


@dataclass
class Outcome:
    code: int
    out: str
    err: str
    cpu_s: float

    @property
    def json(self) -> dict:
        return json.loads(self.out)


def load_factor() -> float:
    """How many times slower than idle a call may run now: the 1-minute load average per CPU
    this process may use (at least 1). A hang never ends; a slow call on a loaded machine does,
    so the alarm that tells them apart scales with the load (a suite run beside another on 2
    cores sees a load of 12-15, 6-8 per core)."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    return max(1.0, os.getloadavg()[0] / max(cpus, 1))


def run_cli(argv, timeout: float = 120.0) -> Outcome:
    """``gyroarray.cli.main.main(argv)`` in this process, stdout/stderr captured, under an alarm
    of ``timeout`` seconds on an idle machine (times :func:`load_factor` on a loaded one)."""
    from gyroarray.cli.main import main
    out, err = io.StringIO(), io.StringIO()
    start = time.process_time()
    with alarm(timeout * load_factor()), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return Outcome(code, out.getvalue(), err.getvalue(), time.process_time() - start)


def finite_numbers(obj) -> bool:
    """No None/NaN/inf anywhere in a JSON result's numbers (lists of numbers included)."""
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, dict):
        return all(finite_numbers(v) for v in obj.values())
    if isinstance(obj, list):
        return all(finite_numbers(v) for v in obj)
    return True


def assert_contract(o: Outcome, name: str | None = None) -> None:
    """Exit 0, or exit 2 with one line naming ``name``; never 1, never a traceback."""
    assert "Traceback" not in o.err and "internal error" not in o.err, o.err
    assert o.code in (0, 2), (o.code, o.err)
    if o.code == 2:
        lines = o.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("gyroarray: "), o.err
        if name is not None:
            assert name in lines[0], (name, o.err)
