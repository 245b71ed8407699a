"""Gyro array layouts: the sensitive axes of N gyros in the platform frame.

Conventions (``shared/spec/measurement-format.md``, paper 003 §2.2):

* Scheme 1: gyro k (k = 1..N) has azimuth ``2π(k-1)/N`` from +x and makes
  angle α with +z: ``axis = [sin α cos β, sin α sin β, cos α]``.
* Scheme 2: gyro 1 is +z; gyros 2..N have azimuth ``2π(k-2)/(N-1)`` and
  angle α with +z.
* The orthogonal triad: x, y, z.

The measurement matrix ``H`` (N×3) has one unit axis per row, so a gyro
array reads ``z = H ω`` for a body rate ``ω``.

Positions (optional, ``positions_m`` of a measurement's ``[layout]``): where
each gyro sits on the platform, metres from the platform origin (the
intersection of the table's axes), platform frame. They matter only for what
depends on the specific force at a gyro (``g_sensitivity``: centripetal and
tangential terms). Absent means zero, as the spec says: every gyro at the
origin. A layout without positions and one with all-zero positions describe
the same array; only the second writes ``positions_m`` to a sidecar.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field

import numpy as np

from gyroarray.core.errors import InputError

#: Largest accepted deviation of an axis norm from 1 (files print axes with
#: 4–6 decimals: ``[0.8165, 0, 0.5774]`` has norm 1.00003).
UNIT_NORM_TOL = 1e-3

#: Largest number of gyros of a conical layout (a sanity bound on user input).
MAX_GYROS = 1024

#: Largest accepted distance of a gyro from the platform origin [m]: a rate
#: table platform is well under a metre; 20 (mm written as m) is refused.
MAX_POSITION_M = 10.0


@dataclass(frozen=True, eq=False)
class Layout:
    """The sensitive axes of a gyro array.

    Parameters
    ----------
    axes : ndarray, shape (N, 3)
        Unit sensitive axes in the platform frame [-], one row per gyro, in
        gyro order (gyro k is row k-1). Stored read-only, normalised.
    scheme : int or None
        1 or 2 for a conical layout, None for explicit axes or the triad.
    alpha_rad : float or None
        Cone angle between each cone gyro's axis and +z [rad], for conical
        layouts.
    name : str
        A short human-readable label.
    positions_m : ndarray, shape (N, 3), or None
        Where each gyro sits, platform frame, from the platform origin [m];
        None: not given (zero, every gyro at the origin). Stored read-only;
        checked with :func:`check_positions`.
    """

    axes: np.ndarray
    scheme: int | None = None
    alpha_rad: float | None = None
    name: str = field(default="explicit axes")
    positions_m: np.ndarray | None = None

    def __post_init__(self):
        a = np.array(self.axes, dtype=float, copy=True)
        a.setflags(write=False)
        object.__setattr__(self, "axes", a)
        if self.positions_m is not None:
            object.__setattr__(self, "positions_m", check_positions(self.positions_m, a.shape[0]))

    def with_positions(self, positions_m, *, source: str | None = None) -> "Layout":
        """The same axes with gyro positions (None removes them).

        Parameters
        ----------
        positions_m : array_like, shape (N, 3), or None
            Position of each gyro, platform frame [m].
        source : str, optional
            File the positions came from, for error messages.
        """
        pos = None if positions_m is None else check_positions(positions_m, self.n_gyros,
                                                                 source=source)
        return Layout(axes=self.axes, scheme=self.scheme, alpha_rad=self.alpha_rad,
                      name=self.name, positions_m=pos)

    @property
    def positions_or_zero(self) -> np.ndarray:
        """Positions [m], shape (N, 3); zeros when not given (the spec's default)."""
        return np.zeros((self.n_gyros, 3)) if self.positions_m is None else self.positions_m

    # -- constructors -------------------------------------------------------
    @classmethod
    def conical(cls, scheme: int, n: int, alpha_rad: float) -> "Layout":
        """Scheme 1 or 2 conical layout.

        Parameters
        ----------
        scheme : {1, 2}
            1: all gyros on the cone; 2: gyro 1 on +z, the others on the cone.
        n : int
            Number of gyros N >= 3 (Scheme 2 needs N >= 3 as well: one on
            +z plus at least two on the cone).
        alpha_rad : float
            Cone angle from +z [rad].
        """
        if scheme not in (1, 2):
            raise InputError(f"scheme must be 1 or 2, got {scheme!r}")
        if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or not 3 <= n <= MAX_GYROS:
            raise InputError(f"number of gyros must be an integer in [3, {MAX_GYROS}], got {n!r}")
        alpha = float(alpha_rad)
        if not np.isfinite(alpha):
            raise InputError(f"cone angle must be finite, got {alpha_rad!r}")
        axes = conical_axes(scheme, int(n), np.array([alpha]))[0]
        name = f"scheme {scheme}, N={n}, alpha={np.degrees(alpha):.2f} deg"
        return cls(axes=axes, scheme=scheme, alpha_rad=alpha, name=name)

    @classmethod
    def triad(cls) -> "Layout":
        """The orthogonal triad (x, y, z)."""
        return cls(axes=np.eye(3), name="orthogonal triad")

    @classmethod
    def from_axes(cls, axes, *, source: str | None = None,
                  tol: float = UNIT_NORM_TOL) -> "Layout":
        """Explicit unit axes, one row per gyro, checked and normalised.

        Parameters
        ----------
        axes : array_like, shape (N, 3)
            Sensitive axes in the platform frame [-].
        source : str, optional
            File (or key) the axes came from, for error messages.
        tol : float
            Largest accepted | |axis| - 1 | [-].
        """
        try:
            raw = np.array(axes, dtype=object)
            numeric = all(isinstance(v, (numbers.Real, np.floating, np.integer))
                          and not isinstance(v, (bool, np.bool_)) for v in raw.ravel())
            a = np.array(axes, dtype=float) if numeric else None
        except (TypeError, ValueError, OverflowError):
            a = None
        if a is None:
            raise InputError("axes must be a list of [x, y, z] rows of numbers",
                             file=source, column="layout.axes")
        if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < 1:
            raise InputError(f"axes must be a list of [x, y, z] rows, got shape {a.shape}",
                             file=source, column="layout.axes")
        if not np.all(np.isfinite(a)):
            raise InputError("axes contain a non-finite number", file=source,
                             column="layout.axes")
        norms = np.linalg.norm(a, axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > tol)
        if bad.size:
            k = int(bad[0])
            raise InputError(
                f"axis of gyro {k + 1} {a[k].tolist()} is not a unit vector "
                f"(norm {norms[k]:.6g}, allowed 1 ± {tol:g})",
                file=source, column="layout.axes")
        return cls(axes=a / norms[:, None], name=f"{a.shape[0]} explicit axes")

    # -- properties ---------------------------------------------------------
    @property
    def n_gyros(self) -> int:
        """Number of gyros N."""
        return int(self.axes.shape[0])

    @property
    def H(self) -> np.ndarray:
        """Measurement matrix (N×3) [-]: gyro readings ``z = H ω``."""
        return self.axes

    def __repr__(self) -> str:
        return f"Layout({self.name})"


def check_positions(positions_m, n_gyros: int, *, source: str | None = None) -> np.ndarray:
    """Gyro positions checked: N rows of 3 finite numbers, each within ``MAX_POSITION_M``.

    Parameters
    ----------
    positions_m : array_like, shape (N, 3)
        Position of each gyro in the platform frame [m].
    n_gyros : int
        Number of gyros N of the layout.
    source : str, optional
        File the positions came from, for error messages.

    Returns
    -------
    ndarray, shape (N, 3)
        A read-only float copy [m].

    Raises
    ------
    InputError
        With ``column = "layout.positions_m"``.
    """
    key = "layout.positions_m"
    try:
        raw = np.array(positions_m, dtype=object)
        numeric = raw.ndim == 2 and all(
            isinstance(v, (numbers.Real, np.floating, np.integer))
            and not isinstance(v, (bool, np.bool_)) for v in raw.ravel())
        p = np.array(positions_m, dtype=float) if numeric else None
    except (TypeError, ValueError, OverflowError):
        p = None
    if p is None or p.ndim != 2 or p.shape[1] != 3:
        raise InputError("positions_m must be a list of [x, y, z] rows of numbers (metres), "
                         "one per gyro", file=source, column=key)
    if p.shape[0] != n_gyros:
        raise InputError(f"positions_m has {p.shape[0]} rows but the layout has {n_gyros} "
                         "gyros (one [x, y, z] per gyro)", file=source, column=key)
    if not np.all(np.isfinite(p)):
        k = int(np.flatnonzero(~np.isfinite(p).all(axis=1))[0])
        raise InputError(f"positions_m of gyro {k + 1} is not finite: {p[k].tolist()}",
                         file=source, column=key)
    dist = np.linalg.norm(p, axis=1)
    if np.any(dist > MAX_POSITION_M):
        k = int(np.argmax(dist))
        raise InputError(f"positions_m of gyro {k + 1} is {dist[k]:.6g} m from the platform "
                         f"origin (more than {MAX_POSITION_M:g} m: positions are in metres, "
                         "not millimetres)", file=source, column=key)
    p = p.copy()
    p.setflags(write=False)
    return p


def conical_axes(scheme: int, n: int, alphas_rad: np.ndarray) -> np.ndarray:
    """Axes of conical layouts for many cone angles at once.

    Parameters
    ----------
    scheme : {1, 2}
    n : int
        Number of gyros N.
    alphas_rad : ndarray, shape (G,)
        Cone angles from +z [rad].

    Returns
    -------
    ndarray, shape (G, N, 3)
        Unit axes; gyro k at azimuth 2π(k-1)/N (Scheme 1), or gyro 1 on +z and
        gyro k at 2π(k-2)/(N-1) (Scheme 2).
    """
    n_cone = n if scheme == 1 else n - 1
    beta = 2.0 * np.pi * np.arange(n_cone) / n_cone
    s = np.sin(alphas_rad)[:, None]
    c = np.cos(alphas_rad)[:, None]
    # axis = [sin α cos β, sin α sin β, cos α]
    cone = np.stack([s * np.cos(beta), s * np.sin(beta), np.broadcast_to(c, s.shape[:1] + beta.shape)],
                    axis=-1)
    if scheme == 1:
        return cone
    up = np.broadcast_to([0.0, 0.0, 1.0], (cone.shape[0], 1, 3))
    return np.concatenate([up, cone], axis=1)
