"""The detector's per-camera slots and fair rounds (services/detector/schedule.py)."""

from __future__ import annotations

import math
import random
import threading
from dataclasses import dataclass, field

import pytest

from common.clock import mono_s
from services.detector.schedule import CameraSlots


def test_one_camera_newest_item_wins_and_each_overwrite_reports_a_drop() -> None:
    slots: CameraSlots[int] = CameraSlots(["front"])
    assert slots.put("front", 1) is False
    assert slots.put("front", 2) is True  # 1 was never taken: dropped
    (taken,) = slots.take(4, timeout=0.1)
    assert (taken.camera, taken.item) == ("front", 2) and taken.received_ns > 0
    assert slots.take(4, timeout=0.01) == []
    assert slots.put("front", 3) is False  # the slot was empty again


def test_a_round_takes_the_longest_waiting_cameras_first_up_to_max_batch() -> None:
    slots: CameraSlots[str] = CameraSlots(["a", "b", "c"])
    slots.put("b", "b1")
    slots.put("c", "c1")
    slots.put("a", "a1")
    slots.put("b", "b2")  # replaces b1 but keeps b's place: b has waited longest
    assert [(w.camera, w.item) for w in slots.take(2, 0)] == [("b", "b2"), ("c", "c1")]
    slots.put("b", "b3")  # b was just served: behind a now
    assert [(w.camera, w.item) for w in slots.take(2, 0)] == [("a", "a1"), ("b", "b3")]
    assert slots.waiting() == 0


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="distinct"):
        CameraSlots(["a", "a"])
    slots: CameraSlots[int] = CameraSlots(["a"])
    with pytest.raises(KeyError):
        slots.put("nope", 1)
    slots.add("nope")  # a camera announced at run time
    assert not slots.put("nope", 1)
    with pytest.raises(ValueError, match="max_batch"):
        slots.take(0, 0)


def test_take_wakes_as_soon_as_a_frame_arrives() -> None:
    slots: CameraSlots[int] = CameraSlots(["a", "b"])
    threading.Timer(0.05, slots.put, args=("b", 7)).start()
    start = mono_s()
    (taken,) = slots.take(2, timeout=30.0)
    assert (taken.camera, taken.item) == ("b", 7)
    assert mono_s() - start < 10.0  # woken by the put, not the timeout


# ------------------------------------------------ the fairness bound, in simulated time


@dataclass
class _Run:
    """What a simulated detector did with each camera's frames."""

    sent: dict[str, int] = field(default_factory=dict)
    detected: dict[str, int] = field(default_factory=dict)
    worst_rounds: dict[str, int] = field(default_factory=dict)  # rounds a wait lasted, at most
    batches: list[int] = field(default_factory=list)


def _simulate(
    rates_hz: dict[str, float], max_batch: int, round_s: float, duration_s: float, seed: int = 0
) -> _Run:
    """Cameras put frames at their rates (random phases) while a detector takes rounds of
    ``round_s`` seconds each, back to back whenever something waits. Time is simulated: the
    slots never see a clock, only the order of puts and takes."""
    rng = random.Random(seed)
    slots: CameraSlots[int] = CameraSlots(rates_hz)
    phases = {cam: rng.uniform(0, 1 / rate) for cam, rate in rates_hz.items()}
    arrivals = sorted(
        (phases[cam] + k / rate, cam)
        for cam, rate in rates_hz.items()
        for k in range(int(duration_s * rate))
    )
    run = _Run(sent=dict.fromkeys(rates_hz, 0), detected=dict.fromkeys(rates_hz, 0))
    run.worst_rounds = dict.fromkeys(rates_hz, 0)
    rounds_started = 0
    wait_began: dict[str, int] = {}  # camera -> rounds started before its wait began
    free_at, i = 0.0, 0
    while i < len(arrivals) or slots.waiting():
        # Every frame that arrives before the detector is free is put first.
        while i < len(arrivals) and (arrivals[i][0] <= free_at or not slots.waiting()):
            at, cam = arrivals[i]
            run.sent[cam] += 1
            if not slots.put(cam, i):
                wait_began[cam] = rounds_started
            free_at = max(free_at, at)
            i += 1
        taken = slots.take(max_batch, timeout=0)
        rounds_started += 1
        run.batches.append(len(taken))
        for w in taken:
            run.detected[w.camera] += 1
            waited = rounds_started - wait_began.pop(w.camera)
            run.worst_rounds[w.camera] = max(run.worst_rounds[w.camera], waited)
        free_at += round_s
    return run


@pytest.mark.parametrize("seed", range(20))
def test_no_camera_waits_more_than_ceil_n_over_max_batch_rounds(seed: int) -> None:
    rng = random.Random(seed)
    n = rng.randint(1, 8)
    rates = {f"cam{k}": rng.choice([1.0, 5.0, 15.0, 30.0, 100.0, 1000.0]) for k in range(n)}
    max_batch = rng.randint(1, n + 1)
    round_s = rng.uniform(0.005, 0.5)  # from much faster to much slower than the cameras
    run = _simulate(rates, max_batch, round_s, duration_s=20.0, seed=seed)
    bound = math.ceil(n / max_batch)
    assert max(run.worst_rounds.values()) <= bound, (rates, max_batch, round_s, run.worst_rounds)
    assert max(run.batches) <= min(max_batch, n)


@pytest.mark.parametrize("max_batch, round_s", [(1, 0.09), (2, 0.15)])
def test_a_100_hz_camera_never_starves_a_5_hz_one(max_batch: int, round_s: float) -> None:
    """Overloaded (the 100 Hz camera alone would need 9 to 15 s of rounds a second): the 5 Hz
    camera still waits at most ceil(2 / max_batch) rounds, which here last less than its
    period (200 ms), so each of its frames is detected before the next one comes."""
    run = _simulate({"fast": 100.0, "slow": 5.0}, max_batch, round_s, duration_s=60.0)
    assert run.worst_rounds["slow"] <= math.ceil(2 / max_batch)
    assert run.detected["slow"] == run.sent["slow"]  # every one: no 5 Hz frame was replaced
    assert run.detected["fast"] < run.sent["fast"] / 5  # the flood is what gets dropped


def test_batches_fill_up_to_the_number_of_waiting_cameras() -> None:
    run = _simulate({f"c{k}": 30.0 for k in range(6)}, 4, round_s=0.2, duration_s=10.0)
    assert max(run.batches) == 4 and run.batches.count(4) > len(run.batches) // 2
