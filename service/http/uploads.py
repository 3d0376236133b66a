"""Uploads: saved to the request's workspace off the event loop, checked before a worker sees
them (an EXR's magic number and header against the limits; a mesh's format from its name), and
errors that name the client's file names and form fields, never the server's paths or the
command line's flags."""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import anyio
from fastapi import UploadFile

from gbuffer.exr import read_layout
from gbuffer.limits import Limits
from service.problems import Problem, from_exception

EXR_MAGIC = b"\x76\x2f\x31\x01"
EXR_MEDIA_TYPE = "image/x-exr"
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")
#: The command-line flags that messages shared with the CLI name, as the form fields that do
#: the same over HTTP.
HTTP_WORDS = (
    ("--camera CAM.json", "a camera field (JSON)"),
    ("--normal-space", "the normal_space field"),
    ("--preset", "the preset field"),
    ("--map ", "map field "),
    ("--map", "the map field"),
    ("--light", "scene.lights"),
)


async def save(upload: UploadFile, target: Path) -> int:
    """Copy an upload to ``target`` (off the event loop); its size in bytes."""

    def copy() -> int:
        with open(target, "wb") as out:
            return _copy_file(upload.file, out)

    return await anyio.to_thread.run_sync(copy)


def _copy_file(source: BinaryIO, out: BinaryIO) -> int:
    """All of ``source`` (from its start) into ``out``; the bytes copied. The form parser's
    file is on disk (a part over 1 MiB) or is put there (:meth:`~tempfile.SpooledTemporaryFile.
    fileno`): the kernel copies it (``sendfile``), where reading it through Python's buffers
    took 0.32-0.46 s of a 135 MB upload (each buffer a fresh mapping, faulted in), 0.035-0.052 s
    this way. A file object with no descriptor, or a system whose ``sendfile`` does not copy
    between files, is copied through buffers."""
    try:
        fd = source.fileno()
        source.flush()
        size = os.fstat(fd).st_size
        sent = os.sendfile(out.fileno(), fd, 0, size) if size else 0
    except (OSError, ValueError) as exc:  # (io.UnsupportedOperation is both)
        if getattr(exc, "errno", None) not in _NO_SENDFILE:
            raise
        source.seek(0)
        shutil.copyfileobj(source, out, 1 << 20)
        return out.tell()
    while 0 < sent < size:
        step = os.sendfile(out.fileno(), fd, sent, size - sent)
        if step == 0:  # (the file shrank meanwhile)
            break
        sent += step
    return sent


#: What ``fileno`` or a first ``sendfile`` answer where the kernel cannot copy this way (None:
#: a file object with no descriptor).
_NO_SENDFILE = {None, errno.EINVAL, errno.ENOSYS, errno.ENOTSOCK, errno.EOPNOTSUPP}


def check_exr(path: Path, limits: Limits) -> None:
    """400 when the file is not an EXR or is truncated, 413 when its header is over the limits
    (pixels, decoded bytes, channels): header and offset tables only, no pixel decoded."""
    with open(path, "rb") as f:
        magic = f.read(4)
    if magic != EXR_MAGIC:
        what = "an empty file" if not magic else f"a file starting with {magic.hex(' ')}"
        raise Problem("bad-file", f"{path} is not an OpenEXR file ({what}); send an .exr")
    limits.check(read_layout(path), str(path))


async def receive_exr(upload: UploadFile, target: Path, limits: Limits) -> None:
    """Save the uploaded EXR and check its header, off the event loop, no worker used."""
    await save(upload, target)
    await anyio.to_thread.run_sync(check_exr, target, limits)


def mesh_suffix(upload: UploadFile) -> str:
    """The mesh format of an upload from its file name, or a 415 listing the known ones."""
    suffix = Path(upload.filename or "").suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise Problem(
            "unsupported-media-type",
            f"mesh file name {upload.filename!r} has no known mesh suffix; "
            f"send one of {', '.join(MESH_SUFFIXES)}",
        )
    return suffix


@contextlib.contextmanager
def scrubbed(work: Path, names: dict[Path, str]) -> Iterator[None]:
    """Errors name the client's file names (``names``: server path -> client's name), never the
    server's temporary paths, and the form fields where shared messages name CLI flags."""
    try:
        yield
    except Exception as exc:
        problem = from_exception(exc)
        if problem.kind == "internal":
            raise
        detail = problem.detail
        for path, name in names.items():
            detail = detail.replace(str(path), name)
        detail = detail.replace(f"{work}/", "").replace(str(work), "")
        for flag, field in HTTP_WORDS:
            detail = detail.replace(flag, field)
        raise Problem(
            problem.kind, detail, headers=problem.headers, status=problem.status, **problem.extra
        ) from None
