"""Who holds a TCP port on this host, so that the error line for a taken port can name it.

Read from Linux's /proc: ``net/tcp`` and ``net/tcp6`` list every socket with its local port,
state and inode, and each process's ``fd/`` links name the sockets it holds
(``socket:[<inode>]``). Another user's processes cannot be read unless we are root, and a
process in another network namespace (a container) is not listed: then the holder is not
found, and the words say how to look (``ss -ltnp``).
"""

from __future__ import annotations

import os
from pathlib import Path

#: Who usually holds a port on a robot: what a user should look for.
KNOWN_PORTS = {
    7447: "rmw_zenohd, the ROS 2 Zenoh router, listens there by default",
    8765: "foxglove_bridge listens there by default",
}
PROC = Path("/proc")
_LISTEN = "0A"  # the state column's code for a listening socket
_COMMAND_CHARS = 80  # a holder's command line, shortened to this


def listening_inodes(table: str, port: int) -> set[int]:
    """The inodes of the sockets listening on ``port`` in a ``/proc/net/tcp`` (or tcp6)
    table's text."""
    found = set()
    for line in table.splitlines()[1:]:
        cols = line.split()
        if len(cols) < 10 or cols[3] != _LISTEN:
            continue
        _, _, hex_port = cols[1].rpartition(":")
        if int(hex_port, 16) == port:
            found.add(int(cols[9]))
    return found


def holders(port: int, proc: Path = PROC) -> list[tuple[int, str]]:
    """(pid, command line) of each process we can see holding a socket that listens on
    ``port``; empty when none can be seen."""
    inodes: set[int] = set()
    for name in ("tcp", "tcp6"):
        try:
            inodes |= listening_inodes((proc / "net" / name).read_text(), port)
        except OSError:
            continue
    if not inodes:
        return []
    links = {f"socket:[{inode}]" for inode in inodes}
    found = []
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            held = any(os.readlink(fd) in links for fd in (entry / "fd").iterdir())
        except OSError:  # gone meanwhile, or another user's
            continue
        if held:
            found.append((int(entry.name), _command(entry)))
    return sorted(found)


def _command(entry: Path) -> str:
    try:
        words = (entry / "cmdline").read_bytes().split(b"\0")
    except OSError:
        return "?"
    text = " ".join(w.decode(errors="replace") for w in words if w) or "?"
    return text if len(text) <= _COMMAND_CHARS else text[: _COMMAND_CHARS - 3] + "..."


def holder_words(port: int, proc: Path = PROC) -> str:
    """Who holds ``port``, in words for an error line: ``held by pid 42 (python3 -m x)``; or,
    when no holder can be seen here, the usual one on a robot and how to look."""
    found = holders(port, proc)
    if found:
        return "held by " + ", ".join(f"pid {pid} ({command})" for pid, command in found)
    usual = f"{KNOWN_PORTS[port]}; " if port in KNOWN_PORTS else ""
    return (
        f"{usual}the holder is not visible to this user: find it with `ss -ltnp 'sport = :{port}'`"
    )
