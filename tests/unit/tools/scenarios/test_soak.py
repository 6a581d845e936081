"""The soak's pure parts: its garbage is garbage, and its verdicts follow from the samples."""

from __future__ import annotations

import random

import numpy as np
import pytest

from common.errors import DecodeError
from common.messages import GroundTruth, Header
from tests.unit.common.test_fuzz_decoders import MESSAGE_TYPES
from tools.scenarios.soak import Sample, SoakFigures, garbage, soak_table, summarise

HDR = Header(stamp_ns=1, frame_id="world", source="sim", seq=0)


def truth(t: float, robot_x: float, target: tuple[float, float]) -> GroundTruth:
    return GroundTruth(
        header=HDR,
        sim_time_s=t,
        robot=(robot_x, 0.0, 0.0),
        targets_xy=np.array([target]),
        target_names=("person",),
        target_ids=("alice",),
    )


def test_garbage_is_refused_by_every_message_type() -> None:
    rng = random.Random(1)
    for _ in range(300):
        payload = garbage(rng)
        for message in MESSAGE_TYPES:
            with pytest.raises(DecodeError):
                message.decode(payload)


def test_flat_memory_bounded_log_and_following() -> None:
    figures = SoakFigures(flood_messages=1000)
    for i, t in enumerate(range(0, 601, 60)):
        rss = {"detector": 300.0 + (50.0 if t == 0 else 0.5 * i), "controller": 80.0}
        figures.samples.append(Sample(float(t), rss, 10_000 + 10 * t, {"detector": 7}))
    truths = [truth(float(t), 0.0, (2.0, 0.2)) for t in range(500, 601)]
    r = summarise(figures, truths, hfov_deg=60.0)
    # The start-up sample (t=0) is not counted: memory is judged after the warm-up.
    assert r["memory"]["detector"]["start_mb"] == pytest.approx(300.5)
    assert r["memory"]["detector"]["growth_mb"] == pytest.approx(4.5)
    assert r["memory"]["controller"]["growth_mb"] == 0.0
    assert r["log_bytes_per_s_second_half"] == pytest.approx(10.0)
    assert r["restarts"] == {"detector": 0}
    assert r["still_following"] is True and r["last_window_s"] == 60.0


def test_a_short_soak_judges_no_memory_growth_and_says_its_window() -> None:
    figures = SoakFigures(flood_messages=10)
    for t in (0, 10, 20, 30, 40):  # a 45 s run: nothing after the 60 s warm-up
        figures.samples.append(Sample(float(t), {"detector": 100.0 + 5 * t}, 1000, {}))
    truths = [truth(float(t), 0.0, (2.0, 0.2)) for t in range(0, 45)]
    r = summarise(figures, truths, hfov_deg=60.0)
    assert r["memory"] == {}  # the model's load is not "growth"
    assert r["last_window_s"] == pytest.approx(22.0)  # the second half, not "the last minute"
    table = soak_table({**r, "log": "x"})
    assert "memory: not judged" in table and "of the last 22 s" in table


def test_a_lost_person_or_a_restart_is_reported() -> None:
    figures = SoakFigures(
        samples=[Sample(float(t), {}, 0, {"detector": 7 if t < 100 else 8}) for t in (0, 200)]
    )
    behind = [truth(float(t), 0.0, (-3.0, 0.0)) for t in range(0, 120)]
    r = summarise(figures, behind, hfov_deg=60.0)
    assert r["restarts"] == {"detector": 1}
    assert r["last_window_in_view"] == 0.0
    assert r["still_following"] is False
