"""The local e-stop socket (common/estop_local.py) with real Unix sockets: an engage arrives
with its reason, anything else is reported as bad, sending never blocks (no listener, a stale
socket, a listener whose queue is full), a long path still works, and the socket is the
owner's alone and removed on close."""

from __future__ import annotations

import socket
import stat
import threading
import time
from pathlib import Path

import pytest

from common.estop_local import ENGAGE, LocalEStop, engage_locally, socket_path

WAIT_S = 10.0


class Heard:
    def __init__(self) -> None:
        self.engages: list[str] = []
        self.bad: list[str] = []
        self.failed: list[str] = []
        self.news = threading.Event()

    def engage(self, reason: str) -> None:
        self.engages.append(reason)
        self.news.set()

    def garbage(self, why: str) -> None:
        self.bad.append(why)
        self.news.set()

    def listen(self, path: Path) -> LocalEStop:
        return LocalEStop(path, self.engage, self.garbage, self.failed.append)

    def wait(self) -> None:
        assert self.news.wait(WAIT_S), "nothing arrived"
        self.news.clear()


def test_an_engage_arrives_with_its_reason_and_the_socket_is_the_owners(tmp_path: Path) -> None:
    path = socket_path(tmp_path / "estop.json")
    assert path == tmp_path / "estop.json.sock"
    heard = Heard()
    local = heard.listen(path)
    try:
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
        assert engage_locally(path, "operator: ramp ahead") == ""
        heard.wait()
        assert heard.engages == ["operator: ramp ahead"] and heard.bad == []
    finally:
        local.close()
    assert not path.exists()  # removed on close
    assert heard.failed == []


def test_anything_but_an_engage_is_bad(tmp_path: Path) -> None:
    path = tmp_path / "e.sock"
    heard = Heard()
    local = heard.listen(path)
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as raw:
            raw.sendto(b"zstack-estop release\n", str(path))
            heard.wait()
            raw.sendto(ENGAGE + b"x" * 1000, str(path))  # too long to be one
            heard.wait()
        assert heard.engages == [] and len(heard.bad) == 2, heard.bad
    finally:
        local.close()


def test_sending_never_blocks_and_says_why_not(tmp_path: Path) -> None:
    path = tmp_path / "e.sock"
    assert "No such file" in engage_locally(path, "")
    # A listener that reads nothing: its queue fills, and a send then fails at once.
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as deaf:
        deaf.bind(str(path))
        started = time.monotonic()
        results = [engage_locally(path, "r" * 400) for _ in range(2000)]
        assert time.monotonic() - started < 30  # each returned at once (no wait per send)
        assert results[0] == "" and results[-1] != "", results[-1]
    # A stale socket (its listener gone): refused at once.
    assert engage_locally(path, "") != ""


def test_a_long_path_and_a_stale_socket(tmp_path: Path) -> None:
    deep = tmp_path / ("d" * 60) / ("e" * 60)
    deep.mkdir(parents=True)
    path = socket_path(deep / "estop.json")
    assert len(str(path)) > 107  # too long for a socket address of its own
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as crashed:  # left behind
        folder = f"/proc/self/fd/{__import__('os').open(deep, 0)}"
        crashed.bind(f"{folder}/{path.name}")
    assert path.is_socket()
    heard = Heard()
    local = heard.listen(path)  # replaces it
    try:
        assert engage_locally(path, "deep") == ""
        heard.wait()
        assert heard.engages == ["deep"]
    finally:
        local.close()
    assert not path.exists()


def test_a_newer_listeners_socket_is_not_removed(tmp_path: Path) -> None:
    path = tmp_path / "e.sock"
    old = Heard().listen(path)
    newer = Heard()
    new = newer.listen(path)  # a restarted controller took the path over
    old.close()
    try:
        assert path.is_socket()
        assert engage_locally(path, "still") == ""
        newer.wait()
        assert newer.engages == ["still"]
    finally:
        new.close()


def test_a_folder_it_cannot_bind_in_is_an_oserror(tmp_path: Path) -> None:
    with pytest.raises(OSError):
        Heard().listen(tmp_path / "missing" / "e.sock")
