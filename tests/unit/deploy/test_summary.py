"""The --duration summary stays short: the per-second timeline only when asked for."""

from __future__ import annotations

from typing import Any, cast

from common.contracts import MetricsAnswer
from deploy.supervisor import brief


def _answer() -> MetricsAnswer:
    raw: dict[str, Any] = {"fps": 5.0, "frames": 46, "timeline": {"t": [1.0, 2.0], "fps": [5, 5]}}
    return cast(MetricsAnswer, raw)


def test_the_summary_drops_the_timeline_unless_asked() -> None:
    short = brief(_answer(), timeline=False)
    assert short is not None and "timeline" not in short and short["fps"] == 5.0
    full = brief(_answer(), timeline=True)
    assert full is not None and full["timeline"]["t"] == [1.0, 2.0]
    assert brief(None, timeline=False) is None
