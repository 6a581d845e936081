"""The pool serving several robots (``zstack pool-benchmark --robots N``, issue 31 item 5).

Two conditions on one pool of 2 workers, the same cameras in all:

- **robots**: N robot stacks, each its simulator rendering ``ROBOT_CAMERAS`` cameras at
  ``--rate`` Hz under a key prefix of its own, and one pool stack (the workers only) serving
  every robot's prefix (``detector.prefixes``);
- **one robot**: one stack with all N x ``ROBOT_CAMERAS`` cameras on its own 2 workers.

For each: detections/s, the worst camera's capture-to-detections p50 and p95, fairness (the
slowest camera's FPS over the fastest's), and the ratio robots / one robot: what serving
several prefixes costs the pool. Each waits ``--warmup`` s once every camera is detected, and
measures ``--seconds``.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from common.clock import mono_s
from common.errors import StackError
from stack.config import Config
from tools.benchmarks.stacks import (
    STARTUP_S,
    CameraLoad,
    Stack,
    Watch,
    fairness,
    percentile,
    progress,
    ratio,
    stack_config,
    start_stack,
    stop_all,
)
from tools.launch import free_port

ROBOT_CAMERAS = 2  # each robot's cameras
POOL_WORKERS = 2
POLL_S = 0.2


@dataclasses.dataclass(frozen=True, slots=True)
class RobotsRun:
    """One condition's figures, over every camera of every robot."""

    label: str
    robots: int
    fps: dict[str, float]  # per camera, named <prefix>/<camera>
    p50_ms: dict[str, float]
    p95_ms: dict[str, float]

    @property
    def total_fps(self) -> float:
        return sum(self.fps.values())

    @property
    def worst_p95_ms(self) -> float:
        return max(self.p95_ms.values(), default=float("nan"))

    @property
    def worst_p50_ms(self) -> float:
        return max(self.p50_ms.values(), default=float("nan"))

    def as_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "fairness": fairness(list(self.fps.values()))}


def robots_configs(base: Config, tmp: Path, robots: int, rate_hz: float) -> list[Config]:
    """The pool's config first, then each robot's: one-chunk prefixes, every robot's
    simulator meeting the pool's endpoint, the pool serving every robot's prefix."""
    loads = [CameraLoad(rate_hz)] * ROBOT_CAMERAS
    robot_configs = []
    for i in range(1, robots + 1):
        c = stack_config(base, tmp / f"robot{i}.toml", loads, tag="robots")
        robot_configs.append(
            dataclasses.replace(
                c,
                stack=dataclasses.replace(c.stack, prefix=f"robot{i}-{free_port()}"),
                supervisor=dataclasses.replace(c.supervisor, services=("sim",)),
                sim=dataclasses.replace(c.sim, wait_for=()),  # no detector of its own
            )
        )
    pool = stack_config(base, tmp / "pool.toml", loads, tag="robots", workers=POOL_WORKERS)
    pool = dataclasses.replace(
        pool,
        stack=dataclasses.replace(pool.stack, prefix=f"pool-{free_port()}"),
        supervisor=dataclasses.replace(pool.supervisor, services=("detector",)),
        detector=dataclasses.replace(
            pool.detector, prefixes=tuple(c.stack.prefix for c in robot_configs)
        ),
    )
    robot_configs = [
        dataclasses.replace(c, zenoh=dataclasses.replace(c.zenoh, connect=(pool.zenoh.endpoint,)))
        for c in robot_configs
    ]
    return [pool, *robot_configs]


def _measure(
    label: str, robots: int, stacks: Sequence[Stack], watches: Sequence[Watch], options: Any,
    stop: threading.Event,
) -> RobotsRun:  # fmt: skip
    """Once every camera of every watch is detected, the warm-up, then ``options.seconds``."""
    deadline = mono_s() + STARTUP_S
    while not all(all(w.take().latency_ms.values()) for w in watches):
        if any(s.proc.poll() is not None for s in stacks):
            raise StackError(f"a stack exited; see {[str(s.log_path) for s in stacks]}")
        if mono_s() > deadline:
            raise StackError(f"not every camera detected within {STARTUP_S:.0f} s")
        if stop.wait(POLL_S):
            raise KeyboardInterrupt
    progress(f"  every camera detected; warming up {options.warmup:.0f} s")
    if stop.wait(options.warmup):
        raise KeyboardInterrupt
    for w in watches:
        w.reset()
    if stop.wait(options.seconds):
        raise KeyboardInterrupt
    fps, p50, p95 = {}, {}, {}
    for w in watches:
        taken = w.take()
        for camera, lat in taken.latency_ms.items():
            name = f"{w.keys.prefix}/{camera}"
            fps[name] = len(lat) / taken.elapsed_s
            p50[name], p95[name] = percentile(lat, 50), percentile(lat, 95)
    run = RobotsRun(label, robots, fps, p50, p95)
    progress("  " + render_run(run))
    return run


def run(base: Config, tmp: Path, options: Any, stop: threading.Event) -> list[RobotsRun]:
    """Both conditions: ``options.robots`` robots on one pool, then one robot with as many
    cameras on as many workers."""
    n = options.robots
    runs = []
    progress(f"[robots] {n} robots x {ROBOT_CAMERAS} cameras at {options.rate_hz:g} Hz "
             f"on one pool of {POOL_WORKERS} workers")  # fmt: skip
    pool, *robot_configs = robots_configs(base, tmp, n, options.rate_hz)
    stacks = [start_stack(pool, Path(pool.path))]
    watches: list[Watch] = []
    try:
        stacks += [start_stack(c, Path(c.path)) for c in robot_configs]
        watches = [Watch(s, workers=()) for s in stacks[1:]]
        runs.append(_measure("robots", n, stacks, watches, options, stop))
    finally:
        for w in watches:
            w.close()
        stop_all(stacks)
    progress(f"[robots] one robot with {n * ROBOT_CAMERAS} cameras on {POOL_WORKERS} workers")
    loads = [CameraLoad(options.rate_hz)] * (n * ROBOT_CAMERAS)
    one = stack_config(base, tmp / "one.toml", loads, tag="robots", workers=POOL_WORKERS)
    stack = start_stack(one, Path(one.path))
    watch: Watch | None = None
    try:
        watch = Watch(stack)
        runs.append(_measure("one robot", 1, [stack], [watch], options, stop))
    finally:
        if watch is not None:
            watch.close()
        stop_all([stack])
    return runs


def render_run(r: RobotsRun) -> str:
    return (
        f"{r.label:9} {r.robots} robot(s), {len(r.fps)} cameras: {r.total_fps:.1f} det/s, worst "
        f"p50 {r.worst_p50_ms:.0f} ms, p95 {r.worst_p95_ms:.0f} ms, fairness "
        f"{fairness(list(r.fps.values())):.2f}"
    )


def render(runs: Sequence[RobotsRun]) -> str:
    lines = [f"several robots on one pool of {POOL_WORKERS} workers:"]
    lines += ["  " + render_run(r) for r in runs]
    by = {r.label: r for r in runs}
    if "robots" in by and "one robot" in by:
        a, b = by["robots"], by["one robot"]
        lines.append(
            f"  robots / one robot: det/s {ratio(a.total_fps, b.total_fps):.2f}x, worst p95 "
            f"{ratio(a.worst_p95_ms, b.worst_p95_ms):.2f}x"
        )
    return "\n".join(lines)
