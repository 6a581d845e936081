"""File helpers shared by the model store and the engine cache: hashing and atomic writes."""

from __future__ import annotations

import hashlib
import os
import secrets
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from common.errors import ConfigError

_CHUNK_BYTES = 1 << 20

#: The signals a stop comes by (common/lifecycle.py takes both as Ctrl-C).
_TEMPORARY_TRIES = 100


def sha256_file(path: Path, chunk: int = _CHUNK_BYTES) -> str:
    """Hex sha256 of a file, read in chunks (models and engines run to hundreds of MB)."""
    digest = hashlib.sha256()
    with path.open("rb") as f:
        while block := f.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def atomic_write_bytes(path: Path, payload: bytes, *, durable: bool = False) -> None:
    """Write ``payload`` to ``path`` so that a reader sees the old file or the new one whole.

    The bytes go to a hidden temporary beside ``path`` (same file system, so the rename is
    atomic), named after this process so that two writers never share one. ``durable`` also
    syncs the file and its folder before returning, so that the new file survives a power cut
    (the e-stop's state must).
    """
    partial = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with partial.open("wb") as f:
            f.write(payload)
            if durable:
                f.flush()
                os.fsync(f.fileno())
        os.replace(partial, path)
    except BaseException:
        # A disk that refused the write (full, read-only) or a stop mid-write: no partial file
        # is left beside the old one.
        partial.unlink(missing_ok=True)
        raise
    if durable:
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)  # the rename itself
        finally:
            os.close(fd)


def temp_root() -> Path:
    """The folder the stack's and its tools' temporary files go in: ``$TMPDIR`` when it is set,
    else the system's (``tempfile.gettempdir()``: ``/tmp`` on Linux).

    A ``TMPDIR`` that is not a folder this process may write in is a ConfigError naming it:
    Python's ``tempfile`` would fall back to ``/tmp`` without a word, and a person who set it
    to keep a run's files (or a lock) elsewhere would not know they went there."""
    chosen = os.environ.get("TMPDIR", "")
    if not chosen:
        return Path(tempfile.gettempdir())
    path = Path(chosen)
    if not path.is_dir():
        raise ConfigError(f"TMPDIR={chosen} is not a folder: make it, or unset TMPDIR")
    if not os.access(path, os.W_OK | os.X_OK):
        raise ConfigError(f"TMPDIR={chosen} is not writable by this user: choose another")
    return path


@contextmanager
def temporary_folder(parent: Path, prefix: str) -> Iterator[Path]:
    """A fresh folder in ``parent`` for work that ends in an atomic rename, removed on the way
    out, whichever way that is. Unlike ``tempfile.TemporaryDirectory``, an interrupt (Ctrl-C,
    SIGTERM taken as one) that lands while the folder is being made cannot leave it behind:
    its name is chosen and held here before it is made, so the way out removes it however
    soon the interrupt lands (a stop signal that arrived just before Python's handler could
    otherwise run inside ``tempfile.mkdtemp``, after its mkdir and before it returned)."""
    path: Path | None = None
    try:
        for _ in range(_TEMPORARY_TRIES):
            path = parent / f"{prefix}{secrets.token_hex(8)}"
            try:
                os.mkdir(path, 0o700)
                break
            except FileExistsError:
                path = None  # another's (64 random bits: never in practice)
        else:
            raise FileExistsError(f"no free name for a temporary folder in {parent}")
        yield path
    finally:
        if path is not None:
            shutil.rmtree(path, ignore_errors=True)  # what is left of a second interrupt
