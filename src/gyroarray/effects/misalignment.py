"""``misalignment``: the true sensitive axis differs from the nominal one."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.analysis.gls import MAX_COND, NotIdentifiableError, RWWhitener
from gyroarray.analysis.memo import by_content
from gyroarray.core.physics import tilt_basis
from gyroarray.core.units import rad_to_deg
from gyroarray.effects.fitting import (as_vector, chi2_to_z, EffectFit, fit_extra, not_identifiable, pm,
                                       projected_rate, Z_EVIDENT)
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.core.physics import tilted_axes
from gyroarray.effects.protocol import Param, RegressionEffect, Stage
from gyroarray.effects.terms import AxisTerm, spread
from gyroarray.core.units import deg_to_rad


def _unit_axis(x):
    a = np.asarray(x, dtype=float)
    return a / np.linalg.norm(a)


class Misalignment(RegressionEffect):
    """Either ``axis`` (the true unit axis of one named gyro, platform frame, unit
    within 1e-3 and normalised) or ``tilt_deg`` θ (every gyro, or one): the
    nominal axis tilted by θ toward ``tilt_azimuth_deg`` ψ (default 0) around
    it, ψ = 0 toward +z (the cone angle shrinks), ψ = 90° horizontal toward
    increasing azimuth (:func:`gyroarray.core.physics.tilted_axes`). Not both.

    Fit: the residual against the rate about the two axes ⟂ h, with the
    (1 − cos θ)·u term; it returns tilt and azimuth (a model reads them back).
    """

    name = "misalignment"
    own_column = True                  # its test reads its gyro's column of the residual only
    order = 11
    stage = Stage.SENSE
    needs = frozenset({"ref", "motion"})
    model_needs = frozenset({"ref"})      # calibrated: regressed on the reference rate
    rivals = ("scale_factor",)
    channel = "other"
    scored = ("tilt_deg", "tilt_azimuth_deg")
    params = (Param("axis", "-", "axis", _unit_axis, kind="axis", required=False,
                    doc="true unit sensitive axis, platform frame"),
              Param("tilt_deg", "deg", "tilt_rad", deg_to_rad, lo=0.0, hi=90.0, required=False,
                    doc="angle between the nominal and the true axis"),
              Param("tilt_azimuth_deg", "deg", "tilt_azimuth_rad", deg_to_rad, required=False,
                    default=0.0, extension=True,
                    doc="direction of the tilt around the nominal axis (0: toward +z)"))
    doc = "true sensitive axis differs from the nominal one"

    def check(self, params, gyro, n_gyros):
        has_axis, has_tilt = "axis" in params, "tilt_deg" in params
        if has_axis and has_tilt:
            raise InputError("give either 'axis' (the true axis) or 'tilt_deg', not both",
                             column="tilt_deg")
        if not (has_axis or has_tilt):
            raise InputError("needs 'axis' (true unit axis, platform frame) or 'tilt_deg'",
                             column="axis")
        if has_axis and gyro is None:
            raise InputError("'axis' is the true axis of one gyro: name the gyro "
                             "(or use 'tilt_deg' for every gyro)", column="axis")
        if "tilt_azimuth_deg" in params and not has_tilt:
            raise InputError("'tilt_azimuth_deg' goes with 'tilt_deg'", column="tilt_azimuth_deg")

    def placeholder(self):
        return {"tilt_deg": 0.0}

    def predictor_term(self, act, n_gyros):
        """A deterministic error (a_i − h_i)·ω for the stated body rate, a_i the true axis."""
        return AxisTerm(spread(act, "axis", n_gyros, (3,)), spread(act, "tilt_rad", n_gyros),
                        spread(act, "tilt_azimuth_rad", n_gyros))

    def simulate(self, state, act, streams):
        p = act.p
        nominal = state.ctx.axes[act.cols]
        tilt = np.nan_to_num(p["tilt_rad"])
        az = np.nan_to_num(p["tilt_azimuth_rad"])
        true = np.where(np.isnan(p["axis"]).any(axis=1, keepdims=True),
                        tilted_axes(nominal, tilt, az), p["axis"])
        axes = state.axes.copy()
        axes[act.cols] = true
        return replace(state, axes=axes)

    def regress(self, ctx, gyro, e, r, q):
        e, ref, inst = self.against_reference(ctx, gyro, e)
        return _fit_misalignment(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use, instrument=inst)

    def entry_params(self, fit, old):
        params = super().entry_params(fit, old)
        params.pop("axis", None)                 # the fit returns tilt and azimuth
        return params

    def free_parameters(self, fit):
        return int(fit.extra.get("dof_c", 2))     # a tilt seen in one direction only has one

    def channel_line(self, fit, x, xm, ym):
        # the panel's regressor is ω⊥ along the fitted tilt: the residual (a − h)·ω = sin(tilt)·that
        if "tilt_deg" not in fit.params or "axis" not in fit.extra:
            return None
        s = math.sin(math.radians(float(fit.params["tilt_deg"])))
        return s * x * 3600.0, "tilt " + self._label(fit, "tilt_deg", unit="°")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"tilt_deg": _draw.u(rng, 0.2, 1.0, True),
                                          "tilt_azimuth_deg": _draw.u(rng, 0.0, 360.0)}


# -- fit ----------------------------------------------------------------------------------
# -- misalignment ----------------------------------------------------------------

def misalignment_basis(h) -> tuple[np.ndarray, np.ndarray]:
    """The orthonormal basis (e1, e2) ⟂ h of :func:`gyroarray.core.physics.tilted_axes` (one axis).

    Parameters
    ----------
    h : array_like, shape (3,)
        Nominal unit axis [-].

    Returns
    -------
    e1, e2 : ndarray, shape (3,)
        e1 = (ẑ − (ẑ·h)h)/|ẑ × h| (toward +z, tilt azimuth ψ = 0),
        e2 = ẑ × h/|ẑ × h| (horizontal, increasing azimuth, ψ = 90°);
        for h along ±z: e1 = +x, e2 = +y.
    """
    e1, e2 = tilt_basis(np.asarray(h, dtype=float)[None, :])
    return e1[0], e2[0]


def _tilt_fit(wh, zy0: np.ndarray, zu: np.ndarray, za: np.ndarray, seen, zi=None) -> tuple:
    """GLS of the tilt components c on the whitened perpendicular rates (along ``seen`` only
    when not None; instrumented by ``zi`` when given), the θ²/2·u term put back twice:
    (fit, c, cov, χ², dof)."""
    one_way = seen is not None
    cos_t = 1.0
    for _ in range(3):                       # plain fit, then the θ²/2·u term put back twice
        zy = zy0 + (1.0 - cos_t) * zu
        if one_way:
            fit = wh.fit_whitened(zy, (za @ seen)[:, None], None if zi is None else (zi @ seen)[:, None])
            c = seen * fit.beta[0]
            cov = np.outer(seen, seen) * fit.cov[0, 0]
            chi2 = float(fit.beta[0] ** 2 / fit.cov[0, 0])
            dof = 1
        else:
            fit = wh.fit_whitened(zy, za, zi)
            c, cov = fit.beta, fit.cov
            chi2 = float(c @ np.linalg.solve(cov, c))
            dof = 2
        cos_t = math.sqrt(max(1.0 - float(c @ c), 0.0))
    return fit, c, cov, chi2, dof


def _tilt_sigmas(c: np.ndarray, cov: np.ndarray, cn: float, sin_t: float, dof: int) -> dict:
    """1σ of the tilt [deg], and of its azimuth [deg] where the data measure it."""
    sigma = {}
    if cn > 0 and sin_t < 1.0:
        gt = c / (cn * math.sqrt(1.0 - sin_t ** 2))       # dθ/dc
        sigma["tilt_deg"] = float(rad_to_deg(math.sqrt(gt @ cov @ gt)))
    else:
        sigma["tilt_deg"] = float(rad_to_deg(math.sqrt(np.linalg.eigvalsh(cov)[-1])))
    cn_sigma = math.sqrt(c @ cov @ c) / cn if cn > 0 else math.inf
    if dof == 2 and cn > 3.0 * cn_sigma:                   # one direction: ψ is assumed, not measured
        gp = np.array([-c[1], c[0]]) / cn ** 2            # dψ/dc
        sigma["tilt_azimuth_deg"] = float(rad_to_deg(math.sqrt(gp @ cov @ gp)))
    return sigma


def _misalignment_evidence(gyro: int, z: float, tilt: float, psi: float, sigma: dict) -> str:
    """The sentence that reports the tilt (or its absence)."""
    if z >= Z_EVIDENT:
        az = (f" toward azimuth {pm(psi, sigma['tilt_azimuth_deg'])}° around it (0° = toward +z)"
              if "tilt_azimuth_deg" in sigma else "")
        ev = (f"gyro {gyro} residual follows the rate about axes perpendicular to its own: its true "
              f"axis is tilted {pm(tilt, sigma['tilt_deg'])}° from the nominal one{az}")
    else:
        ev = (f"gyro {gyro} residual shows no significant response to the rate about other axes "
              f"(tilt {pm(tilt, sigma['tilt_deg'])}°, z = {z:.1f})")
    return ev


def fit_misalignment(e, omega_ref_rad_s, h, time_s, dt_s: float, r: float, q: float, gyro: int,
                     *, use=None, instrument=None) -> EffectFit:
    """True sensitive axis: residual proportional to the rate about other axes.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual y − h·ω_ref [rad/s].
    omega_ref_rad_s : array_like, shape (n, 3)
        Platform-frame reference rate [rad/s].
    h : array_like, shape (3,)
        Nominal unit sensitive axis [-].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`~gyroarray.analysis.gls.gls_rw`).
    instrument : array_like, shape (n, 3), optional
        The reference rate smoothed [rad/s]: a noisy reference (errors in
        variables) is fitted by instrumental variables, the columns read from
        ``omega_ref_rad_s`` instrumented by the same columns read from this.

    Returns
    -------
    EffectFit
        ``misalignment``: ``tilt_deg`` (with sigma) and ``tilt_azimuth_deg``
        (ψ; the true unit axis, platform frame, in ``extra["axis"]``), with sigma
        when the tilt exceeds 3 of its σ); z from the χ² of (c1, c2) with 2
        degrees of freedom (1 when the motion sees one direction only).

    Notes
    -----
    With the basis of :func:`misalignment_basis` (the convention of
    ``gyroarray.core.physics.tilted_axes``)::

        a   = cos θ h + sin θ (cos ψ e1 + sin ψ e2)            (true axis)
        e_t = (a − h)·ω_t + b_t + w_t
            = c1·(e1·ω_t) + c2·(e2·ω_t) + b_t + w_t − (1 − cos θ)·u_t
        c1 = sin θ cos ψ,  c2 = sin θ sin ψ
        θ = asin|c|,  ψ = atan2(c2, c1),  a = √(1 − |c|²) h + c1 e1 + c2 e2

    The last term of e_t, (1 − cos θ)·u ≈ θ²/2·u, is second order (a
    scale-factor-like −152 ppm at θ = 1°, which a table run resolves to
    ~10 ppm): it is put back with the θ of the previous fit and (c1, c2)
    refitted, twice (the change of θ² after the second pass is below 1e-6
    of it at θ = 1°). σ by the delta method from cov(c1, c2). When the motion leaves one direction of the
    (e1, e2) plane unseen (rotation about a single axis), the fit uses the
    seen direction only: the tilt component along it (the unseen component
    taken as 0, so ψ has no sigma), ``extra["unseen"]`` the unseen unit
    vector, 1 degree of freedom.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    as_vector(time_s, n, "time_s")
    w, _ = projected_rate(omega_ref_rad_s, h, n)
    hv = np.asarray(h, dtype=float)
    e1, e2 = misalignment_basis(hv)
    basis = np.column_stack([e1, e2])                      # (3, 2)
    x = w @ basis                                          # (n, 2)
    wh = RWWhitener(n, r, q, use)
    zx = wh.whiten(x, e, w @ hv)
    za, zy0, zu = zx[:, :2], zx[:, 2], zx[:, 3]
    zi = None if instrument is None else wh.whiten(projected_rate(instrument, hv, n)[0] @ basis)
    g = za.T @ za
    lam, vec = np.linalg.eigh(g)
    unseen = None
    none = {"tilt_deg": 0.0, "tilt_azimuth_deg": 0.0}
    if not lam[1] > 0:
        return not_identifiable("misalignment", gyro, none, "there is no rate about the axes "
                                 "perpendicular to its axis", NotIdentifiableError("no rate ⟂ h"))
    one_way = lam[0] < lam[1] / MAX_COND
    if one_way:
        seen = vec[:, 1]
        unseen = basis @ vec[:, 0]
    fit, c, cov, chi2, dof = _tilt_fit(wh, zy0, zu, za, seen if one_way else None, zi)
    z = chi2_to_z(chi2, dof)
    cn = float(np.hypot(c[0], c[1]))
    sin_t = min(cn, 1.0)
    axis = math.sqrt(1.0 - sin_t ** 2) * hv + c[0] * e1 + c[1] * e2
    axis = axis / np.linalg.norm(axis)
    tilt = rad_to_deg(math.asin(sin_t))
    psi_rad = math.atan2(c[1], c[0])
    psi = rad_to_deg(psi_rad)
    sigma = _tilt_sigmas(c, cov, cn, sin_t, dof)
    # tilt + azimuth (not also ``axis``: a model entry takes one form or the other);
    # the true axis itself is in extra["axis"]
    params = {"tilt_deg": float(tilt), "tilt_azimuth_deg": float(psi)}
    ev = _misalignment_evidence(gyro, z, tilt, psi, sigma)
    extra = fit_extra(fit, c=[float(v) for v in c], cov_c=cov.tolist(), chi2_c=chi2, dof_c=dof,
                   axis=[float(v) for v in axis], instrumented=zi is not None)
    if unseen is not None:
        extra["unseen"] = [float(v) for v in unseen]
        ev += "; the motion does not show a tilt toward " + \
            "(" + ", ".join(f"{v:.3f}" for v in unseen) + ")"
    return EffectFit("misalignment", gyro, params, sigma, z, ev, extra)


#: :func:`fit_misalignment` by content: the ranking tests a rival again on records cut by other
#: gyros' fits, where this gyro's residual is as it was, bit for bit.
_fit_misalignment = by_content(maxsize=16)(fit_misalignment)
