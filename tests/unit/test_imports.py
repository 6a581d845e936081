"""The import graph of the project's own modules, read with ``ast``, and the rules it must keep.

Edges. Every ``import`` and ``from ... import`` counts, at module level or inside a function (a
lazy import still ties the two modules together), relative ones resolved. ``from pkg import
name`` points at the submodule ``pkg.name`` when there is one, else at ``pkg``. A package's
``__init__`` is the package's own module; importing ``a.b.c`` is not counted as importing ``a``
or ``a.b``. An import through ``importlib`` counts too: ``import_module("a.b")`` with a literal,
and the string values of a table such as runtimes/table.py's ``BACKENDS`` (name -> module) that
name a project module, absolutely or as a submodule of the table's own module (modelprep
/quantize's ``RUNTIMES``, imported as ``f"{__name__}.{module}"``). Running a module as a program
(``python -m``, ``runpy`` in deploy/zstack.py) is not an import.

Units. For package cycles and layers each module belongs to one unit: ``common``, ``stack``,
``runtimes``, ``perception``, ``rosmsg``, ``simworld``, ``depthscan`` and ``deploy`` are one
unit each; below
``services``, ``tools`` and ``modelprep`` each second level is one (``services.detector``,
``tools.evaluation``, ``modelprep.quantize``, and a module directly in the folder is its own:
``tools.launch``, ``modelprep.files``); a service's contract is a unit of its own
(``services.detector.contract``), so that what reads it (the stack, other services) does not
depend on the service.

Layers: who may import whom (``_allowed`` is exactly this table).

=============  ==========================================================================
importer       may import
=============  ==========================================================================
common         common
a contract     common, another service's contract (what it reads of it), a library's
               settings (``perception.settings``: the detector's contract composes them), and
               ``rosmsg.distro`` (the bridge's ``distro`` setting, a module that imports
               nothing); a contract is ``services.X.contract``
stack          common, stack, the services' contracts (it assembles them)
runtimes       common, runtimes, modelprep
modelprep.X    common, modelprep
perception     common, runtimes, modelprep, perception (the detection library)
rosmsg         common, rosmsg (the ROS 2 message library), and ``perception``'s package root
               (a camera's mounting and the depth columns of 3D detections)
simworld       common, simworld (the simulated world)
depthscan      common, depthscan (the virtual scan of a depth camera), and ``perception``'s
               package root (a camera's mounting, a depth image's intrinsics)
services.X     common, stack, runtimes, modelprep, rosmsg, simworld, depthscan, its own package,
               ``perception`` (the package root: its public API, never its modules), and of
               another service only its contract (``services.Y.contract``): never its package
               root nor its other modules; never tools or deploy
tools.X        anything but deploy (a tool starts the supervisor as a process), and of
               perception only its package root (its public API)
deploy         common, stack, the services' contracts, deploy
=============  ==========================================================================

So no library (``common``, ``runtimes``, ``modelprep``, ``perception``, ``rosmsg``,
``simworld``, ``depthscan``) imports ``services``:
each declares its own settings, and takes them, or plain arguments, from its callers.

Serving's load path (``perception.loading``, what the detector service opens its model with)
reaches nothing under ``modelprep.quantize`` (the INT8 quantizer): preparing a model
(``perception.preparing``) and loading what was prepared are two modules.

No production module reads anything under tests/: no import of ``tests``, and no string that
is a path into it (``"tests/..."``, a ``"tests"`` path part); docstrings and comments may
mention tests.
"""

from __future__ import annotations

import ast
import itertools
import re
from collections.abc import Container, Iterable, Iterator, Mapping
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = (
    "common",
    "stack",
    "runtimes",
    "modelprep",
    "perception",
    "rosmsg",
    "simworld",
    "depthscan",
    "services",
    "tools",
    "deploy",
)
#: Units that are a whole top-level package (the others are split at the second level).
WHOLE = ("common", "stack", "runtimes", "perception", "rosmsg", "simworld", "depthscan", "deploy")
#: The only library modules a contract may read: the ROS distributions (the bridge's setting).
CONTRACT_READS = frozenset({"rosmsg.distro"})

#: The libraries below the services: none imports anything under ``services``.
LIBRARIES = ("common", "runtimes", "modelprep", "perception", "rosmsg", "simworld", "depthscan")
#: The libraries' settings modules a service's contract may import (and compose).
LIBRARY_SETTINGS = ("perception.settings",)
#: Serving's load path, and the quantizer it must never reach.
SERVING_LOAD = "perception.loading"
QUANTIZER = "modelprep.quantize"

#: Module -> the project modules it imports, each with the line of its first import there.
Graph = dict[str, dict[str, int]]


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _resolve(module: str, is_package: bool, level: int, name: str) -> str:
    """``name`` imported ``level`` dots up from ``module`` (``from ..x import`` is level 2)."""
    if not level:
        return name
    package = module if is_package else module.rpartition(".")[0]
    for _ in range(level - 1):
        package = package.rpartition(".")[0]
    return f"{package}.{name}" if name else package


def _is_import_module(call: ast.Call) -> bool:
    func = call.func
    name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
    return name == "import_module"


def _literal(node: ast.expr) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def _import_module_package(call: ast.Call) -> str | None:
    """The literal ``package`` a relative ``import_module(name, package)`` resolves against."""
    if len(call.args) > 1:
        return _literal(call.args[1])
    return next((_literal(k.value) for k in call.keywords if k.arg == "package"), None)


def _imported(
    tree: ast.Module, module: str, is_package: bool, known: Container[str]
) -> Iterator[tuple[str, int]]:
    """``(target, line)`` per candidate target; targets not ``known`` are dropped later."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(module, is_package, node.level, node.module or "")
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                yield (sub if sub in known else base), node.lineno
        elif isinstance(node, ast.Call) and _is_import_module(node) and node.args:
            name, package = _literal(node.args[0]), _import_module_package(node)
            if name is not None:
                level = len(name) - len(name.lstrip("."))
                anchor, anchor_is_package = (package, True) if package else (module, is_package)
                yield _resolve(anchor, anchor_is_package, level, name[level:]), node.lineno
        elif isinstance(node, ast.Dict) and node.values:
            # a table of module names, imported lazily by name (BACKENDS, RUNTIMES)
            names = [_literal(value) for value in node.values]
            for name, value in zip(names, node.values, strict=True):
                if name is not None and all(n is not None for n in names):
                    for target in (name, f"{module}.{name}"):
                        if target in known:
                            yield target, value.lineno


def import_graph(sources: Mapping[str, tuple[str, bool]]) -> Graph:
    """Module -> its project imports, from ``{module: (source, is_package)}``."""
    graph: Graph = {}
    for module, (source, is_package) in sorted(sources.items()):
        tree = ast.parse(source, filename=module)
        edges: dict[str, int] = {}
        for target, line in _imported(tree, module, is_package, sources):
            if target in sources and target != module:
                edges[target] = min(line, edges.get(target, line))
        graph[module] = edges
    return graph


def production_sources(root: Path = ROOT) -> dict[str, Path]:
    return {module_name(p, root): p for pkg in PACKAGES for p in sorted((root / pkg).rglob("*.py"))}


def project_graph() -> Graph:
    paths = production_sources()
    return import_graph(
        {m: (p.read_text(encoding="utf-8"), p.name == "__init__.py") for m, p in paths.items()}
    )


def find_cycles(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """The strongly connected components with more than one node (Tarjan), each sorted."""
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


def unit(module: str) -> str:
    """The package unit a module belongs to (see the module docstring)."""
    parts = module.split(".")
    if parts[0] in WHOLE:
        return parts[0]
    if is_contract(module):
        return module
    return ".".join(parts[:2])


def is_contract(module: str) -> bool:
    """A service's contract: ``services.<name>.contract``."""
    parts = module.split(".")
    return len(parts) == 3 and parts[0] == "services" and parts[2] == "contract"


#: Unit -> unit -> one module edge behind it: ``(module, target, line)``.
UnitGraph = dict[str, dict[str, tuple[str, str, int]]]


def unit_graph(graph: Graph) -> UnitGraph:
    units: UnitGraph = {unit(m): {} for m in graph}
    for module, targets in sorted(graph.items()):
        for target, line in sorted(targets.items()):
            here, there = unit(module), unit(target)
            if here != there:
                units[here].setdefault(there, (module, target, line))
    return units


def _a_cycle(graph: Mapping[str, Iterable[str]], members: list[str]) -> list[str]:
    """One cycle through ``members`` (a strongly connected component), starting at its first."""
    inside = set(members)
    start = members[0]
    came_from: dict[str, str] = {}
    frontier = [start]
    while frontier:  # breadth first: the shortest way back to start
        nxt_frontier = []
        for node in frontier:
            for nxt in sorted(graph[node]):
                if nxt == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(came_from[path[-1]])
                    return [*reversed(path), start]
                if nxt in inside and nxt not in came_from:
                    came_from[nxt] = node
                    nxt_frontier.append(nxt)
        frontier = nxt_frontier
    raise AssertionError(f"{members} is not strongly connected")


def describe_unit_cycles(units: UnitGraph) -> list[str]:
    """Each package cycle as one line per hop, with a module edge that makes the hop."""
    lines = []
    for members in find_cycles(units):
        path = _a_cycle(units, members)
        lines.append(f"package cycle among {', '.join(members)}:")
        for here, there in itertools.pairwise(path):
            module, target, line = units[here][there]
            lines.append(f"  {here} -> {there}: {module} imports {target} (line {line})")
    return lines


def describe_module_cycles(graph: Graph) -> list[str]:
    lines = []
    for members in find_cycles(graph):
        path = _a_cycle(graph, members)
        lines.append(f"module cycle among {', '.join(members)}:")
        for here, there in itertools.pairwise(path):
            lines.append(f"  {here} imports {there} (line {graph[here][there]})")
    return lines


def _allowed(module: str, target: str) -> bool:
    """The layers table of the module docstring."""
    top, target_top = module.split(".")[0], target.split(".")[0]
    if top == "common":
        return target_top == "common"
    if is_contract(module):
        return (
            target_top == "common"
            or is_contract(target)
            or target in CONTRACT_READS
            or target in LIBRARY_SETTINGS
        )
    if top == "stack":
        return target_top in ("common", "stack") or is_contract(target)
    if top == "runtimes":
        return target_top in ("common", "runtimes", "modelprep")
    if top == "modelprep":
        return target_top in ("common", "modelprep")
    if top == "perception":
        return target_top in ("common", "runtimes", "modelprep", "perception")
    if top == "rosmsg":
        return target_top in ("common", "rosmsg") or target == "perception"
    if top == "simworld":
        return target_top in ("common", "simworld")
    if top == "depthscan":
        return target_top in ("common", "depthscan") or target == "perception"
    if top == "services":
        below = ("common", "stack", "runtimes", "modelprep", "rosmsg", "simworld", "depthscan")
        if target_top in below or is_contract(target):
            return True
        if target_top == "perception":
            return target == "perception"  # its public API, never its modules
        if target_top != "services":
            return False  # tools, deploy
        package = unit(module)  # another service: only its contract (above)
        return target == package or target.startswith(f"{package}.")
    if top == "tools":
        if target_top == "perception":
            return target == "perception"
        return target_top != "deploy"
    if top == "deploy":
        return target_top in ("common", "stack", "deploy") or is_contract(target)
    raise AssertionError(f"{module} is in no layer")


GRAPH = project_graph()


def _sources(files: Mapping[str, str]) -> dict[str, tuple[str, bool]]:
    """Synthetic sources for :func:`import_graph`, keyed by path: ``{"pkg/__init__.py": ...}``."""
    root = Path("/synthetic")
    return {
        module_name(root / path, root): (source, path.endswith("__init__.py"))
        for path, source in files.items()
    }


# -- the checker sees what it must --------------------------------------------------------------


def test_the_graph_sees_top_level_and_function_level_imports() -> None:
    assert "tools.evaluation.yolo_dataset" in GRAPH["tools.evaluation.datasets"]
    # imported inside ensure_default_model, only when the model must be fetched
    assert "modelprep.acquire.fetch" in GRAPH["modelprep.files"]
    assert "runtimes.base" in GRAPH["runtimes.select"]
    # (no production module imports relatively today; the synthetic test below covers them)


def test_the_graph_sees_the_backend_tables_behind_importlib() -> None:
    # BACKENDS: name -> module, imported by import_backend with importlib
    assert {"runtimes.onnx", "runtimes.openvino", "runtimes.cuda", "runtimes.tensorrt"} <= set(
        GRAPH["runtimes.table"]
    )
    # RUNTIMES: runtime -> a submodule of modelprep.quantize, imported by f"{__name__}.{name}"
    assert {"modelprep.quantize.ort_int8", "modelprep.quantize.nncf_int8"} <= set(
        GRAPH["modelprep.quantize"]
    )


def test_the_graph_sees_import_module_with_a_literal_and_relative_imports() -> None:
    sources = _sources(
        {
            "pkg/__init__.py": "",
            "pkg/a.py": "import importlib\ndef f():\n    return importlib.import_module('pkg.b')\n",
            "pkg/b.py": "from importlib import import_module\nx = import_module('.c', 'pkg')\n",
            "pkg/c.py": "def g():\n    from . import a\n",
        }
    )
    graph = import_graph(sources)
    assert graph["pkg.a"] == {"pkg.b": 3}
    assert graph["pkg.b"] == {"pkg.c": 2}
    assert graph["pkg.c"] == {"pkg.a": 2}
    assert find_cycles(graph) == [["pkg.a", "pkg.b", "pkg.c"]]


def test_find_cycles_reports_each_cycle_once() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"f"}, "f": {"e"}, "g": set()}
    assert find_cycles(graph) == [["a", "b", "c"], ["e", "f"]]


def test_units_are_the_whole_package_or_its_second_level() -> None:
    assert unit("runtimes.onnx_torch.ops") == "runtimes"
    assert unit("deploy.supervisor") == "deploy"
    assert unit("common.boxes") == "common"
    assert unit("perception.pipeline") == "perception"
    assert unit("services.detector.pool") == "services.detector"
    assert unit("services.detector") == "services.detector"
    assert unit("tools.evaluation.datasets") == "tools.evaluation"
    assert unit("tools.launch") == "tools.launch"
    assert unit("modelprep.quantize.nncf_int8") == "modelprep.quantize"
    assert unit("services.detector.contract") == "services.detector.contract"
    assert unit("stack.access") == "stack"
    assert unit("rosmsg.graph") == "rosmsg"
    assert unit("simworld.render") == "simworld"
    assert unit("depthscan.observe") == "depthscan"


def test_a_package_cycle_through_a_function_level_import_is_caught() -> None:
    # the cycle issue 21 found: evaluation imports the detector at module level, and the
    # detector imports evaluation only inside a function; no module cycle, a package one
    sources = _sources(
        {
            "services/detector/__init__.py": "",
            "services/detector/labelled.py": (
                "def f():\n    from tools.evaluation.metrics import g\n"
            ),
            "tools/evaluation/__init__.py": "",
            "tools/evaluation/metrics.py": "def g(): ...\n",
            "tools/evaluation/evaluate.py": "import services.detector\n",
        }
    )
    graph = import_graph(sources)
    assert find_cycles(graph) == []
    lines = describe_unit_cycles(unit_graph(graph))
    assert lines == [
        "package cycle among services.detector, tools.evaluation:",
        "  services.detector -> tools.evaluation: services.detector.labelled imports "
        "tools.evaluation.metrics (line 2)",
        "  tools.evaluation -> services.detector: tools.evaluation.evaluate imports "
        "services.detector (line 1)",
    ]


def test_a_cycle_hidden_behind_importlib_is_caught() -> None:
    # the openvino <-> quantize cycle issue 21 found: one side a table of module names
    sources = _sources(
        {
            "runtimes/__init__.py": "",
            "runtimes/openvino.py": (
                "def f():\n    from modelprep.quantize import quantized_model\n"
            ),
            "modelprep/__init__.py": "",
            "modelprep/quantize/__init__.py": (
                'RUNTIMES = {\n    "openvino": "runtimes.openvino",\n}\n'
            ),
        }
    )
    graph = import_graph(sources)
    assert graph["modelprep.quantize"] == {"runtimes.openvino": 2}
    assert find_cycles(graph) == [["modelprep.quantize", "runtimes.openvino"]]
    assert describe_unit_cycles(unit_graph(graph))[0] == (
        "package cycle among modelprep.quantize, runtimes:"
    )


def test_the_layering_rule_refuses_what_the_table_refuses() -> None:
    # services never import tools or deploy, even lazily
    assert not _allowed("services.metrics.service", "tools.launch")
    assert not _allowed("services.sim.runner", "tools.scenarios.runner")
    assert not _allowed("services.recorder", "deploy.processes")
    assert not _allowed("services.detector.service", "deploy")
    # nor another service's internals, nor its package root: only its contract
    assert not _allowed("services.metrics.service", "services.detector.pool")
    assert not _allowed("services.metrics.service", "services.detector")
    assert not _allowed("services.recorder.channels", "services.ros2")
    assert not _allowed("services.sim.service", "services.ros2.service")
    assert _allowed("services.sim.service", "services.ros2.contract")
    # the ROS message library and the simulated world: for the services and the tools
    assert _allowed("services.recorder.channels", "rosmsg.convert")
    assert _allowed("services.sim.service", "rosmsg.graph")
    assert _allowed("services.sim.service", "simworld.render")
    assert _allowed("tools.benchmarks.ros2", "rosmsg.graph")
    assert _allowed("tools.scenarios.runner", "simworld.scenarios")
    # ... themselves libraries: no service, no stack, not each other
    assert not _allowed("rosmsg.graph", "services.ros2.contract")
    assert not _allowed("rosmsg.graph", "stack.config")
    assert _allowed("rosmsg.depth", "perception")
    assert not _allowed("rosmsg.depth", "perception.depth")
    assert not _allowed("rosmsg.convert", "simworld.world")
    assert not _allowed("simworld.world", "services.sim.contract")
    assert not _allowed("simworld.render", "stack.config")
    assert not _allowed("simworld.render", "rosmsg.images")
    assert not _allowed("simworld.depth", "perception")
    assert not _allowed("perception.depth", "rosmsg.depth")
    assert not _allowed("common.frames", "simworld.world")
    # the virtual scan's library: for the services; it reads no service, not even a contract
    assert _allowed("services.depthscan.intake", "depthscan.observe")
    assert _allowed("depthscan.frame", "perception")
    assert not _allowed("depthscan.frame", "perception.depth")
    assert not _allowed("depthscan.observe", "services.controller.geometry")
    assert not _allowed("depthscan.frame", "services.controller.contract")
    assert not _allowed("depthscan.frame", "stack.config")
    assert not _allowed("perception.depth", "depthscan.frame")
    # a contract reads of the libraries only the ROS distributions
    assert _allowed("services.ros2.contract", "rosmsg.distro")
    assert not _allowed("services.ros2.contract", "rosmsg.typestore")
    assert not _allowed("services.sim.contract", "simworld.world")
    # the detection library's public API, never its modules
    assert _allowed("services.detector.service", "perception")
    assert not _allowed("services.detector.service", "perception.pipeline")
    assert _allowed("tools.evaluation.evaluate", "perception")
    assert not _allowed("tools.evaluation.evaluate", "perception.pipeline")
    # the library itself: below the services and the tools
    assert _allowed("perception.variants", "modelprep.quantize")
    assert _allowed("perception.pipeline", "runtimes.base")
    assert not _allowed("perception.pipeline", "services.detector")
    assert not _allowed("perception.loading", "tools.detector.fast_profile")
    # the libraries own their settings: none reads the detector's contract for them
    assert not _allowed("perception.variants", "services.detector.contract")
    assert not _allowed("perception.tracker", "services.detector.contract")
    assert not _allowed("runtimes.select", "services.detector.contract")
    assert not _allowed("modelprep.quantize", "services.detector.contract")
    assert _allowed("services.detector.contract", "perception.settings")
    assert not _allowed("services.detector.contract", "perception.pipeline")
    assert not _allowed("services.detector.contract", "perception")
    # tools anything but deploy
    assert _allowed("tools.evaluation.evaluate", "simworld.scenarios")
    assert _allowed("tools.scenarios.runner", "tools.launch")
    assert not _allowed("tools.scenarios.runner", "deploy.processes")
    # the lower floors
    assert not _allowed("common.frames", "services.detector")
    assert not _allowed("common.frames", "runtimes.base")
    assert not _allowed("runtimes.base", "services.detector")
    assert not _allowed("runtimes.base", "perception")
    assert _allowed("runtimes.openvino", "modelprep.quantize")
    assert not _allowed("modelprep.quantize", "runtimes.base")
    assert not _allowed("deploy.supervisor", "services.metrics")
    assert not _allowed("deploy.supervisor", "tools.launch")
    # a contract reads only common and other contracts; the stack assembles contracts only
    assert _allowed("services.metrics.contract", "services.detector.contract")
    assert not _allowed("services.detector.contract", "services.detector.pipeline")
    assert not _allowed("services.detector.contract", "stack.access")
    assert _allowed("stack.access", "services.camera.contract")
    assert not _allowed("stack.access", "services.camera.service")
    assert _allowed("services.metrics.aggregate", "services.detector.contract")
    assert _allowed("services.recorder.service", "stack.access")
    assert not _allowed("common.node", "stack.access")


def test_a_service_importing_tools_or_deploy_inside_a_function_is_reported() -> None:
    sources = _sources(
        {
            "services/sim/__init__.py": "",
            "services/sim/runner.py": (
                "def f():\n    import tools.launch\n    from deploy import lock\n"
            ),
            "tools/__init__.py": "",
            "tools/launch.py": "",
            "deploy/__init__.py": "",
            "deploy/lock.py": "",
        }
    )
    graph = import_graph(sources)
    wrong = [(m, t) for m, ts in graph.items() for t in ts if not _allowed(m, t)]
    assert sorted(wrong) == [
        ("services.sim.runner", "deploy.lock"),
        ("services.sim.runner", "tools.launch"),
    ]


def test_a_service_reaching_into_another_service_is_reported() -> None:
    # the recorder and the simulator took the ROS messages from the bridge's package root
    # (issue 40): editing the bridge silently changed them
    sources = _sources(
        {
            "services/ros2/__init__.py": "",
            "services/ros2/contract.py": "",
            "services/ros2/convert.py": "",
            "services/recorder/__init__.py": "",
            "services/recorder/channels.py": (
                "from services.ros2 import convert\nfrom services.ros2.contract import RosDistro\n"
            ),
            "services/sim/__init__.py": "",
            "services/sim/service.py": "def f():\n    import services.ros2\n",
        }
    )
    graph = import_graph(sources)
    wrong = [(m, t) for m, ts in graph.items() for t in ts if not _allowed(m, t)]
    assert sorted(wrong) == [
        ("services.recorder.channels", "services.ros2.convert"),
        ("services.sim.service", "services.ros2"),
    ]


# -- the project keeps the rules ----------------------------------------------------------------


def test_no_module_cycles() -> None:
    lines = describe_module_cycles(GRAPH)
    assert lines == [], "import cycles:\n" + "\n".join(lines)


def test_no_package_cycles() -> None:
    lines = describe_unit_cycles(unit_graph(GRAPH))
    assert lines == [], "package cycles:\n" + "\n".join(lines)


def test_layers_and_no_service_imports_another_services_internals() -> None:
    wrong = sorted(
        f"{module} imports {target} (line {line})"
        for module, targets in GRAPH.items()
        for target, line in targets.items()
        if not _allowed(module, target)
    )
    assert wrong == [], "imports across the layers:\n" + "\n".join(wrong)


def test_no_library_imports_services() -> None:
    wrong = sorted(
        f"{module} imports {target} (line {line})"
        for module, targets in GRAPH.items()
        if module.split(".")[0] in LIBRARIES
        for target, line in targets.items()
        if target.split(".")[0] == "services"
    )
    assert wrong == [], "libraries importing services:\n" + "\n".join(wrong)


def closure(graph: Graph, start: str) -> dict[str, str]:
    """Every module ``start`` reaches, each with the module that first imports it on the way
    (breadth first: a shortest path back to ``start``)."""
    reached = {start: ""}
    frontier = [start]
    while frontier:
        nxt = []
        for module in frontier:
            for target in sorted(graph.get(module, ())):
                if target not in reached:
                    reached[target] = module
                    nxt.append(target)
        frontier = nxt
    return reached


def _path(reached: Mapping[str, str], module: str) -> str:
    hops = [module]
    while reached[hops[-1]]:
        hops.append(reached[hops[-1]])
    return " <- ".join(hops)


def test_the_closure_sees_a_lazy_import_two_hops_away() -> None:
    sources = _sources(
        {
            "lib/__init__.py": "",
            "lib/load.py": "import lib.files\n",
            "lib/files.py": "def f():\n    from lib.quant import q\n",
            "lib/quant.py": "def q(): ...\n",
        }
    )
    reached = closure(import_graph(sources), "lib.load")
    assert _path(reached, "lib.quant") == "lib.quant <- lib.files <- lib.load"


def test_serving_load_path_reaches_no_quantizer() -> None:
    reached = closure(GRAPH, SERVING_LOAD)
    assert "perception.pipeline" in reached and "runtimes.onnx" in reached  # it sees the path
    wrong = [
        _path(reached, m)
        for m in sorted(reached)
        if m == QUANTIZER or m.startswith(QUANTIZER + ".")
    ]
    assert wrong == [], "serving's load path reaches the quantizer:\n" + "\n".join(wrong)
    # preparing does: the check would see it
    assert QUANTIZER in closure(GRAPH, "perception.preparing")


# -- nothing in production reads tests/ ---------------------------------------------------------

#: A path into tests/ (``tests/x``, ``../tests``, a ``"tests"`` part) or a module under it.
TESTS_PATH = re.compile(r"(?:^|[/\\])tests(?:[/\\]|$)|^tests\.")


def _docstrings(tree: ast.Module) -> set[int]:
    """The ids of the docstring nodes (module, class and function docstrings)."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if (
                body
                and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)
            ):
                found.add(id(body[0].value))
    return found


def references_to_tests(source: str) -> list[tuple[int, str]]:
    """``(line, what)`` for each import of ``tests`` and each string that is a path into it."""
    tree = ast.parse(source)
    docstrings = _docstrings(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            names = [node.module or ""]
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in docstrings
        ):
            if TESTS_PATH.search(node.value):
                found.append((node.lineno, repr(node.value)))
            continue
        else:
            continue
        found += [(node.lineno, f"import {n}") for n in names if n.split(".")[0] == "tests"]
    return sorted(found)


def test_the_tests_path_check_sees_paths_and_ignores_docstrings() -> None:
    source = '''"""Reads tests/data/x.json? No: the docstring only mentions it."""
from pathlib import Path
import tests.conftest
ROOT = Path(__file__).resolve().parents[2]
A = ROOT / "tests" / "data"
B = Path("tests", "data")
C = "tests/data/annotations.json"
D = f"{ROOT}/tests/unit"
E = "the tests pass"  # a comment on tests/data is fine
def f():
    """A docstring naming tests/unit is fine."""
'''
    assert references_to_tests(source) == [
        (3, "import tests.conftest"),
        (5, "'tests'"),
        (6, "'tests'"),
        (7, "'tests/data/annotations.json'"),
        (8, "'/tests/unit'"),
    ]


def test_no_production_module_reads_anything_under_tests() -> None:
    found = sorted(
        f"{path.relative_to(ROOT)}:{line}: {what}"
        for path in production_sources().values()
        for line, what in references_to_tests(path.read_text(encoding="utf-8"))
    )
    assert found == [], "production code reaching into tests/:\n" + "\n".join(found)


def test_every_package_is_walked_and_installed() -> None:
    # A new top-level package left out of this table, or of pyproject's package list, would be
    # outside every rule above, or missing from an install.
    from tests.unit.packages import PACKAGES as FOUND

    assert sorted(PACKAGES) == sorted(FOUND)
    pyproject = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    (include,) = re.findall(r"^include = \[(.*)\]$", pyproject, re.M)
    assert sorted(re.findall(r'"(\w+)\*"', include)) == sorted(FOUND)
