"""A server's port counts as open only when the server itself (or its child) listens there: a free
port picked earlier can be taken by another process before the server binds it, and then a
stranger answered for it (a page test logged in to another test's API, which then went away)."""

from __future__ import annotations

import socket
import subprocess
import sys

import pytest

from prism_cli.stack import free_port, wait_for_port


def _listen(port: int) -> str:
    return (f"import socket, time; s = socket.socket(); s.bind(('127.0.0.1', {port})); s.listen(); "
            "print('up', flush=True); time.sleep(30)")


def test_a_port_someone_else_listens_on_is_not_ours() -> None:
    with socket.socket() as stranger:
        stranger.bind(("127.0.0.1", 0))
        stranger.listen()
        port = stranger.getsockname()[1]
        ours = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
        try:
            with pytest.raises(TimeoutError, match="nothing of ours"):
                wait_for_port(port, 1.0, ours)
        finally:
            ours.kill()
            ours.wait()


@pytest.mark.parametrize("via_child", [False, True], ids=["itself", "its-child"])
def test_a_port_the_process_or_its_child_listens_on_is_ours(via_child: bool) -> None:
    port = free_port()
    code = _listen(port)
    parent = f"import subprocess, sys; subprocess.run([sys.executable, '-c', {code!r}])"
    argv = [sys.executable, "-c", parent if via_child else code]
    proc = subprocess.Popen(argv, start_new_session=True)
    try:
        wait_for_port(port, 20.0, proc)
    finally:
        subprocess.run(["pkill", "-KILL", "-s", str(proc.pid)], check=False)
        proc.wait()
