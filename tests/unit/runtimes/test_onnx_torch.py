"""The ONNX -> torch interpreter against ONNX Runtime, op by op and on nudenet's YOLOv8 export.

Runs on CPU PyTorch (a dev dependency); the GPU side is in tests/integration/test_cuda_backend.py.
"""

from __future__ import annotations

import importlib.resources
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
import onnx
import onnxruntime as ort
import pytest
import torch
from onnx import TensorProto, helper, numpy_helper
from skimage import data

from common.errors import BackendUnavailable, ConfigError, ModelError
from common.letterbox import Preprocessor
from runtimes import BACKENDS, open_backend
from runtimes import cuda as cuda_backend
from runtimes.onnx_torch.interpreter import OPS, build_module, load_module

RNG = np.random.default_rng(0)
F32 = np.float32
I64 = np.int64


def rand(*shape: int) -> npt.NDArray[np.float32]:
    return RNG.standard_normal(shape).astype(F32)


class L(NamedTuple):
    """A graph input (a live tensor); plain arrays in a case are initializers (constants)."""

    value: npt.NDArray[Any]


@dataclass
class Case:
    id: str
    nodes: list[onnx.NodeProto]
    live: dict[str, npt.NDArray[Any]]
    consts: dict[str, npt.NDArray[Any]] = field(default_factory=dict)
    outputs: list[str] = field(default_factory=lambda: ["y0"])
    opset: int = 17

    def model(self) -> onnx.ModelProto:
        inputs = [
            helper.make_tensor_value_info(k, helper.np_dtype_to_tensor_dtype(v.dtype), v.shape)
            for k, v in self.live.items()
        ]
        graph = helper.make_graph(
            self.nodes,
            self.id,
            inputs,
            [onnx.ValueInfoProto(name=o) for o in self.outputs],  # ORT infers the types
            initializer=[numpy_helper.from_array(np.asarray(v), k) for k, v in self.consts.items()],
        )
        return helper.make_model(
            graph, opset_imports=[helper.make_opsetid("", self.opset)], ir_version=9
        )


def one(
    op: str, *inputs: Any, outputs: int = 1, opset: int = 17, tag: str = "", **attrs: Any
) -> Case:
    """A one-node graph; each input is an ``L`` (graph input), an array (constant) or None."""
    names, live, consts = [], {}, {}
    for i, value in enumerate(inputs):
        if value is None:
            names.append("")
        elif isinstance(value, L):
            live[f"x{i}"] = value.value
            names.append(f"x{i}")
        else:
            consts[f"k{i}"] = np.asarray(value)
            names.append(f"k{i}")
    outs = [f"y{j}" for j in range(outputs)]
    node = helper.make_node(op, names, outs, **attrs)
    return Case(f"{op}{tag}", [node], live, consts, outs, opset)


X = rand(1, 4, 6, 6)


def i64(value: Any) -> npt.NDArray[np.int64]:
    """An int64 constant: the type ONNX gives shapes, axes, pads and indices."""
    return np.array(value, dtype=I64)


def _cases() -> list[Case]:
    x = L(X)
    cases = [
        one("Conv", x, rand(8, 4, 3, 3), rand(8), pads=[1, 1, 1, 1], strides=[2, 2]),
        one(
            "Conv",
            x,
            rand(4, 2, 2, 2),
            tag="_asym_group",
            pads=[0, 1, 1, 0],
            group=2,
            dilations=[2, 1],
        ),
        one("Conv", x, rand(3, 4, 3, 3), tag="_same", auto_pad="SAME_UPPER", strides=[2, 2]),
        one("MaxPool", x, kernel_shape=[5, 5], pads=[2, 2, 2, 2], strides=[1, 1]),
        one("MaxPool", x, tag="_ceil", kernel_shape=[3, 3], strides=[2, 2], ceil_mode=1),
        one("MaxPool", x, tag="_asym", kernel_shape=[2, 2], pads=[0, 0, 1, 1], strides=[2, 2]),
        one("AveragePool", x, kernel_shape=[3, 3], pads=[1, 1, 1, 1]),
        one("Pad", x, i64([0, 0, 1, 2, 0, 0, 2, 1]), np.array(0.5, F32)),
        one("Pad", x, i64([0, 0, 1, 2, 0, 0, 2, 1]), tag="_reflect", mode="reflect"),
        one("Pad", x, i64([0, 0, 2, 0, 0, 0, 0, 1]), tag="_edge", mode="edge"),
        one(
            "Resize",
            x,
            None,
            np.array([1, 1, 2, 2], F32),
            mode="nearest",
            coordinate_transformation_mode="asymmetric",
            nearest_mode="floor",
        ),
        one("Resize", x, None, np.array([1, 1, 3, 2], F32), tag="_half_pixel", mode="nearest"),
        one("Resize", x, None, None, i64([1, 4, 9, 4]), tag="_linear", mode="linear"),
        one(
            "Resize",
            x,
            None,
            None,
            i64([1, 4, 9, 9]),
            tag="_corners",
            mode="linear",
            coordinate_transformation_mode="align_corners",
        ),
        one("Reshape", x, i64([0, 2, -1])),
        one("Transpose", x, perm=[0, 2, 3, 1]),
        one("Slice", x, i64([1, 0]), i64([3, 2**62]), i64([1, 3]), i64([1, 2])),
        one(
            "Slice", x, i64([-1, 4]), i64([-(2**62), 0]), i64([2, 3]), i64([-2, -1]), tag="_reverse"
        ),
        one("Split", x, i64([1, 3]), axis=1, outputs=2),
        one("Split", x, axis=2, outputs=3, tag="_equal"),
        one("Concat", x, rand(1, 2, 6, 6), axis=1),
        one("Softmax", x, axis=1),
        one("Softmax", x, axis=2, opset=11, tag="_opset11"),
        one("Gather", x, i64([[0, 2], [-1, 1]]), axis=1),
        one("Gather", x, i64(3), axis=3, tag="_scalar"),
        one("Unsqueeze", x, i64([0, -1])),
        one("Squeeze", x, i64([0])),
        one("Expand", L(rand(1, 4, 1, 6)), i64([2, 1, 3, 1])),
        one("Flatten", x, axis=2),
        one("Cast", x, to=TensorProto.INT64),
        one("Cast", L(np.arange(6, dtype=I64).reshape(2, 3)), to=TensorProto.FLOAT, tag="_float"),
        one("Div", L(i64([[7, -7, 9]])), i64([2, 2, -4]), tag="_int"),
        one("Clip", x, np.array(-0.5, F32), np.array(0.7, F32)),
        one("HardSigmoid", x, alpha=0.3),
        one("LeakyRelu", x, alpha=0.1),
        one("MatMul", L(rand(2, 3, 4)), rand(4, 5)),
        one("Gemm", L(rand(3, 4)), rand(5, 4), rand(5), transB=1, alpha=0.5, beta=2.0),
        one("BatchNormalization", x, rand(4), rand(4), rand(4), np.abs(rand(4)) + 0.1),
        one("ReduceMean", x, i64([1, 3]), keepdims=0, opset=18),
        one("ReduceMax", x, axes=[2], opset=13),
        one("ReduceMin", x, i64([-1]), opset=18),
        one("ReduceSum", x, opset=18),
        one("ArgMax", x, axis=1, keepdims=0),
        one("Where", L(X > 0), x, rand(1, 1, 6, 6)),
        one("Max", x, rand(1, 4, 1, 1), rand(6)),
        one("Min", x, rand(1, 4, 1, 1)),
        one("Identity", x),
        one("Shape", x, start=1),
        one("Size", x),
    ]
    for op in ("Add", "Sub", "Mul", "Div", "Equal", "Less", "Greater"):
        cases.append(one(op, x, rand(1, 4, 1, 1)))
    cases.append(one("Pow", L(np.abs(X) + 0.1), rand(1, 4, 1, 1)))
    cases.append(one("And", L(X > 0), L(X < 0.5)))
    cases.append(one("Not", L(X > 0)))
    unary = (
        "Sigmoid",
        "Relu",
        "Tanh",
        "Exp",
        "Abs",
        "Neg",
        "Floor",
        "Ceil",
        "Erf",
        "HardSwish",
        "GlobalAveragePool",
        "GlobalMaxPool",
    )
    cases += [one(op, x) for op in unary]
    cases += [one(op, L(np.abs(X) + 0.1)) for op in ("Sqrt", "Log", "Reciprocal")]
    # Shape arithmetic on a live tensor folds at build time, as in an Ultralytics export.
    nodes = [
        helper.make_node("Shape", ["x"], ["s"]),
        helper.make_node("Gather", ["s", "k_i"], ["c"], axis=0),
        helper.make_node("Unsqueeze", ["c", "k_ax"], ["cu"]),
        helper.make_node("Concat", ["k_neg", "cu"], ["shape"], axis=0),
        helper.make_node("Reshape", ["x", "shape"], ["r"]),
        helper.make_node("Cast", ["c"], ["cf"], to=TensorProto.FLOAT),
        helper.make_node("Range", ["k_zero", "cf", "k_one"], ["grid"]),
        helper.make_node("Shape", ["r"], ["rs"]),
        helper.make_node(
            "ConstantOfShape",
            ["rs"],
            ["half"],
            value=helper.make_tensor("v", TensorProto.FLOAT, [1], [0.5]),
        ),
        helper.make_node("Constant", [], ["three"], value_float=3.0),
        helper.make_node("Mul", ["r", "three"], ["r3"]),
        helper.make_node("Add", ["r3", "grid"], ["g"]),
        helper.make_node("Sub", ["g", "half"], ["y0"]),
    ]
    consts: dict[str, npt.NDArray[Any]] = {
        "k_i": i64(3),
        "k_ax": i64([0]),
        "k_neg": i64([-1]),
        "k_zero": np.array(0.0, F32),
        "k_one": np.array(1.0, F32),
    }
    cases.append(Case("folded_shape_chain", nodes, {"x": X}, consts))
    return cases


CASES = _cases()


def _ours(case: Case) -> list[npt.NDArray[Any]]:
    module = build_module(case.model())
    with torch.inference_mode():
        outputs = module(*(torch.from_numpy(v) for v in case.live.values()))
    return [o.numpy() for o in outputs]


def _reference(case: Case) -> list[npt.NDArray[Any]]:
    session = ort.InferenceSession(
        case.model().SerializeToString(), providers=["CPUExecutionProvider"]
    )
    return list(session.run(None, case.live))


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_op_matches_onnxruntime(case: Case) -> None:
    ours, ref = _ours(case), _reference(case)
    assert len(ours) == len(ref)
    for got, want in zip(ours, ref, strict=True):
        assert got.dtype == want.dtype and got.shape == want.shape
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)


def test_every_op_in_the_table_is_tested() -> None:
    tested = {node.op_type for case in CASES for node in case.nodes}
    assert set(OPS) - tested == set()


def test_shape_arithmetic_is_folded_away() -> None:
    case = next(c for c in CASES if c.id == "folded_shape_chain")
    assert build_module(case.model()).num_steps == 4  # Reshape, Mul, Add, Sub


def test_unsupported_op_is_a_one_line_model_error() -> None:
    case = one("Einsum", L(X), rand(6, 6), equation="ncij,jk->ncik")
    with pytest.raises(ModelError, match=r"unsupported ONNX op Einsum \(node") as err:
        build_module(case.model())
    assert "\n" not in str(err.value)
    custom = one("Relu", L(X))
    custom.nodes[0].domain = "com.microsoft"
    with pytest.raises(ModelError, match=r"unsupported ONNX op com\.microsoft\.Relu"):
        build_module(custom.model())


def test_unsupported_resize_mode_is_a_model_error() -> None:
    case = one("Resize", L(X), None, np.array([1, 1, 2, 2], F32), mode="cubic")
    with pytest.raises(ModelError, match="Resize mode=cubic"):
        build_module(case.model())


def test_dynamic_input_needs_a_static_shape() -> None:
    model = one("Relu", L(X)).model()
    model.graph.input[0].type.tensor_type.shape.dim[2].dim_param = "height"
    with pytest.raises(ModelError, match="has a dynamic shape"):
        build_module(model)
    assert build_module(model, [(1, 4, 5, 6)]).output_shapes == ((1, 4, 5, 6),)


def test_fp16_precision_casts_float_buffers_only() -> None:
    module = build_module(one("Gather", L(X), i64([0, 2]), axis=1).model()).set_precision(
        torch.float16
    )
    assert {str(b.dtype) for b in module.buffers()} == {"torch.int64"}
    conv = build_module(one("Conv", L(X), rand(8, 4, 3, 3)).model()).set_precision(torch.float16)
    assert {b.dtype for b in conv.buffers()} == {torch.float16}


# --- a real YOLOv8 export ------------------------------------------------------------------


def test_nudenet_yolov8_matches_onnxruntime_on_a_photo() -> None:
    path = Path(str(importlib.resources.files("nudenet") / "320n.onnx"))
    batch, _ = Preprocessor(320, 320, 1).run([np.ascontiguousarray(data.astronaut()[:, :, ::-1])])
    module = load_module(path, [batch.shape])
    with torch.inference_mode():
        ours = module(torch.from_numpy(batch.copy()))[0].numpy()
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (want,) = session.run(None, {"images": batch})
    assert ours.shape == want.shape == (1, 22, 2100)
    np.testing.assert_allclose(ours, want, rtol=1e-3, atol=5e-3)  # boxes are pixels up to 320
    assert want[0, 4:].max() > 0.5  # the photo does give confident scores to compare


# --- the backend on a machine without CUDA -------------------------------------------------


@pytest.fixture()
def tiny_model(tmp_path: Path) -> Path:
    case = one("Conv", L(rand(1, 3, 32, 32)), rand(6, 3, 3, 3), pads=[1, 1, 1, 1])
    model = case.model()
    model.graph.input[0].name = model.graph.node[0].input[0] = "images"
    path = tmp_path / "tiny.onnx"
    onnx.save(model, str(path))
    return path


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA GPU")
def test_cuda_backend_refuses_a_machine_without_cuda(tiny_model: Path) -> None:
    version = ".".join(torch.__version__.split("+")[0].split(".")[:2])
    with pytest.raises(BackendUnavailable, match=rf"PyTorch has no CUDA device \(torch {version}"):
        cuda_backend.load(tiny_model)


def test_reason_names_a_cpu_build(monkeypatch: pytest.MonkeyPatch, tiny_model: Path) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(torch.version, "cuda", None)
    with pytest.raises(
        BackendUnavailable, match=r"no CUDA device \(torch \d+\.\d+, built for CPU\)$"
    ):
        cuda_backend.load(tiny_model, precision="fp32")


def test_missing_torch_is_backend_unavailable(
    monkeypatch: pytest.MonkeyPatch, tiny_model: Path
) -> None:
    monkeypatch.setitem(BACKENDS, "cuda", "runtimes.cuda")
    monkeypatch.setitem(sys.modules, "torch", None)  # makes `import torch` fail
    for name in (
        "cuda",
        "onnx_torch",
        "onnx_torch.interpreter",
        "onnx_torch.tensor_ops",
        "onnx_torch.spatial_ops",
    ):
        monkeypatch.delitem(sys.modules, f"runtimes.{name}", raising=False)
    with pytest.raises(BackendUnavailable, match="PyTorch is not installed"):
        open_backend("cuda", tiny_model)


def test_cpu_device_runs_the_interpreter(tiny_model: Path) -> None:
    backend = cuda_backend.load(tiny_model, device="cpu", precision="fp32")
    assert (backend.name, backend.device, backend.precision) == ("cuda", "cpu", "fp32")
    assert backend.input_shape == (1, 3, 32, 32) and backend.output_shapes == ((1, 6, 32, 32),)
    batch = rand(1, 3, 32, 32)
    session = ort.InferenceSession(str(tiny_model), providers=["CPUExecutionProvider"])
    np.testing.assert_allclose(
        backend.infer(batch)[0], session.run(None, {"images": batch})[0], rtol=1e-5, atol=1e-5
    )
    two = rand(2, 3, 32, 32)  # more rows than the fixed batch: run in parts
    want = np.concatenate([session.run(None, {"images": two[i : i + 1]})[0] for i in (0, 1)])
    np.testing.assert_allclose(backend.infer(two)[0], want, rtol=1e-5, atol=1e-5)
    with pytest.raises(ModelError, match=r"batch shape \[1, 3, 16, 16\] is not"):
        backend.infer(rand(1, 3, 16, 16))
    backend.close()
    with pytest.raises(ModelError, match="closed"):
        backend.infer(batch)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"device": "cpu", "precision": "fp16"}, "fp32 only"),
        ({"device": "cpu", "precision": "int8"}, "precision must be one of"),
        ({"device": "tpu:0", "precision": "fp32"}, "device must be"),
        ({"device": "cpu", "precision": "fp32", "max_batch": 0}, "max_batch must be a positive"),
    ],
)
def test_bad_options_are_config_errors(
    tiny_model: Path, options: dict[str, Any], message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        cuda_backend.load(tiny_model, **options)


@pytest.fixture()
def tiny_dynamic_model(tiny_model: Path) -> Path:
    """The tiny model with a dynamic batch, named and denoted as our converter writes it."""
    model = onnx.load(str(tiny_model))
    dim = model.graph.input[0].type.tensor_type.shape.dim[0]
    dim.dim_param, dim.denotation = "batch", "DATA_BATCH"
    path = tiny_model.with_name("tiny-dynamic.onnx")
    onnx.save(model, str(path))
    return path


def test_batch_sizes_are_powers_of_two_then_the_largest() -> None:
    assert cuda_backend.batch_sizes(1) == (1,)
    assert cuda_backend.batch_sizes(4) == (1, 2, 4)
    assert cuda_backend.batch_sizes(5) == (1, 2, 4, 5)
    assert cuda_backend.batch_sizes(32) == (1, 2, 4, 8, 16, 32)


def test_a_dynamic_batch_runs_every_size_as_single_images_do(tiny_dynamic_model: Path) -> None:
    backend = cuda_backend.CudaBackend(
        tiny_dynamic_model, device="cpu", precision="fp32", max_batch=5
    )
    assert backend.batch_sizes == (1, 2, 4, 5)
    assert backend.input_shape == (None, 3, 32, 32)
    assert backend.output_shapes == ((None, 6, 32, 32),)
    images = rand(7, 3, 32, 32)
    singles = np.concatenate([backend.infer(images[i : i + 1])[0] for i in range(7)])
    for rows in (1, 2, 3, 5, 7):  # 3 runs padded to 4; 7 runs as 5 + 2
        got = backend.infer(images[:rows])[0]
        assert got.shape == (rows, 6, 32, 32)
        np.testing.assert_allclose(got, singles[:rows], rtol=1e-5, atol=1e-5)
    # One copy of the weights, whatever the number of sizes.
    modules = [size.module for size in backend._sizes]
    weight = {n: b.data_ptr() for n, b in modules[0].named_buffers() if b.dim() == 4}
    assert weight and all(
        dict(m.named_buffers())[n].data_ptr() == ptr for m in modules for n, ptr in weight.items()
    )
    with pytest.raises(ModelError, match=r"batch shape \[2, 3, 16, 16\] is not"):
        backend.infer(rand(2, 3, 16, 16))
    backend.close()


def test_a_fixed_batch_is_the_models_own_whatever_max_batch_says(
    tiny_model: Path, tiny_dynamic_model: Path
) -> None:
    backend = cuda_backend.load(tiny_model, device="cpu", precision="fp32", max_batch=4)
    assert backend.input_shape == (1, 3, 32, 32)  # the Detector cuts batches to it
    backend.close()
    one = cuda_backend.load(tiny_dynamic_model, device="cpu", precision="fp32")
    assert one.input_shape == (1, 3, 32, 32)  # max_batch 1: built as a batch-1 export
    one.close()


def test_not_a_model_is_a_model_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"\x00garbage\xff" * 10)
    with pytest.raises(ModelError, match="not a valid ONNX model"):
        cuda_backend.load(bad, device="cpu", precision="fp32")
    with pytest.raises(ModelError, match="no such model file"):
        cuda_backend.load(tmp_path / "missing.onnx", device="cpu", precision="fp32")
