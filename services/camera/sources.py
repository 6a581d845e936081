"""Frame sources: a scikit-image sample, an image, a folder of images, a video, a device, a
network stream (``rtsp://``, ``http://`` ...: OpenCV's FFmpeg reads it), or an RGB-D camera
(``realsense:``, ``oak:``: optional extras, imported only when named; see
:class:`DepthCapable`).

Each source yields BGR uint8 images. Opening a source that does not exist raises ConfigError
with one line; a source that ends (a video without ``loop``, an unplugged device) returns None
from ``read``. A source from which no frame at all can be read (a folder of corrupt files, a
video with no decodable frame, a device that gives nothing) raises ConfigError from ``read``:
waiting will not help, so the service ends with that line and the supervisor does not restart
it. A device or a network stream that gave frames and then stopped is ``live``: the service
reopens it (services/camera/reopen.py). A network stream that does not answer within
``STREAM_TIMEOUT_S`` is one line, never a hang.

The command line's ``detect`` opens videos and devices here too (:func:`is_stream`,
:func:`open_stream`), so both read the same ``device:``/path forms.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, cast

import cv2

from common.errors import ConfigError, ImageError
from common.images import IMAGE_EXTENSIONS, Image, list_images, load_image, load_sample

if TYPE_CHECKING:
    from services.camera.depth import DepthImage

#: File extensions taken for videos, even before the file exists (compared lower-case). Any
#: other existing file that is not an image is tried as a video too.
VIDEO_EXTENSIONS = frozenset(
    {".avi", ".m4v", ".mkv", ".mov", ".mp4", ".mpeg", ".mpg", ".ts", ".webm", ".wmv"}
)
_DEVICE_PREFIX = "device:"
#: RGB-D cameras with depth aligned to colour: ``realsense:`` (the first found) or
#: ``realsense:<serial>``; ``oak:`` or ``oak:<mxid or IP>``.
REALSENSE_PREFIX = "realsense:"
OAK_PREFIX = "oak:"
#: URL schemes read as network streams through OpenCV's FFmpeg backend.
STREAM_SCHEMES = ("rtsp", "rtsps", "rtmp", "http", "https", "udp", "tcp", "srt")
#: How long opening a network stream, or waiting for its next frame, may take.
STREAM_TIMEOUT_S = 5.0


class FrameSource(Protocol):
    """Anything that produces BGR frames. ``live``: a camera device, which may stop giving
    frames and come back (services/camera/reopen.py); False for stills, folders and videos."""

    description: str
    live: bool

    def read(self) -> Image | None:
        """The next frame, or None when the source has ended."""
        ...

    def close(self) -> None: ...


class DepthCapable(FrameSource, Protocol):
    """A source that also gives depth aligned to its colour frames (``has_depth`` True):
    ``depth()`` is the depth of the frame ``read`` returned last, None when that frame came
    without one; ImageError when its depth cannot be used."""

    has_depth: bool

    def depth(self) -> DepthImage | None: ...


def depth_capable(source: FrameSource) -> DepthCapable | None:
    """``source`` as a depth source, or None when it gives colour only."""
    if getattr(source, "has_depth", False):
        return cast(DepthCapable, source)
    return None


class StillSource:
    """One image, repeated forever (a sample photo or an image file)."""

    live = False

    def __init__(self, image: Image, description: str) -> None:
        self._image = image
        self.description = description

    def read(self) -> Image | None:
        return self._image

    def close(self) -> None:
        return None


class FolderSource:
    """The images of a folder in name order, looped. Unreadable files are skipped and counted."""

    live = False

    def __init__(self, folder: Path, on_bad: Callable[[ImageError], None]) -> None:
        self._paths = list_images([folder])
        if not self._paths:
            raise ConfigError(f"{folder}: no images ({', '.join(sorted(IMAGE_EXTENSIONS))})")
        self._i = 0
        self._on_bad = on_bad
        self.description = f"folder {folder} ({len(self._paths)} images)"
        self.last_path: Path | None = None  # the file of the image read last

    def read(self) -> Image | None:
        """The next readable image; ConfigError when a whole pass finds none (each unreadable
        file is handed to ``on_bad`` first)."""
        for _ in range(len(self._paths)):
            path = self._paths[self._i % len(self._paths)]
            self._i += 1
            try:
                image = load_image(path)
            except ImageError as exc:
                self._on_bad(exc)
                continue
            self.last_path = path
            return image
        raise ConfigError(f"{self.description}: not one of them is a readable image")

    def close(self) -> None:
        return None


class CaptureSource:
    """A video file or a camera device (``live``) through OpenCV's VideoCapture."""

    def __init__(
        self,
        target: str | int,
        description: str,
        *,
        loop: bool,
        live: bool = False,
        network: bool = False,
    ) -> None:
        _quiet_opencv()
        with _stderr_silenced():
            if network:
                ms = int(STREAM_TIMEOUT_S * 1000)
                timeouts = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC, ms]
                self._cap = cv2.VideoCapture(target, cv2.CAP_FFMPEG, timeouts)
            else:
                self._cap = cv2.VideoCapture(target)
        if not self._cap.isOpened():
            what = (
                f"no stream there, or none within {STREAM_TIMEOUT_S:g} s"
                if network
                else "no such device"
                if isinstance(target, int)
                else "not a readable video"
            )
            raise ConfigError(f"cannot open {description} ({what})")
        self._loop = loop
        self.description = description
        self.live = live
        self.frames_read = 0

    @property
    def fps(self) -> float:
        """The frame rate the source declares; 0.0 when it does not say (many webcams)."""
        fps = float(self._cap.get(cv2.CAP_PROP_FPS))
        return fps if fps > 0 and fps == fps else 0.0  # fps == fps: not NaN

    @property
    def frame_count(self) -> int:
        """The number of frames a video file declares; 0 when unknown (a device)."""
        count = self._cap.get(cv2.CAP_PROP_FRAME_COUNT)
        return int(count) if count > 0 else 0

    def read(self) -> Image | None:
        """The next frame; None at the end; ConfigError if not even a first frame decodes."""
        ok, image = self._cap.read()
        if not ok and self._loop and self.frames_read:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, image = self._cap.read()
        if not ok:
            if not self.frames_read:
                raise ConfigError(f"{self.description}: not one frame could be read")
            return None
        self.frames_read += 1
        return cast(Image, image)

    def close(self) -> None:
        self._cap.release()


def open_source(
    spec: str, *, loop: bool = True, on_bad: Callable[[ImageError], None] | None = None
) -> FrameSource:
    """Open the source named by ``spec`` (see CameraSettings.source for the forms)."""
    if spec.startswith(REALSENSE_PREFIX):
        from services.camera.realsense import open_realsense  # pyrealsense2: an extra

        return open_realsense(spec.removeprefix(REALSENSE_PREFIX))
    if spec.startswith(OAK_PREFIX):
        from services.camera.oak import open_oak  # depthai: an extra

        return open_oak(spec.removeprefix(OAK_PREFIX))
    if spec.startswith("sample:"):
        name = spec.removeprefix("sample:")
        return StillSource(load_sample(name), f"scikit-image sample {name!r}")
    if is_stream(spec):
        return open_stream(spec, loop=loop)
    path = Path(spec).expanduser()
    if not path.exists():
        raise ConfigError(f"{spec!r}: no such file or folder, nor 'sample:' or 'device:'")
    if path.is_dir():
        return FolderSource(path, on_bad or (lambda exc: None))
    if path.suffix.lower() in IMAGE_EXTENSIONS:
        try:
            return StillSource(load_image(path), f"image {path}")
        except ImageError as exc:
            raise ConfigError(str(exc)) from exc
    raise ConfigError(f"{spec!r}: neither an image, a video nor a folder")  # is_stream said no


def is_url(spec: str) -> bool:
    """Whether ``spec`` is a network stream's URL (``rtsp://host/path``, ``http://...``)."""
    scheme, sep, rest = spec.partition("://")
    return bool(sep and rest) and scheme.lower() in STREAM_SCHEMES


def is_stream(spec: str) -> bool:
    """Whether ``spec`` names a video file, a camera device or a network stream rather than
    images: a ``device:`` spec, a device file (``/dev/video0``), a stream URL, a video
    extension, or any other existing file that is not an image (tried as a video)."""
    if spec.startswith(_DEVICE_PREFIX) or is_url(spec):
        return True
    path = Path(spec).expanduser()
    suffix = path.suffix.lower()
    if _is_device(path) or suffix in VIDEO_EXTENSIONS:
        return True
    return path.is_file() and suffix not in IMAGE_EXTENSIONS


def open_stream(spec: str, *, loop: bool = False) -> CaptureSource:
    """Open a video file, a device (``device:0``, ``device:/dev/video0`` or ``/dev/video0``) or a
    network stream (``rtsp://...``); ConfigError with one line when it does not exist or cannot
    be opened. Devices and streams never loop; both are live (reopened when they stop)."""
    if is_url(spec):
        return CaptureSource(spec, f"network stream {spec}", loop=False, live=True, network=True)
    if spec.startswith(_DEVICE_PREFIX):
        dev = spec.removeprefix(_DEVICE_PREFIX)
        target: str | int = int(dev) if dev.isdigit() else dev
        if isinstance(target, str) and not Path(target).exists():
            raise ConfigError(f"camera device {dev}: no such device")
        return CaptureSource(target, f"camera device {dev}", loop=False, live=True)
    path = Path(spec).expanduser()
    if _is_device(path):
        if not path.exists():
            raise ConfigError(f"camera device {path}: no such device")
        return CaptureSource(str(path), f"camera device {path}", loop=False, live=True)
    if not path.is_file():
        raise ConfigError(f"video {spec}: no such file")
    return CaptureSource(str(path), f"video {path}", loop=loop)


def _is_device(path: Path) -> bool:
    """A device file, or a path in /dev that is missing (an unplugged camera)."""
    return path.is_char_device() or path.parent == Path("/dev")


@contextlib.contextmanager
def _stderr_silenced() -> Iterator[None]:
    """Silence the process's stderr (the file descriptor) for the block: OpenCV's own AVI
    reader prints a corrupt file's complaints with fprintf, past its log level."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _quiet_opencv() -> None:
    """Leave the error report to us: OpenCV and FFmpeg would otherwise print their own
    warnings (several lines) before our one line. A user's own setting is kept. FFmpeg reads
    its level when OpenCV first loads it, so this runs before the first capture opens."""
    if "OPENCV_LOG_LEVEL" not in os.environ:
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET


def resize(image: Image, size: tuple[int, int]) -> Image:
    """Resize to (width, height); (0, 0) keeps the image as it is."""
    if size == (0, 0) or (image.shape[1], image.shape[0]) == size:
        return image
    return cast(Image, cv2.resize(image, size, interpolation=cv2.INTER_AREA))
