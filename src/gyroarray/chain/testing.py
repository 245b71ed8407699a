"""Conformance checks for plugin authors, like scikit-learn's ``parametrize_with_checks``.

An effect of your own (:class:`gyroarray.effects.protocol.Effect`) and an
estimator of your own (:class:`gyroarray.estimators.Estimator`) should pass
the same checks as the built-ins. Run them in your package's tests::

    from gyroarray.chain.testing import check_effect, check_estimator
    from my_package import MyEffect, MyEstimator   # MyEstimator: @register("my_name")
                                                   # or name = "my_name" on the class

    def test_my_effect():
        check_effect(MyEffect)

    def test_my_estimator():
        check_estimator(MyEstimator)

or one test per check with ``@parametrize_effect_checks([MyEffect])`` /
``@parametrize_estimator_checks([MyEstimator])`` (pytest). A failed check
raises ``AssertionError`` naming the check and what went wrong.

Effect checks
-------------
``toml_round_trip``
    The example parameters (:meth:`Effect.example`, else
    :meth:`Effect.placeholder`) survive a model written to TOML and read back.
``bad_parameters``
    A value out of its bounds, a string for a number, an unknown parameter
    and a missing required one are each refused with one
    :class:`~gyroarray.core.errors.InputError` naming the parameter.
``simulate_then_fit``
    A record simulated with the effect (a table session: static, steps and
    swings, static; S1 N = 6; ARW + RRW on every gyro), fitted with the
    effect added, gives back each parameter the effect scores
    (``Effect.scored``) within 2σ of its fit, or within 10 % where the fit
    has no σ. Needs :meth:`Effect.example`.
``absent_z``
    On records without the effect (``n_seeds`` of them, every gyro), its
    candidate z is ≈ N(0, 1): mean within ±(3/√M + 0.3) over the M values, and
    standard deviation in [0.5, 1.6] (a scan's calibration is approximate),
    no z above 6.
"""

from __future__ import annotations

import functools
import math
from typing import Callable, Iterable

import numpy as np

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.tomlio import loads_toml
from gyroarray.core.units import RAD_PER_DEG

__all__ = ["effect_checks", "check_effect", "parametrize_effect_checks", "estimator_checks",
           "check_estimator", "parametrize_estimator_checks"]

#: The table session of the checks [s] and its sample rate [Hz].
STATIC_S, MOTION_S, TAIL_S, RATE_HZ = 600.0, 900.0, 300.0, 50.0
#: The baseline of the checks' records, by ``Effect.baseline_term``: white 0.15 deg/√h,
#: walk 5 deg/h/√h (the one parameter of each baseline effect, in its spec unit).
BASELINE_LEVELS = {"white": 0.15, "walk": 5.0}


def _registered(effect_cls):
    from gyroarray.effects import REGISTRY, register  # lazy: loads numba
    if not (isinstance(effect_cls, type)):
        raise TypeError(f"check_effect takes the Effect class, got {effect_cls!r}")
    eff = REGISTRY.get(getattr(effect_cls, "name", ""))
    if eff is not None and type(eff) is effect_cls:
        return eff
    return register(effect_cls, source=f"gyroarray.chain.testing ({effect_cls.__module__})")


def _layout():
    return Layout.conical(1, 6, math.acos(1.0 / math.sqrt(3.0)))


def _example(eff, rng):
    from gyroarray.sim.lab import table_profile  # lazy: loads numba, pandas
    layout = _layout()
    t = np.arange(0.0, STATIC_S + MOTION_S + TAIL_S, 1.0 / RATE_HZ)
    max_rate = np.abs(table_profile(t, STATIC_S, MOTION_S) @ layout.H.T).max(axis=0) / RAD_PER_DEG
    return eff.example(rng, layout.n_gyros, max_rate)


def _record(extra_entries, seed: int):
    from gyroarray.sim.lab import lab_run  # lazy: loads numba, pandas
    from gyroarray.effects.model import ModelEntry, NoiseModel  # lazy: loads numba
    from gyroarray.effects import REGISTRY  # lazy: loads numba
    rng = np.random.default_rng([20261123, seed])
    base = tuple(ModelEntry(e.name, None, {e.params[0].name: BASELINE_LEVELS[e.baseline_term]})
                 for e in REGISTRY.values() if e.baseline and e.baseline_term in BASELINE_LEVELS)
    return lab_run(NoiseModel(base + tuple(extra_entries)), _layout(), rng, rate_hz=RATE_HZ,
                   static_s=STATIC_S, motion_s=MOTION_S, tail_s=TAIL_S, protocol="table")


def _has_example(eff) -> bool:
    from gyroarray.effects.protocol import Effect  # lazy: runs the effect registry (numba)
    return type(eff).example is not Effect.example


def _params_of(eff, rng) -> tuple:
    if _has_example(eff):
        return _example(eff, rng)
    return (1 if eff.per_gyro else None), eff.placeholder()


def _check_toml_round_trip(effect_cls) -> None:
    from gyroarray.effects.model import ModelEntry, NoiseModel  # lazy: loads numba
    eff = _registered(effect_cls)
    gyro, params = _params_of(eff, np.random.default_rng(1))
    model = NoiseModel((ModelEntry(eff.name, gyro, params),))
    again = NoiseModel.from_toml(loads_toml(model.to_toml(), f"{eff.name} model"), n_gyros=_layout().n_gyros)
    assert again.entries == model.entries, f"{eff.name}: {again.entries} != {model.entries}"


def _check_bad_parameters(effect_cls) -> None:
    from gyroarray.effects.model import ModelEntry  # lazy: loads numba
    eff = _registered(effect_cls)
    gyro, good = _params_of(eff, np.random.default_rng(1))

    def refused(params, key, what):
        try:
            ModelEntry(eff.name, gyro, params)
        except InputError as err:
            text = str(err)
            assert "\n" not in text, f"{eff.name}, {what}: the message has several lines: {text!r}"
            assert key in text, f"{eff.name}, {what}: the message does not name {key!r}: {text!r}"
            return
        raise AssertionError(f"{eff.name}, {what}: {params} was accepted")

    refused({**good, "no_such_parameter": 1.0}, "no_such_parameter", "an unknown parameter")
    for p in eff.params:
        if p.kind != "scalar":
            continue
        if p.name in good:
            refused({**good, p.name: "one"}, p.name, "a string for a number")
        if math.isfinite(p.lo):
            refused({**good, p.name: p.lo - 1.0 - abs(p.lo)}, p.name, "a value below its bound")
        if math.isfinite(p.hi):
            refused({**good, p.name: p.hi + 1.0 + abs(p.hi)}, p.name, "a value above its bound")
        if p.required and p.name in good:
            rest = {k: v for k, v in good.items() if k != p.name}
            refused(rest, p.name, "a missing required parameter")


def _check_simulate_then_fit(effect_cls) -> None:
    from gyroarray.chain.compare import ModelComparison  # lazy: loads numba, pandas
    from gyroarray.effects.model import ModelEntry  # lazy: loads numba
    eff = _registered(effect_cls)
    if not _has_example(eff):
        raise AssertionError(f"{eff.name}: define example(rng, n_gyros, max_rate_deg_s) so the check "
                             "can simulate a record with the effect")
    gyro, params = _example(eff, np.random.default_rng(2))
    m = _record((ModelEntry(eff.name, gyro, params),), seed=2)
    comp = ModelComparison(m, n_runs=10)
    _, after = comp.fit([(eff.name, gyro)])
    fit = after.fits.get((eff.name, gyro))
    assert fit is not None, f"{eff.name}: no fit in the calibrated model"
    scored = eff.scored if eff.scored is not None else tuple(params)
    for key in scored:
        if key not in params:
            continue
        want, got = float(params[key]), float(fit.params.get(key, math.nan))
        s = fit.sigma.get(key)
        ok_sigma = s is not None and math.isfinite(s) and abs(got - want) <= 2.0 * s
        ok_rel = abs(got - want) <= 0.1 * abs(want)
        assert ok_sigma or ok_rel, (f"{eff.name}: {key} fitted {got:.6g} ± {s} against {want:.6g} "
                                    "simulated (neither within 2σ nor within 10 %)")


def _check_absent_z(effect_cls, n_seeds: int = 5) -> None:
    from gyroarray.chain.compare import ModelComparison  # lazy: loads numba, pandas
    eff = _registered(effect_cls)
    zs = []
    for seed in range(n_seeds):
        a = ModelComparison(_record((), seed=100 + seed), n_runs=5).analyse()
        zs += [t.z for t in a.tests if t.effect == eff.name and np.isfinite(t.z)]
    assert zs, f"{eff.name}: never tested on a table session (why_not: see diagnose's notes)"
    z = np.asarray(zs)
    bound = 3.0 / math.sqrt(z.size) + 0.3
    assert abs(z.mean()) <= bound, f"{eff.name}: mean z {z.mean():.2f} over {z.size} absent cases (|mean| > {bound:.2f})"
    if z.size >= 3:
        sd = float(z.std(ddof=1))
        assert 0.5 <= sd <= 1.6, f"{eff.name}: z has standard deviation {sd:.2f} over {z.size} absent cases"
    assert z.max() <= 6.0, f"{eff.name}: z = {z.max():.1f} on a record without the effect"


def effect_checks(effect_cls) -> list[tuple[str, Callable[[], None]]]:
    """The checks of an Effect subclass as (name, zero-argument callable) pairs."""
    return [("toml_round_trip", lambda: _check_toml_round_trip(effect_cls)),
            ("bad_parameters", lambda: _check_bad_parameters(effect_cls)),
            ("simulate_then_fit", lambda: _check_simulate_then_fit(effect_cls)),
            ("absent_z", lambda: _check_absent_z(effect_cls))]


def check_effect(effect_cls, *, skip: Iterable[str] = ()) -> None:
    """Run every effect check (module docstring); AssertionError on the first failure."""
    for name, check in effect_checks(effect_cls):
        if name in set(skip):
            continue
        try:
            check()
        except AssertionError as err:
            raise AssertionError(f"check_effect({effect_cls.__name__}): {name}: {err}") from None


def parametrize_effect_checks(classes):
    """A pytest ``parametrize`` decorator: one test per (effect class, check), argument ``check``."""
    import pytest  # deferred: pytest is a test-only dependency, needed only by a test suite
    cases = [(f"{cls.__name__}-{name}", fn) for cls in classes for name, fn in effect_checks(cls)]
    return pytest.mark.parametrize("check", [fn for _, fn in cases], ids=[i for i, _ in cases])


# -- estimators ------------------------------------------------------------------------

def estimator_checks(estimator_cls) -> list[tuple[str, Callable[[], None]]]:
    """The estimator contract as (name, zero-argument callable) pairs (:mod:`gyroarray.estimators.checks`)."""
    from gyroarray.estimators import checks  # lazy: loads numba
    return [(name, functools.partial(fn, estimator_cls)) for name, fn in checks.CHECKS]


def check_estimator(estimator_cls) -> None:
    """Run every estimator check; AssertionError on the first failure."""
    for name, check in estimator_checks(estimator_cls):
        try:
            check()
        except AssertionError as err:
            raise AssertionError(f"check_estimator({estimator_cls.__name__}): {name}: {err}") from None


def parametrize_estimator_checks(classes):
    """A pytest ``parametrize`` decorator: one test per (estimator class, check), argument ``check``."""
    import pytest  # deferred: pytest is a test-only dependency, needed only by a test suite
    cases = [(f"{cls.__name__}-{name}", fn) for cls in classes for name, fn in estimator_checks(cls)]
    return pytest.mark.parametrize("check", [fn for _, fn in cases], ids=[i for i, _ in cases])
