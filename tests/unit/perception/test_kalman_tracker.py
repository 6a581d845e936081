"""What the Kalman tracker (perception/kalman_tracker.py) holds where the IoU tracker
(perception/tracker.py) lets go: a fast turn of the robot, a person hidden for a second and a
half, two people of different colours passing. Each case against the IoU tracker on the same
frames, which loses the id: the case can fail."""

from __future__ import annotations

import math

import numpy as np

from common.boxes import Boxes
from perception.colour_cue import FEATURES, appearance, similarity
from perception.kalman_tracker import KalmanTracker
from perception.settings import TrackerParams
from perception.tracker import Tracker

W, FOCAL = 640, 554.0
RED, BLUE = (40, 40, 200), (200, 90, 40)


def _boxes(*xyxy: tuple[float, float, float, float]) -> Boxes:
    n = len(xyxy)
    return Boxes(
        xyxy=np.array(xyxy, np.float32).reshape(-1, 4),
        scores=np.full(n, 0.9, np.float32),
        class_ids=np.zeros(n, np.int32),
    )


def _painted(*boxes: tuple[tuple[float, float, float, float], tuple[int, int, int]]) -> np.ndarray:
    """A grey image with each box filled with its colour."""
    img = np.full((480, W, 3), 128, np.uint8)
    for (x0, y0, x1, y1), bgr in boxes:
        img[int(y0) : int(y1), max(int(x0), 0) : max(int(x1), 0)] = bgr
    return img


def _column(bearing: float) -> float:
    return W / 2 - FOCAL * math.tan(bearing)


def test_a_person_standing_still_while_the_robot_turns_fast_keeps_the_id() -> None:
    """The robot turns at 1.5 rad/s; frames come at 5 Hz: a still person's box jumps 0.3 rad
    (about 170 px) a frame, past its own width: without the turn taken out no overlap is
    left."""
    kalman, iou = KalmanTracker(), Tracker()
    k_ids, i_ids = [], []
    bearing = 0.5
    for i in range(5):
        cx = _column(bearing)
        box = _boxes((cx - 30, 100, cx + 30, 300))
        k_ids.append(int(kalman.update(box, 0.2 * i, turned_rad=0.3 if i else 0.0,
                                       focal_px=FOCAL, image_width=W)[0]))  # fmt: skip
        i_ids.append(int(iou.update(box, 0.2 * i)[0]))
        bearing -= 0.3
    assert len(set(k_ids)) == 1
    assert len(set(i_ids)) > 1


def test_a_person_hidden_for_a_second_and_a_half_comes_back_on_their_id() -> None:
    kalman, iou = KalmanTracker(), Tracker()
    box = (300.0, 100.0, 360.0, 300.0)
    image = _painted((box, RED))
    first_k = first_i = -1
    for i in range(5):
        feats = appearance(image, np.array([box]))
        first_k = int(kalman.update(_boxes(box), 0.2 * i, features=feats)[0])
        first_i = int(iou.update(_boxes(box), 0.2 * i)[0])
    for i in range(5, 13):  # hidden 1.6 s: no detection at all
        kalman.update(_boxes(), 0.2 * i, features=np.zeros((0, FEATURES), np.float32))
        iou.update(_boxes(), 0.2 * i)
    back = (310.0, 100.0, 370.0, 300.0)
    feats = appearance(_painted((back, RED)), np.array([back]))
    assert int(kalman.update(_boxes(back), 2.6, features=feats)[0]) == first_k
    assert int(iou.update(_boxes(back), 2.6)[0]) != first_i


def test_another_colour_where_the_lost_person_was_is_not_them() -> None:
    kalman = KalmanTracker()
    box = (300.0, 100.0, 360.0, 300.0)
    red = appearance(_painted((box, RED)), np.array([box]))
    for i in range(5):
        kalman.update(_boxes(box), 0.2 * i, features=red)
    for i in range(5, 13):
        kalman.update(_boxes(), 0.2 * i, features=np.zeros((0, FEATURES), np.float32))
    someone = appearance(_painted((box, BLUE)), np.array([box]))
    assert int(kalman.update(_boxes(box), 2.6, features=someone)[0]) not in (-1, 1)


def test_two_people_who_pass_each_other_keep_their_ids_by_colour() -> None:
    """Red walks right, blue left; at the crossing blue is in front and hides red for three
    frames. After it, each id is still on its colour."""
    kalman = KalmanTracker()
    ids: dict[tuple[int, int, int], set[int]] = {RED: set(), BLUE: set()}
    for i in range(16):
        red = (100.0 + 25 * i, 100.0, 160.0 + 25 * i, 300.0)
        blue = (500.0 - 25 * i, 90.0, 560.0 - 25 * i, 310.0)
        hidden = 6 <= i <= 8
        shown = [(blue, BLUE)] if hidden else [(red, RED), (blue, BLUE)]
        xyxy = np.array([b for b, _ in shown])
        feats = appearance(_painted(*shown), xyxy)
        got = kalman.update(_boxes(*[b for b, _ in shown]), 0.2 * i, features=feats)
        for (_, colour), track in zip(shown, got, strict=True):
            ids[colour].add(int(track))
    assert len(ids[RED]) == 1 and len(ids[BLUE]) == 1 and ids[RED] != ids[BLUE]


def test_colours_alike_and_apart() -> None:
    box = np.array([[300.0, 100.0, 360.0, 300.0]])
    red = appearance(_painted(((300, 100, 360, 300), RED)), box)
    blue = appearance(_painted(((300, 100, 360, 300), BLUE)), box)
    assert similarity(red, red)[0, 0] > 0.99 and similarity(red, blue)[0, 0] < 0.1
    assert np.isclose(red.sum(), 1.0)


def test_a_weak_dip_and_a_class_stay_apart_with_features() -> None:
    kalman = KalmanTracker(TrackerParams(high_score=0.5, low_score=0.1))
    box = (300.0, 100.0, 360.0, 300.0)
    feats = appearance(_painted((box, RED)), np.array([box]))
    first = int(kalman.update(_boxes(box), 0.0, features=feats)[0])
    weak = Boxes(xyxy=np.array([box], np.float32), scores=np.array([0.2], np.float32),
                 class_ids=np.zeros(1, np.int32))  # fmt: skip
    assert int(kalman.update(weak, 0.2, features=feats)[0]) == first
