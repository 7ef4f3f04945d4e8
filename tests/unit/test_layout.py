"""The package's import rules (DEVELOPERS.md, "Import rules"), checked on the source with an AST walk.

- No import cycles: no module imports (directly or through others) a module that imports it back.
  Every import counts, also one inside a function (a lazy import still ties the two modules); only
  ``if TYPE_CHECKING:`` blocks are left out (never executed: annotations only).
- Nothing below the CLI imports it: no module of netsetest/ outside netsetest/cli/, nor of the benchmark
  (netsetest_bench/), imports netsetest.cli, except ``python -m netsetest`` (netsetest/__main__.py), which is
  the CLI's entry point.
- The product never imports the benchmark: netsetest_bench/ is not in the wheel, so only the CLI's ``bench``
  command reaches it (and says so when it is not installed).
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "netsetest"
BENCH = PACKAGE.with_name("netsetest_bench")  # the benchmark beside the product (a checkout's, not the wheel's)
ENTRY_POINTS = {"netsetest.__main__"}  # the CLI itself, under another name


def _module_name(path: Path, package: Path) -> str:
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or (isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING")


def _imported(tree: ast.AST, module: str, is_package: bool) -> set[str]:
    """Every module name an import statement of ``tree`` names (``from a import b``: a and a.b)."""
    out: set[str] = set()
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and _is_type_checking(node):
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolved against the importing module's package
                pkg = module.split(".") if is_package else module.split(".")[:-1]
                pkg = pkg[: len(pkg) - node.level + 1]
                base = ".".join(pkg + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
        stack.extend(ast.iter_child_nodes(node))
    return out


def import_graph(*packages: Path) -> dict[str, set[str]]:
    """Module → the packages' modules it imports (itself excluded); the packages side by side in one folder."""
    files = {_module_name(p, package): p for package in packages for p in package.rglob("*.py")}
    graph = {}
    for name, path in files.items():
        deps = _imported(ast.parse(path.read_text(encoding="utf-8")), name, path.name == "__init__.py")
        graph[name] = {d for d in deps if d in files and d != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_the_checker_finds_a_cycle_and_a_lazy_one(tmp_path: Path) -> None:
    """The walk sees module-level, relative and function-level imports, and skips TYPE_CHECKING blocks."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pkg.b import f\n")
    (pkg / "b.py").write_text("def f():\n    from . import a\n")
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.d import x\n")
    (pkg / "d.py").write_text("import pkg.c\n")
    graph = import_graph(pkg)
    assert graph["pkg.b"] == {"pkg", "pkg.a"} and graph["pkg.c"] == set()
    assert cycles(graph) == [["pkg.a", "pkg.b"]]


@functools.cache
def _graph() -> dict[str, set[str]]:
    """The import graph of netsetest and its benchmark, parsed once for the tests below (they only read it)."""
    return import_graph(PACKAGE, BENCH)


def test_no_import_cycles() -> None:
    assert cycles(_graph()) == []


def _is_cli(module: str) -> bool:
    return module == "netsetest.cli" or module.startswith("netsetest.cli.")


def test_nothing_below_the_cli_imports_it() -> None:
    graph = _graph()
    assert any(_is_cli(d) for d in graph["netsetest.__main__"])  # the walk sees the entry point's import
    assert sum(m.startswith("netsetest_bench.") for m in graph) >= 20  # the benchmark's modules are in the walk, below the CLI
    offenders = {m: sorted(filter(_is_cli, deps)) for m, deps in graph.items() if not _is_cli(m) and m not in ENTRY_POINTS}
    assert {m: d for m, d in offenders.items() if d} == {}


def _is_bench(module: str) -> bool:
    return module == "netsetest_bench" or module.startswith("netsetest_bench.")


def test_the_product_never_imports_the_benchmark() -> None:
    """Only the CLI (its ``bench`` command) imports netsetest_bench/; every other module of netsetest/ works without it."""
    graph = _graph()
    assert any(_is_bench(d) for d in graph["netsetest.cli.main"])  # the walk sees the CLI's import of it
    product = {m: sorted(filter(_is_bench, deps)) for m, deps in graph.items() if m.startswith("netsetest.") and not _is_cli(m)}
    assert {m: d for m, d in product.items() if d} == {}
