"""The simulator service: the robot's camera, laser and base, driven by cmd_vel over Zenoh."""

from __future__ import annotations

import threading
from contextlib import ExitStack

import numpy as np

from common.bus import Publisher, QoS
from common.clock import mono_s
from common.command_sources import CommandSources
from common.errors import ConfigError
from common.frames import image_to_frame
from common.messages import GroundTruth, LaserScan, Twist
from common.node import Node
from common.settings import Config
from services.sim.laser import LaserSpec, cast
from services.sim.render import CameraSpec, render
from services.sim.robot_io import RosRobot, SensorOutput, StackRobot
from services.sim.scenarios import SCENARIOS
from services.sim.world import World


class Clock:
    """Fires every ``period`` seconds of scenario time."""

    def __init__(self, rate_hz: float) -> None:
        self.period = 1.0 / rate_hz
        self.next = 0.0

    def due(self, t: float) -> bool:
        if t + 1e-9 < self.next:
            return False
        self.next = max(self.next + self.period, t)
        return True


def build_world(config: Config) -> World:
    name = config.sim.scenario
    if name not in SCENARIOS:
        raise ConfigError(f"unknown sim.scenario {name!r}; known: {', '.join(SCENARIOS)}")
    return SCENARIOS[name].build()


def run(config: Config, stop: threading.Event) -> int:
    """Simulate in real time until ``stop`` is set."""
    s = config.sim
    world = build_world(config)
    lock = threading.Lock()
    camera = CameraSpec(s.width, s.height, config.camera.hfov_deg, s.camera_height_m)
    laser = LaserSpec(s.laser_fov_deg, s.laser_rays, 0.05, s.laser_range_max_m, s.laser_noise_m)
    rng = np.random.default_rng(s.seed)
    sources = CommandSources(s.command_sources_window_s)
    with Node("sim", config) as node, ExitStack() as closing:
        keys = node.keys

        def command(twist: Twist, source: str) -> None:
            """A velocity command reached the base, from ``source`` (a publisher's id)."""
            with lock:
                active, new = sources.heard(source, mono_s())
                sane = world.command(twist.linear[0], twist.angular[2])
            if not sane:
                node.reject(
                    "commands_out_of_range",
                    f"cmd_vel v={twist.linear[0]:g} w={twist.angular[2]:g} is beyond what the "
                    f"base takes (from {twist.header.source!r}): refused, the base stops",
                )
            if active > 1:
                node.reject(
                    "commands_from_several_sources",
                    f"cmd_vel from {active} publishers at once "
                    f"(this one from {twist.header.source!r}, {source})",
                )
                if new:
                    node.log.warning("another publisher on cmd_vel: %s", sources.active())

        truth_pub = node.publisher(keys.sim_truth(), QoS.TELEMETRY)
        out: SensorOutput
        if s.ros2_robot:
            # The robot speaks ROS 2: it hosts the graph's router, as a robot runs rmw_zenohd.
            out = closing.enter_context(RosRobot(config, node, command))
        else:
            stack_robot = StackRobot(config, node, command)
            closing.callback(stack_robot.close)
            out = stack_robot

        def new_clocks() -> dict[str, Clock]:
            return {
                "frame": Clock(s.camera_rate_hz),
                "scan": Clock(s.scan_rate_hz),
                "truth": Clock(s.truth_rate_hz),
            }

        clocks = new_clocks()
        node.log.info("scenario %r: %s", s.scenario, SCENARIOS[s.scenario].description)
        node.ready()
        dt = 1.0 / s.physics_hz
        started = False
        boot = next_tick = next_check = mono_s()
        try:
            while not stop.is_set():
                now = mono_s()
                if not started and now >= next_check:
                    # Until the detector and controller are ready the world stands still at
                    # t=0 but its sensors publish on the wall clock, so the detector warms up
                    # on real frames; then the scenario clock starts from 0.
                    next_check = now + 0.5
                    started = _ready(node, s.wait_for)
                    if started:
                        clocks = new_clocks()
                        node.log.info("scenario clock started")
                with lock:
                    if started:
                        world.advance(dt)
                    t = world.t if started else now - boot
                    _publish_due(node, world, t, clocks, out, truth_pub, camera, laser, rng, config)
                node.publish_counters()
                next_tick = max(next_tick + dt, mono_s() - dt)
                stop.wait(max(0.0, next_tick - mono_s()))
        finally:
            node.log.info("stopping")
    return 0


def _ready(node: Node, services: tuple[str, ...]) -> bool:
    for service in services:
        replies = list(node.session.liveliness().get(node.keys.health(service), timeout=0.2))
        if not any(r.ok is not None for r in replies):
            return False
    return True


def _publish_due(
    node: Node,
    world: World,
    t: float,
    clocks: dict[str, Clock],
    out: SensorOutput,
    truth_pub: Publisher,
    camera: CameraSpec,
    laser: LaserSpec,
    rng: np.random.Generator,
    config: Config,
) -> None:
    r = world.robot
    pose = (r.x, r.y, r.theta)
    if clocks["frame"].due(t):
        header = node.header(frame_id=config.camera.frame_id)
        frame = image_to_frame(
            render(world, camera), header, jpeg_quality=config.camera.jpeg_quality
        )
        out.frame(frame)
        node.counters.add("frames_out")
    if clocks["scan"].due(t):
        scan = LaserScan(
            header=node.header(frame_id="laser"),
            angle_min=laser.angle_min,
            angle_increment=laser.angle_increment,
            range_min=laser.range_min,
            range_max=laser.range_max,
            ranges=cast(pose, world.circles(), laser, rng),
        )
        out.scan(scan)
    if clocks["truth"].due(t):
        truth = GroundTruth(
            header=node.header(frame_id="world"),
            sim_time_s=world.t,
            robot=pose,
            robot_velocity=(r.v, r.w),
            targets_xy=world.target_positions(),
            target_names=tuple(t.name for t in world.targets),
            target_ids=tuple(t.id for t in world.targets),
            obstacles=world.obstacle_circles(),
        )
        truth_pub.put(truth.encode())
