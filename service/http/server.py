"""``depict serve``: the app on uvicorn, with a guard against clients that never finish
sending their request headers, and malformed requests answered as problems."""

from __future__ import annotations

import json
import logging
from typing import Any

import h11
import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from service.http.app import create_app
from service.logs import configure_logging
from service.problems import MEDIA_TYPE, Problem
from service.settings import Settings

log = logging.getLogger("depict.http")


_MALFORMED = (
    "malformed HTTP request: its request line, a header or the framing of its body "
    "(Content-Length, chunk sizes) could not be parsed"
)


def guarded_protocol(timeout_s: float) -> type:
    """uvicorn's h11 protocol, closing a connection whose request headers have not all arrived
    ``timeout_s`` after it opened or after its previous answer (the body is timed by
    :mod:`service.http.middleware.limits`), and answering a request it cannot parse (a bad
    request line, header or chunk size) with a 400 problem instead of plain text."""

    class GuardedProtocol(H11Protocol):
        _guard: Any = None

        def connection_made(self, transport: Any) -> None:
            super().connection_made(transport)
            self._arm()

        def on_response_complete(self) -> None:
            super().on_response_complete()
            self._arm()

        def connection_lost(self, exc: Exception | None) -> None:
            if self._guard is not None:
                self._guard.cancel()
            super().connection_lost(exc)

        def _arm(self) -> None:
            if self._guard is not None:
                self._guard.cancel()
            self._guard = self.loop.call_later(timeout_s, self._headers_overdue)

        def _headers_overdue(self) -> None:
            waiting = self.cycle is None or self.cycle.response_complete
            if waiting and not self.transport.is_closing():
                log.info("closed a connection whose request did not arrive in time")
                self.transport.close()

        def send_400_response(self, msg: str) -> None:
            cycle = self.cycle
            if cycle is not None and not cycle.response_complete:
                # the app may be answering this request already (e.g. a 401 from the headers
                # alone): its answer is dropped instead of failing on a closed connection
                cycle.disconnected = True
                if cycle.response_started:  # (too late for another answer)
                    self.transport.close()
                    return
            body = json.dumps(Problem("bad-request", _MALFORMED).body()).encode()
            headers = [
                (b"content-type", MEDIA_TYPE.encode()),
                (b"content-length", str(len(body)).encode()),
                (b"connection", b"close"),
            ]
            for event in (
                h11.Response(status_code=400, headers=headers, reason=b"Bad Request"),
                h11.Data(data=body),
                h11.EndOfMessage(),
            ):
                self.transport.write(self.conn.send(event))
            self.transport.close()

    return GuardedProtocol


def serve(settings: Settings | None = None) -> None:
    """Run the service with uvicorn (``depict serve``): JSON logs, one event loop."""
    settings = settings or Settings()
    configure_logging(settings.log_level)
    log.info(
        "starting",
        extra={"path": f"http://{settings.host}:{settings.port}"},
    )
    uvicorn.run(
        create_app(settings),
        host=settings.host,
        port=settings.port,
        http=guarded_protocol(settings.upload_timeout_s),
        log_config=None,
        access_log=False,
        # (typed int, given to asyncio.wait_for: seconds as a float are what it takes)
        timeout_graceful_shutdown=settings.shutdown_grace_s,  # type: ignore[arg-type]
    )
