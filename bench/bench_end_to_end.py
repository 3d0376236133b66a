"""Benchmark: a frame where users meet it, against an ``oiiotool`` copy of the same file, same run.

Run: ``.venv/bin/python -m bench.bench_end_to_end [enhance] [http] [batch] [pipeline]`` (all of
them by default; part of ``make bench``). Two 1920x1080 frames,
made once and kept in ``.bench-cache/`` (git-ignored):

* a Blender Cycles multilayer EXR (``corpus/spot.py`` at 4 samples: every pass Depict reads,
  32-bit float, ZIP), rendered with Debian's ``blender`` when it is installed (else the row is
  skipped, saying so);
* Depict's own render of ``examples/spot.obj`` (``depict render``: half/float channels, ZIP).

Rows, each a ratio to its reference measured just before or after it:

* ``depict enhance IN -o OUT`` (defaults: Radiance Scaling; a new process, start-up included) vs
  ``oiiotool IN -o OUT`` (OpenImageIO's copy: decode every channel, encode every channel), for
  each ``--layout``; also the output's size and the peak memory of ``depict enhance`` against the
  decoded size of the buffers it reads plus the layers it writes; the same for Light Alignment
  and unsharp masking alone (``--op``, layout ``part``, no target); and ``depict enhance`` of 4
  files in one process vs 4 oiiotool copies;
* the HTTP service (``depict serve``, 2 workers, 2 clients) vs 2 ``oiiotool`` copies in parallel
  (throughput);
* ``depict batch`` of 8 frames (2 workers) vs 8 ``oiiotool`` copies on 2 processes (throughput);
* ``pipeline.run`` of curvature, Radiance Scaling and Light Alignment on a fully covered 1080p
  frame, in ratio to a memory-bound copy (``bench.common``) measured just before each run (the
  median of the runs' ratios: ``Report.paired``); then, without a target, what their defaults
  add to the papers' operators: Radiance Scaling without the kept lighting and with the paper's
  preset, Light Alignment without the kept lighting, in the relight form and with the paper's
  preset; and the three operators' defaults on the Cycles frame as read (no target: a
  renderer's frame, with background, a floor and a transmission pass with no light in it).

Targets (issue 20): enhance <= 1.0x oiiotool; HTTP and batch >= 0.8x its throughput;
curvature <= 6x, Radiance Scaling <= 10x, Light Alignment <= 60x a copy; peak memory <= 2x.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np

from bench.common import HD, Report
from gbuffer.frame import Frame

ROOT = Path(__file__).resolve().parent.parent
CACHE = ROOT / ".bench-cache"
BIN = Path(sys.executable).parent
DEPICT = str(BIN / "depict")
OIIOTOOL = str(BIN / "oiiotool") if (BIN / "oiiotool").exists() else shutil.which("oiiotool")
REPEAT = int(os.environ.get("DEPICT_BENCH_REPEAT", "3"))
LAYOUTS = ("same", "part", "sidecar")


def cycles_frame() -> Path | None:
    """The Cycles 1080p frame (rendered once with Blender), or None without Blender."""
    path = CACHE / "cycles_spot_1080.exr"
    if path.exists():
        return path
    blender = shutil.which("blender")
    if blender is None:
        return None
    CACHE.mkdir(exist_ok=True)
    args = ["--out", str(CACHE), "--name", path.stem, "--width", "1920", "--height", "1080"]
    script = str(ROOT / "corpus" / "spot.py")
    cmd = [blender, "-b", "--factory-startup", "--python", script, "--", *args, "--samples", "4"]
    subprocess.run(cmd, check=True, capture_output=True)
    return path


def depict_frame() -> Path:
    """Depict's own 1080p render of examples/spot.obj (made once)."""
    path = CACHE / "depict_spot_1080.exr"
    if not path.exists():
        CACHE.mkdir(exist_ok=True)
        mesh = str(ROOT / "examples" / "spot.obj")
        cmd = [DEPICT, "render", mesh, "--width", "1920", "--height", "1080", "-o", str(path)]
        subprocess.run(cmd, check=True, capture_output=True)
    return path


def timed(cmd: Sequence[str]) -> tuple[float, int]:
    """Seconds and peak resident memory (bytes) of one run of ``cmd``.

    The peak is the child's own ``VmHWM``, polled while it runs: ``ru_maxrss`` of a child
    counts the resident memory of this (large) process at the fork."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    peak = [0]
    watcher = threading.Thread(target=_watch_peak, args=(proc, peak))
    watcher.start()
    _, err = proc.communicate()
    seconds = time.perf_counter() - t0
    watcher.join()
    if proc.returncode != 0:
        text = err.decode(errors="replace").strip()[-400:]
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {text}")
    return seconds, peak[0]


def _watch_peak(proc: subprocess.Popen[bytes], peak: list[int]) -> None:
    status = Path(f"/proc/{proc.pid}/status")
    while proc.poll() is None:
        try:
            for line in status.read_text().splitlines():
                if line.startswith("VmHWM:"):
                    peak[0] = max(peak[0], int(line.split()[1]) * 1024)
        except (OSError, ValueError):
            pass
        time.sleep(0.02)


def paired_runs(cmd: Sequence[str], ref: Sequence[str], repeat: int = REPEAT) -> tuple[float, ...]:
    """``cmd`` and ``ref`` run in turn ``repeat`` times (after one warm-up each), so that both
    see the same load: median seconds of each, median of their ratios, largest peak memory of
    ``cmd``."""
    timed(ref)
    timed(cmd)
    pairs = [(timed(cmd), timed(ref)) for _ in range(repeat)]
    seconds = statistics.median(c[0] for c, _ in pairs)
    ref_seconds = statistics.median(r[0] for _, r in pairs)
    ratio = statistics.median(c[0] / r[0] for c, r in pairs)
    return seconds, ref_seconds, ratio, max(c[1] for c, _ in pairs)


def parallel_rate(job: Callable[[int], object], jobs: int, workers: int) -> float:
    """Jobs per second of ``jobs`` calls of ``job`` on ``workers`` threads."""
    t0 = time.perf_counter()
    with ThreadPoolExecutor(workers) as pool:
        list(pool.map(job, range(jobs)))
    return jobs / (time.perf_counter() - t0)


def oiio_copy(src: Path, dst: Path) -> None:
    assert OIIOTOOL is not None
    subprocess.run([OIIOTOOL, str(src), "-o", str(dst)], check=True, capture_output=True)


def decoded_bytes(path: Path, op: str | None = None) -> tuple[int, int]:
    """Bytes of the buffers ``depict enhance`` reads from ``path`` and of the layers it writes
    (float32; the default pipeline, or operator ``op`` with its defaults)."""
    from gbuffer.io import read
    from service import pipeline

    frame = read(path)
    steps = pipeline.DEFAULT if op is None else [{"op": op}]
    out = pipeline.finish(pipeline.run(frame, steps))
    reads = sum(a.nbytes for a in frame.buffers.values())
    writes = sum(np.asarray(a).nbytes for a in out.outputs.values())
    return reads, writes


def enhance_rows(name: str, path: Path, work: Path) -> None:
    """``depict enhance`` in each layout vs an oiiotool copy; output sizes; peak memory."""
    copy = [OIIOTOOL or "oiiotool", str(path), "-o", str(work / "copy.exr")]
    print(f"-- {name}: {path.name}, {path.stat().st_size / 1e6:.0f} MB")
    reads, writes = decoded_bytes(path)
    for layout in LAYOUTS:
        out = work / f"out_{layout}.exr"
        cmd = [DEPICT, "enhance", str(path), "-o", str(out), "--layout", layout]
        seconds, oiio_s, ratio, peak = paired_runs(cmd, copy)
        size = out.stat().st_size / 1e6
        verdict = "ok" if ratio <= 1.0 else "OVER"
        print(
            f"depict enhance --layout {layout:<8s} {seconds:6.2f} s, oiiotool {oiio_s:5.2f} s: "
            f"{ratio:5.2f}x (target <= 1.0x: {verdict}); output {size:.0f} MB; "
            f"peak {peak / 2**20:.0f} MiB = {peak / (reads + writes):.2f}x the decoded "
            f"reads {reads / 2**20:.0f} MiB + writes {writes / 2**20:.0f} MiB"
        )


#: Operators run alone through ``depict enhance --op`` (rows without a target: the defaults are
#: Radiance Scaling's).
OTHER_OPS = ("light_alignment", "unsharp_masking")


def other_op_rows(path: Path, work: Path) -> None:
    """``depict enhance --op OP`` (layout ``part``) vs an oiiotool copy, and its peak memory."""
    copy = [OIIOTOOL or "oiiotool", str(path), "-o", str(work / "copy.exr")]
    for op in OTHER_OPS:
        reads, writes = decoded_bytes(path, op)
        cmd = [DEPICT, "enhance", str(path), "-o", str(work / f"out_{op}.exr"), "--op", op]
        seconds, oiio_s, ratio, peak = paired_runs(cmd, copy)
        print(
            f"depict enhance --op {op:<16s} {seconds:6.2f} s, oiiotool {oiio_s:5.2f} s: "
            f"{ratio:5.2f}x; peak {peak / 2**20:.0f} MiB = {peak / (reads + writes):.2f}x the "
            f"decoded reads {reads / 2**20:.0f} MiB + writes {writes / 2**20:.0f} MiB"
        )


def several_row(path: Path, work: Path, files: int = 4) -> None:
    """``depict enhance`` of ``files`` copies of a frame in one process vs as many oiiotool
    copies one after the other."""
    src, out = work / f"several_{path.stem}", work / f"several_out_{path.stem}"
    src.mkdir(exist_ok=True)
    out.mkdir(exist_ok=True)
    names = []
    for i in range(files):
        link = src / f"f{i}.exr"
        if not link.exists():
            link.symlink_to(path.resolve())
        names.append(str(link))
    seconds, _ = timed([DEPICT, "enhance", *names, "-o", str(out)])
    t0 = time.perf_counter()
    for i, name in enumerate(names):
        oiio_copy(Path(name), work / f"oiio_{i % 2}.exr")
    copies = time.perf_counter() - t0
    print(
        f"depict enhance of {files} files in one process {seconds:6.2f} s, {files} oiiotool "
        f"copies {copies:5.2f} s: {seconds / copies:5.2f}x"
    )


def http_row(path: Path, work: Path, requests: int = 6) -> None:
    """Throughput of ``depict serve`` (2 workers, 2 clients) vs 2 parallel oiiotool copies."""
    from service.client import Client
    from tests.live_server import live_server

    env = {"DEPICT_WORKERS": "2", "DEPICT_QUEUE": "16", "DEPICT_TIMEOUT_S": "600"}
    with live_server(env) as server:
        clients = threading.local()

        def one(i: int) -> None:
            if not hasattr(clients, "c"):
                clients.c = Client(server.url, api_key="", retries=50)
            clients.c.enhance(path, work / f"http_{i % 2}.exr")

        parallel_rate(one, 2, 2)  # warm both workers
        served = parallel_rate(one, requests, 2)
    copied = parallel_rate(lambda i: oiio_copy(path, work / f"oiio_{i % 2}.exr"), requests, 2)
    verdict = "ok" if served >= 0.8 * copied else "UNDER"
    print(
        f"HTTP, 2 workers, 2 clients: {served:.2f} frames/s; 2 parallel oiiotool: "
        f"{copied:.2f} frames/s: {served / copied:.2f}x (target >= 0.8x: {verdict})"
    )


def batch_row(path: Path, work: Path, frames: int = 8) -> None:
    """``depict batch`` of ``frames`` frames (2 workers) vs as many oiiotool copies, 2 at once."""
    seq = work / "seq"
    seq.mkdir(exist_ok=True)
    for i in range(1, frames + 1):
        link = seq / f"shot.{i:04d}.exr"
        if not link.exists():
            link.symlink_to(path.resolve())
    cmd = [DEPICT, "batch", str(seq / "shot.####.exr"), "-o", str(work / "out.####.exr")]
    seconds, _ = timed([*cmd, "--workers", "2", "--no-progress"])
    batched = frames / seconds
    copied = parallel_rate(lambda i: oiio_copy(path, work / f"oiio_{i % 2}.exr"), frames, 2)
    verdict = "ok" if batched >= 0.8 * copied else "UNDER"
    print(
        f"depict batch of {frames}, 2 workers: {batched:.2f} frames/s; {frames} oiiotool copies "
        f"on 2 processes: {copied:.2f} frames/s: {batched / copied:.2f}x "
        f"(target >= 0.8x: {verdict})"
    )


def covered_frame() -> Frame:
    """A fully covered 1080p frame with lobes (bench_curvature's spheres before a wavy wall)."""
    from bench.bench_curvature import _frame

    normal, depth, mask, lobes, lights = _frame(covered=True)
    buffers = {"normal": normal, "depth": depth, "coverage": mask.astype(np.float32)}
    buffers["beauty"] = sum(lobes.values(), np.zeros_like(normal))
    for lobe, rad in lobes.items():
        buffers[lobe] = rad
        buffers[f"{lobe}.light"] = lights[lobe]
    return Frame(buffers=buffers)


#: What the defaults cost beyond the papers' operators: ``pipeline.run`` rows without a target.
PIPELINE_VARIANTS: tuple[tuple[str, dict[str, object]], ...] = (
    ("radiance_scaling", {"keep_lighting": False}),
    ("radiance_scaling", {"preset": "paper"}),
    ("light_alignment", {"keep_lighting": False}),
    ("light_alignment", {"form": "relight"}),
    ("light_alignment", {"preset": "paper"}),
)


def pipeline_rows() -> None:
    """``pipeline.run`` of each operator, in ratio to a memory-bound copy; then the defaults'
    parts (:data:`PIPELINE_VARIANTS`)."""
    from service import pipeline

    report = Report("pipeline.run on a fully covered frame", HD)
    frame = covered_frame()
    for op, target in (("curvature", 6.0), ("radiance_scaling", 10.0), ("light_alignment", 60.0)):
        compiled = pipeline.compile([{"op": op}])
        report.paired(f"pipeline.run {op}", partial(pipeline.run, frame, compiled), 9, target)
    for op, params in PIPELINE_VARIANTS:
        compiled = pipeline.compile([{"op": op, "params": params}])
        name = ", ".join(f"{k}: {v}" for k, v in params.items())
        report.paired(f"  … {op} {name}", partial(pipeline.run, frame, compiled), 5)


def real_pipeline_rows(path: Path) -> None:
    """``pipeline.run`` of each operator's defaults on a renderer's frame as read (Cycles:
    noise, a floor, background, a transmission pass with no light in it), without targets."""
    import gbuffer
    from service import pipeline

    frame = gbuffer.read(path)
    report = Report(f"pipeline.run on {path.name}", frame.shape)
    for op in ("curvature", "radiance_scaling", "light_alignment"):
        compiled = pipeline.compile([{"op": op}])
        report.paired(f"pipeline.run {op}", partial(pipeline.run, frame, compiled), 5)


SECTIONS = ("enhance", "http", "batch", "pipeline")


def main(argv: Sequence[str] = ()) -> None:
    """Every section, or those named: ``python -m bench.bench_end_to_end enhance http``."""
    sections = list(argv) or list(SECTIONS)
    unknown = sorted(set(sections) - set(SECTIONS))
    if unknown:
        raise SystemExit(f"unknown sections {unknown}; choose from {', '.join(SECTIONS)}")
    if OIIOTOOL is None:
        raise SystemExit("oiiotool not found: `uv sync` installs the openimageio wheel")
    work = Path(tempfile.mkdtemp(prefix="bench-e2e-"))
    try:
        cycles = cycles_frame()
        if cycles is None:
            print("Cycles frame skipped: no blender on PATH (apt-get install blender)")
        frames = [("Cycles multilayer", cycles)] if cycles else []
        frames.append(("Depict render", depict_frame()))
        main_frame = cycles or depict_frame()
        for name, path in frames if "enhance" in sections else ():
            enhance_rows(name, path, work)
            other_op_rows(path, work)
            several_row(path, work)
        if "http" in sections:
            http_row(main_frame, work)
        if "batch" in sections:
            batch_row(main_frame, work)
        if "pipeline" in sections:
            pipeline_rows()
            if cycles is not None:
                real_pipeline_rows(cycles)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main(sys.argv[1:])
