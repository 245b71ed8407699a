"""The effect protocol: what one physical effect is, for the simulator and for the fitter.

An effect of ``shared/spec/effects.md`` is one :class:`Effect` object, in one
module of the ``gyroarray.effects`` package (or of a plugin: an installed
package's ``gyroarray.effects`` entry point, or a file given with
``--plugin``). The object owns

* its spec name and parameters (:class:`Param`: units, bounds, the named
  converter to SI);
* ``needs``: which inputs it requires (:data:`NEEDS`);
* its ``kind`` (:class:`Kind`): per-gyro stochastic, deterministic,
  array-wide, or time;
* ``simulate``: its stage in the chain (:class:`Stage`) and a pure function
  of the chain's state;
* its fit side: :meth:`Effect.fit` estimates its parameters on a residual
  (:class:`FitContext` carries the record and the calibrated noise) and
  returns an :class:`~gyroarray.effects.fitting.EffectFit` whose ``z`` is
  ≈ N(0, 1) when the effect is absent; :meth:`Effect.test` is the candidate
  test when the model does not have it;
* how it enters the calibrated model: :meth:`Effect.predict` (what a
  deterministic effect adds to the outputs), :meth:`Effect.noise_term` (the
  term a per-gyro noise effect adds to the Allan model), ``stochastic`` (it is
  simulated in the model's Monte-Carlo band), :meth:`Effect.exclude` and
  :meth:`Effect.whiten` (samples the regressions leave out, a record brought
  back to the model's white level), ``static_noise``;
* its rivals: ``rivals`` names the effects that explain the same excess, and
  :meth:`Effect.prefer` says when it fits that excess better (AIC of the two
  fits by default).

The orchestrator (:class:`gyroarray.chain.compare.ModelComparison`) loops over the
registry and never names an effect. Units: SI inside; spec units only in
``EffectFit.params`` and in models.
"""

from __future__ import annotations

import enum
import functools
import math
import zlib
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Mapping, Sequence

import numpy as np

from gyroarray.analysis.memo import freeze
from gyroarray.core.errors import InputError
from gyroarray.core.formatting import sig
from gyroarray.core.sensor import rigid_body_specific_force

if TYPE_CHECKING:                                    # pragma: no cover - types only
    from gyroarray.effects.fitting import EffectFit
    from gyroarray.effects.model import ModelEntry, NoiseModel
    from gyroarray.effects.terms import PredictorTerm

__all__ = ["Stage", "Kind", "NEEDS", "RECORD_NEEDS", "Param", "Effect", "SimContext", "ChainState", "Active", "Mixer",
           "SIM_NEEDS", "WhiteShaping", "Streams", "FitContext", "RegressionEffect", "NoiseTermEffect", "same_noise_preference",
           "explains_away", "no_longer_seen", "kept_prediction", "drop_kept", "KeptPrediction", "Explained", "terminal_cut", "with_term", "with_cols", "unit_draws", "identity"]

#: What an effect may need from a record: the reference rates, a part where the
#: table turns, the temperature, the site (heading), the specific force (``acc_*``
#: or gravity through the attitude), a static part, the gyro positions.
NEEDS = ("ref", "motion", "temp", "site", "acc", "static", "positions")

#: The part of :data:`NEEDS` that is data a record holds or lacks (columns, sidecar
#: tables), which a model entry may need (``Effect.model_needs``, ``Effect.predict_needs``).
RECORD_NEEDS = ("ref", "temp", "site", "acc", "positions")

#: What an effect's ``simulate`` may read from :class:`SimContext` beyond the rates
#: (``Effect.sim_needs``): the temperature (``temp_c``), the site, the platform attitude,
#: the specific force at the gyros (gravity through the attitude unless the truth gives it).
SIM_NEEDS = ("temp", "site", "attitude", "acc")


def identity(x):
    """The converter of a parameter already in SI."""
    return x



class Stage(enum.IntEnum):
    """Position of an effect in the chain (module docstring).

    ``simulate(state, act, streams) -> state`` has the same signature at
    every stage; what it may change does not:

    SENSE     ``state.axes`` (true axes) or ``state.frame_rate`` (extra
              platform-frame rate, n×3)
    DELAY     ``state.x`` columns of its gyros (sensed input)
    SCALE     adds a term computed from ``state.u`` (the stage's input)
    SHAPE     ``state.white`` (mixing / gain of the ARW and RRW draws)
    ADD       adds a term to ``state.x``
    FILTER    ``state.x`` columns: the sensor's own response (``bandwidth``)
              to everything above
    QUANTIZE  ``state.x`` columns (output)
    SATURATE  ``state.x`` columns (output)
    FAULT     ``state.x`` columns: what a failed gyro outputs instead of, or
              on top of, its normal output
    """

    SENSE = 1
    DELAY = 2
    SCALE = 3
    SHAPE = 4
    ADD = 5
    FILTER = 6
    QUANTIZE = 7
    SATURATE = 8
    FAULT = 9


class Kind(str, enum.Enum):
    """How an effect shows in a record, and so how the fitter treats it."""

    NOISE = "per-gyro stochastic"       # a term of one gyro's Allan/PSD model
    DETERMINISTIC = "deterministic"     # a regression column / prediction on the residual
    ARRAY = "array-wide"                # one effect of the whole array
    TIME = "time"                       # localised in time (a window, an onset)


@dataclass(frozen=True)
class Param:
    """One parameter of an effect.

    Attributes
    ----------
    name : str
        Key in TOML, CLI and JSON, exactly as in ``shared/spec/effects.md``.
    unit : str
        Unit of the value the user writes.
    si_name : str
        Key of the converted value handed to ``simulate``.
    to_si : callable
        Named converter from ``unit`` to SI.
    kind : {"scalar", "axis", "vector", "rho", "flag"}
        A real number; a unit 3-vector; any finite 3-vector; a scalar or N×N
        correlation matrix; a boolean.
    lo, hi : float
        Bounds of a scalar (inclusive unless ``lo_open`` / ``hi_open``).
    required : bool
        Must be given (else ``default`` is used; ``None`` = "absent").
    default : object
        Value (in ``unit``) when not given.
    extension : bool
        Not (yet) in ``shared/spec/effects.md``; a documented addition.
    doc : str
        One line for messages and docs.
    """

    name: str
    unit: str
    si_name: str
    to_si: Callable[[Any], Any]
    kind: str = "scalar"
    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False
    required: bool = True
    default: Any = None
    extension: bool = False
    doc: str = ""

    def bounds_text(self) -> str:
        """The admissible range in words, e.g. ``>= 0`` or ``in [-90, 90]``."""
        lo = "" if self.lo == -math.inf else ("> " if self.lo_open else ">= ") + f"{self.lo:g}"
        hi = "" if self.hi == math.inf else ("< " if self.hi_open else "<= ") + f"{self.hi:g}"
        return " and ".join(s for s in (lo, hi) if s) or "any finite number"


@dataclass(frozen=True, eq=False)
class SimContext:
    """The inputs of one run (read-only arrays).

    Attributes
    ----------
    omega_body_rad_s : ndarray, shape (n, 3)
        True rate of the platform relative to the Earth, platform frame [rad/s].
    axes : ndarray, shape (N, 3)
        Nominal unit sensitive axes (the layout's ``H``) [-].
    dt_s : float
        Sample step [s].
    time_s : ndarray, shape (n,)
        Sample times [s].
    attitude : ndarray, shape (n, 3, 3), or None
        Platform -> local-level rotation matrices [-].
    temp_c : ndarray, shape (n,), or None
        Temperature at the array [°C].
    site : tuple (latitude_rad, heading_rad) or None
        Where the table stands [rad].
    specific_force_origin_m_s2 : ndarray, shape (n, 3)
        Specific force at the platform origin, platform frame [m/s²]: the
        truth's (MuJoCo accelerometer) when given, else gravity through the
        attitude, Rᵀ[0, 0, g0] (level when ``attitude`` is None).
    angular_accel_rad_s2 : ndarray, shape (n, 3)
        Angular acceleration dω/dt, platform frame [rad/s²]: the truth's when
        given, else central differences of ``omega_body_rad_s``
        (``numpy.gradient``).
    positions_m : ndarray, shape (N, 3)
        Gyro positions, platform frame [m] (zero when the layout has none).
    specific_force_m_s2 : ndarray, shape (n, N, 3)
        (property, computed on first use) the specific force at each gyro,
        f_k = f_0 + α × r_k + ω × (ω × r_k) [m/s²].
    """

    omega_body_rad_s: np.ndarray
    axes: np.ndarray
    dt_s: float
    time_s: np.ndarray
    attitude: np.ndarray | None = None
    temp_c: np.ndarray | None = None
    site: tuple[float, float] | None = None
    specific_force_origin_m_s2: np.ndarray | None = None
    angular_accel_rad_s2: np.ndarray | None = None
    positions_m: np.ndarray | None = None

    @functools.cached_property
    def specific_force_m_s2(self) -> np.ndarray:
        """Specific force at each gyro (n, N, 3) [m/s²] (see the class notes)."""
        a = rigid_body_specific_force(self.specific_force_origin_m_s2, self.omega_body_rad_s,
                                      self.angular_accel_rad_s2, self.positions_m)
        a = np.array(a, dtype=float, copy=True)
        a.setflags(write=False)
        return a

    @property
    def n(self) -> int:
        """Number of samples n."""
        return int(self.omega_body_rad_s.shape[0])

    @property
    def n_gyros(self) -> int:
        """Number of gyros N."""
        return int(self.axes.shape[0])


@dataclass(frozen=True, eq=False)
class Mixer:
    """How unit-variance draws of one white family (ARW or RRW) are correlated.

    Either ``chol`` (lower Cholesky factor L of the N×N correlation matrix C:
    e = L z, so cov(e) = C) or common mode (``common_rho`` ρ and the shared
    unit draws ``common`` c: e_k = √ρ c + √(1−ρ) z_k, so cov(e) = (1−ρ)I + ρ11ᵀ).
    """

    chol: np.ndarray | None = None
    common_rho: float | None = None
    common: np.ndarray | None = None

    @property
    def needs_all_gyros(self) -> bool:
        """Cholesky mixing needs the draws of every gyro."""
        return self.chol is not None

    def apply(self, z: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Correlated draws (n, m) of gyros ``cols`` from iid draws ``z``.

        ``z`` is (n, N) (all gyros) for Cholesky, (n, m) (the gyros ``cols``)
        for common mode.
        """
        if self.chol is not None:
            return (z @ self.chol.T)[:, cols]                      # e = L z, per sample
        r, common = self.common_rho, self.common
        assert r is not None and common is not None        # common mode when not Cholesky
        return math.sqrt(r) * common[:, None] + math.sqrt(1.0 - r) * z


@dataclass(frozen=True, eq=False)
class WhiteShaping:
    """Modifiers of the white sources, set by ``correlation`` and ``burst``.

    Attributes
    ----------
    arw, rrw : Mixer or None
        Cross-gyro mixing of the ARW draws / RRW increments (None: independent).
    arw_gain : ndarray, shape (n,), or None
        Factor on the ARW noise over time (√variance_ratio inside a burst).
    """

    arw: Mixer | None = None
    rrw: Mixer | None = None
    arw_gain: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class ChainState:
    """What the chain has computed so far (see :class:`Stage`).

    Attributes
    ----------
    ctx : SimContext
    axes : ndarray, shape (N, 3)
        True sensitive axes [-].
    frame_rate : ndarray, shape (n, 3)
        Rate added to the table's rate before sensing (Earth rate),
        platform frame [rad/s].
    x : ndarray, shape (n, N), or None
        The signal [rad/s]: None before sensing.
    u : ndarray, shape (n, N), or None
        Input of the SCALE stage [rad/s].
    white : WhiteShaping
    """

    ctx: SimContext
    axes: np.ndarray
    frame_rate: np.ndarray
    x: np.ndarray | None = None
    u: np.ndarray | None = None
    white: WhiteShaping = WhiteShaping()


@dataclass(frozen=True, eq=False)
class Active:
    """One effect resolved for a run.

    Attributes
    ----------
    cols : ndarray of int, shape (m,)
        0-based indices of the gyros it acts on (all gyros for array-wide).
    p : Mapping[str, ndarray or object]
        SI parameters by ``Param.si_name``. Per-gyro effects: arrays whose
        first axis runs over ``cols`` (NaN where an optional parameter is
        absent). Array-wide effects: the values themselves.
    label : str
        Where it comes from, for messages: ``effects[2] (latency)``.
    """

    cols: np.ndarray
    p: Mapping[str, Any]
    label: str


@dataclass(frozen=True)
class Streams:
    """The keyed random streams of one run (module docstring, Randomness).

    Attributes
    ----------
    root : tuple of int
        Four 32-bit words drawn once from the caller's Generator.
    bit_generator : type
        Bit-generator class of the caller's Generator.
    """

    root: tuple[int, ...]
    bit_generator: type

    @classmethod
    def from_rng(cls, rng: np.random.Generator) -> "Streams":
        """Draw the root entropy (4 words) from ``rng``."""
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        words = rng.integers(0, 2**32, size=4, dtype=np.uint64)
        return cls(root=tuple(int(w) for w in words), bit_generator=type(rng.bit_generator))

    def stream(self, effect: str, gyro: int, source: int = 0) -> np.random.Generator:
        """The Generator of ``effect`` on ``gyro`` (1-based; 0 = array-wide)."""
        key = (zlib.crc32(effect.encode("ascii")), int(gyro), int(source))
        return np.random.Generator(self.bit_generator(np.random.SeedSequence(self.root, spawn_key=key)))

    def normals(self, effect: str, cols: Sequence[int] | np.ndarray, n: int) -> np.ndarray:
        """Independent standard normals (n, m): column j from gyro ``cols[j] + 1``'s stream."""
        out = np.empty((len(cols), n))
        for j, c in enumerate(cols):
            self.stream(effect, int(c) + 1).standard_normal(out=out[j])
        return out.T


def with_term(state: ChainState, cols: np.ndarray, term: np.ndarray) -> ChainState:
    assert state.x is not None                               # after sensing
    if len(cols) == state.x.shape[1]:                        # cols sorted, unique: every gyro
        return replace(state, x=state.x + term)
    x = state.x.copy()
    x[:, cols] += term
    return replace(state, x=x)


def with_cols(state: ChainState, cols: np.ndarray, values: np.ndarray) -> ChainState:
    assert state.x is not None                               # after sensing
    if len(cols) == state.x.shape[1]:
        return replace(state, x=np.ascontiguousarray(values))
    x = state.x.copy()
    x[:, cols] = values
    return replace(state, x=x)


def unit_draws(effect: str, mixer: Mixer | None, cols: np.ndarray, n: int, n_gyros: int,
                streams: Streams) -> np.ndarray:
    """Unit-variance draws (n, m) of a white family, correlated by ``mixer``."""
    if mixer is None:
        return streams.normals(effect, cols, n)
    if mixer.needs_all_gyros:
        return mixer.apply(streams.normals(effect, np.arange(n_gyros), n), cols)
    return mixer.apply(streams.normals(effect, cols, n), cols)




# -- the effect ------------------------------------------------------------------

class Effect:
    """One physical effect: subclass it, set the class attributes, write ``simulate``.

    Class attributes
    ----------------
    name : str
        Spec name (``shared/spec/effects.md``), also the key in TOML, CLI, JSON.
    per_gyro : bool
        True: an entry may name one ``gyro`` (none = every gyro). False:
        array-wide, an entry must not name a gyro.
    params : tuple of Param
        In the spec's order.
    stage : Stage
        Where it acts in the chain.
    kind : Kind
        How it shows in a record (what its fit side reads).
    order : float
        Its place in listings and, within a stage, in the chain: the spec's
        table row for the built-ins (a plugin's goes after them by default).
    needs : frozenset of str
        Inputs of :data:`NEEDS` its fit side requires; without them it is not
        tested, and :meth:`why_not` says why.
    model_needs : frozenset of str
        Record data of :data:`RECORD_NEEDS` an entry of this effect in a
        given model needs to be calibrated on a record (its parameters
        fitted): ``compare``, ``diagnose``, ``fit`` and ``ladder`` refuse a
        model with such an entry on a record without it, before any work
        (:func:`gyroarray.chain.compare.check_record_needs`).
    predict_needs : frozenset of str
        The same for an entry whose parameters are kept fixed (``--validate``):
        what its prediction cannot do without. A record without a reference is
        analysed as static (its still parts), where an effect acting through
        the table's motion predicts nothing, so ``ref`` is rarely here.
    rivals : tuple of str
        Effects that explain the same excess in a record (ranked against it
        by :meth:`prefer`).
    baseline : bool
        Part of the baseline every model is calibrated with (``arw``, ``rrw``).
    baseline_term : {"white", "walk"} or None
        Which part of the baseline noise its one parameter is (for reports).
    candidate : bool
        Tested when the model lacks it (False: fitted only on request).
    stochastic : bool
        Simulated in the model's Monte-Carlo ADEV band.
    slow : bool
        A slow drift: its test is repeated with the random walk re-estimated
        without it (a real drift inflates the random walk that would hide it).
    static_noise : str or None
        With this effect in the model, the stochastic tests read the longest
        static part; the reason, for the notes.
    predicts : bool
        It adds a deterministic part to the outputs (:meth:`predict`); in a
        model it is backfitted with the other deterministic effects.
    lowpass : bool
        It is the library's causal low-pass: where the localisation finds a
        low-pass that does not lag on motion, the report says what this effect
        misses, and the ladder adds neither it nor its rivals there.
    refit_absolute : bool
        Its test on what the model's prediction leaves still measures the
        parameters themselves, not their error (a filter read from the noise
        spectrum, which no prediction removes): a validation compares the
        refit with the model's values.
    changes_adev : bool
        An array-wide effect that changes each gyro's own ADEV (a burst; not a
        correlation): when significant it explains every gyro's band.
    own_column : bool
        Its per-gyro test reads the residual (``E``) and the stochastic record
        (``Er``) only in its own gyro's column, the rest of the record only
        through what a cut record shares (the clock, the reference, the layout,
        the model, r and q): a record cut by another gyro's prediction leaves
        its test as it was, so :func:`explains_away` reads that test once per
        gyro instead of once per cut. False (the default) for any effect not
        checked so: a subclass whose test reads other columns must say False.
    reads : {"residual", "noise"}
        What its candidate test reads: the residual left by the model's
        deterministic part (the whole record), or the stochastic record (the
        static part when a deterministic effect is still unexplained).
    channel : str or None
        The record channel its residual follows (``rate``, ``other``,
        ``rate2``, ``accel``, ``temp``, ``time``, ``acc``), for the report.
    sim_needs : frozenset of str
        What its ``simulate`` reads from :class:`SimContext` beyond the rates
        (:data:`SIM_NEEDS`): a run generator makes these inputs for a model
        with such an entry (the lab builds the site and the attitude), and a
        scenario without a ``[temperature]`` table refuses an entry needing
        ``temp``.
    sweep_axes : tuple of str
        Parameters a sweep varies as axes of their own, among the sweep's
        axes (``gyroarray.sweep.sweep.PARAM_KEYS``: ``rho_arw``, ``rho_rrw``):
        a point's value replaces that parameter of the model's array-wide
        entry of this effect, one is added when the model has none.
    scored : tuple of str or None
        Parameters a fit recovers (None: all), for scoring.
    doc : str
        What it models, one sentence.
    """

    name: ClassVar[str] = ""
    per_gyro: ClassVar[bool] = True
    params: ClassVar[tuple[Param, ...]] = ()
    stage: ClassVar[Stage] = Stage.ADD
    kind: ClassVar[Kind] = Kind.DETERMINISTIC
    order: ClassVar[float] = 1000.0
    needs: ClassVar[frozenset] = frozenset()
    model_needs: ClassVar[frozenset] = frozenset()
    predict_needs: ClassVar[frozenset] = frozenset()
    sim_needs: ClassVar[frozenset] = frozenset()
    sweep_axes: ClassVar[tuple[str, ...]] = ()
    rivals: ClassVar[tuple[str, ...]] = ()
    baseline: ClassVar[bool] = False
    baseline_term: ClassVar[str | None] = None
    candidate: ClassVar[bool] = True
    stochastic: ClassVar[bool] = False
    slow: ClassVar[bool] = False
    static_noise: ClassVar[str | None] = None
    predicts: ClassVar[bool] = False
    refit_absolute: ClassVar[bool] = False
    lowpass: ClassVar[bool] = False
    reads: ClassVar[str] = "residual"
    changes_adev: ClassVar[bool] = False
    own_column: ClassVar[bool] = False
    channel: ClassVar[str | None] = None
    scored: ClassVar[tuple[str, ...] | None] = None
    doc: ClassVar[str] = ""

    def __repr__(self) -> str:
        return f"<effect {self.name}>"

    # -- parameters ------------------------------------------------------------
    @property
    def param_names(self) -> tuple[str, ...]:
        """Parameter names, spec order."""
        return tuple(p.name for p in self.params)

    def param(self, name: str) -> Param:
        """The parameter called ``name`` (KeyError if none)."""
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(name)

    def check(self, params: Mapping[str, Any], gyro: int | None, n_gyros: int | None) -> None:
        """Rules across parameters (``n_gyros`` None while the array size is unknown).

        Raises :class:`~gyroarray.core.errors.InputError` with ``column`` set to the
        offending key. The bounds of single parameters are checked before.
        """

    def check_run(self, params: Mapping[str, Any], sample_rate_hz: float, duration_s: float) -> None:
        """Rules a scenario entry's parameters [spec units] must meet in a simulated run of
        ``sample_rate_hz`` [Hz] lasting ``duration_s`` [s] (a frequency below Nyquist), checked
        when the scenario is read, before :meth:`check_record`.

        Raises :class:`~gyroarray.core.errors.InputError` with ``column`` set to the
        offending key, its message in the scenario's words; the default has no such rule.
        """

    def check_record(self, params: Mapping[str, Any], dt_s: float, span_s: float) -> None:
        """Rules a model entry's parameters [spec units] must meet on a record of sample step
        ``dt_s`` [s] and span ``span_s`` [s] (a cut-off below its Nyquist frequency), checked
        before any work on it (:func:`gyroarray.chain.compare.check_record_needs`).

        Raises :class:`~gyroarray.core.errors.InputError` with ``column`` set to the
        offending key; the default has no such rule.
        """

    def placeholder(self) -> dict:
        """Valid parameters [spec units] for an entry that a fit then overwrites."""
        out: dict[str, Any] = {}
        for p in self.params:
            if not p.required:
                continue
            if p.kind == "axis":
                out[p.name] = (0.0, 0.0, 1.0)
            elif p.kind == "flag":
                out[p.name] = False
            else:
                lo = p.lo if math.isfinite(p.lo) else -math.inf
                hi = p.hi if math.isfinite(p.hi) else math.inf
                v = min(max(0.0, lo), hi)
                if (p.lo_open and v <= p.lo) or (p.hi_open and v >= p.hi):
                    v = p.lo + 1.0 if math.isfinite(p.lo) else p.hi - 1.0
                out[p.name] = v
        return out

    def clip(self, params: Mapping[str, Any], n_gyros: int | None = None) -> dict:
        """Fitted parameters kept inside the spec's bounds (a fit may land on an edge)."""
        out = {}
        for p in self.params:
            if p.name not in params:
                continue
            v = params[p.name]
            if p.kind == "scalar" and isinstance(v, (int, float)) and not isinstance(v, bool):
                lo = p.lo + (max(abs(p.lo), 1.0) * 1e-9 if p.lo_open else 0.0)
                hi = p.hi - (max(abs(p.hi), 1.0) * 1e-9 if p.hi_open else 0.0)
                v = float(min(max(v, lo), hi))
            out[p.name] = v
        return out

    def entry_params(self, fit: "EffectFit", old: Mapping[str, Any]) -> dict:
        """The parameters of a model entry after ``fit`` (what the fit does not set is kept)."""
        params = dict(old)
        for k, v in fit.params.items():
            if k not in self.param_names or v is None:
                continue
            a = np.asarray(v, dtype=float)
            if np.all(np.isfinite(a)):
                params[k] = float(a) if a.ndim == 0 else tuple(float(x) for x in a.ravel())
        return params

    # -- simulate side ----------------------------------------------------------
    def simulate(self, state: ChainState, act: Active, streams: Streams) -> ChainState:
        """The chain's state after this effect (pure: never change ``state``)."""
        raise NotImplementedError(f"effect {self.name!r} has no simulate side")

    # -- fit side ---------------------------------------------------------------
    def why_not(self, ctx: "FitContext") -> str | None:
        """None if the effect can be fitted on this record, else why not (one phrase)."""
        for need in sorted(self.needs):
            why = ctx.lacks(need)
            if why:
                return why
        return None

    def fit(self, ctx: "FitContext", gyro: int | None, E: np.ndarray) -> "EffectFit":
        """Fit the parameters on residual ``E`` (n, N) [rad/s] (its own contribution included)."""
        raise NotImplementedError(f"effect {self.name!r} has no fit side")

    def test(self, ctx: "FitContext", gyro: int | None) -> "EffectFit":
        """The candidate test when the model lacks the effect (default: :meth:`fit` on ``ctx.E``,
        through :meth:`FitContext.fitted`, which refits a ``slow`` effect)."""
        assert ctx.E is not None                                 # set by the orchestrator
        return ctx.fitted(self, gyro, ctx.E)

    def predict(self, ctx: "FitContext", entry: "ModelEntry") -> np.ndarray | None:
        """What the entry adds to the outputs [rad/s], (n, N); None: nothing deterministic.

        Default, for deterministic effects: the entry alone simulated on the
        record's reference (zero without one), minus the sensed reference.
        """
        if not self.predicts:
            return None
        return ctx.simulate_entry(entry)

    def static_noise_in(self, ctx: "FitContext", entry: "ModelEntry") -> str | None:
        """Why, with ``entry`` in the model, the stochastic tests read the longest static part on
        this record (the noise differs between still and moving parts), or None (default:
        :attr:`static_noise`, whatever the record)."""
        return self.static_noise

    def band_entries(self, ctx: "FitContext", entry: "ModelEntry") -> list:
        """The entries this calibrated entry puts into the model's Monte-Carlo band (default:
        itself if ``stochastic``, else none). An effect whose noise depends on what else the
        gyro sees adds that too (a quantizer: the gyro's bias, which moves its counter)."""
        return [entry] if self.stochastic else []

    def noise_term(self, ctx: "FitContext", entry: "ModelEntry") -> dict:
        """For an effect in the model: what it changes in its gyro's Allan fit (a term of the
        baseline, ``terms``/``gm_tau_s``; the white column's shape, ``white_shape(m)``, see
        :func:`~gyroarray.effects.stochastic.fit_gyro_noise`)."""
        return {}

    def predictor_term(self, act: Active, n_gyros: int) -> "PredictorTerm | None":
        """What this effect contributes to the design predictor and the estimators' noise.

        Parameters
        ----------
        act : Active
            The model's entries of this effect resolved on an array of ``n_gyros``
            gyros (SI parameters per gyro of ``act.cols``; the values themselves for an
            array-wide effect); :func:`gyroarray.effects.terms.spread` puts one on every gyro.
        n_gyros : int

        Returns
        -------
        PredictorTerm or None
            A term of :mod:`gyroarray.effects.terms` (white, walk, flicker or Gauss–Markov
            noise, a correlation or sensor-filter modifier, or a deterministic rate error
            for a stated motion); None (the default): the predictor leaves the effect out
            and lists it in ``ignored``.
        """
        return None

    def exclude(self, ctx: "FitContext", entry: "ModelEntry") -> np.ndarray | None:
        """Samples (bool, n) the regressions should leave out with this entry in the model."""
        return None

    def silent(self, ctx: "FitContext", entry: "ModelEntry") -> np.ndarray | None:
        """Samples (bool, (n, N)) where this entry leaves a gyro's output without its noise (a clip
        on its plateau), which a test of the noise level must not read; None: none."""
        return None

    def clean(self, ctx: "FitContext", entry: "ModelEntry", x: np.ndarray) -> np.ndarray:
        """The residual (n, N) with what this entry models as glitches taken out (spikes), before any
        test reads it (default: as is)."""
        return x

    def whiten(self, ctx: "FitContext", entry: "ModelEntry", x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """A stochastic record (m, N) brought back to the model's stationary level (default: as is)."""
        return x

    def prefer(self, mine: "EffectFit", other: "EffectFit", ctx: "FitContext") -> str | None:
        """Why ``other`` (a rival) ranks below ``mine`` on the same excess, or None.

        Default: the smaller AIC, χ² + 2·(free parameters), when both fits
        report a ``chi2`` (``extra``). A reason that is an :class:`Explained`
        says more: ``other`` is no longer significant once ``mine`` is taken out
        (it is then not a significant candidate of its own).
        """
        if "chi2" not in mine.extra or "chi2" not in other.extra:
            return None
        a = float(mine.extra["chi2"]) + 2.0 * ctx.effect(mine.effect).free_parameters(mine)
        b = float(other.extra["chi2"]) + 2.0 * ctx.effect(other.effect).free_parameters(other)
        if a < b:
            return (f"; but {self.name.replace('_', ' ')} fits this {ctx.effect(other.effect).evidence_of} "
                    f"better (AIC {a:.1f} against {b:.1f})")
        return None

    def concede(self, mine: "EffectFit", other: "EffectFit", ctx: "FitContext") -> str | None:
        """Why ``other`` (an effect that does not name this one a rival, but that this one names)
        ranks above ``mine``, or None: the declaring side decides both ways."""
        return None

    #: What the fit compares with the data, for the rival sentence ("ADEV", "residual").
    evidence_of: ClassVar[str] = "residual"

    def channel_line(self, fit: "EffectFit", x: np.ndarray, xm: float, ym: float
                     ) -> tuple[np.ndarray, str] | None:
        """Its fit drawn on the panel of its ``channel``: (residual [deg/h] at ``x``, label), or None.

        ``x`` is the channel in display units (deg/s, deg²/s², deg/s², °C, s);
        ``xm``, ``ym`` the weighted means of the binned points (for effects
        whose constant is the bias).
        """
        return None

    def _label(self, fit: "EffectFit", name: str, scale: float = 1.0, unit: str = "") -> str:
        """``fit 6001 ± 18 ppm`` of one parameter."""
        v = float(fit.params[name]) * scale
        s = fit.sigma.get(name)
        pm = f" ± {sig(float(s) * scale, 2)}" if s is not None and np.isfinite(s) else ""
        return f"fit {sig(v)}{pm}{unit}"

    def free_parameters(self, fit: "EffectFit") -> int:
        """Free parameters of a fit, for the AIC (default: the parameters it returns)."""
        return max(len(fit.params), 1)

    def typical(self, rng: np.random.Generator) -> dict:
        """Plausible per-gyro values [spec units] of a term every simulated MEMS gyro has
        (baseline noise, turn-on bias), for the scoring cases; only those effects define it."""
        raise NotImplementedError

    def example(self, rng: np.random.Generator, n_gyros: int, max_rate_deg_s: np.ndarray
                ) -> tuple[int | None, dict] | None:
        """A plausible hidden case for scoring: (gyro, params) in spec units; None: not scored."""
        return None


# -- what a fit side reads ------------------------------------------------------------

@dataclass(eq=False)
class FitContext:
    """A record and its calibrated noise, as an effect's fit side sees it.

    Record (fixed for one comparison), SI: ``H`` (N, 3) nominal axes, ``t``
    (n,) the uniform clock [s], ``dt`` [s], ``y`` (n, N) outputs and ``E0``
    (n, N) outputs minus the projected reference [rad/s], ``ref`` (n, 3)
    [rad/s] or None, ``temp`` (n,) [°C] or None, ``acc`` (n, 3) specific
    force at the platform origin [m/s²] or None, ``positions`` (N, 3) [m] or
    None, ``site`` (the measurement's :class:`~gyroarray.core.measurement.Site`) or
    None, ``static`` (n,) bool, ``longest`` (a, b) the longest static part,
    ``moving`` (the table turns somewhere), ``name`` (the file, for messages),
    ``ref_raw`` (n, 3) [rad/s] the reference as recorded when ``ref`` is it
    smoothed (``--ref-smooth``), else None, ``ref_instrument`` (n, 3)
    [rad/s] the instrument of the regressions on it then, and ``parts``
    ((start, stop), ...) the still parts a record without reference was
    stitched from (empty: one record); the deterministic fits keep one free
    offset per part (:attr:`breaks`).

    Analysis (one calibration): ``model`` (the model being calibrated),
    ``r`` and ``q`` (N,) white and random-walk increment variances per sample
    [rad²/s²], ``use`` (n,) bool or None (samples the regressions use), ``E``
    (n, N) residual without the model's deterministic part, ``rec`` (slice)
    with ``Er`` / ``tr`` the stochastic record (brought back to the model's
    stationary level), ``static_record`` (the model's noise differs between
    still and moving parts, so the noise is read on the static part only),
    ``z_crit``.

    Services (set by the orchestrator): :meth:`simulate_entry`,
    :meth:`noise_rq`, :meth:`gyro_noise`, :meth:`effect`, :meth:`model_entry`,
    :attr:`attitude`.
    """

    name: str
    H: np.ndarray
    t: np.ndarray
    dt: float
    y: np.ndarray
    E0: np.ndarray
    ref: np.ndarray | None
    temp: np.ndarray | None
    acc: np.ndarray | None
    positions: np.ndarray | None
    site: Any
    static: np.ndarray
    longest: tuple[int, int]
    moving: bool
    services: Any = None
    model: "NoiseModel | None" = None
    r: np.ndarray | None = None
    q: np.ndarray | None = None
    use: np.ndarray | None = None
    E: np.ndarray | None = None
    rec: slice = field(default_factory=lambda: slice(None))
    Er: np.ndarray | None = None
    tr: np.ndarray | None = None
    static_record: bool = False
    z_crit: float = math.inf
    cache: dict = field(default_factory=dict)
    ref_raw: np.ndarray | None = None
    ref_instrument: np.ndarray | None = None
    parts: tuple = ()

    def __post_init__(self):
        # the record is fixed for one comparison: read-only, so that the many tests that read it
        # by content (analysis.memo) hash each array once, not on every call (the large arrays
        # the tests read by content; the sidecar's own small ones are left as they are)
        freeze(self.t, self.y, self.E0, self.ref, self.static, self.ref_raw, self.ref_instrument)

    @property
    def n(self) -> int:
        """Samples n."""
        return int(self.t.size)

    @property
    def breaks(self) -> np.ndarray | None:
        """First sample of each stitched part after the first (``parts``), or None (one record).

        A regression passes them to :func:`~gyroarray.analysis.gls.gls_rw` (``breaks``): each
        part's offset (the bias steps with the orientation between parts) is then a free
        parameter of the fit, one intercept per part, not set beforehand."""
        if len(self.parts) < 2:
            return None
        return np.array([a for a, _ in self.parts[1:]], dtype=int)

    def part_intercepts(self, n: int | None = None) -> np.ndarray:
        """One indicator column per stitched part (n, K) (one column of ones for a single record):
        the intercepts of a plain least-squares fit on the stitched record."""
        n = self.n if n is None else int(n)
        parts = self.parts if len(self.parts) >= 2 else ((0, n),)
        out = np.zeros((n, len(parts)))
        for k, (a, b) in enumerate(parts):
            out[a:b, k] = 1.0
        return out

    def equalised(self, x: np.ndarray) -> np.ndarray:
        """``x`` (n, ...) with each stitched part's mean set to the first part's, as the stitched
        outputs were (what the stochastic analysis reads once a deterministic fit with free
        per-part offsets is taken out); ``x`` itself without parts."""
        if len(self.parts) < 2:
            return x
        x = np.array(x, dtype=float, copy=True)
        a0, b0 = self.parts[0]
        first = x[a0:b0].mean(axis=0)
        for a, b in self.parts[1:]:
            x[a:b] += first - x[a:b].mean(axis=0)
        return x

    @property
    def N(self) -> int:
        """Gyros N."""
        return int(self.H.shape[0])

    @property
    def attitude(self) -> np.ndarray | None:
        """Platform -> local-level rotations (n, 3, 3) integrated from ``ref``, or None."""
        return self.services.attitude()

    def lacks(self, need: str) -> str | None:
        """Why the record lacks ``need`` (:data:`NEEDS`), or None."""
        if need == "ref" and self.ref is None:
            return "needs the reference rate (ref_x, ref_y, ref_z)"
        if need == "motion" and not self.moving:
            return ("needs the reference rate (ref_x, ref_y, ref_z)" if self.ref is None else
                    "needs a dynamic part (the table never turns)")
        if need == "temp":
            if self.temp is None:
                return "needs the temperature (temp_c)"
            if float(np.ptp(self.temp)) < 0.5:
                return "needs a temperature that changes (temp_c spans less than 0.5 °C)"
        if need == "site" and self.site is None:
            return "needs the site ([site] heading_deg) of the sidecar"
        if need == "acc" and self.acc is None and self.ref is None:
            return "needs the specific force (acc_x, acc_y, acc_z) or the reference rates"
        if need == "positions" and self.positions is None:
            return "needs the gyro positions (positions_m of the layout)"
        return None

    def effect(self, name: str) -> Effect:
        """The registered effect called ``name``."""
        return self.services.effect(name)

    def model_entry(self, effect: str, gyro: int | None, params: Mapping[str, Any]) -> "ModelEntry":
        """A validated model entry (:class:`~gyroarray.effects.model.ModelEntry`); InputError if invalid."""
        return self.services.model_entry(effect, gyro, params)

    def simulate_entry(self, entry: "ModelEntry") -> np.ndarray:
        """One model entry simulated alone on the record's reference, minus the sensed reference (n, N)."""
        return self.services.simulate_entry(entry)

    def fitted(self, effect: Effect, gyro: int | None, E: np.ndarray) -> "EffectFit":
        """``effect.fit`` on ``E``; a ``slow`` effect with z >= 2 is fitted again with q
        re-estimated on the residual without its first fit (a real drift inflates
        the random walk that would hide it)."""
        return self.services.fitted(effect, gyro, E)

    def noise_rq(self, e: np.ndarray, gyro: int) -> tuple[float, float]:
        """(r, q) of one gyro's residual ``e`` (calibrated on the longest static part)."""
        return self.services.noise_rq(e, gyro)

    def gyro_noise(self, gyro: int) -> dict:
        """The per-gyro noise fit on the stochastic record: effect name -> EffectFit."""
        return self.services.gyro_noise(gyro)

    def specific_force(self) -> np.ndarray:
        """Specific force at each gyro (n, N, 3) [m/s²], platform frame: f_0 from ``acc`` (else
        gravity through the attitude), plus the lever-arm terms from ``positions``."""
        return self.services.specific_force()

    def noise_terms(self, gyro: int) -> list:
        """Fits of the model's per-gyro noise terms of ``gyro`` (beyond the baseline)."""
        return self.services.noise_terms(gyro)

    def at_model_level(self, x: np.ndarray, t: np.ndarray, but: tuple | None = None) -> np.ndarray:
        """A record (m, N) at times ``t`` [s] brought to the model's stationary noise level: every
        entry's :meth:`Effect.whiten` (a burst, a fault's noise ratio), in model order; ``but``
        (effect, gyro): not that entry (the record its own refit reads)."""
        for e in self.model or ():
            if but is None or (e.effect, e.gyro) != tuple(but):
                x = self.effect(e.effect).whiten(self, e, x, t)
        return x

    def fit_prediction(self, effect: Effect, fit: "EffectFit") -> np.ndarray | None:
        """What ``fit`` of a predicting ``effect`` would take out of the record as a model entry
        (n, N) [rad/s], or None (the effect does not predict, or its parameters make no entry)."""
        if not effect.predicts:
            return None
        try:
            entry = self.model_entry(effect.name, fit.gyro, effect.clip(effect.entry_params(fit, effect.placeholder())))
        except InputError:
            return None
        return effect.predict(self, entry)

    def without(self, prediction: np.ndarray) -> "FitContext":
        """The same analysis with ``prediction`` (n, N) [rad/s] taken out of the residual
        (and of the stochastic record): what the record would show without it."""
        E = self.E - prediction
        Er = None if self.Er is None else self.Er - prediction[self.rec]
        if len(self.parts) >= 2:               # stitched parts: their means set equal again
            shift = self.equalised(E) - E
            E = E + shift
            Er = None if Er is None else Er + shift[self.rec]
        ctx = replace(self, E=E, Er=Er, cache={})
        ctx.services = self.services.derive(ctx)
        return ctx

    def leaving_out(self, samples: np.ndarray) -> "FitContext":
        """The same analysis with the regressions also leaving out ``samples`` (bool, n): what the
        record would show without them."""
        use = ~samples if self.use is None else (self.use & ~samples)
        ctx = replace(self, use=use, cache={})
        ctx.services = self.services.derive(ctx)
        return ctx

    @property
    def noise_end(self) -> int:
        """Samples before the run the model leaves out to the end of the record (a gyro frozen from
        its onset on: no noise record of it there), all of them without one (:func:`terminal_cut`)."""
        return terminal_cut(self.use) or self.n

    def entries(self, name: str) -> list:
        """The model's entries of the effect ``name``."""
        return [] if self.model is None else [e for e in self.model if e.effect == name]


# -- the two families most effects belong to ---------------------------------------------

class RegressionEffect(Effect):
    """A per-gyro deterministic effect fitted by one regression on its gyro's residual.

    Subclasses write :meth:`regress`; the fit reads column ``gyro`` of the
    residual with that gyro's white and random-walk variances (an exact GLS
    under ARW + a random-walk bias, :func:`gyroarray.analysis.gls.gls_rw`).
    """

    kind: ClassVar[Kind] = Kind.DETERMINISTIC
    predicts: ClassVar[bool] = True

    def regress(self, ctx: FitContext, gyro: int, e: np.ndarray, r: float, q: float) -> "EffectFit":
        """Fit on gyro ``gyro``'s residual ``e`` (n,) [rad/s] under noise (r, q)."""
        raise NotImplementedError

    @staticmethod
    def against_reference(ctx: FitContext, gyro: int, e: np.ndarray) -> tuple:
        """(residual, reference, instrument) for a regression on the reference rate.

        As recorded: (``e``, ``ctx.ref``, None). With a smoothed reference
        (``ctx.ref_raw`` set), the errors-in-variables form: the residual against
        the recorded reference, the recorded reference as the regressor and
        ``ctx.ref_instrument`` as its instrument (the smoothing's own distortion
        of the motion, at the turns, then biases nothing: it is in the
        instrument only).
        """
        if ctx.ref_raw is None:
            return e, ctx.ref, None
        if ctx.ref_raw is ctx.ref:                # instrumented, the residual as recorded already
            return e, ctx.ref, ctx.ref_instrument
        h = ctx.H[gyro - 1]
        return e - (ctx.ref_raw - ctx.ref) @ h, ctx.ref_raw, ctx.ref_instrument

    def fit(self, ctx: FitContext, gyro: int | None, E: np.ndarray) -> "EffectFit":
        assert gyro is not None and ctx.r is not None and ctx.q is not None   # per gyro, noise known
        g = int(gyro) - 1
        return self.regress(ctx, int(gyro), E[:, g], float(ctx.r[g]), float(ctx.q[g]))


class NoiseTermEffect(Effect):
    """A per-gyro stochastic effect: one term of the gyro's Allan model.

    Its fit is the term's part of the gyro's noise fit on the stochastic
    record (:meth:`FitContext.gyro_noise`): with the effect in the model,
    the term joins the baseline (:meth:`noise_term`); without it, its z is
    the test of one more term.
    """

    kind: ClassVar[Kind] = Kind.NOISE
    stochastic: ClassVar[bool] = True
    reads: ClassVar[str] = "noise"
    evidence_of: ClassVar[str] = "ADEV"

    def fit(self, ctx: FitContext, gyro: int | None, E: np.ndarray) -> "EffectFit":
        assert gyro is not None                                  # a per-gyro term
        return ctx.gyro_noise(int(gyro))[self.name]


def same_noise_preference(mine_effect: RegressionEffect, mine: "EffectFit", other: "EffectFit",
                          ctx: FitContext) -> str | None:
    """Two drifts of one gyro refitted as regressions under the same noise: why ``other`` ranks lower.

    A warm-up temperature and time are nearly collinear over a record, so
    both candidates are significant when either drift is there, and their
    own z's come from different tests. Both are fitted again on the residual
    under the same (r, q); the smaller χ² ranks first (one parameter each).
    """
    assert mine.gyro is not None and ctx.E is not None and ctx.r is not None and ctx.q is not None
    g = int(mine.gyro) - 1
    other_effect = ctx.effect(other.effect)
    if not isinstance(other_effect, RegressionEffect):
        return None
    args = (ctx.E[:, g], float(ctx.r[g]), float(ctx.q[g]))
    a = float(mine_effect.regress(ctx, g + 1, *args).extra["chi2"])
    b = float(other_effect.regress(ctx, g + 1, *args).extra["chi2"])
    if a < b:
        return (f"; but {mine_effect.name.replace('_', ' ')} fits this drift better under the same noise "
                f"(χ² {a:.1f} against {b:.1f}; the two are nearly collinear on this record)")
    return None


def terminal_cut(use: np.ndarray | None) -> int | None:
    """The first sample of the run that ``use`` (samples the regressions use) leaves out to the end
    of the record (a gyro frozen from its onset on), or None."""
    if use is None or use[-1]:
        return None
    kept = np.flatnonzero(use)
    if not kept.size or not np.all(use[:kept[-1] + 1]):
        return None
    return int(kept[-1]) + 1


class Explained(str):
    """A rival's reason (:meth:`Effect.prefer`) that also says the rival is not needed: with the
    winner taken out of the record its test is no longer significant. The ranking then marks the
    rival ``explained_by`` the winner, and it is not a significant candidate of its own (spikes
    are never also a burst)."""

    __slots__ = ()


def explains_away(mine_effect: Effect, mine: "EffectFit", other: "EffectFit", ctx: FitContext) -> str | None:
    """Why ``other`` ranks below ``mine``: with ``mine``'s fit taken out of the record, ``other`` is
    no longer significant (its test on what is left has z <= z_crit), or None.

    A rival rule across kinds: a deterministic effect and a noise term can
    explain the same excess (a square wave makes an ADEV hump, a filter a
    Gauss–Markov one), and their fit statistics are not comparable; what is
    comparable is whether one still sees the other once it is removed.
    """
    kept = kept_prediction(ctx, mine_effect, mine)
    if kept is None:
        return None
    if _column_untouched(kept, other, ctx):
        # ``other`` on another gyro than the cut's columns and its test reads its own column only
        # (Effect.own_column): the cut leaves that column as it was, bit for bit (the other columns
        # of KeptPrediction.cut are copies), so its test there is its test on the record itself
        # (a fresh cache, as a cut's), read once per (effect, gyro), not again on every cut (4.5 s
        # of the 46-min, 5-gyro bandwidth diagnosis: 456 of its 591 rival tests)
        store = ctx.cache.setdefault(KEPT_PREDICTIONS, {})
        key = (_SAME_COLUMN, other.effect, other.gyro, id(ctx.E), id(ctx.Er))
        left = store.get(key)
        if left is None or left[0] is not ctx.E or left[1] is not ctx.Er:
            same = replace(ctx, cache={})
            same.services = ctx.services.derive(same)
            left = store[key] = (ctx.E, ctx.Er, ctx.effect(other.effect).test(same, other.gyro))
        return _explained(left[2], ctx, f"the {mine_effect.name.replace('_', ' ')} removed")
    # the ranking asks the same winner against its rivals in a row: the last cut record is kept
    # (one at a time: the one before is let go first) with what the tests kept on it
    store = ctx.cache.setdefault(KEPT_PREDICTIONS, {})
    last = store.get(_LAST_CUT)
    if last is not None and last[0] is kept:
        cut = last[1]
    else:
        store.pop(_LAST_CUT, None)
        last = None
        cut = kept.cut(ctx)
        freeze(cut.E, cut.Er)                # made here, only read by the tests (digests kept)
        store[_LAST_CUT] = (kept, cut)
    return no_longer_seen(cut, other, ctx, f"the {mine_effect.name.replace('_', ' ')} removed")


#: ``FitContext.cache`` key of the predictions :func:`kept_prediction` keeps, (effect, id(fit)) ->
#: (fit, :class:`KeptPrediction` or None); the ranking drops them when done (:func:`drop_kept`).
KEPT_PREDICTIONS = "kept_fit_predictions"
#: Key, in that store, of the last record :func:`explains_away` cut: (KeptPrediction, FitContext).
_LAST_CUT = "last_cut"
#: First item of the keys, in that store, of the tests :func:`explains_away` reads on the record
#: itself: (_SAME_COLUMN, effect, gyro, id(E), id(Er)) -> (E, Er, the test's EffectFit).
_SAME_COLUMN = "same_column_test"


def _column_untouched(kept: "KeptPrediction", other: "EffectFit", ctx: FitContext) -> bool:
    """Whether cutting ``kept`` out of ``ctx`` leaves ``other``'s test as it is on ``ctx``: the cut
    replaces columns other than ``other``'s gyro's, copies the rest bit for bit (no stitched parts,
    whose means the cut sets equal again; float64 throughout), and the test reads its own column
    only (:attr:`Effect.own_column`)."""
    if other.gyro is None or kept.cols is None or len(ctx.parts) >= 2 or ctx.E is None:
        return False
    if int(other.gyro) - 1 in kept.cols.tolist() or not getattr(ctx.effect(other.effect), "own_column", False):
        return False
    return (ctx.E.dtype == np.float64 and kept.values is not None and kept.values.dtype == np.float64
            and (ctx.Er is None or ctx.Er.dtype == np.float64))


class KeptPrediction:
    """A fit's prediction (n, N) kept by its non-zero columns only: a per-gyro entry predicts on
    its own gyro, the other columns are +0.0 exactly (their bits are zero), so ``E - prediction``
    is ``E`` there, bit for bit. :meth:`cut` is :meth:`FitContext.without` of the whole
    prediction, the same bits, without rebuilding the (n, N) array."""

    __slots__ = ("cols", "values", "full")

    def __init__(self, pred: np.ndarray):
        self.cols: np.ndarray | None
        self.values: np.ndarray | None
        self.full: np.ndarray | None
        pred = np.asarray(pred)
        if pred.ndim != 2 or pred.dtype != np.float64:
            self.cols, self.values, self.full = None, None, pred
            return
        # a column is live where any value's 64 bits are not all zero (one uint64 per value: the
        # same test as any of its 8 bytes, 30x faster than reducing the bytes over two axes)
        live = np.flatnonzero(np.ascontiguousarray(pred).view(np.uint64).any(axis=0))
        if live.size == pred.shape[1]:
            self.cols, self.values, self.full = None, None, pred
        else:
            self.cols, self.values, self.full = live, np.array(pred[:, live]), None

    def cut(self, ctx: "FitContext") -> "FitContext":
        """``ctx.without(prediction)``."""
        if self.full is not None:
            return ctx.without(self.full)
        assert ctx.E is not None                 # a record cut by a fit has its outputs
        if len(ctx.parts) >= 2:                  # stitched parts: without() handles the joins
            return ctx.without(self.dense(ctx.E.shape))
        assert self.cols is not None and self.values is not None     # kept by columns (no full)
        E = np.array(ctx.E, dtype=np.result_type(ctx.E, self.values), copy=True)
        if self.cols.size:
            E[:, self.cols] = ctx.E[:, self.cols] - self.values
        Er = None
        if ctx.Er is not None:
            Er = np.array(ctx.Er, dtype=np.result_type(ctx.Er, self.values), copy=True)
            if self.cols.size:
                Er[:, self.cols] = ctx.Er[:, self.cols] - self.values[ctx.rec]
        out = replace(ctx, E=E, Er=Er, cache={})
        out.services = ctx.services.derive(out)
        return out

    def dense(self, shape) -> np.ndarray:
        assert self.cols is not None and self.values is not None
        out = np.zeros(shape)
        out[:, self.cols] = self.values
        return out


def kept_prediction(ctx: "FitContext", effect: "Effect", fit: "EffectFit") -> KeptPrediction | None:
    """:meth:`FitContext.fit_prediction` of ``fit``, made once per context and fit (the ranking
    asks for the same winner's prediction against every rival), kept by its live columns."""
    store = ctx.cache.setdefault(KEPT_PREDICTIONS, {})
    key = (effect.name, id(fit))
    hit = store.get(key)
    if hit is None or hit[0] is not fit:
        pred = ctx.fit_prediction(effect, fit)
        hit = store[key] = (fit, None if pred is None else KeptPrediction(pred))
    return hit[1]


def drop_kept(ctx: "FitContext") -> None:
    """Forget the predictions :func:`kept_prediction` kept on ``ctx`` (their memory)."""
    ctx.cache.pop(KEPT_PREDICTIONS, None)


def no_longer_seen(cut: FitContext, other: "EffectFit", ctx: FitContext, what: str) -> Explained | None:
    """``other``'s test on ``cut`` (the record with something taken out, ``what``): Explained when
    it is no longer significant there, else None."""
    return _explained(ctx.effect(other.effect).test(cut, other.gyro), ctx, what)


def _explained(left: "EffectFit", ctx: FitContext, what: str) -> Explained | None:
    """Explained when the test ``left`` (on the record with ``what`` taken out) sees nothing."""
    if np.isfinite(left.z) and left.z <= ctx.z_crit:
        return Explained(f"; but with {what} it is no longer seen (z = {left.z:.1f})")
    return None

