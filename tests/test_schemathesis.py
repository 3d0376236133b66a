"""Schemathesis against the committed openapi/openapi.json and a real server: no 500, bounded.

Each operation gets a few derandomised examples (random multipart bodies, JSON fields, query
values); the server must answer every one of them with something other than a 5xx.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import schemathesis
from hypothesis import HealthCheck, settings

from service.openapi import DEFAULT_PATH
from tests.live_server import Server, live_server

schema = schemathesis.openapi.from_path(DEFAULT_PATH)


@pytest.fixture(scope="module")
def server() -> Iterator[Server]:
    env = {
        "DEPICT_WORKERS": "1",
        "DEPICT_QUEUE": "64",
        "DEPICT_MAX_PIXELS": str(256 * 256),
        "DEPICT_MAX_UPLOAD_MB": "4",
    }
    with live_server(env) as s:
        yield s


@schema.parametrize()
@settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    suppress_health_check=list(HealthCheck),
    database=None,
)
def test_no_server_error(case: schemathesis.Case, server: Server) -> None:
    response = case.call(base_url=server.url, timeout=60)
    assert response.status_code < 500, (
        f"{case.method} {case.path} -> {response.status_code}: {response.text[:500]}"
    )
    if response.status_code >= 400:
        content_type = response.headers.get("content-type") or [""]
        assert content_type[0] == "application/problem+json", content_type
