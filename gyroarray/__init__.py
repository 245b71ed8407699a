"""gyroarray: a simulation benchmark for redundant (skewed, conical) MEMS gyro arrays.

Sub-packages (each a top-level folder of the repository):

* ``gyroarray`` (folder ``gyroarray/``): units, layouts and GDOP design
  analysis, measurement files, the CLI.
* ``gyroarray.analysis`` (``analysis/``): statistics shared by simulation
  fitting and reports (Allan/Hadamard deviation, confidence intervals, noise
  fits).
* ``gyroarray.sim``, ``gyroarray.estimators``, ``gyroarray.scenarios``,
  ``gyroarray.reports``: rate table and noise injector, fusion estimators,
  scenario files, reports.

Units: SI inside (rad, rad/s, s); datasheet units (deg/√h, deg/h, deg/h/√h)
only at the edges, through the named converters of :mod:`gyroarray.units`.
"""

__version__ = "0.1.0"


def _numba_cache_fallback() -> None:
    """Point numba's cache at a temporary folder when it has nowhere else to write.

    The kernels are compiled with ``cache=True``; numba caches beside the
    source (``__pycache__``) or, when that is read-only (an installed
    package), under the user's cache folder (``~/.cache``). With neither
    writable (a read-only install and HOME not writable: a service account,
    a locked-down CI container) numba refuses to compile ("no locator
    available"). Then ``NUMBA_CACHE_DIR`` is set to a private folder in the
    system's temporary directory, before numba is first imported. A
    ``NUMBA_CACHE_DIR`` the user set is left alone.
    """
    import os
    import tempfile
    from importlib.util import find_spec
    from pathlib import Path

    if os.environ.get("NUMBA_CACHE_DIR"):
        return

    def writable(folder: Path) -> bool:
        probe = folder
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        return probe.is_dir() and os.access(probe, os.W_OK | os.X_OK)

    dirs = []
    for name in ("gyroarray.analysis", "gyroarray.estimators"):
        try:
            spec = find_spec(name)
        except (ImportError, ValueError):
            spec = None
        dirs += [Path(p) / "__pycache__" for p in (spec.submodule_search_locations or [])] if spec else []
    if dirs and all(writable(d) for d in dirs):
        return
    xdg = os.environ.get("XDG_CACHE_HOME")
    try:
        user = Path(xdg) if xdg else Path.home() / ".cache"
    except (RuntimeError, KeyError):
        user = None
    if user is not None and writable(user / "numba"):
        return
    folder = Path(tempfile.gettempdir()) / f"gyroarray-numba-{os.getuid() if hasattr(os, 'getuid') else 0}"
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
    except OSError:
        return
    os.environ["NUMBA_CACHE_DIR"] = str(folder)


_numba_cache_fallback()
