"""The bridge's ROS 2 graph closes whatever happens at a stop (rosmsg/graph.py), on a real
Zenoh session hosting the graph's router: a publisher used by a callback still running while
the bridge stops, and an undeclare that fails, once left the session open, its callbacks
putting onto the closed stack and the process stuck until the supervisor killed it."""

from __future__ import annotations

import threading
from dataclasses import replace

import pytest

from rosmsg.convert import TWIST
from rosmsg.graph import RosGraph
from services.ros2.contract import Ros2Settings
from tools.launch import free_port


def hosted() -> RosGraph:
    settings = replace(Ros2Settings(), router=(f"tcp/127.0.0.1:{free_port()}",))
    return RosGraph(settings, host=True)


def test_a_failing_undeclare_still_closes_the_others_and_the_session(
    caplog: pytest.LogCaptureFixture,
) -> None:
    graph = hosted()
    pub = graph.publisher("/cmd_vel", TWIST)
    closed: list[str] = []
    graph.on_close(lambda: closed.append("first"))

    def fails() -> None:
        raise RuntimeError("Already borrowed")

    graph.on_close(fails)
    graph.close()
    assert closed == ["first"]
    assert graph.session.is_closed()
    assert "an undeclare failed" in caplog.text
    pub.put_cdr(b"\x00\x01\x00\x00")  # after the close: dropped, not raised


def test_puts_from_other_threads_never_meet_the_close() -> None:
    graph = hosted()
    pub = graph.publisher("/cmd_vel", TWIST)
    stop = threading.Event()
    errors: list[BaseException] = []

    def keep_putting() -> None:
        while not stop.is_set():
            try:
                pub.put_cdr(b"\x00\x01\x00\x00" + bytes(48))
            except BaseException as exc:  # the test reports any
                errors.append(exc)
                return

    putters = [threading.Thread(target=keep_putting) for _ in range(3)]
    for t in putters:
        t.start()
    graph.close()
    stop.set()
    for t in putters:
        t.join(timeout=10)
    assert errors == [] and graph.session.is_closed()
