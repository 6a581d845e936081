"""Which announced cameras the pool admits (issue 39, items 3 and 4; common/pool_rule.py's
``admit_cameras``): at most ``detector.max_robot_cameras`` of one robot, and never two whose
counter labels collide (``cam.x`` and ``cam_x``: one slot, one set of counters). The rest are
refused with a warning and counted, by every worker alike."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest

from common.clock import FakeClock
from common.memory_bus import MemoryHub
from common.pool_rule import PoolCamera, admit_cameras, counter_key
from services.detector import contract
from tests.unit.conftest import MEMORY_BUS_SEED
from tests.unit.detector.inprocess import CameraSource, Worker, cameras_config


@pytest.fixture
def hub(delivery_threads: int) -> Iterator[MemoryHub]:
    """The bus: delivering in the putting thread, or on threads of its own (conftest.py)."""
    hub = MemoryHub(threads=delivery_threads, seed=MEMORY_BUS_SEED)
    yield hub
    hub.close()


def test_admitted_by_name_alike_everywhere() -> None:
    cams = {f"robot2/c{i:02d}": PoolCamera("robot2", f"c{i:02d}", 5.0) for i in range(20)}
    cams["front"] = PoolCamera("stack", "front", 5.0)
    kept, refused = admit_cameras(cams, 16)
    assert "front" in kept, "one robot's many cameras never crowd another's out"
    assert sorted(refused) == [f"robot2/c{i}" for i in range(16, 20)]
    assert sum(1 for c in kept.values() if c.prefix == "robot2") == 16
    # The same, whatever order they were heard in.
    assert admit_cameras(dict(reversed(list(cams.items()))), 16) == (kept, refused)
    # Names whose counter labels collide: the first by name is kept.
    two = {n: PoolCamera("robot2", n.split("/")[1], 5.0) for n in ("robot2/cam_x", "robot2/cam.x")}
    assert counter_key("robot2/cam.x") == counter_key("robot2/cam_x") == "robot2:cam_x"
    kept, refused = admit_cameras(two, 16)
    assert list(kept) == ["robot2/cam.x"]
    assert "camera robot2/cam.x's" in refused["robot2/cam_x"]


def test_a_worker_refuses_a_robots_cameras_over_the_cap_and_colliding_labels(
    hub: MemoryHub, caplog: pytest.LogCaptureFixture
) -> None:
    clock = FakeClock()
    CameraSource(hub).announce("front")
    robot2 = CameraSource(hub, "robot2")
    for cam in ("c0", "c1", "c2", "cam.x", "cam_x", "zz"):
        robot2.announce(cam)
    config = cameras_config(("front",), prefixes=("stack", "robot2"), max_robot_cameras=4)
    worker = Worker(hub, clock, config, "detector")
    caplog.set_level(logging.WARNING)
    worker.pool.join()
    served = worker.loop_pass()
    assert "front" in served
    # By name: c0, c1, c2 and cam.x (label robot2:cam_x) admitted; cam_x (the same label)
    # refused, then zz (over the cap of 4).
    assert sorted(c for c in served if c.startswith("robot2:")) == [
        "robot2:c0", "robot2:c1", "robot2:c2", "robot2:cam_x",
    ]  # fmt: skip
    assert worker.count(contract.CAMERAS_REFUSED) == 2
    said = [r.message for r in caplog.records if "refused by the pool" in r.message]
    assert len(said) == 2, said
    assert any("robot2/cam_x" in m and "counter label" in m for m in said), said
    assert any("robot2/zz" in m and "detector.max_robot_cameras" in m for m in said), said
    # A withdrawn camera makes room: zz is admitted; cam_x stays refused while cam.x lives.
    robot2.withdraw("c0")
    served = worker.loop_pass()
    assert "robot2:zz" in served and worker.count(contract.CAMERAS_REFUSED) == 1
