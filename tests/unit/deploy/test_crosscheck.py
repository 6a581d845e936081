"""Settings of two services that cannot work together are refused with one line."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from onnx import TensorProto, helper

from common.errors import ConfigError
from deploy.crosscheck import cross_check, model_classes
from services.controller.contract import ControllerSettings
from services.detector.contract import DetectorSettings
from stack.config import Config, SupervisorSettings


def _config(**tables: object) -> Config:
    base = Config(path="test")
    return dataclasses.replace(base, **tables)  # type: ignore[arg-type]


def _classes(*names: str):  # type: ignore[no-untyped-def]
    return lambda _config: names


def test_a_filter_that_hides_the_target() -> None:
    config = _config(detector=DetectorSettings(classes=("cup",)))
    with pytest.raises(ConfigError, match=r"filters out controller.target_classes \['person'\]"):
        cross_check(config, _classes("person", "cup"))


def test_a_target_the_model_lacks_gets_a_suggestion() -> None:
    config = _config(controller=ControllerSettings(target_classes=("persn",)))
    with pytest.raises(ConfigError, match=r"did you mean 'persn' -> 'person'"):
        cross_check(config, _classes("person", "cup"))
    with pytest.raises(ConfigError, match=r"\['zzz'\] are not among the model's 2 classes: "):
        cross_check(
            _config(controller=ControllerSettings(target_classes=("zzz",))),
            _classes("person", "cup"),
        )


def test_what_works_together_passes() -> None:
    cross_check(_config(detector=DetectorSettings(classes=("person",))), _classes("person"))
    cross_check(_config(), lambda _c: None)  # classes unknown before the model loads
    # A detector on another host: its controller checks at run time.
    alone = _config(
        supervisor=SupervisorSettings(services=("controller",)),
        detector=DetectorSettings(classes=("cup",)),
    )
    cross_check(alone, _classes("cup"))


def test_model_classes_of_the_default_and_of_an_onnx_file(tmp_path: Path) -> None:
    default = model_classes(_config())
    assert default is not None and len(default) == 80 and default[0] == "person"
    graph = helper.make_graph(
        [helper.make_node("Identity", ["x"], ["y"])],
        "g",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])],
    )
    model = helper.make_model(graph)
    helper.set_model_props(model, {"names": "{0: 'forklift', 1: 'pallet'}"})
    path = tmp_path / "custom.onnx"
    path.write_bytes(model.SerializeToString())
    custom = _config(detector=DetectorSettings(model=str(path)))
    assert model_classes(custom) == ("forklift", "pallet")
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"not a model")
    assert model_classes(_config(detector=DetectorSettings(model=str(garbage)))) is None
