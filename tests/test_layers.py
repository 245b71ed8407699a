"""Imports in src/gyroarray point only downwards, layer by layer (issue 29).

The layers are the folders of ``src/gyroarray``, lowest first (:data:`LAYERS`). An import
(module level or inside a function) of a module of a HIGHER layer fails this test, with
the file, the line and the way out; an import of the same or a lower layer is fine. The
package root ``gyroarray`` (its version) and the data folder sit below every layer.
Read with ``ast``: nothing is imported.
"""

from __future__ import annotations

import ast
from pathlib import Path


SRC = Path(__file__).resolve().parents[1] / "src" / "gyroarray"

#: the layers, lowest first: a module may import its own layer and those before it
LAYERS = ['core', 'analysis', 'effects', 'sim', 'estimators', 'design', 'chain', 'sweep', 'reports', 'cli']


def _module(path: Path, src: Path) -> str:
    parts = list(path.relative_to(src.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _layer(module: str) -> int | None:
    parts = module.split(".")
    if parts[0] != "gyroarray":
        return None
    if len(parts) == 1:
        return -1
    if parts[1] not in LAYERS:
        return None
    return LAYERS.index(parts[1])


def _targets(node, module: str, is_pkg: bool) -> list[str]:
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if node.level:
        base = module.split(".")
        base = base if is_pkg else base[:-1]
        base = base[: len(base) - (node.level - 1)]
        mod = ".".join(base + ([node.module] if node.module else []))
    else:
        mod = node.module or ""
    # ``from gyroarray import sim`` imports the subpackage: judge each name
    if mod == "gyroarray":
        return [f"gyroarray.{a.name}" for a in node.names]
    return [mod]


def upward_imports(src: Path = SRC) -> list[str]:
    """'file:line: LAYER imports LAYER (module)' for every import that points up."""
    bad = []
    for path in sorted(p for p in src.rglob("*.py") if "__pycache__" not in p.parts):
        module = _module(path, src)
        own = _layer(module)
        if own is None:
            bad.append(f"{path.relative_to(src.parent)}: not in a layer folder ({', '.join(LAYERS)})")
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            for target in _targets(node, module, path.name == "__init__.py"):
                layer = _layer(target)
                if layer is not None and layer > own:
                    bad.append(f"{path.relative_to(src.parent)}:{node.lineno}: {LAYERS[own]} imports "
                               f"{LAYERS[layer]} ({target}): move the code it needs down, or the "
                               f"importer up")
    return bad


def test_every_module_sits_in_a_layer_folder():
    top = [p.name for p in SRC.glob("*.py") if p.name != "__init__.py"]
    assert top == [], f"modules beside the layers: {top}"
    assert {p.name for p in SRC.iterdir() if p.is_dir() and p.name != "__pycache__"} <= {*LAYERS, "data"}


def test_imports_point_only_downwards():
    bad = upward_imports()
    assert bad == [], "imports from a higher layer:\n" + "\n".join(bad)


def test_the_check_sees_an_upward_import(tmp_path):
    # the check can fail: a core module importing the cli is caught
    fake = tmp_path / "gyroarray"
    (fake / "core").mkdir(parents=True)
    (fake / "__init__.py").write_text("")
    (fake / "core" / "__init__.py").write_text("")
    (fake / "core" / "x.py").write_text("def f():\n    from gyroarray.cli.main import main\n")
    (fake / "core" / "y.py").write_text("from gyroarray.core import x\n")
    assert [b.split(":")[0:2] for b in upward_imports(fake)] == [["gyroarray/core/x.py", "2"]]


#: layers that compute: they hand result objects to reports/ and never draw (issue 29)
COMPUTING = ("analysis", "effects", "sim", "estimators", "chain", "design")


def matplotlib_imports(src: Path = SRC) -> list[str]:
    """'file:line' of every import of matplotlib (module level or in a function) in a computing layer."""
    bad = []
    for layer in COMPUTING:
        for path in sorted((src / layer).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and not node.level:
                    names = [node.module or ""]
                else:
                    continue
                if any(n == "matplotlib" or n.startswith("matplotlib.") for n in names):
                    bad.append(f"{path.relative_to(src.parent)}:{node.lineno}")
    return bad


def test_no_computing_layer_imports_matplotlib(tmp_path):
    bad = matplotlib_imports()
    assert bad == [], ("matplotlib imported below reports/ (move the plot to gyroarray.reports):\n"
                       + "\n".join(bad))
    # the check can fail: a plot inside analysis/ is caught
    (tmp_path / "gyroarray" / "analysis").mkdir(parents=True)
    (tmp_path / "gyroarray" / "analysis" / "p.py").write_text(
        "def plot():\n    from matplotlib.figure import Figure\n    return Figure\n")
    assert matplotlib_imports(tmp_path / "gyroarray") == ["gyroarray/analysis/p.py:2"]


def _is_module(module: str, src: Path) -> bool:
    """Whether ``gyroarray.a.b`` names a module or package file under ``src`` (the gyroarray folder)."""
    parts = module.split(".")[1:]
    return bool(parts) and ((src.joinpath(*parts).with_suffix(".py")).is_file()
                            or (src.joinpath(*parts) / "__init__.py").is_file())


def _private_module_outside(target: str, importer: str) -> str | None:
    """The private module on ``target``'s path (``gyroarray.analysis._kernels``) when ``importer``
    is not inside the package that holds it, else None."""
    parts = target.split(".")
    for i, part in enumerate(parts[1:], 1):
        if part.startswith("_") and not part.startswith("__"):
            package = ".".join(parts[:i])
            return None if importer.startswith(package + ".") else ".".join(parts[:i + 1])
    return None


def private_imports(src: Path = SRC) -> list[str]:
    """'file:line: ...' for every import of a private name (a leading underscore) from another
    module: a function, class or constant of another module, or a private module from outside
    the package that holds it (``from gyroarray.analysis import _kernels`` is fine inside
    ``gyroarray.analysis``). Module level or inside a function."""
    bad = []
    for path in sorted(p for p in src.rglob("*.py") if "__pycache__" not in p.parts):
        module = _module(path, src)
        where = path.relative_to(src.parent)
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                found = [(a.name, None) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                [mod] = _targets(ast.ImportFrom(module=node.module, names=[], level=node.level),
                                 module, path.name == "__init__.py") or [node.module or ""]
                found = [(mod, a.name) for a in node.names]
            else:
                continue
            modules = set()         # private modules this import reaches from outside their package
            for mod, name in found:
                if not mod.startswith("gyroarray"):
                    continue
                full = mod if name is None else f"{mod}.{name}"
                private = name is not None and name.startswith("_") and not name.startswith("__")
                if private and not _is_module(full, src):
                    bad.append(f"{where}:{node.lineno}: imports the private name {full}: make it "
                               "public at its home (no leading underscore), or move it where both "
                               "users can import it")
                    continue
                modules.add(_private_module_outside(full if private else mod, module))
            bad += [f"{where}:{node.lineno}: imports the private module {m} from outside its package: "
                    "make the module public, or move what it needs" for m in sorted(modules - {None})]
    return bad


def test_no_private_name_is_imported_across_modules(tmp_path):
    bad = private_imports()
    assert bad == [], "private names imported across modules:\n" + "\n".join(bad)
    # the check can fail: a private function, and a private module from another package, are
    # caught; a private module used inside its own package is not
    fake = tmp_path / "gyroarray"
    for folder in ("core", "sim"):
        (fake / folder).mkdir(parents=True)
        (fake / folder / "__init__.py").write_text("")
    (fake / "__init__.py").write_text("")
    (fake / "core" / "_kern.py").write_text("def k():\n    return 1\n")
    (fake / "core" / "a.py").write_text("from gyroarray.core import _kern\n\ndef _f():\n    return 1\n")
    (fake / "core" / "b.py").write_text("from . import _kern\nfrom gyroarray.core._kern import k\n")
    (fake / "sim" / "c.py").write_text("def g():\n    from gyroarray.core.a import _f\n    return _f\n")
    (fake / "sim" / "d.py").write_text("from gyroarray.core._kern import k\nimport gyroarray.core._kern\n")
    (fake / "sim" / "e.py").write_text("from ..core import _kern as kern\n")
    assert [b.split(":")[0:2] for b in private_imports(fake)] == [
        ["gyroarray/sim/c.py", "2"], ["gyroarray/sim/d.py", "1"], ["gyroarray/sim/d.py", "2"],
        ["gyroarray/sim/e.py", "1"]]
