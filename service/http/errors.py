"""Every error answer as ``application/problem+json`` (:mod:`service.problems`): the app's
exception handlers, installed by :func:`install`."""

from __future__ import annotations

import json
import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from starlette.exceptions import HTTPException
from starlette.responses import Response

from gbuffer.errors import FrameError
from service.errors import PipelineError
from service.logs import REQUEST_ID
from service.problems import Problem, from_exception, kind_for_status

log = logging.getLogger("depict.http")


def problem_answer(request: Request, exc: Exception) -> Response:
    """A :class:`Problem`, a frame or pipeline error, or an unexpected exception (500)."""
    problem = from_exception(exc)
    if problem.kind == "internal":
        log.error("unhandled error on %s", request.url.path, exc_info=exc)
    return problem.response(request.url.path, REQUEST_ID.get())


def http_answer(request: Request, exc: Exception) -> Response:
    """Starlette's HTTP errors (404, 405, the multipart parser's 400, the limits' 408/413)."""
    assert isinstance(exc, HTTPException)
    detail = exc.detail if isinstance(exc.detail, str) else json.dumps(exc.detail)
    if exc.status_code == 404:
        detail = f"no route {request.method} {request.url.path}; see /openapi.json"
    elif exc.status_code == 405:
        detail = f"{request.url.path} does not accept {request.method}; see /openapi.json"
    elif exc.status_code == 400 and "exceeded maximum size" in detail:  # the multipart parser
        detail = "a form field is over 1 MiB (the limit of a field that is not a file)"
        return Problem("limit", detail).response(request.url.path, REQUEST_ID.get())
    problem = Problem(
        kind_for_status(exc.status_code),
        detail,
        status=exc.status_code,
        headers=dict(exc.headers or {}),
    )
    return problem.response(request.url.path, REQUEST_ID.get())


def validation_answer(request: Request, exc: Exception) -> Response:
    """A request FastAPI could not bind: each bad field named (422)."""
    assert isinstance(exc, RequestValidationError)
    parts = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err.get("loc", ()) if p not in ("body", "query"))
        parts.append(f"{loc or 'request'}: {err.get('msg', 'invalid')}")
    problem = Problem("invalid-request", "; ".join(parts) or "invalid request")
    return problem.response(request.url.path, REQUEST_ID.get())


def install(app: FastAPI) -> None:
    """Answer every error of ``app`` as a problem."""
    for error in (Problem, FrameError, PipelineError, Exception):
        app.add_exception_handler(error, problem_answer)
    app.add_exception_handler(HTTPException, http_answer)
    app.add_exception_handler(RequestValidationError, validation_answer)
