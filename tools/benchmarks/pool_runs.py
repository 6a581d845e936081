"""The pool benchmark's processes (what tools/benchmarks/pool.py describes): start each
condition's stack, measure it, SIGKILL workers and time the hand-overs."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

from common.clock import mono_s, wall_ns
from common.errors import StackError
from common.files import temp_root
from common.machine import machine_info
from common.pool_rule import camera_rates
from stack.config import Config
from stack.config_file import load_config
from tools.benchmarks import pool_capacity, pool_robots
from tools.benchmarks.pool import (
    UNEVEN,
    Kill,
    PoolOptions,
    Result,
    compare_rules,
    heavy_together_odds,
    render_handover,
    render_results,
    render_rules,
    to_json,
)
from tools.benchmarks.stacks import (
    CameraLoad,
    Stack,
    Watch,
    percentile,
    progress,
    split,
    stack_config,
    start_stack,
    stop_all,
)
from tools.launch import service_pids

#: How long the cameras may take to be split between the workers after readiness (the
#: workers' tokens meet, each settles, their counters report: a few seconds).
SETTLE_S = 60.0
#: A killed worker's cameras are detected again long before this (the bound the integration
#: test holds is Zenoh's lease, 10 s, plus 1 s): past it the run stops and says so.
HANDOVER_TIMEOUT_S = 30.0
#: A restarted worker: backoff, interpreter, model load and warm-up on a loaded 2-core box.
REJOIN_TIMEOUT_S = 180.0
POLL_S = 0.02

_T = TypeVar("_T")


def _poll(
    check: Callable[[], _T | None], timeout_s: float, stop: threading.Event, what: str, stack: Stack
) -> _T:
    """``check()`` once it is truthy, polled every POLL_S; StackError past ``timeout_s``."""
    deadline = mono_s() + timeout_s
    while True:
        got = check()
        if got:
            return got
        if stack.proc.poll() is not None:
            raise StackError(f"the stack exited ({stack.proc.returncode}); see {stack.log_path}")
        if mono_s() > deadline:
            raise StackError(f"no {what} within {timeout_s:.0f} s; see {stack.log_path}")
        if stop.wait(POLL_S):
            raise KeyboardInterrupt


@contextlib.contextmanager
def _running(config: Config, stop: threading.Event) -> Iterator[tuple[Stack, Watch]]:
    """Start ``config``'s stack (written to its ``path``), wait for every worker, stop it."""
    stack = start_stack(config, Path(config.path))
    watch: Watch | None = None
    try:
        watch = Watch(stack)
        watch.wait_ready("sim", stop)
        yield stack, watch
    finally:
        if watch is not None:
            watch.close()
        stop_all([stack])


def measure(
    label: str, stack: Stack, watch: Watch, options: PoolOptions, stop: threading.Event
) -> Result:
    """Wait for the split and the warm-up, then measure ``options.seconds``."""
    _poll(lambda: split(watch.serving(), watch.cameras), SETTLE_S, stop, "split", stack)
    progress(f"  split; warming up {options.warmup:.0f} s")
    if stop.wait(options.warmup):
        raise KeyboardInterrupt
    watch.reset()
    if stop.wait(options.seconds):
        raise KeyboardInterrupt
    taken = watch.take()
    served = watch.serving()
    result = Result(
        label=label,
        n=len(watch.cameras),
        workers=len(watch.workers),
        seconds=options.seconds,
        fps={c: len(v) / taken.elapsed_s for c, v in taken.latency_ms.items()},
        asked_hz={c: s.rate_hz for c, s in stack.config.all_cameras.items()},
        p50_ms={c: percentile(v, 50) for c, v in taken.latency_ms.items()},
        p95_ms={c: percentile(v, 95) for c, v in taken.latency_ms.items()},
        served={w: sorted(c or ()) for w, c in served.items()},
        loads=watch.loads(),
        duplicates=taken.duplicates,
    )
    progress(
        f"  {result.total_fps:.2f} det/s, fairness {result.fairness:.2f}, worst p50 "
        f"{result.worst_p50_ms:.0f} ms, {result.served}"
    )
    return result


def _kill_once(victim: str, stack: Stack, watch: Watch, stop: threading.Event) -> Kill:
    before = watch.serving()
    moved = before[victim] or set()
    [pid] = service_pids(victim, stack.path)
    killed_ns, killed_at = wall_ns(), mono_s()
    os.kill(pid, signal.SIGKILL)

    def served_again() -> dict[str, float] | None:
        firsts = {c: watch.first_after(c, killed_ns) for c in moved}
        got = {c: t for c, t in firsts.items() if t is not None}
        return got if len(got) == len(moved) else None

    firsts = _poll(
        served_again,
        HANDOVER_TIMEOUT_S,
        stop,
        f"detections of {sorted(moved)} after killing {victim}",
        stack,
    )
    handover = {c: t - killed_at for c, t in firsts.items()}
    # Rejoined: every worker heard since the kill (the victim's restart included), split.
    _poll(
        lambda: split(watch.serving(killed_at), watch.cameras),
        REJOIN_TIMEOUT_S,
        stop,
        f"split after {victim} restarted",
        stack,
    )
    rejoined_ns, rejoin_s = wall_ns(), mono_s() - killed_at
    _poll(
        lambda: all(watch.first_after(c, rejoined_ns) for c in watch.cameras),
        SETTLE_S,
        stop,
        "every camera detected after the split",
        stack,
    )
    return Kill(victim=victim, handover_s=handover, rejoin_s=rejoin_s)


def _kill_series(
    stack: Stack, watch: Watch, count: int, stop: threading.Event
) -> tuple[list[Kill], int]:
    """``count`` SIGKILLs, each worker in turn; the kills and the frames detected twice."""
    watch.reset()
    kills = []
    for k in range(count):
        victim = watch.workers[k % len(watch.workers)]
        kills.append(_kill_once(victim, stack, watch, stop))
        times = ", ".join(f"{c} {t:.2f} s" for c, t in kills[-1].handover_s.items())
        progress(
            f"  kill {k + 1}/{count} ({victim}): {times}; split again after "
            f"{kills[-1].rejoin_s:.1f} s"
        )
    return kills, watch.take().duplicates


def main(options: PoolOptions, stop: threading.Event) -> int:
    """Run every part of ``options`` and print the tables (or JSON)."""
    base = load_config(options.config)
    results: list[Result] = []
    kills: list[Kill] = []
    duplicates = 0
    plan = [(n, w) for n in options.cameras for w in options.workers]
    kill_in = (min(n for n in options.cameras if n >= 2), 2) if options.kills else None
    started = mono_s()
    with tempfile.TemporaryDirectory(prefix="pool-bench-", dir=temp_root()) as tmp:
        for i, (n, w) in enumerate(plan, 1):
            progress(
                f"[{i}/{len(plan)}] {n} cameras on {w} worker(s) "
                f"({mono_s() - started:.0f} s so far)"
            )
            loads = [CameraLoad(options.rate_hz)] * n
            config = stack_config(base, Path(tmp) / f"n{n}-w{w}.toml", loads, tag="pool", workers=w)
            with _running(config, stop) as (s, watch):
                results.append(measure("even", s, watch, options, stop))
                if (n, w) == kill_in:
                    progress(f"  {options.kills} SIGKILLs")
                    kills, duplicates = _kill_series(s, watch, options.kills, stop)
                    progress("  " + render_handover(kills, duplicates))
        rules = odds = weights = None
        if options.uneven:
            config = stack_config(base, Path(tmp) / "uneven.toml", UNEVEN, tag="pool", workers=2)
            weights = camera_rates(config.all_cameras)
            workers = list(config.detector_services)
            rules = compare_rules(weights, workers, config.detector.pool_balance)
            odds = heavy_together_odds(UNEVEN, workers, config.detector.pool_balance)
            progress(f"[uneven] {render_rules(rules, weights, odds)}")
            with _running(config, stop) as (s, watch):
                results.append(measure("uneven", s, watch, options, stop))
        capacity = (
            pool_capacity.run(base, Path(tmp), options, stop, measure) if options.capacity else []
        )
        robots = pool_robots.run(base, Path(tmp), options, stop) if options.robots else []
    if options.as_json:
        out = to_json(results, kills, duplicates, rules, odds, options, machine_info(), capacity)
        if robots:
            out = json.dumps({**json.loads(out), "robots": [r.as_dict() for r in robots]})
        print(out)
        return 0
    print(render_results(results))
    if kills:
        print("\n" + render_handover(kills, duplicates))
    if rules is not None and weights is not None and odds is not None:
        print("\n" + render_rules(rules, weights, odds))
        uneven = results[-1]
        print(
            "  measured (weighted): "
            + ", ".join(f"{c} {uneven.fps[c]:.2f} of {uneven.asked_hz[c]:g} Hz" for c in uneven.fps)
            + f"; fairness {uneven.fairness:.2f}; served {uneven.served}"
        )
    if capacity:
        print("\n" + pool_capacity.render(capacity))
    if robots:
        print("\n" + pool_robots.render(robots))
    return 0
