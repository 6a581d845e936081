"""Zenoh's error text without Rust source paths, and a hint for a taken port."""

from __future__ import annotations

from pathlib import Path

from common.zenoh_errors import clean, explain, port_hint

TAKEN = (
    "Can not create a new TCP listener bound to tcp/127.0.0.1:7447: [127.0.0.1:7447: Address "
    "already in use (os error 98) at /root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/cc83980/"
    "io/zenoh-link-commons/src/tcp.rs:61.] at /root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/"
    "cc83980/io/zenoh-links/zenoh-link-tcp/src/unicast.rs:338."
)


def test_rust_locations_go() -> None:
    assert clean(TAKEN) == (
        "Can not create a new TCP listener bound to tcp/127.0.0.1:7447: 127.0.0.1:7447: Address "
        "already in use (os error 98)"
    )
    assert clean("plain words") == "plain words"


def test_a_taken_port_names_its_usual_holder(tmp_path: Path) -> None:
    # An empty /proc: no holder can be seen (common/ports.py finds one where it can).
    assert "port 7447 is taken (rmw_zenohd" in port_hint(TAKEN, tmp_path)
    assert "sport = :7447" in port_hint(TAKEN, tmp_path)
    assert explain(TAKEN).startswith(clean(TAKEN) + "; port 7447 is taken (")
    other = TAKEN.replace("7447", "9000")
    assert "port 9000 is taken (the holder is not visible" in port_hint(other, tmp_path)
    assert port_hint("Unable to connect to any of [tcp/127.0.0.1:7448]") == ""
