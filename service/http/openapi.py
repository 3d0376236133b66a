"""The OpenAPI document of the service (``GET /openapi.json``; committed as
``openapi/openapi.json`` by ``python -m service.openapi``): FastAPI's, completed with the
schemas of the JSON form fields and of the pipeline, and the API key's security scheme."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from pydantic import BaseModel
from pydantic.json_schema import models_json_schema

from service.http.middleware.auth import PUBLIC_PATHS
from service.http.routes.analysis import CompareOptions
from service.http.routes.frames import Scene
from service.problems import PROBLEM_SCHEMA
from service.registry import operators


def pipeline_schemas() -> dict[str, Any]:
    """Components: ``Pipeline`` (one ``oneOf`` branch per registered operator) and its params."""
    ops = list(operators().values())
    models: list[tuple[type[BaseModel], Literal["validation"]]] = [
        (op.params, "validation") for op in ops
    ]
    refs, defs = models_json_schema(models, ref_template="#/components/schemas/{model}")
    components: dict[str, Any] = dict(defs.get("$defs", {}))
    branches = []
    for op in ops:
        branches.append(
            {
                "type": "object",
                "title": op.name,
                "description": op.summary,
                "properties": {
                    "op": {"const": op.name},
                    "params": refs[(op.params, "validation")],
                },
                "required": ["op"],
                "additionalProperties": False,
            }
        )
    step: dict[str, Any] = {"oneOf": branches} if branches else {"type": "object"}
    components["Pipeline"] = {
        "title": "Pipeline",
        "type": "object",
        "description": "operator steps applied in order (the `pipeline` form field, as JSON)",
        "properties": {"steps": {"type": "array", "minItems": 1, "items": step}},
        "required": ["steps"],
        "additionalProperties": False,
    }
    return components


def document(app: FastAPI) -> dict[str, Any]:
    """The app's OpenAPI document, made once: FastAPI's, with the problem body, the JSON form
    fields' schemas, the pipeline's (one branch per operator) and the bearer key."""
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(
        title=app.title,
        version=app.version,
        summary=app.summary,
        description=app.description,
        routes=app.routes,
    )
    components = schema.setdefault("components", {})
    schemas = components.setdefault("schemas", {})
    schemas["Problem"] = PROBLEM_SCHEMA
    schemas["Scene"] = Scene.model_json_schema()
    schemas["CompareOptions"] = CompareOptions.model_json_schema()
    schemas.update(pipeline_schemas())
    components["securitySchemes"] = {
        "bearer": {
            "type": "http",
            "scheme": "bearer",
            "description": "DEPICT_API_KEY, when the server sets one",
        }
    }
    for path, item in schema.get("paths", {}).items():
        if path in PUBLIC_PATHS:
            continue
        for operation in item.values():
            operation["security"] = [{"bearer": []}, {}]
    app.openapi_schema = schema
    return schema
