"""The secure profile's pieces without a bus: rules, settings checks and session configs."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import zenoh

from common.errors import ConfigError
from common.keys import Keys
from common.security import PRINCIPALS, qualified, role_of, stack_principals
from common.settings import REPO_ROOT, ZenohSettings, camera_service
from common.zenoh_bus import QoS, open_session, zenoh_config
from deploy.credentials import generate
from stack.access import access_control
from stack.access_table import may_put, may_read, running_sensors
from stack.config_file import load_config
from stack.hub import hub_access

KEYS = Keys("robot1")


def _allowed(acl: dict, principal: str, message: str) -> set[str]:
    """Key expressions ``principal`` may send ``message`` on, on ingress to the router."""
    subjects = {
        s["id"]
        for s in acl["subjects"]
        # each subject by its role: the rules name one robot's principals, <prefix>/<role>
        if principal in {role_of(n) for n in next(iter(v for k, v in s.items() if k != "id"))}
    }
    rules = {r["id"]: r for r in acl["rules"]}
    out: set[str] = set()
    for policy in acl["policies"]:
        if subjects & set(policy["subjects"]):
            for rid in policy["rules"]:
                rule = rules[rid]
                if message in rule["messages"] and "ingress" in rule["flows"]:
                    out |= set(rule["key_exprs"])
    return out


def _may(acl: dict, principal: str, message: str, key: str) -> bool:
    """Whether ``principal`` may send ``message`` on ``key`` (a key within an allowed one)."""
    return any(
        zenoh.KeyExpr(allowed).includes(zenoh.KeyExpr(key))
        for allowed in _allowed(acl, principal, message)
    )


def test_only_the_controller_puts_cmd_vel_and_only_estop_the_estop() -> None:
    acl = access_control(KEYS, "front", "password")
    assert acl["default_permission"] == "deny"
    putters = {p for p in PRINCIPALS if KEYS.cmd_vel() in _allowed(acl, p, "put")}
    assert putters == {"controller"}
    assert {p for p in PRINCIPALS if KEYS.estop() in _allowed(acl, p, "put")} == {"estop"}
    frames = {p for p in PRINCIPALS if KEYS.frame("front") in _allowed(acl, p, "put")}
    # the camera, the simulator or the ROS 2 bridge: a stack with a live sensor takes no replay
    assert frames == {"camera", "sim", "ros2"}
    scans = {p for p in PRINCIPALS if KEYS.scan() in _allowed(acl, p, "put")}
    assert scans == {"sim", "ros2"}
    # A stack with no live sensor (a replay stack): a recording played back may feed it.
    replay = access_control(KEYS, "front", "password", live_sensors=False)
    assert {KEYS.frame("front"), KEYS.scan()} <= _allowed(replay, "recorder", "put")
    assert _allowed(acl, "observer", "put") == set()
    # The live view puts only its own counters.
    assert _allowed(acl, "viewer", "put") == {KEYS.counters("viewer")}
    assert _allowed(acl, "viewer", "liveliness_token") == {KEYS.health("viewer")}
    assert _allowed(acl, "viewer", "declare_queryable") == set()
    assert _allowed(acl, "estop", "put") == {KEYS.estop()}
    assert _allowed(acl, "detector", "put") == set(may_put(KEYS, "front", "detector"))
    # Counters and health tokens: each stack service its own, nobody else.
    assert _allowed(acl, "metrics", "liveliness_token") == {KEYS.health("metrics")}
    assert KEYS.counters("estop") not in _allowed(acl, "estop", "put")
    # Each reads what it needs; the camera's pictures only the detector, the live view, the
    # recorder and the ROS 2 bridge. Queries and liveliness stay open to all, within the prefix.
    readers = {p for p in PRINCIPALS if _may(acl, p, "declare_subscriber", KEYS.frame("front"))}
    assert readers == {"detector", "viewer", "ros2", "recorder"}
    assert _allowed(acl, "recorder", "declare_subscriber") == {f"{KEYS.prefix}/**"}
    assert KEYS.cmd_vel() in _allowed(acl, "observer", "declare_subscriber")
    assert _allowed(acl, "camera", "declare_subscriber") == set()
    assert _allowed(acl, "estop", "declare_subscriber") == {KEYS.controller_status()}
    assert _allowed(acl, "camera", "query") == {f"{KEYS.prefix}/**"}


def test_certificate_mode_matches_common_names() -> None:
    acl = access_control(KEYS, "front", "certificate")
    assert all("cert_common_names" in s for s in acl["subjects"])


def test_auth_needs_client_mode_and_certificates_need_tls() -> None:
    with pytest.raises(ConfigError, match="client"):
        ZenohSettings(auth="password")
    with pytest.raises(ConfigError, match="tls"):
        ZenohSettings(mode="client", auth="certificate")
    with pytest.raises(ConfigError, match="auth"):
        ZenohSettings(mode="client", auth="kerberos")
    ZenohSettings(mode="client", auth="certificate", endpoint="tls/127.0.0.1:7447")


def test_missing_credentials_are_one_clear_line(tmp_path: Path) -> None:
    s = ZenohSettings(mode="client", auth="password", credentials_dir=str(tmp_path))
    with pytest.raises(ConfigError, match=r"password file .*zstack credentials"):
        open_session(s, "controller")


def test_hub_config_carries_the_rules_and_the_dictionary(tmp_path: Path) -> None:
    from deploy.credentials import generate

    generate(tmp_path)
    s = ZenohSettings(mode="client", auth="password", credentials_dir=str(tmp_path))
    hub = json.loads(str(zenoh_config(s, "stack/supervisor", access={"enabled": True})))
    assert hub["mode"] == "router"
    assert hub["transport"]["auth"]["usrpwd"]["dictionary_file"].endswith("users.txt")
    assert hub["access_control"]["enabled"] is True
    client = json.loads(str(zenoh_config(s, "stack/controller")))
    assert client["mode"] == "client" and client["listen"]["endpoints"] == []
    assert client["transport"]["auth"]["usrpwd"]["user"] == "stack/controller"
    assert client["transport"]["auth"]["usrpwd"]["dictionary_file"] is None


def test_secure_profile_extends_the_default_stack() -> None:
    cfg = load_config(REPO_ROOT / "deploy" / "secure.toml", environ={})
    default = load_config(REPO_ROOT / "deploy" / "stack.toml", environ={})
    assert (cfg.zenoh.mode, cfg.zenoh.auth) == ("client", "password")
    assert cfg.supervisor == default.supervisor and cfg.controller == default.controller
    assert hub_access(cfg)["default_permission"] == "deny"
    assert hub_access(default) == {}


def test_extends_loops_are_refused(tmp_path: Path) -> None:
    (tmp_path / "a.toml").write_text('extends = "b.toml"\n')
    (tmp_path / "b.toml").write_text('extends = "a.toml"\n')
    with pytest.raises(ConfigError, match="loops"):
        load_config(tmp_path / "a.toml", environ={})


def test_control_publishers_are_express_high_priority_and_never_block() -> None:
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf) as session:
        from common.zenoh_bus import Publisher

        control = Publisher(session, "t/cmd_vel", QoS.CONTROL)
        sensor = Publisher(session, "t/frame", QoS.SENSOR)
        assert control._pub.priority == zenoh.Priority.REAL_TIME
        # DROP, not BLOCK: a blocked send holds up every other receiver behind one slow
        # listener (docs/security.md, "QoS by role").
        assert control._pub.congestion_control == zenoh.CongestionControl.DROP
        assert sensor._pub.congestion_control == zenoh.CongestionControl.DROP
        assert sensor._pub.priority == zenoh.Priority.DATA


def _cameras(*names: str) -> dict[str, str]:
    """``Config.camera_services`` for cameras ``names``, the first first."""
    return {c: camera_service(names[0], c) for c in names}


@pytest.mark.parametrize("names", [("front", "rear"), ("front", "rear", "left")])
def test_each_camera_principal_puts_only_its_own_frames(names: tuple[str, ...]) -> None:
    cameras = _cameras(*names)
    principals = stack_principals(cameras)
    assert principals[: PRINCIPALS.index("camera") + len(names)] == (
        *PRINCIPALS[: PRINCIPALS.index("camera")],
        "camera",
        *(f"camera_{n}" for n in names[1:]),
    )
    assert set(principals) == set(PRINCIPALS) | {f"camera_{n}" for n in names[1:]}
    acl = access_control(KEYS, cameras, "password")
    everyone = next(s for s in acl["subjects"] if s["id"] == "everyone")
    assert everyone["usernames"] == [qualified(KEYS.prefix, p) for p in principals]
    for camera, principal in cameras.items():
        # Its own frames and depth images, counters, health token and camera's announcements;
        # nothing else, and it reads nothing.
        own = {KEYS.frame(camera), KEYS.depth(camera), KEYS.counters(principal)}
        assert _allowed(acl, principal, "put") == own
        assert set(may_put(KEYS, cameras, principal)) == own
        assert _allowed(acl, principal, "liveliness_token") == {
            KEYS.health(principal),
            KEYS.camera_announcements_of(camera),
        }
        assert _allowed(acl, principal, "declare_subscriber") == set()
        assert _allowed(acl, principal, "declare_queryable") == set()
        for other in set(names) - {camera}:
            assert not _may(acl, principal, "put", KEYS.frame(other))
            assert not _may(acl, principal, "put", KEYS.depth(other))
            assert not _may(acl, principal, "put", KEYS.detections(other))
        # Who else may put this camera's frames: the simulator and the ROS 2 bridge.
        putters = {p for p in principals if _may(acl, p, "put", KEYS.frame(camera))}
        assert putters == {principal, "sim", "ros2"}
        readers = {p for p in principals if _may(acl, p, "declare_subscriber", KEYS.frame(camera))}
        assert readers == {"detector", "viewer", "ros2", "recorder"}
        # Detections: the detector alone puts them; the controller, metrics, viewer, recorder
        # and ROS 2 bridge read them (and the observer: status lines and tests), and the
        # detector, which judges who delivers them (common/pool_delivery.py), and the
        # simulator, whose scenario clock waits for them (services/sim/waiting.py).
        dets = KEYS.detections(camera)
        assert {p for p in principals if _may(acl, p, "put", dets)} == {"detector"}
        readers = {p for p in principals if _may(acl, p, "declare_subscriber", dets)}
        assert readers == {
            "controller", "metrics", "viewer", "recorder", "ros2", "observer", "detector", "sim",
        }  # fmt: skip
        info = KEYS.detector_info(camera)
        assert {p for p in principals if _may(acl, p, "declare_queryable", info)} == {"detector"}
    # The detector: every camera's detections and its own counters, never a frame.
    detector = {*(KEYS.detections(c) for c in names), KEYS.counters("detector")}
    assert _allowed(acl, "detector", "put") == detector
    # It reads every camera's frames and depth images, the controller's status (attention: the
    # camera that sees the target first), its commands (the robot's turn, which the tracker
    # takes out of its predictions; read, never put) and every camera's detections (who
    # delivers).
    assert _allowed(acl, "detector", "declare_subscriber") == {
        KEYS.all_frames(),
        KEYS.all_depths(),
        KEYS.all_detections(),
        KEYS.controller_status(),
        KEYS.cmd_vel(),
    }
    assert {p for p in principals if _may(acl, p, "put", KEYS.cmd_vel())} == {"controller"}
    # A camera the stack does not have: nobody may put its frames or its detections.
    assert not [p for p in principals if _may(acl, p, "put", KEYS.frame("ghost"))]
    assert not [p for p in principals if _may(acl, p, "put", KEYS.detections("ghost"))]


def test_a_replay_reaches_every_camera_only_on_a_stack_without_live_sensors() -> None:
    cameras = _cameras("front", "rear", "left")
    live = access_control(KEYS, cameras, "password")
    replay = access_control(KEYS, cameras, "password", live_sensors=False)
    assert _allowed(live, "recorder", "put") == {KEYS.counters("recorder")}
    assert _allowed(replay, "recorder", "put") == {
        *(KEYS.frame(c) for c in cameras),
        *(KEYS.depth(c) for c in cameras),  # a recording's depth images (issue 32)
        KEYS.scan(),
        KEYS.counters("recorder"),
    }
    # A further camera's process is a live sensor too.
    assert running_sensors({"camera_rear", "detector", "metrics"}) == ["camera_rear"]
    assert running_sensors({"camera", "sim", "ros2", "controller"}) == ["camera", "ros2", "sim"]
    assert running_sensors({"detector", "controller", "recorder"}) == []


def test_one_camera_is_the_stack_it_always_was() -> None:
    one = access_control(KEYS, "front", "password")
    assert one == access_control(KEYS, {"front": "camera"}, "password")
    assert stack_principals("front") == PRINCIPALS
    assert may_read(KEYS, "front", "camera") == ()
    with pytest.raises(ValueError, match="at least one camera"):
        stack_principals({})


def test_the_hub_refuses_credentials_made_for_fewer_cameras(tmp_path: Path) -> None:
    from deploy.credentials import generate
    from stack.hub import check_credentials

    creds = tmp_path / "creds"
    generate(creds)  # one camera's principals only
    config_path = tmp_path / "two.toml"
    config_path.write_text(
        f'[zenoh]\nmode = "client"\nauth = "password"\ncredentials_dir = "{creds}"\n'
        '[stack]\ncamera = "front"\n[cameras.rear]\nmount_yaw_deg = 180.0\n'
        '[supervisor]\nservices = ["camera", "detector", "controller", "metrics"]\n'
    )
    config = load_config(config_path, environ={})
    with pytest.raises(ConfigError) as refused:
        check_credentials(config)
    line = str(refused.value)
    assert "\n" not in line and "camera_rear" in line, line
    assert f"zstack credentials --config {config_path} --force" in line, line
    # A session of the missing principal says the same, in its own words.
    with pytest.raises(
        ConfigError, match=r"camera_rear.password is missing.*--config FILE --force"
    ):
        open_session(config.zenoh, config.principal("camera_rear"))
    names = tuple(config.principal(p) for p in stack_principals(config.camera_services))
    generate(creds, force=True, principals=names)
    check_credentials(config)
    # With certificates the router needs only the CA: nothing to check there.
    tls = dataclasses.replace(config.zenoh, auth="certificate", endpoint="tls/127.0.0.1:7448")
    generate(creds, force=True)
    check_credentials(dataclasses.replace(config, zenoh=tls))


def test_the_router_drops_under_congestion_on_every_key_but_the_estop() -> None:
    from stack.hub import hub_drop_keys

    cfg = load_config(REPO_ROOT / "deploy" / "secure.toml", environ={})
    keys = Keys(cfg.stack.prefix)
    drop = hub_drop_keys(cfg)
    assert keys.estop() not in drop
    for key in (
        keys.cmd_vel(),
        keys.frame(cfg.stack.camera),
        keys.scan(),
        keys.controller_status(),
    ):
        assert key in drop, key
    s = ZenohSettings(mode="client", endpoint="tcp/127.0.0.1:7447")
    hub = json.loads(str(zenoh_config(s, "stack/supervisor", access={}, drop_keys=drop)))
    (item,) = hub["qos"]["network"]
    assert item["overwrite"]["congestion_control"] == "drop" and item["flows"] == ["ingress"]
    assert item["key_exprs"] == list(drop)
    # A peer-mode hub routes nothing: no overwrite there.
    peer = json.loads(
        str(zenoh_config(ZenohSettings(), "stack/supervisor", access={}, drop_keys=drop))
    )
    assert peer["qos"]["network"] == []


def test_linked_routers_need_certificates_and_link_with_the_routers_own(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r'needs zenoh\.auth = "certificate"'):
        ZenohSettings(mode="client", auth="password", connect=("tcp/10.0.0.2:7448",))
    generate(tmp_path / "c")
    linked = ZenohSettings(
        mode="client", auth="certificate", endpoint="tls/127.0.0.1:7448",
        connect=("tls/10.0.0.2:7448",), credentials_dir=str(tmp_path / "c"),
    )  # fmt: skip
    tls = json.loads(str(zenoh_config(linked, "stack/supervisor", access={"enabled": True})))[
        "transport"
    ]["link"]["tls"]
    assert tls["connect_certificate"] == tls["listen_certificate"]
    assert tls["connect_certificate"].endswith("supervisor.pem")
    assert tls["connect_private_key"].endswith("supervisor.key")
    alone = dataclasses.replace(linked, connect=())
    tls = json.loads(str(zenoh_config(alone, "stack/supervisor", access={"enabled": True})))[
        "transport"
    ]["link"]["tls"]
    assert tls["connect_certificate"] is None


def test_a_remote_principal_the_stack_lacks_is_one_line() -> None:
    cfg = load_config(REPO_ROOT / "deploy" / "secure.toml", environ={})
    ok = dataclasses.replace(
        cfg, zenoh=dataclasses.replace(cfg.zenoh, remote_principals=("detector_a",))
    )
    assert hub_access(ok)["default_permission"] == "deny"
    bad = dataclasses.replace(
        cfg, zenoh=dataclasses.replace(cfg.zenoh, remote_principals=("lidar",))
    )
    with pytest.raises(
        ConfigError, match=r"^zenoh.remote_principals names 'lidar': not a pri"
    ) as e:
        hub_access(bad)
    assert "\n" not in str(e.value)
