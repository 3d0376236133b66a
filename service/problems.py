"""Errors as ``application/problem+json`` (RFC 9457), each with a ``detail`` a user can act on.

Every error answer of the service has this body::

    {"type": "urn:depict:problem:limit", "title": "Content Too Large", "status": 413,
     "detail": "frame is 100000x100000 = 1e10 pixels, over DEPICT_MAX_PIXELS=67108864 ...",
     "instance": "/v1/enhance", "request_id": "3f2c..."}

``type`` is a URN per kind of problem (the table :data:`KINDS`), ``request_id`` the id echoed in
``X-Request-ID`` and written in the logs. How exceptions map to statuses:

======================================================  =======  ======================
exception                                               status   type
======================================================  =======  ======================
:class:`gbuffer.errors.FrameError` (bad / corrupt file)  400      ``bad-file``
missing or wrong API key                                 401      ``unauthorized``
request body not received within DEPICT_UPLOAD_TIMEOUT_S 408      ``request-timeout``
:class:`gbuffer.errors.LimitError`, body too large       413      ``limit``
wrong ``Content-Type``, unknown mesh format              415      ``unsupported-media-type``
:class:`service.registry.PipelineError`, bad form field  422      ``invalid-request``
:class:`gbuffer.errors.OptionError` (map, camera given)  422      ``invalid-request``
:class:`gbuffer.errors.MissingBufferError`               422      ``missing-buffer``
:class:`gbuffer.errors.MissingCameraError`               422      ``missing-camera``
a newer preview of the same frame was asked for         409      ``superseded``
queue full                                               429      ``busy`` (``Retry-After``)
the service cannot work (no worker can start)            503      ``unavailable``
the worker running the job died (signal, out of memory)  503      ``worker-lost``
job over ``DEPICT_TIMEOUT_S``                            504      ``timeout``
======================================================  =======  ======================
"""

from __future__ import annotations

import json
from http import HTTPStatus
from typing import Any

from starlette.responses import Response

from gbuffer.errors import (
    FrameError,
    LimitError,
    MissingBufferError,
    MissingCameraError,
    OptionError,
)
from service.errors import PipelineError

MEDIA_TYPE = "application/problem+json"

#: kind -> (status, title)
KINDS: dict[str, tuple[int, str]] = {
    "bad-file": (400, "Bad Input File"),
    "bad-request": (400, "Bad Request"),
    "unauthorized": (401, "Unauthorized"),
    "not-found": (404, "Not Found"),
    "method-not-allowed": (405, "Method Not Allowed"),
    "request-timeout": (408, "Request Timeout"),
    "superseded": (409, "Superseded"),
    "limit": (413, "Content Too Large"),
    "unsupported-media-type": (415, "Unsupported Media Type"),
    "invalid-request": (422, "Invalid Request"),
    "missing-buffer": (422, "Missing Buffer"),
    "missing-camera": (422, "Missing Camera"),
    "busy": (429, "Too Many Requests"),
    "internal": (500, "Internal Server Error"),
    "unavailable": (503, "Service Unavailable"),
    "worker-lost": (503, "Worker Lost"),
    "timeout": (504, "Job Timed Out"),
}


class Problem(Exception):
    """An error answered as problem+json: ``kind`` (see :data:`KINDS`) and a ``detail``."""

    def __init__(
        self,
        kind: str,
        detail: str,
        *,
        headers: dict[str, str] | None = None,
        status: int | None = None,
        **extra: Any,
    ) -> None:
        super().__init__(detail)
        if kind not in KINDS:
            raise ValueError(f"problem kind {kind!r} is not one of {sorted(KINDS)}")
        self.kind = kind
        self.status = status or KINDS[kind][0]
        self.detail = detail
        self.headers = headers or {}
        self.extra = extra

    def body(self, instance: str | None = None, request_id: str | None = None) -> dict[str, Any]:
        title = KINDS[self.kind][1]
        if self.status != KINDS[self.kind][0]:
            title = HTTPStatus(self.status).phrase
        out: dict[str, Any] = {
            "type": f"urn:depict:problem:{self.kind}",
            "title": title,
            "status": self.status,
            "detail": self.detail,
        }
        if instance:
            out["instance"] = instance
        if request_id:
            out["request_id"] = request_id
        out.update(self.extra)
        return out

    def response(self, instance: str | None = None, request_id: str | None = None) -> Response:
        return Response(
            json.dumps(self.body(instance, request_id)),
            status_code=self.status,
            media_type=MEDIA_TYPE,
            headers=self.headers,
        )


def from_exception(exc: BaseException) -> Problem:
    """The problem for an exception raised while handling a request (500 for unknown ones)."""
    if isinstance(exc, Problem):
        return exc
    if isinstance(exc, LimitError):
        return Problem("limit", str(exc))
    if isinstance(exc, MissingBufferError):
        return Problem("missing-buffer", str(exc))
    if isinstance(exc, MissingCameraError):
        return Problem("missing-camera", str(exc))
    if isinstance(exc, PipelineError | OptionError):
        return Problem("invalid-request", str(exc))
    if isinstance(exc, FrameError):
        return Problem("bad-file", str(exc))
    return Problem("internal", "internal error; the server log has the details (see request_id)")


def kind_for_status(status: int) -> str:
    """The problem kind used for a plain HTTP status (404, 405, ...)."""
    if status == 400:
        return "bad-request"
    for kind, (code, _) in KINDS.items():
        if code == status:
            return kind
    return "bad-request" if 400 <= status < 500 else "internal"


#: OpenAPI description of the problem body, for the responses of every route.
PROBLEM_SCHEMA: dict[str, Any] = {
    "title": "Problem",
    "type": "object",
    "description": "RFC 9457 problem details",
    "properties": {
        "type": {"type": "string", "description": "urn:depict:problem:<kind>"},
        "title": {"type": "string"},
        "status": {"type": "integer"},
        "detail": {"type": "string", "description": "what is wrong and what to do"},
        "instance": {"type": "string", "description": "the request path"},
        "request_id": {"type": "string", "description": "the X-Request-ID of the request"},
    },
    "required": ["type", "title", "status", "detail"],
}


def openapi_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` entries for FastAPI routes: problem+json bodies for ``statuses``."""
    return {
        status: {
            "description": KINDS[kind_for_status(status)][1],
            "content": {MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}},
        }
        for status in statuses
    }
