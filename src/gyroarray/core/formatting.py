"""Numbers as people read them (one formatter for reports, messages and effect labels)."""

from __future__ import annotations

import math

__all__ = ["sig"]


def sig(v: float, digits: int = 3) -> str:
    """``digits`` significant figures, without an exponent between 1e-3 and 1e5; ``–`` if not finite."""
    v = float(v)
    if not math.isfinite(v):
        return "–"
    a = abs(v)
    if a == 0.0:
        return "0"
    if not 1e-3 <= a < 1e5:
        return f"{v:.{digits - 1}e}"
    return f"{v:.{max(digits - 1 - math.floor(math.log10(a)), 0)}f}"
