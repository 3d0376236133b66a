"""The service's error types, in a module of their own (no dependency) so the command line can
catch them without importing the HTTP client (httpx) or the operators on every run."""

from __future__ import annotations

from typing import Any


class DepictError(Exception):
    """An error answer of the server (``status``, ``problem`` body) or a connection failure."""

    def __init__(self, message: str, status: int = 0, problem: dict[str, Any] | None = None):
        super().__init__(message)
        self.status = status
        self.problem = problem or {}


class PipelineError(ValueError):
    """An unknown operator, unknown parameter or a value out of range; the message says which."""
