"""The depth benchmark's synthetic hard cases and its timings of the methods per frame."""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable
from typing import Any

import numpy as np

from common.clock import ms_since, perf_s
from perception import Intrinsics, depth_metres
from perception import measure_depth as measure
from tools.benchmarks.depth_methods import centre_pixel, no_rejection
from tools.benchmarks.depth_reference import Depth, measure_reference

#: Every depth method by name: (depth, intrinsics, boxes) -> the depth columns.
DEPTH_METHODS: dict[str, Callable[..., dict[str, Any]]] = {
    "depth": measure,
    "yolo_ros": measure_reference,
    "centre": centre_pixel,
    "no_reject": no_rejection,
}


def _synthetic(z: float, rect: tuple[int, int, int, int], back: float) -> Depth:
    d = np.full((480, 640), back, np.float32)
    x0, y0, x1, y1 = rect
    d[y0:y1, x0:x1] = z
    return d


def synthetic_cases(corr_px: float | None = None) -> list[dict[str, Any]]:
    """The depth methods on hard synthetic scenes the simulator's worlds seldom make (a flat
    target before a wall, stereo noise 0.005 z^2 correlated over ``corr_px``, None: the
    simulator's default): each case's truth z and what each method says."""
    from simworld.depth import DepthNoise, unit_noise

    if corr_px is None:
        corr_px = DepthNoise().noise_corr_px

    intr = Intrinsics.from_hfov(640, 480, 60.0)
    rng = np.random.default_rng(5)

    def noisy(d: Depth) -> Depth:
        return (d + unit_noise(d.shape, corr_px, rng) * 0.005 * d * d).astype(np.float32)

    thin = noisy(_synthetic(1.5, (305, 100, 335, 400), 5.0))
    occluded = noisy(_synthetic(4.0, (270, 140, 370, 340), 8.0))
    occluded[150:250, 290:350] = 1.2  # a nearer thing over the target's middle, 30 % of it
    legs = noisy(_synthetic(3.0, (280, 120, 360, 360), 9.0))
    legs[290:360, 240:400] = 2.2  # a low bin in front hides the bottom third
    sparse = _synthetic(2.0, (0, 0, 0, 0), 2.0)
    sparse[:] = np.nan
    sparse[240:242, 300:305] = 2.0  # 10 readings in the whole box
    cases = [
        ("thin target, box 80 % background", thin, (245, 90, 395, 410), 1.5),
        ("nearer thing over 30 % of the target", occluded, (270, 140, 370, 340), 4.0),
        ("low bin hides the bottom third", legs, (270, 110, 370, 370), 3.0),
        ("10 valid pixels in the box", sparse, (250, 150, 390, 350), math.nan),
    ]
    out = []
    for name, depth, b, truth in cases:
        xyxy = np.array([b], np.float32)
        row: dict[str, Any] = {"case": name, "truth_z_m": truth}
        for method, fn in DEPTH_METHODS.items():
            row[method] = float(fn(depth, intr, xyxy)["z_m"][0])
        out.append(row)
    return out


def time_per_boxes(camera: Any) -> dict[str, Any]:
    """ms per 640x480 frame for 1, 5 and 20 person-sized boxes: depth_metres + each method,
    on a frame of ``camera`` (depth_worlds.Camera)."""
    from common.messages import Header
    from simworld.depth import depth_frame
    from tools.benchmarks.depth_worlds import make_world

    rng = np.random.default_rng(7)
    world = make_world(rng, np.random.default_rng(8), (2.5, 3.0), camera.spec.hfov_deg)
    depth_m = camera.frame(world).depth
    header = Header(stamp_ns=1, seq=0, frame_id="c", source="b")
    frame = depth_frame(depth_m, camera.spec, header, camera.noise)
    intr = Intrinsics.of(frame)
    out: dict[str, Any] = {"depth_metres": _median_ms(lambda: depth_metres(frame))}
    depth: Depth = depth_metres(frame)
    for n in (1, 5, 20):
        # person-sized boxes (at 2..5 m) spread over the frame
        cx, cy = rng.uniform(60, 580, n), rng.uniform(150, 330, n)
        hh = rng.uniform(100, 240, n)
        xyxy = np.stack([cx - hh / 4, cy - hh / 2, cx + hh / 4, cy + hh / 2], 1).astype(np.float32)
        out[str(n)] = {
            "depth": _median_ms(lambda b=xyxy: measure(depth, intr, b)),
            "yolo_ros": _median_ms(lambda b=xyxy: measure_reference(depth, intr, b)),
        }
    return out


def _median_ms(fn: Any, runs: int = 30) -> float:
    fn()
    samples = []
    for _ in range(runs):
        t0 = perf_s()
        fn()
        samples.append(ms_since(t0))
    return statistics.median(samples)


def report_synthetic(cases: list[dict[str, Any]]) -> None:
    names = " / ".join(DEPTH_METHODS)
    print(f"  synthetic hard cases, z (m): truth / {names} (nan = unknown)")
    for c in cases:
        cells = " ".join(f"{c[m]:6.2f}" for m in DEPTH_METHODS)
        print(f"    {c['case']:<40} {c['truth_z_m']:6.2f} {cells}")
