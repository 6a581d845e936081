"""``python -m tools.scenarios soak``: the whole stack for a long run under a garbage flood.

The simulated robot follows the demo's walking person (the ``make run`` world) while a rogue
session puts garbage on every key the services listen to. Every ``--sample-s`` the soak reads
each process's resident memory and the size of the stack's log; at the end it reports whether
memory stayed flat, whether the log stayed bounded and whether the robot still followed.

This is a benchmark, not a test: it takes ``--duration`` seconds (600 for the figures in
docs/benchmarks.md) and its figures depend on the machine.
"""

from __future__ import annotations

import math
import random
import threading
from dataclasses import dataclass, field
from typing import Any

import msgpack

from common.clock import mono_s
from common.keys import Keys
from common.messages import GroundTruth
from common.settings import SERVICES
from common.zenoh_bus import open_session
from simworld.scenarios import SCENARIOS
from stack.config import Config
from stack.config_file import to_toml
from tools.launch import (
    private_state,
    rss_kb,
    run_folder,
    service_pids,
    start_supervisor,
    stop_supervisor,
    wait_ready,
)
from tools.scenarios.runner import STOP_TIMEOUT_S, record_into, scenario_config
from tools.scenarios.score import ScenarioLog

READY_TIMEOUT_S = 180.0  # the stack's start-up on a loaded 2-core machine
WARM_UP_S = 60.0  # model load, caches and allocator pools settle before memory counts as "flat"
IN_VIEW_MIN_FRACTION = 0.8  # "still following": the person in view this much of the last window
FOLLOW_RANGE_M = 3.0  # ... and no further than this from the robot, on average


@dataclass
class Sample:
    """One look at the stack: seconds since start, resident MB per process, log bytes."""

    t_s: float
    rss_mb: dict[str, float]
    log_bytes: int
    pids: dict[str, int]


@dataclass
class SoakFigures:
    samples: list[Sample] = field(default_factory=list)
    flood_messages: int = 0


def garbage(rng: random.Random) -> bytes:
    """A payload no decoder should accept: random bytes, or msgpack of the wrong shape."""
    kind = rng.randrange(4)
    if kind == 0:
        return rng.randbytes(rng.randrange(0, 2048))
    packed: bytes
    if kind == 1:
        packed = msgpack.packb({"v": rng.randrange(1 << 16), "x": rng.random()})
        return packed
    if kind == 2:
        packed = msgpack.packb([rng.random() for _ in range(rng.randrange(1, 64))])
        return packed
    return b"\xff" * rng.randrange(1, 64)


def flooded_keys(keys: Keys, camera: str) -> list[str]:
    """Every key a service of the default stack subscribes to (and the simulator's truth),
    but the e-stop's: garbage there latches the e-stop by design (when in doubt, stop; tested
    in tests/unit/test_fuzz_handlers.py), and a stopped robot would show nothing of the rest."""
    return [
        keys.frame(camera),
        keys.detections(camera),
        keys.scan(),
        keys.cmd_vel(),
        keys.controller_status(),
        keys.sim_truth(),
        *(keys.counters(s) for s in SERVICES),
    ]


def _rss_mb(pid: int) -> float | None:
    kb = rss_kb(pid)
    return None if kb is None else kb / 1024.0


def in_view_fraction(truths: list[GroundTruth], hfov_deg: float) -> tuple[float, float]:
    """Share of ``truths`` with the first target inside the camera's view, and its mean range."""
    if not truths:
        return 0.0, math.inf
    seen, ranges = 0, []
    for t in truths:
        x, y, theta = t.robot
        tx, ty = t.targets_xy[0]
        bearing = math.atan2(ty - y, tx - x) - theta
        bearing = math.atan2(math.sin(bearing), math.cos(bearing))
        seen += abs(math.degrees(bearing)) <= hfov_deg / 2
        ranges.append(math.hypot(tx - x, ty - y))
    return seen / len(truths), sum(ranges) / len(ranges)


def summarise(
    figures: SoakFigures, truths: list[GroundTruth], hfov_deg: float, window_s: float = 60.0
) -> dict[str, Any]:
    """The soak's verdicts from its samples and the simulator's truth. Pure."""
    samples = figures.samples
    # Memory is judged only after the warm-up (model load, caches, allocator pools); a run
    # too short to have two samples after it judges no growth rather than count the load.
    settled = [s for s in samples if s.t_s >= WARM_UP_S]
    if len(settled) < 2:
        settled = []
    memory: dict[str, dict[str, float]] = {}
    for name in sorted({n for s in samples for n in s.rss_mb}):
        series = [s.rss_mb[name] for s in settled if name in s.rss_mb]
        if series:
            memory[name] = {
                "start_mb": series[0],
                "end_mb": series[-1],
                "max_mb": max(series),
                "growth_mb": series[-1] - series[0],
            }
    restarts = {
        name: len({s.pids[name] for s in samples if name in s.pids}) - 1
        for name in sorted({n for s in samples for n in s.pids})
    }
    half = samples[len(samples) // 2] if samples else None
    last = samples[-1] if samples else None
    log_rate = 0.0
    if half is not None and last is not None and last.t_s > half.t_s:
        log_rate = (last.log_bytes - half.log_bytes) / (last.t_s - half.t_s)
    end_time = truths[-1].sim_time_s if truths else 0.0
    # The last minute, or the second half of a shorter run: what "still following" judges.
    window_s = min(window_s, end_time / 2) if end_time > 0 else window_s
    fraction, mean_range = in_view_fraction(
        [t for t in truths if t.sim_time_s >= end_time - window_s], hfov_deg
    )
    return {
        "duration_s": last.t_s if last else 0.0,
        "flood_messages": figures.flood_messages,
        "memory": memory,
        "restarts": restarts,
        "log_bytes": last.log_bytes if last else 0,
        "log_bytes_per_s_second_half": log_rate,
        "last_window_s": window_s,
        "warm_up_s": WARM_UP_S,
        "last_window_in_view": fraction,
        "last_window_mean_range_m": mean_range,
        "still_following": fraction >= IN_VIEW_MIN_FRACTION and mean_range <= FOLLOW_RANGE_M,
    }


def _flood(config: Config, rate_hz: float, stop: threading.Event, figures: SoakFigures) -> None:
    rng = random.Random(13)
    targets = flooded_keys(Keys(config.stack.prefix), config.stack.camera)
    session = open_session(config.zenoh, config.principal("observer"))
    try:
        period = 1.0 / rate_hz
        next_at = mono_s()
        while not stop.is_set():
            session.put(rng.choice(targets), garbage(rng))
            figures.flood_messages += 1
            next_at += period
            stop.wait(max(0.0, next_at - mono_s()))
    finally:
        session.close()


def run_soak(
    base: Config, duration_s: float, flood_hz: float, sample_s: float, log: Any
) -> dict[str, Any]:
    """Run the demo world under a flood for ``duration_s``; returns ``summarise``'s figures."""
    workdir = run_folder("soak-")
    config = private_state(scenario_config(base, SCENARIOS["demo"]), workdir)
    log(f"soak: the stack on {config.zenoh.endpoint}, its files in {workdir}")
    config_path = workdir / "stack.toml"
    config_path.write_text(to_toml(config))
    log_path = workdir / "stack.log"
    figures, rec, stop = SoakFigures(), ScenarioLog(), threading.Event()
    with log_path.open("wb") as stack_log:
        proc = start_supervisor(config_path, stack_log)
        session = open_session(config.zenoh, config.principal("observer"))
        flooder = threading.Thread(target=_flood, args=(config, flood_hz, stop, figures))
        try:
            keys = Keys(config.stack.prefix)
            # The soak's clock starts once every service is ready: memory is judged from then
            # (after the warm-up), never from before the model was loaded.
            wait_ready(session, keys, set(config.supervisor.services), proc, READY_TIMEOUT_S,
                       log_path=log_path)  # fmt: skip
            subs = record_into(session, keys, [config.stack.camera], rec, frames=False)
            flooder.start()
            start = mono_s()
            while (now := mono_s() - start) < duration_s:
                if proc.poll() is not None:
                    raise RuntimeError(f"the stack exited during the soak (see {log_path})")
                pids = {n: p[0] for n in config.supervisor.services
                        if (p := service_pids(n, config_path))}  # fmt: skip
                rss = {n: mb for n, pid in pids.items() if (mb := _rss_mb(pid)) is not None}
                if (sup := _rss_mb(proc.pid)) is not None:
                    rss["supervisor"] = sup
                figures.samples.append(Sample(now, rss, log_path.stat().st_size, pids))
                log(
                    f"soak {now:5.0f}/{duration_s:.0f} s  flood {figures.flood_messages}  "
                    f"log {log_path.stat().st_size / 1e3:.0f} kB  "
                    + "  ".join(f"{n} {mb:.0f} MB" for n, mb in rss.items())
                )
                stop.wait(sample_s)
            for sub in subs:
                sub.undeclare()
        finally:
            stop.set()
            if flooder.is_alive():
                flooder.join()
            session.close()
            stop_supervisor(proc, STOP_TIMEOUT_S)
    result = summarise(figures, rec.truths, config.camera.hfov_deg)
    result["log"] = str(log_path)
    return result


def soak_table(r: dict[str, Any]) -> str:
    """The figures as markdown, as they go into docs/benchmarks.md."""
    lines = [
        f"soak: {r['duration_s']:.0f} s, {r['flood_messages']} garbage messages, "
        f"log {r['log_bytes'] / 1e3:.0f} kB "
        f"({r['log_bytes_per_s_second_half']:.1f} B/s over the second half)",
        f"still following: {r['still_following']} (person in view "
        f"{100 * r['last_window_in_view']:.0f} % of the last {r['last_window_s']:.0f} s, mean "
        f"range {r['last_window_mean_range_m']:.2f} m)",
        "",
    ]
    if not r["memory"]:
        lines.append(
            f"memory: not judged: the run ended before two samples after the "
            f"{r['warm_up_s']:.0f} s warm-up (the stack counts from when it was ready)"
        )
        return "\n".join(lines)
    lines += [
        f"| process | RSS {r['warm_up_s']:.0f} s after ready (MB) | at the end | max | growth "
        "| restarts |",
        "|---|---|---|---|---|---|",
    ]
    for name, m in r["memory"].items():
        lines.append(
            f"| {name} | {m['start_mb']:.0f} | {m['end_mb']:.0f} | {m['max_mb']:.0f} | "
            f"{m['growth_mb']:+.1f} | {r['restarts'].get(name, 0)} |"
        )
    return "\n".join(lines)
