"""The pool's audit (common/pool_audit.py): what is wrong with its tokens, once it has lasted."""

from __future__ import annotations

from common.pool_audit import MAX_LINES, PoolAudit, Report, lines
from common.pool_rule import PoolCamera, PoolWorker, assign, assign_pool

EVEN = {"front": 0.5, "rear": 0.5}
ALARM_S = 10.0


def kinds(report: Report) -> set[tuple[str, str]]:
    return {(f.kind, f.subject) for f in report.current}


def test_a_healthy_pool_is_quiet() -> None:
    audit = PoolAudit(EVEN, 1.0, ALARM_S)
    owners = assign(["a", "b"], EVEN, 1.0)
    serving = {(w, f"z{w}", c) for c, w in owners.items()}
    assert kinds(audit.check(0.0, {"a", "b"}, serving)) == set()
    assert kinds(audit.check(100.0, {"a", "b"}, serving)) == set()


def test_a_member_that_serves_nothing_leaves_its_camera_unserved() -> None:
    audit = PoolAudit(EVEN, 1.0, ALARM_S)
    [given] = [c for c, w in assign(["a", "zz"], EVEN, 1.0).items() if w == "zz"]
    [kept] = set(EVEN) - {given}
    serving = {("a", "za", kept)}
    assert audit.check(0.0, {"a", "zz"}, serving).current == []  # a hand-over's moment
    early = audit.check(ALARM_S - 0.1, {"a", "zz"}, serving)
    assert early.current == [] and early.raised == []
    report = audit.check(ALARM_S, {"a", "zz"}, serving)
    assert kinds(report) == {("idle_member", "zz"), ("unserved", given)}
    assert len(report.raised) == 2
    assert "pool member zz serves none" in report.current[0].text(ALARM_S)
    again = audit.check(ALARM_S + 1, {"a", "zz"}, serving)
    assert again.raised == [] and len(again.current) == 2  # raised once
    # The stray goes; the worker takes every camera: cleared.
    back = {("a", "za", "front"), ("a", "za", "rear")}
    cleared = audit.check(ALARM_S + 2, {"a"}, back)
    assert cleared.current == [] and {f.kind for f in cleared.cleared} == {
        "idle_member",
        "unserved",
    }


def test_two_tables_two_servers_and_one_name_twice() -> None:
    audit = PoolAudit(EVEN, 1.0, ALARM_S)
    serving = {
        ("a", "z1", "front"), ("a", "z1", "rear"),  # one host
        ("a", "z2", "front"), ("a", "z2", "rear"),  # another, with the same worker id
        ("b", "z3", "front"),  # a worker whose table gives it front too
    }  # fmt: skip
    audit.check(0.0, {"a", "b"}, serving)
    found = kinds(audit.check(ALARM_S, {"a", "b"}, serving))
    assert ("served_twice", "front") in found
    assert ("served_twice", "rear") in found
    assert ("name_twice", "a") in found
    assert ("unserved", "front") not in found


def test_no_live_worker_leaves_every_camera_unserved() -> None:
    # Issue 39: a robot whose pool is on a shared box that is down hears no worker at all;
    # its cameras are unserved, and the audit says so (before, no live worker was no word).
    audit = PoolAudit(EVEN, 1.0, ALARM_S)
    audit.check(0.0, set(), set())
    report = audit.check(ALARM_S * 2, set(), set())
    assert kinds(report) == {("unserved", "front"), ("unserved", "rear")}
    assert "(no live detector worker)" in report.current[0].detail


def test_a_condition_that_stops_and_returns_starts_its_time_again() -> None:
    audit = PoolAudit(EVEN, 1.0, ALARM_S)
    audit.check(0.0, {"a"}, set())  # both cameras unserved from 0
    audit.check(ALARM_S / 2, {"a"}, {("a", "z", "front"), ("a", "z", "rear")})
    assert audit.check(ALARM_S, {"a"}, set()).current == []  # unserved again since ALARM_S
    assert len(audit.check(2 * ALARM_S, {"a"}, set()).current) == 3  # idle a, both unserved


def test_a_flood_of_stray_tokens_is_said_in_a_bounded_number_of_lines() -> None:
    audit = PoolAudit(EVEN, 1.0, ALARM_S)
    # Made-up serving tokens: 100 names each held by two sessions.
    members = {"a"}
    serving = {("a", "z", "front"), ("a", "z", "rear")}
    serving |= {(f"w{i}", z, "rear") for i in range(100) for z in ("z1", "z2")}
    audit.check(0.0, members, serving)
    report = audit.check(ALARM_S, members, serving)
    said = lines(report.raised, ALARM_S)
    assert len(said) == MAX_LINES + 1
    assert said[-1] == f"and {len(report.raised) - MAX_LINES} more findings about the pool"


def test_announced_members_and_cameras_are_audited_by_capacity_and_robot() -> None:
    """As the workers audit (issue 31): members with their announced capacity and robots,
    cameras as announced. The fast worker serving all of robot r1's cameras is what the rule
    gives it; robot r2's camera, which no member lists, is unserved."""
    audit = PoolAudit({}, 1.0, ALARM_S)
    cameras = {
        "front": PoolCamera("r1", "front", 2.0),
        "rear": PoolCamera("r1", "rear", 2.0),
        "r2/front": PoolCamera("r2", "front", 2.0),
    }
    members = {
        "fast": PoolWorker(30.0, frozenset({"r1"})),
        "slow": PoolWorker(1.0, frozenset({"r1"})),
    }
    owners = assign_pool(members, cameras, 1.0)
    assert owners == {"front": "fast", "rear": "fast"}  # slow's share is under one camera
    serving = {("fast", "zf", "front"), ("fast", "zf", "rear")}
    audit.check(0.0, members, serving, cameras=cameras)
    report = audit.check(ALARM_S, members, serving, cameras=cameras)
    assert kinds(report) == {("unserved", "r2/front")}
    assert "no worker serves its robot" in report.current[0].detail
