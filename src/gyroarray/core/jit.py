"""numba, loaded with a cache folder it can write to: every compiled kernel imports it from here.

Importing ``gyroarray`` itself stays light (the command line starts without
numba); the check of where numba may cache runs once, when the first kernel
module is imported.
"""

from __future__ import annotations

import os
from importlib.util import find_spec

__all__ = ["numba", "njit", "prange"]


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
    if os.environ.get("NUMBA_CACHE_DIR"):
        return

    def writable(folder: str) -> bool:
        probe = folder
        while not os.path.exists(probe) and os.path.dirname(probe) != probe:
            probe = os.path.dirname(probe)
        return os.path.isdir(probe) and os.access(probe, os.W_OK | os.X_OK)

    dirs = []
    for name in ("gyroarray.analysis", "gyroarray.estimators"):
        try:
            spec = find_spec(name)
        except (ImportError, ValueError):
            spec = None
        dirs += [os.path.join(p, "__pycache__") for p in (spec.submodule_search_locations or [])] if spec else []
    if dirs and all(writable(d) for d in dirs):
        return
    xdg = os.environ.get("XDG_CACHE_HOME")
    user = xdg if xdg else os.path.join(os.path.expanduser("~"), ".cache")
    if user and not user.startswith("~") and writable(os.path.join(user, "numba")):
        return
    import tempfile                            # only here: it loads shutil and random (~6 ms)
    folder = os.path.join(tempfile.gettempdir(), f"gyroarray-numba-{os.getuid() if hasattr(os, 'getuid') else 0}")
    try:
        os.makedirs(folder, mode=0o700, exist_ok=True)
    except OSError:
        return
    os.environ["NUMBA_CACHE_DIR"] = folder


_numba_cache_fallback()

import numba  # noqa: E402  (after the cache folder is chosen)
from numba import njit, prange  # noqa: E402
