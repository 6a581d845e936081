"""The TF.js -> ONNX translator, op by op, on tiny hand-built graph models.

Each test writes a small model.json + shard, converts it, runs it in ONNX Runtime and compares
with a numpy implementation of TensorFlow's NHWC semantics written here, independently of the
converter.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import onnx
import onnxruntime as ort
import pytest

from common.errors import ModelError
from modelprep.acquire.tfjs_graph import load_tfjs_graph
from modelprep.acquire.tfjs_to_onnx import build_onnx_model, save_onnx
from tests.unit.modelprep.acquire.tfjs_models import TfjsModel, fused_conv

Array = npt.NDArray[Any]
RNG = np.random.default_rng(7)


def _convert(
    model_json: Path,
    names: Sequence[str] = (),
    metadata: Mapping[str, str] | None = None,
    box_scale: tuple[float, ...] | None = None,
) -> Path:
    """Translate ``model_json`` (+ shards) as the fetch does, into model.onnx beside it."""
    onnx_path = model_json.with_name("model.onnx")
    graph = load_tfjs_graph(model_json)
    model = build_onnx_model(graph, names=names, metadata=metadata or {}, box_scale=box_scale)
    save_onnx(model, onnx_path)
    return onnx_path


def _run(
    model: TfjsModel,
    output: str,
    tmp_path: Path,
    x: Array,
    box_scale: tuple[float, ...] | None = None,
) -> Array:
    """Convert, run in ORT (feeding NCHW for 4-D inputs) and return the output."""
    onnx_path = _convert(
        model.write(tmp_path, output), ["a", "b"], {"task": "detect"}, box_scale=box_scale
    )
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    feed = x.transpose(0, 3, 1, 2) if x.ndim == 4 else x
    return np.asarray(session.run(["output0"], {"images": np.ascontiguousarray(feed)})[0])


# ---------------------------------------------------------------- numpy reference (TF, NHWC)


def _tf_pads(size: int, k: int, s: int, d: int, padding: str) -> tuple[int, int]:
    if padding == "VALID":
        return 0, 0
    out = -(-size // s)
    total = max((out - 1) * s + (k - 1) * d + 1 - size, 0)
    return total // 2, total - total // 2


def ref_conv(x: Array, w: Array, b: Array, stride: int, dilation: int, padding: str) -> Array:
    kh, kw = w.shape[:2]
    ph, pw = (_tf_pads(x.shape[i], w.shape[i - 1], stride, dilation, padding) for i in (1, 2))
    xp = np.pad(x, [(0, 0), ph, pw, (0, 0)])
    oh = (xp.shape[1] - (kh - 1) * dilation - 1) // stride + 1
    ow = (xp.shape[2] - (kw - 1) * dilation - 1) // stride + 1
    out = np.zeros((x.shape[0], oh, ow, w.shape[3]), np.float64)
    for a in range(kh):
        for c in range(kw):
            patch = xp[:, a * dilation :: stride, c * dilation :: stride][:, :oh, :ow]
            out += patch @ w[a, c]
    return (out + b).astype(np.float32)


def ref_maxpool(x: Array, k: int, stride: int, padding: str) -> Array:
    ph, pw = (_tf_pads(x.shape[i], k, stride, 1, padding) for i in (1, 2))
    xp = np.pad(x, [(0, 0), ph, pw, (0, 0)], constant_values=-np.inf)
    oh, ow = (xp.shape[1] - k) // stride + 1, (xp.shape[2] - k) // stride + 1
    windows = [xp[:, a::stride, c::stride][:, :oh, :ow] for a in range(k) for c in range(k)]
    return np.asarray(np.max(windows, axis=0))


def ref_resize(x: Array, out_h: int, out_w: int, *, align_corners: bool) -> Array:
    """TF's nearest neighbour: floor((i + .5) * in / out), or round(i * (in-1) / (out-1))."""

    def source(size_in: int, size_out: int) -> Array:
        i = np.arange(size_out)
        if align_corners:
            idx = np.floor(i * (size_in - 1) / (size_out - 1) + 0.5)
        else:
            idx = np.floor((i + 0.5) * size_in / size_out)
        return np.minimum(idx, size_in - 1).astype(int)

    return x[:, source(x.shape[1], out_h)][:, :, source(x.shape[2], out_w)]


def sigmoid(x: Array) -> Array:
    return np.asarray(1.0 / (1.0 + np.exp(-x)), np.float32)


def _rand(*shape: int) -> Array:
    return RNG.standard_normal(shape).astype(np.float32)


# ---------------------------------------------------------------- op tests


@pytest.mark.parametrize(
    ("size", "kernel", "stride", "dilation"),
    [
        ((7, 9), 3, 2, 1),
        ((8, 8), 3, 1, 2),
        ((6, 5), 1, 1, 1),
        ((9, 6), 4, 2, 1),
    ],
)
def test_fused_conv_same_padding(
    tmp_path: Path, size: tuple[int, int], kernel: int, stride: int, dilation: int
) -> None:
    x, w, b = _rand(1, *size, 3), _rand(kernel, kernel, 3, 4), _rand(4)
    model = TfjsModel(x.shape)
    out = fused_conv(model, "conv", "input_1", w, b, stride=stride, dilation=dilation)
    got = _run(model, out, tmp_path, x)
    np.testing.assert_allclose(got, ref_conv(x, w, b, stride, dilation, "SAME"), atol=1e-4)


def test_pad_then_valid_conv_with_fused_relu(tmp_path: Path) -> None:
    x, w, b = _rand(1, 6, 7, 2), _rand(3, 3, 2, 5), _rand(5)
    paddings = [[0, 0], [1, 2], [2, 1], [0, 0]]
    model = TfjsModel(x.shape)
    padded = model.op("pad", "Pad", ["input_1", model.const("p", paddings, np.int32)])
    out = fused_conv(
        model, "conv", padded, w, b, stride=2, padding="VALID", fused=("BiasAdd", "Relu")
    )
    expected = np.maximum(ref_conv(np.pad(x, paddings), w, b, 2, 1, "VALID"), 0)
    np.testing.assert_allclose(_run(model, out, tmp_path, x), expected, atol=1e-4)


def test_silu_broadcast_add_and_concats(tmp_path: Path) -> None:
    """SiLU, a channel-vector constant (re-laid out for NCHW) and concat on C and H."""
    x, w, b, bias = _rand(1, 4, 5, 3), _rand(1, 1, 3, 3), _rand(3), _rand(3)
    model = TfjsModel(x.shape)
    conv = fused_conv(model, "conv", "input_1", w, b)
    silu = model.op("mul", "Mul", [conv, model.op("sig", "Sigmoid", [conv])])
    shifted = model.op("add", "AddV2", [silu, model.const("bias", bias)])
    both = model.op("sum", "Add", [shifted, conv])
    channels = model.op("cat_c", "ConcatV2", [both, silu, model.const("ax_c", -1, np.int32)], N=2)
    out = model.op("cat_h", "ConcatV2", [channels, channels, model.const("ax_h", 1, np.int32)], N=2)
    y = ref_conv(x, w, b, 1, 1, "SAME")
    s = y * sigmoid(y)
    c = np.concatenate([s + bias + y, s], axis=-1)
    np.testing.assert_allclose(_run(model, out, tmp_path, x), np.concatenate([c, c], 1), atol=1e-4)


@pytest.mark.parametrize(
    ("k", "stride", "padding"), [(5, 1, "SAME"), (2, 2, "VALID"), (3, 2, "SAME")]
)
def test_max_pool(tmp_path: Path, k: int, stride: int, padding: str) -> None:
    x = _rand(1, 7, 6, 2)
    model = TfjsModel(x.shape)
    out = model.op(
        "pool",
        "MaxPool",
        ["input_1"],
        ksize=[1, k, k, 1],
        strides=[1, stride, stride, 1],
        padding=padding,
        data_format="NHWC",
    )
    np.testing.assert_array_equal(_run(model, out, tmp_path, x), ref_maxpool(x, k, stride, padding))


@pytest.mark.parametrize(
    ("out_size", "align_corners"),
    [((8, 10), False), ((12, 15), False), ((7, 9), False), ((7, 9), True)],
)
def test_resize_nearest(tmp_path: Path, out_size: tuple[int, int], align_corners: bool) -> None:
    """2x and 3x become "asymmetric" Resize; 7x9 (non-integer) needs TF's own rounding."""
    x = _rand(1, 4, 5, 3)
    model = TfjsModel(x.shape)
    out = model.op(
        "up",
        "ResizeNearestNeighbor",
        ["input_1", model.const("size", out_size, np.int32)],
        half_pixel_centers=not align_corners,
        align_corners=align_corners,
    )
    got = _run(model, out, tmp_path, x)
    np.testing.assert_array_equal(got, ref_resize(x, *out_size, align_corners=align_corners))
    if out_size == (8, 10):
        resize = next(
            n for n in onnx.load(str(tmp_path / "model.onnx")).graph.node if n.op_type == "Resize"
        )
        modes = {a.name: a.s.decode() for a in resize.attribute if a.type == a.STRING}
        assert modes["coordinate_transformation_mode"] == "asymmetric"


def test_detect_head_reshape_transpose_slices_and_box_scale(tmp_path: Path) -> None:
    """The YOLOv5 TF head: conv -> [-1, HW, A, 6] -> transpose -> sigmoid -> decode."""
    x, w, b = _rand(1, 2, 3, 4), _rand(1, 1, 4, 12), _rand(12)
    grid, anchor = _rand(1, 1, 6, 2), _rand(2, 1, 2)
    m = TfjsModel(x.shape)
    conv = fused_conv(m, "conv", "input_1", w, b)
    rs = m.op("rs", "Reshape", [conv, m.const("shape", [-1, 6, 2, 6], np.int32)])
    sig = m.op(
        "sig", "Sigmoid", [m.op("tr", "Transpose", [rs, m.const("perm", [0, 2, 1, 3], np.int32)])]
    )

    def cut(name: str, begin: int, end: int, end_mask: int = 0) -> str:
        consts = [
            m.const(f"{name}/{i}", v, np.int32)
            for i, v in enumerate(([0, begin], [0, end], [1, 1]))
        ]
        return m.op(name, "StridedSlice", [sig, *consts], ellipsis_mask=1, end_mask=end_mask)

    xy = m.op(
        "xy",
        "Add",
        [m.op("m2", "Mul", [cut("s0", 0, 2), m.const("two", 2.0)]), m.const("grid", grid)],
    )
    wh = m.op("wh", "Mul", [m.op("sq", "Square", [cut("s1", 2, 4)]), m.const("anchor", anchor)])
    cat = m.op(
        "cat", "ConcatV2", [xy, wh, cut("s2", 4, 0, end_mask=2), m.const("axis", -1, np.int32)], N=3
    )
    out = m.op("flat", "Reshape", [cat, m.const("shape2", [-1, 12, 6], np.int32)])
    got = _run(m, out, tmp_path, x, box_scale=(10.0, 20.0, 10.0, 20.0))
    p = sigmoid(ref_conv(x, w, b, 1, 1, "SAME").reshape(1, 6, 2, 6).transpose(0, 2, 1, 3))
    ref = np.concatenate([p[..., :2] * 2 + grid, p[..., 2:4] ** 2 * anchor, p[..., 4:]], -1)
    ref = ref.reshape(1, 12, 6) * np.array([10, 20, 10, 20, 1, 1], np.float32)
    np.testing.assert_allclose(got, ref, atol=1e-5)


@pytest.mark.parametrize(
    ("spec", "index"),
    [
        # (begin, end, strides, begin_mask, end_mask, ellipsis, new_axis, shrink), numpy index
        (([1, 0, -3], [0, 0, 0], [1, 2, 1], 0b010, 0b111, 0, 0, 0), np.s_[1:, ::2, -3:]),
        (
            ([0, 0, 0, 1], [1, 0, 0, 4], [1, 1, 1, 1], 0, 0, 0b10, 0b100, 0b1),
            np.s_[0, ..., None, 1:4],
        ),
        (([0, 0], [0, 0], [1, -1], 0b11, 0b11, 0, 0, 0), np.s_[:, ::-1]),
        (([0, 2], [0, 3], [1, 1], 0, 0, 0b1, 0, 0b10), np.s_[..., 2]),
        (([1, -1], [-1, -5], [1, -2], 0, 0, 0, 0, 0), np.s_[1:-1, -1:-5:-2]),
    ],
)
def test_strided_slice_masks(tmp_path: Path, spec: tuple[Any, ...], index: Any) -> None:
    begin, end, strides, begin_mask, end_mask, ellipsis, new_axis, shrink = spec
    x = _rand(3, 5, 6)
    model = TfjsModel(x.shape)
    consts = [model.const(f"c{i}", v, np.int32) for i, v in enumerate((begin, end, strides))]
    out = model.op(
        "slice",
        "StridedSlice",
        ["input_1", *consts],
        begin_mask=begin_mask,
        end_mask=end_mask,
        ellipsis_mask=ellipsis,
        new_axis_mask=new_axis,
        shrink_axis_mask=shrink,
    )
    np.testing.assert_array_equal(_run(model, out, tmp_path, x), x[index])


def test_io_names_shapes_and_metadata(tmp_path: Path) -> None:
    model = TfjsModel((1, 8, 8, 3))
    out = model.op("sig", "Sigmoid", ["input_1"])
    onnx_path = _convert(model.write(tmp_path, out), ["traffic light", "cat"], {"imgsz": "[8, 8]"})
    loaded = onnx.load(str(onnx_path))
    dims = [d.dim_value for d in loaded.graph.input[0].type.tensor_type.shape.dim]
    assert (loaded.graph.input[0].name, dims) == ("images", [1, 3, 8, 8])
    assert loaded.graph.output[0].name == "output0"
    props = {p.key: p.value for p in loaded.metadata_props}
    assert props == {"names": "{0: 'traffic light', 1: 'cat'}", "imgsz": "[8, 8]"}
    assert loaded.opset_import[0].version >= 13


# ---------------------------------------------------------------- errors


def test_unsupported_op_is_a_model_error_naming_it(tmp_path: Path) -> None:
    model = TfjsModel((1, 4, 4, 3))
    out = model.op("r6", "Relu6", ["input_1"])
    with pytest.raises(ModelError, match="Relu6"):
        _convert(model.write(tmp_path, out))


def test_missing_shard_and_bad_json_are_model_errors(tmp_path: Path) -> None:
    model = TfjsModel((1, 4, 4, 3))
    model.const("w", [1.0, 2.0])
    model_json = model.write(tmp_path, "input_1")
    (tmp_path / "group1-shard1of1.bin").unlink()
    with pytest.raises(ModelError, match="shard"):
        _convert(model_json)
    model_json.write_text("{not json")
    with pytest.raises(ModelError, match="JSON"):
        _convert(model_json)
