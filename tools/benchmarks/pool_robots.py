"""The pool benchmark's robots part (``zstack pool-benchmark --robots N``, issue 31): N simulated
robots (prefixes ``<run>/robot1`` .. ``robotN``), each its own stack of a simulator with
``--robot-cameras`` cameras at ``--rate`` Hz, on one network and one pool of the largest of
``--workers`` workers (in robot 1's stack, ``detector.prefixes`` every robot's). Each robot's
detections are heard on its own keys.

Printed: per robot, its cameras served (with detections in the window) of its cameras, its
det/s and its worst camera's capture-to-detections p95; per worker, its share of the pool's
announced capacity against its share of the cameras' frame rate (``pool_load_permille``).
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from common.errors import StackError
from stack.config import Config
from tools.benchmarks.pool_capacity import announced
from tools.benchmarks.stacks import (
    STARTUP_S,
    CameraLoad,
    Stack,
    Watch,
    percentile,
    progress,
    stack_config,
    start_stack,
    stop_all,
)
from tools.launch import free_port, wait_ready

SERVED_S = 120.0  # every robot's every camera detected once, after the pool is ready


@dataclasses.dataclass(frozen=True, slots=True)
class RobotFigures:
    prefix: str
    cameras: int
    served: int  # cameras with detections in the window
    det_s: float
    worst_p95_ms: float


@dataclasses.dataclass(frozen=True, slots=True)
class RobotsRun:
    robots: list[RobotFigures]
    capacity_share: dict[str, float]  # each worker's share of the announced capacity
    load_share: dict[str, float]  # its share of the cameras' frame rate (its counters)

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def configs(base: Config, tmp: Path, options: Any) -> list[Config]:
    """Each robot's stack config: robot 1 runs its simulator and the pool, the others only
    their simulator, connected to robot 1's endpoint."""
    run = f"pool/{free_port()}"
    prefixes = tuple(f"{run}/robot{k}" for k in range(1, options.robots + 1))
    workers = max(options.workers)
    loads = [CameraLoad(options.rate_hz)] * options.robot_cameras
    out: list[Config] = []
    for k, prefix in enumerate(prefixes, 1):
        c = stack_config(
            base, tmp / f"robot{k}.toml", loads, tag="pool", workers=workers,
            prefixes=prefixes, pool_prefix=prefixes[0],
        )  # fmt: skip
        c = dataclasses.replace(c, stack=dataclasses.replace(c.stack, prefix=prefix))
        if k > 1:
            c = dataclasses.replace(
                c,
                zenoh=dataclasses.replace(c.zenoh, connect=(out[0].zenoh.endpoint,)),
                supervisor=dataclasses.replace(c.supervisor, services=("sim",)),
                sim=dataclasses.replace(c.sim, wait_for=()),
            )
        out.append(c)
    return out


def run(base: Config, tmp: Path, options: Any, stop: threading.Event) -> RobotsRun:
    """Start the robots (robot 1 and its pool first), wait for every camera's detections and
    the warm-up, measure ``options.seconds``."""
    stacks: list[Stack] = []
    watches: list[Watch] = []
    try:
        for k, config in enumerate(configs(base, tmp, options), 1):
            stack = start_stack(config, Path(config.path))
            stacks.append(stack)
            watch = Watch(stack)
            watches.append(watch)
            if k == 1:
                watch.wait_ready("sim", stop)
            else:
                wait_ready(watch.session, watch.keys, {"sim"}, stack.proc, STARTUP_S,
                           stop=stop, log_path=stack.log_path)  # fmt: skip
        progress(f"  {len(stacks)} robots up; waiting for every camera's detections")
        _wait_served(watches, stop)
        progress(f"  every camera detected; warming up {options.warmup:.0f} s")
        if stop.wait(options.warmup):
            raise KeyboardInterrupt
        for w in watches:
            w.reset()
        if stop.wait(options.seconds):
            raise KeyboardInterrupt
        taken = [w.take() for w in watches]
        pool = watches[0]
        capacity = {w: a.capacity_hz for w, a in announced(pool.session, pool.keys).items()}
        loads = pool.loads()
    finally:
        for w in watches:
            w.close()
        stop_all(stacks)
    robots = [
        RobotFigures(
            prefix=s.config.stack.prefix,
            cameras=len(t.latency_ms),
            served=sum(1 for v in t.latency_ms.values() if v),
            det_s=sum(len(v) for v in t.latency_ms.values()) / t.elapsed_s,
            worst_p95_ms=max((percentile(v, 95) for v in t.latency_ms.values()), default=0.0),
        )
        for s, t in zip(stacks, taken, strict=True)
    ]
    total_cap = sum(capacity.values()) or 1.0
    return RobotsRun(
        robots=robots,
        capacity_share={w: c / total_cap for w, c in sorted(capacity.items())},
        load_share={w: loads.get(w, 0.0) for w in sorted(capacity)},
    )


def _wait_served(watches: Sequence[Watch], stop: threading.Event) -> None:
    for _ in range(int(SERVED_S / 0.5)):
        if all(all(w.take().latency_ms.values()) for w in watches):
            return
        if stop.wait(0.5):
            raise KeyboardInterrupt
    missing = [
        f"{w.keys.prefix}/{c}" for w in watches for c, v in w.take().latency_ms.items() if not v
    ]
    raise StackError(f"no detections within {SERVED_S:.0f} s of {', '.join(missing)}")


def render(r: RobotsRun) -> str:
    lines = [f"{len(r.robots)} robots on one pool of {len(r.capacity_share)} workers:"]
    lines += [
        f"  {x.prefix}: {x.served}/{x.cameras} cameras served, {x.det_s:.2f} det/s, "
        f"worst p95 {x.worst_p95_ms:.0f} ms"
        for x in r.robots
    ]
    lines += [
        f"  worker {w}: capacity share {share:.2f}, load share {r.load_share.get(w, 0):.2f}"
        for w, share in r.capacity_share.items()
    ]
    return "\n".join(lines)
