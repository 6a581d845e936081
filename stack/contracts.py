"""Each service's contract (``services/<name>/contract.py``), found by its name in the one list
of services (common/service_list.py), and what the stack reads of them all: the settings tables
each declares (``SETTINGS_TABLES``, the stack config's tables: stack/config.py), whether it
feeds a live robot's sensors (``LIVE_SENSOR``: no recording may be played onto its keys) and
whether its work loop beats for the watchdog (``HEARTBEAT``: counters on every pass,
deploy/watchdog.py). Its access (``access``) is read by stack/access_table.py.

Adding a service is its folder and its line in the list: nothing here names one.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Iterable
from types import ModuleType

from common.service_list import SERVICES

#: The tables of the stack config that are no service's own: how to join the bus, the stack's
#: names, the further cameras ([cameras.<name>], each a [camera] table) and the supervisor's.
SHARED_TABLES = ("zenoh", "stack", "cameras", "supervisor")


def contract(service: str) -> ModuleType:
    """The contract module of ``service`` (a name of the list: ``camera``, not ``camera_rear``)."""
    return importlib.import_module(f"services.{service}.contract")


def contracts(services: Iterable[str] = SERVICES) -> dict[str, ModuleType]:
    """``{service: its contract}`` for each of ``services``, in order."""
    return {s: contract(s) for s in services}


def settings_tables(services: Iterable[str] = SERVICES) -> dict[str, type]:
    """``{table: settings dataclass}`` of every table ``services`` declare, in order: each
    service's ``SETTINGS_TABLES`` (the detector's ``detector`` and ``tracker``). TypeError for a
    table two services declare."""
    out: dict[str, type] = {}
    for service, module in contracts(services).items():
        for table, cls in module.SETTINGS_TABLES.items():
            if table in out or table in SHARED_TABLES:
                raise TypeError(f"services.{service}.contract declares table [{table}] again")
            out[table] = cls
    return out


def check_config_tables(config: type, services: Iterable[str] = SERVICES) -> None:
    """TypeError, naming what to write, unless the dataclass ``config`` (stack/config.py's
    Config) has exactly one field per table the services declare, of the type declared, beside
    ``path`` and the SHARED_TABLES."""
    declared = settings_tables(services)
    fields = {f.name: f for f in dataclasses.fields(config)}
    own = {n for n in fields if n not in ("path", *SHARED_TABLES)}
    missing = [t for t in declared if t not in own]
    if missing:
        lines = "; ".join(
            f"{t}: {declared[t].__name__} = field(default_factory={declared[t].__name__})"
            for t in missing
        )
        raise TypeError(f"{config.__name__} lacks the table(s) its services declare: {lines}")
    extra = sorted(own - set(declared))
    if extra:
        raise TypeError(f"{config.__name__} has table(s) no listed service declares: {extra}")
    wrong = [t for t in declared if fields[t].type not in (declared[t], declared[t].__name__)]
    if wrong:
        raise TypeError(f"{config.__name__}'s table(s) {wrong} are not of their declared type")


def live_sensors(services: Iterable[str] = SERVICES) -> frozenset[str]:
    """The services (packages) that feed a live robot's sensors into the stack (their
    contracts' ``LIVE_SENSOR``): while one runs, no recording may be played onto its keys."""
    return frozenset(s for s, m in contracts(services).items() if getattr(m, "LIVE_SENSOR", False))


def heartbeat_services(services: Iterable[str] = SERVICES) -> frozenset[str]:
    """The services (packages) whose work loop publishes counters on every pass (their
    contracts' ``HEARTBEAT``): the watchdog takes a long silence of theirs for a hang."""
    return frozenset(s for s, m in contracts(services).items() if getattr(m, "HEARTBEAT", False))
