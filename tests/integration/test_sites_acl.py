"""The two sites' access control read as Zenoh reads it (deploy/README.md, "Two sites"):
``site-robots-router.json5`` (site A, the robots) and ``site-operators-router.json5`` (site B,
the operators), each router's verdict per certificate common name as in ``test_deploy_acl``,
and what reaches whom end to end: a message crosses four interceptors, the sender's face at its
router (ingress), the other router's face there (egress), that router's face at the other
router (ingress) and the receiver's face (egress). ``test_sites.py`` runs the same files. The
README's command lines for them parse with the real parser.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import zenoh

from tests.integration.harness import ROOT
from tests.integration.test_deploy_acl import ACL as ONE_ROUTER
from tests.integration.test_deploy_acl import IN, OUT, allowed, load_acl
from tests.integration.test_deploy_readme import block_with, commands, parse, section

DEPLOY = ROOT / "deploy"
SITE_A = load_acl(DEPLOY / "site-robots-router.json5")
SITE_B = load_acl(DEPLOY / "site-operators-router.json5")
SITE_B_CONNECT = json.loads(
    zenoh.Config.from_file(str(DEPLOY / "site-operators-router.json5")).get_json(
        "connect/endpoints"
    )
)
ROUTER_A, ROUTER_B = "robots-router", "operators-router"  # the routers' common names
R1 = "egc/robot-1"


@pytest.mark.parametrize("acl", [SITE_A, SITE_B], ids=["site A", "site B"])
def test_the_files_are_what_this_test_reads(acl: dict[str, Any]):
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    ids = [r["id"] for r in acl["rules"]]
    assert len(ids) == len(set(ids))
    subjects = {s["id"] for s in acl["subjects"]}
    used: set[str] = set()
    for policy in acl["policies"]:
        assert set(policy["rules"]) <= set(ids), policy
        assert set(policy["subjects"]) <= subjects, policy
        used |= set(policy["rules"])
    assert used == set(ids), "a rule no policy uses"


def to_robot(cn: str, message: str, key: str, robot: str = "robot-1") -> bool:
    """An operator's message at site B reaches the robot at site A."""
    return (
        allowed(cn, message, IN, key, SITE_B)
        and allowed(ROUTER_A, message, OUT, key, SITE_B)
        and allowed(ROUTER_B, message, IN, key, SITE_A)
        and allowed(robot, message, OUT, key, SITE_A)
    )


def to_operator(cn: str, message: str, key: str, robot: str = "robot-1") -> bool:
    """The robot's message at site A reaches the operator at site B."""
    return (
        allowed(robot, message, IN, key, SITE_A)
        and allowed(ROUTER_B, message, OUT, key, SITE_A)
        and allowed(ROUTER_A, message, IN, key, SITE_B)
        and allowed(cn, message, OUT, key, SITE_B)
    )


# operator-1 may drive robot-1, operator-2 robot-2 (not at site A in the shipped file)
@pytest.mark.parametrize(("cn", "may"), [("operator-1", True), ("operator-2", False)])
def test_only_its_drivers_drive_a_robot(cn, may):
    assert to_robot(cn, "put", f"{R1}/cmd") is may
    assert to_robot(cn, "put", f"{R1}/goal") is may
    assert to_robot(cn, "liveliness_token", f"{R1}/alive/operator/any-id") is may
    assert to_robot(cn, "query", f"{R1}/clock") is may
    # stopped at its own site's router, never sent across
    assert allowed(cn, "put", IN, f"{R1}/cmd", SITE_B) is may
    assert allowed(cn, "query", IN, f"{R1}/clock", SITE_B) is may


def test_a_driver_of_one_robot_drives_no_other():
    assert allowed("operator-2", "put", IN, "egc/robot-2/cmd", SITE_B)
    assert allowed("operator-2", "liveliness_token", IN, "egc/robot-2/alive/operator/x", SITE_B)
    for key in ("egc/robot-2/cmd", "egc/sim/cmd", "egc/*/cmd", "egc/**"):
        assert not allowed("operator-1", "put", IN, key, SITE_B), key


@pytest.mark.parametrize("cn", ["operator-1", "operator-2"])
def test_every_fleet_operator_lists_and_watches_every_robot(cn):
    assert to_operator(cn, "liveliness_token", f"{R1}/alive/robot")
    assert allowed(cn, "declare_liveliness_subscriber", IN, "egc/*/alive/robot", SITE_B)
    assert allowed(cn, "liveliness_query", IN, "egc/*/alive/robot", SITE_B)
    assert to_robot(cn, "query", f"{R1}/info") and to_operator(cn, "reply", f"{R1}/info")
    assert to_robot(cn, "query", f"{R1}/map") and to_operator(cn, "reply", f"{R1}/map")
    assert to_operator(cn, "put", f"{R1}/telemetry") and to_operator(cn, "put", f"{R1}/state")


@pytest.mark.parametrize("cn", ["operator-1", "operator-2", "intruder"])
def test_no_operator_forges_the_robot_side_or_reaches_a_base(cn):
    for key in (f"{R1}/telemetry", f"{R1}/state", f"{R1}/base/cmd", f"{R1}/scan"):
        assert not allowed(cn, "put", IN, key, SITE_B), key
    assert not allowed(cn, "reply", IN, f"{R1}/clock", SITE_B)
    assert not allowed(cn, "liveliness_token", IN, f"{R1}/alive/robot", SITE_B)


def test_base_commands_odometry_and_scans_stay_on_site_a():
    for key in (f"{R1}/base/cmd", f"{R1}/base/odom", f"{R1}/scan"):
        assert allowed("robot-1", "put", IN, key, SITE_A), key  # robot process <-> its bridge
        assert not allowed(ROUTER_B, "put", OUT, key, SITE_A), key
        assert not allowed(ROUTER_B, "put", IN, key, SITE_A), key


@pytest.mark.parametrize("cn", ["operator-1", "operator-2", "intruder"])
def test_an_operator_certificate_gets_nothing_at_site_a(cn):
    """Dialling site A's router directly, past site B's per-operator rules."""
    for message, flow, key in [
        ("put", IN, f"{R1}/cmd"),
        ("liveliness_token", IN, f"{R1}/alive/operator/x"),
        ("liveliness_token", OUT, f"{R1}/alive/robot"),
        ("put", OUT, f"{R1}/telemetry"),
        ("query", IN, f"{R1}/info"),
    ]:
        assert not allowed(cn, message, flow, key, SITE_A), (message, flow, key)


def test_the_site_routers_play_their_side_only():
    """Site A's router cannot act as an operator at site B, nor site B's as a robot at A."""
    assert not allowed(ROUTER_A, "put", IN, f"{R1}/cmd", SITE_B)
    assert not allowed(ROUTER_A, "liveliness_token", IN, f"{R1}/alive/operator/x", SITE_B)
    assert not allowed(ROUTER_B, "put", IN, f"{R1}/telemetry", SITE_A)
    assert not allowed(ROUTER_B, "liveliness_token", IN, f"{R1}/alive/robot", SITE_A)
    assert not allowed(ROUTER_B, "reply", IN, f"{R1}/clock", SITE_A)


KEYS = [
    f"{R1}/{leaf}"
    for leaf in (
        "cmd", "goal", "telemetry", "state", "clock", "map", "info", "base/cmd", "base/odom",
        "scan", "alive/robot", "alive/operator/op-1",
    )
] + ["egc/sim/cmd", "egc/sim/base/cmd", "egc/sim/alive/robot", "egc/sim/clock"]  # fmt: skip
MESSAGES = [
    "put", "query", "reply", "liveliness_token", "declare_liveliness_subscriber",
    "liveliness_query", "declare_subscriber", "declare_queryable",
]  # fmt: skip


def test_robot_1_has_the_same_rules_at_site_a_as_with_one_router():
    """A robot moves between a single router and site A without a new certificate or rule."""
    differ = [
        (m, f, k)
        for m in MESSAGES
        for f in (IN, OUT)
        for k in KEYS
        if allowed("robot-1", m, f, k, SITE_A) != allowed("robot-1", m, f, k, ONE_ROUTER)
    ]
    assert differ == []


def test_the_two_sites_command_lines_parse_and_name_the_shipped_files():
    lines = [c for c in commands(block_with("/etc/egc/site-robots-router.json5")) if c]
    parsed = [parse(argv) for argv in lines]
    assert [name for name, _ in parsed] == ["router", "router"], lines
    configs = [Path(args.zenoh_config) for _, args in parsed]
    assert [c.name for c in configs] == ["site-robots-router.json5", "site-operators-router.json5"]
    for config, (_, args) in zip(configs, parsed, strict=True):
        assert config.parent == Path("/etc/egc") and (DEPLOY / config.name).is_file(), config
        assert args.listen == ["tls/0.0.0.0:7447"], args.listen
    assert "egc-teleop robots --zenoh-config FILE" in section("Two sites")


def test_site_b_dials_a_name_site_a_certificate_carries():
    assert SITE_B_CONNECT == ["tls/site-a.example.net:7447"], SITE_B_CONNECT
    recipe = block_with("/CN=robots-router")
    assert "subjectAltName=DNS:router.local,DNS:site-a.example.net" in recipe
    assert "/CN=robots-router" in recipe and "/CN=operators-router" in recipe
