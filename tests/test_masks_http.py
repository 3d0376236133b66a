"""Masks over HTTP, against a real ``depict serve``: Radiance Scaling and Light Alignment on
Suzanne only (the Blender Cryptomatte fixture) give the local CLI's bytes, the rest of the frame
bit-exact; an unknown name or a bad mask is a 422 problem."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

import gbuffer
from service.cli import main as cli
from service.headers import WARNING, warning_text
from service.masks import matte
from tests.live_server import Server, live_server

FIXTURE = Path(__file__).parent / "fixtures" / "blender" / "cryptomatte.exr"
KEY = "masks-secret"
AUTH = {"Authorization": f"Bearer {KEY}"}
PIPELINE = [
    {"op": "radiance_scaling", "params": {"mask": "cryptomatte:Suzanne"}},
    {"op": "light_alignment", "params": {"mask": "cryptomatte:Suzanne", "mask_stats": True}},
]


@pytest.fixture(scope="module")
def server() -> Iterator[Server]:
    if not FIXTURE.is_file():
        pytest.skip(f"{FIXTURE} is absent (tests/fixtures/blender/README.md)")
    with live_server({"DEPICT_API_KEY": KEY, "DEPICT_WORKERS": "1"}) as server:
        yield server


def post(server: Server, pipeline: object) -> httpx.Response:
    return httpx.post(
        f"{server.url}/v1/enhance",
        files={"file": ("cryptomatte.exr", FIXTURE.read_bytes())},
        data={"pipeline": json.dumps(pipeline)},
        headers=AUTH,
        timeout=120,
    )


def test_masked_steps_over_http_change_only_suzanne(server: Server, tmp_path: Path) -> None:
    response = post(server, PIPELINE)
    assert response.status_code == 200, response.text
    remote = tmp_path / "remote.exr"
    remote.write_bytes(response.content)
    pipe, local = tmp_path / "pipe.json", tmp_path / "local.exr"
    pipe.write_text(json.dumps({"steps": PIPELINE}))
    assert cli(["enhance", str(FIXTURE), "--pipeline", str(pipe), "-o", str(local)]) == 0
    assert remote.read_bytes() == local.read_bytes()
    frame = gbuffer.read(FIXTURE)
    result = gbuffer.read(remote).layer("ViewLayer.Depict")
    after = np.dstack([result[c] for c in "RGB"])
    before = frame.buffers["beauty"]
    m = matte(frame, "cryptomatte:Suzanne")
    changed = (after != before).any(axis=-1)
    assert changed.sum() > 1000 and not changed[m == 0].any()


@pytest.mark.parametrize(
    ("mask", "words"),
    [
        ("cryptomatte:Nope", "no Cryptomatte name matches 'Nope'"),
        ("index:IndexOB", "expected index:LAYER=V"),
    ],
)
def test_bad_masks_are_422_problems(server: Server, mask: str, words: str) -> None:
    response = post(server, [{"op": "radiance_scaling", "params": {"mask": mask}}])
    assert response.status_code == 422, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    assert words in response.json()["detail"]


def test_a_mask_that_selects_nothing_is_said_in_a_warning_header(server: Server) -> None:
    response = post(
        server, [{"op": "radiance_scaling", "params": {"mask": "cryptomatte:Suz*,Nope"}}]
    )
    assert response.status_code == 200, response.text
    said = [warning_text(v) for v in response.headers.get_list(WARNING)]
    assert (
        "radiance_scaling: mask 'cryptomatte:Suz*,Nope': no name of ViewLayer.CryptoObject "
        "matches 'Nope'; the others are used"
    ) in said
