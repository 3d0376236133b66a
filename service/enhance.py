"""The one enhance path: read a frame, run a compiled pipeline step by step (timed), write it.

``depict enhance``, ``POST /v1/enhance`` (on a worker process) and ``depict batch`` (on Dask
workers) all call :func:`enhance` with the same typed requests, so they write the same bytes for
the same input:

* a :class:`service.pipeline.Pipeline`, parsed and validated once by the front end
  (:func:`service.pipeline.compile`);
* a :class:`ReadRequest`: the preset, a :class:`gbuffer.Camera` overriding the file's, the
  :class:`gbuffer.ReadOptions` (mapping, normals' space) and the decode limits;
* a :class:`WriteRequest`: debug layers, the result layer, a PNG preview instead of the EXR, and
  the input's name recorded in the output.

Python API::

    from service import pipeline
    from service.enhance import ReadRequest, enhance

    result = enhance("shot.exr", "shot_out.exr", pipeline.compile([{"op": "radiance_scaling"}]),
                     ReadRequest(preset="blender"))
    print(result["op_s"])  # [("radiance_scaling", 0.21)]
"""

from __future__ import annotations

import contextvars
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from gbuffer.camera import Camera
from gbuffer.colorspace import View
from gbuffer.frame import Frame
from gbuffer.io import DEFAULT_LAYOUT
from gbuffer.io import read as read_exr
from gbuffer.io import write as write_exr
from gbuffer.limits import Limits
from gbuffer.presets import ReadOptions
from gbuffer.preview import picture, write_png
from service import allocator

if TYPE_CHECKING:  # the operators (and Numba) load when a pipeline runs, not to read a frame
    from service import pipeline


@dataclass(frozen=True)
class ReadRequest:
    """How to read a frame: what ``--preset``, ``--camera``, ``--map`` and ``--normal-space`` (or
    the form fields of the same names) say. ``limits``: what the header may claim (``None``: the
    ``DEPICT_MAX_*`` variables when set)."""

    preset: str = "auto"
    camera: Camera | None = None
    options: ReadOptions = field(default_factory=ReadOptions)
    limits: Limits | None = None

    def read(self, path: str | Path, release: bool = False) -> Frame:
        """The frame in ``path`` (:func:`gbuffer.read`; ``release``: keep no decoded channel
        beside the buffers)."""
        return read_exr(
            path,
            preset=self.preset,
            camera=self.camera,
            options=self.options,
            limits=self.limits,
            release=release,
        )


@dataclass(frozen=True)
class WriteRequest:
    """What to write: intermediate layers too (``debug_layers``), the result layer
    (``output_layer``, :mod:`service.output`), a tone-mapped PNG instead of the EXR (``preview``,
    at ``exposure`` stops, through ``view``: the OCIO config's default display and view unless
    given), and the input's name recorded in the output (``input_name``; default: the name of
    the file read), and where new layers go (``layout``: :data:`gbuffer.io.LAYOUTS`, same part,
    an added part, or a sidecar file with only them)."""

    debug_layers: bool = False
    output_layer: str | None = None
    preview: bool = False
    exposure: float = 0.0
    input_name: str | None = None
    view: View = field(default_factory=View)
    layout: str = DEFAULT_LAYOUT


class Enhanced(TypedDict):
    """What :func:`enhance` did: seconds per step (``op_s``), the image ``size`` (w, h), the
    statistics the operators ``measured`` (to pin them for a sequence), the writer's ``warnings``
    (e.g. a compression it could not keep) and the reader's (``read_warnings``: NaN pixels read
    as holes, ...)."""

    op_s: list[tuple[str, float]]
    size: list[int]
    measured: dict[str, float]
    warnings: list[str]
    read_warnings: list[str]


def enhance(
    in_path: str | Path,
    out_path: str | Path,
    steps: pipeline.Pipeline,
    read: ReadRequest | None = None,
    write: WriteRequest | None = None,
    *,
    pinned: dict[str, float] | None = None,
    files: bool = True,
    ahead: ReadAhead | None = None,
    before_write: Callable[[], None] | None = None,
) -> Enhanced:
    """Read ``in_path``, run ``steps``, write the EXR (or the PNG preview) to ``out_path``.

    ``pinned``: statistics pinned for a sequence (:class:`service.registry.Context`); ``files``:
    whether parameters may name image files on this machine (False for the HTTP service);
    ``ahead``: the read of ``in_path`` already started (:class:`ReadAhead`, with the same
    ``read`` and ``write``); ``before_write``: see :func:`enhance_frame`.
    """
    read, write = read or ReadRequest(), write or WriteRequest()
    if ahead is None:
        ahead = ReadAhead(in_path, read, write)
    elif ahead.path != str(in_path):
        raise ValueError(f"the read started ahead is of {ahead.path}, not of {in_path}")
    frame = ahead.frame()
    return enhance_frame(
        frame, out_path, steps, write, pinned=pinned, files=files, before_write=before_write
    )


class ReadAhead:
    """:func:`read_for` of ``path`` on a thread of its own, started now: the OpenEXR library
    decodes without Python's lock, so what the caller's thread does meanwhile is not waited for
    (``depict enhance`` imports the operators and checks the pipeline). With ``prepare``, Numba's
    start-up runs beside it from now on (:func:`ops.jit.prepare_in_background`), else from
    :meth:`prepare`. :meth:`frame` waits for both and gives the frame, or raises what reading
    raised."""

    def __init__(
        self, path: str | Path, read: ReadRequest, write: WriteRequest, *, prepare: bool = True
    ) -> None:
        self.path = str(path)
        self._read = read
        self._write = write
        self._frame: Frame | None = None
        self._error: BaseException | None = None
        self._prepared: threading.Thread | None = None
        if prepare:
            self.prepare()
        self._ended = threading.Event()  # (see wait)
        context = contextvars.copy_context()  # (the caller's, e.g. NumPy's error state)
        self._thread = threading.Thread(
            target=context.run, args=(self._run,), name="depict-read-ahead", daemon=True
        )
        self._thread.start()

    def prepare(self) -> None:
        """Start Numba's start-up beside the read (once). Only once the caller has imported
        what it imports meanwhile: the start-up imports Numba's modules, and two threads
        importing them at once could meet one of Numba's import cycles half done."""
        if self._prepared is None:
            from ops.jit import prepare_in_background

            self._prepared = prepare_in_background()

    def _run(self) -> None:
        try:
            self._frame = read_for(self.path, self._read, self._write)
        except BaseException as exc:  # (raised again by frame(), on the caller's thread)
            self._error = exc
        finally:
            self._ended.set()

    def wait(self) -> None:
        """Until the read and Numba's start-up have ended. Interrupted (Ctrl-C), it may be
        called again: it waits on an event, as a thread's ``join`` cut short by a signal in
        Python 3.11 later returns at once while the thread still runs (and the read still
        points the terminal elsewhere: :mod:`gbuffer.capture`)."""
        self._ended.wait()
        self._thread.join()
        if self._prepared is not None:
            self._prepared.join()

    def frame(self) -> Frame:
        """The frame read (once: it is let go here), or the error reading raised."""
        self.wait()
        if self._error is not None:
            error, self._error = self._error, None
            raise error
        frame, self._frame = self._frame, None
        if frame is None:
            raise RuntimeError(f"the frame read ahead from {self.path} was taken already")
        return frame


def read_for(in_path: str | Path, read: ReadRequest, write: WriteRequest) -> Frame:
    """The frame in ``in_path`` as :func:`enhance` reads it for ``write``: when the input's parts
    are copied, not encoded (``part``, ``sidecar``), its decoded channels go as the buffers are
    made, and their memory goes back to the system (:func:`service.allocator.release_free`)."""
    release = write.layout != "same" and not write.preview
    frame = read.read(in_path, release=release)
    if release:
        allocator.release_free()
    return frame


def enhance_frame(
    frame: Frame,
    out_path: str | Path,
    steps: pipeline.Pipeline,
    write: WriteRequest,
    *,
    pinned: dict[str, float] | None = None,
    files: bool = True,
    before_write: Callable[[], None] | None = None,
) -> Enhanced:
    """The second half of :func:`enhance`: run ``steps`` on a frame :func:`read_for` read, write
    the result to ``out_path``. Where the input's parts are copied and only the new layers
    encoded (a frame read from a file, ``part`` or ``sidecar``), the frame's buffers are let go
    before it is written (it is used up), and ``before_write`` is called then (``depict enhance``
    starts reading its next input there: the memory the frame held is free)."""
    from service import pipeline
    from service.registry import Context

    context = Context(debug_layers=write.debug_layers, pinned=dict(pinned or {}), files=files)
    uncovered = _nothing_covered(frame)
    ran, op_s = pipeline.run_timed(frame, steps, context)
    out = pipeline.finish(ran, write.output_layer, write.input_name, write.layout)
    h, w = out.shape
    warnings: list[str] = []
    if write.preview:
        write_png(picture(out, "beauty", write.exposure, write.view), out_path)
    else:
        if write.layout != "same" and frame.passthrough.parts:  # the input's parts are copied
            for each in (frame, ran, out):  # and only the new layers encoded: the buffers go
                each.buffers.clear()
            if before_write is not None:
                before_write()
        warnings = write_exr(out, out_path, write.layout)
    return {
        "op_s": op_s,
        "size": [w, h],
        "measured": dict(context.measured),
        "warnings": uncovered + context.warnings + warnings,
        "read_warnings": list(getattr(frame.passthrough, "warnings", [])),
    }


def _nothing_covered(frame: Frame) -> list[str]:
    """A warning when no pixel of ``frame`` is covered (depth everywhere 0, negative or
    infinite, no surface in the coverage): the operators can change nothing."""
    if "depth" not in frame.buffers and "coverage" not in frame.buffers:
        return []
    if bool(np.any(frame.mask > 0)):
        return []
    return [
        "no pixel is covered (no finite, positive depth on a surface): the operators changed "
        "nothing; check the depth channel (--map depth=...) and its background value"
    ]
