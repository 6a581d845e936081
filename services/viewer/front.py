"""The live view's public port: a TCP front that checks each WebSocket upgrade request
(services/viewer/access.py) and then relays the connection, bytes unchanged, to the Foxglove
server on a private loopback port. The Foxglove SDK has no hook on the upgrade (no Origin
check, no authentication), so the check is made here, before the SDK sees the request.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable

from services.viewer.access import MAX_HEAD_BYTES, refusal

FORBIDDEN = b"HTTP/1.1 403 Forbidden\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
RELAY_CHUNK = 65536

log = logging.getLogger("viewer.front")


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    try:
        while data := await reader.read(RELAY_CHUNK):
            writer.write(data)
            await writer.drain()
    except ConnectionError as exc:
        log.debug("relay closed: %s", exc)
    finally:
        writer.close()


class Front:
    """Listens on ``host``:``port``; relays admitted clients to 127.0.0.1:``inner_port``; a
    client that has not sent its request head within ``head_timeout_s`` is dropped."""

    def __init__(
        self,
        host: str,
        port: int,
        inner_port: int,
        check: Callable[[bytes], str | None],
        head_timeout_s: float,
    ) -> None:
        self._host, self._port, self._inner = host, port, inner_port
        self._check, self._head_timeout_s = check, head_timeout_s
        self._loop = asyncio.new_event_loop()
        self._server: asyncio.Server | None = None
        self._thread = threading.Thread(target=self._loop.run_forever, name="front", daemon=True)
        self.refused = 0

    def start(self) -> int:
        """Bind (raising OSError if the port is taken) and serve; the port bound."""
        self._server = self._loop.run_until_complete(
            asyncio.start_server(self._client, self._host, self._port, limit=MAX_HEAD_BYTES)
        )
        self._thread.start()
        return int(self._server.sockets[0].getsockname()[1])

    def stop(self) -> None:
        async def close() -> None:
            if self._server is not None:
                self._server.close()

        if self._thread.is_alive():
            asyncio.run_coroutine_threadsafe(close(), self._loop).result(timeout=2.0)
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=2.0)

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), self._head_timeout_s)
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError) as exc:
            log.debug("no request head: %r", exc)
            writer.close()
            return
        why = self._check(head)
        if why is not None:
            self.refused += 1
            log.warning("live view client %s refused: %s", writer.get_extra_info("peername"), why)
            writer.write(FORBIDDEN)
            writer.close()
            return
        try:
            up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self._inner)
        except OSError as exc:
            log.warning("live view: cannot reach the Foxglove server: %s", exc)
            writer.close()
            return
        up_writer.write(head)
        await asyncio.gather(_pipe(reader, up_writer), _pipe(up_reader, writer))


def make_check(allowed: tuple[str, ...], token: str | None) -> Callable[[bytes], str | None]:
    return lambda head: refusal(head, allowed, token)
