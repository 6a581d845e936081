"""The controller reads depth as the depth scan stage puts it (services/depthscan): the virtual
scans, the memory and the known floor, each through the one path every aged input takes. In
process (tests/unit/controller/rig.py, the stage beside the controller on one hub)."""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

from common.access import Shape
from common.errors import ConfigError
from common.keys import Keys
from services.controller import contract
from services.controller.contract import ControllerSettings
from stack.config import Config, SupervisorSettings
from tests.unit.controller.rig import Rig, people
from tests.unit.depthscan.depth_scenes import HFOV, depth_frame, scene

HEIGHT = 0.6
REPO = Path(__file__).resolve().parents[3]


@pytest.fixture
def rig(tmp_path: Path, delivery_threads: int) -> Iterator[Rig]:
    r = Rig(tmp_path, threads=delivery_threads, announced=False, obstacle_sources=("depth",))
    r.announce("front", hfov_deg=HFOV, depth=True, mount_height_m=HEIGHT)
    yield r
    r.close()


def put_depth(rig: Rig) -> None:
    frame = depth_frame(scene(HEIGHT), rig.header(source="sim"))
    rig.put(rig.keys.depth("front"), frame.encode())  # type: ignore[union-attr]
    rig.handle_depth()


def test_the_stage_silent_holds_the_robot_still_turning_included(rig: Rig) -> None:
    # A target off to the side: the controller turns towards it while it drives.
    put_depth(rig)
    rig.detections(payload=people(rig.header(), cx=500.0))
    twist, status = rig.tick()
    assert twist.angular[2] != 0.0, status
    # The stage goes silent (killed or hung): once its memory is depth_timeout_s old the robot
    # holds still, turning included (a turn the stage does not hear would misplace its memory),
    # and zero at once, not at the braking rate.
    rig.clock.advance(rig.config.controller.depth_timeout_s + 0.05)
    rig.detections(payload=people(rig.header(), cx=500.0))
    twist, status = rig.tick(stage_alive=False)
    assert status.state == "blocked", status
    assert status.reason.startswith("no recent depth memory from the depth scan stage"), status
    assert twist.linear[0] == 0.0 and twist.angular[2] == 0.0


def test_no_memory_yet_holds_the_robot_still(rig: Rig) -> None:
    rig.detections(payload=people(rig.header(), cx=500.0))
    twist, status = rig.tick(stage_alive=False)
    assert status.reason == "no depth memory from the depth scan stage yet", status
    assert twist.linear[0] == 0.0 and twist.angular[2] == 0.0


def test_the_virtual_scans_and_memory_are_counted_as_every_input(rig: Rig) -> None:
    put_depth(rig)
    rig.tick()
    c = rig.counters
    assert c["virtual_scans_in"] == 1 and c["virtual_scans_in.front"] == 1, c
    assert c["remembered_in"] >= 1 and c["known_floor_in"] >= 1, c
    # A virtual scan of a camera not announced with depth is ignored, counted.
    rig.put(rig.keys.virtual_scan("rear"), b"")
    assert rig.counters["virtual_scans_unannounced"] == 1


def test_a_config_that_needs_depth_runs_the_depth_scan_stage() -> None:
    depth = ControllerSettings(obstacle_sources=("depth",))
    with pytest.raises(ConfigError, match=r'add "depthscan" to supervisor\.services'):
        Config(controller=depth, supervisor=SupervisorSettings(services=("sim", "controller")))
    Config(controller=depth, supervisor=SupervisorSettings(services=("depthscan", "controller")))
    # A host that runs no controller needs no stage; a controller without depth neither.
    Config(controller=depth, supervisor=SupervisorSettings(services=("sim",)))
    Config(supervisor=SupervisorSettings(services=("sim", "controller")))


def test_the_controller_reads_no_depth_image() -> None:
    # The depth images are the stage's to read: the controller's access reads none, and no
    # module of it imports what makes a scan from one or the memory.
    keys = Keys("stack")
    shape = Shape(keys=keys, cameras={"front": "camera"}, workers=())
    access = contract.access(shape)["controller"]
    assert keys.all_depths() not in access.read
    assert keys.all_virtual_scans() in access.read and keys.remembered_scan() in access.read
    for path in (REPO / "services" / "controller").glob("*.py"):
        tree = ast.parse(path.read_text())
        names = {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)} | {
            a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
        }
        made = {"depthscan.observe", "depthscan.local_map", "depthscan.trust"} & names
        assert not made, f"{path.name} imports {made}"
        assert not any(n.startswith("services.depthscan") for n in names), path.name
