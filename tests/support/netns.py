"""A network namespace that holds only loopback, for camera protocols that broadcast.

Aravis discovers GigE Vision cameras by broadcasting on every interface; its fake camera and
everything that talks to it run in here (``ip netns exec``), so nothing leaves this machine's
loopback. Needs root (CI runs as root) and iproute2's ``ip``.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["LoopbackNamespace", "loopback_namespace", "why_no_namespace"]


def why_no_namespace() -> str | None:
    if shutil.which("ip") is None:
        return "iproute2's ip is not installed"
    if os.geteuid() != 0:
        return "a network namespace needs root (CI runs as root)"
    return None


class LoopbackNamespace:
    def __init__(self, name: str) -> None:
        self.name = name
        self.procs: list[subprocess.Popen] = []

    def popen(self, argv: list[str], **kwargs: Any) -> subprocess.Popen:
        """``argv`` started inside the namespace: ``ip netns exec`` execs it, so the pid is its own."""
        proc = subprocess.Popen(["ip", "netns", "exec", self.name, *argv], **kwargs)
        self.procs.append(proc)
        return proc

    def run(self, argv: list[str], **kwargs: Any) -> subprocess.CompletedProcess:
        return subprocess.run(["ip", "netns", "exec", self.name, *argv], **kwargs)

    def udp_port_open(self, port: int) -> bool:
        out = self.run(["ss", "-Huln", f"sport = :{port}"], capture_output=True, text=True, timeout=30)
        return f":{port}" in out.stdout


@contextmanager
def loopback_namespace() -> Iterator[LoopbackNamespace]:
    name = f"thermcap-test-{uuid.uuid4().hex[:8]}"
    subprocess.run(["ip", "netns", "add", name], check=True, timeout=30)
    ns = LoopbackNamespace(name)
    try:
        subprocess.run(["ip", "netns", "exec", name, "ip", "link", "set", "lo", "up"], check=True, timeout=30)
        yield ns
    finally:
        for proc in ns.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGKILL)
                proc.wait(timeout=30)
        subprocess.run(["ip", "netns", "delete", name], check=False, timeout=30)
