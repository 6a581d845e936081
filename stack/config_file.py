"""Reading and writing the stack's TOML config, with environment overrides.

One file (``deploy/stack.toml`` by default) configures the whole stack, one table per service
(the dataclasses of stack/config.py, each service's from its contract). Environment variables
override single fields:
``STACK__<TABLE>__<FIELD>=<TOML value>``, e.g. ``STACK__DETECTOR__BACKEND=cuda`` or
``STACK__CONTROLLER__TARGET_CLASSES='["cup"]'``, and a further camera's as
``STACK__CAMERAS__<NAME>__<FIELD>`` (the camera itself is added in the file). Unknown tables or
fields, wrong types and out-of-range values raise ConfigError at start-up, so a typo stops the
service with one line instead of being silently ignored. A profile can start with
``extends = "stack.toml"`` and state only the fields it changes (``deploy/secure.toml`` does):
tables merge field by field at every depth (``[cameras.rear] rate_hz = 5.0`` changes the rear
camera's rate and keeps the rest of it); any other value, a list included, replaces the base's
whole.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from common.errors import ConfigError
from common.settings import DEFAULT_CONFIG
from services.camera.contract import CameraSettings
from stack.config import Config
from stack.config_read import (
    ENV_PREFIX,
)
from stack.config_read import (
    blame as _blame,
)
from stack.config_read import (
    build as _build,
)
from stack.config_read import (
    check_tables as _check_tables,
)
from stack.config_read import (
    env_value as _env_value,
)
from stack.config_read import (
    merge as _merge,
)
from stack.config_read import (
    read as _read,
)


def _env_overrides(
    environ: Mapping[str, str], further_cameras: Iterable[str]
) -> dict[str, dict[str, Any]]:
    """Collect ``STACK__TABLE__FIELD=value`` overrides, and ``STACK__CAMERAS__NAME__FIELD``
    ones of the further cameras (``further_cameras``, those the file names); values are TOML,
    else plain strings.

    A misspelt table, camera or field is blamed on the variable, not on the config file (and so
    is a bad value: see :func:`_blame`)."""
    out: dict[str, dict[str, Any]] = {}
    hints = typing.get_type_hints(Config)
    for name, raw in environ.items():
        if not name.startswith(ENV_PREFIX):
            continue
        parts = name[len(ENV_PREFIX) :].lower().split("__")
        if parts[0] == CAMERAS:
            camera, field = _camera_override(name, parts, further_cameras)
            out.setdefault(CAMERAS, {}).setdefault(camera, {})[field] = _env_value(raw)
            continue
        if len(parts) != 2:
            raise ConfigError(f"{name}: overrides look like {ENV_PREFIX}<TABLE>__<FIELD>")
        if parts[0] == "path" or parts[0] not in hints:
            known = sorted(set(hints) - {"path"})
            raise ConfigError(f"{name}: there is no table [{parts[0]}]; known: {known}")
        fields = {f.name for f in dataclasses.fields(hints[parts[0]])}
        if parts[1] not in fields:
            raise ConfigError(
                f"{name}: [{parts[0]}] has no setting {parts[1]!r}; known: {sorted(fields)}"
            )
        out.setdefault(parts[0], {})[parts[1]] = _env_value(raw)
    return out


def _camera_override(
    name: str, parts: list[str], further_cameras: Iterable[str]
) -> tuple[str, str]:
    """The camera and field of ``STACK__CAMERAS__<NAME>__<FIELD>`` (a name may itself hold
    ``__``). Only a camera the file has: a misspelt name must not add a camera."""
    if len(parts) < 3:
        raise ConfigError(
            f"{name}: a further camera's overrides look like {ENV_PREFIX}CAMERAS__<NAME>__<FIELD>"
        )
    camera, field = "__".join(parts[1:-1]), parts[-1]
    known = list(further_cameras)
    if camera not in known:
        raise ConfigError(
            f"{name}: no further camera {camera!r} in the config file; known: {known} (a "
            f"further camera is added in the file, as a [{CAMERAS}.<name>] table; the first "
            f"camera's settings are {ENV_PREFIX}CAMERA__<FIELD>)"
        )
    fields = sorted(f.name for f in dataclasses.fields(CameraSettings))
    if field not in fields:
        raise ConfigError(f"{name}: [{CAMERAS}.{camera}] has no setting {field!r}; known: {fields}")
    return camera, field


def load_config(path: str | Path | None = None, environ: Mapping[str, str] | None = None) -> Config:
    """Read the stack config (default ``deploy/stack.toml``), apply env overrides, validate."""
    cfg_path = Path(path) if path else DEFAULT_CONFIG
    data = _read(cfg_path, (cfg_path.resolve(),))
    _check_tables(cfg_path, data)
    overrides = _env_overrides(os.environ if environ is None else environ, data.get(CAMERAS, {}))
    _merge(data, overrides, cfg_path)
    hints = typing.get_type_hints(Config)
    tables = {f.name for f in dataclasses.fields(Config)} - {"path"}
    unknown = sorted(set(data) - tables)
    if unknown:
        raise ConfigError(f"{cfg_path}: unknown table(s) {unknown}; known: {sorted(tables)}")
    _check_services_named(cfg_path, data)
    built: dict[str, Any] = {}
    for table in sorted(tables - {CAMERAS}):  # [camera] before the cameras laid over it
        try:
            built[table] = _build(hints[table], table, data.get(table, {}))
        except ConfigError as exc:
            raise _blame(exc, table, overrides.get(table, {})) from exc
    built[CAMERAS] = _cameras(cfg_path, data, overrides.get(CAMERAS, {}))
    try:
        return Config(path=str(cfg_path), **built)
    except ConfigError as exc:
        raise _blame(exc, "sim", overrides.get("sim", {})) from exc


CAMERAS = "cameras"  # [cameras.<name>]: the further cameras, each [camera] with its changes


def _check_services_named(cfg_path: Path, data: Mapping[str, Any]) -> None:
    """A config that names a camera source (a real robot's camera) must say which services
    run: the default ones are the profile's simulated robot, whose frames and scans would
    stand in for the robot's own (issue 39)."""
    if "services" in data.get("supervisor", {}) or "source" not in data.get("camera", {}):
        return
    raise ConfigError(
        f"{cfg_path}: sets camera.source but not supervisor.services, whose default runs the "
        "simulated robot (deploy/stack.toml): name the services, e.g. [supervisor] services = "
        '["camera", "detector", "controller", "metrics"]'
    )


def _cameras(
    cfg_path: Path, data: Mapping[str, Any], overrides: Mapping[str, Mapping[str, Any]]
) -> tuple[tuple[str, CameraSettings], ...]:
    """The ``[cameras.<name>]`` tables, each laid over the [camera] table, in file order."""
    first = data.get("camera", {})
    out = []
    for name, values in data.get(CAMERAS, {}).items():
        table = f"{CAMERAS}.{name}"
        if not isinstance(values, dict):
            raise ConfigError(f"{cfg_path}: {table} must be a table, [{table}]")
        try:
            camera = _build(CameraSettings, table, {**first, **values})
        except ConfigError as exc:
            # CameraSettings checks itself as [camera]: name the further camera's own table.
            named = ConfigError(re.sub(r"^camera\.", f"{table}.", str(exc)))
            raise _blame(named, table, overrides.get(name, {})) from exc
        out.append((name, camera))
    return tuple(out)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, float) and not math.isfinite(value):
        return "inf" if value > 0 else "-inf"
    return repr(value)


def to_toml(config: Config) -> str:
    """The whole config as TOML that :func:`load_config` reads back to an equal Config."""
    lines: list[str] = []
    for table in dataclasses.fields(Config):
        if table.name in ("path", CAMERAS):
            continue
        lines.append(f"[{table.name}]")
        section = getattr(config, table.name)
        lines += [
            f"{f.name} = {_toml_value(getattr(section, f.name))}"
            for f in dataclasses.fields(section)
        ]
        lines.append("")
    for name, camera in config.cameras:
        lines.append(f"[{CAMERAS}.{name}]")
        lines += [
            f"{f.name} = {_toml_value(getattr(camera, f.name))}" for f in dataclasses.fields(camera)
        ]
        lines.append("")
    return "\n".join(lines)
