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


def test_connecting_udp_to_nobody_says_so_and_ctrl_c_ends_it():
    """Outside check: an operator connecting udp/ to a port nobody listens on sat silent for
    90 s and ignored Ctrl-C (zenoh.open waits for the TCP half in Rust, in the main thread)."""
    import signal
    import subprocess
    import sys
    import time

    from egc_common.transport import free_port

    port = free_port("udp")
    proc = subprocess.Popen(
        [sys.executable, "-m", "egc_app.cli", "operator", "--robot", "nobody", "--script",
         "demo", "--no-view", "--no-status", "--zenoh-connect", f"udp/127.0.0.1:{port}"],
        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    try:
        lines = []  # the notice comes after 2 s of waiting, after any line about the view
        while not any("waiting for the peer" in line for line in lines) and len(lines) < 10:
            lines.append(proc.stderr.readline())
        line = lines[-1]
        assert f"waiting for the peer to accept at tcp/127.0.0.1:{port}" in line, lines
        assert "Ctrl-C to stop" in line
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 130
        assert time.monotonic() - t0 < 5
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
