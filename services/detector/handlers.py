"""What the detector does with a frame as it arrives (:class:`DetectorHandlers`), and its
per-camera counting (:func:`count_for`, :func:`reject_for`). No bus: the subscriptions that
call ``on_frame`` are the pool member's (services/detector/membership.py)."""

from __future__ import annotations

from collections.abc import Mapping
from functools import partial

from common.clock import SYSTEM_CLOCK, Clock
from common.counters import BAD_INPUT, per_camera
from common.errors import DecodeError, ImageTooLarge
from common.frames import check_pixel_budget
from common.messages import Frame
from common.node import Tally
from common.seqgaps import SeqGaps
from services.detector import contract
from services.detector.schedule import CameraSlots
from stack.config import Config


class DetectorHandlers:
    """What the detector does with a frame as it arrives: decode it, count it (in all and for
    its camera), and leave it in its camera's slot, from which the loop takes rounds. A
    frame's arrival is stamped on ``clock``.

    ``frame_keys``: each camera's frame key by its name in counters (common/pool_rule.py's
    ``label``); by default the config's cameras on the stack's keys. A pool worker starts with
    none and adds each camera it comes to serve (:meth:`add_camera`)."""

    def __init__(
        self,
        config: Config,
        tally: Tally,
        clock: Clock = SYSTEM_CLOCK,
        frame_keys: Mapping[str, str] | None = None,
    ) -> None:
        self.config = config
        self.settings = config.detector
        self.tally = tally
        self.frame_keys = (
            {cam: tally.keys.frame(cam) for cam in config.all_cameras}
            if frame_keys is None
            else dict(frame_keys)
        )
        self.slots: CameraSlots[Frame] = CameraSlots(self.frame_keys, clock)
        self.gaps = {cam: SeqGaps() for cam in self.frame_keys}  # one numbering per camera
        #: The cameras this worker serves (all of them outside a pool); a frame of another,
        #: late from a subscription just undeclared, is left to its new worker. Written by the
        #: pool member under its lock (services/detector/membership.py).
        self.serving: frozenset[str] = frozenset(self.frame_keys)

    def add_camera(self, camera: str, frame_key: str) -> None:
        """Know ``camera`` (its frames on ``frame_key``) from now on (the loop's thread, before
        it subscribes to the frames; nothing when it is known)."""
        if camera in self.frame_keys:
            return
        self.gaps[camera] = SeqGaps()
        self.slots.add(camera)
        self.frame_keys[camera] = frame_key

    def serve(
        self, cameras: frozenset[str], gained: tuple[str, ...], lost: tuple[str, ...]
    ) -> None:
        """Serve ``cameras`` from now on: a camera ``lost`` has its waiting frame dropped (its
        new worker detects on it), one ``gained`` starts its frame numbering afresh (the frames
        sent while another worker served it are no loss)."""
        self.serving = cameras
        for cam in lost:
            self.slots.clear(cam)
        for cam in gained:
            self.gaps[cam] = SeqGaps()

    def on_frame(self, camera: str, payload: bytes) -> None:
        # Decode here, not in the loop: garbage must be counted even when a newer frame would
        # have replaced it in the slot before the loop looked at it; and an oversize frame
        # must never displace a real one there.
        if camera not in self.serving:
            return
        count = partial(count_for, self.tally, camera)
        count(contract.FRAMES_IN)
        key = self.frame_keys[camera]
        try:
            frame = Frame.decode(payload)
            missed = self.gaps[camera].observe(frame.header)
            if missed:
                count(contract.FRAMES_MISSED, missed)
            check_pixel_budget(frame, self.settings.max_frame_pixels)
        except DecodeError as exc:
            self.tally.bad_input(key, exc)
            self.tally.counters.add(per_camera(BAD_INPUT, camera))
            return
        except ImageTooLarge as exc:
            reject_for(self.tally, camera, contract.FRAMES_OVERSIZE, str(exc), key)
            return
        if self.slots.put(camera, frame):
            count(contract.DROPPED)


def count_for(tally: Tally, camera: str, name: str, n: int = 1) -> None:
    """Count ``n`` under ``name`` (the detector's total) and under ``name.<camera>``."""
    tally.counters.add(name, n)
    tally.counters.add(per_camera(name, camera), n)


def reject_for(tally: Tally, camera: str, counter: str, message: str, key: str) -> None:
    """``Tally.reject`` (counted in all, logged rate-limited per key) and counted for
    ``camera`` too."""
    tally.reject(counter, message, key=key)
    tally.counters.add(per_camera(counter, camera))
