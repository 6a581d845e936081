"""Who else may read or change the credentials: checked at start-up, as ssh checks a private key.

A credentials folder that its group or others may write lets them replace a key, a certificate
or the router's user dictionary; a password, key, dictionary or viewer token that others may
read gives away a principal. Either makes a secure stack no more secure than an open one, so
the supervisor and every process that reads a secret refuse it with one line that names the
file and the ``chmod`` that fixes it (ConfigError, exit code 2).

The rules, by mode bits alone (they hold for root too, who reads any file whatever its mode):

- the folder and each subfolder (a robot's): no write for group or others (``zstack
  credentials`` makes them 0700);
- a secret (``*.password``, ``*.key``, ``users.txt``, ``viewer-token``): no write for group or
  others, no read for others (made 0600; a group may read, to share it with a service's group);
- a certificate (``*.pem``): no write for group or others (made 0644: it is public).

A mode is read through links (``os.stat``), as the file is read.
"""

from __future__ import annotations

import os
import shlex
import stat
from pathlib import Path

from common.errors import ConfigError
from common.security import cert_file, key_file, password_file, users_file, viewer_token_file

GROUP_OTHERS_WRITE = stat.S_IWGRP | stat.S_IWOTH
OTHERS_READ = stat.S_IROTH
FOLDER_MODE = 0o700  # what the fix sets, as `zstack credentials` does
SECRET_MODE = 0o600
PUBLIC_MODE = 0o644


def _mode(path: Path) -> int | None:
    """The permission bits of ``path``, or None when there is nothing to check (a missing file
    is said by whoever reads it, with its own fix)."""
    try:
        return stat.S_IMODE(os.stat(path).st_mode)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise ConfigError(f"cannot check the mode of {path}: {exc.strerror}") from exc


def _check(path: Path, forbidden: int, what: str, fix: int) -> None:
    mode = _mode(path)
    if mode is None or not mode & forbidden:
        return
    bad = mode & forbidden
    whom = " and ".join(w for w, bits in (("its group", 0o070), ("others", 0o007)) if bad & bits)
    writes, reads = bad & GROUP_OTHERS_WRITE, bad & OTHERS_READ
    verb = "read and changed" if writes and reads else "changed" if writes else "read"
    raise ConfigError(
        f"{what} {path} (mode {mode:04o}) may be {verb} by {whom}: fix it with "
        f"`chmod {fix:o} {shlex.quote(str(path))}` (docs/security.md)"
    )


def check_folder(directory: Path) -> None:
    """ConfigError, one line, if group or others may write the credentials folder."""
    _check(directory, GROUP_OTHERS_WRITE, "the credentials folder", FOLDER_MODE)


def check_secret(path: Path) -> None:
    """ConfigError, one line, if group or others may change ``path`` or others may read it."""
    _check(path, GROUP_OTHERS_WRITE | OTHERS_READ, "the secret", SECRET_MODE)


def check_public(path: Path) -> None:
    """ConfigError, one line, if group or others may change the certificate ``path``."""
    _check(path, GROUP_OTHERS_WRITE, "the certificate", PUBLIC_MODE)


def is_secret(path: Path) -> bool | None:
    """Whether a file of a credentials folder is a secret (True), a certificate (False) or
    neither (None: not a file the stack reads)."""
    d = path.parent
    if path.name in (users_file(d).name, viewer_token_file(d).name):
        return True
    if path.suffix in (password_file(d, "x").suffix, key_file(d, "x").suffix):
        return True
    if path.suffix == cert_file(d, "x").suffix:
        return False
    return None


def check_credentials_folder(directory: Path) -> None:
    """The folder, its subfolders (one per robot prefix, common/security.py) and every
    credential file in them, in name order: what the supervisor checks before it starts a
    secure stack (each process checks the files it reads too)."""
    check_folder(directory)
    if not directory.is_dir():
        return  # missing: said, with its fix, where the files are read
    for path in sorted(directory.iterdir()):
        if path.is_dir():
            check_credentials_folder(path)
            continue
        secret = is_secret(path)
        if secret is True:
            check_secret(path)
        elif secret is False:
            check_public(path)
