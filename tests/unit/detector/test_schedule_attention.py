"""Rounds taken in attention's order (services/detector/schedule.py with
services/detector/attention.py), in simulated time on a FakeClock: with nothing prioritised
exactly the fair rounds; with a priority camera, that camera first and every other at least at
the floor rate, within the bound the attention module states."""

from __future__ import annotations

import itertools
import math
import random
from collections.abc import Sequence
from dataclasses import dataclass, field

import pytest

from common.clock import FakeClock
from services.controller.contract import ControllerSettings
from services.detector.attention import FLOOR, PRIORITY, SPARE, Attention
from services.detector.contract import DetectorSettings
from services.detector.schedule import CameraSlots


@dataclass
class _Run:
    taken: list[tuple[float, str, str]] = field(default_factory=list)  # (at, camera, reason)

    def times(self, camera: str) -> list[float]:
        return [at for at, cam, _ in self.taken if cam == camera]

    def count(self, camera: str) -> int:
        return len(self.times(camera))


def _simulate(
    rates_hz: dict[str, float],
    max_batch: int,
    round_s: float,
    duration_s: float,
    attention: Attention | None,
    clock: FakeClock,
    locked: str = "",
    seed: int = 0,
) -> _Run:
    """Cameras put frames at their rates (random phases); a detector takes a round whenever
    one is waiting, each lasting ``round_s``; the controller's status names ``locked`` before
    every round."""
    rng = random.Random(seed)
    slots: CameraSlots[int] = CameraSlots(rates_hz, clock)
    arrivals = sorted(
        (phase + k / rate, cam)
        for cam, rate in rates_hz.items()
        for phase in [rng.uniform(0, 1 / rate)]
        for k in range(int(duration_s * rate))
    )
    run, now, i = _Run(), 0.0, 0

    def to(t: float) -> None:
        nonlocal now
        clock.advance(max(0.0, t - now))
        now = max(now, t)

    while i < len(arrivals) or slots.waiting():
        while i < len(arrivals) and (arrivals[i][0] <= now or not slots.waiting()):
            to(arrivals[i][0])
            slots.put(arrivals[i][1], i)
            i += 1
        if attention is not None:
            attention.controller(locked, ("person",))
        for w in slots.take(max_batch, timeout=0, order=attention):
            run.taken.append((now, w.camera, w.reason))
        to(now + round_s)
    return run


def _gaps(times: Sequence[float]) -> list[float]:
    return [b - a for a, b in itertools.pairwise(times)]


@pytest.mark.parametrize("seed", range(10))
def test_with_nothing_prioritised_the_rounds_are_exactly_the_fair_ones(seed: int) -> None:
    rng = random.Random(seed)
    n = rng.randint(1, 6)
    rates = {f"cam{k}": rng.choice([1.0, 5.0, 15.0, 30.0]) for k in range(n)}
    max_batch, round_s = rng.randint(1, n), rng.uniform(0.01, 0.5)
    fair = _simulate(rates, max_batch, round_s, 10.0, None, FakeClock(), seed=seed)
    clock = FakeClock()
    attention = Attention(clock, floor_hz=1.0, hold_s=1.0)
    arranged = _simulate(rates, max_batch, round_s, 10.0, attention, clock, seed=seed)
    assert [(at, cam) for at, cam, _ in arranged.taken] == [(at, cam) for at, cam, _ in fair.taken]
    assert {why for *_, why in arranged.taken} == {""}


@pytest.mark.parametrize("seed", range(20))
def test_the_locked_camera_goes_first_and_every_other_keeps_its_floor(seed: int) -> None:
    """Short of capacity (the cameras send far more than the rounds take): the locked camera
    is taken in most rounds, and every other camera's takes are never further apart than
    1 / floor + ceil(n / max_batch) rounds (+ one frame interval: its next frame may come
    just after it fell due)."""
    rng = random.Random(seed)
    n = rng.randint(2, 6)
    rates = {f"cam{k}": rng.choice([5.0, 10.0, 30.0]) for k in range(n)}
    max_batch = rng.randint(1, n)
    round_s = rng.uniform(0.1, 0.4) * max_batch  # always short: at most 10 frames/s taken
    # The floors take at most half of what the rounds can (floors asking for all of it are
    # the fair rotation again: every camera due in every round).
    floor_hz = min(rng.choice([0.5, 1.0, 2.0]), max_batch / round_s / (2 * (n - 1)))
    clock = FakeClock()
    attention = Attention(clock, floor_hz=floor_hz, hold_s=1.0)
    run = _simulate(rates, max_batch, round_s, 30.0, attention, clock, locked="cam0", seed=seed)
    bound = 1 / floor_hz + math.ceil(n / max_batch) * round_s
    for cam, rate in rates.items():
        worst = max(_gaps(run.times(cam)))
        assert worst <= bound + 1 / rate + 1e-9, (cam, worst, bound, rates, max_batch, round_s)
    others = [run.count(cam) for cam in rates if cam != "cam0"]
    fair = _simulate(rates, max_batch, round_s, 30.0, None, FakeClock(), seed=seed)
    # Served first: never fewer frames than in the fair rounds, nor than an empty camera (but
    # for the very last round, when cam0's frames may have run out first).
    assert run.count("cam0") >= fair.count("cam0")
    assert run.count("cam0") >= max(others) - 1
    assert {why for _, cam, why in run.taken if cam == "cam0"} == {PRIORITY}
    assert {why for _, cam, why in run.taken if cam != "cam0"} <= {FLOOR, SPARE, ""}


def test_three_cameras_on_a_cpu_the_target_camera_gets_several_times_an_empty_ones() -> None:
    """The issue's case: three 10 Hz cameras, one round of one frame taking 0.3 s (about 3.3
    detections a second in all, 1.1 per camera when shared evenly)."""
    rates = {"front": 10.0, "left": 10.0, "rear": 10.0}
    fair = _simulate(rates, 1, 0.3, 60.0, None, FakeClock())
    clock = FakeClock()
    attention = Attention(clock, floor_hz=0.5, hold_s=2.0)
    run = _simulate(rates, 1, 0.3, 60.0, attention, clock, locked="rear")
    assert max(fair.count(c) for c in rates) - min(fair.count(c) for c in rates) <= 1
    assert run.count("rear") >= 2 * max(run.count("front"), run.count("left"))
    for cam in ("front", "left"):  # the floor: 0.5 Hz, within a round or two
        assert max(_gaps(run.times(cam))) <= 2.0 + 2 * 0.3 + 0.1 + 1e-9
        assert run.count(cam) >= 0.5 * 60 * 0.9


def test_a_bad_order_is_refused() -> None:
    class Drops:
        def arrange(self, cameras: Sequence[str]) -> list[tuple[str, str]]:
            return [(cameras[0], "")]

        def taken(self, cameras: Sequence[str]) -> None:
            pass

    slots: CameraSlots[int] = CameraSlots(["a", "b"])
    slots.put("a", 1)
    slots.put("b", 2)
    with pytest.raises(ValueError, match="rearrangement"):
        slots.take(1, 0, order=Drops())


def _defaults(clock: FakeClock) -> Attention:
    s = DetectorSettings()
    return Attention(
        clock, s.attention_floor_hz, s.attention_hold_s, floor_share=s.attention_floor_share
    )


def test_with_the_defaults_empty_cameras_stay_under_the_controllers_dead_man() -> None:
    """Issue 39: the floor let empty cameras' detections come 1.51 s apart (over the
    controller's 1 s dead-man: stale between two). With the defaults and three cameras at 0.1 s
    a round (10 detections a second), no gap of theirs reaches detection_timeout_s, and the
    target's camera still has most of the rounds."""
    timeout_s = ControllerSettings().detection_timeout_s
    rates = {"front": 10.0, "left": 10.0, "rear": 10.0}
    clock = FakeClock()
    attention = _defaults(clock)
    run = _simulate(rates, 1, 0.1, 60.0, attention, clock, locked="rear")
    for cam in ("front", "left"):
        assert max(_gaps(run.times(cam))) < timeout_s, cam
    assert run.count("rear") >= 0.6 * len(run.taken)
    assert attention.floor_held == 0  # the floors fit: their bound holds


def test_floors_that_do_not_fit_leave_the_target_its_share() -> None:
    """A slow worker (0.3 s a round, 3.3 detections a second): the floors of two empty
    cameras would take 3 of them. They are held to attention_floor_share of the frames, and
    said (floor_held): the target's camera keeps half of the rounds."""
    rates = {"front": 10.0, "left": 10.0, "rear": 10.0}
    clock = FakeClock()
    attention = _defaults(clock)
    run = _simulate(rates, 1, 0.3, 60.0, attention, clock, locked="rear")
    assert run.count("rear") >= 0.45 * len(run.taken)
    assert attention.floor_held > 0
    assert min(run.count("front"), run.count("left")) >= 0.2 * len(run.taken)
