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
