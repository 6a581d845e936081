"""The local e-stop: a Unix datagram socket beside the controller's e-stop file, through which
``zstack estop engage`` on the controller's own host hands over an engage without Zenoh.

Why a second road. The command's Zenoh road starts an interpreter, imports Zenoh, opens a
session and waits for a link before its first put: about 100 ms of CPU, which with both cores
busy stretched to 0.2-0.6 s before the first zero (docs/benchmarks.md, "E-stop: from the
command to the first zero"). This road needs only the standard library and the config's path
to the e-stop file: the datagram leaves after a few tens of milliseconds of CPU. The Zenoh road
still follows, always: it reaches a controller on another host, and it is the controller's
status, heard over Zenoh, that acknowledges the stop.

What the socket accepts: an **engage** and nothing else. A release never comes this way (it
needs the ``estop`` principal's Zenoh key and a fresh stamp). The socket is the owner's alone
(mode 0600), so only the controller's own user on its own host reaches it, and all it can do is
stop the robot, which is what anyone in doubt may do. Anything else that arrives is counted by
the controller and, as garbage on the e-stop key is, taken as a press: a stop fails safe.

Sending never blocks: a listener that is gone, stale or flooded (its queue full) makes
:func:`engage_locally` return why at once, and the Zenoh road carries the stop alone.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

#: What opens a local engage; the rest of the datagram, up to MAX_DATAGRAM bytes, is the reason.
ENGAGE = b"zstack-estop engage\n"
MAX_DATAGRAM = 512
#: A Unix socket's address is at most 107 bytes (Linux): a longer path is reached through
#: the open folder (/proc/self/fd/N/name).
MAX_ADDRESS = 100
#: How long :meth:`LocalEStop.close` waits for its thread (woken at once).
CLOSE_WAIT_S = 2.0


def socket_path(estop_file: Path) -> Path:
    """The local e-stop socket of the controller that keeps its latch in ``estop_file``."""
    return estop_file.with_name(estop_file.name + ".sock")


@contextlib.contextmanager
def _address(path: Path) -> Iterator[str]:
    """``path`` as a socket address: itself when short enough, else through an open handle
    of its folder (Linux), closed after use."""
    if len(os.fsencode(path)) <= MAX_ADDRESS:
        yield str(path)
        return
    folder = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
    try:
        yield f"/proc/self/fd/{folder}/{path.name}"
    finally:
        os.close(folder)


def engage_locally(path: Path, reason: str) -> str:
    """Hand an engage to the controller listening at ``path``; "" when the datagram was
    taken, else why not (no such socket, no listener, its queue full, ...). Never blocks."""
    data = (ENGAGE + reason.encode("utf-8", "replace"))[:MAX_DATAGRAM]
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock, _address(path) as address:
            sock.setblocking(False)
            sock.sendto(data, address)
    except OSError as exc:
        return f"{exc.strerror or exc}: {path}"
    return ""


class LocalEStop:
    """The controller's end: binds ``path`` (replacing a stale socket there), owner-only, and
    calls, on its own thread, ``on_engage(reason)`` for each engage, ``on_bad(why)`` for
    any other datagram and ``on_failed(why)`` if the socket fails (the thread ends).
    :meth:`close` stops the thread and removes the socket if it is still this one's. Raises
    OSError when the socket cannot be made (the caller says so, and the Zenoh road is the
    only one)."""

    def __init__(
        self,
        path: Path,
        on_engage: Callable[[str], None],
        on_bad: Callable[[str], None],
        on_failed: Callable[[str], None],
    ) -> None:
        self.path = path
        self._on_engage, self._on_bad, self._on_failed = on_engage, on_bad, on_failed
        self._closed = threading.Event()
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        try:
            if path.is_socket():
                path.unlink()  # a crashed controller's; a live one would hold the same latch
            with _address(path) as address:
                self._sock.bind(address)
            os.chmod(path, 0o600)
            self._inode = path.stat().st_ino
        except OSError:
            self._sock.close()
            raise
        self._wake_r, self._wake_w = os.pipe()  # written by close: the thread's select returns
        self._thread = threading.Thread(target=self._serve, name="estop-local", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._closed.is_set():
            try:
                ready, _, _ = select.select([self._sock.fileno(), self._wake_r], [], [])
                if self._wake_r in ready:
                    return  # woken by close
                data = self._sock.recv(MAX_DATAGRAM + 1)
            except OSError as exc:
                if not self._closed.is_set():
                    self._on_failed(f"{exc.strerror or exc}: {self.path}")
                return
            if data.startswith(ENGAGE) and len(data) <= MAX_DATAGRAM:
                self._on_engage(data[len(ENGAGE) :].decode("utf-8", "replace"))
            else:
                self._on_bad(f"{len(data)} bytes that are not an engage")

    def close(self) -> None:
        self._closed.set()
        os.write(self._wake_w, b"x")
        self._thread.join(timeout=CLOSE_WAIT_S)
        self._sock.close()
        os.close(self._wake_r)
        os.close(self._wake_w)
        with contextlib.suppress(FileNotFoundError):  # already gone: nothing to remove
            if self.path.stat().st_ino == self._inode:  # not a newer controller's
                self.path.unlink()
