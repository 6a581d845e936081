"""The shared file helpers (hashing, atomic writes) and the one-line error text."""

from __future__ import annotations

import hashlib
from pathlib import Path

from common.errors import ONE_LINE_MAX_CHARS, one_line
from common.files import atomic_write_bytes, sha256_file


def test_sha256_file_matches_hashlib(tmp_path: Path) -> None:
    blob = tmp_path / "blob"
    blob.write_bytes(bytes(range(256)) * 5000)
    assert sha256_file(blob, chunk=4096) == hashlib.sha256(blob.read_bytes()).hexdigest()


def test_atomic_write_replaces_the_file_and_leaves_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "state.json"
    target.write_bytes(b"old")
    atomic_write_bytes(target, b"new")
    assert target.read_bytes() == b"new"
    assert [p.name for p in tmp_path.iterdir()] == ["state.json"]


def test_one_line_folds_white_space_and_caps_the_length() -> None:
    assert one_line(ValueError("bad\n  thing\there")) == "bad thing here"
    long = one_line(RuntimeError("x" * 500))
    assert len(long) == ONE_LINE_MAX_CHARS and long.endswith("...")
    assert one_line(RuntimeError("y" * ONE_LINE_MAX_CHARS)) == "y" * ONE_LINE_MAX_CHARS
