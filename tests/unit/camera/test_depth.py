"""Depth from a camera source: the conversion of a library's depth image to a DepthFrame, the
16-bit PNG folder beside a colour folder (real PNGs written with OpenCV, colour from the
scikit-image photos), the depth settings, and the optional extras' one-line errors."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from common.errors import ConfigError, ImageError
from common.images import load_sample
from common.messages import DepthFrame, Header
from perception.depth import depth_metres
from services.camera.contract import CameraSettings
from services.camera.depth import (
    DepthImage,
    device_depth,
    intrinsics_for,
    intrinsics_from_matrix,
    resized,
    to_depth_frame,
    to_millimetres,
)
from services.camera.depth_folder import DepthFolder, with_depth_folder
from services.camera.extras import import_extra
from services.camera.sources import depth_capable, open_source

HEADER = Header(stamp_ns=1_700_000_000_123_456_789, seq=42, frame_id="cam_optical", source="camera")


def _image(data: np.ndarray, scale_m: float = 0.001) -> DepthImage:
    return DepthImage(data=data, scale_m=scale_m, fx=500.0, fy=510.0, cx=1.0, cy=0.5)


# -- the conversion -------------------------------------------------------------------------------
def test_millimetres_pass_through_and_the_frame_keeps_the_colour_header() -> None:
    raw = np.array([[0, 1000, 2500], [65535, 300, 7]], np.uint16)
    frame = to_depth_frame(_image(raw), HEADER, range_min_m=0.2, range_max_m=10.0)
    assert frame.header == HEADER
    assert (frame.encoding, frame.width, frame.height) == ("16UC1", 3, 2)
    assert (frame.fx, frame.fy, frame.cx, frame.cy) == (500.0, 510.0, 1.0, 0.5)
    assert (frame.range_min_m, frame.range_max_m) == (0.2, 10.0)
    assert np.array_equal(np.frombuffer(frame.data, "<u2").reshape(2, 3), raw)
    again = DepthFrame.decode(frame.encode())
    metres = depth_metres(again)
    assert metres[0, 1] == pytest.approx(1.0) and metres[0, 2] == pytest.approx(2.5)
    # 0 (no reading), 65.535 m (past the range) and 7 mm (nearer than it) are no readings.
    assert np.isnan(metres[0, 0]) and np.isnan(metres[1, 0]) and np.isnan(metres[1, 2])


def test_other_units_become_whole_millimetres_and_unholdable_readings_none() -> None:
    # TUM RGB-D's PNGs count fifths of a millimetre.
    tum = to_millimetres(_image(np.array([[5000, 1, 0]], np.uint16), scale_m=0.0002))
    assert tum.tolist() == [[1000, 0, 0]]  # 0.2 mm rounds to no reading, never to a made-up 1
    metres = np.array([[1.2344, np.nan, -1.0, np.inf, 70.0, 0.0]], np.float32)
    assert to_millimetres(_image(metres)).tolist() == [[1234, 0, 0, 0, 0, 0]]
    coarse = to_millimetres(_image(np.array([[3, 70000 // 10]], np.uint16), scale_m=0.01))
    assert coarse.tolist() == [[30, 0]]  # 70 m does not fit in 16-bit millimetres


def test_a_frame_no_message_can_carry_is_a_value_error() -> None:
    raw = np.ones((4, 4), np.uint16)
    with pytest.raises(ValueError, match="focal length"):
        to_depth_frame(dataclasses.replace(_image(raw), fx=0.0), HEADER)


def test_resizing_is_nearest_and_scales_the_intrinsics() -> None:
    raw = np.array([[1000, 2000], [3000, 4000]], np.uint16)
    image = DepthImage(data=raw, scale_m=0.001, fx=100.0, fy=80.0, cx=0.5, cy=0.5)
    assert resized(image, (0, 0)) is image and resized(image, (2, 2)) is image
    big = resized(image, (4, 4))
    assert big.data.tolist() == [[1000, 1000, 2000, 2000]] * 2 + [[3000, 3000, 4000, 4000]] * 2
    assert (big.fx, big.fy, big.cx, big.cy) == (200.0, 160.0, 1.5, 1.5)  # still the centre


def test_intrinsics_stated_from_a_matrix_or_from_the_field_of_view() -> None:
    assert intrinsics_for((600.0, 601.0, 320.0, 240.0), 60.0, 640, 480) == (
        600.0, 601.0, 320.0, 240.0,
    )  # fmt: skip
    fx, fy, cx, cy = intrinsics_for((0.0, 0.0, 0.0, 0.0), 90.0, 640, 480)
    assert fx == pytest.approx(320.0) and fy == fx and (cx, cy) == (320.0, 240.0)
    k = [[615.2, 0.0, 322.1], [0.0, 614.8, 241.9], [0.0, 0.0, 1.0]]
    assert intrinsics_from_matrix(k) == (615.2, 614.8, 322.1, 241.9)
    with pytest.raises(ValueError, match="3x3"):
        intrinsics_from_matrix([[1.0, 2.0]])


def test_device_depth_must_be_aligned_to_its_colour_frame() -> None:
    colour = np.zeros((48, 64, 3), np.uint8)
    intr = (50.0, 50.0, 32.0, 24.0)
    ok = device_depth(colour, np.ones((48, 64), np.uint16), scale_m=0.001, intrinsics=intr)
    assert (ok.width, ok.height, ok.fx, ok.cy) == (64, 48, 50.0, 24.0)
    with pytest.raises(ImageError, match="not aligned"):
        device_depth(colour, np.ones((24, 32), np.uint16), scale_m=0.001, intrinsics=intr)
    with pytest.raises(ImageError, match="uint16 or float32"):
        device_depth(colour, np.ones((48, 64), np.int32), scale_m=0.001, intrinsics=intr)


# -- the PNG folder -------------------------------------------------------------------------------
def _rgbd_folders(tmp_path: Path) -> tuple[Path, Path, dict[str, np.ndarray]]:
    """A colour folder of two sample photos (resized small) and a depth folder of their
    stems' 16-bit PNGs: a ramp in millimetres."""
    rgb, depth = tmp_path / "rgb", tmp_path / "depth"
    rgb.mkdir()
    depth.mkdir()
    truth = {}
    for i, name in enumerate(("chelsea", "coffee")):
        colour = cv2.resize(load_sample(name), (64, 48))
        assert cv2.imwrite(str(rgb / f"{i:04d}.jpg"), colour)
        ramp = np.arange(48 * 64, dtype=np.uint32).reshape(48, 64) % 4000 + 500 * (i + 1)
        truth[f"{i:04d}"] = ramp.astype(np.uint16)
        assert cv2.imwrite(str(depth / f"{i:04d}.png"), truth[f"{i:04d}"])
    return rgb, depth, truth


def _paired(rgb: Path, depth: Path, **settings: object) -> object:
    values: dict[str, object] = {
        "scale_m": 0.001,
        "intrinsics": (0.0, 0.0, 0.0, 0.0),
        "hfov_deg": 60.0,
    }
    values.update(settings)
    return with_depth_folder(open_source(str(rgb)), str(depth), **values)  # type: ignore[arg-type]


def test_each_colour_image_gets_the_depth_png_of_its_stem(tmp_path: Path) -> None:
    rgb, depth, truth = _rgbd_folders(tmp_path)
    source = depth_capable(_paired(rgb, depth, intrinsics=(55.0, 56.0, 31.0, 23.0)))  # type: ignore[arg-type]
    assert source is not None and not source.live
    for stem in ("0000", "0001", "0000"):  # looped
        colour = source.read()
        assert colour is not None and colour.shape == (48, 64, 3)
        image = source.depth()
        assert image is not None and np.array_equal(image.data, truth[stem])
        assert (image.fx, image.fy, image.cx, image.cy) == (55.0, 56.0, 31.0, 23.0)
    source.close()


def test_without_intrinsics_they_come_from_the_field_of_view(tmp_path: Path) -> None:
    rgb, depth, _ = _rgbd_folders(tmp_path)
    source = depth_capable(_paired(rgb, depth, hfov_deg=90.0))  # type: ignore[arg-type]
    assert source is not None and source.read() is not None
    image = source.depth()
    assert image is not None
    assert image.fx == pytest.approx(32.0) and (image.cx, image.cy) == (32.0, 24.0)


def test_a_colour_image_without_a_depth_png_of_its_stem_has_none(tmp_path: Path) -> None:
    rgb, depth, _ = _rgbd_folders(tmp_path)
    (depth / "0001.png").unlink()
    source = depth_capable(_paired(rgb, depth))  # type: ignore[arg-type]
    assert source is not None
    assert source.read() is not None and source.depth() is not None
    assert source.read() is not None and source.depth() is None


@pytest.mark.parametrize(
    "bad, match",
    [
        (np.full((48, 64), 200, np.uint8), "16-bit single-channel PNG, got uint8 with 1"),
        (np.full((48, 64, 3), 2000, np.uint16), "16-bit single-channel PNG, got uint16 with 3"),
        (np.full((24, 32), 2000, np.uint16), "depth is 32x24, its colour image 64x48"),
        (b"\x89PNG\r\n\x1a\n truncated", "not a decodable PNG"),
        (b"", "not a decodable PNG"),
    ],
)
def test_a_bad_depth_png_is_an_image_error_naming_it(
    tmp_path: Path, bad: np.ndarray | bytes, match: str
) -> None:
    rgb, depth, truth = _rgbd_folders(tmp_path)
    path = depth / "0001.png"
    if isinstance(bad, bytes):
        path.write_bytes(bad)
    else:
        assert cv2.imwrite(str(path), bad)
    source = depth_capable(_paired(rgb, depth))  # type: ignore[arg-type]
    assert source is not None
    assert source.read() is not None
    first = source.depth()
    assert first is not None and np.array_equal(first.data, truth["0000"])
    assert source.read() is not None  # the colour image still comes
    with pytest.raises(ImageError, match=match) as err:
        source.depth()
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_missing_or_empty_depth_folder_or_a_colour_source_that_is_no_folder_is_one_line(
    tmp_path: Path,
) -> None:
    rgb, depth, _ = _rgbd_folders(tmp_path)
    with pytest.raises(ConfigError, match=r"camera.depth_source '.*nowhere': no such folder"):
        _paired(rgb, tmp_path / "nowhere")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ConfigError, match=r"no \.png files"):
        DepthFolder(empty)
    with pytest.raises(ConfigError, match=r"needs camera\.source to be a folder"):
        with_depth_folder(
            open_source("sample:chelsea"),
            str(depth),
            scale_m=0.001,
            intrinsics=(0.0, 0.0, 0.0, 0.0),
            hfov_deg=60.0,
        )


def test_a_colour_only_source_is_no_depth_source() -> None:
    assert depth_capable(open_source("sample:chelsea")) is None


# -- settings -------------------------------------------------------------------------------------
def test_depth_settings_that_cannot_work_are_one_line() -> None:
    with pytest.raises(ConfigError, match=r"camera.intrinsics must be \[fx, fy, cx, cy\]"):
        CameraSettings(intrinsics=(0.0, 500.0, 320.0, 240.0))
    with pytest.raises(ConfigError, match=r"camera\.depth_min_m .* must be below"):
        CameraSettings(depth_min_m=5.0, depth_max_m=2.0)
    with pytest.raises(ConfigError, match=r"camera.mount_height_m must be within 0..10 m"):
        CameraSettings(mount_height_m=math.nan)
    ok = CameraSettings(depth_min_m=0.3, depth_max_m=10.0, intrinsics=(600, 600, 320, 240))
    assert ok.depth_max_m == 10.0


# -- the optional extras --------------------------------------------------------------------------
def test_a_missing_extra_is_one_line_naming_it() -> None:
    with pytest.raises(ConfigError) as err:
        import_extra("no_such_depth_sdk_xyz", "realsense", "camera source 'realsense:'")
    assert str(err.value) == (
        "camera source 'realsense:': no_such_depth_sdk_xyz is not installed; install the "
        "realsense extra: pip install '.[realsense]'"
    )


def test_an_extra_that_cannot_load_says_why(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "sdk_without_its_library.py").write_text(
        'raise ImportError("libusb-1.0.so.0: cannot open shared object file")\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ConfigError, match=r"^oak: sdk_without_its_library cannot load \(libusb"):
        import_extra("sdk_without_its_library", "oak", "oak")
    sys.modules.pop("sdk_without_its_library", None)


@pytest.mark.parametrize(
    "spec, module, extra", [("realsense:", "pyrealsense2", "realsense"), ("oak:", "depthai", "oak")]
)
def test_an_rgbd_camera_without_its_extra_or_a_device_is_one_line(
    spec: str, module: str, extra: str
) -> None:
    with pytest.raises(ConfigError) as err:
        open_source(spec)
    line = str(err.value)
    assert line.startswith(f"camera source {spec!r}: ") and "\n" not in line
    if importlib.util.find_spec(module) is None:  # the default install: no extra
        assert f"pip install '.[{extra}]'" in line
    else:  # installed (by hand): no camera on a test machine
        assert "no " in line or "cannot" in line
