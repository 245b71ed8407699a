"""Deciding under what the user does not know: mounting sense, failures, ρ, fixed weights.

The pieces of the design search behind ``design --recommend`` that treat the
gyros' correlation ρ as an uncertain condition (a range), a failed gyro as
something to survive, and the sense in which each gyro is mounted as a design
variable:

* :func:`mounting_patterns` — the sign patterns (which gyros are mounted
  reversed) that differ under correlated noise, one of each class of patterns
  that a rotation of the array or a global sign make equal;
* :func:`mounted_axes` and :func:`mounting_words` — the axes as mounted and
  the pattern said in words ("gyro 1 on −z");
* :func:`fixed_weights` — the per-sample weights an estimator is built with,
  once, for a design ρ (GLS: W = (HᵀC_d⁻¹H)⁻¹HᵀC_d⁻¹);
* :func:`kept_sets` — every set of gyros left after k failures;
* :func:`worst_over_interval` — the largest value of a function of ρ over an
  interval, found continuously (both ends and a bounded Brent search inside).

With fixed weights every error variance is W C(ρ) Wᵀ, linear in ρ, so its
largest value over a range lies at one end; :func:`worst_over_interval` still
searches the inside (an oracle estimator, whose weights follow ρ, has its worst
case inside the range).
"""

from __future__ import annotations

import itertools
import math
from typing import Callable

import numpy as np
from scipy.optimize import minimize_scalar

from gyroarray.core.layout import conical_axes

__all__ = ["mounting_patterns", "mounted_axes", "mounting_words", "fixed_weights", "kept_sets",
           "worst_over_interval", "mirror_pattern", "ALL_PATTERNS_UP_TO"]

#: Up to this N every sign pattern is tried (one per class); above, the named structured ones.
ALL_PATTERNS_UP_TO = 6


def _cone_count(scheme: int, n: int) -> int:
    return n if scheme == 1 else n - 1


def _canonical(signs: tuple[int, ...]) -> tuple[int, ...]:
    """The smallest of a cone sign pattern's images under rotation, reflection and global sign
    (patterns that give the same array up to a rotation of the body frame)."""
    m = len(signs)
    images = []
    for s in (signs, tuple(-v for v in signs)):
        for seq in (s, s[::-1]):
            for k in range(m):
                images.append(seq[k:] + seq[:k])
    return min(images, key=lambda t: tuple(-v for v in t))          # most '+' first


def mounting_patterns(scheme: int, n: int) -> list[np.ndarray]:
    """The mounting senses the search tries for one scheme and N.

    Parameters
    ----------
    scheme : {1, 2}
    n : int
        Number of gyros N.

    Returns
    -------
    list of ndarray (N,)
        ±1 per gyro (−1: mounted reversed, its axis negated); all + first.
        For N <= :data:`ALL_PATTERNS_UP_TO` every pattern of the cone gyros up
        to a rotation about z, a mirror and a global sign; above, the named
        structured ones (all +, one reversed, alternating senses). Scheme 2's
        axial gyro stays + : reversing it is the cone at 180° − α up to a global
        sign and a rotation, which the cone-angle search in (0°, 180°) covers.
    """
    m = _cone_count(scheme, n)
    if n <= ALL_PATTERNS_UP_TO:
        seen: dict[tuple, None] = {}
        for s in itertools.product((1, -1), repeat=m):
            seen.setdefault(_canonical(s), None)
        cones = sorted(seen, key=lambda t: (sum(v < 0 for v in t), tuple(-v for v in t)))
    else:
        one = (1,) * (m - 1) + (-1,)
        alt = tuple(1 if k % 2 == 0 else -1 for k in range(m))
        cones = [(1,) * m, one, alt]
    head = [] if scheme == 1 else [1]
    return [np.array(head + list(c), dtype=float) for c in cones]


def mounted_axes(scheme: int, n: int, alphas_rad: np.ndarray, signs: np.ndarray) -> np.ndarray:
    """Axes of conical layouts with a mounting pattern, (G, N, 3) [-] (row k: gyro k + 1)."""
    return conical_axes(scheme, n, np.asarray(alphas_rad, dtype=float)) * np.asarray(signs)[None, :, None]


def mirror_pattern(scheme: int, alpha_deg: float, signs: np.ndarray) -> tuple[float, np.ndarray]:
    """The mounting mirror of a design: the same cone with the other sense where it matters.

    A pattern with reversed gyros: the same cone angle, every gyro +. Scheme 2
    with every gyro +: the cone at 180° − α (its axial gyro reversed relative to
    the cone). Scheme 1 with every gyro +: gyro 1 reversed.
    """
    s = np.asarray(signs, dtype=float)
    if np.any(s < 0):
        return alpha_deg, np.ones_like(s)
    if scheme == 2:
        return 180.0 - alpha_deg, s.copy()
    out = s.copy()
    out[0] = -1.0
    return alpha_deg, out


def mounting_words(scheme: int, n: int, signs: np.ndarray, alpha_deg: float) -> str:
    """The mounting sense in words, e.g. "gyro 1 on +z; gyros 2–8 on the cone at 119.21° from +z".

    Parameters
    ----------
    scheme : {1, 2}
    n : int
    signs : ndarray (N,)
        ±1 per gyro.
    alpha_deg : float
        Cone angle from +z [deg].
    """
    s = np.asarray(signs)
    rev = [k + 1 for k in range(n) if s[k] < 0]
    first = 1 if scheme == 1 else 2
    parts = []
    if scheme == 2:
        parts.append(f"gyro 1 on {'+' if s[0] > 0 else '−'}z")
    parts.append(f"gyros {first}–{n} on the cone at {alpha_deg:.2f}° from +z")
    cone_rev = [k for k in rev if k >= first]
    if cone_rev:
        parts.append(("gyro " if len(cone_rev) == 1 else "gyros ")
                     + ", ".join(map(str, cone_rev)) + " mounted reversed (axis negated)")
    else:
        parts.append("every cone gyro pointing out along its cone line")
    text = "; ".join(parts)
    if scheme == 2 and alpha_deg > 90.0 and s[0] > 0 and not cone_rev:
        text += (f" — the same lines as the {180.0 - alpha_deg:.2f}° cone with gyro 1 on −z "
                 "(identical at ρ = 0; under correlated noise the common mode moves into the parity space)")
    return text


def fixed_weights(kind: str, H: np.ndarray, C_design: np.ndarray) -> np.ndarray:
    """Per-sample weights M (G, 3, N) built once, for the design covariance.

    Parameters
    ----------
    kind : {"gls", "ols", "naive"}
        ``gls``: M = (HᵀC_d⁻¹H)⁻¹HᵀC_d⁻¹; ``ols``: (HᵀH)⁻¹Hᵀ; ``naive``:
        each axis the projection-weighted mean hᵢ/Σh².
    H : ndarray (G, N, 3)
        Mounted axes [-].
    C_design : ndarray (N, N)
        The covariance (or correlation) the weights are built for.
    """
    if kind == "gls":
        rih = np.linalg.solve(C_design[None], H)
        return np.linalg.solve(np.einsum("gni,gnj->gij", H, rih), np.swapaxes(rih, 1, 2))
    if kind == "ols":
        return np.linalg.solve(np.einsum("gni,gnj->gij", H, H), np.swapaxes(H, 1, 2))
    if kind == "naive":
        return np.swapaxes(H, 1, 2) / np.sum(H * H, axis=1)[:, :, None]
    raise ValueError(kind)


def kept_sets(n: int, failures: int) -> list[tuple[int, ...]]:
    """The gyros left (0-based) intact and after every choice of ``failures`` failed gyros."""
    out = [tuple(range(n))]
    if failures > 0:
        out += list(itertools.combinations(range(n), n - failures))
    return out


def worst_over_interval(f: Callable[[float], float], lo: float, hi: float, *,
                        xatol: float = 1e-9) -> tuple[float, float]:
    """The largest value of f on [lo, hi] and where it is: both ends and a bounded Brent search.

    Returns
    -------
    (value, x)
        ``value`` = max f; inf where f is infinite somewhere tried.
    """
    cands = [(f(lo), lo)]
    if hi > lo:
        cands.append((f(hi), hi))
        res = minimize_scalar(lambda x: -f(x), bounds=(lo, hi), method="bounded",
                              options={"xatol": xatol})
        cands.append((-float(res.fun), float(res.x)))
    best = max(cands, key=lambda c: (c[0] if math.isfinite(c[0]) else math.inf))
    return float(best[0]), float(best[1])
