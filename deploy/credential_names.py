"""Whose credentials ``zstack credentials`` makes (deploy/credentials.py writes them): each
principal by its name (common/security.py: ``<stack.prefix>/<role>``, a detector worker's
``<pool>/<worker>``, each router's ``<prefix>/supervisor``), for one config or several
(``--robot``: each
further robot's config, so that one run and one CA serve a site), which it leaves out and why,
and which earlier files it removes with ``--force``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from common.errors import ConfigError
from common.security import (
    ca_file,
    ca_key_file,
    cert_file,
    is_router,
    key_file,
    password_file,
    role_of,
    stack_principals,
)
from common.settings import is_detector_service, service_package
from stack.config import Config
from stack.principals import TOOL_PRINCIPALS, running_principals, service_principals

#: The suffixes of a principal's own files (common/security.py).
_OWN_FILES = ("*.password", "*.key", "*.pem")


def credential_workers(config: Config, others: Sequence[str]) -> tuple[str, ...]:
    """The detector workers of other hosts to make principals for, by role: ``others`` (by
    name), then those among the config's ``zenoh.remote_principals``; ConfigError, one line,
    for a name no worker can have (a qualified one included: the pool's prefix is the
    config's, ``detector.pool_prefix``)."""
    for name in others:
        if not is_detector_service(name):
            raise ConfigError(
                f"--worker {name!r} is not a detector worker's name: detector, detector_<n>, "
                "detector_<worker_id> or detector_<worker_id>_<n> (docs/detector.md), without "
                "its pool's prefix (the config's detector.pool_prefix, or its stack.prefix)"
            )
    remote = [p for p in config.zenoh.remote_principals if is_detector_service(p)]
    return tuple(dict.fromkeys((*others, *remote)))


def credential_principals(
    config: Config, others: Sequence[str] = ()
) -> tuple[tuple[str, ...], dict[str, str]]:
    """(the principals to make secrets for, by name, {each principal of the config's stack
    left out, by name: why}): those the config has a use for (stack.principals.running_principals:
    the router, the processes of ``supervisor.services``, the tools, ``zenoh.remote_principals``)
    and the other hosts' workers named in ``others`` (``--worker``), each as the config's
    (:meth:`Config.principal`). ConfigError, one line, for a bad name."""
    workers = credential_workers(config, others)
    remote = (*config.zenoh.remote_principals, *workers)
    try:
        roles = running_principals(
            config.supervisor.services, config.camera_services, config.detector_services, remote
        )
        made = tuple(config.principal(p) for p in roles)
    except ValueError as exc:
        raise ConfigError(str(exc)) from exc
    every = stack_principals(config.camera_services, config.detector_services)
    left_out = {
        config.principal(p): f"the config runs no {service_package(p)} service "
        "(supervisor.services)"
        for p in every
        if p not in roles
    }
    return made, left_out


def _found(directory: Path) -> set[str]:
    """The principals whose files lie in ``directory`` or its subfolders, by name."""
    shared = (ca_file(directory), ca_key_file(directory))
    return {
        path.relative_to(directory).with_suffix("").as_posix()
        for pattern in _OWN_FILES
        for path in directory.rglob(pattern)
        if path not in shared
    }


def remove_stale(directory: Path, made: tuple[str, ...]) -> list[str]:
    """Remove the password, key and certificate of every principal in ``directory`` or its
    subfolders other than ``made`` (left there by an earlier run for a config that ran more,
    or by an older version that named principals by role alone), and each subfolder that
    leaves empty: signed by a CA no longer used and absent from the new user dictionary, they
    could log in nowhere, but an old-style certificate among them would still stop every TLS
    session (common/certificates.py) and a copy of the folder would spread them. Returns their
    principals, sorted."""
    stale = sorted(_found(directory) - set(made))
    for p in stale:
        for path in (password_file(directory, p), key_file(directory, p), cert_file(directory, p)):
            try:
                path.unlink(missing_ok=True)  # a link goes, never what it points to
            except OSError as exc:
                raise ConfigError(f"cannot remove {path}: {exc.strerror}") from exc
    folders = sorted((p for p in directory.rglob("*") if p.is_dir() and not p.is_symlink()),
                     key=lambda p: len(p.parts), reverse=True)  # fmt: skip
    for folder in folders:
        if not any(folder.iterdir()):
            folder.rmdir()
    return stale


def made_groups(config: Config, made: Sequence[str], robots: Sequence[Config] = ()) -> str:
    """``made`` in groups, each with what it is for: "supervisor (the router); stack/sim, ...
    (supervisor.services); ..."; each of ``robots`` (``--robot``) a group of its own."""
    services = {
        config.principal(p)
        for p in service_principals(
            config.supervisor.services, config.camera_services, config.detector_services
        )
    }
    tools = {config.principal(p) for p in TOOL_PRINCIPALS}
    groups: dict[str, list[str]] = {
        "the routers": [p for p in made if is_router(p)],
        "supervisor.services": [p for p in made if p in services],
        "the tools: zstack record and play, estop, query": [
            p for p in made if p in tools and p not in services
        ],
    }
    for robot in robots:
        mine = {
            robot.principal(p)
            for p in stack_principals(robot.camera_services, robot.detector_services)
        }
        grouped = {p for ps in groups.values() for p in ps}
        mine |= {robot.principal(p) for p in (*TOOL_PRINCIPALS, *robot.zenoh.remote_principals)}
        groups[f"--robot {robot.path}"] = [p for p in made if p in mine and p not in grouped]
    grouped = {p for ps in groups.values() for p in ps}
    groups["other hosts': zenoh.remote_principals, --worker"] = [
        p for p in made if p not in grouped
    ]
    return "; ".join(f"{', '.join(ps)} ({why})" for why, ps in groups.items() if ps)


def chosen_lines(
    config: Config,
    made: tuple[str, ...],
    left_out: dict[str, str],
    removed: list[str],
    again: str = "",
    robots: Sequence[Config] = (),
) -> list[str]:
    """Which principals got secrets, which were left out and why, whose earlier secrets were
    removed, and how to make them again (``again``: the command's options): one line each."""
    lines = [f"made for {made_groups(config, made, robots)}"]
    for p, why in left_out.items():
        gone = "; its earlier secrets removed" if p in removed else ""
        lines.append(f"{p}: not made, {why}{gone}")
    lines += [
        f"{p}: earlier secrets removed, "
        + (
            "named by its role alone (an older version's)"
            if p == role_of(p)
            else "neither the config nor --worker names it"
        )
        for p in removed
        if p not in left_out
    ]
    if left_out:
        lines.append(
            "after adding a service to supervisor.services, make them again: `zstack "
            f"credentials --config {config.path}{again} --force`"
        )
    return lines
