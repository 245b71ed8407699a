"""The estimator contract, checked over every registered estimator.

Like scikit-learn's ``parametrize_with_checks``: the same checks run on each
name of ``available()`` (built-ins and installed plugins), so an estimator
that fails them is not registered. A plugin that fails to load fails its own
checks with the loader's message and no other.
"""

from __future__ import annotations

import numpy as np
import pytest

from gyroarray.core.errors import InputError
from gyroarray.estimators import Estimator, available, get_estimator, make
from gyroarray.estimators import base as est_base
from gyroarray.estimators.checks import CHECKS
from gyroarray.chain.testing import check_estimator, estimator_checks

NAMES = available()


def _class(name):
    return get_estimator(name)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("check_name", [n for n, _ in CHECKS])
def test_contract(name, check_name):
    """Every registered estimator passes every public check (gyroarray.chain.testing)."""
    cls = _class(name)
    dict(estimator_checks(cls))[check_name]()


def test_registry_lists_the_builtins():
    assert {"kf_array", "kf_single", "ols", "gls", "naive", "bound"} <= set(NAMES)


def test_a_broken_estimator_fails_its_checks():
    """The checks can fail: an estimator whose __init__ learns, and one whose estimate is random."""
    base = get_estimator("naive")

    class Learns(base):
        def __init__(self):
            super().__init__()
            self.weights_ = 1.0

    class Random(base):
        def estimate(self, readings):
            out = super().estimate(readings)
            return out + np.random.default_rng().normal(size=out.shape)

    with pytest.raises(AssertionError, match="init_only_stores"):
        check_estimator(Learns)
    with pytest.raises(AssertionError, match="same bits"):
        check_estimator(Random)


def test_make_refuses_unknown_names():
    with pytest.raises(InputError, match="did you mean 'kf_array'"):
        get_estimator("kf_aray")
    with pytest.raises(InputError, match="unknown hyperparameter"):
        make("gls", lowpass=3.0)


class _EntryPoint:
    def __init__(self, name, value, target=None):
        self.name, self.value, self._target = name, value, target

    def load(self):
        if self._target is None:
            raise ImportError("No module named 'broken_plugin'")
        return self._target


def test_plugins_are_lazy_and_a_broken_one_is_isolated(monkeypatch):
    class Plugin(Estimator):
        description = "a plugin"

        def __init__(self):
            pass

    eps = {"broken": _EntryPoint("broken", "broken_plugin:Est"),
           "good": _EntryPoint("good", "good_plugin:Est", Plugin),
           "notanest": _EntryPoint("notanest", "x:y", dict)}
    monkeypatch.setattr(est_base, "_entry_points", lambda: eps)
    monkeypatch.setattr(est_base, "_LOADED_PLUGINS", {})
    names = available()
    assert {"broken", "good", "notanest", "kf_array"} <= set(names)   # listed without loading
    with pytest.raises(InputError, match=r"plugin 'broken' \(broken_plugin:Est.*ImportError"):
        get_estimator("broken")
    with pytest.raises(InputError, match="not a gyroarray.estimators.Estimator"):
        get_estimator("notanest")
    assert get_estimator("good") is Plugin and Plugin.name == "good"
    assert get_estimator("gls").name == "gls"                         # the others keep working
