"""Letterbox geometry, the round trip back to image pixels, and reuse of the input buffer."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from common.errors import ImageError
from common.letterbox import (
    PAD_VALUE,
    Preprocessor,
    check_bgr_image,
    compute_letterbox,
    unletterbox,
)

# (source width, source height) x (network width, network height): wide, tall, square, tiny,
# extreme, and a non-square network input.
SIZES = [
    ((451, 300), (640, 640)),
    ((300, 451), (640, 640)),
    ((640, 640), (640, 640)),
    ((1920, 1080), (640, 640)),
    ((37, 23), (640, 640)),
    ((10, 1000), (640, 640)),
    ((1280, 720), (640, 384)),
]


def reference_blob(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """The straightforward letterbox the fast path must equal: fresh canvas, RGB, /255, CHW."""
    lb = compute_letterbox(image.shape[1], image.shape[0], width, height)
    canvas = np.full((height, width, 3), PAD_VALUE, np.uint8)
    resized = cv2.resize(image, (lb.resized_width, lb.resized_height))
    canvas[lb.pad_y : lb.pad_y + lb.resized_height, lb.pad_x : lb.pad_x + lb.resized_width] = (
        resized
    )
    return canvas[:, :, ::-1].transpose(2, 0, 1).astype(np.float32) / 255.0


@pytest.mark.parametrize(("src", "dst"), SIZES)
def test_letterbox_fits_and_centres(src: tuple[int, int], dst: tuple[int, int]) -> None:
    lb = compute_letterbox(*src, *dst)
    assert lb.resized_width <= dst[0] and lb.resized_height <= dst[1]
    # One side fills the canvas; the other keeps the aspect ratio.
    assert lb.resized_width == dst[0] or lb.resized_height == dst[1]
    assert lb.resized_width == pytest.approx(src[0] * lb.scale, abs=1)
    assert lb.resized_height == pytest.approx(src[1] * lb.scale, abs=1)
    assert abs(2 * lb.pad_x + lb.resized_width - dst[0]) <= 1
    assert abs(2 * lb.pad_y + lb.resized_height - dst[1]) <= 1


@pytest.mark.parametrize(("src", "dst"), SIZES)
def test_round_trip_of_a_drawn_rectangle(src: tuple[int, int], dst: tuple[int, int]) -> None:
    w, h = src
    box = np.array([[0.2 * w, 0.3 * h, 0.7 * w, 0.9 * h]], np.float32)
    image = np.zeros((h, w, 3), np.uint8)
    x1, y1, x2, y2 = np.rint(box[0]).astype(int)
    image[y1:y2, x1:x2] = 255
    pre = Preprocessor(dst[1], dst[0])
    batch, (lb,) = pre.run([image])
    # Find the rectangle in the network input and map it back to source pixels.
    ys, xs = np.nonzero(batch[0, 0] > 0.9)
    found = np.array([[xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]], np.float32)
    back = unletterbox(found, lb)
    tolerance = 1.5 / lb.scale + 1  # a network pixel of resampling, plus rounding
    np.testing.assert_allclose(back, [[x1, y1, x2, y2]], atol=tolerance)


@pytest.mark.parametrize(("src", "dst"), SIZES)
def test_fast_path_matches_reference(src: tuple[int, int], dst: tuple[int, int]) -> None:
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, (src[1], src[0], 3), dtype=np.uint8)
    batch, _ = Preprocessor(dst[1], dst[0]).run([image])
    assert batch.shape == (1, 3, dst[1], dst[0]) and batch.dtype == np.float32
    np.testing.assert_allclose(batch[0], reference_blob(image, *dst), atol=1e-6)


def test_unletterbox_clips_to_the_image() -> None:
    lb = compute_letterbox(451, 300, 640, 640)
    inside_padding = np.array([[-50, 0, 700, 640]], np.float32)
    np.testing.assert_allclose(unletterbox(inside_padding, lb), [[0, 0, 451, 300]])


def test_buffer_is_reused_and_padding_repainted_on_a_new_geometry() -> None:
    pre = Preprocessor(640, 640)
    wide = np.full((300, 451, 3), 255, np.uint8)
    tall = np.full((451, 300, 3), 255, np.uint8)
    first, _ = pre.run([wide])
    second, (lb,) = pre.run([tall])
    assert np.shares_memory(first, pre.buffer) and np.shares_memory(second, pre.buffer)
    # After the tall image, only its columns are white; the wide image's leftovers are padding.
    pad = np.float32(PAD_VALUE / 255)
    assert np.all(second[0, :, :, : lb.pad_x] == pad)
    assert np.all(second[0, :, :, lb.pad_x + lb.resized_width :] == pad)
    assert np.all(second[0, :, :, lb.pad_x : lb.pad_x + lb.resized_width] == 1.0)
    np.testing.assert_allclose(pre.run([wide])[0][0], reference_blob(wide, 640, 640), atol=1e-6)


def test_fixed_batch_returns_full_batch_and_refuses_more() -> None:
    pre = Preprocessor(64, 64, batch_size=2)
    image = np.zeros((32, 48, 3), np.uint8)
    batch, boxes = pre.run([image])
    assert batch.shape == (2, 3, 64, 64) and len(boxes) == 1
    with pytest.raises(ValueError, match="batches of 2"):
        pre.run([image] * 3)


def test_dynamic_batch_grows() -> None:
    pre = Preprocessor(32, 32)
    images = [np.zeros((16, 16, 3), np.uint8)] * 3
    batch, boxes = pre.run(images)
    assert batch.shape == (3, 3, 32, 32) and len(boxes) == 3


def test_check_bgr_image() -> None:
    grey = np.zeros((4, 5), np.uint8)
    assert check_bgr_image(grey).shape == (4, 5, 3)
    with pytest.raises(ImageError, match=r"\(H, W, 3\) uint8"):
        check_bgr_image(np.zeros((4, 5, 3), np.float32))
    with pytest.raises(ImageError, match=r"got shape \(4, 5, 4\)"):
        check_bgr_image(np.zeros((4, 5, 4), np.uint8))
    with pytest.raises(ImageError, match="cannot letterbox"):
        compute_letterbox(0, 10, 640, 640)
