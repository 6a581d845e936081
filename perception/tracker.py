"""A small multi-object tracker: stable track ids from frame-to-frame box overlap. Pure.

Association is ByteTrack-style in two passes: confident detections claim tracks first, then the
weak ones (down to ``low_score``) may only extend existing tracks, never start one. That keeps
a person whose score dips for a frame on the same id without spawning tracks from noise. Each
track predicts its next box from a constant-velocity model of the box corners, so a target
moving across the image still overlaps its prediction. Matching is greedy on IoU, highest
first, and only within one class. The thresholds are :class:`perception.settings.TrackerParams`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from common.boxes import Boxes
from perception.settings import TrackerParams


@dataclass(slots=True)
class _Track:
    track_id: int
    class_id: int
    box: npt.NDArray[np.float64]
    velocity: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(4))
    last_seen: float = 0.0

    def predict(self, now: float) -> npt.NDArray[np.float64]:
        return self.box + self.velocity * (now - self.last_seen)

    def update(self, box: npt.NDArray[np.float64], now: float) -> None:
        dt = now - self.last_seen
        if dt > 0:
            # Smoothed velocity: a single jittery box should not fling the prediction.
            self.velocity = 0.5 * self.velocity + 0.5 * (box - self.box) / dt
        self.box, self.last_seen = box, now


def iou_matrix(a: npt.NDArray[np.floating], b: npt.NDArray[np.floating]) -> npt.NDArray[np.float64]:
    """Pairwise IoU of xyxy boxes ``a`` (n, 4) and ``b`` (m, 4) as an (n, m) array."""
    a = np.asarray(a, np.float64)[:, None, :]
    b = np.asarray(b, np.float64)[None, :, :]
    w = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    h = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = w * h
    area_a = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1])
    area_b = (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    union = area_a + area_b - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1), 0.0)


def _greedy_match(iou: npt.NDArray[np.float64], threshold: float) -> list[tuple[int, int]]:
    """Pairs (row, col) taken in descending IoU, each row and column at most once."""
    pairs: list[tuple[int, int]] = []
    if iou.size == 0:
        return pairs
    rows, cols = np.nonzero(iou >= threshold)
    order = np.argsort(-iou[rows, cols], kind="stable")
    used_r: set[int] = set()
    used_c: set[int] = set()
    for k in order:  # candidate pairs above threshold only: a handful per frame
        r, c = int(rows[k]), int(cols[k])
        if r not in used_r and c not in used_c:
            pairs.append((r, c))
            used_r.add(r)
            used_c.add(c)
    return pairs


def tracker_clock(
    stamp_ns: int, mono_ns: int, sender_boot: str, arrival_ns: int, boot_id: str
) -> tuple[float, float | None]:
    """The time a frame is tracked at, and its arrival for the stamp-jump check (seconds).

    A frame from this host (same boot id) carries its capture instant on the monotonic clock,
    which cannot step: it is used, and there is no jump to check for (None). Checking would
    even do harm: the check compares stamp and arrival deltas, and at start-up, with every
    service importing and loading on few cores, one frame delivered late made the next three
    look like a clock that jumped, and the tracks restarted for nothing. A frame from another
    host has only the wall clock, which NTP or an operator may step: checked.
    """
    if mono_ns > 0 and sender_boot == boot_id:
        return mono_ns / 1e9, None
    return stamp_ns / 1e9, arrival_ns / 1e9


class StampGuard:
    """The stamp checks every tracker of a camera's stream makes (``settings``'
    ``max_stamp_jump_s`` and ``jumps_before_reset``): a frame whose stamp jumped is ignored,
    counted in ``ignored_frames``; after ``jumps_before_reset`` in a row the stamps are
    believed, the tracks restart (:meth:`restart`) and ``resets`` counts it."""

    def __init__(self, settings: TrackerParams | None = None) -> None:
        self.settings = settings if settings is not None else TrackerParams()
        self._last: tuple[float, float] | None = None  # (stamp, arrival) of the last frame used
        self._jumps_in_a_row = 0
        self.ignored_frames = 0  # frames ignored for a stamp jump
        self.resets = 0  # times the tracks restarted after a lasting jump

    def _stamp_jumped(self, now: float, arrival: float | None) -> bool:
        """Whether this frame's stamp disagrees with the time that really passed."""
        if self._last is None:
            return False
        stamp, arrived = self._last
        if now < stamp:
            return True
        if arrival is None:
            return False
        return abs((now - stamp) - (arrival - arrived)) > self.settings.max_stamp_jump_s

    def admit(self, now: float, arrival: float | None) -> bool:
        """Whether the frame stamped ``now`` (arrived at ``arrival``) is tracked: False for
        one ignored for its stamp."""
        if self._stamp_jumped(now, arrival):
            self._jumps_in_a_row += 1
            if self._jumps_in_a_row < self.settings.jumps_before_reset:
                self.ignored_frames += 1
                return False
            self.restart()
            self.resets += 1
        self._jumps_in_a_row = 0
        self._last = (now, now if arrival is None else arrival)
        return True

    def restart(self) -> None:
        """Forget every track (the stamps jumped for good)."""
        raise NotImplementedError


class Tracker(StampGuard):
    """Assigns a track id to each detection of a stream of frames of one camera."""

    def __init__(self, settings: TrackerParams | None = None) -> None:
        super().__init__(settings)
        self._tracks: list[_Track] = []
        self._next_id = 1

    def restart(self) -> None:
        self._tracks = []

    def update(
        self, boxes: Boxes, now: float, arrival: float | None = None, **_: object
    ) -> npt.NDArray[np.int32]:
        """Track ids (n,) for this frame's ``boxes``; -1 for weak unmatched ones, and for
        every detection of a frame ignored for its stamp. ``boxes.track_ids`` is not read.

        ``now`` is the frame's capture time in seconds (any monotonic origin); ``arrival``, on
        the receiver's own clock in seconds, is when the frame arrived (None: not checked).
        Keyword arguments (a turn, features: perception/kalman_tracker.py's) are not used.
        """
        p = self.settings
        xyxy, scores, class_ids = boxes.xyxy, boxes.scores, boxes.class_ids
        if not self.admit(now, arrival):
            return np.full(len(scores), -1, np.int32)
        self._tracks = [t for t in self._tracks if now - t.last_seen <= p.max_age_s]
        ids = np.full(len(scores), -1, np.int32)
        free_tracks = list(range(len(self._tracks)))
        for lo, hi in ((p.high_score, np.inf), (p.low_score, p.high_score)):
            dets = np.flatnonzero((scores >= lo) & (scores < hi))
            if dets.size == 0 or not free_tracks:
                continue
            predicted = np.array([self._tracks[t].predict(now) for t in free_tracks])
            iou = iou_matrix(xyxy[dets], predicted)
            same_class = class_ids[dets][:, None] == np.array(
                [self._tracks[t].class_id for t in free_tracks]
            )
            matched = _greedy_match(np.where(same_class, iou, 0.0), p.iou)
            for d, t in matched:
                track = self._tracks[free_tracks[t]]
                track.update(xyxy[dets[d]].astype(np.float64), now)
                ids[dets[d]] = track.track_id
            taken = {free_tracks[t] for _, t in matched}
            free_tracks = [t for t in free_tracks if t not in taken]
        for new in np.flatnonzero((ids < 0) & (scores >= p.high_score)):
            track = _Track(self._next_id, int(class_ids[new]), xyxy[new].astype(np.float64))
            track.last_seen = now
            self._tracks.append(track)
            ids[new] = track.track_id
            self._next_id += 1
        return ids
