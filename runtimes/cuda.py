"""PyTorch on an NVIDIA GPU: the ONNX model run by our own interpreter, in FP16, as a CUDA graph.

This is the GPU path for machines with a CUDA build of PyTorch but no TensorRT. The ONNX file is
turned into a ``torch.nn.Module`` by our interpreter, :mod:`runtimes.onnx_torch` (no
converter package), for static input shapes: a fixed-batch model for its own, a dynamic-batch
one for each batch size of :func:`batch_sizes` (1, 2, 4 ... ``max_batch``: one module per size,
their weights shared on the device). Each ``infer`` runs like this:

    host batch (float32) -> pinned host buffer -> static GPU input (async copy)
    -> cast to fp16 -> the module -> outputs cast to float32 -> host

All of that after the host copy is captured once per size as a CUDA graph after warm-up, so a
call costs one graph launch instead of some 300 kernel launches from Python. If capture fails,
the backend logs why and runs eagerly.

The backend refuses a machine without CUDA (BackendUnavailable) unless it is asked for
``device="cpu"`` explicitly: then it runs the same interpreter in fp32 without graphs, which is
how the interpreter is tested on CPU-only machines.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
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


def batch_sizes(max_batch: int) -> tuple[int, ...]:
    """The batch sizes a dynamic-batch model is built for: 1, 2, 4, ... below ``max_batch``,
    then ``max_batch``. A batch in between runs padded up to the next one: a module and a
    CUDA graph per size, shared weights, and at most twice the rows of the batch."""
    if max_batch < 1:
        raise ConfigError(f"max_batch must be a positive integer, got {max_batch}")
    sizes = [1 << k for k in range(max_batch.bit_length()) if 1 << k < max_batch]
    return (*sizes, max_batch)


def _input_shapes(
    declared: tuple[Dim, ...], metadata: Mapping[str, str], max_batch: int
) -> tuple[tuple[int, int, int, int], ...]:
    """The static input shapes the modules are built for, smallest first.

    H and W: declared, else ``imgsz`` metadata, else 640. Batch: a fixed one is the model's own
    whatever ``max_batch`` says (the Detector cuts batches to it); a dynamic one gets
    :func:`batch_sizes`.
    """
    height, width = input_size(declared, metadata)
    sizes = batch_sizes(max_batch)  # checks max_batch, whatever the model
    if declared[0] is not None:
        sizes = (declared[0],)
    return tuple((b, 3, height, width) for b in sizes)


@dataclass(slots=True)
class _Size:
    """One batch size: its module and, once captured, its CUDA graph and static outputs."""

    batch: int
    module: OnnxModule
    graph: torch.cuda.CUDAGraph | None = None
    outputs: list[torch.Tensor] = field(default_factory=list)


def _share_weights(module: OnnxModule, first: OnnxModule) -> set[str]:
    """The buffers of ``module`` equal to ``first``'s of the same name: the weights, which
    every batch size has alike (folded shape constants may differ)."""
    theirs = dict(first.named_buffers())
    return {
        name
        for name, value in module.named_buffers()
        if name in theirs
        and theirs[name].shape == value.shape
        and theirs[name].dtype == value.dtype
        and torch.equal(theirs[name], value)
    }


class CudaBackend:
    """:class:`OnnxModule` s on one device (one per batch size) with static buffers."""

    name = "cuda"

    def __init__(
        self,
        model_path: Path,
        *,
        device: str = "cuda:0",
        precision: str = "fp16",
        cuda_graphs: bool = True,
        max_batch: int = 1,
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
        shapes = _input_shapes(declared_shape(inputs[0]), self.metadata, max_batch)
        modules = [build_module(model, [shape]) for shape in shapes]
        del model  # the modules hold their own copies of the weights
        shared = [_share_weights(m, modules[0]) for m in modules]
        self._dtype = PRECISIONS[precision]
        self._dev = dev
        self._sizes: list[_Size] = []
        for module, same in zip(modules, shared, strict=True):
            if self._sizes:  # the first size's weights, already on the device: one copy
                first = dict(self._sizes[0].module.named_buffers())
                for name in same:
                    module._buffers[name] = first[name]
            module = module.set_precision(self._dtype).to(dev).eval()
            self._sizes.append(_Size(module.input_shapes[0][0], module))
        largest = shapes[-1]
        self.device: str = str(dev)
        self.precision: str = precision
        #: One size built: its shape, as a fixed-batch export declares it (the Detector batches
        #: to it); several: a dynamic batch of up to ``max_batch``.
        dynamic = len(shapes) > 1
        self.input_shape: tuple[Dim, ...] = (None, *largest[1:]) if dynamic else largest
        self.output_shapes: tuple[tuple[Dim, ...], ...] = tuple(
            (None, *o[1:]) if dynamic else o for o in self._sizes[-1].module.output_shapes
        )
        on_gpu = dev.type == "cuda"
        if on_gpu:
            # Process-wide settings. Fixed shapes: let cuDNN time its algorithms once. fp32 is
            # meant as IEEE fp32, so turn off the TF32 convolutions PyTorch allows by default.
            torch.backends.cudnn.benchmark = True
            if precision == "fp32":
                torch.backends.cudnn.allow_tf32 = False
        # One input buffer for the largest batch; a smaller batch uses its first rows.
        self._input = torch.zeros(largest, dtype=torch.float32, device=dev)
        self._host = torch.zeros(largest, dtype=torch.float32, pin_memory=on_gpu)
        self._host_view: npt.NDArray[np.float32] = self._host.numpy()
        self.graph_error: str | None = None  # why capture failed, when it did
        if cuda_graphs and on_gpu:
            self._capture()
        elif cuda_graphs:
            log.info("CUDA graphs need a CUDA device; running eagerly on %s", self.device)

    @property
    def cuda_graphs(self) -> bool:
        """Whether ``infer`` replays captured CUDA graphs."""
        return bool(self._sizes) and all(s.graph is not None for s in self._sizes)

    @property
    def batch_sizes(self) -> tuple[int, ...]:
        """The batch sizes a module is built for, smallest first."""
        return tuple(s.batch for s in self._sizes)

    def _forward(self, size: _Size) -> list[torch.Tensor]:
        """Module on the static input, with the fp32 -> model precision -> fp32 edge casts."""
        outputs = size.module(self._input[: size.batch].to(self._dtype))
        return [o.float() for o in outputs]

    def _capture(self) -> None:
        """Warm up on a side stream, then capture ``_forward`` per batch size (the recipe in
        torch.cuda.graph), largest first. The graphs share one memory pool: safe here, since
        replays never overlap (each ``infer`` waits for its outputs and copies them out) and a
        graph's static outputs stay allocated, so no other graph's capture reuses them."""
        pool = None
        for size in reversed(self._sizes):
            graph = torch.cuda.CUDAGraph()
            try:
                side = torch.cuda.Stream(self._dev)  # type: ignore[no-untyped-call]
                side.wait_stream(torch.cuda.current_stream(self._dev))
                with torch.inference_mode(), torch.cuda.stream(side):
                    for _ in range(WARMUP_RUNS):
                        self._forward(size)
                torch.cuda.current_stream(self._dev).wait_stream(side)
                with torch.inference_mode(), torch.cuda.graph(graph, pool=pool):
                    outputs = self._forward(size)
            except RuntimeError as exc:
                self.graph_error = one_line(exc)
                log.warning("CUDA graph capture failed, running eagerly: %s", self.graph_error)
                for done in self._sizes:
                    done.graph, done.outputs = None, []
                return
            size.graph, size.outputs = graph, outputs
            pool = graph.pool()

    def infer(self, batch: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
        """Run one batch; outputs come back as float32 arrays. A batch larger than the largest
        size is run in parts; one between sizes is padded up to the next (padding rows are
        whatever the buffer held: rows never mix, and their outputs are cut off)."""
        if not self._sizes:
            raise ModelError("inference on a closed cuda backend")
        largest = self._host_view.shape
        if batch.ndim != 4 or batch.shape[1:] != largest[1:] or batch.shape[0] < 1:
            raise ModelError(
                f"batch shape {list(batch.shape)} is not the model's input shape "
                f"{list(self.input_shape)}"
            )
        rows, most = batch.shape[0], largest[0]
        if rows > most:
            parts = [self._run(batch[i : i + most]) for i in range(0, rows, most)]
            return [np.concatenate([p[k] for p in parts]) for k in range(len(parts[0]))]
        return self._run(batch)

    def _run(self, batch: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
        rows = batch.shape[0]
        size = next(s for s in self._sizes if s.batch >= rows)
        # Through the pinned buffer so that the host-to-device copy can be asynchronous; the
        # previous call's copy is finished, since that call waited for its outputs.
        np.copyto(self._host_view[:rows], batch, casting="same_kind")
        try:
            with torch.inference_mode():
                self._input[: size.batch].copy_(self._host[: size.batch], non_blocking=True)
                if size.graph is not None:
                    size.graph.replay()
                    outputs = size.outputs
                else:
                    outputs = self._forward(size)
                # .cpu() waits for the GPU; each call returns fresh arrays, never the buffers.
                return [o[:rows].cpu().numpy() for o in outputs]
        except RuntimeError as exc:
            raise ModelError(f"inference failed: {one_line(exc)}") from exc

    def close(self) -> None:
        """Drop the modules, the graphs and the buffers; give cached GPU memory back."""
        self._sizes = []
        self._input = self._host = torch.empty(0)
        if self._dev.type == "cuda":
            torch.cuda.empty_cache()


def load(
    model_path: Path,
    *,
    device: str = "cuda:0",
    precision: str = "fp16",
    cuda_graphs: bool = True,
    max_batch: int = 1,
) -> Backend:
    """Open ``model_path`` with PyTorch on ``device`` (``cuda:N``, or ``cpu`` for fp32 tests).

    ``precision``: ``fp16`` (default) or ``fp32``. ``cuda_graphs``: capture the forward pass
    after warm-up (ignored on the CPU). ``max_batch``: the largest batch it will be given; a
    dynamic batch is built for :func:`batch_sizes` of it, a fixed one as it is. Raises
    BackendUnavailable without a CUDA device (unless ``device="cpu"``), ConfigError for bad
    options, ModelError for a model it cannot run.
    """
    return CudaBackend(
        model_path, device=device, precision=precision, cuda_graphs=cuda_graphs, max_batch=max_batch
    )
