"""A short soak of a real ``depict serve``: a few hundred mixed requests from several clients
while worker processes are killed by real signals, asserting each answer's status and that the
server's memory comes back flat. The figures (requests, statuses, p50/p95, memory) are printed
(``pytest -s tests/test_soak.py``) and written to ``$DEPICT_SOAK_REPORT`` when set."""

from __future__ import annotations

import json
import os
import random
import signal
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import httpx
import numpy as np
import psutil
import trimesh

from gbuffer.io import write as write_exr
from gbuffer.render import render
from tests.exr_factory import write_decode_bomb
from tests.live_server import Server, live_server

REQUESTS = 200
CLIENTS = 6
KILL_EVERY = 60  # a worker is killed by SIGKILL every this many requests

#: request kind -> the statuses it may get (503: its worker was killed; 429: queue full)
EXPECTED = {
    "enhance": {200, 429, 503},
    "score": {200, 429, 503},
    "health": {200},
    "operators": {200},
    "garbage": {400},
    "truncated": {400},
    "bomb": {413},
    "nested": {422},
    "bad_option": {422},
    "wrong_type": {415},
}
WEIGHTS = {
    "enhance": 25,
    "score": 5,
    "health": 15,
    "operators": 5,
    "garbage": 8,
    "truncated": 8,
    "bomb": 8,
    "nested": 8,
    "bad_option": 4,
    "wrong_type": 4,
}


def tree_rss(pid: int) -> int:
    proc = psutil.Process(pid)
    total = 0
    for p in [proc, *proc.children(recursive=True)]:
        try:
            total += p.memory_info().rss
        except psutil.Error:
            pass
    return total


def worker_pids(pid: int) -> list[int]:
    found = []
    for child in psutil.Process(pid).children():
        try:
            if "spawn_main" in " ".join(child.cmdline()):
                found.append(child.pid)
        except psutil.Error:
            pass
    return found


#: One answered request: its kind, the status it got and its latency in seconds.
Result = tuple[str, int, float]


@dataclass(frozen=True)
class Payloads:
    """What the requests send: a small valid EXR, a decode bomb and a deeply nested pipeline."""

    frame: bytes
    bomb: bytes
    nested: str


def make_payloads(tmp_path: Path) -> Payloads:
    small = tmp_path / "small.exr"
    write_exr(render(trimesh.creation.icosphere(subdivisions=2), 48, 36), small)
    frame = small.read_bytes()
    bomb = write_decode_bomb(tmp_path / "bomb.exr").read_bytes()
    nested = '{"steps": [' + '{"op": "x", "params": {"effect": ' * 30 + "1" + "}}" * 30 + "]}"
    return Payloads(frame, bomb, nested)


def send(client: httpx.Client, url: str, payloads: Payloads, kind: str) -> int:
    """One request of ``kind`` (a key of EXPECTED) to the server at ``url``; its status."""
    frame = payloads.frame
    files = {"file": ("f.exr", frame)}
    if kind == "enhance":
        return client.post(f"{url}/v1/enhance", files=files).status_code
    if kind == "score":
        return client.post(f"{url}/v1/score", files=files).status_code
    if kind == "health":
        return client.get(f"{url}/healthz").status_code
    if kind == "operators":
        return client.get(f"{url}/v1/operators").status_code
    if kind == "garbage":
        files = {"file": ("g.exr", os.urandom(2048))}
        return client.post(f"{url}/v1/enhance", files=files).status_code
    if kind == "truncated":
        files = {"file": ("t.exr", frame[: len(frame) // 2])}
        return client.post(f"{url}/v1/enhance", files=files).status_code
    if kind == "bomb":
        files = {"file": ("b.exr", payloads.bomb)}
        return client.post(f"{url}/v1/enhance", files=files).status_code
    if kind == "nested":
        data = {"pipeline": payloads.nested}
        return client.post(f"{url}/v1/enhance", files=files, data=data).status_code
    if kind == "bad_option":
        data = {"options": '{"params": "x"}'}
        return client.post(f"{url}/v1/compare", files=files, data=data).status_code
    return client.post(f"{url}/v1/score", json={"file": 1}).status_code


def memory_bound(baseline: int) -> float:
    """The most the server's memory may hold after the soak, from its warmed-up baseline."""
    return baseline * 1.3 + 150 * 2**20


def warm_baseline(server: Server, payloads: Payloads) -> int:
    """Both workers busy once, then the server's memory (the baseline)."""
    with httpx.Client(timeout=120) as warm:
        threads = [
            threading.Thread(target=send, args=(warm, server.url, payloads, "enhance"))
            for _ in range(4)
        ]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    time.sleep(1.0)
    return tree_rss(server.process.pid)


def run_clients(
    server: Server, payloads: Payloads, kinds: list[str], rng: random.Random
) -> tuple[list[Result], int, float]:
    """The requests of ``kinds`` from CLIENTS threads, a worker killed every KILL_EVERY
    requests; returns the results, the workers killed and the wall time."""
    results: list[Result] = []
    lock = threading.Lock()
    todo = list(enumerate(kinds))
    kills = 0

    def client_loop() -> None:
        nonlocal kills
        with httpx.Client(timeout=120) as client:
            while True:
                with lock:
                    if not todo:
                        return
                    i, kind = todo.pop(0)
                    kill = i > 0 and i % KILL_EVERY == 0
                if kill:  # the fault: a worker dies (as under the out-of-memory killer)
                    pids = worker_pids(server.process.pid)
                    if pids:
                        os.kill(rng.choice(pids), signal.SIGKILL)
                        kills += 1
                t0 = time.perf_counter()
                status = send(client, server.url, payloads, kind)
                with lock:
                    results.append((kind, status, time.perf_counter() - t0))

    t_start = time.perf_counter()
    clients = [threading.Thread(target=client_loop) for _ in range(CLIENTS)]
    for t in clients:
        t.start()
    for t in clients:
        t.join()
    return results, kills, time.perf_counter() - t_start


def assert_statuses(results: list[Result], kills: int) -> Counter[int]:
    """Every answer as expected of its kind, every request answered, enough of them served."""
    unexpected = [(k, s) for k, s, _ in results if s not in EXPECTED[k]]
    assert not unexpected, unexpected
    assert len(results) == REQUESTS and kills >= 3
    statuses = Counter(s for _, s, _ in results)
    assert statuses[200] >= REQUESTS // 3, statuses
    assert statuses[500] == 0
    return statuses


def rss_after_recovery(server: Server, payloads: Payloads, baseline: int) -> int:
    """Ready again and serving; the server's memory once back within its bound (or after 5 s)."""
    deadline = time.monotonic() + 60
    while httpx.get(f"{server.url}/readyz").status_code != 200:
        assert time.monotonic() < deadline
        time.sleep(0.2)
    with httpx.Client(timeout=120) as client:
        assert send(client, server.url, payloads, "enhance") == 200
    after = tree_rss(server.process.pid)
    for _ in range(20):
        if after <= memory_bound(baseline):
            break
        time.sleep(0.25)
        after = tree_rss(server.process.pid)
    return after


def soak_report(
    results: list[Result],
    kills: int,
    wall: float,
    statuses: Counter[int],
    baseline: int,
    after: int,
) -> dict[str, object]:
    latencies = np.array([s for _, _, s in results]) * 1e3
    return {
        "requests": len(results),
        "clients": CLIENTS,
        "workers_killed": kills,
        "seconds": round(wall, 1),
        "statuses": {str(k): v for k, v in sorted(statuses.items())},
        "p50_ms": round(float(np.percentile(latencies, 50)), 1),
        "p95_ms": round(float(np.percentile(latencies, 95)), 1),
        "rss_before_mb": round(baseline / 2**20),
        "rss_after_mb": round(after / 2**20),
    }


def test_soak(tmp_path: Path) -> None:
    payloads = make_payloads(tmp_path)
    rng = random.Random(7)
    kinds = rng.choices(list(WEIGHTS), weights=list(WEIGHTS.values()), k=REQUESTS)
    env = {"DEPICT_WORKERS": "2", "DEPICT_QUEUE": "6", "DEPICT_TIMEOUT_S": "60"}
    with live_server(env) as server:
        baseline = warm_baseline(server, payloads)
        results, kills, wall = run_clients(server, payloads, kinds, rng)
        statuses = assert_statuses(results, kills)
        # healthy afterwards, and memory back to where it was
        after = rss_after_recovery(server, payloads, baseline)
        report = soak_report(results, kills, wall, statuses, baseline, after)
        print("soak:", json.dumps(report))
        if os.environ.get("DEPICT_SOAK_REPORT"):
            Path(os.environ["DEPICT_SOAK_REPORT"]).write_text(json.dumps(report, indent=2))
        assert after <= memory_bound(baseline), report
        for line in server.logs().splitlines():
            assert line.startswith("{") and json.loads(line), line
