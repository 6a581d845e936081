"""Conversions between OpenCV images (BGR uint8, HxWx3) and Frame messages. No I/O."""

from __future__ import annotations

from typing import cast

import cv2
import numpy as np

from common.errors import ImageError
from common.images import Image
from common.messages import Frame, Header


def image_to_frame(image: Image, header: Header, *, jpeg_quality: int = 0) -> Frame:
    """Wrap a BGR (HxWx3) or grey (HxW) image as a Frame: raw, or JPEG when quality > 0."""
    h, w = image.shape[:2]
    if jpeg_quality > 0:
        ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
        if not ok:
            raise ImageError(f"cannot JPEG-encode a {w}x{h} image")
        return Frame(header=header, encoding="jpeg", width=w, height=h, data=buf.tobytes())
    encoding = "mono8" if image.ndim == 2 else "bgr8"
    data = np.ascontiguousarray(image).tobytes()
    return Frame(header=header, encoding=encoding, width=w, height=h, data=data)


# JPEG start-of-frame markers (baseline, progressive, lossless, arithmetic): they carry the size.
_SOF_MARKERS = frozenset(
    {*range(0xC0, 0xC4), *range(0xC5, 0xC8), *range(0xC9, 0xCC), *range(0xCD, 0xD0)}
)
# Markers that stand alone, with no length field after them.
_STANDALONE = frozenset({0x01, *range(0xD0, 0xD9)})


def jpeg_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a JPEG's start-of-frame header, without decoding; None if absent.

    Decoding first and checking after would let a tiny file claiming 20000x20000 pixels make
    the decoder allocate gigabytes.
    """
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _STANDALONE:
            i += 2
            continue
        length = int.from_bytes(data[i + 2 : i + 4], "big")
        if marker in _SOF_MARKERS:
            if i + 9 > len(data):
                return None
            height = int.from_bytes(data[i + 5 : i + 7], "big")
            width = int.from_bytes(data[i + 7 : i + 9], "big")
            return width, height
        if marker == 0xDA or length < 2:  # start of scan before any frame header
            return None
        i += 2 + length
    return None


def frame_to_bgr(frame: Frame) -> Image:
    """The frame's pixels as a BGR uint8 image; raises ImageError for a corrupt JPEG."""
    if frame.encoding == "jpeg":
        size = jpeg_size(frame.data)
        if size is None:
            raise ImageError(f"frame {frame.header.seq}: corrupt JPEG (no frame header)")
        if size != (frame.width, frame.height):
            raise ImageError(
                f"frame {frame.header.seq}: JPEG header says {size[0]}x{size[1]}, "
                f"message says {frame.width}x{frame.height}"
            )
        buf = np.frombuffer(frame.data, dtype=np.uint8)
        image = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        if image is None:
            raise ImageError(f"frame {frame.header.seq}: corrupt JPEG ({len(frame.data)} bytes)")
        if image.shape[:2] != (frame.height, frame.width):
            raise ImageError(
                f"frame {frame.header.seq}: JPEG is {image.shape[1]}x{image.shape[0]}, "
                f"header says {frame.width}x{frame.height}"
            )
        return cast(Image, image)
    pixels = np.frombuffer(frame.data, dtype=np.uint8)
    if frame.encoding == "mono8":
        grey = pixels.reshape(frame.height, frame.width)
        return cast(Image, cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR))
    image = pixels.reshape(frame.height, frame.width, 3)
    if frame.encoding == "rgb8":
        return np.ascontiguousarray(image[:, :, ::-1])
    return image
