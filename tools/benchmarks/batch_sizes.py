"""Time per image by batch size on one backend, with the choice the detector would make.

The detector's start-up measurement (perception/batching.py) times the whole detection
(letterbox, inference, decoding) at batch 1, 2, 4 ... and keeps a batch only where it saves
``batch_min_gain`` per image. This runs the same measurement on its own, on any backend, with
more runs, and also times the model alone (``infer`` on a ready batch), so that a reader sees
where a batch pays: in the model (one launch for k images on a GPU) or not at all (a CPU whose
threads already fill every core). Ratios are against batch 1, taken in the same run.
"""

from __future__ import annotations

import json
import statistics
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from common.clock import perf_s
from perception import PROBE_SHAPE, Detector, measure_batch, probe_sizes


@dataclass(frozen=True, slots=True)
class BatchOptions:
    model: Path
    backend: str
    largest: int
    runs: int
    min_gain: float
    backend_options: dict[str, Any]
    as_json: bool


def _model_alone_ms(detector: Detector, sizes: list[int], runs: int) -> dict[int, float]:
    """The backend's ``infer`` alone on a ready letterboxed batch: median ms per image."""
    info = detector.info
    times: dict[int, list[float]] = {size: [] for size in sizes}
    batches = {
        size: np.zeros((size, 3, info.input_height, info.input_width), np.float32) for size in sizes
    }
    backend = detector.backend
    for size in sizes:
        backend.infer(batches[size])  # warm-up: buffers (and a CUDA graph) for this shape
    for _ in range(runs):
        for size in sizes:
            t0 = perf_s()
            backend.infer(batches[size])
            times[size].append((perf_s() - t0) / size)
    return {size: statistics.median(t) * 1000 for size, t in times.items()}


def run(options: BatchOptions, say: Callable[[str], None]) -> int:
    """Measure and print; Ctrl-C (KeyboardInterrupt) stops it at once, the model closed."""
    say(f"opening {options.model.name} on {options.backend} for batches up to {options.largest}")
    options_for_backend = {"max_batch": options.largest, **options.backend_options}
    det = Detector.open(options.model, backend=options.backend, **options_for_backend)
    try:
        sizes = probe_sizes(options.largest)
        say(f"timing the whole detection at batch {sizes} ({options.runs} runs each)")
        choice = measure_batch(det.detect_batch, options.largest, options.runs, options.min_gain)
        say("timing the model alone")
        alone = _model_alone_ms(det, sizes, options.runs)
        figures = {
            "backend": options.backend,
            "device": det.backend.device,
            "precision": det.backend.precision,
            "input": [det.info.input_height, det.info.input_width],
            "probe_image": list(PROBE_SHAPE),
            "runs": options.runs,
            "whole_ms_per_image": choice.per_image_ms,
            "model_ms_per_image": alone,
            "chosen_batch": choice.size,
            "min_gain": options.min_gain,
        }
    finally:
        det.close()
    if options.as_json:
        print(json.dumps(figures))
        return 0
    whole, base_model = choice.per_image_ms, alone[1]
    print(
        f"{options.backend} on {figures['device']} ({figures['precision']}), input "
        f"{det.info.input_width}x{det.info.input_height}, median of {options.runs} runs"
    )
    print("| batch | whole ms/image | vs batch 1 | model ms/image | vs batch 1 |")
    print("|---:|---:|---:|---:|---:|")
    for size in sizes:
        print(
            f"| {size} | {whole[size]:.2f} | {whole[size] / whole[1]:.2f}x | "
            f"{alone[size]:.2f} | {alone[size] / base_model:.2f}x |"
        )
    print(
        f"the detector would run rounds of up to {choice.size} frame(s) "
        f"(batch_min_gain {options.min_gain:.0%})"
    )
    sys.stdout.flush()
    return 0
