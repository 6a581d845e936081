"""The one msgpack codec of the stack: the envelope, per-type schema versions, the Message base.

Every message on the bus is the msgpack map ``{"v": <version>, "t": <type tag>, "d": <body>}``.
The body is the message's dataclass fields by name (common/fields.py); numpy arrays travel as
raw little-endian bytes whose dtype is fixed by the field and whose shape is checked on decode.

Versions. Each message type carries its own ``VERSION`` and writes it in ``v``. A decoder reads
every version from ``OLDEST_VERSION`` to its own: an older payload that lacks a field added
since takes that field's default, and ``_upgrade`` may rewrite an older body first. A version
newer than the decoder's own is refused with a DecodeError that says so: bump ``VERSION`` only
for a change that older readers would misread (a field removed, renamed, retyped or given a new
meaning, or a new field without a default); a new field with a default needs no bump, since
readers ignore keys they do not know.

Anything that does not decode to exactly a valid message raises
:class:`common.errors.DecodeError` and nothing else, so a subscriber needs a single
``except DecodeError`` to drop garbage.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar, Self

import msgpack

from common.errors import DecodeError
from common.fields import decode_struct, encode_struct

# A single frame of 8K RGB is ~100 MB; nothing legitimate on the bus is larger than this.
MAX_PAYLOAD_BYTES = 128 * 1024 * 1024


def pack(tag: str, version: int, body: Mapping[str, Any]) -> bytes:
    """Wrap ``body`` in the versioned envelope and serialise it."""
    out = msgpack.packb({"v": version, "t": tag, "d": body}, use_bin_type=True)
    assert isinstance(out, bytes)
    return out


def unpack(
    payload: bytes | bytearray | memoryview, tag: str, newest: int, oldest: int = 1
) -> tuple[int, dict[str, Any]]:
    """Check the envelope of ``payload``; return its version and body, or raise DecodeError."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise DecodeError(f"{tag}: payload of {len(payload)} bytes is over the limit")
    try:
        obj = msgpack.unpackb(bytes(payload), raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises a zoo of types on garbage; all mean the same here
        raise DecodeError(f"{tag}: not msgpack ({type(exc).__name__})") from exc
    if not isinstance(obj, dict):
        raise DecodeError(f"{tag}: expected an envelope map, got {type(obj).__name__}")
    if obj.get("t") != tag:
        raise DecodeError(f"expected a {tag} message, got {obj.get('t')!r}")
    version = obj.get("v")
    if type(version) is not int:
        raise DecodeError(f"{tag}: schema version {version!r} is not a version number")
    if version > newest:
        raise DecodeError(
            f"{tag}: schema version {version} is newer than this build reads "
            f"({oldest}..{newest}); update this reader"
        )
    if version < oldest:
        raise DecodeError(
            f"{tag}: schema version {version} is older than this build reads ({oldest}..{newest})"
        )
    body = obj.get("d")
    if not isinstance(body, dict):
        raise DecodeError(f"{tag}: body is not a map")
    return version, body


class Message:
    """A message type: a frozen dataclass whose fields are its wire body, declared once.

    A subclass sets ``TAG`` (the ``t`` of its envelope) and, when its schema changes,
    ``VERSION``; it keeps its value checks in ``__post_init__``, whose ValueError becomes a
    DecodeError on decode. Two hooks, both optional:

    - ``_wire_extras``: derived values written on the wire for readers in other languages
      (e.g. Detections' ``center_size``); a decoder never reads them back.
    - ``_upgrade``: rewrites the body of an older version before it is decoded.
    """

    __slots__ = ()

    TAG: ClassVar[str]
    VERSION: ClassVar[int] = 1
    OLDEST_VERSION: ClassVar[int] = 1

    def _wire_extras(self) -> dict[str, Any]:
        return {}

    @classmethod
    def _upgrade(cls, version: int, body: dict[str, Any]) -> dict[str, Any]:
        return body

    def encode(self) -> bytes:
        body = encode_struct(self)
        body.update(self._wire_extras())
        return pack(self.TAG, self.VERSION, body)

    @classmethod
    def decode(cls, payload: bytes | bytearray | memoryview) -> Self:
        """Decode ``payload`` or raise DecodeError; never any other exception."""
        version, body = unpack(payload, cls.TAG, cls.VERSION, cls.OLDEST_VERSION)
        try:
            if version != cls.VERSION:
                body = cls._upgrade(version, body)
            return decode_struct(cls, body, cls.TAG)
        except DecodeError:
            raise
        except (ValueError, TypeError) as exc:  # a __post_init__ check on decoded values
            raise DecodeError(f"{cls.TAG}: {exc}") from exc
