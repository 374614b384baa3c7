"""The package's layering (docs/architecture.md): no import cycle among gtrig's modules, no module taking
another module's private names, and the core never importing the CLI, the report or matplotlib."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "gtrig"

#: packages only the command line, the report and plotting modules may import
TOP = ("gtrig.cli", "gtrig.report")


def _modules() -> dict[str, tuple[Path, str]]:
    """Module name -> (file, the package its relative imports resolve against)."""
    out = {}
    for p in PKG.rglob("*.py"):
        parts = list(p.relative_to(PKG.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
            pkg = ".".join(parts)
        else:
            pkg = ".".join(parts[:-1])
        out[".".join(parts)] = (p, pkg)
    return out


def _imports(mods: dict[str, tuple[Path, str]]) -> list[tuple[str, str, str]]:
    """(importer, imported module, name) for every import of a gtrig module, lazy ones included, except
    under ``if TYPE_CHECKING:``."""
    found = []
    for m, (p, pkg) in mods.items():
        tree = ast.parse(p.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                node.body = []
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                for a in node.names:
                    sub = f"{target}.{a.name}"
                    found.append((m, sub, "") if sub in mods else (m, target, a.name))
            elif isinstance(node, ast.Import):
                found.extend((m, a.name, "") for a in node.names)
    return found


MODS = _modules()
IMPORTS = _imports(MODS)


def _cycles() -> list[list[str]]:
    graph: dict[str, set[str]] = {m: set() for m in MODS}
    for a, b, _ in IMPORTS:
        if b in MODS and b != a:
            graph[a].add(b)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
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
                found.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle() -> None:
    assert _cycles() == []


def test_no_module_takes_another_modules_private_names() -> None:
    bad = [(a, b, n) for a, b, n in IMPORTS
           if n.startswith("_") and not n.startswith("__") and b in MODS and b != a]
    assert bad == []


@pytest.mark.parametrize("layer", ["gtrig.cli", "gtrig.report", "matplotlib"])
def test_the_core_never_imports_the_top_layers(layer: str) -> None:
    def top(m: str) -> bool:
        return m in ("gtrig", "gtrig.__main__", "gtrig.plotting") or m.endswith(".plots") or any(
            m == t or m.startswith(t + ".") for t in TOP)

    bad = sorted({a for a, b, _ in IMPORTS if (b == layer or b.startswith(layer + ".")) and not top(a)})
    assert bad == []
