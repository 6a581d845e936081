"""One list of services (common/service_list.py): the names, the principals, the stack
config's tables, the access table, the live sensors and the watchdog's heartbeats all come from
it and the services' contracts; no other list of them is written by hand; and a service added to
the list alone shows up in each (the Config's typed table, the one more line, is asked for)."""

from __future__ import annotations

import ast
import dataclasses
import sys
import types
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from common import settings
from common.access import Access, Shape
from common.keys import Keys
from common.security import PRINCIPALS, ROUTER_PRINCIPAL, SERVICE_PRINCIPALS
from common.service_list import SERVICES
from deploy.watchdog import HEARTBEAT_SERVICES
from stack.access_table import LIVE_SENSORS, access_table
from stack.config import Config
from stack.contracts import (
    SHARED_TABLES,
    check_config_tables,
    heartbeat_services,
    live_sensors,
    settings_tables,
)

ROOT = Path(__file__).resolve().parents[3]
SHAPE = Shape(Keys("stack"), {"front": "camera"}, ("detector",), True, (), "")


def test_each_service_is_a_folder_of_the_list_and_each_folder_is_listed() -> None:
    folders = {p.parent.name for p in (ROOT / "services").glob("*/contract.py")}
    assert folders == set(SERVICES)
    for name in SERVICES:
        for part in ("contract.py", "service.py", "__main__.py"):
            assert (ROOT / "services" / name / part).is_file(), (name, part)


def test_the_names_and_principals_are_the_list() -> None:
    assert settings.SERVICES is SERVICES
    assert SERVICE_PRINCIPALS is SERVICES
    assert (ROUTER_PRINCIPAL, *SERVICES, "estop", "observer") == PRINCIPALS
    assert set(SERVICES) <= set(access_table(SHAPE))


def test_config_has_exactly_the_tables_the_listed_services_declare() -> None:
    check_config_tables(Config)
    fields = {f.name for f in dataclasses.fields(Config)} - {"path", *SHARED_TABLES}
    assert fields == set(settings_tables())
    hints = {f.name: f.type for f in dataclasses.fields(Config)}
    for table, cls in settings_tables().items():
        assert hints[table] in (cls, cls.__name__)
        assert Config().__getattribute__(table) == cls()


def test_the_live_sensors_and_heartbeats_come_from_the_contracts() -> None:
    assert {"camera", "sim", "ros2"} == LIVE_SENSORS
    assert {"camera", "sim", "ros2", "detector", "depthscan", "controller"} == HEARTBEAT_SERVICES


def _lists_of_services(tree: ast.AST, exempt: set[int]) -> Iterator[tuple[int, list[str]]]:
    """Each tuple, list or set literal naming three or more services, but those ``exempt``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Tuple | ast.List | ast.Set) and id(node) not in exempt:
            values = {e.value for e in node.elts if isinstance(e, ast.Constant)}
            names = {v for v in values if isinstance(v, str) and v in SERVICES}
            if len(names) >= 3:
                yield node.lineno, sorted(names)


def _defaults_of_supervisor_services(tree: ast.AST) -> set[int]:
    """The default of ``supervisor.services``: which of the services a stack runs unless told
    (the simulated robot's), a choice among them and not a list of them."""
    return {
        id(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.AnnAssign)
        and isinstance(node.target, ast.Name)
        and node.target.id == "services"
        and node.value is not None
    }


def hand_written_lists(root: Path) -> list[str]:
    """Where a module of common/, stack/ or deploy/ (but the list's own) names the services."""
    found = []
    for package in ("common", "stack", "deploy"):
        for path in sorted((root / package).rglob("*.py")):
            if path == root / "common" / "service_list.py":
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"))
            exempt = _defaults_of_supervisor_services(tree) if path.name == "config.py" else set()
            found += [
                f"{path.relative_to(root)}:{line} {names}"
                for line, names in _lists_of_services(tree, exempt)
            ]
    return found


def test_no_other_list_of_services_is_written_by_hand() -> None:
    assert hand_written_lists(ROOT) == []


def test_the_check_finds_the_lists_of_before(tmp_path: Path) -> None:
    """The lists the tree had before the one list, each found."""
    (tmp_path / "common").mkdir()
    (tmp_path / "deploy").mkdir()
    (tmp_path / "common" / "security.py").write_text(
        'SERVICE_PRINCIPALS = ("recorder", "camera", "sim", "ros2", "detector")\n'
    )
    (tmp_path / "deploy" / "watchdog.py").write_text(
        'HEARTBEAT_SERVICES = frozenset({"camera", "sim", "ros2", "detector", "controller"})\n'
    )
    assert hand_written_lists(tmp_path) == [
        "common/security.py:1 ['camera', 'detector', 'recorder', 'ros2', 'sim']",
        "deploy/watchdog.py:1 ['camera', 'controller', 'detector', 'ros2', 'sim']",
    ]


@dataclass(frozen=True, slots=True, kw_only=True)
class FakeSettings:
    level: int = 1


@pytest.fixture
def fake_service() -> Iterator[tuple[str, ...]]:
    """A service ``fake`` whose contract declares a table, its access, a live sensor and a
    heartbeat: the list with it added."""
    contract = types.ModuleType("services.fake.contract")
    contract.SETTINGS_TABLES = {"fake": FakeSettings}  # type: ignore[attr-defined]
    contract.LIVE_SENSOR = True  # type: ignore[attr-defined]
    contract.HEARTBEAT = True  # type: ignore[attr-defined]
    contract.access = lambda shape: {"fake": Access(put=(shape.keys.counters("fake"),))}  # type: ignore[attr-defined]
    sys.modules["services.fake.contract"] = contract
    try:
        yield (*SERVICES, "fake")
    finally:
        del sys.modules["services.fake.contract"]


def test_a_service_added_to_the_list_alone_shows_up_everywhere(
    fake_service: tuple[str, ...],
) -> None:
    assert settings_tables(fake_service)["fake"] is FakeSettings
    assert "fake" in live_sensors(fake_service) and "fake" in heartbeat_services(fake_service)
    assert access_table(SHAPE, fake_service)["fake"].put == ("stack/counters/fake",)
    with pytest.raises(TypeError, match=r"fake: FakeSettings = field\(default_factory="):
        check_config_tables(Config, fake_service)  # the one more line: its typed table
    with_fake = dataclasses.make_dataclass(
        "Config",
        [("fake", FakeSettings, field(default_factory=FakeSettings))],
        bases=(Config,),
        frozen=True,
        kw_only=True,
    )
    check_config_tables(with_fake, fake_service)
