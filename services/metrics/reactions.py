"""Which camera's frame a command reacts to. Pure: no bus, no clock.

A Twist carries the capture stamp of the frame it reacts to (``input_stamp_ns``), not the
camera: the camera is the one whose detections carried that stamp (``header.stamp_ns``). The
command and the detections travel different paths, so either may arrive first; each side is
remembered, bounded, until the other comes. Only the first command for a stamp is a reaction
(the controller repeats its command between detections).

Two cameras may capture at the same nanosecond: the command is then scored for each of them
(its capture-to-command time is the same; detections-to-command is from each camera's own
detections), and once for the stack's totals, from the first detections published.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class Reaction:
    """A command (``commanded``) reacting to ``camera``'s frame captured at ``captured``, whose
    detections were published at ``published`` (wall-clock ns). ``first``: the first camera
    scored for that frame (the stack's totals count the frame once)."""

    camera: str
    captured: int
    published: int
    commanded: int
    first: bool


@dataclass(slots=True)
class _Frame:
    published: dict[str, int] = field(default_factory=dict)  # camera -> when its detections left
    commanded: int | None = None  # the first command reacting to this frame
    scored: set[str] = field(default_factory=set)  # cameras already scored


class Reactions:
    """Pairs detections and commands by capture stamp; remembers the latest ``keep`` stamps."""

    def __init__(self, keep: int) -> None:
        self.keep = keep
        self._frames: OrderedDict[int, _Frame] = OrderedDict()

    def _frame(self, stamp: int) -> _Frame:
        frame = self._frames.get(stamp)
        if frame is None:
            frame = self._frames[stamp] = _Frame()
            while len(self._frames) > self.keep:
                self._frames.popitem(last=False)
        return frame

    def on_detections(self, camera: str, stamp: int, published: int) -> list[Reaction]:
        """``camera``'s detections of the frame captured at ``stamp``; the reaction they
        complete, if the command came first."""
        frame = self._frame(stamp)
        frame.published.setdefault(camera, published)
        return self._score(stamp, frame)

    def on_command(self, stamp: int, commanded: int) -> list[Reaction]:
        """A command reacting to the frame captured at ``stamp`` (> 0); the reactions it
        completes: none for a repeat, or before that frame's detections arrive."""
        frame = self._frame(stamp)
        if frame.commanded is not None:
            return []  # a repeat: not a reaction
        frame.commanded = commanded
        return self._score(stamp, frame)

    def _score(self, stamp: int, frame: _Frame) -> list[Reaction]:
        if frame.commanded is None:
            return []
        out = []
        for camera, published in frame.published.items():
            if camera not in frame.scored:
                out.append(
                    Reaction(camera, stamp, published, frame.commanded, first=not frame.scored)
                )
                frame.scored.add(camera)
        return out
