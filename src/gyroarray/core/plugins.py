"""Entry-point groups of installed plugins, and what they hold, read without importing anything.

``gyroarray --help`` lists them: reading the metadata loads no plugin (a
broken one cannot break the help) and none of the registries.
"""

from __future__ import annotations

from importlib import metadata

__all__ = ["EFFECTS_GROUP", "ESTIMATORS_GROUP", "installed"]

#: Entry-point group of installed packages that add effects.
EFFECTS_GROUP = "gyroarray.effects"
#: Entry-point group of third-party estimators.
ESTIMATORS_GROUP = "gyroarray.estimators"


def installed(group: str) -> list[tuple[str, str]]:
    """(name, value) of the entry points of ``group`` in the installed packages, sorted
    (none when the metadata cannot be read)."""
    try:
        eps = metadata.entry_points(group=group)
    except Exception:  # broken distribution metadata must not break the caller
        return []
    return sorted((ep.name, ep.value) for ep in eps)
