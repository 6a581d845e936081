"""Which image the viewer sends, the settings' bounds, and the shipped Foxglove layout."""

from __future__ import annotations

import json

import pytest

from common.boxes import Boxes
from common.errors import ConfigError
from common.messages import Detections, Frame, Header
from common.settings import DEFAULT_CONFIG
from services.viewer import channels, layout
from services.viewer.contract import ViewerSettings
from services.viewer.pairing import Pairing
from stack.config_file import load_config


def _frame(stamp_ns: int) -> Frame:
    header = Header(stamp_ns=stamp_ns, frame_id="camera", seq=stamp_ns, source="sim")
    return Frame(header=header, encoding="mono8", width=4, height=2, data=bytes(8))


def _dets(stamp_ns: int) -> Detections:
    header = Header(stamp_ns=stamp_ns, frame_id="camera", seq=stamp_ns, source="sim")
    return Detections(
        header=header,
        image_width=4,
        image_height=2,
        boxes=Boxes(),
        class_names=(),
    )


def test_a_frame_goes_out_with_the_detections_made_on_it() -> None:
    p = Pairing(unpaired_after_s=1.0)
    for stamp in (1, 2, 3):
        p.add_frame(_frame(stamp))
    assert p.add_detections(_dets(2), now=10.0)
    frame, dets = p.take(now=10.1) or (None, None)
    assert frame is not None and dets is not None
    assert frame.header.stamp_ns == dets.header.stamp_ns == 2
    assert p.take(now=10.2) is None  # frame 3 waits for its detections
    assert not p.add_detections(_dets(1), now=10.3)  # already gone with frame 2
    assert p.add_detections(_dets(3), now=10.4)
    p.add_frame(_frame(4))
    assert p.add_detections(_dets(4), now=10.5)  # replaces the pair of 3, not taken
    assert p.dropped == 1
    taken = p.take(now=10.6)
    assert taken is not None and taken[0].header.stamp_ns == 4


def test_without_a_detector_the_newest_frame_goes_out_alone() -> None:
    p = Pairing(unpaired_after_s=1.0)
    p.add_frame(_frame(1))
    p.add_frame(_frame(2))
    taken = p.take(now=100.0)
    assert taken is not None and taken[0].header.stamp_ns == 2 and taken[1] is None
    assert p.take(now=100.1) is None  # nothing new
    p.add_detections(_dets(9), now=100.2)  # a detector has started
    p.add_frame(_frame(3))
    assert p.take(now=100.3) is None  # frame 3 waits for its detections now


@pytest.mark.parametrize(
    "field, value",
    [("port", 0), ("port", 70000), ("jpeg_quality", 0), ("jpeg_quality", 101),
     ("image_rate_hz", 0.0), ("image_rate_hz", 100.0), ("max_image_width", 10),
     ("metrics_rate_hz", -1.0), ("scene_rate_hz", 0.0), ("path_points", 1), ("host", "")],
)  # fmt: skip
def test_viewer_settings_are_bounded(field: str, value: object) -> None:
    with pytest.raises(ConfigError, match=f"viewer.{field}"):
        ViewerSettings(**{field: value})  # type: ignore[arg-type]


def test_the_default_stack_runs_the_viewer_on_loopback() -> None:
    cfg = load_config(DEFAULT_CONFIG, environ={})
    assert cfg.supervisor.services[-1] == "viewer"
    assert (cfg.viewer.host, cfg.viewer.port) == ("127.0.0.1", 8766)


def test_the_shipped_layout_is_the_one_built_here() -> None:
    assert layout.LAYOUT_FILE.read_text() == layout.layout_json(), (
        "run `python -m services.viewer layout` and commit deploy/foxglove/layout.json"
    )
    text = json.dumps(json.loads(layout.layout_json()))
    for topic in (channels.IMAGE, channels.ANNOTATIONS, channels.SCAN, channels.SCENE,
                  channels.CMD_VEL, channels.CONTROLLER, channels.METRICS, "/camera/depth",
                  channels.BOXES_3D, f"{channels.METRICS}.latency_ms.depth.p50"):  # fmt: skip
        assert f'"{topic}' in text, topic


def test_a_port_in_use_is_one_config_error() -> None:
    import socket

    from services.viewer.service import start_front
    from stack.config import Config

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        config = Config(viewer=ViewerSettings(port=port))
        with pytest.raises(ConfigError, match=f"viewer.port: cannot listen on 127.0.0.1:{port}"):
            start_front(config, inner_port=1)


def test_each_camera_has_its_own_topics_the_first_keeps_the_one_camera_ones() -> None:
    assert channels.camera_topics("front", "front") == (channels.IMAGE, channels.ANNOTATIONS)
    assert channels.camera_topics("front", "rear") == (
        "/camera/rear/image",
        "/camera/rear/annotations",
    )


def test_the_layout_shows_an_image_and_a_depth_panel_per_camera() -> None:
    assert layout.layout_json(["rear"]) == layout.layout_json()  # one camera: the shipped one
    built = json.loads(layout.layout_json(["front", "rear"]))

    def panels(node: object) -> list[dict[str, object]]:
        if isinstance(node, dict):
            here = [node] if node.get("panelType") == "Image" else []
            return here + [p for v in node.values() for p in panels(v)]
        if isinstance(node, list):
            return [p for v in node for p in panels(v)]
        return []

    modes = [p["config"]["imageMode"] for p in panels(built)]  # type: ignore[index]
    assert [(m["imageTopic"], list(m.get("annotations") or [])) for m in modes] == [
        (channels.IMAGE, [channels.ANNOTATIONS]),
        ("/camera/depth", []),
        ("/camera/rear/image", ["/camera/rear/annotations"]),
        ("/camera/rear/depth", []),
    ]
    depth = modes[1]
    assert (depth["colorMode"], depth["colorMap"]) == ("colormap", "turbo")
    assert (depth["minValue"], depth["maxValue"]) == (0.0, layout.DEPTH_SHOWN_MAX_MM)
    # Without depth: the image panels alone, as before depth.
    bare = json.loads(layout.layout_json(["front", "rear"], depth=False))
    assert [p["config"]["imageMode"]["imageTopic"] for p in panels(bare)] == [  # type: ignore[index]
        channels.IMAGE,
        "/camera/rear/image",
    ]
