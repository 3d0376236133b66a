"""Service settings, read from ``DEPICT_*`` environment variables (pydantic-settings).

=============================  =============  ======================================================
variable                       default        meaning
=============================  =============  ======================================================
``DEPICT_HOST``                ``127.0.0.1``  address ``depict serve`` binds (``0.0.0.0`` in
                                              Docker)
``DEPICT_PORT``                ``8000``       port ``depict serve`` binds
``DEPICT_API_KEY``             unset          when set, every route except ``/healthz`` and
                                              ``/readyz`` needs ``Authorization: Bearer <key>``
``DEPICT_METRICS_PUBLIC``      ``false``      ``true``: ``/metrics`` needs no key even when one is
                                              set
``DEPICT_MAX_UPLOAD_MB``       ``512``        largest request body, MiB (413 above)
``DEPICT_MAX_PIXELS``          ``67108864``   largest frame, width x height of the EXR data
                                              window or of a render (413 above; checked on the
                                              header)
``DEPICT_MAX_DECODED_MB``      ``1024``       largest decoded EXR, MiB: the sum over channels of
                                              width x height x bytes per sample (413 above; checked
                                              on the header)
``DEPICT_MAX_CHANNELS``        ``512``        most channels in an EXR, all parts together (413)
``DEPICT_UPLOAD_TIMEOUT_S``    ``300``        time a client has to send a request, headers and body
                                              (408 and the connection closed after)
``DEPICT_WORKERS``             ``2``          jobs processed in parallel (worker processes)
``DEPICT_QUEUE``               ``8``          jobs waiting for a worker; one more answers 429
``DEPICT_TIMEOUT_S``           ``120``        time limit of a job, queue wait included (504
                                              after)
``DEPICT_SHUTDOWN_GRACE_S``    ``10``         on SIGTERM, how long running requests may finish
                                              (503 after)
``DEPICT_VIEWER_TTL_S``        ``3600``       how long the web viewer keeps an uploaded frame after
                                              its last use, seconds
``DEPICT_VIEWER_MAX_MB``       ``2048``       the viewer's frames on disk, their preview copies
                                              included, all together, MiB (the least recently
                                              used go first)
``DEPICT_VIEWER_MAX_FRAMES``   ``32``         most frames the viewer keeps
``DEPICT_LOG_LEVEL``           ``info``       ``debug``, ``info``, ``warning`` or ``error``
``DEPICT_EXR_THREADS``         cores          OpenEXR's (de)compression threads (gbuffer.exr)
=============================  =============  ======================================================
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict

from gbuffer.limits import Limits


class Settings(BaseSettings):
    """Settings of the HTTP service; every field is the env variable ``DEPICT_<FIELD>``."""

    model_config = SettingsConfigDict(env_prefix="DEPICT_", extra="ignore")

    host: str = Field(default="127.0.0.1", description="address to bind")
    port: int = Field(default=8000, ge=0, le=65535, description="port to bind (0: any free port)")
    api_key: SecretStr | None = Field(
        default=None, description="bearer token required on every route but health when set"
    )
    metrics_public: bool = Field(default=False, description="serve /metrics without the API key")
    max_upload_mb: float = Field(default=512.0, gt=0, description="largest request body, MiB")
    max_pixels: int = Field(
        default=8192 * 8192,
        ge=1,
        description="largest frame (width x height), checked on the header",
    )
    max_decoded_mb: float = Field(
        default=1024.0,
        gt=0,
        description="largest decoded EXR (sum of channels x width x height x bytes), MiB",
    )
    max_channels: int = Field(default=512, ge=1, description="most channels in an EXR")
    upload_timeout_s: float = Field(
        default=300.0, gt=0, description="time a client has to send a whole request"
    )
    workers: int = Field(default=2, ge=1, le=256, description="jobs processed in parallel")
    queue: int = Field(default=8, ge=0, le=10_000, description="jobs waiting for a worker")
    timeout_s: float = Field(
        default=120.0, gt=0, description="time limit of a job, queue wait included"
    )
    shutdown_grace_s: float = Field(
        default=10.0, ge=0, description="on SIGTERM, how long running requests may finish"
    )
    viewer_ttl_s: float = Field(
        default=3600.0, gt=0, description="seconds the viewer keeps a frame after its last use"
    )
    viewer_max_mb: float = Field(default=2048.0, gt=0, description="the viewer's frames, MiB")
    viewer_max_frames: int = Field(default=32, ge=1, description="most frames the viewer keeps")
    log_level: Literal["debug", "info", "warning", "error"] = Field(
        default="info", description="log level of the JSON logs"
    )

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 1024 * 1024)

    @property
    def limits(self) -> Limits:
        """What an uploaded EXR's header may claim (checked before decoding)."""
        return Limits(
            max_pixels=self.max_pixels,
            max_bytes=int(self.max_decoded_mb * 1024 * 1024),
            max_channels=self.max_channels,
        )

    @property
    def key(self) -> str | None:
        """The API key, or ``None`` when unset or empty."""
        if self.api_key is None:
            return None
        return self.api_key.get_secret_value() or None
