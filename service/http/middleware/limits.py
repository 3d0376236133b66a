"""What a request may be, checked as it arrives: multipart uploads on the upload routes (415),
a body within ``DEPICT_MAX_UPLOAD_MB`` (413, from ``Content-Length`` before any byte is read,
else as the bytes arrive) and received within ``DEPICT_UPLOAD_TIMEOUT_S`` (408, the connection
closed after)."""

from __future__ import annotations

import time

import anyio
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
        await self.app(scope, self._bounded(receive), send)

    def _bounded(self, receive: Receive) -> Receive:
        """``receive`` raising 408 past the upload deadline and 413 past the body limit."""
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
                received += len(message.get("body", b""))
                if received > limit:
                    raise HTTPException(413, self._too_large(None))
                body_done = not message.get("more_body", False)
            return message

        return bounded_receive


async def _drain(receive: Receive) -> None:
    """Read and drop up to :data:`DRAIN_BYTES` of the body, for at most 2 s."""
    with anyio.move_on_after(2.0):
        drained = 0
        while drained < DRAIN_BYTES:
            message = await receive()
            drained += len(message.get("body", b""))
            if not message.get("more_body"):
                break
