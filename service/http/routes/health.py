"""``GET /healthz`` (alive; never needs the key, answers while the workers are saturated),
``GET /readyz`` (a worker is warmed up and could render with OSMesa) and ``GET /metrics``
(Prometheus)."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, Field
from starlette.responses import Response

from service.http.deps import Server
from service.problems import Problem, openapi_responses
from service.version import version

router = APIRouter(tags=["health"])


class Health(BaseModel):
    status: str
    version: str = Field(description="Depict's version")


class Ready(BaseModel):
    status: str
    osmesa: bool
    workers: int
    queue: int


@router.get(
    "/healthz",
    summary="Alive and able to work (503: restart the service)",
    response_model=Health,
    responses=openapi_responses(503),
)
async def healthz(server: Server) -> dict[str, str]:
    healthy, why = server.running_pool().pool.health()
    if not healthy:
        raise Problem("unavailable", f"{why}; restart the service")
    return {"status": "ok", "version": version()}


@router.get(
    "/readyz",
    summary="Ready to take work: worker pool up, OSMesa context created",
    response_model=Ready,
    responses=openapi_responses(503),
)
async def readyz(server: Server) -> dict[str, object]:
    info = server.running_pool().ready()
    if not info.get("osmesa"):
        raise Problem("unavailable", str(info.get("detail", "not ready")))
    return {
        "status": "ready",
        "osmesa": True,
        "workers": server.settings.workers,
        "queue": server.settings.queue,
    }


@router.get(
    "/metrics",
    summary="Prometheus metrics",
    response_class=Response,
    responses={
        200: {"description": "text exposition format", "content": {"text/plain": {}}},
        **openapi_responses(401),
    },
)
async def get_metrics(server: Server) -> Response:
    metrics = server.metrics
    return Response(metrics.render(), media_type=metrics.content_type)
