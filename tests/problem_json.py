"""The one check of an HTTP error answer (RFC 9457 problem+json) the service and viewer tests
share."""

from __future__ import annotations

from typing import Any

import httpx


def assert_problem(response: httpx.Response, status: int, words: str = "") -> dict[str, Any]:
    """``response`` is a problem+json answer of ``status`` whose ``detail`` says ``words``
    (case aside), with every member the service writes and the request's id: its body."""
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == "application/problem+json"
    body: dict[str, Any] = response.json()
    assert {"type", "title", "status", "detail", "instance", "request_id"} <= set(body)
    assert body["status"] == status
    assert body["request_id"] == response.headers["x-request-id"]
    assert words.lower() in body["detail"].lower(), body["detail"]
    return body
