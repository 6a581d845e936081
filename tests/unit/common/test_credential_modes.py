"""The start-up check of the credentials' modes (common/credential_modes.py), as ssh checks a
private key: by mode bits, which hold for root too."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.credential_modes import (
    check_credentials_folder,
    check_folder,
    check_public,
    check_secret,
    is_secret,
)
from common.errors import ConfigError


def _file(tmp_path: Path, name: str, mode: int) -> Path:
    path = tmp_path / name
    path.write_text("x\n")
    path.chmod(mode)
    return path


@pytest.mark.parametrize("mode", [0o700, 0o750, 0o755, 0o711])
def test_a_folder_only_its_owner_may_write_is_accepted(tmp_path: Path, mode: int) -> None:
    tmp_path.chmod(mode)
    check_folder(tmp_path)


@pytest.mark.parametrize(
    "mode, who", [(0o777, "its group and others"), (0o770, "its group"), (0o703, "others")]
)
def test_a_folder_others_may_write_is_refused_with_the_fix(
    tmp_path: Path, mode: int, who: str
) -> None:
    folder = tmp_path / "creds"
    folder.mkdir()
    folder.chmod(mode)
    with pytest.raises(ConfigError) as err:
        check_folder(folder)
    assert str(err.value) == (
        f"the credentials folder {folder} (mode {mode:04o}) may be changed by {who}: "
        f"fix it with `chmod 700 {folder}` (docs/security.md)"
    )


@pytest.mark.parametrize("mode", [0o600, 0o400, 0o640])  # a group may read, to share it
def test_a_secret_only_its_owner_may_change_and_others_not_read_is_accepted(
    tmp_path: Path, mode: int
) -> None:
    check_secret(_file(tmp_path, "camera.password", mode))


@pytest.mark.parametrize(
    "mode, verb",
    [(0o644, "read by others"), (0o620, "changed by its group"),
     (0o666, "read and changed by its group and others"), (0o602, "changed by others")],
)  # fmt: skip
def test_a_secret_others_may_read_or_change_is_refused_with_the_fix(
    tmp_path: Path, mode: int, verb: str
) -> None:
    path = _file(tmp_path, "camera.key", mode)
    with pytest.raises(ConfigError) as err:
        check_secret(path)
    assert str(err.value) == (
        f"the secret {path} (mode {mode:04o}) may be {verb}: "
        f"fix it with `chmod 600 {path}` (docs/security.md)"
    )


def test_a_certificate_is_public_but_nobody_else_may_change_it(tmp_path: Path) -> None:
    check_public(_file(tmp_path, "ca.pem", 0o644))
    with pytest.raises(ConfigError, match=r"ca\.pem \(mode 0664\) may be changed by its group: "
                                          r"fix it with `chmod 644 "):  # fmt: skip
        check_public(_file(tmp_path, "ca.pem", 0o664))


def test_a_path_with_a_space_is_quoted_in_the_fix(tmp_path: Path) -> None:
    folder = tmp_path / "my creds"
    folder.mkdir()
    path = _file(folder, "users.txt", 0o644)
    with pytest.raises(ConfigError, match=f"`chmod 600 '{path}'`"):
        check_secret(path)


def test_what_counts_as_a_secret(tmp_path: Path) -> None:
    kinds = {
        name: is_secret(tmp_path / name)
        for name in ("users.txt", "viewer-token", "ca.key", "camera_rear.key",
                     "detector_2.password", "ca.pem", "supervisor.pem", "README", "notes.md")
    }  # fmt: skip
    assert kinds == {
        "users.txt": True, "viewer-token": True, "ca.key": True, "camera_rear.key": True,
        "detector_2.password": True, "ca.pem": False, "supervisor.pem": False,
        "README": None, "notes.md": None,
    }  # fmt: skip


def test_the_folder_check_names_the_first_bad_file_and_ignores_other_files(
    tmp_path: Path,
) -> None:
    tmp_path.chmod(0o700)
    _file(tmp_path, "README", 0o666)  # not a credential: none of the check's business
    _file(tmp_path, "ca.pem", 0o644)
    _file(tmp_path, "camera.password", 0o600)
    check_credentials_folder(tmp_path)
    bad = _file(tmp_path, "viewer-token", 0o604)
    _file(tmp_path, "users.txt", 0o600)
    with pytest.raises(ConfigError, match=f"the secret {bad} .*`chmod 600 {bad}`"):
        check_credentials_folder(tmp_path)
    check_credentials_folder(tmp_path / "missing")  # said where the files are read


def test_a_missing_file_is_left_to_its_reader(tmp_path: Path) -> None:
    check_secret(tmp_path / "nope.password")
    check_folder(tmp_path / "nope")
