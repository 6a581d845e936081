"""Convolution, pooling, padding and resizing for the ONNX interpreter (see tensor_ops).

Torch pads symmetrically only, so ONNX's per-side ``pads`` (and ``auto_pad``) are turned into an
explicit ``F.pad`` where the two sides differ. Resize is mapped onto ``F.interpolate`` only for
the modes where the two agree exactly; the others raise ModelError.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import torch.nn.functional as F
from torch import Tensor

from common.errors import ModelError
from runtimes.onnx_torch.tensor_ops import Attrs, OpDef, OpResult, RunContext, arg, ints


def spatial_pads(
    a: Attrs,
    size: Sequence[int],
    kernel: Sequence[int],
    strides: Sequence[int],
    dilations: Sequence[int],
) -> tuple[list[int], list[int]]:
    """``(begin, end)`` padding per spatial axis, from ``pads`` or ``auto_pad``."""
    auto = a.get("auto_pad", "NOTSET")
    nd = len(kernel)
    if auto in ("SAME_UPPER", "SAME_LOWER"):
        begin, end = [], []
        for n, k, s, d in zip(size, kernel, strides, dilations, strict=True):
            total = max((math.ceil(n / s) - 1) * s + (k - 1) * d + 1 - n, 0)
            small, large = total // 2, total - total // 2
            begin.append(small if auto == "SAME_UPPER" else large)
            end.append(large if auto == "SAME_UPPER" else small)
        return begin, end
    pads = [0] * (2 * nd) if auto == "VALID" else list(a.get("pads", [0] * (2 * nd)))
    return pads[:nd], pads[nd:]


def torch_pad(begin: Sequence[int], end: Sequence[int]) -> list[int]:
    """ONNX per-axis (begin, end) pads as ``F.pad`` wants them: last axis first."""
    out: list[int] = []
    for b, e in zip(reversed(begin), reversed(end), strict=True):
        out += [b, e]
    return out


def _conv(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data, weight, bias = x[0], x[1], arg(x, 2)
    nd = weight.dim() - 2
    if nd not in (1, 2, 3):
        raise ModelError(f"Conv over {nd} spatial axes is not supported")
    strides = a.get("strides", [1] * nd)
    dilations = a.get("dilations", [1] * nd)
    begin, end = spatial_pads(a, data.shape[2:], weight.shape[2:], strides, dilations)
    if begin != end:  # torch pads symmetrically only: pad explicitly first
        data, begin = F.pad(data, torch_pad(begin, end)), [0] * nd
    conv = (F.conv1d, F.conv2d, F.conv3d)[nd - 1]
    return conv(data, weight, bias, strides, begin, dilations, a.get("group", 1))


def _max_pool(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    if a["_num_outputs"] > 1:
        raise ModelError("MaxPool with an Indices output is not supported")
    data: Tensor = x[0]
    kernel = a["kernel_shape"]
    nd = len(kernel)
    strides = a.get("strides", [1] * nd)
    dilations = a.get("dilations", [1] * nd)
    begin, end = spatial_pads(a, data.shape[2:], kernel, strides, dilations)
    if begin != end or any(2 * b > k for b, k in zip(begin, kernel, strict=True)):
        data = F.pad(data, torch_pad(begin, end), value=-math.inf)
        begin = [0] * nd
    pool = (F.max_pool1d, F.max_pool2d, F.max_pool3d)[nd - 1]
    return pool(data, kernel, strides, begin, dilations, ceil_mode=bool(a.get("ceil_mode", 0)))


def _avg_pool(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    kernel = a["kernel_shape"]
    nd = len(kernel)
    if nd != 2 or a.get("dilations", [1, 1]) != [1, 1]:
        raise ModelError("AveragePool is supported in 2-D, without dilation, only")
    strides = a.get("strides", [1] * nd)
    begin, end = spatial_pads(a, data.shape[2:], kernel, strides, [1] * nd)
    if begin != end:
        raise ModelError("AveragePool with asymmetric padding is not supported")
    return F.avg_pool2d(
        data,
        kernel,
        strides,
        begin,
        ceil_mode=bool(a.get("ceil_mode", 0)),
        count_include_pad=bool(a.get("count_include_pad", 0)),
    )


_PAD_MODES = {"constant": "constant", "reflect": "reflect", "edge": "replicate", "wrap": "circular"}


def _pad(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    pads = ints(x, 1, a, "pads") or []
    value = arg(x, 2)
    value = a.get("value", 0.0) if value is None else value
    value = value[0] if isinstance(value, list) else value
    rank = data.dim()
    axes = [ax % rank for ax in (arg(x, 3) or range(rank))]
    begin, end = [0] * rank, [0] * rank
    for i, axis in enumerate(axes):
        begin[axis], end[axis] = pads[i], pads[i + len(axes)]
    flat = torch_pad(begin, end)
    while flat[-2:] == [0, 0] and len(flat) > 2:  # torch pads the trailing axes only
        flat = flat[:-2]
    mode = _PAD_MODES.get(a.get("mode", "constant"))
    if mode is None:
        raise ModelError(f"Pad mode {a.get('mode')!r} is not supported")
    if mode == "constant":
        return F.pad(data, flat, value=float(value))
    return F.pad(data, flat, mode=mode)


def _resize(ctx: RunContext, x: list[Any], a: Attrs) -> OpResult:
    data: Tensor = x[0]
    scales, sizes = (arg(x, 1), None) if a["_opset"] < 11 else (arg(x, 2), arg(x, 3))
    if a.get("antialias", 0) or a.get("axes") is not None:
        raise ModelError("Resize with antialias or axes is not supported")
    in_size = list(data.shape[2:])
    if sizes:
        if list(sizes[:2]) != list(data.shape[:2]):
            raise ModelError("Resize of the batch or channel axis is not supported")
        out_size = [int(s) for s in sizes[2:]]
        kwargs: dict[str, Any] = {"size": out_size}
        integer_up = all(o % n == 0 for o, n in zip(out_size, in_size, strict=True))
    elif scales:
        if list(scales[:2]) != [1.0, 1.0]:
            raise ModelError("Resize of the batch or channel axis is not supported")
        factors = [float(s) for s in scales[2:]]
        out_size = [math.floor(n * f) for n, f in zip(in_size, factors, strict=True)]
        kwargs = {"scale_factor": factors, "recompute_scale_factor": False}
        integer_up = all(f >= 1 and f.is_integer() for f in factors)
    else:
        raise ModelError("Resize without scales or sizes")
    mode = a.get("mode", "nearest")
    ctm = a.get("coordinate_transformation_mode", "half_pixel")
    if ctm == "pytorch_half_pixel" and all(o > 1 for o in out_size):
        ctm = "half_pixel"  # the two differ only for an output length of 1
    rounding = a.get("nearest_mode", "round_prefer_floor")
    nd = len(in_size)
    if mode == "nearest":
        if ctm == "asymmetric" and rounding == "floor":
            return F.interpolate(data, mode="nearest", **kwargs)
        # torch's nearest-exact rounds half up; the same as round-half-down unless a source
        # coordinate lands on .5 exactly, which an integer upscale never does.
        if ctm == "half_pixel" and (rounding == "round_prefer_ceil" or integer_up):
            return F.interpolate(data, mode="nearest-exact", **kwargs)
    elif mode == "linear" and nd in (1, 2, 3) and ctm in ("half_pixel", "align_corners"):
        tmode = ("linear", "bilinear", "trilinear")[nd - 1]
        return F.interpolate(data, mode=tmode, align_corners=ctm == "align_corners", **kwargs)
    raise ModelError(
        f"Resize mode={mode} coordinate_transformation_mode={ctm} nearest_mode={rounding} "
        "is not supported"
    )


#: The spatial ops.
SPATIAL_OPS: dict[str, OpDef] = {
    "AveragePool": OpDef(_avg_pool),
    "Conv": OpDef(_conv),
    "MaxPool": OpDef(_max_pool),
    "Pad": OpDef(_pad, frozenset({1, 2, 3})),
    "Resize": OpDef(_resize, frozenset({1, 2, 3})),
}
