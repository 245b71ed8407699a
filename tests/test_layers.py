"""Imports in src/gyroarray point only downwards, layer by layer (issue 29).

The layers are the folders of ``src/gyroarray``, lowest first (:data:`LAYERS`). An import
(module level or inside a function) of a module of a HIGHER layer fails this test, with
the file, the line and the way out; an import of the same or a lower layer is fine. The
package root ``gyroarray`` (its version) and the data folder sit below every layer.
Read with ``ast``: nothing is imported.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
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


def _comment_lines(text: str) -> tuple[set[int], set[int]]:
    """The lines that carry a comment, and those that are only a comment (1-based)."""
    carry, only = set(), set()
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            carry.add(tok.start[0])
            if not tok.line[:tok.start[1]].strip():
                only.add(tok.start[0])
    return carry, only


def uncommented_function_imports(src: Path = SRC) -> list[str]:
    """Function-level imports under ``src`` that say nowhere why they are deferred.

    One is commented when a line of the statement carries a comment, or when the line
    directly above it, or above the first of the consecutive import statements it ends, is a
    comment line.
    """
    bad = []
    for path in sorted(src.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        tree = ast.parse(text)
        carry, only = _comment_lines(text)
        imports = sorted((n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))),
                         key=lambda n: n.lineno)
        ends = {n.end_lineno: n for n in imports}
        inner = {id(n) for fn in ast.walk(tree) if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef))
                 for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))}
        for node in imports:
            if id(node) not in inner or carry & set(range(node.lineno, node.end_lineno + 1)):
                continue
            first = node
            while first.lineno - 1 in ends and first.lineno - 1 not in only:
                first = ends[first.lineno - 1]
            if first.lineno - 1 not in only:
                line = text.splitlines()[node.lineno - 1].strip()
                bad.append(f"{path.relative_to(src.parent).as_posix()}:{node.lineno}: {line}")
    return bad


def test_every_function_level_import_says_why_it_is_deferred(tmp_path):
    bad = uncommented_function_imports()
    assert bad == [], ("function-level imports without a comment (move them to module level, or "
                       "say `# deferred: <why>` on the line or just above the block):\n" + "\n".join(bad))
    # the check can fail: an import with no comment, or one after a code line below a commented
    # block, is caught; a comment on the line, above the block, or on a continuation line is not
    fake = tmp_path / "gyroarray"
    fake.mkdir()
    (fake / "m.py").write_text(
        "import os  # module level: never checked\n"
        "import sys\n"
        "\n"
        "def f():\n"
        "    import json  # deferred: the line says why\n"
        "    # deferred: the block says why\n"
        "    import math\n"
        "    from pathlib import (Path,\n"
        "                         PurePath)\n"
        "    import io\n"
        "    x = 1\n"
        "    import csv\n"
        "    return x\n"
        "\n"
        "class C:\n"
        "    def g(self):\n"
        "        s = '# not a comment'\n"
        "        import zlib\n"
        "        from email import (message,  # deferred: a continuation line says why\n"
        "                           parser)\n"
        "        return s\n"
        "\n"
        "async def h():\n"
        "    import asyncio\n")
    assert [b.split(":")[1] for b in uncommented_function_imports(fake)] == ["12", "18", "24"]


#: (file under src/gyroarray, literal) pairs that spell an effect's name but mean something else
EFFECT_NAME_LOOKALIKES = {
    ("sim/profiles.py", "sinusoid"),  # a motion profile's kind, not the sinusoid effect
    # the layer below effects/: the correlation *statistic* (a field of ArrayCovariance)
    ("analysis/array_covariance.py", "correlation"),
}


def effect_name_literals(root: Path = SRC) -> list[str]:
    """``file:line: literal`` for each string in code outside ``effects/`` that names an effect.

    A string is code when it is not a docstring; it names an effect when it is one of
    :func:`gyroarray.effects.effect_names` or holds one in quotes (``"… ('arw') …"``).
    Code that means one effect takes its name from :mod:`gyroarray.effects.names` (the class's
    ``name``) or asks the registry, so the effect's module stays the one place that spells it.
    """
    from gyroarray import effects  # deferred: the other checks of this file import nothing
    names = sorted(effects.effect_names())
    quoted = re.compile(r'''["'](%s)["']''' % "|".join(map(re.escape, names)))
    found = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel.split("/")[0] == "effects":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        docs = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                body = node.body
                if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                    docs.add(id(body[0].value))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
                    and (node.value in names or quoted.search(node.value))
                    and (rel, node.value) not in EFFECT_NAME_LOOKALIKES):
                found.append(f"{rel}:{node.lineno}: {node.value[:60]!r}")
    return found


def test_no_effect_name_literal_outside_effects():
    bad = effect_name_literals()
    assert not bad, ("effect names spelled outside gyroarray/effects (take them from "
                     "gyroarray.effects.names or ask the registry):\n" + "\n".join(bad))


def test_effect_name_check_can_fail(tmp_path):
    fake = tmp_path / "gyroarray"
    (fake / "effects").mkdir(parents=True)
    (fake / "effects" / "x.py").write_text('name = "arw"\n')
    (fake / "m.py").write_text(
        '"""Docs may say effect = "arw"."""\n'
        'def f(e):\n'
        '    """So may a function\'s: "rrw"."""\n'
        '    if e == "arw":\n'
        '        raise ValueError(f"no (\'rrw\') for {e}")\n'
        '    return "arwx"\n')
    assert [b.split(":")[1] for b in effect_name_literals(fake)] == ["4", "5"]
