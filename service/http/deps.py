"""What the routes share, as FastAPI dependencies: the server (its settings, metrics and worker
pool) and a working directory per request. A route declares what it needs in its signature::

    async def my_route(server: Server, work: Work) -> ...:
        out = await server.run("kind", jobs.some_job, str(work.path / "in.exr"), ...)

:class:`Services` holds them for one app; its :meth:`Services.lifespan` starts the worker pool
and the temporary root with the app and stops them with it.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

from fastapi import Depends, FastAPI, Request

from service.http.pool import JobPool
from service.metrics import Metrics
from service.problems import Problem
from service.settings import Settings
from service.viewer.store import FrameStore

_NOT_RUNNING = "the server is starting or stopping; retry shortly"


@dataclass
class Services:
    """One app's settings, metrics, worker pool, temporary root and the viewer's frames (the
    last three while the app runs)."""

    settings: Settings
    metrics: Metrics = field(default_factory=Metrics)
    pool: JobPool | None = None
    root: Path | None = None
    frames: FrameStore | None = None

    def running_pool(self) -> JobPool:
        """The worker pool; 503 while the app is not running."""
        if self.pool is None:
            raise Problem("unavailable", _NOT_RUNNING)
        return self.pool

    def frame_store(self) -> FrameStore:
        """The viewer's frames; 503 while the app is not running."""
        if self.frames is None:
            raise Problem("unavailable", _NOT_RUNNING)
        return self.frames

    async def run(self, kind: str, fn: Callable[..., dict[str, Any]], *args: Any) -> dict[str, Any]:
        """``fn(*args)`` on a worker (:meth:`JobPool.submit`): its dict, or a problem."""
        return await self.running_pool().submit(kind, fn, *args)

    @contextlib.asynccontextmanager
    async def lifespan(self, app: FastAPI) -> AsyncIterator[None]:
        """Start the workers (they warm up in the background; ``/readyz`` says when one is
        ready) and make the temporary root; stop and remove them when the app stops."""
        s = self.settings
        self.root = Path(tempfile.mkdtemp(prefix="depict-"))
        self.pool = JobPool(s.workers, s.queue, s.timeout_s, self.metrics, s.log_level)
        self.pool.start()
        mb = 1024 * 1024
        frames_root = self.root / "frames"
        self.frames = FrameStore(
            frames_root, s.viewer_ttl_s, int(s.viewer_max_mb * mb), s.viewer_max_frames
        )
        try:
            yield
        finally:
            self.frames = None
            await self.pool.shutdown()
            shutil.rmtree(self.root, ignore_errors=True)


class Workspace:
    """A request's temporary folder under the server's root, made on first use of
    :attr:`path` and removed once the answer is sent."""

    def __init__(self, root: Path | None) -> None:
        self._root = root
        self._path: Path | None = None

    @property
    def path(self) -> Path:
        if self._path is None:
            if self._root is None:
                raise Problem("unavailable", _NOT_RUNNING)
            self._path = Path(tempfile.mkdtemp(prefix="job-", dir=self._root))
        return self._path

    def remove(self) -> None:
        if self._path is not None:
            shutil.rmtree(self._path, ignore_errors=True)


def services(request: Request) -> Services:
    """The :class:`Services` of the app serving ``request``."""
    found: Services = request.app.state.services
    return found


def workspace(request: Request) -> Iterator[Workspace]:
    """A :class:`Workspace`, removed after the answer (a file answer is sent from it)."""
    work = Workspace(services(request).root)
    try:
        yield work
    finally:
        work.remove()


Server = Annotated[Services, Depends(services)]
Work = Annotated[Workspace, Depends(workspace)]
