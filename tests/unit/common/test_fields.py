"""The field walk and per-type versions, on small test messages declared here."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar

import msgpack
import numpy as np
import numpy.typing as npt
import pytest

from common.codec import Message
from common.errors import DecodeError
from common.field_types import Dim, Inline, NonNegativeInt, Range, Shape
from common.fields import inline_fields
from common.messages import Header

HEADER = Header(stamp_ns=1_700_000_000_000_000_000, frame_id="x", seq=1, source="test")
N = Dim("n", 0, 100)


@dataclass(frozen=True, slots=True, kw_only=True)
class Everything(Message):
    """One field of every supported kind."""

    TAG: ClassVar[str] = "Everything"
    header: Header
    count: NonNegativeInt
    small: Annotated[int, Range(-5, 5)]
    ratio: float
    name: str
    flag: bool
    blob: bytes
    names: tuple[str, ...]
    vec: tuple[float, float, float]
    gains: dict[str, float]
    totals: dict[str, int]
    nested: dict[str, dict[str, float]]
    boxes: Annotated[npt.NDArray[np.float32], Shape(N, 4)]
    ids: Annotated[npt.NDArray[np.int64], Shape(N)] | None = None
    image: Annotated[npt.NDArray[np.uint8], Shape(-1, 3)]


def _everything(n: int = 3) -> Everything:
    return Everything(
        header=HEADER,
        count=7,
        small=-5,
        ratio=float("inf"),
        name="é",
        flag=True,
        blob=b"\x00\xff",
        names=("a", "b"),
        vec=(1.0, -2.0, 3.5),
        gains={"k": 0.5},
        totals={"t": 2**40},
        nested={"stage": {"p50": 1.0}},
        boxes=np.arange(4 * n, dtype=np.float32).reshape(n, 4),
        ids=np.arange(n, dtype=np.int64),
        image=np.zeros((5, 3), np.uint8),
    )


def _body(payload: bytes) -> dict[str, Any]:
    body: dict[str, Any] = msgpack.unpackb(payload)["d"]
    return body


def _pack(tag: str, version: object, body: dict[str, Any]) -> bytes:
    out: bytes = msgpack.packb({"v": version, "t": tag, "d": body})
    return out


def test_every_field_kind_round_trips() -> None:
    msg = _everything()
    back = Everything.decode(msg.encode())
    for f in dataclasses.fields(Everything):
        a, b = getattr(msg, f.name), getattr(back, f.name)
        if isinstance(a, np.ndarray):
            assert b.dtype == a.dtype and np.array_equal(a, b)
        else:
            assert a == b, f.name
    body = _body(msg.encode())
    assert body["n"] == 3 and list(body)[list(body).index("boxes") - 1] == "n"
    assert body["boxes"] == msg.boxes.astype("<f4").tobytes()  # raw little-endian bytes


def test_an_optional_array_travels_as_nil() -> None:
    msg = dataclasses.replace(_everything(), ids=None)
    assert Everything.decode(msg.encode()).ids is None
    assert _body(msg.encode())["ids"] is None


@dataclass(frozen=True, slots=True, kw_only=True)
class PingV1(Message):
    TAG: ClassVar[str] = "Ping"
    header: Header
    count: int


@dataclass(frozen=True, slots=True, kw_only=True)
class PingV2(Message):
    """PingV1 plus one field: it is declared here and nowhere else, and it travels."""

    TAG: ClassVar[str] = "Ping"
    VERSION: ClassVar[int] = 2
    header: Header
    count: int
    scores: Annotated[npt.NDArray[np.float32], Shape(-1)] = field(
        default_factory=lambda: np.zeros(0, np.float32)
    )


def test_a_field_declared_once_travels() -> None:
    msg = PingV2(header=HEADER, count=1, scores=np.array([0.5, 0.25], np.float32))
    assert _body(msg.encode())["scores"] == np.array([0.5, 0.25], "<f4").tobytes()
    assert np.array_equal(PingV2.decode(msg.encode()).scores, msg.scores)


def test_an_older_version_without_a_newer_defaulted_field_decodes() -> None:
    old = PingV1(header=HEADER, count=4).encode()
    assert msgpack.unpackb(old)["v"] == 1
    new = PingV2.decode(old)
    assert new.count == 4 and new.scores.shape == (0,)


def test_a_newer_version_is_refused_and_says_so() -> None:
    with pytest.raises(DecodeError, match=r"Ping: schema version 2 is newer than this build"):
        PingV1.decode(PingV2(header=HEADER, count=1).encode())


@dataclass(frozen=True, slots=True, kw_only=True)
class PingV3(Message):
    """Reads v2 and v3 only; upgrades v2's ``count`` to ``counts``."""

    TAG: ClassVar[str] = "Ping"
    VERSION: ClassVar[int] = 3
    OLDEST_VERSION: ClassVar[int] = 2
    header: Header
    counts: tuple[int, ...]

    @classmethod
    def _upgrade(cls, version: int, body: dict[str, Any]) -> dict[str, Any]:
        return {**body, "counts": [body.get("count")]}


def test_upgrade_hook_and_oldest_version() -> None:
    assert PingV3.decode(PingV2(header=HEADER, count=9).encode()).counts == (9,)
    with pytest.raises(DecodeError, match="older than this build reads"):
        PingV3.decode(PingV1(header=HEADER, count=9).encode())
    header = _body(PingV1(header=HEADER, count=9).encode())["header"]
    broken_v2 = _pack("Ping", 2, {"header": header})  # no count to upgrade from
    with pytest.raises(DecodeError, match=r"Ping\.counts"):
        PingV3.decode(broken_v2)


def test_header_fields_added_later_take_their_defaults() -> None:
    body = _body(PingV1(header=HEADER, count=1).encode())
    for key in ("mono_ns", "boot_id"):
        del body["header"][key]
    header = PingV1.decode(_pack("Ping", 1, body)).header
    assert (header.mono_ns, header.boot_id) == (0, "")
    del body["header"]["seq"]  # no default: required
    with pytest.raises(DecodeError, match=r"Ping\.header\.seq: missing"):
        PingV1.decode(_pack("Ping", 1, body))


@pytest.mark.parametrize("version", ["1", 1.0, None, True, -1, 0, 2**63])
def test_versions_that_are_not_known(version: object) -> None:
    body = _body(PingV1(header=HEADER, count=1).encode())
    with pytest.raises(DecodeError, match="schema version"):
        PingV1.decode(_pack("Ping", version, body))


def test_unknown_keys_are_ignored() -> None:
    body = _body(PingV1(header=HEADER, count=1).encode())
    assert PingV1.decode(_pack("Ping", 1, {**body, "from_the_future": [1, 2]})).count == 1


def test_errors_name_the_field_path() -> None:
    good = _body(_everything().encode())
    cases: list[tuple[dict[str, Any], str]] = [
        ({"count": -1}, r"Everything\.count: -1 is outside \[0, None\]"),
        ({"small": 6}, r"Everything\.small: 6 is outside \[-5, 5\]"),
        ({"count": True}, r"Everything\.count: expected int, got bool"),
        ({"n": 101}, r"Everything\.n: 101 is outside \[0, 100\]"),
        ({"n": 2}, r"Everything\.boxes: 12 values do not fit shape \(2, 4\)"),
        ({"boxes": b"\x00" * 5}, r"Everything\.boxes: 5 bytes is not a whole float32 array"),
        ({"image": b"\x00" * 4}, r"Everything\.image: 4 values do not fit shape \(-1, 3\)"),
        ({"vec": [1.0, 2.0]}, r"Everything\.vec: expected list of 3 float, got 2"),
        ({"vec": [1.0, 2.0, float("nan")]}, r"Everything\.vec: .*finite"),
        ({"gains": {"k": float("inf")}}, r"Everything\.gains\.k: expected a finite number"),
        ({"nested": {"s": {"p50": "x"}}}, r"Everything\.nested\.s\.p50: expected float, got str"),
        ({"names": ["a", 1]}, r"Everything\.names: expected list of any number of str"),
        ({"header": {**good["header"], "stamp_ns": "now"}}, r"Everything\.header\.stamp_ns"),
        ({"flag": 1}, r"Everything\.flag: expected bool, got int"),
        ({"blob": "text"}, r"Everything\.blob: expected bytes, got str"),
    ]
    for change, message in cases:
        with pytest.raises(DecodeError, match=message):
            Everything.decode(_pack("Everything", 1, {**good, **change}))


def test_a_field_with_no_wire_format_is_refused_at_first_use() -> None:
    @dataclass(frozen=True, slots=True, kw_only=True)
    class NoShape(Message):
        TAG: ClassVar[str] = "NoShape"
        values: npt.NDArray[np.float32]

    @dataclass(frozen=True, slots=True, kw_only=True)
    class AList(Message):
        TAG: ClassVar[str] = "AList"
        values: list[int]

    with pytest.raises(TypeError, match="Shape"):
        NoShape(values=np.zeros(1, np.float32)).encode()
    with pytest.raises(TypeError, match="no wire format"):
        AList(values=[1]).encode()


@dataclass(frozen=True, slots=True, kw_only=True)
class Pair:
    """A struct that travels inline: its keys sit in the enclosing body."""

    left: Annotated[npt.NDArray[np.float32], Shape(N)] = field(
        default_factory=lambda: np.zeros(0, np.float32)
    )
    label: str = ""
    extra: int | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class WithPair(Message):
    TAG: ClassVar[str] = "WithPair"
    header: Header
    pair: Annotated[Pair, Inline()]
    count: int = 0


def test_an_inline_struct_travels_as_keys_of_the_body_and_comes_back_whole() -> None:
    msg = WithPair(header=HEADER, pair=Pair(left=np.array([1.5, 2.0], np.float32), label="a"))
    body = _body(msg.encode())
    assert set(body) == {"header", "n", "left", "label", "extra", "count"} and body["n"] == 2
    back = WithPair.decode(msg.encode())
    assert np.array_equal(back.pair.left, msg.pair.left) and back.pair.label == "a"
    assert inline_fields(WithPair) == {"pair"} and inline_fields(Pair) == frozenset()


def test_an_inline_struct_s_fields_are_required_and_errors_name_them() -> None:
    good = _body(WithPair(header=HEADER, pair=Pair(label="a")).encode())
    for key in ("left", "label", "n"):
        with pytest.raises(DecodeError, match=rf"WithPair\.{key}: "):
            WithPair.decode(_pack("WithPair", 1, {k: v for k, v in good.items() if k != key}))
    assert WithPair.decode(_pack("WithPair", 1, {**good, "extra": None})).pair.extra is None
    del good["extra"]  # it may be None, so it may be missing
    assert WithPair.decode(_pack("WithPair", 1, good)).pair.extra is None
    with pytest.raises(DecodeError, match=r"WithPair\.left: 2 values do not fit shape \(1,\)"):
        WithPair.decode(_pack("WithPair", 1, {**good, "n": 1, "left": b"\x00" * 8}))


def test_an_inline_struct_whose_keys_clash_is_refused_at_first_use() -> None:
    @dataclass(frozen=True, slots=True, kw_only=True)
    class Clash(Message):
        TAG: ClassVar[str] = "Clash"
        pair: Annotated[Pair, Inline()]
        label: str

    with pytest.raises(TypeError, match=r"\['label'\] would travel twice"):
        Clash(pair=Pair(), label="x").encode()
