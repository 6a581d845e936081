"""Fixtures shared by every test package."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def default_model() -> Path:
    """The default COCO model, fetched and converted if needed (``make test`` does it first).

    A machine that cannot fetch it fails here with the fetch error: the real-model tests must
    run, never be skipped quietly.
    """
    from modelprep.files import ensure_default_model

    return ensure_default_model()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The longest tests first: the closed-loop scenarios, then the other real-process tests,
    then the unit tests. With two workers (make test) the short ones then fill in at the end,
    and no long test starts last and runs alone."""

    def rank(item: pytest.Item) -> int:
        path = item.nodeid
        if path.startswith("tests/integration/test_scenarios.py"):
            return 0
        return 1 if path.startswith("tests/integration/") else 2

    items.sort(key=rank)  # stable: within a rank, the collection's order
