"""The camera service: read a source at a fixed rate and publish Frame messages, and with an
RGB-D source (services/camera/sources.py ``DepthCapable``) one DepthFrame per frame."""

from __future__ import annotations

import threading
from collections.abc import Callable
from contextlib import ExitStack

from common.bus import Bus, Publisher, QoS
from common.camera_announce import CameraAnnouncements
from common.clock import mono_s
from common.errors import ImageError
from common.frames import image_to_frame
from common.messages import Header
from common.node import Node
from services.camera import contract
from services.camera.contract import CameraSettings
from services.camera.depth import resized, to_depth_frame
from services.camera.depth_folder import with_depth_folder
from services.camera.reopen import ReopenHooks, ReopeningSource
from services.camera.sources import (
    DepthCapable,
    FrameSource,
    depth_capable,
    open_source,
    resize,
)
from stack.config import Config

#: What opens a camera's source (``open_source``; an in-process test's own source).
Opener = Callable[..., FrameSource]

#: What a camera process says it is in its camera's announcement.
ANNOUNCED_SOURCE = "camera"


def run(
    config: Config,
    camera: str,
    settings: CameraSettings,
    stop: threading.Event,
    *,
    bus: Bus | None = None,
    opener: Opener = open_source,
) -> int:
    """Publish ``camera``'s frames (read with ``settings``) on its key until ``stop`` is set or
    the source ends; returns the exit code. The process is that camera's service
    (``config.camera_services``): its health token, counters and principal are its own, so the
    supervisor watches and restarts each camera apart from the others.

    A source from which no frame at all can be read raises ConfigError (one line, exit 2: the
    supervisor does not restart it). Unreadable frames among good ones are counted and skipped,
    with the log rate limited per key (common/ratelimit.py, through Node.reject). A live device
    that stops giving frames never ends: it is reopened every ``camera.reopen_period_s``
    (services/camera/reopen.py).

    The camera is announced on the bus (common/camera_announce.py) from start to stop, with
    its configured rate, mounting yaw, field of view and frame id; its size is ``resize``, or
    0x0 until the first frame gives the source's. A reopened source keeps the announcement
    (its size is announced again should it differ). ``bus``: an in-process test's.

    A source with depth (``realsense:``, ``oak:``, ``camera.depth_source``) also publishes
    each frame's aligned depth on ``keys.depth(camera)`` with the frame's header (DepthOut),
    and announces the camera with ``depth`` and its ``mount_*`` settings.

    What it opens (its node, the announcement, the source) is closed in the reverse order,
    however it ends.
    """
    with ExitStack() as closing:
        node = closing.enter_context(Node(config.camera_services[camera], config, bus=bus))
        announcements = closing.enter_context(
            CameraAnnouncements(node.bus, node.keys, ANNOUNCED_SOURCE)
        )

        def on_bad(exc: ImageError) -> None:
            node.reject(contract.BAD_IMAGES, str(exc))  # a looped folder repeats it: rate-limited

        source = _reopening(
            _with_depth(opener(settings.source, loop=settings.loop, on_bad=on_bad), settings),
            settings,
            node,
            stop,
            opener,
        )
        closing.callback(source.close)
        key = node.keys.frame(camera)
        publisher = node.publisher(key, QoS.SENSOR)
        node.log.info("publishing %s on %s at %.1f Hz", source.description, key, settings.rate_hz)
        depth = depth_capable(source)
        depth_out = None if depth is None else DepthOut(node, camera, depth, settings)
        _announce(announcements, camera, settings, depth=depth is not None)
        node.ready()
        _publish(camera, settings, node, source, publisher, depth_out, announcements, stop, on_bad)
    return 0


def _announce(
    announcements: CameraAnnouncements, camera: str, settings: CameraSettings, *, depth: bool
) -> None:
    width, height = settings.resize
    announcements.announce(camera, settings, width=width, height=height, depth=depth)


def _publish(
    camera: str,
    settings: CameraSettings,
    node: Node,
    source: FrameSource,
    publisher: Publisher,
    depth_out: DepthOut | None,
    announcements: CameraAnnouncements,
    stop: threading.Event,
    on_bad: Callable[[ImageError], None],
) -> None:
    """Read and publish a frame (its depth first) every ``1 / rate_hz`` until ``stop`` or the
    source's end."""
    period = 1.0 / settings.rate_hz
    next_t = mono_s()
    while not stop.is_set():
        try:
            image = source.read()
            if image is None:
                if not stop.is_set():  # else stopped while a lost device was awaited
                    node.log.info("source ended")
                break
            # The header's stamp is the capture stamp every later latency is measured
            # from: taken as the image is read, before resizing and encoding.
            header = node.header(frame_id=settings.frame_id)
            if depth_out is not None:
                # Before its colour frame: a detector that takes the colour frame as
                # it comes finds its depth already there.
                depth_out.publish(header)
            frame = image_to_frame(
                resize(image, settings.resize),
                header,
                jpeg_quality=settings.jpeg_quality,
            )
            publisher.put(frame.encode())
            announcements.saw(camera, frame.width, frame.height)
            node.counters.add(contract.FRAMES_OUT)
        except (ImageError, ValueError) as exc:
            # An unreadable file, or an image larger than a Frame may carry: skip it.
            on_bad(ImageError(f"{source.description}: {exc}"))
        node.publish_counters()
        next_t += period
        # Never burst to catch up after a stall: a late frame is better than a flood.
        next_t = max(next_t, mono_s())
        stop.wait(next_t - mono_s())


class DepthOut:
    """Publishes the depth of each colour frame, with that frame's header, resized with it
    (``camera.resize``). Depth that cannot be used is logged and counted (``bad_depth``), a
    frame without depth counted (``depth_missing``): the colour frame goes out either way."""

    def __init__(
        self, node: Node, camera: str, source: DepthCapable, settings: CameraSettings
    ) -> None:
        key = node.keys.depth(camera)
        self._node = node
        self._publisher = node.publisher(key, QoS.SENSOR)
        self._source = source
        self._settings = settings
        node.log.info("with depth aligned to it on %s", key)

    def publish(self, header: Header) -> None:
        """The depth of the frame read last, with ``header``, that frame's."""
        source = self._source
        try:
            image = source.depth()
            if image is None:
                self._node.counters.add(contract.DEPTH_MISSING)
                return
            message = to_depth_frame(
                resized(image, self._settings.resize),
                header,
                range_min_m=self._settings.depth_min_m,
                range_max_m=self._settings.depth_max_m,
            )
        except (ImageError, ValueError) as exc:
            self._node.reject(contract.BAD_DEPTH, f"{source.description}: {exc}")
            return
        self._publisher.put(message.encode())
        self._node.counters.add(contract.DEPTH_OUT)


def _with_depth(source: FrameSource, settings: CameraSettings) -> FrameSource:
    """``source`` paired with the depth PNGs of ``camera.depth_source``, when it names any."""
    if not settings.depth_source:
        return source
    return with_depth_folder(
        source,
        settings.depth_source,
        scale_m=settings.depth_scale_m,
        intrinsics=settings.intrinsics,
        hfov_deg=settings.hfov_deg,
    )


def _reopening(
    source: FrameSource,
    settings: CameraSettings,
    node: Node,
    stop: threading.Event,
    opener: Opener = open_source,
) -> FrameSource:
    """A live source wrapped to be reopened when it stops (counted: ``source_lost``,
    ``source_reopened``, ``source_reopen_failed``); any other source as it is."""
    if not source.live:
        return source

    def lost(line: str) -> None:
        node.counters.add(contract.SOURCE_LOST)
        node.log.warning("%s", line)

    def reopened(line: str) -> None:
        node.counters.add(contract.SOURCE_REOPENED)
        node.log.warning("%s", line)

    def failed(line: str) -> None:
        node.reject(contract.SOURCE_REOPEN_FAILED, line)  # one per period: rate-limited

    return ReopeningSource(
        source,
        lambda: opener(settings.source, loop=settings.loop),
        period_s=settings.reopen_period_s,
        stop=stop,
        hooks=ReopenHooks(
            lost=lost, failed=failed, reopened=reopened, heartbeat=node.publish_counters
        ),
    )
