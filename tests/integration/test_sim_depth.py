"""The simulator as a real process playing an RGB-D robot with no laser (``sim.depth = true``,
``sim.laser = false``): every camera's depth images come over Zenoh under their colour frames'
headers, a target's depth in its box is the simulator's truth, and no scan comes at all."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from common.messages import DepthFrame, Frame, GroundTruth
from perception.depth import depth_metres
from services.sim.cameras import sim_cameras
from services.sim.worlds import depth_noise, world_for
from simworld.depth import render_depth, targets_in_camera
from simworld.render import layout
from simworld.scenarios import SCENARIOS
from tests.integration.conftest import Stack
from tests.polling import wait_for

FRAMES = 10  # per camera: at 5 Hz, 2 s in which a laser would have put 20 scans


def test_an_rgbd_robot_with_no_laser_puts_depth_with_each_frame_and_no_scan(
    make_stack: Callable[..., Stack],
) -> None:
    stack = make_stack(
        supervisor={"services": ["sim"]},
        # No detector runs: the world stands still at t = 0 (services/sim/service.py), so the
        # truth is the scenario's start, whatever the time the frames take to come.
        sim={"scenario": "demo", "depth": True, "laser": False, "wait_for": ["detector"]},
        **{"cameras.rear": {"mount_yaw_deg": 180.0, "frame_id": "rear", "resize": [320, 240]}},
    )
    keys, cameras = stack.keys, sim_cameras(stack.config)
    subs = {
        name: (stack.subscribe(keys.frame(name)), stack.subscribe(keys.depth(name)))
        for name in ("front", "rear")
    }
    _scan_sub, scans = stack.subscribe(keys.scan())
    _truth_sub, truths = stack.subscribe(keys.sim_truth())
    stack.wait_ready({"sim"})
    wait_for(
        lambda: all(len(d[1]) >= FRAMES for _, d in subs.values()),
        60,
        lambda: f"{FRAMES} depth images of each camera:\n{stack.log()}",
    )
    assert scans == []
    truth = GroundTruth.decode(truths[-1])
    assert truth.robot == (0.0, 0.0, 0.0) and truth.sim_time_s == 0.0

    for cam in cameras:
        (_, colour), (_, depth) = subs[cam.name]
        headers = {Frame.decode(p).header for p in list(colour)}
        frames = [DepthFrame.decode(p) for p in list(depth)]
        # Each depth image under the header of a colour frame (a frame may be in flight).
        assert sum(f.header in headers for f in frames) >= len(frames) - 1
        assert {(f.width, f.height) for f in frames} == {(cam.spec.width, cam.spec.height)}

    # The demo's person stands 4 m ahead of the front camera: the middle half of their box
    # reads their distance, as the simulator's truth says, plus the hard world's range bias
    # (sim.depth_bias_k z^2: 0.94 % at 3.75 m; the median takes out the zero-mean noise).
    front = cameras[0]
    world = SCENARIOS["demo"].build()
    ((_, name, _, _, z),) = targets_in_camera(world, front.spec)
    (placed,) = [p for p in layout(world, front.spec) if p.target is not None]
    assert placed.rect is not None and name == "person"
    x0, y0, x1, y1 = placed.rect
    qx, qy = (x1 - x0) // 4, (y1 - y0) // 4
    got = depth_metres(DepthFrame.decode(subs["front"][1][1][-1]))[
        y0 + qy : y1 - qy, x0 + qx : x1 - qx
    ]
    assert np.isfinite(got).mean() > 0.3
    bias_k = depth_noise(stack.config.sim).bias_k
    assert bias_k > 0  # the hard world, the default
    # Against the true depth of the same pixels (a body's surface is rounded: the middle of
    # its box reads farther than its front, z), plus the bias.
    truth = render_depth(world_for(stack.config.sim, world), front.spec)[
        y0 + qy : y1 - qy, x0 + qx : x1 - qx
    ]
    want = float(np.nanmedian(truth + bias_k * truth * truth))
    assert z < want and float(np.nanmedian(got)) == pytest.approx(want, rel=0.01)
    assert stack.stop() == 0
