"""Running a service for the handler fuzz tests (test_fuzz_handlers.py,
test_fuzz_new_services.py): its ``run`` in a thread on sessions that reach nobody, and a
hypothesis loop that feeds one subscription callback payloads and checks ``bad_input``."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import ModuleType
from typing import Any

import pytest
from hypothesis import given

from common.codec import Message
from common.errors import DecodeError
from common.node import Node
from common.settings import Config
from tests.unit.fuzz import FakeSample, RecordingSession, fuzz, message_payloads, sessions

NODE_SESSION = "common.node.open_session"
ROS_SESSION = "services.ros2.graph.open_ros_session"
READY_S = 60.0
EXAMPLES = 50  # per subscription: about 750 payloads in all, in a few seconds

#: What a service thread runs: ``module.run`` or the like, its exit code returned.
Run = Callable[[Config, threading.Event], int]


def wait_until(condition: Callable[[], Any], what: str, within_s: float = READY_S) -> None:
    deadline, pause = time.monotonic() + within_s, threading.Event()
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        pause.wait(0.002)


@contextmanager
def serving(
    monkeypatch: pytest.MonkeyPatch,
    module: ModuleType,
    config: Config,
    *opens: str,
    run: Run | None = None,
) -> Iterator[tuple[Node, list[RecordingSession]]]:
    """``module.run(config, stop)`` (or ``run``) in a thread, until ready; yields its Node and
    sessions. Stopping it must end it with exit code 0."""
    nodes: list[Node] = []
    serve: Run = run or module.run

    class Recorded(Node):
        def __init__(self, *args: Any, **kw: Any) -> None:
            super().__init__(*args, **kw)
            nodes.append(self)

    monkeypatch.setattr(module, "Node", Recorded)
    with sessions(monkeypatch, NODE_SESSION, *opens) as opened:
        stop, errors, codes = threading.Event(), [], []

        def target() -> None:
            try:
                codes.append(serve(config, stop))
            except BaseException as exc:  # handed to the test below
                errors.append(exc)

        thread = threading.Thread(target=target, name=f"fuzz-{module.__name__}", daemon=True)
        thread.start()
        wait_until(
            lambda: errors or (nodes and any("/health/" in t for t in opened[0].tokens)), "ready"
        )
        assert not errors, errors
        try:
            yield nodes[0], opened
        finally:
            stop.set()
            thread.join(timeout=10)
        assert not errors, errors
        assert codes == [0], f"{module.__name__} exited with {codes}"


def rejected_by(decode: Callable[[bytes], Any], payload: bytes) -> bool:
    try:
        decode(payload)
    except DecodeError:
        return True
    return False


def fuzz_handler(
    node: Node,
    handler: Callable[[Any], None],
    key: str,
    decode: Callable[[bytes], Any],
    strategy: Any,
    examples: int = EXAMPLES,
) -> int:
    """Feed ``handler`` payloads: ``bad_input`` grows by one exactly for each that ``decode``
    rejects; an exception escaping the handler fails the test. Returns how many it was fed."""
    counts = {"rejected": 0, "taken": 0}

    @fuzz(examples)
    @given(payload=strategy)
    def check(payload: bytes) -> None:
        before = node.counters.get("bad_input")
        handler(FakeSample(key, payload))
        rejected = rejected_by(decode, payload)
        assert node.counters.get("bad_input") - before == int(rejected), key
        counts["rejected" if rejected else "taken"] += 1

    check()
    assert counts["rejected"] > 0, f"{key}: no payload was rejected: {counts}"
    return counts["rejected"] + counts["taken"]


def message_handler(
    node: Node, session: RecordingSession, part: str, cls: type[Message], examples: int = EXAMPLES
) -> int:
    """Fuzz every subscription whose key contains ``part`` with ``cls``'s payloads."""
    found = session.handlers_of(part)
    assert found, f"no subscription on {part!r}"
    return sum(
        fuzz_handler(node, h, key, cls.decode, message_payloads(cls, fresh=True), examples)
        for key, h in found
    )
