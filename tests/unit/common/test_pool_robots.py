"""One pool, several robots (common/pool_rule.py's :func:`assign_pool`): properties of the rule
over many random pools, and a worker that lists two robots kept to its share of the pool."""

from __future__ import annotations

import random

from common.pool_audit import PoolAudit
from common.pool_rule import PoolCamera, PoolWorker, assign, assign_pool, pool_name

BALANCE = 1.25


def random_pool(seed: int) -> tuple[dict[str, PoolWorker], dict[str, PoolCamera]]:
    rng = random.Random(seed)
    robots = [f"robot{i}" for i in range(1, rng.randint(1, 4) + 1)]
    workers = {
        f"w{i}": PoolWorker(
            rng.choice([5.0, 10.0, 30.0]),
            frozenset(rng.sample(robots, rng.randint(1, len(robots)))),
        )
        for i in range(rng.randint(1, 5))
    }
    cameras = {
        pool_name(robot, f"cam{j}", "robot1"): PoolCamera(robot, f"cam{j}", rng.choice([2.0, 5.0]))
        for robot in robots
        for j in range(rng.randint(0, 6))
    }
    return workers, cameras


def test_every_camera_of_a_listed_robot_has_one_eligible_owner_in_any_order() -> None:
    for seed in range(200):
        workers, cameras = random_pool(seed)
        owners = assign_pool(workers, cameras, BALANCE)
        listed = {p for w in workers.values() for p in w.prefixes}
        assert set(owners) == {n for n, c in cameras.items() if c.prefix in listed}, seed
        for name, worker in owners.items():
            assert cameras[name].prefix in workers[worker].prefixes, (seed, name, worker)
        shuffled = dict(reversed(workers.items())), dict(reversed(cameras.items()))
        assert assign_pool(*shuffled, BALANCE) == owners, seed


def test_one_robot_is_assigned_as_before() -> None:
    """A pool of one robot: exactly :func:`assign` over the workers' capacities (today's)."""
    for seed in range(200):
        workers, cameras = random_pool(seed)
        robot = {"robot1"}
        workers = {w: PoolWorker(p.capacity_hz, frozenset(robot)) for w, p in workers.items()}
        mine = {n: c for n, c in cameras.items() if c.prefix == "robot1"}
        capacities = {w: p.capacity_hz for w, p in workers.items()}
        rates = {n: c.rate_hz for n, c in mine.items()}
        assert assign_pool(workers, mine, BALANCE) == assign(capacities, rates, BALANCE), seed


def test_a_worker_serving_two_robots_takes_its_share_of_the_pool_not_of_each() -> None:
    """``both`` lists robot1 and robot2, ``one`` robot1 and ``two`` robot2, all equally fast,
    each robot with six cameras of 5 Hz: ``both``'s load stays within balance x the pool's
    load x its third of the capacity (25 Hz), since the others have room. A whole share of
    each robot would give it 30 Hz, half as much again as the others."""
    one, two = frozenset({"robot1"}), frozenset({"robot2"})
    workers = {
        "both": PoolWorker(10.0, one | two),
        "one": PoolWorker(10.0, one),
        "two": PoolWorker(10.0, two),
    }
    cameras = {
        pool_name(r, f"cam{j}", "robot1"): PoolCamera(r, f"cam{j}", 5.0)
        for r in ("robot1", "robot2")
        for j in range(6)
    }
    owners = assign_pool(workers, cameras, BALANCE)
    load = {w: sum(cameras[n].rate_hz for n, o in owners.items() if o == w) for w in workers}
    total = sum(c.rate_hz for c in cameras.values())
    for worker, got in load.items():
        assert got <= BALANCE * total * 10.0 / 30.0, (worker, load)
    assert load["both"] <= load["one"] + load["two"]  # not the lion's share


def test_a_fast_worker_takes_more_of_each_robot_it_shares() -> None:
    both = frozenset({"robot1", "robot2"})
    workers = {"gpu": PoolWorker(40.0, both), "cpu": PoolWorker(10.0, both)}
    cameras = {
        pool_name(r, f"cam{j}", "robot1"): PoolCamera(r, f"cam{j}", 5.0)
        for r in ("robot1", "robot2")
        for j in range(5)
    }
    owners = assign_pool(workers, cameras, BALANCE)
    for robot in ("robot1", "robot2"):
        gpu = sum(1 for n, o in owners.items() if o == "gpu" and cameras[n].prefix == robot)
        assert gpu == 4, (robot, owners)  # 4/5 of each robot, as the capacities are


def test_the_audit_computes_what_the_workers_serve() -> None:
    """common/pool_audit.py over the rule's own owners: nothing to report, in any pool."""
    for seed in range(100):
        workers, cameras = random_pool(seed)
        owners = assign_pool(workers, cameras, BALANCE)
        serving = {(w, f"z{w}", name) for name, w in owners.items()}
        audit = PoolAudit({}, BALANCE, 1.0)
        audit.check(0.0, workers, serving, cameras=cameras)
        report = audit.check(2.0, workers, serving, cameras=cameras)
        unlisted = {n for n, c in cameras.items() if n not in owners}
        assert {(f.kind, f.subject) for f in report.current} == {
            ("unserved", n) for n in unlisted
        }, seed
