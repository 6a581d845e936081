"""The viewer service: the stack's keys in, a Foxglove WebSocket server out.

Zenoh's callbacks convert the small messages (scan, command, controller status, truth) at
once; each camera's frames and detections only go into that camera's ``Pairing``, and the
viewer's own encoder thread turns each camera's newest pair into a JPEG and its annotations on
the camera's own channels at ``image_rate_hz``, and only while a client watches them. The
cameras' announcements say which have depth (their depth images: depth_feed.py) and where each
stands on the robot (the transforms under the 3D boxes: depth.py). Nothing here publishes on
the stack's keys but the viewer's counters.
"""

from __future__ import annotations

import errno
import threading
from collections.abc import Mapping
from contextlib import ExitStack

import foxglove
from foxglove.websocket import WebSocketServer

from common.announce import Announced, announced_cameras
from common.bus import Declared, undeclare_all
from common.clock import SYSTEM_CLOCK, Clock, mono_s
from common.contracts import MetricsAnswer
from common.credential_modes import check_folder, check_secret
from common.errors import ConfigError, ImageError
from common.keys import virtual_scan_camera
from common.messages import (
    CameraAnnouncement,
    ControllerStatus,
    Detections,
    Frame,
    GroundTruth,
    LaserScan,
    Twist,
)
from common.node import Node, Tally
from common.ports import holder_words
from common.queries import query_metrics
from common.security import viewer_token_file
from services.viewer import contract, convert, depth, scene
from services.viewer.channels import CameraChannels, Channels
from services.viewer.depth_feed import DepthFeed, Subscribe
from services.viewer.front import Front, make_check
from services.viewer.pairing import Pairing
from stack.config import Config

SERVER_NAME = "zenoh-yolo-stack"


def start_server(context: foxglove.Context, port: int = 0) -> WebSocketServer:
    """The Foxglove server, on a private loopback port that only the front relays to:
    ``port`` (``viewer.relay_port``), or one the system picks free (0)."""
    try:
        return foxglove.start_server(name=SERVER_NAME, host="127.0.0.1", port=port, context=context)
    except RuntimeError as exc:  # the SDK's error for an address it cannot bind
        if port:
            raise ConfigError(
                f"viewer.relay_port: cannot start the Foxglove server on 127.0.0.1:{port} "
                f"({exc}; {holder_words(port)}): set viewer.relay_port to a free port, or 0 "
                "for any"
            ) from exc
        raise ConfigError(f"viewer: cannot start the Foxglove server ({exc})") from exc


def viewer_token(config: Config) -> str | None:
    """The token clients must send under the secure profile; None under the default one."""
    if config.zenoh.auth == "none":
        return None
    path = viewer_token_file(config.zenoh.credentials_path)
    check_folder(path.parent)
    check_secret(path)
    try:
        token = path.read_text().strip()
    except OSError as exc:
        raise ConfigError(
            f"viewer: cannot read the viewer token {path} ({exc.strerror}); credentials made "
            "before it existed lack it: write one with umask 077; python3 -c 'import secrets; "
            f"print(secrets.token_urlsafe(24))' > {path}"
        ) from exc
    if not token:
        raise ConfigError(f"viewer: the viewer token {path} is empty")
    return token


def start_front(config: Config, inner_port: int) -> Front:
    v = config.viewer
    check = make_check(v.allowed_origins, viewer_token(config))
    front = Front(v.host, v.port, inner_port, check, v.request_timeout_s)
    try:
        front.start()
    except OSError as exc:
        where = f"viewer.port: cannot listen on {v.host}:{v.port}"
        if exc.errno == errno.EADDRINUSE:
            raise ConfigError(
                f"{where}: port {v.port} is taken ({holder_words(v.port)}): set viewer.port to "
                "a free port"
            ) from exc
        raise ConfigError(f"{where} ({exc})") from exc
    return front


class CameraView:
    """One camera in the view: its frames paired with their detections (``pairing``), sent as
    a JPEG and its annotations on the camera's own channels."""

    def __init__(self, viewer: Viewer, camera: str, channels: CameraChannels) -> None:
        self.viewer = viewer
        self.camera = camera
        self.channels = channels
        self.pairing = Pairing()
        self._frame_key = viewer.tally.keys.frame(camera)
        self._detections_key = viewer.tally.keys.detections(camera)

    def on_frame(self, payload: bytes) -> None:
        frame = self.viewer.tally.decode(self._frame_key, Frame.decode, payload)
        if frame is None:
            return
        self.viewer.tally.counters.add(contract.FRAMES_IN)
        self.pairing.add_frame(frame)

    def on_detections(self, payload: bytes) -> None:
        tally = self.viewer.tally
        dets = tally.decode(self._detections_key, Detections.decode, payload)
        if dets is None:
            return
        if not self.pairing.add_detections(dets, mono_s()):
            tally.counters.add(contract.DETECTIONS_UNPAIRED)
        self.viewer.on_boxes(self.camera, dets)

    def send(self, frame: Frame, dets: Detections | None) -> None:
        """Send ``frame`` as a JPEG, and ``dets`` as its annotations; a frame whose pixels
        cannot be read is bad input, one Foxglove cannot carry is counted as unshowable."""
        viewer = self.viewer
        v = viewer.settings
        try:
            image = convert.compressed_image(frame, v.jpeg_quality, v.max_image_width)
            marks = None
            if dets is not None:
                w, h = convert.scaled_size(frame.width, frame.height, v.max_image_width)
                marks = convert.image_annotations(dets, w, h, viewer.locked_on(self.camera))
        except ImageError as exc:
            viewer.tally.bad_input("frame", exc)
            return
        except ValueError as exc:
            viewer.unshowable("image", exc)
            return
        at = frame.header.stamp_ns
        self.channels.image.log(image, log_time=at)
        viewer.tally.counters.add(contract.IMAGES_OUT)
        if marks is not None:
            self.channels.annotations.log(marks, log_time=at)


class Viewer:
    """The viewer's handlers and what they and the threads share: the channels, each camera's
    view (``cameras``, the first camera first), the latest status and the robot's path. Each
    ``on_*`` takes a payload as it came off the bus; garbage is counted as bad input on its
    key. ``subscribe`` is how it hears the depth images it shows (``Node.subscribe``; None:
    none)."""

    def __init__(
        self,
        tally: Tally,
        channels: Channels,
        config: Config,
        subscribe: Subscribe | None = None,
        *,
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        self.tally = tally
        self.channels = channels
        self.settings = config.viewer
        self.clock = clock
        self.locked_track = -1
        self.locked_camera = ""  # the camera that sees the target: track ids are per camera
        self.trail = scene.PathTrail(self.settings.path_points)
        self._scene_period_s = 1.0 / self.settings.scene_rate_hz
        self._next_scene = 0.0
        self.cameras = {
            name: CameraView(self, name, channels.cameras[name]) for name in config.all_cameras
        }
        #: The viewer's cameras as their sources announce them now (depth, mounting).
        self.announced: dict[str, CameraAnnouncement] = {}
        self._announced_lock = threading.Lock()
        self.depth = (
            None if subscribe is None else DepthFeed(tally, channels, subscribe, self.cameras)
        )
        self._next_boxes = dict.fromkeys(self.cameras, -float("inf"))

    def set_announced(self, announced: Mapping[str, CameraAnnouncement]) -> None:
        """The cameras announced now; only the viewer's own are kept (a made-up name on the
        bus grows nothing)."""
        with self._announced_lock:
            self.announced = {c: a for c, a in announced.items() if c in self.cameras}

    def on_boxes(self, camera: str, dets: Detections) -> None:
        """``camera``'s detections as 3D boxes, if they carry depth and a client watches the
        boxes, at most ``image_rate_hz`` times a second per camera."""
        if not depth.has_depth(dets) or not self.channels.boxes.has_sinks():
            return
        now = self.clock.mono_s()
        if now < self._next_boxes[camera]:
            return
        self._next_boxes[camera] = now + 1.0 / self.settings.image_rate_hz
        with self._announced_lock:
            frame_id = depth.optical_frames(self.announced).get(camera, f"{camera}_optical")
        try:
            boxes = depth.boxes_scene(
                dets, camera, frame_id, self.locked_on(camera), self.settings.boxes_lifetime_s
            )
        except ValueError as exc:
            self.unshowable("3D boxes", exc)
            return
        self.channels.boxes.log(boxes, log_time=dets.header.stamp_ns)

    def unshowable(self, what: str, error: ValueError) -> None:
        """A message that decoded but that Foxglove cannot carry (a stamp past 2106)."""
        self.tally.reject(contract.UNSHOWABLE, f"{what} not shown: {error}")

    def on_scan(self, payload: bytes) -> None:
        scan = self.tally.decode(self.tally.keys.scan(), LaserScan.decode, payload)
        if scan is None:
            return
        try:
            shown = convert.laser_scan(scan)
        except ValueError as exc:
            self.unshowable("scan", exc)
            return
        self.channels.scan.log(shown, log_time=scan.header.stamp_ns)

    def on_virtual_scan(self, key: str, payload: bytes) -> None:
        """A depth camera's virtual scan (``<prefix>/scan/virtual/<camera>``), on its own
        channel beside the laser's."""
        camera = virtual_scan_camera(key)
        scan = self.tally.decode(key, LaserScan.decode, payload)
        if camera is None or scan is None:
            return
        try:
            shown = convert.laser_scan(scan)
        except ValueError as exc:
            self.unshowable("virtual scan", exc)
            return
        self.channels.virtual_scan(camera).log(shown, log_time=scan.header.stamp_ns)

    def on_twist(self, payload: bytes) -> None:
        twist = self.tally.decode(self.tally.keys.cmd_vel(), Twist.decode, payload)
        if twist is None:
            return
        self.channels.cmd_vel.log(convert.twist_json(twist), log_time=twist.header.stamp_ns)

    def locked_on(self, camera: str) -> int:
        """The controller's locked track id on ``camera``'s image, -1 for none: each camera's
        tracker numbers its own tracks, so the same id on another camera is another object.
        A status that names no camera (a controller from before several cameras) locks on
        the first camera's image."""
        locked_camera = self.locked_camera or next(iter(self.cameras))
        return self.locked_track if camera == locked_camera else -1

    def on_status(self, payload: bytes) -> None:
        key = self.tally.keys.controller_status()
        status = self.tally.decode(key, ControllerStatus.decode, payload)
        if status is None:
            return
        self.locked_track = status.track_id
        self.locked_camera = status.camera
        self.channels.controller.log(convert.status_json(status), log_time=status.header.stamp_ns)

    def on_truth(self, payload: bytes) -> None:
        truth = self.tally.decode(self.tally.keys.sim_truth(), GroundTruth.decode, payload)
        if truth is None:
            return
        at = truth.header.stamp_ns
        try:
            pose = scene.transforms(truth)
        except ValueError as exc:
            self.unshowable("ground truth", exc)
            return
        self.trail.add(truth.robot[0], truth.robot[1])
        self.channels.tf.log(pose, log_time=at)
        now = mono_s()
        if now >= self._next_scene:
            self._next_scene = now + self._scene_period_s
            self.channels.scene.log(scene.scene(truth, self.trail.points()), log_time=at)

    def encode_loop(self, stop: threading.Event) -> None:
        """Send each camera's newest image and its annotations, its depth image and where it
        stands, at most ``image_rate_hz`` a second per camera."""
        period = 1.0 / self.settings.image_rate_hz
        dropped = dict.fromkeys(self.cameras, 0)
        while not stop.wait(period):
            for name, view in self.cameras.items():
                item = view.pairing.take(mono_s())
                if view.pairing.dropped > dropped[name]:
                    self.tally.counters.add(
                        contract.IMAGES_DROPPED, view.pairing.dropped - dropped[name]
                    )
                    dropped[name] = view.pairing.dropped
                if item is not None and view.channels.watched():
                    view.send(*item)
            self.send_depth()

    def send_depth(self) -> None:
        """One turn of the encoder for depth: hear the depth a client watches, send each
        camera's newest depth image, and the transforms from the robot to each camera announced
        (the 3D boxes are drawn in them), resent each turn for clients that join later."""
        with self._announced_lock:
            announced = dict(self.announced)
        if self.depth is not None:
            self.depth.update(announced)
            self.depth.send(self.settings.max_image_width, self.unshowable)
        if announced and self.channels.tf.has_sinks():
            at = self.clock.wall_ns()
            self.channels.tf.log(depth.camera_transforms(announced, at), log_time=at)

    def on_metrics(self, answer: MetricsAnswer) -> None:
        """The metrics service's answer to the metrics loop's question, shown."""
        self.channels.metrics.log(convert.metrics_json(answer), log_time=answer["stamp_ns"])


def metrics_loop(node: Node, viewer: Viewer, stop: threading.Event) -> None:
    """Ask the metrics service ``metrics_rate_hz`` times a second; show its figures."""
    period = 1.0 / viewer.settings.metrics_rate_hz
    while not stop.wait(period):
        answer = query_metrics(node.bus, node.keys, min(period, 1.0))
        if answer is not None:
            viewer.on_metrics(answer)


def run(config: Config, stop: threading.Event) -> int:
    """Serve the live view until ``stop`` is set."""
    context = foxglove.Context()
    channels = Channels(context, list(config.all_cameras))
    with ExitStack() as closing:
        node = closing.enter_context(Node("viewer", config))
        server = start_server(context, config.viewer.relay_port)
        closing.callback(server.stop)
        front = start_front(config, server.port)
        closing.callback(front.stop)
        viewer = Viewer(node, channels, config, node.subscribe, clock=node.clock)
        if viewer.depth is not None:
            closing.callback(viewer.depth.close)
        threads = [
            threading.Thread(target=viewer.encode_loop, args=(stop,), name="encode", daemon=True),
            threading.Thread(
                target=metrics_loop, args=(node, viewer, stop), name="metrics", daemon=True
            ),
        ]
        closing.callback(_join, threads)  # after the subscriptions are gone
        heard = _watch_cameras(node, viewer)
        closing.callback(heard.close)
        subs = _subscribe(node, viewer)
        closing.callback(undeclare_all, subs)
        for t in threads:
            t.start()
        node.log.info("foxglove live view on ws://%s:%d", config.viewer.host, config.viewer.port)
        node.ready()
        closing.callback(node.log.info, "stopping")  # first, however it ends
        while not stop.wait(0.5):
            node.publish_counters()
    return 0


def _watch_cameras(node: Node, viewer: Viewer) -> Announced[CameraAnnouncement]:
    """The cameras announced, each change shown."""
    heard: Announced[CameraAnnouncement] | None = None

    def on_cameras() -> None:
        if heard is not None:  # else called back while it is being declared
            viewer.set_announced(heard.current())

    heard = announced_cameras(
        node.bus, node.keys, on_cameras, lambda k, e: node.bad_input(k, e, topic="announcement")
    )
    on_cameras()
    return heard


def _subscribe(node: Node, viewer: Viewer) -> list[Declared]:
    """Each camera's frames and detections, the scan and the depth cameras' virtual scans,
    the commands, the controller's status and the simulator's truth, to the viewer."""
    keys = node.keys
    subs = [
        sub
        for camera, view in viewer.cameras.items()
        for sub in (
            node.subscribe(keys.frame(camera), view.on_frame),
            node.subscribe(keys.detections(camera), view.on_detections),
        )
    ]
    subs += [
        node.subscribe(keys.scan(), viewer.on_scan),
        node.subscribe_keyed(keys.all_virtual_scans(), viewer.on_virtual_scan),
        node.subscribe(keys.cmd_vel(), viewer.on_twist),
        node.subscribe(keys.controller_status(), viewer.on_status),
        node.subscribe(keys.sim_truth(), viewer.on_truth),
    ]
    return subs


def _join(threads: list[threading.Thread]) -> None:
    for t in threads:
        if t.is_alive():
            t.join(timeout=2.0)
