"""A real ``depict serve`` (uvicorn) on 127.0.0.1 for end-to-end tests: start, wait, stop."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parent.parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Server:
    url: str
    process: subprocess.Popen[bytes]
    log: Path

    def logs(self) -> str:
        return self.log.read_text(errors="replace")


def start_server(env: dict[str, str]) -> Server:
    """Start ``python -m service.cli serve`` with ``env`` (DEPICT_*) on a free port."""
    port = free_port()
    full_env = {
        **{k: v for k, v in os.environ.items() if not k.startswith("DEPICT_")},
        "DEPICT_HOST": "127.0.0.1",
        "DEPICT_PORT": str(port),
        "PYOPENGL_PLATFORM": "osmesa",
        **env,
    }
    log = Path(tempfile.mkstemp(prefix="depict-server-", suffix=".log")[1])
    with open(log, "wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "service.cli", "serve"],
            cwd=ROOT,
            env=full_env,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    return Server(f"http://127.0.0.1:{port}", process, log)


def wait_ready(server: Server, timeout: float = 120.0) -> None:
    """Wait for ``/readyz`` to answer 200 (workers up, one OSMesa render done)."""
    deadline = time.monotonic() + timeout
    while True:
        if server.process.poll() is not None:
            raise RuntimeError(f"server exited with {server.process.returncode}:\n{server.logs()}")
        try:
            if httpx.get(f"{server.url}/readyz", timeout=5.0).status_code == 200:
                return
        except httpx.TransportError:
            pass
        if time.monotonic() > deadline:
            raise RuntimeError(f"server not ready after {timeout} s:\n{server.logs()}")
        time.sleep(0.2)


def stop_server(server: Server) -> None:
    """SIGTERM (uvicorn's graceful stop), SIGKILL to its process group if it lingers."""
    process = server.process
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    server.log.unlink(missing_ok=True)


@contextlib.contextmanager
def live_server(env: dict[str, str], ready_timeout: float = 120.0) -> Iterator[Server]:
    """A started and ready server for the duration of the block."""
    server = start_server(env)
    try:
        wait_ready(server, ready_timeout)
        yield server
    finally:
        stop_server(server)


@contextlib.contextmanager
def live_servers(envs: dict[str, dict[str, str]]) -> Iterator[dict[str, Server]]:
    """Several servers, by name, started at once (their start-ups overlap) and all ready."""
    servers: dict[str, Server] = {}
    try:
        for name, env in envs.items():
            servers[name] = start_server(env)
        for server in servers.values():
            wait_ready(server)
        yield servers
    finally:
        for server in servers.values():
            stop_server(server)


def burst_watching_health(server: Server, job: Callable[[], object], count: int) -> list[int]:
    """``job`` on ``count`` threads at once while another thread polls ``/healthz`` until they
    are all done: the health statuses it saw."""
    health: list[int] = []
    done = threading.Event()

    def watch() -> None:
        with httpx.Client(timeout=30) as client:
            while not done.is_set():
                health.append(client.get(f"{server.url}/healthz").status_code)
                time.sleep(0.05)

    watcher = threading.Thread(target=watch)
    watcher.start()
    burst = [threading.Thread(target=job) for _ in range(count)]
    for t in burst:
        t.start()
    for t in burst:
        t.join()
    done.set()
    watcher.join()
    return health
