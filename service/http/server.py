"""``depict serve``: the app on uvicorn, with a guard against clients that never finish
sending their request headers."""

from __future__ import annotations

import logging
from typing import Any

import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from service.http.app import create_app
from service.logs import configure_logging
from service.settings import Settings

log = logging.getLogger("depict.http")


def slow_client_guard(timeout_s: float) -> type:
    """uvicorn's h11 protocol, closing a connection whose request headers have not all arrived
    ``timeout_s`` after it opened or after its previous answer (the body is timed by
    :mod:`service.http.middleware.limits`)."""

    class SlowClientGuard(H11Protocol):
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

    return SlowClientGuard


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
        http=slow_client_guard(settings.upload_timeout_s),
        log_config=None,
        access_log=False,
        # (typed int, given to asyncio.wait_for: seconds as a float are what it takes)
        timeout_graceful_shutdown=settings.shutdown_grace_s,  # type: ignore[arg-type]
    )
