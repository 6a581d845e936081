"""The bus protocol's contract (common/bus.py), checked on both implementations: two Zenoh
sessions linked over loopback, and two participants of a MemoryHub, delivering in the putting
thread or on threads of its own. What the in-process tests rely on the in-memory bus for is
what Zenoh does; where Zenoh takes time, the check waits for it (the memory bus has it done
before the call returns, or once ``drain()`` returns)."""

from __future__ import annotations

import json
import socket
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest
import zenoh

from common.bus import Bus, QoS, Sample
from common.memory_bus import MemoryHub, intersects
from common.zenoh_bus import ZenohBus
from tests.polling import wait_for


@dataclass
class Pair:
    a: Bus
    b: Bus
    eventually: Callable[[Callable[[], bool]], bool]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _session(listen: list[str], connect: list[str]) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", json.dumps(listen))
    conf.insert_json5("connect/endpoints", json.dumps(connect))
    return zenoh.open(conf)


def _poll(check: Callable[[], bool]) -> bool:
    return bool(wait_for(check, 10.0, "the Zenoh sessions to agree", poll=0.02))


@pytest.fixture(params=["memory", "memory-threaded", "zenoh"])
def pair(request: pytest.FixtureRequest) -> Iterator[Pair]:
    if request.param.startswith("memory"):
        hub = MemoryHub(threads=3 if request.param == "memory-threaded" else 0, seed=1)

        def drained(check: Callable[[], bool]) -> bool:
            """``check()`` once what was put has been handled: a check that puts (and then
            looks at what was heard) is asked twice, the second time after its put's drain."""
            hub.drain()
            if check():
                return True
            hub.drain()
            return check()

        a, b = hub.join("a"), hub.join("b")
        yield Pair(a, b, drained)
        b.close()
        a.close()
        hub.close()
        return
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    za = ZenohBus(_session([endpoint], []))
    zb = ZenohBus(_session([], [endpoint]))
    try:
        # Linked once b sees a's token.
        probe = za.declare_token("contract/link")
        _poll(lambda: bool(zb.live_tokens("contract/link", 1.0)))
        probe.undeclare()
        yield Pair(za, zb, _poll)
    finally:
        zb.close()
        za.close()


def _until_heard(pair: Pair, put: Callable[[], bool], *heard: list[Sample]) -> None:
    """Put until every list heard something: on Zenoh a subscription just declared reaches the
    other session a moment later, and a put before that goes to nobody."""
    assert pair.eventually(lambda: put() and all(heard)), "never heard"


def test_a_put_reaches_every_matching_subscriber_with_its_source(pair: Pair) -> None:
    got: list[Sample] = []
    wild: list[Sample] = []
    pair.b.subscribe("r/camera/front/frame", got.append)
    pair.b.subscribe("r/camera/*/frame", wild.append)
    pub = pair.a.publisher("r/camera/front/frame", QoS.SENSOR)
    _until_heard(pair, lambda: pub.put(b"one"), got, wild)
    assert got[0].key == "r/camera/front/frame" and got[0].payload == b"one"
    assert got[0].source != "unidentified" and got[0].source == wild[0].source


def test_a_payload_over_the_limit_is_refused(pair: Pair) -> None:
    refused: list[tuple[str, int]] = []
    got: list[Sample] = []
    pair.b.subscribe("r/frame", got.append)
    pub = pair.a.publisher(
        "r/frame", QoS.SENSOR, max_payload_bytes=4, on_refused=lambda k, n: refused.append((k, n))
    )
    assert not pub.put(b"12345")
    _until_heard(pair, lambda: pub.put(b"1234"), got)
    assert refused == [("r/frame", 5)] and {s.payload for s in got} == {b"1234"}


def test_an_undeclared_subscription_hears_nothing_more(pair: Pair) -> None:
    got: list[Sample] = []
    sub = pair.b.subscribe("r/x", got.append)
    pub = pair.a.publisher("r/x", QoS.CONTROL)
    _until_heard(pair, lambda: pub.put(b"1"), got)
    sub.undeclare()
    pub.put(b"2")
    later: list[Sample] = []
    pair.b.subscribe("r/x", later.append)
    # Zenoh may hand a new subscription what was still on its way when it was declared: wait
    # for the "3" itself.
    assert pair.eventually(lambda: pub.put(b"3") and b"3" in {s.payload for s in later})
    assert {s.payload for s in got} == {b"1"}


def test_tokens_are_watched_with_their_history_and_go_with_their_owner(pair: Pair) -> None:
    events: list[tuple[str, bool]] = []
    early = pair.a.declare_token("r/pool/w1")
    pair.b.watch_tokens("r/pool/*", lambda key, alive: events.append((key, alive)))
    assert pair.eventually(lambda: ("r/pool/w1", True) in events)
    late = pair.a.declare_token("r/pool/w2")
    assert pair.eventually(lambda: ("r/pool/w2", True) in events)
    assert sorted(pair.b.live_tokens("r/pool/*", 2.0)) == ["r/pool/w1", "r/pool/w2"]
    late.undeclare()
    assert pair.eventually(lambda: ("r/pool/w2", False) in events)
    assert pair.b.live_tokens("r/pool/*", 2.0) == ["r/pool/w1"]
    pair.a.close()  # a's process ends: its token goes with it
    assert pair.eventually(lambda: ("r/pool/w1", False) in events)
    del early


def test_a_query_gets_the_queryables_answer(pair: Pair) -> None:
    asked: list[str] = []

    def answer(key: str, payload: bytes) -> bytes:
        asked.append(key)
        return b'{"ok": true}'

    pair.a.serve("r/metrics", answer)
    replies: list[bytes] = []
    assert pair.eventually(
        lambda: bool(replies.extend(r.payload for r in pair.b.query("r/metrics", 2.0)) or replies)
    )
    assert replies[0] == b'{"ok": true}' and asked[0] == "r/metrics"
    assert pair.b.query("r/nobody", 0.5) == []


def test_a_participant_knows_it_is_linked(pair: Pair) -> None:
    assert pair.a.linked(2.0) and pair.b.linked(2.0)


def test_a_lone_zenoh_session_is_not_linked() -> None:
    alone = ZenohBus(_session([], []))
    try:
        assert not alone.linked(0.2)
    finally:
        alone.close()


def test_key_expressions_meet_as_zenohs_do() -> None:
    assert intersects("a/*/c", "a/b/c")
    assert not intersects("a/*/c", "a/b/d/c")
    assert intersects("a/**", "a")
    assert intersects("a/**/c", "a/b/d/c")
    assert intersects("**", "x/y")
    assert not intersects("a/*", "a")
    assert not intersects("a/b", "a/c")
