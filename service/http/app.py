"""The FastAPI app: :func:`create_app` puts the routers (:mod:`service.http.routes`) behind the
middleware (:mod:`service.http.middleware`) with problem answers for every error
(:mod:`service.http.errors`); the routes' shared state is :mod:`service.http.deps`."""

from __future__ import annotations

from fastapi import FastAPI
from fastapi_offline import FastAPIOffline

from service.http import errors, openapi
from service.http.deps import Services
from service.http.middleware import middleware
from service.http.middleware.auth import DOCS_ASSETS
from service.http.routes import analysis, frames, health, operators
from service.settings import Settings
from service.viewer import routes as viewer

API_VERSION = "1"


def create_app(settings: Settings | None = None) -> FastAPI:
    """The FastAPI app. Its worker pool starts and stops with the app's lifespan."""
    services = Services(settings or Settings())
    app = FastAPIOffline(  # /docs (Swagger UI) and /redoc with packaged assets, no CDN
        static_url=DOCS_ASSETS,
        title="Depict",
        version=API_VERSION,
        summary="Shape depiction on EXR G-buffers: enhance, render, score.",
        description=(
            "Errors are application/problem+json (RFC 9457). When the server has "
            "DEPICT_API_KEY set, every route but /healthz and /readyz needs "
            "`Authorization: Bearer <key>` (/metrics too, unless DEPICT_METRICS_PUBLIC=true)."
        ),
        lifespan=services.lifespan,
        middleware=middleware(services.settings, services.metrics),
    )
    app.state.services = services
    errors.install(app)
    app.include_router(frames.router)
    app.include_router(operators.router)
    app.include_router(health.router)
    app.include_router(analysis.router)
    app.include_router(viewer.router)
    viewer.mount_static(app)
    app.openapi = lambda: openapi.document(app)  # type: ignore[method-assign]
    return app
