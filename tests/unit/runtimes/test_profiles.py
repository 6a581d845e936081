"""Optimisation-profile shapes for TensorRT, worked out from a model's declared input."""

from __future__ import annotations

from pathlib import Path

import onnx
import pytest
from onnx import TensorProto, helper

from common.errors import ConfigError, ModelError
from runtimes.profiles import (
    BatchProfile,
    batch_profile,
    calibration_shape,
    model_profile,
    profile_shapes,
    read_onnx_input,
    served_profile,
)


def write_model(path: Path, dims: list[int | str], metadata: dict[str, str] | None = None) -> Path:
    """A one-node ONNX model (Identity) whose input is declared as ``dims``."""
    x = helper.make_tensor_value_info("images", TensorProto.FLOAT, dims)
    y = helper.make_tensor_value_info("out", TensorProto.FLOAT, dims)
    graph = helper.make_graph([helper.make_node("Identity", ["images"], ["out"])], "g", [x], [y])
    model = helper.make_model(graph)
    for key, value in (metadata or {}).items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.save(model, str(path))
    return path


def test_dynamic_batch_takes_min_and_max_of_the_requested_sizes_and_opt_the_largest() -> None:
    assert batch_profile(None, [1, 4, 2]) == BatchProfile(1, 4, 4, dynamic=True)
    assert batch_profile(None, [1]) == BatchProfile(1, 1, 1, dynamic=True)


def test_an_explicit_opt_is_kept_when_within_range() -> None:
    assert batch_profile(None, [1, 8], opt=2) == BatchProfile(1, 2, 8, dynamic=True)
    with pytest.raises(ConfigError, match=r"opt batch 9 must lie within 1\.\.8"):
        batch_profile(None, [1, 8], opt=9)


def test_a_static_batch_gets_a_fixed_profile_whatever_was_asked() -> None:
    assert batch_profile(1, [1, 8]) == BatchProfile(1, 1, 1, dynamic=False)
    assert batch_profile(4, [1]) == BatchProfile(4, 4, 4, dynamic=False)


@pytest.mark.parametrize("sizes", [[], [0], [2, -1]])
def test_bad_batch_sizes_are_refused(sizes: list[int]) -> None:
    with pytest.raises(ConfigError, match="batch sizes must be positive"):
        batch_profile(None, sizes)


def test_profile_order_is_validated() -> None:
    with pytest.raises(ConfigError, match="1 <= min <= opt <= max"):
        BatchProfile(2, 1, 4, dynamic=True)
    assert str(BatchProfile(1, 2, 4, dynamic=True)) == "1/2/4"


def test_shapes_for_a_dynamic_batch_model() -> None:
    shapes = profile_shapes((None, 3, 640, 640), [1, 8], opt=4)
    assert (shapes.min, shapes.opt, shapes.max) == (
        (1, 3, 640, 640),
        (4, 3, 640, 640),
        (8, 3, 640, 640),
    )
    assert shapes.batch.dynamic


def test_shapes_for_a_static_model() -> None:
    shapes = profile_shapes((1, 3, 384, 640), [1, 8])
    assert shapes.min == shapes.opt == shapes.max == (1, 3, 384, 640)
    assert not shapes.batch.dynamic


def test_dynamic_height_and_width_fall_back_to_the_given_size() -> None:
    shapes = profile_shapes((None, 3, None, None), [1], fallback_hw=(384, 640))
    assert shapes.max == (1, 3, 384, 640)
    with pytest.raises(ModelError, match="dynamic height or width and no size"):
        profile_shapes((None, 3, None, 640), [1])


@pytest.mark.parametrize(
    ("shape", "message"),
    [((1, 3, 640), "expected a \\[B, 3, H, W\\] input"), ((1, 1, 64, 64), "3 input channels")],
)
def test_inputs_that_are_not_images_are_refused(
    shape: tuple[int | None, ...], message: str
) -> None:
    with pytest.raises(ModelError, match=message):
        profile_shapes(shape, [1])


def test_calibration_runs_at_one_fixed_shape() -> None:
    dynamic = profile_shapes((None, 3, 640, 640), [1])
    assert calibration_shape(dynamic) == (8, 3, 640, 640)
    assert calibration_shape(dynamic, dynamic_batch=2) == (2, 3, 640, 640)
    static = profile_shapes((4, 3, 320, 320), [1])
    assert calibration_shape(static) == (4, 3, 320, 320)  # a fixed batch must be fed as is


def test_read_onnx_input_gives_declared_shape_and_metadata(tmp_path: Path) -> None:
    path = write_model(tmp_path / "m.onnx", ["batch", 3, 640, 640], {"names": "{0: 'cup'}"})
    assert read_onnx_input(path) == ((None, 3, 640, 640), {"names": "{0: 'cup'}"})


def test_model_profile_uses_imgsz_metadata_for_dynamic_sizes(tmp_path: Path) -> None:
    path = write_model(tmp_path / "m.onnx", ["b", 3, "h", "w"], {"imgsz": "[384, 640]"})
    shapes, metadata = model_profile(path, (1, 2, 4))
    assert shapes.max == (4, 3, 384, 640)
    assert shapes.opt == (2, 3, 384, 640)
    assert metadata["imgsz"] == "[384, 640]"
    static = write_model(tmp_path / "s.onnx", [1, 3, "h", "w"])
    assert model_profile(static, (1, 4, 8))[0].max == (1, 3, 640, 640)  # 640 by default


def test_read_onnx_input_refuses_missing_and_junk_files(tmp_path: Path) -> None:
    with pytest.raises(ModelError, match="no such model file"):
        read_onnx_input(tmp_path / "absent.onnx")
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"\x00\x01 definitely not protobuf \xff" * 10)
    with pytest.raises(ModelError, match="not a valid ONNX model"):
        read_onnx_input(junk)


def test_the_served_profile_is_1_to_max_batch_unless_one_was_set() -> None:
    assert served_profile((1, 1, 1), 1) == (1, 1, 1)  # one camera: as before
    assert served_profile([1, 1, 1], 4) == (1, 4, 4)  # a TOML list
    assert served_profile((1, 2, 8), 4) == (1, 2, 8)  # set explicitly: it wins
    with pytest.raises(ConfigError, match="max_batch"):
        served_profile((1, 1, 1), 0)
