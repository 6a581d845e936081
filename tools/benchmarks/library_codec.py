"""Comparison 3 of tools/benchmarks/library_choices.py: the msgpack field walker,
common/fields.py (with common/field_codecs.py) + common/codec.py, against msgspec Structs
decoding the very same bytes: decode time of a Frame, a Detections of 20 boxes and a Twist,
and the error raised for garbage."""

from __future__ import annotations

import argparse
import functools
import math
import sys
from collections.abc import Callable, Iterator
from typing import Annotated, Any, Literal

import msgpack
import numpy as np

from common.boxes import MAX_DETECTIONS, Boxes
from common.clock import mono_ns, wall_ns
from common.codec import Message
from common.errors import DecodeError
from common.messages import (
    FRAME_ENCODINGS,
    MAX_COMMAND,
    MAX_IMAGE_SIDE,
    MAX_NAME_CHARS,
    Detections,
    Frame,
    Header,
    Twist,
)
from tools.benchmarks.library_shared import (
    REPO,
    code_lines,
    missing,
    per_call_us,
    ratio,
    site_size_mb,
)


def build_msgspec_messages() -> dict[str, Any]:
    """msgspec Structs for the envelope and the bodies of Frame, Detections and Twist, reading
    the bytes our codec writes (same keys; unknown keys such as center_size ignored), with our
    bounds as Meta constraints and the array checks in __post_init__ (our check_boxes)."""
    import msgspec
    from msgspec import Meta
    from msgspec.structs import force_setattr

    from common.boxes import check_boxes

    NonNeg = Annotated[int, Meta(ge=0)]
    Side = Annotated[int, Meta(gt=0, le=MAX_IMAGE_SIDE)]
    Name = Annotated[str, Meta(max_length=MAX_NAME_CHARS)]
    LongName = Annotated[str, Meta(max_length=2 * MAX_NAME_CHARS)]
    Finite = Annotated[float, Meta(ge=-sys.float_info.max, le=sys.float_info.max)]
    Cmd = Annotated[float, Meta(ge=-MAX_COMMAND, le=MAX_COMMAND)]
    Count = Annotated[int, Meta(ge=0, le=MAX_DETECTIONS)]
    Version = Annotated[int, Meta(ge=1, le=1)]
    encodings = Literal[tuple(FRAME_ENCODINGS)]  # type: ignore[valid-type]

    # defstruct, not class statements: this module's annotations are strings (PEP 563), which
    # msgspec cannot resolve for classes local to a function.
    def struct(name: str, fields: list[tuple[Any, ...]], **namespace: Any) -> Any:
        return msgspec.defstruct(name, fields, frozen=True, kw_only=True, namespace=namespace)

    header = struct(
        "MHeader",
        [
            ("stamp_ns", NonNeg),
            ("frame_id", str),
            ("seq", NonNeg),
            ("source", str),
            ("mono_ns", NonNeg, 0),
            ("boot_id", str, ""),
        ],
    )

    def frame_checks(self: Any) -> None:
        channels = FRAME_ENCODINGS[self.encoding]
        if channels and len(self.data) != self.width * self.height * channels:
            raise ValueError(
                f"{self.encoding} {self.width}x{self.height} needs "
                f"{self.width * self.height * channels} bytes"
            )
        if not channels and not self.data:
            raise ValueError("empty jpeg")

    frame = struct(
        "MFrame",
        [
            ("header", header),
            ("encoding", encodings),
            ("width", Side),
            ("height", Side),
            ("data", bytes),
        ],
        __post_init__=frame_checks,
    )

    def array(raw: bytes, dtype: str, shape: tuple[int, ...]) -> Any:
        flat = np.frombuffer(raw, dtype=dtype)
        if flat.size != math.prod(shape):
            raise ValueError(f"{flat.size} values do not fit shape {shape}")
        return flat.reshape(shape)

    def detections_checks(self: Any) -> None:
        n = self.n
        arrays = {
            "xyxy": array(self.xyxy, "<f4", (n, 4)),
            "scores": array(self.scores, "<f4", (n,)),
            "class_ids": array(self.class_ids, "<i4", (n,)),
        }
        if self.track_ids is not None:
            arrays["track_ids"] = array(self.track_ids, "<i4", (n,))
        check_boxes(arrays["xyxy"], arrays["scores"], arrays["class_ids"], arrays.get("track_ids"))
        if len(self.class_names) != n:
            raise ValueError(f"class_names must have {n} entries")
        for k, v in arrays.items():
            force_setattr(self, k, v)

    detections = struct(
        "MDetections",
        [
            ("header", header),
            ("image_width", Side),
            ("image_height", Side),
            ("n", Count),
            ("class_ids", bytes),
            ("class_names", tuple[Name, ...]),
            ("scores", bytes),
            ("xyxy", bytes),
            ("track_ids", bytes | None, None),
            ("timing_ms", dict[str, Finite], msgspec.field(default_factory=dict)),
            ("model", LongName, ""),
            ("backend", LongName, ""),
            ("received_ns", NonNeg, 0),
            ("published_ns", NonNeg, 0),
        ],
        __post_init__=detections_checks,
    )
    zero = (0.0, 0.0, 0.0)
    twist = struct(
        "MTwist",
        [
            ("header", header),
            ("linear", tuple[Cmd, Cmd, Cmd], zero),
            ("angular", tuple[Cmd, Cmd, Cmd], zero),
            ("input_stamp_ns", NonNeg, 0),
        ],
    )

    def envelope(tag: str, body: Any) -> Any:
        return msgspec.defstruct(
            f"{tag}Envelope", [("v", Version), ("t", Literal[tag]), ("d", body)]
        )

    return {
        "Frame": msgspec.msgpack.Decoder(envelope("Frame", frame)),
        "Detections": msgspec.msgpack.Decoder(envelope("Detections", detections)),
        "Twist": msgspec.msgpack.Decoder(envelope("Twist", twist)),
    }


def sample_messages() -> dict[str, bytes]:
    """Encoded by our codec: a rendered 640x480 scene as JPEG and raw bgr8, 20 boxes, a Twist."""
    import cv2

    from simworld.render import CameraSpec, render
    from simworld.scenarios import SCENARIOS

    world = SCENARIOS["two_people"].build()
    world.t = 10.0
    image = render(world, CameraSpec())
    header = Header(
        stamp_ns=wall_ns(),
        frame_id="camera",
        seq=7,
        source="camera",
        mono_ns=mono_ns(),
        boot_id="b" * 36,
    )
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 80])
    assert ok
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 600, (20, 2)).astype(np.float32)
    wh = rng.uniform(5, 40, (20, 2)).astype(np.float32)
    dets = Detections(
        header=header,
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.hstack([xy, xy + wh]),
            class_ids=rng.integers(0, 80, 20).astype(np.int32),
            scores=rng.uniform(0.25, 1, 20).astype(np.float32),
            track_ids=np.arange(20, dtype=np.int32),
        ),
        class_names=("person",) * 20,
        timing_ms={"preprocess": 1.5, "inference": 80.0, "postprocess": 2.0},
        model="yolov5s-coco.onnx",
        backend="onnx",
        received_ns=header.stamp_ns + 1,
        published_ns=header.stamp_ns + 2,
    )
    return {
        "Frame jpeg": Frame(
            header=header, encoding="jpeg", width=640, height=480, data=jpeg.tobytes()
        ).encode(),
        "Frame bgr8": Frame(
            header=header, encoding="bgr8", width=640, height=480, data=image.tobytes()
        ).encode(),
        "Detections": dets.encode(),
        "Twist": Twist(
            header=header,
            linear=(0.3, 0.0, 0.0),
            angular=(0.0, 0.0, -0.4),
            input_stamp_ns=header.stamp_ns,
        ).encode(),
    }


def _edit(payload: bytes, change: Callable[[dict[str, Any]], None]) -> bytes:
    env = msgpack.unpackb(payload, raw=False)
    change(env)
    out = msgpack.packb(env, use_bin_type=True)
    assert isinstance(out, bytes)
    return out


def garbage_cases(msgs: dict[str, bytes]) -> Iterator[tuple[str, str, bytes]]:
    """(what, message type, payload): each must be refused by a decoder of that type."""
    frame, dets, twist = msgs["Frame jpeg"], msgs["Detections"], msgs["Twist"]
    rng = np.random.default_rng(1)

    def setk(*path: str, value: Any) -> Callable[[dict[str, Any]], None]:
        def change(env: dict[str, Any]) -> None:
            node = env
            for p in path[:-1]:
                node = node[p]
            node[path[-1]] = value

        return change

    nan_box = np.frombuffer(msgpack.unpackb(dets)["d"]["xyxy"], "<f4").copy()
    nan_box[2] = np.nan
    yield "truncated (first half)", "Frame", frame[: len(frame) // 2]
    yield "random bytes", "Twist", rng.integers(0, 256, 64, dtype=np.uint8).tobytes()
    yield "empty payload", "Twist", b""
    yield "not a map (a list)", "Twist", msgpack.packb([1, 2, 3])
    yield "deep nesting (100k arrays)", "Twist", b"\x91" * 100_000 + b"\xc0"
    yield "wrong tag (a Twist read as Frame)", "Frame", twist
    yield "newer schema version v=2", "Twist", _edit(twist, setk("v", value=2))
    yield "missing field (Frame without data)", "Frame", _edit(frame, lambda e: e["d"].pop("data"))
    yield "wrong type: width '640'", "Frame", _edit(frame, setk("d", "width", value="640"))
    yield (
        "wrong type: header.seq true",
        "Twist",
        _edit(twist, setk("d", "header", "seq", value=True)),
    )
    yield (
        "wrong type: xyxy as a list",
        "Detections",
        _edit(dets, setk("d", "xyxy", value=[1.0] * 80)),
    )
    yield "negative stamp", "Twist", _edit(twist, setk("d", "header", "stamp_ns", value=-1))
    yield "NaN in linear.x", "Twist", _edit(twist, setk("d", "linear", value=[math.nan, 0.0, 0.0]))
    yield (
        "inf in timing_ms",
        "Detections",
        _edit(dets, setk("d", "timing_ms", value={"x": math.inf})),
    )
    yield "NaN in a box", "Detections", _edit(dets, setk("d", "xyxy", value=nan_box.tobytes()))
    yield (
        "linear.x 1e308 (over 100)",
        "Twist",
        _edit(twist, setk("d", "linear", value=[1e308, 0.0, 0.0])),
    )
    yield (
        "class name of 200 chars",
        "Detections",
        _edit(dets, setk("d", "class_names", value=["x" * 200] * 20)),
    )
    yield "count 21 for 20 boxes", "Detections", _edit(dets, setk("d", "n", value=21))
    yield "count 10**9", "Detections", _edit(dets, setk("d", "n", value=10**9))
    yield "image 0 x 480", "Frame", _edit(frame, setk("d", "width", value=0))
    yield (
        "bgr8 with too few bytes",
        "Frame",
        _edit(msgs["Frame bgr8"], setk("d", "data", value=b"\x00" * 100)),
    )


def codec_section(args: argparse.Namespace) -> None:
    print("\n== 3. msgpack field walker: common/fields.py + codec.py vs msgspec Structs ==")
    ours: dict[str, type[Message]] = {"Frame": Frame, "Detections": Detections, "Twist": Twist}
    msgs = sample_messages()
    try:
        import msgspec

        theirs: dict[str, Any] | None = build_msgspec_messages()
        version = msgspec.__version__
    except ImportError:
        theirs = None
        missing("msgspec", "msgspec comparison")
    env = msgpack.unpackb(msgs["Twist"], raw=False)
    print(
        f"  our envelope: v={env['v']} (schema version per type), t={env['t']!r}, d=body; "
        "every message writes its VERSION"
    )
    print(f"  decode + validate, per message{f' (msgspec {version})' if theirs else ''}:")
    for label, payload in msgs.items():
        kind = label.split()[0]
        our_us = per_call_us(functools.partial(ours[kind].decode, payload))
        line = f"    {label:<11} {len(payload):>7} B   ours {our_us:>7.1f} us"
        if theirs is not None:
            dec = theirs[kind]
            their_us = per_call_us(functools.partial(dec.decode, payload))
            line += f"   msgspec {their_us:>7.1f} us   ours/msgspec {ratio(our_us, their_us)}"
        print(line)
    enc_us = per_call_us(lambda: Detections.decode(msgs["Detections"]).encode())
    print(f"    (ours, Detections decode + encode: {enc_us:.1f} us)")
    if theirs is not None:
        same = []
        for label, payload in msgs.items():
            kind = label.split()[0]
            a: Any = ours[kind].decode(payload)
            b = theirs[kind].decode(payload).d
            same.append(a.header.stamp_ns == b.header.stamp_ns and a.header.seq == b.header.seq)
            if kind == "Detections":
                same.append(
                    all(
                        np.array_equal(getattr(a.boxes, k), getattr(b, k))
                        for k in ("xyxy", "scores", "class_ids", "track_ids")
                    )
                    and tuple(a.class_names) == tuple(b.class_names)
                )
            if kind == "Frame":
                same.append(a.data == b.data)
            if kind == "Twist":
                same.append(a.linear == b.linear and a.angular == b.angular)
        print(
            f"  wire: msgspec Structs decode the bytes our codec writes, same values: {all(same)}"
        )
    print("  garbage (each must be refused with one typed error):")
    ok_ours = ok_theirs = n = 0
    for what, kind, payload in garbage_cases(msgs):
        n += 1
        try:
            ours[kind].decode(payload)
            r1 = "ACCEPTED"
        except DecodeError as exc:
            ok_ours += 1
            r1 = f"DecodeError: {str(exc)[:60]}"
        except Exception as exc:  # shown: anything but DecodeError is a failure of ours
            r1 = f"UNTYPED {type(exc).__name__}: {str(exc)[:50]}"
        line = f"    {what:<34} ours: {r1:<75}"
        if theirs is not None:
            try:
                theirs[kind].decode(payload)
                r2 = "ACCEPTED"
            except msgspec.DecodeError as exc:  # ValidationError is a DecodeError
                ok_theirs += 1
                r2 = f"{type(exc).__name__}: {str(exc)[:60]}"
            except Exception as exc:  # shown: anything else escapes one except clause
                r2 = f"UNTYPED {type(exc).__name__}: {str(exc)[:50]}"
            line += f" msgspec: {r2}"
        print(line)
    print(
        f"  refused with the one typed error: ours {ok_ours}/{n}"
        + (f", msgspec {ok_theirs}/{n} (msgspec.DecodeError / ValidationError)" if theirs else "")
    )
    size = site_size_mb(["msgspec"])
    if size is not None:
        print(
            f"  dependency size: msgspec {size:.1f} MB installed (msgpack, which we use now: "
            f"{site_size_mb(['msgpack']) or 0:.1f} MB)"
        )
    lib = REPO / "common"
    print(
        f"  lines: common/fields.py {code_lines(lib / 'fields.py')}, common/field_codecs.py "
        f"{code_lines(lib / 'field_codecs.py')}, common/codec.py "
        f"{code_lines(lib / 'codec.py')}"
    )
