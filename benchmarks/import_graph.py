"""The import graph of gyroarray between its layers, read from the source (``ast``, nothing run).

    python benchmarks/import_graph.py [ROOT]

ROOT is a checkout (default: this one). Prints, for every pair of layers,
how many module-level imports go from one to the other, the cycles among
the layers, the count of ``gyroarray`` imports made inside functions, and
the cycles among modules (module-level imports only: what Python resolves
at import time). The layers are the folders of ``src/gyroarray`` (:data:`LAYERS`);
``tests/test_layers.py`` fails on an import that points upward.

Used for the closing notes of issues 13 and 29 (before/after); not part of the tests.
"""

from __future__ import annotations

import ast
import sys
from collections import Counter, defaultdict
from pathlib import Path

#: Source folder of the package (a plain src layout since issue 29).
FOLDERS = {"gyroarray": "src/gyroarray"}
#: The layers, lowest first: each a folder of src/gyroarray (tests/test_layers.py holds the code to
#: the same order).
LAYERS = ("core", "analysis", "effects", "sim", "estimators", "design", "chain", "sweep", "reports",
          "cli")


def modules(root: Path) -> dict:
    """Dotted module name -> source path."""
    out = {}
    for package, folder in FOLDERS.items():
        base = root / folder
        if not base.is_dir():
            continue
        for path in sorted(base.rglob("*.py")):
            rel = path.relative_to(base).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            out[".".join([package, *parts])] = path
    return out


def layer(name: str) -> str:
    """The layer folder of a module (``gyroarray.core.units`` -> ``core``)."""
    parts = name.split(".")
    if len(parts) > 1 and parts[1] in LAYERS:
        return parts[1]
    return "root"                               # the package root: its version string only


def _resolve(node, current: str, is_pkg: bool, mods) -> list:
    """Modules an import statement loads (``from P import m``: P.m when it is a module, else P)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if node.level:
        base = current.split(".")
        base = base if is_pkg else base[:-1]
        base = base[: len(base) - (node.level - 1)]
        mod = ".".join(base + ([node.module] if node.module else []))
    else:
        mod = node.module or ""
    subs = [f"{mod}.{a.name}" for a in node.names if f"{mod}.{a.name}" in mods]
    return subs + ([mod] if len(subs) < len(node.names) else [])


def imports(root: Path):
    mods = modules(root)
    top, inner = defaultdict(set), defaultdict(list)
    for name, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        is_pkg = path.name == "__init__.py"
        funcs = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
        in_func = {id(n) for f in funcs for n in ast.walk(f) if isinstance(n, (ast.Import, ast.ImportFrom))}
        for node in ast.walk(tree):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            targets = {t for t in _resolve(node, name, is_pkg, mods) if t in mods}
            if not targets:
                continue
            if id(node) in in_func:
                inner[name].append(targets)
            elif not _type_checking_only(tree, node):
                top[name] |= targets - {name}
    return mods, top, inner


def _type_checking_only(tree, node) -> bool:
    for n in ast.walk(tree):
        if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.unparse(n.test):
            if any(node is c for c in ast.walk(n)):
                return True
    return False


def _reach(graph: dict) -> dict:
    """Module -> every module it loads at import time (transitively)."""
    out: dict = {}
    for v in graph:
        seen, todo = set(), list(graph[v])
        while todo:
            w = todo.pop()
            if w not in seen:
                seen.add(w)
                todo.extend(graph.get(w, ()))
        out[v] = seen
    return out


def cycles(graph: dict) -> list:
    """Strongly connected components with more than one node (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in list(graph):
        if v not in index:
            visit(v)
    return out


def main(argv=None) -> int:
    root = Path((argv or sys.argv[1:] or [Path(__file__).resolve().parents[1]])[0])
    mods, top, inner = imports(root)
    edges = Counter()
    for src, targets in top.items():
        for t in targets:
            a, b = layer(src), layer(t)
            if a != b:
                edges[(a, b)] += 1
    print(f"{root}: {len(mods)} modules")
    print("module-level imports between layers (from -> to: count):")
    for (a, b), c in sorted(edges.items()):
        print(f"  {a:12s} -> {b:12s} {c:4d}")
    lgraph = defaultdict(set)
    for a, b in edges:
        lgraph[a].add(b)
    print("layer cycles:", cycles(lgraph) or "none")
    reach = _reach(top)
    dodging = Counter()
    for name, stmts in inner.items():
        for targets in stmts:
            if any(name in reach.get(t, ()) or t == name for t in targets):
                dodging[name] += 1
    n_inner = sum(len(v) for v in inner.values())
    print(f"gyroarray imports inside functions: {n_inner} (in {len(inner)} modules); "
          f"{sum(dodging.values())} of them would close a cycle at module level")
    for name, stmts in sorted(inner.items(), key=lambda kv: -len(kv[1]))[:8]:
        print(f"  {len(stmts):3d}  {name}  ({dodging[name]} cycle-dodging)")
    mcycles = cycles({k: v for k, v in top.items()})
    print("module cycles (module-level imports):", mcycles or "none")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
