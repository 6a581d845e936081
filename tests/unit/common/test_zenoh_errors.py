"""Zenoh's error text without Rust source paths, and a hint for a taken port."""

from __future__ import annotations

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


def test_a_taken_port_names_its_usual_holder() -> None:
    assert "port 7447 is taken (rmw_zenohd" in explain(TAKEN)
    assert "sport = :7447" in explain(TAKEN)
    other = TAKEN.replace("7447", "9000")
    assert "port 9000 is taken (another program)" in port_hint(other)
    assert port_hint("Unable to connect to any of [tcp/127.0.0.1:7448]") == ""
