from __future__ import annotations

import os
from pathlib import Path

import pytest

from common.errors import ConfigError
from deploy.lock import acquire, lock_path


def test_second_holder_is_refused_naming_the_first(tmp_path: Path) -> None:
    first = acquire(str(tmp_path), "tcp/127.0.0.1:7447", "stack")
    try:
        with pytest.raises(ConfigError, match=rf"pid {os.getpid()}\b.*already runs"):
            acquire(str(tmp_path), "tcp/127.0.0.1:7447", "stack")
        # Another prefix or endpoint is another stack.
        acquire(str(tmp_path), "tcp/127.0.0.1:7447", "other").close()
        acquire(str(tmp_path), "tcp/127.0.0.1:7448", "stack").close()
    finally:
        first.close()
    acquire(str(tmp_path), "tcp/127.0.0.1:7447", "stack").close()  # free again


def test_without_a_lock_dir_the_lock_goes_in_tmpdir(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    assert lock_path("", "tcp/127.0.0.1:7447", "stack").parent == tmp_path
    held = acquire("", "tcp/127.0.0.1:7447", "stack")
    try:
        assert [p.name for p in tmp_path.iterdir()] == [
            lock_path("", "tcp/127.0.0.1:7447", "stack").name
        ]
    finally:
        held.close()
    # supervisor.lock_dir, when set, wins over TMPDIR.
    mine = tmp_path / "locks"
    mine.mkdir()
    assert lock_path(str(mine), "tcp/127.0.0.1:7447", "stack").parent == mine


def test_a_tmpdir_that_is_no_folder_is_named_not_passed_over(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Python's tempfile falls back to /tmp without a word; the lock says what is wrong.
    monkeypatch.setenv("TMPDIR", str(tmp_path / "missing"))
    with pytest.raises(ConfigError, match=r"TMPDIR=.*missing is not a folder"):
        acquire("", "tcp/127.0.0.1:7447", "stack")
