"""The viewer (``/ui/``) in Debian's Chromium through Playwright, for the viewer's benchmark and
screenshots: a real ``depict serve``, a frame loaded through the page's file input."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from playwright.sync_api import sync_playwright

from tests.live_server import live_server

CHROMIUM = "/usr/bin/chromium"


def previews(page: Any) -> int:
    """How many previews the page has shown."""
    return int(page.evaluate("Number(document.body.dataset.previews || 0)"))


def wait_preview(page: Any, seen: int, timeout_ms: float = 300_000) -> None:
    """Wait until the page shows a preview after the ``seen`` first ones."""
    script = f"Number(document.body.dataset.previews || 0) > {seen}"
    page.wait_for_function(script, timeout=timeout_ms, polling="raf")


@contextlib.contextmanager
def viewer(
    frame: Path, env: dict[str, str], width: int = 1600, height: int = 900
) -> Iterator[tuple[Any, str]]:
    """The page with ``frame`` loaded and its first preview shown, and the server's URL."""
    with live_server(env) as server, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM)
        page = browser.new_page(viewport={"width": width, "height": height})
        page.goto(f"{server.url}/ui/")
        page.wait_for_selector("#add-op option[value=radiance_scaling]", state="attached")
        page.set_input_files("#file", str(frame))
        wait_preview(page, 0)
        try:
            yield page, server.url
        finally:
            browser.close()
