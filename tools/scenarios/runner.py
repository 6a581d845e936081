"""``python -m tools.scenarios scenario NAME``: run the real stack against a scripted world.

The runner writes a private stack config (a free port or ``--port``'s, a unique key prefix,
the simulator in place of the camera, the controller in follow mode (or the mode asked for),
the scenario's own further cameras and detector changes, the controller's state files in the
run's own folder in ``$TMPDIR``), starts it under the supervisor, records the truth, the
commands, and every camera's frames and detections, stops it, and scores the run
(tools/scenarios/score.py).
"""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import threading
import uuid
from pathlib import Path
from typing import Any

import zenoh

from common.clock import mono_s, wall_ns
from common.contracts import ControllerMode, DistanceSource, ScenarioResult
from common.errors import DecodeError, StackError
from common.keys import Keys
from common.messages import ControllerStatus, Detections, Frame, GroundTruth, Twist
from common.zenoh_bus import open_session
from services.sim.worlds import world_for, world_line
from simworld.scenarios import SCENARIOS, Scenario
from stack.config import Config
from stack.config_file import to_toml
from tools.launch import (
    private_state,
    run_folder,
    service_pids,
    start_supervisor,
    stop_supervisor,
)
from tools.ports import private_endpoint
from tools.scenarios.depth_truth import depth_error
from tools.scenarios.score import ScenarioLog, score

STARTUP_TIMEOUT_S = 180.0  # model load and warm-up on a busy 2-core machine
STOP_TIMEOUT_S = 30.0  # then the whole stack is killed
#: The longest a scripted detector kill waits past its time for the robot to move.
KILL_WAIT_MOVING_S = 5.0
SETTLE_CHECK_S = 0.5  # how often a run that may end early is scored so far


def scenario_config(
    base: Config,
    scenario: Scenario,
    ros2: bool = False,
    mode: ControllerMode = ControllerMode.FOLLOW,
    endpoint: str | None = None,
) -> Config:
    """``base`` made private to one run of ``scenario``, the controller in ``mode``, its
    router on ``endpoint`` (default: the next private one, tools/launch.py). With
    ``ros2`` the simulator plays a ROS 2 robot on a private router, and the ``ros2`` bridge
    carries its sensors and commands.
    The cameras are ``base``'s first camera and the scenario's further ones (each laid over
    [camera], as a ``[cameras.<name>]`` table is), whatever further cameras ``base`` has: a
    scenario is seen by the same cameras on every machine."""
    zenoh_s = dataclasses.replace(
        base.zenoh,
        endpoint=endpoint or private_endpoint(),
        connect=(),
        listen=("tcp/127.0.0.1:0",),
    )
    changes = dict(scenario.controller)
    if base.controller.distance_source is DistanceSource.DEPTH and "distance_source" in changes:
        # A robot that measures by depth (deploy/depth.toml: it has no laser) keeps doing so,
        # whatever distance source the scenario names: a run of a depth config tests depth.
        # The obstacle scenario's "box" (so that the laser's view of the box is the obstacle
        # stop alone) does not apply to it: its depth camera sees the box either way.
        del changes["distance_source"]
    controller = dataclasses.replace(
        base.controller,
        mode=mode,
        target_classes=("person",),
        **changes,
    )
    bridge = ("ros2",) if ros2 else ()
    stage = ("depthscan",) if controller.needs_depth else ()  # its virtual scans
    # A simulated ROS 2 robot with depth: the bridge takes its depth in, and announces its
    # camera at the height the simulator renders from (the virtual scan takes the floor out
    # by it), as the simulator does on the stack's keys.
    depth_over_ros2 = ros2 and base.sim.depth
    camera = (
        dataclasses.replace(base.camera, mount_height_m=base.sim.camera_height_m)
        if depth_over_ros2
        else base.camera
    )
    cameras = tuple(
        (name, dataclasses.replace(base.camera, **changes))
        for name, changes in scenario.cameras.items()
    )
    return dataclasses.replace(
        base,
        zenoh=zenoh_s,
        camera=camera,
        cameras=cameras,
        detector=dataclasses.replace(base.detector, **scenario.detector),
        stack=dataclasses.replace(base.stack, prefix=f"sim/{uuid.uuid4().hex[:8]}"),
        controller=controller,
        sim=dataclasses.replace(
            base.sim,
            scenario=scenario.name,
            ros2_robot=ros2,
            wait_for=(*base.sim.wait_for, *bridge),
        ),
        ros2=dataclasses.replace(
            base.ros2,
            router=(private_endpoint(),) if ros2 else base.ros2.router,
            depth_in=base.ros2.depth_in or depth_over_ros2,
        ),
        supervisor=dataclasses.replace(
            base.supervisor,
            services=("sim", *bridge, "detector", *stage, "controller", "metrics"),
        ),
    )


#: Why the runner changes these settings for every scenario (those of the scenario itself
#: give the scenario's reason).
RUNNER_REASONS = {
    "controller.mode": "a scenario runs in the mode asked: --mode, default follow",
    "controller.target_classes": "every scenario's target is a person",
    "supervisor.services": "a scenario runs its own stack: the simulator, detector, controller "
    "(with the depth scan stage when it needs depth) and metrics",
}


def _table_changes(name: str, before: Any, after: Any, own: dict[str, Any], why: str) -> list[str]:
    lines = []
    for f in dataclasses.fields(after):
        old, new = getattr(before, f.name), getattr(after, f.name)
        if old != new:
            setting = f"{name}.{f.name}"
            reason = why if f.name in own else RUNNER_REASONS.get(setting, "the scenario runner")
            lines.append(f"{setting}: {_shown(old)} -> {_shown(new)} ({reason})")
    return lines


def _shown(value: Any) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(map(str, value)) + "]"
    return str(value)


def config_changes(base: Config, config: Config, scenario: Scenario) -> list[str]:
    """What of ``base`` (the user's config) the scenario's ``config`` changes, one line each
    with why: the cameras, the detector, the controller and the services. What only makes the
    run private (endpoint, prefix, the simulator's scenario) is left out."""
    own = f"scenario {scenario.name!r}"
    why = own + (f": {scenario.why}" if scenario.why else "")
    kept = dict(config.cameras)
    lines = [
        f"cameras.{name}: left out (a scenario is seen by its own cameras on every machine)"
        for name, _ in base.cameras
        if name not in kept
    ]
    lines += [
        f"cameras.{name}: added ({own}: {scenario.description})"
        for name in kept
        if name not in dict(base.cameras)
    ]
    lines += _table_changes("detector", base.detector, config.detector, scenario.detector, why)
    lines += _table_changes(
        "controller", base.controller, config.controller, scenario.controller, own
    )
    if base.camera.mount_height_m != config.camera.mount_height_m:
        lines.append(
            f"camera.mount_height_m: {base.camera.mount_height_m:g} -> "
            f"{config.camera.mount_height_m:g} (the simulated ROS 2 robot's depth camera: "
            "sim.camera_height_m)"
        )
    if base.ros2.depth_in != config.ros2.depth_in:
        lines.append(
            "ros2.depth_in: false -> true (the simulated ROS 2 robot's depth comes through the "
            "bridge)"
        )
    if base.supervisor.services != config.supervisor.services:
        lines.append(
            f"supervisor.services: {_shown(base.supervisor.services)} -> "
            f"{_shown(config.supervisor.services)} ({RUNNER_REASONS['supervisor.services']})"
        )
    return lines


def record_into(
    session: zenoh.Session,
    keys: Keys,
    cameras: list[str],
    rec: ScenarioLog,
    *,
    frames: bool,
    images: bool = False,
) -> list[Any]:
    """Subscribe to the truth, the commands, the controller's status and each camera's
    detections, appending each to ``rec``; with ``frames``, count each camera's frames too
    (heard, not decoded; a copy of every frame is sent to this subscriber, which a soak does
    not want); with ``images``, keep them (``rec.images``, by capture stamp)."""
    lock = threading.Lock()

    def recorder(decode: Any, into: list[Any]) -> Any:
        def on_sample(sample: zenoh.Sample) -> None:
            try:
                msg = decode(sample.payload.to_bytes())
            except DecodeError:
                return  # the services count garbage; the recorder only scores real messages
            with lock:
                into.append(msg)

        return on_sample

    def frame_counter(camera: str) -> Any:
        kept = rec.images.setdefault(camera, {}) if images else None

        def on_frame(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes() if kept is not None else b""
            stamp = None
            if kept is not None:
                try:
                    stamp = Frame.decode(payload).header.stamp_ns
                except DecodeError:
                    stamp = None  # garbage is the services' to count
            with lock:
                rec.frames[camera] = rec.frames.get(camera, 0) + 1
                if kept is not None and stamp is not None:
                    kept[stamp] = payload

        return on_frame

    subs = [
        session.declare_subscriber(keys.sim_truth(), recorder(GroundTruth.decode, rec.truths)),
        session.declare_subscriber(keys.cmd_vel(), recorder(Twist.decode, rec.twists)),
        session.declare_subscriber(
            keys.controller_status(), recorder(ControllerStatus.decode, rec.statuses)
        ),
    ]
    for camera in cameras:
        into = rec.detections.setdefault(camera, [])
        subs.append(
            session.declare_subscriber(keys.detections(camera), recorder(Detections.decode, into))
        )
        if frames or images:
            subs.append(session.declare_subscriber(keys.frame(camera), frame_counter(camera)))
    return subs


def run_scenario(
    base: Config,
    name: str,
    log: Any = None,
    ros2: bool = False,
    mode: ControllerMode = ControllerMode.FOLLOW,
    full_length: bool = False,
    variant: Scenario | None = None,
    rec: ScenarioLog | None = None,
    images: bool = False,
) -> ScenarioResult:
    """Run scenario ``name`` on the real stack with the controller in ``mode`` (``ros2``:
    through the ROS 2 bridge, the simulator playing a ROS 2 robot); returns its figures (see
    score.py). A scenario with ``settle_s`` ends once its pass conditions have held that long
    (after ``settle_from_s``), unless ``full_length``. A benchmark may run a ``variant`` of
    the scenario (further cameras, detector settings, another world: it keeps the name and
    the simulator plays ``name``'s world unless the variant's ``world`` is one of SCENARIOS)
    and keep what was heard in ``rec`` (with ``images``, every camera's frames too)."""
    if name not in SCENARIOS or name == "demo":
        known = ", ".join(n for n in SCENARIOS if n != "demo")
        raise StackError(f"unknown scenario {name!r}; choose one of {known}")
    scenario = SCENARIOS[name] if variant is None else variant
    config = scenario_config(base, scenario, ros2, mode)
    if log is not None:
        for line in config_changes(base, config, scenario):
            log(f"{name}: changed from your config: {line}")
    workdir = run_folder(f"scenario-{name}-")
    # Each run's world starts afresh: so do the controller's e-stop and depth map (kept with
    # the run, never beside the robot's own).
    config = private_state(config, workdir)
    if log is not None:
        log(f"{name}: the stack on {config.zenoh.endpoint}, its files in {workdir}")
    config_path = workdir / "stack.toml"
    config_path.write_text(to_toml(config))
    world = world_line(config.sim)  # which world and camera faults the simulator runs
    if log is not None:
        log(f"{name}: {world}")
    rec = ScenarioLog() if rec is None else rec
    with (workdir / "stack.log").open("wb") as stack_log:
        proc = start_supervisor(config_path, stack_log)
        try:
            session = open_session(config.zenoh, config.principal("observer"))
            try:
                cameras = list(config.all_cameras)
                subs = record_into(
                    session, Keys(config.stack.prefix), cameras, rec, frames=True, images=images
                )
                settled = None
                if scenario.settle_s is not None and not full_length:
                    settled = Settle(scenario, config, scenario.settle_s)
                _drive(proc, scenario, rec, config_path, log, settled)
                for sub in subs:
                    sub.undeclare()
            finally:
                session.close()
        finally:
            stop_supervisor(proc, STOP_TIMEOUT_S)  # whatever happened, never leave it running
    result = score(
            scenario, rec, world_for(config.sim, scenario.build()), config.controller,
            config.camera.hfov_deg,
        )  # fmt: skip
    result["mode"] = str(config.controller.mode)
    result["world"] = world
    result["log"] = str(workdir / "stack.log")
    result["supervisor_exit_code"] = proc.returncode
    live = depth_error(scenario.build(), config, rec.truths, rec.detections)
    if live is not None:
        result["depth_error"] = live
    return result


def _sim_time(rec: ScenarioLog) -> float:
    return rec.truths[-1].sim_time_s if rec.truths else 0.0


class Settle:
    """Whether a run has shown what it must: every pass condition (score.verdict) holding,
    without a break, for ``hold_s`` of scenario time from ``scenario.settle_from_s`` on."""

    def __init__(self, scenario: Scenario, config: Config, hold_s: float) -> None:
        self.scenario, self.config, self.hold_s = scenario, config, hold_s
        self._since: float | None = None
        self._world = world_for(config.sim, scenario.build())  # as the simulator runs it

    def done(self, rec: ScenarioLog, sim_time_s: float) -> bool:
        if sim_time_s < self.scenario.settle_from_s:
            return False
        result = score(
            self.scenario, rec, self._world, self.config.controller, self.config.camera.hfov_deg
        )
        if not result["success"]:
            self._since = None
            return False
        if self._since is None:
            self._since = sim_time_s
        return sim_time_s - self._since >= self.hold_s


def _kill_now(rec: ScenarioLog, kill_at: float) -> bool:
    """Whether to kill the detector now: from ``kill_at`` (scenario time) on, once the robot
    moves (what the scenario shows is a stop from motion: on a loaded machine the robot may be
    stopped for a stale detection at ``kill_at`` itself), and at ``kill_at`` +
    :data:`KILL_WAIT_MOVING_S` whatever it does (the score then says it was not moving)."""
    now = _sim_time(rec)
    moving = bool(rec.twists) and not rec.twists[-1].is_zero
    return now >= kill_at and (moving or now >= kill_at + KILL_WAIT_MOVING_S)


def _drive(
    proc: subprocess.Popen[bytes],
    scenario: Scenario,
    rec: ScenarioLog,
    config_path: Path,
    log: Any,
    settled: Settle | None = None,
) -> None:
    """Wait for the scenario clock to run its course, killing the detector when scripted, or
    until ``settled`` says the run has shown what it must."""
    start = mono_s()
    pause = threading.Event()
    while _sim_time(rec) <= 0:
        if proc.poll() is not None:
            raise StackError(
                f"the stack exited during start-up (see {config_path.parent}/stack.log)"
            )
        if mono_s() - start > STARTUP_TIMEOUT_S:
            raise StackError(f"the stack did not start within {STARTUP_TIMEOUT_S:.0f} s")
        pause.wait(0.1)
    if log:
        log(f"{scenario.name}: running for {scenario.duration_s:.0f} s of scenario time")
    next_check = 0.0
    while _sim_time(rec) < scenario.duration_s:
        if proc.poll() is not None:
            raise StackError("the stack exited during the scenario")
        kill_at = scenario.kill_detector_at_s
        if kill_at is not None and rec.kill_ns is None and _kill_now(rec, kill_at):
            for pid in service_pids("detector", config_path):
                os.kill(pid, signal.SIGKILL)
            rec.kill_ns = wall_ns()
            if log:
                log(f"{scenario.name}: killed the detector at t={_sim_time(rec):.1f} s")
        if settled is not None and mono_s() >= next_check:
            next_check = mono_s() + SETTLE_CHECK_S
            if settled.done(rec, _sim_time(rec)):
                if log:
                    log(
                        f"{scenario.name}: ended at t={_sim_time(rec):.1f} s: every pass "
                        f"condition held for {settled.hold_s:.0f} s (--full-length runs "
                        f"{scenario.duration_s:.0f} s)"
                    )
                return
        pause.wait(0.05)
