"""lower_priority on a real process (a child, so that this one keeps its priority): the nice
value and SCHED_IDLE, and that threads started afterwards (Zenoh's) inherit both."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from common.priority import lower_priority

CHILD = """
import json, os, threading
from common.priority import lower_priority
said = lower_priority({nice}, {idle})
seen = {{}}
def look():
    seen["thread"] = [os.nice(0), os.sched_getscheduler(0)]
t = threading.Thread(target=look); t.start(); t.join()
print(json.dumps({{"said": said, "main": [os.nice(0), os.sched_getscheduler(0)], **seen}}))
"""
REPO = Path(__file__).resolve().parents[3]


def _child(nice: int, idle: bool) -> dict[str, object]:
    out = subprocess.run(
        [sys.executable, "-c", CHILD.format(nice=nice, idle=idle)], cwd=REPO,
        capture_output=True, text=True, timeout=60, check=True,
    )  # fmt: skip
    return dict(json.loads(out.stdout))


def test_nice_and_sched_idle_reach_every_later_thread() -> None:
    base = os.nice(0)
    got = _child(7, True)
    want = [min(base + 7, 19), os.SCHED_IDLE]
    assert got["main"] == want and got["thread"] == want
    assert "SCHED_IDLE" in str(got["said"])


def test_nice_alone_keeps_the_normal_policy() -> None:
    got = _child(3, False)
    assert got["thread"] == [min(os.nice(0) + 3, 19), os.SCHED_OTHER]


def test_nothing_asked_changes_nothing() -> None:
    assert lower_priority(0, False) == "unchanged"
