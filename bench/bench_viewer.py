"""Benchmark: the web viewer's slider change -> new preview, at 1080p input.

Run: ``.venv/bin/python -m bench.bench_viewer``. A canonical 1920x1080 G-buffer (OSMesa render of
examples/spot.obj) is loaded into the viewer (``/ui/`` of a real ``depict serve``, one worker) in
Debian's Chromium through Playwright, with the default pipeline (Radiance Scaling). Then, 10
times, the γ slider moves and the time until the page shows the new preview is measured: the
request (asked at once: no preview is in flight), the job on the worker (the pipeline on the
960x540 copy, its PNG, the congruence score), the answer and its display. Also the preview
request alone (no browser) at several preview heights, with the worker's share; and how far
each operator on the half-size copy is from its full-resolution result shrunk to half size.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from bench.bench_end_to_end import cycles_frame
from bench.common import HD
from bench.viewer_browser import CHROMIUM, previews, viewer, wait_preview
from gbuffer.frame import Frame
from gbuffer.io import write
from gbuffer.render import load_mesh, render
from service import pipeline
from service.registry import Context
from service.viewer.work import downscale

ROOT = Path(__file__).resolve().parent.parent
REPEAT = 10
PREVIEW_HEIGHT = 540  # the page's default
ENV = {"DEPICT_WORKERS": "1", "DEPICT_TIMEOUT_S": "600"}


def slider_ms(page: Any) -> tuple[list[float], list[str]]:
    """Milliseconds from each γ slider move to the new preview on the page, and the page's own
    status lines."""
    gamma = page.locator('li[data-op="radiance_scaling"] [data-param="gamma"] input[type=range]')
    times, statuses = [], []
    for i in range(REPEAT):
        seen = previews(page)
        t0 = time.perf_counter()
        gamma.fill(str(500 + 20 * i))  # γ from 1 up, a new value each time
        wait_preview(page, seen)
        times.append((time.perf_counter() - t0) * 1e3)
        statuses.append(page.text_content("#status"))
    return times, statuses


def api_ms(url: str, frame_id: str, height: int) -> tuple[float, float]:
    """Median round trip and median worker time (ms) of a preview request at ``height``."""
    trips, jobs = [], []
    with httpx.Client(base_url=url, timeout=600) as client:
        for i in range(REPEAT + 1):
            body = {
                "pipeline": {"steps": [{"op": "radiance_scaling", "params": {"gamma": 1 + i / 4}}]}
            }
            t0 = time.perf_counter()
            answer = client.post(f"/v1/frames/{frame_id}/preview", json={**body, "height": height})
            answer.raise_for_status()
            if i:  # the first one makes the copy at this height
                trips.append((time.perf_counter() - t0) * 1e3)
                jobs.append(answer.json()["job_s"] * 1e3)
    return statistics.median(trips), statistics.median(jobs)


def upload(url: str, path: Path) -> str:
    """The viewer's id of ``path``, sent to the server at ``url``."""
    answer = httpx.post(
        f"{url}/v1/frames", files={"file": (path.name, path.read_bytes())}, timeout=600
    )
    answer.raise_for_status()
    return str(answer.json()["id"])


def carried(frame: Frame, op: str) -> float:
    """How far ``op`` on the half-size copy is from its full-resolution result shrunk to half
    size, as a fraction of the operator's own effect there (mean absolute differences)."""
    steps = pipeline.compile([{"op": op}])
    full, _ = pipeline.run_timed(frame, steps, Context())
    preview, _ = pipeline.run_timed(downscale(frame, 2), steps, Context())
    reference = downscale(full, 2).buffers["beauty"]
    effect = np.abs(reference - downscale(frame, 2).buffers["beauty"]).mean()
    return float(np.abs(preview.buffers["beauty"] - reference).mean() / effect)


def main() -> None:
    if not Path(CHROMIUM).is_file():
        print(f"Chromium is absent ({CHROMIUM}; apt-get install chromium): no viewer benchmark")
        return
    work = Path(tempfile.mkdtemp(prefix="bench-viewer-"))
    frame = work / "spot_1080p.exr"
    h, w = HD
    rendered = render(load_mesh(ROOT / "examples" / "spot.obj"), w, h)
    write(rendered, frame)
    for op in ("radiance_scaling", "light_alignment", "unsharp_masking"):
        print(f"{op} on the 960x540 copy vs its 1080p result shrunk: {carried(rendered, op):.2f}")
    print(f"input {frame.name}: {w}x{h}, {frame.stat().st_size / 2**20:.1f} MiB; one worker")
    with viewer(frame, ENV) as (page, url):
        times, statuses = slider_ms(page)
        print(f"slider -> new preview in the page ({PREVIEW_HEIGHT} px high), {REPEAT} moves:")
        median, low, high = statistics.median(times), min(times), max(times)
        print(f"  median {median:.0f} ms, min {low:.0f}, max {high:.0f}")
        print(f"  the page's last status: {statuses[-1]}")
        print("preview request alone (no browser), median of 10: round trip / on the worker")
        frame_id = upload(url, frame)
        for height in (360, 540, 720, 1080):
            trip, job = api_ms(url, frame_id, height)
            print(f"  {height:5d} px: {trip:6.0f} ms / {job:6.0f} ms")
        cycles = cycles_frame()
        if cycles is None:
            print("Cycles frame skipped: no blender on PATH (apt-get install blender)")
        else:
            print(f"the same, {cycles.name} (Cycles, path traced: noise that PNG compresses badly)")
            cycles_id = upload(url, cycles)
            for height in (540, 1080):
                trip, job = api_ms(url, cycles_id, height)
                print(f"  {height:5d} px: {trip:6.0f} ms / {job:6.0f} ms")
    for p in work.iterdir():
        p.unlink()
    work.rmdir()


if __name__ == "__main__":
    main()
