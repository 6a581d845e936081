"""The configs of several robots on one pool (tools/scenarios/robots.py), checked without
starting them."""

from __future__ import annotations

from common.contracts import ControllerMode
from common.settings import REPO_ROOT
from stack.config_file import load_config
from tools.scenarios.robots import robots_plan


def test_each_robot_has_its_own_prefix_and_the_pool_serves_every_one() -> None:
    base = load_config(REPO_ROOT / "deploy" / "stack.toml", environ={})
    plan = robots_plan(base, "ahead", robots=3, workers=2, mode=ControllerMode.FOLLOW)
    prefixes = [r.stack.prefix for r in plan.robots]
    assert len(set(prefixes)) == 3 and all("/" not in p for p in prefixes)
    assert plan.pool.detector.prefixes == tuple(prefixes)
    assert plan.pool.detector.workers == 2
    assert plan.pool.supervisor.services == ("detector",)
    assert plan.pool.stack.prefix not in prefixes
    for robot in plan.robots:
        assert robot.supervisor.services == ("sim", "controller", "metrics")
        assert robot.zenoh.connect == (plan.pool.zenoh.endpoint,)
        assert robot.sim.scenario == "ahead" and robot.sim.wait_for == ("controller",)
    endpoints = {r.zenoh.endpoint for r in (*plan.robots, plan.pool)}
    assert len(endpoints) == 4
