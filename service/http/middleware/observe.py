"""Request ids, metrics and the access log: the outermost middleware.

Every answer carries ``X-Request-ID`` (the client's, when it sent a valid one, else a fresh one),
set in :data:`service.logs.REQUEST_ID` for every log line of the request; one JSON log line and
the Prometheus metrics (:class:`service.metrics.Metrics`) are written per request, whoever
answered it. An exception no handler took becomes a 500 problem carrying the request id; a
request still running when the stopping server's grace period ends, a 503 problem.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import time
import uuid
from dataclasses import dataclass, field
from typing import Any

from starlette.routing import Match, Mount
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.logs import REQUEST_ID
from service.metrics import Metrics
from service.problems import Problem

log = logging.getLogger("depict.http")

#: The answer to a request still running when the server stops (its grace period over).
_STOPPING = Problem(
    "unavailable",
    "the server is stopping and this request did not finish in time; send it again",
    headers={"Retry-After": "5"},
)

_REQUEST_ID_RE = re.compile(r"^[A-Za-z0-9._:/+=-]{1,128}$")


def request_headers(scope: Scope) -> dict[str, str]:
    """The request's headers, names lower-cased."""
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}


def route_label(scope: Scope) -> str:
    """The route template of a request (``other`` for unknown paths): a bounded label set.

    A request answered before routing (refused by the key or the limits) is labelled with its
    path when that is a route's path (whatever the method), never with a path under a mount."""
    route = scope.get("route")
    path = getattr(route, "path", None)
    if path:
        return str(path)
    app = scope.get("app")
    for candidate in getattr(app, "routes", ()):
        if not isinstance(candidate, Mount) and candidate.matches(scope)[0] is not Match.NONE:
            return str(scope["path"])
    return "other"


@dataclass
class _Exchange:
    """What passed through one request: its status and the body bytes each way."""

    status: int = 500
    started: bool = False
    bytes_in: int = 0
    bytes_out: int = 0
    start: float = field(default_factory=time.perf_counter)


class Observe:
    """Pure ASGI middleware: request id, metrics, access log, last-resort 500."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        rid = request_headers(scope).get("x-request-id", "")
        if not _REQUEST_ID_RE.match(rid):
            rid = uuid.uuid4().hex
        token = REQUEST_ID.set(rid)
        scope.setdefault("state", {})["request_id"] = rid
        seen = _Exchange()

        async def counted_send(message: Message) -> None:
            if message["type"] == "http.response.start":
                seen.status, seen.started = message["status"], True
                message["headers"] = [*message.get("headers", []), (b"x-request-id", rid.encode())]
            elif message["type"] == "http.response.body":
                seen.bytes_out += len(message.get("body", b""))
            await send(message)

        async def counted_receive() -> Message:
            message = await receive()
            if message["type"] == "http.request":
                seen.bytes_in += len(message.get("body", b""))
            return message

        self.metrics.in_flight.inc()
        try:
            await self._answer(scope, counted_receive, counted_send, seen, rid)
        finally:
            self.metrics.in_flight.dec()
            self._record(scope, seen)
            REQUEST_ID.reset(token)

    async def _answer(
        self, scope: Scope, receive: Receive, send: Send, seen: _Exchange, rid: str
    ) -> None:
        try:
            await self.app(scope, receive, send)
        except asyncio.CancelledError:  # the server stopping, its grace period over: a 503
            if seen.started:
                raise
            log.warning("stopping: %s answered 503 before its job finished", scope["path"])
            with contextlib.suppress(Exception):  # (the connection may be gone)
                await _STOPPING.response(scope["path"], rid)(scope, receive, send)
            # answered: the task ends here (uvicorn cancels it only to end it; re-raising
            # would add its plain-text traceback to the JSON log)
        except Exception as exc:  # a bug: 500 problem with the request id, logged
            log.error("unhandled error on %s", scope["path"], exc_info=exc)
            if seen.started:
                raise
            response = Problem(
                "internal", "internal error; the server log has the details (see request_id)"
            ).response(scope["path"], rid)
            await response(scope, receive, send)

    def _record(self, scope: Scope, seen: _Exchange) -> None:
        label = route_label(scope)
        elapsed = time.perf_counter() - seen.start
        method = scope["method"]
        self.metrics.requests.labels(label, method, str(seen.status)).inc()
        self.metrics.latency.labels(label, method).observe(elapsed)
        self.metrics.bytes_in.labels(label).inc(seen.bytes_in)
        self.metrics.bytes_out.labels(label).inc(seen.bytes_out)
        client: Any = scope.get("client")
        log.info(
            "request",
            extra={
                "method": method,
                "path": scope["path"],
                "route": label,
                "status": seen.status,
                "duration_ms": round(elapsed * 1e3, 2),
                "bytes_in": seen.bytes_in,
                "bytes_out": seen.bytes_out,
                "client": f"{client[0]}:{client[1]}" if client else None,
            },
        )
