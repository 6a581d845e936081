"""``sim.world`` (services/sim/worlds.py): "hard" runs the newer camera faults with their
settings, "simple" is today's world and camera whatever those settings say, and the
simulator's log says which in one line."""

from __future__ import annotations

import dataclasses
import logging
import threading
from typing import Any

import numpy as np
import pytest

from common.bus import Sample
from common.errors import ConfigError
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import DepthFrame
from perception.depth import depth_metres
from services.camera.contract import CameraSettings
from services.sim.cameras import sim_cameras
from services.sim.contract import SIMPLE_FAULTS, SimSettings, SimWorld
from services.sim.service import run
from services.sim.worlds import Faults, depth_noise, parse_world_line, world_for, world_line
from simworld.depth import DepthNoise, apply, render_depth
from simworld.render import render
from simworld.scenarios import SCENARIOS
from stack.config import Config
from tests.polling import wait_for


def _config(**sim: Any) -> Config:
    return Config(
        camera=CameraSettings(frame_id="front_cam"),
        sim=SimSettings(width=160, height=120, camera_rate_hz=10.0, **sim),
    )


def test_the_world_is_hard_by_default_and_one_of_two() -> None:
    assert SimSettings().world is SimWorld.HARD
    assert SimSettings(world="simple").world is SimWorld.SIMPLE  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"sim\.world must be one of hard, simple, got 'easy'"):
        SimSettings(world="easy")  # type: ignore[arg-type]


def test_simple_ignores_every_newer_fault_setting_and_keeps_the_older_ones() -> None:
    hard_settings = SimSettings(depth_bias_k=0.01, depth_flying_share=1.0, depth_mirror_scale=5.0)
    simple = dataclasses.replace(hard_settings, world=SimWorld.SIMPLE, depth_noise_k=0.002)
    assert depth_noise(simple) == DepthNoise(noise_k=0.002)
    # With the defaults, simple is today's camera exactly: DepthNoise()'s every field.
    assert depth_noise(SimSettings(world=SimWorld.SIMPLE)) == DepthNoise()
    hard = depth_noise(hard_settings)
    assert (hard.bias_k, hard.flying_share, hard.mirror_scale) == (0.01, 1.0, 5.0)
    assert set(SIMPLE_FAULTS) <= {f.name for f in dataclasses.fields(SimSettings)}


def test_the_world_line_says_which_world_and_faults_run_and_parses_back() -> None:
    hard = world_line(SimSettings(depth=True))
    assert hard.startswith("world=hard faults=depth_bias_k:0.0025,depth_flying_share:0.5,")
    assert parse_world_line(f"12:00:01 INFO sim: {hard}") == (
        "hard",
        {
            "depth_bias_k": 0.0025,
            "depth_flying_share": 0.5,
            "depth_mirror_scale": 2.0,
            "depth_noise_in_disparity": 1.0,  # on: true, said as 1
            "colour_exposure_ms": 20.0,
            "colour_light_change": 0.3,
            "colour_drift": 0.05,
        },
    )
    # Without a depth camera its faults do not run; a fault set off is not listed.
    line = world_line(SimSettings(colour_drift=0.0))
    assert parse_world_line(line) == (
        "hard",
        {"colour_exposure_ms": 20.0, "colour_light_change": 0.3},
    )
    simple = world_line(SimSettings(world=SimWorld.SIMPLE, depth=True, depth_bias_k=0.01))
    assert simple == "world=simple faults=none"
    assert parse_world_line(simple) == ("simple", {})
    assert parse_world_line("scenario 'demo': a person") is None


def test_simple_runs_today_s_cameras_bit_for_bit() -> None:
    """The service's depth and colour in "simple": what it did before the newer faults
    (``apply`` with ``DepthNoise()`` on the stream ``[seed, 1]``; the rendered image itself)."""
    config = _config(depth=True, world=SimWorld.SIMPLE, seed=4)
    camera = sim_cameras(config)[0]
    world = world_for(config.sim, SCENARIOS["demo"].build())
    world.robot.w = 1.5  # turning: no blur in the simple world
    faults = Faults(config.sim, [camera])
    before = np.random.default_rng([4, 1])
    for t in (0.0, 0.1, 0.2):
        image = render(world, camera.spec)
        assert faults.colour(camera, image, world, t) is image
        got = faults.depth_image(camera, image, world)
        expected = apply(render_depth(world, camera.spec), image, DepthNoise(), before)
        np.testing.assert_array_equal(got, expected)


def test_hard_blurs_a_turning_robot_s_image_and_repeats_with_the_seed() -> None:
    config = _config(depth=True, seed=4)
    camera = sim_cameras(config)[0]
    world = SCENARIOS["demo"].build()

    def frames(seed: int, w: float) -> list[np.ndarray]:
        faults = Faults(dataclasses.replace(config.sim, seed=seed), [camera])
        out: list[np.ndarray] = []
        world.robot.w = w
        for t in (0.0, 0.1, 0.2):
            image = render(world, camera.spec)
            out.append(faults.colour(camera, image, world, t))
            out.append(faults.depth_image(camera, image, world))
        return out

    def edges(image: np.ndarray) -> int:
        return int(np.abs(np.diff(image.astype(int), axis=1)).sum())

    still, turning = frames(4, 0.0), frames(4, 1.5)
    sharp = render(world, camera.spec)
    assert edges(turning[0]) < 0.7 * edges(sharp) < edges(still[0])  # 1.5 rad/s: 4 px
    for a, b in zip(frames(4, 0.0), still, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(frames(5, 0.0)[1], still[1], equal_nan=True)


def test_the_simulator_logs_its_world_and_runs_hard_depth(caplog: pytest.LogCaptureFixture) -> None:
    """In-process on a MemoryHub: the start-up line, and the hard camera's depth of the demo's
    person (the world stands still: no detector comes) against the truth plus the range bias
    (0.94 % at 3.75 m; the noise is 7 cm a pixel there, so several frames' medians)."""
    config = _config(depth=True, camera_height_m=0.7)
    keys = Keys(config.stack.prefix)
    hub, got = MemoryHub(), list[Sample]()
    hub.join("watcher").subscribe(keys.depth(config.stack.camera), got.append)
    stop = threading.Event()
    sim = threading.Thread(target=run, args=(config, stop), kwargs={"bus": hub.join("sim")})
    with caplog.at_level(logging.INFO, logger="sim"):
        sim.start()
        try:
            wait_for(lambda: len(got) >= 8, 20, "eight depth images")
        finally:
            stop.set()
            sim.join(20)
    assert not sim.is_alive()
    lines = [parse_world_line(r.getMessage()) for r in caplog.records if r.name == "sim"]
    assert [p[0] for p in lines if p is not None] == ["hard"]
    region = np.s_[45:60, 75:85]
    world = world_for(config.sim, SCENARIOS["demo"].build())
    truth = render_depth(world, sim_cameras(config)[0].spec)[region]
    # The person's body (the floor may show through a gap at the region's edge).
    assert np.isfinite(truth).mean() > 0.9 and np.nanmedian(truth) == pytest.approx(3.75, rel=0.05)
    k = depth_noise(config.sim).bias_k
    medians = [np.nanmedian(depth_metres(DepthFrame.decode(s.payload))[region]) for s in got[-8:]]
    assert np.mean(medians) == pytest.approx(np.nanmedian(truth + k * truth**2), rel=0.02)
