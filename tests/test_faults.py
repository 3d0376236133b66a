"""Faults against a real ``depict serve``: worker processes killed by real signals, jobs over
their time limit, workers that cannot start, oversized and nested inputs, slow clients.

Every server here is a real uvicorn process with real worker processes (tests/live_server.py);
faults are real signals sent to real processes, inputs real files.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import psutil
import pytest
import trimesh

from gbuffer.io import write as write_exr
from gbuffer.render import render
from tests.exr_factory import write_corrupt, write_decode_bomb, write_raw_exr
from tests.live_server import (
    Server,
    burst_watching_health,
    live_server,
    live_servers,
    wait_ready,
)
from tests.problem_json import assert_problem

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"


def workers(server: Server) -> list[psutil.Process]:
    """The server's worker processes (spawned children; not multiprocessing's tracker)."""
    found = []
    for child in psutil.Process(server.process.pid).children():
        try:
            if "spawn_main" in " ".join(child.cmdline()):
                found.append(child)
        except psutil.Error:  # gone, or a zombie not yet reaped
            pass
    return found


def wait_for(what: str, check: object, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not check():  # type: ignore[operator]
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def metric(server: Server, line_start: str) -> float:
    for line in httpx.get(f"{server.url}/metrics").text.splitlines():
        if line.startswith(line_start):
            return float(line.rsplit(" ", 1)[1])
    return 0.0


def json_log_only(server: Server) -> None:
    """Every line the server and its workers wrote is one JSON object."""
    for line in server.logs().splitlines():
        assert line.startswith("{") and json.loads(line), line


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("faults")
    small = root / "small.exr"
    write_exr(render(trimesh.creation.icosphere(subdivisions=2), 64, 48), small)
    return {
        "small": small,
        "bomb": write_decode_bomb(root / "bomb.exr"),
        "channels": write_raw_exr(
            root / "channels.exr", {f"C{i:03d}": np.zeros((4, 4), np.float32) for i in range(101)}
        ),
    }


@pytest.fixture(scope="module")
def servers() -> Iterator[dict[str, Server]]:
    """``main``: one worker, 60 s jobs; ``quick``: one worker, jobs killed after 4 s; both
    close uploads after 2 s. Started together so their start-ups overlap."""
    common = {"DEPICT_WORKERS": "1", "DEPICT_QUEUE": "4", "DEPICT_UPLOAD_TIMEOUT_S": "2"}
    main = {**common, "DEPICT_TIMEOUT_S": "60", "DEPICT_MAX_CHANNELS": "100"}
    with live_servers({"main": main, "quick": {**common, "DEPICT_TIMEOUT_S": "4"}}) as servers:
        yield servers


@pytest.fixture(scope="module")
def server(servers: dict[str, Server]) -> Server:
    return servers["main"]


def enhance(server: Server, path: Path, **data: str) -> httpx.Response:
    return httpx.post(
        f"{server.url}/v1/enhance",
        files={"file": (path.name, path.read_bytes())},
        data=data,
        timeout=120,
    )


def slow_compare(server: Server, size: int = 512) -> httpx.Response:
    """A job of seconds: every method under 21 lights on a ``size``² render of spot (about
    2 s at 512², ten times that at 1536²)."""
    return httpx.post(
        f"{server.url}/v1/compare",
        files={"file": ("spot.obj", SPOT.read_bytes())},
        data={"kind": "mesh", "options": json.dumps({"width": size, "height": size})},
        timeout=180,
    )


# -- self-healing --------------------------------------------------------------------------------


def test_worker_killed_mid_job_answers_503_and_is_replaced(
    server: Server, files: dict[str, Path]
) -> None:
    (worker,) = workers(server)
    answers: list[httpx.Response] = []
    job = threading.Thread(target=lambda: answers.append(slow_compare(server)))
    job.start()
    wait_for("the job to run", lambda: metric(server, "depict_jobs_running") == 1.0, 30)
    time.sleep(0.5)  # well inside the job
    os.kill(worker.pid, signal.SIGKILL)
    job.join()
    body = assert_problem(answers[0], 503, "killed by signal 9 (SIGKILL")
    assert body["type"] == "urn:depict:problem:worker-lost"
    assert answers[0].headers["retry-after"] == "1"
    assert httpx.get(f"{server.url}/healthz").status_code == 200
    assert enhance(server, files["small"]).status_code == 200  # the next request succeeds
    (fresh,) = workers(server)
    assert fresh.pid != worker.pid
    assert metric(server, 'depict_workers_replaced_total{cause="died"}') == 1.0


def test_idle_worker_killed_is_replaced(server: Server, files: dict[str, Path]) -> None:
    wait_ready(server)
    (worker,) = workers(server)
    os.kill(worker.pid, signal.SIGKILL)
    wait_for("a new worker", lambda: [w.pid for w in workers(server)] not in ([], [worker.pid]))
    assert enhance(server, files["small"]).status_code == 200
    assert metric(server, 'depict_workers_replaced_total{cause="idle-died"}') == 1.0
    json_log_only(server)


def test_job_over_time_limit_kills_and_replaces_its_worker(
    servers: dict[str, Server], files: dict[str, Path]
) -> None:
    quick = servers["quick"]
    (worker,) = workers(quick)
    assert_problem(slow_compare(quick, 1536), 504, "DEPICT_TIMEOUT_S=4")
    wait_for(
        "the worker killed",
        lambda: (
            not psutil.pid_exists(worker.pid)
            or psutil.Process(worker.pid).status() == psutil.STATUS_ZOMBIE
        ),
        10,
    )
    wait_ready(quick)  # a fresh worker, warmed up before it takes a job
    assert enhance(quick, files["small"]).status_code == 200
    assert httpx.get(f"{quick.url}/readyz").status_code == 200
    assert metric(quick, 'depict_workers_replaced_total{cause="timeout"}') == 1.0


def test_workers_that_cannot_start_make_the_service_unhealthy(
    servers: dict[str, Server], files: dict[str, Path]
) -> None:
    """Every new worker is killed before it is ready: /healthz says 503 (an orchestrator
    restarts the service); once workers can start again, it is healthy and works."""
    quick = servers["quick"]
    stop = threading.Event()

    def kill_new_workers() -> None:
        while not stop.is_set():
            for w in workers(quick):
                try:
                    w.send_signal(signal.SIGKILL)
                except psutil.NoSuchProcess:
                    pass
            time.sleep(0.02)

    killer = threading.Thread(target=kill_new_workers)
    killer.start()
    try:
        wait_for("/healthz 503", lambda: httpx.get(f"{quick.url}/healthz").status_code == 503, 60)
        body = assert_problem(httpx.get(f"{quick.url}/healthz"), 503, "fail to start")
        assert "restart the service" in body["detail"]
        assert httpx.get(f"{quick.url}/readyz").status_code == 503
    finally:
        stop.set()
        killer.join()
    wait_ready(quick)
    assert httpx.get(f"{quick.url}/healthz").status_code == 200
    assert enhance(quick, files["small"]).status_code == 200
    json_log_only(quick)


# -- limits before decode -------------------------------------------------------------------------


def tree_rss(server: Server) -> int:
    proc = psutil.Process(server.process.pid)
    return sum(p.memory_info().rss for p in [proc, *proc.children(recursive=True)])


def test_decode_bomb_and_channel_count_are_refused_on_the_header(
    server: Server, files: dict[str, Path]
) -> None:
    wait_ready(server)
    before = tree_rss(server)
    body = assert_problem(enhance(server, files["bomb"]), 413, "DEPICT_MAX_DECODED_MB")
    assert "83 channels of 2000x2000 decode to 1266 MiB" in body["detail"]
    assert files["bomb"].stat().st_size < 1_500_000
    assert tree_rss(server) < before + 100 * 2**20  # nothing was decoded
    assert_problem(enhance(server, files["channels"]), 413, "101 channels")


def nested_pipeline(depth: int) -> str:
    effect = '{"op": "radiance_scaling", "params": {"effect": ' * depth + "1" + "}}" * depth
    return json.dumps(
        [{"op": "apparent_relief", "params": {"style": "mask", "effect": "EFFECT"}}]
    ).replace('"EFFECT"', effect)


@pytest.mark.parametrize("depth", [50, 3000, 5000])
def test_deep_pipelines_422(server: Server, files: dict[str, Path], depth: int) -> None:
    response = enhance(server, files["small"], pipeline=nested_pipeline(depth))
    assert_problem(response, 422, "levels deep; at most 20")


def test_pipeline_over_a_mebibyte_413(server: Server, files: dict[str, Path]) -> None:
    response = enhance(server, files["small"], pipeline=nested_pipeline(100_000))
    assert_problem(response, 413, "form field is over 1 MiB")


def test_long_pipeline_and_deep_json_fields_422(server: Server, files: dict[str, Path]) -> None:
    steps = json.dumps([{"op": "radiance_scaling"}] * 65)
    assert_problem(enhance(server, files["small"], pipeline=steps), 422, "at most 64")
    deep = "[" * 5000 + "]" * 5000
    assert_problem(enhance(server, files["small"], camera=deep), 422, "levels deep")


def test_large_pipelines_are_validated_off_the_event_loop(
    server: Server, files: dict[str, Path]
) -> None:
    """20 concurrent 520 KB pipelines (refused: an unknown parameter holding the bulk) while
    /healthz is polled: every pipeline gets its 422, every health check its 200."""
    bulk = [{"op": "radiance_scaling", "params": {"alpha": 0.5, "padding": "x" * 26_000}}] * 20
    text = json.dumps(bulk)
    assert 500_000 < len(text) < 600_000
    statuses: list[int] = []

    def post() -> None:
        statuses.append(enhance(server, files["small"], pipeline=text).status_code)

    health = burst_watching_health(server, post, 20)
    assert statuses == [422] * 20
    assert health and set(health) == {200}


# -- status codes ----------------------------------------------------------------------------------


def test_compare_options_and_content_types(server: Server, files: dict[str, Path]) -> None:
    data = files["small"].read_bytes()
    url = f"{server.url}/v1/compare"
    for options, words in (
        ({"params": "x"}, "options.params"),
        ({"directions": 2, "colour": 1}, "options.colour"),
        ({"albedo": "green"}, "options.albedo"),
        ({"methods": []}, "options.methods"),  # (it ran every method)
    ):
        response = httpx.post(
            url, files={"file": ("a.exr", data)}, data={"options": json.dumps(options)}
        )
        assert_problem(response, 422, words)
    for route in ("/v1/compare", "/v1/relief/pick"):
        response = httpx.post(f"{server.url}{route}", json={"x": 1})
        assert_problem(response, 415, "multipart/form-data")


def test_bad_map_is_422_and_names_the_form_field(server: Server, files: dict[str, Path]) -> None:
    body = assert_problem(
        enhance(server, files["small"], map=json.dumps({"normal": "Nope"})), 422, "map field"
    )
    assert "--map" not in body["detail"]
    assert_problem(enhance(server, files["small"], map=json.dumps({"lobes": "x"})), 422, "lobes")


def test_corrupt_pixels_400_with_the_library_words_in_one_line(
    server: Server, tmp_path: Path
) -> None:
    bad = write_corrupt(tmp_path / "corrupt.exr")
    body = assert_problem(enhance(server, bad), 400, "corrupt.exr: corrupt pixel data")
    assert "OpenEXR:" in body["detail"] and "\n" not in body["detail"]
    assert "/tmp" not in body["detail"]
    json_log_only(server)  # the library's own output went into the answer, not the log


# -- slow clients ----------------------------------------------------------------------------------


def trickle(port: int, headers_done: bool, out: dict[str, object]) -> None:
    """Send a request one byte every 0.3 s (its headers, or its body) until the server answers
    or closes; record what came back and when."""
    start = time.monotonic()
    head = (
        b"POST /v1/enhance HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; "
        b"boundary=b\r\nContent-Length: 100000\r\n\r\n"
    )
    with socket.create_connection(("127.0.0.1", port), timeout=30) as s:
        if headers_done:
            s.sendall(head)
            head = b"--b\r\n" + b"x" * 1000
        s.settimeout(0.3)
        reply = b""
        for byte in head:
            try:
                s.sendall(bytes([byte]))
                chunk = s.recv(65536)
                if not chunk:
                    break
                reply += chunk
                if b"\r\n\r\n" in reply:
                    break
            except TimeoutError:
                continue
            except OSError:  # reset by the server
                break
    out["reply"] = reply
    out["seconds"] = time.monotonic() - start


def test_slow_clients_are_answered_408_or_closed(server: Server) -> None:
    port = int(server.url.rsplit(":", 1)[1])
    results: list[dict[str, object]] = [{} for _ in range(40)]
    threads = [
        threading.Thread(target=trickle, args=(port, i % 2 == 0, results[i])) for i in range(40)
    ]
    for t in threads:
        t.start()
    time.sleep(0.5)
    assert httpx.get(f"{server.url}/healthz").status_code == 200
    for t in threads:
        t.join()
    for i, result in enumerate(results):
        reply = bytes(result["reply"])  # type: ignore[arg-type]
        assert float(result["seconds"]) < 25, result  # not kept open for the whole trickle
        if i % 2 == 0:  # headers sent, body trickling: 408 then closed
            assert reply.startswith(b"HTTP/1.1 408"), reply[:200]
        else:  # headers trickling: closed without an answer
            assert reply == b"", reply[:200]
    json_log_only(server)


def test_a_job_still_running_when_the_server_stops_is_answered_503() -> None:
    """SIGTERM: uvicorn lets requests finish for DEPICT_SHUTDOWN_GRACE_S, then cancels them;
    a cancelled request got a plain-text 500 and the log a traceback. Now a 503 problem with
    Retry-After, and the log stays JSON."""
    env = {"DEPICT_WORKERS": "1", "DEPICT_TIMEOUT_S": "300", "DEPICT_SHUTDOWN_GRACE_S": "1"}
    with live_server(env) as server:
        answer: dict[str, httpx.Response] = {}
        client = threading.Thread(target=lambda: answer.update(r=slow_compare(server, 1024)))
        client.start()
        wait_for("the job to run", lambda: metric(server, "depict_jobs_running ") >= 1)
        server.process.send_signal(signal.SIGTERM)
        client.join(timeout=120)
        body = assert_problem(answer["r"], 503, "the server is stopping")
        assert body["type"] == "urn:depict:problem:unavailable"
        assert answer["r"].headers["retry-after"] == "5"
        assert server.process.wait(timeout=60) in (0, -signal.SIGTERM)
        json_log_only(server)
