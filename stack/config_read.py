"""The config file read as TOML tables (with ``extends`` and the environment's overrides laid
over them) and the checks that turn one table into its settings dataclass: what
stack/config_file.py builds the whole Config from, apart from every service's settings.

:func:`load_bus_settings` reads only what a process needs to reach the stack, ``[zenoh]`` and
``[stack]``, checked exactly as :func:`stack.config_file.load_config` checks them. The e-stop
command uses it (services/controller/estop_command.py): importing every service's settings cost
its first put about a third of its start-up (docs/benchmarks.md, "E-stop: from the command to
the first zero"), and a mistake in a table it never reads (a misspelt detector setting) must
not hold up a stop.
"""

from __future__ import annotations

import dataclasses
import enum
import os
import re
import tomllib
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from common.errors import ConfigError
from common.settings import DEFAULT_CONFIG, REPO_ROOT, StackSettings, ZenohSettings

ENV_PREFIX = "STACK__"
EXTENDS = "extends"  # top-level key: the config file this one changes

_T = TypeVar("_T")


def coerce(where: str, value: Any, hint: Any) -> Any:
    """Check ``value`` against a field's type hint, converting TOML lists to tuples."""
    origin = typing.get_origin(hint)
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where} must be a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(coerce(where, v, args[0]) for v in value)
        if len(value) != len(args):
            raise ConfigError(f"{where} must have {len(args)} items, got {value!r}")
        return tuple(coerce(where, v, a) for v, a in zip(value, args, strict=True))
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


def build(cls: type[_T], table: str, values: Mapping[str, Any]) -> _T:
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(values) - names)
    if unknown:
        raise ConfigError(f"[{table}] has unknown setting(s) {unknown}; known: {sorted(names)}")
    kwargs = {k: coerce(f"{table}.{k}", v, hints[k]) for k, v in values.items()}
    return cls(**kwargs)


def env_value(raw: str) -> Any:
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw


def blame(error: ConfigError, table: str, fields: Mapping[str, Any]) -> ConfigError:
    """``error`` about a setting of ``table`` prefixed with the variable that set it, when an
    environment override did (``STACK__SIM__LASER_RAYS: sim.laser_rays must be ...``)."""
    text = str(error)
    variable = ENV_PREFIX + "__".join(table.split(".")).upper()  # cameras.rear: CAMERAS__REAR
    for name in fields:
        if re.search(rf"(?<![\w.]){re.escape(table)}\.{re.escape(name)}(?!\w)", text):
            return ConfigError(f"{variable}__{name.upper()}: {text}")
    return error


def read(cfg_path: Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
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
    merged = read(base_path, (*seen, base_path))
    check_tables(cfg_path, data)
    merge(merged, data, cfg_path)
    return merged


def check_tables(cfg_path: Path, data: Mapping[str, Any]) -> None:
    for table, values in data.items():
        if not isinstance(values, dict):
            raise ConfigError(f"{cfg_path}: [{table}] must be a table")


def merge(base: dict[str, Any], changes: Mapping[str, Any], where: Path, path: str = "") -> None:
    """Lay ``changes`` (from the file ``where``) over ``base``, in place: a table field by
    field, at every depth; any other value, a list included, replaces the base's whole."""
    for key, value in changes.items():
        dotted = f"{path}.{key}" if path else key
        current = base.get(key)
        if isinstance(current, dict) and isinstance(value, dict):
            merge(current, value, where, dotted)
        elif isinstance(current, dict):
            raise ConfigError(
                f"{where}: {dotted} must be a table, [{dotted}], as in the file it extends"
            )
        else:
            base[key] = value


def estop_file_path(prefix: str, estop_file: str) -> Path:
    """Where the controller of stack ``prefix`` keeps its latched e-stop: ``estop_file``
    (``controller.estop_file``; relative to the repository) or, empty, one file per prefix."""
    name = estop_file or f"state/estop-{prefix.replace('/', '_')}.json"
    path = Path(name).expanduser()
    return path if path.is_absolute() else REPO_ROOT / path


def load_estop_file_path(
    path: str | Path | None = None, environ: Mapping[str, str] | None = None
) -> Path:
    """The controller's e-stop file as the config names it (``stack.prefix`` and
    ``controller.estop_file``, with ``extends`` and the environment's overrides), read without
    building any settings: the e-stop command's local road (common/estop_local.py) needs it
    before anything else. ConfigError when the file cannot be read or the two values are not
    text; the full check is the Zenoh road's."""
    cfg_path = Path(path) if path else DEFAULT_CONFIG
    data = read(cfg_path, (cfg_path.resolve(),))
    env = os.environ if environ is None else environ
    values = []
    prefix = next(f.default for f in dataclasses.fields(StackSettings) if f.name == "prefix")
    for table, name, default in (
        ("stack", "prefix", prefix),
        ("controller", "estop_file", ""),
    ):
        raw = env.get(f"{ENV_PREFIX}{table.upper()}__{name.upper()}")
        value = env_value(raw) if raw is not None else data.get(table, {}).get(name, default)
        if not isinstance(value, str):
            raise ConfigError(f"{table}.{name} must be text, got {value!r:.40}")
        values.append(value)
    return estop_file_path(values[0], values[1])


def load_bus_settings(
    path: str | Path | None = None, environ: Mapping[str, str] | None = None
) -> tuple[ZenohSettings, StackSettings]:
    """The ``[zenoh]`` and ``[stack]`` tables of the config (default ``deploy/stack.toml``),
    with their ``extends`` and their ``STACK__ZENOH__*`` and ``STACK__STACK__*`` overrides, as
    :func:`stack.config_file.load_config` gives them. No other table or variable is read."""
    cfg_path = Path(path) if path else DEFAULT_CONFIG
    data = read(cfg_path, (cfg_path.resolve(),))
    check_tables(cfg_path, {t: v for t, v in data.items() if t in ("zenoh", "stack")})
    env = os.environ if environ is None else environ
    built: list[Any] = []
    for table, cls in (("zenoh", ZenohSettings), ("stack", StackSettings)):
        names = {f.name for f in dataclasses.fields(cls)}
        overrides: dict[str, Any] = {}
        for name, raw in env.items():
            parts = name[len(ENV_PREFIX) :].lower().split("__")
            if name.startswith(ENV_PREFIX) and len(parts) == 2 and parts[0] == table:
                if parts[1] not in names:
                    raise ConfigError(
                        f"{name}: [{table}] has no setting {parts[1]!r}; known: {sorted(names)}"
                    )
                overrides[parts[1]] = env_value(raw)
        values = {**data.get(table, {}), **overrides}
        try:
            built.append(build(cls, table, values))
        except ConfigError as exc:
            raise blame(exc, table, overrides) from exc
    return built[0], built[1]
