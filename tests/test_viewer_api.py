"""The viewer's API (``/v1/frames``) against a real ``depict serve`` behind an API key, one worker
and no queue: frames kept and inspected, layer pictures, previews on the downscaled copy with
their scores, the full-resolution result bit for bit as ``depict enhance``, superseded previews
dropped, a full pool answered 429 ``busy``, and ``/ui/`` served without the key."""

from __future__ import annotations

import io
import json
import threading
import time
from base64 import b64decode
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from PIL import Image

from service.cli import main as cli
from tests.exr_factory import cropped, make_scene, write_canonical
from tests.live_server import Server, live_server
from tests.problem_json import assert_problem

BLENDER = Path(__file__).parent / "fixtures" / "blender" / "cycles_multilayer.exr"
CRYPTO = BLENDER.with_name("cryptomatte.exr")
KEY = "viewer-key"
AUTH = {"Authorization": f"Bearer {KEY}"}
RS = {"steps": [{"op": "radiance_scaling", "params": {"gamma": 4.0}}]}
#: A pipeline that keeps a worker busy for seconds on the example frame.
HEAVY = {"steps": [{"op": "light_alignment"}] * 48}


@pytest.fixture(scope="module")
def server() -> Iterator[Server]:
    env = {"DEPICT_API_KEY": KEY, "DEPICT_WORKERS": "1", "DEPICT_QUEUE": "0"}
    with live_server(env) as s:
        yield s


@pytest.fixture(scope="module")
def api(server: Server) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, headers=AUTH, timeout=120) as c:
        yield c


@pytest.fixture(scope="module")
def frame(api: httpx.Client) -> dict[str, Any]:
    with open(BLENDER, "rb") as f:
        r = api.post("/v1/frames", files={"file": (BLENDER.name, f)})
    assert r.status_code == 200, r.text
    return r.json()


def png(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def test_upload_answers_what_inspect_finds(frame: dict[str, Any], api: httpx.Client) -> None:
    info = frame["info"]
    assert frame["name"] == BLENDER.name and info["file"] == BLENDER.name
    assert info["preset"] == "blender" and info["size"] == [160, 120]
    assert {"beauty", "normal", "depth", "diffuse", "ao"} <= set(info["buffers"])
    assert info["camera"] is not None and "solved" in info["camera_source"]
    assert info["colour_space"].startswith("not stated")
    assert info["layers"][-1] == "score_map" and "normal" in info["layers"]
    assert "radiance_scaling" in info["operators"]["runnable"]
    assert api.get(f"/v1/frames/{frame['id']}").json() == frame


def test_layer_pictures(frame: dict[str, Any], api: httpx.Client) -> None:
    normal = api.get(f"/v1/frames/{frame['id']}/layers/normal.png", params={"height": 60})
    assert normal.status_code == 200 and normal.headers["content-type"] == "image/png"
    depth = png(api.get(f"/v1/frames/{frame['id']}/layers/depth.png?height=60").content)
    assert png(normal.content).shape == depth.shape == (60, 80, 3)
    assert not np.array_equal(png(normal.content), depth)
    score = png(api.get(f"/v1/frames/{frame['id']}/layers/score_map.png?height=60").content)
    assert score.shape == (60, 80, 3) and score.std() > 0
    assert_problem(
        api.get(f"/v1/frames/{frame['id']}/layers/nothing.png"), 404, "no layer 'nothing'"
    )


def test_preview_is_downscaled_scored_and_follows_the_parameters(
    frame: dict[str, Any], api: httpx.Client
) -> None:
    url = f"/v1/frames/{frame['id']}/preview"
    first = api.post(url, json={"pipeline": RS, "height": 60, "score_map": True}).json()
    other = api.post(url, json={"pipeline": {"steps": [{"op": "radiance_scaling"}]}, "height": 60})
    a, b = png(b64decode(first["image"])), png(b64decode(other.json()["image"]))
    assert a.shape == (60, 80, 3) and first["size"] == [80, 60]
    assert np.any(a != b, axis=2).mean() > 0.01  # gamma 4 vs 1 (identical: 0)
    score = first["score"]
    assert 0 < score["before"] < 1 and 0 < score["after"] < 1 and score["before"] != score["after"]
    assert png(b64decode(first["score_map"])).shape == (60, 80, 3)
    assert first["pipeline"]["steps"][0]["params"] == {"gamma": 4.0}
    assert other.json()["score_map"] is None  # not asked for
    tall = api.post(url, json={"pipeline": RS, "height": 4000}).json()
    assert tall["size"] == [160, 120]  # never above the frame's own height


@pytest.mark.parametrize("op", ["unsharp_masking", "light_alignment", "apparent_relief"])
def test_every_kind_of_operator_previews_on_a_downscaled_path_traced_frame(
    frame: dict[str, Any], api: httpx.Client, op: str
) -> None:
    body = {"pipeline": {"steps": [{"op": op}]}, "height": 60}
    r = api.post(f"/v1/frames/{frame['id']}/preview", json=body)
    assert r.status_code == 200, r.text
    assert png(b64decode(r.json()["image"])).shape == (60, 80, 3)


def test_a_masked_step_previews_with_the_files_cryptomatte(api: httpx.Client) -> None:
    """The preview's copy carries the file's channels shrunk as the geometry is, so a step
    restricted to a Cryptomatte object changes that object and leaves the rest as it was."""
    with open(CRYPTO, "rb") as f:
        frame = api.post("/v1/frames", files={"file": (CRYPTO.name, f)}).json()
    url = f"/v1/frames/{frame['id']}/preview"
    rs = {"op": "radiance_scaling", "params": {"gamma": 4.0}}
    masked = {"steps": [{**rs, "params": {"gamma": 4.0, "mask": "cryptomatte:Suzanne*"}}]}
    before = png(api.get(f"/v1/frames/{frame['id']}/layers/beauty.png?height=120").content)
    shown = {}
    for name, pipe in (("masked", masked), ("whole", {"steps": [rs]})):
        r = api.post(url, json={"pipeline": pipe, "height": 120})
        assert r.status_code == 200, r.text
        shown[name] = np.all(png(b64decode(r.json()["image"])) == before, axis=2).mean()
    assert shown["masked"] < 1.0  # Suzanne changed
    assert shown["whole"] < shown["masked"] - 0.02  # the rest did not (the whole step: 7 %)


def test_enhanced_exr_is_the_clis_bit_for_bit(
    frame: dict[str, Any], api: httpx.Client, tmp_path: Path
) -> None:
    r = api.get(f"/v1/frames/{frame['id']}/enhanced.exr", params={"pipeline": json.dumps(RS)})
    assert r.status_code == 200 and r.headers["content-type"] == "image/x-exr"
    assert "cycles_multilayer_depict.exr" in r.headers["content-disposition"]
    (tmp_path / "pipe.json").write_text(json.dumps(RS))
    local = tmp_path / "local.exr"
    args = ["enhance", str(BLENDER), "-o", str(local), "--pipeline", str(tmp_path / "pipe.json")]
    assert cli(args) == 0
    assert r.content == local.read_bytes()
    assert r.content != BLENDER.read_bytes()


def test_errors_are_problems(frame: dict[str, Any], api: httpx.Client, server: Server) -> None:
    assert_problem(api.get("/v1/frames/AAAAAAAAAAAAAAAAAAAAAA"), 404, "no frame")
    assert_problem(api.get("/v1/frames/bad!id"), 422, "")
    url = f"/v1/frames/{frame['id']}/preview"
    assert_problem(api.post(url, json={"pipeline": {"steps": [{"op": "nope"}]}}), 422, "nope")
    assert_problem(api.post(url, json={"pipeline": RS, "size": 3}), 422, "")
    bad = api.get(f"/v1/frames/{frame['id']}/enhanced.exr", params={"pipeline": "{"})
    assert_problem(bad, 422, "not valid JSON")
    assert_problem(
        api.post("/v1/frames", files={"file": ("x.exr", b"hello")}), 400, "not an OpenEXR"
    )
    assert_problem(httpx.get(f"{server.url}/v1/frames/{frame['id']}"), 401, "API key")


def test_ui_is_public_and_self_contained(server: Server) -> None:
    page = httpx.get(f"{server.url}/ui/")
    assert page.status_code == 200 and "Depict viewer" in page.text
    assert httpx.get(f"{server.url}/ui", follow_redirects=True).url.path == "/ui/"
    for name in ("app.js", "forms.js", "view.js", "app.css"):
        text = httpx.get(f"{server.url}/ui/{name}").text
        assert "http://" not in text and "https://" not in text, name


def _post_later(
    api: httpx.Client, url: str, body: dict[str, Any], out: list[Any]
) -> threading.Thread:
    def post() -> None:
        out.append(api.post(url, json=body))

    thread = threading.Thread(target=post)
    thread.start()
    return thread


def test_superseded_previews_are_dropped_and_a_full_pool_is_busy(api: httpx.Client) -> None:
    example = api.post("/v1/frames/example")
    assert example.status_code == 200, example.text
    assert example.json()["info"]["size"] == [960, 720]
    url = f"/v1/frames/{example.json()['id']}/preview"
    heavy: list[Any] = []
    running = _post_later(api, url, {"pipeline": HEAVY, "height": 720}, heavy)
    time.sleep(1.0)  # the heavy preview is on the only worker now
    busy = api.get(f"/v1/frames/{example.json()['id']}/layers/beauty.png")
    body = assert_problem(busy, 429, "busy")
    assert body["type"].endswith("busy") and int(busy.headers["retry-after"]) >= 1
    waiting: list[Any] = []
    threads = [_post_later(api, url, {"pipeline": RS, "height": 120}, waiting) for _ in range(2)]
    for t in [running, *threads]:
        t.join()
    assert heavy[0].status_code == 200, heavy[0].text
    statuses = sorted(r.status_code for r in waiting)
    assert statuses == [200, 409], [r.text for r in waiting]
    assert_problem(next(r for r in waiting if r.status_code == 409), 409, "newer preview")


def test_a_kept_frames_errors_name_the_upload_not_the_servers_files(
    api: httpx.Client, tmp_path: Path
) -> None:
    """(The preview and the layer pictures named the server's temporary copy of the file.)"""
    s = make_scene(48, 64)
    s.normal[...] = np.nan
    path = write_canonical(tmp_path / "my shot.exr", s)
    with open(path, "rb") as f:
        r = api.post("/v1/frames", files={"file": (path.name, f)})
    assert r.status_code == 200, r.text
    fid = r.json()["id"]
    for answer in (
        api.post(f"/v1/frames/{fid}/preview", json={"pipeline": RS, "height": 48}),
        api.get(f"/v1/frames/{fid}/layers/depth.png"),
    ):
        body = assert_problem(answer, 400, "my shot.exr: channel 'N.X'")
        assert "/tmp" not in body["detail"] and "in.exr" not in body["detail"]


def test_a_frame_without_usable_normals_previews_with_a_score_of_zero(
    api: httpx.Client, tmp_path: Path
) -> None:
    """(The input's shading scale, 0, was passed on as a parameter out of range: a 422.)"""
    s = make_scene(48, 64)
    s.normal[...] = 0.0
    path = write_canonical(tmp_path / "flat.exr", s)
    with open(path, "rb") as f:
        fid = api.post("/v1/frames", files={"file": (path.name, f)}).json()["id"]
    r = api.post(f"/v1/frames/{fid}/preview", json={"pipeline": RS, "height": 48})
    assert r.status_code == 200, r.text
    assert r.json()["score"] == {"before": 0.0, "after": 0.0}


def test_a_frame_too_small_to_score_shows_its_layers(api: httpx.Client, tmp_path: Path) -> None:
    """(Its pictures were refused with the score's "depth must be at least 3x3".)"""
    path = write_canonical(tmp_path / "tiny.exr", cropped(make_scene(48, 64), *TINY))
    with open(path, "rb") as f:
        fid = api.post("/v1/frames", files={"file": (path.name, f)}).json()["id"]
    for layer in ("normal", "depth", "beauty"):
        r = api.get(f"/v1/frames/{fid}/layers/{layer}.png")
        assert r.status_code == 200, r.text
        assert png(r.content).shape[:2] == (2, 2)
    r = api.post(f"/v1/frames/{fid}/preview", json={"pipeline": RS, "height": 16})
    assert r.status_code == 200, r.text
    assert r.json()["score"] is None


#: Two rows and two columns on the test sphere.
TINY = (slice(23, 25), slice(31, 33))


def test_the_viewers_routes_refuse_what_they_do_not_take(
    frame: dict[str, Any], api: httpx.Client
) -> None:
    """A misspelt ``?pipline=`` of the full-resolution result ran the default pipeline (200),
    and ``POST /v1/frames`` took any field."""
    with open(BLENDER, "rb") as f:
        r = api.post("/v1/frames", files={"file": (BLENDER.name, f)}, data={"pipline": "[]"})
    assert_problem(r, 422, "unknown form field 'pipline'; /v1/frames takes: ")
    frame_id = frame["id"]
    for url in (
        f"/v1/frames/{frame_id}/enhanced.exr?pipline=%5B%5D",
        f"/v1/frames/{frame_id}?bogus=1",
        f"/v1/frames/{frame_id}/layers/beauty.png?hieght=100",
        "/v1/frames/example?bogus=1",
    ):
        method = api.post if url.endswith("example?bogus=1") else api.get
        assert_problem(method(url), 422, "unknown query parameter")
    assert api.get("/ui?from=bookmark").status_code in (200, 307)  # (the page's address)


def test_the_viewer_reads_a_frame_in_the_colour_space_given(api: httpx.Client) -> None:
    """``POST /v1/frames`` takes ``colorspace`` as ``/v1/enhance`` does (it took no such field,
    and an ACEScg frame was read as linear Rec.709)."""
    with open(BLENDER, "rb") as f:
        r = api.post("/v1/frames", files={"file": (BLENDER.name, f)}, data={"colorspace": "ACEScg"})
    assert r.status_code == 200, r.text
    assert r.json()["info"]["colorspace"]["name"] == "ACEScg"
    assert api.delete(f"/v1/frames/{r.json()['id']}").status_code == 204


def test_a_preview_of_nan_exposure_says_it_is_no_finite_number(
    frame: dict[str, Any], api: httpx.Client
) -> None:
    """(It said "less than or equal to 20", the bound a NaN fails.)"""
    url = f"/v1/frames/{frame['id']}/preview"
    headers = {"content-type": "application/json"}
    r = api.post(url, content='{"exposure": NaN, "height": 64}', headers=headers)
    assert_problem(r, 422, "finite number")


def test_a_preview_says_a_mask_that_selects_nothing(api: httpx.Client) -> None:
    """The viewer is where masks are tuned: a preview answers its steps' warnings."""
    with open(CRYPTO, "rb") as f:
        r = api.post("/v1/frames", files={"file": (CRYPTO.name, f)}, params={"height": 120})
    assert r.status_code == 200, r.text
    steps = [{"op": "radiance_scaling", "params": {"mask": "index:ViewLayer.IndexOB.X=99"}}]
    body = {"pipeline": {"steps": steps}, "height": 120}
    answer = api.post(f"/v1/frames/{r.json()['id']}/preview", json=body)
    assert answer.status_code == 200, answer.text
    assert answer.json()["warnings"] == [
        "radiance_scaling: mask 'index:ViewLayer.IndexOB.X=99' selects no pixel: the step "
        "changed nothing"
    ]
