"""The codec of each kind of field common/fields.py's field walk knows: for a type hint's
kind (an int within a Range, a float, an exact type, an array of a Shape, named Columns, a
tuple, a map, ``X | None``), the encoder (None: the value travels as it is) and the decoder
that checks what arrives, raising :class:`FieldMismatch` with the reason. The walk compiles a
class's plan from these, and fills the field's path into the mismatch on the way up."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, get_args

from common.errors import DecodeError
from common.field_types import COLUMN_DTYPES, Columns, Dim, Range, Shape

if TYPE_CHECKING:
    import numpy as np

Encoder = Callable[[Any], Any]
Decoder = Callable[[Any, Mapping[str, int]], Any]


class FieldMismatch(DecodeError):
    """A value that does not fit its field; the path is filled in on the way up, and the
    walk (common/fields.py's ``decode_struct``) raises a DecodeError naming it."""

    def __init__(self, reason: str, path: tuple[str, ...] = ()) -> None:
        super().__init__(reason)
        self.reason = reason
        self.path = path


def got(v: Any) -> str:
    """The type of ``v`` as a mismatch names it."""
    return type(v).__name__


def is_ndarray(origin: Any) -> bool:
    """Whether a hint's origin is numpy's array. numpy is imported by the messages that carry
    arrays, never here: a hint cannot name ndarray unless numpy is loaded, and the messages
    without arrays (common/control_messages.py: the e-stop command's) must not pay for it."""
    numpy = sys.modules.get("numpy")
    return numpy is not None and origin is numpy.ndarray


def dtype_of(hint: Any, where: str) -> np.dtype[Any]:
    """The element type of ``npt.NDArray[np.float32]``: ndarray[shape, dtype[float32]]."""
    import numpy as np

    args = get_args(hint)
    scalar = get_args(args[1])[0] if len(args) == 2 and get_args(args[1]) else None
    if not (isinstance(scalar, type) and issubclass(scalar, np.generic)) or scalar in (
        np.generic,
        np.number,
        np.floating,
        np.integer,
    ):
        raise TypeError(f"{where}: an array field needs a concrete dtype, got {hint}")
    return np.dtype(scalar)


def array_codec(dtype: np.dtype[Any], meta: tuple[Any, ...], where: str) -> tuple[Encoder, Decoder]:
    import numpy as np

    shape = next((m for m in meta if isinstance(m, Shape)), None)
    if shape is None or list(shape.dims).count(-1) > 1:
        raise TypeError(f"{where}: an array field needs Shape(...) with at most one -1")
    wire = dtype.newbyteorder("<")
    native = None if wire == dtype.newbyteorder("=") else dtype.newbyteorder("=")
    spec = shape.dims

    def encode(arr: Any) -> bytes:
        return np.ascontiguousarray(arr, dtype=wire).tobytes()

    def decode(v: Any, dims: Mapping[str, int]) -> Any:
        if type(v) is not bytes:
            raise FieldMismatch(f"expected {dtype} array bytes, got {got(v)}")
        if len(v) % wire.itemsize:
            raise FieldMismatch(f"{len(v)} bytes is not a whole {dtype} array")
        shp = tuple(dims[d.name] if isinstance(d, Dim) else d for d in spec)
        flat = np.frombuffer(v, dtype=wire)
        try:
            arr = flat.reshape(shp)
        except ValueError:
            raise FieldMismatch(f"{flat.size} values do not fit shape {shp}") from None
        return arr if native is None else arr.astype(native)  # a copy on big-endian hosts only

    return encode, decode


def columns_codec(spec: Columns) -> tuple[Encoder, Decoder]:
    import numpy as np

    wire = {name: np.dtype(name).newbyteorder("<") for name in COLUMN_DTYPES}
    rows, most, longest = spec.rows.name, spec.max_columns, spec.max_name_chars

    def encode(columns: Mapping[str, Any]) -> dict[str, Any]:
        return {
            name: {
                "dtype": arr.dtype.name,
                "data": np.ascontiguousarray(arr, wire[arr.dtype.name]).tobytes(),
            }
            for name, arr in columns.items()
        }

    def decode(v: Any, dims: Mapping[str, int]) -> dict[str, Any]:
        if type(v) is not dict:
            raise FieldMismatch(f"expected map, got {got(v)}")
        if len(v) > most:
            raise FieldMismatch(f"{len(v)} columns is over the limit of {most}")
        n = dims[rows]
        out: dict[str, Any] = {}
        for name, column in v.items():
            if type(name) is not str or not 0 < len(name) <= longest:
                raise FieldMismatch(f"a column name must be 1..{longest} characters of str")
            if type(column) is not dict:
                raise FieldMismatch(f"expected map, got {got(column)}", (name,))
            dtype, data = column.get("dtype"), column.get("data")
            if type(dtype) is not str or dtype not in wire:
                raise FieldMismatch(
                    f"dtype must be one of {', '.join(COLUMN_DTYPES)}", (name, "dtype")
                )
            if type(data) is not bytes or len(data) != n * wire[dtype].itemsize:
                raise FieldMismatch(f"expected {n} {dtype} values as bytes", (name, "data"))
            if dtype == "bool":
                raw = np.frombuffer(data, np.uint8)
                if (raw > 1).any():
                    raise FieldMismatch("a bool is byte 0 or 1", (name, "data"))
                out[name] = raw.view(np.bool_)
            else:
                arr = np.frombuffer(data, wire[dtype])
                out[name] = arr if arr.dtype.isnative else arr.astype(arr.dtype.newbyteorder("="))
        return out

    return encode, decode


def optional(enc: Encoder | None, dec: Decoder) -> tuple[Encoder | None, Decoder]:
    def decode(v: Any, dims: Mapping[str, int]) -> Any:
        return None if v is None else dec(v, dims)

    if enc is None:
        return None, decode
    inner = enc

    def encode(v: Any) -> Any:
        return None if v is None else inner(v)

    return encode, decode


def int_decoder(rng: Range) -> Decoder:
    lo, hi = rng.lo, rng.hi

    def decode(v: Any, dims: Mapping[str, int]) -> int:
        if type(v) is not int:
            raise FieldMismatch(f"expected int, got {got(v)}")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise FieldMismatch(f"{v} is outside [{lo}, {hi}]")
        return v

    return decode


def float_decoder(finite: bool) -> Decoder:
    def decode(v: Any, dims: Mapping[str, int]) -> float:
        if type(v) is not float and type(v) is not int:
            raise FieldMismatch(f"expected float, got {got(v)}")
        if finite and not math.isfinite(v):
            raise FieldMismatch(f"expected a finite number, got {v}")
        return float(v)

    return decode


def exact(kind: type) -> Decoder:
    def decode(v: Any, dims: Mapping[str, int]) -> Any:
        if type(v) is not kind:
            raise FieldMismatch(f"expected {kind.__name__}, got {got(v)}")
        return v

    return decode


def map_decoder(value_dec: Decoder) -> Decoder:
    def decode(v: Any, dims: Mapping[str, int]) -> dict[str, Any]:
        if type(v) is not dict:
            raise FieldMismatch(f"expected map, got {got(v)}")
        out: dict[str, Any] = {}
        for k, x in v.items():
            if type(k) is not str:
                raise FieldMismatch(f"expected str keys, got {got(k)}")
            try:
                out[k] = value_dec(x, dims)
            except FieldMismatch as exc:
                raise FieldMismatch(exc.reason, (k, *exc.path)) from None
        return out

    return decode


def tuple_decoder(item: Any, length: int | None, dec: Decoder) -> Decoder:
    """A list of ``length`` (None: any number of) ``item`` values, each read by ``dec``."""
    expected = f"list of {length or 'any number of'} {getattr(item, '__name__', item)}"

    def decode(v: Any, dims: Mapping[str, int]) -> tuple[Any, ...]:
        if type(v) is not list:
            raise FieldMismatch(f"expected {expected}, got {got(v)}")
        if length is not None and len(v) != length:
            raise FieldMismatch(f"expected {expected}, got {len(v)}")
        if item is str:  # class names: up to MAX_DETECTIONS of them, check types in one pass
            if not all(type(x) is str for x in v):
                raise FieldMismatch(f"expected {expected}, got another type inside")
            return tuple(v)
        try:
            return tuple(dec(x, dims) for x in v)
        except FieldMismatch as exc:
            raise FieldMismatch(f"expected {expected}: {exc.reason}") from None

    return decode
