"""The one msgpack codec of the stack: envelope, schema version and typed-array helpers.

Every message on the bus is the msgpack map ``{"v": SCHEMA_VERSION, "t": <type tag>, "d": <body>}``.
The body is a map of plain msgpack values; numpy arrays travel as raw little-endian bytes whose
dtype is fixed by the field and whose element count is checked on decode. Anything that does not
decode to exactly that raises :class:`common.errors.DecodeError` and nothing else, so a
subscriber needs a single ``except DecodeError`` to drop garbage.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import msgpack
import numpy as np
import numpy.typing as npt

from common.errors import DecodeError

SCHEMA_VERSION = 1

# A single frame of 8K RGB is ~100 MB; nothing legitimate on the bus is larger than this.
MAX_PAYLOAD_BYTES = 128 * 1024 * 1024


def pack(tag: str, body: Mapping[str, Any]) -> bytes:
    """Wrap ``body`` in the versioned envelope and serialise it."""
    out = msgpack.packb({"v": SCHEMA_VERSION, "t": tag, "d": dict(body)}, use_bin_type=True)
    assert isinstance(out, bytes)
    return out


def unpack(payload: bytes | bytearray | memoryview, tag: str) -> dict[str, Any]:
    """Check the envelope of ``payload`` and return its body, or raise DecodeError."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise DecodeError(f"{tag}: payload of {len(payload)} bytes is over the limit")
    try:
        obj = msgpack.unpackb(bytes(payload), raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises a zoo of types on garbage; all mean the same here
        raise DecodeError(f"{tag}: not msgpack ({type(exc).__name__})") from exc
    if not isinstance(obj, dict):
        raise DecodeError(f"{tag}: expected an envelope map, got {type(obj).__name__}")
    version = obj.get("v")
    if version != SCHEMA_VERSION:
        raise DecodeError(f"{tag}: schema version {version!r}, this build reads {SCHEMA_VERSION}")
    if obj.get("t") != tag:
        raise DecodeError(f"expected a {tag} message, got {obj.get('t')!r}")
    body = obj.get("d")
    if not isinstance(body, dict):
        raise DecodeError(f"{tag}: body is not a map")
    return body


class Body:
    """Typed accessors over a decoded body; every mismatch becomes a DecodeError."""

    __slots__ = ("_d", "_tag")

    def __init__(self, tag: str, body: Mapping[str, Any]) -> None:
        self._tag = tag
        self._d = body

    @property
    def tag(self) -> str:
        return self._tag

    def fields(self) -> list[str]:
        return [k for k in self._d if isinstance(k, str)]

    def is_null(self, key: str) -> bool:
        return self._get(key) is None

    def floats(self, key: str) -> list[float]:
        v = self._get(key)
        if not isinstance(v, list) or not all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in v
        ):
            raise self._fail(key, "list of numbers")
        return [float(x) for x in v]

    def _get(self, key: str) -> Any:
        if key not in self._d:
            raise DecodeError(f"{self._tag}: missing field {key!r}")
        return self._d[key]

    def _fail(self, key: str, expected: str) -> DecodeError:
        got = type(self._d.get(key)).__name__
        return DecodeError(f"{self._tag}.{key}: expected {expected}, got {got}")

    def get_int(self, key: str, lo: int | None = None, hi: int | None = None) -> int:
        v = self._get(key)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self._fail(key, "int")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise DecodeError(f"{self._tag}.{key}: {v} is outside [{lo}, {hi}]")
        return v

    def get_bool(self, key: str) -> bool:
        v = self._get(key)
        if not isinstance(v, bool):
            raise self._fail(key, "bool")
        return v

    def get_float(self, key: str) -> float:
        v = self._get(key)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self._fail(key, "float")
        return float(v)

    def get_str(self, key: str) -> str:
        v = self._get(key)
        if not isinstance(v, str):
            raise self._fail(key, "str")
        return v

    def get_bytes(self, key: str) -> bytes:
        v = self._get(key)
        if not isinstance(v, bytes):
            raise self._fail(key, "bytes")
        return v

    def get_map(self, key: str) -> Body:
        v = self._get(key)
        if not isinstance(v, dict):
            raise self._fail(key, "map")
        return Body(f"{self._tag}.{key}", v)

    def float_map(self, key: str) -> dict[str, float]:
        v = self._get(key)
        if not isinstance(v, dict) or not all(
            isinstance(k, str)
            and isinstance(x, int | float)
            and not isinstance(x, bool)
            and math.isfinite(x)
            for k, x in v.items()
        ):
            raise self._fail(key, "map of str to finite float")
        return {k: float(x) for k, x in v.items()}

    def int_map(self, key: str) -> dict[str, int]:
        v = self._get(key)
        if not isinstance(v, dict) or not all(
            isinstance(k, str) and isinstance(x, int) and not isinstance(x, bool)
            for k, x in v.items()
        ):
            raise self._fail(key, "map of str to int")
        return dict(v)

    def str_list(self, key: str) -> tuple[str, ...]:
        v = self._get(key)
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            raise self._fail(key, "list of str")
        return tuple(v)

    def array(self, key: str, dtype: npt.DTypeLike, shape: tuple[int, ...]) -> npt.NDArray[Any]:
        """Read a raw little-endian array of exactly ``shape``; -1 in shape is inferred."""
        raw = self.get_bytes(key)
        dt = np.dtype(dtype).newbyteorder("<")
        if len(raw) % dt.itemsize:
            raise DecodeError(f"{self._tag}.{key}: {len(raw)} bytes is not a whole {dt} array")
        flat = np.frombuffer(raw, dtype=dt)
        try:
            arr = flat.reshape(shape)
        except ValueError as exc:
            raise DecodeError(
                f"{self._tag}.{key}: {flat.size} values do not fit shape {shape}"
            ) from exc
        return arr.astype(dt.newbyteorder("="), copy=False)


def array_bytes(arr: npt.NDArray[Any], dtype: npt.DTypeLike) -> bytes:
    """Serialise ``arr`` as raw little-endian ``dtype`` bytes."""
    return np.ascontiguousarray(arr, dtype=np.dtype(dtype).newbyteorder("<")).tobytes()
