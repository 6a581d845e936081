"""The stacks of ``zstack pool-benchmark --robots N`` (tools/benchmarks/pool_robots.py),
checked without starting them, and its table."""

from __future__ import annotations

from pathlib import Path

from common.settings import REPO_ROOT
from stack.config_file import load_config
from tools.benchmarks.pool_robots import ROBOT_CAMERAS, RobotsRun, render, robots_configs


def test_the_pool_serves_every_robots_prefix_and_the_robots_meet_it(tmp_path: Path) -> None:
    base = load_config(REPO_ROOT / "deploy" / "stack.toml", environ={})
    pool, *robots = robots_configs(base, tmp_path, 2, 5.0)
    assert pool.detector.prefixes == tuple(r.stack.prefix for r in robots)
    assert pool.supervisor.services == ("detector",) and pool.detector.workers == 2
    for r in robots:
        assert "/" not in r.stack.prefix and r.supervisor.services == ("sim",)
        assert r.zenoh.connect == (pool.zenoh.endpoint,) and r.sim.wait_for == ()
        assert len(r.all_cameras) == ROBOT_CAMERAS
        assert all(c.rate_hz == 5.0 for c in r.all_cameras.values())


def test_the_table_gives_the_ratio_robots_over_one_robot() -> None:
    robots = RobotsRun("robots", 2, {"a/x": 4.0, "b/x": 4.0}, {"a/x": 50, "b/x": 60},
                       {"a/x": 100.0, "b/x": 300.0})  # fmt: skip
    one = RobotsRun("one robot", 1, {"x": 5.0, "y": 5.0}, {"x": 50, "y": 50},
                    {"x": 150.0, "y": 100.0})  # fmt: skip
    text = render([robots, one])
    assert "det/s 0.80x, worst p95 2.00x" in text
    assert "robots    2 robot(s), 2 cameras: 8.0 det/s, worst p50 60 ms, p95 300 ms" in text
