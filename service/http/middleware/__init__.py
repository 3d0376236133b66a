"""The service's ASGI middleware, one module per concern, outermost first:

* :mod:`.observe`: request id, metrics, access log, the last-resort 500;
* :mod:`.auth`: the API key;
* :mod:`.limits`: content type, body size, upload time.

Each refuses with a problem answer before any body byte is parsed.
"""

from __future__ import annotations

from starlette.middleware import Middleware
from starlette.types import ASGIApp

from service.http.middleware.auth import Auth
from service.http.middleware.limits import Limits
from service.http.middleware.observe import Observe
from service.metrics import Metrics
from service.settings import Settings


def middleware(settings: Settings, metrics: Metrics) -> list[Middleware]:
    """The middleware of the app, outermost first (``FastAPI(middleware=...)``)."""
    return [
        Middleware(Observe, metrics=metrics),
        Middleware(Auth, settings=settings),
        Middleware(Limits, settings=settings),
    ]


def wrap(app: ASGIApp, settings: Settings, metrics: Metrics) -> ASGIApp:
    """``app`` behind the same middleware (e.g. to test it in front of another app)."""
    for cls, args, kwargs in reversed(middleware(settings, metrics)):
        app = cls(app, *args, **kwargs)
    return app
