"""The TensorRT engine cache: keys, file naming, and every reason an engine is not reused."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from common.errors import ConfigError
from runtimes import engine_cache
from runtimes.engine_cache import BuildOptions, EngineKey, check, store

KEY = EngineKey(
    model_name="yolov5s-coco",
    model_sha256="a" * 64,
    gpu_name="NVIDIA H100 80GB HBM3",
    compute_capability="9.0",
    tensorrt_version="10.3.0",
    precision="fp16",
    batch_profile=(1, 1, 1),
)
ENGINE = b"serialised engine bytes" * 100


@pytest.fixture
def cached(tmp_path: Path) -> Path:
    store(tmp_path, KEY, ENGINE)
    return tmp_path


def test_store_then_check_is_a_hit(cached: Path) -> None:
    path, reason = check(cached, KEY)
    assert path == cached / "yolov5s-coco.fp16.b1-1-1.engine"
    assert path.read_bytes() == ENGINE
    assert reason == f"engine cache hit: {path}"
    assert (cached / "yolov5s-coco.fp16.b1-1-1.json").is_file()


def test_an_empty_cache_is_a_miss_that_says_where(tmp_path: Path) -> None:
    path, reason = check(tmp_path / "nothing-here", KEY)
    assert path is None
    assert reason.startswith("engine cache miss: no cached engine in ")
    assert "yolov5s-coco.fp16.b1-1-1" in reason


@pytest.mark.parametrize(
    ("field", "value", "expected"),
    [
        ("tensorrt_version", "10.5.0", "TensorRT version changed 10.3.0 → 10.5.0"),
        ("model_sha256", "b" * 64, "model changed sha256 aaaaaaaaaaaa → sha256 bbbbbbbbbbbb"),
        ("gpu_name", "NVIDIA L4", "GPU changed NVIDIA H100 80GB HBM3 → NVIDIA L4"),
        ("compute_capability", "8.9", "compute capability changed 9.0 → 8.9"),
        ("calibration", "c" * 64, "calibration data changed none → cccccccccccc"),
        # These two change the slot: the reason comes from the nearest other slot.
        ("precision", "int8", "precision changed fp16 → int8"),
        ("batch_profile", (1, 4, 8), "batch profile changed 1/1/1 → 1/4/8"),
    ],
)
def test_each_key_field_change_is_a_miss_with_its_reason(
    cached: Path, field: str, value: object, expected: str
) -> None:
    path, reason = check(cached, dataclasses.replace(KEY, **{field: value}))
    assert path is None
    assert reason.startswith("engine cache miss: ")
    assert expected in reason


def test_two_fields_changed_are_both_named(cached: Path) -> None:
    wanted = dataclasses.replace(KEY, tensorrt_version="10.5.0", compute_capability="8.9")
    _, reason = check(cached, wanted)
    assert "TensorRT version changed 10.3.0 → 10.5.0" in reason
    assert "compute capability changed 9.0 → 8.9" in reason


def test_the_model_name_alone_only_names_files(tmp_path: Path) -> None:
    store(tmp_path, KEY, ENGINE)
    renamed = dataclasses.replace(KEY, model_name="renamed")
    assert engine_cache.differences(KEY, renamed) == []
    assert check(tmp_path, renamed)[0] is None  # another slot: nothing stored there yet


@pytest.mark.parametrize(
    "sidecar_text",
    [
        "{ not json",
        "[]",
        json.dumps({"format": 99}),
        json.dumps(
            {"format": 1, "key": {"model_name": "x"}, "engine_bytes": 1, "engine_sha256": ""}
        ),
        json.dumps({"format": 1, "key": KEY.to_json()}),
    ],
)
def test_a_corrupt_sidecar_is_a_miss(cached: Path, sidecar_text: str) -> None:
    engine_cache.sidecar_path(cached, KEY).write_text(sidecar_text)
    path, reason = check(cached, KEY)
    assert path is None
    assert reason.startswith(
        "engine cache miss: sidecar yolov5s-coco.fp16.b1-1-1.json is unreadable"
    )


def test_a_sidecar_of_binary_garbage_is_a_miss(cached: Path) -> None:
    engine_cache.sidecar_path(cached, KEY).write_bytes(b"\xff\xfe\x00garbage")
    path, reason = check(cached, KEY)
    assert path is None
    assert "unreadable" in reason


def test_a_missing_engine_file_is_a_miss(cached: Path) -> None:
    engine_cache.engine_path(cached, KEY).unlink()
    assert check(cached, KEY) == (
        None,
        "engine cache miss: engine file yolov5s-coco.fp16.b1-1-1.engine is missing",
    )


def test_a_truncated_engine_is_a_miss(cached: Path) -> None:
    engine_cache.engine_path(cached, KEY).write_bytes(ENGINE[:10])
    path, reason = check(cached, KEY)
    assert path is None
    assert f"engine file is 10 bytes, sidecar says {len(ENGINE)}" in reason


def test_an_engine_changed_in_place_is_a_miss(cached: Path) -> None:
    engine_cache.engine_path(cached, KEY).write_bytes(ENGINE[::-1])  # same size, other bytes
    path, reason = check(cached, KEY)
    assert path is None
    assert "sha256 does not match" in reason


def test_storing_again_replaces_the_slot(cached: Path) -> None:
    newer = dataclasses.replace(KEY, tensorrt_version="10.5.0")
    store(cached, newer, b"new engine")
    assert check(cached, newer)[0] is not None
    assert "TensorRT version changed 10.5.0 → 10.3.0" in check(cached, KEY)[1]
    assert not list(cached.glob(".*.tmp"))  # atomic writes leave no temporaries


def test_any_calibration_accepts_an_int8_engine_built_on_other_images(tmp_path: Path) -> None:
    built = dataclasses.replace(KEY, precision="int8", calibration="e" * 64)
    store(tmp_path, built, ENGINE)
    wanted = dataclasses.replace(built, calibration="")  # a service given no calibration folder
    assert "calibration data changed" in check(tmp_path, wanted)[1]
    assert check(tmp_path, wanted, any_calibration=True)[0] is not None
    newer = dataclasses.replace(wanted, tensorrt_version="10.5.0")
    assert "TensorRT version changed" in check(tmp_path, newer, any_calibration=True)[1]


def test_key_round_trips_through_json() -> None:
    int8 = dataclasses.replace(KEY, precision="int8", calibration="d" * 64, batch_profile=(1, 4, 8))
    assert EngineKey.from_json(json.loads(json.dumps(int8.to_json()))) == int8


def test_file_names_are_safe_and_calibration_cache_is_per_model_and_data(tmp_path: Path) -> None:
    odd = dataclasses.replace(KEY, model_name="../my model")
    assert engine_cache.engine_path(tmp_path, odd).parent == tmp_path
    assert engine_cache.engine_path(tmp_path, odd).name == "___my_model.fp16.b1-1-1.engine"
    int8 = dataclasses.replace(KEY, model_name="m", model_sha256="1" * 64, calibration="2" * 64)
    calib = engine_cache.calibration_cache_path(tmp_path, int8)
    assert calib == tmp_path / "m.111111111111.222222222222.calib"


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"precision": "int4"}, "precision must be one of fp32, fp16, int8"),
        ({"batch_profile": (4, 1, 8)}, "1 <= min <= opt <= max"),
        ({"batch_profile": (1, 2)}, "batch profile must be [min, opt, max]"),
        ({"workspace_gb": 0}, "workspace must be a positive number"),
        ({"device": -1}, "device index must be >= 0"),
    ],
)
def test_build_options_are_validated_up_front(options: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]")):
        BuildOptions(**options)  # type: ignore[arg-type]


def test_build_options_default_cache_folder_is_beside_the_models(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("STACK_MODELS_DIR", str(tmp_path))
    assert BuildOptions().folder() == tmp_path / "engines"
    assert BuildOptions(cache_dir=tmp_path / "x").folder() == tmp_path / "x"
