"""The HTTP app in process (Starlette's TestClient): contract, settings, auth, errors, metrics.

The real-server behaviour (bit-for-bit outputs, saturation, time limit) is in
tests/e2e/; here every answer still goes through the real app, its middleware and
its worker pool.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import OpenEXR
import pytest
from pydantic import ValidationError

from gbuffer.errors import FrameError, LimitError, MissingBufferError, MissingCameraError
from service import problems
from service.http.app import create_app
from service.http.middleware import wrap
from service.logs import JsonFormatter
from service.metrics import Metrics
from service.openapi import DEFAULT_PATH, dumps
from service.registry import PipelineError, operators
from service.settings import Settings
from tests.exr_factory import cropped, make_scene, write_canonical
from tests.problem_json import assert_problem
from tests.test_output_layout import two_view_layers

pytestmark = pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")

KEY = "test-key"
AUTH = {"Authorization": f"Bearer {KEY}"}


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    from fastapi.testclient import TestClient

    app = create_app(Settings(api_key=KEY, workers=1, queue=1, max_pixels=640 * 480))
    with TestClient(app, raise_server_exceptions=False) as c:
        deadline = time.monotonic() + 120
        while c.get("/readyz").status_code != 200:  # the worker warms up in the background
            assert time.monotonic() < deadline, c.get("/readyz").text
            time.sleep(0.2)
        yield c


@pytest.fixture(scope="module")
def gate() -> Iterator[Any]:
    """The app's front middleware alone (no key, public metrics, tiny body limit) before an
    inner app that answers 200 to everything it is given."""
    from fastapi.testclient import TestClient

    async def inner(scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            return
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"inner"})

    settings = Settings(api_key=KEY, metrics_public=True, max_upload_mb=0.05)
    yield TestClient(wrap(inner, settings=settings, metrics=Metrics()))  # no lifespan needed


def exr_bytes() -> bytes:
    """Any bytes with the EXR magic number but no valid header."""
    return b"\x76\x2f\x31\x01" + b"\x02\x00\x00\x00" + b"\x00" * 64


# -- settings ----------------------------------------------------------------------------------


def test_settings_defaults_and_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("HOST", "PORT", "API_KEY", "WORKERS", "QUEUE", "TIMEOUT_S", "MAX_UPLOAD_MB"):
        monkeypatch.delenv(f"DEPICT_{name}", raising=False)
    s = Settings()
    assert (s.host, s.port, s.workers, s.queue, s.timeout_s) == ("127.0.0.1", 8000, 2, 8, 120.0)
    assert s.key is None and s.max_upload_bytes == 512 * 2**20 and s.max_pixels == 8192**2
    assert s.shutdown_grace_s == 10.0
    monkeypatch.setenv("DEPICT_SHUTDOWN_GRACE_S", "2.5")  # (seconds, as every *_S)
    assert Settings().shutdown_grace_s == 2.5
    monkeypatch.setenv("DEPICT_WORKERS", "3")
    monkeypatch.setenv("DEPICT_API_KEY", "abc")
    monkeypatch.setenv("DEPICT_MAX_UPLOAD_MB", "1.5")
    s = Settings()
    assert s.workers == 3 and s.key == "abc" and s.max_upload_bytes == int(1.5 * 2**20)
    assert "abc" not in repr(s)  # the key is a secret
    monkeypatch.setenv("DEPICT_WORKERS", "0")
    with pytest.raises(ValidationError, match="workers"):
        Settings()


# -- the contract ------------------------------------------------------------------------------


def test_served_openapi_is_the_committed_file(client: Any) -> None:
    served = client.get("/openapi.json").json()
    committed = json.loads(DEFAULT_PATH.read_text())
    assert served == committed, (
        "openapi/openapi.json is stale: regenerate it with `python -m service.openapi`"
    )
    assert DEFAULT_PATH.read_text() == dumps(served)


def test_openapi_has_every_operator_and_the_problem_schema(client: Any) -> None:
    schema = client.get("/openapi.json").json()
    branches = schema["components"]["schemas"]["Pipeline"]["properties"]["steps"]["items"]
    names = {b["properties"]["op"]["const"] for b in branches["oneOf"]}
    assert names == set(operators())
    assert "Problem" in schema["components"]["schemas"]
    enhance = schema["paths"]["/v1/enhance"]["post"]
    assert {"400", "401", "413", "415", "422", "429", "504"} <= set(enhance["responses"])
    assert "/healthz" in schema["paths"] and "security" not in schema["paths"]["/healthz"]["get"]


def test_operators_route_lists_the_registry(client: Any) -> None:
    ops = client.get("/v1/operators", headers=AUTH).json()
    assert [op["name"] for op in ops] == list(operators())
    assert all(op["params"]["type"] == "object" for op in ops)


# -- problems ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("exc", "status", "kind"),
    [
        (FrameError("x"), 400, "bad-file"),
        (LimitError("x"), 413, "limit"),
        (MissingBufferError("x"), 422, "missing-buffer"),
        (MissingCameraError("x"), 422, "missing-camera"),
        (PipelineError("x"), 422, "invalid-request"),
        (RuntimeError("x"), 500, "internal"),
    ],
)
def test_exception_mapping(exc: Exception, status: int, kind: str) -> None:
    p = problems.from_exception(exc)
    assert (p.status, p.kind) == (status, kind)
    body = p.body("/v1/enhance", "rid")
    assert body["type"] == f"urn:depict:problem:{kind}" and body["request_id"] == "rid"
    assert (body["detail"] == "x") == (status != 500)  # internals are never shown


def test_unknown_problem_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="problem kind"):
        problems.Problem("nope", "x")


# -- auth --------------------------------------------------------------------------------------


def test_api_key(client: Any) -> None:
    c = client
    assert c.get("/healthz").status_code == 200
    assert c.get("/readyz").json()["osmesa"] is True
    assert_problem(c.get("/v1/operators"), 401, "Authorization: Bearer")
    wrong = c.get("/v1/operators", headers={"Authorization": "Bearer x"})
    assert_problem(wrong, 401, "wrong")
    basic = c.get("/v1/operators", headers={"Authorization": f"Basic {KEY}"})
    assert_problem(basic, 401)
    assert c.get("/v1/operators", headers=AUTH).status_code == 200
    assert_problem(c.get("/metrics"), 401)
    assert c.get("/metrics", headers=AUTH).status_code == 200


def test_metrics_public_without_key(gate: Any) -> None:
    assert gate.get("/metrics").text == "inner"  # let through without the key
    assert_problem(gate.get("/v1/operators"), 401)  # the key is still needed elsewhere


# -- bad requests ------------------------------------------------------------------------------


def test_content_type_415(client: Any) -> None:
    r = client.post("/v1/enhance", headers=AUTH, content=b"x")
    assert_problem(r, 415, "multipart/form-data")
    r = client.post("/v1/render", headers=AUTH, json={"mesh": 1})
    assert_problem(r, 415, "application/json")
    # the viewer's upload too (it answered 422 "file: Field required")
    r = client.post("/v1/frames", headers={**AUTH, "Content-Type": "image/x-exr"}, content=b"x")
    assert_problem(r, 415, "/v1/frames takes multipart/form-data")


def test_body_limit_413(gate: Any) -> None:
    r = gate.post("/v1/enhance", headers=AUTH, files={"file": ("a.exr", b"\0" * 60_000)})
    assert_problem(r, 413, "DEPICT_MAX_UPLOAD_MB")
    r = gate.post("/v1/enhance", headers=AUTH, files={"file": ("a.exr", b"\0" * 1_000)})
    assert r.text == "inner"


def test_not_found_and_method_problems(client: Any) -> None:
    assert_problem(client.get("/nope", headers=AUTH), 404, "no route")
    assert_problem(client.get("/v1/enhance", headers=AUTH), 405, "does not accept GET")


def test_not_an_exr_400(client: Any) -> None:
    r = client.post("/v1/enhance", headers=AUTH, files={"file": ("x.exr", b"hello")})
    body = assert_problem(r, 400, "x.exr is not an OpenEXR file")
    assert body["type"] == "urn:depict:problem:bad-file"
    r = client.post("/v1/enhance", headers=AUTH, files={"file": ("e.exr", b"")})
    assert_problem(r, 400, "empty file")
    r = client.post("/v1/enhance", headers=AUTH, files={"file": ("h.exr", exr_bytes())})
    body = assert_problem(r, 400, "h.exr")
    assert "/tmp" not in body["detail"]


@pytest.mark.parametrize(
    ("data", "words"),
    [
        ({"pipeline": "{"}, "not valid JSON"),
        ({"pipeline": "9" * 5000}, "more digits than can be read"),
        ({"camera": '{"focal_px": ' + "9" * 5000 + "}"}, "'camera' holds a number with more"),
        ({"pipeline": '{"steps": []}'}, "steps"),
        ({"pipeline": '[{"op": "nope"}]'}, "unknown operator 'nope'"),
        ({"camera": "[1, 2]"}, "'camera' must be a JSON object"),
        ({"camera": '{"fov_y_deg": 500}'}, "fov_y_deg"),
        ({"camera": '{"focal_px": [1], "height": 2}'}, "camera"),
        ({"map": '{"normal": 3}'}, "map"),
        ({"preset": "maya"}, "preset 'maya' is unknown"),
        ({"output_layer": "a/b"}, "output_layer"),
        ({"output_layer": "ViewLayer..Depict"}, "output_layer"),
        ({"normal_space": "up"}, "normal_space"),
        ({"colorspace": "nope"}, "colorspace: colour space 'nope' is not in the OCIO config"),
        ({"colorspace": "srgb_tx"}, "is not linear"),
        ({"layout": "beside"}, "layout"),
    ],
)
def test_invalid_request_422(client: Any, data: dict[str, str], words: str) -> None:
    r = client.post("/v1/enhance", headers=AUTH, files={"file": ("a.exr", exr_bytes())}, data=data)
    assert_problem(r, 422, words)


@pytest.mark.parametrize(
    ("route", "data", "words"),
    [  # (each answered 200: the default pipeline; a score of the whole frame)
        ("/v1/enhance", {"pipline": "{}"}, "unknown form field 'pipline'; /v1/enhance takes: "),
        ("/v1/enhance?exposur=2", {}, "unknown query parameter 'exposur'"),
        ("/v1/score", {"mask": "AO.X", "light": "1,1,1"}, "unknown form fields 'light', 'mask'"),
        ("/v1/relief/pick", {"x": "1", "y": "1", "scale": "2"}, "unknown form field 'scale'"),
        ("/v1/enhance?preview=png&exposure=nan", {}, "finite number"),  # (it said "<= 20")
        ("/v1/score", {"gradient_scale": "nan"}, "finite number"),  # (it said "<= 0.1")
    ],
)
def test_unknown_fields_and_odd_queries_422(
    client: Any, route: str, data: dict[str, str], words: str
) -> None:
    r = client.post(route, headers=AUTH, files={"file": ("a.exr", exr_bytes())}, data=data)
    assert_problem(r, 422, words)


def test_a_form_field_given_twice_422(client: Any) -> None:
    """The last of two ``pipeline`` fields (or files) was taken, the first dropped unsaid."""
    steps = ['[{"op": "curvature"}]', '[{"op": "unsharp_masking"}]']
    r = client.post(
        "/v1/enhance",
        headers=AUTH,
        files={"file": ("a.exr", exr_bytes())},
        data={"pipeline": steps},
    )
    assert_problem(r, 422, "form field 'pipeline' given more than once")
    two = [("file", ("a.exr", exr_bytes())), ("file", ("b.exr", exr_bytes()))]
    assert_problem(
        client.post("/v1/enhance", headers=AUTH, files=two), 422, "'file' given more than once"
    )
    r = client.post("/v1/enhance?preview=png&preview=png", headers=AUTH, files=two[:1])
    assert_problem(r, 422, "query parameter 'preview' given more than once")


@pytest.mark.parametrize(
    ("query", "words"),
    [("view=nope", "view 'nope' is not a view of display"), ("display=nope", "display 'nope'")],
)
def test_unknown_preview_view_422(client: Any, query: str, words: str) -> None:
    r = client.post(
        f"/v1/enhance?preview=png&{query}", headers=AUTH, files={"file": ("a.exr", exr_bytes())}
    )
    assert_problem(r, 422, words)


def test_missing_file_field_422(client: Any) -> None:
    r = client.post("/v1/enhance", headers=AUTH, files={"other": ("a", b"x")})
    assert_problem(r, 422, "file")


def test_render_requests(client: Any) -> None:
    mesh = ("m.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    r = client.post("/v1/render", headers=AUTH, files={"mesh": ("m.txt", b"x")})
    assert_problem(r, 415, ".obj")
    big = {"scene": '{"width": 1000, "height": 1000}'}
    r = client.post("/v1/render", headers=AUTH, files={"mesh": mesh}, data=big)
    assert_problem(r, 413, "DEPICT_MAX_PIXELS")
    for scene, words in [
        ("{", "scene"),
        ('{"width": 0}', "width"),
        ('{"width": true}', "expected a number, not true or false"),
        ('{"colour": 1}', "colour"),
        ('{"camera": {"fov_y_deg": -1}}', "scene.camera"),
    ]:
        r = client.post("/v1/render", headers=AUTH, files={"mesh": mesh}, data={"scene": scene})
        assert_problem(r, 422, words)
    r = client.post(
        "/v1/render",
        headers=AUTH,
        files={"mesh": mesh},
        data={"scene": '{"width": 32, "height": 24, "lights": ["sideways"]}'},
    )
    assert_problem(r, 422, "scene.lights")
    small = {"scene": '{"width": 32, "height": 24}'}
    r = client.post("/v1/render", headers=AUTH, files={"mesh": ("bad.ply", b"garbage")}, data=small)
    assert_problem(r, 400, "bad.ply")
    r = client.post(
        "/v1/render",
        headers=AUTH,
        files={"mesh": mesh},
        data={"scene": '{"width": 32, "height": 24}'},
    )
    assert r.status_code == 200 and r.headers["content-type"] == "image/x-exr"
    assert r.content[:4] == b"\x76\x2f\x31\x01"


def test_each_request_workspace_is_removed_after_its_answer(client: Any) -> None:
    """A file answer is sent from the request's workspace, which goes once it is sent; one of a
    refused upload goes too."""
    root = client.app.state.services.root
    mesh = ("m.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = {"scene": '{"width": 32, "height": 24}'}
    r = client.post("/v1/render", headers=AUTH, files={"mesh": mesh}, data=scene)
    assert r.status_code == 200 and r.content[:4] == b"\x76\x2f\x31\x01"
    assert_problem(
        client.post("/v1/score", headers=AUTH, files={"file": ("h.exr", exr_bytes())}), 400
    )
    assert root is not None and root.is_dir() and not list(root.iterdir())


# -- request ids, metrics, logs ----------------------------------------------------------------


def test_request_id(client: Any) -> None:
    r = client.get("/healthz", headers={"X-Request-ID": "abc-123"})
    assert r.headers["x-request-id"] == "abc-123"
    r = client.get("/healthz", headers={"X-Request-ID": "bad id\twith spaces"})
    generated = r.headers["x-request-id"]
    assert generated != "bad id\twith spaces" and len(generated) == 32
    r = client.get("/v1/operators", headers={"X-Request-ID": "xyz"})
    assert r.json()["request_id"] == "xyz" == r.headers["x-request-id"]


def test_metrics_count_requests_by_route(client: Any) -> None:
    client.get("/healthz")
    client.get("/no/such/path/123", headers=AUTH)
    text = client.get("/metrics", headers=AUTH).text
    assert 'depict_http_requests_total{method="GET",route="/healthz",status="200"}' in text
    assert 'route="other",status="404"' in text and "/no/such/path" not in text
    assert 'depict_http_requests_total{method="GET",route="/v1/operators",status="401"}' in text
    for name in (
        "depict_http_request_duration_seconds_bucket",
        "depict_http_requests_in_flight",
        "depict_jobs_queued",
        "depict_jobs_running",
        "depict_http_request_bytes_total",
        "depict_http_response_bytes_total",
    ):
        assert name in text


def test_json_log_lines() -> None:
    record = logging.LogRecord("depict.http", logging.INFO, __file__, 1, "request", (), None)
    record.status = 200
    record.route = "/healthz"
    line = json.loads(JsonFormatter().format(record))
    assert line["msg"] == "request" and line["status"] == 200 and line["level"] == "info"
    assert "request_id" in line and line["ts"].endswith("Z")


def test_a_frame_of_one_pixel_422_and_the_worker_stays(client: Any, tmp_path: Any) -> None:
    """(It used to fail inside OpenCV: a 500 and a worker retired for every such request.)"""
    px = cropped(make_scene(48, 64), slice(24, 25), slice(32, 33))
    data = write_canonical(tmp_path / "px.exr", px).read_bytes()
    for _ in range(2):
        r = client.post("/v1/enhance", headers=AUTH, files={"file": ("px.exr", data)})
        assert_problem(r, 422, "the frame is 1x1 pixels")
    assert client.get("/readyz").status_code == 200


@pytest.mark.parametrize(
    ("size", "refused"), [(0, False), (10_000, False), (3 << 20, False), (3 << 20, True)]
)
def test_an_upload_is_saved_whole_from_memory_or_disk(
    tmp_path: Any, monkeypatch: pytest.MonkeyPatch, size: int, refused: bool
) -> None:
    """The form parser keeps a part of up to 1 MiB in memory and a larger one on disk
    (Starlette's spooled file); either is saved whole (copied by the kernel), as is a file
    object without a descriptor, and a file where the kernel refuses to copy between files
    (``sendfile`` of macOS: EINVAL)."""
    import errno
    import io
    import os
    import tempfile

    import anyio
    from starlette.datastructures import UploadFile

    from service.http.uploads import save

    if refused:

        def no_sendfile(*args: object) -> int:
            raise OSError(errno.EINVAL, "Invalid argument")

        monkeypatch.setattr(os, "sendfile", no_sendfile)
    data = os.urandom(size)
    spooled = tempfile.SpooledTemporaryFile(max_size=1 << 20)
    spooled.write(data)
    for n, source in enumerate([spooled, io.BytesIO(data)]):
        target = tmp_path / f"saved{n}.exr"
        got = anyio.run(save, UploadFile(source), target)  # type: ignore[arg-type]
        assert got == size and target.read_bytes() == data


def test_the_view_layer_form_field_chooses_the_layer(client: Any, tmp_path: Path) -> None:
    """``view_layer`` reads that view layer of a render with several, as ``--view-layer``."""
    data = two_view_layers(tmp_path).read_bytes()
    for layer in ("Back", "ViewLayer"):
        r = client.post(
            "/v1/enhance",
            headers=AUTH,
            files={"file": ("two.exr", data)},
            data={"view_layer": layer},
        )
        assert r.status_code == 200, r.text
        out = tmp_path / f"{layer}.exr"
        out.write_bytes(r.content)
        with OpenEXR.File(str(out), separate_channels=True) as f:
            names = {n for part in f.parts for n in part.channels}
        assert f"{layer}.Depict.R" in names and len([n for n in names if ".Depict." in n]) == 4
    r = client.post(
        "/v1/enhance", headers=AUTH, files={"file": ("two.exr", data)}, data={"view_layer": "No"}
    )
    assert_problem(r, 422, "view layer 'No' not in the file; layers: Back, ViewLayer")
