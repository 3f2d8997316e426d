"""The operator's ``--connect`` serves issue 4 (Zenoh endpoints) and issue 5 (viewer URL)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from egc_common.cli_args import CliArgumentParser
from egc_common.transport import options_from_args
from egc_operator import cli


def parse(*argv: str):
    parser = CliArgumentParser(prog="egc-teleop operator")
    cli.configure(parser)
    return parser.parse_args(["--script", "demo", *argv])


def test_zenoh_endpoints_and_viewer_url_are_told_apart():
    args = parse(
        "--connect",
        "tcp/10.0.0.2:7447",
        "--connect",
        "rerun+http://127.0.0.1:9876/proxy",
        "--zenoh-connect",
        "tls/router.local:7447",
    )
    assert args.connect == "rerun+http://127.0.0.1:9876/proxy"
    assert options_from_args(args).connect == ("tcp/10.0.0.2:7447", "tls/router.local:7447")


def test_defaults_without_connect():
    args = parse()
    assert args.connect is None
    assert options_from_args(args).connect == ("tcp/127.0.0.1:7447",)


@pytest.mark.parametrize(
    "argv",
    [
        ["--connect", "bogus"],
        ["--connect", "rerun+http://a:1/proxy", "--connect", "rerun+http://b:1/proxy"],
    ],
)
def test_bad_connect_values_are_one_line_usage_errors(argv):
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app", "operator", "--script", "demo", *argv],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "--connect" in proc.stderr
