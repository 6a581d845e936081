"""python -m tools.benchmarks depth: the distance to each detected person, measured against the
simulator's truth by five methods side by side per range band, and what the depth stage costs
per frame.

Worlds (tools/benchmarks/depth_worlds.py): the robot at the origin, one to three people with
bodies of their own (standing facing any way, or walking), half of the others overlapping the
first in the image and a low bin hiding the first's legs in 40 % of the worlds, the range bands
up to the depth camera's 10 m evenly filled. ``--world hard`` (the default, ``sim.world``'s):
rendered as the simulator renders them, with the harder camera's faults at ``SimSettings()``'s
defaults (services/sim/worlds.py: D435-class correlated noise, a range bias, flying pixels at
depth edges; motion blur and exposure lag in the colour image). ``--world simple``: the same
worlds and people's places with today's camera (``DepthNoise()``) and every person the flat card
of before. The depth image goes through a 16UC1 DepthFrame as a camera sends it; the real
default detector runs on the colour image. A detection is matched to the target whose true
visible box (the bounding box of its pixels) it overlaps with an IoU of at least
:data:`~tools.benchmarks.depth_methods.MATCH_IOU` (greedy, best first; one detection per
target).

Methods (:data:`METHODS`), each a horizontal range from the camera (the controller follows by
it; the simulator's camera stands at the base's centre):

- ``depth``: ours, perception ``measure_depth``: hypot(x, z) of its row.
- ``yolo_ros``: the yolo_ros-like reference (depth_reference.py), the same.
- ``centre``: the reading at the box's centre pixel (depth_methods.py ``centre_pixel``).
- ``no_reject``: ours with its background rejection (the nearest heavy cluster) left out: the
  weighted median of every valid reading in the box (depth_methods.py ``no_rejection``).
- ``laser``: sector_range over the box's bearing, as the controller uses it (the middle 60 % of
  the box's width).

Truths: for the four depth methods the point a depth camera observes, targets_in_camera's (a
body's surface on its axis at half its height; a card's front face), its hypot(x, z); for the
laser the nearest point of the circle (``Target.radius``) the simulator's laser sees, bodies or
not (its horizontal range minus the radius). Extras (:data:`EXTRA`): ``depth_3d``, ours' 3D
distance against the point's; ``box``, box_distance for a ``target_height_m`` person against
the distance to the target's axis at half its height (boxes cut by the image's top or bottom
counted unknown); ``surface``, an oracle: ours' statistic over the target's own pixels in the
box read from the fault-free depth (depth_methods.py ``surface``), which tells the body's shape
from the camera's faults. Bands by the depth truth's horizontal range, every method scored on
the same rows. Per method and band: median and p95 of the absolute error (m and % of the
truth's range), the share of rows it called unknown, and the median over every row with an
unknown counted as a miss (``median_all_pct``; None where that is a miss). Ctrl-C stops it at
once; ``--json`` prints one object.
"""

from __future__ import annotations

import dataclasses
import json
import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.clock import ms_since, perf_s
from perception import Intrinsics, depth_metres
from tools.benchmarks.depth_methods import MATCH_IOU, Columns, horizontal, match, surface
from tools.benchmarks.depth_synthetic import (
    DEPTH_METHODS,
    report_synthetic,
    synthetic_cases,
    time_per_boxes,
)
from tools.benchmarks.depth_worlds import Camera, Truth, boxes_of, laser_scan, make_world, seen
from tools.benchmarks.library_shared import log

METHODS = ("depth", "yolo_ros", "centre", "no_reject", "laser")
EXTRA = ("depth_3d", "box", "surface")
BANDS = ((0.5, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 5.0), (5.0, 7.0), (7.0, 10.0))
#: Timed per frame: the detector, and each depth method with depth_metres.
TIMED = ("detector", "depth", "yolo_ros")


@dataclass(frozen=True, slots=True)
class DepthBenchOptions:
    worlds: int = 150
    seed: int = 1
    threads: int = 2
    models_dir: str | None = None
    as_json: bool = False
    world: str = "hard"


@dataclass(slots=True)
class Errors:
    """Signed errors (m) and the truth range (m) of one method's estimates, plus unknowns."""

    err: list[float] = field(default_factory=list)
    truth: list[float] = field(default_factory=list)
    unknown: int = 0

    def add(self, estimate: float, truth: float) -> None:
        if math.isfinite(estimate) and estimate > 0:
            self.err.append(estimate - truth)
            self.truth.append(truth)
        else:
            self.unknown += 1

    def summary(self) -> dict[str, Any]:
        rows = len(self.err) + self.unknown
        share = {"unknown_pct": 100.0 * self.unknown / rows} if rows else {}
        if not self.err:
            return {"n": 0, "unknown": self.unknown, **share}
        a = np.abs(np.array(self.err))
        rel = a / np.array(self.truth) * 100
        return {
            "n": len(self.err),
            "unknown": self.unknown,
            **share,
            "median_m": float(np.median(a)),
            "p95_m": float(np.percentile(a, 95)),
            "median_pct": float(np.median(rel)),
            "median_all_pct": _finite(np.median(np.append(rel, np.full(self.unknown, np.inf)))),
            "p95_pct": float(np.percentile(rel, 95)),
            "bias_m": float(np.median(self.err)),
        }


def _finite(x: float) -> float | None:
    """``x``, or None where it is not finite (JSON has no infinity)."""
    return float(x) if math.isfinite(x) else None


def band_of(distance: float) -> int | None:
    for k, (lo, hi) in enumerate(BANDS):
        if lo <= distance < hi or (k == len(BANDS) - 1 and distance == hi):
            return k
    return None


def score_depth(
    errors: dict[str, list[Errors]], band: int, measured: dict[str, Columns], i: int, t: Truth
) -> None:
    """Score detection row ``i`` of every depth method (``measured``: name -> its columns)
    against target truth ``t``: the horizontal range; ours' 3D distance too."""
    for name, cols in measured.items():
        errors[name][band].add(horizontal(cols, i), t.face_h)
    errors["depth_3d"][band].add(float(measured["depth"]["distance_m"][i]), t.face)


def laser_range(scan: Any, box: Any, spec: Any) -> float:
    """The controller's laser range for a box: the nearest ray over its middle 60 %."""
    from services.controller.geometry import sector_range

    x1, _, x2, _ = box
    bearing = -math.atan2((x1 + x2) / 2 - spec.width / 2, spec.focal_px)
    half = math.atan((x2 - x1) / 2 / spec.focal_px)
    got = sector_range(scan, bearing, math.degrees(1.2 * half))
    return got if got > 0 else math.nan


class Bench:
    """The benchmark's state over its worlds: the errors, the misses and the times."""

    def __init__(self, opts: DepthBenchOptions, detector: Any, conf_target_m: float) -> None:
        self.opts = opts
        self.detector = detector
        self.target_height_m = conf_target_m
        self.camera = Camera(opts.world, opts.seed)
        self.errors = {m: [Errors() for _ in BANDS] for m in METHODS + EXTRA}
        self.times: dict[str, list[float]] = {name: [] for name in TIMED}
        self.missed = [0] * len(BANDS)
        self.person_id = detector.names.index("person")

    def world(self, k: int, rng: np.random.Generator, look: np.random.Generator) -> None:
        """Build, render, detect, measure and score world ``k``."""
        from common.messages import Detections, Header
        from services.controller.geometry import box_clipped, box_distance
        from simworld.depth import depth_frame

        cam, spec = self.camera, self.camera.spec
        built = make_world(rng, look, BANDS[k % len(BANDS)], spec.hfov_deg, f"w{k}", self.opts.seed)
        fr = cam.frame(built)
        header = Header(stamp_ns=k + 1, seq=k, frame_id="cam", source="bench")
        frame = depth_frame(fr.depth, spec, header, cam.noise)
        t0 = perf_s()
        result = self.detector.detect(fr.colour)
        self.times["detector"].append(ms_since(t0))
        xyxy = result.boxes.xyxy
        measured: dict[str, Columns] = {}
        for name, fn in DEPTH_METHODS.items():
            t0 = perf_s()
            measured[name] = fn(depth_metres(frame), Intrinsics.of(frame), xyxy)
            if name in self.times:
                self.times[name].append(ms_since(t0))
        dets = Detections(
            header=header,
            image_width=spec.width,
            image_height=spec.height,
            boxes=result.boxes,
            class_names=tuple(result.names[c] for c in result.boxes.class_ids),
        )
        scan = laser_scan(fr.world, rng)
        truth, owner = seen(fr.world, spec)
        ids, boxes = boxes_of(truth)
        people = np.flatnonzero(result.boxes.class_ids == self.person_id)
        pairs = match(xyxy[people], boxes, MATCH_IOU)
        for j, tid in enumerate(ids):
            t = truth[tid]
            band = band_of(t.face_h)
            if band is None:
                continue
            if j not in pairs:
                self.missed[band] += 1
                continue
            i = int(people[pairs[j]])
            score_depth(self.errors, band, measured, i, t)
            self.errors["laser"][band].add(laser_range(scan, xyxy[i], spec), t.surface)
            clipped = box_clipped(dets, i)
            hfov = spec.hfov_deg
            boxd = math.nan if clipped else box_distance(dets, i, hfov, self.target_height_m)
            self.errors["box"][band].add(boxd, t.centre)
            x, z = surface(fr.truth, owner, t.index, Intrinsics.of(frame), xyxy[i])
            self.errors["surface"][band].add(math.hypot(x, z), t.face_h)

    def result(self) -> dict[str, Any]:
        cam = self.camera
        return {
            "world": self.opts.world,
            "worlds": self.opts.worlds,
            "match_iou": MATCH_IOU,
            "noise": dataclasses.asdict(cam.noise),
            "colour_faults": dataclasses.asdict(cam.colour_faults),
            "bands": [
                {
                    "band_m": list(b),
                    "missed_by_detector": self.missed[k],
                    **{m: self.errors[m][k].summary() for m in METHODS + EXTRA},
                }
                for k, b in enumerate(BANDS)
            ],
            "frame_ms": {name: statistics.median(v) for name, v in self.times.items() if v},
            "per_boxes_ms": time_per_boxes(cam),
            "synthetic": synthetic_cases(cam.noise.noise_corr_px),
        }


def run(opts: DepthBenchOptions) -> dict[str, Any]:
    """The benchmark (module docstring)."""
    from common.settings import DEFAULT_CONFIG
    from modelprep.files import default_model_path
    from perception import Detector
    from services.controller.contract import ControllerSettings
    from services.detector.contract import DetectorSettings
    from stack.config_file import load_config

    model = default_model_path(Path(opts.models_dir) if opts.models_dir else None)
    if not model.exists():
        raise SystemExit(f"the default model {model} is missing: `zstack prepare`")
    conf = load_config(DEFAULT_CONFIG, environ={}).detector.conf
    rng = np.random.default_rng(opts.seed)
    look = np.random.default_rng([opts.seed, 3])
    log(f"  {opts.world} world; loading {model.name} (onnx, {opts.threads} thread(s), conf {conf})")
    with Detector.open(
        model, backend="onnx", settings=DetectorSettings(conf=conf), threads=opts.threads
    ) as detector:
        bench = Bench(opts, detector, ControllerSettings().target_height_m)
        for k in range(opts.worlds):
            bench.world(k, rng, look)
            if (k + 1) % 25 == 0:
                log(f"    world {k + 1}/{opts.worlds}")
        return bench.result()


def _cell(s: dict[str, Any]) -> str:
    unknown = f"u{s.get('unknown_pct', 0.0):3.0f}%"
    if s["n"] == 0:
        return f"{'-':>13} {unknown}"
    return f"{s['median_pct']:5.1f}/{s['p95_pct']:5.1f}% {unknown}"


def _cell_all(s: dict[str, Any]) -> str:
    m = s.get("median_all_pct")
    return "inf" if m is None else f"{m:5.1f}%"


def _table(r: dict[str, Any], names: tuple[str, ...], cell: Any) -> None:
    print(f"  {'band m':>8} {'n':>4} {'miss':>4} " + " ".join(f"{m:>19}" for m in names))
    for b in r["bands"]:
        lo, hi = b["band_m"]
        rows = b["depth"]["n"] + b["depth"]["unknown"]
        cells = " ".join(f"{cell(b[m]):>19}" for m in names)
        print(f"  {lo:>3g}-{hi:<4g} {rows:>4} {b['missed_by_detector']:>4} {cells}")


def report(r: dict[str, Any]) -> None:
    n = r["noise"]
    print(
        f"depth benchmark, {r['world']} world: {r['worlds']} simulated worlds; depth noise "
        f"{n['noise_k']} z^2 over {n['noise_corr_px']} px, bias {n['bias_k']} z^2, flying "
        f"share {n['flying_share']}, range {n['range_min_m']}..{n['range_max_m']} m; matched "
        f"by IoU >= {r['match_iou']} with the true visible box"
    )
    print(
        "  horizontal range error, median / p95 (% of range), u: rows called unknown; truth: "
        "the point a depth camera sees (laser: its circle's nearest point; box: the axis); "
        "surface: ours' statistic on the person's own true depths (no faults), an oracle"
    )
    _table(r, METHODS + EXTRA, _cell)
    print("  median % of range over every row, an unknown counted as a miss (inf)")
    _table(r, METHODS, _cell_all)
    f = r["frame_ms"]
    print(
        f"  per frame (median): detector {f['detector']:.1f} ms; depth stage (depth_metres + "
        f"measure) {f['depth']:.2f} ms = {f['depth'] / f['detector']:.3f}x the detector's; "
        f"yolo_ros-like {f['yolo_ros']:.2f} ms = {f['yolo_ros'] / f['detector']:.3f}x"
    )
    p = r["per_boxes_ms"]
    parts = [f"{n} box(es) {p[n]['depth']:.2f} vs {p[n]['yolo_ros']:.2f}" for n in ("1", "5", "20")]
    print(
        f"  640x480 depth_metres {p['depth_metres']:.2f} ms; measure ours vs yolo_ros-like (ms): "
        + "; ".join(parts)
    )


def main(opts: DepthBenchOptions) -> int:
    r = run(opts)
    if opts.as_json:
        print(json.dumps(r, indent=1))
    else:
        report(r)
        report_synthetic(r["synthetic"])
    return 0
