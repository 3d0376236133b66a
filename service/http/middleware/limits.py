"""What a request may be, checked as it arrives: multipart uploads on the upload routes (415),
a body within ``DEPICT_MAX_UPLOAD_MB`` (413, from ``Content-Length`` before any byte is read,
else as the bytes arrive), received within ``DEPICT_UPLOAD_TIMEOUT_S`` (408, the connection
closed after) and, for a multipart body, whole (400 when it ends before its close delimiter: the
form parser would take the cut-off part for a missing field)."""

from __future__ import annotations

import time

import anyio
from python_multipart.multipart import parse_options_header
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.http.middleware.observe import request_headers
from service.logs import REQUEST_ID
from service.problems import Problem
from service.settings import Settings

#: Routes that take an upload: multipart/form-data only.
UPLOAD_PATHS = (
    "/v1/enhance",
    "/v1/render",
    "/v1/score",
    "/v1/compare",
    "/v1/relief/pick",
    "/v1/frames",
)
#: Most bytes of a refused body read (within 2 s) so that the client reads the answer.
DRAIN_BYTES = 32 * 2**20


class Limits:
    """Pure ASGI middleware enforcing the request limits of :class:`Settings`."""

    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        self.settings = settings

    def _too_large(self, size: int | None) -> str:
        got = f"{size / 2**20:.1f} MiB" if size is not None else "the body"
        return (
            f"request body of {got} is over DEPICT_MAX_UPLOAD_MB="
            f"{self.settings.max_upload_mb:g} MiB; send a smaller file"
        )

    def _too_slow(self) -> str:
        return (
            f"the request was not received within DEPICT_UPLOAD_TIMEOUT_S="
            f"{self.settings.upload_timeout_s:g} s; the connection is closed"
        )

    def _refuse(self, scope: Scope) -> Problem | None:
        """A problem known from the headers alone: wrong content type, or too long a body."""
        headers = request_headers(scope)
        path = scope["path"]
        if scope["method"] == "POST" and path in UPLOAD_PATHS:
            ctype = headers.get("content-type", "")
            if not ctype.lower().startswith("multipart/form-data"):
                return Problem(
                    "unsupported-media-type",
                    f"{path} takes multipart/form-data (curl -F file=@frame.exr), "
                    f"not {ctype or 'a body without Content-Type'}",
                )
        length = headers.get("content-length")
        if length is not None and length.isdigit() and int(length) > self.settings.max_upload_bytes:
            return Problem("limit", self._too_large(int(length)))
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        problem = self._refuse(scope)
        if problem is not None:
            if problem.kind == "limit":  # drain a little so the client reads the answer
                await _drain(receive)
            await problem.response(scope["path"], REQUEST_ID.get())(scope, receive, send)
            return
        await self.app(scope, self._bounded(receive, _CloseDelimiter.of(scope)), send)

    def _bounded(self, receive: Receive, close: _CloseDelimiter | None) -> Receive:
        """``receive`` raising 408 past the upload deadline, 413 past the body limit and, with
        ``close``, 400 when a multipart body ends before its close delimiter."""
        deadline = time.perf_counter() + self.settings.upload_timeout_s
        limit = self.settings.max_upload_bytes
        received = 0
        body_done = False

        async def bounded_receive() -> Message:
            nonlocal received, body_done
            if body_done:
                return await receive()
            with anyio.move_on_after(deadline - time.perf_counter()) as waited:
                message = await receive()
            if waited.cancelled_caught:  # a stalled or trickling upload: answer, then close
                raise HTTPException(408, self._too_slow(), headers={"Connection": "close"})
            if message["type"] == "http.request":
                chunk = message.get("body", b"")
                received += len(chunk)
                if received > limit:
                    raise HTTPException(413, self._too_large(None))
                body_done = not message.get("more_body", False)
                if close is not None:
                    close.feed(chunk)
                    if body_done and not close.seen:
                        raise HTTPException(400, _CUT_SHORT)
            return message

        return bounded_receive


_CUT_SHORT = (
    "the multipart body ends before its close delimiter (--BOUNDARY--): the upload was cut "
    "short; send it again"
)


class _CloseDelimiter:
    """Whether a multipart body's close delimiter ``--BOUNDARY--`` has gone by, chunk by chunk
    (its bytes may straddle two chunks)."""

    def __init__(self, boundary: bytes) -> None:
        self.mark = b"--" + boundary + b"--"
        self.tail = b""
        self.seen = False

    @classmethod
    def of(cls, scope: Scope) -> _CloseDelimiter | None:
        """The tracker of an upload route's multipart body with a boundary, else None."""
        if scope["method"] != "POST" or scope["path"] not in UPLOAD_PATHS:
            return None
        ctype, options = parse_options_header(request_headers(scope).get("content-type", ""))
        boundary = options.get(b"boundary")
        if ctype != b"multipart/form-data" or not boundary:
            return None  # (the form parser answers a missing boundary itself)
        return cls(boundary)

    def feed(self, chunk: bytes) -> None:
        if self.seen or not chunk:
            return
        keep = len(self.mark) - 1
        self.seen = self.mark in self.tail + chunk[:keep] or self.mark in chunk
        self.tail = (self.tail + chunk)[-keep:] if len(chunk) < keep else chunk[-keep:]


async def _drain(receive: Receive) -> None:
    """Read and drop up to :data:`DRAIN_BYTES` of the body, for at most 2 s."""
    with anyio.move_on_after(2.0):
        drained = 0
        while drained < DRAIN_BYTES:
            message = await receive()
            drained += len(message.get("body", b""))
            if not message.get("more_body"):
                break
