"""Principals per robot (issue 39, item 1): each robot's router admits its own robot's
principals and its pool's workers only, by the names they authenticate as
(``<stack.prefix>/<role>``, ``<pool>/<worker>``); one site CA (one credentials run) for all."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from common.bus import QoS, Sample
from common.errors import ConfigError
from common.keys import Keys
from common.lifecycle import run_main
from common.memory_bus import MemoryHub
from common.security import cert_file, password_file, users_file
from common.settings import principal_names
from deploy import credentials
from stack.access import access_control
from stack.config_file import load_config
from stack.hub import check_credentials

SITE = "site"
ROBOT1, ROBOT2 = Keys(f"{SITE}/robot1"), Keys(f"{SITE}/robot2")
CAMERAS = {"front": "camera"}
ROLES = ("estop", "controller", "observer", "recorder", "camera", "sim", "ros2", "metrics",
         "viewer", "detector")  # fmt: skip


def _router(keys: Keys) -> dict[str, object]:
    """A robot's router whose pool (under ``site``) serves both robots' worker ``detector_gpu``
    (named in ``remote_principals``) and its own ``detector``."""
    return access_control(
        keys, CAMERAS, "certificate", workers=("detector",), remote=("detector_gpu",),
        pool_prefix=SITE,
    )  # fmt: skip


def test_robot1s_principals_may_do_nothing_on_robot2s_router() -> None:
    hub = MemoryHub(_router(ROBOT2))  # participants join by the names they authenticate as
    one, two = principal_names(ROBOT1.prefix, SITE), principal_names(ROBOT2.prefix, SITE)
    heard: list[Sample] = []
    hub.join("robot 2's recorder", principal=two("recorder")).subscribe(
        f"{ROBOT2.prefix}/**", heard.append
    )
    for role in (*ROLES, "detector_robot1"):  # robot 1's local worker: the pool's name
        bus = hub.join(f"robot 1's {role}", principal=one(role))
        got: list[Sample] = []
        for key in (ROBOT2.cmd_vel(), ROBOT2.estop(), ROBOT2.controller_status()):
            bus.subscribe(key, got.append)
        for key in (ROBOT2.estop(), ROBOT2.cmd_vel(), ROBOT2.frame("front"), ROBOT2.scan()):
            bus.publisher(key, QoS.CONTROL).put(b"rogue")
        assert bus.live_tokens(ROBOT2.all_health(), 0.1) == []
        assert got == [], role
    assert heard == []
    # Every one of robot 1's was refused ("detector" is site/detector, the pool's worker of
    # that name, which robot 2's router admits as its own: one pool, one name; it may put
    # none of these keys either).
    assert {who for who, _, _ in hub.denied} == {one(r) for r in (*ROLES, "detector_robot1")}
    # Robot 2's own: its estop and controller go through.
    hub.join("estop", principal=two("estop")).publisher(ROBOT2.estop(), QoS.CONTROL).put(b"e")
    controller = hub.join("controller", principal=two("controller"))
    controller.publisher(ROBOT2.cmd_vel(), QoS.CONTROL).put(b"c")
    assert [s.key for s in heard] == [ROBOT2.estop(), ROBOT2.cmd_vel()]


def test_the_pools_worker_is_admitted_by_each_robot_it_serves_on_that_robots_keys_only() -> None:
    for mine, other in ((ROBOT1, ROBOT2), (ROBOT2, ROBOT1)):
        hub = MemoryHub(_router(mine), names=principal_names(mine.prefix, SITE))
        heard: list[Sample] = []
        hub.join("recorder", principal="recorder").subscribe(f"{mine.prefix}/**", heard.append)
        worker = hub.join("detector_gpu", principal="detector_gpu")  # site/detector_gpu
        for keys in (mine, other):
            worker.publisher(keys.detections("front"), QoS.PERCEPTION).put(b"d")
            worker.publisher(keys.cmd_vel(), QoS.CONTROL).put(b"x")
        assert [s.key for s in heard] == [mine.detections("front")]
        assert {who for who, _, _ in hub.denied} == {"detector_gpu"}


def test_only_the_linked_routers_named_get_a_linked_routers_rights() -> None:
    """Robot 1's router key (``site/robot1/supervisor``, on robot 1's disk) connects straight to
    robot 2's router as a linked router would: it gets nothing, neither what robot 2's
    ``remote_principals`` may put (detections, cmd_vel) nor the asks; the GPU box's router
    (``site/gpu/supervisor``, named in robot 2's ``zenoh.linked_routers``) may put detections.
    Before per-stack routers every router was ``supervisor``: robot 1's put robot 2's
    detections and commands."""
    rules = access_control(
        ROBOT2, CAMERAS, "certificate", workers=("detector",),
        remote=("detector_gpu", "controller"), pool_prefix=SITE, linked=(f"{SITE}/gpu",),
    )  # fmt: skip
    hub = MemoryHub(rules)
    heard: list[Sample] = []
    two = principal_names(ROBOT2.prefix, SITE)
    hub.join("robot 2's recorder", principal=two("recorder")).subscribe(
        f"{ROBOT2.prefix}/**", heard.append
    )
    for router in (principal_names(ROBOT1.prefix, SITE)("supervisor"), "supervisor"):
        rogue = hub.join("robot 1's router", principal=router)
        got: list[Sample] = []
        rogue.subscribe(ROBOT2.cmd_vel(), got.append)
        for key in (ROBOT2.detections("front"), ROBOT2.cmd_vel(), ROBOT2.estop()):
            rogue.publisher(key, QoS.CONTROL).put(b"rogue")
        assert rogue.live_tokens(f"{ROBOT2.prefix}/**", 0.1) == []
        assert got == [] and heard == [], router
    box = hub.join("the GPU box's router", principal=f"{SITE}/gpu/supervisor")
    box.publisher(ROBOT2.detections("front"), QoS.PERCEPTION).put(b"d")
    box.publisher(ROBOT2.estop(), QoS.CONTROL).put(b"x")  # no remote principal may
    assert [s.key for s in heard] == [ROBOT2.detections("front")]
    # Robot 2's own router name has no linked rights once linked_routers names others.
    assert f"{ROBOT2.prefix}/supervisor" not in str(rules["subjects"])


def test_a_bad_linked_router_is_one_clear_line() -> None:
    from common.settings import ZenohSettings

    for bad in ("site//robot1", "site/../x", "site robot"):
        with pytest.raises(ConfigError, match=r"zenoh\.linked_routers names") as err:
            ZenohSettings(linked_routers=(bad,))
        assert "\n" not in str(err.value)
    with pytest.raises(ConfigError, match="twice"):
        ZenohSettings(linked_routers=("site/gpu", "site/gpu"))


def test_remote_principals_are_roles_and_a_qualified_one_is_one_clear_line() -> None:
    with pytest.raises(ValueError, match=r"write the roles \('camera'\)") as bad:
        access_control(ROBOT1, CAMERAS, "certificate", remote=("site/robot1/camera",))
    assert "\n" not in str(bad.value)


def _config(path: Path, prefix: str, creds: Path, services: list[str]) -> Path:
    path.write_text(
        f'[zenoh]\nmode = "client"\nauth = "password"\ncredentials_dir = "{creds}"\n'
        f'[stack]\nprefix = "{prefix}"\n[supervisor]\nservices = {services!r}\n'.replace("'", '"')
        + f'[detector]\npool_prefix = "{SITE}"\n'
    )
    return path


def test_one_run_makes_both_robots_principals_each_in_its_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    creds = tmp_path / "creds"
    one = _config(tmp_path / "one.toml", ROBOT1.prefix, creds, ["sim", "controller"])
    two = _config(tmp_path / "two.toml", ROBOT2.prefix, creds, ["camera", "controller"])
    monkeypatch.setattr(sys, "argv", ["credentials", "--config", str(one), "--robot", str(two)])
    with pytest.raises(SystemExit) as done:
        run_main(credentials.main, "credentials")
    assert done.value.code == 0, capsys.readouterr().err
    users = [line.split(":", 1)[0] for line in users_file(creds).read_text().splitlines()]
    for robot in (ROBOT1, ROBOT2):
        for role in ("controller", "estop", "observer"):
            assert f"{robot.prefix}/{role}" in users
            assert password_file(creds, f"{robot.prefix}/{role}").is_file()
            assert cert_file(creds, f"{robot.prefix}/{role}").parent == creds / robot.prefix
    assert f"{ROBOT2.prefix}/camera" in users and f"{ROBOT1.prefix}/camera" not in users
    for path in (one, two):
        check_credentials(load_config(path, environ={}))  # each robot's supervisor starts


def test_a_folder_named_by_role_alone_stops_the_start_in_one_line(tmp_path: Path) -> None:
    creds = tmp_path / "creds"
    credentials.generate(
        creds, principals=("supervisor", "controller", "estop", "observer", "recorder")
    )  # fmt: skip  (an older version's)
    config = load_config(_config(tmp_path / "r.toml", ROBOT1.prefix, creds, ["controller"]),
                         environ={})  # fmt: skip
    for refuse in (lambda: check_credentials(config), lambda: _open_as(config, "estop")):
        with pytest.raises(ConfigError) as old:
            refuse()
        line = str(old.value)
        assert "\n" not in line and "by role alone" in line, line
        assert "zstack credentials --config" in line and "--force" in line, line


def _open_as(config: object, role: str) -> None:
    from common.zenoh_bus import zenoh_config

    zenoh_config(config.zenoh, config.principal(role))  # type: ignore[attr-defined]


def test_a_subfolder_that_is_a_link_is_refused(tmp_path: Path) -> None:
    creds, elsewhere = tmp_path / "creds", tmp_path / "elsewhere"
    creds.mkdir()
    elsewhere.mkdir()
    (creds / "stack").symlink_to(elsewhere)
    with pytest.raises(ConfigError, match="symbolic link"):
        credentials.generate(creds, force=True)
    assert list(elsewhere.iterdir()) == []
