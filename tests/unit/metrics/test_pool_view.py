"""``zstack pool`` (services/metrics/pool_view.py) on the in-process bus: the pool's workers and
its robot's cameras from their tokens, and an announcement that does not decode reported (a
WARNING line, listed under ``bad_announcements``), never silently dropped."""

from __future__ import annotations

import dataclasses
import logging

import pytest

from common.announce import to_chunk
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement, WorkerAnnouncement
from services.metrics.pool_view import pool_view
from stack.config import Config


def test_the_pool_from_its_tokens_with_bad_announcements_reported(
    caplog: pytest.LogCaptureFixture,
) -> None:
    config = Config()
    keys = Keys(config.stack.prefix)
    hub = MemoryHub()
    others = hub.join("others")
    worker = WorkerAnnouncement(worker="detector", capacity_hz=12.34)
    others.declare_token(keys.worker_announcement("detector", to_chunk(worker)))
    others.declare_token(keys.pool_serving("detector", others.zid, "front"))
    front = CameraAnnouncement(camera="front", width=640, height=480, rate_hz=10.0)
    others.declare_token(keys.camera_announcement("front", to_chunk(front)))
    rear = dataclasses.replace(front, camera="rear", rate_hz=5.0)
    others.declare_token(keys.camera_announcement("rear", to_chunk(rear)))
    others.declare_token(keys.camera_announcement("left", "AAAA"))  # base64 of no message
    others.declare_token(keys.worker_announcement("ghost", to_chunk(worker)))  # not its name
    with caplog.at_level(logging.WARNING, logger="services.metrics.pool_view"):
        view = pool_view(config, hub.join("observer"))
    assert view["workers"] == {
        "detector": {"capacity_hz": 12.3, "robots": [keys.prefix], "cameras": ["front"]}
    }
    assert view["robots"] == {
        keys.prefix: {
            "front": {"rate_hz": 10.0, "served_by": "detector"},
            "rear": {"rate_hz": 5.0, "served_by": ""},
        }
    }
    assert view["unserved"] == ["rear"]
    bad = view["bad_announcements"]
    assert len(bad) == 2
    assert any("/camera/left/announce/" in line for line in bad)
    assert any("/workers/ghost/" in line for line in bad)
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warned) == 2 and all("bad announcement" in line for line in warned)
