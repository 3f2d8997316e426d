"""Two hosts on one machine: an operator and a robot network namespace joined through a middle
namespace where ``egc-teleop link`` runs (DESIGN 10, emulated mode).

::

    operator ns                 middle ns                          robot ns
    eth0 10.201.1.2/24 ---- op0 10.201.1.1 | rb0 10.201.2.1 ---- eth0 10.201.2.2/24
                                 (the relay listens on 10.201.1.1
                                  and connects to 10.201.2.2)

The middle namespace does **not** forward IP between its two sides (forwarding is off in a new
namespace, and neither side has a route to the other subnet), so the only way from the operator
to the robot is through a process in the middle: the relay. Each instance has its own three
namespaces (``egc-<pid>-<n>-op|mid|rb``); the veth pairs are created inside them, so the same
addresses can be reused by parallel instances without clashing. ``TwoHosts`` is a context
manager: on exit (also on an exception) it kills every process left in its namespaces and
deletes them, which deletes the veth pairs. Namespaces of a process that died without cleaning
up are removed by the next ``TwoHosts`` (``remove_stale``).

Loss and outages in the kernel (for TCP, whose relay cannot drop bytes): ``set_loss(direction,
percent)`` installs an nftables rule in the middle namespace's input hook, ``iifname "op0"``
(``up``, operator -> robot) or ``iifname "rb0"`` (``down``) ``numgen random mod 10000 < N
drop``, so packets are lost on the wire as the sender sees it (a drop in the sender's own output
hook would return EPERM to it instead); ``set_outage(True)`` drops everything in both directions
until ``set_outage(False)``. They need the ``nft`` command (``nft_unavailable_reason()`` says
why not).

Requirements: root and a working ``ip netns`` (``unavailable_reason()`` says which is missing,
in one line a test can skip with). As a command::

    python -m egc_experiments.netns check
    python -m egc_experiments.netns demo -- CMD...   # run CMD in the robot ns of a fresh pair
    python -m egc_experiments.netns cleanup          # remove namespaces of dead processes
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO, Final

SIDES: Final = ("op", "mid", "rb")
OPERATOR_ADDR: Final = "10.201.1.2"
MIDDLE_OP_ADDR: Final = "10.201.1.1"
MIDDLE_RB_ADDR: Final = "10.201.2.1"
ROBOT_ADDR: Final = "10.201.2.2"
_PREFIX: Final = "egc-"
_NAME = re.compile(r"^egc-(\d+)-(\d+)-(op|mid|rb)$")
_counter = itertools.count()
_TIMEOUT_S: Final = 20.0


class NetnsError(RuntimeError):
    """A namespace command failed (with ``ip``'s or ``nft``'s own message)."""


def _run(cmd: Sequence[str], stdin: str | None = None, timeout_s: float = _TIMEOUT_S) -> str:
    try:
        proc = subprocess.run(
            list(cmd), input=stdin, capture_output=True, text=True, timeout=timeout_s
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise NetnsError(f"{' '.join(cmd)}: {exc}") from None
    if proc.returncode != 0:
        message = " ".join((proc.stderr or proc.stdout).split()) or f"exit {proc.returncode}"
        raise NetnsError(f"{' '.join(cmd)}: {message}")
    return proc.stdout


_availability: dict[str, str | None] = {}


def unavailable_reason() -> str | None:
    """None when network namespaces can be used here, else why not (one line)."""
    if "netns" not in _availability:
        _availability["netns"] = _probe_netns()
    return _availability["netns"]


def _probe_netns() -> str | None:
    if sys.platform != "linux":
        return f"network namespaces need Linux, this is {sys.platform}"
    if os.geteuid() != 0:
        return "network namespaces need root (run as root, e.g. in CI)"
    if shutil.which("ip") is None:
        return "the 'ip' command (iproute2) is not installed"
    probe = f"{_PREFIX}{os.getpid()}-probe"
    try:
        _run(["ip", "netns", "add", probe])
    except NetnsError as exc:
        return f"'ip netns add' does not work here: {exc}"
    try:
        _run(["ip", "-n", probe, "link", "add", "p0", "type", "veth", "peer", "name", "p1"])
    except NetnsError as exc:
        return f"veth pairs do not work here: {exc}"
    finally:
        with contextlib.suppress(NetnsError):
            _run(["ip", "netns", "del", probe])
    return None


def nft_unavailable_reason() -> str | None:
    """None when nftables rules can be installed in a namespace, else why not."""
    reason = unavailable_reason()
    if reason is not None:
        return reason
    if shutil.which("nft") is None:
        return "the 'nft' command (nftables) is not installed: no kernel loss or outages"
    return None


def list_namespaces() -> list[str]:
    out = _run(["ip", "netns", "list"])
    return [line.split()[0] for line in out.splitlines() if line.strip()]


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale() -> list[str]:
    """Delete the namespaces of ``TwoHosts`` whose process is gone; returns their names."""
    removed = []
    for name in list_namespaces():
        match = _NAME.match(name)
        if match and not _pid_alive(int(match.group(1))):
            _kill_all_in(name)
            with contextlib.suppress(NetnsError):
                _run(["ip", "netns", "del", name])
                removed.append(name)
    return removed


def _pids_in(ns: str) -> list[int]:
    try:
        out = _run(["ip", "netns", "pids", ns])
    except NetnsError:
        return []
    return [int(p) for p in out.split()]


def _kill_all_in(ns: str) -> None:
    """SIGTERM, then SIGKILL after a grace period, every process in ``ns`` (ours by name)."""
    pids = _pids_in(ns)
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + 3.0
    while pids and time.monotonic() < deadline:
        time.sleep(0.05)
        pids = [p for p in _pids_in(ns) if _pid_alive(p)]
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


@dataclass
class TwoHosts:
    """The operator, middle and robot namespaces of one run (module docstring)."""

    name: str = field(default_factory=lambda: f"{_PREFIX}{os.getpid()}-{next(_counter)}")
    operator_addr: str = OPERATOR_ADDR
    robot_addr: str = ROBOT_ADDR
    middle_op_addr: str = MIDDLE_OP_ADDR
    middle_rb_addr: str = MIDDLE_RB_ADDR
    created: list[str] = field(default_factory=list)
    _loss: dict[str, float] = field(default_factory=lambda: {"up": 0.0, "down": 0.0})
    _loss_proto: str | None = None
    _outage: bool = False
    _nft_installed: bool = False

    def ns(self, side: str) -> str:
        if side not in SIDES:
            raise ValueError(f"side must be one of {', '.join(SIDES)}, got {side!r}")
        return f"{self.name}-{side}"

    # -- building and tearing down --------------------------------------------------------------

    def __enter__(self) -> TwoHosts:
        reason = unavailable_reason()
        if reason is not None:
            raise NetnsError(reason)
        with contextlib.suppress(NetnsError):
            remove_stale()
        try:
            self._build()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _build(self) -> None:
        op, mid, rb = (self.ns(s) for s in SIDES)
        for ns in (op, mid, rb):
            _run(["ip", "netns", "add", ns])
            self.created.append(ns)
            _run(["ip", "-n", ns, "link", "set", "lo", "up"])
        _run(["ip", "-n", op, "link", "add", "eth0", "type", "veth", "peer", "name", "op0",
              "netns", mid])  # fmt: skip
        _run(["ip", "-n", rb, "link", "add", "eth0", "type", "veth", "peer", "name", "rb0",
              "netns", mid])  # fmt: skip
        for ns, dev, addr in (
            (op, "eth0", self.operator_addr),
            (mid, "op0", self.middle_op_addr),
            (mid, "rb0", self.middle_rb_addr),
            (rb, "eth0", self.robot_addr),
        ):
            _run(["ip", "-n", ns, "addr", "add", f"{addr}/24", "dev", dev])
            _run(["ip", "-n", ns, "link", "set", dev, "up"])
        # No IP forwarding in the middle: only the relay connects the two sides.
        _run(["ip", "netns", "exec", mid, "sysctl", "-q", "-w", "net.ipv4.ip_forward=0"])

    def close(self) -> None:
        """Kill what still runs in the namespaces and delete them (idempotent)."""
        for ns in reversed(self.created):
            _kill_all_in(ns)
            with contextlib.suppress(NetnsError):
                _run(["ip", "netns", "del", ns])
        self.created.clear()

    # -- running things inside ------------------------------------------------------------------

    def command(self, side: str, cmd: Sequence[str]) -> list[str]:
        """``cmd`` prefixed so that it runs in ``side``'s namespace (``ip netns exec``)."""
        return ["ip", "netns", "exec", self.ns(side), *cmd]

    def run(self, side: str, cmd: Sequence[str], timeout_s: float = _TIMEOUT_S) -> str:
        """Run ``cmd`` to its end in ``side``'s namespace; its stdout (NetnsError if it fails)."""
        return _run(self.command(side, cmd), timeout_s=timeout_s)

    def popen(
        self,
        side: str,
        cmd: Sequence[str],
        stdout: IO[bytes] | int | None = None,
        stderr: IO[bytes] | int | None = None,
        cwd: Path | str | None = None,
        env: dict[str, str] | None = None,
    ) -> subprocess.Popen[bytes]:
        """Start ``cmd`` in ``side``'s namespace; ``ip netns exec`` execs it, so the Popen's pid
        is the command's own and signals reach it directly."""
        return subprocess.Popen(
            self.command(side, cmd),
            stdout=stdout,
            stderr=stderr,
            stdin=subprocess.DEVNULL,
            cwd=cwd,
            env=env,
        )

    # -- kernel loss and outages (nftables) -------------------------------------------------------

    def _nft_apply(self) -> None:
        """(Re)write the middle namespace's ``inet egc`` table from the loss/outage settings."""
        reason = nft_unavailable_reason()
        if reason is not None:
            raise NetnsError(reason)
        rules = []
        for direction, dev in (("up", "op0"), ("down", "rb0")):
            if self._outage:
                rules.append(f'    iifname "{dev}" drop\n')
            elif self._loss[direction] > 0:
                threshold = round(self._loss[direction] * 100)
                only = f"meta l4proto {self._loss_proto} " if self._loss_proto else ""
                rules.append(
                    f'    iifname "{dev}" {only}numgen random mod 10000 < {threshold} drop\n'
                )
        flush = "delete table inet egc\n" if self._nft_installed else ""
        script = (
            f"{flush}table inet egc {{\n"
            "  chain in {\n"
            "    type filter hook input priority 0; policy accept;\n"
            f"{''.join(rules)}"
            "  }\n"
            "}\n"
        )
        _run(["ip", "netns", "exec", self.ns("mid"), "nft", "-f", "-"], stdin=script)
        self._nft_installed = True

    def set_loss(self, direction: str, percent: float, proto: str | None = None) -> None:
        """Drop ``percent`` % of the packets going ``up`` (operator -> robot) or ``down``;
        with ``proto`` (``tcp`` or ``udp``) only that protocol's (the same for both directions).

        The packets are dropped as they arrive at the middle namespace (nftables input hook),
        so the sender sees a real loss (no local error; TCP has to detect and retransmit)."""
        if direction not in ("up", "down"):
            raise ValueError(f"direction is 'up' or 'down', got {direction!r}")
        if not 0 <= percent <= 100:
            raise ValueError(f"loss is a percentage in [0, 100], got {percent}")
        if proto not in (None, "tcp", "udp"):
            raise ValueError(f"proto is tcp, udp or None, got {proto!r}")
        self._loss[direction] = float(percent)
        self._loss_proto = proto
        self._nft_apply()

    def set_outage(self, down: bool) -> None:
        """Cut (``True``) or restore (``False``) both directions of the link."""
        self._outage = down
        self._nft_apply()

    def nft_ruleset(self) -> str:
        """The middle namespace's ruleset as ``nft`` lists it (for reports)."""
        return self.run("mid", ["nft", "list", "ruleset"])


@contextlib.contextmanager
def two_hosts() -> Iterator[TwoHosts]:
    """``with two_hosts() as net:`` the same as ``with TwoHosts() as net:``."""
    with TwoHosts() as net:
        yield net


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m egc_experiments.netns", description=__doc__)
    sub = parser.add_subparsers(dest="what", required=True)
    sub.add_parser("check", help="say whether namespaces (and nftables) work here")
    sub.add_parser("cleanup", help="remove the namespaces of processes that are gone")
    demo = sub.add_parser("demo", help="build a pair, run a command in each side, tear down")
    demo.add_argument("--side", choices=SIDES, default="rb")
    demo.add_argument("cmd", nargs=argparse.REMAINDER)
    args = parser.parse_args(argv)
    if args.what == "check":
        reason = unavailable_reason()
        print(f"netns: {'available' if reason is None else 'unavailable: ' + reason}")
        nft = nft_unavailable_reason()
        print(f"nftables: {'available' if nft is None else 'unavailable: ' + nft}")
        return 0 if reason is None else 1
    if args.what == "cleanup":
        reason = unavailable_reason()
        if reason is not None:
            print(f"netns: unavailable: {reason}", file=sys.stderr)
            return 1
        print("\n".join(remove_stale()) or "nothing to remove")
        return 0
    cmd = [c for c in args.cmd if c != "--"] or ["ip", "-brief", "addr"]
    try:
        with TwoHosts() as net:
            print(f"namespaces {', '.join(net.ns(s) for s in SIDES)}", file=sys.stderr)
            print(net.run(args.side, cmd), end="")
    except NetnsError as exc:
        print(f"netns: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
