"""What the detector does with a frame or a depth frame as it arrives (:class:`DetectorHandlers`).
No bus: the subscriptions that call ``on_frame`` and ``on_depth`` are the pool member's
(services/detector/membership.py)."""

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
from services.detector.counting import count_for, reject_for
from services.detector.depth_stage import DepthStage
from services.detector.schedule import CameraSlots
from stack.config import Config


class DetectorHandlers:
    """What the detector does with a frame as it arrives: decode it, count it (in all and for
    its camera), note it for the pairing with its depth frame (``depth``, for a camera with
    depth) and leave it in its camera's slot, from which the loop takes rounds. A frame's
    arrival is stamped on ``clock``. Depth frames go to ``depth`` (:meth:`on_depth`).

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
        #: The depth of the cameras that have it (the pool member adds and drops them as their
        #: announcements say), paired with their frames as they arrive here.
        self.depth = DepthStage(self.settings, tally)

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
        self.depth.colour(camera, frame.header)  # before the slot: a round may take it at once
        if self.slots.put(camera, frame):
            count(contract.DROPPED)

    def on_depth(self, camera: str, payload: bytes) -> None:
        """A depth frame of ``camera`` (services/detector/depth_stage.py); nothing for a
        camera this worker does not serve now."""
        if camera in self.serving:
            self.depth.on_depth(camera, payload)
