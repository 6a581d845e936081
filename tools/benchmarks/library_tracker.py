"""Comparison 1 of tools/benchmarks/library_choices.py: perception/tracker.py against
ByteTrack of the ``trackers`` package (Roboflow's clean-room re-implementation), by identity
switches and fragmentations on the ``crossing`` and ``two_people`` scenarios, and time per
frame. Every tracker is fed the same boxes (library_tracker_frames.py); see ``evaluate`` for the
ground-truth rule."""

from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from common.boxes import Boxes
from common.clock import perf_s
from common.settings import DEFAULT_CONFIG
from services.detector.contract import DetectorSettings, TrackerSettings
from services.sim.contract import SimSettings
from stack.config_file import load_config
from tools.benchmarks.library_shared import log, missing, ratio, requirements, site_size_mb
from tools.benchmarks.library_tracker_frames import (
    SCENARIOS_MEASURED,
    STRESS_WORLDS,
    ScenarioFrames,
    run_scenario,
)

MATCH_IOU = 0.3  # least IoU between a projected truth box and a detection to call them one


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
            f"  [skipped] the default model {model} is missing: `zstack prepare`, or "
            "--models-dir DIR"
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
