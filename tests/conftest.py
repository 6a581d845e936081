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
