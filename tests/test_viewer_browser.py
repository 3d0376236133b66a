"""The viewer in a real browser: Debian's Chromium driven by Playwright against a real
``depict serve`` behind an API key. Load a Blender frame, see a preview, change the operator and
a slider and see the preview change, compare, download the pipeline and the full-resolution EXR
(the same bytes as ``depict enhance``); no request leaves the server's origin and, once the key
is given, the console stays free of errors."""

from __future__ import annotations

import json
import shutil
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from service.cli import main as cli
from tests.live_server import Server, live_server

CHROMIUM = Path("/usr/bin/chromium")
BLENDER = Path(__file__).parent / "fixtures" / "blender" / "cycles_multilayer.exr"
KEY = "browser-key"
#: A preview that keeps the only worker busy for seconds.
HEAVY = {"steps": [{"op": "light_alignment"}] * 48}

playwright = pytest.importorskip("playwright.sync_api", reason="the playwright package is absent")
if not CHROMIUM.is_file():
    pytest.skip(
        f"Chromium is absent ({CHROMIUM}; apt-get install chromium)", allow_module_level=True
    )

#: The SHA-256 of the picture on the "after" side, computed in the page from its blob URL.
AFTER_HASH = """async () => {
  const data = await (await fetch(document.querySelector("img.after").src)).arrayBuffer();
  const hash = await crypto.subtle.digest("SHA-256", data);
  return Array.from(new Uint8Array(hash), (b) => b.toString(16).padStart(2, "0")).join("");
}"""


@pytest.fixture(scope="module")
def server() -> Iterator[Server]:
    with live_server({"DEPICT_API_KEY": KEY, "DEPICT_WORKERS": "1"}) as s:
        yield s


@pytest.fixture
def page(server: Server) -> Iterator[Any]:
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM))
        context = browser.new_context(
            accept_downloads=True, viewport={"width": 1400, "height": 900}
        )
        yield context.new_page()
        browser.close()


def previews(page: Any) -> int:
    return int(page.evaluate("Number(document.body.dataset.previews || 0)"))


def wait_preview(page: Any, after: int) -> None:
    page.wait_for_function(
        f"Number(document.body.dataset.previews || 0) > {after}", timeout=120_000
    )


def test_load_tune_compare_download(page: Any, server: Server, tmp_path: Path) -> None:
    requests: list[str] = []
    errors: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(f"page error: {e}"))

    page.goto(f"{server.url}/ui/")
    page.wait_for_function("document.getElementById('status').textContent.includes('API key')")
    assert all("401" in e for e in errors), errors  # without the key: refused, and said so
    errors.clear()
    page.fill("#key", KEY)
    page.press("#key", "Enter")
    page.locator("#key").dispatch_event("change")
    page.wait_for_selector("#add-op option[value=light_alignment]", state="attached")

    page.set_input_files("#file", str(BLENDER))
    wait_preview(page, 0)
    assert "blender" in page.text_content("#info")
    assert "congruence" in page.text_content("#scores")
    first = page.evaluate(AFTER_HASH)

    count = previews(page)
    page.select_option("#presets", "b:Light Alignment")  # another operator
    wait_preview(page, count)
    aligned = page.evaluate(AFTER_HASH)
    assert aligned != first

    count = previews(page)
    gamma = page.locator('li[data-op="light_alignment"] [data-param="gamma"]')
    gamma.locator("input[type=range]").fill("900")  # linear slider on [0, 20]
    assert gamma.locator("input[type=number]").input_value() == "18"
    wait_preview(page, count)
    assert page.evaluate(AFTER_HASH) != aligned

    page.click("#toggle")
    assert page.get_attribute("#compare", "data-mode") == "after"
    page.click("#toggle")
    assert page.get_attribute("#compare", "data-mode") == "before"
    page.click("#actual")
    assert "scale(1)" in page.get_attribute("#compare .stage", "style")

    with page.expect_download() as got:
        page.click("#download-pipeline")
    pipe = tmp_path / "pipeline.json"
    got.value.save_as(pipe)
    assert json.loads(pipe.read_text()) == {
        "steps": [{"op": "light_alignment", "params": {"gamma": 18}}]
    }
    with page.expect_download(timeout=180_000) as got:
        page.click("#download-exr")
    viewer_exr = tmp_path / "viewer.exr"
    got.value.save_as(viewer_exr)
    assert got.value.suggested_filename == "cycles_multilayer_depict.exr"
    assert "depict enhance 'cycles_multilayer.exr'" in page.input_value("#commands")

    local = tmp_path / "cli.exr"
    shutil.copy(BLENDER, tmp_path / BLENDER.name)
    args = ["enhance", str(tmp_path / BLENDER.name), "-o", str(local), "--pipeline", str(pipe)]
    assert cli(args) == 0
    assert viewer_exr.read_bytes() == local.read_bytes()

    foreign = [u for u in requests if not u.startswith((server.url, "blob:", "data:"))]
    assert not foreign, foreign
    assert not errors, errors


@pytest.fixture(scope="module")
def busy_server() -> Iterator[Server]:
    """One worker and no queue: a second job at a time is refused (429)."""
    with live_server({"DEPICT_WORKERS": "1", "DEPICT_QUEUE": "0"}) as s:
        yield s


def test_example_light_sphere_score_map_and_busy(page: Any, busy_server: Server) -> None:
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
    page.goto(f"{busy_server.url}/ui/")
    page.wait_for_selector("#add-op option[value=exaggerated_shading]", state="attached")
    page.click("#example")
    wait_preview(page, 0)
    assert "spot.exr (960×720)" in page.text_content("#info")

    count = previews(page)
    page.select_option("#add-op", "exaggerated_shading")
    page.click("#add-step")
    wait_preview(page, count)
    shaded = page.evaluate(AFTER_HASH)
    count = previews(page)
    sphere = page.locator('li[data-op="exaggerated_shading"] canvas.sphere').bounding_box()
    page.mouse.click(sphere["x"] + 0.8 * sphere["width"], sphere["y"] + 0.5 * sphere["height"])
    wait_preview(page, count)
    light = page.input_value('li[data-op="exaggerated_shading"] [data-param="light"] input')
    x, y, z = (float(v) for v in light.split(","))
    assert x > 0.5 and abs(y) < 0.05 and x * x + y * y + z * z == pytest.approx(1, abs=1e-2)
    lit = page.evaluate(AFTER_HASH)
    assert lit != shaded

    count = previews(page)
    page.select_option("#layer", "score_map")
    wait_preview(page, count)
    assert page.evaluate(AFTER_HASH) != lit  # the result's score map, not the result
    assert errors == [], errors

    other = httpx.post(f"{busy_server.url}/v1/frames/example", timeout=120).json()["id"]
    heavy = threading.Thread(
        target=httpx.post,
        args=(f"{busy_server.url}/v1/frames/{other}/preview",),
        kwargs={"json": {"pipeline": HEAVY, "height": 720}, "timeout": 300},
    )
    heavy.start()
    time.sleep(1.0)  # the heavy preview is on the only worker now
    count = previews(page)
    page.locator(
        'li[data-op="exaggerated_shading"] [data-param="contrast"] input[type=range]'
    ).fill("300")
    page.wait_for_function("document.getElementById('status').textContent.startsWith('busy')")
    assert "busy" in page.get_attribute("#status", "class")
    heavy.join()
    wait_preview(page, count)  # retried after Retry-After, and shown
    assert all("429" in e for e in errors), errors  # the refusal, nothing else


def test_a_cryptomatte_object_as_a_steps_mask(page: Any, server: Server) -> None:
    page.add_init_script(f"sessionStorage.setItem('depict.key', '{KEY}')")
    page.goto(f"{server.url}/ui/")
    page.wait_for_selector("#add-op option[value=radiance_scaling]", state="attached")
    page.set_input_files("#file", str(BLENDER.with_name("cryptomatte.exr")))
    wait_preview(page, 0)
    assert "Suzanne" in page.text_content("#info")
    offered = page.eval_on_selector_all("#suggest-mask option", "os => os.map(o => o.value)")
    assert {"cryptomatte:Suzanne", "cryptomatte/CryptoMaterial:SuzanneMat", "ao"} <= set(offered)
    whole = page.evaluate(AFTER_HASH)
    count = previews(page)
    field = page.locator('li[data-op="radiance_scaling"] [data-param="mask"] input')
    assert field.get_attribute("list") == "suggest-mask"
    field.fill("cryptomatte/CryptoMaterial:SuzanneMat")
    field.dispatch_event("change")
    wait_preview(page, count)
    assert page.evaluate(AFTER_HASH) != whole
    assert "error" not in page.get_attribute("#status", "class")


def test_a_dragged_slider_previews_while_it_moves_and_ends_on_its_last_value(
    page: Any, server: Server
) -> None:
    """One preview in flight at a time, each answered and shown; the settings changed while it
    ran are asked for as soon as it is back, so the last move is the last preview."""
    page.add_init_script(f"sessionStorage.setItem('depict.key', '{KEY}')")
    page.goto(f"{server.url}/ui/")
    page.wait_for_selector("#add-op option[value=radiance_scaling]", state="attached")
    page.set_input_files("#file", str(BLENDER))
    wait_preview(page, 0)
    asked: list[float] = []
    answered: list[int] = []
    in_flight = [0, 0]  # now, most

    def on_request(request: Any) -> None:
        if request.url.endswith("/preview"):
            (step,) = json.loads(request.post_data)["pipeline"]["steps"]
            asked.append(step.get("params", {}).get("gamma", 1.0))  # (absent: the default)
            in_flight[0] += 1
            in_flight[1] = max(in_flight)

    def on_end(request: Any, ok: int) -> None:
        if request.url.endswith("/preview"):
            answered.append(ok)
            in_flight[0] -= 1

    page.on("request", on_request)
    page.on("requestfinished", lambda r: on_end(r, 1))
    page.on("requestfailed", lambda r: on_end(r, 0))
    count = previews(page)
    gamma = page.locator('li[data-op="radiance_scaling"] [data-param="gamma"]')
    moves = [str(300 + 40 * i) for i in range(12)]  # a drag: one input event per position
    for value in moves:
        gamma.locator("input[type=range]").fill(value)
    last = float(gamma.locator("input[type=number]").input_value())
    page.wait_for_function(
        f"Number(document.body.dataset.previews || 0) >= {count} + 2", timeout=120_000
    )
    deadline = time.monotonic() + 120
    while not (asked and asked[-1] == last and len(answered) == len(asked)):
        assert time.monotonic() < deadline, (asked, answered, last)
        page.wait_for_timeout(100)
    page.wait_for_timeout(1000)  # nothing more is asked for
    assert asked[-1] == last and len(asked) >= 2, asked  # (more when previews are quicker)
    assert answered == [1] * len(asked)  # none aborted
    assert in_flight == [0, 1]
    wait_preview(page, count + len(asked) - 1)  # each shown
