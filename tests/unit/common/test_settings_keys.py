from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.errors import ConfigError, ImageError
from common.frames import frame_to_bgr, image_to_frame
from common.keys import Keys
from common.messages import Frame, Header
from common.settings import DEFAULT_CONFIG, REPO_ROOT
from stack.config_file import load_config


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
        ("[controller]\nmode = 'dance'\n", "must be one of track, follow, got 'dance'"),
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

    from stack.config_file import to_toml

    cfg = load_config(DEFAULT_CONFIG, environ={})
    cfg = dataclasses.replace(
        cfg, camera=dataclasses.replace(cfg.camera, source='C:\\videos\\"quoted".mp4')
    )
    path = tmp_path / "out.toml"
    path.write_text(to_toml(cfg))
    again = load_config(path, environ={})
    assert dataclasses.replace(again, path=cfg.path) == cfg


def test_jpeg_size_is_read_without_decoding_and_a_lying_header_is_refused() -> None:
    import cv2

    from common.frames import jpeg_size

    ok, buf = cv2.imencode(".jpg", np.zeros((24, 32, 3), np.uint8))
    assert ok
    data = buf.tobytes()
    assert jpeg_size(data) == (32, 24)
    assert jpeg_size(b"not a jpeg") is None
    # Patch the frame header to claim 20000x20000: refused before any decoding.
    sof = data.index(b"\xff\xc0")
    huge = data[: sof + 5] + (20000).to_bytes(2, "big") * 2 + data[sof + 9 :]
    frame = Frame(header=HEADER, encoding="jpeg", width=32, height=24, data=huge)
    with pytest.raises(ImageError, match="header says"):
        frame_to_bgr(frame)


def test_truncated_jpeg_is_an_image_error() -> None:
    import cv2

    ok, buf = cv2.imencode(".jpg", np.full((24, 32, 3), 128, np.uint8))
    assert ok
    data = buf.tobytes()
    frame = Frame(header=HEADER, encoding="jpeg", width=32, height=24, data=data[: len(data) // 3])
    with pytest.raises(ImageError):
        frame_to_bgr(frame)


@pytest.mark.parametrize(
    "override, message",
    [
        ({"STACK__CONTROLLER__BEARING_KP": "nan"}, "bearing_kp must be within 0..100, got nan"),
        ({"STACK__CONTROLLER__DISTANCE_GAIN": "inf"}, "distance_gain must be within 0..10, got"),
        ({"STACK__SIM__SEED": "-1"}, "sim.seed"),
        ({"STACK__SIM__LASER_NOISE_M": "nan"}, "laser_noise_m must be within 0..1 m, got nan"),
        ({"STACK__CAMERA__RESIZE": "[20000, 10]"}, "camera.resize"),
        ({"STACK__DETECTOR__MAX_DET": "100000"}, "max_det"),
        ({"STACK__SUPERVISOR__SERVICES": '["bogus"]'}, "supervisor.services"),
        ({"STACK__SUPERVISOR__SERVICES": '["camera", "camera"]'}, "at most once"),
    ],
)
def test_unsafe_values_are_refused_at_start_up(override: dict[str, str], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_config(DEFAULT_CONFIG, environ=override)


def test_an_override_into_a_non_table_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "stack.toml"
    path.write_text("camera = 5\n")
    with pytest.raises(ConfigError, match="must be a table"):
        load_config(path, environ={"STACK__CAMERA__RATE_HZ": "3"})


def test_a_mistyped_override_is_blamed_on_the_variable() -> None:
    with pytest.raises(ConfigError) as err:
        load_config(DEFAULT_CONFIG, environ={"STACK__DETECTR__CONF": "0.3"})
    assert str(err.value).startswith("STACK__DETECTR__CONF: there is no table [detectr]")
    assert "stack.toml" not in str(err.value)
    with pytest.raises(ConfigError, match=r"^STACK__DETECTOR__CONFF: \[detector\] has no setting"):
        load_config(DEFAULT_CONFIG, environ={"STACK__DETECTOR__CONFF": "0.3"})


def test_make_run_installs_no_test_tools_and_no_torch() -> None:
    import tomllib

    project = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]
    runtime = " ".join(project["dependencies"]).lower()
    for tool in ("pytest", "mypy", "ruff", "torch", "nudenet", "hypothesis"):
        assert tool not in runtime, tool
    makefile = (REPO_ROOT / "Makefile").read_text()
    # The run target's venv gets the project alone; the dev extra only for tests and lint.
    assert "pip install --quiet -e . >&2\n" in makefile
    run_deps = next(line for line in makefile.splitlines() if line.startswith("run:"))
    setup_deps = next(line for line in makefile.splitlines() if line.startswith("setup:"))
    assert "DEV" not in run_deps and "DEV" not in setup_deps


def test_each_services_settings_are_declared_in_its_contract() -> None:
    """Config is assembled from the contracts (stack/config.py); only the shared tables and the
    supervisor's are declared elsewhere."""
    import dataclasses
    import typing

    from stack.config import Config

    hints = typing.get_type_hints(Config)
    homes = {
        table.name: hints[table.name].__module__
        for table in dataclasses.fields(Config)
        if table.name not in ("path", "cameras")
    }
    shared = {"zenoh": "common.settings", "stack": "common.settings"}
    own = {"tracker": "detector", "supervisor": None}
    for table, module in homes.items():
        if table in shared:
            assert module == shared[table], table
        elif own.get(table, table) is None:
            assert module == "stack.config", table
        else:
            assert module == f"services.{own.get(table, table)}.contract", table


def test_the_default_config_states_the_tracker_reset_and_keeps_its_own_max_det() -> None:
    cfg = load_config(DEFAULT_CONFIG, environ={"STACK__TRACKER__JUMPS_BEFORE_RESET": "5"})
    assert cfg.tracker.jumps_before_reset == 5
    assert "jumps_before_reset" in DEFAULT_CONFIG.read_text()
    assert load_config(DEFAULT_CONFIG, environ={}).detector.max_det == 100


def test_the_default_stack_file_names_every_setting() -> None:
    """deploy/stack.toml says it documents every field: a new setting must appear there."""
    import dataclasses
    import tomllib

    from stack.config import Config

    data = tomllib.loads(DEFAULT_CONFIG.read_text())
    missing = [
        f"{table.name}.{f.name}"
        for table in dataclasses.fields(Config)
        if table.name not in ("path", "cameras")  # [cameras.<name>]: [camera] tables
        for f in dataclasses.fields(getattr(Config(), table.name))
        if f.name not in data.get(table.name, {})
    ]
    assert missing == []
