"""Who touches Zenoh inside services/ and the libraries they stand on (docs/architecture.md,
"Handlers and the bus"), read with ``ast``: in each service package only ``service.py`` does,
and besides it only ``rosmsg/graph.py``, the session a node holds in a robot's ROS 2 graph, and
``services/controller/estop_command.py``, the e-stop command's. Everything else reaches the bus
through the ``Bus`` protocol (common/bus.py) it is handed, which an in-process test fills with
the in-memory bus (common/memory_bus.py).

A module touches Zenoh when it imports zenoh or the stack's session modules (at module level
or inside a function), imports the ROS 2 graph, or reaches for a Zenoh session: an attribute
named ``session``, ``declare_subscriber``, ``declare_publisher`` or ``declare_queryable``, or a
call ``.liveliness()``.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: What opens a Zenoh session, holds one or asks one.
BUS_MODULES = frozenset(
    {"zenoh", "common.zenoh_bus", "common.queries", "common.reach", "rosmsg.graph"}
)
#: A Zenoh session's own declarations (the Bus protocol's ``declare_token`` is not one).
SESSION_CALLS = frozenset({"declare_subscriber", "declare_publisher", "declare_queryable"})
#: The ROS 2 graph's I/O, as a name imported from the message library (``from rosmsg import
#: graph``).
GRAPH_NAMES = frozenset({"RosGraph", "RosPublisher", "graph"})
#: The folders read: the services and the libraries below them.
SCANNED = ("services", "perception", "rosmsg", "simworld")

#: Beside every services/<name>/service.py.
ALLOWED = {
    "rosmsg/graph.py": "the ROS 2 graph's own session, for the bridge and the simulator",
    "services/controller/estop_command.py": "the e-stop command's own session, apart from the "
    "controller's service so that its first put imports nothing else",
}


def _touches(tree: ast.Module) -> Iterator[str]:
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "zenoh" or alias.name in BUS_MODULES:
                    yield f"line {node.lineno}: import {alias.name}"
        elif isinstance(node, ast.ImportFrom) and node.module is not None:
            names = {alias.name for alias in node.names}
            if (
                node.module.split(".")[0] == "zenoh"
                or node.module in BUS_MODULES
                or (node.module == "rosmsg" and names & GRAPH_NAMES)
                or (node.module == "common" and {"zenoh_bus", "queries", "reach"} & names)
            ):
                yield f"line {node.lineno}: from {node.module} import {', '.join(sorted(names))}"
        elif isinstance(node, ast.Attribute) and (
            node.attr == "session" or node.attr in SESSION_CALLS
        ):
            yield f"line {node.lineno}: .{node.attr}"
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "liveliness"
            and not node.args
        ):
            yield f"line {node.lineno}: .liveliness()"


def bus_modules() -> dict[str, list[str]]:
    """Every module under services/ (and the libraries, ``SCANNED``) that touches the bus, with
    where."""
    found = {}
    for path in sorted(path for folder in SCANNED for path in (ROOT / folder).rglob("*.py")):
        where = list(_touches(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))))
        if where:
            found[path.relative_to(ROOT).as_posix()] = where
    return found


def test_only_service_modules_and_the_ros2_graph_touch_the_bus() -> None:
    offenders = {
        module: where
        for module, where in bus_modules().items()
        if not (module.startswith("services/") and Path(module).name == "service.py")
        and module not in ALLOWED
    }
    assert not offenders, (
        "only services/<name>/service.py (and the modules in ALLOWED) may touch the bus; move "
        f"the I/O there and hand the logic bytes: {offenders}"
    )


def test_the_rule_sees_the_bus() -> None:
    # The check is not blind: the modules that do touch the bus are found.
    found = bus_modules()
    assert {"rosmsg/graph.py", "services/recorder/service.py"} <= found.keys()
    assert set(ALLOWED) <= found.keys(), "an allowed module no longer touches the bus: drop it"
