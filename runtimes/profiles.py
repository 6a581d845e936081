"""TensorRT optimisation-profile shapes, worked out without TensorRT.

An engine built from an ONNX model with a dynamic batch dimension needs one optimisation
profile: the smallest, the typical ("opt", the shape TensorRT tunes its kernels for) and the
largest input shape it will ever be given. A model exported with a fixed batch gets a fixed
profile whatever was asked for, because TensorRT rejects a profile that contradicts a static
dimension. Kept pure so that the rules are unit-tested on machines without a GPU.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from common.errors import ConfigError, ModelError
from runtimes.base import Dim

Shape = tuple[int, int, int, int]


@dataclass(frozen=True, slots=True)
class BatchProfile:
    """Batch sizes of one optimisation profile: ``min <= opt <= max``.

    ``dynamic`` is False when the model fixes its batch; then all three are that batch.
    """

    min: int
    opt: int
    max: int
    dynamic: bool

    def __post_init__(self) -> None:
        if not 1 <= self.min <= self.opt <= self.max:
            raise ConfigError(
                f"batch profile must satisfy 1 <= min <= opt <= max, got "
                f"{self.min}/{self.opt}/{self.max}"
            )

    def as_tuple(self) -> tuple[int, int, int]:
        """``(min, opt, max)``, the form stored in the engine cache key."""
        return self.min, self.opt, self.max

    def __str__(self) -> str:
        return f"{self.min}/{self.opt}/{self.max}"


@dataclass(frozen=True, slots=True)
class ProfileShapes:
    """The three NCHW input shapes handed to ``IOptimizationProfile.set_shape``."""

    min: Shape
    opt: Shape
    max: Shape
    batch: BatchProfile


def batch_profile(
    declared_batch: Dim, batch_sizes: Sequence[int], opt: int | None = None
) -> BatchProfile:
    """The batch profile for a model whose input batch is ``declared_batch``.

    ``batch_sizes`` are the batch sizes that will be served (the stack serves single camera
    frames, so ``(1,)`` is usual; a folder run may batch more). min and max are their
    extremes; ``opt`` defaults to the largest, since a throughput run is where kernel choice
    pays most and a batch of one still runs correctly on kernels tuned for more. A fixed
    ``declared_batch`` gives a fixed profile and ignores the request.
    """
    if declared_batch is not None:
        if declared_batch < 1:
            raise ModelError(f"model declares a batch of {declared_batch}")
        return BatchProfile(declared_batch, declared_batch, declared_batch, dynamic=False)
    sizes = list(batch_sizes)
    if not sizes or any(b < 1 for b in sizes):
        raise ConfigError(f"batch sizes must be positive integers, got {sizes}")
    low, high = min(sizes), max(sizes)
    best = high if opt is None else opt
    if not low <= best <= high:
        raise ConfigError(f"opt batch {best} must lie within {low}..{high}")
    return BatchProfile(low, best, high, dynamic=True)


def served_profile(batch_profile: Sequence[int], max_batch: int) -> tuple[int, int, int]:
    """The ``(min, opt, max)`` batch profile to build for a detector serving batches of up to
    ``max_batch``: ``batch_profile`` when it was set (not (1, 1, 1)), else 1..``max_batch``
    with opt ``max_batch`` (the batch a busy detector runs; a batch of one still runs
    correctly on kernels tuned for more). A TOML list is fine for ``batch_profile``."""
    if max_batch < 1:
        raise ConfigError(f"max_batch must be a positive integer, got {max_batch}")
    lo, opt, hi = (int(b) for b in batch_profile)
    if (lo, opt, hi) == (1, 1, 1):
        return 1, max_batch, max_batch
    return lo, opt, hi


def profile_shapes(
    input_shape: Sequence[Dim],
    batch_sizes: Sequence[int],
    *,
    fallback_hw: tuple[int, int] | None = None,
    opt: int | None = None,
) -> ProfileShapes:
    """min/opt/max NCHW shapes for a ``[B, 3, H, W]`` input.

    Dynamic H or W are replaced by ``fallback_hw`` (height, width), e.g. from the model's
    ``imgsz`` metadata: TensorRT could build a spatially dynamic profile too, but the
    letterbox always produces one size, and a fixed size builds faster and runs faster.
    """
    if len(input_shape) != 4:
        raise ModelError(f"expected a [B, 3, H, W] input, got {list(input_shape)}")
    _, channels, height, width = input_shape
    if channels is not None and channels != 3:
        raise ModelError(f"expected 3 input channels, got {channels}")
    if height is None or width is None:
        if fallback_hw is None:
            raise ModelError(
                f"input {list(input_shape)} has a dynamic height or width and no size was given"
            )
        height = height if height is not None else fallback_hw[0]
        width = width if width is not None else fallback_hw[1]
    if height < 1 or width < 1:
        raise ModelError(f"input size must be positive, got {width}x{height}")
    batch = batch_profile(input_shape[0], batch_sizes, opt)
    return ProfileShapes(
        min=(batch.min, 3, height, width),
        opt=(batch.opt, 3, height, width),
        max=(batch.max, 3, height, width),
        batch=batch,
    )


def read_onnx_input(model_path: Path) -> tuple[tuple[Dim, ...], dict[str, str]]:
    """The declared image-input shape (None = dynamic) and the metadata of an ONNX file.

    Reads the graph's header only, not external weights: the engine cache key and the
    profile must be known before TensorRT parses anything, and a serialised engine does not
    carry the ONNX metadata (class names, ``imgsz``) that the pipeline reads.
    """
    import onnx  # only the TensorRT path needs it; a dependency anyway

    if not model_path.is_file():
        raise ModelError(f"{model_path}: no such model file")
    try:
        model = onnx.load(str(model_path), load_external_data=False)
    except Exception as exc:  # protobuf DecodeError, ValueError, ...: junk in any form
        raise ModelError(f"{model_path}: not a valid ONNX model ({exc})") from exc
    weights = {init.name for init in model.graph.initializer}  # old exports list them as inputs
    inputs = [i for i in model.graph.input if i.name not in weights]
    if len(inputs) != 1:
        raise ModelError(f"{model_path}: expected one image input, the model has {len(inputs)}")
    dims = inputs[0].type.tensor_type.shape.dim
    shape = tuple(
        d.dim_value if d.HasField("dim_value") and d.dim_value > 0 else None for d in dims
    )
    return shape, {p.key: p.value for p in model.metadata_props}


def model_profile(
    model_path: Path, batch_profile: tuple[int, int, int]
) -> tuple[ProfileShapes, dict[str, str]]:
    """The profile shapes for an ONNX model and a requested ``(min, opt, max)`` batch.

    A dynamic input size falls back to the ``imgsz`` metadata, then to 640, as the pipeline
    does (:mod:`perception.model_info`). Returns the model's metadata too.
    """
    from runtimes.base import DEFAULT_INPUT_SIZE, parse_imgsz

    declared, metadata = read_onnx_input(model_path)
    hw = parse_imgsz(metadata.get("imgsz")) or (DEFAULT_INPUT_SIZE, DEFAULT_INPUT_SIZE)
    lo, opt, hi = batch_profile
    return profile_shapes(declared, (lo, hi), fallback_hw=hw, opt=opt), metadata


def calibration_shape(shapes: ProfileShapes, dynamic_batch: int = 8) -> Shape:
    """The fixed input shape INT8 calibration runs at.

    TensorRT calibrates at one fixed shape. A fixed-batch model must be fed its own batch;
    a dynamic one gets ``dynamic_batch`` images per batch, whatever the serving profile,
    since more images per step only speeds calibration up.
    """
    batch = dynamic_batch if shapes.batch.dynamic else shapes.batch.max
    return batch, 3, shapes.max[2], shapes.max[3]
