"""Camera sources on real files: images, folders, a video, the scikit-image samples."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from common.errors import ConfigError, ImageError
from common.images import SAMPLES
from services.camera.sources import is_stream, open_source, open_stream, resize


def _write_image(path: Path, value: int, size: tuple[int, int] = (32, 24)) -> None:
    assert cv2.imwrite(str(path), np.full((size[1], size[0], 3), value, np.uint8))


@pytest.mark.parametrize("name", SAMPLES)
def test_every_sample_is_a_bgr_photo(name: str) -> None:
    image = open_source(f"sample:{name}").read()
    assert image is not None and image.dtype == np.uint8
    assert image.ndim == 3 and image.shape[2] == 3 and min(image.shape[:2]) >= 256


def test_unknown_sample_lists_the_known_ones() -> None:
    with pytest.raises(ConfigError, match="cameraman"):
        open_source("sample:nope")


def test_image_is_repeated(tmp_path: Path) -> None:
    _write_image(tmp_path / "a.png", 10)
    src = open_source(str(tmp_path / "a.png"))
    first, second = src.read(), src.read()
    assert first is not None and second is not None and (first == second).all()


def test_folder_loops_in_name_order_and_skips_bad_files(tmp_path: Path) -> None:
    for i, name in enumerate(["b.png", "a.png", "c.jpg"]):
        _write_image(tmp_path / name, 50 * (i + 1))
    (tmp_path / "broken.png").write_bytes(b"not a png")
    (tmp_path / "notes.txt").write_text("ignored: not an image suffix")
    bad: list[ImageError] = []
    src = open_source(str(tmp_path), on_bad=bad.append)
    seen = []
    for _ in range(6):
        image = src.read()
        assert image is not None
        seen.append(int(image[0, 0, 0]))
    # a.png=100, b.png=50, broken (skipped), c.jpg=~150; then again from the start
    assert seen[:3] == seen[3:] and seen[0] == 100 and seen[1] == 50
    assert len(bad) == 2 and "broken.png" in str(bad[0])
    assert not src.live


def test_video_plays_and_loops(tmp_path: Path) -> None:
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
    for i in range(3):
        writer.write(np.full((48, 64, 3), 60 * (i + 1), np.uint8))
    writer.release()
    looped = open_source(str(path), loop=True)
    levels = [int(looped.read()[0, 0, 0]) for _ in range(6)]  # type: ignore[index]
    assert levels[:3] == levels[3:] and levels[0] < levels[1] < levels[2]
    once = open_source(str(path), loop=False)
    assert [once.read() is not None for _ in range(4)] == [True, True, True, False]
    assert not looped.live and not once.live  # a video's end is not reopened


@pytest.mark.parametrize("spec", ["/no/such/file.mp4", "device:/dev/video_nope"])
def test_missing_source_is_a_config_error(spec: str) -> None:
    with pytest.raises(ConfigError):
        open_source(spec)


def test_corrupt_image_file_is_a_config_error(tmp_path: Path) -> None:
    (tmp_path / "x.jpg").write_bytes(b"\xff\xd8 truncated")
    with pytest.raises(ConfigError, match=r"x\.jpg"):
        open_source(str(tmp_path / "x.jpg"))


def test_resize() -> None:
    image = np.zeros((480, 640, 3), np.uint8)
    assert resize(image, (0, 0)) is image
    assert resize(image, (320, 240)).shape == (240, 320, 3)


# --- sources that give nothing readable; videos and devices as detect opens them ----------------


def test_folder_of_only_corrupt_files_is_a_config_error_after_one_pass(tmp_path: Path) -> None:
    for name in ("a.png", "b.jpg", "c.png"):
        (tmp_path / name).write_bytes(b"not an image")
    bad: list[ImageError] = []
    src = open_source(str(tmp_path), on_bad=bad.append)
    with pytest.raises(ConfigError, match=r"not one of them is a readable image"):
        src.read()
    assert [Path(str(e).split(":")[0]).name for e in bad] == ["a.png", "b.jpg", "c.png"]


def test_video_without_a_readable_frame_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "empty.avi"
    cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10, (64, 48)).release()
    with pytest.raises(ConfigError, match=r"empty\.avi"):  # at open, or at the first read
        open_source(str(path), loop=True).read()


def test_video_declares_its_rate_and_length(tmp_path: Path) -> None:
    path = tmp_path / "clip.mkv"  # any other extension than an image's is tried as a video
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 7, (64, 48))
    for i in range(4):
        writer.write(np.full((48, 64, 3), 40 * i, np.uint8))
    writer.release()
    stream = open_stream(str(path))
    assert (stream.fps, stream.frame_count) == (7.0, 4)
    assert [stream.read() is not None for _ in range(5)] == [True] * 4 + [False]  # no loop


@pytest.mark.parametrize(
    ("spec", "stream"),
    [
        ("device:0", True),
        ("device:/dev/video0", True),
        ("/dev/video9", True),  # a device path, even unplugged
        ("missing.mp4", True),
        ("missing.png", False),
        ("sample:chelsea", False),
    ],
)
def test_is_stream(spec: str, stream: bool) -> None:
    assert is_stream(spec) is stream


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("device:/dev/video_nope", "camera device /dev/video_nope: no such device"),
        ("/dev/video_nope", "camera device /dev/video_nope: no such device"),
        ("/no/such/clip.mp4", "video /no/such/clip.mp4: no such file"),
    ],
)
def test_missing_stream_is_one_line(spec: str, message: str) -> None:
    with pytest.raises(ConfigError, match=f"^{message}$"):
        open_stream(spec)


class _OpenCapture:
    """Stands in for cv2.VideoCapture on a device index: opens, gives nothing."""

    def __init__(self, target: object) -> None:
        self.target = target

    def isOpened(self) -> bool:  # OpenCV's name
        return True

    def release(self) -> None:
        return None


def test_devices_are_live(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(cv2, "VideoCapture", _OpenCapture)
    device = open_source("device:3")
    assert device.live and device.description == "camera device 3"
    assert not open_source("sample:chelsea").live
