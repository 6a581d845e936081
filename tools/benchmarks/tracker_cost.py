"""The trackers' cost per frame (issue 42: under 1 ms for 10 people), side by side in one run:
the IoU tracker, the Kalman tracker on positions alone, and with colours (its histograms
included, as the detector computes them from the frame). Synthetic people walk across a
640x480 image at 5 frames a second, each a box of its own colour, for ``frames`` frames;
each row is the median and p95 of the process CPU time of one frame's work."""

from __future__ import annotations

import statistics
from collections.abc import Callable

import numpy as np

from common.boxes import Boxes
from common.clock import cpu_s
from perception import KalmanTracker, Tracker, appearance

W, H, RATE_HZ = 640, 480, 5.0


def _scene(people: int, frames: int, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """``frames`` frames of ``people`` walking boxes: (image, xyxy) each."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(40, W - 80, people)
    vx = rng.uniform(-30, 30, people)
    y0 = rng.uniform(60, 200, people)
    hgt = rng.uniform(120, 260, people)
    colours = rng.integers(0, 255, (people, 3))
    out = []
    for _ in range(frames):
        x = np.clip(x + vx / RATE_HZ, 0, W - 60)
        xyxy = np.stack([x, y0, x + hgt * 0.35, np.minimum(y0 + hgt, H)], axis=1)
        img = np.full((H, W, 3), 110, np.uint8)
        for (a, b, c, d), col in zip(xyxy.astype(int), colours, strict=True):
            img[b:d, a:c] = col
        out.append((img, xyxy.astype(np.float32)))
    return out


def _time(
    step: Callable[[np.ndarray, np.ndarray, float], None],
    scene: list[tuple[np.ndarray, np.ndarray]],
) -> list[float]:
    times = []
    for k, (img, xyxy) in enumerate(scene):
        t0 = cpu_s()
        step(img, xyxy, k / RATE_HZ)
        times.append((cpu_s() - t0) * 1000)
    return times


def _boxes(xyxy: np.ndarray) -> Boxes:
    n = len(xyxy)
    return Boxes(xyxy=xyxy, scores=np.full(n, 0.9, np.float32), class_ids=np.zeros(n, np.int32))


def rows(people: int, frames: int) -> list[tuple[str, float, float]]:
    """(name, median ms, p95 ms) per tracker on the same scene."""
    scene = _scene(people, frames)
    iou, plain, coloured = Tracker(), KalmanTracker(), KalmanTracker()

    def run_iou(img: np.ndarray, xyxy: np.ndarray, t: float) -> None:
        iou.update(_boxes(xyxy), t)

    def run_plain(img: np.ndarray, xyxy: np.ndarray, t: float) -> None:
        plain.update(_boxes(xyxy), t, turned_rad=0.01, focal_px=554.0, image_width=W)

    def run_coloured(img: np.ndarray, xyxy: np.ndarray, t: float) -> None:
        coloured.update(_boxes(xyxy), t, turned_rad=0.01, focal_px=554.0, image_width=W,
                        features=appearance(img, xyxy))  # fmt: skip

    out = []
    for name, step in (("iou", run_iou), ("kalman", run_plain), ("kalman+colour", run_coloured)):
        ms = _time(step, scene)[5:]  # the first frames start the tracks
        out.append((name, statistics.median(ms), float(np.percentile(ms, 95))))
    return out


def main(people: tuple[int, ...], frames: int) -> int:
    print(f"{'people':>6} {'tracker':14} {'median ms':>10} {'p95 ms':>8}")
    for n in people:
        for name, med, p95 in rows(n, frames):
            print(f"{n:>6} {name:14} {med:>10.3f} {p95:>8.3f}")
    return 0
