"""How many frames a detection round takes: a batch only where it serves frames faster.

A batch of k frames pays off where the runtime runs k images in less than k times one image's
time: on a GPU, one launch for k images. On a CPU whose inference threads already fill every
core it does not (docs/benchmarks.md, "Several cameras on one detector": per image, batch 4
cost 25 % more than batch 1 on the 2-core CI machine), and a batched frame also waits for the
whole batch. So the detector does not take ``detector.max_batch`` on trust: at start, with
``detector.batch_choice = "measured"`` (the default), it times the model at batch 1, 2, 4, ...
up to the round's size (``batch_probe_runs`` runs each, taken in turn, their median) and keeps
the largest size whose time per image is at least ``batch_min_gain`` below the best smaller
size's. A batch is thus used only where it was measured to be faster per frame than what it
replaces, and a machine where batching does not pay runs batch 1. ``"max"`` always fills
rounds up to ``max_batch`` (what a benchmark compares against).

The sizes and the rule are pure (:func:`probe_sizes`, :func:`choose`); :func:`measure` runs
the detector on a still image.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.clock import perf_s

#: The still image the sizes are timed on: mid-grey, a common camera size (letterboxed as any
#: frame is; the model's cost does not depend on the pixels).
PROBE_SHAPE = (480, 640, 3)


def probe_sizes(largest: int) -> list[int]:
    """The batch sizes timed for rounds of up to ``largest`` frames: 1, the powers of two
    below ``largest``, and ``largest``."""
    if largest < 1:
        raise ValueError(f"a round takes at least 1 frame, got {largest}")
    sizes = [1]
    while sizes[-1] * 2 < largest:
        sizes.append(sizes[-1] * 2)
    if sizes[-1] != largest:
        sizes.append(largest)
    return sizes


def choose(per_image_s: dict[int, float], min_gain: float) -> int:
    """The batch size to run: the largest whose time per image is at least ``min_gain`` (a
    fraction) below that of the best smaller size, each size judged against the size kept so
    far; 1 when no larger size was measured to gain that much."""
    if 1 not in per_image_s:
        raise ValueError("batch 1 must be measured: it is what every other size is judged by")
    best = 1
    for size in sorted(per_image_s):
        if size > best and per_image_s[size] <= per_image_s[best] * (1.0 - min_gain):
            best = size
    return best


@dataclass(frozen=True, slots=True)
class BatchChoice:
    """What the start-up measurement found and chose."""

    size: int
    per_image_ms: dict[int, float]
    min_gain: float

    def describe(self) -> str:
        """One line for the log: each size's time per image and the choice."""
        times = ", ".join(f"{k}: {ms:.1f}" for k, ms in sorted(self.per_image_ms.items()))
        why = "no larger batch saves" if self.size == 1 else f"batch {self.size} saves at least"
        return (
            f"ms per image by batch size ({times}): rounds of up to {self.size} frame(s) "
            f"({why} {self.min_gain:.0%} per image; detector.batch_min_gain)"
        )


def measure(
    detect_batch: Callable[[Sequence[npt.NDArray[np.uint8]]], object],
    largest: int,
    runs: int,
    min_gain: float,
) -> BatchChoice:
    """Time ``detect_batch`` (the whole detection: letterbox, inference, decoding) at each of
    :func:`probe_sizes`, ``runs`` times each, and choose on the medians. Each size's first run
    allocates, so it is never counted; the timed runs take the sizes in turn (1, 2, 4, 1, 2,
    4, ...), so that a load that comes or goes on the machine meanwhile weighs on every size
    alike."""
    still = np.full(PROBE_SHAPE, 114, np.uint8)
    sizes = probe_sizes(largest)
    for size in sizes:
        detect_batch([still] * size)  # warm-up: buffers for this shape
    times: dict[int, list[float]] = {size: [] for size in sizes}
    for _ in range(runs):
        for size in sizes:
            t0 = perf_s()
            detect_batch([still] * size)
            times[size].append((perf_s() - t0) / size)
    per_image = {size: statistics.median(t) for size, t in times.items()}
    size = choose(per_image, min_gain)
    return BatchChoice(size, {k: v * 1000 for k, v in per_image.items()}, min_gain)
