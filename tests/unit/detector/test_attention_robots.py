"""Attention in a worker serving two robots (services/detector/attention.py, "Several robots"):
each robot's controller status heard on its own key (rounds.heed_controllers, as the service
subscribes), its lock and its target classes applied to its own cameras only, by their labels
in the pool. In-process on a MemoryHub with a FakeClock; the pool (services/detector/
membership.py) names the cameras."""

from __future__ import annotations

from dataclasses import replace

from common.bus import QoS
from common.clock import FakeClock
from common.memory_bus import MemoryHub
from common.messages import ControllerStatus
from common.node import Node
from services.detector.attention import Attention
from services.detector.rounds import heed_controllers
from tests.unit.detector.inprocess import CameraSource, Worker, cameras_config

ROBOTS = ("robot1", "robot2")


def two_robot_worker() -> tuple[MemoryHub, FakeClock, Worker, Attention]:
    base = cameras_config(("front",))
    config = replace(
        base,
        stack=replace(base.stack, prefix="robot1"),
        detector=replace(base.detector, prefixes=ROBOTS),
    )
    hub, clock = MemoryHub(), FakeClock()
    for robot in ROBOTS:  # both robots have a camera named front, and robot1 a rear too
        source = CameraSource(hub, robot)
        source.announce("front")
        if robot == "robot1":
            source.announce("rear")
    worker = Worker(hub, clock, config, "detector")
    worker.pool.join()
    attention = Attention(clock, floor_hz=0.5, hold_s=2.0)
    heed_controllers(worker.node, config, attention)
    return hub, clock, worker, attention


def status(hub: MemoryHub, clock: FakeClock, robot: str, camera: str, target: str) -> None:
    base = cameras_config(("front",))
    config = replace(base, stack=replace(base.stack, prefix=robot))
    node = Node("controller", config, bus=hub.join(f"controller_{robot}"), clock=clock)
    node.publisher(node.keys.controller_status(), QoS.TELEMETRY).put(
        ControllerStatus(
            header=node.header(),
            mode="follow",
            target=target,
            state="following",
            camera=camera,
            target_classes=(target,),
        ).encode()
    )


def test_robot2s_lock_gives_priority_to_robot2s_camera_only() -> None:
    hub, clock, worker, attention = two_robot_worker()
    served = sorted(worker.loop_pass())
    assert served == ["front", "rear", "robot2:front"]
    attention.taken(served)  # all taken just now: none due for its floor
    status(hub, clock, "robot2", "front", "person")
    assert attention.priority() == {"robot2:front"}
    order = attention.arrange(served)
    assert order[0] == ("robot2:front", "priority")
    assert {c for c, why in order if why == "priority"} == {"robot2:front"}
    status(hub, clock, "robot1", "rear", "person")  # robot1's lock adds its own, robot2's holds
    assert attention.priority() == {"robot2:front", "rear"}
    status(hub, clock, "robot2", "", "person")  # robot2's target lost: robot1's lock stays
    assert attention.priority() == {"rear"}


def test_a_sighting_counts_against_its_own_robots_target_classes() -> None:
    hub, clock, worker, attention = two_robot_worker()
    served = sorted(worker.loop_pass())
    attention.taken(served)
    status(hub, clock, "robot1", "", "person")
    status(hub, clock, "robot2", "", "dog")
    attention.saw("robot2:front", ["person"])  # robot2 follows dogs: no priority
    attention.saw("front", ["dog"])  # robot1 follows people: none either
    assert attention.priority() == frozenset()
    attention.saw("robot2:front", ["dog"])
    attention.saw("rear", ["person"])
    assert attention.priority() == {"robot2:front", "rear"}
