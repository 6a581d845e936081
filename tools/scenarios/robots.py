"""Several simulated robots on one detector pool: ``run_robots(base, NAME, robots=N)``.

Each robot is a stack of its own (its simulator, controller and metrics under a key prefix of
its own, ``r<i>-<run>``); one more stack, the pool (``pool-<run>``), runs only detector
workers that serve every robot's prefix (``detector.prefixes``), each robot's detections going
back on its own keys. Every stack is in peer mode on this host and meets the pool's endpoint.
The pool starts first and the robots once every worker is announced, so that model loading
does not eat into the scenario; then each robot is recorded and scored as a one-robot run
(tools/scenarios/runner.py) is.
"""

from __future__ import annotations

import dataclasses
import subprocess
import threading
import uuid
from collections.abc import Callable
from contextlib import ExitStack
from typing import Any, TypedDict

from common.announce import workers_now
from common.clock import mono_s
from common.contracts import ControllerMode, ScenarioResult
from common.errors import StackError
from common.keys import Keys
from common.zenoh_bus import ZenohBus, open_session
from services.sim.worlds import world_for, world_line
from simworld.scenarios import SCENARIOS
from stack.config import Config
from stack.config_file import to_toml
from tools.launch import (
    private_state,
    run_folder,
    start_supervisor,
    stop_supervisor,
)
from tools.ports import private_endpoint
from tools.scenarios.runner import (
    SETTLE_CHECK_S,
    STARTUP_TIMEOUT_S,
    STOP_TIMEOUT_S,
    Settle,
    _sim_time,
    record_into,
    scenario_config,
)
from tools.scenarios.score import ScenarioLog, score

POOL_ASK_TIMEOUT_S = 1.0  # one liveliness look-up of the workers' announcements


class RobotsResult(TypedDict):
    """One run of several robots: each robot's result (score.py's, in ``prefixes``' order),
    and the pool's log and exit code."""

    robots: list[ScenarioResult]
    prefixes: list[str]
    pool_log: str
    pool_exit_code: int | None


@dataclasses.dataclass(frozen=True)
class RobotsPlan:
    """The configs of one run: each robot's and the pool's."""

    robots: tuple[Config, ...]
    pool: Config


def robots_plan(
    base: Config, name: str, robots: int, workers: int, mode: ControllerMode
) -> RobotsPlan:
    """``robots`` robots' stacks for scenario ``name`` and one pool of ``workers`` workers."""
    scenario = SCENARIOS[name]
    run = uuid.uuid4().hex[:6]
    prefixes = tuple(f"r{i}-{run}" for i in range(1, robots + 1))
    pool_endpoint = private_endpoint()

    def stack(prefix: str, services: tuple[str, ...], endpoint: str) -> Config:
        one = scenario_config(base, scenario, mode=mode, endpoint=endpoint)
        return dataclasses.replace(
            one,
            stack=dataclasses.replace(one.stack, prefix=prefix),
            zenoh=dataclasses.replace(
                one.zenoh,
                endpoint=endpoint,
                connect=() if endpoint == pool_endpoint else (pool_endpoint,),
            ),
            supervisor=dataclasses.replace(one.supervisor, services=services),
            # The robot's stack has no detector of its own: its simulator waits for its
            # controller, and the runner starts it once the pool's workers are up.
            sim=dataclasses.replace(one.sim, wait_for=("controller",)),
        )

    pool = stack(f"pool-{run}", ("detector",), pool_endpoint)
    # A robot that needs depth runs its depth scan stage (its virtual scans) beside its controller.
    stage = ("depthscan",) if pool.controller.needs_depth else ()
    pool = dataclasses.replace(
        pool, detector=dataclasses.replace(pool.detector, workers=workers, prefixes=prefixes)
    )
    robot_stacks = tuple(
        stack(p, ("sim", *stage, "controller", "metrics"), private_endpoint()) for p in prefixes
    )
    return RobotsPlan(robot_stacks, pool)


def _workers_announced(pool: Config, on_bad: Callable[[str, Exception], None]) -> int:
    """How many workers the pool's announcements name now (garbage to ``on_bad``)."""
    keys = Keys(pool.detector.pool_prefix or pool.stack.prefix)
    bus = ZenohBus(open_session(pool.zenoh, pool.principal("observer")))
    try:
        return len(workers_now(bus, keys, POOL_ASK_TIMEOUT_S, on_bad))
    finally:
        bus.close()


def run_robots(
    base: Config,
    name: str,
    robots: int = 2,
    workers: int = 2,
    mode: ControllerMode = ControllerMode.FOLLOW,
    log: Any = None,
) -> RobotsResult:
    """Run scenario ``name`` on ``robots`` simulated robots sharing one pool of ``workers``
    detector workers."""
    if name not in SCENARIOS or name == "demo":
        raise StackError(f"unknown scenario {name!r}")
    scenario = SCENARIOS[name]
    plan = robots_plan(base, name, robots, workers, mode)
    workdir = run_folder(f"robots-{name}-")
    if log:
        where = ", ".join(c.zenoh.endpoint for c in (plan.pool, *plan.robots))
        log(f"{name}: the pool and the robots on {where}, their files in {workdir}")
    recs = [ScenarioLog() for _ in plan.robots]
    procs: list[subprocess.Popen[bytes]] = []
    pause = threading.Event()
    with ExitStack() as stack:

        def start(config: Config, tag: str) -> subprocess.Popen[bytes]:
            path = workdir / f"{tag}.toml"
            path.write_text(to_toml(private_state(config, workdir, tag)))
            out = stack.enter_context((workdir / f"{tag}.log").open("wb"))
            proc = start_supervisor(path, out)
            procs.append(proc)
            stack.callback(stop_supervisor, proc, STOP_TIMEOUT_S)
            return proc

        pool_proc = start(plan.pool, "pool")
        started = mono_s()
        told: set[str] = set()

        def bad(key: str, error: Exception) -> None:
            if log and key not in told:
                told.add(key)
                log(f"{name}: a bad worker announcement ignored ({key}: {error})")

        while _workers_announced(plan.pool, bad) < workers:
            if pool_proc.poll() is not None:
                raise StackError(f"the pool exited during start-up (see {workdir}/pool.log)")
            if mono_s() - started > STARTUP_TIMEOUT_S:
                raise StackError(
                    f"the pool's workers did not start within {STARTUP_TIMEOUT_S:.0f} s"
                )
            pause.wait(0.5)
        if log:
            log(f"{name}: {workers} workers announced; starting {robots} robots")
        for i, (config, rec) in enumerate(zip(plan.robots, recs, strict=True), 1):
            start(config, f"robot{i}")
            session = open_session(config.zenoh, config.principal("observer"))
            stack.callback(session.close)
            record_into(session, Keys(config.stack.prefix), list(config.all_cameras), rec,
                        frames=True)  # fmt: skip
        settles = [Settle(scenario, c, scenario.settle_s) if scenario.settle_s else None
                   for c in plan.robots]  # fmt: skip
        done = [False] * robots
        started = mono_s()
        next_check = 0.0
        while not all(done):
            if any(p.poll() is not None for p in procs):
                raise StackError(f"a stack exited during the scenario (see {workdir})")
            if all(_sim_time(r) <= 0 for r in recs) and mono_s() - started > STARTUP_TIMEOUT_S:
                raise StackError(f"the robots did not start within {STARTUP_TIMEOUT_S:.0f} s")
            if mono_s() >= next_check:
                next_check = mono_s() + SETTLE_CHECK_S
                for i, (rec, settle) in enumerate(zip(recs, settles, strict=True)):
                    t = _sim_time(rec)
                    done[i] = (
                        done[i]
                        or t >= scenario.duration_s
                        or (settle is not None and settle.done(rec, t))
                    )
            pause.wait(0.05)
    results = []
    for i, (config, rec, proc) in enumerate(zip(plan.robots, recs, procs[1:], strict=True), 1):
        result = score(
            scenario, rec, world_for(config.sim, scenario.build()), config.controller,
            config.camera.hfov_deg,
        )  # fmt: skip
        result["mode"] = str(config.controller.mode)
        result["world"] = world_line(config.sim)  # which world and faults each robot's sim ran
        result["log"] = str(workdir / f"robot{i}.log")
        result["supervisor_exit_code"] = proc.returncode
        results.append(result)
    return RobotsResult(
        robots=results,
        prefixes=[c.stack.prefix for c in plan.robots],
        pool_log=str(workdir / "pool.log"),
        pool_exit_code=procs[0].returncode,
    )
