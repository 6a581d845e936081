"""The access rules built from the services' contracts are the ones the table in
common/security.py gave before the contracts existed (captured in data/access_before.json)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from common.keys import Keys
from common.security import stack_principals
from stack.access import access_control
from stack.access_table import congestion_overwritten, may_announce, may_put, may_read

BEFORE = json.loads((Path(__file__).parent / "data" / "access_before.json").read_text())


def _case(name: str) -> tuple[dict[str, Any], Keys, Any, tuple[str, ...], bool]:
    case = BEFORE[name]["case"]
    workers = tuple(case.get("workers", ("detector",)))
    return case, Keys(case["keys"]), case["cameras"], workers, case.get("live_sensors", True)


@pytest.mark.parametrize("name", sorted(BEFORE))
def test_the_rules_are_those_of_before_the_contracts(name: str) -> None:
    case, keys, cameras, workers, live = _case(name)
    acl = access_control(keys, cameras, case["auth"], live_sensors=live, workers=workers)
    # the same rules, subjects and policies; each principal's in its contract's order, the
    # principals in the one list's (common/service_list.py), which Zenoh does not read
    assert _canonical(acl) == _canonical(BEFORE[name]["access_control"])


def _canonical(acl: dict[str, Any]) -> str:
    """``acl`` with its rules and subjects by id and its policies by subjects: what the router
    enforces, whatever order the principals' rules come in."""
    out = dict(acl)
    out["rules"] = sorted(acl["rules"], key=lambda r: r["id"])
    out["subjects"] = sorted(acl["subjects"], key=lambda s: s["id"])
    out["policies"] = sorted(acl["policies"], key=lambda p: p["subjects"])
    return json.dumps(out)


@pytest.mark.parametrize("name", sorted(BEFORE))
def test_what_each_principal_may_do_is_as_before(name: str) -> None:
    _, keys, cameras, workers, live = _case(name)
    before = BEFORE[name]
    for p in stack_principals(cameras, workers):
        assert (
            list(may_put(keys, cameras, p, live_sensors=live, workers=workers))
            == (before["may_put"][p])
        )
        assert list(may_announce(keys, cameras, p, workers=workers)) == before["may_announce"][p]
        assert list(may_read(keys, cameras, p)) == before["may_read"][p]
    overwritten = congestion_overwritten(keys, cameras, workers=workers)
    assert len(set(overwritten)) == len(overwritten)
    assert sorted(overwritten) == sorted(before["congestion_overwritten"])


def test_the_cases_cover_one_and_several_cameras_a_pool_and_a_replay() -> None:
    cases = [c["case"] for c in BEFORE.values()]
    assert any(isinstance(c["cameras"], str) for c in cases)
    assert any(isinstance(c["cameras"], dict) and len(c["cameras"]) > 2 for c in cases)
    assert any(len(c.get("workers", ())) > 1 for c in cases)
    assert any(c.get("live_sensors") is False for c in cases)
    assert {c["auth"] for c in cases} == {"password", "certificate"}
