"""The code's defaults and the shipped profile are one source (issue 39, item 6): a config
that does not extend deploy/stack.toml gets what ``make run`` gets, field by field."""

from __future__ import annotations

import dataclasses
import tomllib

from common.settings import DEFAULT_CONFIG
from stack.config import Config
from stack.config_file import load_config


def test_every_settings_default_is_the_shipped_profiles_value() -> None:
    stated = tomllib.loads(DEFAULT_CONFIG.read_text(encoding="utf-8"))
    profile = load_config(DEFAULT_CONFIG, environ={})
    code = Config()
    differences, compared = [], 0
    for table in dataclasses.fields(Config):
        if table.name in ("path", "cameras"):  # [cameras.<name>]: [camera] tables laid over it
            continue
        ours, shipped = getattr(code, table.name), getattr(profile, table.name)
        for f in dataclasses.fields(ours):
            compared += 1
            if f.name not in stated.get(table.name, {}):
                differences.append(f"{table.name}.{f.name}: not in {DEFAULT_CONFIG.name}")
            elif getattr(ours, f.name) != getattr(shipped, f.name):
                differences.append(
                    f"{table.name}.{f.name}: code {getattr(ours, f.name)!r}, "
                    f"{DEFAULT_CONFIG.name} {getattr(shipped, f.name)!r}"
                )
    assert compared > 200  # every table's every field (222 today), not a few
    assert differences == [], "\n".join(differences)


def test_a_standalone_config_gets_the_profiles_values(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """docs/pool.md's GPU-box and two-robots configs state only what they change, without
    ``extends``: what they leave out is what ``make run`` has (follow by the laser, 1.0 m)."""
    path = tmp_path / "robot.toml"
    path.write_text('[zenoh]\nmode = "client"\n\n[supervisor]\nservices = ["sim", "controller"]\n')
    alone = load_config(path, environ={})
    profile = load_config(DEFAULT_CONFIG, environ={})
    assert alone.controller == profile.controller
    assert alone.detector == profile.detector
    assert alone.sim == profile.sim
