"""The floors in pyproject.toml that correctness needs (docs/library-decisions.md, "Version
floors"), and the installed versions meeting them."""

from __future__ import annotations

import tomllib
from importlib.metadata import version
from pathlib import Path

from packaging.requirements import Requirement
from packaging.version import Version

PYPROJECT = Path(__file__).resolve().parents[2] / "pyproject.toml"

#: Routers before zenoh PR #2603 kept a lost link's liveliness tokens and queryables.
FLOORS = {"eclipse-zenoh": Version("1.10")}


def _requirements() -> dict[str, Requirement]:
    deps = tomllib.loads(PYPROJECT.read_text())["project"]["dependencies"]
    return {r.name: r for r in map(Requirement, deps)}


def test_pyproject_refuses_what_is_below_each_floor() -> None:
    requirements = _requirements()
    for name, floor in FLOORS.items():
        spec = requirements[name].specifier
        assert floor in spec, f"{name} {spec} refuses {floor}"
        below = Version(f"{floor.major}.{floor.minor - 1}.99")
        assert below not in spec, f"{name} {spec} accepts {below}, below the floor {floor}"


def test_the_installed_versions_meet_the_floors() -> None:
    for name, floor in FLOORS.items():
        assert Version(version(name)) >= floor, f"{name} {version(name)} is below {floor}"
