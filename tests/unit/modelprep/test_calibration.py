"""INT8 calibration data: real photos in a folder, as fixed-size letterboxed batches."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from skimage import data

from common.errors import ConfigError, ImageError
from common.letterbox import Preprocessor
from modelprep.calibration import (
    batch_count,
    calibration_batches,
    calibration_digest,
    calibration_images,
)

SIZE = 64  # a small network input keeps the test fast; the letterbox logic is the same


@pytest.fixture
def photos(tmp_path: Path) -> Path:
    """Five scikit-image photos written as files, in a folder with one non-image."""
    folder = tmp_path / "calib"
    folder.mkdir()
    for name, image in [
        ("a_astronaut.png", data.astronaut()),
        ("b_chelsea.jpg", data.chelsea()),
        ("c_coffee.png", data.coffee()),
        ("d_rocket.jpg", data.rocket()),
        ("e_camera.png", data.camera()),  # grey
    ]:
        bgr = image[:, :, ::-1] if image.ndim == 3 else image
        assert cv2.imwrite(str(folder / name), np.ascontiguousarray(bgr))
    (folder / "notes.txt").write_text("not an image")
    return folder


def test_the_folder_lists_its_images_sorted(photos: Path) -> None:
    names = [p.name for p in calibration_images(photos)]
    assert names == [
        "a_astronaut.png",
        "b_chelsea.jpg",
        "c_coffee.png",
        "d_rocket.jpg",
        "e_camera.png",
    ]


def test_a_folder_without_images_is_an_error(tmp_path: Path) -> None:
    (tmp_path / "readme.txt").write_text("nothing to see")
    with pytest.raises(ConfigError, match="has no images"):
        calibration_images(tmp_path)
    with pytest.raises(ConfigError, match="does not exist or is not a folder"):
        calibration_images(tmp_path / "missing")


def test_batch_count_pads_or_drops_the_last_partial_batch() -> None:
    assert batch_count(5, 2, "pad") == 3
    assert batch_count(5, 2, "drop") == 2
    assert batch_count(4, 2, "pad") == batch_count(4, 2, "drop") == 2
    with pytest.raises(ConfigError, match="at least 1"):
        batch_count(5, 0)


def test_batches_are_the_pipeline_letterbox_with_the_last_one_padded_by_cycling(
    photos: Path,
) -> None:
    paths = calibration_images(photos)
    batches = list(calibration_batches(paths, 2, SIZE, SIZE))
    assert len(batches) == 3
    assert all(b.shape == (2, 3, SIZE, SIZE) and b.dtype == np.float32 for b in batches)
    # The same letterbox as at inference time, image by image.
    pre = Preprocessor(SIZE, SIZE, 1)
    expected = [pre.run([cv2.imread(str(p), cv2.IMREAD_COLOR)])[0][0].copy() for p in paths]
    flat = [image for batch in batches for image in batch]
    for got, want in zip(flat[:5], expected, strict=True):
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(flat[5], expected[0])  # padding repeats the first image
    assert min(b.min() for b in batches) >= 0.0 and max(b.max() for b in batches) <= 1.0


def test_batches_are_fresh_arrays_not_views_of_one_buffer(photos: Path) -> None:
    first, second, *_ = calibration_batches(calibration_images(photos), 2, SIZE, SIZE)
    assert not np.shares_memory(first, second)
    assert not np.array_equal(first, second)


def test_dropping_keeps_only_full_batches(photos: Path) -> None:
    batches = list(calibration_batches(calibration_images(photos), 2, SIZE, SIZE, last="drop"))
    assert len(batches) == 2


def test_too_few_images_to_drop_into_a_batch_is_an_error(photos: Path) -> None:
    paths = calibration_images(photos)
    with pytest.raises(ConfigError, match="make no full batch of 8"):
        next(calibration_batches(paths, 8, SIZE, SIZE, last="drop"))
    assert len(list(calibration_batches(paths, 8, SIZE, SIZE))) == 1  # padded: 5 + 3 repeats


def test_an_unreadable_image_stops_calibration(photos: Path) -> None:
    (photos / "f_broken.png").write_bytes(b"not a png")
    with pytest.raises(ImageError, match=r"f_broken\.png"):
        list(calibration_batches(calibration_images(photos), 3, SIZE, SIZE))


def test_the_digest_follows_names_and_contents(photos: Path) -> None:
    paths = calibration_images(photos)
    digest = calibration_digest(paths)
    assert digest == calibration_digest(list(paths))
    assert calibration_digest(paths[:-1]) != digest
    (photos / "c_coffee.png").write_bytes((photos / "a_astronaut.png").read_bytes())
    assert calibration_digest(paths) != digest
