"""The physical effects, one module each, and the registry that finds them.

Each module of this package defines one effect of ``shared/spec/effects.md``
as a subclass of :class:`gyroarray.effects.protocol.Effect` (simulate side, fit
side, how it enters a model; see that module). The registry is every such
class found here, plus

* the effects of installed packages, named in their ``gyroarray.effects``
  entry-point group (an Effect subclass, or a module holding some);
* the effects of a file the user names with ``--plugin PATH.py``
  (:func:`load_plugin`): the only way user code runs. Scenario, model and
  measurement files are data and are never executed.

Adding an effect is one new file: nothing else names it. The layer sits
above ``gyroarray.analysis`` (statistics that know no effect) and below the
simulator and the chains that use it (``gyroarray.sim``,
``gyroarray.chain.compare``); each effect's fit is in its own
module (shared helpers: ``gyroarray.effects.fitting``; the faults are the
subpackage ``gyroarray.effects.faults``), the noise-model types in
``gyroarray.effects.model``. The protocol an effect implements is
:mod:`gyroarray.effects.protocol`; it needs nothing from this registry.
"""

from __future__ import annotations

import difflib
import hashlib
import importlib
import importlib.util
import inspect
import pkgutil
import stat
import sys
import traceback
from importlib import metadata
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Mapping, NoReturn

from gyroarray.core.errors import InputError
from gyroarray.core.plugins import EFFECTS_GROUP, installed
from gyroarray.effects.protocol import RECORD_NEEDS, SIM_NEEDS, Effect, Kind, Param, Stage

__all__ = ["REGISTRY", "ENTRY_POINT_GROUP", "effect_names", "get_effect", "did_you_mean", "register",
           "unregister", "run_plugin_file", "effect_classes", "load_plugin", "installed_plugins"]

#: Entry-point group of installed packages that add effects.
ENTRY_POINT_GROUP = EFFECTS_GROUP

_EFFECTS: dict[str, Effect] = {}
_SOURCE: dict[str, str] = {}

#: The effects by spec name, read-only, in the spec's order (then plugins).
REGISTRY: Mapping[str, Effect] = MappingProxyType(_EFFECTS)


def did_you_mean(word, choices) -> str:
    """``"; did you mean 'x'?"`` for the closest of ``choices`` (difflib), or ``""``."""
    close = difflib.get_close_matches(str(word), list(choices), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def effect_names() -> tuple[str, ...]:
    """The registered effect names, in order."""
    return tuple(_EFFECTS)


def get_effect(name: str) -> Effect:
    """The effect called ``name``; InputError (with the closest name) if none."""
    try:
        return _EFFECTS[name]
    except (KeyError, TypeError):
        raise InputError(f"unknown effect {name!r}{did_you_mean(name, _EFFECTS)} "
                         f"(known: {', '.join(_EFFECTS)})") from None


def _validate(cls: type[Effect], source: str) -> Effect:
    """An instance of an Effect subclass, its declarations checked."""
    def bad(why: str) -> NoReturn:
        raise InputError(f"effect class {cls.__name__}: {why}", file=source)
    name = getattr(cls, "name", "")
    if not isinstance(name, str) or not name.isidentifier() or name != name.lower():
        bad(f"name must be a lower-case identifier, got {name!r}")
    if not isinstance(cls.params, tuple) or not all(isinstance(p, Param) for p in cls.params):
        bad("params must be a tuple of gyroarray.effects.protocol.Param")
    if len({p.name for p in cls.params}) != len(cls.params) or any(p.name == "gyro" for p in cls.params):
        bad("parameter names must be unique and not 'gyro'")
    if not isinstance(cls.stage, Stage) or not isinstance(cls.kind, Kind):
        bad("stage must be a Stage and kind a Kind")
    for attr in ("model_needs", "predict_needs"):
        got: object = getattr(cls, attr, frozenset())
        if not isinstance(got, (frozenset, set, tuple)) or not set(got) <= set(RECORD_NEEDS):
            bad(f"{attr} must be a frozenset of {', '.join(RECORD_NEEDS)}, got {got!r}")
    got = getattr(cls, "sim_needs", frozenset())
    if not isinstance(got, (frozenset, set, tuple)) or not set(got) <= set(SIM_NEEDS):
        bad(f"sim_needs must be a frozenset of {', '.join(SIM_NEEDS)}, got {got!r}")
    axes = getattr(cls, "sweep_axes", ())
    if not isinstance(axes, tuple) or not set(axes) <= {p.name for p in cls.params}:
        bad(f"sweep_axes must be a tuple of its parameter names, got {axes!r}")
    if cls.simulate is Effect.simulate:
        bad("it has no simulate(state, act, streams)")
    try:
        return cls()
    except Exception as err:                 # a plugin's own bug: say where
        bad(f"cannot be created: {type(err).__name__}: {err}")
        raise                                # pragma: no cover


def register(effect_cls: type, *, source: str = "<code>") -> Effect:
    """Add an Effect subclass to the registry (its name must be new); returns the instance."""
    if not (inspect.isclass(effect_cls) and issubclass(effect_cls, Effect)):
        raise InputError(f"not an Effect subclass: {effect_cls!r}", file=source)
    eff = _validate(effect_cls, source)
    old = _EFFECTS.get(eff.name)
    if old is not None:
        if type(old) is effect_cls:
            return old
        raise InputError(f"effect {eff.name!r} is already defined by {_SOURCE[eff.name]}; "
                         "a plugin adds effects, it cannot replace one", file=source)
    items = sorted([*_EFFECTS.items(), (eff.name, eff)], key=lambda kv: (kv[1].order, kv[0]))
    _EFFECTS.clear()
    _EFFECTS.update(items)
    _SOURCE[eff.name] = source
    return eff


def effect_classes(module: ModuleType) -> list[type]:
    """The Effect subclasses a module defines (not imports) with a name."""
    return [obj for obj in vars(module).values()
            if inspect.isclass(obj) and issubclass(obj, Effect) and obj.__module__ == module.__name__
            and bool(getattr(obj, "name", ""))]


def _load_builtins() -> None:
    # subpackages too (the faults live in ``faults/``); a private module or package is skipped
    for info in pkgutil.walk_packages(__path__, prefix=f"{__name__}."):
        if any(part.startswith("_") for part in info.name.split(".")):
            continue
        module = importlib.import_module(info.name)
        for cls in effect_classes(module):
            register(cls, source=info.name)


def installed_plugins() -> list[tuple[str, str]]:
    """(name, value) of the ``gyroarray.effects`` entry points of installed packages."""
    return installed(ENTRY_POINT_GROUP)


def _load_entry_points() -> None:
    eps = metadata.entry_points(group=ENTRY_POINT_GROUP)
    for ep in sorted(eps, key=lambda e: e.name):
        source = f"entry point {ep.name} = {ep.value}"
        try:
            obj = ep.load()
        except Exception as err:             # an installed package's bug: one line, named
            raise InputError(f"cannot load the effect plugin {ep.value}: {type(err).__name__}: {err}",
                             file=source) from None
        classes = effect_classes(obj) if isinstance(obj, ModuleType) else [obj]
        for cls in classes:
            register(cls, source=source)


_PLUGINS: dict[str, list[str]] = {}


def run_plugin_file(path) -> tuple[ModuleType, bool]:
    """Run the Python file ``path`` (the user named it) once; returns (its module, first run).

    The file must be a regular ``.py`` file. The same file (after symlinks) is
    run once per process: a second call returns the module of the first.

    Raises
    ------
    InputError
        Not a regular .py file, or an exception while running it (named, one
        line, with the line of the file it came from).
    """
    p = Path(path)
    where = str(p)
    if p.suffix.lower() != ".py":
        raise InputError("a plugin must be a Python file ending in .py", file=where)
    try:
        st = p.stat()
    except OSError as err:
        raise InputError(f"cannot read the plugin: {err.strerror or err}", file=where) from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError("a plugin must be a regular file", file=where)
    key = str(p.resolve())
    modname = "gyroarray_plugin_" + hashlib.sha256(key.encode()).hexdigest()[:12]
    if modname in sys.modules:
        return sys.modules[modname], False
    spec = importlib.util.spec_from_file_location(modname, p)
    if spec is None or spec.loader is None:
        raise InputError("cannot load the plugin as a Python module", file=where)
    module = importlib.util.module_from_spec(spec)
    sys.modules[modname] = module
    try:
        spec.loader.exec_module(module)
    except InputError:
        sys.modules.pop(modname, None)
        raise
    except BaseException as err:             # user code: any failure, one line naming the file
        sys.modules.pop(modname, None)
        if isinstance(err, (KeyboardInterrupt, SystemExit)):
            raise
        line = _plugin_line(err, p)
        raise InputError(f"the plugin raised {type(err).__name__}: {err}", file=where, line=line) from None
    return module, True


def unregister(name: str) -> None:
    """Take an effect a plugin registered out of the registry again (a failed conformance
    check); built-ins and unknown names are left alone. The registry is then as if the plugin had
    never been loaded: its order is the rest's, and :func:`load_plugin` of its file registers it
    again (the file's entry in the loaded plugins is dropped, not left naming an effect that is
    gone)."""
    if name in _EFFECTS and not _SOURCE.get(name, "").startswith("gyroarray.effects."):
        del _EFFECTS[name]
        _SOURCE.pop(name, None)
        for key in [k for k, names in _PLUGINS.items() if name in names]:
            del _PLUGINS[key]


def load_plugin(path) -> list[str]:
    """Run the Python file ``path`` (the user named it) and register the effects it defines.

    Returns the names of its effects. The file must be a regular ``.py`` file
    that defines at least one :class:`~gyroarray.effects.protocol.Effect` subclass
    with a ``name``. Loading the same file twice registers nothing new. The
    CLI's ``--plugin`` goes through :func:`gyroarray.chain.plugins.load_plugin`,
    which also takes estimators and runs the conformance checks first.

    Raises
    ------
    InputError
        Not a regular .py file, an exception while running it (named, one
        line), no effect in it, or an effect name already taken.
    """
    where = str(path)
    key = str(Path(path).resolve())
    if key in _PLUGINS:
        return list(_PLUGINS[key])
    module, _ = run_plugin_file(path)
    classes = effect_classes(module)
    if not classes:
        raise InputError("the plugin defines no effect (a subclass of gyroarray.effects.protocol.Effect "
                         "with a name)", file=where)
    names = [register(cls, source=where).name for cls in classes]
    _PLUGINS[key] = names
    return names


def _plugin_line(err: BaseException, path: Path) -> int | None:
    """The line of ``path`` where ``err`` was raised (deepest frame in that file)."""
    line = getattr(err, "lineno", None) if isinstance(err, SyntaxError) else None
    for frame in traceback.extract_tb(err.__traceback__):
        try:
            if Path(frame.filename).resolve() == path.resolve():
                line = frame.lineno
        except OSError:
            continue
    return line


_load_builtins()
_load_entry_points()
