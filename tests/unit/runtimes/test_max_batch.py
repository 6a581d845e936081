"""``max_batch`` on the CPU runtimes: a dynamic batch pinned to 1 for single frames (the
default), bounded by ``max_batch`` otherwise; a fixed batch left as the model has it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.errors import ConfigError
from runtimes import open_backend
from tests.unit.detector.halves import halves_model

RNG = np.random.default_rng(5)


def batch_of(n: int) -> np.ndarray:
    return RNG.random((n, 3, 32, 32), dtype=np.float32)


def denoted(tmp_path: Path) -> Path:
    """The halves model with its batch denoted DATA_BATCH, as our converter writes it."""
    import onnx

    path = halves_model(tmp_path)
    model = onnx.load(str(path))
    model.graph.input[0].type.tensor_type.shape.dim[0].denotation = "DATA_BATCH"
    onnx.save(model, str(path))
    return path


def test_onnx_pins_a_denoted_batch_to_1_and_leaves_it_dynamic_for_more(tmp_path: Path) -> None:
    path = denoted(tmp_path)
    single = open_backend("onnx", path)
    assert single.input_shape == (1, 3, 32, 32)  # as a batch-1 export: exactly as before
    several = open_backend("onnx", path, max_batch=4)
    assert several.input_shape == (None, 3, 32, 32)
    images = batch_of(4)
    want = np.concatenate([single.infer(images[i : i + 1])[0] for i in range(4)])
    np.testing.assert_allclose(several.infer(images)[0], want, atol=1e-6)
    # An undenoted dynamic batch (another exporter's) stays dynamic, as it always did.
    assert open_backend("onnx", halves_model(tmp_path)).input_shape == (None, 3, 32, 32)
    with pytest.raises(ConfigError, match="max_batch"):
        open_backend("onnx", path, max_batch=0)


def test_openvino_compiles_batch_1_or_a_batch_bounded_by_max_batch(tmp_path: Path) -> None:
    pytest.importorskip("openvino", reason="the openvino extra is not installed")
    path = halves_model(tmp_path)
    single = open_backend("openvino", path)
    assert single.input_shape == (1, 3, 32, 32)
    several = open_backend("openvino", path, max_batch=3)
    assert several.input_shape == (None, 3, 32, 32)
    images = batch_of(3)
    want = np.concatenate([single.infer(images[i : i + 1])[0] for i in range(3)])
    for rows in (3, 2, 1):
        np.testing.assert_allclose(several.infer(images[:rows])[0], want[:rows], atol=1e-5)
    fixed = open_backend("openvino", halves_model(tmp_path, batch=2), max_batch=3)
    assert fixed.input_shape == (2, 3, 32, 32)  # the model's own: the Detector cuts to it
    with pytest.raises(ConfigError, match="max_batch"):
        open_backend("openvino", path, max_batch=0)
