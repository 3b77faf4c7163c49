"""The modules of ``app.evaluation`` import one another without a cycle, counting the
imports inside functions too (a lazy import hides a cycle without ending it)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "app" / "evaluation"
PREFIX = "app.evaluation"


def _imports(path: Path, modules: set[str]) -> set[str]:
    """The modules of the package that ``path`` imports, anywhere in its body."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
        else:
            continue
        for name in names:
            if name.startswith(PREFIX + ".") and name.split(".")[2] in modules:
                found.add(name.split(".")[2])
    return found


def graph() -> dict[str, set[str]]:
    modules = {p.stem for p in PACKAGE.glob("*.py")}
    return {m: _imports(PACKAGE / f"{m}.py", modules) - {m} for m in modules}


def _cycle(edges: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}  # 1: on the path, 2: done

    def visit(m: str, path: list[str]) -> list[str] | None:
        state[m] = 1
        for n in sorted(edges[m]):
            if state.get(n) == 1:
                return path[path.index(n) :] + [n] if n in path else [m, n]
            if n not in state and (found := visit(n, path + [n])):
                return found
        state[m] = 2
        return None

    for m in sorted(edges):
        if m not in state and (found := visit(m, [m])):
            return found
    return None


def test_the_graph_sees_imports_inside_functions():
    edges = graph()
    assert {"report", "raw_report", "plots", "touches", "procedures", "raw"} <= set(edges)
    assert "plots" in edges["touches"] and "plots" in edges["procedures"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_no_module_of_app_evaluation_imports_one_that_imports_it_back():
    assert _cycle(graph()) is None


def test_plots_import_no_protocol_and_no_report():
    assert graph()["plots"] <= {"metrics"}
