"""deploy/router-tls-acl.json5, read as Zenoh reads it: which certificate common name may send
or receive which message on which key (deploy/README.md, "TLS and access control").

Zenoh's ACL (1.x, ``zenoh/src/net/routing/interceptor``) allows a message of a subject when a
rule of one of its policies names that message and flow and has a key expression that includes
the message's key; ``default_permission: "deny"`` denies everything else. Ingress is what a
client sends into the router (a ``liveliness_token`` ingress is a client declaring a token),
egress what the router passes on to it. This file checks the shipped rules against that
reading; ``test_deploy_tls.py`` checks the same rules on a running router.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import zenoh

from tests.integration.harness import ROOT

ACL_FILE = ROOT / "deploy" / "router-tls-acl.json5"
IN, OUT = "ingress", "egress"


def load_acl(path: Path = ACL_FILE) -> dict[str, Any]:
    acl: dict[str, Any] = json.loads(zenoh.Config.from_file(str(path)).get_json("access_control"))
    return acl


ACL = load_acl()


def allowed(cn: str, message: str, flow: str, key: str, acl: dict[str, Any] | None = None) -> bool:
    """Whether ``acl`` (default: router-tls-acl.json5's) lets common name ``cn`` do it."""
    acl = ACL if acl is None else acl
    subjects = {s["id"] for s in acl["subjects"] if cn in (s.get("cert_common_names") or [])}
    rule_ids = {r for p in acl["policies"] if subjects & set(p["subjects"]) for r in p["rules"]}
    verdict = acl["default_permission"] == "allow"
    wanted = zenoh.KeyExpr(key)
    for rule in acl["rules"]:
        if rule["id"] not in rule_ids:
            continue
        if message not in rule["messages"] or flow not in rule["flows"]:
            continue
        if any(zenoh.KeyExpr(k).includes(wanted) for k in rule["key_exprs"]):
            if rule["permission"] == "deny":
                return False
            verdict = True
    return verdict


def test_the_file_is_what_this_test_reads():
    assert ACL["enabled"] is True and ACL["default_permission"] == "deny"
    ids = [r["id"] for r in ACL["rules"]]
    assert len(ids) == len(set(ids))
    for policy in ACL["policies"]:
        assert set(policy["rules"]) <= set(ids), policy


R1 = "egc/robot-1"

# (common name, message, flow, key, allowed?)
CASES = [
    # each role declares its own liveliness tokens and no other role's (outside check: a
    # robot-1 certificate declared egc/robot-1/alive/operator/op-robot-1, the router passed it)
    ("robot-1", "liveliness_token", IN, f"{R1}/alive/robot", True),
    ("robot-1", "liveliness_token", IN, f"{R1}/alive/operator/op-robot-1", False),
    ("robot-1", "liveliness_token", IN, "egc/sim/alive/operator/op-1", False),
    ("robot-1", "liveliness_token", IN, "egc/sim/alive/robot", False),
    ("operator-1", "liveliness_token", IN, f"{R1}/alive/operator/op-1", True),
    ("operator-1", "liveliness_token", IN, f"{R1}/alive/robot", False),
    ("operator-1", "liveliness_token", IN, "egc/sim/alive/robot", False),
    # ... and receives and watches the other role's
    ("robot-1", "liveliness_token", OUT, f"{R1}/alive/operator/op-1", True),
    ("robot-1", "liveliness_token", OUT, "egc/sim/alive/operator/op-1", False),
    ("robot-1", "declare_liveliness_subscriber", IN, f"{R1}/alive/operator/*", True),
    ("robot-1", "liveliness_query", IN, f"{R1}/alive/operator/*", True),
    ("operator-1", "liveliness_token", OUT, f"{R1}/alive/robot", True),
    ("operator-1", "liveliness_token", OUT, "egc/sim/alive/robot", True),
    ("operator-1", "declare_liveliness_subscriber", IN, f"{R1}/alive/robot", True),
    ("operator-1", "liveliness_query", IN, f"{R1}/alive/robot", True),
    # commands and via points: operators send, the robot receives
    ("operator-2", "put", IN, f"{R1}/cmd", True),
    ("operator-1", "put", IN, f"{R1}/goal", True),
    ("robot-1", "put", OUT, f"{R1}/cmd", True),
    ("robot-1", "put", IN, f"{R1}/cmd", False),
    ("robot-1", "put", OUT, "egc/sim/cmd", False),
    # telemetry and state: the robot sends, operators receive
    ("robot-1", "put", IN, f"{R1}/telemetry", True),
    ("robot-1", "put", IN, "egc/sim/telemetry", False),
    ("operator-1", "put", OUT, f"{R1}/telemetry", True),
    ("operator-1", "put", IN, f"{R1}/telemetry", False),
    ("operator-1", "put", IN, f"{R1}/state", False),
    # the base: between robot-1's process and its bridge only
    ("robot-1", "put", IN, f"{R1}/base/cmd", True),
    ("robot-1", "put", OUT, f"{R1}/base/odom", True),
    ("robot-1", "put", IN, "egc/sim/base/cmd", False),
    ("operator-1", "put", IN, f"{R1}/base/cmd", False),
    ("operator-1", "put", OUT, f"{R1}/scan", False),
    # the clock and the map: operators ask, the robot answers
    ("operator-1", "query", IN, f"{R1}/clock", True),
    ("robot-1", "reply", IN, f"{R1}/clock", True),
    ("robot-1", "reply", IN, "egc/sim/clock", False),
    ("operator-1", "reply", IN, f"{R1}/clock", False),
    # the info (egc-teleop robots, DESIGN 15): likewise
    ("operator-2", "query", IN, f"{R1}/info", True),
    ("robot-1", "query", OUT, f"{R1}/info", True),
    ("robot-1", "reply", IN, f"{R1}/info", True),
    ("operator-2", "reply", OUT, f"{R1}/info", True),
    ("robot-1", "reply", IN, "egc/sim/info", False),
    ("operator-1", "reply", IN, f"{R1}/info", False),
    # a certificate of the project CA whose common name is in no subject: nothing
    ("intruder", "put", IN, f"{R1}/cmd", False),
    ("intruder", "put", OUT, f"{R1}/telemetry", False),
    ("intruder", "liveliness_token", IN, f"{R1}/alive/operator/x", False),
]


@pytest.mark.parametrize(("cn", "message", "flow", "key", "expected"), CASES)
def test_who_may_do_what(cn, message, flow, key, expected):
    assert allowed(cn, message, flow, key) is expected


@pytest.mark.parametrize("cn", ["robot-1", "operator-1"])
def test_no_role_may_declare_the_other_roles_tokens_anywhere(cn):
    """Every liveliness_token ingress rule of a role covers only that role's own keys."""
    other = "operator/*" if cn == "robot-1" else "robot"
    for robot in ("robot-1", "sim", "*"):
        assert not allowed(cn, "liveliness_token", IN, f"egc/{robot}/alive/{other}")
        assert not allowed(cn, "liveliness_token", IN, f"egc/{robot}/alive/**")
