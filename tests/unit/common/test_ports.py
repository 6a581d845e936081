"""Who holds a port: /proc's socket tables and file descriptors, read from a made-up /proc and
from this host's own."""

from __future__ import annotations

import os
import socket
from pathlib import Path

from common.ports import holder_words, holders, listening_inodes

HEAD = (
    "  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  "
    "timeout inode\n"
)
# Port 0x223E = 8766: listening (0A) with inode 4242; the same port connected (01), not
# listening; another port listening.
TCP = HEAD + (
    "   0: 0100007F:223E 00000000:0000 0A 00000000:00000000 00:00000000 00000000  0  0 4242 1\n"
    "   1: 0100007F:223E 0100007F:9C40 01 00000000:00000000 00:00000000 00000000  0  0 5555 1\n"
    "   2: 0100007F:1D27 00000000:0000 0A 00000000:00000000 00:00000000 00000000  0  0 7777 1\n"
)


def _proc(tmp_path: Path) -> Path:
    proc = tmp_path / "proc"
    (proc / "net").mkdir(parents=True)
    (proc / "net" / "tcp").write_text(TCP)
    (proc / "net" / "tcp6").write_text(HEAD)
    for pid, inode, argv in ((31, 4242, b"foxglove_bridge\0--port\x008766\0"),
                             (32, 7777, b"rmw_zenohd\0")):  # fmt: skip
        fd = proc / str(pid) / "fd"
        fd.mkdir(parents=True)
        os.symlink("/dev/null", fd / "0")
        os.symlink(f"socket:[{inode}]", fd / "3")
        (proc / str(pid) / "cmdline").write_bytes(argv)
    (proc / "self").mkdir()  # not a pid: skipped
    return proc


def test_the_listening_socket_of_a_port_and_its_holder(tmp_path: Path) -> None:
    assert listening_inodes(TCP, 8766) == {4242}
    assert listening_inodes(TCP, 9000) == set()
    proc = _proc(tmp_path)
    assert holders(8766, proc) == [(31, "foxglove_bridge --port 8766")]
    assert holder_words(8766, proc) == "held by pid 31 (foxglove_bridge --port 8766)"


def test_no_holder_in_sight_says_how_to_look(tmp_path: Path) -> None:
    proc = _proc(tmp_path)
    assert holder_words(8765, proc) == (
        "foxglove_bridge listens there by default; the holder is not visible to this user: "
        "find it with `ss -ltnp 'sport = :8765'`"
    )
    assert holder_words(8765, tmp_path / "nothing").startswith("foxglove_bridge listens")


def test_this_process_is_found_holding_its_own_port() -> None:
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        assert [pid for pid, _ in holders(port)] == [os.getpid()]
