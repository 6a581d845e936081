"""PyTorch on an NVIDIA GPU: the ONNX model run by our own interpreter, in FP16, as a CUDA graph.

This is the GPU path for machines with a CUDA build of PyTorch but no TensorRT. The ONNX file is
turned into a ``torch.nn.Module`` by our interpreter, :mod:`runtimes.onnx_torch` (no
converter package), for one static input shape, and run like this on every ``infer``:

    host batch (float32) -> pinned host buffer -> static GPU input (async copy)
    -> cast to fp16 -> the module -> outputs cast to float32 -> host

All of that after the host copy is captured once as a CUDA graph after warm-up, so a call costs
one graph launch instead of some 300 kernel launches from Python. If capture fails, the backend
logs why and runs eagerly.

The backend refuses a machine without CUDA (BackendUnavailable) unless it is asked for
``device="cpu"`` explicitly: then it runs the same interpreter in fp32 without graphs, which is
how the interpreter is tested on CPU-only machines.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType

import numpy as np
import numpy.typing as npt

try:
    import torch
except ImportError as exc:  # open_backend turns this into BackendUnavailable
    raise ImportError("PyTorch is not installed") from exc

from common.errors import BackendUnavailable, ConfigError, ModelError, one_line
from runtimes.base import Backend, Dim, input_size
from runtimes.onnx_torch.interpreter import (
    OnnxModule,
    build_module,
    declared_shape,
    read_model,
)

log = logging.getLogger(__name__)

PRECISIONS: dict[str, torch.dtype] = {"fp16": torch.float16, "fp32": torch.float32}
#: Eager runs before capture: cuDNN picks its algorithms and the allocator settles.
WARMUP_RUNS = 3


def cuda_unavailable_reason() -> str | None:
    """Why PyTorch cannot use a CUDA GPU here, or None when it can."""
    if torch.cuda.is_available():
        return None
    version = ".".join(torch.__version__.split("+")[0].split(".")[:2])
    if torch.version.cuda is None:
        return f"PyTorch has no CUDA device (torch {version}, built for CPU)"
    return (
        f"PyTorch has no CUDA device (torch {version}, built for CUDA {torch.version.cuda}, "
        "but no GPU is visible)"
    )


def _device(device: str, precision: str) -> torch.device:
    if precision not in PRECISIONS:
        raise ConfigError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    try:
        dev = torch.device(device)
    except RuntimeError as exc:
        raise ConfigError(f"device must be 'cuda', 'cuda:N' or 'cpu', got {device!r}") from exc
    if dev.type == "cpu":
        if precision != "fp32":
            raise ConfigError("device 'cpu' runs in fp32 only; pass precision='fp32'")
        return dev
    if dev.type != "cuda":
        raise ConfigError(f"device must be 'cuda', 'cuda:N' or 'cpu', got {device!r}")
    reason = cuda_unavailable_reason()
    if reason is not None:
        raise BackendUnavailable(reason)
    index = dev.index if dev.index is not None else torch.cuda.current_device()
    if index >= torch.cuda.device_count():
        raise BackendUnavailable(
            f"no CUDA device {index}: this machine has {torch.cuda.device_count()}"
        )
    return torch.device("cuda", index)


def _static_shape(
    declared: tuple[Dim, ...], metadata: Mapping[str, str], batch: int | None
) -> tuple[int, int, int, int]:
    """The one input shape the module is built for; dynamic dims resolved as the pipeline does.

    H and W: declared, else ``imgsz`` metadata, else 640. Batch: declared, else ``batch``
    (default 1); asking for another batch than a fixed one is a ConfigError.
    """
    height, width = input_size(declared, metadata)
    if batch is not None and batch < 1:
        raise ConfigError(f"batch must be a positive integer, got {batch}")
    if declared[0] is not None and batch not in (None, declared[0]):
        raise ConfigError(f"the model has a fixed batch of {declared[0]}; batch={batch} is not")
    return (declared[0] or batch or 1, 3, height, width)


class CudaBackend:
    """An :class:`OnnxModule` on one device with static input and output buffers, opened by
    :func:`load` (whose options, with their defaults, these are)."""

    name = "cuda"

    def __init__(
        self, model_path: Path, *, device: str, precision: str, cuda_graphs: bool, batch: int | None
    ) -> None:
        dev = _device(device, precision)
        model = read_model(model_path)
        weights = {t.name for t in model.graph.initializer}
        inputs = [i for i in model.graph.input if i.name not in weights]
        if len(inputs) != 1:
            raise ModelError(f"{model_path}: expected one image input, the model has {len(inputs)}")
        self.metadata: Mapping[str, str] = MappingProxyType(
            {p.key: p.value for p in model.metadata_props}
        )
        shape = _static_shape(declared_shape(inputs[0]), self.metadata, batch)
        module = build_module(model, [shape])
        del model  # the module holds its own copies of the weights
        self._dtype = PRECISIONS[precision]
        self._dev = dev
        self._module: OnnxModule | None = module.set_precision(self._dtype).to(dev).eval()
        self.device: str = str(dev)
        self.precision: str = precision
        #: The shape the module was built for: the Detector batches to it.
        self.input_shape: tuple[Dim, ...] = shape
        self.output_shapes: tuple[tuple[Dim, ...], ...] = module.output_shapes
        on_gpu = dev.type == "cuda"
        if on_gpu:
            # Process-wide settings. Fixed shapes: let cuDNN time its algorithms once. fp32 is
            # meant as IEEE fp32, so turn off the TF32 convolutions PyTorch allows by default.
            torch.backends.cudnn.benchmark = True
            if precision == "fp32":
                torch.backends.cudnn.allow_tf32 = False
        self._input = torch.zeros(shape, dtype=torch.float32, device=dev)
        self._host = torch.zeros(shape, dtype=torch.float32, pin_memory=on_gpu)
        self._host_view: npt.NDArray[np.float32] = self._host.numpy()
        self._graph: torch.cuda.CUDAGraph | None = None
        self._graph_outputs: list[torch.Tensor] = []
        self.graph_error: str | None = None  # why capture failed, when it did
        if cuda_graphs and on_gpu:
            self._capture()
        elif cuda_graphs:
            log.info("CUDA graphs need a CUDA device; running eagerly on %s", self.device)

    @property
    def cuda_graphs(self) -> bool:
        """Whether ``infer`` replays a captured CUDA graph."""
        return self._graph is not None

    def _forward(self) -> list[torch.Tensor]:
        """Module on the static input, with the fp32 -> model precision -> fp32 edge casts."""
        assert self._module is not None
        outputs = self._module(self._input.to(self._dtype))
        return [o.float() for o in outputs]

    def _capture(self) -> None:
        """Warm up on a side stream, then capture ``_forward`` (the recipe in torch.cuda.graph)."""
        graph = torch.cuda.CUDAGraph()
        try:
            side = torch.cuda.Stream(self._dev)  # type: ignore[no-untyped-call]
            side.wait_stream(torch.cuda.current_stream(self._dev))
            with torch.inference_mode(), torch.cuda.stream(side):
                for _ in range(WARMUP_RUNS):
                    self._forward()
            torch.cuda.current_stream(self._dev).wait_stream(side)
            with torch.inference_mode(), torch.cuda.graph(graph):
                outputs = self._forward()
        except RuntimeError as exc:
            self.graph_error = one_line(exc)
            log.warning("CUDA graph capture failed, running eagerly: %s", self.graph_error)
            return
        self._graph, self._graph_outputs = graph, outputs

    def infer(self, batch: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
        """Run one batch of exactly the input shape; outputs come back as float32 arrays."""
        if self._module is None:
            raise ModelError("inference on a closed cuda backend")
        if batch.shape != self._host_view.shape:
            raise ModelError(
                f"batch shape {list(batch.shape)} is not the model's input shape "
                f"{list(self._host_view.shape)}"
            )
        # Through the pinned buffer so that the host-to-device copy can be asynchronous; the
        # previous call's copy is finished, since that call waited for its outputs.
        np.copyto(self._host_view, batch, casting="same_kind")
        try:
            with torch.inference_mode():
                self._input.copy_(self._host, non_blocking=True)
                if self._graph is not None:
                    self._graph.replay()
                    outputs = self._graph_outputs
                else:
                    outputs = self._forward()
                # .cpu() waits for the GPU; each call returns fresh arrays, never the buffers.
                return [o.cpu().numpy() for o in outputs]
        except RuntimeError as exc:
            raise ModelError(f"inference failed: {one_line(exc)}") from exc

    def close(self) -> None:
        """Drop the module, the graph and the buffers; give cached GPU memory back."""
        self._module = None
        self._graph = None
        self._graph_outputs = []
        self._input = self._host = torch.empty(0)
        if self._dev.type == "cuda":
            torch.cuda.empty_cache()


def load(
    model_path: Path,
    *,
    device: str = "cuda:0",
    precision: str = "fp16",
    cuda_graphs: bool = True,
    batch: int | None = None,
) -> Backend:
    """Open ``model_path`` with PyTorch on ``device`` (``cuda:N``, or ``cpu`` for fp32 tests).

    ``precision``: ``fp16`` (default) or ``fp32``. ``cuda_graphs``: capture the forward pass
    after warm-up (ignored on the CPU). ``batch``: the batch to build for when the model's is
    dynamic (default 1). Raises BackendUnavailable without a CUDA device (unless
    ``device="cpu"``), ConfigError for bad options, ModelError for a model it cannot run.
    """
    return CudaBackend(
        model_path, device=device, precision=precision, cuda_graphs=cuda_graphs, batch=batch
    )
