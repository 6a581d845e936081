"""``load_bus_settings`` (stack/config_read.py): the [zenoh] and [stack] tables as
``load_config`` gives them, and nothing else read (the e-stop command's config); and
``load_estop_file_path``, the e-stop file as the whole config names it."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.errors import ConfigError
from common.settings import REPO_ROOT
from stack.config_file import load_config
from stack.config_read import load_bus_settings, load_estop_file_path

PROFILES = sorted((REPO_ROOT / "deploy").glob("*.toml"))
ENVIRONS = [
    {},
    {"STACK__CONTROLLER__ESTOP_FILE": "/var/lib/robot/estop.json"},
    {"STACK__ZENOH__ENDPOINT": '"tcp/10.0.0.2:7500"', "STACK__STACK__PREFIX": "robot7"},
    {"STACK__ZENOH__LISTEN": '["tcp/0.0.0.0:0"]', "STACK__STACK__CLOCK_TOLERANCE_S": "0.3"},
]


@pytest.mark.parametrize("environ", ENVIRONS)
@pytest.mark.parametrize("profile", PROFILES, ids=lambda p: p.name)
def test_the_same_tables_as_the_whole_config(profile: Path, environ: dict[str, str]) -> None:
    whole = load_config(profile, environ=environ)
    assert load_bus_settings(profile, environ=environ) == (whole.zenoh, whole.stack)
    # The e-stop command's local road finds the controller's socket beside the same file.
    assert load_estop_file_path(profile, environ=environ) == whole.estop_path


def test_a_profile_that_extends_another(tmp_path: Path) -> None:
    base = tmp_path / "base.toml"
    base.write_text('[zenoh]\nendpoint = "tcp/10.0.0.1:7448"\n[stack]\nprefix = "a"\n')
    top = tmp_path / "top.toml"
    top.write_text('extends = "base.toml"\n[stack]\nprefix = "b"\n')
    zenoh, stack = load_bus_settings(top, environ={})
    assert (zenoh.endpoint, stack.prefix) == ("tcp/10.0.0.1:7448", "b")
    assert (zenoh, stack) == (
        load_config(top, environ={}).zenoh,
        load_config(top, environ={}).stack,
    )


@pytest.mark.parametrize(
    ("text", "environ", "error"),
    [
        ('[zenoh]\nmode = "router"\n', {}, "zenoh.mode must be 'peer' or 'client'"),
        ("[zenoh]\nendpoit = 1\n", {}, "[zenoh] has unknown setting(s) ['endpoit']"),
        ("", {"STACK__ZENOH__ENDPOIT": "x"}, "STACK__ZENOH__ENDPOIT: [zenoh] has no setting"),
        ("", {"STACK__STACK__CLOCK_TOLERANCE_S": "9.0"}, "STACK__STACK__CLOCK_TOLERANCE_S: "),
        ("[zenoh\n", {}, "not valid TOML"),
    ],
)
def test_its_own_tables_are_checked_alike(
    tmp_path: Path, text: str, environ: dict[str, str], error: str
) -> None:
    path = tmp_path / "stack.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as whole:
        load_config(path, environ=environ)
    with pytest.raises(ConfigError) as bus:
        load_bus_settings(path, environ=environ)
    assert error in str(bus.value) and str(bus.value) == str(whole.value)


def test_a_mistake_in_another_table_does_not_stop_it(tmp_path: Path) -> None:
    # A stop must reach the stack whatever else the file says: the whole config refuses these.
    path = tmp_path / "stack.toml"
    # (``camera = 5``: a key where a table must be.)
    path.write_text(
        'camera = 5\n[zenoh]\nendpoint = "tcp/10.0.0.3:7448"\n[detector]\nbakend = "cuda"\n'
    )
    environ = {"STACK__TRACKR__IOU": "0.3"}
    with pytest.raises(ConfigError):
        load_config(path, environ=environ)
    zenoh, _ = load_bus_settings(path, environ=environ)
    assert zenoh.endpoint == "tcp/10.0.0.3:7448"
