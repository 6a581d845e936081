"""The import graph of the project's own modules (common, services, deploy), read with ``ast``.

Every ``import`` and ``from ... import`` counts as an edge, at module level or inside a function
(a lazy import still ties the two modules together). ``from pkg import name`` points at the
submodule ``pkg.name`` when there is one, else at ``pkg``. A package's ``__init__`` is the
package's own module; importing ``a.b.c`` is not counted as importing ``a`` or ``a.b``.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator, Mapping
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("common", "services", "deploy")

Graph = dict[str, set[str]]


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported(tree: ast.Module, module: str, is_package: bool) -> Iterator[tuple[str, str]]:
    """``(base, name)`` per imported name: ``from base import name``; ``import x`` is (x, "")."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, ""
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolved against this module's package
                package = module if is_package else module.rpartition(".")[0]
                for _ in range(node.level - 1):
                    package = package.rpartition(".")[0]
                base = f"{package}.{base}" if base else package
            for alias in node.names:
                yield base, alias.name


def import_graph() -> Graph:
    """Module -> the project modules it imports."""
    paths = {module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    graph: Graph = {}
    for module, path in sorted(paths.items()):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        edges = set()
        for base, name in _imported(tree, module, path.name == "__init__.py"):
            target = f"{base}.{name}" if f"{base}.{name}" in paths else base
            if target in paths and target != module:
                edges.add(target)
        graph[module] = edges
    return graph


def find_cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(cycles)


GRAPH = import_graph()


def test_the_graph_sees_top_level_function_level_and_relative_imports() -> None:
    assert "tools.evaluation.yolo_dataset" in GRAPH["tools.evaluation.datasets"]
    # imported inside ensure_default_model, only when the model must be fetched
    assert "modelprep.acquire.fetch" in GRAPH["modelprep.files"]
    assert "runtimes.base" in GRAPH["runtimes.select"]


def test_find_cycles_reports_each_cycle_once() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"f"}, "f": {"e"}, "g": set()}
    assert find_cycles(graph) == [["a", "b", "c"], ["e", "f"]]


def test_no_import_cycles() -> None:
    cycles = find_cycles(GRAPH)
    assert cycles == [], "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def _allowed(module: str, target: str) -> bool:
    """common imports only common; deploy only common and deploy; a service its own package,
    common, another service's package root (its public API) and tools.launch."""
    top = module.split(".")[0]
    target_top = target.split(".")[0]
    if top == "common" or target_top == "common":
        return target_top == "common"
    if top == "deploy":
        return target_top == "deploy"
    if target_top == "deploy":
        return target == "tools.launch"
    own = ".".join(module.split(".")[:2])
    return target == own or target.startswith(f"{own}.") or target.count(".") == 1


def test_layers_and_no_service_imports_another_services_internals() -> None:
    wrong = sorted(
        f"{module} imports {target}"
        for module, targets in GRAPH.items()
        for target in targets
        if not _allowed(module, target)
    )
    assert wrong == []


def test_the_layering_rule_refuses_internals_and_allows_public_packages() -> None:
    assert not _allowed("tools.evaluation.evaluate", "services.detector.pipeline")
    assert _allowed("tools.evaluation.evaluate", "services.detector")
    assert not _allowed("tools.scenarios.runner", "deploy.processes")
    assert _allowed("tools.scenarios.runner", "tools.launch")
    assert not _allowed("common.frames", "services.detector")
    assert not _allowed("deploy.supervisor", "services.metrics")
