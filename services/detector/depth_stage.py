"""The detector's depth stage: each colour frame of a camera that has depth paired with the
depth frame of its camera whose stamp is nearest (:class:`Pairing`, pure), and each of its
detections given perception/depth.py's columns from it (:class:`DepthStage`). No bus: the
subscriptions that call :meth:`DepthStage.on_depth` are the pool member's
(services/detector/membership.py).

When the pairing looks. A source publishes a camera's depth frame with the same header as the
colour frame it was captured with, but the two travel apart and either may come first. The
pairing is decided when the round's detections are built, after the model ran, so a depth frame
that arrives up to a round's inference after its colour frame is still used; with none yet (a
fast GPU round, a depth frame still in transit) it waits up to ``detector.depth_wait_ms`` for
one that may still come, only when the camera's last frame paired (a depth stream gone quiet
costs one wait, not one per frame). A depth frame could leave a short buffer while its colour
frame waits in its slot and then through the model (30 depth frames a second, a round of 100 ms
or more on a CPU); so the best match is *claimed* as the colour frame arrives, and bettered by
each depth frame that arrives after it, until the detections are built. Only the colour-vs-depth
arrival skew must fit in the buffer, not the detector's latency. A depth frame that arrives
after that is too late: those detections are 2D only (counted ``depth_unpaired``).
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass
from typing import Generic, TypeVar

from common.boxes import Boxes
from common.clock import ms_since, perf_s
from common.counters import BAD_INPUT, per_camera
from common.errors import DecodeError
from common.messages import DepthFrame, Header
from common.node import Tally
from perception import DepthParams, Intrinsics, depth_metres, measure_depth, to_depth_pixels
from services.detector import contract
from services.detector.contract import DetectorSettings
from services.detector.counting import count_for, reject_for

_T = TypeVar("_T")


@dataclass(slots=True)
class _Claim(Generic[_T]):
    """A colour frame (its stamp) and the nearest depth frame seen for it so far."""

    stamp_ns: int
    best: tuple[int, _T] | None  # (its stamp, the depth frame)


class Pairing(Generic[_T]):
    """One camera's pairing of colour frames with depth frames by stamp (ns): the nearest
    within ``tolerance_ns`` (inclusive); of two as near, the first heard.

    ``depth`` keeps the last ``buffer`` depth frames (by arrival) and betters the claims;
    ``colour`` claims the nearest one heard for a colour frame as it arrives (the frame in the
    camera's slot: a newer one replaces its claim, as it replaces it in the slot); ``hold``
    moves that claim to the frame the round took (one per camera in a round); ``take`` gives
    the paired depth frame as the detections are built (None: none within the tolerance).
    Not thread-safe: :class:`DepthStage` locks."""

    def __init__(self, buffer: int, tolerance_ns: int) -> None:
        if buffer < 1 or tolerance_ns < 0:
            raise ValueError(f"need buffer >= 1, tolerance >= 0; got {buffer}, {tolerance_ns}")
        self.tolerance_ns = tolerance_ns
        self.recent: deque[tuple[int, _T]] = deque(maxlen=buffer)
        self._waiting: _Claim[_T] | None = None  # the colour frame in the slot
        self._held: _Claim[_T] | None = None  # the one a round took

    def depth(self, stamp_ns: int, item: _T) -> None:
        self.recent.append((stamp_ns, item))
        for claim in (self._waiting, self._held):
            if claim is not None and self._nearer(claim.stamp_ns, (stamp_ns, item), claim.best):
                claim.best = (stamp_ns, item)

    def colour(self, stamp_ns: int) -> None:
        self._waiting = _Claim(stamp_ns, self._nearest(stamp_ns))

    def hold(self, stamp_ns: int) -> None:
        waiting = self._waiting
        if waiting is not None and waiting.stamp_ns == stamp_ns:
            self._held, self._waiting = waiting, None
        else:  # its arrival raced the round's take: what has arrived is all there is
            self._held = _Claim(stamp_ns, self._nearest(stamp_ns))

    def take(self, stamp_ns: int) -> _T | None:
        found = self.peek(stamp_ns)
        self._held = None
        return found

    def peek(self, stamp_ns: int) -> _T | None:
        """What :meth:`take` would give now, the claim left held."""
        held = self._held
        best = held.best if held is not None and held.stamp_ns == stamp_ns else None
        now = self._nearest(stamp_ns)
        if self._nearer(stamp_ns, now, best):
            best = now
        return None if best is None else best[1]

    def may_come(self, stamp_ns: int) -> bool:
        """Whether a depth frame for ``stamp_ns`` may still come: none stamped at or after it
        has been heard (a source sends its depth frames in stamp order)."""
        return all(at < stamp_ns for at, _ in self.recent)

    def _nearest(self, stamp_ns: int) -> tuple[int, _T] | None:
        best: tuple[int, _T] | None = None
        for candidate in self.recent:
            if self._nearer(stamp_ns, candidate, best):
                best = candidate
        return best

    def _nearer(
        self, stamp_ns: int, candidate: tuple[int, _T] | None, than: tuple[int, _T] | None
    ) -> bool:
        """Whether ``candidate`` is within the tolerance of ``stamp_ns`` and strictly nearer
        than ``than``."""
        if candidate is None:
            return False
        gap = abs(candidate[0] - stamp_ns)
        return gap <= self.tolerance_ns and (than is None or gap < abs(than[0] - stamp_ns))


class DepthStage:
    """The depth of every camera this worker serves that has depth: its depth frames in (bus
    threads: :meth:`on_depth`), the pairing claims as its colour frames arrive
    (:meth:`colour`) and are taken (:meth:`hold`), and each paired frame's detections given
    the depth columns (:meth:`measure`, the loop's thread). Counted in all and per camera:
    ``depth_in``, ``depth_paired``, ``depth_unpaired``; garbage on a depth key is bad input
    (``bad_input`` and ``bad_input.<camera>``), dropped. A depth frame is only decoded as a
    message as it arrives; its pixels are read for the frame it is paired with alone."""

    def __init__(self, settings: DetectorSettings, tally: Tally) -> None:
        self.tally = tally
        self.buffer = settings.depth_buffer
        self.tolerance_ns = round(settings.depth_pair_tolerance_ms * 1e6)
        self.max_pixels = settings.max_frame_pixels
        self.params = DepthParams(
            min_valid_pixels=settings.depth_min_valid_pixels,
            min_valid_fraction=settings.depth_min_valid_fraction,
        )
        self.wait_s = settings.depth_wait_ms / 1000.0
        self._lock = threading.Condition()  # notified as each depth frame is kept
        self._pairs: dict[str, Pairing[DepthFrame]] = {}
        self._paired_last: dict[str, bool] = {}  # whether the camera's last frame paired
        self.keys: dict[str, str] = {}  # each camera's depth key
        self.waiting = 0  # how many measure() calls wait for a depth frame now ...
        self.waits = 0  # ... and have waited in all (read by tests)

    def add_camera(self, camera: str, key: str) -> None:
        """Pair ``camera``'s frames with its depth frames on ``key`` from now on (before the
        subscription to them)."""
        with self._lock:
            if camera not in self._pairs:
                self._pairs[camera] = Pairing(self.buffer, self.tolerance_ns)
                self._paired_last[camera] = True  # its first frame may wait
            self.keys[camera] = key
        for name in (contract.DEPTH_IN, contract.DEPTH_PAIRED, contract.DEPTH_UNPAIRED):
            count_for(self.tally, camera, name, 0)

    def drop_camera(self, camera: str) -> None:
        """``camera`` has no depth here any more (lost, or no longer announcing depth): its
        frames go out 2D only, uncounted, and its depth frames are let go."""
        with self._lock:
            self._pairs.pop(camera, None)
            self._paired_last.pop(camera, None)
            self.keys.pop(camera, None)

    def has_depth(self, camera: str) -> bool:
        with self._lock:
            return camera in self._pairs

    def on_depth(self, camera: str, payload: bytes) -> None:
        """A depth frame of ``camera`` arrived (a bus thread)."""
        with self._lock:
            key = self.keys.get(camera)
        if key is None:
            return  # late from a subscription just undeclared
        count_for(self.tally, camera, contract.DEPTH_IN)
        try:
            frame = DepthFrame.decode(payload)
            if frame.width * frame.height > self.max_pixels:
                raise DecodeError(
                    f"depth image {frame.width}x{frame.height} is over detector.max_frame_pixels"
                )
        except DecodeError as exc:
            self.tally.bad_input(key, exc)
            self.tally.counters.add(per_camera(BAD_INPUT, camera))
            return
        with self._lock:
            pairing = self._pairs.get(camera)
            if pairing is not None:
                pairing.depth(frame.header.stamp_ns, frame)
                self._lock.notify_all()

    def colour(self, camera: str, header: Header) -> None:
        """A colour frame of ``camera`` arrived and goes into its slot (a bus thread)."""
        with self._lock:
            pairing = self._pairs.get(camera)
            if pairing is not None:
                pairing.colour(header.stamp_ns)

    def hold(self, camera: str, header: Header) -> None:
        """A round took ``camera``'s frame of ``header`` (the loop, before the model)."""
        with self._lock:
            pairing = self._pairs.get(camera)
            if pairing is not None:
                pairing.hold(header.stamp_ns)

    def _pair(self, camera: str, stamp_ns: int) -> tuple[bool, DepthFrame | None]:
        """Whether ``camera`` has depth, and the depth frame paired with its frame of
        ``stamp_ns``. With none yet, while one may still come,
        it waits up to ``detector.depth_wait_ms`` for it, but only when the camera's last
        frame paired: a depth stream gone quiet costs one wait, not one per frame."""
        deadline = perf_s() + self.wait_s
        with self._lock:
            pairing = self._pairs.get(camera)
            if pairing is None:
                return False, None
            found = pairing.peek(stamp_ns)
            if found is None and self._paired_last[camera] and pairing.may_come(stamp_ns):
                self.waiting += 1
                self.waits += 1
                try:
                    while found is None and pairing.may_come(stamp_ns):
                        left = deadline - perf_s()
                        if left <= 0 or self._pairs.get(camera) is not pairing:
                            break
                        self._lock.wait(left)
                        found = pairing.peek(stamp_ns)
                finally:
                    self.waiting -= 1
            found = pairing.take(stamp_ns)
            self._paired_last[camera] = found is not None
            return True, found

    def measure(
        self, camera: str, header: Header, image_size: tuple[int, int], boxes: Boxes
    ) -> tuple[Boxes, float | None]:
        """``boxes`` (in pixels of the ``image_size`` (width, height) colour frame of
        ``header``) with every depth column, from the depth frame paired with it, and the
        stage's milliseconds; ``boxes`` as they are and None for a camera without depth or a
        frame with no depth frame within the tolerance (counted unpaired)."""
        has_depth, paired = self._pair(camera, header.stamp_ns)
        if not has_depth:
            return boxes, None
        if paired is None:
            count_for(self.tally, camera, contract.DEPTH_UNPAIRED)
            return boxes, None
        start = perf_s()
        try:
            intr = Intrinsics.of(paired)
            xyxy = to_depth_pixels(boxes.xyxy, image_size, intr)
            columns = measure_depth(depth_metres(paired), intr, xyxy, self.params)
            out = boxes.with_columns(columns)
        except Exception as exc:  # a defect in the method must not stop the detections
            reject_for(
                self.tally,
                camera,
                contract.DEPTH_FAILED,
                f"the depth stage failed on frame {header.seq} of {camera} ({exc!r}): "
                "its detections go out without depth",
                f"depth-failed/{camera}",
            )
            return boxes, None
        ms = ms_since(start)
        count_for(self.tally, camera, contract.DEPTH_PAIRED)
        return out, ms
