"""The tracking evaluation's pure parts (tools/tracking): TrackEval's scores on hand-made
sequences, a recorded run labelled with the truth at each frame's capture, a tracker replayed
on it, and the controller's lock read against the truth."""

from __future__ import annotations

import numpy as np
import pytest

from common.boxes import Boxes
from common.messages import ControllerStatus, Detections, GroundTruth, Header, Twist
from perception import KalmanTracker, Tracker
from simworld.cast import card
from simworld.render import CameraSpec
from simworld.truth import visible_boxes
from simworld.world import Robot, World
from tools.tracking.evaluate import lock_figures, replay, turned_between
from tools.tracking.frames import label, nearest_truth
from tools.tracking.mot import MotFrame, mot_metrics

A, B = (0.0, 0.0, 10.0, 10.0), (20.0, 0.0, 30.0, 10.0)
SPEC = CameraSpec(640, 480, 60.0, 0.6)
S = 1_000_000_000


def test_perfect_tracks_score_one_and_a_swap_costs_identity() -> None:
    perfect = [MotFrame([("a", A), ("b", B)], [(1, A), (2, B)]) for _ in range(10)]
    p = mot_metrics(perfect)
    assert (p.hota, p.idf1, p.mota, p.id_switches) == (pytest.approx(1.0), 1.0, 1.0, 0)
    swapped = perfect[:5] + [MotFrame([("a", A), ("b", B)], [(2, A), (1, B)]) for _ in range(5)]
    s = mot_metrics(swapped)
    assert s.id_switches == 2 and s.idf1 == pytest.approx(0.5) and s.hota < 0.7
    missed = [MotFrame([("a", A)], []) for _ in range(4)]
    assert mot_metrics(missed).mota == 0.0


def _truth(t: float, robot_x: float = 0.0) -> GroundTruth:
    return GroundTruth(
        header=Header(stamp_ns=int(t * S), frame_id="world", seq=0, source="sim"),
        sim_time_s=t, robot=(robot_x, 0.0, 0.0),
        targets_xy=np.array([[4.0, 0.0], [4.0, 1.5]]), target_names=("person", "person"),
        target_ids=("alice", "bob"),
    )  # fmt: skip


def _dets(t: float, *boxes: tuple[float, ...], tracks: list[int] | None = None) -> Detections:
    n = len(boxes)
    return Detections(
        header=Header(stamp_ns=int(t * S), frame_id="front", seq=0, source="sim"),
        image_width=640, image_height=480,
        boxes=Boxes(
            xyxy=np.array(boxes, np.float32).reshape(-1, 4), scores=np.full(n, 0.9, np.float32),
            class_ids=np.zeros(n, np.int32),
            track_ids=None if tracks is None else np.array(tracks, np.int32),
        ),
        class_names=("person",) * n,
    )  # fmt: skip


def _world() -> World:
    return World(Robot(), targets=[card("alice", (0, 4.0, 0.0)), card("bob", (0, 4.0, 1.5))])


def test_a_run_is_labelled_with_the_truth_at_each_frame_and_a_tracker_replayed_on_it() -> None:
    assert [nearest_truth([0, 10, 20], s) for s in (-5, 4, 6, 19, 99)] == [0, 0, 1, 2, 2]
    world = _world()
    truths = [_truth(0.1 * k) for k in range(40)]
    # The detector's boxes: the truth's own, as a perfect detector would give them.
    boxes = [b.box for b in visible_boxes(world, SPEC)]
    dets = [_dets(0.2 * k + 0.01, *boxes) for k in range(15)]
    frames = label(world, {"front": SPEC}, truths, {"front": dets, "rear": dets})
    assert list(frames) == ["front"]  # no spec for "rear": not labelled
    assert [b.target for b in frames["front"][0].truth] == ["alice", "bob"]
    for make in (Tracker, KalmanTracker):
        mot = replay(frames["front"], make().update, [], SPEC.focal_px)
        scores = mot_metrics(mot)
        assert scores.idf1 == pytest.approx(1.0) and scores.id_switches == 0


def test_the_turn_between_frames_is_the_commands_integrated() -> None:
    twists = [
        Twist(header=Header(stamp_ns=int(t * S), frame_id="", seq=0, source="c"),
              angular=(0.0, 0.0, w))
        for t, w in ((0.0, 1.0), (1.0, -0.5), (2.0, 0.0))
    ]  # fmt: skip
    stamps = [t.header.stamp_ns for t in twists]
    assert turned_between(twists, stamps, 0, 2 * S) == pytest.approx(0.5)
    assert turned_between(twists, stamps, int(0.5 * S), int(1.5 * S)) == pytest.approx(0.25)
    assert turned_between(twists, stamps, 3 * S, 4 * S) == 0.0


def _status(t: float, track: int, state: str = "following") -> ControllerStatus:
    return ControllerStatus(
        header=Header(stamp_ns=int(t * S), frame_id="", seq=0, source="controller"),
        mode="follow", target="person", state=state, reason="", track_id=track, camera="front",
    )  # fmt: skip


def test_the_lock_is_read_against_the_truth() -> None:
    """alice (the followed) and bob stand side by side; the lock is on alice's track, then on
    bob's for a while (a switch), then back; from 2 s to 3 s alice is out of view (her box is
    not in the truth), and the lock takes her back 0.4 s after she shows again."""
    world = _world()
    a_box, b_box = (b.box for b in visible_boxes(world, SPEC))
    truths = [_truth(0.05 * k) for k in range(120)]
    dets, statuses = [], []
    for k in range(50):
        t = 0.1 * k
        dets.append(_dets(t, a_box, b_box, tracks=[1, 2]))
        on = 2 if 1.0 <= t < 1.5 else 1
        if 3.0 <= t < 3.4:
            statuses.append(_status(t + 0.01, 0, "searching"))
        else:
            statuses.append(_status(t + 0.01, on))
    frames = label(world, {"front": SPEC}, truths, {"front": dets})
    # alice hidden from 2 s to 3 s: drop her box from those frames' truth.
    for i, f in enumerate(frames["front"]):
        if 2.0 <= 0.1 * i < 3.0:
            frames["front"][i] = type(f)(f.detections, f.truth[1:], f.sim_time_s)
    figures = lock_figures(statuses, frames, "alice")
    assert figures.switches == 1
    assert figures.reacquire_s == (pytest.approx(0.4, abs=0.01),)
    assert figures.on_target == pytest.approx(31 / 40)  # 5 on bob, 4 searching, of 40 shown
