"""The API key: when ``DEPICT_API_KEY`` is set, every route but the public ones (health, the API
docs, the viewer's static page) needs ``Authorization: Bearer <key>`` (401 problem otherwise),
checked before any body byte is read."""

from __future__ import annotations

import hmac

from starlette.types import ASGIApp, Receive, Scope, Send

from service.http.middleware.observe import request_headers
from service.logs import REQUEST_ID
from service.problems import Problem
from service.settings import Settings

#: Routes open without the API key.
PUBLIC_PATHS = (
    "/healthz",
    "/readyz",
    "/openapi.json",
    "/docs",
    "/docs/oauth2-redirect",
    "/redoc",
)
#: The web viewer's page and scripts (its API calls carry the key).
VIEWER = "/ui"
#: Where the Swagger UI and ReDoc assets are served from (fastapi-offline's copies: no CDN).
DOCS_ASSETS = "/docs-assets"


def is_public(path: str, settings: Settings) -> bool:
    """Whether ``path`` is served without the API key."""
    return (
        path in PUBLIC_PATHS
        or path.startswith(f"{DOCS_ASSETS}/")
        or path == VIEWER
        or path.startswith(f"{VIEWER}/")
        or (path == "/metrics" and settings.metrics_public)
    )


def refusal(authorization: str, key: str) -> Problem | None:
    """The 401 problem for a request with this ``Authorization`` header, if any."""
    scheme, _, token = authorization.partition(" ")
    if scheme.lower() != "bearer" or not token.strip():
        return Problem(
            "unauthorized",
            "this server needs an API key: send 'Authorization: Bearer <DEPICT_API_KEY>'",
            headers={"WWW-Authenticate": 'Bearer realm="depict"'},
        )
    if not hmac.compare_digest(token.strip().encode(), key.encode()):
        return Problem(
            "unauthorized",
            "the API key is wrong (Authorization: Bearer <key>)",
            headers={"WWW-Authenticate": 'Bearer realm="depict", error="invalid_token"'},
        )
    return None


class Auth:
    """Pure ASGI middleware: refuses a request without the right key (when one is set)."""

    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        self.settings = settings

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        key = self.settings.key
        if scope["type"] == "http" and key and not is_public(scope["path"], self.settings):
            authorization = request_headers(scope).get("authorization", "")
            problem = refusal(authorization, key)
            if problem is not None:
                response = problem.response(scope["path"], REQUEST_ID.get())
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)
