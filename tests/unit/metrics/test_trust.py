"""The metrics service believes only known services' counters, bounded; its JSON is strict."""

from __future__ import annotations

import json
import math
from concurrent.futures import ThreadPoolExecutor

import pytest

from common.boxes import Boxes
from common.errors import ConfigError
from common.messages import Detections, Header, ServiceCounters
from common.node import Tally
from common.settings import SERVICES
from services.metrics.aggregate import Aggregator
from services.metrics.contract import MetricsSettings
from services.metrics.service import MetricsHandlers
from services.metrics.trust import (
    PoolWorkers,
    refuse_counters,
    refuse_detections,
    split_counters,
    strict_json,
)
from stack.config import Config
from tests.unit.announced import announcement

HEADER = Header(stamp_ns=1, frame_id="", seq=1, source="x")
KEY = "stack/counters/detector"


def counters(service: str = "detector", **values: int) -> ServiceCounters:
    return ServiceCounters(header=HEADER, service=service, counters=values or {"frames_in": 3})


def no_constants(name: str) -> float:
    raise ValueError(f"not JSON: {name}")


@pytest.mark.parametrize(
    "msg, key, why",
    [
        (counters(), KEY, None),
        (counters("rogue"), "stack/counters/rogue", "unknown_service"),
        (counters("camera"), KEY, "service_mismatch"),
        (counters(**{f"n{i}": 1 for i in range(11)}), KEY, "too_many_names"),
        # A bad name or count does not spoil the message: only itself (split_counters).
        (counters(**{"x" * 81: 1}), KEY, None),
        (counters(frames_in=-1), KEY, None),
    ],
)
def test_counters_are_believed_only_from_known_services(
    msg: ServiceCounters, key: str, why: str | None
) -> None:
    assert refuse_counters(msg, key, SERVICES, max_names=10) == why


def test_another_hosts_workers_are_believed_up_to_a_bound() -> None:
    workers = PoolWorkers(max_workers=2)

    def refuse(service: str, key_service: str | None = None) -> str | None:
        key = f"stack/counters/{key_service or service}"
        return refuse_counters(counters(service), key, SERVICES, 10, workers)

    assert refuse("detector_a") is None  # another host's worker: no config names it
    assert refuse("detector_a") is None  # once admitted, for good
    assert refuse("camera", "detector_b") == "service_mismatch"  # takes no place
    assert refuse("detector_b_2") is None
    assert refuse("detector_c") == "too_many_workers"
    assert refuse("detector_a") is None and refuse("detector") is None  # known: no place
    for garbage in ("detector_", "detector_C", "detector_../x", "rogue", "x" * 300):
        assert refuse(garbage) == "unknown_service", garbage
    assert workers.names == {"detector_a", "detector_b_2"}
    # Without the pool's bookkeeping, only known services.
    assert refuse_counters(counters("detector_a"), "stack/counters/detector_a", SERVICES, 10) == (
        "unknown_service"
    )


def test_a_bad_name_or_count_costs_only_itself() -> None:
    # The ROS 2 bridge's name for bad input on a Jazzy key once was 81 characters, and every
    # counter of the bridge was refused with it from then on.
    msg = counters(image_in=7, frames_in=-1, **{"bad_input.RIHS01_" + "f" * 64: 1})
    kept, refused = split_counters(msg)
    assert kept.counters == {"image_in": 7} and kept.service == "detector"
    assert refused == {"bad_name": 1, "negative_count": 1}
    fine = counters(image_in=7)
    assert split_counters(fine) == (fine, {})


def test_stage_times_outside_the_bound_are_refused() -> None:
    def dets(ms: float) -> Detections:
        return Detections(
            header=HEADER,
            image_width=4,
            image_height=4,
            boxes=Boxes(),
            class_names=(),
            timing_ms={"inference": ms},
        )

    assert refuse_detections(dets(12.5), 1e6) is None
    assert refuse_detections(dets(1e308), 1e6) == "bad_timing"
    assert refuse_detections(dets(-1.0), 1e6) == "bad_timing"


def test_each_service_keeps_a_bounded_number_of_names() -> None:
    agg = Aggregator(10.0, max_counters_per_service=3)
    agg.on_counters(counters(a=1, b=2, c=3, d=4), 0.0)
    agg.on_counters(counters("camera", a=1), 0.0)
    agg.on_counters(counters(a=5, e=1), 1.0)  # kept names still update, new ones wait
    snap = agg.snapshot(HEADER, 1.0).counters
    assert snap == {"camera.a": 1, "detector.a": 5, "detector.b": 2, "detector.c": 3}


def test_the_answer_is_strict_json() -> None:
    text = strict_json({"p50": math.inf, "xs": [1.0, math.nan, (2, -math.inf)], "n": 3})
    assert json.loads(text, parse_constant=no_constants) == {
        "p50": None, "xs": [1.0, None, [2, None]], "n": 3,
    }  # fmt: skip


def test_metrics_bounds_are_settings() -> None:
    with pytest.raises(ConfigError, match="max_counters_per_service"):
        MetricsSettings(max_counters_per_service=0)
    with pytest.raises(ConfigError, match="max_timing_ms"):
        MetricsSettings(max_timing_ms=math.inf)


def test_every_refusal_heard_is_counted_from_any_number_of_threads() -> None:
    # Issue 29, item 9: "3 refusals (counted 2)" was a message that never arrived, not a lost
    # count: every refusal the handler hears is counted, from Zenoh's threads at once too.
    config = Config()
    handlers = MetricsHandlers(config, Tally("metrics", config))
    handlers.set_cameras({"front": announcement("front", config.camera)})
    key = handlers.tally.keys.detections("front")
    bad = Detections(
        header=HEADER, image_width=4, image_height=4, boxes=Boxes(), class_names=(),
        timing_ms={"inference": 1e308},
    ).encode()  # fmt: skip
    with ThreadPoolExecutor(8) as pool:
        list(pool.map(lambda _: handlers.on_detections("front", key, bad), range(2000)))
    counted = handlers.agg.answer(HEADER, 1.0)["counters"]["metrics.refused.bad_timing"]
    assert counted == 2000
