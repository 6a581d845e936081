"""Scores trackers and the controller's lock against the simulator's truth. Pure: a recorded
run (tools/scenarios/score.py ScenarioLog) labelled frame by frame (frames.py) in, figures
out.

- :func:`replay` runs a tracker over a camera's recorded detections (their boxes; the track
  ids the live tracker gave are not read), with the turn the robot commanded between frames
  and each box's colour where the run kept its images, and gives the frames
  :func:`~tools.tracking.mot.mot_metrics` scores: the same detections for every tracker.
- :func:`lock_figures` reads the controller's status through the run: which person its lock
  was on (the locked track's box in the newest detections of its camera, matched to the truth
  by IoU), the share of the time the followed person showed in some camera that the lock was
  on them, how often it moved to someone else, and how long it took to come back to them
  after they reappeared.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from common.contracts import ControllerState
from common.errors import DecodeError, ImageError
from common.frames import frame_to_bgr
from common.messages import ControllerStatus, Detections, Frame, Twist
from perception import Features, appearance, iou_matrix
from tools.tracking.frames import Labelled
from tools.tracking.mot import MotFrame

#: A tracked or locked box is on a person when its IoU with their visible box is at least this
#: (MOTChallenge's 0.5 is for boxes drawn by people round the whole person; a detector's box
#: round a partly hidden one overlaps less).
MATCH_IOU = 0.3
#: The followed person counts as gone after this long out of every camera's view, and as back
#: when they show again (s).
GONE_S = 0.5
#: The states in which the controller holds a lock.
LOCKED = {ControllerState.FOLLOWING, ControllerState.ARRIVED, ControllerState.BLOCKED,
          ControllerState.TURNING, ControllerState.HOLDING}  # fmt: skip

Tracker = Callable[..., np.ndarray]


def _person_rows(d: Detections, person: str) -> np.ndarray:
    return np.flatnonzero(np.array(d.class_names, dtype=object) == person)


def turned_between(twists: Sequence[Twist], stamps: Sequence[int], t0: int, t1: int) -> float:
    """How far the robot turned (rad, left positive) from ``t0`` to ``t1`` (ns) by the
    commands ``twists`` (in stamp order, ``stamps`` theirs): each holds until the next."""
    if t1 <= t0 or not twists:
        return 0.0
    total = 0.0
    k = max(bisect.bisect_right(stamps, t0) - 1, 0)
    while k < len(twists) and stamps[k] < t1:
        start = max(stamps[k], t0)
        end = min(stamps[k + 1] if k + 1 < len(twists) else t1, t1)
        if end > start:
            total += twists[k].angular[2] * (end - start) / 1e9
        k += 1
    return total


def _features(
    images: Mapping[int, bytes] | None, d: Detections, rows: np.ndarray
) -> Features | None:
    if images is None:
        return None
    payload = images.get(d.header.stamp_ns)
    if payload is None:
        return None
    try:
        image = frame_to_bgr(Frame.decode(payload))
    except (DecodeError, ImageError):
        return None
    return appearance(image, d.boxes.xyxy[rows])


def replay(
    frames: Sequence[Labelled],
    tracker: Tracker,
    twists: Sequence[Twist],
    focal_px: float,
    images: Mapping[int, bytes] | None = None,
    person: str = "person",
) -> list[MotFrame]:
    """``tracker`` (a fresh one's ``update``) over ``frames``' person boxes, with the
    commanded turn between frames and, from ``images``, each box's colour: the frames to
    score."""
    ordered = sorted(twists, key=lambda t: t.header.stamp_ns)
    stamps = [t.header.stamp_ns for t in ordered]
    out = []
    last: int | None = None
    for f in frames:
        d = f.detections
        rows = _person_rows(d, person)
        boxes = d.boxes.take(rows)
        stamp = d.header.stamp_ns
        turned = 0.0 if last is None else turned_between(ordered, stamps, last, stamp)
        last = stamp
        feats = _features(images, d, rows)
        ids = tracker(
            boxes, stamp / 1e9, turned_rad=turned, focal_px=focal_px,
            image_width=d.image_width, features=feats,
        )  # fmt: skip
        tracks = [
            (int(i), tuple(float(v) for v in boxes.xyxy[k])) for k, i in enumerate(ids) if i >= 0
        ]
        truth = [(b.target, tuple(float(v) for v in b.box)) for b in f.truth if b.name == person]
        out.append(MotFrame(truth, tracks))  # type: ignore[arg-type]
    return out


@dataclass(frozen=True, slots=True)
class LockFigures:
    """The controller's lock through one run: ``on_target`` the share of status messages, of
    those while the followed person showed in some camera, whose lock was on them (None: they
    never showed); ``switches`` times the lock moved to someone else; ``reacquire_s`` for each
    time the followed person came back into view after ``GONE_S`` out of it, how long until
    the lock was on them again (None: never)."""

    on_target: float | None
    switches: int
    reacquire_s: tuple[float | None, ...]
    samples: int


def _locked_person(
    status: ControllerStatus,
    frames: Mapping[str, Sequence[Labelled]],
    stamps: Mapping[str, list[int]],
) -> str | None:
    """Which person the status's lock is on ("" : none the truth knows; None: no lock)."""
    if status.state not in LOCKED or status.track_id < 0 or not status.camera:
        return None
    cam = frames.get(status.camera)
    if not cam:
        return ""
    k = bisect.bisect_right(stamps[status.camera], status.header.stamp_ns) - 1
    if k < 0:
        return ""
    f = cam[k]
    d = f.detections
    if d.boxes.track_ids is None or not f.truth:
        return ""
    rows = np.flatnonzero(d.boxes.track_ids == status.track_id)
    if len(rows) == 0:
        return ""
    truth = np.array([b.box for b in f.truth], float)
    overlap = iou_matrix(d.boxes.xyxy[rows[:1]], truth)[0]
    best = int(np.argmax(overlap))
    return f.truth[best].target if overlap[best] >= MATCH_IOU else ""


def lock_figures(
    statuses: Sequence[ControllerStatus],
    frames: Mapping[str, Sequence[Labelled]],
    followed: str,
) -> LockFigures:
    """The lock's figures (:class:`LockFigures`) from the run's ``statuses`` and every
    camera's labelled ``frames`` (each in capture order)."""
    stamps = {c: [f.detections.header.stamp_ns for f in fs] for c, fs in frames.items()}

    def visible(at: int) -> bool:
        for c, fs in frames.items():
            k = bisect.bisect_right(stamps[c], at) - 1
            if k >= 0 and any(b.target == followed for b in fs[k].truth):
                return True
        return False

    on = seen = switches = 0
    previous: str | None = None
    gone_since: float | None = None
    waiting_since: float | None = None
    reacquire: list[float | None] = []
    for s in sorted(statuses, key=lambda m: m.header.stamp_ns):
        t = s.header.stamp_ns / 1e9
        person = _locked_person(s, frames, stamps)
        shows = visible(s.header.stamp_ns)
        if shows:
            seen += 1
            on += person == followed
            if gone_since is not None and t - gone_since >= GONE_S:
                waiting_since = t
                reacquire.append(None)
            gone_since = None
        elif gone_since is None:
            gone_since = t
        if waiting_since is not None and person == followed:
            reacquire[-1] = t - waiting_since
            waiting_since = None
        if person and person != followed and person != previous:
            switches += 1
        if person is not None:
            previous = person
    return LockFigures(on / seen if seen else None, switches, tuple(reacquire), len(statuses))
