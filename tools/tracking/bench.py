"""Runs the tracking evaluation (issue 42): scenarios on the real stack, each tracker live (the
controller's lock) and replayed on the same recorded detections (MOT metrics).

For each scenario and each tracker kind (``tracker.kind``), ``runs`` live runs: the stack as
configured with that tracker, the run's truth, commands, statuses, detections and frames
kept. Every run's detections are then replayed through every tracker (evaluate.py
:func:`~tools.tracking.evaluate.replay`: the same boxes for each), per camera, and scored
against the truth (mot.py); the lock's figures come from the runs made with that tracker.
"""

from __future__ import annotations

import dataclasses
import statistics
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from common.contracts import ControllerMode
from perception import TrackerKind, TrackerParams, new_tracker
from services.sim.cameras import sim_cameras
from services.sim.worlds import world_for
from simworld.scenarios import SCENARIOS
from stack.config import Config
from tools.scenarios.runner import run_scenario, scenario_config
from tools.scenarios.score import ScenarioLog
from tools.tracking.evaluate import LockFigures, lock_figures, replay
from tools.tracking.frames import label
from tools.tracking.mot import MotFrame, MotScores, mot_metrics

#: The trackers run live and replayed: (row name, kind, whether it sees the frames' colours).
REPLAYED = (("iou", TrackerKind.IOU, False), ("kalman", TrackerKind.KALMAN, True))
#: The library's row, replayed only (where Roboflow's ``trackers`` is importable: it is no
#: dependency of the stack, see docs/library-decisions.md section 1).
BYTETRACK = "bytetrack"


def make_tracker(kind: TrackerKind, params: TrackerParams) -> Callable[..., Any]:
    """A fresh tracker's ``update`` of ``kind``."""
    return new_tracker(dataclasses.replace(params, kind=kind)).update


def bytetrack(params: TrackerParams, rate_hz: float) -> Callable[..., Any] | None:
    """A fresh ``trackers.ByteTrackTracker`` (2.6) with the stack's thresholds (activation and
    high score ``high_score``, IoU ``iou``, lost after ``max_age_s``: its buffer counts frames
    at 30 fps whatever ``frame_rate`` is), as our trackers' ``update``; None where the package
    is not importable. The adapter is the library comparison's
    (tools/benchmarks/library_tracker.py)."""
    try:
        import trackers  # noqa: F401
    except ImportError:
        return None
    from tools.benchmarks.library_tracker import bytetrack_tracker

    track = bytetrack_tracker(
        rate_hz, track_activation_threshold=params.high_score,
        high_conf_det_threshold=params.high_score, minimum_iou_threshold=params.iou,
        lost_track_buffer=round(30 * params.max_age_s), minimum_consecutive_frames=1,
    )  # fmt: skip

    def update(boxes: Any, now: float, **_: Any) -> Any:
        return track(boxes.xyxy, boxes.scores, boxes.class_ids, now)

    return update


@dataclass(slots=True)
class Row:
    """One tracker's figures on one scenario: MOT scores per camera sequence (replayed on
    every run), the lock's figures of its own live runs, and whether each run passed."""

    mot: list[MotScores] = field(default_factory=list)
    locks: list[LockFigures] = field(default_factory=list)
    passed: list[bool] = field(default_factory=list)


def _with_tracker(config: Config, kind: TrackerKind) -> Config:
    return dataclasses.replace(config, tracker=dataclasses.replace(config.tracker, kind=kind))


def run_table(
    base: Config,
    scenarios: list[str],
    runs: int,
    log: Callable[[str], None],
    mode: ControllerMode = ControllerMode.FOLLOW,
) -> dict[str, dict[str, Row]]:
    """{scenario: {tracker: Row}} (see the module's docstring)."""
    table: dict[str, dict[str, Row]] = {}
    for name in scenarios:
        scenario = SCENARIOS[name]
        rows = table.setdefault(name, {n: Row() for n, _, _ in REPLAYED})
        rate = base.sim.camera_rate_hz
        if bytetrack(base.tracker, rate) is not None:
            rows.setdefault(BYTETRACK, Row())
        for tracker_name, kind, _ in REPLAYED:
            for k in range(runs):
                log(f"{name}: {tracker_name} live, run {k + 1} of {runs}")
                rec = ScenarioLog()
                config = _with_tracker(base, kind)
                result = run_scenario(config, name, mode=mode, rec=rec, images=True,
                                      full_length=True)  # fmt: skip
                rows[tracker_name].passed.append(bool(result["success"]))
                ran = scenario_config(config, scenario, False, mode)
                world = world_for(ran.sim, scenario.build())
                specs = {c.name: c.spec for c in sim_cameras(ran)}
                frames = label(world, specs, rec.truths, rec.detections)
                if scenario.followed is not None:
                    rows[tracker_name].locks.append(
                        lock_figures(rec.statuses, frames, scenario.followed)
                    )
                for camera, seq in frames.items():
                    if not seq:
                        continue
                    for other, other_kind, colours in REPLAYED:
                        tracker = make_tracker(other_kind, config.tracker)
                        images = rec.images.get(camera) if colours else None
                        mot: list[MotFrame] = replay(
                            seq, tracker, rec.twists, specs[camera].focal_px, images
                        )
                        rows[other].mot.append(mot_metrics(mot))
                    library = bytetrack(config.tracker, rate)
                    if library is not None:
                        mot = replay(seq, library, rec.twists, specs[camera].focal_px)
                        rows[BYTETRACK].mot.append(mot_metrics(mot))
    return table


def _mean(values: list[float]) -> str:
    return f"{statistics.fmean(values):.3f}" if values else "-"


def table_text(table: dict[str, dict[str, Row]]) -> str:
    """The table: per scenario, a row per tracker."""
    head = (
        f"{'scenario':12} {'tracker':8} {'HOTA':>6} {'IDF1':>6} {'MOTA':>6} {'IDsw':>5} "
        f"{'lock on':>8} {'switches':>8} {'reacquire s':>12} {'passed':>7}"
    )
    lines = [head, "-" * len(head)]
    for name, rows in table.items():
        for tracker, row in rows.items():
            m = row.mot
            on = [lk.on_target for lk in row.locks if lk.on_target is not None]
            re = [r for lk in row.locks for r in lk.reacquire_s]
            got = [r for r in re if r is not None]
            reacq = "-" if not re else f"{_mean(got)} ({len(re) - len(got)} never)"
            lines.append(
                f"{name:12} {tracker:8} {_mean([s.hota for s in m]):>6} "
                f"{_mean([s.idf1 for s in m]):>6} {_mean([s.mota for s in m]):>6} "
                f"{sum(s.id_switches for s in m):>5} "
                f"{(_mean(on) if on else '-'):>8} {sum(lk.switches for lk in row.locks):>8} "
                f"{reacq:>12} {sum(row.passed)}/{len(row.passed):<5}"
            )
    return "\n".join(lines)
