"""One scenario on several simulated robots served by one detector pool (issue 31, "one pool,
several robots"): ``robots`` stacks on one Zenoh network, each its own key prefix
(``<run>/robot1`` ...), simulator, controller and metrics; the first also runs the pool's
``workers`` detector workers, which serve every robot's cameras (``detector.prefixes``) and put
each robot's detections on that robot's keys. Each robot's camera has its own frame id
(``robot<k>_camera``), so that detections that went on another robot's keys show.

The first robot's stack starts alone (the pool loads its model); the others once its
simulator runs, then each is scored as tools/scenarios/runner.py scores one.
"""

from __future__ import annotations

import dataclasses
import tempfile
import threading
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.clock import mono_s
from common.errors import StackError
from common.keys import Keys
from common.zenoh_bus import open_session
from services.metrics.service import query as query_metrics
from services.sim.scenarios import SCENARIOS
from stack.config import Config
from stack.config_file import to_toml
from tools.launch import free_port, start_supervisor, stop_supervisor
from tools.scenarios.runner import (
    STARTUP_TIMEOUT_S,
    STOP_TIMEOUT_S,
    Settle,
    record_into,
    scenario_config,
)
from tools.scenarios.score import ScenarioLog, score

METRICS_TIMEOUT_S = 10.0  # each robot's metrics answer at the end


@dataclasses.dataclass(slots=True)
class RobotRun:
    """One robot's config, its stack's process and log, what the runner heard of it."""

    config: Config
    workdir: Path
    rec: ScenarioLog = dataclasses.field(default_factory=ScenarioLog)
    proc: Any = None
    session: Any = None
    subs: list[Any] = dataclasses.field(default_factory=list)
    settle: Settle | None = None


def robot_configs(base: Config, name: str, robots: int, workers: int) -> list[Config]:
    """Each robot's stack config: the scenario's (runner.scenario_config), on one network
    (robot 1's endpoint, which the others connect to), prefixes ``<run>/robot<k>``, the pool
    of ``workers`` workers in robot 1's stack serving every robot, the others without one."""
    scenario = SCENARIOS[name]
    run = f"robots/{uuid.uuid4().hex[:8]}"
    prefixes = tuple(f"{run}/robot{k}" for k in range(1, robots + 1))
    first_endpoint = f"tcp/127.0.0.1:{free_port()}"
    out = []
    for k, prefix in enumerate(prefixes, 1):
        c = scenario_config(base, scenario)
        endpoint = first_endpoint if k == 1 else f"tcp/127.0.0.1:{free_port()}"
        services = ("sim", "detector", "controller", "metrics") if k == 1 else (
            "sim", "controller", "metrics"
        )  # fmt: skip
        out.append(
            dataclasses.replace(
                c,
                zenoh=dataclasses.replace(
                    c.zenoh, endpoint=endpoint, connect=() if k == 1 else (first_endpoint,)
                ),
                stack=dataclasses.replace(c.stack, prefix=prefix),
                camera=dataclasses.replace(c.camera, frame_id=f"robot{k}_camera"),
                detector=dataclasses.replace(
                    c.detector, workers=workers, prefixes=prefixes, pool_prefix=prefixes[0]
                ),
                sim=dataclasses.replace(
                    c.sim, wait_for=("detector", "controller") if k == 1 else ("controller",)
                ),
                supervisor=dataclasses.replace(c.supervisor, services=services),
            )
        )
    return out


def run_robots(
    base: Config,
    name: str,
    robots: int = 2,
    workers: int = 2,
    log: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Run scenario ``name`` on ``robots`` robots and one pool; per robot: its prefix, its
    scenario result (score.py), its metrics answer at the end and the frame ids of the
    detections heard on its keys (``detection_frame_ids``: {camera: sorted set})."""
    if name not in SCENARIOS or name == "demo" or SCENARIOS[name].kill_detector_at_s is not None:
        raise StackError(f"scenario {name!r} cannot run on several robots")
    scenario = SCENARIOS[name]
    runs = []
    for config in robot_configs(base, name, robots, workers):
        workdir = Path(tempfile.mkdtemp(prefix=f"robots-{name}-"))
        config = dataclasses.replace(config, path=str(workdir / "stack.toml"))
        (workdir / "stack.toml").write_text(to_toml(config))
        runs.append(RobotRun(config, workdir))
    answers: list[Any] = [None] * len(runs)
    try:
        for i, r in enumerate(runs):
            with (r.workdir / "stack.log").open("wb") as stack_log:  # the child keeps its own
                r.proc = start_supervisor(r.workdir / "stack.toml", stack_log)
            r.session = open_session(r.config.zenoh, "observer")
            cams = list(r.config.all_cameras)
            r.subs = record_into(r.session, Keys(r.config.stack.prefix), cams, r.rec, frames=True)
            if scenario.settle_s is not None:
                r.settle = Settle(scenario, r.config, scenario.settle_s)
            if i == 0:  # the pool loads its model before the other robots start
                _wait_started(r)
            if log:
                log(f"{name}: robot {r.config.stack.prefix} started")
        for r in runs:
            _wait_started(r)
        _drive(runs, scenario.duration_s)
        for i, r in enumerate(runs):
            answers[i] = query_metrics(r.config, METRICS_TIMEOUT_S)
    finally:
        for r in runs:
            for sub in r.subs:
                sub.undeclare()
            if r.session is not None:
                r.session.close()
        for r in reversed(runs):  # the pool's stack last: the others' detections until then
            if r.proc is not None:
                stop_supervisor(r.proc, STOP_TIMEOUT_S)
    out = []
    for r, answer in zip(runs, answers, strict=True):
        result = score(scenario, r.rec, scenario.build(), r.config.controller,
                       r.config.camera.hfov_deg)  # fmt: skip
        result["log"] = str(r.workdir / "stack.log")
        result["supervisor_exit_code"] = r.proc.returncode
        out.append(
            {
                "prefix": r.config.stack.prefix,
                "result": result,
                "metrics": answer,
                "detection_frame_ids": {
                    cam: sorted({d.header.frame_id for d in dets})
                    for cam, dets in r.rec.detections.items()
                },
            }
        )
    return out


def _sim_time(rec: ScenarioLog) -> float:
    return rec.truths[-1].sim_time_s if rec.truths else 0.0


def _wait_started(r: RobotRun) -> None:
    start, pause = mono_s(), threading.Event()
    while _sim_time(r.rec) <= 0:
        if r.proc.poll() is not None:
            raise StackError(f"the stack exited during start-up (see {r.workdir}/stack.log)")
        if mono_s() - start > STARTUP_TIMEOUT_S:
            raise StackError(f"{r.config.stack.prefix} did not start within "
                             f"{STARTUP_TIMEOUT_S:.0f} s (see {r.workdir}/stack.log)")  # fmt: skip
        pause.wait(0.1)


def _drive(runs: list[RobotRun], duration_s: float) -> None:
    """Until every robot's scenario has run its course or settled (each one's pass
    conditions held for its ``settle_s``)."""
    pause = threading.Event()
    done: set[int] = set()
    while len(done) < len(runs):
        for i, r in enumerate(runs):
            if r.proc.poll() is not None:
                raise StackError(f"the stack of {r.config.stack.prefix} exited during the run")
            t = _sim_time(r.rec)
            if t >= duration_s or (r.settle is not None and r.settle.done(r.rec, t)):
                done.add(i)
        pause.wait(0.5)
