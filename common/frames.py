"""Conversions between OpenCV images (BGR uint8, HxWx3) and Frame messages. No I/O."""

from __future__ import annotations

from typing import cast

import cv2
import numpy as np

from common.errors import ImageError, ImageTooLarge
from common.images import Image
from common.limits import DEFAULT_MAX_FRAME_PIXELS
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


def jpeg_header(data: bytes) -> tuple[int, int, int] | None:
    """(width, height, components) from a JPEG's start-of-frame header, without decoding;
    None if there is none before the image data.

    Decoding first and checking after would let a tiny file claiming 16384x16384 pixels make
    the decoder allocate gigabytes (a decompression bomb).
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
            if i + 10 > len(data):
                return None
            height = int.from_bytes(data[i + 5 : i + 7], "big")
            width = int.from_bytes(data[i + 7 : i + 9], "big")
            return width, height, data[i + 9]
        if marker == 0xDA or length < 2:  # start of scan before any frame header
            return None
        i += 2 + length
    return None


def jpeg_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a JPEG's start-of-frame header (:func:`jpeg_header`)."""
    header = jpeg_header(data)
    return None if header is None else header[:2]


def check_pixel_budget(frame: Frame, max_pixels: int) -> None:
    """Raise ImageTooLarge when ``frame`` claims more than ``max_pixels`` (width x height).

    Only the message's sizes are read, so this is cheap enough for Zenoh's callback; a JPEG's
    own header is held to those sizes before it is decoded (:func:`frame_to_bgr`).
    """
    pixels = frame.width * frame.height
    if pixels > max_pixels:
        raise ImageTooLarge(
            f"frame {frame.header.seq}: {frame.width}x{frame.height} ({pixels} pixels) is over "
            f"the budget of {max_pixels} pixels (detector.max_frame_pixels); not decoded"
        )


def frame_to_bgr(frame: Frame, max_pixels: int = DEFAULT_MAX_FRAME_PIXELS) -> Image:
    """The frame's pixels as a BGR uint8 image.

    Raises ImageTooLarge, before decoding anything, for a frame over ``max_pixels``, and
    ImageError for a corrupt JPEG or one whose own header disagrees with the message.
    """
    check_pixel_budget(frame, max_pixels)
    if frame.encoding == "jpeg":
        header = jpeg_header(frame.data)
        if header is None:
            raise ImageError(f"frame {frame.header.seq}: corrupt JPEG (no frame header)")
        size, components = header[:2], header[2]
        if components not in (1, 3, 4):  # grey, YCbCr or RGB, CMYK: nothing else is a photo
            raise ImageError(f"frame {frame.header.seq}: JPEG with {components} components")
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
