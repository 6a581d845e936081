"""The trackers keep ids across frames, across a weak frame, and apart for two people; both
the IoU tracker (perception/tracker.py) and the Kalman one (perception/kalman_tracker.py)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from common.boxes import Boxes
from common.errors import ConfigError
from perception.kalman_tracker import KalmanTracker
from perception.settings import TrackerParams
from perception.tracker import Tracker, iou_matrix, tracker_clock

Make = Callable[..., Tracker | KalmanTracker]


@pytest.fixture(params=[Tracker, KalmanTracker], ids=["iou", "kalman"])
def make(request: pytest.FixtureRequest) -> Make:
    out: Make = request.param
    return out


def _frame(
    tracker: Tracker | KalmanTracker,
    boxes: list[list[float]],
    scores: list[float],
    t: float,
    classes: list[int] | None = None,
) -> list[int]:
    ids = tracker.update(
        Boxes(
            xyxy=np.array(boxes, np.float32).reshape(-1, 4),
            scores=np.array(scores, np.float32),
            class_ids=np.array(classes or [0] * len(scores), np.int32),
        ),
        t,
    )
    return ids.tolist()


def test_iou_matrix_against_hand_values() -> None:
    a = np.array([[0, 0, 10, 10], [20, 20, 30, 30]], np.float32)
    b = np.array([[5, 0, 15, 10], [0, 0, 10, 10], [100, 100, 101, 101]], np.float32)
    expected = np.array([[50 / 150, 1.0, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(iou_matrix(a, b), expected)
    assert iou_matrix(a[:0], b).shape == (0, 3)


def test_ids_persist_while_the_box_moves(make: Make) -> None:
    tr = make()
    ids = [_frame(tr, [[10 + 8 * i, 10, 60 + 8 * i, 110]], [0.9], t=0.1 * i)[0] for i in range(20)]
    assert len(set(ids)) == 1 and ids[0] > 0


def test_two_people_crossing_keep_their_ids(make: Make) -> None:
    tr = make()
    left, right = [], []
    for i in range(25):  # two boxes approach each other and pass; velocity keeps them apart
        a = [50 + 10 * i, 100, 110 + 10 * i, 250]
        b = [400 - 10 * i, 100, 460 - 10 * i, 250]
        ids = _frame(tr, [a, b], [0.9, 0.8], t=0.1 * i)
        left.append(ids[0])
        right.append(ids[1])
    assert len(set(left)) == 1 and len(set(right)) == 1 and left[0] != right[0]


def test_weak_detection_extends_but_never_starts_a_track(make: Make) -> None:
    tr = make(TrackerParams(high_score=0.5, low_score=0.1))
    first = _frame(tr, [[0, 0, 50, 100]], [0.9], t=0.0)[0]
    assert _frame(tr, [[2, 0, 52, 100]], [0.2], t=0.1) == [first]  # a dip keeps the id
    assert _frame(tr, [[300, 0, 350, 100]], [0.2], t=0.2) == [-1]  # weak and new: no track


def test_lost_track_expires_and_a_new_id_is_given(make: Make) -> None:
    tr = make(TrackerParams(max_age_s=0.5))
    first = _frame(tr, [[0, 0, 50, 100]], [0.9], t=0.0)[0]
    assert _frame(tr, [[0, 0, 50, 100]], [0.9], t=0.4) == [first]
    assert _frame(tr, [[0, 0, 50, 100]], [0.9], t=1.5) != [first]


def test_classes_never_share_a_track(make: Make) -> None:
    tr = make()
    person = _frame(tr, [[0, 0, 50, 100]], [0.9], t=0.0, classes=[0])[0]
    assert _frame(tr, [[0, 0, 50, 100]], [0.9], t=0.1, classes=[15]) != [person]


def test_a_frame_whose_stamp_jumps_is_ignored_and_tracks_survive(make: Make) -> None:
    tr = make(TrackerParams(max_stamp_jump_s=0.5))
    box = Boxes(
        xyxy=np.array([[100, 100, 200, 300]], np.float32),
        scores=np.array([0.9], np.float32),
        class_ids=np.array([0], np.int32),
    )
    first = tr.update(box, now=10.0, arrival=1.0)
    # Stamped an hour ahead though it arrived 0.2 s later: ignored, ids -1, no reset.
    assert (tr.update(box, now=3610.0, arrival=1.2) == -1).all()
    # Stamped in the past: ignored too.
    assert (tr.update(box, now=5.0, arrival=1.3) == -1).all()
    assert tr.ignored_frames == 2
    # The next honest frame keeps the same id.
    assert (tr.update(box, now=10.4, arrival=1.4) == first).all()


def test_a_clock_that_really_stepped_restarts_the_tracks(make: Make) -> None:
    tr = make(TrackerParams(max_stamp_jump_s=0.5, jumps_before_reset=3))
    box = Boxes(
        xyxy=np.array([[100, 100, 200, 300]], np.float32),
        scores=np.array([0.9], np.float32),
        class_ids=np.array([0], np.int32),
    )
    tr.update(box, now=10.0, arrival=1.0)
    assert (tr.update(box, now=110.0, arrival=1.1) == -1).all()
    assert (tr.update(box, now=110.1, arrival=1.2) == -1).all()
    ids = tr.update(box, now=110.2, arrival=1.3)
    assert (ids > 0).all() and tr.resets == 1


def test_the_tracker_takes_the_stack_tracker_settings(make: Make) -> None:
    settings = TrackerParams(max_stamp_jump_s=0.5, jumps_before_reset=1)
    tr = make(settings)
    assert tr.settings is settings
    assert make().settings == TrackerParams()  # one default, the settings' own
    box = Boxes(
        xyxy=np.array([[100, 100, 200, 300]], np.float32),
        scores=np.array([0.9], np.float32),
        class_ids=np.array([0], np.int32),
    )
    tr.update(box, now=10.0, arrival=1.0)
    # jumps_before_reset = 1: the first jump is believed at once and the tracks restart.
    assert (tr.update(box, now=110.0, arrival=1.1) > 0).all() and tr.resets == 1
    message = r"tracker\.jumps_before_reset must be within 1\.\.1000, got 0"
    with pytest.raises(ConfigError, match=message):
        TrackerParams(jumps_before_reset=0)


def test_frames_from_this_host_are_tracked_on_their_monotonic_stamp() -> None:
    # Same boot: the monotonic capture instant, and no jump check (it cannot step).
    assert tracker_clock(5 * 10**18, 2_500_000_000, "boot-a", 9 * 10**18, "boot-a") == (2.5, None)
    # Another host, or no monotonic stamp: the wall stamp, checked against the arrival.
    assert tracker_clock(7_000_000_000, 2_500_000_000, "boot-b", 8_000_000_000, "boot-a") == (
        7.0,
        8.0,
    )
    assert tracker_clock(7_000_000_000, 0, "", 8_000_000_000, "boot-a") == (7.0, 8.0)


def test_late_deliveries_at_start_up_restart_nothing_on_one_host(make: Make) -> None:
    """The start-up seen under the secure profile: the first frame the detector used was
    delivered 0.6 s late (every service loading on two cores), the next ones promptly. On wall
    stamps and arrivals that looked like a clock that stepped three times in a row; on
    monotonic stamps it is nothing."""
    box = Boxes(
        xyxy=np.array([[100, 100, 200, 300]], np.float32),
        scores=np.array([0.9], np.float32),
        class_ids=np.array([0], np.int32),
    )
    captures = [1.0, 1.8, 2.0, 2.2]
    arrivals = [1.6, 1.81, 2.01, 2.21]  # the first 0.6 s late, then 10 ms
    on_wall = make(TrackerParams())
    for c, a in zip(captures, arrivals, strict=True):
        on_wall.update(box, now=c, arrival=a)
    assert on_wall.resets == 1  # what the wall-clock check made of it
    on_mono = make(TrackerParams())
    ids = []
    for c, a in zip(captures, arrivals, strict=True):
        at, arrival = tracker_clock(int(c * 1e9) + 10**18, int(c * 1e9), "b", int(a * 1e9), "b")
        ids.append(int(on_mono.update(box, now=at, arrival=arrival)[0]))
    assert on_mono.resets == 0 and on_mono.ignored_frames == 0
    assert len(set(ids)) == 1 and ids[0] > 0
