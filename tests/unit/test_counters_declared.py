"""Every counter a service counts by name is a constant its contract declares
(``services/<name>/contract.py``), never a string written at the call: what the metrics
service and the tools read is then checked against the same declaration
(tests/unit/metrics/test_contract.py), so a renamed counter cannot silently zero a figure."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: Calls that count: the counter is their first argument ...
FIRST = {"add", "reject", "count", "_gauge", "per_camera"}
#: ... or their third (``count_for(tally, camera, name)``).
THIRD = {"count_for", "reject_for"}


def counted(source: str) -> list[tuple[int, ast.expr]]:
    """``(line, counter argument)`` of each counting call in ``source``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
        index = 0 if name in FIRST else 2 if name in THIRD else None
        if index is not None and len(node.args) > index:
            found.append((node.lineno, node.args[index]))
    return found


def undeclared(package: str, source: str) -> list[str]:
    contract = importlib.import_module(f"services.{package}.contract")
    wrong = []
    for line, arg in counted(source):
        if isinstance(arg, ast.JoinedStr) or (
            isinstance(arg, ast.Constant) and isinstance(arg.value, str)
        ):
            wrong.append(f"{line}: {ast.unparse(arg)} written at the call")
        elif (
            isinstance(arg, ast.Attribute)
            and isinstance(arg.value, ast.Name)
            and arg.value.id == "contract"
        ):
            value = getattr(contract, arg.attr)
            if isinstance(value, str) and value not in contract.COUNTERS:
                wrong.append(f"{line}: contract.{arg.attr} is not in its COUNTERS")
    return wrong


def test_the_check_sees_literals_and_undeclared_constants() -> None:
    source = (
        'node.counters.add("frames_out")\n'
        'count_for(tally, cam, f"x_{y}")\n'
        "node.reject(contract.FRAMES_OUT, 'a message is fine')\n"
        "node.counters.add(contract.LIVE_SENSOR_NAME)\n"
    )
    assert len(counted(source)) == 4
    assert undeclared("camera", source.replace("LIVE_SENSOR_NAME", "FRAMES_OUT")) == [
        "1: 'frames_out' written at the call",
        "2: f'x_{y}' written at the call",
    ]


def test_every_service_counts_only_what_its_contract_declares() -> None:
    wrong = []
    for path in sorted((ROOT / "services").glob("*/*.py")):
        if path.name == "contract.py" or not (path.parent / "contract.py").exists():
            continue
        package = path.parent.name
        for what in undeclared(package, path.read_text(encoding="utf-8")):
            wrong.append(f"{path.relative_to(ROOT)}:{what}")
    assert wrong == []
