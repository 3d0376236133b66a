"""Python client of the Depict HTTP service (httpx); also what ``depict ... --server URL`` uses.

Example::

    from service.client import Client

    with Client("http://127.0.0.1:8000", api_key="secret") as depict:
        print([op["name"] for op in depict.operators()])
        depict.enhance("shot.0001.exr", "shot_rs.0001.exr",
                       pipeline={"steps": [{"op": "radiance_scaling", "params": {"gamma": 2}}]})
        depict.enhance("shot.0001.exr", "preview.png", preview=True)
        depict.render("bunny.obj", "bunny.exr", width=640, height=480, lights=["-1,1,1"])

``Client.from_env()`` reads the URL from ``DEPICT_SERVER`` and the key from ``DEPICT_API_KEY``.
Errors raise :class:`DepictError` whose message is the server's ``detail`` (problem+json) and
whose ``status`` is the HTTP status (0 when the server could not be reached). A 429 answer is
retried after its ``Retry-After`` delay, ``retries`` times (default 5). Outputs are written to a
temporary file renamed into place, so no reader sees half a file.
"""

from __future__ import annotations

import base64
import json
import os
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, BinaryIO

import httpx

from gbuffer.atomic import atomic_path, read_text, regular_file
from service.errors import DepictError
from service.headers import WARNING, warning_text

__all__ = ["Client", "DepictError"]


def _pipeline_json(pipeline: Any) -> str | None:
    """A pipeline (PipelineSpec, dict, list of steps or JSON text) as JSON text."""
    if pipeline is None:
        return None
    if hasattr(pipeline, "model_dump_json"):
        return str(pipeline.model_dump_json())
    if isinstance(pipeline, str):
        return pipeline
    return json.dumps(pipeline)


def _camera_json(camera: Any) -> str | None:
    """A camera (dict, Camera, or path of a camera JSON file) as JSON text."""
    if camera is None:
        return None
    if isinstance(camera, Mapping):
        return json.dumps(dict(camera))
    if hasattr(camera, "to_dict"):
        return json.dumps(camera.to_dict())
    try:
        return read_text(camera)
    except OSError as exc:
        raise DepictError(f"cannot read camera file {camera}: {exc.strerror}") from None


def _opened(path: Path) -> BinaryIO:
    """``path`` open to upload: a regular file (a FIFO would block the upload for ever, a
    device never end), else :class:`DepictError` naming it."""
    try:
        return open(regular_file(path), "rb")
    except FileNotFoundError:
        raise DepictError(f"no such file: {path}") from None
    except OSError as exc:
        raise DepictError(f"cannot read {path}: {exc.strerror or exc}") from None


class Client:
    """A connection to a Depict server.

    Parameters
    ----------
    url : base URL, e.g. ``http://127.0.0.1:8000``.
    api_key : sent as ``Authorization: Bearer``; default ``$DEPICT_API_KEY``.
    timeout : seconds for one request (upload, processing and download).
    retries : how many times a 429 (queue full) is retried after its ``Retry-After``.
    transport : an httpx transport (tests: ``httpx.ASGITransport``); default a real socket.

    After :meth:`enhance` or :meth:`render`, :attr:`warnings` holds the server's warnings about
    that file (as ``depict enhance`` prints them: NaN pixels read as holes, ...).
    """

    def __init__(
        self,
        url: str,
        *,
        api_key: str | None = None,
        timeout: float = 600.0,
        retries: int = 5,
        transport: httpx.BaseTransport | None = None,
    ) -> None:
        if not url.startswith(("http://", "https://")):
            raise DepictError(f"server URL {url!r} must start with http:// or https://")
        key = api_key if api_key is not None else os.environ.get("DEPICT_API_KEY") or None
        if key and not (key.isascii() and key.isprintable()):
            raise DepictError(
                "the API key (DEPICT_API_KEY) must be printable ASCII: an HTTP header holds "
                "nothing else"
            )
        headers = {"Authorization": f"Bearer {key}"} if key else {}
        self.url = url.rstrip("/")
        self.retries = retries
        self.warnings: list[str] = []
        try:
            self._http = httpx.Client(
                base_url=self.url, headers=headers, timeout=timeout, transport=transport
            )
        except httpx.InvalidURL as exc:
            raise DepictError(f"server URL {url!r} is not valid: {exc}") from None

    @classmethod
    def from_env(cls, url: str | None = None, **kwargs: Any) -> Client:
        """A client for ``url`` or ``$DEPICT_SERVER``, with ``$DEPICT_API_KEY``."""
        url = url or os.environ.get("DEPICT_SERVER")
        if not url:
            raise DepictError("no server URL: pass --server URL or set DEPICT_SERVER")
        return cls(url, **kwargs)

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._http.close()

    # -- plumbing ------------------------------------------------------------------------------

    def _error(self, response: httpx.Response) -> DepictError:
        try:
            body = json.loads(response.read())
        except (ValueError, httpx.HTTPError):
            body = {}
        detail = body.get("detail") if isinstance(body, dict) else None
        text = detail or response.reason_phrase or "error"
        return DepictError(
            f"server answered {response.status_code}: {text}",
            response.status_code,
            body if isinstance(body, dict) else {},
        )

    @contextmanager
    def _stream(
        self,
        method: str,
        path: str,
        *,
        files: Mapping[str, Path] | None = None,
        data: Mapping[str, str] | None = None,
        params: Mapping[str, Any] | None = None,
    ) -> Iterator[httpx.Response]:
        """A successful streamed response (retrying 429s), else :class:`DepictError`."""
        attempt = 0
        while True:
            with ExitStack() as stack:
                upload = {
                    name: (p.name, stack.enter_context(_opened(p)))
                    for name, p in (files or {}).items()
                }
                try:
                    response = stack.enter_context(
                        self._http.stream(
                            method,
                            path,
                            files=upload or None,
                            data=dict(data or {}) or None,
                            params=dict(params or {}) or None,
                        )
                    )
                except httpx.TransportError as exc:
                    raise DepictError(f"cannot reach {self.url}: {exc}") from None
                if response.status_code == 429 and attempt < self.retries:
                    attempt += 1
                    delay = response.headers.get("retry-after", "1")
                    time.sleep(min(60.0, float(delay) if delay.isdigit() else 1.0))
                    continue
                if response.status_code >= 400:
                    raise self._error(response)
                try:
                    yield response
                except httpx.TransportError as exc:  # (the server went away while it answered)
                    raise DepictError(f"the answer of {self.url} was cut short: {exc}") from None
                return

    def _json(self, path: str) -> Any:
        with self._stream("GET", path) as response:
            return json.loads(response.read())

    def _download(self, response: httpx.Response, output: str | Path) -> Path:
        with atomic_path(output) as tmp, open(tmp, "wb") as out:
            for chunk in response.iter_bytes(1 << 20):
                out.write(chunk)
        self.warnings = [warning_text(v) for v in response.headers.get_list(WARNING)]
        return Path(output)

    # -- API -----------------------------------------------------------------------------------

    def health(self) -> dict[str, Any]:
        """``GET /healthz``."""
        return dict(self._json("/healthz"))

    def ready(self) -> dict[str, Any]:
        """``GET /readyz`` (raises :class:`DepictError` 503 when not ready)."""
        return dict(self._json("/readyz"))

    def operators(self) -> list[dict[str, Any]]:
        """``GET /v1/operators``: every operator with the JSON schema of its parameters."""
        return list(self._json("/v1/operators"))

    def enhance(
        self,
        input: str | Path,
        output: str | Path,
        *,
        pipeline: Any = None,
        preset: str = "auto",
        camera: Any = None,
        mapping: Mapping[str, str] | None = None,
        normal_space: str | None = None,
        debug_layers: bool = False,
        output_layer: str | None = None,
        layout: str | None = None,
        preview: bool = False,
        exposure: float = 0.0,
        colorspace: str | None = None,
        display: str | None = None,
        view: str | None = None,
        view_layer: str | None = None,
    ) -> Path:
        """``POST /v1/enhance``: write the enhanced EXR (or a PNG with ``preview``, through the
        OCIO ``display`` and ``view``, default the server config's) to ``output``.

        ``pipeline``: a PipelineSpec, dict, list of steps or JSON text (default: the server's
        default, Radiance Scaling). ``camera``: a dict, a Camera or a camera JSON path.
        ``colorspace``: the working space (a name of the server's OCIO config).
        ``layout``: where new layers go (same, part, sidecar; default: the server's).
        ``view_layer``: the view layer read, of a render with several.
        """
        data = self._read_fields(preset, camera, mapping, normal_space, colorspace, view_layer)
        data["debug_layers"] = "true" if debug_layers else "false"
        optional = {
            "pipeline": _pipeline_json(pipeline),
            "output_layer": output_layer,
            "layout": layout,
        }
        data.update({k: v for k, v in optional.items() if v is not None})
        params: dict[str, Any] = {}
        if preview:
            shown = {"preview": "png", "exposure": exposure, "display": display, "view": view}
            params = {k: v for k, v in shown.items() if v is not None}
        with self._stream(
            "POST", "/v1/enhance", files={"file": Path(input)}, data=data, params=params
        ) as response:
            return self._download(response, output)

    def render(
        self,
        mesh: str | Path,
        output: str | Path,
        *,
        width: int = 960,
        height: int = 720,
        camera: Any = None,
        azimuth: float = 30.0,
        elevation: float = 20.0,
        lights: Sequence[str] = (),
    ) -> Path:
        """``POST /v1/render``: render ``mesh`` to a canonical G-buffer EXR at ``output``."""
        scene: dict[str, Any] = {
            "width": width,
            "height": height,
            "azimuth": azimuth,
            "elevation": elevation,
            "lights": list(lights),
        }
        cam = _camera_json(camera)
        if cam is not None:
            try:
                scene["camera"] = json.loads(cam)
            except ValueError as exc:  # (a file's text; a dict or a Camera is JSON already)
                raise DepictError(f"cannot read camera file {camera}: {exc}") from None
        with self._stream(
            "POST", "/v1/render", files={"mesh": Path(mesh)}, data={"scene": json.dumps(scene)}
        ) as response:
            return self._download(response, output)

    def _read_fields(
        self,
        preset: str = "auto",
        camera: Any = None,
        mapping: Mapping[str, str] | None = None,
        normal_space: str | None = None,
        colorspace: str | None = None,
        view_layer: str | None = None,
    ) -> dict[str, str]:
        """The form fields that say how the server reads the uploaded frame."""
        fields = {
            "preset": preset,
            "camera": _camera_json(camera),
            "map": json.dumps(dict(mapping)) if mapping else None,
            "normal_space": normal_space,
            "colorspace": colorspace,
            "view_layer": view_layer,
        }
        return {k: v for k, v in fields.items() if v is not None}

    def _post_json(self, path: str, file: Path, data: dict[str, str]) -> dict[str, Any]:
        with self._stream("POST", path, files={"file": file}, data=data) as response:
            return dict(json.loads(response.read()))

    def score(
        self,
        input: str | Path,
        *,
        pipeline: Any = None,
        preset: str = "auto",
        camera: Any = None,
        mapping: Mapping[str, str] | None = None,
        normal_space: str | None = None,
        colorspace: str | None = None,
        view_layer: str | None = None,
        **options: float | str,
    ) -> dict[str, Any]:
        """``POST /v1/score``: the congruence score of a frame's beauty (after ``pipeline``).

        ``options``: ``gradient_scale``, ``integration_scale``, ``percentile``, ``depth_jump``,
        ``shading_norm``, ``shape``.
        """
        data = self._read_fields(preset, camera, mapping, normal_space, colorspace, view_layer)
        data.update({k: str(v) for k, v in options.items()})
        spec = _pipeline_json(pipeline)
        if spec is not None:
            data["pipeline"] = spec
        return self._post_json("/v1/score", Path(input), data)

    def compare(
        self,
        input: str | Path,
        options: Mapping[str, Any] | None = None,
        *,
        mesh: bool = False,
        sheet: str | Path | None = None,
        preset: str = "auto",
        camera: Any = None,
    ) -> dict[str, Any]:
        """``POST /v1/compare``: the comparison bench (LLA §7) on an EXR frame or a mesh.

        ``options``: ``methods``, ``directions``, ``params``, ``albedo``, ``label`` and, for a
        mesh, ``width``, ``height``, ``azimuth``, ``elevation``. With ``sheet``, the contact
        sheet PNG is written there. Returns the JSON of ``depict compare --json``.
        """
        data = self._read_fields(preset, camera)
        data["options"] = json.dumps(dict(options or {}))
        data["kind"] = "mesh" if mesh else "exr"
        data["sheet"] = "true" if sheet else "false"
        out = self._post_json("/v1/compare", Path(input), data)
        png = out.pop("sheet_png", None)
        if sheet and png:
            with atomic_path(sheet) as tmp:
                Path(tmp).write_bytes(base64.b64decode(png))
        return out

    def relief_pick(
        self,
        input: str | Path,
        x: int,
        y: int,
        params: Mapping[str, Any] | None = None,
        *,
        preset: str = "auto",
        camera: Any = None,
    ) -> dict[str, Any]:
        """``POST /v1/relief/pick``: the Apparent Relief descriptor under pixel (x, y)."""
        data = self._read_fields(preset, camera)
        data.update(x=str(x), y=str(y), params=json.dumps(dict(params or {})))
        return self._post_json("/v1/relief/pick", Path(input), data)
