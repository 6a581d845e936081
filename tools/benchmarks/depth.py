"""python -m tools.benchmarks depth: the distance to each detected target, measured against the
simulator's truth, by four methods side by side, and what the depth stage costs per frame.

Worlds: the robot at the origin, one to three people (half of the others overlapping the first
in the image, in front of or behind them; in 40 % of the worlds a low bin hides the first's
legs) placed so that the range bands (of the first's front face) up to the depth camera's
maximum are evenly filled. Each world
is rendered by the simulator (services/sim): the colour image, and the aligned depth image
with a stereo camera's faults (``DepthNoise()``: noise sigma 0.005 z^2 correlated over 4 px,
holes at edges and on dark pixels, dropout, mm quantisation, 0.3..10 m; the noise drawn from a
random stream of its own, so every noise setting sees the same worlds), sent through a 16UC1
DepthFrame as a camera would send it. The real default detector runs on the colour image;
each detection is matched to the target that owns the pixel at its box's centre (one detection
per target: the highest score). Per match:

- ``depth``: perception.depth.measure (ours); truth: the distance to what a depth camera
  sees of the target, its visible front face on the ray through its centre
  (simworld/depth.py targets_in_camera, optical frame).
- ``yolo_ros``: the yolo_ros-like reference (tools/benchmarks/depth_reference.py); same truth.
- ``laser``: sector_range over the box's bearing, as the controller uses it (the middle 60 %
  of the box's width); truth: the target's nearest surface, centre range minus its radius.
- ``depth_z``: ours again, z alone against the front face's z.
- ``depth_h``, ``yolo_ros_h``: each depth method's horizontal range, hypot(x, z) in the optical
  frame, against the same point's: what the controller follows by (the horizontal distance
  from the robot base, where the simulator's camera stands), which no vertical offset moves.
- ``box``: box_distance for a ``target_height_m`` person, as the controller uses it (a box
  touching the top or bottom edge gives no distance, counted unknown); truth: its own, the
  distance to the target's centre, where the simulator draws the person's picture (its size
  in the image is the centre's). ``box_face``: the same against the front face (it reads a
  target's radius, 0.25 m, farther).

Bands are by the truth distance to the target's front face (the depth methods'). Times: the
depth stage per frame (depth_metres + measure for every box) against the detector's own time
on the frame, and both methods on 1, 5 and 20 boxes of a 640x480 frame. Ctrl-C stops it at once.
"""

from __future__ import annotations

import json
import math
import statistics
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from common.clock import ms_since, perf_s
from perception import Intrinsics, depth_metres
from perception import measure_depth as measure
from tools.benchmarks.depth_reference import Depth, measure_reference
from tools.benchmarks.library_shared import log

METHODS = ("depth", "yolo_ros", "laser", "box")
#: Ours again, z alone against the truth z (near targets cut by the image edge: see docs); the
#: box height against the front face, as a controller following by it would keep its distance;
#: each depth method's horizontal range hypot(x, z), what the controller follows by.
EXTRA = ("depth_z", "box_face", "depth_h", "yolo_ros_h")
BANDS = ((0.5, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 5.0), (5.0, 7.0), (7.0, 10.0))


@dataclass(frozen=True, slots=True)
class DepthBenchOptions:
    worlds: int = 150
    seed: int = 1
    threads: int = 2
    models_dir: str | None = None
    as_json: bool = False


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
        if not self.err:
            return {"n": 0, "unknown": self.unknown}
        a = np.abs(np.array(self.err))
        rel = a / np.array(self.truth) * 100
        return {
            "n": len(self.err),
            "unknown": self.unknown,
            "median_m": float(np.median(a)),
            "p95_m": float(np.percentile(a, 95)),
            "median_pct": float(np.median(rel)),
            "p95_pct": float(np.percentile(rel, 95)),
            "bias_m": float(np.median(self.err)),
        }


def band_of(distance: float) -> int | None:
    for k, (lo, hi) in enumerate(BANDS):
        if lo <= distance < hi or (k == len(BANDS) - 1 and distance == hi):
            return k
    return None


@dataclass(frozen=True, slots=True)
class Truth:
    """One target's truths: ``face`` the distance to its visible front face on the ray through
    its centre (the depth methods'), ``face_z`` that point's z, ``face_h`` its horizontal range
    hypot(x, z), ``centre`` the distance to its centre at half its height (the box height's)."""

    face: float
    face_z: float
    face_h: float
    centre: float


def truths(world: Any, spec: Any, min_visible: float) -> dict[str, Truth]:
    """Each target the camera sees (more than ``min_visible`` of it), by id."""
    from simworld.depth import targets_in_camera

    radius = {tg.id: tg.radius for tg in world.targets}
    out = {}
    for tid, _name, x, y, z in targets_in_camera(world, spec, min_visible=min_visible):
        face = math.sqrt(x * x + y * y + z * z)
        out[tid] = Truth(face, z, math.hypot(x, z), face * (z + radius[tid]) / z)
    return out


def horizontal(measured: dict[str, npt.NDArray[np.float32]], i: int) -> float:
    """Row ``i``'s horizontal range hypot(x, z) in the optical frame (y is down), NaN where
    unknown: the distance the controller follows by, with the camera at the base's centre."""
    return math.hypot(float(measured["x_m"][i]), float(measured["z_m"][i]))


def score_depth(
    errors: dict[str, list[Errors]],
    band: int,
    ours: dict[str, npt.NDArray[np.float32]],
    ref: dict[str, npt.NDArray[np.float32]],
    i: int,
    t: Truth,
) -> None:
    """Score detection row ``i`` of both depth methods against target truth ``t``: the 3D
    distance, z alone (ours) and the horizontal range."""
    errors["depth"][band].add(float(ours["distance_m"][i]), t.face)
    errors["yolo_ros"][band].add(float(ref["distance_m"][i]), t.face)
    errors["depth_z"][band].add(float(ours["z_m"][i]), t.face_z)
    errors["depth_h"][band].add(horizontal(ours, i), t.face_h)
    errors["yolo_ros_h"][band].add(horizontal(ref, i), t.face_h)


def make_world(rng: np.random.Generator, band: tuple[float, float], hfov_deg: float) -> Any:
    """The robot at the origin; a person whose front face is at a range within ``band`` (in
    the camera's view), up to two more people elsewhere, and sometimes a bin in front."""
    from simworld.scenarios import person
    from simworld.world import Obstacle, Robot, World

    half = math.radians(hfov_deg / 2) * 0.8
    targets = []
    # the centre's range: the front face's plus a person's radius
    first = float(rng.uniform(*band)) + person("p", (0.0, 0.0, 0.0)).radius
    placed: list[tuple[float, float]] = [(first, float(rng.uniform(-half, half)))]
    for _ in range(int(rng.integers(0, 3))):
        r = float(rng.uniform(1.0, band[1] + 3.0))
        if rng.random() < 0.5:
            # overlapping the first person in the image: in front of or behind them, off by
            # a third to two thirds of a person's width
            shift = float(rng.uniform(0.2, 0.45)) * float(rng.choice((-1, 1)))
            b = placed[0][1] + shift / min(r, first)
            if abs(r - first) < 0.6:
                continue
        else:
            b = float(rng.uniform(-half, half))
        placed.append((r, b))
    for i, (r, b) in enumerate(placed):
        # a 3D distance of r to the centre at mid-height: the floor distance is a little less
        flat = math.sqrt(max(r * r - 0.25**2, 0.1))
        x, y = flat * math.cos(b), flat * math.sin(b)
        targets.append(person(f"p{i}", (0.0, x, y), mirror=bool(rng.integers(0, 2))))
    obstacles = []
    if rng.random() < 0.4 and first > 1.8:
        # a low bin between the robot and the first person, hiding their legs
        r = float(rng.uniform(1.0, first - 0.7))
        b = placed[0][1] + float(rng.uniform(-0.08, 0.08))
        obstacles.append(Obstacle(r * math.cos(b), r * math.sin(b), 0.25))
    return World(Robot(), obstacles=obstacles, targets=targets)


def owners(world: Any, spec: Any) -> tuple[npt.NDArray[np.int32], list[Any]]:
    """Which drawn thing owns each pixel (-1: none) and the drawn things, as render draws."""
    from simworld.render import layout

    placed = layout(world, spec)
    owner = np.full((spec.height, spec.width), -1, np.int32)
    for k, p in enumerate(placed):
        if p.rect is not None:
            x0, y0, x1, y1 = p.rect
            owner[y0:y1, x0:x1] = k
    return owner, placed


def laser_scan(world: Any, rng: np.random.Generator) -> Any:
    from common.messages import Header, LaserScan
    from simworld.laser import LaserSpec, cast

    spec = LaserSpec()
    r = world.robot
    ranges = cast((r.x, r.y, r.theta), world.circles(), spec, rng)
    return LaserScan(
        header=Header(stamp_ns=1, seq=0, frame_id="laser", source="bench"),
        angle_min=spec.angle_min,
        angle_increment=spec.angle_increment,
        range_min=spec.range_min,
        range_max=spec.range_max,
        ranges=ranges,
    )


def run(opts: DepthBenchOptions, noise_corr_px: float | None = None) -> dict[str, Any]:
    """The benchmark; ``noise_corr_px`` overrides the depth noise's correlation length (px;
    None: the simulator's default; 0: independent pixels, for comparison on the same worlds).
    """
    from common.messages import Detections, Header
    from common.settings import DEFAULT_CONFIG
    from modelprep.files import default_model_path
    from perception import Detector
    from services.controller.contract import ControllerSettings
    from services.controller.geometry import box_clipped, box_distance, sector_range
    from services.detector.contract import DetectorSettings
    from services.sim.contract import SimSettings
    from simworld.depth import DepthNoise, apply, depth_frame, render_depth
    from simworld.render import CameraSpec, render
    from stack.config_file import load_config

    model = default_model_path(Path(opts.models_dir) if opts.models_dir else None)
    if not model.exists():
        raise SystemExit(f"the default model {model} is missing: `zstack prepare`")
    sim, ctl = SimSettings(), ControllerSettings()
    spec = CameraSpec(sim.width, sim.height, 60.0, sim.camera_height_m)
    noise = DepthNoise()
    if noise_corr_px is not None:
        noise = replace(noise, noise_corr_px=noise_corr_px)
    conf = load_config(DEFAULT_CONFIG, environ={}).detector.conf
    rng = np.random.default_rng(opts.seed)
    noise_rng = np.random.default_rng([opts.seed, 1])
    errors = {m: [Errors() for _ in BANDS] for m in METHODS + EXTRA}
    times: dict[str, list[float]] = {"detector": [], "depth": [], "yolo_ros": []}
    missed = [0] * len(BANDS)
    log(f"  loading {model.name} (onnx, {opts.threads} thread(s), conf {conf})")
    with Detector.open(
        model, backend="onnx", settings=DetectorSettings(conf=conf), threads=opts.threads
    ) as detector:
        person_id = detector.names.index("person")
        for k in range(opts.worlds):
            world = make_world(rng, BANDS[k % len(BANDS)], spec.hfov_deg)
            colour = render(world, spec)
            noisy = apply(render_depth(world, spec), colour, noise, noise_rng)
            header = Header(stamp_ns=k + 1, seq=k, frame_id="cam", source="bench")
            frame = depth_frame(noisy, spec, header, noise)
            t0 = perf_s()
            result = detector.detect(colour)
            times["detector"].append(ms_since(t0))
            xyxy = result.boxes.xyxy
            t0 = perf_s()
            depth = depth_metres(frame)
            intr = Intrinsics.of(frame)
            ours = measure(depth, intr, xyxy)
            times["depth"].append(ms_since(t0))
            t0 = perf_s()
            ref = measure_reference(depth_metres(frame), intr, xyxy)
            times["yolo_ros"].append(ms_since(t0))
            dets = Detections(
                header=header,
                image_width=spec.width,
                image_height=spec.height,
                boxes=result.boxes,
                class_names=tuple(result.names[c] for c in result.boxes.class_ids),
            )
            scan = laser_scan(world, rng)
            owner, placed = owners(world, spec)
            truth = truths(world, spec, min_visible=0.3)
            matched: dict[int, int] = {}  # placed index -> detection row
            for i in np.argsort(-result.boxes.scores):
                if int(result.boxes.class_ids[i]) != person_id:
                    continue
                x1, y1, x2, y2 = xyxy[i]
                u = min(max(int((x1 + x2) / 2), 0), spec.width - 1)
                v = min(max(int((y1 + y2) / 2), 0), spec.height - 1)
                o = int(owner[v, u])
                if o >= 0 and placed[o].target is not None and o not in matched:
                    matched[o] = int(i)
            for o, p in enumerate(placed):
                if p.target is None:
                    continue
                tg = world.targets[p.target]
                if tg.id not in truth:
                    continue
                t = truth[tg.id]
                band = band_of(t.face)
                if band is None:
                    continue
                i = matched.get(o)
                if i is None:
                    missed[band] += 1
                    continue
                score_depth(errors, band, ours, ref, i, t)
                x1, _, x2, _ = xyxy[i]
                bearing = -math.atan2((x1 + x2) / 2 - spec.width / 2, spec.focal_px)
                half = math.atan((x2 - x1) / 2 / spec.focal_px)
                laser = sector_range(scan, bearing, math.degrees(1.2 * half))
                surface = math.hypot(p.z, p.lateral) - tg.radius
                errors["laser"][band].add(laser if laser > 0 else math.nan, surface)
                boxd = (
                    math.nan
                    if box_clipped(dets, i)
                    else box_distance(dets, i, spec.hfov_deg, ctl.target_height_m)
                )
                errors["box"][band].add(boxd, t.centre)
                errors["box_face"][band].add(boxd, t.face)
            if (k + 1) % 25 == 0:
                log(f"    world {k + 1}/{opts.worlds}")
    return {
        "worlds": opts.worlds,
        "noise": {
            "noise_k": noise.noise_k,
            "corr_px": noise.noise_corr_px,
            "range_m": [noise.range_min_m, noise.range_max_m],
        },
        "bands": [
            {
                "band_m": list(b),
                "missed_by_detector": missed[k],
                **{m: errors[m][k].summary() for m in METHODS + EXTRA},
            }
            for k, b in enumerate(BANDS)
        ],
        "frame_ms": {name: statistics.median(v) for name, v in times.items() if v},
        "per_boxes_ms": time_per_boxes(spec, noise, noise_rng),
        "synthetic": synthetic_cases(noise.noise_corr_px),
    }


def _synthetic(z: float, rect: tuple[int, int, int, int], back: float) -> Depth:
    d = np.full((480, 640), back, np.float32)
    x0, y0, x1, y1 = rect
    d[y0:y1, x0:x1] = z
    return d


def synthetic_cases(corr_px: float | None = None) -> list[dict[str, Any]]:
    """Both methods on hard synthetic scenes the simulator's worlds seldom make (a flat target
    before a wall, stereo noise 0.005 z^2 correlated over ``corr_px``, None: the simulator's
    default): each case's truth z and what each method says."""
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
        out.append(
            {
                "case": name,
                "truth_z_m": truth,
                "depth": float(measure(depth, intr, xyxy)["z_m"][0]),
                "yolo_ros": float(measure_reference(depth, intr, xyxy)["z_m"][0]),
            }
        )
    return out


def time_per_boxes(spec: Any, noise: Any, rng: np.random.Generator) -> dict[str, Any]:
    """ms per 640x480 frame for 1, 5 and 20 person-sized boxes: depth_metres + each method."""
    from common.messages import Header
    from simworld.depth import apply, depth_frame, render_depth
    from simworld.render import render

    world = make_world(np.random.default_rng(7), (2.5, 3.0), spec.hfov_deg)
    colour = render(world, spec)
    noisy = apply(render_depth(world, spec), colour, noise, rng)
    frame = depth_frame(noisy, spec, Header(stamp_ns=1, seq=0, frame_id="c", source="b"), noise)
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


def report(r: dict[str, Any]) -> None:
    print(
        f"depth benchmark: {r['worlds']} simulated worlds, noise sigma "
        f"{r['noise']['noise_k']} z^2 correlated over {r['noise']['corr_px']} px, range "
        f"{r['noise']['range_m']} m; abs error median / "
        "p95 (m), median % of range, unknown; truth: the target's visible front face (laser: "
        "its nearest surface; box: its centre); bands by the front face's distance"
    )
    print("  _h: horizontal range hypot(x, z), what the controller follows by")
    for methods in (METHODS, EXTRA):
        print(f"  {'band m':>8} {'n':>4} " + " ".join(f"{m:>27}" for m in methods))
        for b in r["bands"]:
            cells = []
            for m in methods:
                s = b[m]
                if s["n"] == 0:
                    cells.append(f"{'-':>22} u{s['unknown']:>3}")
                    continue
                cells.append(
                    f"{s['median_m']:6.3f}/{s['p95_m']:6.3f} {s['median_pct']:5.1f}% "
                    f"u{s['unknown']:>3}"
                )
            lo, hi = b["band_m"]
            n = b["depth"]["n"] + b["depth"]["unknown"]
            print(f"  {lo:>3g}-{hi:<4g} {n:>4} " + " ".join(f"{c:>27}" for c in cells))
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


def report_synthetic(cases: list[dict[str, Any]]) -> None:
    print("  synthetic hard cases, z (m): truth / ours / yolo_ros-like (nan = unknown)")
    for c in cases:
        print(f"    {c['case']:<40} {c['truth_z_m']:6.2f} {c['depth']:6.2f} {c['yolo_ros']:6.2f}")


def main(opts: DepthBenchOptions, noise_corr_px: float | None = None) -> int:
    r = run(opts, noise_corr_px)
    if opts.as_json:
        print(json.dumps(r, indent=1))
    else:
        report(r)
        report_synthetic(r["synthetic"])
    return 0
