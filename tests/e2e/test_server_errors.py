"""Every error status of ``depict serve`` from a real bad request: bad files, cut-short uploads,
malformed HTTP, limits, content types, pipelines, keys; each a problem+json naming what is wrong."""

from __future__ import annotations

import json
import struct
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest

from tests import exr_factory
from tests.e2e.common import AUTH, MAX_UPLOAD_MB, post_enhance
from tests.live_server import Server
from tests.problem_json import assert_problem


def test_file_paths_in_parameters_are_refused_over_http(
    server: Server, files: dict[str, Path]
) -> None:
    """A pipeline must not make the server read its own files (matcaps, gain maps, ARMs)."""
    for op, params in (
        ("radiance_scaling", {"scenario": "lit_sphere", "matcap": "/etc/hostname"}),
        ("unsharp_masking", {"gain_map": "/etc/hostname"}),
        ("apparent_relief", {"arm": "/etc/hostname"}),
    ):
        data = {"pipeline": json.dumps([{"op": op, "params": params}])}
        response = post_enhance(server, files["canonical"].read_bytes(), data=data)
        assert_problem(response, 422, "cannot be named here" if op != "unsharp_masking" else "")


def test_file_paths_in_compare_parameters_are_refused(
    server: Server, files: dict[str, Path], tmp_path: Path
) -> None:
    """``/v1/compare`` runs the methods with the client's parameters: an image on the server
    named there (a matcap, a mask) is refused as on ``/v1/enhance``, not read and scored."""
    image = tmp_path / "on_the_server.png"
    cv2.imwrite(str(image), np.full((8, 8, 3), 200, np.uint8))
    for method, params, words in (
        ("radiance_scaling", {"scenario": "lit_sphere", "matcap": str(image)}, "cannot be named"),
        ("light_alignment", {"mask": str(image)}, "no layer"),  # (a layer's name, not a file)
    ):
        options = {"directions": 1, "methods": [method], "params": {method: params}}
        response = httpx.post(
            f"{server.url}/v1/compare",
            files={"file": ("a.exr", files["canonical"].read_bytes())},
            data={"options": json.dumps(options)},
            headers=AUTH,
            timeout=120,
        )
        assert_problem(response, 422, words)


def test_an_output_layer_the_file_uses_is_422(server: Server, files: dict[str, Path]) -> None:
    """The name the client chose is wrong, not the file (it was a 400 "Bad Input File")."""
    data = {"output_layer": "N"}
    response = post_enhance(server, files["canonical"].read_bytes(), data=data)
    body = assert_problem(response, 422, "output layer 'N' would overwrite the input's channels")
    assert body["type"] == "urn:depict:problem:invalid-request"


# -- every error status from a real bad request --------------------------------------------------


def huge_header(exr: bytes, width: int = 100_000, height: int = 100_000) -> bytes:
    """The same file with a dataWindow claiming ``width`` x ``height`` pixels."""
    key = b"dataWindow\x00box2i\x00"
    at = exr.index(key) + len(key)
    size, x0, y0, _, _ = struct.unpack_from("<iiiii", exr, at)
    assert size == 16
    patched = bytearray(exr)
    struct.pack_into("<ii", patched, at + 12, x0 + width - 1, y0 + height - 1)
    return bytes(patched)


def test_garbage_bytes_400(server: Server) -> None:
    body = assert_problem(post_enhance(server, b"\x00garbage" * 100), 400, "not an OpenEXR")
    assert body["type"] == "urn:depict:problem:bad-file"


def test_truncated_exr_400(server: Server, files: dict[str, Path]) -> None:
    data = files["canonical"].read_bytes()
    body = assert_problem(post_enhance(server, data[: len(data) // 3], name="cut.exr"), 400, "")
    assert "truncat" in body["detail"] and "cut.exr" in body["detail"]
    assert "/tmp" not in body["detail"]  # the server's paths stay private


def test_multipart_cut_before_its_close_delimiter_400(
    server: Server, files: dict[str, Path]
) -> None:
    """A form whose body ends before ``--BOUNDARY--`` is a cut-short upload (it was a 422 "file:
    Field required"); a whole one sent in chunks that split the delimiter is taken."""
    bound = "cut-short-test"
    head = (
        f'--{bound}\r\nContent-Disposition: form-data; name="file"; filename="f.exr"\r\n'
        "Content-Type: image/x-exr\r\n\r\n"
    ).encode()
    whole = head + files["canonical"].read_bytes() + f"\r\n--{bound}--\r\n".encode()
    headers = {**AUTH, "Content-Type": f"multipart/form-data; boundary={bound}"}

    def chunks(body: bytes) -> Iterator[bytes]:  # the last 40 bytes 3 at a time
        yield body[:-40]
        yield from (body[i : i + 3] for i in range(len(body) - 40, len(body), 3))

    for body, status in [(whole[:-20], 400), (whole[: len(head) + 100], 400), (whole, 200)]:
        response = httpx.post(
            f"{server.url}/v1/enhance", content=chunks(body), headers=headers, timeout=60
        )
        if status == 400:
            assert_problem(response, 400, "the upload was cut short")
        else:
            assert response.status_code == 200, response.text


@pytest.mark.parametrize(
    "request_bytes",
    [
        b"GARBAGE\r\n\r\n",
        b"POST /v1/enhance HTTP/1.1\r\nHost: x\r\nContent-Length: -5\r\n\r\n",
        b"POST /v1/enhance HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n",
        b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03" + bytes(32),  # a TLS hello
    ],
    ids=["request line", "negative length", "chunk size", "TLS"],
)
def test_malformed_http_400_problem(server: Server, request_bytes: bytes) -> None:
    """What uvicorn cannot parse is a 400 problem like every other error (it was plain text), and
    an answer the app had begun from the headers alone (a 401) logs no traceback (three did)."""
    import socket

    logged = len(server.logs())
    host, port = server.url.removeprefix("http://").split(":")
    with socket.create_connection((host, int(port)), timeout=30) as sock:
        sock.sendall(request_bytes)
        answer = b""
        while chunk := sock.recv(65536):
            answer += chunk
    head, _, body = answer.partition(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 400 "), answer
    assert b"content-type: application/problem+json" in head.lower(), head
    problem = json.loads(body)
    assert problem["status"] == 400 and problem["type"] == "urn:depict:problem:bad-request"
    assert problem["detail"].startswith("malformed HTTP request: ")
    time.sleep(0.5)  # (the app's own answer is logged after the 400)
    assert "Traceback" not in server.logs()[logged:]


def test_huge_header_413(server: Server, files: dict[str, Path]) -> None:
    data = huge_header(files["canonical"].read_bytes())
    assert_problem(post_enhance(server, data), 413, "DEPICT_MAX_PIXELS")


def test_body_over_upload_limit_413(server: Server) -> None:
    data = b"\x76\x2f\x31\x01" + b"\x00" * (MAX_UPLOAD_MB * 2**20 + 1000)
    assert_problem(post_enhance(server, data), 413, "DEPICT_MAX_UPLOAD_MB")


def test_wrong_content_type_415(server: Server) -> None:
    response = httpx.post(f"{server.url}/v1/enhance", json={"file": "x"}, headers=AUTH, timeout=30)
    assert_problem(response, 415, "multipart/form-data")


def test_bad_pipeline_422(server: Server, files: dict[str, Path]) -> None:
    data = files["canonical"].read_bytes()
    unknown = {"pipeline": json.dumps({"steps": [{"op": "no_such_op"}]})}
    assert_problem(post_enhance(server, data, data=unknown), 422, "unknown operator")
    assert_problem(post_enhance(server, data, data={"pipeline": "{oops"}), 422, "JSON")
    bad_param = {"pipeline": json.dumps([{"op": "radiance_scaling", "params": {"nope": 1}}])}
    assert_problem(post_enhance(server, data, data=bad_param), 422, "nope")


def test_missing_camera_422(server: Server, tmp_path: Path) -> None:
    # world-space normals, no camera, and no Position pass to solve one from
    exr = exr_factory.write_blender(tmp_path / "b.exr", exr_factory.make_scene(), position=False)
    response = post_enhance(server, exr.read_bytes(), data={"preset": "blender"})
    body = assert_problem(response, 422, "camera form field")
    assert body["type"] == "urn:depict:problem:missing-camera"
    assert "--camera" not in body["detail"]  # over HTTP the form fields are named, not flags


def test_wrong_or_missing_key_401(server: Server, files: dict[str, Path]) -> None:
    data = files["canonical"].read_bytes()
    wrong = post_enhance(server, data, headers={"Authorization": "Bearer nope"})
    assert_problem(wrong, 401, "wrong")
    assert wrong.headers["www-authenticate"].startswith("Bearer")
    assert_problem(post_enhance(server, data, headers={}), 401, "Authorization: Bearer")
    assert httpx.get(f"{server.url}/healthz").status_code == 200  # health needs no key
    assert httpx.get(f"{server.url}/metrics").status_code == 401


def test_request_id_echoed_and_logged(server: Server) -> None:
    response = httpx.get(f"{server.url}/healthz", headers={"X-Request-ID": "e2e-trace-42"})
    assert response.headers["x-request-id"] == "e2e-trace-42"
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        lines = [json.loads(x) for x in server.logs().splitlines() if x.startswith("{")]
        hits = [x for x in lines if x.get("request_id") == "e2e-trace-42"]
        if hits:
            break
        time.sleep(0.1)
    assert hits and hits[0]["status"] == 200 and hits[0]["route"] == "/healthz"
