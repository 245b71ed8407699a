"""A wall-clock bound for a test that waits on another process's event, scaled to this machine now.

A test that waits for a child process (a sweep's workers to appear, its first result file) polls
for the event and returns as soon as it happens; the bound only catches a child that hangs. A
fixed bound fails on a loaded machine (a fresh interpreter that imports gyroarray takes ~2 s on
an idle core and 20-40 s at a load of 15 on 2 cores), so the bound is the larger of a floor and a
multiple of what one such start-up takes here, measured just before the wait.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time

#: A start-up is measured on a fresh interpreter importing what a sweep's parent and workers import.
IMPORTS = "import gyroarray.sweep.runner, gyroarray.chain.fuse"


def spawn_s(imports: str = IMPORTS) -> float:
    """Wall time [s] of one fresh Python that imports ``imports`` (the machine's speed now)."""
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-c", imports], check=True, timeout=900)
    return time.monotonic() - t0


def bound_s(floor_s: float, starts: float = 20.0) -> float:
    """A wait's bound [s]: ``floor_s``, or ``starts`` measured start-ups where that is longer.

    The waits it bounds cost a few start-ups each (the parent's imports, then its workers', on the
    same busy cores), so 20 of them is a generous margin at any load, and on an idle machine the
    floor stands (the measurement adds one start-up to the test, ~2 s)."""
    return max(float(floor_s), starts * spawn_s())


def as_from_a_terminal() -> None:
    """``preexec_fn`` of a child that a test interrupts: SIGINT, SIGHUP and SIGTERM at their
    defaults, as a command typed at a terminal has them. A suite started in the background
    (``cmd &`` in a script: SIGINT ignored) or under ``nohup`` (SIGHUP ignored) would hand the
    ignored signals down, and the child rightly keeps what it was given."""
    for sig in (signal.SIGINT, signal.SIGHUP, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)
