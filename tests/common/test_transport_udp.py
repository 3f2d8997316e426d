"""``udp/`` endpoints in egc_common.transport (DESIGN 9 "Transport", docs/transport.md).

A ``udp/HOST:PORT`` on the command line is a TCP link (Zenoh's reliable traffic) plus a
best-effort UDP link on one port, two links of one transport; a connecting process opens the TCP
one first (``exit_on_failure=true`` in its endpoint configuration), so that the declarations
never go out on UDP. Listening endpoints are not changed that way.
"""

from __future__ import annotations

import json

from egc_common.transport import ZenohOptions, build_config


def get(config, key):
    return json.loads(config.get_json(key))


def test_connecting_udp_opens_tcp_first_and_allows_two_links():
    c = build_config(ZenohOptions(connect=("udp/10.0.0.2:7447", "tcp/10.0.0.3:7447")))
    assert get(c, "connect/endpoints") == [
        "tcp/10.0.0.2:7447#exit_on_failure=true",
        "udp/10.0.0.2:7447?rel=0",
        "tcp/10.0.0.3:7447",
    ]
    assert get(c, "transport/unicast/max_links") == 2


def test_listening_udp_is_a_plain_pair_and_explicit_rel_is_kept():
    c = build_config(ZenohOptions(listen=("udp/0.0.0.0:7447",), connect=("udp/h:1?rel=0",)))
    assert get(c, "listen/endpoints") == ["tcp/0.0.0.0:7447", "udp/0.0.0.0:7447?rel=0"]
    assert get(c, "connect/endpoints") == ["udp/h:1?rel=0"]


def test_an_endpoint_configuration_part_is_kept_on_both_links():
    c = build_config(ZenohOptions(connect=("udp/h:3#iface=lo",)))
    tcp, udp = get(c, "connect/endpoints")
    assert tcp.startswith("tcp/h:3#") and {"iface=lo", "exit_on_failure=true"} == set(
        tcp.split("#", 1)[1].split(";")
    )
    assert udp == "udp/h:3?rel=0#iface=lo"
