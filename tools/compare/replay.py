"""``compare`` with one recording: play it through the running stack while recording what the
stack makes of it, then compare the two (compare.py). Bus I/O: services/recorder/service.py.
"""

from __future__ import annotations

import threading
from pathlib import Path

from common.clock import mono_s
from common.lifecycle import Progress
from common.node import Node
from services.recorder import contract as recorder_contract
from services.recorder.service import SERVICE, Recorder, play
from stack.config import Config

SETTLE_S = 1.5  # the stack's last answers: recording ends once nothing new came for this long
TAIL_MAX_S = 15.0


def replay_and_record(
    config: Config, source: Path, target: Path, stop: threading.Event, progress: Progress,
    rate: float = 1.0, *, wait: bool = True,
) -> Path:  # fmt: skip
    """Play ``source`` onto the stack and record everything into ``target`` (``wait``: for a
    detector first; no link to the stack fails at once, play() says where it looked)."""
    with Node(SERVICE, config) as node:
        recorder = Recorder(node, target, config).listen(node)
        try:
            play(config, source, stop, progress, rate=rate, wait=wait)
            progress("waiting for the stack's last detections and commands")
            written, quiet_since = -1, mono_s()
            end = mono_s() + TAIL_MAX_S
            while mono_s() < end and not stop.wait(0.1):
                now = node.counters.get(recorder_contract.WRITTEN)
                if now != written:
                    written, quiet_since = now, mono_s()
                elif mono_s() - quiet_since > SETTLE_S:
                    break
        finally:
            recorder.close()
    progress(recorder.progress())
    return target
