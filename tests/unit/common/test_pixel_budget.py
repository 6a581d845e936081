"""The pixel budget is checked from the headers, before a single pixel is decoded."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from common.errors import ConfigError, ImageError, ImageTooLarge
from common.frames import check_pixel_budget, frame_to_bgr, image_to_frame, jpeg_header
from common.images import load_sample
from common.limits import DEFAULT_MAX_FRAME_PIXELS
from common.messages import Frame, Header
from services.detector.contract import DetectorSettings

HEADER = Header(stamp_ns=1, frame_id="cam", seq=7, source="test")


def jpeg(width: int, height: int, grey: bool = False) -> bytes:
    shape = (height, width) if grey else (height, width, 3)
    ok, buf = cv2.imencode(".jpg", np.full(shape, 90, np.uint8))
    assert ok
    return buf.tobytes()


def bomb() -> bytes:
    """A small real JPEG whose frame header claims 16384x16384 (as a decompression bomb)."""
    data = jpeg(64, 64)
    sof = data.index(b"\xff\xc0")
    return data[: sof + 5] + (16384).to_bytes(2, "big") * 2 + data[sof + 9 :]


def test_jpeg_header_reads_real_jpegs_and_refuses_non_jpegs() -> None:
    photo = image_to_frame(load_sample("astronaut"), HEADER, jpeg_quality=80)
    assert jpeg_header(photo.data) == (512, 512, 3)
    assert jpeg_header(jpeg(40, 30, grey=True)) == (40, 30, 1)
    assert jpeg_header(b"\xff\xd8\xff\xda\x00\x08") is None  # scan before any frame header
    assert jpeg_header(b"\x89PNG\r\n\x1a\n") is None
    assert jpeg_header(jpeg(40, 30)[:20]) is None  # cut before the frame header


def test_a_bomb_is_refused_without_decoding() -> None:
    data = bomb()
    assert len(data) < 1000  # the reported one was 729 bytes
    assert jpeg_header(data) == (16384, 16384, 3)
    frame = Frame(header=HEADER, encoding="jpeg", width=16384, height=16384, data=data)
    start = time.perf_counter()
    with pytest.raises(ImageTooLarge, match=r"16384x16384 \(268435456 pixels\) is over"):
        frame_to_bgr(frame)
    assert time.perf_counter() - start < 0.1  # decoding it took about 2 s and 1.5 GB


def test_raw_frames_have_the_same_budget_and_real_ones_pass() -> None:
    raw = Frame(header=HEADER, encoding="mono8", width=300, height=200, data=bytes(60_000))
    with pytest.raises(ImageTooLarge):
        check_pixel_budget(raw, 59_999)
    check_pixel_budget(raw, 60_000)
    assert frame_to_bgr(raw, 60_000).shape == (200, 300, 3)
    big = Frame(header=HEADER, encoding="jpeg", width=7680, height=4320, data=jpeg(8, 8))
    check_pixel_budget(big, DEFAULT_MAX_FRAME_PIXELS)  # 8K UHD fits the default


def test_a_jpeg_with_odd_components_is_corrupt() -> None:
    data = bytearray(jpeg(16, 16))
    data[data.index(b"\xff\xc0") + 9] = 9
    frame = Frame(header=HEADER, encoding="jpeg", width=16, height=16, data=bytes(data))
    with pytest.raises(ImageError, match="9 components"):
        frame_to_bgr(frame)


def test_the_budget_setting_is_bounded() -> None:
    assert DetectorSettings().max_frame_pixels == 1 << 25
    with pytest.raises(ConfigError, match=r"detector\.max_frame_pixels"):
        DetectorSettings(max_frame_pixels=0)
