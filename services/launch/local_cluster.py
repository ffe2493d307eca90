"""A Ray cluster of separate `ray start` processes on this machine: a head and worker nodes,
each worker in its own network namespace joined to the host by a veth pair when this process
may make one (root and `ip netns`), else on loopback. What docs/training.md's "more machines"
steps do, on one machine: for the multi-node tests and benchmarks/scaling.py.

Token authentication is on (RAY_AUTH_MODE=token, a fresh RAY_AUTH_TOKEN shared by every node
and handed to drivers through `env`).
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

HOST_NET = "10.213"  # 10.213.<i>.1 host side, 10.213.<i>.2 inside namespace i


def _ray_bin() -> str:
    return str(Path(sys.executable).with_name("ray"))


def namespaces_available() -> bool:
    if os.geteuid() != 0 or shutil.which("ip") is None:
        return False
    probe = f"pmprobe{os.getpid()}"
    ok = subprocess.run(["ip", "netns", "add", probe], capture_output=True).returncode == 0
    if ok:
        subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return ok


@dataclass
class Node:
    index: int
    ip: str
    process: subprocess.Popen
    netns: str | None = None

    def stop(self) -> None:
        """Stop the node as a machine leaving would: its raylet and workers go."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)  # `ray start --block` stops its children
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
        if self.netns:  # anything left in the namespace
            pids = subprocess.run(["ip", "netns", "pids", self.netns], capture_output=True,
                                  text=True).stdout.split()  # fmt: skip
            for pid in pids:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(int(pid), signal.SIGKILL)


@dataclass
class LocalCluster:
    """Start with `start()`, add workers with `add_worker(cpus)`, stop everything with `stop()`."""

    head_cpus: int = 0
    port: int = 6390
    use_netns: bool | None = None  # None: when available
    token: str = field(default_factory=lambda: secrets.token_hex(32))
    workers: list[Node] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.use_netns is None:
            self.use_netns = namespaces_available()
        self.tag = f"pm{os.getpid() % 100000}"
        self.temp = Path(tempfile.mkdtemp(prefix="pmray", dir="/tmp"))  # short: unix sockets
        self.head_ip = f"{HOST_NET}.0.1" if self.use_netns else "127.0.0.1"
        self.head: subprocess.Popen | None = None
        self._links: list[str] = []
        self._head_addr = False

    @property
    def address(self) -> str:
        return f"{self.head_ip}:{self.port}"

    @property
    def env(self) -> dict[str, str]:
        """Environment for anything that joins the cluster (drivers included)."""
        return {
            **os.environ,
            "RAY_AUTH_MODE": "token",
            "RAY_AUTH_TOKEN": self.token,
            "RAY_USAGE_STATS_ENABLED": "0",
        }

    def _ip(self, *args: str, netns: str | None = None) -> None:
        cmd = ["ip", "netns", "exec", netns, "ip", *args] if netns else ["ip", *args]
        subprocess.run(cmd, check=True, capture_output=True)

    def _veth(self, i: int) -> str:
        """Namespace i with a veth pair to the host: host 10.213.i.1, inside 10.213.i.2."""
        ns, host_if, ns_if = f"{self.tag}n{i}", f"{self.tag}h{i}", f"{self.tag}c{i}"
        subprocess.run(["ip", "netns", "add", ns], check=True, capture_output=True)
        self._ip("link", "add", host_if, "type", "veth", "peer", "name", ns_if)
        self._links.append(host_if)
        self._ip("link", "set", ns_if, "netns", ns)
        self._ip("addr", "add", f"{HOST_NET}.{i}.1/24", "dev", host_if)
        self._ip("link", "set", host_if, "up")
        self._ip("addr", "add", f"{HOST_NET}.{i}.2/24", "dev", ns_if, netns=ns)
        self._ip("link", "set", ns_if, "up", netns=ns)
        self._ip("link", "set", "lo", "up", netns=ns)
        self._ip("route", "add", "default", "via", f"{HOST_NET}.{i}.1", netns=ns)
        return ns

    def start(self) -> LocalCluster:
        if self.use_netns:  # the head's address, on the host's loopback; namespaces route to it
            self._ip("addr", "add", f"{self.head_ip}/32", "dev", "lo")
            self._head_addr = True
        self.head = subprocess.Popen(
            [_ray_bin(), "start", "--head", "--block", f"--port={self.port}",
             f"--node-ip-address={self.head_ip}", f"--num-cpus={self.head_cpus}",
             "--include-dashboard=false", f"--temp-dir={self.temp / 'head'}",
             "--disable-usage-stats"],
            env=self.env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True,
        )  # fmt: skip
        self.wait_nodes(1)
        return self

    def add_worker(self, cpus: int) -> Node:
        i = len(self.workers) + 1
        ns = self._veth(i) if self.use_netns else None
        ip = f"{HOST_NET}.{i}.2" if ns else "127.0.0.1"
        cmd = [_ray_bin(), "start", "--block", f"--address={self.address}",
               f"--node-ip-address={ip}", f"--num-cpus={cpus}",
               f"--temp-dir={self.temp / f'w{i}'}", "--disable-usage-stats"]  # fmt: skip
        if not ns:  # a second node on the same address needs its own agent ports
            base = 52400 + 10 * i
            cmd += [f"--dashboard-agent-listen-port={base}", f"--metrics-export-port={base + 1}",
                    f"--runtime-env-agent-port={base + 2}"]  # fmt: skip
        if ns:
            cmd = ["ip", "netns", "exec", ns, *cmd]
        process = subprocess.Popen(cmd, env=self.env, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL, start_new_session=True)  # fmt: skip
        node = Node(i, ip, process, ns)
        self.workers.append(node)
        self.wait_nodes(1 + sum(w.process.poll() is None for w in self.workers))
        return node

    def alive_nodes(self) -> list[dict]:
        """The alive nodes as `ray list nodes` sees them (asked in a child process)."""
        import json

        code = (
            f"import json, ray; ray.init(address={self.address!r}, log_to_driver=False, "
            f"_node_ip_address={self.head_ip!r}); "
            "print(json.dumps([n for n in ray.nodes() if n['Alive']]))"
        )
        out = subprocess.run(
            [sys.executable, "-c", code],
            env=self.env, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        if out.returncode:
            return []
        return json.loads(out.stdout.strip().splitlines()[-1])

    def wait_nodes(self, n: int, timeout: float = 120.0) -> None:
        deadline = time.monotonic() + timeout
        while len(self.alive_nodes()) != n:
            if time.monotonic() > deadline:
                raise TimeoutError(f"the cluster at {self.address} did not reach {n} node(s)")
            time.sleep(1.0)

    def stop(self) -> None:
        for w in self.workers:
            w.stop()
        if self.head is not None and self.head.poll() is None:
            self.head.send_signal(signal.SIGTERM)
            try:
                self.head.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(self.head.pid, signal.SIGKILL)
        for w in self.workers:
            if w.netns:
                subprocess.run(["ip", "netns", "del", w.netns], capture_output=True)
        for link in self._links:
            subprocess.run(["ip", "link", "del", link], capture_output=True)
        if self._head_addr:
            subprocess.run(["ip", "addr", "del", f"{self.head_ip}/32", "dev", "lo"],
                           capture_output=True)  # fmt: skip
        shutil.rmtree(self.temp, ignore_errors=True)
