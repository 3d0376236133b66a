"""The viewer's frames: EXR uploads kept on disk under the server's working directory, so that a
user tunes operators on one frame without sending it again for every preview.

Each frame is a folder ``<root>/<id>/`` holding the upload (``in.exr``) and what the previews
cache beside it (the downscaled copies, :mod:`service.viewer.work`). A frame lives
``ttl_s`` seconds after its last use; the store holds at most ``max_bytes`` of frames on disk
(uploads and their copies, counted again as each frame's jobs end: :meth:`FrameStore.job`) and
``max_frames`` frames, the least recently used going first when a frame would pass either
limit. Expired frames are removed on every store operation, so no background task is needed.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import secrets
import shutil
import time
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gbuffer.atomic import partial_files_in
from service.enhance import ReadRequest
from service.problems import Problem

#: What a frame id looks like (ids are random, 128 bits, URL-safe).
ID_PATTERN = r"^[A-Za-z0-9_-]{16,64}$"
_ID = re.compile(ID_PATTERN)


@dataclass
class StoredFrame:
    """One uploaded frame: its folder, the client's file name, how to read it, its bytes on
    disk, what ``inspect`` found, the number of the latest preview asked for (older ones are
    dropped), the lock that lets one preview of it run at a time and how many jobs on its folder
    are running."""

    id: str
    folder: Path
    name: str
    read: ReadRequest
    size_bytes: int
    info: dict[str, Any] = field(default_factory=dict)
    last_used: float = field(default_factory=time.monotonic)
    latest_preview: int = 0
    previewing: asyncio.Lock = field(default_factory=asyncio.Lock)
    jobs: int = 0

    @property
    def source(self) -> Path:
        """The uploaded EXR."""
        return self.folder / "in.exr"


class FrameStore:
    """Frames by id, least recently used first; see the module docstring for the limits."""

    def __init__(self, root: Path, ttl_s: float, max_bytes: int, max_frames: int) -> None:
        self.root = root
        self.ttl_s = ttl_s
        self.max_bytes = max_bytes
        self.max_frames = max_frames
        self._frames: OrderedDict[str, StoredFrame] = OrderedDict()

    @contextlib.contextmanager
    def new_folder(self) -> Iterator[tuple[str, Path]]:
        """A fresh id and its (empty) folder, for a frame being received; the folder is removed
        when the block fails."""
        frame_id = secrets.token_urlsafe(16)
        folder = self.root / frame_id
        folder.mkdir(parents=True)
        try:
            yield frame_id, folder
        except BaseException:
            self.discard(folder)
            raise

    def admit(self, frame: StoredFrame) -> None:
        """Keep ``frame`` (its folder holds the checked upload and the copies its inspection
        made; ``size_bytes`` is set from them): 413 when it alone is over the size cap, else
        older frames are evicted until it fits."""
        self.expire()
        frame.size_bytes = folder_bytes(frame.folder)
        if frame.size_bytes > self.max_bytes:
            self.discard(frame.folder)
            raise Problem(
                "limit",
                f"the frame and its preview copy are {frame.size_bytes / 2**20:.1f} MiB; the "
                f"viewer keeps at most {self.max_bytes / 2**20:.0f} MiB of frames "
                "(DEPICT_VIEWER_MAX_MB)",
            )
        self._frames[frame.id] = frame
        self._evict()

    def _evict(self) -> None:
        """The least recently used frames removed while the store is over a cap; never the most
        recently used one (the frame just kept, or the one the user works on), nor one a job is
        running on (it goes when its jobs end, if the store is still over then)."""
        while len(self._frames) > self.max_frames or self.used_bytes > self.max_bytes:
            newest = next(reversed(self._frames.values()))
            idle = (f for f in self._frames.values() if f is not newest and f.jobs == 0)
            oldest = next(idle, None)
            if oldest is None:
                return
            del self._frames[oldest.id]
            self.discard(oldest.folder)

    @contextlib.contextmanager
    def job(self, frame: StoredFrame) -> Iterator[None]:
        """A job that writes into ``frame``'s folder (the copies previews run on). When the last
        of the frame's running jobs ends: the temporary files a worker killed while it wrote left
        there are removed, and the frame's bytes are counted again (older frames evicted past the
        cap); a frame forgotten meanwhile (deleted, expired, evicted) has its folder removed
        again, since the job may have made it anew, and a job that failed then is answered 404
        (what it lacked was the frame, not anything the client sent)."""
        frame.jobs += 1
        try:
            yield
        except Exception:
            if self._frames.get(frame.id) is frame:
                raise
            raise Problem(
                "not-found",
                f"the frame {frame.id!r} was forgotten while this job ran on it (deleted, or "
                "gone past the viewer's limits); upload it again with POST /v1/frames",
            ) from None
        finally:
            frame.jobs -= 1
            if frame.jobs == 0 and self._frames.get(frame.id) is not frame:
                self.discard(frame.folder)
            elif frame.jobs == 0:
                for partial in partial_files_in(frame.folder):
                    partial.unlink(missing_ok=True)
                frame.size_bytes = folder_bytes(frame.folder)
                self._evict()

    def get(self, frame_id: str) -> StoredFrame:
        """The frame ``frame_id``, now the most recently used; 404 when unknown or expired."""
        self.expire()
        frame = self._frames.get(frame_id) if _ID.match(frame_id) else None
        if frame is None:
            raise Problem(
                "not-found",
                f"no frame {frame_id!r} on this server (frames are kept {self.ttl_s:g} s after "
                "their last use); upload it again with POST /v1/frames",
            )
        frame.last_used = time.monotonic()
        self._frames.move_to_end(frame_id)
        return frame

    def remove(self, frame_id: str) -> None:
        """Forget the frame ``frame_id`` and delete its folder (404 when unknown)."""
        frame = self.get(frame_id)
        del self._frames[frame.id]
        self.discard(frame.folder)

    def expire(self) -> None:
        """Remove the frames unused for ``ttl_s`` seconds."""
        now = time.monotonic()
        for frame_id in [k for k, f in self._frames.items() if now - f.last_used > self.ttl_s]:
            self.discard(self._frames.pop(frame_id).folder)

    @property
    def used_bytes(self) -> int:
        return sum(f.size_bytes for f in self._frames.values())

    def __len__(self) -> int:
        return len(self._frames)

    def __contains__(self, frame_id: object) -> bool:
        return frame_id in self._frames

    @staticmethod
    def discard(folder: Path) -> None:
        shutil.rmtree(folder, ignore_errors=True)


def folder_bytes(folder: Path) -> int:
    """The bytes of the files in a frame's ``folder`` (0 when it is gone)."""
    total = 0
    with contextlib.suppress(FileNotFoundError), os.scandir(folder) as entries:
        for entry in entries:
            with contextlib.suppress(FileNotFoundError):
                if entry.is_file(follow_symlinks=False):
                    total += entry.stat(follow_symlinks=False).st_size
    return total
