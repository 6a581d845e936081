"""python -m tools.benchmarks scale: several cameras on one detector against one stack each.

What it runs: stacks of simulated cameras and the detector, nothing else: the detector is what
several cameras share, so its memory, throughput, latency and fairness are what this measures
most directly (no controller or metrics process competes for the two cores; this process
counts the detections itself). The cameras come from one of two places (``--cameras-from``):

- ``sim`` (the default): the simulator renders every camera of the stack from one world, in one
  process, as a simulated robot's stack runs them (the cameras spread round the robot);
- ``processes``: one camera process per camera with a still source (``--source``), as the
  supervisor starts a real robot's cameras: what each camera process costs shows here.

For each N of ``--cameras``:

- ``measured``: one stack, N cameras, one detector with ``max_batch = N`` and
  ``batch_choice = "measured"`` (what a user who raises max_batch gets: the detector times the
  batch sizes at start and batches only where it pays, perception/batching.py);
- ``shared``: the same with ``batch_choice = "max"``: every round batched up to N (forced);
- ``batch1``: the same stack with ``max_batch = 1`` (one frame per inference, same load);
- ``stacks``: N one-camera stacks, each with its own detector (what a user does today).

N = 1 is one stack of one camera (the three are the same). Each condition starts its stacks
(each on a private port), waits ``warmup_s`` (excluded), then measures ``seconds``: detections
per camera (FPS), capture-to-detections latency per camera (the frame's capture stamp to the
detections' arrival here, one host's wall clock), the detector's mean batch (its ``batches``
and ``batched_frames`` counters) and the memory of the stack's processes (supervisor, detector
and cameras; the detector's apart: one model copy each): the proportional set size (PSS, each
shared page divided among the processes mapping it, so the sum is what they take together;
the ratios use it) and the summed resident set (RSS, which counts every shared library once
per process). Fairness is the slowest camera's FPS over
the fastest's. Progress goes to stderr, the table (or ``--json``) to stdout.
"""

from __future__ import annotations

import dataclasses
import json
import tempfile
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from common.clock import mono_s
from common.errors import StackError
from common.files import temp_root
from common.machine import machine_info
from services.detector import contract as detector
from stack.config import Config
from stack.config_file import load_config
from tools.benchmarks.stacks import (
    DEFAULT_RATE_HZ,
    DEFAULT_SOURCE,
    SOURCES,
    CameraLoad,
    PerCamera,
    Stack,
    Watch,
    percentile,
    progress,
    ratio,
    source_services,
    stack_config,
    start_stack,
    stop_all,
)
from tools.launch import pss_kb, rss_kb, service_pids

#: N one-camera stacks are skipped when their estimated memory passes this share of what the
#: machine has available.
MEMORY_SHARE = 0.7


@dataclasses.dataclass(frozen=True, slots=True)
class ScaleOptions:
    """What ``zstack scale-benchmark`` was asked for."""

    config: str | None = None
    cameras: tuple[int, ...] = (1, 2, 4, 8)
    seconds: float = 20.0
    warmup: float = 20.0
    source: str = DEFAULT_SOURCE
    rate_hz: float = DEFAULT_RATE_HZ
    cameras_from: str = "sim"
    as_json: bool = False

    def __post_init__(self) -> None:
        if not self.cameras or any(not 1 <= n <= 32 for n in self.cameras):
            raise StackError(f"--cameras must be numbers within 1..32, got {self.cameras}")
        if self.seconds <= 0 or self.warmup < 0:
            raise StackError("--seconds must be > 0 and --warmup >= 0")
        if not 0.1 <= self.rate_hz <= 100:
            raise StackError(f"--rate must be within 0.1..100 Hz, got {self.rate_hz}")
        if self.cameras_from not in SOURCES:
            raise StackError(
                f"--cameras-from must be one of {', '.join(SOURCES)}, got {self.cameras_from!r}"
            )


@dataclasses.dataclass(frozen=True, slots=True)
class Result(PerCamera):
    """One condition's figures."""

    n: int
    setup: str  # "shared" | "batch1" | "stacks" | "one"
    seconds: float
    fps: dict[str, float]  # per camera
    p50_ms: dict[str, float]
    p95_ms: dict[str, float]
    rss_mb: float  # summed VmRSS of every process of the condition: detectors and cameras
    detector_rss_mb: float  # the detectors' alone (all of them)
    pss_mb: float  # summed PSS of every process: supervisors, detectors, cameras
    detector_pss_mb: float
    batch_mean: float


SETUP_TEXT = {
    "one": "1 stack, 1 camera",
    "measured": "1 detector, measured",
    "shared": "1 detector, batch N",
    "batch1": "1 detector, batch 1",
    "stacks": "{n} one-camera stacks",
}


def ratios(results: Sequence[Result]) -> list[dict[str, Any]]:
    """For each N: one detector (as shipped: measured batching) against N stacks and against
    one camera (memory: PSS), and each batching choice against batch 1 (detections/s,
    latency)."""
    by = {(r.n, r.setup): r for r in results}
    one = by.get((1, "one"))
    out = []
    for n in sorted({r.n for r in results if r.n > 1}):
        measured, shared = by.get((n, "measured")), by.get((n, "shared"))
        b1, stacks = by.get((n, "batch1")), by.get((n, "stacks"))
        row: dict[str, Any] = {"n": n}
        if measured and one:
            row["memory_vs_one_camera"] = ratio(measured.pss_mb, one.pss_mb)
            row["detector_memory_vs_one_camera"] = ratio(
                measured.detector_pss_mb, one.detector_pss_mb
            )
        if stacks and one:
            row["stacks_memory_vs_one_camera"] = ratio(stacks.pss_mb, one.pss_mb)
        if measured and stacks:
            row["memory_shared_vs_stacks"] = ratio(measured.pss_mb, stacks.pss_mb)
            row["fps_shared_vs_stacks"] = ratio(measured.total_fps, stacks.total_fps)
            row["p50_shared_vs_stacks"] = ratio(measured.worst_p50_ms, stacks.worst_p50_ms)
        for name, batched in (("measured", measured), ("batched", shared)):
            if batched and b1:
                row[f"fps_{name}_vs_batch1"] = ratio(batched.total_fps, b1.total_fps)
                row[f"p50_{name}_vs_batch1"] = ratio(batched.worst_p50_ms, b1.worst_p50_ms)
                row[f"p95_{name}_vs_batch1"] = ratio(batched.worst_p95_ms, b1.worst_p95_ms)
        out.append(row)
    return out


def render_table(results: Sequence[Result], skipped: Sequence[str]) -> str:
    """The figures as a text table, then the ratios and what was skipped."""
    head = (
        f"{'N':>2}  {'setup':22}{'PSS MB':>8}{'det MB':>8}{'RSS MB':>8}{'det/s':>7}{'min FPS':>8}"
        f"{'max FPS':>8}{'fair':>6}{'p50 ms':>8}{'p95 ms':>8}{'batch':>6}"
    )
    lines = [head, "-" * len(head)]
    for r in results:
        fps = list(r.fps.values())
        lines.append(
            f"{r.n:>2}  {SETUP_TEXT[r.setup].format(n=r.n):22}{r.pss_mb:8.0f}"
            f"{r.detector_pss_mb:8.0f}{r.rss_mb:8.0f}{r.total_fps:7.2f}{min(fps, default=0):8.2f}"
            f"{max(fps, default=0):8.2f}{r.fairness:6.2f}{r.worst_p50_ms:8.0f}"
            f"{r.worst_p95_ms:8.0f}{r.batch_mean:6.2f}"
        )
    lines.append(
        "(PSS: supervisors, detectors and cameras, shared pages divided among them; det MB: "
        "the detectors' PSS; RSS: summed resident sets; p50/p95: the worst camera's "
        "capture-to-detections; batch: the mean frames per inference)"
    )
    names = {
        "memory_vs_one_camera": "PSS, 1 detector / 1 camera",
        "detector_memory_vs_one_camera": "detector PSS, 1 detector / 1 camera",
        "stacks_memory_vs_one_camera": "PSS, N stacks / 1 camera",
        "memory_shared_vs_stacks": "PSS, 1 detector / N stacks",
        "fps_shared_vs_stacks": "det/s, 1 detector / N stacks",
        "p50_shared_vs_stacks": "p50, 1 detector / N stacks",
        "fps_measured_vs_batch1": "det/s, measured / batch 1",
        "p50_measured_vs_batch1": "p50, measured / batch 1",
        "p95_measured_vs_batch1": "p95, measured / batch 1",
        "fps_batched_vs_batch1": "det/s, batch N / batch 1",
        "p50_batched_vs_batch1": "p50, batch N / batch 1",
        "p95_batched_vs_batch1": "p95, batch N / batch 1",
    }
    rows = ratios(results)
    if rows:
        lines += ["", "ratios:"]
        for row in rows:
            parts = [f"{text} {row[key]:.2f}x" for key, text in names.items() if key in row]
            lines.append(f"  N={row['n']}: " + "; ".join(parts))
    lines += [f"skipped: {s}" for s in skipped]
    return "\n".join(lines)


# ---------------------------------------------------------------- processes


def _mem_available_mb() -> float:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) / 1024
    return float("inf")


def _config(base: Config, n: int, max_batch: int, choice: str, options: ScaleOptions,
            path: Path) -> Config:  # fmt: skip
    return stack_config(
        base, path, [CameraLoad(options.rate_hz)] * n, tag="scale",
        cameras_from=options.cameras_from, source=options.source, max_batch=max_batch,
        batch_choice=choice,
    )  # fmt: skip


def _condition(
    base: Config, workdir: Path, n: int, setup: str, options: ScaleOptions,
    stop: threading.Event,
) -> Result:  # fmt: skip
    """Start the condition's stacks, warm up, measure, stop them all."""
    batch = n if setup in ("shared", "measured") else 1
    shapes = [(1, 1)] * n if setup == "stacks" else [(n, batch)]
    choice = "max" if setup == "shared" else "measured"
    stacks: list[Stack] = []
    watches: list[Watch] = []
    try:
        for k, (cams, batch) in enumerate(shapes):
            path = workdir / f"n{n}-{setup}-{k}.toml"
            stacks.append(start_stack(_config(base, cams, batch, choice, options, path), path))
        for s in stacks:
            watches.append(Watch(s))
            watches[-1].wait_ready(options.cameras_from, stop)
        progress(f"  ready; warming up {options.warmup:.0f} s")
        if stop.wait(options.warmup):
            raise KeyboardInterrupt
        for w in watches:
            w.reset()
        if stop.wait(options.seconds / 2):
            raise KeyboardInterrupt
        rss = det_rss = pss = det_pss = 0
        for s in stacks:  # memory mid-phase, every process running
            det_pids = service_pids("detector", s.path)
            cam_pids = [
                p for svc in source_services(s.config, options.cameras_from)
                for p in service_pids(svc, s.path)
            ]  # fmt: skip
            det_rss += sum(rss_kb(p) or 0 for p in det_pids)
            rss += sum(rss_kb(p) or 0 for p in det_pids + cam_pids)
            det_pss += sum(pss_kb(p) or 0 for p in det_pids)
            pss += sum(pss_kb(p) or 0 for p in [s.proc.pid, *det_pids, *cam_pids])
        if stop.wait(options.seconds / 2):
            raise KeyboardInterrupt
        fps: dict[str, float] = {}
        p50: dict[str, float] = {}
        p95: dict[str, float] = {}
        batches = frames = 0
        for k, w in enumerate(watches):
            taken = w.take()
            batches += taken.counters.get(detector.BATCHES, 0)
            frames += taken.counters.get(detector.BATCHED_FRAMES, 0)
            for cam, values in taken.latency_ms.items():
                name = cam if len(watches) == 1 else f"{k}:{cam}"
                fps[name] = len(values) / taken.elapsed_s
                p50[name] = percentile(values, 50)
                p95[name] = percentile(values, 95)
        return Result(n=n, setup=setup, seconds=options.seconds, fps=fps, p50_ms=p50,
                      p95_ms=p95, rss_mb=rss / 1024, detector_rss_mb=det_rss / 1024,
                      pss_mb=pss / 1024, detector_pss_mb=det_pss / 1024,
                      batch_mean=ratio(frames, batches))  # fmt: skip
    finally:
        for w in watches:
            w.close()
        stop_all(stacks)


def main(options: ScaleOptions, stop: threading.Event) -> int:
    """Run every condition of ``options`` and print the table (or JSON)."""
    base = load_config(options.config)
    results: list[Result] = []
    skipped: list[str] = []
    plan = [(n, s) for n in options.cameras for s in
            (("one",) if n == 1 else ("measured", "shared", "batch1", "stacks"))]  # fmt: skip
    started = mono_s()
    with tempfile.TemporaryDirectory(prefix="scale-bench-", dir=temp_root()) as tmp:
        for i, (n, setup) in enumerate(plan, 1):
            if setup == "stacks":
                per_stack = next((r.pss_mb for r in results if r.setup == "one"), 0.0)
                available = _mem_available_mb()
                if per_stack * n > MEMORY_SHARE * available:
                    skipped.append(
                        f"{n} one-camera stacks: about {per_stack * n:.0f} MB against "
                        f"{available:.0f} MB available"
                    )
                    progress(f"skipped: {skipped[-1]}")
                    continue
            progress(f"[{i}/{len(plan)}] N={n}: {SETUP_TEXT[setup].format(n=n)} "
                      f"({mono_s() - started:.0f} s so far)")  # fmt: skip
            results.append(_condition(base, Path(tmp), n, setup, options, stop))
            r = results[-1]
            progress(f"  {r.total_fps:.2f} det/s, fairness {r.fairness:.2f}, "
                      f"{r.pss_mb:.0f} MB, batch {r.batch_mean:.2f}")  # fmt: skip
    if options.as_json:
        out = {
            "results": [r.as_dict() for r in results],
            "ratios": ratios(results),
            "skipped": skipped,
            "options": {**dataclasses.asdict(options)},
            "machine": machine_info(),
        }
        print(json.dumps(out, indent=2, default=str))
    else:
        print(render_table(results, skipped))
    return 0
