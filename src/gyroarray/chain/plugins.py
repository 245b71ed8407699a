"""``--plugin PATH.py``: a file of the user's effects and estimators, checked when it loads.

The file is run once (:func:`gyroarray.effects.run_plugin_file`: a regular
``.py`` file; an exception in it is one line naming the file and line). What
it defines is registered only once it passes the conformance checks a load
can afford:

* each :class:`~gyroarray.effects.protocol.Effect` subclass with a ``name``:
  the checks of :data:`LOAD_EFFECT_CHECKS` (its parameters survive a TOML
  round trip; a bad value, a string, an unknown or a missing parameter is
  refused in one line naming it). The statistical checks (simulate then fit
  within 2σ, z ≈ N(0, 1) when absent) simulate a 30-minute table session
  each: run them in your tests with
  :func:`gyroarray.chain.testing.check_effect`;
* each :class:`~gyroarray.estimators.Estimator` subclass it defines: every
  check of :func:`gyroarray.chain.testing.check_estimator` (they take a
  fraction of a second), then it is registered under its ``name`` for
  ``run --estimators``.

A failed check is refused with the class and the check named (exit 2), and
whatever the file had registered is taken out again.
"""

from __future__ import annotations

import inspect
from typing import Iterable

from gyroarray import effects
from gyroarray import estimators
from gyroarray.chain import testing
from gyroarray.core.errors import InputError

__all__ = ["LOAD_EFFECT_CHECKS", "load_plugin", "load_plugins"]

#: The effect checks run when a plugin file loads (fast; the others simulate).
LOAD_EFFECT_CHECKS = ("toml_round_trip", "bad_parameters")

#: Classes that passed their checks in this process (a file loaded again is not checked again).
_PASSED: set[type] = set()

def _estimator_classes(module) -> list[type]:
    return [obj for obj in vars(module).values()
            if inspect.isclass(obj) and issubclass(obj, estimators.Estimator)
            and obj.__module__ == module.__name__ and not inspect.isabstract(obj)]


def _refuse(where: str, cls: type, check: str, err: Exception) -> InputError:
    why = str(err) if isinstance(err, (AssertionError, InputError)) else f"{type(err).__name__}: {err}"
    return InputError(f"{cls.__name__} fails the conformance check {check!r}: {why}; fix it "
                      "(gyroarray.chain.testing runs the same checks in your tests)", file=where)


def load_plugin(path) -> list[str]:
    """Run one plugin file, check and register its effects and estimators; their names.

    Raises
    ------
    InputError
        The file cannot be run, defines neither an effect nor an estimator,
        a name is taken, or a class fails a conformance check (named).
    """
    where = str(path)
    module, _ = effects.run_plugin_file(path)      # run once per process
    effect_cls = effects.effect_classes(module)
    estimator_cls = _estimator_classes(module)
    if not effect_cls and not estimator_cls:
        raise InputError("the plugin defines no effect (a subclass of gyroarray.effects.protocol.Effect "
                         "with a name) and no estimator (a subclass of gyroarray.estimators.Estimator)",
                         file=where)
    names: list[str] = []
    try:
        for cls in effect_cls:
            checked = cls in _PASSED
            names.append(effects.register(cls, source=where).name)
            for check, run in testing.effect_checks(cls):
                if check in LOAD_EFFECT_CHECKS and not checked:
                    try:
                        run()
                    except Exception as err:     # user code: a crash in a check fails it too
                        raise _refuse(where, cls, check, err) from None
            _PASSED.add(cls)
        for cls in estimator_cls:
            name = getattr(cls, "name", "")
            if not (isinstance(name, str) and name.isidentifier()):
                raise InputError(f"the estimator {cls.__name__} has no registry name: set name = "
                                 "'my_name' on the class (run --estimators uses it)", file=where)
            if name in estimators.available() and estimators.get_estimator(name) is not cls:
                raise InputError(f"estimator {name!r} is already defined; a plugin adds estimators, "
                                 "it cannot replace one", file=where)
            checked = cls in _PASSED
            for check, run in ([] if checked else testing.estimator_checks(cls)):
                try:
                    run()
                except Exception as err:     # user code: a crash in a check fails it too
                    raise _refuse(where, cls, check, err) from None
            _PASSED.add(cls)
            estimators.register(name)(cls)
            names.append(name)
    except InputError:                   # take out what this file registered, nothing else
        for cls in effect_cls:
            name = getattr(cls, "name", "")
            if type(effects.REGISTRY.get(name)) is cls:
                effects.unregister(name)
        for cls in estimator_cls:
            name = getattr(cls, "name", "")
            if name in estimators.available() and estimators.get_estimator(name) is cls:
                estimators.unregister(name)
        raise
    return names


def load_plugins(paths: Iterable) -> list[str]:
    """Every ``--plugin`` file in order (:func:`load_plugin`); the names they add."""
    out: list[str] = []
    for path in paths or ():
        out += load_plugin(path)
    return out
