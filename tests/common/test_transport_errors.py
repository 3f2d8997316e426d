"""A session that cannot open says why, in one line (outside check: an expired certificate, a
self-signed one, a certificate not valid for the name connected to, the router down and a
typo in the endpoint all gave the same "Unable to connect to any of [Single(tls/...)]!", with
"#exit_on_failure=true" leaking from the udp/ pairing; Zenoh had the cause in its log)."""

from __future__ import annotations

import pytest
from egc_common.errors import UsageError
from egc_common.transport import (
    ZenohOptions,
    _one_line,
    build_config,
    free_tcp_port,
    open_session,
)


def test_zenoh_text_is_one_line_without_locations_or_internal_wrappers():
    raw = (
        "Unable to connect to any of [Single(tcp/10.0.0.5:7447#exit_on_failure=true), "
        "Single(udp/10.0.0.5:7447?rel=0)]!  at /root/.cargo/git/x/zenoh/src/orchestrator.rs:447."
    )
    assert _one_line(raw) == (
        "Unable to connect to any of tcp/10.0.0.5:7447, udp/10.0.0.5:7447?rel=0"
    )


def test_a_refused_connection_names_its_cause():
    port = free_tcp_port()  # nothing listens there
    with pytest.raises(UsageError) as err:
        open_session(ZenohOptions(mode="client", connect=(f"tcp/127.0.0.1:{port}",)))
    text = str(err.value)
    assert f"Unable to connect to any of tcp/127.0.0.1:{port}" in text
    assert "Connection refused" in text and "Single(" not in text and "\n" not in text


def test_the_configuration_survives_the_trip_to_the_probe():
    config = build_config(ZenohOptions(mode="client", connect=("tcp/127.0.0.1:1",)))
    import zenoh

    again = zenoh.Config.from_json5(str(config))
    assert again.get_json("connect/endpoints") == config.get_json("connect/endpoints")
