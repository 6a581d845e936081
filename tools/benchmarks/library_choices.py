"""Our hand-written tracker, settings loader and msgpack field walker against well-kept libraries.

Issue 21, point 6: where a library already does what we wrote by hand, measure and decide. One
run prints the figures of all three decisions side by side (docs/library-decisions.md has them
and the decisions):

1. tracker: perception/tracker.py against ByteTrack of the ``trackers`` package
   (Roboflow's clean-room re-implementation), by identity switches and fragmentations on the
   ``crossing`` and ``two_people`` scenarios, and time per frame. The frames are rendered
   offline with the simulator's own world and renderer, the real default detector runs once on
   each, and every tracker is fed the same boxes; see ``evaluate`` for the ground-truth rule.
2. settings loader: common/config_file.py + common/setting_checks.py against pydantic-settings
   and msgspec (``msgspec.toml`` + ``Meta`` constraints): load time of deploy/stack.toml, the
   error line for bad configs, dependency size, the lines each would replace.
3. msgpack field walker: common/fields.py + common/codec.py against msgspec Structs decoding
   the very same bytes: decode time of a Frame, a Detections of 20 boxes and a Twist, and the
   error raised for garbage.

A library that is not installed is said in one line (which package to install) and its
comparison skipped; the script always runs with the stack's own code alone. Nothing here is a
dependency of the stack: install the compared libraries into a throwaway place, e.g.
``pip install --target /tmp/site trackers pydantic-settings msgspec`` and run with
``PYTHONPATH=.:/tmp/site``.

    python tools/benchmarks/library_choices.py [--only tracker,settings,codec] [--frames N]
        [--models-dir DIR] [--cache-dir DIR] [--threads N]
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import math
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import typing
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Annotated, Any, Literal

import msgpack
import numpy as np
import numpy.typing as npt

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from common.boxes import MAX_DETECTIONS, Boxes  # noqa: E402
from common.clock import mono_ns, perf_s, wall_ns  # noqa: E402
from common.codec import Message  # noqa: E402
from common.config_file import load_config  # noqa: E402
from common.errors import ConfigError, DecodeError  # noqa: E402
from common.messages import (  # noqa: E402
    FRAME_ENCODINGS,
    MAX_COMMAND,
    MAX_IMAGE_SIDE,
    MAX_NAME_CHARS,
    Detections,
    Frame,
    Header,
    Twist,
)
from common.settings import (  # noqa: E402
    DEFAULT_CONFIG,
    Config,
    ControllerSettings,
    DetectorSettings,
    SimSettings,
    TrackerSettings,
)

SCENARIOS_MEASURED = ("crossing", "two_people")
# Extra worlds, not stack scenarios: two people whose boxes overlap, the case where id switches
# happen at all (in crossing and two_people no two boxes ever overlap). Robot still.
STRESS_WORLDS = {
    # bob walks between the robot and alice, hiding her for a few seconds
    "pass_in_front": (((0, 4.5, 0.0),), ((0, 3.0, -2.0), (12, 3.0, 2.0)), 20.0),
    # alice and bob walk across each other's path at nearly the same depth
    "cross_paths": (((0, 4.5, -1.5), (10, 4.5, 1.5)), ((0, 4.2, 1.5), (10, 4.2, -1.5)), 20.0),
}
MATCH_IOU = 0.3  # least IoU between a projected truth box and a detection to call them one


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def missing(package: str, what: str) -> None:
    print(f"  [skipped] {what}: `pip install {package}` (into a throwaway venv or --target dir)")


def per_call_us(fn: Callable[[], Any], min_s: float = 0.1, repeats: int = 7) -> float:
    """Best of ``repeats`` means of ``fn()`` in microseconds, each run at least ``min_s``."""
    fn()
    best = math.inf
    for _ in range(repeats):
        n, t0 = 0, perf_s()
        while True:
            fn()
            n += 1
            elapsed = perf_s() - t0
            if elapsed >= min_s:
                break
        best = min(best, elapsed / n * 1e6)
    return best


def ratio(a: float, b: float) -> str:
    return f"{a / b:.2f}x" if b > 0 else "-"


def site_size_mb(dist_names: list[str]) -> float | None:
    """Installed size of the given distributions (their RECORD files), in MB."""
    from importlib import metadata

    total = 0
    for name in dist_names:
        try:
            dist = metadata.distribution(name)
        except metadata.PackageNotFoundError:
            return None
        for f in dist.files or ():
            p = Path(str(dist.locate_file(f)))
            if p.is_file():
                total += p.stat().st_size
    return total / 1e6


def requirements(dist: str) -> list[str]:
    """The distribution's own requirements, extras left out."""
    from importlib import metadata

    reqs = metadata.requires(dist) or []
    return [r.split(";")[0].strip() for r in reqs if "extra ==" not in r]


def cold_import_ms(module: str, repeats: int = 3) -> float:
    """Best wall time of ``import module`` in a fresh interpreter (this sys.path), ms."""
    code = (
        "import sys, time; sys.path[:0] = sys.argv[1].split(':'); t = time.perf_counter(); "
        f"import {module}; print((time.perf_counter() - t) * 1e3)"
    )
    path = os.pathsep.join(p for p in sys.path if p)
    best = math.inf
    for _ in range(repeats):
        out = subprocess.run(
            [sys.executable, "-c", code, path], capture_output=True, text=True, check=True
        )
        best = min(best, float(out.stdout.strip()))
    return best


# --------------------------------------------------------------------------------------------
# 1. Tracker
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass
class ScenarioFrames:
    """What one scenario run gives the trackers: per frame, time, truth and detections."""

    name: str
    robot: str
    times: list[float]
    truth_ids: list[list[str]]  # ids of the targets whose projected box is visible
    truth_boxes: list[npt.NDArray[np.float64]]  # (k, 4) their boxes, clipped to the image
    det_xyxy: list[npt.NDArray[np.float32]]
    det_scores: list[npt.NDArray[np.float32]]
    det_classes: list[npt.NDArray[np.int32]]


def _to_camera(dx: float, dy: float, c: float, s: float) -> tuple[float, float]:
    """World offset -> (depth, lateral left), as services/sim/render.py projects."""
    return dx * c + dy * s, -dx * s + dy * c


def truth_boxes(world: Any, spec: Any) -> tuple[list[str], npt.NDArray[np.float64]]:
    """The targets the camera shows, and their boxes, projected exactly as the renderer draws
    them (a billboard of the sprite's aspect standing on the floor), clipped to the image.

    A target counts as visible when its clipped box is at least 30 % of its whole box and at
    least half of that clipped box is not covered by a nearer target's or obstacle's billboard
    (the renderer pastes whole rectangles, so this is exact).
    """
    from services.sim.render import OBSTACLE_HEIGHT_M, sprite

    r = world.robot
    c, s = math.cos(r.theta), math.sin(r.theta)
    f, cx, cy = spec.focal_px, spec.width / 2, spec.height / 2
    items: list[tuple[float, str | None, tuple[float, float, float, float]]] = []
    for tg, (tx, ty) in zip(world.targets, world.target_positions(), strict=True):
        cut = sprite(tg.sprite, tg.mirror)
        z, lateral = _to_camera(tx - r.x, ty - r.y, c, s)
        if z < 0.3:
            continue
        h, w = f * tg.height_m / z, f * tg.height_m * cut.shape[1] / cut.shape[0] / z
        u, bottom = cx - f * lateral / z, cy + f * spec.height_m / z
        items.append((z, tg.id, (u - w / 2, bottom - h, u + w / 2, bottom)))
    for ob in world.obstacles:
        z, lateral = _to_camera(ob.x - r.x, ob.y - r.y, c, s)
        if z < 0.3:
            continue
        u, bottom = cx - f * lateral / z, cy + f * spec.height_m / z
        w, h = f * 2 * ob.radius / z, f * OBSTACLE_HEIGHT_M / z
        items.append((z, None, (u - w / 2, bottom - h, u + w / 2, bottom)))
    label = np.full((spec.height, spec.width), -1, np.int32)
    clipped: list[tuple[int, int, int, int]] = []
    items.sort(key=lambda it: -it[0])  # far to near, as the renderer paints
    for k, (_, _, (x0, y0, x1, y1)) in enumerate(items):
        a, b = max(round(x0), 0), max(round(y0), 0)
        e, d = min(round(x1), spec.width), min(round(y1), spec.height)
        clipped.append((a, b, e, d))
        if e > a and d > b:
            label[b:d, a:e] = k
    ids, boxes = [], []
    for k, (_, tid, (x0, y0, x1, y1)) in enumerate(items):
        a, b, e, d = clipped[k]
        area_in = max(e - a, 0) * max(d - b, 0)
        if tid is None or area_in == 0 or area_in < 0.3 * (x1 - x0) * (y1 - y0):
            continue
        if np.count_nonzero(label[b:d, a:e] == k) >= 0.5 * area_in:
            ids.append(tid)
            boxes.append((a, b, e, d))
    return ids, np.array(boxes, np.float64).reshape(-1, 4)


def _steer(world: Any, target_id: str | None, follow_m: float) -> None:
    """Stand-in for the controller (not imported here): turn towards the followed target and
    drive to ``follow_m`` from its surface, from the simulator's truth. It only gives the
    camera the motion a following robot has; the trackers never see the truth."""
    if target_id is None:
        return
    r = world.robot
    i = [t.id for t in world.targets].index(target_id)
    tx, ty = world.target_positions()[i]
    z, lateral = _to_camera(tx - r.x, ty - r.y, math.cos(r.theta), math.sin(r.theta))
    bearing = math.atan2(lateral, z)
    dist = math.hypot(tx - r.x, ty - r.y) - world.targets[i].radius
    v = min(max(0.5 * (dist - follow_m), 0.0), 0.5) if abs(bearing) < 0.5 else 0.0
    world.command(v, min(max(1.5 * bearing, -1.0), 1.0))


def run_scenario(
    name: str, robot: str, rate_hz: float, max_frames: int, detector: Any, cache: Path | None
) -> ScenarioFrames:
    """Step the scenario's world, render each camera frame, detect on it (or read the cache)."""
    from services.sim.render import CameraSpec, render
    from services.sim.scenarios import SCENARIOS

    if name in STRESS_WORLDS:
        from services.sim.scenarios import Scenario, person
        from services.sim.world import Robot, World

        alice, bob, duration = STRESS_WORLDS[name]
        scenario = Scenario(
            name,
            "stress",
            lambda: World(
                Robot(), targets=[person("alice", *alice), person("bob", *bob, mirror=True)]
            ),
            duration,
        )
    else:
        scenario = SCENARIOS[name]
    sim = SimSettings()
    world = scenario.build()
    spec = CameraSpec(sim.width, sim.height, 60.0, sim.camera_height_m)
    follow_m = ControllerSettings().follow_distance_m
    n = min(max_frames, int(scenario.duration_s * rate_hz))
    cached: dict[str, Any] | None = None
    if cache is not None and cache.exists():
        with np.load(cache) as z:
            cached = {k: z[k] for k in z.files}
        if len(cached["offsets"]) != n + 1:
            cached = None
    out = ScenarioFrames(name, robot, [], [], [], [], [], [])
    dt = 1.0 / sim.physics_hz
    for k in range(n):
        while world.t < k / rate_hz - 1e-9:
            if robot == "follow":
                _steer(world, scenario.followed, follow_m)
            world.advance(dt)
        ids, boxes = truth_boxes(world, spec)
        out.times.append(world.t)
        out.truth_ids.append(ids)
        out.truth_boxes.append(boxes)
        if cached is None:
            boxes_k = detector.detect(render(world, spec)).boxes
            out.det_xyxy.append(boxes_k.xyxy)
            out.det_scores.append(boxes_k.scores)
            out.det_classes.append(boxes_k.class_ids)
            if k % 25 == 0:
                log(f"    {name}/{robot}: frame {k + 1}/{n}")
        else:
            a, b = cached["offsets"][k], cached["offsets"][k + 1]
            out.det_xyxy.append(cached["xyxy"][a:b])
            out.det_scores.append(cached["scores"][a:b])
            out.det_classes.append(cached["classes"][a:b])
    if cached is None and cache is not None:
        offsets = np.cumsum([0] + [len(x) for x in out.det_xyxy])
        tmp = cache.with_suffix(".tmp.npz")
        np.savez(
            tmp,
            offsets=offsets,
            xyxy=np.concatenate(out.det_xyxy).reshape(-1, 4),
            scores=np.concatenate(out.det_scores),
            classes=np.concatenate(out.det_classes),
        )
        tmp.replace(cache)
    return out


def _iou(a: npt.NDArray[np.floating], b: npt.NDArray[np.floating]) -> npt.NDArray[np.float64]:
    from perception import iou_matrix

    return iou_matrix(a, b)


@dataclasses.dataclass
class TrackFigures:
    visible: int = 0  # truth-frames in view
    detected: int = 0  # of those, matched to a detection fed to the tracker
    tracked: int = 0  # of those, the detection got a track id
    id_switches: int = 0
    fragmentations: int = 0
    transfers: int = 0  # a track id that moved from one target to another
    ids_per_target: dict[str, int] = dataclasses.field(default_factory=dict)
    frame_us: list[float] = dataclasses.field(default_factory=list)


def time_frames(
    run: ScenarioFrames, min_score: float, make: Callable[[], Callable[..., Any]], replays: int
) -> list[float]:
    """Per-frame update time in microseconds: the least of ``replays`` replays of the whole
    run, each with a fresh tracker (the runs are deterministic), so that another process
    taking the CPU for a moment does not count."""
    best = [math.inf] * len(run.times)
    for _ in range(replays):
        tracker = make()
        for k, t in enumerate(run.times):
            keep = run.det_scores[k] >= min_score
            args = (run.det_xyxy[k][keep], run.det_scores[k][keep], run.det_classes[k][keep], t)
            t0 = perf_s()
            tracker(*args)
            best[k] = min(best[k], (perf_s() - t0) * 1e6)
    return best


def evaluate(
    run: ScenarioFrames, min_score: float, person: int, tracker: Callable[..., npt.NDArray[Any]]
) -> TrackFigures:
    """Feed one tracker the detections scored at least ``min_score``; count its mistakes.

    Ground-truth rule: each frame, the visible targets' projected boxes are matched one-to-one
    to the ``person`` detections by the Hungarian method on IoU, a pair counting only at IoU
    >= MATCH_IOU. This matching does not depend on the tracker. A target is *tracked* in a
    frame when its detection got a track id (not -1). CLEAR-MOT counts: an *id switch* when a
    target is tracked under another id than the last it was tracked under (gaps bridged); a
    *fragmentation* when a target's tracking resumes after visible frames without it; a
    *transfer* when a track id that was on one target is later on another (the follower's lock
    jumping to someone else).
    """
    from scipy.optimize import linear_sum_assignment

    fig = TrackFigures()
    last_id: dict[str, int] = {}
    owner: dict[int, str] = {}
    was_tracked: dict[str, bool] = {}
    seen_ids: dict[str, set[int]] = {}
    for k, t in enumerate(run.times):
        keep = run.det_scores[k] >= min_score
        xyxy, scores = run.det_xyxy[k][keep], run.det_scores[k][keep]
        classes = run.det_classes[k][keep]
        ids = tracker(xyxy, scores, classes, t)
        gt_ids, gt = run.truth_ids[k], run.truth_boxes[k]
        persons = np.flatnonzero(classes == person)
        match: dict[str, int] = {}
        if len(gt) and len(persons):
            iou = _iou(gt, xyxy[persons])
            rows, cols = linear_sum_assignment(iou, maximize=True)
            match = {
                gt_ids[r]: int(persons[c])
                for r, c in zip(rows, cols, strict=True)
                if iou[r, c] >= MATCH_IOU
            }
        for tid in gt_ids:
            fig.visible += 1
            det = match.get(tid)
            track = int(ids[det]) if det is not None else -1
            fig.detected += det is not None
            if track < 0:
                if tid in was_tracked:  # not yet tracked at all is no fragment
                    was_tracked[tid] = False
                continue
            fig.tracked += 1
            if tid in last_id and last_id[tid] != track:
                fig.id_switches += 1
            if tid in was_tracked and not was_tracked[tid]:
                fig.fragmentations += 1
            if owner.get(track, tid) != tid:
                fig.transfers += 1
            last_id[tid], owner[track], was_tracked[tid] = track, tid, True
            seen_ids.setdefault(tid, set()).add(track)
    fig.ids_per_target = {tid: len(v) for tid, v in sorted(seen_ids.items())}
    return fig


def ours_tracker() -> Callable[..., npt.NDArray[Any]]:
    from perception import Tracker

    tr = Tracker(TrackerSettings())

    def update(xyxy: Any, scores: Any, classes: Any, t: float) -> npt.NDArray[Any]:
        return tr.update(Boxes(xyxy=xyxy, scores=scores, class_ids=classes), t)

    return update


def bytetrack_tracker(rate_hz: float, **kwargs: Any) -> Callable[..., npt.NDArray[Any]]:
    import supervision as sv
    from trackers import ByteTrackTracker

    tr = ByteTrackTracker(frame_rate=rate_hz, **kwargs)

    def update(xyxy: Any, scores: Any, classes: Any, t: float) -> npt.NDArray[Any]:
        n = len(xyxy)
        dets = sv.Detections(
            xyxy=xyxy.reshape(-1, 4),
            confidence=scores,
            class_id=classes,
            data={"row": np.arange(n)},
        )
        out = tr.update(dets, timestamp=t)
        ids = np.full(n, -1, np.int64)
        if len(out):
            ids[out.data["row"]] = out.tracker_id
        return ids

    return update


def tracker_section(args: argparse.Namespace) -> None:
    print("\n== 1. Tracker: perception/tracker.py vs ByteTrack (`trackers` package) ==")
    trackers_ok = True
    try:
        from importlib import metadata

        import trackers  # noqa: F401

        version = metadata.version("trackers")
    except ImportError:
        trackers_ok = False
        missing("trackers", "ByteTrack comparison")
    from modelprep.files import default_model_path
    from perception import Detector

    model = default_model_path(Path(args.models_dir) if args.models_dir else None)
    if not model.exists():
        print(
            f"  [skipped] the default model {model} is missing: `zstack prepare"
            "`, or --models-dir DIR"
        )
        return
    rate = SimSettings().camera_rate_hz if args.rate_hz is None else args.rate_hz
    stack_conf = load_config(DEFAULT_CONFIG, environ={}).detector.conf
    low_conf = 0.1
    st = model.stat()
    cache_dir = Path(args.cache_dir) if args.cache_dir else None
    if cache_dir:
        cache_dir.mkdir(parents=True, exist_ok=True)
    detector = None
    runs: list[ScenarioFrames] = []
    plan = [(n, r) for n in SCENARIOS_MEASURED for r in ("still", "follow")]
    if not args.no_stress:
        plan += [(n, "still") for n in STRESS_WORLDS]
    for name, robot in plan:
        key = f"{name}-{robot}-{rate:g}hz-{args.frames}-{st.st_size}-{int(st.st_mtime)}.npz"
        cache = cache_dir / key if cache_dir else None
        if detector is None and not (cache and cache.exists()):
            log(f"  loading {model.name} (onnx, {args.threads} thread(s), conf {low_conf})")
            detector = Detector.open(
                model,
                backend="onnx",
                settings=DetectorSettings(conf=low_conf),
                threads=args.threads,
            )
        log(f"  scenario {name}, robot {robot}: render + detect")
        runs.append(run_scenario(name, robot, rate, args.frames, detector, cache))
    if detector is not None:
        detector.close()
    from common.coco import COCO80

    person = COCO80.index("person")  # the default model's classes
    ts = TrackerSettings()
    candidates: list[tuple[str, Callable[[], Callable[..., npt.NDArray[Any]]]]] = [
        ("ours", ours_tracker)
    ]
    if trackers_ok:
        candidates.append(
            (
                f"ByteTrack {version} defaults",
                lambda: bytetrack_tracker(rate),
            )
        )
        candidates.append(
            (
                f"ByteTrack {version} our thresholds",
                lambda: bytetrack_tracker(
                    rate,
                    track_activation_threshold=ts.high_score,
                    high_conf_det_threshold=ts.high_score,
                    minimum_iou_threshold=ts.iou,
                    minimum_consecutive_frames=1,
                    lost_track_buffer=round(30 * ts.max_age_s),
                ),
            )
        )
    print(
        f"  frames: {rate:g} Hz (the simulator's camera rate), {len(runs[0].times)} a run; "
        f"detector: {model.name} on onnx, boxes kept from conf {low_conf}"
    )
    print(
        "  robot 'still' stays at the origin; 'follow' turns and drives after the followed "
        "target (truth-fed stand-in for the controller)"
    )
    print(
        f"  truth: projected billboard boxes, Hungarian-matched to person boxes at IoU >= "
        f"{MATCH_IOU}"
    )
    print(
        f"  time: update call per frame (ByteTrack: with building its sv.Detections), the "
        f"least of {args.replays} replays, mean and p95 over the frames; ratio to ours"
    )
    if trackers_ok:
        print("  ByteTrack matches across classes; ours only within a class")
    header = (
        f"  {'feed':<10} {'scenario/robot':<20} {'tracker':<34} {'IDSW':>4} {'frag':>4} "
        f"{'xfer':>4} {'tracked/detected/visible':>25} {'ids/target':<22} "
        f"{'us/frame mean':>13} {'p95':>6}"
    )
    for feed, min_score in ((f"conf {stack_conf:g}", stack_conf), (f"conf {low_conf:g}", low_conf)):
        print(header)
        totals: dict[str, list[float]] = {}
        for run in runs:
            ref_mean = None
            for label, make in candidates:
                fig = evaluate(run, min_score, person, make())
                fig.frame_us = time_frames(run, min_score, make, args.replays)
                mean = statistics.fmean(fig.frame_us)
                p95 = float(np.percentile(fig.frame_us, 95))
                ref_mean = mean if ref_mean is None else ref_mean
                per_target = ", ".join(f"{k}:{v}" for k, v in fig.ids_per_target.items())
                cover = f"{fig.tracked}/{fig.detected}/{fig.visible}"
                print(
                    f"  {feed:<10} {run.name + '/' + run.robot:<20} {label:<34} "
                    f"{fig.id_switches:>4} {fig.fragmentations:>4} {fig.transfers:>4} "
                    f"{cover:>25} {per_target:<22} {mean:>8.0f} ({ratio(mean, ref_mean)}) "
                    f"{p95:>6.0f}"
                )
                group = "TOTAL stack" if run.name in SCENARIOS_MEASURED else "TOTAL stress"
                tot = totals.setdefault(f"{group}|{label}", [0, 0, 0, 0.0, 0])
                tot[0] += fig.id_switches
                tot[1] += fig.fragmentations
                tot[2] += fig.transfers
                tot[3] += sum(fig.frame_us)
                tot[4] += len(fig.frame_us)
        for key, (idsw, frag, xfer, us, frames) in totals.items():
            group, label = key.split("|")
            print(
                f"  {feed:<10} {group:<20} {label:<34} {idsw:>4.0f} {frag:>4.0f} "
                f"{xfer:>4.0f} {'':>25} {'':<22} {us / frames:>8.0f}"
            )
    if trackers_ok:
        for dist in ("trackers", "supervision"):
            print(f"  {dist} requires: {', '.join(requirements(dist))}")
        size = site_size_mb(["trackers", "supervision"])
        print(
            f"  trackers + supervision alone: {size or 0:.1f} MB installed; their dependencies "
            "that the stack lacks (opencv-python beside our opencv-python-headless, av, "
            "pydeprecate, requests, pyyaml, tqdm, defusedxml) come on top: see "
            "docs/library-decisions.md"
        )


# --------------------------------------------------------------------------------------------
# 2. Settings loader
# --------------------------------------------------------------------------------------------


def _tables() -> dict[str, type]:
    hints = typing.get_type_hints(Config)
    return {f.name: hints[f.name] for f in dataclasses.fields(Config) if f.name != "path"}


def _default_of(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    assert f.default_factory is not dataclasses.MISSING
    return f.default_factory()


def _constrained(
    hint: Any, bound: tuple[float, float] | None, length: Any, meta: Callable[..., Any]
) -> Any:
    """``hint`` with our BOUNDS (each item of a tuple) and LENGTHS as library constraints;
    ``meta(ge=, le=)`` / ``meta(min_length=, max_length=)`` makes the library's annotation."""
    # Annotated made with run-time values: through Any, as mypy cannot check such a type.
    annotated: Any = Annotated
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if bound is not None:
            item = annotated[args[0], meta(ge=bound[0], le=bound[1])]
            args = (item, ...) if args[-1] is Ellipsis else (item,) * len(args)
        hint = tuple[args]  # type: ignore[valid-type]
        if length is not None:
            hint = Annotated[hint, meta(min_length=int(length[0]), max_length=int(length[1]))]
        return hint
    if bound is not None:
        return Annotated[hint, meta(ge=bound[0], le=bound[1])]
    return hint


def build_pydantic_settings() -> Callable[[Path], Any]:
    """pydantic-settings models made from our dataclasses: their types, BOUNDS as Field(ge,
    le), LENGTHS as Field(min/max_length), unknown keys forbidden, frozen; TOML file source and
    STACK__TABLE__FIELD environment overrides. Our dataclasses' own cross-field checks run as
    an after-validator (constructing the dataclass), as they would stay after adopting it."""
    from pydantic import ConfigDict, Field, create_model, model_validator
    from pydantic_settings import BaseSettings, SettingsConfigDict, TomlConfigSettingsSource

    def meta(**kw: Any) -> Any:
        if "ge" in kw:
            kw["allow_inf_nan"] = False  # our bounds refuse NaN and inf
        return Field(**kw)

    models: dict[str, Any] = {}
    for table, cls in _tables().items():
        hints = typing.get_type_hints(cls)
        bounds, lengths = getattr(cls, "BOUNDS", {}), getattr(cls, "LENGTHS", {})
        fields: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            hint = _constrained(hints[f.name], bounds.get(f.name), lengths.get(f.name), meta)
            fields[f.name] = (hint, _default_of(f))

        def cross(self: Any, _cls: type = cls) -> Any:
            _cls(**{f.name: getattr(self, f.name) for f in dataclasses.fields(_cls)})
            return self

        models[table] = create_model(
            f"{cls.__name__}Model",
            __config__=ConfigDict(extra="forbid", frozen=True),
            __validators__={"cross": model_validator(mode="after")(cross)},
            **fields,
        )
    holder: dict[str, Path] = {}

    def sources(
        cls: Any,
        settings_cls: Any,
        init_settings: Any,
        env_settings: Any,
        dotenv_settings: Any,
        file_secret_settings: Any,
    ) -> tuple[Any, ...]:
        return (env_settings, TomlConfigSettingsSource(settings_cls, holder["path"]))

    namespace: dict[str, Any] = {
        "__annotations__": dict(models),
        "model_config": SettingsConfigDict(
            extra="forbid", frozen=True, env_prefix="STACK__", env_nested_delimiter="__"
        ),
        "settings_customise_sources": classmethod(sources),
        **{table: Field(default_factory=model) for table, model in models.items()},
    }
    full = type("StackConfigModel", (BaseSettings,), namespace)

    def load(path: Path) -> Any:
        holder["path"] = path
        return full()

    return load


def build_msgspec_settings() -> Callable[[Path], Any]:
    """msgspec Structs made from our dataclasses (types, BOUNDS and LENGTHS as Meta, unknown
    fields forbidden, frozen), decoded with msgspec.toml; cross-field checks as __post_init__
    constructing our dataclass. No environment overrides: msgspec has none (ours would stay)."""
    import msgspec

    def meta(**kw: Any) -> Any:
        return msgspec.Meta(**kw)

    structs: list[tuple[str, Any, Any]] = []
    for table, cls in _tables().items():
        hints = typing.get_type_hints(cls)
        bounds, lengths = getattr(cls, "BOUNDS", {}), getattr(cls, "LENGTHS", {})
        fields = [
            (
                f.name,
                _constrained(hints[f.name], bounds.get(f.name), lengths.get(f.name), meta),
                msgspec.field(default_factory=functools.partial(_default_of, f)),
            )
            for f in dataclasses.fields(cls)
        ]

        def post_init(self: Any, _cls: type = cls) -> None:
            try:
                _cls(**{f.name: getattr(self, f.name) for f in dataclasses.fields(_cls)})
            except ConfigError as exc:
                raise ValueError(str(exc)) from None

        struct = msgspec.defstruct(
            f"{cls.__name__}Struct",
            fields,
            kw_only=True,
            frozen=True,
            forbid_unknown_fields=True,
            namespace={"__post_init__": post_init},
        )
        structs.append((table, struct, msgspec.field(default_factory=struct)))
    top = msgspec.defstruct(
        "ConfigStruct", structs, kw_only=True, frozen=True, forbid_unknown_fields=True
    )

    def load(path: Path) -> Any:
        return msgspec.toml.decode(path.read_bytes(), type=top)

    return load


def _first_line(exc: BaseException) -> str:
    lines = [ln for ln in str(exc).splitlines() if ln.strip()]
    text = " | ".join(ln.strip() for ln in lines[:3])
    return f"{type(exc).__name__}: {text}" + (
        f" (+{len(lines) - 3} lines)" if len(lines) > 3 else ""
    )


BAD_CONFIGS: tuple[tuple[str, str, str, dict[str, str]], ...] = (
    # (what, line pattern in stack.toml, replacement, environment)
    ("typo in a key: tracker.hihg_score", r"^high_score = ", "hihg_score = ", {}),
    ("out of range: controller.max_linear = 50", r"^max_linear = 0\.5", "max_linear = 50.0", {}),
    ('wrong type: camera.rate_hz = "fast"', r"^rate_hz = 10\.0", 'rate_hz = "fast"', {}),
    ('wrong type: camera.rate_hz = "10"', r"^rate_hz = 10\.0", 'rate_hz = "10"', {}),
    ("env typo in a table: STACK__TRACKR__IOU", "", "", {"STACK__TRACKR__IOU": "0.3"}),
    ("env typo in a key: STACK__TRACKER__IUO", "", "", {"STACK__TRACKER__IUO": "0.3"}),
)


@dataclasses.dataclass
class _Env:
    values: dict[str, str]

    def __enter__(self) -> None:
        self.saved = {k: os.environ.get(k) for k in self.values}
        os.environ.update(self.values)

    def __exit__(self, *exc: object) -> None:
        for k, v in self.saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _function_lines(path: Path, names: set[str]) -> int:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return sum(
        (node.end_lineno or node.lineno) - node.lineno + 1
        for node in tree.body
        if isinstance(node, ast.FunctionDef | ast.ClassDef) and node.name in names
    )


def _code_lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def settings_section(args: argparse.Namespace) -> None:
    print("\n== 2. Settings loader: common/config_file.py + setting_checks.py vs libraries ==")
    loaders: list[tuple[str, Callable[[Path], Any], str]] = [
        ("ours", lambda p: load_config(p), "common.config_file")
    ]
    for label, build, package, module in (
        ("pydantic-settings", build_pydantic_settings, "pydantic-settings", "pydantic_settings"),
        ("msgspec", build_msgspec_settings, "msgspec", "msgspec"),
    ):
        try:
            t0 = perf_s()
            loader = build()
            build_ms = (perf_s() - t0) * 1e3
            loaders.append((label, loader, module))
            print(
                f"  {label}: models built from our dataclasses in {build_ms:.0f} ms "
                "(paid once per process, at start-up)"
            )
        except ImportError:
            missing(package, f"{label} comparison")
    path = DEFAULT_CONFIG
    saved = {k: os.environ.pop(k) for k in list(os.environ) if k.startswith("STACK__")}
    try:
        print(f"  load + validate {path.relative_to(REPO)} (TOML parse included), per load:")
        ref = None
        for label, loader, module in loaders:
            us = per_call_us(functools.partial(loader, path))
            ref = us if ref is None else ref
            imp = cold_import_ms(module)
            print(
                f"    {label:<18} {us:>8.0f} us  ({ratio(us, ref)} ours)   "
                f"cold `import {module}`: {imp:.0f} ms"
            )
        text = path.read_text(encoding="utf-8")
        with tempfile.TemporaryDirectory() as tmp:
            for what, pattern, repl, env in BAD_CONFIGS:
                bad = Path(tmp) / "stack.toml"
                if pattern:
                    new, count = re.subn(pattern, repl, text, count=1, flags=re.M)
                    assert count == 1, f"{pattern!r} not in {path}"
                else:
                    new = text
                bad.write_text(new, encoding="utf-8")
                print(f"  bad config: {what}")
                for label, loader, _ in loaders:
                    if env and label == "msgspec":
                        print(f"    {label:<18} n/a: no environment source (ours would stay)")
                        continue
                    with _Env(env):
                        try:
                            loader(bad)
                            result = "ACCEPTED (no error)"
                        except Exception as exc:  # each library's own error type, shown
                            result = _first_line(exc)
                    print(f"    {label:<18} {result}")
    finally:
        os.environ.update(saved)
    cf, sc = REPO / "common" / "config_file.py", REPO / "common" / "setting_checks.py"
    pyd = _function_lines(cf, {"_coerce", "_build", "_env_overrides", "_blame"}) + _function_lines(
        sc, {"check_bounds", "check_lengths"}
    )
    msp = _function_lines(cf, {"_coerce", "_build"}) + _function_lines(
        sc, {"check_bounds", "check_lengths"}
    )
    total = _code_lines(cf) + _code_lines(sc)
    bounds_lines = sum(
        len(getattr(cls, "BOUNDS", {})) + len(getattr(cls, "LENGTHS", {}))
        for cls in _tables().values()
    )
    print(
        f"  our loader: {total} lines (config_file.py {_code_lines(cf)}, setting_checks.py "
        f"{_code_lines(sc)}); BOUNDS/LENGTHS entries across the tables: {bounds_lines}"
    )
    print(
        f"  lines a library would replace: pydantic-settings {pyd} (_coerce, _build, "
        f"_env_overrides, _blame, check_bounds, check_lengths); msgspec {msp} (no env source)"
    )
    print(
        "  (the BOUNDS tables would move into the type hints, one Field/Meta per bounded "
        "field: no lines saved there)"
    )
    for label, dists in (
        (
            "pydantic-settings",
            [
                "pydantic-settings",
                "pydantic",
                "pydantic-core",
                "annotated-types",
                "typing-inspection",
                "python-dotenv",
            ],
        ),
        ("msgspec", ["msgspec"]),
    ):
        size = site_size_mb(dists)
        if size is not None:
            print(f"  dependency size: {label}: {size:.1f} MB installed ({', '.join(dists)})")


# --------------------------------------------------------------------------------------------
# 3. msgpack field walker
# --------------------------------------------------------------------------------------------


def build_msgspec_messages() -> dict[str, Any]:
    """msgspec Structs for the envelope and the bodies of Frame, Detections and Twist, reading
    the bytes our codec writes (same keys; unknown keys such as center_size ignored), with our
    bounds as Meta constraints and the array checks in __post_init__ (our check_boxes)."""
    import msgspec
    from msgspec import Meta
    from msgspec.structs import force_setattr

    from common.boxes import check_boxes

    NonNeg = Annotated[int, Meta(ge=0)]
    Side = Annotated[int, Meta(gt=0, le=MAX_IMAGE_SIDE)]
    Name = Annotated[str, Meta(max_length=MAX_NAME_CHARS)]
    LongName = Annotated[str, Meta(max_length=2 * MAX_NAME_CHARS)]
    Finite = Annotated[float, Meta(ge=-sys.float_info.max, le=sys.float_info.max)]
    Cmd = Annotated[float, Meta(ge=-MAX_COMMAND, le=MAX_COMMAND)]
    Count = Annotated[int, Meta(ge=0, le=MAX_DETECTIONS)]
    Version = Annotated[int, Meta(ge=1, le=1)]
    encodings = Literal[tuple(FRAME_ENCODINGS)]  # type: ignore[valid-type]

    # defstruct, not class statements: this module's annotations are strings (PEP 563), which
    # msgspec cannot resolve for classes local to a function.
    def struct(name: str, fields: list[tuple[Any, ...]], **namespace: Any) -> Any:
        return msgspec.defstruct(name, fields, frozen=True, kw_only=True, namespace=namespace)

    header = struct(
        "MHeader",
        [
            ("stamp_ns", NonNeg),
            ("frame_id", str),
            ("seq", NonNeg),
            ("source", str),
            ("mono_ns", NonNeg, 0),
            ("boot_id", str, ""),
        ],
    )

    def frame_checks(self: Any) -> None:
        channels = FRAME_ENCODINGS[self.encoding]
        if channels and len(self.data) != self.width * self.height * channels:
            raise ValueError(
                f"{self.encoding} {self.width}x{self.height} needs "
                f"{self.width * self.height * channels} bytes"
            )
        if not channels and not self.data:
            raise ValueError("empty jpeg")

    frame = struct(
        "MFrame",
        [
            ("header", header),
            ("encoding", encodings),
            ("width", Side),
            ("height", Side),
            ("data", bytes),
        ],
        __post_init__=frame_checks,
    )

    def array(raw: bytes, dtype: str, shape: tuple[int, ...]) -> Any:
        flat = np.frombuffer(raw, dtype=dtype)
        if flat.size != math.prod(shape):
            raise ValueError(f"{flat.size} values do not fit shape {shape}")
        return flat.reshape(shape)

    def detections_checks(self: Any) -> None:
        n = self.n
        arrays = {
            "xyxy": array(self.xyxy, "<f4", (n, 4)),
            "scores": array(self.scores, "<f4", (n,)),
            "class_ids": array(self.class_ids, "<i4", (n,)),
        }
        if self.track_ids is not None:
            arrays["track_ids"] = array(self.track_ids, "<i4", (n,))
        check_boxes(arrays["xyxy"], arrays["scores"], arrays["class_ids"], arrays.get("track_ids"))
        if len(self.class_names) != n:
            raise ValueError(f"class_names must have {n} entries")
        for k, v in arrays.items():
            force_setattr(self, k, v)

    detections = struct(
        "MDetections",
        [
            ("header", header),
            ("image_width", Side),
            ("image_height", Side),
            ("n", Count),
            ("class_ids", bytes),
            ("class_names", tuple[Name, ...]),
            ("scores", bytes),
            ("xyxy", bytes),
            ("track_ids", bytes | None, None),
            ("timing_ms", dict[str, Finite], msgspec.field(default_factory=dict)),
            ("model", LongName, ""),
            ("backend", LongName, ""),
            ("received_ns", NonNeg, 0),
            ("published_ns", NonNeg, 0),
        ],
        __post_init__=detections_checks,
    )
    zero = (0.0, 0.0, 0.0)
    twist = struct(
        "MTwist",
        [
            ("header", header),
            ("linear", tuple[Cmd, Cmd, Cmd], zero),
            ("angular", tuple[Cmd, Cmd, Cmd], zero),
            ("input_stamp_ns", NonNeg, 0),
        ],
    )

    def envelope(tag: str, body: Any) -> Any:
        return msgspec.defstruct(
            f"{tag}Envelope", [("v", Version), ("t", Literal[tag]), ("d", body)]
        )

    return {
        "Frame": msgspec.msgpack.Decoder(envelope("Frame", frame)),
        "Detections": msgspec.msgpack.Decoder(envelope("Detections", detections)),
        "Twist": msgspec.msgpack.Decoder(envelope("Twist", twist)),
    }


def sample_messages() -> dict[str, bytes]:
    """Encoded by our codec: a rendered 640x480 scene as JPEG and raw bgr8, 20 boxes, a Twist."""
    import cv2

    from services.sim.render import CameraSpec, render
    from services.sim.scenarios import SCENARIOS

    world = SCENARIOS["two_people"].build()
    world.t = 10.0
    image = render(world, CameraSpec())
    header = Header(
        stamp_ns=wall_ns(),
        frame_id="camera",
        seq=7,
        source="camera",
        mono_ns=mono_ns(),
        boot_id="b" * 36,
    )
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 80])
    assert ok
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 600, (20, 2)).astype(np.float32)
    wh = rng.uniform(5, 40, (20, 2)).astype(np.float32)
    dets = Detections(
        header=header,
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.hstack([xy, xy + wh]),
            class_ids=rng.integers(0, 80, 20).astype(np.int32),
            scores=rng.uniform(0.25, 1, 20).astype(np.float32),
            track_ids=np.arange(20, dtype=np.int32),
        ),
        class_names=("person",) * 20,
        timing_ms={"preprocess": 1.5, "inference": 80.0, "postprocess": 2.0},
        model="yolov5s-coco.onnx",
        backend="onnx",
        received_ns=header.stamp_ns + 1,
        published_ns=header.stamp_ns + 2,
    )
    return {
        "Frame jpeg": Frame(
            header=header, encoding="jpeg", width=640, height=480, data=jpeg.tobytes()
        ).encode(),
        "Frame bgr8": Frame(
            header=header, encoding="bgr8", width=640, height=480, data=image.tobytes()
        ).encode(),
        "Detections": dets.encode(),
        "Twist": Twist(
            header=header,
            linear=(0.3, 0.0, 0.0),
            angular=(0.0, 0.0, -0.4),
            input_stamp_ns=header.stamp_ns,
        ).encode(),
    }


def _edit(payload: bytes, change: Callable[[dict[str, Any]], None]) -> bytes:
    env = msgpack.unpackb(payload, raw=False)
    change(env)
    out = msgpack.packb(env, use_bin_type=True)
    assert isinstance(out, bytes)
    return out


def garbage_cases(msgs: dict[str, bytes]) -> Iterator[tuple[str, str, bytes]]:
    """(what, message type, payload): each must be refused by a decoder of that type."""
    frame, dets, twist = msgs["Frame jpeg"], msgs["Detections"], msgs["Twist"]
    rng = np.random.default_rng(1)

    def setk(*path: str, value: Any) -> Callable[[dict[str, Any]], None]:
        def change(env: dict[str, Any]) -> None:
            node = env
            for p in path[:-1]:
                node = node[p]
            node[path[-1]] = value

        return change

    nan_box = np.frombuffer(msgpack.unpackb(dets)["d"]["xyxy"], "<f4").copy()
    nan_box[2] = np.nan
    yield "truncated (first half)", "Frame", frame[: len(frame) // 2]
    yield "random bytes", "Twist", rng.integers(0, 256, 64, dtype=np.uint8).tobytes()
    yield "empty payload", "Twist", b""
    yield "not a map (a list)", "Twist", msgpack.packb([1, 2, 3])
    yield "deep nesting (100k arrays)", "Twist", b"\x91" * 100_000 + b"\xc0"
    yield "wrong tag (a Twist read as Frame)", "Frame", twist
    yield "newer schema version v=2", "Twist", _edit(twist, setk("v", value=2))
    yield "missing field (Frame without data)", "Frame", _edit(frame, lambda e: e["d"].pop("data"))
    yield "wrong type: width '640'", "Frame", _edit(frame, setk("d", "width", value="640"))
    yield (
        "wrong type: header.seq true",
        "Twist",
        _edit(twist, setk("d", "header", "seq", value=True)),
    )
    yield (
        "wrong type: xyxy as a list",
        "Detections",
        _edit(dets, setk("d", "xyxy", value=[1.0] * 80)),
    )
    yield "negative stamp", "Twist", _edit(twist, setk("d", "header", "stamp_ns", value=-1))
    yield "NaN in linear.x", "Twist", _edit(twist, setk("d", "linear", value=[math.nan, 0.0, 0.0]))
    yield (
        "inf in timing_ms",
        "Detections",
        _edit(dets, setk("d", "timing_ms", value={"x": math.inf})),
    )
    yield "NaN in a box", "Detections", _edit(dets, setk("d", "xyxy", value=nan_box.tobytes()))
    yield (
        "linear.x 1e308 (over 100)",
        "Twist",
        _edit(twist, setk("d", "linear", value=[1e308, 0.0, 0.0])),
    )
    yield (
        "class name of 200 chars",
        "Detections",
        _edit(dets, setk("d", "class_names", value=["x" * 200] * 20)),
    )
    yield "count 21 for 20 boxes", "Detections", _edit(dets, setk("d", "n", value=21))
    yield "count 10**9", "Detections", _edit(dets, setk("d", "n", value=10**9))
    yield "image 0 x 480", "Frame", _edit(frame, setk("d", "width", value=0))
    yield (
        "bgr8 with too few bytes",
        "Frame",
        _edit(msgs["Frame bgr8"], setk("d", "data", value=b"\x00" * 100)),
    )


def codec_section(args: argparse.Namespace) -> None:
    print("\n== 3. msgpack field walker: common/fields.py + codec.py vs msgspec Structs ==")
    ours: dict[str, type[Message]] = {"Frame": Frame, "Detections": Detections, "Twist": Twist}
    msgs = sample_messages()
    try:
        import msgspec

        theirs: dict[str, Any] | None = build_msgspec_messages()
        version = msgspec.__version__
    except ImportError:
        theirs = None
        missing("msgspec", "msgspec comparison")
    env = msgpack.unpackb(msgs["Twist"], raw=False)
    print(
        f"  our envelope: v={env['v']} (schema version per type), t={env['t']!r}, d=body; "
        "every message writes its VERSION"
    )
    print(f"  decode + validate, per message{f' (msgspec {version})' if theirs else ''}:")
    for label, payload in msgs.items():
        kind = label.split()[0]
        our_us = per_call_us(functools.partial(ours[kind].decode, payload))
        line = f"    {label:<11} {len(payload):>7} B   ours {our_us:>7.1f} us"
        if theirs is not None:
            dec = theirs[kind]
            their_us = per_call_us(functools.partial(dec.decode, payload))
            line += f"   msgspec {their_us:>7.1f} us   ours/msgspec {ratio(our_us, their_us)}"
        print(line)
    enc_us = per_call_us(lambda: Detections.decode(msgs["Detections"]).encode())
    print(f"    (ours, Detections decode + encode: {enc_us:.1f} us)")
    if theirs is not None:
        same = []
        for label, payload in msgs.items():
            kind = label.split()[0]
            a: Any = ours[kind].decode(payload)
            b = theirs[kind].decode(payload).d
            same.append(a.header.stamp_ns == b.header.stamp_ns and a.header.seq == b.header.seq)
            if kind == "Detections":
                same.append(
                    all(
                        np.array_equal(getattr(a.boxes, k), getattr(b, k))
                        for k in ("xyxy", "scores", "class_ids", "track_ids")
                    )
                    and tuple(a.class_names) == tuple(b.class_names)
                )
            if kind == "Frame":
                same.append(a.data == b.data)
            if kind == "Twist":
                same.append(a.linear == b.linear and a.angular == b.angular)
        print(
            f"  wire: msgspec Structs decode the bytes our codec writes, same values: {all(same)}"
        )
    print("  garbage (each must be refused with one typed error):")
    ok_ours = ok_theirs = n = 0
    for what, kind, payload in garbage_cases(msgs):
        n += 1
        try:
            ours[kind].decode(payload)
            r1 = "ACCEPTED"
        except DecodeError as exc:
            ok_ours += 1
            r1 = f"DecodeError: {str(exc)[:60]}"
        except Exception as exc:  # shown: anything but DecodeError is a failure of ours
            r1 = f"UNTYPED {type(exc).__name__}: {str(exc)[:50]}"
        line = f"    {what:<34} ours: {r1:<75}"
        if theirs is not None:
            try:
                theirs[kind].decode(payload)
                r2 = "ACCEPTED"
            except msgspec.DecodeError as exc:  # ValidationError is a DecodeError
                ok_theirs += 1
                r2 = f"{type(exc).__name__}: {str(exc)[:60]}"
            except Exception as exc:  # shown: anything else escapes one except clause
                r2 = f"UNTYPED {type(exc).__name__}: {str(exc)[:50]}"
            line += f" msgspec: {r2}"
        print(line)
    print(
        f"  refused with the one typed error: ours {ok_ours}/{n}"
        + (f", msgspec {ok_theirs}/{n} (msgspec.DecodeError / ValidationError)" if theirs else "")
    )
    size = site_size_mb(["msgspec"])
    if size is not None:
        print(
            f"  dependency size: msgspec {size:.1f} MB installed (msgpack, which we use now: "
            f"{site_size_mb(['msgpack']) or 0:.1f} MB)"
        )
    fw = REPO / "common" / "fields.py"
    print(
        f"  lines: common/fields.py {_code_lines(fw)}, common/codec.py "
        f"{_code_lines(REPO / 'common' / 'codec.py')}"
    )


# --------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--only",
        default="tracker,settings,codec",
        help="comma-separated sections: tracker, settings, codec",
    )
    p.add_argument(
        "--frames",
        type=int,
        default=1000,
        help="at most this many frames per scenario run (default: the whole run)",
    )
    p.add_argument(
        "--rate-hz",
        type=float,
        default=None,
        help="camera rate (default: the simulator's, sim.camera_rate_hz)",
    )
    p.add_argument("--models-dir", default="", help="where the default model is (default: models/)")
    p.add_argument(
        "--cache-dir",
        default="",
        help="keep the detections here, so a second run skips the detector",
    )
    p.add_argument("--threads", type=int, default=2, help="ONNX Runtime intra-op threads")
    p.add_argument(
        "--replays",
        type=int,
        default=5,
        help="tracker timing: the least per frame of this many replays",
    )
    p.add_argument(
        "--no-stress",
        action="store_true",
        help="tracker: only the stack's scenarios, not the overlapping-people worlds",
    )
    args = p.parse_args(argv)
    sections = {s.strip() for s in args.only.split(",") if s.strip()}
    unknown = sections - {"tracker", "settings", "codec"}
    if unknown:
        p.error(f"unknown section(s) {sorted(unknown)}")
    # Ctrl-C ends the process at once, even inside an ONNX Runtime call (a KeyboardInterrupt
    # would wait for it to return), and even when a shell started it with SIGINT ignored.
    # Nothing needs cleaning up: the detection cache is written under a temporary name first.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, {os.cpu_count()} CPU(s)")
    if "tracker" in sections:
        tracker_section(args)
    if "settings" in sections:
        settings_section(args)
    if "codec" in sections:
        codec_section(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
