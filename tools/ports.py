"""The ports a tool's private stacks listen on (scenario runs, soaks, benchmarks).

Each on a free port the system picks, by default; a command's ``--port N`` (:func:`add_port`)
calls :func:`use_ports` once, and from then on the process's private stacks get N, N+1, ... in
the order the tool asks for them (:func:`private_endpoint`), each checked free when taken: a
run can be placed where a firewall, a container or a robot's other services leave room.
"""

from __future__ import annotations

import argparse
import socket
import threading

from common.errors import ConfigError
from common.ports import holder_words


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (for a private Zenoh endpoint)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class _PortPlan:
    """The ports this process's private stacks get: from a first one on, or each free."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._next: int | None = None

    def start_at(self, first: int | None) -> None:
        with self._lock:
            self._next = first

    def take(self) -> int:
        with self._lock:
            if self._next is None:
                return free_port()
            port = self._next
            self._next += 1
        if port > 65535:
            raise ConfigError(f"--port: the run needs ports up to {port}, past 65535")
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError as exc:
                raise ConfigError(
                    f"--port: port {port} on 127.0.0.1 is taken ({holder_words(port)}): name "
                    "another first port, or leave --port out for free ones"
                ) from exc
        return port


_PORTS = _PortPlan()


def use_ports(first: int | None) -> None:
    """From now on, this process's private stacks listen on ``first``, ``first + 1``, ... in
    the order they are asked for (each checked free when taken); None: each on a free port
    the system picks (the default)."""
    _PORTS.start_at(first)


def private_port() -> int:
    """The next port of :func:`use_ports`' plan (a free one without a plan)."""
    return _PORTS.take()


def private_endpoint() -> str:
    """``tcp/127.0.0.1:<port>`` on :func:`private_port`: a private stack's own router."""
    return f"tcp/127.0.0.1:{private_port()}"


def _first_port(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a port number, got {text!r}") from None
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"a port within 1..65535, got {port}")
    return port


def add_port(p: argparse.ArgumentParser) -> None:
    """The ``--port`` option of a command that starts private stacks (see :func:`use_ports`)."""
    p.add_argument(
        "--port",
        type=_first_port,
        help="the first port the run's own stacks listen on (127.0.0.1), the next ones after "
        "it; each must be free (default: ports the system picks free)",
    )
