"""common.files.temporary_folder leaves nothing behind, however soon an interrupt lands: here
one raised the moment the folder exists, before the call that made it returned (a stop signal
whose Python handler ran inside tempfile.mkdtemp once left '.tfjs-<random>' in the models
folder: tests/integration/test_interrupt_fetch.py under load)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from common import files
from common.files import temporary_folder


def test_an_interrupt_right_after_the_folder_is_made_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real_mkdir = os.mkdir

    def mkdir_then_interrupted(path: Path, mode: int = 0o777) -> None:
        real_mkdir(path, mode)
        raise KeyboardInterrupt

    monkeypatch.setattr(files.os, "mkdir", mkdir_then_interrupted)
    with pytest.raises(KeyboardInterrupt), temporary_folder(tmp_path, ".work-"):
        pass
    assert list(tmp_path.iterdir()) == []


def test_the_folder_is_private_and_gone_after_its_work(tmp_path: Path) -> None:
    with temporary_folder(tmp_path, ".work-") as work:
        assert work.parent == tmp_path and work.name.startswith(".work-")
        assert (work.stat().st_mode & 0o777) == 0o700
        (work / "partial").write_bytes(b"x")
    assert list(tmp_path.iterdir()) == []
