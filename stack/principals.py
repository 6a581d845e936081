"""Which principals a stack has: those of the processes a supervisor starts
(:func:`service_principals`), those it has a use for (:func:`running_principals`: the router,
the processes of ``supervisor.services``, the tools and the other hosts' principals), and the
cameras other hosts run (:func:`remote_cameras`). Only the principals a stack has a use for
get a secret, while the rules (stack/access.py, from stack/access_table.py) are built for
every principal of the stack: one without a secret cannot log in at all. Pure."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from common.errors import ConfigError
from common.security import (
    DETECTOR_PRINCIPAL,
    ROUTER_PRINCIPAL,
    camera_services,
    role_of,
    stack_principals,
)
from common.settings import check_camera_name, is_detector_service, service_package
from services.controller import contract as controller
from services.recorder import contract as recorder

#: A principal that may watch (subscribe, query) but publishes nothing: status lines, tests.
OBSERVER_PRINCIPAL = "observer"
#: The principals of the tools people run against a running stack, whatever services it runs:
#: ``zstack record`` and ``zstack play`` (as the recorder), ``zstack estop``, and the observer
#: (status lines, ``zstack query``, reports, scenario runs, tests).
TOOL_PRINCIPALS = (recorder.SERVICE, controller.ESTOP_PRINCIPAL, OBSERVER_PRINCIPAL)


def check_remote(known: Iterable[str], remote: Iterable[str]) -> None:
    """ValueError, one line, for a name among ``remote`` that is none of ``known`` (or is the
    router's), or is written qualified (``site/robot1/camera``: the roles are written, and
    qualified here as this stack's, docs/security.md)."""
    known = [p for p in known if p != ROUTER_PRINCIPAL]
    if scoped := [p for p in dict.fromkeys(remote) if "/" in p]:
        raise ValueError(
            f"zenoh.remote_principals names {', '.join(map(repr, scoped))}: write the roles "
            f"({', '.join(repr(role_of(p)) for p in scoped)}); each router qualifies them as its "
            "own robot's (<stack.prefix>/<role>) or, for a detector worker, its pool's "
            "(<detector.pool_prefix>/<worker>)"
        )
    unknown = [p for p in dict.fromkeys(remote) if p not in known]
    if unknown:
        raise ValueError(
            f"zenoh.remote_principals names {', '.join(map(repr, unknown))}: not a principal of "
            f"this stack (known: {', '.join(known)}; another host's detector worker: "
            "detector_<worker_id>)"
        )


def service_principals(
    services: Iterable[str],
    cameras: str | Mapping[str, str],
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
) -> tuple[str, ...]:
    """The principals of the processes a supervisor that runs ``services``
    (``supervisor.services``) starts, as deploy/processes.py starts them: each camera's for
    ``camera``, each of ``workers`` for ``detector``, the service's own name otherwise."""
    out: list[str] = []
    for service in services:
        if service == "camera":
            out += camera_services(cameras).values()
        elif service == DETECTOR_PRINCIPAL:
            out += workers
        else:
            out.append(service)
    return tuple(dict.fromkeys(out))


def running_principals(
    services: Iterable[str],
    cameras: str | Mapping[str, str],
    workers: Iterable[str] = (DETECTOR_PRINCIPAL,),
    remote: Iterable[str] = (),
) -> tuple[str, ...]:
    """The principals a stack that runs ``services`` has a use for: the router's, its
    processes' (:func:`service_principals`), the tools' (TOOL_PRINCIPALS) and those other hosts
    run (``remote``: ``zenoh.remote_principals``, another host's workers), in the order of
    :func:`stack_principals`. What ``zstack credentials`` makes; a principal left out (the
    ``camera`` of a stack that runs the simulator) has no secret, so nobody can log in as it.
    ValueError, one line, for a ``remote`` name that is no principal of the stack."""
    remote = tuple(remote)
    workers = tuple(workers)
    remote_workers = [p for p in remote if is_detector_service(p)]
    every = stack_principals(
        remote_cameras(camera_services(cameras), remote), (*workers, *remote_workers)
    )
    check_remote(every, remote)
    wanted = {ROUTER_PRINCIPAL, *service_principals(services, cameras, workers)}
    wanted |= {*TOOL_PRINCIPALS, *remote}
    return tuple(p for p in every if p in wanted)


def remote_cameras(cameras: Mapping[str, str], remote: Iterable[str]) -> dict[str, str]:
    """``cameras`` (``{camera: principal}``) with each further camera another host runs:
    ``camera_<name>`` among the ``remote`` principals is camera ``<name>``, so that a GPU box,
    which has no camera table, admits the robot's cameras over the link. ValueError, one
    line, for a name that is no camera's."""
    out = dict(cameras)
    for principal in remote:
        if service_package(principal) != "camera" or principal in out.values():
            continue
        name = principal.removeprefix("camera_")
        try:
            check_camera_name(name)
        except ConfigError as exc:
            raise ValueError(f"zenoh.remote_principals names {principal!r}: {exc}") from exc
        out[name] = principal
    return out
