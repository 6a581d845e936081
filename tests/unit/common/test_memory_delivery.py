"""The in-memory bus's threaded delivery (common/memory_delivery.py): every subscription's
samples in order, the subscriptions interleaved in an order a seed shuffles, several at once,
and ``drain()`` as the one way a test waits for them."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest

from common.bus import QoS, Sample
from common.memory_bus import MemoryHub

LANES = 8
PER_LANE = 20


@pytest.fixture
def hub() -> Iterator[MemoryHub]:
    hub = MemoryHub(threads=3, seed=5)
    yield hub
    hub.close()


def _order(seed: int) -> list[str]:
    """The order in which one delivery thread handles a sample put on each of LANES keys
    (one subscription each), all put before any is handled."""
    hub = MemoryHub(threads=1, seed=seed)
    heard: list[str] = []
    entered, gate = threading.Event(), threading.Event()

    def hold(_: Sample) -> None:  # holds the one thread until every sample is put
        entered.set()
        gate.wait(10)

    bus = hub.join("b")
    bus.subscribe("gate", hold)
    for n in range(LANES):
        bus.subscribe(f"k/{n}", lambda s: heard.append(s.key))
    pub = hub.join("a")
    pub.publisher("gate", QoS.SENSOR).put(b"")
    assert entered.wait(10)
    for n in range(LANES):
        pub.publisher(f"k/{n}", QoS.SENSOR).put(b"")
    gate.set()
    hub.drain()
    hub.close()
    return heard


def test_delivery_is_on_other_threads_each_subscription_in_order(hub: MemoryHub) -> None:
    heard: dict[int, list[int]] = {n: [] for n in range(LANES)}
    threads: set[str] = set()

    def on(lane: int, sample: Sample) -> None:
        threads.add(threading.current_thread().name)
        heard[lane].append(int(sample.payload))

    bus = hub.join("b")
    for n in range(LANES):
        bus.subscribe(f"k/{n}", lambda s, n=n: on(n, s))
    pubs = [hub.join("a").publisher(f"k/{n}", QoS.SENSOR) for n in range(LANES)]
    for i in range(PER_LANE):
        for pub in pubs:
            pub.put(str(i).encode())
    hub.drain()
    assert heard == {n: list(range(PER_LANE)) for n in range(LANES)}
    assert threading.current_thread().name not in threads


def test_the_subscriptions_interleave_in_an_order_the_seed_draws() -> None:
    orders = {tuple(_order(seed)) for seed in range(6)}
    assert all(sorted(o) == sorted(f"k/{n}" for n in range(LANES)) for o in orders)
    assert len(orders) > 1, "every seed gave the same order"
    assert _order(3) == _order(3)  # one thread: a seed is one order


def test_two_subscriptions_are_handled_at_once(hub: MemoryHub) -> None:
    met = threading.Barrier(2, timeout=10)
    bus = hub.join("b")
    bus.subscribe("x", lambda _: met.wait())
    bus.subscribe("y", lambda _: met.wait())
    pub = hub.join("a")
    pub.publisher("x", QoS.SENSOR).put(b"")
    pub.publisher("y", QoS.SENSOR).put(b"")
    hub.drain()  # a BrokenBarrierError here: the two never ran together


def test_token_events_and_history_come_on_the_watchs_thread_in_order(hub: MemoryHub) -> None:
    events: list[tuple[str, bool]] = []
    a, b = hub.join("a"), hub.join("b")
    first = a.declare_token("t/1")
    b.watch_tokens("t/*", lambda key, alive: events.append((key, alive)))
    second = a.declare_token("t/2")
    first.undeclare()
    second.undeclare()
    hub.drain()
    assert events == [("t/1", True), ("t/2", True), ("t/1", False), ("t/2", False)]


def test_what_a_handler_puts_is_drained_too_and_its_error_raised_there(hub: MemoryHub) -> None:
    heard: list[bytes] = []
    relay = hub.join("relay")
    out = relay.publisher("out", QoS.SENSOR)
    relay.subscribe("in", lambda s: out.put(s.payload + b"!"))
    hub.join("c").subscribe("out", lambda s: heard.append(s.payload))
    hub.join("a").publisher("in", QoS.SENSOR).put(b"hi")
    hub.drain()
    assert heard == [b"hi!"]

    def bad(_: Sample) -> None:
        raise ValueError("a handler's bug")

    relay.subscribe("bad", bad)
    hub.join("a").publisher("bad", QoS.SENSOR).put(b"")
    with pytest.raises(ValueError, match="a handler's bug"):
        hub.drain()
    hub.drain()  # raised once


def test_a_drain_from_a_handler_is_refused(hub: MemoryHub) -> None:
    refused: list[Exception] = []

    def drains(_: Sample) -> None:
        try:
            hub.drain()
        except RuntimeError as exc:
            refused.append(exc)

    hub.join("b").subscribe("x", drains)
    hub.join("a").publisher("x", QoS.SENSOR).put(b"")
    hub.drain()
    assert len(refused) == 1 and "wait for itself" in str(refused[0])


def test_an_undeclared_subscription_hears_nothing_still_queued() -> None:
    hub = MemoryHub(threads=1, seed=0)
    entered, gate = threading.Event(), threading.Event()
    heard: list[bytes] = []

    def hold(_: Sample) -> None:
        entered.set()
        gate.wait(10)

    b, a = hub.join("b"), hub.join("a")
    b.subscribe("gate", hold)
    sub = b.subscribe("x", lambda s: heard.append(s.payload))
    a.publisher("gate", QoS.SENSOR).put(b"")
    assert entered.wait(10)  # the one thread is held
    a.publisher("x", QoS.SENSOR).put(b"late")  # queued behind the gate's handler
    sub.undeclare()
    gate.set()
    hub.drain()
    hub.close()
    assert heard == []
