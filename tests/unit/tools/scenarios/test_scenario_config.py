"""The config a scenario runs with: its own further cameras and detector changes (pure)."""

from __future__ import annotations

import dataclasses

from common.contracts import DistanceSource
from common.settings import REPO_ROOT
from services.camera.contract import CameraSettings
from services.controller.contract import ControllerSettings
from services.detector.contract import DetectorSettings
from services.sim.cameras import sim_cameras
from simworld.scenarios import SCENARIOS
from stack.config import Config
from stack.config_file import load_config
from tools.scenarios.runner import config_changes, scenario_config

BASE = Config(
    camera=CameraSettings(hfov_deg=70.0, rate_hz=8.0),
    # By box height (the default is the laser, as deploy/stack.toml): "behind" changes it.
    controller=ControllerSettings(distance_source=DistanceSource.BOX),
    cameras=(("left", CameraSettings(mount_yaw_deg=90.0)),),
    detector=DetectorSettings(conf=0.3),
)


def test_behind_adds_its_rear_camera_over_the_base_camera() -> None:
    config = scenario_config(BASE, SCENARIOS["behind"])
    assert list(config.all_cameras) == ["front", "rear"]  # the base's "left" is not the world's
    rear = config.camera_settings("rear")
    assert (rear.mount_yaw_deg, rear.frame_id) == (180.0, "camera_rear")
    # What the scenario leaves alone comes from [camera]; the rate too, so the simulator
    # renders the rear camera at the first camera's rate.
    assert (rear.hfov_deg, rear.rate_hz) == (70.0, config.camera.rate_hz)
    rates = {c.name: c.rate_hz for c in sim_cameras(config)}
    assert rates == {"front": config.sim.camera_rate_hz, "rear": config.sim.camera_rate_hz}
    assert (config.detector.imgsz, config.detector.conf) == (320, 0.3)
    assert config.supervisor.services[0] == "sim" and "camera" not in config.supervisor.services


def test_other_scenarios_see_through_the_first_camera_alone() -> None:
    config = scenario_config(BASE, SCENARIOS["ahead"])
    assert list(config.all_cameras) == ["front"]
    assert config.detector == BASE.detector


def test_what_a_scenario_changes_of_the_users_config_is_said_with_why() -> None:
    behind = SCENARIOS["behind"]
    lines = config_changes(BASE, scenario_config(BASE, behind), behind)
    assert "cameras.left: left out (a scenario is seen by its own cameras on every machine)" in (
        lines
    )
    assert any(line.startswith("cameras.rear: added (scenario 'behind': ") for line in lines)
    (imgsz,) = [line for line in lines if line.startswith("detector.")]
    assert imgsz.startswith("detector.imgsz: 0 -> 320 (scenario 'behind': two cameras"), imgsz
    assert "controller.distance_source: box -> laser (scenario 'behind')" in lines
    # A config the scenario leaves alone but for what every scenario needs: only that is said.
    ahead = SCENARIOS["ahead"]
    followed = scenario_config(Config(), ahead).controller
    plain = Config(supervisor=BASE.supervisor, controller=followed)
    lines = config_changes(plain, scenario_config(plain, ahead), ahead)
    assert [line.split(":")[0] for line in lines] == ["supervisor.services"], lines


def test_a_depth_config_keeps_following_by_depth_in_every_scenario() -> None:
    """deploy/depth.toml in the obstacle scenario (which names "box") and in ahead (which
    names "laser"): the run tests depth, and nothing says the distance source changed."""
    depth = load_config(REPO_ROOT / "deploy" / "depth.toml", environ={})
    assert depth.controller.distance_source is DistanceSource.DEPTH
    for name in ("obstacle", "ahead"):
        scenario = SCENARIOS[name]
        assert "distance_source" in scenario.controller
        config = scenario_config(depth, scenario)
        assert config.controller.distance_source is DistanceSource.DEPTH, name
        lines = config_changes(depth, config, scenario)
        assert not any(line.startswith("controller.distance_source") for line in lines), lines
    # A config by box or laser still takes the scenario's own source.
    assert scenario_config(Config(), SCENARIOS["obstacle"]).controller.distance_source is (
        DistanceSource.BOX
    )


def test_a_scenario_runs_in_the_user_s_world_and_its_result_says_which(capsys) -> None:  # type: ignore[no-untyped-def]
    """The runner leaves ``sim.world`` as the config has it (hard by default) and prints the
    world and faults the simulator ran (services/sim/worlds.py's line)."""
    from services.sim.contract import SimSettings, SimWorld
    from services.sim.worlds import world_line
    from tools.scenarios.__main__ import _print_text

    assert scenario_config(BASE, SCENARIOS["ahead"]).sim.world is SimWorld.HARD
    simple = dataclasses.replace(BASE, sim=SimSettings(world=SimWorld.SIMPLE))
    config = scenario_config(simple, SCENARIOS["ahead"])
    assert world_line(config.sim) == "world=simple faults=none"
    _print_text({"scenario": "ahead", "success": True, "log": "x", "world": world_line(config.sim)})
    assert "  world=simple faults=none\n" in capsys.readouterr().out
