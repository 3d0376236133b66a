"""``GET /v1/operators``: every operator of the registry with the JSON schema of its
parameters (what ``depict ops --json`` prints)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel, Field

from service.problems import openapi_responses
from service.registry import operators

router = APIRouter(tags=["operators"])


class OperatorInfo(BaseModel):
    name: str
    summary: str
    needs: list[str]
    writes: list[str]
    params: dict[str, Any] = Field(description="JSON schema of the parameters")


@router.get(
    "/v1/operators",
    summary="Every operator with the JSON schema of its parameters",
    response_model=list[OperatorInfo],
    responses=openapi_responses(401),
)
async def list_operators() -> list[dict[str, Any]]:
    return [op.schema() for op in operators().values()]
