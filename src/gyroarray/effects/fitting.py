"""One fitted effect: the common result of every ``fit`` side.

Every fit function of the calibrator (the ``fit_*`` functions in each
deterministic effect's module, :mod:`gyroarray.effects.stochastic` and the
noise, array and time effects' modules) returns :class:`EffectFit` objects, so the
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

Regression fits of the deterministic effects of one gyro's residual
-------------------------------------------------------------------
The fit side of the deterministic effects of ``shared/spec/effects.md``
(the simulate side is :mod:`gyroarray.sim.effects`). Each fit takes the
residual of ONE gyro,

    e_t = y_t − h·ω_ref,t                          [rad/s]

(gyro output minus the nominal axis times the platform-frame reference
rate, what the caller computes), explains it by one effect's regressors
under the baseline noise model, and returns an
:class:`EffectFit` with the parameters in the
spec's units.

Baseline noise (the model a measurement is compared with first)
--------------------------------------------------------------
ARW white noise plus an RRW random-walk bias with an unknown starting value:

    e_t = X_t β + b_t + w_t
    b_t = b_{t−1} + v_t,   v_t ~ N(0, q),  b_0 unknown (diffuse)
    w_t ~ N(0, r)

with r = N²/dt [rad²/s²] (ARW N [rad/√s]) and q = K²·dt [rad²/s²] (RRW K
[rad/s/√s]), given by the caller. :func:`~gyroarray.analysis.gls.gls_rw` is the exact generalised
least-squares engine for that model; every fit is one or a few calls of it.

Significance z
--------------
Every fit's ``z`` is a standard-normal quantile of a tail probability, so
z ≈ N(0, 1) when the effect is absent and the noise model is right, and
large positive when the effect is present whatever its sign:

* k regression parameters β with covariance C: z = chi2_to_z(βᵀC⁻¹β, k).
  For one parameter this is the two-sided test of t = β/σ (|z| ≈ |t| for
  large |t|; t itself is in ``extra["t"]``). A signed z = β/σ would make a
  strongly *negative* effect (−6000 ppm) look "absent" (z = −150), against
  the "large positive = present" rule of EffectFit.
* nonlinear searches (latency beyond the linear range, the sinusoid) and the
  saturation plateau: see their docstrings.

Units: SI inside (rad, rad/s, s); spec units only at the edge, through the
named converters of :mod:`gyroarray.core.units`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import special, stats

from gyroarray.analysis.allan_gls import Gls, root_sigma
from gyroarray.analysis.gls import GLSFit
from gyroarray.analysis.transfer import shown_lines, transfer_check
from gyroarray.core import units
from gyroarray.core.errors import InputError

__all__ = ["EffectFit", "chi2_to_z", "z_from_log_p", "Z_EVIDENT", "z_two_sided", "num", "pm", "as_vector",
           "projected_rate", "not_identifiable", "fit_extra", "logp_to_z", "as_rate", "as_dt", "nk_extra",
           "ruled_out", "unchecked", "transfer_limit"]


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
    if log_p > -700:
        return float(-special.ndtri(min(math.exp(log_p), 1.0)))
    z = math.sqrt(-2.0 * log_p)
    for _ in range(8):                     # log Φ̄(z) ≈ −z²/2 − log(z√(2π))
        z = math.sqrt(-2.0 * (log_p + math.log(z * math.sqrt(2.0 * math.pi))))
    return z

#: z at and above which an evidence sentence states the signature as found.
Z_EVIDENT = 3.0


# -- helpers of the fits -------------------------------------------------------

def z_two_sided(t: float) -> float:
    """Two-sided significance of one parameter: z with P(N(0,1) > z) = P(|t| > |t_obs|)."""
    return chi2_to_z(t * t, 1)


def num(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}g}"


def pm(v: float, s: float) -> str:
    """``v ± s`` with s to two significant digits and v to the same decimal place."""
    if not (math.isfinite(s) and s > 0):
        return f"{v:.4g}"
    es = math.floor(math.log10(s))
    dec = 1 - es
    if dec <= 7 and (abs(v) >= 1e-3 or dec <= 4) and max(abs(v), s) < 1e7:
        dec = max(dec, 0)
        return f"{v:.{dec}f} ± {s:.{dec}f}"
    ev = math.floor(math.log10(max(abs(v), s)))
    scale = 10.0 ** ev
    dec = max(ev - es + 1, 0)
    return f"({v / scale:.{dec}f} ± {s / scale:.{dec}f})e{ev:d}"


def as_vector(x, n: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
    return a


def projected_rate(omega_ref_rad_s, h, n: int) -> tuple[np.ndarray, np.ndarray]:
    w = np.asarray(omega_ref_rad_s, dtype=float)
    if w.shape != (n, 3):
        raise ValueError(f"omega_ref_rad_s must have shape ({n}, 3), got {w.shape}")
    hv = np.asarray(h, dtype=float)
    if hv.shape != (3,) or abs(np.linalg.norm(hv) - 1.0) > 1e-6:
        raise ValueError(f"h must be a unit 3-vector, got {hv!r}")
    return w, w @ hv


def not_identifiable(effect: str, gyro: int, params: dict, why: str, err: Exception) -> EffectFit:
    return EffectFit(effect=effect, gyro=gyro, params=params, sigma={}, z=0.0,
                     evidence=f"gyro {gyro}: {why}, so {effect.replace('_', ' ')} cannot be seen "
                              "in these samples",
                     extra={"identifiable": False, "reason": str(err)})


def ruled_out(fit: EffectFit, why: str, **numbers) -> EffectFit:
    """``fit`` refused as a candidate: the record's own measurement ``why`` rules it out (issue 44).

    Parameters
    ----------
    fit : EffectFit
        The candidate's fit (its parameters are kept, for a report and for an entry the user adds).
    why : str
        One phrase naming the measurement that rules it out and its numbers.
    **numbers
        What the check measured (spec or SI units named in each key), kept in
        ``extra["limit"]``.

    Returns
    -------
    EffectFit
        z set to 0 when it was positive (not a candidate: the ladder does not add it and the discrepancy does
        not count it), the fitted z kept in ``extra["z_fitted"]``, ``extra["ruled_out"]`` = why,
        and the evidence ending "but the record rules it out: why".
    """
    return replace(fit, z=min(float(fit.z), 0.0) if np.isfinite(fit.z) else 0.0, evidence=f"{fit.evidence}; but the record rules it out: {why}",
                   extra=dict(fit.extra, ruled_out=why, z_fitted=float(fit.z), limit=numbers))


def unchecked(fit: EffectFit, why: str) -> EffectFit:
    """``fit`` with ``extra["limit_unchecked"]`` = why its limit could not be read on this record."""
    return replace(fit, extra=dict(fit.extra, limit_unchecked=why))


def transfer_limit(fit: EffectFit, y, u, dt_s: float, model, param: str, what: str, *, use=None,
                   free_delay: bool = False, lower: float = -math.inf) -> EffectFit:
    """``fit`` refused when its transfer function does not match the lines the gyro shows.

    Parameters
    ----------
    fit : EffectFit
        The candidate (a delay, a low-pass).
    y, u : array_like, shape (n,)
        The gyro's output less the model's deterministic part (residual + sensed rate) and the
        sensed reference rate [rad/s].
    dt_s : float
        Sample step [s].
    model : callable
        ``model(f_hz, p) -> complex ndarray``: the candidate's H(f) for parameter value p
        (``fit.params[param]``, in its spec unit) [-].
    param : str
        The parameter profiled (its σ from ``fit.sigma``).
    what : str
        The candidate as a phrase ("a 12.8 Hz first-order low-pass").
    use : array_like of bool, shape (n,), optional
        Samples that may be read.
    free_delay, lower
        As :func:`~gyroarray.analysis.transfer.transfer_check`.

    Returns
    -------
    EffectFit
        With ``extra["transfer_check"]`` (χ², dof, p and one sentence); refused
        (:func:`ruled_out`) when p < :data:`~gyroarray.analysis.transfer.P_RULED_OUT`; with
        ``extra["limit_unchecked"]`` when the motion has no line the gyro shows.
    """
    got = shown_lines(y, u, dt_s, use=use)
    if isinstance(got, str):
        return unchecked(fit, f"no line of the motion to check {what} against: {got}")
    _, lines = got
    chk = transfer_check(lines, model, float(fit.params[param]), float(fit.sigma.get(param, math.nan)),
                         free_delay=free_delay, lower=lower)
    said = chk.describe(what)
    numbers = {"chi2": chk.chi2, "dof": chk.dof, "p": chk.p, "harmonics": [ln.harmonic for ln in chk.lines],
               "param_at_least_chi2": chk.param, "sentence": said}
    out = replace(fit, extra=dict(fit.extra, transfer_check=numbers))
    if not chk.ruled_out:
        return out
    return ruled_out(out, said, **{k: v for k, v in numbers.items() if k != "sentence"})


def fit_extra(fit: GLSFit, **kw) -> dict:
    out = {"identifiable": True, "chi2": fit.chi2, "dof": fit.dof, "loglik": fit.loglik,
           "n_used": fit.n}
    out.update(kw)
    return out


def logp_to_z(log_p: float) -> float:
    """Standard-normal quantile z with P(N(0,1) > z) = exp(log_p), finite far out.

    χ²(2) has the tail exp(−x/2), so this is chi2_to_z(−2·log_p, 2).
    """
    if log_p > -700.0:
        return float(-special.ndtri(min(math.exp(log_p), 1.0 - 1e-16)))
    return chi2_to_z(-2.0 * log_p, 2)


def as_rate(e, name: str, ndim: int) -> np.ndarray:
    x = np.asarray(e, dtype=float)
    if ndim == 2 and x.ndim == 1:
        x = x[:, None]
    if x.ndim != ndim:
        raise InputError(f"{name} must be {'(n,)' if ndim == 1 else '(n, N)'}, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InputError(f"{name} contains a non-finite value")
    return x


def as_dt(dt_s) -> float:
    try:
        dt = float(dt_s)
    except (TypeError, ValueError):
        raise InputError(f"dt_s must be a number, got {dt_s!r}") from None
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"dt_s must be finite and positive, got {dt_s!r}")
    return dt


def nk_extra(f: Gls) -> dict:
    """N and K of an alternative fit (columns n, k first), spec units."""
    n_, sn = root_sigma(float(f.a[0]), float(math.sqrt(f.cov[0, 0])))
    k_, sk = root_sigma(float(f.a[1]), float(math.sqrt(f.cov[1, 1])))
    return {"n_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(n_)),
            "n_deg_rt_h_sigma": float(units.arw_rad_rt_s_to_deg_rt_h(sn)),
            "k_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(k_)),
            "k_deg_h_rt_h_sigma": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(sk))}
