"""The one way a test waits for something: poll a condition with a deadline, never a sleep.

Shared by the unit tests (a writer thread, two Zenoh sessions linking) and the integration
tests (a real stack)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import pytest


def wait_for(
    condition: Callable[[], Any],
    timeout: float,
    what: str | Callable[[], str],
    poll: float = 0.05,
) -> Any:
    """Poll ``condition`` until it returns something truthy, and return that; fail the test
    naming ``what`` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    pause = threading.Event()  # never set: wait() is the poll interval
    while time.monotonic() < deadline:
        result = condition()
        if result:
            return result
        pause.wait(poll)
    pytest.fail(
        f"timed out after {timeout:.0f} s waiting for {what if isinstance(what, str) else what()}"
    )
