"""Names shared by the parts of Local Light Alignment."""

from __future__ import annotations

from typing import Literal

from ops.filtering import F32

Guide = Literal["diffuse", "specular", "transmission"]
GUIDES: tuple[str, ...] = ("diffuse", "specular", "transmission")
DEFAULT_GAMMA = 3.0

SoA = tuple[F32, F32, F32]
