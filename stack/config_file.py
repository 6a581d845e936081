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
import enum
import math
import os
import re
import tomllib
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from common.errors import ConfigError
from common.settings import DEFAULT_CONFIG
from services.camera.contract import CameraSettings
from stack.config import Config

ENV_PREFIX = "STACK__"
EXTENDS = "extends"  # top-level key: the config file this one changes

_T = TypeVar("_T")


def _coerce(where: str, value: Any, hint: Any) -> Any:
    """Check ``value`` against a field's type hint, converting TOML lists to tuples."""
    origin = typing.get_origin(hint)
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where} must be a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(where, v, args[0]) for v in value)
        if len(value) != len(args):
            raise ConfigError(f"{where} must have {len(args)} items, got {value!r}")
        return tuple(_coerce(where, v, a) for v, a in zip(value, args, strict=True))
    if origin in (types.UnionType, typing.Union):
        raise ConfigError(f"{where}: unions are not supported in settings")
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        choices = [m.value for m in hint]
        if value not in choices:
            raise ConfigError(
                f"{where} must be one of {', '.join(map(str, choices))}, got {value!r}"
            )
        return hint(value)
    if hint is float and isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if hint in (int, str, bool) and type(value) is hint:
        return value
    raise ConfigError(f"{where} must be {getattr(hint, '__name__', hint)}, got {value!r}")


def _build(cls: type[_T], table: str, values: Mapping[str, Any]) -> _T:
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(values) - names)
    if unknown:
        raise ConfigError(f"[{table}] has unknown setting(s) {unknown}; known: {sorted(names)}")
    kwargs = {k: _coerce(f"{table}.{k}", v, hints[k]) for k, v in values.items()}
    return cls(**kwargs)


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


def _env_value(raw: str) -> Any:
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw


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


def _blame(error: ConfigError, table: str, fields: Mapping[str, Any]) -> ConfigError:
    """``error`` about a setting of ``table`` prefixed with the variable that set it, when an
    environment override did (``STACK__SIM__LASER_RAYS: sim.laser_rays must be ...``)."""
    text = str(error)
    variable = ENV_PREFIX + "__".join(table.split(".")).upper()  # cameras.rear: CAMERAS__REAR
    for name in fields:
        if re.search(rf"(?<![\w.]){re.escape(table)}\.{re.escape(name)}(?!\w)", text):
            return ConfigError(f"{variable}__{name.upper()}: {text}")
    return error


def _read(cfg_path: Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    """The TOML tables of ``cfg_path``, laid over those of the file its ``extends`` names
    (relative to it), field by field: a profile states only what it changes."""
    try:
        data = tomllib.loads(cfg_path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise ConfigError(f"{cfg_path}: config file not found") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{cfg_path}: cannot read config ({exc})") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{cfg_path}: not valid TOML ({exc})") from exc
    base = data.pop(EXTENDS, None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise ConfigError(f"{cfg_path}: {EXTENDS} must be a file name")
    base_path = (cfg_path.parent / base).resolve()
    if base_path in seen or len(seen) > 8:
        raise ConfigError(f"{cfg_path}: {EXTENDS} loops back to {base_path}")
    merged = _read(base_path, (*seen, base_path))
    _check_tables(cfg_path, data)
    _merge(merged, data, cfg_path)
    return merged


def _check_tables(cfg_path: Path, data: Mapping[str, Any]) -> None:
    for table, values in data.items():
        if not isinstance(values, dict):
            raise ConfigError(f"{cfg_path}: [{table}] must be a table")


def _merge(base: dict[str, Any], changes: Mapping[str, Any], where: Path, path: str = "") -> None:
    """Lay ``changes`` (from the file ``where``) over ``base``, in place: a table field by
    field, at every depth; any other value, a list included, replaces the base's whole."""
    for key, value in changes.items():
        dotted = f"{path}.{key}" if path else key
        current = base.get(key)
        if isinstance(current, dict) and isinstance(value, dict):
            _merge(current, value, where, dotted)
        elif isinstance(current, dict):
            raise ConfigError(
                f"{where}: {dotted} must be a table, [{dotted}], as in the file it extends"
            )
        else:
            base[key] = value


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
