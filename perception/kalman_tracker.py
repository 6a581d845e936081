"""A tracker that holds a person through an occlusion, the robot's own turning and a look away:
Kalman-filtered boxes, two-stage association by score, the camera's rotation taken out of
every prediction, and re-identification by colour after a short loss. Pure.

Each track is a constant-velocity Kalman filter of its box's centre and size (cx, cy, w, h
and their rates; noise in proportion to the box's height, as in SORT and ByteTrack). At each
frame:

1. **Ego-rotation.** The robot turned ``turned_rad`` (left positive) since the last frame:
   every track's predicted centre moves across the image as a still thing's would, by the
   pinhole model (``cx' = cx0 - f tan(atan((cx0 - cx) / f) - turned)``), so a fast turn does
   not carry a person out of their own track's reach.
2. **Confident detections** (``high_score`` and up) take the tracks seen within
   ``max_age_s``, by IoU with the prediction (at least ``iou``), one to one (the Hungarian
   method), each IoU taken down where the appearance disagrees (``appearance_weight``).
3. **Weak detections** (``low_score`` .. ``high_score``) may extend a track left over, never
   start one (ByteTrack's second pass: a person whose score dips stays on their id).
4. **Re-identification.** A confident detection left over takes a track lost for up to
   ``reid_age_s`` whose colour histogram (perception/colour_cue.py) is at least
   ``reid_similarity`` alike and whose predicted centre is within ``reid_gate`` box heights,
   most alike first: a person who walked behind a pillar or another person comes back on
   their own id.
5. The confident detections still left start tracks; a track unseen for ``reid_age_s``
   (``max_age_s`` with no appearance) is gone. Ids are never reused.

Without features (``features`` None) steps 2 and 4 are by position alone and step 4 is off.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from common.boxes import Boxes
from perception.colour_cue import Features, similarity
from perception.settings import TrackerKind, TrackerParams
from perception.tracker import StampGuard, Tracker, iou_matrix

Vec = npt.NDArray[np.float64]

#: The Kalman filter's noise, in box heights: a measurement's sigma, and the process noise
#: of the position and of the rate per second.
MEASURE_SIGMA = 0.05
POSITION_SIGMA_PER_S = 0.1
RATE_SIGMA_PER_S = 0.6
#: How much a track's colour moves towards each new sighting's.
FEATURE_BLEND = 0.2


def _cxcywh(xyxy: Vec) -> Vec:
    x0, y0, x1, y1 = xyxy
    return np.array([(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0])


def _xyxy(state: Vec) -> Vec:
    cx, cy, w, h = state[:4]
    w, h = max(w, 1.0), max(h, 1.0)
    return np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2])


@dataclass(slots=True)
class _KTrack:
    track_id: int
    class_id: int
    x: Vec  # cx, cy, w, h, vcx, vcy, vw, vh
    p: Vec  # 8x8 covariance
    last_seen: float
    at: float  # the time x is predicted to
    feature: Features | None = None
    hits: int = 1

    @classmethod
    def start(
        cls, track_id: int, class_id: int, xyxy: Vec, now: float, feature: Features | None
    ) -> _KTrack:
        z = _cxcywh(xyxy)
        x = np.concatenate([z, np.zeros(4)])
        h = max(z[3], 1.0)
        p = np.diag(np.r_[np.full(4, (2 * MEASURE_SIGMA * h) ** 2), np.full(4, (h) ** 2)])
        return cls(track_id, class_id, x, p, now, now, feature)

    def correct(self, xyxy: Vec, now: float, feature: Features | None) -> None:
        z = _cxcywh(xyxy)
        h = max(z[3], 1.0)
        s = self.p[:4, :4] + np.eye(4) * (MEASURE_SIGMA * h) ** 2  # H P H^T + R
        k = self.p[:, :4] @ np.linalg.inv(s)  # P H^T S^-1
        self.x = self.x + k @ (z - self.x[:4])
        self.p = self.p - k @ self.p[:4, :]  # (I - K H) P
        self.last_seen, self.hits = now, self.hits + 1
        if feature is not None:
            old = self.feature
            mixed = feature if old is None else (1 - FEATURE_BLEND) * old + FEATURE_BLEND * feature
            self.feature = np.asarray(mixed, np.float32)

    def turn(self, turned_rad: float, focal_px: float, cx0: float) -> None:
        """Move the predicted centre as a still thing's moves when the camera turns left by
        ``turned_rad``."""
        bearing = math.atan((cx0 - self.x[0]) / focal_px) - turned_rad
        bearing = max(-1.5, min(1.5, bearing))
        self.x[0] = cx0 - focal_px * math.tan(bearing)


def _predict(tracks: list[_KTrack], now: float) -> None:
    """Every track's state and covariance carried to ``now`` by the constant-velocity model,
    all at once: x' = F x, P' = F P F^T + Q with F = [[I, dt I], [0, I]] (by its 4x4 blocks),
    Q diagonal, in proportion to each box's height."""
    if not tracks:
        return
    dt = np.array([max(now - t.at, 0.0) for t in tracks])
    x = np.stack([t.x for t in tracks])
    p = np.stack([t.p for t in tracks])
    x[:, :4] += x[:, 4:] * dt[:, None]
    a, b, c, d = p[:, :4, :4], p[:, :4, 4:], p[:, 4:, :4], p[:, 4:, 4:]
    k = dt[:, None, None]
    out = np.empty_like(p)
    out[:, :4, :4] = a + k * (b + c) + k * k * d
    out[:, :4, 4:] = b + k * d
    out[:, 4:, :4] = c + k * d
    out[:, 4:, 4:] = d
    h2 = np.maximum(x[:, 3], 1.0) ** 2 * dt
    idx = np.arange(4)
    out[:, idx, idx] += (POSITION_SIGMA_PER_S**2 * h2)[:, None]
    out[:, idx + 4, idx + 4] += (RATE_SIGMA_PER_S**2 * h2)[:, None]
    for t, xi, pi in zip(tracks, x, out, strict=True):
        t.x, t.p, t.at = xi, pi, max(t.at, now)


@dataclass(frozen=True, slots=True)
class _Frame:
    xyxy: Vec
    scores: npt.NDArray[np.float32]
    class_ids: npt.NDArray[np.int32]
    features: Features | None


class KalmanTracker(StampGuard):
    """Assigns a track id to each detection of a stream of frames of one camera (see the
    module's docstring); the same stamp checks as :class:`perception.tracker.Tracker`."""

    def __init__(self, settings: TrackerParams | None = None) -> None:
        super().__init__(settings)
        self._tracks: list[_KTrack] = []
        self._next_id = 1

    def restart(self) -> None:
        self._tracks = []

    def update(
        self,
        boxes: Boxes,
        now: float,
        arrival: float | None = None,
        *,
        turned_rad: float = 0.0,
        focal_px: float = 0.0,
        image_width: int = 0,
        features: Features | None = None,
    ) -> npt.NDArray[np.int32]:
        """Track ids (n,) for this frame's ``boxes`` (-1: a weak detection no track took, or
        a frame ignored for its stamp). ``turned_rad``: how far the robot turned left since
        the last frame, with the camera's ``focal_px`` and ``image_width`` (0: no
        compensation); ``features``: each box's appearance (perception/colour_cue.py)."""
        n = len(boxes.scores)
        if not self.admit(now, arrival):
            return np.full(n, -1, np.int32)
        p = self.settings
        frame = _Frame(boxes.xyxy.astype(np.float64), boxes.scores, boxes.class_ids, features)
        keep = p.reid_age_s if features is not None else p.max_age_s
        self._tracks = [t for t in self._tracks if now - t.last_seen <= keep]
        _predict(self._tracks, now)
        if turned_rad and focal_px > 0 and image_width > 0:
            for t in self._tracks:
                t.turn(turned_rad, focal_px, image_width / 2)
        ids = np.full(n, -1, np.int32)
        live = [k for k, t in enumerate(self._tracks) if now - t.last_seen <= p.max_age_s]
        high = np.flatnonzero(frame.scores >= p.high_score)
        low = np.flatnonzero((frame.scores >= p.low_score) & (frame.scores < p.high_score))
        live = self._associate(frame, high, live, ids, now, p.appearance_weight)
        self._associate(frame, low, live, ids, now, 0.0)
        if features is not None:
            self._reidentify(frame, ids, now)
        for d in np.flatnonzero((ids < 0) & (frame.scores >= p.high_score)):
            feature = None if features is None else features[d]
            track = _KTrack.start(
                self._next_id, int(frame.class_ids[d]), frame.xyxy[d], now, feature
            )
            self._tracks.append(track)
            ids[d] = track.track_id
            self._next_id += 1
        return ids

    def _associate(
        self,
        frame: _Frame,
        dets: npt.NDArray[np.intp],
        tracks: list[int],
        ids: npt.NDArray[np.int32],
        now: float,
        weight: float,
    ) -> list[int]:
        """Match ``dets`` to ``tracks`` (indices) one to one by IoU, each lowered by
        ``weight`` times the appearance's disagreement; the tracks left over."""
        if dets.size == 0 or not tracks:
            return tracks
        predicted = np.array([_xyxy(self._tracks[t].x) for t in tracks])
        score = iou_matrix(frame.xyxy[dets], predicted)
        classes = np.array([self._tracks[t].class_id for t in tracks])
        same = frame.class_ids[dets][:, None] == classes
        score = np.where(same, score, 0.0)
        if weight > 0 and frame.features is not None:
            feats = [self._tracks[t].feature for t in tracks]
            if all(f is not None for f in feats):
                sim = similarity(frame.features[dets], np.stack(feats))  # type: ignore[arg-type]
                score = score - weight * (1.0 - sim) * (score > 0)
        rows, cols = linear_sum_assignment(-score)
        taken = set()
        for r, c in zip(rows, cols, strict=True):
            if score[r, c] < self.settings.iou:
                continue
            track = self._tracks[tracks[c]]
            feature = None if frame.features is None else frame.features[dets[r]]
            track.correct(frame.xyxy[dets[r]], now, feature)
            ids[dets[r]] = track.track_id
            taken.add(tracks[c])
        return [t for t in tracks if t not in taken]

    def _reidentify(self, frame: _Frame, ids: npt.NDArray[np.int32], now: float) -> None:
        """Confident detections left over take back lost tracks that look alike and are
        near where they were predicted (the module's step 4)."""
        p = self.settings
        assert frame.features is not None
        dets = np.flatnonzero((ids < 0) & (frame.scores >= p.high_score))
        lost = [
            k
            for k, t in enumerate(self._tracks)
            if now - t.last_seen > 0 and t.feature is not None and t.track_id not in ids
        ]
        if dets.size == 0 or not lost:
            return
        feats = np.stack([self._tracks[k].feature for k in lost])  # type: ignore[misc]
        sim = similarity(frame.features[dets], feats)
        for d_i, k_i in sorted(np.ndindex(*sim.shape), key=lambda rc: -sim[rc]):
            d, k = dets[d_i], lost[k_i]
            track = self._tracks[k]
            if ids[d] >= 0 or track.track_id in ids or sim[d_i, k_i] < p.reid_similarity:
                continue
            if track.class_id != int(frame.class_ids[d]):
                continue
            z, pred = _cxcywh(frame.xyxy[d]), track.x[:4]
            h = max(pred[3], 1.0)
            if abs(z[0] - pred[0]) > p.reid_gate * h or not 0.5 <= z[3] / h <= 2.0:
                continue
            track.correct(frame.xyxy[d], now, frame.features[d])
            ids[d] = track.track_id


def new_tracker(params: TrackerParams) -> Tracker | KalmanTracker:
    """A fresh tracker of ``params.kind``."""
    return KalmanTracker(params) if params.kind is TrackerKind.KALMAN else Tracker(params)
