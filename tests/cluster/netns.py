"""A small network of hosts on this machine: one network namespace per host, each with a veth
whose other end sits on a bridge in a switch namespace of its own, and addresses in one private
/24 that exists only inside these namespaces. Nothing is added to the machine's own namespace,
so no traffic of the test can leave them. Everything is removed by `Network.remove`.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["Network", "cannot_make_namespaces", "inside"]

_CLONE_NEWNET = 0x40000000
_libc = ctypes.CDLL(None, use_errno=True)
# A MAC address no interface has: frames sent to it are flooded by the bridge and dropped by
# every host that receives them, which is what a firewall's DROP looks like to the sender.
_NOWHERE_MAC = "02:00:00:de:ad:01"


def cannot_make_namespaces() -> str | None:
    """Why this machine cannot build the network (None: it can)."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if shutil.which("ip") is None:
        return "the `ip` command (iproute2) is not installed"
    return None


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=30)


def _setns(path: str) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        if _libc.setns(fd, _CLONE_NEWNET) != 0:
            err = ctypes.get_errno()
            raise OSError(err, f"setns {path}: {os.strerror(err)}")
    finally:
        os.close(fd)


@contextmanager
def inside(namespace: str) -> Iterator[None]:
    """Run the calling thread in `namespace`: sockets it opens (and threads it starts) are
    there. Python has no os.setns before 3.12, hence libc's."""
    home = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
    try:
        _setns(f"/run/netns/{namespace}")
        try:
            yield
        finally:
            if _libc.setns(home, _CLONE_NEWNET) != 0:
                raise OSError(ctypes.get_errno(), "setns back to the test's own namespace")
    finally:
        os.close(home)


class Network:
    """Hosts named `hosts` (name -> last octet) on 10.199.<subnet>.0/24, namespaces
    `{prefix}-{name}`; the switch is `{prefix}-sw`."""

    def __init__(self, prefix: str, hosts: dict[str, int], subnet: int = 14) -> None:
        self.prefix, self.hosts = prefix, dict(hosts)
        self.net = f"10.199.{subnet}"
        self.made: list[str] = []

    def ns(self, host: str) -> str:
        return f"{self.prefix}-{host}"

    def addr(self, host: str) -> str:
        return f"{self.net}.{self.hosts[host]}"

    def create(self) -> None:
        switch = self.ns("sw")
        self._add_ns(switch)
        _ip("-n", switch, "link", "add", "br0", "type", "bridge")
        _ip("-n", switch, "link", "set", "br0", "up")
        for host in self.hosts:
            ns = self.ns(host)
            self._add_ns(ns)
            _ip("link", "add", "eth0", "netns", ns, "type", "veth", "peer", "name", self.port(host),
                "netns", switch)
            _ip("-n", switch, "link", "set", self.port(host), "master", "br0", "up")
            _ip("-n", ns, "addr", "add", f"{self.addr(host)}/24", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "up")
            _ip("-n", ns, "link", "set", "lo", "up")

    def _add_ns(self, ns: str) -> None:
        _ip("netns", "add", ns)
        self.made.append(ns)

    @staticmethod
    def port(host: str) -> str:
        return f"p-{host}"[:15]

    def remove(self) -> None:
        """Delete every namespace made (their veths and the bridge go with them). The processes
        in them must be stopped first, or a namespace lives on, unnamed, until they exit."""
        for ns in reversed(self.made):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)
        self.made.clear()

    def leftovers(self) -> list[str]:
        listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
        return [line.split()[0] for line in listed.splitlines() if line.startswith(self.prefix + "-")]

    # Faults.

    def link(self, host: str, up: bool) -> None:
        """The host's cable, pulled out or put back (the switch's end of its veth)."""
        _ip("-n", self.ns("sw"), "link", "set", self.port(host), "up" if up else "down")

    def drop_toward(self, host: str, target: str, dropped: bool) -> None:
        """`host`'s packets to `target` silently lost (as a firewall's DROP), or back: a
        permanent neighbour entry with a MAC address no interface has."""
        if dropped:
            _ip("-n", self.ns(host), "neigh", "replace", self.addr(target), "lladdr", _NOWHERE_MAC,
                "dev", "eth0", "nud", "permanent")
        else:
            _ip("-n", self.ns(host), "neigh", "del", self.addr(target), "dev", "eth0")

    def exec_argv(self, host: str, argv: list[str]) -> list[str]:
        return ["ip", "netns", "exec", self.ns(host), *argv]
