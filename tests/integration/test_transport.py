"""The Zenoh adapter (egc_common.transport): configuration rules and command-line options."""

from __future__ import annotations

import argparse
import json

import pytest
from egc_common.errors import UsageError
from egc_common.transport import (
    DEFAULT_ENDPOINT,
    ZenohOptions,
    add_zenoh_arguments,
    build_config,
    free_tcp_port,
    options_from_args,
)


def get(config, key):
    return json.loads(config.get_json(key))


def test_defaults_peer_no_multicast_2s_lease_explicit_endpoints():
    c = build_config(ZenohOptions(connect=("tcp/127.0.0.1:1234",)))
    assert get(c, "mode") == "peer"
    assert get(c, "scouting/multicast/enabled") is False
    assert get(c, "transport/link/tx/lease") == 2000
    assert get(c, "transport/link/tx/keep_alive") == 4
    assert get(c, "connect/endpoints") == ["tcp/127.0.0.1:1234"]
    assert get(c, "listen/endpoints") == []  # a connecting peer opens no port of its own


def test_client_mode_and_lease_override():
    c = build_config(ZenohOptions(mode="client", connect=("tcp/r:7447",), lease_ms=500))
    assert get(c, "mode") == "client"
    assert get(c, "transport/link/tx/lease") == 500


def test_config_file_rules_and_flags_still_override(tmp_path):
    f = tmp_path / "z.json5"
    f.write_text('{ mode: "client", connect: { endpoints: ["tcp/a:1"] } }')
    c = build_config(ZenohOptions(config_file=str(f), connect=("tcp/b:2",)))
    assert get(c, "mode") == "client"
    assert get(c, "connect/endpoints") == ["tcp/b:2"]


@pytest.mark.parametrize(
    "options",
    [
        {"mode": "router"},
        {"connect": ("127.0.0.1:7447",)},
        {"lease_ms": 10},
    ],
)
def test_bad_options_are_usage_errors(options):
    with pytest.raises(UsageError):
        ZenohOptions(**options)


def test_missing_or_invalid_config_file_is_a_usage_error(tmp_path):
    with pytest.raises(UsageError, match="not found"):
        build_config(ZenohOptions(config_file=str(tmp_path / "nope.json5")))
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: ")
    with pytest.raises(UsageError, match="invalid zenoh config"):
        build_config(ZenohOptions(config_file=str(bad)))


def test_arguments_role_defaults_and_the_zenoh_spelling_where_connect_is_taken():
    p = argparse.ArgumentParser()
    add_zenoh_arguments(p, default_connect=(DEFAULT_ENDPOINT,))
    assert options_from_args(p.parse_args([])).connect == (DEFAULT_ENDPOINT,)
    args = p.parse_args(["--connect", "tcp/x:1", "--zenoh-connect", "tcp/y:2"])
    assert options_from_args(args).connect == ("tcp/x:1", "tcp/y:2")
    viewer = argparse.ArgumentParser()
    viewer.add_argument("--connect")  # e.g. the operator view's viewer URL
    add_zenoh_arguments(viewer)
    args = viewer.parse_args(["--connect", "rerun+http://h/proxy", "--zenoh-connect", "tcp/y:2"])
    assert args.connect == "rerun+http://h/proxy"
    assert options_from_args(args).connect == ("tcp/y:2",)


def test_a_config_file_drops_the_role_defaults(tmp_path):
    p = argparse.ArgumentParser()
    add_zenoh_arguments(p, default_listen=(DEFAULT_ENDPOINT,))
    f = tmp_path / "z.json5"
    f.write_text("{}")
    assert options_from_args(p.parse_args(["--zenoh-config", str(f)])).listen == ()


def test_client_mode_drops_the_default_listen_endpoint():
    """`robot --zenoh-mode client --connect ...` next to a router on the same machine: the
    robot's default tcp/127.0.0.1:7447 is the router's port (it failed: address in use)."""
    p = argparse.ArgumentParser()
    add_zenoh_arguments(p, default_listen=(DEFAULT_ENDPOINT,))
    client = p.parse_args(["--zenoh-mode", "client", "--connect", "tcp/127.0.0.1:7447"])
    assert options_from_args(client).listen == ()
    assert options_from_args(p.parse_args([])).listen == (DEFAULT_ENDPOINT,)
    given = p.parse_args(["--zenoh-mode", "client", "--listen", "tcp/127.0.0.1:9"])
    assert options_from_args(given).listen == ("tcp/127.0.0.1:9",)


def test_free_tcp_port():
    assert 1024 <= free_tcp_port() <= 65535
