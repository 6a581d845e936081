"""TensorRT 10 on an NVIDIA GPU: an engine built from the same ONNX file the CPU runs.

NOT VERIFIED ON A TENSORRT MACHINE: none was available. This follows the documented
TensorRT 10 Python API; the cuda-python parts (pinned buffers, stream, copies) ran on an H100,
and the GPU-free logic (engine cache, profiles, calibration batches) is unit-tested.

The engine is built once (minutes) and cached by :mod:`.engine_cache`; fp16 by default, int8
calibrated on letterboxed images. At load, device buffers, pinned host buffers and one CUDA
stream are allocated and every tensor's address is set once; a call is then copy in,
``execute_async_v3``, copy out, one synchronise. Pre-processing stays on the CPU: the letterbox
writes into a reused buffer in about 1.5 ms, and a GPU letterbox would need a kernel (and a
dependency) of its own to save less than that. Design and trade-offs: docs/tensorrt.md.
"""

from __future__ import annotations

import ctypes
import logging
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from common.errors import BackendUnavailable, ConfigError, ModelError
from common.files import sha256_file

try:
    import tensorrt as trt
except ImportError as exc:
    raise BackendUnavailable(
        "TensorRT is not installed (pip install tensorrt-cu12 on a machine with an NVIDIA driver)"
    ) from exc

from common.clock import mono_s
from modelprep import calibration as calib_data
from runtimes import engine_cache
from runtimes.base import Backend, Dim
from runtimes.cudart import cuda_device_count, import_cudart
from runtimes.engine_cache import BuildOptions
from runtimes.profiles import ProfileShapes, calibration_shape, model_profile, served_profile

try:
    cudart = import_cudart()
except ImportError as exc:
    raise BackendUnavailable(
        "TensorRT backend needs cuda-python for device memory (pip install cuda-python)"
    ) from exc

log = logging.getLogger(__name__)
Progress = Callable[[str], None]
HEARTBEAT_S = 5.0  # a build prints at least this often, so minutes of silence never happen
_LOGGER = trt.Logger(trt.Logger.WARNING)


def _cuda(result: Any, what: str, error: type[Exception] = ModelError) -> Any:
    """Unpack a cuda-python ``(err, *values)`` tuple, raising ``error`` on failure."""
    err, *values = result if isinstance(result, tuple) else (result,)
    if err != cudart.cudaError_t.cudaSuccess:
        raise error(f"CUDA {what} failed: {cudart.cudaGetErrorName(err)[1].decode()}")
    return values[0] if len(values) == 1 else tuple(values)


def gpu_identity(device: int) -> tuple[str, str]:
    """``(GPU name, "major.minor" compute capability)`` of CUDA device ``device``."""
    count, error = cuda_device_count(cudart)
    if device >= count:
        raise BackendUnavailable(f"TensorRT: no CUDA device {device} ({error or f'{count} found'})")
    prop = _cuda(cudart.cudaGetDeviceProperties(device), "device query", BackendUnavailable)
    name = prop.name.split(b"\0", 1)[0].decode() if isinstance(prop.name, bytes) else prop.name
    return str(name), f"{prop.major}.{prop.minor}"


class _HostDevicePair:
    """One tensor's device buffer and pinned host buffer of ``nbytes`` each; close frees them."""

    def __init__(self, nbytes: int, dtype: np.dtype[Any]) -> None:
        self.device = int(_cuda(cudart.cudaMalloc(nbytes), "cudaMalloc"))
        self.host_ptr = int(_cuda(cudart.cudaMallocHost(nbytes), "cudaMallocHost"))
        # Page-locked memory seen as a numpy array: async copies need pinned pages.
        self._raw = (ctypes.c_byte * nbytes).from_address(self.host_ptr)
        self.host = np.frombuffer(memoryview(self._raw), dtype=dtype)

    def to_device(self, nbytes: int, stream: Any) -> None:
        kind = cudart.cudaMemcpyKind.cudaMemcpyHostToDevice
        _cuda(cudart.cudaMemcpyAsync(self.device, self.host_ptr, nbytes, kind, stream), "copy in")

    def to_host(self, nbytes: int, stream: Any) -> None:
        kind = cudart.cudaMemcpyKind.cudaMemcpyDeviceToHost
        _cuda(cudart.cudaMemcpyAsync(self.host_ptr, self.device, nbytes, kind, stream), "copy out")

    def close(self) -> None:
        if self.device:
            cudart.cudaFree(self.device)
            cudart.cudaFreeHost(self.host_ptr)
            self.device = self.host_ptr = 0


class _ProgressMonitor(trt.IProgressMonitor):  # type: ignore[misc]
    """Keeps the builder's latest phase and step; the build's heartbeat thread prints it.

    TensorRT calls this from its own threads; one str assignment is atomic in CPython.
    """

    def __init__(self) -> None:
        trt.IProgressMonitor.__init__(self)
        self.current = ""

    def phase_start(self, phase_name: str, parent_phase: str | None, num_steps: int) -> None:
        self.current = f"{phase_name} 0/{num_steps}"

    def step_complete(self, phase_name: str, step: int) -> bool:
        steps = self.current.rpartition("/")[2] if self.current.startswith(phase_name) else "?"
        self.current = f"{phase_name} {step + 1}/{steps}"
        return True  # False would cancel the build

    def phase_finish(self, phase_name: str) -> None:
        self.current = f"{phase_name} done"


class _EntropyCalibrator(trt.IInt8EntropyCalibrator2):  # type: ignore[misc]
    """Feeds letterboxed calibration batches to TensorRT and keeps its cache file."""

    def __init__(
        self, paths: list[Path], shape: tuple[int, int, int, int], cache: Path, progress: Progress
    ) -> None:
        trt.IInt8EntropyCalibrator2.__init__(self)
        self._paths = paths
        self.shape = shape
        self._batch, _, height, width = shape
        self._batches = calib_data.calibration_batches(self._paths, self._batch, height, width)
        self._buffer = _HostDevicePair(int(np.prod(shape)) * 4, np.dtype(np.float32))
        self._cache, self._progress, self._done = cache, progress, 0

    def get_batch_size(self) -> int:
        return self._batch

    def get_batch(self, names: list[str]) -> list[int] | None:
        batch = next(self._batches, None)
        if batch is None:
            return None  # no more data: calibration ends
        self._buffer.host[: batch.size] = batch.ravel()
        self._buffer.to_device(batch.nbytes, 0)  # legacy default stream: the builder syncs it
        _cuda(cudart.cudaStreamSynchronize(0), "calibration copy")
        self._done += 1
        self._progress(f"calibration batch {self._done} ({len(self._paths)} images)")
        return [self._buffer.device]

    def read_calibration_cache(self) -> bytes | None:
        if self._cache.is_file():
            self._progress(f"reusing calibration cache {self._cache}")
            return self._cache.read_bytes()
        return None

    def write_calibration_cache(self, cache: Any) -> None:
        self._cache.parent.mkdir(parents=True, exist_ok=True)
        self._cache.write_bytes(bytes(cache))

    def close(self) -> None:
        self._buffer.close()


def _build(
    model_path: Path,
    shapes: ProfileShapes,
    opts: BuildOptions,
    calibrator: _EntropyCalibrator | None,
    progress: Progress,
) -> bytes:
    """Parse the ONNX file and build a serialised engine; minutes, with progress lines."""
    builder = trt.Builder(_LOGGER)
    network = builder.create_network(0)  # TensorRT 10: explicit batch is the only mode
    parser = trt.OnnxParser(network, _LOGGER)
    if not parser.parse_from_file(str(model_path)):
        errors = "; ".join(str(parser.get_error(i)) for i in range(parser.num_errors))
        raise ModelError(f"{model_path}: TensorRT cannot parse it ({errors})")
    name = network.get_input(0).name
    config = builder.create_builder_config()
    config.set_memory_pool_limit(trt.MemoryPoolType.WORKSPACE, int(opts.workspace_gb * (1 << 30)))
    profile = builder.create_optimization_profile()
    profile.set_shape(name, shapes.min, shapes.opt, shapes.max)
    config.add_optimization_profile(profile)
    if opts.precision in ("fp16", "int8"):
        config.set_flag(trt.BuilderFlag.FP16)  # int8 layers TensorRT cannot quantise run fp16
    if opts.precision == "int8" and calibrator is not None:
        config.set_flag(trt.BuilderFlag.INT8)
        config.int8_calibrator = calibrator
        calib_profile = builder.create_optimization_profile()  # calibration runs at one shape
        calib_profile.set_shape(name, calibrator.shape, calibrator.shape, calibrator.shape)
        config.set_calibration_profile(calib_profile)
    monitor = _ProgressMonitor()
    config.progress_monitor = monitor
    stop, start = threading.Event(), mono_s()

    def heartbeat() -> None:
        while not stop.wait(HEARTBEAT_S):
            elapsed = f"building engine: {mono_s() - start:.0f} s"
            progress(f"{elapsed}: {monitor.current}" if monitor.current else elapsed)

    progress(
        f"building TensorRT {trt.__version__} {opts.precision} engine for {model_path.name}, "
        f"batch {shapes.batch} (this takes minutes)"
    )
    beat = threading.Thread(target=heartbeat, name="trt-build-progress", daemon=True)
    beat.start()
    try:
        serialized = builder.build_serialized_network(network, config)
    finally:
        stop.set()
        beat.join()
    if serialized is None:
        raise ModelError(f"{model_path}: TensorRT could not build an engine (see its log above)")
    progress(f"engine built in {mono_s() - start:.0f} s")
    return bytes(serialized)


def ensure_engine(
    model_path: Path, opts: BuildOptions, say: Progress
) -> tuple[Path, ProfileShapes, dict[str, str]]:
    """Reuse or build the engine for ``opts``: ``(engine path, shapes, ONNX metadata)``."""
    shapes, metadata = model_profile(model_path, opts.batch_profile)
    _cuda(cudart.cudaSetDevice(opts.device), "cudaSetDevice", BackendUnavailable)
    gpu, capability = gpu_identity(opts.device)
    int8 = opts.calib_dir if opts.precision == "int8" else None
    calib = calib_data.calibration_images(int8) if int8 is not None else []
    key = engine_cache.EngineKey(
        model_name=model_path.stem,
        model_sha256=sha256_file(model_path),
        gpu_name=gpu,
        compute_capability=capability,
        tensorrt_version=trt.__version__,
        precision=opts.precision,
        batch_profile=shapes.batch.as_tuple(),
        calibration=calib_data.calibration_digest(calib) if calib else "",
    )
    folder = opts.folder()
    uncalibrated = opts.precision == "int8" and not calib
    path, reason = engine_cache.check(folder, key, any_calibration=uncalibrated)
    say(reason)
    if path is not None:
        return path, shapes, metadata
    if uncalibrated:
        raise ConfigError(f"int8 needs calibration images to build (--calib DIR); {reason}")
    calibrator = None
    if calib:
        cache = engine_cache.calibration_cache_path(folder, key)
        calibrator = _EntropyCalibrator(calib, calibration_shape(shapes), cache, say)
    try:
        engine = _build(model_path, shapes, opts, calibrator, say)
    finally:
        if calibrator is not None:
            calibrator.close()
    path = engine_cache.store(folder, key, engine)
    say(f"engine cached at {path}")
    return path, shapes, metadata


class TensorRTBackend:
    """A deserialised engine with its buffers, context and stream, ready to run batches.

    ``infer`` returns views of the pinned output buffers (fp32 engines) that the next call
    overwrites: the detector decodes them at once, and copying 8 MB per frame would cost
    about as much as the inference itself.
    """

    name = "tensorrt"

    def __init__(
        self, path: Path, shapes: ProfileShapes, metadata: Mapping[str, str], opts: BuildOptions
    ) -> None:
        self.device, self.precision = f"cuda:{opts.device}", opts.precision
        self.metadata: Mapping[str, str] = MappingProxyType(dict(metadata))
        self._shapes = shapes
        self._pairs: dict[str, _HostDevicePair] = {}
        self._stream: Any = None
        engine = trt.Runtime(_LOGGER).deserialize_cuda_engine(path.read_bytes())
        if engine is None:
            # Its key and sha256 matched, so this is not staleness: say so rather than loop.
            raise ModelError(f"{path}: TensorRT cannot deserialise it; delete it to rebuild")
        self._engine, self._context = engine, engine.create_execution_context()
        names = [engine.get_tensor_name(i) for i in range(engine.num_io_tensors)]
        inputs = [n for n in names if engine.get_tensor_mode(n) == trt.TensorIOMode.INPUT]
        if len(inputs) != 1:
            raise ModelError(f"{path}: expected one image input, the engine has {len(inputs)}")
        self._input, self._outputs = inputs[0], [n for n in names if n != inputs[0]]
        fixed = None if shapes.batch.dynamic else shapes.batch.max
        self.input_shape: tuple[Dim, ...] = (fixed, *shapes.max[1:])
        self.output_shapes: tuple[tuple[Dim, ...], ...] = tuple(
            tuple(d if d >= 0 else None for d in engine.get_tensor_shape(n)) for n in self._outputs
        )
        try:
            self._allocate()
        except BaseException:
            self.close()
            raise
        self._rows = shapes.max[0]  # the batch the context's input shape is set to now

    def _allocate(self) -> None:
        """Buffers for the largest batch of the profile, each tensor's address set once."""
        self._stream = _cuda(cudart.cudaStreamCreate(), "cudaStreamCreate")
        if not self._context.set_input_shape(self._input, self._shapes.max):
            raise ModelError(f"engine rejects its own max input shape {self._shapes.max}")
        for name in (self._input, *self._outputs):
            shape = tuple(self._context.get_tensor_shape(name))
            if any(d < 0 for d in shape):
                raise ModelError(f"output {name} has a data-dependent shape {shape}; unsupported")
            dtype = np.dtype(trt.nptype(self._engine.get_tensor_dtype(name)))
            pair = _HostDevicePair(int(np.prod(shape)) * dtype.itemsize, dtype)
            self._pairs[name] = pair
            self._context.set_tensor_address(name, pair.device)

    def infer(self, batch: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
        """Run one ``[B, 3, H, W]`` batch; larger batches than the profile's max are split."""
        if not self._pairs:
            raise ModelError("inference on a closed tensorrt backend")
        rows, most = batch.shape[0], self._shapes.batch.max
        if rows > most:
            # Copies: each run overwrites the pinned buffers the previous one's views point at.
            parts = [
                [o.copy() for o in self._run(batch[i : i + most])] for i in range(0, rows, most)
            ]
            return [np.concatenate([p[k] for p in parts]) for k in range(len(parts[0]))]
        return self._run(batch)

    def _run(self, batch: npt.NDArray[np.float32]) -> list[npt.NDArray[np.float32]]:
        rows = batch.shape[0]
        if not self._shapes.batch.dynamic and rows != self._shapes.batch.max:
            raise ModelError(f"engine takes batches of {self._shapes.batch.max}, got {rows}")
        if rows != self._rows:
            if not self._context.set_input_shape(self._input, (rows, *self._shapes.max[1:])):
                raise ModelError(f"engine rejects a batch of {rows} (profile {self._shapes.batch})")
            self._rows = rows
        src = self._pairs[self._input]
        staged = src.host[: batch.size]
        np.copyto(staged, batch.ravel(), casting="unsafe")  # into pinned memory, fp16 if needed
        src.to_device(staged.nbytes, self._stream)
        # int() of a cuda-python handle is the cudaStream_t value; getPtr() would be the
        # address of the Python object's copy of it (checked on an H100).
        if not self._context.execute_async_v3(int(self._stream)):
            raise ModelError("TensorRT inference failed (see its log above)")
        views = []
        for name in self._outputs:
            pair, shape = self._pairs[name], tuple(self._context.get_tensor_shape(name))
            view = pair.host[: int(np.prod(shape))]
            pair.to_host(view.nbytes, self._stream)
            views.append(view.reshape(shape))
        _cuda(cudart.cudaStreamSynchronize(self._stream), "cudaStreamSynchronize")
        return [v if v.dtype == np.float32 else v.astype(np.float32) for v in views]

    def close(self) -> None:
        """Free buffers and the stream; drop the context before the engine (TensorRT's order)."""
        if self._stream is not None:
            cudart.cudaStreamSynchronize(self._stream)
        for pair in self._pairs.values():
            pair.close()
        self._pairs = {}
        if self._stream is not None:
            cudart.cudaStreamDestroy(self._stream)
            self._stream = None
        self._context = None
        self._engine = None


def load(
    model_path: Path,
    *,
    precision: str = "fp16",
    batch_profile: tuple[int, int, int] = (1, 1, 1),
    calib_dir: str | Path | None = None,
    cache_dir: str | Path | None = None,
    workspace_gb: float = 4.0,
    device: int = 0,
    progress: Progress | None = None,
    max_batch: int = 1,
) -> Backend:
    """Open ``model_path`` (ONNX) on TensorRT, building and caching its engine if needed.

    Options are those of :class:`~.BuildOptions`; ``progress`` receives the
    cache decision and build progress lines (default: this module's logger at INFO).
    ``max_batch`` is the largest batch it will be given: with ``batch_profile`` left at
    (1, 1, 1), a dynamic-batch model's engine is built for 1..``max_batch`` (opt
    ``max_batch``, the batch a busy detector runs); a profile set explicitly wins, and a
    larger batch than its max is run in parts. A fixed batch is the model's own.
    """
    opts = BuildOptions(
        precision=precision,
        batch_profile=served_profile(batch_profile, max_batch),
        calib_dir=Path(calib_dir) if calib_dir is not None else None,
        cache_dir=Path(cache_dir) if cache_dir is not None else None,
        workspace_gb=workspace_gb,
        device=device,
    )
    path, shapes, metadata = ensure_engine(model_path, opts, progress or log.info)
    return TensorRTBackend(path, shapes, metadata, opts)


def export_engine(model_path: Path, progress: Progress, **options: Any) -> Path:
    """Build (or reuse) and cache the engine for ``options`` without opening it: the export."""
    opts = BuildOptions(**options)
    return ensure_engine(model_path, opts, progress)[0]
