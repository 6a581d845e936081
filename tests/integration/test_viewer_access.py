"""Who may watch the live view (issue 19, points 5 and 6), on real processes: a browser page of
a foreign origin is refused before it sees a channel or an image; an allowed origin and a native
client (no Origin) are let in; under the secure profile only a client with the viewer token is;
and the supervisor says at start-up, under the default profile only, that the bus is open."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import websockets
from websockets.exceptions import InvalidStatus
from websockets.typing import Origin, Subprotocol

from services.viewer import channels as ch
from tests.foxglove_client import SUBPROTOCOL, split_message_frame
from tests.integration.conftest import Stack, credentials_for
from tools.launch import free_port

pytestmark = pytest.mark.integration

SERVICES = ["sim", "viewer"]
EVIL = "https://evil.example.com"
FOXGLOVE_APP = "https://app.foxglove.dev"
WATCH_S = 60.0
OPEN_BUS = "any process that reaches zenoh.endpoint can drive the robot and release its e-stop"


async def _image(url: str, origin: str | None) -> tuple[set[str], int]:
    """Connect to ``url`` as a page of ``origin`` (None: a native client); the advertised
    topics and the size of the first image message received."""
    deadline = time.monotonic() + WATCH_S
    page = Origin(origin) if origin is not None else None
    protocols = [Subprotocol(SUBPROTOCOL)]
    async with websockets.connect(url, subprotocols=protocols, origin=page, max_size=None) as ws:
        advertised: dict[str, dict[str, Any]] = {}
        while ch.IMAGE not in advertised:
            msg = json.loads(await asyncio.wait_for(ws.recv(), deadline - time.monotonic()))
            if msg["op"] == "advertise":
                advertised.update({c["topic"]: c for c in msg["channels"]})
        sub = {"id": 1, "channelId": advertised[ch.IMAGE]["id"]}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [sub]}))
        while True:
            frame = await asyncio.wait_for(ws.recv(), deadline - time.monotonic())
            if isinstance(frame, bytes):
                _sub_id, _at, payload = split_message_frame(frame)
                return set(advertised), len(payload)


def _refused(url: str, origin: str | None) -> int:
    """The HTTP status with which the connection was refused; fails if it was let in."""
    with pytest.raises(InvalidStatus) as refused:
        asyncio.run(_image(url, origin))
    return refused.value.response.status_code


def _start(make_stack: Callable[..., Stack], **tables: dict[str, str]) -> tuple[Stack, int]:
    port = free_port()
    stack: Stack = make_stack(
        supervisor={"services": SERVICES}, viewer={"port": port}, sim={"wait_for": []}, **tables
    )
    stack.wait_ready(set(SERVICES))
    return stack, port


def test_a_foreign_web_page_is_refused_and_the_default_profile_says_the_bus_is_open(
    make_stack: Callable[..., Stack],
) -> None:
    stack, port = _start(make_stack)
    url = f"ws://127.0.0.1:{port}/"
    assert _refused(url, EVIL) == 403, stack.log()
    for origin in (FOXGLOVE_APP, None):  # an allowed page, and a native client
        topics, size = asyncio.run(_image(url, origin))
        assert ch.IMAGE in topics and size > 0, (origin, topics, size)
    assert OPEN_BUS in stack.log()
    assert "refused: origin 'https://evil.example.com'" in stack.log()
    assert stack.stop() == 0, stack.log()


def test_the_secure_profile_lets_in_only_a_client_with_the_viewer_token(
    make_stack: Callable[..., Stack], tmp_path: Path
) -> None:
    creds = tmp_path / "credentials"
    prefix = credentials_for(creds)
    token = (creds / "viewer-token").read_text().strip()
    secure = {"mode": "client", "auth": "password", "credentials_dir": str(creds)}
    stack, port = _start(make_stack, stack={"prefix": prefix}, zenoh=secure)
    base = f"ws://127.0.0.1:{port}/"
    assert _refused(base, None) == 403, stack.log()
    assert _refused(f"{base}?token=wrong", None) == 403, stack.log()
    assert _refused(f"{base}?token={token}", EVIL) == 403, stack.log()  # a token is no origin
    for origin in (None, FOXGLOVE_APP):
        topics, size = asyncio.run(_image(f"{base}?token={token}", origin))
        assert ch.IMAGE in topics and size > 0, (origin, topics, size)
    assert OPEN_BUS not in stack.log()
    assert stack.stop() == 0, stack.log()
