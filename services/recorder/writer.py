"""Writing a recording: a bounded queue that never blocks its producers, one writer thread, and
an MCAP file of compressed chunks that a kill leaves readable up to its last full chunk.

Producers (Zenoh's callback threads) only ``offer`` the raw payload; decoding, translating
(channels.py), compressing and writing happen on the writer thread. A full queue drops the
message and counts it (``dropped``). Each finished chunk is flushed to the file at once, and a
chunk is closed at least every ``flush_period_s``, so a killed recorder loses at most that.
No zenoh here: the service (service.py) feeds it.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from mcap.writer import CompressionType, Writer

from common.clock import mono_s
from common.codec import Message
from common.counters import BAD_INPUT, Counters
from common.errors import ConfigError, DecodeError, one_line
from common.lifecycle import Closing
from common.priority import leave_idle, process_threads
from services.recorder import contract
from services.recorder.channels import PROFILE, Channel, Entry, Translator
from services.recorder.contract import Compression, RecorderSettings

log = logging.getLogger("recorder")

_COMPRESSION = {
    Compression.LZ4: CompressionType.LZ4,
    Compression.ZSTD: CompressionType.ZSTD,
    Compression.NONE: CompressionType.NONE,
}
LIBRARY = "zenoh-yolo-stack recorder"

#: Turns a payload into the stack message (``Frame.decode`` ...); DecodeError for garbage.
Decode = Callable[[bytes], Message]


class McapFile(Closing):
    """An MCAP file being written: channels registered on first use, chunks flushed to disk as
    soon as they are complete."""

    def __init__(self, path: Path, settings: RecorderSettings) -> None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._file: IO[bytes] = path.open("wb")
        except OSError as exc:
            raise ConfigError(f"cannot write a recording at {path}: {one_line(exc)}") from exc
        self.path = path
        self._writer = Writer(
            self._file,
            chunk_size=settings.chunk_size_kb * 1024,
            compression=_COMPRESSION[Compression(settings.compression)],
        )
        self._writer.start(profile=PROFILE, library=LIBRARY)
        self._schemas: dict[tuple[str, bytes], int] = {}
        self._channels: dict[Channel, int] = {}
        self._flush_period_s = settings.flush_period_s
        self._next_flush = mono_s() + self._flush_period_s
        self._flushed_at = 0
        self.messages = 0

    @property
    def bytes_written(self) -> int:
        return self._flushed_at

    def _channel_id(self, channel: Channel) -> int:
        found = self._channels.get(channel)
        if found is not None:
            return found
        schema_id = 0
        if channel.schema_name:
            key = (channel.schema_name, channel.schema_data)
            if key not in self._schemas:
                self._schemas[key] = self._writer.register_schema(
                    channel.schema_name, channel.schema_encoding, channel.schema_data
                )
            schema_id = self._schemas[key]
        cid = self._writer.register_channel(
            channel.topic, channel.message_encoding, schema_id, dict(channel.metadata)
        )
        self._channels[channel] = cid
        return cid

    def add(self, entry: Entry, log_ns: int) -> None:
        self._writer.add_message(
            self._channel_id(entry.channel),
            log_time=log_ns,
            data=entry.data,
            publish_time=log_ns if entry.publish_ns is None else entry.publish_ns,
            sequence=entry.sequence & 0xFFFFFFFF,  # MCAP's sequence is uint32
        )
        self.messages += 1
        if self._file.tell() != self._flushed_at:  # a chunk was finished: put it on disk
            self._sync()

    def tick(self) -> None:
        """Close the chunk in progress once ``flush_period_s`` has passed since the last."""
        now = mono_s()
        if now >= self._next_flush:
            self._next_flush = now + self._flush_period_s
            self._writer.flush()  # type: ignore[no-untyped-call]  # mcap's own
            self._sync()

    def _sync(self) -> None:
        self._file.flush()
        self._flushed_at = self._file.tell()

    def close(self) -> None:
        """Write the last chunk, the indexes and the footer."""
        if self._file.closed:
            return
        self._writer.finish()  # type: ignore[no-untyped-call]
        self._sync()
        self._file.close()


@dataclass(frozen=True, slots=True)
class _Item:
    key: str
    payload: bytes
    log_ns: int
    decode: Decode


class QueuedRecorder(Closing):
    """The bounded queue and its writer thread in front of an :class:`McapFile`.

    The writer works in batches: it wakes at most every 0.1 s (half ``flush_period_s`` if less)
    and writes all that is queued, rather than waking for each message: about 6 % of one core
    instead of 7 % on the default stack (docs/benchmarks.md; what keeps it off the detector's
    cores is its priority, service.py). Offering is a length check and an append, with no lock
    to wait on and no thread to wake.

    Counters: ``received`` (offered), ``dropped`` (queue full), ``written`` (stack messages
    written, each one or more MCAP messages), ``bad_input`` (undecodable).
    """

    def __init__(
        self,
        mcap: McapFile,
        translator: Translator,
        settings: RecorderSettings,
        counters: Counters,
    ) -> None:
        self.file = mcap
        self._translator = translator
        self._counters = counters
        self._limit = settings.queue_size
        self._queue: deque[_Item] = deque()  # append and popleft are atomic
        self._closing = threading.Event()
        self._close_by = float("inf")  # on closing: the queue is written until then, then dropped
        self._poll_s = min(0.1, settings.flush_period_s / 2)
        self._thread = threading.Thread(target=self._run, name="recorder-writer", daemon=True)
        self._error: Exception | None = None
        self._thread.start()

    def offer(self, key: str, payload: bytes, log_ns: int, decode: Decode) -> bool:
        """Queue one message (received on ``key`` at ``log_ns``) for writing; never blocks.
        False, and counted, when ``queue_size`` messages are already waiting."""
        self._counters.add(contract.RECEIVED)
        if len(self._queue) >= self._limit:
            self._counters.add(contract.DROPPED)
            return False
        self._queue.append(_Item(key, payload, log_ns, decode))
        return True

    @property
    def failed(self) -> Exception | None:
        """The error that stopped the writer (a full disk ...), if one did."""
        return self._error

    def _run(self) -> None:
        try:
            while True:
                closing = self._closing.wait(self._poll_s)
                while self._queue:  # what came in meanwhile; on closing, what time allows
                    if self._closing.is_set() and mono_s() >= self._close_by:
                        self._counters.add(contract.DROPPED, len(self._queue))
                        self._queue.clear()
                        break
                    self._write(self._queue.popleft())
                self.file.tick()
                if closing:
                    return
        except Exception as exc:  # a full disk, or a bug: the service then exits non-zero
            self._error = exc
            log.error("recording stopped: %s", one_line(exc))

    def _write(self, item: _Item) -> None:
        try:
            msg = item.decode(item.payload)
            entries = self._translator.entries(item.key, msg)
        except (DecodeError, ValueError) as exc:  # ValueError: a stamp no ROS Time can hold
            self._counters.add(BAD_INPUT)
            log.warning("not recorded: bad input on %s: %s", item.key, one_line(exc))
            return
        for entry in entries:
            self.file.add(entry, item.log_ns)
        self._counters.add(contract.WRITTEN)

    def close(self, budget_s: float = float("inf")) -> None:
        """Write what is queued for at most ``budget_s`` (the rest is dropped, counted), then
        finish the file, out of the idle class: a stop must end before the supervisor's stop
        timeout however busy the cores, with a whole file rather than a killed one."""
        # Every thread, Zenoh's too: the session's close after the file's needs them, and an
        # idle-class one starved there until the stop timeout killed the recorder (both cores
        # busy, the file already done).
        log.debug("closing: %s", leave_idle(*process_threads()))
        self._close_by = mono_s() + budget_s
        self._closing.set()
        self._thread.join()
        if self._error is None:
            self.file.close()
