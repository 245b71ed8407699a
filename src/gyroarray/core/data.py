"""The shipped data folder: scenarios, profiles, sweeps, thresholds, paper values and tables.

Every reader of shipped data goes through :func:`data_path`, so the folder can move
(``src/gyroarray/data/`` in a checkout, ``gyroarray/data/`` in an install) without its readers.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["DATA_DIR", "data_path"]

#: The data folder of the installed package.
DATA_DIR = Path(__file__).resolve().parent.parent / "data"


def data_path(*parts: str) -> Path:
    """Path of a shipped data file or folder.

    Parameters
    ----------
    *parts : str
        Path parts under the data folder, e.g. ``("scenarios", "profiles")`` or
        ``("paper003_tables.toml",)``; none for the folder itself.

    Returns
    -------
    pathlib.Path
        The path (it need not exist: callers say what is missing).
    """
    return DATA_DIR.joinpath(*parts)
