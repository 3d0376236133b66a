"""What the end-to-end modules share: the servers' settings, and a request and its answer."""

from __future__ import annotations

from pathlib import Path

import httpx

from tests.live_server import Server

KEY = "e2e-secret"
AUTH = {"Authorization": f"Bearer {KEY}"}
BLENDER = Path(__file__).parent.parent / "fixtures" / "blender"
MAX_PIXELS = 600_000
MAX_UPLOAD_MB = 16


def post_enhance(
    server: Server,
    content: bytes,
    *,
    headers: dict[str, str] | None = None,
    data: dict[str, str] | None = None,
    name: str = "frame.exr",
) -> httpx.Response:
    return httpx.post(
        f"{server.url}/v1/enhance",
        files={"file": (name, content)},
        data=data or {},
        headers=AUTH if headers is None else headers,
        timeout=60,
    )
