"""The noise injector: a noise model's effects run over the table's true rates.

Every effect of ``shared/spec/effects.md`` is one object of the registry
(:data:`REGISTRY`, :mod:`gyroarray.effects`: one module per effect, plus
plugins), looked up by its spec name; the protocol it follows (parameters,
stage, ``simulate``, fit side) is :mod:`gyroarray.effects.protocol`. A noise
model (:class:`gyroarray.effects.model.NoiseModel`) is a list of entries naming
effects; :func:`simulate_readings` runs the chain below over it. Adding a
missing effect is one new module in ``effects/`` (or a plugin file).

Units: parameters are stored as the user wrote them (spec units) and
converted to SI once, through the named converters of
:mod:`gyroarray.core.units`; everything below works in rad, rad/s and s.

The chain
---------
A run has n samples at a uniform step dt, N gyros with nominal unit axes
``H`` (N×3, platform frame) and the table's true rate of the platform
relative to the Earth, ω(t) (n×3, platform frame).

1. Sensed input (``Stage.SENSE``). ``misalignment`` replaces a gyro's nominal
   axis by its true axis a_k; ``earth_rate`` adds the Earth's rate
   ω_ie(t) (platform frame). Then u_k(t) = a_k · (ω(t) + ω_ie(t)).
2. ``latency`` (``Stage.DELAY``): u_k(t) ← u_k(t − d_k), fractional delay by
   4-point (cubic) Lagrange interpolation (:func:`fractional_delay`).
3. ``scale_factor``, ``scale_nonlinearity`` (``Stage.SCALE``), both on the
   same input u: y = (1 + s)·u + k2·u², s = ppm·1e-6.
4. Additive errors. First the array-wide modifiers of the white sources
   (``Stage.SHAPE``): ``correlation`` (cross-gyro correlation of the ARW and
   RRW draws) and ``burst`` (ARW variance × ratio over a time window); then
   the terms (``Stage.ADD``): ``arw``, ``rrw``, ``bias_instability``,
   ``rate_ramp``, ``gauss_markov``, ``sinusoid``, ``constant_bias``,
   ``temperature_bias``.
5. ``bandwidth`` (``Stage.FILTER``): the sensor's own low-pass filter, on
   everything above (rate, biases and noise).
6. ``quantization`` (``Stage.QUANTIZE``): the output angle θ_k = Σ x_j·dt is
   accumulated from θ_{−1} = 0 and rounded to the step Δ = √12·Q; output
   y_k = (round(θ_k/Δ) − round(θ_{k−1}/Δ))·Δ/dt (the spec's definition).
7. ``saturation`` (``Stage.SATURATE``): clip at ±range.
8. Faults (``Stage.FAULT``): what a failed gyro outputs from its onset.

Within a stage, effects run in registry order (the spec's table order). The
additive terms commute; the order only fixes the floating-point bits.

Per-gyro effects apply to every gyro when the entry has no ``gyro``; an entry
with ``gyro = k`` applies to gyro k and overrides an all-gyros entry of the
same effect for that gyro (``arw`` 0.1 on all, ``arw`` 0.2 on gyro 3).

What each effect does is written in its own module of ``gyroarray.effects``.

Frames and signs (``shared/spec/measurement-format.md``)
---------------------------------------------------------
* Platform frame P: the array's frame; the layout's axes are in it.
* Local-level frame L: the platform frame at t = 0, fixed to the Earth:
  z up, x at ``heading`` from true north. "Turning about up" is read as a
  right-handed rotation about the up axis: heading ψ takes north onto x_L by
  a rotation of ψ about up, i.e. counter-clockwise seen from above (ψ = 90°
  puts x_L on west; this is *not* the compass convention, which turns
  clockwise). Then y_L = up × x_L.
* ``attitude[i]`` is the rotation matrix R_i from P to L at sample i
  (v_L = R_i v_P); ``None`` means the platform stays at its t = 0 attitude
  (R = I).
* Earth rate: in east-north-up ω_ie = Ω (0, cos φ, sin φ); in L,
  ω_ie,L = Ω (cos φ cos ψ, −cos φ sin ψ, sin φ); in P at sample i,
  ω_ie,P = R_iᵀ ω_ie,L. Ω = :data:`gyroarray.core.constants.EARTH_RATE_RAD_S`.

Randomness
----------
Only through the ``numpy.random.Generator`` passed to
:func:`simulate_readings`. A run draws from it once: four integers in
[0, 2³²) (``rng.integers``), the root entropy. Every random source then has
its own stream: a new Generator (same bit-generator type as ``rng``) seeded
by ``SeedSequence(root, spawn_key=(crc32(effect name), gyro, source))``,
with gyro the 1-based gyro number (0 for an array-wide source). So

* the same seed gives the same bits (same machine and library versions:
  the Cholesky mixing is a BLAS product);
* adding, removing or changing one entry does not change the draws of any
  other effect (nor of the same effect on other gyros): the streams are keyed
  by name and gyro, not by position in the model. ``correlation`` changes
  ARW/RRW on purpose: it mixes their draws (which stay the same).

Draws per stream (gyro k): ``arw`` n standard normals; ``rrw`` n;
``bias_instability`` M ≥ 2n (FFT length); ``gauss_markov`` n (the first sets
the stationary start); ``quantization`` none (the counter is
deterministic); ``correlation`` (gyro 0) n normals for the common-mode ARW source
(source 1) and n for the RRW one (source 2), only with ``common_mode``.
With a full correlation matrix, ARW/RRW draw on every gyro (Cholesky needs
them all), also on gyros without that effect.
"""

from __future__ import annotations

import math
from dataclasses import replace
from types import MappingProxyType
from typing import Any

import numpy as np

from gyroarray.effects import REGISTRY, did_you_mean, effect_names, get_effect
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.effects.protocol import Active, ChainState, Effect, Stage, Streams, SimContext
from gyroarray.core.sensor import gravity_specific_force

__all__ = ["REGISTRY", "effect_names", "get_effect", "did_you_mean", "simulate_readings", "sim_context",
           "simulate_on", "resolve"]


def _as_site(site) -> tuple[float, float] | None:
    if site is None:
        return None
    if hasattr(site, "latitude_rad") and hasattr(site, "heading_rad"):
        lat, head = site.latitude_rad, site.heading_rad
    else:
        try:
            lat, head = site
        except (TypeError, ValueError):
            raise InputError("site must be (latitude_rad, heading_rad)") from None
    lat, head = float(lat), float(head)
    if not (math.isfinite(lat) and math.isfinite(head)) or abs(lat) > math.pi / 2:
        raise InputError(f"site (latitude_rad, heading_rad) = ({lat:g}, {head:g}) is not a valid site")
    return lat, head


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def _context(truth, layout, dt_s, time_s, attitude, temp_c, site, specific_force=None,
             angular_accel=None) -> SimContext:
    w = np.asarray(truth, dtype=float)
    if w.ndim != 2 or w.shape[1] != 3 or w.shape[0] < 2:
        raise InputError(f"truth_omega_body_rad_s must be (n, 3) with n >= 2, got shape {w.shape}")
    if not np.all(np.isfinite(w)):
        raise InputError("truth_omega_body_rad_s contains a non-finite value")
    n = w.shape[0]
    dt = float(dt_s)
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"dt_s must be a positive number, got {dt_s!r}")
    if time_s is None:
        t = np.arange(n) * dt
    else:
        t = np.asarray(time_s, dtype=float)
        if t.shape != (n,) or not np.all(np.isfinite(t)):
            raise InputError(f"time_s must be {n} finite values, got shape {t.shape}")
        if not np.allclose(np.diff(t), dt, rtol=1e-6, atol=0.0):
            raise InputError(f"time_s must be uniformly spaced at dt_s = {dt:g} s "
                             "(the noise injector needs a uniform step)")
    att = None
    if attitude is not None:
        att = np.asarray(attitude, dtype=float)
        if att.shape != (n, 3, 3) or not np.all(np.isfinite(att)):
            raise InputError(f"attitude must be ({n}, 3, 3) finite rotation matrices, got shape {att.shape}")
        err = np.abs(np.matmul(att.transpose(0, 2, 1), att) - np.eye(3)).max()
        if err > 1e-6:
            raise InputError(f"attitude matrices are not orthonormal (max |RᵀR − I| = {err:.3g})")
    temp = None
    if temp_c is not None:
        temp = np.asarray(temp_c, dtype=float)
        if temp.shape != (n,) or not np.all(np.isfinite(temp)):
            raise InputError(f"temp_c must be {n} finite values, got shape {temp.shape}")
    lay = layout if isinstance(layout, Layout) else Layout.from_axes(layout)
    f0 = _vectors("specific_force", specific_force, n)
    alpha = _vectors("angular_accel", angular_accel, n)
    return SimContext(omega_body_rad_s=_readonly(w), axes=_readonly(lay.H), dt_s=dt,
                      time_s=_readonly(t), attitude=None if att is None else _readonly(att),
                      temp_c=None if temp is None else _readonly(temp), site=_as_site(site),
                      specific_force_origin_m_s2=_readonly(
                          gravity_specific_force(att, n) if f0 is None else f0),
                      angular_accel_rad_s2=_readonly(
                          np.gradient(w, dt, axis=0) if alpha is None else alpha),
                      positions_m=_readonly(lay.positions_or_zero))


def _vectors(name: str, value, n: int) -> np.ndarray | None:
    """An optional (n, 3) array of finite values, checked."""
    if value is None:
        return None
    a = np.asarray(value, dtype=float)
    if a.shape != (n, 3) or not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be ({n}, 3) finite values, got shape {a.shape}")
    return a


def _stack(values: list, kind: str) -> np.ndarray:
    if kind in ("axis", "vector"):
        return np.array([np.full(3, np.nan) if v is None else v for v in values], dtype=float)
    return np.array([np.nan if v is None else v for v in values], dtype=float)


def resolve(model, n_gyros: int) -> list[tuple[Effect, Active]]:
    """The model's effects as they act on an N-gyro array, in chain order.

    Per-gyro effects: a ``gyro = k`` entry wins over an all-gyros entry for
    gyro k. Returns ``(effect, Active)`` pairs sorted by (stage, registry
    order).
    """
    model.check(n_gyros)
    groups: dict[str, list[tuple[int, Any]]] = {}
    for i, entry in enumerate(model.entries):
        groups.setdefault(entry.effect, []).append((i, entry))
    out = []
    for name, items in groups.items():
        eff = REGISTRY[name]
        label = f"effects[{','.join(str(i) for i, _ in items)}] ({name})"
        if not eff.per_gyro:
            (_, entry), = items
            out.append((eff, Active(np.arange(n_gyros), entry.si_params, label)))
            continue
        per: dict[int, Any] = {}
        for _, entry in sorted(items, key=lambda it: it[1].gyro is not None):
            if entry.gyro is None:                           # all gyros, then the overrides
                per.update(dict.fromkeys(range(n_gyros), entry))
            else:
                per[entry.gyro - 1] = entry
        cols = np.array(sorted(per), dtype=np.int64)
        p = {prm.si_name: _stack([per[c].si_params.get(prm.si_name) for c in cols], prm.kind)
             for prm in eff.params}
        out.append((eff, Active(cols, MappingProxyType(p), label)))
    out.sort(key=lambda ea: (ea[0].stage, ea[0].order, ea[0].name))
    return out


def simulate_readings(model, truth_omega_body_rad_s, layout, dt_s: float,
                      rng: np.random.Generator, *, time_s=None, attitude=None,
                      temp_c=None, site=None, specific_force=None,
                      angular_accel=None) -> np.ndarray:
    """Gyro outputs of an array with the effects of a noise model.

    Parameters
    ----------
    model : NoiseModel
        The effects (:class:`gyroarray.effects.model.NoiseModel`).
    truth_omega_body_rad_s : array_like, shape (n, 3)
        True rate of the platform relative to the Earth, platform frame
        [rad/s], at the sample times.
    layout : Layout or array_like, shape (N, 3)
        The array's nominal unit sensitive axes [-] (and, for a Layout, the
        gyro positions ``positions_m`` [m], zero when absent).
    dt_s : float
        Sample step [s] (uniform).
    rng : numpy.random.Generator
        The only source of randomness (four words are drawn from it; see
        the module docstring).
    time_s : array_like, shape (n,), optional
        Sample times [s], uniform at ``dt_s``; default ``arange(n)·dt_s``.
        Used by ``rate_ramp`` (R·t), ``sinusoid`` and ``burst``.
    attitude : array_like, shape (n, 3, 3), optional
        Platform -> local-level rotation matrices (``earth_rate``); default:
        the platform keeps its t = 0 attitude.
    temp_c : array_like, shape (n,), optional
        Temperature at the array [°C] (``temperature_bias``).
    site : (latitude_rad, heading_rad), optional
        Site latitude and heading of the platform x axis at t = 0 [rad]
        (``earth_rate``); an object with those two attributes also works.
    specific_force : array_like, shape (n, 3), optional
        Specific force at the platform origin, platform frame [m/s²] (the
        truth's ``specific_force_m_s2``); default gravity through
        ``attitude``, Rᵀ[0, 0, g0] (``g_sensitivity``).
    angular_accel : array_like, shape (n, 3), optional
        Angular acceleration dω/dt, platform frame [rad/s²] (the truth's
        ``angular_accel_rad_s2``); default central differences of the rate
        (``g_sensitivity`` off the origin).

    Returns
    -------
    ndarray, shape (n, N)
        Gyro outputs along their own sensitive axes [rad/s].

    Raises
    ------
    InputError
        Bad shapes or values, a model invalid for N gyros, or an effect
        missing what it needs (``temperature_bias`` without ``temp_c``,
        ``earth_rate`` without ``site``, ...).

    Notes
    -----
    The chain, the frames and the random streams are in the module docstring.
    """
    ctx = _context(truth_omega_body_rad_s, layout, dt_s, time_s, attitude, temp_c, site,
                   specific_force, angular_accel)
    return simulate_on(model, ctx, rng)


def sim_context(truth_omega_body_rad_s, layout, dt_s: float, *, time_s=None, attitude=None, temp_c=None,
                site=None, specific_force=None, angular_accel=None) -> SimContext:
    """The checked inputs of :func:`simulate_readings` (same parameters), to run many models or
    seeds on one truth with :func:`simulate_on` (a Monte-Carlo band: the checks and the derived
    arrays, up to 0.15 s on 1e6 samples with an attitude, are made once)."""
    return _context(truth_omega_body_rad_s, layout, dt_s, time_s, attitude, temp_c, site,
                    specific_force, angular_accel)


def simulate_on(model, ctx: SimContext, rng: np.random.Generator) -> np.ndarray:
    """:func:`simulate_readings` on inputs prepared by :func:`sim_context` (same bits)."""
    plan = resolve(model, ctx.n_gyros)
    streams = Streams.from_rng(rng)
    state = ChainState(ctx=ctx, axes=ctx.axes.copy(), frame_rate=np.zeros((ctx.n, 3)))
    for eff, act in plan:
        if state.x is None and eff.stage > Stage.SENSE:
            state = _sense(state)
        if state.u is None and eff.stage >= Stage.SCALE:
            state = replace(state, u=state.x)
        state = eff.simulate(state, act, streams)
    if state.x is None:
        state = _sense(state)
    assert state.x is not None                                       # sensed
    return state.x


def _sense(state: ChainState) -> ChainState:
    """u_k = a_k · (ω + ω_extra): the sensed input of every gyro (n, N) (zeros at once for a
    table at rest without an extra rate: the Monte-Carlo band of a static record)."""
    w = state.ctx.omega_body_rad_s
    if state.frame_rate.any():
        w = w + state.frame_rate
    elif not w.any():
        return replace(state, x=np.zeros((w.shape[0], state.axes.shape[0])))
    # axes.T contiguous: 6x faster for this (n, 3) x (3, N) product, the same bits (a 3-term sum)
    return replace(state, x=w @ np.ascontiguousarray(state.axes.T))
