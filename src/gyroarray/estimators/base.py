"""The estimator contract (scikit-learn's) and the estimator registry.

An estimator turns the readings of a gyro array into body rates:

* ``__init__`` only stores its keyword hyperparameters, unchanged;
* ``fit(layout, noise_model, dt_s)`` designs the gains or weights for a
  layout, a noise model and a sample period and returns ``self``; what it
  learns ends in ``_`` (``gain_``, ``weights_``, ``covariance_``);
* ``estimate(readings_rad_s)`` maps readings (n, N) [rad/s] to body rates
  (n, 3) [rad/s] and refuses wrong shapes, NaN, inf and an unfitted
  estimator with :class:`~gyroarray.core.errors.InputError`.

Every estimator has a short ``name`` and a one-line ``description``. The
registry holds the built-in estimators (registered with :func:`register`)
and third-party ones, declared as entry points of the group
``gyroarray.estimators`` (``name = "package.module:Class"``) and imported
only when asked for by :func:`get_estimator`; a plugin that fails to import
gives an :class:`~gyroarray.core.errors.InputError` naming it, and the other
estimators keep working.

Learned attributes shared by every estimator:

``n_gyros_`` (int), ``dt_s_`` [s], ``H_`` (N, 3) [-], ``noise_``
(:class:`~gyroarray.estimators.noise.ArrayNoise`) and ``covariance_``: the
steady-state 3×3 covariance [rad²/s²] of the body-rate error caused by the
white (ARW) measurement noise of the fitted model, for a known deterministic
body rate; ``None`` where the estimator has no such steady state.
"""

from __future__ import annotations

import importlib
import inspect
import math
from dataclasses import dataclass
from importlib import metadata
from typing import Any, Callable, TypeVar

import numpy as np

from gyroarray.core.gdop import unobservable_reason
from gyroarray.core.errors import InputError
from gyroarray.estimators.noise import ArrayNoise, array_noise
from gyroarray.core.layout import Layout
from gyroarray.core.plugins import ESTIMATORS_GROUP

__all__ = ["Estimator", "NotFittedError", "LinearSystem", "DesignTags", "register", "get_estimator",
           "available", "make", "ENTRY_POINT_GROUP", "unobservable_reason"]

#: Entry-point group of third-party estimators.
ENTRY_POINT_GROUP = ESTIMATORS_GROUP

_BUILTIN: dict[str, type] = {}
_LOADED_PLUGINS: dict[str, type] = {}
_BUILTIN_MODULES = ("simple", "kf_array", "kf_single", "bound", "fdi", "svo")


class NotFittedError(InputError):
    """``estimate`` was called before ``fit``."""


@dataclass(frozen=True, eq=False)
class LinearSystem:
    """A fitted linear estimator as a discrete state-space filter.

    x̂_k = A x̂_{k-1} + K z_k,  ω̂_k = C x̂_k,  x̂_{-1} = X0 z_0

    with A diagonalised as A = S diag(lam) S⁻¹ (an estimator's eigenvalues are
    real in [0, 1]; cascaded with a sensor's Butterworth filter,
    :func:`gyroarray.design.predict.cascade`, a complex pair joins them; the
    eigenvalue-1 modes of a Kalman filter with bias states are the
    unobservable directions, which K does not drive).

    Attributes
    ----------
    A : ndarray, shape (D, D)
    K : ndarray, shape (D, N)
        Input gain [-].
    C : ndarray, shape (3, D)
        Output map [-].
    X0 : ndarray, shape (D, N)
        Start: x̂_{-1} = X0 z_0 [-].
    lam : ndarray, shape (D,)
        Eigenvalues of A [-].
    S, S_inv : ndarray, shape (D, D)
        Eigenvectors of A (columns) and the inverse [-].
    """

    A: np.ndarray
    K: np.ndarray
    C: np.ndarray
    X0: np.ndarray
    lam: np.ndarray
    S: np.ndarray
    S_inv: np.ndarray

    @property
    def dim(self) -> int:
        return int(self.A.shape[0])

    def response(self, theta) -> np.ndarray:
        """Frequency response (len(theta), 3, N) from gyro readings to rate estimates at
        normalised angular frequencies θ = 2π f dt [rad] (the stable modes; θ > 0)."""
        th = np.atleast_1d(np.asarray(theta, dtype=float))
        cs = self.C @ self.S                                         # output of each mode
        bk = self.S_inv @ self.K                                     # input of each mode
        live = np.flatnonzero(np.max(np.abs(bk), axis=1) > 0.0)
        g = 1.0 / (1.0 - self.lam[live][None, :] * np.exp(-1j * th)[:, None])  # 1/(1 − λ e^{−jθ})
        return np.einsum("am,tm,mi->tai", cs[:, live], g, bk[live])

    def dc_gain(self) -> np.ndarray:
        """Gain (3, N) from slow changes of the readings to the rate estimates (θ → 0⁺)."""
        cs, bk = self.C @ self.S, self.S_inv @ self.K
        stable = np.abs(1.0 - self.lam) > 1e-12                      # all but the unit modes
        return np.real(cs[:, stable] @ (bk[stable] / (1.0 - self.lam[stable])[:, None]))



@dataclass(frozen=True)
class DesignTags:
    """What the design search (``gyroarray design --recommend``) needs to know of an estimator
    class, in the manner of scikit-learn's estimator tags (:meth:`Estimator.design_tags`).

    Attributes
    ----------
    linear_system : bool
        :meth:`Estimator.linear_system` gives the fitted estimator as a fixed linear filter:
        the accuracy predictor, hence the design search, can model it.
    weights : {"gls", "ols", "naive"} or None
        The closed-form per-sample weights its fused channel is built on (the array KF
        filters the GLS channel, the single-gyro KF the OLS channel); None: the weights are
        read from the fitted estimator, the DC gain (3, N) of its linear system, fitted on each
        layout the search tries (exact for a per-sample estimator).
    rho_weighted : bool
        Its weights depend on the gyros' correlation (the search then chooses a design ρ).
    bandwidth_param : str or None
        The hyperparameter that sets its bandwidth [Hz] (None: it has none; the search tries
        it unfiltered only).
    bandwidth_optional : bool
        The bandwidth hyperparameter may also be None (no filter): tried as well.
    channel_filter : {"none", "lowpass", "kf"}
        The filter on its fused channel in the design's fast channel model.
    bias_states : {"none", "array", "per_gyro"}
        Gyro-bias states: none; the array's N biases in one filter (they couple the axes after a
        failure or with reversed gyros, so the channel model only screens it); one filter per
        gyro (exact on alike gyros only).
    needs_rrw_for_bias_states : bool
        Its bias states need a rate random walk (without one it is built with
        ``bias_states=False``).
    rebuild : {"refit"}
        How it is rebuilt after a failed gyro: fitted again, for the design ρ, on the gyros left.
    """

    linear_system: bool = False
    weights: str | None = None
    rho_weighted: bool = True
    bandwidth_param: str | None = None
    bandwidth_optional: bool = False
    channel_filter: str = "none"
    bias_states: str = "none"
    needs_rrw_for_bias_states: bool = False
    rebuild: str = "refit"


#: An Estimator subclass (``fit`` returns the instance it was called on).
_E = TypeVar("_E", bound="Estimator")


class Estimator:
    """Base of every fusion estimator (scikit-learn's estimator contract).

    Subclasses declare their hyperparameters as keyword-only arguments of
    ``__init__``, store each under its own name and do nothing else, and
    implement ``_fit(H, noise, dt_s)`` and ``_estimate(z)``.
    """

    #: Short registry name.
    name: str = ""
    #: One-line description.
    description: str = ""
    #: Whether the estimator needs every gyro's white-noise level (``arw``) to be designed;
    #: False for estimators that only use the layout (``ols``, ``naive``), which then also run
    #: on a model without ARW (e.g. RRW only), with a zero white-noise covariance.
    needs_arw: bool = True
    #: Overrides of the :class:`DesignTags` this class declares (merged along the MRO by
    #: :meth:`design_tags`); a subclass states only what differs from its base.
    _design_tags: dict[str, Any] = {}

    @classmethod
    def design_tags(cls) -> DesignTags:
        """What the design search needs to know of this estimator (:class:`DesignTags`).

        The defaults: ``linear_system`` True when the class overrides
        :meth:`linear_system`; ``rho_weighted`` = :attr:`needs_arw` (an estimator that uses
        no noise model has weights without ρ); no bandwidth, no bias states, its weights
        read from the fitted linear system. Each class in the MRO may override them with a
        ``_design_tags`` dict.
        """
        kw: dict[str, Any] = {"linear_system": cls.linear_system is not Estimator.linear_system,
                              "rho_weighted": bool(cls.needs_arw)}
        for klass in reversed(cls.__mro__):
            kw.update(klass.__dict__.get("_design_tags", {}))
        return DesignTags(**kw)

    # -- hyperparameters (scikit-learn) ------------------------------------
    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values()
                if p.name != "self" and p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The hyperparameters as a dict (name -> value as passed)."""
        return {k: getattr(self, k) for k in self._param_names()}

    def set_params(self, **params) -> "Estimator":
        """Set hyperparameters; unknown names are refused with InputError.

        Returns ``self``. Learned attributes are left as they are: call
        :meth:`fit` again.
        """
        names = self._param_names()
        for key, value in params.items():
            if key not in names:
                raise InputError(_unknown(f"hyperparameter {key!r} of estimator {self.name!r}",
                                          key, names))
            setattr(self, key, value)
        return self

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    # -- fitting -------------------------------------------------------------
    def fit(self: _E, layout: Layout, noise_model, dt_s: float) -> _E:
        """Design the estimator for a layout, a noise model and a sample period.

        Parameters
        ----------
        layout : Layout
            Sensitive axes H (N×3) [-].
        noise_model : NoiseModel or ArrayNoise
            The noise of the array (only ``arw``, ``rrw`` and ``correlation``
            are used; see :func:`~gyroarray.estimators.noise.array_noise`).
        dt_s : float
            Sample period [s].

        Returns
        -------
        self
        """
        if not isinstance(layout, Layout):
            raise InputError(f"layout must be a gyroarray Layout, got {type(layout).__name__}")
        h = np.array(layout.H, dtype=float)
        why = unobservable_reason(h)
        if why is not None:
            raise InputError(f"{layout.name}: {why}; no estimator can recover a 3-axis rate")
        try:
            dt = float(dt_s)
        except (TypeError, ValueError):
            raise InputError(f"dt_s must be a number [s], got {dt_s!r}") from None
        if not (math.isfinite(dt) and dt > 0):
            raise InputError(f"dt_s must be a finite period > 0 [s], got {dt_s!r}")
        n = h.shape[0]
        if isinstance(noise_model, ArrayNoise):
            if noise_model.n_gyros != n:
                raise InputError(f"the noise is for {noise_model.n_gyros} gyros, the layout has {n}")
            noise = noise_model
        else:
            noise = array_noise(noise_model, n, require_arw=self.needs_arw)
        for key in [k for k in vars(self) if k.endswith("_") and not k.startswith("_")]:
            delattr(self, key)
        self._fit(h, noise, dt)
        self.n_gyros_ = n
        self.dt_s_ = dt
        self.H_ = readonly(h)
        self.noise_ = noise
        return self

    def _fit(self, H: np.ndarray, noise, dt_s: float) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    # -- estimating ----------------------------------------------------------
    def estimate(self, readings_rad_s) -> np.ndarray:
        """Body rates from gyro readings.

        Parameters
        ----------
        readings_rad_s : array_like, shape (n, N)
            Gyro outputs [rad/s], one row per sample, one column per gyro.

        Returns
        -------
        ndarray, shape (n, 3)
            Body rate estimates [rad/s].

        Raises
        ------
        NotFittedError
            Before :meth:`fit`.
        InputError
            Not a 2-D (n, N) array of finite numbers with n >= 1.
        """
        self._check_fitted()
        z = check_readings(readings_rad_s, self.n_gyros_)
        return self._estimate(z)

    def _estimate(self, z: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def linear_system(self) -> LinearSystem:
        """The fitted estimator as a :class:`LinearSystem` (for the accuracy predictor).

        Raises
        ------
        InputError
            The estimator is not a fixed linear filter (e.g. the offline bound).
        """
        self._check_fitted()
        raise InputError(f"estimator {self.name!r} is not a fixed linear filter: the accuracy "
                         "predictor cannot model it")

    def _check_fitted(self) -> None:
        if not hasattr(self, "n_gyros_"):
            raise NotFittedError(f"estimator {self.name!r} is not fitted: call "
                                 "fit(layout, noise_model, dt_s) first")


def check_readings(readings, n_gyros: int) -> np.ndarray:
    """Readings as a C-contiguous float (n, N) array, or InputError."""
    try:
        z = np.asarray(readings, dtype=float)
    except (TypeError, ValueError):
        raise InputError("readings must be a numeric (n, N) array [rad/s]") from None
    if z.ndim != 2:
        raise InputError(f"readings must be a 2-D (n, N) array, got {z.ndim}-D shape {z.shape}")
    if z.shape[1] != n_gyros:
        raise InputError(f"readings have {z.shape[1]} columns, the fitted layout has "
                         f"{n_gyros} gyros")
    if z.shape[0] < 1:
        raise InputError("readings have no samples")
    if not np.all(np.isfinite(z)):
        bad = np.argwhere(~np.isfinite(z))[0]
        raise InputError(f"readings contain a non-finite value (sample {int(bad[0])}, gyro "
                         f"{int(bad[1]) + 1}: {z[bad[0], bad[1]]!r})")
    return np.ascontiguousarray(z)


def readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def _unknown(what: str, key, names) -> str:
    from gyroarray.effects import did_you_mean  # lazy: loads gyroarray.effects and its plugins
    return f"unknown {what}{did_you_mean(key, names)} (known: {', '.join(names) or 'none'})"


# -- registry -----------------------------------------------------------------

def register(name: str) -> Callable[[type], type]:
    """Class decorator: register an estimator class under ``name``.

    The class must subclass :class:`Estimator`; its ``name`` attribute is set
    to ``name``. A name can be registered once.
    """
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"estimator name must be an identifier, got {name!r}")

    def deco(cls: type) -> type:
        if not (isinstance(cls, type) and issubclass(cls, Estimator)):
            raise TypeError(f"{cls!r} is not an Estimator subclass")
        if name in _BUILTIN and _BUILTIN[name] is not cls:
            raise ValueError(f"estimator {name!r} is already registered "
                             f"({_BUILTIN[name].__module__}.{_BUILTIN[name].__qualname__})")
        if not getattr(cls, "description", ""):
            raise ValueError(f"estimator {name!r} needs a one-line description")
        cls.name = name
        _BUILTIN[name] = cls
        return cls
    return deco


def unregister(name: str) -> None:
    """Take an estimator a plugin file registered out of the registry again (a failed
    conformance check); the built-ins are left alone."""
    cls = _BUILTIN.get(name)
    if cls is not None and not cls.__module__.startswith("gyroarray."):
        del _BUILTIN[name]


def _load_builtins() -> None:
    for mod in _BUILTIN_MODULES:
        importlib.import_module(f"{__package__}.{mod}")


def _entry_points() -> dict[str, metadata.EntryPoint]:
    try:
        eps = metadata.entry_points(group=ENTRY_POINT_GROUP)
    except Exception:  # broken distribution metadata must not break the built-ins
        return {}
    return {ep.name: ep for ep in eps}


def available() -> list[str]:
    """Names of the built-in estimators and of the installed plugins (sorted).

    Plugins are listed from their entry points without being imported.
    """
    _load_builtins()
    return sorted(set(_BUILTIN) | set(_entry_points()))


def get_estimator(name: str) -> type:
    """The estimator class registered as ``name``.

    Raises
    ------
    InputError
        Unknown name (with the closest one), or a plugin that fails to load
        or is not an :class:`Estimator` (naming the entry point).
    """
    _load_builtins()
    if name in _BUILTIN:
        return _BUILTIN[name]
    if name in _LOADED_PLUGINS:
        return _LOADED_PLUGINS[name]
    eps = _entry_points()
    if name not in eps:
        raise InputError(_unknown(f"estimator {name!r}", name, available()))
    ep = eps[name]
    try:
        cls = ep.load()
    except Exception as err:  # any import-time failure of a plugin
        raise InputError(f"estimator plugin {name!r} ({ep.value}, entry point group "
                         f"{ENTRY_POINT_GROUP!r}) failed to load: {type(err).__name__}: {err}") from err
    if not (isinstance(cls, type) and issubclass(cls, Estimator)):
        raise InputError(f"estimator plugin {name!r} ({ep.value}) is not a "
                         "gyroarray.estimators.Estimator subclass")
    if not getattr(cls, "description", ""):
        raise InputError(f"estimator plugin {name!r} ({ep.value}) has no description")
    cls.name = name
    _LOADED_PLUGINS[name] = cls
    return cls


def make(name: str, **params) -> Estimator:
    """An estimator by name with hyperparameters; unknown ones refused with InputError."""
    cls = get_estimator(name)
    return cls().set_params(**params)
