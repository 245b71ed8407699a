"""One fitted effect: the common result of every ``fit`` side.

Every fit function of the calibrator (:mod:`gyroarray.effects.fits.regress` for
the deterministic effects, :mod:`gyroarray.effects.fits.stochastic_fit` for the
noise, array and time effects) returns :class:`EffectFit` objects, so the
diagnosis can rank them and the model writer can turn them into TOML
entries without knowing which fit made them.

Conventions
-----------
* ``effect`` is the spec name (``shared/spec/effects.md``), ``gyro`` is
  1-based or ``None`` for an array-wide effect.
* ``params`` and ``sigma`` are in the spec's units (the names of the spec:
  ``ppm``, ``k2_per_deg_s``, ``tilt_deg``, ...), converted at this edge
  through :mod:`gyroarray.core.units`; a parameter without an uncertainty has no
  key in ``sigma``.
* ``z`` is the significance of the effect: a statistic that is
  approximately standard normal (|z| ≲ 2) when the effect is absent and the
  noise model is right: the χ² of the fitted parameters, βᵀC⁻¹β with p
  degrees of freedom, turned into the normal quantile of the same tail
  probability (:func:`chi2_to_z`), so that z ≈ N(0, 1) under "absent" and
  large positive when present, whatever the sign of β (the signed β/σ of a
  one-parameter fit is in ``extra["t"]``).
* ``evidence`` is one sentence a person understands, naming the gyro and the
  signature, e.g. "gyro 3 residual rises 0.41 % of the rate about its axis".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import special, stats

__all__ = ["EffectFit", "chi2_to_z", "z_from_log_p"]


@dataclass(frozen=True)
class EffectFit:
    """A fitted effect with its uncertainty and significance.

    Attributes
    ----------
    effect : str
        Spec name.
    gyro : int or None
        1-based gyro, None for array-wide effects.
    params : dict
        Spec-unit parameters, ready for a model TOML entry.
    sigma : dict
        1σ of the parameters that have one [same units].
    z : float
        Significance (≈ N(0, 1) under "absent"; large positive = present).
    evidence : str
        One sentence.
    extra : dict
        Anything else a report may show (not written to models).
    """

    effect: str
    gyro: int | None
    params: dict
    sigma: dict = field(default_factory=dict)
    z: float = 0.0
    evidence: str = ""
    extra: dict = field(default_factory=dict)

    def entry(self) -> dict:
        """The model TOML entry (``{"effect": .., "gyro": .., **params}``)."""
        out: dict[str, Any] = {"effect": self.effect}
        if self.gyro is not None:
            out["gyro"] = int(self.gyro)
        out.update(self.params)
        return out


def chi2_to_z(chi2: float, dof: int) -> float:
    """The standard-normal quantile with the tail probability of χ²(dof) ≥ ``chi2``.

    Large χ² maps to large positive z; beyond a tail probability of e^-700
    asymptotic tails keep z finite (χ²(1) = 1e4 gives z ≈ 100).
    """
    chi2 = float(chi2)
    if not np.isfinite(chi2):
        return float("inf") if chi2 > 0 else 0.0
    if chi2 <= 0:
        return float(-np.inf) if dof > 0 else 0.0
    log_tail = stats.chi2.logsf(chi2, dof)
    if not (np.isfinite(log_tail) and log_tail > -700):
        # far tail: leading term of the upper incomplete gamma function,
        # Γ(s, x) ≈ x^(s-1) e^(-x), with s = dof/2, x = χ²/2
        s_, x = 0.5 * dof, 0.5 * chi2
        log_tail = (s_ - 1.0) * np.log(x) - x - special.gammaln(s_)
    if log_tail > -700:
        return float(-special.ndtri(np.exp(log_tail)))
    # invert log Q(z) ≈ -z²/2 - log(z √(2π)) (normal tail) by fixed point
    z = np.sqrt(-2.0 * log_tail)
    for _ in range(8):
        z = np.sqrt(-2.0 * (log_tail + np.log(z * np.sqrt(2.0 * np.pi))))
    return float(z)


def z_from_log_p(log_p: float) -> float:
    """z with Φ̄(z) = p for an upper-tail probability given by its log: finite however small
    p is (no cap at p = 1e-300, z = 37.05, where a linear p underflows)."""
    import math
    if log_p > -700:
        return float(-special.ndtri(min(math.exp(log_p), 1.0)))
    z = math.sqrt(-2.0 * log_p)
    for _ in range(8):                     # log Φ̄(z) ≈ −z²/2 − log(z√(2π))
        z = math.sqrt(-2.0 * (log_p + math.log(z * math.sqrt(2.0 * math.pi))))
    return z

