"""End to end against a real ``depict serve`` (uvicorn) on 127.0.0.1 (``conftest.py`` starts it).

The server's EXR is compared bit for bit with the CLI's local output (a canonical render and
the Blender Cycles fixture), its warnings, previews, scores and errors with the command line's;
16 concurrent requests against 2 workers and a queue of 2 give only 200s and 429s while /healthz
answers, and the server's memory comes back to its baseline afterwards. The error statuses from
real bad requests: ``test_server_errors.py``.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import socket
import threading
import time
from pathlib import Path

import httpx
import psutil
import pytest

from analysis.score import score_frame
from gbuffer.exr import read_layout
from gbuffer.io import read as read_exr
from service.cli import main as cli
from service.client import Client, DepictError
from service.headers import warning_text, warning_value
from tests import exr_factory
from tests.e2e.common import AUTH, BLENDER, KEY
from tests.exr_factory import TORN_MESH, render_with_nan
from tests.live_server import (
    Server,
    burst_watching_health,
    free_port,
    start_server,
    stop_server,
    wait_ready,
)
from tests.problem_json import assert_problem

# -- the same bytes as the CLI ------------------------------------------------------------------


def test_enhance_canonical_matches_local_cli_bit_for_bit(
    server: Server, files: dict[str, Path], tmp_path: Path, remote_env: None
) -> None:
    local, remote = tmp_path / "local.exr", tmp_path / "remote.exr"
    assert cli(["enhance", str(files["canonical"]), "-o", str(local)]) == 0
    assert cli(["enhance", str(files["canonical"]), "-o", str(remote), "--server", server.url]) == 0
    assert local.read_bytes() == remote.read_bytes()
    assert local.read_bytes() != files["canonical"].read_bytes()  # the operator did something


def test_several_files_locally_and_on_the_server_give_the_same_bytes(
    server: Server, files: dict[str, Path], tmp_path: Path, remote_env: None
) -> None:
    """``depict enhance A B C -o FOLDER``: one process (or one client), outputs named as their
    inputs, each the bytes of a single-file run; a file that fails is said on one line and the
    others are written (exit code 2)."""
    inputs = tmp_path / "in"
    inputs.mkdir()
    for name in ("a.exr", "b.exr"):
        shutil.copyfile(files["canonical"], inputs / name)
    (inputs / "bad.exr").write_bytes(b"not an exr")
    single = tmp_path / "single"
    single.mkdir()
    for name in ("a.exr", "b.exr"):  # the output records its input's name
        assert cli(["enhance", str(inputs / name), "-o", str(single / name)]) == 0
    names = [str(inputs / n) for n in ("a.exr", "bad.exr", "b.exr")]
    for where, extra in (("local", []), ("remote", ["--server", server.url])):
        out = tmp_path / where
        out.mkdir()
        assert cli(["enhance", *names, "-o", str(out), *extra]) == 2
        assert sorted(p.name for p in out.iterdir()) == ["a.exr", "b.exr"]
        for name in ("a.exr", "b.exr"):
            assert (out / name).read_bytes() == (single / name).read_bytes()
    assert cli(["enhance", *names, "-o", str(tmp_path / "x.exr")]) == 2  # not a folder
    twin = tmp_path / "twin"
    twin.mkdir()
    shutil.copyfile(files["canonical"], twin / "a.exr")
    clash = ["enhance", str(inputs / "a.exr"), str(twin / "a.exr"), "-o", str(tmp_path / "local")]
    assert cli(clash) == 2  # two outputs of one name: refused before anything is read


def test_enhance_blender_matches_local_cli_bit_for_bit(
    server: Server, tmp_path: Path, remote_env: None
) -> None:
    exr, camera = BLENDER / "cycles_multilayer.exr", BLENDER / "camera.json"
    if not exr.is_file():
        pytest.skip(f"Blender fixture {exr} is absent (tests/fixtures/blender/README.md)")
    local, remote = tmp_path / "local.exr", tmp_path / "remote.exr"
    args = ["enhance", str(exr), "--camera", str(camera), "--preset", "blender", "-o"]
    assert cli([*args, str(local)]) == 0
    assert cli([*args, str(remote), "--server", server.url]) == 0
    assert local.read_bytes() == remote.read_bytes()


@pytest.mark.parametrize("layout", ["part", "sidecar"])
def test_enhance_layouts_match_local_cli_bit_for_bit(
    layout: str, server: Server, files: dict[str, Path], tmp_path: Path, remote_env: None
) -> None:
    local, remote = tmp_path / "local.exr", tmp_path / "remote.exr"
    args = ["enhance", str(files["canonical"]), "--layout", layout, "-o"]
    assert cli([*args, str(local)]) == 0
    assert cli([*args, str(remote), "--server", server.url]) == 0
    assert local.read_bytes() == remote.read_bytes()
    written = [[c[0] for c in part.channels] for part in read_layout(remote).parts]
    assert len(written) == (2 if layout == "part" else 1)
    prefix = "Depict." if layout == "part" else ""  # a sidecar's result is its R,G,B,A
    assert sorted(written[-1]) == [prefix + c for c in "ABGR"]


@pytest.mark.parametrize("renderer", ["blender", "arnold", "karma"])
def test_enhance_factory_renderers_match_local_cli(
    server: Server,
    tmp_path: Path,
    remote_env: None,
    renderer: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Files in each renderer's layout (tests/exr_factory.py): multi-layer, world-space normals,
    multi-part with DWA; the server's answer is the CLI's, byte for byte, or the same error."""
    scene = exr_factory.make_scene()
    src = getattr(exr_factory, f"write_{renderer}")(tmp_path / f"{renderer}.exr", scene)
    camera = tmp_path / "camera.json"
    camera.write_text(json.dumps(scene.camera.to_dict()))
    args = ["enhance", str(src), "--camera", str(camera), "-o"]
    local, remote = tmp_path / "local.exr", tmp_path / "remote.exr"
    code = cli([*args, str(local)])
    local_err = capsys.readouterr().err
    assert cli([*args, str(remote), "--server", server.url]) == code
    if code == 0:
        assert local.read_bytes() == remote.read_bytes()
    else:  # the same message, relayed by the server
        detail = local_err.split("error: ", 1)[1].replace(str(src), src.name).strip()
        assert detail in capsys.readouterr().err


def test_render_matches_local_cli(
    server: Server, files: dict[str, Path], tmp_path: Path, remote_env: None
) -> None:
    local, remote = tmp_path / "local.exr", tmp_path / "remote.exr"
    args = ["render", str(files["mesh"]), "--width", "96", "--height", "64", "--light=-1,1,1"]
    assert cli([*args, "-o", str(local)]) == 0
    assert cli([*args, "-o", str(remote), "--server", server.url]) == 0
    assert local.read_bytes() == remote.read_bytes()


def test_the_server_says_what_the_command_line_warns(
    server: Server,
    files: dict[str, Path],
    tmp_path: Path,
    remote_env: None,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """NaN pixels read as holes, triangles left out, an output not named .exr: a file answer
    carries its warnings as Depict-Warning headers (they were dropped), and ``--server`` prints
    them as the local command does."""
    holes = render_with_nan(tmp_path / "holes.exr", (96, 72), {"beauty": [(36, 48, 0, math.nan)]})
    mesh = tmp_path / "torn.obj"
    mesh.write_text(TORN_MESH)
    commands = [
        ["enhance", str(holes), "-o", str(tmp_path / "{}.exr")],
        ["render", str(mesh), "--width", "32", "--height", "24", "-o", str(tmp_path / "{}.out")],
    ]
    for command in commands:
        said = []
        for where, extra in (("local", []), ("remote", ["--server", server.url])):
            assert cli([arg.format(where) for arg in command] + extra) == 0
            said.append(capsys.readouterr().err.replace(where, "WHERE"))
        assert said[0].count("depict: warning: ") == len(said[0].splitlines()) >= 1
        assert said[1] == said[0]
    response = httpx.post(
        f"{server.url}/v1/render",
        files={"mesh": ("torn.obj", mesh.read_bytes())},
        data={"scene": '{"width": 32, "height": 24}'},
        headers=AUTH,
        timeout=60,
    )
    assert response.status_code == 200, response.text
    assert response.headers.get_list("depict-warning") == [
        "1 of the mesh's 3 triangles have a vertex with NaN or infinite coordinates: they are "
        "left out"
    ]
    clean = httpx.post(
        f"{server.url}/v1/enhance",
        files={"file": ("a.exr", files["canonical"].read_bytes())},
        headers=AUTH,
        timeout=60,
    )
    assert clean.status_code == 200 and "depict-warning" not in clean.headers


def test_a_warning_header_gives_back_any_text() -> None:
    for text in ("plain", "100 % of 3 pixels", "ünïcode naïve ☂", "a\nline\x1b[31m", "%41"):
        value = warning_value(text)
        assert value.isascii() and value.isprintable()
        assert warning_text(value) == text


def test_preview_png(server: Server, files: dict[str, Path]) -> None:
    """The config's default view (ACES 2.0 SDR), or Depict's exposure and clip (``raw``)."""
    pngs = []
    for query in ("", "&view=raw"):
        response = httpx.post(
            f"{server.url}/v1/enhance?preview=png{query}",
            files={"file": ("a.exr", files["canonical"].read_bytes())},
            headers=AUTH,
            timeout=60,
        )
        assert response.status_code == 200, response.text
        assert response.headers["content-type"] == "image/png"
        assert response.content[:8] == b"\x89PNG\r\n\x1a\n"
        pngs.append(response.content)
    assert pngs[0] != pngs[1]


def test_python_client_and_score_match_local(server: Server, files: dict[str, Path]) -> None:
    with Client(server.url, api_key=KEY) as client:
        assert client.health()["status"] == "ok" and client.ready()["osmesa"] is True
        assert "radiance_scaling" in {op["name"] for op in client.operators()}
        remote = client.score(files["canonical"], gradient_scale=0.004)
    local = score_frame(read_exr(files["canonical"]), gradient_scale=0.004)
    # OpenCV's multi-threaded reductions change the last digits from run to run (1e-11)
    assert remote["score"] == pytest.approx(local["score"], rel=1e-9, abs=1e-12)
    assert 0.0 < remote["score"] <= 1.0
    assert remote["params"] == local["params"]
    assert remote["analysis_shape"] == local["analysis_shape"]
    with Client(server.url, api_key=KEY) as client:  # the working space named by the client
        acescg = client.score(files["canonical"], gradient_scale=0.004, colorspace="ACEScg")
    local = score_frame(
        read_exr(files["canonical"], options={"colorspace": "ACEScg"}), gradient_scale=0.004
    )
    assert acescg["score"] == pytest.approx(local["score"], rel=1e-9, abs=1e-12)
    assert acescg["score"] != pytest.approx(remote["score"], rel=1e-9, abs=1e-12)
    with Client(server.url, api_key="wrong") as client, pytest.raises(DepictError) as err:
        client.operators()
    assert err.value.status == 401 and err.value.problem["type"].endswith(":unauthorized")
    with Client(f"http://127.0.0.1:{free_port()}") as client, pytest.raises(DepictError) as err:
        client.health()
    assert err.value.status == 0 and "cannot reach" in str(err.value)


@pytest.mark.parametrize(
    "command",
    [
        ["enhance", "{bad}", "-o", "{out}"],
        ["score", "{bad}"],
        ["compare", "{bad}", "--directions", "1"],
        ["relief-pick", "{bad}", "1", "1"],
    ],
    ids=["enhance", "score", "compare", "relief-pick"],
)
def test_remote_error_exits_like_local(
    server: Server,
    tmp_path: Path,
    remote_env: None,
    capsys: pytest.CaptureFixture[str],
    command: list[str],
) -> None:
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an exr at all")
    out = tmp_path / "o.exr"
    args = [a.format(bad=bad, out=out) for a in command]
    assert cli([*args, "--server", server.url]) == 2
    err = capsys.readouterr().err
    assert err.startswith("depict: error: server answered 400") and "bad.exr" in err
    assert err.count("\n") == 1  # one line, no traceback
    assert not out.exists()


def test_unreachable_server_is_one_line(
    tmp_path: Path, remote_env: None, capsys: pytest.CaptureFixture[str]
) -> None:
    url = f"http://127.0.0.1:{free_port()}"
    frame = tmp_path / "x.exr"
    frame.write_bytes(b"anything: it never leaves")
    assert cli(["score", str(frame), "--server", url]) == 2
    err = capsys.readouterr().err
    assert err.startswith("depict: error: cannot reach") and err.count("\n") == 1


#: A frame to send (the Blender fixture), and a mesh.
FRAME = BLENDER / "cycles_multilayer.exr"
MESH = Path(__file__).resolve().parents[2] / "examples" / "spot.obj"


def test_what_the_client_cannot_send_is_one_line(
    tmp_path: Path, remote_env: None, capsys: pytest.CaptureFixture[str]
) -> None:
    """A FIFO input (the upload waited for a writer for ever), a device (it never ended), a
    malformed server URL, an API key no HTTP header can hold, and read flags a route does not
    take: each a traceback, a hang or a flag dropped before, now one line and exit 2, with
    nothing sent."""
    fifo = tmp_path / "fifo.exr"
    os.mkfifo(fifo)
    bad_camera = tmp_path / "camera.json"
    bad_camera.write_text("{")
    url = f"http://127.0.0.1:{free_port()}"
    render_bad_camera = ["render", str(MESH), "-o", str(tmp_path / "r.exr"), "--server", url]
    render_bad_camera += ["--camera", str(bad_camera)]
    for args, words in (
        (["score", str(fifo), "--server", url], "it is a FIFO (named pipe), not a regular file"),
        (["score", "/dev/zero", "--server", url], "it is a character device, not a regular"),
        (["score", str(FRAME), "--server", "http://host:port"], "is not valid: Invalid port"),
        # (dropped without a word: a score unlike the same command here)
        (
            ["relief-pick", str(FRAME), "9", "9", "--map", "normal=N", "--server", url],
            "--map: not sent to a server by relief-pick",
        ),
        (
            ["compare", str(FRAME), "--normal-space", "world", "--server", url],
            "--normal-space: not sent to a server by compare",
        ),
        (  # (the JSON error did not name the file)
            render_bad_camera,
            f"cannot read camera file {bad_camera}: Expecting property name",
        ),
    ):
        assert cli(args) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1, err
    with pytest.raises(DepictError, match=r"API key .* must be printable ASCII"):
        Client(url, api_key="clé")


def test_an_answer_cut_short_is_one_line_and_leaves_the_output(
    tmp_path: Path, remote_env: None, capsys: pytest.CaptureFixture[str]
) -> None:
    """A server that goes away while it sends the result (killed, a proxy's timeout): one line
    and exit 2 (it was httpx's RemoteProtocolError, exit 1); the output kept as it was."""
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]

    def answer_part() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.settimeout(10)
            data = b""
            while b"--\r\n" not in data[-64:]:  # (the multipart body's end)
                data += conn.recv(1 << 16)
            conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: 100000\r\n\r\n" + b"x" * 1000)

    thread = threading.Thread(target=answer_part)
    thread.start()
    out = tmp_path / "out.exr"
    out.write_bytes(b"the output before this run")
    args = ["enhance", str(FRAME), "-o", str(out), "--server", f"http://127.0.0.1:{port}"]
    try:
        assert cli(args) == 2
    finally:
        thread.join(timeout=30)
        listener.close()
    err = capsys.readouterr().err
    assert "was cut short" in err and err.count("\n") == 1, err
    assert out.read_bytes() == b"the output before this run"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]


def _cli_json(args: list[str], capsys: pytest.CaptureFixture[str]) -> dict:
    assert cli(args) == 0
    data = json.loads(capsys.readouterr().out)
    data.pop("seconds", None)  # timings differ from run to run
    return data


@pytest.mark.parametrize(
    "command",
    [
        ["score", "{canonical}", "--json", "--op", "light_alignment"],
        [
            "compare",
            "{canonical}",
            "--json",
            "--directions",
            "2",
            "--methods",
            "lambert,light_alignment",
        ],
        ["compare", "{mesh}", "--json", "--directions", "1", "--width", "96", "--height", "96"],
        ["relief-pick", "{canonical}", "80", "60", "--json"],
    ],
    ids=["score", "compare-exr", "compare-mesh", "relief-pick"],
)
def test_analysis_commands_print_the_same_remotely(
    server: Server,
    files: dict[str, Path],
    command: list[str],
    remote_env: None,
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = [a.format(**{k: str(v) for k, v in files.items()}) for a in command]
    local = _cli_json(args, capsys)
    remote = _cli_json([*args, "--server", server.url], capsys)
    assert_close(remote, local)


def assert_close(a: object, b: object, where: str = "") -> None:
    """Equal JSON, numbers to 1e-6 (OpenCV threads sum in a different order in a worker)."""
    if isinstance(b, dict):
        assert isinstance(a, dict) and a.keys() == b.keys(), where
        for key in b:
            assert_close(a[key], b[key], f"{where}.{key}")
    elif isinstance(b, list):
        assert isinstance(a, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_close(x, y, f"{where}[{i}]")
    elif isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-6, abs=1e-6), where
    else:
        assert a == b, where


def test_compare_sheet_comes_back_over_http(
    server: Server, files: dict[str, Path], tmp_path: Path, remote_env: None
) -> None:
    sheet, plot = tmp_path / "sheet.png", tmp_path / "plot.png"
    args = ["compare", str(files["canonical"]), "--directions", "1", "--sheet", str(sheet)]
    assert cli([*args, "--plot", str(plot), "--server", server.url]) == 0
    assert sheet.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and plot.stat().st_size > 1000


# -- saturation ---------------------------------------------------------------------------------


def tree_rss(pid: int) -> int:
    """RSS of the server process and its workers, bytes."""
    proc = psutil.Process(pid)
    return sum(p.memory_info().rss for p in [proc, *proc.children(recursive=True)])


def test_saturation_only_200_and_429_health_answers_memory_returns(
    server: Server, files: dict[str, Path]
) -> None:
    data = files["big"].read_bytes()

    def enhance() -> httpx.Response:
        with httpx.Client(timeout=120) as client:
            return client.post(
                f"{server.url}/v1/enhance", files={"file": ("big.exr", data)}, headers=AUTH
            )

    # warm both workers, then take the baseline
    warm = [threading.Thread(target=enhance) for _ in range(2)]
    for t in warm:
        t.start()
    for t in warm:
        t.join()
    baseline = tree_rss(server.process.pid)

    statuses: list[int] = []
    retry_after: list[str] = []
    barrier = threading.Barrier(16)

    def one() -> None:
        barrier.wait()
        r = enhance()
        statuses.append(r.status_code)
        if r.status_code == 429:
            retry_after.append(r.headers.get("retry-after", ""))

    health = burst_watching_health(server, one, 16)

    assert len(statuses) == 16
    assert set(statuses) <= {200, 429}, statuses
    assert statuses.count(200) >= 2 and statuses.count(429) >= 1, statuses
    assert all(v.isdigit() and int(v) >= 1 for v in retry_after), retry_after
    assert health and set(health) == {200}, health

    metrics = httpx.get(f"{server.url}/metrics", headers=AUTH).text
    assert 'depict_http_requests_total{method="POST",route="/v1/enhance",status="429"}' in metrics
    assert "depict_operator_duration_seconds_count" in metrics
    assert "depict_jobs_queued 0.0" in metrics

    after = tree_rss(server.process.pid)
    for _ in range(20):  # give the allocator a moment
        if after <= baseline * 1.3 + 150 * 2**20:
            break
        time.sleep(0.25)
        after = tree_rss(server.process.pid)
    assert after <= baseline * 1.3 + 150 * 2**20, (baseline / 2**20, after / 2**20)


# -- time limit ---------------------------------------------------------------------------------


def test_job_over_time_limit_504(servers: dict[str, Server], files: dict[str, Path]) -> None:
    slow = servers["slow"]
    response = httpx.post(
        f"{slow.url}/v1/enhance",
        files={"file": ("a.exr", files["canonical"].read_bytes())},
        timeout=60,
    )
    assert_problem(response, 504, "DEPICT_TIMEOUT_S")
    assert httpx.get(f"{slow.url}/healthz").status_code == 200
    metrics = httpx.get(f"{slow.url}/metrics").text
    assert 'depict_jobs_total{kind="enhance",outcome="timeout"} 1.0' in metrics


def test_health_metrics_and_operators(server: Server) -> None:
    assert httpx.get(f"{server.url}/readyz").json()["osmesa"] is True
    ops = httpx.get(f"{server.url}/v1/operators", headers=AUTH).json()
    assert any(op["name"] == "radiance_scaling" for op in ops)
    assert all({"name", "params", "needs", "writes"} <= set(op) for op in ops)


def test_a_stopped_server_and_its_workers_exit_cleanly(files: dict[str, Path]) -> None:
    """SIGTERM after a job: the server stops gracefully and its workers end without the
    interpreter's teardown, whose "nanobind: leaked ..." lines (the OpenImageIO binding) filled
    the log at every stop."""
    server = start_server({"DEPICT_WORKERS": "2", "DEPICT_API_KEY": ""})
    try:
        wait_ready(server)
        with files["canonical"].open("rb") as f:
            r = httpx.post(f"{server.url}/v1/enhance", files={"file": f}, timeout=120)
        assert r.status_code == 200, r.text
        server.process.send_signal(signal.SIGTERM)
        # uvicorn stops gracefully, then ends by the signal it was sent (as a shell expects)
        assert server.process.wait(timeout=30) in (0, -signal.SIGTERM)
        logs = server.logs()
        assert "Application shutdown complete" in logs
        assert "leaked" not in logs and "Traceback" not in logs, logs[-2000:]
    finally:
        stop_server(server)
