"""The simulator service: the robot's cameras, laser and base, driven by cmd_vel over Zenoh.

Every configured camera is rendered from the same world, each on its own key
(services/sim/cameras.py says at what size and rate). With ``sim.depth`` each camera is an
RGB-D camera: every colour frame comes with a depth image of the same instant, under the same
header (simworld/depth.py). With ``sim.laser`` false the robot has no laser: no scan.

The robot talks either way a robot may: the stack's own messages (``StackRobot``), or ROS 2 over
rmw_zenoh (``RosRobot``: sensor_msgs Image and LaserScan, with depth a depth Image and its
CameraInfo, geometry_msgs Twist or TwistStamped, through a router it hosts), so that every frame,
depth image, scan and command passes through the ``ros2`` bridge service. Either way its
velocity commands go through ``SimHandlers``.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable
from contextlib import ExitStack
from typing import Protocol

import numpy as np

from common.bus import Bus, Publisher, QoS
from common.camera_announce import CameraAnnouncements
from common.clock import mono_s, wall_ns
from common.command_sources import CommandSources
from common.counters import per_camera
from common.errors import ConfigError, DecodeError
from common.frames import image_to_frame
from common.lifecycle import Closing
from common.messages import DepthFrame, Frame, GroundTruth, LaserScan, Twist
from common.node import Node, Tally
from rosmsg.convert import LASER_SCAN, TWIST, TWIST_STAMPED, cdr_decode, scan_to_ros, twist_from_ros
from rosmsg.depth import CAMERA_INFO, camera_info_of, depth_to_image
from rosmsg.graph import RosGraph, RosPublisher
from rosmsg.images import IMAGE, frame_to_image
from rosmsg.wire import SENSOR_DATA_QOS
from services.ros2.contract import camera_topics
from services.sim import contract
from services.sim.cameras import SimCamera, sim_cameras
from services.sim.pacing import Pace
from services.sim.waiting import WARN_PERIOD_S, Waiting, waiting_line
from services.sim.worlds import Faults, world_for, world_line
from simworld.depth import depth_frame
from simworld.laser import LaserSpec, cast
from simworld.render import render
from simworld.scenarios import SCENARIOS
from simworld.world import World
from stack.config import Config


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


OnCommand = Callable[[Twist, str], None]

#: What the simulator says it is in its cameras' announcements.
ANNOUNCED_SOURCE = "sim"


class SimHandlers:
    """The velocity commands that reach the simulated base, decoded: the stack's Twist (from
    the publisher ``source``) or ROS 2's (through the router the robot hosts). Garbage is
    counted as bad input; a command goes to ``on_command(twist, source)``."""

    def __init__(self, config: Config, tally: Tally, on_command: OnCommand) -> None:
        self.distro = config.ros2.distro
        self.ros_type = TWIST_STAMPED if config.ros2.twist_stamped else TWIST
        self.tally = tally
        self.on_command = on_command

    def on_cmd_vel(self, payload: bytes, source: str) -> None:
        twist = self.tally.decode(self.tally.keys.cmd_vel(), Twist.decode, payload)
        if twist is not None:
            self.on_command(twist, source)

    def on_ros_cmd_vel(self, key: str, cdr: memoryview) -> None:
        """``key``: the rmw_zenoh data key the sample came on."""
        try:
            msg = cdr_decode(self.distro, self.ros_type, cdr)
            twist = twist_from_ros(msg, source="ros2", received_ns=wall_ns())
        except DecodeError as exc:
            self.tally.bad_input(key, exc)
            return
        self.on_command(twist, "ros2")


class SensorOutput(Protocol):
    def frame(self, camera: str, frame: Frame) -> None: ...
    def depth(self, camera: str, frame: DepthFrame) -> None: ...
    def scan(self, scan: LaserScan) -> None: ...


class StackRobot:
    """Sensors on the stack's keys (each camera's frames and depth images on its own);
    commands from the controller's cmd_vel key."""

    def __init__(self, config: Config, node: Node, handlers: SimHandlers) -> None:
        keys = node.keys
        cameras = config.all_cameras
        self._frames = {
            camera: node.publisher(keys.frame(camera), QoS.SENSOR) for camera in cameras
        }
        self._depths = (
            {camera: node.publisher(keys.depth(camera), QoS.SENSOR) for camera in cameras}
            if config.sim.depth
            else {}
        )
        self._scan = node.publisher(keys.scan(), QoS.SENSOR) if config.sim.laser else None
        self._sub = node.bus.subscribe(
            keys.cmd_vel(), lambda sample: handlers.on_cmd_vel(sample.payload, sample.source)
        )

    def frame(self, camera: str, frame: Frame) -> None:
        self._frames[camera].put(frame.encode())

    def depth(self, camera: str, frame: DepthFrame) -> None:
        self._depths[camera].put(frame.encode())

    def scan(self, scan: LaserScan) -> None:
        if self._scan is not None:
            self._scan.put(scan.encode())

    def close(self) -> None:
        self._sub.undeclare()


class RosRobot(Closing):
    """Sensors as ROS 2 messages on the rmw_zenoh keys of ``config.ros2``'s topics; commands
    taken from its cmd_vel topic. Hosts the graph's router on ``ros2.router``. One image topic:
    the first camera's frames alone (``run`` renders no other camera for it). With
    ``sim.depth`` that camera is an RGB-D camera as its driver publishes one: each depth image
    a 16UC1 ``sensor_msgs/Image`` (mm) on ``ros2.depth_topic`` and its ``CameraInfo`` (the
    intrinsics) on ``ros2.depth_info_topic``, both under the header (stamp, frame id) of the
    colour image it goes with, so the bridge (``ros2.depth_in``) pairs them. No laser
    (``sim.laser`` false): no scan topic."""

    def __init__(self, config: Config, handlers: SimHandlers) -> None:
        s = config.ros2
        self._distro = s.distro
        self._graph = RosGraph(dataclasses.replace(s, node="sim_robot"), host=True)
        self._image = self._graph.publisher(s.image_topic, IMAGE, SENSOR_DATA_QOS)
        self._scan = (
            self._graph.publisher(s.scan_topic, LASER_SCAN, SENSOR_DATA_QOS)
            if config.sim.laser
            else None
        )
        self._depth: RosPublisher | None = None
        self._depth_info: RosPublisher | None = None
        if config.sim.depth:
            # The first camera's topics: the ros2 table's own (services/ros2/contract.py).
            topics = camera_topics(s, config.stack.camera, config.stack.camera)
            publish = self._graph.publisher
            self._depth = publish(topics.depth, IMAGE, SENSOR_DATA_QOS)
            self._depth_info = publish(topics.depth_info, CAMERA_INFO, SENSOR_DATA_QOS)
        self._graph.subscribe(s.cmd_vel_topic, handlers.ros_type, handlers.on_ros_cmd_vel)

    def frame(self, camera: str, frame: Frame) -> None:
        self._image.put(frame_to_image(self._distro, frame))

    def depth(self, camera: str, frame: DepthFrame) -> None:
        if self._depth is None or self._depth_info is None:
            raise RuntimeError("a depth image from a simulated ROS 2 robot without sim.depth")
        # The CameraInfo first, as with every image: the bridge takes no depth before one.
        self._depth_info.put(camera_info_of(self._distro, frame))
        self._depth.put(depth_to_image(self._distro, frame))

    def scan(self, scan: LaserScan) -> None:
        if self._scan is not None:
            self._scan.put(scan_to_ros(self._distro, scan))

    def close(self) -> None:
        self._graph.close()


def build_world(config: Config) -> World:
    name = config.sim.scenario
    if name not in SCENARIOS:
        raise ConfigError(f"unknown sim.scenario {name!r}; known: {', '.join(SCENARIOS)}")
    return SCENARIOS[name].build()


def announce_cameras(
    announcements: CameraAnnouncements,
    cameras: list[SimCamera],
    physics_hz: float,
    depth: bool = False,
) -> None:
    """Announce each camera the simulator renders on the stack's keys, as it renders it (no
    faster than the physics: frames are rendered on its ticks); with ``depth``, as an RGB-D
    camera at its height above the floor."""
    for c in cameras:
        announcements.announce(
            c.name, c, rate_hz=min(c.rate_hz, physics_hz), width=c.spec.width,
            height=c.spec.height, depth=depth, mount_height_m=None if depth else 0.0,
        )  # fmt: skip


def run(config: Config, stop: threading.Event, *, bus: Bus | None = None) -> int:
    """Simulate in real time until ``stop`` is set (``bus``: an in-process test's).

    Each camera whose frames it puts on the stack's keys is announced (CameraAnnouncement,
    common/camera_announce.py) while it runs; as a ROS 2 robot (``sim.ros2_robot``) it puts
    none there, and the ``ros2`` bridge that does announces them."""
    s = config.sim
    world = world_for(s, build_world(config))
    cameras = sim_cameras(config)
    if s.ros2_robot:
        cameras = cameras[:1]  # one image topic (the supervisor warns of the others)
    with ExitStack() as closing:
        node = closing.enter_context(Node("sim", config, bus=bus))
        lock = threading.Lock()
        truth_pub = node.publisher(node.keys.sim_truth(), QoS.TELEMETRY)
        handlers = SimHandlers(config, node, _base(world, lock, node, s))
        out = _robot(closing, config, node, cameras, handlers)
        _say_setup(node, config, cameras)

        def live(key: str) -> bool:
            return bool(node.bus.live_tokens(key, timeout_s=0.2))

        waiting = Waiting(node.bus, node.keys, s.wait_for, [c.name for c in cameras], live)
        closing.callback(waiting.close)
        node.ready()
        closing.callback(node.log.info, "stopping")  # first, however it ends
        _simulate(config, node, world, lock, waiting, out, truth_pub, cameras, stop)
    return 0


def _base(
    world: World, lock: threading.Lock, node: Node, s: contract.SimSettings
) -> Callable[[Twist, str], None]:
    """What drives the base: a velocity command from ``source`` (a publisher's id), counted
    and refused when out of range, warned of when several publishers command at once."""
    sources = CommandSources(s.command_sources_window_s)

    def command(twist: Twist, source: str) -> None:
        with lock:
            active, new = sources.heard(source, mono_s())
            sane = world.command(twist.linear[0], twist.angular[2])
        if not sane:
            node.reject(
                contract.COMMANDS_OUT_OF_RANGE,
                f"cmd_vel v={twist.linear[0]:g} w={twist.angular[2]:g} is beyond what the "
                f"base takes (from {twist.header.source!r}): refused, the base stops",
            )
        if active > 1:
            node.reject(
                contract.COMMANDS_FROM_SEVERAL_SOURCES,
                f"cmd_vel from {active} publishers at once "
                f"(this one from {twist.header.source!r}, {source})",
            )
            if new:
                node.log.warning("another publisher on cmd_vel: %s", sources.active())

    return command


def _robot(
    closing: ExitStack, config: Config, node: Node, cameras: list[SimCamera], handlers: SimHandlers
) -> SensorOutput:
    """Where the sensors go, closed by ``closing``: a ROS 2 robot that hosts the graph's
    router (as a robot runs rmw_zenohd), or the stack's own keys, each camera announced."""
    s = config.sim
    if s.ros2_robot:
        return closing.enter_context(RosRobot(config, handlers))
    stack_robot = StackRobot(config, node, handlers)
    closing.callback(stack_robot.close)
    announcements = closing.enter_context(
        CameraAnnouncements(node.bus, node.keys, ANNOUNCED_SOURCE)
    )
    announce_cameras(announcements, cameras, s.physics_hz, depth=s.depth)
    return stack_robot


def _say_setup(node: Node, config: Config, cameras: list[SimCamera]) -> None:
    """The scenario, the cameras and what the robot lacks, in the log."""
    s = config.sim
    node.log.info("scenario %r: %s", s.scenario, SCENARIOS[s.scenario].description)
    node.log.info("%s", world_line(s))  # which world and faults run (worlds.parse_world_line)
    for c in cameras:
        node.log.info(
            "camera %r: %dx%d at %.1f Hz, hfov %.0f deg, looking %+.0f deg",
            c.name, c.spec.width, c.spec.height, c.rate_hz, c.spec.hfov_deg,
            c.spec.mount_yaw_deg,
        )  # fmt: skip
    if s.depth and s.ros2_robot:
        node.log.info(
            "sim.depth: depth images on %s, their CameraInfo on %s",
            config.ros2.depth_topic, config.ros2.depth_info_topic,
        )  # fmt: skip
    if not s.laser:
        node.log.info("sim.laser = false: a robot with no laser, no scan")
    missing = [c for c in SCENARIOS[s.scenario].cameras if c not in config.all_cameras]
    if missing:
        node.log.warning(
            "scenario %r is meant to be seen by cameras %s too, which the config lacks "
            "(the scenario runner adds them: python -m tools.scenarios scenario %s)",
            s.scenario, missing, s.scenario,
        )  # fmt: skip


def _simulate(
    config: Config, node: Node, world: World, lock: threading.Lock, waiting: Waiting,
    out: SensorOutput, truth_pub: Publisher, cameras: list[SimCamera], stop: threading.Event,
) -> None:  # fmt: skip
    """The physics' loop, in real time until ``stop``: the world stands still at t=0 until
    what ``sim.wait_for`` names has come, its sensors publishing on the wall clock meanwhile."""
    s = config.sim
    laser = LaserSpec(
        s.laser_fov_deg, s.laser_rays, 0.05, s.laser_range_max_m, s.laser_noise_m, s.laser_height_m
    )
    rng = np.random.default_rng(s.seed)
    faults = Faults(s, cameras)  # the cameras' faults, each on a random stream of its own

    def new_clocks() -> dict[str, Clock]:
        return {
            **{f"frame:{c.name}": Clock(c.rate_hz) for c in cameras},
            **({"scan": Clock(s.scan_rate_hz)} if s.laser else {}),
            "truth": Clock(s.truth_rate_hz),
        }

    clocks = new_clocks()
    dt = 1.0 / s.physics_hz
    pace = Pace(dt, max(1, round(s.catch_up_max_s / dt)))
    behind_ms = 0
    started = False
    boot = next_tick = next_check = mono_s()
    next_warning = boot + WARN_PERIOD_S
    while not stop.is_set():
        now = mono_s()
        if not started and now >= next_check:
            # Until what sim.wait_for names has come (the detections of every camera, the
            # controller ready) the world stands still at t=0 but its sensors publish on the
            # wall clock, so the detector warms up on real frames; then the scenario clock
            # starts from 0.
            next_check = now + 0.5
            missing = waiting.missing()
            started = not missing
            if started:
                clocks = new_clocks()
                pace.start(now)
                node.log.info("scenario clock started")
            elif now >= next_warning:
                next_warning = now + WARN_PERIOD_S
                node.log.warning("%s", waiting_line(missing, now - boot))
        with lock:
            if started:
                # The world keeps the wall clock's time (pacing.py): a slow pass takes the
                # steps it is owed, so a starved simulator does not slow the robot's base.
                for _ in range(pace.due(now)):
                    world.advance(dt)
                if int(pace.given_up_s * 1000) > behind_ms:
                    node.counters.add(
                        contract.PHYSICS_BEHIND_MS, int(pace.given_up_s * 1000) - behind_ms
                    )
                    behind_ms = int(pace.given_up_s * 1000)
            t = world.t if started else now - boot
            _publish_due(
                node, world, t, clocks, out, truth_pub, cameras, laser, rng, faults,
            )  # fmt: skip
        node.publish_counters()
        next_tick = max(next_tick + dt, mono_s() - dt)
        stop.wait(max(0.0, next_tick - mono_s()))


def _publish_due(
    node: Node,
    world: World,
    t: float,
    clocks: dict[str, Clock],
    out: SensorOutput,
    truth_pub: Publisher,
    cameras: list[SimCamera],
    laser: LaserSpec,
    rng: np.random.Generator,
    faults: Faults,
) -> None:
    """Put what is due at scenario time ``t``: each camera's frame with its colour faults
    (and, with ``sim.depth``, its depth image under the same header, its faults drawn against
    the clean image), the scan (when it has a clock: a laser) and the truth."""
    r = world.robot
    pose = (r.x, r.y, r.theta)
    for camera in cameras:
        if clocks[f"frame:{camera.name}"].due(t):
            header = node.header(frame_id=camera.frame_id)
            image = render(world, camera.spec)
            shown = faults.colour(camera, image, world, t)
            out.frame(camera.name, image_to_frame(shown, header, jpeg_quality=camera.jpeg_quality))
            _count(node, contract.FRAMES_OUT, camera.name, len(cameras))
            if faults.depth is not None:
                noisy = faults.depth_image(camera, image, world)
                out.depth(camera.name, depth_frame(noisy, camera.spec, header, faults.depth))
                _count(node, contract.DEPTH_OUT, camera.name, len(cameras))
    if "scan" in clocks and clocks["scan"].due(t):
        scan = LaserScan(
            header=node.header(frame_id="laser"),
            angle_min=laser.angle_min,
            angle_increment=laser.angle_increment,
            range_min=laser.range_min,
            range_max=laser.range_max,
            ranges=cast(
                pose,
                world.laser_circles(laser.height_m),
                laser,
                rng,
                segments=world.laser_walls(laser.height_m),
            ),
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


def _count(node: Node, counter: str, camera: str, cameras: int) -> None:
    node.counters.add(counter)
    if cameras > 1:  # the total above, and each camera's (common/counters.py)
        node.counters.add(per_camera(counter, camera))
