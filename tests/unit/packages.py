"""The repository's production packages, found, not listed: every top-level folder with an
``__init__.py`` but ``tests``. The rules that walk the code (no clock read but through
common/clock.py, no child started but through common/spawn.py, every StackError drawn) walk
these, so that a new package is never left out of them."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = tuple(
    sorted(p.name for p in ROOT.iterdir() if (p / "__init__.py").is_file() and p.name != "tests")
)
