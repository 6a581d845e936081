"""Gaps in a sender's sequence numbers are the messages a receiver never got."""

from __future__ import annotations

from common.clock import BOOT_ID
from common.memory_bus import MemoryHub
from common.messages import Header
from common.node import Node
from common.seqgaps import SeqGaps
from stack.config import Config


def header(seq: int, source: str = "camera", boot: str = "b1", frame_id: str = "") -> Header:
    return Header(stamp_ns=1, frame_id=frame_id, seq=seq, source=source, boot_id=boot)


def test_gaps_are_counted_per_source_and_restarts_are_not_loss() -> None:
    gaps = SeqGaps(max_gap=100)
    assert [gaps.observe(header(s)) for s in (1, 2, 3, 7, 8)] == [0, 0, 0, 3, 0]
    assert gaps.observe(header(5, source="sim")) == 0  # a new source: no history
    assert gaps.observe(header(7, source="sim")) == 1
    assert gaps.observe(header(1)) == 0  # the camera restarted: counting starts again
    assert gaps.observe(header(3)) == 1
    assert gaps.observe(header(4, boot="b2")) == 0  # another boot is another source
    assert gaps.observe(header(10_000)) == 0  # an absurd jump is a restart, not 9996 lost
    assert gaps.observe(header(10_002)) == 1


def test_sources_are_bounded() -> None:
    gaps = SeqGaps(max_sources=2)
    gaps.observe(header(1, "a"))
    gaps.observe(header(1, "b"))
    gaps.observe(header(1, "c"))  # forgets "a"
    assert gaps.observe(header(5, "a")) == 0
    assert gaps.observe(header(5, "c")) == 3


def test_one_source_numbers_each_frame_id_apart_and_its_streams_show_no_false_gaps() -> None:
    # The simulator stamps frames, scans and truths: each is its own numbered stream, so the
    # detector, which hears only the frames, must count nothing missed.
    node = Node("sim", Config(), bus=MemoryHub().join("sim"))
    stamped = [node.header(frame_id=f) for f in ("camera", "laser", "world") * 3]
    gaps = SeqGaps()
    assert [gaps.observe(h) for h in stamped if h.frame_id == "camera"] == [0, 0, 0]
    assert [h.seq for h in stamped if h.frame_id == "laser"] == [1, 2, 3]
    assert gaps.observe(header(3, "sim", BOOT_ID, "laser")) == 0
    assert gaps.observe(header(5, "sim", BOOT_ID, "laser")) == 1
