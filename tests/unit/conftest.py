"""Fixtures of the unit tests."""

from __future__ import annotations

import os

import pytest

#: The delivery threads' order is drawn from this seed (common/memory_delivery.py): another
#: seed, another interleaving (MEMORY_BUS_SEED=7 make unit, to look for more).
MEMORY_BUS_SEED = int(os.environ.get("MEMORY_BUS_SEED", "0"))


@pytest.fixture(params=[0, 3], ids=["inline", "threaded"])
def delivery_threads(request: pytest.FixtureRequest) -> int:
    """The in-memory bus's delivery threads (common/memory_bus.py): 0, in the putting thread;
    3, on threads of the hub's own, in a shuffled order. A test that takes it runs under
    both, and waits for what it put with ``hub.drain()``."""
    return int(request.param)
