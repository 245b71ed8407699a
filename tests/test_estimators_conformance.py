"""The estimator contract, checked over every registered estimator.

Like scikit-learn's ``parametrize_with_checks``: the same checks run on each
name of ``available()`` (built-ins and installed plugins), so an estimator
that fails them is not registered. A plugin that fails to load fails its own
checks with the loader's message and no other.
"""

from __future__ import annotations

import numpy as np
import pytest

from gyroarray.errors import InputError
from gyroarray.estimators import Estimator, NotFittedError, available, get_estimator, make
from gyroarray.estimators import base as est_base
from gyroarray.layout import Layout
from gyroarray.sim.model import ModelEntry, NoiseModel

NAMES = available()
DT = 0.01
LAYOUT = Layout.conical(2, 5, np.deg2rad(65.9))
MODEL = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                    ModelEntry("arw", 3, {"n_deg_rt_h": 0.2}),
                    ModelEntry("rrw", None, {"k_deg_h_rt_h": 600.0}),
                    ModelEntry("correlation", None, {"rho_arw": 0.1, "rho_rrw": 0.05})))


def _readings(n=300, seed=7):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    omega = np.stack([0.01 * np.sin(t), 0.02 * np.cos(2 * t), 0.05 * np.sin(0.3 * t)], axis=1)
    return omega @ LAYOUT.H.T + 3e-4 * rng.standard_normal((n, LAYOUT.n_gyros))


def _learned(est) -> dict:
    return {k: v for k, v in vars(est).items() if k.endswith("_") and not k.startswith("_")}


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape
                and np.array_equal(a, b))
    return type(a) is type(b) and a == b


@pytest.fixture(params=NAMES)
def cls(request):
    return get_estimator(request.param)


def test_registry_lists_the_builtins():
    assert {"kf_array", "kf_single", "ols", "gls", "naive", "bound"} <= set(NAMES)


def test_class_metadata(cls):
    assert issubclass(cls, Estimator)
    assert cls.name in NAMES and cls.name.isidentifier()
    assert isinstance(cls.description, str) and cls.description and "\n" not in cls.description


def test_init_only_stores(cls):
    default = cls()
    params = default.get_params()
    assert not _learned(default), "__init__ must not create learned (…_) attributes"
    assert set(vars(default)) == set(params), "__init__ must store exactly its hyperparameters"
    # passing the defaults back stores them unchanged (identity, not copies)
    sentinel = {k: object() for k in params}
    est = cls(**sentinel)
    for k, v in sentinel.items():
        assert getattr(est, k) is v


def test_get_set_params_round_trip(cls):
    est = cls()
    params = est.get_params()
    clone = cls().set_params(**params)
    assert clone.get_params() == params
    assert cls(**params).get_params() == params
    with pytest.raises(InputError, match="unknown hyperparameter"):
        est.set_params(no_such_parameter=1)


def test_fit_returns_self_and_is_idempotent(cls):
    est = cls()
    assert est.fit(LAYOUT, MODEL, DT) is est
    first = _learned(est)
    assert first, "fit must learn something"
    est.fit(LAYOUT, MODEL, DT)
    second = _learned(est)
    assert first.keys() == second.keys()
    for k in first:
        assert _same(first[k], second[k]), k
    assert est.n_gyros_ == LAYOUT.n_gyros and est.dt_s_ == DT
    cov = est.covariance_
    assert cov is None or (cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(cov) > 0))


def test_estimate_shape_and_determinism(cls):
    est = cls().fit(LAYOUT, MODEL, DT)
    z = _readings()
    out = est.estimate(z)
    assert out.shape == (z.shape[0], 3) and out.dtype == np.float64
    assert np.all(np.isfinite(out))
    again = cls().fit(LAYOUT, MODEL, DT).estimate(z.copy())
    assert np.array_equal(out, again)                 # same input -> same bits
    assert np.array_equal(est.estimate(z[:1]).shape, (1, 3))
    assert np.array_equal(est.estimate(z.tolist()), out)


@pytest.mark.parametrize("bad", ["wrong_n", "one_d", "three_d", "nan", "inf", "empty", "text"])
def test_bad_readings_refused(cls, bad):
    est = cls().fit(LAYOUT, MODEL, DT)
    z = _readings(20)
    cases = {"wrong_n": z[:, :-1], "one_d": z[:, 0], "three_d": z[None], "empty": z[:0],
             "text": [["a"] * LAYOUT.n_gyros]}
    if bad in ("nan", "inf"):
        z = z.copy()
        z[5, 2] = np.nan if bad == "nan" else -np.inf
        cases[bad] = z
    with pytest.raises(InputError):
        est.estimate(cases[bad])


def test_unfitted_refused(cls):
    with pytest.raises(NotFittedError, match="not fitted"):
        cls().estimate(_readings(10))


def test_bad_fit_inputs_refused(cls):
    with pytest.raises(InputError):
        cls().fit(LAYOUT, MODEL, 0.0)
    with pytest.raises(InputError):
        cls().fit(LAYOUT, MODEL, float("nan"))
    with pytest.raises(InputError):
        cls().fit(LAYOUT.H, MODEL, DT)
    no_arw = NoiseModel((ModelEntry("rrw", None, {"k_deg_h_rt_h": 600.0}),))
    with pytest.raises(InputError, match="arw"):
        cls().fit(LAYOUT, no_arw, DT)


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
