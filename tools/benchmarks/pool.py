"""python -m tools.benchmarks pool: the detector pool (issue 23) on one host.

What it runs (tools/benchmarks/stacks.py): stacks of simulated cameras (the simulator renders
every camera in one process) and ``detector.workers`` detector workers, nothing else. Three
parts, in one run:

- **throughput**: for each N of ``--cameras`` (4 and 8), N cameras at ``--rate`` Hz on 1 and on
  2 workers: aggregate detections/s, each camera's FPS and capture-to-detections p50/p95 (the
  table shows the worst camera's), fairness (the slowest camera's FPS over the fastest's), and
  each worker's cameras and load (its ``serving.<cam>`` and ``pool_load_permille`` counters);
  then the ratios 2 workers / 1 worker. Each condition waits ``warmup`` s after readiness
  (excluded) and measures ``seconds``.
- **hand-over** (``--kills``, in the stack of the first N on 2 workers, after its measurement):
  SIGKILL a worker (alternately each; the supervisor restarts it), and for each camera the
  victim served, the time from the kill to the first detections of a frame captured after it
  (the dead worker publishes nothing, so they come from the survivor); then wait for the
  restarted worker to rejoin and the cameras to be split again (each worker serving one or
  more, none twice) and for every camera to be detected once more, before the next kill.
  Frames detected twice (the same camera and frame) are counted throughout.
- **uneven load** (``--uneven``): 2 heavy cameras (10 Hz, 640x480) and 2 light ones (2 Hz,
  320x240) on 2 workers. The pool weighs each camera by its frame rate
  (services/detector/pool.py): the table shows each worker's cameras and frame-rate share
  under that rule and under plain rendezvous (unweighted, no load bound: every camera to the
  worker that ranks highest for it), both computed with the pure rule, and how often each
  rule puts both heavy cameras on one worker over ``UNEVEN_TRIALS`` random sets of camera
  names; then the measured per-camera FPS under the weighted rule.
- **capacity** (``--capacity``, tools/benchmarks/pool_capacity.py): a fast and a slow worker
  (two input sizes), shares by measured capacity against the even split.

``--robots N`` runs instead the robots part (tools/benchmarks/pool_robots.py): N simulated
robots, each with ``--robot-cameras`` cameras, on one pool of the largest of ``--workers``.

Progress goes to stderr, the tables (or ``--json``) to stdout; Ctrl-C stops at once.
"""

from __future__ import annotations

import dataclasses
import json
import random
from collections.abc import Mapping, Sequence
from typing import Any

from common.errors import StackError
from common.pool_rule import assign
from services.detector.contract import MAX_WORKERS
from tools.benchmarks.stacks import (
    DEFAULT_RATE_HZ,
    CameraLoad,
    PerCamera,
    percentile,
    ratio,
)

#: The uneven condition: two heavy cameras and two light ones.
HEAVY = CameraLoad(10.0, (640, 480))
LIGHT = CameraLoad(2.0, (320, 240))
UNEVEN = (HEAVY, HEAVY, LIGHT, LIGHT)
#: Random camera-name sets over which each rule's odds of one worker getting both heavy
#: cameras are counted (pure: no processes).
UNEVEN_TRIALS = 1000
UNEVEN_SEED = 23
#: The workers of a one-host pool (``detector.workers = 2``: the service names).
POOL = ("detector", "detector_2")


@dataclasses.dataclass(frozen=True, slots=True)
class PoolOptions:
    """What ``zstack pool-benchmark`` was asked for."""

    config: str | None = None
    cameras: tuple[int, ...] = (4, 8)
    workers: tuple[int, ...] = (1, 2)
    seconds: float = 20.0
    warmup: float = 15.0
    rate_hz: float = DEFAULT_RATE_HZ
    kills: int = 20
    uneven: bool = True
    capacity: bool = True
    fast_size: int = 320
    slow_size: int = 480
    capacity_cameras: int = 8
    capacity_rate_hz: float = 2.0
    robots: int = 0
    robot_cameras: int = 2
    as_json: bool = False

    def __post_init__(self) -> None:
        if not self.cameras or any(not 1 <= n <= 32 for n in self.cameras):
            raise StackError(f"--cameras must be numbers within 1..32, got {self.cameras}")
        if not self.workers or any(not 1 <= w <= MAX_WORKERS for w in self.workers):
            raise StackError(f"--workers must be numbers within 1..{MAX_WORKERS}")
        if self.seconds <= 0 or self.warmup < 0:
            raise StackError("--seconds must be > 0 and --warmup >= 0")
        if not 0.1 <= self.rate_hz <= 100:
            raise StackError(f"--rate must be within 0.1..100 Hz, got {self.rate_hz}")
        if not 0 <= self.kills <= 1000:
            raise StackError(f"--kills must be within 0..1000, got {self.kills}")
        if self.kills and (2 not in self.workers or min(self.cameras) < 2):
            raise StackError("--kills needs 2 among --workers and 2 or more cameras")
        for what, size in (("--fast-size", self.fast_size), ("--slow-size", self.slow_size)):
            if size % 32 or not 160 <= size <= 1280:
                raise StackError(f"{what} must be a multiple of 32 within 160..1280, got {size}")
        if not (self.robots == 0 or 2 <= self.robots <= 8) or not 1 <= self.robot_cameras <= 8:
            raise StackError(
                f"--robots must be 2..8 and --robot-cameras 1..8, got {self.robots} and "
                f"{self.robot_cameras}"
            )
        if not 2 <= self.capacity_cameras <= 32:
            raise StackError(
                f"--capacity-cameras must be within 2..32, got {self.capacity_cameras}"
            )
        if not 0.1 <= self.capacity_rate_hz <= 100:
            raise StackError(
                f"--capacity-rate must be within 0.1..100 Hz, got {self.capacity_rate_hz}"
            )


# ---------------------------------------------------------------- results


@dataclasses.dataclass(frozen=True, slots=True)
class Result(PerCamera):
    """One condition's figures."""

    label: str  # "even" | "uneven"
    n: int  # cameras
    workers: int
    seconds: float
    fps: dict[str, float]  # per camera
    asked_hz: dict[str, float]  # each camera's rate
    p50_ms: dict[str, float]
    p95_ms: dict[str, float]
    served: dict[str, list[str]]  # each worker's cameras, by its counters at the end
    loads: dict[str, float]  # each worker's frame-rate share (0..1), by its counters
    duplicates: int


def pool_ratios(results: Sequence[Result]) -> list[dict[str, Any]]:
    """For each N with both: 2 workers against 1 (the even conditions)."""
    by = {(r.n, r.workers): r for r in results if r.label == "even"}
    out = []
    for n in sorted({n for n, _ in by}):
        one, two = by.get((n, 1)), by.get((n, 2))
        if one and two:
            out.append(
                {
                    "n": n,
                    "fps": ratio(two.total_fps, one.total_fps),
                    "p50": ratio(two.worst_p50_ms, one.worst_p50_ms),
                    "p95": ratio(two.worst_p95_ms, one.worst_p95_ms),
                    "fairness": ratio(two.fairness, one.fairness),
                }
            )
    return out


@dataclasses.dataclass(frozen=True, slots=True)
class Kill:
    """One SIGKILL: the worker, how long each of its cameras waited for detections again,
    and how long until the restarted worker had its share again (NaN: it did not)."""

    victim: str
    handover_s: dict[str, float]
    rejoin_s: float


def handover_summary(kills: Sequence[Kill], duplicates: int) -> dict[str, Any]:
    """p50/p95/max over every camera of every kill, the rejoin times, and the duplicates."""
    times = [t for k in kills for t in k.handover_s.values()]
    rejoin = [k.rejoin_s for k in kills]
    return {
        "kills": len(kills),
        "cameras_handed_over": len(times),
        "p50_s": percentile(times, 50),
        "p95_s": percentile(times, 95),
        "max_s": max(times, default=float("nan")),
        "rejoin_p50_s": percentile(rejoin, 50),
        "rejoin_max_s": max(rejoin, default=float("nan")),
        "duplicates": duplicates,
    }


# ---------------------------------------------------------------- the assignment, pure


def plain_rendezvous(workers: Sequence[str], cameras: Sequence[str]) -> dict[str, str]:
    """Unweighted rendezvous hashing, no load bound: every camera to the worker that ranks
    highest for it (the pool's rule with equal weights and ``balance`` = the worker count,
    under which no worker is ever full)."""
    return assign(workers, dict.fromkeys(cameras, 1.0 / len(cameras)), float(len(workers)))


def shares(
    owners: Mapping[str, str], weights: Mapping[str, float], workers: Sequence[str]
) -> dict[str, tuple[list[str], float]]:
    """Each worker's cameras and their share (0..1) of the cameras' frame rate under
    ``owners``."""
    total = sum(weights.values()) or 1.0
    return {
        w: (
            [c for c in weights if owners.get(c) == w],
            sum(x for c, x in weights.items() if owners.get(c) == w) / total,
        )
        for w in workers
    }


def compare_rules(
    weights: Mapping[str, float], workers: Sequence[str], balance: float
) -> dict[str, dict[str, tuple[list[str], float]]]:
    """Each worker's cameras and frame-rate share, weighted (the pool's rule) and not."""
    return {
        "weighted": shares(assign(workers, weights, balance), weights, workers),
        "plain": shares(plain_rendezvous(workers, list(weights)), weights, workers),
    }


def heavy_together_odds(
    loads: Sequence[CameraLoad],
    workers: Sequence[str],
    balance: float,
    trials: int = UNEVEN_TRIALS,
    seed: int = UNEVEN_SEED,
) -> dict[str, Any]:
    """Over ``trials`` random sets of camera names for ``loads``: how often each rule gives
    one worker every camera of the heaviest weight, and the mean and worst of the largest
    frame-rate share a worker gets."""
    rng = random.Random(seed)
    together = {"weighted": 0, "plain": 0}
    largest: dict[str, list[float]] = {"weighted": [], "plain": []}
    for _ in range(trials):
        names = [f"c{rng.getrandbits(32):08x}" for _ in loads]
        weights = {name: load.rate_hz for name, load in zip(names, loads, strict=True)}
        top = max(weights.values())
        heavy = [c for c, w in weights.items() if w >= top - 1e-9]
        for rule, per_worker in compare_rules(weights, workers, balance).items():
            if any(set(heavy) <= set(cams) for cams, _ in per_worker.values()):
                together[rule] += 1
            largest[rule].append(max(share for _, share in per_worker.values()))
    return {
        rule: {
            "heavy_together": together[rule] / trials,
            "largest_share_mean": sum(largest[rule]) / trials,
            "largest_share_max": max(largest[rule]),
        }
        for rule in together
    }


# ---------------------------------------------------------------- text


def render_results(results: Sequence[Result]) -> str:
    head = (
        f"{'setup':24}{'det/s':>7}{'min FPS':>8}{'max FPS':>8}{'fair':>6}{'p50 ms':>8}"
        f"{'p95 ms':>8}{'dup':>5}  workers: cameras (load)"
    )
    lines = [head, "-" * len(head)]
    for r in results:
        fps = list(r.fps.values())
        setup = f"{r.n} cameras, {r.workers} worker" + ("s" if r.workers > 1 else "")
        if r.label == "uneven":
            setup = f"uneven {r.n}, {r.workers} workers"
        served = "; ".join(
            f"{w}: {','.join(c)} ({r.loads.get(w, 0):.2f})" for w, c in r.served.items()
        )
        lines.append(
            f"{setup:24}{r.total_fps:7.2f}{min(fps, default=0):8.2f}{max(fps, default=0):8.2f}"
            f"{r.fairness:6.2f}{r.worst_p50_ms:8.0f}{r.worst_p95_ms:8.0f}{r.duplicates:5d}  "
            f"{served}"
        )
    lines.append(
        "(p50/p95: the worst camera's capture-to-detections; fair: slowest camera's "
        "FPS / fastest's; dup: frames detected twice; load: frame-rate share)"
    )
    rows = pool_ratios(results)
    if rows:
        lines += ["", "2 workers / 1 worker:"]
        lines += [
            f"  N={r['n']}: det/s {r['fps']:.2f}x; p50 {r['p50']:.2f}x; p95 {r['p95']:.2f}x;"
            f" fairness {r['fairness']:.2f}x"
            for r in rows
        ]
    return "\n".join(lines)


def render_handover(kills: Sequence[Kill], duplicates: int) -> str:
    s = handover_summary(kills, duplicates)
    return (
        f"hand-over after SIGKILL ({s['kills']} kills, {s['cameras_handed_over']} cameras "
        f"handed over): kill to the next detections p50 {s['p50_s']:.2f} s, p95 "
        f"{s['p95_s']:.2f} s, max {s['max_s']:.2f} s; restarted worker has its share again "
        f"after p50 {s['rejoin_p50_s']:.1f} s (max {s['rejoin_max_s']:.1f} s); frames "
        f"detected twice: {duplicates}"
    )


def render_rules(
    rules: Mapping[str, Mapping[str, tuple[list[str], float]]],
    weights: Mapping[str, float],
    odds: Mapping[str, Any],
) -> str:
    lines = [
        "uneven load: "
        + ", ".join(f"{c} {w:.3f}" for c, w in weights.items())
        + " (frame-rate weights)"
    ]
    names = {"weighted": "weighted (the pool's rule)", "plain": "plain rendezvous, unweighted"}
    for rule, per_worker in rules.items():
        parts = "; ".join(
            f"{w}: {','.join(c) or '-'} ({s:.2f})" for w, (c, s) in per_worker.items()
        )
        o = odds[rule]
        lines.append(
            f"  {names[rule]:30} {parts}   [random names: both heavy on one worker "
            f"{o['heavy_together']:.0%}, largest share mean {o['largest_share_mean']:.2f} "
            f"max {o['largest_share_max']:.2f}]"
        )
    return "\n".join(lines)


def to_json(
    results: Sequence[Result],
    kills: Sequence[Kill],
    duplicates: int,
    rules: Any,
    odds: Any,
    options: PoolOptions,
    machine: Any,
    capacity: Sequence[Any] = (),
) -> str:
    return json.dumps(
        {
            "capacity": [r.as_dict() for r in capacity],
            "results": [r.as_dict() for r in results],
            "ratios": pool_ratios(results),
            "handover": {
                **handover_summary(kills, duplicates),
                "each": [dataclasses.asdict(k) for k in kills],
            }
            if kills
            else None,
            "uneven_rules": rules,
            "uneven_odds": odds,
            "options": dataclasses.asdict(options),
            "machine": machine,
        },
        indent=2,
        default=str,
    )
