"""The access rules across routers and robots, on the in-process bus (common/memory_bus.py
with the router's ``access_control`` section): a linked router (another host's, admitted as
the ``supervisor`` principal) may do what the other hosts' principals may do together, and
nothing more; one robot's principals can read nothing of another robot's, and a pool's worker
serving both reads both robots' frames and puts both robots' detections, nothing else of
theirs. The real routers' enforcement is checked by tests/integration/test_two_hosts.py."""

from __future__ import annotations

import pytest

from common.bus import QoS, Sample
from common.keys import Keys
from common.memory_bus import MemoryBus, MemoryHub
from common.security import ROUTER_PRINCIPAL, stack_principals
from common.settings import principal_names
from stack.access import access_control

ROBOT1, ROBOT2 = Keys("robot1"), Keys("robot2")
CAMERAS = {"front": "camera", "rear": "camera_rear"}
GPU_WORKER = "detector_gpu"  # a worker another host runs (its worker_id "gpu")


def _put(bus: MemoryBus, key: str) -> None:
    bus.publisher(key, QoS.SENSOR).put(b"x")


# --- a robot's router, linked to a GPU box's -----------------------------------------------


def _robot_router(remote: tuple[str, ...]) -> MemoryHub:
    """Robot 1's router: its cameras, its worker ``detector_b``, linked to a GPU box's router
    whose principals are ``remote``."""
    return MemoryHub(
        access_control(ROBOT1, CAMERAS, "certificate", workers=("detector_b",), remote=remote),
        names=principal_names(ROBOT1.prefix),
    )


def test_a_linked_router_may_do_what_the_other_hosts_principals_may_and_no_more() -> None:
    hub = _robot_router(remote=(GPU_WORKER,))
    heard: list[Sample] = []
    hub.join("recorder", principal="recorder").subscribe(f"{ROBOT1.prefix}/**", heard.append)
    link = hub.join("gpu box", principal=ROUTER_PRINCIPAL)
    # What the GPU box's worker does, through its router: detections of every camera, its
    # counters, its tokens, a subscription to the frames.
    for camera in CAMERAS:
        _put(link, ROBOT1.detections(camera))
    _put(link, ROBOT1.counters(GPU_WORKER))
    for key in (ROBOT1.health(GPU_WORKER), ROBOT1.pool_member(GPU_WORKER)):
        link.declare_token(key)
    frames: list[Sample] = []
    link.subscribe(ROBOT1.all_frames(), frames.append)
    _put(hub.join("camera", principal="camera"), ROBOT1.frame("front"))
    assert len(frames) == 1
    # Nothing else: no frame, command, e-stop, status, nor another worker's or service's token.
    for key in (
        ROBOT1.frame("front"), ROBOT1.cmd_vel(), ROBOT1.estop(), ROBOT1.controller_status(),
        ROBOT1.counters("detector_b"), ROBOT1.counters("controller"),
    ):  # fmt: skip
        _put(link, key)
    for key in (ROBOT1.pool_member("detector_b"), ROBOT1.health("controller")):
        link.declare_token(key)
    # A worker reads the robot's commands (its turn, for the tracker), so its link may too:
    # heard, never put (the link's own put of cmd_vel above was refused).
    link.subscribe(ROBOT1.cmd_vel(), frames.append)
    _put(hub.join("controller", principal="controller"), ROBOT1.cmd_vel())
    assert sorted(s.key for s in heard) == sorted(
        [*(ROBOT1.detections(c) for c in CAMERAS), ROBOT1.counters(GPU_WORKER),
         ROBOT1.frame("front"), ROBOT1.cmd_vel()]
    )  # fmt: skip
    assert [s.source.split("-")[1].split("/")[0] for s in frames[1:]] == ["controller"]
    assert hub.tokens() == sorted([ROBOT1.health(GPU_WORKER), ROBOT1.pool_member(GPU_WORKER)])


def test_a_linked_router_with_no_remote_principals_may_only_ask() -> None:
    hub = _robot_router(remote=())
    heard: list[Sample] = []
    hub.join("recorder", principal="recorder").subscribe(f"{ROBOT1.prefix}/**", heard.append)
    link = hub.join("gpu box", principal=ROUTER_PRINCIPAL)
    _put(link, ROBOT1.detections("front"))
    link.declare_token(ROBOT1.pool_member(GPU_WORKER))
    assert heard == [] and hub.tokens() == []
    hub.join("metrics", principal="metrics").serve(ROBOT1.metrics(), lambda k, q: b"answer")
    assert [r.payload for r in link.query(ROBOT1.metrics(), 1.0)] == [b"answer"]


def test_another_hosts_worker_joining_this_router_is_confined_as_its_own_router_would() -> None:
    hub = _robot_router(remote=(GPU_WORKER,))
    heard: list[Sample] = []
    hub.join("recorder", principal="recorder").subscribe(f"{ROBOT1.prefix}/**", heard.append)
    worker = hub.join(GPU_WORKER, principal=GPU_WORKER)
    for key in (ROBOT1.detections("front"), ROBOT1.cmd_vel(), ROBOT1.frame("rear")):
        _put(worker, key)
    assert [s.key for s in heard] == [ROBOT1.detections("front")]


def test_an_unknown_remote_principal_is_refused_in_one_line() -> None:
    with pytest.raises(ValueError, match=r"remote_principals names 'planner'.*known: "):
        access_control(ROBOT1, CAMERAS, "certificate", remote=("planner",))
    with pytest.raises(ValueError, match=r"remote_principals names 'camera_Side'"):
        access_control(ROBOT1, CAMERAS, "certificate", remote=("camera_Side",))
    with pytest.raises(ValueError, match="'supervisor'"):
        access_control(ROBOT1, CAMERAS, "certificate", remote=(ROUTER_PRINCIPAL,))


def test_a_gpu_boxs_router_admits_the_robots_further_cameras_named_only_in_remote_principals() -> (
    None
):
    # The GPU box has no camera table (its one default camera); the robot runs front and rear.
    gpu = MemoryHub(
        access_control(
            ROBOT1, "front", "certificate", workers=(GPU_WORKER,),
            remote=("camera", "camera_rear", "detector_b", "controller", "metrics"),
        ),
        names=principal_names(ROBOT1.prefix),
    )  # fmt: skip
    worker = gpu.join(GPU_WORKER, principal=GPU_WORKER)
    heard: list[Sample] = []
    worker.subscribe(ROBOT1.all_frames(), heard.append)
    link = gpu.join("robot router", principal=ROUTER_PRINCIPAL)
    for camera in ("front", "rear", "side"):
        _put(link, ROBOT1.frame(camera))
    assert [s.key for s in heard] == [ROBOT1.frame("front"), ROBOT1.frame("rear")]


# --- two robots ----------------------------------------------------------------------------

#: What one robot has that another might want to read: every kind of key of robot 2.
ROBOT2_READS = (
    f"{ROBOT2.prefix}/**", ROBOT2.all_frames(), ROBOT2.frame("front"), ROBOT2.all_detections(),
    ROBOT2.cmd_vel(), ROBOT2.controller_status(), ROBOT2.all_counters(), ROBOT2.scan(),
)  # fmt: skip
ROBOT2_ASKS = (ROBOT2.metrics(), ROBOT2.all_health(), ROBOT2.all_detector_info(), "**")


def _asks(bus: MemoryBus) -> list[str]:
    """What ``bus`` could learn of robot 2 by asking: replies, tokens, token events."""
    learnt = [r.key for key in ROBOT2_ASKS for r in bus.query(key, 1.0)]
    learnt += [t for key in ROBOT2_ASKS for t in bus.live_tokens(key, 1.0)]
    for key in ROBOT2_ASKS:
        bus.watch_tokens(key, lambda k, alive: learnt.append(k))
    return learnt


def test_on_a_pool_router_serving_two_robots_robot1s_principals_read_nothing_of_robot2s() -> None:
    """One router for robot 1 whose pool also serves robot 2 (``detector.prefixes``): the
    workers read and put robot 2's frames and detections; no other principal reads or learns
    anything of robot 2, and nobody but a worker may put on its detections."""
    workers = ("detector", "detector_2")
    acl = access_control(
        ROBOT1, CAMERAS, "certificate", workers=workers, prefixes=(ROBOT1.prefix, ROBOT2.prefix)
    )
    hub = MemoryHub(acl, names=principal_names(ROBOT1.prefix))
    # Robot 2's data on this router: a worker's detections, and what a linked router (robot
    # 2's, were it linked) may bring here: nothing of robot 2's, so its frames stay out.
    worker = hub.join("detector_2", principal="detector_2")
    frames: list[Sample] = []
    worker.subscribe(ROBOT2.all_frames(), frames.append)
    worker.serve(ROBOT2.detector_info("front"), lambda k, q: b"info")
    _put(worker, ROBOT2.detections("front"))
    for key in (ROBOT2.frame("front"), ROBOT2.cmd_vel(), ROBOT2.estop()):
        _put(worker, key)
    assert (("detector_2", "put", ROBOT2.frame("front")) in hub.denied
            and ("detector_2", "put", ROBOT2.cmd_vel()) in hub.denied)  # fmt: skip
    assert worker.query(ROBOT2.detector_info("front"), 1.0)  # a worker asks there
    for principal in stack_principals(CAMERAS, workers):
        if principal in workers or principal == ROUTER_PRINCIPAL:
            continue
        bus = hub.join(principal, principal=principal)
        got: list[Sample] = []
        for expr in ROBOT2_READS:
            bus.subscribe(expr, got.append)
        learnt = _asks(bus)
        _put(worker, ROBOT2.detections("rear"))
        _put(bus, ROBOT2.detections("rear"))
        assert got == [] and learnt == [], principal
        assert (principal, "put", ROBOT2.detections("rear")) in hub.denied
    # The control: robot 1's own answers and detections do reach its principals.
    observer = hub.join("observer", principal="observer")
    mine: list[Sample] = []
    observer.subscribe(ROBOT1.all_detections(), mine.append)
    _put(worker, ROBOT1.detections("front"))
    assert [s.key for s in mine] == [ROBOT1.detections("front")]
    assert observer.query(ROBOT1.detector_info("front"), 1.0) == []  # served only for robot 2
    assert frames == []  # nobody may put robot 2's frames here but robot 2's sensors


def test_robot1s_router_admits_no_ask_or_put_of_robot2s() -> None:
    """Robots with routers of their own, linked through a GPU box: robot 1's router admits
    from its own principals, and from the link, nothing on robot 2's keys."""
    hub = _robot_router(remote=(GPU_WORKER,))
    for principal in (*stack_principals(CAMERAS, ("detector_b",)), GPU_WORKER):
        bus = hub.join(principal, principal=principal)
        got: list[Sample] = []
        for expr in ROBOT2_READS:
            bus.subscribe(expr, got.append)
        assert _asks(bus) == [] and got == [], principal
        for key in (ROBOT2.detections("front"), ROBOT2.frame("front")):
            _put(bus, key)
        assert {(principal, "put", ROBOT2.detections("front"))} <= set(hub.denied), principal
    kinds = {kind for _, kind, key in hub.denied if key.startswith(ROBOT2.prefix)}
    assert {"declare_subscriber", "query", "liveliness_query", "put"} <= kinds


def test_a_gpu_boxs_router_serving_two_robots_confines_its_worker_to_frames_and_detections() -> (
    None
):
    """A GPU box's router (its own prefix ``pool``) whose worker serves robot 1 and robot 2,
    linked to each robot's router: the worker reads both robots' frames and puts both robots'
    detections, and nothing else of theirs; each link brings its own robot's frames, and
    nothing of the other robot's (issue 39: robot 1's router key acts on robot 1 alone)."""
    robot_principals = ("camera", "camera_rear", "controller", "metrics")
    acl = access_control(
        Keys("pool"), CAMERAS, "certificate", workers=(GPU_WORKER,),
        prefixes=(ROBOT1.prefix, ROBOT2.prefix), remote=robot_principals,
        linked=(ROBOT1.prefix, ROBOT2.prefix),
    )  # fmt: skip
    role = principal_names("pool")
    hub = MemoryHub(acl, names=lambda p: p if "/" in p else role(p))
    worker = hub.join(GPU_WORKER, principal=GPU_WORKER)
    links = {
        robot: hub.join(f"{robot.prefix}'s router", principal=f"{robot.prefix}/supervisor")
        for robot in (ROBOT1, ROBOT2)
    }
    frames: list[Sample] = []
    for robot, link in links.items():
        worker.subscribe(robot.all_frames(), frames.append)
        _put(link, robot.frame("front"))
    assert [s.key for s in frames] == [ROBOT1.frame("front"), ROBOT2.frame("front")]
    # Robot 1's router puts nothing on robot 2's keys, hears nothing of robot 2 and asks
    # nothing there.
    _put(links[ROBOT1], ROBOT2.frame("front"))
    assert len(frames) == 2
    stolen: list[Sample] = []
    links[ROBOT1].subscribe(ROBOT2.all_detections(), stolen.append)
    _put(worker, ROBOT2.detections("front"))
    assert stolen == []
    assert _asks(links[ROBOT1]) == []
    robot1_router = f"{ROBOT1.prefix}/supervisor"
    refused = {kind for who, kind, key in hub.denied
               if who == robot1_router and key.startswith(ROBOT2.prefix)}  # fmt: skip
    assert {"put", "declare_subscriber", "query", "liveliness_query"} <= refused, refused
    heard: list[Sample] = []
    for robot, link in links.items():
        link.subscribe(robot.all_detections(), heard.append)  # each controller's, via its router
        link.subscribe(robot.cmd_vel(), heard.append)  # nobody here may put it anyway
        for key in (robot.detections("rear"), robot.frame("rear"), robot.cmd_vel(), robot.estop(),
                    robot.controller_status()):  # fmt: skip
            _put(worker, key)
    assert [s.key for s in heard] == [ROBOT1.detections("rear"), ROBOT2.detections("rear")]
    assert len(frames) == 2, "the worker put a frame"
    # The worker asks within the robots' prefixes (camera announcements), not beyond them.
    worker.live_tokens(ROBOT2.all_health(), 1.0)
    worker.live_tokens("robot3/health/*", 1.0)
    asked = [key for who, kind, key in hub.denied if who == GPU_WORKER and kind != "put"]
    assert asked == ["robot3/health/*"]


def test_a_pool_under_its_own_prefix_announces_there_and_every_principal_may_watch_it() -> None:
    """``detector.pool_prefix``: the workers' pool tokens and announcements live there, the
    workers may declare only their own, and every principal may ask there (the metrics
    watch the pool); nothing else of the pool prefix is anyone's."""
    pool = Keys("pool")
    acl = access_control(
        ROBOT1, CAMERAS, "certificate", workers=("detector",), pool_prefix=pool.prefix
    )
    hub = MemoryHub(acl, names=principal_names(ROBOT1.prefix, pool.prefix))
    worker = hub.join("detector", principal="detector")
    for key in (pool.pool_member("detector"), pool.pool_member("detector_9"),
                ROBOT1.pool_member("detector")):  # fmt: skip
        worker.declare_token(key)
    assert hub.tokens() == [pool.pool_member("detector")]
    seen: list[str] = []
    hub.join("metrics", principal="metrics").watch_tokens(
        pool.all_pool_members(), lambda k, alive: seen.append(k)
    )
    assert seen == [pool.pool_member("detector")]


def test_in_a_sites_layout_the_pools_scope_holds_no_other_robot() -> None:
    """docs/pool.md's layout: robots ``site/robot1`` and ``site/robot2``, their pool ``site``.
    Every principal may ask in the pool (its tokens and announcements), and that must not
    open ``site/**``, the other robot's prefix with it: robot 1's observer asked robot 2's
    metrics through the links (issue 39)."""
    robot1, robot2, site = Keys("site/robot1"), Keys("site/robot2"), Keys("site")
    acl = access_control(robot1, CAMERAS, "password", pool_prefix=site.prefix)
    role = principal_names(robot1.prefix, site.prefix)
    hub = MemoryHub(acl, names=role)
    observer = hub.join("observer", principal="observer")
    observer.live_tokens(site.all_pool_members(), 1.0)
    observer.query(robot2.metrics(), 1.0)
    observer.live_tokens(robot2.all_health(), 1.0)
    asked = {(kind, key) for who, kind, key in hub.denied if who == "observer"}
    assert asked == {("query", robot2.metrics()), ("liveliness_query", robot2.all_health())}
