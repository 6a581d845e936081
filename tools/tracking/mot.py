"""Multi-object tracking metrics of one camera's sequence: HOTA, IDF1, MOTA and identity
switches, computed by TrackEval (trackeval 1.3, the reference code of the HOTA paper and the
MOTChallenge), fed here with the truth's and a tracker's boxes frame by frame. Pure.

A frame is the truth's boxes (each with the person's id) and the tracker's (each with its
track id) in the same pixels; :func:`mot_metrics` maps both kinds of id to TrackEval's
contiguous ones and gives each frame's IoU matrix.
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np

from perception import iou_matrix

Box = tuple[float, float, float, float]  # x0, y0, x1, y1 pixels


@dataclass(frozen=True, slots=True)
class MotFrame:
    """One frame: the truth's ``(id, box)`` pairs and the tracker's ``(track id, box)``."""

    truth: Sequence[tuple[Hashable, Box]]
    tracks: Sequence[tuple[Hashable, Box]]


@dataclass(frozen=True, slots=True)
class MotScores:
    """A sequence's scores: ``hota``, ``idf1``, ``mota`` (0..1; MOTA can be negative),
    ``id_switches`` (CLEAR's IDSW), the truth's and the tracker's box counts."""

    hota: float
    idf1: float
    mota: float
    id_switches: int
    truth_boxes: int
    track_boxes: int


def _metrics() -> tuple[object, object, object]:
    # TrackEval prints a line about a dataset whose dependency is absent as it is imported;
    # only its metrics are used here.
    with contextlib.redirect_stdout(io.StringIO()):
        from trackeval.metrics import CLEAR, HOTA, Identity
    quiet = {"PRINT_CONFIG": False}
    return HOTA(quiet), CLEAR(quiet), Identity(quiet)


def mot_metrics(frames: Sequence[MotFrame]) -> MotScores:
    """The scores of ``frames`` (one camera's sequence, in order)."""
    gt_index: dict[Hashable, int] = {}
    tr_index: dict[Hashable, int] = {}
    data: dict[str, object] = {"gt_ids": [], "tracker_ids": [], "similarity_scores": []}
    n_gt = n_tr = 0
    for f in frames:
        g = np.array([gt_index.setdefault(i, len(gt_index)) for i, _ in f.truth], int)
        t = np.array([tr_index.setdefault(i, len(tr_index)) for i, _ in f.tracks], int)
        gb = np.array([b for _, b in f.truth], float).reshape(-1, 4)
        tb = np.array([b for _, b in f.tracks], float).reshape(-1, 4)
        data["gt_ids"].append(g)  # type: ignore[attr-defined]
        data["tracker_ids"].append(t)  # type: ignore[attr-defined]
        data["similarity_scores"].append(iou_matrix(gb, tb))  # type: ignore[attr-defined]
        n_gt, n_tr = n_gt + len(g), n_tr + len(t)
    data.update(
        num_timesteps=len(frames),
        num_gt_ids=len(gt_index),
        num_tracker_ids=len(tr_index),
        num_gt_dets=n_gt,
        num_tracker_dets=n_tr,
        seq="camera",
    )
    hota, clear, identity = _metrics()
    with contextlib.redirect_stdout(io.StringIO()):
        h = hota.eval_sequence(data)  # type: ignore[attr-defined]
        c = clear.eval_sequence(data)  # type: ignore[attr-defined]
        i = identity.eval_sequence(data)  # type: ignore[attr-defined]
    return MotScores(
        hota=float(np.mean(h["HOTA"])),
        idf1=float(i["IDF1"]),
        mota=float(c["MOTA"]),
        id_switches=int(c["IDSW"]),
        truth_boxes=n_gt,
        track_boxes=n_tr,
    )
