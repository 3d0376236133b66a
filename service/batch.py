"""``depict batch``: frame sequences on a Dask cluster, with farm conventions.

Patterns name one file per frame with a frame token:

* ``####`` (or any run of ``#``): the frame, zero-padded to the run's length (``####`` -> 0007);
* ``@`` (or a run of ``@``): the same, padded to the run's length (``@`` -> 7, ``@@@`` -> 007);
* ``%04d``, ``%d``: printf style.

``--frames`` takes ranges with steps and lists: ``1-100``, ``1-100x2`` (every 2nd), ``1,5,9``,
``1-10,20-30x5``. Without it, the frames are those whose input file exists.

Workers receive paths, not pixels: each task reads its input, runs the pipeline and writes its
output. Statistics-dependent parameters (white levels, normalisations: what operators record in
:attr:`service.registry.Context.measured`) are measured once, on the first frame processed, and
pinned for every other frame, so the sequence does not flicker; ``--pinned FILE`` stores them (or
reuses them when FILE exists) so several runs (farm chunks) share them. While the first frame
measures them, each other worker reads the next frame ahead (it stays in that worker's memory and
is enhanced there once the statistics are known).

Without ``--scheduler`` the frames run on a local Dask cluster with one single-threaded worker
process per core (``--workers N`` to change); with ``--scheduler tcp://HOST:8786`` on an existing
Dask distributed cluster (``dask scheduler`` + ``dask worker tcp://HOST:8786`` with the same
Depict installed and the files on a shared path).

Render farms (one task per chunk of frames)
-------------------------------------------

Measure the statistics once, before the chunks, then let every chunk reuse them::

    # pre-task (Deadline: a "pre job script" or a first one-frame job; OpenCue: a first layer)
    depict batch shot.####.exr -o out/shot.####.exr --frames 1 --pinned out/shot.pins.json
    # per chunk (Deadline "Command Line" job, chunk size 10)
    depict batch shot.####.exr -o out/shot.####.exr --frames <STARTFRAME>-<ENDFRAME> \\
        --pinned out/shot.pins.json --skip-existing --workers 1
    # OpenCue: the same command with --frames #FRAME_START#-#FRAME_END# and a chunk size

A chunk's exit status is 0 only when all its frames were written (or skipped), so the farm
retries failed chunks; ``--skip-existing`` makes the retry cheap.
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import re
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from multiprocessing import resource_tracker
from pathlib import Path
from typing import Any

import numpy as np
from distributed import Client, Future, LocalCluster, as_completed, wait
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from gbuffer.atomic import atomic_path, output_target, partial_files, read_text
from gbuffer.errors import FrameError, OutputError
from gbuffer.exr import read_layout
from gbuffer.frame import Frame
from service import allocator
from service.enhance import ReadRequest, WriteRequest, enhance_frame, read_for
from service.pipeline import Pipeline
from service.problems import from_exception
from service.signals import sigint_held

_TOKEN = re.compile(r"#+|@+|%(0?)(\d*)d")

#: Most frames one ``depict batch`` run takes (``--frames`` is checked before it is expanded).
MAX_FRAMES = 100_000


class BatchError(ValueError):
    """A bad pattern, frame range or option; the message says which."""


# -- patterns and frame ranges -----------------------------------------------------------------


def _token(pattern: str) -> re.Match[str]:
    matches = list(_TOKEN.finditer(pattern))
    if not matches:
        raise BatchError(
            f"pattern {pattern!r} has no frame token; use #### (padded), @ or %04d, "
            "e.g. shot.####.exr"
        )
    if len(matches) > 1:
        raise BatchError(f"pattern {pattern!r} has {len(matches)} frame tokens; use exactly one")
    return matches[0]


def expand(pattern: str, frame: int) -> str:
    """The file name of ``frame``: ``expand("shot.####.exr", 7) == "shot.0007.exr"``."""
    m = _token(pattern)
    text = m.group(0)
    if text[0] in "#@":
        width = len(text)
    else:
        width = int(m.group(2) or 0)
    number = f"{frame:0{width}d}" if frame >= 0 else f"-{-frame:0{width}d}"
    return pattern[: m.start()] + number + pattern[m.end() :]


def parse_frames(text: str) -> list[int]:
    """Frames of ``1-100x2,120,130-140``: ranges (inclusive) with an optional step, in order."""
    frames: list[int] = []
    count = 0
    for raw in text.split(","):
        part = raw.strip()
        m = re.fullmatch(r"(-?\d+)(?:\s*-\s*(-?\d+)(?:\s*[x:by]+\s*(\d+))?)?", part)
        if not m:
            raise BatchError(
                f"--frames {text!r}: {part!r} is not FRAME, FIRST-LAST or FIRST-LASTxSTEP"
            )
        first = int(m.group(1))
        last = int(m.group(2)) if m.group(2) is not None else first
        step = int(m.group(3)) if m.group(3) is not None else 1
        if step < 1:
            raise BatchError(f"--frames {text!r}: step must be >= 1, got {step}")
        if last < first:
            raise BatchError(f"--frames {text!r}: range {part!r} ends before it starts")
        count += (last - first) // step + 1
        if count > MAX_FRAMES:
            raise BatchError(
                f"--frames {text!r} names more than {MAX_FRAMES} frames; split the sequence"
            )
        frames.extend(range(first, last + 1, step))
    return list(dict.fromkeys(frames))  # first occurrence of each frame, in order


def find_frames(pattern: str) -> list[int]:
    """Frames whose file exists for ``pattern`` (sorted; padding must match the pattern's)."""
    m = _token(pattern)
    prefix, suffix = pattern[: m.start()], pattern[m.end() :]
    rx = re.compile(re.escape(prefix) + r"(-?\d+)" + re.escape(suffix))
    found = set()
    for path in glob.glob(glob.escape(prefix) + "*" + glob.escape(suffix)):
        hit = rx.fullmatch(path)
        if hit and expand(pattern, int(hit.group(1))) == path:
            found.add(int(hit.group(1)))
    return sorted(found)


def check_sequence_outputs(
    in_pattern: str, out_pattern: str, frames: Sequence[int], pinned: str | Path | None = None
) -> None:
    """BatchError when an output frame (or the pinned statistics file) would replace an input
    frame of the sequence (same path after resolving links, or the same inode), or a special
    file; compared as files, whatever the patterns' spelling. Every frame of the sequence on
    disk counts, not only those of this run: a farm's chunk must not write over the input of
    another chunk (through a link left in the output folder)."""
    inputs = [expand(in_pattern, f) for f in sorted(set(frames) | set(find_frames(in_pattern)))]
    names = {os.path.realpath(p) for p in inputs}
    inodes = set()
    for path in inputs:
        try:
            st = os.stat(path)
        except OSError:
            continue
        inodes.add((st.st_dev, st.st_ino))
    outputs: list[tuple[int | None, str]] = [(f, expand(out_pattern, f)) for f in frames]
    if pinned:
        outputs.append((None, str(pinned)))
    for frame, path in outputs:
        try:
            output_target(path)
        except OutputError as exc:
            raise BatchError(str(exc)) from None
        try:
            st = os.stat(path)
            same_inode = (st.st_dev, st.st_ino) in inodes
        except OSError:
            same_inode = False
        if os.path.realpath(path) in names or same_inode:
            what = f"frame {frame}'s output" if frame is not None else "--pinned"
            raise BatchError(
                f"{what} {path} is an input frame of {in_pattern}: it would be overwritten; "
                "write elsewhere"
            )


# -- one frame, on a worker --------------------------------------------------------------------


def process_frame(
    frame: int,
    in_path: str,
    out_path: str,
    steps: Pipeline,
    read: ReadRequest,
    write: WriteRequest,
    pinned: dict[str, float],
    fetched: Frame | dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Enhance one frame (on a Dask worker), read here or already by :func:`prefetch_frame`
    (``fetched``: the frame, or the failure it read). Never raises: failures come back as
    data."""
    allocator.tune()
    t0 = time.perf_counter()
    if isinstance(fetched, dict):
        return fetched
    try:
        loaded = fetched if fetched is not None else read_for(in_path, read, write)
        out = enhance_frame(loaded, out_path, steps, write, pinned=pinned)
        return {
            "frame": frame,
            "status": "done",
            "measured": out["measured"],
            "warnings": out["warnings"],
            "seconds": time.perf_counter() - t0,
        }
    except Exception as exc:  # one bad frame must not stop the sequence
        return _failure(frame, exc, t0)


def prefetch_frame(
    frame: int, in_path: str, read: ReadRequest, write: WriteRequest
) -> Frame | dict[str, Any]:
    """Read a frame on a worker that would wait while the first frame measures the statistics
    (the frame stays in that worker's memory for :func:`process_frame`); a failure as data."""
    allocator.tune()
    t0 = time.perf_counter()
    try:
        return read_for(in_path, read, write)
    except Exception as exc:
        return _failure(frame, exc, t0)


def _failure(frame: int, exc: Exception, t0: float) -> dict[str, Any]:
    problem = from_exception(exc)
    detail = problem.detail if problem.kind != "internal" else f"{type(exc).__name__}: {exc}"
    return {
        "frame": frame,
        "status": "failed",
        "error": detail,
        "seconds": time.perf_counter() - t0,
    }


# -- the sequence ------------------------------------------------------------------------------


@dataclass
class Summary:
    """What a batch did: frames done, skipped and failed (frame -> message), pinned statistics,
    the writer's warnings (message -> frames)."""

    done: list[int] = field(default_factory=list)
    skipped: list[int] = field(default_factory=list)
    failed: dict[int, str] = field(default_factory=dict)
    pinned: dict[str, float] = field(default_factory=dict)
    seconds: float = 0.0
    warnings: dict[str, list[int]] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.failed

    def record(self, result: dict[str, Any]) -> None:
        """Count one frame's result (from :func:`process_frame`)."""
        if result["status"] == "done":
            self.done.append(result["frame"])
            for warning in result.get("warnings", []):
                self.warnings.setdefault(warning, []).append(result["frame"])
        else:
            self.failed[result["frame"]] = result.get("error", "failed")


def _close(client: Any, cluster: Any) -> None:
    """Close the client, and the cluster when it is this run's own."""
    client.close()
    if cluster is not None:
        cluster.close()


def _load_pinned(path: Path) -> dict[str, float]:
    try:
        data = json.loads(read_text(path))
    except (OSError, ValueError) as exc:  # (not UTF-8, not JSON, a number too long)
        why = (exc.strerror if isinstance(exc, OSError) else None) or exc
        raise BatchError(f"cannot read pinned statistics {path}: {why}") from None
    if not isinstance(data, dict) or not all(_statistic(v) for v in data.values()):
        raise BatchError(  # (true was taken as 1, 1e308 became inf in float32, and 0 or -1
            # failed every frame, naming an operator's inner parameter)
            f"pinned statistics {path} must be a JSON object of numbers (white levels, sizes), "
            "each positive and finite in float32 (not true or false)"
        )
    return {str(k): float(v) for k, v in data.items()}


def _whole_exr(path: str) -> bool:
    """Whether ``path`` is an EXR file whose headers, chunk tables and last chunk are all
    there: ``--skip-existing`` makes a cut-off output again (an empty or truncated one counted
    as done)."""
    if not os.path.exists(path):
        return False
    try:
        read_layout(path)
    except FrameError:
        return False
    return True


def _statistic(value: object) -> bool:
    """Whether a pinned value is a number the operators can use: every statistic they measure
    (white levels, sizes, norms) is positive, finite in float32. (Compared as it is: float() of
    a 400-digit integer raised OverflowError, a traceback.)"""
    return (
        isinstance(value, int | float)
        and not isinstance(value, bool)
        and _FLOAT32_TINY <= value <= _FLOAT32_MAX
    )


#: float32's limits, as Python floats (numbers of any size compare with them exactly); numpy's:
#: the front ends do not import ``ops``, where the operators' are.
_FLOAT32_TINY = float(np.finfo(np.float32).tiny)
_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _cluster(scheduler: str | None, workers: int | None) -> tuple[Client, LocalCluster | None]:
    """A Dask client on ``scheduler``, or on a new local cluster (returned to be closed)."""
    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except OSError as exc:
            raise BatchError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None
    n = workers or os.cpu_count() or 1
    cluster: LocalCluster | None = None
    try:
        with _sigint_ignored():  # (what the worker processes start with: Ctrl-C is ours)
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                scheduler_kwargs={"dashboard_address": ":0"},  # its health routes: any port
                # logging.CRITICAL: what failed is in the summary, frame by frame; distributed's
                # ERROR lines were its shutdown races after a Ctrl-C (a worker's heartbeat to the
                # scheduler just closed), with a traceback
                silence_logs=50,
            )
        return Client(cluster), cluster
    except BaseException:  # (a Ctrl-C held while the workers started comes as the hold ends)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close()
        raise


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while the local cluster starts its processes, which keep that (Python
    does not install its Ctrl-C handler where SIGINT is ignored): Ctrl-C in a terminal, sent to
    every process of the group, stops the batch through this process, which closes the
    cluster, instead of printing each worker's KeyboardInterrupt traceback.

    A Ctrl-C meanwhile is held, not lost (:func:`service.signals.sigint_held`: the threads
    started before it, the command line's, block SIGINT from their start). multiprocessing's
    resource tracker is started first: starting it unblocks SIGINT in the thread that does
    (CPython's bpo-33613 mask), and a thread that does not block it would drop it."""
    if threading.current_thread() is threading.main_thread():
        resource_tracker.ensure_running()
    with sigint_held(ignored=True):
        yield


@dataclass
class _Run:
    """One sequence on a Dask client: frames submitted as tasks, results counted."""

    client: Client
    in_pattern: str
    out_pattern: str
    steps: Pipeline
    read: ReadRequest
    write: WriteRequest
    summary: Summary

    def submit(self, f: int, pins: dict[str, float], fetched: Future | None = None) -> Future:
        """Frame ``f`` as a task; on the worker that holds it when it was read ahead."""
        where = None
        if fetched is not None:
            wait([fetched])
            where = list(self.client.who_has([fetched]).get(fetched.key, ())) or None
        return self.client.submit(
            process_frame,
            f,
            expand(self.in_pattern, f),
            expand(self.out_pattern, f),
            self.steps,
            self.read,
            self.write,
            pins,
            fetched,
            key=f"depict-frame-{f}-{os.urandom(4).hex()}",
            pure=False,
            workers=where,
            # a lost worker: the frame is read again elsewhere, nobody waits for it
            allow_other_workers=where is not None,
        )

    def prefetch(self, f: int) -> Future:
        return self.client.submit(
            prefetch_frame,
            f,
            expand(self.in_pattern, f),
            self.read,
            self.write,
            key=f"depict-read-{f}-{os.urandom(4).hex()}",
            pure=False,
        )

    @staticmethod
    def gather(future: Future, f: int) -> dict[str, Any]:
        try:
            return dict(future.result())
        except Exception as exc:  # worker died, cancelled, ...
            return {"frame": f, "status": "failed", "error": f"{type(exc).__name__}: {exc}"}

    def frames(
        self,
        todo: list[int],
        pinned: dict[str, float] | None,
        pinned_path: Path | None,
        bar: Progress,
    ) -> dict[str, float] | None:
        """Run ``todo``: frames one by one until one measures the statistics (unless
        ``pinned``), the next frames read meanwhile by the other workers, then the others at once
        with them pinned. Returns the pinned statistics."""
        task = bar.add_task("frames", total=len(todo), failed=0)

        def record(result: dict[str, Any]) -> None:
            self.summary.record(result)
            bar.update(task, advance=1, failed=len(self.summary.failed))

        queue = list(todo)
        ahead = max(0, len(self.client.scheduler_info()["workers"]) - 1)
        fetched: dict[int, Future] = {}
        while pinned is None and queue:  # sample frames one by one until one succeeds
            f = queue.pop(0)
            for g in queue[:ahead]:  # read by the workers that would wait meanwhile
                fetched.setdefault(g, self.prefetch(g))
            result = self.gather(self.submit(f, {}, fetched.pop(f, None)), f)
            record(result)
            if result["status"] == "done":
                pinned = dict(result.get("measured") or {})
                if pinned_path is not None:
                    with atomic_path(pinned_path) as tmp:
                        tmp.write_text(json.dumps(pinned, indent=2, sort_keys=True))
        futures = {self.submit(f, pinned or {}, fetched.pop(f, None)): f for f in queue}
        for future in as_completed(futures):
            record(_unpinned(self.gather(future, futures[future]), pinned or {}, pinned_path))
        return pinned


def _unpinned(
    result: dict[str, Any], pinned: dict[str, float], pinned_path: Path | None
) -> dict[str, Any]:
    """``result`` with a warning when its frame measured a statistic the pins lack (a stale or
    hand-edited ``--pinned`` file): measured on each frame, it would flicker along the
    sequence."""
    stray = sorted(set(result.get("measured") or {}) - set(pinned))
    if result["status"] != "done" or not stray:
        return result
    where = f"the pinned statistics {pinned_path}" if pinned_path else "the first frame's"
    warning = (
        f"statistics measured on each frame, not pinned: {', '.join(stray)} ({where} lack "
        f"{'it' if len(stray) == 1 else 'them'}"
        f"{'; delete the file to measure them again' if pinned_path else ''})"
    )
    return {**result, "warnings": [*result.get("warnings", []), warning]}


def _progress(enabled: bool) -> Progress:
    """The progress bar: frames done of all, failures, time spent and left."""
    columns = (
        TextColumn("[bold]depict batch"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[failed]} failed"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    return Progress(*columns, disable=not enabled, transient=False)


def _checked_frames(
    in_pattern: str, out_pattern: str, frames: Sequence[int] | None, pinned_file: str | Path | None
) -> list[int]:
    """The frames to consider, the patterns and outputs checked (BatchError before any work)."""
    _token(in_pattern)
    _token(out_pattern)
    if in_pattern == out_pattern:
        raise BatchError("the output pattern is the input pattern; write elsewhere")
    frame_list = list(frames) if frames is not None else find_frames(in_pattern)
    if not frame_list:
        raise BatchError(f"no frames: no file matches {in_pattern!r} (or pass --frames)")
    check_sequence_outputs(in_pattern, out_pattern, frame_list, pinned_file)
    return frame_list


def _remove_partials(cluster: object | None, out_pattern: str, frames: Sequence[int]) -> None:
    """The temporary files of ``frames``' outputs removed, once the batch's own workers
    (``cluster``) are closed: each is what a worker was writing when it stopped (a Ctrl-C, or a
    worker killed mid-write, whose frame another worker wrote again). The workers of a cluster
    given by its address may still be writing: theirs are left."""
    if cluster is None:
        return
    for partial in partial_files(expand(out_pattern, f) for f in frames):
        partial.unlink(missing_ok=True)


def run_batch(
    in_pattern: str,
    out_pattern: str,
    *,
    steps: Pipeline,
    frames: Sequence[int] | None = None,
    read: ReadRequest | None = None,
    write: WriteRequest | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    skip_existing: bool = False,
    pinned_file: str | Path | None = None,
    progress: bool = True,
) -> Summary:
    """Enhance every frame of a sequence on a Dask cluster; see the module docstring.

    ``steps``: the compiled pipeline (:func:`service.pipeline.compile`). ``read``/``write``: as
    for :func:`service.enhance.enhance`. The first frame to process is run alone to measure the
    statistics that are then pinned for all others (unless ``pinned_file`` already exists).
    """
    frame_list = _checked_frames(in_pattern, out_pattern, frames, pinned_file)
    summary = Summary()
    t_start = time.perf_counter()
    todo = []
    for f in frame_list:
        if skip_existing and _whole_exr(expand(out_pattern, f)):
            summary.skipped.append(f)
        else:
            todo.append(f)
    pinned_path = Path(pinned_file) if pinned_file else None
    pinned: dict[str, float] | None = None
    if pinned_path is not None and pinned_path.exists():
        pinned = _load_pinned(pinned_path)
    if todo:
        client, cluster = _cluster(scheduler, workers)
        run = _Run(
            client,
            in_pattern,
            out_pattern,
            steps,
            read or ReadRequest(),
            write or WriteRequest(),
            summary,
        )
        try:
            with _progress(progress) as bar:
                pinned = run.frames(todo, pinned, pinned_path, bar)
        except BaseException:  # stopped (Ctrl-C, a signal): frames being written stay unwritten
            with contextlib.suppress(Exception):  # (the stop, not this, is what to report)
                _close(client, cluster)
            raise
        else:
            _close(client, cluster)
        finally:  # (a stop's frames, or a worker's lost while it wrote one)
            _remove_partials(cluster, out_pattern, todo)
    summary.done.sort()
    summary.failed = dict(sorted(summary.failed.items()))
    summary.pinned = pinned or {}
    summary.seconds = time.perf_counter() - t_start
    return summary
