"""Choosing a backend: ``auto`` takes the fastest one this machine can run.

Order: ``tensorrt`` (an engine built for this GPU), then ``cuda`` (PyTorch on the GPU), then
``openvino`` (only on a CPU with VNNI or AMX, where the optional extra is installed: see
:func:`openvino_cpu_reason`), then ``onnx`` (ONNX Runtime on the CPU, always there). Each
candidate is first *probed*: can its runtime be imported, and does it see a device? A probe
never loads a model, so ``auto`` costs a few imports, not a model load per candidate. A
candidate that probes fine but still fails to load with BackendUnavailable (a driver too old,
say) is skipped too, and the reason is kept. The choice is returned with one line that says
why (the reasons of the candidates preferred to it), e.g. ``auto: TensorRT not installed
(...); CUDA backend: PyTorch has no CUDA device; OpenVINO: this CPU has neither VNNI nor AMX;
falling back to onnx (CPU)``.
"""

from __future__ import annotations

import importlib
import importlib.util
import logging
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from common.errors import BackendUnavailable, ConfigError
from runtimes.base import AUTO, Backend
from runtimes.cudart import cuda_device_count, import_cudart
from runtimes.table import BACKENDS, load_function, supported_options

log = logging.getLogger(__name__)

#: A probe returns None when its backend can run here, else the reason it cannot.
Probe = Callable[[], str | None]

AUTO_ORDER = ("tensorrt", "cuda", "openvino", "onnx")
_WHERE = {"tensorrt": "GPU", "cuda": "GPU", "openvino": "CPU", "onnx": "CPU"}
#: CPU flags (Linux names) of the INT8 dot-product units OpenVINO's CPU kernels use.
INT8_UNITS = ("avx512_vnni", "avx_vnni", "amx_int8")
CPUINFO = Path("/proc/cpuinfo")
_TRT_INSTALL = "pip install tensorrt-cu12 on a machine with an NVIDIA driver"


def _find(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package is missing or broken
        return False


def probe_tensorrt() -> str | None:
    """None when TensorRT, cuda-python and a CUDA device are all present."""
    if not _find("tensorrt"):
        return f"TensorRT not installed ({_TRT_INSTALL})"
    try:
        importlib.import_module("tensorrt")
    except (ImportError, OSError) as exc:  # OSError: libnvinfer present but unloadable
        return f"TensorRT does not import ({exc})"
    try:
        cudart = import_cudart()
    except ImportError:
        return "TensorRT: cuda-python not installed (pip install cuda-python)"
    count, error = cuda_device_count(cudart)
    if count < 1:
        return f"TensorRT: no CUDA device ({error or 'none found'})"
    return None


def probe_cuda() -> str | None:
    """None when the PyTorch CUDA backend module exists and PyTorch sees a CUDA device."""
    if not _find(BACKENDS["cuda"]):
        return "CUDA backend: its module is not part of this install"
    if not _find("torch"):
        return "CUDA backend: PyTorch not installed"
    try:
        torch = importlib.import_module("torch")
    except (ImportError, OSError) as exc:
        return f"CUDA backend: PyTorch does not import ({exc})"
    if not torch.cuda.is_available():
        return "CUDA backend: PyTorch has no CUDA device"
    return None


def openvino_cpu_reason(cpuinfo: str) -> str | None:
    """None when a CPU described by ``cpuinfo`` (``/proc/cpuinfo`` text) suits OpenVINO.

    The rule goes by the CPU's instruction flags, whatever its vendor: VNNI or AMX
    (:data:`INT8_UNITS`), the hardware dot products that OpenVINO's INT8 kernels use. Measured:
    on an AMD EPYC with AVX2 and no VNNI, OpenVINO FP32 ran at 1.03x ONNX Runtime's time, no
    gain for a 180 MB runtime; on an AMD EPYC with AVX-512 VNNI, OpenVINO INT8 at 480 ran at
    0.30 of ONNX Runtime FP32 640's time (docs/benchmarks.md). The vendor decides nothing.
    """
    flags: set[str] = set()
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        if key.strip() == "flags":
            flags = set(value.split())
            break
    if not flags:
        return "OpenVINO: the CPU's instruction flags are unknown"
    if not flags.intersection(INT8_UNITS):
        return "OpenVINO: this CPU has neither VNNI nor AMX"
    return None


def probe_openvino(cpuinfo_path: Path = CPUINFO) -> str | None:
    """None on a CPU that suits OpenVINO (:func:`openvino_cpu_reason`) with OpenVINO installed.

    Reads the CPU first, so a machine where the rule says no never imports anything.
    """
    try:
        cpuinfo = cpuinfo_path.read_text()
    except OSError:  # not Linux
        return f"OpenVINO: cannot read {cpuinfo_path} to check the CPU"
    reason = openvino_cpu_reason(cpuinfo)
    if reason is not None:
        return reason
    if not _find("openvino"):
        return "OpenVINO not installed (pip install '.[openvino]')"
    return None


def probe_onnx() -> str | None:
    """None when ONNX Runtime is importable (it is a dependency, so this is a formality)."""
    return None if _find("onnxruntime") else "ONNX Runtime not installed"


DEFAULT_PROBES: Mapping[str, Probe] = {
    "tensorrt": probe_tensorrt,
    "cuda": probe_cuda,
    "openvino": probe_openvino,
    "onnx": probe_onnx,
}


def auto_candidates(
    probes: Mapping[str, Probe] | None = None,
) -> tuple[list[str], dict[str, str]]:
    """``(usable backends in preference order, {backend: why it is not usable})``."""
    table = DEFAULT_PROBES if probes is None else probes
    usable: list[str] = []
    reasons: dict[str, str] = {}
    for name in AUTO_ORDER:
        probe = table.get(name)
        why = probe() if probe is not None else f"{name}: no probe"
        if why is None:
            usable.append(name)
        else:
            reasons[name] = why
    return usable, reasons


def _explain(reasons: Mapping[str, str], name: str) -> str:
    """Why ``name`` was chosen: the reasons of the candidates preferred to it, none after it."""
    rank = AUTO_ORDER.index(name)
    skipped = [why for n, why in reasons.items() if AUTO_ORDER.index(n) < rank]
    verb = "falling back to" if skipped else "using"
    return "auto: " + "".join(f"{r}; " for r in skipped) + f"{verb} {name} ({_WHERE[name]})"


def resolve_backend(requested: str, probes: Mapping[str, Probe] | None = None) -> tuple[str, str]:
    """The backend to load for ``requested`` and why.

    A named backend is returned as it is (loading it reports what is missing); ``auto`` is
    resolved by probing. ConfigError for a name that is neither; BackendUnavailable if no
    candidate of ``auto`` can run.
    """
    if requested != AUTO:
        if requested not in BACKENDS:
            raise ConfigError(
                f"unknown backend {requested!r}; valid backends: {', '.join([*BACKENDS, AUTO])}"
            )
        return requested, f"{requested}: requested"
    usable, reasons = auto_candidates(probes)
    if not usable:
        raise BackendUnavailable("auto: no backend can run here: " + "; ".join(reasons.values()))
    return usable[0], _explain(reasons, usable[0])


def open_auto(
    model_path: Path,
    options: Mapping[str, Any],
    probes: Mapping[str, Probe] | None = None,
) -> Backend:
    """Load ``model_path`` on the best backend that works here, logging the choice.

    ``options`` a candidate does not take are dropped for it (``precision`` means nothing to
    ONNX Runtime), and said so in the log. A candidate that refuses an option it takes (the
    GPU's ``fp16`` on openvino) is skipped like one that cannot load, unless it is the last
    one left. A fallback from the first choice is logged as a warning: someone expecting a
    GPU should notice they got the CPU.
    """
    usable, reasons = auto_candidates(probes)
    for name in usable:
        load = load_function(name)
        taken = supported_options(load)
        kept = {k: v for k, v in options.items() if taken is None or k in taken}
        dropped = sorted(set(options) - set(kept))
        try:
            backend = load(model_path, **kept)
        except BackendUnavailable as exc:
            reasons[name] = f"{name}: {exc}"
            continue
        except ConfigError as exc:
            if name == usable[-1]:
                raise
            reasons[name] = f"{name}: {exc}"
            continue
        message = _explain(reasons, name)
        if dropped:
            message += f" (ignoring option(s) it does not take: {', '.join(dropped)})"
        log.log(logging.WARNING if name != AUTO_ORDER[0] else logging.INFO, "%s", message)
        return backend
    raise BackendUnavailable("auto: no backend can run here: " + "; ".join(reasons.values()))


def backend_options(
    precision: str = "", batch_profile: tuple[int, int, int] = (1, 1, 1), max_batch: int = 1
) -> dict[str, Any]:
    """Backend options: only those set away from their defaults.

    ``precision`` ("" = the backend's own default), ``batch_profile`` ((1, 1, 1) = single
    frames) and ``max_batch`` (the largest batch the caller will send: the detector service's
    ``min(detector.max_batch, cameras)``; 1 = single frames) are passed on only when set, so
    the default config loads on every backend.
    """
    options: dict[str, Any] = {}
    if precision:
        options["precision"] = precision
    if batch_profile != (1, 1, 1):
        options["batch_profile"] = batch_profile
    if max_batch != 1:
        options["max_batch"] = max_batch
    return options
