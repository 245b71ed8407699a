"""``earth_rate``: the Earth's rotation sensed through the table attitude."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.effects.fits.earth_fit import fit_earth_rate
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.core.physics import earth_rate_platform
from gyroarray.effects.protocol import Effect, Kind, Param, Stage
from gyroarray.core.units import RAD_PER_DEG, deg_to_rad


class EarthRate(Effect):
    """Needs ``site``; its ``latitude_deg`` must equal the site latitude
    (1e-9 rad), the heading comes from the site. Adds ω_ie,P = R_iᵀ ω_ie,L to
    the rate every gyro senses (frames in :mod:`gyroarray.core.physics`).

    Fit: offsets that change with the attitude as Ω would, on every gyro at
    once (:func:`gyroarray.effects.fits.earth_fit.fit_earth_rate`; slow: tested
    again with the random walk re-estimated without it). The fit weighs the
    gyros as independent; under a modelled noise correlation ρ > 0 the
    variance of a combination of gyros grows by at most 1 + (N − 1)ρ, so its
    z is deflated by the root (a scoring run with ρ_arw = 0.16 on 5 gyros gave
    a false z of 4.3 without it).
    """

    name = "earth_rate"
    order = 16
    per_gyro = False
    stage = Stage.SENSE
    kind = Kind.ARRAY
    predicts = True
    slow = True
    needs = frozenset({"ref", "motion", "site"})
    model_needs = frozenset({"ref"})      # calibrated: the attitude comes from the reference rate
    params = (Param("latitude_deg", "deg", "latitude_rad", deg_to_rad, lo=-90.0, hi=90.0,
                    doc="site latitude (heading from the site)"),)
    doc = "Earth's rotation sensed through the table attitude"

    def simulate(self, state, act, streams):
        ctx = state.ctx
        lat = act.p["latitude_rad"]
        if ctx.site is None:
            raise InputError(f"{act.label}: earth_rate needs the site's heading: pass "
                             "site=(latitude_rad, heading_rad)")
        site_lat, heading = ctx.site
        if abs(site_lat - lat) > 1e-9:
            raise InputError(f"{act.label}: latitude_deg = {math.degrees(lat):.9g} disagrees with the "
                             f"site latitude {math.degrees(site_lat):.9g} deg", column="latitude_deg")
        w = earth_rate_platform(lat, heading, ctx.n, ctx.attitude)
        return replace(state, frame_rate=state.frame_rate + w)

    def fit(self, ctx, gyro, E):
        site = ctx.site
        heading = site.heading_rad / RAD_PER_DEG if site is not None else 0.0
        return fit_earth_rate(E, ctx.H, ctx.ref, ctx.t, ctx.dt, ctx.r, ctx.q, heading,
                              None if site is None else site.latitude_rad / RAD_PER_DEG,
                              attitude=ctx.attitude)

    def test(self, ctx, gyro):
        f = ctx.fitted(self, gyro, ctx.E)
        rho = _largest_correlation(ctx)
        if rho <= 0.0 or not np.isfinite(f.z):
            return f
        factor = math.sqrt(1.0 + (ctx.N - 1) * rho)
        return replace(f, z=float(f.z) / factor, extra={**f.extra, "z_independent": float(f.z),
                                                        "correlation_deflation": factor})

    def example(self, rng, n_gyros, max_rate_deg_s):
        _draw.gyro(rng, n_gyros)
        return None, {"latitude_deg": 34.25}      # the site of the scoring sessions' sidecar


def _largest_correlation(ctx) -> float:
    """The largest mean off-diagonal ρ (ARW or RRW) of the model's correlation, 0 without one."""
    rho = 0.0
    for e in ctx.entries("correlation"):
        for key in ("rho_arw", "rho_rrw"):
            v = np.asarray(e.params.get(key, 0.0), float)
            if v.ndim == 2:
                v = v[~np.eye(v.shape[0], dtype=bool)].mean() if v.shape[0] > 1 else np.float64(0.0)
            rho = max(rho, float(v))
    return rho
