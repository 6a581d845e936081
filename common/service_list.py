"""The stack's services: the one list every other list of them is made from.

A service is its folder, ``services/<name>/`` (``contract.py``, ``service.py``,
``__main__.py``), and its line here. From this list come the names ``supervisor.services`` may
run and the metrics service believes counters from (common/settings.py), each service's
principal (common/security.py), the stack config's tables (each contract's ``SETTINGS_TABLES``,
checked against stack/config.py's ``Config``), the router's access table (each contract's
``access``, stack/access_table.py), which services feed live sensors (a contract's ``LIVE_SENSOR``)
and which beat for the watchdog (a contract's ``HEARTBEAT``; stack/contracts.py reads them).

Pure and plain: common/ imports no service, so this holds names only.
"""

from __future__ import annotations

#: In start order: the recorder first, so that it hears the others from their start; the depth
#: scan stage before the controller, which reads its scans; the viewer after what it watches.
SERVICES = (
    "recorder",
    "camera",
    "sim",
    "ros2",
    "detector",
    "depthscan",
    "controller",
    "metrics",
    "viewer",
)
