"""Frame sources: a scikit-image sample, an image, a folder of images, a video, a device.

Each source yields BGR uint8 images. Opening a source that does not exist raises ConfigError
with one line; a source that ends (a video without ``loop``) returns None from ``read``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Protocol, cast

import cv2

from common.errors import ConfigError, ImageError
from common.images import IMAGE_EXTENSIONS, Image, list_images, load_image, load_sample


class FrameSource(Protocol):
    """Anything that produces BGR frames."""

    description: str

    def read(self) -> Image | None:
        """The next frame, or None when the source has ended."""
        ...

    def close(self) -> None: ...


class StillSource:
    """One image, repeated forever (a sample photo or an image file)."""

    def __init__(self, image: Image, description: str) -> None:
        self._image = image
        self.description = description

    def read(self) -> Image | None:
        return self._image

    def close(self) -> None:
        return None


class FolderSource:
    """The images of a folder in name order, looped. Unreadable files are skipped and counted."""

    def __init__(self, folder: Path, on_bad: Callable[[ImageError], None]) -> None:
        self._paths = list_images([folder])
        if not self._paths:
            raise ConfigError(f"{folder}: no images ({', '.join(sorted(IMAGE_EXTENSIONS))})")
        self._i = 0
        self._on_bad = on_bad
        self.description = f"folder {folder} ({len(self._paths)} images)"

    def read(self) -> Image | None:
        for _ in range(len(self._paths)):
            path = self._paths[self._i % len(self._paths)]
            self._i += 1
            try:
                return load_image(path)
            except ImageError as exc:
                self._on_bad(exc)
        raise ImageError(f"{self.description}: no readable image left")

    def close(self) -> None:
        return None


class CaptureSource:
    """A video file or a camera device through OpenCV's VideoCapture."""

    def __init__(self, target: str | int, description: str, *, loop: bool) -> None:
        self._cap = cv2.VideoCapture(target)
        if not self._cap.isOpened():
            raise ConfigError(f"cannot open {description}")
        self._loop = loop and isinstance(target, str)
        self.description = description

    def read(self) -> Image | None:
        ok, image = self._cap.read()
        if not ok and self._loop:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, image = self._cap.read()
        return cast(Image, image) if ok else None

    def close(self) -> None:
        self._cap.release()


def open_source(
    spec: str, *, loop: bool = True, on_bad: Callable[[ImageError], None] | None = None
) -> FrameSource:
    """Open the source named by ``spec`` (see CameraSettings.source for the forms)."""
    if spec.startswith("sample:"):
        name = spec.removeprefix("sample:")
        return StillSource(load_sample(name), f"scikit-image sample {name!r}")
    if spec.startswith("device:"):
        dev = spec.removeprefix("device:")
        target: str | int = int(dev) if dev.isdigit() else dev
        return CaptureSource(target, f"camera device {dev}", loop=False)
    path = Path(spec).expanduser()
    if not path.exists():
        raise ConfigError(f"camera source {spec!r}: no such file, folder or 'sample:'/'device:'")
    if path.is_dir():
        return FolderSource(path, on_bad or (lambda exc: None))
    if path.suffix.lower() in IMAGE_EXTENSIONS:
        try:
            return StillSource(load_image(path), f"image {path}")
        except ImageError as exc:
            raise ConfigError(str(exc)) from exc
    return CaptureSource(str(path), f"video {path}", loop=loop)


def resize(image: Image, size: tuple[int, int]) -> Image:
    """Resize to (width, height); (0, 0) keeps the image as it is."""
    if size == (0, 0) or (image.shape[1], image.shape[0]) == size:
        return image
    return cast(Image, cv2.resize(image, size, interpolation=cv2.INTER_AREA))
