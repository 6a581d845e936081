"""Asking a running stack over Zenoh: which services are ready, and the metrics service's answer.

The supervisor, the metrics command line, the report's recorder and the tests all ask these two
questions; this is the one place that knows how (a liveliness query on the health keys, a get
on the metrics key answered with JSON).
"""

from __future__ import annotations

import json
from typing import cast

import zenoh

from common.bus import Bus
from common.contracts import MetricsAnswer
from common.keys import Keys


def _bus(on: Bus | zenoh.Session) -> Bus:
    if isinstance(on, zenoh.Session):
        from common.zenoh_bus import ZenohBus

        return ZenohBus(on)  # a view of the caller's session, which stays the caller's to close
    return on


def ready_services(on: Bus | zenoh.Session, keys: Keys, timeout_s: float = 1.0) -> set[str]:
    """The services whose health token is present now (each holds one while it is ready)."""
    return {key.rsplit("/", 1)[-1] for key in _bus(on).live_tokens(keys.all_health(), timeout_s)}


def query_metrics(on: Bus | zenoh.Session, keys: Keys, timeout_s: float) -> MetricsAnswer | None:
    """The metrics service's JSON answer, or None when nobody answered within ``timeout_s``."""
    for reply in _bus(on).query(keys.metrics(), timeout_s):
        return cast(MetricsAnswer, json.loads(reply.payload))
    return None
