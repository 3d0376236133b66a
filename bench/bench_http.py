"""Benchmark: 1080p Radiance Scaling enhance round trip over HTTP vs the local CLI, same run.

Run: ``.venv/bin/python -m bench.bench_http``. A canonical 1920x1080 G-buffer (OSMesa render of
examples/spot.obj) is enhanced with the default pipeline (Radiance Scaling):

* locally, ``depict enhance`` in this process (read, operator, write);
* over HTTP against a real ``depict serve`` on 127.0.0.1 (``DEPICT_WORKERS`` = cores): upload,
  header check, decode, operator, encode, download, with 1, 2 and 4 concurrent clients.

Prints the median latency (and its ratio to the copy unit) and the throughput in requests/s.
"""

from __future__ import annotations

import contextlib
import io
import os
import statistics
import tempfile
import threading
import time
from pathlib import Path

from bench.common import HD, Report, median_ms
from gbuffer.io import write
from gbuffer.render import load_mesh, render
from service.cli import main as cli
from service.client import Client
from tests.live_server import live_server

ROOT = Path(__file__).resolve().parent.parent
REQUESTS_PER_CLIENT = 3


def run_clients(url: str, frame: Path, work: Path, clients: int) -> list[float]:
    """Latencies (ms) of ``clients`` concurrent clients; the last item is the elapsed seconds."""
    latencies: list[float] = []
    lock = threading.Lock()

    def one_client(index: int) -> None:
        with Client(url, api_key="", retries=50) as c:
            for k in range(REQUESTS_PER_CLIENT):
                t0 = time.perf_counter()
                c.enhance(frame, work / f"c{index}_{k}.exr")
                with lock:
                    latencies.append((time.perf_counter() - t0) * 1e3)

    threads = [threading.Thread(target=one_client, args=(i,)) for i in range(clients)]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return [*latencies, time.perf_counter() - t0]


def main() -> None:
    report = Report("HTTP enhance round trip, radiance_scaling", HD)
    work = Path(tempfile.mkdtemp(prefix="bench-http-"))
    frame_path = work / "spot_1080p.exr"
    h, w = HD
    write(render(load_mesh(ROOT / "examples" / "spot.obj"), w, h), frame_path)
    size_mb = frame_path.stat().st_size / 2**20
    print(f"input {frame_path.name}: {size_mb:.1f} MiB")

    out = work / "local.exr"

    def local_cli() -> None:
        with contextlib.redirect_stdout(io.StringIO()):
            cli(["enhance", str(frame_path), "-o", str(out)])

    local = median_ms(local_cli, repeat=5)
    report.add("local CLI enhance (read, operator, write)", local)

    workers = os.cpu_count() or 1
    env = {"DEPICT_WORKERS": str(workers), "DEPICT_QUEUE": "16", "DEPICT_TIMEOUT_S": "600"}
    with live_server(env) as server, Client(server.url, api_key="") as client:
        remote_out = work / "remote.exr"
        http1 = median_ms(lambda: client.enhance(frame_path, remote_out), repeat=5)
        report.add("HTTP enhance, 1 client (upload..download)", http1)
        same = remote_out.read_bytes() == out.read_bytes()
        print(f"HTTP output identical to the local CLI's: {same}")
        print(f"HTTP overhead over local: {http1 - local:+.0f} ms ({http1 / local:.2f}x)")
        print(f"{'clients':>8s} {'median ms':>10s} {'req/s':>8s}   (server workers: {workers})")
        for clients in (1, 2, 4):
            latencies = run_clients(server.url, frame_path, work, clients)
            elapsed = latencies.pop()
            rps = len(latencies) / elapsed
            med = statistics.median(latencies)
            print(f"{clients:8d} {med:10.0f} {rps:8.2f}   ({med / report.unit:.0f}x copy)")
    for p in work.iterdir():
        p.unlink()
    work.rmdir()


if __name__ == "__main__":
    main()
