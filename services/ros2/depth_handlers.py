"""The bridge's depth handlers: a camera's depth images and CameraInfo in as DepthFrames, and
its detections' depth columns out as Detection3DArray. No bus: each is handed a ``Tally`` and a
``put``, so a unit test calls it directly (services/ros2/service.py wires them)."""

from __future__ import annotations

from collections.abc import Callable

from common.errors import DecodeError
from common.messages import CameraAnnouncement, Detections
from common.node import Put, Tally
from perception import Mounting
from rosmsg.convert import cdr_decode, cdr_encode
from rosmsg.depth import (
    CAMERA_INFO,
    DETECTION_3D_ARRAY,
    DepthIntrinsics,
    depth_encoding,
    depth_from_image,
    detections_3d_to_ros,
    has_3d,
    intrinsics_from_camera_info,
)
from rosmsg.images import IMAGE
from services.ros2 import contract
from stack.config import Config

#: The current announcement of a camera (None: not announced).
AnnouncementOf = Callable[[str], CameraAnnouncement | None]


class DepthInbound:
    """One camera's depth ``sensor_msgs/Image`` and its ``CameraInfo`` in, as DepthFrames
    through ``put``. Until a CameraInfo has come, depth images are held back (dropped and
    counted ``depth_without_info``): intrinsics are never guessed. The latest CameraInfo
    serves; an encoding other than 16UC1/32FC1 and a size other than the CameraInfo's are
    counted and dropped; garbage is bad input on its topic."""

    def __init__(
        self, config: Config, tally: Tally, put: Put, *, depth_topic: str, info_topic: str
    ) -> None:
        self.distro = config.ros2.distro
        self.tally = tally
        self.put = put
        self.depth_topic = depth_topic
        self.info_topic = info_topic
        # Replaced whole by the CameraInfo thread, read by the depth one: no lock needed.
        self.intrinsics: DepthIntrinsics | None = None

    def on_info(self, key: str, cdr: memoryview) -> None:
        try:
            intr = intrinsics_from_camera_info(cdr_decode(self.distro, CAMERA_INFO, cdr))
        except DecodeError as exc:
            self.tally.bad_input(key, exc, topic=self.info_topic)
            return
        self.intrinsics = intr
        self.tally.counters.add(contract.DEPTH_INFO_IN)

    def on_depth(self, key: str, cdr: memoryview) -> None:
        try:
            msg = cdr_decode(self.distro, IMAGE, cdr)
        except DecodeError as exc:
            self.tally.bad_input(key, exc, topic=self.depth_topic)
            return
        if depth_encoding(msg) is None:
            self.tally.reject(
                contract.DEPTH_BAD_ENCODING,
                f"depth image on {self.depth_topic} in {str(msg.encoding)!r}, not 16UC1 or 32FC1",
                key=key,
            )
            return
        intr = self.intrinsics
        if intr is None:
            self.tally.reject(
                contract.DEPTH_WITHOUT_INFO,
                f"depth image on {self.depth_topic} before any CameraInfo on {self.info_topic}",
                key=key,
            )
            return
        if (int(msg.width), int(msg.height)) != (intr.width, intr.height):
            self.tally.reject(
                contract.DEPTH_SIZE_MISMATCH,
                f"depth image on {self.depth_topic} is {msg.width}x{msg.height}, its CameraInfo "
                f"{intr.width}x{intr.height}",
                key=key,
            )
            return
        try:
            frame = depth_from_image(msg, intr, source=self.tally.service)
        except DecodeError as exc:
            self.tally.bad_input(key, exc, topic=self.depth_topic)
            return
        self.put(frame.encode())
        self.tally.counters.add(contract.DEPTH_OUT)


class Detections3DToRos:
    """The detections of ``camera`` that carry depth columns out as vision_msgs/
    Detection3DArray CDR through ``put``: in the camera's optical frame, or with
    ``ros2.detections_3d_frame`` in that robot frame by the camera's current announcement
    (``announced``). Detections without depth columns send nothing; rows of unknown depth are
    left out (counted ``detections_3d_unknown``)."""

    def __init__(
        self, config: Config, tally: Tally, put: Put, camera: str, announced: AnnouncementOf
    ) -> None:
        self.distro = config.ros2.distro
        self.frame_id = config.ros2.detections_3d_frame
        self.tally = tally
        self.put = put
        self.camera = camera
        self.announced = announced
        self.key = tally.keys.detections(camera)

    def on_detections(self, payload: bytes) -> None:
        dets = self.tally.decode(self.key, Detections.decode, payload)
        if dets is None or not has_3d(dets):
            return
        mount: Mounting | None = None
        if self.frame_id:
            announcement = self.announced(self.camera)
            if announcement is None:
                self.tally.reject(
                    contract.DETECTIONS_3D_UNMOUNTED,
                    f"no 3D detections of camera {self.camera!r} in {self.frame_id}: the camera "
                    "is not announced, so its mounting is unknown",
                    key=self.key,
                )
                return
            mount = Mounting.of(announcement)
        msg, unknown = detections_3d_to_ros(self.distro, dets, frame_id=self.frame_id, mount=mount)
        self.put(cdr_encode(self.distro, DETECTION_3D_ARRAY, msg))
        self.tally.counters.add(contract.DETECTIONS_3D_OUT)
        if unknown:
            self.tally.counters.add(contract.DETECTIONS_3D_UNKNOWN, unknown)
