"""A pool worker whose detection loop stalls while Zenoh's threads keep its session alive (a
stuck inference, a deadlock) leaves the pool after ``detector.pool_stall_s``: its pool token
goes, so the other workers take its cameras at once instead of after the watchdog's restart;
its next loop pass declares the token again and it serves its share again. Alone in the pool
it stays (nobody could take over).

The worker's bus side (``services/detector/service.py::PoolMember``) runs here in the test's
process on a real Zenoh session, against the supervisor's router, so that the test decides
when the "loop" passes: not passing is the stall. The hand-over that follows a token's loss
is the pool's own and is tested with real workers in test_pool.py.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable

import pytest

from common.node import Node
from services.detector.service import DetectorHandlers, PoolMember
from tests.integration.conftest import Stack, wait_for

pytestmark = pytest.mark.integration

STALL_S = 1.0  # detector.pool_stall_s here: the smallest allowed, so the test is short
NOTICE_S = 10.0  # the resignation seen by another session, on a loaded machine
LOOP_S = 0.2  # an idle detection loop's pass (services/detector/service.py::_WAIT_S)


def _members(stack: Stack) -> set[str]:
    """The pool ids whose tokens another session sees now."""
    replies = stack.session.liveliness().get(stack.keys.all_pool_members(), timeout=2.0)
    return {str(r.ok.key_expr).rsplit("/", 1)[-1] for r in replies if r.ok is not None}


def test_a_stalled_worker_leaves_the_pool_and_comes_back(
    make_stack: Callable[..., Stack],
) -> None:
    stack = make_stack(
        supervisor={"services": ["metrics"]},  # the router, and nothing that takes frames
        **{"cameras.rear": {"frame_id": "rear"}},
    )
    stack.wait_ready({"metrics"})
    config = dataclasses.replace(
        stack.config, detector=dataclasses.replace(stack.config.detector, pool_stall_s=STALL_S)
    )
    # Another worker, as far as the pool can tell: its token, declared by the test's session.
    other = stack.session.liveliness().declare_token(stack.keys.pool_member("detector_2"))
    wait_for(lambda: _members(stack) == {"detector_2"}, NOTICE_S, "the other worker's token")
    with Node("detector", config) as node:
        handlers = DetectorHandlers(config, node)
        pool = PoolMember(node, "detector", handlers)
        try:
            pool.join()

            def loop_pass() -> frozenset[str]:
                pool.beat()
                pool.settle()
                return handlers.serving

            # Two equal cameras, two workers: one each (a member the join's query missed
            # arrives on the liveliness subscription, and the next pass settles it).
            wait_for(lambda: len(loop_pass()) == 1, NOTICE_S, "a share of one camera")
            share = handlers.serving
            wait_for(lambda: _members(stack) == {"detector", "detector_2"}, NOTICE_S, "both tokens")
            # The loop passes, every 0.2 s as an idle detector's does: the worker stays for
            # well over pool_stall_s.
            pace = threading.Event()  # never set: wait() paces the passes
            for _ in range(round(3 * STALL_S / LOOP_S)):
                pool.beat()
                pool.settle()
                pace.wait(LOOP_S)
            assert node_counter(node, "pool_resigned") == 0
            # The loop stops passing (stuck): the worker resigns and refuses frames.
            wait_for(
                lambda: _members(stack) == {"detector_2"}, NOTICE_S + STALL_S, "its token to go"
            )
            assert node_counter(node, "pool_resigned") == 1
            assert handlers.serving == frozenset()
            # A settle() under way when the worker resigned (the pass stalled inside it)
            # applies a change computed before: it must not switch serving back on.
            with pool._lock:
                pool._dirty = True
            pool.settle()
            assert handlers.serving == frozenset(), "a resigned worker serves again"
            # The loop runs again: the token is back and the worker serves its share again.
            pool.beat()
            pool.settle()
            assert handlers.serving == share
            wait_for(
                lambda: _members(stack) == {"detector", "detector_2"}, NOTICE_S, "it to return"
            )
            # Alone in the pool, a stall hands nothing to nobody: the worker stays.
            other.undeclare()
            wait_for(lambda: loop_pass() == {"front", "rear"}, NOTICE_S, "every camera its own")
            # No beat for three times pool_stall_s: what is checked is that nothing happens.
            pace.wait(3 * STALL_S)
            assert node_counter(node, "pool_resigned") == 1
            assert _members(stack) == {"detector"}
        finally:
            pool.close()
    assert stack.stop() == 0


def node_counter(node: Node, name: str) -> int:
    return int(node.counters.get(name))
