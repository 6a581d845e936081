"""Messages a receiver never got, told from gaps in their senders' sequence numbers. Pure.

Every header carries ``seq``, one more per message its source stamps for one ``frame_id``
(common/node.py): a stream is (source, boot, frame_id). A
frame dropped under congestion (QoS SENSOR drops rather than block), lost with its link, or
refused by its publisher as too large leaves a gap that nothing else would report.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from common.messages import Header

MAX_SOURCES = 64  # senders remembered (the least recently heard forgotten first)
#: A jump forward by more than this is a sender that restarted or a forged number, not loss:
#: the count starts again from it rather than adding millions of "missed" messages.
MAX_GAP = 10_000


class SeqGaps:
    """Per stream (``header.source`` and ``frame_id`` on one boot): how many sequence numbers
    were skipped.

    A number at or below the last one heard is a restart (or a replay, which the freshness
    gate refuses): counting starts again from it, and nothing is counted missed.
    Thread-safe: Zenoh may call a subscriber back from several threads (one per link).
    """

    def __init__(self, max_sources: int = MAX_SOURCES, max_gap: int = MAX_GAP) -> None:
        self._last: OrderedDict[tuple[str, str, str], int] = OrderedDict()
        self._max_sources = max_sources
        self._max_gap = max_gap
        self._lock = threading.Lock()

    def observe(self, header: Header) -> int:
        """Note ``header``; return how many messages from its source were skipped before it."""
        source = (header.source, header.boot_id, header.frame_id)
        with self._lock:
            last = self._last.get(source)
            self._last[source] = header.seq
            self._last.move_to_end(source)
            while len(self._last) > self._max_sources:
                self._last.popitem(last=False)
        if last is None or header.seq <= last:
            return 0
        gap = header.seq - last - 1
        return gap if gap <= self._max_gap else 0
