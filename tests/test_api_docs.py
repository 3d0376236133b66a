"""The HTTP service offline and for Blender files: /docs and /redoc from packaged assets (no CDN),
the version in /healthz, dotted output layers, the upload's name in the output, and a
missing-camera answer that speaks HTTP. In process, through the real app and its worker pool."""

from __future__ import annotations

import io
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import OpenEXR
import pytest

from service.http.app import create_app
from service.settings import Settings
from service.version import version
from tests import exr_factory as F

pytestmark = pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")

KEY = "docs-key"
AUTH = {"Authorization": f"Bearer {KEY}"}
BLENDER_EXR = Path(__file__).parent / "fixtures" / "blender" / "cycles_multilayer.exr"


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    from fastapi.testclient import TestClient

    app = create_app(Settings(api_key=KEY, workers=1, queue=1))
    with TestClient(app, raise_server_exceptions=False) as c:
        yield c


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_pages_use_only_local_assets(client: Any, page: str) -> None:
    r = client.get(page)  # public: no key needed
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    urls = re.findall(r"""(?:src|href)=["']([^"']+)["']""", r.text)
    urls += re.findall(r"""url:\s*['"]([^'"]+)['"]""", r.text)
    urls += re.findall(r"""spec-url=["']([^"']+)["']""", r.text)
    assert urls, r.text
    for url in urls:
        assert url.startswith("/"), f"{page} loads {url} from elsewhere"
        assert not url.startswith("//")
    assert "fonts.googleapis" not in r.text and "cdn" not in r.text.lower()
    for url in urls:
        asset = client.get(url)
        assert asset.status_code == 200, url
        if url.endswith(".js"):
            assert len(asset.content) > 100_000  # the real bundle, not a stub


def test_healthz_says_the_version(client: Any) -> None:
    body = client.get("/healthz").json()
    assert body == {"status": "ok", "version": version()}
    assert re.match(r"^\d+\.\d+", body["version"])


def enhance(client: Any, path: Path, name: str, **data: str) -> Any:
    return client.post(
        "/v1/enhance",
        headers=AUTH,
        files={"file": (name, path.read_bytes(), "image/x-exr")},
        data=data,
    )


def test_dotted_output_layer_and_the_uploads_name(client: Any, tmp_path: Path) -> None:
    r = enhance(client, BLENDER_EXR, "shot_0042.exr", output_layer="ViewLayer.Depict Look")
    assert r.status_code == 200, r.text
    out = tmp_path / "out.exr"
    out.write_bytes(r.content)
    with OpenEXR.File(str(out), separate_channels=True) as f:
        added = f.parts[-1]  # the default layout: the result in a part of its own
        assert "ViewLayer.Depict Look.R" in added.channels
        header = {**f.header(), **added.header}
        assert header["depict/input"] == "shot_0042.exr"
        assert header["depict/result"] == "ViewLayer.Depict Look"
        assert "worldToCamera" in header  # the camera solved on the server
    r = enhance(client, BLENDER_EXR, "shot.exr", output_layer="a..b")
    assert r.status_code == 422 and "output_layer" in r.json()["detail"]


def test_missing_camera_answer_names_the_form_field(client: Any, tmp_path: Path) -> None:
    path = F.write_blender(tmp_path / "b.exr", F.make_scene(), position=False)
    r = enhance(client, path, "b.exr")
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert "camera form field" in detail and "world space" in detail
    assert str(tmp_path) not in detail
    assert io.BytesIO(r.content).read(1) == b"{"
