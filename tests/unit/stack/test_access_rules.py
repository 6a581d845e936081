"""The access rules at work on the in-process bus (common/memory_bus.py with the router's
``access_control`` section): each principal can do what its service's contract declares and
nothing else. The real router's enforcement is checked by tests/integration/test_safety_*."""

from __future__ import annotations

import itertools

import pytest

from common.access import Shape
from common.bus import QoS, Sample
from common.camera_announce import CameraAnnouncements
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.security import stack_principals
from common.settings import principal_names
from services.camera.contract import CameraSettings
from stack.access import access_control
from stack.access_table import access_table
from tests.unit.heard import heard_cameras

KEYS = Keys("stack")
CAMERAS = {"front": "camera", "rear": "camera_rear"}
WORKERS = ("detector", "detector_2")
PRINCIPALS = stack_principals(CAMERAS, WORKERS)


def _hub(*, live_sensors: bool = True) -> MemoryHub:
    acl = access_control(KEYS, CAMERAS, "password", live_sensors=live_sensors, workers=WORKERS)
    return MemoryHub(acl, names=principal_names(KEYS.prefix))


def _table(*, live_sensors: bool = True) -> dict[str, tuple[tuple[str, ...], ...]]:
    shape = Shape(KEYS, CAMERAS, WORKERS, live_sensors)
    return {p: (a.put, a.token, a.read, a.serve) for p, a in access_table(shape).items()}


#: Every key the stack puts on, an unconfigured camera's and a made-up one.
PUT_KEYS = (
    *(KEYS.frame(c) for c in (*CAMERAS, "side")),
    *(KEYS.detections(c) for c in CAMERAS),
    KEYS.scan(), KEYS.cmd_vel(), KEYS.controller_status(), KEYS.estop(), KEYS.sim_truth(),
    *(KEYS.counters(p) for p in PRINCIPALS),
    f"{KEYS.prefix}/made/up",
)  # fmt: skip
#: Every token a principal could declare: each one's health, each worker's pool tokens, each
#: camera's announcement (and an unconfigured camera's).
TOKENS = (
    *(KEYS.health(p) for p in PRINCIPALS),
    *(KEYS.pool_member(w) for w in WORKERS),
    *(KEYS.worker_announcement(w, "AAAA") for w in WORKERS),
    *(KEYS.pool_serving(w, "z1", c) for w, c in itertools.product(WORKERS, CAMERAS)),
    *(KEYS.camera_announcement(c, "QUJD") for c in (*CAMERAS, "side")),
)


@pytest.mark.parametrize("live_sensors", [True, False])
def test_each_principal_puts_exactly_the_keys_its_contract_declares(live_sensors: bool) -> None:
    hub = _hub(live_sensors=live_sensors)
    heard: list[Sample] = []
    hub.join("listener", principal="recorder").subscribe(f"{KEYS.prefix}/**", heard.append)
    table = _table(live_sensors=live_sensors)
    for principal in PRINCIPALS:
        bus = hub.join(principal, principal=principal)
        for key in PUT_KEYS:
            heard.clear()
            bus.publisher(key, QoS.TELEMETRY).put(b"x")
            declared = key in table[principal][0]
            assert [s.key for s in heard] == ([key] if declared else []), (principal, key)


def test_each_principal_announces_exactly_the_tokens_its_contract_declares() -> None:
    table = _table()
    for principal in PRINCIPALS:
        hub = _hub()
        bus = hub.join(principal, principal=principal)
        for key in TOKENS:
            bus.declare_token(key)
        declared = table[principal][1]
        own = {
            key
            for key in TOKENS
            for d in declared
            if key == d
            or (d.endswith("/**") and key.startswith(d.removesuffix("**")))
            or _one_chunk_wildcards(d, key)
        }
        assert set(hub.tokens()) == own, principal


@pytest.mark.parametrize("live_sensors", [True, False])
def test_each_camera_source_announces_its_own_cameras_and_no_other(live_sensors: bool) -> None:
    """A camera process announces only its own camera; the simulator and the ROS 2 bridge
    every configured camera; a player (the recorder's principal) only on a stack without live
    sensors; nobody an unconfigured camera."""
    both = ["front", "rear"]
    own = {"camera": ["front"], "camera_rear": ["rear"], "sim": both, "ros2": both,
           "recorder": [] if live_sensors else both}  # fmt: skip
    for principal in PRINCIPALS:
        hub = _hub(live_sensors=live_sensors)
        heard = heard_cameras(hub, KEYS, principal="observer")
        with CameraAnnouncements(hub.join(principal, principal=principal), KEYS, principal) as a:
            for camera in (*CAMERAS, "side"):
                a.announce(camera, CameraSettings(rate_hz=5.0, frame_id="f"))
            assert sorted(heard.current()) == own.get(principal, []), principal
            denied = {key for who, kind, key in hub.denied if kind == "liveliness_token"}
            assert len(denied) == 3 - len(own.get(principal, [])), principal


def test_a_worker_cannot_announce_another_workers_pool_token() -> None:
    hub = _hub()
    second = hub.join("detector_2", principal="detector_2")
    second.declare_token(KEYS.pool_member("detector"))
    second.declare_token(KEYS.pool_serving("detector", "z1", "front"))
    assert hub.tokens(KEYS.all_pool_members()) == []
    assert hub.tokens(KEYS.all_pool_serving()) == []
    second.declare_token(KEYS.pool_member("detector_2"))
    assert hub.tokens(KEYS.all_pool_members()) == [KEYS.pool_member("detector_2")]
    assert ("detector_2", "liveliness_token", KEYS.pool_member("detector")) in hub.denied


def test_a_cameras_cmd_vel_reaches_nobody_and_the_controllers_does() -> None:
    hub = _hub()
    heard: dict[str, list[Sample]] = {p: [] for p in ("sim", "ros2", "metrics", "viewer")}
    for principal, got in heard.items():
        hub.join(principal, principal=principal).subscribe(KEYS.cmd_vel(), got.append)
    hub.join("camera", principal="camera").publisher(KEYS.cmd_vel(), QoS.CONTROL).put(b"go")
    assert all(got == [] for got in heard.values())
    hub.join("controller", principal="controller").publisher(KEYS.cmd_vel(), QoS.CONTROL).put(b"0")
    assert all([s.payload for s in got] == [b"0"] for got in heard.values())


#: Subscriptions a principal might ask for: every key expression some principal reads, a
#: camera's own frames and detections, and wider ones nobody is given.
READS = (
    KEYS.all_frames(), KEYS.frame("front"), KEYS.all_detections(), KEYS.detections("rear"),
    KEYS.scan(), KEYS.cmd_vel(), KEYS.controller_status(), KEYS.estop(), KEYS.sim_truth(),
    KEYS.all_counters(), KEYS.counters("detector"), f"{KEYS.prefix}/**", "**",
    f"{KEYS.prefix}/camera/**",
)  # fmt: skip


def _one_chunk_wildcards(pattern: str, key: str) -> bool:
    """Whether ``key`` is ``pattern`` with each ``*`` chunk filled in (no ``**``)."""
    parts, chunks = pattern.split("/"), key.split("/")
    if len(parts) != len(chunks) or "**" in parts:
        return False
    return all(p in ("*", c) for p, c in zip(parts, chunks, strict=True))


def _a_putter(key_expr: str, table: dict[str, tuple[tuple[str, ...], ...]]) -> tuple[str, str]:
    """A principal allowed to put on a key that ``key_expr`` matches, and that key."""
    for principal, (puts, *_) in table.items():
        for key in puts:
            if key == key_expr or _one_chunk_wildcards(key_expr, key):
                return principal, key
    if key_expr.endswith("**"):
        return "camera", KEYS.frame("front")
    raise AssertionError(key_expr)


def _within_declared(expr: str, declared: tuple[str, ...]) -> bool:
    """By hand: the same expression, ``<prefix>/**`` (the recorder's), or a concrete key under
    a declared ``*`` chunk."""
    for d in declared:
        if expr == d or (d == f"{KEYS.prefix}/**" and expr.startswith(f"{KEYS.prefix}/")):
            return True
        if "*" not in expr and _one_chunk_wildcards(d, expr):
            return True
    return False


def test_each_principal_subscribes_exactly_within_what_its_contract_declares() -> None:
    table = _table()
    for principal in PRINCIPALS:
        for expr in READS:
            hub = _hub()
            got: list[Sample] = []
            hub.join(principal, principal=principal).subscribe(expr, got.append)
            putter, key = _a_putter(expr, table)
            hub.join(putter, principal=putter).publisher(key, QoS.SENSOR).put(b"x")
            declared = _within_declared(expr, table[principal][2])
            assert len(got) == (1 if declared else 0), (principal, expr)


def test_a_wider_subscription_is_denied_whole() -> None:
    hub = _hub()
    got: list[Sample] = []
    hub.join("viewer", principal="viewer").subscribe(f"{KEYS.prefix}/**", got.append)
    hub.join("camera", principal="camera").publisher(KEYS.frame("front"), QoS.SENSOR).put(b"f")
    assert got == []  # the viewer reads frames, but not through <prefix>/**


def test_only_the_metrics_service_answers_on_the_metrics_key() -> None:
    hub = _hub()
    hub.join("metrics", principal="metrics").serve(KEYS.metrics(), lambda k, q: b"real")
    hub.join("viewer", principal="viewer").serve(KEYS.metrics(), lambda k, q: b"fake")
    replies = hub.join("observer", principal="observer").query(KEYS.metrics(), 1.0)
    assert [r.payload for r in replies] == [b"real"]
    assert ("viewer", "declare_queryable", KEYS.metrics()) in hub.denied


def test_a_replay_reaches_the_sensors_keys_only_on_a_stack_without_live_sensors() -> None:
    for live, expected in ((True, []), (False, [b"old"])):
        hub = _hub(live_sensors=live)
        got: list[Sample] = []
        hub.join("detector", principal="detector").subscribe(KEYS.all_frames(), got.append)
        hub.join("recorder", principal="recorder").publisher(KEYS.frame("rear"), QoS.SENSOR).put(
            b"old"
        )
        assert [s.payload for s in got] == expected, live


def test_a_hub_with_rules_admits_no_anonymous_participant() -> None:
    with pytest.raises(ValueError, match="principal"):
        _hub().join("someone")
    open_hub = MemoryHub()  # without rules: everything goes, as in the default peer profile
    got: list[Sample] = []
    open_hub.join("a").subscribe("**", got.append)
    open_hub.join("b").publisher(KEYS.cmd_vel(), QoS.CONTROL).put(b"x")
    assert len(got) == 1


def test_the_controller_and_the_metrics_may_watch_the_camera_announcements() -> None:
    table = access_table(Shape(KEYS, CAMERAS, WORKERS))
    for principal in ("controller", "metrics"):
        assert KEYS.all_camera_announcements() in table[principal].watch, principal
    acl = access_control(KEYS, CAMERAS, "password", workers=WORKERS)
    [rule] = [r for r in acl["rules"] if r["id"] == "controller_watch"]
    assert rule["messages"] == ["declare_liveliness_subscriber", "liveliness_query"]
    assert rule["key_exprs"] == [KEYS.all_camera_announcements()]


def test_the_simulator_may_hear_the_detections_its_clock_waits_for() -> None:
    # Issue 39: sim.wait_for's "detector" is each camera's detections (services/sim/waiting.py);
    # under the secure profile the simulator's subscription was denied, and its world stood
    # still for good while its status said it waited.
    from services.sim.waiting import Waiting

    hub = _hub()
    waiting = Waiting(
        hub.join("sim", principal="sim"), KEYS, ["detector"], list(CAMERAS), lambda _: True
    )
    assert len(waiting.missing()) == 1
    worker = hub.join("detector", principal="detector")
    for camera in CAMERAS:
        worker.publisher(KEYS.detections(camera), QoS.PERCEPTION).put(b"d")
    assert waiting.missing() == []
    waiting.close()
