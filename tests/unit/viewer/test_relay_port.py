"""The live view's private relay port: the Foxglove server behind the front listens on
``viewer.relay_port`` when one is set (0: a free one), and a taken one is one line naming it."""

from __future__ import annotations

import socket

import foxglove
import pytest

from common.errors import ConfigError
from services.viewer.contract import ViewerSettings
from services.viewer.service import start_server
from tools.ports import free_port


def test_the_foxglove_server_listens_on_the_relay_port_given() -> None:
    port = free_port()
    server = start_server(foxglove.Context(), ViewerSettings(relay_port=port).relay_port)
    try:
        assert server.port == port
        with pytest.raises(ConfigError, match=rf"viewer.relay_port: .* 127.0.0.1:{port} .*held by"):
            start_server(foxglove.Context(), port)
    finally:
        server.stop()


def test_without_one_the_system_picks_a_free_port() -> None:
    assert ViewerSettings().relay_port == 0
    server = start_server(foxglove.Context(), 0)
    try:
        with socket.create_connection(("127.0.0.1", server.port), timeout=5):
            pass
    finally:
        server.stop()


def test_the_relay_port_is_not_the_public_one() -> None:
    with pytest.raises(ConfigError, match=r"viewer.relay_port must differ from viewer.port"):
        ViewerSettings(port=9000, relay_port=9000)
    with pytest.raises(ConfigError, match=r"viewer.relay_port must be within 0..65535"):
        ViewerSettings(relay_port=70000)
