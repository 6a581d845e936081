"""The detection library's own settings (perception/settings.py), and its lazy package root:
importing the settings (as the detector's contract, and so the stack's config, does) loads no
model code."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import perception
from common.errors import ConfigError
from common.setting_checks import declared_bounds
from perception.settings import DecodeOptions, DetectorSpec, ModelSpec, TrackerParams
from runtimes import BACKEND_CHOICES

ROOT = Path(__file__).resolve().parents[3]


def test_settings_accept_exactly_the_backend_choices() -> None:
    for name in BACKEND_CHOICES:
        assert ModelSpec(backend=name).backend == name
    with pytest.raises(
        ConfigError, match=r"detector\.backend must be one of onnx, tensorrt, cuda, openvino, auto"
    ):
        ModelSpec(backend="tpu")


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"precision": "int4"}, "detector.precision must be one of"),
        ({"batch_profile": (2, 1, 4)}, "detector.batch_profile must be"),
        ({"batch_profile": (0, 1, 1)}, "detector.batch_profile must be"),
        ({"profile": "quick"}, "detector.profile must be one of default, fast"),
    ],
)
def test_settings_validate_precision_and_batch_profile(
    fields: dict[str, Any], message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        ModelSpec(**fields)
    with pytest.raises(ConfigError, match=message):
        DetectorSpec(**fields)


def test_decode_options_and_the_tracker_check_their_own() -> None:
    with pytest.raises(ConfigError, match=r"detector\.conf must be within 0\.\.1, got 2"):
        DecodeOptions(conf=2)
    with pytest.raises(ConfigError, match=r"detector\.classes must be non-empty class names"):
        DetectorSpec(classes=("person", ""))
    with pytest.raises(ConfigError, match=r"tracker\.low_score must not be above"):
        TrackerParams(low_score=0.5, high_score=0.4)


def test_a_detector_spec_is_a_model_spec_and_decode_options() -> None:
    spec = DetectorSpec(model="m.onnx", conf=0.5)
    assert isinstance(spec, ModelSpec) and isinstance(spec, DecodeOptions)
    assert (spec.model, spec.conf, spec.iou) == ("m.onnx", 0.5, DecodeOptions().iou)
    assert declared_bounds(DetectorSpec) == {
        **declared_bounds(ModelSpec),
        **declared_bounds(DecodeOptions),
    }


def _type_checking_imports() -> dict[str, tuple[str, str]]:
    """The names perception/__init__.py imports under ``if TYPE_CHECKING:``."""
    tree = ast.parse((ROOT / "perception" / "__init__.py").read_text(encoding="utf-8"))
    block = next(n for n in tree.body if isinstance(n, ast.If))
    found = {}
    for node in ast.walk(block):
        if isinstance(node, ast.ImportFrom) and node.module:
            for alias in node.names:
                found[alias.asname or alias.name] = (node.module, alias.name)
    return found


def test_the_lazy_exports_agree_with_what_type_checkers_see() -> None:
    exports = perception._EXPORTS
    assert _type_checking_imports() == exports
    assert sorted(perception.__all__) == sorted(exports)
    for name, (module, attribute) in exports.items():
        assert getattr(perception, name) is getattr(sys.modules[module], attribute), name
    with pytest.raises(AttributeError, match="has no attribute 'nothing'"):
        _ = perception.nothing  # type: ignore[attr-defined]


def _modules_after(code: str) -> set[str]:
    done = subprocess.run(
        [sys.executable, "-c", f"{code}\nimport sys\nprint(' '.join(sys.modules))"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    return set(done.stdout.split())


def test_the_stack_config_reads_the_library_settings_without_loading_models() -> None:
    modules = _modules_after("import stack.config")
    assert "perception.settings" in modules  # through the detector's contract
    assert sorted(m for m in modules if m.startswith("perception.")) == ["perception.settings"]
    assert "numpy" not in modules and "cv2" not in modules
