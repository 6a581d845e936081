from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.config_file import load_config
from common.errors import ConfigError, ImageError
from common.frames import frame_to_bgr, image_to_frame
from common.keys import Keys
from common.messages import Frame, Header
from common.settings import DEFAULT_CONFIG


def test_default_config_loads() -> None:
    cfg = load_config(DEFAULT_CONFIG, environ={})
    assert cfg.detector.backend == "onnx"
    assert cfg.controller.target_classes == ("person",)
    assert cfg.camera.resize == (0, 0)


def test_env_override_is_typed(tmp_path: Path) -> None:
    env = {
        "STACK__DETECTOR__CONF": "0.5",
        "STACK__CONTROLLER__TARGET_CLASSES": '["cup"]',
        "STACK__CAMERA__SOURCE": "device:0",
    }
    cfg = load_config(DEFAULT_CONFIG, environ=env)
    assert cfg.detector.conf == 0.5
    assert cfg.controller.target_classes == ("cup",)
    assert cfg.camera.source == "device:0"


@pytest.mark.parametrize(
    "text, message",
    [
        ("[detector]\nconff = 0.3\n", "unknown setting"),
        ("[detectr]\n", "unknown table"),
        ("[detector]\nconf = 1.5\n", "within 0..1"),
        ("[detector]\nconf = 'high'\n", "must be float"),
        ("[controller]\nmode = 'dance'\n", "track' or 'follow"),
        ("[camera]\nresize = [640]\n", "2 items"),
        ("not toml [", "not valid TOML"),
    ],
)
def test_bad_config_is_one_clear_error(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "stack.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path, environ={})


def test_missing_config_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.toml", environ={})


def test_keys_are_built_under_the_prefix() -> None:
    k = Keys("lab/robot1")
    assert k.frame("front") == "lab/robot1/camera/front/frame"
    assert k.detections("front") == "lab/robot1/detector/front/detections"
    assert k.cmd_vel() == "lab/robot1/controller/cmd_vel"
    assert k.health("detector") == "lab/robot1/health/detector"
    for bad in ("", "a/*", "a//b", "x$y"):
        with pytest.raises(ConfigError):
            Keys(bad)
    with pytest.raises(ConfigError):
        Keys().frame("front/**")


HEADER = Header(stamp_ns=1, frame_id="cam", seq=1, source="t")


@pytest.mark.parametrize("quality", [0, 95])
def test_image_frame_round_trip(quality: int) -> None:
    rng = np.random.default_rng(0)
    image = np.repeat(np.repeat(rng.integers(0, 255, (12, 16, 3), dtype=np.uint8), 4, 0), 4, 1)
    frame = Frame.decode(image_to_frame(image, HEADER, jpeg_quality=quality).encode())
    back = frame_to_bgr(frame)
    assert back.shape == image.shape
    tolerance = 0 if quality == 0 else 40
    assert np.abs(back.astype(int) - image.astype(int)).mean() <= tolerance


def test_rgb_frame_becomes_bgr() -> None:
    rgb = np.zeros((2, 2, 3), np.uint8)
    rgb[..., 0] = 255
    frame = Frame(header=HEADER, encoding="rgb8", width=2, height=2, data=rgb.tobytes())
    assert (frame_to_bgr(frame)[..., 2] == 255).all()


def test_corrupt_jpeg_is_an_image_error() -> None:
    frame = Frame(header=HEADER, encoding="jpeg", width=10, height=10, data=b"\xff\xd8garbage")
    with pytest.raises(ImageError, match="corrupt JPEG"):
        frame_to_bgr(frame)


def test_to_toml_round_trips(tmp_path: Path) -> None:
    import dataclasses

    from common.config_file import to_toml

    cfg = load_config(DEFAULT_CONFIG, environ={})
    cfg = dataclasses.replace(
        cfg, camera=dataclasses.replace(cfg.camera, source='C:\\videos\\"quoted".mp4')
    )
    path = tmp_path / "out.toml"
    path.write_text(to_toml(cfg))
    again = load_config(path, environ={})
    assert dataclasses.replace(again, path=cfg.path) == cfg
