"""One supervisor per stack: an exclusive lock on a file named after the endpoint and prefix.

The kernel drops a ``flock`` when its holder dies, however it dies, so a lock is never stale.
The file holds the holder's PID so that a second supervisor can say who runs the stack.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
from pathlib import Path
from typing import IO

from common.errors import ConfigError
from common.files import temp_root


def lock_path(lock_dir: str, endpoint: str, prefix: str) -> Path:
    """The stack's lock file: in ``lock_dir`` (``supervisor.lock_dir``) when set, else in the
    temporary folder (``$TMPDIR``, else ``/tmp``: common/files.py ``temp_root``)."""
    digest = hashlib.sha256(f"{endpoint}\n{prefix}".encode()).hexdigest()[:16]
    folder = Path(lock_dir) if lock_dir else temp_root()
    return folder / f"zenoh-yolo-stack-{digest}.lock"


def acquire(lock_dir: str, endpoint: str, prefix: str) -> IO[str]:
    """Hold the stack's lock until the returned file is closed (or the process ends)."""
    path = lock_path(lock_dir, endpoint, prefix)
    try:
        f = path.open("a+", encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot open the supervisor lock {path}: {exc}") from exc
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        f.seek(0)
        holder = f.read().strip() or "unknown"
        f.close()
        raise ConfigError(
            f"a supervisor (pid {holder}) already runs the stack on {endpoint} with prefix "
            f"{prefix!r}; stop it first (lock {path})"
        ) from None
    f.seek(0)
    f.truncate()
    f.write(f"{os.getpid()}\n")
    f.flush()
    return f
