"""The estimator contract as plain checks (run by :func:`gyroarray.chain.testing.check_estimator`).

Each check takes the Estimator class and raises ``AssertionError`` when the
class breaks the contract (scikit-learn's estimator checks, for fusion
estimators): ``__init__`` only stores its hyperparameters, ``get_params`` /
``set_params`` round-trip and refuse unknown names, ``fit`` returns ``self``
and is idempotent, ``estimate`` gives (n, 3) finite float64 with the same
bits for the same input, bad readings and bad fit inputs are refused with
:class:`~gyroarray.core.errors.InputError`, an unfitted estimator refuses to
estimate.
"""

from __future__ import annotations

import numpy as np

from gyroarray.core.errors import InputError
from gyroarray.estimators import Estimator, NotFittedError
from gyroarray.core.layout import Layout

__all__ = ["CHECKS", "DT", "LAYOUT", "model", "readings"]

DT = 0.01
LAYOUT = Layout.conical(2, 5, np.deg2rad(65.9))


def _names() -> tuple[str, str, str]:
    """The names of the white-noise, random-walk and correlation effects (their classes say)."""
    # lazy: loads gyroarray.effects and its plugins
    from gyroarray.effects.arw import AngleRandomWalk
    from gyroarray.effects.correlation import Correlation
    from gyroarray.effects.rrw import RateRandomWalk
    return AngleRandomWalk.name, RateRandomWalk.name, Correlation.name


def model():
    """A model with unequal ARW, RRW and correlated noise: what every estimator must accept."""
    from gyroarray.effects.model import ModelEntry, NoiseModel  # lazy: loads gyroarray.effects and its plugins
    white, walk, corr = _names()
    return NoiseModel((ModelEntry(white, None, {"n_deg_rt_h": 0.1}),
                       ModelEntry(white, 3, {"n_deg_rt_h": 0.2}),
                       ModelEntry(walk, None, {"k_deg_h_rt_h": 600.0}),
                       ModelEntry(corr, None, {"rho_arw": 0.1, "rho_rrw": 0.05})))


def readings(n=300, seed=7):
    """Readings of LAYOUT under a slowly varying rate, with white noise [rad/s]."""
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


def _raises(exc, fn, *args, match: str | None = None, what: str = ""):
    try:
        fn(*args)
    except exc as err:
        if match is not None:
            assert match in str(err), f"{what}: the message {str(err)!r} does not say {match!r}"
        return
    raise AssertionError(f"{what}: no {exc.__name__} raised")


def check_class_metadata(cls):
    assert issubclass(cls, Estimator), "not a gyroarray.estimators.Estimator"
    assert isinstance(cls.name, str) and cls.name.isidentifier(), (
        f"the class's registry name is {cls.name!r}, not an identifier: decorate it with "
        "@gyroarray.estimators.register('my_name') (which sets it) or set name = 'my_name' on the "
        "class; --estimators, sweep files and the entry-point group gyroarray.estimators use it")
    assert isinstance(cls.description, str) and cls.description and "\n" not in cls.description, \
        "description must be one non-empty line"


def check_init_only_stores(cls):
    default = cls()
    params = default.get_params()
    assert not _learned(default), "__init__ must not create learned (…_) attributes"
    assert set(vars(default)) == set(params), "__init__ must store exactly its hyperparameters"
    sentinel = {k: object() for k in params}
    est = cls(**sentinel)
    for k, v in sentinel.items():
        assert getattr(est, k) is v, f"__init__ must store {k} as given"


def check_get_set_params_round_trip(cls):
    est = cls()
    params = est.get_params()
    assert cls().set_params(**params).get_params() == params, "set_params(get_params()) changed them"
    assert cls(**params).get_params() == params, "cls(**get_params()) changed them"
    try:
        est.set_params(no_such_parameter=1)
    except InputError as err:
        assert "unknown hyperparameter" in str(err), f"set_params refused with {err!r}"
    else:
        raise AssertionError("set_params(no_such_parameter=1) was accepted")


def check_fit_returns_self_and_is_idempotent(cls):
    m = model()
    est = cls()
    assert est.fit(LAYOUT, m, DT) is est, "fit must return self"
    first = _learned(est)
    assert first, "fit must learn something"
    est.fit(LAYOUT, m, DT)
    second = _learned(est)
    assert first.keys() == second.keys(), "a second fit learned other attributes"
    for k in first:
        assert _same(first[k], second[k]), f"a second fit changed {k}"
    assert est.n_gyros_ == LAYOUT.n_gyros and est.dt_s_ == DT, "n_gyros_ / dt_s_ not learned"
    cov = est.covariance_
    assert cov is None or (cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(cov) > 0)), \
        "covariance_ must be None or a 3x3 positive-definite matrix"


def check_estimate_shape_and_determinism(cls):
    m = model()
    est = cls().fit(LAYOUT, m, DT)
    z = readings()
    out = est.estimate(z)
    assert out.shape == (z.shape[0], 3) and out.dtype == np.float64, "estimate must be (n, 3) float64"
    assert np.all(np.isfinite(out)), "estimate must be finite"
    again = cls().fit(LAYOUT, m, DT).estimate(z.copy())
    assert np.array_equal(out, again), "the same input must give the same bits"
    assert est.estimate(z[:1]).shape == (1, 3), "one sample must give (1, 3)"
    assert np.array_equal(est.estimate(z.tolist()), out), "a list must give the same as an array"


def check_bad_readings_refused(cls):
    est = cls().fit(LAYOUT, model(), DT)
    z = readings(20)
    nan, inf = z.copy(), z.copy()
    nan[5, 2], inf[5, 2] = np.nan, -np.inf
    cases = {"wrong number of gyros": z[:, :-1], "1-D": z[:, 0], "3-D": z[None], "empty": z[:0],
             "text": [["a"] * LAYOUT.n_gyros], "NaN": nan, "inf": inf}
    for what, bad in cases.items():
        _raises(InputError, est.estimate, bad, what=f"estimate({what} readings)")


def check_unfitted_refused(cls):
    _raises(NotFittedError, cls().estimate, readings(10), match="not fitted", what="estimate before fit")


def check_bad_fit_inputs_refused(cls):
    from gyroarray.effects.model import ModelEntry, NoiseModel  # lazy: loads gyroarray.effects and its plugins
    m = model()
    _raises(InputError, cls().fit, LAYOUT, m, 0.0, what="fit with dt = 0")
    _raises(InputError, cls().fit, LAYOUT, m, float("nan"), what="fit with dt = NaN")
    _raises(InputError, cls().fit, LAYOUT.H, m, DT, what="fit with an array instead of a Layout")
    white, walk, _ = _names()
    no_arw = NoiseModel((ModelEntry(walk, None, {"k_deg_h_rt_h": 600.0}),))
    if getattr(cls, "needs_arw", True):
        _raises(InputError, cls().fit, LAYOUT, no_arw, DT, match=white, what="fit with a model without ARW")
    else:   # an estimator of the layout alone (ols, naive) runs on a model without white noise
        assert cls().fit(LAYOUT, no_arw, DT).estimate(readings(10)).shape == (10, 3), \
            "needs_arw = False, but a fit with a model without ARW does not estimate"


#: (name, check) in order.
CHECKS = [(fn.__name__.removeprefix("check_"), fn) for fn in (
    check_class_metadata, check_init_only_stores, check_get_set_params_round_trip,
    check_fit_returns_self_and_is_idempotent, check_estimate_shape_and_determinism,
    check_bad_readings_refused, check_unfitted_refused, check_bad_fit_inputs_refused)]
