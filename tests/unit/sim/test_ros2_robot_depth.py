"""The simulator as a ROS 2 robot with an RGB-D camera: the depth image and its CameraInfo it
publishes (rosmsg/depth.py's ``depth_to_image`` and ``camera_info_of``) read back by the
bridge's own depth handler (``DepthInbound``) as the DepthFrame the simulator rendered."""

from __future__ import annotations

import numpy as np
import pytest

from common.messages import DepthFrame, Header
from common.node import Tally
from rosmsg.convert import cdr_encode
from rosmsg.depth import CAMERA_INFO, camera_info_of, depth_to_image
from rosmsg.distro import RosDistro
from rosmsg.images import IMAGE
from services.ros2 import contract
from services.ros2.depth_handlers import DepthInbound
from simworld.depth import DepthNoise, depth_frame
from simworld.render import CameraSpec
from stack.config import Config

STAMP_NS = 1_700_000_000_123_456_789


def _sim_depth(encoding: str = "16UC1") -> DepthFrame:
    """A depth image as the simulator renders one: 16UC1 mm with holes (0), its intrinsics."""
    spec = CameraSpec(40, 30, 70.0, 0.6, 0.0)
    rng = np.random.default_rng(3)
    metres = rng.uniform(0.3, 9.0, (spec.height, spec.width)).astype(np.float32)
    metres[rng.random(metres.shape) < 0.1] = np.nan
    header = Header(stamp_ns=STAMP_NS, frame_id="front_cam", seq=7, source="sim")
    frame = depth_frame(metres, spec, header, DepthNoise(range_min_m=0.3, range_max_m=10.0))
    if encoding == "32FC1":
        mm = np.frombuffer(frame.data, "<u2").astype(np.float32)
        metres_out = (mm / 1000.0).astype("<f4")
        return DepthFrame(
            header=header, encoding="32FC1", width=frame.width, height=frame.height,
            data=metres_out.tobytes(), fx=frame.fx, fy=frame.fy, cx=frame.cx, cy=frame.cy,
        )  # fmt: skip
    return frame


class Puts(list[bytes]):
    def put(self, payload: bytes) -> None:
        self.append(payload)


@pytest.mark.parametrize("distro", list(RosDistro))
@pytest.mark.parametrize("encoding", ["16UC1", "32FC1"])
def test_the_bridge_reads_the_sim_robots_depth_back_as_it_was_rendered(
    distro: RosDistro, encoding: str
) -> None:
    sent = _sim_depth(encoding)
    tally = Tally("ros2", Config())
    out = Puts()
    inbound = DepthInbound(Config(), tally, out.put, depth_topic="/d", info_topic="/i")
    inbound.on_info("i", memoryview(cdr_encode(distro, CAMERA_INFO, camera_info_of(distro, sent))))
    inbound.on_depth("d", memoryview(cdr_encode(distro, IMAGE, depth_to_image(distro, sent))))
    assert tally.counters.get(contract.DEPTH_INFO_IN) == 1
    assert tally.counters.get(contract.DEPTH_OUT) == 1, tally.counters
    got = DepthFrame.decode(out[0])
    assert (got.encoding, got.width, got.height) == (encoding, sent.width, sent.height)
    assert (got.fx, got.fy, got.cx, got.cy) == (sent.fx, sent.fy, sent.cx, sent.cy)
    # The colour image's stamp and frame id: what the bridge's colour frame gets too.
    assert (got.header.stamp_ns, got.header.frame_id) == (STAMP_NS, "front_cam")
    assert got.data == sent.data  # holes (0 mm) included


def test_the_camera_info_is_a_plain_pinhole_camera() -> None:
    sent = _sim_depth()
    info = camera_info_of(RosDistro.JAZZY, sent)
    k = info.k.reshape(3, 3)
    assert k.tolist() == [[sent.fx, 0, sent.cx], [0, sent.fy, sent.cy], [0, 0, 1]]
    assert info.p.reshape(3, 4)[:, :3].tolist() == k.tolist()
    assert (info.width, info.height, info.distortion_model) == (40, 30, "plumb_bob")
    assert not info.d.any()
    assert info.header.frame_id == "front_cam"
    assert info.header.stamp.sec * 10**9 + info.header.stamp.nanosec == STAMP_NS


def test_a_ros2_scenario_of_a_depth_robot_takes_its_depth_through_the_bridge() -> None:
    # python -m tools.scenarios scenario ahead --ros2 --config deploy/depth.toml
    from services.sim.contract import SimSettings
    from simworld.scenarios import SCENARIOS
    from tools.scenarios.runner import config_changes, scenario_config

    base = Config(sim=SimSettings(depth=True, laser=False, camera_height_m=0.7))
    config = scenario_config(base, SCENARIOS["ahead"], ros2=True)
    assert config.ros2.depth_in and config.sim.ros2_robot
    assert config.camera.mount_height_m == 0.7  # announced by the bridge: the floor comes out
    lines = config_changes(base, config, SCENARIOS["ahead"])
    assert any(line.startswith("ros2.depth_in: false -> true") for line in lines), lines
    # Without depth, or not over ROS 2, nothing of it changes.
    for plain in (scenario_config(Config(), SCENARIOS["ahead"], ros2=True),
                  scenario_config(base, SCENARIOS["ahead"])):  # fmt: skip
        assert not plain.ros2.depth_in and plain.camera.mount_height_m == 0.0
