"""Asking a running stack over Zenoh: which services are ready, and the metrics service's answer.

The supervisor, the metrics command line, the report's recorder and the tests all ask these two
questions; this is the one place that knows how (a liveliness query on the health keys, a get
on the metrics key answered with JSON).
"""

from __future__ import annotations

import json
from typing import cast

import zenoh

from common.contracts import MetricsAnswer
from common.keys import Keys


def ready_services(session: zenoh.Session, keys: Keys, timeout_s: float = 1.0) -> set[str]:
    """The services whose health token is present now (each holds one while it is ready)."""
    replies = session.liveliness().get(keys.all_health(), timeout=timeout_s)
    return {str(r.ok.key_expr).rsplit("/", 1)[-1] for r in replies if r.ok is not None}


def query_metrics(session: zenoh.Session, keys: Keys, timeout_s: float) -> MetricsAnswer | None:
    """The metrics service's JSON answer, or None when nobody answered within ``timeout_s``."""
    for reply in session.get(keys.metrics(), timeout=timeout_s):
        if reply.ok is not None:
            return cast(MetricsAnswer, json.loads(reply.ok.payload.to_string()))
    return None
