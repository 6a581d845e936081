"""The field walk: a message's dataclass fields are its wire format, declared once.

A message body is the msgpack map of its dataclass fields, by name, in declaration order. The
type hint of each field (read with ``typing.get_type_hints(..., include_extras=True)``) says how
it travels and what a decoder accepts; the plan is built once per class and cached.

The type hints it knows, how each travels, and what a decoder accepts:

- ``int``: an int, never a bool; ``Annotated[int, Range(lo, hi)]`` bounds it on decode.
- ``float``: a number (an int is taken as a float), NaN and inf included.
- ``str``, ``bool``, ``bytes``: exactly that type; bytes stay bytes.
- a dataclass (``Header``): a map, by these same rules.
- ``Annotated[SomeDataclass, Inline()]``: no map of its own; its fields (and counts) are keys
  of the enclosing body, by these same rules (Detections' ``boxes``: xyxy, scores ... beside
  the header). It is always written whole, so a decoder requires each of its fields but those
  that may be None.
- ``tuple[X, ...]`` or ``tuple[X, X, X]``: a list (of exactly that length) of plain values.
- ``dict[str, V]``: a map with str keys; V a plain value or another such dict.
- ``Annotated[npt.NDArray[np.float32], Shape(...)]``: raw little-endian bytes of that dtype,
  exactly that shape.
- ``X | None``: nil or X.
- ``Annotated[Mapping[str, npt.NDArray[Any]], Columns(N, ...)]``: named per-row arrays
  (Boxes' ``columns``), a map name -> ``{"dtype": <one of COLUMN_DTYPES>, "data": <raw
  little-endian bytes>}``, each array (n,) with ``n`` the count of the Dim ``N``, which another
  array field must size. A decoder bounds the number of columns and their names' length before
  reading any, and takes a missing map as no columns (payloads from before columns existed).

A float inside a tuple or a map must be finite (a NaN velocity or latency means nothing); a
float field on its own may be anything, and ``__post_init__`` says where it may not.

Array shapes. ``Shape(N, 4)`` is an (n, 4) array where ``N = Dim("n", lo, hi)`` is a count:
it travels as its own key, taken from the shape of the first array that names it and is never
None (and written just before it); a decoder checks it against [lo, hi] before reading any
array, and every array that names it must then have exactly that many rows. A -1 instead takes
the count from the array's byte length. The dtype comes from the ``NDArray`` hint itself. A
decoded array is a read-only view of the received bytes: no copy, no per-element Python.

Versions. A key that is missing takes the field's default, so a payload from before a field
was added still decodes (``Header.mono_ns``); a missing field without a default is an error.
Keys the class does not declare are ignored, so a newer writer's extra fields do no harm.

Anything that does not fit raises :class:`common.errors.DecodeError` naming the field's path.

The marks (``Range``, ``Dim``, ``Shape``, ``Columns``, ``Inline``) are common/field_types.py's;
each kind of field's encoder and decoder is common/field_codecs.py's; this module compiles a
class's plan from them and walks it.
"""

from __future__ import annotations

import dataclasses
import types
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, TypeVar, Union, get_args, get_origin, get_type_hints

from common.errors import DecodeError
from common.field_codecs import (
    Decoder,
    Encoder,
    FieldMismatch,
    array_codec,
    columns_codec,
    dtype_of,
    exact,
    float_decoder,
    got,
    int_decoder,
    is_ndarray,
    map_decoder,
    optional,
    tuple_decoder,
)
from common.field_types import Columns, Dim, Inline, Range, Shape

T = TypeVar("T")


# Counts written on the wire just before a field, from that field's shape: (dim, axis).
_Counts = tuple[tuple[Dim, int], ...]


@dataclass(frozen=True, slots=True)
class _Plan:
    """How one dataclass travels, as flat tuples for a tight loop on every message."""

    # enc None: the value as it is; inline: enc returns keys to merge into the body.
    encoders: tuple[tuple[str, Encoder | None, _Counts, bool], ...]  # (name, enc, counts, inline)
    # An inline field's decoder reads the enclosing body itself.
    decoders: tuple[tuple[str, Decoder, bool, bool], ...]  # (name, dec, required, inline)
    dims: tuple[Dim, ...]
    keys: frozenset[str]  # every key the body holds: fields, counts, inline fields' keys


# By (class, travels inline): an inline struct's fields are all required (see the docstring).
_PLANS: dict[tuple[type, bool], _Plan] = {}


def encode_struct(obj: Any) -> dict[str, Any]:
    """The wire body of dataclass ``obj``: every field by name, plus its counts."""
    plan = _PLANS.get((type(obj), False)) or _plan(type(obj))
    out: dict[str, Any] = {}
    for name, enc, counts, inline in plan.encoders:
        v = getattr(obj, name)
        if inline:
            out.update(enc(v))  # type: ignore[misc]  # an inline field always has an encoder
            continue
        if counts:
            for dim, axis in counts:
                out[dim.name] = int(v.shape[axis])
        out[name] = v if enc is None else enc(v)
    return out


def decode_struct(cls: type[T], body: Mapping[str, Any], where: str) -> T:
    """Build ``cls`` from a wire body, or raise DecodeError naming ``where`` and the field."""
    try:
        return _decode(cls, body)
    except FieldMismatch as exc:
        raise DecodeError(f"{'.'.join((where, *exc.path))}: {exc.reason}") from None


def inline_fields(cls: type) -> frozenset[str]:
    """The names of the fields of dataclass ``cls`` that travel inline (``Inline``)."""
    plan = _PLANS.get((cls, False)) or _plan(cls)
    return frozenset(name for name, _, _, inline in plan.encoders if inline)


def _decode(cls: type[T], body: Mapping[str, Any], whole: bool = False) -> T:
    plan = _PLANS.get((cls, whole)) or _plan(cls, whole)
    dims: dict[str, int] = {}
    for dim in plan.dims:
        v = body.get(dim.name)
        if type(v) is not int:
            raise FieldMismatch(f"expected an int count, got {got(v)}", (dim.name,))
        if not dim.lo <= v <= dim.hi:
            raise FieldMismatch(f"{v} is outside [{dim.lo}, {dim.hi}]", (dim.name,))
        dims[dim.name] = v
    kwargs: dict[str, Any] = {}
    for name, dec, required, inline in plan.decoders:
        if inline:
            kwargs[name] = dec(body, dims)  # its keys are this body's: paths need no prefix
            continue
        if name not in body:
            if required:
                raise FieldMismatch("missing field", (name,))
            continue  # written before this field existed: the dataclass default applies
        try:
            kwargs[name] = dec(body[name], dims)
        except FieldMismatch as exc:
            raise FieldMismatch(exc.reason, (name, *exc.path)) from None
    return cls(**kwargs)


def _plan(cls: type, whole: bool = False) -> _Plan:
    """Compile the encoders and decoders of dataclass ``cls`` from its type hints; ``whole``:
    ``cls`` travels inline, so every field that may not be None is required."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls.__name__} is not a dataclass")
    hints = get_type_hints(cls, include_extras=True)
    encoders: list[tuple[str, Encoder | None, _Counts, bool]] = []
    decoders: list[tuple[str, Decoder, bool, bool]] = []
    placed: set[str] = set()
    dims: dict[str, Dim] = {}
    keys: list[str] = []
    columns: list[Dim] = []
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        where = f"{cls.__name__}.{f.name}"
        inner = _inline_type(hint, where)
        if inner is not None:
            inner_plan = _plan(inner, whole=True)
            encoders.append((f.name, encode_struct, (), True))
            decoders.append((f.name, _inline_decoder(inner), True, True))
            keys.extend(inner_plan.keys)
            continue
        keys.append(f.name)
        enc, dec = _converter(hint, (), where)
        spec = _columns_spec(hint)
        if spec is not None:
            columns.append(spec.rows)
            encoders.append((f.name, enc, (), False))
            decoders.append((f.name, dec, False, False))  # missing: written before columns
            continue
        here: list[tuple[Dim, int]] = []
        shape, optional = _shape_of(hint)
        for axis, d in enumerate(shape.dims if shape else ()):
            if isinstance(d, Dim):
                if dims.setdefault(d.name, d) != d:
                    raise TypeError(f"{cls.__name__}: two different Dims named {d.name!r}")
                if not optional and d.name not in placed:
                    placed.add(d.name)
                    here.append((d, axis))
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        encoders.append((f.name, enc, tuple(here), False))
        decoders.append((f.name, dec, required or (whole and not optional), False))
    for name in dims:
        if name in {e[0] for e in encoders}:
            raise TypeError(f"{cls.__name__}: Dim {name!r} has a field's name")
        if name not in placed:
            raise TypeError(f"{cls.__name__}: Dim {name!r} sizes no array that is always there")
    for d in columns:
        if d.name not in placed or dims[d.name] != d:
            raise TypeError(f"{cls.__name__}: Columns' Dim {d.name!r} sizes no array field")
    keys.extend(dims)
    if len(set(keys)) != len(keys):
        twice = sorted({k for k in keys if keys.count(k) > 1})
        raise TypeError(f"{cls.__name__}: keys {twice} would travel twice (an inline field's?)")
    plan = _Plan(tuple(encoders), tuple(decoders), tuple(dims.values()), frozenset(keys))
    _PLANS[(cls, whole)] = plan
    return plan


def _inline_type(hint: Any, where: str) -> type | None:
    """The dataclass of an ``Annotated[X, Inline()]`` field, or None for any other field."""
    if get_origin(hint) is not Annotated or not any(
        isinstance(m, Inline) for m in get_args(hint)[1:]
    ):
        return None
    inner = get_args(hint)[0]
    if not (isinstance(inner, type) and dataclasses.is_dataclass(inner)):
        raise TypeError(f"{where}: only a dataclass travels inline, got {inner}")
    return inner


def _inline_decoder(cls: type) -> Decoder:
    def decode(body: Any, dims: Mapping[str, int]) -> Any:
        return _decode(cls, body, whole=True)

    return decode


def _columns_spec(hint: Any) -> Columns | None:
    if get_origin(hint) is not Annotated:
        return None
    return next((m for m in get_args(hint)[1:] if isinstance(m, Columns)), None)


def _shape_of(hint: Any) -> tuple[Shape | None, bool]:
    """The Shape annotating an array field, and whether the field may be None."""
    optional = False
    shape = None
    while True:
        origin = get_origin(hint)
        if origin is Annotated:
            hint, *meta = get_args(hint)
            shape = next((m for m in meta if isinstance(m, Shape)), shape)
        elif origin in (Union, types.UnionType) and type(None) in get_args(hint):
            optional = True
            hint = next(a for a in get_args(hint) if a is not type(None))
        else:
            return shape, optional


def _converter(hint: Any, meta: tuple[Any, ...], where: str) -> tuple[Encoder | None, Decoder]:
    origin, args = get_origin(hint), get_args(hint)
    if origin is Annotated:
        return _converter(args[0], meta + tuple(args[1:]), where)
    spec = next((m for m in meta if isinstance(m, Columns)), None)
    if spec is not None:
        if origin not in (Mapping, dict) or args[:1] != (str,):
            raise TypeError(f"{where}: Columns annotates a Mapping[str, NDArray], got {hint}")
        return columns_codec(spec)
    if origin in (Union, types.UnionType):
        rest = [a for a in args if a is not type(None)]
        if len(rest) != 1 or len(args) != 2:
            raise TypeError(f"{where}: only `X | None` unions are supported, got {hint}")
        return optional(*_converter(rest[0], meta, where))
    if is_ndarray(origin):
        return array_codec(dtype_of(hint, where), meta, where)
    if hint is int:
        rng = next((m for m in meta if isinstance(m, Range)), Range())
        return None, int_decoder(rng)
    if hint is float:
        return None, float_decoder(finite=False)
    if hint in (str, bool, bytes):
        return None, exact(hint)
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        _plan(hint)
        return encode_struct, _nested(hint)
    if origin is tuple:
        return list, _tuple(args, where)
    if origin is dict and args and args[0] is str:
        return None, map_decoder(_element(args[1], where))
    raise TypeError(f"{where}: no wire format for {hint}")


def _nested(cls: type) -> Decoder:
    def decode(v: Any, dims: Mapping[str, int]) -> Any:
        if type(v) is not dict:
            raise FieldMismatch(f"expected map, got {got(v)}")
        return _decode(cls, v)

    return decode


def _element(hint: Any, where: str) -> Decoder:
    """Elements of tuples and maps: floats there must be finite (a NaN vector means nothing)."""
    if hint is float:
        return float_decoder(finite=True)
    enc, dec = _converter(hint, (), where)
    if enc is not None:
        raise TypeError(f"{where}: elements must be plain values, got {hint}")
    return dec


def _tuple(args: tuple[Any, ...], where: str) -> Decoder:
    if len(args) == 2 and args[1] is Ellipsis:
        item, length = args[0], None
    elif args and all(a is args[0] for a in args):
        item, length = args[0], len(args)
    else:
        raise TypeError(f"{where}: tuples must be tuple[X, ...] or of one type, got {args}")
    return tuple_decoder(item, length, _element(item, where))
