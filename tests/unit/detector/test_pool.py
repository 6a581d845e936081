"""The pool's assignment rule (services/detector/pool.py)."""

from __future__ import annotations

import pytest

from common.pool_rule import camera_rates, label, pool_name
from services.camera.contract import CameraSettings
from services.detector.pool import PoolCamera, PoolView, PoolWorker, assign, assign_pool, rank

EVEN = {f"cam{i}": 1.0 for i in range(12)}


def test_same_membership_same_assignment_in_any_order() -> None:
    a = assign(["w1", "w2", "w3"], EVEN, 1.25)
    b = assign(["w3", "w1", "w2", "w1"], dict(reversed(EVEN.items())), 1.25)
    assert a == b


def test_rank_is_stable_across_runs() -> None:
    # blake2b, not Python's salted hash(): the same number on every host and run.
    assert rank("front", "detector") == 0xFF6A8A796776AED8


def test_every_camera_has_exactly_one_live_owner() -> None:
    workers = ["a", "b", "c"]
    owners = assign(workers, EVEN, 1.25)
    assert set(owners) == set(EVEN)
    assert set(owners.values()) <= set(workers)


def test_no_worker_no_owner_and_one_worker_owns_all() -> None:
    assert assign([], EVEN, 1.25) == {}
    assert set(assign(["detector"], EVEN, 1.25).values()) == {"detector"}


def test_loads_stay_within_the_bound() -> None:
    workers = ["a", "b", "c", "d"]
    owners = assign(workers, EVEN, 1.25)
    counts = [list(owners.values()).count(w) for w in workers]
    assert max(counts) <= 1.25 * len(EVEN) / len(workers)


def test_a_joining_worker_takes_only_a_share() -> None:
    before = assign(["a", "b", "c"], EVEN, 1.25)
    after = assign(["a", "b", "c", "d"], EVEN, 1.25)
    moved = {c for c in EVEN if before[c] != after[c]}
    taken = {c for c, w in after.items() if w == "d"}
    # The newcomer takes about a quarter; a full first choice may shift one or two more.
    assert 1 <= len(taken) <= 1.25 * len(EVEN) / 4
    assert len(moved) <= len(taken) + 2


def test_a_leaving_worker_hands_on_only_its_cameras_when_loads_allow() -> None:
    workers = ["a", "b", "c", "d"]
    before = assign(workers, EVEN, 4.0)  # room to spare: pure rendezvous
    after = assign(["a", "b", "c"], EVEN, 4.0)
    moved = {c for c in EVEN if before[c] != after[c]}
    assert moved == {c for c, w in before.items() if w == "d"}


def test_heavy_cameras_spread() -> None:
    weights = {"big1": 10.0, "big2": 10.0, "small1": 1.0, "small2": 1.0}
    for pair in (["a", "b"], ["detector", "detector_2"], ["x", "y"]):
        owners = assign(pair, weights, 1.25)
        assert owners["big1"] != owners["big2"], pair


def test_balance_below_one_is_refused() -> None:
    with pytest.raises(ValueError, match="balance"):
        assign(["a"], EVEN, 0.5)


def test_a_configs_cameras_weigh_their_frame_rates() -> None:
    cams = {
        "hd": CameraSettings(rate_hz=10.0, resize=(1280, 720)),
        "source_size": CameraSettings(rate_hz=5.0),
    }
    assert camera_rates(cams) == {"hd": 10.0, "source_size": 5.0}


def test_a_camera_of_another_robot_is_named_with_its_prefix() -> None:
    assert pool_name("stack", "front", "stack") == "front"
    assert pool_name("site/robot2", "front", "stack") == "site/robot2/front"
    assert label("site/robot2/front") == "site:robot2:front"
    assert label("r.2/front") == "r_2:front"  # a counter's camera follows its last dot
    assert label("front") == "front"


def test_each_robots_cameras_go_to_the_workers_that_list_it_by_capacity() -> None:
    cams = {
        **{f"c{i}": PoolCamera("r1", f"c{i}", 5.0) for i in range(8)},
        **{f"r2/c{i}": PoolCamera("r2", f"c{i}", 5.0) for i in range(4)},
    }
    workers = {
        "gpu": PoolWorker(30.0, frozenset({"r1", "r2"})),
        "cpu": PoolWorker(10.0, frozenset({"r1"})),
    }
    owners = assign_pool(workers, cams, 1.0)
    assert set(owners) == set(cams)
    assert {owners[f"r2/c{i}"] for i in range(4)} == {"gpu"}  # only gpu lists r2
    # gpu's 30 split evenly between its two robots: 15 against cpu's 10 for r1, 3/5 of it
    assert sum(1 for i in range(8) if owners[f"c{i}"] == "gpu") == 5
    assert assign_pool({"cpu": workers["cpu"]}, cams, 1.0) == {f"c{i}": "cpu" for i in range(8)}


def test_view_reports_gains_and_losses() -> None:
    cams = {c: PoolCamera("stack", c, 5.0) for c in "abcd"}
    one = frozenset({"stack"})
    view = PoolView("w1", PoolWorker(1.0, one), 1.25)
    view.cameras = cams
    first = view.settle()
    assert set(first.gained) == set(cams) and first.lost == () and first.members == 1
    view.joined("w2")
    assert view.settle().gained == ()  # a token alone is no member
    assert view.strays() == ["w2"]
    view.announced["w2"] = PoolWorker(1.0, one)
    shared = view.settle()
    assert shared.gained == () and 1 <= len(shared.lost) <= 3 and shared.members == 2
    assert shared.serving == set(cams) - set(shared.lost)
    view.left("w2")
    back = view.settle()
    assert set(back.gained) == set(shared.lost) and back.serving == set(cams)
    view.left("w1")  # its own token's loss: it keeps counting itself
    assert view.settle().serving == set(cams)
