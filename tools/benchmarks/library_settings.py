"""Comparison 2 of tools/benchmarks/library_choices.py: stack/config_file.py +
common/setting_checks.py against pydantic-settings and msgspec (``msgspec.toml`` + ``Meta``
constraints): load time of deploy/stack.toml, the error line for bad configs, dependency size,
the lines each would replace."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import os
import re
import tempfile
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

from common.clock import perf_s
from common.errors import ConfigError
from common.setting_checks import declared_bounds, declared_lengths
from common.settings import DEFAULT_CONFIG
from stack.config import Config
from stack.config_file import load_config
from tools.benchmarks.library_shared import (
    REPO,
    code_lines,
    cold_import_ms,
    missing,
    per_call_us,
    ratio,
    site_size_mb,
)


def _tables() -> dict[str, type]:
    hints = typing.get_type_hints(Config)
    return {f.name: hints[f.name] for f in dataclasses.fields(Config) if f.name != "path"}


def _default_of(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    assert f.default_factory is not dataclasses.MISSING
    return f.default_factory()


def _constrained(
    hint: Any, bound: tuple[float, float] | None, length: Any, meta: Callable[..., Any]
) -> Any:
    """``hint`` with our Range (each item of a tuple) and Length as library constraints;
    ``meta(ge=, le=)`` / ``meta(min_length=, max_length=)`` makes the library's annotation."""
    # Annotated made with run-time values: through Any, as mypy cannot check such a type.
    annotated: Any = Annotated
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if bound is not None:
            item = annotated[args[0], meta(ge=bound[0], le=bound[1])]
            args = (item, ...) if args[-1] is Ellipsis else (item,) * len(args)
        hint = tuple[args]  # type: ignore[valid-type]
        if length is not None:
            hint = Annotated[hint, meta(min_length=int(length[0]), max_length=int(length[1]))]
        return hint
    if bound is not None:
        return Annotated[hint, meta(ge=bound[0], le=bound[1])]
    return hint


def build_pydantic_settings() -> Callable[[Path], Any]:
    """pydantic-settings models made from our dataclasses: their types, Range as Field(ge,
    le), Length as Field(min/max_length), unknown keys forbidden, frozen; TOML file source and
    STACK__TABLE__FIELD environment overrides. Our dataclasses' own cross-field checks run as
    an after-validator (constructing the dataclass), as they would stay after adopting it."""
    from pydantic import ConfigDict, Field, create_model, model_validator
    from pydantic_settings import BaseSettings, SettingsConfigDict, TomlConfigSettingsSource

    def meta(**kw: Any) -> Any:
        if "ge" in kw:
            kw["allow_inf_nan"] = False  # our bounds refuse NaN and inf
        return Field(**kw)

    models: dict[str, Any] = {}
    for table, cls in _tables().items():
        hints = typing.get_type_hints(cls)
        bounds, lengths = declared_bounds(cls), declared_lengths(cls)
        fields: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            hint = _constrained(hints[f.name], bounds.get(f.name), lengths.get(f.name), meta)
            fields[f.name] = (hint, _default_of(f))

        def cross(self: Any, _cls: type = cls) -> Any:
            _cls(**{f.name: getattr(self, f.name) for f in dataclasses.fields(_cls)})
            return self

        models[table] = create_model(
            f"{cls.__name__}Model",
            __config__=ConfigDict(extra="forbid", frozen=True),
            __validators__={"cross": model_validator(mode="after")(cross)},
            **fields,
        )
    holder: dict[str, Path] = {}

    def sources(
        cls: Any,
        settings_cls: Any,
        init_settings: Any,
        env_settings: Any,
        dotenv_settings: Any,
        file_secret_settings: Any,
    ) -> tuple[Any, ...]:
        return (env_settings, TomlConfigSettingsSource(settings_cls, holder["path"]))

    namespace: dict[str, Any] = {
        "__annotations__": dict(models),
        "model_config": SettingsConfigDict(
            extra="forbid", frozen=True, env_prefix="STACK__", env_nested_delimiter="__"
        ),
        "settings_customise_sources": classmethod(sources),
        **{table: Field(default_factory=model) for table, model in models.items()},
    }
    full = type("StackConfigModel", (BaseSettings,), namespace)

    def load(path: Path) -> Any:
        holder["path"] = path
        return full()

    return load


def build_msgspec_settings() -> Callable[[Path], Any]:
    """msgspec Structs made from our dataclasses (types, Range and Length as Meta, unknown
    fields forbidden, frozen), decoded with msgspec.toml; cross-field checks as __post_init__
    constructing our dataclass. No environment overrides: msgspec has none (ours would stay)."""
    import msgspec

    def meta(**kw: Any) -> Any:
        return msgspec.Meta(**kw)

    structs: list[tuple[str, Any, Any]] = []
    for table, cls in _tables().items():
        hints = typing.get_type_hints(cls)
        bounds, lengths = declared_bounds(cls), declared_lengths(cls)
        fields = [
            (
                f.name,
                _constrained(hints[f.name], bounds.get(f.name), lengths.get(f.name), meta),
                msgspec.field(default_factory=functools.partial(_default_of, f)),
            )
            for f in dataclasses.fields(cls)
        ]

        def post_init(self: Any, _cls: type = cls) -> None:
            try:
                _cls(**{f.name: getattr(self, f.name) for f in dataclasses.fields(_cls)})
            except ConfigError as exc:
                raise ValueError(str(exc)) from None

        struct = msgspec.defstruct(
            f"{cls.__name__}Struct",
            fields,
            kw_only=True,
            frozen=True,
            forbid_unknown_fields=True,
            namespace={"__post_init__": post_init},
        )
        structs.append((table, struct, msgspec.field(default_factory=struct)))
    top = msgspec.defstruct(
        "ConfigStruct", structs, kw_only=True, frozen=True, forbid_unknown_fields=True
    )

    def load(path: Path) -> Any:
        return msgspec.toml.decode(path.read_bytes(), type=top)

    return load


def _first_line(exc: BaseException) -> str:
    lines = [ln for ln in str(exc).splitlines() if ln.strip()]
    text = " | ".join(ln.strip() for ln in lines[:3])
    return f"{type(exc).__name__}: {text}" + (
        f" (+{len(lines) - 3} lines)" if len(lines) > 3 else ""
    )


BAD_CONFIGS: tuple[tuple[str, str, str, dict[str, str]], ...] = (
    # (what, line pattern in stack.toml, replacement, environment)
    ("typo in a key: tracker.hihg_score", r"^high_score = ", "hihg_score = ", {}),
    ("out of range: controller.max_linear = 50", r"^max_linear = 0\.5", "max_linear = 50.0", {}),
    ('wrong type: camera.rate_hz = "fast"', r"^rate_hz = 10\.0", 'rate_hz = "fast"', {}),
    ('wrong type: camera.rate_hz = "10"', r"^rate_hz = 10\.0", 'rate_hz = "10"', {}),
    ("env typo in a table: STACK__TRACKR__IOU", "", "", {"STACK__TRACKR__IOU": "0.3"}),
    ("env typo in a key: STACK__TRACKER__IUO", "", "", {"STACK__TRACKER__IUO": "0.3"}),
)


@dataclasses.dataclass
class _Env:
    values: dict[str, str]

    def __enter__(self) -> None:
        self.saved = {k: os.environ.get(k) for k in self.values}
        os.environ.update(self.values)

    def __exit__(self, *exc: object) -> None:
        for k, v in self.saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _function_lines(path: Path, names: set[str]) -> int:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return sum(
        (node.end_lineno or node.lineno) - node.lineno + 1
        for node in tree.body
        if isinstance(node, ast.FunctionDef | ast.ClassDef) and node.name in names
    )


def settings_section(args: argparse.Namespace) -> None:
    print("\n== 2. Settings loader: stack/config_file.py + setting_checks.py vs libraries ==")
    loaders: list[tuple[str, Callable[[Path], Any], str]] = [
        ("ours", lambda p: load_config(p), "stack.config_file")
    ]
    for label, build, package, module in (
        ("pydantic-settings", build_pydantic_settings, "pydantic-settings", "pydantic_settings"),
        ("msgspec", build_msgspec_settings, "msgspec", "msgspec"),
    ):
        try:
            t0 = perf_s()
            loader = build()
            build_ms = (perf_s() - t0) * 1e3
            loaders.append((label, loader, module))
            print(
                f"  {label}: models built from our dataclasses in {build_ms:.0f} ms "
                "(paid once per process, at start-up)"
            )
        except ImportError:
            missing(package, f"{label} comparison")
    path = DEFAULT_CONFIG
    saved = {k: os.environ.pop(k) for k in list(os.environ) if k.startswith("STACK__")}
    try:
        print(f"  load + validate {path.relative_to(REPO)} (TOML parse included), per load:")
        ref = None
        for label, loader, module in loaders:
            us = per_call_us(functools.partial(loader, path))
            ref = us if ref is None else ref
            imp = cold_import_ms(module)
            print(
                f"    {label:<18} {us:>8.0f} us  ({ratio(us, ref)} ours)   "
                f"cold `import {module}`: {imp:.0f} ms"
            )
        text = path.read_text(encoding="utf-8")
        with tempfile.TemporaryDirectory() as tmp:
            for what, pattern, repl, env in BAD_CONFIGS:
                bad = Path(tmp) / "stack.toml"
                if pattern:
                    new, count = re.subn(pattern, repl, text, count=1, flags=re.M)
                    assert count == 1, f"{pattern!r} not in {path}"
                else:
                    new = text
                bad.write_text(new, encoding="utf-8")
                print(f"  bad config: {what}")
                for label, loader, _ in loaders:
                    if env and label == "msgspec":
                        print(f"    {label:<18} n/a: no environment source (ours would stay)")
                        continue
                    with _Env(env):
                        try:
                            loader(bad)
                            result = "ACCEPTED (no error)"
                        except Exception as exc:  # each library's own error type, shown
                            result = _first_line(exc)
                    print(f"    {label:<18} {result}")
    finally:
        os.environ.update(saved)
    cf, sc = REPO / "common" / "config_file.py", REPO / "common" / "setting_checks.py"
    pyd = _function_lines(cf, {"_coerce", "_build", "_env_overrides", "_blame"}) + _function_lines(
        sc, {"check_bounds", "check_lengths"}
    )
    msp = _function_lines(cf, {"_coerce", "_build"}) + _function_lines(
        sc, {"check_bounds", "check_lengths"}
    )
    total = code_lines(cf) + code_lines(sc)
    bounds_lines = sum(
        len(declared_bounds(cls)) + len(declared_lengths(cls)) for cls in _tables().values()
    )
    print(
        f"  our loader: {total} lines (config_file.py {code_lines(cf)}, setting_checks.py "
        f"{code_lines(sc)}); bounded fields across the tables: {bounds_lines}"
    )
    print(
        f"  lines a library would replace: pydantic-settings {pyd} (_coerce, _build, "
        f"_env_overrides, _blame, check_bounds, check_lengths); msgspec {msp} (no env source)"
    )
    print(
        "  (our Range/Length on the type hints would become one Field/Meta per bounded "
        "field: no lines saved there)"
    )
    for label, dists in (
        (
            "pydantic-settings",
            [
                "pydantic-settings",
                "pydantic",
                "pydantic-core",
                "annotated-types",
                "typing-inspection",
                "python-dotenv",
            ],
        ),
        ("msgspec", ["msgspec"]),
    ):
        size = site_size_mb(dists)
        if size is not None:
            print(f"  dependency size: {label}: {size:.1f} MB installed ({', '.join(dists)})")
