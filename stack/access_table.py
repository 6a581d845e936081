"""Who may say what on the bus: each principal's :class:`common.access.Access`, built from what
each service's contract (``services/<name>/contract.py``) declares it puts, announces, serves
and reads; stack/access.py turns it into the router's access-control rules. Pure: nothing here
opens a session.

Each process has its own principal (common/security.py) and may publish only its own keys:
only the controller puts ``cmd_vel``, only the ``estop`` principal the e-stop, only the
cameras, the simulator and the ROS 2 bridge frames and scans, only stack services counters and
health tokens. Each camera process may put only its own camera's frames and announce only its
own camera (the simulator, the ROS 2 bridge and a replay: each camera whose frames they may
put); the detector puts every camera's detections and no frame. Each detector worker of a pool
may put every camera's detections (any worker may serve any camera), but announces only its own
health and pool tokens. The recorder (playing a recording back) may put frames and scans only on
a stack that runs no live sensor (no camera, simulator or ROS 2 bridge): a replay must never
reach a live robot's keys.

Each principal may also subscribe only to what it reads: the camera frames only to the
detector, the live view, the recorder and the ROS 2 bridge. A linked router (another host's)
may do what the principals the other hosts run may do, together (:func:`linked_router_access`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping

from common.access import Access, Shape
from common.keys import Keys
from common.security import DETECTOR_PRINCIPAL, ROUTER_PRINCIPAL, camera_services
from common.service_list import SERVICES
from common.settings import is_detector_service, service_package
from services.controller import contract as controller
from stack.contracts import contracts, live_sensors
from stack.principals import OBSERVER_PRINCIPAL, check_remote, remote_cameras

#: The packages whose services feed a live robot's sensors into the stack (their contracts'
#: ``LIVE_SENSOR``): while one of them runs, no recording may be played onto its keys.
LIVE_SENSORS = live_sensors()


def running_sensors(services: Iterable[str]) -> list[str]:
    """Those of ``services`` that feed a live robot's sensors (any camera, the simulator, the
    ROS 2 bridge), sorted."""
    return sorted(s for s in set(services) if service_package(s) in LIVE_SENSORS)


def _observer(shape: Shape) -> dict[str, Access]:
    """Everything but the cameras' pictures: what status lines, tests and tools watch."""
    keys = shape.keys
    watching = (
        keys.all_detections(), keys.scan(), keys.cmd_vel(), keys.controller_status(),
        keys.estop(), keys.sim_truth(), keys.all_counters(),
    )  # fmt: skip
    return {OBSERVER_PRINCIPAL: Access(read=watching)}


def linked_router_access(table: Mapping[str, Access], remote: Iterable[str]) -> Access:
    """What a linked router (another host's, admitted as ROUTER_PRINCIPAL) may do: what the
    ``remote`` principals (those the other hosts run) may do, together, in ``table``'s
    order. ValueError, one line, for a name that is no principal of the stack."""
    remote = tuple(dict.fromkeys(remote))
    check_remote(table, remote)
    return merged(table[p] for p in remote)


def access_table(shape: Shape, services: Iterable[str] = SERVICES) -> dict[str, Access]:
    """What each principal of the stack may do, from its service's contract. Puts name each
    configured camera's key: nobody may put on a camera the stack does not have. Reads and the
    detector's info take the wildcard, so that one subscription (or queryable) for every
    camera is accepted as well as one per camera; nobody can put on an unconfigured camera's
    key, so the wildcard reads nothing more. ``services``: the one list
    (common/service_list.py), each service's ``access`` read from its contract."""
    table: dict[str, Access] = {}
    for module in contracts(services).values():
        table.update(module.access(shape))
    return {
        **table,
        **controller.estop_access(shape),
        ROUTER_PRINCIPAL: Access(),  # its session lives inside the router: no rule applies to it
        **_observer(shape),
    }


def stack_table(
    keys: Keys,
    cameras: str | Mapping[str, str],
    live_sensors: bool = True,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
    prefixes: Iterable[str] = (),
    remote: Iterable[str] = (),
    pool_prefix: str = "",
) -> dict[str, Access]:
    """Each principal's access; with ``remote`` (the principals other hosts run), another
    host's detector workers among them, and the linked routers' (ROUTER_PRINCIPAL's)."""
    remote = tuple(remote)
    pool = tuple(dict.fromkeys((*workers, *(p for p in remote if is_detector_service(p)))))
    shape = Shape(
        keys, remote_cameras(camera_services(cameras), remote), pool, live_sensors,
        tuple(prefixes), pool_prefix,
    )  # fmt: skip
    table = access_table(shape)
    if remote:
        # A pool's router linked to the routers of the robots it serves: their principals
        # act on their own robot's keys, so the link may do what they may on each prefix.
        robots = (
            shape,
            *(
                dataclasses.replace(shape, keys=k, prefixes=(), pool_prefix="")
                for k in shape.other_robots()
            ),
        )
        tables = [table, *(access_table(r) for r in robots[1:])]
        table[ROUTER_PRINCIPAL] = merged(linked_router_access(t, remote) for t in tables)
        for robot, t in zip(robots, tables, strict=True):
            table[linked_entry(robot.keys.prefix)] = linked_router_access(t, remote)
    return table


def linked_entry(prefix: str) -> str:
    """The table's entry for the router of the robot of ``prefix``, linked to this one: what
    that robot's principals among the remote ones may do on that robot's keys alone."""
    return f"{ROUTER_PRINCIPAL}@{prefix}"


def merged(accesses: Iterable[Access]) -> Access:
    """What any of ``accesses`` allows, in order."""
    out: dict[str, dict[str, None]] = {}
    for a in accesses:
        for kind, exprs in dataclasses.asdict(a).items():
            out.setdefault(kind, {}).update(dict.fromkeys(exprs))
    return Access(**{kind: tuple(exprs) for kind, exprs in out.items()})


def may_put(
    keys: Keys,
    cameras: str | Mapping[str, str],
    principal: str,
    *,
    live_sensors: bool = True,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> tuple[str, ...]:
    """The keys ``principal`` may put on (documentation and tests read the same table)."""
    allowed = stack_table(keys, cameras, live_sensors, workers).get(principal)
    return allowed.put if allowed else ()


def congestion_overwritten(
    keys: Keys,
    cameras: str | Mapping[str, str],
    *,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
    prefixes: Iterable[str] = (),
) -> tuple[str, ...]:
    """The keys on which the router puts congestion control DROP on every sample it takes in,
    whatever its publisher asked for: every key any principal may put on (a replay's too),
    but the e-stop. A client's BLOCK there would make the router wait on a full link (a frozen
    listener's) and hold up everyone's traffic behind it (docs/security.md, "QoS by role")."""
    puts: dict[str, None] = {}
    for live in (True, False):
        for allowed in stack_table(keys, cameras, live, workers, prefixes).values():
            puts.update(dict.fromkeys(allowed.put))
    return tuple(k for k in puts if k != keys.estop())


def may_announce(
    keys: Keys,
    cameras: str | Mapping[str, str],
    principal: str,
    *,
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> tuple[str, ...]:
    """The liveliness tokens ``principal`` may declare (its health, a worker's pool and serving
    tokens)."""
    allowed = stack_table(keys, cameras, workers=workers).get(principal)
    return allowed.token if allowed else ()


def may_read(keys: Keys, cameras: str | Mapping[str, str], principal: str) -> tuple[str, ...]:
    """The key expressions ``principal`` may subscribe to (within which any subscription)."""
    allowed = stack_table(keys, cameras).get(principal)
    return allowed.read if allowed else ()
